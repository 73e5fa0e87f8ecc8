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
//!
//! - [`records`]: what is stored and what queries return.
//! - `schema`: the tables and the connection settings.
//! - `writer`: the writer thread's batches and retention.
//! - `query`: the read connections and the queries.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, mpsc};
use std::thread;
use std::time::Duration;

use rusqlite::Connection;

use crate::time::Timestamp;

mod query;
mod records;
mod schema;
mod writer;

pub use records::*;

/// Longest text of one audit field an audit query returns, in characters.
pub const AUDIT_FIELD_MAX: i64 = 2048;

use crate::event::{Event, EventKind};
use query::*;
use schema::*;
use writer::*;

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
}

#[cfg(test)]
mod tests;
