//! `cellbus jbc`, `cellbus sim jbc` and `cellbus decode jbc`, end to end through the binary.

mod common;

use std::io::BufRead;
use std::time::Duration;

use common::{
    Sim, assert_stderr_has, assert_stdout_has, cellbus, interrupt, run, run_within, spawn_piped,
    stderr, stdout,
};

fn jbc(sim: &Sim, args: &[&str]) -> std::process::Output {
    sim.client("jbc", args)
}

#[test]
fn sim_prints_its_tcp_address_first() {
    let sim = Sim::start(&["jbc", "--listen", "127.0.0.1:0"]);
    sim.assert_listens_on("tcp://127.0.0.1:");
}

#[test]
fn read_prints_the_value_with_its_unit() {
    let sim = Sim::start(&["jbc", "--listen", "127.0.0.1:0"]);
    let out = jbc(&sim, &["read", "SMN"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_stdout_has(&out, "JTSE");

    let out = jbc(&sim, &["write", "ST1", "350"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = jbc(&sim, &["read", "ST1"]);
    assert_stdout_has(&out, "350 °C");
}

#[test]
fn read_json_is_one_object_with_code_value_and_unit() {
    let sim = Sim::start(&["jbc", "--listen", "127.0.0.1:0"]);
    assert!(jbc(&sim, &["write", "ST1", "360"]).status.success());
    let out = jbc(&sim, &["--json", "read", "ST1"]);
    let value: serde_json::Value =
        serde_json::from_str(stdout(&out).trim()).expect("one JSON object");
    assert_eq!(
        value,
        serde_json::json!({"code": "ST1", "value": 360, "unit": "°C"})
    );

    let out = jbc(&sim, &["read", "SMN", "--json"]);
    let value: serde_json::Value =
        serde_json::from_str(stdout(&out).trim()).expect("one JSON object");
    assert_eq!(value["value"], "JTSE");
}

#[test]
fn write_json_acknowledges() {
    let sim = Sim::start(&["jbc", "--listen", "127.0.0.1:0"]);
    let out = jbc(&sim, &["--json", "write", "SF1", "50"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let value: serde_json::Value =
        serde_json::from_str(stdout(&out).trim()).expect("one JSON object");
    assert_eq!(
        value,
        serde_json::json!({"code": "SF1", "value": 50, "ok": true})
    );
}

#[test]
fn options_go_before_or_after_the_subcommand() {
    let sim = Sim::start(&["jbc", "--listen", "127.0.0.1:0"]);
    let before = run(&["jbc", "--endpoint", &sim.endpoint, "--json", "read", "SMN"]);
    let after = run(&["jbc", "read", "SMN", "--json", "--endpoint", &sim.endpoint]);
    assert!(after.status.success(), "{}", stderr(&after));
    assert_eq!(stdout(&before), stdout(&after));
    assert_stdout_has(&after, r#""value":"JTSE""#);

    let out = run(&["jbc", "read", "SMN"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert_stderr_has(&out, "--endpoint URL is needed");
}

#[test]
fn watch_stops_after_count_rounds_or_for_a_while() {
    let sim = Sim::start(&["jbc", "--listen", "127.0.0.1:0"]);
    let limit = Duration::from_secs(60);
    let endpoint = sim.endpoint.as_str();
    let args = [
        "jbc",
        "--endpoint",
        endpoint,
        "watch",
        "--interval",
        "100ms",
    ];
    let counted = run_within(&[&args[..], &["--count", "3"]].concat(), limit);
    assert!(counted.status.success(), "{}", stderr(&counted));
    let lines: Vec<String> = stdout(&counted).lines().map(str::to_owned).collect();
    assert_eq!(lines.len(), 1 + 3, "a header and 3 rounds: {lines:?}");
    assert!(lines[1].starts_with("0.0 s "), "{lines:?}");

    let timed = run_within(&[&args[..], &["--for", "300ms", "--json"]].concat(), limit);
    assert!(timed.status.success(), "{}", stderr(&timed));
    let rounds = stdout(&timed).lines().count();
    // Rounds start at 0, 100 and 200 ms; a slow machine may start fewer before the end.
    assert!((1..=3).contains(&rounds), "{}", stdout(&timed));
}

#[test]
fn ctrl_c_ends_a_watch_after_its_round_with_exit_0() {
    let sim = Sim::start(&["jbc", "--listen", "127.0.0.1:0"]);
    let args = [
        "jbc",
        "--endpoint",
        &sim.endpoint,
        "watch",
        "--interval",
        "100ms",
    ];
    let mut child = spawn_piped(&args);
    let mut out = std::io::BufReader::new(child.stdout.take().expect("stdout is piped"));
    let mut lines = Vec::new();
    for _ in 0..2 {
        let mut line = String::new();
        out.read_line(&mut line).expect("a line");
        lines.push(line);
    }
    assert!(lines[1].starts_with("0.0 s "), "{lines:?}");
    interrupt(child.id());
    let status = child.wait().expect("the watch ends");
    assert!(status.success(), "{status:?}");
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut out, &mut rest).expect("the rest of stdout");
    assert!(rest.is_empty() || rest.ends_with('\n'), "{rest:?}");
}

#[test]
fn a_relative_endpoint_path_is_the_serial_device_in_the_working_directory() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("pty")).unwrap();
    let pty = dir.path().join("pty/jbc1");
    let _sim = Sim::start(&["jbc", "--pty", pty.to_str().unwrap()]);
    // PTYs run at 8N1 whatever is asked (the kernel ignores parity).
    for endpoint in ["pty/jbc1?framing=8N1", "./pty/jbc1?framing=8N1"] {
        let out = cellbus()
            .args(["jbc", "--endpoint", endpoint, "read", "SMN"])
            .current_dir(dir.path())
            .output()
            .expect("cellbus runs");
        assert!(out.status.success(), "{endpoint}: {}", stderr(&out));
        assert_stdout_has(&out, "JTSE");
    }

    let out = cellbus()
        .args(["jbc", "--endpoint", "serial://pty/jbc1", "read", "SMN"])
        .current_dir(dir.path())
        .output()
        .expect("cellbus runs");
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert_stderr_has(&out, "write serial:///pty/jbc1 (three slashes)");
    assert_stderr_has(&out, "or pty/jbc1 without serial://");
}

#[test]
fn a_refused_write_exits_1_with_the_reason_in_words() {
    let sim = Sim::start(&["jbc", "--listen", "127.0.0.1:0"]);
    let out = jbc(&sim, &["write", "ST1", "900"]);
    assert_eq!(out.status.code(), Some(1));
    assert_stderr_has(&out, "station refused WST1 00900: out of range (00003)");
}

#[test]
fn a_silent_station_exits_1_naming_endpoint_address_and_attempts() {
    // The simulated station is at 01; nobody answers for 07.
    let sim = Sim::start(&["jbc", "--listen", "127.0.0.1:0"]);
    let out = jbc(
        &sim,
        &[
            "--address",
            "07",
            "--timeout",
            "100ms",
            "--retries",
            "1",
            "read",
            "AT1",
        ],
    );
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(
        err.contains(&sim.endpoint) && err.contains("station 07") && err.contains("2 attempts"),
        "{err}"
    );
}

#[test]
fn bad_arguments_exit_2_before_touching_the_line() {
    // No simulator: the endpoint is never opened.
    let out = run(&["jbc", "--endpoint", "tcp://127.0.0.1:9", "read", "XYZ"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert_stderr_has(&out, "XYZ");
    let out = run(&["jbc", "--endpoint", "bogus://x", "read", "ST1"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    let out = run(&[
        "jbc",
        "--endpoint",
        "tcp://127.0.0.1:9",
        "--address",
        "100",
        "read",
        "ST1",
    ]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
}

#[test]
fn status_reads_every_value_of_the_station() {
    let sim = Sim::start(&["jbc", "--listen", "127.0.0.1:0"]);
    let out = jbc(&sim, &["status", "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let value: serde_json::Value =
        serde_json::from_str(stdout(&out).trim()).expect("one JSON object");
    for code in [
        "ST1", "SF1", "AT1", "ET1", "PS1", "CT1", "SMN", "MAT", "MIT", "SER", "OH1", "TC1",
    ] {
        assert!(
            value.get(code).is_some_and(|v| v.get("value").is_some()),
            "{code} missing in {value}"
        );
    }
    let out = jbc(&sim, &["status"]);
    assert!(stdout(&out).lines().count() >= 20, "{}", stdout(&out));
}

#[test]
fn the_form_without_addresses_works_end_to_end() {
    let sim = Sim::start(&["jbc", "--listen", "127.0.0.1:0", "--no-address"]);
    let out = jbc(&sim, &["--no-address", "read", "SMN"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stdout(&out).contains("JTSE"));
}

#[test]
fn the_client_recovers_through_injected_line_faults() {
    // Late replies are up to 2 s late: keep the timeout short so a late one costs one retry.
    let args = ["--timeout", "300ms", "--retries", "8", "read", "MAT"];
    Sim::client_through_faults("jbc", "11", 5, &args);
}

#[test]
fn the_simulator_serves_a_pty_that_the_client_opens_as_a_serial_port() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ttyJBC");
    let path_text = path.to_str().unwrap();
    let sim = Sim::start(&["jbc", "--pty", path_text]);
    assert_eq!(sim.endpoint, path_text);
    // PTYs run at 8N1 whatever is asked (the kernel ignores parity).
    let url = format!("serial://{path_text}?baud=19200&framing=8N1");
    let out = run(&["jbc", "--endpoint", &url, "read", "SMN"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stdout(&out).contains("JTSE"));
}

#[test]
fn decode_annotates_frames_and_marks_garbage_and_bad_checks() {
    // A read of ST1 from robot 00 to station 01, garbage, then the same frame with a bad BCC.
    let good = frame(b"0001RST1");
    let mut bad = good.clone();
    *bad.last_mut().unwrap() ^= 0xFF;
    let mut capture = good.clone();
    capture.extend_from_slice(&[0xFF, 0x55]);
    capture.extend_from_slice(&bad);
    let hex: Vec<String> = capture.iter().map(|b| format!("{b:02X}")).collect();
    let mut args = vec!["decode", "jbc"];
    args.extend(hex.iter().map(String::as_str));
    let out = run(&args);
    assert_eq!(out.status.code(), Some(1), "garbage makes the exit code 1");
    let text = stdout(&out);
    assert!(text.contains("selected air temperature"), "{text}");
    assert!(text.contains("dropped"), "{text}");
    assert!(text.to_lowercase().contains("bcc"), "{text}");
}

#[test]
fn decode_reads_a_capture_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("capture.bin");
    std::fs::write(&path, frame(b"0100AST100350")).unwrap();
    let out = run(&["decode", "jbc", "--file", path.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stdout(&out));
    assert_stdout_has(&out, "350");
}

/// STX + body + ETX + BCC (XOR of everything before it).
fn frame(body: &[u8]) -> Vec<u8> {
    let mut bytes = vec![0x02];
    bytes.extend_from_slice(body);
    bytes.push(0x03);
    bytes.push(bytes.iter().fold(0, |a, b| a ^ b));
    bytes
}

#[test]
fn no_address_with_an_address_is_refused_instead_of_dropping_the_address() {
    let out = run(&[
        "jbc",
        "--endpoint",
        "tcp://127.0.0.1:9",
        "--no-address",
        "--address",
        "05",
        "read",
        "ST1",
    ]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert_stderr_has(&out, "'--no-address' cannot be used with '--address");
}
