//! What the historian writes and what its queries return.

use std::fmt;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// How far a sample can be trusted: the gateway's quality, one type for both (Sparkplug's
/// `Quality` property 192 / 500 / 0 is mapped to it where messages are ingested). Stored
/// in `samples.quality` as its code (0 good, 1 stale, 2 bad: [`Quality::code`]).
pub use kit::value::Quality;

/// `q` as the column `samples.quality` (a `smallint`) stores it.
pub(crate) fn stored_quality(q: Quality) -> i16 {
    i16::try_from(q.code()).expect("the quality codes are 0, 1 and 2")
}

/// The quality of a stored `samples.quality`; unknown numbers read as bad (as the view
/// does).
pub(crate) fn quality_of_stored(code: i16) -> Quality {
    Quality::from_code(i64::from(code))
}

/// The data type of a point known only from its samples (no birth seen yet).
pub const UNKNOWN_DATATYPE: &str = "unknown";

/// A point as its birth defines it. Points are named by Sparkplug group, edge node, device
/// and metric name; a node's own metrics have the device `""`.
#[derive(Debug, Clone, PartialEq)]
pub struct PointRow {
    /// The Sparkplug group id (`plant`); `""` for a point stored before the group was
    /// recorded (schema version 1), until its node's next birth claims it.
    pub group: String,
    /// The Sparkplug edge node id (`cell7`).
    pub node: String,
    /// The device id (`jbc1`), `""` for the node's own metrics.
    pub device: String,
    /// The point's name (`air_temperature`).
    pub point: String,
    /// The Sparkplug data type's name (`Double`, `Int32`, `Boolean`, `String`), or
    /// [`UNKNOWN_DATATYPE`].
    pub datatype: String,
    /// The engineering unit (`°C`), if any.
    pub unit: Option<String>,
    /// The point's name in words, if any.
    pub description: Option<String>,
    /// Whether the gateway takes writes to it.
    pub writable: bool,
    /// The lowest value a write may set, if limited.
    pub write_min: Option<f64>,
    /// The highest value a write may set, if limited.
    pub write_max: Option<f64>,
}

impl PointRow {
    /// A point known only by its name: unknown type, no unit, not writable (what the store
    /// records for a sample of a point no birth has described).
    pub fn bare(group: &str, node: &str, device: &str, point: &str) -> Self {
        Self {
            group: group.to_owned(),
            node: node.to_owned(),
            device: device.to_owned(),
            point: point.to_owned(),
            datatype: UNKNOWN_DATATYPE.to_owned(),
            unit: None,
            description: None,
            writable: false,
            write_min: None,
            write_max: None,
        }
    }
}

/// One value change of a point.
#[derive(Debug, Clone, PartialEq)]
pub struct SampleRow {
    /// The Sparkplug group id.
    pub group: String,
    /// The edge node id.
    pub node: String,
    /// The device id, `""` for the node's own metrics.
    pub device: String,
    /// The point's name.
    pub point: String,
    /// When the gateway read it (the metric's own timestamp). Stored to the microsecond;
    /// a point has at most one sample per instant (a second one is a duplicate).
    pub t: SystemTime,
    /// The value as a number (booleans 0/1), if numeric and good.
    pub value: Option<f64>,
    /// The value as text, for text points.
    pub text: Option<String>,
    /// Its quality.
    pub quality: Quality,
}

/// An event of a gateway (alarm, transfer, machine state, device down).
#[derive(Debug, Clone, PartialEq)]
pub struct EventRow {
    /// The Sparkplug group id.
    pub group: String,
    /// The edge node id.
    pub node: String,
    /// The device, if any.
    pub device: Option<String>,
    /// The point, if any.
    pub point: Option<String>,
    /// The line, if any.
    pub line: Option<String>,
    /// When it happened.
    pub t: SystemTime,
    /// What kind (`device_down`).
    pub kind: String,
    /// How serious (OPC UA's 1–1000 scale).
    pub severity: i32,
    /// Words.
    pub message: String,
    /// The facts for programs: a JSON object's text (checked by `ingest`), if any.
    pub fields: Option<String>,
}

/// What one call of [`Store::write`](super::Store::write) commits, in one transaction.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Batch {
    /// Points defined or redefined by births (inserted, or updated in place).
    pub points: Vec<PointRow>,
    /// Value changes.
    pub samples: Vec<SampleRow>,
    /// Events.
    pub events: Vec<EventRow>,
}

impl Batch {
    /// Whether there is nothing to write.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty() && self.samples.is_empty() && self.events.is_empty()
    }

    /// Rows of every kind.
    pub fn len(&self) -> usize {
        self.points.len() + self.samples.len() + self.events.len()
    }

    /// Splits the batch in two by point: every sample and definition of one point goes to
    /// the same half, so two connections can write the halves at once without waiting for
    /// each other's point rows. Events go to the first half.
    pub fn split_by_point(self) -> [Batch; 2] {
        fn half(group: &str, node: &str, device: &str, point: &str) -> usize {
            let mut hasher = std::hash::DefaultHasher::new();
            std::hash::Hash::hash(&(group, node, device, point), &mut hasher);
            usize::from(std::hash::Hasher::finish(&hasher) & 1 == 1)
        }
        let mut halves = [Batch::default(), Batch::default()];
        for row in self.points {
            halves[half(&row.group, &row.node, &row.device, &row.point)]
                .points
                .push(row);
        }
        for row in self.samples {
            halves[half(&row.group, &row.node, &row.device, &row.point)]
                .samples
                .push(row);
        }
        halves[0].events = self.events;
        halves
    }
}

impl Written {
    /// Adds what another write committed and left out (the first refusal stays).
    pub fn add(&mut self, other: Written) {
        self.points += other.points;
        self.bare_points += other.bare_points;
        self.samples += other.samples;
        self.duplicate_samples += other.duplicate_samples;
        self.refused_samples += other.refused_samples;
        self.events += other.events;
        self.duplicate_events += other.duplicate_events;
        self.refused_events += other.refused_events;
        self.refused_points += other.refused_points;
        if self.first_refusal.is_none() {
            self.first_refusal = other.first_refusal;
        }
    }
}

/// What a write committed, and what it left out.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Written {
    /// Point rows inserted or updated from the batch's `points`.
    pub points: u64,
    /// Bare point rows created for samples of points no birth described.
    pub bare_points: u64,
    /// Samples stored.
    pub samples: u64,
    /// Samples already stored (same point and time): a replayed backlog.
    pub duplicate_samples: u64,
    /// Samples refused and not written (see [`Written::first_refusal`]).
    pub refused_samples: u64,
    /// Events stored.
    pub events: u64,
    /// Events already stored (same node, device, point, time, kind and message).
    pub duplicate_events: u64,
    /// Events refused and not written.
    pub refused_events: u64,
    /// Point rows refused and not written.
    pub refused_points: u64,
    /// The first row refused, and why (for the log).
    pub first_refusal: Option<Refusal>,
}

/// A row the store refused to write.
#[derive(Debug, Clone, PartialEq)]
pub struct Refusal {
    /// What it was: `sample cell7/jbc1.air_temperature`, `event cell7 device_down`.
    pub row: String,
    /// Its time (points have none: the epoch).
    pub t: SystemTime,
    /// Why.
    pub reason: RefusalReason,
}

/// Why a row was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RefusalReason {
    /// Its time is before 2000-01-01 (a clock not set).
    BeforeEarliest,
    /// Its time is more than [`MAX_AHEAD`] after the historian's clock.
    TooFarAhead,
    /// Its time is further back than the store's maximum age ([`super::Store::set_max_age`]).
    TooOld {
        /// The maximum age, in whole days.
        max_age_days: u64,
    },
    /// A text contains a NUL character, which PostgreSQL's text cannot hold.
    NulCharacter,
}

impl fmt::Display for Refusal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let ms = super::days::epoch_millis(self.t);
        let why = match self.reason {
            RefusalReason::BeforeEarliest => "its time is before 2000-01-01".to_owned(),
            RefusalReason::TooFarAhead => {
                "its time is more than a day ahead of this clock".to_owned()
            }
            RefusalReason::TooOld { max_age_days } => {
                format!("its time is more than {max_age_days} days before this clock (--max-age)")
            }
            RefusalReason::NulCharacter => "a text holds a NUL character".to_owned(),
        };
        write!(f, "{} at {ms} ms since the epoch refused: {why}", self.row)
    }
}

/// The earliest time stored, 2000-01-01T00:00:00Z, in seconds since the epoch (earlier
/// times come from clocks never set).
pub const EARLIEST_UNIX_SECS: u64 = 946_684_800;

/// How far ahead of the historian's clock a time may be (clocks of gateways drift; a day
/// more is a wrong clock, and would create partitions far in the future).
pub const MAX_AHEAD: Duration = Duration::from_secs(24 * 3600);

/// Whether a row at `t` may be stored when the historian's clock says `now`, and rows may
/// be at most `max_age` old (any age after 2000 when `None`).
pub fn check_time(
    t: SystemTime,
    now: SystemTime,
    max_age: Option<Duration>,
) -> Result<(), RefusalReason> {
    if t < UNIX_EPOCH + Duration::from_secs(EARLIEST_UNIX_SECS) {
        return Err(RefusalReason::BeforeEarliest);
    }
    if t > now + MAX_AHEAD {
        return Err(RefusalReason::TooFarAhead);
    }
    if let Some(max_age) = max_age
        && now.duration_since(t).is_ok_and(|age| age > max_age)
    {
        return Err(RefusalReason::TooOld {
            max_age_days: max_age.as_secs() / 86_400,
        });
    }
    Ok(())
}

/// A stored sample of one point.
#[derive(Debug, Clone, PartialEq)]
pub struct StoredSample {
    /// When it was read.
    pub t: SystemTime,
    /// The value as a number, if any.
    pub value: Option<f64>,
    /// The value as text, if any.
    pub text: Option<String>,
    /// Its quality.
    pub quality: Quality,
}

/// Statistics of the good numeric samples of one point in one time bucket.
#[derive(Debug, Clone, PartialEq)]
pub struct Bucket {
    /// Start of the bucket (aligned to multiples of the step since the epoch).
    pub t: SystemTime,
    /// Mean of the samples in the bucket.
    pub avg: f64,
    /// Lowest.
    pub min: f64,
    /// Highest.
    pub max: f64,
    /// How many samples.
    pub count: u64,
}
