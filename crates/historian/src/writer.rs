//! The writer task: the only writer of the historian's PostgreSQL connection.
//!
//! Rows arrive from the MQTT task on a bounded channel, one small [`Batch`] per message.
//! The writer gathers them and commits a batch [`COMMIT_EVERY`] after its first row or at
//! [`BATCH_SAMPLES`] samples, whichever comes first. While a commit runs the writer keeps
//! taking rows into the next batch, so receiving never waits for PostgreSQL (the channel
//! only fills when the writer task itself gets no CPU).
//!
//! A batch is written over two connections at once, split by point
//! ([`Batch::split_by_point`]: the halves never touch the same point rows), each half in a
//! transaction of its own: PostgreSQL's commit work then runs on two backends. A half that
//! fails is retried with its twin; a retried half that was already committed is stored
//! once (the store's dedupe).
//!
//! A commit that takes longer than [`Limits::slow_commit`] counts as failing while it
//! lasts (a lock held on `samples`, a disk that stalls): the historian goes offline, so the
//! edge nodes store from then on, and the rows it holds uncommitted stay within what they
//! send again when it is back (they rewind by twice their keep-alive, 20 s at the least).
//! Without that, a commit that never ends would keep the historian online, taking rows it
//! cannot store, until a restart lost them.
//!
//! A failed commit keeps its batch and tries it again (on a new connection when the old
//! one is gone), waiting [`RETRY_FIRST`] doubling to [`RETRY_CAP`]; the store takes a batch
//! twice without storing a row twice. Meanwhile the state turns [`DbState::Failing`], which
//! the MQTT task answers by going offline (STATE), so the edge nodes store and forward; the
//! first commit that succeeds turns it [`DbState::Ok`] again.
//!
//! Memory is bounded: past [`Limits::max_pending`] samples waiting, new rows are dropped
//! (counted) and the state turns failing, so the historian goes offline at once; the edge
//! nodes then move their forwarded mark back by twice their keep-alive and send what was
//! dropped again once the historian is back online.

use std::future::Future;
use std::sync::Arc;
use std::time::{Duration, SystemTime};

use tokio::sync::{mpsc, watch};
use tokio::time::Instant;
use wire::backoff::{Backoff, BackoffTimer};

use crate::metrics::{Health, Metrics};
use crate::store::{Batch, Store, StoreError, Written};

/// How long rows wait for their commit at most (when fewer than [`BATCH_SAMPLES`] come).
pub const COMMIT_EVERY: Duration = Duration::from_millis(100);
/// Samples that make a batch commit at once.
pub const BATCH_SAMPLES: usize = 10_000;
/// First wait after a failed commit or connection; doubles up to [`RETRY_CAP`].
pub const RETRY_FIRST: Duration = Duration::from_millis(200);
/// Longest wait between two tries.
pub const RETRY_CAP: Duration = Duration::from_secs(5);

/// How old a row may be by default: 31 days.
pub const DEFAULT_MAX_AGE: Duration = Duration::from_secs(31 * 86_400);

/// Whether PostgreSQL takes the historian's commits.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DbState {
    /// The last commit (or connection) succeeded.
    Ok,
    /// It failed, or too many rows wait: why.
    Failing(String),
}

/// The writer's bounds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Most samples waiting for their commit (about 450 bytes each in memory: 500,000 is
    /// about 220 MiB).
    pub max_pending: usize,
    /// How long the last commits may take at shutdown before what remains is given up.
    pub stop_grace: Duration,
    /// A commit still running after this long turns the state failing (offline) until
    /// it ends. Less than the edge nodes' rewind (twice their keep-alive, at least 20 s).
    pub slow_commit: Duration,
    /// Samples and events older than this are refused (counted in the dropped rows): a
    /// clock gone wrong, or a rogue birth, would otherwise create a day partition for
    /// every day it names.
    pub max_age: Duration,
    /// Most point ids each PostgreSQL connection keeps in memory (the store's
    /// [`Store::set_point_cache`]); the historian gives its `--max-points`.
    pub point_cache: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_pending: 500_000,
            stop_grace: Duration::from_secs(10),
            slow_commit: Duration::from_secs(10),
            max_age: DEFAULT_MAX_AGE,
            point_cache: crate::store::DEFAULT_POINT_CACHE,
        }
    }
}

/// Rows taken from the channel while the writer waits for something else.
struct Inbox {
    rx: mpsc::Receiver<Batch>,
    /// The next batch.
    next: Batch,
    /// When the next batch's first row came.
    first_at: Option<Instant>,
    /// The channel is open (the MQTT task still runs).
    open: bool,
    limits: Limits,
    metrics: Arc<Metrics>,
    state: Arc<watch::Sender<DbState>>,
    /// Samples dropped since the bound was last reached.
    overflow: u64,
}

impl Inbox {
    fn take(&mut self, mut rows: Batch) {
        if self.next.samples.len() + rows.samples.len() > self.limits.max_pending {
            let dropped = rows.samples.len() + rows.events.len();
            if self.overflow == 0 {
                let why = format!(
                    "more than {} samples wait for PostgreSQL: new rows dropped, offline until \
                     it catches up",
                    self.limits.max_pending
                );
                tracing::warn!("historian: {why}");
                self.state.send_replace(DbState::Failing(why));
            }
            self.overflow += dropped as u64;
            self.metrics.dropped.inc_by(dropped as u64);
            // Point definitions are few and needed by later rows: keep them.
            self.next.points.append(&mut rows.points);
            return;
        }
        if self.first_at.is_none() {
            self.first_at = Some(Instant::now());
        }
        self.next.points.append(&mut rows.points);
        self.next.samples.append(&mut rows.samples);
        self.next.events.append(&mut rows.events);
    }

    /// Runs `work` while taking rows into the next batch.
    async fn while_doing<F: Future>(&mut self, work: F) -> F::Output {
        tokio::pin!(work);
        loop {
            tokio::select! {
                biased;
                out = &mut work => return out,
                rows = self.rx.recv(), if self.open => match rows {
                    Some(rows) => self.take(rows),
                    None => self.open = false,
                },
            }
        }
    }

    /// Waits for the first row of a batch, then until the batch is due; false when the
    /// channel closed with nothing left.
    async fn gather(&mut self) -> bool {
        while self.next.is_empty() {
            if !self.open {
                return false;
            }
            match self.rx.recv().await {
                Some(rows) => self.take(rows),
                None => self.open = false,
            }
        }
        let due = self.first_at.unwrap_or_else(Instant::now) + COMMIT_EVERY;
        while self.open && self.next.samples.len() < BATCH_SAMPLES {
            tokio::select! {
                rows = self.rx.recv() => match rows {
                    Some(rows) => self.take(rows),
                    None => self.open = false,
                },
                () = tokio::time::sleep_until(due) => break,
            }
        }
        true
    }

    fn take_batch(&mut self) -> Batch {
        self.first_at = None;
        std::mem::take(&mut self.next)
    }
}

/// The writer: commits what the MQTT task sends until the channel closes and everything
/// left is committed (or [`Limits::stop_grace`] passed since the close).
pub struct Writer {
    url: String,
    inbox: Inbox,
    state: Arc<watch::Sender<DbState>>,
    health: Arc<Health>,
    metrics: Arc<Metrics>,
    /// The two writing connections (none until connected, or after one was lost).
    stores: [Option<Store>; 2],
    retry: BackoffTimer,
}

impl Writer {
    /// A writer to the database at `url`, fed by `rx`, telling its state on `state`.
    pub fn new(
        url: String,
        rx: mpsc::Receiver<Batch>,
        state: watch::Sender<DbState>,
        health: Arc<Health>,
        metrics: Arc<Metrics>,
        limits: Limits,
    ) -> Self {
        let state = Arc::new(state);
        Self {
            url,
            inbox: Inbox {
                rx,
                next: Batch::default(),
                first_at: None,
                open: true,
                limits,
                metrics: Arc::clone(&metrics),
                state: Arc::clone(&state),
                overflow: 0,
            },
            state,
            health,
            metrics,
            stores: [None, None],
            retry: Backoff::new(RETRY_FIRST, RETRY_CAP).timer(),
        }
    }

    /// Connects (so the schema is made before the historian goes online), then commits
    /// until the channel closes.
    ///
    /// # Errors
    ///
    /// Only what no retry can fix: a bad URL, a refused login, a schema too new. The
    /// caller stops the historian with it.
    pub async fn run(mut self) -> Result<(), StoreError> {
        loop {
            match self.connect().await {
                Ok(()) => break,
                Err(e) if e.is_connection_lost() => self.failed(&e).await,
                Err(e) => return Err(e),
            }
            if !self.inbox.open {
                return Ok(());
            }
        }
        let mut closed_at: Option<Instant> = None;
        while self.inbox.gather().await {
            let batch = self.inbox.take_batch().split_by_point();
            self.set_pending(&batch);
            loop {
                if !self.inbox.open {
                    let closed = *closed_at.get_or_insert_with(Instant::now);
                    if closed.elapsed() > self.inbox.limits.stop_grace {
                        let lost = samples(&batch) + self.inbox.next.samples.len();
                        tracing::error!(
                            "historian stopping: PostgreSQL took no commit within {:?}; {lost} \
                             samples not stored (the edge nodes send them again when the \
                             historian is back)",
                            self.inbox.limits.stop_grace
                        );
                        return Ok(());
                    }
                }
                match self.commit(&batch).await {
                    Ok(()) => break,
                    Err(e) if e.is_retryable() => self.failed(&e).await,
                    Err(e) if e.is_connection_lost() => self.failed(&e).await,
                    Err(e) => {
                        // Bad data, or a refusal no retry changes: log and go on.
                        let rows = (batch[0].len() + batch[1].len()) as u64;
                        self.metrics.dropped.inc_by(rows);
                        tracing::error!("a batch of {rows} rows was not stored: {e}");
                        break;
                    }
                }
            }
            self.set_pending(&[Batch::default(), Batch::default()]);
        }
        Ok(())
    }

    fn set_pending(&self, committing: &[Batch; 2]) {
        let n = samples(committing) + self.inbox.next.samples.len();
        self.metrics
            .pending
            .set(i64::try_from(n).unwrap_or(i64::MAX));
    }

    async fn connect(&mut self) -> Result<(), StoreError> {
        for slot in 0..self.stores.len() {
            if self.stores[slot].as_ref().is_some_and(|s| !s.is_closed()) {
                continue;
            }
            self.stores[slot] = None;
            let mut store = self.inbox.while_doing(Store::connect(&self.url)).await?;
            store.set_max_age(Some(self.inbox.limits.max_age));
            store.set_point_cache(self.inbox.limits.point_cache);
            if !store.migrated().is_empty() {
                tracing::info!(
                    "historian: database schema migrated to {:?}",
                    store.migrated()
                );
            }
            self.stores[slot] = Some(store);
        }
        self.recovered();
        Ok(())
    }

    async fn commit(&mut self, batch: &[Batch; 2]) -> Result<(), StoreError> {
        self.connect().await?;
        let [Some(first), Some(second)] = &mut self.stores else {
            return Ok(()); // connect() leaves both stores or fails
        };
        let started = Instant::now();
        let (a, b) = {
            let halves =
                async { tokio::join!(write_half(first, &batch[0]), write_half(second, &batch[1])) };
            tokio::pin!(halves);
            let slow_commit = self.inbox.limits.slow_commit;
            match self
                .inbox
                .while_doing(tokio::time::timeout(slow_commit, &mut halves))
                .await
            {
                Ok(written) => written,
                Err(_) => {
                    let why = format!(
                        "a commit has taken more than {slow_commit:?} (a lock on the tables, \
                         a stalled disk?)"
                    );
                    mark_failing(
                        &self.state,
                        &self.health,
                        &self.metrics,
                        &why,
                        "waiting for it",
                    );
                    self.inbox.while_doing(&mut halves).await
                }
            }
        };
        for (slot, result) in [&a, &b].into_iter().enumerate() {
            if let Err(e) = result
                && e.is_connection_lost()
            {
                self.stores[slot] = None;
            }
        }
        let written = match (a, b) {
            (Ok(mut a), Ok(b)) => {
                a.add(b);
                a
            }
            // A lost connection, if either half has one: it decides the retry.
            (Err(a), Err(b)) if b.is_connection_lost() && !a.is_connection_lost() => {
                return Err(b);
            }
            (Err(e), _) | (_, Err(e)) => return Err(e),
        };
        self.metrics
            .commit_seconds
            .observe(started.elapsed().as_secs_f64());
        self.metrics.commits.inc();
        self.metrics.samples_committed.inc_by(written.samples);
        self.metrics.duplicates.inc_by(written.duplicate_samples);
        self.metrics.events_committed.inc_by(written.events);
        let refused = written.refused_samples + written.refused_events + written.refused_points;
        if refused > 0 {
            self.metrics.dropped.inc_by(refused);
            if let Some(first) = &written.first_refusal {
                tracing::warn!("{refused} rows refused by the store; the first: {first}");
            }
        }
        self.health.committed(SystemTime::now());
        self.recovered();
        Ok(())
    }

    /// A commit or connection worked: reset the wait, say so once.
    fn recovered(&mut self) {
        self.retry.reset();
        if self.inbox.overflow > 0 {
            if self.inbox.next.samples.len() > self.inbox.limits.max_pending / 2 {
                return; // still too full to take the edge nodes' data again
            }
            tracing::warn!(
                "historian: {} rows were dropped past the bound of {} pending samples; the \
                 edge nodes send them again",
                self.inbox.overflow,
                self.inbox.limits.max_pending
            );
            self.inbox.overflow = 0;
        }
        self.metrics.database_ok.set(1);
        self.health.set_database(None);
        self.state.send_if_modified(|s| {
            let changed = *s != DbState::Ok;
            if changed {
                tracing::info!("historian: PostgreSQL takes commits");
            }
            *s = DbState::Ok;
            changed
        });
    }

    /// A commit or connection failed: say so, then wait (taking rows meanwhile).
    async fn failed(&mut self, e: &StoreError) {
        self.metrics.commit_errors.inc();
        let wait = self.retry.next_wait();
        mark_failing(
            &self.state,
            &self.health,
            &self.metrics,
            &e.to_string(),
            &format!("retrying every {wait:?} or so"),
        );
        self.inbox.while_doing(tokio::time::sleep(wait)).await;
    }
}

/// The state turns failing (the historian goes offline) for `why`; logged once per reason
/// (the first failure at start too), with what the writer does meanwhile.
fn mark_failing(
    state: &watch::Sender<DbState>,
    health: &Health,
    metrics: &Metrics,
    why: &str,
    meanwhile: &str,
) {
    metrics.database_ok.set(0);
    health.set_database(Some(why.to_owned()));
    state.send_if_modified(|s| {
        let changed = !matches!(&*s, DbState::Failing(old) if old == why);
        if changed {
            tracing::warn!("historian: {why}; {meanwhile}, offline meanwhile");
        }
        *s = DbState::Failing(why.to_owned());
        changed
    });
}

/// Writes one half of a batch (nothing to do for an empty half).
async fn write_half(store: &mut Store, half: &Batch) -> Result<Written, StoreError> {
    if half.is_empty() {
        return Ok(Written::default());
    }
    store.write(half).await
}

/// Samples in both halves.
fn samples(batch: &[Batch; 2]) -> usize {
    batch[0].samples.len() + batch[1].samples.len()
}
