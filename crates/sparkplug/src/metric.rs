//! Typed metrics: data types, values that match their type by construction, the
//! quality of a reading, and the birth description of a metric; with the
//! conversions to and from the protobuf [`Metric`].
//!
//! Quality: a good value carries its value; a stale or bad one is sent with
//! `is_null = true` and an Int32 property `Quality` ([`Quality::code`]: 192 good,
//! 500 stale, 0 bad — the codes Ignition's Sparkplug modules use), never with the last
//! good value.

use std::fmt;
use std::sync::Arc;

use crate::proto::{Metric, PropertySet, PropertyValue, metric, property_value};
use crate::topic::{MAX_NAME_BYTES, misleading_character, quoted_start};

/// The name of the property that carries a reading's quality.
pub const QUALITY: &str = "Quality";
/// Birth property: the engineering unit (String).
pub const ENG_UNIT: &str = "engUnit";
/// Birth property: what the metric is, in words (String).
pub const DOCUMENTATION: &str = "Documentation";
/// Birth property: whether a host may write the metric (Boolean).
pub const WRITABLE: &str = "writable";
/// Birth property: the lowest value a write may set (Double).
pub const WRITE_MIN: &str = "writeMin";
/// Birth property: the highest value a write may set (Double).
pub const WRITE_MAX: &str = "writeMax";

/// Milliseconds since the Unix epoch, UTC: every Sparkplug timestamp.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Timestamp(u64);

impl Timestamp {
    /// A timestamp from milliseconds since the Unix epoch.
    pub const fn from_millis(ms: u64) -> Self {
        Self(ms)
    }

    /// Milliseconds since the Unix epoch.
    pub const fn as_millis(self) -> u64 {
        self.0
    }
}

/// The Sparkplug data types cellbus uses (codes 1–14 of the spec).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DataType {
    /// Signed 8 bits (code 1).
    Int8,
    /// Signed 16 bits (code 2).
    Int16,
    /// Signed 32 bits (code 3).
    Int32,
    /// Signed 64 bits (code 4).
    Int64,
    /// Unsigned 8 bits (code 5).
    UInt8,
    /// Unsigned 16 bits (code 6).
    UInt16,
    /// Unsigned 32 bits (code 7).
    UInt32,
    /// Unsigned 64 bits (code 8).
    UInt64,
    /// 32-bit float (code 9).
    Float,
    /// 64-bit float (code 10).
    Double,
    /// Boolean (code 11).
    Boolean,
    /// UTF-8 string (code 12).
    String,
    /// ms since the Unix epoch (code 13).
    DateTime,
    /// UTF-8 text (code 14).
    Text,
}

impl DataType {
    const ALL: [Self; 14] = [
        Self::Int8,
        Self::Int16,
        Self::Int32,
        Self::Int64,
        Self::UInt8,
        Self::UInt16,
        Self::UInt32,
        Self::UInt64,
        Self::Float,
        Self::Double,
        Self::Boolean,
        Self::String,
        Self::DateTime,
        Self::Text,
    ];

    /// The spec's code for this type.
    pub fn code(self) -> u32 {
        match self {
            Self::Int8 => 1,
            Self::Int16 => 2,
            Self::Int32 => 3,
            Self::Int64 => 4,
            Self::UInt8 => 5,
            Self::UInt16 => 6,
            Self::UInt32 => 7,
            Self::UInt64 => 8,
            Self::Float => 9,
            Self::Double => 10,
            Self::Boolean => 11,
            Self::String => 12,
            Self::DateTime => 13,
            Self::Text => 14,
        }
    }

    /// The type of a spec code, if cellbus supports it.
    pub fn from_code(code: u32) -> Result<Self, ValueError> {
        Self::ALL
            .into_iter()
            .find(|t| t.code() == code)
            .ok_or(ValueError::UnsupportedDataType { code })
    }

    /// The name of the protobuf field that carries values of this type.
    pub fn field(self) -> &'static str {
        match self {
            Self::Int8 | Self::Int16 | Self::Int32 | Self::UInt8 | Self::UInt16 | Self::UInt32 => {
                "int_value"
            }
            Self::Int64 | Self::UInt64 | Self::DateTime => "long_value",
            Self::Float => "float_value",
            Self::Double => "double_value",
            Self::Boolean => "boolean_value",
            Self::String | Self::Text => "string_value",
        }
    }
}

impl fmt::Display for DataType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(self, f)
    }
}

/// A metric value; its variant is its data type, so the two cannot disagree.
#[derive(Debug, Clone, PartialEq)]
pub enum MetricValue {
    /// Int8.
    Int8(i8),
    /// Int16.
    Int16(i16),
    /// Int32.
    Int32(i32),
    /// Int64.
    Int64(i64),
    /// UInt8.
    UInt8(u8),
    /// UInt16.
    UInt16(u16),
    /// UInt32.
    UInt32(u32),
    /// UInt64.
    UInt64(u64),
    /// Float.
    Float(f32),
    /// Double.
    Double(f64),
    /// Boolean.
    Boolean(bool),
    /// String.
    String(String),
    /// DateTime.
    DateTime(Timestamp),
    /// Text.
    Text(String),
}

/// Why a protobuf value is not a [`MetricValue`] of the expected type.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ValueError {
    /// The data type code is not one cellbus supports (1–14).
    #[error("datatype {code} is not one cellbus supports (1-14)")]
    UnsupportedDataType {
        /// The code as received.
        code: u32,
    },
    /// No value field is set and the metric is not null.
    #[error("a {datatype} metric without is_null needs {expected}, none is set")]
    Missing {
        /// The metric's type.
        datatype: DataType,
        /// The field it needs.
        expected: &'static str,
    },
    /// The value is in another field than the type's.
    #[error("a {datatype} metric carries its value in {expected}, not in {found}")]
    WrongField {
        /// The metric's type.
        datatype: DataType,
        /// The field it needs.
        expected: &'static str,
        /// The field that is set.
        found: &'static str,
    },
    /// The number does not fit the type.
    #[error("{field} {value:#x} does not fit a {datatype}")]
    OutOfRange {
        /// The metric's type.
        datatype: DataType,
        /// The field.
        field: &'static str,
        /// The raw bits.
        value: u64,
    },
}

impl MetricValue {
    /// The value's data type.
    pub fn datatype(&self) -> DataType {
        match self {
            Self::Int8(_) => DataType::Int8,
            Self::Int16(_) => DataType::Int16,
            Self::Int32(_) => DataType::Int32,
            Self::Int64(_) => DataType::Int64,
            Self::UInt8(_) => DataType::UInt8,
            Self::UInt16(_) => DataType::UInt16,
            Self::UInt32(_) => DataType::UInt32,
            Self::UInt64(_) => DataType::UInt64,
            Self::Float(_) => DataType::Float,
            Self::Double(_) => DataType::Double,
            Self::Boolean(_) => DataType::Boolean,
            Self::String(_) => DataType::String,
            Self::DateTime(_) => DataType::DateTime,
            Self::Text(_) => DataType::Text,
        }
    }

    /// The value as a number, for range checks (`None` for booleans and text).
    pub fn as_f64(&self) -> Option<f64> {
        // A range check needs an order, not exactness beyond 2^53.
        match *self {
            Self::Int8(v) => Some(v.into()),
            Self::Int16(v) => Some(v.into()),
            Self::Int32(v) => Some(v.into()),
            Self::Int64(v) => Some(v as f64),
            Self::UInt8(v) => Some(v.into()),
            Self::UInt16(v) => Some(v.into()),
            Self::UInt32(v) => Some(v.into()),
            Self::UInt64(v) => Some(v as f64),
            Self::Float(v) => Some(v.into()),
            Self::Double(v) => Some(v),
            Self::Boolean(_) | Self::String(_) | Self::DateTime(_) | Self::Text(_) => None,
        }
    }

    /// The protobuf value field. Signed integers go as their two's complement bits,
    /// sign-extended to the field's width (Int32 -1 → `int_value` 0xFFFF_FFFF).
    pub fn to_proto(&self) -> metric::Value {
        use metric::Value as V;
        match self {
            Self::Int8(v) => V::IntValue(i32::from(*v) as u32),
            Self::Int16(v) => V::IntValue(i32::from(*v) as u32),
            Self::Int32(v) => V::IntValue(*v as u32),
            Self::Int64(v) => V::LongValue(*v as u64),
            Self::UInt8(v) => V::IntValue((*v).into()),
            Self::UInt16(v) => V::IntValue((*v).into()),
            Self::UInt32(v) => V::IntValue(*v),
            Self::UInt64(v) => V::LongValue(*v),
            Self::Float(v) => V::FloatValue(*v),
            Self::Double(v) => V::DoubleValue(*v),
            Self::Boolean(v) => V::BooleanValue(*v),
            Self::String(v) | Self::Text(v) => V::StringValue(v.clone()),
            Self::DateTime(v) => V::LongValue(v.as_millis()),
        }
    }

    /// Reads a protobuf value field as a value of `datatype`. An 8- or 16-bit signed
    /// value must be sign-extended (as [`Self::to_proto`] writes it); anything that
    /// does not fit the type is refused, never cut.
    pub fn from_proto(
        datatype: DataType,
        value: Option<&metric::Value>,
    ) -> Result<Self, ValueError> {
        use metric::Value as V;
        let expected = datatype.field();
        let Some(value) = value else {
            return Err(ValueError::Missing { datatype, expected });
        };
        let out_of_range = |value: u64| ValueError::OutOfRange {
            datatype,
            field: expected,
            value,
        };
        let v = match (datatype, value) {
            (DataType::Int8, &V::IntValue(v)) => {
                Self::Int8(i8::try_from(v as i32).map_err(|_| out_of_range(v.into()))?)
            }
            (DataType::Int16, &V::IntValue(v)) => {
                Self::Int16(i16::try_from(v as i32).map_err(|_| out_of_range(v.into()))?)
            }
            (DataType::Int32, &V::IntValue(v)) => Self::Int32(v as i32),
            (DataType::Int64, &V::LongValue(v)) => Self::Int64(v as i64),
            (DataType::UInt8, &V::IntValue(v)) => {
                Self::UInt8(u8::try_from(v).map_err(|_| out_of_range(v.into()))?)
            }
            (DataType::UInt16, &V::IntValue(v)) => {
                Self::UInt16(u16::try_from(v).map_err(|_| out_of_range(v.into()))?)
            }
            (DataType::UInt32, &V::IntValue(v)) => Self::UInt32(v),
            (DataType::UInt64, &V::LongValue(v)) => Self::UInt64(v),
            (DataType::Float, &V::FloatValue(v)) => Self::Float(v),
            (DataType::Double, &V::DoubleValue(v)) => Self::Double(v),
            (DataType::Boolean, &V::BooleanValue(v)) => Self::Boolean(v),
            (DataType::String, V::StringValue(v)) => Self::String(v.clone()),
            (DataType::Text, V::StringValue(v)) => Self::Text(v.clone()),
            (DataType::DateTime, &V::LongValue(v)) => Self::DateTime(Timestamp::from_millis(v)),
            (datatype, found) => {
                return Err(ValueError::WrongField {
                    datatype,
                    expected,
                    found: field_name(found),
                });
            }
        };
        Ok(v)
    }
}

fn field_name(value: &metric::Value) -> &'static str {
    use metric::Value as V;
    match value {
        V::IntValue(_) => "int_value",
        V::LongValue(_) => "long_value",
        V::FloatValue(_) => "float_value",
        V::DoubleValue(_) => "double_value",
        V::BooleanValue(_) => "boolean_value",
        V::StringValue(_) => "string_value",
        V::BytesValue(_) => "bytes_value",
        V::DatasetValue(_) => "dataset_value",
        V::TemplateValue(_) => "template_value",
        V::ExtensionValue(_) => "extension_value",
    }
}

/// How far a reading can be trusted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Quality {
    /// Read from the device and believed (code 192).
    Good,
    /// The device has not answered for a while; the last value is no longer current
    /// (code 500).
    Stale,
    /// The device answered with something wrong, or a reading failed its checks (code 0).
    Bad,
}

impl Quality {
    /// The Int32 code in the `Quality` property.
    pub fn code(self) -> i32 {
        match self {
            Self::Good => 192,
            Self::Stale => 500,
            Self::Bad => 0,
        }
    }

    /// The quality of a code, if it is one of the three.
    pub fn from_code(code: i32) -> Option<Self> {
        [Self::Good, Self::Stale, Self::Bad]
            .into_iter()
            .find(|q| q.code() == code)
    }

    /// The quality a metric's `Quality` property states, if it has one this crate knows.
    pub fn of(metric: &Metric) -> Option<Self> {
        let properties = metric.properties.as_ref()?;
        let i = properties.keys.iter().position(|k| k == QUALITY)?;
        match properties.values.get(i)?.value {
            Some(property_value::Value::IntValue(bits)) => Self::from_code(bits as i32),
            _ => None,
        }
    }
}

/// A reading: a good value, or no value and why.
#[derive(Debug, Clone, PartialEq)]
pub enum Reading {
    /// A good value.
    Good(MetricValue),
    /// No current value: the device has gone quiet.
    Stale,
    /// No trustworthy value.
    Bad,
}

impl Reading {
    /// The reading's quality.
    pub fn quality(&self) -> Quality {
        match self {
            Self::Good(_) => Quality::Good,
            Self::Stale => Quality::Stale,
            Self::Bad => Quality::Bad,
        }
    }

    /// The value, if good.
    pub fn value(&self) -> Option<&MetricValue> {
        match self {
            Self::Good(v) => Some(v),
            Self::Stale | Self::Bad => None,
        }
    }
}

/// A reading and when it was taken.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// The reading.
    pub reading: Reading,
    /// When it was taken.
    pub timestamp: Timestamp,
}

impl Sample {
    /// A good value taken at `timestamp`.
    pub fn good(value: MetricValue, timestamp: Timestamp) -> Self {
        Self {
            reading: Reading::Good(value),
            timestamp,
        }
    }

    /// A stale reading at `timestamp`.
    pub fn stale(timestamp: Timestamp) -> Self {
        Self {
            reading: Reading::Stale,
            timestamp,
        }
    }

    /// A bad reading at `timestamp`.
    pub fn bad(timestamp: Timestamp) -> Self {
        Self {
            reading: Reading::Bad,
            timestamp,
        }
    }
}

/// A metric name: non-empty, at most [`MAX_NAME_BYTES`] bytes, without control or
/// bidirectional formatting characters (as ids); `/` separates folders
/// (`Node Control/Rebirth`). Shared text: a clone copies no bytes.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct MetricName(Arc<str>);

/// Why a string is not a [`MetricName`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NameError {
    /// The name is empty.
    #[error("a metric name must not be empty")]
    Empty,
    /// The name is longer than [`MAX_NAME_BYTES`].
    #[error("the metric name {start:?}… is {bytes} bytes long; at most {MAX_NAME_BYTES} are taken")]
    TooLong {
        /// Its first characters.
        start: String,
        /// Its length in bytes.
        bytes: usize,
    },
    /// The name contains a control or bidirectional formatting character.
    #[error(
        "the metric name {name:?} contains {character:?}, a control or bidirectional \
         formatting character, which would hide or reorder what is shown"
    )]
    Misleading {
        /// The name as given.
        name: String,
        /// The first such character in it.
        character: char,
    },
}

impl MetricName {
    /// Checks `name` and keeps it.
    pub fn new(name: impl AsRef<str>) -> Result<Self, NameError> {
        Self::check(name.as_ref())?;
        Ok(Self(Arc::from(name.as_ref())))
    }

    /// Checks `name` and keeps this very allocation (a birth's table shares it).
    pub(crate) fn shared(name: &Arc<str>) -> Result<Self, NameError> {
        Self::check(name)?;
        Ok(Self(Arc::clone(name)))
    }

    fn check(name: &str) -> Result<(), NameError> {
        if name.is_empty() {
            return Err(NameError::Empty);
        }
        if name.len() > MAX_NAME_BYTES {
            return Err(NameError::TooLong {
                start: quoted_start(name),
                bytes: name.len(),
            });
        }
        if let Some(character) = misleading_character(name) {
            let name = name.to_owned();
            return Err(NameError::Misleading { name, character });
        }
        Ok(())
    }

    /// The name as text.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

/// Looked up by its text (a hash map keyed by names answers a `&str` without a copy).
impl std::borrow::Borrow<str> for MetricName {
    fn borrow(&self) -> &str {
        &self.0
    }
}

impl fmt::Display for MetricName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// Whether and within what a host may write a metric.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Writable {
    /// Read only: a command to write it is refused.
    No,
    /// Any value of the metric's type.
    Yes,
    /// A number within a range.
    Within(WriteRange),
}

/// An inclusive range for writes: finite ends, `min <= max`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WriteRange {
    min: f64,
    max: f64,
}

/// The ends do not make a range.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("{min}..={max} is not a range of finite numbers with min <= max")]
pub struct BadRange {
    /// The lower end as given.
    pub min: f64,
    /// The upper end as given.
    pub max: f64,
}

impl WriteRange {
    /// `min..=max`, if both are finite and in order.
    pub fn new(min: f64, max: f64) -> Result<Self, BadRange> {
        if min.is_finite() && max.is_finite() && min <= max {
            Ok(Self { min, max })
        } else {
            Err(BadRange { min, max })
        }
    }

    /// The lowest value.
    pub fn min(&self) -> f64 {
        self.min
    }

    /// The highest value.
    pub fn max(&self) -> f64 {
        self.max
    }

    /// Whether `value` is within.
    pub fn contains(&self, value: f64) -> bool {
        (self.min..=self.max).contains(&value)
    }
}

/// What a birth says about a metric besides its value.
#[derive(Debug, Clone, PartialEq)]
pub struct MetricSpec {
    /// The name.
    pub name: MetricName,
    /// The type every value has.
    pub datatype: DataType,
    /// The engineering unit (`°C`, `V`), if any.
    pub unit: Option<String>,
    /// What the metric is, in words.
    pub description: Option<String>,
    /// Whether hosts may write it.
    pub writable: Writable,
}

impl MetricSpec {
    /// A read-only metric without unit or description.
    pub fn new(name: MetricName, datatype: DataType) -> Self {
        Self {
            name,
            datatype,
            unit: None,
            description: None,
            writable: Writable::No,
        }
    }

    /// With a unit.
    #[must_use]
    pub fn unit(mut self, unit: impl Into<String>) -> Self {
        self.unit = Some(unit.into());
        self
    }

    /// With a description.
    #[must_use]
    pub fn description(mut self, description: impl Into<String>) -> Self {
        self.description = Some(description.into());
        self
    }

    /// Writable as stated.
    #[must_use]
    pub fn writable(mut self, writable: Writable) -> Self {
        self.writable = writable;
        self
    }

    /// The birth's properties: unit, documentation, writability and range.
    fn birth_properties(&self) -> Properties {
        let mut p = Properties::default();
        if let Some(unit) = &self.unit {
            p.push(ENG_UNIT, string_property(unit));
        }
        if let Some(description) = &self.description {
            p.push(DOCUMENTATION, string_property(description));
        }
        let writable = !matches!(self.writable, Writable::No);
        p.push(WRITABLE, bool_property(writable));
        if let Writable::Within(range) = self.writable {
            p.push(WRITE_MIN, double_property(range.min));
            p.push(WRITE_MAX, double_property(range.max));
        }
        p
    }
}

/// A property set under construction.
#[derive(Default)]
pub(crate) struct Properties(PropertySet);

impl Properties {
    pub(crate) fn push(&mut self, key: &str, value: PropertyValue) {
        self.0.keys.push(key.to_owned());
        self.0.values.push(value);
    }

    pub(crate) fn quality(quality: Quality) -> Self {
        let mut p = Self::default();
        p.push(
            QUALITY,
            PropertyValue {
                r#type: Some(DataType::Int32.code()),
                is_null: None,
                value: Some(property_value::Value::IntValue(quality.code() as u32)),
            },
        );
        p
    }

    pub(crate) fn into_option(self) -> Option<PropertySet> {
        (!self.0.keys.is_empty()).then_some(self.0)
    }
}

/// Typed reads of a received metric's properties: `None` when the property is absent,
/// null, or of another kind.
pub(crate) mod read {
    use crate::proto::{PropertySet, property_value::Value};

    fn property<'s>(set: Option<&'s PropertySet>, key: &str) -> Option<&'s Value> {
        let set = set?;
        let i = set.keys.iter().position(|k| k == key)?;
        let value = set.values.get(i)?;
        if value.is_null == Some(true) {
            return None;
        }
        value.value.as_ref()
    }

    /// A String or Text property.
    pub(crate) fn string(set: Option<&PropertySet>, key: &str) -> Option<String> {
        match property(set, key)? {
            Value::StringValue(s) => Some(s.clone()),
            _ => None,
        }
    }

    /// A Boolean property.
    pub(crate) fn boolean(set: Option<&PropertySet>, key: &str) -> Option<bool> {
        match *property(set, key)? {
            Value::BooleanValue(b) => Some(b),
            _ => None,
        }
    }

    /// A Double or Float property.
    pub(crate) fn number(set: Option<&PropertySet>, key: &str) -> Option<f64> {
        match *property(set, key)? {
            Value::DoubleValue(d) => Some(d),
            Value::FloatValue(f) => Some(f.into()),
            _ => None,
        }
    }

    /// A number property as a whole number, read by its declared type: Int8–32 carried
    /// in 32 bits are signed (`0xFFFFFFFB` is −5), Int64 is signed, unsigned types are
    /// not, and a Double or Float is rounded. `None` for text, booleans and NaN.
    pub(crate) fn integer(set: Option<&PropertySet>, key: &str) -> Option<i64> {
        use crate::metric::DataType;
        let set = set?;
        let i = set.keys.iter().position(|k| k == key)?;
        let declared = set
            .values
            .get(i)?
            .r#type
            .and_then(|code| DataType::from_code(code).ok());
        let signed = matches!(
            declared,
            Some(DataType::Int8 | DataType::Int16 | DataType::Int32 | DataType::Int64)
        );
        match *property(Some(set), key)? {
            Value::IntValue(n) if signed => Some(i64::from(i32::from_ne_bytes(n.to_ne_bytes()))),
            Value::IntValue(n) => Some(i64::from(n)),
            Value::LongValue(n) if signed => Some(i64::from_ne_bytes(n.to_ne_bytes())),
            Value::LongValue(n) => Some(i64::try_from(n).unwrap_or(i64::MAX)),
            // Saturating: a huge double is the largest integer, NaN is no number.
            Value::DoubleValue(d) if !d.is_nan() => Some(d.round() as i64),
            Value::FloatValue(f) if !f.is_nan() => Some(f64::from(f).round() as i64),
            _ => None,
        }
    }
}

pub(crate) fn string_property(s: &str) -> PropertyValue {
    PropertyValue {
        r#type: Some(DataType::String.code()),
        is_null: None,
        value: Some(property_value::Value::StringValue(s.to_owned())),
    }
}

pub(crate) fn uint32_property(n: u32) -> PropertyValue {
    PropertyValue {
        r#type: Some(DataType::UInt32.code()),
        is_null: None,
        value: Some(property_value::Value::IntValue(n)),
    }
}

fn bool_property(b: bool) -> PropertyValue {
    PropertyValue {
        r#type: Some(DataType::Boolean.code()),
        is_null: None,
        value: Some(property_value::Value::BooleanValue(b)),
    }
}

fn double_property(d: f64) -> PropertyValue {
    PropertyValue {
        r#type: Some(DataType::Double.code()),
        is_null: None,
        value: Some(property_value::Value::DoubleValue(d)),
    }
}

/// A birth's metric: name, alias, type, properties (with `Quality` when the reading is
/// not good) and value (or `is_null`).
pub fn birth_metric(spec: &MetricSpec, alias: Option<u64>, sample: &Sample) -> Metric {
    let mut properties = spec.birth_properties();
    if sample.reading.quality() != Quality::Good {
        let Properties(q) = Properties::quality(sample.reading.quality());
        properties.0.keys.extend(q.keys);
        properties.0.values.extend(q.values);
    }
    Metric {
        name: Some(spec.name.as_str().to_owned()),
        alias,
        datatype: Some(spec.datatype.code()),
        properties: properties.into_option(),
        ..value_fields(sample)
    }
}

/// A data message's metric, by alias only: timestamp, value or `is_null`, the
/// `Quality` property when `with_quality` (always for a reading that is not good),
/// and `is_historical` for stored data.
pub fn data_metric(alias: u64, sample: &Sample, with_quality: bool, historical: bool) -> Metric {
    let quality = sample.reading.quality();
    let properties = (with_quality || quality != Quality::Good)
        .then(|| Properties::quality(quality).into_option())
        .flatten();
    Metric {
        alias: Some(alias),
        properties,
        is_historical: historical.then_some(true),
        ..value_fields(sample)
    }
}

fn value_fields(sample: &Sample) -> Metric {
    let value = sample.reading.value().map(MetricValue::to_proto);
    Metric {
        timestamp: Some(sample.timestamp.as_millis()),
        is_null: value.is_none().then_some(true),
        value,
        ..Metric::default()
    }
}
