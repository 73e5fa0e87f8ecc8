//! The message layout, the same on Port 1 and Port 2 (manual 3.1-2).
//!
//! ```text
//! command   256 bytes  ASCII text, right-padded with blanks (0x20)
//! size        4 bytes  byte count of the data field only, big-endian ("TCP/IP format")
//! data     size bytes  present only when size > 0
//! terminator  3 bytes  three 0x00 ("0 Char / 0 Char / 0 Char")
//! ```
//!
//! No STX, ETX or checksum: a message is framed by its fixed header and its length field.
//! A C2ST request is therefore 263 bytes, a D1 reply carrying `001` 266 bytes.
//!
//! Choices where the manual is loose (fact sheet §2, §7):
//! - **Terminator \[I\]:** we send three NUL bytes. On receive, three ASCII `0` (0x30) are
//!   accepted too, logged, and remembered in [`Message::terminator`]; any other trio is a
//!   [`DecodeError::Terminator`].
//! - **Size field \[I\]:** read as an unsigned 32-bit number, and refused above
//!   [`MAX_DATA_LEN`], so a hostile length can never make a reader buffer more than
//!   4 MiB + 263 bytes.
//! - **Command field \[I\]:** printable ASCII (0x20–0x7E) starting with a capital letter (every
//!   command class is one: `A`, `C`, `D`, `R`); trailing blanks are padding, so a command's
//!   own trailing blanks cannot survive the trip (fact sheet §6).
//!
//! - **Character set \[I\]:** the command field is ASCII; the data field is passed through as
//!   bytes (program text is CRLF-separated ASCII in every example, but nothing says it must be).
//!
//! **Resynchronisation.** The stream has no start byte, so after an error the decoder drops
//! bytes up to the next *possible* start: the next capital letter after the first byte that
//! proves the current start wrong. A byte outside printable ASCII inside the first 256 bytes
//! rules out every start up to and including it, so a stray NUL or CR/LF from a broken
//! message is skipped in one step; a bad size or terminator rules out only the current start.
//! A real message that follows garbage is never skipped, because no capital letter is ever
//! dropped unless it has been proven not to start a message.

use std::fmt;

use wire::words::Bytes;
use wire::{Codec, Resync};

/// Width of the command field.
pub const COMMAND_LEN: usize = 256;
/// Width of the data-size field.
pub const SIZE_LEN: usize = 4;
/// Command field plus size field: where the data starts.
pub const HEADER_LEN: usize = COMMAND_LEN + SIZE_LEN;
/// Width of the terminator.
pub const TERMINATOR_LEN: usize = 3;
/// The shortest message (no data): 263 bytes.
pub const MIN_MESSAGE_LEN: usize = HEADER_LEN + TERMINATOR_LEN;
/// The byte that pads the command field.
pub const PAD: u8 = b' ';
/// The terminator we send: three NUL bytes.
pub const NUL_TERMINATOR: [u8; TERMINATOR_LEN] = [0x00; TERMINATOR_LEN];
/// The terminator we also accept: three ASCII zeros (a literal reading of "0 Char").
pub const ASCII_ZERO_TERMINATOR: [u8; TERMINATOR_LEN] = [b'0'; TERMINATOR_LEN];

/// The largest data field we accept or build: 4 MiB.
///
/// The manual states no maximum beyond the 4-byte field. The largest transfers it names
/// are a 5000-step product program and a 1000-entry part library (3.3-4). At a generous
/// 256 bytes per step line a full program is about 1.3 MB, and a part library at 2 KB per
/// entry about 2 MB; 4 MiB holds either with room to spare while keeping what one hostile
/// length can make a reader buffer small.
pub const MAX_DATA_LEN: usize = 4 * 1024 * 1024;

/// Offsets inside a message.
mod field {
    use core::ops::Range;

    pub const COMMAND: Range<usize> = 0..super::COMMAND_LEN;
    pub const SIZE: Range<usize> = super::COMMAND_LEN..super::HEADER_LEN;
    pub const fn data(size: usize) -> Range<usize> {
        super::HEADER_LEN..super::HEADER_LEN + size
    }
    pub const fn terminator(size: usize) -> Range<usize> {
        let start = super::HEADER_LEN + size;
        start..start + super::TERMINATOR_LEN
    }
}

/// Which terminator a message carried.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Terminator {
    /// Three NUL bytes: what the manual's C-struct table means, and what we send.
    #[default]
    Nul,
    /// Three ASCII `0` characters: tolerated on receive.
    AsciiZero,
}

impl Terminator {
    /// The three bytes on the wire.
    pub const fn bytes(self) -> [u8; TERMINATOR_LEN] {
        match self {
            Terminator::Nul => NUL_TERMINATOR,
            Terminator::AsciiZero => ASCII_ZERO_TERMINATOR,
        }
    }
}

/// One message: a command text and its data.
///
/// The fields are private so that every message can be encoded: the command fits the
/// 256-byte field and the data is at most [`MAX_DATA_LEN`].
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Message {
    command: String,
    data: Vec<u8>,
    terminator: Terminator,
}

/// A command text or data field that cannot go into a message.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum MessageError {
    /// Nothing but blanks.
    #[error("a message needs a command: the command text is empty")]
    EmptyCommand,
    /// Longer than the command field.
    #[error("command text is {len} characters long; the command field holds {max}")]
    CommandTooLong {
        /// Length of the text.
        len: usize,
        /// Width of the field (256).
        max: usize,
    },
    /// Does not start with a capital letter.
    #[error("command text must start with a capital letter (A, C, D, R …), not {found:?}")]
    CommandStart {
        /// The first character.
        found: char,
    },
    /// A character outside printable ASCII.
    #[error("command text has {found:?} at position {offset}; only printable ASCII is allowed")]
    CommandChar {
        /// Position in the text.
        offset: usize,
        /// The character.
        found: char,
    },
    /// More data than we carry.
    #[error("data of {len} bytes is larger than the {max}-byte limit")]
    DataTooLong {
        /// Length of the data.
        len: usize,
        /// The limit ([`MAX_DATA_LEN`]).
        max: usize,
    },
}

impl Message {
    /// A message without data. Trailing blanks of `command` are padding and are dropped.
    pub fn new(command: &str) -> Result<Message, MessageError> {
        Message::with_data(command, Vec::new())
    }

    /// A message with data.
    pub fn with_data(command: &str, data: Vec<u8>) -> Result<Message, MessageError> {
        let command = command.trim_end_matches(' ');
        check_command_text(command)?;
        if data.len() > MAX_DATA_LEN {
            return Err(MessageError::DataTooLong {
                len: data.len(),
                max: MAX_DATA_LEN,
            });
        }
        Ok(Message {
            command: command.to_owned(),
            data,
            terminator: Terminator::Nul,
        })
    }

    /// The same message with another terminator (to reproduce a capture byte for byte).
    pub fn with_terminator(mut self, terminator: Terminator) -> Message {
        self.terminator = terminator;
        self
    }

    /// The command text, without padding.
    pub fn command(&self) -> &str {
        &self.command
    }

    /// The data field (empty when the size is 0).
    pub fn data(&self) -> &[u8] {
        &self.data
    }

    /// The data field, by value.
    pub fn into_data(self) -> Vec<u8> {
        self.data
    }

    /// The terminator the message came with (or will be sent with).
    pub fn terminator(&self) -> Terminator {
        self.terminator
    }

    /// Length on the wire.
    pub fn encoded_len(&self) -> usize {
        MIN_MESSAGE_LEN + self.data.len()
    }

    /// The bytes on the wire.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.encoded_len());
        MessageCodec.encode(self, &mut out);
        out
    }
}

impl fmt::Display for Message {
    /// `C2ST`, or `D1 [3 bytes]` when there is data.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.command)?;
        if !self.data.is_empty() {
            write!(f, " [{}]", Bytes(self.data.len()))?;
        }
        Ok(())
    }
}

/// Why the front of the stream is not a message. Every variant says how many bytes to drop.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum DecodeError {
    /// A byte that cannot start a message.
    #[error(
        "byte {byte:#04x} cannot start a message (commands start with a capital letter); skipping {drop} bytes"
    )]
    NotAStart {
        /// The first byte.
        byte: u8,
        /// Bytes to drop: up to the next capital letter.
        drop: usize,
    },
    /// A byte outside printable ASCII in the command field.
    #[error(
        "command field byte {offset} is {byte:#04x}, not printable ASCII: not a message here; skipping {drop} bytes"
    )]
    CommandField {
        /// Offset of the byte in the command field.
        offset: usize,
        /// The byte.
        byte: u8,
        /// Bytes to drop: past that byte, up to the next capital letter.
        drop: usize,
    },
    /// A data size above the limit.
    #[error(
        "{command} announces {} of data, more than the {max}-byte limit: not a message here; skipping {}",
        Bytes(*size as usize),
        Bytes(*drop)
    )]
    DataTooLong {
        /// The command text (trimmed).
        command: String,
        /// The size field.
        size: u32,
        /// The limit ([`MAX_DATA_LEN`]).
        max: usize,
        /// Bytes to drop: up to the next capital letter.
        drop: usize,
    },
    /// The three bytes after the data are not a terminator: the size is wrong, or the
    /// message was cut.
    #[error(
        "{command} with {} of data ends in {found:02x?} instead of the 00 00 00 terminator; skipping {}",
        Bytes(*size as usize),
        Bytes(*drop)
    )]
    Terminator {
        /// The command text (trimmed).
        command: String,
        /// The size field.
        size: u32,
        /// The three bytes found.
        found: [u8; TERMINATOR_LEN],
        /// Bytes to drop: up to the next capital letter.
        drop: usize,
    },
}

impl Resync for DecodeError {
    fn drop_len(&self) -> usize {
        match self {
            DecodeError::NotAStart { drop, .. }
            | DecodeError::CommandField { drop, .. }
            | DecodeError::DataTooLong { drop, .. }
            | DecodeError::Terminator { drop, .. } => (*drop).max(1),
        }
    }
}

/// The message codec for both ports.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MessageCodec;

impl Codec for MessageCodec {
    type Frame = Message;
    type Error = DecodeError;

    fn decode(&self, buf: &[u8]) -> Result<Option<(Message, usize)>, DecodeError> {
        let Some(&first) = buf.first() else {
            return Ok(None);
        };
        if !is_start(first) {
            return Err(DecodeError::NotAStart {
                byte: first,
                drop: next_start(buf, 0),
            });
        }
        let command_field = buf.get(field::COMMAND).unwrap_or(buf);
        if let Some(offset) = command_field.iter().position(|&b| !is_printable(b)) {
            let byte = command_field.get(offset).copied().unwrap_or_default();
            return Err(DecodeError::CommandField {
                offset,
                byte,
                drop: next_start(buf, offset),
            });
        }
        let Some(&[a, b, c, d]) = buf.get(field::SIZE) else {
            return Ok(None);
        };
        let size = u32::from_be_bytes([a, b, c, d]);
        let command = || command_text(command_field);
        let len = match usize::try_from(size) {
            Ok(len) if len <= MAX_DATA_LEN => len,
            _ => {
                return Err(DecodeError::DataTooLong {
                    command: command(),
                    size,
                    max: MAX_DATA_LEN,
                    drop: next_start(buf, 0),
                });
            }
        };
        let Some(&[t0, t1, t2]) = buf.get(field::terminator(len)) else {
            return Ok(None);
        };
        let terminator = match [t0, t1, t2] {
            NUL_TERMINATOR => Terminator::Nul,
            ASCII_ZERO_TERMINATOR => {
                tracing::warn!(command = %command(), "message ends in ASCII \"000\" instead of three NUL bytes; accepted");
                Terminator::AsciiZero
            }
            found => {
                return Err(DecodeError::Terminator {
                    command: command(),
                    size,
                    found,
                    drop: next_start(buf, 0),
                });
            }
        };
        let data = buf.get(field::data(len)).unwrap_or_default().to_vec();
        let message = Message {
            command: command(),
            data,
            terminator,
        };
        Ok(Some((message, HEADER_LEN + len + TERMINATOR_LEN)))
    }

    fn encode(&self, message: &Message, out: &mut Vec<u8>) {
        out.reserve(message.encoded_len());
        out.extend_from_slice(message.command.as_bytes());
        let padding = COMMAND_LEN.saturating_sub(message.command.len());
        out.extend(std::iter::repeat_n(PAD, padding));
        let size = u32::try_from(message.data.len())
            .expect("data is at most MAX_DATA_LEN, below u32::MAX");
        out.extend_from_slice(&size.to_be_bytes());
        out.extend_from_slice(&message.data);
        out.extend_from_slice(&message.terminator.bytes());
    }
}

/// Checks a (trimmed) command text.
fn check_command_text(command: &str) -> Result<(), MessageError> {
    let Some(first) = command.chars().next() else {
        return Err(MessageError::EmptyCommand);
    };
    if let Some((offset, found)) = command
        .char_indices()
        .find(|&(_, c)| !c.is_ascii() || !is_printable(c as u8))
    {
        return Err(MessageError::CommandChar { offset, found });
    }
    if !is_start(first as u8) {
        return Err(MessageError::CommandStart { found: first });
    }
    if command.len() > COMMAND_LEN {
        return Err(MessageError::CommandTooLong {
            len: command.len(),
            max: COMMAND_LEN,
        });
    }
    Ok(())
}

/// Whether a byte can be the first of a message.
fn is_start(byte: u8) -> bool {
    byte.is_ascii_uppercase()
}

/// Whether a byte can be in the command field.
fn is_printable(byte: u8) -> bool {
    (0x20..=0x7E).contains(&byte)
}

/// The command text of a checked command field: padding removed.
fn command_text(field: &[u8]) -> String {
    let end = field.iter().rposition(|&b| b != PAD).map_or(0, |i| i + 1);
    field
        .get(..end)
        .unwrap_or_default()
        .iter()
        .map(|&b| char::from(b))
        .collect()
}

/// Offset of the first possible message start after `after`, or the whole buffer.
fn next_start(buf: &[u8], after: usize) -> usize {
    buf.iter()
        .enumerate()
        .skip(after + 1)
        .find(|&(_, &b)| is_start(b))
        .map_or(buf.len(), |(i, _)| i)
}

#[cfg(test)]
mod tests;
