//! Waits that double after each failure, up to a cap: how every cellbus component retries
//! something that does not answer (a silent device, a line that cannot be opened, a machine
//! whose connection dropped). Pure arithmetic; the caller owns the clock.

use std::time::Duration;

/// Waits that start at `first` and double after each failure, up to `cap`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Backoff {
    /// The wait after the first failure.
    pub first: Duration,
    /// The longest wait.
    pub cap: Duration,
}

impl Backoff {
    /// Waits from `first`, doubling up to `cap`.
    pub const fn new(first: Duration, cap: Duration) -> Self {
        Self { first, cap }
    }

    /// The wait after `failures` failures in a row (1 or fewer: `first`).
    pub fn after(self, failures: u32) -> Duration {
        let doublings = failures.saturating_sub(1).min(32);
        self.first
            .saturating_mul(2u32.saturating_pow(doublings))
            .min(self.cap)
            .max(self.first.min(self.cap))
    }

    /// A running sequence of these waits.
    pub fn timer(self) -> BackoffTimer {
        BackoffTimer {
            config: self,
            next: self.first.min(self.cap),
        }
    }
}

/// A running backoff: each [`next`](Self::next) gives a wait and doubles the one after.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BackoffTimer {
    config: Backoff,
    next: Duration,
}

impl BackoffTimer {
    /// The wait before the next attempt; the one after is twice as long (up to the cap).
    // Not an iterator: it never ends, and `peek`/`reset` are its point.
    #[allow(clippy::should_implement_trait)]
    pub fn next(&mut self) -> Duration {
        let wait = self.next;
        self.next = wait
            .saturating_mul(2)
            .min(self.config.cap)
            .max(self.config.first.min(self.config.cap));
        wait
    }

    /// The wait the next [`next`](Self::next) gives.
    pub fn peek(&self) -> Duration {
        self.next
    }

    /// Back to the first wait (the thing answered).
    pub fn reset(&mut self) {
        self.next = self.config.first.min(self.config.cap);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: Duration = Duration::from_secs(1);

    #[test]
    fn waits_double_from_the_first_up_to_the_cap() {
        let b = Backoff::new(2 * S, 10 * S);
        let waits: Vec<u64> = (1..=6).map(|f| b.after(f).as_secs()).collect();
        assert_eq!(waits, vec![2, 4, 8, 10, 10, 10]);
        assert_eq!(b.after(0), 2 * S);
        assert_eq!(b.after(u32::MAX), 10 * S);
    }

    #[test]
    fn a_timer_gives_the_same_waits_and_starts_over_when_reset() {
        let b = Backoff::new(S / 2, 3 * S);
        let mut timer = b.timer();
        let waits: Vec<Duration> = (0..5).map(|_| timer.next()).collect();
        assert_eq!(waits, vec![S / 2, S, 2 * S, 3 * S, 3 * S]);
        assert_eq!(timer.peek(), 3 * S);
        timer.reset();
        assert_eq!(timer.next(), S / 2);
    }

    #[test]
    fn a_cap_below_the_first_wait_wins() {
        let b = Backoff::new(5 * S, 2 * S);
        assert_eq!(b.after(1), 2 * S);
        assert_eq!(b.timer().next(), 2 * S);
    }
}
