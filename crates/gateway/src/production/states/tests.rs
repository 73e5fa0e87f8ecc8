use super::*;

fn t(s: i64) -> Timestamp {
    Timestamp(s * 1000)
}

fn good(at: i64, value: Value) -> HistorySample {
    HistorySample {
        t: t(at),
        value: Some(value),
        quality: Quality::Good,
    }
}

fn bad(at: i64) -> HistorySample {
    HistorySample {
        t: t(at),
        value: None,
        quality: Quality::Bad,
    }
}

fn text(s: &str) -> Value {
    Value::Text(s.to_owned())
}

/// A device's three points changing together at each `(second, state, code, reason)`.
fn together(changes: &[(i64, &str, u16, &str)]) -> StateSamples {
    let mut samples = StateSamples::default();
    for (at, state, code, reason) in changes {
        samples.state.during.push(good(*at, text(state)));
        samples
            .code
            .during
            .push(good(*at, Value::Number(f64::from(*code))));
        samples.reason.during.push(good(*at, text(reason)));
    }
    samples
}

#[test]
fn each_change_of_state_starts_an_interval_and_the_last_runs_to_the_end_of_the_range() {
    let samples = together(&[(10, "run", 1100, ""), (40, "ready", 2000, "")]);
    let got = intervals(&samples, t(10), t(100));
    assert_eq!(got.len(), 2);
    assert_eq!((got[0].start, got[0].end), (t(10), t(40)));
    assert_eq!(got[0].state, "run");
    assert_eq!(got[0].category, Category::Productive);
    assert_eq!(got[0].reason, None);
    assert_eq!((got[1].start, got[1].end), (t(40), t(100)));
    assert_eq!(got[1].category, Category::Standby);
}

#[test]
fn time_before_the_first_sample_is_unknown_for_want_of_data() {
    let samples = together(&[(30, "run", 1100, "")]);
    let got = intervals(&samples, t(0), t(60));
    assert_eq!(got[0].state, "unknown");
    assert_eq!(got[0].code, StateCode::UNKNOWN);
    assert_eq!(got[0].reason.as_deref(), Some(NO_DATA));
    assert_eq!((got[0].start, got[0].end), (t(0), t(30)));
    assert_eq!(got[1].state, "run");
}

#[test]
fn a_range_that_starts_mid_interval_takes_the_state_in_force_before_it() {
    let mut samples = together(&[(50, "run", 1100, "")]);
    samples.state.before = Some(good(5, text("parts exhausted")));
    samples.code.before = Some(good(5, Value::Number(5500.0)));
    samples.reason.before = Some(good(5, text("feeder 7")));
    let got = intervals(&samples, t(20), t(80));
    assert_eq!(got[0].state, "parts exhausted");
    assert_eq!(got[0].category, Category::UnscheduledDown);
    assert_eq!(got[0].reason.as_deref(), Some("feeder 7"));
    assert_eq!((got[0].start, got[0].end), (t(20), t(50)));
}

#[test]
fn a_device_that_stops_answering_is_unknown_until_it_answers_again() {
    let mut samples = together(&[(0, "run", 1100, ""), (40, "run", 1100, "")]);
    for points in [&mut samples.state, &mut samples.code, &mut samples.reason] {
        points.during.insert(1, bad(20));
    }
    let got = intervals(&samples, t(0), t(60));
    let states: Vec<(&str, i64, i64)> = got
        .iter()
        .map(|i| (i.state.as_str(), i.start.0 / 1000, i.end.0 / 1000))
        .collect();
    assert_eq!(
        states,
        [("run", 0, 20), ("unknown", 20, 40), ("run", 40, 60)]
    );
    assert_eq!(got[1].reason.as_deref(), Some(NOT_ANSWERING));
}

#[test]
fn a_new_reason_alone_starts_a_new_interval_and_equal_neighbours_merge() {
    let samples = together(&[
        (0, "parts exhausted", 5500, "feeder 7"),
        (10, "parts exhausted", 5500, "feeder 9"),
        (20, "parts exhausted", 5500, "feeder 9"),
    ]);
    let got = intervals(&samples, t(0), t(30));
    let reasons: Vec<_> = got.iter().map(|i| i.reason.clone().unwrap()).collect();
    assert_eq!(reasons, ["feeder 7", "feeder 9"]);
    assert_eq!(got[1].end, t(30));
}

#[test]
fn the_intervals_cover_the_range_without_gaps_or_overlaps() {
    let samples = together(&[
        (3, "run", 1100, ""),
        (7, "ready", 2000, ""),
        (7, "ready", 2000, ""),
        (11, "error stop", 5000, "error code 5"),
    ]);
    let got = intervals(&samples, t(0), t(20));
    assert_eq!(got.first().unwrap().start, t(0));
    assert_eq!(got.last().unwrap().end, t(20));
    for pair in got.windows(2) {
        assert_eq!(pair[0].end, pair[1].start);
    }
    let total: i64 = got.iter().map(Interval::millis).sum();
    assert_eq!(total, 20_000);
}

#[test]
fn a_states_table_naming_a_state_the_kind_lacks_or_a_code_off_the_scale_is_refused() {
    const STATES: [StateDef; 2] = [StateDef::new("run", 1100), StateDef::new("ready", 2000)];
    let raw = |k: &str, v: i64| BTreeMap::from([(k.to_owned(), v)]);
    let moved = check_overrides("placer", &STATES, &raw("ready", 2200)).unwrap();
    assert_eq!(moved["ready"].get(), 2200);
    let error = check_overrides("placer", &STATES, &raw("idle", 2200)).unwrap_err();
    assert!(error.contains("no machine state \"idle\""), "{error}");
    assert!(error.contains("\"run\", \"ready\""), "{error}");
    let error = check_overrides("placer", &STATES, &raw("ready", 2250)).unwrap_err();
    assert!(error.contains("2200 no product"), "{error}");
    let error = check_overrides("modbus", &[], &raw("ready", 2000)).unwrap_err();
    assert!(error.contains("report no machine states"), "{error}");
}
