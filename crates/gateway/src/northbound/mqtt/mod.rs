//! The cell on an MQTT broker, as a Sparkplug B edge node ([`sparkplug`](self::sparkplug))
//! or as plain JSON ([`json`]); rumqttc carries it.
//!
//! One task per gateway. The connection plumbing here is shared by both modes; per
//! connection it:
//!
//! 1. asks the mode for the connection's Will (Sparkplug first stores the next `bdSeq` in
//!    the history database, so a restart never reuses one);
//! 2. builds fresh `MqttOptions` with that Will (rumqttc fixes the Will at connect and
//!    would reconnect with a stale one, so the task makes a new client for every
//!    connection instead of letting rumqttc reconnect);
//! 3. lets the mode serve the connection: on ConnAck it subscribes (rumqttc does not
//!    re-subscribe), publishes its births or retained state, the stored changes since the
//!    forwarded mark ([`forward`]), then the change stream;
//! 4. on a lost connection waits (0.5 s doubling to 30 s) and starts again at 1.
//!
//! A graceful stop publishes the Will itself before disconnecting.

pub mod config;
pub mod forward;
pub mod json;
pub mod mapping;
pub mod primary;
pub mod sparkplug;
pub mod status;
pub mod tls;

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use rumqttc::{
    AsyncClient, Event as MqttEvent, EventLoop, LastWill, MqttOptions, Outgoing as Sent, Packet,
    QoS, Transport,
};
use tokio::sync::{broadcast, mpsc, watch};
use tokio::task::JoinHandle;

use self::config::{MqttConfig, MqttMode};
use self::forward::{Delivery, FORWARDED_KEY};
use super::{BoxStart, Northbound, Running, Start};
use crate::cell::{Cell, LiveMessage};
use crate::config::{CellConfig, TableReader};
use crate::event::{Event, EventKind};
use crate::options::{OptionError, ServeOptions};
use crate::time::Timestamp;
pub use status::{MqttLink, MqttMetrics, MqttStatus, link};

/// First wait after a lost or refused connection; it doubles up to [`RETRY_CAP`].
pub const RETRY_FIRST: Duration = Duration::from_millis(500);
/// Longest wait between connection attempts.
pub const RETRY_CAP: Duration = Duration::from_secs(30);
/// A connection that lasted this long resets the wait to [`RETRY_FIRST`]; a shorter one
/// doubles it like a failed attempt. A broker that ends every session at once (another
/// client with the same client id takes it over) would otherwise be reconnected to, and
/// sent births and stored history, twice a second.
pub const STABLE_SESSION: Duration = Duration::from_secs(30);

/// Requests queued for the MQTT client.
const QUEUE: usize = 1024;
/// Largest MQTT packet sent: large cells make large births.
const MAX_PACKET: usize = 4 << 20;
pub use kit::mqtt::MAX_INCOMING;
/// How long a graceful stop waits for the last messages and DISCONNECT to leave.
const STOP_GRACE: Duration = Duration::from_secs(3);

/// Starts publishing `cell` to the broker in `config` until `stop` turns true; `data_dir`
/// holds the database that keeps `bdSeq` and the forwarded mark. `allow_writes` is the
/// gateway's `--allow-writes`: with the config's `commands = true`, DCMD writes are
/// carried out. Fails at once only for what no retry can fix (an id Sparkplug refuses, a
/// password variable that is not set, TLS files that do not make a TLS setup).
pub fn start(
    cell: Arc<Cell>,
    config: MqttConfig,
    data_dir: PathBuf,
    allow_writes: bool,
    stop: watch::Receiver<bool>,
) -> anyhow::Result<JoinHandle<()>> {
    let password = match &config.password_env {
        Some(var) => Some(std::env::var(var).with_context(|| {
            format!("the MQTT password's environment variable {var} is not set")
        })?),
        None => None,
    };
    let transport = match &config.tls {
        Some(files) => tls::transport(&tls::client_config(files).context("MQTT TLS")?),
        None => Transport::Tcp,
    };
    let status = status::status(&cell);
    status.set_link(MqttLink::Disconnected("not connected yet".to_owned()));
    let mode = config.mode;
    let link = Link {
        cell,
        status,
        config,
        password,
        data_dir,
        transport,
    };
    Ok(match mode {
        MqttMode::Sparkplug => {
            let node = sparkplug::Node::new(&link, allow_writes)?;
            tokio::spawn(link.run(node, stop))
        }
        MqttMode::Json => {
            let publisher = json::Publisher::new(&link);
            tokio::spawn(link.run(publisher, stop))
        }
    })
}

/// What the gateway needs to connect, shared by the modes.
pub struct Link {
    cell: Arc<Cell>,
    /// The link's state and the metrics, as `/healthz` and `/metrics` show them.
    status: Arc<MqttStatus>,
    config: MqttConfig,
    password: Option<String>,
    data_dir: PathBuf,
    /// TCP, or TLS for `mqtts://`.
    transport: Transport,
}

/// A message to publish, with the latest read time among the changes it holds.
#[derive(Debug, Clone)]
pub struct Outgoing {
    /// Where.
    pub topic: String,
    /// What.
    pub payload: Vec<u8>,
    /// With which QoS.
    pub qos: QoS,
    /// Whether the broker keeps it for later subscribers.
    pub retain: bool,
    /// The latest read time of the changes in it, if it holds any.
    pub latest: Option<Timestamp>,
}

/// Why a connection ended.
#[derive(Debug)]
pub enum End {
    /// Lost or refused; try again after a wait.
    Lost(String),
    /// Ended on purpose (a primary host went offline): publish `goodbye` (else the Will),
    /// disconnect, and connect again at once.
    Again {
        /// Why, in words.
        why: String,
        /// What to publish in place of the Will before disconnecting.
        goodbye: Option<Outgoing>,
    },
    /// The gateway stops.
    Stop,
}

/// What a connection brought.
#[derive(Debug)]
pub enum Step {
    /// The broker accepted the connection (ConnAck).
    Connected,
    /// A message on a subscribed topic.
    Message {
        /// Its topic.
        topic: String,
        /// Its payload.
        payload: Vec<u8>,
        /// Whether the broker delivered it as a retained message (published before this
        /// session's subscription).
        retain: bool,
    },
    /// From the change stream.
    Live(Result<LiveMessage, broadcast::error::RecvError>),
    /// The mode's timer.
    Tick,
    /// The time the mode asked for with [`Connection::wake_at`] has come.
    Wake,
}

/// One way of publishing the cell (Sparkplug B or JSON); the connection loop is shared.
pub trait Mode {
    /// Prepares the next connection and gives its Will (also published before a
    /// graceful disconnect).
    fn prepare(&mut self, link: &Link) -> impl Future<Output = Outgoing> + Send;
    /// Serves one connection until it ends.
    fn serve(
        &mut self,
        conn: &mut Connection<'_>,
        live: &mut broadcast::Receiver<LiveMessage>,
    ) -> impl Future<Output = End> + Send;
    /// The connection is gone.
    fn lost(&mut self);
    /// How often [`Step::Tick`] comes.
    fn tick(&self) -> Duration;
}

impl Link {
    /// The cell.
    pub fn cell(&self) -> &Arc<Cell> {
        &self.cell
    }

    /// The `[mqtt]` table.
    pub fn config(&self) -> &MqttConfig {
        &self.config
    }

    async fn run<M: Mode + Send>(self, mut mode: M, mut stop: watch::Receiver<bool>) {
        let mut delivery = Delivery::new(self.read_forwarded().await);
        let mut live = self.cell.subscribe();
        let mut retry = RETRY_FIRST;
        let mut connections = 0_u64;
        let mut was_connected = true; // so that the first failure is reported
        loop {
            if *stop.borrow() {
                return;
            }
            let will = mode.prepare(&self).await;
            let (client, eventloop) = AsyncClient::new(self.options(&will), QUEUE);
            let (events_tx, events) = mpsc::unbounded_channel();
            let pump = tokio::spawn(pump(eventloop, events_tx));
            let mut tick = tokio::time::interval(mode.tick());
            tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
            let mut conn = Connection {
                link: &self,
                client,
                events,
                delivery: &mut delivery,
                stop: &mut stop,
                tick,
                wake: None,
                connected: false,
                connections: &mut connections,
            };
            let started = tokio::time::Instant::now();
            let end = mode.serve(&mut conn, &mut live).await;
            let connected = conn.connected;
            let lasted = started.elapsed();
            retry = first_wait(retry, connected, lasted);
            match end {
                End::Stop => {
                    if connected {
                        conn.close(&will).await;
                    }
                    pump.abort();
                    mode.lost();
                    self.went_down(connected, "the gateway stopped".to_owned());
                    return;
                }
                End::Again { why, goodbye } => {
                    if connected {
                        conn.close(goodbye.as_ref().unwrap_or(&will)).await;
                    }
                    pump.abort();
                    delivery.lost();
                    mode.lost();
                    self.went_down(connected, why);
                    retry = RETRY_FIRST;
                    was_connected = true;
                }
                End::Lost(why) => {
                    pump.abort();
                    delivery.lost();
                    mode.lost();
                    let why = if connected && lasted < STABLE_SESSION {
                        format!(
                            "{why} (the session lasted {:.1} s; if that repeats, another \
                             client may be using the client id {:?}; next attempt in {:.1} s)",
                            lasted.as_secs_f64(),
                            self.config.client_id,
                            retry.as_secs_f64()
                        )
                    } else {
                        why
                    };
                    if connected || was_connected {
                        // The interface_down event is the log line (it names the broker).
                        self.went_down(connected, why.clone());
                    }
                    self.status.set_link(MqttLink::Disconnected(why));
                    was_connected = connected;
                }
            }
            tokio::select! {
                () = tokio::time::sleep(retry) => {}
                _ = stop.changed() => {}
            }
            retry = (retry * 2).min(RETRY_CAP);
        }
    }

    fn went_down(&self, connected: bool, why: String) {
        self.status.metrics.connected.set(0);
        self.status.set_link(MqttLink::Disconnected(why.clone()));
        let what = if connected {
            "MQTT connection ended"
        } else {
            "cannot connect to the MQTT broker"
        };
        self.cell.emit(link_event(
            EventKind::InterfaceDown,
            format!(
                "{what} ({}:{}): {why}; retrying",
                self.config.host, self.config.port
            ),
        ));
    }

    fn options(&self, will: &Outgoing) -> MqttOptions {
        let c = &self.config;
        let mut options = MqttOptions::new(&c.client_id, &c.host, c.port);
        options
            .set_keep_alive(c.keep_alive)
            .set_clean_session(true)
            .set_max_packet_size(MAX_INCOMING, MAX_PACKET)
            .set_transport(self.transport.clone())
            .set_last_will(LastWill::new(
                will.topic.clone(),
                will.payload.clone(),
                will.qos,
                will.retain,
            ));
        if let Some(user) = &c.username {
            options.set_credentials(user, self.password.clone().unwrap_or_default());
        }
        options
    }

    /// Reads a stored integer setting (waiting for the history's open, which moves a
    /// damaged file aside, first).
    pub async fn read_setting(&self, key: &'static str) -> anyhow::Result<Option<i64>> {
        let dir = self.data_dir.clone();
        let store = self.cell.store().clone();
        Ok(tokio::task::spawn_blocking(move || {
            let _ = store.wait_open();
            crate::store::read_setting(&dir, key)
        })
        .await??)
    }

    /// Stores an integer setting, committed when this returns.
    pub async fn write_setting(&self, key: &'static str, value: i64) -> anyhow::Result<()> {
        let dir = self.data_dir.clone();
        tokio::task::spawn_blocking(move || crate::store::write_setting(&dir, key, value))
            .await??;
        Ok(())
    }

    /// The forwarded mark: stored, or now (stored at once) on the first start with MQTT.
    async fn read_forwarded(&self) -> Timestamp {
        match self.read_setting(FORWARDED_KEY).await {
            Ok(Some(t)) => Timestamp(t),
            Ok(None) => {
                let now = Timestamp::now();
                self.store_forwarded(now).await;
                now
            }
            Err(e) => {
                tracing::warn!(
                    "cannot read the MQTT forwarded mark ({e}); changes stored before now \
                     will not be sent"
                );
                Timestamp::now()
            }
        }
    }

    async fn store_forwarded(&self, t: Timestamp) {
        if let Err(e) = self.write_setting(FORWARDED_KEY, t.0).await {
            tracing::warn!("cannot store the MQTT forwarded mark ({e}); a restart may resend");
        }
    }
}

/// One MQTT connection, as the modes see it.
pub struct Connection<'a> {
    link: &'a Link,
    client: AsyncClient,
    events: mpsc::UnboundedReceiver<Pumped>,
    delivery: &'a mut Delivery,
    stop: &'a mut watch::Receiver<bool>,
    tick: tokio::time::Interval,
    /// When to return [`Step::Wake`], once.
    wake: Option<tokio::time::Instant>,
    connections: &'a mut u64,
    /// Whether the mode is serving (set by the mode once its first messages are out).
    pub connected: bool,
}

impl Connection<'_> {
    /// The next thing that happened; the change stream only when `live_on`.
    pub async fn next(
        &mut self,
        live: &mut broadcast::Receiver<LiveMessage>,
        live_on: bool,
    ) -> Result<Step, End> {
        loop {
            let wake = self.wake;
            let event = tokio::select! {
                () = wait_until(wake) => {
                    self.wake = None;
                    return Ok(Step::Wake);
                }
                changed = self.stop.changed() => {
                    if changed.is_err() || *self.stop.borrow() {
                        return Err(End::Stop);
                    }
                    continue;
                }
                event = self.events.recv() => event,
                message = live.recv(), if live_on => return Ok(Step::Live(message)),
                _ = self.tick.tick() => return Ok(Step::Tick),
            };
            match event {
                Some(Pumped::Event(MqttEvent::Incoming(Packet::ConnAck(_)))) => {
                    *self.connections += 1;
                    if *self.connections > 1 {
                        self.link.status.metrics.reconnects.inc();
                    }
                    return Ok(Step::Connected);
                }
                Some(Pumped::Event(MqttEvent::Incoming(Packet::Publish(p)))) => {
                    return Ok(Step::Message {
                        topic: p.topic,
                        payload: p.payload.to_vec(),
                        retain: p.retain,
                    });
                }
                Some(Pumped::Event(MqttEvent::Incoming(Packet::PingResp))) => {
                    if let Some(t) = self.delivery.ping_answered() {
                        self.link.store_forwarded(t).await;
                    }
                }
                Some(Pumped::Ping { written }) => self.delivery.wrote_ping(written),
                Some(Pumped::Event(_) | Pumped::Disconnected { .. }) => {}
                Some(Pumped::End(why)) => return Err(End::Lost(why)),
                None => return Err(End::Lost("the MQTT client stopped".to_owned())),
            }
        }
    }

    /// Asks for one [`Step::Wake`] at `at` (replacing an earlier request).
    pub fn wake_at(&mut self, at: tokio::time::Instant) {
        self.wake = Some(at);
    }

    /// Hands a message to the client (waiting while its queue is full).
    pub async fn publish(&mut self, message: Outgoing) -> Result<(), String> {
        let topic = message.topic.clone();
        self.delivery.handed(message.latest);
        self.client
            .publish(message.topic, message.qos, message.retain, message.payload)
            .await
            .map_err(|e| format!("cannot publish {topic}: {e}"))?;
        self.link.status.metrics.published.inc();
        Ok(())
    }

    /// Subscribes to `filter` (QoS 1).
    pub async fn subscribe(&self, filter: String) -> Result<(), String> {
        self.client
            .subscribe(filter.clone(), QoS::AtLeastOnce)
            .await
            .map_err(|e| format!("cannot subscribe to {filter}: {e}"))
    }

    /// Unsubscribes from `filter`.
    pub async fn unsubscribe(&self, filter: String) -> Result<(), String> {
        self.client
            .unsubscribe(filter.clone())
            .await
            .map_err(|e| format!("cannot unsubscribe from {filter}: {e}"))
    }

    /// The forwarded mark.
    pub fn forwarded(&self) -> Timestamp {
        self.delivery.forwarded()
    }

    /// Where a new birth cycle in this connection resumes the stored changes (after a
    /// lag or a rebirth): the latest change handed to the client, else the mark.
    pub fn catch_up_from(&self) -> Timestamp {
        self.delivery.catch_up_from()
    }

    /// Moves the forwarded mark back to `at` at the latest, and stores it.
    pub async fn rewind_forwarded(&mut self, at: Timestamp) {
        if let Some(t) = self.delivery.rewind_to(at) {
            self.link.store_forwarded(t).await;
        }
    }

    /// The mode is serving: the status says connected.
    pub fn serving(&mut self, words: String) {
        self.connected = true;
        let cell = &self.link.cell;
        self.link.status.metrics.connected.set(1);
        self.link.status.set_link(MqttLink::Connected);
        cell.emit(link_event(EventKind::InterfaceUp, words));
    }

    /// Publishes `will`, disconnects, and waits (bounded) until everything is written; a
    /// clean close moves the forwarded mark.
    async fn close(&mut self, will: &Outgoing) {
        let _ = self.publish(will.clone()).await;
        let _ = self.client.disconnect().await;
        let drained = tokio::time::timeout(STOP_GRACE, async {
            while let Some(event) = self.events.recv().await {
                match event {
                    Pumped::Disconnected { written } => return Some(written),
                    Pumped::End(_) => return None,
                    Pumped::Event(_) | Pumped::Ping { .. } => {}
                }
            }
            None
        })
        .await;
        if let Ok(Some(written)) = drained
            && let Some(t) = self.delivery.closed_cleanly(written)
        {
            self.link.store_forwarded(t).await;
        }
    }
}

/// Sleeps until `at`; never ends for `None`.
async fn wait_until(at: Option<tokio::time::Instant>) {
    match at {
        Some(at) => tokio::time::sleep_until(at).await,
        None => std::future::pending().await,
    }
}

/// What the event loop reports to the connection's task.
#[derive(Debug)]
pub enum Pumped {
    /// An incoming packet (or an outgoing one the task does not count).
    Event(MqttEvent),
    /// A PINGREQ went out after this many publishes of the connection.
    Ping {
        /// Publishes written before it.
        written: u64,
    },
    /// The DISCONNECT went out after this many publishes of the connection.
    Disconnected {
        /// Publishes written before it.
        written: u64,
    },
    /// The connection ended, described (a failed TLS handshake as one).
    End(String),
}

/// Drives the event loop (polling it is what drives the connection) and reports to the
/// connection's task. Written publishes are only counted, not reported one by one: at
/// tens of thousands a second, a message per publish would cost more than the publish.
async fn pump(mut eventloop: EventLoop, events: mpsc::UnboundedSender<Pumped>) {
    let mut written = 0_u64;
    loop {
        let report = match eventloop.poll().await {
            Ok(MqttEvent::Outgoing(Sent::Publish(_))) => {
                written += 1;
                continue;
            }
            Ok(MqttEvent::Outgoing(Sent::PingReq)) => Pumped::Ping { written },
            Ok(MqttEvent::Outgoing(Sent::Disconnect)) => Pumped::Disconnected { written },
            Ok(MqttEvent::Outgoing(_)) => continue,
            Ok(event) => Pumped::Event(event),
            Err(e) => {
                let (host, port) = eventloop.mqtt_options.broker_address();
                let _ = events.send(Pumped::End(tls::describe(&e, &host, port)));
                return;
            }
        };
        if events.send(report).is_err() {
            return;
        }
    }
}

/// The wait before the next connection attempt, given the wait so far and how the last
/// connection went: back to [`RETRY_FIRST`] after a session that lasted
/// [`STABLE_SESSION`], else the wait so far (it doubles after the wait, up to
/// [`RETRY_CAP`]), so sessions the broker ends at once are not retried twice a second.
fn first_wait(retry: Duration, connected: bool, lasted: Duration) -> Duration {
    if connected && lasted >= STABLE_SESSION {
        RETRY_FIRST
    } else {
        retry
    }
}

/// An event about the link to the broker (`interface_up`, `interface_down`), its
/// `interface` field `mqtt`.
fn link_event(kind: EventKind, message: String) -> Event {
    let mut event = Event::of_gateway(kind, message);
    event.fields = crate::event::fields([("interface", serde_json::json!(status::NAME))]);
    event
}

/// What the command line says to the MQTT interface (in [`ServeOptions::flags`]).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct MqttFlags {
    /// `--mqtt mqtt://HOST:PORT` (or `mqtts://HOST:PORT`, TLS): publish the cell as a
    /// Sparkplug B edge node to this broker (the demo cell as group `cellbus`, edge node
    /// `demo`); with a config, it replaces the `[mqtt]` table's broker (keeping its TLS
    /// files for `mqtts://`; without a table, TLS trusts the system's roots).
    pub broker: Option<String>,
    /// `--mqtt-mode`: Sparkplug B or JSON, overriding the `[mqtt]` table's `mode`.
    pub mode: Option<MqttMode>,
    /// `--mqtt-node`: the Sparkplug edge node id, overriding the `[mqtt]` table's.
    pub node: Option<String>,
    /// `--mqtt-primary-host`: the Sparkplug primary host whose STATE gates the births.
    pub primary_host: Option<String>,
}

/// The MQTT interface: the cell on a broker, as a Sparkplug B edge node or plain JSON.
#[derive(Debug)]
pub struct Mqtt;

impl Northbound for Mqtt {
    fn name(&self) -> &'static str {
        "mqtt"
    }

    fn table(&self) -> &'static dyn TableReader {
        &config::MqttTable
    }

    fn start<'a>(&'a self, start: Start<'a>) -> BoxStart<'a> {
        Box::pin(async move {
            let Some(config) = mqtt_config(start.options, start.config, start.demo)? else {
                return Ok(None);
            };
            let task = self::start(
                Arc::clone(start.cell),
                config,
                start.options.data_dir.clone(),
                start.options.allow_writes,
                start.stopped,
            )?;
            Ok(Some(Running {
                name: "mqtt",
                url: None,
                task,
            }))
        })
    }
}

/// The demo cell's Sparkplug edge node id (its group is `cellbus`).
pub const DEMO_EDGE_NODE: &str = "demo";

/// The MQTT connection to make, if any: `--mqtt` (the demo cell's, or replacing the
/// config's broker), else the config's `[mqtt]` table; `--mqtt-mode`, `--mqtt-node` and
/// `--mqtt-primary-host` override the table's fields.
fn mqtt_config(
    options: &ServeOptions,
    cell_config: &CellConfig,
    demo: bool,
) -> anyhow::Result<Option<MqttConfig>> {
    let none = MqttFlags::default();
    let flags = options.flags.get::<MqttFlags>().unwrap_or(&none);
    let mut mqtt = match (&flags.broker, cell_config.interface::<MqttConfig>("mqtt")) {
        (None, None) => {
            if flags.mode.is_some() || flags.node.is_some() || flags.primary_host.is_some() {
                return Err(OptionError(
                    "--mqtt-mode, --mqtt-node and --mqtt-primary-host need a broker: give \
                     --mqtt URL or an [mqtt] table in the configuration"
                        .to_owned(),
                )
                .into());
            }
            return Ok(None);
        }
        (None, Some(table)) => table.clone(),
        (Some(url), Some(table)) => {
            let broker =
                config::parse_broker(url).map_err(|m| OptionError(format!("--mqtt: {m}")))?;
            MqttConfig {
                host: broker.host,
                port: broker.port,
                // mqtts:// keeps the table's CA and client certificate, if it has them.
                tls: broker.tls.then(|| table.tls.clone().unwrap_or_default()),
                ..table.clone()
            }
        }
        (Some(url), None) => {
            let node = match &flags.node {
                Some(node) => node.clone(),
                None if demo => DEMO_EDGE_NODE.to_owned(),
                None => crate::northbound::default_edge_node_id(),
            };
            MqttConfig::for_broker(url, &node).map_err(|m| OptionError(format!("--mqtt: {m}")))?
        }
    };
    if let Some(mode) = flags.mode {
        mqtt.mode = mode;
    }
    if let Some(node) = &flags.node {
        ::sparkplug::Id::new(node.as_str())
            .map_err(|e| OptionError(format!("--mqtt-node {node:?}: {e}")))?;
        if mqtt.prefix == format!("cellbus/{}", mqtt.edge_node_id) {
            mqtt.prefix = format!("cellbus/{node}");
        }
        if mqtt.client_id == format!("cellbus-{}", mqtt.edge_node_id) {
            mqtt.client_id = format!("cellbus-{node}");
        }
        mqtt.edge_node_id.clone_from(node);
    }
    if let Some(host) = &flags.primary_host {
        ::sparkplug::Id::new(host.as_str())
            .map_err(|e| OptionError(format!("--mqtt-primary-host {host:?}: {e}")))?;
        mqtt.primary_host = Some(host.clone());
    }
    Ok(Some(mqtt))
}

#[cfg(test)]
mod retry_tests;
