//! Port 2: the machine's R messages, read for the life of the client and typed.

use std::sync::Arc;

use link::{Endpoint, Line, LineError};
use tokio::sync::watch;
use tokio::time::Instant;
use wire::Deframer;

use crate::Port;
use crate::event::Event;
use crate::message::{DecodeError, Message, MessageCodec};

use super::*;

impl Inner {
    /// Types a message from Port 2 and passes it on.
    pub(super) fn deliver(&self, input: Result<Message, DecodeError>) {
        match input {
            Ok(message) => match Event::parse(&message) {
                Ok(event) => {
                    tracing::debug!(%event, "R message");
                    self.notify(Notice::Event(event));
                }
                Err(error) => {
                    tracing::warn!(%message, %error, "a message on Port 2 that is not an R message we read");
                    self.notify(Notice::Unreadable {
                        message: message.to_string(),
                        reason: error.to_string(),
                    });
                }
            },
            Err(error) => {
                tracing::warn!(%error, "undecodable bytes on Port 2 skipped");
                self.notify(Notice::Unreadable {
                    message: "bytes that are not a message".to_owned(),
                    reason: error.to_string(),
                });
            }
        }
    }
}

/// Reads Port 2 for the life of the client, reconnecting with backoff (connecting first,
/// when the client could not at its start: `first` is `None`).
pub(super) async fn run_port2(inner: Arc<Inner>, endpoint: Endpoint, first: Option<Line>) {
    let mut backoff = inner.config.backoff.timer();
    let mut dead = inner.port2_dead.subscribe();
    let mut line = first;
    loop {
        let current = match line.take() {
            Some(current) => current,
            None => {
                tokio::time::sleep(backoff.next_wait()).await;
                match inner.open(&endpoint, Port::Event).await {
                    Ok(current) => {
                        inner.notify(Notice::Connected {
                            port: Port::Event,
                            endpoint: endpoint.to_string(),
                        });
                        current
                    }
                    Err(error) => {
                        inner.notify(Notice::ConnectFailed {
                            port: Port::Event,
                            endpoint: endpoint.to_string(),
                            reason: error.to_string(),
                            retry_in: backoff.peek(),
                        });
                        continue;
                    }
                }
            }
        };
        // A dead verdict about an earlier connection does not concern this one.
        dead.borrow_and_update();
        let connected = Instant::now();
        let reason = read_events(&inner, current, &mut dead).await;
        if connected.elapsed() >= STABLE_CONNECTION {
            backoff.reset();
        }
        tracing::info!(%endpoint, "Port 2 closed: {reason}");
        inner.notify(Notice::Disconnected {
            port: Port::Event,
            endpoint: endpoint.to_string(),
            reason,
        });
    }
}

/// Reads R messages until the connection goes; returns why it went.
pub(super) async fn read_events(
    inner: &Inner,
    mut line: Line,
    dead: &mut watch::Receiver<u64>,
) -> String {
    let mut deframer = Deframer::new(MessageCodec);
    let mut buf = vec![0u8; 8192];
    loop {
        tokio::select! {
            read = line.recv(&mut buf, Instant::now() + IDLE_READ) => match read {
                Ok(n) => {
                    deframer.push(buf.get(..n).unwrap_or_default());
                    while let Some(input) = deframer.next_frame() {
                        inner.deliver(input);
                    }
                }
                Err(LineError::Timeout { .. }) => {}
                Err(LineError::Closed) => return "the machine closed the connection".to_owned(),
                Err(error) => return error.to_string(),
            },
            changed = dead.changed() => {
                return match changed {
                    Ok(()) => "no R1HB echo to the keep-alive: the connection is dead".to_owned(),
                    Err(_) => "the client stopped".to_owned(),
                };
            }
        }
    }
}
