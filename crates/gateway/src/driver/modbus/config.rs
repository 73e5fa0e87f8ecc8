//! A generic Modbus device's own keys of `[[line.device]]`: how its reads are planned and
//! paced, and its registers, as `[[line.device.register]]` tables or a `registers_csv`
//! file ([`super::register_csv`]). The cell's config hands them here
//! ([`super::Modbus`]'s [`DeviceKind::read_keys`](crate::driver::DeviceKind::read_keys)).

use std::collections::{HashMap, HashSet};
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Duration;

use jbus::data::{DataType, Format, Order, Scaling};
use jbus::rtu::{ReadBitCount, ReadRegisterCount};
use serde::Deserialize;
use toml::Spanned;

use super::register_csv::{RawRegister, RawWritable};
use super::{ModbusOptions, RegisterConfig, RegisterList, RegisterTable};
use crate::config::table::{read_bounded_text, read_text};
use crate::config::{ConfigError, Scratch, Settings, Table, check_deadband, duration};
use crate::driver::{DeviceContext, DriverConfig};
use crate::point::{Deadband, DeviceId};

/// Longest pacing delay accepted (`delay_between_requests`, `delay_after_connect`).
pub const MAX_PACING_DELAY: Duration = Duration::from_secs(60);

/// Largest register list read from a CSV file.
pub const MAX_REGISTERS_CSV: u64 = 4 << 20;

/// The keys of `[[line.device]]` only a modbus device takes.
pub const KEYS: [&str; 7] = [
    "max_registers_per_request",
    "max_bits_per_request",
    "one_request_per_register",
    "delay_between_requests",
    "delay_after_connect",
    "registers_csv",
    "register",
];

/// What a modbus device's own keys say: its registers and how they are read.
#[derive(Debug, Clone, PartialEq)]
pub struct ModbusSettings {
    /// The registers, from the config's tables or its CSV file.
    pub registers: RegisterList,
    /// How reads are planned and paced.
    pub options: ModbusOptions,
}

/// Reads a modbus device's own keys.
pub(super) fn read_keys(
    table: &Table<'_>,
    device: &DeviceContext,
    scratch: &mut Scratch,
) -> Result<Settings, ConfigError> {
    let raw: RawKeys = table.read()?;
    let at = |span: Range<usize>, message: String| table.at(span, message);
    let options = check_modbus_options(&raw, &at)?;
    let registers = check_registers(
        &raw,
        device.id_span.clone(),
        table.path(),
        device.deadband,
        scratch.get::<CsvRegisterLists>(),
        &at,
    )?;
    Ok(Settings::new(ModbusSettings { registers, options }))
}

/// A modbus device's own keys.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawKeys {
    max_registers_per_request: Option<Spanned<i64>>,
    max_bits_per_request: Option<Spanned<i64>>,
    one_request_per_register: Option<Spanned<bool>>,
    delay_between_requests: Option<Spanned<String>>,
    delay_after_connect: Option<Spanned<String>>,
    registers_csv: Option<Spanned<String>>,
    #[serde(default)]
    register: Vec<RawRegister>,
}

/// The device-level Modbus settings: request sizes and pacing.
fn check_modbus_options(
    raw: &RawKeys,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<ModbusOptions, ConfigError> {
    let mut options = ModbusOptions::default();
    if let Some(n) = &raw.max_registers_per_request {
        options.plan.max_registers =
            request_size(n, "max_registers_per_request", ReadRegisterCount::MAX, at)?;
    }
    if let Some(n) = &raw.max_bits_per_request {
        options.plan.max_bits = request_size(n, "max_bits_per_request", ReadBitCount::MAX, at)?;
    }
    if let Some(one) = &raw.one_request_per_register {
        options.plan.one_request_per_item = *one.get_ref();
    }
    let pacing = |d, key| duration(d, Duration::ZERO, MAX_PACING_DELAY, key, at);
    if let Some(d) = &raw.delay_between_requests {
        options.delay_between_requests = pacing(d, "delay_between_requests")?;
    }
    if let Some(d) = &raw.delay_after_connect {
        options.delay_after_connect = pacing(d, "delay_after_connect")?;
    }
    Ok(options)
}

/// The most registers or bits one request asks for, as the device's `key` sets it: refused
/// outside 1 to `max`, what the count `C` allows.
fn request_size<C: TryFrom<u16>>(
    n: &Spanned<i64>,
    key: &str,
    max: u16,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<C, ConfigError> {
    u16::try_from(*n.get_ref())
        .ok()
        .and_then(|n| C::try_from(n).ok())
        .ok_or_else(|| {
            at(
                n.span(),
                format!("{key} {} is out of range: 1 to {max}", n.get_ref()),
            )
        })
}

/// The register lists read from `registers_csv` files so far, by file and the device's
/// deadband (which the registers take): a thousand meters naming one file share one list
/// (each parsing its own copy was two thirds of the heap with 100 registers a meter).
#[derive(Default)]
struct CsvRegisterLists(HashMap<(PathBuf, String), RegisterList>);

/// The registers of a generic Modbus device: its `[[line.device.register]]` tables, or
/// the rows of its `registers_csv` file (relative to the config file's directory), read
/// once for every device that names it with the same deadband.
fn check_registers(
    raw: &RawKeys,
    id_span: Range<usize>,
    path: &Path,
    deadband: Option<Deadband>,
    csv_lists: &mut CsvRegisterLists,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<RegisterList, ConfigError> {
    match (&raw.registers_csv, raw.register.first()) {
        (Some(csv), Some(_)) => Err(at(
            csv.span(),
            "registers_csv and [[line.device.register]] tables both given: name the registers in one place"
                .into(),
        )),
        (Some(csv), None) => {
            let file = path
                .parent()
                .unwrap_or_else(|| Path::new(""))
                .join(csv.get_ref().trim());
            let key = (file.clone(), format!("{deadband:?}"));
            if let Some(list) = csv_lists.0.get(&key) {
                return Ok(list.clone());
            }
            let text = read_bounded_text(&file, MAX_REGISTERS_CSV).map_err(|why| {
                    at(
                        csv.span(),
                        format!("registers_csv {}: {why}", file.display()),
                    )
                })?;
            let table = super::register_csv::CsvRegisters::parse(&text, &file)?;
            if table.rows.is_empty() {
                return Err(at(
                    csv.span(),
                    format!(
                        "registers_csv {} names no registers, only its header: a modbus \
                         device needs at least one",
                        file.display()
                    ),
                ));
            }
            let list = RegisterList::from(check_register_list(
                &table.rows,
                deadband,
                &|span, message| table.error(span, message),
            )?);
            csv_lists.0.insert(key, list.clone());
            Ok(list)
        }
        (None, Some(_)) => check_register_list(&raw.register, deadband, at).map(Into::into),
        (None, None) => Err(at(
            id_span,
            "a modbus device needs its registers: add [[line.device.register]] tables with name and address, or registers_csv"
                .into(),
        )),
    }
}

/// The registers of a CSV register list (`cellbus config import-csv`), checked as a
/// device's would be.
pub fn registers_from_csv(file: &Path) -> Result<Vec<RegisterConfig>, ConfigError> {
    let text = read_text(file)?;
    let table = super::register_csv::CsvRegisters::parse(&text, file)?;
    check_register_list(&table.rows, None, &|span, message| {
        table.error(span, message)
    })
}

/// The example energy meter's register list (`examples/energy-meter.csv`), shipped in the
/// binary: a made-up 3-phase meter, float32 input registers, ABCD.
pub const EXAMPLE_METER_CSV: &str = include_str!("../../../examples/energy-meter.csv");

/// The simulator map that serves the example meter (`examples/energy-meter.map`), shipped
/// in the binary: `cellbus sim modbus --example energy-meter`.
pub const EXAMPLE_METER_MAP: &str = include_str!("../../../examples/energy-meter.map");

/// A configuration that reads the example meter at `endpoint` (a `modbus-tcp://` URL, as
/// `cellbus sim modbus --example energy-meter --framing tcp` prints), its registers as
/// tables: `cellbus config example --modbus-meter`.
pub fn example_meter_config(endpoint: &str) -> Result<String, ConfigError> {
    let path = Path::new("energy-meter.csv");
    let table = super::register_csv::CsvRegisters::parse(EXAMPLE_METER_CSV, path)?;
    let registers = check_register_list(&table.rows, None, &|span, message| {
        table.error(span, message)
    })?;
    Ok(format!(
        "# One energy meter over Modbus TCP: the example meter, as\n\
         #   cellbus sim modbus --example energy-meter --framing tcp --listen 127.0.0.1:5020\n\
         # serves it. Check with `cellbus config check`, run with `cellbus serve --config`.\n\
         [[line]]\n\
         name = \"meters\"\n\
         endpoint = \"{endpoint}\"\n\
         \n\
         [[line.device]]\n\
         id = \"meter1\"\n\
         name = \"Energy meter (example)\"\n\
         protocol = \"modbus\"\n\
         address = 1\n\
         \n\
         {}",
        registers_toml(&registers)
    ))
}

/// `registers` as `[[line.device.register]]` tables (defaults left out).
pub fn registers_toml(registers: &[RegisterConfig]) -> String {
    super::register_csv::to_toml(registers)
}

/// Most pairs of registers [`overlapping_registers`] names for one list.
pub const MAX_OVERLAPS_NAMED: usize = 20;

/// Registers of one list that share a register (a `float32` at 100 and another at 101),
/// one sentence per pair, in address order: how an address off by one shows. The file is
/// still valid (reading a `uint32` and its low word apart can be meant), so these are
/// warnings. Bits (`bit:N`, coils, discrete inputs) are left out: several of one
/// register is what they are for. At most [`MAX_OVERLAPS_NAMED`] pairs are named, then
/// one sentence says there are more (a list of thousands at one address stays quick).
pub fn overlapping_registers(registers: &[RegisterConfig]) -> Vec<String> {
    let mut words: Vec<&RegisterConfig> = registers.iter().filter(|r| !r.is_bool()).collect();
    words.sort_by_key(|r| (r.table, r.address));
    let end = |r: &RegisterConfig| u32::from(r.address) + u32::from(r.length());
    let span = |r: &RegisterConfig| match r.length() {
        1 => format!("{} {}", r.table.as_str(), r.address),
        _ => format!("{} {}–{}", r.table.as_str(), r.address, end(r) - 1),
    };
    let mut found = Vec::new();
    for (i, a) in words.iter().enumerate() {
        let later = words[i + 1..]
            .iter()
            .take_while(|b| b.table == a.table && u32::from(b.address) < end(a));
        for b in later {
            if found.len() == MAX_OVERLAPS_NAMED {
                found.push(format!(
                    "more registers share a register (the first {MAX_OVERLAPS_NAMED} pairs \
                     are named)"
                ));
                return found;
            }
            let shared_end = end(a).min(end(b)) - 1;
            let shared = if shared_end == u32::from(b.address) {
                format!("register {}", b.address)
            } else {
                format!("registers {}–{shared_end}", b.address)
            };
            found.push(format!(
                "registers {:?} ({}) and {:?} ({}) share {} {shared}",
                a.name,
                span(a),
                b.name,
                span(b),
                a.table.as_str()
            ));
        }
    }
    found
}

fn check_register_list(
    raw: &[RawRegister],
    deadband: Option<Deadband>,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<Vec<RegisterConfig>, ConfigError> {
    let mut names = HashSet::new();
    let mut registers = Vec::new();
    for r in raw {
        let name = r.name.get_ref();
        if !names.insert(name.clone()) {
            return Err(at(
                r.name.span(),
                format!("register name {name:?} is used twice"),
            ));
        }
        registers.push(check_register(r, deadband, at)?);
    }
    Ok(registers)
}

/// One register, with `deadband` (the device's) when it names none.
fn check_register(
    r: &RawRegister,
    deadband: Option<Deadband>,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<RegisterConfig, ConfigError> {
    let name = r.name.get_ref();
    DeviceId::new(name).map_err(|e| {
        at(
            r.name.span(),
            format!("register name {name:?} is not valid: {}", e.rule),
        )
    })?;
    let address = u16::try_from(*r.address.get_ref()).map_err(|_| {
        at(
            r.address.span(),
            format!(
                "register {name}: address {} is out of range: 0 to 65535",
                r.address.get_ref()
            ),
        )
    })?;
    let table = match &r.table {
        None => RegisterTable::Holding,
        Some(t) => RegisterTable::parse(t.get_ref()).ok_or_else(|| {
            at(
                t.span(),
                format!(
                    "register {name}: table {:?} is not one a register can be in: write {}",
                    t.get_ref(),
                    RegisterTable::CHOICES
                ),
            )
        })?,
    };
    if table.holds_bits() {
        let word_fields = [
            ("type", r.data_type.as_ref().map(Spanned::span)),
            ("order", r.order.as_ref().map(Spanned::span)),
            ("scale", r.scale.as_ref().map(Spanned::span)),
            ("offset", r.offset.as_ref().map(Spanned::span)),
            ("signed", r.signed.as_ref().map(Spanned::span)),
        ];
        if let Some((field, Some(span))) = word_fields.into_iter().find(|(_, s)| s.is_some()) {
            return Err(at(
                span,
                format!(
                    "register {name}: {field} is for holding and input registers; a {} is a single bit (off or on)",
                    table.as_str()
                ),
            ));
        }
    }
    let data_type = match (&r.data_type, &r.signed) {
        (Some(_), Some(signed)) => {
            return Err(at(
                signed.span(),
                format!(
                    "register {name}: signed is the old way of saying type = \"int16\"; give type only"
                ),
            ));
        }
        (Some(t), None) => t
            .get_ref()
            .trim()
            .parse::<DataType>()
            .map_err(|e| at(t.span(), format!("register {name}: {e}")))?,
        (None, Some(signed)) if *signed.get_ref() => DataType::Int16,
        (None, _) => DataType::Uint16,
    };
    let order = match &r.order {
        None => Order::default(),
        Some(o) => o
            .get_ref()
            .parse::<Order>()
            .map_err(|e| at(o.span(), format!("register {name}: {e}")))?,
    };
    if !data_type.is_number() {
        for (field, value) in [("scale", &r.scale), ("offset", &r.offset)] {
            if let Some(v) = value {
                return Err(at(
                    v.span(),
                    format!(
                        "register {name}: {field} is for numbers; a {data_type} register is not one"
                    ),
                ));
            }
        }
    }
    let scale = match &r.scale {
        None => 1.0,
        Some(s) if s.get_ref().is_finite() && *s.get_ref() > 0.0 => *s.get_ref(),
        Some(s) => {
            return Err(at(
                s.span(),
                format!(
                    "register {name}: scale {} must be a number above 0",
                    s.get_ref()
                ),
            ));
        }
    };
    let offset = match &r.offset {
        None => 0.0,
        Some(o) if o.get_ref().is_finite() => *o.get_ref(),
        Some(o) => {
            return Err(at(
                o.span(),
                format!("register {name}: offset {} must be a number", o.get_ref()),
            ));
        }
    };
    let scaling = Scaling::new(scale, offset).map_err(|e| {
        let span = r.scale.as_ref().map_or(r.name.span(), Spanned::span);
        at(span, format!("register {name}: {e}"))
    })?;
    let own_deadband = check_deadband(&r.deadband, &r.deadband_percent, at)?;
    let mut register = RegisterConfig {
        name: name.clone(),
        title: r.title.clone().unwrap_or_else(|| name.clone()),
        table,
        address,
        format: Format::new(data_type, order).scaled(scaling),
        unit: r.unit.clone(),
        writable: None,
        deadband: None,
    };
    if u32::from(address) + u32::from(register.length()) > 0x1_0000 {
        return Err(at(
            r.address.span(),
            format!("register {name}: a {data_type} at {address} runs past the last address 65535"),
        ));
    }
    if own_deadband.is_some() && !register.is_numeric() {
        let span = r
            .deadband
            .as_ref()
            .or(r.deadband_percent.as_ref())
            .map_or(r.name.span(), Spanned::span);
        return Err(at(
            span,
            format!("register {name}: a deadband is for numbers; this register is not one"),
        ));
    }
    register.deadband = if register.is_numeric() {
        own_deadband.or(deadband)
    } else {
        None
    };
    if let Some(w) = &r.writable {
        register.writable = check_writable(&register, w, at)?;
    }
    Ok(register)
}

/// The write range of a register: coils are on/off, holding registers of any number type
/// take a range within what they hold.
fn check_writable(
    register: &RegisterConfig,
    w: &Spanned<RawWritable>,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<Option<(f64, f64)>, ConfigError> {
    let name = &register.name;
    match register.table {
        RegisterTable::Input | RegisterTable::Discrete => {
            return Err(at(
                w.span(),
                format!(
                    "register {name}: only holding registers and coils can be written; {} are read-only",
                    register.table.table()
                ),
            ));
        }
        RegisterTable::Holding if !register.is_numeric() => {
            return Err(at(
                w.span(),
                format!(
                    "register {name}: a {} register is read-only here; numbers and coils can be written",
                    register.format.data_type
                ),
            ));
        }
        _ => {}
    }
    let (low, high) = register.representable();
    match w.get_ref() {
        RawWritable::Flag(false) => Ok(None),
        RawWritable::Flag(true) => Ok(Some((low, high))),
        RawWritable::Range(range) => {
            if range.min < range.max && range.min >= low && range.max <= high {
                Ok(Some(if register.is_bool() {
                    (0.0, 1.0)
                } else {
                    (range.min, range.max)
                }))
            } else {
                Err(at(
                    w.span(),
                    format!(
                        "register {name}: writable range {} to {} must be increasing and within what the register holds ({low} to {high})",
                        range.min, range.max
                    ),
                ))
            }
        }
    }
}

/// Where `[[line.device.register]]` tables given to another kind are shown: the first
/// one's name.
pub(super) fn first_register_name(value: &Spanned<toml::de::DeValue<'_>>) -> Range<usize> {
    let toml::de::DeValue::Array(tables) = value.get_ref() else {
        return value.span();
    };
    tables
        .iter()
        .next()
        .and_then(|first| match first.get_ref() {
            toml::de::DeValue::Table(table) => table.get("name").map(Spanned::span),
            _ => None,
        })
        .unwrap_or_else(|| value.span())
}

/// The registers of `devices` that share a register ([`overlapping_registers`]), one
/// sentence each naming the device; devices with the same register list (one
/// `registers_csv`) are named once, with how many more.
pub(super) fn warnings(devices: &[&DriverConfig]) -> Vec<String> {
    let mut lists: Vec<(&DriverConfig, &RegisterList, usize)> = Vec::new();
    for driver in devices {
        let Some(settings) = driver.settings.get::<ModbusSettings>() else {
            continue;
        };
        let registers = &settings.registers;
        if registers.is_empty() {
            continue;
        }
        match lists.iter_mut().find(|(_, first, _)| *first == registers) {
            Some((_, _, more)) => *more += 1,
            None => lists.push((driver, registers, 0)),
        }
    }
    let mut warnings = Vec::new();
    for (driver, registers, more) in lists {
        let who = match more {
            0 => format!("device {:?}", driver.id.as_str()),
            n => format!(
                "device {:?} (and {n} more with the same registers)",
                driver.id.as_str()
            ),
        };
        for overlap in overlapping_registers(registers) {
            warnings.push(format!("{who}: {overlap}"));
        }
    }
    warnings
}

#[cfg(test)]
#[path = "config_tests.rs"]
mod tests;
