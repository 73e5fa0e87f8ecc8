//! Any message, typed by its class letter, and annotated dumps of captures.
//!
//! [`Packet::classify`] turns a [`Message`] into a C command, an A/D reply or an R event,
//! or keeps it raw with the reason it is not one ([`Packet::Unknown`]): the twin answers
//! those with `A4E01`, and `cellbus decode panasonic` prints them as they are.

use std::fmt;

use wire::Deframer;
use wire::codec::Chunk;

use crate::command::{self, Command};
use crate::event::{self, Event};
use crate::message::{DecodeError, Message, MessageCodec};
use crate::reply::Reply;

/// A message, typed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Packet {
    /// A C command (host → machine).
    Command(Command),
    /// An A or D message (either way).
    Reply(Reply),
    /// An R message (machine → host, Port 2).
    Event(Event),
    /// A message that is none of those, kept raw.
    Unknown {
        /// The message.
        message: Message,
        /// Why it is not typed.
        reason: String,
    },
}

impl Packet {
    /// Types a message by its class letter.
    pub fn classify(message: &Message) -> Packet {
        let unknown = |reason: String| Packet::Unknown {
            message: message.clone(),
            reason,
        };
        match message.command().chars().next() {
            Some(command::code::CLASS) => {
                Command::parse(message).map_or_else(|e| unknown(e.to_string()), Packet::Command)
            }
            Some('A' | 'D') => {
                Reply::parse(message).map_or_else(|e| unknown(e.to_string()), Packet::Reply)
            }
            Some(event::code::CLASS) => {
                Event::parse(message).map_or_else(|e| unknown(e.to_string()), Packet::Event)
            }
            _ => unknown(format!(
                "{:?} is not a C, A, D or R message",
                message.command()
            )),
        }
    }
}

impl fmt::Display for Packet {
    /// `C2ST (ask for the machine status)`, `R0CT0023 (board finished in 23 s)`, …
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Packet::Command(command) => command.fmt(f),
            Packet::Reply(reply) => reply.fmt(f),
            Packet::Event(event) => event.fmt(f),
            Packet::Unknown { message, reason } => {
                write!(f, "{message} (not understood: {reason})")
            }
        }
    }
}

/// One piece of an annotated capture.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Annotation {
    /// Offset of the first byte in the capture.
    pub offset: usize,
    /// Bytes covered.
    pub len: usize,
    /// A message, or bytes that were skipped.
    pub item: Annotated,
}

/// What a piece of a capture is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Annotated {
    /// A message and its meaning.
    Message(Packet),
    /// Bytes skipped, and why.
    Skipped(DecodeError),
    /// Bytes at the end that do not (yet) make a message.
    Incomplete,
}

impl fmt::Display for Annotation {
    /// `@0 263 bytes: C2ST (ask for the machine status)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "@{} {} bytes: ", self.offset, self.len)?;
        match &self.item {
            Annotated::Message(packet) => packet.fmt(f),
            Annotated::Skipped(error) => write!(f, "skipped: {error}"),
            Annotated::Incomplete => f.write_str("incomplete message at the end of the capture"),
        }
    }
}

/// Splits a capture into messages and skipped bytes, each with its meaning.
pub fn annotate(capture: &[u8]) -> Vec<Annotation> {
    let mut deframer = Deframer::new(MessageCodec);
    deframer.push(capture);
    let mut offset = 0;
    let mut out = Vec::new();
    while let Some(chunk) = deframer.next_chunk() {
        let (len, item) = match chunk {
            Chunk::Frame { frame, raw } => {
                (raw.len(), Annotated::Message(Packet::classify(&frame)))
            }
            Chunk::Skipped { error, raw } => (raw.len(), Annotated::Skipped(error)),
        };
        out.push(Annotation { offset, len, item });
        offset += len;
    }
    if !deframer.buffered().is_empty() {
        out.push(Annotation {
            offset,
            len: deframer.buffered().len(),
            item: Annotated::Incomplete,
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classify_types_each_class_and_keeps_the_rest_raw() {
        let packet = |text: &str| Packet::classify(&Message::new(text).expect("valid"));
        assert_eq!(packet("C2ST"), Packet::Command(Command::Status));
        assert_eq!(packet("A2"), Packet::Reply(Reply::Finished));
        assert_eq!(packet("R1ST"), Packet::Event(Event::Started));
        assert!(matches!(packet("C9ZZ"), Packet::Unknown { .. }));
        assert!(matches!(packet("X1"), Packet::Unknown { .. }));
        assert_eq!(
            packet("C2ST").to_string(),
            "C2ST (ask for the machine status)"
        );
    }

    #[test]
    fn annotate_covers_every_byte_of_a_capture() {
        let mut capture = Message::new("C2ST").expect("valid").to_bytes();
        capture.extend(b"\x00\x00junk");
        capture.extend(
            Message::with_data("D1", b"001".to_vec())
                .expect("valid")
                .to_bytes(),
        );
        capture.extend(b"R1");
        let notes = annotate(&capture);
        assert_eq!(notes.iter().map(|n| n.len).sum::<usize>(), capture.len());
        assert_eq!(
            notes[0].to_string(),
            "@0 263 bytes: C2ST (ask for the machine status)"
        );
        assert!(matches!(
            notes[1].item,
            Annotated::Skipped(DecodeError::NotAStart { .. })
        ));
        assert!(
            notes
                .iter()
                .any(|n| n.to_string().contains("D1 (value \"001\")"))
        );
        assert_eq!(notes.last().map(|n| &n.item), Some(&Annotated::Incomplete));
    }

    #[test]
    fn every_typed_value_serialises_to_json_for_the_cli() {
        use crate::command::{KeepAliveId, ProductionRequest, ProductionScope};
        use crate::event::{BoardTime, ErrorInfo};
        use crate::program::{ProgramName, Target};
        use crate::status::StopMode;
        let json = |value: &dyn erased::Json| value.json();
        let abc = ProgramName::new("ABC").expect("valid");
        let commands = [
            Command::Download {
                target: Target::Product(abc.clone()),
                data: b"*\r\n".to_vec(),
            },
            Command::Delete {
                target: Target::PartLibrary,
            },
            Command::Upload {
                target: Target::MachineData,
            },
            Command::Production(ProductionRequest {
                scope: ProductionScope::CurrentTotal,
                clear: true,
            }),
            Command::ProgramList,
            Command::Status,
            Command::KeepAlive(KeepAliveId::new("ABC123").expect("valid")),
            Command::CurrentProgram,
            Command::Start(Some(StopMode::OneBlock)),
            Command::Start(None),
            Command::Reset,
        ];
        for command in &commands {
            assert!(json(command).contains("\"command\""), "{command}");
        }
        assert_eq!(
            json(&Command::KeepAlive(
                KeepAliveId::new("ABC123").expect("valid")
            )),
            r#"{"command":"keep_alive","args":"ABC123"}"#
        );
        let events = [
            Event::BoardFinished {
                time: Some(BoardTime::new(22).expect("fits")),
            },
            Event::Heartbeat {
                id: KeepAliveId::new("ABC123").expect("valid"),
            },
            Event::Se { program: Some(abc) },
            Event::Error(ErrorInfo::new(3, 1, 2, 3).expect("valid")),
            Event::RecoveryOk,
        ];
        for event in &events {
            assert!(json(event).starts_with("{\"event\":"), "{event}");
        }
        assert_eq!(json(&events[0]), r#"{"event":"board_finished","time":22}"#);
        for reply in [
            Reply::Finished,
            Reply::PROTOCOL_ERROR,
            Reply::Value(b"001".to_vec()),
        ] {
            assert!(json(&reply).contains("\"reply\""), "{reply}");
        }
        let status = crate::status::MachineStatus::parse(b"001").expect("valid");
        assert_eq!(json(&status), r#"{"state":"run","mode":"remote"}"#);
    }

    /// `serde_json::to_string` behind a trait object, so one helper takes every type.
    mod erased {
        pub trait Json {
            fn json(&self) -> String;
        }
        impl<T: serde::Serialize> Json for T {
            fn json(&self) -> String {
                serde_json::to_string(self).expect("every typed value serialises")
            }
        }
    }
}
