//! How the `watch` subcommands run and stop: a round every `--interval`, until `--count`
//! rounds, `--for` a while, or Ctrl-C, whichever comes first. `panasonic events` stops
//! the same way ([`Stop`]), counting R messages instead of rounds.

use std::time::Duration;

use clap::Args;
use tokio::signal::unix::{SignalKind, signal};
use tokio::sync::watch;
use tokio::time::{Instant, Interval, MissedTickBehavior};

/// `--count N` and `--for DURATION`, shared by every watch.
#[derive(Debug, Clone, Copy, Args)]
pub struct StopArgs {
    /// Stop after N rounds, at least 1 (default: until --for or Ctrl-C).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub count: Option<u64>,
    /// Stop after this long: 30s, 5m, 2h (default: until --count or Ctrl-C).
    #[arg(long = "for", value_name = "DURATION", value_parser = parse_period)]
    pub duration: Option<Duration>,
}

/// A watch's `--interval` or `--for`: a duration longer than 0 (`500ms`, `1s`, `5m`).
pub fn parse_period(text: &str) -> Result<Duration, String> {
    let period = humantime::parse_duration(text).map_err(|e| format!("{e}; e.g. 500ms or 5m"))?;
    if period.is_zero() {
        return Err(format!("{text} is no time at all: give more than 0"));
    }
    Ok(period)
}

/// When a watch stops, apart from its count: `--for`'s deadline or Ctrl-C.
pub struct Stop {
    deadline: Option<Instant>,
    interrupted: watch::Receiver<bool>,
}

impl Stop {
    /// From now: stops after `duration` (never without one) or at Ctrl-C. Ctrl-C is
    /// caught from here on; one that comes while the watch is busy (reading a device) is
    /// kept until it next waits.
    pub fn new(duration: Option<Duration>) -> Self {
        Self::from(Instant::now(), duration)
    }

    /// Like [`Stop::new`], the deadline counted from `start`.
    fn from(start: Instant, duration: Option<Duration>) -> Self {
        let (tell, interrupted) = watch::channel(false);
        // Registered now, not when a task first runs: a Ctrl-C right after the first round
        // must not find SIGINT's default action (ending the process mid-line) still set.
        match signal(SignalKind::interrupt()) {
            Ok(mut sigint) => {
                tokio::spawn(async move {
                    if sigint.recv().await.is_some() {
                        let _ = tell.send(true);
                    }
                });
            }
            Err(e) => tracing::debug!("Ctrl-C is not caught, it ends the watch at once: {e}"),
        }
        Self {
            deadline: duration.map(|d| start + d),
            interrupted,
        }
    }

    /// Waits until the watch must stop.
    pub async fn wait(&mut self) {
        let end = self.deadline;
        let deadline = async {
            match end {
                Some(end) => tokio::time::sleep_until(end).await,
                None => std::future::pending().await,
            }
        };
        let interrupted = async {
            if self.interrupted.wait_for(|&stop| stop).await.is_err() {
                // Ctrl-C is not caught (see `new`): only the deadline stops the watch.
                std::future::pending::<()>().await;
            }
        };
        tokio::select! {
            () = interrupted => {}
            () = deadline => {}
        }
    }
}

/// A round every interval (a late one delays the next instead of bursting), and the time
/// since the first.
pub struct Rounds {
    ticker: Interval,
    started: Instant,
    stop: Stop,
    left: Option<u64>,
}

impl Rounds {
    /// Rounds every `interval`, the first at once, until `stop` says.
    pub fn new(interval: Duration, stop: StopArgs) -> Self {
        // One start for the ticks and the deadline: a tick due exactly at `--for`'s end
        // (the fourth of `--interval 100ms --for 300ms`) is at it, not a hair before it.
        let start = Instant::now();
        let mut ticker = tokio::time::interval_at(start, interval);
        ticker.set_missed_tick_behavior(MissedTickBehavior::Delay);
        Self {
            ticker,
            started: start,
            stop: Stop::from(start, stop.duration),
            left: stop.count,
        }
    }

    /// Waits for the next round: `false` when the watch is over (its count done, its time
    /// up, or Ctrl-C). A round due at `--for`'s end is not started.
    pub async fn next(&mut self) -> bool {
        if self.left == Some(0) {
            return false;
        }
        let go = tokio::select! {
            biased;
            () = self.stop.wait() => false,
            due = self.ticker.tick() => self.stop.deadline.is_none_or(|end| due < end),
        };
        if go && let Some(left) = &mut self.left {
            *left -= 1;
        }
        go
    }

    /// How long the watch has run.
    pub fn elapsed(&self) -> Duration {
        self.started.elapsed()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    async fn rounds_of(interval: Duration, count: Option<u64>, duration: Option<Duration>) -> u64 {
        let mut rounds = Rounds::new(interval, StopArgs { count, duration });
        let mut seen = 0;
        while rounds.next().await {
            seen += 1;
        }
        seen
    }

    #[tokio::test(start_paused = true)]
    async fn a_watch_with_a_count_runs_that_many_rounds() {
        assert_eq!(rounds_of(Duration::from_secs(1), Some(3), None).await, 3);
    }

    #[tokio::test(start_paused = true)]
    async fn a_watch_for_a_while_runs_the_rounds_that_start_before_its_end() {
        let second = Duration::from_secs(1);
        assert_eq!(rounds_of(second, None, Some(second * 4)).await, 4);
        assert_eq!(
            rounds_of(second, None, Some(second * 4 / 2 + second / 2)).await,
            3
        );
    }

    #[tokio::test(start_paused = true)]
    async fn the_first_of_count_and_for_stops_a_watch() {
        let second = Duration::from_secs(1);
        assert_eq!(rounds_of(second, Some(2), Some(second * 10)).await, 2);
        assert_eq!(rounds_of(second, Some(10), Some(second * 2)).await, 2);
    }

    #[test]
    fn periods_are_durations_longer_than_zero() {
        assert_eq!(parse_period("500ms"), Ok(Duration::from_millis(500)));
        assert!(parse_period("0s").unwrap_err().contains("more than 0"));
        assert!(parse_period("soon").unwrap_err().contains("e.g. 500ms"));
    }
}
