use super::*;
use crate::event::{Event, EventKind};
use crate::point::{DeviceId, PointId, Quality, Value};
use crate::time::Timestamp;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

fn point(name: &str) -> PointId {
    PointId::parse(name).unwrap()
}

fn sample(p: &str, t: i64, v: f64) -> Sample {
    Sample {
        point: point(p),
        t: Timestamp(t),
        value: Some(Value::Number(v)),
        quality: Quality::Good,
    }
}

/// Bad if `bad`, else good.
fn good_unless(bad: bool) -> Quality {
    if bad { Quality::Bad } else { Quality::Good }
}

/// A store with the default options in a fresh temporary directory (removed when
/// dropped).
fn temp_store() -> (tempfile::TempDir, Store) {
    temp_store_with(StoreOptions::default())
}

/// Like [`temp_store`], with `options`.
fn temp_store_with(options: StoreOptions) -> (tempfile::TempDir, Store) {
    let dir = tempfile::tempdir().unwrap();
    let store = Store::open(dir.path(), options).unwrap();
    (dir, store)
}

fn samples_of(h: &History) -> Vec<(i64, Option<Value>)> {
    match &h.series {
        Series::Samples(s) => s.iter().map(|s| (s.t.0, s.value.clone())).collect(),
        Series::Buckets(_) => panic!("expected raw samples"),
    }
}

/// `h`'s raw samples with their quality: (time, value, quality).
fn samples_with_quality(h: History) -> Vec<(i64, Option<Value>, Quality)> {
    match h.series {
        Series::Samples(s) => s.into_iter().map(|s| (s.t.0, s.value, s.quality)).collect(),
        Series::Buckets(_) => panic!("expected raw samples"),
    }
}

#[tokio::test]
async fn samples_come_back_in_time_order_for_their_point_and_range() {
    let (_dir, store) = temp_store();
    let h = store.handle();
    for (t, v) in [(1000, 1.0), (2000, 2.0), (3000, 3.0), (4000, 4.0)] {
        h.sample(sample("a.temp", t, v));
        h.sample(sample("b.temp", t, v * 10.0));
    }
    h.sample(Sample {
        point: point("a.model"),
        t: Timestamp(1500),
        value: Some(Value::Text("JTSE".into())),
        quality: Quality::Good,
    });
    assert_eq!(h.flush().await.unwrap(), 9);
    let got = h
        .history(&point("a.temp"), Timestamp(2000), Timestamp(4000), None)
        .unwrap();
    assert_eq!(
        samples_of(&got),
        vec![
            (2000, Some(Value::Number(2.0))),
            (3000, Some(Value::Number(3.0)))
        ]
    );
    assert_eq!(got.before.unwrap().value, Some(Value::Number(1.0)));
    let text = h
        .history(&point("a.model"), Timestamp(0), Timestamp(9999), None)
        .unwrap();
    assert_eq!(
        samples_of(&text),
        vec![(1500, Some(Value::Text("JTSE".into())))]
    );
    let none = h
        .history(&point("c.temp"), Timestamp(0), Timestamp(9999), None)
        .unwrap();
    assert_eq!(samples_of(&none), vec![]);
}

#[tokio::test]
async fn a_batch_larger_than_one_multi_row_insert_keeps_every_value_and_quality_in_order() {
    let (_dir, store) = temp_store();
    let h = store.handle();
    // Two full multi-row statements and a remainder of single rows, over two points.
    let count = writer::INSERT_ROWS as i64 * 2 + 7;
    let value = |t: i64| match t % 3 {
        0 => Some(Value::Number(t as f64 / 4.0)),
        1 => Some(Value::Text(format!("text {t}"))),
        _ => None,
    };
    let quality = |t: i64| good_unless(t % 3 == 2);
    for t in 0..count {
        h.sample(Sample {
            point: point(if t % 2 == 0 { "a.mixed" } else { "b.mixed" }),
            t: Timestamp(t),
            value: value(t),
            quality: quality(t),
        });
    }
    assert_eq!(h.flush().await.unwrap(), count as u64);
    for (name, parity) in [("a.mixed", 0), ("b.mixed", 1)] {
        let got = h
            .history(&point(name), Timestamp(0), Timestamp(count), None)
            .unwrap();
        let want: Vec<(i64, Option<Value>, Quality)> = (0..count)
            .filter(|t| t % 2 == parity)
            .map(|t| (t, value(t), quality(t)))
            .collect();
        assert_eq!(samples_with_quality(got), want, "{name}");
    }
}

#[tokio::test]
async fn a_batch_keeps_each_points_samples_in_the_order_they_came_even_at_one_time() {
    // The writer inserts a batch point by point (stable): samples of one point at one
    // time, such as a poll's good readings and then the bad ones of the device going
    // down, must keep their order; three points interleaved over several multi-row
    // statements, every sample at the same time.
    let (dir, store) = temp_store();
    let h = store.handle();
    let names = ["c.level", "a.level", "b.level"];
    let count = writer::INSERT_ROWS * 3 + 5;
    let quality = |i: usize| good_unless(i % 4 == 3);
    for i in 0..count {
        h.sample(Sample {
            point: point(names[i % 3]),
            t: Timestamp(1000),
            value: Some(Value::Number(i as f64)),
            quality: quality(i),
        });
    }
    assert_eq!(h.flush().await.unwrap(), count as u64);
    for (k, name) in names.iter().enumerate() {
        let got = h
            .history(&point(name), Timestamp(0), Timestamp(2000), None)
            .unwrap();
        let want: Vec<(i64, Option<Value>, Quality)> = (0..count)
            .filter(|i| i % 3 == k)
            .map(|i| (1000, Some(Value::Number(i as f64)), quality(i)))
            .collect();
        assert_eq!(samples_with_quality(got), want, "{name}");
    }
    let stored: Vec<(String, Option<f64>)> = every_change(dir.path())
        .into_iter()
        .map(|(_, name, value)| (name, value))
        .collect();
    let order: Vec<(String, Option<f64>)> = names
        .iter()
        .enumerate()
        .flat_map(|(k, name)| {
            (0..count)
                .filter(move |i| i % 3 == k)
                .map(move |i| (name.to_string(), Some(i as f64)))
        })
        .collect();
    assert_eq!(
        stored, order,
        "the stored changes of one time: point by point, in the order the points were first \
         stored, each point's in the order they came"
    );
}

#[tokio::test]
async fn a_step_gives_average_min_and_max_per_bucket_of_good_values() {
    let (_dir, store) = temp_store();
    let h = store.handle();
    for (t, v) in [(0, 1.0), (400, 3.0), (999, 5.0), (1000, 10.0), (2500, 7.0)] {
        h.sample(sample("a.temp", t, v));
    }
    h.sample(Sample {
        point: point("a.temp"),
        t: Timestamp(2600),
        value: None,
        quality: Quality::Bad,
    });
    h.flush().await.unwrap();
    let got = h
        .history(
            &point("a.temp"),
            Timestamp(0),
            Timestamp(3000),
            Some(Duration::from_secs(1)),
        )
        .unwrap();
    let Series::Buckets(b) = got.series else {
        panic!("expected buckets")
    };
    assert_eq!(
        b,
        vec![
            Bucket {
                t: Timestamp(0),
                avg: 3.0,
                min: 1.0,
                max: 5.0,
                count: 3
            },
            Bucket {
                t: Timestamp(1000),
                avg: 10.0,
                min: 10.0,
                max: 10.0,
                count: 1
            },
            Bucket {
                t: Timestamp(2000),
                avg: 7.0,
                min: 7.0,
                max: 7.0,
                count: 1
            },
        ]
    );
    assert_eq!(got.step_ms, Some(1000));
}

#[tokio::test]
async fn rows_are_committed_in_batches_without_a_flush() {
    let (_dir, store) = temp_store_with(StoreOptions {
        batch_rows: 10,
        batch_delay: Duration::from_secs(3600),
        ..StoreOptions::default()
    });
    let h = store.handle();
    for t in 0..25 {
        h.sample(sample("a.temp", t, t as f64));
    }
    // Two full batches are committed by the writer on its own; wait for them with a
    // bounded poll of the committed count (the writer is a real thread).
    let deadline = Instant::now() + Duration::from_secs(10);
    while h.stats().samples_written.load(Ordering::Relaxed) < 20 {
        assert!(Instant::now() < deadline, "batches were not committed");
        std::thread::yield_now();
    }
    assert_eq!(h.stats().samples_written.load(Ordering::Relaxed), 20);
    assert_eq!(h.flush().await.unwrap(), 25);
}

#[tokio::test]
async fn closing_the_store_commits_what_is_queued() {
    let (dir, store) = temp_store_with(StoreOptions {
        batch_delay: Duration::from_secs(3600),
        ..StoreOptions::default()
    });
    let h = store.handle();
    for t in 0..7 {
        h.sample(sample("a.temp", t, 1.0));
    }
    store.close();
    let store = Store::open(dir.path(), StoreOptions::default()).unwrap();
    let got = store
        .handle()
        .history(&point("a.temp"), Timestamp(0), Timestamp(100), None)
        .unwrap();
    assert_eq!(samples_of(&got).len(), 7);
}

#[tokio::test]
async fn retention_deletes_samples_and_events_older_than_the_limit_and_keeps_audit() {
    let (_dir, store) = temp_store_with(StoreOptions {
        retain: Duration::from_secs(10),
        ..StoreOptions::default()
    });
    let h = store.handle();
    for t in [1_000, 5_000, 15_000, 25_000] {
        h.sample(sample("a.temp", t, 1.0));
        h.event(Event {
            t: Timestamp(t),
            kind: EventKind::DeviceDown,
            line: None,
            device: Some(DeviceId::new("a").unwrap()),
            point: None,
            message: "down".into(),
            fields: crate::event::Fields::new(),
        });
    }
    h.audit(AuditEntry {
        t: Timestamp(1),
        client: "127.0.0.1:5000".into(),
        device: "a".into(),
        point: "a.temp".into(),
        old: None,
        new: serde_json::json!(3),
        result: AuditResult::Refused,
        detail: "writes are disabled".into(),
    });
    h.flush().await.unwrap();
    // Now is 20 s: everything before 10 s goes.
    assert_eq!(h.prune(Timestamp(20_000)).await.unwrap(), 4);
    let got = h
        .history(&point("a.temp"), Timestamp(0), Timestamp(99_999), None)
        .unwrap();
    assert_eq!(
        samples_of(&got)
            .into_iter()
            .map(|(t, _)| t)
            .collect::<Vec<_>>(),
        vec![15_000, 25_000]
    );
    let events = h
        .events(&EventFilter {
            limit: 100,
            ..EventFilter::default()
        })
        .unwrap();
    assert_eq!(
        events.iter().map(|e| e.t.0).collect::<Vec<_>>(),
        vec![25_000, 15_000]
    );
    assert_eq!(h.audit_log(None, 10).unwrap().len(), 1);
}

#[tokio::test]
async fn events_filter_by_device_kind_and_time_newest_first() {
    let (_dir, store) = temp_store();
    let h = store.handle();
    let ev = |t, kind, device: &str| Event {
        t: Timestamp(t),
        kind,
        line: Some("bench".into()),
        device: Some(DeviceId::new(device).unwrap()),
        point: None,
        message: format!("{device} {t}"),
        // Odd times carry fields, even ones none.
        fields: crate::event::fields([(
            "odd_time",
            if t % 2 == 1 {
                serde_json::json!(t)
            } else {
                serde_json::Value::Null
            },
        )]),
    };
    h.event(ev(1, EventKind::DeviceDown, "a"));
    h.event(ev(2, EventKind::DeviceUp, "a"));
    h.event(ev(3, EventKind::DeviceDown, "b"));
    h.event(ev(4, EventKind::DeviceDown, "a"));
    h.flush().await.unwrap();
    let got = h
        .events(&EventFilter {
            device: Some("a".into()),
            kind: Some(EventKind::DeviceDown),
            limit: 10,
            ..EventFilter::default()
        })
        .unwrap();
    assert_eq!(
        got.iter().map(|e| e.message.as_str()).collect::<Vec<_>>(),
        vec!["a 4", "a 1"]
    );
    let got = h
        .events(&EventFilter {
            from: Some(Timestamp(2)),
            to: Some(Timestamp(4)),
            limit: 1,
            ..EventFilter::default()
        })
        .unwrap();
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].message, "b 3");
    assert_eq!(got[0].line.as_deref(), Some("bench"));
    assert_eq!(
        serde_json::Value::Object(got[0].fields.clone()),
        serde_json::json!({"odd_time": 3}),
        "an event's fields are kept"
    );
    let all = h
        .events(&EventFilter {
            limit: 10,
            ..EventFilter::default()
        })
        .unwrap();
    assert!(
        all.iter()
            .any(|e| e.message == "a 2" && e.fields.is_empty()),
        "an event without fields reads back with none: {all:?}"
    );
}

#[tokio::test]
async fn audit_rows_keep_old_and_new_values_as_json() {
    let (_dir, store) = temp_store();
    let h = store.handle();
    h.audit(AuditEntry {
        t: Timestamp(5),
        client: "127.0.0.1:4000".into(),
        device: "jbc1".into(),
        point: "jbc1.air_temperature_setpoint".into(),
        old: Some(Value::Number(350.0)),
        new: serde_json::json!(400),
        result: AuditResult::Accepted,
        detail: "written".into(),
    });
    h.flush().await.unwrap();
    let rows = h.audit_log(Some("jbc1"), 10).unwrap();
    assert_eq!(rows.len(), 1);
    assert_eq!(rows[0].old_value, Some(serde_json::json!(350.0)));
    assert_eq!(rows[0].new_value, serde_json::json!(400));
    assert_eq!(rows[0].result, "accepted");
    assert!(h.audit_log(Some("other"), 10).unwrap().is_empty());
    assert_eq!(h.integrity_check().unwrap(), "ok");
}

#[test]
fn an_unusable_data_directory_is_named_in_the_error() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("not-a-dir");
    std::fs::write(&file, b"x").unwrap();
    let err = Store::open(&file.join("sub"), StoreOptions::default()).unwrap_err();
    assert!(err.to_string().contains("not-a-dir"), "{err}");
    assert!(err.to_string().contains("--data"), "{err}");
}

#[test]
fn event_kinds_round_trip_through_their_names() {
    for kind in EventKind::ALL {
        assert_eq!(EventKind::parse(kind.as_str()), Some(kind));
    }
    assert_eq!(EventKind::parse("nope"), None);
}

// --- Faults: a full disk, a damaged file, an unusable directory ---------------------------

/// Events of `kind` in the store.
fn events_of(h: &StoreHandle, kind: EventKind) -> Vec<EventRecord> {
    h.events(&EventFilter {
        kind: Some(kind),
        limit: 100,
        ..EventFilter::default()
    })
    .unwrap()
}

/// Flushes until a commit works (the wait of a failed one may have to pass first).
async fn flush_until_committed(h: &StoreHandle) -> u64 {
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        match h.flush().await {
            Ok(rows) => return rows,
            Err(e) => assert!(Instant::now() < deadline, "still failing after 60 s: {e}"),
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// Enough samples to need new pages, so a capped file refuses them.
fn fill(h: &StoreHandle, p: &str, from: i64, count: i64) {
    for t in from..from + count {
        h.sample(sample(p, t, t as f64));
    }
}

fn audit(t: i64, detail: &str) -> AuditEntry {
    AuditEntry {
        t: Timestamp(t),
        client: "127.0.0.1:5000".into(),
        device: "jbc1".into(),
        point: "jbc1.air_temperature_setpoint".into(),
        old: None,
        new: serde_json::json!(350),
        result: AuditResult::Accepted,
        detail: detail.into(),
    }
}

#[tokio::test]
async fn a_full_disk_is_retried_with_a_doubling_wait_instead_of_a_busy_loop() {
    let (_dir, store) = temp_store();
    let h = store.handle();
    h.fill_disk(true).await;
    fill(&h, "a.temp", 0, 5_000);
    let err = h.flush().await.unwrap_err().to_string();
    assert!(err.contains("full"), "{err}");
    // A bounded window of real time with rows arriving all along: before the fix the
    // writer retried at once, thousands of times a second (57 000 in 15 s on a full disk).
    let window = Instant::now();
    let mut t = 5_000;
    while window.elapsed() < Duration::from_millis(1500) {
        h.sample(sample("a.temp", t, 0.0));
        t += 1;
        std::thread::sleep(Duration::from_millis(1));
    }
    let attempts = h.stats().commit_errors.load(Ordering::Relaxed);
    // 100 ms doubling: tries at 0, 0.1, 0.3, 0.7 and 1.5 s.
    assert!(attempts <= 6, "{attempts} commit attempts in 1.5 s");
    assert!(h.stats().pending_rows.load(Ordering::Relaxed) >= 5_000);
    assert_eq!(h.stats().rows_dropped.load(Ordering::Relaxed), 0);
}

#[test]
fn failed_commits_wait_100_ms_doubling_to_30_s_with_one_log_line_per_wait() {
    use super::fault::CommitFaults;
    let start = Instant::now();
    let mut faults = CommitFaults::default();
    let (mut attempts, mut lines, mut firsts) = (Vec::new(), 0, 0);
    // Ten minutes of a disk that stays full, looked at every 10 ms.
    for tick in 0..60_000u64 {
        let now = start + Duration::from_millis(10 * tick);
        if !faults.may_commit(now) {
            continue;
        }
        attempts.push(now - start);
        let failure = faults.failed(now, "database or disk is full");
        lines += usize::from(failure.log.is_some());
        firsts += usize::from(failure.first);
    }
    let gaps: Vec<u64> = attempts
        .windows(2)
        .map(|w| (w[1] - w[0]).as_millis() as u64)
        .collect();
    assert_eq!(
        gaps[..10],
        [100, 200, 400, 800, 1600, 3200, 6400, 12_800, 25_600, 30_000]
    );
    assert!(gaps[10..].iter().all(|g| *g == 30_000), "{gaps:?}");
    assert_eq!(attempts.len(), 28);
    assert_eq!(lines, attempts.len(), "one line per wait");
    assert_eq!(firsts, 1);
    let end = start + Duration::from_secs(600);
    let recovery = faults.succeeded(end).unwrap();
    assert_eq!(recovery.failures, 28);
    assert_eq!(recovery.lasted, Duration::from_secs(600));
    assert!(faults.may_commit(end));
    assert_eq!(faults.succeeded(end), None);
}

#[test]
fn commits_forced_during_a_wait_still_log_at_most_one_line_per_wait() {
    use super::fault::CommitFaults;
    let start = Instant::now();
    let mut faults = CommitFaults::default();
    let mut lines = Vec::new();
    // A commit forced every millisecond for a minute (flushes, shutdown): at most a line per
    // wait, and every failure counted in one of them.
    for ms in 0..60_000u64 {
        let now = start + Duration::from_millis(ms);
        if let Some(line) = faults.failed(now, "disk I/O error").log {
            lines.push(line);
        }
    }
    assert!(lines.len() <= 8, "{} lines: {lines:#?}", lines.len());
    assert!(
        lines[0].starts_with("commit failed: disk I/O error"),
        "{}",
        lines[0]
    );
    assert!(
        lines[1].contains("commits failed in the last"),
        "{}",
        lines[1]
    );
}

#[tokio::test]
async fn rows_kept_while_the_disk_is_full_are_committed_when_it_has_room_and_an_event_says_so() {
    let (_dir, store) = temp_store();
    let h = store.handle();
    assert_eq!(h.health(Timestamp::now()).history, HistoryState::Ok);
    h.fill_disk(true).await;
    fill(&h, "a.temp", 0, 3_000);
    h.audit(audit(1, "while full"));
    assert!(h.flush().await.is_err());
    let failed_at = Timestamp::now();
    let health = h.health(failed_at);
    assert!(health.degraded());
    assert!(
        health.summary().starts_with("failing: "),
        "{}",
        health.summary()
    );
    assert!(health.pending_rows >= 3_001, "{health:?}");

    h.fill_disk(false).await;
    flush_until_committed(&h).await;
    let got = h
        .history(&point("a.temp"), Timestamp(0), Timestamp(99_999), None)
        .unwrap();
    assert_eq!(samples_of(&got).len(), 3_000);
    assert_eq!(h.audit_log(None, 10).unwrap().len(), 1);
    let failed = events_of(&h, EventKind::HistoryFailed);
    assert_eq!(failed.len(), 1);
    assert!(failed[0].message.contains("full"), "{}", failed[0].message);
    let recovered = events_of(&h, EventKind::HistoryRecovered);
    assert_eq!(recovered.len(), 1);
    assert!(
        recovered[0].message.contains("work again after"),
        "{}",
        recovered[0].message
    );
    // Health looks at the last minute, not at errors since start.
    let now = Timestamp::now();
    assert!(h.health(now).degraded(), "a failure less than a minute ago");
    let later = h.health(now.plus(FAULT_WINDOW + Duration::from_secs(1)));
    assert_eq!(later.history, HistoryState::Ok);
    assert!(later.last_fault.is_some());
    assert_eq!(later.pending_rows, 0);
}

#[tokio::test]
async fn back_pressure_drops_the_oldest_samples_and_never_an_audit_row_or_an_event() {
    let (_dir, store) = temp_store();
    let h = store.handle();
    h.fill_disk(true).await;
    h.audit(audit(0, "first"));
    let over = 1_000;
    let total = i64::try_from(MAX_PENDING_ROWS).unwrap() + over;
    for t in 0..total {
        h.sample(sample("a.temp", t, 0.0));
        if t % 20_000 == 0 {
            h.event(Event {
                t: Timestamp(t),
                kind: EventKind::DeviceDown,
                line: None,
                device: None,
                point: None,
                message: format!("down at {t}"),
                fields: crate::event::Fields::new(),
            });
        }
    }
    h.audit(audit(total, "last"));
    assert!(h.flush().await.is_err());
    h.fill_disk(false).await;
    flush_until_committed(&h).await;
    assert_eq!(h.audit_log(None, 10).unwrap().len(), 2);
    assert_eq!(events_of(&h, EventKind::DeviceDown).len(), 11);
    let dropped = h.stats().rows_dropped.load(Ordering::Relaxed);
    // The extra samples, and as many as the events, audit rows and the history_failed
    // event pending with them, made room by dropping samples.
    assert!(
        (over as u64..=over as u64 + 14).contains(&dropped),
        "{dropped}"
    );
    let got = h
        .history(
            &point("a.temp"),
            Timestamp(0),
            Timestamp(i64::MAX),
            Some(Duration::from_secs(1_000_000)),
        )
        .unwrap();
    let Series::Buckets(buckets) = got.series else {
        panic!("expected buckets")
    };
    assert_eq!(buckets[0].count, (total as u64) - dropped);
    // The oldest samples went, the newest are there.
    let newest = h
        .history(
            &point("a.temp"),
            Timestamp(total - 1),
            Timestamp(total),
            None,
        )
        .unwrap();
    assert_eq!(samples_of(&newest).len(), 1);
    let oldest = h
        .history(
            &point("a.temp"),
            Timestamp(0),
            Timestamp(dropped as i64),
            None,
        )
        .unwrap();
    assert_eq!(samples_of(&oldest).len(), 0);
}

#[tokio::test]
async fn a_garbage_file_is_moved_aside_and_a_new_history_started_with_an_event() {
    let dir = tempfile::tempdir().unwrap();
    let garbage: Vec<u8> = (0..10_000u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    std::fs::write(dir.path().join(DB_FILE), &garbage).unwrap();
    let store = Store::open(dir.path(), StoreOptions::default()).unwrap();
    let h = store.handle();
    h.sample(sample("a.temp", 1, 1.0));
    h.flush().await.unwrap();
    let aside: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n.starts_with("cellbus.db.corrupt-"))
        .collect();
    assert_eq!(aside.len(), 1, "{aside:?}");
    // cellbus.db.corrupt-20261125T064500Z
    let stamp = aside[0].trim_start_matches("cellbus.db.corrupt-");
    assert_eq!(stamp.len(), 16, "{stamp}");
    assert!(
        stamp.ends_with('Z') && stamp.as_bytes()[8] == b'T',
        "{stamp}"
    );
    assert_eq!(std::fs::read(dir.path().join(&aside[0])).unwrap(), garbage);
    let reset = events_of(&h, EventKind::HistoryReset);
    assert_eq!(reset.len(), 1);
    assert!(reset[0].message.contains(&aside[0]), "{}", reset[0].message);
    assert!(
        reset[0].message.contains("not a database"),
        "{}",
        reset[0].message
    );
    assert_eq!(h.integrity_check().unwrap(), "ok");
    assert_eq!(h.health(Timestamp::now()).history, HistoryState::Ok);
}

#[tokio::test]
async fn a_file_with_a_damaged_page_fails_quick_check_and_is_moved_aside() {
    let dir = tempfile::tempdir().unwrap();
    {
        let store = Store::open(dir.path(), StoreOptions::default()).unwrap();
        let h = store.handle();
        fill(&h, "a.temp", 0, 20_000);
        h.flush().await.unwrap();
        store.close();
    }
    // Checkpointed at close: the rows are in the main file. Damage a page in its middle.
    let path = dir.path().join(DB_FILE);
    let mut bytes = std::fs::read(&path).unwrap();
    let page = 4096;
    let middle = (bytes.len() / page / 2) * page;
    bytes[middle..middle + page].fill(0x5a);
    std::fs::write(&path, &bytes).unwrap();
    let _ = std::fs::remove_file(dir.path().join("cellbus.db-wal"));
    let store = Store::open(dir.path(), StoreOptions::default()).unwrap();
    let h = store.handle();
    h.flush().await.unwrap();
    let reset = events_of(&h, EventKind::HistoryReset);
    assert_eq!(reset.len(), 1);
    assert!(
        reset[0].message.contains("quick_check"),
        "{}",
        reset[0].message
    );
    let got = h
        .history(&point("a.temp"), Timestamp(0), Timestamp(99_999), None)
        .unwrap();
    assert_eq!(samples_of(&got).len(), 0, "a new, empty history");
}

#[tokio::test]
async fn an_unusable_data_directory_turns_the_history_off_and_rows_are_counted_and_discarded() {
    let dir = tempfile::tempdir().unwrap();
    // A regular file where the directory should be: refused even to root.
    let data = dir.path().join("data");
    std::fs::write(&data, b"not a directory").unwrap();
    let store = Store::start(&data, StoreOptions::default());
    let h = store.handle();
    assert!(h.wait_open().is_err());
    let health = h.health(Timestamp::now());
    assert!(health.degraded());
    let summary = health.summary();
    assert!(summary.starts_with("off: "), "{summary}");
    assert!(summary.contains(&data.display().to_string()), "{summary}");
    assert!(summary.contains("os error"), "{summary}");
    for t in 0..10 {
        h.sample(sample("a.temp", t, 1.0));
    }
    h.audit(audit(1, "off"));
    let err = h.flush().await.unwrap_err().to_string();
    assert!(err.contains("history is off"), "{err}");
    assert_eq!(h.stats().rows_dropped.load(Ordering::Relaxed), 11);
    let err = h
        .history(&point("a.temp"), Timestamp(0), Timestamp(10), None)
        .unwrap_err();
    assert!(matches!(err, StoreError::Unavailable { .. }), "{err}");
    let text = err.to_string();
    assert!(
        text.contains(&data.display().to_string()) && text.contains("os error"),
        "{text}"
    );
    store.close();
}

// --- Retention ---------------------------------------------------------------------------

#[tokio::test]
async fn retention_deletes_in_chunks_and_commits_new_rows_between_them() {
    let (_dir, store) = temp_store_with(StoreOptions {
        retain: Duration::from_secs(10),
        prune_chunk_rows: 100,
        ..StoreOptions::default()
    });
    let h = store.handle();
    fill(&h, "a.temp", 0, 10_000);
    h.flush().await.unwrap();
    let prune = h.prune(Timestamp(1_000_000));
    h.sample(sample("b.temp", 999_999, 1.0));
    let flushed = h.flush();
    flushed.await.unwrap();
    let pruned = h.stats().rows_pruned.load(Ordering::Relaxed);
    // Before the fix the whole delete ran first, in one transaction.
    assert!(
        pruned < 10_000,
        "{pruned} rows pruned before a new row was committed"
    );
    assert_eq!(prune.await.unwrap(), 10_000);
    let got = h
        .history(&point("a.temp"), Timestamp(0), Timestamp(i64::MAX), None)
        .unwrap();
    assert!(samples_of(&got).is_empty());
}

#[tokio::test]
async fn audit_rows_have_their_own_longer_retention() {
    let (_dir, store) = temp_store_with(StoreOptions {
        retain: Duration::from_secs(10),
        retain_audit: Duration::from_secs(100),
        ..StoreOptions::default()
    });
    let h = store.handle();
    for t in [1_000, 50_000, 150_000] {
        h.audit(audit(t, &format!("at {t}")));
        h.sample(sample("a.temp", t, 1.0));
    }
    h.flush().await.unwrap();
    // Now is 160 s: samples before 150 s go, audit rows before 60 s.
    assert_eq!(h.prune(Timestamp(160_000)).await.unwrap(), 2 + 2);
    let kept: Vec<i64> = h
        .audit_log(None, 10)
        .unwrap()
        .iter()
        .map(|a| a.t.0)
        .collect();
    assert_eq!(kept, vec![150_000]);

    // An audit retention shorter than the history's: the history's wins.
    let short = StoreOptions {
        retain: Duration::from_secs(100),
        retain_audit: Duration::from_secs(10),
        ..StoreOptions::default()
    };
    assert_eq!(short.audit_retention(), Duration::from_secs(100));
    assert_eq!(
        StoreOptions::default().audit_retention(),
        Duration::from_secs(365 * 24 * 3600)
    );
}

#[tokio::test]
async fn a_new_file_vacuums_incrementally_and_shrinks_with_its_wal_after_a_prune() {
    let (dir, store) = temp_store_with(StoreOptions {
        retain: Duration::from_secs(10),
        ..StoreOptions::default()
    });
    let h = store.handle();
    let rows = 100_000;
    fill(&h, "a.temp", 0, rows);
    h.flush().await.unwrap();
    let size = |name: &str| std::fs::metadata(dir.path().join(name)).map_or(0, |m| m.len());
    let before = size(DB_FILE) + size("cellbus.db-wal");
    let started = Instant::now();
    assert_eq!(h.prune(Timestamp(10_000_000)).await.unwrap(), rows as u64);
    let took = started.elapsed();
    let after_db = size(DB_FILE);
    let after_wal = size("cellbus.db-wal");
    println!(
        "prune of {rows} rows: {took:?}; files {before} bytes before, db {after_db} + wal \
         {after_wal} after"
    );
    assert_eq!(after_wal, 0, "the WAL is truncated after a prune");
    assert!(
        after_db * 4 < before,
        "{after_db} bytes after, {before} before"
    );
    let conn = rusqlite::Connection::open(dir.path().join(DB_FILE)).unwrap();
    let auto: i64 = conn
        .query_row("PRAGMA auto_vacuum", [], |r| r.get(0))
        .unwrap();
    assert_eq!(auto, 2, "INCREMENTAL");
    let free: i64 = conn
        .query_row("PRAGMA freelist_count", [], |r| r.get(0))
        .unwrap();
    assert_eq!(free, 0);
}

// --- The gateway on a full disk ----------------------------------------------------------

#[tokio::test(start_paused = true)]
async fn a_full_disk_leaves_live_values_served_and_healthz_reporting_the_fault() {
    use crate::http::{WritePolicy, router};
    use crate::metrics::{PollLabels, PollResult};
    use axum::body::Body;
    use axum::http::{Request, StatusCode};
    use tower::ServiceExt;

    let rig = crate::testing::rig(1);
    let app = router(
        std::sync::Arc::clone(&rig.cell),
        WritePolicy {
            enabled: false,
            token: None,
            read_token: None,
        },
        rig.shutdown.subscribe(),
    );
    let get = |uri: &'static str| {
        let app = app.clone();
        async move {
            let response = app
                .oneshot(Request::get(uri).body(Body::empty()).unwrap())
                .await
                .unwrap();
            let status = response.status();
            let body = axum::body::to_bytes(response.into_body(), 1 << 20)
                .await
                .unwrap();
            (
                status,
                serde_json::from_slice::<serde_json::Value>(&body).unwrap(),
            )
        }
    };
    let polls = || {
        rig.cell
            .metrics()
            .polls
            .get_or_create(&PollLabels {
                line: "bench".into(),
                device: "jbc1".into(),
                result: PollResult::ok,
            })
            .get()
    };
    tokio::time::sleep(Duration::from_secs(2)).await;
    let h = rig.cell.store().clone();
    h.flush().await.unwrap();
    h.fill_disk(true).await;
    fill(&h, "pad.rows", Timestamp::now().0, 5_000);
    assert!(h.flush().await.is_err(), "the disk is full");

    let before = polls();
    tokio::time::sleep(Duration::from_secs(5)).await;
    assert!(polls() > before, "polling goes on");
    let (status, devices) = get("/api/devices").await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(devices["devices"][0]["status"], "up", "{devices}");
    let (status, health) = get("/healthz").await;
    assert_eq!(status, StatusCode::SERVICE_UNAVAILABLE);
    assert_eq!(health["status"], "failing", "{health}");
    assert!(
        health["reasons"][0]
            .as_str()
            .unwrap()
            .starts_with("the history cannot be written: "),
        "{health}"
    );
    let history = health["history"].as_str().unwrap();
    assert!(
        history.starts_with("failing: ") && history.contains("full"),
        "{health}"
    );
    assert!(
        health["history_pending_rows"].as_u64().unwrap() >= 5_000,
        "{health}"
    );
    assert!(health["history_last_error_at"].is_string(), "{health}");
    // What was committed can still be read.
    let (status, _) = get("/api/history?point=jbc1.air_temperature").await;
    assert_eq!(status, StatusCode::OK);

    h.fill_disk(false).await;
    flush_until_committed(&h).await;
    assert_eq!(events_of(&h, EventKind::HistoryRecovered).len(), 1);
    let (_, health) = get("/healthz").await;
    assert_eq!(health["history_pending_rows"], 0, "{health}");
}

#[tokio::test]
async fn stored_changes_of_every_point_come_back_in_time_order_in_pages() {
    let (_dir, store) = temp_store();
    let h = store.handle();
    // Stored out of time order, as two lines' changes can be.
    for (p, t, v) in [
        ("a.temp", 2000, 2.0),
        ("b.temp", 1000, 1.0),
        ("a.temp", 3000, 3.0),
        ("b.temp", 3000, 30.0),
        ("a.temp", 5000, 5.0),
    ] {
        h.sample(sample(p, t, v));
    }
    h.flush().await.unwrap();
    let all = |after: ChangeKey| {
        h.changes(after, Timestamp(4000), 2)
            .unwrap()
            .into_iter()
            .map(|c| (c.point, c.key.t.0))
            .collect::<Vec<_>>()
    };
    let first = h
        .changes(ChangeKey::before(Timestamp(0)), Timestamp(4000), 2)
        .unwrap();
    assert_eq!(
        all(ChangeKey::before(Timestamp(0))),
        vec![("b.temp".to_owned(), 1000), ("a.temp".to_owned(), 2000)]
    );
    assert_eq!(
        all(first[1].key),
        vec![("a.temp".to_owned(), 3000), ("b.temp".to_owned(), 3000)],
        "the page after the last key, ties in the order stored (within a commit point by \
         point), nothing after `until`"
    );
    let (count, start) = h
        .count_changes(ChangeKey::before(Timestamp(0)), Timestamp(4000), 10)
        .unwrap();
    assert_eq!((count, start), (4, None));
    let (count, start) = h
        .count_changes(ChangeKey::before(Timestamp(0)), Timestamp(4000), 2)
        .unwrap();
    assert_eq!(count, 4);
    assert_eq!(
        all(start.unwrap()),
        vec![("a.temp".to_owned(), 3000), ("b.temp".to_owned(), 3000)],
        "the newest two are kept"
    );
}

/// Every stored change as (time, row id, point, value), in time order, read the slow way:
/// the whole table, sorted.
fn every_change(dir: &std::path::Path) -> Vec<(ChangeKey, String, Option<f64>)> {
    let conn = rusqlite::Connection::open(dir.join(DB_FILE)).unwrap();
    let mut stmt = conn
        .prepare(
            "SELECT s.t, s.rowid, p.name, s.value FROM samples s NOT INDEXED \
             JOIN points p ON p.id = s.point ORDER BY s.t, s.rowid",
        )
        .unwrap();
    stmt.query_map([], |r| {
        Ok((
            ChangeKey {
                t: Timestamp(r.get(0)?),
                row: r.get(1)?,
            },
            r.get(2)?,
            r.get(3)?,
        ))
    })
    .unwrap()
    .collect::<Result<_, _>>()
    .unwrap()
}

/// A new history (its directory, store and handle) with what a time-ordered read must get
/// through: a dense second with ties, stored out of order; a gap of three days; a day with
/// one change every seven minutes; a dense stretch again. With its changes read the slow
/// way ([`every_change`]).
async fn dense_gap_sparse_dense() -> (
    tempfile::TempDir,
    Store,
    StoreHandle,
    Vec<(ChangeKey, String, Option<f64>)>,
) {
    let (dir, store) = temp_store();
    let h = store.handle();
    let day = 86_400_000;
    let mut rows = Vec::new();
    for i in 0..3_000i64 {
        let t = 10_000 + i / 3;
        rows.push((format!("a.p{}", i % 7), t, i as f64));
    }
    // Out of order in blocks of fifty, as lines' changes can arrive.
    for block in rows.chunks_mut(50) {
        block.reverse();
    }
    for i in 0..200i64 {
        rows.push((format!("b.p{}", i % 3), 3 * day + i * 7 * 60_000, i as f64));
    }
    for i in 0..1_000i64 {
        rows.push((format!("a.p{}", i % 7), 5 * day + i, -(i as f64)));
    }
    for (p, t, v) in rows {
        h.sample(sample(&p, t, v));
    }
    h.flush().await.unwrap();
    let every = every_change(dir.path());
    (dir, store, h, every)
}

#[tokio::test]
async fn stored_changes_come_back_in_time_order_through_gaps_sparse_and_dense_stretches() {
    let (_dir, _store, h, expected) = dense_gap_sparse_dense().await;
    assert_eq!(expected.len(), 4_200);
    for limit in [1, 13, 5_000] {
        let mut read = Vec::new();
        let mut after = ChangeKey::before(Timestamp(0));
        loop {
            let page = h.changes(after, Timestamp(i64::MAX), limit).unwrap();
            assert!(page.len() <= limit);
            let Some(last) = page.last() else { break };
            after = last.key;
            read.extend(page.into_iter().map(|c| {
                let number = match c.value {
                    Some(Value::Number(x)) => Some(x),
                    other => panic!("a number was stored, read {other:?}"),
                };
                (c.key, c.point, number)
            }));
        }
        assert!(
            read == expected,
            "pages of {limit} read the changes in time order"
        );
    }
    let until = Timestamp(3 * 86_400_000 + 100 * 7 * 60_000);
    let page = h.changes(expected[4].0, until, 10_000).unwrap();
    let within: Vec<_> = expected[5..]
        .iter()
        .take_while(|c| c.0.t <= until)
        .map(|c| c.0)
        .collect();
    assert_eq!(
        page.iter().map(|c| c.key).collect::<Vec<_>>(),
        within,
        "nothing after `until`, nothing at or before the key"
    );
}

#[tokio::test]
async fn the_newest_changes_to_keep_start_where_a_sorted_list_says() {
    let (_dir, _store, h, every) = dense_gap_sparse_dense().await;
    for after in [
        ChangeKey::before(Timestamp(0)),
        every[100].0,
        every[3_500].0,
    ] {
        for until in [
            Timestamp(i64::MAX),
            Timestamp(3 * 86_400_000 + 100 * 7 * 60_000),
        ] {
            let within: Vec<ChangeKey> = every
                .iter()
                .map(|c| c.0)
                .filter(|k| *k > after && k.t <= until)
                .collect();
            let n = within.len() as u64;
            for keep in [0, 1, 17, 999, n.saturating_sub(1), n, n + 5] {
                let (count, start) = h.count_changes(after, until, keep).unwrap();
                let expected = (n > keep).then(|| within[(n - keep - 1) as usize]);
                assert_eq!(
                    (count, start),
                    (n, expected),
                    "after {after:?}, until {until:?}, keeping {keep}"
                );
            }
        }
    }
}

#[test]
fn a_window_grows_to_hold_the_rows_still_wanted_at_most_eightfold() {
    let first = Window::first();
    assert_eq!(first.ms(), 1_000);
    assert_eq!(
        first.after(1_000, 4_000).ms(),
        3_000,
        "three times more to read"
    );
    assert_eq!(first.after(10, 5_000).ms(), 8_000);
    assert_eq!(first.after(4_999, 5_000).ms(), 1_000, "never shorter");
    assert_eq!(
        first.after(0, 5_000),
        first,
        "an empty window tells no density"
    );
    let mut w = first;
    for _ in 0..20 {
        w = w.after(1, 1_000_000);
    }
    assert_eq!(w.ms(), 86_400_000, "at most a day");
    assert_eq!(first.halved().ms(), 500);
    assert_eq!(
        Window::fitted(1, 1, 1).halved().ms(),
        1,
        "never under a millisecond"
    );
}

#[test]
fn a_window_cut_by_the_limit_fits_the_next_to_the_density_it_saw() {
    assert_eq!(
        Window::fitted(400, 2_000, 5_000).ms(),
        1_125,
        "an eighth more than the density says"
    );
    assert_eq!(Window::fitted(8_000, 50_000, 50_000).ms(), 9_000);
    assert_eq!(
        Window::fitted(1, 5_000, 1).ms(),
        1,
        "never under a millisecond"
    );
    assert_eq!(Window::fitted(86_400_000, 1, 5_000).ms(), 86_400_000);
}

#[tokio::test]
async fn a_read_in_many_calls_gets_every_change_once_in_time_order() {
    let (_dir, _store, h, every) = dense_gap_sparse_dense().await;
    let expected: Vec<ChangeKey> = every.into_iter().map(|c| c.0).collect();
    let mut cursor = ChangeCursor::new(ChangeKey::before(Timestamp(0)), Timestamp(i64::MAX));
    let mut read = Vec::new();
    for limit in [7, 500, 1, 2_000].into_iter().cycle() {
        let keys = h.change_keys(&mut cursor, limit).unwrap();
        if keys.is_empty() {
            break;
        }
        assert!(keys.len() == limit || read.len() + keys.len() == expected.len());
        read.extend(keys);
    }
    assert!(
        read == expected,
        "{} keys read of {}",
        read.len(),
        expected.len()
    );
    assert!(
        h.change_keys(&mut cursor, 10).unwrap().is_empty(),
        "the end stays the end"
    );
}

#[test]
fn the_time_ordered_reads_never_scan_the_samples_table() {
    let (dir, store) = temp_store();
    drop(store);
    let conn = rusqlite::Connection::open(dir.path().join(DB_FILE)).unwrap();
    for query in [
        WINDOW_KEYS,
        CHANGES_AT,
        WINDOW_COUNT,
        WINDOW_NTH_NEWEST,
        WINDOW_FIRST,
        WINDOW_LAST,
        rollup::OPEN_MINUTES_SAMPLES,
    ] {
        let mut stmt = conn
            .prepare(&format!("EXPLAIN QUERY PLAN {query}"))
            .unwrap();
        let n = stmt.parameter_count();
        let plan: Vec<String> = stmt
            .query_map(rusqlite::params_from_iter((0..n).map(|_| 0i64)), |r| {
                r.get(3)
            })
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        for step in &plan {
            let words: Vec<&str> = step.split_whitespace().collect();
            let reads_all_samples = words.first() == Some(&"SCAN")
                && ["s", "row", "samples"].contains(words.get(1).unwrap_or(&""))
                && !step.contains("USING");
            assert!(!reads_all_samples, "{step} in the plan of {query}");
        }
        assert!(
            plan.iter().any(|s| s.contains("samples_by_point_time")
                || s.starts_with("SEARCH s USING INTEGER PRIMARY KEY")),
            "{plan:?}"
        );
    }
}

// --- Per-minute rollups --------------------------------------------------------------------

/// The bucketed query as before the rollups: SQLite's own `avg`, `min`, `max`, `count`.
fn buckets_by_sql(dir: &std::path::Path, p: &str, from: i64, to: i64, step: i64) -> Vec<Bucket> {
    let conn = rusqlite::Connection::open(dir.join(DB_FILE)).unwrap();
    let mut stmt = conn
        .prepare(
            "SELECT (t / ?4) * ?4 AS b, avg(value), min(value), max(value), count(*) \
             FROM samples JOIN points ON points.id = samples.point WHERE points.name = ?1 \
             AND t >= ?2 AND t < ?3 AND quality = 0 AND value IS NOT NULL GROUP BY b ORDER BY b",
        )
        .unwrap();
    stmt.query_map(rusqlite::params![p, from, to, step], |r| {
        Ok(Bucket {
            t: Timestamp(r.get(0)?),
            avg: r.get(1)?,
            min: r.get(2)?,
            max: r.get(3)?,
            count: r.get::<_, i64>(4)?.unsigned_abs(),
        })
    })
    .unwrap()
    .collect::<Result<_, _>>()
    .unwrap()
}

fn buckets_of(h: History) -> Vec<Bucket> {
    match h.series {
        Series::Buckets(b) => b,
        Series::Samples(_) => panic!("expected buckets"),
    }
}

fn rollup_rows(dir: &std::path::Path) -> i64 {
    let conn = rusqlite::Connection::open(dir.join(DB_FILE)).unwrap();
    conn.query_row("SELECT count(*) FROM minutes", [], |r| r.get(0))
        .unwrap()
}

/// Every bucketed query of `p` over many ranges and steps: with the rollups, without
/// them, and by SQLite's own aggregates, all equal (bit for bit, `avg` included).
fn assert_rollups_agree(h: &StoreHandle, dir: &std::path::Path, p: &str, end: i64) {
    let edges = [0, 1, 59_999, 60_000, 61_234, 120_000, 179_999, 240_001];
    let steps = [60_000, 120_000, 300_000, 90_000, 1_000];
    let mut compared = 0;
    for from in edges {
        for to in edges.iter().map(|e| end - e).chain([i64::MAX]) {
            if from >= to {
                continue;
            }
            for step in steps {
                let ask = |rollups| {
                    h.history_with(
                        &point(p),
                        Timestamp(from),
                        Timestamp(to),
                        Some(Duration::from_millis(step as u64)),
                        rollups,
                    )
                    .unwrap()
                };
                let with = buckets_of(ask(query::Rollups::Use));
                let without = buckets_of(ask(query::Rollups::Ignore));
                assert_eq!(with, without, "from {from} to {to} step {step}");
                assert_eq!(
                    with,
                    buckets_by_sql(dir, p, from, to, step),
                    "SQLite's avg: from {from} to {to} step {step}"
                );
                compared += 1;
            }
        }
    }
    assert!(compared > 100, "{compared} queries compared");
}

#[tokio::test]
async fn a_rollup_served_query_equals_the_raw_computation_at_every_edge() {
    let (dir, store) = temp_store();
    let h = store.handle();
    // 20 minutes of irregular samples with values that do not add up exactly in binary,
    // stale and bad readings, a text value and a NaN in between; several batches.
    let end = 20 * 60_000;
    let mut t = 0;
    let mut i = 0u64;
    while t < end {
        let quality = match i % 11 {
            3 => Quality::Stale,
            7 => Quality::Bad,
            _ => Quality::Good,
        };
        let value = match i % 17 {
            5 => Some(Value::Text("JTSE".into())),
            9 => None,
            13 => Some(Value::Number(f64::NAN)),
            _ => Some(Value::Number(0.1 * (i % 97) as f64 - 3.3)),
        };
        h.sample(Sample {
            point: point("a.temp"),
            t: Timestamp(t),
            value,
            quality,
        });
        h.sample(sample("b.temp", t, 1e6 + i as f64));
        if i % 50 == 49 {
            h.flush().await.unwrap();
        }
        t += 700 + (i as i64 * 37) % 900;
        i += 1;
    }
    h.flush().await.unwrap();
    assert!(
        rollup_rows(dir.path()) >= 2 * 17,
        "minutes closed a minute behind the newest sample are rolled up"
    );
    assert_rollups_agree(&h, dir.path(), "a.temp", end);
    assert_rollups_agree(&h, dir.path(), "b.temp", end);
}

#[tokio::test]
async fn a_late_sample_joins_its_closed_minute_and_a_restart_rebuilds_the_open_ones() {
    let dir = tempfile::tempdir().unwrap();
    let end = 10 * 60_000;
    {
        let store = Store::open(dir.path(), StoreOptions::default()).unwrap();
        let h = store.handle();
        for t in (0..end).step_by(1_000) {
            h.sample(sample("a.temp", t, (t / 1000) as f64 * 0.25));
        }
        h.flush().await.unwrap();
        let closed = rollup_rows(dir.path());
        assert!(closed >= 8, "{closed} minutes rolled up");
        // A late reading for the second minute, long closed.
        h.sample(sample("a.temp", 60_500, 1234.5));
        h.flush().await.unwrap();
        assert_eq!(rollup_rows(dir.path()), closed, "merged into its row");
        assert_rollups_agree(&h, dir.path(), "a.temp", end);
        store.close();
    }
    // The open minutes were in memory only; the new writer rebuilds them from the samples.
    let store = Store::open(dir.path(), StoreOptions::default()).unwrap();
    let h = store.handle();
    for t in (end..end + 3 * 60_000).step_by(1_500) {
        h.sample(sample("a.temp", t, -(t as f64) / 7.0));
    }
    h.flush().await.unwrap();
    assert_rollups_agree(&h, dir.path(), "a.temp", end + 3 * 60_000);
    let minute = buckets_of(
        h.history(
            &point("a.temp"),
            Timestamp(60_000),
            Timestamp(120_000),
            Some(Duration::from_secs(60)),
        )
        .unwrap(),
    );
    assert_eq!(minute[0].count, 61);
    assert_eq!(minute[0].max, 1234.5);
}

#[tokio::test]
async fn retention_prunes_the_rollups_with_the_samples_and_answers_stay_equal() {
    let (dir, store) = temp_store_with(StoreOptions {
        retain: Duration::from_secs(5 * 60),
        prune_chunk_rows: 7,
        ..StoreOptions::default()
    });
    let h = store.handle();
    let end = 12 * 60_000;
    for t in (0..end).step_by(2_000) {
        h.sample(sample("a.temp", t, (t % 7_000) as f64 / 3.0));
    }
    h.flush().await.unwrap();
    // Keeps from 6.5 minutes on: the minute at 6 loses half its samples.
    let now = 6 * 60_000 + 30_000 + 5 * 60_000;
    let pruned = h.prune(Timestamp(now)).await.unwrap();
    assert_eq!(pruned, (6 * 60_000 + 30_000) / 2_000);
    let conn = rusqlite::Connection::open(dir.path().join(DB_FILE)).unwrap();
    let oldest: i64 = conn
        .query_row("SELECT min(minute) FROM minutes", [], |r| r.get(0))
        .unwrap();
    assert_eq!(oldest, 7 * 60_000, "the partly pruned minute is served raw");
    assert_rollups_agree(&h, dir.path(), "a.temp", end);
    let kept = buckets_of(
        h.history(
            &point("a.temp"),
            Timestamp(0),
            Timestamp(end),
            Some(Duration::from_secs(60)),
        )
        .unwrap(),
    );
    assert_eq!(kept[0].t, Timestamp(6 * 60_000));
    assert_eq!(kept[0].count, 15);
}

/// The tables of schema version 1 (before the rollups), as the previous release made them.
const SCHEMA_1: &str = "
CREATE TABLE points (id INTEGER PRIMARY KEY, name TEXT NOT NULL UNIQUE);
CREATE TABLE samples (point INTEGER NOT NULL REFERENCES points(id), t INTEGER NOT NULL,
    value REAL, text TEXT, quality INTEGER NOT NULL);
CREATE INDEX samples_by_point_time ON samples(point, t);
CREATE INDEX samples_by_time ON samples(t);
CREATE TABLE events (id INTEGER PRIMARY KEY, t INTEGER NOT NULL, kind TEXT NOT NULL,
    line TEXT, device TEXT, point TEXT, message TEXT NOT NULL);
CREATE INDEX events_by_time ON events(t);
CREATE TABLE audit (id INTEGER PRIMARY KEY, t INTEGER NOT NULL, client TEXT NOT NULL,
    device TEXT NOT NULL, point TEXT NOT NULL, old_value TEXT, new_value TEXT NOT NULL,
    result TEXT NOT NULL, detail TEXT NOT NULL);
CREATE INDEX audit_by_time ON audit(t);
PRAGMA user_version = 1;
";

#[tokio::test]
async fn a_file_of_the_previous_schema_opens_answers_and_rolls_up_what_comes_after() {
    let dir = tempfile::tempdir().unwrap();
    {
        let conn = rusqlite::Connection::open(dir.path().join(DB_FILE)).unwrap();
        conn.pragma_update(None, "journal_mode", "WAL").unwrap();
        conn.execute_batch(SCHEMA_1).unwrap();
        conn.execute("INSERT INTO points (id, name) VALUES (1, 'a.temp')", [])
            .unwrap();
        conn.execute(
            "INSERT INTO events (t, kind, message) VALUES (1, 'device_down', 'old')",
            [],
        )
        .unwrap();
        let mut insert = conn
            .prepare("INSERT INTO samples (point, t, value, quality) VALUES (1, ?1, ?2, 0)")
            .unwrap();
        for t in (0..5 * 60_000).step_by(1_000) {
            insert
                .execute(rusqlite::params![t, t as f64 / 1000.0])
                .unwrap();
        }
    }
    let store = Store::open(dir.path(), StoreOptions::default()).unwrap();
    let h = store.handle();
    let conn = rusqlite::Connection::open(dir.path().join(DB_FILE)).unwrap();
    let version: i64 = conn
        .query_row("PRAGMA user_version", [], |r| r.get(0))
        .unwrap();
    assert_eq!(version, 4);
    // Events: the old one reads back without fields, a new one keeps its own.
    h.event(Event {
        fields: crate::event::fields([("feeder", serde_json::json!(7))]),
        ..Event::of_gateway(EventKind::DeviceEvent, "new".into())
    });
    h.flush().await.unwrap();
    let events = h
        .events(&EventFilter {
            limit: 10,
            ..EventFilter::default()
        })
        .unwrap();
    let fields_of = |message: &str| {
        events
            .iter()
            .find(|e| e.message == message)
            .map(|e| serde_json::Value::Object(e.fields.clone()))
    };
    assert_eq!(fields_of("old"), Some(serde_json::json!({})));
    assert_eq!(fields_of("new"), Some(serde_json::json!({"feeder": 7})));
    let time_index: i64 = conn
        .query_row(
            "SELECT count(*) FROM sqlite_master WHERE name = 'samples_by_time'",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(time_index, 0, "the index on time alone is dropped");
    // The old minutes come from the samples, as before.
    let old = buckets_of(
        h.history(
            &point("a.temp"),
            Timestamp(0),
            Timestamp(5 * 60_000),
            Some(Duration::from_secs(60)),
        )
        .unwrap(),
    );
    assert_eq!(old.len(), 5);
    assert_eq!((old[1].count, old[1].min, old[1].max), (60, 60.0, 119.0));
    // New samples are rolled up from the first minute after the newest old one.
    for t in (5 * 60_000..15 * 60_000).step_by(1_000) {
        h.sample(sample("a.temp", t, t as f64 / 1000.0));
    }
    h.flush().await.unwrap();
    let since: i64 = conn
        .query_row("SELECT since FROM rollup_marks", [], |r| r.get(0))
        .unwrap();
    assert_eq!(since, 5 * 60_000);
    assert!(rollup_rows(dir.path()) >= 8);
    assert_rollups_agree(&h, dir.path(), "a.temp", 15 * 60_000);
}

#[test]
fn the_writer_cache_stays_small_for_a_trickle_of_rows() {
    let mut cache = WriterCache::new();
    assert_eq!(cache.kib(), WRITER_CACHE_MIN_KIB);
    for _ in 0..100 {
        assert_eq!(
            cache.for_batch(700),
            None,
            "a trickle leaves the cache alone"
        );
    }
    assert_eq!(cache.kib(), WRITER_CACHE_MIN_KIB);
}

#[test]
fn the_writer_cache_stays_small_for_the_batches_of_a_gateways_start() {
    let mut cache = WriterCache::new();
    for rows in [2_000, 5_000, WRITER_CACHE_GROW_FROM_ROWS - 1, 3_000] {
        assert_eq!(cache.for_batch(rows), None, "{rows} rows");
    }
    assert_eq!(cache.kib(), WRITER_CACHE_MIN_KIB);
}

#[test]
fn the_writer_cache_grows_at_once_for_a_large_batch_up_to_its_largest() {
    let mut cache = WriterCache::new();
    assert_eq!(cache.for_batch(12_000), Some(12_000));
    assert_eq!(cache.for_batch(20_000), Some(WRITER_CACHE_MAX_KIB));
    assert_eq!(cache.for_batch(1_000_000), None, "already at its largest");
    assert_eq!(cache.kib(), WRITER_CACHE_MAX_KIB);
}

#[test]
fn the_writer_cache_shrinks_only_after_ten_smaller_batches_in_a_row() {
    let mut cache = WriterCache::new();
    cache.for_batch(20_000);
    for _ in 0..9 {
        assert_eq!(cache.for_batch(500), None);
    }
    assert_eq!(
        cache.for_batch(20_000),
        None,
        "a large batch again: kept, and the count starts over"
    );
    for _ in 0..9 {
        assert_eq!(cache.for_batch(500), None);
    }
    assert_eq!(cache.for_batch(500), Some(WRITER_CACHE_MIN_KIB));
    assert_eq!(cache.kib(), WRITER_CACHE_MIN_KIB);
}

#[tokio::test]
async fn a_burst_of_queries_at_once_leaves_only_a_few_read_connections_open() {
    let (_dir, store) = temp_store();
    let h = store.handle();
    h.sample(sample("a.temp", 1000, 1.0));
    h.flush().await.unwrap();
    let burst = 3 * super::query::MAX_IDLE_READERS;
    let together = Arc::new(std::sync::Barrier::new(burst));
    let threads: Vec<_> = (0..burst)
        .map(|_| {
            let (h, together) = (h.clone(), Arc::clone(&together));
            std::thread::spawn(move || {
                h.readers.with(|conn| {
                    // Every query holds its own connection while all of them run.
                    together.wait();
                    conn.query_row("SELECT count(*) FROM samples", [], |r| r.get::<_, i64>(0))
                })
            })
        })
        .collect();
    for thread in threads {
        assert_eq!(thread.join().unwrap().unwrap(), 1);
    }
    let idle = h.readers.idle.lock().unwrap().len();
    assert_eq!(idle, super::query::MAX_IDLE_READERS);
}
