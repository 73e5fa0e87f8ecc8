//! The writer thread: batches of rows, commits and their retries, retention in chunks.

use std::collections::{HashMap, VecDeque};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::sync::{Arc, LazyLock, mpsc};
use std::time::{Duration, Instant};

use rusqlite::{Connection, OptionalExtension, Transaction, params};

use crate::point::{DeviceId, PointId, Value};
use crate::time::Timestamp;

use super::fault::CommitFaults;
use super::inbox::Inbox;
use super::open::open_writer;
use super::rollup::{OpenMinutes, Staged, bucket_value};
use super::*;

/// The first automatic prune waits this long after start, so a start after a long
/// stop (with much to delete) is not slowed by it.
const FIRST_PRUNE_AFTER: Duration = Duration::from_secs(60);

/// Commands taken from the channel before the writer looks at its batch and its prune;
/// also the most samples the inbox holds before it wakes the writer.
pub(super) const DRAIN_MAX: usize = 10_000;

/// Rounds of taking the inbox before the writer looks at its channel again, when samples
/// keep arriving (see `Writer::take_inbox`).
const TAKE_ROUNDS: usize = 4;

/// Pages returned to the file system per `incremental_vacuum` step (4 MB of 4 KiB pages).
const VACUUM_PAGES: u32 = 1024;

/// Prepared statements the writer keeps (rusqlite's default is 16).
const STATEMENT_CACHE: usize = 32;

/// A row waiting for its commit.
pub(super) enum Row {
    Sample(Sample),
    Event(Event),
    Audit(AuditEntry),
}

/// The writer thread's body: opens the file, then writes until shut down. If the file
/// cannot be opened, the history is off: rows are counted and discarded.
pub(super) fn run_writer(
    dir: &Path,
    options: StoreOptions,
    stats: Arc<StoreStats>,
    shared: Arc<Shared>,
    inbox: Arc<Inbox>,
    rx: mpsc::Receiver<Command>,
    opened: mpsc::Sender<Result<(), StoreError>>,
) {
    // However the writer ends (even by a panic), later samples are refused and counted.
    let _closing = CloseInbox {
        inbox: Arc::clone(&inbox),
        stats: Arc::clone(&stats),
    };
    let opened_with_rollups = open_writer(dir).and_then(|open| {
        open.conn
            .set_prepared_statement_cache_capacity(STATEMENT_CACHE);
        let rollups = OpenMinutes::load(&open.conn).map_err(|source| StoreError::Sqlite {
            path: dir.join(DB_FILE),
            source,
        })?;
        Ok((open, rollups))
    });
    match opened_with_rollups {
        Ok((open, rollups)) => {
            let mut writer = Writer {
                conn: open.conn,
                rollups,
                path: dir.join(DB_FILE),
                points: HashMap::new(),
                options,
                stats,
                shared,
                pending: VecDeque::new(),
                oldest: None,
                last_prune: None,
                faults: CommitFaults::default(),
                prunes: VecDeque::new(),
                inbox,
                incoming: Vec::new(),
                cache: WriterCache::new(),
            };
            if let Some((aside, fault)) = open.moved_aside {
                writer.push(Row::Event(Event::of_gateway(
                    EventKind::HistoryReset,
                    format!(
                        "the history file was damaged ({fault}); it was moved aside as {} and \
                         a new history started",
                        aside.display()
                    ),
                )));
            }
            writer.shared.set_open(Ok(()));
            let _ = opened.send(Ok(()));
            writer.run(&rx);
        }
        Err(e) => {
            let reason = e.to_string();
            tracing::error!(
                "history is off: {reason}; values are served live but not stored; \
                 fix the data directory and restart"
            );
            let left = inbox.close();
            stats.rows_dropped.fetch_add(left as u64, Ordering::Relaxed);
            shared.set_open(Err(reason.clone()));
            let _ = opened.send(Err(e));
            discard(&rx, &stats, &reason);
        }
    }
}

/// Closes the inbox when the writer thread ends; what was left in it is counted dropped.
struct CloseInbox {
    inbox: Arc<Inbox>,
    stats: Arc<StoreStats>,
}

impl Drop for CloseInbox {
    fn drop(&mut self) {
        let left = self.inbox.close();
        self.stats
            .rows_dropped
            .fetch_add(left as u64, Ordering::Relaxed);
    }
}

/// The history is off: rows are counted and dropped, flushes and prunes say why.
fn discard(rx: &mpsc::Receiver<Command>, stats: &StoreStats, reason: &str) {
    let off = || Err(format!("history is off: {reason}"));
    for command in rx {
        match command {
            // The inbox was closed: its samples are counted as they come.
            Command::Wake => {}
            Command::Event(_) | Command::Audit(..) => {
                stats.rows_dropped.fetch_add(1, Ordering::Relaxed);
            }
            Command::Flush(reply) | Command::Prune(_, reply) => {
                let _ = reply.send(off());
            }
            #[cfg(test)]
            Command::FillDisk(_) => {}
            Command::Shutdown => return,
        }
    }
}

struct Writer {
    conn: Connection,
    /// The per-minute rollups' marks and open minutes.
    rollups: OpenMinutes,
    path: PathBuf,
    /// Point ids known to be committed (a cache; `point_id` asks the table otherwise).
    points: HashMap<PointId, i64>,
    options: StoreOptions,
    stats: Arc<StoreStats>,
    shared: Arc<Shared>,
    pending: VecDeque<Row>,
    oldest: Option<Instant>,
    last_prune: Option<Instant>,
    faults: CommitFaults,
    prunes: VecDeque<PruneJob>,
    /// Samples the pollers queued (see `inbox`).
    inbox: Arc<Inbox>,
    /// The inbox's samples being pushed; empty between two takes.
    incoming: Vec<Sample>,
    /// The page cache's size, following the batches'.
    cache: WriterCache,
}

impl Writer {
    fn run(mut self, rx: &mpsc::Receiver<Command>) {
        let now = Instant::now();
        self.last_prune = Some(
            now.checked_sub(self.options.prune_every.saturating_sub(FIRST_PRUNE_AFTER))
                .unwrap_or(now),
        );
        loop {
            // What came while the writer worked; with nothing, it sleeps, and is woken by
            // the next sample only if no batch is open (an open batch is committed at its
            // time and takes what came meanwhile).
            let armed = self.take_inbox(true);
            let wait = if self.prunes.is_empty() && armed {
                self.wake_in(Instant::now())
            } else {
                Duration::ZERO
            };
            let mut received = Some(rx.recv_timeout(wait));
            let mut handled = 0;
            while let Some(next) = received.take() {
                match next {
                    Ok(command) => {
                        if self.handle(command).is_break() {
                            return;
                        }
                    }
                    Err(mpsc::RecvTimeoutError::Timeout) => break,
                    Err(mpsc::RecvTimeoutError::Disconnected) => {
                        self.shut_down();
                        return;
                    }
                }
                handled += 1;
                if handled < DRAIN_MAX {
                    received = match rx.try_recv() {
                        Ok(command) => Some(Ok(command)),
                        Err(mpsc::TryRecvError::Empty) => None,
                        Err(mpsc::TryRecvError::Disconnected) => {
                            Some(Err(mpsc::RecvTimeoutError::Disconnected))
                        }
                    };
                }
            }
            self.take_inbox(false);
            let now = Instant::now();
            self.commit_if_due(now);
            if self.prunes.is_empty() {
                self.prune_if_due(now);
            } else {
                self.prune_step();
            }
        }
    }

    /// How long to sleep: until the batch is due (or its retry), or the next prune.
    fn wake_in(&self, now: Instant) -> Duration {
        let prune = self
            .last_prune
            .map_or(now, |last| last + self.options.prune_every)
            .min(now + Duration::from_secs(60));
        let commit = self.oldest.map(|oldest| {
            let due = oldest + self.options.batch_delay;
            self.faults.retry_at().map_or(due, |retry| retry.max(due))
        });
        commit
            .map_or(prune, |c| c.min(prune))
            .saturating_duration_since(now)
    }

    /// Pushes the samples waiting in the inbox. With `arm` (the writer is about to sleep),
    /// takes until the inbox is found empty and then arms it: the next sample wakes the
    /// writer when no batch is open. Returns whether it armed: samples arriving faster
    /// than it takes them stop it after a few rounds, so commands (an audit row, a flush)
    /// are never starved; the writer then looks at its channel without sleeping.
    fn take_inbox(&mut self, arm: bool) -> bool {
        for _ in 0..TAKE_ROUNDS {
            let idle = self.oldest.is_none();
            self.inbox.take(&mut self.incoming, arm.then_some(idle));
            if self.incoming.is_empty() {
                return arm;
            }
            let mut incoming = std::mem::take(&mut self.incoming);
            for sample in incoming.drain(..) {
                self.push(Row::Sample(sample));
            }
            self.incoming = incoming;
            if !arm {
                return false;
            }
        }
        false
    }

    fn handle(&mut self, command: Command) -> ControlFlow<()> {
        // Samples queued before these commands come before them (some queued after may
        // too, which does no harm to a commit).
        if matches!(
            command,
            Command::Flush(_) | Command::Prune(..) | Command::Shutdown
        ) {
            self.take_inbox(false);
        }
        match command {
            Command::Wake => {}
            Command::Event(event) => self.push(Row::Event(event)),
            Command::Audit(entry, mark) => {
                let mut incoming = std::mem::take(&mut self.incoming);
                self.inbox.take_until(&mut incoming, mark);
                for sample in incoming.drain(..) {
                    self.push(Row::Sample(sample));
                }
                self.incoming = incoming;
                self.push(Row::Audit(entry));
                if self.faults.may_commit(Instant::now()) {
                    let _ = self.commit();
                }
            }
            Command::Flush(reply) => {
                let result = self.flush();
                let _ = reply.send(result);
            }
            Command::Prune(now, reply) => {
                self.prunes
                    .push_back(PruneJob::new(&self.conn, now, &self.options, Some(reply)))
            }
            #[cfg(test)]
            Command::FillDisk(full) => {
                // Lowering it below the file's size caps the file at its size.
                let pages = if full { 1 } else { 4_294_967_294u64 };
                if let Err(e) =
                    self.conn
                        .query_row(&format!("PRAGMA max_page_count = {pages}"), [], |r| {
                            r.get::<_, i64>(0)
                        })
                {
                    tracing::error!("max_page_count: {e}");
                }
            }
            Command::Shutdown => {
                self.shut_down();
                return ControlFlow::Break(());
            }
        }
        ControlFlow::Continue(())
    }

    /// Commits what is pending, unless a failure's wait is not over: then its error.
    fn flush(&mut self) -> Result<u64, String> {
        let now = Instant::now();
        if !self.faults.may_commit(now)
            && let Some(waiting) = self.faults.waiting(now)
        {
            return Err(waiting);
        }
        self.commit().map(|()| self.stats.rows_written())
    }

    fn shut_down(&mut self) {
        if let Err(e) = self.commit() {
            tracing::error!(
                "history {}: {} rows could not be committed at shutdown: {e}",
                self.path.display(),
                self.pending.len()
            );
        }
        for job in self.prunes.drain(..) {
            if let Some(reply) = job.reply {
                let _ = reply.send(Err("the history writer stopped during the prune".into()));
            }
        }
    }

    fn push(&mut self, row: Row) {
        if self.pending.len() >= MAX_PENDING_ROWS && !self.make_room(&row) {
            return;
        }
        self.pending.push_back(row);
        self.stats
            .pending_rows
            .store(self.pending.len() as u64, Ordering::Relaxed);
        self.oldest.get_or_insert_with(Instant::now);
        if self.pending.len() >= self.options.batch_rows && self.faults.may_commit(Instant::now()) {
            let _ = self.commit();
        }
    }

    /// The pending rows are at their cap: drops the oldest sample, else (for an event) the
    /// oldest event; audit rows are never dropped. Returns whether `incoming` is kept.
    fn make_room(&mut self, incoming: &Row) -> bool {
        let oldest = |pending: &VecDeque<Row>, event: bool| {
            pending.iter().position(|r| match r {
                Row::Sample(_) => !event,
                Row::Event(_) => event,
                Row::Audit(_) => false,
            })
        };
        let victim = match incoming {
            // A sample makes room only by dropping an older sample, or itself.
            Row::Sample(_) => oldest(&self.pending, false),
            Row::Event(_) | Row::Audit(_) => {
                oldest(&self.pending, false).or_else(|| oldest(&self.pending, true))
            }
        };
        let keep = match victim {
            Some(i) => {
                self.pending.remove(i);
                true
            }
            // Nothing older may go: an audit row is kept anyway, the rest is dropped.
            None => matches!(incoming, Row::Audit(_)),
        };
        if victim.is_some() || !keep {
            self.stats.rows_dropped.fetch_add(1, Ordering::Relaxed);
        }
        keep
    }

    fn commit_if_due(&mut self, now: Instant) {
        let due = self.oldest.is_some_and(|oldest| {
            now >= oldest + self.options.batch_delay
                || self.pending.len() >= self.options.batch_rows
        });
        if due && self.faults.may_commit(now) {
            let _ = self.commit();
        }
    }

    /// Commits the pending rows in one transaction. On failure they stay pending and the
    /// next try waits (see [`CommitFaults`]).
    fn commit(&mut self) -> Result<(), String> {
        if self.pending.is_empty() {
            return Ok(());
        }
        let cache_before = self.cache.kib();
        if let Some(kib) = self.cache.for_batch(self.pending.len()) {
            // A cache that could not be resized only costs speed or memory: go on.
            if let Err(e) = self.conn.pragma_update(None, "cache_size", -kib) {
                tracing::warn!(
                    "history {}: the page cache stays at {} KiB, resizing it to {kib} KiB failed: {e}",
                    self.path.display(),
                    cache_before
                );
            }
        }
        let mut rows = std::mem::take(&mut self.pending);
        let result = write_rows(
            &mut self.conn,
            &mut self.points,
            &mut self.rollups,
            rows.make_contiguous(),
        );
        let now = Instant::now();
        match result {
            Ok(counts) => {
                self.oldest = None;
                self.stats.pending_rows.store(0, Ordering::Relaxed);
                self.count(counts);
                if let Some(recovery) = self.faults.succeeded(now) {
                    self.shared.recovered();
                    let message = format!(
                        "history commits work again after {} failed over {:.1} s (last error: {})",
                        recovery.failures,
                        recovery.lasted.as_secs_f64(),
                        recovery.last_error
                    );
                    tracing::warn!("history {}: {message}", self.path.display());
                    let event = [Row::Event(Event::of_gateway(
                        EventKind::HistoryRecovered,
                        message,
                    ))];
                    match write_rows(&mut self.conn, &mut self.points, &mut self.rollups, &event) {
                        Ok(counts) => self.count(counts),
                        Err(_) => self.pending.extend(event),
                    }
                }
                Ok(())
            }
            Err(e) => {
                let error = e.to_string();
                self.stats.commit_errors.fetch_add(1, Ordering::Relaxed);
                self.shared.fault(Timestamp::now(), &error);
                // Ids handed out inside the failed transaction are gone with it.
                self.points.clear();
                self.pending = rows;
                let failure = self.faults.failed(now, &error);
                if let Some(line) = failure.log {
                    tracing::error!(
                        "history {}: {line}; {} rows pending",
                        self.path.display(),
                        self.pending.len()
                    );
                }
                if failure.first {
                    self.push(Row::Event(Event::of_gateway(
                        EventKind::HistoryFailed,
                        format!(
                            "history commits fail: {error}; rows are kept (at most \
                             {MAX_PENDING_ROWS}, oldest samples dropped first) and retried"
                        ),
                    )));
                }
                Err(error)
            }
        }
    }

    fn count(&self, counts: [u64; 3]) {
        let s = &self.stats;
        s.samples_written.fetch_add(counts[0], Ordering::Relaxed);
        s.events_written.fetch_add(counts[1], Ordering::Relaxed);
        s.audit_written.fetch_add(counts[2], Ordering::Relaxed);
        s.commits.fetch_add(1, Ordering::Relaxed);
    }

    fn prune_if_due(&mut self, now: Instant) {
        let due = self
            .last_prune
            .is_none_or(|last| now.saturating_duration_since(last) >= self.options.prune_every);
        // While commits fail, deletes would too; the prune waits for the disk.
        if due && self.faults.retry_at().is_none() {
            self.last_prune = Some(now);
            let job = PruneJob::new(&self.conn, Timestamp::now(), &self.options, None);
            self.prunes.push_back(job);
        }
    }

    /// One chunk of the first prune job; answers it when done or failed.
    fn prune_step(&mut self) {
        let Some(job) = self.prunes.front_mut() else {
            return;
        };
        let chunk = self.options.prune_chunk_rows.max(1);
        match job.step(&self.conn, &mut self.rollups, chunk) {
            Ok(n) => {
                self.stats.rows_pruned.fetch_add(n, Ordering::Relaxed);
                if !job.done() {
                    return;
                }
            }
            Err(e) => {
                tracing::error!("history {}: retention failed: {e}", self.path.display());
                job.failed = Some(e.to_string());
            }
        }
        if let Some(job) = self.prunes.pop_front() {
            if job.deleted > 0 {
                tracing::info!(
                    "history {}: retention deleted {} rows in {:.1} s",
                    self.path.display(),
                    job.deleted,
                    job.started.elapsed().as_secs_f64()
                );
            }
            if let Some(reply) = job.reply {
                let _ = reply.send(match job.failed {
                    Some(e) => Err(e),
                    None => Ok(job.deleted),
                });
            }
        }
    }
}

/// A retention run, done one chunk per writer turn.
struct PruneJob {
    cutoff: i64,
    audit_cutoff: i64,
    /// Point ids left to prune.
    points: Vec<i64>,
    /// Point ids whose rollups are left to prune.
    rollup_points: Vec<i64>,
    stage: Stage,
    deleted: u64,
    started: Instant,
    failed: Option<String>,
    reply: Option<tokio::sync::oneshot::Sender<Result<u64, String>>>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stage {
    /// Rollups stop covering what goes (committed before anything is deleted).
    Marks,
    Samples,
    Minutes,
    Events,
    Audit,
    Vacuum,
    Checkpoint,
    Done,
}

impl PruneJob {
    fn new(
        conn: &Connection,
        now: Timestamp,
        options: &StoreOptions,
        reply: Option<tokio::sync::oneshot::Sender<Result<u64, String>>>,
    ) -> Self {
        // Every point in the table, committed or not yet cached.
        let points: Vec<i64> = conn
            .prepare("SELECT id FROM points ORDER BY id DESC")
            .and_then(|mut stmt| stmt.query_map([], |r| r.get(0))?.collect())
            .unwrap_or_default();
        Self {
            cutoff: now.minus(options.retain).0,
            audit_cutoff: now.minus(options.audit_retention()).0,
            rollup_points: points.clone(),
            points,
            stage: Stage::Marks,
            deleted: 0,
            started: Instant::now(),
            failed: None,
            reply,
        }
    }

    fn done(&self) -> bool {
        self.stage == Stage::Done
    }

    /// Deletes at most `chunk` rows (or returns a chunk of pages); returns the rows deleted.
    fn step(
        &mut self,
        conn: &Connection,
        rollups: &mut OpenMinutes,
        chunk: usize,
    ) -> rusqlite::Result<u64> {
        let limit = i64::try_from(chunk).unwrap_or(i64::MAX);
        let n = match self.stage {
            Stage::Marks => {
                rollups.raise_since(conn, self.cutoff)?;
                self.stage = Stage::Samples;
                0
            }
            Stage::Samples => match self.points.last().copied() {
                Some(point) => {
                    let n = conn
                        .prepare_cached(
                            "DELETE FROM samples WHERE rowid IN (SELECT rowid FROM samples \
                             WHERE point = ?1 AND t < ?2 LIMIT ?3)",
                        )?
                        .execute(params![point, self.cutoff, limit])?;
                    if n < chunk {
                        self.points.pop();
                    }
                    n
                }
                None => {
                    self.stage = Stage::Minutes;
                    0
                }
            },
            Stage::Minutes => {
                // Rollups below `since` are never read again; not counted as rows pruned.
                if let Some(point) = self.rollup_points.last().copied() {
                    let n = conn
                        .prepare_cached(
                            "DELETE FROM minutes WHERE (point, minute) IN (SELECT point, minute \
                             FROM minutes WHERE point = ?1 AND minute < ?2 LIMIT ?3)",
                        )?
                        .execute(params![point, rollups.marks().since, limit])?;
                    if n < chunk {
                        self.rollup_points.pop();
                    }
                } else {
                    self.stage = Stage::Events;
                }
                0
            }
            Stage::Events => {
                let n = delete_before(conn, "events", self.cutoff, limit)?;
                if n < chunk {
                    self.stage = Stage::Audit;
                }
                n
            }
            Stage::Audit => {
                let n = delete_before(conn, "audit", self.audit_cutoff, limit)?;
                if n < chunk {
                    self.stage = if self.deleted + n as u64 > 0 {
                        Stage::Vacuum
                    } else {
                        Stage::Done
                    };
                }
                n
            }
            Stage::Vacuum => {
                // Steps the pragma to its end: each step frees pages.
                let mut stmt =
                    conn.prepare(&format!("PRAGMA incremental_vacuum({VACUUM_PAGES})"))?;
                let mut rows = stmt.query([])?;
                while rows.next()?.is_some() {}
                let free: i64 = conn.query_row("PRAGMA freelist_count", [], |r| r.get(0))?;
                let auto: i64 = conn.query_row("PRAGMA auto_vacuum", [], |r| r.get(0))?;
                // auto_vacuum 2 is INCREMENTAL; an older file (NONE) keeps its free pages.
                if free == 0 || auto != 2 {
                    self.stage = Stage::Checkpoint;
                }
                0
            }
            Stage::Checkpoint => {
                let busy: Option<i64> = conn
                    .query_row("PRAGMA wal_checkpoint(TRUNCATE)", [], |r| r.get(0))
                    .optional()?;
                if busy == Some(1) {
                    tracing::debug!("history checkpoint after the prune: readers kept the WAL");
                }
                self.stage = Stage::Done;
                0
            }
            Stage::Done => 0,
        };
        let n = n as u64;
        self.deleted += n;
        Ok(n)
    }
}

/// Deletes up to `limit` rows of `table` (`events` or `audit`, both keyed by `id`) older
/// than `cutoff`; returns how many went.
fn delete_before(
    conn: &Connection,
    table: &str,
    cutoff: i64,
    limit: i64,
) -> rusqlite::Result<usize> {
    conn.prepare_cached(&format!(
        "DELETE FROM {table} WHERE id IN (SELECT id FROM {table} WHERE t < ?1 LIMIT ?2)"
    ))?
    .execute(params![cutoff, limit])
}

/// Writes rows in one transaction, with the rollups they change; returns how many
/// samples, events and audit rows. The rollups' state changes only if the commit works.
fn write_rows(
    conn: &mut Connection,
    points: &mut HashMap<PointId, i64>,
    rollups: &mut OpenMinutes,
    rows: &[Row],
) -> rusqlite::Result<[u64; 3]> {
    // IMMEDIATE: the write lock is taken at the start, waiting (busy_timeout) for another
    // connection's write (a setting, the production keeper's mark of life). A deferred
    // transaction that read first and found the file written meanwhile got
    // SQLITE_BUSY at once, without waiting: "database is locked" (seen once in the MQTT
    // tests, failing the flush at shutdown).
    let tx = conn.transaction_with_behavior(rusqlite::TransactionBehavior::Immediate)?;
    let mut counts = [0u64; 3];
    let mut staged = Staged::default();
    let mut samples: Vec<(i64, &Sample)> = Vec::new();
    for row in rows {
        match row {
            Row::Sample(s) => {
                let id = point_id(&tx, points, &s.point)?;
                staged.sample(
                    rollups,
                    id,
                    s.t.0,
                    bucket_value(s.value.as_ref(), s.quality),
                );
                samples.push((id, s));
                counts[0] += 1;
            }
            Row::Event(e) => {
                tx.prepare_cached(
                    "INSERT INTO events (t, kind, line, device, point, message, fields) \
                     VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
                )?
                .execute(params![
                    e.t.0,
                    e.kind.as_str(),
                    e.line,
                    e.device.as_ref().map(DeviceId::as_str),
                    e.point.as_ref().map(PointId::as_str),
                    e.message,
                    (!e.fields.is_empty())
                        .then(|| serde_json::to_string(&e.fields).unwrap_or_default()),
                ])?;
                // An alarm journal entry also keeps the alarm's state after it, read back
                // after a restart (`alarm::keeper`), in the same commit.
                if let (Some(id), true) = (
                    e.fields.get("alarm").and_then(|a| a.as_str()),
                    e.fields.contains_key("state"),
                ) {
                    tx.prepare_cached(
                        "INSERT INTO alarm_states (id, t, fields) VALUES (?1, ?2, ?3) \
                         ON CONFLICT(id) DO UPDATE SET t = excluded.t, fields = excluded.fields",
                    )?
                    .execute(params![
                        id,
                        e.t.0,
                        serde_json::to_string(&e.fields).unwrap_or_default()
                    ])?;
                }
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
    // Point by point, each point's samples in the order they came (a stable sort): the
    // index on (point, t) is then written leaf after leaf instead of at a thousand places
    // in turn (DESIGN.md, "store").
    samples.sort_by_key(|&(id, _)| id);
    insert_samples(&tx, &samples)?;
    rollups.write(&tx, &mut staged, Timestamp::now().0)?;
    tx.commit()?;
    rollups.committed(staged);
    Ok(counts)
}

/// Samples a multi-row insert takes at once.
pub(super) const INSERT_ROWS: usize = 64;

/// `INSERT OR FAIL INTO samples … VALUES` with [`INSERT_ROWS`] rows of five parameters.
static INSERT_MANY: LazyLock<String> = LazyLock::new(|| {
    format!(
        "INSERT OR FAIL INTO samples (point, t, value, text, quality) VALUES {}",
        vec!["(?,?,?,?,?)"; INSERT_ROWS].join(",")
    )
});

/// Inserts samples (with their point ids) in order: [`INSERT_ROWS`] a statement, the rest
/// one a statement, each through a prepared statement.
///
/// A multi-row insert is cheaper per row only because nothing in it can abort halfway: the
/// writer's connection does not check foreign keys ([`schema::configure_writer`]) and the
/// statement says `OR FAIL` (a NOT NULL failure keeps the rows before it, and the whole
/// transaction is rolled back anyway). Otherwise SQLite keeps a statement journal of every
/// page such a statement touches, which cost 40–70 % more CPU per row than single-row
/// inserts. Without it, 64 rows a statement and no foreign-key check cost 25–35 % less CPU
/// a row than single rows with the check (`store_ingest`; 16 or 256 rows: the same within
/// the spread; DESIGN.md has the figures).
fn insert_samples(tx: &Transaction<'_>, samples: &[(i64, &Sample)]) -> rusqlite::Result<()> {
    let mut chunks = samples.chunks_exact(INSERT_ROWS);
    let mut many = tx.prepare_cached(&INSERT_MANY)?;
    for chunk in &mut chunks {
        for (row, (id, s)) in chunk.iter().enumerate() {
            bind_sample(&mut many, row * 5 + 1, *id, s)?;
        }
        many.raw_execute()?;
    }
    let mut one = tx.prepare_cached(
        "INSERT INTO samples (point, t, value, text, quality) VALUES (?1, ?2, ?3, ?4, ?5)",
    )?;
    for (id, s) in chunks.remainder() {
        bind_sample(&mut one, 1, *id, s)?;
        one.raw_execute()?;
    }
    Ok(())
}

/// Binds a sample's five columns (point, t, value, text, quality) from parameter `first` on.
fn bind_sample(
    stmt: &mut rusqlite::Statement<'_>,
    first: usize,
    id: i64,
    s: &Sample,
) -> rusqlite::Result<()> {
    let (number, text) = match &s.value {
        Some(Value::Number(n)) => (Some(*n), None),
        Some(Value::Text(t)) => (None, Some(t.as_str())),
        None => (None, None),
    };
    stmt.raw_bind_parameter(first, id)?;
    stmt.raw_bind_parameter(first + 1, s.t.0)?;
    stmt.raw_bind_parameter(first + 2, number)?;
    stmt.raw_bind_parameter(first + 3, text)?;
    stmt.raw_bind_parameter(first + 4, s.quality.code())
}

/// The id of `point`: cached (sharing the id's text), else from the table, else a new row.
fn point_id(
    tx: &Transaction<'_>,
    points: &mut HashMap<PointId, i64>,
    point: &PointId,
) -> rusqlite::Result<i64> {
    let name = point.as_str();
    if let Some(id) = points.get(name) {
        return Ok(*id);
    }
    let known: Option<i64> = tx
        .prepare_cached("SELECT id FROM points WHERE name = ?1")?
        .query_row([name], |r| r.get(0))
        .optional()?;
    let id = match known {
        Some(id) => id,
        None => {
            tx.prepare_cached("INSERT INTO points (name) VALUES (?1)")?
                .execute([name])?;
            tx.last_insert_rowid()
        }
    };
    points.insert(point.clone(), id);
    Ok(id)
}
