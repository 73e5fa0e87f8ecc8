//! Prometheus metrics, served as text at `/metrics`.
//!
//! Per line and device: polls (by result), errors by kind, timeouts, poll latency, whether
//! the device is up, requests per poll (generic Modbus). Per line: busy seconds (its rate is the line's utilisation) and the
//! utilisation over the last window. For the gateway: history rows written, events, write
//! attempts by result, open event streams.

use std::sync::Mutex;
use std::sync::atomic::AtomicU64;

use prometheus_client::encoding::{EncodeLabelSet, EncodeLabelValue};
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::{Histogram, exponential_buckets};
use prometheus_client::registry::Registry;

use crate::store::StoreStats;

/// Labels of per-device metrics.
#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct DeviceLabels {
    /// The line's name.
    pub line: String,
    /// The device's id.
    pub device: String,
}

/// Labels of the poll counter.
#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct PollLabels {
    /// The line's name.
    pub line: String,
    /// The device's id.
    pub device: String,
    /// `ok` or `error`.
    pub result: PollResult,
}

/// How a poll ended.
#[derive(Debug, Clone, Copy, Hash, PartialEq, Eq, EncodeLabelValue)]
#[allow(non_camel_case_types)]
pub enum PollResult {
    /// The device answered.
    ok,
    /// It did not.
    error,
}

/// Labels of the error counter.
#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct ErrorLabels {
    /// The line's name.
    pub line: String,
    /// The device's id.
    pub device: String,
    /// The error kind (`timeout`, `refused`, `decode`, `line`, `disconnected`).
    pub kind: String,
}

/// Labels of per-line metrics.
#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct LineLabels {
    /// The line's name.
    pub line: String,
}

/// Labels of the write counter.
#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct WriteLabels {
    /// `accepted`, `refused` or `failed`.
    pub result: String,
}

type HistogramFamily = Family<LineLabels, Histogram, fn() -> Histogram>;

/// Every metric of the gateway.
#[derive(Debug)]
pub struct Metrics {
    registry: Mutex<Registry>,
    /// Polls by result.
    pub polls: Family<PollLabels, Counter>,
    /// Failed requests by kind.
    pub errors: Family<ErrorLabels, Counter>,
    /// Polls that got no answer in time.
    pub timeouts: Family<DeviceLabels, Counter>,
    /// Time one poll of a group took, seconds.
    pub poll_seconds: HistogramFamily,
    /// 1 while the device answers.
    pub device_up: Family<DeviceLabels, Gauge>,
    /// Generic Modbus devices: requests the last answered poll sent (the read plan's
    /// reads, more while a refused read is being split).
    pub modbus_requests_per_poll: Family<DeviceLabels, Gauge>,
    /// Time the line spent on requests, seconds.
    pub line_busy_seconds: Family<LineLabels, Counter<f64, AtomicU64>>,
    /// Share of the last window the line was busy (0–1).
    pub line_utilisation: Family<LineLabels, Gauge<f64, AtomicU64>>,
    /// 1 while the line is open.
    pub line_open: Family<LineLabels, Gauge>,
    /// Lines reopened because every device on them stopped answering.
    pub line_reopens_for_silence: Family<LineLabels, Counter>,
    /// Value changes seen.
    pub value_changes: Counter,
    /// Events emitted.
    pub events: Counter,
    /// Write attempts by result.
    pub writes: Family<WriteLabels, Counter>,
    /// Open event streams.
    pub sse_clients: Gauge,
    history_rows: Counter,
    history_commit_errors: Counter,
    history_rows_dropped: Counter,
    history_pending_rows: Gauge,
    /// Serialises scrapes, which bring the history counters up to date.
    scrape: Mutex<()>,
}

fn latency_histogram() -> Histogram {
    // 5 ms to about 20 s: one read at 19200 baud to a poll that timed out with retries.
    Histogram::new(exponential_buckets(0.005, 2.0, 12))
}

impl Default for Metrics {
    fn default() -> Self {
        Self::new()
    }
}

impl Metrics {
    /// Polls of `device` on `line` that ended with `result`, so far.
    pub fn poll_count(&self, line: &str, device: &str, result: PollResult) -> u64 {
        self.polls
            .get(&PollLabels {
                line: line.to_owned(),
                device: device.to_owned(),
                result,
            })
            .map_or(0, |c| c.get())
    }

    /// A device's timeouts so far (0 before its first), without creating the counter.
    pub fn timeout_count(&self, line: &str, device: &str) -> u64 {
        self.timeouts
            .get(&DeviceLabels {
                line: line.to_owned(),
                device: device.to_owned(),
            })
            .map_or(0, |c| c.get())
    }

    /// A device's errors of `kind` so far (0 before its first), without creating the
    /// counter.
    pub fn error_count(&self, line: &str, device: &str, kind: &str) -> u64 {
        self.errors
            .get(&ErrorLabels {
                line: line.to_owned(),
                device: device.to_owned(),
                kind: kind.to_owned(),
            })
            .map_or(0, |c| c.get())
    }

    /// Write attempts with `result` so far (0 before the first), without creating the
    /// counter.
    pub fn writes_of(&self, result: &str) -> u64 {
        self.writes
            .get(&WriteLabels {
                result: result.to_owned(),
            })
            .map_or(0, |c| c.get())
    }

    /// Registers every metric.
    pub fn new() -> Self {
        let mut registry = Registry::with_prefix("cellbus");
        let polls = Family::<PollLabels, Counter>::default();
        let errors = Family::<ErrorLabels, Counter>::default();
        let timeouts = Family::<DeviceLabels, Counter>::default();
        let poll_seconds = HistogramFamily::new_with_constructor(latency_histogram);
        let device_up = Family::<DeviceLabels, Gauge>::default();
        let modbus_requests_per_poll = Family::<DeviceLabels, Gauge>::default();
        let line_busy_seconds = Family::<LineLabels, Counter<f64, AtomicU64>>::default();
        let line_utilisation = Family::<LineLabels, Gauge<f64, AtomicU64>>::default();
        let line_open = Family::<LineLabels, Gauge>::default();
        let line_reopens_for_silence = Family::<LineLabels, Counter>::default();
        let value_changes = Counter::default();
        let events = Counter::default();
        let writes = Family::<WriteLabels, Counter>::default();
        let sse_clients = Gauge::default();
        let history_rows = Counter::default();
        let history_commit_errors = Counter::default();
        let history_rows_dropped = Counter::default();
        let history_pending_rows = Gauge::default();
        registry.register("polls", "Polls of a device's point group", polls.clone());
        registry.register(
            "errors",
            "Failed device requests by kind (timeout, refused, decode, line, disconnected)",
            errors.clone(),
        );
        registry.register(
            "timeouts",
            "Polls that got no answer in time",
            timeouts.clone(),
        );
        registry.register(
            "poll_duration_seconds",
            "Time one poll of a point group took on the line",
            poll_seconds.clone(),
        );
        registry.register("device_up", "1 while the device answers", device_up.clone());
        registry.register(
            "modbus_requests_per_poll",
            "Requests the last answered poll of a generic Modbus device sent",
            modbus_requests_per_poll.clone(),
        );
        registry.register(
            "line_busy_seconds",
            "Time the line spent on requests (its rate is the line's utilisation)",
            line_busy_seconds.clone(),
        );
        registry.register(
            "line_utilisation_ratio",
            "Share of the last few seconds the line was busy",
            line_utilisation.clone(),
        );
        registry.register("line_open", "1 while the line is open", line_open.clone());
        registry.register(
            "line_reopens_for_silence",
            "Times the line was closed and reopened because every device on it timed out several times in a row",
            line_reopens_for_silence.clone(),
        );
        registry.register(
            "value_changes",
            "Point value or quality changes seen",
            value_changes.clone(),
        );
        registry.register("events", "Events emitted", events.clone());
        registry.register("writes", "Write attempts by result", writes.clone());
        registry.register(
            "sse_clients",
            "Open server-sent event streams",
            sse_clients.clone(),
        );
        registry.register(
            "history_rows_written",
            "Rows committed to the history database (samples, events, audit)",
            history_rows.clone(),
        );
        registry.register(
            "history_commit_errors",
            "History commits that failed (rows are kept and retried)",
            history_commit_errors.clone(),
        );
        registry.register(
            "history_rows_dropped",
            "Rows never stored: oldest samples (then events, never audit rows) dropped while commits failed, or every row while the history is off",
            history_rows_dropped.clone(),
        );
        registry.register(
            "history_pending_rows",
            "Rows waiting for their history commit",
            history_pending_rows.clone(),
        );
        Self {
            registry: Mutex::new(registry),
            polls,
            errors,
            timeouts,
            poll_seconds,
            device_up,
            modbus_requests_per_poll,
            line_busy_seconds,
            line_utilisation,
            line_open,
            line_reopens_for_silence,
            value_changes,
            events,
            writes,
            sse_clients,
            history_rows,
            history_commit_errors,
            history_rows_dropped,
            history_pending_rows,
            scrape: Mutex::new(()),
        }
    }

    /// Registers the metrics of an interface or a core task (MQTT, OPC UA, the production
    /// and alarm keepers), named `cellbus_…` like the rest, when it starts.
    pub fn register(&self, register: impl FnOnce(&mut Registry)) {
        register(
            &mut self
                .registry
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner),
        );
    }

    /// The metrics in Prometheus text format, with the history counters brought up to date.
    pub fn encode(&self, store: &StoreStats) -> String {
        let _scrape = self
            .scrape
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        catch_up(&self.history_rows, store.rows_written());
        catch_up(
            &self.history_commit_errors,
            store
                .commit_errors
                .load(std::sync::atomic::Ordering::Relaxed),
        );
        catch_up(
            &self.history_rows_dropped,
            store
                .rows_dropped
                .load(std::sync::atomic::Ordering::Relaxed),
        );
        self.history_pending_rows
            .set(i64::try_from(store.rows_waiting()).unwrap_or(i64::MAX));
        let mut text = String::new();
        let registry = self
            .registry
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        prometheus_client::encoding::text::encode(&mut text, &registry)
            .expect("writing to a String cannot fail");
        text
    }
}

/// Raises a counter to `total` (counters only go up).
pub fn catch_up(counter: &Counter, total: u64) {
    let seen = counter.get();
    if total > seen {
        counter.inc_by(total - seen);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_text_format_carries_labels_and_the_history_count() {
        let metrics = Metrics::new();
        let device = DeviceLabels {
            line: "bench".into(),
            device: "jbc1".into(),
        };
        metrics
            .polls
            .get_or_create(&PollLabels {
                line: "bench".into(),
                device: "jbc1".into(),
                result: PollResult::ok,
            })
            .inc();
        metrics
            .poll_seconds
            .get_or_create(&LineLabels {
                line: device.line.clone(),
            })
            .observe(0.02);
        let stats = StoreStats::default();
        stats
            .samples_written
            .store(42, std::sync::atomic::Ordering::Relaxed);
        let text = metrics.encode(&stats);
        assert!(
            text.contains(r#"cellbus_polls_total{line="bench",device="jbc1",result="ok"} 1"#),
            "{text}"
        );
        assert!(
            text.contains("cellbus_history_rows_written_total 42"),
            "{text}"
        );
        assert!(
            text.contains("cellbus_poll_duration_seconds_bucket"),
            "{text}"
        );
        // A second scrape does not count the rows again.
        let text = metrics.encode(&stats);
        assert!(
            text.contains("cellbus_history_rows_written_total 42"),
            "{text}"
        );
    }
}
