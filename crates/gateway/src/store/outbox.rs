//! Messages an interface has made and its receiver has not yet accepted, kept across
//! restarts: the IPC-CFX link's, whose messages carry what happened over time (a state's
//! duration, a fault's pairing) and cannot be made again from a window of the history.
//!
//! Each channel (an interface's name) has its rows in the `outbox` table, numbered in the
//! order they were made (`AUTOINCREMENT`: a number is never used twice, so a reader's "sent
//! up to" stays valid when every row is gone), and one *memory* in `outbox_memory`: what
//! made the messages must know after a restart (the stations' states and open faults). A
//! batch of messages and the memory that made them are committed in one transaction, with
//! the history's `synchronous=FULL`: what [`Outbox::keep`] returned from survives a
//! `kill -9` and a power cut. Rows are removed when the receiver has accepted them
//! ([`Outbox::taken`]; that commit is not synced: losing it sends a message again, with its
//! id, which a receiver drops). At most `max` rows are kept per channel, the oldest dropped
//! first and counted.

use std::path::{Path, PathBuf};

use rusqlite::{Connection, OptionalExtension, params};

use super::StoreError;

const CREATE: &str = "
    CREATE TABLE IF NOT EXISTS outbox (
        seq INTEGER PRIMARY KEY AUTOINCREMENT,
        channel TEXT NOT NULL,
        body BLOB NOT NULL
    );
    CREATE INDEX IF NOT EXISTS outbox_by_channel ON outbox (channel, seq);
    CREATE TABLE IF NOT EXISTS outbox_memory (
        channel TEXT PRIMARY KEY,
        memory TEXT NOT NULL
    );";

/// One channel's kept messages, on a connection of its own.
#[derive(Debug)]
pub struct Outbox {
    path: PathBuf,
    conn: Connection,
    channel: String,
    /// Rows kept (only this outbox writes the channel: the data directory is locked).
    len: u64,
}

impl Outbox {
    /// The channel `channel` of the history database in `dir` (created if needed).
    pub fn open(dir: &Path, channel: &str) -> Result<Self, StoreError> {
        let (path, conn) = super::settings::connect(dir)?;
        Self::with(path, conn, channel)
    }

    /// A channel kept in memory only, for when the data directory cannot be used: the same
    /// order and bounds, without the restarts.
    pub fn in_memory(channel: &str) -> Result<Self, StoreError> {
        let path = PathBuf::from(":memory:");
        let conn = Connection::open_in_memory().map_err(|source| StoreError::Sqlite {
            path: path.clone(),
            source,
        })?;
        Self::with(path, conn, channel)
    }

    fn with(path: PathBuf, conn: Connection, channel: &str) -> Result<Self, StoreError> {
        let mut outbox = Self {
            path,
            conn,
            channel: channel.to_owned(),
            len: 0,
        };
        outbox
            .conn
            .execute_batch(CREATE)
            .map_err(|e| outbox.err(e))?;
        outbox.len = outbox
            .conn
            .query_row(
                "SELECT count(*) FROM outbox WHERE channel = ?1",
                [&outbox.channel],
                |r| r.get(0),
            )
            .map_err(|e| outbox.err(e))?;
        Ok(outbox)
    }

    /// The channel's memory, as last kept.
    pub fn memory(&self) -> Result<Option<String>, StoreError> {
        self.conn
            .query_row(
                "SELECT memory FROM outbox_memory WHERE channel = ?1",
                [&self.channel],
                |r| r.get(0),
            )
            .optional()
            .map_err(|e| self.err(e))
    }

    /// Keeps `messages` (in order) and, if given, the memory that made them, in one
    /// transaction committed when this returns; then drops the oldest rows past `max`.
    /// Returns how many were dropped.
    pub fn keep(
        &mut self,
        messages: &[Vec<u8>],
        memory: Option<&str>,
        max: u64,
    ) -> Result<u64, StoreError> {
        let over = (self.len + messages.len() as u64).saturating_sub(max);
        let tx = self
            .conn
            .transaction()
            .map_err(|source| StoreError::Sqlite {
                path: self.path.clone(),
                source,
            })?;
        let write = |tx: &rusqlite::Transaction<'_>| -> rusqlite::Result<()> {
            let mut insert =
                tx.prepare_cached("INSERT INTO outbox (channel, body) VALUES (?1, ?2)")?;
            for body in messages {
                insert.execute(params![self.channel, body])?;
            }
            if let Some(memory) = memory {
                tx.execute(
                    "INSERT INTO outbox_memory (channel, memory) VALUES (?1, ?2)
                     ON CONFLICT(channel) DO UPDATE SET memory = excluded.memory",
                    params![self.channel, memory],
                )?;
            }
            if over > 0 {
                tx.execute(
                    "DELETE FROM outbox WHERE seq IN
                     (SELECT seq FROM outbox WHERE channel = ?1 ORDER BY seq LIMIT ?2)",
                    params![self.channel, over],
                )?;
            }
            Ok(())
        };
        let done = write(&tx).and_then(|()| tx.commit());
        done.map_err(|e| self.err(e))?;
        self.len = self.len + messages.len() as u64 - over;
        Ok(over)
    }

    /// Up to `limit` rows after number `after` (0: from the first), oldest first.
    pub fn waiting(&self, after: i64, limit: usize) -> Result<Vec<(i64, Vec<u8>)>, StoreError> {
        let read = || -> rusqlite::Result<Vec<(i64, Vec<u8>)>> {
            let mut select = self.conn.prepare_cached(
                "SELECT seq, body FROM outbox WHERE channel = ?1 AND seq > ?2 ORDER BY seq LIMIT ?3",
            )?;
            let rows = select.query_map(
                params![
                    self.channel,
                    after,
                    i64::try_from(limit).unwrap_or(i64::MAX)
                ],
                |r| Ok((r.get(0)?, r.get(1)?)),
            )?;
            rows.collect()
        };
        read().map_err(|e| self.err(e))
    }

    /// The receiver accepted every row up to number `through`: they are removed.
    pub fn taken(&mut self, through: i64) -> Result<(), StoreError> {
        let remove = || -> rusqlite::Result<usize> {
            // Not synced: a removal lost to a power cut sends a message again, with its id.
            self.conn.pragma_update(None, "synchronous", "NORMAL")?;
            let removed = self.conn.execute(
                "DELETE FROM outbox WHERE channel = ?1 AND seq <= ?2",
                params![self.channel, through],
            );
            self.conn.pragma_update(None, "synchronous", "FULL")?;
            removed
        };
        let removed = remove().map_err(|e| self.err(e))?;
        self.len = self.len.saturating_sub(removed as u64);
        Ok(())
    }

    /// Rows kept.
    pub fn len(&self) -> u64 {
        self.len
    }

    /// Whether no row is kept.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    fn err(&self, source: rusqlite::Error) -> StoreError {
        StoreError::Sqlite {
            path: self.path.clone(),
            source,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bodies(rows: &[(i64, Vec<u8>)]) -> Vec<&[u8]> {
        rows.iter().map(|(_, b)| b.as_slice()).collect()
    }

    #[test]
    fn kept_messages_and_memory_are_found_by_a_new_connection_in_order() {
        let dir = tempfile::tempdir().unwrap();
        let mut outbox = Outbox::open(dir.path(), "cfx").unwrap();
        outbox
            .keep(&[b"one".to_vec(), b"two".to_vec()], Some("m1"), 100)
            .unwrap();
        outbox.keep(&[b"three".to_vec()], None, 100).unwrap();
        drop(outbox);

        let again = Outbox::open(dir.path(), "cfx").unwrap();
        assert_eq!(again.len(), 3);
        assert_eq!(again.memory().unwrap().as_deref(), Some("m1"));
        let rows = again.waiting(0, 10).unwrap();
        assert_eq!(bodies(&rows), [&b"one"[..], b"two", b"three"]);
        assert_eq!(bodies(&again.waiting(rows[0].0, 1).unwrap()), [&b"two"[..]]);
        assert!(Outbox::open(dir.path(), "other").unwrap().is_empty());
    }

    #[test]
    fn taken_rows_are_gone_and_numbers_are_never_used_again() {
        let mut outbox = Outbox::in_memory("cfx").unwrap();
        outbox
            .keep(&[b"a".to_vec(), b"b".to_vec()], None, 100)
            .unwrap();
        let rows = outbox.waiting(0, 10).unwrap();
        outbox.taken(rows[1].0).unwrap();
        assert!(outbox.is_empty());
        outbox.keep(&[b"c".to_vec()], None, 100).unwrap();
        let next = outbox.waiting(rows[1].0, 10).unwrap();
        assert_eq!(bodies(&next), [&b"c"[..]]);
        assert!(next[0].0 > rows[1].0);
    }

    #[test]
    fn past_its_bound_the_oldest_rows_are_dropped_and_counted() {
        let mut outbox = Outbox::in_memory("cfx").unwrap();
        assert_eq!(
            outbox
                .keep(&[b"1".to_vec(), b"2".to_vec(), b"3".to_vec()], None, 2)
                .unwrap(),
            1
        );
        assert_eq!(outbox.keep(&[b"4".to_vec()], None, 2).unwrap(), 1);
        assert_eq!(bodies(&outbox.waiting(0, 10).unwrap()), [&b"3"[..], b"4"]);
        assert_eq!(outbox.len(), 2);
    }
}
