//! The map of a generic Modbus server: which addresses of its four tables exist, with
//! their first values, and its unit number, from a small line-oriented text.
//!
//! ```text
//! # A pump controller.        '#' starts a comment; blank lines are ignored.
//! unit 17                     # unit number (default 1; 248-255 allowed, as JBUS does)
//! holding 0x0000 = 1 2 0xFF   # holding registers 0, 1, 2
//! input 100 = 7 8             # input registers 100, 101
//! coil 10 = 1 0 1             # coils 10, 11, 12 (values 0 or 1)
//! discrete 0x20 = 0 1         # discrete inputs 0x20, 0x21
//! holding 0x1000..=0x10FF     # a block of holding registers, all 0
//! holding 0x0100 float32 CDAB = 229.7 -1.5   # typed values: 4 registers from 0x0100
//! input 0x200 int32 = -2       # order ABCD unless given
//! holding 0x300 string:4 = "PUMP 7"           # 4 registers, NUL-padded
//! ```
//!
//! Numbers are decimal or `0x` hex. An address defined twice is an error, so a typo
//! cannot hide a register. Holding and input registers take typed values
//! (`TABLE ADDR TYPE [ORDER] = VALUE…`, types and orders of [`crate::data`]): each value
//! fills the type's registers, one after the other. A string takes the rest of the line,
//! in double quotes if it has spaces at its ends (a `#` inside quotes is text, not a
//! comment). A single bit (`bit:N`) is not a map value: give its register's value.

use std::fmt;
use std::str::FromStr;

use crate::data::{DataType, Format, Order, ParseTypeError};
use crate::rtu::{ADDRESS_SPACE, InvalidValue, UnitId};

/// One of the four Modbus tables.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Table {
    /// Read/write bits (functions 1, 5, 15).
    Coils,
    /// Read-only bits (function 2).
    DiscreteInputs,
    /// Read/write words (functions 3, 6, 16).
    HoldingRegisters,
    /// Read-only words (function 4).
    InputRegisters,
}

impl Table {
    /// Every table.
    pub const ALL: [Self; 4] = [
        Self::Coils,
        Self::DiscreteInputs,
        Self::HoldingRegisters,
        Self::InputRegisters,
    ];

    /// The word that names the table in a map file.
    pub const fn keyword(self) -> &'static str {
        match self {
            Self::Coils => "coil",
            Self::DiscreteInputs => "discrete",
            Self::HoldingRegisters => "holding",
            Self::InputRegisters => "input",
        }
    }

    /// Whether the table holds bits (values 0 and 1).
    pub const fn holds_bits(self) -> bool {
        matches!(self, Self::Coils | Self::DiscreteInputs)
    }

    pub(crate) const fn index(self) -> usize {
        match self {
            Self::Coils => 0,
            Self::DiscreteInputs => 1,
            Self::HoldingRegisters => 2,
            Self::InputRegisters => 3,
        }
    }

    fn from_keyword(word: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|t| t.keyword() == word)
    }
}

impl fmt::Display for Table {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Coils => "coils",
            Self::DiscreteInputs => "discrete inputs",
            Self::HoldingRegisters => "holding registers",
            Self::InputRegisters => "input registers",
        })
    }
}

/// A line of a map that cannot be read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("line {line}: {problem}")]
pub struct MapError {
    /// The line, counting from 1.
    pub line: usize,
    /// What is wrong with it.
    pub problem: MapProblem,
}

/// What is wrong with a line of a map.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum MapProblem {
    /// The first word is not a table or `unit`.
    #[error("`{word}` is not one of: unit, holding, input, coil, discrete")]
    UnknownKeyword {
        /// The word found.
        word: String,
    },
    /// A number that does not parse.
    #[error("`{text}` is not a {what} (write it in decimal or as 0x hex)")]
    BadNumber {
        /// The text found.
        text: String,
        /// What the number was for.
        what: &'static str,
    },
    /// A number too large for what it is.
    #[error("{what} {value} is above {max}")]
    TooLarge {
        /// What the number was for.
        what: &'static str,
        /// The number.
        value: u64,
        /// The largest allowed.
        max: u64,
    },
    /// Something else where a word was expected.
    #[error("expected {expected}, found {found}")]
    Expected {
        /// What should come.
        expected: &'static str,
        /// What came ("end of line" if nothing).
        found: String,
    },
    /// A bit value other than 0 or 1.
    #[error("`{text}` is not a bit value: coils and discrete inputs take 0 or 1")]
    BadBit {
        /// The text found.
        text: String,
    },
    /// Values running past address 0xFFFF.
    #[error("{count} values from address {address} run past the last address 65535 (0xFFFF)")]
    PastLastAddress {
        /// The first address.
        address: u16,
        /// How many values.
        count: usize,
    },
    /// A range whose end is before its start.
    #[error("the range {first}..={last} is empty: its end is before its start")]
    EmptyRange {
        /// The first address.
        first: u16,
        /// The last address.
        last: u16,
    },
    /// An address already defined.
    #[error("{table} address {address} (0x{address:04X}) was already defined on line {first_line}")]
    Duplicate {
        /// The table.
        table: Table,
        /// The address.
        address: u16,
        /// The line that defined it first.
        first_line: usize,
    },
    /// A bad unit number.
    #[error("bad unit: {0}")]
    UnitId(InvalidValue),
    /// A type or order that is not one.
    #[error("{0}")]
    BadType(ParseTypeError),
    /// A type on a table of bits.
    #[error(
        "{table} hold single bits: a type such as `{data_type}` is for holding and input registers"
    )]
    TypeOnBits {
        /// The table.
        table: Table,
        /// The type given.
        data_type: DataType,
    },
    /// `bit:N` as a map value.
    #[error(
        "`{data_type}` is one bit of a register: give the register's value instead (e.g. `= 0x0008` for bit 3)"
    )]
    BitValue {
        /// The type given.
        data_type: DataType,
    },
    /// A value that its type cannot hold, in words.
    #[error("{problem}")]
    BadValue {
        /// What is wrong with it.
        problem: String,
    },
}

/// The addresses of one table that exist, and their values.
#[derive(Clone, PartialEq, Eq)]
pub(crate) struct TableData {
    values: Vec<u16>,
    /// For each address: 0 if absent, else the map line that defined it (empty when
    /// `all`: every address exists).
    defined_on: Vec<u32>,
    all: bool,
}

impl fmt::Debug for TableData {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("TableData")
            .field("all", &self.all)
            .field("defined", &self.defined())
            .finish()
    }
}

impl TableData {
    fn empty() -> Self {
        Self {
            values: vec![0; ADDRESS_SPACE],
            defined_on: vec![0; ADDRESS_SPACE],
            all: false,
        }
    }

    fn full() -> Self {
        Self {
            values: vec![0; ADDRESS_SPACE],
            defined_on: Vec::new(),
            all: true,
        }
    }

    pub(crate) fn exists(&self, address: u16) -> bool {
        self.all
            || self
                .defined_on
                .get(usize::from(address))
                .is_some_and(|&l| l != 0)
    }

    pub(crate) fn get(&self, address: u16) -> Option<u16> {
        if self.exists(address) {
            self.values.get(usize::from(address)).copied()
        } else {
            None
        }
    }

    /// Sets an existing address; false if it does not exist.
    pub(crate) fn set(&mut self, address: u16, value: u16) -> bool {
        if !self.exists(address) {
            return false;
        }
        match self.values.get_mut(usize::from(address)) {
            Some(slot) => {
                *slot = value;
                true
            }
            None => false,
        }
    }

    /// Whether all `count` addresses from `address` exist (and stay below 0x10000).
    pub(crate) fn block_exists(&self, address: u16, count: usize) -> bool {
        usize::from(address) + count <= ADDRESS_SPACE
            && (usize::from(address)..usize::from(address) + count)
                .all(|a| u16::try_from(a).is_ok_and(|a| self.exists(a)))
    }

    pub(crate) fn defined(&self) -> usize {
        if self.all {
            ADDRESS_SPACE
        } else {
            self.defined_on.iter().filter(|&&l| l != 0).count()
        }
    }
}

/// A generic server's unit number and tables.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SlaveMap {
    pub(crate) unit: UnitId,
    pub(crate) tables: [TableData; 4],
}

impl SlaveMap {
    /// The default unit number.
    pub const DEFAULT_UNIT: u8 = 1;

    /// Every address of every table exists and holds 0 (65536 of each).
    pub fn all_writable(unit: UnitId) -> Self {
        Self {
            unit,
            tables: std::array::from_fn(|_| TableData::full()),
        }
    }

    /// Reads a map (see the module documentation for the format).
    pub fn parse(text: &str) -> Result<Self, MapError> {
        let default_unit = UnitId::new(Self::DEFAULT_UNIT).expect("1 is a unit number");
        let mut map = Self {
            unit: default_unit,
            tables: std::array::from_fn(|_| TableData::empty()),
        };
        for (index, raw) in text.lines().enumerate() {
            let line = index + 1;
            map.parse_line(raw, line)
                .map_err(|problem| MapError { line, problem })?;
        }
        Ok(map)
    }

    /// The unit number.
    pub fn unit(&self) -> UnitId {
        self.unit
    }

    /// The same map on another unit number.
    pub fn with_unit(mut self, unit: UnitId) -> Self {
        self.unit = unit;
        self
    }

    /// The value at `address` of `table`, if the address exists.
    pub fn get(&self, table: Table, address: u16) -> Option<u16> {
        self.tables[table.index()].get(address)
    }

    /// How many addresses of `table` exist.
    pub fn defined(&self, table: Table) -> usize {
        self.tables[table.index()].defined()
    }

    fn parse_line(&mut self, raw: &str, line: usize) -> Result<(), MapProblem> {
        let text = strip_comment(raw);
        let mut words = text.split_whitespace();
        let Some(keyword) = words.next() else {
            return Ok(());
        };
        if keyword == "unit" {
            let number = parse_number(words.next(), "unit number", 255)?;
            let number = u8::try_from(number).map_err(|_| MapProblem::TooLarge {
                what: "unit number",
                value: number,
                max: 255,
            })?;
            self.unit = UnitId::jbus(number).map_err(MapProblem::UnitId)?;
            return expect_end(words.next());
        }
        let table = Table::from_keyword(keyword).ok_or_else(|| MapProblem::UnknownKeyword {
            word: keyword.to_owned(),
        })?;
        let target = words.next();
        let (first, last) = match target.and_then(|t| t.split_once("..=")) {
            Some((first, last)) => {
                let first = parse_address(Some(first))?;
                let last = parse_address(Some(last))?;
                if last < first {
                    return Err(MapProblem::EmptyRange { first, last });
                }
                expect_end(words.next())?;
                (first, Some(last))
            }
            None => (parse_address(target)?, None),
        };
        let values: Vec<u16> = match last {
            Some(last) => vec![0; usize::from(last - first) + 1],
            None => {
                let values = match words.next() {
                    Some("=") => words
                        .map(|w| parse_value(w, table))
                        .collect::<Result<Vec<u16>, _>>()?,
                    // A type starts with a letter; anything else is a missing `=`.
                    Some(word) if word.starts_with(|c: char| c.is_ascii_alphabetic()) => {
                        parse_typed(text, word, &mut words, table)?
                    }
                    other => {
                        return Err(expected("`=` and values, or a range `FIRST..=LAST`", other));
                    }
                };
                if values.is_empty() {
                    return Err(expected("values after `=`", None));
                }
                values
            }
        };
        if usize::from(first) + values.len() > ADDRESS_SPACE {
            return Err(MapProblem::PastLastAddress {
                address: first,
                count: values.len(),
            });
        }
        let data = &mut self.tables[table.index()];
        let line_tag = u32::try_from(line).unwrap_or(u32::MAX);
        for (offset, value) in values.into_iter().enumerate() {
            let slot = usize::from(first) + offset;
            let address = u16::try_from(slot).unwrap_or(u16::MAX);
            match data.defined_on.get(slot) {
                Some(&first_line) if first_line != 0 => {
                    return Err(MapProblem::Duplicate {
                        table,
                        address,
                        first_line: first_line as usize,
                    });
                }
                _ => {}
            }
            if let Some(tag) = data.defined_on.get_mut(slot) {
                *tag = line_tag;
            }
            if let Some(stored) = data.values.get_mut(slot) {
                *stored = value;
            }
        }
        Ok(())
    }
}

impl FromStr for SlaveMap {
    type Err = MapError;
    fn from_str(text: &str) -> Result<Self, MapError> {
        Self::parse(text)
    }
}

fn expected(what: &'static str, found: Option<&str>) -> MapProblem {
    MapProblem::Expected {
        expected: what,
        found: found.map_or_else(|| "end of line".to_owned(), |f| format!("`{f}`")),
    }
}

fn expect_end(word: Option<&str>) -> Result<(), MapProblem> {
    match word {
        None => Ok(()),
        Some(w) => Err(expected("end of line", Some(w))),
    }
}

fn parse_number(word: Option<&str>, what: &'static str, max: u64) -> Result<u64, MapProblem> {
    let Some(text) = word else {
        return Err(expected(what, None));
    };
    let bad = || MapProblem::BadNumber {
        text: text.to_owned(),
        what,
    };
    let value = match text.strip_prefix("0x").or_else(|| text.strip_prefix("0X")) {
        Some(hex) => u64::from_str_radix(hex, 16).map_err(|_| bad())?,
        None => text.parse::<u64>().map_err(|_| bad())?,
    };
    if value > max {
        return Err(MapProblem::TooLarge { what, value, max });
    }
    Ok(value)
}

fn parse_address(word: Option<&str>) -> Result<u16, MapProblem> {
    let value = parse_number(word, "address", u64::from(u16::MAX))?;
    Ok(u16::try_from(value).unwrap_or(u16::MAX))
}

/// The line without its comment: from the first `#` outside double quotes.
fn strip_comment(raw: &str) -> &str {
    let mut quoted = false;
    for (index, character) in raw.char_indices() {
        match character {
            '"' => quoted = !quoted,
            '#' if !quoted => return &raw[..index],
            _ => {}
        }
    }
    raw
}

/// The registers of `TYPE [ORDER] = VALUE…`, `type_word` being the type and `words` the
/// rest of `text`'s words.
fn parse_typed<'a>(
    text: &'a str,
    type_word: &str,
    words: &mut impl Iterator<Item = &'a str>,
    table: Table,
) -> Result<Vec<u16>, MapProblem> {
    let data_type: DataType = type_word.parse().map_err(MapProblem::BadType)?;
    if table.holds_bits() {
        return Err(MapProblem::TypeOnBits { table, data_type });
    }
    if matches!(data_type, DataType::Bit(_)) {
        return Err(MapProblem::BitValue { data_type });
    }
    let order = match words.next() {
        Some("=") => Order::default(),
        Some(word) => {
            let order: Order = word.parse().map_err(MapProblem::BadType)?;
            match words.next() {
                Some("=") => order,
                other => return Err(expected("`=` and values", other)),
            }
        }
        None => return Err(expected("an order or `=` and values", None)),
    };
    let format = Format::new(data_type, order);
    let bad = |e: crate::data::EncodeError| MapProblem::BadValue {
        problem: e.to_string(),
    };
    if matches!(data_type, DataType::String(_)) {
        // The rest of the line after the `=` (the first one: the line is not a range).
        let rest = text.split_once('=').map_or("", |(_, rest)| rest).trim();
        if rest.is_empty() {
            return Err(expected("values after `=`", None));
        }
        let unquoted = rest
            .strip_prefix('"')
            .and_then(|r| r.strip_suffix('"'))
            .unwrap_or(rest);
        return format.encode_text(unquoted).map_err(bad);
    }
    let mut registers = Vec::new();
    for word in words {
        registers.extend(format.encode_text(word).map_err(bad)?);
    }
    if registers.is_empty() {
        return Err(expected("values after `=`", None));
    }
    Ok(registers)
}

fn parse_value(word: &str, table: Table) -> Result<u16, MapProblem> {
    if table.holds_bits() {
        return match word {
            "0" => Ok(0),
            "1" => Ok(1),
            _ => Err(MapProblem::BadBit {
                text: word.to_owned(),
            }),
        };
    }
    let value = parse_number(Some(word), "register value", u64::from(u16::MAX))?;
    Ok(u16::try_from(value).unwrap_or(u16::MAX))
}

#[cfg(test)]
mod tests;
