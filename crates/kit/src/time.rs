//! Wall-clock timestamps as the history and the API carry them.
//!
//! A [`Timestamp`] is milliseconds since the Unix epoch (UTC): what SQLite stores and sorts,
//! what the API prints as RFC 3339 (`2026-11-03T08:15:02.125Z`). Query parameters accept RFC
//! 3339 (`Z` or an offset such as `+01:00`), `now`, or a time relative to now (`-1h`,
//! `-15m`, `-2d`), so a person can type them in a browser's address bar. A time given that
//! way must fall in the years 1970 to 9999 ([`Timestamp::MIN`] to [`Timestamp::MAX`]), the
//! range RFC 3339 printing covers.

use std::fmt;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use serde::{Serialize, Serializer};

/// Milliseconds since 1970-01-01T00:00:00Z.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Timestamp(pub i64);

impl Timestamp {
    /// The earliest time a query may name: 1970-01-01T00:00:00.000Z.
    pub const MIN: Timestamp = Timestamp(0);
    /// The latest time a query may name: 9999-12-31T23:59:59.999Z.
    pub const MAX: Timestamp = Timestamp(253_402_300_799_999);

    /// The current wall-clock time.
    pub fn now() -> Self {
        Self::from_system(SystemTime::now())
    }

    /// A system time as a timestamp (times before 1970 count negative).
    pub fn from_system(time: SystemTime) -> Self {
        match time.duration_since(UNIX_EPOCH) {
            Ok(after) => Self(i64::try_from(after.as_millis()).unwrap_or(i64::MAX)),
            Err(before) => Self(-i64::try_from(before.duration().as_millis()).unwrap_or(i64::MAX)),
        }
    }

    /// The timestamp as a system time.
    pub fn to_system(self) -> SystemTime {
        let millis = Duration::from_millis(self.0.unsigned_abs());
        if self.0 >= 0 {
            UNIX_EPOCH + millis
        } else {
            UNIX_EPOCH - millis
        }
    }

    /// Milliseconds since the epoch.
    pub fn millis(self) -> i64 {
        self.0
    }

    /// This time plus `d` (saturating).
    pub fn plus(self, d: Duration) -> Self {
        Self(self.0.saturating_add(duration_millis(d)))
    }

    /// This time minus `d` (saturating).
    pub fn minus(self, d: Duration) -> Self {
        Self(self.0.saturating_sub(duration_millis(d)))
    }

    /// Parses a time given by a person or a program, relative to `now`: RFC 3339, `now`, or
    /// `-<duration>` such as `-1h`, `-90s`, `-2d`. A time before 1970 or after 9999 is
    /// refused, whichever way it was written.
    pub fn parse_relative(text: &str, now: Timestamp) -> Result<Self, TimeError> {
        let text = text.trim();
        let time = if text.eq_ignore_ascii_case("now") {
            now
        } else if let Some(ago) = text.strip_prefix('-') {
            let d = humantime::parse_duration(ago.trim()).map_err(|e| TimeError::Malformed {
                text: text.to_owned(),
                reason: e.to_string(),
            })?;
            now.minus(d)
        } else {
            parse_rfc3339(text)?
        };
        if time < Self::MIN {
            return Err(TimeError::BeforeEpoch {
                text: text.to_owned(),
            });
        }
        if time > Self::MAX {
            return Err(TimeError::AfterYear9999 {
                text: text.to_owned(),
            });
        }
        Ok(time)
    }

    /// Whether RFC 3339 can print this time: the years 1970 to 9999.
    pub fn is_printable(self) -> bool {
        (Self::MIN..=Self::MAX).contains(&self)
    }

    /// RFC 3339 in UTC with milliseconds (`2026-11-03T08:15:02.125Z`), if printable: what
    /// [`Display`](fmt::Display) prints, without a formatter (device listings print tens
    /// of thousands of times).
    pub fn rfc3339_millis(self) -> Option<[u8; 24]> {
        if !self.is_printable() {
            return None;
        }
        let (days, ms_of_day) = (self.0.div_euclid(86_400_000), self.0.rem_euclid(86_400_000));
        let (year, month, day) = wire::calendar::civil_date(days);
        let mut text = *b"0000-00-00T00:00:00.000Z";
        let mut digits = |at: usize, width: usize, mut n: i64| {
            for i in (at..at + width).rev() {
                text[i] = b'0' + (n % 10) as u8;
                n /= 10;
            }
        };
        digits(0, 4, year);
        digits(5, 2, i64::from(month));
        digits(8, 2, i64::from(day));
        digits(11, 2, ms_of_day / 3_600_000);
        digits(14, 2, ms_of_day / 60_000 % 60);
        digits(17, 2, ms_of_day / 1000 % 60);
        digits(20, 3, ms_of_day % 1000);
        Some(text)
    }
}

impl fmt::Display for Timestamp {
    /// RFC 3339 in UTC with milliseconds. A time outside the years 1970 to 9999, which no
    /// query can name but arithmetic can reach, prints as its milliseconds from the epoch
    /// (`-3600000 ms from 1970-01-01T00:00:00Z`) instead of panicking in the formatter.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(text) = self.rfc3339_millis() {
            f.write_str(std::str::from_utf8(&text).map_err(|_| fmt::Error)?)
        } else {
            write!(f, "{} ms from 1970-01-01T00:00:00Z", self.0)
        }
    }
}

impl Serialize for Timestamp {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

/// A time the gateway could not read, or one outside the years it serves.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TimeError {
    /// The text is not a time in any accepted form.
    #[error(
        "{text:?} is not a time ({reason}); write RFC 3339 like 2026-11-03T08:00:00Z, `now`, or a time relative to now like -1h or -15m"
    )]
    Malformed {
        /// The text given.
        text: String,
        /// What is wrong with it.
        reason: String,
    },
    /// The time is before 1970-01-01T00:00:00Z.
    #[error("{text} is before 1970-01-01")]
    BeforeEpoch {
        /// The text given.
        text: String,
    },
    /// The time is after 9999-12-31T23:59:59.999Z.
    #[error("{text} is after 9999-12-31")]
    AfterYear9999 {
        /// The text given.
        text: String,
    },
}

impl TimeError {
    /// The text given.
    pub fn text(&self) -> &str {
        match self {
            TimeError::Malformed { text, .. }
            | TimeError::BeforeEpoch { text }
            | TimeError::AfterYear9999 { text } => text,
        }
    }
}

/// Milliseconds in `d`, saturating.
pub fn duration_millis(d: Duration) -> i64 {
    i64::try_from(d.as_millis()).unwrap_or(i64::MAX)
}

/// Parses RFC 3339 with `Z` or a numeric offset (`+01:00`, `-05:30`; hours 00 to 23,
/// minutes 00 to 59); `t` and `z` may be lower case, as RFC 3339 allows.
fn parse_rfc3339(text: &str) -> Result<Timestamp, TimeError> {
    let err = |reason: &str| TimeError::Malformed {
        text: text.to_owned(),
        reason: reason.to_owned(),
    };
    let upper = text.to_ascii_uppercase();
    // Split a trailing ±HH:MM offset from the local time; humantime reads UTC only.
    let split = upper.len().checked_sub(6).and_then(|at| {
        let (head, tail) = (upper.get(..at)?, upper.get(at..)?);
        let bytes = tail.as_bytes();
        let sign = match bytes.first()? {
            b'+' => 1,
            b'-' => -1,
            _ => return None,
        };
        (bytes.get(3) == Some(&b':') && head.contains('T')).then_some(())?;
        let hours: i64 = tail.get(1..3)?.parse().ok()?;
        let minutes: i64 = tail.get(4..6)?.parse().ok()?;
        Some((head.to_owned() + "Z", tail, sign, hours, minutes))
    });
    let (local, offset_minutes) = match split {
        Some((_, tail, _, hours, minutes)) if hours > 23 || minutes > 59 => {
            return Err(err(&format!(
                "the offset {tail} is not one: hours go from 00 to 23, minutes from 00 to 59"
            )));
        }
        Some((local, _, sign, hours, minutes)) => (local, sign * (hours * 60 + minutes)),
        None => (upper.clone(), 0),
    };
    let time = humantime::parse_rfc3339_weak(&local).map_err(|e| err(&e.to_string()))?;
    let utc = Timestamp::from_system(time);
    Ok(Timestamp(utc.0.saturating_sub(offset_minutes * 60_000)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timestamps_print_as_rfc3339_utc_with_milliseconds() {
        assert_eq!(Timestamp(0).to_string(), "1970-01-01T00:00:00.000Z");
        assert_eq!(
            Timestamp(1_700_000_000_125).to_string(),
            "2023-11-14T22:13:20.125Z"
        );
    }

    #[test]
    fn the_fast_rfc3339_printer_agrees_with_humantime_from_1970_to_9999() {
        let humantime = |t: Timestamp| {
            humantime::format_rfc3339_millis(t.to_system())
                .to_string()
                .into_bytes()
        };
        // Ends of the range, leap days (2000 is a leap year, 2100 is not) and year ends.
        let mut times = vec![
            Timestamp::MIN,
            Timestamp::MAX,
            Timestamp(951_782_400_000),
            Timestamp(951_868_799_999),
            Timestamp(4_107_542_400_000),
            Timestamp(4_102_444_799_999),
            Timestamp(68_169_600_000),
        ];
        let mut rng = fastrand::Rng::with_seed(15);
        times.extend((0..200_000).map(|_| Timestamp(rng.i64(0..=Timestamp::MAX.0))));
        for t in times {
            let fast = t.rfc3339_millis().expect("printable");
            assert_eq!(fast.to_vec(), humantime(t), "{}", t.0);
        }
        assert_eq!(Timestamp(-1).rfc3339_millis(), None);
        assert_eq!(Timestamp(Timestamp::MAX.0 + 1).rfc3339_millis(), None);
    }

    #[test]
    fn an_offset_out_of_range_is_refused_and_lower_case_t_and_z_are_read() {
        let now = Timestamp(0);
        for text in ["2023-11-14T23:13:20+99:99", "2023-11-14T23:13:20+01:60"] {
            let e = Timestamp::parse_relative(text, now).unwrap_err();
            assert!(
                e.to_string().contains("is not one: hours go from 00 to 23"),
                "{e}"
            );
        }
        assert_eq!(
            Timestamp::parse_relative("2023-11-14t22:13:20z", now).unwrap(),
            Timestamp(1_700_000_000_000)
        );
        assert_eq!(
            Timestamp::parse_relative("2023-11-14t23:13:20+01:00", now).unwrap(),
            Timestamp(1_700_000_000_000)
        );
    }

    #[test]
    fn rfc3339_with_z_or_an_offset_gives_the_same_instant() {
        let now = Timestamp(0);
        let z = Timestamp::parse_relative("2023-11-14T22:13:20Z", now).unwrap();
        let plus = Timestamp::parse_relative("2023-11-14T23:13:20+01:00", now).unwrap();
        let minus = Timestamp::parse_relative("2023-11-14T16:43:20-05:30", now).unwrap();
        assert_eq!(z, Timestamp(1_700_000_000_000));
        assert_eq!(plus, z);
        assert_eq!(minus, z);
    }

    #[test]
    fn relative_times_count_back_from_now() {
        let now = Timestamp(10_000_000);
        assert_eq!(
            Timestamp::parse_relative("-1h", now).unwrap(),
            Timestamp(10_000_000 - 3_600_000)
        );
        assert_eq!(
            Timestamp::parse_relative("-90s", now).unwrap(),
            Timestamp(10_000_000 - 90_000)
        );
        assert_eq!(Timestamp::parse_relative("now", now).unwrap(), now);
    }

    #[test]
    fn a_bad_time_names_the_text_and_the_accepted_forms() {
        let err = Timestamp::parse_relative("yesterday", Timestamp(0)).unwrap_err();
        assert_eq!(err.text(), "yesterday");
        assert!(err.to_string().contains("-1h"), "{err}");
        assert!(Timestamp::parse_relative("-1 fortnight", Timestamp(0)).is_err());
    }

    #[test]
    fn a_relative_time_before_1970_is_refused_not_a_panic() {
        let now = Timestamp(1_793_692_800_000);
        let err = Timestamp::parse_relative("-100000d", now).unwrap_err();
        assert_eq!(
            err,
            TimeError::BeforeEpoch {
                text: "-100000d".into()
            }
        );
        assert_eq!(err.to_string(), "-100000d is before 1970-01-01");
        assert!(Timestamp::parse_relative("-1ms", Timestamp::MIN).is_err());
        assert_eq!(
            Timestamp::parse_relative("-0s", Timestamp::MIN),
            Ok(Timestamp::MIN)
        );
    }

    #[test]
    fn an_offset_cannot_carry_a_time_outside_1970_to_9999() {
        let now = Timestamp(0);
        assert!(matches!(
            Timestamp::parse_relative("1970-01-01T00:00:00+00:01", now),
            Err(TimeError::BeforeEpoch { .. })
        ));
        assert!(matches!(
            Timestamp::parse_relative("9999-12-31T23:59:59-00:01", now),
            Err(TimeError::AfterYear9999 { .. })
        ));
        assert_eq!(
            Timestamp::parse_relative("9999-12-31T23:59:59.999Z", now),
            Ok(Timestamp::MAX)
        );
        assert_eq!(
            Timestamp::parse_relative("1970-01-01T01:00:00+01:00", now),
            Ok(Timestamp::MIN)
        );
    }

    #[test]
    fn a_timestamp_outside_1970_to_9999_prints_as_milliseconds_instead_of_panicking() {
        assert_eq!(
            Timestamp(-3_600_000).to_string(),
            "-3600000 ms from 1970-01-01T00:00:00Z"
        );
        assert_eq!(Timestamp::MAX.to_string(), "9999-12-31T23:59:59.999Z");
        assert_eq!(
            Timestamp(i64::MAX).to_string(),
            format!("{} ms from 1970-01-01T00:00:00Z", i64::MAX)
        );
    }

    #[test]
    fn system_time_round_trips_through_timestamps() {
        for millis in [0, 1, 1_700_000_000_125, -5_000] {
            let t = Timestamp(millis);
            assert_eq!(Timestamp::from_system(t.to_system()), t);
        }
    }
}
