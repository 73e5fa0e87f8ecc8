//! What the Sparkplug host made of a message, as rows for the store (sans-IO).
//!
//! [`append`] turns a [`Received`] into [`PointRow`]s, [`SampleRow`]s and [`EventRow`]s
//! added to a [`Batch`]. Points are named by Sparkplug group, edge node, device (`""` for
//! the node's own metrics) and metric name: the same node id in two groups is two nodes.

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use sparkplug::metric::Quality as SpQuality;
use sparkplug::{HostEvent, HostSample, PointInfo, Received, SampleValue, Timestamp, Writable};

use crate::store::{Batch, EventRow, PointRow, Quality, SampleRow};

/// The severity an event gets when its message has none (OPC UA's "medium").
const DEFAULT_SEVERITY: i32 = 500;
/// The highest severity (OPC UA's scale ends at 1000).
const MAX_SEVERITY: u32 = 1000;

/// How many rows [`append`] added.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Added {
    /// Point definitions.
    pub points: usize,
    /// Samples.
    pub samples: usize,
    /// Events.
    pub events: usize,
}

/// Adds the points, samples and events of `received` to `batch`.
pub fn append(batch: &mut Batch, received: &Received) -> Added {
    batch.points.extend(received.points.iter().map(point_row));
    batch
        .samples
        .extend(received.samples.iter().map(sample_row));
    batch.events.extend(received.events.iter().map(event_row));
    Added {
        points: received.points.len(),
        samples: received.samples.len(),
        events: received.events.len(),
    }
}

/// A Sparkplug time as a system time.
pub fn system_time(t: Timestamp) -> SystemTime {
    UNIX_EPOCH + Duration::from_millis(t.as_millis())
}

/// A system time as a Sparkplug time (times before 1970 read as 1970).
pub fn sparkplug_time(t: SystemTime) -> Timestamp {
    let ms = t.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_millis());
    Timestamp::from_millis(u64::try_from(ms).unwrap_or(u64::MAX))
}

fn device_of(device: Option<&sparkplug::Id>) -> String {
    device.map_or_else(String::new, |d| d.as_str().to_owned())
}

fn point_row(info: &PointInfo) -> PointRow {
    let (writable, write_min, write_max) = match &info.writable {
        Writable::No => (false, None, None),
        Writable::Yes => (true, None, None),
        Writable::Within(range) => (true, Some(range.min()), Some(range.max())),
    };
    PointRow {
        group: info.point.group().as_str().to_owned(),
        node: info.point.node().as_str().to_owned(),
        device: device_of(info.point.device()),
        point: info.point.name.as_str().to_owned(),
        datatype: info.datatype.to_string(),
        unit: info.unit.clone(),
        description: info.description.clone(),
        writable,
        write_min,
        write_max,
    }
}

/// A sample as a row. A number that is not finite (NaN, ±Inf: a failed conversion, a
/// division by zero in the source) is no reading: it is stored without a value and `bad`,
/// as JSON, Grafana and the gateway's API have no good NaN.
fn sample_row(sample: &HostSample) -> SampleRow {
    let mut quality = quality(sample.quality);
    let (value, text) = match &sample.value {
        SampleValue::Number(n) if n.is_finite() => (Some(*n), None),
        SampleValue::Number(_) => {
            quality = Quality::Bad;
            (None, None)
        }
        SampleValue::Text(t) => (None, Some(t.clone())),
        SampleValue::Null => (None, None),
    };
    SampleRow {
        group: sample.point.group().as_str().to_owned(),
        node: sample.point.node().as_str().to_owned(),
        device: device_of(sample.point.device()),
        point: sample.point.name.as_str().to_owned(),
        t: system_time(sample.t),
        value,
        text,
        quality,
    }
}

fn quality(q: SpQuality) -> Quality {
    match q {
        SpQuality::Good => Quality::Good,
        SpQuality::Stale => Quality::Stale,
        SpQuality::Bad => Quality::Bad,
    }
}

fn event_row(event: &HostEvent) -> EventRow {
    EventRow {
        group: event.group.as_str().to_owned(),
        node: event.node.as_str().to_owned(),
        device: event.device.clone(),
        point: event.point.clone(),
        line: event.line.clone(),
        t: system_time(event.t),
        kind: event.kind.clone().unwrap_or_else(|| "event".to_owned()),
        // OPC UA's scale is 1–1000: a larger number is as serious as it gets.
        severity: event.severity.map_or(DEFAULT_SEVERITY, |s| {
            i32::try_from(s.clamp(1, MAX_SEVERITY)).unwrap_or(DEFAULT_SEVERITY)
        }),
        message: event.message.clone(),
        fields: event.fields.as_deref().and_then(checked_fields),
    }
}

/// The longest `fields` text stored; a longer one is left out (the words stay).
pub const MAX_FIELDS_BYTES: usize = 16 * 1024;

/// An event's `fields` property when it is a JSON object PostgreSQL's jsonb takes (no NUL
/// in any key or text, at most [`MAX_FIELDS_BYTES`]), in compact form; otherwise `None`:
/// the event is stored with its words and without the facts, never refused for them.
fn checked_fields(text: &str) -> Option<String> {
    fn no_nul(value: &serde_json::Value) -> bool {
        match value {
            serde_json::Value::String(s) => !s.contains('\0'),
            serde_json::Value::Array(items) => items.iter().all(no_nul),
            serde_json::Value::Object(map) => {
                map.iter().all(|(k, v)| !k.contains('\0') && no_nul(v))
            }
            _ => true,
        }
    }
    if text.len() > MAX_FIELDS_BYTES {
        return None;
    }
    let value: serde_json::Value = serde_json::from_str(text).ok()?;
    (value.is_object() && no_nul(&value)).then(|| value.to_string())
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use sparkplug::{DataType, Id, MetricName, PointKey, PointOwner, WriteRange};

    use super::*;

    fn key(device: Option<&str>, name: &str) -> Arc<PointKey> {
        Arc::new(PointKey {
            owner: Arc::new(PointOwner {
                group: Id::new("plant").unwrap(),
                node: Id::new("cellA").unwrap(),
                device: device.map(|d| Id::new(d).unwrap()),
            }),
            name: MetricName::new(name).unwrap(),
        })
    }

    #[test]
    fn a_birth_defines_its_points_with_unit_words_and_write_range() {
        let mut batch = Batch::default();
        let received = Received {
            points: vec![PointInfo {
                point: key(Some("jbc1"), "air_temperature_setpoint"),
                datatype: DataType::Double,
                unit: Some("°C".into()),
                description: Some("Air temperature set-point".into()),
                writable: Writable::Within(WriteRange::new(150.0, 450.0).unwrap()),
            }],
            ..Received::default()
        };
        let added = append(&mut batch, &received);
        assert_eq!(added.points, 1);
        let p = &batch.points[0];
        assert_eq!(
            (
                p.group.as_str(),
                p.node.as_str(),
                p.device.as_str(),
                p.point.as_str()
            ),
            ("plant", "cellA", "jbc1", "air_temperature_setpoint")
        );
        assert_eq!(p.datatype, "Double");
        assert_eq!(p.unit.as_deref(), Some("°C"));
        assert!(p.writable);
        assert_eq!((p.write_min, p.write_max), (Some(150.0), Some(450.0)));
    }

    #[test]
    fn samples_keep_their_own_time_value_and_quality_and_node_metrics_have_no_device() {
        let mut batch = Batch::default();
        let received = Received {
            samples: vec![
                HostSample {
                    point: key(Some("jbc1"), "air_temperature"),
                    t: Timestamp::from_millis(1_700_000_000_123),
                    value: SampleValue::Number(351.5),
                    quality: SpQuality::Good,
                    historical: true,
                },
                HostSample {
                    point: key(None, "history_rows"),
                    t: Timestamp::from_millis(1_700_000_000_200),
                    value: SampleValue::Null,
                    quality: SpQuality::Stale,
                    historical: false,
                },
                HostSample {
                    point: key(Some("pm1"), "program"),
                    t: Timestamp::from_millis(1_700_000_000_300),
                    value: SampleValue::Text("NPM-7".into()),
                    quality: SpQuality::Good,
                    historical: false,
                },
            ],
            ..Received::default()
        };
        assert_eq!(append(&mut batch, &received).samples, 3);
        let s = &batch.samples;
        assert_eq!(
            s[0].t,
            UNIX_EPOCH + Duration::from_millis(1_700_000_000_123)
        );
        assert_eq!((s[0].value, s[0].quality), (Some(351.5), Quality::Good));
        assert_eq!(s[1].device, "");
        assert_eq!((s[1].value, s[1].quality), (None, Quality::Stale));
        assert_eq!((s[2].value, s[2].text.as_deref()), (None, Some("NPM-7")));
    }

    #[test]
    fn an_events_fields_are_kept_only_as_a_json_object_postgresql_takes() {
        let kept = checked_fields(r#"{ "feeder": 7, "event": "parts_exhausted" }"#)
            .expect("an object is kept");
        assert!(!kept.contains(' '), "compact: {kept}");
        assert_eq!(
            serde_json::from_str::<serde_json::Value>(&kept).unwrap(),
            serde_json::json!({"event": "parts_exhausted", "feeder": 7})
        );
        for refused in [
            "[1, 2]",
            "\"words\"",
            "not json",
            r#"{"a": "\u0000"}"#,
            r#"{"\u0000": 1}"#,
            r#"{"deep": [{"x": "a\u0000b"}]}"#,
        ] {
            assert_eq!(checked_fields(refused), None, "{refused}");
        }
        let large = format!(r#"{{"x":"{}"}}"#, "a".repeat(MAX_FIELDS_BYTES));
        assert_eq!(checked_fields(&large), None, "too large");
    }

    #[test]
    fn an_event_without_kind_or_severity_gets_words_that_say_so() {
        let mut batch = Batch::default();
        let received = Received {
            events: vec![HostEvent {
                group: Id::new("plant").unwrap(),
                node: Id::new("cellA").unwrap(),
                device: Some("jbc1".into()),
                point: None,
                line: None,
                t: Timestamp::from_millis(1_700_000_000_000),
                kind: None,
                severity: None,
                message: "station restarted".into(),
                fields: None,
                historical: false,
            }],
            ..Received::default()
        };
        append(&mut batch, &received);
        let e = &batch.events[0];
        assert_eq!((e.kind.as_str(), e.severity), ("event", DEFAULT_SEVERITY));
        assert_eq!(e.device.as_deref(), Some("jbc1"));
        assert_eq!(e.group, "plant");
    }

    #[test]
    fn a_severity_beyond_the_scale_is_the_highest_not_the_default() {
        let event = |severity| HostEvent {
            group: Id::new("plant").unwrap(),
            node: Id::new("cellA").unwrap(),
            device: None,
            point: None,
            line: None,
            t: Timestamp::from_millis(1_700_000_000_000),
            kind: Some("alarm".into()),
            severity: Some(severity),
            message: "over".into(),
            fields: None,
            historical: false,
        };
        let mut batch = Batch::default();
        let received = Received {
            events: vec![event(4_000_000_000), event(0), event(700)],
            ..Received::default()
        };
        append(&mut batch, &received);
        let severities: Vec<i32> = batch.events.iter().map(|e| e.severity).collect();
        assert_eq!(severities, [1000, 1, 700]);
    }

    #[test]
    fn a_number_that_is_not_finite_is_stored_bad_without_a_value() {
        let mut batch = Batch::default();
        let sample = |value: f64| HostSample {
            point: key(Some("meter1"), "power"),
            t: Timestamp::from_millis(1_700_000_000_000),
            value: SampleValue::Number(value),
            quality: SpQuality::Good,
            historical: false,
        };
        let received = Received {
            samples: vec![sample(f64::NAN), sample(f64::INFINITY), sample(2.5)],
            ..Received::default()
        };
        append(&mut batch, &received);
        let rows: Vec<(Option<f64>, Quality)> =
            batch.samples.iter().map(|s| (s.value, s.quality)).collect();
        assert_eq!(
            rows,
            [
                (None, Quality::Bad),
                (None, Quality::Bad),
                (Some(2.5), Quality::Good)
            ]
        );
    }

    #[test]
    fn times_convert_both_ways_to_the_millisecond() {
        let t = Timestamp::from_millis(1_700_000_000_777);
        assert_eq!(sparkplug_time(system_time(t)), t);
        assert_eq!(
            sparkplug_time(UNIX_EPOCH - Duration::from_secs(5)).as_millis(),
            0
        );
    }
}
