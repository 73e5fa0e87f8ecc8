//! A host application's STATE message: `{"online":bool,"timestamp":ms}` as JSON on
//! `spBv1.0/STATE/{host_id}`, QoS 1, retained.

use serde::{Deserialize, Serialize};

use crate::metric::Timestamp;
use crate::node::{Publish, Qos};
use crate::topic::{Id, Topic};

/// Whether a host application is online, and since when.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct HostState {
    /// The host is online.
    pub online: bool,
    /// When the host said so: ms since the Unix epoch, UTC.
    pub timestamp: u64,
}

/// A STATE payload that is not the JSON the spec defines.
#[derive(Debug, thiserror::Error)]
#[error("a STATE payload is JSON {{\"online\":bool,\"timestamp\":ms}}: {0}")]
pub struct StateError(#[from] serde_json::Error);

impl HostState {
    /// The state `online` at `now`.
    pub fn new(online: bool, now: Timestamp) -> Self {
        Self {
            online,
            timestamp: now.as_millis(),
        }
    }

    /// Reads a STATE payload.
    pub fn from_json(payload: &[u8]) -> Result<Self, StateError> {
        Ok(serde_json::from_slice(payload)?)
    }

    /// The JSON payload.
    pub fn to_json(&self) -> Vec<u8> {
        // Serialising a struct of a bool and an integer cannot fail.
        serde_json::to_vec(self).expect("a bool and a u64 always serialise")
    }

    /// The message a host publishes (QoS 1, retained) — for tests and host tools.
    pub fn publish(&self, host: Id) -> Publish {
        Publish {
            topic: Topic::State { host },
            payload: self.to_json(),
            qos: Qos::AtLeastOnce,
            retain: true,
        }
    }
}
