//! Panasonic placement machines (PanaProtocol LAN) as points and events, through
//! `panasonic::client`.
//!
//! # How an event-driven TCP device fits the line scheduler
//!
//! The machine is a TCP server with two ports: Port 1 for C commands and their answers,
//! Port 2 for its unsolicited R messages. Its client keeps both connections itself
//! (reconnection with backoff, the C2HB/R1HB keep-alive), so the driver owns its
//! [`Client`] instead of talking over the line the scheduler attaches: the line's
//! endpoint (`tcp://host:49152`) names Port 1, the device's `event_port` Port 2 (49153 by
//! default), and the line task opens nothing for such a line
//! ([`super::DeviceKind::owns_connections`]). Everything else is the scheduler's as for any
//! device: the poll groups at their periods, backoff of a silent machine, quality, history,
//! metrics.
//!
//! The driver connects on its first poll and forwards Port 2's notices from a small task
//! into a queue, which the scheduler drains after every poll ([`Driver::take_events`]): R
//! messages become `device_event` events (in words: `R2E03… (error stop: parts
//! exhausted …)`), a lost Port 2 connection too, stamped with the time they arrived (the
//! log gets them at most one `live` period, 1 s, later). Keep-alive echoes (`R1HB`) are not
//! recorded.
//!
//! Groups: `live` (1 s: C2ST, run state and control mode), `program` (10 s: C3P, the
//! selected program), `production` (10 s: C1M, the grand total of the production
//! management data, read without clearing). The run state going from run to ready or
//! error (and back) is a `state_changed` event; the error state is an alarm.
//!
//! Machine states (SEMI E10, [`MACHINE_STATES`]): the run state of each `live` poll,
//! refined by the R messages that came before it: an error stop after R2E03 is `parts
//! exhausted` (5500, with the feeder as its reason, so the stops sort by feeder), after
//! another R2E `error stop` (5000, with the error code and feeder), during a recovery `recovery` (5300); ready
//! after a program was selected is `setup` (4500) until the machine runs again.
//!
//! Nothing is writable: C5 start and reset are commands, not values, and the gateway writes
//! values only.

pub mod demo;

use std::sync::Arc;
use std::time::Duration;

use link::{Endpoint, SharedLine};
use panasonic::client::{Client, ClientConfig, ClientError, Notice};
use panasonic::command::{ProductionRequest, ProductionScope};
use panasonic::event::Event;
use panasonic::production::{Counter, RateKind};
use panasonic::status::{ControlMode, RunState};
use panasonic::{DEFAULT_EVENT_PORT, Port};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use super::machine::StatePoints;
use super::{
    BoxFuture, DeviceError, DeviceEvent, DeviceKind, Driver, DriverConfig, ErrorKind, Kind,
    PollGroup, Reading, WriteError,
};
use crate::event::{EventKind, Fields, fields};
use crate::point::{
    AlarmRule, Checked, EnumState, PointDescription, PointId, PointKind, PointSpec, Value,
    ValueError,
};
use crate::production::{ProductionPoints, StateDef};
use crate::time::Timestamp;

/// The status, every second.
pub const LIVE: &str = "live";
/// The selected program, every 10 s.
pub const PROGRAM: &str = "program";
/// The production management data, every 10 s.
pub const PRODUCTION: &str = "production";

/// A machine's own keys of `[[line.device]]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Keys {
    /// The machine's Port 2 (R messages), if not the default 49153. The line's endpoint
    /// names Port 1.
    pub event_port: Option<u16>,
}

/// Reads `event_port`.
fn read_keys(
    table: &crate::config::Table<'_>,
) -> Result<crate::config::Settings, crate::config::ConfigError> {
    #[derive(serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Raw {
        event_port: Option<toml::Spanned<i64>>,
    }
    let raw: Raw = table.read()?;
    let Some(port) = raw.event_port else {
        return Ok(crate::config::Settings::default());
    };
    let event_port = u16::try_from(*port.get_ref())
        .ok()
        .filter(|&p| p != 0)
        .ok_or_else(|| {
            table.at(
                port.span(),
                format!(
                    "event_port {} is out of range: 1 to 65535 (the machine's default is {})",
                    port.get_ref(),
                    panasonic::DEFAULT_EVENT_PORT
                ),
            )
        })?;
    Ok(crate::config::Settings::new(Keys {
        event_port: Some(event_port),
    }))
}

/// The poll groups and their default periods.
const GROUPS: [(&str, Duration); 3] = [
    (LIVE, Duration::from_secs(1)),
    (PROGRAM, Duration::from_secs(10)),
    (PRODUCTION, Duration::from_secs(10)),
];

/// The machine states, with their E10 / IPC-CFX codes (the indexes below name them).
pub const MACHINE_STATES: [StateDef; 6] = [
    StateDef::new("run", 1100),
    StateDef::new("ready", 2000),
    StateDef::new("error stop", 5000),
    StateDef::new("parts exhausted", 5500),
    StateDef::new("recovery", 5300),
    StateDef::new("setup", 4500),
];
const RUN: usize = 0;
const READY: usize = 1;
const ERROR_STOP: usize = 2;
const PARTS_EXHAUSTED: usize = 3;
const RECOVERY: usize = 4;
const SETUP: usize = 5;

/// What the machine counts: boards against its plan, pickups and placements for the
/// placement yield, and each board's time (R0CT) for the best cycle.
pub const PRODUCTION_POINTS: ProductionPoints = ProductionPoints {
    boards: "boards_produced",
    planned: Some("boards_planned"),
    pickups: Some("pickups"),
    placed: Some("parts_placed"),
    program: Some("program"),
    cycle_event: Some(("board_finished", "board_time_s")),
};

/// A Panasonic BM placement machine, host computer protocol over TCP (two ports, R events).
#[derive(Debug)]
pub struct Panasonic;

/// The kind's handle, as the config and the line tasks hold it.
pub const KIND: Kind = Kind::new(&Panasonic);

impl DeviceKind for Panasonic {
    fn name(&self) -> &'static str {
        "panasonic"
    }

    fn default_serial(&self) -> link::SerialSettings {
        // Never used: a Panasonic line must be a tcp:// endpoint.
        link::SerialSettings::new_8n1(9600)
    }

    fn default_address(&self) -> Option<i64> {
        None
    }

    fn check_address(&self, address: Option<i64>) -> Result<(), String> {
        check_address(address)
    }

    fn groups(&self) -> &'static [(&'static str, Duration)] {
        &GROUPS
    }

    fn owns_connections(&self) -> Option<&'static str> {
        Some("tcp://host:49152 (its Port 1)")
    }

    fn keys(&self) -> &'static [&'static str] {
        &["event_port"]
    }

    fn read_keys(
        &self,
        table: &crate::config::Table<'_>,
        _device: &super::DeviceContext,
        _scratch: &mut crate::config::Scratch,
    ) -> Result<crate::config::Settings, crate::config::ConfigError> {
        read_keys(table)
    }

    fn foreign_key(
        &self,
        _key: &str,
        value: &toml::Spanned<toml::de::DeValue<'_>>,
        other: &str,
    ) -> (std::ops::Range<usize>, String) {
        (
            value.span(),
            format!("event_port is for Panasonic machines only, not {other} devices"),
        )
    }

    fn build(&self, config: &DriverConfig) -> Result<Box<dyn Driver>, String> {
        Ok(Box::new(PanasonicDriver::new(config)?))
    }

    fn machine_states(&self) -> &'static [StateDef] {
        &MACHINE_STATES
    }

    fn production(&self) -> Option<&'static ProductionPoints> {
        Some(&PRODUCTION_POINTS)
    }
}

/// Checks the address: a Panasonic machine has none (its endpoint says where it is).
pub fn check_address(address: Option<i64>) -> Result<(), String> {
    match address {
        None => Ok(()),
        Some(a) => Err(format!(
            "a Panasonic machine has no address (given {a}): the line's tcp:// endpoint names its Port 1, event_port its Port 2"
        )),
    }
}

/// The run states, numbered for the `state` point (the C2ST digits).
const STATES: [(RunState, i64); 3] = [
    (RunState::Run, 0),
    (RunState::Ready, 1),
    (RunState::Error, 2),
];

fn state_number(state: RunState) -> i64 {
    STATES
        .iter()
        .find(|(s, _)| *s == state)
        .map_or(2, |(_, n)| *n)
}

/// The counters shown, with their point names.
const COUNTERS: [(Counter, &str); 9] = [
    (Counter::ProductPlan1, "boards_planned"),
    (Counter::Product1, "boards_produced"),
    (Counter::Pickup, "pickups"),
    (Counter::Mount, "parts_placed"),
    (Counter::PickupMiss, "pickup_misses"),
    (Counter::PickupError, "pickup_error_stops"),
    (Counter::RecognitionError1, "recognition_errors"),
    (Counter::PartsExhaustCount, "parts_exhaustion_stops"),
    (Counter::PartsExhaustTime, "parts_exhaustion_time"),
];

/// The rates shown, with their point names.
const RATES: [(RateKind, &str); 2] = [
    (RateKind::Pickup, "pickup_rate"),
    (RateKind::Mount, "placement_rate"),
];

/// Where each point's id is in [`PanasonicDriver::ids`]: the run state, the control mode
/// and the program, then [`COUNTERS`], then [`RATES`].
const STATE: usize = 0;
const MODE: usize = 1;
const SELECTED_PROGRAM: usize = 2;
const FIRST_COUNTER: usize = 3;
const FIRST_RATE: usize = FIRST_COUNTER + COUNTERS.len();

/// The points' names, in the order of [`PanasonicDriver::ids`].
fn point_names() -> impl Iterator<Item = &'static str> {
    ["state", "mode", "program"]
        .into_iter()
        .chain(COUNTERS.iter().map(|(_, name)| *name))
        .chain(RATES.iter().map(|(_, name)| *name))
}

/// A placement machine.
pub struct PanasonicDriver {
    /// Each point's id, made once (see [`STATE`] for the order).
    ids: Box<[PointId]>,
    config: ClientConfig,
    client: Option<Client>,
    notices: Option<mpsc::UnboundedReceiver<(Timestamp, Notice)>>,
    forward: Option<JoinHandle<()>>,
    state: Option<RunState>,
    events: Vec<DeviceEvent>,
    /// Port 2 (R messages) cannot be reached: told once, until it connects.
    port2_down: bool,
    /// The machine state points.
    machine: StatePoints,
    /// What the R messages said since the machine last ran.
    told: Told,
}

/// What the R messages told of a stop, for the machine state.
#[derive(Debug, Default)]
struct Told {
    /// The last error stop (R2E): parts exhausted, and its reason in words.
    error: Option<(bool, String)>,
    /// A recovery (R2RS) is under way.
    recovering: bool,
    /// A program was selected (R1SE) while the machine was not running.
    setup: bool,
}

impl Told {
    /// The machine state for run state `state`, and its reason.
    fn state(&self, state: RunState) -> (usize, Option<String>) {
        match state {
            RunState::Run => (RUN, None),
            RunState::Ready if self.setup => (SETUP, None),
            RunState::Ready => (READY, None),
            RunState::Error if self.recovering => (RECOVERY, None),
            RunState::Error => match &self.error {
                Some((true, reason)) => (PARTS_EXHAUSTED, Some(reason.clone())),
                Some((false, reason)) => (ERROR_STOP, Some(reason.clone())),
                None => (ERROR_STOP, None),
            },
        }
    }

    /// Notes what an R message says about the machine's state.
    fn note(&mut self, event: &Event) {
        match event {
            Event::Error(info) => {
                // What a supervisor sorts stops by: the feeder that ran out, the error and
                // its feeder; the step and nozzle are in the R message's event.
                let reason = if info.is_parts_exhausted() {
                    format!("feeder {}", info.feeder())
                } else {
                    format!("error code {}, feeder {}", info.code(), info.feeder())
                };
                self.error = Some((info.is_parts_exhausted(), reason));
                self.recovering = false;
            }
            Event::RecoveryStarted | Event::RecoveryRetry => self.recovering = true,
            Event::RecoveryOk | Event::RecoveryStop => self.recovering = false,
            Event::Se { .. } | Event::SeNg { .. } => self.setup = true,
            Event::Started | Event::ResetDone => {
                self.error = None;
                self.recovering = false;
            }
            _ => {}
        }
    }

    /// The machine runs: every stop is over.
    fn running(&mut self) {
        *self = Told::default();
    }
}

impl Drop for PanasonicDriver {
    fn drop(&mut self) {
        if let Some(task) = &self.forward {
            task.abort();
        }
    }
}

impl PanasonicDriver {
    /// A driver for the machine `config` describes; its endpoint must be `tcp://`.
    pub fn new(config: &DriverConfig) -> Result<Self, String> {
        check_address(config.address)?;
        let (host, port) = match &config.endpoint {
            Some(Endpoint::Tcp { host, port, .. }) => (host.clone(), *port),
            Some(other) => {
                return Err(format!(
                    "a Panasonic machine is reached over TCP (tcp://host:49152), not {other}"
                ));
            }
            None => ("localhost".to_owned(), panasonic::DEFAULT_COMMAND_PORT),
        };
        let mut client = ClientConfig::new(host);
        client.command_port = port;
        client.event_port = Some(
            config
                .settings
                .get::<Keys>()
                .and_then(|keys| keys.event_port)
                .unwrap_or(panasonic::DEFAULT_EVENT_PORT),
        );
        if let Some(timeout) = config.timeout {
            client.timeout = timeout;
            client.connect_timeout = timeout;
        }
        if let Some(retries) = config.retries {
            client.retries = retries;
        }
        Ok(Self {
            ids: super::point_ids(&config.id, point_names()),
            config: client,
            client: None,
            notices: None,
            forward: None,
            state: None,
            events: Vec::new(),
            port2_down: false,
            machine: StatePoints::new(config, &MACHINE_STATES, LIVE),
            told: Told::default(),
        })
    }

    /// The id of the point at `index` (see [`STATE`]).
    fn id(&self, index: usize) -> PointId {
        self.ids[index].clone()
    }

    fn spec(
        &self,
        index: usize,
        title: impl Into<crate::point::Words>,
        unit: Option<&'static str>,
        kind: PointKind,
        group: &'static str,
    ) -> PointSpec {
        PointSpec::new(
            self.id(index),
            PointDescription {
                name: title.into(),
                unit: unit.map(Into::into),
                kind,
                group: group.into(),
                writable: None,
                alarm: None,
            },
        )
    }

    /// The client, connecting on first use.
    async fn client(&mut self) -> Result<&Client, DeviceError> {
        if self.client.is_none() {
            let (client, mut events) = Client::connect(self.config.clone())
                .await
                .map_err(|e| DeviceError::of(&e))?;
            let (tx, rx) = mpsc::unbounded_channel();
            self.forward = Some(tokio::spawn(async move {
                while let Some(notice) = events.next().await {
                    if tx.send((Timestamp::now(), notice)).is_err() {
                        break;
                    }
                }
            }));
            self.notices = Some(rx);
            self.client = Some(client);
        }
        Ok(self.client.as_ref().expect("connected just above"))
    }

    async fn poll_group(&mut self, group: &str) -> Result<Vec<Reading>, DeviceError> {
        let readings = match group {
            LIVE => {
                let status = self
                    .client()
                    .await?
                    .status()
                    .await
                    .map_err(|e| DeviceError::of(&e))?;
                self.note_state(status.state);
                // The R messages that came before this answer refine the state.
                self.drain_notices();
                if status.state == RunState::Run {
                    self.told.running();
                }
                let (machine, reason) = self.told.state(status.state);
                let mut readings = vec![
                    Reading {
                        point: self.id(STATE),
                        value: Ok(Value::Number(state_number(status.state) as f64)),
                    },
                    Reading {
                        point: self.id(MODE),
                        value: Ok(Value::Number(match status.mode {
                            ControlMode::Online => 0.0,
                            ControlMode::Remote => 1.0,
                        })),
                    },
                ];
                readings.extend(self.machine.readings(machine, reason));
                readings
            }
            PROGRAM => {
                let value = match self.client().await?.current_program().await {
                    Ok(name) => Ok(Value::Text(name.to_string())),
                    Err(e @ ClientError::Refused(_)) => Err(DeviceError::of(&e)),
                    Err(e) => return Err(DeviceError::of(&e)),
                };
                vec![Reading {
                    point: self.id(SELECTED_PROGRAM),
                    value,
                }]
            }
            PRODUCTION => {
                let request = ProductionRequest {
                    scope: ProductionScope::GrandTotal,
                    clear: false,
                };
                let data = match self.client().await?.production(request).await {
                    Ok(data) => Ok(data),
                    Err(e @ ClientError::Refused(_)) => Err(DeviceError::of(&e)),
                    Err(e) => return Err(DeviceError::of(&e)),
                };
                let missing = |what: &str| {
                    DeviceError::new(
                        ErrorKind::Decode,
                        format_args!("the production data carry no {what}"),
                    )
                };
                let mut readings = Vec::new();
                for (i, (counter, _)) in COUNTERS.into_iter().enumerate() {
                    let value = match &data {
                        Ok(d) => d
                            .count(counter)
                            .map(|n| Value::Number(f64::from(n)))
                            .ok_or_else(|| missing(counter.key())),
                        Err(e) => Err(e.clone()),
                    };
                    readings.push(Reading {
                        point: self.id(FIRST_COUNTER + i),
                        value,
                    });
                }
                for (i, (rate, _)) in RATES.into_iter().enumerate() {
                    let value = match &data {
                        Ok(d) => d
                            .rate(rate)
                            .map(|r| Value::Number(r.percent()))
                            .ok_or_else(|| missing(rate.key())),
                        Err(e) => Err(e.clone()),
                    };
                    readings.push(Reading {
                        point: self.id(FIRST_RATE + i),
                        value,
                    });
                }
                readings
            }
            other => {
                return Err(DeviceError::new(
                    ErrorKind::Refused,
                    format_args!("a Panasonic machine has no poll group {other:?}"),
                ));
            }
        };
        Ok(readings)
    }

    /// Records a change of the run state.
    fn note_state(&mut self, state: RunState) {
        let Some(old) = self.state.replace(state) else {
            return;
        };
        if old != state {
            self.events.push(DeviceEvent {
                kind: EventKind::StateChanged,
                point: Some("state"),
                message: format!(
                    "machine went from {} to {}",
                    old.describe(),
                    state.describe()
                ),
                at: None,
                fields: fields([
                    ("from", serde_json::json!(old.describe())),
                    ("to", serde_json::json!(state.describe())),
                ]),
            });
        }
    }

    /// What came on Port 2 since the last call.
    fn drain_notices(&mut self) {
        let Some(rx) = self.notices.as_mut() else {
            return;
        };
        let mut notices = Vec::new();
        while let Ok(notice) = rx.try_recv() {
            notices.push(notice);
        }
        for (at, notice) in notices {
            self.record_notice(&notice, at);
        }
    }

    /// Turns a Port 2 notice into an event, unless it is routine (keep-alive echoes,
    /// Port 1's connections: the device's status shows those). Port 2 that cannot be
    /// reached is the events link's own trouble, told once (with `link: "events"` and
    /// `state: "down"`), and again when it connects (`state: "up"`); the machine's
    /// commands and points go on meanwhile.
    fn record_notice(&mut self, notice: &Notice, at: Timestamp) {
        let (message, fields) = match notice {
            Notice::ConnectFailed {
                port: Port::Event,
                endpoint,
                reason,
                ..
            } if !self.port2_down => {
                self.port2_down = true;
                (
                    format!(
                        "Port 2 (R messages) at {endpoint} cannot be reached: {reason}; the machine's commands go on, its R messages are missed until Port 2 connects: check `event_port` (the machine's default is {DEFAULT_EVENT_PORT}) and that the machine's host communication is on"
                    ),
                    fields([
                        ("link", serde_json::json!("events")),
                        ("state", serde_json::json!("down")),
                        ("error", serde_json::json!(reason)),
                    ]),
                )
            }
            Notice::Connected {
                port: Port::Event,
                endpoint,
            } if self.port2_down => {
                self.port2_down = false;
                (
                    format!("Port 2 (R messages) at {endpoint} connected: R messages flow again"),
                    fields([
                        ("link", serde_json::json!("events")),
                        ("state", serde_json::json!("up")),
                    ]),
                )
            }
            Notice::Event(Event::Heartbeat { .. })
            | Notice::Connected { .. }
            | Notice::ConnectFailed { .. } => return,
            Notice::Event(event) => {
                self.told.note(event);
                (format!("R message {event}"), event_fields(event))
            }
            other => (other.to_string(), Fields::new()),
        };
        self.events.push(DeviceEvent {
            kind: EventKind::DeviceEvent,
            point: None,
            message,
            at: Some(at),
            fields,
        });
    }
}

/// An R message's facts: `event` names it (`board_finished`, `parts_exhausted`,
/// `error_stop`, `machine_started`, `recovery_started`, …), the other fields are what the
/// message carries (a board's time in seconds; an error's code, step, nozzle and feeder).
pub fn event_fields(event: &Event) -> Fields {
    use serde_json::json;
    let board = |name: &str, time: &Option<panasonic::event::BoardTime>| {
        fields([
            ("event", json!(name)),
            ("board_time_s", json!(time.map(|t| t.seconds()))),
        ])
    };
    match event {
        Event::BoardFinished { time } => board("board_finished", time),
        Event::ProductionFinished { time } => board("production_finished", time),
        Event::Started => fields([("event", json!("machine_started"))]),
        Event::ResetDone => fields([("event", json!("reset_done"))]),
        Event::RecoveryStarted => fields([("event", json!("recovery_started"))]),
        Event::Heartbeat { .. } => fields([("event", json!("heartbeat"))]),
        Event::Se { program } => fields([
            ("event", json!("program_selected")),
            ("program", json!(program.as_ref().map(ToString::to_string))),
        ]),
        Event::SeNg { program, .. } => fields([
            ("event", json!("program_selection_failed")),
            ("program", json!(program.as_ref().map(ToString::to_string))),
        ]),
        Event::Error(info) => fields([
            (
                "event",
                json!(if info.is_parts_exhausted() {
                    "parts_exhausted"
                } else {
                    "error_stop"
                }),
            ),
            ("error_code", json!(info.code())),
            ("step", json!(info.step())),
            ("nozzle", json!(info.nozzle())),
            ("feeder", json!(info.feeder())),
        ]),
        Event::RecoveryOk => fields([("event", json!("recovery_succeeded"))]),
        Event::RecoveryRetry => fields([("event", json!("recovery_retrying"))]),
        Event::RecoveryStop => fields([("event", json!("recovery_failed_stopped"))]),
    }
}

impl Driver for PanasonicDriver {
    fn points(&self) -> Vec<PointSpec> {
        let mut state = self.spec(
            STATE,
            "Run state",
            None,
            PointKind::Enum {
                states: STATES
                    .iter()
                    .map(|(s, n)| EnumState {
                        value: *n,
                        label: s.describe().into(),
                    })
                    .collect(),
            },
            LIVE,
        );
        Arc::make_mut(&mut state.description).alarm = Some(AlarmRule::Above(1.5));
        let mut points = vec![
            state,
            self.spec(
                MODE,
                "Control mode",
                None,
                PointKind::Enum {
                    states: [ControlMode::Online, ControlMode::Remote]
                        .iter()
                        .zip(0..)
                        .map(|(m, n)| EnumState {
                            value: n,
                            label: m.describe().into(),
                        })
                        .collect(),
                },
                LIVE,
            ),
            self.spec(
                SELECTED_PROGRAM,
                "Selected program",
                None,
                PointKind::Text,
                PROGRAM,
            ),
        ];
        for (i, (counter, _)) in COUNTERS.into_iter().enumerate() {
            let unit = (counter == Counter::PartsExhaustTime).then_some("s");
            let words = counter.describe();
            let title = words.replace(" (s)", "");
            let mut chars = title.chars();
            let title = chars
                .next()
                .map(|c| c.to_uppercase().chain(chars).collect::<String>())
                .unwrap_or_default();
            let index = FIRST_COUNTER + i;
            points.push(self.spec(index, title, unit, PointKind::Numeric, PRODUCTION));
        }
        for (i, (rate, _)) in RATES.into_iter().enumerate() {
            let words = rate.describe();
            let mut chars = words.chars();
            let title: String = chars
                .next()
                .map(|c| c.to_uppercase().chain(chars).collect())
                .unwrap_or_default();
            let index = FIRST_RATE + i;
            points.push(self.spec(index, title, Some("%"), PointKind::Numeric, PRODUCTION));
        }
        points.extend(self.machine.specs());
        points
    }

    fn groups(&self) -> Vec<PollGroup> {
        PollGroup::list(&GROUPS)
    }

    /// The machine's client keeps its own connections: the line is not used.
    fn attach(&mut self, _line: SharedLine) {}

    fn poll<'a>(&'a mut self, group: &'a str) -> BoxFuture<'a, Result<Vec<Reading>, DeviceError>> {
        Box::pin(self.poll_group(group))
    }

    fn write<'a>(
        &'a mut self,
        point: &'a PointSpec,
        _value: &'a Checked,
    ) -> BoxFuture<'a, Result<(), WriteError>> {
        Box::pin(async move {
            Err(WriteError::Invalid(ValueError::ReadOnly {
                point: point.id.clone(),
                name: point.name.to_string(),
            }))
        })
    }

    fn take_events(&mut self) -> Vec<DeviceEvent> {
        self.drain_notices();
        std::mem::take(&mut self.events)
    }
}

#[cfg(test)]
mod tests;
