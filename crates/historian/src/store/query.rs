//! The read side: the queries of the plant's history API (the gateway's `/api/history`,
//! `/api/points`, `/api/events` and `/healthz` shapes).

use std::collections::HashSet;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use tokio_postgres::Row;

use super::{Bucket, EventRow, PointRow, Store, StoreError, StoredSample};

/// A stored point found by its plant id.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FoundPoint {
    /// Its row id (what [`Store::raw`], [`Store::last_before`] and [`Store::buckets`] take).
    pub id: i32,
    /// The Sparkplug group (`""` for a point stored before groups were recorded).
    pub group: String,
    /// The edge node.
    pub node: String,
    /// The device (`""` for the node's own metrics).
    pub device: String,
    /// The metric's name.
    pub point: String,
}

impl Store {
    /// The points a plant point id names: `NODE/DEVICE.POINT` (a node's own metric
    /// `NODE/.POINT`), or `GROUP/NODE/DEVICE.POINT`. More than one when the node id is in
    /// several groups, or when a device id holds a `.` (`a.b` + `c` and `a` + `b.c`); none
    /// for an unknown point.
    ///
    /// # Errors
    ///
    /// As [`Store::raw`].
    pub async fn find_points(&self, id: &str) -> Result<Vec<FoundPoint>, StoreError> {
        let Some((first, rest)) = id.split_once('/') else {
            return Ok(Vec::new());
        };
        // Ids hold no `/`, so a second `/` before the device's `.` can only be the group
        // form's; a metric's name may hold `/` (`Node Control/Rebirth`), so both forms
        // are asked for and the rows say which matched.
        let grouped = rest.split_once('/');
        let rows = self
            .client
            .query(
                "SELECT id, group_id, node, device, point FROM points \
                 WHERE (node = $1 AND device || '.' || point = $2) \
                 OR (group_id = $3 AND node = $4 AND device || '.' || point = $5) \
                 ORDER BY group_id, node, device, point LIMIT 100",
                &[
                    &first,
                    &rest,
                    &grouped.map(|_| first),
                    &grouped.map(|g| g.0),
                    &grouped.map(|g| g.1),
                ],
            )
            .await
            .map_err(|e| StoreError::statement("looking a point up", e))?;
        Ok(rows
            .iter()
            .map(|r| FoundPoint {
                id: r.get(0),
                group: r.get(1),
                node: r.get(2),
                device: r.get(3),
                point: r.get(4),
            })
            .collect())
    }

    /// The samples of one point with `from <= t < to`, oldest first, at most `limit`.
    ///
    /// # Errors
    ///
    /// As [`Store::write`]'s, for the query.
    pub async fn raw(
        &self,
        point: i32,
        from: SystemTime,
        to: SystemTime,
        limit: usize,
    ) -> Result<Vec<StoredSample>, StoreError> {
        let limit = i64::try_from(limit).unwrap_or(i64::MAX);
        let (from, to) = (within_calendar(from), within_calendar(to));
        let rows = self
            .client
            .query(
                "SELECT t, value, text, quality FROM samples \
                 WHERE point_id = $1 AND t >= $2 AND t < $3 ORDER BY t LIMIT $4",
                &[&point, &from, &to, &limit],
            )
            .await
            .map_err(|e| StoreError::statement("reading a point's samples", e))?;
        Ok(rows.iter().map(stored_sample).collect())
    }

    /// The last sample of one point before `at`: the value it held when a range starts.
    ///
    /// # Errors
    ///
    /// As [`Store::raw`].
    pub async fn last_before(
        &self,
        point: i32,
        at: SystemTime,
    ) -> Result<Option<StoredSample>, StoreError> {
        let at = within_calendar(at);
        let row = self
            .client
            .query_opt(
                "SELECT t, value, text, quality FROM samples \
                 WHERE point_id = $1 AND t < $2 ORDER BY t DESC LIMIT 1",
                &[&point, &at],
            )
            .await
            .map_err(|e| StoreError::statement("reading a point's sample before a time", e))?;
        Ok(row.as_ref().map(stored_sample))
    }

    /// The good numeric samples of one point with `from <= t < to` in buckets of `step`
    /// (at least 1 ms, at most the calendar) aligned to multiples of the step since the epoch, oldest first;
    /// buckets without a sample are left out (the value held).
    ///
    /// # Errors
    ///
    /// As [`Store::raw`].
    pub async fn buckets(
        &self,
        point: i32,
        from: SystemTime,
        to: SystemTime,
        step: Duration,
    ) -> Result<Vec<Bucket>, StoreError> {
        // Longer than the calendar is one bucket anyway (and would overflow an interval).
        let step_ms = i64::try_from(step.as_millis())
            .unwrap_or(i64::MAX)
            .clamp(1, LAST_OF_9999_SECS as i64 * 1000);
        let (from, to) = (within_calendar(from), within_calendar(to));
        let rows = self
            .client
            .query(
                "SELECT date_bin(make_interval(secs => $4::float8 / 1000), t, \
                 timestamptz 'epoch') AS b, avg(value), min(value), max(value), count(*) \
                 FROM samples \
                 WHERE point_id = $1 AND t >= $2 AND t < $3 AND quality = 0 \
                 AND value IS NOT NULL \
                 GROUP BY b ORDER BY b",
                &[&point, &from, &to, &(step_ms as f64)],
            )
            .await
            .map_err(|e| StoreError::statement("reading a point's buckets", e))?;
        Ok(rows
            .iter()
            .map(|r| Bucket {
                t: r.get(0),
                avg: r.get(1),
                min: r.get(2),
                max: r.get(3),
                count: r.get::<_, i64>(4).unsigned_abs(),
            })
            .collect())
    }

    /// The points (of `node` only, when given) by node, device, name and group: `limit`
    /// of them after the first `offset`, and how many there are in all.
    ///
    /// # Errors
    ///
    /// As [`Store::raw`].
    pub async fn points(
        &self,
        node: Option<&str>,
        offset: usize,
        limit: usize,
    ) -> Result<(Vec<PointRow>, u64), StoreError> {
        let offset = i64::try_from(offset).unwrap_or(i64::MAX);
        let limit = i64::try_from(limit).unwrap_or(i64::MAX);
        let rows = self
            .client
            .query(
                "SELECT group_id, node, device, point, datatype, unit, description, writable, \
                 write_min, write_max FROM points WHERE $1::text IS NULL OR node = $1 \
                 ORDER BY node, device, point, group_id OFFSET $2 LIMIT $3",
                &[&node, &offset, &limit],
            )
            .await
            .map_err(|e| StoreError::statement("listing points", e))?;
        let total: i64 = self
            .client
            .query_one(
                "SELECT count(*) FROM points WHERE $1::text IS NULL OR node = $1",
                &[&node],
            )
            .await
            .map_err(|e| StoreError::statement("counting points", e))?
            .get(0);
        let points = rows
            .iter()
            .map(|r| PointRow {
                group: r.get(0),
                node: r.get(1),
                device: r.get(2),
                point: r.get(3),
                datatype: r.get(4),
                unit: r.get(5),
                description: r.get(6),
                writable: r.get(7),
                write_min: r.get(8),
                write_max: r.get(9),
            })
            .collect();
        Ok((points, total.unsigned_abs()))
    }

    /// The edge node ids that have points in more than one Sparkplug group (their points
    /// need the plant id's `GROUP/` form).
    ///
    /// # Errors
    ///
    /// As [`Store::raw`].
    pub async fn nodes_in_several_groups(&self) -> Result<HashSet<String>, StoreError> {
        let rows = self
            .client
            .query(
                "SELECT node FROM points GROUP BY node HAVING count(DISTINCT group_id) > 1",
                &[],
            )
            .await
            .map_err(|e| StoreError::statement("listing nodes in several groups", e))?;
        Ok(rows.iter().map(|r| r.get(0)).collect())
    }

    /// The events with `from <= t < to`, newest first, at most `limit`.
    ///
    /// # Errors
    ///
    /// As [`Store::raw`].
    pub async fn events(
        &self,
        from: SystemTime,
        to: SystemTime,
        limit: usize,
    ) -> Result<Vec<EventRow>, StoreError> {
        let limit = i64::try_from(limit).unwrap_or(i64::MAX);
        let (from, to) = (within_calendar(from), within_calendar(to));
        let rows = self
            .client
            .query(
                "SELECT node, device, point, line, t, kind, severity, message, group_id, \
                 fields::text FROM events WHERE t >= $1 AND t < $2 ORDER BY t DESC, id DESC LIMIT $3",
                &[&from, &to, &limit],
            )
            .await
            .map_err(|e| StoreError::statement("listing events", e))?;
        Ok(rows
            .iter()
            .map(|r| EventRow {
                node: r.get(0),
                device: r.get(1),
                point: r.get(2),
                line: r.get(3),
                t: r.get(4),
                kind: r.get(5),
                severity: r.get(6),
                message: r.get(7),
                group: r.get(8),
                fields: r.get(9),
            })
            .collect())
    }

    /// How many samples are stored (for `/healthz`). Exact, so it reads every partition:
    /// on a large history prefer the runtime's own count of [`Written::samples`].
    ///
    /// [`Written::samples`]: super::Written::samples
    ///
    /// # Errors
    ///
    /// As [`Store::raw`].
    pub async fn count_samples(&self) -> Result<u64, StoreError> {
        let row = self
            .client
            .query_one("SELECT count(*) FROM samples", &[])
            .await
            .map_err(|e| StoreError::statement("counting samples", e))?;
        Ok(row.get::<_, i64>(0).unsigned_abs())
    }
}

/// The last instant of 9999 in seconds since the epoch.
const LAST_OF_9999_SECS: u64 = 253_402_300_799;

/// `t` moved into 1970–9999: the times a query may name. The client's conversion
/// overflows far beyond PostgreSQL's range (and nothing is stored outside 2000 to
/// tomorrow), so a range is cut to the calendar instead of failing.
fn within_calendar(t: SystemTime) -> SystemTime {
    t.clamp(
        UNIX_EPOCH,
        UNIX_EPOCH + Duration::from_secs(LAST_OF_9999_SECS),
    )
}

fn stored_sample(r: &Row) -> StoredSample {
    StoredSample {
        t: r.get(0),
        value: r.get(1),
        text: r.get(2),
        quality: super::rows::quality_of_stored(r.get(3)),
    }
}
