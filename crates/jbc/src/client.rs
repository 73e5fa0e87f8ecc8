//! The async client: typed requests to a station over a [`link`] line, with a timeout,
//! retries and resynchronisation.
//!
//! Retries follow the protocol's split between line trouble and refusals: a timeout, a
//! reply with a bad BCC and NAK 1/2 (the station saw a damaged frame) are retried; NAK
//! 3/4/5/6 mean the station understood and said no, so they are reported at once, in words.
//! A frame that is not the answer to the request (another code, another route) is skipped,
//! never taken as the answer.

use std::time::Duration;

use link::{LineError, SharedLine};
use wire::exchange::{Matcher, Policy, Verdict, VerdictOf};
use wire::{Exchange, Failure, FailureKind};

use crate::code::{Code, NakReason, Reading, interpret};
use crate::frame::{Address, Data, DecodeError, Frame, FrameCodec, Route};
use crate::message::{Match, Request, RequestError, match_reply};

/// Default time to wait for a reply: a 16-byte frame takes 9 ms at 19200 baud and 133 ms
/// at 1200 baud; the station answers within a few milliseconds.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_millis(500);

/// Default number of retries after the first attempt.
pub const DEFAULT_RETRIES: u8 = 2;

/// How the client talks to one station.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClientConfig {
    /// Source and target addresses, or `None` for the form without address fields.
    pub route: Option<Route>,
    /// Time to wait for each reply.
    pub timeout: Duration,
    /// Retries after the first attempt, for line trouble only.
    pub retries: u8,
}

impl Default for ClientConfig {
    /// Robot 00 → station 01, 500 ms, 2 retries.
    fn default() -> Self {
        let robot = Address::new(0).expect("00 is a valid address");
        let station = Address::new(1).expect("01 is a valid address");
        Self {
            route: Some(Route {
                source: robot,
                target: station,
            }),
            timeout: DEFAULT_TIMEOUT,
            retries: DEFAULT_RETRIES,
        }
    }
}

/// Why a request did not get its answer: the exchange's own failures (our request, the
/// station's refusal, no answer, the line), or an answer that means nothing.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ClientError {
    /// The request, the station or the line failed the exchange.
    #[error(transparent)]
    Exchange(#[from] ExchangeError),
    /// The station's answer does not mean anything for this code.
    #[error("station answered {code} with {data:?}, which is not a valid value")]
    BadValue {
        /// The code read.
        code: Code,
        /// The data field received.
        data: String,
    },
}

/// The exchange's failures, with JBC's refusal and trouble.
pub type ExchangeError = wire::ExchangeError<RequestError, Refusal, Trouble, LineError>;

/// Line trouble on one attempt: silence, a damaged reply (bad BCC, wrong length), or the
/// station reporting that it saw our frame damaged (NAK 1 or 2).
pub type Trouble = wire::Trouble<DecodeError, Transmission>;

impl From<RequestError> for ClientError {
    fn from(error: RequestError) -> Self {
        Self::Exchange(error.into())
    }
}

impl ClientError {
    /// Whether the station (or its absence) is the cause, rather than our request.
    pub fn is_device_error(&self) -> bool {
        self.kind().is_device_side()
    }
}

impl Failure for ClientError {
    fn kind(&self) -> FailureKind {
        match self {
            Self::Exchange(e) => e.kind(),
            Self::BadValue { .. } => FailureKind::Damaged,
        }
    }
}

/// The station understood the request and refused it (NAK 3–6 and numbers the spec does
/// not list).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Refusal {
    /// The request as on the wire, e.g. `WST1 00900`.
    pub request: String,
    /// Why, as the station said it.
    pub reason: NakReason,
    /// The NAK number.
    pub number: i32,
}

impl wire::exchange::Refusal for Refusal {
    fn describe(&self, _endpoint: &str, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "station refused {}: {} ({:05})",
            self.request,
            self.reason.brief(),
            self.number
        )
    }
}

/// The station saw our frame damaged (NAK 1 or 2): line trouble, retried.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("station reported a transmission error: {0}")]
pub struct Transmission(pub NakReason);

impl Failure for Transmission {
    fn kind(&self) -> FailureKind {
        FailureKind::Line
    }
}

/// A client for one station on a (possibly shared) line.
#[derive(Debug)]
pub struct Client {
    line: SharedLine,
    config: ClientConfig,
}

impl Client {
    /// A client for the station `config` names on `line`.
    pub fn new(line: SharedLine, config: ClientConfig) -> Self {
        Self { line, config }
    }

    /// The client's settings.
    pub fn config(&self) -> &ClientConfig {
        &self.config
    }

    /// Reads `code` and interprets the answer.
    pub async fn read(&mut self, code: Code) -> Result<Reading, ClientError> {
        let data = self.read_raw(code).await?;
        interpret(code, &data).map_err(|_| ClientError::BadValue {
            code,
            data: String::from_utf8_lossy(data.as_bytes()).into_owned(),
        })
    }

    /// Reads `code` and returns the data field as it came.
    pub async fn read_raw(&mut self, code: Code) -> Result<Data, ClientError> {
        let request = Request::read(code)?;
        let answer = self.request(&request).await?;
        answer.ok_or(ClientError::BadValue {
            code,
            data: String::new(),
        })
    }

    /// Writes `value` to `code` (checked before it reaches the wire).
    pub async fn write(&mut self, code: Code, value: i32) -> Result<(), ClientError> {
        let request = Request::write(code, value)?;
        self.request(&request).await.map(drop)
    }

    /// Sends `request` and returns the data of its acknowledgement.
    pub async fn request(&mut self, request: &Request) -> Result<Option<Data>, ClientError> {
        let frame = request.to_frame(self.config.route);
        let mut bytes = Vec::new();
        wire::Codec::encode(&FrameCodec, &frame, &mut bytes);
        let matcher = Reply {
            request: *request,
            route: self.config.route,
        };
        let policy = Policy::new(self.config.retries, self.config.timeout);
        let mut exchange = Exchange::new(matcher, FrameCodec, bytes, policy);
        let mut line = self.line.lock().await;
        Ok(link::exchange::run(&mut line, &mut exchange).await?)
    }
}

/// What answers one request: an acknowledgement of its code on the route back. The
/// request's text for messages is built only when the station refuses it, not for every
/// request (formatting it was a visible share of a poll's CPU).
struct Reply {
    request: Request,
    route: Option<Route>,
}

impl Matcher for Reply {
    type Codec = FrameCodec;
    type Answer = Option<Data>;
    type Refusal = Refusal;
    type Mismatch = Transmission;

    fn judge(&mut self, input: Result<Frame, DecodeError>) -> VerdictOf<Self> {
        match input {
            Ok(reply) => match match_reply(&self.request, self.route, &reply) {
                Match::Answer(data) => Verdict::Answer(data),
                // The station saw our frame damaged: line trouble, retried.
                Match::Refused(reason) if reason.is_transmission_error() => {
                    Verdict::Retry(Trouble::Mismatch(Transmission(reason)))
                }
                Match::Refused(reason) => Verdict::Refused(Refusal {
                    request: wire_text(&self.request.to_frame(self.route)),
                    reason,
                    number: reason.code(),
                }),
                Match::NotOurs => {
                    tracing::debug!(?reply, "skipping a frame that does not answer the request");
                    // A station other than the one asked: likely a wrong `address`.
                    match reply.route {
                        Some(route)
                            if self.route.is_some_and(|asked| asked.target != route.source) =>
                        {
                            Verdict::SkipFrom(format!("station {}", route.source))
                        }
                        _ => Verdict::Skip,
                    }
                }
            },
            // Noise between frames: the answer may still come.
            Err(DecodeError::Garbage { .. }) => Verdict::Noise,
            // A damaged frame is probably the answer: retry rather than wait for the timeout.
            Err(damage) => Verdict::Retry(Trouble::Damaged(damage)),
        }
    }

    fn device(&self) -> String {
        self.route.map_or_else(
            || "(no address)".to_owned(),
            |r| format!("station {}", r.target),
        )
    }
}

/// A frame as a person reads it in a log: `WST1 00900`.
fn wire_text(frame: &Frame) -> String {
    let mut text = format!("{}{}", char::from(frame.header.as_byte()), frame.code);
    if let Some(data) = &frame.data {
        text.push(' ');
        text.push_str(&String::from_utf8_lossy(data.as_bytes()));
    }
    text
}

#[cfg(test)]
mod tests {
    use link::Line;
    use testkit::{Tap, Trick, Tricky};
    use tokio::time::Instant;
    use wire::device::SharedModel;

    use super::*;
    use crate::device::{Station, StationConfig};
    use crate::message::Reply as StationReply;

    /// A reply from station 01 to the robot, as bytes.
    fn reply_bytes(reply: StationReply) -> Vec<u8> {
        reply
            .to_frame(ClientConfig::default().route.map(Route::reversed))
            .to_bytes()
    }

    /// NAK 1 for `ST1`, as if our frame had arrived damaged.
    fn nak_bcc() -> Trick {
        let code: Code = "ST1".parse().expect("valid code");
        Trick::Replace(reply_bytes(StationReply::Nak {
            code: code.raw(),
            reason: NakReason::Bcc,
        }))
    }

    /// An unrelated answer (to `MAT`) before the reply.
    fn stray_first() -> Trick {
        let code: Code = "MAT".parse().expect("valid code");
        Trick::Before(reply_bytes(StationReply::Ack {
            code: code.raw(),
            data: Some(Data::number(450).expect("fits")),
        }))
    }

    struct Bench {
        client: Client,
        station: SharedModel<Station>,
        tap: Tap,
    }

    fn bench(tricks: Vec<Trick>, config: ClientConfig) -> Bench {
        let station = SharedModel::new(Station::new(StationConfig::default()));
        let device = Tricky::new(station.line(), tricks);
        let tap = device.tap();
        let (ours, theirs) = tokio::io::duplex(1024);
        tokio::spawn(link::serve::serve_stream(theirs, device, None));
        let line = SharedLine::new(Line::from_stream(ours, "test line", None));
        Bench {
            client: Client::new(line, config),
            station,
            tap,
        }
    }

    fn code(text: &str) -> Code {
        text.parse().expect("valid code")
    }

    fn answered(b: &Bench) -> usize {
        b.tap.replies()
    }

    #[tokio::test(start_paused = true)]
    async fn a_write_then_a_read_go_through_the_station() {
        let mut b = bench(vec![], ClientConfig::default());
        b.client.write(code("ST1"), 380).await.expect("accepted");
        let reading = b.client.read(code("ST1")).await.expect("answered");
        assert_eq!(reading.to_string(), "380 °C");
    }

    #[tokio::test(start_paused = true)]
    async fn a_lost_reply_is_retried_after_the_timeout() {
        let mut b = bench(vec![Trick::Drop], ClientConfig::default());
        let started = Instant::now();
        let reading = b
            .client
            .read(code("SMN"))
            .await
            .expect("answered on the second attempt");
        assert_eq!(reading.to_string(), "JTSE");
        assert!(
            started.elapsed() >= DEFAULT_TIMEOUT,
            "waited {:?}",
            started.elapsed()
        );
        assert!(
            started.elapsed() < DEFAULT_TIMEOUT * 2,
            "waited {:?}",
            started.elapsed()
        );
        assert_eq!(answered(&b), 2);
    }

    #[tokio::test(start_paused = true)]
    async fn a_reply_that_is_only_line_noise_is_told_as_noise_not_silence() {
        let garbage = || Trick::Replace(b"xx~xxxxx".to_vec());
        let mut b = bench(
            vec![garbage(), garbage(), garbage()],
            ClientConfig::default(),
        );
        let err = b
            .client
            .read(code("ST1"))
            .await
            .expect_err("only noise came");
        assert!(
            matches!(
                err,
                ClientError::Exchange(ExchangeError::NoAnswer {
                    attempts: 3,
                    last: Trouble::Noise { bytes: 8 },
                    ..
                })
            ),
            "{err:?}"
        );
        assert!(
            err.to_string()
                .ends_with("(last: no reply, only 8 bytes of line noise)"),
            "{err}"
        );
        assert_eq!(err.kind(), FailureKind::Timeout);
    }

    #[tokio::test(start_paused = true)]
    async fn a_silent_station_gives_up_after_every_attempt_with_the_facts() {
        let route = Some(Route {
            source: Address::new(0).expect("valid"),
            target: Address::new(7).expect("valid"),
        });
        let mut b = bench(
            vec![],
            ClientConfig {
                route,
                ..ClientConfig::default()
            },
        );
        let started = Instant::now();
        let err = b
            .client
            .read(code("AT1"))
            .await
            .expect_err("nobody is at 07");
        assert_eq!(started.elapsed(), DEFAULT_TIMEOUT * 3);
        let text = err.to_string();
        assert!(
            text.contains("station 07")
                && text.contains("test line")
                && text.contains("3 attempts"),
            "{text}"
        );
        assert!(matches!(
            err,
            ClientError::Exchange(ExchangeError::NoAnswer {
                attempts: 3,
                last: Trouble::Silence,
                ..
            })
        ));
        assert_eq!(err.kind(), FailureKind::Timeout);
    }

    #[tokio::test(start_paused = true)]
    async fn a_damaged_reply_is_retried_at_once_without_waiting_for_the_timeout() {
        let mut b = bench(vec![Trick::corrupt_last()], ClientConfig::default());
        let started = Instant::now();
        b.client
            .read(code("MAT"))
            .await
            .expect("answered on the second attempt");
        assert!(
            started.elapsed() < DEFAULT_TIMEOUT,
            "waited {:?}",
            started.elapsed()
        );
        assert_eq!(answered(&b), 2);
    }

    #[tokio::test(start_paused = true)]
    async fn nak_1_is_a_transmission_error_and_is_retried() {
        let mut b = bench(vec![nak_bcc()], ClientConfig::default());
        b.client
            .read(code("ST1"))
            .await
            .expect("answered on the second attempt");
        assert_eq!(answered(&b), 2);
    }

    #[tokio::test(start_paused = true)]
    async fn damage_on_every_attempt_is_reported_as_the_last_trouble() {
        let mut b = bench(
            vec![nak_bcc(), nak_bcc(), nak_bcc()],
            ClientConfig::default(),
        );
        let err = b
            .client
            .read(code("ST1"))
            .await
            .expect_err("damaged every time");
        assert!(
            matches!(
                err,
                ClientError::Exchange(ExchangeError::NoAnswer {
                    last: Trouble::Mismatch(Transmission(NakReason::Bcc)),
                    ..
                })
            ),
            "{err}"
        );
    }

    #[tokio::test(start_paused = true)]
    async fn a_refusal_is_reported_at_once_in_words_and_never_retried() {
        let mut b = bench(vec![], ClientConfig::default());
        let err = b
            .client
            .write(code("ST1"), 900)
            .await
            .expect_err("900 °C is above the maximum");
        assert_eq!(
            err.to_string(),
            "station refused WST1 00900: out of range (00003)"
        );
        assert_eq!(err.kind(), FailureKind::Refused);
        assert_eq!(answered(&b), 1);
    }

    #[tokio::test(start_paused = true)]
    async fn a_station_out_of_robot_mode_refuses_with_nak_5() {
        let mut b = bench(vec![], ClientConfig::default());
        b.station.lock().set_robot_mode(false);
        let err = b
            .client
            .read(code("AT1"))
            .await
            .expect_err("robot mode is off");
        assert!(
            matches!(
                err,
                ClientError::Exchange(ExchangeError::Refused {
                    refusal: Refusal {
                        reason: NakReason::NotInRobotMode,
                        number: 5,
                        ..
                    },
                    ..
                })
            ),
            "{err}"
        );
    }

    #[tokio::test(start_paused = true)]
    async fn an_answer_to_another_code_is_not_taken_for_the_answer() {
        let mut b = bench(vec![stray_first()], ClientConfig::default());
        b.client.write(code("ST1"), 300).await.expect("accepted");
        assert_eq!(
            b.client
                .read(code("ST1"))
                .await
                .expect("answered")
                .to_string(),
            "300 °C"
        );
    }

    #[tokio::test(start_paused = true)]
    async fn an_invalid_write_never_reaches_the_wire() {
        let mut b = bench(vec![], ClientConfig::default());
        let err = b
            .client
            .write(code("AT1"), 100)
            .await
            .expect_err("AT1 is read-only");
        assert!(
            matches!(err, ClientError::Exchange(ExchangeError::Request(_))),
            "{err}"
        );
        assert!(!err.is_device_error());
        assert_eq!(err.kind(), FailureKind::Usage, "our mistake, not a refusal");
        assert_eq!(answered(&b), 0);
    }
}
