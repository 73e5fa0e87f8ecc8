//! The gateway's Sparkplug B payloads checked by a decoder that is not ours: Python's
//! paho-mqtt and protobuf classes compiled by grpc_tools.protoc from the spec's schema
//! (`crates/sparkplug/proto/sparkplug_b.proto`), against a real mosquitto and
//! `cellbus serve --mqtt`.

mod common;

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use common::{Gateway, require_python};
use serde_json::Value;
use testkit::Mosquitto;

/// The script's own limit for the messages to come, in seconds.
const SCRIPT_LIMIT: u64 = 60;
/// Ours: the script's limit and time to compile the schema and start Python.
const LIMIT: Duration = Duration::from_secs(SCRIPT_LIMIT + 60);

/// The versions scripts/test installs.
const PIP: &str = "paho-mqtt==2.2.0 protobuf==7.36.2 grpcio==1.85.1 grpcio-tools==1.85.1";

fn script() -> String {
    format!(
        "{}/../sparkplug/tests/interop/sparkplug_check.py",
        env!("CARGO_MANIFEST_DIR")
    )
}

/// Fails (never skips) when python3 or its packages are missing: scripts/test installs them.
fn require_python_packages() {
    require_python(
        "import paho.mqtt.client, google.protobuf, grpc_tools.protoc",
        "Sparkplug interoperability test",
        "paho-mqtt, protobuf or grpcio-tools",
        &format!("run scripts/test, which installs them, or: python3 -m pip install {PIP}"),
    );
}

/// The Sparkplug datatype code of a point of `/api/devices` by its kind.
fn datatype_code(kind: &str) -> u64 {
    match kind {
        "numeric" => 10, // Double
        "enum" => 3,     // Int32
        "text" => 12,    // String
        other => panic!("a point kind the gateway does not map: {other}"),
    }
}

#[test]
fn an_independent_python_decoder_finds_every_device_and_point_in_the_births_with_unit_and_datatype()
{
    require_python_packages();
    let broker = Mosquitto::start();

    // The subscriber first: births are not retained, so it must be listening before the
    // gateway connects.
    let mut python = Command::new("python3")
        .arg(script())
        .arg(broker.port().to_string())
        .args(["--limit", &SCRIPT_LIMIT.to_string()])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("python3 runs");
    let (tx, lines) = mpsc::channel();
    let stdout = python.stdout.take().expect("piped");
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    let stderr = python.stderr.take().expect("piped");
    let errors = std::thread::spawn(move || {
        let mut text = String::new();
        let _ = std::io::Read::read_to_string(&mut BufReader::new(stderr), &mut text);
        text
    });
    let first = lines.recv_timeout(LIMIT);
    assert_eq!(
        first.as_deref(),
        Ok("subscribed"),
        "the script's first line; its stderr: {}",
        {
            let _ = python.kill();
            errors.join().unwrap_or_default()
        }
    );

    let data = tempfile::tempdir().unwrap();
    let gateway = Gateway::start_with(data.path(), &["--mqtt", &broker.url()]);
    let summary = lines.recv_timeout(LIMIT);
    let status = python.wait().expect("python3 can be waited for");
    let errors = errors.join().unwrap_or_default();
    let summary = summary.unwrap_or_else(|e| panic!("no summary from the script ({e}): {errors}"));
    assert!(status.success(), "the script failed: {errors}");
    let summary: Value =
        serde_json::from_str(&summary).unwrap_or_else(|e| panic!("{e}: {summary}"));

    // The node's birth: bdSeq and the rebirth control, as the spec asks.
    assert_eq!(summary["node"]["bdSeq"]["datatype"], 4, "bdSeq is Int64");
    assert_eq!(
        summary["node"]["Node Control/Rebirth"]["datatype"], 11,
        "Node Control/Rebirth is Boolean"
    );

    // Every device and point of /api/devices, with its unit and datatype.
    let api = gateway.get_json("/api/devices");
    let devices = api["devices"].as_array().unwrap();
    assert!(!devices.is_empty());
    for device in devices {
        let id = device["id"].as_str().unwrap();
        let birth = summary["devices"]
            .get(id)
            .unwrap_or_else(|| panic!("no DBIRTH for {id}: {}", summary["devices"]));
        for point in device["points"].as_array().unwrap() {
            let point_id = point["id"].as_str().unwrap();
            let name = point_id.split_once('.').unwrap().1;
            let metric = birth
                .get(name)
                .unwrap_or_else(|| panic!("{point_id} is not in the DBIRTH of {id}"));
            assert_eq!(
                metric["datatype"],
                datatype_code(point["kind"]["type"].as_str().unwrap()),
                "{point_id}"
            );
            assert_eq!(metric["unit"], point["unit"], "{point_id}");
            assert!(
                metric["alias"].is_u64(),
                "{point_id} has an alias: {metric}"
            );
        }
    }

    // Aliases are unique across the node, and every DDATA alias is one of its device's
    // birth metrics.
    let mut owners: BTreeMap<u64, String> = BTreeMap::new();
    let births = std::iter::once(("(node)", &summary["node"])).chain(
        summary["devices"]
            .as_object()
            .unwrap()
            .iter()
            .map(|(d, b)| (d.as_str(), b)),
    );
    for (owner, birth) in births {
        for (name, metric) in birth.as_object().unwrap() {
            if let Some(alias) = metric["alias"].as_u64()
                && let Some(before) = owners.insert(alias, format!("{owner}/{name}"))
            {
                panic!("alias {alias} is both {before} and {owner}/{name}");
            }
        }
    }
    let ddata = summary["data"].as_array().unwrap();
    assert!(!ddata.is_empty(), "the script waits for a DDATA");
    for message in ddata {
        let device = message["device"].as_str().unwrap();
        for metric in message["metrics"].as_array().unwrap() {
            let alias = metric["alias"].as_u64().unwrap_or_else(|| {
                panic!("DDATA of {device} names a metric without alias: {metric}")
            });
            let name = metric["name"].as_str().unwrap_or_else(|| {
                panic!("alias {alias} in a DDATA of {device} is in no metric of its DBIRTH")
            });
            assert_eq!(
                summary["devices"][device][name]["alias"], alias,
                "{device}: {name}"
            );
        }
    }
}
