//! `cellbus serve` and `cellbus config`, end to end through the binary.

mod common;

use std::process::Output;

use common::{Gateway, assert_stderr_has, assert_stdout_has, run, stderr, stdout};
use testkit::{Mosquitto, Subscriber};

/// MQTT waits: generous, for a loaded machine.
const MQTT_LIMIT: std::time::Duration = std::time::Duration::from_secs(60);

/// The bdSeq of the next NBIRTH `node` sees (`what` names it if none comes).
async fn next_birth_bd_seq(node: &mut Subscriber, what: &str) -> u64 {
    node.next_where(what, MQTT_LIMIT, |m| m.kind() == "NBIRTH")
        .await
        .bd_seq()
        .expect("the NBIRTH has a bdSeq")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn serve_mqtt_publishes_the_demo_and_a_killed_gateway_leaves_its_will_with_the_births_bd_seq()
{
    let broker = Mosquitto::start();
    let mut node = Subscriber::start(broker.port(), "spBv1.0/cellbus/+/demo").await;
    let data = tempfile::tempdir().unwrap();
    let url = broker.url();
    let gateway = Gateway::start_with(data.path(), &["--mqtt", &url]);
    let bd_seq = next_birth_bd_seq(&mut node, "an NBIRTH from cellbus serve --mqtt").await;

    // kill -9: no DISCONNECT, so the broker publishes the Will.
    drop(gateway);
    let death = node
        .next_where("the NDEATH Will", MQTT_LIMIT, |m| m.kind() == "NDEATH")
        .await;
    assert_eq!(
        death.bd_seq(),
        Some(bd_seq),
        "the Will's bdSeq is the NBIRTH's"
    );

    // The same data directory: bdSeq moves on.
    let _gateway = Gateway::start_with(data.path(), &["--mqtt", &url]);
    let next = next_birth_bd_seq(&mut node, "an NBIRTH after the restart").await;
    assert!(
        next > bd_seq,
        "bdSeq {next} after the restart, {bd_seq} before"
    );
}

#[test]
fn serve_refuses_a_broker_url_that_is_neither_mqtt_nor_mqtts() {
    let data = tempfile::tempdir().unwrap();
    let output = run(&[
        "serve",
        "--listen",
        "127.0.0.1:0",
        "--data",
        data.path().to_str().unwrap(),
        "--mqtt",
        "ws://127.0.0.1:8883",
    ]);
    assert!(!output.status.success());
    let err = stderr(&output);
    assert!(
        err.contains("write mqtt://host:1883 or mqtts://host:8883"),
        "{err}"
    );
}

#[test]
fn serve_without_arguments_runs_the_demo_cell_and_answers_http() {
    let data = tempfile::tempdir().unwrap();
    let gateway = Gateway::start(data.path());
    let (status, body) = gateway.get("/healthz");
    assert_eq!(status, 200, "{body}");
    // The demo devices are polled through the real clients: their values arrive on the
    // event stream as they change (a blocking read, bounded by the socket's read timeout).
    let event = gateway.first_event("value");
    assert!(
        ["jbc1.", "sealer", "cross1.", "placer1."]
            .iter()
            .any(|device| event.contains(device)),
        "{event}"
    );
    let (status, body) = gateway.get("/api/devices");
    assert_eq!(status, 200, "{body}");
    assert!(body.contains("\"quality\":\"good\""), "{body}");
    let (status, _) = gateway.get("/api/devices/no-such-device");
    assert_eq!(status, 404);
}

#[test]
fn serve_with_a_bad_configuration_exits_2_naming_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cell.toml");
    std::fs::write(&path, "[[line]]\nname = \"a\"\nendpoint = \"bogus://x\"\n").unwrap();
    let out = run(&[
        "serve",
        "--config",
        path.to_str().unwrap(),
        "--listen",
        "127.0.0.1:0",
    ]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert_stderr_has(&out, "cell.toml:");
}

#[test]
fn serve_refuses_a_retention_that_would_delete_the_history_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().to_str().unwrap();
    for (flag, age, least) in [
        ("--retain", "30m", "1h"),
        ("--retain", "0s", "1h"),
        ("--retain-audit", "12m", "1day"),
    ] {
        let out = run(&[
            "serve",
            "--listen",
            "127.0.0.1:0",
            "--data",
            data,
            flag,
            age,
        ]);
        assert_eq!(out.status.code(), Some(2), "{flag} {age}: {}", stderr(&out));
        assert_stderr_has(&out, &format!("{age} would keep less than {least}"));
    }
    assert!(
        std::fs::read_dir(dir.path()).unwrap().next().is_none(),
        "nothing was started or stored"
    );
}

#[test]
fn serve_refuses_a_token_no_client_could_send_and_writes_without_one_as_usage_errors() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().to_str().unwrap();
    // `cellbus serve ARGS…` with `token` as CELLBUS_TOKEN (none if None): a usage error.
    let refused = |args: &[&str], token: Option<&str>| {
        let mut serve = common::cellbus();
        serve
            .args(["serve", "--listen", "127.0.0.1:0", "--data", data])
            .args(args)
            .env_remove("CELLBUS_READ_TOKEN");
        match token {
            Some(token) => serve.env("CELLBUS_TOKEN", token),
            None => serve.env_remove("CELLBUS_TOKEN"),
        };
        let out = serve.output().unwrap();
        assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
        out
    };
    let out = refused(&[], Some("pässwörd"));
    assert!(
        stderr(&out).contains("the write token cannot be used: character 2 is not visible ASCII")
            && !stderr(&out).contains('ä'),
        "{}",
        stderr(&out)
    );
    let out = refused(&["--allow-writes"], None);
    assert_stderr_has(&out, "--allow-writes needs a token");
    // A read token that is the write token would let every reader write.
    let out = refused(&["--read-token", "s3cret"], Some("s3cret"));
    assert!(
        stderr(&out).contains("the read token is the write token")
            && !stderr(&out).contains("s3cret"),
        "{}",
        stderr(&out)
    );
}

/// `cellbus config check` of a cell.toml holding `text`.
fn config_check(text: &[u8]) -> Output {
    let (_dir, path) = config_file(text);
    run(&["config", "check", path.to_str().unwrap()])
}

/// `text` as `cell.toml` in a new temporary directory (kept while the first is held).
fn config_file(text: impl AsRef<[u8]>) -> (tempfile::TempDir, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cell.toml");
    std::fs::write(&path, text).unwrap();
    (dir, path)
}

#[test]
fn config_check_refuses_a_token_with_characters_a_header_cannot_carry() {
    let mut text = b"token = \"secret here\"\n".to_vec();
    text.extend(run(&["config", "example"]).stdout);
    let out = config_check(&text);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("cell.toml:1:")
            && stderr(&out).contains("token cannot be used: character 7 is not visible ASCII"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn the_example_configuration_passes_its_own_check() {
    let example = run(&["config", "example"]);
    assert!(example.status.success());
    let out = config_check(&example.stdout);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_stdout_has(&out, ": ok,");
    assert_stdout_has(
        &out,
        "early: mon, tue, wed, thu, fri 06:00–14:00, 2 breaks; late: mon, tue, wed, thu, fri 14:00–22:00, 1 break",
    );
    // With a limit alarm: told in words.
    let mut text = example.stdout.clone();
    text.extend_from_slice(
        b"\n[[alarm]]\npoint = \"jbc1.air_temperature\"\nhigh = 450.0\ndeadband = 5.0\n\
          on_delay = \"5s\"\npriority = \"urgent\"\n",
    );
    let out = config_check(&text);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_stdout_has(
        &out,
        "  alarm on jbc1.air_temperature: above 450 (deadband 5, on delay 5s), urgent priority",
    );
}

#[test]
fn config_check_import_csv_and_serve_warn_about_registers_sharing_a_register_and_go_on() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("meter.csv"),
        "name,table,address,type\nvoltage,input,0,float32\ncurrent,input,1,float32\n",
    )
    .unwrap();
    let path = dir.path().join("cell.toml");
    std::fs::write(
        &path,
        "[[line]]\nname = \"meters\"\nendpoint = \"modbus-tcp://127.0.0.1:5020\"\n\n\
         [[line.device]]\nid = \"meter1\"\nprotocol = \"modbus\"\naddress = 1\n\
         registers_csv = \"meter.csv\"\n"
            .replace("5020", &testkit::free_port().to_string()),
    )
    .unwrap();
    let shared =
        "registers \"voltage\" (input 0–1) and \"current\" (input 1–2) share input register 1";
    let out = run(&["config", "check", path.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_stdout_has(&out, &format!("warning: device \"meter1\": {shared}"));
    let csv = dir.path().join("meter.csv");
    let out = run(&["config", "import-csv", csv.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        stdout(&out).starts_with("[[line.device.register]]"),
        "{}",
        stdout(&out)
    );
    assert!(
        stderr(&out).contains(&format!("warning: {}: {shared}", csv.display())),
        "{}",
        stderr(&out)
    );
    // The gateway logs it at its start, then runs: once it prints where it listens, the
    // warning (written before) is on its standard error.
    let data = tempfile::tempdir().unwrap();
    let mut serve = common::cellbus()
        .args(["serve", "--listen", "127.0.0.1:0", "--config"])
        .arg(&path)
        .arg("--data")
        .arg(data.path())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("cellbus runs");
    let mut first = String::new();
    std::io::BufRead::read_line(
        &mut std::io::BufReader::new(serve.stdout.take().expect("piped")),
        &mut first,
    )
    .unwrap();
    assert!(first.starts_with("listening on http://"), "{first:?}");
    serve.kill().unwrap();
    let out = serve.wait_with_output().unwrap();
    assert_stderr_has(&out, &format!("cell.toml: device \"meter1\": {shared}"));
}

#[test]
fn config_check_points_at_the_bad_line() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cell.toml");
    let mut text = String::from_utf8(run(&["config", "example"]).stdout).unwrap();
    text.push_str("\nbogus = 1\n");
    let bad_line = text.lines().count();
    std::fs::write(&path, text).unwrap();
    let out = run(&["config", "check", path.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert_stderr_has(&out, &format!("cell.toml:{bad_line}:"));
    assert_stderr_has(&out, "bogus");
}

#[test]
fn serve_says_at_the_default_level_which_devices_answer_and_what_to_check_in_plain_lines() {
    let sim = common::Sim::start(&["jbc", "--listen", "127.0.0.1:0"]);
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("ttyUSB9");
    let path = dir.path().join("cell.toml");
    std::fs::write(
        &path,
        format!(
            "[[line]]\nname = \"bench\"\nendpoint = \"{}\"\n\
             [[line.device]]\nid = \"jbc1\"\nprotocol = \"jbc\"\n\n\
             [[line]]\nname = \"unplugged\"\nendpoint = \"serial://{}\"\n\
             [[line.device]]\nid = \"jbc2\"\nprotocol = \"jbc\"\n",
            sim.endpoint,
            missing.display()
        ),
    )
    .unwrap();
    let (mut serve, stderr) = logging(&[
        "serve".as_ref(),
        "--listen".as_ref(),
        "127.0.0.1:0".as_ref(),
        "--config".as_ref(),
        path.as_os_str(),
        "--data".as_ref(),
        dir.path().join("data").as_os_str(),
    ]);
    let (lines, seen) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in std::io::BufRead::lines(std::io::BufReader::new(stderr)) {
            let Ok(line) = line else { break };
            if lines.send(line).is_err() {
                break;
            }
        }
    });
    let mut log = Vec::new();
    let summary = loop {
        // Generous: the summary comes after the first round, at most a minute in.
        match seen.recv_timeout(std::time::Duration::from_secs(120)) {
            Ok(line) if line.contains("devices answer") => break line,
            Ok(line) => log.push(line),
            Err(e) => panic!("no first-round summary ({e}); stderr so far: {log:#?}"),
        }
    };
    serve.kill().unwrap();
    serve.wait().unwrap();
    log.push(summary.clone());
    assert!(
        summary.contains("WARN")
            && summary
                .contains("1 of 2 devices answer (jbc1); not answering: jbc2 on line unplugged"),
        "{summary}"
    );
    assert!(
        summary.contains("ttyUSB9"),
        "the reason names the port: {summary}"
    );
    assert!(
        log.iter()
            .any(|l| l.contains("WARN") && l.contains("line unplugged is down")),
        "the line going down is a warning: {log:#?}"
    );
    assert!(
        log.iter().all(|l| !l.contains('\u{1b}')),
        "no colour codes on a pipe: {log:#?}"
    );
}

#[test]
fn a_second_gateway_on_the_same_data_directory_refuses_to_start_naming_the_first() {
    let data = tempfile::tempdir().unwrap();
    let _first = Gateway::start(data.path());
    let out = run(&[
        "serve",
        "--listen",
        "127.0.0.1:0",
        "--data",
        data.path().to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert_stderr_has(&out, "is in use by another cellbus (pid ");
    assert_stderr_has(&out, "cellbus serve (the demo cell)");
}

#[test]
fn config_check_and_serve_refuse_a_password_variable_that_is_not_set_naming_its_line() {
    let (_dir, path) = config_file(
        "[[line]]\nname = \"rework\"\nendpoint = \"tcp://127.0.0.1:9\"\n\
         [[line.device]]\nid = \"jbc1\"\nprotocol = \"jbc\"\n\
         [mqtt]\nbroker = \"mqtt://127.0.0.1:1883\"\nusername = \"gw\"\n\
         password_env = \"CELLBUS_TEST_NEVER_SET\"\n",
    );
    let check = common::cellbus()
        .args(["config", "check"])
        .arg(&path)
        .env_remove("CELLBUS_TEST_NEVER_SET")
        .output()
        .unwrap();
    assert_eq!(check.status.code(), Some(2), "{}", stderr(&check));
    assert_stderr_has(&check, "cell.toml:10:");
    assert_stderr_has(
        &check,
        "[mqtt] password_env names the environment variable CELLBUS_TEST_NEVER_SET, which is not set here",
    );
    let data = tempfile::tempdir().unwrap();
    let serve = common::cellbus()
        .args(["serve", "--listen", "127.0.0.1:0", "--config"])
        .arg(&path)
        .arg("--data")
        .arg(data.path())
        .env_remove("CELLBUS_TEST_NEVER_SET")
        .output()
        .unwrap();
    assert_eq!(serve.status.code(), Some(2), "{}", stderr(&serve));
    assert_stderr_has(&serve, "CELLBUS_TEST_NEVER_SET, which is not set here");

    let set = common::cellbus()
        .args(["config", "check"])
        .arg(&path)
        .env("CELLBUS_TEST_NEVER_SET", "secret")
        .output()
        .unwrap();
    assert!(set.status.success(), "{}", stderr(&set));
    assert_stdout_has(&set, "1 line, 1 device, 1 interface");
    assert_stdout_has(&set, "    jbc1 (jbc, address 1): jbc1");
    assert_stdout_has(
        &set,
        "  [mqtt] Sparkplug B to mqtt://127.0.0.1:1883 as cellbus/",
    );
}

#[test]
fn config_check_reports_every_mistake_of_a_file_at_once() {
    let out = config_check(
        b"[[line]]\nname = \"a\"\nendpoint = \"tcp://127.0.0.1:9\"\n\
         [[line.device]]\nid = \"jbc1\"\nprotocol = \"jbc\"\naddress = 100\n\
         [[line]]\nname = \"b\"\nendpoint = \"tcp://127.0.0.1:10\"\n\
         [[line.device]]\nid = \"sealer9\"\nprotocol = \"thermosald\"\naddress = 9\n",
    );
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert_stderr_has(&out, "2 mistakes:");
    assert_stderr_has(&out, "cell.toml:7:");
    assert_stderr_has(&out, "cell.toml:14:");
}

#[test]
fn with_log_format_json_every_log_line_is_one_json_object_for_a_log_shipper() {
    let dir = tempfile::tempdir().unwrap();
    let (mut serve, stderr) = logging(&[
        "--log-format".as_ref(),
        "json".as_ref(),
        "serve".as_ref(),
        "--listen".as_ref(),
        "127.0.0.1:0".as_ref(),
        "--data".as_ref(),
        dir.path().as_os_str(),
    ]);
    let mut lines = std::io::BufRead::lines(std::io::BufReader::new(stderr));
    // The first line is the start, logged before anything else.
    let first = lines.next().expect("a log line").expect("text");
    serve.kill().unwrap();
    serve.wait().unwrap();
    let line: serde_json::Value =
        serde_json::from_str(&first).unwrap_or_else(|e| panic!("{e}: {first}"));
    assert_eq!(line["level"], "INFO", "{line}");
    assert_eq!(line["fields"]["kind"], "gateway_started", "{line}");
    assert!(
        line["fields"]["message"]
            .as_str()
            .unwrap()
            .starts_with("gateway started on http://127.0.0.1:"),
        "{line}"
    );
    assert!(line["timestamp"].is_string(), "{line}");
}

/// Under systemd (`Type=notify`, `WatchdogSec=2`): READY=1 once it listens, WATCHDOG=1 at
/// half the period while it works, STOPPING=1 on SIGTERM; read from the notification
/// socket systemd would hold, here a datagram socket of the test's own.
#[test]
fn under_systemd_serve_says_ready_pets_the_watchdog_and_says_stopping() {
    use std::os::unix::net::UnixDatagram;
    let dir = tempfile::tempdir().unwrap();
    let socket_path = dir.path().join("notify.sock");
    let socket = UnixDatagram::bind(&socket_path).unwrap();
    socket
        .set_read_timeout(Some(std::time::Duration::from_secs(60)))
        .unwrap();
    let mut serve = common::cellbus()
        .args(["serve", "--listen", "127.0.0.1:0", "--data"])
        .arg(dir.path().join("data"))
        .env("NOTIFY_SOCKET", &socket_path)
        .env("WATCHDOG_USEC", "2000000")
        .env_remove("WATCHDOG_PID")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("cellbus runs");
    let next = || {
        let mut buffer = [0u8; 1024];
        let n = socket
            .recv(&mut buffer)
            .expect("a notification within a minute");
        String::from_utf8_lossy(&buffer[..n]).into_owned()
    };
    let ready = next();
    assert!(
        ready.starts_with("READY=1\nSTATUS=listening on http://127.0.0.1:"),
        "{ready:?}"
    );
    assert_eq!(next(), "WATCHDOG=1\n");
    assert_eq!(next(), "WATCHDOG=1\n", "again, a period later");
    let status = std::process::Command::new("kill")
        .args(["-TERM", &serve.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let stopping = loop {
        let message = next();
        if message != "WATCHDOG=1\n" {
            break message;
        }
    };
    assert_eq!(stopping, "STOPPING=1\n");
    assert!(serve.wait().unwrap().success(), "a clean stop");
}

/// Starts `cellbus ARGS…` at its default log level (RUST_LOG left out), its standard
/// output dropped; the process and its log (standard error).
fn logging(args: &[&std::ffi::OsStr]) -> (std::process::Child, std::process::ChildStderr) {
    let mut child = common::cellbus()
        .args(args)
        .env_remove("RUST_LOG")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("cellbus runs");
    let stderr = child.stderr.take().expect("piped");
    (child, stderr)
}
