use std::time::Duration;

use axum::body::Body;
use axum::http::{Request, StatusCode};
use tower::ServiceExt;

use super::*;
use crate::alarm::Priority;
use crate::alarm::limit::Limits;
use crate::store::EventFilter;
use crate::testing::rig;

fn t(ms: i64) -> Timestamp {
    Timestamp(1_800_000_000_000 + ms)
}

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

fn sealer_high() -> AlarmConfig {
    alarm_on(
        "sealer0.temperature",
        Limits {
            high: Some(180.0),
            deadband: 2.0,
            on_delay: Duration::from_secs(5),
            off_delay: Duration::from_secs(5),
            ..Limits::default()
        },
    )
}

#[test]
fn a_sealers_temperature_alarm_fires_after_its_on_delay_and_clears_past_its_deadband_after_its_off_delay()
 {
    let mut w = Watcher::new(vec![sealer_high()]);
    let point = PointId::parse("sealer0.temperature").unwrap();
    assert!(
        w.value(&point, Some(185.0), t(0)).is_empty(),
        "the on delay runs"
    );
    assert!(w.tick(t(4_999)).is_empty());
    let [raised] = w.tick(t(5_000)).try_into().unwrap();
    assert_eq!(raised.id, "sealer0.temperature:high");
    assert!(raised.active);
    assert_eq!((raised.value, raised.limit), (Some(185.0), 180.0));
    assert_eq!(raised.changes, [Change::Activated]);
    assert!(
        w.value(&point, Some(179.0), t(6_000)).is_empty(),
        "inside the deadband"
    );
    assert!(w.tick(t(20_000)).is_empty());
    assert!(
        w.value(&point, Some(170.0), t(21_000)).is_empty(),
        "the off delay runs"
    );
    let [cleared] = w.tick(t(26_000)).try_into().unwrap();
    assert!(!cleared.active);
    assert_eq!(cleared.value, Some(170.0));
    assert_eq!(cleared.changes, [Change::Cleared]);
}

#[test]
fn each_level_of_a_point_is_its_own_alarm_and_other_points_are_not_watched() {
    let config = alarm_on(
        "meter1.active_power",
        Limits {
            high: Some(180.0),
            high_high: Some(200.0),
            ..Limits::default()
        },
    );
    let mut w = Watcher::new(vec![config]);
    let point = PointId::parse("meter1.active_power").unwrap();
    let ids: Vec<String> = w
        .value(&point, Some(210.0), t(0))
        .into_iter()
        .map(|r| r.id)
        .collect();
    assert_eq!(
        ids,
        ["meter1.active_power:high_high", "meter1.active_power:high"]
    );
    let other = PointId::parse("meter1.voltage").unwrap();
    assert!(!w.watches(&other));
    assert!(w.value(&other, Some(1e9), t(0)).is_empty());
}

#[test]
fn a_point_that_loses_its_value_holds_its_alarm_as_it_was() {
    let config = alarm_on(
        "meter1.active_power",
        Limits {
            high: Some(180.0),
            ..Limits::default()
        },
    );
    let mut w = Watcher::new(vec![config]);
    let point = PointId::parse("meter1.active_power").unwrap();
    assert_eq!(w.value(&point, Some(190.0), t(0)).len(), 1);
    assert!(w.value(&point, None, t(1_000)).is_empty());
    assert!(w.tick(t(60_000)).is_empty());
    assert_eq!(w.value(&point, Some(100.0), t(61_000)).len(), 1);
}

/// Through the cell's change stream: a station's air below 50 °C raises a low alarm; the
/// tool switched on heats it, and the alarm clears. Both are events in the history.
#[tokio::test(start_paused = true)]
async fn a_limit_alarm_on_a_live_point_is_raised_and_cleared_as_events_in_the_history() {
    let rig = rig(1);
    let config = alarm_on(
        "jbc1.air_temperature",
        Limits {
            low: Some(50.0),
            deadband: 5.0,
            ..Limits::default()
        },
    );
    tokio::spawn(run(
        Arc::clone(&rig.cell),
        vec![config],
        rig.shutdown.subscribe(),
    ));
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
}
