use std::collections::HashSet;

use super::*;
use crate::point::DeviceId;
use crate::testing::reading as value;
use panasonic::server::TwinServer;
use panasonic::status::StopMode;
use panasonic::{Machine, MachineConfig};

async fn rig() -> (PanasonicDriver, panasonic::server::RunningTwin) {
    let twin = twin().await;
    let driver = placer(twin.command_addr().port(), twin.event_addr().port(), None);
    (driver, twin)
}

/// A machine's twin served on two free loopback ports.
async fn twin() -> panasonic::server::RunningTwin {
    let any: std::net::SocketAddr = "127.0.0.1:0".parse().unwrap();
    TwinServer::bind(any, any, Machine::new(MachineConfig::default()).unwrap())
        .await
        .unwrap()
        .spawn()
        .unwrap()
}

/// `placer1`, its machine's ports on this host, its reply timeout `timeout`.
fn placer(command_port: u16, event_port: u16, timeout: Option<Duration>) -> PanasonicDriver {
    PanasonicDriver::new(&DriverConfig {
        states: Default::default(),
        timeout,
        settings: crate::config::Settings::new(Keys {
            event_port: Some(event_port),
        }),
        endpoint: Some(Endpoint::Tcp {
            host: "127.0.0.1".into(),
            port: command_port,
            line: None,
            framing: link::TcpFraming::Raw,
        }),
        ..DriverConfig::new(DeviceId::new("placer1").unwrap(), super::KIND)
    })
    .unwrap()
}

#[tokio::test]
async fn a_refused_event_port_leaves_the_commands_points_and_is_told_once_as_the_events_link() {
    let twin = twin().await;
    // A port nothing listens on: bound, then closed.
    let closed = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let wrong = closed.local_addr().unwrap().port();
    drop(closed);
    let mut driver = placer(twin.command_addr().port(), wrong, None);
    let readings = driver.poll(LIVE).await.expect("Port 1 answers");
    assert!(readings.iter().all(|r| r.value.is_ok()), "{readings:?}");
    let events = events_until(&mut driver, |events| {
        events.iter().any(|e| e.fields.get("link").is_some())
    })
    .await;
    let told: Vec<_> = events
        .iter()
        .filter(|e| e.fields.get("link").is_some())
        .collect();
    assert_eq!(told.len(), 1, "{events:?}");
    assert_eq!(told[0].fields["state"], "down");
    assert!(
        told[0].message.contains(&format!(":{wrong}"))
            && told[0].message.contains("the machine's commands go on")
            && told[0].message.contains("check `event_port`"),
        "{}",
        told[0].message
    );
}

#[tokio::test]
async fn a_port_2_notice_keeps_the_time_it_arrived_not_the_time_it_is_collected() {
    let (mut driver, _twin) = rig().await;
    let (tx, rx) = mpsc::unbounded_channel();
    driver.notices = Some(rx);
    let arrived = Timestamp(1_700_000_000_000);
    let notice = Notice::Unreadable {
        message: "R9XX".into(),
        reason: "not an R message of the manual".into(),
    };
    tx.send((arrived, notice)).unwrap();
    driver.drain_notices();
    let events = driver.take_events();
    assert_eq!(events.len(), 1, "{events:?}");
    assert_eq!(events[0].at, Some(arrived));
    assert_eq!(events[0].kind, EventKind::DeviceEvent);
}

/// Polls `live` and waits for the next Port 2 notice until `done` holds for the
/// collected events (real sockets: bounded generously, no sleeps).
async fn events_until(
    driver: &mut PanasonicDriver,
    done: impl Fn(&[DeviceEvent]) -> bool,
) -> Vec<DeviceEvent> {
    let mut events = Vec::new();
    for _ in 0..50 {
        driver.poll(LIVE).await.unwrap();
        events.extend(driver.take_events());
        if done(&events) {
            return events;
        }
        let rx = driver.notices.as_mut().expect("connected by the poll");
        let notice = tokio::time::timeout(Duration::from_secs(20), rx.recv())
            .await
            .expect("a notice within 20 s")
            .expect("the client runs");
        driver.record_notice(&notice.1, notice.0);
    }
    panic!("not seen in time: {events:?}");
}

#[test]
fn every_point_has_a_unique_id_and_none_is_writable() {
    let driver = PanasonicDriver::new(&DriverConfig::new(
        DeviceId::new("placer1").unwrap(),
        super::KIND,
    ))
    .unwrap();
    let points = driver.points();
    let ids: HashSet<_> = points.iter().map(|p| &p.id).collect();
    assert_eq!(ids.len(), points.len());
    assert!(points.iter().all(|p| p.writable.is_none()));
    let state = &points[0];
    assert_eq!(state.label(&Value::Number(2.0)), Some("error stop"));
    assert!(state.is_alarm(&Value::Number(2.0)));
    assert!(!state.is_alarm(&Value::Number(0.0)));
    assert!(check_address(Some(1)).unwrap_err().contains("no address"));
}

#[tokio::test]
async fn status_program_and_production_data_are_read_from_the_twin() {
    let (mut driver, _twin) = rig().await;
    let live = driver.poll(LIVE).await.unwrap();
    assert_eq!(value(&live, "state"), Ok(Value::Number(1.0)), "ready");
    assert_eq!(value(&live, "mode"), Ok(Value::Number(0.0)), "online");
    let program = driver.poll(PROGRAM).await.unwrap();
    assert!(matches!(value(&program, "program"), Ok(Value::Text(t)) if !t.is_empty()));
    let production = driver.poll(PRODUCTION).await.unwrap();
    assert_eq!(production.len(), COUNTERS.len() + RATES.len());
    assert!(production.iter().all(|r| r.value.is_ok()), "{production:?}");
}

#[tokio::test]
async fn r_messages_and_run_state_changes_become_events() {
    let (mut driver, twin) = rig().await;
    driver.poll(LIVE).await.unwrap();
    twin.control()
        .operator_start(Some(StopMode::Continuous))
        .unwrap();
    let events = events_until(&mut driver, |events| {
        events.iter().any(|e| e.kind == EventKind::StateChanged)
            && events.iter().any(|e| e.message.contains("R1ST"))
    })
    .await;
    let change = events
        .iter()
        .find(|e| e.kind == EventKind::StateChanged)
        .unwrap();
    assert_eq!(change.message, "machine went from ready to run");
    assert_eq!(change.point, Some("state"));
    assert_eq!(
        serde_json::Value::Object(change.fields.clone()),
        serde_json::json!({"from": "ready", "to": "run"})
    );
    twin.control().force_error(3).unwrap();
    let events = events_until(&mut driver, |events| {
        events
            .iter()
            .any(|e| e.message == "machine went from run to error stop")
    })
    .await;
    let error = events
        .iter()
        .find(|e| e.kind == EventKind::DeviceEvent && e.message.starts_with("R message R2E"))
        .unwrap_or_else(|| panic!("no R2E event: {events:?}"));
    // The error's facts, for programs: no need to parse the words.
    let fields = serde_json::Value::Object(error.fields.clone());
    assert_eq!(fields["event"], "parts_exhausted", "{fields}");
    assert_eq!(fields["error_code"], 3, "{fields}");
    assert!(fields["feeder"].is_u64(), "{fields}");
    // The next status answer is an E10 unscheduled stop for consumables, with the feeder.
    let live = driver.poll(LIVE).await.unwrap();
    assert_eq!(
        value(&live, "machine_state"),
        Ok(Value::Text("parts exhausted".into()))
    );
    assert_eq!(
        value(&live, "machine_state_code"),
        Ok(Value::Number(5500.0))
    );
    let reason = format!("feeder {}", fields["feeder"]);
    assert_eq!(
        value(&live, "machine_state_reason"),
        Ok(Value::Text(reason))
    );
}

#[test]
fn the_r_messages_before_a_status_answer_say_which_stop_the_machine_is_in() {
    use panasonic::event::ErrorInfo;
    let name = |(index, reason): (usize, Option<String>)| (MACHINE_STATES[index].name, reason);
    let mut told = Told::default();
    assert_eq!(name(told.state(RunState::Error)), ("error stop", None));
    told.note(&Event::Error(ErrorInfo::new(12, 1, 2, 3).unwrap()));
    assert_eq!(
        name(told.state(RunState::Error)),
        ("error stop", Some("error code 12, feeder 3".into()))
    );
    told.note(&Event::RecoveryStarted);
    assert_eq!(name(told.state(RunState::Error)), ("recovery", None));
    told.note(&Event::RecoveryStop);
    assert_eq!(name(told.state(RunState::Error)).0, "error stop");
    told.note(&Event::ResetDone);
    told.note(&Event::Se { program: None });
    assert_eq!(name(told.state(RunState::Ready)), ("setup", None));
    told.running();
    assert_eq!(name(told.state(RunState::Ready)), ("ready", None));
    assert_eq!(name(told.state(RunState::Run)), ("run", None));
}

#[test]
fn every_kinds_machine_states_have_codes_on_the_e10_scale_and_distinct_names() {
    for kind in crate::plugins::builtin().config.kinds() {
        let states = kind.machine_states();
        for s in states {
            let code = crate::production::StateCode::new(i64::from(s.code));
            assert!(code.is_ok(), "{kind}: {}: {code:?}", s.name);
        }
        let names: HashSet<_> = states.iter().map(|s| s.name).collect();
        assert_eq!(names.len(), states.len(), "{kind}");
    }
}

#[test]
fn r_messages_become_facts_with_their_numbers() {
    use panasonic::event::{BoardTime, ErrorInfo};
    let of = |event: &Event| serde_json::Value::Object(event_fields(event));
    assert_eq!(
        of(&Event::BoardFinished {
            time: Some(BoardTime::new(42).unwrap())
        }),
        serde_json::json!({"event": "board_finished", "board_time_s": 42})
    );
    assert_eq!(
        of(&Event::BoardFinished { time: None }),
        serde_json::json!({"event": "board_finished"}),
        "a time the machine did not give is left out"
    );
    assert_eq!(
        of(&Event::Error(ErrorInfo::new(3, 87, 7, 7).unwrap())),
        serde_json::json!({
            "event": "parts_exhausted", "error_code": 3, "step": 87, "nozzle": 7, "feeder": 7
        })
    );
    assert_eq!(
        of(&Event::Error(ErrorInfo::new(12, 1, 2, 3).unwrap()))["event"],
        "error_stop"
    );
    assert_eq!(
        of(&Event::RecoveryOk),
        serde_json::json!({"event": "recovery_succeeded"})
    );
}

#[tokio::test]
async fn a_machine_that_is_not_there_is_a_timeout_naming_its_port() {
    let closed = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = closed.local_addr().unwrap().port();
    drop(closed);
    let mut driver = placer(port, port, Some(Duration::from_secs(2)));
    let err = driver.poll(LIVE).await.unwrap_err();
    assert_eq!(err.kind, ErrorKind::Timeout, "{err}");
    // Port 2 refused alone would leave the commands going: the machine is down because
    // Port 1 is.
    assert!(err.message.contains("Port 1 (commands)"), "{err}");
}
