//! The scheduler against JBC station models on in-memory lines, with tokio's clock paused:
//! minutes of polling run in milliseconds and no test waits for real time.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use jbc::code::ToolError;

use super::*;
use crate::cell::{Cell, DeviceStatus};
use crate::store::{EventFilter, Series};
use crate::testing::rig;
use crate::testing::{point, value};

fn polls(cell: &Cell, device: &str, result: PollResult) -> u64 {
    cell.metrics().poll_count("bench", device, result)
}

fn status(cell: &Cell, device: &str) -> DeviceStatus {
    cell.device_entry(device).unwrap().read().status
}

/// Every sample of `id` the store holds, once what is queued is committed.
async fn recorded(cell: &Cell, id: &str) -> Vec<crate::store::HistorySample> {
    let store = cell.store();
    store.flush().await.unwrap();
    let history = store
        .history(&point(id), Timestamp(0), Timestamp(i64::MAX), None)
        .unwrap();
    let Series::Samples(samples) = history.series else {
        panic!("raw samples expected")
    };
    samples
}

/// The events of `cell` that `filter` picks, once what is queued is committed.
async fn events(cell: &Cell, filter: EventFilter) -> Vec<crate::store::EventRecord> {
    cell.store().flush().await.unwrap();
    cell.store().events(&filter).unwrap()
}

/// The backoff after each of the first `failures` failed polls of a device polled every
/// `period`, in seconds.
fn backoff_seconds(failures: u32, period: Duration) -> Vec<u64> {
    (1..=failures)
        .map(|f| backoff_delay(f, period).as_secs())
        .collect()
}

#[test]
fn backoff_doubles_from_two_seconds_up_to_ten() {
    let second = Duration::from_secs(1);
    assert_eq!(backoff_seconds(6, second), vec![2, 4, 8, 10, 10, 10]);
    assert_eq!(backoff_delay(u32::MAX, second), BACKOFF_CAP);
}

#[test]
fn a_device_polled_less_often_than_the_cap_is_backed_off_up_to_its_period() {
    let minute = Duration::from_secs(60);
    assert_eq!(backoff_seconds(7, minute), vec![2, 4, 8, 16, 32, 60, 60]);
}

#[tokio::test(start_paused = true)]
async fn a_silent_device_is_backed_off_while_its_neighbour_keeps_its_rate() {
    let rig = rig(2);
    rig.plugged[1].store(false, Ordering::SeqCst);
    tokio::time::sleep(Duration::from_secs(60)).await;

    // jbc1 reads its live group every second (plus the slower groups).
    let ok = polls(&rig.cell, "jbc1", PollResult::ok);
    assert!((60..=70).contains(&ok), "jbc1 polled {ok} times in 60 s");
    assert_eq!(polls(&rig.cell, "jbc1", PollResult::error), 0);
    // jbc2 is tried at 0, then after 2, 4, 8, 10, 10 and 10 s (plus 1.5 s per failed try).
    let failed = polls(&rig.cell, "jbc2", PollResult::error);
    assert!((6..=8).contains(&failed), "jbc2 tried {failed} times");
    assert_eq!(status(&rig.cell, "jbc2"), DeviceStatus::Down);
    let view = rig.cell.device("jbc2").unwrap();
    assert!(view.summary.next_try_at.is_some());
    assert!(view.next_try_in_ms.is_some_and(|ms| ms <= 10_000));
    assert_eq!(view.summary.error.unwrap().kind, ErrorKind::Timeout);
    assert!(
        view.points
            .iter()
            .all(|p| p.view.quality == Some(Quality::Bad))
    );

    // Plugged back in: answered at its next try and promoted at once (every group read).
    rig.plugged[1].store(true, Ordering::SeqCst);
    tokio::time::sleep(BACKOFF_CAP + Duration::from_secs(3)).await;
    assert_eq!(status(&rig.cell, "jbc2"), DeviceStatus::Up);
    assert!(
        rig.cell
            .device("jbc2")
            .unwrap()
            .summary
            .next_try_at
            .is_none()
    );
    assert_eq!(
        value(&rig.cell, "jbc2.model"),
        Some(Value::Text("JTSE".into()))
    );
    let before = polls(&rig.cell, "jbc2", PollResult::ok);
    tokio::time::sleep(Duration::from_secs(10)).await;
    let after = polls(&rig.cell, "jbc2", PollResult::ok);
    assert!(
        after - before >= 10,
        "jbc2 back at its rate: {}",
        after - before
    );

    let events = events(
        &rig.cell,
        EventFilter {
            device: Some("jbc2".into()),
            limit: 10,
            ..EventFilter::default()
        },
    )
    .await;
    let kinds: Vec<&str> = events.iter().map(|e| e.kind.as_str()).collect();
    // Its silence is also an alarm (`jbc2:down`), raised and cleared.
    assert_eq!(
        kinds,
        vec!["alarm_cleared", "device_up", "alarm_raised", "device_down"]
    );
    assert_eq!(events[2].fields["alarm"], "jbc2:down");
    assert!(
        events[3].message.contains("timeout"),
        "{}",
        events[3].message
    );
}

#[tokio::test(start_paused = true)]
async fn value_changes_are_stored_and_alarms_become_events() {
    let rig = rig(1);
    let mut live = rig.cell.subscribe();
    tokio::time::sleep(Duration::from_secs(3)).await;
    rig.models[0]
        .lock()
        .set_tool_error(ToolError::HeaterMalfunction);
    tokio::time::sleep(Duration::from_secs(2)).await;
    rig.models[0].lock().set_tool_error(ToolError::Ok);
    tokio::time::sleep(Duration::from_secs(2)).await;
    let samples = recorded(&rig.cell, "jbc1.tool_error").await;
    let store = rig.cell.store();
    let values: Vec<Option<Value>> = samples.into_iter().map(|s| s.value).collect();
    assert_eq!(
        values,
        vec![
            Some(Value::Number(0.0)),
            Some(Value::Number(3.0)),
            Some(Value::Number(0.0))
        ],
        "only changes are stored"
    );
    let events = store
        .events(&EventFilter {
            kind: None,
            device: Some("jbc1".into()),
            limit: 10,
            ..EventFilter::default()
        })
        .unwrap();
    let alarms: Vec<(&str, &str)> = events
        .iter()
        .map(|e| (e.kind.as_str(), e.message.as_str()))
        .collect();
    assert_eq!(
        alarms,
        vec![
            ("alarm_cleared", "Station jbc1: Tool error back to OK"),
            (
                "alarm_raised",
                "Station jbc1: Tool error is Heater malfunction: replace heater"
            ),
        ]
    );
    // The event stream saw the value change and the alarm.
    let mut saw_value = false;
    let mut saw_alarm = false;
    while let Ok(message) = live.try_recv() {
        match message {
            LiveMessage::Value(v) if v.id.as_str() == "jbc1.tool_error" => {
                saw_value |= v.value == Some(Value::Number(3.0))
            }
            LiveMessage::Event(e) => saw_alarm |= e.kind == EventKind::AlarmRaised,
            _ => {}
        }
    }
    assert!(saw_value && saw_alarm);
}

#[tokio::test(start_paused = true)]
async fn what_a_poll_read_before_the_line_failed_is_recorded_before_the_device_goes_down() {
    let rig = rig(1);
    tokio::time::sleep(Duration::from_millis(3500)).await;
    assert_eq!(status(&rig.cell, "jbc1"), DeviceStatus::Up);
    // Between two live polls: the tool error changes, and the line carries the replies of
    // the next poll up to the tool error's (read, then read again to confirm the change),
    // then nothing, as if the cable were pulled there.
    rig.models[0]
        .lock()
        .set_tool_error(ToolError::HeaterMalfunction);
    let live = crate::driver::jbc::group_reads()
        .into_iter()
        .find(|g| g.group == crate::driver::jbc::LIVE)
        .unwrap();
    let tool_error = live
        .codes
        .iter()
        .position(|c| *c == jbc::code::Code::PortError(jbc::code::Port::One))
        .unwrap();
    assert!(
        tool_error + 1 < live.codes.len(),
        "reads follow the tool error's"
    );
    rig.replies_left.store(tool_error + 2, Ordering::SeqCst);
    tokio::time::sleep(Duration::from_secs(3)).await;
    assert_eq!(status(&rig.cell, "jbc1"), DeviceStatus::Down);

    let samples = recorded(&rig.cell, "jbc1.tool_error").await;
    let values: Vec<(Option<Value>, Quality)> =
        samples.into_iter().map(|s| (s.value, s.quality)).collect();
    assert_eq!(
        values,
        vec![
            (Some(Value::Number(0.0)), Quality::Good),
            (Some(Value::Number(3.0)), Quality::Good),
            (None, Quality::Bad),
        ],
        "the value read before the line failed is kept, then the device is down"
    );
    let device = rig.cell.device_entry("jbc1").unwrap();
    let index = device.point_index("tool_error").unwrap();
    assert_eq!(device.read().points[index].quality, Some(Quality::Bad));
}

#[tokio::test(start_paused = true)]
async fn writes_go_out_between_polls_and_are_read_back() {
    let rig = rig(1);
    tokio::time::sleep(Duration::from_secs(2)).await;
    let setpoint = point("jbc1.air_temperature_setpoint");
    let outcome = rig
        .cell
        .write(&setpoint, &Value::Number(320.0))
        .await
        .unwrap();
    assert_eq!(outcome.new, Value::Number(320.0));
    assert!(outcome.old.is_some());
    assert_eq!(rig.models[0].lock().settings().air_temp, 320);
    tokio::time::sleep(Duration::from_millis(200)).await;
    assert_eq!(
        value(&rig.cell, "jbc1.air_temperature_setpoint"),
        Some(Value::Number(320.0))
    );

    let err = rig
        .cell
        .write(&setpoint, &Value::Number(900.0))
        .await
        .unwrap_err();
    assert!(matches!(err, WriteError::Invalid(_)), "{err}");
    assert_eq!(rig.models[0].lock().settings().air_temp, 320);
    let err = rig
        .cell
        .write(&point("jbc1.air_temperature"), &Value::Number(100.0))
        .await
        .unwrap_err();
    assert!(err.to_string().contains("read-only"), "{err}");
    let err = rig
        .cell
        .write(&point("jbc1.nothing"), &Value::Number(1.0))
        .await
        .unwrap_err();
    assert!(matches!(err, WriteError::UnknownPoint { .. }), "{err}");
}

#[tokio::test(start_paused = true)]
async fn a_line_that_cannot_be_opened_marks_its_devices_down_and_is_retried() {
    let rig = rig(1);
    // The task has not run yet: its first open fails.
    rig.line_available.store(false, Ordering::SeqCst);
    tokio::time::sleep(Duration::from_secs(10)).await;
    assert!(!rig.cell.lines()[0].state.open);
    assert_eq!(status(&rig.cell, "jbc1"), DeviceStatus::Down);
    let err = rig.cell.device("jbc1").unwrap().summary.error.unwrap();
    assert_eq!(err.kind, ErrorKind::Disconnected);
    assert!(
        err.message.contains("no such serial port"),
        "{}",
        err.message
    );
    let write = rig
        .cell
        .write(
            &point("jbc1.air_temperature_setpoint"),
            &Value::Number(300.0),
        )
        .await
        .unwrap_err();
    assert!(write.to_string().contains("not open"), "{write}");
    let attempts = rig.opens.load(Ordering::SeqCst);
    // 1, 2, 4 s between attempts: about 4 attempts in 10 s, not a busy loop.
    assert!((3..=6).contains(&attempts), "{attempts} attempts");
    rig.line_available.store(true, Ordering::SeqCst);
    tokio::time::sleep(REOPEN_MAX + Duration::from_secs(2)).await;
    assert!(rig.cell.lines()[0].state.open);
    assert_eq!(status(&rig.cell, "jbc1"), DeviceStatus::Up);
}

#[tokio::test(start_paused = true)]
async fn a_hung_line_session_is_reopened_after_every_device_timed_out_three_times() {
    let rig = rig(2);
    tokio::time::sleep(Duration::from_secs(5)).await;
    assert_eq!(status(&rig.cell, "jbc1"), DeviceStatus::Up);
    // The session hangs: the line stays open but nothing on it is heard.
    rig.sessions.lock().unwrap()[0].store(true, Ordering::SeqCst);
    tokio::time::sleep(Duration::from_secs(40)).await;
    assert_eq!(rig.opens.load(Ordering::SeqCst), 2, "reopened once");
    assert_eq!(status(&rig.cell, "jbc1"), DeviceStatus::Up);
    assert_eq!(status(&rig.cell, "jbc2"), DeviceStatus::Up);
    let reopens = rig
        .cell
        .metrics()
        .line_reopens_for_silence
        .get_or_create(&crate::metrics::LineLabels {
            line: "bench".into(),
        })
        .get();
    assert_eq!(reopens, 1);
    let events = events(
        &rig.cell,
        EventFilter {
            limit: 50,
            ..EventFilter::default()
        },
    )
    .await;
    let reopened: Vec<&str> = events
        .iter()
        .filter(|e| e.kind == "line_reopened")
        .map(|e| e.message.as_str())
        .collect();
    assert_eq!(reopened.len(), 1, "{events:?}");
    assert!(
        reopened[0].contains("every device on it timed out 3 times in a row"),
        "{}",
        reopened[0]
    );
}

#[tokio::test(start_paused = true)]
async fn a_line_whose_devices_are_all_off_is_reopened_less_and_less_often() {
    let rig = rig(1);
    rig.plugged[0].store(false, Ordering::SeqCst);
    tokio::time::sleep(Duration::from_secs(600)).await;
    let opens = rig.opens.load(Ordering::SeqCst);
    // Tries every 10 s at most: about 60 in 10 minutes. Reopens after 3, then 6, 12, 24
    // and 48 timeouts: 5 to 7 opens in all, not 20.
    assert!((4..=8).contains(&opens), "{opens} opens");
    // Back on: read again within the backoff cap (plus a try's timeouts).
    rig.plugged[0].store(true, Ordering::SeqCst);
    tokio::time::sleep(BACKOFF_CAP + Duration::from_secs(5)).await;
    assert_eq!(status(&rig.cell, "jbc1"), DeviceStatus::Up);
}

#[tokio::test(start_paused = true)]
async fn the_task_stops_when_asked() {
    let rig = rig(1);
    tokio::time::sleep(Duration::from_secs(1)).await;
    rig.shutdown.send(true).unwrap();
    tokio::time::timeout(Duration::from_secs(5), rig.task)
        .await
        .expect("the task ends promptly")
        .unwrap();
}

#[tokio::test(start_paused = true)]
async fn values_not_refreshed_in_time_turn_stale_and_good_again_at_the_next_read() {
    let rig = rig(1);
    tokio::time::sleep(Duration::from_secs(2)).await;
    let entry = rig.cell.device_entry("jbc1").unwrap();
    let index = entry.point_index("air_temperature").unwrap();
    // As if the line had not reached it for a minute.
    entry.write_state().points[index].t = Some(Timestamp::now().minus(Duration::from_secs(60)));
    let mut live = rig.cell.subscribe();
    mark_stale(&rig.cell, &entry);
    assert_eq!(entry.read().points[index].quality, Some(Quality::Stale));
    let LiveMessage::Value(view) = live.try_recv().unwrap() else {
        panic!("a value message")
    };
    assert_eq!(view.id.as_str(), "jbc1.air_temperature");
    assert_eq!(view.quality, Some(Quality::Stale));
    assert!(live.try_recv().is_err(), "only the old value went stale");

    tokio::time::sleep(Duration::from_secs(2)).await;
    assert_eq!(entry.read().points[index].quality, Some(Quality::Good));
    let mut back = false;
    while let Ok(message) = live.try_recv() {
        if let LiveMessage::Value(v) = message {
            back |= v.id.as_str() == "jbc1.air_temperature" && v.quality == Some(Quality::Good);
        }
    }
    assert!(back, "the return to good is published");
    let samples = recorded(&rig.cell, "jbc1.air_temperature").await;
    assert!(samples.iter().any(|s| s.quality == Quality::Stale));
}

#[tokio::test(start_paused = true)]
async fn a_line_closed_by_the_other_end_is_reopened_and_polling_resumes() {
    let rig = rig(1);
    tokio::time::sleep(Duration::from_secs(2)).await;
    assert_eq!(rig.opens.load(Ordering::SeqCst), 1);
    // The serial server drops the connection.
    for server in rig.servers.lock().unwrap().drain(..) {
        server.abort();
    }
    tokio::time::sleep(Duration::from_secs(5)).await;
    assert_eq!(rig.opens.load(Ordering::SeqCst), 2, "reopened once");
    assert!(rig.cell.lines()[0].state.open);
    assert_eq!(status(&rig.cell, "jbc1"), DeviceStatus::Up);
    let errors = rig
        .cell
        .metrics()
        .error_count("bench", "jbc1", "disconnected");
    assert_eq!(errors, 1);
    let kinds: Vec<String> = events(
        &rig.cell,
        EventFilter {
            limit: 20,
            ..EventFilter::default()
        },
    )
    .await
    .into_iter()
    .map(|e| e.kind)
    .collect();
    assert_eq!(
        kinds,
        vec![
            "alarm_cleared",
            "device_up",
            "line_up",
            "alarm_raised",
            "line_down",
            "device_down",
            "line_up"
        ],
        "newest first: the poll fails, the line goes down (the station's silence an alarm), \
         is reopened, the station answers"
    );
}

#[tokio::test(start_paused = true)]
async fn a_line_dropped_as_soon_as_it_opens_is_retried_less_and_less_often() {
    let rig = rig(1);
    tokio::time::sleep(Duration::from_secs(2)).await;
    assert_eq!(status(&rig.cell, "jbc1"), DeviceStatus::Up);
    // The serial server now takes every connection and closes it at once.
    rig.line_drops.store(true, Ordering::SeqCst);
    for server in rig.servers.lock().unwrap().drain(..) {
        server.abort();
    }
    tokio::time::sleep(Duration::from_secs(120)).await;
    let opens = rig.opens.load(Ordering::SeqCst);
    // 1, 1, 2, 4, 8, 16, 30, 30, 30 s: about 9 attempts in two minutes, not 120.
    assert!((5..=12).contains(&opens), "{opens} opens in two minutes");
    // The server works again: the station answers within the longest wait, and the
    // wait starts over, so the next loss is retried after a second.
    rig.line_drops.store(false, Ordering::SeqCst);
    tokio::time::sleep(REOPEN_MAX + Duration::from_secs(5)).await;
    assert_eq!(status(&rig.cell, "jbc1"), DeviceStatus::Up);
    let before = rig.opens.load(Ordering::SeqCst);
    for server in rig.servers.lock().unwrap().drain(..) {
        server.abort();
    }
    tokio::time::sleep(Duration::from_secs(3)).await;
    assert_eq!(rig.opens.load(Ordering::SeqCst), before + 1);
    assert_eq!(status(&rig.cell, "jbc1"), DeviceStatus::Up);
}

fn due(slot: usize, at: tokio::time::Instant, period_s: u64) -> Due {
    Due {
        slot,
        clock: 0,
        at,
        period: Duration::from_secs(period_s),
    }
}

#[tokio::test(start_paused = true)]
async fn while_the_line_keeps_up_the_group_due_first_goes_first() {
    let now = tokio::time::Instant::now();
    let soon = due(0, now + Duration::from_millis(300), 1);
    let later = due(1, now + Duration::from_millis(200), 60);
    let last = due(2, now + Duration::from_secs(5), 10);
    assert_eq!(most_urgent([soon, later, last], now), Some(later));
}

#[tokio::test(start_paused = true)]
async fn an_overdue_group_goes_before_one_not_yet_due() {
    let now = tokio::time::Instant::now() + Duration::from_secs(10);
    let overdue = due(0, now - Duration::from_millis(1), 60);
    let not_yet = due(1, now + Duration::from_millis(1), 1);
    assert_eq!(most_urgent([not_yet, overdue], now), Some(overdue));
}

#[tokio::test(start_paused = true)]
async fn on_an_overloaded_line_the_group_furthest_behind_its_period_goes_first() {
    let now = tokio::time::Instant::now() + Duration::from_secs(100);
    // Half a period behind a 1 s period outweighs two seconds behind a 10 s period.
    let live = due(0, now - Duration::from_millis(500), 1);
    let settings = due(1, now - Duration::from_secs(2), 10);
    assert_eq!(most_urgent([settings, live], now), Some(live));
    // Equally far behind: the earlier one.
    let a = due(2, now - Duration::from_secs(20), 10);
    let b = due(3, now - Duration::from_secs(2), 1);
    assert_eq!(most_urgent([b, a], now), Some(a));
    assert_eq!(most_urgent(std::iter::empty(), now), None);
}

#[tokio::test(start_paused = true)]
async fn an_overloaded_line_slows_every_group_by_the_same_factor() {
    // Forty stations on one line: their live groups (1 s) alone ask for more than the line
    // carries, so every group falls behind; the live group must keep the share its period
    // gives it over the settings group (10 s), not be served in turn with it.
    let rig = rig(40);
    tokio::time::sleep(Duration::from_secs(120)).await;
    let heard = rig.heard.lock().unwrap().clone();
    let count = |code: &[u8]| heard.windows(code.len()).filter(|w| *w == code).count();
    let (live, settings) = (count(b"RAT1"), count(b"RWM1"));
    assert!(
        live < 40 * 120 * 9 / 10,
        "the line was not overloaded: {live} live reads of 4800 due"
    );
    assert!(
        live >= 5 * settings.max(1),
        "live read {live} times, settings {settings} times"
    );
}

/// A cell of one JBC station whose numeric points have `deadband`; its line is never
/// opened, so only the readings a test applies reach it.
fn cell_with_deadband(deadband: Deadband) -> (Arc<Cell>, crate::store::Store, tempfile::TempDir) {
    cell_with(Some(deadband))
}

/// A cell of one JBC station, `jbc1`, with `deadband` on its numeric points.
fn cell_with(deadband: Option<Deadband>) -> (Arc<Cell>, crate::store::Store, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    let store =
        crate::store::Store::open(dir.path(), crate::store::StoreOptions::default()).unwrap();
    let mut device = crate::testing::device("jbc1", 1);
    device.deadband = deadband;
    let config = crate::config::CellConfig {
        lines: vec![crate::config::LineConfig {
            reopen_after_timeouts: 3,
            name: "bench".into(),
            endpoint: link::Endpoint::parse(
                "tcp://127.0.0.1:9",
                crate::driver::jbc::DEFAULT_SERIAL,
            )
            .unwrap(),
            devices: vec![device],
        }],
        ..crate::config::CellConfig::default()
    };
    let cell = crate::testing::unopened_cell(&config, &store);
    (cell, store, dir)
}

/// Applies `values` to jbc1.air_temperature one by one (`None`: a failed read) and
/// returns what was stored, what was published, and the live value at the end.
async fn record(
    deadband: Deadband,
    values: &[Option<f64>],
) -> (Vec<Option<Value>>, usize, Option<Value>) {
    let (cell, _store, _dir) = cell_with_deadband(deadband);
    let mut live = cell.subscribe();
    let entry = cell.device_entry("jbc1").unwrap();
    for value in values {
        let reading = Reading {
            point: point("jbc1.air_temperature"),
            value: match value {
                Some(v) => Ok(Value::Number(*v)),
                None => Err(DeviceError::new(ErrorKind::Timeout, "no answer")),
            },
        };
        apply_readings(&cell, &entry, vec![reading]);
    }
    let samples = recorded(&cell, "jbc1.air_temperature").await;
    let mut published = 0;
    while let Ok(message) = live.try_recv() {
        published += usize::from(matches!(message, LiveMessage::Value(_)));
    }
    (
        samples.into_iter().map(|s| s.value).collect(),
        published,
        value(&cell, "jbc1.air_temperature"),
    )
}

#[tokio::test]
async fn a_value_within_the_deadband_of_the_last_recorded_one_is_neither_stored_nor_published() {
    let (stored, published, live) = record(
        Deadband::Absolute(0.5),
        &[
            Some(230.0),
            Some(230.3),
            Some(230.6),
            Some(230.9),
            Some(230.4),
        ],
    )
    .await;
    // 230.3 is 0.3 from 230; 230.6 is 0.6 from it; 230.9 and 230.4 are within 0.5 of 230.6
    // (each compared with the last recorded value, not the last read).
    assert_eq!(
        stored,
        vec![Some(Value::Number(230.0)), Some(Value::Number(230.6))]
    );
    assert_eq!(published, 2);
    assert_eq!(
        live,
        Some(Value::Number(230.4)),
        "the live value stays exact"
    );
}

#[tokio::test]
async fn quality_changes_pass_the_deadband() {
    let (stored, _, live) = record(
        Deadband::Absolute(10.0),
        &[Some(230.0), None, Some(231.0), Some(232.0)],
    )
    .await;
    assert_eq!(
        stored,
        vec![Some(Value::Number(230.0)), None, Some(Value::Number(231.0))],
        "bad, then good again, are recorded whatever the value"
    );
    assert_eq!(live, Some(Value::Number(232.0)));
}

#[tokio::test]
async fn a_percent_deadband_is_a_share_of_the_last_recorded_value() {
    let (stored, _, _) = record(
        Deadband::Percent(1.0),
        &[Some(200.0), Some(201.5), Some(202.0), Some(203.9)],
    )
    .await;
    // 1 % of 200 is 2; then 1 % of 202 is 2.02.
    assert_eq!(
        stored,
        vec![Some(Value::Number(200.0)), Some(Value::Number(202.0))]
    );
}

#[test]
fn a_held_back_number_is_compared_with_the_one_recorded_and_text_with_the_last_value() {
    let band = Some(Deadband::Absolute(1.0));
    let text = |s: &str| Value::Text(s.to_owned());
    // Nothing recorded yet: anything is a change.
    assert!(moved_enough(None, None, &Value::Number(5.0), band));
    // 20.4 was read after 20.0 was recorded: 20.8 is still within the band of 20.0, 21.0
    // is not, whatever the last value read.
    let last = Value::Number(20.4);
    assert!(!moved_enough(
        Some(20.0),
        Some(&last),
        &Value::Number(20.8),
        band
    ));
    assert!(moved_enough(
        Some(20.0),
        Some(&last),
        &Value::Number(21.0),
        band
    ));
    // Without a band any other number is a change, the same one is not.
    assert!(moved_enough(
        Some(20.0),
        Some(&Value::Number(20.0)),
        &Value::Number(20.1),
        None
    ));
    assert!(!moved_enough(
        Some(20.0),
        Some(&Value::Number(20.0)),
        &Value::Number(20.0),
        None
    ));
    // Text is never held back: the last value is the one recorded.
    assert!(!moved_enough(None, Some(&text("P12")), &text("P12"), band));
    assert!(moved_enough(None, Some(&text("P12")), &text("P13"), band));
    // A number after text, and text after a number, are changes.
    assert!(moved_enough(
        None,
        Some(&text("P12")),
        &Value::Number(12.0),
        band
    ));
    assert!(moved_enough(
        Some(12.0),
        Some(&Value::Number(12.0)),
        &text("P12"),
        band
    ));
}

#[tokio::test]
async fn a_device_without_deadbands_keeps_no_list_of_them() {
    let (cell, _store, _dir) = cell_with(None);
    let entry = cell.device_entry("jbc1").unwrap();
    assert!(entry.deadbands.is_empty());
    assert!((0..entry.points.len()).all(|i| entry.deadband(i).is_none()));
    let band = Deadband::Absolute(2.0);
    let (cell, _store, _dir) = cell_with(Some(band));
    let entry = cell.device_entry("jbc1").unwrap();
    assert_eq!(entry.deadbands.len(), entry.points.len());
    let air = entry.point_index("air_temperature").unwrap();
    assert_eq!(entry.deadband(air), Some(band));
}
