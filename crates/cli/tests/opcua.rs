//! `cellbus serve --opcua` checked by an OPC UA client that is not ours: Python's asyncua
//! (`crates/cli/tests/opcua/opcua_check.py`), against the demo cell.

mod common;

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use common::require_python;

/// The version scripts/test installs.
const PIP: &str = "asyncua==2.1.0";
/// Ours: the script's own limit (120 s) and Python's start.
const LIMIT: Duration = Duration::from_secs(180);

fn script() -> String {
    format!("{}/tests/opcua/opcua_check.py", env!("CARGO_MANIFEST_DIR"))
}

/// Fails (never skips) when python3 or asyncua is missing: scripts/test installs it.
fn require_asyncua() {
    require_python(
        "import asyncua",
        "OPC UA interoperability test",
        "asyncua",
        &format!("run scripts/test, which installs it, or: python3 -m pip install {PIP}"),
    );
}

/// `cellbus serve` on the demo cell with OPC UA, killed when dropped.
struct Served {
    child: Child,
    http: String,
    opcua: String,
}

impl Served {
    fn start(data: &std::path::Path, args: &[&str], token: Option<&str>) -> Served {
        let mut command = common::cellbus();
        command
            .args([
                "serve",
                "--listen",
                "127.0.0.1:0",
                "--opcua",
                "127.0.0.1:0",
                "--data",
            ])
            .arg(data)
            .args(args)
            .env_remove("CELLBUS_TOKEN")
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit());
        if let Some(token) = token {
            command.env("CELLBUS_TOKEN", token);
        }
        let mut child = command.spawn().expect("cellbus runs");
        let mut stdout = BufReader::new(child.stdout.take().expect("piped"));
        let mut line = |what: &str| {
            let mut text = String::new();
            stdout.read_line(&mut text).expect("a line");
            text.trim_end()
                .strip_prefix(what)
                .unwrap_or_else(|| panic!("a line `{what}…`, got {text:?}"))
                .to_owned()
        };
        let http = line("listening on http://");
        let opcua = line("opcua on ");
        Served { child, http, opcua }
    }
}

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Starts the script with `args`, its standard output piped and its errors to `stderr`.
fn spawn_script(args: &[&str], stderr: Stdio) -> std::process::Child {
    Command::new("python3")
        .arg(script())
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(stderr)
        .spawn()
        .expect("python3 runs")
}

/// Starts the script with `args`; its standard output's lines as they come.
fn script_lines(args: &[&str]) -> (std::process::Child, std::sync::mpsc::Receiver<String>) {
    let mut child = spawn_script(args, Stdio::inherit());
    let (tx, rx) = std::sync::mpsc::channel();
    let stdout = child.stdout.take().expect("piped");
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    (child, rx)
}

/// Runs the script with `args`; panics with its output unless it succeeds.
fn run_script(args: &[&str]) -> String {
    let mut child = spawn_script(args, Stdio::piped());
    let (tx, rx) = std::sync::mpsc::channel();
    let mut stdout = child.stdout.take().expect("piped");
    let mut stderr = child.stderr.take().expect("piped");
    std::thread::spawn(move || {
        let mut out = String::new();
        let mut err = String::new();
        let _ = std::io::Read::read_to_string(&mut stdout, &mut out);
        let _ = std::io::Read::read_to_string(&mut stderr, &mut err);
        let _ = tx.send((out, err));
    });
    let Ok((out, err)) = rx.recv_timeout(LIMIT) else {
        let _ = child.kill();
        panic!("the asyncua script did not finish in {LIMIT:?}");
    };
    let status = child.wait().expect("python3 ends");
    assert!(status.success(), "the asyncua script failed:\n{out}\n{err}");
    out
}

#[test]
fn an_independent_opcua_client_browses_reads_gets_every_stored_change_on_a_subscription_shows_in_healthz_and_is_refused_writes()
 {
    require_asyncua();
    let data = tempfile::tempdir().expect("a temporary directory");
    let served = Served::start(data.path(), &[], None);
    let out = run_script(&["read", &served.opcua, &served.http]);
    for expected in [
        "endpoints, all at",
        "devices and",
        "enumerations with EnumValues",
        "Production folders)",
        "points read Good",
        "/healthz shows the OPC UA session",
        "an absolute deadband held back",
        "as /api/history holds them",
        "BadUserAccessDenied",
    ] {
        assert!(out.contains(expected), "{expected:?} not in:\n{out}");
    }
}

#[test]
fn a_trusted_client_certificate_and_user_write_in_range_are_audited_with_the_client_address_raise_an_opcua_event_and_history_pages_match_the_api()
 {
    require_asyncua();
    let data = tempfile::tempdir().expect("a temporary directory");
    let token = "opcua-test-secret";
    let served = Served::start(data.path(), &["--allow-writes"], Some(token));
    let dir = data.path().to_str().expect("a UTF-8 path");
    let out = run_script(&["write", &served.opcua, &served.http, dir, token]);
    for expected in [
        "untrusted client certificate was refused",
        "SignAndEncrypt",
        "BadOutOfRange",
        "written to",
        "audit log",
        "from 127.0.0.1:",
        "the write's event arrived on the device object",
        "the write's event arrived on the Server object",
        "the write's event carries its kind and fields",
        "HistoryRead raw",
        "numValuesPerNode 2",
        "returnBounds",
        "HistoryRead Average",
    ] {
        assert!(out.contains(expected), "{expected:?} not in:\n{out}");
    }
}

/// A cell of one simulated JBC station (`sim`'s endpoint) with `opcua` as its `[opcua]`
/// table, written in `dir`.
fn station_cell(dir: &std::path::Path, endpoint: &str, opcua: &str) -> std::path::PathBuf {
    let path = dir.join("cell.toml");
    std::fs::write(
        &path,
        format!(
            "[[line]]\nname = \"rework\"\nendpoint = \"{endpoint}\"\n\n\
             [[line.device]]\nid = \"jbc1\"\nname = \"Station\"\nprotocol = \"jbc\"\naddress = 1\n\
             timeout = \"200ms\"\npoll = {{ live = \"1s\", settings = \"10s\", info = \"1m\" }}\n\n\
             [opcua]\n{opcua}\n"
        ),
    )
    .expect("the config is written");
    path
}

/// A simulated JBC station and `cellbus serve` of [`station_cell`] with `opcua` as its
/// `[opcua]` table.
fn station_served(dir: &std::path::Path, opcua: &str) -> (common::Sim, Served) {
    let sim = common::Sim::start(&["jbc", "--listen", "127.0.0.1:0"]);
    let config = station_cell(dir, &sim.endpoint, opcua);
    let config = config.to_str().expect("a UTF-8 path");
    let served = Served::start(dir, &["--config", config], None);
    (sim, served)
}

#[test]
fn a_device_that_stops_answering_turns_its_opcua_values_bad_without_a_value() {
    require_asyncua();
    let data = tempfile::tempdir().expect("a temporary directory");
    let mut sim = Some(common::Sim::start(&["jbc", "--listen", "127.0.0.1:0"]));
    let endpoint = sim.as_ref().map(|s| s.endpoint.clone()).unwrap_or_default();
    let config = station_cell(
        data.path(),
        &endpoint,
        "security = [\"None\"]\nanonymous = true",
    );
    let config = config.to_str().expect("a UTF-8 path");
    let served = Served::start(data.path(), &["--config", config], None);

    let (mut child, rx) = script_lines(&["down", &served.opcua, "jbc1", "air_temperature"]);
    let first = rx.recv_timeout(LIMIT).expect("the script subscribes");
    assert_eq!(first, "subscribed");
    // The station is switched off: the gateway marks its points bad.
    drop(sim.take());
    let said = rx
        .recv_timeout(LIMIT)
        .expect("the script sees the value turn bad");
    assert!(said.contains("turned Bad"), "{said}");
    let status = child.wait().expect("python3 ends");
    assert!(status.success(), "the asyncua script failed after: {said}");
}

#[test]
fn an_independent_opcua_client_gets_an_alarm_event_and_acknowledges_and_shelves_it_as_its_user_which_the_alarm_journal_shows()
 {
    require_asyncua();
    let data = tempfile::tempdir().expect("a temporary directory");
    let mut sim = Some(common::Sim::start(&["jbc", "--listen", "127.0.0.1:0"]));
    let endpoint = sim.as_ref().map(|s| s.endpoint.clone()).unwrap_or_default();
    // Anonymous reading on None, the user `operator` (its password the write token) on
    // Basic256Sha256; the client's certificate trusted as it comes.
    let config = station_cell(
        data.path(),
        &endpoint,
        "security = [\"None\", \"Basic256Sha256 SignAndEncrypt\"]\nanonymous = true\n\
         trust_all_clients = true\n\
         [[opcua.user]]\nname = \"operator\"\npassword_env = \"CELLBUS_TOKEN\"\nwrite = true",
    );
    let config = config.to_str().expect("a UTF-8 path");
    let token = "opcua-alarm-secret";
    let served = Served::start(
        data.path(),
        &["--config", config, "--allow-writes"],
        Some(token),
    );

    let (mut child, rx) = script_lines(&["alarm", &served.opcua, &served.http, token, "jbc1"]);
    let mut out = Vec::new();
    loop {
        let line = rx.recv_timeout(LIMIT).expect("the script subscribes");
        let subscribed = line == "subscribed";
        out.push(line);
        if subscribed {
            break;
        }
    }
    // The station is switched off: jbc1:down is raised.
    drop(sim.take());
    script_said(
        &mut child,
        &rx,
        out,
        &[
            "refused to an anonymous session: BadUserAccessDenied",
            "jbc1:down in jbc1's Alarms folder",
            "the alarm_raised event of jbc1:down arrived",
            "State unacknowledged",
            "Acknowledge answered acknowledged",
            "the alarm_changed event carries",
            "BadConditionBranchAlreadyAcked",
            "BadInvalidArgument",
            "Shelve",
            "BadConditionNotShelved",
            "BadShelvingTimeOutOfRange",
            "the alarm journal has the acknowledgement",
        ],
    );
    // The journal as HTTP gives it, read here too: the acknowledgement with its comment,
    // by the OPC UA user from the client's address.
    let (code, body) = common::http_get(&served.http, "/api/alarms/journal?alarm=jbc1:down");
    assert_eq!(code, 200, "{body}");
    let journal: serde_json::Value = serde_json::from_str(&body).expect("JSON");
    let entries = journal["entries"].as_array().expect("entries");
    let acknowledged = entries
        .iter()
        .find(|e| {
            e["kind"] == "alarm_changed" && e["changes"] == serde_json::json!(["acknowledged"])
        })
        .unwrap_or_else(|| panic!("no acknowledgement in {body}"));
    assert_eq!(acknowledged["comment"], "seen by asyncua", "{acknowledged}");
    let by = acknowledged["by"].as_str().expect("by");
    assert!(
        by.starts_with("opcua user operator from 127.0.0.1:"),
        "{by}"
    );
    assert_eq!(acknowledged["acknowledged"], true, "{acknowledged}");
}

#[test]
fn anonymous_sessions_are_refused_when_the_config_says_so() {
    require_asyncua();
    let data = tempfile::tempdir().expect("a temporary directory");
    let (_sim, served) = station_served(data.path(), "security = [\"None\"]\nanonymous = false");
    let out = run_script(&["anonymous-refused", &served.opcua]);
    assert!(out.contains("anonymous session was refused"), "{out}");
}

#[test]
fn never_activated_sessions_beyond_the_servers_limit_are_closed_and_a_legitimate_client_still_gets_in()
 {
    require_asyncua();
    let data = tempfile::tempdir().expect("a temporary directory");
    // The demo cell on loopback offers security None and anonymous reading: anyone may
    // create sessions.
    let served = Served::start(data.path(), &[], None);
    let out = run_script(&["flood", &served.opcua, &served.http, "120"]);
    for expected in [
        "refused beyond the per-address cap",
        "a legitimate client connected, read and subscribed",
        "waiting sessions closed and counted",
    ] {
        assert!(out.contains(expected), "{expected:?} not in:\n{out}");
    }
}

#[test]
fn monitored_items_beyond_the_cap_are_refused_with_bad_too_many_monitored_items() {
    require_asyncua();
    let data = tempfile::tempdir().expect("a temporary directory");
    let (_sim, served) = station_served(
        data.path(),
        "security = [\"None\"]\nanonymous = true\nmax_monitored_items = 300",
    );
    let out = run_script(&["items", &served.opcua, &served.http, "300"]);
    for expected in [
        "300 made, 20 refused BadTooManyMonitoredItems",
        "made room for 10 more",
    ] {
        assert!(out.contains(expected), "{expected:?} not in:\n{out}");
    }
}

/// A cell of JBC stations on unreachable endpoints (their nodes are there while they are
/// down), one line each: `(line, device, name)`, with anonymous OPC UA on security None.
fn cell_of(stations: &[(&str, &str, &str)]) -> String {
    let mut text = String::from("[opcua]\nsecurity = [\"None\"]\nanonymous = true\n");
    for (port, (line, device, name)) in (1..).zip(stations) {
        text.push_str(&format!(
            "\n[[line]]\nname = \"{line}\"\nendpoint = \"tcp://127.0.0.1:{port}\"\n\n\
             [[line.device]]\nid = \"{device}\"\nname = \"{name}\"\nprotocol = \"jbc\"\n"
        ));
    }
    text
}

#[cfg(unix)]
#[test]
fn after_a_configuration_reload_an_opcua_client_finds_the_added_device_and_the_changed_one_as_it_now_is_and_the_removed_one_nowhere()
 {
    require_asyncua();
    let data = tempfile::tempdir().expect("a temporary directory");
    let config = data.path().join("cell.toml");
    let before = cell_of(&[
        ("a", "jbc_a", "Station A"),
        ("b", "jbc_b", "Station B"),
        ("c", "jbc_c", "Station C"),
    ]);
    std::fs::write(&config, before).expect("the config is written");
    let path = config.to_str().expect("a UTF-8 path");
    let served = Served::start(data.path(), &["--config", path], None);

    let (mut child, rx) = script_lines(&[
        "reload",
        &served.opcua,
        "jbc_b",
        "jbc_d",
        "jbc_c",
        "Rework station C",
        "a,c,d",
    ]);
    let mut out = Vec::new();
    loop {
        let line = rx.recv_timeout(LIMIT).expect("the script browses");
        let browsed = line == "browsed";
        out.push(line);
        if browsed {
            break;
        }
    }
    // Line b and its station go, station C is renamed, line d comes with station D.
    let after = cell_of(&[
        ("a", "jbc_a", "Station A"),
        ("c", "jbc_c", "Rework station C"),
        ("d", "jbc_d", "Station D"),
    ]);
    std::fs::write(&config, after).expect("the config is rewritten");
    let hup = Command::new("kill")
        .args(["-HUP", &served.child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(hup.success(), "SIGHUP was sent");
    script_said(
        &mut child,
        &rx,
        out,
        &[
            "its Production and Alarms folders among them",
            "the config_reloaded event arrived",
            "jbc_d is found after the reload",
            "jbc_c is described as 'Rework station C'",
            "the Gateway's Lines are a,c,d",
            "a read, a write and a monitored item are refused BadNodeIdUnknown",
        ],
    );
}

/// Takes the asyncua script's remaining lines (for at most [`LIMIT`]) after `out`, waits
/// for it to end, and checks that it succeeded and printed each of `expected`.
fn script_said(
    child: &mut std::process::Child,
    rx: &std::sync::mpsc::Receiver<String>,
    mut out: Vec<String>,
    expected: &[&str],
) {
    let deadline = std::time::Instant::now() + LIMIT;
    while let Ok(line) =
        rx.recv_timeout(deadline.saturating_duration_since(std::time::Instant::now()))
    {
        out.push(line);
    }
    let status = child.wait().expect("python3 ends");
    let out = out.join("\n");
    assert!(status.success(), "the asyncua script failed:\n{out}");
    for expected in expected {
        assert!(out.contains(expected), "{expected:?} not in:\n{out}");
    }
}
