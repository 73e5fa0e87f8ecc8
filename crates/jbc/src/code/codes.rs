//! The control codes: what each reads or writes, its unit and its words.

use std::fmt;
use std::str::FromStr;

use crate::frame::RawCode;

use super::*;

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
pub(super) enum Access {
    ReadWrite,
    ReadOnly,
    WriteOnly,
}

/// Makes a port-carrying code.
type PortCode = fn(Port) -> Code;

/// Two-letter commands followed by a port digit.
pub(super) const PORT_CODES: [([u8; 2], PortCode); 14] = [
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
pub(super) const STATION_CODES: [([u8; 3], Code); 10] = [
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
pub(super) const ADJUST_LETTER: u8 = b'A';

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
pub(super) enum CodeFault {
    Unknown,
    Port(u8),
    Tool(u8),
}

pub(super) fn parse_code(bytes: &[u8; 3]) -> Result<Code, CodeFault> {
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

pub(super) fn known_codes() -> String {
    Code::all()
        .iter()
        .map(Code::to_string)
        .collect::<Vec<_>>()
        .join(", ")
}
