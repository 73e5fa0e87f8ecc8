//! The async client: typed requests to a station over a [`link`] line, with a timeout,
//! retries and resynchronisation.
//!
//! Retries follow the protocol's split between line trouble and refusals: a timeout, a
//! reply with a bad BCC and NAK 1/2 (the station saw a damaged frame) are retried; NAK
//! 3/4/5/6 mean the station understood and said no, so they are reported at once, in words.
//! A frame that is not the answer to the request (another code, another route) is skipped,
//! never taken as the answer.

use std::time::Duration;

use link::{LineError, SharedLine, Step};
use wire::Deframer;

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

/// Why a request did not get its answer.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ClientError {
    /// The request was refused before reaching the wire.
    #[error(transparent)]
    Request(#[from] RequestError),
    /// The station understood the request and refused it.
    #[error("station refused {request}: {} ({number:05})", reason.brief())]
    Refused {
        /// The request as on the wire, e.g. `WST1 00900`.
        request: String,
        /// Why, as the station said it.
        reason: NakReason,
        /// The NAK number.
        number: i32,
    },
    /// No valid answer within the attempts.
    #[error(
        "no valid reply from station {station} on {endpoint} after {attempts} attempts of {timeout:?} each (last: {last})"
    )]
    NoAnswer {
        /// The line.
        endpoint: String,
        /// The station's address, or "(no address)".
        station: String,
        /// Attempts made.
        attempts: u8,
        /// Time waited in each.
        timeout: Duration,
        /// What went wrong on the last attempt.
        last: Trouble,
    },
    /// The line itself failed (closed, I/O error).
    #[error("line {endpoint} failed: {source}")]
    Line {
        /// The line.
        endpoint: String,
        /// What happened.
        source: LineError,
    },
    /// The station's answer does not mean anything for this code.
    #[error("station answered {code} with {data:?}, which is not a valid value")]
    BadValue {
        /// The code read.
        code: Code,
        /// The data field received.
        data: String,
    },
}

impl ClientError {
    /// Whether the station (or its absence) is the cause, rather than our request.
    pub fn is_device_error(&self) -> bool {
        !matches!(self, Self::Request(_))
    }
}

/// Line trouble on one attempt.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum Trouble {
    /// Nothing came.
    #[error("no reply")]
    Silence,
    /// A damaged reply came (bad BCC, wrong length).
    #[error("damaged reply: {0}")]
    Damaged(DecodeError),
    /// The station saw our frame damaged (NAK 1 or 2).
    #[error("station reported a transmission error: {0}")]
    Transmission(NakReason),
}

/// A client for one station on a (possibly shared) line.
#[derive(Debug)]
pub struct Client {
    line: SharedLine,
    config: ClientConfig,
    deframer: Deframer<FrameCodec>,
}

impl Client {
    /// A client for the station `config` names on `line`.
    pub fn new(line: SharedLine, config: ClientConfig) -> Self {
        Self {
            line,
            config,
            deframer: Deframer::new(FrameCodec),
        }
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
        let route = self.config.route;
        let mut line = self.line.lock().await;
        let attempts = self.config.retries.saturating_add(1);
        let mut last = Trouble::Silence;
        for _ in 0..attempts {
            let outcome = link::exchange(
                &mut line,
                &mut self.deframer,
                &bytes,
                self.config.timeout,
                |input| judge(request, route, input),
            )
            .await;
            match outcome {
                Ok(Attempt::Answer(data)) => return Ok(data),
                Ok(Attempt::Refused(reason)) if reason.is_transmission_error() => {
                    last = Trouble::Transmission(reason);
                }
                Ok(Attempt::Refused(reason)) => {
                    return Err(ClientError::Refused {
                        request: wire_text(&frame),
                        reason,
                        number: reason.code(),
                    });
                }
                Ok(Attempt::Damaged(damage)) => last = Trouble::Damaged(damage),
                Err(LineError::Timeout { .. }) => last = Trouble::Silence,
                Err(source) => {
                    return Err(ClientError::Line {
                        endpoint: line.name().to_owned(),
                        source,
                    });
                }
            }
            tracing::debug!(%last, "retrying");
        }
        Err(self.no_answer(&line, attempts, last))
    }

    fn no_answer(&self, line: &link::Line, attempts: u8, last: Trouble) -> ClientError {
        ClientError::NoAnswer {
            endpoint: line.name().to_owned(),
            station: self
                .config
                .route
                .map_or_else(|| "(no address)".to_owned(), |r| r.target.to_string()),
            attempts,
            timeout: self.config.timeout,
            last,
        }
    }
}

/// The outcome of one attempt.
enum Attempt {
    Answer(Option<Data>),
    Refused(NakReason),
    Damaged(DecodeError),
}

/// What one decoded frame (or dropped run of bytes) means for `request`.
fn judge(
    request: &Request,
    route: Option<Route>,
    input: Result<Frame, DecodeError>,
) -> Step<Attempt> {
    match input {
        Ok(reply) => match match_reply(request, route, &reply) {
            Match::Answer(data) => Step::Done(Attempt::Answer(data)),
            Match::Refused(reason) => Step::Done(Attempt::Refused(reason)),
            Match::NotOurs => {
                tracing::debug!(?reply, "skipping a frame that does not answer the request");
                Step::Continue
            }
        },
        // Noise between frames: the answer may still come.
        Err(DecodeError::Garbage { .. }) => Step::Continue,
        // A damaged frame is probably the answer: retry rather than wait for the timeout.
        Err(damage) => Step::Done(Attempt::Damaged(damage)),
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
    use std::collections::VecDeque;
    use std::time::Instant as StdInstant;

    use link::Line;
    use tokio::time::Instant;
    use wire::Transmit;
    use wire::device::{Device, SharedModel};

    use super::*;
    use crate::device::{Station, StationConfig};
    use crate::message::Reply;

    /// What the line does to the station's next reply.
    #[derive(Debug, Clone, Copy)]
    enum Trick {
        /// Swallow it.
        Drop,
        /// Flip a bit in its last byte (the BCC).
        Corrupt,
        /// Answer NAK 1 instead (as if our frame had arrived damaged).
        NakBcc,
        /// Send an unrelated answer (another code) before it.
        StrayFirst,
    }

    /// A station behind a line that plays tricks on its replies, counting requests.
    struct Tricky {
        station: wire::device::ModelLine<Station>,
        tricks: VecDeque<Trick>,
        requests: std::sync::Arc<std::sync::atomic::AtomicUsize>,
    }

    impl Device for Tricky {
        fn set_timing(&mut self, timing: wire::LineTiming) {
            self.station.set_timing(timing);
        }

        fn receive(&mut self, bytes: &[u8], now: StdInstant) -> Vec<Transmit> {
            let replies = self.station.receive(bytes, now);
            self.requests
                .fetch_add(replies.len(), std::sync::atomic::Ordering::SeqCst);
            replies
                .into_iter()
                .flat_map(|mut tx| match self.tricks.pop_front() {
                    None => vec![tx],
                    Some(Trick::Drop) => vec![],
                    Some(Trick::Corrupt) => {
                        if let Some(last) = tx.bytes.last_mut() {
                            *last ^= 0x01;
                        }
                        vec![tx]
                    }
                    Some(Trick::NakBcc) => {
                        let code: Code = "ST1".parse().expect("valid code");
                        let nak = Reply::Nak {
                            code: code.raw(),
                            reason: NakReason::Bcc,
                        };
                        vec![Transmit::after(
                            tx.delay,
                            nak.to_frame(ClientConfig::default().route.map(Route::reversed))
                                .to_bytes(),
                        )]
                    }
                    Some(Trick::StrayFirst) => {
                        let code: Code = "MAT".parse().expect("valid code");
                        let stray = Reply::Ack {
                            code: code.raw(),
                            data: Some(Data::number(450).expect("fits")),
                        };
                        let stray = stray
                            .to_frame(ClientConfig::default().route.map(Route::reversed))
                            .to_bytes();
                        vec![Transmit::after(tx.delay, stray), tx]
                    }
                })
                .collect()
        }
    }

    struct Bench {
        client: Client,
        station: SharedModel<Station>,
        requests: std::sync::Arc<std::sync::atomic::AtomicUsize>,
    }

    fn bench(tricks: &[Trick], config: ClientConfig) -> Bench {
        let station = SharedModel::new(Station::new(StationConfig::default()));
        let requests = std::sync::Arc::default();
        let device = Tricky {
            station: station.line(),
            tricks: tricks.iter().copied().collect(),
            requests: std::sync::Arc::clone(&requests),
        };
        let (ours, theirs) = tokio::io::duplex(1024);
        tokio::spawn(link::serve::serve_stream(theirs, device, None));
        let line = SharedLine::new(Line::from_stream(ours, "test line", None));
        Bench {
            client: Client::new(line, config),
            station,
            requests,
        }
    }

    fn code(text: &str) -> Code {
        text.parse().expect("valid code")
    }

    fn answered(b: &Bench) -> usize {
        b.requests.load(std::sync::atomic::Ordering::SeqCst)
    }

    #[tokio::test(start_paused = true)]
    async fn a_write_then_a_read_go_through_the_station() {
        let mut b = bench(&[], ClientConfig::default());
        b.client.write(code("ST1"), 380).await.expect("accepted");
        let reading = b.client.read(code("ST1")).await.expect("answered");
        assert_eq!(reading.to_string(), "380 °C");
    }

    #[tokio::test(start_paused = true)]
    async fn a_lost_reply_is_retried_after_the_timeout() {
        let mut b = bench(&[Trick::Drop], ClientConfig::default());
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
    async fn a_silent_station_gives_up_after_every_attempt_with_the_facts() {
        let route = Some(Route {
            source: Address::new(0).expect("valid"),
            target: Address::new(7).expect("valid"),
        });
        let mut b = bench(
            &[],
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
            ClientError::NoAnswer {
                attempts: 3,
                last: Trouble::Silence,
                ..
            }
        ));
    }

    #[tokio::test(start_paused = true)]
    async fn a_damaged_reply_is_retried_at_once_without_waiting_for_the_timeout() {
        let mut b = bench(&[Trick::Corrupt], ClientConfig::default());
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
        let mut b = bench(&[Trick::NakBcc], ClientConfig::default());
        b.client
            .read(code("ST1"))
            .await
            .expect("answered on the second attempt");
        assert_eq!(answered(&b), 2);
    }

    #[tokio::test(start_paused = true)]
    async fn damage_on_every_attempt_is_reported_as_the_last_trouble() {
        let mut b = bench(
            &[Trick::NakBcc, Trick::NakBcc, Trick::NakBcc],
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
                ClientError::NoAnswer {
                    last: Trouble::Transmission(NakReason::Bcc),
                    ..
                }
            ),
            "{err}"
        );
    }

    #[tokio::test(start_paused = true)]
    async fn a_refusal_is_reported_at_once_in_words_and_never_retried() {
        let mut b = bench(&[], ClientConfig::default());
        let err = b
            .client
            .write(code("ST1"), 900)
            .await
            .expect_err("900 °C is above the maximum");
        assert_eq!(
            err.to_string(),
            "station refused WST1 00900: out of range (00003)"
        );
        assert_eq!(answered(&b), 1);
    }

    #[tokio::test(start_paused = true)]
    async fn a_station_out_of_robot_mode_refuses_with_nak_5() {
        let mut b = bench(&[], ClientConfig::default());
        b.station.lock().set_robot_mode(false);
        let err = b
            .client
            .read(code("AT1"))
            .await
            .expect_err("robot mode is off");
        assert!(
            matches!(
                err,
                ClientError::Refused {
                    reason: NakReason::NotInRobotMode,
                    number: 5,
                    ..
                }
            ),
            "{err}"
        );
    }

    #[tokio::test(start_paused = true)]
    async fn an_answer_to_another_code_is_not_taken_for_the_answer() {
        let mut b = bench(&[Trick::StrayFirst], ClientConfig::default());
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
        let mut b = bench(&[], ClientConfig::default());
        let err = b
            .client
            .write(code("AT1"), 100)
            .await
            .expect_err("AT1 is read-only");
        assert!(matches!(err, ClientError::Request(_)), "{err}");
        assert!(!err.is_device_error());
        assert_eq!(answered(&b), 0);
    }
}
