//! Thermosald ISC impulse-sealer regulators as points, through `thermosald::client`.
//!
//! Each regulator (address 0–7) is one device; several on one RS-485 line share its
//! scheduler, which polls them in turn, and its [`link::SharedLine`], whose quiet times
//! carry the protocol's 40/200/40 ms windows from one regulator's client to the next.
//!
//! Groups, one table read (one message) each: `live` (2 s: the run-time table —
//! temperature, the fault/warning number in words, current, resistance, voltage, power),
//! `settings` (10 s: set points and balancing), `machine` (60 s: gains, ramp, limits) and
//! `service` (60 s: the sealing band and its supply). An exchange takes about 300 ms at
//! 9600 baud (200 ms until the answer, 40 ms release, wire time), so three regulators
//! with `live` at 2 s keep the line about half busy and leave room for the slow groups
//! and writes; `live` at 1 s for three regulators would fill it.
//!
//! Names and units come from the crate's tables ([`thermosald::tables`]), the fault number
//! from [`thermosald::diagnostic`]. The `fault` point is an alarm whenever it is not 0
//! (ready), so a fault appearing or clearing is recorded as an event.
//!
//! Writes: the set points and balancing data of the settings table, and the control data of
//! the machine table (not the address or the serial switch, which would cut the gateway
//! off). Each is checked against the item's range and step before the wire (a tenths item
//! takes 12.5, not 12.55), and the sealing and pre-heating set points also against the
//! maximum working temperature as confirmed (below). Writes go to the regulator's working
//! memory; saving them to EEPROM is left to `cellbus thermosald`, on purpose.
//!
//! # Damaged digits: range check and confirmation
//!
//! Thermosald messages carry no checksum, and 30 of the 80 single-bit flips of an ASCII
//! digit give another digit, so a reply damaged on the line can decode as a plausible wrong
//! value. The driver defends in two ways:
//!
//! - A value outside its item's range ([`tables::Reading::in_range`]: 50–60 Hz, a `1 = …`
//!   switch, an address 0–7) is a bad point for this poll, with an error naming the item,
//!   the value and the range; it is never recorded as good.
//! - Settings, machine and service values, and the fault/warning number, are *confirmed*:
//!   a value is recorded (published, stored, used as the write limit) only when it equals
//!   the last confirmed value of its item, or when a second read right away, in the same
//!   poll, gives the same digits. The first value after start is confirmed the same way.
//!   The second read is one item (one changed item) or the table again (several, as on the
//!   first poll). When the reads disagree, or the second read fails, the poll gives no
//!   reading for the point, so it keeps its last recorded value and time (and turns stale
//!   if that lasts, like any point not refreshed); with no confirmed value yet, the point
//!   is bad for this poll. The next poll tries again. The write limit stays the last
//!   confirmed maximum working temperature. A write whose echo matched is confirmed by
//!   it, and a set-point write before the maximum working temperature is confirmed reads
//!   that limit twice first. In a steady state no second read is needed: each changed
//!   value costs one extra exchange (about 250 ms), once.
//! - The other run-time values (temperature, current, resistance, voltage, power) change
//!   too fast to compare two reads and are only range-checked: a digit damaged into another
//!   digit gives a wrong value until the next `live` poll.
//!
//! Confirmed values are kept while a regulator is silent: a value read again that equals
//! one of them is accepted (a damaged digit would have to land exactly on it), and any
//! other value is confirmed anew.

pub mod demo;

use std::collections::BTreeMap;
use std::time::Duration;

use link::{SerialSettings, SharedLine};
use thermosald::client::{Client, ClientConfig, ClientError};
use thermosald::diagnostic::{self, Fault};
use thermosald::exchange::Values;
use thermosald::tables::{self, Item, Table, machine, runtime, service, settings};
use thermosald::{Address, RawValue, Read, Target};

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

/// A Thermosald line when the URL says nothing: 9600 baud, 8N1 (the spec's).
pub const DEFAULT_SERIAL: SerialSettings = SerialSettings::new_8n1(9600);

/// Default regulator address.
pub const DEFAULT_ADDRESS: i64 = 0;

/// Highest regulator address.
pub const MAX_ADDRESS: i64 = 7;

/// The run-time table, every 2 s.
pub const LIVE: &str = "live";
/// The settings table, every 10 s.
pub const SETTINGS: &str = "settings";
/// The machine table, every minute.
pub const MACHINE: &str = "machine";
/// The service table, every minute.
pub const SERVICE: &str = "service";

/// The poll groups and their default periods.
const GROUPS: [(&str, Duration); 4] = [
    (LIVE, Duration::from_secs(2)),
    (SETTINGS, Duration::from_secs(10)),
    (MACHINE, Duration::from_secs(60)),
    (SERVICE, Duration::from_secs(60)),
];

/// Thermosald ISC impulse-sealer regulators, addresses 0–7 on one RS-485 line.
pub const KIND: Kind = Kind::new(&KIND_FACTS);

/// What the config and the line tasks need to know of the kind.
const KIND_FACTS: Described = Described {
    name: "thermosald",
    serial: DEFAULT_SERIAL,
    address: Some(DEFAULT_ADDRESS),
    check_address,
    groups: &GROUPS,
    speaks_modbus: false,
    build: |config| Ok(Box::new(ThermosaldDriver::new(config)?)),
    machine_states: &MACHINE_STATES,
};

/// The machine states, with their E10 / IPC-CFX codes: a band fired in the cycle under
/// way (its power or the cycle's peak current above 0) is the sealer at work, a band not
/// fired is ready, a calibration is equipment engineering, a fault number a
/// failure. A poll every 2 s cannot see each impulse of a 3 s rhythm, and a state that
/// flipped with each would fill the history: the regulator firing at all is the state.
pub const MACHINE_STATES: [StateDef; 4] = [
    StateDef::new("sealing", 1100),
    StateDef::new("ready", 2000),
    StateDef::new("calibrating", 3200),
    StateDef::new("fault", 5000),
];
const SEALING: usize = 0;
const READY: usize = 1;
const CALIBRATING: usize = 2;
const FAULT: usize = 3;

/// The machine state a run-time poll's readings show, and its reason; `None` when the
/// poll did not read the fault and the power.
fn judge(readings: &[Reading]) -> Option<(usize, Option<String>)> {
    let fault = number_in(readings, "fault")?;
    // The peak current of the cycle under way stays up between its impulses, when the
    // power is 0 while the band cools.
    let power = number_in(readings, "power")?.max(number_in(readings, "maximum_current")?);
    let code = fault as u16;
    Some(match code {
        diagnostic::NONE if power > 0.0 => (SEALING, None),
        diagnostic::NONE => (READY, None),
        diagnostic::CALIBRATION_REQUEST | diagnostic::CALIBRATION_IN_PROGRESS => {
            (CALIBRATING, Some(diagnostic::describe(code).to_owned()))
        }
        _ => (
            FAULT,
            Some(format!("fault {code}: {}", diagnostic::describe(code))),
        ),
    })
}

/// Checks a regulator address: 0–7.
pub fn check_address(address: Option<i64>) -> Result<(), String> {
    match address {
        Some(a) if (0..=MAX_ADDRESS).contains(&a) => Ok(()),
        Some(a) => Err(format!(
            "Thermosald regulator address {a} is out of range: 0 to {MAX_ADDRESS} (machine data item 14)"
        )),
        None => Err(format!(
            "a Thermosald regulator needs its address, 0 to {MAX_ADDRESS}"
        )),
    }
}

/// What a point's value means.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Meaning {
    /// The item's scaled value with its unit.
    Quantity,
    /// The fault/warning number, in words.
    Fault,
    /// A `1 = …` switch.
    Switch,
}

/// One point of a regulator.
struct Def {
    name: &'static str,
    table: Table,
    index: u8,
    meaning: Meaning,
    writable: bool,
    /// Limited by the maximum working temperature (settings item 11).
    below_max_working: bool,
}

const fn def(name: &'static str, table: Table, index: u8) -> Def {
    Def {
        name,
        table,
        index,
        meaning: Meaning::Quantity,
        writable: false,
        below_max_working: false,
    }
}

const fn rw(mut d: Def) -> Def {
    d.writable = true;
    d
}

const fn meaning(mut d: Def, meaning: Meaning) -> Def {
    d.meaning = meaning;
    d
}

const fn limited(mut d: Def) -> Def {
    d.below_max_working = true;
    d
}

use Table::{Machine as M, Runtime as RT, Service as SV, Settings as ST};

/// Every point, table by table, in the order a person reads them.
const POINTS: &[Def] = &[
    def("temperature", RT, runtime::TEMPERATURE),
    meaning(def("fault", RT, runtime::FAULT), Meaning::Fault),
    def("maximum_current", RT, runtime::MAXIMUM_CURRENT),
    def("resistance", RT, runtime::RESISTANCE),
    def("voltage", RT, runtime::VOLTAGE),
    def("power", RT, runtime::POWER),
    limited(rw(def(
        "sealing_temperature",
        ST,
        settings::SEALING_TEMPERATURE,
    ))),
    limited(rw(def(
        "preheat_temperature",
        ST,
        settings::PRE_HEATING_TEMPERATURE,
    ))),
    rw(def(
        "max_working_temperature",
        ST,
        settings::MAXIMUM_WORKING_TEMPERATURE,
    )),
    rw(def(
        "balancing_temperature",
        ST,
        settings::BALANCING_TEMPERATURE,
    )),
    rw(def("cooling_gradient", ST, settings::COOLING_GRADIENT)),
    rw(def("heating_factor", ST, settings::HEATING_FACTOR)),
    rw(def("heating_ramp", M, machine::HEATING_RAMP)),
    rw(def("kv_gain", M, 2)),
    rw(def("kint_gain", M, machine::KINT_GAIN)),
    rw(def("kint_threshold", M, 4)),
    rw(def("kd_gain", M, 11)),
    rw(def("max_sealing_time", M, machine::MAXIMUM_SEALING_TIME)),
    rw(def(
        "short_circuit_factor",
        M,
        machine::PARTIAL_SHORT_CIRCUIT_FACTOR,
    )),
    rw(def("nominal_current", M, 10)),
    rw(meaning(
        def("cold_structure_compensation", M, 12),
        Meaning::Switch,
    )),
    def("mains_frequency", M, 6),
    meaning(
        def("serial_enabled", M, machine::SERIAL_ENABLING),
        Meaning::Switch,
    ),
    def("address", M, machine::ADDRESS),
    rw(def("burn_in_temperature", M, 21)),
    rw(def("burn_in_time", M, 22)),
    def("band_width", SV, service::WIDTH),
    def("band_thickness", SV, service::THICKNESS),
    def("band_length", SV, service::LENGTH),
    def("bands_in_parallel", SV, service::IN_PARALLEL),
    def("bands_in_series", SV, service::IN_SERIES),
    def("duty_cycle", SV, service::DUTY_CYCLE),
    def("set_maximum_current", SV, service::SET_MAXIMUM_CURRENT),
    def("set_voltage", SV, service::SET_VOLTAGE),
    def("set_power", SV, service::SET_POWER),
    def("theoretical_current", SV, service::THEORETICAL_CURRENT),
    def("theoretical_voltage", SV, service::THEORETICAL_VOLTAGE),
    def("theoretical_power", SV, service::THEORETICAL_POWER),
];

impl Def {
    fn item(&self) -> &'static Item {
        self.table
            .item(self.index)
            .expect("POINTS names items that exist (checked by a test)")
    }

    fn group(&self) -> &'static str {
        group_of(self.table)
    }

    /// Whether a changed value must be read twice before it is recorded: every settings,
    /// machine and service value, and the fault/warning number (see the module doc).
    fn confirmed(&self) -> bool {
        self.table != Table::Runtime || self.meaning == Meaning::Fault
    }

    /// The point's value for an item's reading.
    fn value(&self, reading: tables::Reading) -> Value {
        Value::Number(match self.meaning {
            Meaning::Quantity => reading.value(),
            Meaning::Fault | Meaning::Switch => f64::from(reading.raw().get()),
        })
    }
}

fn group_of(table: Table) -> &'static str {
    match table {
        Table::Runtime => LIVE,
        Table::Settings => SETTINGS,
        Table::Machine => MACHINE,
        Table::Service => SERVICE,
    }
}

fn table_of(group: &str) -> Option<Table> {
    Table::ALL.into_iter().find(|t| group_of(*t) == group)
}

/// One regulator on a line.
pub struct ThermosaldDriver {
    device: DeviceId,
    config: ClientConfig,
    client: Option<Client>,
    /// The last confirmed raw value of each confirmed item (see the module doc), by table
    /// and index; the maximum working temperature among them is the write limit.
    confirmed: BTreeMap<(Table, u8), RawValue>,
    /// Each point's id, in the order of [`POINTS`] (made once: readings share them with
    /// the cell's point specs).
    ids: Box<[PointId]>,
    /// The machine state points.
    machine: StatePoints,
}

impl ThermosaldDriver {
    /// A driver for the regulator `config` describes.
    pub fn new(config: &DriverConfig) -> Result<Self, String> {
        let address = config
            .address
            .and_then(|a| u8::try_from(a).ok())
            .and_then(|a| Address::new(a).ok())
            .ok_or_else(|| "Thermosald regulator address out of range".to_owned())?;
        let mut client = ClientConfig::new(Target::Address(address));
        client.timeout = config.timeout;
        if let Some(retries) = config.retries {
            client.retries = retries;
        }
        Ok(Self {
            device: config.id.clone(),
            config: client,
            client: None,
            confirmed: BTreeMap::new(),
            ids: point_ids(&config.id, POINTS.iter().map(|def| def.name)),
            machine: StatePoints::new(config, &MACHINE_STATES, LIVE),
        })
    }

    fn spec(def: &Def, id: PointId) -> PointSpec {
        let item = def.item();
        let symbol = item.unit().symbol();
        let unit = (!symbol.is_empty()).then(|| symbol.into());
        let (kind, unit, alarm) = match def.meaning {
            Meaning::Quantity => (PointKind::Numeric, unit, None),
            Meaning::Fault => (
                enum_states(
                    [
                        diagnostic::NONE,
                        diagnostic::CALIBRATION_REQUEST,
                        diagnostic::CALIBRATION_IN_PROGRESS,
                    ]
                    .into_iter()
                    .chain(Fault::ALL.iter().map(|f| f.code()))
                    .map(|code| (code, diagnostic::describe(code))),
                ),
                None,
                Some(AlarmRule::NotEqual(f64::from(diagnostic::NONE))),
            ),
            Meaning::Switch => (enum_states([(0, "off"), (1, "on")]), None, None),
        };
        let step = item.scale().step();
        PointSpec::new(
            id,
            PointDescription {
                name: item.name().into(),
                unit,
                kind,
                group: def.group().into(),
                writable: (def.writable && item.writable()).then(|| WriteRange {
                    min: item.min(),
                    max: item.max(),
                    integer: step.fract() == 0.0,
                    step: (step != 1.0).then_some(step),
                }),
                alarm,
            },
        )
    }

    async fn poll_group(&mut self, group: &str) -> Result<Vec<Reading>, DeviceError> {
        let table = table_of(group).ok_or_else(|| {
            DeviceError::new(
                ErrorKind::Refused,
                format_args!("Thermosald regulators have no poll group {group:?}"),
            )
        })?;
        let client = self.client.as_mut().ok_or_else(DeviceError::not_attached)?;
        let first = client
            .read_table(table)
            .await
            .map_err(|e| DeviceError::of(&e))?;
        // The table's points, with their places in `POINTS`.
        let defs: Vec<(usize, &'static Def)> = POINTS
            .iter()
            .enumerate()
            .filter(|(_, d)| d.table == table)
            .collect();
        // What the first read settles (`None`: nothing to record this poll), and the
        // readings that need a second read.
        let mut outcomes: Vec<Option<Result<Value, DeviceError>>> = Vec::new();
        let mut changed: Vec<(usize, tables::Reading)> = Vec::new();
        for (i, &(_, def)) in defs.iter().enumerate() {
            let outcome = match checked(def, &first) {
                Ok(reading)
                    if def.confirmed()
                        && self.confirmed.get(&(table, def.index)) != Some(&reading.raw()) =>
                {
                    changed.push((i, reading));
                    None
                }
                Ok(reading) => Some(Ok(def.value(reading))),
                Err(bad) => Some(Err(bad)),
            };
            outcomes.push(outcome);
        }
        if !changed.is_empty() {
            let second = match changed.as_slice() {
                [(_, reading)] => client.read(Read::item(reading.item())).await,
                _ => client.read_table(table).await,
            };
            for (i, reading) in changed {
                let (_, def) = defs[i];
                let confirmation = match &second {
                    Ok(values) => self.confirm(reading, values),
                    Err(e) => Err(unconfirmed_after_failure(reading, e)),
                };
                outcomes[i] = match confirmation {
                    Ok(()) => Some(Ok(def.value(reading))),
                    // The point keeps what it has: no reading this poll.
                    Err(_) if self.confirmed.contains_key(&(table, def.index)) => None,
                    Err(why) => Some(Err(why)),
                };
            }
        }
        let mut readings: Vec<Reading> = defs
            .iter()
            .zip(outcomes)
            .filter_map(|(&(at, _), outcome)| {
                outcome.map(|value| Reading {
                    point: self.ids[at].clone(),
                    value,
                })
            })
            .collect();
        if group == LIVE
            && let Some((state, reason)) = judge(&readings)
        {
            readings.extend(self.machine.readings(state, reason));
        }
        Ok(readings)
    }

    /// Records `first` as its item's confirmed value when the `second` read agrees; else
    /// says how they differ.
    fn confirm(&mut self, first: tables::Reading, second: &Values) -> Result<(), DeviceError> {
        let item = first.item();
        match second.get(item) {
            Some(again) if again.raw() == first.raw() => {
                self.confirmed
                    .insert((item.table(), item.index()), first.raw());
                Ok(())
            }
            again => {
                let again = again.map_or_else(|| "nothing".to_owned(), |r| r.to_string());
                tracing::warn!(
                    device = %self.device,
                    table = %item.table(),
                    item = item.name(),
                    first = %first,
                    second = %again,
                    "two reads disagree (damaged on the line?); the value is not recorded"
                );
                Err(DeviceError::new(
                    ErrorKind::Decode,
                    format_args!(
                        "{} item {:?}: two reads disagree ({first}, then {again}; damaged on \
                         the line?); not recorded until two reads agree",
                        item.table(),
                        item.name()
                    ),
                ))
            }
        }
    }

    /// The maximum working temperature as last confirmed, °C: the limit of the set points.
    fn max_working(&self) -> Option<f64> {
        let item = max_working_item();
        self.confirmed
            .get(&(item.table(), item.index()))
            .map(|raw| item.from_raw(*raw))
    }

    /// The confirmed maximum working temperature; when none is confirmed yet (no settings
    /// poll since start, or its reads disagreed), reads it twice now.
    async fn confirmed_max_working(&mut self) -> Result<f64, DeviceError> {
        if let Some(max) = self.max_working() {
            return Ok(max);
        }
        let item = max_working_item();
        let client = self.client.as_mut().ok_or_else(DeviceError::not_attached)?;
        let first = client
            .read(Read::item(item))
            .await
            .map_err(|e| DeviceError::of(&e))?;
        let first = first
            .get(item)
            .filter(tables::Reading::in_range)
            .ok_or_else(|| {
                DeviceError::new(
                    ErrorKind::Decode,
                    format_args!("the answer carries no valid {}", item.name()),
                )
            })?;
        let second = client
            .read(Read::item(item))
            .await
            .map_err(|e| DeviceError::of(&e))?;
        self.confirm(first, &second)?;
        Ok(first.value())
    }

    async fn write_point(&mut self, point: &PointSpec, value: &Checked) -> Result<(), WriteError> {
        let def = POINTS
            .iter()
            .find(|d| d.name == point.id.name())
            .ok_or_else(|| WriteError::UnknownPoint {
                point: point.id.clone(),
            })?;
        let number = value.number();
        let item = def.item();
        let limit = if def.below_max_working {
            Some(
                self.confirmed_max_working()
                    .await
                    .map_err(|why| WriteError::Device(limit_unknown(why)))?,
            )
        } else {
            None
        };
        if let Some(max) = limit
            && number > max
        {
            return Err(WriteError::Invalid(ValueError::OutOfRange {
                point: point.id.clone(),
                name: format!(
                    "{}, limited by the regulator's maximum working temperature",
                    point.name
                ),
                value: number,
                min: item.min(),
                max,
                unit: point
                    .unit
                    .as_deref()
                    .map(|u| format!(" {u}"))
                    .unwrap_or_default(),
            }));
        }
        // The crate's own check (range, step) once more, so nothing it would refuse is sent.
        let raw = item
            .to_raw(number)
            .map_err(|e| WriteError::Invalid(value_error(point, e)))?;
        let client = self.client.as_mut().ok_or_else(DeviceError::not_attached)?;
        client
            .write_raw(item, raw)
            .await
            .map_err(|e| WriteError::Device(DeviceError::of(&e)))?;
        // The regulator echoed exactly what was sent: the value is confirmed.
        self.confirmed.insert((item.table(), item.index()), raw);
        Ok(())
    }
}

impl Driver for ThermosaldDriver {
    fn points(&self) -> Vec<PointSpec> {
        POINTS
            .iter()
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
        // One table read: the question, the regulator's 200 ms, the answer and the 40 ms
        // release before the next question (the manual's timing).
        let table = table_of(group)?;
        let exchange =
            thermosald::exchange::Exchange::new(self.config.target, Read::all(table).into())
                .ok()?;
        let timing =
            thermosald::exchange::LineTiming::new(serial.baud, serial.bits_per_char()).ok()?;
        Some(timing.poll_cycle(exchange.query().wire_len(), exchange.reply_len()))
    }

    fn write<'a>(
        &'a mut self,
        point: &'a PointSpec,
        value: &'a Checked,
    ) -> BoxFuture<'a, Result<(), WriteError>> {
        Box::pin(self.write_point(point, value))
    }
}

/// The reading of `def`'s item in `values`, if the answer carries it and it is within the
/// item's range; else why the point is bad.
fn checked(def: &Def, values: &Values) -> Result<tables::Reading, DeviceError> {
    let item = def.item();
    let reading = values.get(item).ok_or_else(|| {
        DeviceError::new(
            ErrorKind::Decode,
            format_args!("the answer carries no {}", item.name()),
        )
    })?;
    if reading.in_range() {
        return Ok(reading);
    }
    let bound = |raw| {
        RawValue::new(raw).map_or_else(|_| raw.to_string(), |raw| item.reading(raw).to_string())
    };
    Err(DeviceError::new(
        ErrorKind::Decode,
        format_args!(
            "{} item {:?} read as {reading} (digits {:03}), outside its range {} to {}: \
             damaged on the line?",
            item.table(),
            item.name(),
            reading.raw().get(),
            bound(item.raw_min()),
            bound(item.raw_max()),
        ),
    ))
}

/// Why a changed value is not recorded when its second read failed.
fn unconfirmed_after_failure(first: tables::Reading, error: &ClientError) -> DeviceError {
    let item = first.item();
    let cause = DeviceError::of(error);
    DeviceError::new(
        cause.kind,
        format_args!(
            "{} item {:?} read as {first}, not recorded: the confirming read failed: {}",
            item.table(),
            item.name(),
            cause.message
        ),
    )
}

/// A set-point write refused because the limit could not be confirmed.
fn limit_unknown(why: DeviceError) -> DeviceError {
    DeviceError::new(
        why.kind,
        format_args!(
            "not written: the regulator's maximum working temperature, which limits the set \
             points, could not be confirmed ({why})"
        ),
    )
}

/// Settings item 11, the limit of the sealing and pre-heating set points.
fn max_working_item() -> &'static Item {
    Table::Settings
        .item(settings::MAXIMUM_WORKING_TEMPERATURE)
        .expect("settings data has item 11")
}

/// The crate's refusal of a value, as the gateway's.
fn value_error(point: &PointSpec, error: tables::ValueError) -> ValueError {
    let unit = |u: tables::Unit| {
        let s = u.symbol();
        if s.is_empty() {
            String::new()
        } else {
            format!(" {s}")
        }
    };
    match error {
        tables::ValueError::OutOfRange {
            value,
            min,
            max,
            unit: u,
            ..
        } => ValueError::OutOfRange {
            point: point.id.clone(),
            name: point.name.to_string(),
            value,
            min,
            max,
            unit: unit(u),
        },
        tables::ValueError::NotAStep {
            value,
            step,
            unit: u,
            ..
        } => ValueError::NotAStep {
            point: point.id.clone(),
            name: point.name.to_string(),
            value,
            step,
            unit: unit(u),
        },
        other => ValueError::WrongType {
            point: point.id.clone(),
            expected: "a number".into(),
            got: other.to_string(),
        },
    }
}

#[cfg(test)]
mod tests;
