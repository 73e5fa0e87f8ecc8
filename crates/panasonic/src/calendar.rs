//! Calendar values as the machine writes them: `yy/mm/dd` in the program list (3.3-10) and
//! `yyyy/mm/dd hh/mm/ss` in production management data (3.3-9).
//!
//! The machine has a calendar clock; the twin has only the `Instant`s it is given, so it
//! keeps a [`Timestamp`] for its first instant and adds elapsed seconds
//! ([`Timestamp::plus_seconds`]). Two-digit years are read as 2000–2099 \[I\].

use std::fmt;

use serde::Serialize;

/// A calendar value out of range.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{what} {value} is out of range {min}..={max}")]
pub struct CalendarError {
    /// Which part: "year", "month", "day", "hour", "minute", "second".
    pub what: &'static str,
    /// The value given.
    pub value: u32,
    /// Lowest allowed.
    pub min: u32,
    /// Highest allowed (for a day: the length of that month).
    pub max: u32,
}

/// Text that is not a date or a timestamp.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum CalendarParseError {
    /// Not the expected layout.
    #[error("{text:?} is not a {layout} value")]
    Layout {
        /// The text.
        text: String,
        /// The layout expected.
        layout: &'static str,
    },
    /// The layout is right but a part is out of range.
    #[error(transparent)]
    Range(#[from] CalendarError),
}

/// A date as the program list carries it: `yy/mm/dd`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
pub struct ProgramDate {
    year: u8,
    month: u8,
    day: u8,
}

/// Width of a [`ProgramDate`] on the wire (`yy/mm/dd`).
pub const PROGRAM_DATE_LEN: usize = 8;

impl ProgramDate {
    /// A date; `year` is two digits (0–99, meaning 2000–2099).
    pub fn new(year: u8, month: u8, day: u8) -> Result<ProgramDate, CalendarError> {
        check("year", year.into(), 0, 99)?;
        check_date(2000 + u32::from(year), month, day)?;
        Ok(ProgramDate { year, month, day })
    }

    /// The two-digit year.
    pub fn year(self) -> u8 {
        self.year
    }

    /// The year in full (2000–2099).
    pub fn full_year(self) -> u16 {
        2000 + u16::from(self.year)
    }

    /// Month, 1–12.
    pub fn month(self) -> u8 {
        self.month
    }

    /// Day of the month.
    pub fn day(self) -> u8 {
        self.day
    }

    /// Appends `yy/mm/dd`.
    pub fn write(self, out: &mut Vec<u8>) {
        out.extend_from_slice(self.to_string().as_bytes());
    }

    /// Reads `yy/mm/dd`.
    pub fn parse(text: &[u8]) -> Result<ProgramDate, CalendarParseError> {
        let layout = || layout_error(text, "yy/mm/dd date");
        let [y0, y1, b'/', m0, m1, b'/', d0, d1] = *text else {
            return Err(layout());
        };
        let number = |a: u8, b: u8| two_digits(a, b).ok_or_else(layout);
        Ok(ProgramDate::new(
            number(y0, y1)?,
            number(m0, m1)?,
            number(d0, d1)?,
        )?)
    }
}

impl fmt::Display for ProgramDate {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:02}/{:02}/{:02}", self.year, self.month, self.day)
    }
}

/// A moment as production management data carries it: `yyyy/mm/dd hh/mm/ss`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
pub struct Timestamp {
    year: u16,
    month: u8,
    day: u8,
    hour: u8,
    minute: u8,
    second: u8,
}

impl Timestamp {
    /// A moment; the year is 1970–9999.
    pub fn new(
        year: u16,
        month: u8,
        day: u8,
        hour: u8,
        minute: u8,
        second: u8,
    ) -> Result<Timestamp, CalendarError> {
        check("year", year.into(), 1970, 9999)?;
        check_date(year.into(), month, day)?;
        check("hour", hour.into(), 0, 23)?;
        check("minute", minute.into(), 0, 59)?;
        check("second", second.into(), 0, 59)?;
        Ok(Timestamp {
            year,
            month,
            day,
            hour,
            minute,
            second,
        })
    }

    /// The year.
    pub fn year(self) -> u16 {
        self.year
    }

    /// The date part as the program list writes it (two-digit year).
    pub fn date(self) -> ProgramDate {
        ProgramDate {
            year: (self.year % 100) as u8,
            month: self.month,
            day: self.day,
        }
    }

    /// This moment plus `seconds` (saturating at 9999-12-31 23:59:59).
    pub fn plus_seconds(self, seconds: u64) -> Timestamp {
        let start = days_from_civil(self.year.into(), self.month.into(), self.day.into()) * 86_400
            + i64::from(self.hour) * 3600
            + i64::from(self.minute) * 60
            + i64::from(self.second);
        let last = days_from_civil(9999, 12, 31) * 86_400 + 86_399;
        let total = start
            .saturating_add(i64::try_from(seconds).unwrap_or(i64::MAX))
            .min(last);
        let (days, rest) = (total.div_euclid(86_400), total.rem_euclid(86_400));
        let (year, month, day) = wire::calendar::civil_date(days);
        Timestamp {
            year: year as u16,
            month: month as u8,
            day: day as u8,
            hour: (rest / 3600) as u8,
            minute: (rest % 3600 / 60) as u8,
            second: (rest % 60) as u8,
        }
    }

    /// Appends `yyyy/mm/dd hh/mm/ss`.
    pub fn write(self, out: &mut Vec<u8>) {
        out.extend_from_slice(self.to_string().as_bytes());
    }

    /// Reads `yyyy/mm/dd hh/mm/ss`; `hh:mm:ss` is accepted for the time too \[I\].
    pub fn parse(text: &[u8]) -> Result<Timestamp, CalendarParseError> {
        let layout = || layout_error(text, "yyyy/mm/dd hh/mm/ss timestamp");
        let [
            y0,
            y1,
            y2,
            y3,
            b'/',
            mo0,
            mo1,
            b'/',
            d0,
            d1,
            b' ',
            h0,
            h1,
            s1,
            mi0,
            mi1,
            s2,
            se0,
            se1,
        ] = *text
        else {
            return Err(layout());
        };
        if !matches!((s1, s2), (b'/', b'/') | (b':', b':')) {
            return Err(layout());
        }
        let number = |a: u8, b: u8| two_digits(a, b).ok_or_else(layout);
        let year = u16::from(number(y0, y1)?) * 100 + u16::from(number(y2, y3)?);
        Ok(Timestamp::new(
            year,
            number(mo0, mo1)?,
            number(d0, d1)?,
            number(h0, h1)?,
            number(mi0, mi1)?,
            number(se0, se1)?,
        )?)
    }
}

impl fmt::Display for Timestamp {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{:04}/{:02}/{:02} {:02}/{:02}/{:02}",
            self.year, self.month, self.day, self.hour, self.minute, self.second
        )
    }
}

fn check(what: &'static str, value: u32, min: u32, max: u32) -> Result<(), CalendarError> {
    if (min..=max).contains(&value) {
        Ok(())
    } else {
        Err(CalendarError {
            what,
            value,
            min,
            max,
        })
    }
}

/// Checks the month and the day of a date in the year `full_year`.
fn check_date(full_year: u32, month: u8, day: u8) -> Result<(), CalendarError> {
    check("month", month.into(), 1, 12)?;
    check("day", day.into(), 1, days_in_month(full_year, month.into()))
}

/// `text` is not a `layout` value.
fn layout_error(text: &[u8], layout: &'static str) -> CalendarParseError {
    CalendarParseError::Layout {
        text: String::from_utf8_lossy(text).into_owned(),
        layout,
    }
}

fn two_digits(a: u8, b: u8) -> Option<u8> {
    (a.is_ascii_digit() && b.is_ascii_digit()).then(|| (a - b'0') * 10 + (b - b'0'))
}

fn is_leap(year: u32) -> bool {
    year.is_multiple_of(4) && (!year.is_multiple_of(100) || year.is_multiple_of(400))
}

fn days_in_month(year: u32, month: u32) -> u32 {
    match month {
        2 if is_leap(year) => 29,
        2 => 28,
        4 | 6 | 9 | 11 => 30,
        _ => 31,
    }
}

/// Days since 1970-01-01 of a proleptic Gregorian date (H. Hinnant's algorithm).
fn days_from_civil(year: i64, month: i64, day: i64) -> i64 {
    let y = if month <= 2 { year - 1 } else { year };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (month + 9) % 12;
    let doy = (153 * mp + 2) / 5 + day - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn program_date_reads_the_manual_example() {
        // 3.3-10: the program list example starts "03/01/30PABC…".
        let date = ProgramDate::parse(b"03/01/30").expect("valid date");
        assert_eq!((date.full_year(), date.month(), date.day()), (2003, 1, 30));
        assert_eq!(date.to_string(), "03/01/30");
    }

    #[test]
    fn program_date_refuses_impossible_days() {
        assert_eq!(
            ProgramDate::new(3, 2, 29),
            Err(CalendarError {
                what: "day",
                value: 29,
                min: 1,
                max: 28
            })
        );
        assert!(ProgramDate::new(4, 2, 29).is_ok());
        assert!(matches!(
            ProgramDate::parse(b"03/13/01"),
            Err(CalendarParseError::Range(_))
        ));
        for text in ["03-01-30", "3/1/30"] {
            assert_eq!(
                ProgramDate::parse(text.as_bytes()),
                Err(CalendarParseError::Layout {
                    text: text.into(),
                    layout: "yy/mm/dd date"
                })
            );
        }
    }

    #[test]
    fn timestamp_reads_both_time_separators_and_writes_slashes() {
        let slash = Timestamp::parse(b"2003/01/30 08/15/00").expect("manual layout");
        let colon = Timestamp::parse(b"2003/01/30 08:15:00").expect("colon layout");
        assert_eq!(slash, colon);
        assert_eq!(colon.to_string(), "2003/01/30 08/15/00");
        assert!(Timestamp::parse(b"2003/01/30 08/15:00").is_err());
        assert!(Timestamp::parse(b"2003/01/30 24/00/00").is_err());
    }

    #[test]
    fn timestamp_adds_seconds_across_month_year_and_leap_day() {
        let t = Timestamp::new(2023, 12, 31, 23, 59, 30).expect("valid");
        assert_eq!(t.plus_seconds(30).to_string(), "2024/01/01 00/00/00");
        let leap = Timestamp::new(2024, 2, 28, 12, 0, 0).expect("valid");
        assert_eq!(leap.plus_seconds(86_400).to_string(), "2024/02/29 12/00/00");
        assert_eq!(
            leap.plus_seconds(u64::MAX).to_string(),
            "9999/12/31 23/59/59"
        );
    }

    proptest! {
        #[test]
        fn timestamps_round_trip_and_advance_consistently(days in 0u64..40_000, secs in 0u64..86_400) {
            let base = Timestamp::new(1970, 1, 1, 0, 0, 0).expect("epoch");
            let t = base.plus_seconds(days * 86_400 + secs);
            let mut text = Vec::new();
            t.write(&mut text);
            prop_assert_eq!(Timestamp::parse(&text), Ok(t));
            prop_assert_eq!(t.plus_seconds(86_400).plus_seconds(0), base.plus_seconds((days + 1) * 86_400 + secs));
            let date = t.date();
            prop_assert_eq!(ProgramDate::parse(date.to_string().as_bytes()), Ok(date));
        }
    }
}
