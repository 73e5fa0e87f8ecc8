//! Every alarm of the cell in one model, sans IO: the limit alarms of the config, the
//! devices' own alarms (a point whose [`AlarmRule`](crate::point::AlarmRule) says its value
//! is one: a regulator fault, a CROSS alarm list, a tool error, a machine's error stop) and
//! each device not answering. Each is an [`Instance`] with its ISA-18.2 [`Alarm`] state;
//! conditions, time and operators' actions come in, and each change comes out as a
//! [`Happened`] for the journal (an event) and the interfaces.
//!
//! Ids: a limit alarm is `point:level` (`sealer0.temperature:high`), a device's own alarm
//! its point's id (`sealer0.fault`), a device not answering `device:down`.

use std::collections::HashMap;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::Priority;
use super::config::AlarmConfig;
use super::limit::{Condition, Level};
use super::state::{Alarm, Change, Refused, State};
use crate::point::{DeviceId, PointId, PointSpec, Value};
use crate::time::Timestamp;

/// The priority of the devices' own alarms and of a device not answering.
pub const DEVICE_PRIORITY: Priority = Priority::High;

/// Where an alarm comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Source {
    /// A limit of the config on a numeric point.
    Limit,
    /// The device's own alarm or fault, read from a point.
    Device,
    /// The device does not answer.
    Down,
}

/// A device as the book needs it: its id, its name for people, and its points that carry
/// an alarm rule.
#[derive(Debug, Clone)]
pub struct DeviceAlarms {
    /// The device.
    pub device: DeviceId,
    /// Its name for people (`Sealer 0`).
    pub label: String,
    /// Its points with an alarm rule.
    pub rule_points: Vec<PointSpec>,
}

/// One alarm: what it watches, its words, and its state.
#[derive(Debug)]
pub struct Instance {
    /// Its id (module docs).
    pub id: String,
    /// Where it comes from.
    pub source: Source,
    /// The device it belongs to.
    pub device: DeviceId,
    /// The device's name for people.
    pub device_label: String,
    /// The point it watches (none for a device not answering).
    pub point: Option<PointId>,
    /// A limit alarm's level.
    pub level: Option<Level>,
    /// A limit alarm's limit (the rate for a rate of change).
    pub limit: Option<f64>,
    /// Its priority.
    pub priority: Priority,
    /// Words for the operator.
    pub message: String,
    /// `device` for the devices' own, else the config's category, if any.
    pub category: Option<String>,
    /// Its ISA-18.2 state.
    pub alarm: Alarm,
    /// The value at its last activation (a device not answering: the error).
    pub value: Option<serde_json::Value>,
    /// The value last seen (what a clearing reports).
    pub last_value: Option<serde_json::Value>,
    /// A limit alarm's condition with its delays and deadband.
    condition: Option<Condition>,
    /// A device alarm's rule, through its point's spec.
    spec: Option<PointSpec>,
}

/// What an operator asks of an alarm.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Action {
    /// Acknowledge it.
    Acknowledge,
    /// Shelve it for this long.
    Shelve(Duration),
    /// Unshelve it.
    Unshelve,
    /// Take it out of service (`true`: maintenance; it is not annunciated whatever its
    /// condition) or return it to service (`false`).
    OutOfService(bool),
}

impl Action {
    /// Its name in the API (`ack`).
    pub fn as_str(self) -> &'static str {
        match self {
            Action::Acknowledge => "ack",
            Action::Shelve(_) => "shelve",
            Action::Unshelve => "unshelve",
            Action::OutOfService(true) => "out_of_service",
            Action::OutOfService(false) => "in_service",
        }
    }
}

/// Why an action was not taken.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ActError {
    /// No alarm has this id.
    #[error("no alarm {id:?}; GET /api/alarms lists them")]
    Unknown {
        /// The id asked for.
        id: String,
    },
    /// The action does not apply to the alarm as it is.
    #[error("alarm {id}: {refused}")]
    Refused {
        /// The alarm.
        id: String,
        /// Why.
        refused: Refused,
    },
}

/// One change of one alarm, for the journal.
#[derive(Debug, Clone, PartialEq)]
pub struct Happened {
    /// Which instance (its index in the book).
    pub index: usize,
    /// When.
    pub t: Timestamp,
    /// What the state machine did.
    pub changes: Vec<Change>,
    /// Who did it, for an operator's action.
    pub by: Option<String>,
    /// The operator's comment.
    pub comment: Option<String>,
}

impl Happened {
    /// Whether the condition became active.
    pub fn activated(&self) -> bool {
        self.changes.contains(&Change::Activated)
    }

    /// Whether the condition cleared.
    pub fn cleared(&self) -> bool {
        self.changes.contains(&Change::Cleared)
    }
}

/// An alarm as the API, the page and the journal show it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct View {
    /// Its id.
    pub id: String,
    /// Where it comes from.
    pub source: Source,
    /// The device.
    pub device: DeviceId,
    /// The point, if it watches one.
    pub point: Option<PointId>,
    /// A limit alarm's level.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub level: Option<Level>,
    /// A limit alarm's limit.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub limit: Option<f64>,
    /// Its priority.
    pub priority: Priority,
    /// Words for the operator.
    pub message: String,
    /// Its category.
    pub category: Option<String>,
    /// Its ISA-18.2 state.
    pub state: State,
    /// Whether its condition is active.
    pub active: bool,
    /// Whether nobody needs to acknowledge it.
    pub acknowledged: bool,
    /// Until when it is shelved.
    pub shelved_until: Option<Timestamp>,
    /// Whether it is out of service.
    pub out_of_service: bool,
    /// When it first became active since it was last normal.
    pub first_active: Option<Timestamp>,
    /// When it last became active.
    pub last_active: Option<Timestamp>,
    /// The value at its last activation.
    pub value: Option<serde_json::Value>,
    /// Activations kept.
    pub count: u64,
    /// Times it was found chattering.
    pub chattered: u64,
}

/// Which alarms a list shows.
#[derive(Debug, Clone, Default)]
pub struct ListFilter {
    /// Only this device's.
    pub device: Option<String>,
    /// Only this priority.
    pub priority: Option<Priority>,
    /// Skip this many (the list is sorted: most urgent, then newest, first).
    pub offset: usize,
    /// At most this many.
    pub limit: usize,
}

/// A page of the alarm list.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Page {
    /// The alarms of the page.
    pub alarms: Vec<View>,
    /// How many match the filter in all.
    pub total: usize,
}

/// An alarm's state as its last journal entry saved it, to be restored after a restart.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct Saved {
    /// The state.
    pub state: State,
    /// The condition.
    pub active: bool,
    /// Until when it was shelved.
    #[serde(default)]
    pub shelved_until: Option<String>,
    /// Out of service.
    #[serde(default)]
    pub out_of_service: bool,
    /// First activation since normal.
    #[serde(default)]
    pub first_active: Option<String>,
    /// Last activation.
    #[serde(default)]
    pub last_active: Option<String>,
    /// The value at activation.
    #[serde(default)]
    pub value: Option<serde_json::Value>,
    /// Activations.
    #[serde(default)]
    pub count: u64,
    /// Chatterings.
    #[serde(default)]
    pub chattered: u64,
}

/// Every alarm of the cell.
#[derive(Debug, Default)]
pub struct Book {
    instances: Vec<Instance>,
    by_id: HashMap<String, usize>,
    by_point: HashMap<PointId, Vec<usize>>,
    down_of: HashMap<DeviceId, usize>,
    /// Grows with every change, so a reader knows when to look again.
    generation: u64,
}

impl Book {
    /// The alarms of `configs` (one per level each sets) and of `devices` (one per rule
    /// point, one for not answering), all normal. `labels` names each limit alarm's device.
    pub fn new(configs: &[AlarmConfig], devices: &[DeviceAlarms]) -> Self {
        let mut book = Book::default();
        let label_of = |device: &DeviceId| {
            devices
                .iter()
                .find(|d| &d.device == device)
                .map_or_else(|| device.to_string(), |d| d.label.clone())
        };
        for config in configs {
            for level in config.limits.levels() {
                let l = &config.limits;
                let limit = match level {
                    Level::HighHigh => l.high_high,
                    Level::High => l.high,
                    Level::Low => l.low,
                    Level::LowLow => l.low_low,
                    Level::RateOfChange => l.rate_of_change,
                };
                let Ok(device) = DeviceId::new(config.point.device()) else {
                    continue;
                };
                book.add(Instance {
                    id: format!("{}:{}", config.point, level.as_str()),
                    source: Source::Limit,
                    device_label: label_of(&device),
                    device,
                    point: Some(config.point.clone()),
                    level: Some(level),
                    limit,
                    priority: config.priority,
                    message: config.message.clone().unwrap_or_else(|| {
                        format!(
                            "{} {}",
                            config.point.name(),
                            level.as_str().replace('_', "-")
                        )
                    }),
                    category: config.category.clone(),
                    alarm: Alarm::new(config.chatter),
                    value: None,
                    last_value: None,
                    condition: Some(Condition::new(level, config.limits)),
                    spec: None,
                });
            }
        }
        for d in devices {
            for spec in &d.rule_points {
                book.add(Instance {
                    id: spec.id.to_string(),
                    source: Source::Device,
                    device: d.device.clone(),
                    device_label: d.label.clone(),
                    point: Some(spec.id.clone()),
                    level: None,
                    limit: None,
                    priority: DEVICE_PRIORITY,
                    message: spec.name.to_string(),
                    category: Some("device".to_owned()),
                    alarm: Alarm::new(None),
                    value: None,
                    last_value: None,
                    condition: None,
                    spec: Some(spec.clone()),
                });
            }
            let index = book.add(Instance {
                id: format!("{}:down", d.device),
                source: Source::Down,
                device: d.device.clone(),
                device_label: d.label.clone(),
                point: None,
                level: None,
                limit: None,
                priority: DEVICE_PRIORITY,
                message: "Not answering".to_owned(),
                category: Some("device".to_owned()),
                alarm: Alarm::new(None),
                value: None,
                last_value: None,
                condition: None,
                spec: None,
            });
            book.down_of.insert(d.device.clone(), index);
        }
        book
    }

    fn add(&mut self, instance: Instance) -> usize {
        let index = self.instances.len();
        self.by_id.insert(instance.id.clone(), index);
        if let Some(point) = &instance.point {
            self.by_point.entry(point.clone()).or_default().push(index);
        }
        self.instances.push(instance);
        index
    }

    /// How many alarms it keeps.
    pub fn len(&self) -> usize {
        self.instances.len()
    }

    /// Whether it keeps none.
    pub fn is_empty(&self) -> bool {
        self.instances.is_empty()
    }

    /// Grows with every change.
    pub fn generation(&self) -> u64 {
        self.generation
    }

    /// An alarm by index.
    pub fn instance(&self, index: usize) -> Option<&Instance> {
        self.instances.get(index)
    }

    /// An alarm's index by id.
    pub fn index_of(&self, id: &str) -> Option<usize> {
        self.by_id.get(id).copied()
    }

    /// Whether `point` has alarms.
    pub fn watches(&self, point: &PointId) -> bool {
        self.by_point.contains_key(point)
    }

    /// Every point with alarms.
    pub fn points(&self) -> impl Iterator<Item = &PointId> {
        self.by_point.keys()
    }

    /// `point` now reads `value` (`None`: it has no good value; the device stopped
    /// answering): the alarms it decides, limit and device alike.
    pub fn value(&mut self, point: &PointId, value: Option<&Value>, t: Timestamp) -> Vec<Happened> {
        // Read by position: the point's list stays as it is, and a change of a watched point
        // (thousands a second in a large cell) allocates nothing to look it up.
        let watching = self.by_point.get(point).map_or(0, Vec::len);
        if watching == 0 {
            return Vec::new();
        }
        let json = value.map(|v| serde_json::json!(v));
        let mut out = Vec::new();
        for k in 0..watching {
            let i = self.by_point[point][k];
            let instance = &mut self.instances[i];
            let active = match (&mut instance.condition, &instance.spec) {
                (Some(condition), _) => match value.and_then(Value::as_number) {
                    Some(n) => condition.value(n, t),
                    None => {
                        condition.no_value();
                        None
                    }
                },
                // A device's alarm holds while it has no value: the device being down is
                // its own alarm.
                (None, Some(spec)) => value.map(|v| spec.is_alarm(v)),
                (None, None) => None,
            };
            if json.is_some() {
                instance.last_value = json.clone();
            }
            if let Some(active) = active
                && let Some(h) = self.condition(i, active, t)
            {
                out.push(h);
            }
        }
        out
    }

    /// `device` is answering (`false`) or not (`true`, with why).
    pub fn down(
        &mut self,
        device: &DeviceId,
        down: bool,
        why: Option<&str>,
        t: Timestamp,
    ) -> Option<Happened> {
        let i = *self.down_of.get(device)?;
        self.instances[i].last_value = why.map(|w| serde_json::json!(w));
        self.condition(i, down, t)
    }

    /// Instance `index`'s condition is `active` at `t`.
    fn condition(&mut self, index: usize, active: bool, t: Timestamp) -> Option<Happened> {
        let instance = &mut self.instances[index];
        let changes = instance.alarm.condition(active, t);
        if changes.is_empty() {
            return None;
        }
        if active {
            instance.value = instance.last_value.clone();
        }
        self.generation += 1;
        Some(Happened {
            index,
            t,
            changes,
            by: None,
            comment: None,
        })
    }

    /// Time passes: delays that ran out, shelvings that ended.
    pub fn tick(&mut self, now: Timestamp) -> Vec<Happened> {
        let mut out = Vec::new();
        for index in 0..self.instances.len() {
            let instance = &mut self.instances[index];
            if let Some(change) = instance.alarm.tick(now) {
                self.generation += 1;
                out.push(Happened {
                    index,
                    t: now,
                    changes: vec![change],
                    by: None,
                    comment: None,
                });
            }
            let instance = &mut self.instances[index];
            let ran_out = instance.condition.as_mut().and_then(|c| {
                let active = c.tick(now)?;
                Some((active, c.last_value()))
            });
            if let Some((active, value)) = ran_out {
                if let Some(v) = value {
                    instance.last_value = Some(serde_json::json!(v));
                }
                out.extend(self.condition(index, active, now));
            }
        }
        out
    }

    /// An operator's action on alarm `id` at `now`.
    pub fn act(
        &mut self,
        id: &str,
        action: Action,
        now: Timestamp,
        by: &str,
        comment: Option<&str>,
    ) -> Result<Happened, ActError> {
        let Some(index) = self.index_of(id) else {
            return Err(ActError::Unknown {
                id: kit::bounded::cut(id, kit::bounded::MAX_NAME),
            });
        };
        let alarm = &mut self.instances[index].alarm;
        let change = match action {
            Action::Acknowledge => alarm.acknowledge(),
            Action::Shelve(duration) => alarm.shelve(duration, now),
            Action::Unshelve => alarm.unshelve(),
            Action::OutOfService(out) => alarm.set_out_of_service(out).ok_or(if out {
                Refused::OutOfService
            } else {
                Refused::InService
            }),
        }
        .map_err(|refused| ActError::Refused {
            id: id.to_owned(),
            refused,
        })?;
        self.generation += 1;
        Ok(Happened {
            index,
            t: now,
            changes: vec![change],
            by: Some(by.to_owned()),
            comment: comment.map(str::to_owned),
        })
    }

    /// Alarm `index` as shown.
    pub fn view(&self, index: usize) -> Option<View> {
        let i = self.instances.get(index)?;
        let a = &i.alarm;
        Some(View {
            id: i.id.clone(),
            source: i.source,
            device: i.device.clone(),
            point: i.point.clone(),
            level: i.level,
            limit: i.limit,
            priority: i.priority,
            message: i.message.clone(),
            category: i.category.clone(),
            state: a.state(),
            active: a.active(),
            acknowledged: !a.state().unacknowledged(),
            shelved_until: a.shelved_until(),
            out_of_service: a.out_of_service(),
            first_active: a.first_active,
            last_active: a.last_active,
            value: i.value.clone(),
            count: a.count,
            chattered: a.chattered,
        })
    }

    /// Whether an alarm belongs on the list: active, waiting for an acknowledgement,
    /// shelved or out of service.
    fn listed(instance: &Instance) -> bool {
        let a = &instance.alarm;
        a.state() != State::Normal
            || a.active()
            || a.shelved_until().is_some()
            || a.out_of_service()
    }

    /// The alarm list: every alarm that is active, unacknowledged, shelved or out of
    /// service, most urgent first, then the most recently activated.
    pub fn list(&self, filter: &ListFilter) -> Page {
        let mut matching: Vec<(usize, &Instance)> = self
            .instances
            .iter()
            .enumerate()
            .filter(|(_, i)| Self::listed(i))
            .filter(|(_, i)| {
                filter
                    .device
                    .as_deref()
                    .is_none_or(|d| i.device.as_str() == d)
            })
            .filter(|(_, i)| filter.priority.is_none_or(|p| i.priority == p))
            .collect();
        matching.sort_by(|(_, a), (_, b)| {
            b.priority
                .cmp(&a.priority)
                .then(b.alarm.last_active.cmp(&a.alarm.last_active))
                .then(a.id.cmp(&b.id))
        });
        let total = matching.len();
        let alarms = matching
            .into_iter()
            .skip(filter.offset)
            .take(filter.limit)
            .filter_map(|(index, _)| self.view(index))
            .collect();
        Page { alarms, total }
    }

    /// Per priority: alarms whose condition is active, alarms waiting for an
    /// acknowledgement (ISA-18.2's unacknowledged and returned unacknowledged), and alarms
    /// shelved.
    pub fn counts(&self) -> Vec<Counts> {
        Priority::ALL
            .into_iter()
            .map(|priority| {
                let mut counts = Counts {
                    priority,
                    active: 0,
                    unacknowledged: 0,
                    shelved: 0,
                };
                for i in self.instances.iter().filter(|i| i.priority == priority) {
                    counts.active += u64::from(i.alarm.active());
                    counts.unacknowledged += u64::from(i.alarm.state().unacknowledged());
                    counts.shelved += u64::from(i.alarm.shelved_until().is_some());
                }
                counts
            })
            .collect()
    }

    /// Puts alarm `id` back as a journal entry saved it (after a restart); `false` when
    /// no alarm has the id (the config changed) or the entry cannot be read.
    pub fn restore(&mut self, id: &str, saved: &serde_json::Value, now: Timestamp) -> bool {
        let (Some(index), Ok(saved)) = (
            self.index_of(id),
            serde_json::from_value::<Saved>(saved.clone()),
        ) else {
            return false;
        };
        let time = |text: &Option<String>| {
            text.as_deref()
                .and_then(|t| Timestamp::parse_relative(t, now).ok())
        };
        let instance = &mut self.instances[index];
        instance.alarm.restore(
            saved.state,
            saved.active,
            time(&saved.shelved_until),
            saved.out_of_service,
            (time(&saved.first_active), time(&saved.last_active)),
            (saved.count, saved.chattered),
        );
        if let Some(condition) = &mut instance.condition {
            condition.restore(saved.active);
        }
        instance.value = saved.value;
        self.generation += 1;
        true
    }
}

/// An alarm count of one priority.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Counts {
    /// The priority.
    pub priority: Priority,
    /// Alarms whose condition is active.
    pub active: u64,
    /// Alarms waiting for an acknowledgement.
    pub unacknowledged: u64,
    /// Alarms shelved.
    pub shelved: u64,
}

/// The book shared by the keeper and the interfaces: the keeper feeds it conditions and
/// time, an interface lists and acts through `alarm::keeper::act`. Each use holds the lock
/// only for what it does in memory; nothing waits on IO under it.
#[derive(Debug, Default)]
pub struct Desk {
    book: std::sync::Mutex<Book>,
}

impl Desk {
    /// A desk over `book`.
    pub fn new(book: Book) -> Self {
        Self {
            book: std::sync::Mutex::new(book),
        }
    }

    /// Runs `f` on the book.
    pub fn with<R>(&self, f: impl FnOnce(&mut Book) -> R) -> R {
        f(&mut self
            .book
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner))
    }

    /// Puts `book` in place of the one it holds (a reload): each alarm of both keeps its
    /// state, as a restart would restore it; the others start normal or are gone.
    pub fn replace(&self, mut book: Book, now: Timestamp) {
        self.with(|old| {
            for index in 0..old.len() {
                if let Some(view) = old.view(index) {
                    book.restore(&view.id, &serde_json::json!(view), now);
                }
            }
            book.generation = old.generation + 1;
            *old = book;
        });
    }

    /// The alarm list ([`Book::list`]).
    pub fn list(&self, filter: &ListFilter) -> Page {
        self.with(|book| book.list(filter))
    }

    /// The counts by priority ([`Book::counts`]).
    pub fn counts(&self) -> Vec<Counts> {
        self.with(|book| book.counts())
    }

    /// One alarm as shown.
    pub fn view(&self, id: &str) -> Option<View> {
        self.with(|book| book.index_of(id).and_then(|i| book.view(i)))
    }

    /// Every alarm of `device`, normal or not (for an interface's birth of the device).
    pub fn of_device(&self, device: &str) -> Vec<View> {
        self.with(|book| {
            (0..book.len())
                .filter(|&i| book.instances[i].device.as_str() == device)
                .filter_map(|i| book.view(i))
                .collect()
        })
    }

    /// Every alarm, normal or not.
    pub fn all(&self) -> Vec<View> {
        self.with(|book| (0..book.len()).filter_map(|i| book.view(i)).collect())
    }
}

#[cfg(test)]
mod tests;
