//! A Sparkplug B subscriber for tests: an MQTT client (rumqttc) that follows a topic
//! filter, decodes every payload with the `sparkplug` crate's protobuf types, survives
//! broker restarts (persistent session, re-subscribes on every ConnAck) and waits for a
//! message with a bounded wait.

use std::time::Duration;

use prost::Message as _;
use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};
use sparkplug::proto::{Metric, Payload, metric::Value};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

/// The largest MQTT packet: its remaining length's maximum (256 MiB).
const MAX_PACKET: usize = 268_435_455;

/// One received Sparkplug message.
#[derive(Debug, Clone)]
pub struct SparkplugMessage {
    /// The MQTT topic.
    pub topic: String,
    /// The decoded payload.
    pub payload: Payload,
}

impl SparkplugMessage {
    /// The message type (`NBIRTH`, `DDATA`, …).
    pub fn kind(&self) -> &str {
        self.topic.split('/').nth(2).unwrap_or("")
    }

    /// The device id, for device messages.
    pub fn device(&self) -> Option<&str> {
        self.topic.split('/').nth(4)
    }

    /// The metric named `name`.
    pub fn metric(&self, name: &str) -> Option<&Metric> {
        self.payload
            .metrics
            .iter()
            .find(|m| m.name.as_deref() == Some(name))
    }

    /// The `bdSeq` metric's value (NBIRTH, NDEATH).
    pub fn bd_seq(&self) -> Option<u64> {
        match self.metric("bdSeq")?.value {
            Some(Value::LongValue(n)) => Some(n),
            _ => None,
        }
    }
}

/// A command payload (NCMD or DCMD) setting `metric`, named, of `datatype`, to `value`.
pub fn command_payload(metric: &str, datatype: sparkplug::DataType, value: Value) -> Vec<u8> {
    Payload {
        timestamp: Some(0),
        metrics: vec![Metric {
            name: Some(metric.into()),
            datatype: Some(datatype.code()),
            value: Some(value),
            ..Metric::default()
        }],
        ..Payload::default()
    }
    .encode_to_vec()
}

/// An NCMD payload that asks a node for its births again (`Node Control/Rebirth` = true),
/// as a host application builds it ([`sparkplug::node::rebirth_payload`]).
pub fn rebirth_command() -> Vec<u8> {
    sparkplug::node::rebirth_payload(sparkplug::Timestamp::from_millis(0))
}

enum Incoming {
    Subscribed,
    Message(SparkplugMessage),
}

/// A running subscriber; its task ends on drop.
#[derive(Debug)]
pub struct Subscriber {
    client: AsyncClient,
    messages: mpsc::UnboundedReceiver<Incoming>,
    task: JoinHandle<()>,
}

impl std::fmt::Debug for Incoming {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Incoming::Subscribed => f.write_str("Subscribed"),
            Incoming::Message(m) => write!(f, "Message({})", m.topic),
        }
    }
}

impl Subscriber {
    /// Connects to the broker on 127.0.0.1:`port` (messages of any size MQTT allows, both
    /// ways), subscribes to `filter` (QoS 1) and
    /// returns once the broker acknowledged the subscription.
    ///
    /// # Panics
    ///
    /// When the subscription is not acknowledged within 30 s.
    pub async fn start(port: u16, filter: &str) -> Self {
        let id = format!("cellbus-test-{}", fastrand::u64(..));
        let mut options = MqttOptions::new(id, "127.0.0.1", port);
        options
            .set_clean_session(false)
            .set_keep_alive(Duration::from_secs(30))
            .set_max_packet_size(MAX_PACKET, MAX_PACKET);
        let (client, mut eventloop) = AsyncClient::new(options, 100);
        let (tx, mut messages) = mpsc::unbounded_channel();
        let resubscribe = client.clone();
        let filter = filter.to_owned();
        let task = tokio::spawn(async move {
            loop {
                match eventloop.poll().await {
                    Ok(Event::Incoming(Packet::ConnAck(_))) => {
                        let _ = resubscribe.try_subscribe(filter.clone(), QoS::AtLeastOnce);
                    }
                    Ok(Event::Incoming(Packet::SubAck(_))) => {
                        let _ = tx.send(Incoming::Subscribed);
                    }
                    Ok(Event::Incoming(Packet::Publish(p))) => {
                        // A payload that is not Sparkplug is a failure of the node under test.
                        let payload = Payload::decode(&p.payload[..]).unwrap_or_else(|e| {
                            panic!("{}: not a Sparkplug payload: {e}", p.topic)
                        });
                        let _ = tx.send(Incoming::Message(SparkplugMessage {
                            topic: p.topic.clone(),
                            payload,
                        }));
                    }
                    Ok(_) => {}
                    // The broker is away: rumqttc reconnects on the next poll.
                    Err(_) => tokio::time::sleep(Duration::from_millis(50)).await,
                }
            }
        });
        let subscribed = tokio::time::timeout(Duration::from_secs(30), async {
            while let Some(incoming) = messages.recv().await {
                if matches!(incoming, Incoming::Subscribed) {
                    return;
                }
            }
        })
        .await;
        assert!(
            subscribed.is_ok(),
            "the broker did not acknowledge the subscription in 30 s"
        );
        Self {
            client,
            messages,
            task,
        }
    }

    /// The next message for which `wanted` is true, skipping the others; within `limit`.
    ///
    /// # Panics
    ///
    /// When none comes in time; the message names `what`.
    pub async fn next_where(
        &mut self,
        what: &str,
        limit: Duration,
        mut wanted: impl FnMut(&SparkplugMessage) -> bool,
    ) -> SparkplugMessage {
        let found = tokio::time::timeout(limit, async {
            while let Some(incoming) = self.messages.recv().await {
                if let Incoming::Message(m) = incoming
                    && wanted(&m)
                {
                    return Some(m);
                }
            }
            None
        })
        .await;
        match found {
            Ok(Some(m)) => m,
            Ok(None) => panic!("the subscriber stopped before {what}"),
            Err(_) => panic!("no {what} within {limit:?}"),
        }
    }

    /// Publishes `payload` on `topic` (QoS 1, retained), e.g. a host application's STATE.
    pub async fn publish_retained(&self, topic: &str, payload: Vec<u8>) {
        self.client
            .publish(topic, QoS::AtLeastOnce, true, payload)
            .await
            .expect("the subscriber's client is running");
    }

    /// Publishes `payload` on `topic` (QoS 1), e.g. an NCMD.
    pub async fn publish(&self, topic: &str, payload: Vec<u8>) {
        self.client
            .publish(topic, QoS::AtLeastOnce, false, payload)
            .await
            .expect("the subscriber's client is running");
    }
}

impl Drop for Subscriber {
    fn drop(&mut self) {
        self.task.abort();
    }
}
