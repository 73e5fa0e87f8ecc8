//! The plant's HTTP API (`--listen`): the gateway's history shapes for every cell.
//!
//! - `GET /api/history?point=NODE/DEVICE.POINT&from=&to=&step=`: exactly the gateway's
//!   `/api/history` answer (raw samples with `before` and `truncated`, or buckets), with the
//!   same time forms (RFC 3339, `now`, `-1h`), defaults, limits and errors (the parsing the
//!   gateway uses, [`kit::history`]). A node's own metrics are `NODE/.POINT`.
//! - `GET /api/points`: every point with node, device, unit, name in words, data type and
//!   write range.
//! - `GET /api/events?from=&to=&limit=`: events, newest first.
//! - `GET /healthz`: broker, database, pending samples, nodes online.
//! - `GET /metrics`: Prometheus (OpenMetrics text).
//!
//! Queries use a connection of their own (never the writer's), one query at a time, opened
//! on the first query and again after it is lost. The server loop is the gateway's
//! ([`kit::http::server`]: header and write timeouts, a connection limit).

use std::sync::Arc;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use axum::extract::rejection::QueryRejection;
use axum::extract::{Query, State};
use axum::http::{Method, StatusCode, Uri, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::{Json, Router};
use kit::bounded::MAX_NAME;
use kit::history::{
    Bucket as ApiBucket, HistoryQuery, HistoryRange, HistorySample, MAX_RAW_SAMPLES, Series,
    bounded_by_bytes, check_limit, history_range, parse_time,
};
use kit::http::{ApiError, ApiResult};
use kit::time::Timestamp;
use kit::value::Value;
use serde::{Deserialize, Serialize};
use serde_json::json;

use crate::metrics::{Health, Metrics};
use crate::store::{PointRow, Store, StoreError, StoredSample};

/// How long a query waits for the query connection before the answer is 503.
const QUERY_WAIT: Duration = Duration::from_secs(10);

/// What the handlers share.
pub struct AppState {
    /// The database URL (for the query connection).
    pub url: String,
    /// The query connection, opened on demand.
    pub reader: tokio::sync::Mutex<Option<Store>>,
    /// Counters.
    pub metrics: Arc<Metrics>,
    /// Health.
    pub health: Arc<Health>,
}

/// The router of the plant API.
pub fn router(state: Arc<AppState>) -> Router {
    Router::new()
        .route("/healthz", get(healthz))
        .route("/metrics", get(metrics))
        .route("/api/points", get(points))
        .route("/api/history", get(history))
        .route("/api/events", get(events))
        .fallback(no_route)
        .method_not_allowed_fallback(wrong_method)
        .with_state(state)
}

async fn no_route(method: Method, uri: Uri) -> ApiError {
    ApiError::not_found(format!(
        "no route {method} {}; the historian serves /api/history, /api/points, /api/events, \
         /healthz and /metrics",
        uri.path()
    ))
}

async fn wrong_method(method: Method, uri: Uri) -> ApiError {
    ApiError::new(
        StatusCode::METHOD_NOT_ALLOWED,
        format!("{} does not take {method}", uri.path()),
    )
}

fn db_error(e: StoreError) -> ApiError {
    let status = if e.is_connection_lost() {
        StatusCode::SERVICE_UNAVAILABLE
    } else {
        StatusCode::INTERNAL_SERVER_ERROR
    };
    ApiError::new(status, e.to_string())
}

type Reader<'a> = tokio::sync::MutexGuard<'a, Option<Store>>;

/// The query connection, connected.
async fn reader(s: &AppState) -> ApiResult<Reader<'_>> {
    let mut guard = tokio::time::timeout(QUERY_WAIT, s.reader.lock())
        .await
        .map_err(|_| {
            ApiError::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "the historian is busy with other queries; try again shortly",
            )
        })?;
    if guard.as_ref().is_none_or(Store::is_closed) {
        *guard = Some(Store::connect(&s.url).await.map_err(db_error)?);
    }
    Ok(guard)
}

/// The query connection a [`reader`] guard holds (it always holds one once connected).
fn connected<'g>(guard: &'g Reader<'_>) -> ApiResult<&'g Store> {
    guard
        .as_ref()
        .ok_or_else(|| ApiError::new(StatusCode::SERVICE_UNAVAILABLE, "no query connection"))
}

/// Runs `result`'s error handling: a lost connection is dropped so the next query opens
/// a new one.
fn checked<T>(guard: &mut Reader<'_>, result: Result<T, StoreError>) -> ApiResult<T> {
    result.map_err(|e| {
        if e.is_connection_lost() {
            **guard = None;
        }
        db_error(e)
    })
}

fn ms(t: SystemTime) -> Timestamp {
    Timestamp(
        t.duration_since(UNIX_EPOCH)
            .map_or(0, |d| i64::try_from(d.as_millis()).unwrap_or(i64::MAX)),
    )
}

/// A query time as a system time (the store cuts ranges to its calendar).
fn system_time(t: Timestamp) -> SystemTime {
    UNIX_EPOCH
        .checked_add(Duration::from_millis(t.0.max(0).unsigned_abs()))
        .unwrap_or(UNIX_EPOCH + Duration::from_secs(253_402_300_799))
}

fn api_sample(s: StoredSample) -> HistorySample {
    HistorySample {
        t: ms(s.t),
        value: s.value.map(Value::Number).or(s.text.map(Value::Text)),
        quality: s.quality,
    }
}

/// Checks the form of a plant point id: `NODE/DEVICE.POINT` (`NODE/.POINT` for a node's
/// own metric), or `GROUP/NODE/DEVICE.POINT` when the node id is in several Sparkplug
/// groups. Which point it names is the store's answer ([`Store::find_points`]).
///
/// # Errors
///
/// Words that quote the text and say the form.
pub fn check_point_id(text: &str) -> Result<(), String> {
    // PostgreSQL text holds no NUL: such an id names no point (and is a 400, not the
    // database's refusal as a 500).
    if text.contains('\0') {
        return Err(format!(
            "point {:?} has a NUL character, which no point id has",
            cut(text)
        ));
    }
    let well_formed = text.split_once('/').is_some_and(|(first, rest)| {
        !first.is_empty() && rest.contains('.') && !rest.ends_with('.')
    });
    if well_formed {
        Ok(())
    } else {
        Err(format!(
            "point {:?} is not NODE/DEVICE.POINT (e.g. cellA/jbc1.air_temperature; a node's \
             own metric is NODE/.POINT; GROUP/NODE/DEVICE.POINT when the node id is in \
             several groups)",
            cut(text)
        ))
    }
}

/// A point's plant id: `NODE/DEVICE.POINT`, or with `GROUP/` first when `grouped`.
pub fn point_id(p: &PointRow, grouped: bool) -> String {
    let (node, device, point) = (&p.node, &p.device, &p.point);
    if grouped {
        format!("{}/{node}/{device}.{point}", p.group)
    } else {
        format!("{node}/{device}.{point}")
    }
}

/// A point id as an error message quotes it: as the gateway's errors quote a name.
fn cut(text: &str) -> String {
    kit::bounded::cut(text, MAX_NAME)
}

/// The one point `text` names, or a 404 (none) or 400 (several, listed).
async fn find_point(guard: &mut Reader<'_>, text: &str) -> ApiResult<crate::store::FoundPoint> {
    let store = connected(guard)?;
    let found = store.find_points(text).await;
    let mut found = checked(guard, found)?;
    match found.len() {
        0 => Err(ApiError::not_found(format!(
            "the historian has no point {}; GET /api/points lists them",
            cut(text)
        ))),
        1 => Ok(found.remove(0)),
        _ => {
            let names: Vec<String> = found
                .iter()
                .map(|p| {
                    format!(
                        "group {:?} node {:?} device {:?} point {:?}",
                        p.group, p.node, p.device, p.point
                    )
                })
                .collect();
            let groups: std::collections::BTreeSet<&str> =
                found.iter().map(|p| p.group.as_str()).collect();
            let hint = if groups.len() > 1 {
                "; name the group first: GROUP/NODE/DEVICE.POINT"
            } else {
                "; a device id with a `.` makes such ids ambiguous, and the plant API cannot \
                 tell these apart (query cellbus_samples by its columns)"
            };
            Err(ApiError::bad_request(format!(
                "point {} names {} points: {}{hint}",
                cut(text),
                found.len(),
                names.join(", ")
            )))
        }
    }
}

/// The answer to a history query: the gateway's `History`, with a plant point id.
#[derive(Debug, Serialize)]
struct PlantHistory {
    point: String,
    from: Timestamp,
    to: Timestamp,
    step_ms: Option<i64>,
    before: Option<HistorySample>,
    #[serde(flatten)]
    series: Series,
    truncated: bool,
}

async fn history(
    State(s): State<Arc<AppState>>,
    query: Result<Query<HistoryQuery>, QueryRejection>,
) -> ApiResult<Response> {
    let Query(q) = query?;
    let text = q.point.as_deref().ok_or_else(|| {
        ApiError::bad_request(
            "give the point: /api/history?point=cellA/jbc1.air_temperature&from=-1h",
        )
    })?;
    check_point_id(text).map_err(ApiError::bad_request)?;
    let HistoryRange { from, to, step } = history_range(&q, Timestamp::now())?;
    let mut guard = reader(&s).await?;
    let p = find_point(&mut guard, text).await?;
    let store = connected(&guard)?;
    let (from_t, to_t) = (system_time(from), system_time(to));
    let before = store.last_before(p.id, from_t).await;
    let step_ms = step.map(|d| i64::try_from(d.as_millis()).unwrap_or(i64::MAX));
    let (series, truncated) = match step {
        Some(step) => {
            let buckets = store.buckets(p.id, from_t, to_t, step).await;
            let buckets = checked(&mut guard, buckets)?;
            let buckets = buckets
                .into_iter()
                .map(|b| ApiBucket {
                    t: ms(b.t),
                    avg: b.avg,
                    min: b.min,
                    max: b.max,
                    count: b.count,
                })
                .collect();
            (Series::Buckets(buckets), false)
        }
        None => {
            let raw = store.raw(p.id, from_t, to_t, MAX_RAW_SAMPLES + 1).await;
            let mut raw = checked(&mut guard, raw)?;
            let truncated = raw.len() > MAX_RAW_SAMPLES;
            raw.truncate(MAX_RAW_SAMPLES);
            (
                Series::Samples(raw.into_iter().map(api_sample).collect()),
                truncated,
            )
        }
    };
    let before = checked(&mut guard, before)?.map(api_sample);
    Ok(Json(PlantHistory {
        point: text.to_owned(),
        from,
        to,
        step_ms,
        before,
        series,
        truncated,
    })
    .into_response())
}

/// Query of `/api/points`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PointsQuery {
    node: Option<String>,
    offset: Option<usize>,
    limit: Option<usize>,
}

/// Points in one `/api/points` answer by default and at most (about 150 bytes each).
pub const MAX_POINTS: usize = 10_000;

async fn points(
    State(s): State<Arc<AppState>>,
    query: Result<Query<PointsQuery>, QueryRejection>,
) -> ApiResult<Response> {
    let Query(q) = query?;
    let limit = match q.limit {
        None => MAX_POINTS,
        Some(n) if (1..=MAX_POINTS).contains(&n) => n,
        Some(n) => {
            return Err(ApiError::bad_request(format!(
                "limit {n} is out of range: 1 to {MAX_POINTS} (page with offset)"
            )));
        }
    };
    if q.node.as_deref().is_some_and(|n| n.contains('\0')) {
        return Err(ApiError::bad_request(
            "node has a NUL character, which no node id has",
        ));
    }
    let mut guard = reader(&s).await?;
    let store = connected(&guard)?;
    let page = store
        .points(q.node.as_deref(), q.offset.unwrap_or(0), limit)
        .await;
    let (rows, total) = checked(&mut guard, page)?;
    let store = connected(&guard)?;
    let shared = store.nodes_in_several_groups().await;
    let shared = checked(&mut guard, shared)?;
    let points: Vec<_> = rows
        .into_iter()
        .map(|p| {
            let range = match (p.write_min, p.write_max) {
                (Some(min), Some(max)) => json!({ "min": min, "max": max }),
                _ => serde_json::Value::Null,
            };
            json!({
                "id": point_id(&p, shared.contains(&p.node)),
                "group": p.group,
                "node": p.node,
                "device": p.device,
                "point": p.point,
                "name": p.description,
                "unit": p.unit,
                "datatype": p.datatype,
                "writable": p.writable,
                "range": range,
            })
        })
        .collect();
    Ok(Json(json!({ "points": points, "total": total })).into_response())
}

/// Query of `/api/events`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct EventsQuery {
    from: Option<String>,
    to: Option<String>,
    limit: Option<usize>,
}

/// Where an `/api/events` answer stops (`"truncated": true`): events' messages come from
/// the gateways, and 10,000 long ones would make an answer of any size.
const MAX_EVENTS_BYTES: usize = 4 << 20;

async fn events(
    State(s): State<Arc<AppState>>,
    query: Result<Query<EventsQuery>, QueryRejection>,
) -> ApiResult<Response> {
    let Query(q) = query?;
    let now = Timestamp::now();
    let from = parse_time("from", q.from.as_deref(), now)?.unwrap_or(Timestamp::MIN);
    let to = parse_time("to", q.to.as_deref(), now)?.unwrap_or(Timestamp(i64::MAX));
    if from > to {
        // As the gateway's /api/events says it.
        return Err(ApiError::bad_request(format!(
            "from ({from}) must not be after to ({to})"
        )));
    }
    let limit = check_limit(q.limit)?;
    let mut guard = reader(&s).await?;
    let store = connected(&guard)?;
    let rows = store
        .events(system_time(from), system_time(to), limit)
        .await;
    let rows = checked(&mut guard, rows)?;
    let events = rows.into_iter().map(|e| {
        json!({
            "t": ms(e.t),
            "group": e.group,
            "node": e.node,
            "device": e.device,
            "point": e.point,
            "line": e.line,
            "kind": e.kind,
            "severity": e.severity,
            "message": e.message,
            "fields": e
                .fields
                .as_deref()
                .and_then(|f| serde_json::from_str::<serde_json::Value>(f).ok())
                .unwrap_or_else(|| json!({})),
        })
    });
    let (events, truncated) = bounded_by_bytes(events, MAX_EVENTS_BYTES);
    Ok(Json(json!({ "events": events, "truncated": truncated })).into_response())
}

async fn healthz(State(s): State<Arc<AppState>>) -> Json<serde_json::Value> {
    let broker = s.health.broker();
    let database = s.health.database();
    let last = s.health.last_commit_ms();
    Json(json!({
        "status": if broker.is_none() && database.is_none() { "ok" } else { "degraded" },
        "broker": broker.as_deref().unwrap_or("connected"),
        "database": database.as_deref().unwrap_or("ok"),
        "pending_samples": s.metrics.pending.get(),
        "samples_committed": s.metrics.samples_committed.get(),
        "duplicate_samples": s.metrics.duplicates.get(),
        "nodes_online": s.health.nodes_online(),
        "last_commit": (last > 0).then_some(Timestamp(last)),
    }))
}

async fn metrics(State(s): State<Arc<AppState>>) -> Response {
    (
        [(
            header::CONTENT_TYPE,
            "application/openmetrics-text; version=1.0.0; charset=utf-8",
        )],
        s.metrics.encode(),
    )
        .into_response()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plant_point_is_node_slash_device_dot_point_or_with_its_group_first() {
        for text in [
            "cellA/jbc1.air_temperature",
            "cellA/.history_rows",
            "cellA/.Node Control/Rebirth",
            "plant/cellA/jbc1.air_temperature",
        ] {
            assert_eq!(check_point_id(text), Ok(()), "{text}");
        }
        let mut p = PointRow::bare("plant", "cellA", "jbc1", "air_temperature");
        assert_eq!(point_id(&p, false), "cellA/jbc1.air_temperature");
        assert_eq!(point_id(&p, true), "plant/cellA/jbc1.air_temperature");
        p.device = String::new();
        assert_eq!(point_id(&p, false), "cellA/.air_temperature");
    }

    #[test]
    fn a_point_without_node_or_device_is_refused_with_the_form() {
        for text in [
            "jbc1.air_temperature",
            "cellA/jbc1",
            "/jbc1.x",
            "cellA/jbc1.",
        ] {
            let e = check_point_id(text).unwrap_err();
            assert!(e.contains("NODE/DEVICE.POINT") && e.contains(text), "{e}");
        }
        let e = check_point_id("\0/x.y").unwrap_err();
        assert!(e.contains("NUL"), "{e}");
        let long = format!("{}/x", "é".repeat(1_000));
        let e = check_point_id(&long).unwrap_err();
        assert!(e.len() < 600, "a long id is cut: {} bytes", e.len());
    }
}
