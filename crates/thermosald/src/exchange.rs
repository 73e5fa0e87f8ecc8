//! The master's side of one exchange, and the line's timing. No I/O, no clock: the async
//! client feeds decoded frames to [`Exchange::classify`] and asks
//! [`earliest_next_send`] when the line is free again.
//!
//! # Timing (thermosald-isc-rs485.txt, "FUNCTIONS"; specs/README.md)
//!
//! ```text
//! master  ─%…Q…LF─┐                                      ┌─ next %…Q…LF
//! regulator       │← 40 ms: listens again                │
//!                 │←──── 200 ms ────→%…R…LF─┐            │
//!                                           │← 40 ms ───→│ line released
//! ```
//!
//! A regulator answers [`ANSWER_AFTER_RECEPTION`] after the end of the question and releases
//! the line [`RELEASE_AFTER_ANSWER`] after the end of its answer; after any message it
//! listens again [`LISTEN_AFTER_MESSAGE`] later. The master must not send in between.
//!
//! # Theoretical poll limit
//!
//! One poll = question on the wire + 200 ms + answer on the wire + 40 ms
//! ([`LineTiming::poll_cycle`]). At 9600 8N1 (10 bits per character, 1.0417 ms each):
//!
//! - one item (9-byte question, 12-byte answer): 9.375 + 200 + 12.5 + 40 = 261.9 ms,
//!   **3.82 polls/s**;
//! - the whole run-time table (9-byte question, 30-byte answer): 9.375 + 200 + 31.25 + 40
//!   = 280.6 ms, **3.56 polls/s**;
//! - the whole machine table (84-byte answer): 336.9 ms, 2.97 polls/s.
//!
//! The line is shared: eight regulators polled in turn each get an eighth of that.

use std::time::{Duration, Instant};

use crate::frame::{Count, Direction, Frame, MessageNumber, RawValue, Target};
use crate::request::{Message, Read, Request, RequestError, Selection};
use crate::tables::{Item, Reading, Table};

/// A regulator listens again this long after the end of any message on the line.
pub const LISTEN_AFTER_MESSAGE: Duration = Duration::from_millis(40);
/// A regulator answers this long after the end of the question.
pub const ANSWER_AFTER_RECEPTION: Duration = Duration::from_millis(200);
/// A regulator releases the line this long after the end of its answer.
pub const RELEASE_AFTER_ANSWER: Duration = Duration::from_millis(40);
/// The line's baud rate (thermosald-isc-rs485.txt, "INTERFACE PARAMETERS").
pub const DEFAULT_BAUD: u32 = 9600;
/// Bits per character at 8N1: start, 8 data, stop.
pub const BITS_PER_CHAR_8N1: u32 = 10;
/// Extra time a reply timeout allows beyond the line's own timing: USB adapters' latency
/// timers (up to 16 ms), OS scheduling, a ser2net hop.
pub const TIMEOUT_MARGIN: Duration = Duration::from_millis(200);
/// The default reply timeout, counted from handing the question to the line: the longest
/// exchange at 9600 8N1 (9-byte question 9.4 ms + 200 ms + 84-byte machine table 87.5 ms =
/// 297 ms) plus [`TIMEOUT_MARGIN`], rounded up to 500 ms. [`Exchange::reply_timeout`] gives
/// more on slower lines.
pub const DEFAULT_REPLY_TIMEOUT: Duration = Duration::from_millis(500);

/// The character timing of a line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct LineTiming {
    baud: u32,
    bits_per_char: u32,
}

impl LineTiming {
    /// 9600 baud, 8N1: the spec's line.
    pub const RS485_9600_8N1: LineTiming = LineTiming {
        baud: DEFAULT_BAUD,
        bits_per_char: BITS_PER_CHAR_8N1,
    };

    /// A line at `baud` with `bits_per_char` bits per character (start + data + parity +
    /// stop: 10 for 8N1, 11 for 8E1); refused if either is zero.
    pub fn new(baud: u32, bits_per_char: u32) -> Result<Self, TimingError> {
        if baud == 0 || bits_per_char == 0 {
            return Err(TimingError {
                baud,
                bits_per_char,
            });
        }
        Ok(Self {
            baud,
            bits_per_char,
        })
    }

    /// The baud rate.
    pub const fn baud(&self) -> u32 {
        self.baud
    }

    /// Bits per character.
    pub const fn bits_per_char(&self) -> u32 {
        self.bits_per_char
    }

    /// Time on the wire of one character.
    pub fn char_time(&self) -> Duration {
        self.wire_time(1)
    }

    /// Time on the wire of `bytes` characters (to the nanosecond).
    pub fn wire_time(&self, bytes: usize) -> Duration {
        let bits = bytes as u128 * u128::from(self.bits_per_char);
        let nanos = bits * 1_000_000_000 / u128::from(self.baud);
        Duration::from_nanos(u64::try_from(nanos).unwrap_or(u64::MAX))
    }

    /// From the end of a question to the end of its answer of `reply_len` bytes.
    pub fn answer_window(&self, reply_len: usize) -> Duration {
        ANSWER_AFTER_RECEPTION + self.wire_time(reply_len)
    }

    /// One whole poll: question on the wire, the regulator's 200 ms, the answer on the
    /// wire, the 40 ms release. The shortest time between the starts of two questions.
    pub fn poll_cycle(&self, query_len: usize, reply_len: usize) -> Duration {
        self.wire_time(query_len) + self.answer_window(reply_len) + RELEASE_AFTER_ANSWER
    }

    /// The theoretical limit of polls per second for one exchange shape.
    pub fn polls_per_second(&self, query_len: usize, reply_len: usize) -> f64 {
        1.0 / self.poll_cycle(query_len, reply_len).as_secs_f64()
    }
}

impl Default for LineTiming {
    fn default() -> Self {
        Self::RS485_9600_8N1
    }
}

/// A baud rate or character size of zero.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error(
    "line timing needs a baud rate and bits per character above zero (got {baud} baud, {bits_per_char} bits)"
)]
pub struct TimingError {
    /// The baud rate given.
    pub baud: u32,
    /// The bits per character given.
    pub bits_per_char: u32,
}

/// Time on the wire of `bytes` characters at `baud`, 8N1.
pub fn wire_time(bytes: usize, baud: u32) -> Duration {
    LineTiming::new(baud, BITS_PER_CHAR_8N1).map_or(Duration::MAX, |t| t.wire_time(bytes))
}

/// The last thing the master saw on the line, and when it ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LineActivity {
    /// A regulator's answer ended (its `LF` arrived) at `ended`.
    Answered {
        /// When the answer's last byte arrived.
        ended: Instant,
    },
    /// Some other message ended at `ended` (another regulator's answer, a foreign
    /// question, a broken message).
    Traffic {
        /// When its last byte arrived.
        ended: Instant,
    },
    /// The master's question ended at `ended` and no answer came (timed out, or the
    /// master gave up): a regulator might still answer `reply_len` bytes within the window.
    Unanswered {
        /// When the question's last byte left.
        ended: Instant,
        /// The length of the answer that was expected.
        reply_len: usize,
    },
}

/// The earliest instant the master may start its next question: 40 ms after an answer or
/// any other message, or, after a question left unanswered, after the whole window in which
/// its answer could still come (200 ms + the answer's wire time + 40 ms).
pub fn earliest_next_send(last: LineActivity, timing: &LineTiming) -> Instant {
    match last {
        LineActivity::Answered { ended } => ended + RELEASE_AFTER_ANSWER,
        LineActivity::Traffic { ended } => ended + LISTEN_AFTER_MESSAGE,
        LineActivity::Unanswered { ended, reply_len } => {
            ended + timing.answer_window(reply_len) + RELEASE_AFTER_ANSWER
        }
    }
}

/// One question to one regulator (or to `$`), and how to recognise its answer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Exchange {
    request: Request,
    query: Frame,
}

impl Exchange {
    /// `request` for the regulator at `target`. [`Target::Assign`] (`$`) carries only
    /// address assignment (10).
    pub fn new(target: Target, request: Request) -> Result<Self, RequestError> {
        if target == Target::Assign && request.message() != Message::SetAddress {
            return Err(RequestError::AssignOnlySetsAddress {
                message: request.message(),
            });
        }
        let query = request.to_frame(target);
        Ok(Self { request, query })
    }

    /// The request.
    pub fn request(&self) -> &Request {
        &self.request
    }

    /// The question on the wire.
    pub fn query(&self) -> &Frame {
        &self.query
    }

    /// The bytes to send.
    pub fn query_bytes(&self) -> Vec<u8> {
        self.query.to_bytes()
    }

    /// The length in bytes of the answer (reads: the data; writes and commands: the echo).
    pub fn reply_len(&self) -> usize {
        match &self.request {
            Request::Read(read) => Frame::new(
                self.query.target(),
                self.query.message(),
                Direction::Reply,
                self.query.count(),
                vec![RawValue::ZERO; read.items().len()],
            )
            .map_or(self.query.wire_len(), |f| f.wire_len()),
            _ => self.query.wire_len(),
        }
    }

    /// How long to wait for the answer after handing the question to the line: the
    /// question's and the answer's wire time, the regulator's 200 ms and [`TIMEOUT_MARGIN`],
    /// and never less than [`DEFAULT_REPLY_TIMEOUT`].
    pub fn reply_timeout(&self, timing: &LineTiming) -> Duration {
        let needed = timing.wire_time(self.query.wire_len())
            + timing.answer_window(self.reply_len())
            + TIMEOUT_MARGIN;
        needed.max(DEFAULT_REPLY_TIMEOUT)
    }

    /// What `frame`, decoded from the line while this exchange waits, is to it.
    pub fn classify(&self, frame: &Frame) -> Classified {
        if frame.direction() == Direction::Query {
            return Classified::NotOurs(NotOurs::Query {
                message: frame.message(),
            });
        }
        if frame.target() != self.query.target() {
            return Classified::NotOurs(NotOurs::OtherTarget {
                expected: self.query.target(),
                actual: frame.target(),
            });
        }
        if frame.message() != self.query.message() {
            return Classified::NotOurs(NotOurs::OtherMessage {
                expected: self.query.message(),
                actual: frame.message(),
            });
        }
        match &self.request {
            Request::Read(read) => self.classify_read(read, frame),
            Request::Write(write) if write.selection() == Selection::All => {
                let table = write.table().items();
                let same = frame.count() == Count::All
                    && frame.data().len() == table.len()
                    && table
                        .iter()
                        .zip(write.data().iter().zip(frame.data()))
                        .all(|(item, (sent, echoed))| !item.writable() || sent == echoed);
                self.echo(same, frame)
            }
            _ => {
                let same = frame.count() == self.query.count() && frame.data() == self.query.data();
                self.echo(same, frame)
            }
        }
    }

    fn classify_read(&self, read: &Read, frame: &Frame) -> Classified {
        let expected_items = read.items().len();
        if frame.count() != self.query.count() || frame.data().len() != expected_items {
            return Classified::Mismatch(ExchangeError::ReplyShape {
                message: self.request.message(),
                expected_count: self.query.count(),
                actual_count: frame.count(),
                expected_items,
                actual_items: frame.data().len(),
            });
        }
        Classified::Answer(Answer::Values(Values {
            read: *read,
            data: frame.data().to_vec(),
        }))
    }

    fn echo(&self, same: bool, frame: &Frame) -> Classified {
        if same {
            Classified::Answer(Answer::Echoed)
        } else {
            Classified::Mismatch(ExchangeError::EchoMismatch {
                sent: self.query.clone(),
                received: frame.clone(),
            })
        }
    }
}

/// What a decoded frame is to a waiting exchange.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Classified {
    /// The regulator answered: the exchange is over.
    Answer(Answer),
    /// The regulator answered wrongly: the exchange is over with an error (retrying may
    /// help; an echo mismatch on a write means the regulator kept another value).
    Mismatch(ExchangeError),
    /// Not an answer to this exchange: keep waiting.
    NotOurs(NotOurs),
}

/// A regulator's good answer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Answer {
    /// The data of a read.
    Values(Values),
    /// The echo of a write, address assignment or command matched what was sent.
    Echoed,
}

/// The data a read returned.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Values {
    read: Read,
    data: Vec<RawValue>,
}

impl Values {
    /// The table read.
    pub fn table(&self) -> Table {
        self.read.table()
    }

    /// The raw values, in item order.
    pub fn raw(&self) -> &[RawValue] {
        &self.data
    }

    /// Each item with its value (`Set sealing temperature` = `180 °C`).
    pub fn readings(&self) -> impl Iterator<Item = Reading> + '_ {
        self.read
            .items()
            .iter()
            .zip(&self.data)
            .map(|(item, raw)| item.reading(*raw))
    }

    /// The value of one item, if the read covered it.
    pub fn get(&self, item: &Item) -> Option<Reading> {
        self.readings().find(|r| r.item() == item)
    }
}

/// Why a frame is not an answer to this exchange.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NotOurs {
    /// A question (`Q`): the adapter's local echo of our own question, or another master.
    Query {
        /// Its message number.
        message: MessageNumber,
    },
    /// An answer from another address (a late answer to an earlier question).
    OtherTarget {
        /// The address asked.
        expected: Target,
        /// The address that answered.
        actual: Target,
    },
    /// An answer to another message.
    OtherMessage {
        /// The message asked.
        expected: MessageNumber,
        /// The message answered.
        actual: MessageNumber,
    },
}

/// A regulator's answer that is wrong.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ExchangeError {
    /// The echo of a write or command differs from what was sent.
    #[error("echo mismatch: sent {sent}, the regulator echoed {received}")]
    EchoMismatch {
        /// The question as sent.
        sent: Frame,
        /// The echo as received.
        received: Frame,
    },
    /// A read's answer with the wrong count or number of items.
    #[error(
        "answer to {message} carries {actual_count} with {actual_items} item(s); expected {expected_count} with {expected_items}"
    )]
    ReplyShape {
        /// The message asked.
        message: Message,
        /// The count asked.
        expected_count: Count,
        /// The count answered.
        actual_count: Count,
        /// Items expected.
        expected_items: usize,
        /// Items answered.
        actual_items: usize,
    },
}
