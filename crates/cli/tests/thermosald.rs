//! `cellbus thermosald`, `cellbus sim thermosald` and `cellbus decode thermosald`, end to end
//! through the binary against the simulator over TCP and a PTY.
//!
//! The simulator keeps the regulators' real timing (an answer 200 ms after the question, the
//! line released 40 ms after it), so every exchange here takes a quarter of a second of real
//! time; each test has its own simulator, so the tests run in parallel.

mod common;

use std::io::ErrorKind;
use std::net::TcpListener;
use std::process::Output;

use common::{Sim, assert_stderr_has, assert_stdout_has, run, stderr, stdout};
use serde_json::{Value, json};

/// `cellbus thermosald --endpoint SIM ARGS…`.
fn thermosald(sim: &Sim, args: &[&str]) -> Output {
    sim.client("thermosald", args)
}

fn sim(addresses: &str) -> Sim {
    Sim::start(&[
        "thermosald",
        "--listen",
        "127.0.0.1:0",
        "--addresses",
        addresses,
    ])
}

fn json_of(output: &Output) -> Value {
    serde_json::from_str(stdout(output).trim())
        .unwrap_or_else(|e| panic!("one JSON object expected ({e}): {}", stdout(output)))
}

fn assert_ok(output: &Output) {
    assert!(
        output.status.success(),
        "exit {:?}\nstdout: {}\nstderr: {}",
        output.status.code(),
        stdout(output),
        stderr(output)
    );
}

/// A TCP port nobody answers on that notices a connection: a command refused before the
/// wire must never even open the line.
struct Untouched {
    listener: TcpListener,
    url: String,
}

impl Untouched {
    fn new() -> Self {
        let listener = TcpListener::bind("127.0.0.1:0").expect("a loopback port");
        let url = format!("tcp://{}", listener.local_addr().expect("bound"));
        Untouched { listener, url }
    }

    /// Runs `cellbus thermosald --endpoint THIS ARGS…` and checks it exits 2 without
    /// connecting; returns its stderr.
    fn refused(&self, args: &[&str]) -> String {
        let mut all = vec!["thermosald", "--endpoint", &self.url];
        all.extend_from_slice(args);
        let out = run(&all);
        assert_eq!(
            out.status.code(),
            Some(2),
            "{args:?} should exit 2: {}{}",
            stdout(&out),
            stderr(&out)
        );
        // The process has exited: a connection it made would be waiting in the backlog.
        self.listener.set_nonblocking(true).expect("nonblocking");
        match self.listener.accept() {
            Err(e) if e.kind() == ErrorKind::WouldBlock => {}
            Ok(_) => panic!("{args:?} opened the line before refusing"),
            Err(e) => panic!("accept failed: {e}"),
        }
        stderr(&out)
    }
}

#[test]
fn sim_prints_its_tcp_address_first() {
    let sim = sim("0,1,2");
    sim.assert_listens_on("tcp://127.0.0.1:");
}

#[test]
fn read_prints_every_table_with_names_scaled_values_and_units() {
    let sim = sim("0,1,2");
    let expected: [(&str, &[&str]); 4] = [
        (
            "machine",
            &[
                "regulator 1, machine data:",
                "Heating ramp",
                "°C/10 ms",
                "KINT gain                     5.0",
                "Nominal current               40 A",
            ],
        ),
        (
            "settings",
            &[
                "Maximum working temperature       250 °C",
                "Set sealing temperature           180 °C",
                "Heating factor                    1.00",
            ],
        ),
        (
            "runtime",
            &[
                "Current temperature",
                "Fault/warning number  0 (ready)",
                "Resistance            0.",
                " Ω",
                " VA",
            ],
        ),
        (
            "service",
            &[
                "Sealing plate thickness      0.20 mm",
                "Duty cycle                   50.0 %",
                "Theoretical resistance       0.25 Ω",
            ],
        ),
    ];
    for (table, lines) in expected {
        let out = thermosald(&sim, &["--address", "1", "read", table]);
        assert_ok(&out);
        let text = stdout(&out);
        for line in lines {
            assert!(text.contains(line), "{table}: {line:?} missing in\n{text}");
        }
    }
    let out = thermosald(
        &sim,
        &["read", "settings", "--item", "15", "--address", "2"],
    );
    assert_ok(&out);
    assert_eq!(
        stdout(&out).trim(),
        "regulator 2, settings item 15, Set sealing temperature: 180 °C"
    );
}

#[test]
fn read_json_is_an_object_keyed_by_item_index_with_name_value_unit_and_raw() {
    let sim = sim("0");
    let out = thermosald(
        &sim,
        &[
            "read",
            "settings",
            "--item",
            "sealing temperature",
            "--json",
        ],
    );
    assert_ok(&out);
    assert_eq!(
        json_of(&out),
        json!({"15": {"name": "Set sealing temperature", "value": 180, "unit": "°C", "raw": "180"}})
    );

    let out = thermosald(&sim, &["--json", "read", "runtime"]);
    assert_ok(&out);
    let table = json_of(&out);
    let table = table.as_object().expect("an object");
    let keys: Vec<&str> = table.keys().map(String::as_str).collect();
    assert_eq!(keys, ["0", "1", "2", "3", "4", "5", "6"]);
    for (index, entry) in table {
        let mut fields: Vec<&str> = entry
            .as_object()
            .unwrap_or_else(|| panic!("item {index} is an object"))
            .keys()
            .map(String::as_str)
            .collect();
        fields.sort_unstable();
        assert_eq!(fields, ["name", "raw", "unit", "value"], "item {index}");
        let raw = entry["raw"].as_str().expect("raw is text");
        assert!(
            raw.len() == 3 && raw.bytes().all(|b| b.is_ascii_digit()),
            "{raw}"
        );
    }
    assert_eq!(table["2"]["name"], "Fault/warning number");
    assert_eq!(table["2"]["unit"], Value::Null);
    assert_eq!(table["4"]["unit"], "Ω");
    // Resistance is [x.xx]: the value is the raw digits / 100.
    let raw: f64 = table["4"]["raw"].as_str().unwrap().parse().unwrap();
    assert_eq!(table["4"]["value"].as_f64(), Some(raw / 100.0));
}

#[test]
fn write_takes_user_units_and_the_echo_is_read_back() {
    let sim = sim("0,1");
    let out = thermosald(&sim, &["--address", "1", "write", "machine", "3", "12.5"]);
    assert_ok(&out);
    assert_eq!(
        stdout(&out).trim(),
        "regulator 1 echoed machine item 3, KINT gain = 12.5"
    );
    let out = thermosald(
        &sim,
        &[
            "--address",
            "1",
            "--json",
            "read",
            "machine",
            "--item",
            "KINT gain",
        ],
    );
    assert_eq!(
        json_of(&out),
        json!({"3": {"name": "KINT gain", "value": 12.5, "unit": null, "raw": "125"}})
    );

    let out = thermosald(
        &sim,
        &["--json", "write", "settings", "sealing temperature", "190"],
    );
    assert_ok(&out);
    assert_eq!(
        json_of(&out),
        json!({"table": "settings", "item": 15, "name": "Set sealing temperature",
               "value": 190, "unit": "°C", "raw": "190", "ok": true})
    );
    let out = thermosald(&sim, &["write", "service", "1", "0.25"]);
    assert_ok(&out);
    assert_stdout_has(&out, "Sealing plate thickness = 0.25 mm");
    // Regulator 1 kept its own settings.
    let out = thermosald(
        &sim,
        &["--address", "1", "read", "settings", "--item", "15"],
    );
    assert!(stdout(&out).ends_with("180 °C\n"), "{}", stdout(&out));
}

#[test]
fn a_write_out_of_range_exits_2_with_the_facts_and_nothing_on_the_wire() {
    let line = Untouched::new();
    let err = line.refused(&["write", "settings", "15", "1000"]);
    assert!(
        err.contains(
            "settings item \"Set sealing temperature\" = 1000 °C is outside its range, 0 °C to \
             999 °C; nothing was sent"
        ),
        "{err}"
    );
    let err = line.refused(&["write", "settings", "sealing temperature", "-5"]);
    assert!(err.contains("-5 °C is outside its range"), "{err}");
    let err = line.refused(&["write", "machine", "KINT gain", "12.55"]);
    assert!(
        err.contains("= 12.55 is not a multiple of its step, 0.1; nothing was sent"),
        "{err}"
    );
    let err = line.refused(&["write", "machine", "3", "100"]);
    assert!(err.contains("outside its range, 0 to 99.9"), "{err}");
    let err = line.refused(&["write", "runtime", "1", "20"]);
    assert!(err.contains("runtime data is read-only"), "{err}");
}

#[test]
fn an_echo_that_differs_says_what_was_sent_and_what_came_back() {
    // 400 °C fits the item but not the regulator's maximum working temperature (250 °C): it
    // keeps 180 °C and echoes that, twice (the client retries once).
    let sim = sim("0");
    let out = thermosald(&sim, &["write", "settings", "15", "400"]);
    assert_eq!(out.status.code(), Some(1), "{}", stdout(&out));
    let err = stderr(&out);
    assert!(
        err.contains(&format!(
            "echo mismatch from regulator 0 on {}: sent %012Q150400, it echoed %012R150180; it \
             kept Set sealing temperature = 180 °C, not 400 °C",
            sim.endpoint
        )),
        "{err}"
    );
}

#[test]
fn a_silent_address_exits_1_naming_endpoint_address_and_attempts() {
    let sim = sim("0,1,2");
    let out = thermosald(
        &sim,
        &[
            "--address",
            "6",
            "--timeout",
            "300ms",
            "--retries",
            "1",
            "read",
            "runtime",
        ],
    );
    assert_eq!(out.status.code(), Some(1), "{}", stdout(&out));
    assert_eq!(
        stderr(&out).trim(),
        format!(
            "cellbus: no valid answer from regulator 6 on {} after 2 attempts of 300 ms each \
             (last: no reply)",
            sim.endpoint
        )
    );
}

#[test]
fn commands_are_echoed_and_writes_stay_volatile_until_saved_to_eeprom() {
    let sim = sim("3");
    let at3 = |args: &[&str]| {
        let mut all = vec!["--address", "3"];
        all.extend_from_slice(args);
        let out = thermosald(&sim, &all);
        assert_ok(&out);
        stdout(&out)
    };
    let sealing = || at3(&["read", "settings", "--item", "15"]);

    assert!(at3(&["write", "settings", "15", "190"]).contains("= 190 °C"));
    let loaded = at3(&["eeprom-load"]);
    assert_eq!(
        loaded.trim(),
        "regulator 3 loaded its working data from EEPROM (message 17: read data from EEPROM)"
    );
    assert!(sealing().ends_with("180 °C\n"), "the write was volatile");

    at3(&["write", "settings", "15", "190"]);
    let saved = at3(&["eeprom-save"]);
    assert!(
        saved.contains("saved its working data to EEPROM (message 16"),
        "{saved}"
    );
    at3(&["write", "settings", "15", "170"]);
    at3(&["eeprom-load"]);
    assert!(sealing().ends_with("190 °C\n"), "the saved value is back");

    let cleared = at3(&["clear-faults"]);
    assert_eq!(
        cleared.trim(),
        "regulator 3 cleared its faults whose cause is gone; run-time item 2 shows what remains \
         (message 14: clear faults)"
    );
    let out = thermosald(&sim, &["--address", "3", "--json", "balance"]);
    assert_ok(&out);
    assert_eq!(
        json_of(&out),
        json!({"message": 15, "command": "automatic balancing", "ok": true})
    );
    let fault = at3(&["read", "runtime", "--item", "2"]);
    assert!(
        fault.contains("Fault/warning number: 36 (calibration in progress)"),
        "{fault}"
    );
}

#[test]
fn master_reset_needs_yes_then_the_regulator_needs_an_address_and_asks_for_balancing() {
    let line = Untouched::new();
    let err = line.refused(&["master-reset"]);
    assert!(err.contains("add --yes"), "{err}");

    let sim = sim("0");
    let out = thermosald(&sim, &["master-reset", "--yes"]);
    assert_ok(&out);
    assert_stdout_has(
        &out,
        "regulator 0 is back to factory data: it has no address now",
    );
    // No address until one is set: 0 is silent now.
    let out = thermosald(
        &sim,
        &["--timeout", "300ms", "--retries", "0", "read", "runtime"],
    );
    assert_eq!(out.status.code(), Some(1), "{}", stdout(&out));

    let out = thermosald(&sim, &["--address", "$", "set-address", "4"]);
    assert_ok(&out);
    assert_stdout_has(
        &out,
        "every regulator listening to '$' now answers at address 4",
    );
    let out = thermosald(&sim, &["--address", "4", "read", "runtime", "--item", "2"]);
    assert_ok(&out);
    assert_stdout_has(&out, "Fault/warning number: 35 (calibration request)");
    assert_ok(&thermosald(&sim, &["--address", "4", "balance"]));
    let out = thermosald(&sim, &["--address", "4", "read", "runtime", "--item", "2"]);
    assert_stdout_has(&out, "Fault/warning number: 36 (calibration in progress)");
}

#[test]
fn scan_json_lists_which_of_addresses_0_to_7_answer() {
    let sim = sim("1,4");
    let out = thermosald(&sim, &["--json", "scan"]);
    assert_ok(&out);
    let found = json_of(&out);
    assert_eq!(found["answering"], json!([1, 4]));
    for address in 0..8 {
        let entry = &found["addresses"][address.to_string()];
        assert_eq!(
            entry["answers"],
            json!(address == 1 || address == 4),
            "{entry}"
        );
    }
    assert_eq!(found["addresses"]["4"]["text"], "ready");
}

#[test]
fn watch_is_bounded_by_count_and_shows_temperature_fault_in_words_and_power() {
    let sim = sim("0,1,2");
    let out = thermosald(
        &sim,
        &[
            "--address",
            "0,1,2",
            "watch",
            "--interval",
            "100ms",
            "--count",
            "2",
        ],
    );
    assert_ok(&out);
    let text = stdout(&out);
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 1 + 2 * 3, "{text}");
    assert!(lines[0].contains("temperature") && lines[0].contains("fault/warning"));
    for (line, address) in lines[1..].iter().zip(["0", "1", "2", "0", "1", "2"]) {
        let fields: Vec<&str> = line.split_whitespace().collect();
        assert_eq!(fields.get(2), Some(&address), "{line}");
        assert!(
            line.contains(" °C") && line.contains(" VA") && line.ends_with(" 0 ready"),
            "{line}"
        );
    }

    let out = thermosald(
        &sim,
        &[
            "--json",
            "--address",
            "1",
            "watch",
            "--count",
            "2",
            "--interval",
            "100ms",
        ],
    );
    assert_ok(&out);
    let samples: Vec<Value> = stdout(&out)
        .lines()
        .map(|l| serde_json::from_str(l).expect("one JSON object per line"))
        .collect();
    assert_eq!(samples.len(), 2);
    for sample in samples {
        assert_eq!(sample["address"], 1);
        assert_eq!(sample["fault"], 0);
        assert_eq!(sample["fault_text"], "ready");
        assert!(sample["temperature"].is_number() && sample["power"].is_number());
    }
}

#[test]
fn watch_goes_on_past_a_dead_regulator_and_exits_1() {
    let sim = sim("0");
    let out = thermosald(
        &sim,
        &[
            "--address",
            "7,0",
            "--timeout",
            "300ms",
            "--retries",
            "0",
            "watch",
            "--count",
            "1",
            "--interval",
            "100ms",
        ],
    );
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let text = stdout(&out);
    assert!(
        text.contains(&format!(
            "error: no valid answer from regulator 7 on {}",
            sim.endpoint
        )),
        "{text}"
    );
    assert!(
        text.contains("0 ready"),
        "regulator 0 still watched: {text}"
    );
}

#[test]
fn bad_arguments_exit_2_before_the_line_is_opened() {
    let line = Untouched::new();
    let cases: [(&[&str], &str); 12] = [
        (
            &["--address", "8", "read", "runtime"],
            "regulator address 8 is not one of 0 to 7",
        ),
        (&["--address", "1,1", "read", "runtime"], "given twice"),
        (&["read", "bogus"], "no data table called \"bogus\""),
        (
            &["read", "machine", "--item", "30"],
            "machine data has no item 30 (its items are 0 to 24)",
        ),
        (&["read", "machine", "--item", "nonsense"], "no item called"),
        (
            &["--address", "0,1", "read", "runtime"],
            "give one --address",
        ),
        (
            &["--address", "$", "read", "runtime"],
            "'$' is only for set-address",
        ),
        (
            &["--timeout", "100ms", "read", "runtime"],
            "can never see an answer",
        ),
        (&["set-address", "9"], "9"),
        (&["watch", "--interval", "0s"], "0s is no time at all"),
        (&["watch", "--for", "0s"], "0s is no time at all"),
        (&["watch", "--count", "0"], "0 is not in 1.."),
    ];
    for (args, message) in cases {
        let err = line.refused(args);
        assert!(err.contains(message), "{args:?}: {err}");
    }
    let out = run(&["thermosald", "--endpoint", "bogus://x", "read", "runtime"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
}

#[test]
fn decode_annotates_text_and_hex_and_marks_damaged_messages() {
    let out = run(&["decode", "thermosald", "%012Q150180", "%012R150180\\n"]);
    assert_ok(&out);
    let text = stdout(&out);
    assert!(
        text.contains(
            "address 0, message 12 (write settings data), question, item 15: Set sealing \
             temperature = 180 °C"
        ),
        "{text}"
    );
    assert!(text.contains("@12    frame    %012R150180<LF>"), "{text}");
    assert!(text.contains(", response, item 15"), "{text}");

    // A whole run-time answer, noise, then a message with a letter where a digit belongs.
    let mut capture = b"%053R990000133000375028000000\n".to_vec();
    capture.extend_from_slice(b"zz");
    capture.extend_from_slice(b"%0x2Q150180\n");
    let hex: Vec<String> = capture.iter().map(|b| format!("{b:02X}")).collect();
    let mut args = vec!["decode", "thermosald"];
    args.extend(hex.iter().map(String::as_str));
    let out = run(&args);
    assert_eq!(out.status.code(), Some(1), "damage makes the exit code 1");
    let text = stdout(&out);
    for expected in [
        "message 53 (read run-time data), response, whole table",
        "Current temperature = 133 °C",
        "Maximum current = 37.5 A",
        "Resistance = 0.28 Ω",
        "@30    dropped  zz",
        "@32    dropped  %0x2Q150180<LF>",
        "message number 'x2' is not two digits",
    ] {
        assert!(text.contains(expected), "{expected:?} missing in\n{text}");
    }

    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("capture.bin");
    std::fs::write(&file, b"%$10Q000005\n%153R02").unwrap();
    let out = run(&["decode", "thermosald", "--file", file.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1), "a half message at the end");
    let text = stdout(&out);
    assert!(
        text.contains(
            "address assignment '$', message 10 (write logic address), question, new address 5"
        ),
        "{text}"
    );
    assert!(text.contains("partial  %153R02"), "{text}");

    let out = run(&["decode", "thermosald"]);
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn the_client_recovers_through_injected_line_faults() {
    let args = ["--timeout", "400ms", "--retries", "8", "read", "runtime"];
    Sim::client_through_faults("thermosald", "7", 4, &args);
}

#[test]
fn the_simulator_serves_a_paced_pty_that_the_client_opens_as_a_serial_port() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ttyISC");
    let path_text = path.to_str().unwrap();
    let sim = Sim::start(&[
        "thermosald",
        "--pty",
        path_text,
        "--addresses",
        "0,3",
        "--baud",
        "9600",
    ]);
    assert_eq!(sim.endpoint, path_text);
    let url = format!("serial://{path_text}");
    let out = run(&[
        "thermosald",
        "--endpoint",
        &url,
        "--address",
        "3",
        "read",
        "runtime",
    ]);
    assert_ok(&out);
    assert_stdout_has(&out, "Fault/warning number  0 (ready)");

    let out = run(&["thermosald", "--endpoint", &url, "scan"]);
    assert_ok(&out);
    let text = stdout(&out);
    assert!(
        text.contains("address 3: answers, fault/warning 0 (ready)"),
        "{text}"
    );
    assert!(text.contains("address 5: no answer"), "{text}");
    assert!(
        text.contains(&format!(
            "2 of 8 addresses answer (0, 3) on serial://{path_text}"
        )),
        "{text}"
    );
}

#[test]
fn a_line_that_cannot_be_opened_exits_1_naming_it() {
    let closed = {
        let listener = TcpListener::bind("127.0.0.1:0").expect("a loopback port");
        format!("tcp://{}", listener.local_addr().expect("bound"))
    };
    let out = run(&["thermosald", "--endpoint", &closed, "read", "runtime"]);
    assert_eq!(out.status.code(), Some(1), "{}", stdout(&out));
    assert_stderr_has(&out, &format!("cannot connect to {closed}"));
}

fn sim_with_control(addresses: &str) -> (Sim, common::SimControl) {
    Sim::start_with_control(&[
        "thermosald",
        "--listen",
        "127.0.0.1:0",
        "--addresses",
        addresses,
    ])
}

#[test]
fn a_typed_open_band_shows_in_words_and_clear_faults_clears_it_only_after_repair() {
    let (sim, mut control) = sim_with_control("1");
    let fault = || {
        let out = thermosald(&sim, &["--address", "1", "read", "runtime", "--item", "2"]);
        assert_ok(&out);
        stdout(&out)
    };
    assert_eq!(
        control.ok("fault 1 open-band"),
        "regulator 1: cause of \"sealing band open\" provoked; fault number now 1 (sealing \
         band open)"
    );
    let out = thermosald(&sim, &["--address", "1", "read", "runtime"]);
    assert_ok(&out);
    assert_stdout_has(&out, "Fault/warning number  1 (sealing band open)");
    // The band is still broken: clearing does nothing.
    assert_ok(&thermosald(&sim, &["--address", "1", "clear-faults"]));
    assert!(fault().contains("1 (sealing band open)"), "{}", fault());
    assert!(control.ok("repair 1").contains("every fault cause removed"));
    // Repaired, but latched until cleared.
    assert!(fault().contains("1 (sealing band open)"), "{}", fault());
    assert_ok(&thermosald(&sim, &["--address", "1", "clear-faults"]));
    assert!(fault().contains("0 (ready)"), "{}", fault());
    assert!(
        control.ok("status").starts_with("regulator 1: "),
        "the sim's own status names the regulator"
    );
}

#[test]
fn a_typed_over_current_hits_only_its_regulator_and_a_power_cycle_reloads_the_eeprom() {
    let (sim, mut control) = sim_with_control("1,2");
    let at = |address: &str, args: &[&str]| {
        let mut all = vec!["--address", address];
        all.extend_from_slice(args);
        let out = thermosald(&sim, &all);
        assert_ok(&out);
        stdout(&out)
    };
    control.ok("fault 2 over-current");
    // Latched as soon as the band is fired: poll until it shows (generous deadline).
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    loop {
        let fault = at("2", &["read", "runtime", "--item", "2"]);
        if fault.contains("3 (over-current)") {
            break;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "over-current never latched: {fault}"
        );
    }
    assert!(at("1", &["read", "runtime", "--item", "2"]).contains("0 (ready)"));
    // A volatile write is lost at power-up; the repaired regulator comes back ready.
    assert!(at("2", &["write", "settings", "15", "190"]).contains("= 190 °C"));
    control.ok("repair 2");
    assert!(
        control
            .ok("power-cycle 2")
            .ends_with("working data reloaded from EEPROM; fault number now 0 (ready)")
    );
    assert!(at("2", &["read", "settings", "--item", "15"]).ends_with("180 °C\n"));
    assert!(at("2", &["read", "runtime", "--item", "2"]).contains("0 (ready)"));
}

#[test]
fn wrong_control_commands_answer_an_error_line_and_the_regulators_keep_answering() {
    let (sim, mut control) = sim_with_control("1");
    assert_eq!(
        control.send("repair 5"),
        "error: no regulator at address 5 on this line (addresses: 1)"
    );
    assert_eq!(
        control.send("fault 1 melted"),
        "error: `melted` is not a fault cause: use open-band, short, over-current or not-reached"
    );
    assert_eq!(
        control.send("fault 9 short"),
        "error: regulator address `9` is not a number from 0 to 7"
    );
    assert!(control.ok("help").contains("power-cycle ADDR"));
    let out = thermosald(&sim, &["--address", "1", "read", "runtime", "--item", "2"]);
    assert_ok(&out);
    assert_stdout_has(&out, "0 (ready)");
}

#[test]
fn the_simulators_help_lists_its_control_commands() {
    let out = run(&["sim", "thermosald", "--help"]);
    assert_ok(&out);
    for command in [
        "fault ADDR open-band|short|over-current|not-reached",
        "repair ADDR",
        "power-cycle ADDR",
    ] {
        assert_stdout_has(&out, command);
    }
}
