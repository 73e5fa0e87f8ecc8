//! A one-year history: does the one-day query of one point in 1-minute buckets stay fast
//! when the file holds a year?
//!
//! ```text
//! nice cargo bench -p gateway --bench store_year                  # 6 points, a year
//! nice cargo bench -p gateway --bench store_year -- --points 2 --days 90
//! ```
//!
//! A year at the load bench's rate (about 2,400 changes/s over its 12,000 points) is 75
//! billion rows: terabytes, more than this machine's disk. So the bench keeps the
//! *per-point* density real (one change every 5 s on average, jittered, as 2,400/s over
//! 12,000 points gives) and cuts the number of points: `--points` points × `--days` days,
//! written through the real store (writer thread, batches, WAL, FULL sync, rollups) in
//! time order, points interleaved, into a temporary directory (`--dir` to choose its
//! parent) that is deleted at the end. After each quarter of the range it flushes and
//! times the one-day query (median and slowest of 30, on a warm connection) for one
//! point, on the newest whole day and on a day near the start, with a 1-minute step
//! (rollups) and a 90 s step (samples). How those times move as the file grows from a
//! quarter to the whole year is the figure to extrapolate from: the query reads the
//! point's 1,440 rollup rows and a few samples at the ends, whatever the file's size; a
//! larger file only adds B-tree levels (one more page per seek for each ~100× more rows).
//! At the end the store is reopened (its `quick_check` reads the whole file: timed) and
//! the first query on a new connection is timed too.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use gateway::point::{PointId, Quality, Value};
use gateway::store::{Sample, Series, Store, StoreHandle, StoreOptions};
use gateway::time::Timestamp;

const DAY_MS: i64 = 86_400_000;
/// Mean time between two changes of one point: 2,400 changes/s over 12,000 points.
const MEAN_CHANGE_MS: i64 = 5_000;
/// 2025-01-01T00:00:00Z: the generated year is in the past, so every minute closes.
const START_MS: i64 = 1_735_689_600_000;
/// The bench stops generating past this file size (the machine's disk is shared).
const MAX_FILE_BYTES: u64 = 7_500_000_000;

struct Args {
    points: usize,
    days: i64,
    dir: Option<PathBuf>,
}

fn parse_args() -> Args {
    let mut args = Args {
        points: 6,
        days: 365,
        dir: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        match arg.as_str() {
            "--points" => args.points = it.next().and_then(|v| v.parse().ok()).unwrap_or(6),
            "--days" => args.days = it.next().and_then(|v| v.parse().ok()).unwrap_or(365),
            "--dir" => args.dir = it.next().map(PathBuf::from),
            // cargo bench passes --bench; anything else is ignored too.
            _ => {}
        }
    }
    args
}

fn main() {
    let args = parse_args();
    if std::env::args().all(|a| a != "--bench") {
        // `cargo test --benches`: a smoke run, a few days of two points.
        run(&Args {
            points: 2,
            days: 3,
            dir: args.dir,
        });
        return;
    }
    run(&args);
}

fn run(args: &Args) {
    let parent = args.dir.clone().unwrap_or_else(std::env::temp_dir);
    let dir = tempfile::tempdir_in(&parent).expect("temp dir");
    let options = StoreOptions {
        retain: Duration::from_secs(3 * 365 * 86_400),
        prune_every: Duration::from_secs(10 * 365 * 86_400),
        ..StoreOptions::default()
    };
    let store = Store::open(dir.path(), options).expect("store");
    let handle = store.handle();
    let runtime = tokio::runtime::Builder::new_current_thread()
        .build()
        .expect("runtime");
    let points: Vec<PointId> = (0..args.points)
        .map(|i| PointId::parse(&format!("jbc{i}.air_temperature")).expect("valid id"))
        .collect();
    println!(
        "store_year: {} points × {} days, one change per {} ms on average per point, in {}",
        args.points,
        args.days,
        MEAN_CHANGE_MS,
        dir.path().display()
    );
    let mut rng = fastrand::Rng::with_seed(15);
    let mut next: Vec<i64> = (0..args.points)
        .map(|_| START_MS + rng.i64(0..MEAN_CHANGE_MS))
        .collect();
    let mut value: Vec<f64> = vec![200.0; args.points];
    let end = START_MS + args.days * DAY_MS;
    let quarters: Vec<i64> = (1..=4)
        .map(|q| START_MS + (args.days * q / 4).max(1) * DAY_MS)
        .collect();
    let mut rows: u64 = 0;
    let started = Instant::now();
    let mut generating = Duration::ZERO;
    let mut since_flush = 0;
    let mut reached = START_MS;
    for checkpoint in quarters {
        let leg = Instant::now();
        loop {
            // The point with the earliest next change: time order, points interleaved.
            let (p, t) = next
                .iter()
                .enumerate()
                .min_by_key(|(_, t)| **t)
                .map(|(p, t)| (p, *t))
                .expect("at least one point");
            if t >= checkpoint.min(end) {
                break;
            }
            value[p] = (value[p] + rng.f64() * 2.0 - 1.0).clamp(20.0, 450.0);
            handle.sample(Sample {
                point: points[p].clone(),
                t: Timestamp(t),
                value: Some(Value::Number((value[p] * 10.0).round() / 10.0)),
                quality: Quality::Good,
            });
            next[p] = t + rng.i64(MEAN_CHANGE_MS / 5..MEAN_CHANGE_MS * 9 / 5);
            rows += 1;
            since_flush += 1;
            // The channel to the writer is unbounded: keep it short.
            if since_flush == 200_000 {
                runtime.block_on(handle.flush()).expect("commit");
                since_flush = 0;
            }
        }
        runtime.block_on(handle.flush()).expect("commit");
        generating += leg.elapsed();
        reached = checkpoint.min(end);
        let bytes = file_bytes(dir.path());
        let days = (checkpoint.min(end) - START_MS) / DAY_MS;
        println!(
            "\n{days} days: {rows} rows ({:.1} M), file {:.2} GB ({:.0} bytes/row), \
             written at {:.0} rows/s",
            rows as f64 / 1e6,
            bytes as f64 / 1e9,
            bytes as f64 / rows as f64,
            rows as f64 / generating.as_secs_f64()
        );
        let newest_day = checkpoint.min(end) - DAY_MS;
        let early_day = START_MS + DAY_MS;
        for (what, day) in [("newest day", newest_day), ("second day", early_day)] {
            for step in [60, 90] {
                let (median, slowest, buckets) = time_query(&handle, &points[0], day, step, 30);
                println!(
                    "  one day ({what}) in {step} s buckets: median {:.2} ms, slowest {:.2} ms \
                     ({buckets} buckets)",
                    ms(median),
                    ms(slowest)
                );
            }
        }
        if bytes > MAX_FILE_BYTES {
            println!("  stopping: the file passed {MAX_FILE_BYTES} bytes");
            break;
        }
    }
    drop(handle);
    store.close();
    let reopen = Instant::now();
    let store = Store::open(dir.path(), options).expect("reopen");
    let reopened = reopen.elapsed();
    let handle = store.handle();
    let first = Instant::now();
    let newest_day = reached - DAY_MS;
    let buckets = query(&handle, &points[0], newest_day, 60);
    let first = first.elapsed();
    println!(
        "\nreopened in {:.1} s (quick_check over the whole file); first one-day 1-minute \
         query on a new connection: {:.2} ms ({buckets} buckets); total {:.0} s",
        reopened.as_secs_f64(),
        ms(first),
        started.elapsed().as_secs_f64()
    );
    store.close();
}

fn query(handle: &StoreHandle, point: &PointId, day: i64, step: u64) -> usize {
    let history = handle
        .history(
            point,
            Timestamp(day),
            Timestamp(day + DAY_MS),
            Some(Duration::from_secs(step)),
        )
        .expect("query");
    match history.series {
        Series::Buckets(b) => b.len(),
        Series::Samples(s) => s.len(),
    }
}

/// Median and slowest of `n` runs, and the buckets the query gave.
fn time_query(
    handle: &StoreHandle,
    point: &PointId,
    day: i64,
    step: u64,
    n: usize,
) -> (Duration, Duration, usize) {
    let buckets = query(handle, point, day, step);
    let mut times: Vec<Duration> = (0..n)
        .map(|_| {
            let t = Instant::now();
            std::hint::black_box(query(handle, point, day, step));
            t.elapsed()
        })
        .collect();
    times.sort();
    (times[n / 2], times[n - 1], buckets)
}

fn file_bytes(dir: &std::path::Path) -> u64 {
    ["cellbus.db", "cellbus.db-wal"]
        .iter()
        .map(|f| std::fs::metadata(dir.join(f)).map_or(0, |m| m.len()))
        .sum()
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}
