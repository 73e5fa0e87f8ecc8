//! Memory the host application keeps per metric of the births it has read: edge nodes of
//! 4 devices × 250 Double metrics (realistic names, a unit each) are born one after the
//! other into one `sparkplug::Host`; the figure is the growth of this process's resident
//! memory (`VmRSS`, Linux) divided by the metrics born. Each birth's output is dropped
//! before the next, so what remains is what the host holds; glibc reuses the freed
//! memory of one birth for the next on this single thread.
//!
//! `cargo bench -p sparkplug --bench host_memory` runs 100 nodes (100,000 metrics);
//! `cargo test` (which does not pass `--bench`) runs 5 as a check that the bench works.

use sparkplug::{
    BdSeq, DataType, EdgeNode, Host, Id, MetricName, MetricSpec, MetricValue, Sample, Sharing,
    Timestamp, host::Limits,
};

const DEVICES: usize = 4;
const METRICS: usize = 250;

fn id(s: &str) -> Id {
    Id::new(s).expect("bench ids are valid")
}

/// This process's resident memory in bytes, when the system says.
fn resident() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Node `n`'s births, fed to `host` and dropped.
fn born(host: &mut Host, n: usize, t: Timestamp) {
    let mut node = EdgeNode::new(id("plant"), id(&format!("cell{n:03}")), BdSeq::new(0));
    node.on_connect();
    let specs: Vec<_> = (0..METRICS)
        .map(|i| {
            let name = MetricName::new(format!("station_{i:03}_temperature"))
                .expect("bench names are valid");
            (
                MetricSpec::new(name, DataType::Double).unit("°C"),
                Sample::good(MetricValue::Double(i as f64), t),
            )
        })
        .collect();
    let mut births = vec![node.node_birth(&[], t).expect("connected")];
    for d in 0..DEVICES {
        let device = id(&format!("dev{d:02}"));
        births.push(node.device_birth(&device, &specs, t).expect("connected"));
    }
    for p in births {
        let got = host.receive(&p.topic.to_string(), &p.payload, t);
        assert!(got.problems.is_empty(), "{:?}", got.problems);
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    // `cargo bench` passes --bench; `cargo test` does not: then a smoke run.
    let nodes = if args.iter().any(|a| a == "--bench") {
        100
    } else {
        5
    };
    let t = Timestamp::from_millis(1_764_000_000_000);
    let limits = Limits {
        max_nodes: nodes + 1,
        max_node_points: DEVICES * METRICS + 10,
        max_points: (nodes + 1) * (DEVICES * METRICS + 10),
    };
    let mut host = Host::new(id("historian"), None, Sharing::Alone).with_limits(limits);
    // The first node warms the allocator up (its outputs' memory is then reused).
    born(&mut host, 0, t);
    let before = resident();
    for n in 1..nodes {
        born(&mut host, n, t);
    }
    let after = resident();
    assert_eq!(host.nodes_born(), nodes);
    let metrics = (nodes - 1) * DEVICES * METRICS;
    match before.zip(after) {
        Some((before, after)) => println!(
            "host memory: {} bytes per metric ({metrics} metrics of {} nodes, resident {:.1} → \
             {:.1} MiB)",
            after.saturating_sub(before) / metrics as u64,
            nodes - 1,
            before as f64 / 1048576.0,
            after as f64 / 1048576.0
        ),
        None => println!("host memory: this system does not tell the resident memory"),
    }
}
