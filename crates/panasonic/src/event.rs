//! R messages: the machine's unsolicited events, Port 2 (3.4).
//!
//! Command field only, data size 0. The host need not answer (3.4-1); the twin and the
//! host side both accept an `A2` after one and ignore it \[I\].
//!
//! | event | wire |
//! |---|---|
//! | [`Event::BoardFinished`] | `R0CT[nnnn]`: EOP block done in CONT mode (one board) |
//! | [`Event::ProductionFinished`] | `R0EP[nnnn]`: EOP block done in EOP or 1-BLOCK mode |
//! | [`Event::Started`] | `R1ST`: started (after C5ST) |
//! | [`Event::ResetDone`] | `R1RE`: reset done (after C5RE) |
//! | [`Event::RecoveryStarted`] | `R1RC`: automatic recovery starts |
//! | [`Event::Heartbeat`] | `R1HB00` + id: the keep-alive echo |
//! | [`Event::Se`] | `R1SE[P name]` |
//! | [`Event::SeNg`] | `R1SENG[P name E*** xxxxxx]` |
//! | [`Event::Error`] | `R2ExxSxxxNxxxZxxxM0T000[xxxxxx]`: error stop (E03 = parts exhausted) |
//! | [`Event::RecoveryOk`] | `R3GDCT`: recovery succeeded |
//! | [`Event::RecoveryRetry`] | `R3NGCT`: recovery failed, will retry |
//! | [`Event::RecoveryStop`] | `R3NGEP`: recovery failed, the machine stops |
//!
//! The bracketed parts appear only when the machine's extended-format switch is on
//! (3.4-7); they are `Option`s here. Meanings the pages do not give are marked \[?\].

use std::fmt;

use serde::Serialize;

use crate::command::{KEEP_ALIVE_INFIX, KeepAliveId};
use crate::message::Message;
use crate::program::{PROGRAM_NAME_LEN, ProgramName};

/// Event texts.
pub mod code {
    /// Board finished (CONT).
    pub const BOARD_FINISHED: &str = "R0CT";
    /// Production finished (EOP / 1-BLOCK).
    pub const PRODUCTION_FINISHED: &str = "R0EP";
    /// Started.
    pub const STARTED: &str = "R1ST";
    /// Reset done.
    pub const RESET_DONE: &str = "R1RE";
    /// Recovery starts.
    pub const RECOVERY_STARTED: &str = "R1RC";
    /// Keep-alive echo.
    pub const HEARTBEAT: &str = "R1HB";
    /// `SE` (checked after [`SE_NG`]).
    pub const SE: &str = "R1SE";
    /// `SENG`.
    pub const SE_NG: &str = "R1SENG";
    /// Error info.
    pub const ERROR: &str = "R2E";
    /// Recovery OK.
    pub const RECOVERY_OK: &str = "R3GDCT";
    /// Recovery failed, retrying.
    pub const RECOVERY_RETRY: &str = "R3NGCT";
    /// Recovery failed, stopping.
    pub const RECOVERY_STOP: &str = "R3NGEP";
    /// The class letter of every event.
    pub const CLASS: char = 'R';
}

/// The error number of parts (component) exhaustion (3.4-7).
pub const PARTS_EXHAUSTED: u8 = 3;
/// Width of the optional board time of R0CT/R0EP.
pub const BOARD_TIME_WIDTH: usize = 4;
/// Width of the optional detail of R2 and R1SENG.
pub const DETAIL_LEN: usize = 6;

/// Production time of one board, loading included, in seconds: 0–9999 (`R0CTnnnn`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(transparent)]
pub struct BoardTime(u16);

/// A board time above 9999 s.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("board time {seconds} s does not fit 4 digits (at most {max} s)")]
pub struct BoardTimeError {
    /// The value given.
    pub seconds: u64,
    /// 9999.
    pub max: u16,
}

impl BoardTime {
    /// The longest board time the field holds.
    pub const MAX: u16 = 9999;

    /// A board time.
    pub fn new(seconds: u64) -> Result<BoardTime, BoardTimeError> {
        u16::try_from(seconds)
            .ok()
            .filter(|&s| s <= BoardTime::MAX)
            .map(BoardTime)
            .ok_or(BoardTimeError {
                seconds,
                max: BoardTime::MAX,
            })
    }

    /// A board time, at most 9999 s.
    pub fn saturating(seconds: u64) -> BoardTime {
        BoardTime(u16::try_from(seconds.min(u64::from(BoardTime::MAX))).unwrap_or(BoardTime::MAX))
    }

    /// Seconds.
    pub fn seconds(self) -> u16 {
        self.0
    }
}

/// The `R2` error information: `R2ExxSxxxNxxxZxxxMxTxxx[xxxxxx]`.
///
/// \[I\] S, N and Z are read as step, nozzle and feeder (Z) numbers; the meaning of M, T and
/// the 6-character extension is not in the pages we have \[?\], so they are kept as they come.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize)]
pub struct ErrorInfo {
    code: u8,
    step: u16,
    nozzle: u16,
    feeder: u16,
    m: u8,
    t: u16,
    detail: Option<String>,
}

/// Parts of an [`ErrorInfo`] that do not fit their fields.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ErrorInfoError {
    /// A number too wide for its field.
    #[error("R2 field {field} = {value} does not fit (at most {max})")]
    OutOfRange {
        /// The field letter.
        field: char,
        /// The value.
        value: u32,
        /// Its maximum.
        max: u32,
    },
    /// A detail that is not 6 printable characters.
    #[error("R2 detail {detail:?} must be {DETAIL_LEN} printable ASCII characters without blanks")]
    Detail {
        /// The detail given.
        detail: String,
    },
}

impl ErrorInfo {
    /// Error `code` (0–99) at `step`, `nozzle` and `feeder` (0–999 each), M and T zero.
    pub fn new(code: u8, step: u16, nozzle: u16, feeder: u16) -> Result<ErrorInfo, ErrorInfoError> {
        ErrorInfo::from_parts(code, step, nozzle, feeder, 0, 0, None)
    }

    /// Every field, as R2 carries them.
    pub fn from_parts(
        code: u8,
        step: u16,
        nozzle: u16,
        feeder: u16,
        m: u8,
        t: u16,
        detail: Option<&str>,
    ) -> Result<ErrorInfo, ErrorInfoError> {
        let check = |field: char, value: u32, max: u32| {
            if value <= max {
                Ok(())
            } else {
                Err(ErrorInfoError::OutOfRange { field, value, max })
            }
        };
        check('E', code.into(), 99)?;
        check('S', step.into(), 999)?;
        check('N', nozzle.into(), 999)?;
        check('Z', feeder.into(), 999)?;
        check('M', m.into(), 9)?;
        check('T', t.into(), 999)?;
        if let Some(detail) = detail
            && (detail.len() != DETAIL_LEN || !detail.bytes().all(|b| b.is_ascii_graphic()))
        {
            return Err(ErrorInfoError::Detail {
                detail: detail.to_owned(),
            });
        }
        Ok(ErrorInfo {
            code,
            step,
            nozzle,
            feeder,
            m,
            t,
            detail: detail.map(str::to_owned),
        })
    }

    /// The same with the 6-character extension (extended format).
    pub fn with_detail(self, detail: &str) -> Result<ErrorInfo, ErrorInfoError> {
        ErrorInfo::from_parts(
            self.code,
            self.step,
            self.nozzle,
            self.feeder,
            self.m,
            self.t,
            Some(detail),
        )
    }

    /// The error number (3 = parts exhausted).
    pub fn code(&self) -> u8 {
        self.code
    }

    /// Whether this is parts exhaustion (E03).
    pub fn is_parts_exhausted(&self) -> bool {
        self.code == PARTS_EXHAUSTED
    }

    /// The S field: step number \[I\].
    pub fn step(&self) -> u16 {
        self.step
    }

    /// The N field: nozzle number \[I\].
    pub fn nozzle(&self) -> u16 {
        self.nozzle
    }

    /// The Z field: feeder (Z) number \[I\].
    pub fn feeder(&self) -> u16 {
        self.feeder
    }

    /// The M field \[?\].
    pub fn m(&self) -> u8 {
        self.m
    }

    /// The T field \[?\].
    pub fn t(&self) -> u16 {
        self.t
    }

    /// The 6-character extension \[?\].
    pub fn detail(&self) -> Option<&str> {
        self.detail.as_deref()
    }

    fn wire(&self) -> String {
        format!(
            "{}{:02}S{:03}N{:03}Z{:03}M{}T{:03}{}",
            code::ERROR,
            self.code,
            self.step,
            self.nozzle,
            self.feeder,
            self.m,
            self.t,
            self.detail.as_deref().unwrap_or("")
        )
    }

    /// Reads the text after `R2E`.
    fn parse(rest: &str) -> Option<ErrorInfo> {
        let b = rest.as_bytes();
        let number =
            |range: std::ops::Range<usize>| b.get(range).and_then(wire::ascii::parse_unsigned);
        let letter = |at: usize, expected: u8| b.get(at) == Some(&expected);
        // xx S xxx N xxx Z xxx M x T xxx [xxxxxx]
        if !(letter(2, b'S')
            && letter(6, b'N')
            && letter(10, b'Z')
            && letter(14, b'M')
            && letter(16, b'T'))
        {
            return None;
        }
        let detail = match rest.get(20..) {
            Some("") => None,
            Some(detail) => Some(detail),
            None => return None,
        };
        ErrorInfo::from_parts(
            u8::try_from(number(0..2)?).ok()?,
            u16::try_from(number(3..6)?).ok()?,
            u16::try_from(number(7..10)?).ok()?,
            u16::try_from(number(11..14)?).ok()?,
            u8::try_from(number(15..16)?).ok()?,
            u16::try_from(number(17..20)?).ok()?,
            detail,
        )
        .ok()
    }
}

/// The extended part of `R1SENG`: `E***` + 6 characters \[?\].
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize)]
pub struct SeNgDetail {
    code: String,
    detail: String,
}

impl SeNgDetail {
    /// `code` is the 3 characters after `E`, `detail` the 6 after them (printable, no blanks).
    pub fn new(code: &str, detail: &str) -> Option<SeNgDetail> {
        let graphic =
            |s: &str, len: usize| s.len() == len && s.bytes().all(|b| b.is_ascii_graphic());
        (graphic(code, 3) && graphic(detail, DETAIL_LEN)).then(|| SeNgDetail {
            code: code.to_owned(),
            detail: detail.to_owned(),
        })
    }

    /// The 3 characters after `E`.
    pub fn code(&self) -> &str {
        &self.code
    }

    /// The 6 characters after the code.
    pub fn detail(&self) -> &str {
        &self.detail
    }
}

/// An R message.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum Event {
    /// `R0CT[nnnn]`: a board finished in CONT mode (used to count boards).
    BoardFinished {
        /// Its production time, loading included (extended format).
        time: Option<BoardTime>,
    },
    /// `R0EP[nnnn]`: the EOP block ran in EOP or 1-BLOCK mode: production complete.
    ProductionFinished {
        /// The board's production time (extended format).
        time: Option<BoardTime>,
    },
    /// `R1ST`: the machine started.
    Started,
    /// `R1RE`: the reset finished.
    ResetDone,
    /// `R1RC`: an automatic recovery starts.
    RecoveryStarted,
    /// `R1HB00` + id: the Port 2 half of the keep-alive.
    Heartbeat {
        /// The id of the C2HB it answers.
        id: KeepAliveId,
    },
    /// `R1SE[P name]` \[?\]: read by the twin as "program selected" \[I\].
    Se {
        /// The program (extended format).
        program: Option<ProgramName>,
    },
    /// `R1SENG[P name E*** xxxxxx]` \[?\]: read by the twin as "program selection failed" \[I\].
    SeNg {
        /// The program (extended format).
        program: Option<ProgramName>,
        /// The error part (extended format).
        error: Option<SeNgDetail>,
    },
    /// `R2E…`: error information.
    Error(ErrorInfo),
    /// `R3GDCT`: recovery succeeded.
    RecoveryOk,
    /// `R3NGCT`: recovery failed; the machine retries.
    RecoveryRetry,
    /// `R3NGEP`: recovery failed; the machine stops.
    RecoveryStop,
}

/// An R message we cannot read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum EventError {
    /// Not an R message we know.
    #[error("{command:?} is not a known R message")]
    Unknown {
        /// The command text.
        command: String,
    },
    /// A known R message with a malformed tail.
    #[error("{command:?} is not a valid {kind} message")]
    Malformed {
        /// The command text.
        command: String,
        /// Which message it looks like.
        kind: &'static str,
    },
    /// R messages carry no data.
    #[error("{command} takes no data but came with {size} bytes")]
    UnexpectedData {
        /// The command text.
        command: String,
        /// Bytes of data.
        size: usize,
    },
}

impl Event {
    /// The command text on the wire.
    pub fn wire(&self) -> String {
        let time = |t: &Option<BoardTime>| t.map(|t| format!("{:04}", t.0)).unwrap_or_default();
        match self {
            Event::BoardFinished { time: t } => format!("{}{}", code::BOARD_FINISHED, time(t)),
            Event::ProductionFinished { time: t } => {
                format!("{}{}", code::PRODUCTION_FINISHED, time(t))
            }
            Event::Started => code::STARTED.to_owned(),
            Event::ResetDone => code::RESET_DONE.to_owned(),
            Event::RecoveryStarted => code::RECOVERY_STARTED.to_owned(),
            Event::Heartbeat { id } => format!("{}{KEEP_ALIVE_INFIX}{id}", code::HEARTBEAT),
            Event::Se { program } => format!(
                "{}{}",
                code::SE,
                program
                    .as_ref()
                    .map(|p| format!("P{p}"))
                    .unwrap_or_default()
            ),
            Event::SeNg { program, error } => {
                let mut text = code::SE_NG.to_owned();
                match (program, error) {
                    (Some(program), Some(error)) => {
                        text.push_str(&program.to_field());
                        text.push_str(&format!("E{}{}", error.code, error.detail));
                    }
                    (Some(program), None) => text.push_str(&format!("P{program}")),
                    (None, _) => {}
                }
                text
            }
            Event::Error(info) => info.wire(),
            Event::RecoveryOk => code::RECOVERY_OK.to_owned(),
            Event::RecoveryRetry => code::RECOVERY_RETRY.to_owned(),
            Event::RecoveryStop => code::RECOVERY_STOP.to_owned(),
        }
    }

    /// The message to send.
    pub fn to_message(&self) -> Message {
        Message::new(&self.wire())
            .expect("R message texts are short printable ASCII starting with R")
    }

    /// Reads an R message.
    pub fn parse(message: &Message) -> Result<Event, EventError> {
        let text = message.command();
        if !message.data().is_empty() {
            return Err(EventError::UnexpectedData {
                command: text.to_owned(),
                size: message.data().len(),
            });
        }
        let malformed = |kind| EventError::Malformed {
            command: text.to_owned(),
            kind,
        };
        let exact = [
            (code::STARTED, Event::Started),
            (code::RESET_DONE, Event::ResetDone),
            (code::RECOVERY_STARTED, Event::RecoveryStarted),
            (code::RECOVERY_OK, Event::RecoveryOk),
            (code::RECOVERY_RETRY, Event::RecoveryRetry),
            (code::RECOVERY_STOP, Event::RecoveryStop),
        ];
        if let Some((_, event)) = exact.into_iter().find(|(code, _)| *code == text) {
            return Ok(event);
        }
        if let Some(rest) = text.strip_prefix(code::BOARD_FINISHED) {
            return board_time(rest)
                .map(|time| Event::BoardFinished { time })
                .ok_or_else(|| malformed("R0CT"));
        }
        if let Some(rest) = text.strip_prefix(code::PRODUCTION_FINISHED) {
            return board_time(rest)
                .map(|time| Event::ProductionFinished { time })
                .ok_or_else(|| malformed("R0EP"));
        }
        if let Some(rest) = text.strip_prefix(code::HEARTBEAT) {
            let id = rest
                .strip_prefix(KEEP_ALIVE_INFIX)
                .and_then(|id| KeepAliveId::new(id).ok());
            return id
                .map(|id| Event::Heartbeat { id })
                .ok_or_else(|| malformed("R1HB"));
        }
        if let Some(rest) = text.strip_prefix(code::SE_NG) {
            return se_ng(rest).ok_or_else(|| malformed("R1SENG"));
        }
        if let Some(rest) = text.strip_prefix(code::SE) {
            return optional_program(rest)
                .map(|program| Event::Se { program })
                .ok_or_else(|| malformed("R1SE"));
        }
        if let Some(rest) = text.strip_prefix(code::ERROR) {
            return ErrorInfo::parse(rest)
                .map(Event::Error)
                .ok_or_else(|| malformed("R2"));
        }
        Err(EventError::Unknown {
            command: text.to_owned(),
        })
    }

    /// What happened, in words.
    pub fn describe(&self) -> String {
        let time = |t: &Option<BoardTime>| t.map(|t| format!(" in {} s", t.0)).unwrap_or_default();
        match self {
            Event::BoardFinished { time: t } => format!("board finished{}", time(t)),
            Event::ProductionFinished { time: t } => {
                format!("production finished (end of program){}", time(t))
            }
            Event::Started => "machine started".to_owned(),
            Event::ResetDone => "reset done".to_owned(),
            Event::RecoveryStarted => "automatic recovery started".to_owned(),
            Event::Heartbeat { id } => format!("keep-alive echo {id}"),
            Event::Se { program: Some(p) } => format!("SE (program selected?) {p}"),
            Event::Se { program: None } => "SE (program selected?)".to_owned(),
            Event::SeNg { program, error } => {
                let mut text = "SENG (program selection failed?)".to_owned();
                if let Some(p) = program {
                    text.push_str(&format!(" {p}"));
                }
                if let Some(e) = error {
                    text.push_str(&format!(" E{} {}", e.code, e.detail));
                }
                text
            }
            Event::Error(info) => {
                let what = if info.is_parts_exhausted() {
                    "parts exhausted".to_owned()
                } else {
                    format!("error E{:02}", info.code)
                };
                format!(
                    "{what} at step {}, nozzle {}, feeder {}: machine stopped",
                    info.step, info.nozzle, info.feeder
                )
            }
            Event::RecoveryOk => "recovery succeeded".to_owned(),
            Event::RecoveryRetry => "recovery failed, retrying".to_owned(),
            Event::RecoveryStop => "recovery failed, machine stops".to_owned(),
        }
    }
}

impl fmt::Display for Event {
    /// `R0CT0023 (board finished in 23 s)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} ({})", self.wire(), self.describe())
    }
}

fn board_time(rest: &str) -> Option<Option<BoardTime>> {
    match rest {
        "" => Some(None),
        digits if digits.len() == BOARD_TIME_WIDTH => {
            wire::ascii::parse_unsigned(digits.as_bytes())
                .map(|s| Some(BoardTime::saturating(s.into())))
        }
        _ => None,
    }
}

fn optional_program(rest: &str) -> Option<Option<ProgramName>> {
    if rest.is_empty() {
        return Some(None);
    }
    ProgramName::parse_field(rest.as_bytes()).ok().map(Some)
}

/// `R1SENG` tails: nothing, `P` + name, or `P` + name padded to 15 + `E` + 3 + 6 \[I\].
fn se_ng(rest: &str) -> Option<Event> {
    const FIXED: usize = 1 + PROGRAM_NAME_LEN + 1 + 3 + DETAIL_LEN;
    if rest.len() == FIXED && rest.as_bytes().get(1 + PROGRAM_NAME_LEN) == Some(&b'E') {
        let program =
            ProgramName::parse_field(rest.get(..1 + PROGRAM_NAME_LEN)?.as_bytes()).ok()?;
        let error = SeNgDetail::new(rest.get(17..20)?, rest.get(20..)?)?;
        return Some(Event::SeNg {
            program: Some(program),
            error: Some(error),
        });
    }
    optional_program(rest).map(|program| Event::SeNg {
        program,
        error: None,
    })
}

#[cfg(test)]
mod tests;
