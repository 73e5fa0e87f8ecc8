//! A Modbus device's keys and registers (tables and CSV lists): what they read, the
//! warnings about shared registers, and each mistake where it is.

use std::path::Path;

use super::*;
use crate::EXAMPLE_CONFIG;
use crate::config::table::read_bounded;
use crate::config::{CellConfig, ConfigError};
use crate::driver::DriverConfig;
use crate::driver::modbus::{ModbusOptions, RegisterConfig, RegisterTable};
use crate::plugins::check_config;
use crate::testing::config::{ONE, parse, refused};
use jbus::data::{DataType, Format, Order, Scaling};
use link::Endpoint;

/// A modbus device's registers and options.
fn modbus(driver: &DriverConfig) -> &ModbusSettings {
    driver
        .settings
        .get()
        .expect("a modbus device has its settings")
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
