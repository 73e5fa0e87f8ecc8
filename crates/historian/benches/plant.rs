//! A plant's load into one historian: simulated Sparkplug edge nodes (`sparkplug::EdgeNode`,
//! in a child process) publish DDATA to a real mosquitto; one historian (another child
//! process, the real runtime) stores it in a real PostgreSQL (testkit's cluster, durable
//! commits). Prints the metric changes committed per second, the end-to-end latency and
//! the historian's CPU and peak RSS.
//!
//! `cargo bench -p historian --bench plant` runs 20 nodes × 10 devices × 100 points, every
//! point changing every 100 ms (200,000 changes/s offered) for 20 s after a 5 s warm-up;
//! `-- --nodes N --period-ms P --secs S` change it; `-- --quick` runs 2 nodes for 5 s, as
//! does `cargo test` (which does not pass `--bench`).
//!
//! Latency: every point's value carries the time it was "read" (the metric timestamp,
//! set when the DDATA is built). The parent polls the newest committed sample of one probe
//! point every 50 ms; now − its time is the age of the newest committed row, an upper
//! bound of the end-to-end latency (it adds up to one period since that sample was read).

#[path = "../../gateway/benches/support/process.rs"]
mod process;

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, ExitCode, Stdio};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};
use sparkplug::{
    BdSeq, DataType, Delivery, EdgeNode, Id, MetricName, MetricSpec, MetricValue, Sample,
};
use testkit::{Mosquitto, Postgres};

const HOST_ID: &str = "bench";
const DEVICES: usize = 10;
const POINTS: usize = 100;

#[derive(Debug, Clone, Copy)]
struct Load {
    nodes: usize,
    period: Duration,
    warmup: Duration,
    measure: Duration,
}

fn arg<T: std::str::FromStr>(args: &[String], name: &str) -> Option<T> {
    let i = args.iter().position(|a| a == name)?;
    args.get(i + 1)?.parse().ok()
}

fn now_ms() -> u64 {
    u64::try_from(
        SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap()
            .as_millis(),
    )
    .unwrap()
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "--as-historian") {
        return run_historian(&args[i + 1], &args[i + 2]);
    }
    if let Some(i) = args.iter().position(|a| a == "--as-nodes") {
        let port = args[i + 1].parse().expect("a port");
        let nodes = args[i + 2].parse().expect("a node count");
        let period = Duration::from_millis(args[i + 3].parse().expect("a period"));
        return run_nodes(port, nodes, period);
    }
    // `cargo bench` passes --bench; `cargo test` (scripts/test) does not: then a smoke run.
    let quick = args.iter().any(|a| a == "--quick") || !args.iter().any(|a| a == "--bench");
    let load = Load {
        nodes: arg(&args, "--nodes").unwrap_or(if quick { 2 } else { 20 }),
        period: Duration::from_millis(arg(&args, "--period-ms").unwrap_or(100)),
        warmup: Duration::from_secs(if quick { 2 } else { 5 }),
        measure: Duration::from_secs(arg(&args, "--secs").unwrap_or(if quick { 5 } else { 20 })),
    };
    match bench(load) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("plant bench: {e:#}");
            ExitCode::from(1)
        }
    }
}

/// A child process of this bench binary.
struct ChildProcess(Child);

impl Drop for ChildProcess {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn bench(load: Load) -> anyhow::Result<()> {
    let broker = Mosquitto::start();
    let pg = Postgres::start();
    let database = pg.create_database("plant");
    let me = std::env::current_exe()?;
    let mut historian = ChildProcess(
        Command::new(&me)
            .args(["--as-historian", &broker.url(), &database])
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()?,
    );
    let mut line = String::new();
    BufReader::new(historian.0.stdout.take().expect("piped")).read_line(&mut line)?;
    let api = line
        .trim()
        .strip_prefix("listening on http://")
        .ok_or_else(|| anyhow::anyhow!("the historian child said {line:?}"))?
        .to_owned();
    let _nodes = ChildProcess(
        Command::new(&me)
            .args([
                "--as-nodes",
                &broker.port().to_string(),
                &load.nodes.to_string(),
                &load.period.as_millis().to_string(),
            ])
            .stderr(Stdio::inherit())
            .spawn()?,
    );
    let offered = (load.nodes * DEVICES * POINTS) as f64 / load.period.as_secs_f64();
    println!(
        "plant: {} nodes x {DEVICES} devices x {POINTS} points, every point every {:?}: {offered:.0} changes/s offered",
        load.nodes, load.period
    );
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    runtime.block_on(async {
        let (client, connection) = tokio_postgres::connect(&database, tokio_postgres::NoTls).await?;
        tokio::spawn(connection);
        tokio::time::sleep(load.warmup).await;
        let pid = historian.0.id().to_string();
        let ticks = process::ticks_per_second();
        let committed = |api: String| async move { scrape(&api, "cellbus_historian_samples_committed_total") };
        let (c0, use0, t0) = (committed(api.clone()).await?, process::ProcessUse::of(&pid, ticks)?, Instant::now());
        let mut ages = Vec::new();
        let probe = "SELECT (extract(epoch from max(s.t)) * 1000)::bigint FROM samples s \
                     JOIN points p ON p.id = s.point_id \
                     WHERE p.node = 'node00' AND p.device = 'dev00' AND p.point = 'p000'";
        while t0.elapsed() < load.measure {
            let row = client.query_one(probe, &[]).await?;
            if let Some(newest) = row.get::<_, Option<i64>>(0) {
                ages.push(now_ms().saturating_sub(newest.unsigned_abs()));
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        let elapsed = t0.elapsed().as_secs_f64();
        let (c1, use1) = (committed(api.clone()).await?, process::ProcessUse::of(&pid, ticks)?);
        let rate = (c1 - c0) / elapsed;
        ages.sort_unstable();
        let pct = |p: f64| ages.get(((ages.len() as f64 - 1.0) * p) as usize).copied().unwrap_or(0);
        let window = use1.without(&use0);
        let cpu = window.cpu.as_secs_f64() / elapsed;
        let user = window.user.as_secs_f64() / elapsed;
        let metrics = http_get(&api, "/metrics")?;
        let value = |name: &str| {
            metrics
                .lines()
                .find_map(|l| l.strip_prefix(name)?.strip_prefix(' ')?.trim().parse::<f64>().ok())
                .unwrap_or(f64::NAN)
        };
        println!("committed:   {rate:.0} changes/s over {elapsed:.1} s ({:.0} % of offered)", 100.0 * rate / offered);
        println!("latency:     p50 {} ms, p99 {} ms (age of the newest committed row, {} polls)", pct(0.5), pct(0.99), ages.len());
        println!(
            "historian:   {:.2} cores ({:.2} µs CPU per change, {:.2} of it user), peak RSS {:.1} MiB",
            cpu,
            cpu * 1e6 / rate.max(1.0),
            user * 1e6 / rate.max(1.0),
            use1.peak_rss_kib as f64 / 1024.0
        );
        println!(
            "             commits {}, mean {:.1} ms; pending now {}; dropped {}; duplicates {}; seq gaps {}",
            value("cellbus_historian_commits_total"),
            1000.0 * value("cellbus_historian_commit_seconds_sum") / value("cellbus_historian_commit_seconds_count"),
            value("cellbus_historian_pending_samples"),
            value("cellbus_historian_dropped_rows_total"),
            value("cellbus_historian_duplicate_samples_total"),
            value("cellbus_historian_seq_gaps_total"),
        );
        anyhow::Ok(())
    })
}

/// A plain HTTP GET's body.
fn http_get(addr: &str, path: &str) -> anyhow::Result<String> {
    use std::io::{Read, Write};
    let mut stream = std::net::TcpStream::connect(addr)?;
    write!(
        stream,
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )?;
    let mut response = String::new();
    stream.read_to_string(&mut response)?;
    Ok(response
        .split_once("\r\n\r\n")
        .map(|(_, b)| b.to_owned())
        .unwrap_or_default())
}

fn scrape(addr: &str, name: &str) -> anyhow::Result<f64> {
    let page = http_get(addr, "/metrics")?;
    page.lines()
        .find_map(|l| l.strip_prefix(name)?.strip_prefix(' ')?.trim().parse().ok())
        .ok_or_else(|| anyhow::anyhow!("{name} not in /metrics"))
}

/// The historian child: the real runtime, its API on a free port.
fn run_historian(broker: &str, database: &str) -> ExitCode {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .expect("a runtime");
    let result = runtime.block_on(async {
        let options = historian::Options {
            mqtt: broker.to_owned(),
            tls: kit::mqtt::MqttTls::default(),
            username: None,
            password_env: None,
            database: database.to_owned(),
            host_id: HOST_ID.to_owned(),
            group: None,
            share: None,
            listen: Some("127.0.0.1:0".parse().expect("an address")),
            limits: historian::writer::Limits::default(),
            host_limits: sparkplug::host::Limits::default(),
        };
        let started = historian::Historian::start(options).await?;
        println!(
            "listening on http://{}",
            started.local_addr().expect("--listen")
        );
        started.run(std::future::pending()).await
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("plant bench historian: {e:#}");
            ExitCode::from(1)
        }
    }
}

/// The edge nodes' child: `nodes` Sparkplug nodes, each waits for the historian's STATE
/// online, births, then every `period` one DDATA per device with all its points changed.
fn run_nodes(port: u16, nodes: usize, period: Duration) -> ExitCode {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .expect("a runtime");
    runtime.block_on(async {
        let tasks: Vec<_> = (0..nodes)
            .map(|n| tokio::spawn(node(port, n, period)))
            .collect();
        for t in tasks {
            let _ = t.await;
        }
    });
    ExitCode::SUCCESS
}

async fn node(port: u16, n: usize, period: Duration) {
    let id = format!("node{n:02}");
    let mut edge = EdgeNode::new(
        Id::new("bench").unwrap(),
        Id::new(&id).unwrap(),
        BdSeq::new(0),
    );
    let will = edge.will();
    let mut options = MqttOptions::new(format!("bench-{id}"), "127.0.0.1", port);
    options
        .set_keep_alive(Duration::from_secs(30))
        .set_max_packet_size(16 << 20, 16 << 20)
        .set_last_will(rumqttc::LastWill::new(
            will.topic.to_string(),
            will.payload,
            QoS::AtLeastOnce,
            false,
        ));
    let (client, mut eventloop) = AsyncClient::new(options, 10_000);
    // Wait for the connection and the host's STATE online.
    loop {
        match eventloop.poll().await {
            Ok(Event::Incoming(Packet::ConnAck(_))) => {
                edge.on_connect();
                let _ = client.try_subscribe(format!("spBv1.0/STATE/{HOST_ID}"), QoS::AtLeastOnce);
            }
            Ok(Event::Incoming(Packet::Publish(p)))
                if p.payload.windows(13).any(|w| w == b"\"online\":true") =>
            {
                break;
            }
            Ok(_) => {}
            Err(_) => tokio::time::sleep(Duration::from_millis(100)).await,
        }
    }
    let pump = tokio::spawn(async move { while eventloop.poll().await.is_ok() {} });
    let names: Vec<String> = (0..POINTS).map(|p| format!("p{p:03}")).collect();
    let devices: Vec<Id> = (0..DEVICES)
        .map(|d| Id::new(format!("dev{d:02}")).unwrap())
        .collect();
    let t = sparkplug::Timestamp::from_millis(now_ms());
    let publish = |birth: sparkplug::Publish| {
        client.publish(
            birth.topic.to_string(),
            QoS::AtMostOnce,
            false,
            birth.payload,
        )
    };
    let _ = publish(edge.node_birth(&[], t).unwrap()).await;
    for device in &devices {
        let metrics: Vec<_> = names
            .iter()
            .map(|name| {
                (
                    MetricSpec::new(MetricName::new(name.clone()).unwrap(), DataType::Double),
                    Sample::good(MetricValue::Double(0.0), t),
                )
            })
            .collect();
        let _ = publish(edge.device_birth(device, &metrics, t).unwrap()).await;
    }
    let mut tick = tokio::time::interval(period);
    let mut round = 0_u64;
    loop {
        tick.tick().await;
        round += 1;
        for device in &devices {
            let t = sparkplug::Timestamp::from_millis(now_ms());
            let changes: Vec<(&str, Sample)> = names
                .iter()
                .map(|name| {
                    (
                        name.as_str(),
                        Sample::good(MetricValue::Double(round as f64), t),
                    )
                })
                .collect();
            if let Ok(Some(data)) = edge.device_data(device, &changes, t, Delivery::Live)
                && client
                    .publish(data.topic.to_string(), QoS::AtMostOnce, false, data.payload)
                    .await
                    .is_err()
            {
                pump.abort();
                return;
            }
        }
    }
}
