//! The async master: typed requests to one regulator over a [`link`] line, respecting the
//! line's timing, with a timeout, retries and echo checks.
//!
//! # Timing on the line
//!
//! A regulator listens again 40 ms after the end of any message, answers 200 ms after the
//! question and releases the line 40 ms after its answer ([`crate::exchange`]). After every
//! attempt the client tells the line when it is free again with
//! [`link::Line::keep_quiet_until`], computed by [`earliest_next_send`]:
//!
//! - after an answer (good or not): 40 ms after it arrived;
//! - after any other message heard while waiting (another regulator's late answer, the
//!   adapter's local echo) or a damaged one: 40 ms after it;
//! - after a question left unanswered: the end of the whole window in which its answer could
//!   still have come (200 ms + the answer's wire time + 40 ms), usually already over when
//!   the timeout ends.
//!
//! The quiet time lives on the line, not in the client, so every client of a
//! [`SharedLine`] (one per regulator) respects the windows the others opened.
//!
//! # Several regulators on one line
//!
//! Clients of the regulators on one line share one [`SharedLine`]. Each *attempt* holds the
//! line from its question until its answer or its timeout, then lets it go: the clients
//! waiting for the line go first, in the order they asked, before the next retry. So a dead
//! regulator delays the others by one timeout per attempt, never by its whole retry series.
//!
//! # Retries
//!
//! The protocol has no negative answer and no checksum: a regulator that does not accept a
//! message stays silent, and a digit damaged on the line can still look like a digit.
//!
//! - No answer within the timeout: retried.
//! - A damaged message (bad digits, wrong length) where the answer should be: retried as
//!   soon as the line is free again (40 ms), without waiting for the timeout.
//! - A read answer of the wrong shape (count or number of items): retried.
//! - An echo that differs from what was sent: retried **once**, because without a checksum
//!   a digit damaged on the line looks exactly like a regulator that kept another value; a
//!   second differing echo is reported at once as the regulator's refusal, [`EchoMismatch`] (what was
//!   sent and what came back). Writes and commands are safe to repeat: a write sets a
//!   value, and repeating a command leaves the regulator where one would.
//! - Noise and half messages are skipped: the answer may still follow.
//! - Messages that are not the answer (another address, another message number, a question
//!   such as the adapter's local echo) are skipped, never taken for the answer.
//!
//! A request the crate refuses to build (a value out of range, a read-only item) never
//! reaches the wire: [`ClientError::Request`].

use std::time::Duration;

use std::time::Instant as StdInstant;

use link::{Line, LineError, SharedLine};
use tokio::time::Instant;
use wire::exchange::{AttemptEnd, Ending, Matcher, Policy, Verdict, VerdictOf};
use wire::{Exchange as Engine, Failure, FailureKind};

use crate::exchange::{
    Answer, Classified, DEFAULT_REPLY_TIMEOUT, Exchange, ExchangeError, LineActivity, LineTiming,
    RELEASE_AFTER_ANSWER, TIMEOUT_MARGIN, Values, earliest_next_send,
};
use crate::frame::{Address, Count, DecodeError, Frame, FrameCodec, RawValue, Target};
use crate::request::{Command, Message, MessageKind, Read, Request, RequestError, Write};
use crate::tables::{Item, Reading, Table};

/// Default time to wait for an answer, counted from handing the question to the line: 500 ms
/// at 9600 baud ([`DEFAULT_REPLY_TIMEOUT`]); [`Exchange::reply_timeout`] gives more on
/// slower lines.
pub const DEFAULT_TIMEOUT: Duration = DEFAULT_REPLY_TIMEOUT;

/// Default number of retries after the first attempt.
pub const DEFAULT_RETRIES: u8 = 2;

/// How many differing echoes end a request at once (see the module doc): the first may be
/// line damage, the second is the regulator's answer.
pub const ECHO_MISMATCHES_TOLERATED: u8 = 1;

/// How the client talks to one regulator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClientConfig {
    /// The regulator's address, or `$` (address assignment, message 10 only).
    pub target: Target,
    /// Time to wait for each answer; `None`: [`Exchange::reply_timeout`] (500 ms at 9600
    /// baud, longer on slower lines).
    pub timeout: Option<Duration>,
    /// Retries after the first attempt (see the module doc for what is retried).
    pub retries: u8,
    /// The line's character timing; `None`: from the line's serial settings when it knows
    /// them, else the spec's 9600 8N1.
    pub timing: Option<LineTiming>,
}

impl ClientConfig {
    /// The defaults for the regulator at `target`.
    pub fn new(target: impl Into<Target>) -> Self {
        Self {
            target: target.into(),
            timeout: None,
            retries: DEFAULT_RETRIES,
            timing: None,
        }
    }
}

impl Default for ClientConfig {
    /// Address 0, the default timeout, 2 retries, the line's own timing.
    fn default() -> Self {
        Self::new(Address::new(0).expect("0 is a valid address"))
    }
}

/// Why a request did not get its answer: our request (refused before the wire), the
/// regulator's echo of another value ([`EchoMismatch`]), no valid answer within the
/// attempts, or the line.
pub type ClientError = wire::ExchangeError<RequestError, EchoMismatch, Trouble, LineError>;

/// Line trouble on one attempt: silence, a damaged message where the answer should be, or
/// an answer of the wrong shape or echo ([`ExchangeError`]).
pub type Trouble = wire::Trouble<DecodeError, ExchangeError>;

/// The regulator echoed a write or command differently from what was sent, again after a
/// retry: it kept another value (or something on the line changes the message).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EchoMismatch {
    /// Whom we asked.
    pub target: Target,
    /// The question as sent.
    pub sent: Frame,
    /// The (last) echo as received.
    pub received: Frame,
}

impl wire::exchange::Refusal for EchoMismatch {
    fn describe(&self, endpoint: &str, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "echo mismatch from {} on {endpoint}: sent {}, it echoed {}{}",
            regulator(&self.target),
            self.sent,
            self.received,
            differences(&self.sent, &self.received)
        )
    }
}

impl Failure for ExchangeError {
    /// A regulator's answer of the wrong shape or echo: damage the protocol cannot check.
    fn kind(&self) -> FailureKind {
        FailureKind::Damaged
    }
}

/// A client for one regulator on a (possibly shared) line.
#[derive(Debug)]
pub struct Client {
    line: SharedLine,
    config: ClientConfig,
}

impl Client {
    /// A client for the regulator `config` names on `line`.
    pub fn new(line: SharedLine, config: ClientConfig) -> Self {
        Self { line, config }
    }

    /// The client's settings.
    pub fn config(&self) -> &ClientConfig {
        &self.config
    }

    /// Whom the client talks to.
    pub fn target(&self) -> Target {
        self.config.target
    }

    /// Reads a whole table: every item, named and scaled.
    pub async fn read_table(&mut self, table: Table) -> Result<Values, ClientError> {
        self.read(Read::all(table)).await
    }

    /// Reads one item.
    pub async fn read_item(&mut self, item: &'static Item) -> Result<Reading, ClientError> {
        let values = self.read(Read::item(item)).await?;
        Ok(values
            .get(item)
            .expect("a read answer is checked to carry the item asked"))
    }

    /// Reads what `read` selects.
    pub async fn read(&mut self, read: Read) -> Result<Values, ClientError> {
        match self.request(read.into()).await? {
            Answer::Values(values) => Ok(values),
            Answer::Echoed => unreachable!("a read is answered with values"),
        }
    }

    /// Writes `value` in the item's unit (`180.0` °C, KINT gain `12.5`); checked against the
    /// item before the wire. Returns the value as the regulator echoed it.
    pub async fn write(&mut self, item: &'static Item, value: f64) -> Result<Reading, ClientError> {
        let raw = item.to_raw(value).map_err(RequestError::from)?;
        self.write_raw(item, raw).await
    }

    /// Writes the raw digits `raw` to `item` (checked against its range before the wire).
    pub async fn write_raw(
        &mut self,
        item: &'static Item,
        raw: RawValue,
    ) -> Result<Reading, ClientError> {
        self.request(Write::item(item, raw)?.into()).await?;
        Ok(item.reading(raw))
    }

    /// Writes a whole table (read it, change it, write it back); the echo is compared on the
    /// writable items.
    pub async fn write_table(
        &mut self,
        table: Table,
        values: Vec<RawValue>,
    ) -> Result<(), ClientError> {
        self.request(Write::whole(table, values)?.into())
            .await
            .map(drop)
    }

    /// 14: clears latched faults whose cause is gone.
    pub async fn clear_faults(&mut self) -> Result<(), ClientError> {
        self.command(Command::ClearFaults).await
    }

    /// 15: starts automatic balancing (diagnostic 36 while it runs).
    pub async fn balance(&mut self) -> Result<(), ClientError> {
        self.command(Command::Balance).await
    }

    /// 16: saves the working data to EEPROM (writes are volatile until then).
    pub async fn save_eeprom(&mut self) -> Result<(), ClientError> {
        self.command(Command::SaveEeprom).await
    }

    /// 17: loads the working data from EEPROM.
    pub async fn load_eeprom(&mut self) -> Result<(), ClientError> {
        self.command(Command::LoadEeprom).await
    }

    /// 99: master reset: factory data, no address until one is set, diagnostic 35 until
    /// balancing.
    pub async fn master_reset(&mut self) -> Result<(), ClientError> {
        self.command(Command::MasterReset).await
    }

    /// 10: gives the regulator (or, with target `$`, every powered regulator) the address
    /// `new`. Once echoed, the client talks to `new`.
    pub async fn set_address(&mut self, new: Address) -> Result<(), ClientError> {
        self.request(Request::SetAddress(new)).await?;
        self.config.target = Target::Address(new);
        Ok(())
    }

    async fn command(&mut self, command: Command) -> Result<(), ClientError> {
        self.request(command.into()).await.map(drop)
    }

    /// Sends `request` and returns the regulator's answer, with the timing, retries and
    /// checks of the module doc.
    pub async fn request(&mut self, request: Request) -> Result<Answer, ClientError> {
        let exchange = Exchange::new(self.config.target, request)?;
        let query = exchange.query_bytes();
        let matcher = Answering {
            target: self.config.target,
            query_len: query.len(),
            timing: LineTiming::default(),
            mismatches: 0,
            exchange,
        };
        let policy = Policy::new(self.config.retries, DEFAULT_TIMEOUT);
        let mut engine = Engine::new(matcher, FrameCodec, query, policy);
        loop {
            // One attempt at a time: other regulators' clients may use the line in between.
            let mut line = self.line.lock().await;
            let timing = self.timing(&line);
            let timeout = self
                .config
                .timeout
                .unwrap_or_else(|| engine.matcher().exchange.reply_timeout(&timing));
            engine.set_timeout(timeout);
            engine.matcher_mut().timing = timing;
            if let Some(answer) = link::exchange::step(&mut line, &mut engine).await? {
                return Ok(answer);
            }
        }
    }

    /// The configured timing, else the line's, else the spec's 9600 8N1.
    fn timing(&self, line: &Line) -> LineTiming {
        self.config.timing.unwrap_or_else(|| {
            line.settings()
                .and_then(|s| LineTiming::new(s.baud, s.bits_per_char()).ok())
                .unwrap_or_default()
        })
    }
}

/// How long a line just opened is kept quiet before its first question: the release time
/// after an answer. Another master (an earlier `cellbus` run, a PLC) may have had an answer
/// moments ago; a question inside the regulators' window would be ignored and cost a whole
/// timeout.
pub const QUIET_AFTER_OPEN: Duration = RELEASE_AFTER_ANSWER;

/// Keeps a line just opened quiet for [`QUIET_AFTER_OPEN`]: we cannot know when the last
/// exchange on it ended.
pub fn quiet_after_open(line: &mut Line) {
    line.keep_quiet_until(Instant::now() + QUIET_AFTER_OPEN);
}

/// What a scan found at one address.
#[derive(Debug)]
pub struct Probe {
    /// The address asked.
    pub address: Address,
    /// Its fault/warning number (run-time item 2), or why none came.
    pub outcome: Result<Reading, ClientError>,
}

impl Probe {
    /// Whether something answered at the address (a damaged or odd answer counts: a
    /// regulator is there; line noise alone does not).
    pub fn answered(&self) -> bool {
        match &self.outcome {
            Ok(_) | Err(ClientError::Refused { .. }) => true,
            Err(ClientError::NoAnswer { last, .. }) => !last.heard_nothing(),
            Err(_) => false,
        }
    }
}

/// How long a scan waits at each address: the question's and a one-item answer's time on
/// the wire, the regulator's 200 ms and [`TIMEOUT_MARGIN`] (422 ms at 9600 baud).
pub fn probe_timeout(timing: &LineTiming) -> Duration {
    timing.wire_time(PROBE_QUERY_LEN) + timing.answer_window(PROBE_REPLY_LEN) + TIMEOUT_MARGIN
}

/// A one-item read: `%a53Q020` + LF.
const PROBE_QUERY_LEN: usize = 9;
/// Its answer: `%a53R020ddd` + LF.
const PROBE_REPLY_LEN: usize = 12;

/// Asks every address 0–7 for its fault/warning number, one attempt each, one after the
/// other as fast as the line's timing allows: an address that answers costs one poll cycle
/// (262 ms at 9600 baud), a silent one [`probe_timeout`] (`timeout` overrides it). A
/// regulator without an address (after a master reset) answers only `$` and is not found.
pub async fn scan(line: &SharedLine, timeout: Option<Duration>) -> Result<Vec<Probe>, ClientError> {
    let timing = {
        let line = line.lock().await;
        line.settings()
            .and_then(|s| LineTiming::new(s.baud, s.bits_per_char()).ok())
            .unwrap_or_default()
    };
    let timeout = timeout.unwrap_or_else(|| probe_timeout(&timing));
    let fault = Table::Runtime
        .item(crate::tables::runtime::FAULT)
        .expect("run-time data has item 2");
    let mut probes = Vec::new();
    for address in Address::all() {
        let config = ClientConfig {
            target: Target::Address(address),
            timeout: Some(timeout),
            retries: 0,
            timing: Some(timing),
        };
        match Client::new(line.clone(), config).read_item(fault).await {
            Err(failed @ ClientError::Line { .. }) => return Err(failed),
            outcome => probes.push(Probe { address, outcome }),
        }
    }
    Ok(probes)
}

/// What answers one question: the regulator's answer or echo, with the line's windows.
struct Answering {
    exchange: Exchange,
    target: Target,
    query_len: usize,
    /// The line's timing, for the quiet time after each attempt.
    timing: LineTiming,
    /// Echoes that differed so far.
    mismatches: u8,
}

impl Matcher for Answering {
    type Codec = FrameCodec;
    type Answer = Answer;
    type Refusal = EchoMismatch;
    type Mismatch = ExchangeError;

    fn judge(&mut self, input: Result<Frame, DecodeError>) -> VerdictOf<Self> {
        match input {
            Ok(frame) => match self.exchange.classify(&frame) {
                Classified::Answer(answer) => Verdict::Answer(answer),
                Classified::Mismatch(ExchangeError::EchoMismatch { sent, received }) => {
                    self.mismatches += 1;
                    if self.mismatches > ECHO_MISMATCHES_TOLERATED {
                        Verdict::Refused(EchoMismatch {
                            target: self.target,
                            sent,
                            received,
                        })
                    } else {
                        Verdict::Retry(Trouble::Mismatch(ExchangeError::EchoMismatch {
                            sent,
                            received,
                        }))
                    }
                }
                Classified::Mismatch(other) => Verdict::Retry(Trouble::Mismatch(other)),
                Classified::NotOurs(why) => {
                    tracing::debug!(%frame, ?why, "skipping a message that is not the answer");
                    Verdict::Skip
                }
            },
            // A damaged whole message where the answer should be: retry once the line is free.
            Err(damage) if damage.is_whole_message() => Verdict::Retry(Trouble::Damaged(damage)),
            // Noise or a half message: the answer may still come.
            Err(noise) => {
                tracing::debug!(%noise, "skipping noise while waiting for the answer");
                Verdict::Noise
            }
        }
    }

    /// An echo that differs on the last attempt is the regulator's answer: it kept another
    /// value.
    fn last_word(&mut self, last: &Trouble) -> Option<EchoMismatch> {
        match last {
            Trouble::Mismatch(ExchangeError::EchoMismatch { sent, received }) => {
                Some(EchoMismatch {
                    target: self.target,
                    sent: sent.clone(),
                    received: received.clone(),
                })
            }
            _ => None,
        }
    }

    /// The regulators' windows: 40 ms after an answer or any other message; after a
    /// question left unanswered, the whole window in which its answer could still come.
    fn quiet_after(&mut self, attempt: &AttemptEnd) -> Option<StdInstant> {
        let activity = match attempt.ending {
            Ending::Answered => LineActivity::Answered {
                ended: attempt.ended,
            },
            Ending::Damaged => LineActivity::Traffic {
                ended: attempt.ended,
            },
            // The question ended its wire time after it was handed to the line.
            Ending::TimedOut => LineActivity::Unanswered {
                ended: attempt.sent + self.timing.wire_time(self.query_len),
                reply_len: self.exchange.reply_len(),
            },
        };
        let after_traffic = attempt
            .skipped
            .map(|ended| earliest_next_send(LineActivity::Traffic { ended }, &self.timing));
        Some(earliest_next_send(activity, &self.timing).max(after_traffic.unwrap_or(attempt.ended)))
    }

    fn device(&self) -> String {
        regulator(&self.target)
    }
}

/// `regulator 3`, or `the regulators listening to '$'`.
fn regulator(target: &Target) -> String {
    match target {
        Target::Address(address) => format!("regulator {address}"),
        Target::Assign => "the regulators listening to '$' (address assignment)".to_owned(),
    }
}

/// What differs between a question and its echo, in words: `; it kept Set sealing
/// temperature = 180 °C, not 300 °C`. Empty when the messages say nothing more precise.
fn differences(sent: &Frame, received: &Frame) -> String {
    let Ok(message) = Message::from_number(sent.message()) else {
        return String::new();
    };
    let MessageKind::Write(table) = message.kind() else {
        return String::new();
    };
    let items: &'static [Item] = match sent.count() {
        Count::All => table.items(),
        Count::Item(index) => match table.item(index.get()) {
            Ok(item) => std::slice::from_ref(item),
            Err(_) => return String::new(),
        },
    };
    if sent.count() != received.count() || received.data().len() != items.len() {
        return String::new();
    }
    let kept: Vec<String> = items
        .iter()
        .zip(sent.data().iter().zip(received.data()))
        .filter(|(item, (s, r))| item.writable() && s != r)
        .map(|(item, (s, r))| {
            format!(
                "{} = {}, not {}",
                item.name(),
                item.reading(*r),
                item.reading(*s)
            )
        })
        .collect();
    if kept.is_empty() {
        String::new()
    } else {
        format!("; it kept {}", kept.join(", "))
    }
}
