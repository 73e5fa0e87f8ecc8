//! `POST /api/devices/{id}/write`: the one guarded path from a client to a device.
//!
//! The order of the checks says what a caller learns and what costs the gateway anything:
//!
//! 1. Writes off, a client address that guessed wrong too often, a missing or wrong token:
//!    refused before the body is read or anything is stored. Such refusals only count
//!    (`cellbus_writes_total{result="unauthorised"}`) and leave at most one log line every
//!    [`LOG_EVERY`], because anyone who can reach the port can send them by the thousand.
//!    A client address that sent [`MAX_TOKEN_FAILURES`] wrong tokens within
//!    [`FAILURE_WINDOW`] gets `429` until the window has passed.
//! 2. Authorised: an unknown device, a malformed body (at most [`BODY_LIMIT`] bytes), an
//!    unknown or read-only point, a value outside the point's range are refused before the
//!    wire, each with one audit row.
//! 3. A valid write: an `attempted` audit row is committed before the write goes to the
//!    line, then the write runs in a task of its own and a second row records how it
//!    ended. A client that gives up waiting does not stop the write or its record.
//!
//! Every stored field is cut to a bounded length, so no request can grow the audit table by
//! more than a few kB.

use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use axum::Json;
use axum::extract::rejection::JsonRejection;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use serde_json::json;
use tokio::time::Instant;

use super::{ApiError, ApiResult, AppState, ClientAddr, unknown_device};
use crate::cell::Cell;
use crate::driver::{ErrorKind, WriteError};
use crate::event::{Event, EventKind};
use crate::point::{PointId, Value};
use crate::store::{AuditEntry, AuditResult};
use crate::time::Timestamp;

/// Largest write request body accepted.
pub const BODY_LIMIT: usize = 4096;
/// Wrong tokens one client address may send within [`FAILURE_WINDOW`].
pub const MAX_TOKEN_FAILURES: u32 = 5;
/// The window over which wrong tokens are counted.
pub const FAILURE_WINDOW: Duration = Duration::from_secs(60);
/// At most one log line about unauthorised writes this often.
pub const LOG_EVERY: Duration = Duration::from_secs(10);
/// Client addresses whose wrong tokens are remembered at once.
const MAX_TRACKED_CLIENTS: usize = 4096;

/// Longest stored text of a client address, device or point as the request named them.
const MAX_NAME: usize = 128;
/// Longest stored value as given (its JSON text).
const MAX_VALUE: usize = 256;
/// Longest stored detail.
const MAX_DETAIL: usize = 1024;

/// Body of a write.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct WriteBody {
    point: String,
    value: serde_json::Value,
}

/// Unauthorised attempts: wrong tokens per client address, and the log throttle.
#[derive(Debug, Default)]
pub(super) struct Guard {
    inner: Mutex<GuardState>,
}

#[derive(Debug, Default)]
struct GuardState {
    failures: HashMap<IpAddr, Failures>,
    last_log: Option<Instant>,
    unlogged: u64,
}

#[derive(Debug, Clone, Copy)]
struct Failures {
    since: Instant,
    count: u32,
}

impl Guard {
    /// How long `addr` must still wait, if it guessed wrong too often.
    fn blocked(&self, addr: Option<IpAddr>, now: Instant) -> Option<Duration> {
        let state = self.lock();
        let failures = state.failures.get(&addr?)?;
        let ends = failures.since + FAILURE_WINDOW;
        (failures.count >= MAX_TOKEN_FAILURES && ends > now).then(|| ends - now)
    }

    /// Counts a wrong token from `addr`.
    fn failed(&self, addr: Option<IpAddr>, now: Instant) {
        let Some(addr) = addr else { return };
        let mut state = self.lock();
        if state.failures.len() >= MAX_TRACKED_CLIENTS {
            state.failures.retain(|_, f| f.since + FAILURE_WINDOW > now);
        }
        if state.failures.len() >= MAX_TRACKED_CLIENTS && !state.failures.contains_key(&addr) {
            return;
        }
        let entry = state.failures.entry(addr).or_insert(Failures {
            since: now,
            count: 0,
        });
        if entry.since + FAILURE_WINDOW <= now {
            *entry = Failures {
                since: now,
                count: 0,
            };
        }
        entry.count += 1;
    }

    /// Logs an unauthorised attempt, at most once every [`LOG_EVERY`] (with the count).
    fn log(&self, client: &str, why: &str, now: Instant) {
        let mut state = self.lock();
        state.unlogged += 1;
        if state.last_log.is_some_and(|t| now < t + LOG_EVERY) {
            return;
        }
        let count = std::mem::take(&mut state.unlogged);
        state.last_log = Some(now);
        tracing::warn!(
            "refused {count} unauthorised write(s) in the last {} s; the latest from {}: {}",
            LOG_EVERY.as_secs(),
            cut(client, MAX_NAME),
            why
        );
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, GuardState> {
        self.inner.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// The handler.
pub(super) async fn write(
    State(s): State<AppState>,
    ClientAddr(client): ClientAddr,
    Path(id): Path<String>,
    headers: HeaderMap,
    body: Result<Json<WriteBody>, JsonRejection>,
) -> ApiResult<Response> {
    let now = Instant::now();
    let addr = client.parse::<std::net::SocketAddr>().ok().map(|a| a.ip());
    if !s.writes.enabled {
        return Err(unauthorised(
            &s,
            &client,
            ApiError::new(
                StatusCode::FORBIDDEN,
                "writes are disabled on this gateway; start it with --allow-writes (and a token)",
            ),
            now,
        ));
    }
    if let Some(wait) = s.guard.blocked(addr, now) {
        let error = ApiError::new(
            StatusCode::TOO_MANY_REQUESTS,
            format!(
                "too many wrong tokens from this address; try again in {} s",
                wait.as_secs().max(1)
            ),
        );
        let mut response = unauthorised(&s, &client, error, now).into_response();
        if let Ok(value) = HeaderValue::from_str(&wait.as_secs().max(1).to_string()) {
            response.headers_mut().insert(header::RETRY_AFTER, value);
        }
        return Ok(response);
    }
    if let Err(error) = check_token(&headers, s.writes.token.as_deref()) {
        if error.status == StatusCode::UNAUTHORIZED {
            s.guard.failed(addr, now);
        }
        return Err(unauthorised(&s, &client, error, now));
    }

    // Authorised from here on: every attempt is audited.
    let (point_text, new) = match &body {
        Ok(Json(b)) => (b.point.clone(), b.value.clone()),
        Err(_) => (String::new(), serde_json::Value::Null),
    };
    let mut attempt = Attempt {
        cell: Arc::clone(&s.cell),
        client,
        device: id.clone(),
        point: point_text,
        new,
    };
    let Some(device) = s.cell.device_entry(&id) else {
        return Err(attempt.refuse(unknown_device(&s.cell, &id), None).await);
    };
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
                cut(&body.point, MAX_NAME),
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
                cut(&body.value.to_string(), MAX_VALUE)
            ));
            return Err(attempt.refuse(error, None).await);
        }
    };
    let old = device
        .point_index(&name)
        .and_then(|i| device.read().points.get(i).and_then(|p| p.value.clone()));
    // A value outside the point's range never reaches the wire, nor an `attempted` row.
    if let Some(spec) = s.cell.point(&point)
        && let Err(e) = spec.check_write(&value)
    {
        let error = super::ApiError::from(WriteError::Invalid(e));
        return Err(attempt.refuse(error, old).await);
    }
    // The write and its record run to the end even if the client leaves.
    let task = tokio::spawn(async move { attempt.carry_out(point, value, old).await });
    task.await
        .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()))?
}

/// Counts and (throttled) logs an unauthorised attempt; nothing is stored.
fn unauthorised(s: &AppState, client: &str, error: ApiError, now: Instant) -> ApiError {
    s.cell
        .metrics()
        .writes
        .get_or_create(&crate::metrics::WriteLabels {
            result: "unauthorised".to_owned(),
        })
        .inc();
    s.guard.log(client, &error.message, now);
    error
}

impl From<WriteError> for ApiError {
    fn from(error: WriteError) -> Self {
        let status = match &error {
            WriteError::Invalid(_) => StatusCode::BAD_REQUEST,
            // The protocol crate refused to build the request: it never reached the device.
            WriteError::Device(e) if e.kind == ErrorKind::Usage => StatusCode::BAD_REQUEST,
            WriteError::UnknownPoint { .. } => StatusCode::NOT_FOUND,
            WriteError::Device(e) if e.kind == ErrorKind::Timeout => StatusCode::GATEWAY_TIMEOUT,
            WriteError::Device(_) => StatusCode::BAD_GATEWAY,
            _ => StatusCode::SERVICE_UNAVAILABLE,
        };
        ApiError::new(status, error.to_string())
    }
}

/// A write attempt on its way to the audit table.
struct Attempt {
    cell: Arc<Cell>,
    client: String,
    device: String,
    point: String,
    new: serde_json::Value,
}

impl Attempt {
    /// Records a refusal before the wire and returns the error to answer with.
    async fn refuse(&self, error: ApiError, old: Option<Value>) -> ApiError {
        self.record(AuditResult::Refused, old, &error.message).await;
        error
    }

    /// Records the attempt, writes, records how it ended, and gives the answer.
    async fn carry_out(
        self,
        point: PointId,
        value: Value,
        old: Option<Value>,
    ) -> ApiResult<Response> {
        let asked = format!("{point} to be set to {value} by {}", self.client);
        self.record(AuditResult::Attempted, old.clone(), &asked)
            .await;
        match self.cell.write(&point, &value).await {
            Ok(outcome) => {
                let spec = self.cell.point(&point);
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
                    self.client
                );
                let device = self.cell.device_entry(point.device());
                self.cell.emit(Event {
                    t: Timestamp::now(),
                    kind: EventKind::Write,
                    line: device.map(|d| d.line.clone()),
                    device: device.map(|d| d.id.clone()),
                    point: Some(point.clone()),
                    message: detail.clone(),
                });
                self.record(AuditResult::Accepted, outcome.old.clone(), &detail)
                    .await;
                Ok(Json(json!({
                    "device": point.device(),
                    "point": point,
                    "old": outcome.old,
                    "new": outcome.new,
                    "result": "accepted",
                    "detail": detail,
                }))
                .into_response())
            }
            Err(error) => {
                let result = match &error {
                    WriteError::Invalid(_) | WriteError::UnknownPoint { .. } => {
                        AuditResult::Refused
                    }
                    WriteError::Device(e) if e.kind == ErrorKind::Usage => AuditResult::Refused,
                    WriteError::Device(e) if e.kind == ErrorKind::Refused => AuditResult::Refused,
                    _ => AuditResult::Failed,
                };
                let error = ApiError::from(error);
                self.record(result, old, &error.message).await;
                Err(error)
            }
        }
    }

    /// Writes the audit row and waits for its commit, so an answered request is on disk.
    async fn record(&self, result: AuditResult, old: Option<Value>, detail: &str) {
        let store = self.cell.store();
        let new = match &self.new {
            serde_json::Value::String(text) => serde_json::Value::String(cut(text, MAX_VALUE)),
            other => {
                let text = other.to_string();
                if text.len() > MAX_VALUE {
                    serde_json::Value::String(cut(&text, MAX_VALUE))
                } else {
                    other.clone()
                }
            }
        };
        store.audit(AuditEntry {
            t: Timestamp::now(),
            client: cut(&self.client, MAX_NAME),
            device: cut(&self.device, MAX_NAME),
            point: cut(&self.point, MAX_NAME),
            old,
            new,
            result,
            detail: cut(detail, MAX_DETAIL),
        });
        self.cell
            .metrics()
            .writes
            .get_or_create(&crate::metrics::WriteLabels {
                result: result.as_str().to_owned(),
            })
            .inc();
        if let Err(e) = store.flush().await {
            tracing::error!("audit row not committed: {e}");
        }
    }
}

/// `text` cut to at most `max` bytes (on a character boundary), with `…` when cut.
pub(super) fn cut(text: &str, max: usize) -> String {
    if text.len() <= max {
        return text.to_owned();
    }
    let mut end = max.saturating_sub('…'.len_utf8());
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    format!("{}…", &text[..end])
}

/// Checks `Authorization: Bearer <token>`.
pub(super) fn check_token(headers: &HeaderMap, token: Option<&str>) -> ApiResult<()> {
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
    let given = bearer_value(value).ok_or_else(|| {
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

/// The token of an `Authorization: Bearer <token>` header.
pub(super) fn bearer(headers: &HeaderMap) -> Option<String> {
    bearer_value(headers.get(header::AUTHORIZATION)?).map(str::to_owned)
}

fn bearer_value(value: &HeaderValue) -> Option<&str> {
    let (scheme, rest) = value.to_str().ok()?.trim().split_once(' ')?;
    scheme.eq_ignore_ascii_case("bearer").then(|| rest.trim())
}

/// Compares without stopping at the first difference, so timing does not leak the token.
pub(super) fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    let mut diff = a.len() ^ b.len();
    for (i, x) in a.iter().enumerate() {
        diff |= usize::from(x ^ b.get(i % b.len().max(1)).copied().unwrap_or(0));
    }
    diff == 0
}
