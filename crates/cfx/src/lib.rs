//! IPC-CFX (IPC-2591, Connected Factory Exchange) for cellbus, sans I/O: the envelope
//! ([`envelope::Envelope`]), the message bodies a placement machine publishes and the root
//! topic's requests and responses ([`messages`]), and the values they are made of
//! ([`types`]), written in JSON field by field as the official SDK (2.1.1) writes them,
//! and the AMQP 1.0 properties each message travels with. No AMQP client and no clock:
//! the gateway's CFX interface sends what this crate writes.
//!
//! The SDK's conventions: PascalCase names; enumerations as their names, except resource
//! states (numbers: 1100, 5500); `TimeSpan` as `hh:mm:ss[.fffffff]`; times in ISO 8601
//! with seven decimals and the zone's offset; every property written, `null` when not set;
//! a polymorphic value (the envelope's body, an SMT placement fault) carries
//! `"$type": "<full type name>, CFX"` first.

pub mod endpoint;
pub mod envelope;
pub mod messages;
pub mod types;

pub use envelope::{Envelope, Received};
pub use messages::Message;
pub use types::{Handle, ResourceState, Time, TimeSpan};

#[cfg(test)]
mod tests;
