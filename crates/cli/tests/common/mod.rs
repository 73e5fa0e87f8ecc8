//! Running the `cellbus` binary from tests.

#![allow(dead_code)]

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Child, ChildStdin, ChildStdout, Command, Output, Stdio};
use std::sync::mpsc;
use std::time::{Duration, UNIX_EPOCH};

/// The built `cellbus` binary.
pub fn cellbus() -> Command {
    Command::new(env!("CARGO_BIN_EXE_cellbus"))
}

/// A running simulator, killed when dropped.
pub struct Sim {
    child: Child,
    /// What it printed on its first line after `listening on `.
    pub endpoint: String,
}

impl Sim {
    /// Starts the simulator of `device` on a free loopback port with a faulty line: 30% of
    /// its replies dropped, late, with a flipped bit or garbage before them, as `seed`
    /// draws them.
    pub fn start_faulty(device: &str, seed: &str) -> Sim {
        Sim::start(&[
            device,
            "--listen",
            "127.0.0.1:0",
            "--fault-rate",
            "0.3",
            "--seed",
            seed,
        ])
    }

    /// Runs `cellbus DEVICE --endpoint ENDPOINT ARGS…`: the client of `device` against this
    /// simulator.
    pub fn client(&self, device: &str, args: &[&str]) -> Output {
        let mut all = vec![device, "--endpoint", &self.endpoint];
        all.extend_from_slice(args);
        run(&all)
    }

    /// Runs the client of `device` with `args` `times` times against its simulator on a
    /// faulty line ([`Sim::start_faulty`] with `seed`): every run must get through.
    pub fn client_through_faults(
        device: &str,
        seed: &str,
        times: usize,
        args: &[&str],
    ) -> Vec<Output> {
        let sim = Sim::start_faulty(device, seed);
        (0..times)
            .map(|_| {
                let out = sim.client(device, args);
                assert!(out.status.success(), "{}", stderr(&out));
                out
            })
            .collect()
    }

    /// Starts `cellbus sim ARGS…` (stdin empty: no control channel) and waits for its
    /// `listening on …` line.
    pub fn start(args: &[&str]) -> Sim {
        Sim::spawn(args, Stdio::null()).0
    }

    /// Like [`Sim::start`], with a control channel to type commands into.
    pub fn start_with_control(args: &[&str]) -> (Sim, SimControl) {
        let (mut sim, stdout) = Sim::spawn(args, Stdio::piped());
        let stdin = sim.take_stdin();
        (sim, SimControl { stdin, stdout })
    }

    /// Starts `cellbus sim ARGS…` with `stdin`, waits for its `listening on …` line and
    /// gives its stdout, for simulators that print more lines after it.
    pub fn spawn(args: &[&str], stdin: Stdio) -> (Sim, BufReader<ChildStdout>) {
        let (child, stdout, endpoint) = start_listening(
            cellbus().arg("sim").args(args).stdin(stdin),
            "listening on ",
        );
        (Sim { child, endpoint }, stdout)
    }
}

impl Sim {
    /// Asserts that the simulator's endpoint starts with `prefix`.
    #[track_caller]
    pub fn assert_listens_on(&self, prefix: &str) {
        assert!(self.endpoint.starts_with(prefix), "{}", self.endpoint);
    }

    /// The simulator's stdin, when it was started with a piped one.
    pub fn take_stdin(&mut self) -> ChildStdin {
        self.child.stdin.take().expect("stdin is piped")
    }
}

/// A simulator's control channel: commands on its stdin, answers on its stdout.
pub struct SimControl {
    stdin: ChildStdin,
    stdout: BufReader<ChildStdout>,
}

impl SimControl {
    /// For a simulator whose stdin and stdout the caller piped (and read up to here).
    pub fn new(stdin: ChildStdin, stdout: BufReader<ChildStdout>) -> SimControl {
        SimControl { stdin, stdout }
    }

    /// Types `command` and returns the simulator's one-line answer (`ok: …` or
    /// `error: …`), which comes once the command is carried out.
    pub fn send(&mut self, command: &str) -> String {
        writeln!(self.stdin, "{command}").expect("the simulator reads its stdin");
        self.stdin.flush().expect("command sent");
        let mut answer = String::new();
        let n = self
            .stdout
            .read_line(&mut answer)
            .expect("the simulator answers");
        assert!(
            n > 0,
            "the simulator ended instead of answering {command:?}"
        );
        answer.trim_end().to_owned()
    }

    /// Like [`send`](Self::send), asserting an `ok: …` answer; returns the words after it.
    pub fn ok(&mut self, command: &str) -> String {
        let answer = self.send(command);
        answer
            .strip_prefix("ok: ")
            .unwrap_or_else(|| panic!("{command:?} answered {answer:?}"))
            .to_owned()
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Starts `command` with its stdout piped (its stderr goes to the test's) and reads its
/// first line, which must be `prefix` followed by where it listens: the child, the rest of
/// its stdout and that address.
pub fn start_listening(
    command: &mut Command,
    prefix: &str,
) -> (Child, BufReader<ChildStdout>, String) {
    let mut child = command
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap_or_else(|e| panic!("{:?} runs: {e}", command.get_program()));
    let mut stdout = BufReader::new(child.stdout.take().expect("stdout is piped"));
    let address = line_after(&mut stdout, prefix);
    (child, stdout, address)
}

/// The next line `from` gives, which must start with `prefix`: the rest of it, without the
/// line's end.
pub fn line_after(from: &mut impl BufRead, prefix: &str) -> String {
    let mut line = String::new();
    from.read_line(&mut line).expect("a line");
    line.trim_end()
        .strip_prefix(prefix)
        .unwrap_or_else(|| panic!("expected a line `{prefix}…`, got {line:?}"))
        .to_owned()
}

/// Starts `cellbus ARGS…` with no input and its stdout and stderr piped.
pub fn spawn_piped(args: &[&str]) -> Child {
    cellbus()
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("cellbus runs")
}

/// Runs `cellbus ARGS…`, killing it if it is still running after `limit` (a watchdog for
/// commands that wait for events; a passing run ends long before).
pub fn run_within(args: &[&str], limit: Duration) -> Output {
    let child = spawn_piped(args);
    let id = child.id();
    let (done, finished) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = done.send(child.wait_with_output());
    });
    match finished.recv_timeout(limit) {
        Ok(output) => output.expect("cellbus ran"),
        Err(_) => {
            let _ = std::process::Command::new("kill")
                .arg(id.to_string())
                .status();
            panic!("cellbus {args:?} still running after {limit:?}");
        }
    }
}

/// Sends SIGINT (what Ctrl-C sends) to the process `id`.
pub fn interrupt(id: u32) {
    let status = Command::new("sh")
        .args(["-c", &format!("kill -INT {id}")])
        .status()
        .expect("sh runs");
    assert!(status.success(), "kill -INT {id} failed");
}

/// Now, in ms since the epoch.
pub fn now_ms() -> i64 {
    i64::try_from(
        std::time::SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap()
            .as_millis(),
    )
    .unwrap()
}

/// Fails (never skips) when python3 is missing or cannot run `code` (the imports an
/// interoperability test needs): `test` names the test, `missing` the packages, `hint`
/// says how to install them. Gives what `code` printed.
pub fn require_python(code: &str, test: &str, missing: &str, hint: &str) -> String {
    match Command::new("python3").args(["-c", code]).output() {
        Err(e) => panic!("python3 is needed for the {test} ({e}); {hint}"),
        Ok(out) if !out.status.success() => panic!(
            "{missing} is not installed for python3 ({}); {hint}",
            String::from_utf8_lossy(&out.stderr).trim()
        ),
        Ok(out) => String::from_utf8_lossy(&out.stdout).trim().to_owned(),
    }
}

/// Runs `cellbus ARGS…` to completion.
pub fn run(args: &[&str]) -> Output {
    cellbus()
        .args(args)
        .stdin(Stdio::null())
        .output()
        .expect("cellbus runs")
}

/// Asserts that `output`'s stdout contains `text`, showing all of it if not.
#[track_caller]
pub fn assert_stdout_has(output: &Output, text: &str) {
    assert!(stdout(output).contains(text), "{}", stdout(output));
}

/// Asserts that `output`'s stderr contains `text`, showing all of it if not.
#[track_caller]
pub fn assert_stderr_has(output: &Output, text: &str) {
    assert!(stderr(output).contains(text), "{}", stderr(output));
}

/// Stdout as text.
pub fn stdout(output: &Output) -> String {
    String::from_utf8_lossy(&output.stdout).into_owned()
}

/// Stderr as text.
pub fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// A running gateway, killed when dropped.
pub struct Gateway {
    child: Child,
    /// `IP:PORT` of its HTTP server.
    pub addr: String,
}

impl Gateway {
    pub fn start(data: &std::path::Path) -> Gateway {
        Gateway::start_with(data, &[])
    }

    /// Like [`Gateway::start`], with more `cellbus serve` arguments.
    pub fn start_with(data: &std::path::Path, args: &[&str]) -> Gateway {
        Gateway::start_with_token(data, args, None)
    }

    /// Like [`Gateway::start_with`], with `token` as `CELLBUS_TOKEN` (none if `None`).
    pub fn start_with_token(data: &std::path::Path, args: &[&str], token: Option<&str>) -> Gateway {
        let env: Vec<(&str, &str)> = token.map(|t| ("CELLBUS_TOKEN", t)).into_iter().collect();
        Gateway::start_with_env(data, args, &env)
    }

    /// Like [`Gateway::start_with`], with the environment variables `env` (and no
    /// `CELLBUS_TOKEN` unless it is one of them).
    pub fn start_with_env(data: &std::path::Path, args: &[&str], env: &[(&str, &str)]) -> Gateway {
        let mut command = cellbus();
        command
            .args(["serve", "--listen", "127.0.0.1:0", "--data"])
            .arg(data)
            .args(args)
            .env_remove("CELLBUS_TOKEN")
            .envs(env.iter().copied());
        let (child, _, addr) = start_listening(&mut command, "listening on http://");
        Gateway { child, addr }
    }

    /// A plain HTTP/1.1 POST of the JSON `body` with `Authorization: Bearer token`;
    /// returns the status code and the body.
    pub fn post(&self, path: &str, token: &str, body: &str) -> (u16, String) {
        http_exchange(
            &self.addr,
            &format!(
                "POST {path} HTTP/1.1\r\nHost: {}\r\nConnection: close\r\n\
                 Authorization: Bearer {token}\r\nContent-Type: application/json\r\n\
                 Content-Length: {}\r\n\r\n{body}",
                self.addr,
                body.len()
            ),
        )
    }

    /// Sends the gateway `SIGHUP` (what `systemctl reload cellbus` does): it reloads its
    /// configuration.
    pub fn hang_up(&self) {
        let id = self.child.id();
        let status = Command::new("sh")
            .args(["-c", &format!("kill -HUP {id}")])
            .status()
            .expect("sh runs");
        assert!(status.success(), "kill -HUP {id} failed");
    }

    /// GETs `path`, which must answer 200 with JSON.
    pub fn get_json(&self, path: &str) -> serde_json::Value {
        let (status, body) = self.get(path);
        assert_eq!(status, 200, "{body}");
        serde_json::from_str(&body).unwrap()
    }

    /// A plain HTTP/1.1 GET; returns the status code and the body.
    pub fn get(&self, path: &str) -> (u16, String) {
        http_get(&self.addr, path)
    }

    /// Every point's `/api/history` answer over `[from, to]` (ms since the epoch), by id,
    /// in the order of `/api/devices`.
    pub fn histories(&self, from: i64, to: i64) -> Vec<(String, serde_json::Value)> {
        let (status, body) = self.get("/api/devices");
        assert_eq!(status, 200, "{body}");
        let devices: serde_json::Value = serde_json::from_str(&body).unwrap();
        let mut all = Vec::new();
        for device in devices["devices"].as_array().unwrap() {
            for point in device["points"].as_array().unwrap() {
                let id = point["id"].as_str().unwrap();
                let (status, body) = self.get(&format!(
                    "/api/history?point={id}&from={}&to={}",
                    rfc3339(from),
                    rfc3339(to)
                ));
                assert_eq!(status, 200, "{id}: {body}");
                all.push((id.to_owned(), serde_json::from_str(&body).unwrap()));
            }
        }
        all
    }
}

/// `ms` since the epoch as RFC 3339 with milliseconds.
pub fn rfc3339(ms: i64) -> String {
    humantime::format_rfc3339_millis(UNIX_EPOCH + Duration::from_millis(ms.unsigned_abs()))
        .to_string()
}

/// An RFC 3339 time as ms since the epoch.
pub fn rfc3339_ms(text: &str) -> i64 {
    let t = humantime::parse_rfc3339(text).unwrap_or_else(|e| panic!("{text}: {e}"));
    i64::try_from(t.duration_since(UNIX_EPOCH).unwrap().as_millis()).unwrap()
}

/// A value of the HTTP API as text (numbers as `f64`), `None` for null.
pub fn api_value(v: &serde_json::Value) -> Option<String> {
    match v {
        serde_json::Value::Number(n) => Some(format!("{}", n.as_f64().unwrap())),
        serde_json::Value::String(s) => Some(s.clone()),
        _ => None,
    }
}

/// A plain HTTP/1.1 GET to `addr` (`IP:PORT`); returns the status code and the body.
pub fn http_get(addr: &str, path: &str) -> (u16, String) {
    http_exchange(
        addr,
        &format!("GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"),
    )
}

/// Sends `request` to `addr` on a connection of its own; the answer's status and body.
fn http_exchange(addr: &str, request: &str) -> (u16, String) {
    let mut stream = TcpStream::connect(addr).expect("the server accepts connections");
    stream
        .set_read_timeout(Some(Duration::from_secs(30)))
        .expect("timeout set");
    stream.write_all(request.as_bytes()).expect("request sent");
    let mut response = String::new();
    stream.read_to_string(&mut response).expect("response read");
    let status = response
        .split(' ')
        .nth(1)
        .and_then(|s| s.parse().ok())
        .expect("a status line");
    let body = response
        .split_once("\r\n\r\n")
        .map(|(_, b)| b.to_owned())
        .unwrap_or_default();
    (status, body)
}

impl Gateway {
    /// Reads `/api/events/stream` until an event of `kind` arrives; returns its data line.
    pub fn first_event(&self, kind: &str) -> String {
        let mut stream = TcpStream::connect(&self.addr).expect("the gateway accepts connections");
        stream
            .set_read_timeout(Some(Duration::from_secs(60)))
            .expect("timeout set");
        write!(
            stream,
            "GET /api/events/stream HTTP/1.1\r\nHost: {}\r\n\r\n",
            self.addr
        )
        .expect("request sent");
        let mut lines = BufReader::new(stream).lines();
        let wanted = format!("event: {kind}");
        while let Some(Ok(line)) = lines.next() {
            if line.trim_end() == wanted {
                return lines.next().and_then(Result::ok).unwrap_or_default();
            }
        }
        panic!("the event stream ended before a {kind} event");
    }
}

impl Drop for Gateway {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
