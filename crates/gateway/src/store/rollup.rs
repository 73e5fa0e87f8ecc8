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

use std::borrow::Cow;
use std::collections::BTreeMap;

use rusqlite::{Connection, OptionalExtension, Transaction, params};

use crate::point::{Quality, Value};

use super::changes::newest_sample_time;

/// One minute in milliseconds: the rollups' granularity.
pub(super) const MINUTE_MS: i64 = 60_000;

/// How far behind the newest sample (or the clock, if that is earlier) a minute closes:
/// samples up to a minute late still find their minute open.
const CLOSE_AFTER_MS: i64 = MINUTE_MS;

/// The exact sum of finite numbers, as non-overlapping partial sums in increasing
/// magnitude (Shewchuk's algorithm, as in Python's `math.fsum`); [`ExactSum::total`] is the
/// correctly rounded sum. Infinities (and their NaN) are summed apart and win.
///
/// The largest partial is held inline and only the smaller ones spill to the heap: a
/// minute's sum of integer or float32 readings needs one partial, and an open minute of
/// every point is held in memory (16 bytes here, against 32 with two partials inline).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ExactSum {
    /// The largest partial (0 with none); once a non-finite number was added, or the
    /// partial sums left the range of f64, that non-finite total, which wins.
    top: f64,
    /// The smaller partials, in increasing magnitude; `None` while `top` alone is exact.
    rest: Option<Box<Partials>>,
}

/// The partials below an [`ExactSum`]'s largest, in increasing magnitude; never empty.
#[derive(Debug, Clone, PartialEq)]
struct Partials(Vec<f64>);

impl ExactSum {
    /// Adds `x` exactly.
    pub fn add(&mut self, x: f64) {
        if !self.top.is_finite() {
            // A non-finite total stays what it is, or becomes NaN with an opposite infinity.
            self.top += x;
            return;
        }
        if !x.is_finite() {
            self.top = x;
            self.rest = None;
            return;
        }
        let Some(rest) = self.rest.as_mut() else {
            // One partial (or none: 0 adds nothing): the common case, without the heap.
            let (hi, lo) = two_sum(x, self.top);
            self.top = hi;
            if lo != 0.0 && hi.is_finite() {
                self.rest = Some(Box::new(Partials(vec![lo])));
            }
            return;
        };
        let p = &mut rest.0;
        p.push(self.top);
        let mut x = x;
        let mut kept = 0;
        for j in 0..p.len() {
            let (hi, lo) = two_sum(x, p[j]);
            if lo != 0.0 {
                p[kept] = lo;
                kept += 1;
            }
            x = hi;
        }
        p.truncate(kept);
        // A non-finite `x`: the partial sums left the range of f64, the total is that
        // infinity.
        self.top = x;
        if p.is_empty() || !x.is_finite() {
            self.rest = None;
        }
    }

    /// Adds every number `other` holds.
    pub fn merge(&mut self, other: &ExactSum) {
        if let Some(rest) = &other.rest {
            rest.0.iter().for_each(|p| self.add(*p));
        }
        self.add(other.top);
    }

    /// The sum, correctly rounded to the nearest f64 (ties to even).
    pub fn total(&self) -> f64 {
        let Some(rest) = &self.rest else {
            return self.top;
        };
        // The partials are `rest` and then `top`; `p[n]` is the one below the sum so far.
        let p = &rest.0;
        let mut n = p.len();
        let (mut hi, mut lo) = (self.top, 0.0);
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
        let rest = self.rest.as_ref().map_or(&[][..], |r| &r.0[..]);
        rest.iter()
            .chain(std::iter::once(&self.top))
            .flat_map(|p| p.to_le_bytes())
            .collect()
    }

    /// Reads [`ExactSum::to_bytes`]' form; `None` if the length is not a multiple of 8.
    pub fn from_bytes(bytes: &[u8]) -> Option<Self> {
        if !bytes.len().is_multiple_of(8) {
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

/// `x + y` rounded, and the error of that rounding (exact for finite numbers).
fn two_sum(x: f64, y: f64) -> (f64, f64) {
    let (x, y) = if x.abs() < y.abs() { (y, x) } else { (x, y) };
    let hi = x + y;
    (hi, y - (hi - x))
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
    /// The aggregates of the minutes at or after `marks.until`.
    open: OpenTable,
    /// The newest sample time committed.
    newest: i64,
}

/// What one batch adds to the rollups, applied to [`OpenMinutes`] once its transaction
/// has committed.
#[derive(Debug, Default)]
pub(super) struct Staged {
    /// (point id, minute, value) of the batch's samples in open minutes, in order: added to
    /// the open minutes after the commit (most of them stay open).
    open: Vec<(i64, i64, f64)>,
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
        let minute = minute_of(t);
        if t >= state.marks.until {
            self.open.push((id, minute, x));
            return;
        }
        match self.late.get_mut(&(id, minute)) {
            Some(agg) => agg.add(x),
            None => {
                self.late.insert((id, minute), Aggregate::of(x));
            }
        }
    }
}

/// The good numeric samples from `?1` on, a point at a time (`samples` has no index on
/// time alone).
pub(super) const OPEN_MINUTES_SAMPLES: &str = "SELECT s.point, s.t, s.value FROM points p \
    CROSS JOIN samples s INDEXED BY samples_by_point_time ON s.point = p.id \
    WHERE s.t >= ?1 AND s.quality = 0 AND s.value IS NOT NULL";

impl OpenMinutes {
    /// Reads the marks and rebuilds the open minutes from the samples committed at or
    /// after `until` (after a restart, a `kill -9` included).
    pub(super) fn load(conn: &Connection) -> rusqlite::Result<Self> {
        let marks = Marks::read(conn)?;
        let highest: Option<i64> =
            conn.query_row("SELECT max(id) FROM points", [], |r| r.get(0))?;
        let mut state = OpenMinutes {
            marks,
            open: OpenTable::new(highest.unwrap_or(0)),
            newest: i64::MIN,
        };
        let from = marks.until.max(marks.since).max(0);
        let mut stmt = conn.prepare(OPEN_MINUTES_SAMPLES)?;
        let mut rows = stmt.query([from])?;
        while let Some(r) = rows.next()? {
            let (id, t, x): (i64, i64, f64) = (r.get(0)?, r.get(1)?, r.get(2)?);
            state.open.add(id, minute_of(t), x);
        }
        state.newest = newest_sample_time(conn)?.unwrap_or(i64::MIN);
        Ok(state)
    }

    /// The committed marks.
    pub(super) fn marks(&self) -> Marks {
        self.marks
    }

    /// Writes what `staged` holds in the batch's transaction: late samples merged into
    /// their rows; minutes that close (a minute behind the newest sample, or the clock
    /// `now_ms` if earlier) written once; the new marks. The open minutes are only read:
    /// they change in [`OpenMinutes::committed`].
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
        // The batch's own samples of closing minutes (rare: a minute late at least).
        let mut batch: BTreeMap<(i64, i64), Aggregate> = BTreeMap::new();
        for &(id, minute, x) in staged.open.iter().filter(|s| s.1 < close_before) {
            batch
                .entry((id, minute))
                .and_modify(|a| a.add(x))
                .or_insert_with(|| Aggregate::of(x));
        }
        for (id, minute, held) in self.open.before(close_before) {
            match batch.remove(&(id, minute)) {
                Some(more) => {
                    let mut agg = held.into_owned();
                    agg.merge(&more);
                    merge_row(tx, id, minute, &agg)?;
                }
                None => merge_row(tx, id, minute, &held)?,
            }
        }
        for (&(id, minute), agg) in &batch {
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

    /// The batch committed: closed minutes leave, its samples of open ones join.
    pub(super) fn committed(&mut self, staged: Staged) {
        if let Some(n) = staged.newest {
            self.newest = self.newest.max(n);
        }
        if let Some(marks) = staged.marks {
            self.set_marks(marks);
        }
        for (id, minute, x) in staged.open {
            // Minutes before `until` closed in this batch, these samples with them.
            if minute >= self.marks.until {
                self.open.add(id, minute, x);
            }
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
        self.open.close_before(marks.until);
    }
}

/// The open minutes' aggregates: a column per minute (about two are open: the one
/// closing a minute behind and the current one), each indexed by point id, which the
/// `points` table hands out densely from 1; ids outside that range in a map. A column
/// holds a 4-byte slot per point, an 8-byte number per point with one sample that minute
/// and a 40-byte aggregate per point with more: at 1,000 JBC stations (26,000 points)
/// about 9,500 points change in a minute, so a minute takes about 0.5 MB, against 1 MB
/// with an aggregate per point and about 100 bytes an entry in a map of (point, minute).
/// The first minute after a start holds every point, each read for the first time and
/// most of them once (those whose value does not change): 0.5 MB instead of 1.1.
#[derive(Debug)]
struct OpenTable {
    /// Minute → its column, for the open minutes.
    columns: BTreeMap<i64, Column>,
    /// A closed column, emptied, for the next minute (its memory reused, not reallocated).
    spare: Column,
    /// Ids up to this one are kept in the columns: the highest in the `points` table at
    /// start, raised by the ids of new points, which follow it.
    dense_until: i64,
    /// (point id, minute) → aggregate for the other ids.
    more: BTreeMap<(i64, i64), Aggregate>,
}

/// One open minute of the points kept in columns.
#[derive(Debug, Default)]
struct Column {
    /// Point id → where its samples of the minute are: 0 for none; 1 + an index into
    /// `singles` with [`SINGLE`] set for one sample; 1 + an index into `aggregates` for
    /// more.
    slots: Vec<u32>,
    /// The sample of each point with one sample, in the order they came; a point's entry
    /// stays unused when its second sample moves it to `aggregates`.
    singles: Vec<f64>,
    /// The aggregates of the points with two samples or more, in the order of their
    /// second sample.
    aggregates: Vec<Aggregate>,
}

/// The bit of a slot that says it points into `Column::singles`.
const SINGLE: u32 = 1 << 31;

/// What a column's slot says of its point's samples that minute.
enum Slot {
    None,
    /// One sample, at this index of `Column::singles`.
    Single(usize),
    /// More, aggregated at this index of `Column::aggregates`.
    Many(usize),
}

impl Slot {
    fn of(at: u32) -> Self {
        match at {
            0 => Slot::None,
            at if at & SINGLE != 0 => Slot::Single((at & !SINGLE) as usize - 1),
            at => Slot::Many(at as usize - 1),
        }
    }
}

/// How far past `OpenTable::dense_until` a new point's id may be and still be kept in the
/// columns (new points take the next ids; a stray higher id goes to the map instead of
/// sizing every column).
const DENSE_STEP: i64 = 1024;

/// How many slots (or aggregates) a column grows by at least: new points arrive in bursts,
/// and doubling would leave up to half of a large column unused.
const GROW_ENTRIES: usize = 1024;

impl OpenTable {
    fn new(dense_until: i64) -> Self {
        OpenTable {
            columns: BTreeMap::new(),
            spare: Column::default(),
            dense_until: dense_until.max(0),
            more: BTreeMap::new(),
        }
    }

    /// Adds `x` to point `id`'s minute starting at `minute`.
    fn add(&mut self, id: i64, minute: i64, x: f64) {
        let Some(i) = self.dense_index(id) else {
            self.more
                .entry((id, minute))
                .and_modify(|a| a.add(x))
                .or_insert_with(|| Aggregate::of(x));
            return;
        };
        if !self.columns.contains_key(&minute) {
            // The points of the newest open minute come back in this one: size it for them.
            let (slots, singles, aggregates) =
                self.columns.values().next_back().map_or((0, 0, 0), |c| {
                    (c.slots.len(), c.singles.len(), c.aggregates.len())
                });
            let mut column = std::mem::take(&mut self.spare);
            column.slots.reserve_exact(slots.max(i + 1));
            column.singles.reserve_exact(singles);
            column.aggregates.reserve_exact(aggregates);
            self.columns.insert(minute, column);
        }
        self.columns
            .get_mut(&minute)
            .expect("the minute's column was just made")
            .add(i, x);
    }

    /// The column index of point `id`; `None` for an id kept in the map.
    fn dense_index(&mut self, id: i64) -> Option<usize> {
        let i = usize::try_from(id).ok()?;
        if id > self.dense_until.saturating_add(DENSE_STEP) || i >= MAX_SLOTS {
            return None;
        }
        self.dense_until = self.dense_until.max(id);
        Some(i)
    }

    /// The open minutes before `minute`: (point id, minute, aggregate).
    fn before(&self, minute: i64) -> impl Iterator<Item = (i64, i64, Cow<'_, Aggregate>)> {
        let columns = self
            .columns
            .range(..minute)
            .flat_map(|(&minute, column)| column.held().map(move |(id, agg)| (id, minute, agg)));
        let more = self
            .more
            .iter()
            .filter(move |((_, m), _)| *m < minute)
            .map(|(&(id, m), agg)| (id, m, Cow::Borrowed(agg)));
        columns.chain(more)
    }

    /// Forgets the minutes before `minute` (written, or no longer rolled up).
    fn close_before(&mut self, minute: i64) {
        let open = self.columns.split_off(&minute);
        let closed = std::mem::replace(&mut self.columns, open);
        if let Some(mut column) = closed.into_values().max_by_key(|c| c.slots.capacity()) {
            column.slots.clear();
            column.singles.clear();
            column.aggregates.clear();
            // The first minute after a start holds every point (each is read for the first
            // time); later minutes only the points that change. Keep room for as many as
            // an open minute holds, not for that first one.
            let most = |len: fn(&Column) -> usize| self.columns.values().map(len).max();
            column
                .singles
                .shrink_to(most(|c| c.singles.len()).unwrap_or(0));
            column
                .aggregates
                .shrink_to(most(|c| c.aggregates.len()).unwrap_or(0));
            if column.slots.capacity() > self.spare.slots.capacity() {
                self.spare = column;
            }
        }
        self.more.retain(|(_, m), _| *m >= minute);
    }
}

/// The most slots a column has: a slot holds 1 + an index into the column's singles or
/// aggregates (at most as many as its slots) below the [`SINGLE`] bit.
const MAX_SLOTS: usize = (SINGLE - 1) as usize;

impl Column {
    /// Adds `x` to the point in slot `i` (below [`MAX_SLOTS`]).
    fn add(&mut self, i: usize, x: f64) {
        if i >= self.slots.len() {
            if i >= self.slots.capacity() {
                self.slots
                    .reserve_exact((i + 1 - self.slots.len()).max(GROW_ENTRIES));
            }
            self.slots.resize(i + 1, 0);
        }
        match Slot::of(self.slots[i]) {
            Slot::None => {
                grow_by_a_quarter(&mut self.singles);
                self.singles.push(x);
                self.slots[i] = SINGLE | entry_number(self.singles.len());
            }
            Slot::Single(j) => {
                let mut aggregate = Aggregate::of(self.singles[j]);
                aggregate.add(x);
                grow_by_a_quarter(&mut self.aggregates);
                self.aggregates.push(aggregate);
                self.slots[i] = entry_number(self.aggregates.len());
            }
            Slot::Many(j) => self.aggregates[j].add(x),
        }
    }

    /// (point id, aggregate) of the points with samples, in the order of their ids.
    fn held(&self) -> impl Iterator<Item = (i64, Cow<'_, Aggregate>)> {
        self.slots.iter().enumerate().filter_map(|(i, &at)| {
            let held = match Slot::of(at) {
                Slot::None => return None,
                Slot::Single(j) => Cow::Owned(Aggregate::of(self.singles[j])),
                Slot::Many(j) => Cow::Borrowed(&self.aggregates[j]),
            };
            let id = i64::try_from(i).expect("a column's index came from an i64 id");
            Some((id, held))
        })
    }
}

/// Makes room for one more entry in `list`, by a quarter of its length and not double: a
/// minute's points come in their thousands.
fn grow_by_a_quarter<T>(list: &mut Vec<T>) {
    if list.len() == list.capacity() {
        list.reserve_exact((list.len() / 4).max(GROW_ENTRIES));
    }
}

/// The slot number of the last of `len` entries: 1 + its index, below [`SINGLE`] (a column
/// has at most as many singles, or aggregates, as slots, and fewer than [`MAX_SLOTS`]).
fn entry_number(len: usize) -> u32 {
    u32::try_from(len)
        .ok()
        .filter(|&n| n < SINGLE)
        .expect("a column has fewer entries than MAX_SLOTS")
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
mod tests;
