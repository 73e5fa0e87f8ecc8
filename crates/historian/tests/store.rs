//! The historian's store against a real PostgreSQL (testkit's throwaway cluster, one per
//! test: the restart test crashes its own).

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use historian::store::{SCHEMA_VERSION, SamplesLayout};
use historian::{
    Batch, Bucket, EventRow, PointRow, Quality, RefusalReason, SampleRow, Store, StoreError,
    StoredSample,
};
use testkit::Postgres;
use tokio_postgres::{Client, NoTls};

/// 2025-03-10T00:00:00Z, in milliseconds since the epoch.
const MIDNIGHT_MS: u64 = 20_157 * 86_400_000;

fn at(ms: u64) -> SystemTime {
    UNIX_EPOCH + Duration::from_millis(ms)
}

/// Every point of the store.
async fn all_points(store: &Store) -> Vec<PointRow> {
    store.points(None, 0, 100_000).await.expect("points").0
}

/// The row id of the one point `plant_id` names.
async fn id(store: &Store, plant_id: &str) -> i32 {
    let found = store.find_points(plant_id).await.expect("find");
    assert_eq!(found.len(), 1, "{plant_id}: {found:?}");
    found[0].id
}

fn sample(device: &str, point: &str, ms: u64, value: f64) -> SampleRow {
    SampleRow {
        group: "plant".into(),
        node: "cell1".into(),
        device: device.into(),
        point: point.into(),
        t: at(ms),
        value: Some(value),
        text: None,
        quality: Quality::Good,
    }
}

fn temperature_point() -> PointRow {
    PointRow {
        group: "plant".into(),
        node: "cell1".into(),
        device: "jbc1".into(),
        point: "air_temperature".into(),
        datatype: "Double".into(),
        unit: Some("°C".into()),
        description: Some("Air temperature".into()),
        writable: false,
        write_min: None,
        write_max: None,
    }
}

fn event(ms: u64, message: &str) -> EventRow {
    EventRow {
        group: "plant".into(),
        node: "cell1".into(),
        device: Some("jbc1".into()),
        point: None,
        line: Some("bench".into()),
        t: at(ms),
        kind: "device_down".into(),
        severity: 700,
        message: message.into(),
        fields: None,
    }
}

/// A batch of one point's birth, `n` samples a second apart from `start_ms` and one event.
fn batch(start_ms: u64, n: u64) -> Batch {
    Batch {
        points: vec![temperature_point()],
        samples: (0..n)
            .map(|i| {
                sample(
                    "jbc1",
                    "air_temperature",
                    start_ms + i * 1000,
                    100.0 + i as f64,
                )
            })
            .collect(),
        events: vec![event(start_ms, "jbc1 did not answer")],
    }
}

/// A cluster and a fresh database's URL.
fn database() -> (Postgres, String) {
    let pg = Postgres::start();
    let url = pg.create_database("historian");
    (pg, url)
}

/// A plain client for the test's own SQL.
async fn client(url: &str) -> Client {
    let (client, connection) = tokio_postgres::connect(url, NoTls)
        .await
        .expect("the test connects");
    tokio::spawn(connection);
    client
}

async fn column(client: &Client, sql: &str) -> Vec<String> {
    client
        .query(sql, &[])
        .await
        .unwrap_or_else(|e| panic!("{sql}: {e:?}"))
        .iter()
        .map(|r| r.get(0))
        .collect()
}

#[tokio::test]
async fn the_schema_is_created_on_first_connect_and_not_migrated_again() {
    let (_pg, url) = database();
    let first = Store::connect(&url).await.expect("first connect");
    assert_eq!(first.migrated(), [1, 2, 3, 4, SCHEMA_VERSION]);
    assert_eq!(first.layout(), SamplesLayout::DayPartitions);
    let second = Store::connect(&url).await.expect("second connect");
    assert_eq!(second.migrated(), [] as [i32; 0]);
    let sql = client(&url).await;
    assert_eq!(
        column(&sql, "SELECT version::text FROM cellbus_schema ORDER BY 1").await,
        ["1", "2", "3", "4", "5"]
    );
}

#[tokio::test]
async fn the_views_have_exactly_the_stable_column_names_and_types() {
    let (_pg, url) = database();
    Store::connect(&url).await.expect("connect");
    let sql = client(&url).await;
    let shape = |view: &'static str| {
        let sql = &sql;
        async move {
            column(
                sql,
                &format!(
                    "SELECT column_name || ' ' || data_type FROM information_schema.columns \
                     WHERE table_name = '{view}' ORDER BY ordinal_position"
                ),
            )
            .await
        }
    };
    assert_eq!(
        shape("cellbus_samples").await,
        [
            "node text",
            "device text",
            "point text",
            "t timestamp with time zone",
            "value double precision",
            "text text",
            "quality text",
            "group_id text",
        ]
    );
    assert_eq!(
        shape("cellbus_events").await,
        [
            "t timestamp with time zone",
            "node text",
            "device text",
            "point text",
            "line text",
            "kind text",
            "severity integer",
            "message text",
            "group_id text",
            "fields jsonb",
        ]
    );
    assert_eq!(
        shape("cellbus_points").await,
        [
            "node text",
            "device text",
            "point text",
            "unit text",
            "description text",
            "datatype text",
            "writable boolean",
            "write_min double precision",
            "write_max double precision",
            "group_id text",
        ]
    );
    assert_eq!(
        shape("cellbus_states").await,
        [
            "node text",
            "device text",
            "start timestamp with time zone",
            "end timestamp with time zone",
            "state text",
            "code integer",
            "category text",
            "reason text",
            "group_id text",
        ]
    );
    assert_eq!(
        shape("cellbus_alarms").await,
        [
            "t timestamp with time zone",
            "node text",
            "device text",
            "point text",
            "alarm text",
            "kind text",
            "changes ARRAY",
            "state text",
            "acknowledged boolean",
            "priority text",
            "who text",
            "comment text",
            "value jsonb",
            "message text",
            "group_id text",
        ]
    );
}

/// A gateway's alarm journal reaches the plant: who acknowledged which alarm, and why.
#[tokio::test]
async fn the_alarms_view_reads_the_gateways_alarm_journal_from_their_events() {
    let (_pg, url) = database();
    let mut store = Store::connect(&url).await.expect("connect");
    let t = MIDNIGHT_MS + 7_200_000;
    let alarm = |ms: u64, kind: &str, fields: &str| EventRow {
        kind: kind.into(),
        point: Some("jbc1.tool_error".into()),
        fields: Some(fields.into()),
        ..event(ms, kind)
    };
    let batch = Batch {
        events: vec![
            alarm(
                t,
                "alarm_raised",
                r#"{"alarm":"jbc1.tool_error","changes":["activated"],"state":"unacknowledged","acknowledged":false,"priority":"high","value":3}"#,
            ),
            alarm(
                t + 60_000,
                "alarm_changed",
                r#"{"alarm":"jbc1.tool_error","changes":["acknowledged"],"state":"acknowledged","acknowledged":true,"priority":"high","by":"anna (http 10.0.0.7:50312)","comment":"heater ordered"}"#,
            ),
            // An older gateway's alarm event, without the journal's facts.
            alarm(t + 1, "alarm_raised", r#"{"value":3}"#),
            event(t + 2, "a device event"),
        ],
        ..Batch::default()
    };
    store.write(&batch).await.expect("write");
    let sql = client(&url).await;
    assert_eq!(
        column(
            &sql,
            "SELECT format('%s %s %s %s %s %s', alarm, kind, array_to_string(changes, ','), \
                 state, coalesce(who, '-'), coalesce(comment, '-')) \
             FROM cellbus_alarms WHERE node = 'cell1' ORDER BY t"
        )
        .await,
        [
            "jbc1.tool_error alarm_raised activated unacknowledged - -",
            "jbc1.tool_error alarm_changed acknowledged acknowledged anna (http 10.0.0.7:50312) heater ordered",
        ]
    );
}

/// The samples a gateway sends for a device's machine state at `ms`: its word, its code
/// and its reason; all three bad (no value) for `None`, as a DDEATH makes them.
fn machine_state(device: &str, ms: u64, state: Option<(&str, f64, &str)>) -> Vec<SampleRow> {
    let text = |point: &str, text: Option<&str>| SampleRow {
        text: text.map(str::to_owned),
        value: None,
        quality: if text.is_some() {
            Quality::Good
        } else {
            Quality::Bad
        },
        ..sample(device, point, ms, 0.0)
    };
    vec![
        text("machine_state", state.map(|s| s.0)),
        SampleRow {
            value: state.map(|s| s.1),
            quality: if state.is_some() {
                Quality::Good
            } else {
                Quality::Bad
            },
            ..sample(device, "machine_state_code", ms, 0.0)
        },
        text("machine_state_reason", state.map(|s| s.2)),
    ]
}

#[tokio::test]
async fn machine_state_samples_make_intervals_from_one_change_to_the_next() {
    let (_pg, url) = database();
    let mut store = Store::connect(&url).await.expect("connect");
    let hour = |h: u64, m: u64| MIDNIGHT_MS + h * 3_600_000 + m * 60_000;
    let mut samples = Vec::new();
    samples.extend(machine_state(
        "placer1",
        hour(6, 0),
        Some(("run", 1100.0, "")),
    ));
    // A rebirth sends the same values again: the interval goes on.
    samples.extend(machine_state(
        "placer1",
        hour(6, 30),
        Some(("run", 1100.0, "")),
    ));
    let exhausted = Some(("parts exhausted", 5500.0, "feeder 7 (step 87, nozzle 7)"));
    samples.extend(machine_state("placer1", hour(7, 0), exhausted));
    // The reason changes, the state does not: only the reason is sent.
    samples.push(SampleRow {
        text: Some("feeder 8 (step 88, nozzle 8)".into()),
        value: None,
        ..sample("placer1", "machine_state_reason", hour(7, 10), 0.0)
    });
    // Back to work: the state and its code change, the reason empties.
    samples.extend(machine_state(
        "placer1",
        hour(7, 20),
        Some(("run", 1100.0, "")),
    ));
    // The historian goes offline and the gateway's death says so: stale samples without
    // values, which change nothing (the gateway read on; the gap's changes come later).
    for point in [
        "machine_state",
        "machine_state_code",
        "machine_state_reason",
    ] {
        samples.push(SampleRow {
            value: None,
            quality: Quality::Stale,
            ..sample("placer1", point, hour(7, 40), 0.0)
        });
    }
    // The device stops answering (DDEATH), then is born again in another state.
    samples.extend(machine_state("placer1", hour(8, 0), None));
    samples.extend(machine_state(
        "placer1",
        hour(8, 5),
        Some(("ready", 2200.0, "")),
    ));
    // Only the word and the code change: the empty reason sent at 08:05 still holds.
    let mut error_stop = machine_state("placer1", hour(9, 0), Some(("error stop", 5300.0, "")));
    error_stop.pop();
    samples.extend(error_stop);
    // Another device of the node, and one whose code is off the E10 scale.
    samples.extend(machine_state(
        "placer2",
        hour(6, 30),
        Some(("run", 1100.0, "")),
    ));
    samples.extend(machine_state(
        "placer3",
        hour(6, 30),
        Some(("odd", 9100.0, "")),
    ));
    // Samples of other points make no moments.
    samples.push(sample("placer1", "oee", hour(6, 45), 0.5));
    let written = store
        .write(&Batch {
            samples,
            ..Batch::default()
        })
        .await
        .expect("write");
    assert_eq!(written.samples, 31);

    let sql = client(&url).await;
    let intervals = column(
        &sql,
        "SELECT format('%s %s-%s %s %s %s %s', device, to_char(start AT TIME ZONE 'UTC', \
             'HH24:MI'), coalesce(to_char(\"end\" AT TIME ZONE 'UTC', 'HH24:MI'), 'open'), \
             state, code, category, coalesce(reason, '-')) \
         FROM cellbus_states WHERE node = 'cell1' AND group_id = 'plant' \
         ORDER BY device, start",
    )
    .await;
    assert_eq!(
        intervals,
        [
            "placer1 06:00-07:00 run 1100 productive -",
            "placer1 07:00-07:10 parts exhausted 5500 unscheduled_down feeder 7 (step 87, nozzle 7)",
            "placer1 07:10-07:20 parts exhausted 5500 unscheduled_down feeder 8 (step 88, nozzle 8)",
            "placer1 07:20-08:00 run 1100 productive -",
            "placer1 08:00-08:05 unknown 0 unknown -",
            "placer1 08:05-09:00 ready 2200 standby -",
            "placer1 09:00-open error stop 5300 unscheduled_down -",
            "placer2 06:30-open run 1100 productive -",
            "placer3 06:30-open odd 0 unknown -",
        ]
    );
}

#[tokio::test]
async fn a_batch_written_twice_stores_its_samples_and_events_once() {
    let (_pg, url) = database();
    let mut store = Store::connect(&url).await.expect("connect");
    let batch = batch(MIDNIGHT_MS + 3_600_000, 100);
    let first = store.write(&batch).await.expect("first write");
    assert_eq!(
        (
            first.points,
            first.samples,
            first.duplicate_samples,
            first.events
        ),
        (1, 100, 0, 1)
    );
    let again = store.write(&batch).await.expect("second write");
    assert_eq!(
        (
            again.samples,
            again.duplicate_samples,
            again.events,
            again.duplicate_events
        ),
        (0, 100, 0, 1)
    );
    assert_eq!(store.count_samples().await.expect("count"), 100);
    let sql = client(&url).await;
    assert_eq!(
        column(&sql, "SELECT count(*)::text FROM cellbus_events").await,
        ["1"]
    );
}

#[tokio::test]
async fn an_events_fields_are_kept_as_json_beside_its_words() {
    let (_pg, url) = database();
    let mut store = Store::connect(&url).await.expect("connect");
    let t = MIDNIGHT_MS + 3_600_000;
    let batch = Batch {
        events: vec![
            EventRow {
                fields: Some(r#"{"event":"parts_exhausted","feeder":7}"#.into()),
                ..event(t, "parts exhausted")
            },
            event(t + 1, "no fields"),
        ],
        ..Batch::default()
    };
    store.write(&batch).await.expect("write");
    let sql = client(&url).await;
    assert_eq!(
        column(
            &sql,
            "SELECT coalesce(fields->>'feeder', '-') FROM cellbus_events ORDER BY t"
        )
        .await,
        ["7", "-"]
    );
    let events = store
        .events(at(t - 1), at(t + 10), 10)
        .await
        .expect("events");
    let fields: Vec<Option<&str>> = events.iter().map(|e| e.fields.as_deref()).collect();
    assert_eq!(
        fields,
        [None, Some(r#"{"event": "parts_exhausted", "feeder": 7}"#)],
        "newest first, as PostgreSQL prints jsonb"
    );
}

#[tokio::test]
async fn the_point_id_cache_stays_within_its_bound_and_samples_of_forgotten_ids_still_land() {
    let (_pg, url) = database();
    let mut store = Store::connect(&url).await.expect("connect");
    store.set_point_cache(3);
    let point = |device: &str| PointRow {
        device: device.into(),
        ..temperature_point()
    };
    let t = MIDNIGHT_MS + 3_600_000;
    // Births of two devices at a time: the cache never holds more than 3 ids.
    for (i, pair) in [["d0", "d1"], ["d2", "d3"], ["d4", "d5"]]
        .iter()
        .enumerate()
    {
        let batch = Batch {
            points: pair.iter().map(|d| point(d)).collect(),
            samples: pair
                .iter()
                .map(|d| sample(d, "air_temperature", t + i as u64, 1.0))
                .collect(),
            events: vec![],
        };
        store.write(&batch).await.expect("births");
        assert!(store.cached_points() <= 3, "{} ids", store.cached_points());
    }
    // Samples of all six: the ids forgotten are read again.
    let batch = Batch {
        points: vec![],
        samples: ["d0", "d1", "d2", "d3", "d4", "d5"]
            .iter()
            .map(|d| sample(d, "air_temperature", t + 10, 2.0))
            .collect(),
        events: vec![],
    };
    let written = store.write(&batch).await.expect("samples");
    assert_eq!((written.samples, written.bare_points), (6, 0));
    assert_eq!(store.count_samples().await.expect("count"), 12);
    assert_eq!(all_points(&store).await.len(), 6, "no point twice");
}

#[tokio::test]
async fn samples_across_midnight_land_in_two_day_partitions() {
    let (_pg, url) = database();
    let mut store = Store::connect(&url).await.expect("connect");
    // 10 samples a second apart, 5 before midnight and 5 from it.
    let written = store
        .write(&batch(MIDNIGHT_MS - 5_000, 10))
        .await
        .expect("write");
    assert_eq!(written.samples, 10);
    let sql = client(&url).await;
    assert_eq!(
        column(
            &sql,
            "SELECT format('%s %s', tableoid::regclass, count(*)) FROM samples \
             GROUP BY tableoid ORDER BY 1"
        )
        .await,
        ["samples_2025_03_09 5", "samples_2025_03_10 5"]
    );
}

#[tokio::test]
async fn two_stores_creating_the_same_day_partitions_at_once_both_write() {
    let (_pg, url) = database();
    let mut a = Store::connect(&url).await.expect("connect a");
    let mut b = Store::connect(&url).await.expect("connect b");
    // Three days each, the same days, different points.
    let spread = |device: &str| Batch {
        samples: (0..3)
            .map(|day| sample(device, "p", MIDNIGHT_MS + day * 86_400_000, 1.0))
            .collect(),
        ..Batch::default()
    };
    let (batch_a, batch_b) = (spread("a"), spread("b"));
    let (wa, wb) = tokio::join!(a.write(&batch_a), b.write(&batch_b));
    assert_eq!(wa.expect("a writes").samples, 3);
    assert_eq!(wb.expect("b writes").samples, 3);
    assert_eq!(a.count_samples().await.expect("count"), 6);
}

#[tokio::test]
async fn samples_too_old_or_far_in_the_future_are_refused_and_counted() {
    let (_pg, url) = database();
    let mut store = Store::connect(&url).await.expect("connect");
    let future = SystemTime::now() + Duration::from_secs(2 * 86_400);
    let future_ms = future
        .duration_since(UNIX_EPOCH)
        .expect("after 1970")
        .as_millis() as u64;
    let batch = Batch {
        samples: vec![
            sample("jbc1", "future", future_ms, 1.0),
            sample("jbc1", "ok", MIDNIGHT_MS, 2.0),
            sample("jbc1", "old", 1000, 3.0),
        ],
        ..Batch::default()
    };
    let written = store.write(&batch).await.expect("write");
    assert_eq!((written.samples, written.refused_samples), (1, 2));
    let refusal = written.first_refusal.expect("a refusal");
    assert_eq!(refusal.reason, RefusalReason::TooFarAhead);
    assert_eq!(refusal.row, "sample cell1/jbc1.future");
    assert_eq!(store.count_samples().await.expect("count"), 1);
    let names: Vec<String> = all_points(&store)
        .await
        .into_iter()
        .map(|p| p.point)
        .collect();
    assert_eq!(names, ["ok"], "no point row for refused samples");
}

#[tokio::test]
async fn raw_and_buckets_answer_what_was_written() {
    let (_pg, url) = database();
    let mut store = Store::connect(&url).await.expect("connect");
    let start = MIDNIGHT_MS + 7_200_000;
    let mut batch = batch(start, 120);
    // A stale and a bad sample, left out of the buckets.
    batch.samples[10].quality = Quality::Stale;
    batch.samples[20].quality = Quality::Bad;
    batch.samples[20].value = None;
    // A text point and another point's sample, which raw must not return.
    batch.samples.push(SampleRow {
        text: Some("Sealing".into()),
        value: None,
        ..sample("jbc1", "state", start, 0.0)
    });
    batch
        .samples
        .push(sample("jbc2", "air_temperature", start, 999.0));
    store.write(&batch).await.expect("write");

    let air = id(&store, "cell1/jbc1.air_temperature").await;
    let (from, to) = (at(start + 5_000), at(start + 65_000));
    let raw = store.raw(air, from, to, 1000).await.expect("raw");
    let expected: Vec<StoredSample> = batch.samples[5..65]
        .iter()
        .map(|s| StoredSample {
            t: s.t,
            value: s.value,
            text: None,
            quality: s.quality,
        })
        .collect();
    assert_eq!(raw, expected);
    let limited = store.raw(air, from, to, 3).await.expect("raw with a limit");
    assert_eq!(limited, expected[..3]);
    let before = store.last_before(air, from).await.expect("before");
    assert_eq!(before.map(|s| s.t), Some(at(start + 4_000)));
    let text = store
        .raw(id(&store, "cell1/jbc1.state").await, at(start), to, 10)
        .await
        .expect("text");
    assert_eq!(text[0].text.as_deref(), Some("Sealing"));

    // 30 s buckets over the first two minutes: good numeric samples only.
    let buckets = store
        .buckets(air, at(start), at(start + 120_000), Duration::from_secs(30))
        .await
        .expect("buckets");
    let expected: Vec<Bucket> = (0..4u64)
        .map(|b| {
            let values: Vec<f64> = (b * 30..b * 30 + 30)
                .filter(|i| *i != 10 && *i != 20)
                .map(|i| 100.0 + i as f64)
                .collect();
            Bucket {
                t: at(start + b * 30_000),
                avg: values.iter().sum::<f64>() / values.len() as f64,
                min: values[0],
                max: values[values.len() - 1],
                count: values.len() as u64,
            }
        })
        .collect();
    assert_eq!(buckets, expected);

    let sql = client(&url).await;
    assert_eq!(
        column(
            &sql,
            "SELECT format('%s %s', quality, count(*)) FROM cellbus_samples \
             WHERE point = 'air_temperature' AND device = 'jbc1' GROUP BY quality ORDER BY 1"
        )
        .await,
        ["bad 1", "good 118", "stale 1"]
    );
    let events = store
        .events(at(start), at(start + 1), 10)
        .await
        .expect("events");
    assert_eq!(events, batch.events);
}

#[tokio::test]
async fn a_birth_after_samples_fills_the_bare_point_in() {
    let (_pg, url) = database();
    let mut store = Store::connect(&url).await.expect("connect");
    let early = Batch {
        samples: vec![sample("jbc1", "air_temperature", MIDNIGHT_MS, 1.0)],
        ..Batch::default()
    };
    let written = store.write(&early).await.expect("samples first");
    assert_eq!((written.bare_points, written.samples), (1, 1));
    let bare = all_points(&store).await;
    assert_eq!(
        bare,
        [PointRow::bare("plant", "cell1", "jbc1", "air_temperature")]
    );

    let mut birth = temperature_point();
    birth.writable = true;
    birth.write_min = Some(100.0);
    birth.write_max = Some(450.0);
    let written = store
        .write(&Batch {
            points: vec![birth.clone()],
            ..Batch::default()
        })
        .await
        .expect("birth");
    assert_eq!(written.points, 1);
    assert_eq!(all_points(&store).await, [birth]);
    // The same id: the early sample belongs to the described point.
    let reconnected = Store::connect(&url).await.expect("reconnect");
    assert_eq!(reconnected.count_samples().await.expect("count"), 1);
    let raw = reconnected
        .raw(
            id(&reconnected, "cell1/jbc1.air_temperature").await,
            at(0),
            at(MIDNIGHT_MS + 1),
            10,
        )
        .await
        .expect("raw");
    assert_eq!(raw.len(), 1);
}

#[tokio::test]
async fn after_a_postgres_restart_the_connection_is_lost_and_a_new_store_writes_the_batch_once() {
    let (mut pg, url) = database();
    let mut store = Store::connect(&url).await.expect("connect");
    let first = batch(MIDNIGHT_MS, 50);
    store.write(&first).await.expect("before the restart");

    pg.restart();
    let both = Batch {
        // The first batch's samples again (a replay), and 50 new ones.
        samples: batch(MIDNIGHT_MS, 100).samples,
        ..Batch::default()
    };
    let err = store
        .write(&both)
        .await
        .expect_err("the old connection is gone");
    assert!(err.is_connection_lost(), "{err}");
    assert!(matches!(err, StoreError::ConnectionLost { .. }), "{err:?}");

    let mut fresh = Store::connect(&url).await.expect("reconnect");
    assert_eq!(fresh.migrated(), [] as [i32; 0]);
    let written = fresh.write(&both).await.expect("the retried batch");
    assert_eq!((written.samples, written.duplicate_samples), (50, 50));
    assert_eq!(fresh.count_samples().await.expect("count"), 100);
}

#[tokio::test]
async fn two_stores_migrating_at_once_both_succeed() {
    let (_pg, url) = database();
    let (a, b, c) = tokio::join!(
        Store::connect(&url),
        Store::connect(&url),
        Store::connect(&url)
    );
    let stores = [a.expect("a"), b.expect("b"), c.expect("c")];
    let applied: Vec<&[i32]> = stores.iter().map(Store::migrated).collect();
    assert_eq!(
        applied.iter().filter(|m| !m.is_empty()).count(),
        1,
        "one migrates, the others find it done: {applied:?}"
    );
    let sql = client(&url).await;
    assert_eq!(
        column(&sql, "SELECT count(*)::text FROM cellbus_schema").await,
        [SCHEMA_VERSION.to_string()]
    );
}

#[tokio::test]
async fn connecting_to_nothing_is_transient_and_to_a_missing_database_is_not() {
    let pg = Postgres::start();
    let missing = Store::connect(&pg.url_for("no_such_db"))
        .await
        .expect_err("no such database");
    assert!(!missing.is_connection_lost(), "{missing}");
    assert!(missing.to_string().contains("3D000"), "{missing}");
    let port = pg.port();
    drop(pg);
    let refused = Store::connect(&format!("postgres://cellbus@127.0.0.1:{port}/postgres"))
        .await
        .expect_err("nothing listens");
    assert!(refused.is_connection_lost(), "{refused}");
    let bad = Store::connect("postgres://[").await.expect_err("bad url");
    assert!(matches!(bad, StoreError::BadUrl { .. }), "{bad:?}");
}

#[tokio::test]
async fn queries_with_times_beyond_the_calendar_answer_instead_of_panicking() {
    let (_pg, url) = database();
    let mut store = Store::connect(&url).await.expect("connect");
    store.write(&batch(MIDNIGHT_MS, 3)).await.expect("write");
    let air = id(&store, "cell1/jbc1.air_temperature").await;
    let far = at(u64::MAX / 4);
    let raw = store
        .raw(air, UNIX_EPOCH, far, 10)
        .await
        .expect("raw up to the far future");
    assert_eq!(raw.len(), 3);
    let before = store
        .last_before(air, far)
        .await
        .expect("before the far future");
    assert_eq!(before.map(|s| s.t), Some(at(MIDNIGHT_MS + 2_000)));
    let buckets = store
        .buckets(air, UNIX_EPOCH, far, Duration::MAX)
        .await
        .expect("one huge bucket");
    assert_eq!(buckets.iter().map(|b| b.count).sum::<u64>(), 3);
    let events = store.events(UNIX_EPOCH, far, 10).await.expect("events");
    assert_eq!(events.len(), 1);
}

#[tokio::test]
async fn two_stores_declaring_the_same_points_in_opposite_orders_both_commit() {
    let (_pg, url) = database();
    let mut a = Store::connect(&url).await.expect("connect a");
    let mut b = Store::connect(&url).await.expect("connect b");
    let points: Vec<PointRow> = (0..2_000)
        .map(|i| PointRow::bare("plant", "cell1", "dev", &format!("p{i:04}")))
        .collect();
    let forward = Batch {
        points: points.clone(),
        ..Batch::default()
    };
    let backward = Batch {
        points: points.into_iter().rev().collect(),
        ..Batch::default()
    };
    for round in 0..5 {
        let (wa, wb) = tokio::join!(a.write(&forward), b.write(&backward));
        assert_eq!(wa.expect("a commits").points, 2_000, "round {round}");
        assert_eq!(wb.expect("b commits").points, 2_000, "round {round}");
    }
    assert_eq!(all_points(&a).await.len(), 2_000);
}

#[tokio::test]
async fn the_same_node_id_in_two_groups_is_two_nodes_whose_points_never_merge() {
    let (_pg, url) = database();
    let mut store = Store::connect(&url).await.expect("connect");
    let mut batch = Batch::default();
    for (group, value) in [("north", 1.0), ("south", 2.0)] {
        let mut point = temperature_point();
        point.group = group.into();
        batch.points.push(point);
        let mut s = sample("jbc1", "air_temperature", MIDNIGHT_MS, value);
        s.group = group.into();
        batch.samples.push(s);
        let mut e = event(MIDNIGHT_MS, "station restarted");
        e.group = group.into();
        batch.events.push(e);
    }
    let written = store.write(&batch).await.expect("write");
    assert_eq!(
        (written.points, written.samples, written.events),
        (2, 2, 2),
        "nothing taken for a duplicate of the other group's"
    );
    let both = store
        .find_points("cell1/jbc1.air_temperature")
        .await
        .expect("find");
    let groups: Vec<&str> = both.iter().map(|p| p.group.as_str()).collect();
    assert_eq!(groups, ["north", "south"]);
    for (group, value) in [("north", 1.0), ("south", 2.0)] {
        let point = id(&store, &format!("{group}/cell1/jbc1.air_temperature")).await;
        let raw = store
            .raw(point, UNIX_EPOCH, at(MIDNIGHT_MS + 1), 10)
            .await
            .expect("raw");
        assert_eq!(
            raw.iter().map(|r| r.value).collect::<Vec<_>>(),
            [Some(value)]
        );
    }
    let sql = client(&url).await;
    assert_eq!(
        column(
            &sql,
            "SELECT group_id || ' ' || value FROM cellbus_samples ORDER BY 1"
        )
        .await,
        ["north 1", "south 2"]
    );
    assert_eq!(
        column(&sql, "SELECT group_id FROM cellbus_events ORDER BY 1").await,
        ["north", "south"]
    );
    assert_eq!(
        store.nodes_in_several_groups().await.expect("shared"),
        ["cell1".to_owned()].into_iter().collect()
    );
}

#[tokio::test]
async fn a_device_id_with_a_dot_is_found_by_trying_each_split() {
    let (_pg, url) = database();
    let mut store = Store::connect(&url).await.expect("connect");
    let batch = Batch {
        samples: vec![
            sample("meter.1", "power", MIDNIGHT_MS, 1.0),
            sample("meter", "1.power", MIDNIGHT_MS, 2.0),
            sample("meter.2", "power", MIDNIGHT_MS, 3.0),
        ],
        ..Batch::default()
    };
    store.write(&batch).await.expect("write");
    let found = store
        .find_points("cell1/meter.2.power")
        .await
        .expect("find");
    assert_eq!(
        found
            .iter()
            .map(|p| (p.device.as_str(), p.point.as_str()))
            .collect::<Vec<_>>(),
        [("meter.2", "power")]
    );
    let two = store
        .find_points("cell1/meter.1.power")
        .await
        .expect("find");
    assert_eq!(two.len(), 2, "{two:?}");
    assert!(
        store
            .find_points("cell1/meter.3.power")
            .await
            .expect("find")
            .is_empty()
    );
    assert!(
        store
            .find_points("no slash")
            .await
            .expect("find")
            .is_empty()
    );
}
