//! The envelope every CFX message travels in (SDK `CFXEnvelope`), its JSON, and the
//! AMQP 1.0 properties it is sent with (SDK `AmqpUtilities.MessageFromEnvelope`), without
//! any AMQP client: the transport sets what [`Envelope::amqp`] gives.

use serde::Deserialize;
use uuid::Uuid;

use crate::messages::Message;
use crate::types::{Handle, Time};

/// The CFX version this crate writes.
pub const VERSION: &str = "2.1";

/// The content type of a CFX AMQP message.
pub const CONTENT_TYPE: &str = "application/json; charset=\"utf-8\"";

/// A message in its envelope.
#[derive(Debug, Clone, PartialEq)]
pub struct Envelope {
    /// When it happened (not when it is sent).
    pub time_stamp: Time,
    /// Its id: a receiver handles a message once by it; a message sent again (after an
    /// outage) keeps it.
    pub unique_id: Uuid,
    /// Who publishes it.
    pub source: Handle,
    /// The endpoint a request or response is for.
    pub target: Option<Handle>,
    /// Pairs a response with its request.
    pub request_id: Option<String>,
    /// The body.
    pub message: Message,
}

/// What the AMQP message of an envelope carries besides its body (one Data section of
/// the JSON): its properties and application properties.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AmqpProperties {
    /// `message-id`: the envelope's `UniqueID`.
    pub message_id: String,
    /// `to`: the target, if any.
    pub to: Option<String>,
    /// `reply-to`: the source.
    pub reply_to: String,
    /// `correlation-id`: the request's id, for a response.
    pub correlation_id: Option<String>,
    /// `subject`: `{handle}.{MessageName}`.
    pub subject: String,
    /// `content-type`.
    pub content_type: &'static str,
    /// `creation-time`: when it happened, ms since the epoch.
    pub creation_time_ms: i64,
    /// `cfx-topic`, `cfx-message`, `cfx-handle`, `cfx-target` (the target's handle, or
    /// `null` when the message is for everyone).
    pub application: Vec<(&'static str, Option<String>)>,
}

impl Envelope {
    /// `message` from `source`, happened `at`, with a new id.
    pub fn new(source: Handle, at: Time, message: Message) -> Self {
        Self {
            time_stamp: at,
            unique_id: Uuid::new_v4(),
            source,
            target: None,
            request_id: None,
            message,
        }
    }

    /// The envelope as the SDK writes it.
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "MessageName": self.message.name(),
            "Version": VERSION,
            "TimeStamp": self.time_stamp,
            "UniqueID": self.unique_id,
            "Source": self.source,
            "Target": self.target,
            "RequestID": self.request_id,
            "MessageBody": self.message.body(),
        })
    }

    /// The JSON bytes of one AMQP message's Data section.
    pub fn to_bytes(&self) -> Vec<u8> {
        self.to_json().to_string().into_bytes()
    }

    /// The JSON bytes of a batch (an array: one AMQP message for several envelopes).
    pub fn batch_bytes(envelopes: &[Envelope]) -> Vec<u8> {
        serde_json::Value::Array(envelopes.iter().map(Envelope::to_json).collect())
            .to_string()
            .into_bytes()
    }

    /// The AMQP properties it is sent with.
    pub fn amqp(&self) -> AmqpProperties {
        AmqpProperties::of(Header {
            name: self.message.name(),
            unique_id: self.unique_id,
            time_stamp: &self.time_stamp,
            source: self.source.as_str(),
            target: self.target.as_ref().map(Handle::as_str),
            request_id: self.request_id.as_deref(),
        })
    }
}

/// What the AMQP properties are made of: the envelope's header.
struct Header<'a> {
    name: &'a str,
    unique_id: Uuid,
    time_stamp: &'a Time,
    source: &'a str,
    target: Option<&'a str>,
    request_id: Option<&'a str>,
}

impl AmqpProperties {
    fn of(header: Header<'_>) -> Self {
        let handle = header.source.to_owned();
        let topic = header
            .name
            .rsplit_once('.')
            .map_or(header.name, |(topic, _)| topic);
        AmqpProperties {
            message_id: header.unique_id.to_string(),
            to: header.target.map(str::to_owned),
            reply_to: handle.clone(),
            correlation_id: header.request_id.map(str::to_owned),
            subject: format!("{handle}.{}", header.name),
            content_type: CONTENT_TYPE,
            creation_time_ms: header.time_stamp.timestamp().as_millisecond(),
            application: vec![
                ("cfx-topic", Some(topic.to_owned())),
                ("cfx-message", Some(header.name.to_owned())),
                ("cfx-handle", Some(handle)),
                ("cfx-target", header.target.map(str::to_owned)),
            ],
        }
    }
}

/// An envelope received, its body left as JSON (what a request carries, what
/// `cellbus cfx sub` prints).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(rename_all = "PascalCase")]
pub struct Received {
    /// The message's full name.
    pub message_name: String,
    /// The CFX version it was written for.
    pub version: Option<String>,
    /// When it happened.
    pub time_stamp: Option<Time>,
    /// Its id.
    #[serde(rename = "UniqueID")]
    pub unique_id: Option<Uuid>,
    /// Who sent it.
    pub source: Option<String>,
    /// Who it is for.
    pub target: Option<String>,
    /// Pairs a response with its request.
    #[serde(rename = "RequestID")]
    pub request_id: Option<String>,
    /// The body.
    #[serde(default)]
    pub message_body: serde_json::Value,
}

/// Why received bytes are not CFX envelopes.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("not a CFX envelope: {0}")]
pub struct DecodeError(String);

impl Received {
    /// The AMQP properties it was sent with (as [`Envelope::amqp`] gives them): how a
    /// message kept as its JSON is sent again. Fails when the header lacks the `UniqueID`,
    /// `TimeStamp` or `Source` they are made of.
    pub fn amqp(&self) -> Result<AmqpProperties, DecodeError> {
        let missing = |what: &str| DecodeError(format!("{} has no {what}", self.message_name));
        Ok(AmqpProperties::of(Header {
            name: &self.message_name,
            unique_id: self.unique_id.ok_or_else(|| missing("UniqueID"))?,
            time_stamp: self
                .time_stamp
                .as_ref()
                .ok_or_else(|| missing("TimeStamp"))?,
            source: self.source.as_deref().ok_or_else(|| missing("Source"))?,
            target: self.target.as_deref(),
            request_id: self.request_id.as_deref(),
        }))
    }

    /// The envelopes of one AMQP message's body: one object, or an array of them (a
    /// batch).
    pub fn decode(bytes: &[u8]) -> Result<Vec<Received>, DecodeError> {
        let value: serde_json::Value =
            serde_json::from_slice(bytes).map_err(|e| DecodeError(e.to_string()))?;
        let one = |v: serde_json::Value| {
            serde_json::from_value::<Received>(v).map_err(|e| DecodeError(e.to_string()))
        };
        match value {
            serde_json::Value::Array(items) => items.into_iter().map(one).collect(),
            other => one(other).map(|r| vec![r]),
        }
    }
}
