//! The edge node's state machine, driven as the gateway will drive it: Will, connect,
//! births, data, deaths and commands, each message decoded back from its bytes.

mod common;

use common::{T0, air_temp, at, connected, connected_with, event_metric, heater_on, id, name};
use prost::Message as _;
use sparkplug::node::{BD_SEQ, HOST_OFFLINE, REBIRTH};
use sparkplug::proto::{Metric, Payload, metric::Value};
use sparkplug::{
    BdSeq, Command, CommandError, DataType, Delivery, EdgeNode, MetricSpec, MetricValue, NodeError,
    NodeEvent, Publish, Qos, Quality, Sample, ValueError,
};

fn decode(publish: &Publish) -> Payload {
    Payload::decode(&publish.payload[..]).expect("the node encodes valid payloads")
}

fn by_name<'p>(payload: &'p Payload, wanted: &str) -> &'p Metric {
    payload
        .metrics
        .iter()
        .find(|m| m.name.as_deref() == Some(wanted))
        .unwrap_or_else(|| panic!("no metric {wanted}"))
}

/// A station with a read-only temperature and a writable set point, 100–450 °C.
fn station() -> Vec<(MetricSpec, Sample)> {
    vec![
        air_temp(MetricValue::Int32(25), "air temperature at the nozzle"),
        common::set_point(),
        heater_on(false),
    ]
}

/// A node connected with bdSeq 7, born, with device `jbc` born.
fn running() -> EdgeNode {
    let mut node = connected();
    node.node_birth(&[], T0).unwrap();
    node.device_birth(&id("jbc"), &station(), T0).unwrap();
    node
}

/// The live DDATA `node` sends for device `jbc`'s `air_temp` reading `sample` (at its
/// own time), decoded.
fn air_temp_data(node: &mut EdgeNode, sample: Sample) -> Payload {
    let t = sample.timestamp;
    let publish = node
        .device_data(&id("jbc"), &[("air_temp", sample)], t, Delivery::Live)
        .unwrap()
        .expect("a changed value is sent");
    decode(&publish)
}

fn alias_of(birth: &Payload, wanted: &str) -> u64 {
    by_name(birth, wanted).alias.expect("births give aliases")
}

fn dcmd(metrics: Vec<Metric>) -> Vec<u8> {
    Payload {
        timestamp: Some(T0.as_millis()),
        metrics,
        ..Payload::default()
    }
    .encode_to_vec()
}

#[test]
fn the_first_nbirth_after_connect_has_seq_zero() {
    let mut node = connected();
    let birth = node.node_birth(&[], T0).unwrap();
    assert_eq!(birth.topic.to_string(), "spBv1.0/cell/NBIRTH/gw1");
    assert_eq!((birth.qos, birth.retain), (Qos::AtMostOnce, false));
    let payload = decode(&birth);
    assert_eq!(payload.seq, Some(0));
    assert_eq!(payload.timestamp, Some(T0.as_millis()));
}

#[test]
fn bd_seq_in_the_ndeath_equals_the_nbirths_after_connect() {
    let mut node = EdgeNode::new(id("cell"), id("gw1"), BdSeq::new(7));
    assert_eq!(
        node.next_bd_seq(),
        BdSeq::new(8),
        "persisted before connecting"
    );
    let will = node.will();
    assert_eq!((will.qos, will.retain), (Qos::AtLeastOnce, false));
    let death = decode(&will);
    assert_eq!(death.seq, None, "NDEATH carries no seq");
    node.on_connect();
    let birth = decode(&node.node_birth(&[], T0).unwrap());
    let bd = |p: &Payload| by_name(p, BD_SEQ).value.clone();
    assert_eq!(bd(&death), Some(Value::LongValue(7)));
    assert_eq!(bd(&birth), bd(&death));
    assert_eq!(
        by_name(&birth, BD_SEQ).datatype,
        Some(DataType::Int64.code())
    );

    // The next connection's Will and NBIRTH carry the next bdSeq.
    node.on_disconnect();
    let death = decode(&node.will());
    node.on_connect();
    let birth = decode(&node.node_birth(&[], T0).unwrap());
    assert_eq!(bd(&death), Some(Value::LongValue(8)));
    assert_eq!(bd(&birth), bd(&death));
    assert_eq!(birth.seq, Some(0), "seq starts again after each connect");
}

#[test]
fn a_death_for_an_offline_host_carries_the_sessions_bd_seq_and_says_why() {
    let mut node = EdgeNode::new(id("cell"), id("gw1"), BdSeq::new(7));
    assert!(
        node.host_offline_death(T0).is_none(),
        "no session before the connection"
    );
    node.on_connect();
    let death = node.host_offline_death(at(5)).expect("connected");
    assert_eq!(death.topic.to_string(), "spBv1.0/cell/NDEATH/gw1");
    assert_eq!((death.qos, death.retain), (Qos::AtLeastOnce, false));
    let payload = decode(&death);
    assert_eq!(
        by_name(&payload, BD_SEQ).value,
        Some(Value::LongValue(7)),
        "the session's bdSeq, not the next Will's"
    );
    assert_eq!(
        by_name(&payload, HOST_OFFLINE).value,
        Some(Value::BooleanValue(true))
    );
    assert_eq!(payload.timestamp, Some(at(5).as_millis()));
    assert_eq!(payload.seq, None, "NDEATH carries no seq");
}

#[test]
fn bd_seq_wraps_from_255_to_0() {
    let mut node = EdgeNode::new(id("cell"), id("gw1"), BdSeq::new(255));
    assert_eq!(node.next_bd_seq(), BdSeq::new(0));
    node.on_connect();
    assert_eq!(node.bd_seq(), BdSeq::new(0));
}

#[test]
fn the_nbirth_has_node_control_rebirth_false_and_writable() {
    let mut node = connected_with(0);
    let birth = decode(&node.node_birth(&[], T0).unwrap());
    let rebirth = by_name(&birth, REBIRTH);
    assert_eq!(rebirth.datatype, Some(DataType::Boolean.code()));
    assert_eq!(rebirth.value, Some(Value::BooleanValue(false)));
    assert!(rebirth.alias.is_some());
}

#[test]
fn births_before_connect_are_refused() {
    let mut node = EdgeNode::new(id("cell"), id("gw1"), BdSeq::new(0));
    assert_eq!(node.node_birth(&[], T0), Err(NodeError::NotConnected));
    node.on_connect();
    assert_eq!(
        node.device_birth(&id("jbc"), &station(), T0),
        Err(NodeError::NodeNotBorn)
    );
}

#[test]
fn seq_counts_every_message_of_the_node_and_wraps_from_255_to_0() {
    let mut node = running(); // NBIRTH 0, DBIRTH 1
    let jbc = id("jbc");
    let mut seqs = vec![];
    for i in 0..300 {
        let value = MetricValue::Int32(26 + i);
        let data = air_temp_data(&mut node, Sample::good(value, at(1)));
        seqs.push(data.seq.unwrap());
    }
    assert_eq!(seqs[0], 2);
    assert_eq!(seqs[253], 255);
    assert_eq!(seqs[254], 0);
    assert_eq!(seqs[255], 1);
    let death = decode(&node.device_death(&jbc, at(2)).unwrap());
    assert_eq!(death.seq, Some((302 % 256) as u64));
}

#[test]
fn a_rebirth_starts_seq_again_at_zero() {
    let mut node = running();
    let birth = decode(&node.node_birth(&[], at(5)).unwrap());
    assert_eq!(birth.seq, Some(0));
    let dbirth = decode(&node.device_birth(&id("jbc"), &station(), at(5)).unwrap());
    assert_eq!(dbirth.seq, Some(1));
}

#[test]
fn a_dbirth_describes_every_metric_with_unit_description_and_write_range() {
    let mut node = connected_with(0);
    node.node_birth(&[], T0).unwrap();
    let birth = node.device_birth(&id("jbc"), &station(), T0).unwrap();
    assert_eq!(birth.topic.to_string(), "spBv1.0/cell/DBIRTH/gw1/jbc");
    let payload = decode(&birth);
    assert_eq!(payload.metrics.len(), 3);
    let sp = by_name(&payload, "set_point");
    assert_eq!(sp.datatype, Some(DataType::Int32.code()));
    assert_eq!(sp.value, Some(Value::IntValue(300)));
    assert_eq!(sp.timestamp, Some(T0.as_millis()));
    let props = sp.properties.as_ref().unwrap();
    assert_eq!(props.keys, ["engUnit", "writable", "writeMin", "writeMax"]);
    let air = by_name(&payload, "air_temp").properties.as_ref().unwrap();
    assert_eq!(air.keys, ["engUnit", "Documentation", "writable"]);
}

#[test]
fn ddata_uses_aliases_only_and_only_changed_metrics() {
    let mut node = connected_with(0);
    node.node_birth(&[], T0).unwrap();
    let dbirth = decode(&node.device_birth(&id("jbc"), &station(), T0).unwrap());
    let changes = [
        ("air_temp", Sample::good(MetricValue::Int32(180), at(1000))),
        ("set_point", Sample::good(MetricValue::Int32(300), at(1000))), // unchanged
        (
            "heater_on",
            Sample::good(MetricValue::Boolean(true), at(1000)),
        ),
    ];
    let publish = node
        .device_data(&id("jbc"), &changes, at(1000), Delivery::Live)
        .unwrap()
        .unwrap();
    assert_eq!(publish.topic.to_string(), "spBv1.0/cell/DDATA/gw1/jbc");
    let data = decode(&publish);
    let sent: Vec<(Option<u64>, Option<&str>, Option<u32>)> = data
        .metrics
        .iter()
        .map(|m| (m.alias, m.name.as_deref(), m.datatype))
        .collect();
    assert_eq!(
        sent,
        [
            (Some(alias_of(&dbirth, "air_temp")), None, None),
            (Some(alias_of(&dbirth, "heater_on")), None, None),
        ]
    );
    assert_eq!(data.metrics[0].value, Some(Value::IntValue(180)));
    assert_eq!(data.metrics[0].timestamp, Some(at(1000).as_millis()));
    assert_eq!(
        data.metrics[0].properties, None,
        "a good value needs no Quality"
    );

    // The same readings again: nothing to send, and no seq used.
    let seq = node.seq();
    assert_eq!(
        node.device_data(&id("jbc"), &changes, at(2000), Delivery::Live),
        Ok(None)
    );
    assert_eq!(node.seq(), seq);
}

#[test]
fn a_stale_reading_goes_as_null_with_quality_500_never_as_the_last_value() {
    let mut node = running();
    let data = air_temp_data(&mut node, Sample::stale(at(5)));
    let m = &data.metrics[0];
    assert_eq!(m.is_null, Some(true));
    assert_eq!(m.value, None);
    assert_eq!(Quality::of(m), Some(Quality::Stale));
    let props = m.properties.as_ref().unwrap();
    assert_eq!(props.values[0].r#type, Some(DataType::Int32.code()));
}

#[test]
fn a_bad_reading_goes_as_null_with_quality_0_and_recovery_says_192() {
    let mut node = running();
    let bad = air_temp_data(&mut node, Sample::bad(at(5)));
    let m = &bad.metrics[0];
    assert_eq!(
        (m.is_null, Quality::of(m)),
        (Some(true), Some(Quality::Bad))
    );

    let back = air_temp_data(&mut node, Sample::good(MetricValue::Int32(25), at(6)));
    let m = &back.metrics[0];
    assert_eq!(m.value, Some(Value::IntValue(25)));
    assert_eq!(m.is_null, None);
    assert_eq!(Quality::of(m), Some(Quality::Good));
}

#[test]
fn a_birth_of_a_stale_metric_says_null_and_stale() {
    let mut node = connected_with(0);
    node.node_birth(&[], T0).unwrap();
    let metrics = [(
        MetricSpec::new(name("v"), DataType::Float),
        Sample::stale(T0),
    )];
    let birth = decode(&node.device_birth(&id("cross"), &metrics, T0).unwrap());
    let m = by_name(&birth, "v");
    assert_eq!((m.is_null, m.value.clone()), (Some(true), None));
    assert_eq!(m.datatype, Some(DataType::Float.code()));
    assert_eq!(Quality::of(m), Some(Quality::Stale));
}

#[test]
fn historical_data_is_flagged_keeps_its_timestamp_and_is_not_the_last_reading() {
    let mut node = running();
    let jbc = id("jbc");
    let stored = [
        ("air_temp", Sample::good(MetricValue::Int32(25), at(100))), // same as last live
        ("air_temp", Sample::good(MetricValue::Int32(30), at(200))),
    ];
    let publish = node
        .device_data(&jbc, &stored, at(9000), Delivery::Historical)
        .unwrap()
        .unwrap();
    let data = decode(&publish);
    assert_eq!(data.timestamp, Some(at(9000).as_millis()));
    let flags: Vec<_> = data
        .metrics
        .iter()
        .map(|m| (m.is_historical, m.timestamp))
        .collect();
    assert_eq!(
        flags,
        [
            (Some(true), Some(at(100).as_millis())),
            (Some(true), Some(at(200).as_millis()))
        ]
    );
    // The last live reading is still 25: a live 25 is no change.
    let live = [("air_temp", Sample::good(MetricValue::Int32(25), at(9001)))];
    assert_eq!(
        node.device_data(&jbc, &live, at(9001), Delivery::Live),
        Ok(None)
    );
}

#[test]
fn aliases_are_unique_across_devices_and_stay_the_same_across_a_rebirth() {
    let mut node = running();
    let cross = [(
        MetricSpec::new(name("air_temp"), DataType::Int32),
        Sample::good(MetricValue::Int32(1), T0),
    )];
    let first = decode(&node.device_birth(&id("other"), &cross, T0).unwrap());
    node.node_birth(&[], at(1)).unwrap();
    let jbc_again = decode(&node.device_birth(&id("jbc"), &station(), at(1)).unwrap());
    let other_again = decode(&node.device_birth(&id("other"), &cross, at(1)).unwrap());
    assert_ne!(
        alias_of(&first, "air_temp"),
        alias_of(&jbc_again, "air_temp")
    );
    assert_eq!(
        alias_of(&first, "air_temp"),
        alias_of(&other_again, "air_temp")
    );
    assert!(jbc_again.metrics.iter().all(|m| m.alias != Some(0)));
}

#[test]
fn data_for_a_device_without_a_birth_is_refused() {
    let mut node = running();
    let change = [("air_temp", Sample::good(MetricValue::Int32(1), T0))];
    assert_eq!(
        node.device_data(&id("nobody"), &change, T0, Delivery::Live),
        Err(NodeError::DeviceNotBorn {
            device: id("nobody")
        })
    );
    node.device_death(&id("jbc"), T0).unwrap();
    assert_eq!(
        node.device_data(&id("jbc"), &change, T0, Delivery::Live),
        Err(NodeError::DeviceNotBorn { device: id("jbc") })
    );
}

#[test]
fn a_ddeath_has_a_seq_and_no_metrics() {
    let mut node = running();
    let death = node.device_death(&id("jbc"), at(3)).unwrap();
    assert_eq!(death.topic.to_string(), "spBv1.0/cell/DDEATH/gw1/jbc");
    let payload = decode(&death);
    assert_eq!((payload.seq, payload.metrics.len()), (Some(2), 0));
}

#[test]
fn a_value_of_the_wrong_type_is_refused_and_nothing_is_recorded() {
    let mut node = running();
    let changes = [
        ("air_temp", Sample::good(MetricValue::Int32(99), T0)),
        ("heater_on", Sample::good(MetricValue::Int32(1), T0)),
    ];
    assert_eq!(
        node.device_data(&id("jbc"), &changes, T0, Delivery::Live),
        Err(NodeError::DataTypeMismatch {
            metric: name("heater_on"),
            expected: DataType::Boolean,
            got: DataType::Int32
        })
    );
    // air_temp 99 was not recorded as sent.
    assert!(
        node.device_data(&id("jbc"), &changes[..1], T0, Delivery::Live)
            .unwrap()
            .is_some()
    );
}

#[test]
fn an_unknown_metric_in_data_is_refused_by_name() {
    let mut node = running();
    let change = [("nozzle", Sample::bad(T0))];
    assert_eq!(
        node.device_data(&id("jbc"), &change, T0, Delivery::Live),
        Err(NodeError::UnknownMetric {
            device: Some(id("jbc")),
            name: "nozzle".into()
        })
    );
}

#[test]
fn node_metrics_may_not_use_the_reserved_names() {
    let mut node = connected_with(0);
    let metrics = [(
        MetricSpec::new(name(BD_SEQ), DataType::Int64),
        Sample::good(MetricValue::Int64(0), T0),
    )];
    assert_eq!(
        node.node_birth(&metrics, T0),
        Err(NodeError::ReservedName { name: name(BD_SEQ) })
    );
}

#[test]
fn an_ncmd_setting_rebirth_true_asks_for_a_rebirth_by_name_or_alias() {
    let mut node = connected_with(0);
    let birth = decode(&node.node_birth(&[], T0).unwrap());
    let topic = "spBv1.0/cell/NCMD/gw1";
    let by_name = Metric {
        name: Some(REBIRTH.into()),
        datatype: Some(DataType::Boolean.code()),
        value: Some(Value::BooleanValue(true)),
        ..Metric::default()
    };
    let by_alias = Metric {
        alias: Some(alias_of(&birth, REBIRTH)),
        value: Some(Value::BooleanValue(true)),
        ..Metric::default()
    };
    let no = Metric {
        name: Some(REBIRTH.into()),
        value: Some(Value::BooleanValue(false)),
        ..Metric::default()
    };
    for (metric, commands) in [
        (by_name, vec![Command::Rebirth]),
        (by_alias, vec![Command::Rebirth]),
        (no, vec![]),
    ] {
        let payload = dcmd(vec![metric.clone()]);
        assert_eq!(
            node.handle_command(topic, &payload),
            Ok(commands),
            "{metric:?}"
        );
    }
}

#[test]
fn a_dcmd_by_alias_is_a_write_of_the_named_metric() {
    let mut node = connected_with(0);
    node.node_birth(&[], T0).unwrap();
    let birth = decode(&node.device_birth(&id("jbc"), &station(), T0).unwrap());
    let payload = dcmd(vec![Metric {
        alias: Some(alias_of(&birth, "set_point")),
        datatype: Some(DataType::Int32.code()),
        value: Some(Value::IntValue(350)),
        ..Metric::default()
    }]);
    assert_eq!(
        node.handle_command("spBv1.0/cell/DCMD/gw1/jbc", &payload),
        Ok(vec![Command::Write {
            device: Some(id("jbc")),
            metric: name("set_point"),
            value: MetricValue::Int32(350)
        }])
    );
}

#[test]
fn a_dcmd_by_name_is_a_write_too() {
    let node = running();
    let payload = dcmd(vec![Metric {
        name: Some("set_point".into()),
        value: Some(Value::IntValue(100)),
        ..Metric::default()
    }]);
    assert!(matches!(
        node.handle_command("spBv1.0/cell/DCMD/gw1/jbc", &payload)
            .as_deref(),
        Ok([Command::Write { .. }])
    ));
}

fn set_point(value: Value, datatype: Option<u32>) -> Vec<u8> {
    dcmd(vec![Metric {
        name: Some("set_point".into()),
        datatype,
        value: Some(value),
        ..Metric::default()
    }])
}

#[test]
fn dcmds_that_cannot_be_carried_out_are_refused_with_the_facts() {
    let node = running();
    let jbc = "spBv1.0/cell/DCMD/gw1/jbc";
    let sp = name("set_point");
    assert_eq!(
        node.handle_command(
            "spBv1.0/cell/DCMD/gw1/cross",
            &set_point(Value::IntValue(1), None)
        ),
        Err(CommandError::UnknownDevice {
            device: id("cross")
        })
    );
    let unknown_alias = dcmd(vec![Metric {
        alias: Some(999),
        value: Some(Value::IntValue(1)),
        ..Metric::default()
    }]);
    assert_eq!(
        node.handle_command(jbc, &unknown_alias),
        Err(CommandError::UnknownAlias {
            device: Some(id("jbc")),
            alias: 999
        })
    );
    assert_eq!(
        node.handle_command(
            jbc,
            &set_point(Value::IntValue(350), Some(DataType::Float.code()))
        ),
        Err(CommandError::DataTypeMismatch {
            metric: sp.clone(),
            expected: DataType::Int32,
            got: 9
        })
    );
    assert_eq!(
        node.handle_command(jbc, &set_point(Value::FloatValue(350.0), None)),
        Err(CommandError::Value {
            metric: sp.clone(),
            error: ValueError::WrongField {
                datatype: DataType::Int32,
                expected: "int_value",
                found: "float_value"
            }
        })
    );
    assert_eq!(
        node.handle_command(jbc, &set_point(Value::IntValue(500), None)),
        Err(CommandError::OutOfRange {
            metric: sp.clone(),
            value: 500.0,
            min: 100.0,
            max: 450.0
        })
    );
    let read_only = dcmd(vec![Metric {
        name: Some("air_temp".into()),
        value: Some(Value::IntValue(1)),
        ..Metric::default()
    }]);
    assert_eq!(
        node.handle_command(jbc, &read_only),
        Err(CommandError::NotWritable {
            metric: name("air_temp")
        })
    );
    let null = dcmd(vec![Metric {
        name: Some("set_point".into()),
        is_null: Some(true),
        ..Metric::default()
    }]);
    assert_eq!(
        node.handle_command(jbc, &null),
        Err(CommandError::NullValue { metric: sp })
    );
    let anonymous = dcmd(vec![Metric::default()]);
    assert_eq!(
        node.handle_command(jbc, &anonymous),
        Err(CommandError::NoMetricId { index: 0 })
    );
}

#[test]
fn one_bad_metric_refuses_the_whole_command() {
    let node = running();
    let payload = dcmd(vec![
        Metric {
            name: Some("set_point".into()),
            value: Some(Value::IntValue(200)),
            ..Metric::default()
        },
        Metric {
            name: Some("nozzle".into()),
            value: Some(Value::IntValue(1)),
            ..Metric::default()
        },
    ]);
    assert_eq!(
        node.handle_command("spBv1.0/cell/DCMD/gw1/jbc", &payload),
        Err(CommandError::UnknownMetric {
            device: Some(id("jbc")),
            name: "nozzle".into()
        })
    );
}

#[test]
fn commands_for_other_nodes_or_on_other_topics_are_refused() {
    let node = running();
    let payload = set_point(Value::IntValue(200), None);
    assert!(matches!(
        node.handle_command("spBv1.0/cell/DCMD/gw2/jbc", &payload),
        Err(CommandError::OtherNode { .. })
    ));
    assert!(matches!(
        node.handle_command("spBv1.0/other/DCMD/gw1/jbc", &payload),
        Err(CommandError::OtherNode { .. })
    ));
    assert_eq!(
        node.handle_command("spBv1.0/cell/DDATA/gw1/jbc", &payload),
        Err(CommandError::NotACommand {
            topic: "spBv1.0/cell/DDATA/gw1/jbc".into()
        })
    );
    assert!(matches!(
        node.handle_command("spBv1.0/cell/DCMD/gw1/a/b", &payload),
        Err(CommandError::Topic(_))
    ));
}

#[test]
fn a_command_of_garbage_bytes_is_an_error() {
    let node = running();
    assert!(matches!(
        node.handle_command("spBv1.0/cell/DCMD/gw1/jbc", &[0x12, 0xFF, 0x01]),
        Err(CommandError::Payload(_))
    ));
}

#[test]
fn an_ncmd_before_the_nbirth_is_refused() {
    let node = connected_with(0);
    assert_eq!(
        node.handle_command("spBv1.0/cell/NCMD/gw1", &[]),
        Err(CommandError::NodeNotBorn)
    );
}

#[test]
fn the_command_filters_cover_ncmd_and_every_dcmd() {
    let node = running();
    assert_eq!(
        node.command_filters(),
        ["spBv1.0/cell/NCMD/gw1", "spBv1.0/cell/DCMD/gw1/+"]
    );
}

#[test]
fn node_metrics_are_born_and_reported_like_device_metrics() {
    let mut node = connected_with(0);
    let uptime = [(
        MetricSpec::new(name("uptime_s"), DataType::UInt64),
        Sample::good(MetricValue::UInt64(1), T0),
    )];
    let birth = decode(&node.node_birth(&uptime, T0).unwrap());
    let change = [("uptime_s", Sample::good(MetricValue::UInt64(2), at(1000)))];
    let data = node
        .node_data(&change, at(1000), Delivery::Live)
        .unwrap()
        .unwrap();
    assert_eq!(data.topic.to_string(), "spBv1.0/cell/NDATA/gw1");
    let payload = decode(&data);
    assert_eq!(payload.metrics[0].alias, Some(alias_of(&birth, "uptime_s")));
    assert_eq!(payload.metrics[0].value, Some(Value::LongValue(2)));
    assert_eq!(payload.seq, Some(1));
}

proptest::proptest! {
    #[test]
    fn random_command_bytes_are_refused_or_read_never_a_panic(
        bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..128)
    ) {
        let node = running();
        let _ = node.handle_command("spBv1.0/cell/DCMD/gw1/jbc", &bytes);
        let _ = node.handle_command("spBv1.0/cell/NCMD/gw1", &bytes);
    }
}

fn device_down_event() -> NodeEvent {
    NodeEvent {
        t: at(250),
        kind: "device_down".into(),
        severity: 700,
        message: "jbc: no answer".into(),
        line: Some("line1".into()),
        device: Some("jbc".into()),
        point: None,
        fields: Some(r#"{"error_kind":"timeout","retry_s":2}"#.into()),
    }
}

#[test]
fn an_event_is_an_ndata_of_the_event_metric_by_alias_with_its_properties_and_time() {
    let mut node = connected_with(0);
    let birth = node.node_birth(&[event_metric()], T0).unwrap();
    let event_alias = alias_of(&decode(&birth), sparkplug::event::EVENT);
    assert_eq!(
        by_name(&decode(&birth), sparkplug::event::EVENT).datatype,
        Some(DataType::String.code())
    );

    let published = node.node_event(&device_down_event(), at(300)).unwrap();
    assert_eq!(published.topic.to_string(), "spBv1.0/cell/NDATA/gw1");
    let payload = decode(&published);
    assert_eq!(payload.seq, Some(1), "an event counts in seq");
    let [m] = &payload.metrics[..] else {
        panic!("one metric: {payload:?}")
    };
    assert_eq!((m.name.as_deref(), m.alias), (None, Some(event_alias)));
    assert_eq!(m.timestamp, Some(at(250).as_millis()), "the event's time");
    assert_eq!(m.value, Some(Value::StringValue("jbc: no answer".into())));
    let properties = m.properties.as_ref().unwrap();
    assert_eq!(
        properties.keys,
        ["kind", "severity", "line", "device", "fields"]
    );
    assert_eq!(
        properties.values[4].value,
        Some(sparkplug::proto::property_value::Value::StringValue(
            r#"{"error_kind":"timeout","retry_s":2}"#.into()
        )),
        "the facts as a JSON object"
    );
    assert_eq!(
        properties.values[1].r#type,
        Some(DataType::UInt32.code()),
        "severity is a UInt32"
    );

    // The same event again is published again: events are not changes.
    let again = decode(&node.node_event(&device_down_event(), at(301)).unwrap());
    assert_eq!(again.metrics.len(), 1);
}

#[test]
fn an_event_needs_the_event_metric_in_the_nbirth() {
    let mut node = connected_with(0);
    assert_eq!(
        node.node_event(&device_down_event(), T0),
        Err(NodeError::NodeNotBorn)
    );
    node.node_birth(&[], T0).unwrap();
    assert_eq!(
        node.node_event(&device_down_event(), T0),
        Err(NodeError::UnknownMetric {
            device: None,
            name: "Event".into()
        })
    );
}
