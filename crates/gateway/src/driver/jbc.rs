//! The JBC JTSE hot-air station as points, through `jbc::client`.
//!
//! Groups: `live` (1 s: temperatures, power, set points, status, errors, tool), `settings`
//! (10 s: limits, adjust temperatures, work mode, external set point) and `info` (60 s:
//! model and counters). At 19200 baud one read takes about 20 ms on the wire, so `live`
//! keeps the line about 20 % busy.
//!
//! Writes: set points, limits, adjust temperatures, work mode and the tool (on/off, written
//! as the port status `00001`/`00000`). Ranges are the JTSE's ([`jbc::device`]'s constants);
//! set points are also checked against the station's own limits (`MIT`/`MAT`, `MIF`/`MAF`,
//! `MIE`/`MAE`) as last read, so a value the station would refuse with NAK 3 never goes out.
//!
//! # Damaged frames the block check misses
//!
//! The frame's block check is an XOR of its bytes, so two flipped bits in the same place of
//! two characters cancel out (`00000` → `80800` passes): the noise soak met one in a
//! million requests. So:
//!
//! - A value outside what the station can show (a writable point's range, -50 to 999 °C,
//!   0 to 100 %, 0 to 1000 ‰) is bad, not good.
//! - A changed value of any code except the live measurements (air and external
//!   temperature, power) is *confirmed* before it is recorded or used as a write limit:
//!   it is accepted when it equals the last confirmed value of its code, or when a second
//!   read right away gives the same. When the two disagree, the poll gives no reading for
//!   the code's points (they keep their last value, and turn stale if this lasts), or a
//!   bad one when there is no confirmed value yet. An acknowledged write confirms the
//!   value written. A steady station costs no extra request.
//! - The live measurements change between two reads and are only range-checked: the
//!   user guide states the residual risk (docs/guide/src/jbc.md).

pub mod demo;

use std::ops::RangeInclusive;
use std::sync::{Arc, LazyLock};
use std::time::Duration;

use jbc::client::{Client, ClientConfig, ClientError, ExchangeError};
use jbc::code::{Code, Port, StationError, Tool, ToolError};
use jbc::device::{ADJUST_TEMP_RANGE, AIR_FLOW_RANGE, AIR_TEMP_RANGE, EXTERNAL_TEMP_RANGE};
use jbc::frame::{Address, Route};
use link::{SerialSettings, SharedLine};

use super::machine::{StatePoints, number_in};
use super::{
    BoxFuture, Described, DeviceError, Driver, DriverConfig, ErrorKind, Kind, PollGroup, Reading,
    WriteError, enum_states, point_ids,
};
use crate::point::{
    AlarmRule, Checked, DeviceId, PointDescription, PointId, PointKind, PointSpec, Value,
    ValueError, WriteRange,
};
use crate::production::StateDef;

/// A JTSE's line when the URL says nothing: 19200 baud, 8E1 (the manual's example).
pub const DEFAULT_SERIAL: SerialSettings = SerialSettings::new_8e1(19200);

/// Default station address (factory setting).
pub const DEFAULT_ADDRESS: i64 = 1;

/// Group read every second.
pub const LIVE: &str = "live";
/// Group read every 10 s.
pub const SETTINGS: &str = "settings";
/// Group read every minute.
pub const INFO: &str = "info";

use Meaning::{OnOff, Quantity};

const PORT: Port = Port::One;

/// The JBC JTSE hot-air station, RS-232 (the station–robot protocol).
pub const KIND: Kind = Kind::new(&KIND_FACTS);

/// What the config and the line tasks need to know of the kind.
const KIND_FACTS: Described = Described {
    name: "jbc",
    serial: DEFAULT_SERIAL,
    address: Some(DEFAULT_ADDRESS),
    check_address,
    groups: &GROUPS,
    speaks_modbus: false,
    build: |config| Ok(Box::new(JbcDriver::new(config)?)),
    machine_states: &MACHINE_STATES,
};

/// Checks a station address: 0–99, or `None` for the form without addresses.
pub fn check_address(address: Option<i64>) -> Result<(), String> {
    match address {
        None => Ok(()),
        Some(a) if (0..=i64::from(Address::MAX)).contains(&a) => Ok(()),
        Some(a) => Err(format!(
            "JBC station address {a} is out of range: 0 to {} (factory default {DEFAULT_ADDRESS}), or \"none\" for the form without addresses",
            Address::MAX
        )),
    }
}

/// Which part of a code's value a point shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Part {
    /// The whole value.
    Whole,
    /// One digit of the port status (1 = tool on, 10 = cooling, 100 = suction).
    StatusDigit(i32),
}

/// What a point's value means.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Meaning {
    Quantity,
    Text,
    OnOff,
    ToolError,
    StationError,
    Tool,
    WorkMode,
}

/// One point of the station.
struct Def {
    name: &'static str,
    title: &'static str,
    code: Code,
    part: Part,
    group: &'static str,
    meaning: Meaning,
    /// The JTSE's range for writes, if writable.
    range: Option<RangeInclusive<i32>>,
    /// Codes holding the lower and upper limit the station applies to writes.
    limits: Option<(Code, Code)>,
}

const fn def(
    name: &'static str,
    title: &'static str,
    code: Code,
    group: &'static str,
    meaning: Meaning,
) -> Def {
    Def {
        name,
        title,
        code,
        part: Part::Whole,
        group,
        meaning,
        range: None,
        limits: None,
    }
}

const fn writable(mut d: Def, range: RangeInclusive<i32>) -> Def {
    d.range = Some(range);
    d
}

const fn limited(mut d: Def, low: Code, high: Code) -> Def {
    d.limits = Some((low, high));
    d
}

const fn digit(mut d: Def, place: i32) -> Def {
    d.part = Part::StatusDigit(place);
    d
}

/// Temperatures a JTSE can show at all, °C; a reading outside was damaged on the line.
const PLAUSIBLE_TEMP: RangeInclusive<i32> = -50..=999;

/// A code's answer in one poll.
enum Answer {
    /// Plausible and, where needed, confirmed.
    Good(jbc::Reading),
    /// Two reads disagreed and the points keep their confirmed value: no reading.
    Unconfirmed,
    /// Why the points are bad.
    Bad(DeviceError),
}

impl Def {
    /// The values the station can show for this point, where that is known.
    fn plausible(&self) -> Option<RangeInclusive<i32>> {
        if let Some(range) = &self.range {
            return Some(range.clone());
        }
        if self.part != Part::Whole || self.meaning != Quantity {
            return None;
        }
        match self.code.unit()? {
            jbc::code::Unit::Celsius => Some(PLAUSIBLE_TEMP),
            jbc::code::Unit::Percent => Some(0..=100),
            jbc::code::Unit::Permille => Some(0..=1000),
            jbc::code::Unit::Hours | jbc::code::Unit::Cycles => None,
        }
    }

    /// A value outside what the station can show is damage, not a reading.
    fn check_plausible(&self, value: &Value) -> Result<(), DeviceError> {
        let (Some(range), Some(n)) = (self.plausible(), value.as_number()) else {
            return Ok(());
        };
        if n >= f64::from(*range.start()) && n <= f64::from(*range.end()) {
            return Ok(());
        }
        Err(DeviceError::new(
            ErrorKind::Decode,
            format_args!(
                "{} ({}) read as {n}, outside what the station can show ({} to {}): damaged \
                 on the line?",
                self.title,
                self.code,
                range.start(),
                range.end()
            ),
        ))
    }

    /// Whether a changed value is confirmed by a second read: all but the live
    /// measurements, which change between two reads.
    fn confirmed(&self) -> bool {
        !(self.meaning == Quantity && self.range.is_none() && self.group == LIVE)
    }
}

/// Every point, in the order a person reads them.
const POINTS: &[Def] = &[
    def(
        "air_temperature",
        "Air temperature",
        Code::AirTemp(PORT),
        LIVE,
        Quantity,
    ),
    limited(
        writable(
            def(
                "air_temperature_setpoint",
                "Selected air temperature",
                Code::SelectAirTemp(PORT),
                LIVE,
                Quantity,
            ),
            AIR_TEMP_RANGE,
        ),
        Code::MinAirTemp,
        Code::MaxAirTemp,
    ),
    limited(
        writable(
            def(
                "air_flow_setpoint",
                "Selected air flow",
                Code::SelectAirFlow(PORT),
                LIVE,
                Quantity,
            ),
            AIR_FLOW_RANGE,
        ),
        Code::MinAirFlow,
        Code::MaxAirFlow,
    ),
    def(
        "external_temperature",
        "External temperature",
        Code::ExternalTemp(PORT),
        LIVE,
        Quantity,
    ),
    def("power", "Power", Code::PortPower(PORT), LIVE, Quantity),
    writable(
        digit(
            def("tool_on", "Tool on", Code::PortStatus(PORT), LIVE, OnOff),
            1,
        ),
        0..=1,
    ),
    digit(
        def("cooling", "Cooling", Code::PortStatus(PORT), LIVE, OnOff),
        10,
    ),
    digit(
        def("suction", "Suction", Code::PortStatus(PORT), LIVE, OnOff),
        100,
    ),
    def(
        "tool_error",
        "Tool error",
        Code::PortError(PORT),
        LIVE,
        Meaning::ToolError,
    ),
    def(
        "station_error",
        "Station error",
        Code::StationError,
        LIVE,
        Meaning::StationError,
    ),
    def(
        "connected_tool",
        "Connected tool",
        Code::ConnectedTool(PORT),
        LIVE,
        Meaning::Tool,
    ),
    limited(
        writable(
            def(
                "external_temperature_setpoint",
                "Selected external temperature",
                Code::SelectExternalTemp(PORT),
                SETTINGS,
                Quantity,
            ),
            EXTERNAL_TEMP_RANGE,
        ),
        Code::MinExternalTemp,
        Code::MaxExternalTemp,
    ),
    writable(
        def(
            "work_mode",
            "Work mode",
            Code::WorkMode(PORT),
            SETTINGS,
            Meaning::WorkMode,
        ),
        0..=1,
    ),
    writable(
        def(
            "adjust_jt",
            "Adjust temperature, JT tool",
            Code::AdjustTemp(PORT, Tool::Jt),
            SETTINGS,
            Quantity,
        ),
        ADJUST_TEMP_RANGE,
    ),
    writable(
        def(
            "adjust_te",
            "Adjust temperature, TE tool",
            Code::AdjustTemp(PORT, Tool::Te),
            SETTINGS,
            Quantity,
        ),
        ADJUST_TEMP_RANGE,
    ),
    writable(
        def(
            "max_air_temperature",
            "Maximum air temperature",
            Code::MaxAirTemp,
            SETTINGS,
            Quantity,
        ),
        AIR_TEMP_RANGE,
    ),
    writable(
        def(
            "min_air_temperature",
            "Minimum air temperature",
            Code::MinAirTemp,
            SETTINGS,
            Quantity,
        ),
        AIR_TEMP_RANGE,
    ),
    writable(
        def(
            "max_air_flow",
            "Maximum air flow",
            Code::MaxAirFlow,
            SETTINGS,
            Quantity,
        ),
        AIR_FLOW_RANGE,
    ),
    writable(
        def(
            "min_air_flow",
            "Minimum air flow",
            Code::MinAirFlow,
            SETTINGS,
            Quantity,
        ),
        AIR_FLOW_RANGE,
    ),
    writable(
        def(
            "max_external_temperature",
            "Maximum external temperature",
            Code::MaxExternalTemp,
            SETTINGS,
            Quantity,
        ),
        EXTERNAL_TEMP_RANGE,
    ),
    writable(
        def(
            "min_external_temperature",
            "Minimum external temperature",
            Code::MinExternalTemp,
            SETTINGS,
            Quantity,
        ),
        EXTERNAL_TEMP_RANGE,
    ),
    def(
        "model",
        "Station model",
        Code::StationModel,
        INFO,
        Meaning::Text,
    ),
    def(
        "plugged_hours",
        "Plugged hours",
        Code::PluggedHours(PORT),
        INFO,
        Quantity,
    ),
    def(
        "work_hours",
        "Work hours",
        Code::WorkHours(PORT),
        INFO,
        Quantity,
    ),
    def(
        "tool_cycles",
        "Tool cycles",
        Code::ToolCycles(PORT),
        INFO,
        Quantity,
    ),
    def(
        "suction_cycles",
        "Suction cycles",
        Code::SuctionCycles(PORT),
        INFO,
        Quantity,
    ),
];

/// The machine states, with their E10 / IPC-CFX codes: hot air flowing is work, a tool
/// missing is waiting for a support tool, a tool or station error a failure.
pub const MACHINE_STATES: [StateDef; 5] = [
    StateDef::new("in use", 1100),
    StateDef::new("idle", 2000),
    StateDef::new("no tool", 2300),
    StateDef::new("tool error", 5000),
    StateDef::new("station error", 5000),
];
const IN_USE: usize = 0;
const IDLE: usize = 1;
const NO_TOOL: usize = 2;
const TOOL_ERROR: usize = 3;
const STATION_ERROR: usize = 4;

/// The machine state a `live` poll's readings show, and its reason; `None` when the
/// poll did not read the errors and the tool's status.
fn judge(readings: &[Reading]) -> Option<(usize, Option<String>)> {
    let station = number_in(readings, "station_error")?;
    let tool = number_in(readings, "tool_error")?;
    let on = number_in(readings, "tool_on")?;
    let words = |n: f64| ToolError::from_code(n as i32).map(ToolError::words);
    Some(if station != 0.0 {
        let words = StationError::from_code(station as i32).map(StationError::words);
        let words = words.unwrap_or("unknown station error");
        (STATION_ERROR, Some(words.to_owned()))
    } else if tool == f64::from(ToolError::NoTool.code())
        || number_in(readings, "connected_tool") == Some(f64::from(Tool::None.number()))
    {
        (NO_TOOL, None)
    } else if tool != 0.0 && tool != f64::from(ToolError::CheckingTool.code()) {
        let words = words(tool).unwrap_or("unknown tool error");
        (TOOL_ERROR, Some(words.to_owned()))
    } else if on == 1.0 {
        (IN_USE, None)
    } else {
        (IDLE, None)
    })
}

/// A JBC station on a line.
pub struct JbcDriver {
    device: DeviceId,
    config: ClientConfig,
    client: Option<Client>,
    /// The id of each of [`POINTS`], in order: a reading clones one (a reference count),
    /// and the specs hold the same ones.
    ids: Box<[PointId]>,
    /// The last confirmed value of each code that is confirmed (see the module doc); the
    /// limit codes among them check set points before the wire.
    confirmed: Confirmed,
    /// The good readings of a poll that then failed, until the scheduler takes them.
    partial: Vec<Reading>,
    /// The machine state points.
    machine: StatePoints,
}

/// The last confirmed value of each code: a few codes, so a short list searched in
/// order, made as long as the codes that can be confirmed (a `HashMap` each, or a list
/// grown by doubling, was a kilobyte per station).
#[derive(Debug)]
struct Confirmed(Vec<(Code, jbc::code::Value)>);

/// How many codes can be confirmed: those of a point confirmed by a second read or
/// written.
static CONFIRMABLE_CODES: LazyLock<usize> = LazyLock::new(|| {
    let mut codes: Vec<Code> = Vec::new();
    for d in POINTS.iter().filter(|d| d.confirmed() || d.range.is_some()) {
        if !codes.contains(&d.code) {
            codes.push(d.code);
        }
    }
    codes.len()
});

impl Default for Confirmed {
    fn default() -> Self {
        Self(Vec::with_capacity(*CONFIRMABLE_CODES))
    }
}

impl Confirmed {
    /// The confirmed value of `code`, if there is one.
    fn get(&self, code: Code) -> Option<&jbc::code::Value> {
        self.0.iter().find(|(c, _)| *c == code).map(|(_, v)| v)
    }

    /// Notes `value` as the confirmed value of `code`.
    fn insert(&mut self, code: Code, value: jbc::code::Value) {
        match self.0.iter_mut().find(|(c, _)| *c == code) {
            Some((_, v)) => *v = value,
            None => self.0.push((code, value)),
        }
    }
}

impl JbcDriver {
    /// A driver for the station `config` describes.
    pub fn new(config: &DriverConfig) -> Result<Self, String> {
        let defaults = ClientConfig::default();
        let route = match config.address {
            None => None,
            Some(a) => {
                let target = u8::try_from(a)
                    .ok()
                    .and_then(|a| Address::new(a).ok())
                    .ok_or_else(|| format!("JBC station address {a} is out of range"))?;
                Some(Route {
                    source: Address::ROBOT,
                    target,
                })
            }
        };
        let ids = point_ids(&config.id, POINTS.iter().map(|def| def.name));
        Ok(Self {
            device: config.id.clone(),
            ids,
            config: ClientConfig {
                route,
                timeout: config.timeout.unwrap_or(defaults.timeout),
                retries: config.retries.unwrap_or(defaults.retries),
            },
            client: None,
            confirmed: Confirmed::default(),
            partial: Vec::new(),
            machine: StatePoints::new(config, &MACHINE_STATES, LIVE),
        })
    }
}

/// The description of every point in [`POINTS`], built once for every station.
static DESCRIPTIONS: LazyLock<Vec<Arc<PointDescription>>> =
    LazyLock::new(|| POINTS.iter().map(|d| Arc::new(describe(d))).collect());

/// How each group is read, worked out once for every station: its points and the codes
/// they need, so a poll compares no group names and scans no list for a code's points.
static PLANS: LazyLock<Vec<GroupPlan>> = LazyLock::new(|| {
    let mut plans: Vec<GroupPlan> = Vec::new();
    for (index, def) in POINTS.iter().enumerate() {
        let at = match plans.iter().position(|p| p.group == def.group) {
            Some(at) => at,
            None => {
                plans.push(GroupPlan {
                    group: def.group,
                    points: Vec::new(),
                    reads: Vec::new(),
                });
                plans.len() - 1
            }
        };
        let plan = &mut plans[at];
        let read = match plan.reads.iter().position(|r| r.code == def.code) {
            Some(read) => read,
            None => {
                plan.reads.push(CodeRead {
                    code: def.code,
                    defs: Vec::new(),
                });
                plan.reads.len() - 1
            }
        };
        plan.reads[read].defs.push(def);
        plan.points.push((index, read));
    }
    plans
});

/// The groups and their default periods.
const GROUPS: [(&str, Duration); 3] = [
    (LIVE, Duration::from_secs(1)),
    (SETTINGS, Duration::from_secs(10)),
    (INFO, Duration::from_secs(60)),
];

/// What a poll of one group sends and gives, the same for every station.
#[derive(Debug, Clone, PartialEq)]
pub struct GroupReads {
    /// The group's name.
    pub group: &'static str,
    /// Its default period.
    pub period: Duration,
    /// The codes a poll reads, one request each, in the order it sends them (a changed
    /// value of a code that is confirmed is read a second time: see the module doc).
    pub codes: Vec<Code>,
    /// The points a poll gives.
    pub points: usize,
}

/// What a poll of each group sends and gives. The load bench's floor (`--bare`) sends
/// the same requests at the same periods with nothing of the gateway around them.
pub fn group_reads() -> Vec<GroupReads> {
    GROUPS
        .iter()
        .map(|&(group, period)| {
            let plan = PLANS.iter().find(|p| p.group == group);
            GroupReads {
                group,
                period,
                codes: plan.map_or_else(Vec::new, |p| p.reads.iter().map(|r| r.code).collect()),
                points: plan.map_or(0, |p| p.points.len()),
            }
        })
        .collect()
}

/// How one group is read.
struct GroupPlan {
    group: &'static str,
    /// Its points in [`POINTS`] order: the index of each there and of its code's read in
    /// `reads`, which are in the order their first point needs them.
    points: Vec<(usize, usize)>,
    reads: Vec<CodeRead>,
}

/// One code read in a group, and the group's points it gives.
struct CodeRead {
    code: Code,
    defs: Vec<&'static Def>,
}

/// What `def`'s point is, the same on every station.
fn describe(def: &Def) -> PointDescription {
    let (kind, unit, alarm) = match def.meaning {
        Quantity => (
            PointKind::Numeric,
            def.code.unit().map(|u| u.symbol().into()),
            None,
        ),
        Meaning::Text => (PointKind::Text, None, None),
        OnOff => (enum_states([(0, "off"), (1, "on")]), None, None),
        Meaning::ToolError => (
            enum_states(ToolError::ALL.iter().map(|e| (e.code(), e.words()))),
            None,
            Some(AlarmRule::NotEqual(f64::from(ToolError::Ok.code()))),
        ),
        Meaning::StationError => (
            enum_states(StationError::ALL.iter().map(|e| (e.code(), e.words()))),
            None,
            Some(AlarmRule::NotEqual(f64::from(StationError::Ok.code()))),
        ),
        Meaning::Tool => (
            enum_states(Tool::ALL.iter().map(|t| (t.number(), t.words()))),
            None,
            None,
        ),
        Meaning::WorkMode => (
            enum_states([(0, "manual (profiles off)"), (1, "profile (profiles on)")]),
            None,
            None,
        ),
    };
    PointDescription {
        name: def.title.into(),
        unit,
        kind,
        group: def.group.into(),
        writable: def.range.as_ref().map(|r| WriteRange {
            min: f64::from(*r.start()),
            max: f64::from(*r.end()),
            integer: true,
            step: None,
        }),
        alarm,
    }
}

impl JbcDriver {
    async fn poll_group(&mut self, group: &str) -> Result<Vec<Reading>, DeviceError> {
        self.partial.clear();
        let Some(plan) = PLANS.iter().find(|p| p.group == group) else {
            return Ok(Vec::new());
        };
        let mut answers: Vec<Option<Answer>> = Vec::with_capacity(plan.reads.len());
        answers.resize_with(plan.reads.len(), || None);
        let mut readings = Vec::with_capacity(plan.points.len());
        for &(index, read) in &plan.points {
            if answers[read].is_none() {
                let code = &plan.reads[read];
                match self.read_code(code.code, &code.defs).await {
                    Ok(answer) => answers[read] = Some(answer),
                    Err(e) => {
                        // The points read so far are kept (a code's points are
                        // neighbours in the list, so no later point has its read done).
                        readings.retain(|r: &Reading| r.value.is_ok());
                        self.partial = readings;
                        return Err(e);
                    }
                }
            }
            let Some(answer) = &answers[read] else {
                continue;
            };
            let value = match answer {
                // `read_code` found the value plausible for every point of the code.
                Answer::Good(reading) => Ok(value_of(reading, POINTS[index].part)),
                Answer::Unconfirmed => continue,
                Answer::Bad(e) => Err(e.clone()),
            };
            readings.push(Reading {
                point: self.ids[index].clone(),
                value,
            });
        }
        if group == LIVE
            && let Some((state, reason)) = judge(&readings)
        {
            readings.extend(self.machine.readings(state, reason));
        }
        Ok(readings)
    }

    /// The confirmed number of `code`, if there is one.
    fn confirmed_number(&self, code: Code) -> Option<i32> {
        match self.confirmed.get(code)? {
            jbc::code::Value::Number(n) => Some(*n),
            jbc::code::Value::Text(_) => None,
        }
    }

    /// Reads `code` for the points `of` a group it gives, checks its value is plausible
    /// for each of them, and confirms a changed value by a second read (see the module
    /// doc). `Err` only when the station cannot be reached at all.
    async fn read_code(&mut self, code: Code, of: &[&Def]) -> Result<Answer, DeviceError> {
        let client = self.client.as_mut().ok_or_else(DeviceError::not_attached)?;
        let first = match client.read(code).await {
            Ok(reading) => reading,
            Err(e) if point_level(&e) => return Ok(Answer::Bad(DeviceError::of(&e))),
            Err(e) => return Err(DeviceError::of(&e)),
        };
        let defs = || of.iter().copied();
        if let Some(error) = defs().find_map(|d| d.check_plausible(&value_of(&first, d.part)).err())
        {
            return Ok(Answer::Bad(error));
        }
        let value = first.value();
        if !defs().any(Def::confirmed) || self.confirmed.get(code) == Some(&value) {
            return Ok(Answer::Good(first));
        }
        let second = client.read(code).await;
        let agree = matches!(&second, Ok(again) if again.value() == value);
        if agree {
            self.confirmed.insert(code, value);
            return Ok(Answer::Good(first));
        }
        let why = match second {
            Ok(again) => format!("read as {first}, then as {again}"),
            Err(e) if point_level(&e) => format!("read as {first}, then {}", DeviceError::of(&e)),
            Err(e) => return Err(DeviceError::of(&e)),
        };
        tracing::warn!(device = %self.device, %code, "two reads disagree, not recorded: {why}");
        if self.confirmed.get(code).is_some() {
            Ok(Answer::Unconfirmed)
        } else {
            Ok(Answer::Bad(DeviceError::new(
                ErrorKind::Decode,
                format_args!("{code} {why}: not recorded until two reads agree"),
            )))
        }
    }

    async fn write_point(&mut self, point: &PointSpec, value: &Checked) -> Result<(), WriteError> {
        let def = POINTS
            .iter()
            .find(|d| d.name == point.id.name())
            .ok_or_else(|| WriteError::UnknownPoint {
                point: point.id.clone(),
            })?;
        let number = value.number();
        // Whole and within the JTSE's range (check_write), so it fits an i32.
        let number = number as i32;
        if let Some((low, high)) = def.limits
            && let (Some(min), Some(max)) =
                (self.confirmed_number(low), self.confirmed_number(high))
            && !(min..=max).contains(&number)
        {
            return Err(WriteError::Invalid(ValueError::OutOfRange {
                point: point.id.clone(),
                name: format!("{}, limited by the station's {low}/{high}", point.name),
                value: f64::from(number),
                min: f64::from(min),
                max: f64::from(max),
                unit: point
                    .unit
                    .as_deref()
                    .map(|u| format!(" {u}"))
                    .unwrap_or_default(),
            }));
        }
        let client = self.client.as_mut().ok_or_else(DeviceError::not_attached)?;
        client
            .write(def.code, number)
            .await
            .map_err(|e| WriteError::Device(DeviceError::of(&e)))?;
        // Acknowledged: the station holds what was written.
        self.confirmed
            .insert(def.code, jbc::code::Value::Number(number));
        Ok(())
    }
}

impl Driver for JbcDriver {
    fn points(&self) -> Vec<PointSpec> {
        self.ids
            .iter()
            .zip(DESCRIPTIONS.iter())
            .map(|(id, description)| PointSpec::new(id.clone(), Arc::clone(description)))
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

    fn take_partial(&mut self) -> Vec<Reading> {
        std::mem::take(&mut self.partial)
    }

    fn poll_time(&self, group: &str, serial: SerialSettings) -> Option<Duration> {
        let plan = PLANS.iter().find(|p| p.group == group)?;
        // Each code read once (a confirmation's second read comes only on a change): the
        // request and the answer with its data, on the wire.
        let (request, answer) = match self.config.route {
            Some(_) => (jbc::frame::LEN_ADDRESSED, jbc::frame::LEN_ADDRESSED_DATA),
            None => (jbc::frame::LEN_SHORT, jbc::frame::LEN_SHORT_DATA),
        };
        Some(serial.time_for(plan.reads.len() * (request + answer)))
    }

    fn write<'a>(
        &'a mut self,
        point: &'a PointSpec,
        value: &'a Checked,
    ) -> BoxFuture<'a, Result<(), WriteError>> {
        Box::pin(self.write_point(point, value))
    }
}

fn value_of(reading: &jbc::Reading, part: Part) -> Value {
    match (reading.value(), part) {
        (jbc::code::Value::Number(n), Part::Whole) => Value::Number(f64::from(n)),
        (jbc::code::Value::Number(n), Part::StatusDigit(place)) => {
            Value::Number(f64::from((n / place) % 10))
        }
        (jbc::code::Value::Text(t), _) => Value::Text(t),
    }
}

/// Whether a failed read concerns one code only (the station answered, just not with a
/// value), so the other points of the poll are still read.
fn point_level(error: &ClientError) -> bool {
    matches!(
        error,
        ClientError::BadValue { .. }
            | ClientError::Exchange(ExchangeError::Refused { .. } | ExchangeError::Request(_))
    )
}

#[cfg(test)]
mod tests;
