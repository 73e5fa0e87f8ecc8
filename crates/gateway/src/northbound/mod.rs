//! The gateway's northbound side: interfaces that publish the cell to other systems.
//!
//! The rule every interface here follows: it reads only from the cell's one change stream
//! ([`Cell::subscribe`](crate::cell::Cell::subscribe), plus
//! [`Cell::devices`](crate::cell::Cell::devices) for births) and writes only through the
//! cell's one guarded write path; it never polls a device or knows a field protocol.
//!
//! - [`mqtt`]: the cell on an MQTT broker (rumqttc), as a Sparkplug B edge node
//!   ([`sparkplug::EdgeNode`]) or as plain JSON, with store and forward.
//! - OPC UA, the cell as an OPC UA server (async-opcua), is a crate of its own
//!   (`cellbus-opcua`, in `crates/opcua`) behind the binary's `opcua` feature: it
//!   implements [`Northbound`] with only what this crate makes public.
//!
//! This module holds the sans-IO mapping from the cell's points to Sparkplug metrics:
//!
//! | point kind | Sparkplug datatype | value |
//! |---|---|---|
//! | numeric | Double | the number |
//! | enumeration | Int32 | the state's number (labels are in the gateway's API) |
//! | text | String | the text |
//!
//! A point whose quality is stale or bad, or that was never read, is sent as null with
//! the `Quality` property (Stale 500, Bad 0), never with its last good value. Each metric is
//! named by the point's short name (`air_temperature`); its words go in the
//! `Documentation` property, its unit in `engUnit`, and writability and range in
//! `writable`, `writeMin`, `writeMax`.

pub mod mqtt;
#[cfg(test)]
mod tests;

use std::fmt;
use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;

use tokio::sync::watch;
use tokio::task::JoinHandle;

use crate::cell::Cell;
use crate::config::{CellConfig, TableReader};
use crate::http::WritePolicy;
use crate::options::ServeOptions;
use sparkplug::{DataType, MetricName, MetricSpec, MetricValue, Sample, Writable, WriteRange};

use crate::cell::{DeviceView, PointDetail, PointView};
use crate::point::{PointKind, Quality, Value};
use crate::time::Timestamp;

/// This machine's host name as an id (a Sparkplug id: no `/`, `+`, `#`), else `cellbus`:
/// the MQTT edge node's default id and the OPC UA application URI's host part.
pub fn default_edge_node_id() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .map(|h| h.trim().to_owned())
        .filter(|h| sparkplug::Id::new(h.as_str()).is_ok())
        .unwrap_or_else(|| "cellbus".to_owned())
}

/// An interface that serves the cell to other systems: what `serve` asks of each. It is
/// listed once in a [`Registry`](crate::plugins::Registry) (the gateway's own in
/// [`crate::plugins::builtin`], another crate's by the binary through
/// [`Registry::with_interface`](crate::plugins::Registry::with_interface)); `serve` starts
/// every one the config or the options ask for and stops them in turn. It reads only the
/// cell's change stream and writes only through the cell's write path.
pub trait Northbound: Sync + fmt::Debug {
    /// Its name in logs and messages (`mqtt`).
    fn name(&self) -> &'static str;

    /// The reader of its table in the config file (`[mqtt]`).
    fn table(&self) -> &'static dyn TableReader;

    /// Starts it when its table or the options ask for it (`Ok(None)`: not asked for).
    /// An error stops the gateway's start: a port taken, a password variable not set.
    fn start<'a>(&'a self, start: Start<'a>) -> BoxStart<'a>;
}

/// What [`Northbound::start`] returns.
pub type BoxStart<'a> = Pin<Box<dyn Future<Output = anyhow::Result<Option<Running>>> + Send + 'a>>;

/// What an interface starts with.
#[derive(Debug, Clone)]
pub struct Start<'a> {
    /// The live cell: its change stream, its points, its write path.
    pub cell: &'a Arc<Cell>,
    /// The checked configuration (the interface's table is in
    /// [`CellConfig::interfaces`]).
    pub config: &'a CellConfig,
    /// What `cellbus serve` was asked for.
    pub options: &'a ServeOptions,
    /// Whether this is the demo cell (no config file).
    pub demo: bool,
    /// Who may write.
    pub writes: &'a WritePolicy,
    /// Turns true when the gateway stops.
    pub stopped: watch::Receiver<bool>,
}

/// A started interface.
#[derive(Debug)]
pub struct Running {
    /// Its name.
    pub name: &'static str,
    /// Where clients reach it, printed under `listening on …` at start
    /// (`opcua on opc.tcp://…`); `None` for an interface that connects out (MQTT).
    pub url: Option<String>,
    /// Ends when it has stopped.
    pub task: JoinHandle<()>,
}

/// The Sparkplug data type of a point of `kind`.
pub fn datatype_of(kind: &PointKind) -> DataType {
    match kind {
        PointKind::Numeric => DataType::Double,
        PointKind::Enum { .. } => DataType::Int32,
        PointKind::Text => DataType::String,
    }
}

/// The birth description of a point.
pub fn metric_spec(point: &PointDetail) -> Option<MetricSpec> {
    let view = &point.view;
    let name = MetricName::new(view.id.name()).ok()?;
    let mut metric =
        MetricSpec::new(name, datatype_of(&point.kind)).description(view.name.as_ref());
    if let Some(unit) = &view.unit {
        metric = metric.unit(unit.as_ref());
    }
    if let Some(range) = point.writable {
        let writable = match (&point.kind, WriteRange::new(range.min, range.max)) {
            (PointKind::Text, _) | (_, Err(_)) => Writable::Yes,
            (_, Ok(range)) => Writable::Within(range),
        };
        metric = metric.writable(writable);
    }
    Some(metric)
}

/// A point's current reading as a Sparkplug sample: the value only when its quality is
/// good, timed when the device was read (`now` if never).
pub fn sample_of(kind: &PointKind, view: &PointView, now: Timestamp) -> Sample {
    match view.quality {
        Some(quality) => {
            sample_of_stored(kind, view.value.as_ref(), quality, view.t.unwrap_or(now))
        }
        None => Sample::bad(sparkplug_time(view.t.unwrap_or(now))),
    }
}

/// A reading (live or stored) read at `t` as a Sparkplug sample: the value only when its
/// quality is good.
pub fn sample_of_stored(
    kind: &PointKind,
    value: Option<&Value>,
    quality: Quality,
    t: Timestamp,
) -> Sample {
    let t = sparkplug_time(t);
    match (quality, value) {
        (Quality::Good, Some(value)) => match metric_value(kind, value) {
            Some(value) => Sample::good(value, t),
            None => Sample::bad(t),
        },
        (Quality::Stale, _) => Sample::stale(t),
        _ => Sample::bad(t),
    }
}

/// Every point of `device`, described and with its current reading, for a DBIRTH.
pub fn device_metrics(device: &DeviceView, now: Timestamp) -> Vec<(MetricSpec, Sample)> {
    device
        .points
        .iter()
        .filter_map(|p| Some((metric_spec(p)?, sample_of(&p.kind, &p.view, now))))
        .collect()
}

/// A gateway time as a Sparkplug time (times before 1970 read as 1970).
pub fn sparkplug_time(t: Timestamp) -> sparkplug::Timestamp {
    sparkplug::Timestamp::from_millis(u64::try_from(t.0).unwrap_or(0))
}

fn metric_value(kind: &PointKind, value: &Value) -> Option<MetricValue> {
    match (kind, value) {
        (PointKind::Numeric, Value::Number(n)) => Some(MetricValue::Double(*n)),
        (PointKind::Enum { .. }, Value::Number(n)) => {
            let whole = n.round();
            (whole == *n && whole >= f64::from(i32::MIN) && whole <= f64::from(i32::MAX))
                .then_some(MetricValue::Int32(whole as i32))
        }
        (PointKind::Text, Value::Text(t)) => Some(MetricValue::String(t.clone())),
        (PointKind::Text, Value::Number(n)) => Some(MetricValue::String(n.to_string())),
        _ => None,
    }
}

#[cfg(test)]
mod mapping_tests {
    use super::*;
    use crate::point::EnumState;

    use crate::testing::air_temperature_view as view;

    #[test]
    fn a_good_number_is_a_double_timed_when_it_was_read() {
        let s = sample_of(
            &PointKind::Numeric,
            &view(Some(Value::Number(21.5)), Some(Quality::Good)),
            Timestamp(9_000),
        );
        assert_eq!(
            s,
            Sample::good(
                MetricValue::Double(21.5),
                sparkplug::Timestamp::from_millis(1_000)
            )
        );
    }

    #[test]
    fn a_stale_or_bad_point_is_sent_without_its_last_good_value() {
        let now = Timestamp(9_000);
        let stale = sample_of(
            &PointKind::Numeric,
            &view(Some(Value::Number(21.5)), Some(Quality::Stale)),
            now,
        );
        assert_eq!(stale.reading, sparkplug::Reading::Stale);
        let bad = sample_of(
            &PointKind::Numeric,
            &view(Some(Value::Number(21.5)), Some(Quality::Bad)),
            now,
        );
        assert_eq!(bad.reading, sparkplug::Reading::Bad);
        let never = sample_of(&PointKind::Numeric, &view(None, None), now);
        assert_eq!(never.reading, sparkplug::Reading::Bad);
    }

    #[test]
    fn an_enumeration_is_an_int32_of_its_state_number() {
        let kind = PointKind::Enum {
            states: vec![EnumState {
                value: 9,
                label: "No tool".into(),
            }],
        };
        assert_eq!(datatype_of(&kind), DataType::Int32);
        let s = sample_of(
            &kind,
            &view(Some(Value::Number(9.0)), Some(Quality::Good)),
            Timestamp(0),
        );
        assert_eq!(s.reading, sparkplug::Reading::Good(MetricValue::Int32(9)));
    }
}
