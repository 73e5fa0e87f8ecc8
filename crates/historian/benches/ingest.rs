//! Ingest into the historian's PostgreSQL store: batches of samples over 20,000 points
//! into a throwaway PostgreSQL (testkit's cluster, fsync on), committed by
//! `Store::write`. Prints, per configuration, the samples committed per second, the
//! per-batch latency p50/p99 and this process's CPU per sample.
//!
//! `cargo bench -p historian --bench ingest` runs the default matrix;
//! `-- --samples N` changes the samples per configuration (default 1,000,000),
//! `-- --quick` runs one small configuration (a check that the bench works), as does
//! `cargo test` (which does not pass `--bench`).
//!
//! Issue #17's goal is ≥ 200,000 metric changes/s committed on the 2-core machine.

use std::time::{Duration, Instant, SystemTime};

use historian::{Batch, PointRow, Quality, SampleRow, Store};
use testkit::Postgres;

/// Points the samples are spread over (20 gateways of 1,000 points).
const POINTS: usize = 20_000;

/// One run's shape.
#[derive(Debug, Clone, Copy)]
struct Config {
    batch: usize,
    writers: usize,
    synchronous_commit: bool,
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    // `cargo bench` passes --bench; `cargo test` (scripts/test) does not: then a smoke run.
    let quick = args.iter().any(|a| a == "--quick") || !args.iter().any(|a| a == "--bench");
    let total = args
        .iter()
        .position(|a| a == "--samples")
        .and_then(|i| args.get(i + 1))
        .and_then(|n| n.parse::<usize>().ok())
        .unwrap_or(if quick { 40_000 } else { 1_000_000 });
    let configs: Vec<Config> = if quick {
        vec![Config {
            batch: 10_000,
            writers: 1,
            synchronous_commit: true,
        }]
    } else {
        let durable = |batch, writers| Config {
            batch,
            writers,
            synchronous_commit: true,
        };
        vec![
            durable(1_000, 1),
            durable(10_000, 1),
            durable(50_000, 1),
            durable(10_000, 2),
            durable(50_000, 2),
            Config {
                batch: 10_000,
                writers: 1,
                synchronous_commit: false,
            },
            Config {
                batch: 10_000,
                writers: 2,
                synchronous_commit: false,
            },
        ]
    };
    // Checkpoints every 5 min or 4 GB of WAL, not every 1 GB: an ingest server's usual
    // first change. fsync and full_page_writes stay on.
    let pg = Postgres::start_with(&[("max_wal_size", "4GB"), ("shared_buffers", "512MB")]);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("a tokio runtime");
    println!(
        "historian ingest: {total} samples per run over {POINTS} points, PostgreSQL on \
         127.0.0.1:{} (fsync on, max_wal_size 4GB, shared_buffers 512MB), {} cores",
        pg.port(),
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    println!(
        "{:>7} {:>7} {:>11} {:>12} {:>10} {:>10} {:>13}",
        "batch", "writers", "sync_commit", "samples/s", "p50 ms", "p99 ms", "client µs/row"
    );
    for (i, config) in configs.iter().enumerate() {
        let url = pg.create_database(&format!("ingest_{i}"));
        let url = if config.synchronous_commit {
            url
        } else {
            format!("{url}?options=-c%20synchronous_commit%3Doff")
        };
        let result = runtime.block_on(run(&url, *config, total));
        println!(
            "{:>7} {:>7} {:>11} {:>12.0} {:>10.1} {:>10.1} {:>13.2}",
            config.batch,
            config.writers,
            if config.synchronous_commit {
                "on"
            } else {
                "off"
            },
            result.per_second,
            result.p50.as_secs_f64() * 1e3,
            result.p99.as_secs_f64() * 1e3,
            result.client_cpu.as_secs_f64() * 1e6 / total as f64,
        );
        // Free the disk for the next run.
        pg.psql("postgres", &format!("DROP DATABASE ingest_{i}"));
    }
}

struct Outcome {
    per_second: f64,
    p50: Duration,
    p99: Duration,
    client_cpu: Duration,
}

/// Writes `total` samples in batches of `config.batch`, split over `config.writers`
/// stores each writing its own points, and times it from the first batch to the last
/// commit.
async fn run(url: &str, config: Config, total: usize) -> Outcome {
    let mut stores = Vec::new();
    for writer in 0..config.writers {
        let mut store = Store::connect(url).await.expect("the bench connects");
        // Births first, as after an NBIRTH, and not timed.
        let births = Batch {
            points: (0..POINTS)
                .filter(|p| p % config.writers == writer)
                .map(point)
                .collect(),
            ..Batch::default()
        };
        store.write(&births).await.expect("births");
        stores.push(store);
    }
    // A day ago, so every sample is in one or two partitions that already exist after the
    // first batch.
    let base = SystemTime::now() - Duration::from_secs(86_400);
    let per_writer = total / config.writers;
    let cpu_before = testkit::process_cpu();
    let started = Instant::now();
    let mut tasks = Vec::new();
    for (writer, mut store) in stores.into_iter().enumerate() {
        tasks.push(tokio::spawn(async move {
            let points: Vec<usize> = (0..POINTS)
                .filter(|p| p % config.writers == writer)
                .collect();
            let mut latencies = Vec::new();
            let mut made = 0;
            while made < per_writer {
                let n = config.batch.min(per_writer - made);
                let batch = Batch {
                    samples: (made..made + n)
                        .map(|i| {
                            // One round over the writer's points per millisecond.
                            let p = points[i % points.len()];
                            let ms = (i / points.len()) as u64;
                            sample(p, base + Duration::from_millis(ms), i)
                        })
                        .collect(),
                    ..Batch::default()
                };
                let t0 = Instant::now();
                let written = store.write(&batch).await.expect("a batch commits");
                latencies.push(t0.elapsed());
                assert_eq!(written.samples as usize, n, "every sample is new");
                made += n;
            }
            latencies
        }));
    }
    let mut latencies = Vec::new();
    for task in tasks {
        latencies.extend(task.await.expect("a writer task"));
    }
    let elapsed = started.elapsed();
    let client_cpu = testkit::process_cpu().saturating_sub(cpu_before);
    latencies.sort();
    let at = |q: f64| latencies[((latencies.len() - 1) as f64 * q).round() as usize];
    Outcome {
        per_second: (per_writer * config.writers) as f64 / elapsed.as_secs_f64(),
        p50: at(0.5),
        p99: at(0.99),
        client_cpu,
    }
}

fn point(p: usize) -> PointRow {
    PointRow {
        group: "plant".into(),
        node: format!("cell{:02}", p / 1000),
        device: format!("jbc{}", (p % 1000) / 10),
        point: format!("p{}", p % 10),
        datatype: "Double".into(),
        unit: Some("°C".into()),
        description: None,
        writable: false,
        write_min: None,
        write_max: None,
    }
}

fn sample(p: usize, t: SystemTime, i: usize) -> SampleRow {
    SampleRow {
        group: "plant".into(),
        node: format!("cell{:02}", p / 1000),
        device: format!("jbc{}", (p % 1000) / 10),
        point: format!("p{}", p % 10),
        t,
        value: Some(20.0 + (i % 400) as f64 * 0.5),
        text: None,
        quality: Quality::Good,
    }
}
