//! The endpoints' own AMQP 1.0 listener (`--cfx-listen IP:PORT`, `[cfx] listen`): requests
//! of the root topic, point to point, answered as the SDK's request processor does. A
//! requester attaches a sender to an endpoint's handle (the address requests go to) and a
//! receiver whose target is its reply-to address; it sends the request with `reply-to`;
//! the answer ([`cfx::endpoint::Endpoint::answer`]) goes back on the link whose target is
//! that address, with `correlation-id` = the request's `RequestID`. SASL ANONYMOUS.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, PoisonError};

use fe2o3_amqp::acceptor::{
    ConnectionAcceptor, LinkAcceptor, LinkEndpoint, SaslAnonymousMechanism, SessionAcceptor,
};
use fe2o3_amqp::types::messaging::{Body, Message};
use fe2o3_amqp::types::primitives::Value;
use tokio::net::TcpListener;
use tokio::sync::{mpsc, watch};

use crate::time::Timestamp;

/// Answers waiting for their link, per reply-to address.
type Replies = Arc<Mutex<HashMap<String, mpsc::Sender<cfx::Envelope>>>>;

/// What the listener answers for.
#[derive(Debug, Clone)]
pub struct Listener {
    /// The endpoints now (a reload adds and removes them).
    pub endpoints: super::Endpoints,
    /// The zone answers are dated in.
    pub zone: jiff::tz::TimeZone,
}

/// Serves requests on `socket` until `stop` turns true.
pub async fn serve(socket: TcpListener, listener: Listener, mut stop: watch::Receiver<bool>) {
    let listener = Arc::new(listener);
    let acceptor = Arc::new(
        ConnectionAcceptor::builder()
            .container_id("cellbus-cfx")
            .sasl_acceptor(SaslAnonymousMechanism::new())
            .build(),
    );
    loop {
        let accepted = tokio::select! {
            _ = stop.wait_for(|s| *s) => return,
            accepted = socket.accept() => accepted,
        };
        let (stream, peer) = match accepted {
            Ok(accepted) => accepted,
            Err(e) => {
                tracing::warn!("IPC-CFX listener: {e}");
                continue;
            }
        };
        let (acceptor, listener) = (Arc::clone(&acceptor), Arc::clone(&listener));
        tokio::spawn(async move {
            let mut connection = match acceptor.accept(stream).await {
                Ok(connection) => connection,
                Err(e) => {
                    tracing::debug!("IPC-CFX listener: {peer} did not open: {e}");
                    return;
                }
            };
            let replies = Replies::default();
            let sessions = SessionAcceptor::new();
            while let Ok(mut session) = sessions.accept(&mut connection).await {
                let (listener, replies) = (Arc::clone(&listener), Arc::clone(&replies));
                tokio::spawn(async move {
                    let links = LinkAcceptor::new();
                    while let Ok(link) = links.accept(&mut session).await {
                        match link {
                            LinkEndpoint::Sender(sender) => {
                                // Known before the next link is taken: a request sent
                                // right after its reply link finds it.
                                let Some(address) =
                                    sender.target().as_ref().and_then(|t| t.address.clone())
                                else {
                                    continue;
                                };
                                let (tx, rx) = mpsc::channel(16);
                                replies
                                    .lock()
                                    .unwrap_or_else(PoisonError::into_inner)
                                    .insert(address.clone(), tx);
                                tokio::spawn(answer_on(sender, address, rx, Arc::clone(&replies)));
                            }
                            LinkEndpoint::Receiver(receiver) => {
                                tokio::spawn(requests_on(
                                    receiver,
                                    Arc::clone(&listener),
                                    Arc::clone(&replies),
                                ));
                            }
                        }
                    }
                });
            }
        });
    }
}

/// Sends the answers for `address`, this link's target (a requester's reply-to).
async fn answer_on(
    mut sender: fe2o3_amqp::Sender,
    address: String,
    mut answers: mpsc::Receiver<cfx::Envelope>,
    replies: Replies,
) {
    while let Some(envelope) = answers.recv().await {
        if let Err(e) = sender.send(super::amqp_message(&envelope)).await {
            tracing::debug!("IPC-CFX listener: the answer to {address} was not taken: {e}");
            break;
        }
    }
    replies
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .remove(&address);
    let _ = sender.close().await;
}

/// Takes the requests of one link and answers each.
async fn requests_on(
    mut receiver: fe2o3_amqp::Receiver,
    listener: Arc<Listener>,
    replies: Replies,
) {
    let link_target = receiver.target().as_ref().and_then(|t| t.address.clone());
    loop {
        let delivery = match receiver.recv::<Body<Value>>().await {
            Ok(delivery) => delivery,
            Err(e) => {
                tracing::debug!("IPC-CFX listener: a request link ended: {e}");
                return;
            }
        };
        let _ = receiver.accept(&delivery).await;
        let message: &Message<Body<Value>> = delivery.message();
        let properties = message.properties.as_ref();
        let reply_to = properties.and_then(|p| p.reply_to.clone());
        let to = properties
            .and_then(|p| p.to.clone())
            .or_else(|| link_target.clone());
        let Some(bytes) = body_bytes(&message.body) else {
            tracing::debug!("IPC-CFX listener: a request without a JSON body");
            continue;
        };
        let requests = match cfx::Received::decode(&bytes) {
            Ok(requests) => requests,
            Err(e) => {
                tracing::debug!("IPC-CFX listener: {e}");
                continue;
            }
        };
        let endpoint = {
            let endpoints = listener
                .endpoints
                .read()
                .unwrap_or_else(PoisonError::into_inner);
            endpoints
                .iter()
                .map(|s| &s.endpoint)
                .find(|e| {
                    to.as_deref()
                        .is_some_and(|to| to.ends_with(e.handle.as_str()))
                })
                .or_else(|| endpoints.first().map(|s| &s.endpoint))
                .cloned()
        };
        let Some(endpoint) = endpoint else {
            continue;
        };
        let now = jiff::Timestamp::from_millisecond(Timestamp::now().0)
            .unwrap_or(jiff::Timestamp::UNIX_EPOCH);
        for request in &requests {
            let Some(answer) = endpoint.answer(request, cfx::Time::new(now, &listener.zone)) else {
                continue;
            };
            let link = reply_to.as_ref().and_then(|r| {
                replies
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .get(r)
                    .cloned()
            });
            match link {
                Some(link) => {
                    let _ = link.send(answer).await;
                }
                None => tracing::debug!(
                    "IPC-CFX listener: no link to answer {} on (reply-to {reply_to:?})",
                    request.message_name
                ),
            }
        }
    }
}

/// The JSON bytes of a request's body: its Data sections, or a string or binary value.
fn body_bytes(body: &Body<Value>) -> Option<Vec<u8>> {
    match body {
        Body::Data(sections) => Some(sections.iter().flat_map(|d| d.0.iter().copied()).collect()),
        Body::Value(value) => match &value.0 {
            Value::String(text) => Some(text.clone().into_bytes()),
            Value::Binary(bytes) => Some(bytes.to_vec()),
            _ => None,
        },
        _ => None,
    }
}

/// What a receiver took: the message's subject and its body's bytes, or why the link ended.
pub type Taken = Result<(Option<String>, Vec<u8>), String>;

/// Takes every message sent to `socket` (any address), as a broker-less receiver would:
/// `cellbus cfx sub --listen`, for `serve --cfx` to send to. Each goes to `out`; ends when
/// `out` is closed.
pub async fn receive(socket: TcpListener, out: mpsc::Sender<Taken>) {
    let acceptor = Arc::new(
        ConnectionAcceptor::builder()
            .container_id("cellbus-cfx-sub")
            .sasl_acceptor(SaslAnonymousMechanism::new())
            .build(),
    );
    loop {
        let accepted = tokio::select! {
            () = out.closed() => return,
            accepted = socket.accept() => accepted,
        };
        let Ok((stream, _)) = accepted else {
            continue;
        };
        let (acceptor, out) = (Arc::clone(&acceptor), out.clone());
        tokio::spawn(async move {
            let Ok(mut connection) = acceptor.accept(stream).await else {
                return;
            };
            let sessions = SessionAcceptor::new();
            while let Ok(mut session) = sessions.accept(&mut connection).await {
                let out = out.clone();
                tokio::spawn(async move {
                    let links = LinkAcceptor::new();
                    while let Ok(link) = links.accept(&mut session).await {
                        if let LinkEndpoint::Receiver(receiver) = link {
                            tokio::spawn(take_all(receiver, out.clone()));
                        }
                    }
                });
            }
        });
    }
}

/// Connects to the broker at `url` (`amqp://HOST:PORT`) and takes what comes to `address`:
/// `cellbus cfx sub amqp://HOST:PORT/ADDRESS`. Each goes to `out`; an error ends it.
pub async fn subscribe(
    url: String,
    address: String,
    credentials: Option<(String, String)>,
    out: mpsc::Sender<Taken>,
) {
    let builder = fe2o3_amqp::Connection::builder().container_id("cellbus-cfx-sub");
    let builder = match credentials {
        Some((username, password)) => builder
            .sasl_profile(fe2o3_amqp::sasl_profile::SaslProfile::Plain { username, password }),
        None => builder.sasl_profile(fe2o3_amqp::sasl_profile::SaslProfile::Anonymous),
    };
    let mut connection = match builder.open(url.as_str()).await {
        Ok(connection) => connection,
        Err(e) => {
            let _ = out.send(Err(format!("cannot connect to {url}: {e}"))).await;
            return;
        }
    };
    let mut session = match fe2o3_amqp::Session::begin(&mut connection).await {
        Ok(session) => session,
        Err(e) => {
            let _ = out.send(Err(format!("{url}: no session: {e}"))).await;
            return;
        }
    };
    match fe2o3_amqp::Receiver::attach(&mut session, "cellbus-cfx-sub", address.as_str()).await {
        Ok(receiver) => take_all(receiver, out).await,
        Err(e) => {
            let _ = out
                .send(Err(format!("{url}: address {address} refused: {e}")))
                .await;
        }
    }
}

/// Takes the messages of one link until it ends or `out` is closed.
async fn take_all(mut receiver: fe2o3_amqp::Receiver, out: mpsc::Sender<Taken>) {
    loop {
        let delivery = match receiver.recv::<Body<Value>>().await {
            Ok(delivery) => delivery,
            Err(e) => {
                let _ = out.send(Err(format!("the link ended: {e}"))).await;
                return;
            }
        };
        let _ = receiver.accept(&delivery).await;
        let message = delivery.message();
        let subject = message.properties.as_ref().and_then(|p| p.subject.clone());
        let Some(bytes) = body_bytes(&message.body) else {
            continue;
        };
        if out.send(Ok((subject, bytes))).await.is_err() {
            return;
        }
    }
}
