//! The edge node over a real mosquitto, driven by JBC stations on an in-memory line: a
//! device that stops answering is a DDEATH (after null readings with their quality, never
//! the last good value) and a DBIRTH when it answers again.

use std::sync::atomic::Ordering;
use std::time::Duration;

use sparkplug::Quality as SpQuality;
use sparkplug::proto::metric::Value as SpValue;
use testkit::{Mosquitto, SparkplugMessage, Subscriber};
use tokio::sync::watch;

use crate::northbound::mqtt::config::MqttConfig;
use crate::point::Value;
use crate::testing::rig;

/// Generous: a loaded 2-core machine, and a device's backoff of up to 10 s.
const LIMIT: Duration = Duration::from_secs(60);

fn config(broker: &Mosquitto) -> MqttConfig {
    MqttConfig {
        group_id: "rig".into(),
        ..MqttConfig::for_broker(&broker.url(), "cell").unwrap()
    }
}

/// The next message of `kind` (`NBIRTH`) `sub` sees; `what` names it if none comes.
async fn next_of_kind(sub: &mut Subscriber, kind: &str, what: &str) -> SparkplugMessage {
    sub.next_where(what, LIMIT, |m| m.kind() == kind).await
}

/// A rig of `stations` JBC stations, a broker and a subscriber to every message of the
/// rig's cell on it.
async fn on_a_broker(stations: u8) -> (crate::testing::Rig, Mosquitto, Subscriber) {
    let broker = Mosquitto::start();
    let sub = Subscriber::start(broker.port(), "spBv1.0/rig/+/cell/#").await;
    (rig(stations), broker, sub)
}

/// The `[mqtt]` table of [`config`], taking commands.
fn taking_commands(broker: &Mosquitto) -> MqttConfig {
    MqttConfig {
        commands: true,
        ..config(broker)
    }
}

/// The MQTT side of `rig`'s cell, running until [`Node::stop`].
struct Node {
    task: tokio::task::JoinHandle<()>,
    stop: watch::Sender<bool>,
}

impl Node {
    /// Starts publishing `rig`'s cell with `config`; `allow_writes` is `--allow-writes`.
    fn start(rig: &crate::testing::Rig, config: MqttConfig, allow_writes: bool) -> Self {
        let (stop, stopped) = watch::channel(false);
        let task = super::mqtt::start(
            rig.cell.clone(),
            config,
            rig.dir.path().join("mqtt"),
            allow_writes,
            stopped,
        )
        .unwrap();
        Self { task, stop }
    }

    /// Like [`Node::start`], returning once `sub` saw jbc1's first DDATA.
    async fn start_until_data(
        rig: &crate::testing::Rig,
        config: MqttConfig,
        allow_writes: bool,
        sub: &mut Subscriber,
    ) -> Self {
        let node = Self::start(rig, config, allow_writes);
        next_of_kind(sub, "DDATA", "a DDATA of jbc1").await;
        node
    }

    /// Stops it gracefully and waits (bounded) for the end.
    async fn stop(self) {
        self.stop.send(true).unwrap();
        tokio::time::timeout(LIMIT, self.task)
            .await
            .unwrap()
            .unwrap();
    }
}

fn of_jbc2(m: &SparkplugMessage) -> bool {
    m.device() == Some("jbc2")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_silent_device_dies_with_null_readings_and_is_born_again_when_it_answers() {
    let (rig, broker, mut sub) = on_a_broker(2).await;
    let node = Node::start(&rig, config(&broker), false);

    // Born, then read: a DDATA with good values.
    sub.next_where("the DBIRTH of jbc2", LIMIT, |m| {
        of_jbc2(m) && m.kind() == "DBIRTH"
    })
    .await;
    sub.next_where("a DDATA of jbc2", LIMIT, |m| {
        of_jbc2(m) && m.kind() == "DDATA"
    })
    .await;

    // Unplugged: its points go bad (null and Quality, never the last value), then DDEATH.
    rig.plugged[1].store(false, Ordering::SeqCst);
    let mut nulls = 0;
    loop {
        let m = sub.next_where("jbc2's DDEATH", LIMIT, of_jbc2).await;
        match m.kind() {
            "DDEATH" => break,
            "DDATA" => {
                for metric in &m.payload.metrics {
                    let quality = SpQuality::of(metric).unwrap_or(SpQuality::Good);
                    if quality != SpQuality::Good {
                        assert_eq!(metric.is_null, Some(true), "{metric:?}");
                        assert_eq!(metric.value, None, "no last good value: {metric:?}");
                        nulls += 1;
                    }
                }
            }
            other => panic!("{other} for jbc2 before its DDEATH"),
        }
    }
    assert!(
        nulls > 0,
        "the failed reads were published as null readings"
    );

    // Plugged back: the next message about jbc2 is its DBIRTH, with good values.
    rig.plugged[1].store(true, Ordering::SeqCst);
    let back = sub.next_where("jbc2's next message", LIMIT, of_jbc2).await;
    assert_eq!(back.kind(), "DBIRTH", "{}", back.topic);
    assert!(
        back.payload.metrics.iter().any(|m| m.value.is_some()),
        "born again with values"
    );

    node.stop().await;
    next_of_kind(&mut sub, "NDEATH", "the NDEATH at the stop").await;
}

/// A message as received, in its encoded form again, read by a Sparkplug host.
fn host_reads(host: &mut sparkplug::Host, m: &SparkplugMessage) -> sparkplug::Received {
    use prost::Message as _;
    let now = sparkplug::Timestamp::from_millis(now_ms());
    host.receive(&m.topic, &m.payload.encode_to_vec(), now)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_device_going_down_is_an_ndata_event_with_its_kind_severity_and_device() {
    let (rig, broker, mut sub) = on_a_broker(2).await;
    let mut live = rig.cell.subscribe();
    let node = Node::start(&rig, config(&broker), false);
    let id = |s: &str| sparkplug::Id::new(s).unwrap();
    let mut host =
        sparkplug::Host::new(id("historian"), Some(id("rig")), sparkplug::Sharing::Alone);

    // The NBIRTH carries the event channel: a String metric `Event`.
    let birth = next_of_kind(&mut sub, "NBIRTH", "the NBIRTH").await;
    let channel = birth
        .metric("Event")
        .expect("the NBIRTH has an Event metric");
    assert_eq!(channel.datatype, Some(sparkplug::DataType::String.code()));
    let alias = channel.alias.expect("an alias");
    assert_eq!(host_reads(&mut host, &birth).problems, []);

    // Every message up to jbc2's death reads cleanly: no seq gap, no unknown alias.
    let mut jbc2_born = false;
    let event = loop {
        let m = sub
            .next_where("jbc2's device_down event", LIMIT, |_| true)
            .await;
        let got = host_reads(&mut host, &m);
        assert_eq!(got.problems, [], "{}", m.topic);
        assert_eq!(got.commands, [], "{}", m.topic);
        if of_jbc2(&m) && m.kind() == "DBIRTH" && !jbc2_born {
            jbc2_born = true;
            rig.plugged[1].store(false, Ordering::SeqCst);
        }
        if let Some(e) = got
            .events
            .into_iter()
            .find(|e| e.kind.as_deref() == Some("device_down"))
        {
            // As published: the Event metric by alias, the message as its value.
            assert_eq!(m.kind(), "NDATA");
            let metric = m
                .payload
                .metrics
                .iter()
                .find(|x| x.alias == Some(alias))
                .expect("the event by the Event metric's alias");
            assert_eq!(metric.value, Some(SpValue::StringValue(e.message.clone())));
            break e;
        }
    };
    assert!(jbc2_born);
    assert_eq!(event.node, id("cell"));
    assert_eq!(event.device.as_deref(), Some("jbc2"));
    assert_eq!(event.severity, Some(700));
    assert!(event.line.is_some(), "the line of the device");
    assert!(event.message.contains("jbc2"), "{}", event.message);
    assert!(!event.historical);

    // The gateway's own event, as its change stream gave it: same time, same words.
    let recorded = next_event(&mut live, crate::event::EventKind::DeviceDown).await;
    assert_eq!(event.t.as_millis(), u64::try_from(recorded.t.0).unwrap());
    assert_eq!(event.message, recorded.message);
    assert_eq!(event.line, recorded.line);

    node.stop().await;
}

/// A writable number of jbc1 once it has been read: its name, value, and a value to write.
fn writable_number(rig: &crate::testing::Rig) -> (String, f64, f64) {
    let device = rig.cell.device("jbc1").unwrap();
    device
        .points
        .iter()
        .find_map(|p| {
            let range = p.writable?;
            let Some(Value::Number(old)) = p.view.value else {
                return None;
            };
            let target = if old == range.min {
                range.max
            } else {
                range.min
            };
            Some((p.view.id.name().to_owned(), old, target))
        })
        .expect("a JBC station has a writable number")
}

/// Where jbc1's commands go.
const JBC1_DCMD: &str = "spBv1.0/rig/DCMD/cell/jbc1";

/// A DCMD payload that sets the metric `name` to the double `value`.
fn set_number(name: &str, value: f64) -> Vec<u8> {
    testkit::command_payload(
        name,
        sparkplug::DataType::Double,
        SpValue::DoubleValue(value),
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_dcmd_write_is_refused_without_allow_writes_and_nothing_is_stored() {
    let (rig, broker, mut sub) = on_a_broker(1).await;
    // The table asks for commands, but the gateway runs without --allow-writes.
    let node = Node::start_until_data(&rig, taking_commands(&broker), false, &mut sub).await;
    let (name, old, target) = writable_number(&rig);

    sub.publish(JBC1_DCMD, set_number(&name, target)).await;
    // Commands are handled in order: once the rebirth asked after it is out, the DCMD was
    // handled, and the birth shows the value unchanged.
    sub.publish("spBv1.0/rig/NCMD/cell", testkit::rebirth_command())
        .await;
    next_of_kind(&mut sub, "NBIRTH", "the NBIRTH of the rebirth").await;
    let birth = next_of_kind(&mut sub, "DBIRTH", "the DBIRTH of jbc1").await;
    assert_eq!(
        birth.metric(&name).and_then(|m| m.value.clone()),
        Some(SpValue::DoubleValue(old)),
        "{name} unchanged"
    );
    assert_eq!(
        rig.cell
            .device("jbc1")
            .unwrap()
            .points
            .iter()
            .find(|p| p.view.id.name() == name)
            .and_then(|p| p.view.value.clone()),
        Some(Value::Number(old))
    );
    assert_eq!(
        rig.cell.store().audit_log(None, 10).unwrap(),
        vec![],
        "nothing stored"
    );
    let refused = rig.cell.metrics().writes_of("unauthorised");
    assert_eq!(refused, 1, "counted");

    node.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_dcmd_write_goes_through_the_audited_write_path_when_allowed() {
    let (rig, broker, mut sub) = on_a_broker(1).await;
    let mut live = rig.cell.subscribe();
    let node = Node::start_until_data(&rig, taking_commands(&broker), true, &mut sub).await;
    let (name, old, target) = writable_number(&rig);

    // Outside the point's range: refused before the wire, with one audit row.
    sub.publish(JBC1_DCMD, set_number(&name, 1e9)).await;
    sub.publish(JBC1_DCMD, set_number(&name, target)).await;
    // The write event is emitted when the device took the value.
    next_event(&mut live, crate::event::EventKind::Write).await;
    let audit = rig.cell.store().audit_log(None, 10).unwrap();
    let results: Vec<&str> = audit.iter().rev().map(|a| a.result.as_str()).collect();
    assert_eq!(
        results,
        vec!["refused", "attempted", "accepted"],
        "{audit:#?}"
    );
    assert!(
        audit
            .iter()
            .all(|a| a.client == "mqtt spBv1.0/rig/DCMD/cell/jbc1"),
        "{audit:#?}"
    );
    assert_eq!(audit[0].old_value, Some(serde_json::json!(old)));
    assert!(audit[0].detail.contains(&name), "{}", audit[0].detail);

    node.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dcmd_writes_are_carried_out_in_the_order_they_came_and_a_retained_one_never() {
    let (rig, broker, mut sub) = on_a_broker(1).await;
    let mut live = rig.cell.subscribe();
    let read = || {
        let device = rig.cell.device("jbc1").unwrap();
        device
            .points
            .iter()
            .any(|p| p.writable.is_some() && p.view.value.is_some())
    };
    tokio::time::timeout(LIMIT, async {
        while !read() {
            let _ = live.recv().await;
        }
    })
    .await
    .expect("jbc1 read");
    let (name, old, _) = writable_number(&rig);
    // A command kept by the broker from before the node's session: delivered as retained
    // when the node subscribes, and refused. It is 5 MiB (its payload's body), more than a
    // message the gateway publishes: a client that dropped the connection on it would get
    // it again at every reconnection and never stay connected.
    let stale = old + 7.0;
    let mut large =
        <sparkplug::proto::Payload as prost::Message>::decode(&set_number(&name, stale)[..])
            .expect("a Sparkplug payload");
    large.body = Some(vec![0x55; 5 << 20]);
    sub.publish_retained(JBC1_DCMD, prost::Message::encode_to_vec(&large))
        .await;
    let node = Node::start_until_data(&rig, taking_commands(&broker), true, &mut sub).await;
    // Five commands, one right after the other: carried out in that order.
    let values: Vec<f64> = (1..=5).map(|k| old + f64::from(k)).collect();
    for &value in &values {
        sub.publish(JBC1_DCMD, set_number(&name, value)).await;
    }
    // Each write's event comes once its audit rows are committed.
    let mut done = Vec::new();
    for _ in &values {
        done.push(next_event(&mut live, crate::event::EventKind::Write).await);
    }
    let last = *values.last().unwrap();
    assert!(
        done[4].message.contains(&format!(" set to {last}")),
        "{}",
        done[4].message
    );
    let audit = rig.cell.store().audit_log(None, 50).unwrap();
    let accepted: Vec<&serde_json::Value> = audit
        .iter()
        .rev()
        .filter(|a| a.result == "accepted")
        .map(|a| &a.new_value)
        .collect();
    let expected: Vec<serde_json::Value> = values.iter().map(|v| serde_json::json!(v)).collect();
    assert_eq!(accepted, expected.iter().collect::<Vec<_>>(), "{audit:#?}");
    // The retained command: one refused row, never carried out.
    let refused: Vec<_> = audit.iter().filter(|a| a.result == "refused").collect();
    assert_eq!(refused.len(), 1, "{audit:#?}");
    assert!(
        refused[0].detail.contains("retained"),
        "{}",
        refused[0].detail
    );
    assert!(
        !audit
            .iter()
            .any(|a| a.result == "accepted" && a.new_value == serde_json::json!(stale)),
        "{audit:#?}"
    );
    node.stop().await;
}

/// A device's alarm on MQTT: its state, priority and acknowledgement are metrics of the
/// device, born with it and sent as DDATA when they change; a host acknowledges it by
/// setting `Acknowledged` to true (a DCMD), which reaches the same journal as the API.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_devices_alarm_is_three_metrics_of_it_and_a_dcmd_acknowledges_it_in_the_journal() {
    let (rig, broker, mut sub) = on_a_broker(1).await;
    let mut live = rig.cell.subscribe();
    let node = Node::start(&rig, taking_commands(&broker), true);
    let birth = next_of_kind(&mut sub, "DBIRTH", "the DBIRTH of jbc1").await;
    let state = "Alarms/tool_error/State";
    assert_eq!(
        birth.metric(state).and_then(|m| m.value.clone()),
        Some(SpValue::StringValue("normal".into()))
    );
    assert!(birth.metric("Alarms/down/Acknowledged").is_some());
    let alias = |name: &str| birth.metric(name).and_then(|m| m.alias).unwrap();
    let (state_alias, ack_alias) = (alias(state), alias("Alarms/tool_error/Acknowledged"));

    rig.models[0]
        .lock()
        .set_tool_error(jbc::code::ToolError::HeaterMalfunction);
    next_event(&mut live, crate::event::EventKind::AlarmRaised).await;
    let raised = sub
        .next_where("the alarm's DDATA", LIMIT, |m| {
            m.kind() == "DDATA"
                && m.payload
                    .metrics
                    .iter()
                    .any(|x| x.alias == Some(state_alias))
        })
        .await;
    let value_of = |m: &SparkplugMessage, alias: u64| {
        m.payload
            .metrics
            .iter()
            .find(|x| x.alias == Some(alias))
            .and_then(|x| x.value.clone())
    };
    assert_eq!(
        value_of(&raised, state_alias),
        Some(SpValue::StringValue("unacknowledged".into()))
    );
    assert_eq!(
        value_of(&raised, ack_alias),
        Some(SpValue::BooleanValue(false))
    );

    sub.publish(
        JBC1_DCMD,
        testkit::command_payload(
            "Alarms/tool_error/Acknowledged",
            sparkplug::DataType::Boolean,
            SpValue::BooleanValue(true),
        ),
    )
    .await;
    let acked = next_event(&mut live, crate::event::EventKind::AlarmChanged).await;
    assert_eq!(acked.fields["alarm"], "jbc1.tool_error");
    assert_eq!(acked.fields["state"], "acknowledged");
    assert_eq!(acked.fields["by"], "mqtt DCMD spBv1.0/rig/DCMD/cell/jbc1");
    let data = sub
        .next_where("the acknowledgement's DDATA", LIMIT, |m| {
            m.kind() == "DDATA" && m.payload.metrics.iter().any(|x| x.alias == Some(ack_alias))
        })
        .await;
    assert_eq!(
        value_of(&data, ack_alias),
        Some(SpValue::BooleanValue(true))
    );
    rig.cell.store().flush().await.unwrap();
    let journal = rig
        .cell
        .store()
        .alarm_journal(
            crate::time::Timestamp(0),
            crate::time::Timestamp(i64::MAX),
            Some("jbc1.tool_error"),
            None,
            10,
        )
        .unwrap();
    let kinds: Vec<&str> = journal.iter().map(|e| e.kind.as_str()).collect();
    assert_eq!(kinds, ["alarm_changed", "alarm_raised"]);
    node.stop().await;
}

/// The next event of `kind` on the cell's change stream.
async fn next_event(
    live: &mut tokio::sync::broadcast::Receiver<crate::cell::LiveMessage>,
    kind: crate::event::EventKind,
) -> crate::event::Event {
    tokio::time::timeout(LIMIT, async {
        loop {
            match live.recv().await {
                Ok(crate::cell::LiveMessage::Event(e)) if e.kind == kind => return *e,
                Ok(_) | Err(tokio::sync::broadcast::error::RecvError::Lagged(_)) => {}
                Err(e) => panic!("the change stream ended: {e}"),
            }
        }
    })
    .await
    .unwrap_or_else(|_| panic!("no {kind:?} event within {LIMIT:?}"))
}

fn host_state(online: bool) -> Vec<u8> {
    sparkplug::HostState::new(online, sparkplug::Timestamp::from_millis(now_ms())).to_json()
}

fn now_ms() -> u64 {
    u64::try_from(crate::time::Timestamp::now().0).unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_a_primary_host_births_wait_for_it_and_what_it_missed_offline_comes_as_history() {
    let (rig, broker, mut sub) = on_a_broker(1).await;
    let mut live = rig.cell.subscribe();
    let config = MqttConfig {
        primary_host: Some("scada".into()),
        ..config(&broker)
    };
    let node = Node::start(&rig, config, false);

    // Connected, but silent until the host says it is online.
    next_event(&mut live, crate::event::EventKind::InterfaceUp).await;
    let online_at = now_ms();
    sub.publish_retained("spBv1.0/STATE/scada", host_state(true))
        .await;
    let birth = next_of_kind(&mut sub, "NBIRTH", "the NBIRTH once the host is online").await;
    assert!(
        birth.payload.timestamp.unwrap() >= online_at,
        "no birth before the host was online"
    );
    let dbirth = next_of_kind(&mut sub, "DBIRTH", "the DBIRTH of jbc1").await;
    let bd_seq = birth.bd_seq().unwrap();

    // The host goes away: the node ends its session (NDEATH with the session's bdSeq) and
    // keeps reading the station meanwhile.
    sub.publish_retained("spBv1.0/STATE/scada", host_state(false))
        .await;
    let death = next_of_kind(&mut sub, "NDEATH", "the NDEATH when the host went offline").await;
    assert_eq!(death.bd_seq(), Some(bd_seq));
    let offline_at = now_ms();
    // The node is connected again (a new session), still silent: wait for some readings.
    next_event(&mut live, crate::event::EventKind::InterfaceUp).await;
    // Changes while it is away: the station stops answering (its points go bad) and
    // answers again.
    rig.plugged[0].store(false, Ordering::SeqCst);
    next_event(&mut live, crate::event::EventKind::DeviceDown).await;
    rig.plugged[0].store(true, Ordering::SeqCst);
    next_event(&mut live, crate::event::EventKind::DeviceUp).await;
    let back_at = now_ms();
    sub.publish_retained("spBv1.0/STATE/scada", host_state(true))
        .await;
    let again = next_of_kind(&mut sub, "NBIRTH", "the NBIRTH when the host is back").await;
    assert!(again.bd_seq().unwrap() > bd_seq);
    // What changed while the host was away comes as history, with its own read times.
    let history = sub
        .next_where("historical DDATA", LIMIT, |m| {
            m.kind() == "DDATA"
                && m.payload
                    .metrics
                    .iter()
                    .any(|x| x.is_historical == Some(true))
        })
        .await;
    let times: Vec<u64> = history
        .payload
        .metrics
        .iter()
        .map(|m| m.timestamp.unwrap())
        .collect();
    assert!(
        times.iter().any(|&t| t > offline_at && t < back_at),
        "readings from the offline time {offline_at}..{back_at}: {times:?}"
    );
    assert!(dbirth.payload.metrics.len() > 5);

    node.stop().await;
}

/// Polls `holds` until it is true, within [`LIMIT`].
async fn until(what: &str, mut holds: impl FnMut() -> bool) {
    let deadline = tokio::time::Instant::now() + LIMIT;
    while !holds() {
        assert!(
            tokio::time::Instant::now() < deadline,
            "not {what} within {LIMIT:?}"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

fn host_state_at(online: bool, timestamp: u64) -> Vec<u8> {
    sparkplug::HostState { online, timestamp }.to_json()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn forged_host_states_cannot_latch_the_node_offline() {
    let (rig, broker, mut sub) = on_a_broker(1).await;
    let config = MqttConfig {
        primary_host: Some("scada".into()),
        ..config(&broker)
    };
    let node = Node::start(&rig, config, false);
    let state_topic = "spBv1.0/STATE/scada";
    let session = now_ms() - 60_000;
    sub.publish_retained(state_topic, host_state_at(true, session))
        .await;
    let birth = next_of_kind(&mut sub, "NBIRTH", "the NBIRTH").await;
    let bd_seq = birth.bd_seq().unwrap();
    let metrics = &super::mqtt::status::status(&rig.cell).metrics;

    // Any client's offline dated now, at once contradicted by the host's own session.
    sub.publish(state_topic, host_state(false)).await;
    sub.publish_retained(state_topic, host_state_at(true, session))
        .await;
    until("contradicted", || metrics.offline_contradicted.get() == 1).await;

    // An offline dated in the year 9999, retained: refused and counted.
    sub.publish_retained(state_topic, host_state_at(false, 253_402_300_799_000))
        .await;
    until("refused", || metrics.state_refused.get() == 1).await;
    // The session goes on: a rebirth is an NBIRTH with the same bdSeq, no NDEATH before it.
    sub.publish("spBv1.0/rig/NCMD/cell", testkit::rebirth_command())
        .await;
    let again = sub
        .next_where("the NBIRTH of the rebirth", LIMIT, |m| {
            assert_ne!(m.kind(), "NDEATH", "the session ended");
            m.kind() == "NBIRTH"
        })
        .await;
    assert_eq!(again.bd_seq(), Some(bd_seq));

    // An offline nobody contradicts: after the grace, an NDEATH that says why.
    sub.publish(state_topic, host_state(false)).await;
    let death = next_of_kind(&mut sub, "NDEATH", "the NDEATH").await;
    assert_eq!(death.bd_seq(), Some(bd_seq));
    assert_eq!(
        death
            .metric(sparkplug::node::HOST_OFFLINE)
            .and_then(|m| m.value.clone()),
        Some(SpValue::BooleanValue(true))
    );
    // The next connection refuses the year-9999 STATE it finds retained and believes the
    // host's own session, published again though older than the offline that ended the
    // last connection: births follow.
    until("the retained forgery refused again", || {
        metrics.state_refused.get() == 2
    })
    .await;
    sub.publish_retained(state_topic, host_state_at(true, session))
        .await;
    let reborn = next_of_kind(&mut sub, "NBIRTH", "the NBIRTH of the next session").await;
    assert!(reborn.bd_seq().unwrap() > bd_seq);
    node.stop().await;
}

/// A DCMD of `writes` (name, value) for jbc1's Double points.
fn dcmd(writes: &[(&str, f64)]) -> Vec<u8> {
    let payload = sparkplug::proto::Payload {
        timestamp: Some(now_ms()),
        metrics: writes
            .iter()
            .map(|&(name, value)| sparkplug::proto::Metric {
                name: Some(name.to_owned()),
                datatype: Some(sparkplug::DataType::Double.code()),
                value: Some(SpValue::DoubleValue(value)),
                ..sparkplug::proto::Metric::default()
            })
            .collect(),
        ..sparkplug::proto::Payload::default()
    };
    prost::Message::encode_to_vec(&payload)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_dcmd_is_carried_out_whole_or_refused_whole_and_refusals_do_not_fill_the_audit_log() {
    let broker = Mosquitto::start();
    let mut sub = Subscriber::start(broker.port(), "spBv1.0/rig/DDATA/cell/#").await;
    let rig = rig(1);
    let mut live = rig.cell.subscribe();
    let config = MqttConfig {
        max_command_metrics: 8,
        ..taking_commands(&broker)
    };
    let node = Node::start_until_data(&rig, config, true, &mut sub).await;
    let (name, old, target) = writable_number(&rig);
    let topic = "spBv1.0/rig/DCMD/cell/jbc1";
    let metrics = &super::mqtt::status::status(&rig.cell).metrics;

    // A point named twice, and more metrics than max_command_metrics: each refused whole.
    sub.publish(topic, dcmd(&[(&name, target), (&name, target)]))
        .await;
    until("the first refusal", || metrics.commands_refused.get() == 1).await;
    let many: Vec<(&str, f64)> = (0..100).map(|_| (name.as_str(), target)).collect();
    sub.publish(topic, dcmd(&many)).await;
    // 200 commands that are not Sparkplug at all, from a client that reads nothing.
    let rogue = Subscriber::start(broker.port(), "rogue/inbox").await;
    for _ in 0..200 {
        rogue.publish(topic, b"garbage".to_vec()).await;
    }
    until("every refusal counted", || {
        metrics.commands_refused.get() == 202
    })
    .await;
    // Then a good one: carried out, with its full rows.
    sub.publish(topic, dcmd(&[(&name, target)])).await;
    next_event(&mut live, crate::event::EventKind::Write).await;

    let audit = rig.cell.store().audit_log(None, 1000).unwrap();
    let results: Vec<&str> = audit.iter().rev().map(|a| a.result.as_str()).collect();
    // The first refusal has its row; the 201 after it within the interval are counted in
    // at most one more row (a slow machine may cross the 10 s interval once).
    let refused = results.iter().filter(|r| **r == "refused").count();
    assert!((1..=2).contains(&refused), "{audit:#?}");
    assert_eq!(
        results[refused..],
        ["attempted", "accepted"],
        "nothing of the refused commands was written: {audit:#?}"
    );
    let first = audit.last().unwrap();
    assert!(first.detail.contains("named twice"), "{}", first.detail);
    assert_eq!(first.point, name);
    assert_eq!(audit[0].old_value, Some(serde_json::json!(old)));
    node.stop().await;
}

/// A plain MQTT client on `broker` subscribed to `filter`: its messages as (topic,
/// payload), and the client to publish with.
async fn plain_client(
    broker: &Mosquitto,
    filter: &str,
) -> (
    rumqttc::AsyncClient,
    tokio::sync::mpsc::UnboundedReceiver<(String, Vec<u8>)>,
) {
    let id = format!("plain-{}", fastrand::u64(..));
    let options = rumqttc::MqttOptions::new(id, "127.0.0.1", broker.port());
    let (client, mut eventloop) = rumqttc::AsyncClient::new(options, 100);
    let (tx, rx) = tokio::sync::mpsc::unbounded_channel();
    let (subscribed_tx, subscribed) = tokio::sync::oneshot::channel();
    let mut subscribed_tx = Some(subscribed_tx);
    client
        .subscribe(filter, rumqttc::QoS::AtLeastOnce)
        .await
        .unwrap();
    tokio::spawn(async move {
        while let Ok(event) = eventloop.poll().await {
            match event {
                rumqttc::Event::Incoming(rumqttc::Packet::SubAck(_)) => {
                    if let Some(tx) = subscribed_tx.take() {
                        let _ = tx.send(());
                    }
                }
                rumqttc::Event::Incoming(rumqttc::Packet::Publish(p)) => {
                    let _ = tx.send((p.topic, p.payload.to_vec()));
                }
                _ => {}
            }
        }
    });
    tokio::time::timeout(LIMIT, subscribed)
        .await
        .expect("subscribed")
        .unwrap();
    (client, rx)
}

/// The next message on `topic` with `payload`, within [`LIMIT`].
async fn next_on(
    messages: &mut tokio::sync::mpsc::UnboundedReceiver<(String, Vec<u8>)>,
    topic: &str,
    payload: &str,
) {
    tokio::time::timeout(LIMIT, async {
        while let Some((t, p)) = messages.recv().await {
            if t == topic && p == payload.as_bytes() {
                return;
            }
        }
        panic!("the client stopped");
    })
    .await
    .unwrap_or_else(|_| panic!("no {payload:?} on {topic} within {LIMIT:?}"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn json_mode_answers_another_clients_retained_status_and_point_values_with_the_truth() {
    let broker = Mosquitto::start();
    let rig = rig(1);
    let config = MqttConfig {
        mode: crate::northbound::mqtt::config::MqttMode::Json,
        prefix: "plant/cell".into(),
        check_retained: Duration::from_secs(1),
        ..config(&broker)
    };
    let (rogue, mut seen) = plain_client(&broker, "plant/cell/#").await;
    let node = Node::start(&rig, config, false);
    next_on(&mut seen, "plant/cell/status", "online").await;
    next_on(&mut seen, "plant/cell/jbc1/status", "online").await;

    for topic in ["plant/cell/status", "plant/cell/jbc1/status"] {
        rogue
            .publish(topic, rumqttc::QoS::AtLeastOnce, true, "offline")
            .await
            .unwrap();
        next_on(&mut seen, topic, "offline").await;
        next_on(&mut seen, topic, "online").await;
    }
    // Both counted (on a loaded machine the station may also time out and come back,
    // and an echo of the gateway's own older status is answered too: harmless). Waited
    // for: an "online" the gateway published at its start can reach the subscriber after
    // the one the test waited for, and stand in for an answer not sent yet.
    let status = super::mqtt::status::status(&rig.cell);
    until("both forged statuses answered", || {
        status.metrics.foreign_reasserted.get() >= 2
    })
    .await;
    // What a new subscriber finds retained is the truth.
    let (_, mut fresh) = plain_client(&broker, "plant/cell/status").await;
    next_on(&mut fresh, "plant/cell/status", "online").await;

    // A forged retained value of a point: the next check of the retained messages puts
    // it right.
    let (name, _, _) = writable_number(&rig);
    let topic = format!("plant/cell/jbc1/{name}");
    let forged = br#"{"t":1,"value":999999.0,"unit":null,"quality":"good"}"#;
    rogue
        .publish(topic.as_str(), rumqttc::QoS::AtLeastOnce, true, &forged[..])
        .await
        .unwrap();
    // The forgery, then the gateway's answer (the set point does not change by itself).
    tokio::time::timeout(LIMIT, async {
        let mut forgery_seen = false;
        while let Some((t, p)) = seen.recv().await {
            if t == topic && p == forged {
                forgery_seen = true;
            } else if t == topic && forgery_seen {
                return;
            }
        }
    })
    .await
    .expect("the forged value answered");
    let (_, mut fresh) = plain_client(&broker, &topic).await;
    let retained = tokio::time::timeout(LIMIT, fresh.recv())
        .await
        .expect("a retained message")
        .expect("the client runs");
    assert_ne!(retained.1, forged, "the truth is retained again");
    let truth: serde_json::Value = serde_json::from_slice(&retained.1).unwrap();
    assert_eq!(truth["quality"], "good", "{truth}");
    node.stop().await;
}

/// JSON mode: each alarm is a retained message on `{prefix}/alarms/{id}`, the alarm as
/// the API shows it, published at the start and again at each change.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn json_mode_publishes_each_alarm_retained_under_alarms_and_again_when_it_changes() {
    let broker = Mosquitto::start();
    let rig = rig(1);
    let config = MqttConfig {
        mode: crate::northbound::mqtt::config::MqttMode::Json,
        prefix: "plant/cell".into(),
        ..config(&broker)
    };
    let (_client, mut seen) = plain_client(&broker, "plant/cell/alarms/#").await;
    let node = Node::start(&rig, config, false);
    let topic = "plant/cell/alarms/jbc1.tool_error";
    let normal = alarm_on(&mut seen, topic, "normal").await;
    assert_eq!(normal["priority"], "high");
    rig.models[0]
        .lock()
        .set_tool_error(jbc::code::ToolError::HeaterMalfunction);
    let raised = alarm_on(&mut seen, topic, "unacknowledged").await;
    assert_eq!(raised["active"], true);
    assert_eq!(raised["value"], 3.0, "{raised}");
    node.stop().await;
}

/// The next alarm on `topic` in `state`, within [`LIMIT`].
async fn alarm_on(
    seen: &mut tokio::sync::mpsc::UnboundedReceiver<(String, Vec<u8>)>,
    topic: &str,
    state: &str,
) -> serde_json::Value {
    tokio::time::timeout(LIMIT, async {
        while let Some((t, payload)) = seen.recv().await {
            let alarm: serde_json::Value = serde_json::from_slice(&payload).unwrap();
            if t == topic && alarm["state"] == state {
                return alarm;
            }
        }
        panic!("the client stopped");
    })
    .await
    .unwrap_or_else(|_| panic!("no {state} alarm on {topic} within {LIMIT:?}"))
}
