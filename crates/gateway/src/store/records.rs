//! What the history stores and what its queries return.

use std::sync::atomic::{AtomicU64, Ordering};

use serde::Serialize;

use crate::event::EventKind;
use crate::point::{PointId, Quality, Value};
use crate::time::Timestamp;

// A history answer's series, shared with the historian.
pub use kit::history::{Bucket, HistorySample, Series};

/// A value change of a point, as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// The point.
    pub point: PointId,
    /// When it was read.
    pub t: Timestamp,
    /// The value; `None` when the read failed.
    pub value: Option<Value>,
    /// Its quality.
    pub quality: Quality,
}

/// An event as stored, with its id.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EventRecord {
    /// Increasing id.
    pub id: i64,
    /// When.
    pub t: Timestamp,
    /// What kind (`device_down`).
    pub kind: String,
    /// The line, if any.
    pub line: Option<String>,
    /// The device, if any.
    pub device: Option<String>,
    /// The point, if any.
    pub point: Option<String>,
    /// Words.
    pub message: String,
    /// The facts for programs (`{}` for events without any, and for events stored before
    /// events had fields).
    pub fields: crate::event::Fields,
}

/// How a write attempt ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum AuditResult {
    /// An authorised, valid write is about to go to the line (a second row says how it
    /// ended).
    Attempted,
    /// The device took the value.
    Accepted,
    /// Refused before the wire (unknown point, bad value) or by the device.
    Refused,
    /// The device did not answer or the line failed.
    Failed,
}

impl AuditResult {
    /// The name stored and shown (`accepted`).
    pub fn as_str(self) -> &'static str {
        match self {
            AuditResult::Attempted => "attempted",
            AuditResult::Accepted => "accepted",
            AuditResult::Refused => "refused",
            AuditResult::Failed => "failed",
        }
    }
}

/// One write attempt.
#[derive(Debug, Clone, PartialEq)]
pub struct AuditEntry {
    /// When.
    pub t: Timestamp,
    /// The client's address.
    pub client: String,
    /// The device named in the request.
    pub device: String,
    /// The point named in the request.
    pub point: String,
    /// The point's value before the write, if known.
    pub old: Option<Value>,
    /// The value asked for, as given.
    pub new: serde_json::Value,
    /// How it ended.
    pub result: AuditResult,
    /// Why, in words.
    pub detail: String,
}

/// A write attempt as stored.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AuditRecord {
    /// Increasing id.
    pub id: i64,
    /// When.
    pub t: Timestamp,
    /// The client's address.
    pub client: String,
    /// The device named.
    pub device: String,
    /// The point named.
    pub point: String,
    /// The value before, if known.
    pub old_value: Option<serde_json::Value>,
    /// The value asked for.
    pub new_value: serde_json::Value,
    /// `accepted`, `refused` or `failed`.
    pub result: String,
    /// Why.
    pub detail: String,
}

/// Where a stored change sits in a point's history: its time, then the order it was
/// stored in (changes at the same millisecond keep their order).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct SampleCursor {
    /// Its time.
    pub t: Timestamp,
    /// Its row.
    pub row: i64,
}

/// Which way a page of history runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PageOrder {
    /// `from <= t < to`, oldest first.
    OldestFirst,
    /// `from < t <= to`, newest first (OPC UA's time running backward: the domain starts
    /// at the later time and ends just after the earlier one).
    NewestFirst,
}

/// A stored change of any point, in the order changes are forwarded after an outage.
#[derive(Debug, Clone, PartialEq)]
pub struct StoredChange {
    /// Its place in the order: (time, row id).
    pub key: ChangeKey,
    /// The point, as stored.
    pub point: String,
    /// The value, `None` when the read failed.
    pub value: Option<Value>,
    /// Its quality.
    pub quality: Quality,
}

/// Where a stored change is in time order: its time, then the order it was stored in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct ChangeKey {
    /// When the point was read.
    pub t: Timestamp,
    /// The row id (ties between changes of the same millisecond).
    pub row: i64,
}

impl ChangeKey {
    /// Before every change stored at `t` or later.
    pub fn before(t: Timestamp) -> Self {
        Self { t, row: i64::MIN }
    }
}

/// The answer to a history query.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct History {
    /// The point.
    pub point: PointId,
    /// Start of the range (inclusive).
    pub from: Timestamp,
    /// End of the range (exclusive).
    pub to: Timestamp,
    /// Bucket width in milliseconds, when downsampled.
    pub step_ms: Option<i64>,
    /// The last change before `from`: the value held at the start of the range.
    pub before: Option<HistorySample>,
    /// Samples or buckets.
    #[serde(flatten)]
    pub series: Series,
    /// Whether raw samples were cut at [`MAX_RAW_SAMPLES`].
    pub truncated: bool,
}

/// Which events to list.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EventFilter {
    /// From (inclusive).
    pub from: Option<Timestamp>,
    /// To (exclusive).
    pub to: Option<Timestamp>,
    /// Only this device.
    pub device: Option<String>,
    /// Only this kind.
    pub kind: Option<EventKind>,
    /// At most this many, newest first.
    pub limit: usize,
}

/// Counters of the writer, for the metrics.
#[derive(Debug, Default)]
pub struct StoreStats {
    /// Samples committed.
    pub samples_written: AtomicU64,
    /// Events committed.
    pub events_written: AtomicU64,
    /// Audit rows committed.
    pub audit_written: AtomicU64,
    /// Commits made.
    pub commits: AtomicU64,
    /// Commits that failed.
    pub commit_errors: AtomicU64,
    /// Rows never stored: dropped (oldest samples first, never audit rows) while the disk
    /// refused writes for too long, or discarded while the history is off.
    pub rows_dropped: AtomicU64,
    /// Rows the writer holds, waiting for their commit (a gauge).
    pub pending_rows: AtomicU64,
    /// Samples queued for the writer that it has not taken yet (a gauge; see
    /// [`rows_waiting`](Self::rows_waiting)).
    pub queued_rows: AtomicU64,
    /// Rows deleted by retention.
    pub rows_pruned: AtomicU64,
}

impl StoreStats {
    /// Every row not committed yet: those the writer holds and those queued for it.
    pub fn rows_waiting(&self) -> u64 {
        self.pending_rows.load(Ordering::Relaxed) + self.queued_rows.load(Ordering::Relaxed)
    }

    /// Every row committed so far.
    pub fn rows_written(&self) -> u64 {
        self.samples_written.load(Ordering::Relaxed)
            + self.events_written.load(Ordering::Relaxed)
            + self.audit_written.load(Ordering::Relaxed)
    }
}
