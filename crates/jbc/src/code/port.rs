//! Ports and tools: the station's tool port and the tools it takes.

use std::fmt;

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

    pub(super) fn digit(self) -> u8 {
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
