//! Units and values: what a station's data means, in words.

use std::fmt;

use crate::frame::Data;

use super::*;

/// The unit of a code's number.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Unit {
    /// Degrees Celsius: every temperature on the line.
    Celsius,
    /// Thousandths of the station's theoretical maximum power.
    Permille,
    /// Percent of the maximum air flow (the spec gives no unit for air flow; the JTSE
    /// shows it in percent).
    Percent,
    /// Hours (counters).
    Hours,
    /// Cycles (counters).
    Cycles,
}

impl Unit {
    /// The symbol printed after a number.
    pub fn symbol(self) -> &'static str {
        match self {
            Unit::Celsius => "°C",
            Unit::Permille => "‰",
            Unit::Percent => "%",
            Unit::Hours => "h",
            Unit::Cycles => "cycles",
        }
    }
}

impl fmt::Display for Unit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.symbol())
    }
}

/// The raw value of a data field: a number, or text (the model name).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Value {
    /// A number (`00350` → 350).
    Number(i32),
    /// Text, blanks trimmed (`" JTSE"` → `JTSE`).
    Text(String),
}

impl fmt::Display for Value {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Value::Number(n) => write!(f, "{n}"),
            Value::Text(t) => f.write_str(t),
        }
    }
}

/// What a station's data means for a given code.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reading {
    /// A number with its unit (`350 °C`, `412 ‰`, `3 h`).
    Quantity {
        /// The number.
        value: i32,
        /// Its unit.
        unit: Unit,
    },
    /// The connected tool.
    Tool(Tool),
    /// The port's error.
    ToolError(ToolError),
    /// The station's error.
    StationError(StationError),
    /// Tool, cooling and suction bits.
    PortStatus(PortStatus),
    /// Manual or profile mode.
    WorkMode(WorkMode),
    /// The station model name (`JTSE`).
    Model(String),
}

impl Reading {
    /// The raw value behind the reading.
    pub fn value(&self) -> Value {
        match self {
            Reading::Quantity { value, .. } => Value::Number(*value),
            Reading::Tool(t) => Value::Number(t.number()),
            Reading::ToolError(e) => Value::Number(e.code()),
            Reading::StationError(e) => Value::Number(e.code()),
            Reading::PortStatus(s) => Value::Number(s.to_number()),
            Reading::WorkMode(m) => Value::Number(m.number()),
            Reading::Model(name) => Value::Text(name.clone()),
        }
    }

    /// The unit, for quantities.
    pub fn unit(&self) -> Option<Unit> {
        match self {
            Reading::Quantity { unit, .. } => Some(*unit),
            _ => None,
        }
    }
}

impl fmt::Display for Reading {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Reading::Quantity { value, unit } => write!(f, "{value} {unit}"),
            Reading::Tool(t) => write!(f, "{t}"),
            Reading::ToolError(e) => write!(f, "{e}"),
            Reading::StationError(e) => write!(f, "{e}"),
            Reading::PortStatus(s) => write!(f, "{s}"),
            Reading::WorkMode(m) => write!(f, "{m}"),
            Reading::Model(name) => f.write_str(name),
        }
    }
}

/// Data that does not mean anything for its code.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum InterpretError {
    /// A number was expected.
    #[error("{code} ({what}) should carry a number, but the data is {data:?}", what = code.describe())]
    NotANumber {
        /// The code.
        code: Code,
        /// The data field as received.
        data: String,
    },
    /// A number outside the code's table.
    #[error("{code} ({what}) answered {value}, which is not in the spec's table ({known})", what = code.describe())]
    UnknownValue {
        /// The code.
        code: Code,
        /// The number received.
        value: i32,
        /// The values the table lists.
        known: &'static str,
    },
    /// The code is an action that carries no reading.
    #[error("{code} ({what}) is an action and has no reading", what = code.describe())]
    NoReading {
        /// The code.
        code: Code,
    },
}

/// What `data` means for `code`: a quantity with its unit, a table value in words, or the
/// model name.
pub fn interpret(code: Code, data: &Data) -> Result<Reading, InterpretError> {
    if code == Code::StationModel {
        return Ok(Reading::Model(data.as_text()));
    }
    let number = || {
        data.as_number().ok_or_else(|| InterpretError::NotANumber {
            code,
            data: data.to_string(),
        })
    };
    let unknown = |value, known| InterpretError::UnknownValue { code, value, known };
    if let Some(unit) = code.unit() {
        return Ok(Reading::Quantity {
            value: number()?,
            unit,
        });
    }
    // A value of one of the spec's tables: `known` says which values it has.
    let in_table = |reading: fn(i32) -> Option<Reading>, known| {
        let n = number()?;
        reading(n).ok_or_else(|| unknown(n, known))
    };
    match code {
        Code::ConnectedTool(_) => in_table(|n| Tool::from_number(n).map(Reading::Tool), "0 to 2"),
        Code::PortError(_) => in_table(
            |n| ToolError::from_code(n).map(Reading::ToolError),
            "0 to 10",
        ),
        Code::StationError => in_table(
            |n| StationError::from_code(n).map(Reading::StationError),
            "0 to 6",
        ),
        Code::PortStatus(_) => in_table(
            |n| PortStatus::from_number(n).map(Reading::PortStatus),
            "digits 0/1 for tool (units), cooling (tens), suction (hundreds)",
        ),
        Code::WorkMode(_) => in_table(
            |n| WorkMode::from_number(n).map(Reading::WorkMode),
            "0 or 1",
        ),
        _ => Err(InterpretError::NoReading { code }),
    }
}
