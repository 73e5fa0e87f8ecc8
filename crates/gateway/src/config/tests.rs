use super::*;
use crate::driver::DriverConfig;
use crate::driver::modbus::config::{
    MAX_OVERLAPS_NAMED, MAX_REGISTERS_CSV, ModbusSettings, overlapping_registers,
    registers_from_csv, registers_toml,
};
use crate::driver::modbus::{ModbusOptions, RegisterConfig, RegisterTable};
use crate::northbound::mqtt::config::{
    DEFAULT_MQTT_BACKLOG, DEFAULT_MQTT_CHECK_RETAINED, DEFAULT_MQTT_COMMAND_METRICS,
    DEFAULT_MQTT_KEEP_ALIVE, MqttClientCert, MqttConfig, MqttMode, MqttTls, parse_broker,
};
use crate::plugins::{check_config, parse_config};
use jbus::data::{DataType, Format, Order, Scaling};
use table::{hide_secret, hide_userinfo, read_bounded};

/// A modbus device's registers and options.
fn modbus(driver: &DriverConfig) -> &ModbusSettings {
    driver
        .settings
        .get()
        .expect("a modbus device has its settings")
}

/// A Panasonic machine's event port, if its table names one.
fn event_port(driver: &DriverConfig) -> Option<u16> {
    driver
        .settings
        .get::<crate::driver::panasonic::Keys>()
        .and_then(|keys| keys.event_port)
}

/// The `[mqtt]` table, if the file has one.
fn mqtt_table(config: &CellConfig) -> Option<MqttConfig> {
    config.interface::<MqttConfig>("mqtt").cloned()
}

fn parse(text: &str) -> Result<CellConfig, ConfigError> {
    parse_config(text, Path::new("cell.toml"))
}

/// Parses `text`, expecting an error at `line:column` whose message contains `words`.
fn refused(text: &str, line: usize, column: usize, words: &str) {
    let err = parse(text).expect_err("the config must be refused");
    let shown = err.to_string();
    assert_eq!(err.position(), Some((line, column)), "{shown}");
    assert!(
        shown.starts_with(&format!("cell.toml:{line}:{column}: ")),
        "{shown}"
    );
    assert!(shown.contains(words), "{shown}");
}

const ONE: &str = r#"
[[line]]
name = "rework"
endpoint = "serial:///dev/ttyUSB0"

[[line.device]]
id = "jbc1"
protocol = "jbc"
"#;

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

const PLACER: &str = r#"
[[line]]
name = "placement"
endpoint = "tcp://192.0.2.50:49152"

[[line.device]]
id = "placer1"
protocol = "panasonic"
"#;

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

const CHILLER: &str = r#"
[[line]]
name = "utilities"
endpoint = "tcp://192.0.2.60:4001"

[[line.device]]
id = "chiller1"
protocol = "modbus"
address = 17

[[line.device.register]]
name = "supply"
table = "input"
address = 0x10
scale = 0.1
unit = "°C"
signed = true

[[line.device.register]]
name = "setpoint"
address = 0x20
scale = 0.1
writable = { min = 5.0, max = 30.0 }
"#;

#[test]
fn modbus_registers_are_read_from_their_tables() {
    let config = parse(CHILLER).unwrap();
    let driver = &config.lines[0].devices[0].driver;
    assert_eq!(driver.address, Some(17));
    assert_eq!(modbus(driver).registers.len(), 2);
    let supply = &modbus(driver).registers[0];
    assert_eq!(
        (
            supply.table,
            supply.address,
            supply.format.scaling.scale(),
            supply.format.data_type
        ),
        (RegisterTable::Input, 0x10, 0.1, DataType::Int16),
        "the old signed = true is an int16"
    );
    assert_eq!(
        modbus(driver).registers[1].format.data_type,
        DataType::Uint16
    );
    assert_eq!(supply.unit.as_deref(), Some("°C"));
    assert_eq!(modbus(driver).registers[1].writable, Some((5.0, 30.0)));
}

/// A Modbus TCP line of meters `ids`, each with the registers `registers`
/// (`(name, table, address, type)`, no type written when it is empty).
fn meters(ids: &[&str], registers: &[(&str, &str, u16, &str)]) -> String {
    let mut toml =
        "[[line]]\nname = \"utilities\"\nendpoint = \"modbus-tcp://192.0.2.61\"\n".to_owned();
    for (unit, id) in ids.iter().enumerate() {
        toml += &format!(
            "\n[[line.device]]\nid = \"{id}\"\nprotocol = \"modbus\"\naddress = {}\n",
            unit + 1
        );
        for (name, table, address, data_type) in registers {
            toml += &format!(
                "[[line.device.register]]\nname = \"{name}\"\ntable = \"{table}\"\n\
                 address = {address}\n"
            );
            if !data_type.is_empty() {
                toml += &format!("type = \"{data_type}\"\n");
            }
        }
    }
    toml
}

#[test]
fn registers_that_share_a_register_are_warned_about_with_names_and_addresses() {
    let config = parse(&meters(
        &["meter1"],
        &[
            ("voltage", "holding", 100, "float32"),
            ("current", "holding", 101, "float32"),
            ("energy", "holding", 300, "uint64"),
            ("energy_low", "holding", 302, "uint32"),
            ("status", "holding", 200, "uint16"),
            ("running", "holding", 200, "bit:0"),
            ("tripped", "holding", 200, "bit:1"),
            ("frequency", "input", 100, "float32"),
            ("alarm", "coil", 100, ""),
            ("reset", "coil", 100, ""),
        ],
    ))
    .unwrap();
    assert_eq!(
        config.warnings(),
        [
            "device \"meter1\": registers \"voltage\" (holding 100–101) and \"current\" \
             (holding 101–102) share holding register 101",
            "device \"meter1\": registers \"energy\" (holding 300–303) and \"energy_low\" \
             (holding 302–303) share holding registers 302–303",
        ],
        "bits of one register, another table and coils are not warned about"
    );
    assert!(parse(CHILLER).unwrap().warnings().is_empty());
    assert!(
        parse(EXAMPLE_CONFIG).unwrap().warnings().is_empty(),
        "the example has no overlap"
    );
}

#[test]
fn a_list_of_many_registers_at_one_address_names_a_few_pairs_and_says_there_are_more() {
    let registers: Vec<RegisterConfig> = (0..50_000)
        .map(|i| RegisterConfig::holding(&format!("r{i}"), 7))
        .collect();
    let overlaps = overlapping_registers(&registers);
    assert_eq!(overlaps.len(), MAX_OVERLAPS_NAMED + 1);
    assert_eq!(
        overlaps[0],
        "registers \"r0\" (holding 7) and \"r1\" (holding 7) share holding register 7"
    );
    assert_eq!(
        overlaps[MAX_OVERLAPS_NAMED],
        "more registers share a register (the first 20 pairs are named)"
    );
}

#[test]
fn devices_with_the_same_overlapping_registers_are_warned_about_once() {
    let config = parse(&meters(
        &["meter1", "meter2", "meter3"],
        &[("a", "input", 0, "uint32"), ("b", "input", 1, "uint16")],
    ))
    .unwrap();
    assert_eq!(
        config.warnings(),
        [
            "device \"meter1\" (and 2 more with the same registers): registers \"a\" \
          (input 0–1) and \"b\" (input 1) share input register 1"
        ]
    );
}

#[test]
fn a_modbus_tcp_line_parses_and_gives_its_modbus_devices_the_endpoint() {
    let config =
        parse(&CHILLER.replace("tcp://192.0.2.60:4001", "modbus-tcp://192.0.2.60:502")).unwrap();
    let line = &config.lines[0];
    assert!(line.endpoint.is_mbap());
    assert_eq!(
        line.devices[0]
            .driver
            .endpoint
            .as_ref()
            .map(Endpoint::is_mbap),
        Some(true),
        "the driver frames Modbus TCP"
    );
    let raw = parse(CHILLER).unwrap();
    assert_eq!(raw.lines[0].devices[0].driver.endpoint, None);
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
fn modbus_register_mistakes_are_refused_where_they_are() {
    refused(
        &CHILLER.replace("table = \"input\"", "table = \"coils\""),
        13,
        9,
        "write \"holding\", \"input\", \"coil\" or \"discrete\"",
    );
    refused(
        &CHILLER.replace("address = 0x20", "address = 70000"),
        21,
        11,
        "register setpoint: address 70000 is out of range: 0 to 65535",
    );
    refused(
        &CHILLER.replace("name = \"setpoint\"", "name = \"supply\""),
        20,
        8,
        "register name \"supply\" is used twice",
    );
    refused(
        &CHILLER.replace("min = 5.0, max = 30.0", "min = 5.0, max = 9000.0"),
        23,
        12,
        "within what the register holds",
    );
    refused(
        &CHILLER.replace("scale = 0.1\nunit", "scale = 0.0\nunit"),
        15,
        9,
        "scale 0 must be a number above 0",
    );
    refused(
        &format!("{ONE}\n[[line.device.register]]\nname = \"x\"\naddress = 1\n"),
        11,
        8,
        "registers are named for modbus devices only",
    );
    let bare = CHILLER.split("[[line.device.register]]").next().unwrap();
    refused(bare, 7, 6, "needs its registers");
}

const METER: &str = r#"
[[line]]
name = "utilities"
endpoint = "modbus-tcp://192.0.2.61"

[[line.device]]
id = "meter1"
protocol = "modbus"
max_registers_per_request = 60
max_bits_per_request = 800
one_request_per_register = true
delay_between_requests = "50ms"
delay_after_connect = "1s"
deadband = 0.5

[[line.device.register]]
name = "voltage"
table = "input"
address = 0x0100
type = "float32"
order = "CDAB"
unit = "V"

[[line.device.register]]
name = "energy"
table = "input"
address = 0x0200
type = "uint32"
scale = 0.01
offset = 5
deadband_percent = 1

[[line.device.register]]
name = "limit"
address = 0x0300
type = "int32"
writable = { min = -1000, max = 1000 }

[[line.device.register]]
name = "pump"
table = "coil"
address = 3
writable = true

[[line.device.register]]
name = "door"
table = "discrete"
address = 0x20

[[line.device.register]]
name = "label"
address = 0x0400
type = "string:4"
"#;

#[test]
fn modbus_types_orders_tables_pacing_and_deadbands_are_read() {
    let config = parse(METER).unwrap();
    let device = &config.lines[0].devices[0];
    let driver = &device.driver;
    assert_eq!(device.deadband, Some(Deadband::Absolute(0.5)));
    let options = modbus(driver).options;
    assert_eq!(options.plan.max_registers.get(), 60);
    assert_eq!(options.plan.max_bits.get(), 800);
    assert!(options.plan.one_request_per_item);
    assert_eq!(options.delay_between_requests, Duration::from_millis(50));
    assert_eq!(options.delay_after_connect, Duration::from_secs(1));
    let r = |name: &str| {
        modbus(driver)
            .registers
            .iter()
            .find(|r| r.name == name)
            .unwrap()
    };
    assert_eq!(
        r("voltage").format,
        Format::new(DataType::Float32, Order::Cdab)
    );
    assert_eq!(
        r("voltage").deadband,
        Some(Deadband::Absolute(0.5)),
        "the device's deadband"
    );
    assert_eq!(r("energy").format.scaling, Scaling::new(0.01, 5.0).unwrap());
    assert_eq!(r("energy").deadband, Some(Deadband::Percent(1.0)));
    assert_eq!(r("limit").writable, Some((-1000.0, 1000.0)));
    assert_eq!(
        (r("pump").table, r("pump").writable),
        (RegisterTable::Coil, Some((0.0, 1.0)))
    );
    assert_eq!(r("door").table, RegisterTable::Discrete);
    assert_eq!(r("door").deadband, None, "bits have no deadband");
    assert_eq!(r("label").deadband, None, "text has no deadband");
    let defaults = parse(CHILLER).unwrap();
    let chiller = &defaults.lines[0].devices[0];
    assert_eq!(chiller.deadband, None);
    assert_eq!(modbus(&chiller.driver).options, ModbusOptions::default());
    assert_eq!(
        modbus(&chiller.driver).options.plan.max_registers.get(),
        125
    );
    assert_eq!(modbus(&chiller.driver).options.plan.max_bits.get(), 2000);
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
fn modbus_field_mistakes_are_refused_naming_register_field_and_place() {
    let cases: [(&str, &str, usize, usize, &str); 14] = [
        (
            "type = \"float32\"\norder",
            "type = \"float33\"\norder",
            20,
            8,
            "register voltage: `float33` is not a data type",
        ),
        (
            "order = \"CDAB\"",
            "order = \"ACBD\"",
            21,
            9,
            "register voltage: `ACBD` is not a byte order",
        ),
        (
            "offset = 5",
            "offset = nan",
            30,
            10,
            "register energy: offset NaN must be a number",
        ),
        (
            "deadband_percent = 1\n",
            "deadband_percent = 1\ndeadband = 2\n",
            31,
            20,
            "deadband and deadband_percent both given",
        ),
        (
            "deadband_percent = 1\n",
            "deadband_percent = 150\n",
            31,
            20,
            "deadband_percent 150 is out of range",
        ),
        (
            "deadband = 0.5",
            "deadband = -1",
            14,
            12,
            "deadband -1 must be a number of at least 0",
        ),
        (
            "max_registers_per_request = 60",
            "max_registers_per_request = 126",
            9,
            29,
            "max_registers_per_request 126 is out of range: 1 to 125",
        ),
        (
            "max_bits_per_request = 800",
            "max_bits_per_request = 0",
            10,
            24,
            "max_bits_per_request 0 is out of range: 1 to 2000",
        ),
        (
            "delay_between_requests = \"50ms\"",
            "delay_between_requests = \"fast\"",
            12,
            26,
            "delay_between_requests \"fast\" is not a duration",
        ),
        (
            "delay_after_connect = \"1s\"",
            "delay_after_connect = \"2m\"",
            13,
            23,
            "delay_after_connect 2m is out of range",
        ),
        (
            "table = \"discrete\"\naddress = 0x20\n",
            "table = \"discrete\"\naddress = 0x20\nwritable = true\n",
            49,
            12,
            "register door: only holding registers and coils can be written; discrete inputs are read-only",
        ),
        (
            "type = \"string:4\"\n",
            "type = \"string:4\"\nwritable = true\n",
            54,
            12,
            "register label: a string:4 register is read-only here",
        ),
        (
            "table = \"coil\"\naddress = 3\n",
            "table = \"coil\"\naddress = 3\ntype = \"int16\"\n",
            43,
            8,
            "register pump: type is for holding and input registers; a coil is a single bit",
        ),
        (
            "address = 0x0400",
            "address = 65534",
            52,
            11,
            "register label: a string:4 at 65534 runs past the last address 65535",
        ),
    ];
    for (from, to, line, column, words) in cases {
        assert!(METER.contains(from), "{from}");
        refused(&METER.replacen(from, to, 1), line, column, words);
    }
    refused(
        &CHILLER.replace("signed = true", "signed = true\ntype = \"int32\""),
        17,
        10,
        "register supply: signed is the old way of saying type = \"int16\"; give type only",
    );
    refused(
        &format!("{ONE}one_request_per_register = true\n"),
        9,
        28,
        "one_request_per_register is for modbus devices only, not jbc devices",
    );
    refused(
        &format!("{ONE}registers_csv = \"x.csv\"\n"),
        9,
        17,
        "registers_csv is for modbus devices only",
    );
    refused(
        &METER.replace(
            "deadband = 0.5",
            "deadband = 0.5\nregisters_csv = \"meter.csv\"",
        ),
        15,
        17,
        "registers_csv and [[line.device.register]] tables both given",
    );
}

fn csv_cell(dir: &Path, csv: &str) -> Result<CellConfig, ConfigError> {
    std::fs::write(dir.join("meter.csv"), csv).unwrap();
    let toml = String::from(
        "[[line]]\nname = \"utilities\"\nendpoint = \"modbus-tcp://192.0.2.61\"\n\n\
         [[line.device]]\nid = \"meter1\"\nprotocol = \"modbus\"\nregisters_csv = \"meter.csv\"\n",
    );
    let path = dir.join("cell.toml");
    std::fs::write(&path, toml).unwrap();
    check_config(&path)
}

#[test]
fn meters_naming_one_registers_csv_share_its_registers_and_their_point_descriptions() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("meter.csv"),
        "address,name,type,table\n0,voltage,uint16,input\n1,current,uint16,input\n",
    )
    .unwrap();
    let device = |id: &str, unit: u8, extra: &str| {
        format!(
            "[[line.device]]\nid = \"{id}\"\nprotocol = \"modbus\"\naddress = {unit}\n\
             registers_csv = \"meter.csv\"\n{extra}\n"
        )
    };
    let toml = format!(
        "[[line]]\nname = \"utilities\"\nendpoint = \"modbus-tcp://192.0.2.61\"\n\n{}{}{}",
        device("meter1", 1, ""),
        device("meter2", 2, ""),
        device("meter3", 3, "deadband = 0.5"),
    );
    let path = dir.path().join("cell.toml");
    std::fs::write(&path, toml).unwrap();
    let config = check_config(&path).unwrap();
    let points: Vec<Vec<crate::point::PointSpec>> = config.lines[0]
        .devices
        .iter()
        .map(|d| d.driver.build().unwrap().points())
        .collect();
    let shared = |a: usize, b: usize| {
        points[a]
            .iter()
            .zip(&points[b])
            .all(|(a, b)| std::sync::Arc::ptr_eq(&a.description, &b.description))
    };
    assert_eq!(points[0][1].id.as_str(), "meter1.current");
    assert_eq!(points[1][1].id.as_str(), "meter2.current");
    assert!(shared(0, 1), "one file, one deadband: one list");
    assert!(!shared(0, 2), "another deadband is another list");
    let deadbands: Vec<_> = config.lines[0]
        .devices
        .iter()
        .map(|d| modbus(&d.driver).registers[0].deadband)
        .collect();
    assert_eq!(
        deadbands,
        [None, None, Some(Deadband::Absolute(0.5))],
        "each device keeps its own deadband"
    );
}

#[test]
fn a_csv_register_list_is_read_relative_to_the_config_file_with_columns_in_any_order() {
    let dir = tempfile::tempdir().unwrap();
    let config = csv_cell(
        dir.path(),
        "# a meter\nunit,address,name,type,order,table,scale,writable_min,writable_max,title\n\
         V,0x0000,voltage_l1,float32,CDAB,input,,,,Voltage L1-N\n\
         kW,256,limit,uint16,,,0.1,0,200,\n",
    )
    .unwrap();
    let registers = &modbus(&config.lines[0].devices[0].driver).registers;
    assert_eq!(registers.len(), 2);
    assert_eq!(registers[0].title, "Voltage L1-N");
    assert_eq!(registers[0].table, RegisterTable::Input);
    assert_eq!(
        registers[0].format,
        Format::new(DataType::Float32, Order::Cdab)
    );
    assert_eq!(registers[1].address, 256);
    assert_eq!(registers[1].table, RegisterTable::Holding, "empty: default");
    assert_eq!(registers[1].writable, Some((0.0, 200.0)));
    assert_eq!(registers[1].unit.as_deref(), Some("kW"));
}

#[test]
fn a_registers_csv_with_a_header_and_no_rows_is_refused_like_a_device_without_registers() {
    let dir = tempfile::tempdir().unwrap();
    for csv in ["name,address\n", "# a meter\nname,address\n# no rows yet\n"] {
        let err = csv_cell(dir.path(), csv).unwrap_err().to_string();
        assert!(
            err.contains("meter.csv names no registers") && err.contains("cell.toml:"),
            "{csv:?}: {err}"
        );
    }
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
fn a_registers_csv_that_is_not_a_small_file_is_refused_without_reading_it_all() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cell.toml");
    for (csv, words) in [
        ("/dev/zero", "is not a file"),
        (".", "is not a file"),
        ("missing.csv", "cannot be read"),
    ] {
        std::fs::write(
            &path,
            format!(
                "[[line]]\nname = \"utilities\"\nendpoint = \"modbus-tcp://192.0.2.61\"\n\n\
                 [[line.device]]\nid = \"meter1\"\nprotocol = \"modbus\"\nregisters_csv = \"{csv}\"\n"
            ),
        )
        .unwrap();
        let error = check_config(&path).unwrap_err().to_string();
        assert!(error.contains(words), "{csv}: {error}");
    }
    let big = dir.path().join("big.csv");
    std::fs::write(&big, vec![b'a'; (MAX_REGISTERS_CSV + 1) as usize]).unwrap();
    let error = read_bounded(&big, MAX_REGISTERS_CSV).unwrap_err();
    assert!(error.contains("larger than 4 MiB"), "{error}");
}

#[test]
fn csv_mistakes_name_the_file_row_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let header = "name,table,address,type\n";
    for (rows, words) in [
        (
            "a,input,0x10,float32\nb,input,0x1G,float32\n",
            "meter.csv: row 3: column \"address\": \"0x1G\" is not an address",
        ),
        (
            "a,input,0x10,float32\nb,inputs,0x12,float32\n",
            "meter.csv: row 3: column \"table\": register b: table \"inputs\" is not one",
        ),
        (
            "a,input,0x10,float99\n",
            "meter.csv: row 2: column \"type\": register a: `float99` is not a data type",
        ),
        (
            "a,input,0x10,float32\na,input,0x12,float32\n",
            "meter.csv: row 3: column \"name\": register name \"a\" is used twice",
        ),
        (
            ",input,0x10,float32\n",
            "meter.csv: row 2: column \"name\": empty",
        ),
        ("a,input,0x10\n", "meter.csv: row 2: "),
    ] {
        let err = csv_cell(dir.path(), &format!("{header}{rows}")).unwrap_err();
        let shown = err.to_string();
        assert!(shown.contains(words), "{shown}\nwanted: {words}");
    }
    let err = csv_cell(dir.path(), "name,adress\n")
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("row 1: column \"adress\" is not one cellbus knows"),
        "{err}"
    );
    let err = csv_cell(dir.path(), "name,title\n")
        .unwrap_err()
        .to_string();
    assert!(err.contains("row 1: no column \"address\""), "{err}");
    std::fs::remove_file(dir.path().join("meter.csv")).unwrap();
    let err = check_config(&dir.path().join("cell.toml")).unwrap_err();
    assert_eq!(err.position(), Some((8, 17)), "{err}");
    assert!(
        err.to_string().contains("registers_csv")
            && err.to_string().contains("meter.csv: cannot be read"),
        "{err}"
    );
}

#[test]
fn the_example_energy_meter_csv_becomes_toml_that_parses_to_the_same_registers() {
    let csv = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/energy-meter.csv");
    let registers = registers_from_csv(&csv).unwrap();
    assert!(registers.len() >= 12, "{}", registers.len());
    let toml = registers_toml(&registers);
    let config = parse(&format!(
        "[[line]]\nname = \"l\"\nendpoint = \"modbus-tcp://192.0.2.61\"\n\n\
         [[line.device]]\nid = \"meter1\"\nprotocol = \"modbus\"\n\n{toml}"
    ))
    .unwrap();
    assert_eq!(
        *modbus(&config.lines[0].devices[0].driver).registers,
        *registers
    );
}

#[test]
fn no_mqtt_table_means_no_mqtt() {
    assert_eq!(mqtt_table(&parse(ONE).unwrap()), None);
}

#[test]
fn an_mqtt_table_is_read_with_its_defaults() {
    let text =
        format!("{ONE}\n[mqtt]\nbroker = \"mqtt://broker.local\"\nedge_node_id = \"cell-7\"\n");
    let mqtt = mqtt_table(&parse(&text).unwrap()).unwrap();
    assert_eq!((mqtt.host.as_str(), mqtt.port), ("broker.local", 1883));
    assert_eq!(mqtt.group_id, "cellbus");
    assert_eq!(mqtt.client_id, "cellbus-cell-7");
    assert_eq!(mqtt.keep_alive, DEFAULT_MQTT_KEEP_ALIVE);
    assert_eq!((mqtt.username, mqtt.password_env), (None, None));
}

#[test]
fn mqtt_mistakes_are_refused_where_they_are() {
    let at = |table: &str| format!("{ONE}\n[mqtt]\n{table}");
    refused(
        &at("broker = \"http://b\"\n"),
        11,
        10,
        "write mqtt://host:1883",
    );
    refused(
        &at("broker = \"mqtt://b\"\npassword = \"x\"\n"),
        12,
        1,
        "unknown field `password`",
    );
    refused(
        &at("broker = \"mqtt://b\"\ngroup_id = \"a/b\"\n"),
        12,
        12,
        "group_id",
    );
    refused(
        &at("broker = \"mqtt://b\"\nkeep_alive = \"1ms\"\n"),
        12,
        14,
        "keep_alive",
    );
    refused(
        &at("broker = \"mqtt://b:0\"\n"),
        11,
        10,
        "port 0 is not a port a broker listens on",
    );
    refused(
        &at(&format!(
            "broker = \"mqtt://b\"\nclient_id = \"{}\"\n",
            "c".repeat(70_000)
        )),
        12,
        13,
        "client_id is 70000 bytes; MQTT carries at most 65535",
    );
}

#[test]
fn the_mqtt_modes_commands_primary_host_and_backlog_are_read_with_their_defaults() {
    let text = format!("{ONE}\n[mqtt]\nbroker = \"mqtt://b\"\nedge_node_id = \"cell-7\"\n");
    let mqtt = mqtt_table(&parse(&text).unwrap()).unwrap();
    assert_eq!(mqtt.mode, MqttMode::Sparkplug);
    assert_eq!(mqtt.prefix, "cellbus/cell-7");
    assert!(!mqtt.commands);
    assert_eq!(mqtt.primary_host, None);
    assert_eq!(mqtt.max_backlog, DEFAULT_MQTT_BACKLOG);
    assert_eq!(mqtt.max_command_metrics, DEFAULT_MQTT_COMMAND_METRICS);
    assert_eq!(mqtt.check_retained, DEFAULT_MQTT_CHECK_RETAINED);
    let text = format!(
        "{ONE}\n[mqtt]\nbroker = \"mqtt://b\"\nmode = \"JSON\"\nprefix = \"plant/cell7/\"\n\
         commands = true\nprimary_host = \"scada\"\nmax_backlog = 5000\n\
         max_command_metrics = 8\ncheck_retained = \"1h\"\n"
    );
    let mqtt = mqtt_table(&parse(&text).unwrap()).unwrap();
    assert_eq!(mqtt.mode, MqttMode::Json);
    assert_eq!(mqtt.prefix, "plant/cell7", "a trailing / is dropped");
    assert!(mqtt.commands);
    assert_eq!(mqtt.primary_host.as_deref(), Some("scada"));
    assert_eq!(mqtt.max_backlog, 5000);
    assert_eq!(mqtt.max_command_metrics, 8);
    assert_eq!(mqtt.check_retained, Duration::from_secs(3600));
}

#[test]
fn mqtt_mode_prefix_primary_host_and_backlog_mistakes_are_refused_where_they_are() {
    let at = |line: &str| format!("{ONE}\n[mqtt]\nbroker = \"mqtt://b\"\n{line}\n");
    refused(
        &at("mode = \"xml\""),
        12,
        8,
        "write \"sparkplug\" or \"json\"",
    );
    refused(&at("prefix = \"a/#\""), 12, 10, "not a usable topic prefix");
    refused(&at("primary_host = \"a+b\""), 12, 16, "primary_host");
    refused(&at("max_backlog = 0"), 12, 15, "outside 1–100000000");
    refused(&at("max_command_metrics = 0"), 12, 23, "outside 1–10000");
    refused(&at("check_retained = \"1s\""), 12, 18, "out of range");
    refused(&at("commands = \"yes\""), 12, 12, "bool");
}

#[test]
fn an_mqtts_broker_takes_port_8883_and_trusts_the_systems_roots_by_default() {
    let text = format!("{ONE}\n[mqtt]\nbroker = \"mqtts://broker.local\"\n");
    let mqtt = mqtt_table(&parse(&text).unwrap()).unwrap();
    assert_eq!((mqtt.host.as_str(), mqtt.port), ("broker.local", 8883));
    assert_eq!(mqtt.tls, Some(MqttTls::default()));
    let cli = MqttConfig::for_broker("mqtts://b:18883", "cell").unwrap();
    assert_eq!((cli.port, cli.tls), (18883, Some(MqttTls::default())));
    let plain = MqttConfig::for_broker("mqtt://b", "cell").unwrap();
    assert_eq!((plain.port, plain.tls), (1883, None));
}

#[test]
fn tls_keys_with_an_mqtt_broker_are_refused_naming_the_key() {
    let at = |table: &str| format!("{ONE}\n[mqtt]\nbroker = \"mqtt://b\"\n{table}");
    refused(&at("ca_file = \"ca.pem\"\n"), 12, 11, "ca_file is for TLS");
    refused(
        &at("client_key = \"k.pem\"\n"),
        12,
        14,
        "client_key is for TLS",
    );
}

#[test]
fn a_client_cert_without_its_key_is_refused_and_the_other_way_round() {
    let at = |table: &str| format!("{ONE}\n[mqtt]\nbroker = \"mqtts://b\"\n{table}");
    refused(
        &at("client_cert = \"c.pem\"\n"),
        12,
        15,
        "client_cert needs client_key",
    );
    refused(
        &at("client_key = \"k.pem\"\n"),
        12,
        14,
        "client_key needs client_cert",
    );
}

#[test]
fn tls_files_are_read_relative_to_the_config_file_and_named_when_missing() {
    let text = format!("{ONE}\n[mqtt]\nbroker = \"mqtts://b\"\nca_file = \"certs/ca.pem\"\n");
    let err = parse_config(&text, Path::new("/nonexistent/cellbus/cell.toml"))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains(":12:11: ca_file /nonexistent/cellbus/certs/ca.pem: cannot be read"),
        "{err}"
    );
}

#[test]
fn tls_files_that_are_not_pem_are_refused_without_showing_a_key() {
    let dir = tempfile::tempdir().unwrap();
    let key = rcgen::KeyPair::generate().unwrap();
    let cert = rcgen::CertificateParams::new(vec!["gateway".to_owned()])
        .unwrap()
        .self_signed(&key)
        .unwrap();
    std::fs::write(dir.path().join("ca.pem"), cert.pem()).unwrap();
    std::fs::write(dir.path().join("gateway.pem"), cert.pem()).unwrap();
    std::fs::write(dir.path().join("gateway.key"), key.serialize_pem()).unwrap();
    std::fs::write(dir.path().join("notes.txt"), "no PEM here").unwrap();
    let secret = key.serialize_pem().replace("PRIVATE KEY", "PRIVAT KEY");
    std::fs::write(dir.path().join("mangled.key"), &secret).unwrap();
    let path = dir.path().join("cell.toml");
    let at = |table: &str| format!("{ONE}\n[mqtt]\nbroker = \"mqtts://b\"\n{table}");

    let good = parse_config(
        &at("ca_file = \"ca.pem\"\nclient_cert = \"gateway.pem\"\nclient_key = \"gateway.key\"\n"),
        &path,
    )
    .unwrap();
    let tls = mqtt_table(&good).unwrap().tls.unwrap();
    assert_eq!(tls.ca_file, Some(dir.path().join("ca.pem")));
    assert_eq!(
        tls.client,
        Some(MqttClientCert {
            cert: dir.path().join("gateway.pem"),
            key: dir.path().join("gateway.key"),
        })
    );

    let err = parse_config(&at("ca_file = \"notes.txt\"\n"), &path)
        .unwrap_err()
        .to_string();
    assert!(err.contains("notes.txt holds no certificate"), "{err}");
    let err = parse_config(
        &at("client_cert = \"gateway.pem\"\nclient_key = \"mangled.key\"\n"),
        &path,
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains(":13:14: client_key "), "{err}");
    assert!(err.contains("mangled.key: "), "{err}");
    let body: String = secret.lines().filter(|l| !l.starts_with("-----")).collect();
    assert!(!err.contains(&body[..16]), "{err}");
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
fn a_broker_url_with_a_user_and_password_is_refused_without_showing_them() {
    let err = parse_broker("mqtt://user:pw@127.0.0.1:1883").unwrap_err();
    assert!(!err.contains("pw") && !err.contains("user:"), "{err}");
    assert!(err.contains("mqtt://(hidden)@127.0.0.1:1883"), "{err}");
    let text = format!("[mqtt]\nbroker = \"mqtt://user:pw@127.0.0.1:1883\"\n{ONE}");
    let shown = parse(&text).unwrap_err().to_string();
    assert!(!shown.contains("pw"), "{shown}");
    assert_eq!(
        hide_userinfo("mqtt://host:1883/a@b"),
        "mqtt://host:1883/a@b"
    );
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
