//! The cell as a Sparkplug B edge node on an MQTT broker: [`sparkplug::EdgeNode`] decides
//! what to publish, rumqttc carries it.
//!
//! One task per gateway. Per connection it:
//!
//! 1. stores the next `bdSeq` in the history database (`settings` table) before
//!    connecting, so a restart never reuses one;
//! 2. builds fresh `MqttOptions` whose Will is the NDEATH with this connection's `bdSeq`
//!    (rumqttc fixes the Will at connect and would reconnect with a stale one, so the
//!    task makes a new client for every connection instead of letting rumqttc reconnect);
//! 3. on ConnAck: subscribes to NCMD and DCMD (rumqttc does not re-subscribe), then
//!    publishes the NBIRTH and a DBIRTH per device (followed by a DDEATH for a device that
//!    is down), from a fresh subscription to the change stream so nothing falls between;
//! 4. turns each change into a DDATA by alias (changed metrics only), a device going down
//!    into a DDEATH and coming back into a DBIRTH; a lagging change stream, or an NCMD
//!    `Node Control/Rebirth`, gives a full rebirth;
//! 5. on a lost connection waits (0.5 s doubling to 30 s) and starts again at 1.
//!
//! A graceful stop publishes the NDEATH itself before disconnecting. DCMD writes are not
//! enabled in this version: a valid DCMD is logged and ignored.

use std::collections::HashSet;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use rumqttc::{
    AsyncClient, Event as MqttEvent, EventLoop, LastWill, MqttOptions, Packet, QoS, Transport,
};
use sparkplug::{
    BdSeq, Command, DataType, Delivery, EdgeNode, Id, MetricName, MetricSpec, MetricValue, Publish,
    Qos, Sample,
};
use tokio::sync::{broadcast, mpsc, watch};
use tokio::task::JoinHandle;

use super::{device_metrics, sample_of, sparkplug_time};
use crate::cell::{Cell, DeviceStatus, LiveMessage, MqttLink};
use crate::config::MqttConfig;
use crate::event::{Event, EventKind};
use crate::point::{DeviceId, PointId};
use crate::time::Timestamp;

pub mod tls;

/// The key of the stored `bdSeq` in the history database's `settings` table.
pub const BD_SEQ_KEY: &str = "mqtt.bd_seq";

/// First wait after a lost or refused connection; it doubles up to [`RETRY_CAP`].
pub const RETRY_FIRST: Duration = Duration::from_millis(500);
/// Longest wait between connection attempts.
pub const RETRY_CAP: Duration = Duration::from_secs(30);

/// Requests queued for the MQTT client.
const QUEUE: usize = 1024;
/// Largest MQTT packet sent or accepted: large cells make large births.
const MAX_PACKET: usize = 4 << 20;
/// How long a graceful stop waits for the NDEATH and DISCONNECT to leave.
const STOP_GRACE: Duration = Duration::from_secs(3);

/// Node metric: the gateway's version.
pub const VERSION_METRIC: &str = "Gateway/Version";
/// Node metric: the number of lines.
pub const LINES_METRIC: &str = "Gateway/Lines";
/// Node metric: history rows written since start.
pub const HISTORY_ROWS_METRIC: &str = "Gateway/History rows";

/// Starts publishing `cell` to the broker in `config` until `stop` turns true; `data_dir`
/// holds the database that keeps `bdSeq`. Fails at once only for what no retry can fix
/// (an id Sparkplug refuses, a password variable that is not set, TLS files that do not
/// make a TLS setup).
pub fn start(
    cell: Arc<Cell>,
    config: MqttConfig,
    data_dir: PathBuf,
    stop: watch::Receiver<bool>,
) -> anyhow::Result<JoinHandle<()>> {
    let password = match &config.password_env {
        Some(var) => Some(std::env::var(var).with_context(|| {
            format!("the MQTT password's environment variable {var} is not set")
        })?),
        None => None,
    };
    let group = Id::new(config.group_id.as_str())
        .map_err(|e| anyhow::anyhow!("MQTT group_id {:?}: {e}", config.group_id))?;
    let edge_node = Id::new(config.edge_node_id.as_str())
        .map_err(|e| anyhow::anyhow!("MQTT edge_node_id {:?}: {e}", config.edge_node_id))?;
    let transport = match &config.tls {
        Some(files) => tls::transport(&tls::client_config(files).context("MQTT TLS")?),
        None => Transport::Tcp,
    };
    cell.set_mqtt(MqttLink::Disconnected("not connected yet".to_owned()));
    let link = Link {
        cell,
        config,
        password,
        data_dir,
        transport,
    };
    Ok(tokio::spawn(link.run(group, edge_node, stop)))
}

struct Link {
    cell: Arc<Cell>,
    config: MqttConfig,
    password: Option<String>,
    data_dir: PathBuf,
    /// TCP, or TLS for `mqtts://`.
    transport: Transport,
}

/// Why a connection ended.
enum End {
    /// Lost or refused; try again.
    Lost(String),
    /// The gateway stops.
    Stop,
}

impl Link {
    async fn run(self, group: Id, edge_node: Id, mut stop: watch::Receiver<bool>) {
        let first = match self.read_bd_seq().await {
            Ok(n) => n,
            Err(e) => {
                tracing::warn!("cannot read the stored MQTT bdSeq ({e}); starting from 0");
                BdSeq::new(0)
            }
        };
        let mut node = EdgeNode::new(group, edge_node, first);
        let mut live = self.cell.subscribe();
        let mut retry = RETRY_FIRST;
        let mut connections = 0_u64;
        let mut was_connected = true; // so that the first failure is reported
        loop {
            if *stop.borrow() {
                return;
            }
            if let Err(e) = self.write_bd_seq(node.next_bd_seq()).await {
                tracing::warn!(
                    "cannot store the next MQTT bdSeq ({e}); a restart may repeat bdSeq {}",
                    node.bd_seq().value()
                );
            }
            let will = node.will();
            let (client, eventloop) = AsyncClient::new(self.options(&will), QUEUE);
            let (events_tx, events) = mpsc::unbounded_channel();
            let pump = tokio::spawn(pump(eventloop, events_tx));
            let mut session = Session {
                cell: &self.cell,
                client: &client,
                node: &mut node,
                dead: HashSet::new(),
                connected: false,
            };
            let end = session
                .serve(events, &mut live, &mut stop, &mut connections)
                .await;
            let connected = session.connected;
            if connected {
                retry = RETRY_FIRST;
            }
            match end {
                End::Stop => {
                    if connected {
                        let _ = publish(&self.cell, &client, &will).await;
                        let _ = client.disconnect().await;
                        let _ = tokio::time::timeout(STOP_GRACE, pump).await;
                    } else {
                        pump.abort();
                    }
                    self.went_down(&mut node, connected, "the gateway stopped".to_owned());
                    return;
                }
                End::Lost(why) => {
                    pump.abort();
                    if connected || was_connected {
                        self.went_down(&mut node, connected, why.clone());
                    }
                    self.cell.set_mqtt(MqttLink::Disconnected(why));
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

    fn went_down(&self, node: &mut EdgeNode, connected: bool, why: String) {
        node.on_disconnect();
        self.cell.metrics().mqtt_connected.set(0);
        self.cell.set_mqtt(MqttLink::Disconnected(why.clone()));
        let what = if connected {
            "MQTT connection lost"
        } else {
            "cannot connect to the MQTT broker"
        };
        self.cell.emit(event(
            EventKind::MqttDisconnected,
            format!(
                "{what} ({}:{}): {why}; retrying",
                self.config.host, self.config.port
            ),
        ));
    }

    fn options(&self, will: &Publish) -> MqttOptions {
        let c = &self.config;
        let mut options = MqttOptions::new(&c.client_id, &c.host, c.port);
        options
            .set_keep_alive(c.keep_alive)
            .set_clean_session(true)
            .set_max_packet_size(MAX_PACKET, MAX_PACKET)
            .set_transport(self.transport.clone())
            .set_last_will(LastWill::new(
                will.topic.to_string(),
                will.payload.clone(),
                qos(will.qos),
                will.retain,
            ));
        if let Some(user) = &c.username {
            options.set_credentials(user, self.password.clone().unwrap_or_default());
        }
        options
    }

    async fn read_bd_seq(&self) -> anyhow::Result<BdSeq> {
        let dir = self.data_dir.clone();
        let store = self.cell.store().clone();
        let stored = tokio::task::spawn_blocking(move || {
            // The writer's open moves a damaged file aside: wait for it (bounded) first.
            let _ = store.wait_open();
            crate::store::read_setting(&dir, BD_SEQ_KEY)
        })
        .await??;
        Ok(BdSeq::new(
            u8::try_from(stored.unwrap_or(0).rem_euclid(256)).unwrap_or(0),
        ))
    }

    async fn write_bd_seq(&self, next: BdSeq) -> anyhow::Result<()> {
        let dir = self.data_dir.clone();
        tokio::task::spawn_blocking(move || {
            crate::store::write_setting(&dir, BD_SEQ_KEY, i64::from(next.value()))
        })
        .await??;
        Ok(())
    }
}

/// One MQTT connection's life.
struct Session<'a> {
    cell: &'a Arc<Cell>,
    client: &'a AsyncClient,
    node: &'a mut EdgeNode,
    /// Devices with a DDEATH since their last DBIRTH.
    dead: HashSet<DeviceId>,
    connected: bool,
}

impl Session<'_> {
    async fn serve(
        &mut self,
        mut events: mpsc::UnboundedReceiver<Result<MqttEvent, String>>,
        live: &mut broadcast::Receiver<LiveMessage>,
        stop: &mut watch::Receiver<bool>,
        connections: &mut u64,
    ) -> End {
        loop {
            let step = tokio::select! {
                changed = stop.changed() => {
                    if changed.is_err() || *stop.borrow() {
                        return End::Stop;
                    }
                    Ok(())
                }
                event = events.recv() => match event {
                    Some(Ok(MqttEvent::Incoming(Packet::ConnAck(_)))) => {
                        *connections += 1;
                        if *connections > 1 {
                            self.cell.metrics().mqtt_reconnects.inc();
                        }
                        // A fresh receiver: the births are a snapshot taken after it.
                        *live = live.resubscribe();
                        self.on_connect().await
                    }
                    Some(Ok(MqttEvent::Incoming(Packet::Publish(p)))) => {
                        self.on_command(&p.topic, &p.payload).await
                    }
                    Some(Ok(_)) => Ok(()),
                    Some(Err(why)) => return End::Lost(why),
                    None => return End::Lost("the MQTT client stopped".to_owned()),
                },
                message = live.recv(), if self.connected => match message {
                    Ok(message) => self.on_change(message).await,
                    Err(broadcast::error::RecvError::Lagged(missed)) => {
                        tracing::warn!("MQTT: {missed} changes missed; publishing births again");
                        self.births().await
                    }
                    Err(broadcast::error::RecvError::Closed) => return End::Stop,
                },
            };
            if let Err(why) = step {
                return End::Lost(why);
            }
        }
    }

    async fn on_connect(&mut self) -> Result<(), String> {
        self.node.on_connect();
        for filter in self.node.command_filters() {
            self.client
                .subscribe(filter, QoS::AtLeastOnce)
                .await
                .map_err(|e| format!("cannot subscribe to commands: {e}"))?;
        }
        self.births().await?;
        self.connected = true;
        self.cell.metrics().mqtt_connected.set(1);
        self.cell.set_mqtt(MqttLink::Connected);
        let bd_seq = self.node.bd_seq().value().wrapping_sub(1);
        self.cell.emit(event(
            EventKind::MqttConnected,
            format!(
                "MQTT connected as spBv1.0/{}/{} (bdSeq {bd_seq}); births published",
                self.node.group(),
                self.node.edge_node()
            ),
        ));
        Ok(())
    }

    /// NBIRTH, then a DBIRTH per device (and a DDEATH after it for a device that is down).
    async fn births(&mut self) -> Result<(), String> {
        let now = Timestamp::now();
        let t = sparkplug_time(now);
        let birth = self
            .node
            .node_birth(&node_metrics(self.cell, t), t)
            .map_err(|e| format!("cannot build the NBIRTH: {e}"))?;
        publish(self.cell, self.client, &birth).await?;
        self.dead.clear();
        for device in self.cell.devices() {
            let Ok(id) = Id::new(device.summary.id.as_str()) else {
                continue;
            };
            let birth = self
                .node
                .device_birth(&id, &device_metrics(&device, now), t)
                .map_err(|e| format!("cannot build the DBIRTH of {id}: {e}"))?;
            publish(self.cell, self.client, &birth).await?;
            if device.summary.status == DeviceStatus::Down {
                self.device_down(&device.summary.id, t).await?;
            }
        }
        Ok(())
    }

    async fn device_down(
        &mut self,
        device: &DeviceId,
        t: sparkplug::Timestamp,
    ) -> Result<(), String> {
        let Ok(id) = Id::new(device.as_str()) else {
            return Ok(());
        };
        if let Ok(death) = self.node.device_death(&id, t) {
            publish(self.cell, self.client, &death).await?;
        }
        self.dead.insert(device.clone());
        Ok(())
    }

    async fn on_change(&mut self, message: LiveMessage) -> Result<(), String> {
        let now = Timestamp::now();
        let t = sparkplug_time(now);
        match message {
            LiveMessage::Value(view) => {
                let Some(device) = self.live_device(&view.id) else {
                    return Ok(());
                };
                let Some(spec) = self.cell.point(&view.id) else {
                    return Ok(());
                };
                let sample = sample_of(&spec.kind, &view, now);
                match self
                    .node
                    .device_data(&device, &[(view.id.name(), sample)], t, Delivery::Live)
                {
                    Ok(Some(data)) => publish(self.cell, self.client, &data).await?,
                    Ok(None) => {}
                    Err(e) => tracing::debug!("MQTT: no DDATA for {}: {e}", view.id),
                }
            }
            LiveMessage::Device(summary) => match summary.status {
                DeviceStatus::Down if !self.dead.contains(&summary.id) => {
                    self.device_down(&summary.id, t).await?;
                }
                DeviceStatus::Up if self.dead.contains(&summary.id) => {
                    let Some(device) = self.cell.device(summary.id.as_str()) else {
                        return Ok(());
                    };
                    let Ok(id) = Id::new(summary.id.as_str()) else {
                        return Ok(());
                    };
                    let birth = self
                        .node
                        .device_birth(&id, &device_metrics(&device, now), t)
                        .map_err(|e| format!("cannot build the DBIRTH of {id}: {e}"))?;
                    publish(self.cell, self.client, &birth).await?;
                    self.dead.remove(&summary.id);
                }
                _ => {}
            },
            LiveMessage::Event(_) => {}
        }
        Ok(())
    }

    /// The Sparkplug id of the point's device, unless the device is dead.
    fn live_device(&self, point: &PointId) -> Option<Id> {
        let device = DeviceId::new(point.device()).ok()?;
        if self.dead.contains(&device) {
            return None;
        }
        Id::new(device.as_str()).ok()
    }

    async fn on_command(&mut self, topic: &str, payload: &[u8]) -> Result<(), String> {
        match self.node.handle_command(topic, payload) {
            Ok(commands) => {
                for command in commands {
                    match command {
                        Command::Rebirth => {
                            tracing::info!("MQTT: rebirth asked on {topic}");
                            self.births().await?;
                        }
                        Command::Write {
                            device,
                            metric,
                            value,
                        } => tracing::warn!(
                            device = device.as_ref().map(Id::as_str),
                            metric = metric.as_str(),
                            "DCMD writes are not enabled: {metric} = {value:?} on {topic} ignored"
                        ),
                    }
                }
            }
            Err(e) => tracing::warn!("MQTT: command on {topic} refused: {e}"),
        }
        Ok(())
    }
}

/// Forwards the event loop's incoming packets and its end (described, a failed TLS
/// handshake as one); polling it is what drives the connection.
async fn pump(mut eventloop: EventLoop, events: mpsc::UnboundedSender<Result<MqttEvent, String>>) {
    loop {
        let event = eventloop.poll().await.map_err(|e| {
            let (host, port) = eventloop.mqtt_options.broker_address();
            tls::describe(&e, &host, port)
        });
        let end = event.is_err();
        if matches!(event, Ok(MqttEvent::Outgoing(_))) {
            continue;
        }
        if events.send(event).is_err() || end {
            return;
        }
    }
}

async fn publish(cell: &Cell, client: &AsyncClient, message: &Publish) -> Result<(), String> {
    client
        .publish(
            message.topic.to_string(),
            qos(message.qos),
            message.retain,
            message.payload.clone(),
        )
        .await
        .map_err(|e| format!("cannot publish {}: {e}", message.topic))?;
    cell.metrics().mqtt_published.inc();
    Ok(())
}

fn qos(qos: Qos) -> QoS {
    match qos {
        Qos::AtMostOnce => QoS::AtMostOnce,
        Qos::AtLeastOnce => QoS::AtLeastOnce,
    }
}

/// The node's own metrics in its NBIRTH: version, lines, history rows written.
fn node_metrics(cell: &Cell, t: sparkplug::Timestamp) -> Vec<(MetricSpec, Sample)> {
    let name = |n: &str| MetricName::new(n).expect("the node metric names are not empty");
    let rows = i64::try_from(cell.store().stats().rows_written()).unwrap_or(i64::MAX);
    let lines = i64::try_from(cell.lines().len()).unwrap_or(i64::MAX);
    vec![
        (
            MetricSpec::new(name(VERSION_METRIC), DataType::String)
                .description("cellbus gateway version"),
            Sample::good(MetricValue::String(env!("CARGO_PKG_VERSION").to_owned()), t),
        ),
        (
            MetricSpec::new(name(LINES_METRIC), DataType::Int64)
                .description("lines the gateway polls"),
            Sample::good(MetricValue::Int64(lines), t),
        ),
        (
            MetricSpec::new(name(HISTORY_ROWS_METRIC), DataType::Int64)
                .description("history rows written since the gateway started"),
            Sample::good(MetricValue::Int64(rows), t),
        ),
    ]
}

fn event(kind: EventKind, message: String) -> Event {
    Event {
        t: Timestamp::now(),
        kind,
        line: None,
        device: None,
        point: None,
        message,
    }
}
