//! Devices, points and values: the vocabulary every protocol driver maps its device onto.
//!
//! A device (`jbc1`) has points (`jbc1.air_temperature`). A point's [`PointSpec`] says
//! what it is (name, unit, kind), which poll group reads it, whether and in which range it
//! may be written, and which values are an alarm. Writes are checked against the spec
//! ([`PointSpec::check_write`]) before anything reaches a line.

use std::borrow::Cow;
use std::fmt;
use std::sync::Arc;

use serde::Serialize;

// A point's value and its quality: the vocabulary the gateway shares with the historian.
pub use kit::value::{Quality, Value};

/// Words that a driver usually knows at compile time (a point's name in words, its unit,
/// its poll group, an enumeration's labels): borrowed from the driver's tables, so a
/// thousand devices of one kind share them instead of each holding a copy; owned when
/// they come from the configuration (a Modbus register list).
pub type Words = Cow<'static, str>;

/// Longest device id or point name accepted.
pub const MAX_ID_LEN: usize = 64;

/// A device's id: 1–64 characters of `a-z`, `0-9`, `_` and `-`, starting with a letter or
/// digit. It appears in URLs, point ids and metric labels, so it is kept plain.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(transparent)]
pub struct DeviceId(String);

/// A point's id: `<device>.<point>`, e.g. `jbc1.air_temperature`. Its text is shared:
/// a clone (a reading, a sample, the history writer's map) costs no copy. It hashes and
/// compares as its text, so a map keyed by ids is looked up with a `&str`.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(transparent)]
pub struct PointId(#[serde(serialize_with = "serialize_shared_str")] Arc<str>);

fn serialize_shared_str<S: serde::Serializer>(text: &Arc<str>, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(text)
}

impl std::borrow::Borrow<str> for PointId {
    fn borrow(&self) -> &str {
        &self.0
    }
}

/// An id that does not follow the rules.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{what} {text:?} is not valid: {rule}")]
pub struct IdError {
    /// What kind of id.
    pub what: &'static str,
    /// The text given.
    pub text: String,
    /// The rule it breaks.
    pub rule: &'static str,
}

const ID_RULE: &str =
    "use 1 to 64 characters a-z, 0-9, _ and -, starting with a letter or digit (e.g. jbc1)";

fn check_name(what: &'static str, text: &str) -> Result<(), IdError> {
    let ok = !text.is_empty()
        && text.len() <= MAX_ID_LEN
        && text
            .bytes()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'_' || b == b'-')
        && text
            .bytes()
            .next()
            .is_some_and(|b| b.is_ascii_lowercase() || b.is_ascii_digit());
    if ok {
        Ok(())
    } else {
        Err(IdError {
            what,
            text: text.to_owned(),
            rule: ID_RULE,
        })
    }
}

impl DeviceId {
    /// A device id, checked.
    pub fn new(text: &str) -> Result<Self, IdError> {
        check_name("device id", text)?;
        Ok(Self(text.to_owned()))
    }

    /// The id as text.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl fmt::Display for DeviceId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl PointId {
    /// The id of point `name` of `device`; `name` follows the device id rules.
    pub fn new(device: &DeviceId, name: &str) -> Result<Self, IdError> {
        check_name("point name", name)?;
        // Plain copies, not the formatting machinery: a device's ids are made at its start
        // (every device of a cell at once).
        let device = device.as_str();
        let mut id = String::with_capacity(device.len() + 1 + name.len());
        id.push_str(device);
        id.push('.');
        id.push_str(name);
        Ok(Self(id.into()))
    }

    /// Parses `device.point`.
    pub fn parse(text: &str) -> Result<Self, IdError> {
        let bad = || IdError {
            what: "point id",
            text: text.to_owned(),
            rule: "write <device>.<point>, e.g. jbc1.air_temperature",
        };
        let (device, name) = text.split_once('.').ok_or_else(bad)?;
        let device = DeviceId::new(device).map_err(|_| bad())?;
        Self::new(&device, name).map_err(|_| bad())
    }

    /// The whole id as text.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// The device part.
    pub fn device(&self) -> &str {
        self.0.split_once('.').map_or("", |(d, _)| d)
    }

    /// The point part, after the device.
    pub fn name(&self) -> &str {
        self.0.split_once('.').map_or("", |(_, p)| p)
    }
}

impl fmt::Display for PointId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// One labelled value of an enumeration (`9` = `No tool`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EnumState {
    /// The number.
    pub value: i64,
    /// Its words.
    pub label: Words,
}

/// What kind of value a point carries.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum PointKind {
    /// A number with a unit; plotted.
    Numeric,
    /// Text.
    Text,
    /// A number from a table, shown by its label.
    Enum {
        /// The table.
        states: Vec<EnumState>,
    },
}

/// The range a writable number must fall into.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct WriteRange {
    /// Lowest value accepted.
    pub min: f64,
    /// Highest value accepted.
    pub max: f64,
    /// Whether only whole numbers are accepted.
    pub integer: bool,
    /// The device's step for numbers it stores in fixed point (0.1 for a tenths item),
    /// if finer than whole numbers matter: values between two steps are refused.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub step: Option<f64>,
}

/// Which values of a point are an alarm.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum AlarmRule {
    /// Any value other than this normal one (error codes: 0 = OK).
    NotEqual(f64),
    /// Values above this.
    Above(f64),
    /// Values below this.
    Below(f64),
    /// Any text other than this normal one (a list of active alarms other than `none`).
    NotText(&'static str),
}

impl AlarmRule {
    /// Whether `value` is in alarm under this rule.
    pub fn is_alarm(&self, value: &Value) -> bool {
        if let (AlarmRule::NotText(normal), Value::Text(text)) = (self, value) {
            return text != normal;
        }
        let Some(n) = value.as_number() else {
            return false;
        };
        match *self {
            AlarmRule::NotText(_) => false,
            AlarmRule::NotEqual(normal) => n != normal,
            AlarmRule::Above(limit) => n > limit,
            AlarmRule::Below(limit) => n < limit,
        }
    }
}

/// How far a good number must move from the last recorded value before it is recorded
/// (stored and published) again; smaller moves only update the live value.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Deadband {
    /// A move of at least this much, in the point's unit.
    Absolute(f64),
    /// A move of at least this share (in percent) of the last recorded value's magnitude.
    Percent(f64),
}

impl Deadband {
    /// Whether a move from `recorded` to `value` is big enough to be recorded. A move from
    /// 0 under a percentage passes: 0's share is 0.
    pub fn passes(self, recorded: f64, value: f64) -> bool {
        let moved = (value - recorded).abs();
        match self {
            Deadband::Absolute(band) => moved >= band,
            Deadband::Percent(percent) => moved >= recorded.abs() * percent / 100.0,
        }
    }
}

/// What a point is, apart from its id: the same for every device of one kind, so a
/// driver builds it once and its devices share it ([`PointSpec::description`]). With a
/// description per point, the specs were a third of the heap at 1,000 stations.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PointDescription {
    /// Words for people: `Air temperature`.
    pub name: Words,
    /// Unit symbol (`°C`, `%`), if any.
    pub unit: Option<Words>,
    /// Number, text or enumeration.
    pub kind: PointKind,
    /// The poll group that reads it.
    pub group: Words,
    /// `Some` when it may be written, with the accepted range for numbers.
    pub writable: Option<WriteRange>,
    /// When its value is an alarm, if ever.
    pub alarm: Option<AlarmRule>,
}

/// What a point is: its id and its (shared) description, whose fields read through the
/// spec (`spec.name`, `spec.kind`).
#[derive(Debug, Clone, PartialEq)]
pub struct PointSpec {
    /// `device.point`.
    pub id: PointId,
    /// Everything else, shared by the devices of one kind.
    pub description: Arc<PointDescription>,
}

impl PointSpec {
    /// The spec of point `id`, described by `description` (an `Arc` to share one).
    pub fn new(id: PointId, description: impl Into<Arc<PointDescription>>) -> Self {
        Self {
            id,
            description: description.into(),
        }
    }
}

impl std::ops::Deref for PointSpec {
    type Target = PointDescription;

    fn deref(&self) -> &PointDescription {
        &self.description
    }
}

impl Serialize for PointSpec {
    /// The id and the description's fields in one object, as before they were split.
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        let d = &*self.description;
        let mut s = serializer.serialize_struct("PointSpec", 7)?;
        s.serialize_field("id", &self.id)?;
        s.serialize_field("name", &d.name)?;
        s.serialize_field("unit", &d.unit)?;
        s.serialize_field("kind", &d.kind)?;
        s.serialize_field("group", &d.group)?;
        s.serialize_field("writable", &d.writable)?;
        s.serialize_field("alarm", &d.alarm)?;
        s.end()
    }
}

/// A value to write that passed its point's [`PointSpec::check_write`]: writable, of the
/// point's type, within its range, an enumeration as its state's number. Only
/// `check_write` makes one, so a driver is never handed a value nobody checked.
#[derive(Debug, Clone, PartialEq)]
pub struct Checked(Value);

impl Checked {
    /// The value as it will be sent.
    pub fn value(&self) -> &Value {
        &self.0
    }

    /// The value as a number (numeric and enumerated points always have one).
    pub fn as_number(&self) -> Option<f64> {
        self.0.as_number()
    }

    /// The number a numeric or enumerated point's driver sends: `check_write` makes a
    /// number of every value for such a point (only a text point's value is text, and no
    /// driver calls this for one).
    pub fn number(&self) -> f64 {
        self.0
            .as_number()
            .expect("check_write gives numbers for numeric and enumerated points")
    }

    /// The value, unwrapped.
    pub fn into_value(self) -> Value {
        self.0
    }
}

/// A value refused before it reached the line.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ValueError {
    /// The point is read-only.
    #[error("{point} ({name}) is read-only")]
    ReadOnly {
        /// The point.
        point: PointId,
        /// Its name.
        name: String,
    },
    /// A number was needed.
    #[error("{point} takes {expected}, not {got:?}")]
    WrongType {
        /// The point.
        point: PointId,
        /// What it takes.
        expected: String,
        /// What was given.
        got: String,
    },
    /// A number outside the range.
    #[error("{value} is out of range for {point} ({name}): {min} to {max}{unit}")]
    OutOfRange {
        /// The point.
        point: PointId,
        /// Its name.
        name: String,
        /// The value given.
        value: f64,
        /// Lowest accepted.
        min: f64,
        /// Highest accepted.
        max: f64,
        /// Unit suffix (` °C`) or empty.
        unit: String,
    },
    /// A fraction where whole numbers are needed.
    #[error("{point} takes whole numbers, not {value}")]
    NotWhole {
        /// The point.
        point: PointId,
        /// The value given.
        value: f64,
    },
    /// A value between the steps the device stores (a tenths item given hundredths).
    #[error("{value} is not a multiple of {step}{unit} for {point} ({name})")]
    NotAStep {
        /// The point.
        point: PointId,
        /// Its name.
        name: String,
        /// The value given.
        value: f64,
        /// The device's step.
        step: f64,
        /// Unit suffix (` °C`) or empty.
        unit: String,
    },
    /// A value not in an enumeration.
    #[error("{value} is not a state of {point}; known: {known}")]
    UnknownState {
        /// The point.
        point: PointId,
        /// The value given.
        value: String,
        /// The states accepted.
        known: String,
    },
    /// A value within the range that the device's representation cannot hold (a number
    /// too close to 0 for a float32 register).
    #[error("{point} ({name}) cannot be set to that: {why}")]
    NotRepresentable {
        /// The point.
        point: PointId,
        /// Its name.
        name: String,
        /// Why, in words, with the value.
        why: String,
    },
}

impl PointSpec {
    /// The label of `value` for enumerations.
    pub fn label(&self, value: &Value) -> Option<&str> {
        let PointKind::Enum { states } = &self.kind else {
            return None;
        };
        let n = value.as_number()?;
        states
            .iter()
            .find(|s| s.value as f64 == n)
            .map(|s| s.label.as_ref())
    }

    /// Whether `value` is an alarm for this point.
    pub fn is_alarm(&self, value: &Value) -> bool {
        self.alarm.is_some_and(|rule| rule.is_alarm(value))
    }

    /// Checks a value to write and returns it as the driver takes it: enumeration labels
    /// become their numbers. Nothing that fails here reaches a line.
    pub fn check_write(&self, value: &Value) -> Result<Checked, ValueError> {
        self.check_value(value).map(Checked)
    }

    fn check_value(&self, value: &Value) -> Result<Value, ValueError> {
        let Some(range) = self.writable else {
            return Err(ValueError::ReadOnly {
                point: self.id.clone(),
                name: self.name.to_string(),
            });
        };
        let number = match (&self.kind, value) {
            (PointKind::Enum { states }, _) => {
                let found = states.iter().find(|s| match value {
                    Value::Number(n) => s.value as f64 == *n,
                    Value::Text(t) => {
                        s.label.eq_ignore_ascii_case(t.trim())
                            || t.trim().parse::<i64>() == Ok(s.value)
                    }
                });
                let allowed = |s: &&EnumState| (range.min..=range.max).contains(&(s.value as f64));
                return match found.filter(allowed) {
                    Some(state) => Ok(Value::Number(state.value as f64)),
                    None => Err(ValueError::UnknownState {
                        point: self.id.clone(),
                        value: value.to_string(),
                        known: states
                            .iter()
                            .filter(allowed)
                            .map(|s| format!("{} ({})", s.value, s.label))
                            .collect::<Vec<_>>()
                            .join(", "),
                    }),
                };
            }
            (PointKind::Text, Value::Text(_)) => return Ok(value.clone()),
            (PointKind::Text, Value::Number(_)) => {
                return Err(ValueError::WrongType {
                    point: self.id.clone(),
                    expected: "text".into(),
                    got: value.to_string(),
                });
            }
            (PointKind::Numeric, Value::Number(n)) => *n,
            (PointKind::Numeric, Value::Text(t)) => {
                t.trim().parse::<f64>().map_err(|_| ValueError::WrongType {
                    point: self.id.clone(),
                    expected: "a number".into(),
                    got: t.clone(),
                })?
            }
        };
        if !number.is_finite() || number < range.min || number > range.max {
            return Err(ValueError::OutOfRange {
                point: self.id.clone(),
                name: self.name.to_string(),
                value: number,
                min: range.min,
                max: range.max,
                unit: self
                    .unit
                    .as_deref()
                    .map(|u| format!(" {u}"))
                    .unwrap_or_default(),
            });
        }
        if range.integer && number.fract() != 0.0 {
            return Err(ValueError::NotWhole {
                point: self.id.clone(),
                value: number,
            });
        }
        if let Some(step) = range.step
            && step > 0.0
        {
            let steps = number / step;
            // Tolerates the binary representation of decimal steps (0.1 × 3 ≠ 0.3).
            if (steps - steps.round()).abs() > 1e-6 {
                return Err(ValueError::NotAStep {
                    point: self.id.clone(),
                    name: self.name.to_string(),
                    value: number,
                    step,
                    unit: self
                        .unit
                        .as_deref()
                        .map(|u| format!(" {u}"))
                        .unwrap_or_default(),
                });
            }
        }
        Ok(Value::Number(number))
    }
}

#[cfg(test)]
mod tests;
