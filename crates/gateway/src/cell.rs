//! The live state of the cell: every device and point with value, time and quality, the
//! lines' health, and the stream of changes the web page and SSE clients follow.
//!
//! The [`scheduler`](crate::scheduler) tasks are the only writers of this state; the HTTP
//! handlers read snapshots ([`Cell::devices`], [`Cell::lines`]) and send writes through
//! the one write gate ([`Cell::check_write`], then [`crate::write::Attempt`]), which hands
//! the checked value to the line's task, so a write is serialised with the polls of its
//! line.

use std::collections::BTreeMap;
use std::sync::{Arc, PoisonError, RwLock, RwLockReadGuard, RwLockWriteGuard};
use std::time::Duration;

use serde::Serialize;
use tokio::sync::{broadcast, mpsc, oneshot};

use crate::config::{CellConfig, LineConfig};
use crate::driver::{DeviceError, Driver, Kind, PollGroup, WriteError};
use crate::event::{Event, EventKind};
use crate::metrics::Metrics;
use crate::point::{
    Checked, Deadband, DeviceId, PointId, PointKind, PointSpec, Quality, Value, Words,
};
use crate::store::StoreHandle;
use crate::time::{Timestamp, duration_millis};

/// Messages kept for a slow subscriber (an interface, an event-stream client) before it
/// misses some: 16,384 slots of 16 B (a message is dropped once every subscriber has read
/// it). At 50,000 value changes a second that is 330 ms: the MQTT interface's births of
/// 1,000 devices of 100 metrics fit in it, where 4,096 (80 ms) sent it into one rebirth
/// and catch-up from the history after another (load bench `--modbus-changes 50 --mqtt`).
const LIVE_CAPACITY: usize = 16384;

/// Queued writes per line.
const WRITE_QUEUE: usize = 32;

/// The cell.
#[derive(Debug)]
pub struct Cell {
    /// The devices and lines polled now: replaced whole when the configuration is
    /// reloaded ([`crate::reload`]), so a reader's snapshot never mixes two.
    roster: RwLock<Arc<Roster>>,
    live: broadcast::Sender<LiveMessage>,
    store: StoreHandle,
    metrics: Arc<Metrics>,
    interfaces: RwLock<Vec<(&'static str, Arc<dyn InterfaceStatus>)>>,
    log_throttle: std::sync::Mutex<crate::oplog::Throttle>,
    /// A device's own links that are down (a Panasonic machine's Port 2), by device and
    /// link, with why: told by its events (`link`, `state`, `error` fields).
    links_down: RwLock<BTreeMap<(DeviceId, String), String>>,
    /// The shifts, and which devices report states and production ([`Cell::production`]).
    production: RwLock<Arc<crate::production::Plan>>,
    /// Every alarm of the cell (`alarm::keeper` runs them).
    pub alarms: crate::alarm::book::Desk,
    /// The configuration in force: where it came from, when it was loaded, and why the last
    /// reload was refused, if it was.
    config: RwLock<ConfigStatus>,
}

/// The configuration in force, as `/healthz` shows it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ConfigStatus {
    /// The file, or `null` for the demo cell.
    pub path: Option<String>,
    /// When the configuration in force was loaded (at the start, or by a reload).
    pub loaded_at: Timestamp,
    /// Why the last reload was refused (the configuration in force stays), `null` when
    /// the last load succeeded.
    pub error: Option<String>,
    /// When that reload was refused.
    pub error_at: Option<Timestamp>,
}

/// The shifts of `config`, its devices with states and those that produce.
fn production_plan(config: &CellConfig) -> crate::production::Plan {
    let mut plan = crate::production::Plan::new(config.shifts.clone());
    for device in config.lines.iter().flat_map(|l| &l.devices) {
        let kind = device.driver.protocol;
        plan.add(
            &device.driver.id,
            kind.machine_states(),
            kind.production(),
            device.production.clone(),
        );
    }
    plan
}

/// The status of an interface the gateway has but that does not run (not configured):
/// `null` under its name in `/healthz`, until the interface registers its own.
#[derive(Debug)]
pub struct NotRunning;

impl InterfaceStatus for NotRunning {
    fn health(&self) -> serde_json::Value {
        serde_json::Value::Null
    }

    fn into_any(self: Arc<Self>) -> Arc<dyn std::any::Any + Send + Sync> {
        self
    }
}

/// What an interface (MQTT, OPC UA) shows of itself: its state under its name in
/// `/healthz` (the web page's badges read it), and its gauges brought up to date before
/// `/metrics` is read. The interface registers it when it starts
/// ([`Cell::set_interface`]); the core reads it without knowing the interface.
pub trait InterfaceStatus: Send + Sync + std::fmt::Debug {
    /// Its state as `/healthz` shows it.
    fn health(&self) -> serde_json::Value;

    /// Why the interface cannot do its job now (its link is down), for `/healthz`'s
    /// `degraded`; `None` when it works.
    fn problem(&self) -> Option<String> {
        None
    }

    /// Brings the interface's gauges up to date (before a scrape of `/metrics`).
    fn before_scrape(&self) {}

    /// The status as `Any`, for the interface to take back its own type.
    fn into_any(self: Arc<Self>) -> Arc<dyn std::any::Any + Send + Sync>;
}

/// One device: what it is and its live state.
#[derive(Debug)]
pub struct DeviceEntry {
    /// Its id.
    pub id: DeviceId,
    /// Words for people.
    pub name: String,
    /// Its protocol.
    pub protocol: Kind,
    /// The line it is on.
    pub line: String,
    /// Its address on the line.
    pub address: Option<i64>,
    /// Its points.
    pub points: Vec<PointSpec>,
    /// Each point's deadband (numeric points only), in the order of `points`; empty when
    /// no point has one (a JBC station: 400 bytes each less). Read through
    /// [`DeviceEntry::deadband`].
    pub deadbands: Vec<Option<Deadband>>,
    /// Its poll groups, with the periods in force.
    pub groups: Vec<PollGroup>,
    /// Indices into `points`, sorted by point name: the lookup by name without a second
    /// copy of every name (a map of owned names was a tenth of the heap with 1,000 devices).
    by_name: Vec<u32>,
    state: RwLock<DeviceState>,
    writes: mpsc::Sender<WriteRequest>,
}

/// Whether a device answers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DeviceStatus {
    /// Not polled yet.
    Connecting,
    /// Answered its last poll.
    Up,
    /// Did not answer; backed off.
    Down,
}

/// The changing part of a device.
#[derive(Debug, Clone)]
pub struct DeviceState {
    /// Up, down or connecting.
    pub status: DeviceStatus,
    /// Since when.
    pub since: Timestamp,
    /// Why it is down, or the last error of a point-level refusal.
    pub error: Option<DeviceError>,
    /// Its last answered poll.
    pub last_ok: Option<Timestamp>,
    /// Failed polls in a row.
    pub failures: u32,
    /// When it is tried next while backed off.
    pub next_try_at: Option<Timestamp>,
    /// Points, in the order of [`DeviceEntry::points`].
    pub points: Vec<PointState>,
}

impl DeviceState {
    /// A device not yet polled since `since`, with `points` points not yet read.
    fn connecting(since: Timestamp, points: usize) -> Self {
        Self {
            status: DeviceStatus::Connecting,
            since,
            error: None,
            last_ok: None,
            failures: 0,
            next_try_at: None,
            points: vec![PointState::default(); points],
        }
    }
}

/// The changing part of a point: 64 bytes (one is kept per point: 1.7 MB at 26,000).
#[derive(Debug, Clone)]
pub struct PointState {
    /// Last value read.
    pub value: Option<Value>,
    /// When it was last read (good) or last failed (bad).
    pub t: Option<Timestamp>,
    /// Good, stale (not refreshed in time: set by the line task's sweep, and judged again
    /// when shown) or bad.
    pub quality: Option<Quality>,
    /// Why the last read failed (shared by the points of a device that went down; an
    /// `Arc<String>`, not an `Arc<str>`, for a pointer of 8 bytes instead of 16).
    pub error: Option<Arc<String>>,
    /// Whether the value is in alarm.
    pub alarm: bool,
    /// The last value stored and published when it was a number, NaN otherwise (see
    /// [`PointState::recorded`]): a `Value` here made a point 96 bytes, an `Option<f64>`
    /// 80.
    recorded: f64,
}

impl Default for PointState {
    fn default() -> Self {
        Self {
            value: None,
            t: None,
            quality: None,
            error: None,
            alarm: false,
            recorded: f64::NAN,
        }
    }
}

impl PartialEq for PointState {
    fn eq(&self, other: &Self) -> bool {
        self.value == other.value
            && self.t == other.t
            && self.quality == other.quality
            && self.error == other.error
            && self.alarm == other.alarm
            && self.recorded() == other.recorded()
    }
}

impl PointState {
    /// The last value stored and published, when it was a number (and not NaN): a number
    /// within the point's deadband of it updates only `value`. Text, NaN and no value are
    /// never held back, so then the last value stored is `value` itself.
    pub fn recorded(&self) -> Option<f64> {
        (!self.recorded.is_nan()).then_some(self.recorded)
    }

    /// Notes that its value was just stored and published.
    pub(crate) fn set_recorded(&mut self) {
        self.recorded = self
            .value
            .as_ref()
            .and_then(Value::as_number)
            .unwrap_or(f64::NAN);
    }
}

/// One line and its health.
#[derive(Debug)]
pub struct LineEntry {
    /// Its name.
    pub name: String,
    /// Its endpoint, as text.
    pub endpoint: String,
    /// Devices on it, in poll order.
    pub devices: Vec<DeviceId>,
    /// Close and reopen it when every device on it has timed out this many times in a row
    /// (0: never; never either for a line of a device that keeps its own connections).
    pub reopen_after_timeouts: u32,
    state: RwLock<LineState>,
}

/// How a line is doing.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct LineState {
    /// Whether it is open.
    pub open: bool,
    /// Why it is not.
    pub error: Option<String>,
    /// Share of the last window spent on requests (0–1).
    pub utilisation: f64,
    /// Polls per second over the last window.
    pub polls_per_second: f64,
    /// Failed polls per second over the last window.
    pub errors_per_second: f64,
}

/// A change pushed to event-stream clients.
///
/// Each kind is boxed: the change stream keeps [`LIVE_CAPACITY`] slots of this size from
/// the start, 16 bytes each instead of 168 (0.6 MB less), and a message's box lives only
/// until every subscriber has read it.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum LiveMessage {
    /// A point's value or quality changed.
    Value(Box<PointView>),
    /// A device went up or down.
    Device(Box<DeviceSummary>),
    /// An event was recorded.
    Event(Box<Event>),
}

impl LiveMessage {
    /// The SSE event name (`value`, `device`, `event`).
    pub fn name(&self) -> &'static str {
        match self {
            LiveMessage::Value(_) => "value",
            LiveMessage::Device(_) => "device",
            LiveMessage::Event(_) => "event",
        }
    }
}

/// A point as the API shows it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PointView {
    /// `device.point`.
    pub id: PointId,
    /// Words.
    pub name: Words,
    /// Unit symbol.
    pub unit: Option<Words>,
    /// Current value, if ever read.
    pub value: Option<Value>,
    /// The label of an enumerated value.
    pub text: Option<String>,
    /// Good, stale or bad; `null` before the first poll.
    pub quality: Option<Quality>,
    /// When it was last read.
    pub t: Option<Timestamp>,
    /// Why the last read failed.
    pub error: Option<String>,
    /// Whether the value is in alarm.
    pub alarm: bool,
    /// Its poll group's period, ms (a value older than a few periods is stale).
    pub period_ms: i64,
}

/// A point with its description, for device listings.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PointDetail {
    /// The live part.
    #[serde(flatten)]
    pub view: PointView,
    /// Number, text or enumeration with its states.
    pub kind: PointKind,
    /// The poll group.
    pub group: Words,
    /// The write range, if writable.
    pub writable: Option<crate::point::WriteRange>,
}

/// A device's status without its points.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DeviceSummary {
    /// Its id.
    pub id: DeviceId,
    /// Up, down or connecting.
    pub status: DeviceStatus,
    /// Since when.
    pub since: Timestamp,
    /// Why it is down.
    pub error: Option<DeviceError>,
    /// Last answered poll.
    pub last_ok: Option<Timestamp>,
    /// Failed polls in a row.
    pub failures: u32,
    /// Next try while backed off.
    pub next_try_at: Option<Timestamp>,
}

/// A device as the API shows it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DeviceView {
    /// Words.
    pub name: String,
    /// Its protocol.
    pub protocol: Kind,
    /// The name of the line it is on.
    pub line: String,
    /// Its address on the line (JBC station, regulator, Modbus unit), if it has one.
    pub address: Option<i64>,
    /// Its id and status.
    #[serde(flatten)]
    pub summary: DeviceSummary,
    /// Milliseconds until the next try while backed off.
    pub next_try_in_ms: Option<i64>,
    /// Poll groups with their periods (ms).
    pub groups: Vec<GroupView>,
    /// Points with values.
    pub points: Vec<PointDetail>,
}

/// A poll group as the API shows it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GroupView {
    /// Its name.
    pub name: String,
    /// Its period, ms.
    pub period_ms: i64,
}

/// A line as the API shows it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LineView {
    /// Its name.
    pub name: String,
    /// Its endpoint URL, as configured (`serial:///dev/ttyUSB0?baud=9600`).
    pub endpoint: String,
    /// Devices on it.
    pub devices: Vec<DeviceId>,
    /// Devices backed off now.
    pub backed_off: Vec<DeviceId>,
    /// Health.
    #[serde(flatten)]
    pub state: LineState,
}

/// A write for a line's task.
#[derive(Debug)]
pub(crate) struct WriteRequest {
    pub device: DeviceId,
    pub point: usize,
    pub value: Checked,
    pub reply: oneshot::Sender<Result<(), WriteError>>,
}

/// What a write changed.
#[derive(Debug, Clone, PartialEq)]
pub struct WriteOutcome {
    /// The value before, as last read.
    pub old: Option<Value>,
    /// The value written, as sent (labels turned into numbers).
    pub new: Value,
}

/// A write that passed the gate's check ([`Cell::check_write`]): its point, found once,
/// and its value as it will be sent (labels turned into numbers, whole for an integer
/// point). Only the check makes one.
#[derive(Debug, Clone)]
pub struct CheckedWrite {
    device: Arc<DeviceEntry>,
    index: usize,
    value: Checked,
}

impl CheckedWrite {
    /// The point.
    pub fn point(&self) -> &PointId {
        &self.spec().id
    }

    /// The point's spec.
    pub fn spec(&self) -> &PointSpec {
        &self.device.points[self.index]
    }

    /// The value as it will be sent.
    pub fn value(&self) -> &Value {
        self.value.value()
    }

    /// The device's line.
    pub fn line(&self) -> &str {
        &self.device.line
    }

    /// The device.
    pub fn device(&self) -> &DeviceId {
        &self.device.id
    }

    /// The point's value as last read.
    pub fn old(&self) -> Option<Value> {
        self.device
            .read()
            .points
            .get(self.index)
            .and_then(|p| p.value.clone())
    }
}

/// One line of a new cell, for its poll task ([`LineTask`](crate::scheduler::LineTask)):
/// the line's entry, its devices with their drivers, and the queue of writes for them.
pub struct LinePlan {
    /// The line as the cell shows it.
    pub(crate) entry: Arc<LineEntry>,
    /// Its devices, in the config's order, each with its driver.
    pub(crate) devices: Vec<(Arc<DeviceEntry>, Box<dyn Driver>)>,
    /// The writes [`Cell::write_checked`] queues for the line's devices.
    pub(crate) writes: mpsc::Receiver<WriteRequest>,
}

impl LinePlan {
    /// The plan of `line`: its devices' drivers built, their entries not yet polled since
    /// `now`.
    pub(crate) fn new(line: &LineConfig, now: Timestamp) -> Result<Self, String> {
        let (writes_tx, writes_rx) = mpsc::channel(WRITE_QUEUE);
        let mut slots: Vec<(Arc<DeviceEntry>, Box<dyn Driver>)> = Vec::new();
        for device in &line.devices {
            let driver = device.driver.build()?;
            let entry = DeviceEntry::new(device, &line.name, driver.as_ref(), now, &writes_tx);
            slots.push((Arc::new(entry), driver));
        }
        let entry = Arc::new(LineEntry {
            name: line.name.clone(),
            endpoint: line.endpoint.to_string(),
            devices: slots.iter().map(|(d, _)| d.id.clone()).collect(),
            reopen_after_timeouts: if line.owns_connections() {
                0
            } else {
                line.reopen_after_timeouts
            },
            state: RwLock::new(LineState::default()),
        });
        Ok(LinePlan {
            entry,
            devices: slots,
            writes: writes_rx,
        })
    }

    /// The line and its devices, for the roster.
    pub(crate) fn roster_part(&self) -> (Arc<LineEntry>, Vec<Arc<DeviceEntry>>) {
        (
            Arc::clone(&self.entry),
            self.devices.iter().map(|(d, _)| Arc::clone(d)).collect(),
        )
    }
}

/// The alarms of `config` over the devices of `roster`, all normal.
fn alarm_book(config: &CellConfig, roster: &Roster) -> crate::alarm::book::Book {
    let device_alarms: Vec<_> = roster
        .devices()
        .map(|d| crate::alarm::book::DeviceAlarms {
            device: d.id.clone(),
            label: d.name.clone(),
            rule_points: d
                .points
                .iter()
                .filter(|p| p.alarm.is_some())
                .cloned()
                .collect(),
        })
        .collect();
    crate::alarm::book::Book::new(&config.alarms, &device_alarms)
}

impl std::fmt::Debug for LinePlan {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LinePlan")
            .field("line", &self.entry.name)
            .field("devices", &self.devices.len())
            .finish()
    }
}

impl Cell {
    /// The cell `config` describes, with one [`LinePlan`] per line (in the config's order)
    /// for the scheduler to run (`scheduler::build` does both).
    pub fn new(
        config: &CellConfig,
        store: StoreHandle,
        metrics: Arc<Metrics>,
    ) -> Result<(Arc<Cell>, Vec<LinePlan>), String> {
        let (live, _) = broadcast::channel(LIVE_CAPACITY);
        let now = Timestamp::now();
        let plans = config
            .lines
            .iter()
            .map(|line| LinePlan::new(line, now))
            .collect::<Result<Vec<_>, _>>()?;
        let roster = Roster::of(plans.iter().map(LinePlan::roster_part).collect())?;
        let alarms = alarm_book(config, &roster);
        let cell = Arc::new(Cell {
            roster: RwLock::new(Arc::new(roster)),
            live,
            store,
            metrics,
            interfaces: RwLock::new(Vec::new()),
            log_throttle: std::sync::Mutex::default(),
            links_down: RwLock::default(),
            production: RwLock::new(Arc::new(production_plan(config))),
            alarms: crate::alarm::book::Desk::new(alarms),
            config: RwLock::new(ConfigStatus {
                path: config.source.as_ref().map(|p| p.display().to_string()),
                loaded_at: now,
                error: None,
                error_at: None,
            }),
        });
        Ok((cell, plans))
    }

    /// The devices and lines polled now: a snapshot, kept whole by a reload.
    pub fn roster(&self) -> Arc<Roster> {
        Arc::clone(&self.roster.read().unwrap_or_else(PoisonError::into_inner))
    }

    /// Puts `roster` in force, with the production plan and the alarms of `config` (each
    /// alarm that stays keeps its state): a reload's moment of change.
    pub(crate) fn replace_roster(&self, roster: Roster, config: &CellConfig) {
        let book = alarm_book(config, &roster);
        self.alarms.replace(book, Timestamp::now());
        *self
            .production
            .write()
            .unwrap_or_else(PoisonError::into_inner) = Arc::new(production_plan(config));
        *self.roster.write().unwrap_or_else(PoisonError::into_inner) = Arc::new(roster);
        self.links_down
            .write()
            .unwrap_or_else(PoisonError::into_inner)
            .retain(|(device, _), _| self.device_entry(device.as_str()).is_some());
    }

    /// The shifts, and which devices report states and production.
    pub fn production(&self) -> Arc<crate::production::Plan> {
        Arc::clone(
            &self
                .production
                .read()
                .unwrap_or_else(PoisonError::into_inner),
        )
    }

    /// The configuration in force, and why the last reload was refused.
    pub fn config_status(&self) -> ConfigStatus {
        self.config
            .read()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    /// Notes a reload: loaded now (`error` `None`), or refused for `error`.
    pub(crate) fn note_config(&self, error: Option<String>) {
        let now = Timestamp::now();
        let mut status = self.config.write().unwrap_or_else(PoisonError::into_inner);
        match error {
            None => {
                status.loaded_at = now;
                status.error = None;
                status.error_at = None;
            }
            Some(error) => {
                status.error = Some(error);
                status.error_at = Some(now);
            }
        }
    }

    /// The history.
    pub fn store(&self) -> &StoreHandle {
        &self.store
    }

    /// The metrics.
    pub fn metrics(&self) -> &Metrics {
        &self.metrics
    }

    /// Every device, by id (of the roster in force when called).
    pub fn device_entries(&self) -> impl Iterator<Item = Arc<DeviceEntry>> + use<> {
        let roster = self.roster();
        roster.devices().cloned().collect::<Vec<_>>().into_iter()
    }

    /// A device by id.
    pub fn device_entry(&self, id: &str) -> Option<Arc<DeviceEntry>> {
        self.roster().device(id).cloned()
    }

    /// Every device with its points, as the API shows them.
    pub fn devices(&self) -> Vec<DeviceView> {
        let now = Timestamp::now();
        self.roster().devices().map(|d| d.view(now)).collect()
    }

    /// One device, as the API shows it.
    pub fn device(&self, id: &str) -> Option<DeviceView> {
        self.device_entry(id).map(|d| d.view(Timestamp::now()))
    }

    /// The spec of a point, if it exists.
    pub fn point(&self, id: &PointId) -> Option<PointRef> {
        let device = self.device_entry(id.device())?;
        let index = device.point_index(id.name())?;
        Some(PointRef { device, index })
    }

    /// Every line with its health.
    pub fn lines(&self) -> Vec<LineView> {
        let roster = self.roster();
        roster
            .lines
            .iter()
            .map(|line| LineView {
                name: line.name.clone(),
                endpoint: line.endpoint.clone(),
                devices: line.devices.clone(),
                backed_off: line
                    .devices
                    .iter()
                    .filter(|id| {
                        roster
                            .devices
                            .get(*id)
                            .is_some_and(|d| d.read().next_try_at.is_some())
                    })
                    .cloned()
                    .collect(),
                state: line.read().clone(),
            })
            .collect()
    }

    /// The status the interface `name` registered, if it runs.
    pub fn interface(&self, name: &str) -> Option<Arc<dyn InterfaceStatus>> {
        self.interfaces
            .read()
            .unwrap_or_else(PoisonError::into_inner)
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, status)| Arc::clone(status))
    }

    /// The running interfaces' statuses, in the order they registered.
    pub fn interfaces(&self) -> Vec<(&'static str, Arc<dyn InterfaceStatus>)> {
        self.interfaces
            .read()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    /// Registers the status of the interface `name` (an interface does when it starts),
    /// replacing one it registered before; returns the one registered, which stays when
    /// `name` had one already and `replace` is false.
    pub fn set_interface(
        &self,
        name: &'static str,
        status: Arc<dyn InterfaceStatus>,
        replace: bool,
    ) -> Arc<dyn InterfaceStatus> {
        let mut interfaces = self
            .interfaces
            .write()
            .unwrap_or_else(PoisonError::into_inner);
        match interfaces.iter_mut().find(|(n, _)| *n == name) {
            Some((_, existing)) if !replace => Arc::clone(existing),
            Some((_, existing)) => {
                *existing = Arc::clone(&status);
                status
            }
            None => {
                interfaces.push((name, Arc::clone(&status)));
                status
            }
        }
    }

    /// Follows live changes.
    pub fn subscribe(&self) -> broadcast::Receiver<LiveMessage> {
        self.live.subscribe()
    }

    /// Records an event and tells the event-stream clients.
    pub fn emit(&self, event: Event) {
        self.metrics.events.inc();
        crate::oplog::log(&self.log_throttle, &event);
        self.note_link(&event);
        self.store.event(event.clone());
        self.publish(LiveMessage::Event(Box::new(event)));
    }

    /// Follows a device's own link from its events: `link` names it, `state` is `down` (with
    /// `error`) or `up`.
    fn note_link(&self, event: &Event) {
        let (Some(device), Some(link), Some(state)) = (
            &event.device,
            event.fields.get("link").and_then(|l| l.as_str()),
            event.fields.get("state").and_then(|s| s.as_str()),
        ) else {
            return;
        };
        let key = (device.clone(), link.to_owned());
        let mut down = self
            .links_down
            .write()
            .unwrap_or_else(PoisonError::into_inner);
        match state {
            "down" => {
                let why = event
                    .fields
                    .get("error")
                    .and_then(|e| e.as_str())
                    .unwrap_or("no reason given");
                down.insert(key, why.to_owned());
            }
            _ => {
                down.remove(&key);
            }
        }
    }

    /// The devices' own links that are down: device, link and why.
    pub fn links_down(&self) -> Vec<(DeviceId, String, String)> {
        self.links_down
            .read()
            .unwrap_or_else(PoisonError::into_inner)
            .iter()
            .map(|((device, link), why)| (device.clone(), link.clone(), why.clone()))
            .collect()
    }

    /// Tells the event-stream clients.
    pub(crate) fn publish(&self, message: LiveMessage) {
        // No subscriber is not an error.
        let _ = self.live.send(message);
    }

    /// The write gate's check, the only one before the wire: looks `point` up once and
    /// checks `value` against its spec ([`PointSpec::check_write`]). The checked write
    /// carries what [`Cell::write_checked`] needs, so nothing is looked up or checked again.
    /// Every interface writes through [`crate::write::Attempt`], which calls both.
    pub fn check_write(&self, point: &PointId, value: &Value) -> Result<CheckedWrite, WriteError> {
        let unknown = || WriteError::UnknownPoint {
            point: point.clone(),
        };
        let device = self.device_entry(point.device()).ok_or_else(unknown)?;
        let index = device.point_index(point.name()).ok_or_else(unknown)?;
        let spec = device.points.get(index).ok_or_else(unknown)?;
        let value = spec.check_write(value)?;
        Ok(CheckedWrite {
            device: Arc::clone(&device),
            index,
            value,
        })
    }

    /// Has the line's task write a checked write (between two polls of that line).
    pub(crate) async fn write_checked(
        &self,
        write: &CheckedWrite,
    ) -> Result<WriteOutcome, WriteError> {
        let device = &write.device;
        let old = write.old();
        let (reply, answer) = oneshot::channel();
        let not_running = || WriteError::NotRunning {
            line: device.line.clone(),
        };
        device
            .writes
            .send(WriteRequest {
                device: device.id.clone(),
                point: write.index,
                value: write.value.clone(),
                reply,
            })
            .await
            .map_err(|_| not_running())?;
        answer.await.map_err(|_| not_running())??;
        Ok(WriteOutcome {
            old,
            new: write.value.value().clone(),
        })
    }

    /// Checks and writes, unaudited: for the scheduler's tests.
    #[cfg(test)]
    pub(crate) async fn write(
        &self,
        point: &PointId,
        value: &Value,
    ) -> Result<WriteOutcome, WriteError> {
        let write = self.check_write(point, value)?;
        self.write_checked(&write).await
    }

    /// Emits the event for a line that could not be opened or failed.
    pub(crate) fn line_event(&self, line: &LineEntry, kind: EventKind, message: String) {
        self.emit(Event {
            t: Timestamp::now(),
            kind,
            line: Some(line.name.clone()),
            device: None,
            point: None,
            message,
            fields: crate::event::Fields::new(),
        });
    }
}

impl DeviceEntry {
    /// The entry of `device` on the line `line`, read by `driver`, not yet polled since
    /// `now`; its writes go to the line's queue `writes`.
    fn new(
        device: &crate::config::DeviceConfig,
        line: &str,
        driver: &dyn Driver,
        now: Timestamp,
        writes: &mpsc::Sender<WriteRequest>,
    ) -> Self {
        let mut points = driver.points();
        if device.driver.protocol.production().is_some() {
            points.extend(crate::production::oee_specs(&device.driver.id));
        }
        let groups = driver
            .groups()
            .into_iter()
            .map(|g| PollGroup {
                period: device.period_of(&g),
                name: g.name,
            })
            .collect();
        let deadbands = points
            .iter()
            .map(|p| {
                driver
                    .deadband(p.id.name())
                    .unwrap_or(device.deadband)
                    .filter(|_| p.kind == PointKind::Numeric)
            })
            .collect::<Vec<_>>();
        let deadbands = if deadbands.iter().all(Option::is_none) {
            Vec::new()
        } else {
            deadbands
        };
        let by_name = sorted_by_name(&points);
        DeviceEntry {
            id: device.driver.id.clone(),
            name: device.name.clone(),
            protocol: device.driver.protocol,
            line: line.to_owned(),
            address: device.driver.address,
            state: RwLock::new(DeviceState::connecting(now, points.len())),
            points,
            deadbands,
            groups,
            by_name,
            writes: writes.clone(),
        }
    }

    /// Takes over `old`'s live state (status, values, errors): the same device, with the
    /// same points, whose line's task was restarted by a reload.
    pub(crate) fn take_state_of(&self, old: &DeviceEntry) {
        if self.points == old.points {
            *self.write_state() = old.read().clone();
        }
    }

    /// The live state, for reading.
    pub fn read(&self) -> RwLockReadGuard<'_, DeviceState> {
        self.state.read().unwrap_or_else(PoisonError::into_inner)
    }

    pub(crate) fn write_state(&self) -> RwLockWriteGuard<'_, DeviceState> {
        self.state.write().unwrap_or_else(PoisonError::into_inner)
    }

    /// The deadband of the point at `index`, if it has one.
    pub fn deadband(&self, index: usize) -> Option<Deadband> {
        self.deadbands.get(index).copied().flatten()
    }

    /// The index of a point by its name (the part after the device id).
    pub fn point_index(&self, name: &str) -> Option<usize> {
        // Every point id is `<this device's id>.<name>`: skip the prefix instead of
        // looking for the dot at each step.
        let skip = self.id.as_str().len() + 1;
        self.by_name
            .binary_search_by(|&i| {
                let id = self.points[i as usize].id.as_str();
                id.get(skip..).unwrap_or_default().cmp(name)
            })
            .ok()
            .map(|found| self.by_name[found] as usize)
    }

    /// The period of a poll group.
    pub fn period(&self, group: &str) -> Duration {
        if group == crate::production::OEE_GROUP {
            return crate::production::OEE_PERIOD;
        }
        self.groups
            .iter()
            .find(|g| g.name == group)
            .map_or(Duration::from_secs(1), |g| g.period)
    }

    /// The device in words for messages: `Rework station 1 (jbc1)`, or its id alone when
    /// it has no name of its own.
    pub fn label(&self) -> String {
        if self.name == self.id.as_str() {
            self.name.clone()
        } else {
            format!("{} ({})", self.name, self.id)
        }
    }

    /// The device's status without points.
    pub fn summary(&self) -> DeviceSummary {
        summary_of(&self.id, &self.read())
    }

    /// A point's view.
    pub fn point_view(&self, index: usize, state: &PointState, now: Timestamp) -> PointView {
        let spec = &self.points[index];
        let period = self.period(&spec.group);
        PointView {
            id: spec.id.clone(),
            name: spec.name.clone(),
            unit: spec.unit.clone(),
            text: state
                .value
                .as_ref()
                .and_then(|v| spec.label(v))
                .map(str::to_owned),
            value: state.value.clone(),
            quality: state
                .quality
                .map(|q| judge_staleness(q, state.t, period, now)),
            t: state.t,
            error: state.error.as_deref().cloned(),
            alarm: state.alarm,
            period_ms: duration_millis(period),
        }
    }

    /// The device as the API shows it.
    pub fn view(&self, now: Timestamp) -> DeviceView {
        self.build_view(now, true)
    }

    /// The device without its points (cheaper, for listings that leave them out).
    pub fn view_without_points(&self, now: Timestamp) -> DeviceView {
        self.build_view(now, false)
    }

    /// Status and points from one look at the state, so they agree.
    fn build_view(&self, now: Timestamp, with_points: bool) -> DeviceView {
        let state = self.read();
        let points = if with_points {
            state
                .points
                .iter()
                .enumerate()
                .map(|(i, p)| PointDetail {
                    view: self.point_view(i, p, now),
                    kind: self.points[i].kind.clone(),
                    group: self.points[i].group.clone(),
                    writable: self.points[i].writable,
                })
                .collect()
        } else {
            Vec::new()
        };
        let summary = summary_of(&self.id, &state);
        DeviceView {
            name: self.name.clone(),
            protocol: self.protocol,
            line: self.line.clone(),
            address: self.address,
            next_try_in_ms: state.next_try_at.map(|t| (t.0 - now.0).max(0)),
            summary,
            groups: self
                .groups
                .iter()
                .map(|g| GroupView {
                    name: g.name.clone(),
                    period_ms: duration_millis(g.period),
                })
                .collect(),
            points,
        }
    }
}

impl LineEntry {
    /// The line's health.
    pub fn read(&self) -> RwLockReadGuard<'_, LineState> {
        self.state.read().unwrap_or_else(PoisonError::into_inner)
    }

    pub(crate) fn write_state(&self) -> RwLockWriteGuard<'_, LineState> {
        self.state.write().unwrap_or_else(PoisonError::into_inner)
    }
}

/// The indices of `points` in the order of their names.
fn sorted_by_name(points: &[PointSpec]) -> Vec<u32> {
    let mut order: Vec<u32> = (0..points.len())
        .map(|i| u32::try_from(i).expect("a device has fewer than 2^32 points"))
        .collect();
    order.sort_by(|&a, &b| {
        points[a as usize]
            .id
            .name()
            .cmp(points[b as usize].id.name())
    });
    order
}

fn summary_of(id: &DeviceId, state: &DeviceState) -> DeviceSummary {
    DeviceSummary {
        id: id.clone(),
        status: state.status,
        since: state.since,
        error: state.error.clone(),
        last_ok: state.last_ok,
        failures: state.failures,
        next_try_at: state.next_try_at,
    }
}

/// A good value older than three periods plus two seconds is stale.
pub fn judge_staleness(
    quality: Quality,
    t: Option<Timestamp>,
    period: Duration,
    now: Timestamp,
) -> Quality {
    let limit = period * 3 + Duration::from_secs(2);
    match (quality, t) {
        (Quality::Good, Some(t)) if now.0 - t.0 > duration_millis(limit) => Quality::Stale,
        _ => quality,
    }
}

mod roster;
pub use roster::{PointRef, Roster};

#[cfg(test)]
mod tests;
