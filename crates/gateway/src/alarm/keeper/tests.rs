use std::time::Duration;

use axum::body::Body;
use axum::http::{Request, StatusCode};
use tower::ServiceExt;

use super::*;
use crate::alarm::Priority;
use crate::alarm::config::AlarmConfig;
use crate::alarm::limit::Limits;
use crate::point::PointId;
use crate::store::EventFilter;
use crate::testing::rig_with_alarms;

fn alarm_on(point: &str, limits: Limits) -> AlarmConfig {
    AlarmConfig {
        point: PointId::parse(point).unwrap(),
        limits,
        priority: Priority::High,
        message: Some("Band too hot".into()),
        category: None,
        chatter: None,
    }
}

/// Through the cell's change stream: a station's air below 50 °C raises a low alarm; the
/// tool switched on heats it, and the alarm clears. Both are events in the history.
#[tokio::test(start_paused = true)]
async fn a_limit_alarm_on_a_live_point_is_raised_and_cleared_as_events_in_the_history() {
    let config = alarm_on(
        "jbc1.air_temperature",
        Limits {
            low: Some(50.0),
            deadband: 5.0,
            ..Limits::default()
        },
    );
    let rig = rig_with_alarms(1, vec![config]);
    let events = |kind| {
        let store = rig.cell.store().clone();
        async move {
            store.flush().await.unwrap();
            store
                .events(&EventFilter {
                    kind: Some(kind),
                    device: Some("jbc1".into()),
                    limit: 10,
                    ..EventFilter::default()
                })
                .unwrap()
        }
    };
    let mut raised = Vec::new();
    for _ in 0..100 {
        raised = events(EventKind::AlarmRaised).await;
        if !raised.is_empty() {
            break;
        }
        tokio::time::sleep(Duration::from_millis(500)).await;
    }
    let [raised] = raised.as_slice() else {
        panic!("{raised:?}")
    };
    assert_eq!(raised.fields["alarm"], "jbc1.air_temperature:low");
    assert_eq!(raised.fields["priority"], "high");
    assert_eq!(raised.fields["changes"], serde_json::json!(["activated"]));
    assert!(
        raised
            .message
            .contains("Band too hot: low limit 50 °C crossed"),
        "{}",
        raised.message
    );
    // The gauges as /metrics shows them.
    let gauge = |name: &str| -> i64 {
        let text = rig.cell.metrics().encode(rig.cell.store().stats());
        let line = format!("cellbus_{name}{{priority=\"high\"}} ");
        let value = text
            .lines()
            .find_map(|l| l.strip_prefix(line.as_str()))
            .unwrap_or_else(|| panic!("no {line} in /metrics:\n{text}"));
        value.parse().unwrap()
    };
    assert_eq!(gauge("alarms_active"), 1);
    assert_eq!(gauge("alarms_unacknowledged"), 1);

    let app = crate::http::router(
        Arc::clone(&rig.cell),
        crate::http::WritePolicy {
            enabled: true,
            token: Some("t0ken".into()),
            read_token: None,
        },
        rig.shutdown.subscribe(),
    );
    for body in [
        r#"{"point": "air_temperature_setpoint", "value": 300}"#,
        r#"{"point": "tool_on", "value": "on"}"#,
    ] {
        let request = Request::post("/api/devices/jbc1/write")
            .header("content-type", "application/json")
            .header("authorization", "Bearer t0ken")
            .body(Body::from(body))
            .unwrap();
        let response = app.clone().oneshot(request).await.unwrap();
        assert_eq!(response.status(), StatusCode::OK, "{body}");
    }
    let mut cleared = Vec::new();
    for _ in 0..200 {
        cleared = events(EventKind::AlarmCleared).await;
        if !cleared.is_empty() {
            break;
        }
        tokio::time::sleep(Duration::from_millis(500)).await;
    }
    let [cleared] = cleared.as_slice() else {
        panic!("{cleared:?}")
    };
    assert_eq!(cleared.fields["alarm"], "jbc1.air_temperature:low");
    assert!(
        cleared.fields["value"].as_f64().unwrap() > 55.0,
        "{:?}",
        cleared.fields
    );
    assert!(
        cleared.message.contains("back within the low limit"),
        "{}",
        cleared.message
    );
    // Nobody acknowledged it: back to normal, still waiting for one (ISA-18.2).
    assert_eq!(gauge("alarms_active"), 0);
    assert_eq!(gauge("alarms_unacknowledged"), 1);
    let list = get(&app, "/api/alarms").await;
    assert_eq!(list["total"], 1, "{list}");
    assert_eq!(list["alarms"][0]["id"], "jbc1.air_temperature:low");
    assert_eq!(list["alarms"][0]["state"], "returned_unacknowledged");

    // Acknowledged from the API: journalled with who and why, and off the list.
    let ack = |id: &str, token: &str| {
        Request::post(format!("/api/alarms/{id}/ack"))
            .header("content-type", "application/json")
            .header("authorization", format!("Bearer {token}"))
            .body(Body::from(r#"{"by": "anna", "comment": "tool was off"}"#))
            .unwrap()
    };
    let (status, body) = call(&app, ack("jbc1.air_temperature:low", "wrong")).await;
    assert_eq!(status, StatusCode::UNAUTHORIZED, "{body}");
    let (status, body) = call(&app, ack("jbc9.nothing:high", "t0ken")).await;
    assert_eq!(status, StatusCode::NOT_FOUND, "{body}");
    assert!(
        body["error"]
            .as_str()
            .unwrap()
            .contains("no alarm \"jbc9.nothing:high\"")
    );
    let (status, body) = call(&app, ack("jbc1.air_temperature:low", "t0ken")).await;
    assert_eq!(status, StatusCode::OK, "{body}");
    assert_eq!(body["alarm"]["state"], "normal");
    let (status, body) = call(&app, ack("jbc1.air_temperature:low", "t0ken")).await;
    assert_eq!(status, StatusCode::CONFLICT, "{body}");
    assert!(
        body["error"]
            .as_str()
            .unwrap()
            .contains("already acknowledged (it is normal)"),
        "{body}"
    );
    assert_eq!(get(&app, "/api/alarms").await["total"], 0);
    let journal = get(&app, "/api/alarms/journal?alarm=jbc1.air_temperature:low").await;
    let entries = journal["entries"].as_array().unwrap();
    let kinds: Vec<&str> = entries
        .iter()
        .map(|e| e["kind"].as_str().unwrap())
        .collect();
    assert_eq!(kinds, ["alarm_changed", "alarm_cleared", "alarm_raised"]);
    assert_eq!(entries[0]["changes"], serde_json::json!(["acknowledged"]));
    assert_eq!(entries[0]["comment"], "tool was off");
    assert!(
        entries[0]["by"]
            .as_str()
            .unwrap()
            .starts_with("anna (http "),
        "{}",
        entries[0]
    );
    assert_eq!(entries[0]["state"], "normal");
    rig.shutdown.send(true).unwrap();
}

/// A GET answered 200, as JSON.
async fn get(app: &axum::Router, uri: &str) -> serde_json::Value {
    let (status, body) = call(app, Request::get(uri).body(Body::empty()).unwrap()).await;
    assert_eq!(status, StatusCode::OK, "{uri}: {body}");
    body
}

async fn call(app: &axum::Router, request: Request<Body>) -> (StatusCode, serde_json::Value) {
    let response = app.clone().oneshot(request).await.unwrap();
    let status = response.status();
    let bytes = axum::body::to_bytes(response.into_body(), 1 << 20)
        .await
        .unwrap();
    (status, serde_json::from_slice(&bytes).unwrap_or_default())
}

/// What the history kept of each alarm puts it back after a restart: a fault nobody
/// acknowledged still waits, a shelving still runs.
#[tokio::test(start_paused = true)]
async fn after_a_restart_the_alarms_are_as_the_journal_left_them() {
    let rig = rig_with_alarms(1, Vec::new());
    rig.models[0]
        .lock()
        .set_tool_error(jbc::code::ToolError::HeaterMalfunction);
    let raised = loop {
        let page = rig.cell.alarms.list(&crate::alarm::book::ListFilter {
            limit: 10,
            ..Default::default()
        });
        if let Some(alarm) = page.alarms.into_iter().find(|a| a.id == "jbc1.tool_error") {
            break alarm;
        }
        tokio::time::sleep(Duration::from_millis(500)).await;
    };
    assert_eq!(raised.state, crate::alarm::state::State::Unacknowledged);
    act(
        &rig.cell,
        "jbc1.tool_error",
        Action::Shelve(Duration::from_secs(3600)),
        "anna",
        Some("waiting for a heater"),
    )
    .await
    .unwrap();
    // A new book from the history alone, as `run` builds it at start.
    let saved = rig.cell.store().alarm_states().unwrap();
    let mut book = Book::new(
        &[],
        &[crate::alarm::book::DeviceAlarms {
            device: crate::point::DeviceId::new("jbc1").unwrap(),
            label: "jbc1".into(),
            rule_points: rig
                .cell
                .device_entry("jbc1")
                .unwrap()
                .points
                .iter()
                .filter(|p| p.alarm.is_some())
                .cloned()
                .collect(),
        }],
    );
    for (id, fields) in &saved {
        book.restore(id, fields, Timestamp::now());
    }
    let alarm = book
        .view(book.index_of("jbc1.tool_error").unwrap())
        .unwrap();
    assert_eq!(alarm.state, crate::alarm::state::State::Unacknowledged);
    assert!(alarm.active);
    assert!(alarm.shelved_until.unwrap() > Timestamp::now());
    rig.shutdown.send(true).unwrap();
}
