//! The writer thread: batches of rows, commits, retention.

use std::collections::{HashMap, VecDeque};
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::sync::{Arc, mpsc};
use std::time::{Duration, Instant};

use rusqlite::{Connection, Transaction, params};

use crate::point::{DeviceId, PointId, Value};
use crate::time::Timestamp;

use super::*;

/// A row waiting for its commit.
pub(super) enum Row {
    Sample(Sample),
    Event(Event),
    Audit(AuditEntry),
}

pub(super) struct Writer {
    pub(super) conn: Connection,
    pub(super) path: PathBuf,
    pub(super) points: HashMap<String, i64>,
    pub(super) options: StoreOptions,
    pub(super) stats: Arc<StoreStats>,
    pub(super) pending: VecDeque<Row>,
    pub(super) oldest: Option<Instant>,
    pub(super) last_prune: Option<Instant>,
}

impl Writer {
    pub(super) fn run(mut self, rx: mpsc::Receiver<Command>) {
        self.prune_if_due(Timestamp::now());
        loop {
            let wait = match self.oldest {
                Some(oldest) => {
                    (oldest + self.options.batch_delay).saturating_duration_since(Instant::now())
                }
                None => self.options.prune_every.min(Duration::from_secs(60)),
            };
            match rx.recv_timeout(wait) {
                Ok(Command::Sample(sample)) => self.push(Row::Sample(sample)),
                Ok(Command::Event(event)) => self.push(Row::Event(event)),
                Ok(Command::Audit(entry)) => {
                    self.push(Row::Audit(entry));
                    let _ = self.commit();
                }
                Ok(Command::Flush(reply)) => {
                    let _ = reply.send(self.commit().map(|()| self.stats.rows_written()));
                }
                Ok(Command::Prune(now, reply)) => {
                    let result = self.commit().and_then(|()| self.prune(now));
                    let _ = reply.send(result);
                }
                Ok(Command::Shutdown) | Err(mpsc::RecvTimeoutError::Disconnected) => {
                    if let Err(e) = self.commit() {
                        tracing::error!(
                            "history: {} rows could not be committed at shutdown: {e}",
                            self.pending.len()
                        );
                    }
                    return;
                }
                Err(mpsc::RecvTimeoutError::Timeout) => {
                    let _ = self.commit();
                    self.prune_if_due(Timestamp::now());
                }
            }
        }
    }

    pub(super) fn push(&mut self, row: Row) {
        if self.pending.len() >= MAX_PENDING_ROWS {
            self.pending.pop_front();
            self.stats.rows_dropped.fetch_add(1, Ordering::Relaxed);
        }
        self.pending.push_back(row);
        self.oldest.get_or_insert_with(Instant::now);
        if self.pending.len() >= self.options.batch_rows {
            let _ = self.commit();
        }
    }

    /// Commits the pending rows in one transaction. On failure they stay pending.
    pub(super) fn commit(&mut self) -> Result<(), String> {
        if self.pending.is_empty() {
            return Ok(());
        }
        let mut rows = std::mem::take(&mut self.pending);
        match write_rows(&mut self.conn, &mut self.points, rows.make_contiguous()) {
            Ok(counts) => {
                self.oldest = None;
                let s = &self.stats;
                s.samples_written.fetch_add(counts[0], Ordering::Relaxed);
                s.events_written.fetch_add(counts[1], Ordering::Relaxed);
                s.audit_written.fetch_add(counts[2], Ordering::Relaxed);
                s.commits.fetch_add(1, Ordering::Relaxed);
                Ok(())
            }
            Err(e) => {
                self.stats.commit_errors.fetch_add(1, Ordering::Relaxed);
                tracing::error!("history {}: commit failed: {e}", self.path.display());
                // Ids handed out inside the failed transaction are gone with it.
                self.points = load_points(&self.conn).unwrap_or_default();
                self.pending = rows;
                Err(e.to_string())
            }
        }
    }

    pub(super) fn prune_if_due(&mut self, now: Timestamp) {
        let due = self
            .last_prune
            .is_none_or(|last| last.elapsed() >= self.options.prune_every);
        if due {
            self.last_prune = Some(Instant::now());
            if let Err(e) = self.prune(now) {
                tracing::error!("history {}: retention failed: {e}", self.path.display());
            }
        }
    }

    pub(super) fn prune(&mut self, now: Timestamp) -> Result<u64, String> {
        let cutoff = now.minus(self.options.retain).0;
        let mut deleted = 0u64;
        let ids: Vec<i64> = self.points.values().copied().collect();
        for id in ids {
            let n = self
                .conn
                .execute(
                    "DELETE FROM samples WHERE point = ?1 AND t < ?2",
                    params![id, cutoff],
                )
                .map_err(|e| e.to_string())?;
            deleted += n as u64;
        }
        let n = self
            .conn
            .execute("DELETE FROM events WHERE t < ?1", [cutoff])
            .map_err(|e| e.to_string())?;
        deleted += n as u64;
        self.stats.rows_pruned.fetch_add(deleted, Ordering::Relaxed);
        Ok(deleted)
    }
}

/// Writes rows in one transaction; returns how many samples, events and audit rows.
pub(super) fn write_rows(
    conn: &mut Connection,
    points: &mut HashMap<String, i64>,
    rows: &[Row],
) -> rusqlite::Result<[u64; 3]> {
    let tx = conn.transaction()?;
    let mut counts = [0u64; 3];
    for row in rows {
        match row {
            Row::Sample(s) => {
                let id = point_id(&tx, points, s.point.as_str())?;
                let (number, text) = match &s.value {
                    Some(Value::Number(n)) => (Some(*n), None),
                    Some(Value::Text(t)) => (None, Some(t.as_str())),
                    None => (None, None),
                };
                tx.prepare_cached(
                    "INSERT INTO samples (point, t, value, text, quality) VALUES (?1, ?2, ?3, ?4, ?5)",
                )?
                .execute(params![id, s.t.0, number, text, s.quality.code()])?;
                counts[0] += 1;
            }
            Row::Event(e) => {
                tx.prepare_cached(
                    "INSERT INTO events (t, kind, line, device, point, message) VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
                )?
                .execute(params![
                    e.t.0,
                    e.kind.as_str(),
                    e.line,
                    e.device.as_ref().map(DeviceId::as_str),
                    e.point.as_ref().map(PointId::as_str),
                    e.message
                ])?;
                counts[1] += 1;
            }
            Row::Audit(a) => {
                let old = a.old.as_ref().and_then(|v| serde_json::to_string(v).ok());
                tx.prepare_cached(
                    "INSERT INTO audit (t, client, device, point, old_value, new_value, result, detail) \
                     VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8)",
                )?
                .execute(params![
                    a.t.0,
                    a.client,
                    a.device,
                    a.point,
                    old,
                    a.new.to_string(),
                    a.result.as_str(),
                    a.detail
                ])?;
                counts[2] += 1;
            }
        }
    }
    tx.commit()?;
    Ok(counts)
}

pub(super) fn point_id(
    tx: &Transaction<'_>,
    points: &mut HashMap<String, i64>,
    name: &str,
) -> rusqlite::Result<i64> {
    if let Some(id) = points.get(name) {
        return Ok(*id);
    }
    tx.prepare_cached("INSERT INTO points (name) VALUES (?1)")?
        .execute([name])?;
    let id = tx.last_insert_rowid();
    points.insert(name.to_owned(), id);
    Ok(id)
}
