//! Test rigs shared by the unit tests: JBC station models on an in-memory line, polled by
//! a real line task and recorded in a real (temporary) store.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use jbc::device::{Station, StationConfig};
use jbc::frame::Address;
use link::{Endpoint, Line};
use tokio::sync::watch;
use wire::Transmit;
use wire::device::{Device, SharedModel};

use crate::cell::Cell;
use crate::config::{CellConfig, DeviceConfig, LineConfig};
use crate::driver::DriverConfig;
use crate::metrics::Metrics;
use crate::point::DeviceId;
use crate::scheduler::Opener;
use crate::store::{Store, StoreOptions};

/// Stations sharing one line; each can be unplugged (it then hears nothing).
pub struct Bus {
    pub stations: Vec<(Arc<AtomicBool>, wire::device::ModelLine<Station>)>,
    /// Every byte sent on the line.
    pub heard: Arc<std::sync::Mutex<Vec<u8>>>,
    /// Set when this session of the line hangs (a serial server's session stuck): nothing
    /// on it is heard any more, though a new session works.
    pub hung: Arc<AtomicBool>,
}

impl Device for Bus {
    fn set_timing(&mut self, timing: wire::LineTiming) {
        for (_, station) in &mut self.stations {
            station.set_timing(timing);
        }
    }

    fn receive(&mut self, bytes: &[u8], now: std::time::Instant) -> Vec<Transmit> {
        self.heard.lock().unwrap().extend_from_slice(bytes);
        if self.hung.load(Ordering::SeqCst) {
            return Vec::new();
        }
        self.stations
            .iter_mut()
            .filter(|(plugged, _)| plugged.load(Ordering::SeqCst))
            .flat_map(|(_, station)| station.receive(bytes, now))
            .collect()
    }
}

pub struct Rig {
    pub cell: Arc<Cell>,
    pub models: Vec<SharedModel<Station>>,
    pub plugged: Vec<Arc<AtomicBool>>,
    pub line_available: Arc<AtomicBool>,
    /// When set, a line opens and its other end closes at once (a serial server that
    /// accepts the connection and drops it).
    pub line_drops: Arc<AtomicBool>,
    pub opens: Arc<AtomicUsize>,
    /// Answers the line still carries (its bus is behind [`testkit::Tricky::silent_after`];
    /// `usize::MAX` at first: no limit).
    pub replies_left: Arc<AtomicUsize>,
    /// Every byte the gateway sent on the line.
    pub heard: Arc<std::sync::Mutex<Vec<u8>>>,
    /// Per line session opened so far, its switch to make that session hang.
    pub sessions: Arc<std::sync::Mutex<Vec<Arc<AtomicBool>>>>,
    /// The serve loops of the lines opened so far (abort one to cut its line).
    pub servers: Arc<std::sync::Mutex<Vec<tokio::task::JoinHandle<std::io::Result<()>>>>>,
    pub shutdown: watch::Sender<bool>,
    pub task: tokio::task::JoinHandle<()>,
    _store: Store,
    pub dir: tempfile::TempDir,
}

pub fn device(id: &str, address: i64) -> DeviceConfig {
    let driver = DriverConfig {
        address: Some(address),
        ..DriverConfig::new(DeviceId::new(id).unwrap(), crate::driver::jbc::KIND)
    };
    DeviceConfig::new(driver, format!("Station {id}"))
}

/// `count` stations at addresses 1, 2, … on one line, polled by a running line task.
pub fn rig(count: u8) -> Rig {
    rig_with_alarms(count, Vec::new())
}

/// [`rig`] with limit alarms (`[[alarm]]`).
pub fn rig_with_alarms(count: u8, alarms: Vec<crate::alarm::config::AlarmConfig>) -> Rig {
    let dir = tempfile::tempdir().unwrap();
    let store = Store::open(dir.path(), StoreOptions::default()).unwrap();
    let models: Vec<_> = (1..=count)
        .map(|a| {
            SharedModel::new(Station::new(StationConfig {
                address: Some(Address::new(a).unwrap()),
                ..StationConfig::default()
            }))
        })
        .collect();
    let plugged: Vec<_> = models
        .iter()
        .map(|_| Arc::new(AtomicBool::new(true)))
        .collect();
    let line_available = Arc::new(AtomicBool::new(true));
    let line_drops = Arc::new(AtomicBool::new(false));
    let opens = Arc::new(AtomicUsize::new(0));
    let replies_left = Arc::new(AtomicUsize::new(usize::MAX));
    let servers = Arc::new(std::sync::Mutex::new(Vec::new()));
    let heard = Arc::new(std::sync::Mutex::new(Vec::new()));
    let sessions = Arc::new(std::sync::Mutex::new(Vec::new()));
    let opener: Opener = {
        let (models, plugged) = (models.clone(), plugged.clone());
        let heard = Arc::clone(&heard);
        let sessions = Arc::clone(&sessions);
        let (available, opens) = (Arc::clone(&line_available), Arc::clone(&opens));
        let drops = Arc::clone(&line_drops);
        let servers = Arc::clone(&servers);
        let replies_left = Arc::clone(&replies_left);
        Arc::new(move || {
            opens.fetch_add(1, Ordering::SeqCst);
            let result = if drops.load(Ordering::SeqCst) {
                let (a, b) = tokio::io::duplex(4096);
                drop(b);
                Ok(Line::from_stream(a, "memory", None))
            } else if available.load(Ordering::SeqCst) {
                let (a, b) = tokio::io::duplex(4096);
                let hung = Arc::new(AtomicBool::new(false));
                sessions.lock().unwrap().push(Arc::clone(&hung));
                let bus = Bus {
                    hung,
                    stations: plugged
                        .iter()
                        .cloned()
                        .zip(models.iter().map(SharedModel::line))
                        .collect(),
                    heard: Arc::clone(&heard),
                };
                let bus = testkit::Tricky::new(bus, []).silent_after(Arc::clone(&replies_left));
                let server = tokio::spawn(link::serve::serve_stream(b, bus, None));
                servers.lock().unwrap().push(server);
                Ok(Line::from_stream(a, "memory", None))
            } else {
                Err("no such serial port".to_owned())
            };
            Box::pin(async move { result })
        })
    };
    let config = CellConfig {
        lines: vec![LineConfig {
            reopen_after_timeouts: crate::config::DEFAULT_REOPEN_AFTER_TIMEOUTS,
            name: "bench".into(),
            endpoint: Endpoint::parse("tcp://127.0.0.1:9", crate::driver::jbc::DEFAULT_SERIAL)
                .unwrap(),
            devices: (1..=count)
                .map(|a| device(&format!("jbc{a}"), i64::from(a)))
                .collect(),
        }],
        alarms,
        ..CellConfig::default()
    };
    let metrics = Arc::new(Metrics::new());
    let (cell, mut tasks) =
        crate::scheduler::build_with_openers(&config, store.handle(), metrics, |_| {
            Arc::clone(&opener)
        })
        .unwrap();
    let (shutdown, stop) = watch::channel(false);
    // The alarms run as under `serve`: a device's own alarm is raised by the keeper.
    tokio::spawn(crate::alarm::keeper::run(Arc::clone(&cell), stop.clone()));
    let task = tokio::spawn(tasks.remove(0).run(stop));
    Rig {
        cell,
        models,
        plugged,
        line_available,
        line_drops,
        opens,
        replies_left,
        heard,
        sessions,
        servers,
        shutdown,
        task,
        _store: store,
        dir,
    }
}

/// jbc1's air temperature (°C, read at 1 s) with `value` and `quality`: a point view for
/// the northbound mappings' tests.
pub fn air_temperature_view(
    value: Option<crate::point::Value>,
    quality: Option<crate::point::Quality>,
) -> crate::cell::PointView {
    let device = DeviceId::new("jbc1").unwrap();
    crate::cell::PointView {
        id: crate::point::PointId::new(&device, "air_temperature").unwrap(),
        name: "Air temperature".into(),
        unit: Some("°C".into()),
        value,
        text: None,
        quality,
        t: Some(crate::time::Timestamp(1_000)),
        error: None,
        alarm: false,
        period_ms: 1000,
    }
}

/// The value (or the failure) a poll read for the point `name`; panics when the poll read
/// no such point.
pub fn reading(
    readings: &[crate::driver::Reading],
    name: &str,
) -> Result<crate::point::Value, crate::driver::DeviceError> {
    readings
        .iter()
        .find(|r| r.point.name() == name)
        .unwrap_or_else(|| panic!("no reading for {name}"))
        .value
        .clone()
}

/// A driver's write as the gateway makes it: the value checked against the point's spec
/// first ([`PointSpec::check_write`](crate::point::PointSpec::check_write)), then handed to
/// the driver. Drivers' tests write through it.
pub trait CheckThenWrite {
    /// Checks `value` against `point` and, if it passes, writes it.
    fn check_then_write<'a>(
        &'a mut self,
        point: &'a crate::point::PointSpec,
        value: &crate::point::Value,
    ) -> crate::driver::BoxFuture<'a, Result<(), crate::driver::WriteError>>;
}

impl<D: crate::driver::Driver + ?Sized> CheckThenWrite for D {
    fn check_then_write<'a>(
        &'a mut self,
        point: &'a crate::point::PointSpec,
        value: &crate::point::Value,
    ) -> crate::driver::BoxFuture<'a, Result<(), crate::driver::WriteError>> {
        let checked = point.check_write(value);
        Box::pin(async move {
            let checked = checked?;
            self.write(point, &checked).await
        })
    }
}

/// The point `id` (`device.point`); panics when it is not one.
pub fn point(id: &str) -> crate::point::PointId {
    crate::point::PointId::parse(id).unwrap()
}

/// The current value of the point `id` in `cell`; panics when the cell has no such point.
pub fn value(cell: &Cell, id: &str) -> Option<crate::point::Value> {
    let id = point(id);
    let device = cell.device_entry(id.device()).unwrap();
    let index = device.point_index(id.name()).unwrap();
    device.read().points[index].value.clone()
}

/// The cell of `config`, recording in `store`, its lines never opened: only what a test
/// applies to it reaches it.
pub fn unopened_cell(config: &CellConfig, store: &Store) -> Arc<Cell> {
    let metrics = Arc::new(Metrics::new());
    let (cell, _lines) = Cell::new(config, store.handle(), metrics).unwrap();
    cell
}

/// Config text for the tests of the config and of each kind's and interface's keys.
pub mod config {
    use std::path::Path;

    use crate::config::{CellConfig, ConfigError};
    use crate::plugins::parse_config;

    /// `text` as the file `cell.toml`, read with the built-in kinds and interfaces.
    pub fn parse(text: &str) -> Result<CellConfig, ConfigError> {
        parse_config(text, Path::new("cell.toml"))
    }

    /// Parses `text`, expecting an error at `line:column` whose message contains `words`.
    pub fn refused(text: &str, line: usize, column: usize, words: &str) {
        let err = parse(text).expect_err("the config must be refused");
        let shown = err.to_string();
        assert_eq!(err.position(), Some((line, column)), "{shown}");
        assert!(
            shown.starts_with(&format!("cell.toml:{line}:{column}: ")),
            "{shown}"
        );
        assert!(shown.contains(words), "{shown}");
    }

    /// A cell of one Panasonic placement machine.
    pub const PLACER: &str = r#"
[[line]]
name = "placement"
endpoint = "tcp://192.0.2.50:49152"

[[line.device]]
id = "placer1"
protocol = "panasonic"
"#;

    /// A cell of one JBC station on one serial line.
    pub const ONE: &str = r#"
[[line]]
name = "rework"
endpoint = "serial:///dev/ttyUSB0"

[[line.device]]
id = "jbc1"
protocol = "jbc"
"#;
}
