//! The fixture the edge node, host and describer tests share: one moment, ids and names
//! that are valid, a connected edge node and the metrics of a soldering station.
//!
//! Included by the integration tests (`mod common;`) and by the host's unit tests (with
//! `#[path]`; the crate names itself `sparkplug` in its tests).

#![allow(dead_code)]

use sparkplug::{
    BdSeq, DataType, Delivery, EdgeNode, Id, MetricName, MetricSpec, MetricValue, Publish, Sample,
    Timestamp, Writable, WriteRange,
};

/// 2025-11-24T16:00:00.000Z.
pub const T0: Timestamp = Timestamp::from_millis(1_764_000_000_000);

/// `offset_ms` after [`T0`].
pub fn at(offset_ms: u64) -> Timestamp {
    Timestamp::from_millis(T0.as_millis() + offset_ms)
}

pub fn id(s: &str) -> Id {
    Id::new(s).expect("test ids are valid")
}

pub fn name(s: &str) -> MetricName {
    MetricName::new(s).expect("test names are not empty")
}

/// Edge node `cell/gw1` (bdSeq 7), connected, nothing born.
pub fn connected() -> EdgeNode {
    connected_with(7)
}

/// Edge node `cell/gw1` with `bd_seq`, connected, nothing born.
pub fn connected_with(bd_seq: u8) -> EdgeNode {
    let mut node = EdgeNode::new(id("cell"), id("gw1"), BdSeq::new(bd_seq));
    node.on_connect();
    node
}

/// The read-only air temperature in °C, described as `description`, reading `value` at
/// [`T0`].
pub fn air_temp(value: MetricValue, description: &str) -> (MetricSpec, Sample) {
    (
        MetricSpec::new(name("air_temp"), value.datatype())
            .unit("°C")
            .description(description),
        Sample::good(value, T0),
    )
}

/// The set point in °C, writable 100–450 °C, at 300 °C at [`T0`].
pub fn set_point() -> (MetricSpec, Sample) {
    (
        MetricSpec::new(name("set_point"), DataType::Int32)
            .unit("°C")
            .writable(Writable::Within(WriteRange::new(100.0, 450.0).unwrap())),
        Sample::good(MetricValue::Int32(300), T0),
    )
}

/// The heater switch, `on` at [`T0`].
pub fn heater_on(on: bool) -> (MetricSpec, Sample) {
    (
        MetricSpec::new(name("heater_on"), DataType::Boolean),
        Sample::good(MetricValue::Boolean(on), T0),
    )
}

/// The status text, `idle` at [`T0`].
pub fn status() -> (MetricSpec, Sample) {
    (
        MetricSpec::new(name("status"), DataType::String),
        Sample::good(MetricValue::String("idle".into()), T0),
    )
}

/// The node's event metric (cellbus's convention), empty at [`T0`].
pub fn event_metric() -> (MetricSpec, Sample) {
    (
        sparkplug::event::spec(),
        Sample::good(MetricValue::String(String::new()), T0),
    )
}

/// The live DDATA of `device` after its air temperature changed to `temp` °C at `t`.
pub fn ddata(node: &mut EdgeNode, device: &str, temp: f64, t: Timestamp) -> Publish {
    let changes = [("air_temp", Sample::good(MetricValue::Double(temp), t))];
    node.device_data(&id(device), &changes, t, Delivery::Live)
        .unwrap()
        .expect("the temperature changed")
}
