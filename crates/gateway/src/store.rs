//! The history: every value change, every event and every write attempt, in SQLite.
//!
//! One database file, `cellbus.db`, in the data directory. A dedicated writer thread owns
//! the only writing connection; the pollers and the HTTP handlers send it rows through a
//! channel and never wait for the disk. The writer commits a batch every
//! [`StoreOptions::batch_delay`] (200 ms) or [`StoreOptions::batch_rows`] (5000 rows),
//! whichever comes first, and at once for an audit row. The delay is the bound in normal
//! running; the row count only cuts batches short above 25 000 changes per second, and is
//! high because each commit costs an fsync (see below): 500-row commits capped the
//! throughput at the disk's fsync rate in the store bench. Queries run on separate read
//! connections, which WAL lets read while the writer writes.
//!
//! Durability: `journal_mode=WAL` with `synchronous=FULL`. A `kill -9` loses nothing that
//! was committed under either NORMAL or FULL (the OS still holds the written WAL pages);
//! FULL also keeps the last commits through a power cut or a kernel crash, which a gateway
//! in a cabinet will meet. Its price is one fsync per commit, and with batching that is at
//! most five per second. Rows still queued in the channel when the process is killed are
//! lost by definition: they were never reported committed ([`StoreHandle::flush`] tells
//! when they are). The test `store_keeps_every_committed_row_after_kill_9` proves it on a
//! real child process.
//!
//! Retention: rows older than [`StoreOptions::retain`] are deleted every
//! [`StoreOptions::prune_every`] (samples point by point, so no delete holds the write
//! lock for long). The audit table is kept whole: it is the record of who changed what.

use std::collections::{HashMap, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError, mpsc};
use std::thread;
use std::time::{Duration, Instant};

use rusqlite::{Connection, OptionalExtension, Transaction, params};
use serde::Serialize;

use crate::point::{DeviceId, PointId, Quality, Value};
use crate::time::{Timestamp, duration_millis};

/// File name of the database inside the data directory.
pub const DB_FILE: &str = "cellbus.db";

/// Most raw samples one history query returns; ask with a `step` for longer ranges.
pub const MAX_RAW_SAMPLES: usize = 50_000;

/// Most pending rows kept while the disk refuses writes; older ones are dropped (counted).
const MAX_PENDING_ROWS: usize = 200_000;

/// How the store batches and how long it keeps history.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StoreOptions {
    /// Samples and events older than this are deleted.
    pub retain: Duration,
    /// Commit when this many rows are waiting.
    pub batch_rows: usize,
    /// Commit when the oldest waiting row is this old.
    pub batch_delay: Duration,
    /// How often old rows are deleted.
    pub prune_every: Duration,
}

impl Default for StoreOptions {
    /// 30 days, 5000 rows or 200 ms, pruning hourly.
    fn default() -> Self {
        Self {
            retain: Duration::from_secs(30 * 24 * 3600),
            batch_rows: 5_000,
            batch_delay: Duration::from_millis(200),
            prune_every: Duration::from_secs(3600),
        }
    }
}

/// What went wrong with the history database.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum StoreError {
    /// The data directory could not be created.
    #[error("cannot create the data directory {path}: {source}; choose another with --data DIR")]
    Directory {
        /// The directory.
        path: PathBuf,
        /// What the OS said.
        source: std::io::Error,
    },
    /// SQLite refused.
    #[error("history database {path}: {source}")]
    Sqlite {
        /// The database file.
        path: PathBuf,
        /// What SQLite said.
        source: rusqlite::Error,
    },
    /// The writer thread has stopped (after a failed commit or at shutdown).
    #[error("the history writer has stopped")]
    WriterGone,
    /// A commit failed; the rows stay queued and are retried.
    #[error("history commit failed: {0}")]
    Commit(String),
}

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

/// What happened, for the event log.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EventKind {
    /// The gateway started.
    GatewayStarted,
    /// The gateway stopped.
    GatewayStopped,
    /// A line was opened.
    LineUp,
    /// A line failed or could not be opened.
    LineDown,
    /// A line was closed and reopened because every device on it stopped answering.
    LineReopened,
    /// A device answered again.
    DeviceUp,
    /// A device stopped answering.
    DeviceDown,
    /// A point went into alarm (a tool error appeared, a limit was crossed).
    AlarmRaised,
    /// A point came out of alarm.
    AlarmCleared,
    /// A write was made.
    Write,
    /// A device changed state on its own: a CROSS transferred its load, a machine went
    /// from run to error.
    StateChanged,
    /// A device reported something unsolicited (a Panasonic R message).
    DeviceEvent,
}

impl EventKind {
    /// Every kind, for filters and the API description.
    pub const ALL: [EventKind; 12] = [
        EventKind::GatewayStarted,
        EventKind::GatewayStopped,
        EventKind::LineUp,
        EventKind::LineDown,
        EventKind::LineReopened,
        EventKind::DeviceUp,
        EventKind::DeviceDown,
        EventKind::AlarmRaised,
        EventKind::AlarmCleared,
        EventKind::Write,
        EventKind::StateChanged,
        EventKind::DeviceEvent,
    ];

    /// The name stored and printed (`device_down`).
    pub fn as_str(self) -> &'static str {
        match self {
            EventKind::GatewayStarted => "gateway_started",
            EventKind::GatewayStopped => "gateway_stopped",
            EventKind::LineUp => "line_up",
            EventKind::LineDown => "line_down",
            EventKind::LineReopened => "line_reopened",
            EventKind::DeviceUp => "device_up",
            EventKind::DeviceDown => "device_down",
            EventKind::AlarmRaised => "alarm_raised",
            EventKind::AlarmCleared => "alarm_cleared",
            EventKind::Write => "write",
            EventKind::StateChanged => "state_changed",
            EventKind::DeviceEvent => "device_event",
        }
    }

    /// The kind for a stored name.
    pub fn parse(text: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.as_str() == text)
    }
}

/// An event to record.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Event {
    /// When.
    pub t: Timestamp,
    /// What kind.
    pub kind: EventKind,
    /// The line, if it concerns one.
    pub line: Option<String>,
    /// The device, if it concerns one.
    pub device: Option<DeviceId>,
    /// The point, if it concerns one.
    pub point: Option<PointId>,
    /// Words for the event log.
    pub message: String,
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
}

/// How a write attempt ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum AuditResult {
    /// The device took the value.
    Accepted,
    /// Refused before the wire (bad token, writes off, bad value) or by the device.
    Refused,
    /// The device did not answer or the line failed.
    Failed,
}

impl AuditResult {
    fn as_str(self) -> &'static str {
        match self {
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
    /// Rows dropped because the disk refused writes for too long.
    pub rows_dropped: AtomicU64,
    /// Rows deleted by retention.
    pub rows_pruned: AtomicU64,
}

impl StoreStats {
    /// Every row committed so far.
    pub fn rows_written(&self) -> u64 {
        self.samples_written.load(Ordering::Relaxed)
            + self.events_written.load(Ordering::Relaxed)
            + self.audit_written.load(Ordering::Relaxed)
    }
}

enum Command {
    Sample(Sample),
    Event(Event),
    Audit(AuditEntry),
    Flush(tokio::sync::oneshot::Sender<Result<u64, String>>),
    Prune(Timestamp, tokio::sync::oneshot::Sender<Result<u64, String>>),
    Shutdown,
}

/// The history database; owns the writer thread. Dropping it (or [`Store::close`]) commits
/// what is queued and stops the writer.
#[derive(Debug)]
pub struct Store {
    handle: StoreHandle,
    writer: Option<thread::JoinHandle<()>>,
}

/// A cheap, cloneable way to record rows and run queries.
#[derive(Debug, Clone)]
pub struct StoreHandle {
    tx: mpsc::Sender<Command>,
    readers: Arc<ReaderPool>,
    stats: Arc<StoreStats>,
}

impl Store {
    /// Opens (creating if needed) the history in `dir` and starts its writer.
    pub fn open(dir: &Path, options: StoreOptions) -> Result<Self, StoreError> {
        std::fs::create_dir_all(dir).map_err(|source| StoreError::Directory {
            path: dir.to_owned(),
            source,
        })?;
        let path = dir.join(DB_FILE);
        let sqlite = |source| StoreError::Sqlite {
            path: path.clone(),
            source,
        };
        let conn = Connection::open(&path).map_err(sqlite)?;
        configure(&conn).map_err(sqlite)?;
        conn.execute_batch(SCHEMA).map_err(sqlite)?;
        let points = load_points(&conn).map_err(sqlite)?;
        let stats = Arc::new(StoreStats::default());
        let (tx, rx) = mpsc::channel();
        let writer = Writer {
            conn,
            path: path.clone(),
            points,
            options,
            stats: Arc::clone(&stats),
            pending: VecDeque::new(),
            oldest: None,
            last_prune: None,
        };
        let writer = thread::Builder::new()
            .name("cellbus-history".into())
            .spawn(move || writer.run(rx))
            .map_err(|source| StoreError::Directory {
                path: dir.to_owned(),
                source,
            })?;
        Ok(Self {
            handle: StoreHandle {
                tx,
                readers: Arc::new(ReaderPool {
                    path,
                    idle: Mutex::new(Vec::new()),
                }),
                stats,
            },
            writer: Some(writer),
        })
    }

    /// A handle for recording and querying.
    pub fn handle(&self) -> StoreHandle {
        self.handle.clone()
    }

    /// Commits everything queued and stops the writer.
    pub fn close(mut self) {
        self.stop();
    }

    fn stop(&mut self) {
        if let Some(writer) = self.writer.take() {
            let _ = self.handle.tx.send(Command::Shutdown);
            if writer.join().is_err() {
                tracing::error!("the history writer panicked");
            }
        }
    }
}

impl Drop for Store {
    fn drop(&mut self) {
        self.stop();
    }
}

impl StoreHandle {
    /// Queues a value change.
    pub fn sample(&self, sample: Sample) {
        let _ = self.tx.send(Command::Sample(sample));
    }

    /// Queues an event.
    pub fn event(&self, event: Event) {
        let _ = self.tx.send(Command::Event(event));
    }

    /// Queues a write attempt; the writer commits it at once.
    pub fn audit(&self, entry: AuditEntry) {
        let _ = self.tx.send(Command::Audit(entry));
    }

    /// Commits everything queued before this call; returns the rows committed so far.
    pub async fn flush(&self) -> Result<u64, StoreError> {
        let (reply, answer) = tokio::sync::oneshot::channel();
        self.tx
            .send(Command::Flush(reply))
            .map_err(|_| StoreError::WriterGone)?;
        answer
            .await
            .map_err(|_| StoreError::WriterGone)?
            .map_err(StoreError::Commit)
    }

    /// Deletes rows older than the retention before `now`; returns how many went.
    pub async fn prune(&self, now: Timestamp) -> Result<u64, StoreError> {
        let (reply, answer) = tokio::sync::oneshot::channel();
        self.tx
            .send(Command::Prune(now, reply))
            .map_err(|_| StoreError::WriterGone)?;
        answer
            .await
            .map_err(|_| StoreError::WriterGone)?
            .map_err(StoreError::Commit)
    }

    /// The writer's counters.
    pub fn stats(&self) -> &StoreStats {
        &self.stats
    }

    /// Stored changes of `point` in `[from, to)`, raw or in buckets of `step`.
    pub fn history(
        &self,
        point: &PointId,
        from: Timestamp,
        to: Timestamp,
        step: Option<Duration>,
    ) -> Result<History, StoreError> {
        self.readers.with(|conn| {
            let id: Option<i64> = conn
                .query_row(
                    "SELECT id FROM points WHERE name = ?1",
                    [point.as_str()],
                    |r| r.get(0),
                )
                .optional()?;
            let step_ms = step.map(duration_millis).filter(|s| *s > 0);
            let empty = match step_ms {
                Some(_) => Series::Buckets(Vec::new()),
                None => Series::Samples(Vec::new()),
            };
            let mut history = History {
                point: point.clone(),
                from,
                to,
                step_ms,
                before: None,
                series: empty,
                truncated: false,
            };
            let Some(id) = id else {
                return Ok(history);
            };
            history.before = conn
                .query_row(
                    "SELECT t, value, text, quality FROM samples WHERE point = ?1 AND t < ?2 \
                     ORDER BY t DESC LIMIT 1",
                    params![id, from.0],
                    read_sample,
                )
                .optional()?;
            match step_ms {
                Some(step) => {
                    let mut stmt = conn.prepare_cached(
                        "SELECT (t / ?4) * ?4 AS b, avg(value), min(value), max(value), count(*) \
                         FROM samples WHERE point = ?1 AND t >= ?2 AND t < ?3 \
                         AND quality = 0 AND value IS NOT NULL GROUP BY b ORDER BY b",
                    )?;
                    let buckets = stmt
                        .query_map(params![id, from.0, to.0, step], |r| {
                            Ok(Bucket {
                                t: Timestamp(r.get(0)?),
                                avg: r.get(1)?,
                                min: r.get(2)?,
                                max: r.get(3)?,
                                count: r.get::<_, i64>(4)?.unsigned_abs(),
                            })
                        })?
                        .collect::<Result<Vec<_>, _>>()?;
                    history.series = Series::Buckets(buckets);
                }
                None => {
                    let mut stmt = conn.prepare_cached(
                        "SELECT t, value, text, quality FROM samples \
                         WHERE point = ?1 AND t >= ?2 AND t < ?3 ORDER BY t LIMIT ?4",
                    )?;
                    let limit = i64::try_from(MAX_RAW_SAMPLES + 1).unwrap_or(i64::MAX);
                    let mut samples = stmt
                        .query_map(params![id, from.0, to.0, limit], read_sample)?
                        .collect::<Result<Vec<_>, _>>()?;
                    if samples.len() > MAX_RAW_SAMPLES {
                        samples.truncate(MAX_RAW_SAMPLES);
                        history.truncated = true;
                    }
                    history.series = Series::Samples(samples);
                }
            }
            Ok(history)
        })
    }

    /// Stored events, newest first.
    pub fn events(&self, filter: &EventFilter) -> Result<Vec<EventRecord>, StoreError> {
        self.readers.with(|conn| {
            let mut stmt = conn.prepare_cached(
                "SELECT id, t, kind, line, device, point, message FROM events \
                 WHERE t >= ?1 AND t < ?2 AND (?3 IS NULL OR device = ?3) \
                 AND (?4 IS NULL OR kind = ?4) ORDER BY id DESC LIMIT ?5",
            )?;
            let rows = stmt.query_map(
                params![
                    filter.from.map_or(i64::MIN, |t| t.0),
                    filter.to.map_or(i64::MAX, |t| t.0),
                    filter.device,
                    filter.kind.map(EventKind::as_str),
                    i64::try_from(filter.limit).unwrap_or(i64::MAX),
                ],
                |r| {
                    Ok(EventRecord {
                        id: r.get(0)?,
                        t: Timestamp(r.get(1)?),
                        kind: r.get(2)?,
                        line: r.get(3)?,
                        device: r.get(4)?,
                        point: r.get(5)?,
                        message: r.get(6)?,
                    })
                },
            )?;
            rows.collect()
        })
    }

    /// Stored write attempts, newest first.
    pub fn audit_log(
        &self,
        device: Option<&str>,
        limit: usize,
    ) -> Result<Vec<AuditRecord>, StoreError> {
        self.readers.with(|conn| {
            let mut stmt = conn.prepare_cached(
                "SELECT id, t, client, device, point, old_value, new_value, result, detail \
                 FROM audit WHERE (?1 IS NULL OR device = ?1) ORDER BY id DESC LIMIT ?2",
            )?;
            let json = |text: Option<String>| {
                text.and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
            };
            let rows = stmt.query_map(
                params![device, i64::try_from(limit).unwrap_or(i64::MAX)],
                |r| {
                    Ok(AuditRecord {
                        id: r.get(0)?,
                        t: Timestamp(r.get(1)?),
                        client: r.get(2)?,
                        device: r.get(3)?,
                        point: r.get(4)?,
                        old_value: json(r.get(5)?),
                        new_value: json(r.get(6)?).unwrap_or(serde_json::Value::Null),
                        result: r.get(7)?,
                        detail: r.get(8)?,
                    })
                },
            )?;
            rows.collect()
        })
    }

    /// The database's own consistency check (`PRAGMA integrity_check`): `ok` or the faults.
    pub fn integrity_check(&self) -> Result<String, StoreError> {
        self.readers.with(|conn| {
            let mut stmt = conn.prepare("PRAGMA integrity_check")?;
            let lines = stmt
                .query_map([], |r| r.get::<_, String>(0))?
                .collect::<Result<Vec<_>, _>>()?;
            Ok(lines.join("; "))
        })
    }
}

const SCHEMA: &str = "
CREATE TABLE IF NOT EXISTS points (
    id   INTEGER PRIMARY KEY,
    name TEXT NOT NULL UNIQUE
);
CREATE TABLE IF NOT EXISTS samples (
    point   INTEGER NOT NULL REFERENCES points(id),
    t       INTEGER NOT NULL,
    value   REAL,
    text    TEXT,
    quality INTEGER NOT NULL
);
CREATE INDEX IF NOT EXISTS samples_by_point_time ON samples(point, t);
CREATE TABLE IF NOT EXISTS events (
    id      INTEGER PRIMARY KEY,
    t       INTEGER NOT NULL,
    kind    TEXT NOT NULL,
    line    TEXT,
    device  TEXT,
    point   TEXT,
    message TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS events_by_time ON events(t);
CREATE TABLE IF NOT EXISTS audit (
    id        INTEGER PRIMARY KEY,
    t         INTEGER NOT NULL,
    client    TEXT NOT NULL,
    device    TEXT NOT NULL,
    point     TEXT NOT NULL,
    old_value TEXT,
    new_value TEXT NOT NULL,
    result    TEXT NOT NULL,
    detail    TEXT NOT NULL
);
PRAGMA user_version = 1;
";

/// WAL, FULL sync (see the module docs), and patience with a busy database.
fn configure(conn: &Connection) -> rusqlite::Result<()> {
    conn.pragma_update(None, "journal_mode", "WAL")?;
    conn.pragma_update(None, "synchronous", "FULL")?;
    conn.busy_timeout(Duration::from_secs(5))?;
    Ok(())
}

fn load_points(conn: &Connection) -> rusqlite::Result<HashMap<String, i64>> {
    // The schema may not exist yet on a reader opened before the writer; callers order it.
    let mut stmt = conn.prepare("SELECT name, id FROM points")?;
    let rows = stmt.query_map([], |r| Ok((r.get(0)?, r.get(1)?)))?;
    rows.collect()
}

fn read_sample(r: &rusqlite::Row<'_>) -> rusqlite::Result<HistorySample> {
    let number: Option<f64> = r.get(1)?;
    let text: Option<String> = r.get(2)?;
    Ok(HistorySample {
        t: Timestamp(r.get(0)?),
        value: number.map(Value::Number).or(text.map(Value::Text)),
        quality: Quality::from_code(r.get(3)?),
    })
}

/// Read connections, reused.
#[derive(Debug)]
struct ReaderPool {
    path: PathBuf,
    idle: Mutex<Vec<Connection>>,
}

impl ReaderPool {
    fn with<T>(&self, f: impl FnOnce(&Connection) -> rusqlite::Result<T>) -> Result<T, StoreError> {
        let sqlite = |source| StoreError::Sqlite {
            path: self.path.clone(),
            source,
        };
        let taken = self
            .idle
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .pop();
        let conn = match taken {
            Some(conn) => conn,
            None => {
                let conn = Connection::open(&self.path).map_err(sqlite)?;
                conn.busy_timeout(Duration::from_secs(5)).map_err(sqlite)?;
                conn.pragma_update(None, "query_only", true)
                    .map_err(sqlite)?;
                conn
            }
        };
        let result = f(&conn).map_err(sqlite);
        self.idle
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(conn);
        result
    }
}

/// A row waiting for its commit.
enum Row {
    Sample(Sample),
    Event(Event),
    Audit(AuditEntry),
}

struct Writer {
    conn: Connection,
    path: PathBuf,
    points: HashMap<String, i64>,
    options: StoreOptions,
    stats: Arc<StoreStats>,
    pending: VecDeque<Row>,
    oldest: Option<Instant>,
    last_prune: Option<Instant>,
}

impl Writer {
    fn run(mut self, rx: mpsc::Receiver<Command>) {
        self.prune_if_due(Timestamp::now());
        loop {
            let wait = match self.oldest {
                Some(oldest) => {
                    (oldest + self.options.batch_delay).saturating_duration_since(Instant::now())
                }
                None => self.options.prune_every.min(Duration::from_secs(60)),
            };
            match rx.recv_timeout(wait) {
                Ok(Command::Sample(sample)) => self.push(Row::Sample(sample)),
                Ok(Command::Event(event)) => self.push(Row::Event(event)),
                Ok(Command::Audit(entry)) => {
                    self.push(Row::Audit(entry));
                    let _ = self.commit();
                }
                Ok(Command::Flush(reply)) => {
                    let _ = reply.send(self.commit().map(|()| self.stats.rows_written()));
                }
                Ok(Command::Prune(now, reply)) => {
                    let result = self.commit().and_then(|()| self.prune(now));
                    let _ = reply.send(result);
                }
                Ok(Command::Shutdown) | Err(mpsc::RecvTimeoutError::Disconnected) => {
                    if let Err(e) = self.commit() {
                        tracing::error!(
                            "history: {} rows could not be committed at shutdown: {e}",
                            self.pending.len()
                        );
                    }
                    return;
                }
                Err(mpsc::RecvTimeoutError::Timeout) => {
                    let _ = self.commit();
                    self.prune_if_due(Timestamp::now());
                }
            }
        }
    }

    fn push(&mut self, row: Row) {
        if self.pending.len() >= MAX_PENDING_ROWS {
            self.pending.pop_front();
            self.stats.rows_dropped.fetch_add(1, Ordering::Relaxed);
        }
        self.pending.push_back(row);
        self.oldest.get_or_insert_with(Instant::now);
        if self.pending.len() >= self.options.batch_rows {
            let _ = self.commit();
        }
    }

    /// Commits the pending rows in one transaction. On failure they stay pending.
    fn commit(&mut self) -> Result<(), String> {
        if self.pending.is_empty() {
            return Ok(());
        }
        let mut rows = std::mem::take(&mut self.pending);
        match write_rows(&mut self.conn, &mut self.points, rows.make_contiguous()) {
            Ok(counts) => {
                self.oldest = None;
                let s = &self.stats;
                s.samples_written.fetch_add(counts[0], Ordering::Relaxed);
                s.events_written.fetch_add(counts[1], Ordering::Relaxed);
                s.audit_written.fetch_add(counts[2], Ordering::Relaxed);
                s.commits.fetch_add(1, Ordering::Relaxed);
                Ok(())
            }
            Err(e) => {
                self.stats.commit_errors.fetch_add(1, Ordering::Relaxed);
                tracing::error!("history {}: commit failed: {e}", self.path.display());
                // Ids handed out inside the failed transaction are gone with it.
                self.points = load_points(&self.conn).unwrap_or_default();
                self.pending = rows;
                Err(e.to_string())
            }
        }
    }

    fn prune_if_due(&mut self, now: Timestamp) {
        let due = self
            .last_prune
            .is_none_or(|last| last.elapsed() >= self.options.prune_every);
        if due {
            self.last_prune = Some(Instant::now());
            if let Err(e) = self.prune(now) {
                tracing::error!("history {}: retention failed: {e}", self.path.display());
            }
        }
    }

    fn prune(&mut self, now: Timestamp) -> Result<u64, String> {
        let cutoff = now.minus(self.options.retain).0;
        let mut deleted = 0u64;
        let ids: Vec<i64> = self.points.values().copied().collect();
        for id in ids {
            let n = self
                .conn
                .execute(
                    "DELETE FROM samples WHERE point = ?1 AND t < ?2",
                    params![id, cutoff],
                )
                .map_err(|e| e.to_string())?;
            deleted += n as u64;
        }
        let n = self
            .conn
            .execute("DELETE FROM events WHERE t < ?1", [cutoff])
            .map_err(|e| e.to_string())?;
        deleted += n as u64;
        self.stats.rows_pruned.fetch_add(deleted, Ordering::Relaxed);
        Ok(deleted)
    }
}

/// Writes rows in one transaction; returns how many samples, events and audit rows.
fn write_rows(
    conn: &mut Connection,
    points: &mut HashMap<String, i64>,
    rows: &[Row],
) -> rusqlite::Result<[u64; 3]> {
    let tx = conn.transaction()?;
    let mut counts = [0u64; 3];
    for row in rows {
        match row {
            Row::Sample(s) => {
                let id = point_id(&tx, points, s.point.as_str())?;
                let (number, text) = match &s.value {
                    Some(Value::Number(n)) => (Some(*n), None),
                    Some(Value::Text(t)) => (None, Some(t.as_str())),
                    None => (None, None),
                };
                tx.prepare_cached(
                    "INSERT INTO samples (point, t, value, text, quality) VALUES (?1, ?2, ?3, ?4, ?5)",
                )?
                .execute(params![id, s.t.0, number, text, s.quality.code()])?;
                counts[0] += 1;
            }
            Row::Event(e) => {
                tx.prepare_cached(
                    "INSERT INTO events (t, kind, line, device, point, message) VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
                )?
                .execute(params![
                    e.t.0,
                    e.kind.as_str(),
                    e.line,
                    e.device.as_ref().map(DeviceId::as_str),
                    e.point.as_ref().map(PointId::as_str),
                    e.message
                ])?;
                counts[1] += 1;
            }
            Row::Audit(a) => {
                let old = a.old.as_ref().and_then(|v| serde_json::to_string(v).ok());
                tx.prepare_cached(
                    "INSERT INTO audit (t, client, device, point, old_value, new_value, result, detail) \
                     VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8)",
                )?
                .execute(params![
                    a.t.0,
                    a.client,
                    a.device,
                    a.point,
                    old,
                    a.new.to_string(),
                    a.result.as_str(),
                    a.detail
                ])?;
                counts[2] += 1;
            }
        }
    }
    tx.commit()?;
    Ok(counts)
}

fn point_id(
    tx: &Transaction<'_>,
    points: &mut HashMap<String, i64>,
    name: &str,
) -> rusqlite::Result<i64> {
    if let Some(id) = points.get(name) {
        return Ok(*id);
    }
    tx.prepare_cached("INSERT INTO points (name) VALUES (?1)")?
        .execute([name])?;
    let id = tx.last_insert_rowid();
    points.insert(name.to_owned(), id);
    Ok(id)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(name: &str) -> PointId {
        PointId::parse(name).unwrap()
    }

    fn sample(p: &str, t: i64, v: f64) -> Sample {
        Sample {
            point: point(p),
            t: Timestamp(t),
            value: Some(Value::Number(v)),
            quality: Quality::Good,
        }
    }

    fn samples_of(h: &History) -> Vec<(i64, Option<Value>)> {
        match &h.series {
            Series::Samples(s) => s.iter().map(|s| (s.t.0, s.value.clone())).collect(),
            Series::Buckets(_) => panic!("expected raw samples"),
        }
    }

    #[tokio::test]
    async fn samples_come_back_in_time_order_for_their_point_and_range() {
        let dir = tempfile::tempdir().unwrap();
        let store = Store::open(dir.path(), StoreOptions::default()).unwrap();
        let h = store.handle();
        for (t, v) in [(1000, 1.0), (2000, 2.0), (3000, 3.0), (4000, 4.0)] {
            h.sample(sample("a.temp", t, v));
            h.sample(sample("b.temp", t, v * 10.0));
        }
        h.sample(Sample {
            point: point("a.model"),
            t: Timestamp(1500),
            value: Some(Value::Text("JTSE".into())),
            quality: Quality::Good,
        });
        assert_eq!(h.flush().await.unwrap(), 9);
        let got = h
            .history(&point("a.temp"), Timestamp(2000), Timestamp(4000), None)
            .unwrap();
        assert_eq!(
            samples_of(&got),
            vec![
                (2000, Some(Value::Number(2.0))),
                (3000, Some(Value::Number(3.0)))
            ]
        );
        assert_eq!(got.before.unwrap().value, Some(Value::Number(1.0)));
        let text = h
            .history(&point("a.model"), Timestamp(0), Timestamp(9999), None)
            .unwrap();
        assert_eq!(
            samples_of(&text),
            vec![(1500, Some(Value::Text("JTSE".into())))]
        );
        let none = h
            .history(&point("c.temp"), Timestamp(0), Timestamp(9999), None)
            .unwrap();
        assert_eq!(samples_of(&none), vec![]);
    }

    #[tokio::test]
    async fn a_step_gives_average_min_and_max_per_bucket_of_good_values() {
        let dir = tempfile::tempdir().unwrap();
        let store = Store::open(dir.path(), StoreOptions::default()).unwrap();
        let h = store.handle();
        for (t, v) in [(0, 1.0), (400, 3.0), (999, 5.0), (1000, 10.0), (2500, 7.0)] {
            h.sample(sample("a.temp", t, v));
        }
        h.sample(Sample {
            point: point("a.temp"),
            t: Timestamp(2600),
            value: None,
            quality: Quality::Bad,
        });
        h.flush().await.unwrap();
        let got = h
            .history(
                &point("a.temp"),
                Timestamp(0),
                Timestamp(3000),
                Some(Duration::from_secs(1)),
            )
            .unwrap();
        let Series::Buckets(b) = got.series else {
            panic!("expected buckets")
        };
        assert_eq!(
            b,
            vec![
                Bucket {
                    t: Timestamp(0),
                    avg: 3.0,
                    min: 1.0,
                    max: 5.0,
                    count: 3
                },
                Bucket {
                    t: Timestamp(1000),
                    avg: 10.0,
                    min: 10.0,
                    max: 10.0,
                    count: 1
                },
                Bucket {
                    t: Timestamp(2000),
                    avg: 7.0,
                    min: 7.0,
                    max: 7.0,
                    count: 1
                },
            ]
        );
        assert_eq!(got.step_ms, Some(1000));
    }

    #[tokio::test]
    async fn rows_are_committed_in_batches_without_a_flush() {
        let dir = tempfile::tempdir().unwrap();
        let options = StoreOptions {
            batch_rows: 10,
            batch_delay: Duration::from_secs(3600),
            ..StoreOptions::default()
        };
        let store = Store::open(dir.path(), options).unwrap();
        let h = store.handle();
        for t in 0..25 {
            h.sample(sample("a.temp", t, t as f64));
        }
        // Two full batches are committed by the writer on its own; wait for them with a
        // bounded poll of the committed count (the writer is a real thread).
        let deadline = Instant::now() + Duration::from_secs(10);
        while h.stats().samples_written.load(Ordering::Relaxed) < 20 {
            assert!(Instant::now() < deadline, "batches were not committed");
            std::thread::yield_now();
        }
        assert_eq!(h.stats().samples_written.load(Ordering::Relaxed), 20);
        assert_eq!(h.flush().await.unwrap(), 25);
    }

    #[tokio::test]
    async fn closing_the_store_commits_what_is_queued() {
        let dir = tempfile::tempdir().unwrap();
        let options = StoreOptions {
            batch_delay: Duration::from_secs(3600),
            ..StoreOptions::default()
        };
        let store = Store::open(dir.path(), options).unwrap();
        let h = store.handle();
        for t in 0..7 {
            h.sample(sample("a.temp", t, 1.0));
        }
        store.close();
        let store = Store::open(dir.path(), StoreOptions::default()).unwrap();
        let got = store
            .handle()
            .history(&point("a.temp"), Timestamp(0), Timestamp(100), None)
            .unwrap();
        assert_eq!(samples_of(&got).len(), 7);
    }

    #[tokio::test]
    async fn retention_deletes_samples_and_events_older_than_the_limit_and_keeps_audit() {
        let dir = tempfile::tempdir().unwrap();
        let options = StoreOptions {
            retain: Duration::from_secs(10),
            ..StoreOptions::default()
        };
        let store = Store::open(dir.path(), options).unwrap();
        let h = store.handle();
        for t in [1_000, 5_000, 15_000, 25_000] {
            h.sample(sample("a.temp", t, 1.0));
            h.event(Event {
                t: Timestamp(t),
                kind: EventKind::DeviceDown,
                line: None,
                device: Some(DeviceId::new("a").unwrap()),
                point: None,
                message: "down".into(),
            });
        }
        h.audit(AuditEntry {
            t: Timestamp(1),
            client: "127.0.0.1:5000".into(),
            device: "a".into(),
            point: "a.temp".into(),
            old: None,
            new: serde_json::json!(3),
            result: AuditResult::Refused,
            detail: "writes are disabled".into(),
        });
        h.flush().await.unwrap();
        // Now is 20 s: everything before 10 s goes.
        assert_eq!(h.prune(Timestamp(20_000)).await.unwrap(), 4);
        let got = h
            .history(&point("a.temp"), Timestamp(0), Timestamp(99_999), None)
            .unwrap();
        assert_eq!(
            samples_of(&got)
                .into_iter()
                .map(|(t, _)| t)
                .collect::<Vec<_>>(),
            vec![15_000, 25_000]
        );
        let events = h
            .events(&EventFilter {
                limit: 100,
                ..EventFilter::default()
            })
            .unwrap();
        assert_eq!(
            events.iter().map(|e| e.t.0).collect::<Vec<_>>(),
            vec![25_000, 15_000]
        );
        assert_eq!(h.audit_log(None, 10).unwrap().len(), 1);
    }

    #[tokio::test]
    async fn events_filter_by_device_kind_and_time_newest_first() {
        let dir = tempfile::tempdir().unwrap();
        let store = Store::open(dir.path(), StoreOptions::default()).unwrap();
        let h = store.handle();
        let ev = |t, kind, device: &str| Event {
            t: Timestamp(t),
            kind,
            line: Some("bench".into()),
            device: Some(DeviceId::new(device).unwrap()),
            point: None,
            message: format!("{device} {t}"),
        };
        h.event(ev(1, EventKind::DeviceDown, "a"));
        h.event(ev(2, EventKind::DeviceUp, "a"));
        h.event(ev(3, EventKind::DeviceDown, "b"));
        h.event(ev(4, EventKind::DeviceDown, "a"));
        h.flush().await.unwrap();
        let got = h
            .events(&EventFilter {
                device: Some("a".into()),
                kind: Some(EventKind::DeviceDown),
                limit: 10,
                ..EventFilter::default()
            })
            .unwrap();
        assert_eq!(
            got.iter().map(|e| e.message.as_str()).collect::<Vec<_>>(),
            vec!["a 4", "a 1"]
        );
        let got = h
            .events(&EventFilter {
                from: Some(Timestamp(2)),
                to: Some(Timestamp(4)),
                limit: 1,
                ..EventFilter::default()
            })
            .unwrap();
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].message, "b 3");
        assert_eq!(got[0].line.as_deref(), Some("bench"));
    }

    #[tokio::test]
    async fn audit_rows_keep_old_and_new_values_as_json() {
        let dir = tempfile::tempdir().unwrap();
        let store = Store::open(dir.path(), StoreOptions::default()).unwrap();
        let h = store.handle();
        h.audit(AuditEntry {
            t: Timestamp(5),
            client: "127.0.0.1:4000".into(),
            device: "jbc1".into(),
            point: "jbc1.air_temperature_setpoint".into(),
            old: Some(Value::Number(350.0)),
            new: serde_json::json!(400),
            result: AuditResult::Accepted,
            detail: "written".into(),
        });
        h.flush().await.unwrap();
        let rows = h.audit_log(Some("jbc1"), 10).unwrap();
        assert_eq!(rows.len(), 1);
        assert_eq!(rows[0].old_value, Some(serde_json::json!(350.0)));
        assert_eq!(rows[0].new_value, serde_json::json!(400));
        assert_eq!(rows[0].result, "accepted");
        assert!(h.audit_log(Some("other"), 10).unwrap().is_empty());
        assert_eq!(h.integrity_check().unwrap(), "ok");
    }

    #[test]
    fn an_unusable_data_directory_is_named_in_the_error() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("not-a-dir");
        std::fs::write(&file, b"x").unwrap();
        let err = Store::open(&file.join("sub"), StoreOptions::default()).unwrap_err();
        assert!(err.to_string().contains("not-a-dir"), "{err}");
        assert!(err.to_string().contains("--data"), "{err}");
    }

    #[test]
    fn event_kinds_round_trip_through_their_names() {
        for kind in EventKind::ALL {
            assert_eq!(EventKind::parse(kind.as_str()), Some(kind));
        }
        assert_eq!(EventKind::parse("nope"), None);
    }
}
