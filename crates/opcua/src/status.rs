//! What the OPC UA interface shows of itself: the server's state under `opcua` in
//! `/healthz`, and its metrics (`cellbus_opcua_*`), registered with the cell when the
//! server starts and brought up to date before each scrape.

use std::sync::Arc;

use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::registry::Registry;
use serde::Serialize;

use gateway::cell::{Cell, InterfaceStatus};
use gateway::metrics::catch_up;

/// The interface's name in `/healthz` and in the cell.
pub const NAME: &str = "opcua";

/// The OPC UA server as `/healthz` and `/metrics` show it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct OpcuaState {
    /// The endpoint URL clients use.
    pub endpoint: String,
    /// Open TCP connections.
    pub connections: u64,
    /// Sessions (created, activated or not).
    pub sessions: u64,
    /// Subscriptions.
    pub subscriptions: u64,
    /// Monitored items (of every node: the cell's and the server's own).
    pub monitored_items: u64,
    /// What the server refused or closed to protect itself, since it started.
    pub refused: OpcuaRefused,
}

/// Sessions and monitored items the OPC UA server refused or closed since it started.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct OpcuaRefused {
    /// Sessions closed because they were not activated within `activation_timeout`.
    pub sessions_not_activated: u64,
    /// Sessions closed because their client left before activating them.
    pub sessions_abandoned: u64,
    /// Sessions refused because their IP address had `sessions_per_address` already.
    pub sessions_per_address: u64,
    /// Monitored items refused (`Bad_TooManyMonitoredItems`) at `max_monitored_items`.
    pub monitored_items: u64,
}

/// Reads the OPC UA server's state when asked (the server registers one at start).
pub struct OpcuaProbe(Box<dyn Fn() -> OpcuaState + Send + Sync>);

impl OpcuaProbe {
    /// A probe that calls `read`.
    pub fn new(read: impl Fn() -> OpcuaState + Send + Sync + 'static) -> Self {
        Self(Box::new(read))
    }

    /// The state now.
    pub fn read(&self) -> OpcuaState {
        (self.0)()
    }
}

impl std::fmt::Debug for OpcuaProbe {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_tuple("OpcuaProbe").field(&self.read()).finish()
    }
}

/// Labels of the OPC UA sessions refused.
#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct OpcuaRefusalLabels {
    /// `not_activated`, `abandoned` or `per_address`.
    pub reason: &'static str,
}

/// The OPC UA server's gauges and counters, set from its state before a scrape.
#[derive(Debug, Default)]
struct OpcuaMetrics {
    connections: Gauge,
    sessions: Gauge,
    subscriptions: Gauge,
    monitored_items: Gauge,
    sessions_refused: Family<OpcuaRefusalLabels, Counter>,
    monitored_items_refused: Counter,
}

impl OpcuaMetrics {
    fn register(&self, registry: &mut Registry) {
        registry.register(
            "opcua_connections",
            "Open OPC UA TCP connections",
            self.connections.clone(),
        );
        registry.register("opcua_sessions", "OPC UA sessions", self.sessions.clone());
        registry.register(
            "opcua_subscriptions",
            "OPC UA subscriptions",
            self.subscriptions.clone(),
        );
        registry.register(
            "opcua_monitored_items",
            "OPC UA monitored items (every node: the cell's and the server's own)",
            self.monitored_items.clone(),
        );
        registry.register(
            "opcua_sessions_refused",
            "OPC UA sessions the gateway closed or refused, by reason (not_activated: not activated within activation_timeout; abandoned: the client left before activating; per_address: over sessions_per_address)",
            self.sessions_refused.clone(),
        );
        registry.register(
            "opcua_monitored_items_refused",
            "OPC UA monitored items refused (Bad_TooManyMonitoredItems) at max_monitored_items",
            self.monitored_items_refused.clone(),
        );
    }

    /// Sets the gauges from the server's state.
    fn set(&self, state: &OpcuaState) {
        let gauge = |n: u64| i64::try_from(n).unwrap_or(i64::MAX);
        self.connections.set(gauge(state.connections));
        self.sessions.set(gauge(state.sessions));
        self.subscriptions.set(gauge(state.subscriptions));
        self.monitored_items.set(gauge(state.monitored_items));
        let refused = &state.refused;
        for (reason, total) in [
            ("not_activated", refused.sessions_not_activated),
            ("abandoned", refused.sessions_abandoned),
            ("per_address", refused.sessions_per_address),
        ] {
            catch_up(
                &self
                    .sessions_refused
                    .get_or_create(&OpcuaRefusalLabels { reason }),
                total,
            );
        }
        catch_up(&self.monitored_items_refused, refused.monitored_items);
    }
}

/// The OPC UA server's status: how to read its state, and its metrics.
#[derive(Debug)]
struct OpcuaStatus {
    probe: OpcuaProbe,
    metrics: OpcuaMetrics,
}

impl InterfaceStatus for OpcuaStatus {
    fn health(&self) -> serde_json::Value {
        serde_json::to_value(self.probe.read()).unwrap_or(serde_json::Value::Null)
    }

    fn before_scrape(&self) {
        self.metrics.set(&self.probe.read());
    }

    fn into_any(self: Arc<Self>) -> Arc<dyn std::any::Any + Send + Sync> {
        self
    }
}

/// Registers the server's status (and, the first time, its metrics) with the cell.
pub fn register(cell: &Cell, probe: OpcuaProbe) {
    let first = cell
        .interface(NAME)
        .is_none_or(|s| s.into_any().downcast::<OpcuaStatus>().is_err());
    let status = Arc::new(OpcuaStatus {
        probe,
        metrics: OpcuaMetrics::default(),
    });
    cell.set_interface(NAME, Arc::clone(&status) as _, true);
    if first {
        cell.metrics()
            .register(|registry| status.metrics.register(registry));
    }
}

/// The OPC UA server's state now, if it runs.
pub fn state(cell: &Cell) -> Option<OpcuaState> {
    let status = cell
        .interface(NAME)?
        .into_any()
        .downcast::<OpcuaStatus>()
        .ok()?;
    Some(status.probe.read())
}
