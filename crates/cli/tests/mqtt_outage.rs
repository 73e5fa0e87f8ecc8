//! Store and forward, end to end: a broker outage with the gateway killed (`kill -9`) and
//! restarted in the middle. Every change the history recorded during the outage must reach
//! a subscriber afterwards, in time order, marked historical.
//!
//! The outage lasts two minutes, as a plant's would; `CELLBUS_TEST_OUTAGE_SECS` shortens
//! it while working on this code.

mod common;

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::time::Duration;

use common::{Gateway, api_value, now_ms, rfc3339_ms};
use sparkplug::proto::metric::Value as SpValue;
use testkit::{Mosquitto, SparkplugMessage, Subscriber};

/// Generous: a loaded 2-core machine, and the gateway's reconnection wait of up to 30 s.
const LIMIT: Duration = Duration::from_secs(90);

fn outage() -> Duration {
    let secs = std::env::var("CELLBUS_TEST_OUTAGE_SECS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(120);
    Duration::from_secs(secs)
}

/// A stored or received change: point, read time (ms), and the value when there is one.
type Change = (String, i64, Option<String>);

fn sparkplug_value(v: &SpValue) -> String {
    match v {
        SpValue::DoubleValue(d) => format!("{d}"),
        SpValue::IntValue(n) => format!("{}", f64::from(i32::from_ne_bytes(n.to_ne_bytes()))),
        SpValue::StringValue(s) => s.clone(),
        other => format!("{other:?}"),
    }
}

/// What the gateway's history holds for every point in `[from, to]`.
fn stored_changes(gateway: &Gateway, from: i64, to: i64) -> BTreeSet<Change> {
    let mut changes = BTreeSet::new();
    for (id, history) in gateway.histories(from, to) {
        for sample in history["samples"].as_array().unwrap() {
            let good = sample["quality"] == "good";
            changes.insert((
                id.clone(),
                rfc3339_ms(sample["t"].as_str().unwrap()),
                good.then(|| api_value(&sample["value"])).flatten(),
            ));
        }
    }
    changes
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_broker_outage_with_the_gateway_killed_in_the_middle_loses_no_change() {
    let mut broker = Mosquitto::start();
    let mut sub = Subscriber::start(broker.port(), "spBv1.0/cellbus/#").await;
    let data = tempfile::tempdir().unwrap();
    let url = broker.url();
    let first = Gateway::start_with(data.path(), &["--mqtt", &url]);
    let birth = sub
        .next_where("the first NBIRTH", LIMIT, |m| m.kind() == "NBIRTH")
        .await;
    let killed_bd_seq = birth.bd_seq().expect("the NBIRTH has a bdSeq");
    sub.next_where("live data", LIMIT, |m| m.kind() == "DDATA")
        .await;

    // The outage: half of it with the first gateway, which is then killed, and half with
    // a second one on the same data directory.
    let outage_start = now_ms();
    broker.stop();
    tokio::time::sleep(outage() / 2).await;
    drop(first); // kill -9
    let second = Gateway::start_with(data.path(), &["--mqtt", &url]);
    tokio::time::sleep(outage() / 2).await;
    let outage_end = now_ms();
    broker.start_again();

    // The second gateway's births, with a bdSeq after the killed run's.
    let birth = sub
        .next_where("the NBIRTH after the outage", LIMIT, |m| {
            m.kind() == "NBIRTH" && m.bd_seq() != Some(killed_bd_seq)
        })
        .await;
    let bd_seq = birth.bd_seq().expect("the NBIRTH has a bdSeq");
    assert!(
        bd_seq > killed_bd_seq,
        "bdSeq {bd_seq} after the restart, {killed_bd_seq} in the killed run"
    );
    // Aliases from the DBIRTHs, then the historical DDATA until the first live one.
    let mut aliases: HashMap<u64, String> = HashMap::new();
    let mut received: Vec<Change> = Vec::new();
    loop {
        let m: SparkplugMessage = sub
            .next_where("the forwarded changes", LIMIT, |_| true)
            .await;
        let device = m.device().unwrap_or_default().to_owned();
        match m.kind() {
            "DBIRTH" => {
                for metric in &m.payload.metrics {
                    aliases.insert(
                        metric.alias.unwrap(),
                        format!("{device}.{}", metric.name.clone().unwrap()),
                    );
                }
            }
            "DDATA" => {
                let historical: Vec<_> = m
                    .payload
                    .metrics
                    .iter()
                    .filter(|metric| metric.is_historical == Some(true))
                    .collect();
                if historical.is_empty() {
                    break;
                }
                assert_eq!(
                    historical.len(),
                    m.payload.metrics.len(),
                    "a DDATA is all historical or all live"
                );
                for metric in historical {
                    let point = aliases[&metric.alias.unwrap()].clone();
                    let t = i64::try_from(metric.timestamp.unwrap()).unwrap();
                    received.push((point, t, metric.value.as_ref().map(sparkplug_value)));
                }
            }
            _ => {}
        }
    }

    // In time order.
    let times: Vec<i64> = received.iter().map(|c| c.1).collect();
    assert!(
        times.windows(2).all(|w| w[0] <= w[1]),
        "historical changes arrive in time order"
    );
    // Every change stored during the outage arrived, with its value.
    let stored = stored_changes(&second, outage_start, outage_end);
    assert!(
        stored.len() > 10,
        "the demo changed during the outage: {stored:?}"
    );
    let got: BTreeSet<Change> = received.into_iter().collect();
    let missing: Vec<&Change> = stored.difference(&got).collect();
    let mut per_point: BTreeMap<&str, usize> = BTreeMap::new();
    for (point, _, _) in &missing {
        *per_point.entry(point.as_str()).or_default() += 1;
    }
    assert!(
        missing.is_empty(),
        "{} of {} stored changes did not arrive (by point: {per_point:?}); first: {:?}",
        missing.len(),
        stored.len(),
        missing.iter().take(5).collect::<Vec<_>>()
    );
    // Both gateways' changes were among them.
    let killed_at = outage_start + i64::try_from((outage() / 2).as_millis()).unwrap();
    assert!(stored.iter().any(|c| c.1 < killed_at - 1000));
    assert!(stored.iter().any(|c| c.1 > killed_at + 5000));
}
