//! The sans-IO mapping from the cell's points to Sparkplug metrics:
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
//!
//! Each alarm of a device is three metrics of the device, named by the alarm's id without
//! the device (`sealer0.temperature:high` of `sealer0` is `Alarms/temperature:high/…`):
//! `State` (String: normal, unacknowledged, acknowledged, returned_unacknowledged),
//! `Priority` (Int32, 1 low to 4 urgent) and `Acknowledged` (Boolean), which a host sets
//! to true by DCMD to acknowledge the alarm when commands are allowed.

use sparkplug::{DataType, MetricName, MetricSpec, MetricValue, Sample, Writable, WriteRange};

use crate::alarm::book::View as AlarmView;
use crate::cell::{DeviceView, PointDetail, PointView};
use crate::point::{PointKind, Quality, Value};
use crate::time::Timestamp;

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

/// The first part of every alarm metric's name.
pub const ALARMS: &str = "Alarms/";

/// The metric names of alarm `id` of `device`, as `(state, priority, acknowledged)`.
pub fn alarm_metric_names(device: &str, id: &str) -> Option<(MetricName, MetricName, MetricName)> {
    let short = id
        .strip_prefix(device)
        .and_then(|rest| rest.strip_prefix(['.', ':']))
        .unwrap_or(id);
    let name = |what: &str| MetricName::new(format!("{ALARMS}{short}/{what}")).ok();
    Some((name("State")?, name("Priority")?, name("Acknowledged")?))
}

/// The alarm ids a DCMD's `Alarms/{short}/Acknowledged` of `device` may mean: the device's
/// point alarm (`device.short`) or its own (`device:short`). `None`: not an alarm's
/// acknowledgement.
pub fn acknowledged_alarm(device: &str, metric: &str) -> Option<[String; 2]> {
    let short = metric.strip_prefix(ALARMS)?.strip_suffix("/Acknowledged")?;
    Some([format!("{device}.{short}"), format!("{device}:{short}")])
}

/// An alarm's three metrics with their samples: for a DBIRTH (with `writable`: DCMDs
/// are carried out) and for a DDATA.
pub fn alarm_metrics(
    device: &str,
    alarm: &AlarmView,
    writable: bool,
    t: Timestamp,
) -> Vec<(MetricSpec, Sample)> {
    let Some((state, priority, acknowledged)) = alarm_metric_names(device, &alarm.id) else {
        return Vec::new();
    };
    let t = sparkplug_time(t);
    vec![
        (
            MetricSpec::new(state, DataType::String).description(alarm.message.as_str()),
            Sample::good(MetricValue::String(alarm.state.as_str().to_owned()), t),
        ),
        (
            MetricSpec::new(priority, DataType::Int32)
                .description("The alarm's priority: 1 low, 2 medium, 3 high, 4 urgent"),
            Sample::good(MetricValue::Int32(i32::from(alarm.priority.number())), t),
        ),
        (
            MetricSpec::new(acknowledged, DataType::Boolean)
                .description("Set to true to acknowledge the alarm")
                .writable(if writable {
                    Writable::Yes
                } else {
                    Writable::No
                }),
            Sample::good(MetricValue::Boolean(alarm.acknowledged), t),
        ),
    ]
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
mod tests {
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
