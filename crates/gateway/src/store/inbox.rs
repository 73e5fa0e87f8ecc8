//! Samples on their way to the writer thread.
//!
//! A poll's value changes used to travel one by one through the writer's channel, and each
//! woke the writer thread (a futex wake, two context switches) only for it to queue the row
//! and sleep again until its batch was due: with a thousand stations that was most of the
//! gateway's thread switches. Samples now wait in this inbox, and the writer is woken only
//! when it needs to be: for the first sample after it committed everything (it then sleeps
//! until that batch is due, and takes what came meanwhile), or when the inbox holds
//! `wake_at` samples (so a batch is still cut at its row count and a long retry wait holds
//! a bounded number of them here). Commands that must see every sample queued before them
//! (flush, audit, prune, shutdown) make the writer take the inbox first.

use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use super::{Sample, StoreStats};

/// What [`Inbox::put`] did with a sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Put {
    /// Queued; the writer takes it when it wakes.
    Queued,
    /// Queued, and the writer must be woken for it.
    Wake,
    /// The writer is gone (or the history is off): the sample was dropped.
    Closed,
}

/// Samples the writer has not taken yet.
#[derive(Debug)]
pub(super) struct Inbox {
    state: Mutex<State>,
    /// Where the number of queued samples is shown (`queued_rows`).
    stats: Arc<StoreStats>,
}

#[derive(Debug)]
struct State {
    samples: Vec<Sample>,
    /// Samples the writer has taken since the start: the number of the first queued one.
    taken: u64,
    /// The writer sleeps without an open batch: the next sample wakes it.
    wake: bool,
    /// The writer is woken when this many samples wait, whatever `wake` says.
    wake_at: usize,
    closed: bool,
}

impl Inbox {
    /// An empty inbox whose writer is woken by the first sample, and by the `wake_at`-th.
    pub(super) fn new(wake_at: usize, stats: Arc<StoreStats>) -> Self {
        Self {
            stats,
            state: Mutex::new(State {
                samples: Vec::new(),
                taken: 0,
                wake: true,
                wake_at: wake_at.max(1),
                closed: false,
            }),
        }
    }

    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Shows how many samples `state` holds (under its lock, so the gauge follows it).
    fn show(&self, state: &State) {
        self.stats
            .queued_rows
            .store(state.samples.len() as u64, Ordering::Relaxed);
    }

    /// Queues `sample`; says whether the writer must be woken.
    pub(super) fn put(&self, sample: Sample) -> Put {
        let mut state = self.lock();
        if state.closed {
            return Put::Closed;
        }
        state.samples.push(sample);
        self.show(&state);
        if state.wake || state.samples.len() == state.wake_at {
            state.wake = false;
            Put::Wake
        } else {
            Put::Queued
        }
    }

    /// How many samples were ever queued: a command sent after this call and carrying it
    /// is handled after exactly those samples ([`take_until`](Self::take_until)).
    pub(super) fn mark(&self) -> u64 {
        let state = self.lock();
        state.taken + state.samples.len() as u64
    }

    /// The writer takes the samples queued before `mark` (those it has not taken yet),
    /// oldest first, into `into`.
    pub(super) fn take_until(&self, into: &mut Vec<Sample>, mark: u64) {
        let mut state = self.lock();
        let before = usize::try_from(mark.saturating_sub(state.taken))
            .unwrap_or(usize::MAX)
            .min(state.samples.len());
        into.extend(state.samples.drain(..before));
        state.taken += before as u64;
        self.show(&state);
    }

    /// The writer takes every queued sample into `into` (which it keeps empty between
    /// calls, so the two buffers are swapped, not reallocated). With `arm` (the writer is
    /// about to sleep, `Some(idle)`: whether it has no open batch) and nothing queued, the
    /// next sample wakes it exactly when it is idle.
    pub(super) fn take(&self, into: &mut Vec<Sample>, arm: Option<bool>) {
        let mut state = self.lock();
        std::mem::swap(&mut state.samples, into);
        state.taken += into.len() as u64;
        self.show(&state);
        if into.is_empty()
            && let Some(idle) = arm
        {
            state.wake = idle;
        }
    }

    /// The writer stops: later samples are refused. Returns how many were still queued
    /// (never to be written).
    pub(super) fn close(&self) -> usize {
        let mut state = self.lock();
        state.closed = true;
        let left = state.samples.len();
        state.samples = Vec::new();
        self.show(&state);
        left
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::point::{PointId, Quality, Value};
    use crate::time::Timestamp;

    fn sample(t: i64) -> Sample {
        Sample {
            point: PointId::parse("a.temp").unwrap(),
            t: Timestamp(t),
            value: Some(Value::Number(1.0)),
            quality: Quality::Good,
        }
    }

    #[test]
    fn only_the_first_sample_for_an_idle_writer_wakes_it() {
        let inbox = Inbox::new(100, Arc::default());
        assert_eq!(inbox.put(sample(1)), Put::Wake);
        assert_eq!(inbox.put(sample(2)), Put::Queued);
        let mut taken = Vec::new();
        inbox.take(&mut taken, None);
        assert_eq!(taken.len(), 2);
        // The writer now has an open batch and sleeps until it is due.
        taken.clear();
        inbox.take(&mut taken, Some(false));
        assert_eq!(inbox.put(sample(3)), Put::Queued);
        // It committed everything and sleeps idle: the next sample wakes it again.
        taken.clear();
        inbox.take(&mut taken, Some(true));
        assert_eq!(
            taken.len(),
            1,
            "the sample that came meanwhile is taken, not armed"
        );
        taken.clear();
        inbox.take(&mut taken, Some(true));
        assert_eq!(inbox.put(sample(4)), Put::Wake);
    }

    #[test]
    fn a_full_inbox_wakes_a_writer_with_an_open_batch() {
        let inbox = Inbox::new(3, Arc::default());
        let mut taken = Vec::new();
        inbox.take(&mut taken, Some(false));
        assert_eq!(inbox.put(sample(1)), Put::Queued);
        assert_eq!(inbox.put(sample(2)), Put::Queued);
        assert_eq!(inbox.put(sample(3)), Put::Wake);
        assert_eq!(inbox.put(sample(4)), Put::Queued);
    }

    #[test]
    fn a_mark_takes_exactly_the_samples_queued_before_it() {
        let inbox = Inbox::new(100, Arc::default());
        inbox.put(sample(1));
        let mut taken = Vec::new();
        inbox.take(&mut taken, None);
        inbox.put(sample(2));
        inbox.put(sample(3));
        let mark = inbox.mark();
        inbox.put(sample(4));
        taken.clear();
        inbox.take_until(&mut taken, mark);
        let times: Vec<i64> = taken.iter().map(|s| s.t.0).collect();
        assert_eq!(times, [2, 3]);
        taken.clear();
        inbox.take_until(&mut taken, mark);
        assert!(taken.is_empty(), "nothing more was queued before the mark");
        inbox.take(&mut taken, None);
        assert_eq!(taken.len(), 1);
    }

    #[test]
    fn queued_samples_count_as_waiting_until_the_writer_takes_them() {
        let stats = Arc::new(StoreStats::default());
        stats.pending_rows.store(5, Ordering::Relaxed);
        let inbox = Inbox::new(100, Arc::clone(&stats));
        inbox.put(sample(1));
        inbox.put(sample(2));
        let mark = inbox.mark();
        inbox.put(sample(3));
        assert_eq!(stats.rows_waiting(), 8);
        let mut taken = Vec::new();
        inbox.take_until(&mut taken, mark);
        assert_eq!(stats.queued_rows.load(Ordering::Relaxed), 1);
        taken.clear();
        inbox.take(&mut taken, None);
        assert_eq!(
            stats.rows_waiting(),
            5,
            "taken samples are the writer's to count"
        );
        inbox.put(sample(4));
        assert_eq!(inbox.close(), 1);
        assert_eq!(stats.queued_rows.load(Ordering::Relaxed), 0);
    }

    #[test]
    fn a_closed_inbox_refuses_samples_and_counts_those_left() {
        let inbox = Inbox::new(10, Arc::default());
        inbox.put(sample(1));
        inbox.put(sample(2));
        assert_eq!(inbox.close(), 2);
        assert_eq!(inbox.put(sample(3)), Put::Closed);
        let mut taken = Vec::new();
        inbox.take(&mut taken, None);
        assert!(taken.is_empty());
    }
}
