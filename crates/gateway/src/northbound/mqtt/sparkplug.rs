//! The Sparkplug B edge node: [`sparkplug::EdgeNode`] decides what to publish.
//!
//! Per connection:
//!
//! 1. the next `bdSeq` is stored before connecting; the Will is the NDEATH with this one;
//! 2. on ConnAck: subscribe to NCMD and DCMD, and to the primary host's STATE when
//!    `primary_host` is set; without a primary host, or once it says it is online, a
//!    *birth cycle*: NBIRTH, a DBIRTH per device (from a fresh change-stream subscription,
//!    so nothing falls between), then the stored changes since the forwarded mark as
//!    historical DDATA, then a DDEATH for each device that is down;
//! 3. live: changes become DDATA by alias (changed metrics only, one DDATA per device for
//!    what arrived together), a device going down a DDEATH and coming back a DBIRTH, the
//!    node's history row count an NDATA every 10 s, each gateway event an NDATA of the node
//!    metric `Event` ([`sparkplug::event`]: the message, its time, and `kind`, `severity`,
//!    `line`, `device`, `point` properties); a lagging change stream, or an NCMD
//!    `Node Control/Rebirth`, gives a new birth cycle. Events are live only: those of an
//!    outage, or missed in a lag, are not sent (the history's event log has them);
//! 4. the primary host going offline ends the connection (an NDEATH saying why, with
//!    [`sparkplug::node::HOST_OFFLINE`], then DISCONNECT) and moves the forwarded mark back
//!    by twice the keep-alive: the host may have been gone that long before the broker
//!    noticed, and what it missed is sent again once it is back. What a STATE is believed
//!    for (forged, late or far-future ones) is [`super::primary`]'s.
//!
//! DCMD writes go through the gateway's one audited write path
//! ([`crate::write::Attempt`]) when the gateway runs with `--allow-writes` and the
//! `[mqtt]` table says `commands = true`; otherwise they are refused, counted and logged
//! (throttled), and nothing is stored, as for an HTTP write without the switch.

use std::collections::HashSet;
use std::sync::Arc;
use std::time::Duration;

use rumqttc::QoS;
use sparkplug::{
    BdSeq, Command, DataType, Delivery, EdgeNode, HostState, Id, MessageKind, MetricName,
    MetricSpec, MetricValue, NodeEvent, Publish, Qos, Sample, Topic,
};
use tokio::sync::{broadcast, mpsc};

use super::forward::Backlog;
use super::mapping::{
    acknowledged_alarm, alarm_metrics, device_metrics, sample_of, sample_of_stored, sparkplug_time,
};
use super::primary::{OFFLINE_GRACE, PrimaryHost, STATE_SKEW_MS, Verdict};
use super::status;
use super::{Connection, End, Link, Mode, Outgoing, Step};
use crate::cell::{
    Cell, CheckedWrite, DeviceEntry, DeviceStatus, DeviceSummary, LiveMessage, PointView,
};
use crate::driver::WriteError;
use crate::event::{Event, EventKind};
use crate::point::{DeviceId, PointId, Value};
use crate::time::{Timestamp, duration_millis};
use crate::write::{Attempt, LOG_EVERY, LogThrottle, RowThrottle, Unauthorised};

/// The key of the stored `bdSeq` in the history database's `settings` table.
pub const BD_SEQ_KEY: &str = "mqtt.bd_seq";

/// Node metric: the gateway's version.
pub const VERSION_METRIC: &str = "Gateway/Version";
/// Node metric: the number of lines.
pub const LINES_METRIC: &str = "Gateway/Lines";
/// Node metric: history rows written since start.
pub const HISTORY_ROWS_METRIC: &str = "Gateway/History rows";

/// How often the node metrics are published when they changed.
const NODE_DATA_EVERY: Duration = Duration::from_secs(10);
/// Value changes of one device taken together, with the latest read time among them.
type DeviceChanges = (DeviceId, Vec<(String, Sample)>, Timestamp);

/// The change of `entry`'s point that `view` read, as a metric name and sample; `None`
/// when the device has no such point (any more).
fn change_of(entry: &DeviceEntry, view: &PointView, now: Timestamp) -> Option<(String, Sample)> {
    let name = view.id.name();
    let index = entry.point_index(name)?;
    Some((
        name.to_owned(),
        sample_of(&entry.points[index].kind, view, now),
    ))
}

/// Most metrics in one historical DDATA.
const HISTORICAL_BATCH: usize = 500;

/// The edge node of one gateway.
pub struct Node {
    cell: Arc<Cell>,
    node: EdgeNode,
    primary_host: Option<Id>,
    /// Whether DCMD writes are carried out (`--allow-writes` and `commands = true`).
    writes: bool,
    /// What the STATE messages of the primary host said in this connection.
    host: PrimaryHost,
    /// Refused STATE messages since the last log line.
    state_refused: LogThrottle,
    /// Devices with a DDEATH since their last DBIRTH.
    dead: HashSet<DeviceId>,
    /// Births published in this connection.
    born: bool,
    /// The history row count last published.
    rows_published: i64,
    /// Refused DCMDs since the last log line, and when that was.
    refused: Unauthorised,
    keep_alive: Duration,
    /// Whether the stored `bdSeq` was read (before the first connection).
    bd_seq_read: bool,
    /// The task that carries out DCMD writes in order, once the first came.
    writer: Option<mpsc::Sender<CheckedCommand>>,
    /// When the last rebirth asked for was published.
    last_rebirth: Option<tokio::time::Instant>,
    /// Refused NCMDs since the last log line.
    node_refused: LogThrottle,
    /// Audit rows of refused DCMDs, at most one per topic every [`LOG_EVERY`].
    refused_rows: RowThrottle,
    /// The most metrics one DCMD may carry (`max_command_metrics`).
    max_command_metrics: usize,
}

/// DCMDs waiting for the write task; more are refused whole (and audited).
const COMMANDS_WAITING: usize = 256;

/// Rebirth requests closer together than this get one birth cycle: each sends every
/// metric of the node and its devices again.
const REBIRTH_AT_MOST_EVERY: Duration = Duration::from_secs(2);

/// One DCMD, every write of it checked against its point: carried out in order by the
/// write task, or not at all.
struct CheckedCommand {
    writes: Vec<Write>,
}

/// One write of a checked DCMD.
struct Write {
    attempt: Attempt,
    write: CheckedWrite,
}

impl CheckedCommand {
    /// Carries the writes out in order; a write that fails stops the command, and each
    /// write after it gets a refused row saying so.
    async fn carry_out(self) {
        let mut writes = self.writes.into_iter();
        while let Some(write) = writes.next() {
            let point = write.write.point().clone();
            match write.attempt.carry_out_checked(write.write).await {
                Ok(done) => tracing::info!("MQTT: {}", done.detail),
                Err(e) => {
                    tracing::warn!("MQTT: DCMD write of {point} failed: {e}");
                    let why = format!(
                        "not carried out: the write of {point} before it in the same command \
                         failed"
                    );
                    for left in writes {
                        left.attempt.refuse(&why, None).await;
                    }
                    return;
                }
            }
        }
    }
}

/// Why a command was refused, and what its audit row names.
struct Refusal {
    why: String,
    /// The point (its name within the device) the refusal is about, if one.
    point: String,
    /// The value asked for that point.
    new: serde_json::Value,
}

impl Refusal {
    /// A refusal of the command as a whole.
    fn whole(why: impl Into<String>) -> Self {
        Self {
            why: why.into(),
            point: String::new(),
            new: serde_json::Value::Null,
        }
    }
}

/// A DCMD value as the write path's.
fn value_of(value: MetricValue) -> Result<Value, MetricValue> {
    match value {
        MetricValue::String(text) => Ok(Value::Text(text)),
        other => other.as_f64().map(Value::Number).ok_or(other),
    }
}

fn json_of(value: &Value) -> serde_json::Value {
    match value {
        Value::Number(n) => serde_json::json!(n),
        Value::Text(t) => serde_json::json!(t),
    }
}

impl Node {
    /// The edge node of the `[mqtt]` table in `link`.
    pub fn new(link: &Link, allow_writes: bool) -> anyhow::Result<Self> {
        let config = link.config();
        let group = Id::new(config.group_id.as_str())
            .map_err(|e| anyhow::anyhow!("MQTT group_id {:?}: {e}", config.group_id))?;
        let edge_node = Id::new(config.edge_node_id.as_str())
            .map_err(|e| anyhow::anyhow!("MQTT edge_node_id {:?}: {e}", config.edge_node_id))?;
        let primary_host = config
            .primary_host
            .as_deref()
            .map(Id::new)
            .transpose()
            .map_err(|e| anyhow::anyhow!("MQTT primary_host: {e}"))?;
        Ok(Self {
            cell: Arc::clone(link.cell()),
            // The stored bdSeq is read before the first connection (`prepare`).
            node: EdgeNode::new(group, edge_node, BdSeq::new(0)),
            primary_host,
            writes: allow_writes && config.commands,
            host: PrimaryHost::default(),
            state_refused: LogThrottle::default(),
            dead: HashSet::new(),
            born: false,
            rows_published: -1,
            refused: Unauthorised::default(),
            keep_alive: config.keep_alive,
            bd_seq_read: false,
            writer: None,
            last_rebirth: None,
            node_refused: LogThrottle::default(),
            refused_rows: RowThrottle::default(),
            max_command_metrics: config.max_command_metrics,
        })
    }
}

impl Mode for Node {
    async fn prepare(&mut self, link: &Link) -> Outgoing {
        if !self.bd_seq_read {
            self.bd_seq_read = true;
            match link.read_setting(BD_SEQ_KEY).await {
                Ok(stored) => {
                    let n = u8::try_from(stored.unwrap_or(0).rem_euclid(256)).unwrap_or(0);
                    self.node = EdgeNode::new(
                        self.node.group().clone(),
                        self.node.edge_node().clone(),
                        BdSeq::new(n),
                    );
                }
                Err(e) => {
                    tracing::warn!("cannot read the stored MQTT bdSeq ({e}); starting from 0")
                }
            }
        }
        let next = self.node.next_bd_seq();
        if let Err(e) = link
            .write_setting(BD_SEQ_KEY, i64::from(next.value()))
            .await
        {
            tracing::warn!(
                "cannot store the next MQTT bdSeq ({e}); a restart may repeat bdSeq {}",
                self.node.bd_seq().value()
            );
        }
        outgoing(self.node.will(), None)
    }

    async fn serve(
        &mut self,
        conn: &mut Connection<'_>,
        live: &mut broadcast::Receiver<LiveMessage>,
    ) -> End {
        loop {
            let step = match conn.next(live, self.born).await {
                Ok(step) => step,
                Err(end) => return end,
            };
            let done = match step {
                Step::Connected => self.on_connect(conn, live).await,
                Step::Message {
                    topic,
                    payload,
                    retain,
                } => self.on_message(conn, live, &topic, &payload, retain).await,
                Step::Live(Ok(message)) => self.on_change(conn, live, message).await,
                Step::Live(Err(broadcast::error::RecvError::Lagged(missed))) => {
                    tracing::warn!("MQTT: {missed} changes missed; publishing births again");
                    let from = conn.catch_up_from();
                    self.birth_cycle(conn, live, from).await
                }
                Step::Live(Err(broadcast::error::RecvError::Closed)) => return End::Stop,
                Step::Tick => self.node_data(conn).await,
                Step::Wake => self.host_offline(conn).await,
            };
            if let Err(end) = done {
                return end;
            }
        }
    }

    fn lost(&mut self) {
        self.host.reconnected();
        self.node.on_disconnect();
        self.born = false;
        self.dead.clear();
    }

    fn tick(&self) -> Duration {
        NODE_DATA_EVERY
    }
}

type Done = Result<(), End>;

fn lost(why: String) -> End {
    End::Lost(why)
}

impl Node {
    async fn on_connect(
        &mut self,
        conn: &mut Connection<'_>,
        live: &mut broadcast::Receiver<LiveMessage>,
    ) -> Done {
        self.node.on_connect();
        for filter in self.node.command_filters() {
            conn.subscribe(filter).await.map_err(lost)?;
        }
        match &self.primary_host {
            Some(host) => {
                conn.subscribe(Topic::State { host: host.clone() }.to_string())
                    .await
                    .map_err(lost)?;
                let bd_seq = self.session_bd_seq();
                conn.serving(format!(
                    "MQTT connected as spBv1.0/{}/{} (bdSeq {bd_seq}); waiting for primary \
                     host {host} to be online before the births",
                    self.node.group(),
                    self.node.edge_node()
                ));
                Ok(())
            }
            None => {
                let from = conn.forwarded();
                self.birth_cycle(conn, live, from).await?;
                let bd_seq = self.session_bd_seq();
                conn.serving(format!(
                    "MQTT connected as spBv1.0/{}/{} (bdSeq {bd_seq}); births published",
                    self.node.group(),
                    self.node.edge_node()
                ));
                Ok(())
            }
        }
    }

    fn session_bd_seq(&self) -> u8 {
        self.node.bd_seq().value().wrapping_sub(1)
    }

    /// NBIRTH, a DBIRTH per device, the changes stored since `from` as historical DDATA,
    /// then a DDEATH for each device that is down.
    async fn birth_cycle(
        &mut self,
        conn: &mut Connection<'_>,
        live: &mut broadcast::Receiver<LiveMessage>,
        from: Timestamp,
    ) -> Done {
        // A fresh receiver: the births are a snapshot taken after it.
        *live = live.resubscribe();
        let now = Timestamp::now();
        let t = sparkplug_time(now);
        let (metrics, rows) = node_metrics(&self.cell, t);
        let birth = self
            .node
            .node_birth(&metrics, t)
            .map_err(|e| lost(format!("cannot build the NBIRTH: {e}")))?;
        conn.publish(outgoing(birth, None)).await.map_err(lost)?;
        self.rows_published = rows;
        self.dead.clear();
        // One device's view at a time: a large cell's views together are tens of MB.
        let entries: Vec<_> = self.cell.device_entries().collect();
        let mut down = Vec::new();
        for entry in entries {
            if self.device_birth(conn, &entry, now).await? == Some(DeviceStatus::Down) {
                down.push(entry.id.clone());
            }
        }
        self.born = true;
        self.forward_backlog(conn, from, now).await?;
        for device in &down {
            self.device_down(conn, device, t).await?;
        }
        Ok(())
    }

    /// The DBIRTH of `entry` (its points and its alarms as they are now); its status then,
    /// or `None` when its id cannot be a Sparkplug id.
    async fn device_birth(
        &mut self,
        conn: &mut Connection<'_>,
        entry: &DeviceEntry,
        now: Timestamp,
    ) -> Result<Option<DeviceStatus>, End> {
        let device = entry.view(now);
        let Ok(id) = Id::new(device.summary.id.as_str()) else {
            return Ok(None);
        };
        let mut metrics = device_metrics(&device, now);
        for alarm in self.cell.alarms.of_device(id.as_str()) {
            metrics.extend(alarm_metrics(id.as_str(), &alarm, self.writes, now));
        }
        let birth = self
            .node
            .device_birth(&id, &metrics, sparkplug_time(now))
            .map_err(|e| lost(format!("cannot build the DBIRTH of {id}: {e}")))?;
        conn.publish(outgoing(birth, None)).await.map_err(lost)?;
        Ok(Some(device.summary.status))
    }

    /// A reload of the configuration (its `config_reloaded` event): a DDEATH for each
    /// device removed or changed, then a DBIRTH for each added or changed (with its new
    /// points), a DDEATH after it when it is down.
    async fn on_reload(&mut self, conn: &mut Connection<'_>, event: &Event) -> Done {
        if !self.born {
            return Ok(());
        }
        let now = Timestamp::now();
        let t = sparkplug_time(now);
        let changed = crate::reload::devices_in(event, "changed");
        for device in crate::reload::devices_in(event, "removed")
            .iter()
            .chain(&changed)
        {
            if let Ok(id) = Id::new(device.as_str())
                && let Ok(death) = self.node.device_death(&id, t)
            {
                conn.publish(outgoing(death, None)).await.map_err(lost)?;
            }
            self.dead.remove(device);
        }
        for device in crate::reload::devices_in(event, "added")
            .iter()
            .chain(&changed)
        {
            let Some(entry) = self.cell.device_entry(device.as_str()) else {
                continue;
            };
            if self.device_birth(conn, &entry, now).await? == Some(DeviceStatus::Down) {
                self.device_down(conn, device, t).await?;
            }
        }
        Ok(())
    }

    /// The changes stored after `from` and up to `until`, as historical DDATA in time
    /// order (consecutive changes of one device in one message).
    async fn forward_backlog(
        &mut self,
        conn: &mut Connection<'_>,
        from: Timestamp,
        until: Timestamp,
    ) -> Done {
        let max = conn.link.config().max_backlog;
        let Some(mut backlog) = Backlog::start(&self.cell, from, until, max).await else {
            return Ok(());
        };
        let mut sent = 0_u64;
        loop {
            let page = backlog.next_page_or_end().await;
            if page.is_empty() {
                break;
            }
            let mut batch: Vec<(String, Sample)> = Vec::new();
            let mut batch_device: Option<DeviceId> = None;
            let mut latest = None;
            for change in page {
                let Ok(point) = PointId::parse(&change.point) else {
                    continue;
                };
                let Some(spec) = self.cell.point(&point) else {
                    continue; // a point no longer configured
                };
                let sample = sample_of_stored(
                    &spec.kind,
                    change.value.as_ref(),
                    change.quality,
                    change.key.t,
                );
                let device = DeviceId::new(point.device()).ok();
                if device != batch_device || batch.len() >= HISTORICAL_BATCH {
                    sent += self
                        .historical(conn, &batch_device, &mut batch, latest)
                        .await?;
                    batch_device = device;
                }
                latest = Some(change.key.t);
                batch.push((point.name().to_owned(), sample));
            }
            sent += self
                .historical(conn, &batch_device, &mut batch, latest)
                .await?;
        }
        if sent > 0 {
            status::status(&self.cell).metrics.forwarded.inc_by(sent);
        }
        Ok(())
    }

    async fn historical(
        &mut self,
        conn: &mut Connection<'_>,
        device: &Option<DeviceId>,
        batch: &mut Vec<(String, Sample)>,
        latest: Option<Timestamp>,
    ) -> Result<u64, End> {
        let changes = std::mem::take(batch);
        let (Some(device), false) = (device, changes.is_empty()) else {
            return Ok(0);
        };
        let Ok(id) = Id::new(device.as_str()) else {
            return Ok(0);
        };
        let t = sparkplug_time(Timestamp::now());
        match self
            .node
            .device_data(&id, &changes, t, Delivery::Historical)
        {
            Ok(Some(data)) => {
                conn.publish(outgoing(data, latest)).await.map_err(lost)?;
                Ok(changes.len() as u64)
            }
            Ok(None) => Ok(0),
            Err(e) => {
                tracing::debug!("MQTT: no historical DDATA for {id}: {e}");
                Ok(0)
            }
        }
    }

    async fn device_down(
        &mut self,
        conn: &mut Connection<'_>,
        device: &DeviceId,
        t: sparkplug::Timestamp,
    ) -> Done {
        let Ok(id) = Id::new(device.as_str()) else {
            return Ok(());
        };
        if let Ok(death) = self.node.device_death(&id, t) {
            conn.publish(outgoing(death, None)).await.map_err(lost)?;
        }
        self.dead.insert(device.clone());
        Ok(())
    }

    /// One change, and every change already waiting behind it: value changes become one
    /// DDATA per device.
    async fn on_change(
        &mut self,
        conn: &mut Connection<'_>,
        live: &mut broadcast::Receiver<LiveMessage>,
        first: LiveMessage,
    ) -> Done {
        let mut values: Vec<DeviceChanges> = Vec::new();
        // The entry of each device in `values`, in the same order.
        let mut entries: Vec<Arc<DeviceEntry>> = Vec::new();
        let mut roster = self.cell.roster();
        let now = Timestamp::now();
        let mut next = Some(first);
        while let Some(message) = next.take() {
            match message {
                LiveMessage::Value(view) => {
                    let read = view.t.unwrap_or(now);
                    // A poll's changes come together: the group is nearly always the last.
                    match values
                        .iter()
                        .rposition(|(d, _, _)| d.as_str() == view.id.device())
                    {
                        Some(at) => {
                            if let Some(change) = change_of(&entries[at], &view, now) {
                                let (_, changes, latest) = &mut values[at];
                                changes.push(change);
                                *latest = (*latest).max(read);
                            }
                        }
                        None => {
                            if let Some(entry) = roster.device(view.id.device())
                                && let Some(change) = change_of(entry, &view, now)
                            {
                                values.push((entry.id.clone(), vec![change], read));
                                entries.push(Arc::clone(entry));
                            }
                        }
                    }
                }
                LiveMessage::Event(event) => {
                    // Keep the order: what came before an event goes out first.
                    entries.clear();
                    self.device_data(conn, std::mem::take(&mut values)).await?;
                    // A reload's devices are in the roster from its event on.
                    roster = self.cell.roster();
                    self.on_event(conn, &event).await?;
                    if event.kind == EventKind::ConfigReloaded {
                        self.on_reload(conn, &event).await?;
                    }
                    // An alarm's change is also its device's alarm metrics.
                    if let (Some(id), Some(device)) = (
                        event.fields.get("alarm").and_then(|a| a.as_str()),
                        &event.device,
                    ) && let Some(alarm) = self.cell.alarms.view(id)
                    {
                        let now = Timestamp::now();
                        let changes = alarm_metrics(device.as_str(), &alarm, self.writes, now)
                            .into_iter()
                            .map(|(spec, sample)| (spec.name.as_str().to_owned(), sample))
                            .collect();
                        self.device_data(conn, vec![(device.clone(), changes, now)])
                            .await?;
                    }
                }
                LiveMessage::Device(summary) => {
                    // Keep the order: what came before a status change goes out first.
                    entries.clear();
                    self.device_data(conn, std::mem::take(&mut values)).await?;
                    self.on_status(conn, *summary).await?;
                }
            }
            next = match live.try_recv() {
                Ok(message) => Some(message),
                Err(broadcast::error::TryRecvError::Lagged(missed)) => {
                    self.device_data(conn, values).await?;
                    tracing::warn!("MQTT: {missed} changes missed; publishing births again");
                    let from = conn.catch_up_from();
                    return self.birth_cycle(conn, live, from).await;
                }
                Err(_) => None,
            };
        }
        self.device_data(conn, values).await
    }

    async fn device_data(&mut self, conn: &mut Connection<'_>, values: Vec<DeviceChanges>) -> Done {
        let t = sparkplug_time(Timestamp::now());
        for (device, changes, latest) in values {
            if self.dead.contains(&device) {
                continue;
            }
            let Ok(id) = Id::new(device.as_str()) else {
                continue;
            };
            match self.node.device_data(&id, &changes, t, Delivery::Live) {
                Ok(Some(data)) => {
                    conn.publish(outgoing(data, Some(latest)))
                        .await
                        .map_err(lost)?;
                }
                Ok(None) => {}
                Err(e) => tracing::debug!("MQTT: no DDATA for {id}: {e}"),
            }
        }
        Ok(())
    }

    async fn on_status(&mut self, conn: &mut Connection<'_>, summary: DeviceSummary) -> Done {
        let now = Timestamp::now();
        let t = sparkplug_time(now);
        match summary.status {
            DeviceStatus::Down if !self.dead.contains(&summary.id) => {
                self.device_down(conn, &summary.id, t).await
            }
            DeviceStatus::Up if self.dead.contains(&summary.id) => {
                let Some(entry) = self.cell.device_entry(summary.id.as_str()) else {
                    return Ok(());
                };
                self.device_birth(conn, &entry, now).await?;
                self.dead.remove(&summary.id);
                Ok(())
            }
            _ => Ok(()),
        }
    }

    /// An NDATA with `event` as the node's `Event` metric.
    async fn on_event(&mut self, conn: &mut Connection<'_>, event: &Event) -> Done {
        let t = sparkplug_time(Timestamp::now());
        match self.node.node_event(&node_event(event), t) {
            Ok(data) => conn.publish(outgoing(data, None)).await.map_err(lost),
            Err(e) => {
                tracing::debug!("MQTT: no NDATA for the event: {e}");
                Ok(())
            }
        }
    }

    /// An NDATA with the history row count, when it changed.
    async fn node_data(&mut self, conn: &mut Connection<'_>) -> Done {
        if !self.born {
            return Ok(());
        }
        let rows = history_rows(&self.cell);
        if rows == self.rows_published {
            return Ok(());
        }
        let t = sparkplug_time(Timestamp::now());
        let sample = Sample::good(MetricValue::Int64(rows), t);
        match self
            .node
            .node_data(&[(HISTORY_ROWS_METRIC, sample)], t, Delivery::Live)
        {
            Ok(Some(data)) => {
                conn.publish(outgoing(data, None)).await.map_err(lost)?;
                self.rows_published = rows;
            }
            Ok(None) => {}
            Err(e) => tracing::debug!("MQTT: no NDATA: {e}"),
        }
        Ok(())
    }

    async fn on_message(
        &mut self,
        conn: &mut Connection<'_>,
        live: &mut broadcast::Receiver<LiveMessage>,
        topic: &str,
        payload: &[u8],
        retained: bool,
    ) -> Done {
        if let Some(host) = &self.primary_host
            && topic == (Topic::State { host: host.clone() }).to_string()
        {
            return self.on_host_state(conn, live, payload).await;
        }
        // Sparkplug B 3.0 (6.4.18, 6.4.19): NCMD and DCMD are published with retain false.
        // A retained one would be carried out again at every reconnection, after whatever
        // an operator set since.
        if retained {
            self.audit_refused_command(
                topic,
                Refusal::whole(
                    "a command the broker kept as retained (Sparkplug commands are never \
                     retained): not carried out again",
                ),
            )
            .await;
            return Ok(());
        }
        let commands = match self.node.handle_command(topic, payload) {
            Ok(commands) => commands,
            Err(e) => {
                self.audit_refused_command(topic, Refusal::whole(e.to_string()))
                    .await;
                return Ok(());
            }
        };
        if commands.is_empty() {
            self.audit_refused_command(topic, Refusal::whole("a command without metrics"))
                .await;
            return Ok(());
        }
        let mut writes = Vec::new();
        for command in commands {
            match command {
                Command::Rebirth => {
                    let now = tokio::time::Instant::now();
                    if self
                        .last_rebirth
                        .is_some_and(|t| now < t + REBIRTH_AT_MOST_EVERY)
                    {
                        tracing::debug!("MQTT: rebirth on {topic} ignored: births just sent");
                        continue;
                    }
                    self.last_rebirth = Some(now);
                    tracing::info!("MQTT: rebirth asked on {topic}");
                    let from = conn.catch_up_from();
                    self.birth_cycle(conn, live, from).await?;
                }
                Command::Write {
                    device,
                    metric,
                    value,
                } => writes.push((device, metric, value)),
            }
        }
        let (acks, writes): (Vec<_>, Vec<_>) =
            writes.into_iter().partition(|(device, metric, _)| {
                device
                    .as_ref()
                    .is_some_and(|d| acknowledged_alarm(d.as_str(), metric.as_str()).is_some())
            });
        if !acks.is_empty() {
            self.on_acknowledgements(topic, acks).await;
        }
        if !writes.is_empty() {
            self.on_writes(topic, writes).await;
        }
        Ok(())
    }

    /// A DCMD's `Alarms/…/Acknowledged = true`: each alarm acknowledged through the one
    /// alarm path (journalled with the topic as who), in a task of its own. Writes off:
    /// refused as a write is. `false` asks nothing.
    async fn on_acknowledgements(
        &mut self,
        topic: &str,
        acks: Vec<(Option<Id>, MetricName, MetricValue)>,
    ) {
        let mut ids = Vec::new();
        for (device, metric, value) in acks {
            let Some(device) = device else { continue };
            if !self.writes {
                self.refuse(topic, &device, metric.as_str());
                return;
            }
            if value != MetricValue::Boolean(true) {
                continue;
            }
            if let Some(candidates) = acknowledged_alarm(device.as_str(), metric.as_str()) {
                let known = candidates
                    .into_iter()
                    .find(|id| self.cell.alarms.view(id).is_some());
                match known {
                    Some(id) => ids.push(id),
                    None => {
                        self.audit_refused_command(
                            topic,
                            Refusal {
                                why: format!("{metric}: device {device} has no such alarm"),
                                point: metric.as_str().to_owned(),
                                new: serde_json::json!(true),
                            },
                        )
                        .await;
                    }
                }
            }
        }
        let cell = Arc::clone(&self.cell);
        let by = format!("mqtt DCMD {topic}");
        tokio::spawn(async move {
            for id in ids {
                if let Err(e) = crate::alarm::keeper::act(
                    &cell,
                    &id,
                    crate::alarm::book::Action::Acknowledge,
                    &by,
                    None,
                )
                .await
                {
                    tracing::info!("MQTT: {by}: {e}");
                }
            }
        });
    }

    async fn on_host_state(
        &mut self,
        conn: &mut Connection<'_>,
        live: &mut broadcast::Receiver<LiveMessage>,
        payload: &[u8],
    ) -> Done {
        let state = match HostState::from_json(payload) {
            Ok(state) => state,
            Err(e) => {
                tracing::warn!("MQTT: primary host STATE ignored: {e}");
                return Ok(());
            }
        };
        let topic = self
            .primary_host
            .as_ref()
            .map(|host| Topic::State { host: host.clone() }.to_string())
            .unwrap_or_default();
        let now = u64::try_from(Timestamp::now().0).unwrap_or(0);
        match (self.host.receive(state, now), self.born) {
            (Verdict::Online, false) => {
                let from = conn.forwarded();
                self.birth_cycle(conn, live, from).await?;
                tracing::info!("MQTT: primary host online; births published");
                Ok(())
            }
            (Verdict::OfflinePending, true) => {
                conn.wake_at(tokio::time::Instant::now() + OFFLINE_GRACE);
                Ok(())
            }
            (Verdict::Contradicted, _) => {
                status::status(&self.cell)
                    .metrics
                    .offline_contradicted
                    .inc();
                tracing::warn!(
                    "MQTT: an offline STATE on {topic} was contradicted by the host within {} s: \
                     another client of the broker published it; ignored (the broker's ACLs \
                     can keep it from happening: the user guide's MQTT chapter, \
                     \"Broker access control\")",
                    OFFLINE_GRACE.as_secs()
                );
                Ok(())
            }
            (Verdict::Restarted, true) => {
                tracing::info!(
                    "MQTT: the primary host started a new session; ending this one to send \
                     again what its last session may not have kept"
                );
                self.end_for_offline_host(conn).await
            }
            (Verdict::Restarted, false) => {
                let from = conn.forwarded();
                self.birth_cycle(conn, live, from).await?;
                tracing::info!("MQTT: primary host online; births published");
                Ok(())
            }
            (Verdict::FromTheFuture { ahead_ms }, _) => {
                status::status(&self.cell).metrics.state_refused.inc();
                if let Some(count) = self.state_refused.count(tokio::time::Instant::now()) {
                    tracing::warn!(
                        "MQTT: refused {count} STATE message(s) on {topic} since the last                          report; the latest is dated {:.0} s after this gateway's clock (at                          most {} s are taken): check both clocks (NTP), or another client                          of the broker is publishing on the host's topic",
                        ahead_ms as f64 / 1000.0,
                        STATE_SKEW_MS / 1000
                    );
                }
                Ok(())
            }
            _ => Ok(()),
        }
    }

    /// The grace after an offline STATE has passed: unless the host contradicted it, the
    /// session ends with an NDEATH that says the host is offline.
    async fn host_offline(&mut self, conn: &mut Connection<'_>) -> Done {
        if !self.host.offline_confirmed() || !self.born {
            return Ok(());
        }
        self.end_for_offline_host(conn).await
    }

    /// Ends the session because the primary host went offline (or started anew): the
    /// forwarded mark moves back by twice the keep-alive, and the goodbye is an NDEATH
    /// that says why.
    async fn end_for_offline_host(&mut self, conn: &mut Connection<'_>) -> Done {
        let window = duration_millis(self.keep_alive * 2);
        let now = Timestamp::now();
        let goodbye = self
            .node
            .host_offline_death(sparkplug_time(now))
            .map(|death| outgoing(death, None));
        conn.rewind_forwarded(Timestamp(now.0 - window)).await;
        Err(End::Again {
            why: "the primary host went offline; storing until it is back".to_owned(),
            goodbye,
        })
    }

    /// A refused node command: not a write, so logged with a throttle of its own and not
    /// counted as one.
    fn node_command_refused(&mut self, topic: &str, why: &str) {
        if let Some(count) = self.node_refused.count(tokio::time::Instant::now()) {
            tracing::warn!(
                "refused {count} MQTT node command(s) since the last report; the latest on \
                 {topic}: {why}"
            );
        }
    }

    /// Checks a DCMD's writes as one command and queues it whole for the node's write
    /// task, which carries commands out one after the other in the order they came (the
    /// audit records how each write ended); or refuses it whole: writes off, more metrics
    /// than `max_command_metrics`, a point named twice, a value one of its points refuses,
    /// or a full queue. A refusal is one (throttled) audit row, and nothing is written.
    async fn on_writes(&mut self, topic: &str, writes: Vec<(Option<Id>, MetricName, MetricValue)>) {
        let Some((Some(device), first, _)) = writes.first().cloned() else {
            let metric = writes
                .first()
                .map(|(_, m, _)| m.as_str())
                .unwrap_or_default();
            self.node_command_refused(
                topic,
                &format!("{metric}: the node has no writable metrics"),
            );
            return;
        };
        if !self.writes {
            self.refuse(topic, &device, first.as_str());
            return;
        }
        let command = match self.check_command(topic, &device, writes) {
            Ok(command) => command,
            Err(refusal) => return self.audit_refused_command(topic, refusal).await,
        };
        let queue = self.writer.get_or_insert_with(|| {
            let (queue, mut commands) = mpsc::channel::<CheckedCommand>(COMMANDS_WAITING);
            tokio::spawn(async move {
                while let Some(command) = commands.recv().await {
                    command.carry_out().await;
                }
            });
            queue
        });
        if let Err(refused) = queue.try_send(command) {
            let n = match refused {
                mpsc::error::TrySendError::Full(c) | mpsc::error::TrySendError::Closed(c) => {
                    c.writes.len()
                }
            };
            let why = format!(
                "{COMMANDS_WAITING} commands are waiting already; this one ({n} write(s)) was \
                 not carried out"
            );
            self.audit_refused_command(topic, Refusal::whole(why)).await;
        }
    }

    /// Every write of a DCMD against its point: all pass, or the command is refused.
    fn check_command(
        &self,
        topic: &str,
        device: &Id,
        writes: Vec<(Option<Id>, MetricName, MetricValue)>,
    ) -> Result<CheckedCommand, Refusal> {
        let n = writes.len();
        if n > self.max_command_metrics {
            return Err(Refusal::whole(format!(
                "{n} metrics in one command; at most {} are taken (max_command_metrics in \
                 [mqtt]): nothing was written",
                self.max_command_metrics
            )));
        }
        let nothing = if n > 1 {
            format!("; none of the command's {n} writes was carried out")
        } else {
            String::new()
        };
        let device_id = DeviceId::new(device.as_str())
            .map_err(|e| Refusal::whole(format!("device {device}: {e}")))?;
        let mut named = HashSet::with_capacity(n);
        let mut checked = Vec::with_capacity(n);
        for (_, metric, value) in writes {
            let refusal = |why: String, new: serde_json::Value| Refusal {
                why: format!("{why}{nothing}"),
                point: metric.as_str().to_owned(),
                new,
            };
            let value = value_of(value).map_err(|other| {
                refusal(
                    format!("{metric}: {other:?} is not a number"),
                    serde_json::Value::Null,
                )
            })?;
            let json = json_of(&value);
            if !named.insert(metric.clone()) {
                return Err(refusal(
                    format!("{metric} is named twice in one command"),
                    json,
                ));
            }
            let no_such = || format!("no such point {device}.{metric}");
            let Ok(point) = PointId::new(&device_id, metric.as_str()) else {
                return Err(refusal(no_such(), json));
            };
            let write = match self.cell.check_write(&point, &value) {
                Ok(write) => write,
                Err(WriteError::UnknownPoint { .. }) => return Err(refusal(no_such(), json)),
                Err(e) => return Err(refusal(e.to_string(), json)),
            };
            let attempt = Attempt::new(
                Arc::clone(&self.cell),
                format!("mqtt {topic}"),
                device.as_str(),
                metric.as_str(),
                json,
            );
            checked.push(Write { attempt, write });
        }
        Ok(CheckedCommand { writes: checked })
    }

    /// A command the node refused (undecodable, a value of the wrong type or out of
    /// range, an unknown metric, a retained or empty command, one of the refusals of
    /// [`Self::on_writes`]): counted, and when writes are on audited, at most one row per
    /// topic every [`LOG_EVERY`] saying how many it stands for; counted like any refused
    /// write when writes are off; an NCMD's refusal is logged, at most once every
    /// [`LOG_EVERY`].
    async fn audit_refused_command(&mut self, topic: &str, refusal: Refusal) {
        let Ok(Topic::Device {
            kind: MessageKind::Command,
            device,
            ..
        }) = topic.parse::<Topic>()
        else {
            self.node_command_refused(topic, &refusal.why);
            return;
        };
        tracing::debug!("MQTT: command on {topic} refused: {}", refusal.why);
        if !self.writes {
            self.refuse(topic, &device, "(refused command)");
            return;
        }
        status::status(&self.cell).metrics.commands_refused.inc();
        let Some(count) = self.refused_rows.count(topic, tokio::time::Instant::now()) else {
            return;
        };
        let why = match count {
            1 => refusal.why,
            n => format!(
                "{} ({} more command(s) refused on this topic since its last row are not \
                 recorded one by one)",
                refusal.why,
                n - 1
            ),
        };
        let attempt = Attempt::new(
            Arc::clone(&self.cell),
            format!("mqtt {topic}"),
            device.as_str(),
            refusal.point,
            refusal.new,
        );
        attempt.refuse(&why, None).await;
    }

    fn refuse(&mut self, topic: &str, device: &Id, metric: &str) {
        let now = tokio::time::Instant::now();
        let Some(count) = self.refused.refused(&self.cell, now) else {
            return;
        };
        tracing::warn!(
            "refused {count} MQTT write(s) in the last {} s; the latest: {device}.{metric} on \
             {topic}: DCMD writes need --allow-writes and commands = true in [mqtt]",
            LOG_EVERY.as_secs()
        );
    }
}

/// A Sparkplug message as the client's.
fn outgoing(message: Publish, latest: Option<Timestamp>) -> Outgoing {
    Outgoing {
        topic: message.topic.to_string(),
        payload: message.payload,
        qos: match message.qos {
            Qos::AtMostOnce => QoS::AtMostOnce,
            Qos::AtLeastOnce => QoS::AtLeastOnce,
        },
        retain: message.retain,
        latest,
    }
}

/// A gateway event as Sparkplug's: its kind's words and severity, and the point's name
/// within its device.
fn node_event(event: &Event) -> NodeEvent {
    NodeEvent {
        t: sparkplug_time(event.t),
        kind: event.kind.as_str().to_owned(),
        severity: event.kind.severity().into(),
        message: event.message.clone(),
        line: event.line.clone(),
        device: event.device.as_ref().map(|d| d.as_str().to_owned()),
        point: event.point.as_ref().map(|p| p.name().to_owned()),
        fields: (!event.fields.is_empty())
            .then(|| serde_json::to_string(&event.fields).unwrap_or_default()),
    }
}

fn history_rows(cell: &Cell) -> i64 {
    i64::try_from(cell.store().stats().rows_written()).unwrap_or(i64::MAX)
}

/// The node's own metrics in its NBIRTH (version, lines, history rows written, the event
/// channel), and the row count in it.
fn node_metrics(cell: &Cell, t: sparkplug::Timestamp) -> (Vec<(MetricSpec, Sample)>, i64) {
    let name = |n: &str| MetricName::new(n).expect("the node metric names are not empty");
    let rows = history_rows(cell);
    let lines = i64::try_from(cell.lines().len()).unwrap_or(i64::MAX);
    let metrics = vec![
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
        (
            sparkplug::event::spec(),
            Sample::good(MetricValue::String(String::new()), t),
        ),
    ];
    (metrics, rows)
}
