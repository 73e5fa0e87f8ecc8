//! One request/response exchange with retries, as a sans-IO state machine: bytes and time
//! go in, bytes to send and deadlines come out. `link` drives it on a line; every
//! request/response protocol (JBC, Thermosald, JBUS) plugs its knowledge in as a
//! [`Matcher`].
//!
//! The methods follow quinn-proto's order: [`Exchange::poll_transmit`] gives the request
//! to send at the start of each attempt, [`Exchange::handle_sent`] starts the attempt's
//! clock, [`Exchange::handle_input`] and [`Exchange::handle_timeout`] feed what the line
//! did, [`Exchange::poll_timeout`] says when to call back, [`Exchange::poll_quiet`] how
//! long the line must then stay quiet, and [`Exchange::poll_outcome`] gives the end.
//!
//! # Policy
//!
//! - An attempt ends with the answer, the device's refusal, or trouble ([`Trouble`]): the
//!   timeout passed in silence, a damaged frame, an answer that does not fit. Trouble is
//!   retried while attempts remain; an answer or a refusal never is.
//! - The matcher judges every decoded frame and every run of dropped bytes ([`Verdict`]):
//!   answer, refused, retry now, retry once the line falls quiet, note and keep listening,
//!   or skip (another device's frame, noise).
//! - With a quiet gap ([`Policy::quiet_gap`]), bytes left undecoded when the line falls
//!   quiet are handed to [`Matcher::look_past`] (RTU frames carry no length, so a broken
//!   head can hold the decoder), and trouble marked "when quiet" ends the attempt then,
//!   without waiting for the timeout.
//! - When the attempts run out, [`Matcher::last_word`] may still take the last trouble as
//!   the device's answer (a Thermosald regulator that echoes another value).
//! - After every attempt, [`Matcher::quiet_after`] says until when the line must stay
//!   quiet (a regulator's release time, Modbus's inter-frame silence).

use std::fmt;
use std::time::{Duration, Instant};

use crate::codec::{Codec, Deframer};
use crate::failure::{Failure, FailureKind};
use crate::words::Bytes;

/// Line trouble on one attempt: what makes an exchange retry.
///
/// `D` is the protocol's decode error, `M` its reason why a well-formed frame is not the
/// answer.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum Trouble<D, M> {
    /// Nothing came.
    Silence,
    /// Only bytes the codec drops as noise came (no frame, nothing that looks damaged):
    /// still no reply, told with what the line carried instead.
    Noise {
        /// How many bytes were dropped.
        bytes: usize,
    },
    /// Only well-formed frames that answer something else came (another address's, a late
    /// answer to an earlier request): still no reply, told with what came instead.
    Others {
        /// How many such frames came.
        frames: usize,
        /// Who sent the last one, where the protocol can tell (`station 01`, `unit 3`):
        /// a device answering at another address than the one configured.
        from: Option<String>,
    },
    /// A damaged frame came.
    Damaged(D),
    /// The line fell quiet after bytes that make no frame.
    Incomplete {
        /// How many bytes were left undecoded.
        bytes: usize,
    },
    /// A well-formed answer that does not fit the request (wrong shape, an echo that
    /// differs, a reported transmission error).
    Mismatch(M),
}

impl<D, M> Trouble<D, M> {
    /// Whether nothing that could be this request's answer came: silence, line noise, or
    /// only frames that answer something else (no device is heard at the address).
    pub fn heard_nothing(&self) -> bool {
        // Every variant named: a new one must be judged here.
        match self {
            Trouble::Silence | Trouble::Noise { .. } | Trouble::Others { .. } => true,
            Trouble::Damaged(_) | Trouble::Incomplete { .. } | Trouble::Mismatch(_) => false,
        }
    }
}

impl<D: fmt::Display, M: fmt::Display> fmt::Display for Trouble<D, M> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Trouble::Silence => f.write_str("no reply"),
            Trouble::Noise { bytes } => {
                write!(f, "no reply, only {} of line noise", Bytes(*bytes))
            }
            Trouble::Others { frames: 1, from } => {
                f.write_str("no reply, only a frame that answers something else")?;
                match from {
                    Some(from) => write!(f, ", from {from}"),
                    None => Ok(()),
                }
            }
            Trouble::Others { frames, from } => {
                write!(
                    f,
                    "no reply, only {frames} frames that answer something else"
                )?;
                match from {
                    Some(from) => write!(f, ", the last from {from}"),
                    None => Ok(()),
                }
            }
            Trouble::Damaged(damage) => write!(f, "damaged reply: {damage}"),
            Trouble::Incomplete { bytes } => {
                write!(
                    f,
                    "the line fell quiet after {} that make no frame",
                    Bytes(*bytes)
                )
            }
            Trouble::Mismatch(mismatch) => write!(f, "{mismatch}"),
        }
    }
}

impl<D, M> std::error::Error for Trouble<D, M>
where
    D: fmt::Debug + fmt::Display,
    M: fmt::Debug + fmt::Display,
{
}

impl<D, M> Failure for Trouble<D, M>
where
    D: fmt::Debug + fmt::Display,
    M: Failure,
{
    fn kind(&self) -> FailureKind {
        match self {
            Trouble::Silence | Trouble::Noise { .. } | Trouble::Others { .. } => {
                FailureKind::Timeout
            }
            Trouble::Damaged(_) | Trouble::Incomplete { .. } => FailureKind::Damaged,
            Trouble::Mismatch(mismatch) => mismatch.kind(),
        }
    }
}

/// A device's refusal, told in words with the line it answered on.
pub trait Refusal: fmt::Debug {
    /// Writes what the device refused and why; `endpoint` names the line.
    fn describe(&self, endpoint: &str, f: &mut fmt::Formatter<'_>) -> fmt::Result;

    /// What the refusal means for the device: [`FailureKind::Refused`] (it is there and
    /// said no), unless the answer comes from a go-between saying the device itself did
    /// not answer ([`FailureKind::Timeout`]: a Modbus gateway's exception 11).
    fn kind(&self) -> FailureKind {
        FailureKind::Refused
    }
}

/// Why a request did not get its answer: one type for every request/response client.
///
/// `Q` is the protocol's error for a request it refuses to build, `R` the device's refusal,
/// `T` its [`Trouble`], `L` the line's error.
#[derive(Debug)]
#[non_exhaustive]
pub enum ExchangeError<Q, R, T, L> {
    /// Our own request was refused before reaching the wire.
    Request(Q),
    /// The device understood the request and refused it.
    Refused {
        /// The line's endpoint as the user named it (`tcp://…`, `serial:///dev/…`).
        endpoint: String,
        /// What the device said.
        refusal: R,
    },
    /// No valid answer within the attempts.
    NoAnswer {
        /// The line's endpoint as the user named it (`tcp://…`, `serial:///dev/…`).
        endpoint: String,
        /// Whom we asked (`station 07`, `regulator 5`, `unit 9`).
        device: String,
        /// The request in words, when the protocol names it in messages.
        request: Option<String>,
        /// Attempts made.
        attempts: u8,
        /// Time waited in each.
        timeout: Duration,
        /// What went wrong on the last attempt.
        last: T,
    },
    /// The line itself failed (closed, I/O error).
    Line {
        /// The line's endpoint as the user named it (`tcp://…`, `serial:///dev/…`).
        endpoint: String,
        /// What happened.
        source: L,
    },
}

impl<Q, R, T, L> ExchangeError<Q, R, T, L> {
    /// Whether the device, its absence or the line is the cause, rather than our request.
    pub fn is_device_error(&self) -> bool {
        !matches!(self, Self::Request(_))
    }

    /// The device's refusal, when it said no.
    pub fn refusal(&self) -> Option<&R> {
        match self {
            Self::Refused { refusal, .. } => Some(refusal),
            _ => None,
        }
    }

    /// The error for an exchange that ended without its answer, on the line `endpoint`.
    pub fn ended<M>(ended: Ended<R, T>, endpoint: &str, matcher: &M) -> Self
    where
        M: Matcher<Refusal = R> + ?Sized,
    {
        match ended {
            Ended::Refused(refusal) => Self::Refused {
                endpoint: endpoint.to_owned(),
                refusal,
            },
            Ended::GaveUp {
                attempts,
                timeout,
                last,
            } => Self::NoAnswer {
                endpoint: endpoint.to_owned(),
                device: matcher.device(),
                request: matcher.request_in_words(),
                attempts,
                timeout,
                last,
            },
        }
    }
}

impl<Q, R, T, L> From<Q> for ExchangeError<Q, R, T, L> {
    /// A request the protocol refused to build.
    fn from(request: Q) -> Self {
        Self::Request(request)
    }
}

impl<Q, R, T, L> fmt::Display for ExchangeError<Q, R, T, L>
where
    Q: fmt::Display,
    R: Refusal,
    T: fmt::Display,
    L: fmt::Display,
{
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Request(request) => write!(f, "{request}"),
            Self::Refused { endpoint, refusal } => refusal.describe(endpoint, f),
            Self::NoAnswer {
                endpoint,
                device,
                request,
                attempts,
                timeout,
                last,
            } => {
                write!(f, "no valid answer from {device} on {endpoint}")?;
                if let Some(request) = request {
                    write!(f, " to \"{request}\"")?;
                }
                write!(
                    f,
                    " after {} of {} each (last: {last})",
                    attempts_in_words(*attempts),
                    millis(*timeout)
                )
            }
            Self::Line { endpoint, source } => write!(f, "line {endpoint} failed: {source}"),
        }
    }
}

impl<Q, R, T, L> std::error::Error for ExchangeError<Q, R, T, L>
where
    Q: std::error::Error,
    R: Refusal,
    T: fmt::Debug + fmt::Display,
    L: std::error::Error + 'static,
{
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Request(request) => request.source(),
            Self::Line { source, .. } => Some(source),
            _ => None,
        }
    }
}

impl<Q, R, T, L> Failure for ExchangeError<Q, R, T, L>
where
    Q: std::error::Error,
    R: Refusal,
    T: Failure,
    L: Failure + 'static,
{
    fn kind(&self) -> FailureKind {
        match self {
            Self::Request(_) => FailureKind::Usage,
            Self::Refused { refusal, .. } => refusal.kind(),
            Self::NoAnswer { last, .. } => last.kind(),
            Self::Line { source, .. } => source.kind(),
        }
    }
}

/// `1 attempt`, `3 attempts`.
fn attempts_in_words(attempts: u8) -> String {
    match attempts {
        1 => "1 attempt".to_owned(),
        n => format!("{n} attempts"),
    }
}

/// A timeout as a plant engineer reads it: `500 ms`, `422 ms`, `1.5 s`.
fn millis(duration: Duration) -> String {
    let ms = duration.as_secs_f64() * 1000.0;
    if ms < 1000.0 {
        format!("{ms:.0} ms")
    } else {
        format!("{:.1} s", ms / 1000.0)
    }
}

/// The [`Trouble`] of a matcher.
pub type TroubleOf<M> = Trouble<<<M as Matcher>::Codec as Codec>::Error, <M as Matcher>::Mismatch>;

/// The [`Verdict`] of a matcher.
pub type VerdictOf<M> = Verdict<<M as Matcher>::Answer, <M as Matcher>::Refusal, TroubleOf<M>>;

/// What a matcher says about one decoded frame or run of dropped bytes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Verdict<A, R, T> {
    /// The answer: the exchange is over.
    Answer(A),
    /// The device refused: the exchange is over, never retried.
    Refused(R),
    /// Trouble that ends the attempt now (retried while attempts remain).
    Retry(T),
    /// Trouble that ends the attempt once the line falls quiet ([`Policy::quiet_gap`]), or
    /// at the timeout without one.
    RetryWhenQuiet(T),
    /// Trouble to report if nothing better comes; keep listening.
    Note(T),
    /// A whole frame that is not the answer (another device's, our own echo): keep
    /// listening. The line was busy with it.
    Skip,
    /// [`Verdict::Skip`] for a frame whose sender the protocol can name (`station 01`,
    /// `unit 3`): if nothing better comes, the trouble names it, since a device that
    /// answers at another address than the one asked usually means a wrong address.
    SkipFrom(String),
    /// Bytes that make no frame: keep listening.
    Noise,
}

/// A protocol's knowledge of one request: is this frame its answer?
pub trait Matcher {
    /// Decodes what comes back.
    type Codec: Codec;
    /// The good answer.
    type Answer;
    /// The device's refusal.
    type Refusal;
    /// Why a well-formed frame is not a fitting answer.
    type Mismatch;

    /// What `input`, decoded from the line while the request waits, means for it.
    fn judge(
        &mut self,
        input: Result<<Self::Codec as Codec>::Frame, <Self::Codec as Codec>::Error>,
    ) -> VerdictOf<Self>;

    /// The line fell quiet with `buffered` bytes undecoded: a frame inside them, if any,
    /// with how many bytes it and what precedes it take, and its verdict. By default none.
    fn look_past(&mut self, buffered: &[u8]) -> Option<(usize, VerdictOf<Self>)> {
        let _ = buffered;
        None
    }

    /// The attempts ran out with `last`: whether it is in fact the device's answer (a
    /// refusal). By default it is not.
    fn last_word(&mut self, last: &TroubleOf<Self>) -> Option<Self::Refusal> {
        let _ = last;
        None
    }

    /// Until when the line must stay quiet after `attempt`. By default no quiet time.
    fn quiet_after(&mut self, attempt: &AttemptEnd) -> Option<Instant> {
        let _ = attempt;
        None
    }

    /// Whom the request is for, in words (`station 07`, `regulator 5`).
    fn device(&self) -> String;

    /// The request in words, when messages should name it. By default not.
    fn request_in_words(&self) -> Option<String> {
        None
    }
}

/// How an exchange retries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Policy {
    /// Attempts in all (at least 1).
    pub attempts: u8,
    /// Time to wait for the answer in each, from the moment the request has left.
    pub timeout: Duration,
    /// Silence after which undecoded bytes count as a finished frame and trouble marked
    /// [`Verdict::RetryWhenQuiet`] ends the attempt; `None`: only the timeout ends it.
    pub quiet_gap: Option<Duration>,
}

impl Policy {
    /// `retries` after the first attempt, `timeout` each, no quiet gap.
    pub fn new(retries: u8, timeout: Duration) -> Self {
        Self {
            attempts: retries.saturating_add(1),
            timeout,
            quiet_gap: None,
        }
    }

    /// The same with a quiet gap.
    pub fn with_quiet_gap(self, gap: Duration) -> Self {
        Self {
            quiet_gap: Some(gap),
            ..self
        }
    }
}

/// The longest wait the engine counts: a longer timeout or quiet gap (a user's
/// `--timeout` of 585 years) waits this long instead of overflowing the clock.
pub const LONGEST_WAIT: Duration = Duration::from_secs(24 * 3600);

/// `wait` after `at`, at most [`LONGEST_WAIT`].
pub fn after(at: Instant, wait: Duration) -> Instant {
    at + wait.min(LONGEST_WAIT)
}

/// How an exchange ended without its answer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Ended<R, T> {
    /// The device refused.
    Refused(R),
    /// Every attempt ended in trouble.
    GaveUp {
        /// Attempts made.
        attempts: u8,
        /// Time waited in each.
        timeout: Duration,
        /// The last attempt's trouble.
        last: T,
    },
}

/// One attempt's end, for the matcher to decide the line's quiet time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AttemptEnd {
    /// When the request had left.
    pub sent: Instant,
    /// When the attempt ended.
    pub ended: Instant,
    /// What ended it.
    pub ending: Ending,
    /// When the last whole frame that was not the answer arrived, if one did.
    pub skipped: Option<Instant>,
}

/// What ended an attempt.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ending {
    /// A whole frame from the device: the answer, a refusal or an answer that does not fit.
    Answered,
    /// Damaged bytes.
    Damaged,
    /// The timeout, with no fitting answer.
    TimedOut,
}

/// The outcome of an exchange.
pub type Outcome<M> = Result<<M as Matcher>::Answer, Ended<<M as Matcher>::Refusal, TroubleOf<M>>>;

/// One request and its attempts, as a state machine.
pub struct Exchange<M: Matcher> {
    matcher: M,
    deframer: Deframer<M::Codec>,
    request: Vec<u8>,
    policy: Policy,
    attempt: u8,
    state: State<M>,
    quiet_until: Option<Instant>,
}

impl<M: Matcher> fmt::Debug for Exchange<M> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let state = match self.state {
            State::Ready => "ready",
            State::Sending => "sending",
            State::Waiting(_) => "waiting",
            State::Done(_) => "done",
        };
        f.debug_struct("Exchange")
            .field("request", &self.request)
            .field("policy", &self.policy)
            .field("attempt", &self.attempt)
            .field("state", &state)
            .finish_non_exhaustive()
    }
}

enum State<M: Matcher> {
    /// The next attempt may start.
    Ready,
    /// The request was handed out; waiting to hear it left.
    Sending,
    /// Waiting for the answer.
    Waiting(Waiting<TroubleOf<M>>),
    /// Over; the outcome not yet taken.
    Done(Option<Outcome<M>>),
}

struct Waiting<T> {
    sent: Instant,
    deadline: Instant,
    last_input: Instant,
    /// The trouble so far, and whether it ends the attempt once the line is quiet.
    trouble: Option<(T, bool)>,
    skipped: Option<Instant>,
    /// Frames skipped ([`Verdict::Skip`]) in this attempt.
    others: usize,
    /// Who sent the last frame skipped, if the protocol named it ([`Verdict::SkipFrom`]).
    others_from: Option<String>,
    /// Bytes dropped as noise ([`Verdict::Noise`]) in this attempt.
    noise: usize,
}

impl<M: Matcher> Exchange<M> {
    /// An exchange that sends `request` and lets `matcher` judge what comes back through
    /// `codec`.
    pub fn new(matcher: M, codec: M::Codec, request: Vec<u8>, policy: Policy) -> Self {
        Self {
            matcher,
            deframer: Deframer::new(codec),
            request,
            policy: Policy {
                attempts: policy.attempts.max(1),
                ..policy
            },
            attempt: 0,
            state: State::Ready,
            quiet_until: None,
        }
    }

    /// The matcher.
    pub fn matcher(&self) -> &M {
        &self.matcher
    }

    /// The matcher, to change what it knows between attempts (the line's timing).
    pub fn matcher_mut(&mut self) -> &mut M {
        &mut self.matcher
    }

    /// The retry policy.
    pub fn policy(&self) -> Policy {
        self.policy
    }

    /// Changes the timeout of the attempts still to come (it may depend on the line).
    pub fn set_timeout(&mut self, timeout: Duration) {
        self.policy.timeout = timeout;
    }

    /// Attempts started so far.
    pub fn attempts(&self) -> u8 {
        self.attempt
    }

    /// The request to send, when an attempt is due: the attempt starts on a clean buffer.
    pub fn poll_transmit(&mut self) -> Option<Vec<u8>> {
        if !matches!(self.state, State::Ready) {
            return None;
        }
        self.attempt += 1;
        self.deframer.clear();
        self.state = State::Sending;
        Some(self.request.clone())
    }

    /// The request handed out by [`poll_transmit`](Self::poll_transmit) left at `now`: the
    /// attempt's timeout starts.
    pub fn handle_sent(&mut self, now: Instant) {
        if matches!(self.state, State::Sending) {
            self.state = State::Waiting(Waiting {
                sent: now,
                deadline: after(now, self.policy.timeout),
                last_input: now,
                trouble: None,
                skipped: None,
                others: 0,
                others_from: None,
                noise: 0,
            });
        }
    }

    /// Bytes that arrived at `now`. Input at or past the attempt's deadline ends the
    /// attempt once its frames are judged (as [`handle_timeout`](Self::handle_timeout)
    /// would): a line that never stops talking cannot hold an attempt open, whether or
    /// not the caller's reads ever wait.
    pub fn handle_input(&mut self, bytes: &[u8], now: Instant) {
        let State::Waiting(waiting) = &mut self.state else {
            return;
        };
        waiting.last_input = now;
        let deadline = waiting.deadline;
        self.deframer.push(bytes);
        loop {
            let before = self.deframer.buffered().len();
            let Some(input) = self.deframer.next_frame() else {
                break;
            };
            let consumed = before - self.deframer.buffered().len();
            let verdict = self.matcher.judge(input);
            if self.apply(verdict, now, consumed) {
                return;
            }
        }
        if now >= deadline {
            self.handle_timeout(now);
        }
    }

    /// Time passed to `now`: ends the attempt at its deadline, or when the line has been
    /// quiet for the gap. Early calls do nothing.
    pub fn handle_timeout(&mut self, now: Instant) {
        let State::Waiting(waiting) = &self.state else {
            return;
        };
        let deadline = waiting.deadline;
        if self.quiet_due(now) {
            while !self.deframer.buffered().is_empty() {
                let Some((consumed, verdict)) = self.matcher.look_past(self.deframer.buffered())
                else {
                    break;
                };
                let rest = self
                    .deframer
                    .buffered()
                    .get(consumed..)
                    .unwrap_or_default()
                    .to_vec();
                self.deframer.clear();
                self.deframer.push(&rest);
                if self.apply(verdict, now, consumed) {
                    return;
                }
            }
            let left = self.deframer.buffered().len();
            if left > 0 {
                self.deframer.clear();
                if let State::Waiting(waiting) = &mut self.state {
                    waiting.trouble = Some((Trouble::Incomplete { bytes: left }, true));
                }
            }
            if let State::Waiting(Waiting {
                trouble: Some((_, true)),
                ..
            }) = &self.state
            {
                self.end_attempt(None, Ending::Damaged, now);
                return;
            }
        }
        if now >= deadline {
            self.end_attempt(None, Ending::TimedOut, now);
        }
    }

    /// When to call [`handle_timeout`](Self::handle_timeout) while an answer is awaited.
    pub fn poll_timeout(&self) -> Option<Instant> {
        let State::Waiting(waiting) = &self.state else {
            return None;
        };
        match self.policy.quiet_gap {
            Some(gap) if self.listening_for_quiet(waiting) => {
                Some(waiting.deadline.min(after(waiting.last_input, gap)))
            }
            _ => Some(waiting.deadline),
        }
    }

    /// Until when the line must stay quiet after the attempt that just ended.
    pub fn poll_quiet(&mut self) -> Option<Instant> {
        self.quiet_until.take()
    }

    /// Whether an attempt is under way (sent, not yet ended).
    pub fn is_waiting(&self) -> bool {
        matches!(self.state, State::Sending | State::Waiting(_))
    }

    /// The outcome, once the exchange is over (given once).
    pub fn poll_outcome(&mut self) -> Option<Outcome<M>> {
        match &mut self.state {
            State::Done(outcome) => outcome.take(),
            _ => None,
        }
    }

    fn listening_for_quiet(&self, waiting: &Waiting<TroubleOf<M>>) -> bool {
        matches!(waiting.trouble, Some((_, true))) || !self.deframer.buffered().is_empty()
    }

    fn quiet_due(&self, now: Instant) -> bool {
        let (State::Waiting(waiting), Some(gap)) = (&self.state, self.policy.quiet_gap) else {
            return false;
        };
        self.listening_for_quiet(waiting)
            && (now >= after(waiting.last_input, gap) || now >= waiting.deadline)
    }

    /// Applies a verdict on `bytes` bytes heard at `now`; whether the attempt ended.
    fn apply(&mut self, verdict: VerdictOf<M>, now: Instant, bytes: usize) -> bool {
        let State::Waiting(waiting) = &mut self.state else {
            return true;
        };
        match verdict {
            Verdict::Answer(answer) => self.finish(Ok(answer), Ending::Answered, now),
            Verdict::Refused(refusal) => {
                self.finish(Err(Ended::Refused(refusal)), Ending::Answered, now)
            }
            Verdict::Retry(trouble) => {
                let ending = match trouble {
                    Trouble::Mismatch(_) => Ending::Answered,
                    _ => Ending::Damaged,
                };
                self.end_attempt(Some(trouble), ending, now);
            }
            Verdict::RetryWhenQuiet(trouble) => {
                waiting.trouble = Some((trouble, true));
                return false;
            }
            Verdict::Note(trouble) => {
                waiting.trouble = Some((trouble, false));
                return false;
            }
            Verdict::Skip => {
                waiting.skipped = Some(now);
                waiting.others += 1;
                return false;
            }
            Verdict::SkipFrom(sender) => {
                waiting.skipped = Some(now);
                waiting.others += 1;
                waiting.others_from = Some(sender);
                return false;
            }
            Verdict::Noise => {
                waiting.noise += bytes;
                return false;
            }
        }
        true
    }

    /// Ends the attempt with `trouble` (else the trouble noted, else silence): retries
    /// while attempts remain.
    fn end_attempt(&mut self, trouble: Option<TroubleOf<M>>, ending: Ending, now: Instant) {
        let (noted, others, from, noise) = match &mut self.state {
            State::Waiting(waiting) => (
                waiting.trouble.take().map(|(t, _)| t),
                waiting.others,
                waiting.others_from.take(),
                waiting.noise,
            ),
            _ => (None, 0, None, 0),
        };
        // No answer: say what came instead, frames for something else before noise.
        let nothing = match (others, noise) {
            (0, 0) => Trouble::Silence,
            (0, bytes) => Trouble::Noise { bytes },
            (frames, _) => Trouble::Others { frames, from },
        };
        let last = trouble.or(noted).unwrap_or(nothing);
        if self.attempt < self.policy.attempts {
            self.note_quiet(ending, now);
            self.state = State::Ready;
            return;
        }
        let outcome = match self.matcher.last_word(&last) {
            Some(refusal) => Ended::Refused(refusal),
            None => Ended::GaveUp {
                attempts: self.attempt,
                timeout: self.policy.timeout,
                last,
            },
        };
        self.finish(Err(outcome), ending, now);
    }

    fn finish(&mut self, outcome: Outcome<M>, ending: Ending, now: Instant) {
        self.note_quiet(ending, now);
        self.state = State::Done(Some(outcome));
    }

    fn note_quiet(&mut self, ending: Ending, now: Instant) {
        let State::Waiting(waiting) = &self.state else {
            return;
        };
        let end = AttemptEnd {
            sent: waiting.sent,
            ended: now,
            ending,
            skipped: waiting.skipped,
        };
        self.quiet_until = self.matcher.quiet_after(&end);
    }
}

#[cfg(test)]
mod tests;
