//! The API through `tower::ServiceExt::oneshot` on the router (paused clock, in-memory
//! line), and over a real loopback socket for the event stream and client addresses.

use std::sync::Arc;
use std::time::Duration;

use axum::body::Body;
use axum::http::{Request, StatusCode};
use serde_json::{Value as Json, json};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tower::ServiceExt;

use super::write::constant_time_eq;
use super::*;
use crate::testing::{Rig, rig};

const TOKEN: &str = "s3cret-token";

fn app(rig: &Rig, enabled: bool) -> Router {
    app_with(rig, enabled, None)
}

fn app_with(rig: &Rig, enabled: bool, read_token: Option<&str>) -> Router {
    router(
        Arc::clone(&rig.cell),
        WritePolicy {
            enabled,
            token: Some(TOKEN.into()),
            read_token: read_token.map(str::to_owned),
        },
        rig.shutdown.subscribe(),
    )
}

async fn call(app: &Router, request: Request<Body>) -> (StatusCode, Json) {
    let response = app.clone().oneshot(request).await.unwrap();
    let status = response.status();
    let bytes = axum::body::to_bytes(response.into_body(), 16 << 20)
        .await
        .unwrap();
    let body = serde_json::from_slice(&bytes)
        .unwrap_or_else(|_| Json::String(String::from_utf8_lossy(&bytes).into_owned()));
    (status, body)
}

async fn get(app: &Router, uri: &str) -> (StatusCode, Json) {
    call(app, Request::get(uri).body(Body::empty()).unwrap()).await
}

fn write_request(device: &str, token: Option<&str>, body: &str) -> Request<Body> {
    let mut request = Request::post(format!("/api/devices/{device}/write"))
        .header("content-type", "application/json");
    if let Some(token) = token {
        request = request.header("authorization", format!("Bearer {token}"));
    }
    request.body(Body::from(body.to_owned())).unwrap()
}

/// A write to `jbc1` with the token.
async fn write_jbc1(app: &Router, body: &str) -> (StatusCode, Json) {
    call(app, write_request("jbc1", Some(TOKEN), body)).await
}

fn error_of(body: &Json) -> &str {
    body["error"]
        .as_str()
        .unwrap_or_else(|| panic!("no error field in {body}"))
}

/// Concrete URIs for the route patterns.
fn example_uri(path: &str) -> String {
    path.replace("{id}", "jbc1")
}

#[tokio::test(start_paused = true)]
async fn every_route_is_in_the_openapi_document_and_every_documented_path_is_a_route() {
    let rig = rig(1);
    let app = app(&rig, true);
    let doc: Json = serde_json::from_str(OPENAPI).unwrap();
    assert_eq!(doc["openapi"], "3.0.3");
    let paths = doc["paths"].as_object().unwrap();
    for (method, path) in API_ROUTES {
        let operation = &paths
            .get(*path)
            .unwrap_or_else(|| panic!("{path} is not in openapi.json"))[method.to_lowercase()];
        assert!(
            operation.is_object(),
            "{method} {path} is not in openapi.json"
        );
        assert!(
            operation["responses"].is_object(),
            "{method} {path} has no responses"
        );
        // The router has the route: whatever it answers, it is not the fallback.
        if *path == "/api/events/stream" {
            continue;
        }
        let request = Request::builder()
            .method(*method)
            .uri(example_uri(path))
            .header("content-type", "application/json")
            .body(Body::from("{}"))
            .unwrap();
        let (status, body) = call(&app, request).await;
        assert!(
            !body.to_string().contains("no route"),
            "{method} {path}: {status} {body}"
        );
    }
    let documented: usize = paths.values().map(|p| p.as_object().unwrap().len()).sum();
    assert_eq!(
        documented,
        API_ROUTES.len(),
        "openapi.json has routes the router lacks"
    );
    // Every $ref points at something that exists.
    let text = OPENAPI;
    for reference in text.split("\"$ref\": \"#/").skip(1) {
        let target = reference.split('"').next().unwrap();
        let mut node = &doc;
        for part in target.split('/') {
            node = &node[part];
        }
        assert!(!node.is_null(), "dangling $ref #/{target}");
    }
}

#[tokio::test(start_paused = true)]
async fn devices_show_points_with_value_unit_quality_and_time() {
    let rig = rig(1);
    let app = app(&rig, false);
    tokio::time::sleep(Duration::from_secs(2)).await;
    let (status, body) = get(&app, "/api/devices").await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(body["writes_enabled"], false);
    let device = &body["devices"][0];
    assert_eq!(device["id"], "jbc1");
    assert_eq!(device["status"], "up");
    assert_eq!(device["protocol"], "jbc");
    let points = device["points"].as_array().unwrap();
    let air = points
        .iter()
        .find(|p| p["id"] == "jbc1.air_temperature")
        .unwrap();
    assert_eq!(air["unit"], "°C");
    assert_eq!(air["quality"], "good");
    assert!(air["value"].is_number());
    assert!(air["t"].as_str().unwrap().ends_with('Z'));
    let tool = points
        .iter()
        .find(|p| p["id"] == "jbc1.connected_tool")
        .unwrap();
    assert_eq!(tool["text"], "JT");
    assert_eq!(tool["kind"]["type"], "enum");

    let (status, one) = get(&app, "/api/devices/jbc1").await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(one["id"], "jbc1");
    // Each key once: a JSON parser may keep either of two duplicates.
    let response = app
        .clone()
        .oneshot(
            Request::get("/api/devices/jbc1")
                .body(Body::empty())
                .unwrap(),
        )
        .await
        .unwrap();
    let raw = axum::body::to_bytes(response.into_body(), 16 << 20)
        .await
        .unwrap();
    let raw = String::from_utf8(raw.to_vec()).unwrap();
    assert_eq!(raw.matches("\"id\":\"jbc1\"").count(), 1, "{raw}");
    let (status, body) = get(&app, "/api/lines").await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(body["lines"][0]["name"], "bench");
    assert_eq!(body["lines"][0]["open"], true);
}

#[tokio::test(start_paused = true)]
async fn lines_can_be_asked_for_by_name() {
    let rig = rig(1);
    let app = app(&rig, false);
    let (status, named) = get(&app, "/api/lines?line=bench").await;
    assert_eq!(status, StatusCode::OK, "{named}");
    assert_eq!(named["lines"].as_array().unwrap().len(), 1);
    assert_eq!(named["lines"][0]["name"], "bench");
    let (status, body) = get(&app, "/api/lines?line=bench,nope").await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    assert!(error_of(&body).contains("\"nope\"; lines: bench"), "{body}");
    let (status, _) = get(&app, "/api/lines?colour=red").await;
    assert_eq!(status, StatusCode::BAD_REQUEST);
}

#[tokio::test(start_paused = true)]
async fn devices_can_be_filtered_by_line_and_id_cut_to_fields_and_paged() {
    let rig = rig(3);
    let app = app(&rig, false);
    tokio::time::sleep(Duration::from_secs(2)).await;
    let ids = |body: &Json| -> Vec<String> {
        body["devices"]
            .as_array()
            .unwrap()
            .iter()
            .map(|d| d["id"].as_str().unwrap().to_owned())
            .collect()
    };
    let (status, all) = get(&app, "/api/devices").await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(ids(&all), ["jbc1", "jbc2", "jbc3"]);
    assert_eq!(all["total"], 3);
    let line = all["devices"][0]["line"].as_str().unwrap().to_owned();

    let (_, some) = get(&app, "/api/devices?device=jbc3,jbc1").await;
    assert_eq!(ids(&some), ["jbc1", "jbc3"], "in the cell's order");
    let (_, on_line) = get(&app, &format!("/api/devices?line={line}")).await;
    assert_eq!(on_line["total"], 3);

    let (_, paged) = get(&app, "/api/devices?offset=1&limit=1").await;
    assert_eq!(ids(&paged), ["jbc2"]);
    assert_eq!(paged["total"], 3, "the total counts every match");
    let (status, none) = get(&app, "/api/devices?device=").await;
    assert_eq!(status, StatusCode::OK, "{none}");
    assert_eq!(none["total"], 0, "an empty list names no device");

    let (_, slim) = get(&app, "/api/devices?fields=status,line").await;
    let first = slim["devices"][0].as_object().unwrap();
    let mut keys: Vec<&str> = first.keys().map(String::as_str).collect();
    keys.sort_unstable();
    assert_eq!(keys, ["id", "line", "status"]);

    let (status, body) = get(&app, "/api/devices?line=nope").await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    assert!(body["error"].as_str().unwrap().contains(&line), "{body}");
    let (status, body) = get(&app, "/api/devices?device=jbc1,jbc9").await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    assert!(body["error"].as_str().unwrap().contains("jbc9"), "{body}");
    let (status, body) = get(&app, "/api/devices?fields=colour").await;
    assert_eq!(status, StatusCode::BAD_REQUEST);
    assert!(body["error"].as_str().unwrap().contains("colour"), "{body}");
    let (status, _) = get(&app, "/api/devices?limit=-1").await;
    assert_eq!(status, StatusCode::BAD_REQUEST);
}

#[tokio::test(start_paused = true)]
async fn an_unknown_device_in_a_large_cell_lists_the_first_twenty_and_the_count() {
    let rig = rig(25);
    let app = app(&rig, false);
    let (status, body) = get(&app, "/api/devices/nope").await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    // In the order of the listing (by id, as text).
    let mut ids: Vec<String> = (1..=25).map(|n| format!("jbc{n}")).collect();
    ids.sort();
    let first = &ids[..20];
    assert_eq!(
        error_of(&body),
        format!(
            "no device \"nope\"; devices: {}, … (25 in all; GET /api/devices?fields=line lists \
             them)",
            first.join(", ")
        )
    );
}

#[tokio::test(start_paused = true)]
async fn unknown_ids_and_routes_are_404_with_json_that_says_what_exists() {
    let rig = rig(1);
    let app = app(&rig, false);
    let (status, body) = get(&app, "/api/devices/nope").await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    assert_eq!(error_of(&body), "no device \"nope\"; devices: jbc1");
    // A long id, line or step is cut in the answer.
    let long = "x".repeat(5000);
    for (path, status) in [
        (format!("/api/devices/{long}"), StatusCode::NOT_FOUND),
        (format!("/api/devices?line={long}"), StatusCode::NOT_FOUND),
        (format!("/api/lines?line={long}"), StatusCode::NOT_FOUND),
        (
            format!("/api/history?point=jbc1.air_temperature&step={long}"),
            StatusCode::BAD_REQUEST,
        ),
    ] {
        let (got, body) = get(&app, &path).await;
        assert_eq!(got, status, "{path}: {body}");
        assert!(error_of(&body).len() < 300, "{path}: {body}");
    }
    let (status, body) = get(&app, "/api/nothing").await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    assert!(error_of(&body).contains("/api/openapi.json"));
    let (status, body) = call(
        &app,
        Request::delete("/api/devices").body(Body::empty()).unwrap(),
    )
    .await;
    assert_eq!(status, StatusCode::METHOD_NOT_ALLOWED);
    assert!(error_of(&body).contains("DELETE"));
    let (status, body) = get(&app, "/api/history?point=jbc1.nothing").await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    assert!(error_of(&body).contains("no point \"nothing\""), "{body}");
    let (status, _) = get(&app, "/api/history?point=zzz.air_temperature").await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    let (status, _) = get(&app, "/api/events?device=zzz").await;
    assert_eq!(status, StatusCode::NOT_FOUND);
}

#[tokio::test(start_paused = true)]
async fn malformed_queries_are_400_and_say_what_is_wrong() {
    let rig = rig(1);
    let app = app(&rig, false);
    for (uri, expected) in [
        ("/api/history", "give the point"),
        ("/api/history?point=jbc1", "<device>.<point>"),
        (
            "/api/history?point=jbc1.air_temperature&from=yesterday",
            "from: \"yesterday\" is not a time",
        ),
        (
            "/api/history?point=jbc1.air_temperature&from=-1h&to=-2h",
            "must be before",
        ),
        (
            "/api/history?point=jbc1.air_temperature&step=often",
            "step \"often\" is not a duration",
        ),
        (
            "/api/history?point=jbc1.air_temperature&colour=red",
            "unknown field `colour`",
        ),
        ("/api/events?kind=explosion", "kinds: gateway_started"),
        ("/api/events?limit=0", "limit 0 is out of range"),
        ("/api/events?limit=many", "bad query"),
        ("/api/audit?limit=100000", "1 to 10000"),
    ] {
        let (status, body) = get(&app, uri).await;
        assert_eq!(status, StatusCode::BAD_REQUEST, "{uri}: {body}");
        assert!(error_of(&body).contains(expected), "{uri}: {body}");
    }
}

#[tokio::test(start_paused = true)]
async fn a_history_query_from_before_1970_is_refused_not_a_panic() {
    let rig = rig(1);
    let app = app(&rig, false);
    let (status, body) = get(
        &app,
        "/api/history?point=jbc1.air_temperature&from=-100000d",
    )
    .await;
    assert_eq!(status, StatusCode::BAD_REQUEST, "{body}");
    assert_eq!(error_of(&body), "from: -100000d is before 1970-01-01");
}

#[tokio::test(start_paused = true)]
async fn every_time_parameter_outside_1970_to_9999_is_a_400_naming_the_parameter() {
    let rig = rig(1);
    let app = app(&rig, false);
    for (uri, expected) in [
        (
            "/api/history?point=jbc1.air_temperature&to=-100000d",
            "to: -100000d is before 1970-01-01",
        ),
        (
            "/api/history?point=jbc1.air_temperature&from=1970-01-01T00:00:00%2B01:00",
            "from: 1970-01-01T00:00:00+01:00 is before 1970-01-01",
        ),
        (
            "/api/history?point=jbc1.air_temperature&to=9999-12-31T23:59:59-01:00",
            "to: 9999-12-31T23:59:59-01:00 is after 9999-12-31",
        ),
        (
            "/api/events?from=-100000d",
            "from: -100000d is before 1970-01-01",
        ),
        (
            "/api/events?to=-100000d",
            "to: -100000d is before 1970-01-01",
        ),
    ] {
        let (status, body) = get(&app, uri).await;
        assert_eq!(status, StatusCode::BAD_REQUEST, "{uri}: {body}");
        assert_eq!(error_of(&body), expected, "{uri}");
    }
}

#[tokio::test(start_paused = true)]
async fn a_history_query_ending_at_the_epoch_is_refused_without_reaching_before_it() {
    let rig = rig(1);
    let app = app(&rig, false);
    // Without `from`, the range would start an hour before `to`: before 1970.
    let (status, body) = get(
        &app,
        "/api/history?point=jbc1.air_temperature&to=1970-01-01T00:00:00Z",
    )
    .await;
    assert_eq!(status, StatusCode::BAD_REQUEST, "{body}");
    assert_eq!(
        error_of(&body),
        "from (1970-01-01T00:00:00.000Z) must be before to (1970-01-01T00:00:00.000Z)"
    );
    let (status, body) = get(
        &app,
        "/api/history?point=jbc1.air_temperature&to=1970-01-01T00:30:00Z",
    )
    .await;
    assert_eq!(status, StatusCode::OK, "{body}");
}

#[tokio::test(start_paused = true)]
async fn history_gives_changes_and_buckets_and_events_list_what_happened() {
    let rig = rig(1);
    let app = app(&rig, true);
    tokio::time::sleep(Duration::from_secs(1)).await;
    rig.models[0]
        .lock()
        .set_tool_error(jbc::code::ToolError::AirPump);
    tokio::time::sleep(Duration::from_secs(2)).await;
    rig.cell.store().flush().await.unwrap();

    let (status, body) = get(&app, "/api/history?point=jbc1.tool_error&from=-1h").await;
    assert_eq!(status, StatusCode::OK, "{body}");
    let values: Vec<&Json> = body["samples"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| &s["value"])
        .collect();
    assert_eq!(values, vec![&json!(0.0), &json!(1.0)]);
    let (status, body) = get(
        &app,
        "/api/history?point=jbc1.tool_error&from=-1h&to=now&step=1h",
    )
    .await;
    assert_eq!(status, StatusCode::OK, "{body}");
    let buckets = body["buckets"].as_array().unwrap();
    let count: u64 = buckets.iter().map(|b| b["count"].as_u64().unwrap()).sum();
    assert_eq!(count, 2);
    assert_eq!(body["step_ms"], 3_600_000);

    let (status, body) = get(&app, "/api/events?kind=alarm_raised&device=jbc1").await;
    assert_eq!(status, StatusCode::OK);
    let events = body["events"].as_array().unwrap();
    assert_eq!(events.len(), 1);
    assert_eq!(events[0]["point"], "jbc1.tool_error");
    assert!(
        events[0]["message"]
            .as_str()
            .unwrap()
            .contains("Air pump malfunction")
    );
}

#[tokio::test(start_paused = true)]
async fn metrics_and_health_report_polls_and_history() {
    let rig = rig(1);
    let app = app(&rig, false);
    tokio::time::sleep(Duration::from_secs(3)).await;
    rig.cell.store().flush().await.unwrap();
    let response = app
        .clone()
        .oneshot(Request::get("/metrics").body(Body::empty()).unwrap())
        .await
        .unwrap();
    assert_eq!(response.status(), StatusCode::OK);
    assert!(
        response.headers()["content-type"]
            .to_str()
            .unwrap()
            .starts_with("application/openmetrics-text")
    );
    let text = String::from_utf8(
        axum::body::to_bytes(response.into_body(), 1 << 20)
            .await
            .unwrap()
            .to_vec(),
    )
    .unwrap();
    for expected in [
        r#"cellbus_polls_total{line="bench",device="jbc1",result="ok"}"#,
        r#"cellbus_poll_duration_seconds_count{line="bench"}"#,
        r#"cellbus_line_busy_seconds_total{line="bench"}"#,
        r#"cellbus_device_up{line="bench",device="jbc1"} 1"#,
        "cellbus_history_rows_written_total",
    ] {
        assert!(text.contains(expected), "missing {expected} in\n{text}");
    }
    // A healthy device's failure counters are not there until it fails (a thousand
    // devices' zeros would be most of the page).
    assert!(!text.contains("cellbus_errors_total{"), "{text}");
    let (status, body) = get(&app, "/healthz").await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(body["status"], "ok");
    assert_eq!(body["devices_up"], 1);
    assert!(body["history_rows_written"].as_u64().unwrap() > 0);
}

#[tokio::test(start_paused = true)]
async fn writes_need_the_switch_and_the_token_and_every_attempt_is_audited() {
    let rig = rig(1);
    tokio::time::sleep(Duration::from_secs(2)).await;
    let off = app(&rig, false);
    let on = app(&rig, true);
    let body = r#"{"point": "air_temperature_setpoint", "value": 333}"#;

    let (status, reply) = write_jbc1(&off, body).await;
    assert_eq!(status, StatusCode::FORBIDDEN);
    assert!(error_of(&reply).contains("--allow-writes"));
    let (status, reply) = call(&on, write_request("jbc1", None, body)).await;
    assert_eq!(status, StatusCode::UNAUTHORIZED);
    assert!(error_of(&reply).contains("Bearer"));
    let (status, _) = call(&on, write_request("jbc1", Some("guess"), body)).await;
    assert_eq!(status, StatusCode::UNAUTHORIZED);
    let (status, reply) = write_jbc1(
        &on,
        r#"{"point": "air_temperature_setpoint", "value": 999}"#,
    )
    .await;
    assert_eq!(status, StatusCode::BAD_REQUEST);
    assert!(error_of(&reply).contains("150 to 450 °C"), "{reply}");
    let (status, reply) = write_jbc1(&on, "{not json").await;
    assert_eq!(status, StatusCode::BAD_REQUEST);
    assert!(error_of(&reply).contains("bad request body"), "{reply}");
    let (status, reply) = write_jbc1(&on, r#"{"point": "air_temperature", "value": 1}"#).await;
    assert_eq!(status, StatusCode::BAD_REQUEST);
    assert!(error_of(&reply).contains("read-only"), "{reply}");
    let (status, reply) = write_jbc1(&on, r#"{"point": "warp_drive", "value": 1}"#).await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    assert!(
        error_of(&reply).contains("writable points: air_temperature_setpoint"),
        "{reply}"
    );
    let (status, _) = call(&on, write_request("nope", Some(TOKEN), body)).await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    assert_ne!(
        rig.models[0].lock().settings().air_temp,
        333,
        "nothing reached the station"
    );

    let (status, reply) = write_jbc1(&on, body).await;
    assert_eq!(status, StatusCode::OK, "{reply}");
    assert_eq!(reply["new"], 333.0);
    assert_eq!(rig.models[0].lock().settings().air_temp, 333);
    let (status, reply) = write_jbc1(&on, r#"{"point": "jbc1.tool_on", "value": "on"}"#).await;
    assert_eq!(status, StatusCode::OK, "{reply}");
    assert!(
        reply["detail"]
            .as_str()
            .unwrap()
            .contains("set to on (was off)"),
        "{reply}"
    );
    assert!(rig.models[0].lock().port_status().tool_on);

    let (status, audit) = get(&on, "/api/audit?device=jbc1").await;
    assert_eq!(status, StatusCode::OK);
    let rows = audit["audit"].as_array().unwrap();
    let results: Vec<&str> = rows.iter().map(|r| r["result"].as_str().unwrap()).collect();
    // Refusals without a valid token are counted, not stored; each valid write is
    // recorded as attempted before the wire, then with its result.
    assert_eq!(
        results,
        vec![
            "accepted",
            "attempted",
            "accepted",
            "attempted",
            "refused",
            "refused",
            "refused",
            "refused"
        ]
    );
    let accepted = &rows[2];
    assert_eq!(accepted["point"], "jbc1.air_temperature_setpoint");
    assert_eq!(accepted["new_value"], 333);
    assert!(accepted["old_value"].is_number());
    assert_eq!(rows[3]["point"], "jbc1.air_temperature_setpoint");
    let (_, all) = get(&on, "/api/audit").await;
    assert_eq!(
        all["audit"].as_array().unwrap().len(),
        9,
        "an authorised write to an unknown device is audited too"
    );
    let unauthorised = rig.cell.metrics().writes_of("unauthorised");
    assert_eq!(unauthorised, 3, "writes off, no token, wrong token");
    let (_, events) = get(&on, "/api/events?kind=write").await;
    assert_eq!(events["events"].as_array().unwrap().len(), 2);
}

#[tokio::test]
async fn a_token_in_the_query_is_ignored_where_the_gateway_needs_none() {
    let rig = rig(1);
    let app = app(&rig, false);
    let (status, body) = get(&app, "/api/events?token=look-only&limit=5").await;
    assert_eq!(status, StatusCode::OK, "{body}");
}

#[tokio::test]
async fn a_reversed_range_of_events_is_refused_as_a_reversed_history_range_is() {
    let rig = rig(1);
    let app = app(&rig, false);
    for uri in [
        "/api/events?from=now&to=-1h",
        "/api/history?point=jbc1.tool_on&from=now&to=-1h",
    ] {
        let (status, body) = get(&app, uri).await;
        assert_eq!(status, StatusCode::BAD_REQUEST, "{uri}: {body}");
        assert!(error_of(&body).starts_with("from ("), "{uri}: {body}");
    }
}

#[tokio::test]
async fn a_device_path_that_is_not_utf8_is_refused_in_json_like_everything_else() {
    let rig = rig(1);
    let app = app(&rig, true);
    for uri in ["/api/devices/%ff", "/api/devices/%ff/write"] {
        let request = if uri.ends_with("write") {
            Request::post(uri)
        } else {
            Request::get(uri)
        };
        let (status, body) = call(&app, request.body(Body::empty()).unwrap()).await;
        assert_eq!(status, StatusCode::BAD_REQUEST, "{uri}: {body}");
        assert!(
            error_of(&body).starts_with("the device id in the path is not one: "),
            "{uri}: {body}"
        );
    }
}

#[tokio::test]
async fn a_query_whose_client_hung_up_keeps_its_turn_until_it_ends() {
    let rig = rig(1);
    let turns = Arc::new(tokio::sync::Semaphore::new(1));
    let (started, running) = tokio::sync::oneshot::channel::<()>();
    let (release, wait) = std::sync::mpsc::channel::<()>();
    let client = tokio::spawn({
        let turns = Arc::clone(&turns);
        let store = rig.cell.store().clone();
        async move {
            super::run_query_on(&turns, store, move |_| {
                let _ = started.send(());
                let _ = wait.recv();
                Ok(())
            })
            .await
        }
    });
    running.await.expect("the query starts");
    // The client hangs up: hyper drops the handler's future.
    client.abort();
    assert!(client.await.unwrap_err().is_cancelled());
    assert_eq!(
        turns.available_permits(),
        0,
        "the query still runs, so it still holds its turn"
    );
    release.send(()).unwrap();
    let turn = tokio::time::timeout(Duration::from_secs(60), turns.acquire())
        .await
        .expect("the turn comes back when the query ends");
    drop(turn);
}

/// Paused time lets the 10 s body timeout pass at once; the bound on each answer is in real
/// time. (The refusal's audit row is committed by the history writer, a thread of its own;
/// while the runtime waits for it, paused time runs on from poll to poll, so a bound in
/// paused time would trip on a slow machine.)
#[test]
fn a_write_whose_body_never_comes_holds_no_connection() {
    let ended = testkit::ends_within_paused(Duration::from_secs(120), || async {
        let rig = rig(1);
        // Headers that announce a body, and no body.
        let head = |token: &str| {
            format!(
                "POST /api/devices/jbc1/write HTTP/1.1\r\nHost: test\r\nConnection: close\r\n\
                 Authorization: Bearer {token}\r\nContent-Type: application/json\r\n\
                 Content-Length: 4000\r\n\r\n"
            )
        };
        // Writes off, or a wrong token: refused before the body is read.
        let off = serve_on_loopback(app(&rig, false)).await;
        let response = raw_http(off, &head(TOKEN)).await;
        assert!(response.starts_with("HTTP/1.1 403"), "{response}");
        let on = serve_on_loopback(app(&rig, true)).await;
        let response = raw_http(on, &head("wrong")).await;
        assert!(response.starts_with("HTTP/1.1 401"), "{response}");
        // Authorised: the body has BODY_TIMEOUT to arrive, and the attempt is audited.
        let started = tokio::time::Instant::now();
        let response = raw_http(on, &head(TOKEN)).await;
        assert!(response.starts_with("HTTP/1.1 408"), "{response}");
        assert!(
            response.contains("did not arrive within 10 s"),
            "{response}"
        );
        let waited = started.elapsed();
        assert!(waited >= super::write::BODY_TIMEOUT, "{waited:?}");
        // The refusal's audit row is committed before the answer.
        let rows = rig.cell.store().audit_log(Some("jbc1"), 10).unwrap();
        assert_eq!(rows.len(), 1, "{rows:?}");
    });
    assert!(
        ended.is_some(),
        "every answer within 2 minutes, not a connection held open"
    );
}

/// Sends one request over a real socket and returns the raw response.
async fn raw_http(addr: SocketAddr, request: &str) -> String {
    let mut stream = tokio::net::TcpStream::connect(addr).await.unwrap();
    stream.write_all(request.as_bytes()).await.unwrap();
    let mut response = String::new();
    stream.read_to_string(&mut response).await.unwrap();
    response
}

async fn serve_on_loopback(app: Router) -> SocketAddr {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    tokio::spawn(async move {
        axum::serve(
            listener,
            app.into_make_service_with_connect_info::<SocketAddr>(),
        )
        .await
        .unwrap();
    });
    addr
}

#[tokio::test]
async fn the_event_stream_starts_with_a_snapshot_and_carries_live_values_over_a_socket() {
    let rig = rig(1);
    let addr = serve_on_loopback(app(&rig, true)).await;
    let mut stream = tokio::net::TcpStream::connect(addr).await.unwrap();
    stream
        .write_all(b"GET /api/events/stream HTTP/1.1\r\nHost: test\r\n\r\n")
        .await
        .unwrap();
    let mut seen = String::new();
    let deadline = tokio::time::Instant::now() + Duration::from_secs(20);
    let mut buf = [0u8; 8192];
    while !(seen.contains("event: snapshot") && seen.contains("event: value")) {
        let n = tokio::time::timeout_at(deadline, stream.read(&mut buf))
            .await
            .expect("snapshot and a value within 20 s")
            .unwrap();
        assert!(n > 0, "the stream closed early: {seen}");
        seen.push_str(&String::from_utf8_lossy(&buf[..n]));
    }
    assert!(seen.starts_with("HTTP/1.1 200 OK"), "{seen}");
    assert!(seen.contains("text/event-stream"), "{seen}");
    assert!(seen.contains("\"type\":\"value\""), "{seen}");
    assert_eq!(rig.cell.metrics().sse_clients.get(), 1);
    // Shutdown ends the stream, so a graceful stop is not held up by open pages.
    rig.shutdown.send(true).unwrap();
    // The chunked body ends (the connection itself is closed by the server's graceful stop).
    let deadline = tokio::time::Instant::now() + Duration::from_secs(20);
    while !seen.ends_with("0\r\n\r\n") {
        let n = tokio::time::timeout_at(deadline, stream.read(&mut buf))
            .await
            .expect("the stream ends at shutdown")
            .unwrap();
        assert!(n > 0, "closed without ending the body");
        seen.push_str(&String::from_utf8_lossy(&buf[..n]));
    }
}

/// The events of a stream answer, each as (name, data), until `enough` says so.
async fn sse_events(
    response: axum::response::Response,
    enough: impl Fn(&[(String, Json)]) -> bool,
) -> Vec<(String, Json)> {
    let mut body = response.into_body().into_data_stream();
    let mut text = String::new();
    let mut events = Vec::new();
    let deadline = tokio::time::Instant::now() + Duration::from_secs(20);
    while !enough(&events) {
        let chunk = tokio::time::timeout_at(deadline, body.next())
            .await
            .unwrap_or_else(|_| panic!("20 s and still not enough: {events:?}"))
            .expect("the stream goes on")
            .unwrap();
        text.push_str(&String::from_utf8_lossy(&chunk));
        while let Some((event, rest)) = text.split_once("\n\n") {
            let field = |name: &str| {
                event
                    .lines()
                    .find_map(|l| l.strip_prefix(name))
                    .unwrap_or_default()
                    .to_owned()
            };
            let data = serde_json::from_str(&field("data: ")).unwrap_or(Json::Null);
            events.push((field("event: "), data));
            text = rest.to_owned();
        }
    }
    events
}

#[tokio::test]
async fn an_event_stream_for_some_devices_carries_only_their_snapshot_and_changes() {
    let rig = rig(3);
    let app = app(&rig, false);
    let open = |uri: &str| {
        app.clone()
            .oneshot(Request::get(uri).body(Body::empty()).unwrap())
    };

    let response = open("/api/events/stream?device=jbc2").await.unwrap();
    assert_eq!(response.status(), StatusCode::OK);
    let values = |events: &[(String, Json)]| {
        events
            .iter()
            .filter(|(name, _)| name == "value")
            .map(|(_, data)| data["id"].as_str().unwrap_or_default().to_owned())
            .collect::<Vec<_>>()
    };
    // The other two stations change as often: 20 values of jbc2 would hold some of theirs.
    let events = sse_events(response, |events| values(events).len() >= 20).await;
    assert_eq!(events[0].0, "snapshot");
    let snapshot = &events[0].1;
    let shown: Vec<&str> = snapshot["devices"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| d["id"].as_str().unwrap())
        .collect();
    assert_eq!(shown, ["jbc2"]);
    assert_eq!(
        snapshot["lines"][0]["devices"].as_array().unwrap().len(),
        3,
        "the lines are the whole cell's"
    );
    for id in values(&events) {
        assert!(id.starts_with("jbc2."), "{id} is not one of jbc2's points");
    }
    for (name, data) in &events {
        if name == "device" {
            assert_eq!(data["id"], "jbc2");
        }
    }

    // The same filters as /api/devices: a line, an empty list, unknown names.
    let response = open("/api/events/stream?line=bench").await.unwrap();
    let events = sse_events(response, |events| !events.is_empty()).await;
    assert_eq!(events[0].1["devices"].as_array().unwrap().len(), 3);
    let response = open("/api/events/stream?device=").await.unwrap();
    let events = sse_events(response, |events| !events.is_empty()).await;
    assert_eq!(events[0].1["devices"], json!([]));
    let (status, body) = get(&app, "/api/events/stream?line=nope").await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    assert!(error_of(&body).contains("bench"), "{body}");
    let (status, body) = get(&app, "/api/events/stream?device=jbc2,jbc9").await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    assert!(error_of(&body).contains("jbc9"), "{body}");
    let (status, _) = get(&app, "/api/events/stream?colour=red").await;
    assert_eq!(status, StatusCode::BAD_REQUEST);
}

#[tokio::test]
async fn the_audit_names_the_client_address_over_a_socket() {
    let rig = rig(1);
    let addr = serve_on_loopback(app(&rig, false)).await;
    let body = r#"{"point":"tool_on","value":1}"#;
    let response = raw_http(
        addr,
        &format!(
            "POST /api/devices/jbc1/write HTTP/1.1\r\nHost: test\r\nConnection: close\r\n\
             Content-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}",
            body.len()
        ),
    )
    .await;
    assert!(response.starts_with("HTTP/1.1 403"), "{response}");
    assert!(
        response.contains("{\"error\":\"writes are disabled"),
        "{response}"
    );
    assert!(
        rig.cell
            .store()
            .audit_log(Some("jbc1"), 10)
            .unwrap()
            .is_empty(),
        "a write refused before its token is checked is not stored"
    );
    // An authorised one names the client's address.
    let app = app(&rig, true);
    let addr = serve_on_loopback(app).await;
    let response = raw_http(
        addr,
        &format!(
            "POST /api/devices/jbc1/write HTTP/1.1\r\nHost: test\r\nConnection: close\r\n\
             Authorization: Bearer {TOKEN}\r\nContent-Type: application/json\r\n\
             Content-Length: {}\r\n\r\n{body}",
            body.len()
        ),
    )
    .await;
    assert!(response.starts_with("HTTP/1.1 "), "{response}");
    let rows = rig.cell.store().audit_log(Some("jbc1"), 10).unwrap();
    assert!(!rows.is_empty());
    assert!(
        rows[0].client.starts_with("127.0.0.1:"),
        "{}",
        rows[0].client
    );
    assert_eq!(rows[0].new_value, json!(1));
}

#[test]
fn tokens_compare_equal_only_when_identical() {
    assert!(constant_time_eq(b"abc", b"abc"));
    assert!(!constant_time_eq(b"abc", b"abd"));
    assert!(!constant_time_eq(b"abc", b"abcd"));
    assert!(!constant_time_eq(b"", b"a"));
    assert!(constant_time_eq(b"", b""));
}

#[tokio::test(start_paused = true)]
async fn the_page_and_its_assets_are_served_and_fetch_nothing_from_elsewhere() {
    let rig = rig(1);
    let app = app(&rig, false);
    for (_, path) in web::PAGE_ROUTES {
        let response = app
            .clone()
            .oneshot(Request::get(*path).body(Body::empty()).unwrap())
            .await
            .unwrap();
        assert_eq!(response.status(), StatusCode::OK, "{path}");
        let content_type = response.headers()["content-type"]
            .to_str()
            .unwrap()
            .to_owned();
        let body = axum::body::to_bytes(response.into_body(), 1 << 20)
            .await
            .unwrap();
        let text = String::from_utf8(body.to_vec()).unwrap();
        let expected = match *path {
            "/" => "text/html",
            p if p.ends_with(".css") => "text/css",
            p if p.ends_with(".LICENSE") => "text/plain",
            _ => "text/javascript",
        };
        assert!(content_type.starts_with(expected), "{path}: {content_type}");
        // A vendored file starts with its banner (`/*! https://github.com/… */`), a
        // comment naming where it comes from, not something fetched.
        let code = match text.strip_prefix("/*!") {
            Some(rest) => rest.split_once("*/").map_or(rest, |(_, code)| code),
            None => &text,
        };
        for external in ["http://", "https://", "//fonts.", "@import", "cdn"] {
            assert!(!code.contains(external), "{path} refers to {external}");
        }
    }
    // The chart library is served with its licence, and the page loads both of its files.
    assert!(web::UPLOT_LICENSE.starts_with("The MIT License"));
    assert!(web::UPLOT_JS.starts_with("/*! https://github.com/leeoniya/uPlot (v1.6.32) */"));
    assert!(web::INDEX_HTML.contains(r#"<script src="/vendor/uPlot.iife.min.js"></script>"#));
    assert!(web::INDEX_HTML.contains(r#"href="/vendor/uPlot.min.css""#));
    // The page is built from the stream and marks devices and points for tests and tools.
    assert!(web::INDEX_HTML.contains(r#"<script src="/app.js"></script>"#));
    assert!(web::APP_JS.contains("new EventSource("));
    assert!(web::APP_JS.contains("'/api/events/stream'"));
    assert!(web::APP_JS.contains("card.id = `device-${device.id}`"));
    assert!(web::APP_JS.contains("tile.id = `point-${point.id}`"));
}

#[tokio::test(start_paused = true)]
async fn a_write_of_true_switches_on_and_a_whole_number_beyond_2_to_the_53_is_refused() {
    let rig = rig(1);
    tokio::time::sleep(Duration::from_secs(2)).await;
    let on = app(&rig, true);
    let (status, reply) = write_jbc1(&on, r#"{"point": "tool_on", "value": true}"#).await;
    assert_eq!(status, StatusCode::OK, "{reply}");
    assert!(rig.models[0].lock().port_status().tool_on);
    let (status, reply) = write_jbc1(
        &on,
        r#"{"point": "air_temperature_setpoint", "value": 9007199254740993}"#,
    )
    .await;
    assert_eq!(status, StatusCode::BAD_REQUEST);
    assert!(
        error_of(&reply).contains("beyond 9007199254740992"),
        "{reply}"
    );
    let (_, audit) = get(&on, "/api/audit?device=jbc1").await;
    assert_eq!(audit["audit"][0]["result"], "refused", "{audit}");
    assert_eq!(
        audit["audit"][0]["point"], "jbc1.air_temperature_setpoint",
        "a refusal of a known point names it by its full id: {audit}"
    );
}

#[tokio::test(start_paused = true)]
async fn a_write_the_device_does_not_answer_is_a_504_and_audited_as_failed() {
    let rig = rig(1);
    tokio::time::sleep(Duration::from_secs(2)).await;
    rig.plugged[0].store(false, std::sync::atomic::Ordering::SeqCst);
    let on = app(&rig, true);
    let (status, reply) = write_jbc1(&on, r#"{"point": "air_flow_setpoint", "value": 50}"#).await;
    assert_eq!(status, StatusCode::GATEWAY_TIMEOUT, "{reply}");
    assert!(error_of(&reply).contains("no valid answer"), "{reply}");
    let rows = rig.cell.store().audit_log(Some("jbc1"), 10).unwrap();
    assert_eq!(rows[0].result, "failed");
    assert_eq!(rows[0].point, "jbc1.air_flow_setpoint");
    assert_eq!(rows[1].result, "attempted");
}

#[tokio::test(start_paused = true)]
async fn a_write_whose_client_left_is_still_carried_out_and_audited() {
    let rig = rig(1);
    tokio::time::sleep(Duration::from_secs(2)).await;
    let on = app(&rig, true);
    let request = write_request(
        "jbc1",
        Some(TOKEN),
        r#"{"point": "air_temperature_setpoint", "value": 400}"#,
    );
    // The client gives up after 1 ms, before the station has answered.
    let gave_up = tokio::time::timeout(Duration::from_millis(1), on.clone().oneshot(request)).await;
    assert!(gave_up.is_err(), "the client left before the answer");
    // The write goes on without the client: its second audit row comes within seconds of
    // the clock (the history writer is a real thread, so look a bounded number of times).
    let mut rows = Vec::new();
    for _ in 0..50 {
        rig.cell.store().flush().await.unwrap();
        rows = rig.cell.store().audit_log(Some("jbc1"), 10).unwrap();
        if rows.len() >= 2 {
            break;
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    assert_eq!(rig.models[0].lock().settings().air_temp, 400);
    let results: Vec<&str> = rows.iter().map(|r| r.result.as_str()).collect();
    assert_eq!(results, vec!["accepted", "attempted"]);
}

#[tokio::test(start_paused = true)]
async fn refused_writes_with_huge_bodies_do_not_grow_the_database() {
    let rig = rig(1);
    tokio::time::sleep(Duration::from_secs(2)).await;
    let huge = format!(
        r#"{{"point": "air_temperature_setpoint", "value": "{}"}}"#,
        "x".repeat(2 << 20)
    );
    let db = rig.dir.path().join(crate::store::DB_FILE);
    // Polling stopped, so only the writes could grow the file.
    rig.shutdown.send(true).unwrap();
    rig.cell.store().flush().await.unwrap();
    let before = std::fs::metadata(&db).unwrap().len();
    for app in [app(&rig, false), app(&rig, true)] {
        for token in [None, Some("guess"), Some(TOKEN)] {
            for _ in 0..17 {
                let (status, _) = call(&app, write_request("jbc1", token, &huge)).await;
                assert!(status.is_client_error(), "{status}");
            }
        }
    }
    rig.cell.store().flush().await.unwrap();
    let after = std::fs::metadata(&db).unwrap().len();
    assert!(
        after < before + 100_000,
        "the database grew from {before} to {after} bytes"
    );
    // Only the 17 authorised ones are audited, each a few hundred bytes (the WAL holds
    // their pages until SQLite checkpoints it).
    let rows = rig.cell.store().audit_log(None, 1000).unwrap();
    assert_eq!(rows.len(), 17);
    let stored: usize = rows
        .iter()
        .map(|r| serde_json::to_string(r).unwrap().len())
        .sum();
    assert!(stored < 17 * 1024, "{stored} bytes of audit rows");
}

#[tokio::test(start_paused = true)]
async fn a_client_that_guesses_tokens_is_told_to_wait_and_nothing_is_stored() {
    let rig = rig(1);
    tokio::time::sleep(Duration::from_secs(2)).await;
    let addr = serve_on_loopback(app(&rig, true)).await;
    let body = r#"{"point": "air_temperature_setpoint", "value": 333}"#;
    let request = |token: &str| {
        format!(
            "POST /api/devices/jbc1/write HTTP/1.1\r\nhost: x\r\ncontent-type: application/json\r\nauthorization: Bearer {token}\r\ncontent-length: {}\r\nconnection: close\r\n\r\n{body}",
            body.len()
        )
    };
    // Requests that send no token at all are refused, but are not guesses.
    let bare = request("x").replace("authorization: Bearer x\r\n", "");
    for _ in 0..2 * MAX_TOKEN_FAILURES {
        let answer = raw_http(addr, &bare).await;
        assert!(answer.starts_with("HTTP/1.1 401"), "{answer}");
    }
    for _ in 0..MAX_TOKEN_FAILURES {
        let answer = raw_http(addr, &request("guess")).await;
        assert!(answer.starts_with("HTTP/1.1 401"), "{answer}");
    }
    let answer = raw_http(addr, &request("guess")).await;
    assert!(answer.starts_with("HTTP/1.1 429"), "{answer}");
    assert!(answer.to_lowercase().contains("retry-after:"), "{answer}");
    // Even the right token waits until the window has passed.
    let answer = raw_http(addr, &request(TOKEN)).await;
    assert!(answer.starts_with("HTTP/1.1 429"), "{answer}");
    tokio::time::sleep(FAILURE_WINDOW).await;
    let answer = raw_http(addr, &request(TOKEN)).await;
    assert!(answer.starts_with("HTTP/1.1 200"), "{answer}");
    let rows = rig.cell.store().audit_log(None, 100).unwrap();
    assert_eq!(rows.len(), 2, "only the authorised write: {rows:?}");
}

#[tokio::test(start_paused = true)]
async fn a_history_query_for_too_many_buckets_is_refused_with_the_smallest_step_allowed() {
    let rig = rig(1);
    tokio::time::sleep(Duration::from_secs(2)).await;
    let on = app(&rig, false);
    let (status, reply) = get(
        &on,
        "/api/history?point=jbc1.air_temperature&from=-30d&step=1ms",
    )
    .await;
    assert_eq!(status, StatusCode::BAD_REQUEST, "{reply}");
    let error = error_of(&reply);
    assert!(error.contains("2592000000 buckets"), "{error}");
    assert!(error.contains("the most is 10000"), "{error}");
    assert!(error.contains("use a step of 4m 20s or more"), "{error}");
    let (status, reply) = get(
        &on,
        "/api/history?point=jbc1.air_temperature&from=-30d&step=5m",
    )
    .await;
    assert_eq!(status, StatusCode::OK, "{reply}");
    let (status, reply) = get(&on, "/api/audit").await;
    assert_eq!(status, StatusCode::OK, "{reply}");
    assert_eq!(reply["truncated"], false);
}

#[tokio::test(start_paused = true)]
async fn event_streams_beyond_the_cap_are_refused_until_one_closes() {
    let rig = rig(1);
    let app = app(&rig, false);
    let open_stream = || {
        app.clone().oneshot(
            Request::get("/api/events/stream")
                .body(Body::empty())
                .unwrap(),
        )
    };
    let mut held = Vec::new();
    for _ in 0..MAX_EVENT_STREAMS {
        let response = open_stream().await.unwrap();
        assert_eq!(response.status(), StatusCode::OK);
        held.push(response);
    }
    let refused = open_stream().await.unwrap();
    assert_eq!(refused.status(), StatusCode::SERVICE_UNAVAILABLE);
    held.pop();
    let again = open_stream().await.unwrap();
    assert_eq!(again.status(), StatusCode::OK);
}

#[tokio::test(start_paused = true)]
async fn with_a_read_token_every_api_route_needs_it_and_the_page_and_health_do_not() {
    let rig = rig(1);
    tokio::time::sleep(Duration::from_secs(2)).await;
    let app = app_with(&rig, false, Some("look-only"));
    let with = |uri: &str, token: &str| {
        Request::get(uri)
            .header("authorization", format!("Bearer {token}"))
            .body(Body::empty())
            .unwrap()
    };
    let (status, reply) = get(&app, "/api/devices").await;
    assert_eq!(status, StatusCode::UNAUTHORIZED);
    assert!(error_of(&reply).contains("read token"), "{reply}");
    assert_eq!(get(&app, "/metrics").await.0, StatusCode::UNAUTHORIZED);
    let (status, reply) = call(&app, with("/api/devices", "guess")).await;
    assert_eq!(status, StatusCode::UNAUTHORIZED);
    assert_eq!(error_of(&reply), "wrong read token");
    assert_eq!(
        call(&app, with("/api/devices", "look-only")).await.0,
        StatusCode::OK
    );
    assert_eq!(
        call(&app, with("/api/lines", TOKEN)).await.0,
        StatusCode::OK,
        "the write token reads too"
    );
    // An EventSource cannot send headers: `?token=` works, and the query's own fields
    // are still checked without it.
    let (status, reply) = get(
        &app,
        "/api/history?point=jbc1.air_temperature&token=look-only&from=-1m",
    )
    .await;
    assert_eq!(status, StatusCode::OK, "{reply}");
    assert_eq!(get(&app, "/healthz").await.0, StatusCode::OK);
    assert_eq!(get(&app, "/").await.0, StatusCode::OK);
}

/// The example configuration's cell (every kind of device), its lines never opened, each
/// point given a value, quality, time and error that exercise the JSON: text needing
/// escapes, numbers JSON cannot hold, enumeration values with and without a label, stale
/// and bad qualities, times outside what RFC 3339 prints.
fn example_cell_with_every_kind_of_state(
    dir: &std::path::Path,
) -> (crate::store::Store, Arc<Cell>) {
    use crate::cell::{DeviceState, PointState};
    use crate::driver::{DeviceError, ErrorKind};
    use crate::point::{PointKind, Quality, Value};
    let store = crate::store::Store::open(dir, crate::store::StoreOptions::default()).unwrap();
    let config = crate::plugins::parse_config(
        crate::EXAMPLE_CONFIG,
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/cell.toml"),
    )
    .unwrap();
    let cell = crate::testing::unopened_cell(&config, &store);
    let numbers = [
        350.0,
        -0.0,
        0.1,
        1e300,
        f64::NAN,
        f64::INFINITY,
        9.0,
        1.5e-7,
    ];
    let texts = [
        "JT",
        "quote \" and \\ back",
        "tab\tnew\nline",
        "°C ünïcode ✓",
        "\u{1}",
    ];
    let times = [
        Some(NOW),
        Some(NOW.minus(Duration::from_secs(3600))),
        Some(Timestamp(-5)),
        None,
    ];
    let mut n = 0usize;
    for device in cell.device_entries() {
        let mut state = device.write_state();
        let points = device
            .points
            .iter()
            .map(|spec| {
                n += 1;
                let value = match (&spec.kind, n % 5) {
                    (_, 0) => None,
                    (PointKind::Text, _) => Some(Value::Text(texts[n % texts.len()].to_owned())),
                    (PointKind::Enum { states }, _)
                        if n.is_multiple_of(2) && !states.is_empty() =>
                    {
                        Some(Value::Number(states[n % states.len()].value as f64))
                    }
                    _ => Some(Value::Number(numbers[n % numbers.len()])),
                };
                let mut point = PointState::default();
                point.value = value;
                point.t = times[n % times.len()];
                point.quality = [
                    None,
                    Some(Quality::Good),
                    Some(Quality::Bad),
                    Some(Quality::Stale),
                ][n % 4];
                point.error = n
                    .is_multiple_of(3)
                    .then(|| Arc::new(texts[n % texts.len()].to_owned()));
                point.alarm = n.is_multiple_of(7);
                point
            })
            .collect();
        n += 1;
        *state = DeviceState {
            status: [
                DeviceStatus::Up,
                DeviceStatus::Down,
                DeviceStatus::Connecting,
            ][n % 3],
            since: NOW.minus(Duration::from_secs(n as u64)),
            error: n
                .is_multiple_of(2)
                .then(|| DeviceError::new(ErrorKind::Timeout, "no \"answer\"\n")),
            last_ok: times[n % times.len()],
            failures: n as u32,
            next_try_at: n
                .is_multiple_of(2)
                .then(|| NOW.plus(Duration::from_millis(1500))),
            points,
        };
    }
    (store, cell)
}

/// A fixed now for the listing tests.
const NOW: Timestamp = Timestamp(1_793_692_800_000);

#[test]
fn a_device_listing_is_byte_for_byte_what_the_device_views_serialise_to() {
    let dir = tempfile::tempdir().unwrap();
    let (_store, cell) = example_cell_with_every_kind_of_state(dir.path());
    let listing = listing::Listing::new(&cell.roster());
    assert_eq!(listing.len(), cell.device_entries().count());
    for now in [
        NOW,
        NOW.plus(Duration::from_secs(10)),
        NOW.plus(Duration::from_secs(86_400)),
    ] {
        let mut fast = Vec::new();
        listing::devices_array(&mut fast, listing.entries(), listing::Fields::ALL, now);
        listing::field(&mut fast, "total", &listing.len(), false);
        listing::field(&mut fast, "writes_enabled", &true, true);
        #[derive(serde::Serialize)]
        struct Body {
            devices: Vec<crate::cell::DeviceView>,
            total: usize,
            writes_enabled: bool,
        }
        let views = Body {
            devices: cell.device_entries().map(|d| d.view(now)).collect(),
            total: listing.len(),
            writes_enabled: true,
        };
        let derived = serde_json::to_vec(&views).unwrap();
        assert_eq!(
            String::from_utf8(fast).unwrap(),
            String::from_utf8(derived).unwrap()
        );
    }
}

#[test]
fn a_listing_cut_to_some_fields_has_just_those_of_the_full_view_and_the_id() {
    let dir = tempfile::tempdir().unwrap();
    let (_store, cell) = example_cell_with_every_kind_of_state(dir.path());
    let listing = listing::Listing::new(&cell.roster());
    let names = listing::Field::NAMES;
    let mut selections: Vec<Vec<&str>> = names.iter().map(|n| vec![*n]).collect();
    selections.push(vec!["status", "line"]);
    selections.push(vec!["points", "name", "next_try_in_ms"]);
    selections.push(names.to_vec());
    for selection in selections {
        let fields = listing::Fields::parse(&selection.join(" , ")).unwrap();
        for device in listing.entries() {
            let mut fast = Vec::new();
            device.write(&mut fast, fields, NOW);
            let mut expected =
                serde_json::to_value(cell.device_entry(device.id()).unwrap().view(NOW)).unwrap();
            expected
                .as_object_mut()
                .unwrap()
                .retain(|k, _| k == "id" || selection.contains(&k.as_str()));
            // The same members; in the full view's order (the listing before this one,
            // through a `serde_json::Value`, sorted them by name).
            let fast: Json = serde_json::from_slice(&fast).unwrap();
            assert_eq!(fast, expected, "fields {selection:?}");
        }
    }
    assert_eq!(
        listing::Fields::parse("status,colour"),
        Err("colour".to_owned())
    );
    assert_eq!(listing::Fields::parse(""), Err(String::new()));
}

#[tokio::test(start_paused = true)]
async fn devices_with_the_same_description_share_one_template() {
    let dir = tempfile::tempdir().unwrap();
    let (_store, cell) = example_cell_with_every_kind_of_state(dir.path());
    let listing = listing::Listing::new(&cell.roster());
    let kinds: std::collections::HashSet<_> = cell
        .device_entries()
        .map(|d| format!("{:?}", d.protocol))
        .collect();
    assert!(listing.templates() >= kinds.len());
    assert!(listing.templates() <= listing.len());
    let rig = rig(3);
    let stations = listing::Listing::new(&rig.cell.roster());
    assert_eq!((stations.len(), stations.templates()), (3, 1));
    // Polled stations' listing is about as big as estimated (the first buffer's size).
    tokio::time::sleep(Duration::from_secs(2)).await;
    let mut out = Vec::new();
    listing::devices_array(
        &mut out,
        stations.entries(),
        listing::Fields::ALL,
        Timestamp::now(),
    );
    let ratio = stations.size_estimate() as f64 / out.len() as f64;
    assert!(
        (0.9..1.2).contains(&ratio),
        "estimated {} bytes, took {}",
        stations.size_estimate(),
        out.len()
    );
}

#[tokio::test(start_paused = true)]
async fn device_listings_are_served_as_json() {
    let rig = rig(2);
    let app = app(&rig, false);
    for uri in [
        "/api/devices",
        "/api/devices?fields=status",
        "/api/devices/jbc2",
    ] {
        let response = app
            .clone()
            .oneshot(Request::get(uri).body(Body::empty()).unwrap())
            .await
            .unwrap();
        assert_eq!(response.status(), StatusCode::OK, "{uri}");
        assert_eq!(
            response.headers()["content-type"],
            "application/json",
            "{uri}"
        );
        let bytes = axum::body::to_bytes(response.into_body(), 1 << 20)
            .await
            .unwrap();
        let body: Json = serde_json::from_slice(&bytes).unwrap();
        assert!(body.is_object(), "{uri}: {body}");
    }
}

/// Stores `jbc1`'s machine state `(state, code, reason)` at `t`.
fn store_state(rig: &Rig, t: Timestamp, state: &str, code: f64, reason: &str) {
    use crate::point::{Quality, Value};
    use crate::store::Sample;
    for (name, value) in [
        ("machine_state", Value::Text(state.into())),
        ("machine_state_code", Value::Number(code)),
        ("machine_state_reason", Value::Text(reason.into())),
    ] {
        rig.cell.store().sample(Sample {
            point: PointId::parse(&format!("jbc1.{name}")).unwrap(),
            t,
            value: Some(value),
            quality: Quality::Good,
        });
    }
}

#[tokio::test(start_paused = true)]
async fn states_and_production_of_a_range_agree_and_add_up_to_it() {
    let rig = rig(1);
    let app = app(&rig, true);
    // An hour ago (the live polls store at the wall clock's now, after the range): in
    // use 0–600 s, a tool error 600–900 s, in use 900–1,200 s.
    let base = Timestamp::now().minus(Duration::from_secs(3600));
    let at = |s: u64| base.plus(Duration::from_secs(s));
    store_state(&rig, at(0), "in use", 1100.0, "");
    store_state(&rig, at(600), "tool error", 5000.0, "Heater malfunction");
    store_state(&rig, at(900), "in use", 1100.0, "");
    rig.cell.store().flush().await.unwrap();
    let range = format!("device=jbc1&from={}&to={}", at(0), at(1200));

    let (status, states) = get(&app, &format!("/api/states?{range}")).await;
    assert_eq!(status, StatusCode::OK, "{states}");
    let intervals = states["intervals"].as_array().unwrap();
    let seen: Vec<(&str, &str, i64)> = intervals
        .iter()
        .map(|i| {
            (
                i["state"].as_str().unwrap(),
                i["category"].as_str().unwrap(),
                i["code"].as_i64().unwrap(),
            )
        })
        .collect();
    assert_eq!(
        seen,
        [
            ("in use", "productive", 1100),
            ("tool error", "unscheduled_down", 5000),
            ("in use", "productive", 1100),
        ]
    );
    assert_eq!(intervals[1]["reason"], "Heater malfunction");
    assert_eq!(intervals[1]["start"], json!(at(600)));

    let (status, production) = get(&app, &format!("/api/production?{range}")).await;
    assert_eq!(status, StatusCode::OK, "{production}");
    let seconds: f64 = production["states"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["seconds"].as_f64().unwrap())
        .sum();
    assert_eq!(seconds, 1200.0, "the states add up to the range");
    // One shift of 24 h by default: everything is planned.
    assert_eq!(production["planned_s"], 1200.0);
    assert!(
        production.get("oee").is_none(),
        "a station counts no production: {production}"
    );
    let run = production["states"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["category"] == "productive")
        .unwrap();
    assert_eq!(run["seconds"], 900.0);
    assert_eq!(run["code"], 1100);
}

#[tokio::test(start_paused = true)]
async fn production_queries_that_cannot_be_answered_say_why() {
    let rig = rig(1);
    let app = app(&rig, true);
    for (uri, status, words) in [
        ("/api/states", StatusCode::BAD_REQUEST, "device is missing"),
        ("/api/states?device=nope", StatusCode::NOT_FOUND, "nope"),
        (
            "/api/production?device=jbc1&shift=late",
            StatusCode::NOT_FOUND,
            "no shift \"late\"; the cell's shifts: day",
        ),
        (
            "/api/production?device=jbc1&day=2026-11-02&from=-1h",
            StatusCode::BAD_REQUEST,
            "not both",
        ),
        (
            "/api/production?device=jbc1&shift=day&day=2 Nov",
            StatusCode::BAD_REQUEST,
            "is not a date",
        ),
        (
            "/api/production?device=jbc1&shift=day&from=-1h",
            StatusCode::BAD_REQUEST,
            "not both",
        ),
        (
            "/api/production?device=jbc1&from=-40d",
            StatusCode::BAD_REQUEST,
            "longer than 31 days",
        ),
        (
            "/api/states?device=jbc1&from=-1h&to=-2h",
            StatusCode::BAD_REQUEST,
            "must be before",
        ),
        (
            "/api/states?device=jbc1&colour=red",
            StatusCode::BAD_REQUEST,
            "colour",
        ),
    ] {
        let uri = uri.replace(' ', "%20");
        let (got, body) = get(&app, &uri).await;
        assert_eq!(got, status, "{uri}: {body}");
        assert!(error_of(&body).contains(words), "{uri}: {body}");
    }
    // A named shift on a day: the whole shift, named in the answer.
    let (status, body) = get(&app, "/api/production?device=jbc1&shift=day&day=2026-07-15").await;
    assert_eq!(status, StatusCode::OK, "{body}");
    assert_eq!(body["shift"]["name"], "day");
    assert_eq!(body["shift"]["day"], "2026-07-15");
    assert_eq!(body["unobserved_s"], 24.0 * 3600.0, "{body}");
    // A whole day without a shift: midnight to midnight.
    let (status, body) = get(&app, "/api/production?device=jbc1&day=2026-07-15").await;
    assert_eq!(status, StatusCode::OK, "{body}");
    assert!(body.get("shift").is_none(), "{body}");
    assert_eq!(body["unobserved_s"], 24.0 * 3600.0, "{body}");
}
