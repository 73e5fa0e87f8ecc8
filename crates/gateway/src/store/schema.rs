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
CREATE INDEX IF NOT EXISTS samples_by_time ON samples(t);
CREATE TABLE IF NOT EXISTS events (
    id      INTEGER PRIMARY KEY,
    t       INTEGER NOT NULL,
    kind    TEXT NOT NULL,
    line    TEXT,
    device  TEXT,
    point   TEXT,
    message TEXT NOT NULL
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
PRAGMA user_version = 1;
";

/// WAL, FULL sync (see the module docs), and patience with a busy database.
pub(super) fn configure(conn: &Connection) -> rusqlite::Result<()> {
    conn.pragma_update(None, "journal_mode", "WAL")?;
    conn.pragma_update(None, "synchronous", "FULL")?;
    conn.busy_timeout(Duration::from_secs(5))?;
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
