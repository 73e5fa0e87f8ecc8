//! The rounds of the `watch` subcommands: one every interval, until Ctrl-C.

use std::time::Duration;

use tokio::time::{Instant, Interval, MissedTickBehavior};

/// A round every interval (a late one delays the next instead of bursting), and the time
/// since the first.
pub struct Rounds {
    ticker: Interval,
    started: Instant,
}

impl Rounds {
    /// Rounds every `interval`, the first at once.
    pub fn every(interval: Duration) -> Self {
        let mut ticker = tokio::time::interval(interval);
        ticker.set_missed_tick_behavior(MissedTickBehavior::Delay);
        Self {
            ticker,
            started: Instant::now(),
        }
    }

    /// Waits for the next round: `false` when Ctrl-C came first.
    pub async fn next(&mut self) -> bool {
        tokio::select! {
            _ = self.ticker.tick() => true,
            _ = tokio::signal::ctrl_c() => false,
        }
    }

    /// How long the watch has run.
    pub fn elapsed(&self) -> Duration {
        self.started.elapsed()
    }
}
