//! The alarms over HTTP: `GET /api/alarms` (the list: every alarm active, unacknowledged,
//! shelved or out of service), `GET /api/alarms/journal` (what happened to them, with who
//! and the comment) and `POST /api/alarms/{id}/ack|shelve|unshelve|out_of_service|in_service`,
//! which need what a write needs (`--allow-writes` and the token: `write::authorise`).

use std::time::Duration;

use axum::Json;
use axum::body::to_bytes;
use axum::extract::rejection::QueryRejection;
use axum::extract::{Path, Query, Request, State};
use axum::http::{HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use serde_json::json;

use super::write::{BODY_LIMIT, BODY_TIMEOUT, authorise, body_too_slow};
use super::{
    ApiError, ApiResult, AppState, ClientAddr, body_too_large, check_limit, known_device,
    parse_time,
};
use crate::alarm::Priority;
use crate::alarm::book::{ActError, Action, ListFilter};
use crate::alarm::state::MAX_SHELVE;
use crate::time::Timestamp;
use crate::write::{MAX_NAME, cut};

/// Query of `/api/alarms`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ListQuery {
    device: Option<String>,
    priority: Option<String>,
    limit: Option<usize>,
    offset: Option<usize>,
}

/// A priority as a query gives it (`high` or 3).
fn priority(text: Option<&str>) -> ApiResult<Option<Priority>> {
    text.map(|p| {
        Priority::parse(p).ok_or_else(|| {
            ApiError::bad_request(format!(
                "priority {:?} is not one of low, medium, high, urgent (or 1 to 4)",
                cut(p, MAX_NAME)
            ))
        })
    })
    .transpose()
}

/// `GET /api/alarms`.
pub(super) async fn list(
    State(s): State<AppState>,
    query: Result<Query<ListQuery>, QueryRejection>,
) -> ApiResult<Response> {
    let Query(q) = query?;
    known_device(&s.cell, q.device.as_deref())?;
    let filter = ListFilter {
        priority: priority(q.priority.as_deref())?,
        device: q.device,
        offset: q.offset.unwrap_or(0),
        limit: check_limit(q.limit)?,
    };
    let page = s.cell.alarms.list(&filter);
    let counts = s.cell.alarms.counts();
    Ok(Json(json!({
        "alarms": page.alarms,
        "total": page.total,
        "offset": filter.offset,
        "counts": counts,
    }))
    .into_response())
}

/// Query of `/api/alarms/journal`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct JournalQuery {
    from: Option<String>,
    to: Option<String>,
    alarm: Option<String>,
    device: Option<String>,
    limit: Option<usize>,
}

/// `GET /api/alarms/journal`: newest first.
pub(super) async fn journal(
    State(s): State<AppState>,
    query: Result<Query<JournalQuery>, QueryRejection>,
) -> ApiResult<Response> {
    let Query(q) = query?;
    known_device(&s.cell, q.device.as_deref())?;
    let now = Timestamp::now();
    let from = parse_time("from", q.from.as_deref(), now)?.unwrap_or(Timestamp(i64::MIN));
    let to = parse_time("to", q.to.as_deref(), now)?.unwrap_or(Timestamp(i64::MAX));
    if from > to {
        return Err(ApiError::bad_request(format!(
            "from ({from}) must not be after to ({to})"
        )));
    }
    let limit = check_limit(q.limit)?;
    let rows = super::run_query(&s, move |store| {
        store.alarm_journal(from, to, q.alarm.as_deref(), q.device.as_deref(), limit)
    })
    .await?;
    let entries: Vec<serde_json::Value> = rows
        .into_iter()
        .map(|row| {
            let mut entry = row.fields;
            entry.insert("t".into(), json!(row.t));
            entry.insert("kind".into(), json!(row.kind));
            entry.insert("device".into(), json!(row.device));
            entry.insert("point".into(), json!(row.point));
            entry.insert("message".into(), json!(row.message));
            serde_json::Value::Object(entry)
        })
        .collect();
    Ok(Json(json!({ "entries": entries })).into_response())
}

/// The body of an action: all optional.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct ActBody {
    /// Why, for the journal.
    comment: Option<String>,
    /// Who, as the operator gives it (the client's address is added).
    by: Option<String>,
    /// How long to shelve (`30m`), required to shelve.
    duration: Option<String>,
}

/// Reads an action's body: none at all, or a JSON object.
async fn act_body(request: Request) -> ApiResult<ActBody> {
    let bytes = tokio::time::timeout(BODY_TIMEOUT, to_bytes(request.into_body(), BODY_LIMIT))
        .await
        .map_err(|_| body_too_slow())?
        .map_err(|_| body_too_large())?;
    if bytes.iter().all(u8::is_ascii_whitespace) {
        return Ok(ActBody::default());
    }
    serde_json::from_slice(&bytes).map_err(|e| {
        ApiError::bad_request(format!(
            "the body must be a JSON object with comment, by and (to shelve) duration: {e}"
        ))
    })
}

/// `POST /api/alarms/{id}/{action}`.
pub(super) async fn act(
    State(s): State<AppState>,
    ClientAddr(client): ClientAddr,
    Path((id, action)): Path<(String, String)>,
    headers: HeaderMap,
    request: Request,
) -> ApiResult<Response> {
    if let Err(refused) = authorise(&s, &client, &headers) {
        return Ok(*refused);
    }
    let body = act_body(request).await?;
    let action = match action.as_str() {
        "ack" | "acknowledge" => Action::Acknowledge,
        "unshelve" => Action::Unshelve,
        "out_of_service" => Action::OutOfService(true),
        "in_service" => Action::OutOfService(false),
        "shelve" => {
            let Some(text) = body.duration.as_deref() else {
                return Err(ApiError::bad_request(format!(
                    "shelving needs a duration, like {{\"duration\": \"30m\"}} (1 s to {})",
                    humantime::format_duration(MAX_SHELVE)
                )));
            };
            let duration: Duration = humantime::parse_duration(text).map_err(|e| {
                ApiError::bad_request(format!(
                    "duration {:?} is not a duration like 30m or 2h: {e}",
                    cut(text, MAX_NAME)
                ))
            })?;
            Action::Shelve(duration)
        }
        other => {
            return Err(ApiError::not_found(format!(
                "no action {:?} on alarms; actions: ack, shelve, unshelve, out_of_service, in_service",
                cut(other, MAX_NAME)
            )));
        }
    };
    let by = match body.by.as_deref().map(str::trim).filter(|b| !b.is_empty()) {
        Some(name) => format!("{} (http {client})", cut(name, MAX_NAME)),
        None => format!("http {client}"),
    };
    match crate::alarm::keeper::act(&s.cell, &id, action, &by, body.comment.as_deref()).await {
        Ok(alarm) => Ok(Json(json!({ "alarm": alarm })).into_response()),
        Err(error @ ActError::Unknown { .. }) => Err(ApiError::not_found(error.to_string())),
        Err(error @ ActError::Refused { .. }) => {
            Err(ApiError::new(StatusCode::CONFLICT, error.to_string()))
        }
    }
}
