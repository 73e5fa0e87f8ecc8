//! The async Modbus client: typed requests to the units on a [`link`] line, with a
//! response timeout, retries, the line's inter-frame silence and checked answers, in RTU
//! framing or Modbus TCP's ([`Framing`]).
//!
//! - **Modbus TCP** ([`Framing::Tcp`], `modbus-tcp://` endpoints): each request carries a
//!   new transaction id (increasing, wrapping at 65535, shared by a client's clones); only a
//!   response with the same transaction id and unit is taken, any other (a late answer to
//!   an earlier request) is dropped. No CRC and no inter-frame silence; several units share
//!   one connection, one request at a time. Everything else below holds for both.
//!
//! - **One request in flight per line.** A [`Client`] holds a [`SharedLine`]; clones of it
//!   and clients made on the same shared line queue for it in order, so units that share
//!   an RS-485 pair never see interleaved frames.
//! - **Inter-frame silence.** After every exchange the client keeps the line quiet for 3.5
//!   character times at the line's speed and format (1.75 ms above 19200 baud) through
//!   [`Line::keep_quiet_until`], so the next request, whoever sends it, respects it. A TCP
//!   endpoint that names no serial line (`tcp://host:port` without `?baud=`) has no
//!   character time, and no silence.
//! - **Checked answers.** A frame is the answer only if [`check_response`] accepts it (same
//!   unit, function, count or echo). Other frames (a late answer to an earlier request,
//!   another master's traffic) are skipped.
//! - **Retries for line trouble only.** Silence, a damaged frame (bad CRC, bytes that the
//!   line's silence cut short) and answers that never match are retried; an exception is
//!   the device's answer and is reported at once, in words ([`ClientError::Exception`]).
//!   A damaged answer is retried as soon as the line falls quiet after it, without waiting
//!   for the timeout.
//! - **Resynchronisation.** RTU frames carry no length; bytes that look like the head of a
//!   long frame would hold the decoder until that many bytes arrive. When the line falls
//!   quiet with bytes still undecoded, the client looks past them with [`find_frame`].
//! - **Broadcasts** (unit 0, writes only) are sent and never answered; the line is then kept
//!   quiet for the units' turnaround time ([`ClientConfig::turnaround`]).
//! - **A dead unit costs its own timeouts only**: every attempt starts on a clean line
//!   (stale input dropped), so the next unit's exchange is unaffected.

use std::sync::Arc;
use std::sync::atomic::{AtomicU16, Ordering};
use std::time::Duration;

use link::{Endpoint, Line, LineError, SharedLine};
use tokio::time::Instant;
use wire::exchange::{AttemptEnd, Matcher, Policy, Verdict, VerdictOf};
use wire::{Exchange, Failure, FailureKind};

use crate::rtu::{
    Addressed, Answer, Broadcast, DecodeError, Exception, ExceptionCode, InvalidValue, LineTiming,
    Mismatch, Request, RequestAdu, ResponseAdu, ResponseCodec, UnitId, check_response, find_frame,
};
use crate::tcp::{self, Mbap, TransactionId};

/// Default time to wait for an answer after the request has left, on top of the wire time
/// of the request and the answer at the line's speed (when known): Modbus devices answer
/// within a few to a few hundred milliseconds.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_millis(500);

/// Default number of retries after the first attempt.
pub const DEFAULT_RETRIES: u8 = 2;

/// Default quiet time after a broadcast, so every unit has handled it before the next
/// request (the Modbus serial-line guide's "turnaround delay", typically 100–200 ms).
pub const DEFAULT_TURNAROUND: Duration = Duration::from_millis(100);

/// The shortest quiet time after which undecoded bytes are taken as a finished (damaged or
/// padded) frame. The standard's 3.5 characters are 4 ms at 9600 baud, but USB adapters
/// and TCP serial servers deliver a frame in bursts with gaps of up to about 16 ms inside
/// it; a longer wait only delays recovery from damage, never a good answer.
pub const MIN_QUIET_GAP: Duration = Duration::from_millis(50);

/// How the client talks to the units on a line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClientConfig {
    /// Time to wait for each answer (the wire time of request and answer is added).
    pub timeout: Duration,
    /// Retries after the first attempt, for line trouble only.
    pub retries: u8,
    /// Quiet time after a broadcast.
    pub turnaround: Duration,
    /// How frames are framed on the line.
    pub framing: Framing,
}

impl Default for ClientConfig {
    /// 500 ms, 2 retries, 100 ms turnaround after broadcasts, RTU framing.
    fn default() -> Self {
        Self {
            timeout: DEFAULT_TIMEOUT,
            retries: DEFAULT_RETRIES,
            turnaround: DEFAULT_TURNAROUND,
            framing: Framing::Rtu,
        }
    }
}

/// How Modbus messages are framed on a line.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub enum Framing {
    /// Modbus RTU: unit, PDU, CRC, frames told apart by silence (serial lines, and TCP
    /// serial servers: `serial://`, `tcp://`).
    #[default]
    Rtu,
    /// Modbus TCP: an MBAP header (transaction id, length, unit id) before the PDU, no CRC
    /// (`modbus-tcp://`).
    Tcp,
}

impl Framing {
    /// The framing an endpoint's URL asks for: Modbus TCP for `modbus-tcp://`, else RTU.
    pub fn of(endpoint: &Endpoint) -> Self {
        if endpoint.is_mbap() {
            Self::Tcp
        } else {
            Self::Rtu
        }
    }
}

/// Why a request did not get its answer: our request (refused before the wire), the
/// unit's exception ([`UnitRefusal`]), no valid answer within the attempts, or the line.
pub type ClientError = wire::ExchangeError<InvalidValue, UnitRefusal, Trouble, LineError>;

/// Line trouble on one attempt, what makes the client retry: silence, a damaged frame (bad
/// CRC, or a good CRC around invalid content), bytes the line's silence cut short, or
/// well-formed frames none of which answers the request.
pub type Trouble = wire::Trouble<Damage, Mismatch>;

/// Why bytes that came back are not a frame, in the line's framing.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Damage {
    /// An RTU frame: a bad CRC, a good CRC around invalid content, an unknown function.
    #[error(transparent)]
    Rtu(#[from] DecodeError),
    /// A Modbus TCP frame: a bad header, a length that does not add up, invalid content.
    #[error(transparent)]
    Tcp(#[from] tcp::DecodeError),
}

impl wire::Resync for Damage {
    fn drop_len(&self) -> usize {
        match self {
            Self::Rtu(e) => e.drop_len(),
            Self::Tcp(e) => e.drop_len(),
        }
    }
}

/// RTU responses, their errors as [`Damage`].
#[derive(Debug, Clone, Copy, Default)]
struct RtuResponses;

impl wire::Codec for RtuResponses {
    type Frame = ResponseAdu;
    type Error = Damage;

    fn decode(&self, buf: &[u8]) -> Result<Option<(ResponseAdu, usize)>, Damage> {
        Ok(ResponseCodec.decode(buf)?)
    }

    fn encode(&self, frame: &ResponseAdu, out: &mut Vec<u8>) {
        ResponseCodec.encode(frame, out);
    }
}

/// Modbus TCP responses, their errors as [`Damage`].
#[derive(Debug, Clone, Copy, Default)]
struct TcpResponses;

impl wire::Codec for TcpResponses {
    type Frame = Mbap<ResponseAdu>;
    type Error = Damage;

    fn decode(&self, buf: &[u8]) -> Result<Option<(Mbap<ResponseAdu>, usize)>, Damage> {
        Ok(tcp::ResponseCodec.decode(buf)?)
    }

    fn encode(&self, frame: &Mbap<ResponseAdu>, out: &mut Vec<u8>) {
        tcp::ResponseCodec.encode(frame, out);
    }
}

/// A unit understood the request and refused it with an exception.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnitRefusal {
    /// The unit that answered.
    pub unit: u8,
    /// The request, in words.
    pub request: String,
    /// The function refused and why.
    pub exception: Exception,
}

impl wire::exchange::Refusal for UnitRefusal {
    fn describe(&self, _endpoint: &str, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.exception.code.is_target_silent() {
            return write!(
                f,
                "unit {} did not answer \"{}\": the Modbus gateway in between says {}",
                self.unit, self.request, self.exception.code
            );
        }
        write!(
            f,
            "unit {} refused \"{}\": {}",
            self.unit, self.request, self.exception.code
        )
    }

    /// A gateway's "no path" or "no answer from the target" is the unit's silence.
    fn kind(&self) -> FailureKind {
        if self.exception.code.is_target_silent() {
            FailureKind::Timeout
        } else {
            FailureKind::Refused
        }
    }
}

impl Failure for Mismatch {
    /// An answer that does not fit the request: a frame damaged in a way the CRC let
    /// through, or another master's traffic.
    fn kind(&self) -> FailureKind {
        FailureKind::Damaged
    }
}

/// The exception code of `error`, when the unit refused the request.
pub fn exception_code(error: &ClientError) -> Option<ExceptionCode> {
    error.refusal().map(|refusal| refusal.exception.code)
}

/// A Modbus master on one (possibly shared) line. Clone it to give each task its own
/// handle: clones queue for the same line (and, over Modbus TCP, share the transaction
/// ids).
#[derive(Debug, Clone)]
pub struct Client {
    line: SharedLine,
    config: ClientConfig,
    /// The last Modbus TCP transaction id given out.
    transaction: Arc<AtomicU16>,
}

impl Client {
    /// A client on `line`.
    pub fn new(line: SharedLine, config: ClientConfig) -> Self {
        Self {
            line,
            config,
            transaction: Arc::new(AtomicU16::new(0)),
        }
    }

    /// The next Modbus TCP transaction id: 1 first, wrapping after 65535.
    fn next_transaction(&self) -> TransactionId {
        TransactionId(self.transaction.fetch_add(1, Ordering::Relaxed)).next()
    }

    /// The bytes of `adu` in the client's framing (a new transaction id for Modbus TCP).
    fn frame(&self, adu: RequestAdu) -> (Vec<u8>, TransactionId) {
        match self.config.framing {
            Framing::Rtu => (adu.to_bytes(), TransactionId::default()),
            Framing::Tcp => {
                let transaction = self.next_transaction();
                (Mbap { transaction, adu }.to_bytes(), transaction)
            }
        }
    }

    /// The client's settings.
    pub fn config(&self) -> &ClientConfig {
        &self.config
    }

    /// The shared line, to make clients with other settings on it.
    pub fn line(&self) -> &SharedLine {
        &self.line
    }

    /// Function 1: `count` (1–2000) coils from `address`.
    pub async fn read_coils(
        &mut self,
        unit: UnitId,
        address: u16,
        count: u16,
    ) -> Result<Vec<bool>, ClientError> {
        let request = Request::read_coils(address, count)?;
        self.read_bits(unit, request).await
    }

    /// Function 2: `count` (1–2000) discrete inputs from `address`.
    pub async fn read_discrete_inputs(
        &mut self,
        unit: UnitId,
        address: u16,
        count: u16,
    ) -> Result<Vec<bool>, ClientError> {
        let request = Request::read_discrete_inputs(address, count)?;
        self.read_bits(unit, request).await
    }

    /// Function 3: `count` (1–125) holding registers from `address`.
    pub async fn read_holding_registers(
        &mut self,
        unit: UnitId,
        address: u16,
        count: u16,
    ) -> Result<Vec<u16>, ClientError> {
        let request = Request::read_holding_registers(address, count)?;
        self.read_registers(unit, request).await
    }

    /// Function 4: `count` (1–125) input registers from `address`.
    pub async fn read_input_registers(
        &mut self,
        unit: UnitId,
        address: u16,
        count: u16,
    ) -> Result<Vec<u16>, ClientError> {
        let request = Request::read_input_registers(address, count)?;
        self.read_registers(unit, request).await
    }

    /// Function 5: switches one coil on or off.
    pub async fn write_single_coil(
        &mut self,
        unit: UnitId,
        address: u16,
        value: bool,
    ) -> Result<(), ClientError> {
        self.write(unit, Request::write_single_coil(address, value))
            .await
    }

    /// Function 6: writes one holding register.
    pub async fn write_single_register(
        &mut self,
        unit: UnitId,
        address: u16,
        value: u16,
    ) -> Result<(), ClientError> {
        self.write(unit, Request::write_single_register(address, value))
            .await
    }

    /// Function 15: writes 1–1968 coils from `address`.
    pub async fn write_multiple_coils(
        &mut self,
        unit: UnitId,
        address: u16,
        values: &[bool],
    ) -> Result<(), ClientError> {
        let request = Request::write_multiple_coils(address, values.to_vec())?;
        self.write(unit, request).await
    }

    /// Function 16: writes 1–123 holding registers from `address`.
    pub async fn write_multiple_registers(
        &mut self,
        unit: UnitId,
        address: u16,
        values: &[u16],
    ) -> Result<(), ClientError> {
        let request = Request::write_multiple_registers(address, values.to_vec())?;
        self.write(unit, request).await
    }

    /// Sends `request` to its unit and returns the checked answer (never
    /// [`Answer::Exception`]: a refusal is [`ClientError::Exception`]).
    pub async fn request(&mut self, request: &Addressed) -> Result<Answer, ClientError> {
        let (bytes, transaction) = self.frame(request.to_adu());
        let mut line = self.line.lock().await;
        if self.config.framing == Framing::Tcp {
            // No CRC, no silence, no character time: the answer comes whole, or a header
            // says how much is missing; a half frame is damage once the line falls quiet.
            let policy =
                Policy::new(self.config.retries, self.config.timeout).with_quiet_gap(MIN_QUIET_GAP);
            let matcher = TcpAnswering {
                request: request.clone(),
                transaction,
            };
            let mut exchange = Exchange::new(matcher, TcpResponses, bytes, policy);
            return link::exchange::run(&mut line, &mut exchange).await;
        }
        let silence = inter_frame_silence(&line);
        let timeout = self.config.timeout
            + line.wire_time(bytes.len() + expected_answer_len(&request.request));
        let policy =
            Policy::new(self.config.retries, timeout).with_quiet_gap(MIN_QUIET_GAP.max(silence));
        let matcher = Answering {
            request: request.clone(),
            silence,
        };
        let mut exchange = Exchange::new(matcher, RtuResponses, bytes, policy);
        link::exchange::run(&mut line, &mut exchange).await
    }

    /// Sends a write to every unit on the line (unit 0). Nobody answers; the line is then
    /// kept quiet for [`ClientConfig::turnaround`] and the inter-frame silence.
    pub async fn broadcast(&mut self, write: &Broadcast) -> Result<(), ClientError> {
        let (bytes, _) = self.frame(write.to_adu());
        let mut line = self.line.lock().await;
        let sent = async {
            line.discard_input().await?;
            line.send(&bytes).await
        }
        .await;
        if let Err(source) = sent {
            return Err(ClientError::Line {
                endpoint: line.name().to_owned(),
                source,
            });
        }
        // A serial port may return before the last byte left: count the frame's wire time.
        let quiet =
            line.wire_time(bytes.len()) + self.config.turnaround + inter_frame_silence(&line);
        line.keep_quiet_until(Instant::now() + quiet);
        Ok(())
    }

    async fn read_bits(
        &mut self,
        unit: UnitId,
        request: Request,
    ) -> Result<Vec<bool>, ClientError> {
        match self.request(&Addressed::new(unit, request)).await? {
            Answer::Bits(bits) => Ok(bits),
            other => unreachable_answer(other),
        }
    }

    async fn read_registers(
        &mut self,
        unit: UnitId,
        request: Request,
    ) -> Result<Vec<u16>, ClientError> {
        match self.request(&Addressed::new(unit, request)).await? {
            Answer::Registers(values) => Ok(values),
            other => unreachable_answer(other),
        }
    }

    async fn write(&mut self, unit: UnitId, request: Request) -> Result<(), ClientError> {
        self.request(&Addressed::new(unit, request)).await.map(drop)
    }
}

/// `check_response` gives a read's kind of answer for a read: another kind cannot come.
#[allow(
    clippy::result_large_err,
    reason = "it never returns: typed as the client's result so it fits the match arms"
)]
fn unreachable_answer<T>(answer: Answer) -> Result<T, ClientError> {
    unreachable!("check_response answers a read with its own kind of values, not {answer:?}")
}

/// The silence before each frame on `line`: 3.5 characters at its speed and format, 1.75 ms
/// above 19200 baud, none when the line's speed is unknown.
pub fn inter_frame_silence(line: &Line) -> Duration {
    line.settings()
        .and_then(|s| LineTiming::new(s.baud, s.bits_per_char()).ok())
        .map_or(Duration::ZERO, |timing| timing.inter_frame_silence())
}

/// The length of a normal answer to `request`, to count its wire time.
pub fn expected_answer_len(request: &Request) -> usize {
    // unit, function, CRC; reads add a byte count and the data, writes an echo of 4 bytes.
    const FIXED: usize = 4;
    match request {
        Request::ReadCoils(r) | Request::ReadDiscreteInputs(r) => {
            FIXED + 1 + crate::rtu::packed_len(usize::from(r.count().get()))
        }
        Request::ReadHoldingRegisters(r) | Request::ReadInputRegisters(r) => {
            FIXED + 1 + 2 * usize::from(r.count().get())
        }
        _ => FIXED + 4,
    }
}

/// The verdict on a well-formed response to `request`: what [`check_response`] says.
fn verdict(request: &Addressed, adu: &ResponseAdu) -> Verdict<Answer, UnitRefusal, Trouble> {
    match check_response(request, adu) {
        Ok(Answer::Exception(exception)) => Verdict::Refused(UnitRefusal {
            unit: request.unit.get(),
            request: request.request.to_string(),
            exception,
        }),
        Ok(answer) => Verdict::Answer(answer),
        Err(mismatch) => {
            tracing::debug!(%mismatch, "skipping a frame that does not answer the request");
            Verdict::Note(Trouble::Mismatch(mismatch))
        }
    }
}

/// What answers one request: a frame [`check_response`] accepts.
struct Answering {
    request: Addressed,
    /// The inter-frame silence kept after every attempt.
    silence: Duration,
}

impl Matcher for Answering {
    type Codec = RtuResponses;
    type Answer = Answer;
    type Refusal = UnitRefusal;
    type Mismatch = Mismatch;

    fn judge(&mut self, input: Result<ResponseAdu, Damage>) -> VerdictOf<Self> {
        match input {
            Ok(adu) => verdict(&self.request, &adu),
            // A byte that starts no frame: noise between frames.
            Err(Damage::Rtu(DecodeError::UnknownFunction { .. })) => Verdict::Noise,
            // Probably the answer, damaged: retry as soon as the line falls quiet.
            Err(damage) => Verdict::RetryWhenQuiet(Trouble::Damaged(damage)),
        }
    }

    /// The silence ended a frame: look past its head.
    fn look_past(&mut self, buffered: &[u8]) -> Option<(usize, VerdictOf<Self>)> {
        let (offset, adu, len) = find_frame(&ResponseCodec, buffered)?;
        Some((offset + len, verdict(&self.request, &adu)))
    }

    /// Whatever happened, the next frame on this line waits for the silence (a zero wait
    /// would still cost a timer tick: tokio rounds deadlines up to 1 ms).
    fn quiet_after(&mut self, attempt: &AttemptEnd) -> Option<std::time::Instant> {
        (!self.silence.is_zero()).then(|| attempt.ended + self.silence)
    }

    fn device(&self) -> String {
        format!("unit {}", self.request.unit.get())
    }

    fn request_in_words(&self) -> Option<String> {
        Some(self.request.request.to_string())
    }
}

/// What answers one request over Modbus TCP: a frame of the same transaction and unit that
/// [`check_response`] accepts. Frames of other transactions or units are dropped.
struct TcpAnswering {
    request: Addressed,
    transaction: TransactionId,
}

impl TcpAnswering {
    fn judge_frame(&self, frame: &Mbap<ResponseAdu>) -> VerdictOf<Self> {
        let unit = self.request.unit.get();
        if frame.transaction != self.transaction || frame.adu.unit != unit {
            tracing::debug!(
                expected_transaction = %self.transaction,
                transaction = %frame.transaction,
                expected_unit = unit,
                unit = frame.adu.unit,
                "dropping a Modbus TCP frame of another transaction or unit"
            );
            // Our transaction answered by another unit: likely a wrong unit number.
            if frame.transaction == self.transaction {
                return Verdict::SkipFrom(format!("unit {}", frame.adu.unit));
            }
            return Verdict::Skip;
        }
        verdict(&self.request, &frame.adu)
    }
}

impl Matcher for TcpAnswering {
    type Codec = TcpResponses;
    type Answer = Answer;
    type Refusal = UnitRefusal;
    type Mismatch = Mismatch;

    fn judge(&mut self, input: Result<Mbap<ResponseAdu>, Damage>) -> VerdictOf<Self> {
        match input {
            Ok(frame) => self.judge_frame(&frame),
            // Bytes that are no MBAP header: noise (or a stream out of step).
            Err(Damage::Tcp(
                tcp::DecodeError::Protocol { .. } | tcp::DecodeError::Length { .. },
            )) => Verdict::Noise,
            Err(damage) => Verdict::RetryWhenQuiet(Trouble::Damaged(damage)),
        }
    }

    /// The line fell quiet inside what a header announced: a frame behind it, if any.
    fn look_past(&mut self, buffered: &[u8]) -> Option<(usize, VerdictOf<Self>)> {
        let (offset, frame, len) = find_frame(&tcp::ResponseCodec, buffered)?;
        Some((offset + len, self.judge_frame(&frame)))
    }

    fn device(&self) -> String {
        format!("unit {}", self.request.unit.get())
    }

    fn request_in_words(&self) -> Option<String> {
        Some(self.request.request.to_string())
    }
}

#[cfg(test)]
mod tests;
