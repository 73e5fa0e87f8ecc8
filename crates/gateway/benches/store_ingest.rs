//! Sustained history ingest: a million value changes over a thousand points sent to the
//! store as fast as one producer can, committed by the writer thread in its batches (WAL,
//! synchronous=FULL, per-minute rollups), one flush at the end. Prints rows per second
//! (wall time from the first row sent to the last commit), commits made, the writer
//! process's CPU and the file's size; at the end, how long the MQTT backlog's reads take on
//! the file written.
//!
//! ```text
//! nice cargo bench -p gateway --bench store_ingest                       # 1M rows, 1000 points
//! nice cargo bench -p gateway --bench store_ingest -- --rows 3000000 --points 12000
//! nice cargo bench -p gateway --bench store_ingest -- --batch-rows 20000
//! ```
//!
//! Timestamps advance 1 ms per row, points in turn: every point changes once a second,
//! each minute of each point is rolled up. Runs `--runs` times (default 3) into the same
//! file, so later runs write into a larger file.

use std::time::Instant;

use gateway::point::{Quality, Value};
use gateway::store::{ChangeCursor, ChangeKey, Sample, StoreHandle, StoreOptions};
use gateway::time::Timestamp;

#[path = "support/store.rs"]
mod temp;
use temp::{device_points, temp_store};

fn arg(name: &str, default: usize) -> usize {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn main() {
    let smoke = std::env::args().all(|a| a != "--bench");
    let rows = arg("--rows", if smoke { 20_000 } else { 1_000_000 });
    let points_n = arg("--points", 1_000);
    let runs = arg("--runs", if smoke { 1 } else { 3 });
    let options = StoreOptions {
        batch_rows: arg("--batch-rows", StoreOptions::default().batch_rows),
        ..StoreOptions::default()
    };
    let (dir, store, runtime) = temp_store(options);
    let handle = store.handle();
    let points = device_points(points_n);
    let mut t = 0i64;
    for run in 1..=runs {
        let commits = handle
            .stats()
            .commits
            .load(std::sync::atomic::Ordering::Relaxed);
        let cpu = testkit::process_cpu();
        let started = Instant::now();
        for i in 0..rows {
            t += 1;
            handle.sample(Sample {
                point: points[i % points_n].clone(),
                t: Timestamp(t),
                value: Some(Value::Number((t % 1000) as f64 * 0.1)),
                quality: Quality::Good,
            });
        }
        runtime.block_on(handle.flush()).expect("commit");
        let took = started.elapsed();
        let cpu = testkit::process_cpu().saturating_sub(cpu);
        let commits = handle
            .stats()
            .commits
            .load(std::sync::atomic::Ordering::Relaxed)
            - commits;
        let bytes: u64 = ["cellbus.db", "cellbus.db-wal"]
            .iter()
            .map(|f| std::fs::metadata(dir.path().join(f)).map_or(0, |m| m.len()))
            .sum();
        println!(
            "store_ingest run {run}: {rows} rows over {points_n} points in {:.2} s: {:.0} rows/s, \
             {commits} commits, CPU {:.2} s ({:.2} µs/row, producer included), file {:.0} MB",
            took.as_secs_f64(),
            rows as f64 / took.as_secs_f64(),
            cpu.as_secs_f64(),
            cpu.as_secs_f64() * 1e6 / rows as f64,
            bytes as f64 / 1e6
        );
    }
    backlog_reads(&handle, t, rows * runs);
    store.close();
}

/// How long the MQTT backlog's reads take on the file written (every point's changes in
/// time order, without an index on time): counting a backlog of the newest half and finding
/// where it starts, then reading the keys of 50,000 changes and the rows of 5,000.
fn backlog_reads(handle: &StoreHandle, newest: i64, stored: usize) {
    let from = ChangeKey::before(Timestamp(0));
    let keep = (stored / 2) as u64;
    let started = Instant::now();
    let (count, start) = handle
        .count_changes(from, Timestamp(newest), keep)
        .expect("count");
    let counted = started.elapsed();
    let start = start.unwrap_or(from);
    let started = Instant::now();
    let keys = handle
        .change_keys(&mut ChangeCursor::new(start, Timestamp(newest)), 50_000)
        .expect("keys");
    let keyed = started.elapsed();
    let started = Instant::now();
    let page = handle
        .changes_at(&keys[..keys.len().min(5_000)])
        .expect("rows");
    println!(
        "store_ingest backlog: {count} changes counted and the start of the newest {keep} found \
         in {:.0} ms; {} keys after it in {:.1} ms; {} rows of them in {:.1} ms",
        counted.as_secs_f64() * 1e3,
        keys.len(),
        keyed.as_secs_f64() * 1e3,
        page.len(),
        started.elapsed().as_secs_f64() * 1e3
    );
}
