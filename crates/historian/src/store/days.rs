//! Days in UTC: which day partition of `samples` holds a time, its name and its bounds.

use std::time::{SystemTime, UNIX_EPOCH};

use wire::calendar::civil_date;

const SECONDS_PER_DAY: i64 = 86_400;

/// Milliseconds since the epoch (negative before it; saturating far away).
pub fn epoch_millis(t: SystemTime) -> i64 {
    match t.duration_since(UNIX_EPOCH) {
        Ok(after) => i64::try_from(after.as_millis()).unwrap_or(i64::MAX),
        Err(before) => i64::try_from(before.duration().as_millis()).map_or(i64::MIN, |ms| -ms),
    }
}

/// The UTC day of `t`, counted from 1970-01-01 (day 0; negative before).
pub fn day_of(t: SystemTime) -> i64 {
    epoch_millis(t).div_euclid(SECONDS_PER_DAY * 1000)
}

/// The name of the partition of `samples` that holds `day`: `samples_2026_01_31`.
pub fn partition_name(day: i64) -> String {
    let (y, m, d) = civil_date(day);
    format!("samples_{y:04}_{m:02}_{d:02}")
}

/// The SQL literal of the instant `day` starts: `'2026-01-31 00:00:00+00'`.
pub fn day_start_literal(day: i64) -> String {
    let (y, m, d) = civil_date(day);
    format!("'{y:04}-{m:02}-{d:02} 00:00:00+00'")
}

/// The statement that creates the partition of `day` unless it exists.
pub fn create_partition_sql(day: i64) -> String {
    format!(
        "CREATE TABLE IF NOT EXISTS {} PARTITION OF samples FOR VALUES FROM ({}) TO ({})",
        partition_name(day),
        day_start_literal(day),
        day_start_literal(day + 1)
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn at(ms: i64) -> SystemTime {
        if ms >= 0 {
            UNIX_EPOCH + Duration::from_millis(ms.unsigned_abs())
        } else {
            UNIX_EPOCH - Duration::from_millis(ms.unsigned_abs())
        }
    }

    #[test]
    fn days_are_counted_in_utc_from_1970() {
        assert_eq!(day_of(at(0)), 0);
        assert_eq!(day_of(at(86_399_999)), 0);
        assert_eq!(day_of(at(86_400_000)), 1);
        assert_eq!(day_of(at(-1)), -1);
    }

    #[test]
    fn a_partition_covers_its_day_up_to_the_next_midnight() {
        assert_eq!(partition_name(19_782), "samples_2024_02_29");
        assert_eq!(
            create_partition_sql(19_782),
            "CREATE TABLE IF NOT EXISTS samples_2024_02_29 PARTITION OF samples FOR VALUES \
             FROM ('2024-02-29 00:00:00+00') TO ('2024-03-01 00:00:00+00')"
        );
    }

    #[test]
    fn milliseconds_are_negative_before_the_epoch() {
        assert_eq!(epoch_millis(at(-1500)), -1500);
        assert_eq!(epoch_millis(at(1_700_000_000_123)), 1_700_000_000_123);
    }
}
