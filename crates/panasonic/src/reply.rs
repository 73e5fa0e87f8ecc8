//! A and D messages: acknowledgements and data (3.2-1, 4.1-1). Either side sends A
//! messages; D messages carry the machine's data.
//!
//! | reply | wire | meaning |
//! |---|---|---|
//! | [`Reply::Received`] | `A0` | data received OK / send the next |
//! | [`Reply::Finished`] | `A2` | exchange finished without error; leave conversation mode |
//! | [`Reply::NoSuchProgram`] | `A3` | the requested program does not exist |
//! | [`Reply::Invalid`] | `A4E00`, `A4E01` | received data invalid, discarded |
//! | [`Reply::Data`] | `D0` + data | a data block (program, production data, list); answered by `A0` |
//! | [`Reply::Value`] | `D1` + data | a fixed-length value (status, program name); answered by `A2` |
//!
//! There is no `A1`. `A4` sub-codes other than `E00`/`E01` are not in the pages we have
//! \[?\]: they decode as [`A4Reason::Other`], a bare `A4` as [`A4Reason::Unspecified`].

use std::fmt;

use serde::Serialize;

use crate::message::{Message, MessageError};

/// Reply texts.
pub mod code {
    /// Data received OK.
    pub const RECEIVED: &str = "A0";
    /// Exchange finished.
    pub const FINISHED: &str = "A2";
    /// No such program.
    pub const NO_SUCH_PROGRAM: &str = "A3";
    /// Received data invalid.
    pub const INVALID: &str = "A4";
    /// Sub-code letter after `A4`.
    pub const SUB_CODE: &str = "E";
    /// Data block.
    pub const DATA: &str = "D0";
    /// Fixed-length value.
    pub const VALUE: &str = "D1";
}

/// Why the receiver refused with `A4` (4.1-1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum A4Reason {
    /// `A4E00`: operation error, the receiver is not in a state to accept the command.
    OperationError,
    /// `A4E01`: protocol error (also C3 without a selected program).
    ProtocolError,
    /// `A4Enn` with another number.
    Other(u8),
    /// `A4` without a sub-code.
    Unspecified,
}

impl A4Reason {
    /// The text after `A4`.
    pub fn suffix(self) -> String {
        match self {
            A4Reason::OperationError => "E00".to_owned(),
            A4Reason::ProtocolError => "E01".to_owned(),
            A4Reason::Other(n) => format!("E{:02}", n % 100),
            A4Reason::Unspecified => String::new(),
        }
    }

    fn from_suffix(suffix: &str) -> Option<A4Reason> {
        if suffix.is_empty() {
            return Some(A4Reason::Unspecified);
        }
        let digits = suffix.strip_prefix(code::SUB_CODE)?;
        if digits.len() != 2 {
            return None;
        }
        match wire::ascii::parse_unsigned(digits.as_bytes())? {
            0 => Some(A4Reason::OperationError),
            1 => Some(A4Reason::ProtocolError),
            n => u8::try_from(n).ok().map(A4Reason::Other),
        }
    }
}

/// An A or D message.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize)]
#[serde(tag = "reply", content = "data", rename_all = "snake_case")]
pub enum Reply {
    /// `A0`.
    Received,
    /// `A2`.
    Finished,
    /// `A3`.
    NoSuchProgram,
    /// `A4…`.
    Invalid(A4Reason),
    /// `D0` + data block.
    Data(#[serde(skip)] Vec<u8>),
    /// `D1` + fixed-length value.
    Value(#[serde(skip)] Vec<u8>),
}

/// A message that is not an A or D message we know.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ReplyError {
    /// Not A0/A2/A3/A4/D0/D1.
    #[error("{command:?} is not a known A or D message")]
    Unknown {
        /// The command text.
        command: String,
    },
    /// An A message with data.
    #[error("{command} takes no data but came with {size} bytes")]
    UnexpectedData {
        /// The command text.
        command: String,
        /// Bytes of data.
        size: usize,
    },
}

impl Reply {
    /// `A4E00`.
    pub const OPERATION_ERROR: Reply = Reply::Invalid(A4Reason::OperationError);
    /// `A4E01`.
    pub const PROTOCOL_ERROR: Reply = Reply::Invalid(A4Reason::ProtocolError);

    /// The command text on the wire.
    pub fn wire(&self) -> String {
        match self {
            Reply::Received => code::RECEIVED.to_owned(),
            Reply::Finished => code::FINISHED.to_owned(),
            Reply::NoSuchProgram => code::NO_SUCH_PROGRAM.to_owned(),
            Reply::Invalid(reason) => format!("{}{}", code::INVALID, reason.suffix()),
            Reply::Data(_) => code::DATA.to_owned(),
            Reply::Value(_) => code::VALUE.to_owned(),
        }
    }

    /// The message to send (fails only for data above [`MAX_DATA_LEN`]).
    ///
    /// [`MAX_DATA_LEN`]: crate::message::MAX_DATA_LEN
    pub fn to_message(&self) -> Result<Message, MessageError> {
        let data = match self {
            Reply::Data(data) | Reply::Value(data) => data.clone(),
            _ => Vec::new(),
        };
        Message::with_data(&self.wire(), data)
    }

    /// The message of a reply without data (`A0`, `A2`, `A3`, `A4…`, or `D0`/`D1` with their
    /// data left out): cannot fail, so the state machines use it for acknowledgements.
    pub(crate) fn ack_message(&self) -> Message {
        Message::new(&self.wire()).expect("reply texts are short capitalised ASCII")
    }

    /// Reads an A or D message.
    pub fn parse(message: &Message) -> Result<Reply, ReplyError> {
        let text = message.command();
        let unknown = || ReplyError::Unknown {
            command: text.to_owned(),
        };
        let data = message.data();
        let reply = match text {
            code::DATA => return Ok(Reply::Data(data.to_vec())),
            code::VALUE => return Ok(Reply::Value(data.to_vec())),
            code::RECEIVED => Reply::Received,
            code::FINISHED => Reply::Finished,
            code::NO_SUCH_PROGRAM => Reply::NoSuchProgram,
            _ => {
                let suffix = text.strip_prefix(code::INVALID).ok_or_else(unknown)?;
                Reply::Invalid(A4Reason::from_suffix(suffix).ok_or_else(unknown)?)
            }
        };
        if data.is_empty() {
            Ok(reply)
        } else {
            Err(ReplyError::UnexpectedData {
                command: text.to_owned(),
                size: data.len(),
            })
        }
    }

    /// What it means, in words.
    pub fn describe(&self) -> String {
        match self {
            Reply::Received => "data received OK".to_owned(),
            Reply::Finished => "exchange finished".to_owned(),
            Reply::NoSuchProgram => "no such program".to_owned(),
            Reply::Invalid(A4Reason::OperationError) => "refused: operation error".to_owned(),
            Reply::Invalid(A4Reason::ProtocolError) => "refused: protocol error".to_owned(),
            Reply::Invalid(A4Reason::Other(n)) => format!("refused: error E{n:02}"),
            Reply::Invalid(A4Reason::Unspecified) => "refused".to_owned(),
            Reply::Data(data) => format!("data block of {}", wire::words::Bytes(data.len())),
            Reply::Value(data) => format!("value {:?}", String::from_utf8_lossy(data)),
        }
    }
}

impl fmt::Display for Reply {
    /// `A4E00 (refused: operation error)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} ({})", self.wire(), self.describe())
    }
}

/// The machine's "no" to a command: `A3` or `A4…`, with its meaning in words.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize)]
pub struct Refusal {
    /// The command refused, as sent (e.g. `C5STCT`).
    pub command: String,
    /// `A3` ([`Reply::NoSuchProgram`]) or `A4…` ([`Reply::Invalid`]).
    pub reply: Reply,
}

impl Refusal {
    /// Why the machine refuses this command, in words a plant engineer can act on.
    pub fn meaning(&self) -> String {
        let command = self.command.as_str();
        match &self.reply {
            Reply::NoSuchProgram => match command
                .strip_prefix("C1P")
                .or_else(|| command.strip_prefix("C0RP"))
            {
                Some(name) => format!("program {name:?} does not exist on the machine"),
                None => "the requested program or data does not exist on the machine".to_owned(),
            },
            Reply::Invalid(A4Reason::OperationError) => {
                let why = if command.starts_with("C5") {
                    "C5 commands need Remote mode, a selected program and no error stop (start), or a stopped machine (reset)"
                } else if command.starts_with("C0R") {
                    "the program is selected or being edited, or is not a product program"
                } else if command.starts_with("C0") {
                    "the program is selected or being edited, or the storage limits (100 programs, 5000 steps, library sizes) would be exceeded"
                } else if command.starts_with("C2HB") {
                    "the keep-alive was malformed (the port itself works)"
                } else {
                    "the machine is busy with another exchange or cannot take this command now"
                };
                format!(
                    "operation error (A4E00): the machine is not in a state to accept {command}: {why}"
                )
            }
            Reply::Invalid(A4Reason::ProtocolError) => {
                if command.starts_with("C3") {
                    "protocol error (A4E01): no product program is selected".to_owned()
                } else {
                    format!(
                        "protocol error (A4E01): the machine found {command} or its data invalid and discarded it"
                    )
                }
            }
            Reply::Invalid(A4Reason::Other(n)) => {
                format!(
                    "the machine refused {command} with error A4E{n:02}, which the manual pages we have do not explain"
                )
            }
            Reply::Invalid(A4Reason::Unspecified) => {
                format!("the machine refused {command} (A4, no reason given)")
            }
            other => format!("the machine answered {command} with {}", other.wire()),
        }
    }
}

impl fmt::Display for Refusal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "machine refused {}: {}", self.command, self.meaning())
    }
}

impl std::error::Error for Refusal {}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn every_reply_of_the_manual_parses_from_its_text() {
        let cases = [
            ("A0", Reply::Received),
            ("A2", Reply::Finished),
            ("A3", Reply::NoSuchProgram),
            ("A4E00", Reply::OPERATION_ERROR),
            ("A4E01", Reply::PROTOCOL_ERROR),
            ("A4E07", Reply::Invalid(A4Reason::Other(7))),
            ("A4", Reply::Invalid(A4Reason::Unspecified)),
        ];
        for (text, reply) in cases {
            assert_eq!(
                Reply::parse(&Message::new(text).expect("valid")),
                Ok(reply.clone()),
                "{text}"
            );
            assert_eq!(reply.wire(), text);
            assert_eq!(reply.ack_message().command(), text);
        }
    }

    #[test]
    fn d1_001_is_a_value_reply() {
        let message = Message::with_data("D1", b"001".to_vec()).expect("valid");
        assert_eq!(Reply::parse(&message), Ok(Reply::Value(b"001".to_vec())));
        assert_eq!(Reply::Value(b"001".to_vec()).to_message(), Ok(message));
    }

    #[test]
    fn unknown_a_codes_and_a_replies_with_data_are_refused() {
        for text in ["A1", "A4X00", "A4E0", "A4E001", "D2", "A"] {
            assert!(
                matches!(
                    Reply::parse(&Message::new(text).expect("valid")),
                    Err(ReplyError::Unknown { .. })
                ),
                "{text}"
            );
        }
        let a2_with_data = Message::with_data("A2", b"x".to_vec()).expect("valid");
        assert_eq!(
            Reply::parse(&a2_with_data),
            Err(ReplyError::UnexpectedData {
                command: "A2".into(),
                size: 1
            })
        );
    }

    #[test]
    fn refusals_explain_themselves_per_command() {
        let refusal = |command: &str, reply| Refusal {
            command: command.into(),
            reply,
        };
        assert_eq!(
            refusal("C1PABC", Reply::NoSuchProgram).meaning(),
            "program \"ABC\" does not exist on the machine"
        );
        assert_eq!(
            refusal("C0RPABC", Reply::NoSuchProgram).meaning(),
            "program \"ABC\" does not exist on the machine"
        );
        for (command, reply, words) in [
            ("C5STCT", Reply::OPERATION_ERROR, "Remote mode"),
            ("C0PABC", Reply::OPERATION_ERROR, "storage limits"),
            ("C2HB00ABC123", Reply::OPERATION_ERROR, "port itself works"),
            (
                "C3P",
                Reply::PROTOCOL_ERROR,
                "no product program is selected",
            ),
        ] {
            let meaning = refusal(command, reply).meaning();
            assert!(meaning.contains(words), "{command}: {meaning}");
        }
        assert!(
            refusal("C1M000", Reply::PROTOCOL_ERROR)
                .to_string()
                .starts_with("machine refused C1M000: protocol error")
        );
    }

    proptest! {
        #[test]
        fn replies_round_trip(reply in prop_oneof![
            Just(Reply::Received),
            Just(Reply::Finished),
            Just(Reply::NoSuchProgram),
            (0u8..100).prop_map(|n| Reply::Invalid(A4Reason::from_suffix(&format!("E{n:02}")).expect("two digits"))),
            Just(Reply::Invalid(A4Reason::Unspecified)),
            prop::collection::vec(any::<u8>(), 0..300).prop_map(Reply::Data),
            prop::collection::vec(any::<u8>(), 0..20).prop_map(Reply::Value),
        ]) {
            let message = reply.to_message().expect("fits");
            prop_assert_eq!(Reply::parse(&message), Ok(reply));
        }
    }
}
