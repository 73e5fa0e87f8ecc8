//! The history: every value change, every event and every write attempt, in SQLite.
//!
//! One database file, `cellbus.db`, in the data directory. A dedicated writer thread owns
//! the only writing connection; the pollers and the HTTP handlers send it rows through a
//! channel and never wait for the disk. The writer commits a batch every
//! [`StoreOptions::batch_delay`] (200 ms) or [`StoreOptions::batch_rows`] (20 000 rows),
//! whichever comes first, and at once for an audit row. The delay is the bound in normal
//! running; the row count only cuts batches short above 100 000 changes per second, and is
//! high because each commit costs an fsync (see below) and rewrites every index page the
//! batch touched (with a thousand points, about a thousand leaves of
//! `samples_by_point_time` whatever the batch's size): 500-row commits capped the
//! throughput at the disk's fsync rate in the store bench, and 20 000-row commits ingest
//! 1.5–2× the rows per second of 5 000-row ones (`store_ingest` bench). Queries run on separate read
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
//! [`StoreOptions::prune_every`], the audit table's after [`StoreOptions::retain_audit`]
//! (a year by default, never less than the history's). Deletes go in chunks of
//! [`StoreOptions::prune_chunk_rows`], each its own transaction, with new rows committed
//! between chunks, so a large prune never stalls the writer for long. A new file is created
//! with `auto_vacuum=INCREMENTAL`, and a prune that deleted rows returns the freed pages
//! to the file system (`PRAGMA incremental_vacuum`) and truncates the WAL
//! (`wal_checkpoint(TRUNCATE)`). A file created before this setting keeps
//! `auto_vacuum=NONE` (SQLite can change it only by a full `VACUUM`, which copies the whole
//! file): its freed pages are reused but the file does not shrink.
//!
//! Faults: a failed commit keeps its rows pending and is retried after a wait that doubles
//! from 100 ms to 30 s; one log line per wait says how many commits failed since the last
//! one. While rows cannot be committed, at most [`MAX_PENDING_ROWS`] are kept: past it the
//! oldest samples are dropped first, then the oldest events, never audit rows (counted in
//! [`StoreStats::rows_dropped`]). The first failure queues a `history_failed` event and the
//! first commit after it records `history_recovered`. [`StoreHandle::health`] is degraded
//! while a commit failed in the last minute. At start the writer runs `PRAGMA quick_check`;
//! a file that is not a database or fails it is moved aside as
//! `cellbus.db.corrupt-<UTC time>` (with its `-wal` and `-shm`), a new one is started, and a
//! `history_reset` event names the old one. A data directory that cannot be used turns the
//! history off ([`Store::start`]): rows are counted and discarded, queries answer
//! [`StoreError::Unavailable`], and the live values go on.
//!
//! - [`records`]: what is stored and what queries return.
//! - `schema`: the tables and the connection settings.
//! - `open`: opening, checking and moving aside a damaged file.
//! - `fault`: when to retry a failed commit and what to log.
//! - `writer`: the writer thread's batches (multi-row inserts) and retention.
//! - `rollup`: per-minute rollups (count, exact sum, min, max per point and minute) kept
//!   in the batches' transactions; bucketed queries of whole minutes read them.
//! - `query`: the read connections and the queries.
//! - `settings`: small values kept across restarts (the Sparkplug `bdSeq`).
//! - `outbox`: messages an interface made and its receiver has not yet accepted (IPC-CFX's),
//!   with what made them must remember, kept across restarts.

use std::future::Future;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::sync::{Arc, Condvar, Mutex, PoisonError, mpsc};
use std::thread;
use std::time::Duration;

use crate::time::Timestamp;

mod changes;
mod fault;
mod inbox;
pub mod lock;
mod open;
mod outbox;
mod query;
mod records;
mod rollup;
mod schema;
mod settings;
mod writer;

pub use changes::ChangeCursor;
pub use outbox::Outbox;
pub use records::*;
pub use settings::{read_setting, write_setting};

/// Longest text of one audit field an audit query returns, in characters.
pub const AUDIT_FIELD_MAX: i64 = 2048;

use crate::event::{Event, EventKind};
use changes::*;
use query::*;
use schema::*;
use writer::*;

/// File name of the database inside the data directory.
pub const DB_FILE: &str = "cellbus.db";

/// Most raw samples one history query returns (kit's, shared with the historian).
pub use kit::history::MAX_RAW_SAMPLES;

/// Most pending rows kept while the disk refuses writes; past it the oldest samples go
/// first, then the oldest events; audit rows are never dropped.
pub const MAX_PENDING_ROWS: usize = 200_000;

/// Pending rows past which the history is reported degraded even without a recent failure.
pub const PENDING_ROWS_DEGRADED: usize = MAX_PENDING_ROWS / 4;

/// How long after a failed commit the history is reported degraded.
pub const FAULT_WINDOW: Duration = Duration::from_secs(60);

/// The wait before retrying a failed commit, doubling up to [`COMMIT_RETRY_CAP`].
pub const COMMIT_RETRY_FIRST: Duration = Duration::from_millis(100);

/// The longest wait between two attempts to commit.
pub const COMMIT_RETRY_CAP: Duration = Duration::from_secs(30);

/// How long a query waits for the writer to finish opening and checking the file.
const OPEN_WAIT: Duration = Duration::from_secs(120);

/// How the store batches and how long it keeps history.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StoreOptions {
    /// Samples and events older than this are deleted.
    pub retain: Duration,
    /// Audit rows older than this are deleted; never less than `retain` (the longer wins).
    pub retain_audit: Duration,
    /// Commit when this many rows are waiting.
    pub batch_rows: usize,
    /// Commit when the oldest waiting row is this old.
    pub batch_delay: Duration,
    /// How often old rows are deleted.
    pub prune_every: Duration,
    /// Rows deleted per retention transaction; new rows are committed between two.
    pub prune_chunk_rows: usize,
}

impl Default for StoreOptions {
    /// 30 days of history, a year of audit, 20 000 rows or 200 ms, pruning hourly in
    /// chunks of 10 000 rows.
    fn default() -> Self {
        Self {
            retain: Duration::from_secs(30 * 24 * 3600),
            retain_audit: Duration::from_secs(365 * 24 * 3600),
            batch_rows: 20_000,
            batch_delay: Duration::from_millis(200),
            prune_every: Duration::from_secs(3600),
            prune_chunk_rows: 10_000,
        }
    }
}

impl StoreOptions {
    /// How long audit rows are kept: `retain_audit`, or `retain` if that is longer.
    pub fn audit_retention(&self) -> Duration {
        self.retain_audit.max(self.retain)
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
    /// A damaged file could not be moved aside.
    #[error("history database {path} is damaged ({fault}) and cannot be moved aside: {source}")]
    MoveAside {
        /// The database file.
        path: PathBuf,
        /// What was wrong with it.
        fault: String,
        /// What the OS said.
        source: std::io::Error,
    },
    /// The history is off: its directory or file could not be used at start.
    #[error("history is off: {reason}; live values still work; fix the data directory and restart")]
    Unavailable {
        /// Why, with the directory and what the OS or SQLite said.
        reason: String,
    },
    /// The writer thread has stopped (after a failed commit or at shutdown).
    #[error("the history writer has stopped")]
    WriterGone,
    /// A commit failed; the rows stay queued and are retried.
    #[error("history commit failed: {0}")]
    Commit(String),
}

enum Command {
    /// Samples wait in the [`inbox::Inbox`]: take them.
    Wake,
    Event(Event),
    /// An audit row, committed at once with the samples queued before it (the inbox's
    /// mark when it was sent), never with later ones.
    Audit(AuditEntry, u64),
    Flush(tokio::sync::oneshot::Sender<Result<u64, String>>),
    Prune(Timestamp, tokio::sync::oneshot::Sender<Result<u64, String>>),
    /// Caps the file at its current size (`max_page_count`), as a full disk would.
    #[cfg(test)]
    FillDisk(bool),
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
    inbox: Arc<inbox::Inbox>,
    readers: Arc<ReaderPool>,
    stats: Arc<StoreStats>,
    shared: Arc<Shared>,
}

/// What the writer tells the handles: whether the file is open, the last commit fault.
#[derive(Debug, Default)]
pub(crate) struct Shared {
    state: Mutex<SharedState>,
    opened: Condvar,
}

#[derive(Debug, Default)]
struct SharedState {
    /// `None` while the writer opens and checks the file.
    open: Option<Result<(), String>>,
    /// The last failed commit: when and why.
    last_fault: Option<(Timestamp, String)>,
    /// Set while commits fail, cleared by the first that works.
    failing: bool,
}

impl Shared {
    fn lock(&self) -> std::sync::MutexGuard<'_, SharedState> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn set_open(&self, result: Result<(), String>) {
        self.lock().open = Some(result);
        self.opened.notify_all();
    }

    fn fault(&self, t: Timestamp, error: &str) {
        let mut state = self.lock();
        state.last_fault = Some((t, error.to_owned()));
        state.failing = true;
    }

    fn recovered(&self) {
        self.lock().failing = false;
    }

    /// Waits (bounded) until the writer has opened the file; `Err` if the history is off.
    fn wait_open(&self) -> Result<(), StoreError> {
        let state = self.lock();
        let (state, _) = self
            .opened
            .wait_timeout_while(state, OPEN_WAIT, |s| s.open.is_none())
            .unwrap_or_else(PoisonError::into_inner);
        match &state.open {
            Some(Ok(())) => Ok(()),
            Some(Err(reason)) => Err(StoreError::Unavailable {
                reason: reason.clone(),
            }),
            None => Err(StoreError::Unavailable {
                reason: format!(
                    "the history file is still being checked after {} s",
                    OPEN_WAIT.as_secs()
                ),
            }),
        }
    }
}

/// How the history is doing, for `/healthz`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StoreHealth {
    /// Off, failing or fine.
    pub history: HistoryState,
    /// Rows waiting for a commit.
    pub pending_rows: u64,
    /// Rows never stored (dropped under back-pressure or discarded while off).
    pub rows_dropped: u64,
    /// The last failed commit, however old: when and why.
    pub last_fault: Option<(Timestamp, String)>,
}

/// The history's state in one word and its reason.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum HistoryState {
    /// Commits work (or the last failure is more than [`FAULT_WINDOW`] old).
    Ok,
    /// The writer is still opening and checking the file.
    Opening,
    /// A commit failed in the last [`FAULT_WINDOW`], or too many rows are pending.
    Failing(String),
    /// The history could not be opened at start; rows are discarded.
    Off(String),
}

impl StoreHealth {
    /// Whether the history has a problem (`/healthz` then says `failing`).
    pub fn degraded(&self) -> bool {
        matches!(
            self.history,
            HistoryState::Failing(_) | HistoryState::Off(_)
        )
    }

    /// `ok`, `opening`, `failing: <error>` or `off: <error>`.
    pub fn summary(&self) -> String {
        match &self.history {
            HistoryState::Ok => "ok".to_owned(),
            HistoryState::Opening => "opening".to_owned(),
            HistoryState::Failing(e) => format!("failing: {e}"),
            HistoryState::Off(e) => format!("off: {e}"),
        }
    }
}

impl Store {
    /// Opens (creating if needed) the history in `dir`, checks it and starts its writer;
    /// waits for the check and says what failed. A damaged file is moved aside and a new one
    /// started (see the module docs).
    pub fn open(dir: &Path, options: StoreOptions) -> Result<Self, StoreError> {
        let (store, opened) = Self::spawn(dir, options);
        match opened.recv() {
            Ok(Ok(())) => Ok(store),
            Ok(Err(e)) => Err(e),
            Err(_) => Err(StoreError::WriterGone),
        }
    }

    /// Starts the history in `dir` without waiting: the writer opens and checks the file on
    /// its own thread while rows queue. If the directory or the file cannot be used, the
    /// history is off (logged, in [`StoreHandle::health`]): rows are counted and discarded
    /// and queries answer [`StoreError::Unavailable`]. What a gateway uses: polling and
    /// the live API never wait on the history.
    pub fn start(dir: &Path, options: StoreOptions) -> Self {
        Self::spawn(dir, options).0
    }

    fn spawn(dir: &Path, options: StoreOptions) -> (Self, mpsc::Receiver<Result<(), StoreError>>) {
        let path = dir.join(DB_FILE);
        let stats = Arc::new(StoreStats::default());
        let shared = Arc::new(Shared::default());
        let (tx, rx) = mpsc::channel();
        let (opened_tx, opened) = mpsc::channel();
        let inbox = Arc::new(inbox::Inbox::new(
            options.batch_rows.min(writer::DRAIN_MAX),
            Arc::clone(&stats),
        ));
        let spawned = {
            let (dir, stats, shared) = (dir.to_owned(), Arc::clone(&stats), Arc::clone(&shared));
            let inbox = Arc::clone(&inbox);
            thread::Builder::new()
                .name("cellbus-history".into())
                .spawn(move || run_writer(&dir, options, stats, shared, inbox, rx, opened_tx))
        };
        let writer = match spawned {
            Ok(writer) => Some(writer),
            Err(e) => {
                let reason = format!("cannot start the history writer thread: {e}");
                tracing::error!("{reason}");
                inbox.close();
                shared.set_open(Err(reason.clone()));
                // `opened` then reports the sender gone: `open` says so.
                None
            }
        };
        let store = Self {
            handle: StoreHandle {
                tx,
                inbox,
                readers: Arc::new(ReaderPool {
                    path,
                    idle: Mutex::new(Vec::new()),
                    shared: Arc::clone(&shared),
                }),
                stats,
                shared,
            },
            writer,
        };
        (store, opened)
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
    /// Queues a value change. It waits in the inbox, without waking the writer thread
    /// unless the writer has no batch open (see `inbox`).
    pub fn sample(&self, sample: Sample) {
        match self.inbox.put(sample) {
            inbox::Put::Queued => {}
            // A writer that is gone closed the inbox and counted what it left.
            inbox::Put::Wake => {
                let _ = self.tx.send(Command::Wake);
            }
            inbox::Put::Closed => {
                self.stats.rows_dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Queues an event.
    pub fn event(&self, event: Event) {
        self.send(Command::Event(event));
    }

    /// Queues a write attempt; the writer commits it at once (unless commits are failing).
    pub fn audit(&self, entry: AuditEntry) {
        self.send(Command::Audit(entry, self.inbox.mark()));
    }

    fn send(&self, command: Command) {
        if self.tx.send(command).is_err() {
            self.stats.rows_dropped.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Commits everything queued before this call; returns the rows committed so far. While
    /// commits fail and wait for their retry, answers the last error at once.
    pub fn flush(&self) -> impl Future<Output = Result<u64, StoreError>> + use<> {
        self.ask(Command::Flush)
    }

    /// Deletes rows older than the retention before `now` (in chunks, new rows being
    /// committed between them); returns how many went.
    pub fn prune(&self, now: Timestamp) -> impl Future<Output = Result<u64, StoreError>> + use<> {
        self.ask(move |reply| Command::Prune(now, reply))
    }

    /// Sends the writer the command `ask` makes of a reply channel; the future gives the
    /// writer's answer.
    fn ask<A>(&self, ask: A) -> impl Future<Output = Result<u64, StoreError>> + use<A>
    where
        A: FnOnce(tokio::sync::oneshot::Sender<Result<u64, String>>) -> Command,
    {
        let (reply, answer) = tokio::sync::oneshot::channel();
        let sent = self.tx.send(ask(reply));
        async move {
            sent.map_err(|_| StoreError::WriterGone)?;
            answer
                .await
                .map_err(|_| StoreError::WriterGone)?
                .map_err(StoreError::Commit)
        }
    }

    /// The writer's counters.
    pub fn stats(&self) -> &StoreStats {
        &self.stats
    }

    /// How the history is doing at `now`: degraded while a commit failed in the last
    /// [`FAULT_WINDOW`] or more than [`PENDING_ROWS_DEGRADED`] rows wait, or when it is off.
    pub fn health(&self, now: Timestamp) -> StoreHealth {
        let pending_rows = self.stats.rows_waiting();
        let rows_dropped = self.stats.rows_dropped.load(Ordering::Relaxed);
        let state = self.shared.lock();
        let recent = state
            .last_fault
            .as_ref()
            .filter(|(t, _)| state.failing || now.minus(FAULT_WINDOW) < *t);
        let history = match (&state.open, recent) {
            (None, _) => HistoryState::Opening,
            (Some(Err(reason)), _) => HistoryState::Off(reason.clone()),
            (Some(Ok(())), Some((_, error))) => HistoryState::Failing(error.clone()),
            (Some(Ok(())), None) if pending_rows > PENDING_ROWS_DEGRADED as u64 => {
                HistoryState::Failing(format!("{pending_rows} rows wait for their commit"))
            }
            (Some(Ok(())), None) => HistoryState::Ok,
        };
        StoreHealth {
            history,
            pending_rows,
            rows_dropped,
            last_fault: state.last_fault.clone(),
        }
    }

    /// Waits (at most two minutes) until the writer has opened and checked the file;
    /// [`StoreError::Unavailable`] if the history is off. Blocks: not for async code.
    pub fn wait_open(&self) -> Result<(), StoreError> {
        self.shared.wait_open()
    }

    /// Makes the writer's commits fail as on a full disk (`true`) or work again (`false`).
    #[cfg(test)]
    pub(crate) async fn fill_disk(&self, full: bool) {
        let _ = self.tx.send(Command::FillDisk(full));
        // Samples travel apart from commands (the inbox): a flush queued behind the fault
        // returns once the disk is full, so the samples a test queues next meet it. Its
        // own result (an error with rows pending) is not the point.
        if full {
            let _ = self.flush().await;
        }
    }
}

#[cfg(test)]
mod tests;
