//! Running as a systemd service (`Type=notify`): the gateway says `READY=1` once it
//! listens, `RELOADING=1` while it reloads its configuration (`SIGHUP`, then `READY=1`
//! again), `STOPPING=1` when it stops, and, when the unit sets `WatchdogSec=`, pets the
//! watchdog (`WATCHDOG=1`) at half that period for as long as it works: the pollers'
//! thread ticks (a heartbeat on its own runtime, so a poll that blocks it stops the
//! ticks) and the history writer commits (a flush answered in time). A gateway that is
//! wedged stops petting and systemd restarts it. Outside systemd (no `NOTIFY_SOCKET`)
//! nothing is sent. The protocol is sd_notify(3) over a datagram socket, through the
//! `sd-notify` crate.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use sd_notify::NotifyState;
use tokio::sync::watch;

use crate::store::StoreHandle;

/// How often the pollers' heartbeat ticks.
pub const HEARTBEAT: Duration = Duration::from_secs(1);

/// Tells systemd the gateway is ready, with a status line (`systemctl status`).
pub fn ready(status: &str) {
    send(&[NotifyState::Ready, NotifyState::Status(status)]);
}

/// Tells systemd the gateway is reloading its configuration (`READY=1` follows when it is
/// done, [`ready`]).
pub fn reloading() {
    match NotifyState::monotonic_usec_now() {
        Ok(now) => send(&[NotifyState::Reloading, now]),
        Err(_) => send(&[NotifyState::Reloading]),
    }
}

/// Tells systemd the gateway is stopping.
pub fn stopping() {
    send(&[NotifyState::Stopping]);
}

fn send(states: &[NotifyState]) {
    if let Err(e) = sd_notify::notify(states) {
        tracing::warn!("cannot tell systemd ({:?}): {e}", states.first());
    }
}

/// The pollers' heartbeat: a count their thread raises every [`HEARTBEAT`].
#[derive(Debug, Clone, Default)]
pub struct Heartbeat(Arc<AtomicU64>);

impl Heartbeat {
    /// One more tick.
    pub fn beat(&self) {
        self.0.fetch_add(1, Ordering::Relaxed);
    }

    /// Ticks so far.
    pub fn count(&self) -> u64 {
        self.0.load(Ordering::Relaxed)
    }
}

/// Whether the gateway works, from what one watchdog period saw: the pollers' heartbeat
/// moved, and the history committed (or is off, which is not a fault of its own).
pub fn works(beats_before: u64, beats_now: u64, history: Result<(), String>) -> Result<(), String> {
    if beats_now == beats_before {
        return Err("the pollers' thread has not ticked for a watchdog period".to_owned());
    }
    history.map_err(|e| format!("the history does not commit: {e}"))
}

/// Pets systemd's watchdog every half `WatchdogSec=` while [`works`] says so, until `stop`
/// turns true. Without a watchdog (not under systemd, or no `WatchdogSec=`) returns at once.
pub async fn watchdog(heartbeat: Heartbeat, store: StoreHandle, mut stop: watch::Receiver<bool>) {
    let Some(period) = sd_notify::watchdog_enabled() else {
        return;
    };
    let every = period / 2;
    let mut before = heartbeat.count();
    let mut complained = false;
    loop {
        tokio::select! {
            _ = stop.changed() => return,
            () = tokio::time::sleep(every) => {}
        }
        let history = match tokio::time::timeout(every, store.flush()).await {
            Ok(Ok(_)) => Ok(()),
            // The history is off or failing: `/healthz` and the events say so; polling and
            // the interfaces go on, so the gateway is not wedged.
            Ok(Err(_)) => Ok(()),
            Err(_) => Err(format!("a commit took more than {} s", every.as_secs())),
        };
        let now = heartbeat.count();
        match works(before, now, history) {
            Ok(()) => {
                send(&[NotifyState::Watchdog]);
                complained = false;
            }
            Err(why) if !complained => {
                tracing::error!("not petting systemd's watchdog: {why}");
                complained = true;
            }
            Err(_) => {}
        }
        before = now;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_gateway_works_while_its_pollers_tick_and_its_history_commits() {
        assert_eq!(works(3, 5, Ok(())), Ok(()));
        assert!(
            works(5, 5, Ok(()))
                .unwrap_err()
                .contains("pollers' thread has not ticked")
        );
        assert!(
            works(5, 6, Err("a commit took more than 15 s".into()))
                .unwrap_err()
                .contains("the history does not commit")
        );
    }
}
