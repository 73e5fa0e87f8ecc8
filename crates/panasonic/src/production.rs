//! Production management data: the answer to C1M / C1N / C1Z (3.3-7 … 3.3-9).
//!
//! ```text
//! %HEADER
//! NAME=M000
//! MACHINE=BM
//! START=2003/01/30 08/00/00
//! END=2003/01/30 17/00/00
//! PANASONIC=3010
//! %MANAGEMENT
//! PRODUCTPLAN1=0000100
//! PRODUCT1=0000005
//! %CHARACTER
//! PICKUP_RATE=075.75
//! PICKUP=0001234
//! *
//! ```
//!
//! Every line ends in CRLF. The manual shows the keys above and a few more (the full list is
//! in the separate "Prg./DATA FORMAT" manual \[?\]). So this module keeps every `KEY=VALUE`
//! line it reads, in order, typed by its look: 7-digit counters as [`Value::Count`],
//! `ddd.dd` rates as [`Value::Rate`], anything else as [`Value::Text`]; the keys the
//! manual names have typed accessors ([`Counter`], [`RateKind`]).

use std::fmt;

use serde::{Serialize, Serializer};

use crate::calendar::{CalendarParseError, Timestamp};
use crate::program::{CRLF, END_MARK, HEADER_SECTION, lines};

/// The section of board and production counts.
pub const MANAGEMENT_SECTION: &str = "%MANAGEMENT";
/// The section of pick-up, mounting and error figures.
pub const CHARACTER_SECTION: &str = "%CHARACTER";
/// Width of a counter on the wire (3.3-9: `PRODUCT1=0000005`).
pub const COUNT_WIDTH: usize = 7;
/// The largest counter that fits 7 digits.
pub const MAX_COUNT: u32 = 9_999_999;
/// `MACHINE=` value of the manual's example.
pub const MACHINE_BM: &str = "BM";
/// `PANASONIC=` value of the manual's example (a format version, we assume \[I\]).
pub const PANASONIC_FORMAT: &str = "3010";

/// A percentage with two decimals, 0.00–100.00 (`075.75` on the wire).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Rate(u16);

/// A rate above 100.00 %.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("rate of {hundredths} hundredths of a percent is above 100.00 %")]
pub struct RateError {
    /// The value given.
    pub hundredths: u32,
}

impl Rate {
    /// 100.00 %.
    pub const FULL: Rate = Rate(10_000);

    /// A rate in hundredths of a percent (7575 = 75.75 %).
    pub fn from_hundredths(hundredths: u32) -> Result<Rate, RateError> {
        u16::try_from(hundredths)
            .ok()
            .filter(|&h| h <= Rate::FULL.0)
            .map(Rate)
            .ok_or(RateError { hundredths })
    }

    /// `part` of `whole`, rounded to hundredths of a percent; 0 % when `whole` is 0.
    pub fn ratio(part: u64, whole: u64) -> Rate {
        if whole == 0 {
            return Rate(0);
        }
        let hundredths =
            (u128::from(part.min(whole)) * 10_000 + u128::from(whole) / 2) / u128::from(whole);
        Rate(u16::try_from(hundredths).unwrap_or(Rate::FULL.0))
    }

    /// Hundredths of a percent.
    pub fn hundredths(self) -> u16 {
        self.0
    }

    /// The percentage.
    pub fn percent(self) -> f64 {
        f64::from(self.0) / 100.0
    }

    /// Reads `075.75` (1 to 3 integer digits, 2 decimals).
    pub fn parse(text: &[u8]) -> Option<Rate> {
        let (whole, fraction) = text.split_at_checked(text.len().checked_sub(3)?)?;
        let [b'.', d0, d1] = *fraction else {
            return None;
        };
        if whole.is_empty() || whole.len() > 3 || !d0.is_ascii_digit() || !d1.is_ascii_digit() {
            return None;
        }
        let whole = wire::ascii::parse_unsigned(whole)?;
        Rate::from_hundredths(whole * 100 + u32::from(d0 - b'0') * 10 + u32::from(d1 - b'0')).ok()
    }
}

impl fmt::Display for Rate {
    /// `075.75`, as on the wire.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:03}.{:02}", self.0 / 100, self.0 % 100)
    }
}

impl Serialize for Rate {
    /// As a percentage number (75.75).
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_f64(self.percent())
    }
}

/// The value of one `KEY=VALUE` line.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize)]
#[serde(untagged)]
pub enum Value {
    /// Digits only: a counter (written with 7 digits).
    Count(u32),
    /// `ddd.dd` under a key ending in `_RATE`: a percentage.
    Rate(Rate),
    /// Anything else, as it came.
    Text(String),
}

impl Value {
    /// Types a value by its key and look.
    pub fn parse(key: &str, text: &[u8]) -> Value {
        if key.ends_with("_RATE")
            && let Some(rate) = Rate::parse(text)
        {
            return Value::Rate(rate);
        }
        match wire::ascii::parse_unsigned(text) {
            Some(count) => Value::Count(count),
            None => Value::Text(String::from_utf8_lossy(text).into_owned()),
        }
    }
}

impl fmt::Display for Value {
    /// As on the wire: `0000005`, `075.75`, text.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Value::Count(count) => write!(f, "{count:0width$}", width = COUNT_WIDTH),
            Value::Rate(rate) => rate.fmt(f),
            Value::Text(text) => f.write_str(text),
        }
    }
}

/// One `KEY=VALUE` line.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize)]
pub struct Field {
    /// The key, e.g. `PICKUP`.
    pub key: String,
    /// The value.
    pub value: Value,
}

/// A `%NAME` section and its lines.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize)]
pub struct Section {
    /// The section mark, `%` included (e.g. `%MANAGEMENT`).
    pub name: String,
    /// Its lines, in order.
    pub fields: Vec<Field>,
}

/// The `%HEADER` section.
#[derive(Debug, Clone, Default, PartialEq, Eq, Hash, Serialize)]
pub struct ProductionHeader {
    /// `NAME=`: which data (the manual shows `M…`; the twin writes the request code,
    /// e.g. `M000P` \[I\]).
    pub name: Option<String>,
    /// `MACHINE=`: `BM`.
    pub machine: Option<String>,
    /// `START=`: when counting started (last clear).
    pub start: Option<Timestamp>,
    /// `END=`: when the data was taken.
    pub end: Option<Timestamp>,
    /// `PANASONIC=`: `3010` in the manual.
    pub format: Option<String>,
    /// Other header lines, in order.
    pub other: Vec<Field>,
}

/// Production management data.
#[derive(Debug, Clone, Default, PartialEq, Eq, Hash, Serialize)]
pub struct ProductionData {
    /// The `%HEADER` section.
    pub header: ProductionHeader,
    /// The other sections (`%MANAGEMENT`, `%CHARACTER`, …), in order.
    pub sections: Vec<Section>,
}

/// Counters the manual names, with their section and key (3.3-9).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[non_exhaustive]
pub enum Counter {
    /// `PRODUCTPLAN1`: boards planned.
    ProductPlan1,
    /// `PRODUCTPLAN2`: second plan figure (\[?\] meaning not in the pages we have).
    ProductPlan2,
    /// `PRODUCT1`: boards produced.
    Product1,
    /// `PRODUCT2`: second production figure (\[?\] meaning not in the pages we have).
    Product2,
    /// `PARTS_EXHAUST_C`: parts-exhaustion stops.
    PartsExhaustCount,
    /// `PARTS_EXHAUST_T`: time stopped for parts exhaustion, in seconds \[I\].
    PartsExhaustTime,
    /// `PICKUP`: pick-up attempts.
    Pickup,
    /// `MOUNT`: parts placed.
    Mount,
    /// `PICKUP_ERR`: pick-up error stops.
    PickupError,
    /// `PICKUP_MISS`: pick-ups that came back without a part.
    PickupMiss,
    /// `RECOG_ERR1`: part recognition errors (first camera).
    RecognitionError1,
    /// `RECOG_ERR2`: part recognition errors (second camera).
    RecognitionError2,
    /// `BRECOG_ERR1`: board mark recognition errors (first kind).
    BoardRecognitionError1,
    /// `BRECOG_ERR2`: board mark recognition errors (second kind).
    BoardRecognitionError2,
}

impl Counter {
    /// Every counter, in the order the twin writes them.
    pub const ALL: [Counter; 14] = [
        Counter::ProductPlan1,
        Counter::ProductPlan2,
        Counter::Product1,
        Counter::Product2,
        Counter::PartsExhaustCount,
        Counter::PartsExhaustTime,
        Counter::Pickup,
        Counter::Mount,
        Counter::PickupError,
        Counter::PickupMiss,
        Counter::RecognitionError1,
        Counter::RecognitionError2,
        Counter::BoardRecognitionError1,
        Counter::BoardRecognitionError2,
    ];

    /// The key on the wire.
    pub const fn key(self) -> &'static str {
        match self {
            Counter::ProductPlan1 => "PRODUCTPLAN1",
            Counter::ProductPlan2 => "PRODUCTPLAN2",
            Counter::Product1 => "PRODUCT1",
            Counter::Product2 => "PRODUCT2",
            Counter::PartsExhaustCount => "PARTS_EXHAUST_C",
            Counter::PartsExhaustTime => "PARTS_EXHAUST_T",
            Counter::Pickup => "PICKUP",
            Counter::Mount => "MOUNT",
            Counter::PickupError => "PICKUP_ERR",
            Counter::PickupMiss => "PICKUP_MISS",
            Counter::RecognitionError1 => "RECOG_ERR1",
            Counter::RecognitionError2 => "RECOG_ERR2",
            Counter::BoardRecognitionError1 => "BRECOG_ERR1",
            Counter::BoardRecognitionError2 => "BRECOG_ERR2",
        }
    }

    /// What it counts, in words.
    pub const fn describe(self) -> &'static str {
        match self {
            Counter::ProductPlan1 => "boards planned",
            Counter::ProductPlan2 => "second plan figure",
            Counter::Product1 => "boards produced",
            Counter::Product2 => "second production figure",
            Counter::PartsExhaustCount => "parts-exhaustion stops",
            Counter::PartsExhaustTime => "time stopped for parts exhaustion (s)",
            Counter::Pickup => "pick-ups",
            Counter::Mount => "parts placed",
            Counter::PickupError => "pick-up error stops",
            Counter::PickupMiss => "pick-up misses",
            Counter::RecognitionError1 => "part recognition errors (1)",
            Counter::RecognitionError2 => "part recognition errors (2)",
            Counter::BoardRecognitionError1 => "board mark recognition errors (1)",
            Counter::BoardRecognitionError2 => "board mark recognition errors (2)",
        }
    }

    /// The counter with this key, if the manual names it.
    pub fn from_key(key: &str) -> Option<Counter> {
        Counter::ALL
            .into_iter()
            .find(|counter| counter.key() == key)
    }

    /// The section the manual puts it in.
    pub const fn section(self) -> &'static str {
        match self {
            Counter::ProductPlan1
            | Counter::ProductPlan2
            | Counter::Product1
            | Counter::Product2 => MANAGEMENT_SECTION,
            _ => CHARACTER_SECTION,
        }
    }
}

/// Rates the manual names (3.3-9).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub enum RateKind {
    /// `PICKUP_RATE`: share of pick-ups that brought a part.
    Pickup,
    /// `MOUNT_RATE`: share of pick-ups that ended placed.
    Mount,
}

impl RateKind {
    /// Both rates.
    pub const ALL: [RateKind; 2] = [RateKind::Pickup, RateKind::Mount];

    /// The key on the wire.
    pub const fn key(self) -> &'static str {
        match self {
            RateKind::Pickup => "PICKUP_RATE",
            RateKind::Mount => "MOUNT_RATE",
        }
    }

    /// What it measures, in words.
    pub const fn describe(self) -> &'static str {
        match self {
            RateKind::Pickup => "pick-up rate",
            RateKind::Mount => "placement rate",
        }
    }

    /// The rate with this key, if the manual names it.
    pub fn from_key(key: &str) -> Option<RateKind> {
        RateKind::ALL.into_iter().find(|rate| rate.key() == key)
    }
}

/// A data block that is not production management data.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ProductionDataError {
    /// The first line is not `%HEADER`.
    #[error("production data must start with %HEADER, not {found:?}")]
    MissingHeader {
        /// The first line.
        found: String,
    },
    /// A line that is neither a section mark, `KEY=VALUE`, nor the end mark.
    #[error("production data line {line} ({text:?}) is not KEY=VALUE")]
    BadLine {
        /// 1-based line number.
        line: usize,
        /// The line of text as the machine sent it.
        text: String,
    },
    /// `START=` or `END=` is not a timestamp.
    #[error("production data {key}: {source}")]
    BadTimestamp {
        /// The key.
        key: String,
        /// What is wrong.
        source: CalendarParseError,
    },
    /// The `*` end mark is missing.
    #[error("production data does not end with the \"*\" line")]
    MissingEnd,
    /// Lines after the end mark.
    #[error("production data has lines after its \"*\" end line")]
    TrailingData,
}

impl ProductionData {
    /// The value under `key` in `section` (`%MANAGEMENT`, …).
    pub fn value(&self, section: &str, key: &str) -> Option<&Value> {
        self.sections
            .iter()
            .filter(|s| s.name == section)
            .flat_map(|s| &s.fields)
            .find(|field| field.key == key)
            .map(|field| &field.value)
    }

    /// A named counter, if present and a number.
    pub fn count(&self, counter: Counter) -> Option<u32> {
        match self.value(counter.section(), counter.key()) {
            Some(Value::Count(count)) => Some(*count),
            _ => None,
        }
    }

    /// A named rate, if present and a rate.
    pub fn rate(&self, rate: RateKind) -> Option<Rate> {
        match self.value(CHARACTER_SECTION, rate.key()) {
            Some(Value::Rate(rate)) => Some(*rate),
            _ => None,
        }
    }

    /// Sets `key` in `section`, adding the section or the line at the end if missing.
    pub fn set(&mut self, section: &str, key: &str, value: Value) {
        let index = match self.sections.iter().position(|s| s.name == section) {
            Some(index) => index,
            None => {
                self.sections.push(Section {
                    name: section.to_owned(),
                    fields: Vec::new(),
                });
                self.sections.len() - 1
            }
        };
        let fields = &mut self.sections[index].fields;
        match fields.iter_mut().find(|field| field.key == key) {
            Some(field) => field.value = value,
            None => fields.push(Field {
                key: key.to_owned(),
                value,
            }),
        }
    }

    /// Sets a named counter (saturating at the 7-digit maximum).
    pub fn set_count(&mut self, counter: Counter, count: u64) {
        let count = u32::try_from(count.min(u64::from(MAX_COUNT))).unwrap_or(MAX_COUNT);
        self.set(counter.section(), counter.key(), Value::Count(count));
    }

    /// Sets a named rate.
    pub fn set_rate(&mut self, kind: RateKind, rate: Rate) {
        self.set(CHARACTER_SECTION, kind.key(), Value::Rate(rate));
    }

    /// Appends the data block: `%HEADER` with NAME, MACHINE, START, END, PANASONIC and
    /// other header lines, the sections, then `*` CRLF.
    pub fn write(&self, out: &mut Vec<u8>) {
        let mut line = |text: &str| {
            out.extend_from_slice(text.as_bytes());
            out.extend_from_slice(CRLF);
        };
        line(HEADER_SECTION);
        let header = &self.header;
        let known = [
            ("NAME", header.name.clone()),
            ("MACHINE", header.machine.clone()),
            ("START", header.start.map(|t| t.to_string())),
            ("END", header.end.map(|t| t.to_string())),
            ("PANASONIC", header.format.clone()),
        ];
        for (key, value) in known {
            if let Some(value) = value {
                line(&format!("{key}={value}"));
            }
        }
        for field in &header.other {
            line(&format!("{}={}", field.key, field.value));
        }
        for section in &self.sections {
            line(&section.name);
            for field in &section.fields {
                line(&format!("{}={}", field.key, field.value));
            }
        }
        out.extend_from_slice(END_MARK);
    }

    /// The data block.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::new();
        self.write(&mut out);
        out
    }

    /// Reads a data block (lines ending in CRLF or LF).
    pub fn parse(data: &[u8]) -> Result<ProductionData, ProductionDataError> {
        let mut all = lines(data).enumerate();
        match all.next() {
            Some((_, line)) if line == HEADER_SECTION.as_bytes() => {}
            Some((_, line)) => {
                return Err(ProductionDataError::MissingHeader {
                    found: String::from_utf8_lossy(line).into_owned(),
                });
            }
            None => {
                return Err(ProductionDataError::MissingHeader {
                    found: String::new(),
                });
            }
        }
        let mut parsed = ProductionData::default();
        let mut current: Option<Section> = None;
        for (index, line) in all.by_ref() {
            if line == b"*" {
                parsed.sections.extend(current.take());
                return match all.next() {
                    None => Ok(parsed),
                    Some(_) => Err(ProductionDataError::TrailingData),
                };
            }
            if line.first() == Some(&b'%') {
                parsed.sections.extend(current.take());
                current = Some(Section {
                    name: String::from_utf8_lossy(line).into_owned(),
                    fields: Vec::new(),
                });
                continue;
            }
            let bad = || ProductionDataError::BadLine {
                line: index + 1,
                text: String::from_utf8_lossy(line).into_owned(),
            };
            let eq = line.iter().position(|&b| b == b'=').ok_or_else(bad)?;
            let (key, value) = (&line[..eq], &line[eq + 1..]);
            if key.is_empty() {
                return Err(bad());
            }
            let key = String::from_utf8_lossy(key).into_owned();
            match current.as_mut() {
                Some(section) => {
                    let value = Value::parse(&key, value);
                    section.fields.push(Field { key, value });
                }
                None => parsed.header.read(key, value)?,
            }
        }
        Err(ProductionDataError::MissingEnd)
    }
}

impl ProductionHeader {
    fn read(&mut self, key: String, value: &[u8]) -> Result<(), ProductionDataError> {
        let text = || String::from_utf8_lossy(value).into_owned();
        let timestamp = |key: &str| {
            Timestamp::parse(value).map_err(|source| ProductionDataError::BadTimestamp {
                key: key.to_owned(),
                source,
            })
        };
        match key.as_str() {
            "NAME" => self.name = Some(text()),
            "MACHINE" => self.machine = Some(text()),
            "START" => self.start = Some(timestamp("START")?),
            "END" => self.end = Some(timestamp("END")?),
            "PANASONIC" => self.format = Some(text()),
            _ => {
                let value = Value::parse(&key, value);
                self.other.push(Field { key, value });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests;
