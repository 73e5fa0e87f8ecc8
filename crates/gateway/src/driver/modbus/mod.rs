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
use jbus::rtu::{ExceptionCode, UnitId};
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
    Checked, Deadband, DeviceId, PointDescription, PointId, PointKind, PointSpec, Value, WriteRange,
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
        super::foreign_key(self.name(), key, value, other)
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
    super::jbus_unit(
        address,
        "a Modbus device",
        "Modbus unit number",
        "never answered",
    )
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

    async fn write_point(&mut self, point: &PointSpec, value: &Checked) -> Result<(), WriteError> {
        let register = self
            .registers
            .iter()
            .find(|r| r.name == point.id.name())
            .cloned()
            .ok_or_else(|| WriteError::UnknownPoint {
                point: point.id.clone(),
            })?;
        let number = value.number();
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

    fn poll_time(&self, group: &str, serial: SerialSettings) -> Option<Duration> {
        if group != LIVE {
            return None;
        }
        let reads = self.plan.reads();
        let data = reads.iter().map(|read| match read.table() {
            jbus::slave::Table::Coils | jbus::slave::Table::DiscreteInputs => {
                usize::from(read.count()).div_ceil(8)
            }
            jbus::slave::Table::HoldingRegisters | jbus::slave::Table::InputRegisters => {
                2 * usize::from(read.count())
            }
        });
        let pauses = self.options.delay_between_requests
            * u32::try_from(reads.len().saturating_sub(1)).unwrap_or(u32::MAX);
        Some(super::rtu_reads_time(serial, data) + pauses)
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
        value: &'a Checked,
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
mod tests;
