//! Port 1: the command connection, its exchanges and its reconnection with backoff.

use std::time::Duration;

use link::{Endpoint, Line, LineError};
use tokio::time::Instant;
use wire::Deframer;
use wire::backoff::BackoffTimer;

use crate::Port;
use crate::command::Command;
use crate::conversation::{ConversationError, HostConversation, Next, Outcome};
use crate::event::{self};
use crate::message::MessageCodec;
use crate::reply::Refusal;

use super::*;

/// Port 1: the connection, when open, and the exchange state.
#[derive(Debug)]
pub(super) struct Port1 {
    pub(super) line: Option<Line>,
    /// Bumped at every connection, so the keep-alive closes only the one it found dead.
    pub(super) generation: u64,
    pub(super) deframer: Deframer<MessageCodec>,
    pub(super) conversation: HostConversation,
    pub(super) buf: Vec<u8>,
}

impl Default for Port1 {
    fn default() -> Self {
        Port1 {
            line: None,
            generation: 0,
            deframer: Deframer::new(MessageCodec),
            conversation: HostConversation::new(),
            buf: vec![0; READ_BUFFER],
        }
    }
}

/// How one attempt ended, when it gave no outcome.
pub(super) enum Failure {
    Refused(Refusal),
    Protocol(ConversationError),
    Trouble(Trouble),
}

pub(super) fn trouble(error: LineError) -> Failure {
    use std::io::ErrorKind::{BrokenPipe, ConnectionAborted, ConnectionReset, UnexpectedEof};
    Failure::Trouble(match error {
        LineError::Timeout { .. } => Trouble::Silence,
        LineError::Closed => Trouble::Closed,
        // A machine that closes a connection with our request unread resets it.
        LineError::Io(e)
            if matches!(
                e.kind(),
                ConnectionReset | ConnectionAborted | BrokenPipe | UnexpectedEof
            ) =>
        {
            Trouble::Closed
        }
        other => Trouble::Io(other.to_string()),
    })
}

impl Port1 {
    /// Sends `request` and follows the exchange to its end.
    pub(super) async fn attempt(
        &mut self,
        command: &Command,
        request: &[u8],
        timeout: Duration,
    ) -> Result<Outcome, Failure> {
        let Port1 {
            line,
            deframer,
            conversation,
            buf,
            ..
        } = self;
        let line = line.as_mut().ok_or(Failure::Trouble(Trouble::Closed))?;
        conversation.abort();
        conversation.start(command).map_err(Failure::Protocol)?;
        let stale = line.discard_input().await.map_err(trouble)?;
        if stale > 0 {
            tracing::debug!(
                bytes = stale,
                "dropped bytes that came between exchanges on Port 1"
            );
        }
        deframer.clear();
        line.send(request).await.map_err(trouble)?;
        let mut deadline = Instant::now() + timeout.min(wire::exchange::LONGEST_WAIT);
        loop {
            let n = line.recv(buf, deadline).await.map_err(trouble)?;
            deframer.push(buf.get(..n).unwrap_or_default());
            while let Some(input) = deframer.next_frame() {
                let message = input.map_err(|error| Failure::Trouble(Trouble::Damaged(error)))?;
                if message.command().starts_with(event::code::CLASS) {
                    tracing::warn!(%message, "an R message on Port 1 (R messages belong on Port 2): skipped");
                    continue;
                }
                match conversation.handle(message) {
                    Next::Send(ack) => {
                        line.send(&ack.to_bytes()).await.map_err(trouble)?;
                        deadline = Instant::now() + timeout.min(wire::exchange::LONGEST_WAIT);
                    }
                    Next::Done { send, outcome } => {
                        if let Some(last) = send {
                            line.send(&last.to_bytes()).await.map_err(trouble)?;
                        }
                        return Ok(outcome);
                    }
                    Next::Failed { send, error } => {
                        if let Some(last) = send
                            && let Err(error) = line.send(&last.to_bytes()).await
                        {
                            tracing::debug!(%error, "cannot send the closing message");
                        }
                        return Err(match error {
                            ConversationError::Refused(refusal) => Failure::Refused(refusal),
                            other => Failure::Protocol(other),
                        });
                    }
                }
            }
            // Input at or past the deadline (R messages, a peer that never stops talking)
            // does not keep the attempt open: a read that never waits never times out.
            if Instant::now() >= deadline {
                return Err(Failure::Trouble(Trouble::Silence));
            }
        }
    }
}

impl Inner {
    /// Opens a port within the connect time-out.
    pub(super) async fn open(&self, endpoint: &Endpoint, port: Port) -> Result<Line, ClientError> {
        let after = self.config.connect_timeout;
        match tokio::time::timeout(after, Line::open(endpoint)).await {
            Ok(Ok(line)) => Ok(line),
            Ok(Err(source)) => Err(ClientError::Connect { port, source }),
            Err(_) => Err(ClientError::ConnectTimeout {
                port,
                endpoint: endpoint.to_string(),
                after,
            }),
        }
    }

    pub(super) async fn connect_port1(&self, port1: &mut Port1) -> Result<(), ClientError> {
        let line = self.open(&self.command, Port::Command).await?;
        port1.line = Some(line);
        port1.generation += 1;
        self.notify(Notice::Connected {
            port: Port::Command,
            endpoint: self.command.to_string(),
        });
        Ok(())
    }

    pub(super) fn disconnect_port1(&self, port1: &mut Port1, reason: String) {
        port1.conversation.abort();
        if port1.line.take().is_some() {
            tracing::info!(endpoint = %self.command, "Port 1 closed: {reason}");
            self.notify(Notice::Disconnected {
                port: Port::Command,
                endpoint: self.command.to_string(),
                reason,
            });
        }
    }

    /// Runs `command` on Port 1 (already locked), with up to `attempts` attempts.
    pub(super) async fn exchange(
        &self,
        port1: &mut Port1,
        command: &Command,
        attempts: u8,
    ) -> Result<Outcome, ClientError> {
        let request = command
            .to_message()
            .map_err(|source| ClientError::Request {
                command: command.wire(),
                source,
            })?
            .to_bytes();
        let attempts = attempts.max(1);
        let mut last = Trouble::Silence;
        for attempt in 1..=attempts {
            if port1.line.is_none() {
                self.connect_port1(port1).await?;
            }
            match port1.attempt(command, &request, self.config.timeout).await {
                Ok(outcome) => return Ok(outcome),
                Err(Failure::Refused(refusal)) => return Err(ClientError::Refused(refusal)),
                Err(Failure::Protocol(error)) => {
                    // The machine's idea of the exchange is unknown: start clean next time.
                    self.disconnect_port1(port1, format!("protocol error: {error}"));
                    return Err(ClientError::Protocol {
                        endpoint: self.command.to_string(),
                        error,
                    });
                }
                Err(Failure::Trouble(trouble)) => {
                    tracing::debug!(attempt, %trouble, command = %command.wire(), "Port 1 attempt failed");
                    // The machine may still be in conversation mode: a new connection
                    // starts it afresh.
                    self.disconnect_port1(port1, format!("{} during {}", trouble, command.wire()));
                    last = trouble;
                }
            }
        }
        Err(ClientError::NoAnswer {
            endpoint: self.command.to_string(),
            command: command.wire(),
            attempts,
            timeout: self.config.timeout,
            last,
            repeatable: command.is_repeatable(),
        })
    }

    /// Reconnects Port 1 after the keep-alive found connection `generation` dead: closes
    /// it (unless a command replaced it already), then tries with backoff until connected.
    pub(super) async fn reconnect_port1(&self, generation: u64, backoff: &mut BackoffTimer) {
        {
            let mut port1 = self.port1.lock().await;
            if port1.line.is_some() && port1.generation != generation {
                return;
            }
            self.disconnect_port1(
                &mut port1,
                "no answer to the keep-alive: the connection is dead".to_owned(),
            );
        }
        loop {
            tokio::time::sleep(backoff.next_wait()).await;
            let mut port1 = self.port1.lock().await;
            if port1.line.is_some() {
                return;
            }
            match self.connect_port1(&mut port1).await {
                Ok(()) => return,
                Err(error) => self.notify(Notice::ConnectFailed {
                    port: Port::Command,
                    endpoint: self.command.to_string(),
                    reason: error.to_string(),
                    retry_in: backoff.peek(),
                }),
            }
        }
    }
}
