//! What the historian counts and how it is doing: Prometheus metrics (`/metrics`) and the
//! health (`/healthz`), shared by the MQTT task, the writer and the HTTP handlers.

use std::sync::Mutex;
use std::sync::atomic::{AtomicI64, AtomicU64, Ordering};
use std::time::SystemTime;

use prometheus_client::encoding::text::encode;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::{Histogram, exponential_buckets};
use prometheus_client::registry::Registry;

/// The historian's counters and gauges.
#[derive(Debug)]
pub struct Metrics {
    registry: Registry,
    /// MQTT messages received.
    pub messages: Counter,
    /// Samples the host returned (before the store's dedupe).
    pub samples_received: Counter,
    /// Samples committed to PostgreSQL (new rows).
    pub samples_committed: Counter,
    /// Samples PostgreSQL already had (same point and time): replays, births after a
    /// rebirth, shared births and deaths.
    pub duplicates: Counter,
    /// Samples and events dropped: past the pending bound, or refused by the store.
    pub dropped: Counter,
    /// Events committed.
    pub events_committed: Counter,
    /// Rebirth requests (NCMD) published.
    pub rebirths: Counter,
    /// `seq` gaps seen.
    pub seq_gaps: Counter,
    /// Messages with a problem (unreadable, unknown alias, data before a birth, …).
    pub problems: Counter,
    /// Births refused for the host's limits (`--max-nodes`, `--max-points`,
    /// `--max-node-points`).
    pub births_refused: Counter,
    /// Birth metrics left out for their name (too long, control or bidirectional
    /// formatting characters).
    pub names_refused: Counter,
    /// STATE messages on the historian's own topic that did not say online while it was,
    /// each answered with online.
    pub state_reasserted: Counter,
    /// Metrics in the current births of all edge nodes (a gauge; `--max-points` bounds it).
    pub points_held: Gauge,
    /// Commits made.
    pub commits: Counter,
    /// Commits that failed (each retried).
    pub commit_errors: Counter,
    /// Time of each commit, seconds.
    pub commit_seconds: Histogram,
    /// Samples received and not committed yet (a gauge).
    pub pending: Gauge,
    /// 1 while connected to the broker and online.
    pub mqtt_connected: Gauge,
    /// 1 while the last commit or connection attempt to PostgreSQL succeeded.
    pub database_ok: Gauge,
}

impl Default for Metrics {
    fn default() -> Self {
        Self::new()
    }
}

impl Metrics {
    /// Every metric at zero, registered under `cellbus_historian_`.
    pub fn new() -> Self {
        let mut registry = Registry::with_prefix("cellbus_historian");
        let counter = |registry: &mut Registry, name: &str, help: &str| {
            let c = Counter::default();
            registry.register(name, help, c.clone());
            c
        };
        let gauge = |registry: &mut Registry, name: &str, help: &str| {
            let g = Gauge::default();
            registry.register(name, help, g.clone());
            g
        };
        let messages = counter(&mut registry, "messages", "MQTT messages received");
        let samples_received = counter(
            &mut registry,
            "samples_received",
            "Samples read from Sparkplug messages",
        );
        let samples_committed = counter(
            &mut registry,
            "samples_committed",
            "Samples committed to PostgreSQL as new rows",
        );
        let duplicates = counter(
            &mut registry,
            "duplicate_samples",
            "Samples PostgreSQL already had (same point and time)",
        );
        let dropped = counter(
            &mut registry,
            "dropped_rows",
            "Rows dropped: past the pending bound, or refused by the store",
        );
        let events_committed = counter(&mut registry, "events_committed", "Events committed");
        let rebirths = counter(
            &mut registry,
            "rebirths_asked",
            "NCMD Rebirth requests sent",
        );
        let seq_gaps = counter(&mut registry, "seq_gaps", "Sparkplug seq gaps seen");
        let problems = counter(
            &mut registry,
            "message_problems",
            "Problems in received messages",
        );
        let births_refused = counter(
            &mut registry,
            "births_refused",
            "Births refused for the limits of nodes and points",
        );
        let names_refused = counter(
            &mut registry,
            "metric_names_refused",
            "Birth metrics left out for a name too long or with control or bidi characters",
        );
        let state_reasserted = counter(
            &mut registry,
            "state_reasserted",
            "STATE messages on the historian's own topic not saying online, answered with online",
        );
        let points_held = gauge(
            &mut registry,
            "points_held",
            "Metrics in the current births of all edge nodes",
        );
        let commits = counter(&mut registry, "commits", "Batches committed");
        let commit_errors = counter(
            &mut registry,
            "commit_errors",
            "Commits that failed and were retried",
        );
        let commit_seconds = Histogram::new(exponential_buckets(0.001, 2.0, 14));
        registry.register(
            "commit_seconds",
            "Time of a batch commit",
            commit_seconds.clone(),
        );
        let pending = gauge(
            &mut registry,
            "pending_samples",
            "Samples received and not committed yet",
        );
        let mqtt_connected = gauge(
            &mut registry,
            "mqtt_connected",
            "1 while connected to the broker and online",
        );
        let database_ok = gauge(
            &mut registry,
            "database_ok",
            "1 while PostgreSQL takes commits",
        );
        Self {
            registry,
            messages,
            samples_received,
            samples_committed,
            duplicates,
            dropped,
            events_committed,
            rebirths,
            seq_gaps,
            problems,
            births_refused,
            names_refused,
            state_reasserted,
            points_held,
            commits,
            commit_errors,
            commit_seconds,
            pending,
            mqtt_connected,
            database_ok,
        }
    }

    /// The Prometheus text exposition.
    pub fn encode(&self) -> String {
        let mut out = String::new();
        // Writing to a String does not fail.
        let _ = encode(&mut out, &self.registry);
        out
    }
}

/// The health `/healthz` shows, beside the metrics.
#[derive(Debug, Default)]
pub struct Health {
    /// Why the broker link is down, `None` while connected.
    broker: Mutex<Option<String>>,
    /// Why PostgreSQL is failing, `None` while it takes commits.
    database: Mutex<Option<String>>,
    /// When the last commit succeeded (ms since the epoch, 0: never).
    last_commit_ms: AtomicI64,
    /// Edge nodes whose NBIRTH is current.
    nodes_online: AtomicU64,
}

impl Health {
    /// New: broker and database not connected yet.
    pub fn new() -> Self {
        Self {
            broker: Mutex::new(Some("not connected yet".to_owned())),
            database: Mutex::new(Some("not connected yet".to_owned())),
            ..Self::default()
        }
    }

    /// The broker link: `None` connected, else why not.
    pub fn set_broker(&self, down: Option<String>) {
        *self.broker.lock().unwrap_or_else(|e| e.into_inner()) = down;
    }

    /// PostgreSQL: `None` takes commits, else why not.
    pub fn set_database(&self, failing: Option<String>) {
        *self.database.lock().unwrap_or_else(|e| e.into_inner()) = failing;
    }

    /// A commit succeeded now.
    pub fn committed(&self, at: SystemTime) {
        let ms = at
            .duration_since(SystemTime::UNIX_EPOCH)
            .map_or(0, |d| i64::try_from(d.as_millis()).unwrap_or(i64::MAX));
        self.last_commit_ms.store(ms, Ordering::Relaxed);
    }

    /// How many edge nodes are born.
    pub fn set_nodes_online(&self, n: usize) {
        self.nodes_online.store(n as u64, Ordering::Relaxed);
    }

    /// Why the broker link is down.
    pub fn broker(&self) -> Option<String> {
        self.broker
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    /// Why PostgreSQL is failing.
    pub fn database(&self) -> Option<String> {
        self.database
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    /// The last successful commit, ms since the epoch (0: none yet).
    pub fn last_commit_ms(&self) -> i64 {
        self.last_commit_ms.load(Ordering::Relaxed)
    }

    /// Edge nodes born.
    pub fn nodes_online(&self) -> u64 {
        self.nodes_online.load(Ordering::Relaxed)
    }
}
