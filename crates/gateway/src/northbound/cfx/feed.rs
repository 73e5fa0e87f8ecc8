//! The feeder: the change stream into the stations, what they make into the outbox.

use std::collections::{BTreeMap, VecDeque};
use std::sync::PoisonError;
use std::time::Duration;

use tokio::sync::{Notify, broadcast, mpsc, watch};

use super::kept::Kept;
use super::station::{Input, Memory, Station};
use super::{CfxStatus, Endpoints, MAX_WAITING, MEMORY_EVERY, Maker, Shown, stopped};
use crate::cell::{Cell, LiveMessage};
use crate::event::EventKind;
use crate::time::Timestamp;

/// Feeds the stations from the change stream until `stop`, and keeps what they make.
pub(super) async fn feed(
    mut feeder: Feeder<'_>,
    kept: &Kept,
    wake: &Notify,
    mut stop: watch::Receiver<bool>,
) {
    let mut live = feeder.cell.subscribe();
    // What was read before the stream was taken (the program is read once, at the start).
    feeder.seed();
    let mut tick = tokio::time::interval(Duration::from_secs(1));
    let mut last_kept = tokio::time::Instant::now();
    loop {
        let stopping = tokio::select! {
            () = stopped(&mut stop) => true,
            message = live.recv() => {
                feeder.live(message);
                false
            }
            _ = tick.tick() => {
                feeder.tick(Timestamp::now());
                false
            }
        };
        // The memory alone (a placement window's counts) is kept every MEMORY_EVERY.
        let memory_due = feeder.remember && last_kept.elapsed() >= MEMORY_EVERY;
        let due = !feeder.made.is_empty() || memory_due || (stopping && feeder.remember);
        if due && feeder.keep(kept).await {
            last_kept = tokio::time::Instant::now();
            wake.notify_one();
        }
        if stopping {
            return;
        }
    }
}

/// The stations, and what they made that is not kept yet.
pub(super) struct Feeder<'a> {
    pub(super) stations: Vec<(String, Station)>,
    /// Made, waiting for the outbox (only while it fails: at most [`MAX_WAITING`]).
    pub(super) made: VecDeque<cfx::Envelope>,
    /// A station's memory changed since it was last kept.
    pub(super) remember: bool,
    /// The outbox refused the last try (said once in the log, until it takes again).
    pub(super) failing: bool,
    pub(super) status: &'a CfxStatus,
    pub(super) cell: &'a Cell,
    /// Makes the station of a device a reload adds.
    pub(super) maker: Maker,
    pub(super) endpoints: Endpoints,
    /// To the sender, sent at once if the link is up (see [`run`]).
    pub(super) now: mpsc::Sender<cfx::Envelope>,
}

impl Feeder<'_> {
    /// One message of the change stream.
    fn live(&mut self, message: Result<LiveMessage, broadcast::error::RecvError>) {
        match message {
            Ok(LiveMessage::Value(view)) => {
                let device = view.id.device().to_owned();
                let at = view.t.unwrap_or_else(Timestamp::now);
                self.feed(
                    &device,
                    Input::Value {
                        point: view.id.name(),
                        value: view.value.as_ref(),
                        quality: view.quality,
                        at,
                    },
                );
            }
            Ok(LiveMessage::Event(event)) => {
                if event.kind == EventKind::ConfigReloaded {
                    self.reloaded(&event);
                } else if let Some(device) = event.device.as_ref().map(ToString::to_string) {
                    self.feed(&device, Input::Event(&event));
                }
            }
            Ok(LiveMessage::Device(_)) => {}
            Err(broadcast::error::RecvError::Lagged(missed)) => {
                tracing::warn!("IPC-CFX: {missed} changes of the cell were missed");
            }
            Err(broadcast::error::RecvError::Closed) => {}
        }
    }

    /// A reload: the stations of devices removed (or no longer placement machines) say
    /// `EndpointShuttingDown` and go; devices added (or now placement machines) get a
    /// station, which says `EndpointConnected`. A changed device keeps its station.
    fn reloaded(&mut self, event: &crate::event::Event) {
        let roster = self.cell.roster();
        let now = Timestamp::now();
        let touched: Vec<String> = ["removed", "changed", "added"]
            .into_iter()
            .flat_map(|field| crate::reload::devices_in(event, field))
            .map(|d| d.to_string())
            .collect();
        for device in &touched {
            let entry = roster.device(device);
            let had = self.stations.iter().position(|(d, _)| d == device);
            let counts = entry.is_some_and(|e| e.protocol.production().is_some());
            match (had, counts) {
                (Some(i), false) => {
                    let (_, station) = self.stations.remove(i);
                    tracing::info!("IPC-CFX: endpoint {} removed", station.handle());
                    let _ = self.now.try_send(station.shutting_down(now));
                    self.shown().retain(|s| s.station.device() != device);
                }
                (None, true) => {
                    let made = entry.map(|e| self.maker.station(e));
                    match made {
                        Some(Ok(Some(station))) => {
                            tracing::info!("IPC-CFX: endpoint {} added", station.handle());
                            let _ = self.now.try_send(station.connected(now));
                            self.shown().push(Shown::of(self.cell, &station));
                            self.stations.push((device.clone(), station));
                        }
                        Some(Err(e)) => tracing::warn!("IPC-CFX: no endpoint for {device}: {e}"),
                        _ => {}
                    }
                }
                _ => {}
            }
        }
    }

    /// Feeds each station the current values of its machine's state code and program:
    /// the change stream says only what changes after it was taken.
    fn seed(&mut self) {
        for (device, station) in &mut self.stations {
            let Some(entry) = self.cell.device_entry(device) else {
                continue;
            };
            let points = entry.protocol.production().copied();
            let names = [
                Some(crate::production::states::CODE_POINT),
                points.and_then(|p| p.program),
            ];
            for name in names.into_iter().flatten() {
                let Some(index) = entry.point_index(name) else {
                    continue;
                };
                let current = entry.read().points[index].clone();
                let (Some(value), Some(at)) = (current.value, current.t) else {
                    continue;
                };
                let made = station.feed(Input::Value {
                    point: name,
                    value: Some(&value),
                    quality: current.quality,
                    at,
                });
                self.made.extend(made);
                self.remember = true;
            }
        }
    }

    fn shown(&self) -> std::sync::RwLockWriteGuard<'_, Vec<Shown>> {
        self.endpoints
            .write()
            .unwrap_or_else(PoisonError::into_inner)
    }

    /// One input of `device`. A placement machine's counters move with nearly every
    /// poll, so its station's memory is taken as changed (kept at most every
    /// `MEMORY_EVERY` without a message) rather than compared copy for copy each time.
    fn feed(&mut self, device: &str, input: Input<'_>) {
        for (_, station) in self.stations.iter_mut().filter(|(d, _)| d == device) {
            self.made.extend(station.feed(input));
            self.remember = true;
        }
        self.bound();
    }

    /// Time passing: placement windows close; the heartbeats due go to the sender (a
    /// heartbeat is not sent late: while the link is down it is not sent at all).
    fn tick(&mut self, now: Timestamp) {
        for (_, station) in &mut self.stations {
            let before = station.memory();
            for envelope in station.feed(Input::Tick(now)) {
                if matches!(envelope.message, cfx::Message::Heartbeat(_)) {
                    let _ = self.now.try_send(envelope);
                } else {
                    self.made.push_back(envelope);
                }
            }
            self.remember |= station.memory() != before;
        }
        self.bound();
    }

    fn bound(&mut self) {
        while self.made.len() > MAX_WAITING {
            self.made.pop_front();
            self.status.metrics.dropped.inc();
        }
    }

    /// Keeps what was made, with the stations' memory; whether it was kept (else it waits
    /// here for the next try).
    async fn keep(&mut self, kept: &Kept) -> bool {
        let bodies: Vec<_> = self.made.iter().map(cfx::Envelope::to_bytes).collect();
        let memory: BTreeMap<String, Memory> = self
            .stations
            .iter()
            .map(|(_, s)| (s.handle().to_string(), s.memory()))
            .collect();
        let memory = serde_json::to_string(&memory).ok();
        match kept.keep(bodies, memory).await {
            Ok(dropped) => {
                if std::mem::take(&mut self.failing) {
                    tracing::info!("IPC-CFX: the outbox takes the messages again");
                }
                self.made.clear();
                self.remember = false;
                self.status.metrics.dropped.inc_by(dropped);
                self.status.metrics.waiting.set(kept.len().await);
                true
            }
            Err(why) => {
                if !std::mem::replace(&mut self.failing, true) {
                    tracing::warn!(
                        "IPC-CFX: cannot keep its messages: {why}; they wait in memory (at most {MAX_WAITING})"
                    );
                }
                false
            }
        }
    }
}
