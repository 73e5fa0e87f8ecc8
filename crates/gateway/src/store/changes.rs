//! The stored changes of every point in time order: what the MQTT backlog sends after an
//! outage, read without an index on time.
//!
//! `samples` has one index, on (point, t). An index on t alone cost 13–15 % of every
//! insert (DESIGN.md, "Ingest") for reads that happen only after an outage, so a
//! time-ordered read goes through windows of time instead: for each point the index gives
//! the window's keys (one seek a point; time and row id are both in the index), which are
//! sorted here. A window's length follows how many keys the last one held ([`Window`]),
//! and one holding far more than wanted is halved and read again; after a
//! window that held none the read jumps to the next stored time, so a gap of days costs
//! one query. A seek a point and window is most of the cost, so the backlog reads many
//! pages' keys at a time ([`StoreHandle::change_keys`]) and then each page's rows by their
//! row ids ([`StoreHandle::changes_at`]).

use std::fmt::Write as _;

use rusqlite::{Connection, OptionalExtension};

use crate::point::{Quality, Value};
use crate::time::Timestamp;

use super::*;

/// The first window's length, in ms.
const FIRST_WINDOW_MS: i64 = 1_000;

/// The longest window, in ms (a day): stored times far apart are jumped, not read through.
const LONGEST_WINDOW_MS: i64 = 86_400_000;

/// The most a window grows from one to the next.
const MOST_GROWTH: i64 = 8;

/// The most keys a window may hold, as a multiple of the keys wanted: a longer window is
/// halved and read again, so a sudden rise in the rate of changes cannot fill the memory.
const MOST_OVERSHOOT: usize = 4;

/// The length of the next window of a time-ordered read (sans IO).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Window {
    ms: i64,
}

impl Window {
    /// The first window of a read.
    pub(super) fn first() -> Self {
        Self {
            ms: FIRST_WINDOW_MS,
        }
    }

    /// Its length, in ms.
    pub(super) fn ms(self) -> i64 {
        self.ms
    }

    /// The window after one whose first `held` rows spanned `spanned_ms` before the limit
    /// cut it: an eighth longer than `wanted` rows need at that density, from 1 ms to a
    /// day.
    pub(super) fn fitted(spanned_ms: i64, held: u64, wanted: u64) -> Self {
        // An eighth more: a window a few keys short costs a second seek a point.
        let ms =
            i128::from(spanned_ms.max(1)) * i128::from(wanted) * 9 / (i128::from(held.max(1)) * 8);
        Self {
            ms: i64::try_from(ms)
                .unwrap_or(LONGEST_WINDOW_MS)
                .clamp(1, LONGEST_WINDOW_MS),
        }
    }

    /// Half as long (at least 1 ms), after a window that held too many rows.
    pub(super) fn halved(self) -> Self {
        Self {
            ms: (self.ms / 2).max(1),
        }
    }

    /// The window after one that held `held` rows when `wanted` were still wanted: long
    /// enough for the rows still wanted at the density just seen, at most
    /// [`MOST_GROWTH`] times longer and never shorter. An empty window says nothing of the
    /// density (the read jumps to the next stored time): the length stays.
    pub(super) fn after(self, held: u64, wanted: u64) -> Self {
        if held == 0 {
            return self;
        }
        let growth = i64::try_from(wanted.saturating_sub(held).div_ceil(held))
            .unwrap_or(MOST_GROWTH)
            .clamp(1, MOST_GROWTH);
        Self {
            ms: self.ms.saturating_mul(growth).min(LONGEST_WINDOW_MS),
        }
    }
}

/// The rows of a window through `samples_by_point_time`, points in the outer loop:
/// `?3 <= t <= ?4` and `(t, rowid) > (?1, ?2)`.
macro_rules! window {
    ($columns:literal, $rest:literal) => {
        concat!(
            "SELECT ",
            $columns,
            " FROM points p CROSS JOIN samples s INDEXED BY samples_by_point_time \
             ON s.point = p.id WHERE s.t >= ?3 AND s.t <= ?4 AND (s.t, s.rowid) > (?1, ?2)",
            $rest
        )
    };
}

/// The keys of at most `?5` changes of a window, in the index's order (by point): sorted
/// here, which is cheaper than an `ORDER BY`, for which SQLite builds a B-tree of them.
pub(super) const WINDOW_KEYS: &str = window!("s.t, s.rowid", " LIMIT ?5");

/// The changes whose row ids `?1` lists (a JSON array), looked up in the list's order (a
/// `rowid IN (…)` would first sort the list into a B-tree).
pub(super) const CHANGES_AT: &str = "SELECT s.t, s.rowid, p.name, s.value, s.text, s.quality \
    FROM json_each(?1) j CROSS JOIN samples s ON s.rowid = j.value \
    CROSS JOIN points p ON p.id = s.point";

/// How many changes a window holds.
pub(super) const WINDOW_COUNT: &str = window!("count(*)", "");

/// The key of a window's change that has `?5` newer ones in the window.
pub(super) const WINDOW_NTH_NEWEST: &str = window!(
    "s.t, s.rowid",
    " ORDER BY s.t DESC, s.rowid DESC LIMIT 1 OFFSET ?5"
);

/// `min` or `max` of the stored times in a window: one seek a point.
macro_rules! window_time {
    ($fold:literal) => {
        concat!(
            "SELECT ",
            $fold,
            "((SELECT ",
            $fold,
            "(s.t) FROM samples s INDEXED BY samples_by_point_time \
             WHERE s.point = p.id AND s.t >= ?3 AND s.t <= ?4 AND (s.t, s.rowid) > (?1, ?2))) \
             FROM points p"
        )
    };
}

/// The earliest stored time in a window (`NULL` when it holds none).
pub(super) const WINDOW_FIRST: &str = window_time!("min");

/// The latest stored time in a window (`NULL` when it holds none).
pub(super) const WINDOW_LAST: &str = window_time!("max");

/// Where a time-ordered read of the stored changes is between calls of
/// [`StoreHandle::change_keys`]: after which change, up to when, and how long its next
/// window is (so a long read does not start each call from the first window's length).
#[derive(Debug, Clone, Copy)]
pub struct ChangeCursor {
    after: ChangeKey,
    until: Timestamp,
    window: Window,
}

impl ChangeCursor {
    /// A read of the changes after `after` and at or before `until`.
    pub fn new(after: ChangeKey, until: Timestamp) -> Self {
        Self {
            after,
            until,
            window: Window::first(),
        }
    }
}

/// The changes after `after` with `lo <= t <= hi`.
#[derive(Debug, Clone, Copy)]
struct Span {
    after: ChangeKey,
    lo: i64,
    hi: i64,
}

/// The key in a row's first two columns (t, rowid).
fn key(r: &rusqlite::Row<'_>) -> rusqlite::Result<ChangeKey> {
    Ok(ChangeKey {
        t: Timestamp(r.get(0)?),
        row: r.get(1)?,
    })
}

impl Span {
    /// Every stored change.
    fn everything() -> Self {
        Self {
            after: ChangeKey::before(Timestamp(i64::MIN)),
            lo: i64::MIN,
            hi: i64::MAX,
        }
    }

    /// The window's parameters `?1` to `?4`, and `?5`.
    fn with(self, fifth: u64) -> [i64; 5] {
        let [a, b, c, d] = self.bounds();
        [a, b, c, d, i64::try_from(fifth).unwrap_or(i64::MAX)]
    }

    /// The window's parameters `?1` to `?4`.
    fn bounds(self) -> [i64; 4] {
        [self.after.t.0, self.after.row, self.lo, self.hi]
    }

    fn count(self, conn: &Connection) -> rusqlite::Result<u64> {
        let n: i64 = conn
            .prepare_cached(WINDOW_COUNT)?
            .query_row(self.bounds(), |r| r.get(0))?;
        Ok(n.unsigned_abs())
    }

    /// The earliest stored time in the span.
    fn first_time(self, conn: &Connection) -> rusqlite::Result<Option<i64>> {
        conn.prepare_cached(WINDOW_FIRST)?
            .query_row(self.bounds(), |r| r.get(0))
    }

    /// The latest stored time in the span.
    fn last_time(self, conn: &Connection) -> rusqlite::Result<Option<i64>> {
        conn.prepare_cached(WINDOW_LAST)?
            .query_row(self.bounds(), |r| r.get(0))
    }

    /// Appends the keys of the span's first `limit` changes to `out`, oldest first, and
    /// says how many; `None` when the span holds more than [`MOST_OVERSHOOT`] times
    /// `limit` and is more than a millisecond long (read a shorter one).
    fn keys(
        self,
        conn: &Connection,
        limit: usize,
        out: &mut Vec<ChangeKey>,
    ) -> rusqlite::Result<Option<u64>> {
        let most = if self.hi > self.lo {
            limit.saturating_mul(MOST_OVERSHOOT)
        } else {
            usize::MAX - 1
        };
        let mut stmt = conn.prepare_cached(WINDOW_KEYS)?;
        let mut keys = stmt
            .query_map(self.with(most as u64 + 1), key)?
            .collect::<rusqlite::Result<Vec<_>>>()?;
        if keys.len() > most {
            return Ok(None);
        }
        keys.sort_unstable();
        keys.truncate(limit);
        let held = keys.len() as u64;
        out.extend(keys);
        Ok(Some(held))
    }

    /// The key of the change with `newer` newer ones in the span.
    fn nth_newest(self, conn: &Connection, newer: u64) -> rusqlite::Result<Option<ChangeKey>> {
        conn.prepare_cached(WINDOW_NTH_NEWEST)?
            .query_row(self.with(newer), key)
            .optional()
    }
}

/// The end of a window of `ms` starting at `lo`, no later than `until`.
fn window_end(lo: i64, window: Window, until: i64) -> i64 {
    lo.saturating_add(window.ms() - 1).min(until)
}

impl StoreHandle {
    /// At most `limit` stored changes of any point after `after` and at or before `until`,
    /// in time order (ties in the order they were stored, which within a commit is point
    /// by point): the keys, then the rows (the backlog does the two apart, reading keys
    /// ahead).
    #[cfg(test)]
    pub(super) fn changes(
        &self,
        after: ChangeKey,
        until: Timestamp,
        limit: usize,
    ) -> Result<Vec<StoredChange>, StoreError> {
        let keys = self.change_keys(&mut ChangeCursor::new(after, until), limit)?;
        self.changes_at(&keys)
    }

    /// The keys of the next `limit` stored changes of the read `cursor` is at, in time
    /// order (ties in the order they were stored, which within a commit is point by
    /// point); fewer at its end. Moves `cursor` on.
    pub fn change_keys(
        &self,
        cursor: &mut ChangeCursor,
        limit: usize,
    ) -> Result<Vec<ChangeKey>, StoreError> {
        let until = cursor.until.0;
        self.readers.with(|conn| {
            // One snapshot for every window.
            let snapshot = conn.unchecked_transaction()?;
            let conn: &Connection = &snapshot;
            let mut out = Vec::new();
            let mut lo = cursor.after.t.0;
            while out.len() < limit && lo <= until {
                let wanted = limit - out.len();
                let hi = window_end(lo, cursor.window, until);
                let span = Span {
                    after: cursor.after,
                    lo,
                    hi,
                };
                let Some(held) = span.keys(conn, wanted, &mut out)? else {
                    cursor.window = cursor.window.halved();
                    continue;
                };
                if let Some(last) = out.last() {
                    cursor.after = *last;
                }
                if held == 0 {
                    // Jump to the next stored time.
                    let rest = Span { hi: until, ..span };
                    match rest.first_time(conn)? {
                        Some(first) if first > hi => lo = first,
                        _ => break,
                    }
                } else if out.len() == limit {
                    // Cut by the limit: the next call's first window fits what this one saw.
                    let spanned = cursor.after.t.0.saturating_sub(lo).saturating_add(1);
                    cursor.window = Window::fitted(spanned, held, limit as u64);
                } else {
                    cursor.window = cursor.window.after(held, wanted as u64);
                    lo = hi.saturating_add(1);
                }
            }
            Ok(out)
        })
    }

    /// The changes `keys` name (from [`StoreHandle::change_keys`]), in their order; those
    /// pruned since the keys were read are left out.
    pub fn changes_at(&self, keys: &[ChangeKey]) -> Result<Vec<StoredChange>, StoreError> {
        if keys.is_empty() {
            return Ok(Vec::new());
        }
        let mut rows = String::with_capacity(keys.len() * 12);
        rows.push('[');
        for (i, key) in keys.iter().enumerate() {
            if i > 0 {
                rows.push(',');
            }
            write!(rows, "{}", key.row).expect("writing to a String cannot fail");
        }
        rows.push(']');
        let mut changes = self.readers.with(|conn| {
            let mut stmt = conn.prepare_cached(CHANGES_AT)?;
            let changes = stmt.query_map([rows], |r| {
                let number: Option<f64> = r.get(3)?;
                let text: Option<String> = r.get(4)?;
                Ok(StoredChange {
                    key: key(r)?,
                    point: r.get(2)?,
                    value: number.map(Value::Number).or(text.map(Value::Text)),
                    quality: Quality::from_code(r.get(5)?),
                })
            })?;
            changes.collect::<rusqlite::Result<Vec<_>>>()
        })?;
        changes.sort_unstable_by_key(|c| c.key);
        Ok(changes)
    }

    /// How many changes are stored after `after` and at or before `until`, and, when more
    /// than `keep`, the key after which the newest `keep` of them start.
    pub fn count_changes(
        &self,
        after: ChangeKey,
        until: Timestamp,
        keep: u64,
    ) -> Result<(u64, Option<ChangeKey>), StoreError> {
        self.readers.with(|conn| {
            let snapshot = conn.unchecked_transaction()?;
            let conn: &Connection = &snapshot;
            let all = Span {
                after,
                lo: after.t.0,
                hi: until.0,
            };
            let count = all.count(conn)?;
            if count <= keep {
                return Ok((count, None));
            }
            // Windows back from `until`, counted, to the one the start is in.
            let mut newer = 0;
            let mut window = Window::first();
            let mut hi = until.0;
            while hi >= after.t.0 {
                let lo = hi.saturating_sub(window.ms() - 1).max(after.t.0);
                let span = Span { after, lo, hi };
                let held = span.count(conn)?;
                if newer + held > keep {
                    return Ok((count, span.nth_newest(conn, keep - newer)?));
                }
                let wanted = keep + 1 - newer;
                newer += held;
                if held == 0 {
                    // Jump back to the previous stored time.
                    match (Span {
                        lo: after.t.0,
                        ..span
                    })
                    .last_time(conn)?
                    {
                        Some(last) if last < lo => hi = last,
                        _ => break,
                    }
                } else {
                    window = window.after(held, wanted);
                    hi = lo.saturating_sub(1);
                }
            }
            // Counted once and again in the same snapshot: not reached.
            Ok((count, None))
        })
    }
}

/// The newest stored time, one seek a point (`samples` has no index on time alone).
pub(super) fn newest_sample_time(conn: &Connection) -> rusqlite::Result<Option<i64>> {
    Span::everything().last_time(conn)
}
