use super::*;
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

fn samples_of(h: &History) -> Vec<(i64, Option<Value>)> {
    match &h.series {
        Series::Samples(s) => s.iter().map(|s| (s.t.0, s.value.clone())).collect(),
        Series::Buckets(_) => panic!("expected raw samples"),
    }
}

#[tokio::test]
async fn samples_come_back_in_time_order_for_their_point_and_range() {
    let dir = tempfile::tempdir().unwrap();
    let store = Store::open(dir.path(), StoreOptions::default()).unwrap();
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
async fn a_step_gives_average_min_and_max_per_bucket_of_good_values() {
    let dir = tempfile::tempdir().unwrap();
    let store = Store::open(dir.path(), StoreOptions::default()).unwrap();
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
    let dir = tempfile::tempdir().unwrap();
    let options = StoreOptions {
        batch_rows: 10,
        batch_delay: Duration::from_secs(3600),
        ..StoreOptions::default()
    };
    let store = Store::open(dir.path(), options).unwrap();
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
    let dir = tempfile::tempdir().unwrap();
    let options = StoreOptions {
        batch_delay: Duration::from_secs(3600),
        ..StoreOptions::default()
    };
    let store = Store::open(dir.path(), options).unwrap();
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
    let dir = tempfile::tempdir().unwrap();
    let options = StoreOptions {
        retain: Duration::from_secs(10),
        ..StoreOptions::default()
    };
    let store = Store::open(dir.path(), options).unwrap();
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
    let dir = tempfile::tempdir().unwrap();
    let store = Store::open(dir.path(), StoreOptions::default()).unwrap();
    let h = store.handle();
    let ev = |t, kind, device: &str| Event {
        t: Timestamp(t),
        kind,
        line: Some("bench".into()),
        device: Some(DeviceId::new(device).unwrap()),
        point: None,
        message: format!("{device} {t}"),
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
}

#[tokio::test]
async fn audit_rows_keep_old_and_new_values_as_json() {
    let dir = tempfile::tempdir().unwrap();
    let store = Store::open(dir.path(), StoreOptions::default()).unwrap();
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
