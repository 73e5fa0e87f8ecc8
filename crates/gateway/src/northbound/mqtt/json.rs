//! JSON mode, for Node-RED, Telegraf and home-made consumers: one topic per point.
//!
//! | topic | payload | QoS, retained |
//! |---|---|---|
//! | `{prefix}/{device}/{point}` | `{"t":ms,"value":…,"unit":"°C","quality":"good"}` | 1, retained |
//! | `{prefix}/{device}/status` | `online` or `offline` (`removed` by a reload) | 1, retained |
//! | `{prefix}/status` | `online`; `offline` as the gateway's Will | 1, retained |
//! | `{prefix}/events` | an event as the API shows it | 1, not retained |
//! | `{prefix}/alarms/{id}` | the alarm as `GET /api/alarms` shows it (its state after each change) | 1, retained |
//!
//! `value` is `null` unless the quality is `good` (a stale or bad point is never published
//! with its last good value). After an outage the changes stored since the forwarded mark
//! go first, not retained and with `"historical":true`, then every point's current value
//! (retained), then the change stream.
//!
//! The gateway also reads its own status topics (`{prefix}/status`, `{prefix}/+/status`):
//! a message there that says something else than the gateway's or the device's status
//! (another client's retained `offline`) is answered at once by the true status,
//! retained, so new subscribers are not misled. Point topics are read back only every
//! `check_retained` (10 min): MQTT 3.1.1 has no "no local" option, so a lasting
//! subscription would bring every point message back to the gateway and double the
//! broker's traffic. A check subscribes to `{prefix}/+/+` for [`CHECK_WINDOW`], takes the
//! retained messages the subscription brings (the broker flags them; live ones are not
//! looked at), publishes the truth for each point whose retained message is not what the
//! gateway last published, and unsubscribes. The broker's ACLs keep other clients off the
//! prefix in the first place (the user guide, docs/guide/src/mqtt.md,
//! "Broker access control").

use std::sync::Arc;
use std::time::Duration;

use rumqttc::QoS;
use serde_json::json;
use tokio::sync::broadcast;

use super::forward::Backlog;
use super::status;
use super::{Connection, End, Link, Mode, Outgoing, Step};
use crate::cell::{Cell, DeviceStatus, DeviceView, LiveMessage};
use crate::event::{Event, EventKind};
use crate::point::{PointId, Quality, Value};
use crate::time::Timestamp;
use crate::write::LogThrottle;

/// How long a check of the retained point messages listens for them.
pub const CHECK_WINDOW: Duration = Duration::from_secs(5);

/// The JSON publisher of one gateway.
pub struct Publisher {
    cell: Arc<Cell>,
    prefix: String,
    /// The snapshot was published in this connection.
    born: bool,
    /// Foreign status messages answered since the last log line.
    foreign: LogThrottle,
    /// How often the retained point messages are checked (`check_retained`).
    check_every: Duration,
    /// A check of the retained point messages is listening.
    checking: bool,
}

impl Publisher {
    /// The publisher of the `[mqtt]` table in `link`.
    pub fn new(link: &Link) -> Self {
        Self {
            cell: Arc::clone(link.cell()),
            prefix: link.config().prefix.clone(),
            born: false,
            foreign: LogThrottle::default(),
            check_every: link.config().check_retained,
            checking: false,
        }
    }

    fn status(&self, online: bool) -> Outgoing {
        Outgoing {
            topic: format!("{}/status", self.prefix),
            payload: if online { "online" } else { "offline" }.into(),
            qos: QoS::AtLeastOnce,
            retain: true,
            latest: None,
        }
    }
}

impl Mode for Publisher {
    async fn prepare(&mut self, _link: &Link) -> Outgoing {
        self.status(false)
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
                Step::Connected => {
                    let from = conn.forwarded();
                    let mut done = self.snapshot(conn, live, from).await;
                    // After the snapshot: the retained messages the subscription brings
                    // are the gateway's own.
                    for filter in self.status_filters() {
                        if done.is_ok() {
                            done = conn.subscribe(filter).await;
                        }
                    }
                    conn.serving(format!(
                        "MQTT connected; publishing JSON under {}/",
                        self.prefix
                    ));
                    done
                }
                Step::Live(Ok(message)) => self.on_change(conn, message).await,
                Step::Live(Err(broadcast::error::RecvError::Lagged(missed))) => {
                    tracing::warn!("MQTT: {missed} changes missed; publishing every point again");
                    let from = conn.catch_up_from();
                    self.snapshot(conn, live, from).await
                }
                Step::Live(Err(broadcast::error::RecvError::Closed)) => return End::Stop,
                Step::Message {
                    topic,
                    payload,
                    retain,
                } => match self.on_status_message(conn, &topic, &payload).await {
                    Ok(()) if self.checking && retain => {
                        self.on_retained_point(conn, &topic, &payload).await
                    }
                    done => done,
                },
                Step::Tick => self.start_check(conn).await,
                Step::Wake => self.end_check(conn).await,
            };
            if let Err(why) = done {
                return End::Lost(why);
            }
        }
    }

    fn lost(&mut self) {
        self.born = false;
        self.checking = false;
    }

    fn tick(&self) -> Duration {
        self.check_every
    }
}

impl Publisher {
    /// The gateway's and its devices' status topics.
    fn status_filters(&self) -> [String; 2] {
        [
            format!("{}/status", self.prefix),
            format!("{}/+/status", self.prefix),
        ]
    }

    fn points_filter(&self) -> String {
        format!("{}/+/+", self.prefix)
    }

    /// Starts a check of the retained point messages (not before the snapshot is out).
    async fn start_check(&mut self, conn: &mut Connection<'_>) -> Result<(), String> {
        if !self.born || self.checking {
            return Ok(());
        }
        conn.subscribe(self.points_filter()).await?;
        self.checking = true;
        conn.wake_at(tokio::time::Instant::now() + CHECK_WINDOW);
        Ok(())
    }

    async fn end_check(&mut self, conn: &mut Connection<'_>) -> Result<(), String> {
        if !self.checking {
            return Ok(());
        }
        self.checking = false;
        conn.unsubscribe(self.points_filter()).await
    }

    /// What follows `{prefix}/` in `topic`, if it is one of the gateway's topics.
    fn under_prefix<'t>(&self, topic: &'t str) -> Option<&'t str> {
        topic.strip_prefix(self.prefix.as_str())?.strip_prefix('/')
    }

    /// A retained point message brought by a check: when it is not the point's truth, the
    /// truth again, retained.
    async fn on_retained_point(
        &mut self,
        conn: &mut Connection<'_>,
        topic: &str,
        payload: &[u8],
    ) -> Result<(), String> {
        let Some((device, name)) = self.under_prefix(topic).and_then(|r| r.split_once('/')) else {
            return Ok(());
        };
        let Some(entry) = self.cell.device_entry(device) else {
            return Ok(());
        };
        let Some(index) = entry.point_index(name) else {
            return Ok(());
        };
        let view = {
            let state = entry.read();
            let Some(point) = state.points.get(index) else {
                return Ok(());
            };
            entry.point_view(index, point, Timestamp::now())
        };
        let truth = self.point_message(&view.id, view.value.as_ref(), view.quality, view.t, false);
        if same_reading(payload, &truth.payload) {
            return Ok(());
        }
        self.answer_foreign(conn, topic, payload, truth).await
    }

    /// A message on a status topic: when it says something else than the truth (another
    /// client published it), the true status again, retained.
    async fn on_status_message(
        &mut self,
        conn: &mut Connection<'_>,
        topic: &str,
        payload: &[u8],
    ) -> Result<(), String> {
        let Some(rest) = self.under_prefix(topic) else {
            return Ok(());
        };
        let truth = match rest.strip_suffix("/status") {
            None if rest == "status" => self.status(true),
            None => return Ok(()),
            Some(device) => match self.cell.device_entry(device) {
                Some(entry) => self.device_status(device, entry.summary().status),
                None => return Ok(()),
            },
        };
        self.answer_foreign(conn, topic, payload, truth).await
    }

    /// Publishes `truth` when `payload`, read on `topic`, is not it; counted and logged
    /// (throttled).
    async fn answer_foreign(
        &mut self,
        conn: &mut Connection<'_>,
        topic: &str,
        payload: &[u8],
        truth: Outgoing,
    ) -> Result<(), String> {
        if payload == truth.payload.as_slice() {
            return Ok(());
        }
        status::status(&self.cell).metrics.foreign_reasserted.inc();
        if let Some(count) = self.foreign.count(tokio::time::Instant::now()) {
            tracing::warn!(
                "MQTT: {count} message(s) on this gateway's topics said something else than \
                 the truth since the last report (the latest on {topic}: {:?}); another \
                 client of the broker publishes there: the truth is published again (the \
                 broker's ACLs can keep other clients off the prefix: the user guide's MQTT \
                 chapter, \"Broker access control\")",
                String::from_utf8_lossy(&payload[..payload.len().min(64)])
            );
        }
        conn.publish(truth).await
    }

    /// `online`, the changes stored since `from`, then every point and device status.
    async fn snapshot(
        &mut self,
        conn: &mut Connection<'_>,
        live: &mut broadcast::Receiver<LiveMessage>,
        from: Timestamp,
    ) -> Result<(), String> {
        *live = live.resubscribe();
        let now = Timestamp::now();
        conn.publish(self.status(true)).await?;
        self.backlog(conn, from, now).await?;
        for device in self.cell.device_entries() {
            self.device_snapshot(conn, &device.view(now)).await?;
        }
        for alarm in self.cell.alarms.all() {
            conn.publish(self.alarm_message(&alarm)).await?;
        }
        self.born = true;
        Ok(())
    }

    /// A device's points and status.
    async fn device_snapshot(
        &mut self,
        conn: &mut Connection<'_>,
        device: &DeviceView,
    ) -> Result<(), String> {
        for point in &device.points {
            let view = &point.view;
            let message =
                self.point_message(&view.id, view.value.as_ref(), view.quality, view.t, false);
            conn.publish(message).await?;
        }
        conn.publish(self.device_status(device.summary.id.as_str(), device.summary.status))
            .await
    }

    /// A reload of the configuration (its `config_reloaded` event): each device added or
    /// changed publishes its points, status and alarms; each removed has its status
    /// `removed` (its points' retained messages stay until someone clears them).
    async fn on_reload(&mut self, conn: &mut Connection<'_>, event: &Event) -> Result<(), String> {
        for device in crate::reload::devices_in(event, "removed") {
            conn.publish(Outgoing {
                topic: format!("{}/{device}/status", self.prefix),
                payload: "removed".into(),
                qos: QoS::AtLeastOnce,
                retain: true,
                latest: None,
            })
            .await?;
        }
        let now = Timestamp::now();
        for device in crate::reload::devices_in(event, "added")
            .into_iter()
            .chain(crate::reload::devices_in(event, "changed"))
        {
            let Some(entry) = self.cell.device_entry(device.as_str()) else {
                continue;
            };
            self.device_snapshot(conn, &entry.view(now)).await?;
            for alarm in self.cell.alarms.of_device(device.as_str()) {
                conn.publish(self.alarm_message(&alarm)).await?;
            }
        }
        Ok(())
    }

    /// An alarm's retained message: the alarm as the API shows it.
    fn alarm_message(&self, alarm: &crate::alarm::book::View) -> Outgoing {
        Outgoing {
            topic: format!("{}/alarms/{}", self.prefix, alarm.id),
            payload: serde_json::to_vec(alarm).unwrap_or_default(),
            qos: QoS::AtLeastOnce,
            retain: true,
            latest: None,
        }
    }

    async fn backlog(
        &mut self,
        conn: &mut Connection<'_>,
        from: Timestamp,
        until: Timestamp,
    ) -> Result<(), String> {
        let max = conn.link.config().max_backlog;
        let Some(mut backlog) = Backlog::start(&self.cell, from, until, max).await else {
            return Ok(());
        };
        loop {
            let page = backlog.next_page_or_end().await;
            if page.is_empty() {
                return Ok(());
            }
            let sent = page.len() as u64;
            for change in page {
                let Ok(point) = PointId::parse(&change.point) else {
                    continue;
                };
                let message = self.point_message(
                    &point,
                    change.value.as_ref(),
                    Some(change.quality),
                    Some(change.key.t),
                    true,
                );
                conn.publish(message).await?;
            }
            status::status(&self.cell).metrics.forwarded.inc_by(sent);
        }
    }

    async fn on_change(
        &mut self,
        conn: &mut Connection<'_>,
        message: LiveMessage,
    ) -> Result<(), String> {
        match message {
            LiveMessage::Value(view) => {
                let message =
                    self.point_message(&view.id, view.value.as_ref(), view.quality, view.t, false);
                conn.publish(message).await?;
            }
            LiveMessage::Device(summary) => {
                conn.publish(self.device_status(summary.id.as_str(), summary.status))
                    .await?;
            }
            LiveMessage::Event(event) => {
                let payload = serde_json::to_vec(&event).unwrap_or_default();
                conn.publish(Outgoing {
                    topic: format!("{}/events", self.prefix),
                    payload,
                    qos: QoS::AtLeastOnce,
                    retain: false,
                    latest: None,
                })
                .await?;
                if let Some(alarm) = event
                    .fields
                    .get("alarm")
                    .and_then(|a| a.as_str())
                    .and_then(|id| self.cell.alarms.view(id))
                {
                    conn.publish(self.alarm_message(&alarm)).await?;
                }
                if event.kind == EventKind::ConfigReloaded {
                    self.on_reload(conn, &event).await?;
                }
            }
        }
        Ok(())
    }

    fn device_status(&self, device: &str, status: DeviceStatus) -> Outgoing {
        let online = status != DeviceStatus::Down;
        Outgoing {
            topic: format!("{}/{device}/status", self.prefix),
            payload: if online { "online" } else { "offline" }.into(),
            qos: QoS::AtLeastOnce,
            retain: true,
            latest: None,
        }
    }

    /// A point's message: retained when live, not retained and marked when historical.
    fn point_message(
        &self,
        point: &PointId,
        value: Option<&Value>,
        quality: Option<Quality>,
        t: Option<Timestamp>,
        historical: bool,
    ) -> Outgoing {
        let unit = self.cell.point(point).and_then(|p| p.unit.clone());
        let payload = point_payload(value, quality, t, unit.as_deref(), historical);
        Outgoing {
            topic: format!("{}/{}/{}", self.prefix, point.device(), point.name()),
            payload,
            qos: QoS::AtLeastOnce,
            retain: !historical,
            latest: t,
        }
    }
}

/// Whether two point messages say the same value, unit and quality. The time may differ:
/// the gateway publishes a point when it changes, with that read's time, while its view
/// holds the latest read, which did not change it.
fn same_reading(a: &[u8], b: &[u8]) -> bool {
    let read = |bytes: &[u8]| serde_json::from_slice::<serde_json::Value>(bytes).ok();
    match (read(a), read(b)) {
        (Some(a), Some(b)) => ["value", "unit", "quality"]
            .iter()
            .all(|key| a.get(key) == b.get(key)),
        _ => false,
    }
}

/// `{"t":ms,"value":…,"unit":…,"quality":…}` (plus `"historical":true` for a stored
/// change); the value only when the quality is good.
pub fn point_payload(
    value: Option<&Value>,
    quality: Option<Quality>,
    t: Option<Timestamp>,
    unit: Option<&str>,
    historical: bool,
) -> Vec<u8> {
    let quality_word = match quality {
        Some(Quality::Good) => "good",
        Some(Quality::Stale) => "stale",
        Some(Quality::Bad) => "bad",
        None => "unknown",
    };
    let value = match (quality, value) {
        (Some(Quality::Good), Some(Value::Number(n))) => json!(n),
        (Some(Quality::Good), Some(Value::Text(t))) => json!(t),
        _ => serde_json::Value::Null,
    };
    let mut body = json!({
        "t": t.map(|t| t.0),
        "value": value,
        "unit": unit,
        "quality": quality_word,
    });
    if historical {
        body["historical"] = json!(true);
    }
    serde_json::to_vec(&body).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parsed(bytes: &[u8]) -> serde_json::Value {
        serde_json::from_slice(bytes).unwrap()
    }

    #[test]
    fn a_retained_point_message_is_the_truth_when_its_value_unit_and_quality_are() {
        let published = br#"{"quality":"good","t":5,"unit":"degC","value":25.0}"#;
        let now = br#"{"quality":"good","t":9,"unit":"degC","value":25.0}"#;
        assert!(
            same_reading(published, now),
            "a later read of the same value"
        );
        let forged = br#"{"t":1,"value":999.0,"unit":"degC","quality":"good"}"#;
        assert!(!same_reading(forged, now));
        assert!(!same_reading(b"not json", now));
        let bad = br#"{"quality":"bad","t":9,"unit":"degC","value":null}"#;
        assert!(!same_reading(published, bad));
    }

    #[test]
    fn a_good_point_carries_its_value_unit_and_read_time() {
        let p = point_payload(
            Some(&Value::Number(350.0)),
            Some(Quality::Good),
            Some(Timestamp(1_700_000_000_000)),
            Some("°C"),
            false,
        );
        assert_eq!(
            parsed(&p),
            json!({"t": 1_700_000_000_000_i64, "value": 350.0, "unit": "°C", "quality": "good"})
        );
    }

    #[test]
    fn a_stale_point_is_published_without_its_last_good_value() {
        let p = point_payload(
            Some(&Value::Number(350.0)),
            Some(Quality::Stale),
            Some(Timestamp(5)),
            None,
            true,
        );
        assert_eq!(
            parsed(&p),
            json!({"t": 5, "value": null, "unit": null, "quality": "stale", "historical": true})
        );
    }
}
