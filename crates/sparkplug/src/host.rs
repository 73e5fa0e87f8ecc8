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
        let bd_seq = payload
            .metrics
            .iter()
            .find(|m| m.name.as_deref() == Some(BD_SEQ))
            .and_then(|m| match m.value {
                Some(metric::Value::LongValue(n)) => Some(n),
                Some(metric::Value::IntValue(n)) => Some(n.into()),
                _ => None,
            });
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
        let value_of = |name: &str| {
            payload
                .metrics
                .iter()
                .find(|m| m.name.as_deref() == Some(name))
                .and_then(|m| m.value.as_ref())
        };
        let death = value_of(BD_SEQ).and_then(|value| match value {
            metric::Value::LongValue(n) => Some(*n),
            metric::Value::IntValue(n) => Some((*n).into()),
            _ => None,
        });
        let host_offline = matches!(
            value_of(HOST_OFFLINE),
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
mod tests {
    use super::*;
    use crate::event::NodeEvent;
    use crate::metric::{MetricSpec, Sample};
    use crate::node::{BdSeq, Command, Delivery, EdgeNode, REBIRTH};
    use prost::Message as _;

    /// 2025-11-24T16:00:00.000Z.
    const T0: Timestamp = Timestamp::from_millis(1_764_000_000_000);

    fn at(offset_ms: u64) -> Timestamp {
        Timestamp::from_millis(T0.as_millis() + offset_ms)
    }

    fn id(s: &str) -> Id {
        Id::new(s).expect("test ids are valid")
    }

    fn name(s: &str) -> MetricName {
        MetricName::new(s).expect("test names are not empty")
    }

    /// A station: a temperature in °C, a set point writable 100–450 °C, a heater switch
    /// and a status text.
    fn station() -> Vec<(MetricSpec, Sample)> {
        vec![
            (
                MetricSpec::new(name("air_temp"), DataType::Double)
                    .unit("°C")
                    .description("air temperature at the nozzle"),
                Sample::good(MetricValue::Double(25.5), T0),
            ),
            (
                MetricSpec::new(name("set_point"), DataType::Int32)
                    .unit("°C")
                    .writable(Writable::Within(WriteRange::new(100.0, 450.0).unwrap())),
                Sample::good(MetricValue::Int32(300), T0),
            ),
            (
                MetricSpec::new(name("heater_on"), DataType::Boolean),
                Sample::good(MetricValue::Boolean(true), T0),
            ),
            (
                MetricSpec::new(name("status"), DataType::String),
                Sample::good(MetricValue::String("idle".into()), T0),
            ),
        ]
    }

    /// The node's own metrics: the event channel and a line count.
    fn node_metrics() -> Vec<(MetricSpec, Sample)> {
        vec![
            (
                event::spec(),
                Sample::good(MetricValue::String(String::new()), T0),
            ),
            (
                MetricSpec::new(name("Gateway/Lines"), DataType::Int64),
                Sample::good(MetricValue::Int64(3), T0),
            ),
        ]
    }

    fn feed(host: &mut Host, p: &Publish, now: Timestamp) -> Received {
        host.receive(&p.topic.to_string(), &p.payload, now)
    }

    fn alone() -> Host {
        Host::new(id("historian"), Some(id("cell")), Sharing::Alone)
    }

    /// Edge node `cell/gw1` (bdSeq 7), connected and born with devices `jbc1` and
    /// `jbc2`; a host that has read the births.
    fn born(host: &mut Host) -> EdgeNode {
        born_with_will(host).0
    }

    /// [`born`], and the Will the node registered for this session.
    /// Edge node `cell/gw1` (bdSeq 7), connected, nothing born.
    fn connected() -> EdgeNode {
        let mut node = EdgeNode::new(id("cell"), id("gw1"), BdSeq::new(7));
        node.on_connect();
        node
    }

    fn born_with_will(host: &mut Host) -> (EdgeNode, Publish) {
        let mut node = EdgeNode::new(id("cell"), id("gw1"), BdSeq::new(7));
        let will = node.will();
        node.on_connect();
        let nbirth = node.node_birth(&node_metrics(), T0).unwrap();
        assert!(feed(host, &nbirth, T0).problems.is_empty());
        for device in ["jbc1", "jbc2"] {
            let dbirth = node.device_birth(&id(device), &station(), T0).unwrap();
            assert!(feed(host, &dbirth, T0).problems.is_empty());
        }
        (node, will)
    }

    fn ddata(node: &mut EdgeNode, device: &str, temp: f64, t: Timestamp) -> Publish {
        let changes = [("air_temp", Sample::good(MetricValue::Double(temp), t))];
        node.device_data(&id(device), &changes, t, Delivery::Live)
            .unwrap()
            .expect("the temperature changed")
    }

    fn key(device: Option<&str>, point: &str) -> PointKey {
        PointKey {
            owner: Arc::new(PointOwner {
                group: id("cell"),
                node: id("gw1"),
                device: device.map(id),
            }),
            name: name(point),
        }
    }

    /// Whether `p` is an NCMD that a born edge node `cell/gw1` reads as a Rebirth.
    fn is_rebirth_of_gw1(p: &Publish) -> bool {
        let mut node = EdgeNode::new(id("cell"), id("gw1"), BdSeq::new(0));
        node.on_connect();
        node.node_birth(&[], T0).unwrap();
        p.topic.to_string() == "spBv1.0/cell/NCMD/gw1"
            && !p.retain
            && p.qos == Qos::AtMostOnce
            && node.handle_command(&p.topic.to_string(), &p.payload) == Ok(vec![Command::Rebirth])
    }

    #[test]
    fn births_define_points_with_units_and_ranges_and_ddata_by_alias_resolves_to_names() {
        let mut host = alone();
        let mut node = connected();
        let nbirth = node.node_birth(&node_metrics(), T0).unwrap();
        let got = feed(&mut host, &nbirth, at(5));
        let names: Vec<_> = got.points.iter().map(|p| p.point.name.as_str()).collect();
        assert_eq!(
            names,
            ["Gateway/Lines"],
            "bdSeq, Node Control and Event are no points"
        );
        assert_eq!(got.samples.len(), 1);
        assert_eq!(got.samples[0].value, SampleValue::Number(3.0));

        let dbirth = node.device_birth(&id("jbc1"), &station(), T0).unwrap();
        let got = feed(&mut host, &dbirth, at(5));
        assert_eq!(got.problems, []);
        let air = &got.points[0];
        assert_eq!(*air.point, key(Some("jbc1"), "air_temp"));
        assert_eq!(air.datatype, DataType::Double);
        assert_eq!(air.unit.as_deref(), Some("°C"));
        assert_eq!(
            air.description.as_deref(),
            Some("air temperature at the nozzle")
        );
        assert_eq!(air.writable, Writable::No);
        assert_eq!(
            got.points[1].writable,
            Writable::Within(WriteRange::new(100.0, 450.0).unwrap())
        );
        let values: Vec<_> = got.samples.iter().map(|s| s.value.clone()).collect();
        assert_eq!(
            values,
            [
                SampleValue::Number(25.5),
                SampleValue::Number(300.0),
                SampleValue::Number(1.0),
                SampleValue::Text("idle".into()),
            ],
            "births give current values; booleans and integers are numbers"
        );
        assert!(
            got.samples
                .iter()
                .all(|s| s.t == T0 && s.quality == Quality::Good)
        );

        let data = ddata(&mut node, "jbc1", 26.0, at(1_000));
        let got = feed(&mut host, &data, at(1_010));
        assert_eq!(got.problems, []);
        assert_eq!(got.commands, []);
        assert_eq!(got.samples.len(), 1);
        let s = &got.samples[0];
        assert_eq!(*s.point, key(Some("jbc1"), "air_temp"));
        assert_eq!(s.value, SampleValue::Number(26.0));
        assert_eq!(s.t, at(1_000), "the metric's own time");
        assert_eq!(s.quality, Quality::Good);
        assert!(!s.historical);
        assert!(
            Arc::ptr_eq(&s.point, &air.point),
            "samples share their point's key with the birth"
        );
        assert_eq!(host.stats().samples, 1 + 4 + 1);
    }

    #[test]
    fn historical_ddata_keeps_its_timestamps_and_says_it_is_historical() {
        let mut host = alone();
        let mut node = born(&mut host);
        let changes = [
            ("air_temp", Sample::good(MetricValue::Double(30.0), at(100))),
            ("air_temp", Sample::good(MetricValue::Double(31.0), at(200))),
        ];
        let data = node
            .device_data(&id("jbc2"), &changes, at(60_000), Delivery::Historical)
            .unwrap()
            .unwrap();
        let got = feed(&mut host, &data, at(60_001));
        let samples: Vec<_> = got
            .samples
            .iter()
            .map(|s| {
                (
                    s.point.device().cloned(),
                    s.t,
                    s.value.clone(),
                    s.historical,
                )
            })
            .collect();
        assert_eq!(
            samples,
            [
                (Some(id("jbc2")), at(100), SampleValue::Number(30.0), true),
                (Some(id("jbc2")), at(200), SampleValue::Number(31.0), true),
            ]
        );
    }

    #[test]
    fn stale_and_bad_readings_are_null_samples_with_their_quality_and_good_comes_back() {
        let mut host = alone();
        let mut node = born(&mut host);
        let mut send = |sample: Sample| {
            let data = node
                .device_data(&id("jbc1"), &[("status", sample)], at(1), Delivery::Live)
                .unwrap()
                .unwrap();
            let got = feed(&mut host, &data, at(2));
            let s = &got.samples[0];
            (s.value.clone(), s.quality)
        };
        assert_eq!(
            send(Sample::stale(at(1))),
            (SampleValue::Null, Quality::Stale)
        );
        assert_eq!(send(Sample::bad(at(1))), (SampleValue::Null, Quality::Bad));
        assert_eq!(
            send(Sample::good(MetricValue::String("run".into()), at(1))),
            (SampleValue::Text("run".into()), Quality::Good)
        );
    }

    #[test]
    fn a_null_value_without_a_quality_is_bad_and_with_quality_good_is_still_bad() {
        let mut host = alone();
        let mut node = born(&mut host);
        let data = node
            .device_data(
                &id("jbc1"),
                &[("air_temp", Sample::good(MetricValue::Double(1.0), at(1)))],
                at(1),
                Delivery::Live,
            )
            .unwrap()
            .unwrap();
        let mut payload = Payload::decode(&data.payload[..]).unwrap();
        let m = &mut payload.metrics[0];
        m.value = None;
        m.is_null = Some(true);
        let got = host.receive(&data.topic.to_string(), &payload.encode_to_vec(), at(2));
        assert_eq!(got.samples[0].quality, Quality::Bad);
        let m = &mut payload.metrics[0];
        m.properties = crate::metric::Properties::quality(Quality::Good).into_option();
        payload.seq = payload.seq.map(|s| (s + 1) % 256);
        let got = host.receive(&data.topic.to_string(), &payload.encode_to_vec(), at(3));
        assert_eq!(got.problems, []);
        assert_eq!(got.samples[0].value, SampleValue::Null);
        assert_eq!(got.samples[0].quality, Quality::Bad);
    }

    #[test]
    fn a_seq_gap_asks_for_one_rebirth_and_not_again_within_five_seconds() {
        let mut host = alone();
        let mut node = born(&mut host);
        let _lost = ddata(&mut node, "jbc1", 40.0, at(1_000));
        let after = ddata(&mut node, "jbc2", 41.0, at(1_100));
        let got = feed(&mut host, &after, at(1_100));
        assert_eq!(
            got.problems[0].problem,
            Problem::SeqGap {
                expected: 3,
                got: 4
            },
            "NBIRTH 0, DBIRTHs 1 and 2, the lost DDATA 3"
        );
        assert!(
            got.problems[0]
                .to_string()
                .starts_with("spBv1.0/cell/DDATA/gw1/jbc2: seq 4"),
            "{}",
            got.problems[0]
        );
        assert_eq!(got.commands.len(), 1);
        assert!(is_rebirth_of_gw1(&got.commands[0]));
        assert_eq!(
            got.samples.len(),
            1,
            "the data of the message after the gap is kept"
        );

        // Another gap 4.9 s later: counted, no second request yet.
        let _lost = ddata(&mut node, "jbc1", 42.0, at(5_000));
        let got = feed(
            &mut host,
            &ddata(&mut node, "jbc1", 43.0, at(6_000)),
            at(6_000),
        );
        assert!(matches!(got.problems[0].problem, Problem::SeqGap { .. }));
        assert_eq!(got.commands, []);
        // In sequence again: nothing to ask.
        let got = feed(
            &mut host,
            &ddata(&mut node, "jbc1", 44.0, at(6_050)),
            at(6_050),
        );
        assert_eq!((got.problems.len(), got.commands.len()), (0, 0));
        // A gap 5 s after the request: asked again.
        let _lost = ddata(&mut node, "jbc1", 45.0, at(6_100));
        let got = feed(
            &mut host,
            &ddata(&mut node, "jbc1", 46.0, at(6_200)),
            at(6_200),
        );
        assert_eq!(got.commands.len(), 1);
        assert_eq!(host.stats().seq_gaps, 3);
        assert_eq!(host.stats().rebirths, 2);

        // The NBIRTH of the rebirth ends the hold-off: the next gap asks at once.
        let nbirth = node.node_birth(&node_metrics(), at(6_300)).unwrap();
        feed(&mut host, &nbirth, at(6_300));
        let _lost = node
            .device_birth(&id("jbc1"), &station(), at(6_300))
            .unwrap();
        let dbirth = node
            .device_birth(&id("jbc2"), &station(), at(6_300))
            .unwrap();
        let got = feed(&mut host, &dbirth, at(6_400));
        assert_eq!(got.commands.len(), 1);
    }

    #[test]
    fn seq_wraps_from_255_to_0_without_a_gap() {
        let mut host = alone();
        let mut node = born(&mut host);
        for i in 0..300 {
            let t = at(i * 10);
            let got = feed(&mut host, &ddata(&mut node, "jbc1", i as f64, t), t);
            assert_eq!(got.problems, [], "message {i}");
        }
        assert_eq!(host.stats().seq_gaps, 0);
    }

    #[test]
    fn data_before_a_birth_is_dropped_and_asks_for_a_rebirth() {
        let mut host = alone();
        let mut node = connected();
        node.node_birth(&node_metrics(), T0).unwrap();
        node.device_birth(&id("jbc1"), &station(), T0).unwrap();
        let got = feed(&mut host, &ddata(&mut node, "jbc1", 50.0, at(10)), at(10));
        assert_eq!(got.samples, []);
        assert_eq!(
            got.problems[0].problem,
            Problem::NodeNotBorn {
                message_type: "DDATA".into()
            }
        );
        assert_eq!(got.commands.len(), 1);
        assert!(is_rebirth_of_gw1(&got.commands[0]));
        assert_eq!(host.stats().dropped, 1);
        // More data within 5 s: dropped, no second request.
        let got = feed(&mut host, &ddata(&mut node, "jbc1", 51.0, at(20)), at(20));
        assert_eq!(got.commands, []);
        assert_eq!(host.stats().dropped, 2);
    }

    #[test]
    fn data_of_a_device_never_born_and_an_unknown_alias_ask_for_a_rebirth() {
        let mut host = alone();
        let mut node = born(&mut host);
        let jbc3 = node.device_birth(&id("jbc3"), &station(), T0).unwrap();
        let _ = jbc3; // not delivered to the host
        let got = feed(&mut host, &ddata(&mut node, "jbc3", 1.0, at(10)), at(10));
        assert_eq!(
            got.problems.iter().map(|p| &p.problem).collect::<Vec<_>>(),
            [
                &Problem::SeqGap {
                    expected: 3,
                    got: 4
                },
                &Problem::DeviceNotBorn { device: id("jbc3") }
            ]
        );
        assert_eq!(got.commands.len(), 1, "one request per message");

        let mut host = alone();
        let mut node = born(&mut host);
        let data = ddata(&mut node, "jbc1", 60.0, at(10));
        let mut payload = Payload::decode(&data.payload[..]).unwrap();
        let mut unknown = payload.metrics[0].clone();
        unknown.alias = Some(999);
        payload.metrics.push(unknown);
        let got = host.receive(&data.topic.to_string(), &payload.encode_to_vec(), at(10));
        assert_eq!(got.samples.len(), 1, "the known metric is kept");
        assert_eq!(
            got.problems[0].problem,
            Problem::UnknownAlias {
                device: Some(id("jbc1")),
                alias: 999
            }
        );
        assert_eq!(
            got.problems[0].to_string(),
            "spBv1.0/cell/DDATA/gw1/jbc1: device jbc1 has no metric with alias 999 in its \
             birth: dropped"
        );
        assert_eq!(got.commands.len(), 1);
        assert_eq!(host.stats().dropped, 1);
    }

    #[test]
    fn an_alias_a_birth_gives_twice_resolves_no_data_and_is_a_problem() {
        let mut host = alone();
        let mut node = born(&mut host);
        let dbirth = node.device_birth(&id("jbc9"), &station(), T0).unwrap();
        let mut payload = Payload::decode(&dbirth.payload[..]).unwrap();
        let shared = payload.metrics[0].alias.expect("births give aliases");
        payload.metrics[1].alias = Some(shared);
        let got = host.receive(&dbirth.topic.to_string(), &payload.encode_to_vec(), at(1));
        assert_eq!(
            got.problems.iter().map(|p| &p.problem).collect::<Vec<_>>(),
            [&Problem::DuplicateAlias { alias: shared }]
        );
        assert_eq!(
            got.points.len(),
            station().len(),
            "the points are still defined"
        );

        let data = ddata(&mut node, "jbc9", 60.0, at(10));
        let mut payload = Payload::decode(&data.payload[..]).unwrap();
        let mut by_alias = payload.metrics[0].clone();
        by_alias.name = None;
        by_alias.alias = Some(shared);
        let mut by_name = by_alias.clone();
        by_name.name = Some("air_temp".into());
        payload.metrics = vec![by_alias, by_name];
        let got = host.receive(&data.topic.to_string(), &payload.encode_to_vec(), at(10));
        assert_eq!(
            got.samples
                .iter()
                .map(|s| s.point.name.as_str())
                .collect::<Vec<_>>(),
            ["air_temp"],
            "only the metric that also has its name"
        );
        assert!(
            got.problems.iter().any(|p| p.problem
                == Problem::UnknownAlias {
                    device: Some(id("jbc9")),
                    alias: shared
                }),
            "{:?}",
            got.problems
        );
    }

    #[test]
    fn ndeath_with_the_current_bd_seq_marks_every_point_of_the_node_and_its_devices_bad() {
        let mut host = alone();
        let (mut node, will) = born_with_will(&mut host);
        let got = feed(&mut host, &will, at(9_000));
        assert_eq!(got.problems, []);
        assert_eq!(
            got.samples.len(),
            1 + 4 + 4,
            "Gateway/Lines and both stations"
        );
        assert!(got.samples.iter().all(|s| s.t == at(9_000)
            && s.value == SampleValue::Null
            && s.quality == Quality::Bad
            && !s.historical));
        let mut points: Vec<_> = got.samples.iter().map(|s| (*s.point).clone()).collect();
        points.sort();
        assert!(points.contains(&key(None, "Gateway/Lines")));
        assert!(points.contains(&key(Some("jbc2"), "status")));

        // Dead: a second death changes nothing, and its data asks for a rebirth.
        let got = feed(&mut host, &will, at(9_001));
        assert_eq!(got, Received::default());
        let got = feed(
            &mut host,
            &ddata(&mut node, "jbc1", 1.0, at(9_002)),
            at(9_002),
        );
        assert_eq!(got.samples, []);
        assert_eq!(got.commands.len(), 1);
    }

    #[test]
    fn a_stale_ndeath_of_an_older_session_is_ignored() {
        let mut host = alone();
        let mut node = EdgeNode::new(id("cell"), id("gw1"), BdSeq::new(7));
        let old_will = node.will();
        node.on_connect();
        feed(
            &mut host,
            &node.node_birth(&node_metrics(), T0).unwrap(),
            T0,
        );
        // Reconnected: session 8 is born before the broker gives up on session 7.
        let new_will = node.will();
        node.on_connect();
        feed(
            &mut host,
            &node.node_birth(&node_metrics(), at(10)).unwrap(),
            at(10),
        );
        feed(
            &mut host,
            &node.device_birth(&id("jbc1"), &station(), at(10)).unwrap(),
            at(10),
        );

        let got = feed(&mut host, &old_will, at(20));
        assert_eq!(got.samples, []);
        assert_eq!(
            got.problems[0].problem,
            Problem::StaleDeath {
                death: Some(7),
                birth: Some(8)
            }
        );
        assert_eq!(host.stats().stale_deaths, 1);
        // Still born: its data is recorded.
        let got = feed(&mut host, &ddata(&mut node, "jbc1", 70.0, at(30)), at(30));
        assert_eq!((got.samples.len(), got.commands.len()), (1, 0));
        // The current session's Will marks it dead.
        let got = feed(&mut host, &new_will, at(40));
        assert_eq!(got.samples.len(), 1 + 4);
    }

    #[test]
    fn ddeath_marks_that_devices_points_bad_and_its_later_data_asks_for_a_rebirth() {
        let mut host = alone();
        let mut node = born(&mut host);
        let death = node.device_death(&id("jbc2"), at(500)).unwrap();
        let got = feed(&mut host, &death, at(510));
        assert_eq!(got.problems, []);
        assert_eq!(got.samples.len(), 4);
        assert!(
            got.samples
                .iter()
                .all(|s| s.point.device() == Some(&id("jbc2"))
                    && s.t == at(500)
                    && s.quality == Quality::Bad)
        );
        // jbc1 lives on.
        let got = feed(&mut host, &ddata(&mut node, "jbc1", 80.0, at(600)), at(600));
        assert_eq!((got.samples.len(), got.commands.len()), (1, 0));
        // Data of the dead device (a node that ignores its own DDEATH): rebirth.
        let mut node2 = EdgeNode::new(id("cell"), id("gw1"), BdSeq::new(0));
        node2.on_connect();
        node2.node_birth(&node_metrics(), T0).unwrap();
        node2.device_birth(&id("jbc2"), &station(), T0).unwrap();
        let mut stray = ddata(&mut node2, "jbc2", 1.0, at(700));
        let mut payload = Payload::decode(&stray.payload[..]).unwrap();
        payload.seq = Some(u64::from(node.seq()));
        stray.payload = payload.encode_to_vec();
        let got = feed(&mut host, &stray, at(700));
        assert_eq!(
            got.problems[0].problem,
            Problem::DeviceNotBorn { device: id("jbc2") }
        );
        assert_eq!(got.commands.len(), 1);
    }

    #[test]
    fn a_gateway_event_arrives_with_its_kind_severity_device_point_and_line() {
        let mut host = alone();
        let mut node = born(&mut host);
        let event = NodeEvent {
            fields: Some(r#"{"value":3}"#.into()),
            t: at(123),
            kind: "alarm_raised".into(),
            severity: 700,
            message: "jbc1: tool error".into(),
            line: Some("line1".into()),
            device: Some("jbc1".into()),
            point: Some("error".into()),
        };
        let published = node.node_event(&event, at(130)).unwrap();
        assert_eq!(published.topic.to_string(), "spBv1.0/cell/NDATA/gw1");
        let got = feed(&mut host, &published, at(140));
        assert_eq!(got.problems, []);
        assert_eq!(got.samples, [], "an event is no sample");
        assert_eq!(
            got.events,
            [HostEvent {
                group: id("cell"),
                node: id("gw1"),
                device: Some("jbc1".into()),
                point: Some("error".into()),
                line: Some("line1".into()),
                t: at(123),
                kind: Some("alarm_raised".into()),
                severity: Some(700),
                message: "jbc1: tool error".into(),
                fields: Some(r#"{"value":3}"#.into()),
                historical: false,
            }]
        );
        // Twice the same event is two events.
        let again = node.node_event(&event, at(131)).unwrap();
        assert_eq!(feed(&mut host, &again, at(141)).events.len(), 1);
        assert_eq!(host.stats().events, 2);
    }

    #[test]
    fn an_event_severity_of_any_number_type_is_read_by_its_sign_and_kept_within_1_to_1000() {
        use crate::proto::{PropertyValue, property_value::Value as P};
        let mut host = alone();
        let mut node = born(&mut host);
        let event = NodeEvent {
            fields: None,
            t: at(123),
            kind: "alarm_raised".into(),
            severity: 700,
            message: "over".into(),
            line: None,
            device: None,
            point: None,
        };
        let published = node.node_event(&event, at(130)).unwrap();
        let template = Payload::decode(&published.payload[..]).unwrap();
        let severity_of = |host: &mut Host, datatype: DataType, value: P| {
            let mut payload = template.clone();
            let properties = payload.metrics[0].properties.as_mut().unwrap();
            let i = properties
                .keys
                .iter()
                .position(|k| k == "severity")
                .unwrap();
            properties.values[i] = PropertyValue {
                r#type: Some(datatype.code()),
                is_null: None,
                value: Some(value),
            };
            payload.seq = None;
            let got = host.receive(
                &published.topic.to_string(),
                &payload.encode_to_vec(),
                at(140),
            );
            got.events[0].severity
        };
        assert_eq!(
            severity_of(
                &mut host,
                DataType::Int32,
                P::IntValue(u32::from_ne_bytes((-5i32).to_ne_bytes()))
            ),
            Some(1)
        );
        assert_eq!(
            severity_of(
                &mut host,
                DataType::Int64,
                P::LongValue(u64::from_ne_bytes((-5i64).to_ne_bytes()))
            ),
            Some(1)
        );
        assert_eq!(
            severity_of(&mut host, DataType::Double, P::DoubleValue(700.0)),
            Some(700)
        );
        assert_eq!(
            severity_of(&mut host, DataType::UInt32, P::IntValue(5000)),
            Some(1000)
        );
        assert_eq!(
            severity_of(&mut host, DataType::UInt64, P::LongValue(u64::MAX)),
            Some(1000)
        );
        assert_eq!(
            severity_of(&mut host, DataType::String, P::StringValue("high".into())),
            None
        );
    }

    #[test]
    fn garbage_and_truncated_payloads_are_problems_not_panics() {
        let mut host = alone();
        let mut node = born(&mut host);
        let got = host.receive("spBv1.0/cell/DDATA/gw1/jbc1", &[0xff; 12], at(1));
        assert!(matches!(got.problems[0].problem, Problem::Undecodable(_)));
        let got = host.receive("spBv1.0/cell/NOPE/gw1", &[], at(1));
        assert!(matches!(got.problems[0].problem, Problem::Topic(_)));
        assert_eq!(host.stats().undecodable, 2);

        let nbirth = node.node_birth(&node_metrics(), at(2)).unwrap();
        let dbirth = node.device_birth(&id("jbc1"), &station(), at(2)).unwrap();
        let data = ddata(&mut node, "jbc1", 9.0, at(3));
        let mut undecodable = 0;
        for message in [&nbirth, &dbirth, &data] {
            let topic = message.topic.to_string();
            for end in 0..message.payload.len() {
                let got = host.receive(&topic, &message.payload[..end], at(4));
                undecodable += got
                    .problems
                    .iter()
                    .filter(|p| matches!(p.problem, Problem::Undecodable(_)))
                    .count();
            }
        }
        assert!(undecodable > 0, "cut inside a field is undecodable");
        assert_eq!(host.stats().undecodable, 2 + undecodable as u64);
    }

    /// A host within `limits`, following `cell`.
    fn limited(limits: Limits) -> Host {
        alone().with_limits(limits)
    }

    /// `p` with its payload changed by `change`.
    fn edited(p: &Publish, change: impl FnOnce(&mut Payload)) -> Publish {
        let mut payload = Payload::decode(&p.payload[..]).unwrap();
        change(&mut payload);
        Publish {
            payload: payload.encode_to_vec(),
            ..p.clone()
        }
    }

    #[test]
    fn a_birth_past_the_point_cap_is_refused_whole_and_not_asked_again_at_once() {
        // The NBIRTH's 4 metrics (bdSeq, Rebirth, Event, Gateway/Lines) and jbc1's 4 fit;
        // jbc2's 4 would make 12.
        let mut host = limited(Limits {
            max_points: 11,
            ..Limits::default()
        });
        let mut node = connected();
        feed(
            &mut host,
            &node.node_birth(&node_metrics(), T0).unwrap(),
            T0,
        );
        let jbc1 = node.device_birth(&id("jbc1"), &station(), T0).unwrap();
        assert_eq!(feed(&mut host, &jbc1, T0).problems, []);
        assert_eq!(host.points_held(), 8);

        let jbc2 = node.device_birth(&id("jbc2"), &station(), T0).unwrap();
        let got = feed(&mut host, &jbc2, T0);
        assert_eq!(
            (got.points.len(), got.samples.len()),
            (0, 0),
            "refused whole"
        );
        assert_eq!(got.commands, []);
        assert_eq!(
            got.problems[0].problem,
            Problem::BirthRefused {
                metrics: 4,
                cap: Cap::Points,
                max: 11
            }
        );
        let words = got.problems[0].to_string();
        assert!(
            words.starts_with("spBv1.0/cell/DBIRTH/gw1/jbc2: a birth of 4 metrics refused")
                && words.contains("more than 11 metrics")
                && words.contains("5 min"),
            "{words}"
        );
        assert_eq!(host.stats().births_refused, 1);
        assert_eq!(host.points_held(), 8);

        // jbc2 stays unborn, and its data asks for no Rebirth for 5 minutes, not 5 s.
        for (offset, asked) in [(1_000, 0), (6_000, 0), (299_000, 0), (301_000, 1)] {
            let got = feed(
                &mut host,
                &ddata(&mut node, "jbc2", offset as f64, at(offset)),
                at(offset),
            );
            assert_eq!(got.samples, []);
            assert_eq!(
                got.problems[0].problem,
                Problem::DeviceNotBorn { device: id("jbc2") }
            );
            assert_eq!(got.commands.len(), asked, "at +{offset} ms");
        }
        // jbc1 lives on.
        let got = feed(
            &mut host,
            &ddata(&mut node, "jbc1", 2.0, at(302_000)),
            at(302_000),
        );
        assert_eq!((got.samples.len(), got.problems.len()), (1, 0));
    }

    #[test]
    fn a_node_birth_past_the_per_node_cap_is_refused_and_a_smaller_one_is_taken() {
        let mut host = limited(Limits {
            max_node_points: 7,
            ..Limits::default()
        });
        let mut node = connected();
        let lines = (0..4).map(|i| {
            (
                MetricSpec::new(name(&format!("Line {i}")), DataType::Int64),
                Sample::good(MetricValue::Int64(i), T0),
            )
        });
        let big: Vec<_> = node_metrics().into_iter().chain(lines).collect();
        let got = feed(&mut host, &node.node_birth(&big, T0).unwrap(), T0);
        assert_eq!(got.points, []);
        assert!(matches!(
            got.problems[0].problem,
            Problem::BirthRefused {
                metrics: 8,
                cap: Cap::NodePoints,
                max: 7
            }
        ));
        assert_eq!(host.nodes_born(), 0);
        let dbirth = node.device_birth(&id("jbc1"), &station(), T0).unwrap();
        let got = feed(&mut host, &dbirth, at(6_000));
        assert!(matches!(
            got.problems[0].problem,
            Problem::NodeNotBorn { .. }
        ));
        assert_eq!(got.commands, [], "not asked again 6 s after a refusal");

        // The node's own rebirth with fewer metrics is taken, and its DBIRTH then passes
        // the node's limit (4 + 4 > 7).
        node.on_connect();
        let got = feed(
            &mut host,
            &node.node_birth(&node_metrics(), at(7_000)).unwrap(),
            at(7_000),
        );
        assert_eq!((got.problems.len(), got.points.len()), (0, 1));
        let dbirth = node
            .device_birth(&id("jbc1"), &station(), at(7_000))
            .unwrap();
        let got = feed(&mut host, &dbirth, at(7_000));
        assert!(matches!(
            got.problems[0].problem,
            Problem::BirthRefused {
                cap: Cap::NodePoints,
                ..
            }
        ));
        assert_eq!(host.points_held(), 4);
    }

    #[test]
    fn a_new_node_past_the_node_cap_is_refused_unless_an_unborn_one_makes_room() {
        let mut host = limited(Limits {
            max_nodes: 1,
            ..Limits::default()
        });
        let (_gw1, gw1_will) = born_with_will(&mut host);
        let mut gw2 = EdgeNode::new(id("cell"), id("gw2"), BdSeq::new(0));
        gw2.on_connect();
        let birth = gw2.node_birth(&node_metrics(), at(10)).unwrap();
        let got = feed(&mut host, &birth, at(10));
        assert!(matches!(
            got.problems[0].problem,
            Problem::BirthRefused {
                cap: Cap::Nodes,
                max: 1,
                ..
            }
        ));
        // Its data asks for nothing: no state is kept for it.
        let data = gw2.node_event(&event_at(at(20)), at(20)).unwrap();
        let got = feed(&mut host, &data, at(20));
        assert!(matches!(
            got.problems[0].problem,
            Problem::NodeNotBorn { .. }
        ));
        assert_eq!((got.commands.len(), host.nodes_known()), (0, 1));

        // gw1 dies: its place may go to gw2.
        feed(&mut host, &gw1_will, at(30));
        let got = feed(&mut host, &birth, at(40));
        assert_eq!(got.problems, []);
        assert_eq!((host.nodes_born(), host.nodes_known()), (1, 1));
        assert_eq!(host.points_held(), 4, "gw1's 12 given back, gw2's 4 taken");
    }

    fn event_at(t: Timestamp) -> NodeEvent {
        NodeEvent {
            t,
            kind: "line_down".into(),
            severity: 500,
            message: "line1 down".into(),
            line: None,
            device: None,
            point: None,
            fields: None,
        }
    }

    #[test]
    fn a_dead_nodes_state_is_freed_after_the_grace() {
        let mut host = alone();
        let (_node, will) = born_with_will(&mut host);
        let mut other = EdgeNode::new(id("cell"), id("gw2"), BdSeq::new(0));
        other.on_connect();
        feed(
            &mut host,
            &other.node_birth(&node_metrics(), T0).unwrap(),
            T0,
        );
        feed(&mut host, &will, at(1_000));
        assert_eq!((host.nodes_born(), host.nodes_known()), (1, 2));
        assert_eq!(host.points_held(), 4);

        // Any message looks, at most once a minute: 9 minutes after the death gw1 is kept.
        let nothing = |host: &mut Host, t| host.receive("spBv1.0/STATE/other", b"{}", t);
        nothing(&mut host, at(1_000 + 9 * 60_000));
        assert_eq!(host.nodes_known(), 2);
        nothing(&mut host, at(1_000 + DEAD_NODE_GRACE_MS + 60_000));
        assert_eq!(host.nodes_known(), 1, "gw1 freed, gw2 (born) kept");
        assert_eq!(host.stats().nodes_freed, 1);
        // A message of gw1's dead session changes nothing; a new birth is read as ever.
        assert_eq!(
            feed(&mut host, &will, at(DEAD_NODE_GRACE_MS * 2)),
            Received::default()
        );
    }

    #[test]
    fn a_death_for_an_offline_host_marks_the_points_stale_not_bad() {
        let mut host = alone();
        let (mut node, _will) = born_with_will(&mut host);
        let death = node.host_offline_death(at(9_000)).unwrap();
        let got = feed(&mut host, &death, at(9_010));
        assert_eq!(got.problems, []);
        assert_eq!(
            got.samples.len(),
            1 + 4 + 4,
            "Gateway/Lines and both stations"
        );
        assert!(got.samples.iter().all(|s| s.t == at(9_000)
            && s.value == SampleValue::Null
            && s.quality == Quality::Stale));
        // Unborn as after any death: its data asks for a rebirth.
        let got = feed(
            &mut host,
            &ddata(&mut node, "jbc1", 1.0, at(9_100)),
            at(9_100),
        );
        assert_eq!((got.samples.len(), got.commands.len()), (0, 1));
        assert_eq!(host.points_held(), 0);
    }

    #[test]
    fn metric_names_with_a_right_to_left_override_are_left_out() {
        let mut host = alone();
        let mut node = born(&mut host);
        node.on_connect();
        feed(
            &mut host,
            &node.node_birth(&node_metrics(), at(1)).unwrap(),
            at(1),
        );
        let long = "x".repeat(300);
        let dbirth = edited(
            &node.device_birth(&id("jbc1"), &station(), at(1)).unwrap(),
            |payload| {
                // air_temp shows as "air_temp" followed by a reversed "lio": "air_templio"
                // would read "air_tempoil" in a table.
                payload.metrics[0].name = Some("air_temp\u{202e}lio".into());
                payload.metrics[1].name = Some(long.clone());
                payload.metrics[2].name = Some("heater\non".into());
            },
        );
        let got = feed(&mut host, &dbirth, at(2));
        let names: Vec<_> = got.points.iter().map(|p| p.point.name.as_str()).collect();
        assert_eq!(names, ["status"]);
        assert_eq!(got.samples.len(), 1);
        let problems: Vec<_> = got.problems.iter().map(|p| p.to_string()).collect();
        assert_eq!(problems.len(), 3, "{problems:#?}");
        assert!(
            problems[0].contains("birth metric 0")
                && problems[0].contains(r"\u{202e}")
                && !problems[0].contains('\u{202e}')
                && problems[0].ends_with("left out"),
            "{}",
            problems[0]
        );
        assert!(
            problems[1].contains("300 bytes long") && !problems[1].contains(&long),
            "{}",
            problems[1]
        );
        assert_eq!(host.stats().names_refused, 3);
        // Their data, by alias, is dropped without asking for a rebirth each time.
        let got = feed(&mut host, &ddata(&mut node, "jbc1", 3.0, at(3)), at(3));
        assert_eq!(got, Received::default());
        assert_eq!(host.stats().dropped, 1);
    }

    #[test]
    fn a_message_whose_ids_are_too_long_or_hold_control_characters_is_refused_whole() {
        let mut host = alone();
        let mut node = born(&mut host);
        let birth = node.device_birth(&id("jbc1"), &station(), T0).unwrap();
        let device = "d".repeat(60_000);
        for (topic, level) in [
            (format!("spBv1.0/cell/DBIRTH/gw1/{device}"), "device id"),
            (
                "spBv1.0/cell/DBIRTH/gw1/jbc\u{202e}1".to_owned(),
                "device id",
            ),
            ("spBv1.0/cell/NBIRTH/gw\u{7}1".to_owned(), "edge node id"),
        ] {
            let got = host.receive(&topic, &birth.payload, at(1));
            assert_eq!((got.points.len(), got.samples.len()), (0, 0));
            let Problem::Topic(TopicError::Id {
                level: got_level, ..
            }) = &got.problems[0].problem
            else {
                panic!("{:?}", got.problems);
            };
            assert_eq!(*got_level, level);
            assert!(
                got.problems[0].to_string().len() < 2_000,
                "the problem does not repeat a 60 kB topic"
            );
        }
        assert_eq!(host.nodes_known(), 1);
    }

    #[test]
    fn a_state_offline_on_the_hosts_own_topic_is_answered_with_the_sessions_own_online() {
        let host = alone();
        let online_at = at(10);
        let now = at(60_000);
        assert_eq!(
            host.state_subscription(),
            Subscription {
                filter: "spBv1.0/STATE/historian".into(),
                qos: Qos::AtLeastOnce
            }
        );
        let answer = |payload: &[u8]| {
            host.reassert_online(payload, online_at).map(|p| {
                assert_eq!(p.topic.to_string(), "spBv1.0/STATE/historian");
                assert_eq!((p.qos, p.retain), (Qos::AtLeastOnce, true));
                HostState::from_json(&p.payload).unwrap()
            })
        };
        let state = |online, t: Timestamp| HostState::new(online, t).to_json();
        assert_eq!(answer(&state(true, online_at)), None, "its own online");
        assert_eq!(
            answer(&state(true, at(1))),
            None,
            "an online is never answered"
        );
        // Forged now, ahead, at the session's own time, older, far ahead, or no STATE at
        // all: always this session's own online, whose time its Will shares (a newer one
        // would make the edge nodes ignore the Will).
        for payload in [
            state(false, now),
            state(false, at(65_000)),
            state(false, online_at),
            state(false, at(9)),
            state(false, at(253_402_300_799_000)),
            b"not json".to_vec(),
        ] {
            assert_eq!(answer(&payload), Some(HostState::new(true, online_at)));
        }
    }

    /// One step of a random plant: what an edge node (of three) publishes.
    #[derive(Debug, Clone)]
    enum Step {
        /// A new session and its NBIRTH of this many metrics of its own.
        NodeBirth(usize, usize),
        /// A DBIRTH of device 0–2 with this many metrics.
        DeviceBirth(usize, usize, usize),
        /// A DDEATH of device 0–2.
        DeviceDeath(usize, usize),
        /// The session's Will.
        NodeDeath(usize),
        /// The NDEATH of a node whose primary host went offline.
        HostOffline(usize),
    }

    fn step() -> impl proptest::strategy::Strategy<Value = Step> {
        use proptest::prelude::*;
        prop_oneof![
            (0..3usize, 0..8usize).prop_map(|(n, k)| Step::NodeBirth(n, k)),
            (0..3usize, 0..3usize, 0..8usize).prop_map(|(n, d, k)| Step::DeviceBirth(n, d, k)),
            (0..3usize, 0..3usize).prop_map(|(n, d)| Step::DeviceDeath(n, d)),
            (0..3usize).prop_map(Step::NodeDeath),
            (0..3usize).prop_map(Step::HostOffline),
        ]
    }

    fn metrics(k: usize) -> Vec<(MetricSpec, Sample)> {
        (0..k)
            .map(|i| {
                (
                    MetricSpec::new(name(&format!("m{i}")), DataType::Int64),
                    Sample::good(MetricValue::Int64(i as i64), T0),
                )
            })
            .collect()
    }

    proptest::proptest! {
        #[test]
        fn any_births_and_deaths_keep_within_the_limits_and_give_every_point_back(
            steps in proptest::collection::vec(step(), 0..60),
        ) {
            let limits = Limits { max_nodes: 2, max_node_points: 12, max_points: 20 };
            let mut host = limited(limits);
            let mut nodes: Vec<EdgeNode> = (0..3)
                .map(|n| EdgeNode::new(id("cell"), id(&format!("gw{n}")), BdSeq::new(0)))
                .collect();
            let mut wills: Vec<Option<Publish>> = vec![None, None, None];
            for (i, step) in steps.into_iter().enumerate() {
                let t = at(i as u64 * 1_000);
                let published = match step {
                    Step::NodeBirth(n, k) => {
                        wills[n] = Some(nodes[n].will());
                        nodes[n].on_connect();
                        nodes[n].node_birth(&metrics(k), t).ok()
                    }
                    Step::DeviceBirth(n, d, k) => nodes[n]
                        .device_birth(&id(&format!("d{d}")), &metrics(k), t)
                        .ok(),
                    Step::DeviceDeath(n, d) => {
                        nodes[n].device_death(&id(&format!("d{d}")), t).ok()
                    }
                    Step::NodeDeath(n) => wills[n].clone(),
                    Step::HostOffline(n) => nodes[n].host_offline_death(t),
                };
                if let Some(p) = published {
                    feed(&mut host, &p, t);
                }
                proptest::prop_assert!(host.points_held() <= limits.max_points);
                proptest::prop_assert!(host.nodes_known() <= limits.max_nodes);
            }
            // Every session's Will: nothing is held any more.
            for will in wills.into_iter().flatten() {
                feed(&mut host, &will, at(100_000));
            }
            proptest::prop_assert_eq!(host.nodes_born(), 0);
            proptest::prop_assert_eq!(host.points_held(), 0);
        }
    }

    proptest::proptest! {
        #[test]
        fn any_bytes_on_any_topic_never_panic(
            bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..200),
            topic in 0usize..8,
        ) {
            let topics = [
                "spBv1.0/cell/NBIRTH/gw1",
                "spBv1.0/cell/NDATA/gw1",
                "spBv1.0/cell/NDEATH/gw1",
                "spBv1.0/cell/DBIRTH/gw1/jbc1",
                "spBv1.0/cell/DDATA/gw1/jbc1",
                "spBv1.0/cell/DDEATH/gw1/jbc1",
                "spBv1.0/STATE/other",
                "garbage/#",
            ];
            let mut host = alone();
            born(&mut host);
            let before = host.stats().messages;
            let got = host.receive(topics[topic], &bytes, at(1));
            proptest::prop_assert_eq!(host.stats().messages, before + 1);
            proptest::prop_assert!(got.commands.len() <= 1);
        }
    }

    #[test]
    fn alone_subscribes_to_the_six_message_types_of_its_group_and_not_to_state_or_commands() {
        let subscriptions = alone().subscriptions();
        let filters: Vec<_> = subscriptions
            .iter()
            .map(|s| (s.filter.as_str(), s.qos))
            .collect();
        assert_eq!(
            filters,
            [
                ("spBv1.0/cell/NBIRTH/+", Qos::AtLeastOnce),
                ("spBv1.0/cell/NDEATH/+", Qos::AtLeastOnce),
                ("spBv1.0/cell/DBIRTH/+/+", Qos::AtLeastOnce),
                ("spBv1.0/cell/DDEATH/+/+", Qos::AtLeastOnce),
                ("spBv1.0/cell/NDATA/+", Qos::AtMostOnce),
                ("spBv1.0/cell/DDATA/+/+", Qos::AtMostOnce),
            ]
        );
        let every_group = Host::new(id("h"), None, Sharing::Alone).subscriptions();
        assert_eq!(every_group[0].filter, "spBv1.0/+/NBIRTH/+");
    }

    #[test]
    fn shared_mode_subscribes_births_unshared_and_data_shared_and_asks_no_rebirth_on_a_gap() {
        let sharing = Sharing::Shared { name: id("plant") };
        let mut host = Host::new(id("historian-2"), Some(id("cell")), sharing);
        let filters: Vec<_> = host.subscriptions().into_iter().map(|s| s.filter).collect();
        assert_eq!(
            filters,
            [
                "spBv1.0/cell/NBIRTH/+",
                "spBv1.0/cell/NDEATH/+",
                "spBv1.0/cell/DBIRTH/+/+",
                "spBv1.0/cell/DDEATH/+/+",
                "$share/plant/spBv1.0/cell/NDATA/+",
                "$share/plant/spBv1.0/cell/DDATA/+/+",
            ]
        );
        let mut node = born(&mut host);
        let _taken_by_another_host = ddata(&mut node, "jbc1", 1.0, at(10));
        let got = feed(&mut host, &ddata(&mut node, "jbc1", 2.0, at(20)), at(20));
        assert_eq!((got.problems.len(), got.commands.len()), (0, 0));
        assert_eq!(got.samples.len(), 1);
        assert_eq!(host.stats().seq_gaps, 0);
        // Data before a birth still asks for one.
        let mut stranger = EdgeNode::new(id("cell"), id("gw9"), BdSeq::new(0));
        stranger.on_connect();
        stranger.node_birth(&[], T0).unwrap();
        stranger.device_birth(&id("d"), &station(), T0).unwrap();
        let got = feed(&mut host, &ddata(&mut stranger, "d", 1.0, at(30)), at(30));
        assert_eq!(got.commands.len(), 1);
        assert_eq!(got.commands[0].topic.to_string(), "spBv1.0/cell/NCMD/gw9");
    }

    #[test]
    fn state_online_and_will_are_retained_qos1_json_on_the_hosts_state_topic() {
        let host = alone();
        let will = host.will(at(0));
        let online = host.state_online(at(0));
        for (p, online_flag) in [(&will, false), (&online, true)] {
            assert_eq!(p.topic.to_string(), "spBv1.0/STATE/historian");
            assert_eq!((p.qos, p.retain), (Qos::AtLeastOnce, true));
            let state = HostState::from_json(&p.payload).unwrap();
            assert_eq!(state, HostState::new(online_flag, T0));
        }
    }

    #[test]
    fn other_groups_state_and_commands_are_ignored() {
        let mut host = alone();
        born(&mut host);
        let state = HostState::new(true, T0).publish(id("other"));
        assert_eq!(feed(&mut host, &state, at(1)), Received::default());
        let ncmd = rebirth_request(&id("cell"), &id("gw1"), at(1));
        assert_eq!(feed(&mut host, &ncmd, at(1)), Received::default());
        let mut elsewhere = EdgeNode::new(id("line2"), id("gw1"), BdSeq::new(0));
        elsewhere.on_connect();
        let birth = elsewhere.node_birth(&node_metrics(), T0).unwrap();
        assert_eq!(feed(&mut host, &birth, at(1)), Received::default());
    }

    #[test]
    fn a_rebirth_request_names_the_rebirth_metric_and_the_edge_node_reads_it() {
        let request = rebirth_request(&id("cell"), &id("gw1"), at(5));
        let payload = Payload::decode(&request.payload[..]).unwrap();
        assert_eq!(payload.metrics[0].name.as_deref(), Some(REBIRTH));
        assert_eq!(payload.timestamp, Some(at(5).as_millis()));
        assert!(is_rebirth_of_gw1(&request));
    }

    #[test]
    fn float32_values_are_the_decimal_they_were_written_as() {
        assert_eq!(
            SampleValue::from(MetricValue::Float(0.1)),
            SampleValue::Number(0.1)
        );
        assert_eq!(
            SampleValue::from(MetricValue::UInt64(u64::MAX)),
            SampleValue::Number(u64::MAX as f64)
        );
        assert_eq!(
            SampleValue::from(MetricValue::DateTime(T0)),
            SampleValue::Number(T0.as_millis() as f64)
        );
    }
}
