//! The limit alarms at work: a task that reads the change stream, feeds each watched
//! point's values to its alarms' conditions, lets their delays run out, and records each
//! activation and clearing as an event (`alarm_raised`, `alarm_cleared`) with the alarm's
//! facts, which the history, MQTT, OPC UA and the page carry as they carry every event.
//! The deciding is sans IO ([`Watcher`]); the task only feeds it.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;

use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::registry::Registry;
use tokio::sync::{broadcast, watch};

use super::config::AlarmConfig;
use super::limit::{Condition, Level};
use super::state::{Alarm, Change};
use crate::cell::{Cell, LiveMessage};
use crate::event::{Event, EventKind};
use crate::point::{PointId, Quality, Value};
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
    /// Limit alarms whose condition is active, by priority.
    active: Family<PriorityLabels, Gauge>,
    /// Limit alarms waiting for an acknowledgement (active or returned), by priority.
    unacknowledged: Family<PriorityLabels, Gauge>,
}

impl AlarmMetrics {
    fn register(&self, registry: &mut Registry) {
        registry.register(
            "alarms_active",
            "Limit alarms whose condition is active, by priority",
            self.active.clone(),
        );
        registry.register(
            "alarms_unacknowledged",
            "Limit alarms waiting for an acknowledgement (active or returned to normal), by priority",
            self.unacknowledged.clone(),
        );
    }

    /// The gauges from the watcher's counts.
    fn set(&self, watcher: &Watcher) {
        for (priority, active, unacked) in watcher.counts() {
            let labels = PriorityLabels {
                priority: priority.as_str().to_owned(),
            };
            self.active.get_or_create(&labels).set(active);
            self.unacknowledged.get_or_create(&labels).set(unacked);
        }
    }
}

/// One limit alarm: its level's condition and its ISA-18.2 state.
#[derive(Debug)]
struct Watched {
    config: usize,
    condition: Condition,
    alarm: Alarm,
}

/// A condition that changed, for the event.
#[derive(Debug, Clone, PartialEq)]
pub struct Raised {
    /// Which `[[alarm]]` of the config (its index).
    pub config: usize,
    /// `point:level` (`meter1.active_power:high`).
    pub id: String,
    /// The point.
    pub point: PointId,
    /// Which limit.
    pub level: Level,
    /// Active now, or cleared.
    pub active: bool,
    /// The value that decided it (the last one seen, for a delay that ran out).
    pub value: Option<f64>,
    /// The limit crossed (the rate for a rate of change).
    pub limit: f64,
    /// What the ISA-18.2 state machine did with it.
    pub changes: Vec<Change>,
}

/// Every limit alarm of the cell, sans IO.
#[derive(Debug)]
pub struct Watcher {
    configs: Vec<AlarmConfig>,
    watched: Vec<Watched>,
    by_point: HashMap<PointId, Vec<usize>>,
}

impl Watcher {
    /// The alarms of `configs`, one per level each sets, all normal.
    pub fn new(configs: Vec<AlarmConfig>) -> Self {
        let mut watched = Vec::new();
        let mut by_point: HashMap<PointId, Vec<usize>> = HashMap::new();
        for (i, config) in configs.iter().enumerate() {
            for level in config.limits.levels() {
                by_point
                    .entry(config.point.clone())
                    .or_default()
                    .push(watched.len());
                watched.push(Watched {
                    config: i,
                    condition: Condition::new(level, config.limits),
                    alarm: Alarm::new(config.chatter),
                });
            }
        }
        Self {
            configs,
            watched,
            by_point,
        }
    }

    /// Per priority: alarms whose condition is active, and alarms waiting for an
    /// acknowledgement (ISA-18.2's unacknowledged and returned unacknowledged).
    pub fn counts(&self) -> Vec<(super::Priority, i64, i64)> {
        super::Priority::ALL
            .into_iter()
            .map(|priority| {
                let of = self
                    .watched
                    .iter()
                    .filter(|w| self.configs[w.config].priority == priority);
                let active = of.clone().filter(|w| w.alarm.state().active()).count();
                let unacked = of.filter(|w| w.alarm.state().unacknowledged()).count();
                (
                    priority,
                    i64::try_from(active).unwrap_or(i64::MAX),
                    i64::try_from(unacked).unwrap_or(i64::MAX),
                )
            })
            .collect()
    }

    /// Whether `point` is watched.
    pub fn watches(&self, point: &PointId) -> bool {
        self.by_point.contains_key(point)
    }

    /// The `[[alarm]]` a raised alarm comes from.
    pub fn config(&self, raised: &Raised) -> Option<&AlarmConfig> {
        self.configs.get(raised.config)
    }

    /// `point` read `value` at `t` (`None`: it has none, the device is not answering).
    pub fn value(&mut self, point: &PointId, value: Option<f64>, t: Timestamp) -> Vec<Raised> {
        let Some(indexes) = self.by_point.get(point) else {
            return Vec::new();
        };
        let mut out = Vec::new();
        for &i in indexes {
            let w = &mut self.watched[i];
            let changed = match value {
                Some(v) => w.condition.value(v, t),
                None => {
                    w.condition.no_value();
                    None
                }
            };
            if let Some(active) = changed {
                out.push(Self::raised(&self.configs, w, active, value, t));
            }
        }
        out
    }

    /// Time passes: delays that ran out, and shelvings.
    pub fn tick(&mut self, now: Timestamp) -> Vec<Raised> {
        let mut out = Vec::new();
        for w in &mut self.watched {
            w.alarm.tick(now);
            if let Some(active) = w.condition.tick(now) {
                let value = w.condition.last_value();
                out.push(Self::raised(&self.configs, w, active, value, now));
            }
        }
        out
    }

    fn raised(
        configs: &[AlarmConfig],
        w: &mut Watched,
        active: bool,
        value: Option<f64>,
        t: Timestamp,
    ) -> Raised {
        let config = &configs[w.config];
        let level = w.condition.level();
        let limits = &config.limits;
        let limit = match level {
            Level::HighHigh => limits.high_high,
            Level::High => limits.high,
            Level::Low => limits.low,
            Level::LowLow => limits.low_low,
            Level::RateOfChange => limits.rate_of_change,
        }
        .unwrap_or(f64::NAN);
        Raised {
            config: w.config,
            id: format!("{}:{}", config.point, level.as_str()),
            point: config.point.clone(),
            level,
            active,
            value,
            limit,
            changes: w.alarm.condition(active, t),
        }
    }
}

/// Runs the limit alarms of `configs` on `cell`'s change stream until `stop` turns true.
pub async fn run(cell: Arc<Cell>, configs: Vec<AlarmConfig>, mut stop: watch::Receiver<bool>) {
    if configs.is_empty() {
        return;
    }
    let mut watcher = Watcher::new(configs);
    let metrics = AlarmMetrics::default();
    cell.metrics()
        .register(|registry| metrics.register(registry));
    metrics.set(&watcher);
    let mut changes = cell.subscribe();
    let mut tick = tokio::time::interval(TICK);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        let raised = tokio::select! {
            _ = stop.changed() => break,
            _ = tick.tick() => watcher.tick(Timestamp::now()),
            message = changes.recv() => match message {
                Ok(LiveMessage::Value(view)) if watcher.watches(&view.id) => {
                    let value = match (view.quality, &view.value) {
                        (Some(Quality::Good | Quality::Stale), Some(v)) => v.as_number(),
                        _ => None,
                    };
                    watcher.value(&view.id, value, view.t.unwrap_or_else(Timestamp::now))
                }
                Err(broadcast::error::RecvError::Closed) => break,
                _ => Vec::new(),
            },
        };
        if !raised.is_empty() {
            metrics.set(&watcher);
        }
        for r in raised {
            emit(&cell, &watcher, &r);
        }
    }
}

/// Records a raised or cleared limit alarm as an event.
fn emit(cell: &Cell, watcher: &Watcher, r: &Raised) {
    let Some(entry) = cell.device_entry(r.point.device()) else {
        return;
    };
    let Some(config) = watcher.config(r) else {
        return;
    };
    let spec = cell.point(&r.point);
    let unit = spec.and_then(|s| s.unit.as_deref()).unwrap_or("");
    let what = config
        .message
        .clone()
        .or_else(|| spec.map(|s| s.name.to_string()))
        .unwrap_or_else(|| r.point.name().to_owned());
    let value = r.value.map_or_else(
        || "no value".to_owned(),
        |v| format!("{v} {unit}").trim().to_owned(),
    );
    let message = if r.active {
        format!(
            "{}: {what}: {} limit {} {unit} crossed, {value}",
            entry.label(),
            r.level.as_str().replace('_', "-"),
            r.limit
        )
    } else {
        format!(
            "{}: {what}: back within the {} limit, {value}",
            entry.label(),
            r.level.as_str().replace('_', "-")
        )
    };
    cell.emit(Event {
        t: Timestamp::now(),
        kind: if r.active {
            EventKind::AlarmRaised
        } else {
            EventKind::AlarmCleared
        },
        line: Some(entry.line.clone()),
        device: Some(entry.id.clone()),
        point: Some(r.point.clone()),
        message,
        fields: crate::event::fields([
            ("alarm", serde_json::json!(r.id)),
            ("level", serde_json::json!(r.level.as_str())),
            ("limit", serde_json::json!(r.limit)),
            ("value", serde_json::json!(r.value.map(Value::Number))),
            ("priority", serde_json::json!(config.priority.as_str())),
            ("category", serde_json::json!(config.category)),
            (
                "changes",
                serde_json::json!(r.changes.iter().map(|c| c.as_str()).collect::<Vec<_>>()),
            ),
        ]),
    });
}

#[cfg(test)]
mod tests;
