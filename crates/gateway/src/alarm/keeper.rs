//! The alarms at work: a task that reads the change stream, feeds each watched point's
//! values and each device's going down and coming back to the cell's [`Book`], lets
//! delays and shelvings run out, and records every change of every alarm as an event, the
//! alarm journal: `alarm_raised` (activated), `alarm_cleared` (returned to normal) and
//! `alarm_changed` (acknowledged, shelved, unshelved, a shelving that ran out), each with
//! the alarm's facts and its state after the change, and who did it with the comment for
//! an operator's action ([`act`]). The history, MQTT, OPC UA and the page carry them as
//! they carry every event; the history also keeps each alarm's last entry, from which
//! [`restore`] puts the alarms back after a restart (also after `kill -9`). The deciding is
//! sans IO ([`Book`]); the task only feeds it.

use std::sync::Arc;
use std::time::Duration;

use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::registry::Registry;
use tokio::sync::{broadcast, watch};

use super::book::{ActError, Action, Book, Happened, Source, View};
use super::state::Change;
use crate::cell::{Cell, DeviceStatus, LiveMessage};
use crate::event::{Event, EventKind};
use crate::point::{Quality, Value};
use crate::time::Timestamp;

/// How often the delays are looked at.
const TICK: Duration = Duration::from_millis(250);

/// Labels of the alarm gauges.
#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
struct PriorityLabels {
    priority: String,
}

/// The keeper's metrics, registered when it starts.
#[derive(Debug, Default)]
struct AlarmMetrics {
    /// Alarms whose condition is active, by priority.
    active: Family<PriorityLabels, Gauge>,
    /// Alarms waiting for an acknowledgement (active or returned), by priority.
    unacknowledged: Family<PriorityLabels, Gauge>,
}

impl AlarmMetrics {
    fn register(&self, registry: &mut Registry) {
        registry.register(
            "alarms_active",
            "Alarms whose condition is active, by priority",
            self.active.clone(),
        );
        registry.register(
            "alarms_unacknowledged",
            "Alarms waiting for an acknowledgement (active or returned to normal), by priority",
            self.unacknowledged.clone(),
        );
    }

    /// The gauges from the book's counts.
    fn set(&self, book: &Book) {
        for counts in book.counts() {
            let labels = PriorityLabels {
                priority: counts.priority.as_str().to_owned(),
            };
            let gauge = |n: u64| i64::try_from(n).unwrap_or(i64::MAX);
            self.active.get_or_create(&labels).set(gauge(counts.active));
            self.unacknowledged
                .get_or_create(&labels)
                .set(gauge(counts.unacknowledged));
        }
    }
}

/// Runs the cell's alarms on its change stream until `stop` turns true: follows values,
/// devices, time and reloads of the configuration (`serve` has put back what the history kept of each, [`restore`],
/// before the polls and the interfaces started).
pub async fn run(cell: Arc<Cell>, mut stop: watch::Receiver<bool>) {
    let metrics = AlarmMetrics::default();
    cell.metrics()
        .register(|registry| metrics.register(registry));
    let mut changes = cell.subscribe();
    let mut seen = u64::MAX;
    let happened = resync(&cell);
    record(&cell, &happened);
    let mut tick = tokio::time::interval(TICK);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        let happened = tokio::select! {
            _ = stop.changed() => break,
            _ = tick.tick() => cell.alarms.with(|book| book.tick(Timestamp::now())),
            message = changes.recv() => match message {
                Ok(LiveMessage::Value(view)) => {
                    let value = match view.quality {
                        Some(Quality::Good | Quality::Stale) => view.value.as_ref(),
                        _ => None,
                    };
                    let t = view.t.unwrap_or_else(Timestamp::now);
                    cell.alarms.with(|book| {
                        if book.watches(&view.id) {
                            book.value(&view.id, value, t)
                        } else {
                            Vec::new()
                        }
                    })
                }
                Ok(LiveMessage::Event(event)) => match (event.kind, &event.device) {
                    (EventKind::DeviceDown | EventKind::DeviceUp, Some(device)) => {
                        let down = event.kind == EventKind::DeviceDown;
                        let why = event.fields.get("error").and_then(|e| e.as_str());
                        cell.alarms
                            .with(|book| book.down(device, down, why, event.t))
                            .into_iter()
                            .collect()
                    }
                    // The alarms were replaced: the current values say where the new ones are.
                    (EventKind::ConfigReloaded, _) => resync(&cell),
                    _ => Vec::new(),
                },
                // Changes were missed: the cell's current values say where each alarm is.
                Err(broadcast::error::RecvError::Lagged(_)) => resync(&cell),
                Err(broadcast::error::RecvError::Closed) => break,
                Ok(_) => Vec::new(),
            },
        };
        record(&cell, &happened);
        let generation = cell.alarms.with(|book| book.generation());
        if generation != seen {
            seen = generation;
            cell.alarms.with(|book| metrics.set(book));
        }
    }
}

/// Puts each alarm back as its last journal entry left it: once, at the start, before
/// anything reads or feeds the alarms (the polls, the interfaces' births and address
/// spaces).
pub async fn restore(cell: &Cell) {
    let store = cell.store().clone();
    let saved = tokio::task::spawn_blocking(move || store.alarm_states())
        .await
        .map_err(|e| e.to_string())
        .and_then(|r| r.map_err(|e| e.to_string()));
    match saved {
        Ok(saved) => {
            let now = Timestamp::now();
            let restored = cell.alarms.with(|book| {
                saved
                    .iter()
                    .filter(|(id, fields)| book.restore(id, fields, now))
                    .count()
            });
            if restored > 0 {
                tracing::info!("{restored} alarms restored as the history kept them");
            }
        }
        Err(e) => tracing::warn!("the alarms' states could not be read back: {e}"),
    }
}

/// Feeds the book the cell's current values and device states (at start, and after the
/// change stream lagged).
fn resync(cell: &Cell) -> Vec<Happened> {
    let now = Timestamp::now();
    let points: Vec<_> = cell.alarms.with(|book| book.points().cloned().collect());
    let mut out = Vec::new();
    for point in points {
        let Some(entry) = cell.device_entry(point.device()) else {
            continue;
        };
        let Some(index) = entry.point_index(point.name()) else {
            continue;
        };
        let (value, t) = {
            let state = entry.read();
            let Some(p) = state.points.get(index) else {
                continue;
            };
            let value = match p.quality {
                Some(Quality::Good | Quality::Stale) => p.value.clone(),
                _ => None,
            };
            (value, p.t.unwrap_or(now))
        };
        out.extend(
            cell.alarms
                .with(|book| book.value(&point, value.as_ref(), t)),
        );
    }
    for entry in cell.device_entries() {
        let (down, why) = {
            let state = entry.read();
            let down = match state.status {
                DeviceStatus::Down => true,
                DeviceStatus::Up => false,
                // Not polled yet (at start): nothing said either way.
                DeviceStatus::Connecting => continue,
            };
            (down, state.error.as_ref().map(|e| e.message.clone()))
        };
        out.extend(
            cell.alarms
                .with(|book| book.down(&entry.id, down, why.as_deref(), now)),
        );
    }
    out
}

/// An operator's action on alarm `id`, by `by` (`anna from 10.0.0.7:50312`, `opcua user
/// anna`, `mqtt DCMD …`) with a comment: applied, journalled, and committed to the
/// history before this returns. The alarm as it is now, or why nothing was done.
pub async fn act(
    cell: &Cell,
    id: &str,
    action: Action,
    by: &str,
    comment: Option<&str>,
) -> Result<View, ActError> {
    let by = crate::write::cut(by, crate::write::MAX_NAME);
    let comment = comment.map(|c| crate::write::cut(c, MAX_COMMENT));
    let happened = cell
        .alarms
        .with(|book| book.act(id, action, Timestamp::now(), &by, comment.as_deref()))?;
    let index = happened.index;
    record(cell, std::slice::from_ref(&happened));
    if let Err(e) = cell.store().flush().await {
        tracing::error!("alarm journal entry not committed: {e}");
    }
    cell.alarms
        .with(|book| book.view(index))
        .ok_or(ActError::Unknown { id: id.to_owned() })
}

/// Longest comment kept with an operator's action.
pub const MAX_COMMENT: usize = 1024;

/// Journals each change: one event each.
fn record(cell: &Cell, happened: &[Happened]) {
    for h in happened {
        if let Some(event) = cell.alarms.with(|book| journal_entry(cell, book, h)) {
            cell.emit(event);
        }
    }
}

/// The journal entry (an event) of one change.
fn journal_entry(cell: &Cell, book: &Book, h: &Happened) -> Option<Event> {
    let instance = book.instance(h.index)?;
    let view = book.view(h.index)?;
    let entry = cell.device_entry(instance.device.as_str());
    let spec_ref = instance.point.as_ref().and_then(|p| cell.point(p));
    let spec = spec_ref.as_deref();
    let unit = spec.and_then(|s| s.unit.as_deref()).unwrap_or("");
    let shown = |value: &Option<serde_json::Value>| match value {
        None | Some(serde_json::Value::Null) => "no value".to_owned(),
        Some(v) => {
            let value: Option<Value> = serde_json::from_value(v.clone()).ok();
            match (spec, &value) {
                (Some(spec), Some(value)) if spec.label(value).is_some() => {
                    spec.label(value).unwrap_or_default().to_owned()
                }
                (_, Some(Value::Text(text))) => text.clone(),
                (_, Some(value)) => format!("{value} {unit}").trim().to_owned(),
                (_, None) => v.to_string(),
            }
        }
    };
    let who = instance.device_label.as_str();
    let what = instance.message.as_str();
    let level = instance.level.map(|l| l.as_str().replace('_', "-"));
    let limit = instance
        .limit
        .map_or_else(String::new, |l| format!("{l} {unit}"));
    let mut message = if h.activated() {
        match instance.source {
            Source::Limit => format!(
                "{who}: {what}: {} limit {} crossed, {}",
                level.unwrap_or_default(),
                limit.trim(),
                shown(&instance.value)
            ),
            Source::Device => format!("{who}: {what} is {}", shown(&instance.value)),
            Source::Down => format!("{who}: not answering ({})", shown(&instance.value)),
        }
    } else if h.cleared() {
        match instance.source {
            Source::Limit => format!(
                "{who}: {what}: back within the {} limit, {}",
                level.unwrap_or_default(),
                shown(&instance.last_value)
            ),
            Source::Device => format!("{who}: {what} back to {}", shown(&instance.last_value)),
            Source::Down => format!("{who}: answering again"),
        }
    } else {
        format!("{who}: {what}")
    };
    for change in &h.changes {
        let words = match change {
            Change::Activated | Change::Cleared => continue,
            Change::Acknowledged => "acknowledged".to_owned(),
            Change::Shelved => format!("shelved until {}", until(&view)),
            Change::ShelvedForChattering => format!(
                "chattering ({} activations); shelved until {}",
                view.count,
                until(&view)
            ),
            Change::Unshelved => "unshelved".to_owned(),
            Change::ShelveExpired => "its shelving ran out".to_owned(),
            Change::RemovedFromService => "taken out of service".to_owned(),
            Change::ReturnedToService => "back in service".to_owned(),
        };
        message.push_str("; ");
        message.push_str(&words);
    }
    if let Some(by) = &h.by {
        message.push_str(&format!(" by {by}"));
    }
    if let Some(comment) = h.comment.as_deref().filter(|c| !c.is_empty()) {
        message.push_str(&format!(": {comment}"));
    }
    let kind = if h.activated() {
        EventKind::AlarmRaised
    } else if h.cleared() {
        EventKind::AlarmCleared
    } else {
        EventKind::AlarmChanged
    };
    let serde_json::Value::Object(mut fields) = serde_json::json!(view) else {
        return None;
    };
    fields.remove("id");
    fields.remove("device");
    fields.remove("point");
    fields.insert("alarm".into(), serde_json::json!(view.id));
    fields.insert(
        "changes".into(),
        serde_json::json!(h.changes.iter().map(|c| c.as_str()).collect::<Vec<_>>()),
    );
    if instance.source == Source::Device
        && let (Some(spec), Some(value)) = (spec, &instance.last_value)
        && let Ok(value) = serde_json::from_value::<Value>(value.clone())
    {
        fields.insert("label".into(), serde_json::json!(spec.label(&value)));
    }
    if h.cleared() {
        fields.insert(
            "value".into(),
            instance.last_value.clone().unwrap_or_default(),
        );
    }
    if let Some(by) = &h.by {
        fields.insert("by".into(), serde_json::json!(by));
    }
    if let Some(comment) = &h.comment {
        fields.insert("comment".into(), serde_json::json!(comment));
    }
    Some(Event {
        t: h.t,
        kind,
        line: entry.map(|e| e.line.clone()),
        device: Some(instance.device.clone()),
        point: instance.point.clone(),
        message,
        fields: fields.into_iter().collect(),
    })
}

/// When a shelving ends, in words.
fn until(view: &View) -> String {
    view.shelved_until
        .map_or_else(|| "further notice".to_owned(), |t| t.to_string())
}

#[cfg(test)]
mod tests;
