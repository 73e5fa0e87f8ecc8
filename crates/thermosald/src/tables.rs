//! The four data tables of a regulator, as named, scaled, ranged items.
//!
//! thermosald-isc-rs485.txt, "LIST OF DATA ITEMS": machine data 0–24, settings data 0–15,
//! run-time data 0–6, service (start-up, commissioning) data 0–16. The wire carries three
//! digits; the item's [`Scale`] turns them into the value a user reads and writes
//! (`[xx.x]` tenths, `[x.xx]` hundredths, `[xxx0]` tens). Where the label says `(x100)` or
//! `(x 1000)` over a plain `[xxx]` field (heating factor, resistivity), the label's factor
//! is the scaling.
//!
//! The spec gives almost no ranges: an item accepts 0–999 raw unless the spec names its
//! values (address 0–7, 50/60 Hz, the `1 = …` switches). Items the regulator computes or
//! keeps for itself (run-time data, the theoretical service values, "internal" and "not
//! used" items) are not [`Item::writable`].
//!
//! Look items up by index ([`Table::item`]) or by name ([`Table::find`]; case, spaces,
//! underscores and punctuation do not matter): `settings` / `set sealing temperature`,
//! `machine` / `KINT gain`.

use std::fmt;

use crate::frame::{MAX_RAW, RawValue};
use crate::request::Message;

/// Items in the machine data table (0–24).
pub const MACHINE_ITEMS: usize = 25;
/// Items in the settings data table (0–15).
pub const SETTINGS_ITEMS: usize = 16;
/// Items in the run-time data table (0–6).
pub const RUNTIME_ITEMS: usize = 7;
/// Items in the service (start-up, commissioning) data table (0–16).
pub const SERVICE_ITEMS: usize = 17;

/// One of the regulator's data tables.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Table {
    /// MACHINE DATA: control gains, heating ramp, limits, the regulator's own address.
    Machine,
    /// SETTINGS DATA: set points and balancing parameters.
    Settings,
    /// RUN TIME DATA: measurements and the fault/warning number; read-only.
    Runtime,
    /// SERVICE DATA (start-up, commissioning): the sealing band and its supply.
    Service,
}

impl Table {
    /// Every table, in the spec's order.
    pub const ALL: [Table; 4] = [
        Table::Machine,
        Table::Settings,
        Table::Runtime,
        Table::Service,
    ];

    /// The items, by index.
    pub fn items(self) -> &'static [Item] {
        match self {
            Table::Machine => &MACHINE,
            Table::Settings => &SETTINGS,
            Table::Runtime => &RUNTIME,
            Table::Service => &SERVICE,
        }
    }

    /// How many items the table has (what a whole-table message carries).
    pub const fn len(self) -> usize {
        match self {
            Table::Machine => MACHINE_ITEMS,
            Table::Settings => SETTINGS_ITEMS,
            Table::Runtime => RUNTIME_ITEMS,
            Table::Service => SERVICE_ITEMS,
        }
    }

    /// Always false: every table has items (for clippy's `len` convention).
    pub const fn is_empty(self) -> bool {
        false
    }

    /// A short name for command lines and logs: `machine`, `settings`, `runtime`, `service`.
    pub const fn name(self) -> &'static str {
        match self {
            Table::Machine => "machine",
            Table::Settings => "settings",
            Table::Runtime => "runtime",
            Table::Service => "service",
        }
    }

    /// The message that reads the table (51, 52, 53, 58).
    pub const fn read_message(self) -> Message {
        match self {
            Table::Machine => Message::ReadMachine,
            Table::Settings => Message::ReadSettings,
            Table::Runtime => Message::ReadRuntime,
            Table::Service => Message::ReadService,
        }
    }

    /// The message that writes the table (11, 12, 18); `None` for run-time data.
    pub const fn write_message(self) -> Option<Message> {
        match self {
            Table::Machine => Some(Message::WriteMachine),
            Table::Settings => Some(Message::WriteSettings),
            Table::Runtime => None,
            Table::Service => Some(Message::WriteService),
        }
    }

    /// The item at `index`.
    pub fn item(self, index: u8) -> Result<&'static Item, LookupError> {
        self.items()
            .get(usize::from(index))
            .ok_or(LookupError::NoIndex {
                table: self,
                index: index.into(),
                len: self.len(),
            })
    }

    /// The item called `name`: its name, the spec's label, or an alias, compared without
    /// case, spaces, underscores or punctuation (`set_sealing_temperature`, `KINT gain`).
    ///
    /// A name several items share (the spec's label `Internal data item`) is refused as
    /// ambiguous, naming the candidates' indexes.
    pub fn find(self, name: &str) -> Result<&'static Item, LookupError> {
        let key = normalize(name);
        let mut found = self
            .items()
            .iter()
            .filter(|item| !key.is_empty() && item.keys().any(|k| normalize(k) == key));
        match (found.next(), found.next()) {
            (Some(item), None) => Ok(item),
            (None, _) => Err(LookupError::NoName {
                table: self,
                name: name.to_owned(),
            }),
            (Some(first), Some(second)) => {
                let mut indexes = vec![first.index, second.index];
                indexes.extend(found.map(|item| item.index));
                Err(LookupError::Ambiguous {
                    table: self,
                    name: name.to_owned(),
                    indexes,
                })
            }
        }
    }

    /// The item given by index (`15`) or by name (`set sealing temperature`).
    pub fn lookup(self, key: &str) -> Result<&'static Item, LookupError> {
        match key.trim().parse::<u32>() {
            Ok(index) => u8::try_from(index)
                .ok()
                .and_then(|i| self.items().get(usize::from(i)))
                .ok_or(LookupError::NoIndex {
                    table: self,
                    index,
                    len: self.len(),
                }),
            Err(_) => self.find(key),
        }
    }
}

impl fmt::Display for Table {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Table {
    type Err = LookupError;

    /// `machine`, `settings`, `runtime` (`run-time`, `run time`), `service` (`start-up`,
    /// `commissioning`), in any case.
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        match normalize(text).as_str() {
            "machine" | "machinedata" => Ok(Table::Machine),
            "settings" | "setting" | "settingsdata" => Ok(Table::Settings),
            "runtime" | "runtimedata" => Ok(Table::Runtime),
            "service" | "servicedata" | "startup" | "commissioning" => Ok(Table::Service),
            _ => Err(LookupError::NoTable {
                name: text.to_owned(),
            }),
        }
    }
}

/// An item or table that does not exist.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum LookupError {
    /// No item at this index.
    #[error("{table} data has no item {index} (its items are 0 to {})", .len - 1)]
    NoIndex {
        /// The table.
        table: Table,
        /// The index asked for.
        index: u32,
        /// Items in the table.
        len: usize,
    },
    /// No item by this name.
    #[error("{table} data has no item called {name:?}")]
    NoName {
        /// The table.
        table: Table,
        /// The name asked for.
        name: String,
    },
    /// A name several items answer to.
    #[error("{table} data has several items called {name:?} (indexes {indexes:?}); give the index")]
    Ambiguous {
        /// The table.
        table: Table,
        /// The name asked for.
        name: String,
        /// The indexes of the items that answer to it.
        indexes: Vec<u8>,
    },
    /// No table by this name.
    #[error("no data table called {name:?} (machine, settings, runtime, service)")]
    NoTable {
        /// The name asked for.
        name: String,
    },
}

/// The fixed-point scaling of an item: what one raw step is worth.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Scale {
    /// `[xxx]`: the raw value is the value.
    Units,
    /// `[xx.x]`, `(x10)`: tenths.
    Tenths,
    /// `[x.xx]`, `(x100)`: hundredths.
    Hundredths,
    /// `(x 1000)`: thousandths.
    Thousandths,
    /// `[xxx0]`, `(…/10)`: tens.
    Tens,
}

impl Scale {
    /// The value of one raw step.
    pub fn step(self) -> f64 {
        self.from_raw(1)
    }

    /// Decimal places to show.
    pub const fn decimals(self) -> usize {
        match self {
            Scale::Units | Scale::Tens => 0,
            Scale::Tenths => 1,
            Scale::Hundredths => 2,
            Scale::Thousandths => 3,
        }
    }

    /// The value of `raw` steps (dividing, so tenths are the nearest doubles: 125 → 12.5).
    pub fn from_raw(self, raw: u16) -> f64 {
        let raw = f64::from(raw);
        match self {
            Scale::Units => raw,
            Scale::Tenths => raw / 10.0,
            Scale::Hundredths => raw / 100.0,
            Scale::Thousandths => raw / 1000.0,
            Scale::Tens => raw * 10.0,
        }
    }

    /// `value` in raw steps, unrounded.
    fn to_steps(self, value: f64) -> f64 {
        match self {
            Scale::Units => value,
            Scale::Tenths => value * 10.0,
            Scale::Hundredths => value * 100.0,
            Scale::Thousandths => value * 1000.0,
            Scale::Tens => value / 10.0,
        }
    }
}

/// The unit of an item's value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Unit {
    /// A number without unit (gains, counts, switches, codes).
    None,
    /// Degrees Celsius (the line always carries °C).
    Celsius,
    /// Degrees per 10 ms (the heating ramp).
    CelsiusPer10Ms,
    /// Degrees per 10 s (the cooling gradient when balancing).
    CelsiusPer10S,
    /// Hertz.
    Hertz,
    /// Seconds.
    Seconds,
    /// Amperes.
    Ampere,
    /// Ohms.
    Ohm,
    /// Volts.
    Volt,
    /// Volt-amperes.
    VoltAmpere,
    /// Millimetres.
    Millimetre,
    /// Resistivity, ohm square millimetres per metre.
    OhmSquareMmPerMetre,
    /// Current density, amperes per square millimetre.
    AmperePerSquareMm,
    /// Percent.
    Percent,
}

impl Unit {
    /// The symbol, empty for [`Unit::None`].
    pub const fn symbol(self) -> &'static str {
        match self {
            Unit::None => "",
            Unit::Celsius => "°C",
            Unit::CelsiusPer10Ms => "°C/10 ms",
            Unit::CelsiusPer10S => "°C/10 s",
            Unit::Hertz => "Hz",
            Unit::Seconds => "s",
            Unit::Ampere => "A",
            Unit::Ohm => "Ω",
            Unit::Volt => "V",
            Unit::VoltAmpere => "VA",
            Unit::Millimetre => "mm",
            Unit::OhmSquareMmPerMetre => "Ω·mm²/m",
            Unit::AmperePerSquareMm => "A/mm²",
            Unit::Percent => "%",
        }
    }
}

impl fmt::Display for Unit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.symbol())
    }
}

/// One data item: where it is, what it is called, how it is scaled and what it accepts.
#[derive(Debug, PartialEq, Eq, Hash)]
pub struct Item {
    table: Table,
    index: u8,
    name: &'static str,
    label: &'static str,
    aliases: &'static [&'static str],
    unit: Unit,
    scale: Scale,
    min: u16,
    max: u16,
    writable: bool,
}

impl Item {
    /// The table the item belongs to.
    pub const fn table(&self) -> Table {
        self.table
    }

    /// The item's index in its table (the count field of a single-item message).
    pub const fn index(&self) -> u8 {
        self.index
    }

    /// The item's name: the spec's wording, without its scaling note.
    pub const fn name(&self) -> &'static str {
        self.name
    }

    /// The spec's label exactly as the item list prints it.
    pub const fn label(&self) -> &'static str {
        self.label
    }

    /// The unit of the scaled value.
    pub const fn unit(&self) -> Unit {
        self.unit
    }

    /// The fixed-point scaling.
    pub const fn scale(&self) -> Scale {
        self.scale
    }

    /// The lowest raw value the item accepts.
    pub const fn raw_min(&self) -> u16 {
        self.min
    }

    /// The highest raw value the item accepts.
    pub const fn raw_max(&self) -> u16 {
        self.max
    }

    /// The lowest value the item accepts, in its unit.
    pub fn min(&self) -> f64 {
        self.scale.from_raw(self.min)
    }

    /// The highest value the item accepts, in its unit.
    pub fn max(&self) -> f64 {
        self.scale.from_raw(self.max)
    }

    /// Whether the master may write the item (11, 12, 18). The regulator keeps run-time,
    /// computed, internal and unused items itself.
    pub const fn writable(&self) -> bool {
        self.writable
    }

    /// Whether `raw` is within the item's range.
    pub const fn accepts(&self, raw: RawValue) -> bool {
        raw.get() >= self.min && raw.get() <= self.max
    }

    /// The three wire digits for `value` in the item's unit (`180.0` °C → `180`, KINT gain
    /// `12.5` → `125`). Refused, naming the item, value, range and unit, when it is not a
    /// finite number, not a whole number of scale steps, or outside the item's range (which
    /// never exceeds three digits).
    pub fn to_raw(&self, value: f64) -> Result<RawValue, ValueError> {
        if !value.is_finite() {
            return Err(ValueError::NotANumber {
                table: self.table,
                item: self.name,
                value,
            });
        }
        let steps = self.scale.to_steps(value);
        let rounded = steps.round();
        if (steps - rounded).abs() > 1e-6 * rounded.abs().max(1.0) {
            return Err(ValueError::NotAStep {
                table: self.table,
                item: self.name,
                value,
                step: self.scale.step(),
                unit: self.unit,
            });
        }
        if rounded < f64::from(self.min) || rounded > f64::from(self.max) {
            return Err(ValueError::OutOfRange {
                table: self.table,
                item: self.name,
                value,
                min: self.min(),
                max: self.max(),
                unit: self.unit,
            });
        }
        // In range, so 0..=999: the cast is exact.
        Ok(RawValue::saturating(rounded))
    }

    /// The value of `raw` in the item's unit.
    pub fn from_raw(&self, raw: RawValue) -> f64 {
        self.scale.from_raw(raw.get())
    }

    /// The item with a raw value, for display (`180 °C`).
    pub fn reading(&'static self, raw: RawValue) -> Reading {
        Reading { item: self, raw }
    }

    /// Every name the item answers to in [`Table::find`].
    fn keys(&self) -> impl Iterator<Item = &'static str> {
        [self.name, self.label]
            .into_iter()
            .chain(self.aliases.iter().copied())
    }
}

/// A value that cannot be written to an item.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ValueError {
    /// Outside the item's range (which never exceeds three digits).
    #[error(
        "{table} item {item:?} = {} is outside its range, {} to {}",
        Quantity(*value, *unit),
        Quantity(*min, *unit),
        Quantity(*max, *unit)
    )]
    OutOfRange {
        /// The table.
        table: Table,
        /// The item's name.
        item: &'static str,
        /// The value given.
        value: f64,
        /// The lowest value accepted.
        min: f64,
        /// The highest value accepted.
        max: f64,
        /// The item's unit.
        unit: Unit,
    },
    /// Not a whole number of the item's steps.
    #[error(
        "{table} item {item:?} = {} is not a multiple of its step, {}",
        Quantity(*value, *unit),
        Quantity(*step, *unit)
    )]
    NotAStep {
        /// The table.
        table: Table,
        /// The item's name.
        item: &'static str,
        /// The value given.
        value: f64,
        /// The value of one raw step.
        step: f64,
        /// The item's unit.
        unit: Unit,
    },
    /// NaN or infinite.
    #[error("{table} item {item:?}: {value} is not a number")]
    NotANumber {
        /// The table.
        table: Table,
        /// The item's name.
        item: &'static str,
        /// The value given.
        value: f64,
    },
}

/// A value with its unit, for messages: `180 °C`, or `12.5` when the item has no unit.
struct Quantity(f64, Unit);

impl fmt::Display for Quantity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.1 {
            Unit::None => write!(f, "{}", self.0),
            unit => write!(f, "{} {unit}", self.0),
        }
    }
}

/// An item and its raw value: what a read returns, shown as `180 °C` or `12.5`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Reading {
    item: &'static Item,
    raw: RawValue,
}

impl Reading {
    /// The item.
    pub fn item(&self) -> &'static Item {
        self.item
    }

    /// The three wire digits.
    pub fn raw(&self) -> RawValue {
        self.raw
    }

    /// The scaled value in the item's unit.
    pub fn value(&self) -> f64 {
        self.item.from_raw(self.raw)
    }

    /// Whether the raw value is within the item's range.
    pub fn in_range(&self) -> bool {
        self.item.accepts(self.raw)
    }
}

impl fmt::Display for Reading {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let decimals = self.item.scale.decimals();
        write!(f, "{:.*}", decimals, self.value())?;
        match self.item.unit {
            Unit::None => Ok(()),
            unit => write!(f, " {unit}"),
        }
    }
}

/// Lower-case letters and digits only: how names are compared.
fn normalize(name: &str) -> String {
    name.chars()
        .filter(|c| c.is_alphanumeric())
        .flat_map(char::to_lowercase)
        .collect()
}

/// Shorthand for the static tables below.
#[allow(clippy::too_many_arguments)]
const fn item(
    table: Table,
    index: u8,
    name: &'static str,
    label: &'static str,
    unit: Unit,
    scale: Scale,
    range: (u16, u16),
    writable: bool,
) -> Item {
    Item {
        table,
        index,
        name,
        label,
        aliases: &[],
        unit,
        scale,
        min: range.0,
        max: range.1,
        writable,
    }
}

const fn aka(mut item: Item, aliases: &'static [&'static str]) -> Item {
    item.aliases = aliases;
    item
}

/// Any three-digit value.
const ANY: (u16, u16) = (0, MAX_RAW);
/// A `1 = …` switch.
const SWITCH: (u16, u16) = (0, 1);
const RW: bool = true;
const RO: bool = false;

use Scale::{Hundredths, Tens, Tenths, Thousandths, Units};
use Table::{Machine as M, Runtime as RT, Service as SV, Settings as ST};

/// MACHINE DATA 0–24.
static MACHINE: [Item; MACHINE_ITEMS] = [
    item(M, 0, "Not used", "Not used", Unit::None, Units, ANY, RO),
    item(
        M,
        1,
        "Heating ramp",
        "Heating ramp, Degrees/10ms",
        Unit::CelsiusPer10Ms,
        Units,
        ANY,
        RW,
    ),
    item(M, 2, "KV gain", "KV GAIN", Unit::None, Units, ANY, RW),
    item(
        M,
        3,
        "KINT gain",
        "KINT Gain (x10)",
        Unit::None,
        Tenths,
        ANY,
        RW,
    ),
    item(
        M,
        4,
        "KINT switching-on threshold",
        "KINT switching-on threshold",
        Unit::None,
        Units,
        ANY,
        RW,
    ),
    // The spec shows the panel's `00C` / `00F`; the wire's digits for them are not given.
    aka(
        item(
            M,
            5,
            "Temperature unit",
            "00C = ℃ / 00F = °F",
            Unit::None,
            Units,
            ANY,
            RW,
        ),
        &["degrees", "celsius fahrenheit"],
    ),
    aka(
        item(
            M,
            6,
            "Mains frequency",
            "50 / 60 Hz",
            Unit::Hertz,
            Units,
            (50, 60),
            RW,
        ),
        &["frequency"],
    ),
    item(
        M,
        7,
        "Maximum sealing time",
        "Maximum sealing time (x 10)",
        Unit::Seconds,
        Tenths,
        ANY,
        RW,
    ),
    item(
        M,
        8,
        "Partial short-circuit factor",
        "Part. Short. circ. factor (x10)",
        Unit::None,
        Tenths,
        ANY,
        RW,
    ),
    item(
        M,
        9,
        "Disabling 1 fault",
        "Disabling 1 fault",
        Unit::None,
        Units,
        ANY,
        RW,
    ),
    item(
        M,
        10,
        "Nominal current",
        "Nominal I current",
        Unit::Ampere,
        Units,
        ANY,
        RW,
    ),
    item(M, 11, "KD gain", "KD Gain", Unit::None, Units, ANY, RW),
    item(
        M,
        12,
        "Cold structure compensation",
        "1 = cold struct. comp.",
        Unit::None,
        Units,
        SWITCH,
        RW,
    ),
    item(
        M,
        13,
        "Serial enabling",
        "1 = serial enabling",
        Unit::None,
        Units,
        SWITCH,
        RW,
    ),
    aka(
        item(
            M,
            14,
            "Heat-sealer address",
            "Heat-sealer address",
            Unit::None,
            Units,
            (0, 7),
            RW,
        ),
        &["address"],
    ),
    item(
        M,
        15,
        "Disabling 2 fault",
        "Disabling 2 fault",
        Unit::None,
        Units,
        ANY,
        RW,
    ),
    item(M, 16, "J", "J", Unit::None, Units, ANY, RW),
    item(M, 17, "Unnamed 17", "", Unit::None, Units, ANY, RW),
    item(M, 18, "Unnamed 18", "", Unit::None, Units, ANY, RW),
    item(M, 19, "Unnamed 19", "", Unit::None, Units, ANY, RW),
    item(M, 20, "Unnamed 20", "", Unit::None, Units, ANY, RW),
    item(
        M,
        21,
        "Burn-in temperature",
        "Burn-in Temperature (℃)",
        Unit::Celsius,
        Units,
        ANY,
        RW,
    ),
    item(
        M,
        22,
        "Burn-in heating-up time",
        "Burn-in Heating-up time (sec.)",
        Unit::Seconds,
        Units,
        ANY,
        RW,
    ),
    item(M, 23, "Unnamed 23", "= (0001)", Unit::None, Units, ANY, RW),
    item(M, 24, "Unnamed 24", "", Unit::None, Units, ANY, RW),
];

/// SETTINGS DATA 0–15.
static SETTINGS: [Item; SETTINGS_ITEMS] = [
    item(
        ST,
        0,
        "Internal data item 0",
        "Internal data item",
        Unit::None,
        Units,
        ANY,
        RO,
    ),
    item(
        ST,
        1,
        "Internal data item 1",
        "Internal data item",
        Unit::None,
        Units,
        ANY,
        RO,
    ),
    item(
        ST,
        2,
        "Internal data item 2",
        "Internal data item",
        Unit::None,
        Units,
        ANY,
        RO,
    ),
    item(
        ST,
        3,
        "Internal data item 3",
        "Internal data item",
        Unit::None,
        Units,
        ANY,
        RO,
    ),
    item(
        ST,
        4,
        "Internal data item 4",
        "Internal data item",
        Unit::None,
        Units,
        ANY,
        RO,
    ),
    item(
        ST,
        5,
        "Heating factor",
        "Heating Factor (x100)",
        Unit::None,
        Hundredths,
        ANY,
        RW,
    ),
    item(
        ST,
        6,
        "Internal data item 6",
        "Internal data item",
        Unit::None,
        Units,
        ANY,
        RO,
    ),
    item(
        ST,
        7,
        "Internal data item 7",
        "Internal data item",
        Unit::None,
        Units,
        ANY,
        RO,
    ),
    item(
        ST,
        8,
        "Internal data item 8",
        "Internal data item",
        Unit::None,
        Units,
        ANY,
        RO,
    ),
    item(
        ST,
        9,
        "Internal data item 9",
        "Internal data item",
        Unit::None,
        Units,
        ANY,
        RO,
    ),
    item(
        ST,
        10,
        "Internal data item 10",
        "Internal data item 10 (A)",
        Unit::None,
        Units,
        ANY,
        RO,
    ),
    item(
        ST,
        11,
        "Maximum working temperature",
        "Maximum working temperature (℃)",
        Unit::Celsius,
        Units,
        ANY,
        RW,
    ),
    item(
        ST,
        12,
        "Cooling gradient when balancing",
        "Cooling Gradient when balancing (degrees/10sec.)",
        Unit::CelsiusPer10S,
        Units,
        ANY,
        RW,
    ),
    aka(
        item(
            ST,
            13,
            "Sealer temperature for balancing",
            "Sealer temperature for balancing (℃)",
            Unit::Celsius,
            Units,
            ANY,
            RW,
        ),
        &["balancing temperature"],
    ),
    aka(
        item(
            ST,
            14,
            "Set pre-heating temperature",
            "Set pre-heating temp. (℃)",
            Unit::Celsius,
            Units,
            ANY,
            RW,
        ),
        &["pre-heating temperature", "preheat temperature", "pre-heat"],
    ),
    aka(
        item(
            ST,
            15,
            "Set sealing temperature",
            "Set sealing temp. (℃)",
            Unit::Celsius,
            Units,
            ANY,
            RW,
        ),
        &["sealing temperature"],
    ),
];

/// RUN TIME DATA 0–6 (read-only).
static RUNTIME: [Item; RUNTIME_ITEMS] = [
    item(RT, 0, "Not used", "Not used", Unit::None, Units, ANY, RO),
    aka(
        item(
            RT,
            1,
            "Current temperature",
            "Current Temperature (°C)",
            Unit::Celsius,
            Units,
            ANY,
            RO,
        ),
        &["temperature"],
    ),
    aka(
        item(
            RT,
            2,
            "Fault/warning number",
            "Fault/warning number (u)",
            Unit::None,
            Units,
            ANY,
            RO,
        ),
        &["fault", "fault number", "warning"],
    ),
    item(
        RT,
        3,
        "Maximum current",
        "Maximum current (A x 10)",
        Unit::Ampere,
        Tenths,
        ANY,
        RO,
    ),
    item(
        RT,
        4,
        "Resistance",
        "Resistance (ohm x 100)",
        Unit::Ohm,
        Hundredths,
        ANY,
        RO,
    ),
    aka(
        item(
            RT,
            5,
            "Actual voltage",
            "Actual voltage (volts)",
            Unit::Volt,
            Units,
            ANY,
            RO,
        ),
        &["voltage"],
    ),
    item(
        RT,
        6,
        "Power",
        "Power (VA/10)",
        Unit::VoltAmpere,
        Tens,
        ANY,
        RO,
    ),
];

/// SERVICE DATA 0–16.
static SERVICE: [Item; SERVICE_ITEMS] = [
    item(
        SV,
        0,
        "Sealing plate width",
        "Sealing plate width (mm x 10)",
        Unit::Millimetre,
        Tenths,
        ANY,
        RW,
    ),
    item(
        SV,
        1,
        "Sealing plate thickness",
        "Sealing plate thickness (mm x 100)",
        Unit::Millimetre,
        Hundredths,
        ANY,
        RW,
    ),
    item(
        SV,
        2,
        "Wire gauge",
        "Wire gauge (mm x 100)",
        Unit::Millimetre,
        Hundredths,
        ANY,
        RW,
    ),
    item(
        SV,
        3,
        "Sealing plate length",
        "Sealing plate length (mm)",
        Unit::Millimetre,
        Units,
        ANY,
        RW,
    ),
    item(
        SV,
        4,
        "Sealing plates in parallel",
        "No. of sealing plates in parallel (u)",
        Unit::None,
        Units,
        ANY,
        RW,
    ),
    item(
        SV,
        5,
        "Sealing plates in series",
        "No. of sealing plates in series (u)",
        Unit::None,
        Units,
        ANY,
        RW,
    ),
    aka(
        item(
            SV,
            6,
            "Resistivity",
            "Ohm x sq.mm / m (x 1000)",
            Unit::OhmSquareMmPerMetre,
            Thousandths,
            ANY,
            RW,
        ),
        &["ohm sq mm per m"],
    ),
    item(
        SV,
        7,
        "Current density",
        "Amperage / sq.mm (A/mmq)",
        Unit::AmperePerSquareMm,
        Units,
        ANY,
        RW,
    ),
    item(
        SV,
        8,
        "Duty cycle",
        "Duty cycle (x 10)",
        Unit::Percent,
        Tenths,
        ANY,
        RW,
    ),
    item(
        SV,
        9,
        "Maximum theoretical current",
        "Max. theoretical current (A)",
        Unit::Ampere,
        Units,
        ANY,
        RO,
    ),
    item(
        SV,
        10,
        "Theoretical resistance",
        "Theoretical resistence (ohm)",
        Unit::Ohm,
        Hundredths,
        ANY,
        RO,
    ),
    item(
        SV,
        11,
        "Theoretical voltage",
        "Theoretical voltage (V)",
        Unit::Volt,
        Units,
        ANY,
        RO,
    ),
    item(
        SV,
        12,
        "Theoretical power",
        "Theoretical power (VA / 10)",
        Unit::VoltAmpere,
        Tens,
        ANY,
        RO,
    ),
    item(
        SV,
        13,
        "Set maximum current",
        "Set max. current (A)",
        Unit::Ampere,
        Units,
        ANY,
        RW,
    ),
    item(
        SV,
        14,
        "Set resistance",
        "Set resistance (ohm x 100)",
        Unit::Ohm,
        Hundredths,
        ANY,
        RW,
    ),
    item(
        SV,
        15,
        "Set voltage",
        "Set voltage (V)",
        Unit::Volt,
        Units,
        ANY,
        RW,
    ),
    item(
        SV,
        16,
        "Set power",
        "Set power (VA / 10)",
        Unit::VoltAmpere,
        Tens,
        ANY,
        RW,
    ),
];

/// Indexes of the machine data items the twin and tools use by meaning.
pub mod machine {
    /// Heating ramp, degrees per 10 ms.
    pub const HEATING_RAMP: u8 = 1;
    /// KINT gain (tenths).
    pub const KINT_GAIN: u8 = 3;
    /// Maximum sealing time (tenths of a second).
    pub const MAXIMUM_SEALING_TIME: u8 = 7;
    /// Partial short-circuit factor (tenths).
    pub const PARTIAL_SHORT_CIRCUIT_FACTOR: u8 = 8;
    /// 1 = the serial interface answers.
    pub const SERIAL_ENABLING: u8 = 13;
    /// The regulator's own logic address, 0–7.
    pub const ADDRESS: u8 = 14;
}

/// Indexes of the settings data items the twin and tools use by meaning.
pub mod settings {
    /// Heating factor (hundredths).
    pub const HEATING_FACTOR: u8 = 5;
    /// Maximum working temperature, °C: the set points may not exceed it.
    pub const MAXIMUM_WORKING_TEMPERATURE: u8 = 11;
    /// Cooling gradient below which balancing measures, °C per 10 s.
    pub const COOLING_GRADIENT: u8 = 12;
    /// The band's temperature while balancing measures, °C.
    pub const BALANCING_TEMPERATURE: u8 = 13;
    /// Pre-heating set point, °C.
    pub const PRE_HEATING_TEMPERATURE: u8 = 14;
    /// Sealing set point, °C.
    pub const SEALING_TEMPERATURE: u8 = 15;
}

/// Indexes of the run-time data items.
pub mod runtime {
    /// Current temperature, °C.
    pub const TEMPERATURE: u8 = 1;
    /// Fault/warning number ([`crate::diagnostic`]).
    pub const FAULT: u8 = 2;
    /// Maximum current, tenths of an ampere.
    pub const MAXIMUM_CURRENT: u8 = 3;
    /// Resistance, hundredths of an ohm.
    pub const RESISTANCE: u8 = 4;
    /// Actual voltage, V.
    pub const VOLTAGE: u8 = 5;
    /// Power, tens of VA.
    pub const POWER: u8 = 6;
}

/// Indexes of the service data items.
pub mod service {
    /// Sealing plate (band) width, tenths of a millimetre.
    pub const WIDTH: u8 = 0;
    /// Band thickness, hundredths of a millimetre.
    pub const THICKNESS: u8 = 1;
    /// Wire gauge (round wire instead of a flat band), hundredths of a millimetre.
    pub const WIRE_GAUGE: u8 = 2;
    /// Band length, mm.
    pub const LENGTH: u8 = 3;
    /// Bands in parallel.
    pub const IN_PARALLEL: u8 = 4;
    /// Bands in series.
    pub const IN_SERIES: u8 = 5;
    /// Resistivity, thousandths of an Ω·mm²/m.
    pub const RESISTIVITY: u8 = 6;
    /// Current density, A/mm².
    pub const CURRENT_DENSITY: u8 = 7;
    /// Duty cycle, tenths of a percent.
    pub const DUTY_CYCLE: u8 = 8;
    /// Maximum theoretical current, A (computed).
    pub const THEORETICAL_CURRENT: u8 = 9;
    /// Theoretical resistance, hundredths of an ohm (computed).
    pub const THEORETICAL_RESISTANCE: u8 = 10;
    /// Theoretical voltage, V (computed).
    pub const THEORETICAL_VOLTAGE: u8 = 11;
    /// Theoretical power, tens of VA (computed).
    pub const THEORETICAL_POWER: u8 = 12;
    /// Set maximum current, A: above it the regulator trips on over-current.
    pub const SET_MAXIMUM_CURRENT: u8 = 13;
    /// Set resistance, hundredths of an ohm.
    pub const SET_RESISTANCE: u8 = 14;
    /// Set voltage, V: the transformer's secondary voltage.
    pub const SET_VOLTAGE: u8 = 15;
    /// Set power, tens of VA.
    pub const SET_POWER: u8 = 16;
}
