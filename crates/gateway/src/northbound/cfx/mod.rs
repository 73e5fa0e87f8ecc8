//! IPC-CFX (IPC-2591): the cell's placement machines as CFX endpoints on an AMQP 1.0
//! broker (or receiver). The messages' JSON and AMQP properties are the `cfx` crate's;
//! [`station`] turns what the change stream says of one machine into its messages, sans
//! IO; this module keeps them and sends them (`fe2o3-amqp`), one AMQP message each with
//! the SDK's properties, to the `[cfx]` table's (or `--cfx`'s) address; [`listen`]
//! answers the requests sent to the endpoints.
//!
//! Delivery: every message a station makes (heartbeats aside) is first committed to the
//! history database's outbox (`store::Outbox`), in one transaction with what the stations
//! must remember (their state and since when, their open faults, their placement window);
//! only then is it sent, oldest first, and it is removed when the receiver has accepted it.
//! So a broker outage, a lost link or a gateway restart (`kill -9` and power cuts included)
//! loses nothing: what was kept goes out when the link is back, in order, each with its
//! original `UniqueID` and `TimeStamp`, and a station after a restart goes on where it was
//! (an open fault still gets its `FaultCleared`). At most [`MAX_KEPT`] messages are kept,
//! the oldest dropped first and counted. A message whose acceptance was not heard before the
//! link broke is sent again with its id (at least once: a receiver drops an id it has).
//! Heartbeats are sent only while the link is up, never late: the receiver learns of the
//! outage by their absence and by the next connection's `EndpointConnected`.
//!
//! Each connection starts with every endpoint's `EndpointConnected`; a clean stop sends
//! what is kept (for at most [`FINISH_PATIENCE`]) and ends with `EndpointShuttingDown`. The
//! link is opened again with a backoff of 1 s doubling to 30 s.

pub mod config;
pub mod listen;
pub mod station;

use std::collections::{BTreeMap, VecDeque};
use std::sync::{Arc, PoisonError, RwLock};
use std::time::Duration;

use fe2o3_amqp::types::messaging::{ApplicationProperties, Header, Message, Properties};
use fe2o3_amqp::types::primitives::{Binary, SimpleValue, Timestamp as AmqpTime};
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::registry::Registry;
use tokio::sync::{Notify, broadcast, mpsc, watch};
use wire::backoff::Backoff;

use self::config::{CfxConfig, CfxTable};
use self::station::{Input, Memory, Station, StationConfig};
use super::{BoxStart, Northbound, Running, Start};
use crate::cell::{Cell, InterfaceStatus, LiveMessage};
use crate::config::TableReader;
use crate::event::EventKind;
use crate::options::OptionError;
use crate::store::Outbox;
use crate::time::Timestamp;

/// The interface's name in `/healthz` and logs.
pub const NAME: &str = "cfx";

/// How long opening the link, or the receiver's verdict on one message, may take.
const LINK_PATIENCE: Duration = Duration::from_secs(30);

/// Messages kept in the outbox, at most (about 60 MB of the history database).
pub const MAX_KEPT: u64 = 100_000;

/// Messages made that wait in memory while the outbox cannot take them, at most.
pub const MAX_WAITING: usize = 10_000;

/// Kept messages read from the outbox at a time.
const PAGE: usize = 200;

/// How often the stations' memory is kept when no message was made (a placement window's
/// counts move with every poll).
const MEMORY_EVERY: Duration = Duration::from_secs(10);

/// How long a clean stop goes on sending what is kept (the rest waits for the next start).
const FINISH_PATIENCE: Duration = Duration::from_secs(5);

/// The demo cell's handles: `cellbus.demo.<device>`.
pub const DEMO_PREFIX: &str = "cellbus.demo";

/// `--cfx amqp://HOST:PORT/ADDRESS`: publish the cell's placement machines as CFX
/// endpoints there (the demo's as `cellbus.demo.placer1`); with a config, it replaces the
/// `[cfx]` table's broker and address.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CfxFlags {
    /// The URL, with the address as its path.
    pub url: Option<String>,
    /// `--cfx-listen IP:PORT`: where the endpoints answer requests (port 0: a free one).
    pub listen: Option<std::net::SocketAddr>,
}

/// The IPC-CFX interface.
#[derive(Debug)]
pub struct Cfx;

impl Northbound for Cfx {
    fn name(&self) -> &'static str {
        NAME
    }

    fn table(&self) -> &'static dyn TableReader {
        &CfxTable
    }

    fn start<'a>(&'a self, start: Start<'a>) -> BoxStart<'a> {
        Box::pin(async move {
            let Some(config) = cfx_config(&start)? else {
                return Ok(None);
            };
            let prefix = if start.demo {
                DEMO_PREFIX.to_owned()
            } else {
                format!("cellbus.{}", super::default_edge_node_id())
            };
            let (listener_url, listener) = match config.listen {
                Some(addr) => {
                    let socket = tokio::net::TcpListener::bind(addr).await.map_err(|e| {
                        OptionError(format!("IPC-CFX: cannot listen on {addr}: {e}"))
                    })?;
                    let url = format!("amqp://{}", socket.local_addr()?);
                    (Some(url), Some(socket))
                }
                None => (None, None),
            };
            let maker = Maker {
                handles: config.handles.clone(),
                prefix,
                zone: start.cell.production().shifts.zone().clone(),
                heartbeat: config.heartbeat,
                request_uri: listener_url.as_ref().map(|url| format!("{url}/")),
            };
            let stations = stations(start.cell, &config, &maker)?;
            let password = match &config.password_env {
                Some(var) => Some(std::env::var(var).map_err(|_| {
                    OptionError(format!(
                        "[cfx] password_env names {var}, which is not set in the environment"
                    ))
                })?),
                None => None,
            };
            let status = Arc::new(CfxStatus::new(&config));
            start
                .cell
                .metrics()
                .register(|registry| status.metrics.register(registry));
            start
                .cell
                .set_interface(NAME, Arc::clone(&status) as Arc<dyn InterfaceStatus>, true);
            tracing::info!(
                "IPC-CFX: {} endpoint(s) ({}) to {} address {}",
                stations.len(),
                stations
                    .iter()
                    .map(|s| s.handle().to_string())
                    .collect::<Vec<_>>()
                    .join(", "),
                config.url(),
                config.address
            );
            let endpoints: Endpoints = Arc::new(RwLock::new(
                stations.iter().map(|s| Shown::of(start.cell, s)).collect(),
            ));
            if let Some(socket) = listener {
                tokio::spawn(listen::serve(
                    socket,
                    listen::Listener {
                        endpoints: Arc::clone(&endpoints),
                        zone: maker.zone.clone(),
                    },
                    start.stopped.clone(),
                ));
            }
            let task = tokio::spawn(run(
                Arc::clone(start.cell),
                Setup {
                    config,
                    password,
                    stations,
                    maker,
                    endpoints,
                    status,
                    data_dir: start.options.data_dir.clone(),
                },
                start.stopped,
            ));
            Ok(Some(Running {
                name: NAME,
                url: listener_url,
                task,
            }))
        })
    }
}

/// The endpoints now (a reload adds and removes them): whom the sender greets on each
/// connection and bids farewell at a stop, and whom the listener answers for.
pub type Endpoints = Arc<RwLock<Vec<Shown>>>;

/// One endpoint as the sender and the listener see it.
#[derive(Debug, Clone)]
pub struct Shown {
    /// Its station as it was made (its handle and request address).
    pub station: Station,
    /// What it says of itself (`GetEndpointInformation`).
    pub endpoint: cfx::endpoint::Endpoint,
}

impl Shown {
    fn of(cell: &Cell, station: &Station) -> Self {
        let device = cell.device_entry(station.device());
        Self {
            station: station.clone(),
            endpoint: cfx::endpoint::Endpoint {
                handle: station.handle().clone(),
                request_uri: station.request_uri().map(str::to_owned),
                request_address: station.request_uri().map(|_| station.handle().to_string()),
                friendly_name: device.as_ref().map(|d| d.name.clone()),
                vendor: None,
                model: device.as_ref().map(|d| d.protocol.name().to_owned()),
                serial: None,
                software: Some(format!("cellbus {}", env!("CARGO_PKG_VERSION"))),
            },
        }
    }
}

/// The endpoints' stations, as they are now.
fn shown_stations(endpoints: &Endpoints) -> Vec<Station> {
    endpoints
        .read()
        .unwrap_or_else(PoisonError::into_inner)
        .iter()
        .map(|s| s.station.clone())
        .collect()
}

/// The link to run, if any: `--cfx` (replacing the table's broker and address), else the
/// `[cfx]` table.
fn cfx_config(start: &Start<'_>) -> anyhow::Result<Option<CfxConfig>> {
    let table = start.config.interface::<CfxConfig>(NAME);
    let url = start
        .options
        .flags
        .get::<CfxFlags>()
        .and_then(|f| f.url.clone());
    let listen = start.options.flags.get::<CfxFlags>().and_then(|f| f.listen);
    let Some(url) = url else {
        if listen.is_some() && table.is_none() {
            return Err(OptionError(
                "--cfx-listen needs --cfx URL or a [cfx] table: the endpoints it answers for publish there"
                    .to_owned(),
            )
            .into());
        }
        return Ok(table.cloned().map(|t| CfxConfig {
            listen: listen.or(t.listen),
            ..t
        }));
    };
    let config::CfxUrl {
        tls,
        host,
        port,
        address,
    } = config::parse_url(&url).map_err(|m| OptionError(format!("--cfx: {m}")))?;
    let address = address.ok_or_else(|| {
        OptionError(format!(
            "--cfx {url}: no address; write amqp://HOST:PORT/ADDRESS (a queue, or //exchange/NAME)"
        ))
    })?;
    let base = table.cloned().unwrap_or(CfxConfig {
        tls: None,
        host: String::new(),
        port: 0,
        address: String::new(),
        username: None,
        password_env: None,
        heartbeat: config::DEFAULT_HEARTBEAT,
        handles: BTreeMap::new(),
        listen: None,
    });
    let listen = start
        .options
        .flags
        .get::<CfxFlags>()
        .and_then(|f| f.listen)
        .or(base.listen);
    // amqps:// with the table's TLS files, else the system's roots.
    let tls = tls.then(|| base.tls.clone().unwrap_or_default());
    Ok(Some(CfxConfig {
        tls,
        host,
        port,
        address,
        listen,
        ..base
    }))
}

/// How a device's station is made: at the start, and when a reload adds a device.
#[derive(Debug, Clone)]
struct Maker {
    /// `[cfx.handles]`.
    handles: BTreeMap<String, cfx::Handle>,
    /// The default handles' start: `cellbus.<host>` (`cellbus.demo` for the demo).
    prefix: String,
    /// The cell's time zone.
    zone: jiff::tz::TimeZone,
    heartbeat: Duration,
    /// `amqp://IP:PORT/`, when the gateway answers requests.
    request_uri: Option<String>,
}

impl Maker {
    /// The station of `device`, if it counts production (a placement machine).
    fn station(&self, device: &crate::cell::DeviceEntry) -> Result<Option<Station>, OptionError> {
        let Some(points) = device.protocol.production() else {
            return Ok(None);
        };
        let handle = match self.handles.get(device.id.as_str()) {
            Some(handle) => handle.clone(),
            None => cfx::Handle::new(&format!("{}.{}", self.prefix, device.id))
                .map_err(|e| OptionError(format!("device {}: {e}", device.id)))?,
        };
        let mut station = Station::new(StationConfig {
            device: device.id.to_string(),
            handle,
            zone: self.zone.clone(),
            points: *points,
            heartbeat: self.heartbeat,
        });
        if let Some(uri) = &self.request_uri {
            station.listens_at(uri);
        }
        Ok(Some(station))
    }
}

/// One station per device that counts production (and per device given a handle).
fn stations(cell: &Cell, config: &CfxConfig, maker: &Maker) -> anyhow::Result<Vec<Station>> {
    let roster = cell.roster();
    for device in config.handles.keys() {
        let Some(entry) = roster.device(device) else {
            return Err(OptionError(format!(
                "[cfx.handles] names device {device}, which the cell does not have"
            ))
            .into());
        };
        if entry.protocol.production().is_none() {
            return Err(OptionError(format!(
                "[cfx.handles] names device {device}, a {} that counts no production: CFX endpoints are placement machines",
                entry.protocol.name()
            ))
            .into());
        }
    }
    let mut out = Vec::new();
    for device in roster.devices() {
        out.extend(maker.station(device)?);
    }
    Ok(out)
}

/// What the interface's task starts from.
struct Setup {
    config: CfxConfig,
    password: Option<String>,
    stations: Vec<Station>,
    maker: Maker,
    endpoints: Endpoints,
    status: Arc<CfxStatus>,
    data_dir: std::path::PathBuf,
}

/// Feeds the stations from the change stream and keeps what they make (a task), sends
/// what is kept (another), until `stop`.
async fn run(cell: Arc<Cell>, setup: Setup, stop: watch::Receiver<bool>) {
    let Setup {
        config,
        password,
        mut stations,
        maker,
        endpoints,
        status,
        data_dir,
    } = setup;
    let kept = Kept::open(&cell, &data_dir).await;
    kept.recall(&mut stations).await;
    status.metrics.waiting.set(kept.len().await);
    let wake = Arc::new(Notify::new());
    // Sent at once while the link is up, never kept: heartbeats, and the greetings and
    // farewells of endpoints a reload adds and removes.
    let (now, now_rx) = mpsc::channel(64);
    let (finish, finished) = watch::channel(false);
    let sender = tokio::spawn(send(
        Sender {
            config,
            password,
            endpoints: Arc::clone(&endpoints),
            kept: kept.clone(),
            status: Arc::clone(&status),
        },
        Arc::clone(&wake),
        now_rx,
        finished,
    ));
    let feeder = Feeder {
        stations: stations
            .into_iter()
            .map(|s| (s.device().to_owned(), s))
            .collect(),
        made: VecDeque::new(),
        remember: false,
        status: &status,
        cell: &cell,
        maker,
        endpoints,
        now,
    };
    feed(feeder, &kept, &wake, stop).await;
    let _ = finish.send(true);
    let _ = sender.await;
}

/// Feeds the stations from the change stream until `stop`, and keeps what they make.
async fn feed(mut feeder: Feeder<'_>, kept: &Kept, wake: &Notify, mut stop: watch::Receiver<bool>) {
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

/// Resolves once `stop` turns true (or its sender is gone).
async fn stopped(stop: &mut watch::Receiver<bool>) {
    let _ = stop.wait_for(|s| *s).await;
}

/// The stations, and what they made that is not kept yet.
struct Feeder<'a> {
    stations: Vec<(String, Station)>,
    /// Made, waiting for the outbox (only while it fails: at most [`MAX_WAITING`]).
    made: VecDeque<cfx::Envelope>,
    /// A station's memory changed since it was last kept.
    remember: bool,
    status: &'a CfxStatus,
    cell: &'a Cell,
    /// Makes the station of a device a reload adds.
    maker: Maker,
    endpoints: Endpoints,
    /// To the sender, sent at once if the link is up (see [`run`]).
    now: mpsc::Sender<cfx::Envelope>,
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

    fn feed(&mut self, device: &str, input: Input<'_>) {
        for (_, station) in self.stations.iter_mut().filter(|(d, _)| d == device) {
            let before = station.memory();
            let made = station.feed(input);
            self.remember |= station.memory() != before;
            self.made.extend(made);
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
                self.made.clear();
                self.remember = false;
                self.status.metrics.dropped.inc_by(dropped);
                self.status.metrics.waiting.set(kept.len().await);
                true
            }
            Err(why) => {
                tracing::warn!("IPC-CFX: cannot keep its messages: {why}; they wait in memory");
                false
            }
        }
    }
}

/// The outbox of the history database (or, when the data directory cannot be used, one in
/// memory), shared by the feeder and the sender; its calls run off the async threads.
#[derive(Clone)]
struct Kept(Arc<std::sync::Mutex<Outbox>>);

impl Kept {
    async fn open(cell: &Cell, dir: &std::path::Path) -> Kept {
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

    async fn call<R: Send + 'static>(
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
    async fn recall(&self, stations: &mut [Station]) {
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

    async fn keep(&self, bodies: Vec<Vec<u8>>, memory: Option<String>) -> Result<u64, String> {
        self.call(move |o| o.keep(&bodies, memory.as_deref(), MAX_KEPT))
            .await
            .map_err(|e| e.to_string())
    }

    async fn len(&self) -> i64 {
        self.call(|o| i64::try_from(o.len()).unwrap_or(i64::MAX))
            .await
    }
}

/// What the sender needs.
struct Sender {
    config: CfxConfig,
    password: Option<String>,
    /// The endpoints now.
    endpoints: Endpoints,
    kept: Kept,
    status: Arc<CfxStatus>,
}

/// Sends what is kept, oldest first, each removed when the receiver accepted it, and the
/// heartbeats while the link is up; opens the link again with a backoff. Once `finish`
/// turns true (the feeder has kept its last messages), sends what is kept for at most
/// [`FINISH_PATIENCE`], the endpoints' `EndpointShuttingDown`, and closes the link.
async fn send(
    sender: Sender,
    wake: Arc<Notify>,
    mut beats: mpsc::Receiver<cfx::Envelope>,
    mut finish: watch::Receiver<bool>,
) {
    let Sender {
        config,
        password,
        endpoints,
        kept,
        status,
    } = sender;
    let mut backoff = Backoff::new(Duration::from_secs(1), Duration::from_secs(30)).timer();
    let mut sent: i64 = 0;
    let mut first = true;
    loop {
        let opened = tokio::select! {
            () = stopped(&mut finish) => return,
            opened = tokio::time::timeout(LINK_PATIENCE, Link::open(&config, password.as_deref())) => {
                opened.unwrap_or_else(|_| Err(format!(
                    "{} did not open the link within {LINK_PATIENCE:?}", config.url()
                )))
            }
        };
        let mut link = match opened {
            Ok(link) => link,
            Err(why) => {
                // Said once, not at every try.
                if status.link().err().as_deref() != Some(why.as_str()) {
                    tracing::warn!("IPC-CFX: no link: {why}; trying again");
                }
                status.set_link(Err(why));
                tokio::select! {
                    () = stopped(&mut finish) => return,
                    () = tokio::time::sleep(backoff.next_wait()) => {}
                }
                continue;
            }
        };
        if !first {
            status.metrics.reconnects.inc();
        }
        first = false;
        status.set_link(Ok(()));
        backoff.reset();
        // Heartbeats made while the link was down are not sent late.
        while beats.try_recv().is_ok() {}
        let now = Timestamp::now();
        let lost = 'connected: {
            for station in shown_stations(&endpoints) {
                if let Err(why) = link.send(amqp_message(&station.connected(now))).await {
                    break 'connected why;
                }
            }
            loop {
                if let Err(why) = link.send_kept(&kept, &mut sent, &status).await {
                    break 'connected why;
                }
                tokio::select! {
                    () = stopped(&mut finish) => {
                        let _ = tokio::time::timeout(
                            FINISH_PATIENCE,
                            link.send_kept(&kept, &mut sent, &status),
                        ).await;
                        let now = Timestamp::now();
                        for station in shown_stations(&endpoints) {
                            let _ = link.send(amqp_message(&station.shutting_down(now))).await;
                        }
                        link.close().await;
                        return;
                    }
                    () = wake.notified() => {}
                    Some(beat) = beats.recv() => {
                        if let Err(why) = link.send(amqp_message(&beat)).await {
                            break 'connected why;
                        }
                    }
                }
            }
        };
        tracing::warn!("IPC-CFX: the link to {} was lost: {lost}", config.url());
        status.set_link(Err(lost));
    }
}

/// An open AMQP link: connection, session, sender.
struct Link {
    connection: fe2o3_amqp::connection::ConnectionHandle<()>,
    session: fe2o3_amqp::session::SessionHandle<()>,
    sender: fe2o3_amqp::Sender,
}

impl Link {
    async fn open(config: &CfxConfig, password: Option<&str>) -> Result<Link, String> {
        let url = config.url();
        let builder = fe2o3_amqp::Connection::builder()
            .container_id(format!("cellbus-{}", super::default_edge_node_id()))
            .hostname(config.host.as_str());
        // SASL always (a broker such as RabbitMQ wants it; ANONYMOUS without a user).
        let builder = match (&config.username, password) {
            (Some(username), password) => {
                builder.sasl_profile(fe2o3_amqp::sasl_profile::SaslProfile::Plain {
                    username: username.clone(),
                    password: password.unwrap_or_default().to_owned(),
                })
            }
            _ => builder.sasl_profile(fe2o3_amqp::sasl_profile::SaslProfile::Anonymous),
        };
        let opened = match &config.tls {
            None => builder.open(url.as_str()).await,
            // amqps://: TLS on our own stream (fe2o3-amqp's TLS features bring aws-lc;
            // this is the rustls with ring the MQTT link uses), then AMQP inside it.
            Some(files) => {
                let tls = kit::mqtt::tls::client_config(files).map_err(|e| e.to_string())?;
                let name =
                    rustls::pki_types::ServerName::try_from(config.host.clone()).map_err(|e| {
                        format!(
                            "{url}: {} is not a host name TLS can check: {e}",
                            config.host
                        )
                    })?;
                let tcp = tokio::net::TcpStream::connect((config.host.as_str(), config.port))
                    .await
                    .map_err(|e| format!("cannot connect to {url}: {e}"))?;
                let stream = tokio_rustls::TlsConnector::from(tls)
                    .connect(name, tcp)
                    .await
                    .map_err(|e| format!("TLS with {url} failed: {e}"))?;
                builder.open_with_stream(stream).await
            }
        };
        let mut connection = opened.map_err(|e| match e {
            fe2o3_amqp::connection::OpenError::SaslError { code, .. } => {
                let who = match (&config.username, &config.password_env) {
                    (Some(user), Some(var)) => {
                        format!("the user {user} with the password in {var}")
                    }
                    (Some(user), None) => format!("the user {user} without a password"),
                    _ => "an anonymous login".to_owned(),
                };
                format!("cannot connect to {url}: the broker refused {who} (SASL {code:?})")
            }
            e => format!("cannot connect to {url}: {e}"),
        })?;
        let mut session = fe2o3_amqp::Session::begin(&mut connection)
            .await
            .map_err(|e| format!("{url}: no session: {e}"))?;
        let sender =
            fe2o3_amqp::Sender::attach(&mut session, "cellbus-cfx", config.address.as_str())
                .await
                .map_err(|e| format!("{url}: address {} refused: {e}", config.address))?;
        Ok(Link {
            connection,
            session,
            sender,
        })
    }

    /// Sends what is kept after number `sent`, oldest first, moving `sent` on as the
    /// receiver accepts each and removing them from the outbox page by page.
    async fn send_kept(
        &mut self,
        kept: &Kept,
        sent: &mut i64,
        status: &CfxStatus,
    ) -> Result<(), String> {
        loop {
            let after = *sent;
            let page = kept
                .call(move |o| o.waiting(after, PAGE))
                .await
                .map_err(|e| format!("cannot read the kept messages: {e}"))?;
            let Some(&(last, _)) = page.last() else {
                return Ok(());
            };
            let mut result = Ok(());
            for (seq, body) in page {
                match kept_message(&body) {
                    Ok(message) => {
                        if let Err(why) = self.send(message).await {
                            result = Err(why);
                            break;
                        }
                        status.metrics.sent.inc();
                    }
                    Err(why) => {
                        tracing::warn!("IPC-CFX: a kept message is dropped: {why}");
                        status.metrics.dropped.inc();
                    }
                }
                *sent = seq;
            }
            let through = *sent;
            if let Err(e) = kept.call(move |o| o.taken(through)).await {
                tracing::warn!("IPC-CFX: cannot remove the messages sent from the outbox: {e}");
            }
            status.metrics.waiting.set(kept.len().await);
            result?;
            if *sent < last {
                return Ok(());
            }
        }
    }

    /// Sends one message and waits for the receiver's verdict (at most
    /// [`LINK_PATIENCE`]: a receiver that takes no more is a lost link).
    async fn send(
        &mut self,
        message: Message<fe2o3_amqp::types::messaging::Data>,
    ) -> Result<(), String> {
        let outcome = tokio::time::timeout(LINK_PATIENCE, self.sender.send(message))
            .await
            .map_err(|_| format!("no verdict on a message within {LINK_PATIENCE:?}"))?
            .map_err(|e| e.to_string())?;
        outcome
            .accepted_or_else(|state| format!("the receiver did not accept it: {state:?}"))
            .map(drop)
    }

    async fn close(self) {
        let Link {
            mut connection,
            mut session,
            sender,
        } = self;
        let _ = sender.close().await;
        let _ = session.end().await;
        let _ = connection.close().await;
    }
}

/// The AMQP message of `envelope`: one Data section of its JSON, the SDK's properties.
pub fn amqp_message(envelope: &cfx::Envelope) -> Message<fe2o3_amqp::types::messaging::Data> {
    message_of(envelope.amqp(), envelope.to_bytes())
}

/// The AMQP message of an envelope kept as its JSON.
fn kept_message(body: &[u8]) -> Result<Message<fe2o3_amqp::types::messaging::Data>, String> {
    let envelopes = cfx::Received::decode(body).map_err(|e| e.to_string())?;
    let [envelope] = envelopes.as_slice() else {
        return Err(format!("{} envelopes in one kept message", envelopes.len()));
    };
    let properties = envelope.amqp().map_err(|e| e.to_string())?;
    Ok(message_of(properties, body.to_vec()))
}

/// One Data section of `body`, with `p`.
fn message_of(
    p: cfx::envelope::AmqpProperties,
    body: Vec<u8>,
) -> Message<fe2o3_amqp::types::messaging::Data> {
    let mut properties = Properties::builder()
        .message_id(p.message_id)
        .subject(p.subject)
        .reply_to(p.reply_to)
        .content_type(p.content_type)
        .creation_time(AmqpTime::from_milliseconds(p.creation_time_ms));
    if let Some(to) = p.to {
        properties = properties.to(to);
    }
    if let Some(correlation) = p.correlation_id {
        properties = properties.correlation_id(correlation);
    }
    let mut application = ApplicationProperties::builder();
    for (key, value) in p.application {
        application = application.insert(key, value.map_or(SimpleValue::Null, SimpleValue::String));
    }
    Message::builder()
        .header(Header {
            durable: true,
            ..Header::default()
        })
        .properties(properties.build())
        .application_properties(application.build())
        .data(Binary::from(body))
        .build()
}

/// What the interface shows of itself: its link under `cfx` in `/healthz`, its metrics.
#[derive(Debug)]
pub struct CfxStatus {
    url: String,
    link: RwLock<Result<(), String>>,
    /// Its counters.
    pub metrics: CfxMetrics,
}

/// The interface's metrics (`cellbus_cfx_*`).
#[derive(Debug, Default)]
pub struct CfxMetrics {
    /// 1 while connected.
    pub connected: Gauge,
    /// Messages accepted by the receiver.
    pub sent: Counter,
    /// Messages dropped: the oldest past [`MAX_KEPT`] (or [`MAX_WAITING`] while the outbox
    /// failed), or a kept one that could not be read.
    pub dropped: Counter,
    /// Messages kept, waiting to be sent.
    pub waiting: Gauge,
    /// Connections made after the first.
    pub reconnects: Counter,
}

impl CfxMetrics {
    fn register(&self, registry: &mut Registry) {
        registry.register(
            "cfx_connected",
            "1 while the IPC-CFX AMQP link is up",
            self.connected.clone(),
        );
        registry.register(
            "cfx_sent",
            "IPC-CFX messages the receiver accepted (EndpointConnected and shutdowns aside)",
            self.sent.clone(),
        );
        registry.register(
            "cfx_dropped",
            "IPC-CFX messages dropped, the oldest first, past the 100,000 the outbox keeps",
            self.dropped.clone(),
        );
        registry.register(
            "cfx_waiting",
            "IPC-CFX messages kept in the outbox, waiting for the link",
            self.waiting.clone(),
        );
        registry.register(
            "cfx_reconnects",
            "IPC-CFX AMQP connections made after the first",
            self.reconnects.clone(),
        );
    }
}

impl CfxStatus {
    fn new(config: &CfxConfig) -> Self {
        Self {
            url: format!(
                "{}/{}",
                config.url(),
                config.address.trim_start_matches('/')
            ),
            link: RwLock::new(Err("connecting".to_owned())),
            metrics: CfxMetrics::default(),
        }
    }

    fn set_link(&self, link: Result<(), String>) {
        self.metrics.connected.set(i64::from(link.is_ok()));
        *self.link.write().unwrap_or_else(PoisonError::into_inner) = link;
    }

    fn link(&self) -> Result<(), String> {
        self.link
            .read()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }
}

impl InterfaceStatus for CfxStatus {
    fn health(&self) -> serde_json::Value {
        let waiting = match self.metrics.waiting.get() {
            0 => String::new(),
            1 => "; 1 message waits".to_owned(),
            n => format!("; {n} messages wait"),
        };
        match self.link() {
            Ok(()) => serde_json::json!(format!("connected to {}{waiting}", self.url)),
            Err(why) => serde_json::json!(format!("disconnected: {why}{waiting}")),
        }
    }

    fn problem(&self) -> Option<String> {
        self.link()
            .err()
            .map(|why| format!("IPC-CFX not connected to {}: {why}", self.url))
    }

    fn into_any(self: Arc<Self>) -> Arc<dyn std::any::Any + Send + Sync> {
        self
    }
}
