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

use std::collections::BTreeMap;
use std::time::Duration;

use link::{SerialSettings, SharedLine};
use thermosald::client::{Client, ClientConfig, ClientError};
use thermosald::diagnostic::{self, Fault};
use thermosald::exchange::Values;
use thermosald::tables::{self, Item, Table, machine, runtime, service, settings};
use thermosald::{Address, RawValue, Read, Target};

use super::{
    BoxFuture, Described, DeviceError, Driver, DriverConfig, ErrorKind, Kind, PollGroup, Reading,
    WriteError, enum_states, point_ids,
};
use crate::point::{
    AlarmRule, DeviceId, PointDescription, PointId, PointKind, PointSpec, Value, ValueError,
    WriteRange,
};

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
};

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
}

impl ThermosaldDriver {
    /// A driver for the regulator `config` describes.
    pub fn new(config: &DriverConfig) -> Result<Self, String> {
        check_address(config.address)?;
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
        Ok(defs
            .iter()
            .zip(outcomes)
            .filter_map(|(&(at, _), outcome)| {
                outcome.map(|value| Reading {
                    point: self.ids[at].clone(),
                    value,
                })
            })
            .collect())
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

    async fn write_point(&mut self, point: &PointSpec, value: &Value) -> Result<(), WriteError> {
        let def = POINTS
            .iter()
            .find(|d| d.name == point.id.name())
            .ok_or_else(|| WriteError::UnknownPoint {
                point: point.id.clone(),
            })?;
        let checked = point.check_write(value)?;
        let number = checked
            .as_number()
            .expect("check_write gives numbers for numeric and enumerated points");
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

    fn write<'a>(
        &'a mut self,
        point: &'a PointSpec,
        value: &'a Value,
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
mod tests {
    use std::collections::HashSet;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::{Arc, Mutex};

    use super::*;
    use thermosald::device::RegulatorBus;
    use wire::Transmit;
    use wire::device::{Device, FaultInjector, ModelLine, SharedModel};

    fn config(id: &str, address: i64) -> DriverConfig {
        DriverConfig {
            id: DeviceId::new(id).unwrap(),
            protocol: super::KIND,
            address: Some(address),
            timeout: None,
            retries: Some(1),
            endpoint: None,
            settings: Default::default(),
        }
    }

    fn address(n: u8) -> Address {
        Address::new(n).unwrap()
    }

    /// Drivers for regulators 0, 1 and 2 on one simulated RS-485 line.
    fn rig(addresses: &[u8]) -> (Vec<ThermosaldDriver>, SharedModel<RegulatorBus>) {
        let list: Vec<Address> = addresses.iter().map(|&a| address(a)).collect();
        let twin = RegulatorBus::new(&list, tokio::time::Instant::now().into_std()).unwrap();
        let model = SharedModel::new(twin);
        let (a, b) = tokio::io::duplex(1024);
        tokio::spawn(link::serve::serve_stream(b, model.line(), None));
        let line = SharedLine::new(link::Line::from_stream(a, "rs485", Some(DEFAULT_SERIAL)));
        let drivers = addresses
            .iter()
            .map(|&n| {
                let mut d =
                    ThermosaldDriver::new(&config(&format!("sealer{n}"), n.into())).unwrap();
                d.attach(line.clone());
                d
            })
            .collect();
        (drivers, model)
    }

    fn value(readings: &[Reading], name: &str) -> Result<Value, DeviceError> {
        readings
            .iter()
            .find(|r| r.point.name() == name)
            .unwrap_or_else(|| panic!("no reading for {name}"))
            .value
            .clone()
    }

    /// The reading of a point, if the poll gave one (a value whose two reads disagreed
    /// gives none: the point keeps what it has).
    fn recorded(readings: &[Reading], name: &str) -> Option<Result<Value, DeviceError>> {
        readings
            .iter()
            .find(|r| r.point.name() == name)
            .map(|r| r.value.clone())
    }

    fn spec(driver: &ThermosaldDriver, name: &str) -> PointSpec {
        driver
            .points()
            .into_iter()
            .find(|p| p.id.name() == name)
            .unwrap()
    }

    #[test]
    fn every_point_names_an_item_with_a_unit_and_a_known_group() {
        let driver = ThermosaldDriver::new(&config("sealer0", 0)).unwrap();
        let groups: Vec<String> = driver.groups().into_iter().map(|g| g.name).collect();
        let points = driver.points();
        assert_eq!(points.len(), POINTS.len());
        for p in &points {
            assert!(groups.contains(&p.group.to_string()), "{}", p.id);
        }
        let ids: HashSet<_> = points.iter().map(|p| &p.id).collect();
        assert_eq!(ids.len(), points.len(), "point ids are unique");
        let temperature = spec(&driver, "temperature");
        assert_eq!(temperature.unit.as_deref(), Some("°C"));
        assert_eq!(temperature.group, LIVE);
        assert_eq!(spec(&driver, "power").unit.as_deref(), Some("VA"));
        assert!(spec(&driver, "address").writable.is_none());
        assert!(spec(&driver, "serial_enabled").writable.is_none());
        let kint = spec(&driver, "kint_gain").writable.unwrap();
        assert_eq!(kint.step, Some(0.1));
        assert!(!kint.integer);
    }

    #[test]
    fn regulator_addresses_outside_0_to_7_are_refused() {
        assert!(check_address(Some(0)).is_ok());
        assert!(check_address(Some(7)).is_ok());
        assert!(check_address(Some(8)).unwrap_err().contains("0 to 7"));
        assert!(
            check_address(None)
                .unwrap_err()
                .contains("needs its address")
        );
        assert!(ThermosaldDriver::new(&config("sealer9", 9)).is_err());
    }

    #[tokio::test(start_paused = true)]
    async fn three_regulators_on_one_line_each_answer_their_own_polls() {
        let (mut drivers, _model) = rig(&[0, 1, 2]);
        for driver in &mut drivers {
            let live = driver.poll(LIVE).await.unwrap();
            assert_eq!(live.len(), 6);
            assert!(matches!(value(&live, "temperature"), Ok(Value::Number(t)) if t > 0.0));
            assert_eq!(value(&live, "fault"), Ok(Value::Number(0.0)));
            for group in [SETTINGS, MACHINE, SERVICE] {
                let readings = driver.poll(group).await.unwrap();
                assert!(readings.iter().all(|r| r.value.is_ok()), "{readings:?}");
            }
        }
        let machine = drivers[2].poll(MACHINE).await.unwrap();
        assert_eq!(value(&machine, "address"), Ok(Value::Number(2.0)));
    }

    #[tokio::test(start_paused = true)]
    async fn a_provoked_fault_shows_as_its_number_and_words() {
        let (mut drivers, model) = rig(&[0, 1]);
        model
            .lock()
            .regulator_mut(address(1))
            .unwrap()
            .provoke(Fault::OpenBand, tokio::time::Instant::now().into_std());
        let live = drivers[1].poll(LIVE).await.unwrap();
        assert_eq!(value(&live, "fault"), Ok(Value::Number(1.0)));
        let fault = spec(&drivers[1], "fault");
        assert_eq!(fault.label(&Value::Number(1.0)), Some("sealing band open"));
        assert!(fault.is_alarm(&Value::Number(1.0)));
        let other = drivers[0].poll(LIVE).await.unwrap();
        assert_eq!(value(&other, "fault"), Ok(Value::Number(0.0)));
    }

    #[tokio::test(start_paused = true)]
    async fn a_set_point_write_reaches_the_regulator_and_reads_back() {
        let (mut drivers, _model) = rig(&[0]);
        let driver = &mut drivers[0];
        let sealing = spec(driver, "sealing_temperature");
        driver.write(&sealing, &Value::Number(150.0)).await.unwrap();
        let kint = spec(driver, "kint_gain");
        driver.write(&kint, &Value::Number(12.5)).await.unwrap();
        let settings = driver.poll(SETTINGS).await.unwrap();
        assert_eq!(
            value(&settings, "sealing_temperature"),
            Ok(Value::Number(150.0))
        );
        let machine = driver.poll(MACHINE).await.unwrap();
        assert_eq!(value(&machine, "kint_gain"), Ok(Value::Number(12.5)));
    }

    #[tokio::test(start_paused = true)]
    async fn writes_out_of_range_between_steps_or_above_the_working_limit_never_reach_the_wire() {
        let (mut drivers, model) = rig(&[0]);
        let driver = &mut drivers[0];
        driver.poll(SETTINGS).await.unwrap();
        let before = model.lock().regulators_mut()[0]
            .table(Table::Settings, tokio::time::Instant::now().into_std());
        let sealing = spec(driver, "sealing_temperature");
        let err = driver
            .write(&sealing, &Value::Number(1000.0))
            .await
            .unwrap_err();
        assert!(
            matches!(err, WriteError::Invalid(ValueError::OutOfRange { .. })),
            "{err}"
        );
        let max = driver
            .max_working()
            .expect("confirmed by the settings poll");
        let err = driver
            .write(&sealing, &Value::Number(max + 1.0))
            .await
            .unwrap_err();
        assert!(
            err.to_string().contains("maximum working temperature"),
            "{err}"
        );
        let kint = spec(driver, "kint_gain");
        let err = driver
            .write(&kint, &Value::Number(12.55))
            .await
            .unwrap_err();
        assert!(
            matches!(err, WriteError::Invalid(ValueError::NotAStep { .. })),
            "{err}"
        );
        let address = spec(driver, "address");
        let err = driver
            .write(&address, &Value::Number(3.0))
            .await
            .unwrap_err();
        assert!(
            matches!(err, WriteError::Invalid(ValueError::ReadOnly { .. })),
            "{err}"
        );
        let after = model.lock().regulators_mut()[0]
            .table(Table::Settings, tokio::time::Instant::now().into_std());
        assert_eq!(before, after, "nothing was written");
    }

    #[tokio::test(start_paused = true)]
    async fn a_regulator_that_is_not_on_the_line_times_out() {
        let (_drivers, model) = rig(&[0]);
        let (a, b) = tokio::io::duplex(1024);
        tokio::spawn(link::serve::serve_stream(b, model.line(), None));
        let mut driver = ThermosaldDriver::new(&config("sealer5", 5)).unwrap();
        driver.attach(SharedLine::new(link::Line::from_stream(
            a,
            "rs485",
            Some(DEFAULT_SERIAL),
        )));
        let err = driver.poll(LIVE).await.unwrap_err();
        assert_eq!(err.kind, ErrorKind::Timeout, "{err}");
        assert!(err.message.contains('5'), "{err}");
    }

    /// A digit to damage in the next whole-table answer to a table's read: `mask` flipped
    /// into digit `digit` (0 = hundreds) of item `index`.
    #[derive(Debug, Clone, Copy)]
    struct Damage {
        table: Table,
        index: u8,
        digit: usize,
        mask: u8,
    }

    impl Damage {
        /// Byte offset of the damaged digit: `%`, address, 2-digit message, `R`, 2-digit
        /// count, the unused byte, then 3 digits per item.
        fn offset(&self) -> usize {
            8 + 3 * usize::from(self.index) + self.digit
        }

        fn matches(&self, answer: &[u8]) -> bool {
            let message = self.table.read_message().number().to_string();
            answer.get(2..4) == Some(message.as_bytes()) && answer.get(5..7) == Some(b"99")
        }
    }

    /// The line as the driver under test hears it: the twin behind `D` (a fault injector,
    /// or the twin's own line), every question counted, chosen answers damaged once.
    struct Tap<D> {
        inner: Arc<Mutex<D>>,
        questions: Arc<AtomicUsize>,
        damage: Arc<Mutex<Vec<Damage>>>,
    }

    impl<D: Device> Device for Tap<D> {
        fn receive(&mut self, bytes: &[u8], now: std::time::Instant) -> Vec<Transmit> {
            // The master sends only questions, each ending in LF.
            let questions = bytes.iter().filter(|&&b| b == b'\n').count();
            self.questions.fetch_add(questions, Ordering::SeqCst);
            let mut replies = self.inner.lock().unwrap().receive(bytes, now);
            let mut damage = self.damage.lock().unwrap();
            for reply in &mut replies {
                if let Some(i) = damage.iter().position(|d| d.matches(&reply.bytes)) {
                    let d = damage.remove(i);
                    reply.bytes[d.offset()] ^= d.mask;
                }
            }
            replies
        }
    }

    /// Regulator 0's driver on a line to its twin through a [`Tap`].
    struct Bench<D> {
        driver: ThermosaldDriver,
        model: SharedModel<RegulatorBus>,
        device: Arc<Mutex<D>>,
        questions: Arc<AtomicUsize>,
        damage: Arc<Mutex<Vec<Damage>>>,
    }

    fn bench<D: Device>(retries: u8, wrap: impl FnOnce(ModelLine<RegulatorBus>) -> D) -> Bench<D> {
        let twin =
            RegulatorBus::new(&[address(0)], tokio::time::Instant::now().into_std()).unwrap();
        let model = SharedModel::new(twin);
        let device = Arc::new(Mutex::new(wrap(model.line())));
        let questions = Arc::new(AtomicUsize::new(0));
        let damage = Arc::new(Mutex::new(Vec::new()));
        let tap = Tap {
            inner: Arc::clone(&device),
            questions: Arc::clone(&questions),
            damage: Arc::clone(&damage),
        };
        let (a, b) = tokio::io::duplex(1024);
        tokio::spawn(link::serve::serve_stream(b, tap, None));
        let mut driver = ThermosaldDriver::new(&DriverConfig {
            retries: Some(retries),
            ..config("sealer0", 0)
        })
        .unwrap();
        driver.attach(SharedLine::new(link::Line::from_stream(
            a,
            "rs485",
            Some(DEFAULT_SERIAL),
        )));
        Bench {
            driver,
            model,
            device,
            questions,
            damage,
        }
    }

    impl<D> Bench<D> {
        /// Damages the next whole-table answer of `table` at one digit of item `index`.
        fn damage_next(&self, table: Table, index: u8, digit: usize, mask: u8) {
            self.damage.lock().unwrap().push(Damage {
                table,
                index,
                digit,
                mask,
            });
        }

        /// Polls `group`, returning its readings and the questions it cost.
        async fn poll_counted(&mut self, group: &str) -> (Vec<Reading>, usize) {
            let before = self.questions.load(Ordering::SeqCst);
            let readings = self.driver.poll(group).await.unwrap();
            (readings, self.questions.load(Ordering::SeqCst) - before)
        }

        /// The twin's true raw value of a table's item now.
        fn truth(&self, table: Table, index: u8) -> RawValue {
            let now = tokio::time::Instant::now().into_std();
            let mut line = self.model.lock();
            let regulator = &mut line.regulators_mut()[0];
            match table {
                Table::Runtime => RawValue::new(regulator.fault_number(now)).unwrap(),
                _ => regulator.table(table, now)[usize::from(index)],
            }
        }
    }

    /// Another master on the same twin (the regulator's panel, a PLC) writes `value` to
    /// `item` over its own line, away from the driver's exchanges.
    async fn set_on_the_twin(model: &SharedModel<RegulatorBus>, item: &'static Item, value: f64) {
        tokio::time::sleep(Duration::from_millis(300)).await;
        let (a, b) = tokio::io::duplex(1024);
        tokio::spawn(link::serve::serve_stream(b, model.line(), None));
        let line = SharedLine::new(link::Line::from_stream(a, "panel", Some(DEFAULT_SERIAL)));
        let mut panel = Client::new(line, ClientConfig::new(address(0)));
        panel.write(item, value).await.unwrap();
        tokio::time::sleep(Duration::from_millis(300)).await;
    }

    fn settings_item(index: u8) -> &'static Item {
        Table::Settings.item(index).unwrap()
    }

    #[tokio::test(start_paused = true)]
    async fn a_reading_outside_its_items_range_is_bad_and_says_which_value_and_range() {
        let mut bench = bench(1, |line| line);
        // Mains frequency 050 Hz, its tens digit 5 damaged into 7: 70 Hz, outside 50–60 Hz.
        bench.damage_next(Table::Machine, 6, 1, 0b10);
        let (machine, _) = bench.poll_counted(MACHINE).await;
        let err = value(&machine, "mains_frequency").unwrap_err();
        assert_eq!(err.kind, ErrorKind::Decode, "{err}");
        for fact in ["Mains frequency", "70 Hz", "50 Hz to 60 Hz"] {
            assert!(err.message.contains(fact), "{fact:?} in {err}");
        }
        assert_eq!(value(&machine, "kint_gain"), Ok(Value::Number(5.0)));
        // Confirmed items keep their confirmed value out of it: the same digit damaged
        // again is bad again, never good.
        let (machine, _) = bench.poll_counted(MACHINE).await;
        assert_eq!(value(&machine, "mains_frequency"), Ok(Value::Number(50.0)));
        bench.damage_next(Table::Machine, 6, 1, 0b10);
        let (machine, _) = bench.poll_counted(MACHINE).await;
        assert!(value(&machine, "mains_frequency").is_err());
    }

    #[tokio::test(start_paused = true)]
    async fn a_corrupted_setting_is_not_recorded_until_a_second_read_confirms_it() {
        let mut bench = bench(1, |line| line);
        // The first answer says 350 °C for the maximum working temperature (its hundreds
        // digit 2 damaged into 3); the confirming read says 250 °C.
        bench.damage_next(Table::Settings, settings::MAXIMUM_WORKING_TEMPERATURE, 0, 1);
        let (readings, questions) = bench.poll_counted(SETTINGS).await;
        let err = value(&readings, "max_working_temperature").unwrap_err();
        assert_eq!(err.kind, ErrorKind::Decode);
        assert!(err.message.contains("350 °C, then 250 °C"), "{err}");
        assert_eq!(
            value(&readings, "sealing_temperature"),
            Ok(Value::Number(180.0))
        );
        assert_eq!(
            questions, 2,
            "the table read, then the table again to confirm"
        );
        assert_eq!(bench.driver.max_working(), None);

        // A set point above the true limit is refused: the limit is confirmed first.
        let sealing = spec(&bench.driver, "sealing_temperature");
        let err = bench
            .driver
            .write(&sealing, &Value::Number(300.0))
            .await
            .unwrap_err();
        assert!(
            err.to_string().contains("maximum working temperature"),
            "{err}"
        );
        assert_eq!(bench.driver.max_working(), Some(250.0));
        assert_eq!(
            bench.truth(Table::Settings, settings::SEALING_TEMPERATURE),
            RawValue::new(180).unwrap()
        );

        // Once confirmed, the same damage is not recorded: the point keeps its value.
        let (readings, _) = bench.poll_counted(SETTINGS).await;
        assert_eq!(
            value(&readings, "max_working_temperature"),
            Ok(Value::Number(250.0))
        );
        bench.damage_next(Table::Settings, settings::MAXIMUM_WORKING_TEMPERATURE, 0, 1);
        let (readings, questions) = bench.poll_counted(SETTINGS).await;
        assert_eq!(recorded(&readings, "max_working_temperature"), None);
        assert_eq!(questions, 2, "the table read, then the item to confirm");
        assert_eq!(bench.driver.max_working(), Some(250.0));
    }

    #[tokio::test(start_paused = true)]
    async fn the_damaged_digits_of_the_issue_are_never_recorded_as_good() {
        // bands_in_series 1 → 5, kd_gain 0 → 40, kint_gain 5.0 → 5.8, as seen with
        // `cellbus sim thermosald --fault-rate 0.5`.
        let cases = [
            (
                SERVICE,
                Table::Service,
                service::IN_SERIES,
                2,
                0b100,
                "bands_in_series",
                1.0,
            ),
            (MACHINE, Table::Machine, 11, 1, 0b100, "kd_gain", 0.0),
            (
                MACHINE,
                Table::Machine,
                machine::KINT_GAIN,
                2,
                0b1000,
                "kint_gain",
                5.0,
            ),
        ];
        let mut bench = bench(1, |line| line);
        for (group, table, index, digit, mask, point, truth) in cases {
            bench.poll_counted(group).await;
            bench.damage_next(table, index, digit, mask);
            let (readings, questions) = bench.poll_counted(group).await;
            assert_eq!(recorded(&readings, point), None, "{point}");
            assert_eq!(questions, 2, "{point}: one confirming read");
            let (readings, _) = bench.poll_counted(group).await;
            assert_eq!(value(&readings, point), Ok(Value::Number(truth)), "{point}");
        }
    }

    #[tokio::test(start_paused = true)]
    async fn a_new_fault_number_is_raised_only_after_a_confirming_read() {
        let mut bench = bench(1, |line| line);
        let (live, questions) = bench.poll_counted(LIVE).await;
        assert_eq!(value(&live, "fault"), Ok(Value::Number(0.0)));
        assert_eq!(questions, 2, "the first fault number is confirmed too");
        // A damaged 000 → 001 ("sealing band open") is not taken for a fault.
        bench.damage_next(Table::Runtime, runtime::FAULT, 2, 1);
        let (live, questions) = bench.poll_counted(LIVE).await;
        assert_eq!(recorded(&live, "fault"), None);
        assert!(matches!(value(&live, "temperature"), Ok(Value::Number(_))));
        assert_eq!(questions, 2);
        // A real fault is, once read twice.
        bench
            .model
            .lock()
            .regulator_mut(address(0))
            .unwrap()
            .provoke(Fault::OpenBand, tokio::time::Instant::now().into_std());
        let (live, questions) = bench.poll_counted(LIVE).await;
        assert_eq!(value(&live, "fault"), Ok(Value::Number(1.0)));
        assert_eq!(questions, 2);
        let (_, questions) = bench.poll_counted(LIVE).await;
        assert_eq!(questions, 1, "an unchanged fault number costs nothing more");
    }

    #[tokio::test(start_paused = true)]
    async fn a_real_change_is_recorded_after_one_confirming_read_and_limits_the_writes() {
        let mut bench = bench(1, |line| line);
        bench.poll_counted(SETTINGS).await;
        let max_working = settings_item(settings::MAXIMUM_WORKING_TEMPERATURE);
        set_on_the_twin(&bench.model, max_working, 200.0).await;
        let (readings, questions) = bench.poll_counted(SETTINGS).await;
        assert_eq!(
            value(&readings, "max_working_temperature"),
            Ok(Value::Number(200.0))
        );
        assert_eq!(questions, 2);
        assert_eq!(bench.driver.max_working(), Some(200.0));
        let sealing = spec(&bench.driver, "sealing_temperature");
        let err = bench
            .driver
            .write(&sealing, &Value::Number(220.0))
            .await
            .unwrap_err();
        assert!(
            err.to_string().contains("maximum working temperature"),
            "{err}"
        );
        // A write the regulator echoed is confirmed by its echo: no second read follows.
        bench
            .driver
            .write(&sealing, &Value::Number(190.0))
            .await
            .unwrap();
        let (readings, questions) = bench.poll_counted(SETTINGS).await;
        assert_eq!(
            value(&readings, "sealing_temperature"),
            Ok(Value::Number(190.0))
        );
        assert_eq!(questions, 1);
    }

    #[tokio::test(start_paused = true)]
    async fn in_a_steady_state_every_poll_is_one_exchange() {
        let mut bench = bench(1, |line| line);
        for group in [LIVE, SETTINGS, MACHINE, SERVICE] {
            bench.poll_counted(group).await;
        }
        let before = bench.questions.load(Ordering::SeqCst);
        let mut polls = 0;
        for _ in 0..10 {
            for group in [LIVE, SETTINGS, MACHINE, SERVICE] {
                let (readings, _) = bench.poll_counted(group).await;
                assert!(readings.iter().all(|r| r.value.is_ok()), "{readings:?}");
                polls += 1;
            }
            tokio::time::sleep(Duration::from_secs(2)).await;
        }
        assert_eq!(bench.questions.load(Ordering::SeqCst) - before, polls);
    }

    #[tokio::test(start_paused = true)]
    async fn under_heavy_line_damage_no_wrong_confirmed_value_is_ever_recorded_as_good() {
        let mut bench = bench(2, |line| FaultInjector::new(line, 20261, 0.5).unwrap());
        let groups = [LIVE, SETTINGS, LIVE, MACHINE, LIVE, SERVICE];
        let sealing = settings_item(settings::SEALING_TEMPERATURE);
        let (mut polls, mut failed, mut checked, mut wrong, mut bad, mut kept) = (0, 0, 0, 0, 0, 0);
        for round in 0..400usize {
            let group = groups[round % groups.len()];
            let table = table_of(group).unwrap();
            let truths: Vec<(&Def, RawValue)> = POINTS
                .iter()
                // Every settings, machine and service point, and the fault number.
                .filter(|d| {
                    d.table == table && (table != Table::Runtime || d.index == runtime::FAULT)
                })
                .map(|d| (d, bench.truth(table, d.index)))
                .collect();
            polls += 1;
            match bench.driver.poll(group).await {
                Err(_) => failed += 1,
                Ok(readings) => {
                    for (def, truth) in truths {
                        match recorded(&readings, def.name) {
                            None => kept += 1,
                            Some(Ok(v)) => {
                                checked += 1;
                                if v != def.value(def.item().reading(truth)) {
                                    wrong += 1;
                                    eprintln!("{}: {v:?}, the twin has {truth:?}", def.name);
                                }
                            }
                            Some(Err(_)) => bad += 1,
                        }
                    }
                }
            }
            // The truth changes between polls: a fault comes and goes, the panel changes
            // the sealing temperature.
            let now = tokio::time::Instant::now().into_std();
            match round % 60 {
                20 => bench.model.lock().regulators_mut()[0].provoke(Fault::OpenBand, now),
                40 => {
                    let mut line = bench.model.lock();
                    line.regulators_mut()[0].remove_cause(Fault::OpenBand, now);
                    line.regulators_mut()[0].power_cycle(now);
                }
                50 => set_on_the_twin(&bench.model, sealing, 150.0 + (round % 7) as f64).await,
                _ => {}
            }
            // Longer than the latest a delayed answer can come, so it never meets a change.
            tokio::time::sleep(Duration::from_secs(3)).await;
        }
        let injected = bench.device.lock().unwrap().injected();
        eprintln!(
            "{polls} polls ({failed} without an answer), {checked} confirmed values recorded \
             as good, {wrong} of them wrong, {kept} kept (two reads disagreed), {bad} bad; \
             faults injected: {injected:?}; \
             questions: {}",
            bench.questions.load(Ordering::SeqCst)
        );
        assert!(injected.corrupted > 50, "{injected:?}");
        assert!(checked > 1000, "{checked}");
        assert_eq!(wrong, 0);
    }

    #[test]
    fn a_bit_flip_in_a_run_time_answer_passes_as_another_measurement_in_at_most_a_quarter_of_its_bits()
     {
        // A run-time answer while sealing, as the twin gives it 1.5 s into its first impulse.
        let t0 = std::time::Instant::now();
        let mut twin = RegulatorBus::new(&[address(0)], t0).unwrap();
        let data = twin.regulators_mut()[0].table(Table::Runtime, t0 + Duration::from_millis(3500));
        let digits: String = data.iter().map(|raw| format!("{:03}", raw.get())).collect();
        let answer = format!("%053R990{digits}\n").into_bytes();
        let read = thermosald::Exchange::new(
            Target::Address(address(0)),
            Read::all(Table::Runtime).into(),
        )
        .unwrap();
        // For each single-bit flip: the items whose value changed in an answer the client
        // takes.
        let mut changed_by_item = [0usize; tables::RUNTIME_ITEMS];
        let bits = answer.len() * 8;
        for bit in 0..bits {
            let mut damaged = answer.clone();
            damaged[bit / 8] ^= 1 << (bit % 8);
            let mut deframer = wire::Deframer::new(thermosald::FrameCodec);
            deframer.push(&damaged);
            while let Some(input) = deframer.next_frame() {
                let Ok(frame) = input else { continue };
                if let thermosald::exchange::Classified::Answer(
                    thermosald::exchange::Answer::Values(values),
                ) = read.classify(&frame)
                {
                    let differing: Vec<usize> = (0..data.len())
                        .filter(|&i| values.raw().get(i) != data.get(i))
                        .collect();
                    assert!(differing.len() <= 1, "one flip, one digit: {differing:?}");
                    for i in differing {
                        changed_by_item[i] += 1;
                    }
                }
            }
        }
        let fault = changed_by_item[usize::from(runtime::FAULT)];
        let measured: usize = POINTS
            .iter()
            .filter(|d| d.table == Table::Runtime && d.meaning == Meaning::Quantity)
            .map(|d| changed_by_item[usize::from(d.index)])
            .sum();
        eprintln!(
            "run-time answer {:?}: of its {bits} single-bit flips, {measured} pass as another \
             measurement, {fault} as another fault number (confirmed by a second read)",
            String::from_utf8_lossy(&answer)
        );
        // 2 to 4 of a digit's 8 bits give another digit; 15 measurement digits in 240 bits.
        assert_eq!(fault, 12, "000: each digit has 4 flips to another digit");
        assert!(measured * 4 <= bits, "{measured} of {bits}");
    }
}
