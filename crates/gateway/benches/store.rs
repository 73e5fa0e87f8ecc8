//! History throughput: committing value changes (batched, WAL, synchronous=FULL) in
//! bursts of 10,000 rows, and downsampled queries over a day of one
//! point: in 1-minute buckets (served by the per-minute rollups) and in 90 s buckets
//! (which no whole number of minutes makes: served from the samples).
//!
//! `nice cargo bench -p gateway --bench store -- --warm-up-time 1 --measurement-time 3`
//!
//! Sustained ingest (a million rows) is the `store_ingest` bench, the one-year database
//! the `store_year` bench.

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use gateway::point::{PointId, Quality, Value};
use gateway::store::{Sample, StoreOptions};
use gateway::time::Timestamp;

#[path = "support/store.rs"]
mod temp;
use temp::{device_points, temp_store};

const ROWS: usize = 10_000;
const POINTS: usize = 1_000;

fn commit(c: &mut Criterion) {
    let (_dir, store, runtime) = temp_store(StoreOptions::default());
    let handle = store.handle();
    let points = device_points(POINTS);
    let mut t = 0i64;
    let mut group = c.benchmark_group("history");
    group.throughput(Throughput::Elements(ROWS as u64));
    group.bench_function("commit 10k value changes over 1000 points", |b| {
        b.iter(|| {
            for i in 0..ROWS {
                t += 1;
                handle.sample(Sample {
                    point: points[i % POINTS].clone(),
                    t: Timestamp(t),
                    value: Some(Value::Number(t as f64)),
                    quality: Quality::Good,
                });
            }
            black_box(runtime.block_on(handle.flush()).expect("commit"));
        });
    });
    group.finish();
}

fn query(c: &mut Criterion) {
    let (_dir, store, runtime) = temp_store(StoreOptions::default());
    let handle = store.handle();
    let point = PointId::parse("jbc1.air_temperature").expect("valid id");
    // A day of changes every second.
    let day = 86_400i64;
    for s in 0..day {
        handle.sample(Sample {
            point: point.clone(),
            t: Timestamp(s * 1000),
            value: Some(Value::Number((s % 400) as f64)),
            quality: Quality::Good,
        });
    }
    runtime.block_on(handle.flush()).expect("commit");
    let mut group = c.benchmark_group("history");
    group.throughput(Throughput::Elements(day as u64));
    for (name, step) in [
        ("one day of 1 s changes in 1 min buckets", 60),
        (
            "one day of 1 s changes in 90 s buckets (from the samples)",
            90,
        ),
    ] {
        group.bench_function(name, |b| {
            b.iter(|| {
                black_box(
                    handle
                        .history(
                            &point,
                            Timestamp(0),
                            Timestamp(day * 1000),
                            Some(Duration::from_secs(step)),
                        )
                        .expect("query"),
                )
            });
        });
    }
    group.finish();
}

criterion_group!(benches, commit, query);
criterion_main!(benches);
