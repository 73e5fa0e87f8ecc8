//! Values that span registers: 16-, 32- and 64-bit integers, IEEE 754 floats, ASCII
//! strings and single bits, in the byte and word order a device uses, with a linear
//! scale.
//!
//! A [`Format`] is a [`DataType`], an [`Order`] and a [`Scaling`]: [`Format::decode`]
//! turns the registers of one value into a [`TypedValue`], [`Format::encode`] turns a value
//! into the registers to write, refusing any value the type cannot hold.
//!
//! # Byte and word order
//!
//! The letters name the bytes of the value, `A` the most significant, in the order they
//! stand on the wire (the first register's high byte first). Each order is two independent
//! choices, and 64-bit values use the same two:
//!
//! | order  | words (registers)      | bytes in a word | 32 bits `0x4365B333` | 64 bits `0x0102030405060708` |
//! |--------|------------------------|-----------------|----------------------|------------------------------|
//! | `ABCD` | most significant first | high byte first | `4365 B333`          | `0102 0304 0506 0708`        |
//! | `CDAB` | least significant first| high byte first | `B333 4365`          | `0708 0506 0304 0102`        |
//! | `BADC` | most significant first | low byte first  | `6543 33B3`          | `0201 0403 0605 0807`        |
//! | `DCBA` | least significant first| low byte first  | `33B3 6543`          | `0807 0605 0403 0201`        |
//!
//! For 64 bits these are Telegraf's `ABCDEFGH`, `GHEFCDAB`, `BADCFEHG` and `HGFEDCBA`
//! (Neuron's 8-byte orders likewise): `CDAB` reverses all four words, not each pair. For
//! 16-bit types only the byte half matters: `ABCD` and `CDAB` read a register as it is,
//! `BADC` and `DCBA` swap its two bytes. A string keeps its registers in address order
//! and takes the byte half only: two characters per register, the first in the high byte
//! (`ABCD`, `CDAB`) or the low byte (`BADC`, `DCBA`). A bit is taken from the register's
//! value as read (bit 0 the least significant), whatever the order.

use std::fmt;
use std::str::FromStr;

/// The most registers one value may take: a string of 125 registers is one whole read.
pub const MAX_VALUE_REGISTERS: u16 = 125;

/// How the registers of one value are read: the kind of number (or text, or bit) and its
/// width.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DataType {
    /// Signed 16 bits, one register.
    Int16,
    /// Unsigned 16 bits, one register.
    Uint16,
    /// Signed 32 bits, two registers.
    Int32,
    /// Unsigned 32 bits, two registers.
    Uint32,
    /// Signed 64 bits, four registers.
    Int64,
    /// Unsigned 64 bits, four registers.
    Uint64,
    /// IEEE 754 single precision, two registers.
    Float32,
    /// IEEE 754 double precision, four registers.
    Float64,
    /// ASCII text in a fixed number of registers, two characters each; trailing NULs and
    /// spaces are not part of the text (`string:N` in words).
    String(StringRegisters),
    /// One bit of a register (`bit:N`, N from 0, the least significant, to 15).
    Bit(BitIndex),
}

/// How many registers a [`DataType::String`] takes: 1–125.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct StringRegisters(u16);

impl StringRegisters {
    /// A length of 1–125 registers (2–250 characters).
    pub fn new(registers: u16) -> Result<Self, ParseTypeError> {
        if (1..=MAX_VALUE_REGISTERS).contains(&registers) {
            Ok(Self(registers))
        } else {
            Err(ParseTypeError::StringLength {
                registers: registers.into(),
            })
        }
    }

    /// The number of registers.
    pub const fn get(self) -> u16 {
        self.0
    }
}

/// Which bit of a register a [`DataType::Bit`] is: 0 (the least significant) to 15.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct BitIndex(u8);

impl BitIndex {
    /// Bit `index`, 0–15.
    pub fn new(index: u8) -> Result<Self, ParseTypeError> {
        if index < 16 {
            Ok(Self(index))
        } else {
            Err(ParseTypeError::BitIndex {
                index: index.into(),
            })
        }
    }

    /// The bit's number.
    pub const fn get(self) -> u8 {
        self.0
    }

    /// Whether the bit is set in `register`.
    pub const fn of(self, register: u16) -> bool {
        register & (1 << self.0) != 0
    }

    /// `register` with the bit set or cleared, the other 15 bits unchanged: how a bit is
    /// written (read its register, set the bit, write the register).
    pub const fn set(self, register: u16, on: bool) -> u16 {
        if on {
            register | (1 << self.0)
        } else {
            register & !(1 << self.0)
        }
    }
}

impl DataType {
    /// The names [`FromStr`] takes, for messages.
    pub const CHOICES: &'static str = "int16, uint16, int32, uint32, int64, uint64, float32, float64, string:N (N registers), bit:N (N 0-15)";

    /// How many registers one value takes.
    pub const fn registers(self) -> u16 {
        match self {
            Self::Int16 | Self::Uint16 | Self::Bit(_) => 1,
            Self::Int32 | Self::Uint32 | Self::Float32 => 2,
            Self::Int64 | Self::Uint64 | Self::Float64 => 4,
            Self::String(length) => length.get(),
        }
    }

    /// Whether values of the type are numbers (everything but strings and bits), the
    /// values a [`Scaling`] applies to.
    pub const fn is_number(self) -> bool {
        !matches!(self, Self::String(_) | Self::Bit(_))
    }

    /// The value that `registers` (exactly [`registers`](Self::registers) of them) hold
    /// in `order`, unscaled.
    pub fn decode(self, order: Order, registers: &[u16]) -> Result<TypedValue, DecodeError> {
        let expected = self.registers();
        if registers.len() != usize::from(expected) {
            return Err(DecodeError::WrongLength {
                data_type: self,
                expected,
                actual: registers.len(),
            });
        }
        let bytes = order.bytes_of(registers, self.is_string());
        let array = |n: usize| -> [u8; 8] {
            let mut out = [0u8; 8];
            out[8 - n..].copy_from_slice(&bytes[..n]);
            out
        };
        Ok(match self {
            Self::Int16 => TypedValue::Int(i16::from_be_bytes([bytes[0], bytes[1]]).into()),
            Self::Uint16 => TypedValue::Uint(u16::from_be_bytes([bytes[0], bytes[1]]).into()),
            Self::Int32 => TypedValue::Int(i32::from_be_bytes(first4(&bytes)).into()),
            Self::Uint32 => TypedValue::Uint(u32::from_be_bytes(first4(&bytes)).into()),
            Self::Int64 => TypedValue::Int(i64::from_be_bytes(array(8))),
            Self::Uint64 => TypedValue::Uint(u64::from_be_bytes(array(8))),
            Self::Float32 => TypedValue::Float(widen(f32::from_be_bytes(first4(&bytes)))),
            Self::Float64 => TypedValue::Float(f64::from_be_bytes(array(8))),
            Self::String(_) => TypedValue::Text(decode_text(self, &bytes)?),
            Self::Bit(index) => TypedValue::Bool(index.of(registers[0])),
        })
    }

    /// The registers that hold `value` in `order`, unscaled; refuses a value the type
    /// cannot hold exactly (out of range, not whole for an integer, not finite, text
    /// where a number is wanted or the reverse, a string too long or not ASCII).
    ///
    /// A [`DataType::Bit`] is refused: a bit is written through its register
    /// ([`BitIndex::set`]), which this function does not know.
    pub fn encode(self, order: Order, value: &TypedValue) -> Result<Vec<u16>, EncodeError> {
        let bytes: Vec<u8> = match self {
            Self::Int16 => (self.integer(value, i16::MIN.into(), i16::MAX.into())? as i16)
                .to_be_bytes()
                .to_vec(),
            Self::Uint16 => (self.integer(value, 0, u16::MAX.into())? as u16)
                .to_be_bytes()
                .to_vec(),
            Self::Int32 => (self.integer(value, i32::MIN.into(), i32::MAX.into())? as i32)
                .to_be_bytes()
                .to_vec(),
            Self::Uint32 => (self.integer(value, 0, u32::MAX.into())? as u32)
                .to_be_bytes()
                .to_vec(),
            Self::Int64 => (self.integer(value, i64::MIN.into(), i64::MAX.into())? as i64)
                .to_be_bytes()
                .to_vec(),
            Self::Uint64 => (self.integer(value, 0, u64::MAX.into())? as u64)
                .to_be_bytes()
                .to_vec(),
            Self::Float32 => {
                let float = self.float(value)?;
                if float.abs() > f64::from(f32::MAX) {
                    return Err(self.out_of_range(
                        value,
                        format_args!("{:e}", f32::MIN),
                        format_args!("{:e}", f32::MAX),
                    ));
                }
                let narrow = float as f32;
                if narrow == 0.0 && float != 0.0 {
                    return Err(EncodeError::TooSmall {
                        value: float,
                        data_type: self,
                    });
                }
                narrow.to_be_bytes().to_vec()
            }
            Self::Float64 => self.float(value)?.to_be_bytes().to_vec(),
            Self::String(length) => encode_text(self, length, value)?,
            Self::Bit(index) => return Err(EncodeError::BitNeedsItsRegister { index }),
        };
        Ok(order.registers_of(&bytes, self.is_string()))
    }

    /// The value `text` stands for in this type: a number (decimal, `0x` hex for
    /// integers, a decimal fraction or exponent for floats and scaled integers), the text
    /// itself for a string, `0`/`1`/`true`/`false`/`on`/`off` for a bit. Whether the
    /// number fits is [`encode`](Self::encode)'s business.
    pub fn parse_value(self, text: &str) -> Result<TypedValue, EncodeError> {
        let bad = || EncodeError::NotAValue {
            text: text.to_owned(),
            data_type: self,
        };
        match self {
            Self::String(_) => Ok(TypedValue::Text(text.to_owned())),
            Self::Bit(_) => match text.to_ascii_lowercase().as_str() {
                "1" | "true" | "on" => Ok(TypedValue::Bool(true)),
                "0" | "false" | "off" => Ok(TypedValue::Bool(false)),
                _ => Err(bad()),
            },
            _ => parse_number(text).ok_or_else(bad),
        }
    }

    const fn is_string(self) -> bool {
        matches!(self, Self::String(_))
    }

    /// `value` as a whole number within `min..=max`.
    fn integer(self, value: &TypedValue, min: i128, max: i128) -> Result<i128, EncodeError> {
        let whole = match *value {
            TypedValue::Int(i) => i128::from(i),
            TypedValue::Uint(u) => i128::from(u),
            TypedValue::Float(f) => {
                if !f.is_finite() {
                    return Err(EncodeError::NotFinite {
                        value: f,
                        data_type: self,
                    });
                }
                let rounded = f.round();
                // Decimal scales (0.1, 0.01) are not exact in binary: 22.9 / 0.1 is
                // 228.99999999999997. Within a billionth it is the whole number meant.
                if (f - rounded).abs() > WHOLE_TOLERANCE * rounded.abs().max(1.0) {
                    return Err(EncodeError::NotWhole {
                        value: f,
                        data_type: self,
                    });
                }
                // Beyond i128 (about 1.7e38) is out of every range anyway.
                if rounded.abs() >= 1.0e38 {
                    return Err(self.out_of_range(value, min, max));
                }
                rounded as i128
            }
            TypedValue::Text(_) | TypedValue::Bool(_) => return Err(self.wrong_kind(value)),
        };
        if (min..=max).contains(&whole) {
            Ok(whole)
        } else {
            Err(self.out_of_range(value, min, max))
        }
    }

    /// `value` as a finite float.
    fn float(self, value: &TypedValue) -> Result<f64, EncodeError> {
        let float = match *value {
            TypedValue::Int(i) => i as f64,
            TypedValue::Uint(u) => u as f64,
            TypedValue::Float(f) => f,
            TypedValue::Text(_) | TypedValue::Bool(_) => return Err(self.wrong_kind(value)),
        };
        if float.is_finite() {
            Ok(float)
        } else {
            Err(EncodeError::NotFinite {
                value: float,
                data_type: self,
            })
        }
    }

    fn out_of_range(
        self,
        value: &TypedValue,
        min: impl fmt::Display,
        max: impl fmt::Display,
    ) -> EncodeError {
        EncodeError::OutOfRange {
            value: value.to_string(),
            data_type: self,
            min: min.to_string(),
            max: max.to_string(),
        }
    }

    fn wrong_kind(self, value: &TypedValue) -> EncodeError {
        EncodeError::WrongKind {
            value: value.to_string(),
            data_type: self,
        }
    }
}

impl fmt::Display for DataType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Int16 => f.write_str("int16"),
            Self::Uint16 => f.write_str("uint16"),
            Self::Int32 => f.write_str("int32"),
            Self::Uint32 => f.write_str("uint32"),
            Self::Int64 => f.write_str("int64"),
            Self::Uint64 => f.write_str("uint64"),
            Self::Float32 => f.write_str("float32"),
            Self::Float64 => f.write_str("float64"),
            Self::String(length) => write!(f, "string:{}", length.get()),
            Self::Bit(index) => write!(f, "bit:{}", index.get()),
        }
    }
}

impl FromStr for DataType {
    type Err = ParseTypeError;

    /// `int16` … `float64`, `string:N` (N registers, 1–125) or `bit:N` (0–15), in any case.
    fn from_str(text: &str) -> Result<Self, ParseTypeError> {
        let lower = text.trim().to_ascii_lowercase();
        let (name, argument) = match lower.split_once(':') {
            Some((name, argument)) => (name, Some(argument)),
            None => (lower.as_str(), None),
        };
        let unknown = || ParseTypeError::UnknownType {
            text: text.to_owned(),
        };
        let number = |argument: Option<&str>| -> Result<u32, ParseTypeError> {
            let argument = argument.ok_or_else(|| ParseTypeError::MissingLength {
                text: text.to_owned(),
            })?;
            argument.parse().map_err(|_| ParseTypeError::BadNumber {
                text: text.to_owned(),
            })
        };
        let plain = match name {
            "int16" => Self::Int16,
            "uint16" => Self::Uint16,
            "int32" => Self::Int32,
            "uint32" => Self::Uint32,
            "int64" => Self::Int64,
            "uint64" => Self::Uint64,
            "float32" => Self::Float32,
            "float64" => Self::Float64,
            "string" => {
                let registers = number(argument)?;
                return u16::try_from(registers)
                    .map_err(|_| ParseTypeError::StringLength { registers })
                    .and_then(StringRegisters::new)
                    .map(Self::String);
            }
            "bit" => {
                let index = number(argument)?;
                return u8::try_from(index)
                    .map_err(|_| ParseTypeError::BitIndex { index })
                    .and_then(BitIndex::new)
                    .map(Self::Bit);
            }
            _ => return Err(unknown()),
        };
        match argument {
            None => Ok(plain),
            Some(_) => Err(unknown()),
        }
    }
}

/// The byte and word order of a value's registers (see the [module](self) documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Order {
    /// Big-endian words, big-endian bytes: the Modbus convention.
    #[default]
    Abcd,
    /// Words reversed (least significant first), bytes big-endian in each.
    Cdab,
    /// Words big-endian, the two bytes of each swapped.
    Badc,
    /// Everything reversed: little-endian bytes and words.
    Dcba,
}

impl Order {
    /// Every order.
    pub const ALL: [Self; 4] = [Self::Abcd, Self::Cdab, Self::Badc, Self::Dcba];

    /// The names [`FromStr`] takes, for messages.
    pub const CHOICES: &'static str = "ABCD, CDAB, BADC, DCBA";

    /// Whether the least significant word comes first.
    pub const fn words_reversed(self) -> bool {
        matches!(self, Self::Cdab | Self::Dcba)
    }

    /// Whether each register carries its low byte first.
    pub const fn bytes_swapped(self) -> bool {
        matches!(self, Self::Badc | Self::Dcba)
    }

    /// The value's bytes, most significant first, from its registers.
    fn bytes_of(self, registers: &[u16], text: bool) -> Vec<u8> {
        self.arrange(registers.to_vec(), text)
            .iter()
            .flat_map(|word| word.to_be_bytes())
            .collect()
    }

    /// The registers that carry `bytes` (most significant first, an even number).
    fn registers_of(self, bytes: &[u8], text: bool) -> Vec<u16> {
        let words = bytes
            .chunks(2)
            .map(|pair| u16::from_be_bytes([pair[0], pair.get(1).copied().unwrap_or(0)]))
            .collect();
        self.arrange(words, text)
    }

    /// Swaps bytes and reverses words as the order says; each is its own inverse, so the
    /// same steps go both ways. Text keeps its registers in address order.
    fn arrange(self, mut words: Vec<u16>, text: bool) -> Vec<u16> {
        if self.bytes_swapped() {
            words.iter_mut().for_each(|w| *w = w.swap_bytes());
        }
        if self.words_reversed() && !text {
            words.reverse();
        }
        words
    }
}

impl fmt::Display for Order {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Abcd => "ABCD",
            Self::Cdab => "CDAB",
            Self::Badc => "BADC",
            Self::Dcba => "DCBA",
        })
    }
}

impl FromStr for Order {
    type Err = ParseTypeError;

    /// `ABCD`, `CDAB`, `BADC` or `DCBA`, in any case.
    fn from_str(text: &str) -> Result<Self, ParseTypeError> {
        Self::ALL
            .into_iter()
            .find(|order| order.to_string().eq_ignore_ascii_case(text.trim()))
            .ok_or_else(|| ParseTypeError::UnknownOrder {
                text: text.to_owned(),
            })
    }
}

/// A value read from or written to registers.
#[derive(Debug, Clone, PartialEq)]
pub enum TypedValue {
    /// A signed integer (int16, int32, int64).
    Int(i64),
    /// An unsigned integer (uint16, uint32, uint64).
    Uint(u64),
    /// A float, or a scaled integer.
    Float(f64),
    /// A string's text.
    Text(String),
    /// A bit.
    Bool(bool),
}

impl TypedValue {
    /// The value as a number, if it is one (a bit counts 0 or 1).
    pub fn as_f64(&self) -> Option<f64> {
        match *self {
            Self::Int(i) => Some(i as f64),
            Self::Uint(u) => Some(u as f64),
            Self::Float(f) => Some(f),
            Self::Bool(b) => Some(f64::from(u8::from(b))),
            Self::Text(_) => None,
        }
    }
}

impl fmt::Display for TypedValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Int(i) => write!(f, "{i}"),
            Self::Uint(u) => write!(f, "{u}"),
            Self::Float(x) => write_number(f, *x),
            Self::Text(text) => write!(f, "{text:?}"),
            Self::Bool(b) => write!(f, "{}", u8::from(*b)),
        }
    }
}

/// A number as people read it: `229.7`, and with an exponent when it is very small or very
/// large (`1.4e-45`, `3.4028235e38`), never forty zeros.
fn write_number(f: &mut fmt::Formatter<'_>, x: f64) -> fmt::Result {
    let magnitude = x.abs();
    if magnitude != 0.0 && x.is_finite() && !(1e-6..1e16).contains(&magnitude) {
        write!(f, "{x:e}")
    } else {
        write!(f, "{x}")
    }
}

/// A linear scale between a register's number and the value it stands for:
/// `value = raw * scale + offset` on a read, `raw = (value - offset) / scale` on a write.
/// Numbers only: strings and bits are never scaled.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scaling {
    scale: f64,
    offset: f64,
}

impl Default for Scaling {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Scaling {
    /// Scale 1, offset 0: values as the registers hold them.
    pub const IDENTITY: Self = Self {
        scale: 1.0,
        offset: 0.0,
    };

    /// A scale (finite, not 0, so a write can be inverted) and an offset (finite).
    pub fn new(scale: f64, offset: f64) -> Result<Self, ScalingError> {
        if !scale.is_finite() || scale == 0.0 {
            return Err(ScalingError::Scale { scale });
        }
        if !offset.is_finite() {
            return Err(ScalingError::Offset { offset });
        }
        Ok(Self { scale, offset })
    }

    /// The scale.
    pub const fn scale(self) -> f64 {
        self.scale
    }

    /// The offset.
    pub const fn offset(self) -> f64 {
        self.offset
    }

    /// Whether values pass unchanged.
    pub fn is_identity(self) -> bool {
        self == Self::IDENTITY
    }

    /// The value a raw number stands for; integers stay exact under the identity.
    pub fn apply(self, raw: TypedValue) -> TypedValue {
        match (&raw, raw.as_f64()) {
            (TypedValue::Int(_) | TypedValue::Uint(_) | TypedValue::Float(_), Some(number))
                if !self.is_identity() =>
            {
                TypedValue::Float(number * self.scale + self.offset)
            }
            _ => raw,
        }
    }

    /// The raw number that stands for `value`.
    pub fn invert(self, value: TypedValue) -> TypedValue {
        match (&value, value.as_f64()) {
            (TypedValue::Int(_) | TypedValue::Uint(_) | TypedValue::Float(_), Some(number))
                if !self.is_identity() =>
            {
                TypedValue::Float((number - self.offset) / self.scale)
            }
            _ => value,
        }
    }
}

/// Everything needed to read and write one value: type, order and scale.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Format {
    /// The type.
    pub data_type: DataType,
    /// The byte and word order.
    pub order: Order,
    /// The scale, for numbers.
    pub scaling: Scaling,
}

impl Default for DataType {
    /// A plain register: `uint16`.
    fn default() -> Self {
        Self::Uint16
    }
}

impl Format {
    /// `data_type` in `order`, unscaled.
    pub const fn new(data_type: DataType, order: Order) -> Self {
        Self {
            data_type,
            order,
            scaling: Scaling::IDENTITY,
        }
    }

    /// The same format with `scaling`.
    pub const fn scaled(mut self, scaling: Scaling) -> Self {
        self.scaling = scaling;
        self
    }

    /// How many registers one value takes.
    pub const fn registers(&self) -> u16 {
        self.data_type.registers()
    }

    /// The value that `registers` hold, scaled.
    pub fn decode(&self, registers: &[u16]) -> Result<TypedValue, DecodeError> {
        let raw = self.data_type.decode(self.order, registers)?;
        Ok(if self.data_type.is_number() {
            self.scaling.apply(raw)
        } else {
            raw
        })
    }

    /// The registers that hold `value`, with the scale inverted first; refuses what the
    /// type cannot hold after inverting (see [`DataType::encode`]).
    pub fn encode(&self, value: &TypedValue) -> Result<Vec<u16>, EncodeError> {
        let raw = if self.data_type.is_number() {
            self.scaling.invert(value.clone())
        } else {
            value.clone()
        };
        self.data_type
            .encode(self.order, &raw)
            .map_err(|e| e.about(value))
    }

    /// The registers for a value written as text ([`DataType::parse_value`]).
    pub fn encode_text(&self, text: &str) -> Result<Vec<u16>, EncodeError> {
        self.encode(&self.data_type.parse_value(text)?)
    }
}

/// A type or order name that is not one.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ParseTypeError {
    /// Not a type's name.
    #[error("`{text}` is not a data type: choose one of {}", DataType::CHOICES)]
    UnknownType {
        /// The text given.
        text: String,
    },
    /// `string` or `bit` without its number.
    #[error("`{text}` needs its number: string:N (N registers, 1-125) or bit:N (0-15)")]
    MissingLength {
        /// The text given.
        text: String,
    },
    /// The number after `string:` or `bit:` does not parse.
    #[error("`{text}` has no number after the colon: string:N (1-125) or bit:N (0-15)")]
    BadNumber {
        /// The text given.
        text: String,
    },
    /// A string length outside 1–125 registers.
    #[error("a string of {registers} registers is not possible: 1 to 125 registers")]
    StringLength {
        /// The length given.
        registers: u32,
    },
    /// A bit index outside 0–15.
    #[error("bit {index} is not a bit of a register: 0 to 15")]
    BitIndex {
        /// The index given.
        index: u32,
    },
    /// Not an order's name.
    #[error("`{text}` is not a byte order: choose one of {}", Order::CHOICES)]
    UnknownOrder {
        /// The text given.
        text: String,
    },
}

/// Registers that do not hold a value of the type.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum DecodeError {
    /// Not as many registers as the type takes.
    #[error("{data_type} takes {expected} registers, {actual} given")]
    WrongLength {
        /// The type.
        data_type: DataType,
        /// The registers it takes.
        expected: u16,
        /// The registers given.
        actual: usize,
    },
    /// A byte of a string outside ASCII.
    #[error("{data_type}: byte 0x{byte:02X} at character {position} is not ASCII")]
    NotAscii {
        /// The type.
        data_type: DataType,
        /// The byte.
        byte: u8,
        /// Its place in the text, from 0.
        position: usize,
    },
}

/// A value that the type cannot hold.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum EncodeError {
    /// A number outside the type's range.
    #[error("{value} does not fit {data_type} ({min} to {max})")]
    OutOfRange {
        /// The value (as given, before the scale was inverted).
        value: String,
        /// The type.
        data_type: DataType,
        /// The smallest the type holds.
        min: String,
        /// The largest the type holds.
        max: String,
    },
    /// A number so close to zero that the type would hold 0 instead.
    #[error(
        "{value:e} is too small for {data_type}: it would be written as 0 (the smallest \
         number it holds above 0 is about 1.4e-45)"
    )]
    TooSmall {
        /// The number.
        value: f64,
        /// The type.
        data_type: DataType,
    },
    /// A fraction for an integer type.
    #[error("{value} is not a whole number, which {data_type} needs")]
    NotWhole {
        /// The number, after the scale was inverted.
        value: f64,
        /// The type.
        data_type: DataType,
    },
    /// NaN or an infinity.
    #[error("{value} is not a finite number, which {data_type} needs")]
    NotFinite {
        /// The number.
        value: f64,
        /// The type.
        data_type: DataType,
    },
    /// Text for a number or a number for text.
    #[error("{value} is not a value of type {data_type}")]
    WrongKind {
        /// The value.
        value: String,
        /// The type.
        data_type: DataType,
    },
    /// Text that does not parse as a value of the type.
    #[error("`{text}` is not a value of type {data_type}")]
    NotAValue {
        /// The text.
        text: String,
        /// The type.
        data_type: DataType,
    },
    /// A string longer than its registers hold.
    #[error("{text:?} has {length} characters, {data_type} holds at most {max}")]
    TooLong {
        /// The text.
        text: String,
        /// Its length in characters.
        length: usize,
        /// The type.
        data_type: DataType,
        /// The most characters it holds.
        max: usize,
    },
    /// A string with a character outside ASCII, or a NUL (which would end it).
    #[error("{text:?} has {character:?}, which {data_type} cannot hold (ASCII without NUL)")]
    NotAscii {
        /// The text.
        text: String,
        /// The first character that is not allowed.
        character: char,
        /// The type.
        data_type: DataType,
    },
    /// A bit alone cannot be written as a register.
    #[error(
        "bit {} is one bit of a register: read the register, set the bit (BitIndex::set) and write the register",
        index.get()
    )]
    BitNeedsItsRegister {
        /// The bit.
        index: BitIndex,
    },
}

impl EncodeError {
    /// The error naming the value as given (before the scale was inverted).
    fn about(self, given: &TypedValue) -> Self {
        match self {
            Self::OutOfRange {
                data_type,
                min,
                max,
                ..
            } => Self::OutOfRange {
                value: given.to_string(),
                data_type,
                min,
                max,
            },
            other => other,
        }
    }
}

/// A scale or offset that cannot be used.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ScalingError {
    /// A scale of 0 or not finite: a write could not be inverted.
    #[error("scale {scale} is not usable: it must be a finite number other than 0")]
    Scale {
        /// The scale given.
        scale: f64,
    },
    /// An offset that is not finite.
    #[error("offset {offset} is not usable: it must be a finite number")]
    Offset {
        /// The offset given.
        offset: f64,
    },
}

/// How far from a whole number a float may be and still be taken as it, relative to its
/// size: decimal scales are not exact in binary.
const WHOLE_TOLERANCE: f64 = 1e-9;

/// The NUL that ends a string early or pads it.
const NUL: u8 = 0;

fn first4(bytes: &[u8]) -> [u8; 4] {
    [bytes[0], bytes[1], bytes[2], bytes[3]]
}

/// A float32 as the f64 of its shortest decimal form, so 229.7 reads as 229.7 and not
/// 229.6999969482422; the f64 narrows back to the same f32.
fn widen(value: f32) -> f64 {
    if value.is_finite() {
        value.to_string().parse().unwrap_or(f64::from(value))
    } else {
        f64::from(value)
    }
}

/// The text of a string's bytes: up to the first NUL, trailing spaces dropped.
fn decode_text(data_type: DataType, bytes: &[u8]) -> Result<String, DecodeError> {
    let end = bytes.iter().position(|&b| b == NUL).unwrap_or(bytes.len());
    let text = &bytes[..end];
    if let Some(position) = text.iter().position(|b| !b.is_ascii()) {
        return Err(DecodeError::NotAscii {
            data_type,
            byte: text[position],
            position,
        });
    }
    Ok(String::from_utf8_lossy(text)
        .trim_end_matches(' ')
        .to_owned())
}

/// A string's bytes, NUL-padded to its registers.
fn encode_text(
    data_type: DataType,
    length: StringRegisters,
    value: &TypedValue,
) -> Result<Vec<u8>, EncodeError> {
    let TypedValue::Text(text) = value else {
        return Err(data_type.wrong_kind(value));
    };
    if let Some(character) = text.chars().find(|c| !c.is_ascii() || *c == '\0') {
        return Err(EncodeError::NotAscii {
            text: text.clone(),
            character,
            data_type,
        });
    }
    let max = 2 * usize::from(length.get());
    if text.len() > max {
        return Err(EncodeError::TooLong {
            text: text.clone(),
            length: text.len(),
            data_type,
            max,
        });
    }
    let mut bytes = text.as_bytes().to_vec();
    bytes.resize(max, NUL);
    Ok(bytes)
}

/// A number as typed: decimal or `0x` hex integers (with a sign), else a float.
fn parse_number(text: &str) -> Option<TypedValue> {
    let text = text.trim();
    let (negative, digits) = match text.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, text.strip_prefix('+').unwrap_or(text)),
    };
    if let Some(hex) = digits
        .strip_prefix("0x")
        .or_else(|| digits.strip_prefix("0X"))
    {
        let magnitude = u64::from_str_radix(hex, 16).ok()?;
        return Some(signed(negative, magnitude));
    }
    if !digits.is_empty()
        && digits.bytes().all(|b| b.is_ascii_digit())
        && let Ok(magnitude) = digits.parse::<u64>()
    {
        return Some(signed(negative, magnitude));
    }
    // "inf" and "nan" parse as floats but are not numbers a register can be told.
    let float: f64 = text.parse().ok()?;
    float.is_finite().then_some(TypedValue::Float(float))
}

fn signed(negative: bool, magnitude: u64) -> TypedValue {
    if !negative {
        return TypedValue::Uint(magnitude);
    }
    match i64::try_from(i128::from(magnitude).wrapping_neg()) {
        Ok(value) => TypedValue::Int(value),
        Err(_) => TypedValue::Float(-(magnitude as f64)),
    }
}

#[cfg(test)]
mod tests;
