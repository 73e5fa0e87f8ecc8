use super::*;
use gateway::point::{DeviceId, PointId};
use gateway::store::HistorySample;

fn history(samples: Vec<(i64, Option<f64>, Quality)>) -> History {
    History {
        point: PointId::new(&DeviceId::new("jbc1").unwrap(), "air_temperature").unwrap(),
        from: Timestamp(0),
        to: Timestamp(10_000),
        step_ms: None,
        before: None,
        series: Series::Samples(
            samples
                .into_iter()
                .map(|(t, v, quality)| HistorySample {
                    t: Timestamp(t),
                    value: v.map(Value::Number),
                    quality,
                })
                .collect(),
        ),
        truncated: false,
    }
}

/// The store's part of a raw read, over samples in memory (as `history_page` and
/// `history_nearest` do in SQLite; the row is the index).
fn fetch(read: &RawRead, samples: &[HistorySample]) -> Fetched {
    let rows: Vec<(SampleCursor, HistorySample)> = samples
        .iter()
        .enumerate()
        .map(|(i, s)| {
            (
                SampleCursor {
                    t: s.t,
                    row: i as i64,
                },
                s.clone(),
            )
        })
        .collect();
    let (from, to) = (read.range.from, read.range.to);
    let nearest = |t: Timestamp, later: bool| {
        if later {
            samples.iter().find(|s| s.t >= t).cloned()
        } else {
            samples.iter().rev().find(|s| s.t <= t).cloned()
        }
    };
    let page: Vec<_> = match read.range.order() {
        PageOrder::OldestFirst => rows
            .into_iter()
            .filter(|(c, _)| from <= c.t && c.t < to && read.after.is_none_or(|a| *c > a))
            .take(read.rows_wanted())
            .collect(),
        PageOrder::NewestFirst => rows
            .into_iter()
            .rev()
            .filter(|(c, _)| from < c.t && c.t <= to && read.after.is_none_or(|a| *c < a))
            .take(read.rows_wanted())
            .collect(),
    };
    Fetched {
        start_bound: read
            .wants_start_bound()
            .then(|| nearest(read.range.start(), read.range.reverse)),
        rows: page,
        end_bound: read
            .bounds
            .then(|| nearest(read.range.end(), !read.range.reverse)),
    }
}

/// Every call of a raw read until no continuation is left: the values of each call.
fn read_all(read: RawRead, samples: &[HistorySample]) -> Vec<Vec<DataValue>> {
    let mut calls = Vec::new();
    let mut next = Some(read);
    while let Some(read) = next {
        let fetched = fetch(&read, samples);
        let (values, more) = read.page(&PointKind::Numeric, fetched);
        calls.push(values);
        next = more;
        assert!(calls.len() < 100, "the read never ends");
    }
    calls
}

fn samples(changes: &[(i64, Option<f64>, Quality)]) -> Vec<HistorySample> {
    changes
        .iter()
        .map(|&(t, v, quality)| HistorySample {
            t: Timestamp(t),
            value: v.map(Value::Number),
            quality,
        })
        .collect()
}

fn times(values: &[DataValue]) -> Vec<i64> {
    values
        .iter()
        .map(|v| gateway_time(&v.source_timestamp.unwrap()).0)
        .collect()
}

fn range(start: i64, end: i64) -> TimeRange {
    TimeRange::of(
        &opc_time(Timestamp(start)),
        &opc_time(Timestamp(end)),
        Timestamp(0),
    )
}

#[test]
fn raw_history_keeps_each_change_with_its_quality_and_time() {
    let stored = samples(&[
        (1_000, Some(20.0), Quality::Good),
        (2_000, None, Quality::Bad),
        (3_000, Some(21.0), Quality::Stale),
    ]);
    let calls = read_all(RawRead::new(range(0, 10_000), 0, false), &stored);
    assert_eq!(calls.len(), 1);
    let values = &calls[0];
    let statuses: Vec<_> = values.iter().map(|v| v.status()).collect();
    assert_eq!(
        statuses,
        [
            StatusCode::Good,
            StatusCode::BadCommunicationError,
            StatusCode::UncertainLastUsableValue
        ]
    );
    assert_eq!(values[0].value, Some(Variant::Double(20.0)));
    assert_eq!(times(values), [1_000, 2_000, 3_000]);
}

#[test]
fn num_values_per_node_pages_the_read_with_continuation_points_until_all_are_given() {
    let stored = samples(&[
        (1_000, Some(1.0), Quality::Good),
        (2_000, Some(2.0), Quality::Good),
        (2_000, Some(3.0), Quality::Good),
        (3_000, Some(4.0), Quality::Good),
        (4_000, Some(5.0), Quality::Good),
    ]);
    let calls = read_all(RawRead::new(range(0, 10_000), 2, false), &stored);
    let sizes: Vec<_> = calls.iter().map(Vec::len).collect();
    assert_eq!(sizes, [2, 2, 1]);
    let values: Vec<_> = calls.concat().into_iter().map(|v| v.value).collect();
    let expected: Vec<_> = (1..=5)
        .map(|n| Some(Variant::Double(f64::from(n))))
        .collect();
    assert_eq!(
        values, expected,
        "two changes at one millisecond are both given, once"
    );
    let exact = read_all(RawRead::new(range(0, 10_000), 5, false), &stored);
    assert_eq!(
        exact.len(),
        1,
        "no continuation when the last call had room"
    );
}

#[test]
fn bounds_are_the_changes_around_the_range_or_bound_not_found() {
    let stored = samples(&[
        (1_000, Some(1.0), Quality::Good),
        (3_000, Some(3.0), Quality::Good),
        (5_000, Some(5.0), Quality::Good),
        (7_000, Some(7.0), Quality::Good),
    ]);
    let all = |read| read_all(read, &stored).concat();
    // The last change before the start and the first at or after the end.
    assert_eq!(
        times(&all(RawRead::new(range(2_000, 6_000), 0, true))),
        [1_000, 3_000, 5_000, 7_000]
    );
    // A change at the start time is the start bound itself; one at the end time is
    // the end bound (the end is outside the range).
    assert_eq!(
        times(&all(RawRead::new(range(3_000, 5_000), 0, true))),
        [3_000, 5_000]
    );
    // Nothing before or after: Bad_BoundNotFound at the start and end times.
    let values = all(RawRead::new(range(0, 9_000), 0, true));
    assert_eq!(times(&values), [0, 1_000, 3_000, 5_000, 7_000, 9_000]);
    assert_eq!(values[0].status(), StatusCode::BadBoundNotFound);
    assert_eq!(values[0].value, None);
    assert_eq!(values[5].status(), StatusCode::BadBoundNotFound);
    // Backward: from the later time down to the earlier one.
    assert_eq!(
        times(&all(RawRead::new(range(6_000, 2_000), 0, true))),
        [7_000, 5_000, 3_000, 1_000]
    );
    assert_eq!(
        times(&all(RawRead::new(range(5_000, 3_000), 0, false))),
        [5_000]
    );
}

#[test]
fn bounds_count_in_num_values_per_node_and_page_like_the_changes() {
    let stored = samples(&[
        (1_000, Some(1.0), Quality::Good),
        (3_000, Some(3.0), Quality::Good),
        (5_000, Some(5.0), Quality::Good),
        (7_000, Some(7.0), Quality::Good),
    ]);
    for per_call in 1..=5 {
        let calls = read_all(RawRead::new(range(2_000, 6_000), per_call, true), &stored);
        assert!(
            calls.iter().all(|c| c.len() <= per_call as usize),
            "{per_call}"
        );
        assert_eq!(
            times(&calls.concat()),
            [1_000, 3_000, 5_000, 7_000],
            "{per_call}"
        );
    }
}

#[test]
fn an_end_before_the_start_reads_newest_first() {
    let stored = samples(&[
        (1_000, Some(20.0), Quality::Good),
        (3_000, Some(21.0), Quality::Good),
    ]);
    let read = RawRead::new(range(10_000, 0), 1, false);
    assert!(read.range.reverse);
    let calls = read_all(read, &stored);
    assert_eq!(times(&calls.concat()), [3_000, 1_000]);
    assert_eq!(calls.len(), 2);
}

#[test]
fn history_values_keep_only_the_timestamps_asked_for() {
    let value = || DataValue {
        value: Some(Variant::Double(1.0)),
        source_timestamp: Some(opc_time(Timestamp(1_000))),
        server_timestamp: Some(opc_time(Timestamp(2_000))),
        ..DataValue::default()
    };
    let [source] = with_timestamps(vec![value()], TimestampsToReturn::Source)
        .try_into()
        .unwrap();
    assert!(source.source_timestamp.is_some() && source.server_timestamp.is_none());
    let [server] = with_timestamps(vec![value()], TimestampsToReturn::Server)
        .try_into()
        .unwrap();
    assert!(server.source_timestamp.is_none() && server.server_timestamp.is_some());
    let [both] = with_timestamps(vec![value()], TimestampsToReturn::Both)
        .try_into()
        .unwrap();
    assert_eq!(both, value());
}

#[test]
fn only_an_end_time_reads_backward_from_it() {
    let end = TimeRange::of(
        &DateTime::null(),
        &opc_time(Timestamp(5_000)),
        Timestamp(9_000),
    );
    assert!(end.reverse);
    assert_eq!(end.start(), Timestamp(5_000));
}

#[test]
fn processed_history_aggregates_good_changes_per_interval_from_the_start() {
    let stored = history(vec![
        (500, Some(10.0), Quality::Good),
        (900, Some(20.0), Quality::Good),
        (950, None, Quality::Bad),
        (2_100, Some(5.0), Quality::Good),
    ]);
    let range = TimeRange {
        from: Timestamp(0),
        to: Timestamp(3_000),
        reverse: false,
    };
    let step = Duration::from_secs(1);
    let average = processed(&stored, range, step, Aggregate::Average);
    assert_eq!(average.len(), 3);
    assert_eq!(average[0].value, Some(Variant::Double(15.0)));
    assert_eq!(average[1].status(), StatusCode::BadNoData);
    assert_eq!(average[2].value, Some(Variant::Double(5.0)));
    let max = processed(&stored, range, step, Aggregate::Maximum);
    assert_eq!(max[0].value, Some(Variant::Double(20.0)));
    let min = processed(&stored, range, step, Aggregate::Minimum);
    assert_eq!(min[0].value, Some(Variant::Double(10.0)));
}

#[test]
fn too_many_or_empty_intervals_are_refused_and_an_interval_of_0_is_the_whole_range() {
    let range = TimeRange {
        from: Timestamp(0),
        to: Timestamp(100_000_000),
        reverse: false,
    };
    assert_eq!(check_interval(range, Duration::from_millis(1)), None);
    assert_eq!(check_interval(range, Duration::from_micros(500)), None);
    assert!(check_interval(range, Duration::from_secs(60)).is_some());
    assert_eq!(
        check_interval(range, Duration::ZERO),
        Some(Duration::from_millis(100_000_000))
    );
    let stored = history(vec![
        (10, Some(10.0), Quality::Good),
        (50_000_000, Some(30.0), Quality::Good),
    ]);
    let whole = check_interval(range, Duration::ZERO).unwrap();
    let average = processed(&stored, range, whole, Aggregate::Average);
    assert_eq!(average.len(), 1);
    assert_eq!(average[0].value, Some(Variant::Double(20.0)));
}
