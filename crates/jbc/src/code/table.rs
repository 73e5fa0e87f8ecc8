//! The spec's tables: tool, tool error, station error, NAK reason, port status, work mode.

use std::fmt;

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
