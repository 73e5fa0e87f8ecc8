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
mod tests {
    use std::time::Instant as StdInstant;

    use link::SerialSettings;
    use testkit::{Tap, Trick, Tricky};
    use wire::device::{Device, SharedModel};

    use super::*;
    use crate::cross::device::{CrossTwin, REPLY_DELAY};
    use crate::cross::{Feed, Source};
    use crate::rtu::{FunctionCode, RegisterValues, Response, Write, WriteRegister};
    use crate::slave::{DEFAULT_REPLY_DELAY, Slave, SlaveMap, Table};

    /// Bytes before the answer that look like the head of a 255-byte answer.
    fn long_head() -> Trick {
        Trick::Before(vec![0x07, 0x03, 0xFA])
    }

    /// Another unit's answer before the answer.
    fn stray_first() -> Trick {
        let stray = ResponseAdu {
            unit: 99,
            response: Response::ReadHoldingRegisters(
                RegisterValues::new(vec![1, 2]).expect("2 values"),
            ),
        };
        Trick::Before(stray.to_bytes())
    }

    /// `unit` answers function 3 with exception `code` instead.
    fn refuse(unit: u8, code: u8) -> Trick {
        let refusal = ResponseAdu {
            unit,
            response: Response::exception(
                FunctionCode::READ_HOLDING_REGISTERS,
                ExceptionCode::new(code).expect("test codes are 1-255"),
            ),
        };
        Trick::Replace(refusal.to_bytes())
    }

    struct Bench {
        client: Client,
        tap: Tap,
    }

    impl Bench {
        fn requests(&self) -> usize {
            self.tap.requests()
        }

        fn heard_at(&self, index: usize) -> StdInstant {
            self.tap.request_at(index).expect("heard")
        }
    }

    /// A client on a line (`settings` if it has a speed) to `device`, with `tricks`.
    fn bench<D: Device>(
        device: D,
        tricks: Vec<Trick>,
        settings: Option<SerialSettings>,
        config: ClientConfig,
    ) -> Bench {
        let device = Tricky::new(device, tricks);
        let tap = device.tap();
        let (ours, theirs) = tokio::io::duplex(4096);
        tokio::spawn(link::serve::serve_stream(theirs, device, None));
        let line = SharedLine::new(Line::from_stream(ours, "test line", settings));
        Bench {
            client: Client::new(line, config),
            tap,
        }
    }

    fn unit(number: u8) -> UnitId {
        UnitId::new(number).expect("test unit")
    }

    fn twin() -> SharedModel<CrossTwin> {
        SharedModel::new(CrossTwin::new(unit(2), 7))
    }

    fn slave() -> SharedModel<Slave> {
        SharedModel::new(Slave::all_writable(unit(1)))
    }

    fn at_9600() -> Option<SerialSettings> {
        Some(SerialSettings::new_8n1(9600))
    }

    #[tokio::test(start_paused = true)]
    async fn every_function_reads_and_writes_a_generic_server() {
        let server = slave();
        let mut b = bench(server.line(), vec![], None, ClientConfig::default());
        let c = &mut b.client;
        c.write_single_coil(unit(1), 3, true)
            .await
            .expect("written");
        c.write_multiple_coils(unit(1), 10, &[true, false, true, true])
            .await
            .expect("written");
        assert_eq!(
            c.read_coils(unit(1), 2, 12).await.expect("read"),
            [
                false, true, false, false, false, false, false, false, true, false, true, true
            ]
        );
        c.write_single_register(unit(1), 100, 0xBEEF)
            .await
            .expect("written");
        c.write_multiple_registers(unit(1), 101, &[1, 2, 3])
            .await
            .expect("written");
        assert_eq!(
            c.read_holding_registers(unit(1), 100, 4)
                .await
                .expect("read"),
            [0xBEEF, 1, 2, 3]
        );
        {
            let mut s = server.lock();
            s.set(Table::DiscreteInputs, 7, 1);
            s.set(Table::InputRegisters, 30, 4242);
        }
        assert_eq!(
            c.read_discrete_inputs(unit(1), 6, 3).await.expect("read"),
            [false, true, false]
        );
        assert_eq!(
            c.read_input_registers(unit(1), 30, 2).await.expect("read"),
            [4242, 0]
        );
        assert_eq!(b.requests(), 8);
    }

    #[tokio::test(start_paused = true)]
    async fn cross_read_decodes_the_twin_in_four_requests_and_sees_a_transfer() {
        let cross = twin();
        let mut b = bench(cross.line(), vec![], at_9600(), ClientConfig::default());
        let state = crate::cross::read(&mut b.client, unit(2))
            .await
            .expect("read");
        assert_eq!(state.feed(), Feed::StaticSwitch(Source::S1));
        assert!(state.alarms().is_empty(), "{:?}", state.alarms());
        assert_eq!(b.requests(), 4);
        cross.lock().fail_source(Source::S1);
        let state = crate::cross::read(&mut b.client, unit(2))
            .await
            .expect("read");
        assert_eq!(state.feed(), Feed::StaticSwitch(Source::S2));
        assert!(
            state.alarms().iter().any(|a| a.contains("S1 failure")),
            "{:?}",
            state.alarms()
        );
    }

    #[tokio::test(start_paused = true)]
    async fn an_exception_is_reported_at_once_in_words_and_never_retried() {
        let mut b = bench(twin().line(), vec![], None, ClientConfig::default());
        let started = Instant::now();
        let err = b
            .client
            .read_holding_registers(unit(2), 0x12, 2)
            .await
            .expect_err("0x12 is undefined");
        assert_eq!(
            exception_code(&err),
            Some(ExceptionCode::ILLEGAL_DATA_ADDRESS)
        );
        assert_eq!(
            err.to_string(),
            "unit 2 refused \"read 2 holding registers from 18 (0x0012)\": exception 2 \
             (illegal data address: the request touches an address the device does not have)"
        );
        assert!(err.is_device_error());
        assert_eq!(err.kind(), FailureKind::Refused);
        assert_eq!(b.requests(), 1);
        assert_eq!(started.elapsed(), REPLY_DELAY);
    }

    #[tokio::test(start_paused = true)]
    async fn the_cross_refuses_any_function_but_3_with_exception_1() {
        let mut b = bench(twin().line(), vec![], None, ClientConfig::default());
        let err = b
            .client
            .read_input_registers(unit(2), 0, 1)
            .await
            .expect_err("function 4 is unknown to a CROSS");
        assert!(
            matches!(
                err,
                ClientError::Refused {
                    refusal: UnitRefusal {
                        unit: 2,
                        exception: Exception {
                            function: FunctionCode::READ_INPUT_REGISTERS,
                            code: ExceptionCode::ILLEGAL_FUNCTION
                        },
                        ..
                    },
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("illegal function"), "{err}");
    }

    #[tokio::test(start_paused = true)]
    async fn exception_3_is_reported_with_its_number_and_meaning() {
        let mut b = bench(
            slave().line(),
            vec![refuse(1, 3)],
            None,
            ClientConfig::default(),
        );
        let err = b
            .client
            .read_holding_registers(unit(1), 0, 100)
            .await
            .expect_err("refused");
        assert_eq!(
            exception_code(&err),
            Some(ExceptionCode::ILLEGAL_DATA_VALUE)
        );
        assert!(
            err.to_string().contains("exception 3 (illegal data value"),
            "{err}"
        );
        assert_eq!(b.requests(), 1);
    }

    #[tokio::test(start_paused = true)]
    async fn an_address_missing_from_a_slave_map_is_exception_2() {
        let map = SlaveMap::parse("unit 5\nholding 0 = 1 2 3\n").expect("valid map");
        let server = SharedModel::new(Slave::new(map));
        let mut b = bench(server.line(), vec![], None, ClientConfig::default());
        assert_eq!(
            b.client
                .read_holding_registers(unit(5), 0, 3)
                .await
                .expect("defined"),
            [1, 2, 3]
        );
        let err = b
            .client
            .write_single_register(unit(5), 3, 9)
            .await
            .expect_err("3 is not in the map");
        assert_eq!(
            exception_code(&err),
            Some(ExceptionCode::ILLEGAL_DATA_ADDRESS)
        );
    }

    #[tokio::test(start_paused = true)]
    async fn a_late_answer_waiting_on_the_line_is_dropped_not_taken_for_the_answer() {
        use tokio::io::AsyncWriteExt as _;
        let (ours, mut theirs) = tokio::io::duplex(4096);
        // An answer to the same request that came too late for an earlier exchange.
        let stale = ResponseAdu {
            unit: 1,
            response: Response::ReadHoldingRegisters(
                RegisterValues::new(vec![0xDEAD, 0xBEEF]).expect("2 values"),
            ),
        };
        theirs.write_all(&stale.to_bytes()).await.expect("buffered");
        tokio::spawn(link::serve::serve_stream(theirs, slave().line(), None));
        let line = SharedLine::new(Line::from_stream(ours, "test line", None));
        let mut client = Client::new(line, ClientConfig::default());
        let started = Instant::now();
        let words = client
            .read_holding_registers(unit(1), 0, 2)
            .await
            .expect("the server answers");
        assert_eq!(words, [0, 0], "the server's registers, not the stale ones");
        assert_eq!(
            started.elapsed(),
            DEFAULT_REPLY_DELAY,
            "no wait to drop them"
        );
    }

    #[tokio::test(start_paused = true)]
    async fn a_lost_answer_is_retried_after_the_timeout() {
        let mut b = bench(
            twin().line(),
            vec![Trick::Drop],
            None,
            ClientConfig::default(),
        );
        let started = Instant::now();
        b.client
            .read_holding_registers(unit(2), 0x46, 20)
            .await
            .expect("answered on the second attempt");
        assert_eq!(started.elapsed(), DEFAULT_TIMEOUT + REPLY_DELAY);
        assert_eq!(b.requests(), 2);
    }

    #[tokio::test(start_paused = true)]
    async fn a_dead_unit_gives_up_after_every_attempt_naming_endpoint_unit_and_attempts() {
        let mut b = bench(twin().line(), vec![], None, ClientConfig::default());
        let started = Instant::now();
        let err = b
            .client
            .read_holding_registers(unit(9), 0, 1)
            .await
            .expect_err("nobody is unit 9");
        assert_eq!(started.elapsed(), DEFAULT_TIMEOUT * 3);
        assert_eq!(
            err.to_string(),
            "no valid answer from unit 9 on test line to \"read 1 holding register from 0 \
             (0x0000)\" after 3 attempts of 500 ms each (last: no reply)"
        );
        assert_eq!(b.requests(), 3);
    }

    #[tokio::test(start_paused = true)]
    async fn the_timeout_counts_the_wire_time_of_request_and_answer() {
        let mut b = bench(twin().line(), vec![], at_9600(), ClientConfig::default());
        let err = b
            .client
            .read_holding_registers(unit(9), 0, 125)
            .await
            .expect_err("nobody is unit 9");
        // 8 + 255 bytes at 1.0417 ms each.
        let ClientError::NoAnswer { timeout, .. } = err else {
            panic!("{err}")
        };
        assert_eq!(timeout, DEFAULT_TIMEOUT + Duration::from_nanos(273_958_333));
    }

    #[tokio::test(start_paused = true)]
    async fn a_damaged_answer_is_retried_when_the_line_falls_quiet_not_after_the_timeout() {
        let mut b = bench(
            twin().line(),
            vec![Trick::corrupt_last()],
            None,
            ClientConfig::default(),
        );
        let started = Instant::now();
        b.client
            .read_holding_registers(unit(2), 0x00, 18)
            .await
            .expect("answered on the second attempt");
        assert_eq!(started.elapsed(), REPLY_DELAY + MIN_QUIET_GAP + REPLY_DELAY);
        assert_eq!(b.requests(), 2);
    }

    #[tokio::test(start_paused = true)]
    async fn damage_on_every_attempt_is_reported_as_the_last_trouble() {
        let mut b = bench(
            twin().line(),
            vec![Trick::corrupt_last(); 3],
            None,
            ClientConfig::default(),
        );
        let err = b
            .client
            .read_holding_registers(unit(2), 0x14, 4)
            .await
            .expect_err("damaged every time");
        assert!(
            matches!(
                err,
                ClientError::NoAnswer {
                    attempts: 3,
                    last: Trouble::Damaged(Damage::Rtu(DecodeError::Crc { .. }))
                        | Trouble::Incomplete { .. },
                    ..
                }
            ),
            "{err}"
        );
    }

    #[tokio::test(start_paused = true)]
    async fn bytes_that_look_like_a_long_frame_do_not_hold_the_answer_back() {
        let mut b = bench(
            twin().line(),
            vec![long_head()],
            None,
            ClientConfig::default(),
        );
        let started = Instant::now();
        let words = b
            .client
            .read_holding_registers(unit(2), 0x1E, 17)
            .await
            .expect("found behind the garbage");
        assert_eq!(words.len(), 17);
        // Found when the line fell quiet, on the first attempt.
        assert_eq!(started.elapsed(), REPLY_DELAY + MIN_QUIET_GAP);
        assert_eq!(b.requests(), 1);
    }

    #[tokio::test(start_paused = true)]
    async fn an_answer_that_does_not_match_is_skipped() {
        let mut b = bench(
            twin().line(),
            vec![stray_first()],
            None,
            ClientConfig::default(),
        );
        let words = b
            .client
            .read_holding_registers(unit(2), 0x2E, 1)
            .await
            .expect("the real answer follows");
        assert_eq!(words, [crate::cross::device::PROTOCOL_REVISION]);
        assert_eq!(b.requests(), 1);
    }

    #[tokio::test(start_paused = true)]
    async fn an_answer_from_another_unit_is_never_accepted() {
        // The answer to the read below, from unit 3 (with a good CRC).
        let wrong_unit = Trick::Replace(
            ResponseAdu {
                unit: 3,
                response: Response::ReadHoldingRegisters(
                    RegisterValues::new(vec![crate::cross::device::PROTOCOL_REVISION])
                        .expect("1 value"),
                ),
            }
            .to_bytes(),
        );
        let mut b = bench(
            twin().line(),
            vec![wrong_unit; 3],
            None,
            ClientConfig::default(),
        );
        let err = b
            .client
            .read_holding_registers(unit(2), 0x2E, 1)
            .await
            .expect_err("only wrong units answered");
        assert!(
            matches!(
                err,
                ClientError::NoAnswer {
                    last: Trouble::Mismatch(Mismatch::UnitId {
                        expected: 2,
                        actual: 3
                    }),
                    ..
                }
            ),
            "{err}"
        );
        assert_eq!(b.requests(), 3);
    }

    /// Time from the end of the first answer to the second request.
    async fn gap_between_exchanges(settings: Option<SerialSettings>) -> Duration {
        let mut b = bench(slave().line(), vec![], settings, ClientConfig::default());
        b.client
            .read_holding_registers(unit(1), 0, 1)
            .await
            .expect("read");
        b.client
            .read_holding_registers(unit(1), 0, 1)
            .await
            .expect("read");
        let answered = b.heard_at(0) + DEFAULT_REPLY_DELAY;
        b.heard_at(1).duration_since(answered)
    }

    #[tokio::test(start_paused = true)]
    async fn each_request_waits_3_5_character_times_after_the_last_frame() {
        let gap = gap_between_exchanges(at_9600()).await;
        let silence = Duration::from_nanos(3_645_834);
        // tokio's timers tick in milliseconds: the wait ends on the next tick.
        assert!(
            gap >= silence && gap < silence + Duration::from_millis(1),
            "{gap:?}"
        );
    }

    #[tokio::test(start_paused = true)]
    async fn above_19200_baud_the_silence_is_1_75_ms() {
        let gap = gap_between_exchanges(Some(SerialSettings::new_8e1(38_400))).await;
        let silence = Duration::from_micros(1_750);
        assert!(
            gap >= silence && gap < silence + Duration::from_millis(1),
            "{gap:?}"
        );
    }

    #[tokio::test(start_paused = true)]
    async fn a_line_without_a_speed_has_no_silence() {
        assert_eq!(gap_between_exchanges(None).await, Duration::ZERO);
    }

    #[tokio::test(start_paused = true)]
    async fn a_broadcast_is_never_answered_and_the_line_stays_quiet_for_the_turnaround() {
        let server = slave();
        let mut b = bench(server.line(), vec![], at_9600(), ClientConfig::default());
        let started = Instant::now();
        let write = Broadcast(Write::SingleRegister(WriteRegister {
            address: 4,
            value: 77,
        }));
        b.client.broadcast(&write).await.expect("sent");
        assert_eq!(started.elapsed(), Duration::ZERO, "no wait for an answer");
        assert_eq!(
            b.client
                .read_holding_registers(unit(1), 4, 1)
                .await
                .expect("read"),
            [77]
        );
        assert_eq!(server.lock().counters().broadcasts, 1);
        let quiet = b.heard_at(1).duration_since(b.heard_at(0));
        // 8 bytes on the wire, the turnaround, the silence.
        let least =
            Duration::from_nanos(8_333_334) + DEFAULT_TURNAROUND + Duration::from_nanos(3_645_834);
        assert!(
            quiet >= least && quiet < least + Duration::from_millis(1),
            "{quiet:?}"
        );
    }

    #[tokio::test(start_paused = true)]
    async fn a_dead_unit_delays_the_others_on_its_line_only_by_its_own_timeouts() {
        let cross = twin();
        let server = slave();
        let bus = wire::device::Bus(vec![Box::new(cross.line()), Box::new(server.line())]);
        let b = bench(bus, vec![], None, ClientConfig::default());
        let mut dead = b.client.clone();
        let mut alive = b.client.clone();
        let started = Instant::now();
        let dead_task =
            tokio::spawn(async move { dead.read_holding_registers(unit(9), 0, 1).await });
        tokio::task::yield_now().await;
        let alive_task = tokio::spawn(async move {
            let state = crate::cross::read(&mut alive, unit(2)).await;
            let first = Instant::now();
            let words = alive.read_holding_registers(unit(1), 0, 2).await;
            (state, first, words)
        });
        let dead_result = dead_task.await.expect("task ran");
        let (state, first, words) = alive_task.await.expect("task ran");
        assert!(matches!(
            dead_result,
            Err(ClientError::NoAnswer { ref device, .. }) if device == "unit 9"
        ));
        assert_eq!(state.expect("read").feed(), Feed::StaticSwitch(Source::S1));
        assert_eq!(words.expect("read"), [0, 0]);
        // The dead unit's three timeouts, then the CROSS's four reads, then one more.
        assert_eq!(
            first.duration_since(started),
            DEFAULT_TIMEOUT * 3 + REPLY_DELAY * 4
        );
        assert_eq!(Instant::now().duration_since(first), DEFAULT_REPLY_DELAY);
        // 3 attempts for the dead unit, 4 + 1 requests for the others, never interleaved.
        assert_eq!(b.requests(), 8);
    }

    #[tokio::test(start_paused = true)]
    async fn a_closed_line_fails_at_once_naming_it() {
        let (ours, theirs) = tokio::io::duplex(64);
        drop(theirs);
        let line = SharedLine::new(Line::from_stream(ours, "gone line", None));
        let mut client = Client::new(line, ClientConfig::default());
        let err = client
            .read_holding_registers(unit(1), 0, 1)
            .await
            .expect_err("closed");
        assert!(matches!(err, ClientError::Line { .. }), "{err}");
        assert!(err.to_string().contains("gone line"), "{err}");
    }

    // --- Modbus TCP ---

    fn over_tcp() -> ClientConfig {
        ClientConfig {
            framing: Framing::Tcp,
            ..ClientConfig::default()
        }
    }

    /// `device` (RTU) served over Modbus TCP, with `tricks` on its MBAP replies.
    fn tcp_bench<D: Device>(device: D, tricks: Vec<Trick>) -> Bench {
        bench(
            crate::tcp::MbapServer::new(device),
            tricks,
            None,
            over_tcp(),
        )
    }

    /// Unit 1's answer to a read of `values.len()` holding registers, in transaction `t`.
    fn registers_in(t: u16, values: Vec<u16>) -> Vec<u8> {
        Mbap {
            transaction: TransactionId(t),
            adu: ResponseAdu {
                unit: 1,
                response: Response::ReadHoldingRegisters(
                    RegisterValues::new(values).expect("test values"),
                ),
            },
        }
        .to_bytes()
    }

    /// The transaction ids of the requests the device heard.
    fn transactions(tap: &Tap) -> Vec<u16> {
        tap.traffic()
            .iter()
            .filter(|t| !t.from_device)
            .map(|t| u16::from_be_bytes([t.bytes[0], t.bytes[1]]))
            .collect()
    }

    #[tokio::test(start_paused = true)]
    async fn every_function_reads_and_writes_a_generic_server_over_modbus_tcp() {
        let server = slave();
        let mut b = tcp_bench(server.line(), vec![]);
        let c = &mut b.client;
        c.write_single_coil(unit(1), 3, true)
            .await
            .expect("written");
        c.write_multiple_coils(unit(1), 10, &[true, false, true])
            .await
            .expect("written");
        assert_eq!(
            c.read_coils(unit(1), 2, 10).await.expect("read"),
            [
                false, true, false, false, false, false, false, false, true, false
            ]
        );
        c.write_single_register(unit(1), 100, 0xBEEF)
            .await
            .expect("written");
        c.write_multiple_registers(unit(1), 101, &[1, 2])
            .await
            .expect("written");
        assert_eq!(
            c.read_holding_registers(unit(1), 100, 3)
                .await
                .expect("read"),
            [0xBEEF, 1, 2]
        );
        server.lock().set(Table::InputRegisters, 30, 4242);
        assert_eq!(
            c.read_input_registers(unit(1), 30, 1).await.expect("read"),
            [4242]
        );
        assert_eq!(
            c.read_discrete_inputs(unit(1), 0, 2).await.expect("read"),
            [false, false]
        );
        assert_eq!(b.requests(), 8);
        assert_eq!(transactions(&b.tap), [1, 2, 3, 4, 5, 6, 7, 8]);
    }

    #[tokio::test(start_paused = true)]
    async fn a_response_with_another_transaction_id_is_dropped_and_the_right_one_after_it_taken() {
        // A late answer to an earlier transaction, same unit and function, other values.
        let stale = Trick::Before(registers_in(0x7777, vec![0xDEAD, 0xBEEF]));
        let mut b = tcp_bench(slave().line(), vec![stale]);
        let started = Instant::now();
        let words = b
            .client
            .read_holding_registers(unit(1), 0, 2)
            .await
            .expect("the right answer follows");
        assert_eq!(words, [0, 0], "the server's registers, not the stale ones");
        assert_eq!(b.requests(), 1, "not retried");
        assert_eq!(started.elapsed(), DEFAULT_REPLY_DELAY);
    }

    #[tokio::test(start_paused = true)]
    async fn only_responses_of_another_transaction_are_no_answer() {
        let stale = Trick::Replace(registers_in(0x7777, vec![1, 2]));
        let mut b = tcp_bench(slave().line(), vec![stale; 3]);
        let err = b
            .client
            .read_holding_registers(unit(1), 0, 2)
            .await
            .expect_err("never the right transaction");
        assert!(
            matches!(
                err,
                ClientError::NoAnswer {
                    attempts: 3,
                    last: Trouble::Others { frames: 1 },
                    ..
                }
            ),
            "{err}"
        );
        assert!(
            err.to_string()
                .ends_with("(last: no reply, only a frame that answers something else)"),
            "{err}"
        );
        assert_eq!(
            transactions(&b.tap),
            [1, 1, 1],
            "retries repeat the request"
        );
    }

    #[tokio::test(start_paused = true)]
    async fn two_units_share_one_modbus_tcp_connection() {
        let first = SharedModel::new(Slave::all_writable(unit(1)));
        let second = SharedModel::new(Slave::all_writable(unit(2)));
        let bus = wire::device::Bus(vec![Box::new(first.line()), Box::new(second.line())]);
        let mut b = tcp_bench(bus, vec![]);
        let c = &mut b.client;
        c.write_single_register(unit(1), 5, 111)
            .await
            .expect("unit 1");
        c.write_single_register(unit(2), 5, 222)
            .await
            .expect("unit 2");
        assert_eq!(
            c.read_holding_registers(unit(1), 5, 1).await.expect("1"),
            [111]
        );
        assert_eq!(
            c.read_holding_registers(unit(2), 5, 1).await.expect("2"),
            [222]
        );
        assert_eq!(first.lock().get(Table::HoldingRegisters, 5), Some(111));
        assert_eq!(second.lock().get(Table::HoldingRegisters, 5), Some(222));
        let err = c
            .read_holding_registers(unit(3), 5, 1)
            .await
            .expect_err("nobody is unit 3");
        assert!(err.to_string().contains("unit 3"), "{err}");
    }

    #[tokio::test(start_paused = true)]
    async fn a_half_modbus_tcp_frame_then_silence_is_retried_when_the_line_falls_quiet() {
        let whole = registers_in(1, vec![0, 0]);
        let half = Trick::Replace(whole[..9].to_vec());
        let mut b = tcp_bench(slave().line(), vec![half]);
        let started = Instant::now();
        let words = b
            .client
            .read_holding_registers(unit(1), 0, 2)
            .await
            .expect("answered on the second attempt");
        assert_eq!(words, [0, 0]);
        assert_eq!(b.requests(), 2);
        assert_eq!(
            started.elapsed(),
            DEFAULT_REPLY_DELAY + MIN_QUIET_GAP + DEFAULT_REPLY_DELAY
        );
    }

    #[tokio::test(start_paused = true)]
    async fn a_half_modbus_tcp_frame_every_time_is_reported_as_incomplete() {
        let half = Trick::Replace(registers_in(1, vec![0, 0])[..9].to_vec());
        let mut b = tcp_bench(slave().line(), vec![half; 3]);
        let err = b
            .client
            .read_holding_registers(unit(1), 0, 2)
            .await
            .expect_err("never whole");
        assert!(
            matches!(
                err,
                ClientError::NoAnswer {
                    last: Trouble::Incomplete { bytes: 9 },
                    ..
                }
            ),
            "{err}"
        );
    }

    #[tokio::test(start_paused = true)]
    async fn an_exception_over_modbus_tcp_is_the_units_refusal() {
        let map = SlaveMap::parse("unit 1\nholding 0 = 1 2 3\n").expect("valid map");
        let mut b = tcp_bench(SharedModel::new(Slave::new(map)).line(), vec![]);
        let err = b
            .client
            .read_holding_registers(unit(1), 2, 2)
            .await
            .expect_err("3 is not in the map");
        assert_eq!(
            exception_code(&err),
            Some(ExceptionCode::ILLEGAL_DATA_ADDRESS)
        );
        assert_eq!(b.requests(), 1);
    }

    #[tokio::test(start_paused = true)]
    async fn clones_share_the_transaction_ids_which_wrap_after_65535() {
        let mut b = tcp_bench(slave().line(), vec![]);
        b.client.transaction.store(65534, Ordering::Relaxed);
        let mut clone = b.client.clone();
        b.client
            .read_coils(unit(1), 0, 1)
            .await
            .expect("transaction 65535");
        clone
            .read_coils(unit(1), 0, 1)
            .await
            .expect("transaction 0");
        b.client
            .read_coils(unit(1), 0, 1)
            .await
            .expect("transaction 1");
        assert_eq!(transactions(&b.tap), [65535, 0, 1]);
    }

    #[test]
    fn a_modbus_tcp_endpoint_asks_for_tcp_framing() {
        let line = link::SerialSettings::new_8n1(9600);
        let mbap = Endpoint::parse("modbus-tcp://127.0.0.1:502", line).expect("valid");
        let raw = Endpoint::parse("tcp://127.0.0.1:4001", line).expect("valid");
        assert_eq!(Framing::of(&mbap), Framing::Tcp);
        assert_eq!(Framing::of(&raw), Framing::Rtu);
    }

    #[tokio::test(start_paused = true)]
    async fn an_invalid_request_never_reaches_the_wire() {
        let mut b = bench(slave().line(), vec![], None, ClientConfig::default());
        let err = b
            .client
            .read_holding_registers(unit(1), 0, 126)
            .await
            .expect_err("126 registers is too many");
        assert!(matches!(err, ClientError::Request(_)), "{err}");
        assert!(!err.is_device_error());
        assert_eq!(err.kind(), FailureKind::Usage, "our mistake, not a refusal");
        assert_eq!(b.requests(), 0);
    }
}
