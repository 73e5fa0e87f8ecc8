//! The host application's side of Sparkplug B 3.0 as a sans-IO state machine: it reads
//! what edge nodes publish and says what to record (points, samples, events), what to
//! send back (Rebirth requests) and what was wrong. No MQTT, no clock: the caller
//! subscribes to [`Host::subscriptions`], publishes [`Host::will`] /
//! [`Host::state_online`], feeds every received message to [`Host::receive`] with the
//! time it arrived, and publishes the [`Received::commands`].
//!
//! Per edge node (group and node id) the host keeps what its NBIRTH and DBIRTHs said:
//! each metric's name, alias and datatype, and the `bdSeq` and last `seq`.
//!
//! - **Births** (NBIRTH, DBIRTH) describe the points ([`PointInfo`]: datatype, unit,
//!   description, write range) and give their current values as samples. An NBIRTH
//!   forgets the node's devices (they are born again after it). `bdSeq`,
//!   `Node Control/*` and the [`EVENT`] metric are not points.
//!   A metric of a datatype this crate does not read (DataSet, Template, arrays) is
//!   reported once at its birth and its data is ignored.
//! - **Data** (NDATA, DDATA) by alias or name become samples of the born points;
//!   `is_transient` metrics are not recorded (the spec's meaning); a node's `Event`
//!   metric becomes a [`HostEvent`] ([`crate::event`]).
//! - **Deaths**: an NDEATH whose `bdSeq` is the current NBIRTH's marks every point of
//!   the node and of its devices Bad (a null sample) at the death's time (the payload's
//!   timestamp, else the arrival time); an NDEATH with another `bdSeq` is the Will of an
//!   older session, delivered late, and is ignored (a [`Problem::StaleDeath`]). An NDEATH
//!   that carries [`HOST_OFFLINE`] = true (the node ended its session because its primary
//!   host went offline, and stores what it reads until the host is back) marks them
//!   Stale instead: the node kept reading, and what it stored follows. A DDEATH marks its
//!   device's points Bad. After a death the node or device is unborn again.
//! - **Rebirth requests** (NCMD `Node Control/Rebirth` = true, [`rebirth_request`]):
//!   when data, a DBIRTH or a DDEATH comes from a node whose NBIRTH was not seen (or that
//!   died since), data from a device without a DBIRTH, a metric whose alias or name no
//!   birth gave, or (alone only) a `seq` gap. At most one per node every
//!   [`REBIRTH_HOLD_OFF_MS`] (5 s) until its NBIRTH arrives; after a birth refused for a
//!   limit, one every [`REFUSED_REBIRTH_HOLD_OFF_MS`] (5 min). What cannot be resolved is
//!   dropped and counted ([`Stats::dropped`]).
//! - **Limits** ([`Limits`]): what a rogue client can make the host keep is bounded. A
//!   birth that would make more edge nodes than [`Limits::max_nodes`], more metrics in the
//!   node's current births than [`Limits::max_node_points`], or more in all current births
//!   than [`Limits::max_points`] is refused whole ([`Problem::BirthRefused`], counted in
//!   [`Stats::births_refused`]): the node or device stays unborn. Every metric of a birth
//!   counts, points or not. Ids (group, node, device) and birth metric names longer than
//!   [`crate::topic::MAX_NAME_BYTES`] or holding control or bidirectional formatting
//!   characters are refused: a topic with such an id is not read ([`Problem::Topic`]), a
//!   birth metric with such a name is left out ([`Problem::BadMetricName`]) and its data
//!   is dropped without a Rebirth request. A node dead (or never born) for
//!   [`DEAD_NODE_GRACE_MS`] (10 min) is forgotten, looked for at most once a minute as
//!   messages arrive: a churn of made-up node names keeps nothing for long.
//! - **`seq`**: every message of a node after its NBIRTH (NDATA, DBIRTH, DDATA, DDEATH)
//!   carries the previous one's `seq` + 1, 0–255 wrapping, across the node and all its
//!   devices; a gap means messages were lost. The data of the message that shows the
//!   gap is still recorded.
//! - **Samples**: `t` is the metric's timestamp, else the payload's, else the arrival
//!   time; booleans, integers, floats and DateTimes (ms) are numbers (64-bit integers
//!   beyond 2^53 lose precision), String and Text are text. Quality: the `Quality`
//!   property (192 good, 500 stale, 0 bad) when it has one of these codes; otherwise
//!   Good with a value, Bad without one. A null value is never Good.
//!
//! **Shared subscriptions** ([`Sharing::Shared`]): several hosts share the data of the
//! same nodes through `$share/{name}/…`. Births and deaths are subscribed unshared, so
//! every host knows every metric's alias and marks deaths, and data shared, so each data
//! message reaches one of them. Consequences: each host sees only part of a node's
//! `seq` sequence, so **seq checking is off** in shared mode (a lost data message is not
//! noticed); births' and deaths' samples come to every host (the store must take a
//! sample it already has — same point and time — without a second row); each host asks
//! for rebirths on its own, so a node may get one per host.
//!
//! Sparkplug 3.0 STATE: publish [`Host::will`] as the MQTT Will and, once connected,
//! [`Host::state_online`] with the **same** `now`, so a node can tell this session's
//! Will from an older one's. Then subscribe to [`Host::state_subscription`] (the host's
//! own STATE topic): any client can publish a retained `online:false` there, and edge
//! nodes would stay away until the host restarted. Every STATE read there that is not
//! `online` is answered with [`Host::reassert_online`].

use std::collections::HashMap;
use std::sync::Arc;

use crate::births::Table;
use crate::event::{self, EVENT};
use crate::metric::{
    DOCUMENTATION, DataType, ENG_UNIT, MetricName, MetricValue, NameError, Quality, Timestamp,
    ValueError, WRITABLE, WRITE_MAX, WRITE_MIN, Writable, WriteRange, read,
};
use crate::node::{BD_SEQ, HOST_OFFLINE, Publish, Qos, rebirth_request};
use crate::proto::{Metric, Payload, metric};
use crate::state::HostState;
use crate::topic::{Id, MessageKind, NAMESPACE, Topic, TopicError};

/// The least time between two Rebirth requests to one node, until its NBIRTH arrives.
pub const REBIRTH_HOLD_OFF_MS: u64 = 5_000;
/// The least time between two Rebirth requests to a node whose last birth was refused for
/// a limit (5 min): its births would be refused again, and each costs the node a rebirth
/// and the broker the whole birth.
pub const REFUSED_REBIRTH_HOLD_OFF_MS: u64 = 300_000;
/// How long a node stays known once dead or unborn (10 min): a late message of its last
/// session is still read as before, and then its state is freed.
pub const DEAD_NODE_GRACE_MS: u64 = 600_000;
/// How often the host looks for nodes to forget, at most (1 min, as messages arrive).
const SWEEP_EVERY_MS: u64 = 60_000;

/// What a rogue or broken client can make the host keep; births past them are refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Most edge nodes known at once (born, or dead or unborn for less than
    /// [`DEAD_NODE_GRACE_MS`]).
    pub max_nodes: usize,
    /// Most metrics in one edge node's current births: its NBIRTH's and all its DBIRTHs'.
    pub max_node_points: usize,
    /// Most metrics in the current births of all nodes.
    pub max_points: usize,
}

impl Default for Limits {
    /// 1,000 edge nodes, 100,000 metrics per node (a large plant gateway), 250,000 in all.
    fn default() -> Self {
        Self {
            max_nodes: 1_000,
            max_node_points: 100_000,
            max_points: 250_000,
        }
    }
}

/// Which of the [`Limits`] a refused birth would have passed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cap {
    /// [`Limits::max_nodes`]: a new edge node while as many are known.
    Nodes,
    /// [`Limits::max_node_points`]: the metrics of the node's current births.
    NodePoints,
    /// [`Limits::max_points`]: the metrics of all current births.
    Points,
}

/// The folder of node metrics that control the node and are not points.
const NODE_CONTROL: &str = "Node Control/";

/// Whether the host takes all the data of its nodes or shares it with other hosts.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Sharing {
    /// The only host: it receives every message and checks `seq`.
    Alone,
    /// One of several hosts that share data messages through the MQTT shared
    /// subscription `$share/{name}/…` (births and deaths unshared); `seq` is not
    /// checked.
    Shared {
        /// The share's name (without `/`, `+`, `#`).
        name: Id,
    },
}

/// A topic filter to subscribe to, with its QoS.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Subscription {
    /// The MQTT topic filter.
    pub filter: String,
    /// QoS 1 for births and deaths (the NDEATH Will is QoS 1), 0 for data.
    pub qos: Qos,
}

/// Whose points: an edge node's own (`device: None`) or one of its devices'. One per
/// birth, shared by all its points.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct PointOwner {
    /// The group id.
    pub group: Id,
    /// The edge node id.
    pub node: Id,
    /// The device id, `None` for the node's own metrics.
    pub device: Option<Id>,
}

/// Which point: a metric of a node or of one of its devices. Small (a shared owner and
/// a shared name), as the host keeps one per metric born.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct PointKey {
    /// The node or device it belongs to.
    pub owner: Arc<PointOwner>,
    /// The metric's name.
    pub name: MetricName,
}

impl PointKey {
    /// The group id.
    pub fn group(&self) -> &Id {
        &self.owner.group
    }

    /// The edge node id.
    pub fn node(&self) -> &Id {
        &self.owner.node
    }

    /// The device id, `None` for the node's own metrics.
    pub fn device(&self) -> Option<&Id> {
        self.owner.device.as_ref()
    }
}

/// A point as a birth describes it.
#[derive(Debug, Clone, PartialEq)]
pub struct PointInfo {
    /// Which point; the same allocation as its samples'.
    pub point: Arc<PointKey>,
    /// Its datatype.
    pub datatype: DataType,
    /// The `engUnit` property.
    pub unit: Option<String>,
    /// The `Documentation` property: what the point is, in words.
    pub description: Option<String>,
    /// The `writable`, `writeMin` and `writeMax` properties.
    pub writable: Writable,
}

/// A sample's value.
#[derive(Debug, Clone, PartialEq)]
pub enum SampleValue {
    /// Numbers, booleans (1 or 0) and DateTimes (ms since the Unix epoch).
    Number(f64),
    /// String and Text.
    Text(String),
    /// No value: the reading was not good, or the node or device died.
    Null,
}

impl From<MetricValue> for SampleValue {
    fn from(value: MetricValue) -> Self {
        match value {
            MetricValue::String(s) | MetricValue::Text(s) => Self::Text(s),
            MetricValue::Boolean(b) => Self::Number(if b { 1.0 } else { 0.0 }),
            MetricValue::DateTime(t) => Self::Number(t.as_millis() as f64),
            // A float32 as the decimal it was written as (0.1, not 0.10000000149).
            MetricValue::Float(f) => Self::Number(f.to_string().parse().unwrap_or(f.into())),
            other => Self::Number(other.as_f64().unwrap_or(f64::NAN)),
        }
    }
}

/// One value of one point at one time.
#[derive(Debug, Clone, PartialEq)]
pub struct HostSample {
    /// Which point.
    pub point: Arc<PointKey>,
    /// When it was read.
    pub t: Timestamp,
    /// The value.
    pub value: SampleValue,
    /// How far it can be trusted.
    pub quality: Quality,
    /// Sent with `is_historical`: stored by the node while no host was there.
    pub historical: bool,
}

/// A gateway event received as a node's `Event` metric ([`crate::event`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HostEvent {
    /// The group id.
    pub group: Id,
    /// The edge node id.
    pub node: Id,
    /// The `device` property.
    pub device: Option<String>,
    /// The `point` property: the point's name within its device.
    pub point: Option<String>,
    /// The `line` property.
    pub line: Option<String>,
    /// When it happened: the metric's timestamp, else the payload's, else arrival.
    pub t: Timestamp,
    /// The `kind` property (`device_down`).
    pub kind: Option<String>,
    /// The `severity` property, 1–1000.
    pub severity: Option<u32>,
    /// The value: words for the event log.
    pub message: String,
    /// The `fields` property: the event's facts as JSON text, as sent (the reader
    /// checks it).
    pub fields: Option<String>,
    /// Sent with `is_historical`.
    pub historical: bool,
}

/// What the host made of one message.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Received {
    /// Points a birth described (again, after a rebirth).
    pub points: Vec<PointInfo>,
    /// Values to record.
    pub samples: Vec<HostSample>,
    /// Events to record.
    pub events: Vec<HostEvent>,
    /// Messages to publish: Rebirth requests.
    pub commands: Vec<Publish>,
    /// What was wrong with the message.
    pub problems: Vec<HostProblem>,
}

/// What was wrong with a received message, and its topic.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{topic}: {problem}")]
pub struct HostProblem {
    /// The MQTT topic as received.
    pub topic: String,
    /// What was wrong.
    pub problem: Problem,
}

/// What can be wrong with a received message.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Problem {
    /// The topic is not a Sparkplug topic.
    #[error("not a Sparkplug topic: {0}")]
    Topic(#[from] TopicError),
    /// The payload is not a Sparkplug B protobuf payload, or carries more metrics than
    /// [`crate::proto::MAX_METRICS`].
    #[error(transparent)]
    Undecodable(#[from] crate::proto::PayloadError),
    /// A message of a node whose NBIRTH was not seen, or that died since.
    #[error("a {message_type} from an edge node without a current NBIRTH: dropped")]
    NodeNotBorn {
        /// `NDATA`, `DBIRTH`, `DDATA` or `DDEATH`.
        message_type: String,
    },
    /// Data of a device without a DBIRTH since the NBIRTH (or since its DDEATH).
    #[error("DDATA of device {device}, which has no DBIRTH since the node's NBIRTH: dropped")]
    DeviceNotBorn {
        /// The device.
        device: Id,
    },
    /// A data metric's alias that no birth gave.
    #[error("{} has no metric with alias {alias} in its birth: dropped", owner(.device))]
    UnknownAlias {
        /// The device, `None` for the node.
        device: Option<Id>,
        /// The alias.
        alias: u64,
    },
    /// A data metric's name that no birth gave.
    #[error("{} has no metric {name:?} in its birth: dropped", owner(.device))]
    UnknownMetric {
        /// The device, `None` for the node.
        device: Option<Id>,
        /// The name.
        name: String,
    },
    /// A metric with neither name nor alias.
    #[error("metric {index} has neither name nor alias: dropped")]
    NoMetricId {
        /// Its place in the payload, from 0.
        index: usize,
    },
    /// The `seq` is not the one after the node's previous message's.
    #[error("seq {got} where {expected} was expected: messages of this node were lost")]
    SeqGap {
        /// The previous `seq` + 1, wrapping at 256.
        expected: u64,
        /// The `seq` received.
        got: u64,
    },
    /// A message that needs a `seq` has none.
    #[error("the payload has no seq")]
    NoSeq,
    /// An NDEATH whose `bdSeq` is not the current NBIRTH's: an older session's Will.
    #[error(
        "NDEATH with bdSeq {} while the NBIRTH has bdSeq {}: an older session's Will, ignored",
        bd(.death),
        bd(.birth)
    )]
    StaleDeath {
        /// The death's `bdSeq`.
        death: Option<u64>,
        /// The current NBIRTH's.
        birth: Option<u64>,
    },
    /// A birth metric without a name.
    #[error("birth metric {index} has no name: left out")]
    UnnamedBirthMetric {
        /// Its place in the payload, from 0.
        index: usize,
    },
    /// A birth metric whose name is too long or holds a character that hides or
    /// reorders text.
    #[error("birth metric {index}: {error}: left out")]
    BadMetricName {
        /// Its place in the payload, from 0.
        index: usize,
        /// What is wrong with the name.
        error: NameError,
    },
    /// A birth (NBIRTH or DBIRTH) that would pass one of the host's [`Limits`]: refused
    /// whole, the node or device stays unborn.
    #[error(
        "a birth of {metrics} metrics refused: {}; no Rebirth is asked of this node for {} min",
        refusal(*.cap, *.max),
        REFUSED_REBIRTH_HOLD_OFF_MS / 60_000
    )]
    BirthRefused {
        /// The metrics in the birth.
        metrics: usize,
        /// Which limit.
        cap: Cap,
        /// The limit's value.
        max: usize,
    },
    /// A birth gave one alias to several metrics: data by that alias cannot be resolved
    /// (a data metric that also has its name is still read by it).
    #[error("the birth gives alias {alias} to more than one metric: data by that alias is dropped")]
    DuplicateAlias {
        /// The alias.
        alias: u64,
    },
    /// A birth metric of a datatype this crate does not read.
    #[error("metric {metric:?} has {}, which is not recorded", datatype(.code))]
    UnsupportedDataType {
        /// The metric's name.
        metric: String,
        /// The datatype code, if any.
        code: Option<u32>,
    },
    /// A data metric states another datatype than its birth.
    #[error("metric {metric:?} is {expected} in its birth, the data says datatype {got}: dropped")]
    DataTypeMismatch {
        /// The metric's name.
        metric: String,
        /// The birth's datatype.
        expected: DataType,
        /// The code the data gave.
        got: u32,
    },
    /// A value that cannot be read as its metric's datatype.
    #[error("metric {metric:?}: {error}: dropped")]
    Value {
        /// The metric's name.
        metric: String,
        /// What is wrong with the value.
        error: ValueError,
    },
}

fn refusal(cap: Cap, max: usize) -> String {
    match cap {
        Cap::Nodes => format!("{max} edge nodes are known already (the limit of edge nodes)"),
        Cap::NodePoints => format!(
            "the node's births would hold more than {max} metrics (the limit per edge node)"
        ),
        Cap::Points => {
            format!("all nodes' births would hold more than {max} metrics (the limit in all)")
        }
    }
}

fn owner(device: &Option<Id>) -> String {
    match device {
        Some(d) => format!("device {d}"),
        None => "the node".to_owned(),
    }
}

/// The value of the metric named `name` in `payload`, if it has one.
fn value_of<'p>(payload: &'p Payload, name: &str) -> Option<&'p metric::Value> {
    payload
        .metrics
        .iter()
        .find(|m| m.name.as_deref() == Some(name))
        .and_then(|m| m.value.as_ref())
}

/// The `bdSeq` an NBIRTH or NDEATH carries (Int64, or Int32 from some nodes).
fn bd_seq_of(payload: &Payload) -> Option<u64> {
    match value_of(payload, BD_SEQ)? {
        metric::Value::LongValue(n) => Some(*n),
        metric::Value::IntValue(n) => Some((*n).into()),
        _ => None,
    }
}

fn bd(bd_seq: &Option<u64>) -> String {
    bd_seq.map_or_else(|| "(none)".to_owned(), |n| n.to_string())
}

fn datatype(code: &Option<u32>) -> String {
    code.map_or_else(
        || "no datatype".to_owned(),
        |c| format!("datatype {}", crate::describe::datatype_name(c)),
    )
}

/// Counters for the runtime to export as metrics; they only grow.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Stats {
    /// Messages received.
    pub messages: u64,
    /// Samples returned.
    pub samples: u64,
    /// Events returned.
    pub events: u64,
    /// Rebirth requests returned.
    pub rebirths: u64,
    /// `seq` gaps seen.
    pub seq_gaps: u64,
    /// Messages whose topic or payload could not be read.
    pub undecodable: u64,
    /// Data metrics dropped: of unborn nodes or devices, unknown aliases, unreadable
    /// values.
    pub dropped: u64,
    /// NDEATHs of older sessions, ignored.
    pub stale_deaths: u64,
    /// Births refused for one of the [`Limits`].
    pub births_refused: u64,
    /// Birth metrics left out for their name (too long, or a control or bidirectional
    /// formatting character).
    pub names_refused: u64,
    /// Edge nodes forgotten: dead or unborn for [`DEAD_NODE_GRACE_MS`], or unborn the
    /// longest when a new node's NBIRTH needed the room ([`Limits::max_nodes`]).
    pub nodes_freed: u64,
    /// Problems returned.
    pub problems: u64,
}

/// A Sparkplug B host application: what it knows of every edge node it follows.
#[derive(Debug)]
pub struct Host {
    host_id: Id,
    group: Option<Id>,
    sharing: Sharing,
    nodes: HashMap<(Id, Id), NodeState>,
    stats: Stats,
    limits: Limits,
    /// Metrics in all current births.
    points: usize,
    /// When the host last looked for nodes to forget.
    last_sweep: Option<Timestamp>,
}

#[derive(Debug)]
struct NodeState {
    /// The current NBIRTH's, until the node dies.
    birth: Option<Birth>,
    /// When the last Rebirth was asked, since the last NBIRTH.
    rebirth_asked: Option<Timestamp>,
    /// The least time between two Rebirth requests: longer after a refused birth.
    hold_off_ms: u64,
    /// When the node was last seen unborn (first heard of, dead, refused), by arrival.
    unborn_since: Timestamp,
}

impl NodeState {
    fn unborn(now: Timestamp) -> Self {
        Self {
            birth: None,
            rebirth_asked: None,
            hold_off_ms: REBIRTH_HOLD_OFF_MS,
            unborn_since: now,
        }
    }
}

#[derive(Debug)]
struct Birth {
    bd_seq: Option<u64>,
    /// The last `seq` received.
    last_seq: Option<u64>,
    metrics: Table<Role>,
    devices: HashMap<Id, DeviceBirth>,
    /// Metrics in the NBIRTH and the current DBIRTHs.
    points: usize,
}

#[derive(Debug)]
struct DeviceBirth {
    table: Table<Role>,
    /// Metrics in the DBIRTH.
    points: usize,
}

/// What a born metric's data becomes.
#[derive(Debug, Clone)]
enum Role {
    /// Samples of this point, read as this datatype.
    Point(Arc<PointKey>, DataType),
    /// The node's events.
    Event,
    /// Nothing: `bdSeq`, `Node Control/*`, a datatype this crate does not read.
    Ignored,
}

/// One received message's identity and default time.
struct Message<'a> {
    topic: &'a str,
    group: Id,
    node: Id,
    device: Option<Id>,
    /// The payload's timestamp, else the arrival time.
    t: Timestamp,
    now: Timestamp,
}

impl Received {
    fn problem(&mut self, topic: &str, problem: Problem) {
        self.problems.push(HostProblem {
            topic: shortened(topic),
            problem,
        });
    }
}

/// The most of a topic or name a problem repeats, in bytes: an MQTT topic may be 64 kB.
const QUOTED_BYTES: usize = 2 * crate::topic::MAX_NAME_BYTES;

/// `text`, or its first [`QUOTED_BYTES`] (at a character's boundary) and `…`.
fn shortened(text: &str) -> String {
    if text.len() <= QUOTED_BYTES {
        return text.to_owned();
    }
    let mut end = QUOTED_BYTES;
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    format!("{}…", &text[..end])
}

impl Host {
    /// The host `host_id`, following the nodes of `group` (every group when `None`),
    /// alone or sharing the data with other hosts, within the default [`Limits`].
    pub fn new(host_id: Id, group: Option<Id>, sharing: Sharing) -> Self {
        Self {
            host_id,
            group,
            sharing,
            nodes: HashMap::new(),
            stats: Stats::default(),
            limits: Limits::default(),
            points: 0,
            last_sweep: None,
        }
    }

    /// The same host within `limits` instead of the defaults.
    pub fn with_limits(mut self, limits: Limits) -> Self {
        self.limits = limits;
        self
    }

    /// The host id.
    pub fn host_id(&self) -> &Id {
        &self.host_id
    }

    /// The counters so far.
    pub fn stats(&self) -> Stats {
        self.stats
    }

    /// How many edge nodes have a current NBIRTH (born and not dead since).
    pub fn nodes_born(&self) -> usize {
        self.nodes.values().filter(|n| n.birth.is_some()).count()
    }

    /// How many edge nodes the host keeps a state for: born, or dead or unborn for less
    /// than [`DEAD_NODE_GRACE_MS`]; at most [`Limits::max_nodes`].
    pub fn nodes_known(&self) -> usize {
        self.nodes.len()
    }

    /// The metrics of all current births (what [`Limits::max_points`] bounds).
    pub fn points_held(&self) -> usize {
        self.points
    }

    /// The topic filters to subscribe to, again after every reconnect: births and deaths
    /// (QoS 1, never shared), data (QoS 0, shared with `$share/{name}/` when sharing).
    /// Each names its message type, so neither STATE nor commands arrive.
    pub fn subscriptions(&self) -> Vec<Subscription> {
        let group = self.group.as_ref().map_or("+", Id::as_str);
        let filter = |message_type: &str, levels: &str| {
            format!("{NAMESPACE}/{group}/{message_type}/{levels}")
        };
        let unshared = |message_type, levels| Subscription {
            filter: filter(message_type, levels),
            qos: Qos::AtLeastOnce,
        };
        let data = |message_type, levels| Subscription {
            filter: match &self.sharing {
                Sharing::Alone => filter(message_type, levels),
                Sharing::Shared { name } => {
                    format!("$share/{name}/{}", filter(message_type, levels))
                }
            },
            qos: Qos::AtMostOnce,
        };
        vec![
            unshared("NBIRTH", "+"),
            unshared("NDEATH", "+"),
            unshared("DBIRTH", "+/+"),
            unshared("DDEATH", "+/+"),
            data("NDATA", "+"),
            data("DDATA", "+/+"),
        ]
    }

    /// The host's own STATE topic, QoS 1: subscribe to it only after publishing
    /// [`Host::state_online`] on the same connection, so the retained message it brings is
    /// this host's own `online`. What arrives there goes to [`Host::reassert_online`].
    pub fn state_subscription(&self) -> Subscription {
        Subscription {
            filter: Topic::State {
                host: self.host_id.clone(),
            }
            .to_string(),
            qos: Qos::AtLeastOnce,
        }
    }

    /// The STATE to register as the MQTT Will: `{"online":false,"timestamp":now}` on
    /// `spBv1.0/STATE/{host_id}`, QoS 1, retained. Also what to publish before a
    /// clean disconnect.
    pub fn will(&self, now: Timestamp) -> Publish {
        HostState::new(false, now).publish(self.host_id.clone())
    }

    /// The STATE to publish once connected (after subscribing):
    /// `{"online":true,"timestamp":now}`, QoS 1, retained; `now` the Will's.
    pub fn state_online(&self, now: Timestamp) -> Publish {
        HostState::new(true, now).publish(self.host_id.clone())
    }

    /// What to publish when this host, online since `online_at` (its Will's timestamp)
    /// and not going offline itself, reads `payload` on its own STATE topic: `None` for an
    /// `online` STATE; for anything else (an `online:false`, which only a forgery or a
    /// stale message can be while the host is up, or a payload that is no STATE) this
    /// session's `online` again, with its own timestamp `online_at`, retained.
    ///
    /// Always `online_at`, never a newer time: the Will carries `online_at`, and an edge
    /// node ignores an offline older than the newest STATE it believed, so a newer online
    /// would make every node ignore this host's Will after a `kill -9`. A cellbus gateway
    /// waits a grace after an offline for the host to say its same session is online
    /// again (the gateway's `northbound::mqtt::primary`), so this answer is enough to keep it
    /// publishing; a node that acts on an offline at once comes back at its next
    /// connection, when it reads the retained STATE, which this answer has put right.
    pub fn reassert_online(&self, payload: &[u8], online_at: Timestamp) -> Option<Publish> {
        match HostState::from_json(payload) {
            Ok(state) if state.online => None,
            _ => Some(self.state_online(online_at)),
        }
    }

    /// Reads one message received on `topic` at `now`. Never fails: what is wrong is
    /// in [`Received::problems`]. STATE, NCMD and DCMD messages and other groups' are
    /// ignored.
    pub fn receive(&mut self, topic: &str, payload: &[u8], now: Timestamp) -> Received {
        let mut out = Received::default();
        self.stats.messages += 1;
        self.sweep(now);
        self.read(topic, payload, now, &mut out);
        self.stats.samples += out.samples.len() as u64;
        self.stats.events += out.events.len() as u64;
        self.stats.rebirths += out.commands.len() as u64;
        self.stats.problems += out.problems.len() as u64;
        out
    }

    /// Forgets the nodes dead or unborn for [`DEAD_NODE_GRACE_MS`]; at most once every
    /// [`SWEEP_EVERY_MS`] (and at once when the clock went back).
    fn sweep(&mut self, now: Timestamp) {
        if let Some(last) = self.last_sweep
            && last <= now
            && now.as_millis() - last.as_millis() < SWEEP_EVERY_MS
        {
            return;
        }
        self.last_sweep = Some(now);
        let before = self.nodes.len();
        self.nodes.retain(|_, state| {
            if state.birth.is_some() {
                return true;
            }
            if state.unborn_since > now {
                state.unborn_since = now; // the clock went back: the grace starts again
            }
            now.as_millis() - state.unborn_since.as_millis() < DEAD_NODE_GRACE_MS
        });
        self.stats.nodes_freed += (before - self.nodes.len()) as u64;
    }

    fn read(&mut self, topic: &str, payload: &[u8], now: Timestamp, out: &mut Received) {
        let parsed: Topic = match topic.parse() {
            Ok(parsed) => parsed,
            Err(e) => {
                self.stats.undecodable += 1;
                return out.problem(topic, Problem::Topic(e));
            }
        };
        let Ok((group, kind, node, device)) = parsed.into_edge() else {
            return; // a host's STATE
        };
        if kind == MessageKind::Command || self.group.as_ref().is_some_and(|g| *g != group) {
            return;
        }
        let payload = match crate::proto::decode_payload(payload) {
            Ok(payload) => payload,
            Err(e) => {
                self.stats.undecodable += 1;
                return out.problem(topic, Problem::Undecodable(e));
            }
        };
        let msg = Message {
            topic,
            group,
            node,
            device,
            t: payload.timestamp.map_or(now, Timestamp::from_millis),
            now,
        };
        match (kind, msg.device.is_some()) {
            (MessageKind::Birth, false) => self.node_birth(&msg, &payload, out),
            (MessageKind::Death, false) => self.node_death(&msg, &payload, out),
            (kind, _) => self.after_birth(kind, &msg, &payload, out),
        }
    }

    /// Whether a state can be kept for one more node: there is room, or an unborn node
    /// (the one unborn longest) is forgotten to make some.
    fn room_for_a_node(&mut self) -> bool {
        if self.nodes.len() < self.limits.max_nodes {
            return true;
        }
        let oldest = self
            .nodes
            .iter()
            .filter(|(_, state)| state.birth.is_none())
            .min_by_key(|(_, state)| state.unborn_since)
            .map(|(key, _)| key.clone());
        match oldest {
            Some(key) => {
                self.nodes.remove(&key);
                self.stats.nodes_freed += 1;
                true
            }
            None => false,
        }
    }

    /// Refuses a birth of `metrics` metrics for `cap`: the node (an NBIRTH) or the device
    /// (a DBIRTH) is unborn from now on, and asked no Rebirth for a long while.
    fn refuse_birth(&mut self, msg: &Message<'_>, metrics: usize, cap: Cap, out: &mut Received) {
        self.stats.births_refused += 1;
        let max = match cap {
            Cap::Nodes => self.limits.max_nodes,
            Cap::NodePoints => self.limits.max_node_points,
            Cap::Points => self.limits.max_points,
        };
        out.problem(msg.topic, Problem::BirthRefused { metrics, cap, max });
        let key = (msg.group.clone(), msg.node.clone());
        if !self.nodes.contains_key(&key) {
            // A new node: its refusal is kept (for the hold-off) while there is room.
            if cap == Cap::Nodes || !self.room_for_a_node() {
                return;
            }
            self.nodes.insert(key.clone(), NodeState::unborn(msg.now));
        }
        let Some(state) = self.nodes.get_mut(&key) else {
            return;
        };
        match &msg.device {
            None => {
                if let Some(old) = state.birth.take() {
                    self.points = self.points.saturating_sub(old.points);
                    state.unborn_since = msg.now;
                }
            }
            Some(device) => {
                if let Some(birth) = &mut state.birth
                    && let Some(old) = birth.devices.remove(device)
                {
                    birth.points = birth.points.saturating_sub(old.points);
                    self.points = self.points.saturating_sub(old.points);
                }
            }
        }
        state.rebirth_asked = Some(msg.now);
        state.hold_off_ms = REFUSED_REBIRTH_HOLD_OFF_MS;
    }

    fn node_birth(&mut self, msg: &Message<'_>, payload: &Payload, out: &mut Received) {
        let key = (msg.group.clone(), msg.node.clone());
        let metrics = payload.metrics.len();
        let old = self
            .nodes
            .get(&key)
            .and_then(|state| state.birth.as_ref())
            .map_or(0, |birth| birth.points);
        let cap = if metrics > self.limits.max_node_points {
            Some(Cap::NodePoints)
        } else if self.points.saturating_sub(old) + metrics > self.limits.max_points {
            Some(Cap::Points)
        } else if !self.nodes.contains_key(&key) && !self.room_for_a_node() {
            Some(Cap::Nodes)
        } else {
            None
        };
        if let Some(cap) = cap {
            return self.refuse_birth(msg, metrics, cap, out);
        }
        let bd_seq = bd_seq_of(payload);
        let table = birth_table(msg, &payload.metrics, &mut self.stats, out);
        let state = self
            .nodes
            .entry(key)
            .or_insert_with(|| NodeState::unborn(msg.now));
        let birth = Birth {
            bd_seq,
            last_seq: payload.seq,
            metrics: table,
            devices: HashMap::new(),
            points: metrics,
        };
        if let Some(old) = state.birth.replace(birth) {
            self.points = self.points.saturating_sub(old.points);
        }
        self.points += metrics;
        state.rebirth_asked = None;
        state.hold_off_ms = REBIRTH_HOLD_OFF_MS;
    }

    fn node_death(&mut self, msg: &Message<'_>, payload: &Payload, out: &mut Received) {
        let death = bd_seq_of(payload);
        let host_offline = matches!(
            value_of(payload, HOST_OFFLINE),
            Some(metric::Value::BooleanValue(true))
        );
        let key = (msg.group.clone(), msg.node.clone());
        let Some(state) = self.nodes.get_mut(&key) else {
            return; // never born here: nothing to mark
        };
        match &state.birth {
            None => return, // already dead
            Some(birth) if birth.bd_seq != death => {
                self.stats.stale_deaths += 1;
                return out.problem(
                    msg.topic,
                    Problem::StaleDeath {
                        death,
                        birth: birth.bd_seq,
                    },
                );
            }
            Some(_) => {}
        }
        let Some(birth) = state.birth.take() else {
            return;
        };
        state.unborn_since = msg.now;
        self.points = self.points.saturating_sub(birth.points);
        // The node stores what it reads while its host is away: not a failure.
        let quality = if host_offline {
            Quality::Stale
        } else {
            Quality::Bad
        };
        mark(&birth.metrics, msg.t, quality, out);
        for device in birth.devices.values() {
            mark(&device.table, msg.t, quality, out);
        }
    }

    /// NDATA, DBIRTH, DDATA and DDEATH: messages of a born node, with a `seq`.
    fn after_birth(
        &mut self,
        kind: MessageKind,
        msg: &Message<'_>,
        payload: &Payload,
        out: &mut Received,
    ) {
        let key = (msg.group.clone(), msg.node.clone());
        // Only a birth makes room by forgetting an unborn node; data does not.
        let tracked = self.nodes.contains_key(&key) || self.nodes.len() < self.limits.max_nodes;
        let message_type = || match &msg.device {
            Some(_) => format!("D{}", suffix(kind)),
            None => format!("N{}", suffix(kind)),
        };
        if !tracked {
            // As many nodes as allowed are known: this one is not asked for a birth.
            if kind == MessageKind::Data {
                self.stats.dropped += payload.metrics.len() as u64;
            }
            let message_type = message_type();
            return out.problem(msg.topic, Problem::NodeNotBorn { message_type });
        }
        let state = self
            .nodes
            .entry(key)
            .or_insert_with(|| NodeState::unborn(msg.now));
        let Some(birth) = &mut state.birth else {
            if kind == MessageKind::Data {
                self.stats.dropped += payload.metrics.len() as u64;
            }
            let message_type = message_type();
            out.problem(msg.topic, Problem::NodeNotBorn { message_type });
            return ask_rebirth(state, msg, out);
        };
        let mut rebirth = false;
        if self.sharing == Sharing::Alone {
            match (birth.last_seq, payload.seq) {
                (Some(last), Some(got)) => {
                    let expected = (last % 256 + 1) % 256;
                    if got != expected {
                        self.stats.seq_gaps += 1;
                        out.problem(msg.topic, Problem::SeqGap { expected, got });
                        rebirth = true;
                    }
                }
                (_, None) => out.problem(msg.topic, Problem::NoSeq),
                (None, Some(_)) => {}
            }
        }
        birth.last_seq = payload.seq.or(birth.last_seq);
        match (kind, &msg.device) {
            (MessageKind::Birth, Some(device)) => {
                let metrics = payload.metrics.len();
                let old = birth.devices.get(device).map_or(0, |d| d.points);
                let cap =
                    if birth.points.saturating_sub(old) + metrics > self.limits.max_node_points {
                        Some(Cap::NodePoints)
                    } else if self.points.saturating_sub(old) + metrics > self.limits.max_points {
                        Some(Cap::Points)
                    } else {
                        None
                    };
                if let Some(cap) = cap {
                    return self.refuse_birth(msg, metrics, cap, out);
                }
                let table = birth_table(msg, &payload.metrics, &mut self.stats, out);
                let known = DeviceBirth {
                    table,
                    points: metrics,
                };
                if let Some(old) = birth.devices.insert(device.clone(), known) {
                    birth.points = birth.points.saturating_sub(old.points);
                    self.points = self.points.saturating_sub(old.points);
                }
                birth.points += metrics;
                self.points += metrics;
            }
            (MessageKind::Death, Some(device)) => {
                if let Some(old) = birth.devices.remove(device) {
                    birth.points = birth.points.saturating_sub(old.points);
                    self.points = self.points.saturating_sub(old.points);
                    mark(&old.table, msg.t, Quality::Bad, out);
                }
            }
            (MessageKind::Data, None) => {
                let (dropped, unknown) = data(msg, &birth.metrics, &payload.metrics, out);
                self.stats.dropped += dropped;
                rebirth |= unknown;
            }
            (MessageKind::Data, Some(device)) => match birth.devices.get(device) {
                Some(known) => {
                    let (dropped, unknown) = data(msg, &known.table, &payload.metrics, out);
                    self.stats.dropped += dropped;
                    rebirth |= unknown;
                }
                None => {
                    self.stats.dropped += payload.metrics.len() as u64;
                    let device = device.clone();
                    out.problem(msg.topic, Problem::DeviceNotBorn { device });
                    rebirth = true;
                }
            },
            // NBIRTH and NDEATH are read before; commands never come here.
            _ => {}
        }
        if rebirth {
            ask_rebirth(state, msg, out);
        }
    }
}

fn suffix(kind: MessageKind) -> &'static str {
    match kind {
        MessageKind::Birth => "BIRTH",
        MessageKind::Data => "DATA",
        MessageKind::Death => "DEATH",
        MessageKind::Command => "CMD",
    }
}

/// A Rebirth request for the message's node, unless one was asked less than its hold-off
/// ago ([`REBIRTH_HOLD_OFF_MS`], or [`REFUSED_REBIRTH_HOLD_OFF_MS`] after a refused birth;
/// a clock that went back does not hold it off).
fn ask_rebirth(state: &mut NodeState, msg: &Message<'_>, out: &mut Received) {
    if let Some(asked) = state.rebirth_asked
        && asked <= msg.now
        && msg.now.as_millis() - asked.as_millis() < state.hold_off_ms
    {
        return;
    }
    state.rebirth_asked = Some(msg.now);
    out.commands
        .push(rebirth_request(&msg.group, &msg.node, msg.now));
}

/// The table of a birth's metrics; its points and their current values into `out`.
/// Metrics without a name, or with a name [`MetricName`] refuses, are left out.
fn birth_table(
    msg: &Message<'_>,
    metrics: &[Metric],
    stats: &mut Stats,
    out: &mut Received,
) -> Table<Role> {
    for (index, m) in metrics.iter().enumerate() {
        if m.name.is_none() {
            out.problem(msg.topic, Problem::UnnamedBirthMetric { index });
        }
    }
    let owner = Arc::new(PointOwner {
        group: msg.group.clone(),
        node: msg.node.clone(),
        device: msg.device.clone(),
    });
    let table = Table::of_birth(metrics, |index, shared, m| {
        let metric_name = match MetricName::shared(shared) {
            Ok(name) => name,
            Err(error) => {
                stats.names_refused += 1;
                out.problem(msg.topic, Problem::BadMetricName { index, error });
                return None;
            }
        };
        let name: &str = shared;
        if msg.device.is_none() {
            if name == BD_SEQ || name.starts_with(NODE_CONTROL) {
                return Some(Role::Ignored);
            }
            if name == EVENT {
                return Some(Role::Event);
            }
        }
        let Some(datatype) = m.datatype.and_then(|code| DataType::from_code(code).ok()) else {
            out.problem(
                msg.topic,
                Problem::UnsupportedDataType {
                    metric: name.to_owned(),
                    code: m.datatype,
                },
            );
            return Some(Role::Ignored);
        };
        let point = Arc::new(PointKey {
            owner: Arc::clone(&owner),
            name: metric_name,
        });
        out.points.push(point_info(&point, datatype, m));
        match sample(&point, datatype, m, msg.t) {
            Ok(Some(s)) => out.samples.push(s),
            Ok(None) => {}
            Err(error) => out.problem(
                msg.topic,
                Problem::Value {
                    metric: name.to_owned(),
                    error,
                },
            ),
        }
        Some(Role::Point(point, datatype))
    });
    for &alias in table.ambiguous_aliases() {
        out.problem(msg.topic, Problem::DuplicateAlias { alias });
    }
    table
}

fn point_info(point: &Arc<PointKey>, datatype: DataType, m: &Metric) -> PointInfo {
    let p = m.properties.as_ref();
    let range = match (read::number(p, WRITE_MIN), read::number(p, WRITE_MAX)) {
        (Some(min), Some(max)) => WriteRange::new(min, max).ok(),
        _ => None,
    };
    let writable = match (read::boolean(p, WRITABLE), range) {
        (Some(true), Some(range)) => Writable::Within(range),
        (Some(true), None) => Writable::Yes,
        _ => Writable::No,
    };
    PointInfo {
        point: Arc::clone(point),
        datatype,
        unit: read::string(p, ENG_UNIT),
        description: read::string(p, DOCUMENTATION),
        writable,
    }
}

/// A metric's sample, `None` for a transient one.
fn sample(
    point: &Arc<PointKey>,
    datatype: DataType,
    m: &Metric,
    t: Timestamp,
) -> Result<Option<HostSample>, ValueError> {
    if m.is_transient == Some(true) {
        return Ok(None);
    }
    let stated = Quality::of(m);
    let (value, quality) = if m.is_null == Some(true) {
        let quality = stated.filter(|q| *q != Quality::Good);
        (SampleValue::Null, quality.unwrap_or(Quality::Bad))
    } else {
        let value = MetricValue::from_proto(datatype, m.value.as_ref())?;
        (value.into(), stated.unwrap_or(Quality::Good))
    };
    Ok(Some(HostSample {
        point: Arc::clone(point),
        t: m.timestamp.map_or(t, Timestamp::from_millis),
        value,
        quality,
        historical: m.is_historical == Some(true),
    }))
}

/// The samples and events of a data message's metrics; the count dropped, and whether
/// a metric's alias or name was unknown.
fn data(
    msg: &Message<'_>,
    table: &Table<Role>,
    metrics: &[Metric],
    out: &mut Received,
) -> (u64, bool) {
    let mut dropped = 0;
    let mut unknown = false;
    for (index, m) in metrics.iter().enumerate() {
        let Some(known) = table.lookup(m) else {
            dropped += 1;
            if table.left_out(m) {
                continue; // reported at its birth
            }
            let problem = match (m.alias, &m.name) {
                (Some(alias), _) => Problem::UnknownAlias {
                    device: msg.device.clone(),
                    alias,
                },
                (None, Some(name)) => Problem::UnknownMetric {
                    device: msg.device.clone(),
                    name: shortened(name),
                },
                (None, None) => Problem::NoMetricId { index },
            };
            unknown |= !matches!(problem, Problem::NoMetricId { .. });
            out.problem(msg.topic, problem);
            continue;
        };
        let read = match &known.extra {
            Role::Ignored => continue,
            Role::Event => node_event(msg, m).map(|e| out.events.push(e)),
            Role::Point(point, datatype) => match m.datatype {
                Some(got) if got != datatype.code() => {
                    dropped += 1;
                    out.problem(
                        msg.topic,
                        Problem::DataTypeMismatch {
                            metric: known.name.to_string(),
                            expected: *datatype,
                            got,
                        },
                    );
                    continue;
                }
                _ => sample(point, *datatype, m, msg.t).map(|s| out.samples.extend(s)),
            },
        };
        if let Err(error) = read {
            dropped += 1;
            let metric = known.name.to_string();
            out.problem(msg.topic, Problem::Value { metric, error });
        }
    }
    (dropped, unknown)
}

/// A node's `Event` metric as an event.
fn node_event(msg: &Message<'_>, m: &Metric) -> Result<HostEvent, ValueError> {
    let message = match MetricValue::from_proto(DataType::String, m.value.as_ref())? {
        MetricValue::String(s) | MetricValue::Text(s) => s,
        // from_proto reads a String metric as a String; any other is shown as read.
        other => format!("{other:?}"),
    };
    let p = m.properties.as_ref();
    Ok(HostEvent {
        group: msg.group.clone(),
        node: msg.node.clone(),
        device: read::string(p, event::DEVICE),
        point: read::string(p, event::POINT),
        line: read::string(p, event::LINE),
        t: m.timestamp.map_or(msg.t, Timestamp::from_millis),
        kind: read::string(p, event::KIND),
        // 1–1000 whatever number type it came as: −5 is the least severe, 4e9 the most.
        severity: read::integer(p, event::SEVERITY)
            .map(|n| u32::try_from(n.clamp(1, 1000)).unwrap_or(1000)),
        message,
        fields: read::string(p, event::FIELDS),
        historical: m.is_historical == Some(true),
    })
}

/// A null sample of `quality` at `t` for every point of `table`.
fn mark(table: &Table<Role>, t: Timestamp, quality: Quality, out: &mut Received) {
    for known in table.iter() {
        if let Role::Point(point, _) = &known.extra {
            out.samples.push(HostSample {
                point: Arc::clone(point),
                t,
                value: SampleValue::Null,
                quality,
                historical: false,
            });
        }
    }
}

#[cfg(test)]
mod tests;
