//! A Modbus TCP energy meter, end to end: `cellbus sim modbus --framing tcp` serving the
//! example map, and `cellbus serve` reading it through the example CSV register list.

mod common;

use std::path::Path;
use std::time::{Duration, Instant};

use common::{Gateway, Sim};

fn example(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../gateway/examples")
        .join(name)
        .to_str()
        .expect("a UTF-8 path")
        .to_owned()
}

/// The Modbus TCP simulator on a free port, serving what `source` names.
fn meter(source: &[&str]) -> Sim {
    Sim::start(
        &[
            &["modbus", "--framing", "tcp", "--listen", "127.0.0.1:0"],
            source,
        ]
        .concat(),
    )
}

/// The points of `device` in `/api/devices`: name → (value, unit).
fn points(gateway: &Gateway, device: &str) -> Vec<(String, serde_json::Value, Option<String>)> {
    let body = gateway.get_json("/api/devices");
    let devices = body["devices"].as_array().unwrap();
    let meter = devices
        .iter()
        .find(|d| d["id"] == device)
        .unwrap_or_else(|| panic!("{device} in {body}"));
    meter["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            let name = p["id"].as_str().unwrap().split_once('.').unwrap().1;
            (
                name.to_owned(),
                p["value"].clone(),
                p["unit"].as_str().map(str::to_owned),
            )
        })
        .collect()
}

/// The value of a metric line that starts with `prefix`.
fn metric(gateway: &Gateway, prefix: &str) -> Option<f64> {
    let (status, body) = gateway.get("/metrics");
    assert_eq!(status, 200, "{body}");
    body.lines()
        .find(|l| l.starts_with(prefix))
        .and_then(|l| l.rsplit(' ').next())
        .and_then(|v| v.parse().ok())
}

#[test]
fn a_simulated_energy_meter_is_read_through_its_csv_register_list_in_the_planned_requests() {
    let sim = meter(&["--map", &example("energy-meter.map")]);
    sim.assert_listens_on("modbus-tcp://");
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(
        example("energy-meter.csv"),
        dir.path().join("energy-meter.csv"),
    )
    .unwrap();
    let config = dir.path().join("cell.toml");
    std::fs::write(
        &config,
        format!(
            "[[line]]\nname = \"supply\"\nendpoint = \"{}\"\n\n\
             [[line.device]]\nid = \"meter1\"\nprotocol = \"modbus\"\naddress = 1\n\
             period = \"200ms\"\nregisters_csv = \"energy-meter.csv\"\n",
            sim.endpoint
        ),
    )
    .unwrap();
    // What the planner promises for the example list: the registers from 0x0000 to 0x0011,
    // and those from 0x0034 to 0x0049 (gaps of at most 10 bridged).
    let registers =
        gateway::driver::modbus::config::registers_from_csv(&dir.path().join("energy-meter.csv"))
            .unwrap();
    let plan = jbus::plan::Plan::new(
        &gateway::driver::modbus::plan_items(&registers),
        jbus::plan::PlanOptions::default(),
    )
    .unwrap();
    assert_eq!(plan.reads().len(), 2);

    let data = tempfile::tempdir().unwrap();
    let gateway = Gateway::start_with(data.path(), &["--config", config.to_str().unwrap()]);
    let deadline = Instant::now() + Duration::from_secs(30);
    let points = loop {
        let points = points(&gateway, "meter1");
        if points.iter().all(|(_, value, _)| !value.is_null()) {
            break points;
        }
        assert!(Instant::now() < deadline, "no values in time: {points:?}");
        std::thread::sleep(Duration::from_millis(100));
    };
    let find = |name: &str| {
        points
            .iter()
            .find(|(n, _, _)| n == name)
            .map(|(_, v, u)| (v.as_f64(), u.as_deref().map(str::to_owned)))
            .unwrap_or_else(|| panic!("{name} in {points:?}"))
    };
    assert_eq!(find("voltage_l1"), (Some(230.1), Some("V".into())));
    assert_eq!(find("current_l3"), (Some(13.1), Some("A".into())));
    assert_eq!(find("active_power_total"), (Some(8.36), Some("kW".into())));
    assert_eq!(find("power_factor_total"), (Some(0.97), None));
    assert_eq!(find("frequency"), (Some(50.02), Some("Hz".into())));
    assert_eq!(find("import_energy"), (Some(123456.7), Some("kWh".into())));
    assert_eq!(points.len(), registers.len());
    assert_eq!(
        metric(
            &gateway,
            "cellbus_modbus_requests_per_poll{line=\"supply\",device=\"meter1\"}"
        ),
        Some(plan.reads().len() as f64),
    );
}

#[test]
fn config_import_csv_prints_register_tables_and_names_the_row_of_a_mistake() {
    let out = common::run(&["config", "import-csv", &example("energy-meter.csv")]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    let toml = common::stdout(&out);
    assert_eq!(
        toml.matches("[[line.device.register]]").count(),
        13,
        "{toml}"
    );
    assert!(
        toml.contains("name = \"import_energy\"\ntitle = \"Total import active energy\"\ntable = \"input\"\naddress = 0x0048\ntype = \"float32\"\nunit = \"kWh\"\n"),
        "{toml}"
    );

    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.csv");
    std::fs::write(&bad, "name,address,type\nv,0,float32\nw,2,float23\n").unwrap();
    let out = common::run(&["config", "import-csv", bad.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    let err = common::stderr(&out);
    assert!(
        err.contains("bad.csv: row 3: column \"type\": register w: `float23` is not a data type"),
        "{err}"
    );
}

#[test]
fn the_examples_shipped_in_the_binary_serve_the_meter_and_configure_the_gateway_to_read_it() {
    // No file of the checkout: what a user of an installed binary has.
    let sim = meter(&["--example", "energy-meter"]);
    let out = common::run(&["config", "example", "--modbus-meter", &sim.endpoint]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("meter.toml");
    std::fs::write(&config, &out.stdout).unwrap();
    let check = common::run(&["config", "check", config.to_str().unwrap()]);
    assert!(check.status.success(), "{}", common::stderr(&check));
    common::assert_stdout_has(&check, "meter1 (modbus, address 1): Energy meter (example)");

    let data = tempfile::tempdir().unwrap();
    let gateway = Gateway::start_with(data.path(), &["--config", config.to_str().unwrap()]);
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let points = points(&gateway, "meter1");
        if let Some((_, value, unit)) = points.iter().find(|(n, _, _)| n == "voltage_l1")
            && value.as_f64() == Some(230.1)
        {
            assert_eq!(unit.as_deref(), Some("V"));
            break;
        }
        assert!(Instant::now() < deadline, "no voltage in time: {points:?}");
        std::thread::sleep(Duration::from_millis(100));
    }
}
