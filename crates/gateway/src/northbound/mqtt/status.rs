//! What the MQTT interface shows of itself: its link under `mqtt` in `/healthz`, and its
//! metrics (`cellbus_mqtt_*`), registered with the cell when the interface starts.

use std::sync::{Arc, PoisonError, RwLock};

use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::registry::Registry;

use crate::cell::{Cell, InterfaceStatus};

/// The interface's name in `/healthz` and in the cell.
pub const NAME: &str = "mqtt";

/// The northbound MQTT connection as `/healthz` shows it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MqttLink {
    /// Connected to the broker.
    Connected,
    /// Not connected, and why.
    Disconnected(String),
}

impl std::fmt::Display for MqttLink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            MqttLink::Connected => f.write_str("connected"),
            MqttLink::Disconnected(why) => write!(f, "disconnected: {why}"),
        }
    }
}

/// The MQTT interface's metrics.
#[derive(Debug, Default)]
pub struct MqttMetrics {
    /// 1 while the MQTT connection is up.
    pub connected: Gauge,
    /// MQTT messages handed to the client (births, data, deaths).
    pub published: Counter,
    /// MQTT connections made after the first.
    pub reconnects: Counter,
    /// Stored changes sent after an outage (Sparkplug historical metrics, JSON backlog).
    pub forwarded: Counter,
    /// Primary host STATE messages refused: dated too far after this gateway's clock.
    pub state_refused: Counter,
    /// Primary host `offline` STATEs the host contradicted within the grace (forged).
    pub offline_contradicted: Counter,
    /// MQTT commands refused whole before any write reached a device.
    pub commands_refused: Counter,
    /// Foreign messages on the gateway's own JSON topics, answered with its own state.
    pub foreign_reasserted: Counter,
}

impl MqttMetrics {
    fn register(&self, registry: &mut Registry) {
        registry.register(
            "mqtt_connected",
            "1 while the MQTT connection to the broker is up",
            self.connected.clone(),
        );
        registry.register(
            "mqtt_published",
            "MQTT messages handed to the client (Sparkplug births, data, deaths)",
            self.published.clone(),
        );
        registry.register(
            "mqtt_reconnects",
            "MQTT connections made after the first",
            self.reconnects.clone(),
        );
        registry.register(
            "mqtt_forwarded",
            "Stored changes sent to the broker after an outage (store and forward)",
            self.forwarded.clone(),
        );
        registry.register(
            "mqtt_state_refused",
            "Primary host STATE messages refused because they are dated too far after this \
             gateway's clock",
            self.state_refused.clone(),
        );
        registry.register(
            "mqtt_offline_contradicted",
            "Primary host offline STATEs that the host contradicted within the grace \
             (another client published them)",
            self.offline_contradicted.clone(),
        );
        registry.register(
            "mqtt_commands_refused",
            "MQTT commands refused whole before any write reached a device",
            self.commands_refused.clone(),
        );
        registry.register(
            "mqtt_foreign_reasserted",
            "Messages another client published on this gateway's JSON topics, answered by \
             publishing the gateway's own state again",
            self.foreign_reasserted.clone(),
        );
    }
}

/// The MQTT interface's link and metrics, one per cell.
#[derive(Debug)]
pub struct MqttStatus {
    link: RwLock<MqttLink>,
    /// The metrics.
    pub metrics: MqttMetrics,
}

impl MqttStatus {
    /// Records the link's state.
    pub fn set_link(&self, link: MqttLink) {
        *self.link.write().unwrap_or_else(PoisonError::into_inner) = link;
    }

    /// The link's state.
    pub fn link(&self) -> MqttLink {
        self.link
            .read()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }
}

impl InterfaceStatus for MqttStatus {
    fn health(&self) -> serde_json::Value {
        serde_json::Value::String(self.link().to_string())
    }

    fn problem(&self) -> Option<String> {
        match self.link() {
            MqttLink::Connected => None,
            MqttLink::Disconnected(why) => Some(format!("not connected to the broker: {why}")),
        }
    }

    fn into_any(self: Arc<Self>) -> Arc<dyn std::any::Any + Send + Sync> {
        self
    }
}

/// The cell's MQTT status: registered (with its metrics) at the first call, the same one
/// after.
pub fn status(cell: &Cell) -> Arc<MqttStatus> {
    if let Some(status) = of(cell) {
        return status;
    }
    let status = Arc::new(MqttStatus {
        link: RwLock::new(MqttLink::Disconnected("not connected yet".to_owned())),
        metrics: MqttMetrics::default(),
    });
    // Replaces the `null` of an interface not running yet.
    cell.set_interface(NAME, Arc::clone(&status) as _, true);
    cell.metrics()
        .register(|registry| status.metrics.register(registry));
    status
}

/// The cell's MQTT status, if the interface has started.
pub fn of(cell: &Cell) -> Option<Arc<MqttStatus>> {
    cell.interface(NAME)?.into_any().downcast().ok()
}

/// The MQTT link's state, if the interface has started.
pub fn link(cell: &Cell) -> Option<MqttLink> {
    of(cell).map(|status| status.link())
}
