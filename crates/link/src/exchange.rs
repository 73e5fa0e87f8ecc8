//! One request/response attempt on a line.

use std::time::Duration;

use tokio::time::Instant;
use wire::{Codec, Deframer};

use crate::line::{Line, LineError};

/// What a protocol's matcher says about each decoded frame or dropped run of bytes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Step<T> {
    /// Not the answer (another device's frame, garbage): keep listening.
    Continue,
    /// The exchange is over with this outcome.
    Done(T),
}

/// Sends `request` and feeds what comes back through `deframer` to `on_input` until it
/// says [`Step::Done`] or `timeout` passes.
///
/// Input that arrived before the request (a late answer to an earlier one) is dropped
/// first, so it cannot be taken for this request's answer.
pub async fn exchange<C: Codec, T>(
    line: &mut Line,
    deframer: &mut Deframer<C>,
    request: &[u8],
    timeout: Duration,
    mut on_input: impl FnMut(Result<C::Frame, C::Error>) -> Step<T>,
) -> Result<T, LineError> {
    line.discard_input().await?;
    deframer.clear();
    line.send(request).await?;
    let deadline = Instant::now() + timeout;
    let mut buf = [0u8; 512];
    loop {
        let n = match line.recv(&mut buf, deadline).await {
            Err(LineError::Timeout { .. }) => return Err(LineError::Timeout { after: timeout }),
            other => other?,
        };
        deframer.push(&buf[..n]);
        while let Some(input) = deframer.next_frame() {
            if let Step::Done(outcome) = on_input(input) {
                return Ok(outcome);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    /// Frames are bytes up to `\n`; anything else cannot happen.
    #[derive(Clone)]
    struct Lines;

    #[derive(Debug)]
    struct Never;

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

    #[tokio::test(start_paused = true)]
    async fn exchange_skips_frames_that_are_not_the_answer_and_drops_stale_input() {
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
        let mut deframer = Deframer::new(Lines);
        let answer = exchange(
            &mut line,
            &mut deframer,
            b"ask\n",
            Duration::from_secs(1),
            |f| match f {
                Ok(frame) if frame.starts_with(b"ans") => Step::Done(frame),
                _ => Step::Continue,
            },
        )
        .await
        .unwrap();
        assert_eq!(answer, b"answer");
        device.await.unwrap();
    }

    #[tokio::test(start_paused = true)]
    async fn exchange_times_out_after_the_given_time() {
        let (a, _b) = tokio::io::duplex(256);
        let mut line = Line::from_stream(a, "test", None);
        let mut deframer = Deframer::new(Lines);
        let started = Instant::now();
        let err = exchange(
            &mut line,
            &mut deframer,
            b"ask\n",
            Duration::from_millis(250),
            |_| Step::Done(()),
        )
        .await
        .unwrap_err();
        assert!(matches!(err, LineError::Timeout { after } if after == Duration::from_millis(250)));
        assert_eq!(started.elapsed(), Duration::from_millis(250));
    }
}
