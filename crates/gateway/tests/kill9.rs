//! A real process writing history is killed with SIGKILL mid-write; after a restart every
//! row it reported committed is there exactly once, the per-minute buckets (served from
//! the rollups committed with the rows, and from the samples of the minutes still open)
//! match those rows, and SQLite's integrity check passes.
//!
//! The test runs itself as the child: with `CELLBUS_KILL9_CHILD=<dir>` in its environment,
//! the same test function becomes the writer, so no helper binary is needed.

use std::io::{BufRead, BufReader, Write};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use gateway::point::{PointId, Quality, Value};
use gateway::store::{Sample, Series, Store, StoreOptions};
use gateway::time::Timestamp;

const CHILD_ENV: &str = "CELLBUS_KILL9_CHILD";
const TEST_NAME: &str = "store_keeps_every_committed_row_after_kill_9";
/// Commits the parent waits to see before it kills the child.
const COMMITS_BEFORE_KILL: u64 = 25;
/// Rows between two reported commits.
const ROWS_PER_FLUSH: u64 = 37;
/// Milliseconds between two samples: the rows the parent waits for span several minutes,
/// so some minutes are closed (rolled up) and some open when the child dies.
const SAMPLE_EVERY_MS: i64 = 200;

#[test]
fn store_keeps_every_committed_row_after_kill_9() {
    if let Ok(dir) = std::env::var(CHILD_ENV) {
        run_child(&dir);
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args(["--exact", TEST_NAME, "--nocapture", "--test-threads=1"])
        .env(CHILD_ENV, dir.path())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let mut lines = BufReader::new(stdout).lines();
    let mut committed = None;
    let mut commits = 0;
    let deadline = Instant::now() + Duration::from_secs(120);
    while commits < COMMITS_BEFORE_KILL {
        assert!(
            Instant::now() < deadline,
            "the child did not commit in time"
        );
        let line = lines
            .next()
            .expect("the child ended before it was killed")
            .unwrap();
        if let Some(n) = line.strip_prefix("committed ") {
            committed = Some(n.trim().parse::<u64>().unwrap());
            commits += 1;
        }
    }
    // The child keeps writing while it dies: SIGKILL, no chance to flush or close.
    child.kill().unwrap();
    let status = child.wait().unwrap();
    assert!(!status.success(), "the child must have been killed");
    // Lines already in the pipe were reported before the kill: they count too.
    for line in lines {
        if let Some(n) = line.unwrap().strip_prefix("committed ") {
            committed = Some(n.trim().parse::<u64>().unwrap());
        }
    }
    let committed = committed.unwrap();

    let store = Store::open(dir.path(), StoreOptions::default()).unwrap();
    let handle = store.handle();
    assert_eq!(handle.integrity_check().unwrap(), "ok");
    let history = handle
        .history(&point(), Timestamp(0), Timestamp(i64::MAX), None)
        .unwrap();
    let Series::Samples(samples) = history.series else {
        panic!("raw samples expected")
    };
    let values: Vec<u64> = samples
        .iter()
        .map(|s| match s.value {
            Some(Value::Number(n)) => n as u64,
            ref other => panic!("unexpected value {other:?}"),
        })
        .collect();
    // Every reported row is there, in order, once; rows after it may or may not be.
    assert!(
        values.len() as u64 > committed,
        "{} rows stored, {} reported committed",
        values.len(),
        committed + 1
    );
    for (i, v) in values.iter().enumerate() {
        assert_eq!(*v, i as u64, "row {i} is missing or duplicated");
    }
    // Minute buckets equal what the stored rows give (integers: sums are exact).
    let first = samples[0].t.0;
    let mut expected: Vec<(i64, u64, f64, f64, f64)> = Vec::new();
    for (s, v) in samples.iter().zip(&values) {
        let (b, v) = ((s.t.0 / 60_000) * 60_000, *v as f64);
        match expected.last_mut() {
            Some(e) if e.0 == b => {
                e.1 += 1;
                e.2 += v;
                e.4 = v;
            }
            _ => expected.push((b, 1, v, v, v)),
        }
    }
    for e in &mut expected {
        e.2 /= e.1 as f64;
    }
    let buckets = handle
        .history(
            &point(),
            Timestamp(first),
            Timestamp(i64::MAX),
            Some(Duration::from_secs(60)),
        )
        .unwrap();
    let Series::Buckets(buckets) = buckets.series else {
        panic!("buckets expected")
    };
    let got: Vec<(i64, u64, f64, f64, f64)> = buckets
        .iter()
        .map(|b| (b.t.0, b.count, b.avg, b.min, b.max))
        .collect();
    assert_eq!(got, expected);
    assert!(expected.len() >= 3, "{} minutes", expected.len());
    // The database takes writes again after the crash.
    handle.sample(Sample {
        point: point(),
        t: Timestamp(i64::MAX - 1),
        value: Some(Value::Number(-1.0)),
        quality: Quality::Good,
    });
    tokio::runtime::Builder::new_current_thread()
        .build()
        .unwrap()
        .block_on(handle.flush())
        .unwrap();
    assert_eq!(handle.integrity_check().unwrap(), "ok");
}

fn point() -> PointId {
    PointId::parse("kill.seq").unwrap()
}

/// Writes numbered samples as fast as it can, reporting each flushed number, until killed
/// (or for at most two minutes, so an orphan cannot run forever).
fn run_child(dir: &str) {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .build()
        .unwrap();
    let options = StoreOptions {
        batch_rows: 50,
        batch_delay: Duration::from_millis(5),
        ..StoreOptions::default()
    };
    let store = Store::open(std::path::Path::new(dir), options).unwrap();
    let handle = store.handle();
    let started = Instant::now();
    let mut out = std::io::stdout().lock();
    // Recent times: rows of 1970 would be the retention's to delete when the parent reopens
    // the store, racing its query. An hour back, so minutes close by the samples' times.
    let base = Timestamp::now().0 - 3_600_000;
    let mut i: u64 = 0;
    while started.elapsed() < Duration::from_secs(120) {
        handle.sample(Sample {
            point: point(),
            t: Timestamp(base + i as i64 * SAMPLE_EVERY_MS),
            value: Some(Value::Number(i as f64)),
            quality: Quality::Good,
        });
        if i % ROWS_PER_FLUSH == ROWS_PER_FLUSH - 1 {
            runtime.block_on(handle.flush()).unwrap();
            writeln!(out, "committed {i}").unwrap();
            out.flush().unwrap();
        }
        i += 1;
    }
}
