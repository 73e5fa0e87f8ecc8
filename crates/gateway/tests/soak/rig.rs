//! The noise soak: the real gateway polls simulated devices of every serial kind over noisy
//! lines (`testkit`'s noisy line, seeded), and the soak counts what matters to a user: how
//! many requests went out and how many frames were damaged, whether any wrong value was
//! taken as good, how many polls were answered, how long a device stayed down while its
//! line was merely noisy, and how long the cell took to recover from a total outage.
//!
//! Shared by the short soak test (`tests/soak.rs`, in memory and paused time) and the soak
//! bench (`benches/soak.rs`, over loopback TCP in real time).
//!
//! Each group of lines carries: a JBC station on its own line; three Thermosald regulators
//! on one line; a CROSS (unit 2) and a generic Modbus server (unit 1) on one RS-485 line.
//!
//! Wrong values are judged against the truth each point showed on a clean line: a calm
//! phase (no noise) first finds the points that keep one value (settings, counters, the
//! fault number, registers), the noisy phase then must never publish another value as
//! good for them, and a clean phase at the end checks that the truth still holds (a point
//! that changed on its own is left out, and counted). Measurements the drivers do not
//! confirm by a second read because they change between reads are the residual risk the
//! user guide states (docs/guide/src/jbc.md, thermosald.md): an idle JBC station's temperatures and power keep one value and are
//! counted apart; Thermosald run-time values move with every sealing cycle and are not
//! judged. Every other wrong value fails the soak.

#![allow(dead_code)] // each of the test and the bench uses part of it

use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use gateway::cell::{Cell, LiveMessage};
use gateway::config::{CellConfig, DeviceConfig, LineConfig};
use gateway::driver::modbus::{ModbusSettings, RegisterConfig};
use gateway::driver::{DriverConfig, Kind};
use gateway::metrics::{Metrics, PollResult};
use gateway::point::{DeviceId, PointId, Quality, Value};
use gateway::scheduler::Opener;
use gateway::store::{Store, StoreOptions};
use jbc::device::{Station, StationConfig};
use jbus::cross::device::CrossTwin;
use jbus::rtu::UnitId;
use jbus::slave::{Slave, SlaveMap};
use link::{Endpoint, Line};
use testkit::{LineControl, NoiseConfig, NoiseCounts, NoisyProxy, noisy_pipe};
use thermosald::Address;
use thermosald::device::{Regulator, RegulatorBus, RegulatorConfig};
use tokio::sync::{broadcast, watch};
use tokio::time::Instant;
use wire::device::{Bus, SharedModel};

/// How the gateway reaches the simulators.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transport {
    /// In-memory streams (for paused time).
    Memory,
    /// Loopback TCP through a noisy proxy, opened by the gateway's own `tcp://` opener.
    Tcp,
}

/// What to run.
#[derive(Debug, Clone)]
pub struct SoakOptions {
    /// Seed of every random thing (noise, CROSS measurements).
    pub seed: u64,
    /// The lines' trouble during the noisy phase.
    pub noise: NoiseConfig,
    /// Copies of the set of lines (3 lines, 6 devices each).
    pub groups: usize,
    /// Requests (frames towards the devices) to send during the noisy phase.
    pub requests: u64,
    /// The devices' poll period (every group).
    pub period: Duration,
    /// The JBC and Modbus reply timeout (Thermosald keeps its protocol's).
    pub timeout: Duration,
    /// The clean phase before the noise.
    pub calm: Duration,
    /// The total outage after the noise.
    pub outage: Duration,
    /// How the gateway reaches the simulators.
    pub transport: Transport,
}

impl Default for SoakOptions {
    fn default() -> Self {
        Self {
            seed: 1,
            noise: NoiseConfig::FIELD,
            groups: 1,
            requests: 3000,
            period: Duration::from_millis(50),
            timeout: Duration::from_millis(200),
            calm: Duration::from_secs(5),
            outage: Duration::from_secs(10),
            transport: Transport::Memory,
        }
    }
}

/// What the soak found.
#[derive(Debug, Clone, Default)]
pub struct SoakReport {
    /// Requests sent to the devices during the noisy phase.
    pub requests: u64,
    /// What the lines did to the frames in the noisy phase, both ways.
    pub line: NoiseCounts,
    /// Polls (one group of one device) in the noisy phase, and how many were answered.
    pub polls: u64,
    /// Polls answered.
    pub polls_answered: u64,
    /// Points judged (one true value each) by protocol.
    pub judged_points: BTreeMap<&'static str, usize>,
    /// Good values published for judged points during the noisy phase, by protocol.
    pub judged_values: BTreeMap<&'static str, u64>,
    /// Wrong values published as good for judged points, by protocol, with examples.
    pub wrong: BTreeMap<&'static str, u64>,
    /// Up to ten wrong values, `point: truth -> published`.
    pub wrong_examples: Vec<String>,
    /// Measurements (not confirmed by a second read) judged, by protocol.
    pub measurement_points: BTreeMap<&'static str, usize>,
    /// Wrong measurements published as good, by protocol: the residual risk.
    pub measurement_wrong: BTreeMap<&'static str, u64>,
    /// Points that kept one value in the calm phase but changed on their own by the end.
    pub drifted_points: usize,
    /// Live messages the soak missed (it fell behind the change stream): must be 0 for
    /// the count of wrong values to be complete.
    pub missed_messages: u64,
    /// The longest a device stayed down while its line was merely noisy.
    pub longest_down: Duration,
    /// Devices that went down during the noisy phase.
    pub downs: u64,
    /// Lines reopened because every device on them was silent.
    pub reopens_for_silence: u64,
    /// Time from the end of the total outage until every device answered again.
    pub recovery: Option<Duration>,
    /// Length of the noisy phase.
    pub noisy_for: Duration,
}

impl SoakReport {
    /// Wrong values published as good, all protocols.
    pub fn wrong_total(&self) -> u64 {
        self.wrong.values().sum()
    }

    /// Share of polls answered in the noisy phase.
    pub fn answered_share(&self) -> f64 {
        self.polls_answered as f64 / (self.polls.max(1)) as f64
    }

    /// The report, one fact a line.
    pub fn lines(&self) -> Vec<String> {
        let l = &self.line;
        let mut out = vec![
            format!(
                "requests {} in {:.1} s ({:.0}/s); polls {} of which answered {} ({:.2} %)",
                self.requests,
                self.noisy_for.as_secs_f64(),
                self.requests as f64 / self.noisy_for.as_secs_f64().max(1e-9),
                self.polls,
                self.polls_answered,
                100.0 * self.answered_share()
            ),
            format!(
                "frames carried {} ({} bytes), damaged {}: {} bits flipped, {} bytes lost, {} inserted, {} duplicated, {} frames lost, {} bursts",
                l.chunks,
                l.bytes,
                l.damaged_chunks,
                l.flipped,
                l.dropped,
                l.inserted,
                l.duplicated,
                l.frames_dropped,
                l.bursts
            ),
        ];
        for (protocol, points) in &self.judged_points {
            out.push(format!(
                "{protocol}: {points} points judged, {} good values published, {} wrong",
                self.judged_values.get(protocol).copied().unwrap_or(0),
                self.wrong.get(protocol).copied().unwrap_or(0)
            ));
        }
        for (protocol, points) in &self.measurement_points {
            out.push(format!(
                "{protocol} measurements (not confirmed, residual risk): {points} points judged, {} wrong",
                self.measurement_wrong.get(protocol).copied().unwrap_or(0)
            ));
        }
        for example in &self.wrong_examples {
            out.push(format!("  wrong: {example}"));
        }
        out.push(format!(
            "points that changed on their own (not judged): {}; live messages missed: {}",
            self.drifted_points, self.missed_messages
        ));
        out.push(format!(
            "devices went down {} times while the lines were noisy; longest down {:.1} s; lines reopened for silence {}",
            self.downs,
            self.longest_down.as_secs_f64(),
            self.reopens_for_silence
        ));
        out.push(match self.recovery {
            Some(r) => format!("recovery after the outage: {:.1} s", r.as_secs_f64()),
            None => "recovery after the outage: not within the limit".to_owned(),
        });
        out
    }
}

/// Why the soak could not run.
pub type SoakError = Box<dyn std::error::Error + Send + Sync>;

/// Runs the soak: calm, noisy, outage, recovery, clean check. Call it in a tokio runtime
/// (paused time with [`Transport::Memory`]).
pub async fn run(options: SoakOptions) -> Result<SoakReport, SoakError> {
    let dir = tempfile::tempdir()?;
    let store = Store::open(dir.path(), StoreOptions::default())?;
    let control = LineControl::default();
    control.set_noisy(false);
    let cell_set = CellSet::build(&options, &control).await?;
    let metrics = Arc::new(Metrics::new());
    let (cell, tasks) = gateway::scheduler::build_with_openers(
        &cell_set.config,
        store.handle(),
        Arc::clone(&metrics),
        |line| Arc::clone(&cell_set.openers[&line.name]),
    )?;
    let (shutdown, stop) = watch::channel(false);
    let running: Vec<_> = tasks
        .into_iter()
        .map(|t| tokio::spawn(t.run(stop.clone())))
        .collect();
    let mut watcher = Watcher::new(&cell);

    // Calm: the truth of every point that keeps one value.
    watcher.phase = Phase::Calm;
    watcher.run_for(options.calm).await;
    watcher.settle_truth();

    // Noisy: until enough requests went out.
    let polls_before = polls(&cell);
    let line_before = control.to_device().plus(control.to_client());
    watcher.phase = Phase::Noisy;
    control.set_noisy(true);
    let noisy_from = Instant::now();
    while control.to_device().minus(line_before).chunks < options.requests && !watcher.ended {
        watcher.run_for(Duration::from_millis(100)).await;
    }
    let noisy_for = noisy_from.elapsed();
    control.set_noisy(false);
    let line = control
        .to_device()
        .plus(control.to_client())
        .minus(line_before);
    let requests = control.to_device().minus(line_before).chunks;
    let polls_after = polls(&cell);
    watcher.close_downs(Instant::now());

    // A total outage, then the time until every device answers again.
    watcher.phase = Phase::Outage;
    control.set_outage(true);
    watcher.run_for(options.outage).await;
    control.set_outage(false);
    let back = Instant::now();
    watcher.phase = Phase::Recovery;
    let limit = Duration::from_secs(120);
    let mut recovery = None;
    while back.elapsed() < limit {
        if all_up(&cell) {
            recovery = Some(back.elapsed());
            break;
        }
        watcher.run_for(Duration::from_millis(50)).await;
    }

    // Clean: the truth still holds (or the point changed on its own).
    watcher.phase = Phase::Clean;
    watcher.run_for(options.calm).await;
    let drifted = watcher.drifted(&cell);

    shutdown.send(true)?;
    for task in running {
        task.await?;
    }
    store.handle().flush().await?;

    let mut report = SoakReport {
        requests,
        line,
        polls: (polls_after.0 + polls_after.1) - (polls_before.0 + polls_before.1),
        polls_answered: polls_after.0 - polls_before.0,
        drifted_points: drifted.len(),
        missed_messages: watcher.missed,
        longest_down: watcher.longest_down,
        downs: watcher.downs,
        recovery,
        noisy_for,
        ..SoakReport::default()
    };
    report.reopens_for_silence = cell
        .lines()
        .iter()
        .map(|l| {
            metrics
                .line_reopens_for_silence
                .get_or_create(&gateway::metrics::LineLabels {
                    line: l.name.clone(),
                })
                .get()
        })
        .sum();
    for (point, truth) in &watcher.truth {
        if drifted.contains(point) {
            continue;
        }
        let points = if truth.measurement {
            &mut report.measurement_points
        } else {
            &mut report.judged_points
        };
        *points.entry(truth.protocol).or_default() += 1;
    }
    for (point, published) in &watcher.published {
        if drifted.contains(point) {
            continue;
        }
        let Some(truth) = watcher.truth.get(point) else {
            continue;
        };
        if !truth.measurement {
            *report.judged_values.entry(truth.protocol).or_default() += published.len() as u64;
        }
        for value in published {
            if *value != truth.value {
                let wrong = if truth.measurement {
                    &mut report.measurement_wrong
                } else {
                    &mut report.wrong
                };
                *wrong.entry(truth.protocol).or_default() += 1;
                if report.wrong_examples.len() < 10 {
                    report.wrong_examples.push(format!(
                        "{point}{}: {:?} -> {value:?}",
                        if truth.measurement {
                            " (measurement)"
                        } else {
                            ""
                        },
                        truth.value
                    ));
                }
            }
        }
    }
    drop(cell_set);
    Ok(report)
}

/// The simulated devices, the gateway's configuration for them, and how each line opens.
struct CellSet {
    config: CellConfig,
    openers: HashMap<String, Opener>,
    _proxies: Vec<NoisyProxy>,
    _servers: Vec<tokio::task::JoinHandle<std::io::Result<()>>>,
}

/// The devices of one line, as a factory of per-connection buses.
type MakeBus = Arc<dyn Fn() -> Bus + Send + Sync>;

impl CellSet {
    async fn build(options: &SoakOptions, control: &LineControl) -> Result<Self, SoakError> {
        let mut set = CellSet {
            config: CellConfig::default(),
            openers: HashMap::new(),
            _proxies: Vec::new(),
            _servers: Vec::new(),
        };
        let connections = Arc::new(AtomicU64::new(0));
        for g in 0..options.groups {
            let now = Instant::now().into_std();
            // A JBC station on its own line.
            let station = SharedModel::new(Station::new(StationConfig::default()));
            let make: MakeBus = Arc::new(move || Bus(vec![Box::new(station.line())]));
            let jbc = device(&format!("jbc{g}"), gateway::driver::jbc::KIND, 1, options);
            set.add_line(
                options,
                control,
                &connections,
                &format!("jbc{g}"),
                vec![jbc],
                make,
            )
            .await?;
            // Three Thermosald regulators on one line.
            let regulators = (0u8..3)
                .map(|a| {
                    let address = Address::new(a).expect("0-2 are addresses");
                    Regulator::new(address, RegulatorConfig::default(), now)
                })
                .collect();
            let sealers = SharedModel::new(RegulatorBus::from_regulators(regulators));
            let make: MakeBus = Arc::new(move || Bus(vec![Box::new(sealers.line())]));
            let devices = (0..3)
                .map(|a| {
                    let mut d = device(
                        &format!("sealer{g}x{a}"),
                        gateway::driver::thermosald::KIND,
                        a,
                        options,
                    );
                    d.driver.timeout = None;
                    d
                })
                .collect();
            set.add_line(
                options,
                control,
                &connections,
                &format!("sealers{g}"),
                devices,
                make,
            )
            .await?;
            // A CROSS and a generic Modbus server on one RS-485 line.
            let cross = SharedModel::new(CrossTwin::new(
                UnitId::jbus(2).expect("2 is a unit"),
                options.seed.wrapping_add(g as u64),
            ));
            let map = SlaveMap::parse("unit 1\nholding 0 = 1234 0 65535 42 7 0x8000 12 13\n")
                .expect("the soak's map parses");
            let slave = SharedModel::new(Slave::new(map));
            let make: MakeBus =
                Arc::new(move || Bus(vec![Box::new(cross.line()), Box::new(slave.line())]));
            let mut meter = device(
                &format!("meter{g}"),
                gateway::driver::modbus::KIND,
                1,
                options,
            );
            let registers: Vec<RegisterConfig> = (0u16..8)
                .map(|address| RegisterConfig {
                    title: format!("Register {address}"),
                    format: jbus::data::Format::new(
                        if address == 5 {
                            jbus::data::DataType::Int16
                        } else {
                            jbus::data::DataType::Uint16
                        },
                        jbus::data::Order::Abcd,
                    ),
                    ..RegisterConfig::holding(&format!("r{address}"), address)
                })
                .collect();
            meter.driver.settings = gateway::config::Settings::new(ModbusSettings {
                registers: registers.into(),
                options: Default::default(),
            });
            let devices = vec![
                device(
                    &format!("cross{g}"),
                    gateway::driver::cross::KIND,
                    2,
                    options,
                ),
                meter,
            ];
            set.add_line(
                options,
                control,
                &connections,
                &format!("rs485-{g}"),
                devices,
                make,
            )
            .await?;
        }
        Ok(set)
    }

    async fn add_line(
        &mut self,
        options: &SoakOptions,
        control: &LineControl,
        connections: &Arc<AtomicU64>,
        name: &str,
        devices: Vec<DeviceConfig>,
        make: MakeBus,
    ) -> Result<(), SoakError> {
        let serial = devices[0].driver.protocol.default_serial();
        let (endpoint, opener): (Endpoint, Opener) = match options.transport {
            Transport::Memory => {
                let endpoint = Endpoint::parse("tcp://127.0.0.1:9", serial)?;
                let (noise, seed, control) = (options.noise, options.seed, control.clone());
                let connections = Arc::clone(connections);
                let name = name.to_owned();
                let opener: Opener = Arc::new(move || {
                    let (gateway_end, near) = tokio::io::duplex(4096);
                    let (far, device_end) = tokio::io::duplex(4096);
                    let n = connections.fetch_add(1, Ordering::Relaxed);
                    tokio::spawn(noisy_pipe(
                        near,
                        far,
                        noise,
                        seed.wrapping_add(n),
                        control.clone(),
                    ));
                    tokio::spawn(link::serve::serve_stream(device_end, make(), None));
                    let line = Line::from_stream(gateway_end, name.clone(), None);
                    Box::pin(async move { Ok(line) })
                });
                (endpoint, opener)
            }
            Transport::Tcp => {
                let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
                let upstream = listener.local_addr()?;
                let make = Arc::clone(&make);
                self._servers.push(tokio::spawn(link::serve::serve_tcp(
                    listener,
                    move || make(),
                    None,
                )));
                let seed = options
                    .seed
                    .wrapping_add(connections.fetch_add(1000, Ordering::Relaxed));
                let proxy =
                    NoisyProxy::start_with(upstream, options.noise, seed, control.clone()).await?;
                let endpoint = Endpoint::parse(&format!("tcp://{}", proxy.addr()), serial)?;
                self._proxies.push(proxy);
                let opener = gateway::scheduler::endpoint_opener(endpoint.clone());
                (endpoint, opener)
            }
        };
        self.openers.insert(name.to_owned(), opener);
        self.config.lines.push(LineConfig {
            name: name.to_owned(),
            endpoint,
            devices,
            reopen_after_timeouts: gateway::config::DEFAULT_REOPEN_AFTER_TIMEOUTS,
        });
        Ok(())
    }
}

fn device(id: &str, protocol: Kind, address: i64, options: &SoakOptions) -> DeviceConfig {
    let driver = DriverConfig {
        states: Default::default(),
        address: Some(address),
        timeout: Some(options.timeout),
        ..DriverConfig::new(
            DeviceId::new(id).expect("the soak's ids are valid"),
            protocol,
        )
    };
    DeviceConfig {
        period: Some(options.period),
        ..DeviceConfig::new(driver, id)
    }
}

/// Polls answered and failed so far, all devices.
fn polls(cell: &Cell) -> (u64, u64) {
    let metrics = cell.metrics();
    let mut ok = 0;
    let mut failed = 0;
    for line in cell.lines() {
        for device in &line.devices {
            ok += metrics.poll_count(&line.name, device.as_str(), PollResult::ok);
            failed += metrics.poll_count(&line.name, device.as_str(), PollResult::error);
        }
    }
    (ok, failed)
}

fn all_up(cell: &Cell) -> bool {
    cell.devices()
        .iter()
        .all(|d| d.summary.status == gateway::cell::DeviceStatus::Up)
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    Calm,
    Noisy,
    Outage,
    Recovery,
    Clean,
}

struct Truth {
    protocol: &'static str,
    /// Not confirmed by a second read (it changes between reads).
    measurement: bool,
    value: Value,
}

/// What the soak knows of a point.
#[derive(Debug, Clone, Copy)]
struct Judged {
    protocol: &'static str,
    measurement: bool,
}

/// Follows the gateway's change stream through the phases.
struct Watcher {
    live: broadcast::Receiver<LiveMessage>,
    phase: Phase,
    protocols: HashMap<PointId, Judged>,
    /// Good values seen in the calm phase, per point.
    calm: HashMap<PointId, Vec<Value>>,
    truth: HashMap<PointId, Truth>,
    /// Good values published in the noisy phase, per point.
    published: HashMap<PointId, Vec<Value>>,
    /// Good values seen in the clean phase, per point.
    clean: HashMap<PointId, Vec<Value>>,
    down_since: HashMap<DeviceId, Instant>,
    longest_down: Duration,
    downs: u64,
    missed: u64,
    ended: bool,
}

impl Watcher {
    fn new(cell: &Cell) -> Self {
        let mut protocols = HashMap::new();
        for view in cell.devices() {
            let Some(entry) = cell.device_entry(view.summary.id.as_str()) else {
                continue;
            };
            for point in &entry.points {
                // Thermosald run-time values move with every sealing cycle: no truth.
                if entry.protocol == gateway::driver::thermosald::KIND
                    && point.group == gateway::driver::thermosald::LIVE
                    && point.id.name() != "fault"
                {
                    continue;
                }
                // What the drivers do not confirm: values that change between two reads
                // (an idle station's temperatures and power keep one value, so they can be
                // judged, apart).
                let measurement = entry.protocol == gateway::driver::jbc::KIND
                    && point.group == gateway::driver::jbc::LIVE
                    && point.writable.is_none()
                    && point.kind == gateway::point::PointKind::Numeric;
                protocols.insert(
                    point.id.clone(),
                    Judged {
                        protocol: entry.protocol.name(),
                        measurement,
                    },
                );
            }
        }
        Self {
            live: cell.subscribe(),
            phase: Phase::Calm,
            protocols,
            calm: HashMap::new(),
            truth: HashMap::new(),
            published: HashMap::new(),
            clean: HashMap::new(),
            down_since: HashMap::new(),
            longest_down: Duration::ZERO,
            downs: 0,
            missed: 0,
            ended: false,
        }
    }

    /// Takes the change stream for `duration`.
    async fn run_for(&mut self, duration: Duration) {
        let until = Instant::now() + duration;
        loop {
            let message = tokio::select! {
                m = self.live.recv() => m,
                () = tokio::time::sleep_until(until) => return,
            };
            match message {
                Ok(m) => self.take(m),
                Err(broadcast::error::RecvError::Lagged(n)) => self.missed += n,
                Err(broadcast::error::RecvError::Closed) => {
                    self.ended = true;
                    return;
                }
            }
        }
    }

    fn take(&mut self, message: LiveMessage) {
        match message {
            LiveMessage::Value(view) => {
                let (Some(value), Some(Quality::Good)) = (view.value, view.quality) else {
                    return;
                };
                if !self.protocols.contains_key(&view.id) {
                    return;
                }
                let into = match self.phase {
                    Phase::Calm => &mut self.calm,
                    Phase::Noisy => &mut self.published,
                    Phase::Clean => &mut self.clean,
                    Phase::Outage | Phase::Recovery => return,
                };
                into.entry(view.id).or_default().push(value);
            }
            LiveMessage::Device(summary) => {
                if self.phase != Phase::Noisy {
                    return;
                }
                let now = Instant::now();
                match summary.status {
                    gateway::cell::DeviceStatus::Down => {
                        if self.down_since.insert(summary.id, now).is_none() {
                            self.downs += 1;
                        }
                    }
                    _ => {
                        if let Some(since) = self.down_since.remove(&summary.id) {
                            self.longest_down = self.longest_down.max(now - since);
                        }
                    }
                }
            }
            LiveMessage::Event(_) => {}
        }
    }

    /// Devices still down when the noise ends count until then.
    fn close_downs(&mut self, now: Instant) {
        for (_, since) in self.down_since.drain() {
            self.longest_down = self.longest_down.max(now - since);
        }
    }

    /// The points that kept one value in the calm phase, with that value.
    fn settle_truth(&mut self) {
        for (point, values) in &self.calm {
            let Some(first) = values.first() else {
                continue;
            };
            if values.iter().all(|v| v == first)
                && let Some(judged) = self.protocols.get(point)
            {
                self.truth.insert(
                    point.clone(),
                    Truth {
                        protocol: judged.protocol,
                        measurement: judged.measurement,
                        value: first.clone(),
                    },
                );
            }
        }
    }

    /// Judged points whose clean value at the end is not their calm truth.
    fn drifted(&self, cell: &Cell) -> Vec<PointId> {
        self.truth
            .iter()
            .filter(|(point, truth)| {
                let now = current(cell, point);
                let clean = self.clean.get(*point);
                now.as_ref().is_some_and(|v| *v != truth.value)
                    || clean.is_some_and(|values| values.iter().any(|v| *v != truth.value))
            })
            .map(|(point, _)| point.clone())
            .collect()
    }
}

/// A point's current good value.
fn current(cell: &Cell, point: &PointId) -> Option<Value> {
    let entry = cell.device_entry(point.device())?;
    let index = entry.point_index(point.name())?;
    let state = entry.read();
    let p = state.points.get(index)?;
    (p.quality == Some(Quality::Good))
        .then(|| p.value.clone())
        .flatten()
}
