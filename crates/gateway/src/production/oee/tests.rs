//! Hand-computed examples: each figure is worked out in the comments.

use super::*;
use crate::production::shift::{Shift, Shifts, clock};

fn utc(text: &str) -> Timestamp {
    let t: jiff::Timestamp = text.parse().unwrap();
    Timestamp(t.as_millisecond())
}

fn iv(start: &str, end: &str, state: &str, code: i64, reason: Option<&str>) -> Interval {
    let code = StateCode::new(code).unwrap();
    Interval {
        start: utc(start),
        end: utc(end),
        state: state.into(),
        category: code.category(),
        code,
        reason: reason.map(Into::into),
    }
}

fn shift(name: &str, start: &str, end: &str, breaks: &[(&str, &str)]) -> Shift {
    Shift {
        name: name.into(),
        days: crate::production::shift::EVERY_DAY.to_vec(),
        start: clock(start).unwrap(),
        end: clock(end).unwrap(),
        breaks: breaks
            .iter()
            .map(|(s, e)| (clock(s).unwrap(), clock(e).unwrap()))
            .collect(),
    }
}

/// `s` seconds after 08:00 UTC on 2026-11-02, as RFC 3339.
fn after_eight(s: i64) -> String {
    let base = utc("2026-11-02T08:00:00Z").0;
    jiff::Timestamp::from_millisecond(base + s * 1000)
        .unwrap()
        .to_string()
}

/// Each stop as (reason, count, seconds).
fn stops(oee: &Oee) -> Vec<(&str, u32, f64)> {
    oee.stops
        .iter()
        .map(|s| (s.reason.as_str(), s.count, s.seconds))
        .collect()
}

fn seconds_of(b: &Breakdown, state: &str) -> f64 {
    b.states
        .iter()
        .find(|s| s.state == state)
        .map_or(0.0, |s| s.seconds)
}

fn close(a: Option<f64>, b: f64) -> bool {
    a.is_some_and(|a| (a - b).abs() < 1e-9)
}

/// An early shift 06:00–14:00 with a break 10:00–10:30: 8 h less 30 min = 27,000 s
/// planned. Run 06:00–09:00 (10,800 s), parts exhausted 09:00–09:20 (1,200 s), run
/// 09:20–10:40 of which the break takes 1,800 s (3,000 s planned), ready 10:40–11:00
/// (1,200 s), run 11:00–13:00 (7,200 s), error stop 13:00–13:10 (600 s), run 13:10–14:00
/// (3,000 s): productive 24,000 s, stops 3,000 s.
fn early_shift() -> (Vec<Interval>, Planned) {
    let shifts = Shifts::new(
        Some("UTC"),
        vec![shift("early", "06:00", "14:00", &[("10:00", "10:30")])],
    )
    .unwrap();
    let day = "2026-11-02T";
    let at = |t: &str| format!("{day}{t}:00Z");
    let intervals = vec![
        iv(&at("06:00"), &at("09:00"), "run", 1100, None),
        iv(
            &at("09:00"),
            &at("09:20"),
            "parts exhausted",
            5500,
            Some("feeder 7"),
        ),
        iv(&at("09:20"), &at("10:40"), "run", 1100, None),
        iv(&at("10:40"), &at("11:00"), "ready", 2000, None),
        iv(&at("11:00"), &at("13:00"), "run", 1100, None),
        iv(
            &at("13:00"),
            &at("13:10"),
            "error stop",
            5000,
            Some("error code 5"),
        ),
        iv(&at("13:10"), &at("14:00"), "run", 1100, None),
    ];
    let planned = shifts.planned(utc(&at("06:00")), utc(&at("14:00")));
    (intervals, planned)
}

#[test]
fn an_early_shift_with_a_break_adds_up_and_gives_its_hand_computed_oee() {
    let (intervals, planned) = early_shift();
    let b = breakdown(&intervals, &planned, None);
    assert_eq!(b.planned_s, 27_000.0);
    assert_eq!(b.productive_s, 24_000.0);
    assert_eq!(seconds_of(&b, "run"), 24_000.0);
    assert_eq!(seconds_of(&b, BREAK), 1_800.0);
    let total: f64 = b.states.iter().map(|s| s.seconds).sum();
    assert_eq!(total, 8.0 * 3600.0, "the states add up to the range");
    let counts = Counts {
        boards: Some(700.0),
        pickups: Some(100_000.0),
        placed: Some(99_000.0),
        ..Counts::default()
    };
    let ideal = IdealCycle::Configured {
        seconds: 30.0,
        program: None,
    };
    let oee = oee(&b, &counts, &ideal, b.planned_s);
    // 24,000 / 27,000.
    assert!(close(oee.availability, 24_000.0 / 27_000.0));
    // 30 s × 700 boards / 24,000 s run = 21,000 / 24,000.
    assert!(close(oee.performance, 0.875));
    // 99,000 placed / 100,000 picked up.
    assert!(close(oee.quality, 0.99));
    // 21,000 / 27,000 × 0.99.
    assert!(close(oee.oee, 0.77));
    // 27,000 s / 30 s.
    assert_eq!(oee.boards_planned, Some(900.0));
    // Two failures (5500 and 5000): 24,000 / 2 and (1,200 + 600) / 2.
    assert!(close(oee.mtbf_s, 12_000.0));
    assert!(close(oee.mttr_s, 900.0));
    assert_eq!(
        stops(&oee),
        [
            ("parts exhausted: feeder 7", 1, 1_200.0),
            ("ready", 1, 1_200.0),
            ("error stop: error code 5", 1, 600.0),
        ]
    );
    assert!(oee.basis.performance.contains("30 s, from the config"));
    assert!(oee.basis.quality.starts_with("placement yield"));
}

/// A night shift 22:00–06:00 with a break 02:00–02:30, asked from 23:30, in the middle of
/// a stop that began at 23:00: planned 23:30–06:00 = 23,400 s less 1,800 s = 21,600 s.
/// Parts exhausted 23:30–00:15 (2,700 s), run 00:15–06:00 (20,700 s less the break:
/// 18,900 s).
#[test]
fn a_range_that_starts_mid_stop_in_a_shift_across_midnight_counts_only_its_part() {
    let shifts = Shifts::new(
        Some("UTC"),
        vec![shift("night", "22:00", "06:00", &[("02:00", "02:30")])],
    )
    .unwrap();
    let (from, to) = (utc("2026-11-02T23:30:00Z"), utc("2026-11-03T06:00:00Z"));
    let intervals = vec![
        iv(
            "2026-11-02T23:30:00Z",
            "2026-11-03T00:15:00Z",
            "parts exhausted",
            5500,
            Some("feeder 9"),
        ),
        iv(
            "2026-11-03T00:15:00Z",
            "2026-11-03T06:00:00Z",
            "run",
            1100,
            None,
        ),
    ];
    let planned = shifts.planned(from, to);
    let b = breakdown(&intervals, &planned, None);
    assert_eq!(b.planned_s, 21_600.0);
    assert_eq!(b.productive_s, 18_900.0);
    let counts = Counts {
        boards: Some(400.0),
        good_boards: Some(390.0),
        pickups: Some(10.0),
        placed: Some(9.0),
        machine_plan: Some(1000.0),
    };
    let oee = oee(&b, &counts, &IdealCycle::BestSeen(42.0), b.planned_s);
    // 18,900 / 21,600.
    assert!(close(oee.availability, 0.875));
    // 42 s × 400 / 18,900 s.
    assert!(close(oee.performance, 16_800.0 / 18_900.0));
    // The good-board count wins over the placement yield: 390 / 400.
    assert!(close(oee.quality, 0.975));
    assert!(oee.basis.quality.starts_with("good boards"));
    assert!(oee.basis.performance.contains("best cycle seen"));
    // No ideal cycle configured: the machine's own plan.
    assert_eq!(oee.boards_planned, Some(1000.0));
    assert!(close(oee.mtbf_s, 18_900.0));
    assert!(close(oee.mttr_s, 2_700.0));
    assert_eq!(oee.stops[0].reason, "parts exhausted: feeder 9");
    assert_eq!(oee.stops[0].seconds, 2_700.0);
}

/// A 24 h shift, 1,500 s asked: run 0–600, ready 600–660 (60 s, under the 2 min
/// threshold: run time), run 660–1,200, error stop 1,200–1,500. Run time 1,140 + 60 =
/// 1,200 s of 1,500.
#[test]
fn stops_under_the_micro_stop_threshold_are_run_time_and_one_line_of_the_stops() {
    let shifts = Shifts::new(Some("UTC"), Vec::new()).unwrap();
    let t = after_eight;
    let intervals = vec![
        iv(&t(0), &t(600), "run", 1100, None),
        iv(&t(600), &t(660), "ready", 2000, None),
        iv(&t(660), &t(1200), "run", 1100, None),
        iv(&t(1200), &t(1500), "error stop", 5000, None),
    ];
    let planned = shifts.planned(utc(&t(0)), utc(&t(1500)));
    let b = breakdown(&intervals, &planned, Some(Duration::from_secs(120)));
    let oee = oee(&b, &Counts::default(), &IdealCycle::Unknown, b.planned_s);
    assert!(close(oee.availability, 0.8));
    assert_eq!(oee.performance, None);
    assert_eq!(oee.oee, None);
    assert_eq!(
        stops(&oee),
        [("error stop", 1, 300.0), ("short stops under 2m", 1, 60.0)]
    );
}

#[test]
fn a_performance_over_a_hundred_percent_says_the_ideal_cycle_is_too_long() {
    let (intervals, planned) = early_shift();
    let b = breakdown(&intervals, &planned, None);
    let counts = Counts {
        boards: Some(1_000.0),
        ..Counts::default()
    };
    let ideal = IdealCycle::Configured {
        seconds: 30.0,
        program: Some("PCB-A".into()),
    };
    let oee = oee(&b, &counts, &ideal, b.planned_s);
    assert!(oee.performance.unwrap() > 1.0);
    assert!(oee.basis.performance.contains("program PCB-A"));
    assert!(oee.basis.performance.contains("set too long"));
}

#[test]
fn time_outside_every_shift_is_not_scheduled_and_not_planned() {
    let shifts = Shifts::new(Some("UTC"), vec![shift("early", "06:00", "14:00", &[])]).unwrap();
    let intervals = vec![iv(
        "2026-11-02T12:00:00Z",
        "2026-11-02T16:00:00Z",
        "run",
        1100,
        None,
    )];
    let planned = shifts.planned(utc("2026-11-02T12:00:00Z"), utc("2026-11-02T16:00:00Z"));
    let b = breakdown(&intervals, &planned, None);
    assert_eq!(b.planned_s, 7_200.0);
    assert_eq!(seconds_of(&b, OUTSIDE_SHIFTS), 7_200.0);
    let outside = b.states.iter().find(|s| s.state == OUTSIDE_SHIFTS).unwrap();
    assert_eq!(outside.category, Category::NonScheduled);
}

/// A 24 h shift, 1,000 s asked: no data 0–400 (the gateway was not running), run
/// 400–700, the device not answering 700–800, run 800–1,000. Planned with data: 600 s,
/// of which 500 s run; the silent device is a stop.
#[test]
fn time_without_data_is_left_out_of_planned_time_but_a_silent_device_is_a_stop() {
    use crate::production::states::{NO_DATA, NOT_ANSWERING};
    let shifts = Shifts::new(Some("UTC"), Vec::new()).unwrap();
    let t = after_eight;
    let unknown = |a: i64, b: i64, why: &str| iv(&t(a), &t(b), "unknown", 0, Some(why));
    let intervals = vec![
        unknown(0, 400, NO_DATA),
        iv(&t(400), &t(700), "run", 1100, None),
        unknown(700, 800, NOT_ANSWERING),
        iv(&t(800), &t(1000), "run", 1100, None),
    ];
    let planned = shifts.planned(utc(&t(0)), utc(&t(1000)));
    let b = breakdown(&intervals, &planned, None);
    assert_eq!(b.planned_s, 600.0);
    assert_eq!(b.unobserved_s, 400.0);
    assert_eq!(seconds_of(&b, "unknown"), 500.0, "both unknowns are states");
    let oee = oee(&b, &Counts::default(), &IdealCycle::Unknown, b.planned_s);
    assert!(close(oee.availability, 500.0 / 600.0));
    assert_eq!(oee.stops.len(), 1);
    assert!(oee.stops[0].reason.contains(NOT_ANSWERING));
}

#[test]
fn a_counter_that_resets_counts_what_it_counted_after_the_reset() {
    // 100 → 150 (+50), reset, 30 (+30), 50 (+20).
    assert_eq!(increase([100.0, 150.0, 30.0, 50.0]), Some(100.0));
    assert_eq!(increase([7.0]), Some(0.0));
    assert_eq!(increase([]), None);
}
