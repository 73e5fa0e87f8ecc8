//! `cellbus modbus`, `cellbus cross`, `cellbus sim cross|modbus` and `cellbus decode
//! modbus`, end to end through the binary.

mod common;

use std::process::{Output, Stdio};
use std::time::Duration;

use common::{
    Sim, assert_stderr_has, assert_stdout_has, require_python, run, run_within, start_listening,
    stderr, stdout,
};
use serde_json::{Value, json};

fn modbus(sim: &Sim, unit: &str, args: &[&str]) -> Output {
    let mut all = vec!["modbus", "--endpoint", &sim.endpoint, "--unit", unit];
    all.extend_from_slice(args);
    run(&all)
}

fn cross(sim: &Sim, args: &[&str]) -> Output {
    sim.client("cross", args)
}

fn json_of(output: &Output) -> Value {
    serde_json::from_str(stdout(output).trim())
        .unwrap_or_else(|e| panic!("one JSON object expected ({e}): {}", stdout(output)))
}

#[test]
fn sim_cross_prints_its_tcp_address_first() {
    let sim = Sim::start(&["cross", "--listen", "127.0.0.1:0"]);
    sim.assert_listens_on("tcp://127.0.0.1:");
}

#[test]
fn cross_status_says_what_feeds_the_load_the_alarms_and_the_measures_with_units() {
    let sim = Sim::start(&["cross", "--listen", "127.0.0.1:0", "--seed", "3"]);
    let out = cross(&sim, &["status"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    for expected in [
        "unit 2",
        "load: supplied by source 1 (S1) through static switch S1-SW",
        "alarms: none",
        " Hz",
        " kVA",
        " V",
        " A",
        "JBUS protocol revision 5",
    ] {
        assert!(text.contains(expected), "{expected:?} missing in:\n{text}");
    }
}

#[test]
fn cross_status_json_names_the_source_and_gives_every_measure_with_its_unit() {
    let sim = Sim::start(&["cross", "--listen", "127.0.0.1:0", "--unit", "7"]);
    let out = cross(&sim, &["--unit", "7", "status", "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let value = json_of(&out);
    assert_eq!(value["unit"], 7);
    assert_eq!(value["source"], "S1");
    assert_eq!(value["alarms"], json!([]));
    assert_eq!(value["measures"]["load_power"]["unit"], "kVA");
    assert_eq!(value["measures"]["s1_frequency"]["unit"], "Hz");
    assert_eq!(value["ratings"]["protocol_revision"], 5);
    let volts = value["measures"]["s1_voltage"]["u"]
        .as_f64()
        .expect("a number");
    assert!((220.0..240.0).contains(&volts), "{volts}");
    assert_eq!(value["mimic"]["lamps"]["IOUT"], "on");
}

#[test]
fn cross_watch_prints_a_transfer_when_the_preferred_source_fails_and_returns() {
    let sim = Sim::start(&[
        "cross",
        "--listen",
        "127.0.0.1:0",
        "--cycle-outage",
        "400ms",
    ]);
    let out = cross_watch(&sim, &["--changes", "2"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    assert!(text.contains("S1 failure"), "{text}");
    assert!(
        text.contains("load supplied by source 2 (S2) through static switch S2-SW"),
        "{text}"
    );
    assert!(
        text.contains("load supplied by source 1 (S1) through static switch S1-SW"),
        "{text}"
    );
}

#[test]
fn modbus_reads_a_cross_area_in_text_and_json_with_hex_addresses() {
    let sim = Sim::start(&["cross", "--listen", "127.0.0.1:0"]);
    let out = modbus(&sim, "2", &["read-holding", "0x2E", "1"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(stdout(&out).trim(), "46 (0x002E) =     5 (0x0005)");
    let out = modbus(&sim, "2", &["--json", "read-holding", "30", "17"]);
    let value = json_of(&out);
    assert_eq!(value["unit"], 2);
    assert_eq!(value["address"], 30);
    assert_eq!(value["values"].as_array().map(Vec::len), Some(17));
    assert_eq!(value["values"][16], 5);
}

#[test]
fn exceptions_exit_1_with_their_number_and_meaning() {
    let sim = Sim::start(&["cross", "--listen", "127.0.0.1:0"]);
    let out = modbus(&sim, "2", &["read-input", "0", "1"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains("exception 1 (illegal function"),
        "{}",
        stderr(&out)
    );
    let out = modbus(&sim, "2", &["read-holding", "0x12", "2"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains("exception 2 (illegal data address"),
        "{}",
        stderr(&out)
    );
    let out = modbus(&sim, "2", &["--json", "write-register", "0", "1"]);
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(
        json_of(&out)["exception"]["code"],
        1,
        "a CROSS writes nothing"
    );
}

#[test]
fn every_read_and_write_form_works_against_the_generic_simulator() {
    let sim = Sim::start(&["modbus", "--listen", "127.0.0.1:0"]);
    let ok = |args: &[&str]| {
        let out = modbus(&sim, "1", args);
        assert!(out.status.success(), "{args:?}: {}", stderr(&out));
        out
    };
    let out = ok(&["write-register", "0x10", "-2"]);
    assert_stdout_has(
        &out,
        "unit 1 acknowledged: write register 16 (0x0010) = 65534",
    );
    ok(&["write-registers", "17", "1", "0x0002", "3"]);
    let out = ok(&["--json", "read-holding", "16", "4"]);
    assert_eq!(
        json_of(&out),
        json!({"unit": 1, "address": 16, "values": [65534, 1, 2, 3]})
    );
    ok(&["write-coil", "5", "on"]);
    ok(&["write-coils", "6", "1", "0", "1"]);
    let out = ok(&["--json", "read-coils", "4", "5"]);
    assert_eq!(
        json_of(&out),
        json!({"unit": 1, "address": 4, "values": [false, true, true, false, true]})
    );
    ok(&["write-coil", "5", "off"]);
    let out = ok(&["read-coils", "5", "1"]);
    assert_eq!(stdout(&out).trim(), "5 (0x0005) = 0 (off)");
    let out = ok(&["--json", "read-discrete", "0", "3"]);
    assert_eq!(json_of(&out)["values"], json!([false, false, false]));
    let out = ok(&["--json", "read-input", "0x100", "2"]);
    assert_eq!(json_of(&out)["values"], json!([0, 0]));
    let out = ok(&["--json", "write-registers", "100", "7", "8"]);
    assert_eq!(
        json_of(&out),
        json!({"unit": 1, "address": 100, "values": [7, 8]})
    );
}

#[test]
fn a_map_file_defines_the_simulators_tables_and_unit() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("pump.map");
    std::fs::write(
        &path,
        "# a pump\nunit 17\nholding 0 = 100 200\ninput 5 = 7\ncoil 3 = 1\n",
    )
    .unwrap();
    let sim = Sim::start(&[
        "modbus",
        "--listen",
        "127.0.0.1:0",
        "--map",
        path.to_str().unwrap(),
    ]);
    let out = modbus(&sim, "17", &["--json", "read-holding", "0", "2"]);
    assert_eq!(json_of(&out)["values"], json!([100, 200]));
    let out = modbus(&sim, "17", &["read-holding", "0", "3"]);
    assert_eq!(out.status.code(), Some(1));
    assert_stderr_has(&out, "exception 2");
    let out = modbus(&sim, "17", &["--json", "read-input", "5", "1"]);
    assert_eq!(json_of(&out)["values"], json!([7]));

    let sim = Sim::start(&[
        "modbus",
        "--listen",
        "127.0.0.1:0",
        "--map",
        path.to_str().unwrap(),
        "--unit",
        "30",
    ]);
    let out = modbus(&sim, "30", &["--json", "read-coils", "3", "1"]);
    assert_eq!(json_of(&out)["values"], json!([true]));
}

/// A generic simulator serving `map` (unit 1).
fn sim_with_map(dir: &tempfile::TempDir, map: &str) -> Sim {
    let path = dir.path().join("typed.map");
    std::fs::write(&path, map).unwrap();
    Sim::start(&[
        "modbus",
        "--listen",
        "127.0.0.1:0",
        "--map",
        path.to_str().unwrap(),
    ])
}

#[test]
fn typed_values_in_a_map_read_back_with_their_type_and_order() {
    let dir = tempfile::tempdir().unwrap();
    let sim = sim_with_map(
        &dir,
        "holding 0x0100 float32 CDAB = 229.7\n\
         holding 0x0110 int32 = -2 70000\n\
         holding 0x0120 string:4 = \"PUMP 7\"\n\
         holding 0x0130 uint64 DCBA = 0x0102030405060708\n\
         holding 0x0140 = 0x0009\n\
         input 0x10 float64 = 1.5 -2.25\n",
    );
    let read = |args: &[&str]| {
        let out = modbus(&sim, "1", args);
        assert!(out.status.success(), "{args:?}: {}", stderr(&out));
        out
    };
    let out = read(&[
        "--json",
        "read-holding",
        "0x100",
        "1",
        "--type",
        "float32",
        "--order",
        "CDAB",
    ]);
    assert_eq!(
        json_of(&out),
        json!({"unit": 1, "address": 256, "type": "float32", "values": [229.7]})
    );
    // The registers as they stand: 229.7 = 0x4365B333, words swapped.
    let out = read(&["--json", "read-holding", "0x100", "2"]);
    assert_eq!(json_of(&out)["values"], json!([0xB333, 0x4365]));
    let out = read(&[
        "read-holding",
        "0x100",
        "1",
        "--type",
        "float32",
        "--order",
        "cdab",
    ]);
    assert_eq!(stdout(&out).trim(), "256 (0x0100) = 229.7");
    let out = read(&["--json", "read-holding", "0x110", "2", "--type", "int32"]);
    assert_eq!(json_of(&out)["values"], json!([-2, 70000]));
    let out = read(&["read-holding", "0x110", "2", "--type", "int32"]);
    assert_eq!(
        stdout(&out),
        "  272 (0x0110) = -2\n  274 (0x0112) = 70000\n"
    );
    let out = read(&["--json", "read-holding", "0x120", "1", "--type", "string:4"]);
    assert_eq!(json_of(&out)["values"], json!(["PUMP 7"]));
    let out = read(&[
        "--json",
        "read-holding",
        "0x130",
        "1",
        "--type",
        "uint64",
        "--order",
        "DCBA",
    ]);
    assert_eq!(json_of(&out)["values"], json!([0x0102_0304_0506_0708u64]));
    let out = read(&["--json", "read-holding", "0x140", "1", "--type", "bit:3"]);
    assert_eq!(json_of(&out)["values"], json!([true]));
    let out = read(&["--json", "read-holding", "0x140", "1", "--type", "bit:1"]);
    assert_eq!(json_of(&out)["values"], json!([false]));
    let out = read(&["--json", "read-input", "0x10", "2", "--type", "float64"]);
    assert_eq!(
        json_of(&out),
        json!({"unit": 1, "address": 16, "type": "float64", "values": [1.5, -2.25]})
    );
}

#[test]
fn typed_writes_encode_each_value_in_its_registers() {
    let sim = Sim::start(&["modbus", "--listen", "127.0.0.1:0"]);
    let ok = |args: &[&str]| {
        let out = modbus(&sim, "1", args);
        assert!(out.status.success(), "{args:?}: {}", stderr(&out));
        out
    };
    let out = ok(&[
        "--json",
        "write-registers",
        "0x10",
        "--type",
        "int32",
        "-2",
        "70000",
    ]);
    assert_eq!(
        json_of(&out),
        json!({"unit": 1, "address": 16, "values": [-2, 70000]})
    );
    // 70000 = 0x00011170.
    let out = ok(&["--json", "read-holding", "0x10", "4"]);
    assert_eq!(
        json_of(&out)["values"],
        json!([0xFFFF, 0xFFFE, 0x0001, 0x1170])
    );
    let out = ok(&["--json", "read-holding", "0x10", "2", "--type", "int32"]);
    assert_eq!(json_of(&out)["values"], json!([-2, 70000]));

    ok(&[
        "write-registers",
        "0x20",
        "--type",
        "float32",
        "--order",
        "CDAB",
        "229.7",
    ]);
    let out = ok(&["--json", "read-holding", "0x20", "2"]);
    assert_eq!(json_of(&out)["values"], json!([0xB333, 0x4365]));

    ok(&["write-registers", "0x30", "--type", "string:3", "Hi!"]);
    let out = ok(&["--json", "read-holding", "0x30", "3"]);
    assert_eq!(json_of(&out)["values"], json!([0x4869, 0x2100, 0]));
    let out = ok(&["--json", "read-holding", "0x30", "1", "--type", "string:3"]);
    assert_eq!(json_of(&out)["values"], json!(["Hi!"]));

    // --order alone: plain registers with their bytes swapped.
    ok(&["write-registers", "0x40", "--order", "BADC", "0x1234"]);
    let out = ok(&["--json", "read-holding", "0x40", "1"]);
    assert_eq!(json_of(&out)["values"], json!([0x3412]));

    // Registers that hold no value of the type: an error, and with --json the registers
    // and the error on stdout, so a script still sees what came.
    ok(&["write-registers", "0x50", "0xC3A4"]);
    let out = modbus(
        &sim,
        "1",
        &["--json", "read-holding", "0x50", "1", "--type", "string:1"],
    );
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert_stderr_has(&out, "not ASCII");
    let seen = json_of(&out);
    assert_eq!(seen["registers"], json!([0xC3A4]));
    assert_eq!(seen["type"], "string:1");
    assert!(
        seen["error"].as_str().unwrap().contains("byte 0xC3"),
        "{seen}"
    );
}

#[test]
fn bad_types_orders_and_typed_values_exit_2_naming_the_text_and_the_choices() {
    // No simulator: nothing reaches a line.
    let endpoint = "tcp://127.0.0.1:9";
    let usage = |args: &[&str], expected: &[&str]| {
        let mut all = vec!["modbus", "--endpoint", endpoint, "--unit", "1"];
        all.extend_from_slice(args);
        let out = run(&all);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {}", stderr(&out));
        for text in expected {
            assert!(
                stderr(&out).contains(text),
                "{text:?} missing: {}",
                stderr(&out)
            );
        }
    };
    let cases: [(&[&str], &[&str]); 11] = [
        (
            &["read-holding", "0", "1", "--type", "float"],
            &[
                "`float` is not a data type",
                "int16, uint16, int32",
                "float32",
                "string:N",
            ],
        ),
        (
            &[
                "read-holding",
                "0",
                "1",
                "--type",
                "float32",
                "--order",
                "ACBD",
            ],
            &["`ACBD` is not a byte order", "ABCD, CDAB, BADC, DCBA"],
        ),
        (
            &["write-registers", "0", "--type", "int16", "40000"],
            &["40000 does not fit int16 (-32768 to 32767)"],
        ),
        (
            &["write-registers", "0", "--type", "uint16", "-1"],
            &["-1 does not fit uint16"],
        ),
        (
            &["write-registers", "0", "--type", "int32", "1.5"],
            &["1.5 is not a whole number"],
        ),
        (
            &["write-registers", "0", "--type", "string:1", "ABC"],
            &["holds at most 2"],
        ),
        (
            &["write-registers", "0", "--type", "bit:3", "1"],
            &["bit 3"],
        ),
        (
            &["read-holding", "0", "63", "--type", "float32"],
            &["63 values of float32 take 126 registers"],
        ),
        (
            &["read-holding", "0", "1", "--type", "string:200"],
            &["1 to 125 registers"],
        ),
        (
            &["write-registers", "0", "--type", "float32", "1e-50"],
            &["1e-50 is too small for float32: it would be written as 0"],
        ),
        (&["scan"], &["not --unit", "scan --units 1"]),
    ];
    for (args, expected) in cases {
        usage(args, expected);
    }
}

#[test]
fn a_bad_map_file_exits_2_naming_the_line() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.map");
    std::fs::write(&path, "holding 0 = 1\nregister 4 = 2\n").unwrap();
    let out = run(&["sim", "modbus", "--map", path.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert_stderr_has(&out, "line 2");
}

#[test]
fn a_broadcast_write_is_done_without_an_answer_and_a_broadcast_read_is_refused() {
    let sim = Sim::start(&["modbus", "--listen", "127.0.0.1:0"]);
    let out = modbus(&sim, "0", &["write-register", "5", "42"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_stdout_has(&out, "broadcast");
    let out = modbus(&sim, "1", &["--json", "read-holding", "5", "1"]);
    assert_eq!(json_of(&out)["values"], json!([42]));
    let out = modbus(&sim, "0", &["read-holding", "5", "1"]);
    assert_eq!(out.status.code(), Some(2));
    assert_stderr_has(&out, "only writes can be broadcast");
    // Modbus TCP has no broadcast: refused before anything is sent.
    let tcp = Sim::start(&["modbus", "--listen", "127.0.0.1:0", "--framing", "tcp"]);
    let out = modbus(&tcp, "0", &["write-register", "5", "42"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert_stderr_has(&out, "Modbus TCP does not carry");
}

#[test]
fn a_silent_unit_exits_1_naming_endpoint_unit_and_attempts() {
    let sim = Sim::start(&["cross", "--listen", "127.0.0.1:0"]);
    let out = modbus(
        &sim,
        "9",
        &[
            "--timeout",
            "100ms",
            "--retries",
            "1",
            "read-holding",
            "0",
            "1",
        ],
    );
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(
        err.contains(&sim.endpoint) && err.contains("unit 9") && err.contains("2 attempts"),
        "{err}"
    );
}

#[test]
fn bad_arguments_exit_2_before_touching_the_line() {
    // No simulator: the endpoint is never opened.
    let endpoint = "tcp://127.0.0.1:9";
    for args in [
        &["read-holding", "0", "126"][..],
        &["read-holding", "70000", "1"],
        &["read-coils", "0", "2001"],
        &["write-coil", "1", "maybe"],
        &["write-coils", "1", "1", "2"],
        &["write-register", "1", "-40000"],
    ] {
        let mut all = vec!["modbus", "--endpoint", endpoint, "--unit", "1"];
        all.extend_from_slice(args);
        let out = run(&all);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {}", stderr(&out));
    }
    let out = run(&[
        "modbus",
        "--endpoint",
        "bogus://x",
        "--unit",
        "1",
        "read-holding",
        "0",
        "1",
    ]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    let out = run(&["cross", "--endpoint", endpoint, "--unit", "0", "status"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
}

#[test]
fn the_client_recovers_through_injected_line_faults() {
    // Late replies are up to 2 s late: keep the timeout short so a late one costs one retry.
    let args = ["--timeout", "300ms", "--retries", "8", "status", "--json"];
    for out in Sim::client_through_faults("cross", "11", 3, &args) {
        assert_eq!(json_of(&out)["source"], "S1");
    }
}

#[test]
fn a_paced_simulator_and_a_client_that_knows_the_line_speed_work_together() {
    let sim = Sim::start(&["cross", "--listen", "127.0.0.1:0", "--baud", "9600"]);
    let endpoint = format!("{}?baud=9600", sim.endpoint);
    let out = run(&["cross", "--endpoint", &endpoint, "status", "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(json_of(&out)["ratings"]["protocol_revision"], 5);
}

#[test]
fn the_simulator_serves_a_pty_that_the_client_opens_as_a_serial_port() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ttyCROSS");
    let path_text = path.to_str().unwrap();
    let sim = Sim::start(&["cross", "--pty", path_text]);
    assert_eq!(sim.endpoint, path_text);
    let url = format!("serial://{path_text}?baud=9600&framing=8N1");
    let out = run(&["cross", "--endpoint", &url, "status"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_stdout_has(&out, "supplied by source 1");
    let out = run(&[
        "modbus",
        "--endpoint",
        &url,
        "--unit",
        "2",
        "--json",
        "read-holding",
        "0x46",
        "20",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(json_of(&out)["values"].as_array().map(Vec::len), Some(20));
}

#[test]
fn the_generic_simulator_serves_a_pty_too() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ttyMODBUS");
    let path_text = path.to_str().unwrap();
    let _sim = Sim::start(&["modbus", "--pty", path_text, "--unit", "4"]);
    let out = run(&[
        "modbus",
        "--endpoint",
        path_text,
        "--unit",
        "4",
        "write-coils",
        "0",
        "1",
        "1",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = run(&[
        "modbus",
        "--endpoint",
        path_text,
        "--unit",
        "4",
        "--json",
        "read-coils",
        "0",
        "3",
    ]);
    assert_eq!(json_of(&out)["values"], json!([true, true, false]));
}

/// Sends `bytes` on a raw connection to the simulator, then (after `pause` of silence) a
/// read of holding register 0 of unit 1, and returns what came back within 3 s.
fn read_after_garbage(sim: &Sim, bytes: &[u8], pause: Duration) -> Vec<u8> {
    use std::io::{Read, Write};
    let addr = sim
        .endpoint
        .strip_prefix("tcp://")
        .expect("a TCP simulator");
    let mut stream = std::net::TcpStream::connect(addr).expect("the simulator accepts");
    stream.set_nodelay(true).unwrap();
    stream.write_all(bytes).unwrap();
    // The silence a real line would have between a damaged request and the next one.
    std::thread::sleep(pause);
    stream
        .write_all(&frame(&[0x01, 0x03, 0x00, 0x00, 0x00, 0x01]))
        .unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(3)))
        .unwrap();
    let mut reply = vec![0u8; 7];
    match stream.read_exact(&mut reply) {
        Ok(()) => reply,
        Err(_) => Vec::new(),
    }
}

#[test]
fn a_damaged_request_announcing_a_long_frame_does_not_stall_the_simulator() {
    // A function-16 header announcing 246 data bytes that never come (the noisy-line
    // report): after the line's silence the simulator drops it and answers the next read.
    let sim = Sim::start(&["modbus", "--listen", "127.0.0.1:0"]);
    let stuck = [0x01, 0x10, 0x00, 0x00, 0x00, 0x7B, 0xF6];
    let reply = read_after_garbage(&sim, &stuck, Duration::from_millis(300));
    assert_eq!(
        reply.get(..3),
        Some(&[0x01, 0x03, 0x02][..]),
        "{reply:02X?}"
    );
}

#[test]
fn a_frame_gap_the_user_chose_keeps_a_half_frame_until_it_passes() {
    // With a 10 s gap, the read sent 300 ms later is taken as the long frame's data.
    let sim = Sim::start(&["modbus", "--listen", "127.0.0.1:0", "--frame-gap", "10s"]);
    let stuck = [0x01, 0x10, 0x00, 0x00, 0x00, 0x7B, 0xF6];
    let reply = read_after_garbage(&sim, &stuck, Duration::from_millis(300));
    assert!(reply.is_empty(), "answered {reply:02X?}");
}

/// The CRC-16/MODBUS of `body` appended, low byte first.
fn frame(body: &[u8]) -> Vec<u8> {
    let mut crc: u16 = 0xFFFF;
    for &byte in body {
        crc ^= u16::from(byte);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xA001
            } else {
                crc >> 1
            };
        }
    }
    let mut bytes = body.to_vec();
    bytes.extend_from_slice(&crc.to_le_bytes());
    bytes
}

fn hex_args(bytes: &[u8]) -> Vec<String> {
    bytes.iter().map(|b| format!("{b:02X}")).collect()
}

#[test]
fn decode_tells_requests_from_responses_and_marks_a_bad_crc() {
    let mut capture = frame(&[0x02, 0x03, 0x00, 0x46, 0x00, 0x02]);
    capture.extend(frame(&[0x02, 0x03, 0x04, 0x08, 0xFC, 0x09, 0x01]));
    capture.extend(frame(&[0x02, 0x83, 0x02]));
    let mut damaged = frame(&[0x01, 0x06, 0x00, 0x04, 0x00, 0x4D]);
    damaged[3] ^= 0x10;
    capture.extend(damaged);
    capture.extend(frame(&[0x01, 0x06, 0x00, 0x04, 0x00, 0x4D]));
    let hex = hex_args(&capture);
    let mut args = vec!["decode", "modbus"];
    args.extend(hex.iter().map(String::as_str));
    let out = run(&args);
    assert_eq!(
        out.status.code(),
        Some(1),
        "the bad CRC makes the exit code 1"
    );
    let text = stdout(&out);
    for expected in [
        "request to unit 2, function 3 (read holding registers): 2 holding registers from 70 (0x0046)",
        "response from unit 2, function 3 (read holding registers): 2 registers: 2300 2305",
        "refused: exception 2 (illegal data address",
        "8 bytes dropped, CRC bad",
        "request to unit 1, function 6 (write single register): write register 4 (0x0004) = 77",
        "CRC 0x",
        "good",
    ] {
        assert!(text.contains(expected), "{expected:?} missing in:\n{text}");
    }
}

#[test]
fn decode_reads_a_capture_file_and_the_spec_crc_example() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("capture.bin");
    let mut capture = frame(&[0x01, 0x06, 0x00, 0x04, 0x00, 0x4D]);
    capture.extend(frame(&[0x01, 0x06, 0x00, 0x04, 0x00, 0x4D]));
    std::fs::write(&path, &capture).unwrap();
    let out = run(&["decode", "modbus", "--file", path.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stdout(&out));
    let text = stdout(&out);
    assert!(text.contains("request to unit 1"), "{text}");
    assert!(
        text.contains("response from unit 1, function 6 (write single register): wrote register 4"),
        "{text}"
    );
    // The manual's example: frame 02 07 has CRC 0x1241, sent 41 12. A request of function 7
    // (read exception status) is exactly that frame.
    assert_eq!(frame(&[0x02, 0x07])[2..], [0x41, 0x12]);
    let out = run(&["decode", "modbus", "02 07 41 12"]);
    assert!(out.status.success(), "{}", stdout(&out));
    assert_stdout_has(&out, "CRC 0x1241 good");
}

// --- Interoperability with pymodbus (scripts/test installs it) ---

/// The pinned pymodbus version, as scripts/test installs it.
const PYMODBUS: &str = "3.16.1";

/// Where the Python halves of the interoperability tests are.
fn interop_script(name: &str) -> String {
    format!(
        "{}/../jbus/tests/interop/{name}",
        env!("CARGO_MANIFEST_DIR")
    )
}

/// Fails (never skips) when python3 or pymodbus is missing: CI installs them.
fn require_pymodbus() {
    let hint = format!(
        "run scripts/test, which installs it, or: python3 -m pip install pymodbus=={PYMODBUS}"
    );
    let version = require_python(
        "import pymodbus; print(pymodbus.__version__)",
        "pymodbus interoperability tests",
        "pymodbus",
        &hint,
    );
    assert!(
        version.starts_with("3."),
        "pymodbus {version} is installed, the tests need 3.x; {hint}"
    );
}

/// A pymodbus RTU server over TCP, killed when dropped.
struct PyServer {
    child: std::process::Child,
    endpoint: String,
}

impl PyServer {
    fn start() -> Self {
        Self::start_script("pymodbus_server.py")
    }

    /// Runs an interop server script that prints `listening on URL` first.
    fn start_script(script: &str) -> Self {
        require_pymodbus();
        let (child, _, endpoint) = start_listening(
            std::process::Command::new("python3")
                .arg(interop_script(script))
                .stdin(Stdio::null()),
            "listening on ",
        );
        Self { child, endpoint }
    }
}

impl Drop for PyServer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Runs the pymodbus client script against a simulator and returns its JSON report.
fn pymodbus_reads(sim: &Sim, unit: &str) -> Value {
    require_pymodbus();
    let port = sim
        .endpoint
        .rsplit(':')
        .next()
        .expect("tcp://IP:PORT")
        .to_owned();
    let out = std::process::Command::new("python3")
        .args([&interop_script("pymodbus_read_cross.py"), &port, unit])
        .stdin(Stdio::null())
        .output()
        .expect("python3 runs");
    assert!(out.status.success(), "{}", stderr(&out));
    json_of(&out)
}

/// The CROSS's four areas, as `(first address, words)`, in the read plan's order.
const READ_PLAN: [(u16, u16); 4] = [(0x00, 18), (0x14, 4), (0x1E, 17), (0x46, 20)];

#[test]
fn pymodbus_reads_every_area_of_the_cross_exactly_as_our_client_does() {
    // The twin's measures carry noise drawn from its seed, one draw per read: two
    // simulators with the same seed, read with the same sequence of requests, give the
    // same words. So every area compares exactly, measures included.
    let seed = "21";
    let theirs = Sim::start(&["cross", "--listen", "127.0.0.1:0", "--seed", seed]);
    let report = pymodbus_reads(&theirs, "2");
    let areas = report["areas"].as_array().expect("areas");
    assert_eq!(areas.len(), READ_PLAN.len());

    let ours = Sim::start(&["cross", "--listen", "127.0.0.1:0", "--seed", seed]);
    for ((address, count), theirs) in READ_PLAN.iter().zip(areas) {
        let out = modbus(
            &ours,
            "2",
            &[
                "--json",
                "read-holding",
                &address.to_string(),
                &count.to_string(),
            ],
        );
        assert!(out.status.success(), "{}", stderr(&out));
        assert_eq!(theirs[0], json!(address));
        assert_eq!(
            json_of(&out)["values"],
            theirs[1],
            "area at 0x{address:02X} differs"
        );
    }

    // Our decoding of the same words: a third twin with the same seed, read by `cross status`
    // (the same four reads in the same order).
    let decoded = Sim::start(&["cross", "--listen", "127.0.0.1:0", "--seed", seed]);
    let out = cross(&decoded, &["status", "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let state = json_of(&out);
    let word = |address: u16| -> f64 {
        let (start, words) = READ_PLAN
            .iter()
            .zip(areas)
            .find(|((start, count), _)| (*start..start + count).contains(&address))
            .map(|((start, _), area)| (*start, area[1].clone()))
            .expect("a defined address");
        words[usize::from(address - start)]
            .as_f64()
            .expect("a number")
    };
    let measures = &state["measures"];
    let close = |decoded: &Value, expected: f64| {
        let decoded = decoded.as_f64().expect("a number");
        assert!((decoded - expected).abs() < 1e-9, "{decoded} vs {expected}");
    };
    close(&measures["s1_voltage"]["u"], word(0x46) / 10.0);
    close(&measures["s1_frequency"]["value"], word(0x49) / 100.0);
    close(&measures["s2_voltage"]["w"], word(0x4C) / 10.0);
    close(&measures["output_current"]["v"], word(0x52) / 10.0);
    close(&measures["output_frequency"]["value"], word(0x56) / 100.0);
    close(&measures["load_power"]["value"], word(0x57) / 10.0);
    close(&measures["inlet_air"]["value"], word(0x59) / 10.0);
    close(
        &state["ratings"]["rated_current"]["value"],
        word(0x1E) / 10.0,
    );
    close(
        &state["ratings"]["output_current_full_scale"]["u"],
        word(0x28),
    );
    assert_eq!(
        state["ratings"]["protocol_revision"],
        json!(word(0x2E) as u16)
    );
    // Word 0x08 bit 0: "load on source 1"; alarm words 0x01, 0x04, 0x07, 0x0A, 0x0D, 0x10.
    assert_eq!(word(0x08) as u16 & 1, 1);
    assert_eq!(state["source"], "S1");
    for alarm_word in [0x01, 0x04, 0x07, 0x0A, 0x0D, 0x10] {
        assert_eq!(word(alarm_word), 0.0, "alarm word 0x{alarm_word:02X}");
    }
    assert_eq!(state["alarms"], json!([]));
}

#[test]
fn pymodbus_gets_the_refusals_the_manual_specifies_from_the_cross() {
    let sim = Sim::start(&["cross", "--listen", "127.0.0.1:0"]);
    let report = pymodbus_reads(&sim, "2");
    assert_eq!(report["pymodbus"], PYMODBUS, "the pinned version runs");
    assert_eq!(
        report["exceptions"],
        json!({
            "function 4": 1,
            "function 1": 1,
            "function 6": 1,
            "function 16": 1,
            "undefined 0x12": 2,
            "straddling 0x10-0x13": 2,
            "past the map 0x59-0x5A": 2,
            "count 0": 3,
            "count 126": 3,
        })
    );
    assert_eq!(report["silent"], json!({"another unit": true}));
}

#[test]
fn our_client_reads_and_writes_a_pymodbus_server_with_every_function() {
    let server = PyServer::start();
    let run_ok = |args: &[&str]| {
        let mut all = vec!["modbus", "--endpoint", &server.endpoint, "--unit", "1"];
        all.extend_from_slice(args);
        let out = run(&all);
        assert!(out.status.success(), "{args:?}: {}", stderr(&out));
        out
    };
    // Functions 3 and 4, as pymodbus filled them.
    let out = run_ok(&["--json", "read-holding", "0", "5"]);
    assert_eq!(
        json_of(&out),
        json!({"unit": 1, "address": 0, "values": [0, 3, 6, 9, 12]})
    );
    let out = run_ok(&["--json", "read-input", "0x62", "2"]);
    assert_eq!(json_of(&out)["values"], json!([1098, 1099]));
    // Function 2.
    let out = run_ok(&["--json", "read-discrete", "0", "4"]);
    assert_eq!(json_of(&out)["values"], json!([true, false, true, false]));
    // Functions 6 and 16, read back with 3.
    run_ok(&["write-register", "1", "777"]);
    run_ok(&["write-registers", "2", "8", "0xFFFF", "-2"]);
    let out = run_ok(&["--json", "read-holding", "0", "6"]);
    assert_eq!(
        json_of(&out)["values"],
        json!([0, 777, 8, 65535, 65534, 15])
    );
    // Functions 5 and 15, read back with 1 (across a 16-bit boundary).
    run_ok(&["write-coils", "14", "1", "0", "1", "1"]);
    run_ok(&["write-coil", "20", "on"]);
    run_ok(&["write-coil", "16", "off"]);
    let out = run_ok(&["--json", "read-coils", "13", "8"]);
    assert_eq!(
        json_of(&out)["values"],
        json!([false, true, false, false, true, false, false, true])
    );
}

#[test]
fn our_client_reports_a_pymodbus_servers_exceptions_in_words() {
    let server = PyServer::start();
    let refused = |args: &[&str]| {
        let mut all = vec![
            "modbus",
            "--endpoint",
            &server.endpoint,
            "--unit",
            "1",
            "--json",
        ];
        all.extend_from_slice(args);
        let out = run(&all);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {}", stderr(&out));
        (json_of(&out)["exception"]["code"].clone(), stderr(&out))
    };
    let (code, text) = refused(&["read-holding", "98", "3"]);
    assert_eq!(code, 2);
    assert!(text.contains("exception 2 (illegal data address"), "{text}");
    let (code, text) = refused(&["read-holding", "500", "1"]);
    assert_eq!(code, 3);
    assert!(text.contains("exception 3 (illegal data value"), "{text}");
    let (code, text) = refused(&["write-register", "501", "1"]);
    assert_eq!(code, 4);
    assert!(
        text.contains("exception 4 (server device failure"),
        "{text}"
    );
    let (code, text) = refused(&["write-registers", "502", "1"]);
    assert_eq!(code, 1);
    assert!(text.contains("exception 1 (illegal function"), "{text}");
    let (code, _) = refused(&["read-coils", "1600", "1"]);
    assert_eq!(code, 2);
}

// --- Modbus TCP ---

/// The port of a `…://IP:PORT` endpoint.
fn port_of(endpoint: &str) -> String {
    endpoint.rsplit(':').next().expect("…://IP:PORT").to_owned()
}

#[test]
fn sim_modbus_and_cross_with_tcp_framing_print_a_modbus_tcp_address_first() {
    for device in ["modbus", "cross"] {
        let sim = Sim::start(&[device, "--listen", "127.0.0.1:0", "--framing", "tcp"]);
        assert!(
            sim.endpoint.starts_with("modbus-tcp://127.0.0.1:"),
            "{device}: {}",
            sim.endpoint
        );
    }
}

#[test]
fn tcp_framing_on_a_pty_is_a_usage_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tty");
    let out = run(&[
        "sim",
        "modbus",
        "--pty",
        path.to_str().unwrap(),
        "--framing",
        "tcp",
    ]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert_stderr_has(&out, "--framing tcp");
}

#[test]
fn modbus_over_modbus_tcp_writes_and_reads_the_simulator() {
    let sim = Sim::start(&["modbus", "--listen", "127.0.0.1:0", "--framing", "tcp"]);
    let out = modbus(&sim, "1", &["write-registers", "3", "7", "-1"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = modbus(&sim, "1", &["write-coil", "4", "on"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = modbus(&sim, "1", &["--json", "read-holding", "2", "3"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(json_of(&out)["values"], json!([0, 7, 65535]));
    let out = modbus(&sim, "1", &["--json", "read-coils", "3", "2"]);
    assert_eq!(json_of(&out)["values"], json!([false, true]));
}

#[test]
fn cross_status_works_over_modbus_tcp() {
    let sim = Sim::start(&["cross", "--listen", "127.0.0.1:0", "--framing", "tcp"]);
    let out = cross(&sim, &["status", "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(json_of(&out)["source"], "S1");
}

#[test]
fn scan_lists_the_units_that_answer_and_exits_0_when_none_does() {
    let sim = Sim::start(&[
        "modbus",
        "--listen",
        "127.0.0.1:0",
        "--framing",
        "tcp",
        "--unit",
        "3",
    ]);
    let scan = |units: &str, json: bool| {
        let mut args = vec![
            "modbus",
            "scan",
            "--endpoint",
            &sim.endpoint,
            "--units",
            units,
        ];
        if json {
            args.push("--json");
        }
        run(&args)
    };
    let out = scan("1-4", true);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(json_of(&out), json!({"units": [3]}));
    let out = scan("3", false);
    assert_eq!(stdout(&out).trim(), "unit 3 answers");
    let out = scan("4-5", false);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_stdout_has(&out, "no unit of 4-5 answered");
    let out = scan("5-4", false);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
}

#[test]
fn scan_behind_a_gateway_does_not_count_its_no_answer_exception_as_an_answer() {
    // A serial-to-Ethernet gateway answers exception 11 for every unit that is not there.
    let sim = Sim::start(&[
        "modbus",
        "--listen",
        "127.0.0.1:0",
        "--framing",
        "tcp",
        "--unit",
        "3",
        "--gateway-timeout",
        "20ms",
    ]);
    let out = run(&[
        "modbus",
        "scan",
        "--endpoint",
        &sim.endpoint,
        "--units",
        "1-5",
        "--json",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(json_of(&out), json!({"units": [3]}));
    // A read of such a unit says who did not answer, and exits 1.
    let out = run(&[
        "modbus",
        "--endpoint",
        &sim.endpoint,
        "--unit",
        "4",
        "read-holding",
        "0",
        "1",
    ]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("unit 4 did not answer")
            && stderr(&out).contains("the Modbus gateway in between says exception 11"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn scan_over_rtu_counts_an_exception_as_an_answer() {
    // A map without holding register 0: unit 9 answers the scan's read with exception 2.
    let dir = tempfile::tempdir().unwrap();
    let map = dir.path().join("map.txt");
    std::fs::write(&map, "unit 9\ncoil 0 = 1\n").unwrap();
    let sim = Sim::start(&[
        "modbus",
        "--listen",
        "127.0.0.1:0",
        "--map",
        map.to_str().unwrap(),
    ]);
    let out = run(&[
        "modbus",
        "scan",
        "--endpoint",
        &sim.endpoint,
        "--units",
        "8-9",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    assert!(text.contains("unit 9 answers (refused"), "{text}");
    assert!(!text.contains("unit 8"), "{text}");
}

#[test]
fn a_modbus_tcp_endpoint_is_refused_by_the_jbc_command() {
    let out = run(&[
        "jbc",
        "--endpoint",
        "modbus-tcp://127.0.0.1:9",
        "read",
        "AT1",
    ]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert_stderr_has(&out, "modbus-tcp:// is for Modbus devices");
}

#[test]
fn pymodbus_reads_and_writes_registers_and_coils_of_our_modbus_tcp_simulator() {
    require_pymodbus();
    let sim = Sim::start(&[
        "modbus",
        "--listen",
        "127.0.0.1:0",
        "--framing",
        "tcp",
        "--unit",
        "5",
    ]);
    let out = std::process::Command::new("python3")
        .args([
            &interop_script("pymodbus_tcp_client.py"),
            &port_of(&sim.endpoint),
            "5",
        ])
        .stdin(Stdio::null())
        .output()
        .expect("python3 runs");
    assert!(out.status.success(), "{}", stderr(&out));
    let report = json_of(&out);
    assert_eq!(report["pymodbus"], PYMODBUS);
    assert_eq!(report["registers"], json!([111, 222, 65535, 4242]));
    assert_eq!(report["coils"], json!([true, false, true, true]));
    // What pymodbus wrote, read back by our client.
    let out = modbus(&sim, "5", &["--json", "read-holding", "10", "4"]);
    assert_eq!(json_of(&out)["values"], json!([111, 222, 65535, 4242]));
}

#[test]
fn our_client_reads_and_writes_two_units_of_a_pymodbus_tcp_server_on_one_port() {
    let server = PyServer::start_script("pymodbus_tcp_server.py");
    assert!(
        server.endpoint.starts_with("modbus-tcp://"),
        "{}",
        server.endpoint
    );
    let run_ok = |unit: &str, args: &[&str]| {
        let mut all = vec!["modbus", "--endpoint", &server.endpoint, "--unit", unit];
        all.extend_from_slice(args);
        let out = run(&all);
        assert!(out.status.success(), "{args:?}: {}", stderr(&out));
        out
    };
    let out = run_ok("1", &["--json", "read-holding", "0", "3"]);
    assert_eq!(json_of(&out)["values"], json!([0, 10, 20]));
    let out = run_ok("2", &["--json", "read-holding", "0", "3"]);
    assert_eq!(json_of(&out)["values"], json!([0, 20, 40]));
    run_ok("1", &["write-register", "1", "777"]);
    run_ok("2", &["write-registers", "1", "8", "-2"]);
    let out = run_ok("1", &["--json", "read-holding", "0", "3"]);
    assert_eq!(json_of(&out)["values"], json!([0, 777, 20]));
    let out = run_ok("2", &["--json", "read-holding", "0", "3"]);
    assert_eq!(json_of(&out)["values"], json!([0, 8, 65534]));
    run_ok("1", &["write-coils", "2", "1", "0", "1"]);
    run_ok("2", &["write-coil", "0", "on"]);
    let out = run_ok("1", &["--json", "read-coils", "0", "5"]);
    assert_eq!(
        json_of(&out)["values"],
        json!([false, false, true, false, true])
    );
    let out = run_ok("2", &["--json", "read-coils", "0", "3"]);
    assert_eq!(json_of(&out)["values"], json!([true, false, false]));
    let out = run(&[
        "modbus",
        "scan",
        "--endpoint",
        &server.endpoint,
        "--units",
        "1-2",
        "--json",
    ]);
    assert_eq!(json_of(&out), json!({"units": [1, 2]}));
}

/// pymodbus reads `count` values of `data_type` (float32, int32) in word `order` from
/// holding register `address` of `unit`, decoded by Python's struct; their JSON.
fn pymodbus_reads_typed(
    server: &PyServer,
    unit: &str,
    address: u16,
    count: usize,
    data_type: &str,
    order: &str,
) -> Value {
    let out = std::process::Command::new("python3")
        .args([
            &interop_script("pymodbus_tcp_read_typed.py"),
            &port_of(&server.endpoint),
            unit,
            &address.to_string(),
            &count.to_string(),
            data_type,
            order,
        ])
        .stdin(Stdio::null())
        .output()
        .expect("python3 runs");
    assert!(out.status.success(), "{}", stderr(&out));
    json_of(&out)["values"].clone()
}

#[test]
fn our_client_reads_and_writes_float32_cdab_and_int32_values_of_a_pymodbus_tcp_server() {
    let server = PyServer::start_script("pymodbus_tcp_server.py");
    let run_ok = |unit: &str, args: &[&str]| {
        let mut all = vec!["modbus", "--endpoint", &server.endpoint, "--unit", unit];
        all.extend_from_slice(args);
        let out = run(&all);
        assert!(out.status.success(), "{args:?}: {}", stderr(&out));
        out
    };
    // What the server script packed with struct: float32 CDAB from 100, int32 ABCD from 104.
    // Our client shows a float32 as the shortest decimal that is that float32 (229.7, not
    // 229.6999969482422 as struct widens it).
    let floats = [229.7, -1.5];
    for unit in ["1", "2"] {
        let out = run_ok(
            unit,
            &[
                "--json",
                "read-holding",
                "100",
                "2",
                "--type",
                "float32",
                "--order",
                "CDAB",
            ],
        );
        let read = json_of(&out);
        assert_eq!(read["type"], "float32");
        assert_eq!(read["values"], json!(floats), "unit {unit}");
        let out = run_ok(
            unit,
            &["--json", "read-holding", "104", "3", "--type", "int32"],
        );
        assert_eq!(
            json_of(&out)["values"],
            json!([-123_456, 2_000_000_000, 70_000]),
            "unit {unit}"
        );
    }
    // Typed writes (function 16), read back by pymodbus and decoded by struct.
    run_ok(
        "1",
        &[
            "write-registers",
            "110",
            "--type",
            "float32",
            "--order",
            "CDAB",
            "--",
            "12.25",
            "-0.1",
            "1e-3",
        ],
    );
    run_ok(
        "2",
        &[
            "write-registers",
            "110",
            "--type",
            "int32",
            "--",
            "-7",
            "123456789",
            "-2147483648",
        ],
    );
    assert_eq!(
        pymodbus_reads_typed(&server, "1", 110, 3, "float32", "CDAB"),
        json!([12.25, f64::from(-0.1_f32), f64::from(1e-3_f32)])
    );
    assert_eq!(
        pymodbus_reads_typed(&server, "2", 110, 3, "int32", "ABCD"),
        json!([-7, 123_456_789, -2_147_483_648_i64])
    );
    // Each write stopped at its last register (116-121 still hold 0), and our typed reads
    // agree with struct.
    assert_eq!(
        pymodbus_reads_typed(&server, "1", 116, 3, "int32", "ABCD"),
        json!([0, 0, 0])
    );
    let out = run_ok(
        "2",
        &["--json", "read-holding", "110", "3", "--type", "int32"],
    );
    assert_eq!(
        json_of(&out)["values"],
        json!([-7, 123_456_789, -2_147_483_648_i64])
    );
}

#[test]
fn every_client_refuses_a_timeout_of_zero_or_beyond_an_hour_as_a_usage_error() {
    // Refused while the arguments are read: nothing is connected to (port 9 is unused).
    let clients: [&[&str]; 5] = [
        &["jbc", "--endpoint", "tcp://127.0.0.1:9", "read", "ST1"],
        &[
            "modbus",
            "--endpoint",
            "tcp://127.0.0.1:9",
            "--unit",
            "1",
            "read-holding",
            "0",
            "1",
        ],
        &["cross", "--endpoint", "tcp://127.0.0.1:9", "status"],
        &[
            "thermosald",
            "--endpoint",
            "tcp://127.0.0.1:9",
            "--address",
            "1",
            "read",
            "runtime",
        ],
        &["panasonic", "--host", "127.0.0.1:9", "status"],
    ];
    for client in clients {
        for timeout in ["0s", "18446744073709551615s", "2h"] {
            let mut args = client.to_vec();
            args.splice(1..1, ["--timeout", timeout]);
            let out = run(&args);
            assert_eq!(out.status.code(), Some(2), "{args:?}: {}", stderr(&out));
            assert!(
                stderr(&out).contains(&format!("{timeout} is not a timeout from 1ms to 1h"))
                    || stderr(&out).contains("number is too large"),
                "{args:?}: {}",
                stderr(&out)
            );
        }
    }
}

#[test]
fn a_simulator_map_that_cannot_be_read_says_why() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.map");
    let out = run(&["sim", "modbus", "--map", missing.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert_stderr_has(&out, "missing.map: No such file or directory");
}

#[test]
fn a_modicon_looking_address_is_warned_about_and_read_as_asked() {
    let sim = Sim::start(&["modbus", "--listen", "127.0.0.1:0"]);
    let out = modbus(&sim, "1", &["read-holding", "40001", "1"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(stdout(&out), "40001 (0x9C41) =     0 (0x0000)\n");
    assert_eq!(
        stderr(&out),
        "cellbus: warning: 40001 looks like Modicon holding register 40001, which is protocol \
         address 0 of the holding registers; addresses here are 0-based protocol addresses, so \
         this reads address 40001 as asked\n"
    );
    let plain = modbus(&sim, "1", &["read-holding", "0", "1"]);
    assert_eq!(stderr(&plain), "");
}

#[test]
fn modbus_and_cross_options_go_before_or_after_the_subcommand() {
    let sim = Sim::start(&["cross", "--listen", "127.0.0.1:0"]);
    let before = modbus(&sim, "2", &["--json", "read-holding", "0x2E", "1"]);
    let after = run(&[
        "modbus",
        "read-holding",
        "0x2E",
        "1",
        "--unit",
        "2",
        "--json",
        "--endpoint",
        &sim.endpoint,
    ]);
    assert!(after.status.success(), "{}", stderr(&after));
    assert_eq!(stdout(&before), stdout(&after));
    let status = run(&[
        "cross",
        "status",
        "--unit",
        "2",
        "--endpoint",
        &sim.endpoint,
    ]);
    assert!(status.status.success(), "{}", stderr(&status));
    assert_stdout_has(&status, "Chloride CROSS, unit 2");
}

#[test]
fn cross_watch_stops_after_count_rounds_or_for_a_while() {
    let sim = Sim::start(&["cross", "--listen", "127.0.0.1:0"]);
    // A steady switch: the state at the start, then no change.
    let counted = cross_watch(&sim, &["--count", "3", "--json"]);
    assert!(counted.status.success(), "{}", stderr(&counted));
    let text = stdout(&counted);
    assert_eq!(text.lines().count(), 1, "{text}");
    let timed = cross_watch(&sim, &["--for", "300ms"]);
    assert!(timed.status.success(), "{}", stderr(&timed));
    assert!(
        stdout(&timed).starts_with("0.0 s     load supplied by source 1"),
        "{}",
        stdout(&timed)
    );
}

/// `cellbus cross --endpoint … watch --interval 100ms ARGS…`, stopped after a minute.
fn cross_watch(sim: &Sim, args: &[&str]) -> Output {
    let watch = [
        "cross",
        "--endpoint",
        &sim.endpoint,
        "watch",
        "--interval",
        "100ms",
    ];
    run_within(&[&watch[..], args].concat(), Duration::from_secs(60))
}
