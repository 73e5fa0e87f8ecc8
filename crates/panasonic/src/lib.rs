//! The host computer protocol of Panasonic BM122/123/133/221/231 placement machines
//! ("PanaProtocol LAN", manual E35HEC-4A-181-B0): a sans-IO core, the twin's TCP server
//! and the host's async client.
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
//! - [`operator`]: the commands an operator gives the twin at its panel (`start ep`,
//!   `pause-feeder 7`, `clear`), parsed and carried out the same way by `cellbus sim` and
//!   the gateway's demo cell.
//! - [`server`]: the twin on its two TCP ports (tokio), with a control handle for tests
//!   and demos; [`client`]: the host side over [`link`]: every C command with time-outs,
//!   the keep-alive, reconnection with backoff, and the R messages as a typed stream.
//!
//! Everything but `server` and `client` is sans-IO: no sockets, no clock.
//!
//! Where the manual is silent or unavailable the crate follows the fact sheet's
//! recommendations; each choice is documented where it is made and marked \[I\] (inferred)
//! or \[?\] (unknown, decided here).
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod calendar;
#[cfg(feature = "io")]
pub mod client;
pub mod command;
pub mod conversation;
pub mod event;
pub mod keepalive;
pub mod message;
pub mod operator;
pub mod packet;
pub mod production;
pub mod program;
pub mod reply;
#[cfg(feature = "io")]
pub mod server;
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

/// One of the machine's two TCP ports (3.1-1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Port {
    /// Port 1 (49152): C commands and their A/D replies, one exchange at a time.
    Command,
    /// Port 2 (49153): the machine's unsolicited R messages.
    Event,
}

impl Port {
    /// The port's number in the manual (1 or 2).
    pub const fn number(self) -> u8 {
        match self {
            Port::Command => 1,
            Port::Event => 2,
        }
    }

    /// The machine's default TCP port for it.
    pub const fn default_tcp_port(self) -> u16 {
        match self {
            Port::Command => DEFAULT_COMMAND_PORT,
            Port::Event => DEFAULT_EVENT_PORT,
        }
    }
}

impl std::fmt::Display for Port {
    /// `Port 1 (commands)`, `Port 2 (events)`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Port::Command => f.write_str("Port 1 (commands)"),
            Port::Event => f.write_str("Port 2 (events)"),
        }
    }
}
