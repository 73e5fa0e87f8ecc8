use super::*;
use std::time::UNIX_EPOCH;

fn sample(point: &str, ms: u64) -> SampleRow {
    SampleRow {
        group: "plant".into(),
        node: "cell1".into(),
        device: "jbc1".into(),
        point: point.into(),
        t: UNIX_EPOCH + Duration::from_millis(ms),
        value: Some(1.0),
        text: None,
        quality: Quality::Good,
    }
}

const NOW_MS: u64 = 1_800_000_000_000;

#[test]
fn a_batch_split_by_point_keeps_each_points_rows_together_and_loses_none() {
    let mut batch = Batch::default();
    for i in 0..200 {
        let name = format!("p{i}");
        batch
            .points
            .push(PointRow::bare("plant", "cell1", "jbc1", &name));
        batch.samples.push(sample(&name, NOW_MS));
        batch.samples.push(sample(&name, NOW_MS + 1));
    }
    batch.events.push(EventRow {
        group: "plant".into(),
        node: "cell1".into(),
        device: None,
        point: None,
        line: None,
        t: UNIX_EPOCH + Duration::from_millis(NOW_MS),
        kind: "device_down".into(),
        severity: 700,
        message: "down".into(),
        fields: None,
    });
    let halves = batch.clone().split_by_point();
    assert_eq!(halves[0].len() + halves[1].len(), batch.len());
    assert!(
        halves.iter().all(|h| h.samples.len() > 100),
        "both halves work"
    );
    assert_eq!(halves[0].events.len(), 1);
    for half in &halves {
        let defined: std::collections::BTreeSet<&str> =
            half.points.iter().map(|p| p.point.as_str()).collect();
        for s in &half.samples {
            assert!(
                defined.contains(s.point.as_str()),
                "{} away from its definition",
                s.point
            );
        }
    }
}

#[test]
fn samples_before_2000_or_a_day_ahead_are_refused_and_counted() {
    let now = UNIX_EPOCH + Duration::from_millis(NOW_MS);
    let batch = Batch {
        samples: vec![
            sample("ok", NOW_MS),
            sample("old", 900_000_000_000),
            sample("ahead", NOW_MS + 86_400_001),
            sample("edge", NOW_MS + 86_400_000),
        ],
        ..Batch::default()
    };
    let mut written = Written::default();
    let accepted = Accepted::sort(&batch, now, None, &mut written);
    let names: Vec<&str> = accepted.samples.iter().map(|s| s.point.as_str()).collect();
    assert_eq!(names, ["ok", "edge"]);
    assert_eq!(written.refused_samples, 2);
    let first = written.first_refusal.expect("a refusal");
    assert_eq!(first.reason, RefusalReason::BeforeEarliest);
    assert_eq!(first.row, "sample cell1/jbc1.old");
}

#[test]
fn a_text_with_a_nul_is_refused_instead_of_failing_the_batch() {
    let mut bad = sample("t", NOW_MS);
    bad.text = Some("a\0b".into());
    let mut bad_point = PointRow::bare("plant", "cell1", "jbc1", "p");
    bad_point.unit = Some("\0".into());
    let batch = Batch {
        points: vec![bad_point],
        samples: vec![bad],
        ..Batch::default()
    };
    let mut written = Written::default();
    let accepted = Accepted::sort(
        &batch,
        UNIX_EPOCH + Duration::from_millis(NOW_MS),
        None,
        &mut written,
    );
    assert!(accepted.is_empty());
    assert_eq!((written.refused_points, written.refused_samples), (1, 1));
    assert_eq!(
        written.first_refusal.map(|r| r.reason),
        Some(RefusalReason::NulCharacter)
    );
}

#[test]
fn a_point_defined_twice_in_a_batch_keeps_its_last_definition() {
    let mut second = PointRow::bare("plant", "cell1", "jbc1", "p");
    second.unit = Some("°C".into());
    let batch = Batch {
        points: vec![
            PointRow::bare("plant", "cell1", "jbc1", "p"),
            second.clone(),
        ],
        ..Batch::default()
    };
    let mut written = Written::default();
    let accepted = Accepted::sort(&batch, SystemTime::now(), None, &mut written);
    assert_eq!(accepted.points, [&second]);
}

#[test]
fn rows_older_than_the_maximum_age_are_refused_so_a_rogue_birth_makes_no_partitions() {
    const DAY_MS: u64 = 86_400_000;
    let now = UNIX_EPOCH + Duration::from_millis(NOW_MS);
    // A rogue birth: one metric per day back to 2000.
    let mut batch = Batch::default();
    for day in 0..6_000 {
        batch
            .samples
            .push(sample(&format!("m{day}"), NOW_MS - day * DAY_MS));
    }
    let mut event = EventRow {
        group: "plant".into(),
        node: "cell1".into(),
        device: None,
        point: None,
        line: None,
        t: UNIX_EPOCH + Duration::from_millis(NOW_MS - 32 * DAY_MS),
        kind: "device_down".into(),
        severity: 700,
        message: "old".into(),
        fields: None,
    };
    batch.events.push(event.clone());
    event.t = now;
    batch.events.push(event);
    let mut written = Written::default();
    let max_age = Some(Duration::from_secs(31 * 86_400));
    let accepted = Accepted::sort(&batch, now, max_age, &mut written);
    assert_eq!(accepted.samples.len(), 32, "today and the 31 days before");
    let days: HashSet<i64> = accepted.samples.iter().map(|s| days::day_of(s.t)).collect();
    assert!(days.len() <= 33, "{} partitions", days.len());
    assert_eq!(accepted.events.len(), 1);
    assert_eq!(
        (written.refused_samples, written.refused_events),
        (6_000 - 32, 1)
    );
    let first = written.first_refusal.expect("a refusal");
    assert_eq!(first.reason, RefusalReason::TooOld { max_age_days: 31 });
    assert!(
        first
            .to_string()
            .contains("more than 31 days before this clock"),
        "{first}"
    );
}

#[tokio::test]
async fn a_version_1_database_keeps_each_points_history_when_its_node_is_born_in_a_group() {
    let pg = testkit::Postgres::start();
    let url = pg.create_database("v1");
    let config = parse_url(&url).unwrap();
    let (mut client, connection) = config.connect(NoTls).await.unwrap();
    tokio::spawn(connection);
    schema::migrate_to(&mut client, 1).await.unwrap();
    // What a version-1 historian wrote: a point, a sample of it, an event.
    client
        .batch_execute(
            "CREATE TABLE samples_2025_03_10 PARTITION OF samples \
                 FOR VALUES FROM ('2025-03-10') TO ('2025-03-11');
             INSERT INTO points (node, device, point, datatype) \
                 VALUES ('cell1', 'jbc1', 'air_temperature', 'Double');
             INSERT INTO samples SELECT id, '2025-03-10 01:00:00+00', 300, NULL, 0 \
                 FROM points;
             INSERT INTO events (t, node, kind, severity, message) \
                 VALUES ('2025-03-10 01:00:00+00', 'cell1', 'device_down', 700, 'down')",
        )
        .await
        .unwrap();
    drop(client);

    let mut store = Store::connect(&url).await.unwrap();
    assert_eq!(store.migrated(), [2, 3, 4, 5]);
    let old = store
        .find_points("cell1/jbc1.air_temperature")
        .await
        .unwrap();
    assert_eq!((old.len(), old[0].group.as_str()), (1, ""));
    // The node's birth in its group claims the point: the same row, its history kept.
    let mut birth = PointRow::bare("plant", "cell1", "jbc1", "air_temperature");
    birth.datatype = "Double".into();
    let later = sample("air_temperature", 1_741_575_600_000);
    store
        .write(&Batch {
            points: vec![birth],
            samples: vec![later],
            ..Batch::default()
        })
        .await
        .unwrap();
    let claimed = store
        .find_points("plant/cell1/jbc1.air_temperature")
        .await
        .unwrap();
    assert_eq!(claimed.len(), 1);
    assert_eq!(claimed[0].id, old[0].id, "the same point row");
    let history = store
        .raw(claimed[0].id, UNIX_EPOCH, SystemTime::now(), 10)
        .await
        .unwrap();
    assert_eq!(history.len(), 2, "the version-1 sample and the new one");
    // Another group's node of the same id is another node.
    store
        .write(&Batch {
            points: vec![PointRow::bare("other", "cell1", "jbc1", "air_temperature")],
            ..Batch::default()
        })
        .await
        .unwrap();
    assert_eq!(
        store
            .find_points("cell1/jbc1.air_temperature")
            .await
            .unwrap()
            .len(),
        2
    );
    let events = store
        .events(UNIX_EPOCH, SystemTime::now(), 10)
        .await
        .unwrap();
    assert_eq!(events.len(), 1);
    assert_eq!(events[0].group, "plant", "the event went with its node");
    // The same event sent again by the gateway (a replayed backlog) is a duplicate.
    let again = EventRow {
        group: "plant".into(),
        node: "cell1".into(),
        device: None,
        point: None,
        line: None,
        t: events[0].t,
        kind: "device_down".into(),
        severity: 700,
        message: "down".into(),
        fields: None,
    };
    let written = store
        .write(&Batch {
            events: vec![again],
            ..Batch::default()
        })
        .await
        .unwrap();
    assert_eq!((written.events, written.duplicate_events), (0, 1));
}

#[test]
fn points_of_a_node_are_shown_without_a_device() {
    assert_eq!(display_point("cell1", "", "rows"), "cell1/rows");
    assert_eq!(display_point("cell1", "jbc1", "t"), "cell1/jbc1.t");
}
