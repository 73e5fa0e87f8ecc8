//! The host side: every C command on Port 1 with time-outs, the keep-alive, reconnection
//! with backoff, and the machine's R messages as a typed stream.
//!
//! [`Client::connect`] gives the client and an [`Events`] stream. Port 1 opens on the first
//! command (at once when the keep-alive runs) and carries one exchange at a time: callers
//! queue in order on a fair mutex, and [`HostConversation`] follows the exchange to its
//! last `A2`. Port 2 opens at once when events are wanted; a task reads it, types every R
//! message ([`Event`]) and reconnects with backoff when the connection goes. The stream
//! survives reconnects and reports them as [`Notice`]s between the events.
//!
//! Here: the configuration, the errors, the notices and [`Client`]'s commands; `port1` the
//! command connection and its reconnection, `port2` the R-message reader, `keep_alive` the
//! `C2HB` schedule. Reconnection waits are `wire::backoff`'s, as the gateway's are.
//!
//! **Retries.** TCP does not damage bytes, so a missing answer means a busy machine or a
//! dead connection: the client drops the connection (the machine may still be in
//! conversation mode) and, for a command that changes nothing
//! ([`Command::is_repeatable`]), tries again on a new one. A download, a delete, a
//! clearing read, a start or a reset is never repeated by the client: it may have taken
//! effect, so the error says so and the caller decides. `A3`/`A4` are answers, never
//! retried: [`ClientError::Refused`] carries their meaning in words.
//!
//! **Keep-alive** (3.5-2). Every interval (30 s by default, never less) a `C2HB` goes out
//! on Port 1, queued like any command. `A2` (or `A4E00`: a wrong command, a working port)
//! proves Port 1, the matching `R1HB` on Port 2 proves Port 2. A port that stays silent
//! until the reply time-out is dead: the client closes it and reconnects with backoff.
//!
//! Choices where the manual is silent \[?\]: answers are awaited [`DEFAULT_TIMEOUT`] each
//! and connections [`DEFAULT_CONNECT_TIMEOUT`]; reconnection waits [`DEFAULT_BACKOFF`]
//! (0.5 s, doubling to 30 s), back to the start once a connection has lasted
//! [`STABLE_CONNECTION`] or a keep-alive succeeded; the host does not answer R messages
//! with `A2` (3.4-1: "no need to respond"); an R message on Port 1, or an A/D message on
//! Port 2, is logged and skipped.

use std::fmt;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use link::{Endpoint, OpenError};
use tokio::sync::{Mutex, broadcast, watch};
use tokio::task::JoinHandle;
use tokio::time::Instant;
pub use wire::backoff::Backoff;

use crate::Port;
use crate::command::{Command, KeepAliveId, ProductionRequest};
use crate::conversation::{ConversationError, Outcome};
use crate::event::Event;
use crate::keepalive::{self, KeepAlive, KeepAliveConfig, KeepAliveConfigError};
use crate::message::{DecodeError, MessageError};
use crate::production::ProductionData;
use crate::program::{ProgramList, ProgramName, Target};
use crate::reply::Refusal;
use crate::status::{MachineStatus, StopMode};

/// Time to wait for each answer of the machine \[?\]: it answers status and names at once;
/// 5 s leaves room for a large upload or production data being prepared.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(5);
/// Retries of a repeatable command after a lost answer, each on a new connection.
pub const DEFAULT_RETRIES: u8 = 1;
/// Time to wait for a TCP connection \[?\].
pub const DEFAULT_CONNECT_TIMEOUT: Duration = Duration::from_secs(5);
/// Waits between reconnection attempts \[?\]: 0.5 s, doubling up to 30 s.
pub const DEFAULT_BACKOFF: Backoff =
    Backoff::new(Duration::from_millis(500), Duration::from_secs(30));
/// A connection that lasted this long resets the backoff to its first wait.
pub const STABLE_CONNECTION: Duration = Duration::from_secs(10);
/// Notices an [`Events`] stream holds before a slow reader misses some ([`Notice::Missed`]).
pub const EVENT_CAPACITY: usize = 1024;

/// Read buffer for Port 1: a large upload arrives in few reads.
const READ_BUFFER: usize = 64 * 1024;
/// Bound of one idle read on Port 2 (the loop simply reads again).
const IDLE_READ: Duration = Duration::from_secs(3600);

/// How the client reaches the machine.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ClientConfig {
    /// The machine's host name or address.
    pub host: String,
    /// Port 1 (commands).
    pub command_port: u16,
    /// Port 2 (events), or `None` to leave it alone: no events and no `R1HB` expected.
    pub event_port: Option<u16>,
    /// Time to wait for each answer.
    pub timeout: Duration,
    /// Retries of a repeatable command after a lost answer.
    pub retries: u8,
    /// Time to wait for a connection.
    pub connect_timeout: Duration,
    /// The keep-alive, or `None` for none.
    pub keep_alive: Option<KeepAliveConfig>,
    /// Waits between reconnection attempts.
    pub backoff: Backoff,
}

impl ClientConfig {
    /// Both ports at their defaults (49152, 49153), the keep-alive every 30 s, 5 s
    /// time-outs, one retry of repeatable commands.
    pub fn new(host: impl Into<String>) -> ClientConfig {
        ClientConfig {
            host: host.into(),
            command_port: crate::DEFAULT_COMMAND_PORT,
            event_port: Some(crate::DEFAULT_EVENT_PORT),
            timeout: DEFAULT_TIMEOUT,
            retries: DEFAULT_RETRIES,
            connect_timeout: DEFAULT_CONNECT_TIMEOUT,
            keep_alive: Some(KeepAliveConfig::default()),
            backoff: DEFAULT_BACKOFF,
        }
    }

    /// Port 1 only, no keep-alive: for one command or a few, as a command-line tool sends.
    pub fn commands_only(host: impl Into<String>, command_port: u16) -> ClientConfig {
        ClientConfig {
            command_port,
            event_port: None,
            keep_alive: None,
            ..ClientConfig::new(host)
        }
    }

    /// The endpoint of a TCP port of the machine.
    pub fn endpoint(&self, port: u16) -> Endpoint {
        Endpoint::Tcp {
            host: self.host.clone(),
            port,
            line: None,
            framing: link::TcpFraming::Raw,
        }
    }
}

/// Why a command did not give its outcome.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ClientError {
    /// The command cannot be put into a message (data above the 4 MiB limit).
    #[error("cannot send {command}: {source}")]
    Request {
        /// The command text.
        command: String,
        /// What is wrong.
        source: MessageError,
    },
    /// The keep-alive settings break the manual's rules.
    #[error("invalid keep-alive settings: {0}")]
    Config(#[from] KeepAliveConfigError),
    /// The machine understood the command and said no (`A3`, `A4…`).
    #[error(transparent)]
    Refused(Refusal),
    /// No answer within the attempts.
    #[error(
        "no answer to {command} from the machine at {endpoint} (Port 1) after {attempts} attempt{plural} of {timeout:?} each (last: {last}){note}",
        plural = if *attempts == 1 { "" } else { "s" },
        note = if *repeatable { "" } else { "; not repeated, as it may have taken effect: check the machine before sending it again" }
    )]
    NoAnswer {
        /// Port 1's endpoint.
        endpoint: String,
        /// The command text.
        command: String,
        /// Attempts made.
        attempts: u8,
        /// Time waited for each answer.
        timeout: Duration,
        /// What went wrong on the last attempt.
        last: Trouble,
        /// Whether the command was one the client may repeat.
        repeatable: bool,
    },
    /// A port could not be opened.
    #[error("{port}: {source}")]
    Connect {
        /// Which port.
        port: Port,
        /// What the OS said, and what to check.
        source: OpenError,
    },
    /// A connection attempt took too long.
    #[error(
        "{port}: no connection to {endpoint} within {after:?}; is the machine on and the address right?"
    )]
    ConnectTimeout {
        /// Which port.
        port: Port,
        /// The machine's port, as `tcp://host:port`.
        endpoint: String,
        /// The time waited.
        after: Duration,
    },
    /// The machine's answer broke the exchange rules or carried data that means nothing
    /// for the command.
    #[error("the machine at {endpoint} broke the protocol: {error}")]
    Protocol {
        /// Port 1's endpoint.
        endpoint: String,
        /// What went wrong.
        error: ConversationError,
    },
    /// Port 1 answered the keep-alive, Port 2 did not echo it.
    #[error(
        "keep-alive {id}: Port 1 answered, but no R1HB00{id} came back on Port 2 ({endpoint}) within {after:?}; Port 2 is not working"
    )]
    NoEcho {
        /// The keep-alive id.
        id: KeepAliveId,
        /// Port 2's endpoint.
        endpoint: String,
        /// The time waited.
        after: Duration,
    },
}

impl ClientError {
    /// Whether the machine (or its absence) is the cause, rather than our request or
    /// settings.
    pub fn is_device_error(&self) -> bool {
        wire::Failure::kind(self).is_device_side()
    }

    /// The refusal, when the machine said no.
    pub fn refusal(&self) -> Option<&Refusal> {
        match self {
            ClientError::Refused(refusal) => Some(refusal),
            _ => None,
        }
    }
}

impl wire::Failure for ClientError {
    /// A lost connection is a timeout of the machine: the client reconnects by itself.
    fn kind(&self) -> wire::FailureKind {
        use wire::FailureKind;
        match self {
            ClientError::Request { .. } | ClientError::Config(_) => FailureKind::Usage,
            ClientError::Refused(_) => FailureKind::Refused,
            ClientError::NoAnswer { last, .. } => match last {
                Trouble::Silence => FailureKind::Timeout,
                Trouble::Damaged(_) => FailureKind::Damaged,
                Trouble::Closed | Trouble::Io(_) => FailureKind::Line,
            },
            ClientError::Protocol { .. } => FailureKind::Damaged,
            ClientError::ConnectTimeout { .. } | ClientError::Connect { .. } => {
                FailureKind::Timeout
            }
            ClientError::NoEcho { .. } => FailureKind::Line,
        }
    }
}

/// Trouble on one attempt.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum Trouble {
    /// Nothing (complete) came.
    #[error("no answer")]
    Silence,
    /// The machine closed the connection.
    #[error(
        "the machine closed the connection; it serves one host at a time on Port 1: is another host connected?"
    )]
    Closed,
    /// The connection failed.
    #[error("connection failed: {0}")]
    Io(String),
    /// Bytes that are not a message came.
    #[error("undecodable answer: {0}")]
    Damaged(DecodeError),
}

/// What the [`Events`] stream carries: the machine's R messages, and what happened to the
/// connections in between.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum Notice {
    /// An R message.
    Event(Event),
    /// A message on Port 2 that is not an R message we can read (kept as text).
    Unreadable {
        /// The message (`R9XX`), or the skipped bytes' description.
        message: String,
        /// Why it is not read.
        reason: String,
    },
    /// A port is connected.
    Connected {
        /// Which port.
        port: Port,
        /// The machine's port, as `tcp://host:port`.
        endpoint: String,
    },
    /// A port's connection is gone; the client reconnects.
    Disconnected {
        /// Which port.
        port: Port,
        /// The machine's port, as `tcp://host:port`.
        endpoint: String,
        /// Why.
        reason: String,
    },
    /// A reconnection attempt failed; the next one follows after `retry_in`.
    ConnectFailed {
        /// Which port.
        port: Port,
        /// The machine's port, as `tcp://host:port`.
        endpoint: String,
        /// Why.
        reason: String,
        /// Wait before the next attempt.
        retry_in: Duration,
    },
    /// A keep-alive found a port dead.
    KeepAliveFailed {
        /// The check's id.
        id: KeepAliveId,
        /// Port 1 gave no answer.
        port1: bool,
        /// Port 2 gave no `R1HB`.
        port2: bool,
    },
    /// This reader fell behind and missed `count` notices.
    Missed {
        /// How many.
        count: u64,
    },
}

impl fmt::Display for Notice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Notice::Event(event) => event.fmt(f),
            Notice::Unreadable { message, reason } => {
                write!(f, "unreadable message on Port 2: {message}: {reason}")
            }
            Notice::Connected { port, endpoint } => write!(f, "{port} connected to {endpoint}"),
            Notice::Disconnected {
                port,
                endpoint,
                reason,
            } => write!(f, "{port} at {endpoint} lost: {reason}; reconnecting"),
            Notice::ConnectFailed {
                port,
                endpoint,
                reason,
                retry_in,
            } => write!(
                f,
                "{port}: cannot reconnect to {endpoint}: {reason}; next attempt in {retry_in:?}"
            ),
            Notice::KeepAliveFailed { id, port1, port2 } => {
                let dead = match (port1, port2) {
                    (true, true) => "no answer on Port 1 and no R1HB on Port 2",
                    (true, false) => "no answer on Port 1",
                    _ => "no R1HB on Port 2",
                };
                write!(f, "keep-alive {id}: {dead}; reconnecting")
            }
            Notice::Missed { count } => {
                write!(f, "{count} notices missed: this reader fell behind")
            }
        }
    }
}

/// The machine's R messages and connection notices, in order; survives reconnects.
#[derive(Debug)]
pub struct Events {
    receiver: broadcast::Receiver<Notice>,
}

impl Events {
    /// The next notice; `None` once the client is gone.
    pub async fn next(&mut self) -> Option<Notice> {
        match self.receiver.recv().await {
            Ok(notice) => Some(notice),
            Err(broadcast::error::RecvError::Lagged(count)) => Some(Notice::Missed { count }),
            Err(broadcast::error::RecvError::Closed) => None,
        }
    }

    /// The next R message, skipping connection notices; `None` once the client is gone.
    pub async fn next_event(&mut self) -> Option<Event> {
        loop {
            if let Notice::Event(event) = self.next().await? {
                return Some(event);
            }
        }
    }
}

/// The result of one keep-alive check run on demand ([`Client::keep_alive`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KeepAliveReport {
    /// The check's id.
    pub id: KeepAliveId,
    /// Time until Port 1's `A2`.
    pub port1: Duration,
    /// Time until Port 2's `R1HB`, when the client uses Port 2.
    pub port2: Option<Duration>,
}

/// A connection to a placement machine (see the [module documentation](self)). Dropping
/// it closes both ports and stops its tasks.
#[derive(Debug)]
pub struct Client {
    inner: Arc<Inner>,
    tasks: Vec<JoinHandle<()>>,
}

impl Drop for Client {
    fn drop(&mut self) {
        for task in &self.tasks {
            task.abort();
        }
    }
}

impl Client {
    /// Connects: Port 2 at once when `config.event_port` is set, Port 1 at once when the
    /// keep-alive runs (otherwise on the first command). Fails when Port 1 cannot be
    /// reached; Port 2 that cannot is told (a [`Notice::ConnectFailed`]) and tried again in
    /// the background, as later losses of either port are, while the commands go on.
    pub async fn connect(config: ClientConfig) -> Result<(Client, Events), ClientError> {
        let schedule = match config.keep_alive {
            Some(mut keep_alive) => {
                keep_alive.expect_echo &= config.event_port.is_some();
                Some(KeepAlive::new(keep_alive, now_std())?)
            }
            None => None,
        };
        let (notices, receiver) = broadcast::channel(EVENT_CAPACITY);
        let inner = Arc::new(Inner {
            command: config.endpoint(config.command_port),
            event: config.event_port.map(|port| config.endpoint(port)),
            config,
            port1: Mutex::new(Port1::default()),
            notices,
            port2_dead: watch::Sender::new(0),
            checks: AtomicU64::new(0),
        });
        let mut client = Client {
            inner,
            tasks: Vec::new(),
        };
        let events = Events { receiver };
        if let Some(endpoint) = client.inner.event.clone() {
            // Port 2 refused is its own trouble: the commands on Port 1 go on, and Port 2
            // is tried again in the background (each failure a `ConnectFailed` notice).
            let line = match client.inner.open(&endpoint, Port::Event).await {
                Ok(line) => {
                    client.inner.notify(Notice::Connected {
                        port: Port::Event,
                        endpoint: endpoint.to_string(),
                    });
                    Some(line)
                }
                Err(error) => {
                    client.inner.notify(Notice::ConnectFailed {
                        port: Port::Event,
                        endpoint: endpoint.to_string(),
                        reason: error.to_string(),
                        retry_in: client.inner.config.backoff.timer().peek(),
                    });
                    None
                }
            };
            let task = run_port2(Arc::clone(&client.inner), endpoint, line);
            client.tasks.push(tokio::spawn(task));
        }
        if let Some(schedule) = schedule {
            let mut port1 = client.inner.port1.lock().await;
            client.inner.connect_port1(&mut port1).await?;
            drop(port1);
            let echoes = client.inner.notices.subscribe();
            let task = run_keep_alive(Arc::clone(&client.inner), schedule, echoes);
            client.tasks.push(tokio::spawn(task));
        }
        Ok((client, events))
    }

    /// Another stream of the notices from now on.
    pub fn subscribe(&self) -> Events {
        Events {
            receiver: self.inner.notices.subscribe(),
        }
    }

    /// The settings.
    pub fn config(&self) -> &ClientConfig {
        &self.inner.config
    }

    /// Port 1's endpoint.
    pub fn command_endpoint(&self) -> &Endpoint {
        &self.inner.command
    }

    /// Port 2's endpoint, when used.
    pub fn event_endpoint(&self) -> Option<&Endpoint> {
        self.inner.event.as_ref()
    }

    /// Runs one Port 1 exchange and returns what it gave.
    pub async fn command(&self, command: &Command) -> Result<Outcome, ClientError> {
        let attempts = if command.is_repeatable() {
            self.inner.config.retries.saturating_add(1)
        } else {
            1
        };
        let mut port1 = self.inner.port1.lock().await;
        self.inner.exchange(&mut port1, command, attempts).await
    }

    /// `C2ST`: run, ready or error; online or remote.
    pub async fn status(&self) -> Result<MachineStatus, ClientError> {
        self.typed(
            Command::Status,
            "a machine status",
            |outcome| match outcome {
                Outcome::Status(status) => Ok(status),
                other => Err(outcome_name(&other)),
            },
        )
        .await
    }

    /// `C3P`: the selected product program.
    pub async fn current_program(&self) -> Result<ProgramName, ClientError> {
        self.typed(
            Command::CurrentProgram,
            "a program name",
            |outcome| match outcome {
                Outcome::CurrentProgram(name) => Ok(name),
                other => Err(outcome_name(&other)),
            },
        )
        .await
    }

    /// `C1RP`: the stored programs with their dates.
    pub async fn program_list(&self) -> Result<ProgramList, ClientError> {
        self.typed(
            Command::ProgramList,
            "a program list",
            |outcome| match outcome {
                Outcome::ProgramList(list) => Ok(list),
                other => Err(outcome_name(&other)),
            },
        )
        .await
    }

    /// `C1M`/`C1N`/`C1Z`: production management data, kept or cleared after reading.
    pub async fn production(
        &self,
        request: ProductionRequest,
    ) -> Result<ProductionData, ClientError> {
        self.typed(
            Command::Production(request),
            "production management data",
            |outcome| match outcome {
                Outcome::Production(data) => Ok(data),
                other => Err(outcome_name(&other)),
            },
        )
        .await
    }

    /// `C1`: a program, a library or the machine data, as the machine stores it.
    pub async fn upload(&self, target: Target) -> Result<Vec<u8>, ClientError> {
        self.typed(
            Command::Upload { target },
            "a data block",
            |outcome| match outcome {
                Outcome::Uploaded(data) => Ok(data),
                other => Err(outcome_name(&other)),
            },
        )
        .await
    }

    /// `C0`: stores a program, a library, or (`C0G`) the operating-condition data. The
    /// machine stores it when the host closes the exchange with `A2`, which this sends.
    pub async fn download(&self, target: Target, data: Vec<u8>) -> Result<(), ClientError> {
        self.finished(Command::Download { target, data }).await
    }

    /// `C0R`: deletes a program.
    pub async fn delete(&self, target: Target) -> Result<(), ClientError> {
        self.finished(Command::Delete { target }).await
    }

    /// `C5ST[BL|EP|CT]`: starts the machine (Remote mode only), in `mode` or the previous
    /// stop mode; the machine confirms with `R1ST` on Port 2.
    pub async fn start(&self, mode: Option<StopMode>) -> Result<(), ClientError> {
        self.finished(Command::Start(mode)).await
    }

    /// `C5RE`: resets the machine (Remote mode only); `R1RE` follows on Port 2.
    pub async fn reset(&self) -> Result<(), ClientError> {
        self.finished(Command::Reset).await
    }

    /// `C2HB` now, outside the schedule: waits for Port 1's `A2` and, when the client uses
    /// Port 2, for the matching `R1HB` (within the keep-alive reply time-out).
    pub async fn keep_alive(&self) -> Result<KeepAliveReport, ClientError> {
        let n = self.inner.checks.fetch_add(1, Ordering::Relaxed) + 1;
        let id = KeepAliveId::new(&format!("H{:05}", n % 100_000))
            .expect("H and five digits make a valid keep-alive id");
        let mut echoes = self.subscribe();
        let started = Instant::now();
        self.finished(Command::KeepAlive(id.clone())).await?;
        let port1 = started.elapsed();
        let Some(event) = &self.inner.event else {
            return Ok(KeepAliveReport {
                id,
                port1,
                port2: None,
            });
        };
        let wait = self
            .inner
            .config
            .keep_alive
            .map_or(keepalive::DEFAULT_REPLY_TIMEOUT, |k| k.reply_timeout);
        let deadline = started + wait;
        loop {
            match tokio::time::timeout_at(deadline, echoes.next_event()).await {
                Ok(Some(Event::Heartbeat { id: echoed })) if echoed == id => {
                    return Ok(KeepAliveReport {
                        id,
                        port1,
                        port2: Some(started.elapsed()),
                    });
                }
                Ok(Some(_)) => {}
                Ok(None) | Err(_) => {
                    return Err(ClientError::NoEcho {
                        id,
                        endpoint: event.to_string(),
                        after: wait,
                    });
                }
            }
        }
    }

    /// A command whose exchange ends with the machine's `A2` (or the host's, for a download).
    async fn finished(&self, command: Command) -> Result<(), ClientError> {
        self.typed(
            command,
            "the end of the exchange",
            |outcome| match outcome {
                Outcome::Finished | Outcome::Downloaded => Ok(()),
                other => Err(outcome_name(&other)),
            },
        )
        .await
    }

    /// Runs `command` and takes the outcome it must give (`pick` names any other kind).
    async fn typed<T>(
        &self,
        command: Command,
        expected: &'static str,
        pick: impl FnOnce(Outcome) -> Result<T, &'static str>,
    ) -> Result<T, ClientError> {
        let outcome = self.command(&command).await?;
        pick(outcome).map_err(|other| ClientError::Protocol {
            endpoint: self.inner.command.to_string(),
            error: ConversationError::Unexpected {
                command: command.wire(),
                expected,
                got: other.to_owned(),
            },
        })
    }
}

/// An outcome's kind, for messages.
fn outcome_name(outcome: &Outcome) -> &'static str {
    match outcome {
        Outcome::Finished => "the end of the exchange",
        Outcome::Downloaded => "a download acknowledgement",
        Outcome::Uploaded(_) => "a data block",
        Outcome::Production(_) => "production management data",
        Outcome::ProgramList(_) => "a program list",
        Outcome::Status(_) => "a machine status",
        Outcome::CurrentProgram(_) => "a program name",
    }
}

/// The client's time as the sans-IO parts take it (virtual under paused time).
fn now_std() -> std::time::Instant {
    Instant::now().into_std()
}

/// What the client and its tasks share.
#[derive(Debug)]
struct Inner {
    config: ClientConfig,
    command: Endpoint,
    event: Option<Endpoint>,
    port1: Mutex<Port1>,
    notices: broadcast::Sender<Notice>,
    /// Bumped when the keep-alive finds Port 2 dead: the reader drops its connection.
    port2_dead: watch::Sender<u64>,
    /// Keep-alive checks run on demand (for their ids).
    checks: AtomicU64,
}

impl Inner {
    fn notify(&self, notice: Notice) {
        // Nobody listening is fine: the notices are for whoever wants them.
        let _ = self.notices.send(notice);
    }
}

mod keep_alive;
mod port1;
mod port2;

use keep_alive::*;
use port1::*;
use port2::*;

#[cfg(test)]
mod tests;
