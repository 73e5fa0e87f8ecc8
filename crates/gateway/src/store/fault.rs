//! Failed commits: when to try again and what to log. Sans-IO: time comes in as `now`, so
//! the tests run an hour of failures in microseconds.

use std::time::{Duration, Instant};

use wire::backoff::{Backoff, BackoffTimer};

use super::{COMMIT_RETRY_CAP, COMMIT_RETRY_FIRST};

/// The writer's record of failing commits.
#[derive(Debug)]
pub(super) struct CommitFaults {
    backoff: BackoffTimer,
    failing: Option<Failing>,
}

#[derive(Debug)]
struct Failing {
    /// The first failure of this run.
    since: Instant,
    /// Failures in this run.
    failures: u64,
    /// Failures since the last log line.
    unlogged: u64,
    /// When the last log line was written.
    logged_at: Instant,
    /// No commit before this.
    retry_at: Instant,
    last_error: String,
}

/// What to do about one failed commit.
#[derive(Debug, PartialEq, Eq)]
pub(super) struct Failure {
    /// The first of a run: record a `history_failed` event.
    pub(super) first: bool,
    /// A line to log, at most one per wait.
    pub(super) log: Option<String>,
}

/// A run of failures that a commit ended.
#[derive(Debug, PartialEq, Eq)]
pub(super) struct Recovery {
    /// Failed commits in the run.
    pub(super) failures: u64,
    /// From the first failure to the commit that worked.
    pub(super) lasted: Duration,
    /// What the last failure said.
    pub(super) last_error: String,
}

impl Default for CommitFaults {
    fn default() -> Self {
        Self {
            backoff: Backoff::new(COMMIT_RETRY_FIRST, COMMIT_RETRY_CAP).timer(),
            failing: None,
        }
    }
}

impl CommitFaults {
    /// When the next commit may be tried; `None` when commits work.
    pub(super) fn retry_at(&self) -> Option<Instant> {
        self.failing.as_ref().map(|f| f.retry_at)
    }

    /// Whether a commit may be tried at `now` (always, unless waiting out a failure).
    pub(super) fn may_commit(&self, now: Instant) -> bool {
        self.retry_at().is_none_or(|at| now >= at)
    }

    /// The error of the current run of failures, with the wait left, for a flush to answer.
    pub(super) fn waiting(&self, now: Instant) -> Option<String> {
        let f = self.failing.as_ref()?;
        Some(format!(
            "{} (failed {} times; next try in {:.1} s)",
            f.last_error,
            f.failures,
            f.retry_at.saturating_duration_since(now).as_secs_f64()
        ))
    }

    /// A commit failed at `now`.
    pub(super) fn failed(&mut self, now: Instant, error: &str) -> Failure {
        let wait = self.backoff.next_wait();
        match &mut self.failing {
            None => {
                self.failing = Some(Failing {
                    since: now,
                    failures: 1,
                    unlogged: 0,
                    logged_at: now,
                    retry_at: now + wait,
                    last_error: error.to_owned(),
                });
                Failure {
                    first: true,
                    log: Some(format!(
                        "commit failed: {error}; rows are kept and retried, first in {:.1} s",
                        wait.as_secs_f64()
                    )),
                }
            }
            Some(f) => {
                f.failures += 1;
                f.unlogged += 1;
                f.retry_at = now + wait;
                f.last_error = error.to_owned();
                // At most one line per wait, however the commits were triggered.
                let log = (now.saturating_duration_since(f.logged_at) >= wait / 2).then(|| {
                    let line = format!(
                        "{} commits failed in the last {:.1} s ({} since {:.0} s ago): {error}; \
                         next try in {:.1} s",
                        f.unlogged,
                        now.saturating_duration_since(f.logged_at).as_secs_f64(),
                        f.failures,
                        now.saturating_duration_since(f.since).as_secs_f64(),
                        wait.as_secs_f64()
                    );
                    f.unlogged = 0;
                    f.logged_at = now;
                    line
                });
                Failure { first: false, log }
            }
        }
    }

    /// A commit worked at `now`; ends a run of failures if there was one.
    pub(super) fn succeeded(&mut self, now: Instant) -> Option<Recovery> {
        self.backoff.reset();
        self.failing.take().map(|f| Recovery {
            failures: f.failures,
            lasted: now.saturating_duration_since(f.since),
            last_error: f.last_error,
        })
    }
}
