//! A device's machine states as points, and the intervals the history makes of them.
//!
//! A device kind lists the states it reports, each with its default code
//! ([`StateDef`]); a device's `states` table in the config moves a state to another code
//! (`states = { ready = 2200 }`). The driver reports its state after each poll of the
//! group that reads it through `driver::machine::StatePoints`, as three points of the device:
//! `machine_state` (the device's own word: `run`, `parts exhausted`),
//! `machine_state_code` (the E10 / IPC-CFX code, an enumeration labelled with its words)
//! and `machine_state_reason` (what the device said: the feeder, the fault number; empty
//! when it said nothing). Being points, they are kept in the history on change, survive a
//! `kill -9` like any sample, and reach MQTT, OPC UA and the plant historian as every
//! point does. An interval runs from one change of the three to the next; a bad sample (the
//! device not answering) or no sample at all is unknown.

use std::collections::BTreeMap;

use serde::Serialize;

use super::e10::{Category, StateCode};
use crate::point::{DeviceId, PointId, Quality, Value};
use crate::store::HistorySample;
use crate::time::Timestamp;

/// The point with the device's own word for its state.
pub const STATE_POINT: &str = "machine_state";
/// The point with the state's E10 / IPC-CFX code.
pub const CODE_POINT: &str = "machine_state_code";
/// The point with the reason the device gave, empty when none.
pub const REASON_POINT: &str = "machine_state_reason";

/// One state a device kind reports, with its code unless the config moves it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StateDef {
    /// The device's word (`parts exhausted`), as the `machine_state` point shows it and
    /// the config's `states` table names it.
    pub name: &'static str,
    /// Its E10 / IPC-CFX code (5500): a kind's test checks it is on the scale.
    pub code: u16,
}

impl StateDef {
    /// State `name` at `code`.
    pub const fn new(name: &'static str, code: u16) -> Self {
        Self { name, code }
    }
}

/// The codes the config gives some of a device's states (`states = { ready = 2200 }`),
/// checked against its kind's states when the file is read.
pub type StateOverrides = BTreeMap<String, StateCode>;

/// Checks a device's `states` table against its kind's states: each key a state of the
/// kind, each value a code of the scale. The error names the key and what is allowed.
pub fn check_overrides(
    kind: &str,
    states: &[StateDef],
    raw: &BTreeMap<String, i64>,
) -> Result<StateOverrides, String> {
    if states.is_empty() && !raw.is_empty() {
        return Err(format!(
            "{kind} devices report no machine states, so `states` has nothing to map"
        ));
    }
    let mut overrides = StateOverrides::new();
    for (name, code) in raw {
        if !states.iter().any(|s| s.name == name) {
            let names: Vec<String> = states.iter().map(|s| format!("{:?}", s.name)).collect();
            return Err(format!(
                "{kind} devices have no machine state {name:?}; their states: {}",
                names.join(", ")
            ));
        }
        let code = StateCode::new(*code).map_err(|e| format!("states.{name:?}: {e}"))?;
        overrides.insert(name.clone(), code);
    }
    Ok(overrides)
}

/// The id of `device`'s point `name`.
pub fn point_id(device: &DeviceId, name: &str) -> PointId {
    PointId::new(device, name).expect("the state points' names are valid point names")
}

/// One stretch of time in one state.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Interval {
    /// When it began (clipped to the range asked for).
    pub start: Timestamp,
    /// When it ended (clipped likewise).
    pub end: Timestamp,
    /// The device's word, `unknown` without data.
    pub state: String,
    /// Its E10 category.
    pub category: Category,
    /// Its code, 0 when unknown.
    pub code: StateCode,
    /// What the device gave as the reason, if anything; why there is no data, if unknown.
    pub reason: Option<String>,
}

impl Interval {
    /// Its length in milliseconds.
    pub fn millis(&self) -> i64 {
        self.end.0 - self.start.0
    }
}

/// What the history holds of a device's state points for a range: each point's change
/// in force at the start (`before`) and its changes in the range, oldest first.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StateSamples {
    /// `machine_state`.
    pub state: Changes,
    /// `machine_state_code`.
    pub code: Changes,
    /// `machine_state_reason`.
    pub reason: Changes,
}

/// One point's changes: the one in force at the range's start, then those in it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Changes {
    /// The last change before the range.
    pub before: Option<HistorySample>,
    /// The changes in the range, oldest first.
    pub during: Vec<HistorySample>,
}

/// Why an interval has no state: no data at all.
pub const NO_DATA: &str = "no data: the device was not polled or the gateway was not running";
/// Why an interval has no state: the device did not answer.
pub const NOT_ANSWERING: &str = "the device did not answer";

/// What the keeper stores, as a bad sample of the reason point, where the gateway's stop
/// began: the time up to the next change has no data, like time before the first poll
/// ([`super::keeper::close_gap`]).
pub const GATEWAY_DOWN: &str = "the gateway was not running";

/// The intervals of `[from, to)` that `samples` make: one per change of state, code or
/// reason, unknown where there is no good value. They cover the range without gaps.
pub fn intervals(samples: &StateSamples, from: Timestamp, to: Timestamp) -> Vec<Interval> {
    // Every moment one of the three changes, with its value then.
    let mut moments: Vec<Timestamp> = [&samples.state, &samples.code, &samples.reason]
        .iter()
        .flat_map(|c| c.during.iter().map(|s| s.t))
        .filter(|t| *t > from && *t < to)
        .collect();
    moments.push(from);
    moments.sort();
    moments.dedup();
    let series = [&samples.state, &samples.code, &samples.reason];
    let mut next = [0usize; 3];
    let mut out: Vec<Interval> = Vec::new();
    for (i, start) in moments.iter().enumerate() {
        let end = moments.get(i + 1).copied().unwrap_or(to);
        if end <= *start {
            continue;
        }
        // Each series' cursor moves past the changes up to this moment: one pass in all.
        let [state, code, reason] = [0, 1, 2].map(|k| {
            let changes = series[k];
            while next[k] < changes.during.len() && changes.during[next[k]].t <= *start {
                next[k] += 1;
            }
            let last = match next[k] {
                0 => changes.before.as_ref(),
                n => changes.during.get(n - 1),
            };
            held(last)
        });
        let interval = match (state, code) {
            (Held::Value(state), Held::Value(code)) => {
                let code = code
                    .as_number()
                    .map_or(StateCode::UNKNOWN, StateCode::of_number);
                Interval {
                    start: *start,
                    end,
                    state: match state {
                        Value::Text(t) => t.clone(),
                        other => other.to_string(),
                    },
                    category: code.category(),
                    code,
                    reason: match reason {
                        Held::Value(Value::Text(t)) if !t.is_empty() => Some(t.clone()),
                        _ => None,
                    },
                }
            }
            (state, code) => {
                let gateway_down =
                    matches!(reason, Held::Bad(Some(Value::Text(t))) if t == GATEWAY_DOWN);
                let answered = matches!(state, Held::Bad(_)) || matches!(code, Held::Bad(_));
                Interval {
                    start: *start,
                    end,
                    state: "unknown".into(),
                    category: Category::Unknown,
                    code: StateCode::UNKNOWN,
                    reason: Some(
                        if answered && !gateway_down {
                            NOT_ANSWERING
                        } else {
                            NO_DATA
                        }
                        .into(),
                    ),
                }
            }
        };
        match out.last_mut() {
            Some(last)
                if last.end == interval.start
                    && last.state == interval.state
                    && last.code == interval.code
                    && last.reason == interval.reason =>
            {
                last.end = interval.end;
            }
            _ => out.push(interval),
        }
    }
    out
}

/// What a point held at a moment.
enum Held<'a> {
    Nothing,
    /// A bad sample, with what it carries (the keeper's [`GATEWAY_DOWN`]).
    Bad(Option<&'a Value>),
    Value(&'a Value),
}

fn held(last: Option<&HistorySample>) -> Held<'_> {
    match last {
        None => Held::Nothing,
        Some(s) => match (&s.value, s.quality) {
            (Some(v), Quality::Good | Quality::Stale) => Held::Value(v),
            (value, _) => Held::Bad(value.as_ref()),
        },
    }
}

#[cfg(test)]
mod tests;
