//! `cellbus jbc`, `cellbus sim jbc` and `cellbus decode jbc`, end to end through the binary.

mod common;

use common::{Sim, assert_stderr_has, assert_stdout_has, run, stderr, stdout};

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
