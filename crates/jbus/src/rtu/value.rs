//! Ranged values of Modbus RTU: unit numbers, function and exception codes, counts.
//!
//! Each type checks its range once, in its constructor, so a request built from them is
//! valid by construction. Errors carry the value, the range and what the value was for.

use std::fmt;
use std::num::NonZeroU8;

/// A value outside what the protocol allows.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum InvalidValue {
    /// A number outside its range.
    #[error("{what} {value} is outside the allowed range {min}..={max}")]
    OutOfRange {
        /// What the number was for ("unit number", "register count", ...).
        what: &'static str,
        /// The number given.
        value: u32,
        /// The smallest allowed.
        min: u32,
        /// The largest allowed.
        max: u32,
    },
    /// A block of addresses that would run past the last address 0xFFFF.
    #[error(
        "{count} {what} from address {address} (0x{address:04X}) would run past the last address 65535 (0xFFFF)"
    )]
    PastLastAddress {
        /// What the block holds ("registers", "coils").
        what: &'static str,
        /// The first address.
        address: u16,
        /// How many items.
        count: u32,
    },
}

impl InvalidValue {
    pub(crate) fn out_of_range(
        what: &'static str,
        value: impl TryInto<u32>,
        min: u32,
        max: u32,
    ) -> Self {
        Self::OutOfRange {
            what,
            value: value.try_into().unwrap_or(u32::MAX),
            min,
            max,
        }
    }
}

/// Checks that `count` items from `address` stay within 0..=0xFFFF.
pub(crate) fn check_block(
    what: &'static str,
    address: u16,
    count: usize,
) -> Result<(), InvalidValue> {
    if usize::from(address) + count > ADDRESS_SPACE {
        return Err(InvalidValue::PastLastAddress {
            what,
            address,
            count: u32::try_from(count).unwrap_or(u32::MAX),
        });
    }
    Ok(())
}

/// Number of addresses in each Modbus table (0x0000..=0xFFFF).
pub const ADDRESS_SPACE: usize = 0x1_0000;

/// The unit number 0: a broadcast to every device on the line, which none answers.
pub const BROADCAST_UNIT: u8 = 0;

/// The number of one device on the line: 1–247 as Modbus allows, or up to 255 for JBUS
/// devices, which the JBUS documents allow ("from 1 to FF") but must be asked for with
/// [`UnitId::jbus`]. Broadcast (0) is not a unit: see [`Broadcast`](super::Broadcast).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct UnitId(NonZeroU8);

impl UnitId {
    /// The lowest unit number.
    pub const MIN: u8 = 1;
    /// The highest Modbus unit number (248–255 are reserved by Modbus).
    pub const MAX: u8 = 247;
    /// The highest JBUS unit number.
    pub const JBUS_MAX: u8 = 255;

    /// A Modbus unit number, 1–247.
    pub fn new(number: u8) -> Result<Self, InvalidValue> {
        Self::in_range(number, Self::MAX)
    }

    /// A JBUS unit number, 1–255: JBUS devices may use the numbers Modbus reserves.
    pub fn jbus(number: u8) -> Result<Self, InvalidValue> {
        Self::in_range(number, Self::JBUS_MAX)
    }

    /// The number on the wire.
    pub const fn get(self) -> u8 {
        self.0.get()
    }

    fn in_range(number: u8, max: u8) -> Result<Self, InvalidValue> {
        match NonZeroU8::new(number) {
            Some(n) if number <= max => Ok(Self(n)),
            _ => Err(InvalidValue::out_of_range(
                "unit number",
                number,
                Self::MIN.into(),
                max.into(),
            )),
        }
    }
}

/// Checks the unit number a configuration gives a JBUS device (any integer, or none at
/// all): one of 1–255, as [`UnitId::jbus`]. The one check for every configured JBUS or
/// Modbus device; the caller words the error for its device.
pub fn check_unit(number: Option<i64>) -> Result<UnitId, UnitProblem> {
    let number = number.ok_or(UnitProblem::Missing)?;
    u8::try_from(number)
        .ok()
        .and_then(|n| UnitId::jbus(n).ok())
        .ok_or(UnitProblem::OutOfRange { number })
}

/// Why a configured unit number is not a JBUS unit number ([`check_unit`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum UnitProblem {
    /// No unit number was given.
    #[error("a unit number is needed, {} to {}", UnitId::MIN, UnitId::JBUS_MAX)]
    Missing,
    /// The number is outside 1–255 (0 is broadcast, which no device answers).
    #[error(
        "unit number {number} is out of range: {} to {} (0 is broadcast, never answered)",
        UnitId::MIN,
        UnitId::JBUS_MAX
    )]
    OutOfRange {
        /// The number given.
        number: i64,
    },
}

impl TryFrom<u8> for UnitId {
    type Error = InvalidValue;
    /// Same as [`UnitId::new`] (1–247).
    fn try_from(number: u8) -> Result<Self, InvalidValue> {
        Self::new(number)
    }
}

impl fmt::Display for UnitId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.get())
    }
}

/// Defines a count newtype with a checked constructor.
macro_rules! count_type {
    ($(#[$doc:meta])* $name:ident, $what:literal, $max:expr) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
        pub struct $name(u16);

        impl $name {
            /// The smallest count.
            pub const MIN: u16 = 1;
            /// The largest count the protocol allows.
            pub const MAX: u16 = $max;

            /// A count, checked against the protocol's limits.
            pub fn new(count: u16) -> Result<Self, InvalidValue> {
                if (Self::MIN..=Self::MAX).contains(&count) {
                    Ok(Self(count))
                } else {
                    Err(InvalidValue::out_of_range($what, count, Self::MIN.into(), Self::MAX.into()))
                }
            }

            /// A count from a length (of a slice of values to write).
            pub fn from_len(len: usize) -> Result<Self, InvalidValue> {
                u16::try_from(len)
                    .map_err(|_| InvalidValue::out_of_range($what, len, Self::MIN.into(), Self::MAX.into()))
                    .and_then(Self::new)
            }

            /// The count.
            pub const fn get(self) -> u16 {
                self.0
            }
        }

        impl TryFrom<u16> for $name {
            type Error = InvalidValue;
            fn try_from(count: u16) -> Result<Self, InvalidValue> {
                Self::new(count)
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "{}", self.0)
            }
        }
    };
}

count_type!(
    /// How many registers one read (functions 3 and 4) asks for: 1–125, so the reply's
    /// 250 data bytes fit its one-byte byte count.
    ReadRegisterCount,
    "register count",
    125
);
count_type!(
    /// How many registers one write (function 16) carries: 1–123, so the request fits
    /// the 256-byte RTU frame.
    WriteRegisterCount,
    "register count to write",
    123
);
count_type!(
    /// How many coils or discrete inputs one read (functions 1 and 2) asks for: 1–2000.
    ReadBitCount,
    "bit count",
    2000
);
count_type!(
    /// How many coils one write (function 15) carries: 1–1968.
    WriteBitCount,
    "coil count to write",
    1968
);

/// A Modbus function code, 0–127 (the high bit marks an exception response).
///
/// The eight functions this crate frames have named constants; any other code can be
/// held (a server refuses it with [`ExceptionCode::ILLEGAL_FUNCTION`]).
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct FunctionCode(u8);

/// The bit a server sets in the function code of an exception response.
pub const EXCEPTION_BIT: u8 = 0x80;

impl FunctionCode {
    /// 1: read n output and internal bits (coils).
    pub const READ_COILS: Self = Self(1);
    /// 2: read n input bits (discrete inputs).
    pub const READ_DISCRETE_INPUTS: Self = Self(2);
    /// 3: read n output and internal words (holding registers); the only function of a CROSS.
    pub const READ_HOLDING_REGISTERS: Self = Self(3);
    /// 4: read n input words (input registers).
    pub const READ_INPUT_REGISTERS: Self = Self(4);
    /// 5: write one bit (coil).
    pub const WRITE_SINGLE_COIL: Self = Self(5);
    /// 6: write one word (holding register).
    pub const WRITE_SINGLE_REGISTER: Self = Self(6);
    /// 15: write n bits (coils).
    pub const WRITE_MULTIPLE_COILS: Self = Self(15);
    /// 16: write n words (holding registers).
    pub const WRITE_MULTIPLE_REGISTERS: Self = Self(16);

    /// A function code, 0–127.
    pub fn new(code: u8) -> Result<Self, InvalidValue> {
        if code & EXCEPTION_BIT == 0 {
            Ok(Self(code))
        } else {
            Err(InvalidValue::out_of_range("function code", code, 0, 127))
        }
    }

    /// The function an exception response's function byte refers to (its high bit cleared).
    pub const fn of_exception(byte: u8) -> Self {
        Self(byte & !EXCEPTION_BIT)
    }

    /// The code on the wire.
    pub const fn get(self) -> u8 {
        self.0
    }

    /// What the function does, for the functions Modbus and JBUS define.
    pub fn name(self) -> Option<&'static str> {
        Some(match self.0 {
            1 => "read coils",
            2 => "read discrete inputs",
            3 => "read holding registers",
            4 => "read input registers",
            5 => "write single coil",
            6 => "write single register",
            7 => "read exception status",
            8 => "diagnostics",
            11 => "get comm event counter",
            12 => "get comm event log",
            13 => "program command (JBUS)",
            14 => "program command diagnostics (JBUS)",
            15 => "write multiple coils",
            16 => "write multiple registers",
            17 => "report server id",
            20 => "read file record",
            21 => "write file record",
            22 => "mask write register",
            23 => "read/write multiple registers",
            24 => "read FIFO queue",
            43 => "encapsulated interface transport",
            _ => return None,
        })
    }
}

impl fmt::Debug for FunctionCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "FunctionCode({self})")
    }
}

impl fmt::Display for FunctionCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.name() {
            Some(name) => write!(f, "{} ({name})", self.0),
            None => write!(f, "{}", self.0),
        }
    }
}

/// The code of an exception response: why a device refused a request.
///
/// Codes 1–4 are the ones every server uses and have named constants; 5–255 are kept by
/// number (5, 6, 8, 10 and 11 also have names). Code 0 does not exist.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ExceptionCode(NonZeroU8);

impl ExceptionCode {
    /// 1: the device does not know or allow the function ("function code unknown").
    pub const ILLEGAL_FUNCTION: Self = Self::known(1);
    /// 2: the request touches an address the device does not have.
    pub const ILLEGAL_DATA_ADDRESS: Self = Self::known(2);
    /// 3: a value in the request is not allowed (a count of 0, more than 125 words, ...).
    pub const ILLEGAL_DATA_VALUE: Self = Self::known(3);
    /// 4: the device failed while doing what was asked.
    pub const SERVER_DEVICE_FAILURE: Self = Self::known(4);
    /// 5: accepted, but it will take long (poll for completion).
    pub const ACKNOWLEDGE: Self = Self::known(5);
    /// 6: busy with a long command; try again later.
    pub const SERVER_DEVICE_BUSY: Self = Self::known(6);
    /// 8: memory parity error in a file record.
    pub const MEMORY_PARITY_ERROR: Self = Self::known(8);
    /// 10 (0x0A): a gateway has no path to the target.
    pub const GATEWAY_PATH_UNAVAILABLE: Self = Self::known(10);
    /// 11 (0x0B): a gateway's target did not respond.
    pub const GATEWAY_TARGET_FAILED: Self = Self::known(11);

    /// Whether the exception comes from a Modbus gateway saying the unit behind it is not
    /// there: no path to it (10) or no answer from it (11). As far as the master can tell,
    /// the unit is silent.
    pub fn is_target_silent(self) -> bool {
        self == Self::GATEWAY_PATH_UNAVAILABLE || self == Self::GATEWAY_TARGET_FAILED
    }

    /// Whether a read refused with this exception may be split to find the registers it
    /// is refused for: 2 (an address the device lacks), 3 (a count or range it does not
    /// take in one read) and 4 (it failed on some register). Busy (6) and the rest say
    /// nothing about the addresses.
    pub fn is_about_the_addresses(self) -> bool {
        self == Self::ILLEGAL_DATA_ADDRESS
            || self == Self::ILLEGAL_DATA_VALUE
            || self == Self::SERVER_DEVICE_FAILURE
    }

    const fn known(code: u8) -> Self {
        match NonZeroU8::new(code) {
            Some(n) => Self(n),
            None => panic!("exception code constants are not zero"),
        }
    }

    /// An exception code, 1–255.
    pub fn new(code: u8) -> Result<Self, InvalidValue> {
        NonZeroU8::new(code)
            .map(Self)
            .ok_or_else(|| InvalidValue::out_of_range("exception code", code, 1, 255))
    }

    /// The code on the wire.
    pub const fn get(self) -> u8 {
        self.0.get()
    }

    /// The meaning in words, for the codes Modbus defines.
    pub fn meaning(self) -> Option<&'static str> {
        Some(match self.get() {
            1 => "illegal function: the device does not support this function",
            2 => "illegal data address: the request touches an address the device does not have",
            3 => "illegal data value: a value in the request (such as the count) is not allowed",
            4 => "server device failure: the device failed while handling the request",
            5 => "acknowledge: the device accepted a long command and is working on it",
            6 => "server device busy: the device is busy with a long command, try again later",
            8 => "memory parity error: the device found a parity error in its file memory",
            10 => "gateway path unavailable: the gateway has no path to the target device",
            11 => "gateway target failed to respond: the device behind the gateway did not answer",
            _ => return None,
        })
    }
}

impl fmt::Debug for ExceptionCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ExceptionCode({})", self.get())
    }
}

impl fmt::Display for ExceptionCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.meaning() {
            Some(meaning) => write!(f, "exception {} ({meaning})", self.get()),
            None => write!(f, "exception {} (not defined by Modbus)", self.get()),
        }
    }
}

/// A device's refusal of a request: the function it refused and why.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Exception {
    /// The function of the refused request.
    pub function: FunctionCode,
    /// Why.
    pub code: ExceptionCode,
}

impl fmt::Display for Exception {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "function {} refused with {}", self.function, self.code)
    }
}

impl std::error::Error for Exception {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_configured_unit_is_checked_against_1_to_255_and_must_be_given() {
        assert_eq!(check_unit(Some(1)).map(UnitId::get), Ok(1));
        assert_eq!(check_unit(Some(255)).map(UnitId::get), Ok(255));
        for number in [0, 256, -1, i64::MAX] {
            assert_eq!(
                check_unit(Some(number)),
                Err(UnitProblem::OutOfRange { number })
            );
        }
        assert_eq!(check_unit(None), Err(UnitProblem::Missing));
        assert_eq!(
            UnitProblem::OutOfRange { number: 0 }.to_string(),
            "unit number 0 is out of range: 1 to 255 (0 is broadcast, never answered)"
        );
        assert_eq!(
            UnitProblem::Missing.to_string(),
            "a unit number is needed, 1 to 255"
        );
    }

    #[test]
    fn unit_accepts_1_to_247_and_refuses_0_and_248() {
        assert_eq!(UnitId::new(1).map(UnitId::get), Ok(1));
        assert_eq!(UnitId::new(247).map(UnitId::get), Ok(247));
        assert_eq!(
            UnitId::new(0),
            Err(InvalidValue::OutOfRange {
                what: "unit number",
                value: 0,
                min: 1,
                max: 247
            })
        );
        assert_eq!(
            UnitId::new(248),
            Err(InvalidValue::OutOfRange {
                what: "unit number",
                value: 248,
                min: 1,
                max: 247
            })
        );
    }

    #[test]
    fn jbus_units_reach_255_but_never_0() {
        assert_eq!(UnitId::jbus(255).map(UnitId::get), Ok(255));
        assert_eq!(UnitId::jbus(248).map(UnitId::get), Ok(248));
        assert!(UnitId::jbus(0).is_err());
    }

    #[test]
    fn counts_hold_the_protocol_limits() {
        assert_eq!(
            ReadRegisterCount::new(125).map(ReadRegisterCount::get),
            Ok(125)
        );
        assert!(ReadRegisterCount::new(126).is_err());
        assert!(ReadRegisterCount::new(0).is_err());
        assert_eq!(
            WriteRegisterCount::new(123).map(WriteRegisterCount::get),
            Ok(123)
        );
        assert!(WriteRegisterCount::new(124).is_err());
        assert_eq!(ReadBitCount::new(2000).map(ReadBitCount::get), Ok(2000));
        assert!(ReadBitCount::new(2001).is_err());
        assert_eq!(WriteBitCount::new(1968).map(WriteBitCount::get), Ok(1968));
        assert_eq!(
            WriteBitCount::from_len(70_000),
            Err(InvalidValue::OutOfRange {
                what: "coil count to write",
                value: 70_000,
                min: 1,
                max: 1968
            })
        );
    }

    #[test]
    fn exception_codes_name_1_to_4_in_words_and_keep_others_by_number() {
        assert_eq!(
            ExceptionCode::new(2),
            Ok(ExceptionCode::ILLEGAL_DATA_ADDRESS)
        );
        assert!(
            ExceptionCode::ILLEGAL_FUNCTION
                .to_string()
                .contains("illegal function")
        );
        assert!(
            ExceptionCode::SERVER_DEVICE_FAILURE
                .to_string()
                .contains("server device failure")
        );
        assert_eq!(ExceptionCode::new(0x0B).map(ExceptionCode::get), Ok(11));
        assert!(
            ExceptionCode::GATEWAY_TARGET_FAILED
                .to_string()
                .contains("gateway target")
        );
        assert_eq!(
            ExceptionCode::new(0x42).map(|c| c.to_string()),
            Ok("exception 66 (not defined by Modbus)".into())
        );
        assert!(ExceptionCode::new(0).is_err());
    }

    #[test]
    fn function_codes_with_the_exception_bit_are_refused() {
        assert_eq!(
            FunctionCode::new(3),
            Ok(FunctionCode::READ_HOLDING_REGISTERS)
        );
        assert!(FunctionCode::new(0x83).is_err());
        assert_eq!(
            FunctionCode::of_exception(0x83),
            FunctionCode::READ_HOLDING_REGISTERS
        );
        assert_eq!(
            FunctionCode::READ_HOLDING_REGISTERS.to_string(),
            "3 (read holding registers)"
        );
    }

    #[test]
    fn blocks_may_end_at_0xffff_but_not_past_it() {
        assert_eq!(check_block("registers", 0xFFFF, 1), Ok(()));
        assert_eq!(check_block("registers", 0xFF83, 125), Ok(()));
        assert_eq!(
            check_block("registers", 0xFF84, 125),
            Err(InvalidValue::PastLastAddress {
                what: "registers",
                address: 0xFF84,
                count: 125
            })
        );
    }
}
