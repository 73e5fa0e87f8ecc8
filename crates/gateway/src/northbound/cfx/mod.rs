//! IPC-CFX (IPC-2591): the cell's placement machines as CFX endpoints on an AMQP 1.0
//! broker (or receiver). The messages' JSON and AMQP properties are the `cfx` crate's;
//! [`station`] turns what the change stream says of one machine into its messages, sans
//! IO; this module sends them (`fe2o3-amqp`), one AMQP message each with the SDK's
//! properties, to the `[cfx]` table's (or `--cfx`'s) address.
//!
//! Each connection starts with every endpoint's `EndpointConnected`; a clean stop ends with
//! `EndpointShuttingDown`. While the link is down, the messages wait in memory (at most
//! [`MAX_WAITING`], the oldest dropped and counted) and go out in order, each once, when it
//! is back; the link is opened again with a backoff of 1 s doubling to 30 s.
//!
//! Not built yet (issue #39): `amqps://`, the endpoint's request listener, the catch-up
//! from the history after a restart (the stations' ids are made for it: the same history
//! gives the same `UniqueID`s), and `cellbus cfx sub`.

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
use tokio::sync::{broadcast, watch};
use wire::backoff::Backoff;

use self::config::{CfxConfig, CfxTable};
use self::station::{Input, Station, StationConfig};
use super::{BoxStart, Northbound, Running, Start};
use crate::cell::{Cell, InterfaceStatus, LiveMessage};
use crate::config::TableReader;
use crate::options::OptionError;
use crate::time::Timestamp;

/// The interface's name in `/healthz` and logs.
pub const NAME: &str = "cfx";

/// How long opening the link, or the receiver's verdict on one message, may take.
const LINK_PATIENCE: Duration = Duration::from_secs(30);

/// Messages kept while the link is down, at most.
pub const MAX_WAITING: usize = 10_000;

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
            let mut stations = stations(start.cell, &config, &prefix)?;
            let (listener_url, listener) = match config.listen {
                Some(addr) => {
                    let socket = tokio::net::TcpListener::bind(addr).await.map_err(|e| {
                        OptionError(format!("IPC-CFX: cannot listen on {addr}: {e}"))
                    })?;
                    let local = socket.local_addr()?;
                    let url = format!("amqp://{local}");
                    for station in &mut stations {
                        station.listens_at(&format!("{url}/"));
                    }
                    (Some(url), Some(socket))
                }
                None => (None, None),
            };
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
            if let Some(socket) = listener {
                let endpoints = stations
                    .iter()
                    .map(|s| endpoint_of(start.cell, s))
                    .collect();
                tokio::spawn(listen::serve(
                    socket,
                    listen::Listener {
                        endpoints,
                        zone: start.cell.production().shifts.zone().clone(),
                    },
                    start.stopped.clone(),
                ));
            }
            let task = tokio::spawn(run(
                Arc::clone(start.cell),
                config,
                password,
                stations,
                status,
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

/// What a station's endpoint says of itself (`GetEndpointInformation`).
fn endpoint_of(cell: &Cell, station: &Station) -> cfx::endpoint::Endpoint {
    let device = cell.device_entry(station.device());
    cfx::endpoint::Endpoint {
        handle: station.handle().clone(),
        request_uri: station.request_uri().map(str::to_owned),
        request_address: station.request_uri().map(|_| station.handle().to_string()),
        friendly_name: device.as_ref().map(|d| d.name.clone()),
        vendor: None,
        model: device.as_ref().map(|d| d.protocol.name().to_owned()),
        serial: None,
        software: Some(format!("cellbus {}", env!("CARGO_PKG_VERSION"))),
    }
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
    let (host, port, address) =
        config::parse_url(&url).map_err(|m| OptionError(format!("--cfx: {m}")))?;
    let address = address.ok_or_else(|| {
        OptionError(format!(
            "--cfx {url}: no address; write amqp://HOST:PORT/ADDRESS (a queue, or //exchange/NAME)"
        ))
    })?;
    let base = table.cloned().unwrap_or(CfxConfig {
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
    Ok(Some(CfxConfig {
        host,
        port,
        address,
        listen,
        ..base
    }))
}

/// One station per device that counts production (and per device given a handle), in
/// the cell's time zone.
fn stations(cell: &Cell, config: &CfxConfig, prefix: &str) -> anyhow::Result<Vec<Station>> {
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
    let zone = cell.production().shifts.zone().clone();
    let mut out = Vec::new();
    for device in roster.devices() {
        let Some(points) = device.protocol.production() else {
            continue;
        };
        let handle = match config.handles.get(device.id.as_str()) {
            Some(handle) => handle.clone(),
            None => cfx::Handle::new(&format!("{prefix}.{}", device.id))
                .map_err(|e| OptionError(format!("device {}: {e}", device.id)))?,
        };
        out.push(Station::new(StationConfig {
            device: device.id.to_string(),
            handle,
            zone: zone.clone(),
            points: *points,
            heartbeat: config.heartbeat,
        }));
    }
    Ok(out)
}

/// Feeds the stations from the change stream and sends what they make, until `stop`.
async fn run(
    cell: Arc<Cell>,
    config: CfxConfig,
    password: Option<String>,
    stations: Vec<Station>,
    status: Arc<CfxStatus>,
    mut stop: watch::Receiver<bool>,
) {
    let mut feeder = Feeder {
        stations: stations
            .into_iter()
            .map(|s| (s.device().to_owned(), s))
            .collect(),
        waiting: VecDeque::new(),
        status: Arc::clone(&status),
    };
    let mut live = cell.subscribe();
    let mut tick = tokio::time::interval(Duration::from_secs(1));
    let mut backoff = Backoff::new(Duration::from_secs(1), Duration::from_secs(30)).timer();
    let mut first = true;
    loop {
        let opened = tokio::select! {
            () = stopped(&mut stop) => return,
            opened = tokio::time::timeout(LINK_PATIENCE, Link::open(&config, password.as_deref())) => {
                opened.unwrap_or_else(|_| Err(format!(
                    "{} did not open the link within {LINK_PATIENCE:?}", config.url()
                )))
            }
        };
        let mut link = match opened {
            Ok(link) => link,
            Err(why) => {
                status.set_link(Err(why));
                let wait = tokio::time::sleep(backoff.next_wait());
                tokio::pin!(wait);
                loop {
                    tokio::select! {
                        () = stopped(&mut stop) => return,
                        () = &mut wait => break,
                        message = live.recv() => feeder.live(message),
                        _ = tick.tick() => feeder.tick_offline(Timestamp::now()),
                    }
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
        let now = Timestamp::now();
        let connected: Vec<_> = feeder
            .stations
            .iter_mut()
            .map(|(_, s)| s.connected(now))
            .collect();
        let lost = 'connected: {
            for envelope in &connected {
                if let Err(why) = link.send(envelope).await {
                    break 'connected why;
                }
            }
            loop {
                while let Some(envelope) = feeder.waiting.front() {
                    if let Err(why) = link.send(envelope).await {
                        break 'connected why;
                    }
                    feeder.waiting.pop_front();
                    status.metrics.sent.inc();
                }
                tokio::select! {
                    () = stopped(&mut stop) => {
                        let now = Timestamp::now();
                        for (_, station) in &feeder.stations {
                            let _ = link.send(&station.shutting_down(now)).await;
                        }
                        link.close().await;
                        return;
                    }
                    message = live.recv() => feeder.live(message),
                    _ = tick.tick() => feeder.feed_all(Input::Tick(Timestamp::now())),
                }
            }
        };
        tracing::warn!("IPC-CFX: the link to {} was lost: {lost}", config.url());
        status.set_link(Err(lost));
    }
}

/// Resolves once `stop` turns true (or its sender is gone).
async fn stopped(stop: &mut watch::Receiver<bool>) {
    let _ = stop.wait_for(|s| *s).await;
}

/// The stations and the messages waiting to be sent.
struct Feeder {
    stations: Vec<(String, Station)>,
    waiting: VecDeque<cfx::Envelope>,
    status: Arc<CfxStatus>,
}

impl Feeder {
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
                if let Some(device) = event.device.as_ref().map(ToString::to_string) {
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

    fn feed(&mut self, device: &str, input: Input<'_>) {
        let made: Vec<_> = self
            .stations
            .iter_mut()
            .filter(|(d, _)| d == device)
            .flat_map(|(_, s)| s.feed(input))
            .collect();
        self.keep(made);
    }

    fn feed_all(&mut self, input: Input<'_>) {
        let made: Vec<_> = self
            .stations
            .iter_mut()
            .flat_map(|(_, s)| s.feed(input))
            .collect();
        self.keep(made);
    }

    /// Time passing while the link is down: placement windows close, but no heartbeat is
    /// kept to be sent late (the receiver learns of the outage by their absence, and the
    /// next connection's `EndpointConnected`).
    fn tick_offline(&mut self, now: Timestamp) {
        let made: Vec<_> = self
            .stations
            .iter_mut()
            .flat_map(|(_, s)| s.feed(Input::Tick(now)))
            .filter(|e| !matches!(e.message, cfx::Message::Heartbeat(_)))
            .collect();
        self.keep(made);
    }

    fn keep(&mut self, made: Vec<cfx::Envelope>) {
        for envelope in made {
            if self.waiting.len() >= MAX_WAITING {
                self.waiting.pop_front();
                self.status.metrics.dropped.inc();
            }
            self.waiting.push_back(envelope);
        }
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
        let mut connection = builder
            .open(url.as_str())
            .await
            .map_err(|e| format!("cannot connect to {url}: {e}"))?;
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

    /// Sends one envelope and waits for the receiver's verdict (at most
    /// [`LINK_PATIENCE`]: a receiver that takes no more is a lost link).
    async fn send(&mut self, envelope: &cfx::Envelope) -> Result<(), String> {
        let outcome = tokio::time::timeout(LINK_PATIENCE, self.sender.send(amqp_message(envelope)))
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
    let p = envelope.amqp();
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
        .data(Binary::from(envelope.to_bytes()))
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
    /// Messages dropped while the link was down past [`MAX_WAITING`].
    pub dropped: Counter,
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
            "IPC-CFX messages dropped, the oldest first, while more than 10,000 waited for the link",
            self.dropped.clone(),
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
        match self.link() {
            Ok(()) => serde_json::json!(format!("connected to {}", self.url)),
            Err(why) => serde_json::json!(format!("disconnected: {why}")),
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
