//! The historian's MQTT side: one rumqttc connection at a time, as the Sparkplug primary
//! host.
//!
//! A connection is made only while PostgreSQL takes commits ([`DbState::Ok`]). Each one:
//!
//! 1. registers the Will `STATE {"online":false,"timestamp":T}` (retained, QoS 1) with a
//!    **persistent session** (`clean_session = false`, client id `cellbus-historian-{host
//!    id}`), so the broker keeps the edge nodes' NDEATHs (QoS 1) for the historian while
//!    it is away: a gateway that died meanwhile is marked bad when the historian is back;
//! 2. on ConnAck subscribes to [`Host::subscriptions`], then publishes STATE offline with
//!    T − 1 ms and STATE online with T. The offline first makes every edge node that was
//!    sending to an earlier session of this host (killed, or cut off before the broker
//!    noticed) end its session and move its forwarded mark back by twice its keep-alive,
//!    so what that session received but never committed is sent again. Only then does it
//!    subscribe to its own STATE topic ([`Host::state_subscription`]; the retained
//!    message that brings is its own online);
//! 3. hands every message to [`Host::receive`], sends its rows to the writer and publishes
//!    its Rebirth requests. A birth the host refuses for a limit is counted and logged
//!    (at most once every few seconds, naming the node);
//! 4. answers any STATE on its own topic that is not online (a rogue client's retained
//!    offline, which would keep every gateway away until the historian restarted, or a
//!    stale one) with online again at once ([`Host::reassert_online`]), counted and
//!    logged; except while it goes offline itself.
//!
//! When PostgreSQL fails (or too many rows wait) the historian publishes STATE offline and
//! disconnects, so the edge nodes store and forward, and connects again once a commit
//! succeeds. A lost connection is tried again after [`RETRY_FIRST`] doubling to
//! [`RETRY_CAP`].
//!
//! A `kill -9`: the broker publishes the Will after 1.5 × [`KEEP_ALIVE`] (15 s); the
//! gateways then rewind by twice their keep-alive (60 s with their default 30 s) from that
//! moment, 45 s before the kill, which covers the rows the historian held uncommitted
//! (100 ms) and every message the broker dropped for it meanwhile. Gateways need a
//! keep-alive of at least 10 s for this margin.

use std::collections::{HashMap, VecDeque};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, SystemTime};

use kit::bounded::LogThrottle;
use rumqttc::{
    AsyncClient, Event, EventLoop, LastWill, MqttOptions, Outgoing, Packet, QoS, SubscribeFilter,
    SubscribeReasonCode, Transport,
};
use sparkplug::{Host, Problem, Publish, Qos};
use tokio::sync::{mpsc, watch};
use wire::backoff::Backoff;

use crate::ingest;
use crate::metrics::{Health, Metrics};
use crate::store::Batch;
use crate::writer::DbState;

/// The historian's MQTT keep-alive: the broker notices a dead historian after 1.5 × this.
pub const KEEP_ALIVE: Duration = Duration::from_secs(10);
/// First wait after a lost or refused connection; it doubles up to [`RETRY_CAP`].
pub const RETRY_FIRST: Duration = Duration::from_millis(500);
/// Longest wait between connection attempts.
pub const RETRY_CAP: Duration = Duration::from_secs(30);
/// Largest MQTT packet sent (STATE and Rebirth requests are small).
const MAX_OUTGOING: usize = 1 << 20;
/// Requests queued for the client (STATE, subscriptions, Rebirth requests).
const QUEUE: usize = 1024;
/// How long a disconnect waits for STATE offline and DISCONNECT to leave.
const CLOSE_GRACE: Duration = Duration::from_secs(3);

/// Where the broker is and how to log in.
#[derive(Clone)]
pub struct Broker {
    /// Host name or address.
    pub host: String,
    /// Port.
    pub port: u16,
    /// TCP, or TLS for `mqtts://`.
    pub transport: Transport,
    /// User name and password, if the broker wants them.
    pub credentials: Option<(String, String)>,
}

impl std::fmt::Debug for Broker {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Never the password.
        f.debug_struct("Broker")
            .field("host", &self.host)
            .field("port", &self.port)
            .field("user", &self.credentials.as_ref().map(|(u, _)| u))
            .finish_non_exhaustive()
    }
}

/// What the MQTT task shares with the rest of the historian.
pub struct Link {
    /// The broker.
    pub broker: Broker,
    /// The host application's state, kept across connections.
    pub host: Arc<Mutex<Host>>,
    /// Rows to the writer.
    pub rows: mpsc::Sender<Batch>,
    /// Whether PostgreSQL takes commits.
    pub db: watch::Receiver<DbState>,
    /// Counters.
    pub metrics: Arc<Metrics>,
    /// Health.
    pub health: Arc<Health>,
}

fn lock(host: &Mutex<Host>) -> std::sync::MutexGuard<'_, Host> {
    host.lock().unwrap_or_else(|e| e.into_inner())
}

fn lock_throttles(throttles: &Mutex<Throttles>) -> std::sync::MutexGuard<'_, Throttles> {
    throttles.lock().unwrap_or_else(|e| e.into_inner())
}

fn now_ms() -> sparkplug::Timestamp {
    ingest::sparkplug_time(SystemTime::now())
}

fn qos(q: Qos) -> QoS {
    match q {
        Qos::AtMostOnce => QoS::AtMostOnce,
        Qos::AtLeastOnce => QoS::AtLeastOnce,
    }
}

impl Link {
    /// Runs until `stop` turns true; then publishes STATE offline, disconnects and returns
    /// (dropping its sender, which lets the writer commit what is left and end).
    pub async fn run(self, mut stop: watch::Receiver<bool>) {
        let Link {
            broker,
            host,
            rows,
            mut db,
            metrics,
            health,
        } = self;
        let client_id = format!("cellbus-historian-{}", lock(&host).host_id());
        let mut retry = Backoff::new(RETRY_FIRST, RETRY_CAP).timer();
        // Kept across connections: one log line every few seconds at most.
        let throttles = Arc::new(Mutex::new(Throttles::default()));
        loop {
            // Online only while PostgreSQL takes commits.
            loop {
                if *stop.borrow() {
                    return;
                }
                if *db.borrow() == DbState::Ok {
                    break;
                }
                health.set_broker(Some("offline while PostgreSQL fails".to_owned()));
                tokio::select! {
                    r = db.changed() => if r.is_err() { return },
                    _ = stop.changed() => {}
                }
            }
            let t = now_ms();
            let will = lock(&host).will(t);
            let mut options = MqttOptions::new(&client_id, &broker.host, broker.port);
            options
                .set_keep_alive(KEEP_ALIVE)
                .set_clean_session(false)
                .set_max_packet_size(kit::mqtt::MAX_INCOMING, MAX_OUTGOING)
                .set_transport(broker.transport.clone())
                .set_last_will(LastWill::new(
                    will.topic.to_string(),
                    will.payload.clone(),
                    qos(will.qos),
                    will.retain,
                ));
            if let Some((user, password)) = &broker.credentials {
                options.set_credentials(user, password);
            }
            let (client, eventloop) = AsyncClient::new(options, QUEUE);
            let leaving = Arc::new(AtomicBool::new(false));
            let pump = Pump {
                host: Arc::clone(&host),
                client: client.clone(),
                rows: rows.clone(),
                metrics: Arc::clone(&metrics),
                health: Arc::clone(&health),
                online_at: t,
                describe: (broker.host.clone(), broker.port),
                leaving: Arc::clone(&leaving),
                throttles: Arc::clone(&throttles),
                state_topic: lock(&host).state_subscription().filter,
            };
            let mut task = tokio::spawn(pump.run(eventloop));
            enum End {
                Lost(String),
                Offline,
                Stop,
            }
            let end = loop {
                tokio::select! {
                    why = &mut task => break End::Lost(why.unwrap_or_else(|e| e.to_string())),
                    r = db.changed() => {
                        if r.is_err() || *db.borrow() != DbState::Ok {
                            break End::Offline;
                        }
                    }
                    _ = stop.changed() => if *stop.borrow() { break End::Stop },
                }
            };
            let connected = health.broker().is_none();
            metrics.mqtt_connected.set(0);
            match end {
                End::Lost(why) => {
                    if connected {
                        tracing::warn!("historian: MQTT connection ended: {why}; retrying");
                        retry.reset();
                    } else {
                        tracing::debug!("historian: cannot connect to the broker: {why}");
                    }
                    health.set_broker(Some(why));
                    tokio::select! {
                        () = tokio::time::sleep(retry.next_wait()) => {}
                        _ = stop.changed() => {}
                    }
                }
                End::Offline | End::Stop => {
                    // Offline at once, so the edge nodes store and forward (at the session's
                    // time, the Will's, which every online it announced carries too), and
                    // not answered as a forgery.
                    leaving.store(true, Ordering::SeqCst);
                    let _ = client
                        .publish(will.topic.to_string(), QoS::AtLeastOnce, true, will.payload)
                        .await;
                    let _ = client.disconnect().await;
                    if tokio::time::timeout(CLOSE_GRACE, &mut task).await.is_err() {
                        task.abort();
                    }
                    health.set_broker(Some("offline".to_owned()));
                    if matches!(end, End::Stop) {
                        return;
                    }
                    tracing::warn!("historian: offline (STATE) until PostgreSQL takes commits");
                    retry.reset();
                }
            }
        }
    }
}

/// Log throttles for what a rogue client can cause by the thousand.
#[derive(Default)]
struct Throttles {
    refused_births: LogThrottle,
    state_reasserted: LogThrottle,
}

/// What a SUBSCRIBE was for, to read its SubAck.
struct Sent {
    filters: Vec<SubscribeFilter>,
    /// The data subscriptions (their SubAck puts the historian online), not its STATE.
    data: bool,
}

/// One connection's event loop: what it receives goes to the host and the writer.
struct Pump {
    host: Arc<Mutex<Host>>,
    client: AsyncClient,
    rows: mpsc::Sender<Batch>,
    metrics: Arc<Metrics>,
    health: Arc<Health>,
    online_at: sparkplug::Timestamp,
    describe: (String, u16),
    /// Set by the link before it publishes STATE offline itself (PostgreSQL failing, a
    /// stop): that offline is not answered.
    leaving: Arc<AtomicBool>,
    throttles: Arc<Mutex<Throttles>>,
    /// `spBv1.0/STATE/{host id}`.
    state_topic: String,
}

impl Pump {
    /// Polls the event loop until the connection ends; returns why.
    async fn run(self, mut eventloop: EventLoop) -> String {
        // SUBSCRIBEs in the order queued, then by packet id once sent.
        let mut queued: VecDeque<Sent> = VecDeque::new();
        let mut sent: HashMap<u16, Sent> = HashMap::new();
        // Until its own STATE subscription is acknowledged, a STATE can only come from the
        // persistent session's earlier one: queued while the historian was away.
        let mut state_subscribed = false;
        loop {
            match eventloop.poll().await {
                Ok(Event::Incoming(Packet::ConnAck(_))) => {
                    let (subscriptions, state, offline, online) = {
                        let host = lock(&self.host);
                        let earlier = sparkplug::Timestamp::from_millis(
                            self.online_at.as_millis().saturating_sub(1),
                        );
                        (
                            host.subscriptions(),
                            host.state_subscription(),
                            host.will(earlier),
                            host.state_online(self.online_at),
                        )
                    };
                    let filters: Vec<_> = subscriptions
                        .iter()
                        .map(|s| SubscribeFilter::new(s.filter.clone(), qos(s.qos)))
                        .collect();
                    // The persistent session may still hold the STATE subscription of an
                    // earlier connection: dropped first, so the offline below does not
                    // come back to be answered.
                    if let Err(e) = self.client.try_unsubscribe(state.filter.clone()) {
                        return format!("cannot unsubscribe: {e}");
                    }
                    if let Err(e) = self.client.try_subscribe_many(filters.clone()) {
                        return format!("cannot subscribe: {e}");
                    }
                    queued.push_back(Sent {
                        filters,
                        data: true,
                    });
                    for state in [offline, online] {
                        if let Err(e) = self.publish(state) {
                            return e;
                        }
                    }
                    // After its own online: the retained message it brings is that one.
                    let filter = SubscribeFilter::new(state.filter, qos(state.qos));
                    if let Err(e) = self.client.try_subscribe_many([filter.clone()]) {
                        return format!("cannot subscribe: {e}");
                    }
                    queued.push_back(Sent {
                        filters: vec![filter],
                        data: false,
                    });
                }
                Ok(Event::Outgoing(Outgoing::Subscribe(pkid))) => {
                    if let Some(subscribe) = queued.pop_front() {
                        sent.insert(pkid, subscribe);
                    }
                }
                Ok(Event::Incoming(Packet::SubAck(ack))) => {
                    let Some(subscribe) = sent.remove(&ack.pkid) else {
                        continue;
                    };
                    if let Some(i) = ack
                        .return_codes
                        .iter()
                        .position(|c| matches!(c, SubscribeReasonCode::Failure))
                    {
                        let filter: Option<&SubscribeFilter> = subscribe.filters.get(i);
                        tracing::error!(
                            "historian: the broker refused the subscription to {}",
                            filter.map_or("?", |f| f.path.as_str())
                        );
                    } else if !subscribe.data {
                        state_subscribed = true;
                    } else {
                        self.health.set_broker(None);
                        self.metrics.mqtt_connected.set(1);
                        tracing::info!(
                            "historian: online on mqtt://{}:{}",
                            self.describe.0,
                            self.describe.1
                        );
                    }
                }
                Ok(Event::Incoming(Packet::Publish(p))) => {
                    if p.topic == self.state_topic {
                        self.on_own_state(&p.payload, state_subscribed);
                    } else if let Err(e) = self.on_message(&p.topic, &p.payload).await {
                        return e;
                    }
                }
                Ok(Event::Outgoing(Outgoing::Disconnect)) => {
                    return "disconnected".to_owned();
                }
                Ok(_) => {}
                Err(e) => {
                    return kit::mqtt::tls::describe(&e, &self.describe.0, self.describe.1);
                }
            }
        }
    }

    fn publish(&self, message: Publish) -> Result<(), String> {
        let topic = message.topic.to_string();
        self.client
            .try_publish(&topic, qos(message.qos), message.retain, message.payload)
            .map_err(|e| format!("cannot publish {topic}: {e}"))
    }

    /// A STATE on the historian's own topic: anything but online is answered with online,
    /// unless the historian is going offline itself, or it is an offline older than this
    /// connection queued for the session (its own Will after a `kill -9`: the online this
    /// connection published since is the retained STATE already).
    fn on_own_state(&self, payload: &[u8], subscribed: bool) {
        if self.leaving.load(Ordering::SeqCst) {
            return;
        }
        if !subscribed
            && let Ok(state) = sparkplug::HostState::from_json(payload)
            && state.timestamp < self.online_at.as_millis()
        {
            tracing::debug!(
                "historian: an earlier session's STATE {:?} queued while away, ignored",
                String::from_utf8_lossy(payload)
            );
            return;
        }
        let Some(online) = lock(&self.host).reassert_online(payload, self.online_at) else {
            return;
        };
        let topic = online.topic.to_string();
        if let Err(e) = self.publish(online) {
            // The next such STATE is answered again.
            tracing::warn!("historian: {e}");
            return;
        }
        self.metrics.state_reasserted.inc();
        let due = lock_throttles(&self.throttles)
            .state_reasserted
            .count(tokio::time::Instant::now());
        if let Some(count) = due {
            tracing::warn!(
                "historian: {count} STATE message(s) on {topic} that did not say online while \
                 the historian is (the latest: {:?}); online announced again. Another client \
                 publishes on the historian's STATE topic: restrict it in the broker's ACL",
                String::from_utf8_lossy(&payload[..payload.len().min(200)])
            );
        }
    }

    async fn on_message(&self, topic: &str, payload: &[u8]) -> Result<(), String> {
        let (received, nodes, points) = {
            let mut host = lock(&self.host);
            let received = host.receive(topic, payload, now_ms());
            (received, host.nodes_born(), host.points_held())
        };
        self.health.set_nodes_online(nodes);
        let m = &self.metrics;
        m.messages.inc();
        m.points_held.set(i64::try_from(points).unwrap_or(i64::MAX));
        m.samples_received.inc_by(received.samples.len() as u64);
        for problem in &received.problems {
            m.problems.inc();
            match problem.problem {
                Problem::SeqGap { .. } => {
                    m.seq_gaps.inc();
                }
                Problem::BirthRefused { .. } => {
                    m.births_refused.inc();
                    let due = lock_throttles(&self.throttles)
                        .refused_births
                        .count(tokio::time::Instant::now());
                    if let Some(count) = due {
                        tracing::warn!(
                            "historian: {count} birth(s) refused for the historian's limits \
                             (--max-nodes, --max-points, --max-node-points) since the last \
                             report; the latest on {problem}"
                        );
                    }
                    continue;
                }
                Problem::BadMetricName { .. } => {
                    m.names_refused.inc();
                }
                _ => {}
            }
            tracing::debug!("historian: {problem}");
        }
        for command in &received.commands {
            m.rebirths.inc();
            tracing::info!("historian: asking for a rebirth on {}", command.topic);
        }
        for command in received.commands.iter().cloned() {
            // A full queue loses a Rebirth request; the host asks again later.
            if let Err(e) = self.publish(command) {
                tracing::warn!("historian: {e}");
            }
        }
        if received.points.is_empty() && received.samples.is_empty() && received.events.is_empty() {
            return Ok(());
        }
        let mut batch = Batch::default();
        ingest::append(&mut batch, &received);
        self.rows
            .send(batch)
            .await
            .map_err(|_| "the writer stopped".to_owned())
    }
}
