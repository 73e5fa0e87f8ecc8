//! Store and forward: what reached the broker, and the stored changes to send after an
//! outage.
//!
//! The outbox is the history itself. Every value change the gateway publishes is also a
//! row in the history database, committed within 200 ms and kept by a `kill -9`; so the
//! publisher only has to remember how far the broker has certainly got (the *forwarded*
//! mark, a read time kept in the database's `settings` table) and, after an outage or a
//! restart, send the stored changes after it (oldest first, at most `max_backlog` of the
//! newest) before going live again.
//!
//! Births, data and deaths go out with QoS 0, so the broker acknowledges nothing. What it
//! has certainly received is read from the keep-alive: rumqttc sends a PINGREQ every
//! keep-alive whatever else it sends, the packets of one connection arrive in order, and the
//! broker answers a PINGREQ only after it has read what came before. [`Delivery`] numbers
//! the publishes handed to the client; the client's event loop counts the publishes it
//! wrote and reports the count with each PINGREQ: when its PINGRESP arrives, everything
//! written before it has arrived. A clean DISCONNECT confirms everything written before it
//! in the same way.
//!
//! The stored changes sent after an outage start [`MARGIN`] before the mark: changes read on
//! different lines reach the change stream in about, not exactly, their time order. A
//! subscriber may see a change twice across an outage (at least once, never lost); both
//! copies carry the same read time.

use std::collections::VecDeque;
use std::sync::Arc;
use std::time::Duration;

use crate::cell::Cell;
use crate::store::{ChangeCursor, ChangeKey, StoredChange};
use crate::time::{Timestamp, duration_millis};

/// How far before the forwarded mark the stored changes are sent again.
pub const MARGIN: Duration = Duration::from_secs(1);
/// Stored changes read from the database at a time.
pub const PAGE: usize = 5_000;
/// Keys of stored changes read ahead at a time (16 bytes each): the history has no index on
/// time alone and pays a seek a point for each window of time it reads (`store::changes`),
/// so it reads many pages' keys at once.
pub const KEYS_AHEAD: usize = 50_000;

/// The key of the forwarded mark in the database's `settings` table.
pub const FORWARDED_KEY: &str = "mqtt.forwarded_until";

/// What the broker has certainly received, from the client's view of one connection.
///
/// Each publish handed to the client is numbered (0, 1, …, per connection) with the latest
/// read time among the changes it holds; the client's event loop counts the publishes it
/// has written and reports the count with each PINGREQ and the DISCONNECT.
#[derive(Debug)]
pub struct Delivery {
    /// Publishes handed to the client in this connection.
    handed: u64,
    /// The latest read time handed to the client in this connection.
    latest_handed: Option<Timestamp>,
    /// (number, latest read time) of publishes holding changes, not yet confirmed.
    unconfirmed: VecDeque<(u64, Timestamp)>,
    /// Publishes written when the last PINGREQ went out, if its answer is awaited.
    at_ping: Option<u64>,
    /// The mark: every change read at or before it has reached the broker.
    forwarded: Timestamp,
}

impl Delivery {
    /// Starts from the mark `forwarded` (read from the database, or the start time).
    pub fn new(forwarded: Timestamp) -> Self {
        Self {
            handed: 0,
            latest_handed: None,
            unconfirmed: VecDeque::new(),
            at_ping: None,
            forwarded,
        }
    }

    /// The mark.
    pub fn forwarded(&self) -> Timestamp {
        self.forwarded
    }

    /// A publish holding changes read up to `latest` (none for births and deaths) was
    /// handed to the client.
    pub fn handed(&mut self, latest: Option<Timestamp>) {
        if let Some(t) = latest {
            self.unconfirmed.push_back((self.handed, t));
            self.latest_handed = Some(self.latest_handed.map_or(t, |l| l.max(t)));
        }
        self.handed += 1;
    }

    /// Where a new birth cycle in this connection resumes the stored changes: the latest
    /// read time handed to the client, else the mark.
    pub fn catch_up_from(&self) -> Timestamp {
        self.latest_handed.unwrap_or(self.forwarded)
    }

    /// The client wrote a PINGREQ after writing `written` publishes.
    pub fn wrote_ping(&mut self, written: u64) {
        self.at_ping = Some(written);
    }

    /// The broker answered the PINGREQ: returns the new mark if it moved.
    pub fn ping_answered(&mut self) -> Option<Timestamp> {
        let written = self.at_ping.take()?;
        self.confirm(written)
    }

    /// The client wrote the DISCONNECT after `written` publishes, and the connection was
    /// closed cleanly: returns the new mark if it moved.
    pub fn closed_cleanly(&mut self, written: u64) -> Option<Timestamp> {
        self.confirm(written)
    }

    /// The connection is gone: nothing unconfirmed counts any more, and the next
    /// connection numbers its publishes from 0.
    pub fn lost(&mut self) {
        self.handed = 0;
        self.latest_handed = None;
        self.unconfirmed.clear();
        self.at_ping = None;
    }

    /// The mark goes back to `at` at the latest (a primary host that went offline did not
    /// see what the broker got before it noticed): returns the new mark if it moved. What
    /// this connection published is no longer confirmed by a later PINGRESP or the clean
    /// DISCONNECT that follows: the broker got it, the host may not have, and confirming
    /// it would move the mark forward past the rewind again.
    pub fn rewind_to(&mut self, at: Timestamp) -> Option<Timestamp> {
        self.unconfirmed.clear();
        self.at_ping = None;
        self.latest_handed = None;
        (at < self.forwarded).then(|| {
            self.forwarded = at;
            at
        })
    }

    /// The first `written` publishes have arrived.
    fn confirm(&mut self, written: u64) -> Option<Timestamp> {
        let mut latest = None;
        while let Some(&(number, t)) = self.unconfirmed.front() {
            if number >= written {
                break;
            }
            latest = Some(latest.map_or(t, |l: Timestamp| l.max(t)));
            self.unconfirmed.pop_front();
        }
        let to = latest?;
        (to > self.forwarded).then(|| {
            self.forwarded = to;
            to
        })
    }
}

/// The stored changes to send after an outage, read page by page.
#[derive(Debug)]
pub struct Backlog {
    cell: Arc<Cell>,
    /// Where the next keys are read from.
    cursor: ChangeCursor,
    /// Keys read, not yet sent.
    ahead: VecDeque<ChangeKey>,
    /// Changes not sent because of `max_backlog`.
    pub skipped: u64,
    /// Changes to send.
    pub total: u64,
}

impl Backlog {
    /// The changes read after `MARGIN` before `forwarded` and up to `until`, at most the
    /// newest `max`. Commits what the history has queued first, so every change before
    /// `until` is there.
    pub async fn open(
        cell: &Arc<Cell>,
        forwarded: Timestamp,
        until: Timestamp,
        max: u64,
    ) -> Result<Self, String> {
        cell.store()
            .flush()
            .await
            .map_err(|e| format!("the history cannot be committed: {e}"))?;
        let from = ChangeKey::before(Timestamp(forwarded.0 - duration_millis(MARGIN) + 1));
        let store = cell.store().clone();
        let (count, start) =
            tokio::task::spawn_blocking(move || store.count_changes(from, until, max))
                .await
                .map_err(|e| e.to_string())?
                .map_err(|e| format!("the stored changes cannot be counted: {e}"))?;
        let (next, skipped, total) = match start {
            Some(start) => (start, count - max, max),
            None => (from, 0, count),
        };
        Ok(Self {
            cell: Arc::clone(cell),
            cursor: ChangeCursor::new(next, until),
            ahead: VecDeque::new(),
            skipped,
            total,
        })
    }

    /// [`Backlog::open`], with what goes wrong or is left out logged: `None` when the
    /// stored changes cannot be read (the live data goes on).
    pub async fn start(
        cell: &Arc<Cell>,
        forwarded: Timestamp,
        until: Timestamp,
        max: u64,
    ) -> Option<Self> {
        let backlog = match Self::open(cell, forwarded, until, max).await {
            Ok(b) => b,
            Err(e) => {
                tracing::warn!("MQTT: the stored changes cannot be sent: {e}");
                return None;
            }
        };
        if backlog.skipped > 0 {
            tracing::warn!(
                "MQTT: {} stored changes are older than the newest {max} (max_backlog) and \
                 are not sent",
                backlog.skipped
            );
        }
        if backlog.total > 0 {
            tracing::info!("MQTT: sending {} stored changes", backlog.total);
        }
        Some(backlog)
    }

    /// The next page, oldest first; empty when all were read or reading failed (logged).
    pub async fn next_page_or_end(&mut self) -> Vec<StoredChange> {
        self.next_page().await.unwrap_or_else(|e| {
            tracing::warn!("MQTT: sending stored changes stopped: {e}");
            Vec::new()
        })
    }

    /// The next page, oldest first; empty when all were read.
    pub async fn next_page(&mut self) -> Result<Vec<StoredChange>, String> {
        loop {
            if self.ahead.is_empty() {
                let store = self.cell.store().clone();
                let mut cursor = self.cursor;
                let (cursor, keys) = tokio::task::spawn_blocking(move || {
                    let keys = store.change_keys(&mut cursor, KEYS_AHEAD);
                    (cursor, keys)
                })
                .await
                .map_err(|e| e.to_string())?;
                let keys = keys.map_err(|e| format!("the stored changes cannot be read: {e}"))?;
                if keys.is_empty() {
                    return Ok(Vec::new());
                }
                self.cursor = cursor;
                self.ahead.extend(keys);
            }
            let keys: Vec<ChangeKey> = self.ahead.drain(..PAGE.min(self.ahead.len())).collect();
            let store = self.cell.store().clone();
            let page = tokio::task::spawn_blocking(move || store.changes_at(&keys))
                .await
                .map_err(|e| e.to_string())?
                .map_err(|e| format!("the stored changes cannot be read: {e}"))?;
            // Empty only if retention pruned every change of the page meanwhile.
            if !page.is_empty() {
                return Ok(page);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ping_answered_confirms_what_was_written_before_it() {
        let mut d = Delivery::new(Timestamp(100));
        d.handed(Some(Timestamp(200)));
        d.handed(None);
        d.handed(Some(Timestamp(300)));
        d.wrote_ping(2); // the third publish was written after the ping
        assert_eq!(d.ping_answered(), Some(Timestamp(200)));
        assert_eq!(d.forwarded(), Timestamp(200));
        d.wrote_ping(3);
        assert_eq!(d.ping_answered(), Some(Timestamp(300)));
    }

    #[test]
    fn a_birth_cycle_catches_up_from_the_latest_change_handed_else_from_the_mark() {
        let mut d = Delivery::new(Timestamp(100));
        assert_eq!(d.catch_up_from(), Timestamp(100));
        d.handed(Some(Timestamp(300)));
        d.handed(None);
        d.handed(Some(Timestamp(200)));
        assert_eq!(d.catch_up_from(), Timestamp(300));
        d.lost();
        assert_eq!(
            d.catch_up_from(),
            Timestamp(100),
            "a new connection starts at the mark"
        );
    }

    #[test]
    fn nothing_is_confirmed_without_an_answer_or_after_a_loss() {
        let mut d = Delivery::new(Timestamp(100));
        d.handed(Some(Timestamp(200)));
        assert_eq!(d.ping_answered(), None, "no ping was written");
        d.wrote_ping(1);
        d.lost();
        assert_eq!(d.ping_answered(), None);
        assert_eq!(d.closed_cleanly(1), None);
        assert_eq!(d.forwarded(), Timestamp(100));
        // The next connection numbers from 0 again.
        d.handed(Some(Timestamp(400)));
        d.wrote_ping(1);
        assert_eq!(d.ping_answered(), Some(Timestamp(400)));
    }

    #[test]
    fn a_clean_close_confirms_everything_written_and_the_mark_never_goes_back_by_itself() {
        let mut d = Delivery::new(Timestamp(500));
        d.handed(Some(Timestamp(400)));
        assert_eq!(d.closed_cleanly(1), None, "older than the mark");
        d.handed(Some(Timestamp(600)));
        assert_eq!(d.closed_cleanly(2), Some(Timestamp(600)));
        assert_eq!(d.rewind_to(Timestamp(550)), Some(Timestamp(550)));
        assert_eq!(d.rewind_to(Timestamp(700)), None);
    }

    #[test]
    fn a_rewind_for_a_host_gone_offline_is_not_undone_by_the_disconnect_that_follows_it() {
        let mut d = Delivery::new(Timestamp(100));
        // Live changes published, not yet confirmed by a PINGRESP.
        d.handed(Some(Timestamp(800)));
        d.handed(Some(Timestamp(900)));
        d.wrote_ping(2);
        // The host went offline: back to 300; the connection then closes cleanly.
        d.rewind_to(Timestamp(300));
        assert_eq!(d.ping_answered(), None);
        assert_eq!(d.closed_cleanly(2), None);
        assert_eq!(
            d.forwarded(),
            Timestamp(100),
            "the mark never moved past the rewind"
        );
        let mut d = Delivery::new(Timestamp(850));
        d.handed(Some(Timestamp(900)));
        assert_eq!(d.rewind_to(Timestamp(300)), Some(Timestamp(300)));
        assert_eq!(d.closed_cleanly(1), None);
        assert_eq!(d.forwarded(), Timestamp(300));
    }
}
