//! Per-minute rollups: the count, exact sum, minimum and maximum of every point's good
//! numeric samples in each minute, kept in the `minutes` table as the samples arrive, so a
//! bucketed query whose step is a whole number of minutes reads one row per minute instead
//! of every sample.
//!
//! The rollups are exact, not an approximation: a bucket built from them equals the one
//! built from the raw samples, bit for bit. Count, minimum and maximum combine exactly by
//! nature; the sum is kept as an [`ExactSum`] (the non-overlapping partial sums of Python's
//! `math.fsum`), so the mean is the correctly rounded sum divided by the count, whatever
//! the order the samples arrived in and however they were split between batches and
//! minutes. The raw path computes its means the same way.
//!
//! Which samples are rolled up is fixed by two marks in `rollup_marks`, committed with the
//! rows they describe:
//! - `since`: rollups are complete from this minute on. A new file starts at 0; a file
//!   from before the rollups starts at the first minute after its newest sample (older
//!   minutes are served from the raw samples until retention removes them); retention
//!   raises it to the first whole minute it keeps.
//! - `until`: minutes before it are in the table; minutes from it on are still open and
//!   held by the writer in memory ([`OpenMinutes`]), to be written once when they close
//!   (one row per point and minute, not one per batch). After a `kill -9` the open minutes
//!   are rebuilt from the samples committed from `until` on, which are exactly the ones not
//!   yet in the table. A sample that arrives for a closed minute (a late reading) is merged
//!   into its row in the same transaction.

use std::collections::BTreeMap;

use rusqlite::{Connection, OptionalExtension, Transaction, params};
use smallvec::SmallVec;

use crate::point::{Quality, Value};

/// One minute in milliseconds: the rollups' granularity.
pub(super) const MINUTE_MS: i64 = 60_000;

/// How far behind the newest sample (or the clock, if that is earlier) a minute closes:
/// samples up to a minute late still find their minute open.
const CLOSE_AFTER_MS: i64 = MINUTE_MS;

/// The exact sum of finite numbers, as non-overlapping partial sums in increasing
/// magnitude (Shewchuk's algorithm, as in Python's `math.fsum`); [`ExactSum::total`] is the
/// correctly rounded sum. Infinities (and their NaN) are summed apart and win.
///
/// The partials are held inline up to two (a minute's sum rarely needs more): an open
/// minute of every point is held in memory, and a heap block each was a tenth of the
/// gateway's heap with 100,000 points.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ExactSum {
    partials: SmallVec<[f64; 2]>,
    /// The plain sum of non-finite inputs (and of an overflow); 0 when there were none.
    special: f64,
}

impl ExactSum {
    /// Adds `x` exactly.
    pub fn add(&mut self, x: f64) {
        if !x.is_finite() {
            self.special += x;
            return;
        }
        let mut x = x;
        let mut kept = 0;
        for j in 0..self.partials.len() {
            let mut y = self.partials[j];
            if x.abs() < y.abs() {
                std::mem::swap(&mut x, &mut y);
            }
            let hi = x + y;
            let lo = y - (hi - x);
            if lo != 0.0 {
                self.partials[kept] = lo;
                kept += 1;
            }
            x = hi;
        }
        self.partials.truncate(kept);
        if x.is_finite() {
            self.partials.push(x);
        } else {
            // The partial sums left the range of f64: the total is that infinity.
            self.special += x;
            self.partials.clear();
        }
    }

    /// Adds every number `other` holds.
    pub fn merge(&mut self, other: &ExactSum) {
        for &p in &other.partials {
            self.add(p);
        }
        self.special += other.special;
    }

    /// The sum, correctly rounded to the nearest f64 (ties to even).
    pub fn total(&self) -> f64 {
        if self.special != 0.0 || self.special.is_nan() {
            return self.special;
        }
        let p = &self.partials;
        let Some(&top) = p.last() else {
            return 0.0;
        };
        let mut n = p.len() - 1;
        let (mut hi, mut lo) = (top, 0.0);
        while n > 0 {
            n -= 1;
            let (x, y) = (hi, p[n]);
            hi = x + y;
            lo = y - (hi - x);
            if lo != 0.0 {
                break;
            }
        }
        // Round half to even when the rest below `lo` pushes past the halfway point.
        if n > 0 && ((lo < 0.0 && p[n - 1] < 0.0) || (lo > 0.0 && p[n - 1] > 0.0)) {
            let y = lo * 2.0;
            let x = hi + y;
            if y == x - hi {
                hi = x;
            }
        }
        hi
    }

    /// The stored form: the partials as little-endian f64s, or the non-finite total alone.
    pub fn to_bytes(&self) -> Vec<u8> {
        if self.special != 0.0 || self.special.is_nan() {
            return self.special.to_le_bytes().to_vec();
        }
        self.partials.iter().flat_map(|p| p.to_le_bytes()).collect()
    }

    /// Reads [`ExactSum::to_bytes`]' form; `None` if the length is not a multiple of 8.
    pub fn from_bytes(bytes: &[u8]) -> Option<Self> {
        if bytes.len() % 8 != 0 {
            return None;
        }
        let mut sum = ExactSum::default();
        for chunk in bytes.chunks_exact(8) {
            let mut word = [0u8; 8];
            word.copy_from_slice(chunk);
            // Re-adding keeps the invariant even for bytes this code did not write.
            sum.add(f64::from_le_bytes(word));
        }
        Some(sum)
    }
}

/// Count, exact sum, minimum and maximum of some good numeric samples: one minute's
/// rollup, or one bucket of a query.
#[derive(Debug, Clone, PartialEq)]
pub struct Aggregate {
    /// How many samples.
    pub count: u64,
    /// Their exact sum.
    pub sum: ExactSum,
    /// The lowest.
    pub min: f64,
    /// The highest.
    pub max: f64,
}

impl Aggregate {
    /// The aggregate of the single value `x`.
    pub fn of(x: f64) -> Self {
        // SQLite stores -0.0 as 0: the rollup sees what the table keeps.
        let x = x + 0.0;
        let mut sum = ExactSum::default();
        sum.add(x);
        Self {
            count: 1,
            sum,
            min: x,
            max: x,
        }
    }

    /// Adds the value `x`.
    pub fn add(&mut self, x: f64) {
        let x = x + 0.0;
        self.count += 1;
        self.sum.add(x);
        self.min = self.min.min(x);
        self.max = self.max.max(x);
    }

    /// Adds every sample `other` counts.
    pub fn merge(&mut self, other: &Aggregate) {
        self.count += other.count;
        self.sum.merge(&other.sum);
        self.min = self.min.min(other.min);
        self.max = self.max.max(other.max);
    }

    /// The mean: the correctly rounded sum over the count.
    pub fn mean(&self) -> f64 {
        self.sum.total() / self.count as f64
    }
}

/// The value a sample contributes to the buckets, as the raw query selects it: good
/// quality and a number (a NaN is stored as NULL, so it does not count either).
pub(super) fn bucket_value(value: Option<&Value>, quality: Quality) -> Option<f64> {
    match (value, quality) {
        (Some(Value::Number(x)), Quality::Good) if !x.is_nan() => Some(*x),
        _ => None,
    }
}

/// The start of the minute holding `t` (`i64::MIN`, whose minute starts before it, for
/// itself).
pub(super) fn minute_of(t: i64) -> i64 {
    t.saturating_sub(t.rem_euclid(MINUTE_MS))
}

/// The first minute boundary at or after `t`.
pub(super) fn next_minute(t: i64) -> i64 {
    let floor = minute_of(t);
    if floor == t {
        t
    } else {
        // Past the last whole minute of i64 there is none: stay on the one before.
        floor.checked_add(MINUTE_MS).unwrap_or(floor)
    }
}

/// The two marks (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Marks {
    /// Rollups are complete from here.
    pub(super) since: i64,
    /// Minutes before this are in the table; later ones are open.
    pub(super) until: i64,
}

impl Marks {
    /// The marks as committed.
    pub(super) fn read(conn: &Connection) -> rusqlite::Result<Marks> {
        conn.query_row(
            "SELECT since, until FROM rollup_marks WHERE id = 1",
            [],
            |r| {
                Ok(Marks {
                    since: r.get(0)?,
                    until: r.get(1)?,
                })
            },
        )
    }

    fn write(self, conn: &Connection) -> rusqlite::Result<()> {
        conn.prepare_cached("UPDATE rollup_marks SET since = ?1, until = ?2 WHERE id = 1")?
            .execute(params![self.since, self.until])
            .map(drop)
    }

    /// Whether a sample at `t` is rolled up.
    fn covers(self, t: i64) -> bool {
        t >= self.since && t >= 0
    }
}

/// The writer's rollup state: the committed marks and the open minutes' aggregates.
#[derive(Debug)]
pub(super) struct OpenMinutes {
    marks: Marks,
    /// (point id, minute) → aggregate, for minutes at or after `marks.until`.
    open: BTreeMap<(i64, i64), Aggregate>,
    /// The newest sample time committed.
    newest: i64,
}

/// What one batch adds to the rollups, applied to [`OpenMinutes`] once its transaction
/// has committed.
#[derive(Debug, Default)]
pub(super) struct Staged {
    open: BTreeMap<(i64, i64), Aggregate>,
    late: BTreeMap<(i64, i64), Aggregate>,
    newest: Option<i64>,
    marks: Option<Marks>,
}

impl Staged {
    /// Notes a committed-to-be sample of point `id`.
    pub(super) fn sample(&mut self, state: &OpenMinutes, id: i64, t: i64, x: Option<f64>) {
        self.newest = Some(self.newest.map_or(t, |n| n.max(t)));
        let Some(x) = x else {
            return;
        };
        if !state.marks.covers(t) {
            return;
        }
        let key = (id, minute_of(t));
        let into = if t >= state.marks.until {
            &mut self.open
        } else {
            &mut self.late
        };
        match into.get_mut(&key) {
            Some(agg) => agg.add(x),
            None => {
                into.insert(key, Aggregate::of(x));
            }
        }
    }
}

impl OpenMinutes {
    /// Reads the marks and rebuilds the open minutes from the samples committed at or
    /// after `until` (after a restart, a `kill -9` included).
    pub(super) fn load(conn: &Connection) -> rusqlite::Result<Self> {
        let marks = Marks::read(conn)?;
        let mut state = OpenMinutes {
            marks,
            open: BTreeMap::new(),
            newest: i64::MIN,
        };
        let from = marks.until.max(marks.since).max(0);
        let mut stmt = conn.prepare(
            "SELECT point, t, value FROM samples WHERE t >= ?1 \
             AND quality = 0 AND value IS NOT NULL",
        )?;
        let mut rows = stmt.query([from])?;
        while let Some(r) = rows.next()? {
            let (id, t, x): (i64, i64, f64) = (r.get(0)?, r.get(1)?, r.get(2)?);
            state
                .open
                .entry((id, minute_of(t)))
                .and_modify(|a| a.add(x))
                .or_insert_with(|| Aggregate::of(x));
        }
        state.newest = conn
            .query_row("SELECT max(t) FROM samples", [], |r| {
                r.get::<_, Option<i64>>(0)
            })?
            .unwrap_or(i64::MIN);
        Ok(state)
    }

    /// The committed marks.
    pub(super) fn marks(&self) -> Marks {
        self.marks
    }

    /// Writes what `staged` holds in the batch's transaction: late samples merged into
    /// their rows; minutes that close (a minute behind the newest sample, or the clock
    /// `now_ms` if earlier) written once; the new marks.
    pub(super) fn write(
        &self,
        tx: &Transaction<'_>,
        staged: &mut Staged,
        now_ms: i64,
    ) -> rusqlite::Result<()> {
        for (&(id, minute), agg) in &staged.late {
            merge_row(tx, id, minute, agg)?;
        }
        let newest = staged.newest.map_or(self.newest, |n| n.max(self.newest));
        if newest == i64::MIN {
            return Ok(());
        }
        let close_before = minute_of(newest.min(now_ms).saturating_sub(CLOSE_AFTER_MS));
        if close_before <= self.marks.until {
            return Ok(());
        }
        let closing = |map: &BTreeMap<(i64, i64), Aggregate>| {
            map.iter()
                .filter(|((_, minute), _)| *minute < close_before)
                .map(|(k, a)| (*k, a.clone()))
                .collect::<Vec<_>>()
        };
        let mut closed: BTreeMap<(i64, i64), Aggregate> = closing(&self.open).into_iter().collect();
        for (key, agg) in closing(&staged.open) {
            closed
                .entry(key)
                .and_modify(|a| a.merge(&agg))
                .or_insert(agg);
        }
        for (&(id, minute), agg) in &closed {
            merge_row(tx, id, minute, agg)?;
        }
        let marks = Marks {
            since: self.marks.since,
            until: close_before,
        };
        marks.write(tx)?;
        staged.marks = Some(marks);
        Ok(())
    }

    /// The batch committed: its open minutes join the held ones, closed ones leave.
    pub(super) fn committed(&mut self, staged: Staged) {
        if let Some(n) = staged.newest {
            self.newest = self.newest.max(n);
        }
        for (key, agg) in staged.open {
            self.open
                .entry(key)
                .and_modify(|a| a.merge(&agg))
                .or_insert(agg);
        }
        if let Some(marks) = staged.marks {
            self.set_marks(marks);
        }
    }

    /// Retention keeps samples from `cutoff` on: rollups now start at the first whole
    /// minute after it. Committed at once (before any row is deleted), so no query mixes a
    /// rollup with a minute whose samples are going.
    pub(super) fn raise_since(&mut self, conn: &Connection, cutoff: i64) -> rusqlite::Result<()> {
        let since = self.marks.since.max(next_minute(cutoff));
        if since == self.marks.since {
            return Ok(());
        }
        let marks = Marks {
            since,
            until: self.marks.until.max(since),
        };
        marks.write(conn)?;
        self.set_marks(marks);
        Ok(())
    }

    fn set_marks(&mut self, marks: Marks) {
        self.marks = marks;
        self.open.retain(|(_, minute), _| *minute >= marks.until);
    }
}

/// Adds `agg` to the row of (`id`, `minute`), creating it if need be.
fn merge_row(tx: &Transaction<'_>, id: i64, minute: i64, agg: &Aggregate) -> rusqlite::Result<()> {
    let old = read_row(tx, id, minute)?;
    let merged = match old {
        Some(mut old) => {
            old.merge(agg);
            old
        }
        None => agg.clone(),
    };
    tx.prepare_cached(
        "INSERT OR REPLACE INTO minutes (point, minute, count, sum, min, max) \
         VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
    )?
    .execute(params![
        id,
        minute,
        i64::try_from(merged.count).unwrap_or(i64::MAX),
        merged.sum.to_bytes(),
        merged.min,
        merged.max
    ])
    .map(drop)
}

fn read_row(conn: &Connection, id: i64, minute: i64) -> rusqlite::Result<Option<Aggregate>> {
    conn.prepare_cached(
        "SELECT count, sum, min, max FROM minutes WHERE point = ?1 AND minute = ?2",
    )?
    .query_row(params![id, minute], read_aggregate)
    .optional()
}

/// A `minutes` row's count, sum, min and max (columns 0 to 3 of `r`, from `offset`).
pub(super) fn read_aggregate(r: &rusqlite::Row<'_>) -> rusqlite::Result<Aggregate> {
    aggregate_at(r, 0)
}

/// As [`read_aggregate`], from column `offset`.
pub(super) fn aggregate_at(r: &rusqlite::Row<'_>, offset: usize) -> rusqlite::Result<Aggregate> {
    let bytes: Vec<u8> = r.get(offset + 1)?;
    let sum = ExactSum::from_bytes(&bytes).ok_or_else(|| {
        rusqlite::Error::FromSqlConversionFailure(
            offset + 1,
            rusqlite::types::Type::Blob,
            format!("a rollup sum of {} bytes is not a list of f64", bytes.len()).into(),
        )
    })?;
    Ok(Aggregate {
        count: r.get::<_, i64>(offset)?.unsigned_abs(),
        sum,
        min: r.get(offset + 2)?,
        max: r.get(offset + 3)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_exact_sum_is_correctly_rounded_whatever_the_order() {
        let values = [1e16, 1.0, -1e16, 0.1, 0.2, 0.3, 1e-20, 3.5e15, -7.25];
        let mut forward = ExactSum::default();
        values.iter().for_each(|v| forward.add(*v));
        let mut backward = ExactSum::default();
        values.iter().rev().for_each(|v| backward.add(*v));
        // Split in two halves and merged, as two batches or two minutes would be.
        let (mut a, mut b) = (ExactSum::default(), ExactSum::default());
        values[..4].iter().for_each(|v| a.add(*v));
        values[4..].iter().for_each(|v| b.add(*v));
        a.merge(&b);
        // 1 + 0.1 + 0.2 + 0.3 + 3.5e15 - 7.25 (+ 1e-20), rounded once.
        let expected = 3_500_000_000_000_000.0 - 7.25 + 1.0 + 0.6;
        assert_eq!(forward.total(), expected);
        assert_eq!(backward.total(), expected);
        assert_eq!(a.total(), expected);
        let naive: f64 = values.iter().sum();
        assert_ne!(naive, expected, "the naive sum loses the 1.0 next to 1e16");
    }

    #[test]
    fn an_exact_sum_survives_its_stored_form_and_keeps_infinities() {
        let mut sum = ExactSum::default();
        [0.1, 1e300, -1e300, 0.7].iter().for_each(|v| sum.add(*v));
        let back = ExactSum::from_bytes(&sum.to_bytes()).unwrap();
        assert_eq!(back.total(), sum.total());
        assert_eq!(ExactSum::from_bytes(&[1, 2, 3]), None);
        sum.add(f64::INFINITY);
        assert_eq!(sum.total(), f64::INFINITY);
        let back = ExactSum::from_bytes(&sum.to_bytes()).unwrap();
        assert_eq!(back.total(), f64::INFINITY);
        sum.add(f64::NEG_INFINITY);
        assert!(sum.total().is_nan());
        let mut huge = ExactSum::default();
        huge.add(f64::MAX);
        huge.add(f64::MAX);
        assert_eq!(huge.total(), f64::INFINITY);
    }

    #[test]
    fn minutes_are_cut_at_whole_minutes() {
        assert_eq!(minute_of(59_999), 0);
        assert_eq!(minute_of(-1), -60_000);
        assert_eq!(minute_of(i64::MIN), i64::MIN);
        assert_eq!(minute_of(i64::MAX) % MINUTE_MS, 0);
        assert_eq!(minute_of(60_000), 60_000);
        assert_eq!(next_minute(0), 0);
        assert_eq!(next_minute(1), 60_000);
        assert_eq!(next_minute(60_000), 60_000);
        assert_eq!(next_minute(i64::MAX), minute_of(i64::MAX));
    }
}
