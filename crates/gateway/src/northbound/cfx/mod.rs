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
mod feed;
mod kept;
pub mod listen;
mod send;
pub mod station;

pub use send::amqp_message;

use std::collections::{BTreeMap, VecDeque};
use std::sync::{Arc, PoisonError, RwLock};
use std::time::Duration;

use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::registry::Registry;
use tokio::sync::{Notify, mpsc, watch};

use self::config::{CfxConfig, CfxTable};
use self::feed::{Feeder, feed};
use self::kept::Kept;
use self::send::{Sender, send};
use self::station::{Station, StationConfig};
use super::{BoxStart, Northbound, Running, Start};
use crate::cell::{Cell, InterfaceStatus};
use crate::config::TableReader;
use crate::options::OptionError;

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
        failing: false,
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

/// Resolves once `stop` turns true (or its sender is gone).
async fn stopped(stop: &mut watch::Receiver<bool>) {
    let _ = stop.wait_for(|s| *s).await;
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
