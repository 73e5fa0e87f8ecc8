//! Limit alarms on a numeric point, sans IO: high-high, high, low, low-low and rate of
//! change, each its own alarm, with a deadband and on and off delays.
//!
//! A high limit becomes true above `high` and false again only below `high - deadband`
//! (a low one mirrors it), so a value hovering at the limit does not chatter. The
//! condition must hold for `on_delay` before the alarm activates, and be false for
//! `off_delay` before it clears. Values come on change only, so a value that stays above
//! the limit activates the alarm at `on_delay` through [`Condition::tick`], without a new
//! value; [`Condition::due`] says when to call it.

use std::time::Duration;

use serde::Serialize;

use crate::time::Timestamp;

/// Which limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Level {
    /// Above `high_high`.
    HighHigh,
    /// Above `high`.
    High,
    /// Below `low`.
    Low,
    /// Below `low_low`.
    LowLow,
    /// Moving faster than `rate_of_change` per second, either way.
    RateOfChange,
}

impl Level {
    /// The name in alarm ids and the API (`high_high`).
    pub fn as_str(self) -> &'static str {
        match self {
            Level::HighHigh => "high_high",
            Level::High => "high",
            Level::Low => "low",
            Level::LowLow => "low_low",
            Level::RateOfChange => "rate_of_change",
        }
    }
}

/// A point's limits, checked ([`Limits::check`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Limits {
    /// Above it: the high-high alarm.
    pub high_high: Option<f64>,
    /// Above it: the high alarm.
    pub high: Option<f64>,
    /// Below it: the low alarm.
    pub low: Option<f64>,
    /// Below it: the low-low alarm.
    pub low_low: Option<f64>,
    /// Faster than this, in the point's unit per second: the rate-of-change alarm.
    pub rate_of_change: Option<f64>,
    /// How far back past a limit the value must go to clear it.
    pub deadband: f64,
    /// How long a condition must hold before its alarm activates.
    pub on_delay: Duration,
    /// How long a condition must be false before its alarm clears.
    pub off_delay: Duration,
}

impl Limits {
    /// What is wrong with these limits, if anything: none at all, a limit that is not a
    /// number, limits in the wrong order (low above high), a negative deadband or rate.
    pub fn check(&self) -> Result<(), String> {
        let named = [
            ("low_low", self.low_low),
            ("low", self.low),
            ("high", self.high),
            ("high_high", self.high_high),
        ];
        if named.iter().all(|(_, v)| v.is_none()) && self.rate_of_change.is_none() {
            return Err(
                "an alarm needs a limit: high, high_high, low, low_low or rate_of_change".into(),
            );
        }
        for (name, value) in named
            .iter()
            .chain(&[("rate_of_change", self.rate_of_change)])
        {
            if let Some(v) = value
                && !v.is_finite()
            {
                return Err(format!("{name} {v} is not a number"));
            }
        }
        // In order from low_low up to high_high: each set limit below the next set one.
        let set: Vec<(&str, f64)> = named
            .iter()
            .filter_map(|(name, v)| v.map(|v| (*name, v)))
            .collect();
        for pair in set.windows(2) {
            let ((a, x), (b, y)) = (pair[0], pair[1]);
            if x >= y {
                return Err(format!(
                    "{a} {x} is not below {b} {y}: the alarm could never be right (low_low < low < high < high_high)"
                ));
            }
        }
        if !(self.deadband.is_finite() && self.deadband >= 0.0) {
            return Err(format!("deadband {} must be 0 or more", self.deadband));
        }
        if let (Some(low), Some(high)) = (self.low, self.high)
            && low + self.deadband >= high - self.deadband
        {
            return Err(format!(
                "deadband {} is too wide for low {low} and high {high}: a value could be in both alarms at once",
                self.deadband
            ));
        }
        if self.rate_of_change.is_some_and(|r| r <= 0.0) {
            return Err("rate_of_change must be above 0 (per second)".into());
        }
        Ok(())
    }

    /// The levels these limits set.
    pub fn levels(&self) -> Vec<Level> {
        [
            (Level::HighHigh, self.high_high.is_some()),
            (Level::High, self.high.is_some()),
            (Level::Low, self.low.is_some()),
            (Level::LowLow, self.low_low.is_some()),
            (Level::RateOfChange, self.rate_of_change.is_some()),
        ]
        .into_iter()
        .filter_map(|(level, set)| set.then_some(level))
        .collect()
    }
}

/// One level's condition over time: the raw test with its deadband, then the delays.
#[derive(Debug, Clone, PartialEq)]
pub struct Condition {
    level: Level,
    limits: Limits,
    /// The raw test's result, and since when.
    raw: bool,
    since: Option<Timestamp>,
    /// What the alarm was told last.
    active: bool,
    /// The value before, for the rate of change.
    last: Option<(f64, Timestamp)>,
}

impl Condition {
    /// `level`'s condition under `limits`.
    pub fn new(level: Level, limits: Limits) -> Self {
        Self {
            level,
            limits,
            raw: false,
            since: None,
            active: false,
            last: None,
        }
    }

    /// Puts back a condition saved `active` (after a restart): it holds until values
    /// say otherwise.
    pub fn restore(&mut self, active: bool) {
        self.raw = active;
        self.active = active;
        self.since = None;
    }

    /// Its level.
    pub fn level(&self) -> Level {
        self.level
    }

    /// The last value seen, if the point still has one.
    pub fn last_value(&self) -> Option<f64> {
        self.last.map(|(value, _)| value)
    }

    /// A new value at `now`: `Some(active)` when the alarm's condition changes.
    pub fn value(&mut self, value: f64, now: Timestamp) -> Option<bool> {
        let raw = self.test(value, now);
        self.last = Some((value, now));
        if raw != self.raw {
            self.raw = raw;
            self.since = Some(now);
        }
        self.tick(now)
    }

    /// The point lost its value (the device stopped answering): the condition holds as
    /// it was; the delays wait for values.
    pub fn no_value(&mut self) {
        self.last = None;
    }

    /// Time passes: `Some(active)` when a delay has run out.
    pub fn tick(&mut self, now: Timestamp) -> Option<bool> {
        let due = self.due()?;
        if now >= due {
            self.active = self.raw;
            return Some(self.active);
        }
        None
    }

    /// When [`Condition::tick`] will next change something, if it will: the raw test
    /// differs from the alarm, and its delay (on or off) runs from when it began to.
    pub fn due(&self) -> Option<Timestamp> {
        if self.raw == self.active {
            return None;
        }
        let delay = if self.raw {
            self.limits.on_delay
        } else {
            self.limits.off_delay
        };
        self.since.map(|since| since.plus(delay))
    }

    /// The raw test, with the deadband on the way back.
    fn test(&self, value: f64, now: Timestamp) -> bool {
        let l = &self.limits;
        let band = l.deadband;
        let above = |limit: Option<f64>| {
            limit.is_some_and(|x| {
                if self.raw {
                    value > x - band
                } else {
                    value > x
                }
            })
        };
        let below = |limit: Option<f64>| {
            limit.is_some_and(|x| {
                if self.raw {
                    value < x + band
                } else {
                    value < x
                }
            })
        };
        match self.level {
            Level::HighHigh => above(l.high_high),
            Level::High => above(l.high),
            Level::Low => below(l.low),
            Level::LowLow => below(l.low_low),
            Level::RateOfChange => {
                let (Some(rate), Some((before, then))) = (l.rate_of_change, self.last) else {
                    return false;
                };
                let seconds = (now.0 - then.0) as f64 / 1000.0;
                seconds > 0.0 && ((value - before) / seconds).abs() > rate
            }
        }
    }
}

#[cfg(test)]
mod tests;
