//! The tables, their indexes and the connection settings.

use std::time::Duration;

use rusqlite::Connection;

use crate::point::{Quality, Value};
use crate::time::Timestamp;

use super::*;

pub(super) const SCHEMA: &str = "
CREATE TABLE IF NOT EXISTS points (
    id   INTEGER PRIMARY KEY,
    name TEXT NOT NULL UNIQUE
);
CREATE TABLE IF NOT EXISTS samples (
    point   INTEGER NOT NULL REFERENCES points(id),
    t       INTEGER NOT NULL,
    value   REAL,
    text    TEXT,
    quality INTEGER NOT NULL
);
CREATE INDEX IF NOT EXISTS samples_by_point_time ON samples(point, t);
CREATE TABLE IF NOT EXISTS events (
    id      INTEGER PRIMARY KEY,
    t       INTEGER NOT NULL,
    kind    TEXT NOT NULL,
    line    TEXT,
    device  TEXT,
    point   TEXT,
    message TEXT NOT NULL,
    fields  TEXT
);
CREATE INDEX IF NOT EXISTS events_by_time ON events(t);
CREATE TABLE IF NOT EXISTS audit (
    id        INTEGER PRIMARY KEY,
    t         INTEGER NOT NULL,
    client    TEXT NOT NULL,
    device    TEXT NOT NULL,
    point     TEXT NOT NULL,
    old_value TEXT,
    new_value TEXT NOT NULL,
    result    TEXT NOT NULL,
    detail    TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS audit_by_time ON audit(t);
CREATE TABLE IF NOT EXISTS alarm_states (
    id     TEXT PRIMARY KEY,
    t      INTEGER NOT NULL,
    fields TEXT NOT NULL
);
";

/// Version 2: per-minute rollups of the good numeric samples (see `rollup`). `sum` is the
/// exact sum's partials as little-endian f64s; `minute` its start in ms since the epoch.
const ROLLUPS: &str = "
CREATE TABLE IF NOT EXISTS minutes (
    point  INTEGER NOT NULL,
    minute INTEGER NOT NULL,
    count  INTEGER NOT NULL,
    sum    BLOB NOT NULL,
    min    REAL NOT NULL,
    max    REAL NOT NULL,
    PRIMARY KEY (point, minute)
) WITHOUT ROWID;
CREATE TABLE IF NOT EXISTS rollup_marks (
    id    INTEGER PRIMARY KEY CHECK (id = 1),
    since INTEGER NOT NULL,
    until INTEGER NOT NULL
);
";

/// The schema's version in `PRAGMA user_version`: 1 before the rollups, 2 with them, 3
/// without the index on `samples(t)` (see `changes`), 4 with the events' `fields` (a JSON
/// object, NULL when the event has none).
pub(super) const VERSION: i64 = 4;

/// Creates the tables of a new file, or brings an older file up to [`VERSION`], in one
/// transaction. A file from version 1 gets empty rollups that start at the first minute
/// after its newest sample: older minutes are answered from the samples (as before) until
/// retention removes them, so opening a large old file costs no rewrite. A file from
/// version 1 or 2 loses its index on `samples(t)`: its pages become free pages, which
/// the next retention gives back to the disk.
pub(super) fn migrate(conn: &mut Connection) -> rusqlite::Result<()> {
    let tx = conn.transaction_with_behavior(rusqlite::TransactionBehavior::Immediate)?;
    let version: i64 = tx.query_row("PRAGMA user_version", [], |r| r.get(0))?;
    tx.execute_batch(SCHEMA)?;
    tx.execute_batch(ROLLUPS)?;
    if version < 2 {
        let newest = newest_sample_time(&tx)?;
        let since = newest.map_or(0, |t| rollup::next_minute(t.saturating_add(1)).max(0));
        tx.execute(
            "INSERT OR IGNORE INTO rollup_marks (id, since, until) VALUES (1, ?1, ?1)",
            [since],
        )?;
        if newest.is_some() {
            tracing::info!(
                "history upgraded to schema 2: per-minute rollups from {} on",
                Timestamp(since)
            );
        }
    }
    if version < 3 {
        let indexed: bool = tx.query_row(
            "SELECT count(*) > 0 FROM sqlite_master WHERE name = 'samples_by_time'",
            [],
            |r| r.get(0),
        )?;
        if indexed {
            tx.execute_batch("DROP INDEX samples_by_time")?;
            tracing::info!("history upgraded to schema 3: the index on time alone is dropped");
        }
    }
    if version < 4 {
        // A file made by an older gateway has no column `fields` (a new file has it from
        // SCHEMA); adding a nullable column rewrites nothing.
        let has_fields: bool = tx.query_row(
            "SELECT count(*) > 0 FROM pragma_table_info('events') WHERE name = 'fields'",
            [],
            |r| r.get(0),
        )?;
        if !has_fields {
            tx.execute_batch("ALTER TABLE events ADD COLUMN fields TEXT")?;
            tracing::info!("history upgraded to schema 4: events keep their fields");
        }
    }
    if version < VERSION {
        tx.pragma_update(None, "user_version", VERSION)?;
    }
    tx.commit()
}

/// WAL, FULL sync (see the module docs), and patience with a busy database.
pub(super) fn configure(conn: &Connection) -> rusqlite::Result<()> {
    conn.pragma_update(None, "journal_mode", "WAL")?;
    conn.pragma_update(None, "synchronous", "FULL")?;
    conn.busy_timeout(Duration::from_secs(5))?;
    Ok(())
}

/// The writer's largest page cache, in KiB, while it commits large batches (a backlog,
/// the `store_ingest` bench): the hot leaf of every point in `samples_by_point_time` for
/// a few thousand points fits, so a batch does not read back the pages the last one wrote.
/// In the `store_ingest` bench (1,000 points, 20,000-row batches) 4 MiB cost 1.7× the CPU
/// per row of 16 MiB, 64 MiB gained nothing.
pub(super) const WRITER_CACHE_MAX_KIB: i64 = 16 * 1024;

/// The writer's page cache for the trickle of a running cell (a few hundred rows a batch),
/// in KiB: half SQLite's default. Pages missed are read back from the OS's file cache, not
/// the disk; 16 MiB here was 12 MiB of the gateway's resident memory at 1,000 stations.
/// A batch of a running cell adds to the leaves of `samples_by_point_time` of hundreds of
/// points, one leaf each, which no cache of this size holds once the file has grown; the
/// cache keeps the inner pages, which 1 MiB holds as well as 2.
pub(super) const WRITER_CACHE_MIN_KIB: i64 = 1024;

/// Cache per row of the batch being committed, in KiB: a 16,000-row batch gets the
/// largest cache.
const WRITER_CACHE_KIB_PER_ROW: i64 = 1;

/// The smallest batch for which the cache grows: half the default batch (20,000 rows),
/// which a writer gathers only behind a backlog or from more than 50,000 rows a second.
/// Below it the cache stays at its floor: a gateway's start (every point read, stored
/// and added to `points` for the first time, in batches of 2,000–5,000 rows at 1,000
/// stations) grew it to 5 MiB, and the 0.7 MiB it filled beyond the floor stayed in the
/// process's memory after the cache shrank back.
pub(super) const WRITER_CACHE_GROW_FROM_ROWS: usize = 10_000;

/// Batches in a row that want a smaller cache before the writer lowers it: the last,
/// short batch of a backlog does not give back the cache the next one needs.
const WRITER_CACHE_LOWER_AFTER: u32 = 10;

/// The writer's page-cache size, following the size of its batches (sans IO: it says
/// what `PRAGMA cache_size` should become; the writer applies it). It grows at once for
/// a large batch (from [`WRITER_CACHE_GROW_FROM_ROWS`] rows) and shrinks after
/// [`WRITER_CACHE_LOWER_AFTER`] smaller ones; SQLite frees the pages above a lowered size.
#[derive(Debug)]
pub(super) struct WriterCache {
    kib: i64,
    smaller: u32,
}

impl WriterCache {
    /// The cache a new connection starts with ([`configure_writer`] sets it).
    pub(super) fn new() -> Self {
        Self {
            kib: WRITER_CACHE_MIN_KIB,
            smaller: 0,
        }
    }

    /// The size in force, in KiB.
    pub(super) fn kib(&self) -> i64 {
        self.kib
    }

    /// Notes a batch of `rows` about to be committed; `Some(kib)` when the cache size must
    /// change to it before the batch.
    pub(super) fn for_batch(&mut self, rows: usize) -> Option<i64> {
        let wanted = if rows < WRITER_CACHE_GROW_FROM_ROWS {
            WRITER_CACHE_MIN_KIB
        } else {
            i64::try_from(rows)
                .unwrap_or(i64::MAX)
                .saturating_mul(WRITER_CACHE_KIB_PER_ROW)
                .clamp(WRITER_CACHE_MIN_KIB, WRITER_CACHE_MAX_KIB)
        };
        if wanted >= self.kib {
            self.smaller = 0;
            let grow = wanted > self.kib;
            self.kib = wanted;
            return grow.then_some(wanted);
        }
        self.smaller += 1;
        if self.smaller < WRITER_CACHE_LOWER_AFTER {
            return None;
        }
        self.smaller = 0;
        self.kib = wanted;
        Some(wanted)
    }
}

/// Pages the WAL may hold before the writer copies them back into the database file.
/// SQLite's 1000 (4 MB) checkpointed (with its own fsync) every few batches under load,
/// copying the same hot index pages again each time; 10,000 (40 MB) copies them once for
/// ten times as many commits (1.3–1.6× the rows/s in the `store_ingest` bench).
pub(super) const WAL_CHECKPOINT_PAGES: i64 = 10_000;

/// The writer's connection: [`configure`], plus its checkpoint size and its smallest
/// cache ([`WriterCache`] resizes it per batch), and no foreign-key checks: the writer
/// gives samples only point ids it has just read or inserted, and deletes no point, so
/// the check (a lookup in `points` for every sample, on by default in the bundled SQLite)
/// could never fail; without it a multi-row insert needs no statement journal
/// (`writer::insert_samples`).
pub(super) fn configure_writer(conn: &Connection) -> rusqlite::Result<()> {
    configure(conn)?;
    conn.pragma_update(None, "cache_size", -WRITER_CACHE_MIN_KIB)?;
    conn.pragma_update(None, "foreign_keys", false)?;
    conn.pragma_update(None, "wal_autocheckpoint", WAL_CHECKPOINT_PAGES)?;
    Ok(())
}

pub(super) fn read_sample(r: &rusqlite::Row<'_>) -> rusqlite::Result<HistorySample> {
    let number: Option<f64> = r.get(1)?;
    let text: Option<String> = r.get(2)?;
    Ok(HistorySample {
        t: Timestamp(r.get(0)?),
        value: number.map(Value::Number).or(text.map(Value::Text)),
        quality: Quality::from_code(r.get(3)?),
    })
}
