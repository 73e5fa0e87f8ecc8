use super::*;
use crate::driver::DriverConfig;
use crate::plugins::check_config;
use crate::testing::config::{ONE, PLACER, parse, refused};
use table::hide_secret;

/// A Panasonic machine's event port, if its table names one.
fn event_port(driver: &DriverConfig) -> Option<u16> {
    driver
        .settings
        .get::<crate::driver::panasonic::Keys>()
        .and_then(|keys| keys.event_port)
}

#[test]
fn the_example_config_parses_into_its_lines_and_devices() {
    let config = parse(EXAMPLE_CONFIG).unwrap();
    assert!(!config.lines.is_empty());
    let devices: usize = config.lines.iter().map(|l| l.devices.len()).sum();
    assert!(devices >= 2, "the example shows more than one device");
    assert!(
        config
            .lines
            .iter()
            .any(|l| matches!(l.endpoint, Endpoint::Serial { .. }))
    );
    assert!(
        config
            .lines
            .iter()
            .any(|l| matches!(l.endpoint, Endpoint::Tcp { .. }))
    );
}

#[test]
fn a_config_that_is_not_a_file_too_large_or_not_text_is_refused_without_reading_it_all() {
    let dir = tempfile::tempdir().unwrap();
    let why = |path: &Path| match check_config(path) {
        Err(e @ ConfigError::Read { .. }) => e.to_string(),
        other => panic!("{other:?}"),
    };
    assert_eq!(
        why(Path::new("/dev/zero")),
        "config /dev/zero is not a file"
    );
    let big = dir.path().join("big.toml");
    let file = std::fs::File::create(&big).unwrap();
    file.set_len(MAX_CONFIG + 1).unwrap();
    assert!(
        why(&big).ends_with("big.toml is larger than 16 MiB"),
        "{}",
        why(&big)
    );
    let latin1 = dir.path().join("latin1.toml");
    std::fs::write(&latin1, b"# caf\xe9\n").unwrap();
    assert!(
        why(&latin1).ends_with("latin1.toml is not UTF-8 text (byte 6 is not)"),
        "{}",
        why(&latin1)
    );
    let missing = dir.path().join("missing.toml");
    assert!(
        why(&missing).contains("missing.toml cannot be read: "),
        "{}",
        why(&missing)
    );
}

#[test]
fn the_example_file_in_examples_is_the_one_built_in() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/cell.toml");
    assert_eq!(std::fs::read_to_string(&path).unwrap(), EXAMPLE_CONFIG);
    check_config(&path).unwrap();
}

#[test]
fn a_minimal_config_takes_the_protocol_defaults() {
    let config = parse(ONE).unwrap();
    let line = &config.lines[0];
    assert_eq!(line.name, "rework");
    assert_eq!(
        line.endpoint.line_settings(),
        Some(link::SerialSettings::new_8e1(19200)),
        "JBC's 19200 8E1 when the URL says nothing"
    );
    let device = &line.devices[0];
    assert_eq!(device.name, "jbc1");
    assert_eq!(device.driver.address, Some(1));
    assert_eq!(device.driver.timeout, None);
    assert!(device.groups.is_empty());
}

#[test]
fn periods_addresses_and_retries_are_read() {
    let config = parse(&format!(
        "token = \"t0k\"\n{ONE}address = \"none\"\ntimeout = \"300ms\"\nretries = 1\nperiod = \"2s\"\npoll = {{ live = \"500ms\", info = \"5m\" }}\n"
    ))
    .unwrap();
    let device = &config.lines[0].devices[0];
    assert_eq!(config.token.as_deref(), Some("t0k"));
    assert_eq!(device.driver.address, None);
    assert_eq!(device.driver.timeout, Some(Duration::from_millis(300)));
    assert_eq!(device.driver.retries, Some(1));
    assert_eq!(device.period, Some(Duration::from_secs(2)));
    assert_eq!(device.groups["live"], Duration::from_millis(500));
    assert_eq!(device.groups["info"], Duration::from_secs(300));
}

#[test]
fn unknown_fields_are_refused_where_they_are() {
    refused(
        &format!("{ONE}colour = \"red\"\n"),
        9,
        1,
        "unknown field `colour`",
    );
    refused(
        "[[line]]\nname = \"a\"\nendpoint = \"tcp://h:1\"\nspeed = 9600\n",
        4,
        1,
        "unknown field `speed`",
    );
}

#[test]
fn a_table_of_an_interface_this_build_left_out_is_refused_with_why_where_it_is() {
    let plugins = crate::plugins::builtin()
        .config
        .with_table_left_out("radio", "this build has no radio interface");
    let text = format!("{ONE}\n[radio]\nchannel = 4\n");
    let err = crate::config::parse_config(&text, Path::new("cell.toml"), &plugins)
        .expect_err("the table is refused");
    assert_eq!(
        err.to_string().lines().next(),
        Some("cell.toml:10:2: this build has no radio interface")
    );
    // A build that knows nothing of it calls it unknown.
    refused(&text, 10, 2, "unknown field `radio`");
}

#[test]
fn toml_syntax_errors_name_line_and_column() {
    refused("[[line]\nname = \"a\"\n", 1, 8, "expected `]`");
}

#[test]
fn semantic_errors_point_at_the_offending_value() {
    refused(
        &ONE.replace("\"jbc\"", "\"profibus\""),
        8,
        12,
        "known: jbc, thermosald, cross, panasonic, modbus",
    );
    refused(
        &ONE.replace("serial:///dev/ttyUSB0", "serial:///dev/ttyUSB0?baud=fast"),
        4,
        12,
        "option baud=",
    );
    refused(&format!("{ONE}address = 100\n"), 9, 11, "0 to 99");
    refused(
        &format!("{ONE}address = \"one\"\n"),
        9,
        11,
        "write a number or \"none\"",
    );
    refused(
        &format!("{ONE}timeout = \"soon\"\n"),
        9,
        11,
        "not a duration",
    );
    refused(
        &format!("{ONE}period = \"1ms\"\n"),
        9,
        10,
        "out of range: 50ms",
    );
    refused(&format!("{ONE}retries = 99\n"), 9, 11, "0 to 10");
    refused(
        &format!("{ONE}poll = {{ fast = \"1s\" }}\n"),
        9,
        17,
        "groups: live, settings, info",
    );
    refused(
        &ONE.replace("\"jbc1\"", "\"JBC 1\""),
        7,
        6,
        "device id \"JBC 1\" is not valid",
    );
    refused(&ONE.replace("\"rework\"", "\"re work\""), 3, 8, "line name");
    refused(
        &format!(
            "{ONE}\n{}",
            ONE.replace("\"rework\"", "\"two\"")
                .replace("ttyUSB0", "ttyUSB1")
        ),
        16,
        6,
        "\"jbc1\" is used twice",
    );
    refused(
        &format!("{ONE}\n{}", ONE.replace("\"jbc1\"", "\"jbc2\"")),
        12,
        8,
        "line name \"rework\" is used twice",
    );
    refused("token = \"x\"\n", 1, 1, "no [[line]]");
    refused(
        "[[line]]\nname = \"a\"\nendpoint = \"tcp://h:1\"\n",
        2,
        8,
        "has no devices",
    );
    refused(
        &ONE.replace("[[line]]", "token = \" \"\n[[line]]"),
        2,
        9,
        "token is empty",
    );
}

const SEALERS: &str = r#"
[[line]]
name = "sealers"
endpoint = "tcp://192.0.2.1:4001"

[[line.device]]
id = "sealer0"
protocol = "thermosald"
address = 0
"#;

#[test]
fn thermosald_and_cross_devices_take_their_protocols_defaults() {
    let config = parse(&format!(
        "{SEALERS}\n[[line.device]]\nid = \"sealer7\"\nprotocol = \"thermosald\"\naddress = 7\n\n[[line]]\nname = \"mains\"\nendpoint = \"serial:///dev/ttyUSB1\"\n[[line.device]]\nid = \"cross1\"\nprotocol = \"cross\"\npoll = {{ ratings = \"10m\" }}\n"
    ))
    .unwrap();
    let sealers = &config.lines[0];
    assert_eq!(sealers.endpoint.line_settings(), None, "TCP without ?baud=");
    assert_eq!(sealers.devices.len(), 2);
    assert_eq!(sealers.devices[1].driver.address, Some(7));
    let mains = &config.lines[1];
    assert_eq!(
        mains.endpoint.line_settings(),
        Some(link::SerialSettings::new_8n1(9600)),
        "JBUS's 9600 8N1 when the URL says nothing"
    );
    assert_eq!(mains.devices[0].driver.protocol, crate::driver::cross::KIND);
    assert_eq!(
        mains.devices[0].driver.address,
        Some(1),
        "unit 1 by default"
    );
    assert_eq!(mains.devices[0].groups["ratings"], Duration::from_secs(600));
}

#[test]
fn thermosald_and_cross_mistakes_are_refused_where_they_are() {
    refused(
        &SEALERS.replace("address = 0", "address = 8"),
        9,
        11,
        "address 8 is out of range: 0 to 7",
    );
    refused(
        &SEALERS.replace("address = 0", "address = \"none\""),
        9,
        11,
        "needs its address",
    );
    refused(
        &format!(
            "{SEALERS}\n[[line.device]]\nid = \"sealer9\"\nprotocol = \"thermosald\"\naddress = 0\n"
        ),
        14,
        11,
        "address 0 is used twice on line \"sealers\"",
    );
    refused(
        &format!("{SEALERS}\n[[line.device]]\nid = \"jbc1\"\nprotocol = \"jbc\"\n"),
        13,
        12,
        "a jbc device needs a line of its own",
    );
    refused(
        &format!("{SEALERS}poll = {{ fast = \"1s\" }}\n"),
        10,
        17,
        "groups: live, settings, machine, service",
    );
    let cross = SEALERS
        .replace("thermosald", "cross")
        .replace("sealer0", "cross1");
    refused(
        &cross,
        9,
        11,
        "JBUS unit number 0 is out of range: 1 to 255",
    );
    refused(
        &cross.replace("address = 0", "address = 300"),
        9,
        11,
        "1 to 255",
    );
}

#[test]
fn a_panasonic_machine_takes_its_ports_from_the_endpoint_and_event_port() {
    let config = parse(PLACER).unwrap();
    let driver = &config.lines[0].devices[0].driver;
    assert_eq!(driver.address, None);
    assert_eq!(event_port(driver), None, "49153 by default");
    assert_eq!(driver.endpoint, Some(config.lines[0].endpoint.clone()));
    let config = parse(&format!("{PLACER}event_port = 50000\n")).unwrap();
    assert_eq!(event_port(&config.lines[0].devices[0].driver), Some(50000));
}

#[test]
fn panasonic_mistakes_are_refused_where_they_are() {
    refused(
        &PLACER.replace("tcp://192.0.2.50:49152", "serial:///dev/ttyS0"),
        4,
        12,
        "is reached over TCP: write tcp://host:49152",
    );
    refused(&format!("{PLACER}address = 3\n"), 9, 11, "has no address");
    refused(
        &format!("{PLACER}event_port = 70000\n"),
        9,
        14,
        "event_port 70000 is out of range: 1 to 65535",
    );
    refused(
        &format!("{ONE}event_port = 49153\n"),
        9,
        14,
        "event_port is for Panasonic machines only",
    );
    refused(
        &format!("{PLACER}\n[[line.device]]\nid = \"placer2\"\nprotocol = \"panasonic\"\n"),
        3,
        8,
        "each machine is its own TCP server and needs a [[line]] of its own",
    );
}

#[test]
fn a_modbus_tcp_endpoint_for_a_device_that_is_not_modbus_is_refused() {
    refused(
        &ONE.replace("serial:///dev/ttyUSB0", "modbus-tcp://192.0.2.9"),
        4,
        12,
        "modbus-tcp:// is for Modbus devices (modbus, cross); a jbc line",
    );
}

#[test]
fn a_deadband_applies_to_any_protocol() {
    let config = parse(&format!("{ONE}deadband_percent = 2\n")).unwrap();
    assert_eq!(
        config.lines[0].devices[0].deadband,
        Some(Deadband::Percent(2.0))
    );
}

#[test]
fn two_lines_on_one_serial_port_are_refused_but_a_tcp_server_decides_for_itself() {
    let two = |first: &str, second: &str, protocol: &str| {
        format!(
            "[[line]]\nname = \"a\"\nendpoint = \"{first}\"\n[[line.device]]\nid = \"d1\"\n\
             protocol = \"{protocol}\"\naddress = 1\n\
             [[line]]\nname = \"b\"\nendpoint = \"{second}\"\n[[line.device]]\nid = \"d2\"\n\
             protocol = \"{protocol}\"\naddress = 2\n"
        )
    };
    refused(
        &two("serial:///dev/ttyUSB0", "/dev/ttyUSB0", "cross"),
        10,
        12,
        "line \"b\" is on serial port /dev/ttyUSB0, as line \"a\" is",
    );
    // A serial server may take one connection or several, and a simulator serves each
    // connection a bus of its own: its answer, not the configuration, decides.
    parse(&two("tcp://moxa:4001", "tcp://moxa:4001", "cross"))
        .expect("two connections to one TCP server");
    refused(
        &two("tcp://moxa:0", "tcp://moxa:4002", "cross"),
        3,
        12,
        "port 0 is not a port a device listens on",
    );
    parse(&two("modbus-tcp://plc", "modbus-tcp://plc", "cross"))
        .expect("a Modbus TCP server serves several connections");
}

#[test]
fn an_address_of_the_wrong_type_is_told_in_words_not_rust_types() {
    for address in ["1.5", "true"] {
        refused(
            &format!("{ONE}address = {address}\n"),
            9,
            11,
            "the address must be a whole number (see the protocol's range) or \"none\"",
        );
    }
}

#[test]
fn the_error_shows_the_line_with_a_caret_under_the_column() {
    let err = parse(&format!("{ONE}address = 100\n"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("9 | address = 100\n  |           ^"), "{err}");
}

#[test]
fn a_number_beyond_64_bits_is_called_too_large_not_an_i128() {
    let text = ONE.replace(
        "protocol = \"jbc\"",
        "protocol = \"jbc\"\naddress = 99999999999999999999999",
    );
    refused(
        &text,
        9,
        11,
        "99999999999999999999999 is too large: no number in the configuration is beyond \
         9223372036854775807",
    );
    assert_eq!(plain_toml_message("expected a table\n"), "expected a table");
}

#[test]
fn device_ids_the_gateways_own_objects_use_are_refused() {
    for id in RESERVED_DEVICE_IDS {
        let text = ONE.replace("id = \"jbc1\"", &format!("id = \"{id}\""));
        refused(&text, 7, 6, "is taken by the gateway's own objects");
    }
}

#[test]
fn a_missing_file_is_named() {
    let err = check_config(Path::new("/nonexistent/cell.toml")).unwrap_err();
    assert!(err.to_string().contains("/nonexistent/cell.toml"), "{err}");
}

#[test]
fn a_read_token_equal_to_the_write_token_is_refused_without_showing_either() {
    let text = format!("token = \"s3cret\"\nread_token = \" s3cret\"\n{ONE}");
    refused(
        &text,
        2,
        14,
        "read_token cannot be used: the read token is the write token",
    );
    let shown = parse(&text).unwrap_err().to_string();
    assert!(!shown.contains("s3cret"), "{shown}");
    let text = format!("token = \"s3cret\"\nread_token = \"look\"\n{ONE}");
    assert_eq!(parse(&text).unwrap().read_token.as_deref(), Some("look"));
}

#[test]
fn an_error_on_the_token_line_does_not_show_the_token() {
    let err = parse(&format!("token = \"s3cret-value\n{ONE}")).unwrap_err();
    let shown = err.to_string();
    assert!(!shown.contains("s3cret"), "{shown}");
    assert!(shown.contains("token = \"(hidden)\""), "{shown}");
    assert_eq!(hide_secret("name = \"rework\""), "name = \"rework\"");
}

#[test]
fn every_mistake_of_a_file_is_reported_in_one_run_in_the_order_of_the_file() {
    let text = "[[line]]\nname = \"a\"\nendpoint = \"serial:///dev/ttyUSB0\"\n\
                [[line.device]]\nid = \"jbc1\"\nprotocol = \"jbc\"\naddress = 100\n\
                [[line.device]]\nid = \"jbc2\"\nprotocol = \"jbc\"\nbogus = 1\n\
                [[line]]\nname = \"b\"\nendpoint = \"serial:///dev/ttyUSB1\"\n\
                [[line.device]]\nid = \"jbc1\"\nprotocol = \"jbc\"\n\
                [mqtt]\nbroker = \"ftp://x\"\n";
    let error = parse(text).unwrap_err();
    let positions: Vec<usize> = error
        .each()
        .iter()
        .map(|e| e.position().unwrap().0)
        .collect();
    assert_eq!(positions, [7, 11, 16, 19], "{error}");
    let words = error.to_string();
    assert!(words.starts_with("4 mistakes:\ncell.toml:7:"), "{words}");
    assert!(
        words.contains("cell.toml:11:1: unknown field `bogus`"),
        "{words}"
    );
    assert!(
        words.contains("device id \"jbc1\" is used twice"),
        "{words}"
    );
}
