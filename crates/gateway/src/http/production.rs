//! `/api/states` and `/api/production`: a device's machine states and production over a
//! range, a shift or the shift under way.

use axum::Json;
use axum::extract::rejection::QueryRejection;
use axum::extract::{Query, State};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;

use super::{ApiError, ApiResult, AppState, run_query, unknown_device};
use crate::point::DeviceId;
use crate::production::report;
use crate::production::shift::ShiftWindow;
use crate::time::Timestamp;

/// Longest range a states or production query covers: the history's default retention.
const MAX_RANGE_MS: i64 = 31 * 24 * 3600 * 1000;

/// Query of `/api/states` and `/api/production`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct ProductionQuery {
    device: Option<String>,
    from: Option<String>,
    to: Option<String>,
    shift: Option<String>,
    day: Option<String>,
}

/// The range asked for: `from`/`to`, or `shift` (on `day`, default today), or a whole
/// `day`, or without any the shift under way (or, outside every shift, the last 24 h).
fn range(
    s: &AppState,
    q: &ProductionQuery,
    now: Timestamp,
) -> ApiResult<(Timestamp, Timestamp, Option<ShiftWindow>)> {
    let plan = s.cell.production();
    let shifts = &plan.shifts;
    if q.shift.is_some() && (q.from.is_some() || q.to.is_some()) {
        return Err(ApiError::bad_request(
            "give either shift (and day) or from and to, not both",
        ));
    }
    if q.day.is_some() && (q.from.is_some() || q.to.is_some()) {
        return Err(ApiError::bad_request(
            "give either day (and shift) or from and to, not both",
        ));
    }
    let day = |text: &str| {
        text.parse::<jiff::civil::Date>().map_err(|_| {
            ApiError::bad_request(format!(
                "day {:?} is not a date; write YYYY-MM-DD",
                kit::bounded::cut(text, 40)
            ))
        })
    };
    if let (None, Some(text)) = (&q.shift, &q.day) {
        // A whole day, midnight to midnight in the cell's zone.
        let (from, to) = shifts
            .day(day(text)?)
            .ok_or_else(|| ApiError::bad_request("day is outside the calendar"))?;
        return Ok((from, to, None));
    }
    if let Some(name) = &q.shift {
        let day = match &q.day {
            Some(text) => day(text)?,
            None => shifts.day_of(now),
        };
        let Some(known) = shifts.shifts().iter().find(|s| &s.name == name) else {
            let names: Vec<&str> = shifts.shifts().iter().map(|s| s.name.as_str()).collect();
            return Err(ApiError::not_found(format!(
                "no shift {:?}; the cell's shifts: {}",
                kit::bounded::cut(name, 40),
                names.join(", ")
            )));
        };
        let Some(window) = shifts.on(&known.name, day) else {
            return Err(ApiError::not_found(format!(
                "shift {} does not work on {day}, a {}",
                known.name,
                day.strftime("%A")
            )));
        };
        return Ok((window.start, window.end, Some(window)));
    }
    if q.from.is_none() && q.to.is_none() {
        return Ok(match shifts.at(now) {
            Some(window) => (window.start, window.end, Some(window)),
            None => (
                now.minus(std::time::Duration::from_secs(24 * 3600)),
                now,
                None,
            ),
        });
    }
    // The history's own reading of a range: its defaults, forms and checks.
    let kit::history::HistoryRange { from, to, .. } = kit::history::history_range(
        &kit::history::HistoryQuery {
            point: None,
            from: q.from.clone(),
            to: q.to.clone(),
            step: None,
        },
        now,
    )?;
    if to.0 - from.0 > MAX_RANGE_MS {
        return Err(ApiError::bad_request(format!(
            "the range from {from} to {to} is longer than 31 days; ask for less"
        )));
    }
    Ok((from, to, None))
}

/// The device asked for, which must report machine states.
fn device(s: &AppState, q: &ProductionQuery) -> ApiResult<DeviceId> {
    let Some(id) = q.device.as_deref() else {
        return Err(ApiError::bad_request(
            "device is missing: ?device=ID (GET /api/devices lists them)",
        ));
    };
    let Some(entry) = s.cell.device_entry(id) else {
        return Err(unknown_device(&s.cell, id));
    };
    if !s.cell.production().has_states(id) {
        return Err(ApiError::not_found(format!(
            "device {id} ({}) reports no machine states",
            entry.protocol
        )));
    }
    Ok(entry.id.clone())
}

/// What a states or production query asks for: the device, now, and the range.
struct Asked {
    device: DeviceId,
    now: Timestamp,
    from: Timestamp,
    to: Timestamp,
    shift: Option<ShiftWindow>,
}

fn asked(s: &AppState, query: Result<Query<ProductionQuery>, QueryRejection>) -> ApiResult<Asked> {
    let Query(q) = query?;
    let device = device(s, &q)?;
    let now = Timestamp::now();
    let (from, to, shift) = range(s, &q, now)?;
    Ok(Asked {
        device,
        now,
        from,
        to,
        shift,
    })
}

/// `GET /api/states?device=ID&from=&to=`: the device's state intervals.
pub(crate) async fn states(
    State(s): State<AppState>,
    query: Result<Query<ProductionQuery>, QueryRejection>,
) -> ApiResult<Response> {
    let a = asked(&s, query)?;
    let answer = run_query(&s, move |store| {
        report::states(&store, &a.device, a.from, a.to, a.now)
    })
    .await?;
    Ok(Json(answer).into_response())
}

/// `GET /api/production?device=ID&from=&to=` (or `&shift=&day=`, or the shift under
/// way): the device's states, OEE and stops.
pub(crate) async fn production(
    State(s): State<AppState>,
    query: Result<Query<ProductionQuery>, QueryRejection>,
) -> ApiResult<Response> {
    let a = asked(&s, query)?;
    let cell = std::sync::Arc::clone(&s.cell);
    let answer = run_query(&s, move |store| {
        let range = (a.from, a.to);
        report::production(&store, &cell.production(), &a.device, range, a.shift, a.now)
    })
    .await?;
    Ok(Json(answer).into_response())
}
