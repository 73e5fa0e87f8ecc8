//! The edge node's side of Sparkplug B as a sans-IO state machine: it builds every
//! message the node sends and reads the commands it receives, and keeps the rules
//! that make a host trust the stream. No MQTT, no clock: the caller publishes what
//! it returns and passes time in.
//!
//! One connection, in order:
//! 1. [`EdgeNode::next_bd_seq`] — persist it before connecting, so a restart never
//!    reuses the `bdSeq` of a Will the broker may still hold.
//! 2. [`EdgeNode::will`] — the NDEATH to register as the MQTT Will (QoS 1).
//! 3. Connect; on the CONNACK call [`EdgeNode::on_connect`]: `seq` starts again and
//!    the Will's `bdSeq` is the session's; the next connection will use the one after.
//! 4. [`EdgeNode::node_birth`] (seq 0, the session's `bdSeq`, `Node Control/Rebirth`),
//!    then [`EdgeNode::device_birth`] for each device.
//! 5. [`EdgeNode::node_data`], [`EdgeNode::device_data`], [`EdgeNode::device_death`];
//!    [`EdgeNode::handle_command`] for what arrives on [`EdgeNode::command_filters`].
//!    A [`Command::Rebirth`] means: steps 4 again. [`EdgeNode::node_event`] publishes a
//!    gateway event as an NDATA ([`crate::event`]).
//!
//! Rules kept here:
//! - `seq` is one counter for all the node's messages (NBIRTH, NDATA, DBIRTH, DDATA,
//!   DDEATH), 0–255 wrapping. Every NBIRTH has seq 0 (after a connect and after a
//!   rebirth): the reading of the spec every host accepts.
//! - `bdSeq` (0–255 wrapping) is fixed per connection: the Will's, then the NBIRTH's.
//!   The NDEATH carries no `seq`.
//! - Aliases are unique across the node and all its devices, assigned 1, 2, 3… in the
//!   order metrics first appear in a birth, and kept for the life of the `EdgeNode`,
//!   so a rebirth gives a metric the same alias. 0 is never used (a proto2 reader may
//!   take an absent alias for 0). `bdSeq` has no alias.
//! - Data messages name metrics by alias only and carry only readings that changed
//!   since the last one sent (historical data is sent as given and does not count as
//!   the last reading). A stale or bad reading is `is_null` with a `Quality` property;
//!   the first good reading after one carries `Quality` 192, so a host clears it.

use std::collections::HashMap;

use prost::Message as _;

use crate::event::{EVENT, NodeEvent};
use crate::metric::{
    DataType, MetricName, MetricSpec, MetricValue, Quality, Reading, Sample, Timestamp, ValueError,
    Writable, birth_metric, data_metric,
};
use crate::proto::{Metric, Payload, metric};
use crate::topic::{Id, MessageKind, Topic, TopicError};

/// The name of the birth/death sequence metric in NBIRTH and NDEATH.
pub const BD_SEQ: &str = "bdSeq";
/// The name of the node metric a host sets to true to ask for a rebirth.
pub const REBIRTH: &str = "Node Control/Rebirth";
/// A Boolean metric, true, in an NDEATH the node publishes itself because its primary
/// host went offline ([`EdgeNode::host_offline_death`]): the node is alive and stores
/// what it reads until the host is back, so a host that reads this death does not mark
/// the node's points bad. cellbus's own convention; other hosts read only the `bdSeq`.
pub const HOST_OFFLINE: &str = "Node Control/Host Offline";

/// MQTT quality of service, as much as Sparkplug uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Qos {
    /// QoS 0: births and data.
    AtMostOnce,
    /// QoS 1: NDEATH (the Will) and STATE.
    AtLeastOnce,
}

/// One MQTT message to publish, as plain data.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Publish {
    /// Where.
    pub topic: Topic,
    /// The encoded payload.
    pub payload: Vec<u8>,
    /// With which QoS.
    pub qos: Qos,
    /// Whether the broker keeps it for later subscribers.
    pub retain: bool,
}

/// The birth/death sequence number, 0–255 wrapping.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct BdSeq(u8);

impl BdSeq {
    /// The number `n`.
    pub const fn new(n: u8) -> Self {
        Self(n)
    }

    /// The number.
    pub const fn value(self) -> u8 {
        self.0
    }

    /// The one after, 255 → 0.
    #[must_use]
    pub const fn next(self) -> Self {
        Self(self.0.wrapping_add(1))
    }
}

/// Whether data is live or was stored while the host was away.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Delivery {
    /// Current readings.
    Live,
    /// Readings stored during an outage, sent with `is_historical` and their own
    /// timestamps.
    Historical,
}

/// What a host asked for.
#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    /// Publish NBIRTH and every DBIRTH again.
    Rebirth,
    /// Write a metric of the node (`device: None`) or of a device.
    Write {
        /// The device, or `None` for the node itself.
        device: Option<Id>,
        /// The metric, by name whether the host used its name or its alias.
        metric: MetricName,
        /// The value, of the metric's type and within its write range.
        value: MetricValue,
    },
}

/// A message the caller asked for cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NodeError {
    /// Births and data need a connection: call `on_connect` first.
    #[error("not connected: call on_connect after the CONNACK")]
    NotConnected,
    /// Device messages and node data need an NBIRTH in this session.
    #[error("the node has no NBIRTH in this session")]
    NodeNotBorn,
    /// Data or death for a device without a DBIRTH since the last NBIRTH.
    #[error("device {device} has no DBIRTH since the last NBIRTH")]
    DeviceNotBorn {
        /// The device.
        device: Id,
    },
    /// A metric the birth did not describe.
    #[error("{} has no metric {name:?} in its birth", owner(.device))]
    UnknownMetric {
        /// The device, or `None` for the node.
        device: Option<Id>,
        /// The name asked for.
        name: String,
    },
    /// A birth names a metric twice.
    #[error("the birth names metric {name} twice")]
    DuplicateMetric {
        /// The name.
        name: MetricName,
    },
    /// A node metric uses a name this crate reserves.
    #[error("{name} is a name the edge node reserves ({BD_SEQ}, {REBIRTH})")]
    ReservedName {
        /// The name.
        name: MetricName,
    },
    /// A value's type is not the metric's.
    #[error("metric {metric} is {expected}, the value is {got}")]
    DataTypeMismatch {
        /// The metric.
        metric: MetricName,
        /// Its type.
        expected: DataType,
        /// The value's type.
        got: DataType,
    },
}

fn owner(device: &Option<Id>) -> String {
    match device {
        Some(d) => format!("device {d}"),
        None => "the node".to_owned(),
    }
}

/// A received command is refused; nothing of it is to be carried out.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CommandError {
    /// The topic is not a Sparkplug topic.
    #[error(transparent)]
    Topic(#[from] TopicError),
    /// The topic is not NCMD or DCMD.
    #[error("{topic} is not a command topic (NCMD or DCMD)")]
    NotACommand {
        /// The topic as received.
        topic: String,
    },
    /// The command is for another edge node.
    #[error("{topic} is for another edge node than {group}/{edge_node}")]
    OtherNode {
        /// The topic as received.
        topic: String,
        /// Our group.
        group: Id,
        /// Our edge node.
        edge_node: Id,
    },
    /// The payload is not a Sparkplug protobuf payload, or carries more metrics than
    /// [`crate::proto::MAX_METRICS`].
    #[error(transparent)]
    Payload(#[from] crate::proto::PayloadError),
    /// An NCMD came before the NBIRTH.
    #[error("an NCMD came before this session's NBIRTH")]
    NodeNotBorn,
    /// A DCMD for a device without a DBIRTH.
    #[error("no device {device} has been born on this node")]
    UnknownDevice {
        /// The device.
        device: Id,
    },
    /// An alias no birth assigned to this node or device.
    #[error("{} has no metric with alias {alias}", owner(.device))]
    UnknownAlias {
        /// The device, or `None` for the node.
        device: Option<Id>,
        /// The alias.
        alias: u64,
    },
    /// A name no birth described for this node or device.
    #[error("{} has no metric {name:?}", owner(.device))]
    UnknownMetric {
        /// The device, or `None` for the node.
        device: Option<Id>,
        /// The name.
        name: String,
    },
    /// A metric with neither name nor alias.
    #[error("metric {index} of the command has neither name nor alias")]
    NoMetricId {
        /// Its place in the payload, from 0.
        index: usize,
    },
    /// The command states another data type than the birth.
    #[error("metric {metric} is {expected}, the command says datatype {got}")]
    DataTypeMismatch {
        /// The metric.
        metric: MetricName,
        /// Its type from the birth.
        expected: DataType,
        /// The code the command gave.
        got: u32,
    },
    /// The value cannot be read as the metric's type.
    #[error("metric {metric}: {error}")]
    Value {
        /// The metric.
        metric: MetricName,
        /// What is wrong with the value.
        error: ValueError,
    },
    /// A command to set a metric to null.
    #[error("metric {metric}: a command cannot write null")]
    NullValue {
        /// The metric.
        metric: MetricName,
    },
    /// The metric is read only.
    #[error("metric {metric} is read only")]
    NotWritable {
        /// The metric.
        metric: MetricName,
    },
    /// The value is outside the metric's write range.
    #[error("metric {metric}: {value} is outside {min}..={max}")]
    OutOfRange {
        /// The metric.
        metric: MetricName,
        /// The value asked for.
        value: f64,
        /// The lowest allowed.
        min: f64,
        /// The highest allowed.
        max: f64,
    },
}

/// An edge node's Sparkplug state: ids, `bdSeq`, `seq`, and what its births said.
#[derive(Debug)]
pub struct EdgeNode {
    group: Id,
    edge_node: Id,
    /// The `bdSeq` of the next connection's Will.
    bd_seq: BdSeq,
    /// The `bdSeq` of the current connection, once connected.
    session: Option<BdSeq>,
    /// The `seq` of the next message.
    seq: u8,
    aliases: HashMap<(Option<Id>, MetricName), u64>,
    next_alias: u64,
    /// The node's metrics from this session's NBIRTH.
    node: Option<Table>,
    /// Devices born since the last NBIRTH.
    devices: HashMap<Id, Table>,
}

/// The metrics of one birth: about 150 bytes each (a million metrics of a large plant
/// take 150 MB), so what is kept is what data and commands are checked against.
#[derive(Debug, Default)]
struct Table {
    /// In the order of their aliases.
    entries: Vec<Entry>,
    /// Each metric's place in `entries`.
    by_name: HashMap<MetricName, usize>,
}

#[derive(Debug)]
struct Entry {
    alias: u64,
    name: MetricName,
    datatype: DataType,
    writable: Writable,
    /// The last live reading sent.
    last: Reading,
}

impl Table {
    /// The metric named `name`.
    fn named(&self, name: &str) -> Option<&Entry> {
        let &at = self.by_name.get(name)?;
        self.entries.get(at)
    }

    /// The metric of `alias`.
    fn aliased(&self, alias: u64) -> Option<&Entry> {
        let at = self
            .entries
            .binary_search_by_key(&alias, |e| e.alias)
            .ok()?;
        self.entries.get(at)
    }
}

impl EdgeNode {
    /// The edge node `edge_node` of `group`, whose next connection uses `bd_seq`
    /// (kept on disk by the caller).
    pub fn new(group: Id, edge_node: Id, bd_seq: BdSeq) -> Self {
        Self {
            group,
            edge_node,
            bd_seq,
            session: None,
            seq: 0,
            aliases: HashMap::new(),
            next_alias: 1,
            node: None,
            devices: HashMap::new(),
        }
    }

    /// The group id.
    pub fn group(&self) -> &Id {
        &self.group
    }

    /// The edge node id.
    pub fn edge_node(&self) -> &Id {
        &self.edge_node
    }

    /// The `bdSeq` the next connection's Will carries.
    pub fn bd_seq(&self) -> BdSeq {
        self.bd_seq
    }

    /// The `bdSeq` to persist before connecting with [`Self::bd_seq`]: after a restart
    /// the node starts from it and never repeats a Will the broker may still hold.
    pub fn next_bd_seq(&self) -> BdSeq {
        self.bd_seq.next()
    }

    /// The `seq` the next message will carry.
    pub fn seq(&self) -> u8 {
        self.seq
    }

    /// The topic filters to subscribe to (NCMD, and DCMD for every device), again
    /// after every reconnect.
    pub fn command_filters(&self) -> [String; 2] {
        let (g, n) = (&self.group, &self.edge_node);
        [
            format!("{}/{g}/NCMD/{n}", crate::topic::NAMESPACE),
            format!("{}/{g}/DCMD/{n}/+", crate::topic::NAMESPACE),
        ]
    }

    /// The NDEATH to register as the MQTT Will of the next connection: a `bdSeq`
    /// (Int64) metric and nothing else; QoS 1, not retained.
    pub fn will(&self) -> Publish {
        self.death(Payload {
            metrics: vec![bd_seq_metric(self.bd_seq)],
            ..Payload::default()
        })
    }

    /// An NDEATH of `payload`: QoS 1, not retained.
    fn death(&self, payload: Payload) -> Publish {
        Publish {
            topic: self.node_topic(MessageKind::Death),
            payload: payload.encode_to_vec(),
            qos: Qos::AtLeastOnce,
            retain: false,
        }
    }

    /// The NDEATH to publish before a clean disconnect because the primary host went
    /// offline: the session's `bdSeq`, [`HOST_OFFLINE`] = true and the payload time `now`;
    /// QoS 1, not retained. `None` when not connected.
    pub fn host_offline_death(&self, now: Timestamp) -> Option<Publish> {
        let bd_seq = self.session?;
        let payload = Payload {
            timestamp: Some(now.as_millis()),
            metrics: vec![
                bd_seq_metric(bd_seq),
                Metric {
                    name: Some(HOST_OFFLINE.to_owned()),
                    datatype: Some(DataType::Boolean.code()),
                    value: Some(metric::Value::BooleanValue(true)),
                    ..Metric::default()
                },
            ],
            ..Payload::default()
        };
        Some(self.death(payload))
    }

    /// The connection is up (CONNACK): the Will's `bdSeq` becomes the session's and the
    /// next connection will use the one after; `seq` starts at 0; nothing is born yet.
    pub fn on_connect(&mut self) {
        self.session = Some(self.bd_seq);
        self.bd_seq = self.bd_seq.next();
        self.seq = 0;
        self.node = None;
        self.devices.clear();
    }

    /// The connection is gone: the broker has published the Will.
    pub fn on_disconnect(&mut self) {
        self.session = None;
        self.node = None;
        self.devices.clear();
    }

    /// The NBIRTH: seq 0, the session's `bdSeq`, `Node Control/Rebirth` (false) and
    /// `node_metrics` with their current readings. Every device must be born again.
    pub fn node_birth(
        &mut self,
        node_metrics: &[(MetricSpec, Sample)],
        now: Timestamp,
    ) -> Result<Publish, NodeError> {
        let bd_seq = self.session.ok_or(NodeError::NotConnected)?;
        for (spec, _) in node_metrics {
            if [BD_SEQ, REBIRTH].contains(&spec.name.as_str()) {
                return Err(NodeError::ReservedName {
                    name: spec.name.clone(),
                });
            }
        }
        let rebirth = (
            MetricSpec::new(reserved(REBIRTH), DataType::Boolean).writable(Writable::Yes),
            Sample::good(MetricValue::Boolean(false), now),
        );
        let specs: Vec<&(MetricSpec, Sample)> =
            std::iter::once(&rebirth).chain(node_metrics).collect();
        let (table, mut metrics) = self.birth_table(None, &specs)?;
        metrics.insert(0, bd_seq_metric(bd_seq));
        self.seq = 0;
        self.node = Some(table);
        self.devices.clear();
        Ok(self.message(self.node_topic(MessageKind::Birth), metrics, now))
    }

    /// A DBIRTH: every metric of `device` with its current reading.
    pub fn device_birth(
        &mut self,
        device: &Id,
        metrics: &[(MetricSpec, Sample)],
        now: Timestamp,
    ) -> Result<Publish, NodeError> {
        self.born()?;
        let specs: Vec<&(MetricSpec, Sample)> = metrics.iter().collect();
        let (table, metrics) = self.birth_table(Some(device), &specs)?;
        self.devices.insert(device.clone(), table);
        Ok(self.message(self.device_topic(MessageKind::Birth, device), metrics, now))
    }

    /// An NDATA with the node metrics in `changes` that changed, or `None` when none did.
    pub fn node_data<N: AsRef<str>>(
        &mut self,
        changes: &[(N, Sample)],
        now: Timestamp,
        delivery: Delivery,
    ) -> Result<Option<Publish>, NodeError> {
        self.born()?;
        let table = self.node.as_mut().ok_or(NodeError::NodeNotBorn)?;
        let metrics = data(table, None, changes, delivery)?;
        let topic = self.node_topic(MessageKind::Data);
        Ok((!metrics.is_empty()).then(|| self.message(topic, metrics, now)))
    }

    /// A DDATA with the metrics of `device` in `changes` that changed, by alias only, or
    /// `None` when none did. Nothing is recorded when an error is returned.
    pub fn device_data<N: AsRef<str>>(
        &mut self,
        device: &Id,
        changes: &[(N, Sample)],
        now: Timestamp,
        delivery: Delivery,
    ) -> Result<Option<Publish>, NodeError> {
        self.born()?;
        let table = self
            .devices
            .get_mut(device)
            .ok_or_else(|| NodeError::DeviceNotBorn {
                device: device.clone(),
            })?;
        let metrics = data(table, Some(device), changes, delivery)?;
        let topic = self.device_topic(MessageKind::Data, device);
        Ok((!metrics.is_empty()).then(|| self.message(topic, metrics, now)))
    }

    /// A DDEATH: `device` is gone until its next DBIRTH.
    pub fn device_death(&mut self, device: &Id, now: Timestamp) -> Result<Publish, NodeError> {
        self.born()?;
        if self.devices.remove(device).is_none() {
            return Err(NodeError::DeviceNotBorn {
                device: device.clone(),
            });
        }
        Ok(self.message(self.device_topic(MessageKind::Death, device), vec![], now))
    }

    /// An NDATA carrying `event` as the node's [`EVENT`] metric
    /// (see [`crate::event`]); the NBIRTH must have described that metric
    /// ([`crate::event::spec`]). Every event is sent, equal or not to the one before.
    pub fn node_event(&mut self, event: &NodeEvent, now: Timestamp) -> Result<Publish, NodeError> {
        self.born()?;
        let table = self.node.as_ref().ok_or(NodeError::NodeNotBorn)?;
        let alias =
            table
                .named(EVENT)
                .map(|e| e.alias)
                .ok_or_else(|| NodeError::UnknownMetric {
                    device: None,
                    name: EVENT.to_owned(),
                })?;
        let metrics = vec![crate::event::metric(alias, event)];
        Ok(self.message(self.node_topic(MessageKind::Data), metrics, now))
    }

    /// Reads an NCMD or DCMD for this node. Every metric is checked against the birth
    /// (alias or name, type, writability, range) before anything is returned: one bad
    /// metric refuses the whole command. `Node Control/Rebirth` set to false is no
    /// command.
    pub fn handle_command(
        &self,
        topic: &str,
        payload: &[u8],
    ) -> Result<Vec<Command>, CommandError> {
        let text = topic;
        let topic: Topic = topic.parse()?;
        let (group, edge_node, device) = match &topic {
            Topic::Node {
                group,
                kind: MessageKind::Command,
                edge_node,
            } => (group, edge_node, None),
            Topic::Device {
                group,
                kind: MessageKind::Command,
                edge_node,
                device,
            } => (group, edge_node, Some(device)),
            _ => {
                return Err(CommandError::NotACommand {
                    topic: text.to_owned(),
                });
            }
        };
        if *group != self.group || *edge_node != self.edge_node {
            return Err(CommandError::OtherNode {
                topic: text.to_owned(),
                group: self.group.clone(),
                edge_node: self.edge_node.clone(),
            });
        }
        let device = device.cloned();
        let table = match &device {
            None => self.node.as_ref().ok_or(CommandError::NodeNotBorn)?,
            Some(d) => self
                .devices
                .get(d)
                .ok_or_else(|| CommandError::UnknownDevice { device: d.clone() })?,
        };
        let payload = crate::proto::decode_payload(payload)?;
        let mut commands = Vec::new();
        for (index, m) in payload.metrics.iter().enumerate() {
            let entry = lookup(table, &device, index, m)?;
            let metric_name = entry.name.clone();
            if m.is_null == Some(true) {
                return Err(CommandError::NullValue {
                    metric: metric_name,
                });
            }
            let expected = entry.datatype;
            if let Some(got) = m.datatype.filter(|&code| code != expected.code()) {
                return Err(CommandError::DataTypeMismatch {
                    metric: metric_name,
                    expected,
                    got,
                });
            }
            let value = MetricValue::from_proto(expected, m.value.as_ref()).map_err(|error| {
                CommandError::Value {
                    metric: metric_name.clone(),
                    error,
                }
            })?;
            if device.is_none() && metric_name.as_str() == REBIRTH {
                if value == MetricValue::Boolean(true) {
                    commands.push(Command::Rebirth);
                }
                continue;
            }
            check_writable(&entry.name, entry.writable, &value)?;
            commands.push(Command::Write {
                device: device.clone(),
                metric: metric_name,
                value,
            });
        }
        Ok(commands)
    }

    fn born(&self) -> Result<(), NodeError> {
        match (&self.session, &self.node) {
            (None, _) => Err(NodeError::NotConnected),
            (Some(_), None) => Err(NodeError::NodeNotBorn),
            (Some(_), Some(_)) => Ok(()),
        }
    }

    /// The table and birth metrics for `specs`, assigning aliases as needed.
    fn birth_table(
        &mut self,
        device: Option<&Id>,
        specs: &[&(MetricSpec, Sample)],
    ) -> Result<(Table, Vec<Metric>), NodeError> {
        let mut table = Table::default();
        for (spec, sample) in specs {
            if table.by_name.contains_key(&spec.name) {
                return Err(NodeError::DuplicateMetric {
                    name: spec.name.clone(),
                });
            }
            check_type(&spec.name, spec.datatype, sample)?;
            table.by_name.insert(spec.name.clone(), 0);
        }
        table.by_name.clear();
        let mut metrics = Vec::with_capacity(specs.len());
        table.entries.reserve_exact(specs.len());
        for (spec, sample) in specs {
            let alias = self.alias(device, &spec.name);
            metrics.push(birth_metric(spec, Some(alias), sample));
            // What data and commands are checked against; the unit and the description
            // went out with the birth.
            table.entries.push(Entry {
                alias,
                name: spec.name.clone(),
                datatype: spec.datatype,
                writable: spec.writable,
                last: sample.reading.clone(),
            });
        }
        table.entries.sort_unstable_by_key(|e| e.alias);
        for (at, entry) in table.entries.iter().enumerate() {
            table.by_name.insert(entry.name.clone(), at);
        }
        Ok((table, metrics))
    }

    fn alias(&mut self, device: Option<&Id>, name: &MetricName) -> u64 {
        let key = (device.cloned(), name.clone());
        if let Some(&alias) = self.aliases.get(&key) {
            return alias;
        }
        let alias = self.next_alias;
        self.next_alias += 1;
        self.aliases.insert(key, alias);
        alias
    }

    /// A birth, data or death payload with the next `seq`.
    fn message(&mut self, topic: Topic, metrics: Vec<Metric>, now: Timestamp) -> Publish {
        let seq = self.seq;
        self.seq = self.seq.wrapping_add(1);
        let payload = Payload {
            timestamp: Some(now.as_millis()),
            metrics,
            seq: Some(seq.into()),
            ..Payload::default()
        };
        Publish {
            topic,
            payload: payload.encode_to_vec(),
            qos: Qos::AtMostOnce,
            retain: false,
        }
    }

    fn node_topic(&self, kind: MessageKind) -> Topic {
        Topic::Node {
            group: self.group.clone(),
            kind,
            edge_node: self.edge_node.clone(),
        }
    }

    fn device_topic(&self, kind: MessageKind, device: &Id) -> Topic {
        Topic::Device {
            group: self.group.clone(),
            kind,
            edge_node: self.edge_node.clone(),
            device: device.clone(),
        }
    }
}

/// The NCMD payload a host sends to ask a node for its births again: the metric
/// `Node Control/Rebirth` (Boolean) set to true, timestamped `now`.
pub fn rebirth_payload(now: Timestamp) -> Vec<u8> {
    Payload {
        timestamp: Some(now.as_millis()),
        metrics: vec![Metric {
            name: Some(REBIRTH.to_owned()),
            datatype: Some(DataType::Boolean.code()),
            value: Some(metric::Value::BooleanValue(true)),
            ..Metric::default()
        }],
        ..Payload::default()
    }
    .encode_to_vec()
}

/// The NCMD that asks `edge_node` of `group` for a rebirth: QoS 0, not retained.
pub fn rebirth_request(group: &Id, edge_node: &Id, now: Timestamp) -> Publish {
    Publish {
        topic: Topic::Node {
            group: group.clone(),
            kind: MessageKind::Command,
            edge_node: edge_node.clone(),
        },
        payload: rebirth_payload(now),
        qos: Qos::AtMostOnce,
        retain: false,
    }
}

fn reserved(name: &str) -> MetricName {
    MetricName::new(name).expect("the reserved names are not empty")
}

fn bd_seq_metric(bd_seq: BdSeq) -> Metric {
    Metric {
        name: Some(BD_SEQ.to_owned()),
        datatype: Some(DataType::Int64.code()),
        value: Some(metric::Value::LongValue(bd_seq.value().into())),
        ..Metric::default()
    }
}

fn check_type(name: &MetricName, datatype: DataType, sample: &Sample) -> Result<(), NodeError> {
    match sample.reading.value() {
        Some(v) if v.datatype() != datatype => Err(NodeError::DataTypeMismatch {
            metric: name.clone(),
            expected: datatype,
            got: v.datatype(),
        }),
        _ => Ok(()),
    }
}

/// The data metrics for `changes`; records them as the last readings only when all
/// are valid.
fn data<N: AsRef<str>>(
    table: &mut Table,
    device: Option<&Id>,
    changes: &[(N, Sample)],
    delivery: Delivery,
) -> Result<Vec<Metric>, NodeError> {
    let historical = delivery == Delivery::Historical;
    let mut metrics = Vec::new();
    let mut updates = Vec::new();
    for (name, sample) in changes {
        let name = name.as_ref();
        let at = table
            .by_name
            .get(name)
            .copied()
            .ok_or_else(|| NodeError::UnknownMetric {
                device: device.cloned(),
                name: name.to_owned(),
            })?;
        let entry = &table.entries[at];
        let alias = entry.alias;
        check_type(&entry.name, entry.datatype, sample)?;
        if historical {
            metrics.push(data_metric(alias, sample, false, true));
            continue;
        }
        if entry.last == sample.reading {
            continue;
        }
        let recovered =
            sample.reading.quality() == Quality::Good && entry.last.quality() != Quality::Good;
        metrics.push(data_metric(alias, sample, recovered, false));
        updates.push((at, sample.reading.clone()));
    }
    for (at, reading) in updates {
        if let Some(entry) = table.entries.get_mut(at) {
            entry.last = reading;
        }
    }
    Ok(metrics)
}

fn lookup<'t>(
    table: &'t Table,
    device: &Option<Id>,
    index: usize,
    m: &Metric,
) -> Result<&'t Entry, CommandError> {
    match (m.alias, &m.name) {
        (Some(alias), _) => table
            .aliased(alias)
            .ok_or_else(|| CommandError::UnknownAlias {
                device: device.clone(),
                alias,
            }),
        (None, Some(name)) => table
            .named(name)
            .ok_or_else(|| CommandError::UnknownMetric {
                device: device.clone(),
                name: name.clone(),
            }),
        (None, None) => Err(CommandError::NoMetricId { index }),
    }
}

fn check_writable(
    name: &MetricName,
    writable: Writable,
    value: &MetricValue,
) -> Result<(), CommandError> {
    match writable {
        Writable::No => Err(CommandError::NotWritable {
            metric: name.clone(),
        }),
        Writable::Yes => Ok(()),
        Writable::Within(range) => match value.as_f64() {
            Some(v) if range.contains(v) => Ok(()),
            Some(v) => Err(CommandError::OutOfRange {
                metric: name.clone(),
                value: v,
                min: range.min(),
                max: range.max(),
            }),
            None => Ok(()),
        },
    }
}
