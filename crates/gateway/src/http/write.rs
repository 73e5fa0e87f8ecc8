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
use axum::extract::{FromRequest, Request, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use serde_json::json;
use tokio::time::Instant;

use super::{ApiError, ApiResult, AppState, ClientAddr, DeviceIdPath, unknown_device};
use crate::cell::Cell;
use crate::driver::{ErrorKind, WriteError};
use crate::point::{PointId, Value};
use crate::write::{Attempt, LOG_EVERY, MAX_NAME, MAX_VALUE, Unauthorised, cut};

/// 2^53: whole numbers up to it are exact as the double every written value is.
const MAX_EXACT: u64 = 1 << 53;

/// Largest write request body accepted.
pub const BODY_LIMIT: usize = 4096;
/// How long an authorised write's body may take to arrive (a client that sends the
/// headers and then nothing must not hold a connection for ever).
pub const BODY_TIMEOUT: Duration = Duration::from_secs(10);
/// Wrong tokens one client address may send within [`FAILURE_WINDOW`].
pub const MAX_TOKEN_FAILURES: u32 = 5;
/// The window over which wrong tokens are counted.
pub const FAILURE_WINDOW: Duration = Duration::from_secs(60);
/// Client addresses whose wrong tokens are remembered at once.
const MAX_TRACKED_CLIENTS: usize = 4096;

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
    unauthorised: Unauthorised,
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

    /// Counts an unauthorised attempt and logs it, at most once every [`LOG_EVERY`] (with
    /// the count).
    fn refused(&self, cell: &Cell, client: &str, why: &str, now: Instant) {
        let Some(count) = self.lock().unauthorised.refused(cell, now) else {
            return;
        };
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

/// Reads the write's JSON body: at most [`BODY_LIMIT`] bytes (the route's
/// `DefaultBodyLimit`), within [`BODY_TIMEOUT`].
async fn read_body(request: Request) -> Result<Json<WriteBody>, ApiError> {
    match tokio::time::timeout(BODY_TIMEOUT, Json::<WriteBody>::from_request(request, &())).await {
        Ok(Ok(body)) => Ok(body),
        Ok(Err(rejection)) => Err(super::body_error(rejection)),
        Err(_) => Err(body_too_slow()),
    }
}

/// A body that did not arrive within [`BODY_TIMEOUT`].
pub(super) fn body_too_slow() -> ApiError {
    ApiError::new(
        StatusCode::REQUEST_TIMEOUT,
        format!(
            "the request body did not arrive within {} s",
            BODY_TIMEOUT.as_secs()
        ),
    )
}

/// The handler. The body is read only once the caller is authorised (step 1 of the module
/// docs), and within [`BODY_TIMEOUT`].
pub(super) async fn write(
    State(s): State<AppState>,
    ClientAddr(client): ClientAddr,
    DeviceIdPath(id): DeviceIdPath,
    headers: HeaderMap,
    request: Request,
) -> ApiResult<Response> {
    if let Err(refused) = authorise(&s, &client, &headers) {
        return Ok(*refused);
    }

    // Authorised from here on: every attempt is audited.
    let body = read_body(request).await;
    let (point_text, new) = match &body {
        Ok(Json(b)) => (b.point.clone(), b.value.clone()),
        Err(_) => (String::new(), serde_json::Value::Null),
    };
    let mut attempt = Attempt::new(Arc::clone(&s.cell), client, id.clone(), point_text, new);
    let Some(device) = s.cell.device_entry(&id) else {
        return Err(refuse(&attempt, unknown_device(&s.cell, &id)).await);
    };
    let Json(body) = match body {
        Ok(body) => body,
        Err(error) => return Err(refuse(&attempt, error).await),
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
            return Err(refuse(&attempt, error).await);
        }
    };
    attempt.names(&point);
    // Whole numbers beyond 2^53 do not survive as the double every value is: the device
    // would get a neighbour of the number asked for.
    if let serde_json::Value::Number(n) = &body.value
        && (n.as_u64().is_some_and(|n| n > MAX_EXACT)
            || n.as_i64().is_some_and(|n| n < -(MAX_EXACT as i64)))
    {
        let error = ApiError::bad_request(format!(
            "value {n} is beyond {MAX_EXACT}, the largest whole number a write carries exactly"
        ));
        return Err(refuse(&attempt, error).await);
    }
    let value = match &body.value {
        // A coil or on/off point: true is 1, false 0.
        serde_json::Value::Bool(on) => Ok(Value::Number(if *on { 1.0 } else { 0.0 })),
        other => serde_json::from_value::<Value>(other.clone()),
    };
    let Ok(value) = value else {
        let error = ApiError::bad_request(format!(
            "value must be a number, a string or true/false, not {}",
            cut(&body.value.to_string(), MAX_VALUE)
        ));
        return Err(refuse(&attempt, error).await);
    };
    // The write and its record run to the end even if the client leaves.
    let task = tokio::spawn(attempt.carry_out(point, value));
    let accepted = task
        .await
        .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()))??;
    Ok(Json(json!({
        "device": accepted.point.device(),
        "point": accepted.point,
        "old": accepted.old,
        "new": accepted.new,
        "result": "accepted",
        "detail": accepted.detail,
    }))
    .into_response())
}

/// Records a refusal before the wire and gives the error to answer with.
async fn refuse(attempt: &Attempt, error: ApiError) -> ApiError {
    attempt.refuse(&error.message, None).await;
    error
}

/// Counts and (throttled) logs an unauthorised attempt; nothing is stored.
fn unauthorised(s: &AppState, client: &str, error: ApiError, now: Instant) -> ApiError {
    s.guard.refused(&s.cell, client, &error.message, now);
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

/// Step 1 of the module docs, shared by every route that acts (a write, an action on an
/// alarm): writes on, the address not locked out, the token right. A refusal is the
/// response to send, counted and logged as such refusals are.
pub(super) fn authorise(
    s: &AppState,
    client: &str,
    headers: &HeaderMap,
) -> Result<(), Box<Response>> {
    let now = Instant::now();
    let addr = client.parse::<std::net::SocketAddr>().ok().map(|a| a.ip());
    if !s.writes.enabled {
        let error = ApiError::new(
            StatusCode::FORBIDDEN,
            "writes are disabled on this gateway; start it with --allow-writes (and a token)",
        );
        return Err(Box::new(
            unauthorised(s, client, error, now).into_response(),
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
        let mut response = unauthorised(s, client, error, now).into_response();
        if let Ok(value) = HeaderValue::from_str(&wait.as_secs().max(1).to_string()) {
            response.headers_mut().insert(header::RETRY_AFTER, value);
        }
        return Err(Box::new(response));
    }
    if let Err(error) = check_token(headers, s.writes.token.as_deref()) {
        // Only a token sent counts as a guess: clients behind one address (a proxy, NAT)
        // that forget the header do not lock each other out.
        if error.status == StatusCode::UNAUTHORIZED && headers.contains_key(header::AUTHORIZATION) {
            s.guard.failed(addr, now);
        }
        return Err(Box::new(
            unauthorised(s, client, error, now).into_response(),
        ));
    }
    Ok(())
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
