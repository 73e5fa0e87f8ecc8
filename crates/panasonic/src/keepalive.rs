//! The host's wire-break check (3.5-1, 3.5-2), sans-IO.
//!
//! Every interval (30 s or more) the host sends `C2HB00` + id on Port 1. An `A2` back on
//! Port 1 proves Port 1; an `R1HB00` + the same id on Port 2 proves Port 2. `A4E00` instead
//! of `A2` means the command was wrong but Port 1 works. If either answer is missing when
//! the reply time-out ends, that port is dead and the host must reconnect.
//!
//! [`KeepAlive`] keeps the schedule and the verdict; the caller sends, receives and
//! reconnects. Time comes in as `now`.

use std::time::{Duration, Instant};

use crate::command::{Command, KeepAliveId};

/// The shortest interval the manual allows ("at intervals of 30 s or more").
pub const MIN_INTERVAL: Duration = Duration::from_secs(30);
/// Default interval.
pub const DEFAULT_INTERVAL: Duration = Duration::from_secs(30);
/// Default time to wait for both answers \[?\] (the manual gives none).
pub const DEFAULT_REPLY_TIMEOUT: Duration = Duration::from_secs(10);

/// How the check runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct KeepAliveConfig {
    /// Time between checks (at least [`MIN_INTERVAL`]).
    pub interval: Duration,
    /// Time to wait for the `A2` and the `R1HB`.
    pub reply_timeout: Duration,
    /// Whether to expect `R1HB` on Port 2 (not when the machine's R commands are off).
    pub expect_echo: bool,
}

impl Default for KeepAliveConfig {
    fn default() -> Self {
        KeepAliveConfig {
            interval: DEFAULT_INTERVAL,
            reply_timeout: DEFAULT_REPLY_TIMEOUT,
            expect_echo: true,
        }
    }
}

/// A configuration the manual does not allow.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum KeepAliveConfigError {
    /// Interval below 30 s.
    #[error("keep-alive interval {interval:?} is below the {min:?} the manual requires")]
    IntervalTooShort {
        /// The interval given.
        interval: Duration,
        /// 30 s.
        min: Duration,
    },
    /// A reply time-out of zero, or one not shorter than the interval.
    #[error(
        "keep-alive reply time-out {timeout:?} must be above zero and shorter than the interval {interval:?}"
    )]
    BadTimeout {
        /// The time-out given.
        timeout: Duration,
        /// The interval.
        interval: Duration,
    },
}

/// The outcome of one check.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Verdict {
    /// Both ports answered.
    Alive {
        /// The check's id.
        id: KeepAliveId,
    },
    /// At least one port did not answer in time: reconnect.
    Dead {
        /// The check's id.
        id: KeepAliveId,
        /// Port 1 gave neither `A2` nor `A4E00`.
        port1: bool,
        /// Port 2 gave no matching `R1HB`.
        port2: bool,
    },
}

#[derive(Debug, Clone, PartialEq, Eq)]
struct Probe {
    id: KeepAliveId,
    deadline: Instant,
    port1: bool,
    port2: bool,
}

/// The keep-alive schedule and verdicts for one host connection pair.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KeepAlive {
    config: KeepAliveConfig,
    next_check: Instant,
    probe: Option<Probe>,
    sequence: u64,
}

impl KeepAlive {
    /// A schedule whose first check is due one interval after `now` (just connected).
    pub fn new(config: KeepAliveConfig, now: Instant) -> Result<KeepAlive, KeepAliveConfigError> {
        if config.interval < MIN_INTERVAL {
            return Err(KeepAliveConfigError::IntervalTooShort {
                interval: config.interval,
                min: MIN_INTERVAL,
            });
        }
        if config.reply_timeout.is_zero() || config.reply_timeout >= config.interval {
            return Err(KeepAliveConfigError::BadTimeout {
                timeout: config.reply_timeout,
                interval: config.interval,
            });
        }
        Ok(KeepAlive {
            config,
            next_check: now + config.interval,
            probe: None,
            sequence: 0,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &KeepAliveConfig {
        &self.config
    }

    /// Starts over after a reconnect: no check open, the next one interval after `now`.
    pub fn reset(&mut self, now: Instant) {
        self.probe = None;
        self.next_check = now + self.config.interval;
    }

    /// The `C2HB` to send, when a check is due at `now` and none is open.
    pub fn poll_transmit(&mut self, now: Instant) -> Option<Command> {
        if self.probe.is_some() || now < self.next_check {
            return None;
        }
        self.sequence += 1;
        let id = KeepAliveId::sequence(self.sequence);
        self.probe = Some(Probe {
            id: id.clone(),
            deadline: now + self.config.reply_timeout,
            port1: false,
            port2: false,
        });
        self.next_check = now + self.config.interval;
        Some(Command::KeepAlive(id))
    }

    /// Whether a check is open: sent, its verdict not yet given.
    pub fn is_checking(&self) -> bool {
        self.probe.is_some()
    }

    /// When to call [`poll_transmit`](Self::poll_transmit) or [`poll_verdict`](Self::poll_verdict) next.
    pub fn poll_timeout(&self) -> Instant {
        self.probe
            .as_ref()
            .map_or(self.next_check, |probe| probe.deadline)
    }

    /// Port 1 answered the open check (`A2`, or `A4E00`: wrong command, working port).
    pub fn port1_answered(&mut self) {
        if let Some(probe) = &mut self.probe {
            probe.port1 = true;
        }
    }

    /// An `R1HB` arrived on Port 2; returns whether it matches the open check.
    pub fn port2_echo(&mut self, id: &KeepAliveId) -> bool {
        match &mut self.probe {
            Some(probe) if &probe.id == id => {
                probe.port2 = true;
                true
            }
            _ => false,
        }
    }

    /// The verdict on the open check, once both ports answered or the time-out passed.
    pub fn poll_verdict(&mut self, now: Instant) -> Option<Verdict> {
        let probe = self.probe.as_ref()?;
        let port2_ok = probe.port2 || !self.config.expect_echo;
        if probe.port1 && port2_ok {
            let id = probe.id.clone();
            self.probe = None;
            return Some(Verdict::Alive { id });
        }
        if now < probe.deadline {
            return None;
        }
        let verdict = Verdict::Dead {
            id: probe.id.clone(),
            port1: !probe.port1,
            port2: !port2_ok,
        };
        self.probe = None;
        Some(verdict)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn schedule(now: Instant) -> KeepAlive {
        KeepAlive::new(KeepAliveConfig::default(), now).expect("default config is valid")
    }

    /// A keep-alive scheduled now that sent its first check one interval later: it, when
    /// the check went out and its id.
    fn first_check() -> (KeepAlive, Instant, KeepAliveId) {
        let t0 = Instant::now();
        let mut keep = schedule(t0);
        let t1 = t0 + DEFAULT_INTERVAL;
        let id = id_of(keep.poll_transmit(t1));
        (keep, t1, id)
    }

    fn id_of(command: Option<Command>) -> KeepAliveId {
        match command {
            Some(Command::KeepAlive(id)) => id,
            other => panic!("expected a C2HB, got {other:?}"),
        }
    }

    #[test]
    fn a_check_goes_out_every_interval_and_is_alive_when_both_ports_answer() {
        let t0 = Instant::now();
        let mut keep = schedule(t0);
        assert_eq!(keep.poll_transmit(t0 + Duration::from_secs(29)), None);
        assert_eq!(keep.poll_timeout(), t0 + DEFAULT_INTERVAL);
        let t1 = t0 + DEFAULT_INTERVAL;
        assert!(!keep.is_checking());
        let id = id_of(keep.poll_transmit(t1));
        assert!(keep.is_checking());
        assert_eq!(Command::KeepAlive(id.clone()).wire(), "C2HB00000001");
        assert_eq!(keep.poll_transmit(t1), None, "one check at a time");
        keep.port1_answered();
        assert_eq!(keep.poll_verdict(t1), None, "Port 2 still due");
        assert!(
            !keep.port2_echo(&KeepAliveId::new("999999").expect("valid")),
            "another id does not count"
        );
        assert!(keep.port2_echo(&id));
        assert_eq!(keep.poll_verdict(t1), Some(Verdict::Alive { id }));
        assert!(!keep.is_checking());
        assert_eq!(keep.poll_timeout(), t1 + DEFAULT_INTERVAL);
    }

    #[test]
    fn a_missing_echo_marks_port_2_dead_after_the_time_out() {
        let (mut keep, t1, id) = first_check();
        keep.port1_answered();
        assert_eq!(
            keep.poll_verdict(t1 + DEFAULT_REPLY_TIMEOUT - Duration::from_millis(1)),
            None
        );
        assert_eq!(
            keep.poll_verdict(t1 + DEFAULT_REPLY_TIMEOUT),
            Some(Verdict::Dead {
                id,
                port1: false,
                port2: true
            })
        );
    }

    #[test]
    fn silence_on_both_ports_marks_both_dead_and_reset_starts_over() {
        let (mut keep, t1, id) = first_check();
        let late = t1 + DEFAULT_REPLY_TIMEOUT;
        assert_eq!(
            keep.poll_verdict(late),
            Some(Verdict::Dead {
                id,
                port1: true,
                port2: true
            })
        );
        keep.reset(late);
        assert_eq!(keep.poll_transmit(late), None);
        assert_eq!(
            id_of(keep.poll_transmit(late + DEFAULT_INTERVAL)).as_str(),
            "000002"
        );
    }

    #[test]
    fn without_r_commands_port_1_alone_decides() {
        let t0 = Instant::now();
        let config = KeepAliveConfig {
            expect_echo: false,
            ..KeepAliveConfig::default()
        };
        let mut keep = KeepAlive::new(config, t0).expect("valid");
        let id = id_of(keep.poll_transmit(t0 + DEFAULT_INTERVAL));
        keep.port1_answered();
        assert_eq!(
            keep.poll_verdict(t0 + DEFAULT_INTERVAL),
            Some(Verdict::Alive { id })
        );
    }

    #[test]
    fn intervals_below_30_seconds_are_refused() {
        let now = Instant::now();
        let short = KeepAliveConfig {
            interval: Duration::from_secs(10),
            ..KeepAliveConfig::default()
        };
        assert_eq!(
            KeepAlive::new(short, now),
            Err(KeepAliveConfigError::IntervalTooShort {
                interval: Duration::from_secs(10),
                min: MIN_INTERVAL
            })
        );
        let slow = KeepAliveConfig {
            reply_timeout: Duration::from_secs(30),
            ..KeepAliveConfig::default()
        };
        assert!(matches!(
            KeepAlive::new(slow, now),
            Err(KeepAliveConfigError::BadTimeout { .. })
        ));
    }
}
