//! Shifts: when the cell is planned to produce, in the cell's time zone.
//!
//! A `[[shift]]` has a name, the weekdays it starts on, a start and an end (an end at or
//! before the start is on the next day: `22:00`–`06:00` crosses midnight) and planned
//! breaks. Without any `[[shift]]` the cell has one shift, `day`, of 24 h from midnight.
//! Time outside every shift, and in breaks, is not planned production time (E10
//! non-scheduled). Days and times are the cell's wall clock (`time_zone`, default the
//! machine's own): a shift on the night the clocks change is an hour shorter or longer.

use std::fmt;

use jiff::civil::{Date, Time, Weekday};
use jiff::tz::TimeZone;
use serde::Serialize;

use crate::time::Timestamp;

/// One shift of the config.
#[derive(Debug, Clone, PartialEq)]
pub struct Shift {
    /// Its name (`early`).
    pub name: String,
    /// The weekdays it starts on.
    pub days: Vec<Weekday>,
    /// Its start, wall clock.
    pub start: Time,
    /// Its end; at or before `start`, on the next day.
    pub end: Time,
    /// Planned breaks, wall clock, each within the shift.
    pub breaks: Vec<(Time, Time)>,
}

/// The cell's shifts and its time zone.
#[derive(Debug, Clone, PartialEq)]
pub struct Shifts {
    zone: TimeZone,
    /// The zone's name as configured (`Europe/Berlin`), or the machine's.
    zone_name: String,
    shifts: Vec<Shift>,
}

/// One shift on one day, in time.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ShiftWindow {
    /// The shift's name.
    pub name: String,
    /// The day it starts on, in the cell's zone.
    #[serde(serialize_with = "serialize_date")]
    pub day: Date,
    /// Its start.
    pub start: Timestamp,
    /// Its end.
    pub end: Timestamp,
    /// Its planned breaks.
    #[serde(skip)]
    pub breaks: Vec<(Timestamp, Timestamp)>,
}

fn serialize_date<S: serde::Serializer>(date: &Date, s: S) -> Result<S::Ok, S::Error> {
    s.collect_str(date)
}

/// Every weekday, for a shift without `days`.
pub const EVERY_DAY: [Weekday; 7] = [
    Weekday::Monday,
    Weekday::Tuesday,
    Weekday::Wednesday,
    Weekday::Thursday,
    Weekday::Friday,
    Weekday::Saturday,
    Weekday::Sunday,
];

impl Default for Shifts {
    /// One 24 h shift, `day`, every day, in the machine's time zone.
    fn default() -> Self {
        Self::new(None, Vec::new()).expect("the machine's own zone needs no lookup")
    }
}

impl Shifts {
    /// The shifts in `zone` (a tz database name; the machine's zone when `None`); none
    /// given makes one 24 h shift, `day`.
    pub fn new(zone: Option<&str>, mut shifts: Vec<Shift>) -> Result<Self, String> {
        let (zone, zone_name) = match zone {
            Some(name) => (
                TimeZone::get(name).map_err(|_| {
                    format!(
                        "time zone {name:?} is not in the tz database; write a name like \"Europe/Berlin\", \"America/Chicago\" or \"UTC\""
                    )
                })?,
                name.to_owned(),
            ),
            None => {
                let zone = TimeZone::system();
                let name = zone.iana_name().unwrap_or("the machine's local time").to_owned();
                (zone, name)
            }
        };
        if shifts.is_empty() {
            shifts.push(Shift {
                name: "day".into(),
                days: EVERY_DAY.to_vec(),
                start: Time::midnight(),
                end: Time::midnight(),
                breaks: Vec::new(),
            });
        }
        Ok(Self {
            zone,
            zone_name,
            shifts,
        })
    }

    /// The configured shifts.
    pub fn shifts(&self) -> &[Shift] {
        &self.shifts
    }

    /// The cell's time zone.
    pub fn zone(&self) -> &TimeZone {
        &self.zone
    }

    /// The zone's name.
    pub fn zone_name(&self) -> &str {
        &self.zone_name
    }

    /// The day (in the cell's zone) that `t` falls on.
    pub fn day_of(&self, t: Timestamp) -> Date {
        to_jiff(t).to_zoned(self.zone.clone()).date()
    }

    /// Day `day` in the cell's zone, from its midnight to the next (23 or 25 h on the days
    /// the clocks change).
    pub fn day(&self, day: Date) -> Option<(Timestamp, Timestamp)> {
        let start = |d: Date| -> Option<Timestamp> {
            let zoned = d.to_zoned(self.zone.clone()).ok()?;
            Some(Timestamp(zoned.timestamp().as_millisecond()))
        };
        Some((start(day)?, start(day.tomorrow().ok()?)?))
    }

    /// The shifts that overlap `[from, to)`, in time order.
    pub fn windows(&self, from: Timestamp, to: Timestamp) -> Vec<ShiftWindow> {
        let mut out = Vec::new();
        let Some(mut day) = self.day_of(from).yesterday().ok() else {
            return out;
        };
        let last = self.day_of(to);
        while day <= last {
            for shift in &self.shifts {
                if let Some(w) = self.window(shift, day)
                    && w.end > from
                    && w.start < to
                {
                    out.push(w);
                }
            }
            let Ok(next) = day.tomorrow() else { break };
            day = next;
        }
        out.sort_by_key(|w| w.start);
        out
    }

    /// `shift` on `day`, if it starts on that weekday.
    fn window(&self, shift: &Shift, day: Date) -> Option<ShiftWindow> {
        if !shift.days.contains(&day.weekday()) {
            return None;
        }
        let at = |time: Time| -> Option<Timestamp> {
            let start_day = if time <= shift.start && shift.end <= shift.start {
                // The shift crossed midnight: a time at or before its start is tomorrow.
                if time == shift.start {
                    day
                } else {
                    day.tomorrow().ok()?
                }
            } else {
                day
            };
            let zoned = start_day
                .to_datetime(time)
                .to_zoned(self.zone.clone())
                .ok()?;
            Some(Timestamp(zoned.timestamp().as_millisecond()))
        };
        let start = at(shift.start)?;
        let end = if shift.end <= shift.start {
            let zoned = day
                .tomorrow()
                .ok()?
                .to_datetime(shift.end)
                .to_zoned(self.zone.clone())
                .ok()?;
            Timestamp(zoned.timestamp().as_millisecond())
        } else {
            at(shift.end)?
        };
        let breaks = shift
            .breaks
            .iter()
            .filter_map(|(b, e)| Some((at(*b)?, at(*e)?)))
            .filter(|(b, e)| b < e)
            .collect();
        Some(ShiftWindow {
            name: shift.name.clone(),
            day,
            start,
            end,
            breaks,
        })
    }

    /// The shift `t` falls in, if any.
    pub fn at(&self, t: Timestamp) -> Option<ShiftWindow> {
        self.windows(t, Timestamp(t.0 + 1))
            .into_iter()
            .find(|w| w.start <= t && t < w.end)
    }

    /// Shift `name` that starts on `day`, if it works that day.
    pub fn on(&self, name: &str, day: Date) -> Option<ShiftWindow> {
        let shift = self.shifts.iter().find(|s| s.name == name)?;
        self.window(shift, day)
    }

    /// The planned production time in `[from, to)`: the shifts less their breaks, as
    /// ordered, disjoint stretches; and the breaks, likewise.
    pub fn planned(&self, from: Timestamp, to: Timestamp) -> Planned {
        let mut work = Vec::new();
        let mut breaks = Vec::new();
        for w in self.windows(from, to) {
            let mut pieces = vec![(w.start.max(from), w.end.min(to))];
            for (b, e) in &w.breaks {
                let (b, e) = ((*b).max(from), (*e).min(to));
                if b < e {
                    breaks.push((b, e));
                }
                pieces = pieces
                    .into_iter()
                    .flat_map(|(s, t)| cut(s, t, b, e))
                    .collect();
            }
            work.extend(pieces.into_iter().filter(|(s, t)| s < t));
        }
        Planned {
            work: merge(work),
            breaks: merge(breaks),
        }
    }
}

/// When production is planned, and the planned breaks.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Planned {
    /// The stretches of planned production, ordered and disjoint.
    pub work: Vec<(Timestamp, Timestamp)>,
    /// The planned breaks, ordered and disjoint.
    pub breaks: Vec<(Timestamp, Timestamp)>,
}

impl Planned {
    /// The planned production time, in milliseconds.
    pub fn millis(&self) -> i64 {
        self.work.iter().map(|(s, e)| e.0 - s.0).sum()
    }
}

/// `[s, t)` less `[b, e)`: none, one or two pieces.
fn cut(s: Timestamp, t: Timestamp, b: Timestamp, e: Timestamp) -> Vec<(Timestamp, Timestamp)> {
    if e <= s || b >= t {
        return vec![(s, t)];
    }
    [(s, b.min(t)), (e.max(s), t)]
        .into_iter()
        .filter(|(x, y)| x < y)
        .collect()
}

/// Ordered, disjoint stretches covering the same time as `spans`.
fn merge(mut spans: Vec<(Timestamp, Timestamp)>) -> Vec<(Timestamp, Timestamp)> {
    spans.sort();
    let mut out: Vec<(Timestamp, Timestamp)> = Vec::new();
    for (s, e) in spans {
        match out.last_mut() {
            Some(last) if s <= last.1 => last.1 = last.1.max(e),
            _ => out.push((s, e)),
        }
    }
    out
}

fn to_jiff(t: Timestamp) -> jiff::Timestamp {
    jiff::Timestamp::from_millisecond(t.0).unwrap_or(jiff::Timestamp::UNIX_EPOCH)
}

/// The weekdays' names, Monday first, as [`EVERY_DAY`] orders them.
const DAY_NAMES: [&str; 7] = [
    "monday",
    "tuesday",
    "wednesday",
    "thursday",
    "friday",
    "saturday",
    "sunday",
];

/// Reads a weekday as the config writes it (`mon`, `monday`).
pub fn weekday(text: &str) -> Option<Weekday> {
    let t = text.to_ascii_lowercase();
    DAY_NAMES
        .iter()
        .zip(EVERY_DAY)
        .find(|(name, _)| t.len() >= 3 && name.starts_with(&t))
        .map(|(_, day)| day)
}

/// Reads a wall-clock time (`06:00`, `22:30`, `24:00` for the end of the day).
pub fn clock(text: &str) -> Option<Time> {
    if text == "24:00" {
        return Some(Time::midnight());
    }
    let (h, m) = text.split_once(':')?;
    if h.len() > 2 || m.len() != 2 {
        return None;
    }
    Time::new(h.parse().ok()?, m.parse().ok()?, 0, 0).ok()
}

impl fmt::Display for Shift {
    /// `early: mon, tue, wed, thu, fri 06:00–14:00, 2 breaks`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let days = if self.days.len() == 7 {
            "every day".to_owned()
        } else {
            self.days
                .iter()
                .map(|d| &DAY_NAMES[d.to_monday_zero_offset() as usize][..3])
                .collect::<Vec<_>>()
                .join(", ")
        };
        write!(
            f,
            "{}: {days} {}–{}",
            self.name,
            self.start.strftime("%H:%M"),
            self.end.strftime("%H:%M")
        )?;
        match self.breaks.len() {
            0 => Ok(()),
            1 => f.write_str(", 1 break"),
            n => write!(f, ", {n} breaks"),
        }
    }
}

impl fmt::Display for ShiftWindow {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} on {}", self.name, self.day)
    }
}

#[cfg(test)]
mod tests;
