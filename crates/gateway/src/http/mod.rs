//! The HTTP API, the event stream, the metrics and the web page (axum).
//!
//! Every route is listed in [`API_ROUTES`] and described in `/api/openapi.json`; a test
//! checks the two agree. Errors are JSON `{"error": "..."}` saying what was wrong: 400 for
//! a malformed request, 404 for an unknown device, point or route, 401 for a missing or
//! wrong token, 403 when writes are off, 502/504 when the device refused or did not answer.

use std::convert::Infallible;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use axum::extract::rejection::{JsonRejection, QueryRejection};
use axum::extract::{ConnectInfo, FromRequestParts, Path, Query, State};
use axum::http::request::Parts;
use axum::http::{HeaderMap, HeaderValue, Method, StatusCode, Uri, header};
use axum::response::sse::{Event as SseEvent, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use serde::Deserialize;
use serde_json::json;
use tokio::sync::watch;
use tokio_stream::{Stream, StreamExt};

use crate::cell::{Cell, DeviceStatus, LiveMessage};
use crate::driver::{ErrorKind, WriteError};
use crate::point::{PointId, Value};
use crate::store::{AuditEntry, AuditResult, Event, EventFilter, EventKind};
use crate::time::Timestamp;

pub mod web;

/// The API's routes: method and path as axum writes them.
pub const API_ROUTES: &[(&str, &str)] = &[
    ("GET", "/healthz"),
    ("GET", "/metrics"),
    ("GET", "/api/devices"),
    ("GET", "/api/devices/{id}"),
    ("POST", "/api/devices/{id}/write"),
    ("GET", "/api/lines"),
    ("GET", "/api/history"),
    ("GET", "/api/events"),
    ("GET", "/api/events/stream"),
    ("GET", "/api/audit"),
    ("GET", "/api/openapi.json"),
];

/// The OpenAPI 3 description of the API.
pub const OPENAPI: &str = include_str!("openapi.json");

/// Most rows one event or audit listing returns.
pub const MAX_LIMIT: usize = 10_000;

/// Default length of a history query without `from`.
const DEFAULT_HISTORY: Duration = Duration::from_secs(3600);

/// Who may write.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WritePolicy {
    /// Whether writes are on (`--allow-writes`).
    pub enabled: bool,
    /// The bearer token they need.
    pub token: Option<String>,
}

/// What the handlers share.
#[derive(Debug, Clone)]
pub struct AppState {
    cell: Arc<Cell>,
    writes: Arc<WritePolicy>,
    started: Timestamp,
    shutdown: watch::Receiver<bool>,
}

/// The router over `cell`; event streams end when `shutdown` turns true.
pub fn router(cell: Arc<Cell>, writes: WritePolicy, shutdown: watch::Receiver<bool>) -> Router {
    let state = AppState {
        cell,
        writes: Arc::new(writes),
        started: Timestamp::now(),
        shutdown,
    };
    Router::new()
        .route("/healthz", get(healthz))
        .route("/metrics", get(metrics))
        .route("/api/devices", get(devices))
        .route("/api/devices/{id}", get(device))
        .route("/api/devices/{id}/write", post(write))
        .route("/api/lines", get(lines))
        .route("/api/history", get(history))
        .route("/api/events", get(events))
        .route("/api/events/stream", get(stream))
        .route("/api/audit", get(audit))
        .route("/api/openapi.json", get(openapi))
        .merge(web::routes())
        .fallback(no_route)
        .method_not_allowed_fallback(wrong_method)
        .with_state(state)
}

/// An error answer: a status and words.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ApiError {
    /// The status.
    pub status: StatusCode,
    /// What was wrong.
    pub message: String,
}

impl ApiError {
    fn new(status: StatusCode, message: impl Into<String>) -> Self {
        Self {
            status,
            message: message.into(),
        }
    }

    fn bad_request(message: impl Into<String>) -> Self {
        Self::new(StatusCode::BAD_REQUEST, message)
    }

    fn not_found(message: impl Into<String>) -> Self {
        Self::new(StatusCode::NOT_FOUND, message)
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let mut response = (self.status, Json(json!({ "error": self.message }))).into_response();
        if self.status == StatusCode::UNAUTHORIZED {
            response
                .headers_mut()
                .insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
        }
        response
    }
}

impl From<QueryRejection> for ApiError {
    fn from(rejection: QueryRejection) -> Self {
        Self::bad_request(format!("bad query: {}", rejection.body_text()))
    }
}

impl From<JsonRejection> for ApiError {
    fn from(rejection: JsonRejection) -> Self {
        Self::bad_request(format!(
            "bad request body: {}; send JSON like {{\"point\": \"air_temperature_setpoint\", \"value\": 350}}",
            rejection.body_text()
        ))
    }
}

impl From<crate::store::StoreError> for ApiError {
    fn from(error: crate::store::StoreError) -> Self {
        Self::new(StatusCode::INTERNAL_SERVER_ERROR, error.to_string())
    }
}

pub(crate) type ApiResult<T> = Result<T, ApiError>;

async fn no_route(method: Method, uri: Uri) -> ApiError {
    ApiError::not_found(format!(
        "no route {method} {}; the API is described at /api/openapi.json",
        uri.path()
    ))
}

async fn wrong_method(method: Method, uri: Uri) -> ApiError {
    ApiError::new(
        StatusCode::METHOD_NOT_ALLOWED,
        format!(
            "{} does not take {method}; see /api/openapi.json",
            uri.path()
        ),
    )
}

async fn healthz(State(s): State<AppState>) -> Json<serde_json::Value> {
    let devices = s.cell.devices();
    let up = devices
        .iter()
        .filter(|d| d.summary.status == DeviceStatus::Up)
        .count();
    let lines = s.cell.lines();
    let stats = s.cell.store().stats();
    let commit_errors = stats
        .commit_errors
        .load(std::sync::atomic::Ordering::Relaxed);
    Json(json!({
        "status": if commit_errors == 0 { "ok" } else { "degraded" },
        "started": s.started,
        "devices": devices.len(),
        "devices_up": up,
        "lines": lines.len(),
        "lines_open": lines.iter().filter(|l| l.state.open).count(),
        "history_rows_written": stats.rows_written(),
        "history_commit_errors": commit_errors,
        "writes_enabled": s.writes.enabled,
    }))
}

async fn metrics(State(s): State<AppState>) -> Response {
    let text = s.cell.metrics().encode(s.cell.store().stats());
    (
        [(
            header::CONTENT_TYPE,
            "application/openmetrics-text; version=1.0.0; charset=utf-8",
        )],
        text,
    )
        .into_response()
}

async fn devices(State(s): State<AppState>) -> Json<serde_json::Value> {
    Json(json!({ "devices": s.cell.devices(), "writes_enabled": s.writes.enabled }))
}

async fn device(State(s): State<AppState>, Path(id): Path<String>) -> ApiResult<Response> {
    let view = s
        .cell
        .device(&id)
        .ok_or_else(|| unknown_device(&s.cell, &id))?;
    Ok(Json(view).into_response())
}

async fn lines(State(s): State<AppState>) -> Json<serde_json::Value> {
    Json(json!({ "lines": s.cell.lines() }))
}

fn unknown_device(cell: &Cell, id: &str) -> ApiError {
    let known: Vec<String> = cell.device_entries().map(|d| d.id.to_string()).collect();
    ApiError::not_found(format!(
        "no device {id:?}; devices: {}",
        if known.is_empty() {
            "none".to_owned()
        } else {
            known.join(", ")
        }
    ))
}

/// Query of `/api/history`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct HistoryQuery {
    point: Option<String>,
    from: Option<String>,
    to: Option<String>,
    step: Option<String>,
}

/// The time range and step a history query asks for, checked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct HistoryRange {
    pub(crate) from: Timestamp,
    pub(crate) to: Timestamp,
    pub(crate) step: Option<Duration>,
}

fn parse_time(name: &str, text: Option<&str>, now: Timestamp) -> ApiResult<Option<Timestamp>> {
    text.map(|t| Timestamp::parse_relative(t, now))
        .transpose()
        .map_err(|e| ApiError::bad_request(format!("{name}: {e}")))
}

/// The point a history query names, as written (whether the cell has it is the handler's
/// question).
pub(crate) fn history_point(q: &HistoryQuery) -> ApiResult<PointId> {
    let point = q.point.as_deref().ok_or_else(|| {
        ApiError::bad_request("give the point: /api/history?point=jbc1.air_temperature&from=-1h")
    })?;
    PointId::parse(point).map_err(|e| ApiError::bad_request(e.to_string()))
}

/// The range of a history query at `now`: `to` defaults to now, `from` to an hour before
/// `to` (not before 1970), and `from` must be before `to`.
pub(crate) fn history_range(q: &HistoryQuery, now: Timestamp) -> ApiResult<HistoryRange> {
    let to = parse_time("to", q.to.as_deref(), now)?.unwrap_or(now);
    let from = parse_time("from", q.from.as_deref(), now)?
        .unwrap_or(to.minus(DEFAULT_HISTORY).max(Timestamp::MIN));
    if from >= to {
        return Err(ApiError::bad_request(format!(
            "from ({from}) must be before to ({to})"
        )));
    }
    let step = q.step.as_deref().map(parse_step).transpose()?;
    Ok(HistoryRange { from, to, step })
}

/// A history step: a duration of at least 1 ms.
pub(crate) fn parse_step(text: &str) -> ApiResult<Duration> {
    match humantime::parse_duration(text.trim()) {
        Ok(d) if d >= Duration::from_millis(1) => Ok(d),
        Ok(_) => Err(ApiError::bad_request("step must be at least 1ms")),
        Err(e) => Err(ApiError::bad_request(format!(
            "step {text:?} is not a duration ({e}); write e.g. 10s, 1m or 1h"
        ))),
    }
}

async fn history(
    State(s): State<AppState>,
    query: Result<Query<HistoryQuery>, QueryRejection>,
) -> ApiResult<Response> {
    let Query(q) = query?;
    let point = history_point(&q)?;
    if s.cell.point(&point).is_none() {
        if s.cell.device_entry(point.device()).is_none() {
            return Err(unknown_device(&s.cell, point.device()));
        }
        return Err(ApiError::not_found(format!(
            "device {} has no point {:?}; GET /api/devices/{} lists its points",
            point.device(),
            point.name(),
            point.device()
        )));
    }
    let HistoryRange { from, to, step } = history_range(&q, Timestamp::now())?;
    let store = s.cell.store().clone();
    let history = tokio::task::spawn_blocking(move || store.history(&point, from, to, step))
        .await
        .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()))??;
    Ok(Json(history).into_response())
}

/// Query of `/api/events`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct EventsQuery {
    from: Option<String>,
    to: Option<String>,
    device: Option<String>,
    kind: Option<String>,
    limit: Option<usize>,
}

pub(crate) fn check_limit(limit: Option<usize>) -> ApiResult<usize> {
    match limit {
        None => Ok(100),
        Some(n) if (1..=MAX_LIMIT).contains(&n) => Ok(n),
        Some(n) => Err(ApiError::bad_request(format!(
            "limit {n} is out of range: 1 to {MAX_LIMIT}"
        ))),
    }
}

/// The filter an events query asks for at `now` (whether the cell has the device is the
/// handler's question, asked first).
pub(crate) fn events_filter(q: EventsQuery, now: Timestamp) -> ApiResult<EventFilter> {
    let kind = q
        .kind
        .as_deref()
        .map(|k| {
            EventKind::parse(k).ok_or_else(|| {
                ApiError::bad_request(format!(
                    "kind {k:?} is not an event kind; kinds: {}",
                    EventKind::ALL.map(EventKind::as_str).join(", ")
                ))
            })
        })
        .transpose()?;
    Ok(EventFilter {
        from: parse_time("from", q.from.as_deref(), now)?,
        to: parse_time("to", q.to.as_deref(), now)?,
        device: q.device,
        kind,
        limit: check_limit(q.limit)?,
    })
}

async fn events(
    State(s): State<AppState>,
    query: Result<Query<EventsQuery>, QueryRejection>,
) -> ApiResult<Response> {
    let Query(q) = query?;
    if let Some(device) = &q.device
        && s.cell.device_entry(device).is_none()
    {
        return Err(unknown_device(&s.cell, device));
    }
    let filter = events_filter(q, Timestamp::now())?;
    let store = s.cell.store().clone();
    let events = tokio::task::spawn_blocking(move || store.events(&filter))
        .await
        .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()))??;
    Ok(Json(json!({ "events": events })).into_response())
}

/// Query of `/api/audit`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct AuditQuery {
    pub(crate) device: Option<String>,
    pub(crate) limit: Option<usize>,
}

async fn audit(
    State(s): State<AppState>,
    query: Result<Query<AuditQuery>, QueryRejection>,
) -> ApiResult<Response> {
    let Query(q) = query?;
    let limit = check_limit(q.limit)?;
    let store = s.cell.store().clone();
    let rows = tokio::task::spawn_blocking(move || store.audit_log(q.device.as_deref(), limit))
        .await
        .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()))??;
    Ok(Json(json!({ "audit": rows })).into_response())
}

async fn openapi() -> Response {
    ([(header::CONTENT_TYPE, "application/json")], OPENAPI).into_response()
}

/// One item of an event stream.
enum StreamItem {
    Live(Result<LiveMessage, u64>),
    Stop(bool),
}

async fn stream(
    State(s): State<AppState>,
) -> Sse<impl Stream<Item = Result<SseEvent, Infallible>>> {
    // Subscribe before the snapshot, so no change falls between the two.
    let live = tokio_stream::wrappers::BroadcastStream::new(s.cell.subscribe()).map(|m| {
        StreamItem::Live(
            m.map_err(|tokio_stream::wrappers::errors::BroadcastStreamRecvError::Lagged(n)| n),
        )
    });
    let snapshot = json!({
        "devices": s.cell.devices(),
        "lines": s.cell.lines(),
        "writes_enabled": s.writes.enabled,
    });
    let first = SseEvent::default()
        .event("snapshot")
        .data(snapshot.to_string());
    let stop = tokio_stream::wrappers::WatchStream::new(s.shutdown.clone()).map(StreamItem::Stop);
    let guard = ClientGuard::new(Arc::clone(&s.cell));
    let events = live
        .merge(stop)
        .take_while(|item| !matches!(item, StreamItem::Stop(true)))
        .filter_map(move |item| {
            let _alive = &guard;
            match item {
                StreamItem::Live(Ok(message)) => Some(
                    SseEvent::default()
                        .event(message.name())
                        .json_data(&message)
                        .unwrap_or_else(|e| SseEvent::default().event("error").data(e.to_string())),
                ),
                // The client fell behind: it should fetch a fresh snapshot.
                StreamItem::Live(Err(missed)) => Some(
                    SseEvent::default()
                        .event("lagged")
                        .data(json!({ "missed": missed }).to_string()),
                ),
                StreamItem::Stop(_) => None,
            }
        });
    let all = tokio_stream::once(first).chain(events).map(Ok);
    Sse::new(all).keep_alive(KeepAlive::default())
}

/// Counts open event streams.
struct ClientGuard(Arc<Cell>);

impl ClientGuard {
    fn new(cell: Arc<Cell>) -> Self {
        cell.metrics().sse_clients.inc();
        Self(cell)
    }
}

impl Drop for ClientGuard {
    fn drop(&mut self) {
        self.0.metrics().sse_clients.dec();
    }
}

/// The client's address, when the server knows it (`unknown` in in-process tests).
struct ClientAddr(String);

impl<S: Send + Sync> FromRequestParts<S> for ClientAddr {
    type Rejection = Infallible;

    async fn from_request_parts(parts: &mut Parts, _: &S) -> Result<Self, Infallible> {
        Ok(ClientAddr(
            parts
                .extensions
                .get::<ConnectInfo<SocketAddr>>()
                .map_or_else(|| "unknown".to_owned(), |c| c.0.to_string()),
        ))
    }
}

/// Body of a write.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct WriteBody {
    point: String,
    value: serde_json::Value,
}

async fn write(
    State(s): State<AppState>,
    ClientAddr(client): ClientAddr,
    Path(id): Path<String>,
    headers: HeaderMap,
    body: Result<Json<WriteBody>, JsonRejection>,
) -> ApiResult<Response> {
    let (point_text, new) = match &body {
        Ok(Json(b)) => (b.point.clone(), b.value.clone()),
        Err(_) => (String::new(), serde_json::Value::Null),
    };
    let mut attempt = Attempt {
        state: &s,
        client,
        device: id.clone(),
        point: point_text.clone(),
        new,
    };
    // The order says what a caller learns: unknown device, writes off, token, body, value.
    let Some(device) = s.cell.device_entry(&id) else {
        return Err(attempt.refuse(unknown_device(&s.cell, &id), None).await);
    };
    if !s.writes.enabled {
        let error = ApiError::new(
            StatusCode::FORBIDDEN,
            "writes are disabled on this gateway; start it with --allow-writes (and a token)",
        );
        return Err(attempt.refuse(error, None).await);
    }
    if let Err(error) = check_token(&headers, s.writes.token.as_deref()) {
        return Err(attempt.refuse(error, None).await);
    }
    let Json(body) = match body {
        Ok(body) => body,
        Err(rejection) => return Err(attempt.refuse(rejection.into(), None).await),
    };
    // Accept the point's own name or its full id.
    let name = body
        .point
        .strip_prefix(&format!("{}.", device.id))
        .unwrap_or(&body.point)
        .to_owned();
    let point = match PointId::new(&device.id, &name) {
        Ok(p) if device.point_index(&name).is_some() => p,
        _ => {
            let error = ApiError::not_found(format!(
                "device {} has no point {:?}; writable points: {}",
                device.id,
                body.point,
                device
                    .points
                    .iter()
                    .filter(|p| p.writable.is_some())
                    .map(|p| p.id.name())
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
            return Err(attempt.refuse(error, None).await);
        }
    };
    attempt.point = point.to_string();
    let value = match serde_json::from_value::<Value>(body.value.clone()) {
        Ok(v) => v,
        Err(_) => {
            let error = ApiError::bad_request(format!(
                "value must be a number or a string, not {}",
                body.value
            ));
            return Err(attempt.refuse(error, None).await);
        }
    };
    let old = device
        .point_index(&name)
        .and_then(|i| device.read().points.get(i).and_then(|p| p.value.clone()));
    match s.cell.write(&point, &value).await {
        Ok(outcome) => {
            let spec = s.cell.point(&point);
            let shown = |v: &Value| {
                let label = spec.and_then(|p| p.label(v)).map(str::to_owned);
                let unit = spec.and_then(|p| p.unit.clone());
                label.unwrap_or_else(|| match unit {
                    Some(u) => format!("{v} {u}"),
                    None => v.to_string(),
                })
            };
            let detail = format!(
                "{point} set to {}{} by {}",
                shown(&outcome.new),
                outcome
                    .old
                    .as_ref()
                    .map(|o| format!(" (was {})", shown(o)))
                    .unwrap_or_default(),
                attempt.client
            );
            s.cell.emit(Event {
                t: Timestamp::now(),
                kind: EventKind::Write,
                line: Some(device.line.clone()),
                device: Some(device.id.clone()),
                point: Some(point.clone()),
                message: detail.clone(),
            });
            attempt
                .record(AuditResult::Accepted, outcome.old.clone(), &detail)
                .await;
            Ok(Json(json!({
                "device": device.id,
                "point": point,
                "old": outcome.old,
                "new": outcome.new,
                "result": "accepted",
                "detail": detail,
            }))
            .into_response())
        }
        Err(error) => {
            let (status, result) = match &error {
                WriteError::Invalid(_) => (StatusCode::BAD_REQUEST, AuditResult::Refused),
                WriteError::UnknownPoint { .. } => (StatusCode::NOT_FOUND, AuditResult::Refused),
                WriteError::Device(e) if e.kind == ErrorKind::Refused => {
                    (StatusCode::BAD_GATEWAY, AuditResult::Refused)
                }
                WriteError::Device(e) if e.kind == ErrorKind::Timeout => {
                    (StatusCode::GATEWAY_TIMEOUT, AuditResult::Failed)
                }
                WriteError::Device(_) => (StatusCode::BAD_GATEWAY, AuditResult::Failed),
                _ => (StatusCode::SERVICE_UNAVAILABLE, AuditResult::Failed),
            };
            let error = ApiError::new(status, error.to_string());
            attempt.record(result, old, &error.message).await;
            Err(error)
        }
    }
}

/// A write attempt on its way to the audit table.
struct Attempt<'a> {
    state: &'a AppState,
    client: String,
    device: String,
    point: String,
    new: serde_json::Value,
}

impl Attempt<'_> {
    /// Records a refusal before the wire and returns the error to answer with.
    async fn refuse(&self, error: ApiError, old: Option<Value>) -> ApiError {
        self.record(AuditResult::Refused, old, &error.message).await;
        error
    }

    /// Writes the audit row and waits for its commit, so an answered request is on disk.
    async fn record(&self, result: AuditResult, old: Option<Value>, detail: &str) {
        let store = self.state.cell.store();
        store.audit(AuditEntry {
            t: Timestamp::now(),
            client: self.client.clone(),
            device: self.device.clone(),
            point: self.point.clone(),
            old,
            new: self.new.clone(),
            result,
            detail: detail.to_owned(),
        });
        self.state
            .cell
            .metrics()
            .writes
            .get_or_create(&crate::metrics::WriteLabels {
                result: match result {
                    AuditResult::Accepted => "accepted",
                    AuditResult::Refused => "refused",
                    AuditResult::Failed => "failed",
                }
                .to_owned(),
            })
            .inc();
        if let Err(e) = store.flush().await {
            tracing::error!("audit row not committed: {e}");
        }
    }
}

/// Checks `Authorization: Bearer <token>`.
fn check_token(headers: &HeaderMap, token: Option<&str>) -> ApiResult<()> {
    let Some(expected) = token else {
        return Err(ApiError::new(
            StatusCode::FORBIDDEN,
            "writes need a token and none is configured; set CELLBUS_TOKEN or token in the config",
        ));
    };
    let Some(value) = headers.get(header::AUTHORIZATION) else {
        return Err(ApiError::new(
            StatusCode::UNAUTHORIZED,
            "missing Authorization header; send Authorization: Bearer <token>",
        ));
    };
    let given = value
        .to_str()
        .ok()
        .and_then(|v| {
            let (scheme, rest) = v.trim().split_once(' ')?;
            scheme.eq_ignore_ascii_case("bearer").then(|| rest.trim())
        })
        .ok_or_else(|| {
            ApiError::new(
                StatusCode::UNAUTHORIZED,
                "the Authorization header must be Bearer <token>",
            )
        })?;
    if constant_time_eq(given.as_bytes(), expected.as_bytes()) {
        Ok(())
    } else {
        Err(ApiError::new(StatusCode::UNAUTHORIZED, "wrong token"))
    }
}

/// Compares without stopping at the first difference, so timing does not leak the token.
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    let mut diff = a.len() ^ b.len();
    for (i, x) in a.iter().enumerate() {
        diff |= usize::from(x ^ b.get(i % b.len().max(1)).copied().unwrap_or(0));
    }
    diff == 0
}

#[cfg(test)]
mod tests;
