//! One poll task per line.
//!
//! A [`LineTask`] owns its line and the drivers of the devices on it. It polls one group of
//! one device at a time, always the one due first, so requests on a line are strictly
//! serialised and each device keeps its periods while the line has time. When the line has
//! not (more groups due than it carries), the group furthest behind relative to its period
//! goes first, so every group slows by the same factor and a 1 s group keeps ten times the
//! reads of a 10 s one. Writes queued by
//! [`Cell::write`] go out between two polls. Separate lines run in parallel.
//!
//! A device that does not answer is marked down and backed off: it is tried again after
//! [`BACKOFF_FIRST`], then twice as long each time up to the larger of its fastest period
//! and [`BACKOFF_CAP`], with only its fastest group as a probe, so the others on the line
//! keep their rate, and a device whose line recovers is read again within that time. The
//! time of the next try is in the device's state (`next_try_at` in the API). When it
//! answers it is promoted back at once: every group is read straight away and polling
//! resumes at the configured periods.
//!
//! When the line itself fails (a TCP serial server closes, a USB adapter is pulled), every
//! device on it goes down and the task reopens the line, waiting [`REOPEN_FIRST`] doubling
//! to [`REOPEN_MAX`] between attempts. The wait starts again from [`REOPEN_FIRST`] only
//! once a device has answered on the line: one that opens and is lost before any answer (a
//! serial server that accepts the connection and closes it) counts as a failed attempt.
//! A line can also hang while it stays open (a serial
//! server's session stuck, an adapter wedged): when every device on it has timed out
//! `reopen_after_timeouts` times in a row, the task closes and reopens it at once, and
//! records a `line_reopened` event and `cellbus_line_reopens_for_silence_total`. If no
//! device answered since the last such reopen, the next needs twice as many timeouts (up
//! to [`SILENCE_THRESHOLD_GROWTH`] times the setting), so a cell whose devices are merely
//! switched off is not reopened every few seconds.
//!
//! Value changes become history samples and live messages; a point crossing into or out
//! of alarm and a device going down or up become events, and so do the events a driver
//! reports ([`Driver::take_events`]: transfers, machine states, unsolicited messages),
//! drained after every poll and write.

use std::sync::Arc;
use std::time::Duration;

use link::{Line, SerialSettings, SharedLine};
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::Histogram;
use tokio::sync::{mpsc, watch};
use tokio::time::Instant;
use wire::backoff::Backoff;

use crate::cell::{
    Cell, DeviceEntry, DeviceStatus, LineEntry, LinePlan, LiveMessage, WriteRequest,
};
use crate::config::{CellConfig, LineConfig};
use crate::driver::{BoxFuture, DeviceError, DeviceEvent, Driver, ErrorKind, Reading, WriteError};
use crate::event::{Event, EventKind};
use crate::metrics::{DeviceLabels, ErrorLabels, LineLabels, Metrics, PollLabels, PollResult};
use crate::point::{Deadband, Quality, Value};
use crate::store::{Sample, StoreHandle};
use crate::time::Timestamp;

/// First wait before a device that stopped answering is tried again.
pub const BACKOFF_FIRST: Duration = Duration::from_secs(2);
/// Longest wait between tries of a device that does not answer, unless its fastest period
/// is longer: a device whose line recovers is read again within the larger of the two.
pub const BACKOFF_CAP: Duration = Duration::from_secs(10);
/// How far the timeouts needed before a reopen for silence grow while reopening does not
/// help: up to this many times the line's `reopen_after_timeouts`.
pub const SILENCE_THRESHOLD_GROWTH: u32 = 16;
/// First wait before a line that failed is reopened.
pub const REOPEN_FIRST: Duration = Duration::from_secs(1);
/// Longest wait between attempts to reopen a line.
pub const REOPEN_MAX: Duration = Duration::from_secs(30);
/// Window over which line health (utilisation, poll and error rates) is measured.
pub const HEALTH_WINDOW: Duration = Duration::from_secs(5);

/// How often good values are checked for staleness.
pub const STALE_SWEEP: Duration = Duration::from_secs(1);

/// Opens a line (again): by endpoint in production, in memory in tests.
pub type Opener = Arc<dyn Fn() -> BoxFuture<'static, Result<Line, String>> + Send + Sync>;

/// The cell `config` describes, with one poll task per line; lines are opened by their
/// endpoints.
pub fn build(
    config: &CellConfig,
    store: StoreHandle,
    metrics: Arc<Metrics>,
) -> Result<(Arc<Cell>, Vec<LineTask>), String> {
    build_with_openers(config, store, metrics, line_opener)
}

/// Like [`build`], with the lines opened by `opener` (tests use in-memory lines).
pub fn build_with_openers(
    config: &CellConfig,
    store: StoreHandle,
    metrics: Arc<Metrics>,
    opener: impl Fn(&LineConfig) -> Opener,
) -> Result<(Arc<Cell>, Vec<LineTask>), String> {
    let (cell, plans) = Cell::new(config, store, metrics)?;
    let tasks = config
        .lines
        .iter()
        .zip(plans)
        .map(|(line, plan)| LineTask::new(Arc::clone(&cell), plan, opener(line)))
        .collect();
    Ok((cell, tasks))
}

/// Drops the series of the line `line` and of its `devices` from `/metrics`: a reload
/// stopped its task, and a device or line no longer polled must not show its last state
/// (`cellbus_device_up` 1) for ever. A task started again for the line makes them anew.
pub(crate) fn forget_metrics(metrics: &Metrics, line: &str, devices: &[crate::point::DeviceId]) {
    for device in devices {
        let labels = DeviceLabels {
            line: line.to_owned(),
            device: device.to_string(),
        };
        metrics.device_up.remove(&labels);
        metrics.modbus_requests_per_poll.remove(&labels);
        metrics.timeouts.remove(&labels);
        for result in [PollResult::ok, PollResult::error] {
            metrics.polls.remove(&PollLabels {
                line: line.to_owned(),
                device: device.to_string(),
                result,
            });
        }
        for kind in ErrorKind::ALL {
            metrics.errors.remove(&ErrorLabels {
                line: line.to_owned(),
                device: device.to_string(),
                kind: kind.as_str().to_owned(),
            });
        }
    }
    let labels = LineLabels {
        line: line.to_owned(),
    };
    metrics.poll_seconds.remove(&labels);
    metrics.line_busy_seconds.remove(&labels);
    metrics.line_utilisation.remove(&labels);
    metrics.line_open.remove(&labels);
    metrics.line_reopens_for_silence.remove(&labels);
}

/// Opens a configured line: by its endpoint URL, or, for a protocol whose client keeps
/// its own connections ([`DeviceKind::owns_connections`](crate::driver::DeviceKind::owns_connections)), not at all: the line task then
/// gets a line that carries nothing and only schedules the device's polls.
pub fn line_opener(line: &LineConfig) -> Opener {
    if !line.owns_connections() {
        return endpoint_opener(line.endpoint.clone());
    }
    let name = line.endpoint.to_string();
    Arc::new(move || {
        let line = link::Line::from_stream(tokio::io::empty(), name.clone(), None);
        Box::pin(async move { Ok(line) })
    })
}

/// Opens lines by their endpoint URL.
pub fn endpoint_opener(endpoint: link::Endpoint) -> Opener {
    Arc::new(move || {
        let endpoint = endpoint.clone();
        Box::pin(async move { link::Line::open(&endpoint).await.map_err(|e| e.to_string()) })
    })
}

/// The poll task of one line.
pub struct LineTask {
    cell: Arc<Cell>,
    line: Arc<LineEntry>,
    opener: Opener,
    slots: Vec<Slot>,
    writes: mpsc::Receiver<WriteRequest>,
    window: Window,
    last_sweep: Instant,
    busy_seconds: prometheus_client::metrics::counter::Counter<f64, std::sync::atomic::AtomicU64>,
    utilisation: Gauge<f64, std::sync::atomic::AtomicU64>,
    open_gauge: Gauge,
    reopens_for_silence: Counter,
    /// Timeouts in a row every device must reach before the line is reopened for silence
    /// (0: never); doubles while reopening does not help.
    silence_threshold: u32,
    /// A device answered (even with a refusal) since the line was last opened.
    answered: bool,
}

impl std::fmt::Debug for LineTask {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LineTask")
            .field("line", &self.line.name)
            .field("devices", &self.slots.len())
            .finish()
    }
}

/// A device on the line with its driver and its clocks.
struct Slot {
    entry: Arc<DeviceEntry>,
    driver: Box<dyn Driver>,
    clocks: Vec<Clock>,
    /// The group used to probe a backed-off device (the fastest).
    probe: usize,
    backoff: Option<BackedOff>,
    /// Polls in a row that got no answer in time.
    timeouts_in_a_row: u32,
    m: SlotMetrics,
}

struct Clock {
    group: String,
    period: Duration,
    next: Instant,
}

#[derive(Debug, Clone, Copy)]
struct BackedOff {
    next: Instant,
}

struct SlotMetrics {
    ok: Counter,
    /// The line's poll duration histogram (per line, not per device: 1,000 devices' buckets
    /// would be most of `/metrics`).
    latency: Histogram,
    up: Gauge,
    failures: FailureMetrics,
    /// Drivers that plan their reads (generic Modbus): requests of the last poll.
    requests_per_poll: Option<Gauge>,
}

/// A device's failure counters, created at its first failure of each kind, so that a
/// thousand healthy devices do not fill `/metrics` with zeros.
#[derive(Debug)]
struct FailureMetrics {
    polls: Family<PollLabels, Counter>,
    timeouts: Family<DeviceLabels, Counter>,
    errors: Family<ErrorLabels, Counter>,
    labels: DeviceLabels,
}

impl FailureMetrics {
    fn count(&self, kind: ErrorKind) {
        let DeviceLabels { line, device } = &self.labels;
        self.polls
            .get_or_create(&PollLabels {
                line: line.clone(),
                device: device.clone(),
                result: PollResult::error,
            })
            .inc();
        if kind == ErrorKind::Timeout {
            self.timeouts.get_or_create(&self.labels).inc();
        }
        self.errors
            .get_or_create(&ErrorLabels {
                line: line.clone(),
                device: device.clone(),
                kind: kind.as_str().to_owned(),
            })
            .inc();
    }
}

#[derive(Debug)]
struct Window {
    started: Instant,
    busy: Duration,
    polls: u64,
    errors: u64,
}

/// Why the poll loop ended.
enum Ended {
    Stop,
    LineLost(String),
    /// Every device on the line timed out often enough in a row: reopen it.
    Silent,
}

/// Why a poll or a write ends the poll loop.
enum Lost {
    /// The line failed.
    Line(String),
    /// The line is open but nothing on it answers.
    Silent,
}

impl LineTask {
    pub(crate) fn new(cell: Arc<Cell>, plan: LinePlan, opener: Opener) -> Self {
        let LinePlan {
            entry: line,
            devices,
            writes,
        } = plan;
        let shared = Arc::clone(&cell);
        let metrics = shared.metrics();
        let now = Instant::now();
        let line_latency = metrics
            .poll_seconds
            .get_or_create(&LineLabels {
                line: line.name.clone(),
            })
            .clone();
        let slots = devices
            .into_iter()
            .map(|(entry, driver)| {
                let labels = DeviceLabels {
                    line: line.name.clone(),
                    device: entry.id.to_string(),
                };
                let m = SlotMetrics {
                    ok: metrics
                        .polls
                        .get_or_create(&PollLabels {
                            line: line.name.clone(),
                            device: entry.id.to_string(),
                            result: PollResult::ok,
                        })
                        .clone(),
                    up: metrics.device_up.get_or_create(&labels).clone(),
                    requests_per_poll: entry.protocol.plans_reads().then(|| {
                        metrics
                            .modbus_requests_per_poll
                            .get_or_create(&labels)
                            .clone()
                    }),
                    latency: line_latency.clone(),
                    failures: FailureMetrics {
                        polls: metrics.polls.clone(),
                        timeouts: metrics.timeouts.clone(),
                        errors: metrics.errors.clone(),
                        labels,
                    },
                };
                let clocks: Vec<Clock> = entry
                    .groups
                    .iter()
                    .map(|g| Clock {
                        group: g.name.clone(),
                        period: g.period,
                        next: now,
                    })
                    .collect();
                let probe = clocks
                    .iter()
                    .enumerate()
                    .min_by_key(|(_, c)| c.period)
                    .map_or(0, |(i, _)| i);
                Slot {
                    entry,
                    driver,
                    clocks,
                    probe,
                    backoff: None,
                    timeouts_in_a_row: 0,
                    m,
                }
            })
            .collect();
        let labels = LineLabels {
            line: line.name.clone(),
        };
        Self {
            busy_seconds: metrics.line_busy_seconds.get_or_create(&labels).clone(),
            utilisation: metrics.line_utilisation.get_or_create(&labels).clone(),
            open_gauge: metrics.line_open.get_or_create(&labels).clone(),
            reopens_for_silence: metrics
                .line_reopens_for_silence
                .get_or_create(&labels)
                .clone(),
            silence_threshold: line.reopen_after_timeouts,
            answered: false,
            cell,
            line,
            opener,
            slots,
            writes,
            last_sweep: now,
            window: Window {
                started: now,
                busy: Duration::ZERO,
                polls: 0,
                errors: 0,
            },
        }
    }

    /// The line's name.
    pub fn name(&self) -> &str {
        &self.line.name
    }

    /// The estimated load of the line's polls at `serial`, from the drivers and periods in
    /// force ([`crate::load::line_load`]).
    pub fn load(&self, serial: SerialSettings) -> crate::load::LineLoad {
        let polls = self.slots.iter().flat_map(|slot| {
            slot.entry.groups.iter().map(move |group| {
                (
                    slot.entry.id.as_str(),
                    slot.driver.as_ref(),
                    group.name.clone(),
                    group.period,
                )
            })
        });
        crate::load::line_load(&self.line.name, serial, polls)
    }

    /// Polls until `shutdown` turns true (or its sender is dropped).
    pub async fn run(mut self, mut shutdown: watch::Receiver<bool>) {
        let mut reopen = Backoff::new(REOPEN_FIRST, REOPEN_MAX).timer();
        loop {
            let opened = tokio::select! {
                biased;
                () = stopped(&mut shutdown) => return,
                opened = (self.opener)() => opened,
            };
            let line = match opened {
                Ok(line) => line,
                Err(error) => {
                    let wait = reopen.next_wait();
                    if !self.failed_then_wait(&error, wait, &mut shutdown).await {
                        return;
                    }
                    continue;
                }
            };
            // The wait is reset once a device answers on the line, not when it opens: a
            // serial server that accepts the connection and drops it at once would
            // otherwise be reconnected to every second, with two events each time.
            self.answered = false;
            self.line_opened();
            let shared = SharedLine::new(line);
            let now = Instant::now();
            for slot in &mut self.slots {
                slot.driver.attach(shared.clone());
                slot.backoff = None;
                for clock in &mut slot.clocks {
                    clock.next = now;
                }
            }
            let ended = self.poll_loop(&mut shutdown).await;
            if self.answered {
                reopen.reset();
            }
            // Close the line before opening it again (a serial port opens only once).
            drop(shared);
            for slot in &mut self.slots {
                slot.driver.attach(closed_line(&self.line.endpoint));
            }
            match ended {
                Ended::Stop => return,
                Ended::Silent => self.reopen_for_silence(),
                Ended::LineLost(error) => {
                    let wait = if self.answered {
                        REOPEN_FIRST
                    } else {
                        reopen.next_wait()
                    };
                    if !self.failed_then_wait(&error, wait, &mut shutdown).await {
                        return;
                    }
                }
            }
        }
    }

    /// Marks the line failed for `error` and waits `wait` before the next open, refusing
    /// writes meanwhile; false when the gateway stops during the wait.
    async fn failed_then_wait(
        &mut self,
        error: &str,
        wait: Duration,
        shutdown: &mut watch::Receiver<bool>,
    ) -> bool {
        self.line_failed(error, wait);
        self.wait_refusing_writes(Instant::now() + wait, error, shutdown)
            .await
    }

    async fn poll_loop(&mut self, shutdown: &mut watch::Receiver<bool>) -> Ended {
        loop {
            let due = self.next_due();
            let at = due.map_or_else(|| Instant::now() + Duration::from_secs(3600), |d| d.2);
            tokio::select! {
                biased;
                () = stopped(shutdown) => return Ended::Stop,
                Some(request) = self.writes.recv() => {
                    if let Some(lost) = self.write(request).await {
                        return Ended::LineLost(lost);
                    }
                }
                () = tokio::time::sleep_until(at) => {
                    let Some((slot, group, _)) = due else { continue };
                    let lost = tokio::select! {
                        biased;
                        () = stopped(shutdown) => return Ended::Stop,
                        lost = self.poll(slot, group) => lost,
                    };
                    match lost {
                        None => {}
                        Some(Lost::Line(error)) => return Ended::LineLost(error),
                        Some(Lost::Silent) => return Ended::Silent,
                    }
                }
            }
        }
    }

    /// The device and group to poll next: `(slot, clock, when)` (see [`most_urgent`]).
    fn next_due(&self) -> Option<(usize, usize, Instant)> {
        let candidates = self.slots.iter().enumerate().flat_map(|(i, slot)| {
            let backoff = slot.backoff.map(|b| Due {
                slot: i,
                clock: slot.probe,
                at: b.next,
                period: slot.clocks[slot.probe].period,
            });
            let clocks = slot
                .clocks
                .iter()
                .enumerate()
                .filter(move |_| slot.backoff.is_none())
                .map(move |(g, c)| Due {
                    slot: i,
                    clock: g,
                    at: c.next,
                    period: c.period,
                });
            backoff.into_iter().chain(clocks)
        });
        most_urgent(candidates, Instant::now()).map(|d| (d.slot, d.clock, d.at))
    }

    /// Polls one group; says whether the line is lost or silent.
    async fn poll(&mut self, index: usize, clock: usize) -> Option<Lost> {
        let slot = &mut self.slots[index];
        let started = Instant::now();
        let result = slot.driver.poll(&slot.clocks[clock].group).await;
        let now = Instant::now();
        let took = now - started;
        slot.m.latency.observe(took.as_secs_f64());
        self.busy_seconds.inc_by(took.as_secs_f64());
        self.window.busy += took;
        self.window.polls += 1;
        let mut lost = None;
        match result {
            Ok(readings) => {
                self.answered = true;
                slot.m.ok.inc();
                slot.timeouts_in_a_row = 0;
                self.silence_threshold = self.line.reopen_after_timeouts;
                let was_up = slot.backoff.is_none() && slot.entry.read().status == DeviceStatus::Up;
                slot.backoff = None;
                let c = &mut slot.clocks[clock];
                c.next = (c.next + c.period).max(now);
                if !was_up {
                    // Promoted at once: read everything now, then resume the periods.
                    for (g, c) in slot.clocks.iter_mut().enumerate() {
                        if g != clock {
                            c.next = now;
                        }
                    }
                }
                let entry = Arc::clone(&slot.entry);
                slot.m.up.set(1);
                if let (Some(gauge), Some(requests)) =
                    (&slot.m.requests_per_poll, slot.driver.requests_per_poll())
                {
                    gauge.set(i64::try_from(requests).unwrap_or(i64::MAX));
                }
                apply_readings(&self.cell, &entry, readings);
                mark_up(&self.cell, &entry);
                record_events(&self.cell, &entry, slot.driver.take_events());
            }
            Err(error) => {
                slot.m.failures.count(error.kind);
                self.window.errors += 1;
                if error.kind == ErrorKind::Timeout {
                    slot.timeouts_in_a_row += 1;
                } else if error.kind != ErrorKind::Disconnected {
                    // An answer, even a refusal or a damaged one: the line carries bytes.
                    slot.timeouts_in_a_row = 0;
                    self.answered = true;
                } else {
                    slot.timeouts_in_a_row = 0;
                }
                slot.m.up.set(0);
                let failures = slot.entry.read().failures + 1;
                let delay = backoff_delay(failures, slot.clocks[slot.probe].period);
                slot.backoff = Some(BackedOff { next: now + delay });
                let entry = Arc::clone(&slot.entry);
                // What the poll read before it failed is recorded first: those values were
                // good when read.
                let partial = slot.driver.take_partial();
                if !partial.is_empty() {
                    apply_readings(&self.cell, &entry, partial);
                }
                mark_down(&self.cell, &entry, &error, delay);
                if error.kind == ErrorKind::Disconnected {
                    lost = Some(Lost::Line(error.message));
                }
            }
        }
        if lost.is_none() && self.is_silent() {
            lost = Some(Lost::Silent);
        }
        self.roll_window(now);
        if now - self.last_sweep >= STALE_SWEEP {
            self.last_sweep = now;
            for slot in &self.slots {
                mark_stale(&self.cell, &slot.entry);
            }
        }
        lost
    }

    /// Whether every device on the line has timed out often enough in a row to reopen it.
    fn is_silent(&self) -> bool {
        self.silence_threshold > 0
            && self
                .slots
                .iter()
                .all(|s| s.timeouts_in_a_row >= self.silence_threshold)
    }

    /// Records a reopen for silence; the next needs more timeouts unless a device answers.
    fn reopen_for_silence(&mut self) {
        self.reopens_for_silence.inc();
        let threshold = self.silence_threshold;
        self.cell.line_event(
            &self.line,
            EventKind::LineReopened,
            format!(
                "line {} reopened: every device on it timed out {threshold} times in a row ({})",
                self.line.name, self.line.endpoint
            ),
        );
        for slot in &mut self.slots {
            slot.timeouts_in_a_row = 0;
        }
        let ceiling = self
            .line
            .reopen_after_timeouts
            .saturating_mul(SILENCE_THRESHOLD_GROWTH);
        self.silence_threshold = threshold.saturating_mul(2).min(ceiling);
    }

    /// Writes between polls; returns the error if the line is lost.
    async fn write(&mut self, request: WriteRequest) -> Option<String> {
        let Some(slot) = self.slots.iter_mut().find(|s| s.entry.id == request.device) else {
            let _ = request.reply.send(Err(WriteError::NotRunning {
                line: self.line.name.clone(),
            }));
            return None;
        };
        let Some(spec) = slot.entry.points.get(request.point).cloned() else {
            let _ = request.reply.send(Err(WriteError::NotRunning {
                line: self.line.name.clone(),
            }));
            return None;
        };
        let started = Instant::now();
        let result = slot.driver.write(&spec, &request.value).await;
        let now = Instant::now();
        let took = now - started;
        self.busy_seconds.inc_by(took.as_secs_f64());
        self.window.busy += took;
        record_events(&self.cell, &slot.entry, slot.driver.take_events());
        let lost = match &result {
            Ok(()) => {
                // Read the point back at once (unless the device is backed off).
                if let Some(c) = slot.clocks.iter_mut().find(|c| c.group == spec.group) {
                    c.next = now;
                }
                None
            }
            Err(WriteError::Device(e)) if e.kind == ErrorKind::Disconnected => {
                Some(e.message.clone())
            }
            Err(_) => None,
        };
        let _ = request.reply.send(result);
        lost
    }

    /// Waits until `until`, answering writes with the line's error. False on shutdown.
    async fn wait_refusing_writes(
        &mut self,
        until: Instant,
        error: &str,
        shutdown: &mut watch::Receiver<bool>,
    ) -> bool {
        loop {
            tokio::select! {
                biased;
                () = stopped(shutdown) => return false,
                Some(request) = self.writes.recv() => {
                    let _ = request.reply.send(Err(WriteError::Device(DeviceError::new(
                        ErrorKind::Disconnected,
                        format_args!("line {} is not open: {error}", self.line.name),
                    ))));
                }
                () = tokio::time::sleep_until(until) => return true,
            }
        }
    }

    fn line_opened(&mut self) {
        self.open_gauge.set(1);
        {
            let mut state = self.line.write_state();
            state.open = true;
            state.error = None;
        }
        self.cell.line_event(
            &self.line,
            EventKind::LineUp,
            format!("line {} open ({})", self.line.name, self.line.endpoint),
        );
    }

    fn line_failed(&mut self, error: &str, retry: Duration) {
        self.open_gauge.set(0);
        let changed = {
            let mut state = self.line.write_state();
            let changed = state.open || state.error.as_deref() != Some(error);
            state.open = false;
            state.error = Some(error.to_owned());
            changed
        };
        if changed {
            self.cell.line_event(
                &self.line,
                EventKind::LineDown,
                format!(
                    "line {} is down: {error}; retrying every {} s at most",
                    self.line.name,
                    REOPEN_MAX.as_secs()
                ),
            );
        }
        let device_error = DeviceError::new(
            ErrorKind::Disconnected,
            format_args!("line {} is not open: {error}", self.line.name),
        );
        for slot in &mut self.slots {
            slot.m.up.set(0);
            mark_down(&self.cell, &slot.entry, &device_error, retry);
        }
    }

    fn roll_window(&mut self, now: Instant) {
        let elapsed = now - self.window.started;
        if elapsed < HEALTH_WINDOW {
            return;
        }
        let secs = elapsed.as_secs_f64();
        let utilisation = (self.window.busy.as_secs_f64() / secs).min(1.0);
        self.utilisation.set(utilisation);
        {
            let mut state = self.line.write_state();
            state.utilisation = utilisation;
            state.polls_per_second = self.window.polls as f64 / secs;
            state.errors_per_second = self.window.errors as f64 / secs;
        }
        self.window = Window {
            started: now,
            busy: Duration::ZERO,
            polls: 0,
            errors: 0,
        };
    }
}

/// Resolves when shutdown is asked for (or nobody can ask any more).
async fn stopped(shutdown: &mut watch::Receiver<bool>) {
    let _ = shutdown.wait_for(|stop| *stop).await;
}

/// A group (or a backed-off device's probe) waiting for its turn on the line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Due {
    slot: usize,
    clock: usize,
    at: Instant,
    period: Duration,
}

/// Which candidate to poll next. While the line keeps up, the one due first. When several
/// are overdue (the line cannot keep every period), the one furthest behind relative to its
/// period, ties to the earliest: an overloaded line then slows every group by the same
/// factor, instead of giving a 1 s group the same share as a 60 s one.
fn most_urgent(candidates: impl IntoIterator<Item = Due>, now: Instant) -> Option<Due> {
    let behind = |d: &Due| {
        now.saturating_duration_since(d.at).as_secs_f64() / d.period.as_secs_f64().max(1e-3)
    };
    let mut best: Option<Due> = None;
    for candidate in candidates {
        let better = match best {
            None => true,
            Some(b) if candidate.at <= now && b.at <= now => {
                let (c, b_) = (behind(&candidate), behind(&b));
                c > b_ || (c == b_ && candidate.at < b.at)
            }
            Some(b) => candidate.at < b.at,
        };
        if better {
            best = Some(candidate);
        }
    }
    best
}

/// The wait before try number `failures + 1` of a device that does not answer, whose
/// fastest group has `period`: doubling from [`BACKOFF_FIRST`] up to the larger of
/// `period` and [`BACKOFF_CAP`].
pub fn backoff_delay(failures: u32, period: Duration) -> Duration {
    Backoff::new(BACKOFF_FIRST, period.max(BACKOFF_CAP)).after(failures)
}

/// A line that carries nothing, held by the drivers while their real line is closed.
fn closed_line(name: &str) -> SharedLine {
    SharedLine::new(Line::from_stream(tokio::io::empty(), name.to_owned(), None))
}

/// Stores and publishes what changed in a poll's readings.
pub(crate) fn apply_readings(cell: &Cell, entry: &DeviceEntry, readings: Vec<Reading>) {
    let now = Timestamp::now();
    let mut samples = Vec::new();
    let mut messages = Vec::new();
    {
        let mut state = entry.write_state();
        // Drivers give their readings in the order of their points: the point after the
        // last one found is tried first, the search by name only when it is not that one.
        let mut next = 0;
        for reading in readings {
            let guess = entry
                .points
                .get(next)
                .filter(|spec| spec.id == reading.point)
                .map(|_| next);
            let Some(i) = guess.or_else(|| entry.point_index(reading.point.name())) else {
                continue;
            };
            next = i + 1;
            let (Some(spec), Some(point)) = (entry.points.get(i), state.points.get_mut(i)) else {
                continue;
            };
            let changed = match reading.value {
                Ok(value) => {
                    let deadband = entry.deadband(i);
                    let changed = point.quality != Some(Quality::Good)
                        || moved_enough(point.recorded(), point.value.as_ref(), &value, deadband);
                    // Whether it is an alarm; the alarm keeper (`alarm::keeper`) raises and
                    // journals it from the change stream.
                    let alarm = spec.is_alarm(&value);
                    point.value = Some(value);
                    point.quality = Some(Quality::Good);
                    point.error = None;
                    point.alarm = alarm;
                    point.t = Some(now);
                    changed
                }
                Err(error) => {
                    let changed = point.quality != Some(Quality::Bad)
                        || point.error.as_deref().map(String::as_str)
                            != Some(error.message.as_str());
                    point.quality = Some(Quality::Bad);
                    point.error = Some(Arc::new(error.message));
                    point.t = Some(now);
                    changed
                }
            };
            if changed {
                point.set_recorded();
                samples.push(Sample {
                    point: spec.id.clone(),
                    t: now,
                    value: match point.quality {
                        Some(Quality::Good) => point.value.clone(),
                        _ => None,
                    },
                    quality: point.quality.unwrap_or(Quality::Bad),
                });
                messages.push(entry.point_view(i, point, now));
            }
        }
    }
    record(cell, samples, messages);
}

/// Whether a good value is to be recorded against the last recorded one: any change, or
/// under a deadband a move at least as big as the band (numbers only).
///
/// `recorded` is the number last recorded, if it was one; otherwise what was last recorded
/// is `last`, the point's value before `value` (text is never held back).
fn moved_enough(
    recorded: Option<f64>,
    last: Option<&Value>,
    value: &Value,
    deadband: Option<Deadband>,
) -> bool {
    let number;
    let recorded = match recorded {
        Some(x) => {
            number = Value::Number(x);
            Some(&number)
        }
        None => last,
    };
    match (recorded, deadband) {
        (None, _) => true,
        (Some(recorded), None) => recorded != value,
        (Some(recorded), Some(band)) => match (recorded.as_number(), value.as_number()) {
            (Some(before), Some(now)) => before != now && band.passes(before, now),
            _ => recorded != value,
        },
    }
}

/// Records what the driver saw happen (transfers, machine states, unsolicited messages).
fn record_events(cell: &Cell, entry: &DeviceEntry, events: Vec<DeviceEvent>) {
    for event in events {
        let point = event
            .point
            .and_then(|name| entry.point_index(name))
            .and_then(|i| entry.points.get(i))
            .map(|spec| spec.id.clone());
        cell.emit(Event {
            t: event.at.unwrap_or_else(Timestamp::now),
            kind: event.kind,
            line: Some(entry.line.clone()),
            device: Some(entry.id.clone()),
            point,
            message: format!("{}: {}", entry.name, event.message),
            fields: event.fields,
        });
    }
}

/// Marks a device up after an answered poll; an event if it was down.
fn mark_up(cell: &Cell, entry: &DeviceEntry) {
    let now = Timestamp::now();
    let previous = {
        let mut state = entry.write_state();
        let previous = state.status;
        state.failures = 0;
        state.next_try_at = None;
        state.last_ok = Some(now);
        if previous != DeviceStatus::Up {
            state.status = DeviceStatus::Up;
            state.since = now;
            state.error = None;
        }
        previous
    };
    if previous == DeviceStatus::Up {
        return;
    }
    cell.publish(LiveMessage::Device(Box::new(entry.summary())));
    if previous == DeviceStatus::Down {
        cell.emit(Event {
            t: now,
            kind: EventKind::DeviceUp,
            line: Some(entry.line.clone()),
            device: Some(entry.id.clone()),
            point: None,
            message: format!("{} answers again", entry.label()),
            fields: crate::event::Fields::new(),
        });
    }
}

/// Marks a device down (backed off for `retry`) and its points bad.
fn mark_down(cell: &Cell, entry: &DeviceEntry, error: &DeviceError, retry: Duration) {
    let now = Timestamp::now();
    let mut samples = Vec::new();
    let mut views = Vec::new();
    let went_down = {
        let mut state = entry.write_state();
        let went_down = state.status != DeviceStatus::Down;
        state.failures += 1;
        state.next_try_at = Some(now.plus(retry));
        state.error = Some(error.clone());
        if went_down {
            state.status = DeviceStatus::Down;
            state.since = now;
        }
        let message = Arc::new(error.message.clone());
        for (i, point) in state.points.iter_mut().enumerate() {
            if point.quality == Some(Quality::Bad) {
                continue;
            }
            point.quality = Some(Quality::Bad);
            point.error = Some(Arc::clone(&message));
            point.t = Some(now);
            samples.push(Sample {
                point: entry.points[i].id.clone(),
                t: now,
                value: None,
                quality: Quality::Bad,
            });
            views.push(entry.point_view(i, point, now));
        }
        went_down
    };
    record(cell, samples, views);
    cell.publish(LiveMessage::Device(Box::new(entry.summary())));
    if went_down {
        let mut fields = crate::event::fields([
            ("error_kind", serde_json::json!(error.kind.as_str())),
            ("error", serde_json::json!(error.message)),
            ("retry_s", serde_json::json!(retry.as_secs())),
        ]);
        if let Some(hint) = entry.protocol.hint(error.kind) {
            fields.insert("hint".to_owned(), serde_json::json!(hint));
        }
        cell.emit(Event {
            t: now,
            kind: EventKind::DeviceDown,
            line: Some(entry.line.clone()),
            device: Some(entry.id.clone()),
            point: None,
            message: format!(
                "{} is not answering ({}): {}; next try in {} s",
                entry.label(),
                error.kind,
                error.message,
                retry.as_secs()
            ),
            fields,
        });
    }
}

/// Turns good values that were not refreshed in time stale (stored and published), so a
/// slow or overloaded line shows on every screen, not only in fresh API reads.
fn mark_stale(cell: &Cell, entry: &DeviceEntry) {
    let now = Timestamp::now();
    let mut samples = Vec::new();
    let mut views = Vec::new();
    {
        let mut state = entry.write_state();
        for (i, point) in state.points.iter_mut().enumerate() {
            let Some(spec) = entry.points.get(i) else {
                continue;
            };
            if point.quality != Some(Quality::Good) {
                continue;
            }
            let period = entry.period(&spec.group);
            if crate::cell::judge_staleness(Quality::Good, point.t, period, now) != Quality::Stale {
                continue;
            }
            point.quality = Some(Quality::Stale);
            samples.push(Sample {
                point: spec.id.clone(),
                t: now,
                value: point.value.clone(),
                quality: Quality::Stale,
            });
            views.push(entry.point_view(i, point, now));
        }
    }
    record(cell, samples, views);
}

/// Records changes: counted, stored in the history, and told to the change stream.
fn record(cell: &Cell, samples: Vec<Sample>, views: Vec<crate::cell::PointView>) {
    cell.metrics().value_changes.inc_by(samples.len() as u64);
    for sample in samples {
        cell.store().sample(sample);
    }
    for view in views {
        cell.publish(LiveMessage::Value(Box::new(view)));
    }
}

#[cfg(test)]
mod tests;

#[cfg(test)]
mod protocol_tests;
