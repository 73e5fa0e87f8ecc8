//! The JTSE's commands and the meaning of their data, from both editions of the protocol.
//!
//! A [`Code`] is one control code (`ST1`, `A11`, `SMN`…) with its spec meaning: whether it
//! can be read or written, its unit, its words. [`interpret`] turns the data a station
//! answers into a [`Reading`] with words (`350 °C`, `No tool (9)`, `tool on, cooling off,
//! suction off`). The spec's tables are enums here: [`Tool`], [`ToolError`],
//! [`StationError`], [`NakReason`], [`PortStatus`], [`WorkMode`].
//!
//! Only port 1 exists on a JTSE: a code naming another port does not parse (the CLI refuses
//! it before the wire), while a station receiving one answers NAK 4.

use std::fmt;
use std::str::FromStr;

use crate::frame::{Data, RawCode};

// ---------------------------------------------------------------------------------------
// Ports and tools

/// A tool port of the station. A JTSE has one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Port {
    /// Port 1, the only port of a JTSE.
    One,
}

impl Port {
    /// The port's number (1).
    pub fn number(self) -> u8 {
        match self {
            Port::One => 1,
        }
    }

    /// The ASCII digit that stands for the port in a code (`1` in `ST1`).
    pub fn digit(self) -> u8 {
        b'0' + self.number()
    }

    /// The port for a code's digit, if the station has it.
    pub fn from_digit(digit: u8) -> Option<Port> {
        match digit {
            b'1' => Some(Port::One),
            _ => None,
        }
    }
}

impl fmt::Display for Port {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "port {}", self.number())
    }
}

/// The tool connected to a port (spec table "Tools").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Tool {
    /// `00000`: no tool connected.
    None,
    /// `00001`: a JT hot-air tool.
    Jt,
    /// `00002`: a TE hot-air tool.
    Te,
}

impl Tool {
    /// Every tool value, in table order.
    pub const ALL: [Tool; 3] = [Tool::None, Tool::Jt, Tool::Te];

    /// The tool's number on the wire (0, 1, 2); also its digit in `A1y`.
    pub fn number(self) -> i32 {
        match self {
            Tool::None => 0,
            Tool::Jt => 1,
            Tool::Te => 2,
        }
    }

    /// The tool for a number from the wire.
    pub fn from_number(number: i32) -> Option<Tool> {
        Tool::ALL.into_iter().find(|t| t.number() == number)
    }

    /// The spec's words for the value.
    pub fn words(self) -> &'static str {
        match self {
            Tool::None => "No tool",
            Tool::Jt => "JT",
            Tool::Te => "TE",
        }
    }

    fn digit(self) -> u8 {
        match self {
            Tool::None => b'0',
            Tool::Jt => b'1',
            Tool::Te => b'2',
        }
    }
}

impl fmt::Display for Tool {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.words())
    }
}

// ---------------------------------------------------------------------------------------
// Codes

/// One control code of the JTSE, typed. The header (`R`/`W`/`A`/`N`) is not part of it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Code {
    /// `STx`: selected air temperature (°C), read/write.
    SelectAirTemp(Port),
    /// `SFx`: selected air flow (%), read/write.
    SelectAirFlow(Port),
    /// `SEx`: selected external temperature (°C), read/write.
    SelectExternalTemp(Port),
    /// `ATx`: air temperature at the tool's thermocouple (°C), read only.
    AirTemp(Port),
    /// `ETx`: temperature at the external thermocouple (°C), read only.
    ExternalTemp(Port),
    /// `WMx`: work mode ([`WorkMode`]), read/write.
    WorkMode(Port),
    /// `PPx`: power supplied to the tool (‰ of the station's maximum), read only.
    PortPower(Port),
    /// `PEx`: port error ([`ToolError`]), read only.
    PortError(Port),
    /// `PSx`: port status ([`PortStatus`]), read/write (only `00000`/`00001` may be written).
    PortStatus(Port),
    /// `CTx`: connected tool ([`Tool`]), read only.
    ConnectedTool(Port),
    /// `Axy`: adjust temperature of tool `y` on port `x` (°C), read/write. Codes exist for
    /// JT (`A11`) and TE (`A12`); `Tool::None` makes a code the station does not accept.
    AdjustTemp(Port, Tool),
    /// `SMN`: station model name (text, `" JTSE"`), read only.
    StationModel,
    /// `MAT`: maximum air temperature (°C), read/write.
    MaxAirTemp,
    /// `MIT`: minimum air temperature (°C), read/write.
    MinAirTemp,
    /// `MAF`: maximum air flow (%), read/write.
    MaxAirFlow,
    /// `MIF`: minimum air flow (%), read/write.
    MinAirFlow,
    /// `MAE`: maximum external temperature (°C), read/write.
    MaxExternalTemp,
    /// `MIE`: minimum external temperature (°C), read/write.
    MinExternalTemp,
    /// `SER`: station error ([`StationError`]), read only.
    StationError,
    /// `RSP`: reset station parameters to factory values, write only (an action).
    ResetParameters,
    /// `RST`: reset station settings (later edition), write only (an action).
    ResetSettings,
    /// `OHx`: plugged (on) hours counter, read only.
    PluggedHours(Port),
    /// `WHx`: work hours counter, read only.
    WorkHours(Port),
    /// `TCx`: tool cycles counter, read only.
    ToolCycles(Port),
    /// `SCx`: suction cycles counter, read only.
    SuctionCycles(Port),
}

/// Text that is not a control code of the JTSE.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CodeError {
    /// A known command for a port the station does not have (`ST3`).
    #[error("{text:?} names port {port}, but a JTSE has only port 1 (write {suggestion})")]
    NoSuchPort {
        /// The text given.
        text: String,
        /// The port character in it.
        port: char,
        /// The same command for port 1.
        suggestion: String,
    },
    /// An adjust-temperature code for a tool that has none (`A10`, `A13`).
    #[error(
        "{text:?} names tool {tool}; adjust temperatures exist for tool 1 (JT, A11) and tool 2 (TE, A12)"
    )]
    NoSuchTool {
        /// The text given.
        text: String,
        /// The tool character in it.
        tool: char,
    },
    /// Not a code at all.
    #[error("{text:?} is not a JTSE control code; known codes: {known}", known = known_codes())]
    Unknown {
        /// The text given.
        text: String,
    },
}

/// Whether a code carries a value for the robot to read or to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Access {
    ReadWrite,
    ReadOnly,
    WriteOnly,
}

/// Makes a port-carrying code.
type PortCode = fn(Port) -> Code;

/// Two-letter commands followed by a port digit.
const PORT_CODES: [([u8; 2], PortCode); 14] = [
    (*b"ST", Code::SelectAirTemp),
    (*b"SF", Code::SelectAirFlow),
    (*b"SE", Code::SelectExternalTemp),
    (*b"AT", Code::AirTemp),
    (*b"ET", Code::ExternalTemp),
    (*b"WM", Code::WorkMode),
    (*b"PP", Code::PortPower),
    (*b"PE", Code::PortError),
    (*b"PS", Code::PortStatus),
    (*b"CT", Code::ConnectedTool),
    (*b"OH", Code::PluggedHours),
    (*b"WH", Code::WorkHours),
    (*b"TC", Code::ToolCycles),
    (*b"SC", Code::SuctionCycles),
];

/// Three-letter station commands.
const STATION_CODES: [([u8; 3], Code); 10] = [
    (*b"SMN", Code::StationModel),
    (*b"MAT", Code::MaxAirTemp),
    (*b"MIT", Code::MinAirTemp),
    (*b"MAF", Code::MaxAirFlow),
    (*b"MIF", Code::MinAirFlow),
    (*b"MAE", Code::MaxExternalTemp),
    (*b"MIE", Code::MinExternalTemp),
    (*b"SER", Code::StationError),
    (*b"RSP", Code::ResetParameters),
    (*b"RST", Code::ResetSettings),
];

/// The letter that starts an adjust-temperature code (`A11`).
const ADJUST_LETTER: u8 = b'A';

impl Code {
    /// Every code of a JTSE (port 1; adjust temperature for JT and TE), in spec order.
    pub fn all() -> Vec<Code> {
        let port = Port::One;
        vec![
            Code::SelectAirTemp(port),
            Code::SelectAirFlow(port),
            Code::SelectExternalTemp(port),
            Code::AirTemp(port),
            Code::ExternalTemp(port),
            Code::WorkMode(port),
            Code::PortPower(port),
            Code::PortError(port),
            Code::PortStatus(port),
            Code::ConnectedTool(port),
            Code::AdjustTemp(port, Tool::Jt),
            Code::AdjustTemp(port, Tool::Te),
            Code::StationModel,
            Code::MaxAirTemp,
            Code::MinAirTemp,
            Code::MaxAirFlow,
            Code::MinAirFlow,
            Code::MaxExternalTemp,
            Code::MinExternalTemp,
            Code::StationError,
            Code::ResetSettings,
            Code::ResetParameters,
            Code::PluggedHours(port),
            Code::WorkHours(port),
            Code::ToolCycles(port),
            Code::SuctionCycles(port),
        ]
    }

    /// The three characters on the wire.
    pub fn raw(self) -> RawCode {
        let bytes = match self {
            Code::AdjustTemp(port, tool) => [ADJUST_LETTER, port.digit(), tool.digit()],
            _ => match self.port() {
                Some(port) => {
                    let [a, b] = PORT_CODES
                        .iter()
                        .find(|(_, make)| make(port) == self)
                        .map(|(letters, _)| *letters)
                        .expect("every port-carrying code other than AdjustTemp is in PORT_CODES");
                    [a, b, port.digit()]
                }
                None => STATION_CODES
                    .iter()
                    .find(|(_, code)| *code == self)
                    .map(|(letters, _)| *letters)
                    .expect("every code without a port is in STATION_CODES"),
            },
        };
        RawCode::new(bytes).expect("code tables hold printable ASCII only")
    }

    /// The typed code for three wire characters, if the station accepts them (exact case,
    /// port 1 only, adjust temperature for JT or TE only).
    pub fn from_raw(raw: RawCode) -> Option<Code> {
        parse_code(raw.as_bytes()).ok()
    }

    /// The port the code is about, if it names one.
    pub fn port(self) -> Option<Port> {
        match self {
            Code::SelectAirTemp(p)
            | Code::SelectAirFlow(p)
            | Code::SelectExternalTemp(p)
            | Code::AirTemp(p)
            | Code::ExternalTemp(p)
            | Code::WorkMode(p)
            | Code::PortPower(p)
            | Code::PortError(p)
            | Code::PortStatus(p)
            | Code::ConnectedTool(p)
            | Code::AdjustTemp(p, _)
            | Code::PluggedHours(p)
            | Code::WorkHours(p)
            | Code::ToolCycles(p)
            | Code::SuctionCycles(p) => Some(p),
            Code::StationModel
            | Code::MaxAirTemp
            | Code::MinAirTemp
            | Code::MaxAirFlow
            | Code::MinAirFlow
            | Code::MaxExternalTemp
            | Code::MinExternalTemp
            | Code::StationError
            | Code::ResetParameters
            | Code::ResetSettings => None,
        }
    }

    /// Whether the robot may read it (`R` + code).
    pub fn readable(self) -> bool {
        self.access() != Access::WriteOnly
    }

    /// Whether the robot may write it (`W` + code).
    pub fn writable(self) -> bool {
        self.access() != Access::ReadOnly
    }

    fn access(self) -> Access {
        match self {
            Code::SelectAirTemp(_)
            | Code::SelectAirFlow(_)
            | Code::SelectExternalTemp(_)
            | Code::WorkMode(_)
            | Code::PortStatus(_)
            | Code::AdjustTemp(..)
            | Code::MaxAirTemp
            | Code::MinAirTemp
            | Code::MaxAirFlow
            | Code::MinAirFlow
            | Code::MaxExternalTemp
            | Code::MinExternalTemp => Access::ReadWrite,
            Code::AirTemp(_)
            | Code::ExternalTemp(_)
            | Code::PortPower(_)
            | Code::PortError(_)
            | Code::ConnectedTool(_)
            | Code::StationModel
            | Code::StationError
            | Code::PluggedHours(_)
            | Code::WorkHours(_)
            | Code::ToolCycles(_)
            | Code::SuctionCycles(_) => Access::ReadOnly,
            Code::ResetParameters | Code::ResetSettings => Access::WriteOnly,
        }
    }

    /// What the code is, in the spec's words.
    pub fn describe(self) -> &'static str {
        match self {
            Code::SelectAirTemp(_) => "selected air temperature",
            Code::SelectAirFlow(_) => "selected air flow",
            Code::SelectExternalTemp(_) => "selected external temperature",
            Code::AirTemp(_) => "air temperature (tool thermocouple)",
            Code::ExternalTemp(_) => "external temperature (external thermocouple)",
            Code::WorkMode(_) => "work mode",
            Code::PortPower(_) => "port power",
            Code::PortError(_) => "port error",
            Code::PortStatus(_) => "port status",
            Code::ConnectedTool(_) => "connected tool",
            Code::AdjustTemp(_, Tool::Jt) => "adjust temperature of the JT tool",
            Code::AdjustTemp(_, Tool::Te) => "adjust temperature of the TE tool",
            Code::AdjustTemp(_, Tool::None) => "adjust temperature (no tool: not accepted)",
            Code::StationModel => "station model name",
            Code::MaxAirTemp => "maximum air temperature",
            Code::MinAirTemp => "minimum air temperature",
            Code::MaxAirFlow => "maximum air flow",
            Code::MinAirFlow => "minimum air flow",
            Code::MaxExternalTemp => "maximum external temperature",
            Code::MinExternalTemp => "minimum external temperature",
            Code::StationError => "station error",
            Code::ResetParameters => "reset station parameters (factory default)",
            Code::ResetSettings => "reset station settings",
            Code::PluggedHours(_) => "counter plugged hours",
            Code::WorkHours(_) => "counter work hours",
            Code::ToolCycles(_) => "counter tool cycles",
            Code::SuctionCycles(_) => "counter suction cycles",
        }
    }

    /// The unit of the code's number; `None` for enumerations (work mode, tool, errors,
    /// port status), text (model name) and actions (resets).
    pub fn unit(self) -> Option<Unit> {
        match self {
            Code::SelectAirTemp(_)
            | Code::SelectExternalTemp(_)
            | Code::AirTemp(_)
            | Code::ExternalTemp(_)
            | Code::AdjustTemp(..)
            | Code::MaxAirTemp
            | Code::MinAirTemp
            | Code::MaxExternalTemp
            | Code::MinExternalTemp => Some(Unit::Celsius),
            Code::SelectAirFlow(_) | Code::MaxAirFlow | Code::MinAirFlow => Some(Unit::Percent),
            Code::PortPower(_) => Some(Unit::Permille),
            Code::PluggedHours(_) | Code::WorkHours(_) => Some(Unit::Hours),
            Code::ToolCycles(_) | Code::SuctionCycles(_) => Some(Unit::Cycles),
            Code::WorkMode(_)
            | Code::PortError(_)
            | Code::PortStatus(_)
            | Code::ConnectedTool(_)
            | Code::StationModel
            | Code::StationError
            | Code::ResetParameters
            | Code::ResetSettings => None,
        }
    }
}

impl FromStr for Code {
    type Err = CodeError;

    /// Accepts the three characters of a code in any case: `ST1`, `a11`, `SMN`.
    fn from_str(text: &str) -> Result<Code, CodeError> {
        let upper = text.trim().to_ascii_uppercase();
        let bytes: [u8; 3] = upper
            .as_bytes()
            .try_into()
            .map_err(|_| CodeError::Unknown {
                text: text.to_owned(),
            })?;
        parse_code(&bytes).map_err(|fault| match fault {
            CodeFault::Unknown => CodeError::Unknown {
                text: text.to_owned(),
            },
            CodeFault::Port(port) => CodeError::NoSuchPort {
                text: text.to_owned(),
                port: char::from(port),
                suggestion: format!(
                    "{}{}",
                    String::from_utf8_lossy(&bytes[..2]),
                    char::from(Port::One.digit())
                ),
            },
            CodeFault::Tool(tool) => CodeError::NoSuchTool {
                text: text.to_owned(),
                tool: char::from(tool),
            },
        })
    }
}

impl fmt::Display for Code {
    /// The three wire characters (`ST1`).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.raw())
    }
}

/// Why three bytes are not a code the station accepts.
enum CodeFault {
    Unknown,
    Port(u8),
    Tool(u8),
}

fn parse_code(bytes: &[u8; 3]) -> Result<Code, CodeFault> {
    if let Some((_, code)) = STATION_CODES.iter().find(|(letters, _)| letters == bytes) {
        return Ok(*code);
    }
    let [a, b, c] = *bytes;
    if a == ADJUST_LETTER && b.is_ascii_digit() {
        let port = Port::from_digit(b).ok_or(CodeFault::Port(b))?;
        let tool = match c {
            b'1' => Tool::Jt,
            b'2' => Tool::Te,
            _ if c.is_ascii_digit() => return Err(CodeFault::Tool(c)),
            _ => return Err(CodeFault::Unknown),
        };
        return Ok(Code::AdjustTemp(port, tool));
    }
    let make = PORT_CODES
        .iter()
        .find(|(letters, _)| *letters == [a, b])
        .map(|(_, make)| *make)
        .ok_or(CodeFault::Unknown)?;
    if !c.is_ascii_digit() {
        return Err(CodeFault::Unknown);
    }
    let port = Port::from_digit(c).ok_or(CodeFault::Port(c))?;
    Ok(make(port))
}

fn known_codes() -> String {
    Code::all()
        .iter()
        .map(Code::to_string)
        .collect::<Vec<_>>()
        .join(", ")
}

// ---------------------------------------------------------------------------------------
// Units and values

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
    match code {
        Code::ConnectedTool(_) => {
            let n = number()?;
            Tool::from_number(n)
                .map(Reading::Tool)
                .ok_or_else(|| unknown(n, "0 to 2"))
        }
        Code::PortError(_) => {
            let n = number()?;
            ToolError::from_code(n)
                .map(Reading::ToolError)
                .ok_or_else(|| unknown(n, "0 to 10"))
        }
        Code::StationError => {
            let n = number()?;
            StationError::from_code(n)
                .map(Reading::StationError)
                .ok_or_else(|| unknown(n, "0 to 6"))
        }
        Code::PortStatus(_) => {
            let n = number()?;
            PortStatus::from_number(n)
                .map(Reading::PortStatus)
                .ok_or_else(|| {
                    unknown(
                        n,
                        "digits 0/1 for tool (units), cooling (tens), suction (hundreds)",
                    )
                })
        }
        Code::WorkMode(_) => {
            let n = number()?;
            WorkMode::from_number(n)
                .map(Reading::WorkMode)
                .ok_or_else(|| unknown(n, "0 or 1"))
        }
        _ => Err(InterpretError::NoReading { code }),
    }
}

// ---------------------------------------------------------------------------------------
// Tables

/// Declares a spec table as an enum with numbers and words.
macro_rules! spec_table {
    (
        $(#[$meta:meta])*
        $name:ident { $( $(#[$vmeta:meta])* $variant:ident = $number:literal, $words:literal; )+ }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum $name {
            $( $(#[$vmeta])* $variant, )+
        }

        impl $name {
            /// Every value, in table order.
            pub const ALL: &'static [$name] = &[ $( $name::$variant, )+ ];

            /// The number on the wire.
            pub fn code(self) -> i32 {
                match self { $( $name::$variant => $number, )+ }
            }

            /// The value for a number from the wire.
            pub fn from_code(number: i32) -> Option<$name> {
                match number { $( $number => Some($name::$variant), )+ _ => None }
            }

            /// The spec's words for the value.
            pub fn words(self) -> &'static str {
                match self { $( $name::$variant => $words, )+ }
            }
        }

        impl fmt::Display for $name {
            /// The words and the number: `No tool (9)`.
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "{} ({})", self.words(), self.code())
            }
        }
    };
}

spec_table! {
    /// A port's error (spec table "Tool errors", read with `PEx`).
    ToolError {
        /// `00000`
        Ok = 0, "OK";
        /// `00001`
        AirPump = 1, "Air pump malfunction";
        /// `00002`
        InsufficientAirFlow = 2, "Insufficient air flow: check for air leaks or obturation in heater";
        /// `00003`
        HeaterMalfunction = 3, "Heater malfunction: replace heater";
        /// `00004`
        ThermocoupleNeeded = 4, "Thermocouple needed";
        /// `00005`
        SetTempNotReached = 5, "Set temperature not reached";
        /// `00006`
        ShortCircuit = 6, "Short-circuit: replace heater";
        /// `00007`
        IncorrectToolResistance = 7, "Incorrect tool resistance";
        /// `00008`
        IncorrectHeater = 8, "Incorrect heater";
        /// `00009`
        NoTool = 9, "No tool";
        /// `00010`
        CheckingTool = 10, "Checking tool";
    }
}

spec_table! {
    /// The station's error (spec table "Station errors", read with `SER`).
    StationError {
        /// `00000`
        Ok = 0, "OK";
        /// `00001` (the spec marks it unused)
        Overload = 1, "Stop by overload (TRAFO)";
        /// `00002` (the spec marks it unused)
        TemperatureSensor = 2, "Temperature sensor";
        /// `00003`
        Memory = 3, "Memory";
        /// `00004`
        MainsFrequency = 4, "Mains frequency";
        /// `00005`
        StationModel = 5, "Station model";
        /// `00006`
        McuToolsNotConnected = 6, "Not connected MCU Tools";
    }
}

/// Why a station refused a frame: the communication-error number a NAK carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum NakReason {
    /// `00001`: the frame failed its BCC check.
    Bcc,
    /// `00002`: the format is wrong (incorrect size).
    Format,
    /// `00003`: the written value is out of limits.
    OutOfRange,
    /// `00004`: control code not accepted.
    ControlCode,
    /// `00005`: the station is not in robot mode.
    NotInRobotMode,
    /// `00006`: station model unknown.
    StationModel,
    /// `99999`: undefined error.
    Undefined,
    /// A number the spec does not list, kept as received.
    Other(i32),
}

impl NakReason {
    /// Number of the BCC error.
    pub const BCC: i32 = 1;
    /// Number of the format error.
    pub const FORMAT: i32 = 2;
    /// Number of the out-of-range error.
    pub const OUT_OF_RANGE: i32 = 3;
    /// Number of the control-code error.
    pub const CONTROL_CODE: i32 = 4;
    /// Number of the control-mode (robot mode) error.
    pub const NOT_IN_ROBOT_MODE: i32 = 5;
    /// Number of the station-model error.
    pub const STATION_MODEL: i32 = 6;
    /// Number of the undefined error.
    pub const UNDEFINED: i32 = 99999;

    /// The number on the wire.
    pub fn code(self) -> i32 {
        match self {
            NakReason::Bcc => Self::BCC,
            NakReason::Format => Self::FORMAT,
            NakReason::OutOfRange => Self::OUT_OF_RANGE,
            NakReason::ControlCode => Self::CONTROL_CODE,
            NakReason::NotInRobotMode => Self::NOT_IN_ROBOT_MODE,
            NakReason::StationModel => Self::STATION_MODEL,
            NakReason::Undefined => Self::UNDEFINED,
            NakReason::Other(n) => n,
        }
    }

    /// The reason for a number from the wire; numbers the spec does not list are kept.
    pub fn from_code(number: i32) -> NakReason {
        match number {
            Self::BCC => NakReason::Bcc,
            Self::FORMAT => NakReason::Format,
            Self::OUT_OF_RANGE => NakReason::OutOfRange,
            Self::CONTROL_CODE => NakReason::ControlCode,
            Self::NOT_IN_ROBOT_MODE => NakReason::NotInRobotMode,
            Self::STATION_MODEL => NakReason::StationModel,
            Self::UNDEFINED => NakReason::Undefined,
            n => NakReason::Other(n),
        }
    }

    /// Whether the frame was damaged on the line (BCC or format error), so sending it
    /// again may succeed. Other refusals repeat whatever the robot does.
    pub fn is_transmission_error(self) -> bool {
        matches!(self, NakReason::Bcc | NakReason::Format)
    }

    /// A few lowercase words for messages: `out of range`.
    pub fn brief(self) -> &'static str {
        match self {
            NakReason::Bcc => "BCC error",
            NakReason::Format => "format error",
            NakReason::OutOfRange => "out of range",
            NakReason::ControlCode => "control code not accepted",
            NakReason::NotInRobotMode => "not in robot mode",
            NakReason::StationModel => "station model unknown",
            NakReason::Undefined => "undefined error",
            NakReason::Other(_) => "error number not in the spec",
        }
    }

    /// The spec's words.
    pub fn words(self) -> &'static str {
        match self {
            NakReason::Bcc => "BCC error (the frame failed its check)",
            NakReason::Format => "Format error (incorrect size or layout)",
            NakReason::OutOfRange => "Out of range (value beyond the station's limits)",
            NakReason::ControlCode => "Control error (control code not accepted)",
            NakReason::NotInRobotMode => "Control mode error (the station is not in robot mode)",
            NakReason::StationModel => "Station model error (station unknown)",
            NakReason::Undefined => "Undefined error",
            NakReason::Other(_) => "Error number not in the spec",
        }
    }
}

impl fmt::Display for NakReason {
    /// The words and the number: `Out of range (…) (3)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} ({})", self.words(), self.code())
    }
}

/// The port status digits: units = tool on, tens = cooling, hundreds = suction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct PortStatus {
    /// Heater and air pump on.
    pub tool_on: bool,
    /// Cooling: heater off, air pump on.
    pub cooling: bool,
    /// Suction (vacuum pick-up) on.
    pub suction: bool,
}

impl PortStatus {
    /// The number on the wire (`00101` = suction on, tool on).
    pub fn to_number(self) -> i32 {
        i32::from(self.tool_on) + 10 * i32::from(self.cooling) + 100 * i32::from(self.suction)
    }

    /// The status for a number from the wire: only 0/1 digits in the lowest three places.
    pub fn from_number(number: i32) -> Option<PortStatus> {
        if !(0..1000).contains(&number) {
            return None;
        }
        let bit = |place: i32| match (number / place) % 10 {
            0 => Some(false),
            1 => Some(true),
            _ => None,
        };
        Some(PortStatus {
            tool_on: bit(1)?,
            cooling: bit(10)?,
            suction: bit(100)?,
        })
    }
}

impl fmt::Display for PortStatus {
    /// `tool on, cooling off, suction off`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let on = |b: bool| if b { "on" } else { "off" };
        write!(
            f,
            "tool {}, cooling {}, suction {}",
            on(self.tool_on),
            on(self.cooling),
            on(self.suction)
        )
    }
}

/// The work mode (spec table "Work modes").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum WorkMode {
    /// `00000`: manual mode, profiles off.
    #[default]
    Manual,
    /// `00001`: profile mode, profiles on.
    Profile,
}

impl WorkMode {
    /// The number on the wire.
    pub fn number(self) -> i32 {
        match self {
            WorkMode::Manual => 0,
            WorkMode::Profile => 1,
        }
    }

    /// The mode for a number from the wire.
    pub fn from_number(number: i32) -> Option<WorkMode> {
        match number {
            0 => Some(WorkMode::Manual),
            1 => Some(WorkMode::Profile),
            _ => None,
        }
    }
}

impl fmt::Display for WorkMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            WorkMode::Manual => "Manual mode (profiles off)",
            WorkMode::Profile => "Profile mode (profiles on)",
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_code_round_trips_through_its_wire_characters() {
        for code in Code::all() {
            assert_eq!(Code::from_raw(code.raw()), Some(code), "{code}");
            assert_eq!(code.to_string().parse::<Code>(), Ok(code));
        }
        assert_eq!(Code::all().len(), 26);
    }

    #[test]
    fn codes_parse_in_any_case() {
        assert_eq!("st1".parse(), Ok(Code::SelectAirTemp(Port::One)));
        assert_eq!("a11".parse(), Ok(Code::AdjustTemp(Port::One, Tool::Jt)));
        assert_eq!("A12".parse(), Ok(Code::AdjustTemp(Port::One, Tool::Te)));
        assert_eq!("Smn".parse(), Ok(Code::StationModel));
        assert_eq!("RST".parse(), Ok(Code::ResetSettings));
        assert_eq!("SER".parse(), Ok(Code::StationError));
        assert_eq!("SE1".parse(), Ok(Code::SelectExternalTemp(Port::One)));
    }

    #[test]
    fn a_code_for_port_three_is_refused_with_a_suggestion() {
        let err = "ST3".parse::<Code>().unwrap_err();
        assert_eq!(
            err,
            CodeError::NoSuchPort {
                text: "ST3".into(),
                port: '3',
                suggestion: "ST1".into()
            }
        );
        assert!(err.to_string().contains("only port 1"), "{err}");
        assert!(matches!(
            "PP3".parse::<Code>(),
            Err(CodeError::NoSuchPort { .. })
        ));
        assert!(matches!(
            "A21".parse::<Code>(),
            Err(CodeError::NoSuchPort { .. })
        ));
    }

    #[test]
    fn adjust_codes_exist_only_for_jt_and_te() {
        assert_eq!(
            "A10".parse::<Code>(),
            Err(CodeError::NoSuchTool {
                text: "A10".into(),
                tool: '0'
            })
        );
        assert!(matches!(
            "A13".parse::<Code>(),
            Err(CodeError::NoSuchTool { .. })
        ));
        assert_eq!(
            Code::AdjustTemp(Port::One, Tool::None).raw().to_string(),
            "A10"
        );
        assert_eq!(
            Code::from_raw(Code::AdjustTemp(Port::One, Tool::None).raw()),
            None
        );
    }

    #[test]
    fn unknown_codes_name_the_text_and_list_the_known_ones() {
        let err = "XYZ".parse::<Code>().unwrap_err();
        let text = err.to_string();
        assert!(text.contains("\"XYZ\""), "{text}");
        assert!(
            text.contains("ST1") && text.contains("A12") && text.contains("SC1"),
            "{text}"
        );
        assert!(matches!(
            "RST1".parse::<Code>(),
            Err(CodeError::Unknown { .. })
        ));
        assert!(matches!("".parse::<Code>(), Err(CodeError::Unknown { .. })));
        assert!(matches!(
            "STX".parse::<Code>(),
            Err(CodeError::Unknown { .. })
        ));
        assert!(matches!(
            "é1".parse::<Code>(),
            Err(CodeError::Unknown { .. })
        ));
    }

    #[test]
    fn wire_codes_are_case_exact() {
        let lower = RawCode::new(*b"st1").expect("printable");
        assert_eq!(Code::from_raw(lower), None);
    }

    #[test]
    fn access_follows_the_command_list() {
        use Code::*;
        let p = Port::One;
        for code in [
            SelectAirTemp(p),
            WorkMode(p),
            PortStatus(p),
            AdjustTemp(p, Tool::Te),
            MinExternalTemp,
        ] {
            assert!(code.readable() && code.writable(), "{code}");
        }
        for code in [
            AirTemp(p),
            ExternalTemp(p),
            PortPower(p),
            PortError(p),
            ConnectedTool(p),
        ] {
            assert!(code.readable() && !code.writable(), "{code}");
        }
        for code in [
            StationModel,
            StationError,
            PluggedHours(p),
            WorkHours(p),
            ToolCycles(p),
            SuctionCycles(p),
        ] {
            assert!(code.readable() && !code.writable(), "{code}");
        }
        for code in [ResetParameters, ResetSettings] {
            assert!(!code.readable() && code.writable(), "{code}");
        }
    }

    #[test]
    fn units_and_words_follow_the_spec() {
        assert_eq!(Code::SelectAirTemp(Port::One).unit(), Some(Unit::Celsius));
        assert_eq!(
            Code::PortPower(Port::One).unit().map(Unit::symbol),
            Some("‰")
        );
        assert_eq!(
            Code::WorkHours(Port::One).unit().map(Unit::symbol),
            Some("h")
        );
        assert_eq!(
            Code::ToolCycles(Port::One).unit().map(Unit::symbol),
            Some("cycles")
        );
        assert_eq!(Code::PortStatus(Port::One).unit(), None);
        assert_eq!(
            Code::SelectAirTemp(Port::One).describe(),
            "selected air temperature"
        );
    }

    fn data(text: &str) -> Data {
        Data::from_bytes(text.as_bytes().try_into().expect("5 bytes")).expect("printable")
    }

    #[test]
    fn interpret_gives_quantities_with_units() {
        let r = interpret(Code::SelectAirTemp(Port::One), &data("00350")).unwrap();
        assert_eq!(r.to_string(), "350 °C");
        assert_eq!(r.value(), Value::Number(350));
        assert_eq!(r.unit(), Some(Unit::Celsius));
        let r = interpret(Code::AdjustTemp(Port::One, Tool::Jt), &data("-0050")).unwrap();
        assert_eq!(r.to_string(), "-50 °C");
        assert_eq!(
            interpret(Code::PortPower(Port::One), &data("00412"))
                .unwrap()
                .to_string(),
            "412 ‰"
        );
    }

    #[test]
    fn interpret_gives_table_values_in_words() {
        let p = Port::One;
        assert_eq!(
            interpret(Code::ConnectedTool(p), &data("00001"))
                .unwrap()
                .to_string(),
            "JT"
        );
        assert_eq!(
            interpret(Code::PortError(p), &data("00009"))
                .unwrap()
                .to_string(),
            "No tool (9)"
        );
        assert_eq!(
            interpret(Code::PortStatus(p), &data("00001"))
                .unwrap()
                .to_string(),
            "tool on, cooling off, suction off"
        );
        assert_eq!(
            interpret(Code::PortStatus(p), &data("00110"))
                .unwrap()
                .to_string(),
            "tool off, cooling on, suction on"
        );
        assert_eq!(
            interpret(Code::WorkMode(p), &data("00000"))
                .unwrap()
                .to_string(),
            "Manual mode (profiles off)"
        );
        assert_eq!(
            interpret(Code::StationError, &data("00004"))
                .unwrap()
                .to_string(),
            "Mains frequency (4)"
        );
        let model = interpret(Code::StationModel, &data(" JTSE")).unwrap();
        assert_eq!(model.to_string(), "JTSE");
        assert_eq!(model.value(), Value::Text("JTSE".into()));
    }

    #[test]
    fn interpret_refuses_values_outside_the_tables() {
        let p = Port::One;
        assert_eq!(
            interpret(Code::PortError(p), &data("00011")),
            Err(InterpretError::UnknownValue {
                code: Code::PortError(p),
                value: 11,
                known: "0 to 10"
            })
        );
        assert!(matches!(
            interpret(Code::PortStatus(p), &data("00002")),
            Err(InterpretError::UnknownValue { .. })
        ));
        assert!(matches!(
            interpret(Code::PortStatus(p), &data("01000")),
            Err(InterpretError::UnknownValue { .. })
        ));
        assert!(matches!(
            interpret(Code::AirTemp(p), &data(" JTSE")),
            Err(InterpretError::NotANumber { .. })
        ));
        assert_eq!(
            interpret(Code::ResetParameters, &Data::ZERO),
            Err(InterpretError::NoReading {
                code: Code::ResetParameters
            })
        );
    }

    #[test]
    fn nak_reasons_keep_unknown_numbers_and_know_which_to_retry() {
        for n in [1, 2, 3, 4, 5, 6, 99999, 7, 42, -1] {
            assert_eq!(NakReason::from_code(n).code(), n);
        }
        assert_eq!(NakReason::from_code(7), NakReason::Other(7));
        assert!(NakReason::Bcc.is_transmission_error());
        assert!(NakReason::Format.is_transmission_error());
        for r in [
            NakReason::OutOfRange,
            NakReason::ControlCode,
            NakReason::NotInRobotMode,
            NakReason::Other(1),
        ] {
            assert!(!r.is_transmission_error(), "{r}");
        }
        assert!(NakReason::OutOfRange.to_string().ends_with("(3)"));
    }

    #[test]
    fn port_status_digits_map_to_bits_and_back() {
        for n in [0, 1, 10, 11, 100, 101, 110, 111] {
            assert_eq!(
                PortStatus::from_number(n).map(PortStatus::to_number),
                Some(n)
            );
        }
        for n in [2, 20, 200, 1000, -1, 99999] {
            assert_eq!(PortStatus::from_number(n), None, "{n}");
        }
    }

    #[test]
    fn tables_round_trip_their_numbers() {
        for e in ToolError::ALL {
            assert_eq!(ToolError::from_code(e.code()), Some(*e));
        }
        for e in StationError::ALL {
            assert_eq!(StationError::from_code(e.code()), Some(*e));
        }
        assert_eq!(ToolError::ALL.len(), 11);
        assert_eq!(StationError::ALL.len(), 7);
        for t in Tool::ALL {
            assert_eq!(Tool::from_number(t.number()), Some(t));
        }
    }
}
