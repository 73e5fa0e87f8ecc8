//! The byte layout of a Thermosald ISC/RS485 message.
//!
//! ```text
//! byte  0   1        2-3      4     5-6     7        8..        last
//!       %   address  message  Q/R   count   unused   data…      LF
//!           0-7, $   2 digits       2 digits (send 0) 3 digits
//!                                   99 = whole table,     per item
//!                                   else one item's index
//! ```
//!
//! Everything is ASCII (thermosald-isc-rs485.txt, "TRANSMISSION PROTOCOL"; the layout is
//! fixed by the "Thermosald ISC/RS485: decisions" in specs/README.md). A query from the
//! master carries `Q`; the regulator answers with the same address, message number and
//! count, and `R`.
//!
//! Decoding is strict about the fields and lenient about the unused byte (any value is
//! accepted, `0` is sent). Data are digits only, so neither `%` nor `LF` can occur inside a
//! message: [`wire::scan::Delimited`] finds every message, and a broken one is dropped
//! whole without losing the message after it.

use std::fmt;

use wire::scan::{Delimited, Scan};

/// The first byte of every message.
pub const START: u8 = b'%';
/// The last byte of every message (ASCII line feed).
pub const END: u8 = b'\n';
/// The address character of an address-assignment message: every regulator that hears it
/// takes the address carried in data item 0.
pub const ASSIGN: u8 = b'$';
/// The type character of a question from the master.
pub const QUERY: u8 = b'Q';
/// The type character of a response from a regulator.
pub const REPLY: u8 = b'R';
/// The count that selects a whole table.
pub const WHOLE_TABLE: u8 = 99;
/// What the master sends in the unused byte.
pub const UNUSED: u8 = b'0';
/// Characters per data item.
pub const ITEM_WIDTH: usize = 3;
/// The largest data item value (three decimal digits).
pub const MAX_RAW: u16 = 999;
/// The most data items a message carries: the machine data table, items 0–24.
pub const MAX_DATA_ITEMS: usize = 25;
/// Bytes before the first data item: `%`, address, message number, type, count, unused.
pub const HEADER_LEN: usize = 8;
/// The shortest message: a header and `LF`, no data.
pub const MIN_LEN: usize = HEADER_LEN + 1;
/// The longest message: a header, the whole machine table and `LF` (84 bytes).
pub const MAX_LEN: usize = HEADER_LEN + MAX_DATA_ITEMS * ITEM_WIDTH + 1;

/// How messages are delimited on the line.
pub const SCANNER: Delimited = Delimited {
    start: START,
    end: END,
    trailer: 0,
    max_len: MAX_LEN,
};

/// Byte offsets of the header fields (smoltcp style: named ranges, not magic numbers).
mod field {
    use core::ops::Range;
    pub const ADDRESS: usize = 1;
    pub const MESSAGE: Range<usize> = 2..4;
    pub const DIRECTION: usize = 4;
    pub const COUNT: Range<usize> = 5..7;
    pub const DATA_START: usize = super::HEADER_LEN;
}

/// A regulator's logic address, 0–7.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Address(u8);

impl Address {
    /// The lowest address.
    pub const MIN: u8 = 0;
    /// The highest address.
    pub const MAX: u8 = 7;

    /// An address, refused outside 0–7.
    pub const fn new(value: u8) -> Result<Self, AddressError> {
        if value <= Self::MAX {
            Ok(Self(value))
        } else {
            Err(AddressError::OutOfRange {
                value: value as u32,
                min: Self::MIN,
                max: Self::MAX,
            })
        }
    }

    /// The address as a number.
    pub const fn get(self) -> u8 {
        self.0
    }

    /// Every address, 0 to 7.
    pub fn all() -> impl Iterator<Item = Address> {
        (Self::MIN..=Self::MAX).map(Self)
    }

    /// The ASCII character that carries the address.
    pub const fn to_ascii(self) -> u8 {
        b'0' + self.0
    }
}

impl fmt::Display for Address {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.fmt(f)
    }
}

impl std::str::FromStr for Address {
    type Err = AddressError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let value: u32 = text.trim().parse().map_err(|_| AddressError::NotANumber {
            text: text.to_owned(),
        })?;
        u8::try_from(value)
            .ok()
            .and_then(|v| Address::new(v).ok())
            .ok_or(AddressError::OutOfRange {
                value,
                min: Self::MIN,
                max: Self::MAX,
            })
    }
}

/// An address that is not 0–7.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum AddressError {
    /// A number outside the range.
    #[error("regulator address {value} is not one of {min} to {max}")]
    OutOfRange {
        /// The number given.
        value: u32,
        /// The lowest address.
        min: u8,
        /// The highest address.
        max: u8,
    },
    /// Not a number at all.
    #[error("regulator address {text:?} is not a number from 0 to 7")]
    NotANumber {
        /// The text given.
        text: String,
    },
}

/// Whom a message is for: one regulator, or (`$`) whoever hears an address assignment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Target {
    /// The regulator at this address (the reply carries the same address).
    Address(Address),
    /// `$`: address assignment (message 10); every powered regulator takes the address in
    /// data item 0, so power one regulator at a time (thermosald-isc-rs485.txt, "Logic
    /// address assignment").
    Assign,
}

impl Target {
    /// The ASCII character that carries the target.
    pub const fn to_ascii(self) -> u8 {
        match self {
            Target::Address(a) => a.to_ascii(),
            Target::Assign => ASSIGN,
        }
    }

    fn from_ascii(byte: u8) -> Option<Self> {
        match byte {
            ASSIGN => Some(Target::Assign),
            b'0'..=b'7' => Some(Target::Address(Address(byte - b'0'))),
            _ => None,
        }
    }
}

impl From<Address> for Target {
    fn from(address: Address) -> Self {
        Target::Address(address)
    }
}

impl fmt::Display for Target {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Target::Address(a) => write!(f, "address {a}"),
            Target::Assign => f.write_str("address assignment '$'"),
        }
    }
}

/// A two-digit message number, 00–99. The meaning of each is in [`crate::request::Message`];
/// the frame layer carries any number, so a regulator can log an unknown one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct MessageNumber(u8);

impl MessageNumber {
    /// The highest two-digit number.
    pub const MAX: u8 = 99;

    /// A message number, refused above 99.
    pub const fn new(value: u8) -> Result<Self, FrameError> {
        if value <= Self::MAX {
            Ok(Self(value))
        } else {
            Err(FrameError::MessageNumber {
                value,
                max: Self::MAX,
            })
        }
    }

    /// The number.
    pub const fn get(self) -> u8 {
        self.0
    }

    /// A number known to be at most 99 (for the named constants).
    pub(crate) const fn known(value: u8) -> Self {
        assert!(value <= Self::MAX, "message numbers have two digits");
        Self(value)
    }
}

impl fmt::Display for MessageNumber {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:02}", self.0)
    }
}

/// Who speaks: the master asks (`Q`), a regulator answers (`R`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Direction {
    /// `Q`: a question from the master (the controller).
    Query,
    /// `R`: a response (answer or echo) from a regulator.
    Reply,
}

impl Direction {
    /// The ASCII character that carries the direction.
    pub const fn to_ascii(self) -> u8 {
        match self {
            Direction::Query => QUERY,
            Direction::Reply => REPLY,
        }
    }
}

/// The index of a single data item in the count field: 00–98 (99 means the whole table).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ItemIndex(u8);

impl ItemIndex {
    /// The highest single-item index the field can carry.
    pub const MAX: u8 = WHOLE_TABLE - 1;

    /// An index, refused from 99 on (99 selects the whole table).
    pub const fn new(value: u8) -> Result<Self, FrameError> {
        if value <= Self::MAX {
            Ok(Self(value))
        } else {
            Err(FrameError::ItemIndex {
                value,
                max: Self::MAX,
            })
        }
    }

    /// The index.
    pub const fn get(self) -> u8 {
        self.0
    }
}

/// The count field: the whole table (`99`) or one item's index.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Count {
    /// `99`: all items of the table, in index order.
    All,
    /// One item, by index.
    Item(ItemIndex),
}

impl Count {
    /// The single item at `index` (below 99).
    pub const fn item(index: u8) -> Result<Self, FrameError> {
        match ItemIndex::new(index) {
            Ok(i) => Ok(Count::Item(i)),
            Err(e) => Err(e),
        }
    }

    /// The two-digit value on the wire.
    pub const fn wire_value(self) -> u8 {
        match self {
            Count::All => WHOLE_TABLE,
            Count::Item(i) => i.0,
        }
    }

    const fn from_wire(value: u8) -> Self {
        if value >= WHOLE_TABLE {
            Count::All
        } else {
            Count::Item(ItemIndex(value))
        }
    }
}

impl fmt::Display for Count {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Count::All => f.write_str("whole table (99)"),
            Count::Item(i) => write!(f, "item {}", i.0),
        }
    }
}

/// One data item as the wire carries it: three decimal digits, 000–999, before scaling.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct RawValue(u16);

impl RawValue {
    /// `000`.
    pub const ZERO: RawValue = RawValue(0);
    /// `999`, the largest three-digit value.
    pub const MAX: RawValue = RawValue(MAX_RAW);

    /// A raw value, refused above 999.
    pub const fn new(value: u16) -> Result<Self, FrameError> {
        if value <= MAX_RAW {
            Ok(Self(value))
        } else {
            Err(FrameError::RawValue {
                value,
                max: MAX_RAW,
            })
        }
    }

    /// The nearest raw value to `value`, clamped to 0–999 (NaN gives 0). For the twin's
    /// measurements, which must always fit the field.
    pub fn saturating(value: f64) -> Self {
        if value.is_nan() {
            return Self::ZERO;
        }
        // The clamp makes the cast exact: 0.0..=999.0 fits u16.
        Self(value.round().clamp(0.0, f64::from(MAX_RAW)) as u16)
    }

    /// The value.
    pub const fn get(self) -> u16 {
        self.0
    }
}

impl fmt::Display for RawValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:03}", self.0)
    }
}

/// A value that cannot go into a frame field.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum FrameError {
    /// A message number above 99.
    #[error("message number {value} does not fit two digits (max {max})")]
    MessageNumber {
        /// The number given.
        value: u8,
        /// The highest number.
        max: u8,
    },
    /// An item index of 99 or more (99 means the whole table).
    #[error(
        "item index {value} does not fit the count field (max {max}; 99 means the whole table)"
    )]
    ItemIndex {
        /// The index given.
        value: u8,
        /// The highest index.
        max: u8,
    },
    /// A raw value above 999.
    #[error("raw value {value} does not fit three digits (max {max})")]
    RawValue {
        /// The value given.
        value: u16,
        /// The highest raw value.
        max: u16,
    },
    /// More data items than the longest table.
    #[error("{items} data items do not fit one message (max {max})")]
    TooManyItems {
        /// Items given.
        items: usize,
        /// The most a message carries.
        max: usize,
    },
}

/// One message, decoded: a valid header and up to [`MAX_DATA_ITEMS`] raw data items.
/// What the items mean depends on the message number and the count; see
/// [`crate::request`].
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Frame {
    target: Target,
    message: MessageNumber,
    direction: Direction,
    count: Count,
    data: Vec<RawValue>,
}

impl Frame {
    /// A frame; refused with more than [`MAX_DATA_ITEMS`] data items.
    pub fn new(
        target: Target,
        message: MessageNumber,
        direction: Direction,
        count: Count,
        data: Vec<RawValue>,
    ) -> Result<Self, FrameError> {
        if data.len() > MAX_DATA_ITEMS {
            return Err(FrameError::TooManyItems {
                items: data.len(),
                max: MAX_DATA_ITEMS,
            });
        }
        Ok(Self {
            target,
            message,
            direction,
            count,
            data,
        })
    }

    /// Whom the message is for (a reply carries the address of the question).
    pub fn target(&self) -> Target {
        self.target
    }

    /// The message number.
    pub fn message(&self) -> MessageNumber {
        self.message
    }

    /// Question or response.
    pub fn direction(&self) -> Direction {
        self.direction
    }

    /// Whole table or one item.
    pub fn count(&self) -> Count {
        self.count
    }

    /// The data items, before scaling.
    pub fn data(&self) -> &[RawValue] {
        &self.data
    }

    /// The same message with another direction: a regulator's echo is the question with `R`.
    pub fn with_direction(mut self, direction: Direction) -> Self {
        self.direction = direction;
        self
    }

    /// The same header with other data (up to [`MAX_DATA_ITEMS`]).
    pub fn with_data(mut self, data: Vec<RawValue>) -> Result<Self, FrameError> {
        if data.len() > MAX_DATA_ITEMS {
            return Err(FrameError::TooManyItems {
                items: data.len(),
                max: MAX_DATA_ITEMS,
            });
        }
        self.data = data;
        Ok(self)
    }

    /// Bytes on the wire, `%` to `LF`.
    pub fn wire_len(&self) -> usize {
        HEADER_LEN + self.data.len() * ITEM_WIDTH + 1
    }

    /// The bytes of the message.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.wire_len());
        self.encode_into(&mut out);
        out
    }

    /// Appends the bytes of the message to `out`. Infallible: every field is typed to fit.
    pub fn encode_into(&self, out: &mut Vec<u8>) {
        out.push(START);
        out.push(self.target.to_ascii());
        push_digits(out, u16::from(self.message.0), 2);
        out.push(self.direction.to_ascii());
        push_digits(out, u16::from(self.count.wire_value()), 2);
        out.push(UNUSED);
        for item in &self.data {
            push_digits(out, item.0, ITEM_WIDTH);
        }
        out.push(END);
    }
}

/// The message as text without its `LF`, e.g. `%015Q000000`.
impl fmt::Display for Frame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let bytes = self.to_bytes();
        let text = bytes.strip_suffix(&[END]).unwrap_or(&bytes);
        // Every byte is ASCII by construction.
        f.write_str(&String::from_utf8_lossy(text))
    }
}

/// Why bytes at the front of the stream are not a message. Every variant carries the number
/// of bytes to drop ([`wire::Resync`]): a run before a `%`, or the whole `%…LF` of a broken
/// message, so the next message is never lost.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum DecodeError {
    /// Bytes that do not start with `%`: line noise, or the tail of a message heard halfway.
    #[error("{len} byte(s) of noise before a message start '%'")]
    Garbage {
        /// Bytes to drop.
        len: usize,
    },
    /// A message that broke off: a new `%` came before its `LF`, or no `LF` came within
    /// the longest message.
    #[error(
        "a message broke off after {len} byte(s) (no LF before the next '%' or within {max} bytes)"
    )]
    Unterminated {
        /// Bytes to drop.
        len: usize,
        /// The longest message.
        max: usize,
    },
    /// `%…LF` shorter than a header.
    #[error("a message of {len} bytes is shorter than the {min}-byte header and LF")]
    TooShort {
        /// Bytes of the message, dropped.
        len: usize,
        /// The shortest message.
        min: usize,
    },
    /// The address is neither `0`–`7` nor `$`.
    #[error("address character {} is neither 0-7 nor '$'", show(&[*.found]))]
    Address {
        /// The byte found.
        found: u8,
        /// Bytes of the message, dropped.
        len: usize,
    },
    /// The message number is not two digits.
    #[error("message number {} is not two digits", show(.found))]
    MessageNumber {
        /// The bytes found.
        found: [u8; 2],
        /// Bytes of the message, dropped.
        len: usize,
    },
    /// The type is neither `Q` nor `R`.
    #[error("message type {} is neither 'Q' nor 'R'", show(&[*.found]))]
    Direction {
        /// The byte found.
        found: u8,
        /// Bytes of the message, dropped.
        len: usize,
    },
    /// The count is not two digits.
    #[error("data count {} is not two digits", show(.found))]
    Count {
        /// The bytes found.
        found: [u8; 2],
        /// Bytes of the message, dropped.
        len: usize,
    },
    /// The data are not a whole number of 3-digit items.
    #[error("{data_len} data characters are not a whole number of {ITEM_WIDTH}-digit items")]
    DataLength {
        /// Characters between the header and `LF`.
        data_len: usize,
        /// Bytes of the message, dropped.
        len: usize,
    },
    /// A data item holds something other than digits.
    #[error("data item {item} is {}, not three digits", show(.found))]
    DataItem {
        /// Position of the item in the message (0 = first).
        item: usize,
        /// The bytes found.
        found: [u8; 3],
        /// Bytes of the message, dropped.
        len: usize,
    },
}

impl DecodeError {
    /// Whether the dropped bytes were a whole `%…LF` message (malformed), rather than noise
    /// or a half message. A regulator treats a whole message as traffic on the line.
    pub fn is_whole_message(&self) -> bool {
        !matches!(
            self,
            DecodeError::Garbage { .. } | DecodeError::Unterminated { .. }
        )
    }
}

impl wire::Resync for DecodeError {
    fn drop_len(&self) -> usize {
        match *self {
            DecodeError::Garbage { len }
            | DecodeError::Unterminated { len, .. }
            | DecodeError::TooShort { len, .. }
            | DecodeError::Address { len, .. }
            | DecodeError::MessageNumber { len, .. }
            | DecodeError::Direction { len, .. }
            | DecodeError::Count { len, .. }
            | DecodeError::DataLength { len, .. }
            | DecodeError::DataItem { len, .. } => len.max(1),
        }
    }
}

/// The Thermosald message codec for [`wire::Deframer`] and [`wire::device::Model`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FrameCodec;

impl wire::Codec for FrameCodec {
    type Frame = Frame;
    type Error = DecodeError;

    fn decode(&self, buf: &[u8]) -> Result<Option<(Frame, usize)>, DecodeError> {
        match SCANNER.scan(buf) {
            Scan::NeedMore => Ok(None),
            Scan::Garbage { len } => Err(DecodeError::Garbage { len }),
            Scan::Unterminated { len } => Err(DecodeError::Unterminated { len, max: MAX_LEN }),
            Scan::Frame { len } => {
                let message = buf
                    .get(..len)
                    .ok_or(DecodeError::Unterminated { len, max: MAX_LEN })?;
                parse(message).map(|frame| Some((frame, len)))
            }
        }
    }

    fn encode(&self, frame: &Frame, out: &mut Vec<u8>) {
        frame.encode_into(out);
    }
}

/// Parses one whole message, `%` to `LF` (as the scanner delimited it).
fn parse(message: &[u8]) -> Result<Frame, DecodeError> {
    let len = message.len();
    if len < MIN_LEN {
        return Err(DecodeError::TooShort { len, min: MIN_LEN });
    }
    let byte = |at: usize| message.get(at).copied().unwrap_or(0);
    let pair = |at: core::ops::Range<usize>| [byte(at.start), byte(at.start + 1)];

    let found = byte(field::ADDRESS);
    let target = Target::from_ascii(found).ok_or(DecodeError::Address { found, len })?;

    let found = pair(field::MESSAGE);
    let message_number = two_digits(found).ok_or(DecodeError::MessageNumber { found, len })?;

    let direction = match byte(field::DIRECTION) {
        QUERY => Direction::Query,
        REPLY => Direction::Reply,
        found => return Err(DecodeError::Direction { found, len }),
    };

    let found = pair(field::COUNT);
    let count = Count::from_wire(two_digits(found).ok_or(DecodeError::Count { found, len })?);

    // The unused byte (offset 7) is accepted whatever it holds.
    let data_field = message.get(field::DATA_START..len - 1).unwrap_or(&[]);
    if data_field.len() % ITEM_WIDTH != 0 {
        return Err(DecodeError::DataLength {
            data_len: data_field.len(),
            len,
        });
    }
    let data = data_field
        .chunks_exact(ITEM_WIDTH)
        .enumerate()
        .map(|(item, digits)| {
            let found = [digits[0], digits[1], digits[2]];
            wire::ascii::parse_unsigned(digits)
                .and_then(|v| u16::try_from(v).ok())
                .map(RawValue)
                .ok_or(DecodeError::DataItem { item, found, len })
        })
        .collect::<Result<Vec<_>, _>>()?;

    Ok(Frame {
        target,
        message: MessageNumber(message_number),
        direction,
        count,
        data,
    })
}

fn two_digits(found: [u8; 2]) -> Option<u8> {
    wire::ascii::parse_unsigned(&found).and_then(|v| u8::try_from(v).ok())
}

/// Appends `value` as exactly `width` decimal digits; the typed fields always fit.
fn push_digits(out: &mut Vec<u8>, value: u16, width: usize) {
    let mut divisor = 10u16.pow(width.saturating_sub(1) as u32);
    while divisor > 0 {
        out.push(b'0' + ((value / divisor) % 10) as u8);
        divisor /= 10;
    }
}

/// Bytes as a plant engineer can read them: `'5'` for printable ASCII, `0x0d` otherwise.
fn show(bytes: &[u8]) -> String {
    if bytes.iter().all(|b| b.is_ascii_graphic() || *b == b' ') {
        format!("'{}'", String::from_utf8_lossy(bytes))
    } else {
        let hex: Vec<String> = bytes.iter().map(|b| format!("0x{b:02x}")).collect();
        hex.join(" ")
    }
}
