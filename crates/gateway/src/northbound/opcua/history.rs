//! HistoryRead from the gateway's history, sans-IO: raw values, and Average, Minimum and
//! Maximum over intervals.
//!
//! Raw: the stored changes in `[start, end)` with their quality as status codes (see
//! [`space`](super::space)), newest first when the end is before the start, at most
//! `numValuesPerNode` (no continuation points: the rest is left out). Processed: the mean,
//! lowest and highest of the good changes stored in each interval, the intervals starting
//! at the start time (as `/api/history?step=` when the start is a multiple of the step);
//! an interval without any is Bad_NoData.

use std::time::Duration;

use ::opcua::types::{DataValue, DateTime, NodeId, ObjectId, StatusCode, Variant};

use super::space::{gateway_time, opc_time, stored_data_value};
use crate::point::{PointKind, Quality, Value};
use crate::store::{History, Series};
use crate::time::{Timestamp, duration_millis};

/// The most intervals one processed read may ask for (as the HTTP API's buckets).
pub const MAX_INTERVALS: i64 = 10_000;

/// The times asked for, in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TimeRange {
    /// Start (inclusive).
    pub from: Timestamp,
    /// End (exclusive).
    pub to: Timestamp,
    /// Whether the client asked end before start (newest first).
    pub reverse: bool,
}

impl TimeRange {
    /// The range between `start` and `end`; a null start is the beginning of time, a
    /// null end is `now`.
    pub fn of(start: &DateTime, end: &DateTime, now: Timestamp) -> Self {
        let start = if start.is_null() {
            Timestamp(0)
        } else {
            gateway_time(start)
        };
        let end = if end.is_null() {
            now
        } else {
            gateway_time(end)
        };
        if end < start {
            Self {
                from: end,
                to: start,
                reverse: true,
            }
        } else {
            Self {
                from: start,
                to: end,
                reverse: false,
            }
        }
    }
}

/// An aggregate the server computes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Aggregate {
    /// The mean of the good changes.
    Average,
    /// The lowest.
    Minimum,
    /// The highest.
    Maximum,
}

impl Aggregate {
    /// The aggregate of an `AggregateFunction_*` node id, if the server computes it.
    pub fn of(node: &NodeId) -> Option<Self> {
        match node.as_object_id().ok()? {
            ObjectId::AggregateFunction_Average => Some(Aggregate::Average),
            ObjectId::AggregateFunction_Minimum => Some(Aggregate::Minimum),
            ObjectId::AggregateFunction_Maximum => Some(Aggregate::Maximum),
            _ => None,
        }
    }
}

/// The interval as a step, if it is at least a millisecond and makes at most
/// [`MAX_INTERVALS`] intervals in `range`.
pub fn check_interval(range: TimeRange, interval: Duration) -> Option<Duration> {
    let step = duration_millis(interval);
    (step > 0 && (range.to.0 - range.from.0) / step < MAX_INTERVALS).then_some(interval)
}

/// The stored changes as data values, in the order asked, at most `limit` (0: all).
pub fn raw(kind: &PointKind, stored: &History, range: TimeRange, limit: usize) -> Vec<DataValue> {
    let Series::Samples(samples) = &stored.series else {
        return Vec::new();
    };
    let value = |s: &crate::store::HistorySample| {
        stored_data_value(kind, s.value.as_ref(), Some(s.quality), Some(s.t), s.t)
    };
    let limit = if limit == 0 { usize::MAX } else { limit };
    if range.reverse {
        samples.iter().rev().take(limit).map(value).collect()
    } else {
        samples.iter().take(limit).map(value).collect()
    }
}

/// The aggregate of the good changes in each interval of `step` from the range's start.
pub fn processed(
    stored: &History,
    range: TimeRange,
    step: Duration,
    aggregate: Aggregate,
) -> Vec<DataValue> {
    let step = duration_millis(step).max(1);
    let Series::Samples(samples) = &stored.series else {
        return Vec::new();
    };
    let mut values = Vec::new();
    let mut start = range.from.0;
    while start < range.to.0 {
        let end = (start + step).min(range.to.0);
        let good = samples.iter().filter_map(|s| match (&s.value, s.quality) {
            (Some(Value::Number(n)), Quality::Good) if (start..end).contains(&s.t.0) => Some(*n),
            _ => None,
        });
        let (count, sum, min, max) = good.fold(
            (0_u64, 0.0, f64::INFINITY, f64::NEG_INFINITY),
            |(count, sum, min, max), n| (count + 1, sum + n, min.min(n), max.max(n)),
        );
        let t = opc_time(Timestamp(start));
        values.push(if count == 0 {
            DataValue {
                status: Some(if stored.truncated {
                    StatusCode::UncertainDataSubNormal
                } else {
                    StatusCode::BadNoData
                }),
                source_timestamp: Some(t),
                server_timestamp: Some(t),
                ..DataValue::default()
            }
        } else {
            let n = match aggregate {
                Aggregate::Average => sum / count as f64,
                Aggregate::Minimum => min,
                Aggregate::Maximum => max,
            };
            DataValue {
                value: Some(Variant::Double(n)),
                status: Some(StatusCode::Good),
                source_timestamp: Some(t),
                server_timestamp: Some(t),
                ..DataValue::default()
            }
        });
        start = end;
    }
    if range.reverse {
        values.reverse();
    }
    values
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::point::{DeviceId, PointId};
    use crate::store::HistorySample;

    fn history(samples: Vec<(i64, Option<f64>, Quality)>) -> History {
        History {
            point: PointId::new(&DeviceId::new("jbc1").unwrap(), "air_temperature").unwrap(),
            from: Timestamp(0),
            to: Timestamp(10_000),
            step_ms: None,
            before: None,
            series: Series::Samples(
                samples
                    .into_iter()
                    .map(|(t, v, quality)| HistorySample {
                        t: Timestamp(t),
                        value: v.map(Value::Number),
                        quality,
                    })
                    .collect(),
            ),
            truncated: false,
        }
    }

    #[test]
    fn raw_history_keeps_each_change_with_its_quality_and_time() {
        let stored = history(vec![
            (1_000, Some(20.0), Quality::Good),
            (2_000, None, Quality::Bad),
            (3_000, Some(21.0), Quality::Stale),
        ]);
        let range = TimeRange::of(
            &opc_time(Timestamp(0)),
            &opc_time(Timestamp(10_000)),
            Timestamp(0),
        );
        let values = raw(&PointKind::Numeric, &stored, range, 0);
        let statuses: Vec<_> = values.iter().map(|v| v.status()).collect();
        assert_eq!(
            statuses,
            [
                StatusCode::Good,
                StatusCode::BadCommunicationError,
                StatusCode::UncertainLastUsableValue
            ]
        );
        assert_eq!(values[0].value, Some(Variant::Double(20.0)));
        assert_eq!(
            gateway_time(&values[2].source_timestamp.unwrap()),
            Timestamp(3_000)
        );
        assert_eq!(raw(&PointKind::Numeric, &stored, range, 1).len(), 1);
    }

    #[test]
    fn an_end_before_the_start_reads_newest_first() {
        let stored = history(vec![
            (1_000, Some(20.0), Quality::Good),
            (3_000, Some(21.0), Quality::Good),
        ]);
        let range = TimeRange::of(
            &opc_time(Timestamp(10_000)),
            &opc_time(Timestamp(0)),
            Timestamp(0),
        );
        assert!(range.reverse);
        let values = raw(&PointKind::Numeric, &stored, range, 0);
        assert_eq!(values[0].value, Some(Variant::Double(21.0)));
    }

    #[test]
    fn processed_history_aggregates_good_changes_per_interval_from_the_start() {
        let stored = history(vec![
            (500, Some(10.0), Quality::Good),
            (900, Some(20.0), Quality::Good),
            (950, None, Quality::Bad),
            (2_100, Some(5.0), Quality::Good),
        ]);
        let range = TimeRange {
            from: Timestamp(0),
            to: Timestamp(3_000),
            reverse: false,
        };
        let step = Duration::from_secs(1);
        let average = processed(&stored, range, step, Aggregate::Average);
        assert_eq!(average.len(), 3);
        assert_eq!(average[0].value, Some(Variant::Double(15.0)));
        assert_eq!(average[1].status(), StatusCode::BadNoData);
        assert_eq!(average[2].value, Some(Variant::Double(5.0)));
        let max = processed(&stored, range, step, Aggregate::Maximum);
        assert_eq!(max[0].value, Some(Variant::Double(20.0)));
        let min = processed(&stored, range, step, Aggregate::Minimum);
        assert_eq!(min[0].value, Some(Variant::Double(10.0)));
    }

    #[test]
    fn too_many_or_empty_intervals_are_refused() {
        let range = TimeRange {
            from: Timestamp(0),
            to: Timestamp(100_000_000),
            reverse: false,
        };
        assert_eq!(check_interval(range, Duration::from_millis(1)), None);
        assert_eq!(check_interval(range, Duration::ZERO), None);
        assert!(check_interval(range, Duration::from_secs(60)).is_some());
    }
}
