//! One machine as a CFX endpoint, sans IO: what the change stream says of a device (its
//! E10 state code, its production counters and program, its device events, its going
//! down and up) in, the CFX messages it publishes out ([`Station::feed`]). No clock and no
//! randomness: every id is derived from the handle, the message and the time of what
//! caused it (name-based UUIDs), so feeding the same history again gives the same
//! messages with the same `UniqueID`s: a catch-up after an outage or a restart can send
//! them again and a receiver drops the ones it had.
//!
//! What the change stream gives and what CFX gets:
//!
//! | cell | CFX |
//! |---|---|
//! | the state code point (`machine_state_code`) changes | `StationStateChanged` (old state, its duration, new state; the active fault when the new state is a down state) |
//! | a device event `parts_exhausted` (feeder, nozzle, step) | `FaultOccurred` with an SMT placement fault `PartsExhaust` |
//! | a device event `error_stop` (error code, step) | `FaultOccurred` with a fault of that code (the host protocol's other codes say no fault type) |
//! | a device event `recovery_succeeded`, `reset_done` or `machine_started` | `FaultCleared` for each active fault |
//! | a device event `board_finished` (the board's time) | `WorkStarted` back-dated by the board's time, and `WorkCompleted`, one `TransactionID` |
//! | the program point changes | `RecipeActivated` |
//! | the parts placed and pickups counters | `ComponentsPlaced` per window of at most [`WINDOW`] |
//! | the device goes down / up | `StationOffline` / `StationOnline` (with how long) |
//! | time | `Heartbeat` with the active faults, every heartbeat period |
//!
//! The host protocol reports a board only when it is finished: its `WorkStarted` is dated
//! back by the board time the machine reports, and sent just before its `WorkCompleted`.
//! The first state seen (after a start) has the SDK's default old state, non-scheduled
//! (6000), with no duration: the gateway does not know what came before.

use std::time::Duration;

use cfx::messages::{
    ComponentsPlaced, EndpointConnected, EndpointShuttingDown, Fault, FaultCleared, FaultOccurred,
    Heartbeat, Placement, RecipeActivated, StationOffline, StationOnline, StationStateChanged,
    WorkCompleted, WorkStarted,
};
use cfx::types::{FaultCause, FaultSeverity, PlacementFaultType};
use cfx::{Envelope, Handle, Message, ResourceState, Time, TimeSpan};
use serde::{Deserialize, Serialize};
use uuid::Uuid;

use crate::event::{Event, EventKind};
use crate::point::{Quality, Value};
use crate::production::ProductionPoints;
use crate::time::Timestamp;

/// The longest window of one `ComponentsPlaced`.
pub const WINDOW: Duration = Duration::from_secs(600);

/// The SDK's default resource state (non-scheduled), the old state of the first change.
const UNKNOWN_BEFORE: u32 = 6000;

/// The namespace of cellbus's name-based CFX ids.
const NAMESPACE: Uuid = Uuid::from_u128(0x6365_6c6c_6275_7300_8000_0000_6366_7801);

/// What a station needs to know of its machine.
#[derive(Debug, Clone)]
pub struct StationConfig {
    /// The device it speaks for.
    pub device: String,
    /// Its CFX handle.
    pub handle: Handle,
    /// The zone its times are written in (the cell's, or UTC).
    pub zone: jiff::tz::TimeZone,
    /// Its production points (the device kind's).
    pub points: ProductionPoints,
    /// How often it beats.
    pub heartbeat: Duration,
}

/// What comes in.
#[derive(Debug, Clone, Copy)]
pub enum Input<'a> {
    /// One of the device's points changed: its name (without the device), value, quality
    /// and when it was read.
    Value {
        /// The point's name.
        point: &'a str,
        /// Its value.
        value: Option<&'a Value>,
        /// Its quality.
        quality: Option<Quality>,
        /// When it was read.
        at: Timestamp,
    },
    /// An event of the device.
    Event(&'a Event),
    /// Time passed.
    Tick(Timestamp),
}

/// A fault not yet cleared.
#[derive(Debug, Clone, PartialEq)]
struct Active {
    fault: Fault,
}

/// The counts at the start of the placement window.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
struct Window {
    #[serde(with = "millis_serde")]
    start: Timestamp,
    placed: Option<u64>,
    pickups: Option<u64>,
    /// The counts last seen.
    last_placed: Option<u64>,
    last_pickups: Option<u64>,
    #[serde(with = "millis_serde")]
    last_at: Timestamp,
}

/// What a station must know after a restart of the gateway, kept with the messages it
/// made (`store::Outbox`): its state and since when, its open faults (so that their
/// `FaultCleared` still comes), whether the machine is offline, its program, and its
/// placement window. Times in ms since the epoch.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Memory {
    state: Option<(u16, i64)>,
    #[serde(default)]
    faults: Vec<KeptFault>,
    offline_since: Option<i64>,
    program: Option<String>,
    window: Option<Window>,
}

/// An open fault, as kept.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct KeptFault {
    code: String,
    occurrence: Uuid,
    at: i64,
    cause: FaultCause,
    severity: FaultSeverity,
    description: Option<String>,
    transaction: Option<Uuid>,
    placement: Option<(PlacementFaultType, i32, Option<String>, Option<i32>)>,
}

/// A `Timestamp` as its ms.
mod millis_serde {
    use serde::{Deserialize, Deserializer, Serializer};

    use crate::time::Timestamp;

    pub fn serialize<S: Serializer>(t: &Timestamp, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_i64(t.0)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Timestamp, D::Error> {
        i64::deserialize(d).map(Timestamp)
    }
}

/// One machine as a CFX endpoint.
#[derive(Debug, Clone)]
pub struct Station {
    config: StationConfig,
    state: Option<(ResourceState, Timestamp)>,
    faults: Vec<Active>,
    offline_since: Option<Timestamp>,
    program: Option<String>,
    window: Option<Window>,
    last_beat: Option<Timestamp>,
    /// Where its requests go (`amqp://IP:PORT/`), when the gateway listens.
    request_uri: Option<String>,
}

impl Station {
    /// A station not yet told anything.
    pub fn new(config: StationConfig) -> Self {
        Self {
            config,
            state: None,
            faults: Vec::new(),
            offline_since: None,
            program: None,
            window: None,
            last_beat: None,
            request_uri: None,
        }
    }

    /// Says that its requests are answered at `uri` (`amqp://IP:PORT/`, the address its
    /// handle): its `EndpointConnected` tells the line.
    pub fn listens_at(&mut self, uri: &str) {
        self.request_uri = Some(uri.to_owned());
    }

    /// Where its requests are answered, if they are.
    pub fn request_uri(&self) -> Option<&str> {
        self.request_uri.as_deref()
    }

    /// Its handle.
    pub fn handle(&self) -> &Handle {
        &self.config.handle
    }

    /// The device it speaks for.
    pub fn device(&self) -> &str {
        &self.config.device
    }

    /// What it must know after a restart.
    pub fn memory(&self) -> Memory {
        Memory {
            state: self.state.map(|(state, since)| (state.code(), since.0)),
            faults: self
                .faults
                .iter()
                .map(|Active { fault }| KeptFault {
                    code: fault.fault_code.clone(),
                    occurrence: fault.fault_occurrence_id,
                    at: fault.occurred_at.timestamp().as_millisecond(),
                    cause: fault.cause,
                    severity: fault.severity,
                    description: fault.description.clone(),
                    transaction: fault.transaction_id,
                    placement: fault
                        .placement
                        .as_ref()
                        .map(|p| (p.fault_type, p.program_step, p.feeder.clone(), p.nozzle)),
                })
                .collect(),
            offline_since: self.offline_since.map(|t| t.0),
            program: self.program.clone(),
            window: self.window,
        }
    }

    /// Takes up where a station of the same machine was when it kept `memory`.
    pub fn remember(&mut self, memory: Memory) {
        self.state = memory.state.and_then(|(code, since)| {
            Some((ResourceState::new(u32::from(code)).ok()?, Timestamp(since)))
        });
        self.faults = memory
            .faults
            .into_iter()
            .map(|kept| Active {
                fault: Fault {
                    placement: kept
                        .placement
                        .map(|(fault_type, program_step, feeder, nozzle)| Placement {
                            fault_type,
                            program_step,
                            feeder,
                            nozzle,
                        }),
                    transaction_id: kept.transaction,
                    cause: kept.cause,
                    severity: kept.severity,
                    fault_code: kept.code,
                    fault_occurrence_id: kept.occurrence,
                    description: kept.description,
                    occurred_at: self.time(Timestamp(kept.at)),
                },
            })
            .collect();
        self.offline_since = memory.offline_since.map(Timestamp);
        self.program = memory.program;
        self.window = memory.window;
    }

    /// The messages `input` makes.
    pub fn feed(&mut self, input: Input<'_>) -> Vec<Envelope> {
        match input {
            Input::Value {
                point,
                value,
                quality,
                at,
            } => {
                let good = matches!(quality, Some(Quality::Good));
                let value = value.filter(|_| good);
                self.on_value(point, value, at)
            }
            Input::Event(event) => self.on_event(event),
            Input::Tick(now) => self.on_tick(now),
        }
    }

    /// Its `EndpointConnected`, as a connection to the broker starts (`now`).
    pub fn connected(&self, now: Timestamp) -> Envelope {
        let message = Message::EndpointConnected(EndpointConnected {
            cfx_handle: self.config.handle.clone(),
            request_network_uri: self.request_uri.clone(),
            request_target_address: self
                .request_uri
                .as_ref()
                .map(|_| self.config.handle.to_string()),
        });
        self.envelope(now, message, "")
    }

    /// Its `EndpointShuttingDown`, as the gateway stops (`now`).
    pub fn shutting_down(&self, now: Timestamp) -> Envelope {
        let message = Message::EndpointShuttingDown(EndpointShuttingDown {
            cfx_handle: self.config.handle.clone(),
        });
        self.envelope(now, message, "")
    }

    /// The `Heartbeat` due at `now`, with the active faults.
    pub fn heartbeat(&mut self, now: Timestamp) -> Envelope {
        self.last_beat = Some(now);
        let message = Message::Heartbeat(Heartbeat {
            cfx_handle: self.config.handle.clone(),
            heartbeat_frequency: TimeSpan(self.config.heartbeat),
            active_faults: self.faults.iter().map(|a| a.fault.clone()).collect(),
            active_recipes: Vec::new(),
        });
        self.envelope(now, message, "")
    }

    fn on_value(&mut self, point: &str, value: Option<&Value>, at: Timestamp) -> Vec<Envelope> {
        let points = self.config.points;
        if point == crate::production::states::CODE_POINT {
            return self.on_state(value, at);
        }
        if Some(point) == points.program {
            let Some(Value::Text(program)) = value else {
                return Vec::new();
            };
            if program.is_empty() || self.program.as_deref() == Some(program) {
                return Vec::new();
            }
            self.program = Some(program.clone());
            let message = Message::RecipeActivated(RecipeActivated::named(program.clone()));
            return vec![self.envelope(at, message, program)];
        }
        let count = value.and_then(Value::as_number).and_then(whole);
        let placed = Some(point) == points.placed;
        let pickups = Some(point) == points.pickups;
        if !(placed || pickups) {
            return Vec::new();
        }
        let Some(count) = count else {
            return Vec::new();
        };
        let window = self.window.get_or_insert(Window {
            start: at,
            placed: None,
            pickups: None,
            last_placed: None,
            last_pickups: None,
            last_at: at,
        });
        let (first, last) = if placed {
            (&mut window.placed, &mut window.last_placed)
        } else {
            (&mut window.pickups, &mut window.last_pickups)
        };
        // A counter that went back was reset at the machine: counting starts again.
        if first.is_none() || last.is_some_and(|l| count < l) {
            *first = Some(count);
        }
        *last = Some(count);
        window.last_at = at;
        self.close_window(at)
    }

    /// A `ComponentsPlaced` when the window has lasted [`WINDOW`] by `now`, and a new
    /// window from there.
    fn close_window(&mut self, now: Timestamp) -> Vec<Envelope> {
        let Some(window) = self.window else {
            return Vec::new();
        };
        if now.0 - window.start.0 < millis(WINDOW) {
            return Vec::new();
        }
        let placed = delta(window.placed, window.last_placed);
        let picked = delta(window.pickups, window.last_pickups);
        self.window = Some(Window {
            start: window.last_at,
            placed: window.last_placed,
            pickups: window.last_pickups,
            ..window
        });
        if placed == 0 && picked == 0 {
            return Vec::new();
        }
        let message = Message::ComponentsPlaced(ComponentsPlaced {
            start_time: self.time(window.start),
            end_time: self.time(window.last_at),
            total_components_placed: placed,
            total_components_not_placed: picked.saturating_sub(placed),
        });
        vec![self.envelope(window.last_at, message, "")]
    }

    fn on_state(&mut self, value: Option<&Value>, at: Timestamp) -> Vec<Envelope> {
        let Some(code) = value.and_then(Value::as_number).and_then(whole) else {
            return Vec::new();
        };
        let Ok(new) = ResourceState::new(u32::try_from(code).unwrap_or(u32::MAX)) else {
            return Vec::new();
        };
        let (old, duration) = match self.state {
            Some((old, _)) if old == new => return Vec::new(),
            Some((old, since)) => (old, Some(span(since, at))),
            None => (ResourceState::new(UNKNOWN_BEFORE).unwrap_or(new), None),
        };
        self.state = Some((new, at));
        let down = new.code() / 1000 == 5;
        let message = Message::StationStateChanged(StationStateChanged {
            old_state: old,
            old_state_duration: duration,
            new_state: new,
            related_fault: down
                .then(|| self.faults.last().map(|a| a.fault.clone()))
                .flatten(),
        });
        vec![self.envelope(at, message, &new.code().to_string())]
    }

    fn on_event(&mut self, event: &Event) -> Vec<Envelope> {
        let at = event.t;
        match event.kind {
            EventKind::DeviceDown if self.offline_since.is_none() => {
                self.offline_since = Some(at);
                let message = Message::StationOffline(StationOffline {});
                return vec![self.envelope(at, message, "")];
            }
            EventKind::DeviceUp => {
                let Some(since) = self.offline_since.take() else {
                    return Vec::new();
                };
                let message = Message::StationOnline(StationOnline {
                    offline_duration: Some(span(since, at)),
                });
                return vec![self.envelope(at, message, "")];
            }
            EventKind::DeviceEvent => {}
            _ => return Vec::new(),
        }
        let field = |name: &str| event.fields.get(name);
        let number = |name: &str| field(name).and_then(serde_json::Value::as_i64);
        match field("event").and_then(serde_json::Value::as_str) {
            Some(what @ ("parts_exhausted" | "error_stop")) => {
                let code = number("error_code").unwrap_or_default();
                let fault_code = format!("E{code:02}");
                let exhausted = what == "parts_exhausted";
                let fault = Fault {
                    placement: exhausted.then(|| Placement {
                        fault_type: PlacementFaultType::PartsExhaust,
                        program_step: number("step")
                            .and_then(|s| i32::try_from(s).ok())
                            .unwrap_or_default(),
                        feeder: number("feeder").map(|f| f.to_string()),
                        nozzle: number("nozzle").and_then(|n| i32::try_from(n).ok()),
                    }),
                    transaction_id: None,
                    cause: if exhausted {
                        FaultCause::Refill
                    } else {
                        FaultCause::MechanicalFailure
                    },
                    severity: FaultSeverity::Error,
                    fault_occurrence_id: self.id("fault", at, &fault_code),
                    fault_code,
                    description: Some(event.message.clone()),
                    occurred_at: self.time(at),
                };
                self.faults.push(Active {
                    fault: fault.clone(),
                });
                let message = Message::FaultOccurred(FaultOccurred { fault });
                vec![self.envelope(at, message, "")]
            }
            Some("recovery_succeeded" | "reset_done" | "machine_started") => {
                std::mem::take(&mut self.faults)
                    .into_iter()
                    .map(|active| {
                        let id = active.fault.fault_occurrence_id;
                        let message = Message::FaultCleared(FaultCleared {
                            fault_occurrence_id: id,
                            operator: None,
                        });
                        self.envelope(at, message, &id.to_string())
                    })
                    .collect()
            }
            Some(name) if Some(name) == self.config.points.cycle_event.map(|(e, _)| e) => {
                let time_field = self.config.points.cycle_event.map(|(_, f)| f);
                let seconds = time_field
                    .and_then(field)
                    .and_then(serde_json::Value::as_f64)
                    .filter(|s| s.is_finite() && *s >= 0.0);
                let started = match seconds {
                    Some(s) => Timestamp(at.0 - (s * 1000.0).round() as i64),
                    None => at,
                };
                let transaction_id = self.id("board", at, "");
                let start =
                    Message::WorkStarted(WorkStarted::board(transaction_id, self.program.clone()));
                let end = Message::WorkCompleted(WorkCompleted::board(transaction_id));
                vec![
                    self.envelope(started, start, &at.0.to_string()),
                    self.envelope(at, end, ""),
                ]
            }
            _ => Vec::new(),
        }
    }

    fn on_tick(&mut self, now: Timestamp) -> Vec<Envelope> {
        let mut out = self.close_window(now);
        let due = self
            .last_beat
            .is_none_or(|last| now.0 - last.0 >= millis(self.config.heartbeat));
        if due {
            out.push(self.heartbeat(now));
        }
        out
    }

    /// A message of this station's, happened `at`; `extra` tells apart two messages of
    /// one kind at one time.
    fn envelope(&self, at: Timestamp, message: Message, extra: &str) -> Envelope {
        let unique_id = self.id(message.name(), at, extra);
        Envelope {
            unique_id,
            ..Envelope::new(self.config.handle.clone(), self.time(at), message)
        }
    }

    /// The name-based id of `what` at `at`.
    fn id(&self, what: &str, at: Timestamp, extra: &str) -> Uuid {
        let name = format!("{}/{what}/{}/{extra}", self.config.handle, at.0);
        Uuid::new_v5(&NAMESPACE, name.as_bytes())
    }

    fn time(&self, at: Timestamp) -> Time {
        let at = jiff::Timestamp::from_millisecond(at.0).unwrap_or(jiff::Timestamp::UNIX_EPOCH);
        Time::new(at, &self.config.zone)
    }
}

/// A count as a whole number, if it is one.
fn whole(n: f64) -> Option<u64> {
    (n.is_finite() && n >= 0.0 && n.fract() == 0.0 && n < u64::MAX as f64).then_some(n as u64)
}

/// What a counter grew by in a window.
fn delta(first: Option<u64>, last: Option<u64>) -> u64 {
    match (first, last) {
        (Some(first), Some(last)) => last.saturating_sub(first),
        _ => 0,
    }
}

/// The time from `since` to `at`.
fn span(since: Timestamp, at: Timestamp) -> TimeSpan {
    TimeSpan(Duration::from_millis(
        u64::try_from(at.0 - since.0).unwrap_or_default(),
    ))
}

fn millis(duration: Duration) -> i64 {
    i64::try_from(duration.as_millis()).unwrap_or(i64::MAX)
}

#[cfg(test)]
mod tests;
