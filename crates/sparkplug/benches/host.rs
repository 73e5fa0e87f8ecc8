//! Samples per second through the host application: DDATA of a gateway (10 changed
//! Doubles by alias per message, in `seq` order) read by `sparkplug::Host` into samples,
//! protobuf decoding included. What one historian core can take off the broker before
//! any storage.

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use sparkplug::{
    BdSeq, DataType, Delivery, EdgeNode, Host, Id, MetricName, MetricSpec, MetricValue, Sample,
    Sharing, Timestamp,
};

const POINTS: usize = 50;
const CHANGED: usize = 10;

fn id(s: &str) -> Id {
    Id::new(s).expect("bench ids are valid")
}

/// A host that has read a node's births, and 256 DDATA (one full `seq` cycle) that follow
/// them, as (topic, payload).
fn setup() -> (Host, Vec<(String, Vec<u8>)>) {
    let t0 = Timestamp::from_millis(1_764_000_000_000);
    let mut host = Host::new(id("historian"), Some(id("plant")), Sharing::Alone);
    let mut node = EdgeNode::new(id("plant"), id("cell1"), BdSeq::new(0));
    node.on_connect();
    let names: Vec<String> = (0..POINTS).map(|i| format!("point_{i}")).collect();
    let specs: Vec<_> = names
        .iter()
        .map(|n| {
            (
                MetricSpec::new(MetricName::new(n.as_str()).unwrap(), DataType::Double).unit("°C"),
                Sample::good(MetricValue::Double(0.0), t0),
            )
        })
        .collect();
    for p in [
        node.node_birth(&[], t0).unwrap(),
        node.device_birth(&id("station"), &specs, t0).unwrap(),
    ] {
        host.receive(&p.topic.to_string(), &p.payload, t0);
    }
    let messages = (0..256u64)
        .map(|i| {
            let t = Timestamp::from_millis(t0.as_millis() + 1 + i);
            let changes: Vec<_> = (0..CHANGED)
                .map(|k| {
                    let n = &names[(i as usize * CHANGED + k) % POINTS];
                    (
                        n.as_str(),
                        Sample::good(MetricValue::Double(i as f64 + 0.5), t),
                    )
                })
                .collect();
            let p = node
                .device_data(&id("station"), &changes, t, Delivery::Live)
                .unwrap()
                .expect("every value changed");
            (p.topic.to_string(), p.payload)
        })
        .collect();
    (host, messages)
}

fn receive(c: &mut Criterion) {
    let (mut host, messages) = setup();
    let mut group = c.benchmark_group("host");
    group.throughput(Throughput::Elements((messages.len() * CHANGED) as u64));
    let now = Timestamp::from_millis(1_764_000_100_000);
    group.bench_function("ddata 10 metrics -> samples", |b| {
        b.iter(|| {
            let mut samples = 0;
            for (topic, payload) in &messages {
                samples += host.receive(topic, black_box(payload), now).samples.len();
            }
            assert_eq!(samples, messages.len() * CHANGED);
        });
    });
    group.finish();
    let stats = host.stats();
    assert_eq!((stats.seq_gaps, stats.problems), (0, 0), "{stats:?}");
}

criterion_group!(benches, receive);
criterion_main!(benches);
