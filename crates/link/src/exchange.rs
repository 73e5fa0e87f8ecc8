//! Drives a sans-IO [`wire::Exchange`] on a line: sends each attempt's request, feeds
//! what arrives and the passing time, and keeps the line quiet as the protocol asks.
//!
//! Time is tokio's (paused in tests) converted to `std::time::Instant` for the engine,
//! as the serve loop does.

use tokio::time::Instant;
use wire::exchange::{ExchangeError, Matcher, TroubleOf};
use wire::{Exchange, Failure, FailureKind};

use crate::line::{Line, LineError};

/// The error of an exchange driven on a line; `Q` is the protocol's request error.
pub type LineExchangeError<Q, M> =
    ExchangeError<Q, <M as Matcher>::Refusal, TroubleOf<M>, LineError>;

/// Runs `exchange` to its end on `line`, holding the line for every attempt.
pub async fn run<M: Matcher, Q>(
    line: &mut Line,
    exchange: &mut Exchange<M>,
) -> Result<M::Answer, LineExchangeError<Q, M>> {
    loop {
        if let Some(answer) = step(line, exchange).await? {
            return Ok(answer);
        }
    }
}

/// Runs the next attempt of `exchange` on `line`: `Ok(Some(answer))` or `Err` when the
/// exchange is over, `Ok(None)` when another attempt is due (the caller may let other
/// devices use the line in between).
pub async fn step<M: Matcher, Q>(
    line: &mut Line,
    exchange: &mut Exchange<M>,
) -> Result<Option<M::Answer>, LineExchangeError<Q, M>> {
    if let Err(source) = attempt(line, exchange).await {
        return Err(ExchangeError::Line {
            endpoint: line.name().to_owned(),
            source,
        });
    }
    match exchange.poll_outcome() {
        Some(Ok(answer)) => Ok(Some(answer)),
        None => {
            line.expect_late_input();
            Ok(None)
        }
        Some(Err(ended)) => {
            line.expect_late_input();
            Err(ExchangeError::ended(ended, line.name(), exchange.matcher()))
        }
    }
}

/// One attempt: drop stale input (a late answer to an earlier request), send, listen
/// until the engine says the attempt is over, then keep the line quiet as long as the
/// protocol asks.
async fn attempt<M: Matcher>(line: &mut Line, exchange: &mut Exchange<M>) -> Result<(), LineError> {
    let Some(request) = exchange.poll_transmit() else {
        return Ok(());
    };
    line.discard_input().await?;
    line.send(&request).await?;
    exchange.handle_sent(Instant::now().into_std());
    let mut buf = [0u8; 512];
    while let Some(deadline) = exchange.poll_timeout() {
        match line.recv(&mut buf, Instant::from_std(deadline)).await {
            Ok(n) => exchange.handle_input(buf.get(..n).unwrap_or_default(), now()),
            Err(LineError::Timeout { .. }) => exchange.handle_timeout(now()),
            Err(e) => return Err(e),
        }
    }
    if let Some(quiet) = exchange.poll_quiet() {
        line.keep_quiet_until(Instant::from_std(quiet));
    }
    Ok(())
}

fn now() -> std::time::Instant {
    Instant::now().into_std()
}

impl Failure for LineError {
    fn kind(&self) -> FailureKind {
        match self {
            LineError::Timeout { .. } => FailureKind::Timeout,
            LineError::Echo { .. } => FailureKind::Line,
            LineError::Closed | LineError::Io(_) => FailureKind::Disconnected,
        }
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    use wire::exchange::{Policy, Verdict, VerdictOf};
    use wire::{Codec, Failure, FailureKind};

    use super::*;

    /// Frames are bytes up to `\n`; anything else cannot happen.
    #[derive(Clone)]
    struct Lines;

    #[derive(Debug)]
    struct Never;

    impl std::fmt::Display for Never {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            f.write_str("never")
        }
    }

    impl wire::Resync for Never {
        fn drop_len(&self) -> usize {
            1
        }
    }

    impl Codec for Lines {
        type Frame = Vec<u8>;
        type Error = Never;
        fn decode(&self, buf: &[u8]) -> Result<Option<(Vec<u8>, usize)>, Never> {
            Ok(buf
                .iter()
                .position(|&b| b == b'\n')
                .map(|i| (buf[..i].to_vec(), i + 1)))
        }
        fn encode(&self, frame: &Vec<u8>, out: &mut Vec<u8>) {
            out.extend_from_slice(frame);
            out.push(b'\n');
        }
    }

    /// Takes a frame starting with `ans` for the answer, `no` for a refusal.
    struct Answers;

    #[derive(Debug, thiserror::Error)]
    #[error("mismatch")]
    struct Mismatch;

    impl Failure for Mismatch {
        fn kind(&self) -> FailureKind {
            FailureKind::Damaged
        }
    }

    #[derive(Debug)]
    struct No;

    impl wire::exchange::Refusal for No {
        fn describe(&self, endpoint: &str, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            write!(f, "refused on {endpoint}")
        }
    }

    impl Matcher for Answers {
        type Codec = Lines;
        type Answer = Vec<u8>;
        type Refusal = No;
        type Mismatch = Mismatch;
        fn judge(&mut self, input: Result<Vec<u8>, Never>) -> VerdictOf<Self> {
            match input {
                Ok(frame) if frame.starts_with(b"ans") => Verdict::Answer(frame),
                Ok(frame) if frame.starts_with(b"no") => Verdict::Refused(No),
                _ => Verdict::Skip,
            }
        }
        fn device(&self) -> String {
            "the test device".to_owned()
        }
    }

    type Error = LineExchangeError<std::io::Error, Answers>;

    fn exchange(retries: u8, timeout: Duration) -> Exchange<Answers> {
        Exchange::new(
            Answers,
            Lines,
            b"ask\n".to_vec(),
            Policy::new(retries, timeout),
        )
    }

    #[tokio::test(start_paused = true)]
    async fn run_skips_frames_that_are_not_the_answer_and_drops_stale_input() {
        let (a, mut b) = tokio::io::duplex(256);
        let mut line = Line::from_stream(a, "test", None);
        b.write_all(b"stale\n").await.unwrap();
        tokio::task::yield_now().await;
        let device = tokio::spawn(async move {
            let mut buf = [0u8; 4];
            b.read_exact(&mut buf).await.unwrap();
            assert_eq!(&buf, b"ask\n");
            b.write_all(b"other\nans").await.unwrap();
            tokio::time::sleep(Duration::from_millis(50)).await;
            b.write_all(b"wer\n").await.unwrap();
            b
        });
        let mut ex = exchange(0, Duration::from_secs(1));
        let answer: Result<_, Error> = run(&mut line, &mut ex).await;
        assert_eq!(answer.unwrap(), b"answer");
        device.await.unwrap();
    }

    #[tokio::test(start_paused = true)]
    async fn run_gives_up_after_every_attempt_with_the_facts() {
        let (a, _b) = tokio::io::duplex(256);
        let mut line = Line::from_stream(a, "test", None);
        let started = Instant::now();
        let mut ex = exchange(1, Duration::from_millis(250));
        let err: Error = run(&mut line, &mut ex).await.unwrap_err();
        assert_eq!(started.elapsed(), Duration::from_millis(500));
        assert_eq!(
            err.to_string(),
            "no valid answer from the test device on test after 2 attempts of 250 ms each \
             (last: no reply)"
        );
        assert_eq!(err.kind(), FailureKind::Timeout);
    }

    #[tokio::test(start_paused = true)]
    async fn a_refusal_ends_the_exchange_at_once_and_names_the_line() {
        let (a, mut b) = tokio::io::duplex(256);
        let mut line = Line::from_stream(a, "test", None);
        b.write_all(b"no\n").await.unwrap();
        let device = tokio::spawn(async move {
            let mut buf = [0u8; 4];
            b.read_exact(&mut buf).await.unwrap();
            b.write_all(b"no\n").await.unwrap();
            b
        });
        let mut ex = exchange(2, Duration::from_secs(1));
        let err: Error = run(&mut line, &mut ex).await.unwrap_err();
        assert_eq!(err.to_string(), "refused on test");
        assert_eq!(err.kind(), FailureKind::Refused);
        assert_eq!(ex.attempts(), 1);
        device.await.unwrap();
    }

    #[tokio::test(start_paused = true)]
    async fn a_closed_line_is_a_disconnection_naming_the_line() {
        let (a, b) = tokio::io::duplex(256);
        drop(b);
        let mut line = Line::from_stream(a, "gone", None);
        let mut ex = exchange(2, Duration::from_secs(1));
        let err: Error = run(&mut line, &mut ex).await.unwrap_err();
        assert!(err.to_string().starts_with("line gone failed"), "{err}");
        assert_eq!(err.kind(), FailureKind::Disconnected);
    }

    #[test]
    fn a_line_that_never_stops_talking_still_ends_every_attempt_at_its_timeout() {
        let ended = testkit::ends_within(Duration::from_secs(60), || async {
            let mut line = Line::from_stream(testkit::Chatter::new(*b"chat\n"), "chatty", None);
            let mut ex = exchange(1, Duration::from_millis(20));
            let err: Error = run(&mut line, &mut ex).await.unwrap_err();
            (err.kind(), err.to_string(), ex.attempts())
        });
        let (kind, text, attempts) =
            ended.expect("the exchange ends although the line never falls silent");
        assert_eq!(kind, FailureKind::Timeout);
        assert_eq!(attempts, 2);
        assert!(text.contains("after 2 attempts of 20 ms each"), "{text}");
    }
}
