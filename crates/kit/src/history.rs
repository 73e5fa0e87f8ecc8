//! The history API's shapes, shared by the gateway's `/api/history` and the historian's:
//! the query ([`HistoryQuery`], checked into a [`HistoryRange`] by [`history_range`]),
//! its time forms and limits, and the answer's series of raw samples or buckets.

use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::bounded::{MAX_NAME, cut};
use crate::http::{ApiError, ApiResult};
use crate::time::Timestamp;
use crate::value::{Quality, Value};

/// Most rows one event or audit listing returns.
pub const MAX_LIMIT: usize = 10_000;

/// Most buckets one history query returns; a smaller `step` over the span is refused.
pub const MAX_BUCKETS: usize = 10_000;

/// Most raw samples one history query returns; ask with a `step` for longer ranges.
pub const MAX_RAW_SAMPLES: usize = 50_000;

/// Default length of a history query without `from`.
pub const DEFAULT_HISTORY: Duration = Duration::from_secs(3600);

/// Query of `/api/history` (the gateway's and the plant historian's).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HistoryQuery {
    /// The point (`jbc1.air_temperature`; the historian's `NODE/DEVICE.POINT`).
    pub point: Option<String>,
    /// Start: RFC 3339, `now` or `-DURATION`.
    pub from: Option<String>,
    /// End, the same forms.
    pub to: Option<String>,
    /// Bucket width (`1m`); raw samples without it.
    pub step: Option<String>,
}

/// The time range and step a history query asks for, checked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HistoryRange {
    /// Start (inclusive).
    pub from: Timestamp,
    /// End (exclusive).
    pub to: Timestamp,
    /// Bucket width, when downsampled.
    pub step: Option<Duration>,
}

/// A query's time `name` (RFC 3339, `now` or `-DURATION`), read at `now`.
pub fn parse_time(name: &str, text: Option<&str>, now: Timestamp) -> ApiResult<Option<Timestamp>> {
    text.map(|t| Timestamp::parse_relative(t, now))
        .transpose()
        .map_err(|e| ApiError::bad_request(format!("{name}: {e}")))
}

/// The range of a history query at `now`: `to` defaults to now, `from` to an hour before
/// `to` (not before 1970), and `from` must be before `to`.
pub fn history_range(q: &HistoryQuery, now: Timestamp) -> ApiResult<HistoryRange> {
    let to = parse_time("to", q.to.as_deref(), now)?.unwrap_or(now);
    let from = parse_time("from", q.from.as_deref(), now)?
        .unwrap_or(to.minus(DEFAULT_HISTORY).max(Timestamp::MIN));
    if from >= to {
        return Err(ApiError::bad_request(format!(
            "from ({from}) must be before to ({to})"
        )));
    }
    let step = q.step.as_deref().map(parse_step).transpose()?;
    if let Some(step) = step {
        check_buckets(from, to, step)?;
    }
    Ok(HistoryRange { from, to, step })
}

/// A history step: a duration of at least 1 ms.
pub fn parse_step(text: &str) -> ApiResult<Duration> {
    match humantime::parse_duration(text.trim()) {
        Ok(d) if d >= Duration::from_millis(1) => Ok(d),
        Ok(_) => Err(ApiError::bad_request("step must be at least 1ms")),
        Err(e) => Err(ApiError::bad_request(format!(
            "step {:?} is not a duration ({e}); write e.g. 10s, 1m or 1h",
            cut(text, MAX_NAME)
        ))),
    }
}

/// A listing's `limit`: 100 by default, 1 to [`MAX_LIMIT`].
pub fn check_limit(limit: Option<usize>) -> ApiResult<usize> {
    match limit {
        None => Ok(100),
        Some(n) if (1..=MAX_LIMIT).contains(&n) => Ok(n),
        Some(n) => Err(ApiError::bad_request(format!(
            "limit {n} is out of range: 1 to {MAX_LIMIT}"
        ))),
    }
}

/// A listing bounded by bytes as well as rows: the first `rows` whose JSON stays within
/// `max` bytes (at least one, so a listing always moves on), and whether some were left
/// out. Rows come from users' and devices' text, and a row limit alone bounds nothing.
pub fn bounded_by_bytes(
    rows: impl IntoIterator<Item = serde_json::Value>,
    max: usize,
) -> (Vec<serde_json::Value>, bool) {
    let mut kept = Vec::new();
    let mut bytes = 0;
    for row in rows {
        bytes += row.to_string().len();
        if bytes > max && !kept.is_empty() {
            return (kept, true);
        }
        kept.push(row);
    }
    (kept, false)
}

/// One stored sample in a history answer.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HistorySample {
    /// When.
    pub t: Timestamp,
    /// The value, `null` when the read failed.
    pub value: Option<Value>,
    /// Its quality.
    pub quality: Quality,
}

/// Statistics of the good numeric samples in one time bucket.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Bucket {
    /// Start of the bucket (aligned to multiples of the step since the epoch).
    pub t: Timestamp,
    /// Mean of the changes stored in the bucket.
    pub avg: f64,
    /// Lowest.
    pub min: f64,
    /// Highest.
    pub max: f64,
    /// How many changes.
    pub count: u64,
}

/// Raw samples or buckets.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Series {
    /// Every stored change.
    Samples(Vec<HistorySample>),
    /// Downsampled; buckets without a change are left out (the value held).
    Buckets(Vec<Bucket>),
}

/// Refuses a step that would cut `from`..`to` into more than [`MAX_BUCKETS`] buckets,
/// naming the smallest step that would do.
fn check_buckets(from: Timestamp, to: Timestamp, step: Duration) -> ApiResult<()> {
    let span = u128::try_from(to.millis().saturating_sub(from.millis())).unwrap_or(0);
    let buckets = span.div_ceil(step.as_millis().max(1));
    if buckets <= MAX_BUCKETS as u128 {
        return Ok(());
    }
    let least = Duration::from_millis(
        u64::try_from(span.div_ceil(MAX_BUCKETS as u128)).unwrap_or(u64::MAX),
    );
    Err(ApiError::bad_request(format!(
        "from {from} to {to} in steps of {} would be {buckets} buckets; the most is \
         {MAX_BUCKETS}: use a step of {} or more, or a shorter span",
        humantime::format_duration(step),
        humantime::format_duration(round_up_to_second(least))
    )))
}

/// `d` rounded up to whole seconds (at least one), for a step to suggest.
fn round_up_to_second(d: Duration) -> Duration {
    Duration::from_secs(d.as_secs() + u64::from(d.subsec_nanos() > 0)).max(Duration::from_secs(1))
}

#[cfg(test)]
mod tests {
    use super::*;

    const NOW: Timestamp = Timestamp(1_800_000_000_000);

    fn query(from: Option<&str>, to: Option<&str>, step: Option<&str>) -> HistoryQuery {
        HistoryQuery {
            point: Some("jbc1.air_temperature".into()),
            from: from.map(str::to_owned),
            to: to.map(str::to_owned),
            step: step.map(str::to_owned),
        }
    }

    #[test]
    fn a_range_defaults_to_the_last_hour_and_must_run_forward() {
        let range = history_range(&query(None, None, None), NOW).unwrap();
        assert_eq!(
            (range.from, range.to, range.step),
            (NOW.minus(DEFAULT_HISTORY), NOW, None)
        );
        let range = history_range(&query(Some("-2h"), Some("-1h"), Some("1m")), NOW).unwrap();
        assert_eq!(range.step, Some(Duration::from_secs(60)));
        let err = history_range(&query(Some("now"), Some("-1h"), None), NOW).unwrap_err();
        assert_eq!(err.status, axum::http::StatusCode::BAD_REQUEST);
        assert!(err.message.contains("must be before to"), "{}", err.message);
    }

    #[test]
    fn too_many_buckets_are_refused_naming_the_smallest_step_that_would_do() {
        let err = history_range(&query(Some("-1d"), None, Some("1s")), NOW).unwrap_err();
        assert!(err.message.contains("86400 buckets"), "{}", err.message);
        assert!(
            err.message.contains("use a step of 9s or more"),
            "{}",
            err.message
        );
        let err = parse_step("0s").unwrap_err();
        assert_eq!(err.message, "step must be at least 1ms");
    }

    #[test]
    fn limits_and_byte_bounds_keep_listings_small_but_never_empty() {
        assert_eq!(check_limit(None), Ok(100));
        assert_eq!(check_limit(Some(MAX_LIMIT)), Ok(MAX_LIMIT));
        assert!(check_limit(Some(0)).is_err());
        assert!(check_limit(Some(MAX_LIMIT + 1)).is_err());
        let rows = || (0..3).map(|n| serde_json::json!({ "n": n }));
        assert_eq!(
            bounded_by_bytes(rows(), 1),
            (vec![serde_json::json!({"n": 0})], true)
        );
        assert_eq!(bounded_by_bytes(rows(), 1000).0.len(), 3);
    }
}
