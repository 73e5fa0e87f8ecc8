//! The config's production keys: `time_zone` and `[[shift]]` at the top, a device's
//! `states` and `[line.device.production]`.

use std::collections::{BTreeMap, HashSet};
use std::ops::Range;
use std::time::Duration;

use jiff::civil::{Time, Weekday};
use serde::Deserialize;
use toml::Spanned;

use super::shift::{self, EVERY_DAY, Shift, Shifts};
use super::states::{StateOverrides, check_overrides};
use super::{ProductionSettings, StateDef};
use crate::config::table::{ConfigError, duration};
use crate::point::PointId;

/// Longest ideal cycle or micro-stop threshold accepted.
const MAX_CYCLE: Duration = Duration::from_secs(24 * 3600);

/// A `[[shift]]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawShift {
    name: Spanned<String>,
    days: Option<Spanned<Vec<String>>>,
    start: Spanned<String>,
    end: Spanned<String>,
    #[serde(default)]
    breaks: Vec<RawBreak>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawBreak {
    start: Spanned<String>,
    end: Spanned<String>,
}

/// A device's `[line.device.production]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawProduction {
    ideal_cycle: Option<Spanned<RawCycle>>,
    micro_stop: Option<Spanned<String>>,
    good_boards: Option<Spanned<String>>,
}

/// One ideal cycle, or one per program (`"*"` for the others).
#[derive(Debug, Deserialize)]
#[serde(
    untagged,
    expecting = "ideal_cycle is a duration (\"42s\") or a table of durations by program ({ \"PCB-A\" = \"40s\", \"*\" = \"45s\" })"
)]
pub(crate) enum RawCycle {
    One(String),
    ByProgram(BTreeMap<String, String>),
}

/// The cell's shifts from `time_zone` and the `[[shift]]` tables; each mistake in
/// `errors`.
pub(crate) fn read_shifts(
    zone: Option<&Spanned<String>>,
    raw: &[RawShift],
    at: &impl Fn(Range<usize>, String) -> ConfigError,
    errors: &mut Vec<ConfigError>,
) -> Shifts {
    let mut shifts = Vec::new();
    let mut names = HashSet::new();
    for s in raw {
        match read_shift(s, at) {
            Ok(shift) => {
                if !names.insert(shift.name.clone()) {
                    errors.push(at(
                        s.name.span(),
                        format!("shift name {:?} is used twice", shift.name),
                    ));
                    continue;
                }
                shifts.push(shift);
            }
            Err(e) => errors.push(e),
        }
    }
    match Shifts::new(zone.map(|z| z.get_ref().as_str()), shifts) {
        Ok(shifts) => shifts,
        Err(message) => {
            let span = zone.map_or(0..0, Spanned::span);
            errors.push(at(span, message));
            Shifts::default()
        }
    }
}

fn read_shift(
    raw: &RawShift,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<Shift, ConfigError> {
    let name = raw.name.get_ref().trim();
    if name.is_empty() {
        return Err(at(raw.name.span(), "a shift needs a name".into()));
    }
    let clock = |text: &Spanned<String>, what: &str| -> Result<Time, ConfigError> {
        shift::clock(text.get_ref().trim()).ok_or_else(|| {
            at(
                text.span(),
                format!(
                    "shift {name:?}: {what} {:?} is not a time of day; write HH:MM, e.g. \"06:00\" or \"22:30\"",
                    text.get_ref()
                ),
            )
        })
    };
    let start = clock(&raw.start, "start")?;
    let end = clock(&raw.end, "end")?;
    let days = match &raw.days {
        None => EVERY_DAY.to_vec(),
        Some(days) => read_days(days.get_ref())
            .map_err(|m| at(days.span(), format!("shift {name:?}: {m}")))?,
    };
    // Minutes from the shift's start, for checking that breaks fall within it.
    let offset = |t: Time| -> i64 {
        let minutes = |t: Time| i64::from(t.hour()) * 60 + i64::from(t.minute());
        (minutes(t) - minutes(start)).rem_euclid(24 * 60)
    };
    let length = match offset(end) {
        0 => 24 * 60,
        n => n,
    };
    let mut breaks = Vec::new();
    for b in &raw.breaks {
        let (bs, be) = (clock(&b.start, "break start")?, clock(&b.end, "break end")?);
        let (from, to) = (offset(bs), offset(be));
        if to <= from || to > length {
            return Err(at(
                b.start.span(),
                format!(
                    "shift {name:?}: the break {}–{} is not within the shift {}–{}",
                    b.start.get_ref(),
                    b.end.get_ref(),
                    raw.start.get_ref(),
                    raw.end.get_ref()
                ),
            ));
        }
        breaks.push((bs, be));
    }
    Ok(Shift {
        name: name.to_owned(),
        days,
        start,
        end,
        breaks,
    })
}

/// Weekdays from `["mon", "tue"]` or ranges `["mon-fri"]`.
fn read_days(days: &[String]) -> Result<Vec<Weekday>, String> {
    let day = |t: &str| {
        shift::weekday(t.trim()).ok_or_else(|| {
            format!("{t:?} is not a weekday; write mon, tue, wed, thu, fri, sat, sun, or a range like \"mon-fri\"")
        })
    };
    let mut out = Vec::new();
    for text in days {
        match text.split_once('-') {
            Some((a, b)) => {
                let (a, b) = (day(a)?, day(b)?);
                let mut d = a;
                loop {
                    out.push(d);
                    if d == b {
                        break;
                    }
                    d = d.next();
                }
            }
            None => out.push(day(text)?),
        }
    }
    if out.is_empty() {
        return Err("days is empty; leave it out for every day".into());
    }
    out.sort_by_key(|d| d.to_monday_zero_offset());
    out.dedup();
    Ok(out)
}

/// A device's `states` table against its kind's states.
pub(crate) fn read_states(
    kind: &str,
    states: &[StateDef],
    raw: Option<&Spanned<BTreeMap<String, i64>>>,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<StateOverrides, ConfigError> {
    match raw {
        None => Ok(StateOverrides::new()),
        Some(raw) => check_overrides(kind, states, raw.get_ref()).map_err(|m| at(raw.span(), m)),
    }
}

/// A device's `[line.device.production]`, for a kind that produces.
pub(crate) fn read_production(
    kind: &str,
    produces: bool,
    raw: Option<&Spanned<RawProduction>>,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<Option<ProductionSettings>, ConfigError> {
    let Some(raw) = raw else {
        return Ok(None);
    };
    if !produces {
        return Err(at(
            raw.span(),
            format!(
                "{kind} devices count no production, so [line.device.production] does not apply to them"
            ),
        ));
    }
    let raw = raw.get_ref();
    let cycle = |text: &str, span: Range<usize>, what: &str| {
        duration(
            &Spanned::new(span, text.to_owned()),
            Duration::from_millis(100),
            MAX_CYCLE,
            what,
            at,
        )
    };
    let mut settings = ProductionSettings::default();
    if let Some(spanned) = &raw.ideal_cycle {
        match spanned.get_ref() {
            RawCycle::One(text) => {
                settings.ideal_cycle = Some(cycle(text, spanned.span(), "ideal_cycle")?);
            }
            RawCycle::ByProgram(programs) => {
                for (program, text) in programs {
                    let what = format!("ideal_cycle of {program:?}");
                    let d = cycle(text, spanned.span(), &what)?;
                    if program == "*" {
                        settings.ideal_cycle = Some(d);
                    } else {
                        settings.ideal_cycle_by_program.insert(program.clone(), d);
                    }
                }
            }
        }
    }
    if let Some(text) = &raw.micro_stop {
        settings.micro_stop = Some(duration(
            text,
            Duration::from_secs(1),
            MAX_CYCLE,
            "micro_stop",
            at,
        )?);
    }
    if let Some(point) = &raw.good_boards {
        settings.good_boards = Some(PointId::parse(point.get_ref()).map_err(|e| {
            at(
                point.span(),
                format!(
                    "good_boards {:?} is not a point id (device.point): {}",
                    point.get_ref(),
                    e.rule
                ),
            )
        })?);
    }
    Ok(Some(settings))
}

#[cfg(test)]
mod tests;
