//! A gateway's events over Sparkplug: cellbus's own convention on top of the spec.
//!
//! The NBIRTH carries a String node metric [`EVENT`] (`Event`, value empty). Each event
//! is then an NDATA with that metric by alias: the value is the event's message, the
//! metric's timestamp the event's time, and its properties say the rest:
//!
//! | property | type | what |
//! |---|---|---|
//! | `kind` | String | the event's kind as the gateway's `/api/events` spells it (`device_down`) |
//! | `severity` | UInt32 | 1–1000, as the gateway's OPC UA events (700 an alarm, 200 a write) |
//! | `line` | String | the line, when the event concerns one |
//! | `device` | String | the device, when the event concerns one |
//! | `point` | String | the point's name within its device, when it concerns one |
//! | `fields` | String | the event's facts for programs as a JSON object (`{"feeder":7}`), when it has any |
//!
//! Events are sent live, never repeated (two equal events are two NDATA), and are not
//! part of the store-and-forward backlog: events of an outage are not sent after it.
//! [`EdgeNode::node_event`](crate::EdgeNode::node_event) builds the NDATA; the
//! [`Host`](crate::Host) reads it back as a [`HostEvent`](crate::host::HostEvent).

use crate::metric::{
    DataType, MetricName, MetricSpec, Properties, Timestamp, string_property, uint32_property,
};
use crate::proto::{Metric, metric};

/// The name of the node metric that carries events.
pub const EVENT: &str = "Event";
/// Event property: the kind (String).
pub const KIND: &str = "kind";
/// Event property: the severity, 1–1000 (UInt32).
pub const SEVERITY: &str = "severity";
/// Event property: the line (String).
pub const LINE: &str = "line";
/// Event property: the device (String).
pub const DEVICE: &str = "device";
/// Event property: the point's name within its device (String).
pub const POINT: &str = "point";
/// Event property: the event's facts as a JSON object (String).
pub const FIELDS: &str = "fields";

/// One event as an edge node publishes it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeEvent {
    /// When it happened.
    pub t: Timestamp,
    /// What kind (`alarm_raised`, `device_down`, …).
    pub kind: String,
    /// How grave: 1–1000.
    pub severity: u32,
    /// Words for the event log.
    pub message: String,
    /// The line, if it concerns one.
    pub line: Option<String>,
    /// The device, if it concerns one.
    pub device: Option<String>,
    /// The point's name within its device, if it concerns one.
    pub point: Option<String>,
    /// The event's facts as a JSON object's text, if it has any.
    pub fields: Option<String>,
}

/// The birth description of the [`EVENT`] metric, to put among a node's metrics in its
/// NBIRTH (with an empty String value).
pub fn spec() -> MetricSpec {
    MetricSpec::new(
        MetricName::new(EVENT).expect("the event metric's name is not empty"),
        DataType::String,
    )
    .description("the gateway's events: each NDATA value is one event's message")
}

/// The data metric of `event`, by `alias`.
pub(crate) fn metric(alias: u64, event: &NodeEvent) -> Metric {
    let mut properties = Properties::default();
    properties.push(KIND, string_property(&event.kind));
    properties.push(SEVERITY, uint32_property(event.severity));
    for (key, value) in [
        (LINE, &event.line),
        (DEVICE, &event.device),
        (POINT, &event.point),
        (FIELDS, &event.fields),
    ] {
        if let Some(value) = value {
            properties.push(key, string_property(value));
        }
    }
    Metric {
        alias: Some(alias),
        timestamp: Some(event.t.as_millis()),
        value: Some(metric::Value::StringValue(event.message.clone())),
        properties: properties.into_option(),
        ..Metric::default()
    }
}
