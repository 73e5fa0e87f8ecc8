//! `cellbus mqtt sub` end to end: a real mosquitto, `cellbus serve --mqtt` (the demo cell)
//! and `cellbus mqtt sub` as child processes.

mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::io::{BufRead, BufReader};
use std::process::Child;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use common::{Gateway, assert_stderr_has, run, spawn_piped, stderr};
use testkit::{Mosquitto, Subscriber};

/// Waits for MQTT: generous, for a loaded 2-core machine.
const LIMIT: Duration = Duration::from_secs(60);

/// A running `cellbus mqtt sub`, killed on drop; its stdout and stderr lines as they come.
struct Sub {
    child: Child,
    stdout: mpsc::Receiver<String>,
    stderr: mpsc::Receiver<String>,
}

impl Sub {
    /// Starts `cellbus mqtt sub ARGS…` and returns once it says it has subscribed.
    fn start(args: &[&str]) -> Sub {
        let mut child = spawn_piped(&[&["mqtt", "sub"], args].concat());
        let stdout = lines(child.stdout.take().expect("piped"));
        let stderr = lines(child.stderr.take().expect("piped"));
        let sub = Sub {
            child,
            stdout,
            stderr,
        };
        let line = sub
            .stderr
            .recv_timeout(LIMIT)
            .unwrap_or_else(|e| panic!("cellbus mqtt sub said nothing on stderr: {e}"));
        assert!(
            line.starts_with("cellbus: subscribed to "),
            "first stderr line: {line:?}"
        );
        sub
    }

    /// The next stdout line, within [`LIMIT`].
    fn line(&self) -> String {
        self.stdout.recv_timeout(LIMIT).unwrap_or_else(|e| {
            let err: Vec<String> = self.stderr.try_iter().collect();
            panic!("no line from cellbus mqtt sub within {LIMIT:?} ({e}); stderr: {err:?}")
        })
    }

    /// Waits (bounded) for the process to end; its exit code.
    fn wait(&mut self) -> Option<i32> {
        let deadline = Instant::now() + LIMIT;
        while Instant::now() < deadline {
            if let Some(status) = self.child.try_wait().expect("the child can be waited for") {
                return status.code();
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        panic!("cellbus mqtt sub did not end within {LIMIT:?}");
    }
}

impl Drop for Sub {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The lines of `reader`, read by a thread, as a channel (closed at end of file).
fn lines(reader: impl std::io::Read + Send + 'static) -> mpsc::Receiver<String> {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(reader).lines() {
            let Ok(line) = line else { break };
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    rx
}

/// Every device of the gateway's `/api/devices`: point name → (unit, Sparkplug datatype).
fn api_devices(
    gateway: &Gateway,
) -> BTreeMap<String, BTreeMap<String, (Option<String>, &'static str)>> {
    let body = gateway.get_json("/api/devices");
    body["devices"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| {
            let device = d["id"].as_str().unwrap().to_owned();
            let points = d["points"]
                .as_array()
                .unwrap()
                .iter()
                .map(|p| {
                    let id = p["id"].as_str().unwrap();
                    let name = id.split_once('.').unwrap().1.to_owned();
                    let unit = p["unit"].as_str().map(str::to_owned);
                    let datatype = match p["kind"]["type"].as_str().unwrap() {
                        "numeric" => "Double",
                        "enum" => "Int32",
                        "text" => "String",
                        other => panic!("{id}: kind {other}"),
                    };
                    (name, (unit, datatype))
                })
                .collect();
            (device, points)
        })
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sub_json_shows_every_demo_device_birth_with_each_point_its_unit_and_datatype() {
    let broker = Mosquitto::start();
    let mut node = Subscriber::start(broker.port(), "spBv1.0/cellbus/+/demo").await;
    let data = tempfile::tempdir().unwrap();
    let gateway = Gateway::start_with(data.path(), &["--mqtt", &broker.url()]);
    node.next_where("the gateway's NBIRTH", LIMIT, |m| m.kind() == "NBIRTH")
        .await;
    let devices = api_devices(&gateway);
    let count = devices.len().to_string();

    // Births are not retained: subscribe, then ask the node for them again.
    let mut sub = Sub::start(&[
        "--broker",
        &broker.url(),
        "--json",
        "--count",
        &count,
        "--timeout",
        "60s",
        "spBv1.0/cellbus/DBIRTH/#",
    ]);
    node.publish("spBv1.0/cellbus/NCMD/demo", testkit::rebirth_command())
        .await;

    let mut births = BTreeMap::new();
    for _ in 0..devices.len() {
        let line = sub.line();
        let birth: serde_json::Value =
            serde_json::from_str(&line).unwrap_or_else(|e| panic!("{e}: {line}"));
        assert_eq!(birth["kind"], "DBIRTH", "{line}");
        assert_eq!(birth["group"], "cellbus");
        assert_eq!(birth["edge_node"], "demo");
        assert!(
            birth["seq"].is_u64() && birth["timestamp"].is_u64(),
            "{line}"
        );
        births.insert(birth["device"].as_str().unwrap().to_owned(), birth);
    }
    assert_eq!(sub.wait(), Some(0), "--count {count} ends the run with 0");
    assert_eq!(
        births.keys().collect::<BTreeSet<_>>(),
        devices.keys().collect::<BTreeSet<_>>()
    );
    for (device, points) in &devices {
        let metrics = births[device]["metrics"].as_array().unwrap();
        for (point, (unit, datatype)) in points {
            let metric = metrics
                .iter()
                .find(|m| m["name"] == point.as_str())
                .unwrap_or_else(|| panic!("{device}.{point} is not in its DBIRTH"));
            assert_eq!(metric["datatype"], *datatype, "{device}.{point}");
            assert!(metric["alias"].is_u64(), "{device}.{point}: {metric}");
            assert_eq!(
                metric["properties"]["engUnit"].as_str(),
                unit.as_deref(),
                "{device}.{point}"
            );
        }
    }
    let unit = |device: &str, name: &str| {
        births[device]["metrics"]
            .as_array()
            .unwrap()
            .iter()
            .find(|m| m["name"] == name)
            .map(|m| m["properties"]["engUnit"].clone())
    };
    assert_eq!(unit("jbc1", "air_temperature"), Some("°C".into()));
}

#[test]
fn sub_in_words_prints_births_then_data_with_aliases_named_from_the_births() {
    let broker = Mosquitto::start();
    let sub = Sub::start(&[
        "--broker",
        &broker.url(),
        "--timeout",
        "60s",
        "spBv1.0/cellbus/#",
    ]);
    let data = tempfile::tempdir().unwrap();
    let _gateway = Gateway::start_with(data.path(), &["--mqtt", &broker.url()]);

    let head = sub.line();
    assert!(
        head.starts_with("spBv1.0/cellbus/NBIRTH/demo seq=0 timestamp=20")
            && head.ends_with(" metrics)"),
        "{head}"
    );
    assert!(sub.line().starts_with("  bdSeq: Int64 "));
    // Lines arrive as messages do (stdout is flushed per message): read until a DDATA
    // whose device's DBIRTH came before it.
    let mut born = BTreeSet::new();
    let mut device = String::new();
    let mut kind = String::new();
    let mut birth_lines = Vec::new();
    loop {
        let line = sub.line();
        if let Some(metric) = line.strip_prefix("  ") {
            if kind == "DBIRTH" {
                birth_lines.push(metric.to_owned());
            }
            if kind == "DDATA" && born.contains(&device) {
                assert!(
                    metric.contains(" (alias ") && !metric.starts_with("alias "),
                    "a DDATA metric after its DBIRTH is named: {line}"
                );
                break;
            }
            continue;
        }
        let topic = line.split(' ').next().unwrap();
        let levels: Vec<&str> = topic.split('/').collect();
        assert!(line.contains(" seq="), "{line}");
        kind = levels[2].to_owned();
        device = levels.get(4).copied().unwrap_or_default().to_owned();
        if kind == "DBIRTH" {
            born.insert(device.clone());
        }
    }
    assert!(
        birth_lines
            .iter()
            .any(|l| l.starts_with("air_temperature (alias ") && l.contains(" unit °C ")),
        "jbc1's air temperature in °C: {birth_lines:#?}"
    );
    assert!(
        birth_lines
            .iter()
            .any(|l| l.contains(" writable 150..450 ")),
        "a write range in a birth: {birth_lines:#?}"
    );
}

#[test]
fn sub_with_a_bad_broker_url_exits_2_naming_it() {
    let out = run(&["mqtt", "sub", "--broker", "htp://127.0.0.1:1883"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert_stderr_has(&out, "htp://127.0.0.1:1883");

    let out = run(&["mqtt", "sub", "--broker", "mqtt://127.0.0.1:1883", "a/#/b"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert_stderr_has(&out, "\"a/#/b\"");
}

#[test]
fn sub_to_a_closed_port_exits_1_naming_the_broker() {
    let url = format!("mqtt://127.0.0.1:{}", testkit::free_port());
    let out = run(&["mqtt", "sub", "--broker", &url, "--timeout", "30s"]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert_stderr_has(&out, &format!("cannot connect to broker {url}"));
}

#[test]
fn sub_exits_1_when_its_timeout_passes_without_a_message_and_when_the_broker_goes() {
    let mut broker = Mosquitto::start();
    let url = broker.url();
    let out = run(&[
        "mqtt",
        "sub",
        "--broker",
        &url,
        "--timeout",
        "300ms",
        "nobody/#",
    ]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert_stderr_has(
        &out,
        &format!("no message from {url} on nobody/# within 300ms"),
    );

    let mut sub = Sub::start(&["--broker", &url, "nobody/#"]);
    broker.kill();
    assert_eq!(sub.wait(), Some(1));
    let err: String = sub.stderr.try_iter().collect();
    assert!(
        err.contains(&format!("lost the connection to broker {url}")),
        "{err}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn json_mode_keeps_a_retained_message_per_point_and_the_will_says_offline() {
    let broker = Mosquitto::start();
    let data = tempfile::tempdir().unwrap();
    let url = broker.url();
    let gateway = Gateway::start_with(data.path(), &["--mqtt", &url, "--mqtt-mode", "json"]);
    // The gateway's status and every point are retained: a subscriber that comes later
    // gets them at once. Waiting for `online` first makes sure the points were published.
    let mut status = Sub::start(&[
        "--broker",
        &url,
        "--json",
        "--count",
        "1",
        "cellbus/demo/status",
    ]);
    let line = status.line();
    let message: serde_json::Value = serde_json::from_str(&line).unwrap();
    assert_eq!(message["payload"], "online", "{line}");
    assert_eq!(status.wait(), Some(0));

    let devices = api_devices(&gateway);
    let points: usize = devices.values().map(BTreeMap::len).sum();
    let statuses = devices.len();
    let mut all = Sub::start(&[
        "--broker",
        &url,
        "--json",
        "--count",
        &(points + statuses).to_string(),
        "cellbus/demo/+/+",
    ]);
    let mut seen = BTreeSet::new();
    for _ in 0..points + statuses {
        let line = all.line();
        let message: serde_json::Value = serde_json::from_str(&line).unwrap();
        let topic = message["topic"].as_str().unwrap().to_owned();
        let (device, point) = topic
            .strip_prefix("cellbus/demo/")
            .and_then(|rest| rest.split_once('/'))
            .unwrap_or_else(|| panic!("{topic}"));
        let payload = message["payload"].as_str().unwrap();
        if point == "status" {
            assert!(["online", "offline"].contains(&payload), "{line}");
        } else {
            let (unit, _) = &devices[device][point];
            let value: serde_json::Value = serde_json::from_str(payload).unwrap();
            assert_eq!(value["unit"].as_str(), unit.as_deref(), "{line}");
            assert!(value["t"].is_i64() || value["t"].is_null(), "{line}");
            let quality = value["quality"].as_str().unwrap();
            assert!(
                ["good", "stale", "bad", "unknown"].contains(&quality),
                "{line}"
            );
            assert_eq!(
                value["value"].is_null(),
                quality != "good",
                "a value only when good: {line}"
            );
        }
        seen.insert(topic);
    }
    assert_eq!(all.wait(), Some(0));
    assert_eq!(
        seen.len(),
        points + statuses,
        "one retained message per topic"
    );

    // kill -9: the broker publishes the Will, which stays as the gateway's status.
    drop(gateway);
    let status = Sub::start(&[
        "--broker",
        &url,
        "--json",
        "--timeout",
        "60s",
        "cellbus/demo/status",
    ]);
    loop {
        let line = status.line();
        let message: serde_json::Value = serde_json::from_str(&line).unwrap();
        if message["payload"] == "offline" {
            break;
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sub_started_after_the_births_says_so_and_with_rebirth_asks_the_node_and_names_its_metrics()
{
    let broker = Mosquitto::start();
    let mut node = Subscriber::start(broker.port(), "spBv1.0/cellbus/+/demo").await;
    let data = tempfile::tempdir().unwrap();
    let _gateway = Gateway::start_with(data.path(), &["--mqtt", &broker.url()]);
    node.next_where("the demo's NBIRTH", LIMIT, |m| m.kind() == "NBIRTH")
        .await;

    // Born before it subscribed: data by alias only, and a word on what to do.
    let late = Sub::start(&["--broker", &broker.url(), "spBv1.0/cellbus/#"]);
    let advice = late.stderr.recv_timeout(LIMIT).expect("advice on stderr");
    assert!(
        advice.contains("node cellbus/demo names metrics by alias and its birth was not seen")
            && advice.contains("--rebirth"),
        "{advice}"
    );
    drop(late);

    let asking = Sub::start(&["--broker", &broker.url(), "--rebirth", "spBv1.0/cellbus/#"]);
    let asked = asking.stderr.recv_timeout(LIMIT).expect("a word on stderr");
    assert!(
        asked.contains("asked it for a rebirth (spBv1.0/cellbus/NCMD/demo)"),
        "{asked}"
    );
    let mut born = false;
    loop {
        let line = asking.line();
        if line.starts_with("spBv1.0/cellbus/NBIRTH/demo ") {
            born = true;
        }
        if born && line.starts_with("spBv1.0/cellbus/DDATA/") {
            let metric = asking.line();
            assert!(
                metric.contains(" (alias ") && !metric.trim_start().starts_with("alias "),
                "after the rebirth, data is named: {metric}"
            );
            break;
        }
    }
}
