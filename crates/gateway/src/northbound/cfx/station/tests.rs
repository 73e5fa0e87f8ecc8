use super::*;
use crate::event::fields;
use crate::point::DeviceId;
use serde_json::json;

const MINUTE: i64 = 60_000;

fn station() -> Station {
    Station::new(StationConfig {
        device: "placer1".into(),
        handle: Handle::new("Panasonic.BM221.placer1").unwrap(),
        zone: jiff::tz::TimeZone::UTC,
        points: crate::driver::panasonic::PRODUCTION_POINTS,
        heartbeat: Duration::from_secs(60),
    })
}

fn value(station: &mut Station, point: &str, value: Value, at: i64) -> Vec<Envelope> {
    station.feed(Input::Value {
        point,
        value: Some(&value),
        quality: Some(Quality::Good),
        at: Timestamp(at),
    })
}

fn device_event(
    station: &mut Station,
    kind: EventKind,
    fields: crate::event::Fields,
    at: i64,
) -> Vec<Envelope> {
    let event = Event {
        t: Timestamp(at),
        kind,
        line: None,
        device: Some(DeviceId::new("placer1").unwrap()),
        point: None,
        message: "R message".into(),
        fields,
    };
    station.feed(Input::Event(&event))
}

/// Feeder 12 ran out at step 87, nozzle 7 (R message E03).
fn parts_exhausted(station: &mut Station, at: i64) -> Vec<Envelope> {
    device_event(
        station,
        EventKind::DeviceEvent,
        fields([
            ("event", json!("parts_exhausted")),
            ("error_code", json!(3)),
            ("step", json!(87)),
            ("nozzle", json!(7)),
            ("feeder", json!(12)),
        ]),
        at,
    )
}

fn names(out: &[Envelope]) -> Vec<&'static str> {
    out.iter().map(|e| e.message.name()).collect()
}

fn body(envelope: &Envelope) -> serde_json::Value {
    envelope.to_json()["MessageBody"].clone()
}

#[test]
fn a_state_change_says_the_old_state_its_duration_and_the_fault_that_stopped_the_machine() {
    let mut s = station();
    let first = value(&mut s, "machine_state_code", Value::Number(1100.0), 0);
    assert_eq!(
        names(&first),
        ["CFX.ResourcePerformance.StationStateChanged"]
    );
    // The first state seen: what came before is not known.
    assert_eq!(body(&first[0])["OldState"], 6000);
    assert_eq!(body(&first[0])["OldStateDuration"], json!(null));
    assert!(value(&mut s, "machine_state_code", Value::Number(1100.0), 1000).is_empty());

    let fault = parts_exhausted(&mut s, 2 * MINUTE);
    assert_eq!(names(&fault), ["CFX.ResourcePerformance.FaultOccurred"]);
    let occurred = body(&fault[0])["Fault"].clone();
    assert_eq!(
        occurred["$type"],
        "CFX.Structures.SMTPlacement.SMTPlacementFault, CFX"
    );
    assert_eq!(occurred["PlacementFaultType"], "PartsExhaust");
    assert_eq!(occurred["FaultCode"], "E03");
    assert_eq!(occurred["ProgramStep"], 87);
    assert_eq!(occurred["MaterialLocation"]["LocationName"], "12");
    assert_eq!(occurred["HeadAndNozzle"]["HeadNozzleNumber"], 7);

    let stopped = value(
        &mut s,
        "machine_state_code",
        Value::Number(5500.0),
        2 * MINUTE,
    );
    let changed = body(&stopped[0]);
    assert_eq!(changed["OldState"], 1100);
    assert_eq!(changed["OldStateDuration"], "00:02:00");
    assert_eq!(changed["NewState"], 5500);
    assert_eq!(
        changed["RelatedFault"]["FaultOccurrenceId"],
        occurred["FaultOccurrenceId"]
    );

    // Recovery clears it, with the same occurrence id; running again has no fault.
    let cleared = device_event(
        &mut s,
        EventKind::DeviceEvent,
        fields([("event", json!("recovery_succeeded"))]),
        3 * MINUTE,
    );
    assert_eq!(names(&cleared), ["CFX.ResourcePerformance.FaultCleared"]);
    assert_eq!(
        body(&cleared[0])["FaultOccurrenceId"],
        occurred["FaultOccurrenceId"]
    );
    let running = value(
        &mut s,
        "machine_state_code",
        Value::Number(1100.0),
        3 * MINUTE,
    );
    assert_eq!(body(&running[0])["RelatedFault"], json!(null));
}

#[test]
fn a_finished_board_is_back_dated_work_started_and_work_completed_with_one_transaction() {
    let mut s = station();
    let program = value(&mut s, "program", Value::Text("MAINBOARD-A".into()), 0);
    assert_eq!(names(&program), ["CFX.Production.RecipeActivated"]);
    assert_eq!(body(&program[0])["RecipeName"], "MAINBOARD-A");
    assert!(value(&mut s, "program", Value::Text("MAINBOARD-A".into()), 10).is_empty());

    let board = device_event(
        &mut s,
        EventKind::DeviceEvent,
        fields([
            ("event", json!("board_finished")),
            ("board_time_s", json!(42.5)),
        ]),
        MINUTE,
    );
    assert_eq!(
        names(&board),
        ["CFX.Production.WorkStarted", "CFX.Production.WorkCompleted"]
    );
    let (started, completed) = (board[0].to_json(), board[1].to_json());
    assert_eq!(started["TimeStamp"], "1970-01-01T00:00:17.5000000+00:00");
    assert_eq!(completed["TimeStamp"], "1970-01-01T00:01:00.0000000+00:00");
    assert_eq!(
        started["MessageBody"]["TransactionID"],
        completed["MessageBody"]["TransactionID"]
    );
    assert_eq!(started["MessageBody"]["RecipeName"], "MAINBOARD-A");
    assert_eq!(completed["MessageBody"]["Result"], "Completed");
    assert_ne!(started["UniqueID"], completed["UniqueID"]);
}

#[test]
fn placements_are_counted_in_windows_of_at_most_ten_minutes_and_a_reset_counter_starts_again() {
    let mut s = station();
    assert!(value(&mut s, "parts_placed", Value::Number(1000.0), 0).is_empty());
    assert!(value(&mut s, "pickups", Value::Number(1010.0), 0).is_empty());
    assert!(value(&mut s, "parts_placed", Value::Number(1500.0), 5 * MINUTE).is_empty());
    assert!(value(&mut s, "pickups", Value::Number(1530.0), 5 * MINUTE).is_empty());
    // The machine's counters were reset: counting starts again from what it says.
    assert!(value(&mut s, "parts_placed", Value::Number(100.0), 8 * MINUTE).is_empty());
    let out = value(&mut s, "parts_placed", Value::Number(400.0), 10 * MINUTE);
    assert_eq!(
        names(&out),
        ["CFX.ResourcePerformance.SMTPlacement.ComponentsPlaced"]
    );
    let placed = body(&out[0]);
    assert_eq!(placed["StartTime"], "1970-01-01T00:00:00.0000000+00:00");
    assert_eq!(placed["EndTime"], "1970-01-01T00:10:00.0000000+00:00");
    assert_eq!(placed["TotalComponentsPlaced"], 300);
    assert_eq!(placed["TotalComponentsNotPlaced"], 220);
    // The next window starts where this one ended.
    assert!(value(&mut s, "parts_placed", Value::Number(500.0), 15 * MINUTE).is_empty());
    let next = s.feed(Input::Tick(Timestamp(20 * MINUTE)));
    let placed: Vec<_> = next
        .iter()
        .filter(|e| matches!(e.message, Message::ComponentsPlaced(_)))
        .collect();
    assert_eq!(placed.len(), 1);
    assert_eq!(body(placed[0])["TotalComponentsPlaced"], 100);
}

#[test]
fn a_machine_going_down_and_up_is_offline_then_online_with_how_long_and_heartbeats_carry_the_faults()
 {
    let mut s = station();
    let beat = s.feed(Input::Tick(Timestamp(0)));
    assert_eq!(names(&beat), ["CFX.Heartbeat"]);
    assert_eq!(body(&beat[0])["HeartbeatFrequency"], "00:01:00");
    assert!(s.feed(Input::Tick(Timestamp(30_000))).is_empty());

    let down = device_event(&mut s, EventKind::DeviceDown, fields([]), 40_000);
    assert_eq!(names(&down), ["CFX.ResourcePerformance.StationOffline"]);
    assert!(device_event(&mut s, EventKind::DeviceDown, fields([]), 45_000).is_empty());
    let up = device_event(
        &mut s,
        EventKind::DeviceUp,
        fields([]),
        40_000 + 23 * MINUTE,
    );
    assert_eq!(names(&up), ["CFX.ResourcePerformance.StationOnline"]);
    assert_eq!(body(&up[0])["OfflineDuration"], "00:23:00");

    device_event(
        &mut s,
        EventKind::DeviceEvent,
        fields([("event", json!("error_stop")), ("error_code", json!(30))]),
        25 * MINUTE,
    );
    let beat = s.feed(Input::Tick(Timestamp(26 * MINUTE)));
    let faults = body(&beat[0])["ActiveFaults"].clone();
    assert_eq!(faults.as_array().unwrap().len(), 1);
    assert_eq!(faults[0]["FaultCode"], "E30");
    assert_eq!(
        faults[0]["$type"],
        json!(null),
        "an error stop has no placement type"
    );
}

#[test]
fn the_same_history_fed_again_gives_the_same_messages_with_the_same_ids() {
    let run = || {
        let mut s = station();
        let mut out = value(&mut s, "machine_state_code", Value::Number(1100.0), 0);
        out.extend(device_event(
            &mut s,
            EventKind::DeviceEvent,
            fields([
                ("event", json!("board_finished")),
                ("board_time_s", json!(30)),
            ]),
            MINUTE,
        ));
        out.extend(device_event(
            &mut s,
            EventKind::DeviceDown,
            fields([]),
            2 * MINUTE,
        ));
        out
    };
    let (first, second) = (run(), run());
    assert_eq!(first, second);
    let ids: std::collections::HashSet<_> = first.iter().map(|e| e.unique_id).collect();
    assert_eq!(ids.len(), first.len(), "every message has its own id");
}

#[test]
fn bad_values_and_codes_cfx_does_not_have_change_nothing() {
    let mut s = station();
    assert!(value(&mut s, "machine_state_code", Value::Number(1234.0), 0).is_empty());
    assert!(value(&mut s, "machine_state_code", Value::Number(f64::NAN), 0).is_empty());
    assert!(value(&mut s, "machine_state_code", Value::Text("run".into()), 0).is_empty());
    let stale = s.feed(Input::Value {
        point: "machine_state_code",
        value: Some(&Value::Number(1100.0)),
        quality: Some(Quality::Bad),
        at: Timestamp(0),
    });
    assert!(stale.is_empty());
    assert!(value(&mut s, "parts_placed", Value::Number(-3.0), 0).is_empty());
    assert!(value(&mut s, "temperature", Value::Number(20.0), 0).is_empty());
}

#[test]
fn a_station_that_remembers_goes_on_as_the_one_before_the_restart_would_have() {
    let mut before = station();
    value(&mut before, "machine_state_code", Value::Number(1100.0), 0);
    value(&mut before, "program", Value::Text("BOARD-A".into()), 0);
    value(&mut before, "parts_placed", Value::Number(100.0), MINUTE);
    parts_exhausted(&mut before, 2 * MINUTE);
    device_event(&mut before, EventKind::DeviceDown, fields([]), 3 * MINUTE);

    // Kept as JSON (as the outbox keeps it) and taken up by a new station.
    let kept = serde_json::to_string(&before.memory()).unwrap();
    let mut after = station();
    after.remember(serde_json::from_str(&kept).unwrap());
    assert_eq!(after.memory(), before.memory());

    let later = |s: &mut Station| {
        let mut out = device_event(s, EventKind::DeviceUp, fields([]), 4 * MINUTE);
        out.extend(value(
            s,
            "program",
            Value::Text("BOARD-A".into()),
            4 * MINUTE,
        ));
        out.extend(device_event(
            s,
            EventKind::DeviceEvent,
            fields([("event", json!("recovery_succeeded"))]),
            5 * MINUTE,
        ));
        out.extend(value(
            s,
            "machine_state_code",
            Value::Number(2000.0),
            5 * MINUTE,
        ));
        out.extend(value(s, "parts_placed", Value::Number(160.0), 11 * MINUTE));
        out
    };
    let expected = later(&mut before);
    let got = later(&mut after);
    assert_eq!(got, expected);
    // The open fault is cleared, the state's duration runs from before the restart, the
    // program is not activated again and the window counts from its first count.
    assert_eq!(
        names(&got),
        [
            "CFX.ResourcePerformance.StationOnline",
            "CFX.ResourcePerformance.FaultCleared",
            "CFX.ResourcePerformance.StationStateChanged",
            "CFX.ResourcePerformance.SMTPlacement.ComponentsPlaced",
        ]
    );
    assert_eq!(body(&got[2])["OldStateDuration"], "00:05:00");
    assert_eq!(body(&got[3])["TotalComponentsPlaced"], 60);
}
