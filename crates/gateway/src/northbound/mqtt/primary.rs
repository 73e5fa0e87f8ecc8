//! What the edge node believes of its primary host, from the STATE messages it reads:
//! sans-IO (the caller passes the time), so every forged or late STATE is a unit test.
//!
//! Sparkplug B 3.0 has no authentication: any client of the broker can publish on
//! `spBv1.0/STATE/{host}`. The rules below keep one forged message from stopping the
//! node for good; the broker's ACLs (the user guide, docs/guide/src/mqtt.md, "Broker
//! access control") keep it from
//! being sent at all.
//!
//! - A STATE dated more than [`STATE_SKEW_MS`] after the node's clock is refused: it
//!   would otherwise hide every later real STATE (a year-9999 offline sent retained
//!   latched the node offline across restarts).
//! - The first STATE of each connection is believed whatever its time: the retained
//!   message is the latest the host (or anyone) published, and an older forged offline
//!   cannot latch from one connection to the next.
//! - An `offline` newer than what was seen is not acted on at once: the node waits
//!   [`OFFLINE_GRACE`] for the host to say again that the session it announced is online
//!   (the historian answers any offline for its id while it is up with its session's
//!   `online`, same timestamp). Only an offline nobody contradicts ends the node's
//!   session. A real host's Will is never contradicted (the host is gone), so the cost of
//!   the grace is a node ending its session that much later, which the rewind of twice the
//!   keep-alive covers.
//! - An `online` of a *newer* session during the grace is a host that restarted (the
//!   historian's `offline(T−1)` then `online(T)`): the offline was real, and the node ends
//!   its session at once, so it rewinds and sends again what the host's old session may
//!   have received and never kept.

use std::time::Duration;

use sparkplug::HostState;

/// How far ahead of the node's clock a STATE's timestamp may be. Plant PCs without NTP
/// drift; two minutes is a lot of drift and still refuses a forged far-future offline.
pub const STATE_SKEW_MS: u64 = 120_000;

/// How long an `offline` waits for the host to contradict it before the node acts on it.
pub const OFFLINE_GRACE: Duration = Duration::from_secs(2);

/// What a STATE message means for the node.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// The host is online (publish the births if not yet done).
    Online,
    /// The host says again that its session is online: a pending offline is cancelled.
    Contradicted,
    /// A newer session of the host came online after an offline: the host restarted, and
    /// the node ends its session at once (to rewind), then reads the host's new state.
    Restarted,
    /// An offline the node acts on after [`OFFLINE_GRACE`], unless contradicted; then ask
    /// [`PrimaryHost::offline_confirmed`].
    OfflinePending,
    /// Older than a STATE already seen: nothing to do.
    Older,
    /// Dated this many milliseconds after the node's clock (more than [`STATE_SKEW_MS`]):
    /// refused.
    FromTheFuture {
        /// How far ahead.
        ahead_ms: u64,
    },
}

/// The node's belief about its primary host.
#[derive(Debug, Default, Clone)]
pub struct PrimaryHost {
    /// The newest STATE timestamp believed in this connection; `None` before the first.
    seen: Option<u64>,
    /// The timestamp of the `online` the node believes (its session), while it does.
    session: Option<u64>,
    /// An offline is waiting out the grace.
    pending: bool,
}

impl PrimaryHost {
    /// A new connection: the next STATE (the retained one) is believed whatever its time.
    pub fn reconnected(&mut self) {
        *self = Self::default();
    }

    /// Reads one STATE at the node's time `now_ms`.
    pub fn receive(&mut self, state: HostState, now_ms: u64) -> Verdict {
        if let Some(ahead_ms) = state
            .timestamp
            .checked_sub(now_ms)
            .filter(|&ahead| ahead > STATE_SKEW_MS)
        {
            return Verdict::FromTheFuture { ahead_ms };
        }
        if state.online && self.pending && self.session == Some(state.timestamp) {
            // The host's own session again: whatever offline came meanwhile was not its.
            self.pending = false;
            self.seen = Some(state.timestamp);
            return Verdict::Contradicted;
        }
        if self.seen.is_some_and(|seen| state.timestamp < seen) {
            return Verdict::Older;
        }
        self.seen = Some(state.timestamp);
        if state.online && self.pending && self.session.is_some() {
            self.pending = false;
            self.session = Some(state.timestamp);
            Verdict::Restarted
        } else if state.online {
            self.pending = false;
            self.session = Some(state.timestamp);
            Verdict::Online
        } else {
            self.pending = true;
            Verdict::OfflinePending
        }
    }

    /// The grace after an offline has passed: whether the offline stands (then the host
    /// is offline until a newer online).
    pub fn offline_confirmed(&mut self) -> bool {
        if !self.pending {
            return false;
        }
        self.pending = false;
        self.session = None;
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const NOW: u64 = 1_764_000_000_000;

    fn state(online: bool, timestamp: u64) -> HostState {
        HostState { online, timestamp }
    }

    /// A host believed online since `NOW - 60 s`.
    fn online_host() -> PrimaryHost {
        let mut host = PrimaryHost::default();
        assert_eq!(
            host.receive(state(true, NOW - 60_000), NOW),
            Verdict::Online
        );
        host
    }

    #[test]
    fn an_offline_contradicted_by_the_hosts_own_session_within_the_grace_is_dropped() {
        let mut host = online_host();
        // A forgery dated now, newer than the host's online.
        assert_eq!(
            host.receive(state(false, NOW), NOW),
            Verdict::OfflinePending
        );
        // The host answers with its session's online, same timestamp as before.
        assert_eq!(
            host.receive(state(true, NOW - 60_000), NOW + 5),
            Verdict::Contradicted
        );
        assert!(
            !host.offline_confirmed(),
            "the grace ends with nothing to do"
        );
    }

    #[test]
    fn a_host_that_restarts_ends_the_session_at_once_so_the_node_rewinds() {
        let mut host = online_host();
        // The historian starting again: offline(T' - 1 ms), then online(T').
        assert_eq!(
            host.receive(state(false, NOW - 1), NOW),
            Verdict::OfflinePending
        );
        assert_eq!(host.receive(state(true, NOW), NOW + 3), Verdict::Restarted);
        assert!(!host.offline_confirmed(), "nothing left for the grace");
        // The next connection reads the retained online of the new session.
        host.reconnected();
        assert_eq!(host.receive(state(true, NOW), NOW + 500), Verdict::Online);
    }

    #[test]
    fn an_offline_nobody_contradicts_stands_after_the_grace() {
        let mut host = online_host();
        // The host's Will: offline with its session's timestamp.
        assert_eq!(
            host.receive(state(false, NOW - 60_000), NOW),
            Verdict::OfflinePending
        );
        assert!(host.offline_confirmed());
        assert!(!host.offline_confirmed(), "once");
        // An offline dated now: an online older than it does not bring the host back, a
        // new session does.
        let mut host = online_host();
        host.receive(state(false, NOW), NOW);
        assert!(host.offline_confirmed());
        assert_eq!(
            host.receive(state(true, NOW - 60_000), NOW + 10),
            Verdict::Older
        );
        assert_eq!(
            host.receive(state(true, NOW + 1), NOW + 10),
            Verdict::Online
        );
    }

    #[test]
    fn a_state_from_far_in_the_future_is_refused_and_changes_nothing() {
        let mut host = online_host();
        assert_eq!(
            host.receive(state(false, 253_402_300_799_000), NOW),
            Verdict::FromTheFuture {
                ahead_ms: 253_402_300_799_000 - NOW
            }
        );
        assert!(!host.offline_confirmed());
        // The host's later real states still count.
        assert_eq!(
            host.receive(state(false, NOW), NOW),
            Verdict::OfflinePending
        );
        // Within the skew is believed: plant clocks drift.
        let mut host = online_host();
        assert_eq!(
            host.receive(state(true, NOW + STATE_SKEW_MS), NOW),
            Verdict::Online
        );
    }

    #[test]
    fn each_connection_believes_its_first_state_whatever_an_earlier_one_saw() {
        let mut host = online_host();
        // A forged offline dated a minute ahead was believed in the last connection...
        host.receive(state(false, NOW + 60_000), NOW);
        assert!(host.offline_confirmed());
        assert_eq!(host.receive(state(true, NOW - 60_000), NOW), Verdict::Older);
        // ...the next connection reads the retained online again and believes it.
        host.reconnected();
        assert_eq!(
            host.receive(state(true, NOW - 60_000), NOW + 1_000),
            Verdict::Online
        );
    }

    #[test]
    fn an_older_offline_is_ignored_and_a_forged_online_cannot_cancel_a_confirmed_offline() {
        let mut host = online_host();
        assert_eq!(
            host.receive(state(false, NOW - 120_000), NOW),
            Verdict::Older
        );
        assert!(!host.offline_confirmed());
        host.receive(state(false, NOW), NOW);
        assert!(host.offline_confirmed());
        assert_eq!(host.receive(state(true, NOW - 1), NOW), Verdict::Older);
    }
}
