//! Any Modbus RTU / JBUS / Modbus TCP device, with its registers named in the
//! configuration (or in a CSV file, `registers_csv`), through `jbus::client`.
//!
//! ```toml
//! [[line.device]]
//! id = "chiller1"
//! protocol = "modbus"
//! address = 17                   # unit 1-255
//! max_registers_per_request = 125   # 1-125: some devices take less
//! max_bits_per_request = 2000       # 1-2000, coils and discrete inputs
//! one_request_per_register = false  # true: every register alone (devices that refuse holes)
//! delay_between_requests = "0ms"    # wait between two of this device's requests
//! delay_after_connect = "0ms"       # wait after the line (re)opens, before the first request
//! deadband = 0.5                    # any protocol: default deadband of numeric points
//!
//! [[line.device.register]]
//! name = "supply_temperature"    # the point's name: a-z, 0-9, _ and -
//! title = "Supply temperature"   # words for people (default: the name)
//! table = "input"                # holding (default), input, coil or discrete
//! address = 0x0010               # first register (or bit) address, 0-65535
//! type = "int16"                 # int16, uint16 (default), int32, uint32, int64, uint64,
//!                                # float32, float64, string:N, bit:N
//! order = "ABCD"                 # ABCD (default), CDAB, BADC, DCBA
//! scale = 0.1                    # value = raw × scale + offset (default 1 and 0)
//! offset = 0
//! unit = "°C"
//! deadband = 0.2                 # or deadband_percent = 1 (of the last recorded value)
//!
//! [[line.device.register]]
//! name = "setpoint"
//! address = 0x0020
//! type = "float32"
//! writable = { min = 5.0, max = 30.0 }   # holding registers: function 6 or 16
//!
//! [[line.device.register]]
//! name = "pump"
//! table = "coil"
//! address = 3
//! writable = true                # coils: function 5
//! ```
//!
//! One group, `live` (1 s). The registers are planned once into the fewest reads
//! ([`jbus::plan`]): each poll sends the plan's reads. A merged read that the device
//! refuses with exception 2, 3 or 4 (an address it lacks, a range it does not take in one
//! read, a failure on some register) is split for good (logged once) and the rest of the
//! poll goes on with the parts; a read of a single register that is refused marks that
//! register's point bad with the exception in words, as does any other exception (busy)
//! for its read's points. Silence or damage marks the device down, and so does a Modbus
//! gateway's exception 10 or 11 (no path to the unit, no answer from it): through a
//! serial-to-Ethernet gateway that is how a meter switched off looks. Coils, discrete inputs and `bit:N` registers are enumerations `0` off / `1` on;
//! `string:N` registers are text.
//!
//! Pacing: the driver waits `delay_between_requests` between two of its own requests (the
//! line is free for other devices meanwhile) and `delay_after_connect` before its first
//! request after the scheduler (re)attached the line, which it does after every (re)open.

use std::sync::{Arc, Mutex, OnceLock, PoisonError};
use std::time::Duration;

use jbus::client::{Client, ClientConfig, ClientError, Framing};
use jbus::data::{DataType, Format, TypedValue};
use jbus::plan::{Item, Plan, PlanOptions, Split};
use jbus::rtu::{ExceptionCode, UnitId, UnitProblem};
use jbus::slave::Table;
use link::{SerialSettings, SharedLine};
use tokio::time::Instant;
use wire::{Failure as _, FailureKind};

use super::{
    BoxFuture, DeviceContext, DeviceError, DeviceKind, Driver, DriverConfig, ErrorKind, Kind,
    PollGroup, Reading, WriteError, enum_states,
};
use crate::config::{ConfigError, Scratch, Settings};
use crate::point::{
    Deadband, DeviceId, PointDescription, PointId, PointKind, PointSpec, Value, WriteRange,
};

pub mod config;
mod register_csv;

pub use config::ModbusSettings;

/// Any Modbus RTU / JBUS / Modbus TCP device, its registers named in the config.
#[derive(Debug)]
pub struct Modbus;

/// The kind's handle, as the config and the line tasks hold it.
pub const KIND: Kind = Kind::new(&Modbus);

impl DeviceKind for Modbus {
    fn name(&self) -> &'static str {
        "modbus"
    }

    fn default_serial(&self) -> SerialSettings {
        DEFAULT_SERIAL
    }

    fn default_address(&self) -> Option<i64> {
        Some(DEFAULT_UNIT)
    }

    fn check_address(&self, address: Option<i64>) -> Result<(), String> {
        check_address(address)
    }

    fn groups(&self) -> &'static [(&'static str, Duration)] {
        &GROUPS
    }

    fn speaks_modbus(&self) -> bool {
        true
    }

    fn plans_reads(&self) -> bool {
        true
    }

    fn keys(&self) -> &'static [&'static str] {
        &config::KEYS
    }

    fn read_keys(
        &self,
        table: &crate::config::Table<'_>,
        device: &DeviceContext,
        scratch: &mut Scratch,
    ) -> Result<Settings, ConfigError> {
        config::read_keys(table, device, scratch)
    }

    fn foreign_key(
        &self,
        key: &str,
        value: &toml::Spanned<toml::de::DeValue<'_>>,
        other: &str,
    ) -> (std::ops::Range<usize>, String) {
        if key == "register" {
            return (
                config::first_register_name(value),
                format!(
                    "registers are named for modbus devices only; {other} devices have their points built in"
                ),
            );
        }
        (
            value.span(),
            format!("{key} is for modbus devices only, not {other} devices"),
        )
    }

    fn check(&self, config: &DriverConfig) -> Result<(), String> {
        ModbusDriver::new(config).map(drop)
    }

    fn warnings(&self, devices: &[&DriverConfig]) -> Vec<String> {
        config::warnings(devices)
    }

    fn build(&self, config: &DriverConfig) -> Result<Box<dyn Driver>, String> {
        Ok(Box::new(ModbusDriver::new(config)?))
    }
}

/// A Modbus line when the URL says nothing: 9600 baud, 8N1.
pub const DEFAULT_SERIAL: SerialSettings = SerialSettings::new_8n1(9600);

/// Default unit number.
pub const DEFAULT_UNIT: i64 = 1;

/// The only group.
pub const LIVE: &str = "live";

/// The poll group and its default period.
const GROUPS: [(&str, Duration); 1] = [(LIVE, Duration::from_secs(1))];

/// Which table a register is in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum RegisterTable {
    /// Holding registers: read with function 3, written with 6 or 16.
    Holding,
    /// Input registers: read-only, function 4.
    Input,
    /// Coils: bits read with function 1, written with 5.
    Coil,
    /// Discrete inputs: read-only bits, function 2.
    Discrete,
}

impl RegisterTable {
    /// The names the config takes, for messages.
    pub const CHOICES: &'static str = "\"holding\", \"input\", \"coil\" or \"discrete\"";

    /// The table for its config name (`holding`, `input`, `coil`, `discrete`).
    pub fn parse(text: &str) -> Option<Self> {
        match text.trim() {
            "holding" => Some(Self::Holding),
            "input" => Some(Self::Input),
            "coil" => Some(Self::Coil),
            "discrete" => Some(Self::Discrete),
            _ => None,
        }
    }

    /// The config name.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Holding => "holding",
            Self::Input => "input",
            Self::Coil => "coil",
            Self::Discrete => "discrete",
        }
    }

    /// The Modbus table.
    pub fn table(self) -> Table {
        match self {
            Self::Holding => Table::HoldingRegisters,
            Self::Input => Table::InputRegisters,
            Self::Coil => Table::Coils,
            Self::Discrete => Table::DiscreteInputs,
        }
    }

    /// Whether it holds single bits (coils, discrete inputs).
    pub fn holds_bits(self) -> bool {
        self.table().holds_bits()
    }
}

/// One register (or bit) as the configuration names it.
#[derive(Debug, Clone, PartialEq)]
pub struct RegisterConfig {
    /// The point's name.
    pub name: String,
    /// Words for people.
    pub title: String,
    /// The table it is in.
    pub table: RegisterTable,
    /// Its first register (or bit) address, from 0.
    pub address: u16,
    /// Type, order and scale of its value (unused for bits).
    pub format: Format,
    /// The symbol of its unit of measure (`°C`, `kW`).
    pub unit: Option<String>,
    /// The range a write must fall into, if writable (`0` to `1` for a coil).
    pub writable: Option<(f64, f64)>,
    /// How far its value must move before it is recorded again, if not every change.
    pub deadband: Option<Deadband>,
}

impl RegisterConfig {
    /// A plain `uint16` holding register, read-only, unscaled.
    pub fn holding(name: &str, address: u16) -> Self {
        Self {
            name: name.to_owned(),
            title: name.to_owned(),
            table: RegisterTable::Holding,
            address,
            format: Format::default(),
            unit: None,
            writable: None,
            deadband: None,
        }
    }

    /// Whether its value is on or off: a coil, a discrete input or a `bit:N` register.
    pub fn is_bool(&self) -> bool {
        self.table.holds_bits() || matches!(self.format.data_type, DataType::Bit(_))
    }

    /// Whether its value is a number with a unit (not a bit, not text).
    pub fn is_numeric(&self) -> bool {
        !self.table.holds_bits() && self.format.data_type.is_number()
    }

    /// How many registers (or bits) it takes.
    pub fn length(&self) -> u16 {
        if self.table.holds_bits() {
            1
        } else {
            self.format.registers()
        }
    }

    /// The point kind: on/off enumeration, text or number.
    pub fn kind(&self) -> PointKind {
        if self.is_bool() {
            enum_states([(0, "off"), (1, "on")])
        } else if self.is_numeric() {
            PointKind::Numeric
        } else {
            PointKind::Text
        }
    }

    /// The lowest and highest value the register can hold, in its unit.
    pub fn representable(&self) -> (f64, f64) {
        if !self.is_numeric() {
            return (0.0, 1.0);
        }
        let (low, high) = match self.format.data_type {
            DataType::Int16 => (f64::from(i16::MIN), f64::from(i16::MAX)),
            DataType::Int32 => (f64::from(i32::MIN), f64::from(i32::MAX)),
            DataType::Uint32 => (0.0, f64::from(u32::MAX)),
            DataType::Int64 => (i64::MIN as f64, i64::MAX as f64),
            DataType::Uint64 => (0.0, u64::MAX as f64),
            DataType::Float32 => (f64::from(f32::MIN), f64::from(f32::MAX)),
            DataType::Float64 => (f64::MIN, f64::MAX),
            _ => (0.0, f64::from(u16::MAX)),
        };
        let scaling = self.format.scaling;
        let (a, b) = (
            low * scaling.scale() + scaling.offset(),
            high * scaling.scale() + scaling.offset(),
        );
        (a.min(b), a.max(b))
    }

    /// The write range a point shows: whole numbers for integer types on a whole scale,
    /// the scale as step when it is not 1.
    fn write_range(&self, (min, max): (f64, f64)) -> WriteRange {
        if self.is_bool() {
            return WriteRange {
                min: 0.0,
                max: 1.0,
                integer: true,
                step: None,
            };
        }
        let float = matches!(self.format.data_type, DataType::Float32 | DataType::Float64);
        let scaling = self.format.scaling;
        WriteRange {
            min,
            max,
            integer: !float && scaling.scale().fract() == 0.0 && scaling.offset().fract() == 0.0,
            step: (!float && scaling.scale() != 1.0).then_some(scaling.scale()),
        }
    }

    /// The point's value for its registers (or bit).
    fn value(&self, part: Part<'_>) -> Result<Value, DeviceError> {
        match part {
            Part::Bits(bits) => bits
                .first()
                .map(|&on| Value::Number(f64::from(u8::from(on))))
                .ok_or_else(|| missing(self)),
            Part::Words(words) => {
                let typed = self
                    .format
                    .decode(words)
                    .map_err(|e| DeviceError::new(ErrorKind::Decode, e))?;
                match typed {
                    TypedValue::Text(text) => Ok(Value::Text(text)),
                    TypedValue::Bool(on) => Ok(Value::Number(f64::from(u8::from(on)))),
                    other => {
                        let number = other.as_f64().ok_or_else(|| missing(self))?;
                        if !number.is_finite() {
                            return Err(DeviceError::new(
                                ErrorKind::Decode,
                                format_args!(
                                    "register {} holds {number}, not a number",
                                    self.address
                                ),
                            ));
                        }
                        Ok(Value::Number(if self.format.scaling.is_identity() {
                            number
                        } else {
                            round(number)
                        }))
                    }
                }
            }
        }
    }
}

/// How a Modbus device is read, beyond its registers.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ModbusOptions {
    /// How reads are planned: the most registers and bits per request
    /// (`max_registers_per_request`, `max_bits_per_request`) and
    /// `one_request_per_register`.
    pub plan: PlanOptions,
    /// Waited between two of the device's requests.
    pub delay_between_requests: Duration,
    /// Waited after the line (re)opens, before the device's first request.
    pub delay_after_connect: Duration,
}

/// Checks a unit number: 1–255.
pub fn check_address(address: Option<i64>) -> Result<(), String> {
    unit(address).map(drop)
}

/// The unit number the config gives, checked by [`jbus::rtu::check_unit`] and worded for
/// this kind of device.
fn unit(address: Option<i64>) -> Result<UnitId, String> {
    jbus::rtu::check_unit(address).map_err(|problem| match problem {
        UnitProblem::Missing => format!(
            "a Modbus device needs its unit number, {} to {}",
            UnitId::MIN,
            UnitId::JBUS_MAX
        ),
        UnitProblem::OutOfRange { number } => format!(
            "Modbus unit number {number} is out of range: {} to {} (0 is broadcast, never answered)",
            UnitId::MIN,
            UnitId::JBUS_MAX
        ),
    })
}

/// The plan's items for `registers`, in their order: one per register.
pub fn plan_items(registers: &[RegisterConfig]) -> Vec<Item> {
    registers
        .iter()
        .map(|r| Item::new(r.table.table(), r.address, r.length()))
        .collect()
}

/// A Modbus device's registers, shared by every device configured with the same list (one
/// `registers_csv` file is parsed once for all its devices), with their points'
/// descriptions, built on first use, once for all of them, and their read plan (shared
/// until a device asks for a split). Reads as a slice of registers.
#[derive(Debug, Clone, Default)]
pub struct RegisterList(Arc<SharedRegisters>);

#[derive(Debug, Default)]
struct SharedRegisters {
    registers: Vec<RegisterConfig>,
    descriptions: OnceLock<Vec<Arc<PointDescription>>>,
    /// The first plan made of the registers, with its options.
    plan: Mutex<Option<(PlanOptions, Arc<Plan>)>>,
}

impl RegisterList {
    /// The reads of the registers under `options`: the plan made for the first device of
    /// the list when its options were the same (a device that splits a read gets its own
    /// copy), else a new one.
    fn plan(&self, options: PlanOptions) -> Result<Arc<Plan>, jbus::plan::PlanError> {
        let mut shared = self.0.plan.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some((made_for, plan)) = &*shared
            && *made_for == options
        {
            return Ok(Arc::clone(plan));
        }
        let plan = Arc::new(Plan::new(&plan_items(&self.0.registers), options)?);
        if shared.is_none() {
            *shared = Some((options, Arc::clone(&plan)));
        }
        Ok(plan)
    }

    /// The description of each register's point, in the registers' order.
    fn descriptions(&self) -> &[Arc<PointDescription>] {
        self.0.descriptions.get_or_init(|| {
            self.0
                .registers
                .iter()
                .map(|r| {
                    Arc::new(PointDescription {
                        name: r.title.clone().into(),
                        unit: r.unit.clone().map(Into::into),
                        kind: r.kind(),
                        group: LIVE.into(),
                        writable: r.writable.map(|range| r.write_range(range)),
                        alarm: None,
                    })
                })
                .collect()
        })
    }
}

impl From<Vec<RegisterConfig>> for RegisterList {
    fn from(registers: Vec<RegisterConfig>) -> Self {
        Self(Arc::new(SharedRegisters {
            registers,
            descriptions: OnceLock::new(),
            plan: Mutex::new(None),
        }))
    }
}

impl FromIterator<RegisterConfig> for RegisterList {
    fn from_iter<I: IntoIterator<Item = RegisterConfig>>(registers: I) -> Self {
        Self::from(registers.into_iter().collect::<Vec<_>>())
    }
}

impl std::ops::Deref for RegisterList {
    type Target = [RegisterConfig];

    fn deref(&self) -> &[RegisterConfig] {
        &self.0.registers
    }
}

impl PartialEq for RegisterList {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.0, &other.0) || self.0.registers == other.0.registers
    }
}

/// A Modbus device with configured registers.
pub struct ModbusDriver {
    device: DeviceId,
    unit: UnitId,
    config: ClientConfig,
    client: Option<Client>,
    registers: RegisterList,
    /// The reads, item `i` being register `i`; splits are kept across polls. Shared with
    /// the devices of the same register list until a split.
    plan: Arc<Plan>,
    options: ModbusOptions,
    /// When the last request ended, for `delay_between_requests`.
    last_request: Option<Instant>,
    /// The line was (re)attached since the last request: `delay_after_connect` is due.
    fresh_line: bool,
    /// Requests the last poll sent.
    requests: Option<u64>,
    /// The good readings of a poll that then failed, until the scheduler takes them.
    partial: Vec<Reading>,
    /// Each register's point id, in the registers' order (made once: readings share them
    /// with the cell's point specs).
    ids: Vec<PointId>,
}

/// A read's answer.
#[derive(Debug, Clone, PartialEq)]
enum Answer {
    Words(Vec<u16>),
    Bits(Vec<bool>),
}

/// One register's (or bit's) part of an answer.
#[derive(Debug, Clone, Copy)]
enum Part<'a> {
    Words(&'a [u16]),
    Bits(&'a [bool]),
}

impl ModbusDriver {
    /// A driver for the device `config` describes.
    pub fn new(config: &DriverConfig) -> Result<Self, String> {
        let unit = unit(config.address)?;
        let settings = config.settings.get::<ModbusSettings>().ok_or_else(|| {
            "a modbus device needs its registers: add [[line.device.register]] tables with name and address, or registers_csv".to_owned()
        })?;
        let ids = settings
            .registers
            .iter()
            .map(|r| PointId::new(&config.id, &r.name).map_err(|e| e.to_string()))
            .collect::<Result<Vec<_>, _>>()?;
        let plan = settings
            .registers
            .plan(settings.options.plan)
            .map_err(|e| match settings.registers.get(plan_error_index(&e)) {
                Some(r) => format!("register {}: {e}", r.name),
                None => e.to_string(),
            })?;
        let defaults = ClientConfig::default();
        Ok(Self {
            device: config.id.clone(),
            unit,
            config: ClientConfig {
                timeout: config.timeout.unwrap_or(defaults.timeout),
                retries: config.retries.unwrap_or(defaults.retries),
                framing: config.endpoint.as_ref().map_or(Framing::Rtu, Framing::of),
                ..defaults
            },
            client: None,
            plan,
            options: settings.options,
            registers: settings.registers.clone(),
            last_request: None,
            fresh_line: false,
            requests: None,
            partial: Vec::new(),
            ids,
        })
    }

    /// The reads each poll sends (fewer registers per read after splits).
    pub fn plan(&self) -> &Plan {
        &self.plan
    }

    /// Waits what the pacing asks before a request.
    async fn pace(&mut self) {
        if std::mem::take(&mut self.fresh_line) {
            if !self.options.delay_after_connect.is_zero() {
                tokio::time::sleep(self.options.delay_after_connect).await;
            }
        } else if let Some(last) = self.last_request
            && !self.options.delay_between_requests.is_zero()
        {
            tokio::time::sleep_until(last + self.options.delay_between_requests).await;
        }
    }

    /// Sends read `index` of the plan.
    async fn read(&mut self, index: usize) -> Result<Answer, ClientError> {
        self.pace().await;
        let read = self.plan.reads()[index].clone();
        let (unit, address, count) = (self.unit, read.address(), read.count());
        let client = self
            .client
            .as_mut()
            .expect("poll_live checks that the line is attached");
        let answer = match read.table() {
            Table::HoldingRegisters => client
                .read_holding_registers(unit, address, count)
                .await
                .map(Answer::Words),
            Table::InputRegisters => client
                .read_input_registers(unit, address, count)
                .await
                .map(Answer::Words),
            Table::Coils => client
                .read_coils(unit, address, count)
                .await
                .map(Answer::Bits),
            Table::DiscreteInputs => client
                .read_discrete_inputs(unit, address, count)
                .await
                .map(Answer::Bits),
        };
        self.last_request = Some(Instant::now());
        answer
    }

    async fn poll_live(&mut self) -> Result<Vec<Reading>, DeviceError> {
        // What a failed poll hands over is this poll's only.
        self.partial.clear();
        if self.client.is_none() {
            return Err(DeviceError::not_attached());
        }
        let mut answers: Vec<Result<Answer, DeviceError>> = Vec::new();
        let mut requests = 0u64;
        while answers.len() < self.plan.reads().len() {
            let index = answers.len();
            requests += 1;
            match self.read(index).await {
                Ok(answer) => answers.push(Ok(answer)),
                Err(e)
                    if jbus::client::exception_code(&e)
                        .is_some_and(ExceptionCode::is_about_the_addresses) =>
                {
                    match Arc::make_mut(&mut self.plan).split(index) {
                        Some(split @ Split::Into { .. }) => {
                            tracing::warn!(device = %self.device, "{split}");
                        }
                        _ => answers.push(Err(DeviceError::of(&e))),
                    }
                }
                // A refusal from the device itself, not a go-between's "no answer from it".
                Err(e @ ClientError::Refused { .. }) if e.kind() == FailureKind::Refused => {
                    answers.push(Err(DeviceError::of(&e)));
                }
                Err(e) => {
                    self.requests = Some(requests);
                    // The registers of the reads answered so far are kept.
                    self.partial = self
                        .readings(&answers)
                        .filter(|r| r.value.is_ok())
                        .collect();
                    return Err(DeviceError::of(&e));
                }
            }
        }
        self.requests = Some(requests);
        Ok(self.readings(&answers).collect())
    }

    /// The readings of the registers whose reads are among `answers` (the plan's first
    /// reads, in order): all of them once every read is answered.
    fn readings<'a>(
        &'a self,
        answers: &'a [Result<Answer, DeviceError>],
    ) -> impl Iterator<Item = Reading> + 'a {
        self.registers.iter().enumerate().filter_map(move |(i, r)| {
            let value = match self.plan.locate(i) {
                Some(at) => match answers.get(at.read)? {
                    Ok(Answer::Words(words)) => at
                        .slice(words)
                        .ok_or_else(|| missing(r))
                        .and_then(|words| r.value(Part::Words(words))),
                    Ok(Answer::Bits(bits)) => at
                        .slice(bits)
                        .ok_or_else(|| missing(r))
                        .and_then(|bits| r.value(Part::Bits(bits))),
                    Err(e) => Err(e.clone()),
                },
                None => Err(missing(r)),
            };
            Some(Reading {
                point: self.ids[i].clone(),
                value,
            })
        })
    }

    async fn write_point(&mut self, point: &PointSpec, value: &Value) -> Result<(), WriteError> {
        let register = self
            .registers
            .iter()
            .find(|r| r.name == point.id.name())
            .cloned()
            .ok_or_else(|| WriteError::UnknownPoint {
                point: point.id.clone(),
            })?;
        let checked = point.check_write(value)?;
        let number = checked
            .as_number()
            .expect("check_write gives numbers for numeric and enumeration points");
        let out_of_range = || {
            let (min, max) = register.representable();
            WriteError::Invalid(crate::point::ValueError::OutOfRange {
                point: point.id.clone(),
                name: point.name.to_string(),
                value: number,
                min,
                max,
                unit: String::new(),
            })
        };
        let words =
            match register.table {
                RegisterTable::Coil => None,
                _ => Some(register.format.encode(&TypedValue::Float(number)).map_err(
                    |e| match e {
                        jbus::data::EncodeError::OutOfRange { .. } => out_of_range(),
                        other => WriteError::Invalid(crate::point::ValueError::NotRepresentable {
                            point: point.id.clone(),
                            name: point.name.to_string(),
                            why: other.to_string(),
                        }),
                    },
                )?),
            };
        self.pace().await;
        let (unit, address) = (self.unit, register.address);
        let client = self.client.as_mut().ok_or_else(DeviceError::not_attached)?;
        let sent = match words.as_deref() {
            None => client.write_single_coil(unit, address, number != 0.0).await,
            Some([word]) => client.write_single_register(unit, address, *word).await,
            Some(words) => client.write_multiple_registers(unit, address, words).await,
        };
        self.last_request = Some(Instant::now());
        sent.map_err(|e| WriteError::Device(DeviceError::of(&e)))
    }
}

impl Driver for ModbusDriver {
    fn points(&self) -> Vec<PointSpec> {
        self.registers
            .descriptions()
            .iter()
            .zip(&self.ids)
            .map(|(description, id)| PointSpec::new(id.clone(), Arc::clone(description)))
            .collect()
    }

    fn groups(&self) -> Vec<PollGroup> {
        vec![PollGroup {
            name: LIVE.to_owned(),
            period: Duration::from_secs(1),
        }]
    }

    fn attach(&mut self, line: SharedLine) {
        self.client = Some(Client::new(line, self.config));
        self.fresh_line = true;
    }

    fn poll<'a>(&'a mut self, group: &'a str) -> BoxFuture<'a, Result<Vec<Reading>, DeviceError>> {
        Box::pin(async move {
            if group == LIVE {
                self.poll_live().await
            } else {
                Err(DeviceError::new(
                    ErrorKind::Refused,
                    format_args!("Modbus devices have no poll group {group:?}"),
                ))
            }
        })
    }

    fn write<'a>(
        &'a mut self,
        point: &'a PointSpec,
        value: &'a Value,
    ) -> BoxFuture<'a, Result<(), WriteError>> {
        Box::pin(self.write_point(point, value))
    }

    fn take_partial(&mut self) -> Vec<Reading> {
        std::mem::take(&mut self.partial)
    }

    fn requests_per_poll(&self) -> Option<u64> {
        self.requests
    }

    fn deadband(&self, point: &str) -> Option<Option<Deadband>> {
        self.registers
            .iter()
            .find(|r| r.name == point)
            .map(|r| r.deadband)
    }
}

/// The register a plan error is about.
fn plan_error_index(error: &jbus::plan::PlanError) -> usize {
    match error {
        jbus::plan::PlanError::Empty { index, .. }
        | jbus::plan::PlanError::TooLong { index, .. }
        | jbus::plan::PlanError::PastLastAddress { index, .. } => *index,
        _ => usize::MAX,
    }
}

fn missing(register: &RegisterConfig) -> DeviceError {
    DeviceError::new(
        ErrorKind::Decode,
        format_args!("register {} was not in the answer", register.address),
    )
}

/// Scaled register values as the nearest short decimal.
fn round(value: f64) -> f64 {
    if value.abs() < 1e9 {
        (value * 1e6).round() / 1e6
    } else {
        value
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use jbus::data::Order;
    use jbus::slave::{Slave, SlaveMap};
    use wire::device::SharedModel;

    fn register(name: &str, table: RegisterTable, address: u16) -> RegisterConfig {
        RegisterConfig {
            table,
            ..RegisterConfig::holding(name, address)
        }
    }

    fn typed(name: &str, table: RegisterTable, address: u16, data_type: &str) -> RegisterConfig {
        RegisterConfig {
            format: Format::new(data_type.parse().unwrap(), Order::Abcd),
            ..register(name, table, address)
        }
    }

    fn scaled(register: RegisterConfig, scale: f64) -> RegisterConfig {
        RegisterConfig {
            format: register
                .format
                .scaled(jbus::data::Scaling::new(scale, 0.0).unwrap()),
            ..register
        }
    }

    fn registers() -> Vec<RegisterConfig> {
        vec![
            RegisterConfig {
                unit: Some("°C".into()),
                ..scaled(typed("supply", RegisterTable::Input, 100, "int16"), 0.1)
            },
            register("flow", RegisterTable::Input, 101),
            RegisterConfig {
                writable: Some((5.0, 30.0)),
                ..scaled(register("setpoint", RegisterTable::Holding, 0), 0.1)
            },
            register("mode", RegisterTable::Holding, 7),
        ]
    }

    const MAP: &str = "unit 17\nholding 0 = 215\nholding 7 = 2\ninput 100 = 0xFFF6 42\n";

    fn rig_with(
        map: &str,
        registers: impl Into<RegisterList>,
        options: ModbusOptions,
    ) -> (ModbusDriver, SharedModel<Slave>) {
        let slave = SharedModel::new(Slave::new(SlaveMap::parse(map).unwrap()));
        let (a, b) = tokio::io::duplex(1024);
        tokio::spawn(link::serve::serve_stream(b, slave.line(), None));
        let mut driver = ModbusDriver::new(&DriverConfig {
            id: DeviceId::new("chiller1").unwrap(),
            protocol: super::KIND,
            address: Some(17),
            timeout: Some(Duration::from_millis(200)),
            retries: Some(1),
            endpoint: None,
            settings: Settings::new(ModbusSettings {
                registers: registers.into(),
                options,
            }),
        })
        .unwrap();
        driver.attach(SharedLine::new(link::Line::from_stream(
            a,
            "modbus",
            Some(DEFAULT_SERIAL),
        )));
        (driver, slave)
    }

    fn rig() -> (ModbusDriver, SharedModel<Slave>) {
        rig_with(MAP, registers(), ModbusOptions::default())
    }

    fn value(readings: &[Reading], name: &str) -> Result<Value, DeviceError> {
        readings
            .iter()
            .find(|r| r.point.name() == name)
            .unwrap()
            .value
            .clone()
    }

    fn spans(driver: &ModbusDriver) -> Vec<(Table, u16, u16)> {
        driver
            .plan()
            .reads()
            .iter()
            .map(|r| (r.table(), r.address(), r.count()))
            .collect()
    }

    #[tokio::test(start_paused = true)]
    async fn registers_close_together_in_one_table_are_planned_into_one_read() {
        let (driver, _slave) = rig_with(MAP, registers(), ModbusOptions::default());
        assert_eq!(
            spans(&driver),
            vec![
                (Table::HoldingRegisters, 0, 8),
                (Table::InputRegisters, 100, 2),
            ]
        );
    }

    #[tokio::test(start_paused = true)]
    async fn one_request_per_register_reads_every_register_alone() {
        let options = ModbusOptions {
            plan: PlanOptions {
                one_request_per_item: true,
                ..PlanOptions::default()
            },
            ..ModbusOptions::default()
        };
        let (mut driver, _slave) = rig_with(MAP, registers(), options);
        assert_eq!(driver.plan().reads().len(), 4);
        let live = driver.poll(LIVE).await.unwrap();
        assert_eq!(value(&live, "mode"), Ok(Value::Number(2.0)));
        assert_eq!(driver.requests_per_poll(), Some(4));
    }

    #[tokio::test(start_paused = true)]
    async fn registers_are_read_scaled_and_signed_as_configured() {
        let (mut driver, _slave) = rig();
        let live = driver.poll(LIVE).await.unwrap();
        assert_eq!(value(&live, "supply"), Ok(Value::Number(-1.0)));
        assert_eq!(value(&live, "flow"), Ok(Value::Number(42.0)));
        assert_eq!(value(&live, "setpoint"), Ok(Value::Number(21.5)));
        assert_eq!(value(&live, "mode"), Ok(Value::Number(2.0)));
    }

    #[tokio::test(start_paused = true)]
    async fn a_merged_read_refused_for_a_hole_is_split_once_and_the_poll_goes_on() {
        // Holding 0 and 7 are one planned read of 8 registers; 1-6 do not exist.
        let (mut driver, slave) = rig();
        let live = driver.poll(LIVE).await.unwrap();
        assert_eq!(value(&live, "setpoint"), Ok(Value::Number(21.5)));
        assert_eq!(value(&live, "mode"), Ok(Value::Number(2.0)));
        assert_eq!(value(&live, "supply"), Ok(Value::Number(-1.0)));
        // The refused read, its two parts, and the input registers.
        assert_eq!(driver.requests_per_poll(), Some(4));
        assert_eq!(
            spans(&driver),
            vec![
                (Table::HoldingRegisters, 0, 1),
                (Table::HoldingRegisters, 7, 1),
                (Table::InputRegisters, 100, 2),
            ]
        );
        driver.poll(LIVE).await.unwrap();
        assert_eq!(driver.requests_per_poll(), Some(3), "the split is kept");
        drop(slave);
    }

    #[tokio::test(start_paused = true)]
    async fn devices_of_one_register_list_share_its_plan_until_one_splits_a_read() {
        let list = RegisterList::from(registers());
        let (mut first, _first) = rig_with(MAP, list.clone(), ModbusOptions::default());
        let (second, _second) = rig_with(MAP, list.clone(), ModbusOptions::default());
        assert!(Arc::ptr_eq(&first.plan, &second.plan));
        // Holding 1-6 do not exist: the first device splits its merged read.
        first.poll(LIVE).await.unwrap();
        assert_eq!(spans(&first).len(), 3);
        assert_eq!(
            spans(&second),
            vec![
                (Table::HoldingRegisters, 0, 8),
                (Table::InputRegisters, 100, 2),
            ],
            "the other device keeps the plan as made"
        );
        let alone = ModbusOptions {
            plan: PlanOptions {
                one_request_per_item: true,
                ..PlanOptions::default()
            },
            ..ModbusOptions::default()
        };
        let (third, _third) = rig_with(MAP, list, alone);
        assert_eq!(third.plan().reads().len(), 4, "other options, another plan");
    }

    #[tokio::test(start_paused = true)]
    async fn a_register_the_device_does_not_have_is_bad_with_the_exception_in_words() {
        let mut registers = registers();
        registers.push(register("ghost", RegisterTable::Holding, 500));
        let (mut driver, _slave) = rig_with(MAP, registers, ModbusOptions::default());
        let live = driver.poll(LIVE).await.unwrap();
        let ghost = value(&live, "ghost").unwrap_err();
        assert_eq!(ghost.kind, ErrorKind::Refused, "{ghost}");
        assert!(ghost.message.contains("illegal data address"), "{ghost}");
        assert_eq!(value(&live, "flow"), Ok(Value::Number(42.0)));
        assert_eq!(value(&live, "mode"), Ok(Value::Number(2.0)));
    }

    /// A device that answers a request with an exception when `refuse` says so (a read
    /// that covers a register it fails on, a unit behind a gateway that is not there),
    /// and is `inner` otherwise.
    struct Refusing<D> {
        inner: D,
        refuse: fn(&jbus::rtu::RequestPdu) -> Option<ExceptionCode>,
    }

    impl<D: wire::Device> wire::Device for Refusing<D> {
        fn receive(&mut self, bytes: &[u8], now: std::time::Instant) -> Vec<wire::Transmit> {
            if let Ok(Some((adu, _))) = jbus::rtu::codec::decode_request(bytes)
                && let Some(code) = (self.refuse)(&adu.pdu)
            {
                let answer = jbus::rtu::ResponseAdu {
                    unit: adu.unit,
                    response: jbus::rtu::Response::exception(
                        jbus::rtu::FunctionCode::of_exception(adu.pdu.function_byte()),
                        code,
                    ),
                };
                let mut out = Vec::new();
                jbus::rtu::codec::encode_response(&answer, &mut out);
                return vec![wire::Transmit::now(out)];
            }
            self.inner.receive(bytes, now)
        }
    }

    fn rig_refusing(
        registers: Vec<RegisterConfig>,
        refuse: fn(&jbus::rtu::RequestPdu) -> Option<ExceptionCode>,
    ) -> ModbusDriver {
        let slave = SharedModel::new(Slave::new(SlaveMap::parse(MAP).unwrap()));
        let (a, b) = tokio::io::duplex(1024);
        let device = Refusing {
            inner: slave.line(),
            refuse,
        };
        tokio::spawn(link::serve::serve_stream(b, device, None));
        let (mut driver, _) = rig_with(MAP, registers, ModbusOptions::default());
        driver.attach(SharedLine::new(link::Line::from_stream(
            a,
            "modbus",
            Some(DEFAULT_SERIAL),
        )));
        driver
    }

    #[tokio::test(start_paused = true)]
    async fn a_poll_that_fails_midway_hands_over_what_its_answered_reads_gave() {
        // Holding 0-7 all defined, so the first read is answered whole.
        const FULL: &str = "unit 17\nholding 0 = 215 0 0 0 0 0 0 2\ninput 100 = 0xFFF6 42\n";
        let slave = SharedModel::new(Slave::new(SlaveMap::parse(FULL).unwrap()));
        let (a, b) = tokio::io::duplex(1024);
        let device =
            testkit::Tricky::new(slave.line(), []).silent_after(std::sync::Arc::new(1.into()));
        tokio::spawn(link::serve::serve_stream(b, device, None));
        let (mut driver, _) = rig_with(FULL, registers(), ModbusOptions::default());
        driver.attach(SharedLine::new(link::Line::from_stream(
            a,
            "modbus",
            Some(DEFAULT_SERIAL),
        )));
        assert_eq!(driver.plan.reads().len(), 2, "holding 0-7, input 100-101");
        let in_first_read =
            |driver: &ModbusDriver, i: usize| driver.plan.locate(i).is_some_and(|at| at.read == 0);
        let first: Vec<String> = (0..driver.registers.len())
            .filter(|&i| in_first_read(&driver, i))
            .map(|i| driver.registers[i].name.to_string())
            .collect();
        assert_eq!(first, ["setpoint", "mode"]);

        let down = driver.poll(LIVE).await.unwrap_err();
        assert_eq!(down.kind, ErrorKind::Timeout, "{down}");
        let partial = driver.take_partial();
        let names: Vec<String> = partial.iter().map(|r| r.point.name().to_owned()).collect();
        assert_eq!(
            names, first,
            "the first read's registers, none of the second's"
        );
        assert_eq!(value(&partial, "setpoint"), Ok(Value::Number(21.5)));
        assert_eq!(value(&partial, "mode"), Ok(Value::Number(2.0)));
        assert!(driver.take_partial().is_empty(), "taken once");
    }

    #[tokio::test(start_paused = true)]
    async fn a_merged_read_refused_with_exception_4_is_split_so_only_the_failing_register_is_bad() {
        // Holding 0-7 are one read; the device fails on holding 7 (exception 4).
        let mut driver = rig_refusing(registers(), |pdu| match *pdu {
            jbus::rtu::RequestPdu::ReadHoldingRegisters { address, count }
                if address <= 7 && 7 < address + count =>
            {
                Some(ExceptionCode::SERVER_DEVICE_FAILURE)
            }
            _ => None,
        });
        let live = driver.poll(LIVE).await.unwrap();
        assert_eq!(value(&live, "setpoint"), Ok(Value::Number(21.5)));
        let mode = value(&live, "mode").unwrap_err();
        assert_eq!(mode.kind, ErrorKind::Refused, "{mode}");
        assert!(mode.message.contains("exception 4"), "{mode}");
        assert_eq!(value(&live, "flow"), Ok(Value::Number(42.0)));
    }

    #[tokio::test(start_paused = true)]
    async fn a_unit_a_modbus_gateway_says_does_not_answer_is_down_not_up_with_bad_points() {
        let mut driver = rig_refusing(registers(), |_| Some(ExceptionCode::GATEWAY_TARGET_FAILED));
        let down = driver.poll(LIVE).await.unwrap_err();
        assert_eq!(down.kind, ErrorKind::Timeout, "{down}");
        assert!(down.message.contains("did not answer"), "{down}");
        let mut driver = rig_refusing(registers(), |_| {
            Some(ExceptionCode::GATEWAY_PATH_UNAVAILABLE)
        });
        assert_eq!(
            driver.poll(LIVE).await.unwrap_err().kind,
            ErrorKind::Timeout
        );
    }

    const TYPED: &str = "unit 17\n\
        input 0x0100 float32 CDAB = 229.7 -1.5\n\
        input 0x0104 int32 = -70000\n\
        holding 0x0200 float32 = 12.5\n\
        holding 0x0300 string:4 = \"PUMP 7\"\n\
        holding 0x0310 = 0x0008\n\
        coil 3 = 1 0\n\
        discrete 0x20 = 0 1\n";

    fn typed_registers() -> Vec<RegisterConfig> {
        vec![
            RegisterConfig {
                format: Format::new(DataType::Float32, Order::Cdab),
                unit: Some("V".into()),
                ..register("voltage", RegisterTable::Input, 0x0100)
            },
            RegisterConfig {
                format: Format::new(DataType::Float32, Order::Cdab),
                ..register("current", RegisterTable::Input, 0x0102)
            },
            typed("energy", RegisterTable::Input, 0x0104, "int32"),
            RegisterConfig {
                writable: Some((0.0, 100.0)),
                ..typed("limit", RegisterTable::Holding, 0x0200, "float32")
            },
            typed("label", RegisterTable::Holding, 0x0300, "string:4"),
            typed("alarm_bit", RegisterTable::Holding, 0x0310, "bit:3"),
            RegisterConfig {
                writable: Some((0.0, 1.0)),
                ..register("pump", RegisterTable::Coil, 3)
            },
            register("door", RegisterTable::Discrete, 0x21),
        ]
    }

    #[tokio::test(start_paused = true)]
    async fn typed_registers_coils_and_discrete_inputs_are_read_as_their_kinds() {
        let (mut driver, _slave) = rig_with(TYPED, typed_registers(), ModbusOptions::default());
        let live = driver.poll(LIVE).await.unwrap();
        assert_eq!(value(&live, "voltage"), Ok(Value::Number(229.7)));
        assert_eq!(value(&live, "current"), Ok(Value::Number(-1.5)));
        assert_eq!(value(&live, "energy"), Ok(Value::Number(-70000.0)));
        assert_eq!(value(&live, "limit"), Ok(Value::Number(12.5)));
        assert_eq!(value(&live, "label"), Ok(Value::Text("PUMP 7".into())));
        assert_eq!(value(&live, "alarm_bit"), Ok(Value::Number(1.0)));
        assert_eq!(value(&live, "pump"), Ok(Value::Number(1.0)));
        assert_eq!(value(&live, "door"), Ok(Value::Number(1.0)));
        let points = driver.points();
        let kind = |name: &str| {
            points
                .iter()
                .find(|p| p.id.name() == name)
                .unwrap()
                .kind
                .clone()
        };
        assert_eq!(kind("voltage"), PointKind::Numeric);
        assert_eq!(kind("label"), PointKind::Text);
        for on_off in ["pump", "door", "alarm_bit"] {
            assert!(
                matches!(kind(on_off), PointKind::Enum { ref states } if states.len() == 2),
                "{on_off}"
            );
        }
    }

    #[tokio::test(start_paused = true)]
    async fn a_float_is_written_with_function_16_and_a_coil_with_function_5() {
        let (mut driver, slave) = rig_with(TYPED, typed_registers(), ModbusOptions::default());
        let points = driver.points();
        let point = |name: &str| points.iter().find(|p| p.id.name() == name).unwrap();
        driver
            .write(point("limit"), &Value::Number(42.25))
            .await
            .unwrap();
        let words = {
            let slave = slave.lock();
            [
                slave.get(Table::HoldingRegisters, 0x0200).unwrap(),
                slave.get(Table::HoldingRegisters, 0x0201).unwrap(),
            ]
        };
        assert_eq!(
            Format::new(DataType::Float32, Order::Abcd).decode(&words),
            Ok(TypedValue::Float(42.25))
        );
        driver
            .write(point("pump"), &Value::Text("off".into()))
            .await
            .unwrap();
        assert_eq!(slave.lock().get(Table::Coils, 3), Some(0));
        let err = driver
            .write(point("voltage"), &Value::Number(1.0))
            .await
            .unwrap_err();
        assert!(matches!(err, WriteError::Invalid(_)), "{err}");
        // Within the range, but a float32 would hold 0: refused with that reason.
        let err = driver
            .write(point("limit"), &Value::Number(1e-50))
            .await
            .unwrap_err();
        assert!(
            matches!(
                &err,
                WriteError::Invalid(crate::point::ValueError::NotRepresentable { .. })
            ) && err.to_string().contains("too small for float32"),
            "{err}"
        );
    }

    #[tokio::test(start_paused = true)]
    async fn a_write_is_checked_against_range_and_step_then_sent_as_the_register_word() {
        let (mut driver, slave) = rig();
        let points = driver.points();
        let setpoint = points.iter().find(|p| p.id.name() == "setpoint").unwrap();
        let err = driver
            .write(setpoint, &Value::Number(31.0))
            .await
            .unwrap_err();
        assert!(matches!(err, WriteError::Invalid(_)), "{err}");
        let err = driver
            .write(setpoint, &Value::Number(22.25))
            .await
            .unwrap_err();
        assert!(err.to_string().contains("multiple of 0.1"), "{err}");
        assert_eq!(slave.lock().get(Table::HoldingRegisters, 0), Some(215));
        driver.write(setpoint, &Value::Number(22.5)).await.unwrap();
        assert_eq!(slave.lock().get(Table::HoldingRegisters, 0), Some(225));
        let mode = points.iter().find(|p| p.id.name() == "mode").unwrap();
        assert!(driver.write(mode, &Value::Number(1.0)).await.is_err());
    }

    #[tokio::test(start_paused = true)]
    async fn requests_are_paced_after_the_line_is_attached_and_between_each_other() {
        let options = ModbusOptions {
            plan: PlanOptions {
                one_request_per_item: true,
                ..PlanOptions::default()
            },
            delay_between_requests: Duration::from_millis(50),
            delay_after_connect: Duration::from_secs(2),
        };
        let (mut driver, _slave) = rig_with(MAP, registers(), options);
        let started = Instant::now();
        driver.poll(LIVE).await.unwrap();
        let first = started.elapsed();
        // 2 s after the attach, then 3 gaps of 50 ms between the 4 requests.
        assert!(
            first >= Duration::from_millis(2150) && first < Duration::from_millis(2500),
            "{first:?}"
        );
        let started = Instant::now();
        driver.poll(LIVE).await.unwrap();
        let second = started.elapsed();
        assert!(
            second >= Duration::from_millis(150) && second < Duration::from_millis(500),
            "{second:?}"
        );
    }
}
