//! A range's states and production from the history: what `/api/states` and
//! `/api/production` answer, and the keeper's current-shift OEE.

use serde::Serialize;

use super::oee::{self, Counts, IdealCycle, Oee, StateTime};
use super::shift::ShiftWindow;
use super::states::{self, Changes, Interval, StateSamples};
use super::{Plan, Producer};
use crate::event::EventKind;
use crate::point::{DeviceId, PointId, Value};
use crate::store::{EventFilter, PageOrder, StoreError, StoreHandle};
use crate::time::Timestamp;

/// Most changes of one point read for one range: 30 days of a state changing every
/// 10 s. A range with more is answered from the first ones.
const MAX_CHANGES: usize = 260_000;

/// Changes read per page.
const PAGE: usize = 5_000;

/// Most board events read for the best cycle of a range.
const MAX_CYCLE_EVENTS: usize = 100_000;

/// A device's states over a range (`/api/states`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StatesReport {
    /// The device.
    pub device: DeviceId,
    /// Start of the range.
    pub from: Timestamp,
    /// End of the range (now, for a range that has not ended).
    pub to: Timestamp,
    /// The intervals, covering the range.
    pub intervals: Vec<Interval>,
}

/// A device's production over a range (`/api/production`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// The device.
    pub device: DeviceId,
    /// Start of the range.
    pub from: Timestamp,
    /// End of the range (now, for a range that has not ended).
    pub to: Timestamp,
    /// The shift asked for, if one was.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shift: Option<ShiftWindow>,
    /// Planned production seconds in the range that have data.
    pub planned_s: f64,
    /// Planned seconds without data (before the first poll, the gateway not running): left
    /// out of `planned_s`, still in `states` as unknown.
    pub unobserved_s: f64,
    /// Seconds per state; they add up to the range.
    pub states: Vec<StateTime>,
    /// OEE and its parts, for a device that counts production.
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub production: Option<Oee>,
}

/// The intervals of `device` in `[from, to)`, `to` no later than `now`.
pub fn states(
    store: &StoreHandle,
    device: &DeviceId,
    from: Timestamp,
    to: Timestamp,
    now: Timestamp,
) -> Result<StatesReport, StoreError> {
    let to = to.min(now).max(from);
    let samples = state_samples(store, device, from, to)?;
    Ok(StatesReport {
        device: device.clone(),
        from,
        to,
        intervals: states::intervals(&samples, from, to),
    })
}

/// The production report of `device` for `[from, to)` (`to` no later than `now`).
pub fn production(
    store: &StoreHandle,
    plan: &Plan,
    device: &DeviceId,
    (from, to): (Timestamp, Timestamp),
    shift: Option<ShiftWindow>,
    now: Timestamp,
) -> Result<Report, StoreError> {
    let to = to.min(now).max(from);
    let intervals = states::intervals(&state_samples(store, device, from, to)?, from, to);
    let planned = plan.shifts.planned(from, to);
    let producer = plan.producers.get(device);
    let micro = producer.and_then(|p| p.settings.micro_stop);
    let breakdown = oee::breakdown(&intervals, &planned, micro);
    let production = match producer {
        Some(producer) => {
            let counts = counts(store, device, producer, from, to)?;
            let ideal = ideal_cycle(store, device, producer, from, to)?;
            let elapsed = breakdown.planned_s;
            Some(oee::oee(&breakdown, &counts, &ideal, elapsed))
        }
        None => None,
    };
    Ok(Report {
        device: device.clone(),
        from,
        to,
        shift,
        planned_s: breakdown.planned_s,
        unobserved_s: breakdown.unobserved_s,
        states: breakdown.states,
        production,
    })
}

/// The state points' changes of `device` for `[from, to)`.
fn state_samples(
    store: &StoreHandle,
    device: &DeviceId,
    from: Timestamp,
    to: Timestamp,
) -> Result<StateSamples, StoreError> {
    let read = |name| changes(store, &states::point_id(device, name), from, to);
    Ok(StateSamples {
        state: read(states::STATE_POINT)?,
        code: read(states::CODE_POINT)?,
        reason: read(states::REASON_POINT)?,
    })
}

/// `point`'s change in force at `from` and its changes in `[from, to)`.
fn changes(
    store: &StoreHandle,
    point: &PointId,
    from: Timestamp,
    to: Timestamp,
) -> Result<Changes, StoreError> {
    let before = store.history_nearest(point, Timestamp(from.0 - 1), false)?;
    let mut during = Vec::new();
    let mut after = None;
    while during.len() < MAX_CHANGES {
        let page = store.history_page(point, from, to, PageOrder::OldestFirst, after, PAGE)?;
        let full = page.len() == PAGE;
        after = page.last().map(|(cursor, _)| *cursor);
        during.extend(page.into_iter().map(|(_, sample)| sample));
        if !full {
            break;
        }
    }
    Ok(Changes { before, during })
}

/// A counter's good values: the one in force at `from`, then its changes in the range.
fn counter(
    store: &StoreHandle,
    point: &PointId,
    from: Timestamp,
    to: Timestamp,
) -> Result<Option<f64>, StoreError> {
    let changes = changes(store, point, from, to)?;
    let values = changes
        .before
        .iter()
        .chain(&changes.during)
        .filter_map(|s| s.value.as_ref().and_then(Value::as_number));
    Ok(oee::increase(values))
}

fn counts(
    store: &StoreHandle,
    device: &DeviceId,
    producer: &Producer,
    from: Timestamp,
    to: Timestamp,
) -> Result<Counts, StoreError> {
    let point = |name: &str| states::point_id(device, name);
    let optional = |name: Option<&str>| -> Result<Option<f64>, StoreError> {
        match name {
            Some(name) => counter(store, &point(name), from, to),
            None => Ok(None),
        }
    };
    let machine_plan = match producer.points.planned {
        Some(name) => store
            .history_nearest(&point(name), Timestamp(to.0 - 1), false)?
            .and_then(|s| s.value)
            .and_then(|v| v.as_number()),
        None => None,
    };
    let good_boards = match &producer.settings.good_boards {
        Some(good) => counter(store, good, from, to)?,
        None => None,
    };
    Ok(Counts {
        boards: counter(store, &point(producer.points.boards), from, to)?,
        good_boards,
        pickups: optional(producer.points.pickups)?,
        placed: optional(producer.points.placed)?,
        machine_plan,
    })
}

/// The ideal cycle for the range: the config's for the program selected at its end, else
/// the config's default, else the best cycle the machine reported in it.
fn ideal_cycle(
    store: &StoreHandle,
    device: &DeviceId,
    producer: &Producer,
    from: Timestamp,
    to: Timestamp,
) -> Result<IdealCycle, StoreError> {
    let settings = &producer.settings;
    if let Some(name) = producer.points.program
        && !settings.ideal_cycle_by_program.is_empty()
    {
        let program = store
            .history_nearest(&states::point_id(device, name), Timestamp(to.0 - 1), false)?
            .and_then(|s| s.value);
        if let Some(Value::Text(program)) = program
            && let Some(cycle) = settings.ideal_cycle_by_program.get(program.trim())
        {
            return Ok(IdealCycle::Configured {
                seconds: cycle.as_secs_f64(),
                program: Some(program.trim().to_owned()),
            });
        }
    }
    if let Some(cycle) = settings.ideal_cycle {
        return Ok(IdealCycle::Configured {
            seconds: cycle.as_secs_f64(),
            program: None,
        });
    }
    let Some((event, field)) = producer.points.cycle_event else {
        return Ok(IdealCycle::Unknown);
    };
    let events = store.events(&EventFilter {
        from: Some(from),
        to: Some(to),
        device: Some(device.to_string()),
        kind: Some(EventKind::DeviceEvent),
        limit: MAX_CYCLE_EVENTS,
    })?;
    let best = events
        .iter()
        .filter(|e| e.fields.get("event").and_then(|v| v.as_str()) == Some(event))
        .filter_map(|e| e.fields.get(field).and_then(serde_json::Value::as_f64))
        .filter(|s| *s > 0.0)
        .min_by(f64::total_cmp);
    Ok(best.map_or(IdealCycle::Unknown, IdealCycle::BestSeen))
}
