//! Any Modbus RTU / JBUS device, with its registers named in the configuration, through
//! `jbus::client`.
//!
//! ```toml
//! [[line.device]]
//! id = "chiller1"
//! protocol = "modbus"
//! address = 17                   # unit 1-255
//!
//! [[line.device.register]]
//! name = "supply_temperature"    # the point's name: a-z, 0-9, _ and -
//! title = "Supply temperature"   # words for people (default: the name)
//! table = "input"                # "holding" (default, functions 3/6) or "input" (4)
//! address = 0x0010               # register address (0-65535)
//! scale = 0.1                    # value = register × scale (default 1)
//! unit = "°C"
//! signed = true                  # two's complement (default false)
//!
//! [[line.device.register]]
//! name = "setpoint"
//! address = 0x0020
//! scale = 0.1
//! unit = "°C"
//! writable = { min = 5.0, max = 30.0 }   # holding registers only
//! ```
//!
//! One group, `live` (1 s): registers at consecutive addresses of one table are read
//! together (up to 125 per read). An exception marks the points of its read only; silence
//! or damage marks the device down. A write is checked against its range and the register's
//! step (`scale`) before it goes out as function 6.

use std::time::Duration;

use jbus::client::{Client, ClientConfig, ClientError, Framing};

use jbus::rtu::UnitId;
use link::{SerialSettings, SharedLine};

use super::{
    BoxFuture, DeviceError, Driver, DriverConfig, ErrorKind, PollGroup, Reading, WriteError,
};
use crate::point::{DeviceId, PointId, PointKind, PointSpec, Value, WriteRange};

/// A Modbus line when the URL says nothing: 9600 baud, 8N1.
pub const DEFAULT_SERIAL: SerialSettings = SerialSettings::new_8n1(9600);

/// Default unit number.
pub const DEFAULT_UNIT: i64 = 1;

/// The only group.
pub const LIVE: &str = "live";

/// Most registers one read asks for (Modbus's limit for function 3/4).
const MAX_READ: u16 = 125;

/// Which table a register is in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum RegisterTable {
    /// Holding registers: read with function 3, written with 6.
    Holding,
    /// Input registers: read-only, function 4.
    Input,
}

impl RegisterTable {
    /// The table for its config name (`holding`, `input`).
    pub fn parse(text: &str) -> Option<Self> {
        match text {
            "holding" => Some(Self::Holding),
            "input" => Some(Self::Input),
            _ => None,
        }
    }
}

/// One register as the configuration names it.
#[derive(Debug, Clone, PartialEq)]
pub struct RegisterConfig {
    /// The point's name.
    pub name: String,
    /// Words for people.
    pub title: String,
    /// The table it is in (holding or input registers).
    pub table: RegisterTable,
    /// Its register address, from 0.
    pub address: u16,
    /// What one step of the register is worth.
    pub scale: f64,
    /// The symbol of its unit of measure (`°C`, `kW`).
    pub unit: Option<String>,
    /// Two's complement.
    pub signed: bool,
    /// The range a write must fall into, if writable.
    pub writable: Option<(f64, f64)>,
}

impl RegisterConfig {
    /// The lowest and highest value the register can hold, in its unit.
    pub fn representable(&self) -> (f64, f64) {
        let (low, high) = if self.signed {
            (f64::from(i16::MIN), f64::from(i16::MAX))
        } else {
            (0.0, f64::from(u16::MAX))
        };
        (low * self.scale, high * self.scale)
    }

    fn value(&self, word: u16) -> f64 {
        let raw = if self.signed {
            f64::from(i16::from_ne_bytes(word.to_ne_bytes()))
        } else {
            f64::from(word)
        };
        round(raw * self.scale)
    }

    /// The word for `value`, already checked against the range and step.
    fn word(&self, value: f64) -> Option<u16> {
        let steps = (value / self.scale).round();
        if self.signed {
            (f64::from(i16::MIN)..=f64::from(i16::MAX))
                .contains(&steps)
                .then(|| u16::from_ne_bytes((steps as i16).to_ne_bytes()))
        } else {
            (0.0..=f64::from(u16::MAX))
                .contains(&steps)
                .then_some(steps as u16)
        }
    }
}

/// Checks a unit number: 1–255.
pub fn check_address(address: Option<i64>) -> Result<(), String> {
    match address {
        Some(a) if (i64::from(UnitId::MIN)..=i64::from(UnitId::JBUS_MAX)).contains(&a) => Ok(()),
        Some(a) => Err(format!(
            "Modbus unit number {a} is out of range: {} to {} (0 is broadcast, never answered)",
            UnitId::MIN,
            UnitId::JBUS_MAX
        )),
        None => Err(format!(
            "a Modbus device needs its unit number, {} to {}",
            UnitId::MIN,
            UnitId::JBUS_MAX
        )),
    }
}

/// A Modbus device with configured registers.
pub struct ModbusDriver {
    device: DeviceId,
    unit: UnitId,
    config: ClientConfig,
    client: Option<Client>,
    registers: Vec<RegisterConfig>,
    /// Reads covering every register: `(table, first address, count)`.
    plan: Vec<(RegisterTable, u16, u16)>,
}

impl ModbusDriver {
    /// A driver for the device `config` describes.
    pub fn new(config: &DriverConfig) -> Result<Self, String> {
        check_address(config.address)?;
        let unit = config
            .address
            .and_then(|a| u8::try_from(a).ok())
            .and_then(|a| UnitId::jbus(a).ok())
            .ok_or_else(|| "Modbus unit number out of range".to_owned())?;
        for r in &config.registers {
            PointId::new(&config.id, &r.name).map_err(|e| e.to_string())?;
        }
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
            plan: plan(&config.registers),
            registers: config.registers.clone(),
        })
    }

    fn point_id(&self, register: &RegisterConfig) -> PointId {
        PointId::new(&self.device, &register.name).expect("register names are checked in new")
    }

    async fn poll_live(&mut self) -> Result<Vec<Reading>, DeviceError> {
        let client = self.client.as_mut().ok_or_else(DeviceError::not_attached)?;
        let mut blocks = Vec::new();
        for &(table, start, count) in &self.plan {
            let read = match table {
                RegisterTable::Holding => {
                    client.read_holding_registers(self.unit, start, count).await
                }
                RegisterTable::Input => client.read_input_registers(self.unit, start, count).await,
            };
            let words = match read {
                Ok(words) => Ok(words),
                Err(e @ ClientError::Refused { .. }) => Err(DeviceError::of(&e)),
                Err(e) => return Err(DeviceError::of(&e)),
            };
            blocks.push((table, start, count, words));
        }
        Ok(self
            .registers
            .iter()
            .map(|r| {
                let covers = |(table, start, count, _): &&(
                    RegisterTable,
                    u16,
                    u16,
                    Result<Vec<u16>, DeviceError>,
                )| {
                    *table == r.table
                        && (u32::from(*start)..u32::from(*start) + u32::from(*count))
                            .contains(&u32::from(r.address))
                };
                let value = match blocks.iter().find(covers) {
                    Some((_, start, _, Ok(words))) => words
                        .get(usize::from(r.address - *start))
                        .map(|&w| Value::Number(r.value(w)))
                        .ok_or_else(|| missing(r)),
                    Some((_, _, _, Err(e))) => Err(e.clone()),
                    None => Err(missing(r)),
                };
                Reading {
                    point: self.point_id(r),
                    value,
                }
            })
            .collect())
    }

    async fn write_point(&mut self, point: &PointSpec, value: &Value) -> Result<(), WriteError> {
        let register = self
            .registers
            .iter()
            .find(|r| r.name == point.id.name())
            .ok_or_else(|| WriteError::UnknownPoint {
                point: point.id.clone(),
            })?;
        let checked = point.check_write(value)?;
        let number = checked
            .as_number()
            .expect("check_write gives numbers for numeric points");
        let word = register.word(number).ok_or_else(|| {
            let (min, max) = register.representable();
            WriteError::Invalid(crate::point::ValueError::OutOfRange {
                point: point.id.clone(),
                name: point.name.clone(),
                value: number,
                min,
                max,
                unit: String::new(),
            })
        })?;
        let (unit, address) = (self.unit, register.address);
        let client = self.client.as_mut().ok_or_else(DeviceError::not_attached)?;
        client
            .write_single_register(unit, address, word)
            .await
            .map_err(|e| WriteError::Device(DeviceError::of(&e)))
    }
}

impl Driver for ModbusDriver {
    fn points(&self) -> Vec<PointSpec> {
        self.registers
            .iter()
            .map(|r| PointSpec {
                id: self.point_id(r),
                name: r.title.clone(),
                unit: r.unit.clone(),
                kind: PointKind::Numeric,
                group: LIVE.to_owned(),
                writable: r.writable.map(|(min, max)| WriteRange {
                    min,
                    max,
                    integer: r.scale.fract() == 0.0,
                    step: (r.scale != 1.0).then_some(r.scale),
                }),
                alarm: None,
            })
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
}

/// The fewest reads covering every register: runs of consecutive addresses in one table,
/// up to [`MAX_READ`] long.
fn plan(registers: &[RegisterConfig]) -> Vec<(RegisterTable, u16, u16)> {
    let mut wanted: Vec<(RegisterTable, u16)> =
        registers.iter().map(|r| (r.table, r.address)).collect();
    wanted.sort_unstable();
    wanted.dedup();
    let mut plan: Vec<(RegisterTable, u16, u16)> = Vec::new();
    for (table, address) in wanted {
        match plan.last_mut() {
            Some((t, start, count))
                if *t == table
                    && u32::from(*start) + u32::from(*count) == u32::from(address)
                    && *count < MAX_READ =>
            {
                *count += 1;
            }
            _ => plan.push((table, address, 1)),
        }
    }
    plan
}

fn missing(register: &RegisterConfig) -> DeviceError {
    DeviceError::new(
        ErrorKind::Decode,
        format_args!("register {} was not in the answer", register.address),
    )
}

/// Scaled register values as the nearest short decimal.
fn round(value: f64) -> f64 {
    (value * 1e6).round() / 1e6
}

#[cfg(test)]
mod tests {
    use super::*;
    use jbus::slave::{Slave, SlaveMap};
    use wire::device::SharedModel;

    fn register(name: &str, table: RegisterTable, address: u16) -> RegisterConfig {
        RegisterConfig {
            name: name.into(),
            title: name.into(),
            table,
            address,
            scale: 1.0,
            unit: None,
            signed: false,
            writable: None,
        }
    }

    fn registers() -> Vec<RegisterConfig> {
        vec![
            RegisterConfig {
                scale: 0.1,
                unit: Some("°C".into()),
                signed: true,
                ..register("supply", RegisterTable::Input, 100)
            },
            register("flow", RegisterTable::Input, 101),
            RegisterConfig {
                scale: 0.1,
                writable: Some((5.0, 30.0)),
                ..register("setpoint", RegisterTable::Holding, 0)
            },
            register("mode", RegisterTable::Holding, 7),
        ]
    }

    fn rig() -> (ModbusDriver, SharedModel<Slave>) {
        let map =
            SlaveMap::parse("unit 17\nholding 0 = 215\nholding 7 = 2\ninput 100 = 0xFFF6 42\n")
                .unwrap();
        let slave = SharedModel::new(Slave::new(map));
        let (a, b) = tokio::io::duplex(1024);
        tokio::spawn(link::serve::serve_stream(b, slave.line(), None));
        let mut driver = ModbusDriver::new(&DriverConfig {
            id: DeviceId::new("chiller1").unwrap(),
            protocol: super::super::Protocol::Modbus,
            address: Some(17),
            timeout: Some(Duration::from_millis(200)),
            retries: Some(1),
            event_port: None,
            endpoint: None,
            registers: registers(),
        })
        .unwrap();
        driver.attach(SharedLine::new(link::Line::from_stream(
            a,
            "modbus",
            Some(DEFAULT_SERIAL),
        )));
        (driver, slave)
    }

    fn value(readings: &[Reading], name: &str) -> Result<Value, DeviceError> {
        readings
            .iter()
            .find(|r| r.point.name() == name)
            .unwrap()
            .value
            .clone()
    }

    #[test]
    fn consecutive_registers_of_one_table_are_read_together() {
        assert_eq!(
            plan(&registers()),
            vec![
                (RegisterTable::Holding, 0, 1),
                (RegisterTable::Holding, 7, 1),
                (RegisterTable::Input, 100, 2),
            ]
        );
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
        assert_eq!(
            slave
                .lock()
                .get(jbus::slave::map::Table::HoldingRegisters, 0),
            Some(215)
        );
        driver.write(setpoint, &Value::Number(22.5)).await.unwrap();
        assert_eq!(
            slave
                .lock()
                .get(jbus::slave::map::Table::HoldingRegisters, 0),
            Some(225)
        );
        let mode = points.iter().find(|p| p.id.name() == "mode").unwrap();
        assert!(driver.write(mode, &Value::Number(1.0)).await.is_err());
    }

    #[tokio::test(start_paused = true)]
    async fn an_exception_marks_only_the_points_of_its_read() {
        let (mut driver, _slave) = rig();
        driver
            .registers
            .push(register("ghost", RegisterTable::Holding, 500));
        driver.plan = plan(&driver.registers);
        let live = driver.poll(LIVE).await.unwrap();
        let ghost = value(&live, "ghost").unwrap_err();
        assert_eq!(ghost.kind, ErrorKind::Refused, "{ghost}");
        assert_eq!(value(&live, "flow"), Ok(Value::Number(42.0)));
    }
}
