//! The byte layout of a JBC station–robot frame.
//!
//! ```text
//! without address:  STX  hdr code3 [data5] ETX BCC         7 or 12 bytes
//! with address:     STX src2 dst2 hdr code3 [data5] ETX BCC  11 or 16 bytes (factory default)
//! ```
//!
//! Everything between `STX` and `ETX` is ASCII; the block check character (BCC) is the XOR
//! of every byte before it, `STX` and `ETX` included. The [`FrameCodec`] decodes both forms
//! (their lengths never collide) and encodes whichever the [`Frame`] carries; whether a
//! given form is *welcome* is the station's or the client's business, not the codec's.
//!
//! Values that cannot be invalid: an [`Address`] is 00–99, a [`RawCode`] is three printable
//! ASCII characters, a [`Data`] field five printable ASCII characters. A frame whose code is
//! not a known command still decodes (as a [`RawCode`]), so a station can answer it with
//! NAK 4 instead of a format error.

use std::fmt;
use std::str::FromStr;

use wire::checksum::xor_bcc;
use wire::scan::{Delimited, Scan};
use wire::{Codec, Resync};

use crate::code::NakReason;

/// Start of a frame (ASCII STX).
pub const STX: u8 = 0x02;
/// End of a frame's body (ASCII ETX); the BCC follows it.
pub const ETX: u8 = 0x03;

/// Length of a frame without address fields and without data.
pub const LEN_SHORT: usize = 7;
/// Length of a frame without address fields, with data.
pub const LEN_SHORT_DATA: usize = 12;
/// Length of a frame with address fields, without data.
pub const LEN_ADDRESSED: usize = 11;
/// Length of a frame with address fields and data (the longest frame).
pub const LEN_ADDRESSED_DATA: usize = 16;
/// The longest frame on the line.
pub const MAX_LEN: usize = LEN_ADDRESSED_DATA;

/// Width of the data field.
pub const DATA_LEN: usize = 5;
/// Width of the control code.
pub const CODE_LEN: usize = 3;

/// The lowest number a data field carries (`-9999`).
pub const DATA_MIN: i32 = -9999;
/// The highest number a data field carries (`99999`).
pub const DATA_MAX: i32 = 99999;

/// How the scanner finds frames on the line: `STX … ETX` plus one check byte.
const FRAMING: Delimited = Delimited {
    start: STX,
    end: ETX,
    trailer: 1,
    max_len: MAX_LEN,
};

/// Offsets inside a frame. `at` is where the header is: 1 without address, 5 with.
mod field {
    use core::ops::Range;

    pub const SOURCE: Range<usize> = 1..3;
    pub const TARGET: Range<usize> = 3..5;
    pub const HEADER_SHORT: usize = 1;
    pub const HEADER_ADDRESSED: usize = 5;
    pub const fn code(at: usize) -> Range<usize> {
        at + 1..at + 4
    }
    pub const fn data(at: usize) -> Range<usize> {
        at + 4..at + 9
    }
}

// ---------------------------------------------------------------------------------------
// Address and route

/// A station or robot address on the line, `00` to `99`.
///
/// Factory settings: the robot is [`Address::ROBOT`] (`00`), a soldering station
/// [`Address::STATION`] (`01`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Address(u8);

/// An address that is not `00`–`99`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AddressError {
    /// A number above the highest address.
    #[error("address {value} is out of range: JBC addresses are 00 to {max}")]
    OutOfRange {
        /// The number given.
        value: u64,
        /// The highest address (99).
        max: u8,
    },
    /// Text that is not a decimal number.
    #[error("{text:?} is not an address: write a number from 00 to 99")]
    NotANumber {
        /// The text given.
        text: String,
    },
}

impl Address {
    /// The highest address.
    pub const MAX: u8 = 99;
    /// The robot's factory address (`00`).
    pub const ROBOT: Address = Address(0);
    /// A soldering station's factory address (`01`).
    pub const STATION: Address = Address(1);

    /// An address, if `value` is 0–99.
    pub fn new(value: u8) -> Result<Address, AddressError> {
        if value > Self::MAX {
            return Err(AddressError::OutOfRange {
                value: value.into(),
                max: Self::MAX,
            });
        }
        Ok(Address(value))
    }

    /// The address as a number.
    pub fn get(self) -> u8 {
        self.0
    }

    /// The two ASCII digits on the wire.
    pub fn to_ascii(self) -> [u8; 2] {
        [b'0' + self.0 / 10, b'0' + self.0 % 10]
    }

    /// Reads two ASCII digits from the wire.
    pub fn from_ascii(digits: [u8; 2]) -> Option<Address> {
        let [tens, units] = digits;
        if !tens.is_ascii_digit() || !units.is_ascii_digit() {
            return None;
        }
        Some(Address((tens - b'0') * 10 + (units - b'0')))
    }
}

impl FromStr for Address {
    type Err = AddressError;

    /// Accepts `1`, `01`, `99` (decimal digits, leading zeros allowed).
    fn from_str(text: &str) -> Result<Address, AddressError> {
        let not_a_number = || AddressError::NotANumber {
            text: text.to_owned(),
        };
        if text.is_empty() || !text.bytes().all(|b| b.is_ascii_digit()) {
            return Err(not_a_number());
        }
        let value: u64 = text.parse().map_err(|_| AddressError::OutOfRange {
            value: u64::MAX,
            max: Self::MAX,
        })?;
        match u8::try_from(value) {
            Ok(v) if v <= Self::MAX => Ok(Address(v)),
            _ => Err(AddressError::OutOfRange {
                value,
                max: Self::MAX,
            }),
        }
    }
}

impl fmt::Display for Address {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:02}", self.0)
    }
}

/// Who sent a frame and for whom it is, in the addressed form.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Route {
    /// The sender.
    pub source: Address,
    /// The receiver.
    pub target: Address,
}

impl Route {
    /// The route of the answer to a frame on this route (target and source swapped).
    pub fn reversed(self) -> Route {
        Route {
            source: self.target,
            target: self.source,
        }
    }
}

impl fmt::Display for Route {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}→{}", self.source, self.target)
    }
}

// ---------------------------------------------------------------------------------------
// Header, code, data

/// The control header: what kind of frame this is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Header {
    /// `R`: the robot reads a value; no data.
    Read,
    /// `W`: the robot writes a value; data.
    Write,
    /// `A`: the station accepts; data when answering a read, none when answering a write.
    Ack,
    /// `N`: the station refuses; data = the communication-error number.
    Nak,
}

impl Header {
    /// The ASCII character on the wire.
    pub fn as_byte(self) -> u8 {
        match self {
            Header::Read => b'R',
            Header::Write => b'W',
            Header::Ack => b'A',
            Header::Nak => b'N',
        }
    }

    /// The header for a wire character.
    pub fn from_byte(byte: u8) -> Option<Header> {
        match byte {
            b'R' => Some(Header::Read),
            b'W' => Some(Header::Write),
            b'A' => Some(Header::Ack),
            b'N' => Some(Header::Nak),
            _ => None,
        }
    }
}

impl fmt::Display for Header {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", char::from(self.as_byte()))
    }
}

/// Whether a byte may appear in a code or data field (printable ASCII, blank included).
fn is_printable(byte: u8) -> bool {
    (0x20..=0x7e).contains(&byte)
}

/// Bytes that cannot be a code or a data field.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FieldError {
    /// A byte that is not printable ASCII.
    #[error("{what} {text:?} holds byte 0x{byte:02X}, which is not printable ASCII")]
    NotPrintable {
        /// Which field.
        what: &'static str,
        /// The field, lossily shown.
        text: String,
        /// The first offending byte.
        byte: u8,
    },
    /// Text of the wrong length.
    #[error("{what} {text:?} has {len} characters; it takes {min} to {max}")]
    Length {
        /// Which field.
        what: &'static str,
        /// The text given.
        text: String,
        /// Its length in bytes.
        len: usize,
        /// Fewest characters.
        min: usize,
        /// Most characters.
        max: usize,
    },
    /// A number that does not fit the five-character data field.
    #[error("{value} does not fit the data field: numbers are {min} to {max}")]
    NumberOutOfRange {
        /// The number given.
        value: i64,
        /// Lowest number ([`DATA_MIN`]).
        min: i32,
        /// Highest number ([`DATA_MAX`]).
        max: i32,
    },
}

fn check_printable(what: &'static str, bytes: &[u8]) -> Result<(), FieldError> {
    match bytes.iter().find(|b| !is_printable(**b)) {
        Some(&byte) => Err(FieldError::NotPrintable {
            what,
            text: String::from_utf8_lossy(bytes).into_owned(),
            byte,
        }),
        None => Ok(()),
    }
}

/// The three characters of a control code as they are on the wire, known or not
/// (`ST1`, `A11`, `SMN`, or `XYZ`). [`crate::code::Code`] is the typed view.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct RawCode([u8; CODE_LEN]);

impl RawCode {
    /// A code from three printable ASCII bytes.
    pub fn new(bytes: [u8; CODE_LEN]) -> Result<RawCode, FieldError> {
        check_printable("control code", &bytes)?;
        Ok(RawCode(bytes))
    }

    /// The three bytes.
    pub fn as_bytes(&self) -> &[u8; CODE_LEN] {
        &self.0
    }
}

impl FromStr for RawCode {
    type Err = FieldError;

    /// Exactly three printable ASCII characters, taken as they are (no case folding).
    fn from_str(text: &str) -> Result<RawCode, FieldError> {
        let bytes: [u8; CODE_LEN] = text.as_bytes().try_into().map_err(|_| FieldError::Length {
            what: "control code",
            text: text.to_owned(),
            len: text.len(),
            min: CODE_LEN,
            max: CODE_LEN,
        })?;
        RawCode::new(bytes)
    }
}

impl fmt::Display for RawCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write_ascii(f, &self.0)
    }
}

/// The five-character data field: a zero-padded number (`00375`, `-0050`) or text
/// right-aligned with blanks on the left (`" JTSE"`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Data([u8; DATA_LEN]);

impl Data {
    /// Zero.
    pub const ZERO: Data = Data(*b"00000");

    /// A number, zero padded, a negative sign in the first position (`-50` is `-0050`).
    pub fn number(value: i32) -> Result<Data, FieldError> {
        if !(DATA_MIN..=DATA_MAX).contains(&value) {
            return Err(FieldError::NumberOutOfRange {
                value: value.into(),
                min: DATA_MIN,
                max: DATA_MAX,
            });
        }
        let mut out = Vec::with_capacity(DATA_LEN);
        wire::ascii::write_signed(value, DATA_LEN, &mut out).map_err(|_| {
            FieldError::NumberOutOfRange {
                value: value.into(),
                min: DATA_MIN,
                max: DATA_MAX,
            }
        })?;
        let bytes: [u8; DATA_LEN] = out
            .try_into()
            .expect("write_signed writes exactly DATA_LEN bytes on success");
        Ok(Data(bytes))
    }

    /// Text of up to five printable ASCII characters, right-aligned with blanks on the left,
    /// as the station sends its model name (`"JTSE"` becomes `" JTSE"`).
    pub fn text(text: &str) -> Result<Data, FieldError> {
        let bytes = text.as_bytes();
        if bytes.len() > DATA_LEN {
            return Err(FieldError::Length {
                what: "data field",
                text: text.to_owned(),
                len: bytes.len(),
                min: 0,
                max: DATA_LEN,
            });
        }
        check_printable("data field", bytes)?;
        let mut field = [b' '; DATA_LEN];
        field[DATA_LEN - bytes.len()..].copy_from_slice(bytes);
        Ok(Data(field))
    }

    /// The field as it came off the wire, if every byte is printable ASCII.
    pub fn from_bytes(bytes: [u8; DATA_LEN]) -> Result<Data, FieldError> {
        check_printable("data field", &bytes)?;
        Ok(Data(bytes))
    }

    /// The number in the field, if it holds one (`00375` → 375, `-0050` → −50).
    pub fn as_number(&self) -> Option<i32> {
        wire::ascii::parse_signed(&self.0)
    }

    /// The field as text, blanks around it removed (`" JTSE"` → `"JTSE"`).
    pub fn as_text(&self) -> String {
        // Printable ASCII by construction.
        String::from_utf8_lossy(&self.0).trim().to_owned()
    }

    /// The five bytes.
    pub fn as_bytes(&self) -> &[u8; DATA_LEN] {
        &self.0
    }
}

impl fmt::Display for Data {
    /// The five characters as they are on the wire, blanks kept.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write_ascii(f, &self.0)
    }
}

/// Writes bytes that are printable ASCII (by construction: a code or a data field), each
/// byte one char.
fn write_ascii(f: &mut fmt::Formatter<'_>, bytes: &[u8]) -> fmt::Result {
    bytes
        .iter()
        .try_for_each(|&b| write!(f, "{}", char::from(b)))
}

// ---------------------------------------------------------------------------------------
// Frame

/// One frame, either form, any header.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Frame {
    /// Source and target, in the addressed form; `None` in the form without address.
    pub route: Option<Route>,
    /// What kind of frame.
    pub header: Header,
    /// The control code.
    pub code: RawCode,
    /// The data field, when the frame carries one.
    pub data: Option<Data>,
}

impl Frame {
    /// The frame's length on the wire.
    pub fn wire_len(&self) -> usize {
        match (self.route.is_some(), self.data.is_some()) {
            (false, false) => LEN_SHORT,
            (false, true) => LEN_SHORT_DATA,
            (true, false) => LEN_ADDRESSED,
            (true, true) => LEN_ADDRESSED_DATA,
        }
    }

    /// The frame's bytes on the wire.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.wire_len());
        FrameCodec.encode(self, &mut out);
        out
    }
}

impl fmt::Display for Frame {
    /// `01→00 A ST1 [00350]`, or `A ST1 [00350]` without address.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(route) = self.route {
            write!(f, "{route} ")?;
        }
        write!(f, "{} {}", self.header, self.code)?;
        if let Some(data) = self.data {
            write!(f, " [{data}]")?;
        }
        Ok(())
    }
}

/// What could still be read from a damaged frame: enough for a station to address its NAK
/// and echo the code. `None` where the bytes at that place are not plausible.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameHead {
    /// The route, when the frame looks addressed and its address digits are intact.
    pub route: Option<Route>,
    /// The code, when the bytes at its place are printable.
    pub code: RawCode,
}

/// Why the front of a buffer is not a frame. Every variant says how many bytes to drop
/// (`len`) before decoding again; variants for a delimited but damaged frame also carry
/// what could be salvaged from it ([`FrameHead`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum DecodeError {
    /// Bytes before the next `STX`: noise on the line.
    #[error("{} of line noise before the next frame start (STX)", wire::words::Bytes(*len))]
    Garbage {
        /// Bytes dropped.
        len: usize,
    },
    /// A frame start with no end: a new `STX` came first, or no `ETX` within the longest frame.
    #[error(
        "a frame broke off after {len} bytes (no ETX before the next STX or within {MAX_LEN} bytes)"
    )]
    Unterminated {
        /// Bytes dropped.
        len: usize,
    },
    /// The block check character does not match the frame: bytes were damaged on the line.
    #[error(
        "BCC check failed: the frame's bytes XOR to 0x{expected:02X} but it carries 0x{actual:02X} ({len} bytes dropped)"
    )]
    Bcc {
        /// The BCC computed over the frame.
        expected: u8,
        /// The BCC the frame carries.
        actual: u8,
        /// Bytes dropped.
        len: usize,
        /// Route and code, if they can still be read.
        head: Option<FrameHead>,
    },
    /// A delimited frame whose length is none of 7, 11, 12, 16.
    #[error("a frame of {len} bytes: JBC frames are 7 or 12 bytes without address, 11 or 16 with")]
    Length {
        /// The frame's length, all dropped.
        len: usize,
        /// Route and code, if they can still be read.
        head: Option<FrameHead>,
    },
    /// The control header is not `R`, `W`, `A` or `N`.
    #[error("control header 0x{byte:02X} is not R, W, A or N ({len} bytes dropped)")]
    Header {
        /// The header byte.
        byte: u8,
        /// Bytes dropped.
        len: usize,
        /// Route and code, if they can still be read.
        head: Option<FrameHead>,
    },
    /// The address fields are not two decimal digits each.
    #[error("address fields {text:?} are not two digits each ({len} bytes dropped)")]
    Address {
        /// The four address bytes, lossily shown.
        text: String,
        /// Bytes dropped.
        len: usize,
        /// Route and code, if they can still be read.
        head: Option<FrameHead>,
    },
    /// The control code holds a byte that is not printable ASCII.
    #[error(
        "control code holds byte 0x{byte:02X}, which is not printable ASCII ({len} bytes dropped)"
    )]
    Code {
        /// The first offending byte.
        byte: u8,
        /// Bytes dropped.
        len: usize,
    },
    /// The data field holds a byte that is not printable ASCII.
    #[error(
        "data field holds byte 0x{byte:02X}, which is not printable ASCII ({len} bytes dropped)"
    )]
    Data {
        /// The first offending byte.
        byte: u8,
        /// Bytes dropped.
        len: usize,
        /// Route and code, if they can still be read.
        head: Option<FrameHead>,
    },
}

impl DecodeError {
    /// What could be salvaged from the damaged frame, for a station's NAK.
    pub fn head(&self) -> Option<&FrameHead> {
        match self {
            DecodeError::Bcc { head, .. }
            | DecodeError::Length { head, .. }
            | DecodeError::Header { head, .. }
            | DecodeError::Address { head, .. }
            | DecodeError::Data { head, .. } => head.as_ref(),
            DecodeError::Garbage { .. }
            | DecodeError::Unterminated { .. }
            | DecodeError::Code { .. } => None,
        }
    }

    /// Whether the bytes were a delimited frame (`STX … ETX BCC`) at all, as opposed to
    /// noise or a broken-off start.
    pub fn is_damaged_frame(&self) -> bool {
        !matches!(
            self,
            DecodeError::Garbage { .. } | DecodeError::Unterminated { .. }
        )
    }
}

impl Resync for DecodeError {
    fn drop_len(&self) -> usize {
        match *self {
            DecodeError::Garbage { len }
            | DecodeError::Unterminated { len }
            | DecodeError::Bcc { len, .. }
            | DecodeError::Length { len, .. }
            | DecodeError::Header { len, .. }
            | DecodeError::Address { len, .. }
            | DecodeError::Code { len, .. }
            | DecodeError::Data { len, .. } => len.max(1),
        }
    }
}

impl From<&DecodeError> for NakReason {
    /// The communication error a station answers a damaged frame with: a failed check is a
    /// BCC error (1), everything else a format error (2).
    fn from(error: &DecodeError) -> NakReason {
        match error {
            DecodeError::Bcc { .. } => NakReason::Bcc,
            _ => NakReason::Format,
        }
    }
}

/// The JBC frame layer: decodes both forms, encodes the form a [`Frame`] carries.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FrameCodec;

impl Codec for FrameCodec {
    type Frame = Frame;
    type Error = DecodeError;

    fn decode(&self, buf: &[u8]) -> Result<Option<(Frame, usize)>, DecodeError> {
        match FRAMING.scan(buf) {
            Scan::NeedMore => Ok(None),
            Scan::Garbage { len } => Err(DecodeError::Garbage { len }),
            Scan::Unterminated { len } => Err(DecodeError::Unterminated { len }),
            Scan::Frame { len } => match buf.get(..len) {
                Some(frame) => parse(frame).map(|f| Some((f, len))),
                // The scanner only reports frames it holds; waiting is the safe answer.
                None => Ok(None),
            },
        }
    }

    fn encode(&self, frame: &Frame, out: &mut Vec<u8>) {
        let start = out.len();
        out.push(STX);
        if let Some(route) = frame.route {
            out.extend_from_slice(&route.source.to_ascii());
            out.extend_from_slice(&route.target.to_ascii());
        }
        out.push(frame.header.as_byte());
        out.extend_from_slice(frame.code.as_bytes());
        if let Some(data) = frame.data {
            out.extend_from_slice(data.as_bytes());
        }
        out.push(ETX);
        let bcc = xor_bcc(&out[start..]);
        out.push(bcc);
    }
}

/// Parses one delimited frame (`STX … ETX BCC`, as the scanner found it).
fn parse(frame: &[u8]) -> Result<Frame, DecodeError> {
    let len = frame.len();
    let Some((&actual, checked)) = frame.split_last() else {
        return Err(DecodeError::Length {
            len: len.max(1),
            head: None,
        });
    };
    let expected = xor_bcc(checked);
    if expected != actual {
        // A lost check byte lets the next frame's STX stand in for it: keep that STX.
        let drop = if actual == STX && len > 1 {
            len - 1
        } else {
            len
        };
        return Err(DecodeError::Bcc {
            expected,
            actual,
            len: drop,
            head: salvage(frame),
        });
    }
    let (addressed, has_data) = match len {
        LEN_SHORT => (false, false),
        LEN_SHORT_DATA => (false, true),
        LEN_ADDRESSED => (true, false),
        LEN_ADDRESSED_DATA => (true, true),
        _ => {
            return Err(DecodeError::Length {
                len,
                head: salvage(frame),
            });
        }
    };
    let head = || salvage(frame);
    let at = if addressed {
        field::HEADER_ADDRESSED
    } else {
        field::HEADER_SHORT
    };

    let route = if addressed {
        let route = read_route(frame);
        if route.is_none() {
            let text = frame
                .get(field::SOURCE.start..field::TARGET.end)
                .unwrap_or_default();
            let text = String::from_utf8_lossy(text).into_owned();
            return Err(DecodeError::Address {
                text,
                len,
                head: head(),
            });
        }
        route
    } else {
        None
    };

    let header_byte = byte_at(frame, at);
    let header = Header::from_byte(header_byte).ok_or_else(|| DecodeError::Header {
        byte: header_byte,
        len,
        head: head(),
    })?;

    let code_bytes: [u8; CODE_LEN] = array_at(frame, field::code(at));
    let code = RawCode::new(code_bytes).map_err(|_| DecodeError::Code {
        byte: first_unprintable(&code_bytes),
        len,
    })?;

    let data = if has_data {
        let data_bytes: [u8; DATA_LEN] = array_at(frame, field::data(at));
        let data = Data::from_bytes(data_bytes).map_err(|_| DecodeError::Data {
            byte: first_unprintable(&data_bytes),
            len,
            head: head(),
        })?;
        Some(data)
    } else {
        None
    };

    Ok(Frame {
        route,
        header,
        code,
        data,
    })
}

/// Reads what a station needs to address a NAK from a damaged delimited frame: the route
/// (if the frame looks addressed) and the code. Frames of a known length are read at the
/// known places; others are read as addressed when they start with four digits.
fn salvage(frame: &[u8]) -> Option<FrameHead> {
    let body_len = frame.len().checked_sub(3)?; // STX, ETX, BCC
    let addressed = match frame.len() {
        LEN_SHORT | LEN_SHORT_DATA => false,
        LEN_ADDRESSED | LEN_ADDRESSED_DATA => true,
        _ => {
            body_len >= 8
                && frame
                    .get(1..5)
                    .is_some_and(|a| a.iter().all(u8::is_ascii_digit))
        }
    };
    let at = if addressed {
        field::HEADER_ADDRESSED
    } else {
        field::HEADER_SHORT
    };
    let code_range = field::code(at);
    // The code must lie inside the body (before ETX).
    if code_range.end > body_len + 1 {
        return None;
    }
    let code = RawCode::new(frame.get(code_range)?.try_into().ok()?).ok()?;
    let route = if addressed { read_route(frame) } else { None };
    Some(FrameHead { route, code })
}

fn read_route(frame: &[u8]) -> Option<Route> {
    let source = Address::from_ascii(frame.get(field::SOURCE)?.try_into().ok()?)?;
    let target = Address::from_ascii(frame.get(field::TARGET)?.try_into().ok()?)?;
    Some(Route { source, target })
}

/// The byte at `i`; frames reaching this have a checked length, so 0 never shows.
fn byte_at(frame: &[u8], i: usize) -> u8 {
    frame.get(i).copied().unwrap_or(0)
}

/// The bytes in `range`; frames reaching this have a checked length, so zeros never show.
fn array_at<const N: usize>(frame: &[u8], range: core::ops::Range<usize>) -> [u8; N] {
    frame
        .get(range)
        .and_then(|s| s.try_into().ok())
        .unwrap_or([0; N])
}

fn first_unprintable(bytes: &[u8]) -> u8 {
    bytes
        .iter()
        .copied()
        .find(|b| !is_printable(*b))
        .unwrap_or(0)
}

#[cfg(test)]
mod tests;
