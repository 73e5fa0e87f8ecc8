//! The HTTP server loop of the gateway and the historian: the router served over HTTP/1.1
//! with the limits an exposed server needs, so no client can hold it up.
//!
//! - A request's headers must arrive within [`Limits::header_read_timeout`], counted from
//!   the connection's start or the end of its previous answer (a half-sent request or an
//!   idle keep-alive connection is closed).
//! - A connection whose client stops reading is closed once writing to it has made no
//!   progress for [`Limits::write_stall`] (a stuck event-stream client among them).
//! - At most [`Limits::max_connections`] at once; more are closed as they arrive, so the
//!   server keeps file descriptors for its own work (the gateway's lines).
//! - On shutdown every connection is asked to finish its answer and close; those still open
//!   after [`Limits::shutdown_grace`] are cut.

use std::future::Future;
use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;

use axum::Router;
use axum::extract::ConnectInfo;
use hyper::body::Incoming;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{Semaphore, watch};
use tokio::task::JoinSet;
use tokio::time::{Instant, Sleep};
use tower::ServiceExt;

/// The server's limits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Time a client has to send a request's headers (and the idle time allowed between
    /// two requests on one connection).
    pub header_read_timeout: Duration,
    /// Time a connection may go without any progress in writing its answer.
    pub write_stall: Duration,
    /// Connections open at once.
    pub max_connections: usize,
    /// Time open connections get to finish at shutdown.
    pub shutdown_grace: Duration,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            header_read_timeout: Duration::from_secs(10),
            write_stall: Duration::from_secs(30),
            max_connections: 256,
            shutdown_grace: Duration::from_secs(5),
        }
    }
}

/// Serves `app` on `listener` until `stop` turns true, then shuts down within the grace.
pub async fn serve(
    listener: TcpListener,
    app: Router,
    limits: Limits,
    mut stop: watch::Receiver<bool>,
) -> io::Result<()> {
    let permits = Arc::new(Semaphore::new(limits.max_connections));
    let (closing, closing_rx) = watch::channel(false);
    let mut connections = JoinSet::new();
    let mut refused = 0u64;
    let mut last_refusal_log: Option<Instant> = None;
    loop {
        tokio::select! {
            biased;
            () = turned_true(&mut stop) => break,
            Some(_) = connections.join_next(), if !connections.is_empty() => {}
            accepted = listener.accept() => {
                let (stream, peer) = match accepted {
                    Ok(accepted) => accepted,
                    Err(e) => {
                        // Out of file descriptors, most likely: wait instead of spinning.
                        tracing::warn!("cannot accept an HTTP connection: {e}");
                        tokio::time::sleep(Duration::from_millis(100)).await;
                        continue;
                    }
                };
                let Ok(permit) = Arc::clone(&permits).try_acquire_owned() else {
                    refused += 1;
                    let now = Instant::now();
                    if last_refusal_log.is_none_or(|t| now >= t + Duration::from_secs(10)) {
                        tracing::warn!(
                            "{refused} HTTP connection(s) closed at once: {} are open, the most \
                             allowed",
                            limits.max_connections
                        );
                        last_refusal_log = Some(now);
                        refused = 0;
                    }
                    drop(stream);
                    continue;
                };
                let _ = stream.set_nodelay(true);
                let app = app.clone();
                let closing = closing_rx.clone();
                connections.spawn(async move {
                    serve_connection(stream, peer, app, limits, closing).await;
                    drop(permit);
                });
            }
        }
    }
    let _ = closing.send(true);
    let drained = tokio::time::timeout(limits.shutdown_grace, async {
        while connections.join_next().await.is_some() {}
    })
    .await;
    if drained.is_err() {
        tracing::warn!(
            "{} HTTP connection(s) still open after {:?} at shutdown: cut",
            connections.len(),
            limits.shutdown_grace
        );
        connections.abort_all();
    }
    Ok(())
}

async fn serve_connection(
    stream: TcpStream,
    peer: SocketAddr,
    app: Router,
    limits: Limits,
    mut closing: watch::Receiver<bool>,
) {
    let service = TowerToHyperService::new(tower::service_fn(
        move |mut request: hyper::Request<Incoming>| {
            request.extensions_mut().insert(ConnectInfo(peer));
            app.clone().oneshot(request.map(axum::body::Body::new))
        },
    ));
    let io = TokioIo::new(StallGuard::new(stream, limits.write_stall));
    let connection = hyper::server::conn::http1::Builder::new()
        .timer(TokioTimer::new())
        .header_read_timeout(limits.header_read_timeout)
        .serve_connection(io, service);
    tokio::pin!(connection);
    let result = tokio::select! {
        result = connection.as_mut() => result,
        () = turned_true(&mut closing) => {
            connection.as_mut().graceful_shutdown();
            connection.await
        }
    };
    if let Err(e) = result {
        tracing::debug!(%peer, "HTTP connection ended: {e}");
    }
}

/// Resolves when `switch` turns true (or its sender is gone).
async fn turned_true(switch: &mut watch::Receiver<bool>) {
    let _ = switch.wait_for(|on| *on).await;
}

/// A stream whose writes fail once they have made no progress for a while: a client that
/// stops reading cannot hold its connection (and its answer's memory) for ever.
struct StallGuard<S> {
    inner: S,
    limit: Duration,
    stalled: Option<Pin<Box<Sleep>>>,
}

impl<S> StallGuard<S> {
    fn new(inner: S, limit: Duration) -> Self {
        Self {
            inner,
            limit,
            stalled: None,
        }
    }

    /// After a write returned `Pending`: an error once the stall has lasted too long.
    fn check_stall(&mut self, cx: &mut Context<'_>) -> Poll<io::Result<usize>> {
        let limit = self.limit;
        let sleep = self
            .stalled
            .get_or_insert_with(|| Box::pin(tokio::time::sleep(limit)));
        match sleep.as_mut().poll(cx) {
            Poll::Ready(()) => Poll::Ready(Err(io::Error::new(
                io::ErrorKind::TimedOut,
                format!("the client read nothing for {limit:?}"),
            ))),
            Poll::Pending => Poll::Pending,
        }
    }
}

impl<S: AsyncRead + Unpin> AsyncRead for StallGuard<S> {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_read(cx, buf)
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for StallGuard<S> {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        match Pin::new(&mut self.inner).poll_write(cx, buf) {
            Poll::Ready(result) => {
                self.stalled = None;
                Poll::Ready(result)
            }
            Poll::Pending => self.check_stall(cx),
        }
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        match Pin::new(&mut self.inner).poll_flush(cx) {
            Poll::Ready(result) => {
                self.stalled = None;
                Poll::Ready(result)
            }
            Poll::Pending => self.check_stall(cx).map(|r| r.map(|_| ())),
        }
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use axum::routing::get;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    const SHORT: Limits = Limits {
        header_read_timeout: Duration::from_millis(300),
        write_stall: Duration::from_millis(300),
        max_connections: 2,
        shutdown_grace: Duration::from_millis(300),
    };

    async fn start(
        limits: Limits,
    ) -> (SocketAddr, watch::Sender<bool>, tokio::task::JoinHandle<()>) {
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let app = Router::new().route("/", get(|| async { "hello" }));
        let (stop, stopped) = watch::channel(false);
        let task = tokio::spawn(async move {
            serve(listener, app, limits, stopped).await.unwrap();
        });
        (addr, stop, task)
    }

    /// Reads until the server closes the connection; what it sent.
    async fn until_closed(stream: &mut TcpStream) -> String {
        let mut seen = Vec::new();
        let _ = tokio::time::timeout(Duration::from_secs(10), stream.read_to_end(&mut seen)).await;
        String::from_utf8_lossy(&seen).into_owned()
    }

    #[tokio::test]
    async fn a_half_sent_request_is_closed_after_the_header_timeout() {
        let (addr, _stop, _task) = start(SHORT).await;
        let mut client = TcpStream::connect(addr).await.unwrap();
        client
            .write_all(b"GET / HTTP/1.1\r\nHost: te")
            .await
            .unwrap();
        let started = std::time::Instant::now();
        until_closed(&mut client).await;
        let took = started.elapsed();
        assert!(took < Duration::from_secs(5), "closed after {took:?}");
    }

    #[tokio::test]
    async fn connections_beyond_the_cap_are_closed_at_once_and_the_others_still_served() {
        let (addr, _stop, _task) = start(Limits {
            header_read_timeout: Duration::from_secs(30),
            ..SHORT
        })
        .await;
        let mut held = Vec::new();
        for _ in 0..2 {
            held.push(TcpStream::connect(addr).await.unwrap());
        }
        let mut extra = TcpStream::connect(addr).await.unwrap();
        assert_eq!(
            until_closed(&mut extra).await,
            "",
            "closed without an answer"
        );
        let first = &mut held[0];
        first
            .write_all(b"GET / HTTP/1.1\r\nHost: t\r\nConnection: close\r\n\r\n")
            .await
            .unwrap();
        assert!(until_closed(first).await.ends_with("hello"));
    }

    #[tokio::test]
    async fn a_half_sent_request_does_not_hold_shutdown_past_the_grace() {
        let (addr, stop, task) = start(Limits {
            header_read_timeout: Duration::from_secs(60),
            ..SHORT
        })
        .await;
        let mut client = TcpStream::connect(addr).await.unwrap();
        client
            .write_all(b"GET / HTTP/1.1\r\nHost: te")
            .await
            .unwrap();
        // Let the server take the connection in before stopping.
        let mut probe = TcpStream::connect(addr).await.unwrap();
        probe
            .write_all(b"GET / HTTP/1.1\r\nHost: t\r\nConnection: close\r\n\r\n")
            .await
            .unwrap();
        assert!(until_closed(&mut probe).await.ends_with("hello"));
        let started = std::time::Instant::now();
        stop.send(true).unwrap();
        tokio::time::timeout(Duration::from_secs(10), task)
            .await
            .expect("the server stops")
            .unwrap();
        let took = started.elapsed();
        assert!(took < Duration::from_secs(3), "stopped after {took:?}");
    }
}
