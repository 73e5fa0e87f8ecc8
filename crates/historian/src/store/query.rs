//! The read side: the queries of the plant's history API (the gateway's `/api/history`,
//! `/api/points`, `/api/events` and `/healthz` shapes).

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use tokio_postgres::Row;

use super::{Bucket, EventRow, PointRow, Quality, Store, StoreError, StoredSample};

impl Store {
    /// The samples of one point with `from <= t < to`, oldest first, at most `limit`.
    ///
    /// # Errors
    ///
    /// As [`Store::write`]'s, for the query.
    pub async fn raw(
        &self,
        node: &str,
        device: &str,
        point: &str,
        from: SystemTime,
        to: SystemTime,
        limit: usize,
    ) -> Result<Vec<StoredSample>, StoreError> {
        let limit = i64::try_from(limit).unwrap_or(i64::MAX);
        let (from, to) = (within_calendar(from), within_calendar(to));
        let rows = self
            .client
            .query(
                "SELECT s.t, s.value, s.text, s.quality FROM samples s \
                 JOIN points p ON p.id = s.point_id \
                 WHERE p.node = $1 AND p.device = $2 AND p.point = $3 \
                 AND s.t >= $4 AND s.t < $5 ORDER BY s.t LIMIT $6",
                &[&node, &device, &point, &from, &to, &limit],
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
        node: &str,
        device: &str,
        point: &str,
        at: SystemTime,
    ) -> Result<Option<StoredSample>, StoreError> {
        let at = within_calendar(at);
        let row = self
            .client
            .query_opt(
                "SELECT s.t, s.value, s.text, s.quality FROM samples s \
                 JOIN points p ON p.id = s.point_id \
                 WHERE p.node = $1 AND p.device = $2 AND p.point = $3 AND s.t < $4 \
                 ORDER BY s.t DESC LIMIT 1",
                &[&node, &device, &point, &at],
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
        node: &str,
        device: &str,
        point: &str,
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
                "SELECT date_bin(make_interval(secs => $6::float8 / 1000), s.t, \
                 timestamptz 'epoch') AS b, avg(s.value), min(s.value), max(s.value), count(*) \
                 FROM samples s JOIN points p ON p.id = s.point_id \
                 WHERE p.node = $1 AND p.device = $2 AND p.point = $3 \
                 AND s.t >= $4 AND s.t < $5 AND s.quality = 0 AND s.value IS NOT NULL \
                 GROUP BY b ORDER BY b",
                &[&node, &device, &point, &from, &to, &(step_ms as f64)],
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

    /// Whether the point (node, device, name) is known.
    ///
    /// # Errors
    ///
    /// As [`Store::raw`].
    pub async fn has_point(
        &self,
        node: &str,
        device: &str,
        point: &str,
    ) -> Result<bool, StoreError> {
        let row = self
            .client
            .query_opt(
                "SELECT 1 FROM points WHERE node = $1 AND device = $2 AND point = $3",
                &[&node, &device, &point],
            )
            .await
            .map_err(|e| StoreError::statement("looking a point up", e))?;
        Ok(row.is_some())
    }

    /// Every point, by node, device and name.
    ///
    /// # Errors
    ///
    /// As [`Store::raw`].
    pub async fn points(&self) -> Result<Vec<PointRow>, StoreError> {
        let rows = self
            .client
            .query(
                "SELECT node, device, point, datatype, unit, description, writable, \
                 write_min, write_max FROM points ORDER BY node, device, point",
                &[],
            )
            .await
            .map_err(|e| StoreError::statement("listing points", e))?;
        Ok(rows
            .iter()
            .map(|r| PointRow {
                node: r.get(0),
                device: r.get(1),
                point: r.get(2),
                datatype: r.get(3),
                unit: r.get(4),
                description: r.get(5),
                writable: r.get(6),
                write_min: r.get(7),
                write_max: r.get(8),
            })
            .collect())
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
                "SELECT node, device, point, line, t, kind, severity, message FROM events \
                 WHERE t >= $1 AND t < $2 ORDER BY t DESC, id DESC LIMIT $3",
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
        quality: Quality::from_code(r.get(3)),
    }
}
