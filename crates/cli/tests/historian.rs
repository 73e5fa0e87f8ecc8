//! The plant historian end to end: a real mosquitto, a real PostgreSQL, three demo
//! gateways (`cellbus serve --mqtt … --mqtt-node cellX --mqtt-primary-host plant`) and the
//! real `cellbus historian`.
//!
//! One run covers the checks in one window of a minute and more, so the 30 s gap
//! is paid once: every device in `cellbus_points`; `cellbus_samples` equal to each
//! gateway's own `/api/history` across a `kill -9` of the historian for 30 s and a
//! PostgreSQL restart; a `seq` gap answered by a Rebirth; the plant API.
//!
//! "Equal" is checked in both directions. Every change a gateway stored in the window is a
//! row of `cellbus_samples` with its time, quality and (when good) value. Every row of
//! `cellbus_samples` in the window is one of those changes, or repeats the value the
//! gateway's history held at that time (a birth's current value), or is a death marker (a
//! node's NDEATH marks all its points bad at one instant, or stale when the node ended its
//! session because the historian went away or started again).

mod common;

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::io::BufReader;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::{Gateway, api_value, cellbus, http_get, line_after, now_ms, rfc3339, rfc3339_ms};
use sparkplug::{BdSeq, DataType, EdgeNode, Id, MetricName, MetricSpec, MetricValue, Sample};
use testkit::{Mosquitto, Postgres, Subscriber};

/// Generous: a loaded 2-core machine, gateways reconnecting, backlogs replayed.
const LIMIT: Duration = Duration::from_secs(120);

const NODES: [&str; 3] = ["cellA", "cellB", "cellC"];
const HOST_ID: &str = "plant";

/// A running `cellbus historian`, killed (`kill -9`) when dropped.
struct Historian {
    child: Child,
    /// `IP:PORT` of its API.
    addr: String,
}

impl Historian {
    fn start(broker: &str, database: &str, args: &[&str]) -> Historian {
        let mut child = cellbus()
            .args(["historian", "--mqtt", broker, "--database", database])
            .args(["--listen", "127.0.0.1:0"])
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("cellbus runs");
        let mut out = BufReader::new(child.stdout.take().expect("piped"));
        assert_eq!(
            line_after(&mut out, "historian on "),
            broker,
            "the first line"
        );
        let addr = line_after(&mut out, "listening on http://");
        Historian { child, addr }
    }

    fn get_json(&self, path: &str) -> serde_json::Value {
        let (status, body) = http_get(&self.addr, path);
        assert_eq!(status, 200, "{path}: {body}");
        serde_json::from_str(&body).unwrap_or_else(|e| panic!("{path}: {e}: {body}"))
    }

    /// Polls `/healthz` until the historian is online with PostgreSQL taking commits.
    fn wait_healthy(&self, what: &str) {
        let deadline = Instant::now() + LIMIT;
        loop {
            let health = self.get_json("/healthz");
            if health["status"] == "ok" {
                return;
            }
            assert!(
                Instant::now() < deadline,
                "{what}: not healthy in {LIMIT:?}: {health}"
            );
            std::thread::sleep(Duration::from_millis(200));
        }
    }

    /// SIGTERM, and the exit status.
    fn terminate(mut self) -> std::process::ExitStatus {
        let pid = self.child.id().to_string();
        let status = Command::new("kill").args(["-TERM", &pid]).status().unwrap();
        assert!(status.success());
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                return status;
            }
            assert!(
                Instant::now() < deadline,
                "the historian did not stop on SIGTERM"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl Drop for Historian {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A stored sample: time (ms), quality word, and the value when good.
#[derive(Debug, Clone, PartialEq)]
struct Row {
    t: i64,
    quality: String,
    value: Option<String>,
}

fn api_row(sample: &serde_json::Value) -> Row {
    let quality = sample["quality"].as_str().unwrap().to_owned();
    Row {
        t: rfc3339_ms(sample["t"].as_str().unwrap()),
        value: (quality == "good")
            .then(|| api_value(&sample["value"]))
            .flatten(),
        quality,
    }
}

/// One point's history in a gateway: the value held before the window, and the changes.
#[derive(Debug, Default)]
struct Series {
    before: Option<Row>,
    rows: Vec<Row>,
}

impl Series {
    /// What the gateway's history held at `t`.
    fn held_at(&self, t: i64) -> Option<&Row> {
        self.rows
            .iter()
            .rev()
            .find(|r| r.t <= t)
            .or(self.before.as_ref())
    }
}

/// Every point's history in a gateway over `[from, to)`, by `device.point`.
fn gateway_history(gateway: &Gateway, from: i64, to: i64) -> BTreeMap<String, Series> {
    gateway
        .histories(from, to)
        .into_iter()
        .map(|(id, history)| {
            let series = Series {
                before: history.get("before").filter(|b| !b.is_null()).map(api_row),
                rows: history["samples"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(api_row)
                    .collect(),
            };
            (id, series)
        })
        .collect()
}

fn gateway_devices(gateway: &Gateway) -> Vec<String> {
    let devices = gateway.get_json("/api/devices");
    devices["devices"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| d["id"].as_str().unwrap().to_owned())
        .collect()
}

/// The historian's rows of `node`'s devices over `[from, to)`, by `device.point`. A device's
/// alarm metrics (`Alarms/…`, their state as the gateway's Sparkplug births and data give it) are
/// stored too, but are not points of the gateway's history: the alarm journal is its events.
fn historian_rows(pg: &Postgres, node: &str, from: i64, to: i64) -> BTreeMap<String, Vec<Row>> {
    let out = pg.psql(
        "plant",
        &format!(
            "SELECT device || '.' || point, (extract(epoch from t) * 1000)::bigint, quality, \
             coalesce(value::text, '=' || text) FROM cellbus_samples WHERE node = '{node}' \
             AND device <> '' AND point NOT LIKE 'Alarms/%' \
             AND t >= to_timestamp({from} / 1000.0) \
             AND t < to_timestamp({to} / 1000.0) ORDER BY 1, 2"
        ),
    );
    let mut rows: BTreeMap<String, Vec<Row>> = BTreeMap::new();
    for line in out.lines().filter(|l| !l.is_empty()) {
        let f: Vec<&str> = line.splitn(4, '|').collect();
        let quality = f[2].to_owned();
        // Text comes as `=TEXT` (an empty text is `=`, not NULL's empty field); numbers as
        // the API prints them (shortest form).
        let value = (quality == "good" && !f[3].is_empty()).then(|| match f[3].strip_prefix('=') {
            Some(text) => text.to_owned(),
            None => f[3]
                .parse::<f64>()
                .map_or_else(|_| f[3].to_owned(), |n| format!("{n}")),
        });
        rows.entry(f[0].to_owned()).or_default().push(Row {
            t: f[1].parse().unwrap(),
            quality,
            value,
        });
    }
    rows
}

/// What is wrong between a gateway's history and the historian's rows, in words (empty:
/// equal in the sense of the module's docs).
fn differences(
    gateway: &BTreeMap<String, Series>,
    historian: &BTreeMap<String, Vec<Row>>,
) -> Vec<String> {
    let mut wrong = Vec::new();
    // Death markers: instants at which the historian marked many points bad at once (a
    // node's Will), or stale (a node that ended its session because the historian went
    // away or started again, and kept reading).
    let marker = |r: &Row| (r.quality == "bad" || r.quality == "stale") && r.value.is_none();
    let mut bad_at: HashMap<i64, usize> = HashMap::new();
    for rows in historian.values() {
        for r in rows.iter().filter(|r| marker(r)) {
            *bad_at.entry(r.t).or_default() += 1;
        }
    }
    let deaths: BTreeSet<i64> = bad_at
        .into_iter()
        .filter(|(_, n)| *n * 2 >= gateway.len())
        .map(|(t, _)| t)
        .collect();
    for (point, series) in gateway {
        let stored = historian.get(point).map_or(&[][..], Vec::as_slice);
        for change in &series.rows {
            if !stored.contains(change) {
                wrong.push(format!(
                    "{point}: gateway change {change:?} not in the historian"
                ));
            }
        }
        for row in stored {
            if series.rows.contains(row) {
                continue;
            }
            if series.rows.iter().any(|c| c.t == row.t) {
                wrong.push(format!(
                    "{point}: historian row {row:?} differs from the gateway's"
                ));
                continue;
            }
            let held = series.held_at(row.t);
            let repeats = held.is_some_and(|h| h.quality == row.quality && h.value == row.value);
            let death = marker(row) && deaths.contains(&row.t);
            if !repeats && !death {
                wrong.push(format!(
                    "{point}: historian row {row:?} is neither a change of the gateway, nor the \
                     value it held ({held:?}), nor a death"
                ));
            }
        }
    }
    for point in historian.keys() {
        if !gateway.contains_key(point) {
            wrong.push(format!("{point}: a point the gateway does not have"));
        }
    }
    wrong
}

/// Polls until the historian's rows of every gateway equal the gateway's history over
/// `[from, to)`.
fn assert_equal_histories(pg: &Postgres, gateways: &[(&str, Gateway)], from: i64, to: i64) {
    let expected: Vec<_> = gateways
        .iter()
        .map(|(node, g)| (*node, gateway_history(g, from, to)))
        .collect();
    let changes: usize = expected
        .iter()
        .map(|(_, h)| h.values().map(|s| s.rows.len()).sum::<usize>())
        .sum();
    assert!(
        changes > 30,
        "the demo cells changed in the window: {changes} changes"
    );
    let deadline = Instant::now() + LIMIT;
    loop {
        let mut wrong = Vec::new();
        for (node, history) in &expected {
            let rows = historian_rows(pg, node, from, to);
            wrong.extend(
                differences(history, &rows)
                    .into_iter()
                    .map(|w| format!("{node}/{w}")),
            );
        }
        if wrong.is_empty() {
            return;
        }
        assert!(
            Instant::now() < deadline,
            "{} differences after {LIMIT:?} ({changes} changes in the window); the first: {:#?}",
            wrong.len(),
            &wrong[..wrong.len().min(10)]
        );
        std::thread::sleep(Duration::from_secs(1));
    }
}

fn start_gateway(broker: &str, node: &str, data: &std::path::Path) -> Gateway {
    Gateway::start_with(
        data,
        &[
            "--mqtt",
            broker,
            "--mqtt-node",
            node,
            "--mqtt-primary-host",
            HOST_ID,
        ],
    )
}

/// A fake edge node publishes its births, then data with a skipped `seq`: the historian
/// asks it for a rebirth.
async fn a_seq_gap_asks_for_a_rebirth(broker: &Mosquitto) {
    let mut sub = Subscriber::start(broker.port(), "spBv1.0/+/NCMD/#").await;
    let mut node = EdgeNode::new(
        Id::new("cellbus").unwrap(),
        Id::new("fake").unwrap(),
        BdSeq::new(0),
    );
    node.on_connect();
    let t = sparkplug::Timestamp::from_millis(now_ms().unsigned_abs());
    let spec = MetricSpec::new(MetricName::new("level").unwrap(), DataType::Double);
    let device = Id::new("tank").unwrap();
    let sample = |v: f64| Sample::good(MetricValue::Double(v), t);
    let births = [
        node.node_birth(&[], t).unwrap(),
        node.device_birth(&device, &[(spec, sample(1.0))], t)
            .unwrap(),
    ];
    let live = sparkplug::Delivery::Live;
    let skipped = node.device_data(&device, &[("level", sample(2.0))], t, live);
    assert!(skipped.unwrap().is_some(), "a DDATA not published: the gap");
    let after_gap = node
        .device_data(&device, &[("level", sample(3.0))], t, live)
        .unwrap()
        .expect("a DDATA after the gap");
    for message in births.into_iter().chain([after_gap]) {
        sub.publish(&message.topic.to_string(), message.payload)
            .await;
    }
    let rebirth = sub
        .next_where("an NCMD Rebirth to the node with the gap", LIMIT, |m| {
            m.topic == "spBv1.0/cellbus/NCMD/fake"
        })
        .await;
    let metric = rebirth
        .metric("Node Control/Rebirth")
        .expect("a Rebirth metric");
    assert_eq!(
        metric.value,
        Some(sparkplug::proto::metric::Value::BooleanValue(true))
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn three_gateways_lose_nothing_across_a_historian_kill_and_a_postgres_restart() {
    let broker = Mosquitto::start();
    let mut pg = Postgres::start();
    let database = pg.create_database("plant");
    let url = broker.url();
    let historian = Historian::start(&url, &database, &["--host-id", HOST_ID]);
    let dirs: Vec<_> = NODES.iter().map(|_| tempfile::tempdir().unwrap()).collect();
    let gateways: Vec<(&str, Gateway)> = NODES
        .iter()
        .zip(&dirs)
        .map(|(node, dir)| (*node, start_gateway(&url, node, dir.path())))
        .collect();

    // Every device of every gateway appears in cellbus_points.
    let wanted: BTreeSet<String> = gateways
        .iter()
        .flat_map(|(node, g)| {
            gateway_devices(g)
                .into_iter()
                .map(move |d| format!("{node}/{d}"))
        })
        .collect();
    assert!(
        wanted.len() >= 3 * 3,
        "the demo cells have devices: {wanted:?}"
    );
    // Healthy = connected to the broker and to PostgreSQL, its schema made.
    historian.wait_healthy("at start");
    let deadline = Instant::now() + LIMIT;
    loop {
        let out = pg.psql(
            "plant",
            "SELECT DISTINCT node || '/' || device FROM cellbus_points WHERE device <> ''",
        );
        let got: BTreeSet<String> = out.lines().map(str::to_owned).collect();
        if wanted.is_subset(&got) {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "devices missing from cellbus_points: {:?}",
            wanted.difference(&got).collect::<Vec<_>>()
        );
        std::thread::sleep(Duration::from_millis(500));
    }
    let from = now_ms();

    // A seq gap from a test publisher is answered with a Rebirth.
    a_seq_gap_asks_for_a_rebirth(&broker).await;

    // The historian killed for 30 s, then restarted.
    tokio::time::sleep(Duration::from_secs(10)).await;
    drop(historian); // kill -9
    tokio::time::sleep(Duration::from_secs(30)).await;
    let historian = Historian::start(&url, &database, &["--host-id", HOST_ID]);
    historian.wait_healthy("after the restart");

    // PostgreSQL restarted (a crash and recovery) while the historian runs.
    tokio::time::sleep(Duration::from_secs(5)).await;
    pg.restart();
    historian.wait_healthy("after the PostgreSQL restart");
    // At least 10 s more, and a window of at least a minute however fast the steps went.
    let rest = (from + 62_000 - now_ms()).max(10_000);
    tokio::time::sleep(Duration::from_millis(rest as u64)).await;
    let to = now_ms() - 1_000;
    assert!(to - from >= 60_000, "a window of a minute or more");

    assert_equal_histories(&pg, &gateways, from, to);

    // The plant API: the gateway's /api/history shape for the same window.
    let window = format!("from={}&to={}", rfc3339(from), rfc3339(to));
    let (status, body) = gateways[0]
        .1
        .get(&format!("/api/history?point=jbc1.air_temperature&{window}"));
    assert_eq!(status, 200, "{body}");
    let theirs: serde_json::Value = serde_json::from_str(&body).unwrap();
    let ours = historian.get_json(&format!(
        "/api/history?point=cellA/jbc1.air_temperature&{window}"
    ));
    let keys = |v: &serde_json::Value| {
        v.as_object()
            .unwrap()
            .keys()
            .cloned()
            .collect::<BTreeSet<_>>()
    };
    assert_eq!(keys(&ours), keys(&theirs), "the same fields: {ours}");
    assert_eq!(ours["point"], "cellA/jbc1.air_temperature");
    assert_eq!(
        (&ours["from"], &ours["to"]),
        (&theirs["from"], &theirs["to"])
    );
    let series = |v: &serde_json::Value| Series {
        before: v.get("before").filter(|b| !b.is_null()).map(api_row),
        rows: v["samples"]
            .as_array()
            .unwrap()
            .iter()
            .map(api_row)
            .collect(),
    };
    let ours_rows = series(&ours).rows;
    let theirs_series = series(&theirs);
    assert!(
        !theirs_series.rows.is_empty(),
        "the air temperature changed: {theirs}"
    );
    let mut gateway_side = BTreeMap::new();
    gateway_side.insert("jbc1.air_temperature".to_owned(), theirs_series);
    let mut historian_side = BTreeMap::new();
    historian_side.insert("jbc1.air_temperature".to_owned(), ours_rows);
    let wrong = differences(&gateway_side, &historian_side);
    assert!(wrong.is_empty(), "/api/history differs: {wrong:#?}");
    let buckets = historian.get_json(&format!(
        "/api/history?point=cellA/jbc1.air_temperature&{window}&step=10s"
    ));
    assert_eq!(buckets["step_ms"], 10_000);
    assert!(
        !buckets["buckets"].as_array().unwrap().is_empty(),
        "{buckets}"
    );
    let (status, body) = http_get(&historian.addr, "/api/history?point=jbc1.air_temperature");
    assert_eq!(status, 400, "{body}");
    assert!(body.contains("NODE/DEVICE.POINT"), "{body}");
    let (status, body) = http_get(&historian.addr, "/api/history?point=cellA/jbc1.nothing");
    assert_eq!(status, 404, "{body}");

    let points = historian.get_json("/api/points");
    let air = points["points"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["id"] == "cellA/jbc1.air_temperature")
        .unwrap_or_else(|| panic!("cellA/jbc1.air_temperature in /api/points: {points}"));
    assert_eq!(
        (&air["node"], &air["device"]),
        (&"cellA".into(), &"jbc1".into())
    );
    assert_eq!(air["unit"], "°C");
    assert!(air["name"].as_str().is_some_and(|n| !n.is_empty()), "{air}");
    for node in NODES {
        assert!(
            points["points"]
                .as_array()
                .unwrap()
                .iter()
                .any(|p| p["node"] == node),
            "{node} in /api/points"
        );
    }
    let health = historian.get_json("/healthz");
    assert_eq!(health["status"], "ok", "{health}");
    assert_eq!(health["broker"], "connected", "{health}");
    assert_eq!(health["database"], "ok", "{health}");
    assert!(health["nodes_online"].as_u64().unwrap() >= 3, "{health}");
    assert!(
        health["samples_committed"].as_u64().unwrap() > 0,
        "{health}"
    );
    let (status, metrics) = http_get(&historian.addr, "/metrics");
    assert_eq!(status, 200);
    for name in [
        "cellbus_historian_messages_total",
        "cellbus_historian_samples_committed_total",
        "cellbus_historian_duplicate_samples_total",
        "cellbus_historian_rebirths_asked_total",
        "cellbus_historian_seq_gaps_total",
        "cellbus_historian_commit_seconds_bucket",
        "cellbus_historian_pending_samples",
    ] {
        assert!(metrics.contains(name), "{name} in /metrics:\n{metrics}");
    }

    // SIGTERM: a clean stop.
    let status = historian.terminate();
    assert!(status.success(), "exit status {status}");
    let out = pg.psql("plant", "SELECT count(*) FROM cellbus_samples");
    assert!(out.trim().parse::<u64>().unwrap() > 0);
}

/// A counter's value in a Prometheus text page.
fn counter(metrics: &str, name: &str) -> f64 {
    metrics
        .lines()
        .find_map(|l| l.strip_prefix(name)?.strip_prefix(' ')?.trim().parse().ok())
        .unwrap_or_else(|| panic!("{name} in:\n{metrics}"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_historians_sharing_the_data_store_every_change() {
    let broker = Mosquitto::start();
    let pg = Postgres::start();
    let database = pg.create_database("plant");
    let url = broker.url();
    // Each historian has its own host id; the gateway follows one of them.
    let first = Historian::start(&url, &database, &["--host-id", HOST_ID, "--share", "plant"]);
    let second = Historian::start(
        &url,
        &database,
        &["--host-id", "plant2", "--share", "plant"],
    );
    first.wait_healthy("the first");
    second.wait_healthy("the second");
    let dir = tempfile::tempdir().unwrap();
    let gateways = vec![("cellA", start_gateway(&url, "cellA", dir.path()))];
    let deadline = Instant::now() + LIMIT;
    while first.get_json("/healthz")["nodes_online"] != 1
        || second.get_json("/healthz")["nodes_online"] != 1
    {
        assert!(
            Instant::now() < deadline,
            "both historians see the gateway's birth"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    let from = now_ms();
    tokio::time::sleep(Duration::from_secs(20)).await;
    let to = now_ms() - 1_000;
    assert_equal_histories(&pg, &gateways, from, to);
    // Both took part: each got far more messages than the births.
    for h in [&first, &second] {
        let (_, metrics) = http_get(&h.addr, "/metrics");
        let messages = counter(&metrics, "cellbus_historian_messages_total");
        assert!(messages > 40.0, "{} got {messages} messages", h.addr);
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_retained_message_larger_than_any_usual_limit_is_read_not_a_reason_to_stay_offline() {
    let broker = Mosquitto::start();
    let pg = Postgres::start();
    let database = pg.create_database("plant");
    // 17 MiB of garbage, retained where the historian subscribes: it comes at every
    // connection, and a client with a smaller packet limit drops each one on it.
    let publisher = Subscriber::start(broker.port(), "cellbus/test/nothing").await;
    publisher
        .publish_retained("spBv1.0/plant/NDATA/big", vec![0xff; 17 << 20])
        .await;
    let historian = Historian::start(&broker.url(), &database, &["--host-id", HOST_ID]);
    let deadline = Instant::now() + LIMIT;
    loop {
        let (_, metrics) = http_get(&historian.addr, "/metrics");
        if counter(&metrics, "cellbus_historian_messages_total") >= 1.0 {
            assert!(
                counter(&metrics, "cellbus_historian_message_problems_total") >= 1.0,
                "the garbage is a problem counted:\n{metrics}"
            );
            break;
        }
        assert!(
            Instant::now() < deadline,
            "the 17 MiB message was not received in {LIMIT:?}"
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    historian.wait_healthy("after the large message");
    let health = historian.get_json("/healthz");
    assert_eq!(health["broker"], "connected", "{health}");
}

#[test]
fn a_database_that_is_not_postgresql_no_pending_room_or_no_age_exits_2_before_anything_starts() {
    for (args, words) in [
        (
            ["--database", "mysql://u:secret@127.0.0.1/db"],
            "mysql:// is not PostgreSQL",
        ),
        (
            ["--database", "postgres://u:secret@127.0.0.1:notaport/db"],
            "not a PostgreSQL connection string",
        ),
    ] {
        let out = cellbus()
            .args(["historian", "--mqtt", "mqtt://127.0.0.1:1"])
            .args(args)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{stderr}");
        assert!(
            stderr.contains(words) && !stderr.contains("secret"),
            "{stderr}"
        );
    }
    let out = cellbus()
        .args(["historian", "--mqtt", "mqtt://127.0.0.1:1"])
        .args([
            "--database",
            "postgres://u@127.0.0.1/db",
            "--max-pending",
            "0",
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let out = cellbus()
        .args(["historian", "--mqtt", "mqtt://127.0.0.1:1"])
        .args(["--database", "postgres://u@127.0.0.1/db", "--max-age", "0s"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("would refuse every sample"), "{stderr}");
}

/// The retained STATE on `spBv1.0/STATE/{HOST_ID}` as a fresh client reads it, as JSON;
/// `None` when none comes within 5 s.
async fn retained_state(port: u16) -> Option<serde_json::Value> {
    use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};
    let id = format!("cellbus-test-state-{}", now_ms());
    let (client, mut eventloop) = AsyncClient::new(MqttOptions::new(id, "127.0.0.1", port), 10);
    let topic = format!("spBv1.0/STATE/{HOST_ID}");
    let read = tokio::time::timeout(Duration::from_secs(5), async {
        loop {
            match eventloop.poll().await {
                Ok(Event::Incoming(Packet::ConnAck(_))) => {
                    client.try_subscribe(&topic, QoS::AtLeastOnce).unwrap();
                }
                Ok(Event::Incoming(Packet::Publish(p))) if p.retain => {
                    return serde_json::from_slice::<serde_json::Value>(&p.payload).ok();
                }
                Ok(_) => {}
                Err(e) => panic!("the test's MQTT client: {e}"),
            }
        }
    })
    .await;
    let _ = client.try_disconnect();
    read.ok().flatten()
}

/// A fake edge node's NBIRTH of `metrics` Double metrics, as (topic, payload).
fn fake_birth(node: &str, metrics: usize) -> (String, Vec<u8>) {
    let mut edge = EdgeNode::new(
        Id::new("cellbus").unwrap(),
        Id::new(node).unwrap(),
        BdSeq::new(0),
    );
    edge.on_connect();
    let t = sparkplug::Timestamp::from_millis(now_ms().unsigned_abs());
    let specs: Vec<_> = (0..metrics)
        .map(|i| {
            (
                MetricSpec::new(MetricName::new(format!("m{i}")).unwrap(), DataType::Double),
                Sample::good(MetricValue::Double(i as f64), t),
            )
        })
        .collect();
    let birth = edge.node_birth(&specs, t).unwrap();
    (birth.topic.to_string(), birth.payload)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_forged_retained_state_offline_is_answered_and_births_past_max_points_are_refused() {
    let broker = Mosquitto::start();
    let pg = Postgres::start();
    let database = pg.create_database("plant");
    let historian = Historian::start(
        &broker.url(),
        &database,
        &["--host-id", HOST_ID, "--max-points", "1000"],
    );
    historian.wait_healthy("at start");
    // A gateway whose primary host is the historian, born once the historian is online.
    let dir = tempfile::tempdir().unwrap();
    let gateway = start_gateway(&broker.url(), "cellF", dir.path());
    let session = loop {
        let state = retained_state(broker.port()).await;
        if let Some(t) = state
            .as_ref()
            .filter(|s| s["online"] == true)
            .and_then(|s| s["timestamp"].as_i64())
        {
            break t;
        }
    };
    let deadline = Instant::now() + LIMIT;
    while counter(&gateway.get("/metrics").1, "cellbus_mqtt_published_total") < 1.0 {
        assert!(Instant::now() < deadline, "the gateway published nothing");
        tokio::time::sleep(Duration::from_millis(200)).await;
    }

    // A rogue client says the historian is offline, retained: gateways that connect later
    // would wait for it for ever, and those connected would end their sessions.
    let rogue = Subscriber::start(broker.port(), "cellbus/test/nothing").await;
    let forged = now_ms();
    let offline = serde_json::json!({ "online": false, "timestamp": forged });
    rogue
        .publish_retained(
            &format!("spBv1.0/STATE/{HOST_ID}"),
            serde_json::to_vec(&offline).unwrap(),
        )
        .await;
    let deadline = Instant::now() + LIMIT;
    loop {
        let state = retained_state(broker.port()).await;
        // Answered with the historian's own session (the time its Will carries too).
        let answered = state
            .as_ref()
            .is_some_and(|s| s["online"] == true && s["timestamp"].as_i64() == Some(session));
        if answered {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "the retained STATE is still {state:?} after {LIMIT:?}"
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    let (_, metrics) = http_get(&historian.addr, "/metrics");
    assert!(
        counter(&metrics, "cellbus_historian_state_reasserted_total") >= 1.0,
        "{metrics}"
    );
    // The gateway took the answer as the host contradicting the forgery, within its grace:
    // it keeps its session and goes on publishing.
    let deadline = Instant::now() + LIMIT;
    loop {
        let metrics = gateway.get("/metrics").1;
        if counter(&metrics, "cellbus_mqtt_offline_contradicted_total") >= 1.0 {
            assert_eq!(
                counter(&metrics, "cellbus_mqtt_reconnects_total"),
                0.0,
                "{metrics}"
            );
            break;
        }
        assert!(Instant::now() < deadline, "{metrics}");
        tokio::time::sleep(Duration::from_millis(200)).await;
    }

    // A rogue birth of 1,001 metrics passes --max-points 1000 alone: refused whole, nothing
    // stored; a birth of 10 after it is taken (with the gateway's, well under 1,000).
    for (node, metrics) in [("rogue", 1001), ("small", 10)] {
        let (topic, payload) = fake_birth(node, metrics);
        rogue.publish(&topic, payload).await;
    }
    let deadline = Instant::now() + LIMIT;
    loop {
        let out = pg.psql(
            "plant",
            "SELECT node, count(*) FROM cellbus_points GROUP BY node ORDER BY node",
        );
        if out.contains("small|10") {
            assert!(!out.contains("rogue"), "{out}");
            break;
        }
        assert!(Instant::now() < deadline, "cellbus_points: {out}");
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    let (_, metrics) = http_get(&historian.addr, "/metrics");
    assert!(
        counter(&metrics, "cellbus_historian_births_refused_total") >= 1.0,
        "{metrics}"
    );
    historian.wait_healthy("after the rogue client");
}

#[test]
fn a_historian_whose_database_is_not_there_says_so_at_the_default_level() {
    // A port nothing listens on: bound, then closed.
    let closed = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = closed.local_addr().unwrap().port();
    drop(closed);
    let mut child = cellbus()
        .args(["historian", "--mqtt", "mqtt://127.0.0.1:1"])
        .args([
            "--database",
            &format!("postgres://cellbus@127.0.0.1:{port}/plant"),
        ])
        .args(["--listen", "127.0.0.1:0"])
        .env_remove("RUST_LOG")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("cellbus runs");
    let err = BufReader::new(child.stderr.take().expect("piped"));
    let (lines, heard) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in std::io::BufRead::lines(err).map_while(Result::ok) {
            if lines.send(line).is_err() {
                break;
            }
        }
    });
    let mut seen = Vec::new();
    let told = loop {
        match heard.recv_timeout(LIMIT) {
            Ok(line) if line.contains("WARN") && line.contains(&format!("127.0.0.1:{port}")) => {
                break Some(line);
            }
            Ok(line) => seen.push(line),
            Err(_) => break None,
        }
    };
    let _ = child.kill();
    let _ = child.wait();
    let told = told.unwrap_or_else(|| panic!("no warning naming the database: {seen:?}"));
    assert!(told.contains("offline meanwhile"), "{told}");
}
