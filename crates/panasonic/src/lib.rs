//! The host computer protocol of Panasonic BM122/123/133/221/231 placement machines
//! ("PanaProtocol LAN", manual E35HEC-4A-181-B0), without I/O and without a clock.
//!
//! The machine is a TCP server with two ports: **Port 1** (49152) carries the host's C
//! commands and the A/D replies, one exchange at a time; **Port 2** (49153) carries the
//! machine's unsolicited R messages. Both use the same message layout.
//!
//! - [`message`]: the 256-byte command field + big-endian size + data + terminator layout,
//!   as a [`wire::Codec`] that resynchronises after garbage and caps hostile lengths.
//! - [`command`], [`reply`], [`event`]: typed C commands, A/D replies and R events, each
//!   with its encoder; [`packet`] types any message by its class and annotates captures.
//! - [`status`], [`program`], [`production`], [`calendar`]: the values they carry:
//!   machine status, program names and lists, production management data, dates.
//! - [`conversation`]: the Port 1 exchange rules as state machines for the host
//!   ([`HostConversation`]) and the machine ([`MachineConversation`]).
//! - [`keepalive`]: the host's C2HB/R1HB wire-break check.
//! - [`twin`]: a placement-machine model for simulators and tests: program store, modes,
//!   a production run over simulated time, the R-message buffer and the exact refusals.
//!
//! Where the manual is silent or unavailable the crate follows the fact sheet's
//! recommendations; each choice is documented where it is made and marked \[I\] (inferred)
//! or \[?\] (unknown, decided here).
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod calendar;
pub mod command;
pub mod conversation;
pub mod event;
pub mod keepalive;
pub mod message;
pub mod packet;
pub mod production;
pub mod program;
pub mod reply;
pub mod status;
pub mod twin;

#[doc(hidden)]
pub mod fuzzing;

pub use command::{Command, KeepAliveId, ProductionRequest, ProductionScope};
pub use conversation::{
    ConversationError, HostConversation, MachineAnswer, MachineConversation, MachineStep, Next,
    Outcome,
};
pub use event::{BoardTime, ErrorInfo, Event};
pub use message::{DecodeError, Message, MessageCodec};
pub use packet::Packet;
pub use production::ProductionData;
pub use program::{ProgramList, ProgramListEntry, ProgramName, Target};
pub use reply::{A4Reason, Refusal, Reply};
pub use status::{ControlMode, MachineStatus, RunState, StopMode};
pub use twin::{Machine, MachineConfig};

/// Port 1: C commands and their A/D replies.
pub const DEFAULT_COMMAND_PORT: u16 = 49152;
/// Port 2: the machine's R messages.
pub const DEFAULT_EVENT_PORT: u16 = 49153;
