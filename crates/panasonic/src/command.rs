//! C commands: host → machine, Port 1 (3.3, 3.5).
//!
//! | command | wire | data | machine answers |
//! |---|---|---|---|
//! | [`Command::Download`] | `C0` + target (`C0P123456789ABC`, `C0G`) | program text | `A0`, host closes with `A2` |
//! | [`Command::Delete`] | `C0R` + target | – | `A2` (the manual's text is cut; A2 \[I\]) |
//! | [`Command::Upload`] | `C1` + target | – | `D0` + text, host `A0`, machine `A2` |
//! | [`Command::Production`] | `C1M000`, `C1M900`, `C1M000P`, `C1M900P`, `C1N000`, `C1N900`, `C1Z000`, `C1Z900` | – | `D0` … |
//! | [`Command::ProgramList`] | `C1RP` | – | `D0` … |
//! | [`Command::Status`] | `C2ST` | – | `D1` + `mmn`, host `A2` |
//! | [`Command::KeepAlive`] | `C2HB00` + 6-character id | – | `A2`; `R1HB00` + id on Port 2 |
//! | [`Command::CurrentProgram`] | `C3P` | – | `D1` + `P` + 15 characters, host `A2` |
//! | [`Command::Start`] | `C5ST`, `C5STBL`, `C5STEP`, `C5STCT` | – | `A2`; `R1ST` on Port 2 |
//! | [`Command::Reset`] | `C5RE` | – | `A2`; `R1RE` on Port 2, later |
//!
//! Any of them may instead get `A3` (no such program) or `A4E00`/`A4E01` (refused).
//!
//! Choices where the manual is loose:
//! - `C3` is sent as `C3P` ("C3 + program type"; only product programs have names); a
//!   bare `C3` is read as `C3P` too \[I\].
//! - `C5HB` (once in 3.5-2) is read as a typo for `C2HB` and not accepted \[I\].
//! - The `00` between `C2HB` and the id is sent as is; a `C2HB` with anything else there,
//!   or an id that is not 6 printable characters, is a bad keep-alive, which 3.5-2 answers
//!   with `A4E00` (see [`CommandError::refusal`]).
//! - Stop and the other C5 codes of 3.3-14..16 are not in the pages we have: they are
//!   unknown commands (`A4E01`).

use std::fmt;

use serde::Serialize;

use crate::message::{Message, MessageError};
use crate::program::{Target, TargetError};
use crate::reply::{A4Reason, Reply};
use crate::status::StopMode;

/// Length of a keep-alive id.
pub const KEEP_ALIVE_ID_LEN: usize = 6;
/// The two characters between `C2HB` / `R1HB` and the id.
pub const KEEP_ALIVE_INFIX: &str = "00";

/// Command texts and prefixes.
pub mod code {
    /// Download.
    pub const DOWNLOAD: &str = "C0";
    /// Delete (checked before [`DOWNLOAD`]).
    pub const DELETE: &str = "C0R";
    /// Upload.
    pub const UPLOAD: &str = "C1";
    /// Production management data, grand or current total.
    pub const MANAGEMENT: &str = "C1M";
    /// Production management data, nozzles.
    pub const NOZZLE: &str = "C1N";
    /// Production management data, feeders.
    pub const FEEDER: &str = "C1Z";
    /// Keep the counters after reading.
    pub const KEEP: &str = "000";
    /// Clear the counters after reading.
    pub const CLEAR: &str = "900";
    /// Suffix for the current total.
    pub const CURRENT: &str = "P";
    /// Program list.
    pub const PROGRAM_LIST: &str = "C1RP";
    /// Machine status.
    pub const STATUS: &str = "C2ST";
    /// Keep-alive (wire-break check).
    pub const KEEP_ALIVE: &str = "C2HB";
    /// Current program name.
    pub const CURRENT_PROGRAM: &str = "C3";
    /// Product program type after `C3`.
    pub const PRODUCT_TYPE: &str = "P";
    /// Remote start.
    pub const START: &str = "C5ST";
    /// Remote reset.
    pub const RESET: &str = "C5RE";
    /// The class letter of every command.
    pub const CLASS: char = 'C';
}

/// A keep-alive id: 6 printable, non-blank ASCII characters (`ABC123`).
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize)]
#[serde(transparent)]
pub struct KeepAliveId(String);

/// Text that cannot be a keep-alive id.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "keep-alive id {id:?} must be exactly {KEEP_ALIVE_ID_LEN} printable ASCII characters without blanks"
)]
pub struct KeepAliveIdError {
    /// The text given.
    pub id: String,
}

impl KeepAliveId {
    /// An id.
    pub fn new(id: &str) -> Result<KeepAliveId, KeepAliveIdError> {
        if id.len() == KEEP_ALIVE_ID_LEN && id.bytes().all(|b| b.is_ascii_graphic()) {
            Ok(KeepAliveId(id.to_owned()))
        } else {
            Err(KeepAliveIdError { id: id.to_owned() })
        }
    }

    /// The id for sequence number `n` (modulo 1 000 000): `000042`.
    pub fn sequence(n: u64) -> KeepAliveId {
        KeepAliveId(format!("{:06}", n % 1_000_000))
    }

    /// The id.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl fmt::Display for KeepAliveId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// Which production management data (3.3-7, 3.3-8).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ProductionScope {
    /// `C1M…`: grand total. Clearing it leaves the nozzle and feeder totals.
    GrandTotal,
    /// `C1M…P`: current total. Clearing it also clears the nozzle and feeder totals.
    CurrentTotal,
    /// `C1N…`: nozzle information.
    Nozzle,
    /// `C1Z…`: feeder information.
    Feeder,
}

/// A request for production management data.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub struct ProductionRequest {
    /// Which data.
    pub scope: ProductionScope,
    /// Clear the counters after reading (`900`) or keep them (`000`).
    pub clear: bool,
}

impl ProductionRequest {
    /// Every request the manual lists.
    pub const ALL: [ProductionRequest; 8] = {
        use ProductionScope::*;
        [
            ProductionRequest {
                scope: GrandTotal,
                clear: false,
            },
            ProductionRequest {
                scope: GrandTotal,
                clear: true,
            },
            ProductionRequest {
                scope: CurrentTotal,
                clear: false,
            },
            ProductionRequest {
                scope: CurrentTotal,
                clear: true,
            },
            ProductionRequest {
                scope: Nozzle,
                clear: false,
            },
            ProductionRequest {
                scope: Nozzle,
                clear: true,
            },
            ProductionRequest {
                scope: Feeder,
                clear: false,
            },
            ProductionRequest {
                scope: Feeder,
                clear: true,
            },
        ]
    };

    /// The code after `C1`: `M000`, `M900P`, `N900`, …
    pub fn code(self) -> String {
        let (letter, suffix) = match self.scope {
            ProductionScope::GrandTotal => ("M", ""),
            ProductionScope::CurrentTotal => ("M", code::CURRENT),
            ProductionScope::Nozzle => ("N", ""),
            ProductionScope::Feeder => ("Z", ""),
        };
        let digits = if self.clear { code::CLEAR } else { code::KEEP };
        format!("{letter}{digits}{suffix}")
    }
}

/// A C command.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize)]
#[serde(tag = "command", content = "args", rename_all = "snake_case")]
pub enum Command {
    /// `C0`: store a program, a library or machine data on the machine.
    Download {
        /// What the data is.
        target: Target,
        /// The data (`%HEADER` … `*` CRLF).
        #[serde(skip)]
        data: Vec<u8>,
    },
    /// `C0R`: delete a program.
    Delete {
        /// What to delete.
        target: Target,
    },
    /// `C1`: read a program, a library or machine data from the machine.
    Upload {
        /// What to read.
        target: Target,
    },
    /// `C1M` / `C1N` / `C1Z`: read production management data.
    Production(ProductionRequest),
    /// `C1RP`: list the stored programs.
    ProgramList,
    /// `C2ST`: machine status.
    Status,
    /// `C2HB00` + id: wire-break check.
    KeepAlive(KeepAliveId),
    /// `C3P`: name of the selected program.
    CurrentProgram,
    /// `C5ST[BL|EP|CT]`: start, in the given stop mode or the previous one.
    Start(Option<StopMode>),
    /// `C5RE`: reset.
    Reset,
}

/// A C command message that is not one of ours, or is malformed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum CommandError {
    /// Not a command we know.
    #[error("{command:?} is not a known C command")]
    Unknown {
        /// The command text.
        command: String,
    },
    /// A transfer command with a bad target.
    #[error("{command:?}: {source}")]
    Target {
        /// The command text.
        command: String,
        /// What is wrong with the target.
        source: TargetError,
    },
    /// A malformed `C2HB`.
    #[error("{command:?} is not a keep-alive: expected C2HB00 and a 6-character id")]
    KeepAlive {
        /// The command text.
        command: String,
    },
    /// Data on a command that takes none.
    #[error("{command} takes no data but came with {size} bytes")]
    UnexpectedData {
        /// The command text.
        command: String,
        /// Bytes of data.
        size: usize,
    },
    /// A download without data.
    #[error("{command} needs data (the program text) but came without")]
    MissingData {
        /// The command text.
        command: String,
    },
}

impl CommandError {
    /// The refusal the machine sends: `A4E00` for a bad keep-alive (3.5-2), `A4E01`
    /// (protocol error) for everything else.
    pub fn refusal(&self) -> Reply {
        match self {
            CommandError::KeepAlive { .. } => Reply::Invalid(A4Reason::OperationError),
            _ => Reply::Invalid(A4Reason::ProtocolError),
        }
    }
}

impl Command {
    /// The command text on the wire.
    pub fn wire(&self) -> String {
        match self {
            Command::Download { target, .. } => format!("{}{}", code::DOWNLOAD, target.to_wire()),
            Command::Delete { target } => format!("{}{}", code::DELETE, target.to_wire()),
            Command::Upload { target } => format!("{}{}", code::UPLOAD, target.to_wire()),
            Command::Production(request) => format!("{}{}", code::UPLOAD, request.code()),
            Command::ProgramList => code::PROGRAM_LIST.to_owned(),
            Command::Status => code::STATUS.to_owned(),
            Command::KeepAlive(id) => format!("{}{KEEP_ALIVE_INFIX}{id}", code::KEEP_ALIVE),
            Command::CurrentProgram => format!("{}{}", code::CURRENT_PROGRAM, code::PRODUCT_TYPE),
            Command::Start(mode) => format!("{}{}", code::START, mode.map_or("", StopMode::code)),
            Command::Reset => code::RESET.to_owned(),
        }
    }

    /// The message to send.
    pub fn to_message(&self) -> Result<Message, MessageError> {
        let data = match self {
            Command::Download { data, .. } => data.clone(),
            _ => Vec::new(),
        };
        Message::with_data(&self.wire(), data)
    }

    /// Reads a C command message.
    pub fn parse(message: &Message) -> Result<Command, CommandError> {
        let text = message.command();
        let size = message.data().len();
        match parse_text(text)? {
            Command::Download { .. } if size == 0 => Err(CommandError::MissingData {
                command: text.to_owned(),
            }),
            Command::Download { target, .. } => Ok(Command::Download {
                target,
                data: message.data().to_vec(),
            }),
            command if size == 0 => Ok(command),
            _ => Err(CommandError::UnexpectedData {
                command: text.to_owned(),
                size,
            }),
        }
    }

    /// Whether sending the command again, after an attempt whose answer was lost, is
    /// harmless: the reads that change nothing (status, selected program, program list,
    /// upload, production data kept, keep-alive). A download, a delete, a read that clears
    /// counters, a start or a reset may have happened already, so a client must not repeat
    /// them on its own.
    pub fn is_repeatable(&self) -> bool {
        match self {
            Command::Status
            | Command::CurrentProgram
            | Command::ProgramList
            | Command::Upload { .. }
            | Command::KeepAlive(_) => true,
            Command::Production(request) => !request.clear,
            Command::Download { .. }
            | Command::Delete { .. }
            | Command::Start(_)
            | Command::Reset => false,
        }
    }

    /// Whether this is a C5 command, which only Remote mode accepts.
    pub fn is_remote_control(&self) -> bool {
        matches!(self, Command::Start(_) | Command::Reset)
    }

    /// What the command does, in words.
    pub fn describe(&self) -> String {
        match self {
            Command::Download { target, data } => {
                format!("download {target} ({} bytes)", data.len())
            }
            Command::Delete { target } => format!("delete {target}"),
            Command::Upload { target } => format!("upload {target}"),
            Command::Production(request) => {
                let what = match request.scope {
                    ProductionScope::GrandTotal => "grand total",
                    ProductionScope::CurrentTotal => "current total",
                    ProductionScope::Nozzle => "nozzle information",
                    ProductionScope::Feeder => "feeder information",
                };
                let then = if request.clear { "clear it" } else { "keep it" };
                format!("read production management data ({what}), then {then}")
            }
            Command::ProgramList => "list the stored programs".to_owned(),
            Command::Status => "ask for the machine status".to_owned(),
            Command::KeepAlive(id) => format!("keep-alive {id}"),
            Command::CurrentProgram => "ask for the selected program".to_owned(),
            Command::Start(Some(mode)) => format!("start in {} mode", mode.describe()),
            Command::Start(None) => "start in the previous stop mode".to_owned(),
            Command::Reset => "reset".to_owned(),
        }
    }
}

impl fmt::Display for Command {
    /// `C2ST (ask for the machine status)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} ({})", self.wire(), self.describe())
    }
}

/// Reads the command text; the data length is checked by the caller.
fn parse_text(text: &str) -> Result<Command, CommandError> {
    let unknown = || CommandError::Unknown {
        command: text.to_owned(),
    };
    let target = |rest: &str| {
        Target::parse(rest).map_err(|source| CommandError::Target {
            command: text.to_owned(),
            source,
        })
    };
    let exact = |command: Command| Ok(command);
    if text == code::PROGRAM_LIST {
        return exact(Command::ProgramList);
    }
    if text == code::STATUS {
        return exact(Command::Status);
    }
    if text == code::RESET {
        return exact(Command::Reset);
    }
    if let Some(rest) = text.strip_prefix(code::KEEP_ALIVE) {
        let id = rest
            .strip_prefix(KEEP_ALIVE_INFIX)
            .and_then(|id| KeepAliveId::new(id).ok());
        return id
            .map(Command::KeepAlive)
            .ok_or_else(|| CommandError::KeepAlive {
                command: text.to_owned(),
            });
    }
    if let Some(rest) = text.strip_prefix(code::START) {
        return match rest {
            "" => exact(Command::Start(None)),
            code => StopMode::from_code(code)
                .map(|mode| Command::Start(Some(mode)))
                .ok_or_else(unknown),
        };
    }
    if let Some(rest) = text.strip_prefix(code::CURRENT_PROGRAM) {
        return match rest {
            "" | code::PRODUCT_TYPE => exact(Command::CurrentProgram),
            _ => Err(unknown()),
        };
    }
    if let Some(rest) = text.strip_prefix(code::DELETE) {
        return Ok(Command::Delete {
            target: target(rest)?,
        });
    }
    if let Some(rest) = text.strip_prefix(code::UPLOAD) {
        if let Some(request) = ProductionRequest::ALL
            .into_iter()
            .find(|r| r.code() == rest)
        {
            return Ok(Command::Production(request));
        }
        if [code::MANAGEMENT, code::NOZZLE, code::FEEDER]
            .iter()
            .any(|prefix| text.starts_with(prefix))
        {
            return Err(unknown());
        }
        return Ok(Command::Upload {
            target: target(rest)?,
        });
    }
    if let Some(rest) = text.strip_prefix(code::DOWNLOAD) {
        // The data is attached by the caller; an empty placeholder here.
        return Ok(Command::Download {
            target: target(rest)?,
            data: Vec::new(),
        });
    }
    Err(unknown())
}

#[cfg(test)]
mod tests;
