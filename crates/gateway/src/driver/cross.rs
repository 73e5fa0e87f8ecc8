//! The Chloride CROSS static transfer switch as points, through `jbus::client`.
//!
//! Groups: `live` (1 s: the internal-state and measures areas, two function-3 reads) and
//! `ratings` (60 s: the ratings area). At 9600 baud a `live` poll takes about 120 ms on the
//! wire, so several CROSS units can share one line.
//!
//! Points:
//! - `load_feed`: which source feeds the load and how (static switch, manual bypass), or
//!   that it is disconnected or not supplied; `on_reserve_line`;
//! - `states`: the on/off states of the six operating conditions in words;
//! - one alarm point per condition (`s1_alarms`, `s2_alarms`, `s1_switch_alarms`,
//!   `s2_switch_alarms`, `load_alarms`, `system_alarms`): the active alarms in words, or
//!   `none`; anything else is an alarm, so alarms appearing and clearing are events;
//! - the measures and ratings of `jbus::cross::points` with their units: source, output
//!   and neutral voltages (V), currents (A), frequencies (Hz), load power (kVA), phase
//!   error (°), inlet air (°C), full scales; a three-phase quantity is one point per phase
//!   (`s1_voltage_u`, `s1_voltage_v`, `s1_voltage_w`).
//!
//! A change of `load_feed` between two polls, as `jbus::cross::change` detects it (the
//! changes `cellbus cross watch` prints), is recorded as a `state_changed` event: a
//! transfer (the load moved to the other source) says from which source to which.
//!
//! The CROSS is read-only over JBUS (it answers function 3 only): no point is writable.
//! The mimic diagram area is not shown; the state words say the same in words.

pub mod demo;

use std::sync::LazyLock;
use std::time::Duration;

use jbus::client::{Client, ClientConfig, ClientError, Framing};
use jbus::cross::points::{self, Amount, Phase, Quantity};
use jbus::cross::{
    Area, Change, Discrete, Feed, InternalState, Measures, Ratings, Source, Transfer,
};
use jbus::rtu::UnitId;
use link::{SerialSettings, SharedLine};

use super::machine::StatePoints;
use super::{
    BoxFuture, Described, DeviceError, DeviceEvent, Driver, DriverConfig, ErrorKind, Kind,
    PollGroup, Reading, WriteError, point_ids,
};
use crate::event::EventKind;
use crate::point::{
    AlarmRule, Checked, EnumState, PointDescription, PointId, PointKind, PointSpec, Value,
};
use crate::production::StateDef;

/// A CROSS line when the URL says nothing: 9600 baud, 8N1.
pub const DEFAULT_SERIAL: SerialSettings = SerialSettings::new_8n1(9600);

/// Default JBUS unit number.
pub const DEFAULT_UNIT: i64 = 1;

/// The state and measures, every second.
pub const LIVE: &str = "live";
/// The ratings, every minute.
pub const RATINGS: &str = "ratings";

/// What an alarm point shows when no alarm is active.
const NO_ALARM: &str = "none";

/// The poll groups and their default periods.
const GROUPS: [(&str, Duration); 2] = [
    (LIVE, Duration::from_secs(1)),
    (RATINGS, Duration::from_secs(60)),
];

/// The Chloride CROSS static transfer switch, JBUS (Modbus RTU) units 1–255.
pub const KIND: Kind = Kind::new(&KIND_FACTS);

/// What the config and the line tasks need to know of the kind.
/// The machine states, with their E10 / IPC-CFX codes. The switch's work is the load
/// being fed: fed through a static switch is productive (the alarms active meanwhile are
/// the reason), through a manual bypass the switch is out of service for maintenance,
/// an open output breaker is a planned disconnection, a load not supplied a failure.
pub const MACHINE_STATES: [StateDef; 5] = [
    StateDef::new("load on S1", 1100),
    StateDef::new("load on S2", 1100),
    StateDef::new("load on bypass", 4300),
    StateDef::new("output breaker open", 4000),
    StateDef::new("load not supplied", 5000),
];
const ON_S1: usize = 0;
const ON_S2: usize = 1;
const ON_BYPASS: usize = 2;
const BREAKER_OPEN: usize = 3;
const NOT_SUPPLIED: usize = 4;

/// The machine state of a read internal state, and its reason (the active alarms).
fn judge(internal: &InternalState) -> (usize, Option<String>) {
    let alarms = internal.alarms();
    let reason = (!alarms.is_empty()).then(|| alarms.join(", "));
    let state = match internal.feed() {
        Feed::StaticSwitch(Source::S1) => ON_S1,
        Feed::StaticSwitch(Source::S2) => ON_S2,
        Feed::Bypass(source) => {
            return (ON_BYPASS, Some(format!("through the bypass of {source}")));
        }
        Feed::OutputBreakerOpen => BREAKER_OPEN,
        Feed::NotSupplied => NOT_SUPPLIED,
    };
    (state, reason)
}

const KIND_FACTS: Described = Described {
    name: "cross",
    serial: DEFAULT_SERIAL,
    address: Some(DEFAULT_UNIT),
    check_address,
    groups: &GROUPS,
    speaks_modbus: true,
    build: |config| Ok(Box::new(CrossDriver::new(config)?)),
    machine_states: &MACHINE_STATES,
};

/// Checks a JBUS unit number: 1–255 (JBUS allows numbers above Modbus's 247).
pub fn check_address(address: Option<i64>) -> Result<(), String> {
    unit(address).map(drop)
}

/// The unit number the config gives, checked by [`jbus::rtu::check_unit`] and worded for
/// this kind of device.
fn unit(address: Option<i64>) -> Result<UnitId, String> {
    super::jbus_unit(
        address,
        "a CROSS",
        "JBUS unit number",
        "which the CROSS never answers",
    )
}

/// What a point shows.
#[derive(Clone, Copy)]
enum Show {
    Feed,
    Reserve,
    States,
    Alarms(Condition),
    /// A measure, or one phase of it.
    Measure(&'static Quantity<Measures>, Option<Phase>),
    /// A rating, or one phase of it.
    Rating(&'static Quantity<Ratings>, Option<Phase>),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Condition {
    S1,
    S2,
    S1Switch,
    S2Switch,
    Load,
    System,
}

struct Def {
    name: String,
    title: String,
    unit: Option<&'static str>,
    show: Show,
}

fn def(name: &str, title: &str, show: Show) -> Def {
    Def {
        name: name.to_owned(),
        title: title.to_owned(),
        unit: None,
        show,
    }
}

/// One point per value of `quantity`: `name` for one value, `name_u`… for each phase.
fn quantity_defs<A>(
    quantity: &'static Quantity<A>,
    area: &A,
    show: fn(&'static Quantity<A>, Option<Phase>) -> Show,
) -> Vec<Def> {
    (quantity.read)(area)
        .values()
        .into_iter()
        .map(|(phase, _)| Def {
            name: match phase {
                Some(p) => format!("{}_{}", quantity.name, p.key()),
                None => quantity.name.to_owned(),
            },
            title: match phase {
                Some(p) => format!("{} {p}", quantity.title),
                None => quantity.title.to_owned(),
            },
            unit: quantity.unit,
            show: show(quantity, phase),
        })
        .collect()
}

/// Every point, in the order a person reads them (see [`defs`]): one list for every CROSS
/// driver.
static DEFS: LazyLock<Vec<Def>> = LazyLock::new(defs);

/// Every point, in the order a person reads them: the load, states and alarms, then the
/// measures and ratings of `jbus::cross::points`.
fn defs() -> Vec<Def> {
    let mut defs = vec![
        def("load_feed", "Load fed by", Show::Feed),
        def("on_reserve_line", "Load on reserve line", Show::Reserve),
        def("states", "States", Show::States),
        def("s1_alarms", "Source 1 alarms", Show::Alarms(Condition::S1)),
        def("s2_alarms", "Source 2 alarms", Show::Alarms(Condition::S2)),
        def(
            "s1_switch_alarms",
            "S1 static switch alarms",
            Show::Alarms(Condition::S1Switch),
        ),
        def(
            "s2_switch_alarms",
            "S2 static switch alarms",
            Show::Alarms(Condition::S2Switch),
        ),
        def("load_alarms", "Load alarms", Show::Alarms(Condition::Load)),
        def(
            "system_alarms",
            "System alarms",
            Show::Alarms(Condition::System),
        ),
    ];
    // The shape of a quantity (one value or three) does not depend on the words.
    let measures = Measures::from_words(&[0; Measures::LEN]);
    let ratings = Ratings::from_words(&[0; Ratings::LEN]);
    for quantity in points::MEASURES {
        defs.extend(quantity_defs(quantity, &measures, Show::Measure));
    }
    for quantity in points::RATINGS {
        defs.extend(quantity_defs(quantity, &ratings, Show::Rating));
    }
    defs
}

impl Def {
    fn group(&self) -> &'static str {
        match self.show {
            Show::Rating(..) => RATINGS,
            _ => LIVE,
        }
    }
}

/// The feeds, numbered for the `load_feed` point.
const FEEDS: [(Feed, i64); 6] = [
    (Feed::NotSupplied, 0),
    (Feed::StaticSwitch(Source::S1), 1),
    (Feed::StaticSwitch(Source::S2), 2),
    (Feed::Bypass(Source::S1), 3),
    (Feed::Bypass(Source::S2), 4),
    (Feed::OutputBreakerOpen, 5),
];

fn feed_number(feed: Feed) -> i64 {
    FEEDS
        .iter()
        .find(|(f, _)| *f == feed)
        .map_or(0, |(_, n)| *n)
}

/// A CROSS on a line.
pub struct CrossDriver {
    unit: UnitId,
    config: ClientConfig,
    client: Option<Client>,
    /// Each point's id, in the order of [`DEFS`] (made once: readings share them with the
    /// cell's point specs).
    ids: Box<[PointId]>,
    /// The discrete parts at the last poll, to see transfers.
    last: Option<Discrete>,
    events: Vec<DeviceEvent>,
    /// The good readings of a poll that then failed, until the scheduler takes them.
    partial: Vec<Reading>,
    /// The machine state points.
    machine: StatePoints,
}

impl CrossDriver {
    /// A driver for the CROSS `config` describes.
    pub fn new(config: &DriverConfig) -> Result<Self, String> {
        let unit = unit(config.address)?;
        let defaults = ClientConfig::default();
        Ok(Self {
            unit,
            config: ClientConfig {
                timeout: config.timeout.unwrap_or(defaults.timeout),
                retries: config.retries.unwrap_or(defaults.retries),
                framing: config.endpoint.as_ref().map_or(Framing::Rtu, Framing::of),
                ..defaults
            },
            client: None,
            ids: point_ids(&config.id, DEFS.iter().map(|def| def.name.as_str())),
            last: None,
            events: Vec::new(),
            partial: Vec::new(),
            machine: StatePoints::new(config, &MACHINE_STATES, LIVE),
        })
    }

    fn spec(def: &Def, id: PointId) -> PointSpec {
        let (kind, alarm) = match def.show {
            Show::Feed => (
                PointKind::Enum {
                    states: FEEDS
                        .iter()
                        .map(|(feed, value)| EnumState {
                            value: *value,
                            label: feed.to_string().into(),
                        })
                        .collect(),
                },
                None,
            ),
            Show::Reserve => (
                PointKind::Enum {
                    states: vec![
                        EnumState {
                            value: 0,
                            label: "no".into(),
                        },
                        EnumState {
                            value: 1,
                            label: "yes".into(),
                        },
                    ],
                },
                None,
            ),
            Show::States => (PointKind::Text, None),
            Show::Alarms(_) => (PointKind::Text, Some(AlarmRule::NotText(NO_ALARM))),
            Show::Measure(..) | Show::Rating(..) => (PointKind::Numeric, None),
        };
        PointSpec::new(
            id,
            PointDescription {
                name: def.title.clone().into(),
                unit: def.unit.map(Into::into),
                kind,
                group: def.group().into(),
                writable: None,
                alarm,
            },
        )
    }

    /// Reads one area; `Ok(Err)` when the unit refused it (an exception), which marks only
    /// that area's points.
    async fn read_area(
        &mut self,
        area: Area,
    ) -> Result<Result<Vec<u16>, DeviceError>, DeviceError> {
        let client = self.client.as_mut().ok_or_else(DeviceError::not_attached)?;
        match client
            .read_holding_registers(self.unit, area.start(), area.words())
            .await
        {
            Ok(words) => Ok(Ok(words)),
            Err(e @ ClientError::Refused { .. }) => Ok(Err(DeviceError::of(&e))),
            Err(e) => Err(DeviceError::of(&e)),
        }
    }

    async fn poll_group(&mut self, group: &str) -> Result<Vec<Reading>, DeviceError> {
        self.partial.clear();
        let mut readings = Vec::new();
        if group == LIVE {
            let internal = self
                .read_area(Area::InternalState)
                .await?
                .and_then(|w| words::<{ InternalState::LEN }>(&w, Area::InternalState))
                .map(|w| InternalState::from_words(&w));
            let measures = match self.read_area(Area::Measures).await {
                Ok(measures) => measures
                    .and_then(|w| words::<{ Measures::LEN }>(&w, Area::Measures))
                    .map(|w| Measures::from_words(&w)),
                Err(e) => {
                    // The state was read: its points are kept.
                    self.partial = self.live_readings(&internal, None);
                    self.partial.retain(|r| r.value.is_ok());
                    return Err(e);
                }
            };
            if let Ok(internal) = &internal {
                self.note_changes(internal);
            }
            readings = self.live_readings(&internal, Some(&measures));
            if let Ok(internal) = &internal {
                let (state, reason) = judge(internal);
                readings.extend(self.machine.readings(state, reason));
            }
        } else if group == RATINGS {
            let ratings = self
                .read_area(Area::Ratings)
                .await?
                .and_then(|w| words::<{ Ratings::LEN }>(&w, Area::Ratings))
                .map(|w| Ratings::from_words(&w));
            for (def, id) in DEFS.iter().zip(&self.ids) {
                if def.group() != RATINGS {
                    continue;
                }
                let value = match (def.show, &ratings) {
                    (Show::Rating(quantity, phase), Ok(r)) => Ok(number((quantity.read)(r), phase)),
                    (_, Err(e)) => Err(e.clone()),
                    _ => continue,
                };
                readings.push(Reading {
                    point: id.clone(),
                    value,
                });
            }
        } else {
            return Err(DeviceError::new(
                ErrorKind::Refused,
                format_args!("a CROSS has no poll group {group:?}"),
            ));
        }
        Ok(readings)
    }

    /// The live group's readings from the state and the measures read (the measures'
    /// points left out when they were not read).
    fn live_readings(
        &self,
        internal: &Result<InternalState, DeviceError>,
        measures: Option<&Result<Measures, DeviceError>>,
    ) -> Vec<Reading> {
        DEFS.iter()
            .zip(&self.ids)
            .filter(|(def, _)| def.group() == LIVE)
            .filter_map(|(def, id)| {
                let value = match def.show {
                    Show::Measure(quantity, phase) => measures?
                        .as_ref()
                        .map(|m| number((quantity.read)(m), phase))
                        .map_err(Clone::clone),
                    _ => internal
                        .as_ref()
                        .map(|s| live_value(def.show, s))
                        .map_err(Clone::clone),
                };
                Some(Reading {
                    point: id.clone(),
                    value,
                })
            })
            .collect()
    }

    /// Records a change of what feeds the load (a transfer names both sources), as
    /// `jbus::cross::change` detects it; alarms are events through their points' rules.
    fn note_changes(&mut self, internal: &InternalState) {
        let now = Discrete::of(internal);
        let Some(before) = self.last.replace(now.clone()) else {
            return;
        };
        for change in now.changes_since(&before) {
            let Change::Load { was, now: load } = change else {
                continue;
            };
            if was.feed == load.feed {
                continue;
            }
            let (message, transfer) = match change.transfer() {
                Some(Transfer { from, to }) => (
                    format!(
                        "load transferred from {from} to {to}: {} (was {})",
                        load.feed, was.feed
                    ),
                    Some((from.to_string(), to.to_string())),
                ),
                None => (format!("load {} (was {})", load.feed, was.feed), None),
            };
            let (from, to) = transfer.unzip();
            self.events.push(DeviceEvent {
                kind: EventKind::StateChanged,
                point: Some("load_feed"),
                message,
                at: None,
                fields: crate::event::fields([
                    ("feed", serde_json::json!(load.feed.to_string())),
                    ("was", serde_json::json!(was.feed.to_string())),
                    ("from", serde_json::json!(from)),
                    ("to", serde_json::json!(to)),
                ]),
            });
        }
    }
}

impl Driver for CrossDriver {
    fn points(&self) -> Vec<PointSpec> {
        DEFS.iter()
            .zip(&self.ids)
            .map(|(def, id)| Self::spec(def, id.clone()))
            .chain(self.machine.specs())
            .collect()
    }

    fn groups(&self) -> Vec<PollGroup> {
        PollGroup::list(&GROUPS)
    }

    fn attach(&mut self, line: SharedLine) {
        self.client = Some(Client::new(line, self.config));
    }

    fn poll<'a>(&'a mut self, group: &'a str) -> BoxFuture<'a, Result<Vec<Reading>, DeviceError>> {
        Box::pin(self.poll_group(group))
    }

    fn poll_time(&self, group: &str, serial: SerialSettings) -> Option<Duration> {
        let areas: &[Area] = match group {
            LIVE => &[Area::InternalState, Area::Measures],
            RATINGS => &[Area::Ratings],
            _ => return None,
        };
        Some(super::rtu_reads_time(
            serial,
            areas.iter().map(|a| 2 * usize::from(a.words())),
        ))
    }

    fn write<'a>(
        &'a mut self,
        point: &'a PointSpec,
        _value: &'a Checked,
    ) -> BoxFuture<'a, Result<(), WriteError>> {
        Box::pin(async move {
            Err(WriteError::Invalid(crate::point::ValueError::ReadOnly {
                point: point.id.clone(),
                name: point.name.to_string(),
            }))
        })
    }

    fn take_events(&mut self) -> Vec<DeviceEvent> {
        std::mem::take(&mut self.events)
    }

    fn take_partial(&mut self) -> Vec<Reading> {
        std::mem::take(&mut self.partial)
    }
}

/// A quantity's value (of one phase) as a point value, the nearest short decimal.
fn number(amount: Amount, phase: Option<Phase>) -> Value {
    Value::Number(round(amount.get(phase).unwrap_or(f64::NAN)))
}

fn live_value(show: Show, s: &InternalState) -> Value {
    let text = |t: String| Value::Text(t);
    match show {
        Show::Feed => Value::Number(feed_number(s.feed()) as f64),
        Show::Reserve => Value::Number(if s.on_reserve_line() { 1.0 } else { 0.0 }),
        Show::States => {
            let states = s.conditions();
            text(if states.is_empty() {
                NO_ALARM.to_owned()
            } else {
                states.join(", ")
            })
        }
        Show::Alarms(c) => text(match c {
            Condition::S1 => s.s1.alarm.to_string(),
            Condition::S2 => s.s2.alarm.to_string(),
            Condition::S1Switch => s.s1_switch.alarm.to_string(),
            Condition::S2Switch => s.s2_switch.alarm.to_string(),
            Condition::Load => s.load.alarm.to_string(),
            Condition::System => s.system.alarm.to_string(),
        }),
        Show::Measure(..) | Show::Rating(..) => text(String::new()),
    }
}

/// Scaled register values as the nearest short decimal (230.1, not 230.10000000000002).
fn round(value: f64) -> f64 {
    (value * 1000.0).round() / 1000.0
}

/// An area's words as an array; the client checks the count, so a mismatch is damage.
fn words<const N: usize>(words: &[u16], area: Area) -> Result<[u16; N], DeviceError> {
    words.try_into().map_err(|_| {
        DeviceError::new(
            ErrorKind::Decode,
            format_args!("the {area} area came with {} words, not {N}", words.len()),
        )
    })
}

#[cfg(test)]
mod tests;
