//! The read side: a small pool of read connections, which WAL lets read while the writer
//! writes, and the queries the API runs.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use rusqlite::{Connection, OptionalExtension, params};

use crate::point::PointId;
use crate::time::{Timestamp, duration_millis};

use super::rollup::{Aggregate, MINUTE_MS, Marks, aggregate_at, minute_of, next_minute};
use super::*;

/// A page of a point's changes oldest first, `from` included: point, from (or the last
/// page's time, if later), to, the last page's time and row, limit.
const OLDEST_FIRST_PAGE: &str = "SELECT t, value, text, quality, rowid FROM samples \
     WHERE point = ?1 AND t >= ?2 AND t < ?3 \
     AND (t > ?4 OR (t = ?4 AND rowid > ?5)) \
     ORDER BY t, rowid LIMIT ?6";

/// A page of a point's changes newest first, `to` included: point, from, to (or the last
/// page's time, if earlier), the last page's time and row, limit.
const NEWEST_FIRST_PAGE: &str = "SELECT t, value, text, quality, rowid FROM samples \
     WHERE point = ?1 AND t > ?2 AND t <= ?3 \
     AND (t < ?4 OR (t = ?4 AND rowid < ?5)) \
     ORDER BY t DESC, rowid DESC LIMIT ?6";

impl StoreHandle {
    /// Stored changes of `point` in `[from, to)`, raw or in buckets of `step`.
    ///
    /// Buckets hold the good numeric samples' mean, minimum, maximum and count. A step of
    /// whole minutes reads the per-minute rollups for the whole minutes they cover, and
    /// the samples only for the rest (the partial minutes at the ends, minutes still open,
    /// minutes from before the rollups); the answer is the same either way (see
    /// `rollup`).
    pub fn history(
        &self,
        point: &PointId,
        from: Timestamp,
        to: Timestamp,
        step: Option<Duration>,
    ) -> Result<History, StoreError> {
        self.history_with(point, from, to, step, Rollups::Use)
    }

    /// [`StoreHandle::history`] with or without the rollups: both must give the same
    /// answer, which the tests check.
    pub(super) fn history_with(
        &self,
        point: &PointId,
        from: Timestamp,
        to: Timestamp,
        step: Option<Duration>,
        rollups: Rollups,
    ) -> Result<History, StoreError> {
        self.readers.with(|conn| {
            // One snapshot: the marks, the rollups and the samples agree.
            let snapshot = conn.unchecked_transaction()?;
            let conn: &Connection = &snapshot;
            let id: Option<i64> = conn
                .query_row(
                    "SELECT id FROM points WHERE name = ?1",
                    [point.as_str()],
                    |r| r.get(0),
                )
                .optional()?;
            let step_ms = step.map(duration_millis).filter(|s| *s > 0);
            let empty = match step_ms {
                Some(_) => Series::Buckets(Vec::new()),
                None => Series::Samples(Vec::new()),
            };
            let mut history = History {
                point: point.clone(),
                from,
                to,
                step_ms,
                before: None,
                series: empty,
                truncated: false,
            };
            let Some(id) = id else {
                return Ok(history);
            };
            history.before = conn
                .query_row(
                    "SELECT t, value, text, quality FROM samples WHERE point = ?1 AND t < ?2 \
                     ORDER BY t DESC LIMIT 1",
                    params![id, from.0],
                    read_sample,
                )
                .optional()?;
            match step_ms {
                Some(step) => {
                    history.series = Series::Buckets(buckets(conn, id, from, to, step, rollups)?);
                }
                None => {
                    let mut stmt = conn.prepare_cached(
                        "SELECT t, value, text, quality FROM samples \
                         WHERE point = ?1 AND t >= ?2 AND t < ?3 ORDER BY t LIMIT ?4",
                    )?;
                    let limit = i64::try_from(MAX_RAW_SAMPLES + 1).unwrap_or(i64::MAX);
                    let mut samples = stmt
                        .query_map(params![id, from.0, to.0, limit], read_sample)?
                        .collect::<Result<Vec<_>, _>>()?;
                    if samples.len() > MAX_RAW_SAMPLES {
                        samples.truncate(MAX_RAW_SAMPLES);
                        history.truncated = true;
                    }
                    history.series = Series::Samples(samples);
                }
            }
            Ok(history)
        })
    }

    /// A page of `point`'s stored changes between `from` and `to` in `order` (see
    /// [`PageOrder`] for which end is included), those after `after` in that order, at
    /// most `limit`, each with its cursor.
    pub fn history_page(
        &self,
        point: &PointId,
        from: Timestamp,
        to: Timestamp,
        order: PageOrder,
        after: Option<SampleCursor>,
        limit: usize,
    ) -> Result<Vec<(SampleCursor, HistorySample)>, StoreError> {
        self.readers.with(|conn| {
            let Some(id) = point_row(conn, point)? else {
                return Ok(Vec::new());
            };
            let limit = i64::try_from(limit).unwrap_or(i64::MAX);
            let read = |r: &rusqlite::Row<'_>| {
                let sample = read_sample(r)?;
                let cursor = SampleCursor {
                    t: sample.t,
                    row: r.get(4)?,
                };
                Ok((cursor, sample))
            };
            // Before the first page, the cursor stands before every change, in `order`.
            let edge = match order {
                PageOrder::OldestFirst => i64::MIN,
                PageOrder::NewestFirst => i64::MAX,
            };
            let after = after.unwrap_or(SampleCursor {
                t: Timestamp(edge),
                row: edge,
            });
            let (sql, low, high) = match order {
                PageOrder::OldestFirst => (OLDEST_FIRST_PAGE, from.0.max(after.t.0), to.0),
                PageOrder::NewestFirst => (NEWEST_FIRST_PAGE, from.0, to.0.min(after.t.0)),
            };
            let rows = conn
                .prepare_cached(sql)?
                .query_map(params![id, low, high, after.t.0, after.row, limit], read)?
                .collect::<Result<Vec<_>, _>>()?;
            Ok(rows)
        })
    }

    /// `point`'s stored change nearest `t` on one side: the last at or before it
    /// (`later = false`), or the first at or after it.
    pub fn history_nearest(
        &self,
        point: &PointId,
        t: Timestamp,
        later: bool,
    ) -> Result<Option<HistorySample>, StoreError> {
        self.readers.with(|conn| {
            let Some(id) = point_row(conn, point)? else {
                return Ok(None);
            };
            let sql = if later {
                "SELECT t, value, text, quality FROM samples WHERE point = ?1 AND t >= ?2 \
                 ORDER BY t, rowid LIMIT 1"
            } else {
                "SELECT t, value, text, quality FROM samples WHERE point = ?1 AND t <= ?2 \
                 ORDER BY t DESC, rowid DESC LIMIT 1"
            };
            conn.prepare_cached(sql)?
                .query_row(params![id, t.0], read_sample)
                .optional()
        })
    }

    /// Each alarm's state as its last journal entry saved it: id and the entry's fields.
    pub fn alarm_states(&self) -> Result<Vec<(String, serde_json::Value)>, StoreError> {
        self.readers.with(|conn| {
            let mut stmt = conn.prepare_cached("SELECT id, fields FROM alarm_states")?;
            let rows = stmt.query_map([], |r| {
                let fields: String = r.get(1)?;
                Ok((
                    r.get::<_, String>(0)?,
                    serde_json::from_str(&fields).unwrap_or_default(),
                ))
            })?;
            rows.collect()
        })
    }

    /// The alarm journal: the alarm events (raised, cleared, changed) from `from` to `to`,
    /// of one alarm or device if given, newest first, at most `limit`.
    pub fn alarm_journal(
        &self,
        from: Timestamp,
        to: Timestamp,
        alarm: Option<&str>,
        device: Option<&str>,
        limit: usize,
    ) -> Result<Vec<EventRecord>, StoreError> {
        self.readers.with(|conn| {
            let mut stmt = conn.prepare_cached(
                "SELECT id, t, kind, line, device, point, message, fields FROM events \
                 WHERE t >= ?1 AND t < ?2 \
                 AND kind IN ('alarm_raised', 'alarm_cleared', 'alarm_changed') \
                 AND (?3 IS NULL OR json_extract(fields, '$.alarm') = ?3) \
                 AND (?4 IS NULL OR device = ?4) ORDER BY t DESC, id DESC LIMIT ?5",
            )?;
            let rows = stmt.query_map(
                params![
                    from.0,
                    to.0,
                    alarm,
                    device,
                    i64::try_from(limit).unwrap_or(i64::MAX)
                ],
                read_event,
            )?;
            rows.collect()
        })
    }

    /// Stored events, newest first.
    pub fn events(&self, filter: &EventFilter) -> Result<Vec<EventRecord>, StoreError> {
        self.readers.with(|conn| {
            let mut stmt = conn.prepare_cached(
                "SELECT id, t, kind, line, device, point, message, fields FROM events \
                 WHERE t >= ?1 AND t < ?2 AND (?3 IS NULL OR device = ?3) \
                 AND (?4 IS NULL OR kind = ?4) ORDER BY id DESC LIMIT ?5",
            )?;
            let rows = stmt.query_map(
                params![
                    filter.from.map_or(i64::MIN, |t| t.0),
                    filter.to.map_or(i64::MAX, |t| t.0),
                    filter.device,
                    filter.kind.map(EventKind::as_str),
                    i64::try_from(filter.limit).unwrap_or(i64::MAX),
                ],
                read_event,
            )?;
            rows.collect()
        })
    }

    /// Stored write attempts, newest first. Each text field is cut to
    /// [`AUDIT_FIELD_MAX`] characters as it is read (rows stored before fields were cut
    /// on writing can be large), and a value cut that way is shown as text.
    pub fn audit_log(
        &self,
        device: Option<&str>,
        limit: usize,
    ) -> Result<Vec<AuditRecord>, StoreError> {
        self.readers.with(|conn| {
            let mut stmt = conn.prepare_cached(
                "SELECT id, t, substr(client, 1, ?3), substr(device, 1, ?3), \
                 substr(point, 1, ?3), substr(old_value, 1, ?3), substr(new_value, 1, ?3), \
                 result, substr(detail, 1, ?3) \
                 FROM audit WHERE (?1 IS NULL OR device = ?1) ORDER BY id DESC LIMIT ?2",
            )?;
            let json = |text: Option<String>| {
                text.map(|t| {
                    serde_json::from_str::<serde_json::Value>(&t)
                        .unwrap_or(serde_json::Value::String(t))
                })
            };
            let rows = stmt.query_map(
                params![
                    device,
                    i64::try_from(limit).unwrap_or(i64::MAX),
                    AUDIT_FIELD_MAX
                ],
                |r| {
                    Ok(AuditRecord {
                        id: r.get(0)?,
                        t: Timestamp(r.get(1)?),
                        client: r.get(2)?,
                        device: r.get(3)?,
                        point: r.get(4)?,
                        old_value: json(r.get(5)?),
                        new_value: json(r.get(6)?).unwrap_or(serde_json::Value::Null),
                        result: r.get(7)?,
                        detail: r.get(8)?,
                    })
                },
            )?;
            rows.collect()
        })
    }

    /// The database's own consistency check (`PRAGMA integrity_check`): `ok` or the faults.
    pub fn integrity_check(&self) -> Result<String, StoreError> {
        self.readers.with(|conn| {
            let mut stmt = conn.prepare("PRAGMA integrity_check")?;
            let lines = stmt
                .query_map([], |r| r.get::<_, String>(0))?
                .collect::<Result<Vec<_>, _>>()?;
            Ok(lines.join("; "))
        })
    }
}

/// Whether a bucketed query may read the per-minute rollups.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Rollups {
    /// Where they cover the range (what the API does).
    Use,
    /// Never: every bucket from the samples.
    #[cfg_attr(not(test), allow(dead_code, reason = "the tests compare both paths"))]
    Ignore,
}

/// The buckets of `step` ms of point `id` in `[from, to)`: rollups for the whole minutes
/// they hold, samples for the rest. A bucket starts at `(t / step) * step` (SQLite's and
/// Rust's integer division, which truncates toward zero for times before 1970: those are
/// only ever answered from the samples).
fn buckets(
    conn: &Connection,
    id: i64,
    from: Timestamp,
    to: Timestamp,
    step: i64,
    rollups: Rollups,
) -> rusqlite::Result<Vec<Bucket>> {
    let mut acc: BTreeMap<i64, Aggregate> = BTreeMap::new();
    let whole_minutes = match rollups {
        Rollups::Use if step % MINUTE_MS == 0 && from.0 >= 0 => {
            let marks = Marks::read(conn)?;
            let start = next_minute(from.0).max(marks.since);
            let end = minute_of(to.0).min(marks.until);
            (start < end).then_some((start, end))
        }
        Rollups::Use | Rollups::Ignore => None,
    };
    match whole_minutes {
        Some((start, end)) => {
            add_samples(conn, id, from.0, start, step, &mut acc)?;
            let mut stmt = conn.prepare_cached(
                "SELECT minute, count, sum, min, max FROM minutes \
                 WHERE point = ?1 AND minute >= ?2 AND minute < ?3",
            )?;
            let mut rows = stmt.query(params![id, start, end])?;
            while let Some(r) = rows.next()? {
                let minute: i64 = r.get(0)?;
                add(&mut acc, (minute / step) * step, &aggregate_at(r, 1)?);
            }
            add_samples(conn, id, end, to.0, step, &mut acc)?;
        }
        None => add_samples(conn, id, from.0, to.0, step, &mut acc)?,
    }
    Ok(acc
        .into_iter()
        .map(|(t, a)| Bucket {
            t: Timestamp(t),
            avg: a.mean(),
            min: a.min,
            max: a.max,
            count: a.count,
        })
        .collect())
}

/// Adds the good numeric samples of point `id` in `[from, to)` to their buckets.
fn add_samples(
    conn: &Connection,
    id: i64,
    from: i64,
    to: i64,
    step: i64,
    acc: &mut BTreeMap<i64, Aggregate>,
) -> rusqlite::Result<()> {
    if from >= to {
        return Ok(());
    }
    let mut stmt = conn.prepare_cached(
        "SELECT t, value FROM samples WHERE point = ?1 AND t >= ?2 AND t < ?3 \
         AND quality = 0 AND value IS NOT NULL",
    )?;
    let mut rows = stmt.query(params![id, from, to])?;
    // Samples come in time order: one bucket is filled before the next starts.
    let mut current: Option<(i64, Aggregate)> = None;
    while let Some(r) = rows.next()? {
        let (t, x): (i64, f64) = (r.get(0)?, r.get(1)?);
        let bucket = (t / step) * step;
        match &mut current {
            Some((b, agg)) if *b == bucket => agg.add(x),
            _ => {
                if let Some((b, agg)) = current.replace((bucket, Aggregate::of(x))) {
                    add(acc, b, &agg);
                }
            }
        }
    }
    if let Some((b, agg)) = current {
        add(acc, b, &agg);
    }
    Ok(())
}

fn add(acc: &mut BTreeMap<i64, Aggregate>, bucket: i64, agg: &Aggregate) {
    match acc.get_mut(&bucket) {
        Some(a) => a.merge(agg),
        None => {
            acc.insert(bucket, agg.clone());
        }
    }
}

/// Read connections kept open between queries; more may run at once (the HTTP API's
/// queries, the MQTT backlog, OPC UA reads), and a connection beyond these is closed after
/// its query, so a burst leaves no open files or page caches behind.
pub(super) const MAX_IDLE_READERS: usize = 8;

/// Read connections, reused (at most [`MAX_IDLE_READERS`] kept).
#[derive(Debug)]
pub(super) struct ReaderPool {
    pub(super) path: PathBuf,
    pub(super) idle: Mutex<Vec<Connection>>,
    /// Whether the writer has opened the file (or the history is off).
    pub(super) shared: Arc<Shared>,
}

impl ReaderPool {
    pub(super) fn with<T>(
        &self,
        f: impl FnOnce(&Connection) -> rusqlite::Result<T>,
    ) -> Result<T, StoreError> {
        self.shared.wait_open()?;
        let sqlite = |source| StoreError::Sqlite {
            path: self.path.clone(),
            source,
        };
        let taken = self
            .idle
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .pop();
        let conn = match taken {
            Some(conn) => conn,
            None => {
                let conn = Connection::open(&self.path).map_err(sqlite)?;
                conn.busy_timeout(Duration::from_secs(5)).map_err(sqlite)?;
                conn.pragma_update(None, "query_only", true)
                    .map_err(sqlite)?;
                conn
            }
        };
        let result = f(&conn).map_err(sqlite);
        let mut idle = self.idle.lock().unwrap_or_else(PoisonError::into_inner);
        if idle.len() < MAX_IDLE_READERS {
            idle.push(conn);
        }
        result
    }
}

/// The row id of `point` in `points`, if it was ever stored.
fn point_row(conn: &Connection, point: &PointId) -> rusqlite::Result<Option<i64>> {
    conn.query_row(
        "SELECT id FROM points WHERE name = ?1",
        [point.as_str()],
        |r| r.get(0),
    )
    .optional()
}

/// An event row: `id, t, kind, line, device, point, message, fields`.
fn read_event(r: &rusqlite::Row<'_>) -> rusqlite::Result<EventRecord> {
    Ok(EventRecord {
        id: r.get(0)?,
        t: Timestamp(r.get(1)?),
        kind: r.get(2)?,
        line: r.get(3)?,
        device: r.get(4)?,
        point: r.get(5)?,
        message: r.get(6)?,
        fields: r
            .get::<_, Option<String>>(7)?
            .and_then(|text| serde_json::from_str(&text).ok())
            .unwrap_or_default(),
    })
}
