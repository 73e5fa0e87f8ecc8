//! The Port 1 conversation rules as sans-IO state machines, one for each side (3.2, 3.3).
//!
//! ```text
//! upload-type      host  C1…/C1M…/C1RP ─►        machine
//!                        ◄─ D0 + data
//!                        A0 ─►
//!                        ◄─ A2                    (conversation over)
//! value-type       host  C2ST/C3P ─►
//!                        ◄─ D1 + value
//!                        A2 ─►                    (conversation over)
//! download         host  C0… + data ─►
//!                        ◄─ A0
//!                        A2 ─►                    (conversation over; the machine stores the data)
//! no-data          host  C0R…/C2HB…/C5… ─►
//!                        ◄─ A2                    (conversation over)
//! any command            ◄─ A3 / A4E00 / A4E01    (refused; conversation over)
//! ```
//!
//! One conversation at a time: [`HostConversation::start`] refuses a second command until
//! the first is over, and [`MachineConversation`] answers a command that arrives in the
//! middle of an exchange with `A4E00` and abandons that exchange (the manual: A4 = "a
//! sequence anomaly, or a command that arrived when the machine could not accept it"; the
//! machine discards what it received). Abandoning, rather than keeping the old exchange
//! open, lets a host that timed out start again cleanly \[I\].
//!
//! Choices where the manual is loose:
//! - The data receiver may refuse a data block: a host that cannot read a `D0`/`D1` answers
//!   `A4E01` and ends the exchange; a machine that receives `A3`/`A4` instead of `A0`/`A2`
//!   ends the exchange quietly \[I\].
//! - Whichever of `D0` or `D1` the machine sends, the host follows it (`A0` then wait for
//!   `A2`, or `A2` and done): the manual's examples label D1 answers "D0 command" \[C 3.3-12\].
//! - One `D0` per exchange: a second `D0` where `A2` is due is a sequence error \[?\].
//! - A stray `A0`/`A2`/`A3`/`A4` on an idle machine is ignored (never answer an
//!   acknowledgement with one); a stray `D`/`R`/unknown message gets `A4E01`.
//! - Undecodable bytes (bad size or terminator) get one `A4E01` per run of bad bytes, and the
//!   exchange in progress is abandoned; the next good message ends the run (fact sheet,
//!   "What the product decides").

use crate::command::Command;
use crate::message::{DecodeError, Message, MessageError};
use crate::production::{ProductionData, ProductionDataError};
use crate::program::{ProgramList, ProgramListError, ProgramName, ProgramNameError};
use crate::reply::{A4Reason, Refusal, Reply};
use crate::status::{MachineStatus, StatusError};

/// What the host does next, after a message from the machine.
#[derive(Debug, Clone, PartialEq, Eq)]
#[must_use]
pub enum Next {
    /// Send this acknowledgement; the exchange goes on.
    Send(Message),
    /// The exchange is over. Send `send` first, when there is one (the host's closing `A2`
    /// after a `D1` or after the `A0` to a download).
    Done {
        /// The host's last message of the exchange.
        send: Option<Message>,
        /// What the exchange gave.
        outcome: Outcome,
    },
    /// The exchange failed and is over. Send `send` first, when there is one (`A4E01` to
    /// data the host cannot read).
    Failed {
        /// The host's last message of the exchange.
        send: Option<Message>,
        /// What went wrong.
        error: ConversationError,
    },
}

/// What a finished exchange gave the host, typed by the command.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outcome {
    /// `A2` to a command without data (delete, keep-alive, start, reset).
    Finished,
    /// The machine took the download (`A0`); the host's `A2` closes the exchange.
    Downloaded,
    /// The data block of an upload (`C1` + target).
    Uploaded(Vec<u8>),
    /// Production management data (`C1M`/`C1N`/`C1Z`).
    Production(ProductionData),
    /// The program list (`C1RP`).
    ProgramList(ProgramList),
    /// The machine status (`C2ST`).
    Status(MachineStatus),
    /// The selected program (`C3P`).
    CurrentProgram(ProgramName),
}

/// Data from the machine that does not mean what the command asked for.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum DataError {
    /// A bad status.
    #[error(transparent)]
    Status(#[from] StatusError),
    /// A bad program name.
    #[error(transparent)]
    ProgramName(#[from] ProgramNameError),
    /// A bad program list.
    #[error(transparent)]
    ProgramList(#[from] ProgramListError),
    /// Bad production management data.
    #[error(transparent)]
    Production(#[from] ProductionDataError),
}

/// Why an exchange did not give its outcome.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ConversationError {
    /// A second command while one is open.
    #[error(
        "cannot send {refused} yet: {pending} is still waiting for its answer (Port 1 runs one exchange at a time)"
    )]
    Busy {
        /// The open exchange's command.
        pending: String,
        /// The command that was not sent.
        refused: String,
    },
    /// The command cannot be put into a message (data above the limit).
    #[error("cannot send the command: {0}")]
    Message(#[from] MessageError),
    /// The machine answered `A3` or `A4`.
    #[error(transparent)]
    Refused(Refusal),
    /// A message that does not fit the exchange.
    #[error("during {command}: expected {expected} from the machine, got {got}")]
    Unexpected {
        /// The open exchange's command.
        command: String,
        /// What the rules allow here.
        expected: &'static str,
        /// What came.
        got: String,
    },
    /// A message while no exchange is open.
    #[error("the machine sent {got} on Port 1 while no exchange was open")]
    NotInConversation {
        /// What came.
        got: String,
    },
    /// The machine's data does not mean what the command asked for.
    #[error("the machine's answer to {command} is not valid: {error}")]
    BadData {
        /// The command.
        command: String,
        /// What is wrong.
        error: DataError,
    },
}

impl ConversationError {
    /// Whether the machine said no (`A3`/`A4`), as opposed to a line or protocol problem.
    pub fn is_refusal(&self) -> bool {
        matches!(self, ConversationError::Refused(_))
    }
}

/// What the host waits for after its command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Expect {
    /// `A2` (commands without data).
    Finish,
    /// `A0` (download).
    Ack,
    /// `D0` or `D1`, read as this.
    Data(DataKind),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum DataKind {
    Upload,
    Production,
    ProgramList,
    Status,
    CurrentProgram,
}

impl Expect {
    fn of(command: &Command) -> Expect {
        match command {
            Command::Download { .. } => Expect::Ack,
            Command::Delete { .. } | Command::KeepAlive(_) | Command::Start(_) | Command::Reset => {
                Expect::Finish
            }
            Command::Upload { .. } => Expect::Data(DataKind::Upload),
            Command::Production(_) => Expect::Data(DataKind::Production),
            Command::ProgramList => Expect::Data(DataKind::ProgramList),
            Command::Status => Expect::Data(DataKind::Status),
            Command::CurrentProgram => Expect::Data(DataKind::CurrentProgram),
        }
    }

    fn describe(self) -> &'static str {
        match self {
            Expect::Finish => "A2, A3 or A4",
            Expect::Ack => "A0, A3 or A4",
            Expect::Data(_) => "D0, D1, A3 or A4",
        }
    }
}

impl DataKind {
    fn read(self, data: Vec<u8>) -> Result<Outcome, DataError> {
        Ok(match self {
            DataKind::Upload => Outcome::Uploaded(data),
            DataKind::Production => Outcome::Production(ProductionData::parse(&data)?),
            DataKind::ProgramList => Outcome::ProgramList(ProgramList::parse(&data)?),
            DataKind::Status => Outcome::Status(MachineStatus::parse(&data)?),
            DataKind::CurrentProgram => Outcome::CurrentProgram(ProgramName::parse_field(&data)?),
        })
    }
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum HostState {
    Idle,
    /// The command went out; its first answer is due.
    AwaitAnswer {
        command: String,
        expect: Expect,
    },
    /// A `D0` came and the host sent `A0`; the machine's `A2` is due.
    AwaitEnd {
        command: String,
        outcome: Outcome,
    },
}

/// The host's side of Port 1.
///
/// Feed it every message decoded from Port 1 with [`handle`](Self::handle) and send what
/// it says; time-outs are the caller's: on one, call [`abort`](Self::abort) (and usually
/// reconnect, since the machine may still be in conversation mode).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HostConversation {
    state: HostState,
}

impl Default for HostConversation {
    fn default() -> Self {
        HostConversation::new()
    }
}

impl HostConversation {
    /// An idle conversation.
    pub fn new() -> HostConversation {
        HostConversation {
            state: HostState::Idle,
        }
    }

    /// Whether no exchange is open.
    pub fn is_idle(&self) -> bool {
        self.state == HostState::Idle
    }

    /// The command of the open exchange, as sent.
    pub fn pending(&self) -> Option<&str> {
        match &self.state {
            HostState::Idle => None,
            HostState::AwaitAnswer { command, .. } | HostState::AwaitEnd { command, .. } => {
                Some(command)
            }
        }
    }

    /// Opens an exchange: the message to send for `command`.
    pub fn start(&mut self, command: &Command) -> Result<Message, ConversationError> {
        if let Some(pending) = self.pending() {
            return Err(ConversationError::Busy {
                pending: pending.to_owned(),
                refused: command.wire(),
            });
        }
        let message = command.to_message()?;
        self.state = HostState::AwaitAnswer {
            command: command.wire(),
            expect: Expect::of(command),
        };
        Ok(message)
    }

    /// Forgets the open exchange (after a time-out or a reconnect).
    pub fn abort(&mut self) {
        self.state = HostState::Idle;
    }

    /// Takes a message from the machine.
    pub fn handle(&mut self, message: Message) -> Next {
        let got = message.to_string();
        let is_data = message.command().starts_with('D');
        let reply = Reply::parse(&message);
        let protocol_error = || Some(Reply::PROTOCOL_ERROR.ack_message());
        match std::mem::replace(&mut self.state, HostState::Idle) {
            HostState::Idle => Next::Failed {
                send: None,
                error: ConversationError::NotInConversation { got },
            },
            HostState::AwaitAnswer { command, expect } => match (expect, reply) {
                (_, Ok(reply @ (Reply::NoSuchProgram | Reply::Invalid(_)))) => Next::Failed {
                    send: None,
                    error: ConversationError::Refused(Refusal { command, reply }),
                },
                (Expect::Finish, Ok(Reply::Finished)) => Next::Done {
                    send: None,
                    outcome: Outcome::Finished,
                },
                (Expect::Ack, Ok(Reply::Received)) => Next::Done {
                    send: Some(Reply::Finished.ack_message()),
                    outcome: Outcome::Downloaded,
                },
                (Expect::Data(kind), Ok(Reply::Data(data))) => match kind.read(data) {
                    Ok(outcome) => {
                        self.state = HostState::AwaitEnd { command, outcome };
                        Next::Send(Reply::Received.ack_message())
                    }
                    Err(error) => Next::Failed {
                        send: protocol_error(),
                        error: ConversationError::BadData { command, error },
                    },
                },
                (Expect::Data(kind), Ok(Reply::Value(data))) => match kind.read(data) {
                    Ok(outcome) => Next::Done {
                        send: Some(Reply::Finished.ack_message()),
                        outcome,
                    },
                    Err(error) => Next::Failed {
                        send: protocol_error(),
                        error: ConversationError::BadData { command, error },
                    },
                },
                (expect, _) => Next::Failed {
                    send: if is_data { protocol_error() } else { None },
                    error: ConversationError::Unexpected {
                        command,
                        expected: expect.describe(),
                        got,
                    },
                },
            },
            HostState::AwaitEnd { command, outcome } => match reply {
                Ok(Reply::Finished) => Next::Done {
                    send: None,
                    outcome,
                },
                Ok(reply @ (Reply::NoSuchProgram | Reply::Invalid(_))) => Next::Failed {
                    send: None,
                    error: ConversationError::Refused(Refusal { command, reply }),
                },
                _ => Next::Failed {
                    send: if is_data { protocol_error() } else { None },
                    error: ConversationError::Unexpected {
                        command,
                        expected: "A2",
                        got,
                    },
                },
            },
        }
    }
}

/// How the machine answers a command (decided by its state: the twin's business).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MachineAnswer {
    /// `A2`: done (delete, keep-alive, start, reset).
    Finished,
    /// `A0` to a download: the data is fine; the command comes back as
    /// [`MachineStep::Commit`] when the host closes with `A2`.
    Received(Command),
    /// `D0` + data block; the host answers `A0`, the machine closes with `A2`.
    Data(Vec<u8>),
    /// `D1` + value; the host closes with `A2`.
    Value(Vec<u8>),
    /// `A3`.
    NoSuchProgram,
    /// `A4…`.
    Refused(A4Reason),
}

/// What the machine does with a message from the host.
#[derive(Debug, Clone, PartialEq, Eq)]
#[must_use]
pub enum MachineStep {
    /// A new command: decide, then call [`MachineConversation::answer`].
    Command(Command),
    /// Send this (the closing `A2` after the host's `A0`, or a refusal).
    Reply(Message),
    /// The host closed a download with `A2`: store the data now.
    Commit(Command),
    /// Nothing to do or send.
    Quiet,
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum MachineState {
    Idle,
    /// `D0` went out; the host's `A0` is due.
    AwaitAck,
    /// `D1` or `A0` (to a download) went out; the host's `A2` is due.
    AwaitEnd {
        pending: Option<Command>,
    },
}

/// The machine's side of Port 1 (used by the twin).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MachineConversation {
    state: MachineState,
    resyncing: bool,
}

impl Default for MachineConversation {
    fn default() -> Self {
        MachineConversation::new()
    }
}

impl MachineConversation {
    /// An idle conversation.
    pub fn new() -> MachineConversation {
        MachineConversation {
            state: MachineState::Idle,
            resyncing: false,
        }
    }

    /// Whether no exchange is open ("conversation mode" is off).
    pub fn is_idle(&self) -> bool {
        self.state == MachineState::Idle
    }

    /// Forgets the open exchange (the host's connection closed).
    pub fn reset(&mut self) {
        *self = MachineConversation::new();
    }

    /// Takes a decoded message from the host, or the error for bytes the codec dropped.
    pub fn receive(&mut self, input: Result<Message, DecodeError>) -> MachineStep {
        let message = match input {
            Ok(message) => message,
            Err(error) => {
                self.state = MachineState::Idle;
                if std::mem::replace(&mut self.resyncing, true) {
                    return MachineStep::Quiet;
                }
                tracing::debug!(%error, "undecodable bytes on Port 1: answering A4E01 and resynchronising");
                return MachineStep::Reply(Reply::PROTOCOL_ERROR.ack_message());
            }
        };
        self.resyncing = false;
        let is_command = message.command().starts_with(crate::command::code::CLASS);
        let reply = Reply::parse(&message);
        let refuse = |reply: Reply| MachineStep::Reply(reply.ack_message());
        match std::mem::replace(&mut self.state, MachineState::Idle) {
            MachineState::Idle if is_command => match Command::parse(&message) {
                Ok(command) => MachineStep::Command(command),
                Err(error) => {
                    tracing::debug!(%error, "refusing a command");
                    refuse(error.refusal())
                }
            },
            MachineState::Idle => match reply {
                Ok(
                    Reply::Received | Reply::Finished | Reply::NoSuchProgram | Reply::Invalid(_),
                ) => MachineStep::Quiet,
                _ => refuse(Reply::PROTOCOL_ERROR),
            },
            MachineState::AwaitAck => match reply {
                Ok(Reply::Received) => MachineStep::Reply(Reply::Finished.ack_message()),
                Ok(Reply::NoSuchProgram | Reply::Invalid(_)) => MachineStep::Quiet,
                _ if is_command => refuse(Reply::OPERATION_ERROR),
                _ => refuse(Reply::PROTOCOL_ERROR),
            },
            MachineState::AwaitEnd { pending } => match reply {
                Ok(Reply::Finished) => pending.map_or(MachineStep::Quiet, MachineStep::Commit),
                Ok(Reply::NoSuchProgram | Reply::Invalid(_)) => MachineStep::Quiet,
                _ if is_command => refuse(Reply::OPERATION_ERROR),
                _ => refuse(Reply::PROTOCOL_ERROR),
            },
        }
    }

    /// The message that answers the command [`receive`](Self::receive) returned, and the
    /// state it leaves the exchange in.
    pub fn answer(&mut self, answer: MachineAnswer) -> Message {
        let (reply, state) = match answer {
            MachineAnswer::Finished => (Ok(Reply::Finished.ack_message()), MachineState::Idle),
            MachineAnswer::Received(command) => (
                Ok(Reply::Received.ack_message()),
                MachineState::AwaitEnd {
                    pending: Some(command),
                },
            ),
            MachineAnswer::Data(data) => (Reply::Data(data).to_message(), MachineState::AwaitAck),
            MachineAnswer::Value(data) => (
                Reply::Value(data).to_message(),
                MachineState::AwaitEnd { pending: None },
            ),
            MachineAnswer::NoSuchProgram => {
                (Ok(Reply::NoSuchProgram.ack_message()), MachineState::Idle)
            }
            MachineAnswer::Refused(reason) => {
                (Ok(Reply::Invalid(reason).ack_message()), MachineState::Idle)
            }
        };
        match reply {
            Ok(message) => {
                self.state = state;
                message
            }
            Err(error) => {
                tracing::warn!(%error, "answer does not fit a message: refusing with A4E00");
                self.state = MachineState::Idle;
                Reply::OPERATION_ERROR.ack_message()
            }
        }
    }
}

#[cfg(test)]
mod tests;
