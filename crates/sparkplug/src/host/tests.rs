use super::*;
use crate::event::NodeEvent;
use crate::metric::{MetricSpec, Sample};
use crate::node::{BdSeq, Command, Delivery, EdgeNode, REBIRTH};
use common::{
    T0, air_temp, at, connected, connected_with, ddata, event_metric, heater_on, id, name,
    set_point, status,
};
use prost::Message as _;

#[path = "../../tests/common/mod.rs"]
mod common;

/// A station: a temperature in °C, a set point writable 100–450 °C, a heater switch
/// and a status text.
fn station() -> Vec<(MetricSpec, Sample)> {
    vec![
        air_temp(MetricValue::Double(25.5), "air temperature at the nozzle"),
        set_point(),
        heater_on(true),
        status(),
    ]
}

/// The node's own metrics: the event channel and a line count.
fn node_metrics() -> Vec<(MetricSpec, Sample)> {
    vec![
        event_metric(),
        (
            MetricSpec::new(name("Gateway/Lines"), DataType::Int64),
            Sample::good(MetricValue::Int64(3), T0),
        ),
    ]
}

fn feed(host: &mut Host, p: &Publish, now: Timestamp) -> Received {
    host.receive(&p.topic.to_string(), &p.payload, now)
}

fn alone() -> Host {
    Host::new(id("historian"), Some(id("cell")), Sharing::Alone)
}

/// Edge node `cell/gw1` (bdSeq 7), connected and born with devices `jbc1` and
/// `jbc2`; a host that has read the births.
fn born(host: &mut Host) -> EdgeNode {
    born_with_will(host).0
}

/// [`born`], and the Will the node registered for this session.
fn born_with_will(host: &mut Host) -> (EdgeNode, Publish) {
    let mut node = EdgeNode::new(id("cell"), id("gw1"), BdSeq::new(7));
    let will = node.will();
    node.on_connect();
    let nbirth = node.node_birth(&node_metrics(), T0).unwrap();
    assert!(feed(host, &nbirth, T0).problems.is_empty());
    for device in ["jbc1", "jbc2"] {
        let dbirth = node.device_birth(&id(device), &station(), T0).unwrap();
        assert!(feed(host, &dbirth, T0).problems.is_empty());
    }
    (node, will)
}

fn key(device: Option<&str>, point: &str) -> PointKey {
    PointKey {
        owner: Arc::new(PointOwner {
            group: id("cell"),
            node: id("gw1"),
            device: device.map(id),
        }),
        name: name(point),
    }
}

/// Whether `p` is an NCMD that a born edge node `cell/gw1` reads as a Rebirth.
fn is_rebirth_of_gw1(p: &Publish) -> bool {
    let mut node = connected_with(0);
    node.node_birth(&[], T0).unwrap();
    p.topic.to_string() == "spBv1.0/cell/NCMD/gw1"
        && !p.retain
        && p.qos == Qos::AtMostOnce
        && node.handle_command(&p.topic.to_string(), &p.payload) == Ok(vec![Command::Rebirth])
}

#[test]
fn births_define_points_with_units_and_ranges_and_ddata_by_alias_resolves_to_names() {
    let mut host = alone();
    let mut node = connected();
    let nbirth = node.node_birth(&node_metrics(), T0).unwrap();
    let got = feed(&mut host, &nbirth, at(5));
    let names: Vec<_> = got.points.iter().map(|p| p.point.name.as_str()).collect();
    assert_eq!(
        names,
        ["Gateway/Lines"],
        "bdSeq, Node Control and Event are no points"
    );
    assert_eq!(got.samples.len(), 1);
    assert_eq!(got.samples[0].value, SampleValue::Number(3.0));

    let dbirth = node.device_birth(&id("jbc1"), &station(), T0).unwrap();
    let got = feed(&mut host, &dbirth, at(5));
    assert_eq!(got.problems, []);
    let air = &got.points[0];
    assert_eq!(*air.point, key(Some("jbc1"), "air_temp"));
    assert_eq!(air.datatype, DataType::Double);
    assert_eq!(air.unit.as_deref(), Some("°C"));
    assert_eq!(
        air.description.as_deref(),
        Some("air temperature at the nozzle")
    );
    assert_eq!(air.writable, Writable::No);
    assert_eq!(
        got.points[1].writable,
        Writable::Within(WriteRange::new(100.0, 450.0).unwrap())
    );
    let values: Vec<_> = got.samples.iter().map(|s| s.value.clone()).collect();
    assert_eq!(
        values,
        [
            SampleValue::Number(25.5),
            SampleValue::Number(300.0),
            SampleValue::Number(1.0),
            SampleValue::Text("idle".into()),
        ],
        "births give current values; booleans and integers are numbers"
    );
    assert!(
        got.samples
            .iter()
            .all(|s| s.t == T0 && s.quality == Quality::Good)
    );

    let data = ddata(&mut node, "jbc1", 26.0, at(1_000));
    let got = feed(&mut host, &data, at(1_010));
    assert_eq!(got.problems, []);
    assert_eq!(got.commands, []);
    assert_eq!(got.samples.len(), 1);
    let s = &got.samples[0];
    assert_eq!(*s.point, key(Some("jbc1"), "air_temp"));
    assert_eq!(s.value, SampleValue::Number(26.0));
    assert_eq!(s.t, at(1_000), "the metric's own time");
    assert_eq!(s.quality, Quality::Good);
    assert!(!s.historical);
    assert!(
        Arc::ptr_eq(&s.point, &air.point),
        "samples share their point's key with the birth"
    );
    assert_eq!(host.stats().samples, 1 + 4 + 1);
}

#[test]
fn historical_ddata_keeps_its_timestamps_and_says_it_is_historical() {
    let mut host = alone();
    let mut node = born(&mut host);
    let changes = [
        ("air_temp", Sample::good(MetricValue::Double(30.0), at(100))),
        ("air_temp", Sample::good(MetricValue::Double(31.0), at(200))),
    ];
    let data = node
        .device_data(&id("jbc2"), &changes, at(60_000), Delivery::Historical)
        .unwrap()
        .unwrap();
    let got = feed(&mut host, &data, at(60_001));
    let samples: Vec<_> = got
        .samples
        .iter()
        .map(|s| {
            (
                s.point.device().cloned(),
                s.t,
                s.value.clone(),
                s.historical,
            )
        })
        .collect();
    assert_eq!(
        samples,
        [
            (Some(id("jbc2")), at(100), SampleValue::Number(30.0), true),
            (Some(id("jbc2")), at(200), SampleValue::Number(31.0), true),
        ]
    );
}

#[test]
fn stale_and_bad_readings_are_null_samples_with_their_quality_and_good_comes_back() {
    let mut host = alone();
    let mut node = born(&mut host);
    let mut send = |sample: Sample| {
        let data = node
            .device_data(&id("jbc1"), &[("status", sample)], at(1), Delivery::Live)
            .unwrap()
            .unwrap();
        let got = feed(&mut host, &data, at(2));
        let s = &got.samples[0];
        (s.value.clone(), s.quality)
    };
    assert_eq!(
        send(Sample::stale(at(1))),
        (SampleValue::Null, Quality::Stale)
    );
    assert_eq!(send(Sample::bad(at(1))), (SampleValue::Null, Quality::Bad));
    assert_eq!(
        send(Sample::good(MetricValue::String("run".into()), at(1))),
        (SampleValue::Text("run".into()), Quality::Good)
    );
}

#[test]
fn a_null_value_without_a_quality_is_bad_and_with_quality_good_is_still_bad() {
    let mut host = alone();
    let mut node = born(&mut host);
    let data = ddata(&mut node, "jbc1", 1.0, at(1));
    let mut payload = Payload::decode(&data.payload[..]).unwrap();
    let m = &mut payload.metrics[0];
    m.value = None;
    m.is_null = Some(true);
    let got = host.receive(&data.topic.to_string(), &payload.encode_to_vec(), at(2));
    assert_eq!(got.samples[0].quality, Quality::Bad);
    let m = &mut payload.metrics[0];
    m.properties = crate::metric::Properties::quality(Quality::Good).into_option();
    payload.seq = payload.seq.map(|s| (s + 1) % 256);
    let got = host.receive(&data.topic.to_string(), &payload.encode_to_vec(), at(3));
    assert_eq!(got.problems, []);
    assert_eq!(got.samples[0].value, SampleValue::Null);
    assert_eq!(got.samples[0].quality, Quality::Bad);
}

#[test]
fn a_seq_gap_asks_for_one_rebirth_and_not_again_within_five_seconds() {
    let mut host = alone();
    let mut node = born(&mut host);
    let _lost = ddata(&mut node, "jbc1", 40.0, at(1_000));
    let after = ddata(&mut node, "jbc2", 41.0, at(1_100));
    let got = feed(&mut host, &after, at(1_100));
    assert_eq!(
        got.problems[0].problem,
        Problem::SeqGap {
            expected: 3,
            got: 4
        },
        "NBIRTH 0, DBIRTHs 1 and 2, the lost DDATA 3"
    );
    assert!(
        got.problems[0]
            .to_string()
            .starts_with("spBv1.0/cell/DDATA/gw1/jbc2: seq 4"),
        "{}",
        got.problems[0]
    );
    assert_eq!(got.commands.len(), 1);
    assert!(is_rebirth_of_gw1(&got.commands[0]));
    assert_eq!(
        got.samples.len(),
        1,
        "the data of the message after the gap is kept"
    );

    // Another gap 4.9 s later: counted, no second request yet.
    let _lost = ddata(&mut node, "jbc1", 42.0, at(5_000));
    let got = feed(
        &mut host,
        &ddata(&mut node, "jbc1", 43.0, at(6_000)),
        at(6_000),
    );
    assert!(matches!(got.problems[0].problem, Problem::SeqGap { .. }));
    assert_eq!(got.commands, []);
    // In sequence again: nothing to ask.
    let got = feed(
        &mut host,
        &ddata(&mut node, "jbc1", 44.0, at(6_050)),
        at(6_050),
    );
    assert_eq!((got.problems.len(), got.commands.len()), (0, 0));
    // A gap 5 s after the request: asked again.
    let _lost = ddata(&mut node, "jbc1", 45.0, at(6_100));
    let got = feed(
        &mut host,
        &ddata(&mut node, "jbc1", 46.0, at(6_200)),
        at(6_200),
    );
    assert_eq!(got.commands.len(), 1);
    assert_eq!(host.stats().seq_gaps, 3);
    assert_eq!(host.stats().rebirths, 2);

    // The NBIRTH of the rebirth ends the hold-off: the next gap asks at once.
    let nbirth = node.node_birth(&node_metrics(), at(6_300)).unwrap();
    feed(&mut host, &nbirth, at(6_300));
    let _lost = node
        .device_birth(&id("jbc1"), &station(), at(6_300))
        .unwrap();
    let dbirth = node
        .device_birth(&id("jbc2"), &station(), at(6_300))
        .unwrap();
    let got = feed(&mut host, &dbirth, at(6_400));
    assert_eq!(got.commands.len(), 1);
}

#[test]
fn seq_wraps_from_255_to_0_without_a_gap() {
    let mut host = alone();
    let mut node = born(&mut host);
    for i in 0..300 {
        let t = at(i * 10);
        let got = feed(&mut host, &ddata(&mut node, "jbc1", i as f64, t), t);
        assert_eq!(got.problems, [], "message {i}");
    }
    assert_eq!(host.stats().seq_gaps, 0);
}

#[test]
fn data_before_a_birth_is_dropped_and_asks_for_a_rebirth() {
    let mut host = alone();
    let mut node = connected();
    node.node_birth(&node_metrics(), T0).unwrap();
    node.device_birth(&id("jbc1"), &station(), T0).unwrap();
    let got = feed(&mut host, &ddata(&mut node, "jbc1", 50.0, at(10)), at(10));
    assert_eq!(got.samples, []);
    assert_eq!(
        got.problems[0].problem,
        Problem::NodeNotBorn {
            message_type: "DDATA".into()
        }
    );
    assert_eq!(got.commands.len(), 1);
    assert!(is_rebirth_of_gw1(&got.commands[0]));
    assert_eq!(host.stats().dropped, 1);
    // More data within 5 s: dropped, no second request.
    let got = feed(&mut host, &ddata(&mut node, "jbc1", 51.0, at(20)), at(20));
    assert_eq!(got.commands, []);
    assert_eq!(host.stats().dropped, 2);
}

#[test]
fn data_of_a_device_never_born_and_an_unknown_alias_ask_for_a_rebirth() {
    let mut host = alone();
    let mut node = born(&mut host);
    let jbc3 = node.device_birth(&id("jbc3"), &station(), T0).unwrap();
    let _ = jbc3; // not delivered to the host
    let got = feed(&mut host, &ddata(&mut node, "jbc3", 1.0, at(10)), at(10));
    assert_eq!(
        got.problems.iter().map(|p| &p.problem).collect::<Vec<_>>(),
        [
            &Problem::SeqGap {
                expected: 3,
                got: 4
            },
            &Problem::DeviceNotBorn { device: id("jbc3") }
        ]
    );
    assert_eq!(got.commands.len(), 1, "one request per message");

    let mut host = alone();
    let mut node = born(&mut host);
    let data = ddata(&mut node, "jbc1", 60.0, at(10));
    let mut payload = Payload::decode(&data.payload[..]).unwrap();
    let mut unknown = payload.metrics[0].clone();
    unknown.alias = Some(999);
    payload.metrics.push(unknown);
    let got = host.receive(&data.topic.to_string(), &payload.encode_to_vec(), at(10));
    assert_eq!(got.samples.len(), 1, "the known metric is kept");
    assert_eq!(
        got.problems[0].problem,
        Problem::UnknownAlias {
            device: Some(id("jbc1")),
            alias: 999
        }
    );
    assert_eq!(
        got.problems[0].to_string(),
        "spBv1.0/cell/DDATA/gw1/jbc1: device jbc1 has no metric with alias 999 in its \
         birth: dropped"
    );
    assert_eq!(got.commands.len(), 1);
    assert_eq!(host.stats().dropped, 1);
}

#[test]
fn an_alias_a_birth_gives_twice_resolves_no_data_and_is_a_problem() {
    let mut host = alone();
    let mut node = born(&mut host);
    let dbirth = node.device_birth(&id("jbc9"), &station(), T0).unwrap();
    let mut payload = Payload::decode(&dbirth.payload[..]).unwrap();
    let shared = payload.metrics[0].alias.expect("births give aliases");
    payload.metrics[1].alias = Some(shared);
    let got = host.receive(&dbirth.topic.to_string(), &payload.encode_to_vec(), at(1));
    assert_eq!(
        got.problems.iter().map(|p| &p.problem).collect::<Vec<_>>(),
        [&Problem::DuplicateAlias { alias: shared }]
    );
    assert_eq!(
        got.points.len(),
        station().len(),
        "the points are still defined"
    );

    let data = ddata(&mut node, "jbc9", 60.0, at(10));
    let mut payload = Payload::decode(&data.payload[..]).unwrap();
    let mut by_alias = payload.metrics[0].clone();
    by_alias.name = None;
    by_alias.alias = Some(shared);
    let mut by_name = by_alias.clone();
    by_name.name = Some("air_temp".into());
    payload.metrics = vec![by_alias, by_name];
    let got = host.receive(&data.topic.to_string(), &payload.encode_to_vec(), at(10));
    assert_eq!(
        got.samples
            .iter()
            .map(|s| s.point.name.as_str())
            .collect::<Vec<_>>(),
        ["air_temp"],
        "only the metric that also has its name"
    );
    assert!(
        got.problems.iter().any(|p| p.problem
            == Problem::UnknownAlias {
                device: Some(id("jbc9")),
                alias: shared
            }),
        "{:?}",
        got.problems
    );
}

#[test]
fn ndeath_with_the_current_bd_seq_marks_every_point_of_the_node_and_its_devices_bad() {
    let mut host = alone();
    let (mut node, will) = born_with_will(&mut host);
    let got = feed(&mut host, &will, at(9_000));
    assert_eq!(got.problems, []);
    assert_eq!(
        got.samples.len(),
        1 + 4 + 4,
        "Gateway/Lines and both stations"
    );
    assert!(got.samples.iter().all(|s| s.t == at(9_000)
        && s.value == SampleValue::Null
        && s.quality == Quality::Bad
        && !s.historical));
    let mut points: Vec<_> = got.samples.iter().map(|s| (*s.point).clone()).collect();
    points.sort();
    assert!(points.contains(&key(None, "Gateway/Lines")));
    assert!(points.contains(&key(Some("jbc2"), "status")));

    // Dead: a second death changes nothing, and its data asks for a rebirth.
    let got = feed(&mut host, &will, at(9_001));
    assert_eq!(got, Received::default());
    let got = feed(
        &mut host,
        &ddata(&mut node, "jbc1", 1.0, at(9_002)),
        at(9_002),
    );
    assert_eq!(got.samples, []);
    assert_eq!(got.commands.len(), 1);
}

#[test]
fn a_stale_ndeath_of_an_older_session_is_ignored() {
    let mut host = alone();
    let mut node = EdgeNode::new(id("cell"), id("gw1"), BdSeq::new(7));
    let old_will = node.will();
    node.on_connect();
    feed(
        &mut host,
        &node.node_birth(&node_metrics(), T0).unwrap(),
        T0,
    );
    // Reconnected: session 8 is born before the broker gives up on session 7.
    let new_will = node.will();
    node.on_connect();
    feed(
        &mut host,
        &node.node_birth(&node_metrics(), at(10)).unwrap(),
        at(10),
    );
    feed(
        &mut host,
        &node.device_birth(&id("jbc1"), &station(), at(10)).unwrap(),
        at(10),
    );

    let got = feed(&mut host, &old_will, at(20));
    assert_eq!(got.samples, []);
    assert_eq!(
        got.problems[0].problem,
        Problem::StaleDeath {
            death: Some(7),
            birth: Some(8)
        }
    );
    assert_eq!(host.stats().stale_deaths, 1);
    // Still born: its data is recorded.
    let got = feed(&mut host, &ddata(&mut node, "jbc1", 70.0, at(30)), at(30));
    assert_eq!((got.samples.len(), got.commands.len()), (1, 0));
    // The current session's Will marks it dead.
    let got = feed(&mut host, &new_will, at(40));
    assert_eq!(got.samples.len(), 1 + 4);
}

#[test]
fn ddeath_marks_that_devices_points_bad_and_its_later_data_asks_for_a_rebirth() {
    let mut host = alone();
    let mut node = born(&mut host);
    let death = node.device_death(&id("jbc2"), at(500)).unwrap();
    let got = feed(&mut host, &death, at(510));
    assert_eq!(got.problems, []);
    assert_eq!(got.samples.len(), 4);
    assert!(
        got.samples
            .iter()
            .all(|s| s.point.device() == Some(&id("jbc2"))
                && s.t == at(500)
                && s.quality == Quality::Bad)
    );
    // jbc1 lives on.
    let got = feed(&mut host, &ddata(&mut node, "jbc1", 80.0, at(600)), at(600));
    assert_eq!((got.samples.len(), got.commands.len()), (1, 0));
    // Data of the dead device (a node that ignores its own DDEATH): rebirth.
    let mut node2 = connected_with(0);
    node2.node_birth(&node_metrics(), T0).unwrap();
    node2.device_birth(&id("jbc2"), &station(), T0).unwrap();
    let mut stray = ddata(&mut node2, "jbc2", 1.0, at(700));
    let mut payload = Payload::decode(&stray.payload[..]).unwrap();
    payload.seq = Some(u64::from(node.seq()));
    stray.payload = payload.encode_to_vec();
    let got = feed(&mut host, &stray, at(700));
    assert_eq!(
        got.problems[0].problem,
        Problem::DeviceNotBorn { device: id("jbc2") }
    );
    assert_eq!(got.commands.len(), 1);
}

#[test]
fn a_gateway_event_arrives_with_its_kind_severity_device_point_and_line() {
    let mut host = alone();
    let mut node = born(&mut host);
    let event = NodeEvent {
        fields: Some(r#"{"value":3}"#.into()),
        t: at(123),
        kind: "alarm_raised".into(),
        severity: 700,
        message: "jbc1: tool error".into(),
        line: Some("line1".into()),
        device: Some("jbc1".into()),
        point: Some("error".into()),
    };
    let published = node.node_event(&event, at(130)).unwrap();
    assert_eq!(published.topic.to_string(), "spBv1.0/cell/NDATA/gw1");
    let got = feed(&mut host, &published, at(140));
    assert_eq!(got.problems, []);
    assert_eq!(got.samples, [], "an event is no sample");
    assert_eq!(
        got.events,
        [HostEvent {
            group: id("cell"),
            node: id("gw1"),
            device: Some("jbc1".into()),
            point: Some("error".into()),
            line: Some("line1".into()),
            t: at(123),
            kind: Some("alarm_raised".into()),
            severity: Some(700),
            message: "jbc1: tool error".into(),
            fields: Some(r#"{"value":3}"#.into()),
            historical: false,
        }]
    );
    // Twice the same event is two events.
    let again = node.node_event(&event, at(131)).unwrap();
    assert_eq!(feed(&mut host, &again, at(141)).events.len(), 1);
    assert_eq!(host.stats().events, 2);
}

#[test]
fn an_event_severity_of_any_number_type_is_read_by_its_sign_and_kept_within_1_to_1000() {
    use crate::proto::{PropertyValue, property_value::Value as P};
    let mut host = alone();
    let mut node = born(&mut host);
    let event = NodeEvent {
        fields: None,
        t: at(123),
        kind: "alarm_raised".into(),
        severity: 700,
        message: "over".into(),
        line: None,
        device: None,
        point: None,
    };
    let published = node.node_event(&event, at(130)).unwrap();
    let template = Payload::decode(&published.payload[..]).unwrap();
    let severity_of = |host: &mut Host, datatype: DataType, value: P| {
        let mut payload = template.clone();
        let properties = payload.metrics[0].properties.as_mut().unwrap();
        let i = properties
            .keys
            .iter()
            .position(|k| k == "severity")
            .unwrap();
        properties.values[i] = PropertyValue {
            r#type: Some(datatype.code()),
            is_null: None,
            value: Some(value),
        };
        payload.seq = None;
        let got = host.receive(
            &published.topic.to_string(),
            &payload.encode_to_vec(),
            at(140),
        );
        got.events[0].severity
    };
    assert_eq!(
        severity_of(
            &mut host,
            DataType::Int32,
            P::IntValue(u32::from_ne_bytes((-5i32).to_ne_bytes()))
        ),
        Some(1)
    );
    assert_eq!(
        severity_of(
            &mut host,
            DataType::Int64,
            P::LongValue(u64::from_ne_bytes((-5i64).to_ne_bytes()))
        ),
        Some(1)
    );
    assert_eq!(
        severity_of(&mut host, DataType::Double, P::DoubleValue(700.0)),
        Some(700)
    );
    assert_eq!(
        severity_of(&mut host, DataType::UInt32, P::IntValue(5000)),
        Some(1000)
    );
    assert_eq!(
        severity_of(&mut host, DataType::UInt64, P::LongValue(u64::MAX)),
        Some(1000)
    );
    assert_eq!(
        severity_of(&mut host, DataType::String, P::StringValue("high".into())),
        None
    );
}

#[test]
fn garbage_and_truncated_payloads_are_problems_not_panics() {
    let mut host = alone();
    let mut node = born(&mut host);
    let got = host.receive("spBv1.0/cell/DDATA/gw1/jbc1", &[0xff; 12], at(1));
    assert!(matches!(got.problems[0].problem, Problem::Undecodable(_)));
    let got = host.receive("spBv1.0/cell/NOPE/gw1", &[], at(1));
    assert!(matches!(got.problems[0].problem, Problem::Topic(_)));
    assert_eq!(host.stats().undecodable, 2);

    let nbirth = node.node_birth(&node_metrics(), at(2)).unwrap();
    let dbirth = node.device_birth(&id("jbc1"), &station(), at(2)).unwrap();
    let data = ddata(&mut node, "jbc1", 9.0, at(3));
    let mut undecodable = 0;
    for message in [&nbirth, &dbirth, &data] {
        let topic = message.topic.to_string();
        for end in 0..message.payload.len() {
            let got = host.receive(&topic, &message.payload[..end], at(4));
            undecodable += got
                .problems
                .iter()
                .filter(|p| matches!(p.problem, Problem::Undecodable(_)))
                .count();
        }
    }
    assert!(undecodable > 0, "cut inside a field is undecodable");
    assert_eq!(host.stats().undecodable, 2 + undecodable as u64);
}

/// A host within `limits`, following `cell`.
fn limited(limits: Limits) -> Host {
    alone().with_limits(limits)
}

/// `p` with its payload changed by `change`.
fn edited(p: &Publish, change: impl FnOnce(&mut Payload)) -> Publish {
    let mut payload = Payload::decode(&p.payload[..]).unwrap();
    change(&mut payload);
    Publish {
        payload: payload.encode_to_vec(),
        ..p.clone()
    }
}

#[test]
fn a_birth_past_the_point_cap_is_refused_whole_and_not_asked_again_at_once() {
    // The NBIRTH's 4 metrics (bdSeq, Rebirth, Event, Gateway/Lines) and jbc1's 4 fit;
    // jbc2's 4 would make 12.
    let mut host = limited(Limits {
        max_points: 11,
        ..Limits::default()
    });
    let mut node = connected();
    feed(
        &mut host,
        &node.node_birth(&node_metrics(), T0).unwrap(),
        T0,
    );
    let jbc1 = node.device_birth(&id("jbc1"), &station(), T0).unwrap();
    assert_eq!(feed(&mut host, &jbc1, T0).problems, []);
    assert_eq!(host.points_held(), 8);

    let jbc2 = node.device_birth(&id("jbc2"), &station(), T0).unwrap();
    let got = feed(&mut host, &jbc2, T0);
    assert_eq!(
        (got.points.len(), got.samples.len()),
        (0, 0),
        "refused whole"
    );
    assert_eq!(got.commands, []);
    assert_eq!(
        got.problems[0].problem,
        Problem::BirthRefused {
            metrics: 4,
            cap: Cap::Points,
            max: 11
        }
    );
    let words = got.problems[0].to_string();
    assert!(
        words.starts_with("spBv1.0/cell/DBIRTH/gw1/jbc2: a birth of 4 metrics refused")
            && words.contains("more than 11 metrics")
            && words.contains("5 min"),
        "{words}"
    );
    assert_eq!(host.stats().births_refused, 1);
    assert_eq!(host.points_held(), 8);

    // jbc2 stays unborn, and its data asks for no Rebirth for 5 minutes, not 5 s.
    for (offset, asked) in [(1_000, 0), (6_000, 0), (299_000, 0), (301_000, 1)] {
        let got = feed(
            &mut host,
            &ddata(&mut node, "jbc2", offset as f64, at(offset)),
            at(offset),
        );
        assert_eq!(got.samples, []);
        assert_eq!(
            got.problems[0].problem,
            Problem::DeviceNotBorn { device: id("jbc2") }
        );
        assert_eq!(got.commands.len(), asked, "at +{offset} ms");
    }
    // jbc1 lives on.
    let got = feed(
        &mut host,
        &ddata(&mut node, "jbc1", 2.0, at(302_000)),
        at(302_000),
    );
    assert_eq!((got.samples.len(), got.problems.len()), (1, 0));
}

#[test]
fn a_node_birth_past_the_per_node_cap_is_refused_and_a_smaller_one_is_taken() {
    let mut host = limited(Limits {
        max_node_points: 7,
        ..Limits::default()
    });
    let mut node = connected();
    let lines = (0..4).map(|i| {
        (
            MetricSpec::new(name(&format!("Line {i}")), DataType::Int64),
            Sample::good(MetricValue::Int64(i), T0),
        )
    });
    let big: Vec<_> = node_metrics().into_iter().chain(lines).collect();
    let got = feed(&mut host, &node.node_birth(&big, T0).unwrap(), T0);
    assert_eq!(got.points, []);
    assert!(matches!(
        got.problems[0].problem,
        Problem::BirthRefused {
            metrics: 8,
            cap: Cap::NodePoints,
            max: 7
        }
    ));
    assert_eq!(host.nodes_born(), 0);
    let dbirth = node.device_birth(&id("jbc1"), &station(), T0).unwrap();
    let got = feed(&mut host, &dbirth, at(6_000));
    assert!(matches!(
        got.problems[0].problem,
        Problem::NodeNotBorn { .. }
    ));
    assert_eq!(got.commands, [], "not asked again 6 s after a refusal");

    // The node's own rebirth with fewer metrics is taken, and its DBIRTH then passes
    // the node's limit (4 + 4 > 7).
    node.on_connect();
    let got = feed(
        &mut host,
        &node.node_birth(&node_metrics(), at(7_000)).unwrap(),
        at(7_000),
    );
    assert_eq!((got.problems.len(), got.points.len()), (0, 1));
    let dbirth = node
        .device_birth(&id("jbc1"), &station(), at(7_000))
        .unwrap();
    let got = feed(&mut host, &dbirth, at(7_000));
    assert!(matches!(
        got.problems[0].problem,
        Problem::BirthRefused {
            cap: Cap::NodePoints,
            ..
        }
    ));
    assert_eq!(host.points_held(), 4);
}

#[test]
fn a_new_node_past_the_node_cap_is_refused_unless_an_unborn_one_makes_room() {
    let mut host = limited(Limits {
        max_nodes: 1,
        ..Limits::default()
    });
    let (_gw1, gw1_will) = born_with_will(&mut host);
    let mut gw2 = EdgeNode::new(id("cell"), id("gw2"), BdSeq::new(0));
    gw2.on_connect();
    let birth = gw2.node_birth(&node_metrics(), at(10)).unwrap();
    let got = feed(&mut host, &birth, at(10));
    assert!(matches!(
        got.problems[0].problem,
        Problem::BirthRefused {
            cap: Cap::Nodes,
            max: 1,
            ..
        }
    ));
    // Its data asks for nothing: no state is kept for it.
    let data = gw2.node_event(&event_at(at(20)), at(20)).unwrap();
    let got = feed(&mut host, &data, at(20));
    assert!(matches!(
        got.problems[0].problem,
        Problem::NodeNotBorn { .. }
    ));
    assert_eq!((got.commands.len(), host.nodes_known()), (0, 1));

    // gw1 dies: its place may go to gw2.
    feed(&mut host, &gw1_will, at(30));
    let got = feed(&mut host, &birth, at(40));
    assert_eq!(got.problems, []);
    assert_eq!((host.nodes_born(), host.nodes_known()), (1, 1));
    assert_eq!(host.points_held(), 4, "gw1's 12 given back, gw2's 4 taken");
}

fn event_at(t: Timestamp) -> NodeEvent {
    NodeEvent {
        t,
        kind: "line_down".into(),
        severity: 500,
        message: "line1 down".into(),
        line: None,
        device: None,
        point: None,
        fields: None,
    }
}

#[test]
fn a_dead_nodes_state_is_freed_after_the_grace() {
    let mut host = alone();
    let (_node, will) = born_with_will(&mut host);
    let mut other = EdgeNode::new(id("cell"), id("gw2"), BdSeq::new(0));
    other.on_connect();
    feed(
        &mut host,
        &other.node_birth(&node_metrics(), T0).unwrap(),
        T0,
    );
    feed(&mut host, &will, at(1_000));
    assert_eq!((host.nodes_born(), host.nodes_known()), (1, 2));
    assert_eq!(host.points_held(), 4);

    // Any message looks, at most once a minute: 9 minutes after the death gw1 is kept.
    let nothing = |host: &mut Host, t| host.receive("spBv1.0/STATE/other", b"{}", t);
    nothing(&mut host, at(1_000 + 9 * 60_000));
    assert_eq!(host.nodes_known(), 2);
    nothing(&mut host, at(1_000 + DEAD_NODE_GRACE_MS + 60_000));
    assert_eq!(host.nodes_known(), 1, "gw1 freed, gw2 (born) kept");
    assert_eq!(host.stats().nodes_freed, 1);
    // A message of gw1's dead session changes nothing; a new birth is read as ever.
    assert_eq!(
        feed(&mut host, &will, at(DEAD_NODE_GRACE_MS * 2)),
        Received::default()
    );
}

#[test]
fn a_death_for_an_offline_host_marks_the_points_stale_not_bad() {
    let mut host = alone();
    let (mut node, _will) = born_with_will(&mut host);
    let death = node.host_offline_death(at(9_000)).unwrap();
    let got = feed(&mut host, &death, at(9_010));
    assert_eq!(got.problems, []);
    assert_eq!(
        got.samples.len(),
        1 + 4 + 4,
        "Gateway/Lines and both stations"
    );
    assert!(
        got.samples.iter().all(|s| s.t == at(9_000)
            && s.value == SampleValue::Null
            && s.quality == Quality::Stale)
    );
    // Unborn as after any death: its data asks for a rebirth.
    let got = feed(
        &mut host,
        &ddata(&mut node, "jbc1", 1.0, at(9_100)),
        at(9_100),
    );
    assert_eq!((got.samples.len(), got.commands.len()), (0, 1));
    assert_eq!(host.points_held(), 0);
}

#[test]
fn metric_names_with_a_right_to_left_override_are_left_out() {
    let mut host = alone();
    let mut node = born(&mut host);
    node.on_connect();
    feed(
        &mut host,
        &node.node_birth(&node_metrics(), at(1)).unwrap(),
        at(1),
    );
    let long = "x".repeat(300);
    let dbirth = edited(
        &node.device_birth(&id("jbc1"), &station(), at(1)).unwrap(),
        |payload| {
            // air_temp shows as "air_temp" followed by a reversed "lio": "air_templio"
            // would read "air_tempoil" in a table.
            payload.metrics[0].name = Some("air_temp\u{202e}lio".into());
            payload.metrics[1].name = Some(long.clone());
            payload.metrics[2].name = Some("heater\non".into());
        },
    );
    let got = feed(&mut host, &dbirth, at(2));
    let names: Vec<_> = got.points.iter().map(|p| p.point.name.as_str()).collect();
    assert_eq!(names, ["status"]);
    assert_eq!(got.samples.len(), 1);
    let problems: Vec<_> = got.problems.iter().map(|p| p.to_string()).collect();
    assert_eq!(problems.len(), 3, "{problems:#?}");
    assert!(
        problems[0].contains("birth metric 0")
            && problems[0].contains(r"\u{202e}")
            && !problems[0].contains('\u{202e}')
            && problems[0].ends_with("left out"),
        "{}",
        problems[0]
    );
    assert!(
        problems[1].contains("300 bytes long") && !problems[1].contains(&long),
        "{}",
        problems[1]
    );
    assert_eq!(host.stats().names_refused, 3);
    // Their data, by alias, is dropped without asking for a rebirth each time.
    let got = feed(&mut host, &ddata(&mut node, "jbc1", 3.0, at(3)), at(3));
    assert_eq!(got, Received::default());
    assert_eq!(host.stats().dropped, 1);
}

#[test]
fn a_message_whose_ids_are_too_long_or_hold_control_characters_is_refused_whole() {
    let mut host = alone();
    let mut node = born(&mut host);
    let birth = node.device_birth(&id("jbc1"), &station(), T0).unwrap();
    let device = "d".repeat(60_000);
    for (topic, level) in [
        (format!("spBv1.0/cell/DBIRTH/gw1/{device}"), "device id"),
        (
            "spBv1.0/cell/DBIRTH/gw1/jbc\u{202e}1".to_owned(),
            "device id",
        ),
        ("spBv1.0/cell/NBIRTH/gw\u{7}1".to_owned(), "edge node id"),
    ] {
        let got = host.receive(&topic, &birth.payload, at(1));
        assert_eq!((got.points.len(), got.samples.len()), (0, 0));
        let Problem::Topic(TopicError::Id {
            level: got_level, ..
        }) = &got.problems[0].problem
        else {
            panic!("{:?}", got.problems);
        };
        assert_eq!(*got_level, level);
        assert!(
            got.problems[0].to_string().len() < 2_000,
            "the problem does not repeat a 60 kB topic"
        );
    }
    assert_eq!(host.nodes_known(), 1);
}

#[test]
fn a_state_offline_on_the_hosts_own_topic_is_answered_with_the_sessions_own_online() {
    let host = alone();
    let online_at = at(10);
    let now = at(60_000);
    assert_eq!(
        host.state_subscription(),
        Subscription {
            filter: "spBv1.0/STATE/historian".into(),
            qos: Qos::AtLeastOnce
        }
    );
    let answer = |payload: &[u8]| {
        host.reassert_online(payload, online_at).map(|p| {
            assert_eq!(p.topic.to_string(), "spBv1.0/STATE/historian");
            assert_eq!((p.qos, p.retain), (Qos::AtLeastOnce, true));
            HostState::from_json(&p.payload).unwrap()
        })
    };
    let state = |online, t: Timestamp| HostState::new(online, t).to_json();
    assert_eq!(answer(&state(true, online_at)), None, "its own online");
    assert_eq!(
        answer(&state(true, at(1))),
        None,
        "an online is never answered"
    );
    // Forged now, ahead, at the session's own time, older, far ahead, or no STATE at
    // all: always this session's own online, whose time its Will shares (a newer one
    // would make the edge nodes ignore the Will).
    for payload in [
        state(false, now),
        state(false, at(65_000)),
        state(false, online_at),
        state(false, at(9)),
        state(false, at(253_402_300_799_000)),
        b"not json".to_vec(),
    ] {
        assert_eq!(answer(&payload), Some(HostState::new(true, online_at)));
    }
}

/// One step of a random plant: what an edge node (of three) publishes.
#[derive(Debug, Clone)]
enum Step {
    /// A new session and its NBIRTH of this many metrics of its own.
    NodeBirth(usize, usize),
    /// A DBIRTH of device 0–2 with this many metrics.
    DeviceBirth(usize, usize, usize),
    /// A DDEATH of device 0–2.
    DeviceDeath(usize, usize),
    /// The session's Will.
    NodeDeath(usize),
    /// The NDEATH of a node whose primary host went offline.
    HostOffline(usize),
}

fn step() -> impl proptest::strategy::Strategy<Value = Step> {
    use proptest::prelude::*;
    prop_oneof![
        (0..3usize, 0..8usize).prop_map(|(n, k)| Step::NodeBirth(n, k)),
        (0..3usize, 0..3usize, 0..8usize).prop_map(|(n, d, k)| Step::DeviceBirth(n, d, k)),
        (0..3usize, 0..3usize).prop_map(|(n, d)| Step::DeviceDeath(n, d)),
        (0..3usize).prop_map(Step::NodeDeath),
        (0..3usize).prop_map(Step::HostOffline),
    ]
}

fn metrics(k: usize) -> Vec<(MetricSpec, Sample)> {
    (0..k)
        .map(|i| {
            (
                MetricSpec::new(name(&format!("m{i}")), DataType::Int64),
                Sample::good(MetricValue::Int64(i as i64), T0),
            )
        })
        .collect()
}

proptest::proptest! {
    #[test]
    fn any_births_and_deaths_keep_within_the_limits_and_give_every_point_back(
        steps in proptest::collection::vec(step(), 0..60),
    ) {
        let limits = Limits { max_nodes: 2, max_node_points: 12, max_points: 20 };
        let mut host = limited(limits);
        let mut nodes: Vec<EdgeNode> = (0..3)
            .map(|n| EdgeNode::new(id("cell"), id(&format!("gw{n}")), BdSeq::new(0)))
            .collect();
        let mut wills: Vec<Option<Publish>> = vec![None, None, None];
        for (i, step) in steps.into_iter().enumerate() {
            let t = at(i as u64 * 1_000);
            let published = match step {
                Step::NodeBirth(n, k) => {
                    wills[n] = Some(nodes[n].will());
                    nodes[n].on_connect();
                    nodes[n].node_birth(&metrics(k), t).ok()
                }
                Step::DeviceBirth(n, d, k) => nodes[n]
                    .device_birth(&id(&format!("d{d}")), &metrics(k), t)
                    .ok(),
                Step::DeviceDeath(n, d) => {
                    nodes[n].device_death(&id(&format!("d{d}")), t).ok()
                }
                Step::NodeDeath(n) => wills[n].clone(),
                Step::HostOffline(n) => nodes[n].host_offline_death(t),
            };
            if let Some(p) = published {
                feed(&mut host, &p, t);
            }
            proptest::prop_assert!(host.points_held() <= limits.max_points);
            proptest::prop_assert!(host.nodes_known() <= limits.max_nodes);
        }
        // Every session's Will: nothing is held any more.
        for will in wills.into_iter().flatten() {
            feed(&mut host, &will, at(100_000));
        }
        proptest::prop_assert_eq!(host.nodes_born(), 0);
        proptest::prop_assert_eq!(host.points_held(), 0);
    }
}

proptest::proptest! {
    #[test]
    fn any_bytes_on_any_topic_never_panic(
        bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..200),
        topic in 0usize..8,
    ) {
        let topics = [
            "spBv1.0/cell/NBIRTH/gw1",
            "spBv1.0/cell/NDATA/gw1",
            "spBv1.0/cell/NDEATH/gw1",
            "spBv1.0/cell/DBIRTH/gw1/jbc1",
            "spBv1.0/cell/DDATA/gw1/jbc1",
            "spBv1.0/cell/DDEATH/gw1/jbc1",
            "spBv1.0/STATE/other",
            "garbage/#",
        ];
        let mut host = alone();
        born(&mut host);
        let before = host.stats().messages;
        let got = host.receive(topics[topic], &bytes, at(1));
        proptest::prop_assert_eq!(host.stats().messages, before + 1);
        proptest::prop_assert!(got.commands.len() <= 1);
    }
}

#[test]
fn alone_subscribes_to_the_six_message_types_of_its_group_and_not_to_state_or_commands() {
    let subscriptions = alone().subscriptions();
    let filters: Vec<_> = subscriptions
        .iter()
        .map(|s| (s.filter.as_str(), s.qos))
        .collect();
    assert_eq!(
        filters,
        [
            ("spBv1.0/cell/NBIRTH/+", Qos::AtLeastOnce),
            ("spBv1.0/cell/NDEATH/+", Qos::AtLeastOnce),
            ("spBv1.0/cell/DBIRTH/+/+", Qos::AtLeastOnce),
            ("spBv1.0/cell/DDEATH/+/+", Qos::AtLeastOnce),
            ("spBv1.0/cell/NDATA/+", Qos::AtMostOnce),
            ("spBv1.0/cell/DDATA/+/+", Qos::AtMostOnce),
        ]
    );
    let every_group = Host::new(id("h"), None, Sharing::Alone).subscriptions();
    assert_eq!(every_group[0].filter, "spBv1.0/+/NBIRTH/+");
}

#[test]
fn shared_mode_subscribes_births_unshared_and_data_shared_and_asks_no_rebirth_on_a_gap() {
    let sharing = Sharing::Shared { name: id("plant") };
    let mut host = Host::new(id("historian-2"), Some(id("cell")), sharing);
    let filters: Vec<_> = host.subscriptions().into_iter().map(|s| s.filter).collect();
    assert_eq!(
        filters,
        [
            "spBv1.0/cell/NBIRTH/+",
            "spBv1.0/cell/NDEATH/+",
            "spBv1.0/cell/DBIRTH/+/+",
            "spBv1.0/cell/DDEATH/+/+",
            "$share/plant/spBv1.0/cell/NDATA/+",
            "$share/plant/spBv1.0/cell/DDATA/+/+",
        ]
    );
    let mut node = born(&mut host);
    let _taken_by_another_host = ddata(&mut node, "jbc1", 1.0, at(10));
    let got = feed(&mut host, &ddata(&mut node, "jbc1", 2.0, at(20)), at(20));
    assert_eq!((got.problems.len(), got.commands.len()), (0, 0));
    assert_eq!(got.samples.len(), 1);
    assert_eq!(host.stats().seq_gaps, 0);
    // Data before a birth still asks for one.
    let mut stranger = EdgeNode::new(id("cell"), id("gw9"), BdSeq::new(0));
    stranger.on_connect();
    stranger.node_birth(&[], T0).unwrap();
    stranger.device_birth(&id("d"), &station(), T0).unwrap();
    let got = feed(&mut host, &ddata(&mut stranger, "d", 1.0, at(30)), at(30));
    assert_eq!(got.commands.len(), 1);
    assert_eq!(got.commands[0].topic.to_string(), "spBv1.0/cell/NCMD/gw9");
}

#[test]
fn state_online_and_will_are_retained_qos1_json_on_the_hosts_state_topic() {
    let host = alone();
    let will = host.will(at(0));
    let online = host.state_online(at(0));
    for (p, online_flag) in [(&will, false), (&online, true)] {
        assert_eq!(p.topic.to_string(), "spBv1.0/STATE/historian");
        assert_eq!((p.qos, p.retain), (Qos::AtLeastOnce, true));
        let state = HostState::from_json(&p.payload).unwrap();
        assert_eq!(state, HostState::new(online_flag, T0));
    }
}

#[test]
fn other_groups_state_and_commands_are_ignored() {
    let mut host = alone();
    born(&mut host);
    let state = HostState::new(true, T0).publish(id("other"));
    assert_eq!(feed(&mut host, &state, at(1)), Received::default());
    let ncmd = rebirth_request(&id("cell"), &id("gw1"), at(1));
    assert_eq!(feed(&mut host, &ncmd, at(1)), Received::default());
    let mut elsewhere = EdgeNode::new(id("line2"), id("gw1"), BdSeq::new(0));
    elsewhere.on_connect();
    let birth = elsewhere.node_birth(&node_metrics(), T0).unwrap();
    assert_eq!(feed(&mut host, &birth, at(1)), Received::default());
}

#[test]
fn a_rebirth_request_names_the_rebirth_metric_and_the_edge_node_reads_it() {
    let request = rebirth_request(&id("cell"), &id("gw1"), at(5));
    let payload = Payload::decode(&request.payload[..]).unwrap();
    assert_eq!(payload.metrics[0].name.as_deref(), Some(REBIRTH));
    assert_eq!(payload.timestamp, Some(at(5).as_millis()));
    assert!(is_rebirth_of_gw1(&request));
}

#[test]
fn float32_values_are_the_decimal_they_were_written_as() {
    assert_eq!(
        SampleValue::from(MetricValue::Float(0.1)),
        SampleValue::Number(0.1)
    );
    assert_eq!(
        SampleValue::from(MetricValue::UInt64(u64::MAX)),
        SampleValue::Number(u64::MAX as f64)
    );
    assert_eq!(
        SampleValue::from(MetricValue::DateTime(T0)),
        SampleValue::Number(T0.as_millis() as f64)
    );
}
