//! The plant API against a real PostgreSQL: point ids with groups and dots, the pages of
//! `/api/points`, the byte bound of `/api/events`.

use std::sync::Arc;
use std::time::{Duration, SystemTime};

use axum::body::Body;
use axum::http::{Request, StatusCode};
use historian::http::{AppState, router};
use historian::metrics::{Health, Metrics};
use historian::{Batch, EventRow, PointRow, Quality, SampleRow, Store};
use testkit::Postgres;
use tower::ServiceExt as _;

fn sample(group: &str, device: &str, point: &str, t: SystemTime, value: f64) -> SampleRow {
    SampleRow {
        group: group.into(),
        node: "cell1".into(),
        device: device.into(),
        point: point.into(),
        t,
        value: Some(value),
        text: None,
        quality: Quality::Good,
    }
}

fn event(t: SystemTime, message: String) -> EventRow {
    EventRow {
        group: "north".into(),
        node: "cell1".into(),
        device: None,
        point: None,
        line: None,
        t,
        kind: "alarm".into(),
        severity: 700,
        message,
        fields: None,
    }
}

async fn get(state: &Arc<AppState>, path: &str) -> (StatusCode, serde_json::Value) {
    let response = router(Arc::clone(state))
        .oneshot(Request::get(path).body(Body::empty()).unwrap())
        .await
        .unwrap();
    let status = response.status();
    let body = axum::body::to_bytes(response.into_body(), usize::MAX)
        .await
        .unwrap();
    let json = serde_json::from_slice(&body)
        .unwrap_or_else(|e| panic!("{path}: {e}: {}", String::from_utf8_lossy(&body)));
    (status, json)
}

/// The error of `path`, which must be refused as a bad request.
async fn refusal(state: &Arc<AppState>, path: &str) -> String {
    let (status, body) = get(state, path).await;
    assert_eq!(status, StatusCode::BAD_REQUEST, "{path}: {body}");
    body["error"]
        .as_str()
        .expect("an error in words")
        .to_owned()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn point_ids_name_one_point_or_say_which_and_the_listings_are_bounded() {
    let pg = Postgres::start();
    let url = pg.create_database("plant");
    let mut store = Store::connect(&url).await.expect("connect");
    let now = SystemTime::now() - Duration::from_secs(60);
    let points = [
        ("north", "jbc1", "air_temperature"),
        ("south", "jbc1", "air_temperature"),
        ("north", "meter.1", "power"),
        ("north", "meter", "1.power"),
        ("north", "meter.2", "power"),
    ];
    let batch = Batch {
        points: points
            .iter()
            .map(|(g, d, p)| PointRow::bare(g, "cell1", d, p))
            .collect(),
        samples: points
            .iter()
            .enumerate()
            .map(|(i, (g, d, p))| sample(g, d, p, now, i as f64))
            .collect(),
        // Two events of 3 MiB each: more than one answer may hold.
        events: (0..2u64)
            .map(|i| {
                let t = now + Duration::from_millis(i);
                event(t, format!("{i}{}", "x".repeat(3 << 20)))
            })
            .collect(),
    };
    store.write(&batch).await.expect("write");
    let state = Arc::new(AppState {
        url,
        reader: tokio::sync::Mutex::new(None),
        metrics: Arc::new(Metrics::new()),
        health: Arc::new(Health::new()),
    });

    let words = refusal(&state, "/api/history?point=cell1/jbc1.air_temperature").await;
    assert!(
        words.contains("names 2 points")
            && words.contains("\"north\"")
            && words.contains("\"south\"")
            && words.contains("GROUP/NODE/DEVICE.POINT"),
        "{words}"
    );
    for (group, value) in [("north", 0.0), ("south", 1.0)] {
        let path = format!("/api/history?point={group}/cell1/jbc1.air_temperature&from=-1h");
        let (status, body) = get(&state, &path).await;
        assert_eq!(status, StatusCode::OK, "{body}");
        assert_eq!(body["samples"][0]["value"], value, "{body}");
    }
    let words = refusal(&state, "/api/history?point=cell1/meter.1.power").await;
    assert!(words.contains("device id with a `.`"), "{words}");
    let (status, body) = get(&state, "/api/history?point=cell1/meter.2.power&from=-1h").await;
    assert_eq!(status, StatusCode::OK, "{body}");
    assert_eq!(body["samples"][0]["value"], 4.0, "{body}");
    let (status, _) = get(&state, "/api/history?point=cell1/meter.3.power").await;
    assert_eq!(status, StatusCode::NOT_FOUND);

    // Pages of points, each id in the form that names it.
    let (status, body) = get(&state, "/api/points?limit=2").await;
    assert_eq!(status, StatusCode::OK, "{body}");
    assert_eq!(body["total"], 5);
    let ids: Vec<&str> = body["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["id"].as_str().unwrap())
        .collect();
    assert_eq!(
        ids,
        [
            "north/cell1/jbc1.air_temperature",
            "south/cell1/jbc1.air_temperature"
        ]
    );
    let (_, rest) = get(&state, "/api/points?offset=2&node=cell1").await;
    assert_eq!(rest["points"].as_array().unwrap().len(), 3, "{rest}");
    let (_, none) = get(&state, "/api/points?node=cell9").await;
    assert_eq!(
        (
            none["total"].as_u64(),
            none["points"].as_array().map(Vec::len)
        ),
        (Some(0), Some(0))
    );
    for limit in ["0", "10001"] {
        let words = refusal(&state, &format!("/api/points?limit={limit}")).await;
        assert!(words.contains("1 to 10000"), "{words}");
    }

    // Events stop at 4 MiB, the newest first.
    let (status, body) = get(&state, "/api/events").await;
    assert_eq!(status, StatusCode::OK);
    let events = body["events"].as_array().unwrap();
    assert_eq!(events.len(), 1);
    assert!(events[0]["message"].as_str().unwrap().starts_with('1'));
    assert_eq!(events[0]["group"], "north");
    assert_eq!(body["truncated"], true);
    let words = refusal(&state, "/api/events?from=-1h&to=-2h").await;
    assert!(words.contains("must not be after"), "{words}");
}
