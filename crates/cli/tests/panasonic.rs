//! `cellbus panasonic`, `cellbus sim panasonic` and `cellbus decode panasonic` end to end:
//! the binary against the simulated placement machine on loopback TCP, port 0.

mod common;

use std::io::BufReader;
use std::process::{ChildStdin, ChildStdout, Stdio};

use common::{Sim, SimControl, assert_stderr_has, cellbus, line_after, run, stderr, stdout};

/// A running `cellbus sim panasonic`, killed when dropped.
struct Machine {
    _sim: Sim,
    /// Kept open so the simulator's stdout stays writable (or handed to the control).
    out: Option<BufReader<ChildStdout>>,
    /// `IP:PORT` of Port 1.
    command: String,
    /// Port 2's port number.
    events_port: String,
}

impl Machine {
    /// Starts the simulator with `extra` options (stdin empty: no control channel) and
    /// reads its first two lines.
    fn start(extra: &[&str]) -> Machine {
        Machine::spawn(extra, false).0
    }

    /// Like [`Machine::start`], with a control channel to type commands into.
    fn start_with_control(extra: &[&str]) -> (Machine, SimControl) {
        let (mut machine, stdin) = Machine::spawn(extra, true);
        let stdout = machine.out.take().expect("stdout kept");
        (
            machine,
            SimControl::new(stdin.expect("stdin is piped"), stdout),
        )
    }

    /// Starts the simulator; with `control`, its stdin is piped and handed back.
    fn spawn(extra: &[&str], control: bool) -> (Machine, Option<ChildStdin>) {
        let stdin = if control {
            Stdio::piped()
        } else {
            Stdio::null()
        };
        let mut args = vec![
            "panasonic",
            "--listen",
            "127.0.0.1:0",
            "--events-listen",
            "127.0.0.1:0",
        ];
        args.extend_from_slice(extra);
        let (mut sim, mut out) = Sim::spawn(&args, stdin);
        let command = sim
            .endpoint
            .strip_prefix("tcp://")
            .unwrap_or_else(|| panic!("Port 1 is a tcp:// endpoint, got {}", sim.endpoint))
            .to_owned();
        let events = line_after(&mut out, "events on tcp://");
        let events_port = events.rsplit_once(':').expect("IP:PORT").1.to_owned();
        let stdin = control.then(|| sim.take_stdin());
        let machine = Machine {
            _sim: sim,
            out: Some(out),
            command,
            events_port,
        };
        (machine, stdin)
    }

    /// Runs `cellbus panasonic --host … --events-port … ARGS…`.
    fn run(&self, args: &[&str]) -> std::process::Output {
        let mut all = vec![
            "panasonic",
            "--host",
            &self.command,
            "--events-port",
            &self.events_port,
        ];
        all.extend_from_slice(args);
        run(&all)
    }
}

fn code(output: &std::process::Output) -> i32 {
    output.status.code().expect("exited")
}

/// Asserts exit code 0 and returns stdout.
fn ok(output: std::process::Output) -> String {
    assert_eq!(code(&output), 0, "stderr: {}", stderr(&output));
    stdout(&output)
}

/// A message as the manual lays it out: command padded to 256 bytes, big-endian size,
/// data, three NUL bytes.
fn message(command: &str, data: &[u8]) -> Vec<u8> {
    let mut bytes = command.as_bytes().to_vec();
    bytes.resize(256, b' ');
    bytes.extend_from_slice(&u32::try_from(data.len()).expect("small").to_be_bytes());
    bytes.extend_from_slice(data);
    bytes.extend_from_slice(&[0, 0, 0]);
    bytes
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

#[test]
fn the_simulator_prints_port_1_then_port_2_and_status_reads_both_forms() {
    let machine = Machine::start(&[]);
    assert!(machine.command.starts_with("127.0.0.1:"));
    let text = ok(machine.run(&["status"]));
    assert_eq!(text, "state: ready\nmode:  online\n");
    let json = ok(machine.run(&["status", "--json"]));
    assert_eq!(json.trim_end(), r#"{"state":"ready","mode":"online"}"#);
}

#[test]
fn program_and_programs_name_the_selected_and_stored_programs() {
    let machine = Machine::start(&[]);
    assert_eq!(ok(machine.run(&["program"])), "DEMO-BOARD\n");
    assert_eq!(
        ok(machine.run(&["program", "--json"])).trim_end(),
        r#"{"program":"DEMO-BOARD"}"#
    );
    assert_eq!(ok(machine.run(&["programs"])), "26/01/05  DEMO-BOARD\n");
    let json: serde_json::Value =
        serde_json::from_str(&ok(machine.run(&["programs", "--json"]))).expect("JSON");
    assert_eq!(json[0]["name"], "DEMO-BOARD");
}

#[test]
fn production_data_prints_named_counters_and_clears_on_request() {
    let machine = Machine::start(&[]);
    let text = ok(machine.run(&["production"]));
    assert!(text.starts_with("data:  M000\n"), "{text}");
    assert!(text.contains("%MANAGEMENT\n"), "{text}");
    assert!(text.contains("  PRODUCT1         0000000\n"), "{text}");
    assert!(text.contains("  PICKUP_RATE      "), "{text}");
    let cleared = ok(machine.run(&["production", "--clear"]));
    assert!(cleared.starts_with("data:  M900\n"), "{cleared}");
    assert!(
        cleared.ends_with("(counters cleared after reading)\n"),
        "{cleared}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&ok(machine.run(&["production", "--json"]))).expect("JSON");
    assert_eq!(json["header"]["machine"], "BM");
}

#[test]
fn download_upload_and_delete_a_program_through_files() {
    let machine = Machine::start(&[]);
    let dir = tempfile::tempdir().expect("temp dir");
    let program = dir.path().join("pcb42.txt");
    let text = "%HEADER\r\nNAME=PCB-42\r\n%STEP\r\n0001,X010.00,Y010.00,R000,Z001\r\n*\r\n";
    std::fs::write(&program, text).expect("written");
    let stored = ok(machine.run(&["download", "PCB-42", program.to_str().expect("UTF-8")]));
    assert_eq!(
        stored,
        format!(
            "program PCB-42 stored on the machine ({} bytes)\n",
            text.len()
        )
    );
    assert!(ok(machine.run(&["programs"])).contains("  PCB-42\n"));
    assert_eq!(ok(machine.run(&["upload", "PCB-42"])), text);
    let back = dir.path().join("back.txt");
    let wrote = ok(machine.run(&["upload", "PCB-42", "--out", back.to_str().expect("UTF-8")]));
    assert!(
        wrote.starts_with(&format!("{} bytes written to ", text.len())),
        "{wrote}"
    );
    assert_eq!(std::fs::read_to_string(&back).expect("read"), text);
    assert_eq!(
        ok(machine.run(&["delete", "PCB-42"])),
        "program PCB-42 deleted\n"
    );
    let gone = machine.run(&["upload", "PCB-42"]);
    assert_eq!(code(&gone), 1);
    assert_stderr_has(&gone, "program \"PCB-42\" does not exist on the machine");
}

#[test]
fn downloading_the_selected_program_is_refused_in_words() {
    let machine = Machine::start(&[]);
    let dir = tempfile::tempdir().expect("temp dir");
    let program = dir.path().join("demo.txt");
    std::fs::write(&program, "%HEADER\r\n*\r\n").expect("written");
    let refused = machine.run(&["download", "DEMO-BOARD", program.to_str().expect("UTF-8")]);
    assert_eq!(code(&refused), 1);
    let text = stderr(&refused);
    assert!(text.contains("operation error (A4E00)"), "{text}");
    assert!(text.contains("selected or being edited"), "{text}");
}

#[test]
fn start_outside_remote_mode_is_refused_with_a4e00_in_words() {
    let machine = Machine::start(&[]);
    let refused = machine.run(&["start"]);
    assert_eq!(code(&refused), 1);
    let text = stderr(&refused);
    assert!(
        text.contains("machine refused C5ST: operation error (A4E00)"),
        "{text}"
    );
    assert!(text.contains("Remote mode"), "{text}");
    assert_eq!(
        ok(machine.run(&["status"])),
        "state: ready\nmode:  online\n"
    );
}

#[test]
fn remote_start_gets_a2_and_events_shows_r1st_in_words_and_json() {
    let machine = Machine::start(&["--remote"]);
    let started = ok(machine.run(&["start", "--mode", "ct"]));
    assert_eq!(
        started,
        "machine started in continuous mode (A2); R1ST follows on Port 2\n"
    );
    assert_eq!(
        ok(machine.run(&["status", "--json"])).trim_end(),
        r#"{"state":"run","mode":"remote"}"#
    );
    // No host listened on Port 2 when R1ST was sent: the machine kept it for the next one.
    assert_eq!(
        ok(machine.run(&["events", "--count", "1"])),
        "R1ST (machine started)\n"
    );
    // A running machine refuses a second start.
    let again = machine.run(&["start"]);
    assert_eq!(code(&again), 1);
    assert_stderr_has(&again, "A4E00");
}

#[test]
fn events_json_prints_one_object_per_r_message() {
    let machine = Machine::start(&["--remote"]);
    ok(machine.run(&["start", "--mode", "bl"]));
    let json = ok(machine.run(&["events", "--json", "--count", "1"]));
    assert_eq!(
        json.trim_end(),
        r#"{"event":"started","wire":"R1ST","text":"machine started"}"#
    );
}

#[test]
fn reset_in_remote_mode_gets_a2_then_r1re() {
    let machine = Machine::start(&["--remote"]);
    assert_eq!(
        ok(machine.run(&["reset"])),
        "reset accepted (A2); R1RE follows on Port 2 when done\n"
    );
    assert_eq!(
        ok(machine.run(&["events", "--count", "1"])),
        "R1RE (reset done)\n"
    );
}

#[test]
fn decode_annotates_the_fact_sheets_c2st_request_and_d1_001_reply() {
    let c2st = message("C2ST", b"");
    assert_eq!(c2st.len(), 263);
    let d1 = message("D1", b"001");
    assert_eq!(d1.len(), 266);
    assert_eq!(
        hex(&d1[254..]),
        format!("{}00000003303031000000", "20".repeat(2))
    );
    let capture = [c2st, d1].concat();
    let out = ok(run(&["decode", "panasonic", &hex(&capture)]));
    let lines: Vec<&str> = out.lines().collect();
    assert!(lines[0].starts_with("@0 263 bytes: C2ST"), "{out}");
    assert_eq!(
        lines[1].trim(),
        "command \"C2ST\" + 252 blanks | size 00 00 00 00 (0 bytes) | terminator 00 00 00"
    );
    assert!(lines[2].starts_with("@263 266 bytes: D1"), "{out}");
    assert_eq!(
        lines[3].trim(),
        "command \"D1\" + 254 blanks | size 00 00 00 03 (3 bytes) | data \"001\" | terminator 00 00 00"
    );
}

#[test]
fn decode_reads_a_file_and_exits_1_on_garbage() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("capture.bin");
    let capture = [b"\x01\x02junk".to_vec(), message("R1ST", b"")].concat();
    std::fs::write(&path, capture).expect("written");
    let out = run(&[
        "decode",
        "panasonic",
        "--file",
        path.to_str().expect("UTF-8"),
    ]);
    assert_eq!(code(&out), 1);
    let text = stdout(&out);
    assert!(text.contains("skipped"), "{text}");
    assert!(text.contains("R1ST (machine started)"), "{text}");
}

#[test]
fn bad_arguments_exit_2_without_touching_the_machine() {
    // Nothing listens on port 1 of 127.0.0.1: a connection attempt would exit 1.
    for args in [
        &["upload", "A-NAME-OF-SIXTEEN"][..],
        &["start", "--mode", "xx"],
        &["events", "--count", "0"],
        &["download", "PCB", "/nonexistent/file"],
    ] {
        let mut all = vec!["panasonic", "--host", "127.0.0.1:1"];
        all.extend_from_slice(args);
        let out = run(&all);
        assert_eq!(code(&out), 2, "{args:?}: {}", stderr(&out));
    }
    let out = run(&["panasonic", "--host", "127.0.0.1:99999", "status"]);
    assert_eq!(code(&out), 2);
    assert_stderr_has(&out, "not a TCP port");
    // The other commands' --endpoint URLs are not hosts.
    let out = run(&["panasonic", "--host", "tcp://127.0.0.1:1", "status"]);
    assert_eq!(code(&out), 2);
    assert!(
        stderr(&out).contains("without tcp:// (e.g. 192.168.0.20"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn an_unreachable_machine_exits_1_naming_the_port() {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").expect("binds");
    let addr = listener.local_addr().expect("bound").to_string();
    drop(listener);
    let out = run(&["panasonic", "--host", &addr, "status"]);
    assert_eq!(code(&out), 1);
    let text = stderr(&out);
    assert!(text.contains("Port 1 (commands)"), "{text}");
    assert!(text.contains(&addr), "{text}");
}

#[test]
fn events_running_before_a_remote_start_sees_r1st_arrive_live() {
    let machine = Machine::start(&["--remote"]);
    let mut events = cellbus()
        .args([
            "panasonic",
            "--host",
            &machine.command,
            "--events-port",
            &machine.events_port,
            "events",
            "--json",
            "--count",
            "1",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("cellbus runs");
    // Its first notice (on stderr) says Port 2 is connected: then start the machine.
    let mut notices = BufReader::new(events.stderr.take().expect("piped"));
    line_after(&mut notices, "cellbus: Port 2 (events) connected to tcp://");
    ok(machine.run(&["start"]));
    let out = events
        .wait_with_output()
        .expect("events ends after one R message");
    assert_eq!(code(&out), 0);
    assert_eq!(
        stdout(&out).trim_end(),
        r#"{"event":"started","wire":"R1ST","text":"machine started"}"#
    );
}

#[test]
fn a_simulator_started_with_run_is_producing_without_a_host_command() {
    let machine = Machine::start(&["--run"]);
    assert_eq!(ok(machine.run(&["status"])), "state: run\nmode:  online\n");
    assert_eq!(
        ok(machine.run(&["events", "--count", "1"])),
        "R1ST (machine started)\n"
    );
}

#[test]
fn typed_remote_and_error_3_show_in_status_and_events_reports_r2e03_in_words() {
    let (machine, mut control) = Machine::start_with_control(&[]);
    assert_eq!(
        control.ok("remote"),
        "mode remote: the host may also start and reset the machine (C5)"
    );
    assert_eq!(
        ok(machine.run(&["status"])),
        "state: ready\nmode:  remote\n"
    );
    assert_eq!(
        control.ok("error 3"),
        "error stop with code 03: R2E03 goes out on Port 2"
    );
    assert_eq!(
        ok(machine.run(&["status"])),
        "state: error stop\nmode:  remote\n"
    );
    // No host listened on Port 2: the machine kept R2E03 for the next one.
    let events = ok(machine.run(&["events", "--count", "1"]));
    assert!(events.starts_with("R2E03"), "{events}");
    assert!(events.contains("parts exhausted"), "{events}");
    assert!(
        control
            .ok("status")
            .starts_with("error stop, remote; program DEMO-BOARD"),
        "the sim's own status agrees"
    );
    assert_eq!(
        control.ok("clear"),
        "error causes cleared and RESET pressed: ready"
    );
    assert_eq!(
        control.ok("online"),
        "mode online: the host may transfer data; C5 start/reset are refused"
    );
    assert_eq!(
        ok(machine.run(&["status"])),
        "state: ready\nmode:  online\n"
    );
}

#[test]
fn a_typed_operator_start_runs_the_machine_in_online_mode_and_stop_makes_it_ready() {
    let (machine, mut control) = Machine::start_with_control(&[]);
    assert_eq!(
        control.ok("start ct"),
        "started at the panel in continuous mode; R1ST goes out on Port 2"
    );
    assert_eq!(ok(machine.run(&["status"])), "state: run\nmode:  online\n");
    assert_eq!(
        ok(machine.run(&["events", "--count", "1"])),
        "R1ST (machine started)\n"
    );
    assert_eq!(control.ok("stop"), "stopped at the panel: ready");
    assert_eq!(
        ok(machine.run(&["status"])),
        "state: ready\nmode:  online\n"
    );
}

#[test]
fn wrong_control_commands_answer_an_error_line_and_the_simulator_keeps_serving() {
    let (machine, mut control) = Machine::start_with_control(&[]);
    assert_eq!(
        control.send("pause-feeder 999"),
        "error: feeder 999 does not exist: the machine has feeders 1 to 20"
    );
    assert_eq!(
        control.send("pause-feeder two"),
        "error: feeder number `two` is not a number from 1 to 65535"
    );
    assert_eq!(
        control.send("launch"),
        "error: unknown command `launch`; `help` lists the commands"
    );
    assert_eq!(
        control.send("error 100"),
        "error: error code `100` is not a number from 0 to 99"
    );
    let help = control.ok("help");
    for command in [
        "online",
        "remote",
        "start [bl|ep|ct]",
        "pause-feeder N",
        "error CODE",
    ] {
        assert!(help.contains(command), "{help}");
    }
    assert!(
        control
            .ok("refill-feeder 2")
            .starts_with("feeder 2 refilled: ")
    );
    assert_eq!(
        control.ok("pause-feeder 2"),
        "feeder 2 paused: its next pick runs out (R2E03, error stop)"
    );
    assert_eq!(control.ok("resume-feeder 2"), "feeder 2 feeds again");
    assert_eq!(
        ok(machine.run(&["status"])),
        "state: ready\nmode:  online\n"
    );
}

#[test]
fn the_simulators_help_lists_its_control_commands() {
    let help = ok(run(&["sim", "panasonic", "--help"]));
    for command in [
        "remote",
        "start [bl|ep|ct]",
        "pause-feeder N",
        "error CODE",
        "clear",
    ] {
        assert!(help.contains(command), "{help}");
    }
}

#[test]
fn json_goes_before_or_after_the_subcommand_and_acts_are_objects_too() {
    let machine = Machine::start(&["--remote"]);
    let before = ok(run(&[
        "panasonic",
        "--json",
        "--host",
        &machine.command,
        "status",
    ]));
    let after = ok(run(&[
        "panasonic",
        "status",
        "--host",
        &machine.command,
        "--json",
    ]));
    assert_eq!(before, after);
    assert_eq!(before.trim_end(), r#"{"state":"ready","mode":"remote"}"#);
    assert_eq!(
        ok(machine.run(&["--json", "start", "--mode", "ct"])).trim_end(),
        r#"{"started":true,"mode":"continuous"}"#
    );
    let out = run(&["panasonic", "status"]);
    assert_eq!(code(&out), 2);
    assert_stderr_has(&out, "--host HOST[:PORT] is needed");
}

#[test]
fn events_for_a_while_ends_with_exit_0_after_the_messages_it_got() {
    let machine = Machine::start(&["--remote"]);
    ok(machine.run(&["start"]));
    let text = ok(machine.run(&["events", "--for", "1s"]));
    // R1ST was kept for the next host on Port 2; the first board takes 22 s.
    assert_eq!(text, "R1ST (machine started)\n");
}
