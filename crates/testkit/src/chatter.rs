//! A line that never stops talking, and a way to run a client on it without a hang
//! holding the test.
//!
//! Every read of a [`Chatter`] gets more of one message, repeated, at once: its reads
//! never wait, as a stream outside tokio's cooperative budget need not (a serial driver, a
//! custom stream). A client on it must end its attempts at their deadlines by itself
//! instead of counting on a read that times out. [`Chatter::after_request`] keeps quiet
//! until something is written, so the talk starts at a message's first byte.

use std::future::Future;
use std::io;
use std::pin::Pin;
use std::task::{Context, Poll, Waker};
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

/// A byte stream whose reads always return the next bytes of `message`, repeated, and
/// whose writes are all taken.
#[derive(Debug, Clone)]
pub struct Chatter {
    message: Vec<u8>,
    at: usize,
    /// Whether it talks yet (from the start, or from the first write).
    talking: bool,
    /// A read waiting for the first write.
    waiting: Option<Waker>,
}

impl Chatter {
    /// A stream repeating `message` (which must not be empty) for ever, from the start.
    pub fn new(message: impl Into<Vec<u8>>) -> Self {
        let message = message.into();
        assert!(!message.is_empty(), "a chatter needs something to say");
        Self {
            message,
            at: 0,
            talking: true,
            waiting: None,
        }
    }

    /// Like [`Chatter::new`], silent until the first write (a request).
    pub fn after_request(message: impl Into<Vec<u8>>) -> Self {
        Self {
            talking: false,
            ..Self::new(message)
        }
    }
}

impl AsyncRead for Chatter {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        if !self.talking {
            self.waiting = Some(cx.waker().clone());
            return Poll::Pending;
        }
        while buf.remaining() > 0 {
            let at = self.at;
            let rest = &self.message[at..];
            let n = rest.len().min(buf.remaining());
            buf.put_slice(&rest[..n]);
            self.at = (at + n) % self.message.len();
        }
        Poll::Ready(Ok(()))
    }
}

impl AsyncWrite for Chatter {
    fn poll_write(
        mut self: Pin<&mut Self>,
        _: &mut Context<'_>,
        bytes: &[u8],
    ) -> Poll<io::Result<usize>> {
        self.talking = true;
        if let Some(waker) = self.waiting.take() {
            waker.wake();
        }
        Poll::Ready(Ok(bytes.len()))
    }

    fn poll_flush(self: Pin<&mut Self>, _: &mut Context<'_>) -> Poll<io::Result<()>> {
        Poll::Ready(Ok(()))
    }

    fn poll_shutdown(self: Pin<&mut Self>, _: &mut Context<'_>) -> Poll<io::Result<()>> {
        Poll::Ready(Ok(()))
    }
}

/// Runs the future `make` gives on a runtime of its own thread, in real time (paused time
/// does not move while a task never waits), and gives its output if it ends within
/// `limit`; `None` if it does not (the thread is left behind), so a hang fails the test
/// instead of holding it.
pub fn ends_within<F, T>(limit: Duration, make: impl FnOnce() -> F + Send + 'static) -> Option<T>
where
    F: Future<Output = T>,
    T: Send + 'static,
{
    on_own_thread(limit, false, make)
}

/// Like [`ends_within`], on a runtime with I/O whose clock is paused: long timeouts pass at
/// once, and the bound stays in real time. For tests that wait on a thread outside the
/// runtime (the history writer): while the runtime waits for it, paused time jumps from
/// timer to timer, so a bound in paused time would trip however fast that thread is.
pub fn ends_within_paused<F, T>(
    limit: Duration,
    make: impl FnOnce() -> F + Send + 'static,
) -> Option<T>
where
    F: Future<Output = T>,
    T: Send + 'static,
{
    on_own_thread(limit, true, make)
}

fn on_own_thread<F, T>(
    limit: Duration,
    paused: bool,
    make: impl FnOnce() -> F + Send + 'static,
) -> Option<T>
where
    F: Future<Output = T>,
    T: Send + 'static,
{
    let (done, ended) = std::sync::mpsc::channel();
    let thread = std::thread::spawn(move || {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .start_paused(paused)
            .build()
            .expect("a runtime for the test");
        let _ = done.send(runtime.block_on(make()));
    });
    match ended.recv_timeout(limit) {
        Ok(output) => Some(output),
        Err(std::sync::mpsc::RecvTimeoutError::Timeout) => None,
        // The future panicked (a failed assertion): the test fails with its message.
        Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => match thread.join() {
            Err(panic) => std::panic::resume_unwind(panic),
            Ok(()) => None,
        },
    }
}

#[cfg(test)]
mod tests {
    use tokio::io::AsyncReadExt;

    use super::*;

    #[tokio::test]
    async fn a_chatter_repeats_its_message_across_reads_of_any_size() {
        let mut chatter = Chatter::new(*b"abc");
        let mut buf = [0u8; 7];
        chatter.read_exact(&mut buf).await.unwrap();
        assert_eq!(&buf, b"abcabca");
        let mut buf = [0u8; 2];
        chatter.read_exact(&mut buf).await.unwrap();
        assert_eq!(&buf, b"bc");
    }

    #[tokio::test]
    async fn a_chatter_after_a_request_is_quiet_until_written_to() {
        use tokio::io::AsyncWriteExt;
        let (mut reads, mut writes) = tokio::io::split(Chatter::after_request(*b"abc"));
        let reader = tokio::spawn(async move {
            let mut buf = [0u8; 4];
            reads.read_exact(&mut buf).await.unwrap();
            buf
        });
        tokio::task::yield_now().await;
        assert!(!reader.is_finished(), "nothing before the request");
        writes.write_all(b"ask").await.unwrap();
        assert_eq!(&reader.await.unwrap(), b"abca");
    }

    #[test]
    fn ends_within_gives_what_ends_and_nothing_for_what_does_not() {
        assert_eq!(
            ends_within(Duration::from_secs(60), || async { 7 }),
            Some(7)
        );
        let never = ends_within(Duration::from_millis(50), std::future::pending::<()>);
        assert_eq!(never, None);
    }
}
