//! Sparkplug B 3.0 for cellbus, sans I/O: the wire formats and the edge node's
//! sequencing rules, testable without a broker. The gateway wires it to an MQTT
//! client; this crate knows nothing of MQTT I/O, tokio or the gateway.
//!
//! - [`topic`][]: [`Topic`] (`spBv1.0/{group}/{type}/{edge_node}[/{device}]`, STATE)
//!   with ids that cannot be invalid ([`Id`]).
//! - [`proto`][]: the protobuf payload, field for field as `proto/sparkplug_b.proto`.
//! - [`metric`][]: [`DataType`], [`MetricValue`], [`Quality`] and [`Reading`],
//!   [`MetricSpec`] (a birth's description) and the conversions to protobuf.
//! - [`node`][]: [`EdgeNode`], the edge node's state machine: Will, births, data,
//!   deaths, `seq` and `bdSeq`, aliases, commands.
//! - [`state`][]: a host application's STATE JSON.
//! - [`host`][]: [`Host`], a host application's state machine: subscriptions, STATE,
//!   births, data by alias, deaths, `seq` gaps and Rebirth requests, turned into points,
//!   samples and events to record.
//! - [`event`][]: a gateway's events as the node metric `Event` (cellbus's convention).
//! - [`describe`][]: what a received message says, in words or JSON, with data
//!   messages' aliases resolved against the births seen ([`Describer`]).
#![forbid(unsafe_code)]
#![warn(missing_docs)]

// The shared test fixture (`tests/common`) names the crate `sparkplug`, as the integration
// tests see it.
#[cfg(test)]
extern crate self as sparkplug;

mod births;
pub mod describe;
pub mod event;
pub mod host;
pub mod metric;
pub mod node;
pub mod proto;
pub mod state;
pub mod topic;

pub use describe::{Describer, Description};
pub use event::NodeEvent;
pub use host::{
    Host, HostEvent, HostProblem, HostSample, PointInfo, PointKey, PointOwner, Problem, Received,
    SampleValue, Sharing, Stats, Subscription,
};
pub use metric::{
    DataType, MetricName, MetricSpec, MetricValue, NameError, Quality, Reading, Sample, Timestamp,
    ValueError, Writable, WriteRange,
};
pub use node::{BdSeq, Command, CommandError, Delivery, EdgeNode, NodeError, Publish, Qos};
pub use state::HostState;
pub use topic::{Id, IdError, MessageKind, Topic, TopicError};
