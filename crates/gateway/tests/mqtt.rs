//! The cell on MQTT, against a real mosquitto: the demo cell's Sparkplug B births, data,
//! rebirth, death and reconnection, as an independent subscriber sees them.

use gateway::northbound::mqtt::MqttFlags;
use gateway::options::Flags;
use std::collections::{BTreeMap, BTreeSet};
use std::net::SocketAddr;
use std::time::{Duration, Instant};

use gateway::ServeOptions;
use gateway::northbound::mqtt::MqttLink;
use testkit::{Mosquitto, SparkplugMessage, Subscriber};

mod running;
use running::{LIMIT, Running};
use testkit::get_response;

const NODE: &str = "spBv1.0/cellbus/+/demo";
const DEVICES: &str = "spBv1.0/cellbus/+/demo/#";

/// The demo cell, publishing to `broker`, with its data in `dir`.
async fn start(broker: &Mosquitto, dir: &std::path::Path) -> Running {
    Running::start(ServeOptions {
        data_dir: dir.join("data"),
        flags: Flags::default().with(MqttFlags {
            broker: Some(broker.url()),
            ..MqttFlags::default()
        }),
        ..ServeOptions::default()
    })
    .await
}

async fn subscribe(broker: &Mosquitto) -> (Subscriber, Subscriber) {
    (
        Subscriber::start(broker.port(), NODE).await,
        Subscriber::start(broker.port(), DEVICES).await,
    )
}

async fn get(addr: SocketAddr, path: &str) -> String {
    get_response(addr, path)
        .await
        .split_once("\r\n\r\n")
        .map(|(_, b)| b.to_owned())
        .unwrap_or_default()
}

/// Every device of `/api/devices` with the names of its points.
async fn api_points(addr: SocketAddr) -> BTreeMap<String, BTreeSet<String>> {
    let body: serde_json::Value = serde_json::from_str(&get(addr, "/api/devices").await).unwrap();
    body["devices"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| {
            let points = d["points"]
                .as_array()
                .unwrap()
                .iter()
                .map(|p| {
                    let id = p["id"].as_str().unwrap();
                    id.split_once('.').unwrap().1.to_owned()
                })
                .collect();
            (d["id"].as_str().unwrap().to_owned(), points)
        })
        .collect()
}

fn nbirth(m: &SparkplugMessage) -> bool {
    m.kind() == "NBIRTH"
}

/// Runs the demo cell on `dir` until `node` sees its NBIRTH (`what`), then stops it; the
/// NBIRTH's bdSeq.
async fn born_and_stopped(
    broker: &Mosquitto,
    dir: &std::path::Path,
    node: &mut Subscriber,
    what: &str,
) -> u64 {
    let gateway = start(broker, dir).await;
    let birth = node.next_where(what, LIMIT, nbirth).await;
    gateway.stop().await;
    birth.bd_seq().expect("the NBIRTH has a bdSeq")
}

/// The DBIRTHs that follow an NBIRTH: one per device of `wanted`, by device.
async fn dbirths(
    devices: &mut Subscriber,
    wanted: &BTreeMap<String, BTreeSet<String>>,
) -> BTreeMap<String, SparkplugMessage> {
    let mut births = BTreeMap::new();
    while births.len() < wanted.len() {
        let m = devices
            .next_where("a DBIRTH for every device", LIMIT, |m| m.kind() == "DBIRTH")
            .await;
        births.insert(m.device().unwrap().to_owned(), m);
    }
    births
}

fn names(m: &SparkplugMessage) -> BTreeSet<String> {
    m.payload
        .metrics
        .iter()
        .filter_map(|m| m.name.clone())
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn births_describe_every_point_changes_arrive_by_alias_and_rebirth_and_death_follow() {
    let broker = Mosquitto::start();
    let (mut node, mut devices) = subscribe(&broker).await;
    let dir = tempfile::tempdir().unwrap();
    let gateway = start(&broker, dir.path()).await;

    let birth = node.next_where("an NBIRTH", LIMIT, nbirth).await;
    assert_eq!(birth.topic, "spBv1.0/cellbus/NBIRTH/demo");
    assert_eq!(birth.payload.seq, Some(0));
    let bd_seq = birth.bd_seq().expect("the NBIRTH has a bdSeq");
    for metric in ["Node Control/Rebirth", "Gateway/Version", "Gateway/Lines"] {
        assert!(birth.metric(metric).is_some(), "NBIRTH without {metric}");
    }

    // Every point of the API is in its device's DBIRTH, with an alias and a datatype.
    let api = api_points(gateway.addr).await;
    assert!(!api.is_empty());
    let births = dbirths(&mut devices, &api).await;
    let mut aliases = BTreeMap::new();
    for (device, points) in &api {
        let birth = &births[device];
        // The points, and each of the device's alarms as three metrics (`Alarms/…`).
        let (alarms, metrics): (BTreeSet<String>, BTreeSet<String>) = names(birth)
            .into_iter()
            .partition(|n| n.starts_with("Alarms/"));
        assert_eq!(&metrics, points, "DBIRTH of {device}");
        for what in ["State", "Priority", "Acknowledged"] {
            let name = format!("Alarms/down/{what}");
            assert!(alarms.contains(&name), "DBIRTH of {device} without {name}");
        }
        for m in &birth.payload.metrics {
            assert!(
                m.datatype.is_some(),
                "{device}: {:?} has no datatype",
                m.name
            );
            aliases.insert((device.clone(), m.alias.expect("births give aliases")), ());
        }
    }

    // The demo's operators change values: they come as DDATA, by alias only.
    let data = devices
        .next_where("a DDATA", LIMIT, |m| m.kind() == "DDATA")
        .await;
    let device = data.device().unwrap().to_owned();
    assert!(!data.payload.metrics.is_empty());
    for m in &data.payload.metrics {
        assert_eq!(m.name, None, "DDATA goes by alias");
        let alias = m.alias.expect("an alias");
        assert!(
            aliases.contains_key(&(device.clone(), alias)),
            "alias {alias} of {device} was born"
        );
        assert!(m.timestamp.is_some(), "the time the device was read");
        if m.is_null == Some(true) {
            assert!(m.properties.is_some(), "a null value says its quality");
        }
    }

    // Visible state.
    let health: serde_json::Value =
        serde_json::from_str(&get(gateway.addr, "/healthz").await).unwrap();
    assert_eq!(health["mqtt"], "connected");
    let metrics = get(gateway.addr, "/metrics").await;
    assert!(metrics.contains("cellbus_mqtt_connected 1"), "{metrics}");
    assert!(
        metrics.contains("cellbus_mqtt_published_total"),
        "{metrics}"
    );

    // Rebirth on request: a fresh NBIRTH (same session, same bdSeq) and every DBIRTH.
    node.publish("spBv1.0/cellbus/NCMD/demo", testkit::rebirth_command())
        .await;
    let again = node
        .next_where("an NBIRTH after the rebirth command", LIMIT, nbirth)
        .await;
    assert_eq!(again.bd_seq(), Some(bd_seq));
    assert_eq!(again.payload.seq, Some(0));
    let reborn = dbirths(&mut devices, &api).await;
    assert_eq!(
        reborn.keys().collect::<Vec<_>>(),
        api.keys().collect::<Vec<_>>()
    );

    // A graceful stop publishes the NDEATH with the session's bdSeq.
    gateway.stop().await;
    let death = node
        .next_where("an NDEATH", LIMIT, |m| m.kind() == "NDEATH")
        .await;
    assert_eq!(death.bd_seq(), Some(bd_seq));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn after_a_broker_outage_the_gateway_reconnects_and_births_again_with_the_next_bd_seq() {
    let mut broker = Mosquitto::start();
    let (mut node, _devices) = subscribe(&broker).await;
    let dir = tempfile::tempdir().unwrap();
    let gateway = start(&broker, dir.path()).await;
    let first = node.next_where("an NBIRTH", LIMIT, nbirth).await;
    let first_bd_seq = first.bd_seq().unwrap();
    gateway
        .wait_for_link("connected", |l| l == &Some(MqttLink::Connected))
        .await;

    broker.restart();

    let second = node
        .next_where("an NBIRTH after the outage", LIMIT, nbirth)
        .await;
    assert_eq!(second.bd_seq(), Some(first_bd_seq + 1));
    gateway
        .wait_for_link("reconnected", |l| l == &Some(MqttLink::Connected))
        .await;
    assert!(
        gateway::northbound::mqtt::status::status(&gateway.cell)
            .metrics
            .reconnects
            .get()
            >= 1
    );
    gateway.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bd_seq_survives_a_restart_on_the_same_data_directory() {
    let broker = Mosquitto::start();
    let (mut node, _devices) = subscribe(&broker).await;
    let dir = tempfile::tempdir().unwrap();

    let first = born_and_stopped(&broker, dir.path(), &mut node, "an NBIRTH").await;
    let second = born_and_stopped(
        &broker,
        dir.path(),
        &mut node,
        "an NBIRTH after the restart",
    )
    .await;
    assert!(
        second > first,
        "bdSeq {second} after a restart, {first} before"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unreachable_broker_shows_in_healthz_and_events_and_nothing_else_stops() {
    // A port nobody listens on.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let dir = tempfile::tempdir().unwrap();
    let gateway = Running::start(ServeOptions {
        data_dir: dir.path().join("data"),
        flags: Flags::default().with(MqttFlags {
            broker: Some(format!("mqtt://127.0.0.1:{port}")),
            ..MqttFlags::default()
        }),
        ..ServeOptions::default()
    })
    .await;
    let addr = gateway.addr;
    gateway
        .wait_for_link(
            "reported the refused connection",
            |l| matches!(l, Some(MqttLink::Disconnected(why)) if why != "not connected yet"),
        )
        .await;
    let health: serde_json::Value = serde_json::from_str(&get(addr, "/healthz").await).unwrap();
    let shown = health["mqtt"].as_str().unwrap();
    assert!(shown.starts_with("disconnected: "), "{shown}");
    // The event is committed to the history within a batch: bounded polling.
    let deadline = Instant::now() + LIMIT;
    loop {
        let events = get(addr, "/api/events?kind=interface_down").await;
        if events.contains("cannot connect to the MQTT broker")
            && events.contains(r#""interface":"mqtt""#)
        {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "no interface_down event: {events}"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    gateway.stop().await;
}

/// Serves a JBC station on a free loopback port (as a serial server would); its endpoint.
async fn jbc_station() -> String {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let model = wire::device::SharedModel::new(jbc::device::Station::new(
        jbc::device::StationConfig::default(),
    ));
    tokio::spawn(link::serve::serve_tcp(listener, move || model.line(), None));
    format!("tcp://{addr}")
}

/// A cell file publishing to `broker`, with one JBC station per `(line, id, endpoint)`.
fn cell_file(broker: &Mosquitto, stations: &[(&str, &str, &str)]) -> String {
    let mut text = format!("[mqtt]\nbroker = \"{}\"\n", broker.url());
    for (line, id, endpoint) in stations {
        text.push_str(&format!(
            "\n[[line]]\nname = \"{line}\"\nendpoint = \"{endpoint}\"\n\
             [[line.device]]\nid = \"{id}\"\nprotocol = \"jbc\"\n"
        ));
    }
    text
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_reload_births_the_device_added_and_buries_the_one_removed_while_the_node_stays_born() {
    let broker = Mosquitto::start();
    let mut all = Subscriber::start(broker.port(), "spBv1.0/#").await;
    let dir = tempfile::tempdir().unwrap();
    let (a, b, c) = (
        jbc_station().await,
        jbc_station().await,
        jbc_station().await,
    );
    let path = dir.path().join("cell.toml");
    std::fs::write(
        &path,
        cell_file(&broker, &[("a", "jbc_a", &a), ("b", "jbc_b", &b)]),
    )
    .unwrap();
    let gateway = Running::start(ServeOptions {
        config: Some(path.clone()),
        data_dir: dir.path().join("data"),
        ..ServeOptions::default()
    })
    .await;
    let mut born = BTreeSet::new();
    while born.len() < 2 {
        let birth = all
            .next_where("the DBIRTHs of both stations", LIMIT, |m| {
                m.kind() == "DBIRTH"
            })
            .await;
        born.insert(birth.device().unwrap().to_owned());
    }

    std::fs::write(
        &path,
        cell_file(&broker, &[("a", "jbc_a", &a), ("c", "jbc_c", &c)]),
    )
    .unwrap();
    let plan = gateway.reloader.reload().await.unwrap();
    assert_eq!(plan.kept, ["a"]);
    let mut seen = Vec::new();
    while !(seen.contains(&("DDEATH".to_owned(), "jbc_b".to_owned()))
        && seen.contains(&("DBIRTH".to_owned(), "jbc_c".to_owned())))
    {
        let m = all
            .next_where("the DDEATH of b and the DBIRTH of c", LIMIT, |m| {
                matches!(m.kind(), "DBIRTH" | "DDEATH" | "NBIRTH" | "NDEATH")
            })
            .await;
        seen.push((
            m.kind().to_owned(),
            m.device().unwrap_or_default().to_owned(),
        ));
    }
    // Nothing else died or was born again: the node and station a carry on.
    assert_eq!(
        seen,
        [
            ("DDEATH".to_owned(), "jbc_b".to_owned()),
            ("DBIRTH".to_owned(), "jbc_c".to_owned())
        ]
    );
    gateway.stop().await;
}
