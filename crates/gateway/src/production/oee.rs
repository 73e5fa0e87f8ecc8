//! OEE, the state breakdown and the stops of a range, from its state intervals, its
//! planned time and its counters: sans IO, so every figure has a hand-computed test.
//!
//! - Planned production time: the shifts less their breaks, within the range, less the
//!   time without data (before the gateway first polled the device, or while it was not
//!   running): what the machine did then is not known, so it is neither run nor stop. A
//!   device that did not answer while the gateway ran is a stop (unknown): a machine
//!   switched off in its shift is not producing.
//! - Availability = run time / planned time. Run time is the productive (E10 1000s) time
//!   in planned time, plus stops shorter than `micro_stop` when one is configured (a
//!   short stop is then a speed loss, counted in performance, not availability).
//! - Performance = ideal cycle × boards / run time, from the configured ideal cycle of the
//!   program, else the best cycle seen in the range (the basis says which). Over 100 %
//!   means the ideal cycle is too long: the basis says so.
//! - Quality = good boards / boards when a good-board count is configured, else the
//!   placement yield (parts placed / pickups) in the range.
//! - MTBF = productive time / failures, MTTR = unscheduled-down time / failures, a
//!   failure being an unscheduled-down stop (E10).

use std::collections::BTreeMap;
use std::time::Duration;

use serde::Serialize;

use super::e10::{Category, StateCode};
use super::shift::Planned;
use super::states::Interval;
use crate::time::Timestamp;

/// The state of time outside every shift.
pub const OUTSIDE_SHIFTS: &str = "outside shifts";
/// The state of a planned break.
pub const BREAK: &str = "planned break";

/// Seconds spent in one state in a range.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StateTime {
    /// The device's word, or [`OUTSIDE_SHIFTS`] / [`BREAK`].
    pub state: String,
    /// Its category.
    pub category: Category,
    /// Its code.
    pub code: StateCode,
    /// Seconds.
    pub seconds: f64,
}

/// One reason the machine stopped, with how often and how long.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Stop {
    /// The state and what the device said (`parts exhausted: feeder 7`).
    pub reason: String,
    /// Its category.
    pub category: Category,
    /// Stops for it in the range.
    pub count: u32,
    /// Planned seconds lost to it.
    pub seconds: f64,
}

/// The breakdown of a range by state, in planned time and outside it, with its stops.
#[derive(Debug, Clone, PartialEq)]
pub struct Breakdown {
    /// Seconds per state (planned time by the device's states, the rest as outside shifts
    /// or breaks), longest first: they add up to the range.
    pub states: Vec<StateTime>,
    /// Planned seconds with data.
    pub planned_s: f64,
    /// Planned seconds without data, left out of `planned_s`.
    pub unobserved_s: f64,
    /// Productive seconds in planned time.
    pub productive_s: f64,
    /// Stops shorter than the micro-stop threshold, counted as run time.
    pub micro_stops: Option<Stop>,
    /// The other stops by reason, longest first.
    pub stops: Vec<Stop>,
    /// Unscheduled-down stops (E10 failures).
    pub failures: u32,
    /// Unscheduled-down seconds in planned time.
    pub unscheduled_s: f64,
}

/// Splits `intervals` (clipped to the range, covering it) by `planned`.
pub fn breakdown(
    intervals: &[Interval],
    planned: &Planned,
    micro_stop: Option<Duration>,
) -> Breakdown {
    let mut states: BTreeMap<(String, StateCode), f64> = BTreeMap::new();
    let mut stops: BTreeMap<String, Stop> = BTreeMap::new();
    let mut micro: Option<Stop> = None;
    let (mut planned_s, mut productive_s, mut unscheduled_s) = (0.0, 0.0, 0.0);
    let mut unobserved_s = 0.0;
    let mut failures = 0;
    for interval in intervals {
        let inside = overlap(interval.start, interval.end, &planned.work);
        let in_breaks = overlap(interval.start, interval.end, &planned.breaks);
        let outside = seconds(interval.millis()) - inside - in_breaks;
        if in_breaks > 0.0 {
            *states
                .entry((BREAK.into(), StateCode::new(6100).expect("on the scale")))
                .or_default() += in_breaks;
        }
        if outside > 1e-9 {
            *states
                .entry((
                    OUTSIDE_SHIFTS.into(),
                    StateCode::new(6100).expect("on the scale"),
                ))
                .or_default() += outside;
        }
        if inside <= 0.0 {
            continue;
        }
        *states
            .entry((interval.state.clone(), interval.code))
            .or_default() += inside;
        if interval.category == Category::Unknown
            && interval.reason.as_deref() == Some(super::states::NO_DATA)
        {
            unobserved_s += inside;
            continue;
        }
        planned_s += inside;
        let category = interval.category;
        if category == Category::Productive {
            productive_s += inside;
            continue;
        }
        if !category.is_stop() {
            continue;
        }
        let whole = Duration::from_millis(u64::try_from(interval.millis()).unwrap_or(0));
        if let Some(threshold) = micro_stop
            && whole < threshold
        {
            let stop = micro.get_or_insert_with(|| Stop {
                reason: format!(
                    "short stops under {}",
                    humantime::format_duration(threshold)
                ),
                category: Category::Standby,
                count: 0,
                seconds: 0.0,
            });
            stop.count += 1;
            stop.seconds += inside;
            continue;
        }
        if category == Category::UnscheduledDown {
            failures += 1;
            unscheduled_s += inside;
        }
        let reason = match &interval.reason {
            Some(r) => format!("{}: {r}", interval.state),
            None => interval.state.clone(),
        };
        let stop = stops.entry(reason.clone()).or_insert(Stop {
            reason,
            category,
            count: 0,
            seconds: 0.0,
        });
        stop.count += 1;
        stop.seconds += inside;
    }
    let mut states: Vec<StateTime> = states
        .into_iter()
        .map(|((state, code), seconds)| StateTime {
            state,
            category: code.category(),
            code,
            seconds,
        })
        .collect();
    states.sort_by(|a, b| b.seconds.total_cmp(&a.seconds));
    let mut stops: Vec<Stop> = stops.into_values().collect();
    stops.sort_by(|a, b| b.seconds.total_cmp(&a.seconds));
    Breakdown {
        states,
        planned_s,
        unobserved_s,
        productive_s,
        micro_stops: micro,
        stops,
        failures,
        unscheduled_s,
    }
}

/// How the performance and quality were reckoned.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Basis {
    /// The ideal cycle used, and where it came from.
    pub performance: String,
    /// What quality is the share of.
    pub quality: String,
    /// Where the plan came from.
    pub boards_planned: String,
}

/// The ideal cycle of the range: from the config, or the best seen.
#[derive(Debug, Clone, PartialEq)]
pub enum IdealCycle {
    /// The config's, for this program (`None`: its default).
    Configured {
        /// Seconds per board.
        seconds: f64,
        /// The program it is for, if it is a program's own.
        program: Option<String>,
    },
    /// The shortest board time the machine reported in the range.
    BestSeen(f64),
    /// Neither: no performance.
    Unknown,
}

/// The counts of a range.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Counts {
    /// Boards finished.
    pub boards: Option<f64>,
    /// Good boards, when a good-board count is configured.
    pub good_boards: Option<f64>,
    /// Pickups.
    pub pickups: Option<f64>,
    /// Parts placed.
    pub placed: Option<f64>,
    /// The machine's own plan (its last value in the range).
    pub machine_plan: Option<f64>,
}

/// The OEE figures of a range.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Oee {
    /// Run time / planned time.
    pub availability: Option<f64>,
    /// Ideal cycle × boards / run time.
    pub performance: Option<f64>,
    /// Good / total.
    pub quality: Option<f64>,
    /// A × P × Q.
    pub oee: Option<f64>,
    /// Boards finished.
    pub boards: Option<f64>,
    /// Boards the plan asked for by the end of the range (or by now).
    pub boards_planned: Option<f64>,
    /// Stops in planned time (the micro stops as one line).
    pub stops: Vec<Stop>,
    /// Productive seconds per failure.
    pub mtbf_s: Option<f64>,
    /// Unscheduled-down seconds per failure.
    pub mttr_s: Option<f64>,
    /// How performance, quality and the plan were reckoned.
    pub basis: Basis,
}

/// OEE from a breakdown, the counts, the ideal cycle and the planned seconds that have
/// passed (`planned_elapsed_s`: up to now for a range that has not ended).
pub fn oee(b: &Breakdown, counts: &Counts, ideal: &IdealCycle, planned_elapsed_s: f64) -> Oee {
    let micro_s = b.micro_stops.as_ref().map_or(0.0, |m| m.seconds);
    let run_s = b.productive_s + micro_s;
    let availability = ratio(run_s, b.planned_s);
    let ideal_s = match ideal {
        IdealCycle::Configured { seconds, .. } => Some(*seconds),
        IdealCycle::BestSeen(s) => Some(*s),
        IdealCycle::Unknown => None,
    };
    let performance = match (ideal_s, counts.boards) {
        (Some(ideal), Some(boards)) => ratio(ideal * boards, run_s),
        _ => None,
    };
    let mut perf_words = match ideal {
        IdealCycle::Configured {
            seconds,
            program: Some(p),
        } => format!(
            "ideal cycle {} s for program {p}, from the config",
            trim(*seconds)
        ),
        IdealCycle::Configured {
            seconds,
            program: None,
        } => format!("ideal cycle {} s, from the config", trim(*seconds)),
        IdealCycle::BestSeen(s) => format!(
            "best cycle seen in the range, {} s (no ideal cycle configured)",
            trim(*s)
        ),
        IdealCycle::Unknown => {
            "no ideal cycle configured and no board time seen in the range".to_owned()
        }
    };
    if performance.is_some_and(|p| p > 1.0) {
        perf_words.push_str(
            "; over 100 %: the machine ran faster than the ideal cycle, which is set too long",
        );
    }
    let (quality, quality_words) = match (
        counts.good_boards,
        counts.boards,
        counts.placed,
        counts.pickups,
    ) {
        (Some(good), Some(boards), _, _) => (
            ratio(good, boards),
            "good boards / boards finished (the configured good-board count)".to_owned(),
        ),
        (_, _, Some(placed), Some(pickups)) => (
            ratio(placed, pickups),
            "placement yield: parts placed / pickups (no good-board count configured)".to_owned(),
        ),
        _ => (None, "no counts to reckon quality from".to_owned()),
    };
    let oee = match (availability, performance, quality) {
        (Some(a), Some(p), Some(q)) => Some(a * p * q),
        _ => None,
    };
    let (boards_planned, plan_words) = match (ideal, counts.machine_plan) {
        (IdealCycle::Configured { seconds, .. }, _) if *seconds > 0.0 => (
            Some((planned_elapsed_s / seconds).floor()),
            "planned time so far / the configured ideal cycle".to_owned(),
        ),
        (_, Some(plan)) if plan > 0.0 => {
            (Some(plan), "the machine's own production plan".to_owned())
        }
        (_, Some(_)) => (
            None,
            "no ideal cycle configured, and the machine's production plan is not set (0)"
                .to_owned(),
        ),
        _ => (
            None,
            "no ideal cycle configured and no plan from the machine".to_owned(),
        ),
    };
    let mut stops = b.stops.clone();
    if let Some(m) = &b.micro_stops {
        stops.push(m.clone());
        stops.sort_by(|a, b| b.seconds.total_cmp(&a.seconds));
    }
    let (mtbf_s, mttr_s) = if b.failures > 0 {
        let n = f64::from(b.failures);
        (Some(b.productive_s / n), Some(b.unscheduled_s / n))
    } else {
        (None, None)
    };
    Oee {
        availability,
        performance,
        quality,
        oee,
        boards: counts.boards,
        boards_planned,
        stops,
        mtbf_s,
        mttr_s,
        basis: Basis {
            performance: perf_words,
            quality: quality_words,
            boards_planned: plan_words,
        },
    }
}

/// How much a counter rose over its samples (`before` then those in the range): the sum
/// of its rises, a fall being a reset to zero (the new value is what was counted since).
pub fn increase(values: impl IntoIterator<Item = f64>) -> Option<f64> {
    let mut last: Option<f64> = None;
    let mut total: Option<f64> = None;
    for v in values {
        if let Some(prev) = last {
            let rise = if v >= prev { v - prev } else { v };
            *total.get_or_insert(0.0) += rise;
        } else {
            total.get_or_insert(0.0);
        }
        last = Some(v);
    }
    total
}

/// Seconds of `[start, end)` inside `spans` (ordered, disjoint).
fn overlap(start: Timestamp, end: Timestamp, spans: &[(Timestamp, Timestamp)]) -> f64 {
    spans
        .iter()
        .map(|(s, e)| (end.0.min(e.0) - start.0.max(s.0)).max(0))
        .map(seconds)
        .sum()
}

fn seconds(ms: i64) -> f64 {
    ms as f64 / 1000.0
}

fn ratio(a: f64, b: f64) -> Option<f64> {
    (b > 0.0).then(|| a / b)
}

/// A number of seconds without a trailing `.0`.
fn trim(s: f64) -> String {
    let text = format!("{s:.1}");
    text.strip_suffix(".0").map(str::to_owned).unwrap_or(text)
}

#[cfg(test)]
mod tests;
