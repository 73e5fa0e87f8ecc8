//! The sender: what is kept, and what is sent at once, over the AMQP link.

use std::sync::Arc;
use std::time::Duration;

use fe2o3_amqp::types::messaging::{ApplicationProperties, Header, Message, Properties};
use fe2o3_amqp::types::primitives::{Binary, SimpleValue, Timestamp as AmqpTime};
use tokio::sync::{Notify, mpsc, watch};
use wire::backoff::Backoff;

use super::config::CfxConfig;
use super::kept::Kept;
use super::{CfxStatus, Endpoints, FINISH_PATIENCE, LINK_PATIENCE, PAGE, shown_stations, stopped};
use crate::time::Timestamp;

/// What the sender needs.
pub(super) struct Sender {
    pub(super) config: CfxConfig,
    pub(super) password: Option<String>,
    /// The endpoints now.
    pub(super) endpoints: Endpoints,
    pub(super) kept: Kept,
    pub(super) status: Arc<CfxStatus>,
}

/// Sends what is kept, oldest first, each removed when the receiver accepted it, and what
/// comes on `now` (heartbeats, the greetings and farewells of endpoints a reload adds and
/// removes) while the link is up; opens the link again with a backoff. Once `finish`
/// turns true (the feeder has kept its last messages), sends what is kept for at most
/// [`FINISH_PATIENCE`], the endpoints' `EndpointShuttingDown`, and closes the link.
pub(super) async fn send(
    sender: Sender,
    wake: Arc<Notify>,
    mut now: mpsc::Receiver<cfx::Envelope>,
    mut finish: watch::Receiver<bool>,
) {
    let Sender {
        config,
        password,
        endpoints,
        kept,
        status,
    } = sender;
    let mut backoff = Backoff::new(Duration::from_secs(1), Duration::from_secs(30)).timer();
    let mut sent: i64 = 0;
    let mut first = true;
    loop {
        let opened = tokio::select! {
            () = stopped(&mut finish) => return,
            opened = tokio::time::timeout(LINK_PATIENCE, Link::open(&config, password.as_deref())) => {
                opened.unwrap_or_else(|_| Err(format!(
                    "{} did not open the link within {LINK_PATIENCE:?}", config.url()
                )))
            }
        };
        let mut link = match opened {
            Ok(link) => link,
            Err(why) => {
                // Said once, not at every try.
                if status.link().err().as_deref() != Some(why.as_str()) {
                    tracing::warn!("IPC-CFX: no link: {why}; trying again");
                }
                status.set_link(Err(why));
                tokio::select! {
                    () = stopped(&mut finish) => return,
                    () = tokio::time::sleep(backoff.next_wait()) => {}
                }
                continue;
            }
        };
        if !first {
            status.metrics.reconnects.inc();
        }
        first = false;
        status.set_link(Ok(()));
        backoff.reset();
        // What was to be sent at once while the link was down is not sent late (every
        // endpoint now greets the line below).
        while now.try_recv().is_ok() {}
        let at = Timestamp::now();
        let lost = 'connected: {
            for station in shown_stations(&endpoints) {
                if let Err(why) = link.send(amqp_message(&station.connected(at))).await {
                    break 'connected why;
                }
            }
            loop {
                if let Err(why) = link.send_kept(&kept, &mut sent, &status).await {
                    break 'connected why;
                }
                tokio::select! {
                    () = stopped(&mut finish) => {
                        let _ = tokio::time::timeout(
                            FINISH_PATIENCE,
                            link.send_kept(&kept, &mut sent, &status),
                        ).await;
                        let at = Timestamp::now();
                        for station in shown_stations(&endpoints) {
                            let _ = link.send(amqp_message(&station.shutting_down(at))).await;
                        }
                        link.close().await;
                        return;
                    }
                    () = wake.notified() => {}
                    Some(envelope) = now.recv() => {
                        if let Err(why) = link.send(amqp_message(&envelope)).await {
                            break 'connected why;
                        }
                    }
                }
            }
        };
        tracing::warn!("IPC-CFX: the link to {} was lost: {lost}", config.url());
        status.set_link(Err(lost));
    }
}

/// An open AMQP link: connection, session, sender.
struct Link {
    connection: fe2o3_amqp::connection::ConnectionHandle<()>,
    session: fe2o3_amqp::session::SessionHandle<()>,
    sender: fe2o3_amqp::Sender,
}

impl Link {
    async fn open(config: &CfxConfig, password: Option<&str>) -> Result<Link, String> {
        let url = config.url();
        let builder = fe2o3_amqp::Connection::builder()
            .container_id(format!(
                "cellbus-{}",
                crate::northbound::default_edge_node_id()
            ))
            .hostname(config.host.as_str());
        // SASL always (a broker such as RabbitMQ wants it; ANONYMOUS without a user).
        let builder = match (&config.username, password) {
            (Some(username), password) => {
                builder.sasl_profile(fe2o3_amqp::sasl_profile::SaslProfile::Plain {
                    username: username.clone(),
                    password: password.unwrap_or_default().to_owned(),
                })
            }
            _ => builder.sasl_profile(fe2o3_amqp::sasl_profile::SaslProfile::Anonymous),
        };
        let opened = match &config.tls {
            None => builder.open(url.as_str()).await,
            // amqps://: TLS on our own stream (fe2o3-amqp's TLS features bring aws-lc;
            // this is the rustls with ring the MQTT link uses), then AMQP inside it.
            Some(files) => {
                let tls = kit::mqtt::tls::client_config(files).map_err(|e| e.to_string())?;
                let name =
                    rustls::pki_types::ServerName::try_from(config.host.clone()).map_err(|e| {
                        format!(
                            "{url}: {} is not a host name TLS can check: {e}",
                            config.host
                        )
                    })?;
                let tcp = tokio::net::TcpStream::connect((config.host.as_str(), config.port))
                    .await
                    .map_err(|e| format!("cannot connect to {url}: {e}"))?;
                let stream = tokio_rustls::TlsConnector::from(tls)
                    .connect(name, tcp)
                    .await
                    .map_err(|e| format!("TLS with {url} failed: {e}"))?;
                builder.open_with_stream(stream).await
            }
        };
        let mut connection = opened.map_err(|e| match e {
            fe2o3_amqp::connection::OpenError::SaslError { code, .. } => {
                let who = match (&config.username, &config.password_env) {
                    (Some(user), Some(var)) => {
                        format!("the user {user} with the password in {var}")
                    }
                    (Some(user), None) => format!("the user {user} without a password"),
                    _ => "an anonymous login".to_owned(),
                };
                format!("cannot connect to {url}: the broker refused {who} (SASL {code:?})")
            }
            e => format!("cannot connect to {url}: {e}"),
        })?;
        let mut session = fe2o3_amqp::Session::begin(&mut connection)
            .await
            .map_err(|e| format!("{url}: no session: {e}"))?;
        let sender =
            fe2o3_amqp::Sender::attach(&mut session, "cellbus-cfx", config.address.as_str())
                .await
                .map_err(|e| format!("{url}: address {} refused: {e}", config.address))?;
        Ok(Link {
            connection,
            session,
            sender,
        })
    }

    /// Sends what is kept after number `sent`, oldest first, moving `sent` on as the
    /// receiver accepts each and removing them from the outbox page by page.
    async fn send_kept(
        &mut self,
        kept: &Kept,
        sent: &mut i64,
        status: &CfxStatus,
    ) -> Result<(), String> {
        loop {
            let after = *sent;
            let page = kept
                .call(move |o| o.waiting(after, PAGE))
                .await
                .map_err(|e| format!("cannot read the kept messages: {e}"))?;
            let Some(&(last, _)) = page.last() else {
                return Ok(());
            };
            let mut result = Ok(());
            for (seq, body) in page {
                match kept_message(&body) {
                    Ok(message) => {
                        if let Err(why) = self.send(message).await {
                            result = Err(why);
                            break;
                        }
                        status.metrics.sent.inc();
                    }
                    Err(why) => {
                        tracing::warn!("IPC-CFX: a kept message is dropped: {why}");
                        status.metrics.dropped.inc();
                    }
                }
                *sent = seq;
            }
            let through = *sent;
            if let Err(e) = kept.call(move |o| o.taken(through)).await {
                tracing::warn!("IPC-CFX: cannot remove the messages sent from the outbox: {e}");
            }
            status.metrics.waiting.set(kept.len().await);
            result?;
            if *sent < last {
                return Ok(());
            }
        }
    }

    /// Sends one message and waits for the receiver's verdict (at most
    /// [`LINK_PATIENCE`]: a receiver that takes no more is a lost link).
    pub(super) async fn send(
        &mut self,
        message: Message<fe2o3_amqp::types::messaging::Data>,
    ) -> Result<(), String> {
        let outcome = tokio::time::timeout(LINK_PATIENCE, self.sender.send(message))
            .await
            .map_err(|_| format!("no verdict on a message within {LINK_PATIENCE:?}"))?
            .map_err(|e| e.to_string())?;
        outcome
            .accepted_or_else(|state| format!("the receiver did not accept it: {state:?}"))
            .map(drop)
    }

    async fn close(self) {
        let Link {
            mut connection,
            mut session,
            sender,
        } = self;
        let _ = sender.close().await;
        let _ = session.end().await;
        let _ = connection.close().await;
    }
}

/// The AMQP message of `envelope`: one Data section of its JSON, the SDK's properties.
pub fn amqp_message(envelope: &cfx::Envelope) -> Message<fe2o3_amqp::types::messaging::Data> {
    message_of(envelope.amqp(), envelope.to_bytes())
}

/// The AMQP message of an envelope kept as its JSON.
fn kept_message(body: &[u8]) -> Result<Message<fe2o3_amqp::types::messaging::Data>, String> {
    let envelopes = cfx::Received::decode(body).map_err(|e| e.to_string())?;
    let [envelope] = envelopes.as_slice() else {
        return Err(format!("{} envelopes in one kept message", envelopes.len()));
    };
    let properties = envelope.amqp().map_err(|e| e.to_string())?;
    Ok(message_of(properties, body.to_vec()))
}

/// One Data section of `body`, with `p`.
fn message_of(
    p: cfx::envelope::AmqpProperties,
    body: Vec<u8>,
) -> Message<fe2o3_amqp::types::messaging::Data> {
    let mut properties = Properties::builder()
        .message_id(p.message_id)
        .subject(p.subject)
        .reply_to(p.reply_to)
        .content_type(p.content_type)
        .creation_time(AmqpTime::from_milliseconds(p.creation_time_ms));
    if let Some(to) = p.to {
        properties = properties.to(to);
    }
    if let Some(correlation) = p.correlation_id {
        properties = properties.correlation_id(correlation);
    }
    let mut application = ApplicationProperties::builder();
    for (key, value) in p.application {
        application = application.insert(key, value.map_or(SimpleValue::Null, SimpleValue::String));
    }
    Message::builder()
        .header(Header {
            durable: true,
            ..Header::default()
        })
        .properties(properties.build())
        .application_properties(application.build())
        .data(Binary::from(body))
        .build()
}
