//! The outbox the feeder keeps messages in and the sender takes them from.

use std::collections::BTreeMap;
use std::sync::{Arc, PoisonError};

use super::station::{Memory, Station};
use super::{MAX_KEPT, NAME};
use crate::cell::Cell;
use crate::store::Outbox;

/// The outbox of the history database (or, when the data directory cannot be used, one in
/// memory), shared by the feeder and the sender; its calls run off the async threads.
#[derive(Clone)]
pub(super) struct Kept(Arc<std::sync::Mutex<Outbox>>);

impl Kept {
    pub(super) async fn open(cell: &Cell, dir: &std::path::Path) -> Kept {
        let store = cell.store().clone();
        let dir = dir.to_owned();
        let opened = tokio::task::spawn_blocking(move || {
            // The history's open moves a damaged file aside first.
            let _ = store.wait_open();
            Outbox::open(&dir, NAME)
        })
        .await;
        let outbox = match opened {
            Ok(Ok(outbox)) => outbox,
            Ok(Err(e)) => {
                tracing::warn!(
                    "IPC-CFX: cannot keep its messages in the history ({e}); they wait in \
                     memory and a restart loses those not yet sent"
                );
                Outbox::in_memory(NAME).expect("SQLite opens a database in memory")
            }
            Err(e) => std::panic::resume_unwind(e.into_panic()),
        };
        Kept(Arc::new(std::sync::Mutex::new(outbox)))
    }

    pub(super) async fn call<R: Send + 'static>(
        &self,
        f: impl FnOnce(&mut Outbox) -> R + Send + 'static,
    ) -> R {
        let outbox = Arc::clone(&self.0);
        match tokio::task::spawn_blocking(move || {
            f(&mut outbox.lock().unwrap_or_else(PoisonError::into_inner))
        })
        .await
        {
            Ok(r) => r,
            Err(e) => std::panic::resume_unwind(e.into_panic()),
        }
    }

    /// Gives each station the memory kept for its handle.
    pub(super) async fn recall(&self, stations: &mut [Station]) {
        let memory = match self.call(|o| o.memory()).await {
            Ok(memory) => memory,
            Err(e) => {
                tracing::warn!("IPC-CFX: cannot read what the stations knew: {e}");
                None
            }
        };
        let Some(memory) = memory else { return };
        let mut memory: BTreeMap<String, Memory> = match serde_json::from_str(&memory) {
            Ok(memory) => memory,
            Err(e) => {
                tracing::warn!(
                    "IPC-CFX: what the stations knew is unreadable ({e}); they start afresh"
                );
                return;
            }
        };
        for station in stations {
            if let Some(m) = memory.remove(station.handle().as_str()) {
                station.remember(m);
            }
        }
    }

    pub(super) async fn keep(
        &self,
        bodies: Vec<Vec<u8>>,
        memory: Option<String>,
    ) -> Result<u64, String> {
        self.call(move |o| o.keep(&bodies, memory.as_deref(), MAX_KEPT))
            .await
            .map_err(|e| e.to_string())
    }

    pub(super) async fn len(&self) -> i64 {
        self.call(|o| i64::try_from(o.len()).unwrap_or(i64::MAX))
            .await
    }
}
