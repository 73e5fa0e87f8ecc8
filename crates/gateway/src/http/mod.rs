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
use axum::extract::{ConnectInfo, DefaultBodyLimit, FromRequestParts, Path, Query, State};
use axum::http::request::Parts;
use axum::http::{HeaderValue, Method, StatusCode, Uri, header};
use axum::response::sse::{Event as SseEvent, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use serde::Deserialize;
use serde_json::json;
use tokio::sync::watch;
use tokio_stream::{Stream, StreamExt};

use crate::cell::{Cell, DeviceStatus, LiveMessage};
use crate::event::EventKind;
use crate::point::PointId;
use crate::store::EventFilter;
use crate::time::Timestamp;

mod alarms;
mod listing;
mod production;
pub mod server;
pub mod web;
mod write;

pub use write::{BODY_LIMIT, FAILURE_WINDOW, MAX_TOKEN_FAILURES};

// The history query and the listings' limits, shared with the historian.
pub(crate) use kit::history::parse_step;
pub use kit::history::{
    DEFAULT_HISTORY, HistoryQuery, HistoryRange, MAX_BUCKETS, MAX_LIMIT, bounded_by_bytes,
    check_limit, history_range, parse_time,
};

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
    ("GET", "/api/states"),
    ("GET", "/api/production"),
    ("GET", "/api/alarms"),
    ("GET", "/api/alarms/journal"),
    ("POST", "/api/alarms/{id}/{action}"),
    ("GET", "/api/openapi.json"),
];

/// The OpenAPI 3 description of the API.
pub const OPENAPI: &str = include_str!("openapi.json");

/// Most bytes of rows one audit listing returns (`truncated` says when it stopped).
pub const MAX_AUDIT_BYTES: usize = 4 << 20;

/// History, event and audit queries running at once; more wait their turn.
pub const MAX_CONCURRENT_QUERIES: usize = 4;

/// Event streams open at once; more are answered 503.
pub const MAX_EVENT_STREAMS: usize = 64;

/// How long a query waits for its turn before the answer is 503.
const QUERY_WAIT: Duration = Duration::from_secs(10);

/// Who may write.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WritePolicy {
    /// Whether writes are on (`--allow-writes`).
    pub enabled: bool,
    /// The bearer token they need.
    pub token: Option<String>,
    /// A token every `/api/` route and `/metrics` then need (the write token is taken
    /// too); `None`: reading is open.
    pub read_token: Option<String>,
}

/// What the handlers share.
#[derive(Debug, Clone)]
pub struct AppState {
    cell: Arc<Cell>,
    writes: Arc<WritePolicy>,
    started: Timestamp,
    shutdown: watch::Receiver<bool>,
    guard: Arc<write::Guard>,
    queries: Arc<tokio::sync::Semaphore>,
    streams: Arc<std::sync::atomic::AtomicUsize>,
    /// The device listing of the roster in force ([`AppState::listing`]).
    listing: Arc<std::sync::Mutex<(Arc<crate::cell::Roster>, Arc<listing::Listing>)>>,
    /// Bytes the last full device listing took: the next one's buffer is that big at once.
    listing_size: Arc<std::sync::atomic::AtomicUsize>,
}

impl AppState {
    /// The device listing of the roster in force: made again after a reload changed it.
    fn listing(&self) -> Arc<listing::Listing> {
        let roster = self.cell.roster();
        let mut held = self
            .listing
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if !Arc::ptr_eq(&held.0, &roster) {
            let listing = Arc::new(listing::Listing::new(&roster));
            *held = (roster, listing);
        }
        Arc::clone(&held.1)
    }
}

/// The router over `cell`; event streams end when `shutdown` turns true.
pub fn router(cell: Arc<Cell>, writes: WritePolicy, shutdown: watch::Receiver<bool>) -> Router {
    let roster = cell.roster();
    let listing = Arc::new(listing::Listing::new(&roster));
    tracing::debug!(
        "device listings: {} device descriptions serialised once, {} distinct",
        listing.len(),
        listing.templates()
    );
    let state = AppState {
        listing: Arc::new(std::sync::Mutex::new((roster, listing))),
        listing_size: Arc::default(),
        cell,
        writes: Arc::new(writes),
        started: Timestamp::now(),
        shutdown,
        guard: Arc::default(),
        queries: Arc::new(tokio::sync::Semaphore::new(MAX_CONCURRENT_QUERIES)),
        streams: Arc::default(),
    };
    Router::new()
        .route("/healthz", get(healthz))
        .route("/metrics", get(metrics))
        .route("/api/devices", get(devices))
        .route("/api/devices/{id}", get(device))
        .route(
            "/api/devices/{id}/write",
            post(write::write).layer(DefaultBodyLimit::max(BODY_LIMIT)),
        )
        .route("/api/lines", get(lines))
        .route("/api/history", get(history))
        .route("/api/events", get(events))
        .route("/api/events/stream", get(stream))
        .route("/api/audit", get(audit))
        .route("/api/states", get(production::states))
        .route("/api/production", get(production::production))
        .route("/api/alarms", get(alarms::list))
        .route("/api/alarms/journal", get(alarms::journal))
        .route("/api/alarms/{id}/{action}", post(alarms::act))
        .route("/api/openapi.json", get(openapi))
        .merge(web::routes())
        .fallback(no_route)
        .method_not_allowed_fallback(wrong_method)
        .layer(axum::middleware::from_fn_with_state(
            state.clone(),
            require_read_token,
        ))
        .with_state(state)
}

/// With a read token set, every `/api/` route and `/metrics` need it (or the write token)
/// as `Authorization: Bearer …`, or as `?token=` for an event stream (a browser's
/// EventSource cannot send headers). The page and `/healthz` stay open. A `?token=` is
/// taken off the query before the handlers see it, also where none is needed (a client set
/// up for a read token still reads a gateway without one).
async fn require_read_token(
    State(s): State<AppState>,
    mut request: axum::extract::Request,
    next: axum::middleware::Next,
) -> Response {
    let Some(read) = s.writes.read_token.as_deref() else {
        if let Some(uri) = without_token(request.uri()) {
            *request.uri_mut() = uri;
        }
        return next.run(request).await;
    };
    let path = request.uri().path();
    if !(path.starts_with("/api/") || path == "/metrics") {
        return next.run(request).await;
    }
    let given = write::bearer(request.headers()).or_else(|| query_token(request.uri()));
    let accepted = given.as_deref().is_some_and(|given| {
        write::constant_time_eq(given.as_bytes(), read.as_bytes())
            || s.writes
                .token
                .as_deref()
                .is_some_and(|t| write::constant_time_eq(given.as_bytes(), t.as_bytes()))
    });
    if !accepted {
        let message = if given.is_some() {
            "wrong read token"
        } else {
            "this gateway needs its read token: send Authorization: Bearer <token>"
        };
        return ApiError::new(StatusCode::UNAUTHORIZED, message).into_response();
    }
    // The handlers' queries refuse fields they do not know: the token is not theirs.
    if let Some(uri) = without_token(request.uri()) {
        *request.uri_mut() = uri;
    }
    next.run(request).await
}

/// The `token` query parameter, if any.
fn query_token(uri: &Uri) -> Option<String> {
    url::form_urlencoded::parse(uri.query()?.as_bytes())
        .find(|(k, _)| k == "token")
        .map(|(_, v)| v.into_owned())
}

/// `uri` without its `token` query parameter, if it had one.
fn without_token(uri: &Uri) -> Option<Uri> {
    let query = uri.query()?;
    let pairs: Vec<(String, String)> = url::form_urlencoded::parse(query.as_bytes())
        .into_owned()
        .collect();
    if !pairs.iter().any(|(k, _)| k == "token") {
        return None;
    }
    let rest = url::form_urlencoded::Serializer::new(String::new())
        .extend_pairs(pairs.iter().filter(|(k, _)| k != "token"))
        .finish();
    let path_and_query = if rest.is_empty() {
        uri.path().to_owned()
    } else {
        format!("{}?{rest}", uri.path())
    };
    path_and_query.parse().ok()
}

pub use kit::http::{ApiError, ApiResult};

/// The error for a write body that is not the JSON a write takes (or is too large).
/// A body over [`BODY_LIMIT`].
pub(crate) fn body_too_large() -> ApiError {
    ApiError::new(
        StatusCode::PAYLOAD_TOO_LARGE,
        format!("the request body is larger than {BODY_LIMIT} bytes"),
    )
}

pub(crate) fn body_error(rejection: JsonRejection) -> ApiError {
    if rejection.status() == StatusCode::PAYLOAD_TOO_LARGE {
        return body_too_large();
    }
    ApiError::bad_request(format!(
        "bad request body: {}; send JSON like {{\"point\": \"air_temperature_setpoint\", \"value\": 350}}",
        rejection.body_text()
    ))
}

impl From<crate::store::StoreError> for ApiError {
    fn from(error: crate::store::StoreError) -> Self {
        let status = match error {
            crate::store::StoreError::Unavailable { .. } => StatusCode::SERVICE_UNAVAILABLE,
            _ => StatusCode::INTERNAL_SERVER_ERROR,
        };
        Self::new(status, error.to_string())
    }
}

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

async fn healthz(State(s): State<AppState>) -> Response {
    let devices = s.listing().len();
    let lines = s.cell.lines();
    let store = s.cell.store();
    let stats = store.stats();
    let commit_errors = stats
        .commit_errors
        .load(std::sync::atomic::Ordering::Relaxed);
    let history = store.health(Timestamp::now());
    let (last_error_at, last_error) = history.last_fault.clone().unzip();
    // Each device's status alone (see `health::Facts::of`), read once for both.
    let facts = crate::health::Facts::of(&s.cell, history.history.clone());
    let up = facts
        .devices
        .iter()
        .filter(|(_, status, _)| *status == DeviceStatus::Up)
        .count();
    let judged = crate::health::judge(&facts);
    let mut health = json!({
        "status": judged.status,
        "reasons": judged.reasons,
        "started": s.started,
        "devices": devices,
        "devices_up": up,
        "lines": lines.len(),
        "lines_open": lines.iter().filter(|l| l.state.open).count(),
        "history_rows_written": stats.rows_written(),
        "history_commit_errors": commit_errors,
        "history": history.summary(),
        "history_pending_rows": history.pending_rows,
        "history_rows_dropped": history.rows_dropped,
        "history_last_error": last_error,
        "history_last_error_at": last_error_at,
        "writes_enabled": s.writes.enabled,
        "config": s.cell.config_status(),
    });
    // Each running interface's state under its name (`mqtt`, `opcua`).
    if let Some(object) = health.as_object_mut() {
        for (name, status) in s.cell.interfaces() {
            object.insert(name.to_owned(), status.health());
        }
    }
    let code = if judged.status == crate::health::Status::Failing {
        StatusCode::SERVICE_UNAVAILABLE
    } else {
        StatusCode::OK
    };
    (code, Json(health)).into_response()
}

async fn metrics(State(s): State<AppState>) -> Response {
    for (_, status) in s.cell.interfaces() {
        status.before_scrape();
    }
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

/// Query of `/api/devices`: which devices, which of their fields, which page.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct DevicesQuery {
    /// Only the devices on this line.
    line: Option<String>,
    /// Only these devices (ids separated by commas).
    device: Option<String>,
    /// Only these fields of each device (names separated by commas; `id` always).
    fields: Option<String>,
    /// Devices to skip (after the filters).
    offset: Option<usize>,
    /// Most devices to return.
    limit: Option<usize>,
}

/// Devices past which a listing is written on a blocking thread, not a runtime worker
/// (1,000 devices take milliseconds the pollers should not wait for).
const BLOCKING_LISTING: usize = 50;

async fn devices(
    State(s): State<AppState>,
    query: Result<Query<DevicesQuery>, QueryRejection>,
) -> ApiResult<Response> {
    let Query(q) = query?;
    let selection = Selection::new(&s.cell, q.line.as_deref(), q.device.as_deref())?;
    let fields = match q.fields.as_deref() {
        None => listing::Fields::ALL,
        Some(list) => listing::Fields::parse(list).map_err(|unknown| {
            ApiError::bad_request(format!(
                "fields: no device field {unknown:?}; fields: {}",
                listing::Field::NAMES.join(", ")
            ))
        })?,
    };
    let (offset, limit) = (q.offset.unwrap_or(0), q.limit.unwrap_or(usize::MAX));
    let writes_enabled = s.writes.enabled;
    let full = fields == listing::Fields::ALL
        && selection.ids.is_none()
        && (offset, limit) == (0, usize::MAX);
    let listing = s.listing();
    let blocking = listing.len() > BLOCKING_LISTING;
    let write = move || {
        let total = listing
            .entries()
            .filter(|d| selection.contains(d.id()))
            .count();
        let page = listing
            .entries()
            .filter(|d| selection.contains(d.id()))
            .skip(offset)
            .take(limit);
        let sized = std::sync::atomic::Ordering::Relaxed;
        let mut out = Vec::with_capacity(if full {
            listing::capacity(s.listing_size.load(sized), listing.size_estimate())
        } else {
            4096
        });
        listing::devices_array(&mut out, page, fields, Timestamp::now());
        listing::field(&mut out, "total", &total, false);
        listing::field(&mut out, "writes_enabled", &writes_enabled, true);
        if full {
            s.listing_size.store(out.len(), sized);
        }
        json_response(out)
    };
    if !blocking {
        return Ok(write());
    }
    tokio::task::spawn_blocking(write)
        .await
        .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()))
}

/// A JSON answer from bytes already written.
fn json_response(body: Vec<u8>) -> Response {
    (
        [(
            header::CONTENT_TYPE,
            HeaderValue::from_static("application/json"),
        )],
        body,
    )
        .into_response()
}

/// The devices a request names: those on `line` among the ids listed in `device` (ids
/// separated by commas; an empty list names none), each filter only when given.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Selection {
    /// The selected ids; `None`: every device.
    ids: Option<std::collections::HashSet<String>>,
}

impl Selection {
    /// Checks the filters against `cell`: an unknown line or device is a 404 naming those
    /// there are.
    fn new(cell: &Cell, line: Option<&str>, device: Option<&str>) -> ApiResult<Selection> {
        if let Some(line) = line
            && !cell.device_entries().any(|d| d.line == line)
        {
            let lines: Vec<String> = cell.lines().into_iter().map(|l| l.name).collect();
            return Err(ApiError::not_found(format!(
                "no line {:?}; lines: {}",
                crate::write::cut(line, crate::write::MAX_NAME),
                lines.join(", ")
            )));
        }
        let wanted: Option<Vec<&str>> = device.map(|d| {
            d.split(',')
                .map(str::trim)
                .filter(|id| !id.is_empty())
                .collect()
        });
        if let Some(missing) = wanted
            .iter()
            .flatten()
            .find(|id| cell.device_entry(id).is_none())
        {
            return Err(unknown_device(cell, missing));
        }
        if line.is_none() && wanted.is_none() {
            return Ok(Selection { ids: None });
        }
        let ids = cell
            .device_entries()
            .filter(|d| line.is_none_or(|line| d.line == line))
            .filter(|d| {
                wanted
                    .as_ref()
                    .is_none_or(|ids| ids.contains(&d.id.as_str()))
            })
            .map(|d| d.id.to_string())
            .collect();
        Ok(Selection { ids: Some(ids) })
    }

    /// Whether the device `id` is selected.
    fn contains(&self, id: &str) -> bool {
        self.ids.as_ref().is_none_or(|ids| ids.contains(id))
    }

    /// Whether a live message concerns a selected device (events are the cell's, always).
    fn passes(&self, message: &LiveMessage) -> bool {
        match message {
            LiveMessage::Value(point) => self.contains(point.id.device()),
            LiveMessage::Device(device) => self.contains(device.id.as_str()),
            LiveMessage::Event(_) => true,
        }
    }
}

async fn device(State(s): State<AppState>, DeviceIdPath(id): DeviceIdPath) -> ApiResult<Response> {
    let listing = s.listing();
    let device = listing
        .get(&id)
        .ok_or_else(|| unknown_device(&s.cell, &id))?;
    let mut out = Vec::with_capacity(16 << 10);
    device.write(&mut out, listing::Fields::ALL, Timestamp::now());
    Ok(json_response(out))
}

/// Query of `/api/lines`.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct LinesQuery {
    /// Only these lines (names separated by commas).
    line: Option<String>,
}

async fn lines(
    State(s): State<AppState>,
    query: Result<Query<LinesQuery>, QueryRejection>,
) -> ApiResult<Json<serde_json::Value>> {
    let Query(q) = query?;
    let mut lines = s.cell.lines();
    if let Some(wanted) = q.line.as_deref() {
        let wanted: Vec<&str> = wanted
            .split(',')
            .map(str::trim)
            .filter(|l| !l.is_empty())
            .collect();
        if let Some(unknown) = wanted.iter().find(|w| !lines.iter().any(|l| l.name == **w)) {
            let names: Vec<&str> = lines.iter().map(|l| l.name.as_str()).collect();
            return Err(ApiError::not_found(format!(
                "no line {:?}; lines: {}",
                crate::write::cut(unknown, crate::write::MAX_NAME),
                names.join(", ")
            )));
        }
        lines.retain(|l| wanted.contains(&l.name.as_str()));
    }
    Ok(Json(json!({ "lines": lines })))
}

/// How many device ids a "no device" answer lists before it points to the listing.
const KNOWN_LISTED: usize = 20;

/// A 404 for `id` (cut to [`MAX_NAME`](crate::write::MAX_NAME) bytes) with the first
/// [`KNOWN_LISTED`] devices: a cell of thousands answers a typo in a line, not in 50 kB.
/// A query's `device`, when it names one, must be a device of the cell.
fn known_device(cell: &Cell, device: Option<&str>) -> ApiResult<()> {
    match device {
        Some(device) if cell.device_entry(device).is_none() => Err(unknown_device(cell, device)),
        _ => Ok(()),
    }
}

fn unknown_device(cell: &Cell, id: &str) -> ApiError {
    let total = cell.device_entries().count();
    let first: Vec<String> = cell
        .device_entries()
        .take(KNOWN_LISTED)
        .map(|d| d.id.to_string())
        .collect();
    let known = match total {
        0 => "none".to_owned(),
        n if n <= KNOWN_LISTED => first.join(", "),
        n => format!(
            "{}, … ({n} in all; GET /api/devices?fields=line lists them)",
            first.join(", ")
        ),
    };
    ApiError::not_found(format!(
        "no device {:?}; devices: {known}",
        crate::write::cut(id, crate::write::MAX_NAME)
    ))
}

/// The point a history query names, as written (whether the cell has it is the handler's
/// question).
pub(crate) fn history_point(q: &HistoryQuery) -> ApiResult<PointId> {
    let point = q.point.as_deref().ok_or_else(|| {
        ApiError::bad_request("give the point: /api/history?point=jbc1.air_temperature&from=-1h")
    })?;
    PointId::parse(point).map_err(|e| ApiError::bad_request(e.to_string()))
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
    let history = run_query(&s, move |store| store.history(&point, from, to, step)).await?;
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

/// Runs a query of the history on a blocking thread, at most [`MAX_CONCURRENT_QUERIES`] at once.
async fn run_query<T: Send + 'static>(
    s: &AppState,
    run: impl FnOnce(crate::store::StoreHandle) -> Result<T, crate::store::StoreError> + Send + 'static,
) -> ApiResult<T> {
    run_query_on(&s.queries, s.cell.store().clone(), run).await
}

/// Runs `run` on a blocking thread once one of `turns` is free. The turn is held by the
/// blocking thread, not by the caller: a client that hangs up drops the caller, but its
/// query runs on, and still counts, until it ends.
async fn run_query_on<T: Send + 'static>(
    turns: &Arc<tokio::sync::Semaphore>,
    store: crate::store::StoreHandle,
    run: impl FnOnce(crate::store::StoreHandle) -> Result<T, crate::store::StoreError> + Send + 'static,
) -> ApiResult<T> {
    let busy = || {
        ApiError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            format!(
                "the history is busy with {MAX_CONCURRENT_QUERIES} other queries; try again shortly"
            ),
        )
    };
    let turn = tokio::time::timeout(QUERY_WAIT, Arc::clone(turns).acquire_owned())
        .await
        .map_err(|_| busy())?
        .map_err(|_| busy())?;
    tokio::task::spawn_blocking(move || {
        let _turn = turn;
        run(store)
    })
    .await
    .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()))?
    .map_err(ApiError::from)
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
    let from = parse_time("from", q.from.as_deref(), now)?;
    let to = parse_time("to", q.to.as_deref(), now)?;
    if let (Some(from), Some(to)) = (from, to)
        && from > to
    {
        return Err(ApiError::bad_request(format!(
            "from ({from}) must not be after to ({to})"
        )));
    }
    Ok(EventFilter {
        from,
        to,
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
    known_device(&s.cell, q.device.as_deref())?;
    let filter = events_filter(q, Timestamp::now())?;
    let events = run_query(&s, move |store| store.events(&filter)).await?;
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
    let rows = run_query(&s, move |store| store.audit_log(q.device.as_deref(), limit)).await?;
    let rows = rows
        .into_iter()
        .map(serde_json::to_value)
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()))?;
    let (kept, truncated) = bounded_by_bytes(rows, MAX_AUDIT_BYTES);
    Ok(Json(json!({ "audit": kept, "truncated": truncated })).into_response())
}

async fn openapi() -> Response {
    ([(header::CONTENT_TYPE, "application/json")], OPENAPI).into_response()
}

/// One item of an event stream.
enum StreamItem {
    Live(Result<LiveMessage, u64>),
    Stop(bool),
}

/// Query of `/api/events/stream`: which devices' snapshot and changes to send.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct StreamQuery {
    /// Only the devices on this line.
    line: Option<String>,
    /// Only these devices (ids separated by commas).
    device: Option<String>,
}

async fn stream(
    State(s): State<AppState>,
    query: Result<Query<StreamQuery>, QueryRejection>,
) -> ApiResult<Sse<impl Stream<Item = Result<SseEvent, Infallible>>>> {
    let Query(q) = query?;
    let selection = Selection::new(&s.cell, q.line.as_deref(), q.device.as_deref())?;
    let guard = ClientGuard::new(Arc::clone(&s.cell), Arc::clone(&s.streams)).ok_or_else(|| {
        ApiError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            format!(
                "{MAX_EVENT_STREAMS} event streams are open, the most allowed; try again later"
            ),
        )
    })?;
    // Subscribe before the snapshot, so no change falls between the two.
    let live = tokio_stream::wrappers::BroadcastStream::new(s.cell.subscribe()).map(|m| {
        StreamItem::Live(
            m.map_err(|tokio_stream::wrappers::errors::BroadcastStreamRecvError::Lagged(n)| n),
        )
    });
    let mut snapshot = Vec::new();
    listing::devices_array(
        &mut snapshot,
        s.listing().entries().filter(|d| selection.contains(d.id())),
        listing::Fields::ALL,
        Timestamp::now(),
    );
    listing::field(&mut snapshot, "lines", &s.cell.lines(), false);
    listing::field(&mut snapshot, "writes_enabled", &s.writes.enabled, true);
    let first = SseEvent::default()
        .event("snapshot")
        .data(String::from_utf8_lossy(&snapshot));
    let stop = tokio_stream::wrappers::WatchStream::new(s.shutdown.clone()).map(StreamItem::Stop);
    let mut lagged = false;
    let events = live
        .merge(stop)
        .take_while(|item| !matches!(item, StreamItem::Stop(true)))
        .map_while(move |item| {
            let _alive = &guard;
            if lagged {
                return None;
            }
            Some(match item {
                // Changes of devices the client did not ask for are not sent.
                StreamItem::Live(Ok(message)) if !selection.passes(&message) => None,
                StreamItem::Live(Ok(message)) => Some(
                    SseEvent::default()
                        .event(message.name())
                        .json_data(&message)
                        .unwrap_or_else(|e| SseEvent::default().event("error").data(e.to_string())),
                ),
                // The client fell behind (its buffer filled): tell it, and end the stream; an
                // EventSource reconnects and starts again from a fresh snapshot.
                StreamItem::Live(Err(missed)) => {
                    lagged = true;
                    Some(
                        SseEvent::default()
                            .event("lagged")
                            .data(json!({ "missed": missed }).to_string()),
                    )
                }
                StreamItem::Stop(_) => None,
            })
        })
        .filter_map(|event| event);
    let all = tokio_stream::once(first).chain(events).map(Ok);
    Ok(Sse::new(all).keep_alive(KeepAlive::default()))
}

/// Counts open event streams; at most [`MAX_EVENT_STREAMS`].
struct ClientGuard {
    cell: Arc<Cell>,
    open: Arc<std::sync::atomic::AtomicUsize>,
}

impl ClientGuard {
    /// A place for one more stream, if there is one.
    fn new(cell: Arc<Cell>, open: Arc<std::sync::atomic::AtomicUsize>) -> Option<Self> {
        use std::sync::atomic::Ordering;
        open.fetch_update(Ordering::SeqCst, Ordering::SeqCst, |n| {
            (n < MAX_EVENT_STREAMS).then_some(n + 1)
        })
        .ok()?;
        cell.metrics().sse_clients.inc();
        Some(Self { cell, open })
    }
}

impl Drop for ClientGuard {
    fn drop(&mut self) {
        self.open.fetch_sub(1, std::sync::atomic::Ordering::SeqCst);
        self.cell.metrics().sse_clients.dec();
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

/// The `{id}` of a device's route; a path that is not one (`%ff`, not UTF-8) is a JSON
/// `400` like every other refusal, not axum's plain text.
struct DeviceIdPath(String);

impl<S: Send + Sync> FromRequestParts<S> for DeviceIdPath {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, ApiError> {
        match Path::<String>::from_request_parts(parts, state).await {
            Ok(Path(id)) => Ok(DeviceIdPath(id)),
            Err(rejection) => Err(ApiError::bad_request(format!(
                "the device id in the path is not one: {}",
                rejection.body_text()
            ))),
        }
    }
}

#[cfg(test)]
mod tests;
