//! Describing received messages in words and JSON, with payloads built by the crate's own
//! edge node: births with units and write ranges, data by alias resolved against the
//! births seen, quality, history, STATE, other topics and payloads that are not Sparkplug.

mod common;

use common::{T0, air_temp, at, connected, ddata, event_metric, id, set_point, status};
use prost::Message as _;
use sparkplug::describe::{RawPayload, Value, iso_time};
use sparkplug::proto::{Metric, Payload};
use sparkplug::{
    DataType, Delivery, Describer, Description, EdgeNode, HostState, MetricSpec, MetricValue,
    Publish, Quality, Sample,
};

/// A station with a temperature in °C, a writable set point 100–450 °C and a status text.
fn station() -> Vec<(MetricSpec, Sample)> {
    vec![
        air_temp(MetricValue::Double(25.5), "Air temperature"),
        set_point(),
        status(),
    ]
}

/// A connected, born node `cell/gw1` with device `jbc` born; the births it sent.
fn running() -> (EdgeNode, Publish, Publish) {
    let mut node = connected();
    let nbirth = node.node_birth(&[], T0).unwrap();
    let dbirth = node.device_birth(&id("jbc"), &station(), T0).unwrap();
    (node, nbirth, dbirth)
}

fn describe(describer: &mut Describer, p: &Publish) -> Description {
    describer.describe(&p.topic.to_string(), &p.payload)
}

fn sparkplug(d: Description) -> sparkplug::describe::SparkplugMessage {
    match d {
        Description::Sparkplug(m) => m,
        other => panic!("not described as Sparkplug: {other:?}"),
    }
}

#[test]
fn a_device_birth_is_described_with_names_aliases_types_units_and_write_ranges() {
    let (_, _, dbirth) = running();
    let m = sparkplug(describe(&mut Describer::new(), &dbirth));
    assert_eq!(m.message_type, "DBIRTH");
    assert_eq!((m.group.as_str(), m.edge_node.as_str()), ("cell", "gw1"));
    assert_eq!(m.device.as_deref(), Some("jbc"));
    assert_eq!(m.seq, Some(1));
    assert_eq!(m.timestamp, Some(T0.as_millis()));
    let air = m.metric("air_temp").expect("air_temp in the birth");
    assert_eq!(air.datatype, Some(DataType::Double.code()));
    assert_eq!(air.value, Value::Value(MetricValue::Double(25.5)));
    assert_eq!(air.unit(), Some("°C"));
    assert!(!air.resolved, "a birth names its metrics itself");

    let text = Description::Sparkplug(m.clone()).to_text();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(
        lines[0],
        "spBv1.0/cell/DBIRTH/gw1/jbc seq=1 timestamp=2025-11-24T16:00:00.000Z (3 metrics)"
    );
    let set_point = m.metric("set_point").unwrap().alias.unwrap();
    assert_eq!(
        lines[2],
        format!(
            "  set_point (alias {set_point}): Int32 300 at 2025-11-24T16:00:00.000Z unit °C writable 100..450"
        )
    );
    assert!(
        lines[1].contains(": Double 25.5 ") && lines[1].ends_with("read-only \"Air temperature\""),
        "{}",
        lines[1]
    );
    assert!(lines[3].contains(": String \"idle\" "), "{}", lines[3]);
}

#[test]
fn data_by_alias_is_resolved_to_the_names_of_the_birth_seen_before() {
    let (mut node, nbirth, dbirth) = running();
    let ddata = ddata(&mut node, "jbc", 312.5, at(500));
    let mut describer = Describer::new();
    describe(&mut describer, &nbirth);
    describe(&mut describer, &dbirth);
    let m = sparkplug(describe(&mut describer, &ddata));
    let air = &m.metrics[0];
    assert_eq!(air.name.as_deref(), Some("air_temp"));
    assert!(air.resolved);
    assert_eq!(air.datatype, Some(DataType::Double.code()));
    assert_eq!(air.value, Value::Value(MetricValue::Double(312.5)));
    let alias = air.alias.unwrap();
    let text = Description::Sparkplug(m).to_text();
    assert_eq!(
        text.lines().nth(1),
        Some(
            format!("  air_temp (alias {alias}): Double 312.5 at 2025-11-24T16:00:00.500Z")
                .as_str()
        ),
        "{text}"
    );
}

#[test]
fn data_without_a_birth_seen_shows_the_bare_alias_and_the_raw_value() {
    let (mut node, _, _) = running();
    let ddata = ddata(&mut node, "jbc", 312.5, at(500));
    let m = sparkplug(describe(&mut Describer::new(), &ddata));
    let metric = &m.metrics[0];
    assert_eq!(metric.name, None);
    assert_eq!(
        metric.value,
        Value::Raw {
            field: "double_value",
            value: serde_json::json!(312.5)
        }
    );
    let alias = metric.alias.unwrap();
    let json = Description::Sparkplug(m.clone()).to_json();
    assert_eq!(json["metrics"][0]["name"], serde_json::Value::Null);
    assert_eq!(json["metrics"][0]["datatype"], serde_json::Value::Null);
    assert_eq!(json["metrics"][0]["value"], 312.5);
    let text = Description::Sparkplug(m).to_text();
    assert_eq!(
        text.lines().nth(1),
        Some(format!("  alias {alias}: double_value 312.5 at 2025-11-24T16:00:00.500Z").as_str()),
        "{text}"
    );
}

#[test]
fn a_new_node_birth_forgets_the_aliases_of_the_devices_born_before_it() {
    let (mut node, nbirth, dbirth) = running();
    let mut describer = Describer::new();
    describe(&mut describer, &nbirth);
    describe(&mut describer, &dbirth);
    describe(&mut describer, &nbirth);
    let ddata = ddata(&mut node, "jbc", 1.0, at(1));
    let m = sparkplug(describe(&mut describer, &ddata));
    assert_eq!(m.metrics[0].name, None);
}

#[test]
fn stale_and_historical_readings_show_null_their_quality_and_history() {
    let (mut node, _, dbirth) = running();
    let mut describer = Describer::new();
    describe(&mut describer, &dbirth);
    let stale = node
        .device_data(
            &id("jbc"),
            &[("air_temp", Sample::stale(at(100)))],
            at(100),
            Delivery::Live,
        )
        .unwrap()
        .unwrap();
    let m = sparkplug(describe(&mut describer, &stale));
    assert_eq!(m.metrics[0].value, Value::Null);
    assert_eq!(m.metrics[0].quality, Some(Quality::Stale));
    let text = Description::Sparkplug(m.clone()).to_text();
    assert!(text.contains(": Double null stale at "), "{text}");
    let json = Description::Sparkplug(m).to_json();
    assert_eq!(json["metrics"][0]["value"], serde_json::Value::Null);
    assert_eq!(json["metrics"][0]["quality"], "stale");

    let history = node
        .device_data(
            &id("jbc"),
            &[("air_temp", Sample::good(MetricValue::Double(200.0), at(50)))],
            at(200),
            Delivery::Historical,
        )
        .unwrap()
        .unwrap();
    let m = sparkplug(describe(&mut describer, &history));
    assert!(m.metrics[0].historical);
    let text = Description::Sparkplug(m.clone()).to_text();
    assert!(
        text.contains(": Double 200.0 historical at 2025-11-24T16:00:00.050Z"),
        "{text}"
    );
    assert_eq!(
        Description::Sparkplug(m).to_json()["metrics"][0]["historical"],
        true
    );
}

#[test]
fn json_has_the_topic_ids_seq_and_every_metric_with_its_properties() {
    let (mut node, _, dbirth) = running();
    let mut describer = Describer::new();
    let json = describe(&mut describer, &dbirth).to_json();
    assert_eq!(json["topic"], "spBv1.0/cell/DBIRTH/gw1/jbc");
    assert_eq!(json["kind"], "DBIRTH");
    assert_eq!(json["group"], "cell");
    assert_eq!(json["edge_node"], "gw1");
    assert_eq!(json["device"], "jbc");
    assert_eq!(json["seq"], 1);
    assert_eq!(json["timestamp"], T0.as_millis());
    let set_point = &json["metrics"][1];
    assert_eq!(set_point["name"], "set_point");
    assert_eq!(set_point["datatype"], "Int32");
    assert_eq!(set_point["value"], 300);
    assert_eq!(set_point["quality"], serde_json::Value::Null);
    assert_eq!(set_point["historical"], false);
    assert_eq!(set_point["timestamp"], T0.as_millis());
    assert_eq!(set_point["properties"]["engUnit"], "°C");
    assert_eq!(set_point["properties"]["writable"], true);
    assert_eq!(set_point["properties"]["writeMin"], 100.0);
    assert_eq!(set_point["properties"]["writeMax"], 450.0);

    let ddata = node
        .device_data(
            &id("jbc"),
            &[(
                "status",
                Sample::good(MetricValue::String("heating".into()), at(1)),
            )],
            at(1),
            Delivery::Live,
        )
        .unwrap()
        .unwrap();
    let json = describe(&mut describer, &ddata).to_json();
    let status = &json["metrics"][0];
    assert_eq!(status["name"], "status");
    assert_eq!(status["alias"], set_point["alias"].as_u64().unwrap() + 1);
    assert_eq!(status["datatype"], "String");
    assert_eq!(status["value"], "heating");
}

#[test]
fn the_node_birth_and_death_carry_bd_seq_and_the_death_has_no_seq() {
    let (node, nbirth, _) = running();
    let mut describer = Describer::new();
    let m = sparkplug(describe(&mut describer, &nbirth));
    assert_eq!(m.message_type, "NBIRTH");
    assert_eq!(m.device, None);
    assert_eq!(m.seq, Some(0));
    assert_eq!(
        m.metric("bdSeq").unwrap().value,
        Value::Value(MetricValue::Int64(7))
    );
    let rebirth = m.metric("Node Control/Rebirth").unwrap();
    assert!(
        rebirth.to_text(true).ends_with("writable"),
        "{}",
        rebirth.to_text(true)
    );
    // The Will of the next connection.
    let m = sparkplug(describe(&mut describer, &node.will()));
    assert_eq!(m.message_type, "NDEATH");
    assert_eq!(m.seq, None);
    let text = Description::Sparkplug(m).to_text();
    assert_eq!(text, "spBv1.0/cell/NDEATH/gw1 (1 metric)\n  bdSeq: Int64 8");
}

#[test]
fn a_payload_that_is_not_protobuf_is_described_as_undecodable_naming_topic_and_error() {
    let mut describer = Describer::new();
    let d = describer.describe("spBv1.0/cell/DDATA/gw1/jbc", b"\xff\xff\xff not protobuf");
    let Description::Undecodable { topic, error } = &d else {
        panic!("{d:?}");
    };
    assert_eq!(topic, "spBv1.0/cell/DDATA/gw1/jbc");
    assert!(error.contains("not a Sparkplug B payload"), "{error}");
    assert!(
        d.to_text()
            .starts_with("spBv1.0/cell/DDATA/gw1/jbc: cannot decode: not a Sparkplug B payload"),
        "{}",
        d.to_text()
    );
    assert_eq!(d.to_json()["topic"], "spBv1.0/cell/DDATA/gw1/jbc");
    assert!(d.to_json()["error"].is_string());

    let bad_topic = describer.describe("spBv1.0/cell/XDATA/gw1", b"");
    assert!(
        matches!(&bad_topic, Description::Undecodable { error, .. } if error.contains("XDATA")),
        "{bad_topic:?}"
    );
}

#[test]
fn a_value_in_the_wrong_field_is_unreadable_with_the_reason_and_the_rest_still_shows() {
    let payload = Payload {
        seq: Some(3),
        metrics: vec![
            Metric {
                name: Some("odd".into()),
                datatype: Some(DataType::Double.code()),
                value: Some(sparkplug::proto::metric::Value::StringValue("x".into())),
                ..Metric::default()
            },
            Metric {
                name: Some("fine".into()),
                datatype: Some(DataType::Boolean.code()),
                value: Some(sparkplug::proto::metric::Value::BooleanValue(true)),
                ..Metric::default()
            },
        ],
        ..Payload::default()
    };
    let d = Describer::new().describe("spBv1.0/cell/NDATA/gw1", &payload.encode_to_vec());
    let text = d.to_text();
    assert!(
        text.contains("odd: Double unreadable (a Double metric carries its value in double_value, not in string_value)"),
        "{text}"
    );
    assert!(text.contains("fine: Boolean true"), "{text}");
    let json = d.to_json();
    assert_eq!(json["metrics"][0]["value"], serde_json::Value::Null);
    assert!(json["metrics"][0]["value_error"].is_string());
}

#[test]
fn state_is_shown_as_its_json_and_other_topics_as_text_or_hex() {
    let mut describer = Describer::new();
    let state = HostState::new(true, T0).publish(id("scada"));
    let d = describe(&mut describer, &state);
    assert!(matches!(d, Description::State { .. }));
    assert_eq!(
        d.to_text(),
        format!(
            "spBv1.0/STATE/scada {{\"online\":true,\"timestamp\":{}}}",
            T0.as_millis()
        )
    );
    assert_eq!(d.to_json()["payload"]["online"], true);
    assert_eq!(d.to_json()["kind"], "STATE");

    let text = describer.describe("plant/hall1/temp", b"21.5");
    assert_eq!(text.to_text(), "plant/hall1/temp 21.5");
    assert_eq!(text.to_json()["payload"], "21.5");
    assert_eq!(text.to_json()["encoding"], "text");

    let bytes = describer.describe("plant/raw", &[0x00, 0xff, 0x10]);
    assert!(matches!(
        &bytes,
        Description::Other {
            payload: RawPayload::Bytes(_),
            ..
        }
    ));
    assert_eq!(bytes.to_text(), "plant/raw 00ff10");
    assert_eq!(bytes.to_json()["encoding"], "hex");
}

#[test]
fn iso_time_is_utc_with_milliseconds() {
    assert_eq!(iso_time(0), "1970-01-01T00:00:00.000Z");
    assert_eq!(iso_time(951_782_400_123), "2000-02-29T00:00:00.123Z");
    assert_eq!(
        iso_time(T0.as_millis() + 59_999),
        "2025-11-24T16:00:59.999Z"
    );
    assert_eq!(iso_time(4_102_444_799_000), "2099-12-31T23:59:59.000Z");
}

#[test]
fn an_event_shows_its_message_and_properties_in_words() {
    let mut node = connected();
    let nbirth = node.node_birth(&[event_metric()], T0).unwrap();
    let event = sparkplug::NodeEvent {
        t: at(250),
        kind: "alarm_raised".into(),
        severity: 700,
        message: "jbc: tool error".into(),
        line: None,
        device: Some("jbc".into()),
        point: Some("error".into()),
        fields: None,
    };
    let ndata = node.node_event(&event, at(300)).unwrap();
    let mut describer = Describer::new();
    describe(&mut describer, &nbirth);
    let text = describe(&mut describer, &ndata).to_text();
    let line = text.lines().nth(1).unwrap();
    assert!(
        line.starts_with("  Event (alias ")
            && line.ends_with(
                ": String \"jbc: tool error\" at 2025-11-24T16:00:00.250Z \
                 kind=\"alarm_raised\" severity=700 device=\"jbc\" point=\"error\""
            ),
        "{text}"
    );
}
