//! The config's `[[alarm]]` tables: limit alarms on any numeric point of the cell.
//!
//! ```toml
//! [[alarm]]
//! point = "meter1.active_power"
//! high = 180.0            # and/or high_high, low, low_low, rate_of_change (per second)
//! deadband = 2.0          # it returns to normal only below high - deadband
//! on_delay = "5s"         # the condition must hold this long to raise it
//! off_delay = "5s"        # and be gone this long to clear it
//! priority = "high"       # low, medium, high, urgent (or 1 to 4)
//! message = "Cell supply near its limit"
//! category = "process"
//! chatter = { activations = 5, window = "10m", shelve = "30m" }
//! ```

use std::ops::Range;
use std::time::Duration;

use serde::Deserialize;
use toml::Spanned;

use super::Priority;
use super::limit::Limits;
use super::state::ChatterRule;
use crate::config::table::{ConfigError, duration};
use crate::point::{PointId, PointKind, PointSpec};

/// Longest on or off delay, and longest chatter window or shelving.
const MAX_DELAY: Duration = Duration::from_secs(24 * 3600);

/// A limit alarm of the config, checked.
#[derive(Debug, Clone, PartialEq)]
pub struct AlarmConfig {
    /// The point it watches.
    pub point: PointId,
    /// Its limits, delays and deadband.
    pub limits: Limits,
    /// Its priority (medium unless given).
    pub priority: Priority,
    /// Words for the operator (the point's name and the limit when not given).
    pub message: Option<String>,
    /// A category of the plant's own (`process`, `safety`, `quality`).
    pub category: Option<String>,
    /// When it chatters.
    pub chatter: Option<ChatterRule>,
}

impl AlarmConfig {
    /// Its limits in words: `sealer0.temperature: above 190 (deadband 5, on delay 5s),
    /// high priority`.
    pub fn describe(&self) -> String {
        let l = &self.limits;
        let mut parts: Vec<String> = [
            ("above", l.high_high, " (high-high)"),
            ("above", l.high, ""),
            ("below", l.low, ""),
            ("below", l.low_low, " (low-low)"),
        ]
        .into_iter()
        .filter_map(|(word, v, which)| v.map(|v| format!("{word} {v}{which}")))
        .collect();
        if let Some(rate) = l.rate_of_change {
            parts.push(format!("changing faster than {rate}/s"));
        }
        let mut extra = Vec::new();
        if l.deadband > 0.0 {
            extra.push(format!("deadband {}", l.deadband));
        }
        for (word, d) in [("on delay", l.on_delay), ("off delay", l.off_delay)] {
            if !d.is_zero() {
                extra.push(format!("{word} {}", humantime::format_duration(d)));
            }
        }
        let extra = if extra.is_empty() {
            String::new()
        } else {
            format!(" ({})", extra.join(", "))
        };
        format!(
            "{}: {}{extra}, {} priority",
            self.point,
            parts.join(" or "),
            self.priority.as_str()
        )
    }
}

/// An `[[alarm]]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawAlarm {
    point: Spanned<String>,
    high_high: Option<Spanned<f64>>,
    high: Option<Spanned<f64>>,
    low: Option<Spanned<f64>>,
    low_low: Option<Spanned<f64>>,
    rate_of_change: Option<Spanned<f64>>,
    deadband: Option<Spanned<f64>>,
    on_delay: Option<Spanned<String>>,
    off_delay: Option<Spanned<String>>,
    priority: Option<Spanned<RawPriority>>,
    message: Option<String>,
    category: Option<String>,
    chatter: Option<Spanned<RawChatter>>,
}

#[derive(Debug, Deserialize)]
#[serde(
    untagged,
    expecting = "priority is low, medium, high or urgent (or 1 to 4)"
)]
enum RawPriority {
    Number(i64),
    Name(String),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawChatter {
    activations: Spanned<i64>,
    window: Spanned<String>,
    shelve: Option<Spanned<String>>,
}

/// A device's points by its id: `None` when the cell has no such device, an error when
/// its driver cannot be made.
pub(crate) type PointsOf<'a> = dyn Fn(&str) -> Option<Result<Vec<PointSpec>, String>> + 'a;

/// The `[[alarm]]` tables against the cell's devices (`points_of`): each point must be a
/// numeric point of a device of the cell, its limits able to hold. Each mistake goes to
/// `errors`.
pub(crate) fn read_alarms(
    raw: Vec<RawAlarm>,
    points_of: &PointsOf<'_>,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
    errors: &mut Vec<ConfigError>,
) -> Vec<AlarmConfig> {
    let mut alarms = Vec::new();
    for alarm in raw {
        match read_alarm(alarm, points_of, at) {
            Ok(alarm) => alarms.push(alarm),
            Err(e) => errors.push(e),
        }
    }
    alarms
}

fn read_alarm(
    raw: RawAlarm,
    points_of: &PointsOf<'_>,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<AlarmConfig, ConfigError> {
    let text = raw.point.get_ref();
    let point = PointId::parse(text).map_err(|e| {
        at(
            raw.point.span(),
            format!(
                "alarm point {text:?} is not a point id (device.point): {}",
                e.rule
            ),
        )
    })?;
    check_point(&point, points_of).map_err(|m| at(raw.point.span(), m))?;
    let number = |v: &Option<Spanned<f64>>| v.as_ref().map(|s| *s.get_ref());
    let delay = |d: &Option<Spanned<String>>, what: &str| {
        d.as_ref()
            .map(|d| duration(d, Duration::ZERO, MAX_DELAY, what, at))
            .transpose()
    };
    let limits = Limits {
        high_high: number(&raw.high_high),
        high: number(&raw.high),
        low: number(&raw.low),
        low_low: number(&raw.low_low),
        rate_of_change: number(&raw.rate_of_change),
        deadband: number(&raw.deadband).unwrap_or(0.0),
        on_delay: delay(&raw.on_delay, "on_delay")?.unwrap_or_default(),
        off_delay: delay(&raw.off_delay, "off_delay")?.unwrap_or_default(),
    };
    limits
        .check()
        .map_err(|m| at(raw.point.span(), format!("alarm on {point}: {m}")))?;
    let priority = match &raw.priority {
        None => Priority::Medium,
        Some(p) => {
            let found = match p.get_ref() {
                RawPriority::Number(n) => Priority::parse(&n.to_string()),
                RawPriority::Name(name) => Priority::parse(name.trim()),
            };
            found.ok_or_else(|| {
                at(
                    p.span(),
                    "priority is low, medium, high or urgent (or 1 to 4)".into(),
                )
            })?
        }
    };
    let chatter = match &raw.chatter {
        None => None,
        Some(c) => {
            let c = c.get_ref();
            let activations = u32::try_from(*c.activations.get_ref())
                .ok()
                .filter(|n| *n >= 1)
                .ok_or_else(|| {
                    at(
                        c.activations.span(),
                        format!(
                            "chatter activations {} must be 1 or more",
                            c.activations.get_ref()
                        ),
                    )
                })?;
            let second = Duration::from_secs(1);
            Some(ChatterRule {
                activations,
                window: duration(&c.window, second, MAX_DELAY, "chatter window", at)?,
                shelve: c
                    .shelve
                    .as_ref()
                    .map(|s| duration(s, second, super::state::MAX_SHELVE, "chatter shelve", at))
                    .transpose()?,
            })
        }
    };
    Ok(AlarmConfig {
        point,
        limits,
        priority,
        message: raw.message,
        category: raw.category,
        chatter,
    })
}

/// Whether `point` is a numeric point of a device of the cell (its driver lists the
/// device's points; building one opens nothing).
fn check_point(point: &PointId, points_of: &PointsOf<'_>) -> Result<(), String> {
    let Some(points) = points_of(point.device()) else {
        return Err(format!(
            "alarm point {point}: the cell has no device {:?}",
            point.device()
        ));
    };
    let points = points?;
    let Some(spec) = points.iter().find(|p| p.id == *point) else {
        let numeric: Vec<&str> = points
            .iter()
            .filter(|p| p.kind == PointKind::Numeric)
            .map(|p| p.id.name())
            .take(12)
            .collect();
        return Err(format!(
            "device {} has no point {:?}; its numeric points include {}",
            point.device(),
            point.name(),
            numeric.join(", ")
        ));
    };
    if spec.kind != PointKind::Numeric {
        return Err(format!(
            "alarm point {point} is not a number ({}): limits apply to numeric points",
            match spec.kind {
                PointKind::Text => "text",
                _ => "an enumeration",
            }
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests;
