//! HistoryRead from the gateway's history, sans-IO: raw values, and Average, Minimum and
//! Maximum over intervals.
//!
//! Raw ([`RawRead`]): the stored changes in `[start, end)` with their quality as status
//! codes (see [`space`](super::space)); when the end is before the start (or only the end
//! is given), newest first over `(end, start]`. With `returnBounds`, the bounding values
//! come first and last: the change at the start time or the last one before it, and the
//! change at the end time or the first one after it (in the direction of the read), each
//! with its own time, or Bad_BoundNotFound at the start or end time. At most
//! `numValuesPerNode` values a call (bounds included; [`PAGE_MAX`] when it is 0), with a
//! continuation point for the rest. Processed: the mean,
//! lowest and highest of the good changes stored in each interval, the intervals starting
//! at the start time (as `/api/history?step=` when the start is a multiple of the step);
//! an interval without any is Bad_NoData.

use std::time::Duration;

use ::opcua::types::{
    DataValue, DateTime, NodeId, ObjectId, StatusCode, TimestampsToReturn, Variant,
};

use super::space::{gateway_time, opc_time, stored_data_value};
use gateway::point::{PointKind, Quality, Value};
use gateway::store::{History, HistorySample, PageOrder, SampleCursor, Series};
use gateway::time::{Timestamp, duration_millis};

/// The most values one raw read call returns; more come with a continuation point.
pub const PAGE_MAX: usize = gateway::store::MAX_RAW_SAMPLES;

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
        let start_given = !start.is_null();
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
        .backward_from_end_unless(start_given)
    }

    /// Only an end time given: the read runs backward from it (OPC UA Part 11, 6.5.3.2).
    fn backward_from_end_unless(self, start_given: bool) -> Self {
        Self {
            reverse: self.reverse || !start_given,
            ..self
        }
    }

    /// The order the values are read in.
    pub fn order(&self) -> PageOrder {
        if self.reverse {
            PageOrder::NewestFirst
        } else {
            PageOrder::OldestFirst
        }
    }

    /// Where the read starts: the start time (the later time when reading backward).
    pub fn start(&self) -> Timestamp {
        if self.reverse { self.to } else { self.from }
    }

    /// Where the read ends.
    pub fn end(&self) -> Timestamp {
        if self.reverse { self.from } else { self.to }
    }
}

/// A raw HistoryRead of one node, read in calls: what the client asked and how far it
/// got. This is the content of the continuation point between calls.
#[derive(Debug, Clone, PartialEq)]
pub struct RawRead {
    /// The times asked for.
    pub range: TimeRange,
    /// Values per call (`numValuesPerNode`; 0 asks for all, which is [`PAGE_MAX`]).
    pub per_call: usize,
    /// Whether the bounding values were asked for.
    pub bounds: bool,
    /// The last stored change handed out.
    pub after: Option<SampleCursor>,
    /// Whether the start bound has been handed out (or is one of the changes).
    pub started: bool,
}

/// What one call needs from the history, fetched by the caller for [`RawRead::page`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Fetched {
    /// When the start bound is wanted ([`RawRead::wants_start_bound`]): the stored change
    /// nearest the start on its outer side, at the start time included.
    pub start_bound: Option<Option<HistorySample>>,
    /// The stored changes after [`RawRead::after`], at most [`RawRead::rows_wanted`].
    pub rows: Vec<(SampleCursor, HistorySample)>,
    /// When bounds are asked: the stored change nearest the end on its outer side.
    pub end_bound: Option<Option<HistorySample>>,
}

impl RawRead {
    /// A read from its first call.
    pub fn new(range: TimeRange, num_values_per_node: u32, bounds: bool) -> Self {
        let per_call = usize::try_from(num_values_per_node).unwrap_or(usize::MAX);
        Self {
            range,
            per_call: if per_call == 0 {
                PAGE_MAX
            } else {
                per_call.min(PAGE_MAX)
            },
            bounds,
            after: None,
            started: false,
        }
    }

    /// Whether this call needs the start bound fetched.
    pub fn wants_start_bound(&self) -> bool {
        self.bounds && !self.started
    }

    /// How many stored changes to fetch: one more than fit, to know whether more follow.
    pub fn rows_wanted(&self) -> usize {
        self.per_call + 1
    }

    /// This call's values, and the read to continue with when there are more.
    pub fn page(mut self, kind: &PointKind, fetched: Fetched) -> (Vec<DataValue>, Option<Self>) {
        let mut values = Vec::new();
        if self.wants_start_bound() {
            self.started = true;
            let start = self.range.start();
            match fetched.start_bound.flatten() {
                // At the start time: it is the first of the changes, not an extra value.
                Some(s) if s.t == start => {}
                Some(s) => values.push(sample_value(kind, &s)),
                None => values.push(bound_not_found(start)),
            }
        }
        let room = self.per_call.saturating_sub(values.len());
        let more_rows = fetched.rows.len() > room;
        for (cursor, sample) in fetched.rows.into_iter().take(room) {
            values.push(sample_value(kind, &sample));
            self.after = Some(cursor);
        }
        if more_rows {
            return (values, Some(self));
        }
        if self.bounds {
            if values.len() == self.per_call {
                // The end bound goes in the next call.
                return (values, Some(self));
            }
            values.push(match fetched.end_bound.flatten() {
                Some(s) => sample_value(kind, &s),
                None => bound_not_found(self.range.end()),
            });
        }
        (values, None)
    }
}

fn sample_value(kind: &PointKind, s: &HistorySample) -> DataValue {
    stored_data_value(kind, s.value.as_ref(), Some(s.quality), Some(s.t), s.t)
}

/// A bound the history has no value for.
fn bound_not_found(t: Timestamp) -> DataValue {
    DataValue {
        value: None,
        status: Some(StatusCode::BadBoundNotFound),
        source_timestamp: Some(opc_time(t)),
        server_timestamp: Some(opc_time(t)),
        ..DataValue::default()
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
/// [`MAX_INTERVALS`] intervals in `range`; an interval of 0 is the whole range, one
/// interval (OPC UA Part 13, 5.1.3: "If the ProcessingInterval is 0 … one interval").
pub fn check_interval(range: TimeRange, interval: Duration) -> Option<Duration> {
    if interval.is_zero() {
        let whole = u64::try_from(range.to.0 - range.from.0).unwrap_or(0).max(1);
        return Some(Duration::from_millis(whole));
    }
    let step = duration_millis(interval);
    (step > 0 && (range.to.0 - range.from.0) / step < MAX_INTERVALS).then_some(interval)
}

/// `values` with the timestamps the client asked for (OPC UA Part 11, 6.4: `Source`, the
/// device's time only; `Server`, the server's only; `Both`). `Neither` is refused before.
pub fn with_timestamps(mut values: Vec<DataValue>, which: TimestampsToReturn) -> Vec<DataValue> {
    for value in &mut values {
        match which {
            TimestampsToReturn::Source => {
                value.server_timestamp = None;
                value.server_picoseconds = None;
            }
            TimestampsToReturn::Server => {
                value.source_timestamp = None;
                value.source_picoseconds = None;
            }
            _ => {}
        }
    }
    values
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
mod tests;
