//! What a received MQTT message says, for people and for scripts: a Sparkplug payload
//! decoded into its metrics, with data messages' aliases resolved against the births
//! seen before; a host's STATE as its JSON; anything else as text or hex. Sans-IO: the
//! caller feeds `(topic, payload)` and prints [`Description::to_text`] or
//! [`Description::to_json`].
//!
//! Nothing received makes it fail: a payload that is not Sparkplug is described as
//! [`Description::Undecodable`], naming the topic and the decode error, and a metric whose
//! value does not match its datatype gets [`Value::Unreadable`] with the reason.
//!
//! Aliases: an NBIRTH or DBIRTH records alias → (name, datatype) for its node or device
//! (an NBIRTH also forgets the node's devices: they are born again after it). NDATA,
//! DDATA, NCMD and DCMD metrics that carry only an alias get their name and datatype
//! from there, when that birth was seen; a metric named without a datatype gets the
//! birth's datatype.
//!
//! Properties: a birth's metric shows its unit, writability and documentation in words;
//! a data metric shows every property other than `Quality` as `key=value` (a gateway
//! event's `kind`, `severity`, `device`, …, see [`crate::event`]). JSON shows them all.

use std::collections::HashMap;
use std::fmt::Write as _;

use serde::Serialize;
use serde::ser::{SerializeMap, Serializer};

use crate::births::Table;
use crate::metric::{
    DOCUMENTATION, DataType, ENG_UNIT, MetricValue, QUALITY, Quality, WRITABLE, WRITE_MAX,
    WRITE_MIN,
};
use crate::proto::{Metric, PropertySet, PropertyValue, metric, property_value};
use crate::topic::{Id, MessageKind, NAMESPACE, Topic};

/// What one message says.
#[derive(Debug, Clone, PartialEq)]
pub enum Description {
    /// A Sparkplug NBIRTH/NDATA/NDEATH/NCMD or DBIRTH/DDATA/DDEATH/DCMD.
    Sparkplug(SparkplugMessage),
    /// A host application's `spBv1.0/STATE/{host}`: its payload as received.
    State {
        /// The MQTT topic.
        topic: String,
        /// The host id.
        host: String,
        /// The payload (JSON, if the host keeps to the spec).
        payload: RawPayload,
    },
    /// A `spBv1.0/…` message that cannot be read as Sparkplug.
    Undecodable {
        /// The MQTT topic.
        topic: String,
        /// What is wrong, in words.
        error: String,
    },
    /// A message on a topic outside Sparkplug.
    Other {
        /// The MQTT topic.
        topic: String,
        /// The payload.
        payload: RawPayload,
    },
}

/// A payload that is not protobuf: text if it is UTF-8, else bytes.
#[derive(Debug, Clone, PartialEq)]
pub enum RawPayload {
    /// Valid UTF-8.
    Text(String),
    /// Anything else.
    Bytes(Vec<u8>),
}

impl RawPayload {
    fn new(payload: &[u8]) -> Self {
        match std::str::from_utf8(payload) {
            Ok(text) => Self::Text(text.to_owned()),
            Err(_) => Self::Bytes(payload.to_vec()),
        }
    }

    fn text(&self) -> String {
        match self {
            Self::Text(text) => text.clone(),
            Self::Bytes(bytes) => hex(bytes),
        }
    }

    fn encoding(&self) -> &'static str {
        match self {
            Self::Text(_) => "text",
            Self::Bytes(_) => "hex",
        }
    }
}

/// A decoded Sparkplug message.
#[derive(Debug, Clone, PartialEq)]
pub struct SparkplugMessage {
    /// The MQTT topic as received.
    pub topic: String,
    /// The message type as the topic spells it (`NBIRTH`, `DDATA`, …).
    pub message_type: String,
    /// Birth, data, death or command.
    pub kind: MessageKind,
    /// The group id.
    pub group: String,
    /// The edge node id.
    pub edge_node: String,
    /// The device id, for device messages.
    pub device: Option<String>,
    /// The payload's `seq`.
    pub seq: Option<u64>,
    /// The payload's timestamp, ms since the Unix epoch.
    pub timestamp: Option<u64>,
    /// The metrics, in payload order.
    pub metrics: Vec<MetricDescription>,
}

/// One metric of a Sparkplug message.
#[derive(Debug, Clone, PartialEq)]
pub struct MetricDescription {
    /// The name, from the metric itself or, for an alias, from the birth.
    pub name: Option<String>,
    /// The alias, if the metric carries one.
    pub alias: Option<u64>,
    /// Whether the name came from a birth (the metric carried only its alias).
    pub resolved: bool,
    /// The datatype code, from the metric or from the birth.
    pub datatype: Option<u32>,
    /// The value.
    pub value: Value,
    /// The `Quality` property, if present and one of the three codes.
    pub quality: Option<Quality>,
    /// `is_historical`.
    pub historical: bool,
    /// `is_transient`.
    pub transient: bool,
    /// The metric's own timestamp, ms since the Unix epoch.
    pub timestamp: Option<u64>,
    /// Every property, in payload order.
    pub properties: Vec<(String, serde_json::Value)>,
}

/// A metric's value as described.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// A value of the metric's datatype.
    Value(MetricValue),
    /// `is_null`, or no value field at all in a death or a metric of unknown type.
    Null,
    /// A value whose datatype is not known (an alias whose birth was not seen): the
    /// field it came in and its plain reading (integers unsigned, bytes as hex).
    Raw {
        /// The protobuf field: `double_value`, `int_value`, …
        field: &'static str,
        /// Its content.
        value: serde_json::Value,
    },
    /// A value that does not match the datatype, or a datatype this crate cannot read.
    Unreadable(String),
}

/// Turns received messages into [`Description`]s, remembering the births seen.
#[derive(Debug, Default)]
pub struct Describer {
    births: HashMap<Owner, Table<Option<u32>>>,
}

/// A node (`device: None`) or one of its devices.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
struct Owner {
    group: Id,
    edge_node: Id,
    device: Option<Id>,
}

impl Describer {
    /// A describer that has seen no birth.
    pub fn new() -> Self {
        Self::default()
    }

    /// Describes the message `payload` received on `topic`; a birth is remembered for
    /// the aliases of later messages.
    pub fn describe(&mut self, topic: &str, payload: &[u8]) -> Description {
        let sparkplug = topic
            .strip_prefix(NAMESPACE)
            .is_some_and(|rest| rest.starts_with('/'));
        if !sparkplug {
            return Description::Other {
                topic: topic.to_owned(),
                payload: RawPayload::new(payload),
            };
        }
        let parsed: Topic = match topic.parse() {
            Ok(parsed) => parsed,
            Err(e) => {
                return Description::Undecodable {
                    topic: topic.to_owned(),
                    error: format!("not a Sparkplug topic: {e}"),
                };
            }
        };
        let message_type = parsed.message_type();
        let (group, kind, edge_node, device) = match parsed.into_edge() {
            Ok(parts) => parts,
            Err(host) => {
                return Description::State {
                    topic: topic.to_owned(),
                    host: host.to_string(),
                    payload: RawPayload::new(payload),
                };
            }
        };
        let decoded = match crate::proto::decode_payload(payload) {
            Ok(decoded) => decoded,
            Err(e) => {
                let error = match e {
                    crate::proto::PayloadError::Undecodable(e) => {
                        format!("not a Sparkplug B payload: {e}")
                    }
                    too_many => too_many.to_string(),
                };
                return Description::Undecodable {
                    topic: topic.to_owned(),
                    error,
                };
            }
        };
        let owner = Owner {
            group,
            edge_node,
            device,
        };
        if kind == MessageKind::Birth {
            self.remember(&owner, &decoded.metrics);
        }
        let known = self.births.get(&owner);
        let metrics = decoded
            .metrics
            .iter()
            .map(|m| describe_metric(m, known))
            .collect();
        Description::Sparkplug(SparkplugMessage {
            topic: topic.to_owned(),
            message_type,
            kind,
            group: owner.group.to_string(),
            edge_node: owner.edge_node.to_string(),
            device: owner.device.as_ref().map(Id::to_string),
            seq: decoded.seq,
            timestamp: decoded.timestamp,
            metrics,
        })
    }

    fn remember(&mut self, owner: &Owner, metrics: &[Metric]) {
        if owner.device.is_none() {
            self.births
                .retain(|o, _| o.group != owner.group || o.edge_node != owner.edge_node);
        }
        self.births.insert(
            owner.clone(),
            Table::of_birth(metrics, |_, _, m| Some(m.datatype)),
        );
    }
}

fn describe_metric(m: &Metric, known: Option<&Table<Option<u32>>>) -> MetricDescription {
    let from_birth = known.and_then(|table| table.lookup(m));
    let resolved = m.name.is_none() && from_birth.is_some();
    let name = m
        .name
        .clone()
        .or_else(|| from_birth.map(|k| k.name.to_string()));
    let datatype = m.datatype.or_else(|| from_birth.and_then(|k| k.extra));
    MetricDescription {
        name,
        alias: m.alias,
        resolved,
        datatype,
        value: value(m, datatype),
        quality: Quality::of(m),
        historical: m.is_historical == Some(true),
        transient: m.is_transient == Some(true),
        timestamp: m.timestamp,
        properties: m.properties.as_ref().map(property_list).unwrap_or_default(),
    }
}

fn value(m: &Metric, datatype: Option<u32>) -> Value {
    if m.is_null == Some(true) {
        return Value::Null;
    }
    let Some(code) = datatype else {
        return match &m.value {
            None => Value::Null,
            Some(raw) => raw_value(raw),
        };
    };
    let datatype = match DataType::from_code(code) {
        Ok(datatype) => datatype,
        Err(_) if m.value.is_none() => return Value::Null,
        Err(_) => {
            return Value::Unreadable(format!("a {} value, not shown", datatype_name(code)));
        }
    };
    match MetricValue::from_proto(datatype, m.value.as_ref()) {
        Ok(v) => Value::Value(v),
        Err(e) => Value::Unreadable(e.to_string()),
    }
}

fn raw_value(raw: &metric::Value) -> Value {
    use metric::Value as V;
    use serde_json::Value as J;
    let (field, value) = match raw {
        &V::IntValue(n) => ("int_value", J::from(n)),
        &V::LongValue(n) => ("long_value", J::from(n)),
        &V::FloatValue(f) => ("float_value", J::from(f)),
        &V::DoubleValue(d) => ("double_value", J::from(d)),
        &V::BooleanValue(b) => ("boolean_value", J::from(b)),
        V::StringValue(s) => ("string_value", J::from(s.as_str())),
        V::BytesValue(b) => ("bytes_value", J::from(hex(b))),
        V::DatasetValue(b) => ("dataset_value", J::from(hex(b))),
        V::TemplateValue(b) => ("template_value", J::from(hex(b))),
        V::ExtensionValue(b) => ("extension_value", J::from(hex(b))),
    };
    Value::Raw { field, value }
}

fn property_list(set: &PropertySet) -> Vec<(String, serde_json::Value)> {
    set.keys
        .iter()
        .zip(&set.values)
        .map(|(k, v)| (k.clone(), property_json(v)))
        .collect()
}

fn property_json(p: &PropertyValue) -> serde_json::Value {
    use property_value::Value as V;
    use serde_json::Value as J;
    if p.is_null == Some(true) {
        return J::Null;
    }
    let Some(value) = &p.value else {
        return J::Null;
    };
    let datatype = p.r#type.and_then(|code| DataType::from_code(code).ok());
    match value {
        &V::IntValue(bits) => match datatype {
            Some(DataType::Int8) => J::from(bits as i32 as i8),
            Some(DataType::Int16) => J::from(bits as i32 as i16),
            Some(DataType::Int32) => J::from(bits as i32),
            _ => J::from(bits),
        },
        &V::LongValue(bits) => match datatype {
            Some(DataType::Int64) => J::from(bits as i64),
            _ => J::from(bits),
        },
        &V::FloatValue(f) => J::from(f),
        &V::DoubleValue(d) => J::from(d),
        &V::BooleanValue(b) => J::from(b),
        V::StringValue(s) => J::from(s.as_str()),
        V::PropertysetValue(set) => J::Object(property_list(set).into_iter().collect()),
        V::PropertysetsValue(list) => J::Array(
            list.propertyset
                .iter()
                .map(|set| J::Object(property_list(set).into_iter().collect()))
                .collect(),
        ),
        V::ExtensionValue(bytes) => J::from(hex(bytes)),
    }
}

/// The spec's name of a datatype code (`Double`, `DataSet`, `Int32Array`), or
/// `datatype N` for a code it does not define.
pub fn datatype_name(code: u32) -> String {
    const NAMES: [&str; 35] = [
        "Unknown",
        "Int8",
        "Int16",
        "Int32",
        "Int64",
        "UInt8",
        "UInt16",
        "UInt32",
        "UInt64",
        "Float",
        "Double",
        "Boolean",
        "String",
        "DateTime",
        "Text",
        "UUID",
        "DataSet",
        "Bytes",
        "File",
        "Template",
        "PropertySet",
        "PropertySetList",
        "Int8Array",
        "Int16Array",
        "Int32Array",
        "Int64Array",
        "UInt8Array",
        "UInt16Array",
        "UInt32Array",
        "UInt64Array",
        "FloatArray",
        "DoubleArray",
        "BooleanArray",
        "StringArray",
        "DateTimeArray",
    ];
    usize::try_from(code)
        .ok()
        .and_then(|i| NAMES.get(i))
        .map_or_else(|| format!("datatype {code}"), |name| (*name).to_owned())
}

/// The words for a quality: `good`, `stale`, `bad`.
pub fn quality_word(quality: Quality) -> &'static str {
    match quality {
        Quality::Good => "good",
        Quality::Stale => "stale",
        Quality::Bad => "bad",
    }
}

/// A Sparkplug timestamp as ISO 8601 UTC with milliseconds: `2025-06-01T12:00:00.250Z`.
pub fn iso_time(ms: u64) -> String {
    // At most 2^64 ms / 86,400,000 ≈ 2.1e11 days: always an i64.
    let days = i64::try_from(ms / 86_400_000).unwrap_or(i64::MAX / 2);
    let in_day = ms % 86_400_000;
    let (year, month, day) = wire::calendar::civil_date(days);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}.{:03}Z",
        in_day / 3_600_000,
        in_day / 60_000 % 60,
        in_day / 1000 % 60,
        in_day % 1000
    )
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().fold(String::new(), |mut s, b| {
        let _ = write!(s, "{b:02x}");
        s
    })
}

impl Value {
    fn text(&self) -> String {
        match self {
            Self::Value(v) => value_text(v),
            Self::Raw { value, .. } => value.to_string(),
            Self::Null => "null".to_owned(),
            Self::Unreadable(why) => format!("unreadable ({why})"),
        }
    }

    fn json(&self) -> serde_json::Value {
        match self {
            Self::Value(v) => value_json(v),
            Self::Raw { value, .. } => value.clone(),
            Self::Null | Self::Unreadable(_) => serde_json::Value::Null,
        }
    }
}

fn value_text(v: &MetricValue) -> String {
    match v {
        MetricValue::String(s) | MetricValue::Text(s) => format!("{s:?}"),
        MetricValue::DateTime(t) => iso_time(t.as_millis()),
        other => value_json(other).to_string(),
    }
}

fn value_json(v: &MetricValue) -> serde_json::Value {
    use serde_json::Value as J;
    match v {
        MetricValue::Int8(n) => J::from(*n),
        MetricValue::Int16(n) => J::from(*n),
        MetricValue::Int32(n) => J::from(*n),
        MetricValue::Int64(n) => J::from(*n),
        MetricValue::UInt8(n) => J::from(*n),
        MetricValue::UInt16(n) => J::from(*n),
        MetricValue::UInt32(n) => J::from(*n),
        MetricValue::UInt64(n) => J::from(*n),
        MetricValue::Float(f) => J::from(*f),
        MetricValue::Double(d) => J::from(*d),
        MetricValue::Boolean(b) => J::from(*b),
        MetricValue::String(s) | MetricValue::Text(s) => J::from(s.as_str()),
        MetricValue::DateTime(t) => J::from(t.as_millis()),
    }
}

impl MetricDescription {
    /// A property by name.
    pub fn property(&self, key: &str) -> Option<&serde_json::Value> {
        self.properties
            .iter()
            .find_map(|(k, v)| (k == key).then_some(v))
    }

    /// The `engUnit` property.
    pub fn unit(&self) -> Option<&str> {
        self.property(ENG_UNIT)?.as_str()
    }

    /// Who the metric is, in words: `name`, `name (alias N)`, `alias N` or `(no name)`.
    pub fn label(&self) -> String {
        match (&self.name, self.alias) {
            (Some(name), Some(alias)) => format!("{name} (alias {alias})"),
            (Some(name), None) => name.clone(),
            (None, Some(alias)) => format!("alias {alias}"),
            (None, None) => "(no name)".to_owned(),
        }
    }

    /// The metric on one line: label, datatype, value, quality, `historical`, time, and
    /// for a birth its unit and whether it is writable (and within what); for data, its
    /// properties other than `Quality` as `key=value` (JSON values).
    pub fn to_text(&self, birth: bool) -> String {
        let mut line = self.label();
        let datatype = match (self.datatype, &self.value) {
            (Some(code), _) => datatype_name(code),
            (None, Value::Raw { field, .. }) => (*field).to_owned(),
            (None, _) => "?".to_owned(),
        };
        let _ = write!(line, ": {datatype} {}", self.value.text());
        if let Some(quality) = self.quality {
            let _ = write!(line, " {}", quality_word(quality));
        }
        if self.historical {
            line.push_str(" historical");
        }
        if self.transient {
            line.push_str(" transient");
        }
        if let Some(t) = self.timestamp {
            let _ = write!(line, " at {}", iso_time(t));
        }
        if birth {
            if let Some(unit) = self.unit() {
                let _ = write!(line, " unit {unit}");
            }
            let number = |key| self.property(key).and_then(serde_json::Value::as_f64);
            match (
                self.property(WRITABLE).and_then(serde_json::Value::as_bool),
                number(WRITE_MIN),
                number(WRITE_MAX),
            ) {
                (Some(true), Some(min), Some(max)) => {
                    let _ = write!(line, " writable {min}..{max}");
                }
                (Some(true), _, _) => line.push_str(" writable"),
                (Some(false), _, _) => line.push_str(" read-only"),
                (None, _, _) => {}
            }
            if let Some(doc) = self.property(DOCUMENTATION).and_then(|d| d.as_str()) {
                let _ = write!(line, " {doc:?}");
            }
        } else {
            for (key, value) in self.properties.iter().filter(|(k, _)| k != QUALITY) {
                let _ = write!(line, " {key}={value}");
            }
        }
        line
    }
}

impl Serialize for MetricDescription {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut map = serializer.serialize_map(None)?;
        map.serialize_entry("name", &self.name)?;
        map.serialize_entry("alias", &self.alias)?;
        map.serialize_entry("datatype", &self.datatype.map(datatype_name))?;
        map.serialize_entry("value", &self.value.json())?;
        if let Value::Unreadable(why) = &self.value {
            map.serialize_entry("value_error", why)?;
        }
        map.serialize_entry("quality", &self.quality.map(quality_word))?;
        map.serialize_entry("historical", &self.historical)?;
        if self.transient {
            map.serialize_entry("transient", &true)?;
        }
        map.serialize_entry("timestamp", &self.timestamp)?;
        map.serialize_entry("properties", &Properties(&self.properties))?;
        map.end()
    }
}

/// Properties as a JSON object in payload order.
struct Properties<'a>(&'a [(String, serde_json::Value)]);

impl Serialize for Properties<'_> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut map = serializer.serialize_map(Some(self.0.len()))?;
        for (k, v) in self.0 {
            map.serialize_entry(k, v)?;
        }
        map.end()
    }
}

impl SparkplugMessage {
    /// The metric named `name`.
    pub fn metric(&self, name: &str) -> Option<&MetricDescription> {
        self.metrics
            .iter()
            .find(|m| m.name.as_deref() == Some(name))
    }
}

impl Description {
    /// The MQTT topic.
    pub fn topic(&self) -> &str {
        match self {
            Self::Sparkplug(m) => &m.topic,
            Self::State { topic, .. }
            | Self::Undecodable { topic, .. }
            | Self::Other { topic, .. } => topic,
        }
    }

    /// The message for people: a Sparkplug message as a head line
    /// (`TOPIC seq=N timestamp=ISO (N metrics)`) and one indented line per metric; a
    /// STATE or other message as `TOPIC PAYLOAD` (text, or hex when not UTF-8); an
    /// undecodable one as `TOPIC: cannot decode: ERROR`.
    pub fn to_text(&self) -> String {
        match self {
            Self::Sparkplug(m) => {
                let mut text = m.topic.clone();
                if let Some(seq) = m.seq {
                    let _ = write!(text, " seq={seq}");
                }
                if let Some(t) = m.timestamp {
                    let _ = write!(text, " timestamp={}", iso_time(t));
                }
                let n = m.metrics.len();
                let _ = write!(text, " ({n} metric{})", if n == 1 { "" } else { "s" });
                let birth = m.kind == MessageKind::Birth;
                for metric in &m.metrics {
                    let _ = write!(text, "\n  {}", metric.to_text(birth));
                }
                text
            }
            Self::State { topic, payload, .. } | Self::Other { topic, payload } => {
                format!("{topic} {}", payload.text())
            }
            Self::Undecodable { topic, error } => format!("{topic}: cannot decode: {error}"),
        }
    }

    /// The message as one JSON object: a Sparkplug message as
    /// `{"topic","kind","group","edge_node","device","seq","timestamp","metrics":[…]}`;
    /// STATE as `{"topic","kind":"STATE","host","payload"}` (the JSON itself when it is
    /// JSON); other messages as `{"topic","payload","encoding":"text"|"hex"}`; an
    /// undecodable one as `{"topic","error"}`.
    pub fn to_json(&self) -> serde_json::Value {
        use serde_json::json;
        match self {
            Self::Sparkplug(m) => json!({
                "topic": m.topic,
                "kind": m.message_type,
                "group": m.group,
                "edge_node": m.edge_node,
                "device": m.device,
                "seq": m.seq,
                "timestamp": m.timestamp,
                "metrics": m.metrics,
            }),
            Self::State {
                topic,
                host,
                payload,
            } => {
                let value = match payload {
                    RawPayload::Text(text) => serde_json::from_str(text)
                        .unwrap_or_else(|_| serde_json::Value::from(text.as_str())),
                    RawPayload::Bytes(bytes) => serde_json::Value::from(hex(bytes)),
                };
                json!({"topic": topic, "kind": "STATE", "host": host, "payload": value})
            }
            Self::Other { topic, payload } => json!({
                "topic": topic,
                "payload": payload.text(),
                "encoding": payload.encoding(),
            }),
            Self::Undecodable { topic, error } => json!({"topic": topic, "error": error}),
        }
    }
}
