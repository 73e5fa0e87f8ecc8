//! Who is connected: the client's socket address for the audit log.
//!
//! async-opcua 0.19 takes the accepted `TcpStream` into its connection task
//! (`Server::run_with` → `TcpConnector::new(socket, …)`) and keeps the peer address only
//! for a log line; a `Session` knows its secure channel id, not its socket. So the gateway
//! accepts the clients itself and relays each connection to the server, listening on
//! loopback, while watching the server's first answers: the OpenSecureChannel response
//! carries the secure channel id ([`ChannelSniffer`]). [`Peers`] maps that id to the
//! client's address while the connection lasts, and a write's audit row says
//! `from IP:PORT` (the session's `secure_channel_id`).
//!
//! The relay also guards the server's sessions ([`Guard`]). async-opcua 0.19 keeps a
//! session that was created but never activated until its session timeout, also after its
//! channel closed, and counts it against the server's session limit; it offers no way to
//! close a session from outside (`SessionManager::expire_session` is crate-private), and a
//! never-activated session can be closed only by a CloseSession on the channel that
//! created it. The relay passes whole chunks ([`chunks`](super::chunks)); on plain
//! channels (security None, where anyone may create sessions) it reads each
//! CreateSession response's authentication token and, when the session is not activated
//! within `activation_timeout` or the client leaves first, closes the client's connection,
//! sends the server a CloseSession for it on the client's channel and closes the
//! channel. It also refuses a session beyond `sessions_per_address` from one IP address
//! (the response is not passed on).

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use ::opcua::types::NodeId;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::watch;
use tokio::time::Instant;

use super::chunks::{self, ClientSide, Framer, ServerSide};

/// The length of an OPC UA TCP message header: type (3), chunk (1), size (4).
const HEADER_LEN: usize = 8;
/// The header and the secure channel id of a secure conversation message.
const CHANNEL_HEADER_LEN: usize = 12;
/// Server bytes watched before the sniffer gives up (a Hello's ACK and an
/// OpenSecureChannel response with a 16 kB certificate chain fit many times).
const SNIFF_LIMIT: u64 = 1 << 20;
/// The relay's buffer per direction.
const RELAY_BUFFER: usize = 64 * 1024;
/// Client connections relayed at once; more are closed as they come (each costs three
/// sockets and two buffers until the server's hello timeout ends it: a flood of idle
/// connections must not exhaust the process's memory or file descriptors).
pub const MAX_CONNECTIONS: usize = 256;

/// How long the relay waits for the server's answers to the CloseSession requests it sent.
const CLOSE_WAIT: Duration = Duration::from_secs(2);
/// How long one write to either side may take before the connection is dropped (a client
/// that does not read must not hold the relay's checks).
const WRITE_LIMIT: Duration = Duration::from_secs(10);

/// The clients' addresses by secure channel id, the open connections, the sessions of
/// plain channels by IP address, and the sessions refused.
#[derive(Debug, Default)]
pub struct Peers {
    by_channel: Mutex<HashMap<u32, SocketAddr>>,
    connections: AtomicU64,
    /// Authentication tokens of the sessions created on plain channels, by client IP.
    sessions: Mutex<HashMap<IpAddr, Vec<NodeId>>>,
    not_activated: AtomicU64,
    abandoned: AtomicU64,
    per_address: AtomicU64,
    /// Closings are logged at most every 10 s (a flood makes thousands).
    closings: Mutex<gateway::write::LogThrottle>,
}

/// Why the relay closed or refused a session.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// Not activated within `activation_timeout`.
    NotActivated,
    /// Its client left (or was cut off) before activating it.
    Abandoned,
    /// Its IP address had `sessions_per_address` sessions already.
    PerAddress,
}

impl Refusal {
    /// The `reason` label of the metric.
    pub fn label(self) -> &'static str {
        match self {
            Self::NotActivated => "not_activated",
            Self::Abandoned => "abandoned",
            Self::PerAddress => "per_address",
        }
    }
}

/// A session as the server holds it, looked up by authentication token.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SessionState {
    /// The server has no such session (closed or timed out).
    Gone,
    /// Created, not activated yet.
    Waiting,
    /// Activated.
    Activated,
}

/// Looks sessions up in the server (async-opcua's `SessionManager::find_by_token`).
pub trait SessionStates: Send + Sync {
    /// The state of the session with authentication token `token`.
    fn state(&self, token: &NodeId) -> SessionState;
}

/// What the relay enforces on the sessions of plain channels.
#[derive(Clone)]
pub struct Guard {
    /// How long a created session may wait for its activation.
    pub activation_timeout: Duration,
    /// Sessions at once from one IP address.
    pub sessions_per_address: usize,
    /// Where the sessions' states are read.
    pub sessions: Arc<dyn SessionStates>,
}

impl std::fmt::Debug for Guard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Guard")
            .field("activation_timeout", &self.activation_timeout)
            .field("sessions_per_address", &self.sessions_per_address)
            .finish_non_exhaustive()
    }
}

impl Peers {
    /// Sessions the relay closed or refused for `reason`.
    pub fn refused(&self, reason: Refusal) -> u64 {
        self.refusals(reason).load(Ordering::Relaxed)
    }

    fn refusals(&self, reason: Refusal) -> &AtomicU64 {
        match reason {
            Refusal::NotActivated => &self.not_activated,
            Refusal::Abandoned => &self.abandoned,
            Refusal::PerAddress => &self.per_address,
        }
    }

    /// Records the session `token` that `ip` created, unless `ip` has `cap` sessions the
    /// server still holds; says whether it did. Sessions gone from the server are
    /// forgotten on the way.
    fn admit(&self, ip: IpAddr, token: NodeId, cap: usize, states: &dyn SessionStates) -> bool {
        let mut sessions = self.sessions.lock().unwrap_or_else(PoisonError::into_inner);
        sessions.retain(|_, tokens| {
            tokens.retain(|t| states.state(t) != SessionState::Gone);
            !tokens.is_empty()
        });
        let tokens = sessions.entry(ip).or_default();
        if tokens.len() >= cap {
            return false;
        }
        tokens.push(token);
        true
    }

    /// The address of the client on secure channel `channel`, while it is connected.
    pub fn address(&self, channel: u32) -> Option<SocketAddr> {
        self.lock().get(&channel).copied()
    }

    /// Open client connections.
    pub fn connections(&self) -> u64 {
        self.connections.load(Ordering::Relaxed)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<u32, SocketAddr>> {
        self.by_channel
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
    }
}

/// What the sniffer has learnt from the server's bytes so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sniffed {
    /// Not yet: feed more of the server's bytes.
    Waiting,
    /// The secure channel id of the connection's OpenSecureChannel response.
    Channel(u32),
    /// The server's bytes are not what was expected before a channel (an error, a close,
    /// a malformed header, or more than [`SNIFF_LIMIT`] bytes): stop watching.
    GaveUp,
}

/// Finds the secure channel id in the bytes a server sends on one connection, sans-IO:
/// the messages before the first `OPN` (the `ACK` to the client's Hello) are skipped by
/// their size; the `OPN` message's header is followed by its secure channel id
/// (OPC UA Part 6, 7.1.2).
#[derive(Debug, Clone)]
pub struct ChannelSniffer {
    header: [u8; CHANNEL_HEADER_LEN],
    have: usize,
    /// Bytes of the current message still to skip after its header.
    skip: u64,
    seen: u64,
    state: Sniffed,
}

impl Default for ChannelSniffer {
    fn default() -> Self {
        Self::new()
    }
}

impl ChannelSniffer {
    /// A sniffer at the start of a connection.
    pub fn new() -> Self {
        Self {
            header: [0; CHANNEL_HEADER_LEN],
            have: 0,
            skip: 0,
            seen: 0,
            state: Sniffed::Waiting,
        }
    }

    /// What is known so far.
    pub fn state(&self) -> Sniffed {
        self.state
    }

    /// Takes the next bytes the server sent; says what is known after them.
    pub fn feed(&mut self, mut bytes: &[u8]) -> Sniffed {
        while self.state == Sniffed::Waiting && !bytes.is_empty() {
            if self.seen > SNIFF_LIMIT {
                self.state = Sniffed::GaveUp;
                break;
            }
            if self.skip > 0 {
                let n = usize::try_from(self.skip)
                    .unwrap_or(usize::MAX)
                    .min(bytes.len());
                self.skip -= n as u64;
                self.seen += n as u64;
                bytes = &bytes[n..];
                continue;
            }
            let want = if self.have < HEADER_LEN || !self.is_open() {
                HEADER_LEN
            } else {
                CHANNEL_HEADER_LEN
            };
            let n = (want - self.have).min(bytes.len());
            self.header[self.have..self.have + n].copy_from_slice(&bytes[..n]);
            self.have += n;
            self.seen += n as u64;
            bytes = &bytes[n..];
            if self.have < want {
                continue;
            }
            self.state = self.judge_header();
        }
        self.state
    }

    fn is_open(&self) -> bool {
        &self.header[..3] == b"OPN"
    }

    /// A whole header (12 bytes for OPN, 8 otherwise) is in: the channel, a message to
    /// skip, or trouble.
    fn judge_header(&mut self) -> Sniffed {
        let size = u32::from_le_bytes([
            self.header[4],
            self.header[5],
            self.header[6],
            self.header[7],
        ]);
        match &self.header[..3] {
            b"OPN" if self.have == CHANNEL_HEADER_LEN && size as usize >= CHANNEL_HEADER_LEN => {
                Sniffed::Channel(u32::from_le_bytes([
                    self.header[8],
                    self.header[9],
                    self.header[10],
                    self.header[11],
                ]))
            }
            // Only the OPN header is read to 12 bytes; here it is still 8.
            b"OPN" if (size as usize) >= CHANNEL_HEADER_LEN => Sniffed::Waiting,
            b"ACK" if size as usize >= HEADER_LEN => {
                self.skip = u64::from(size) - HEADER_LEN as u64;
                self.have = 0;
                Sniffed::Waiting
            }
            _ => Sniffed::GaveUp,
        }
    }
}

/// Accepts clients on `listener` and relays each to the server on `server` (loopback),
/// recording its address by secure channel id in `peers` and guarding the sessions of
/// plain channels with `guard`, until `stop` turns true.
pub async fn relay(
    listener: TcpListener,
    server: SocketAddr,
    peers: Arc<Peers>,
    guard: Guard,
    mut stop: watch::Receiver<bool>,
) {
    let slots = Arc::new(tokio::sync::Semaphore::new(MAX_CONNECTIONS));
    let mut refused = gateway::write::LogThrottle::default();
    loop {
        let accepted = tokio::select! {
            accepted = listener.accept() => accepted,
            _ = stop.wait_for(|stopped| *stopped) => return,
        };
        match accepted {
            Ok((client, address)) => {
                let Ok(slot) = Arc::clone(&slots).try_acquire_owned() else {
                    drop(client);
                    if let Some(count) = refused.count(tokio::time::Instant::now()) {
                        tracing::warn!(
                            "OPC UA: {MAX_CONNECTIONS} client connections are open; closed \
                             {count} more since the last report (the latest from {address})"
                        );
                    }
                    continue;
                };
                let peers = Arc::clone(&peers);
                let guard = guard.clone();
                tokio::spawn(async move {
                    let _slot = slot;
                    peers.connections.fetch_add(1, Ordering::Relaxed);
                    let channel = relay_one(client, address, server, &peers, &guard).await;
                    peers.connections.fetch_sub(1, Ordering::Relaxed);
                    if let Some(channel) = channel {
                        peers.lock().remove(&channel);
                    }
                });
            }
            Err(e) => {
                tracing::warn!("an OPC UA client connection was not accepted: {e}");
                // Out of file descriptors, most likely: let some close.
                tokio::time::sleep(std::time::Duration::from_millis(100)).await;
            }
        }
    }
}

/// How a relayed connection ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum End {
    /// The client closed, broke the framing, or did not read in time.
    ClientLeft,
    /// The server closed (nothing can be sent on the channel any more).
    ServerLeft,
    /// A session was not activated in time.
    NotActivated,
    /// A session beyond the per-address cap was refused.
    PerAddress,
}

/// One relayed connection: both directions cut into whole chunks.
struct Relayed {
    client_read: OwnedReadHalf,
    client_write: OwnedWriteHalf,
    server_read: OwnedReadHalf,
    server_write: OwnedWriteHalf,
    from_client: Framer,
    from_server: Framer,
    client: ClientSide,
    server: ServerSide,
    sniffer: ChannelSniffer,
    channel: Option<u32>,
    /// Sessions created on this connection and not yet seen activated, with their
    /// deadlines.
    waiting: Vec<(NodeId, Instant)>,
}

/// Relays one connection until either side closes, or a session of a plain channel is
/// not activated in time or is one too many for the client's address; returns the secure
/// channel id it recorded.
async fn relay_one(
    client: TcpStream,
    address: SocketAddr,
    server: SocketAddr,
    peers: &Peers,
    guard: &Guard,
) -> Option<u32> {
    let upstream = match TcpStream::connect(server).await {
        Ok(s) => s,
        Err(e) => {
            tracing::warn!("cannot relay the OPC UA client {address} to the server: {e}");
            return None;
        }
    };
    let _ = client.set_nodelay(true);
    let _ = upstream.set_nodelay(true);
    let (client_read, client_write) = client.into_split();
    let (server_read, server_write) = upstream.into_split();
    let mut relayed = Relayed {
        client_read,
        client_write,
        server_read,
        server_write,
        from_client: Framer::default(),
        from_server: Framer::default(),
        client: ClientSide::default(),
        server: ServerSide::default(),
        sniffer: ChannelSniffer::new(),
        channel: None,
        waiting: Vec::new(),
    };
    let (end, refused) = relayed.run(address, peers, guard).await;
    if end != End::ServerLeft && relayed.client.is_plain() {
        let mut to_close: Vec<(NodeId, Refusal)> = refused
            .into_iter()
            .map(|token| (token, Refusal::PerAddress))
            .collect();
        let reason = if end == End::NotActivated {
            Refusal::NotActivated
        } else {
            Refusal::Abandoned
        };
        for (token, _) in std::mem::take(&mut relayed.waiting) {
            if guard.sessions.state(&token) == SessionState::Waiting {
                to_close.push((token, reason));
            }
        }
        relayed.close_sessions(address, to_close, peers).await;
    }
    relayed.channel
}

impl Relayed {
    /// Passes whole chunks both ways until the connection ends; returns how, and the
    /// token of a session refused for the per-address cap.
    async fn run(
        &mut self,
        address: SocketAddr,
        peers: &Peers,
        guard: &Guard,
    ) -> (End, Option<NodeId>) {
        let mut from_client = vec![0; RELAY_BUFFER];
        let mut from_server = vec![0; RELAY_BUFFER];
        loop {
            let deadline = self.waiting.iter().map(|(_, due)| *due).min();
            tokio::select! {
                read = self.client_read.read(&mut from_client) => {
                    let n = match read {
                        Ok(0) | Err(_) => return (End::ClientLeft, None),
                        Ok(n) => n,
                    };
                    self.from_client.push(&from_client[..n]);
                    loop {
                        let chunk = match self.from_client.next_chunk() {
                            Ok(Some(chunk)) => chunk,
                            Ok(None) => break,
                            Err(e) => {
                                tracing::info!("OPC UA: closed the connection of {address}: {e}");
                                return (End::ClientLeft, None);
                            }
                        };
                        self.client.see(&chunk);
                        // A client closing a plain channel: the relay first closes the
                        // sessions it left waiting (or is being answered), then the channel.
                        if chunk.starts_with(b"CLO") && self.client.is_plain() {
                            return (End::ClientLeft, None);
                        }
                        if !write(&mut self.server_write, &chunk).await {
                            return (End::ServerLeft, None);
                        }
                    }
                }
                read = self.server_read.read(&mut from_server) => {
                    let n = match read {
                        Ok(0) | Err(_) => return (End::ServerLeft, None),
                        Ok(n) => n,
                    };
                    self.from_server.push(&from_server[..n]);
                    loop {
                        let chunk = match self.from_server.next_chunk() {
                            Ok(Some(chunk)) => chunk,
                            Ok(None) => break,
                            Err(e) => {
                                tracing::warn!("OPC UA: the server sent {e}; closed {address}");
                                return (End::ServerLeft, None);
                            }
                        };
                        if self.sniffer.state() == Sniffed::Waiting
                            && let Sniffed::Channel(id) = self.sniffer.feed(&chunk)
                        {
                            peers.lock().insert(id, address);
                            self.channel = Some(id);
                        }
                        if self.client.is_plain()
                            && let Some(token) = self.server.see(&chunk)
                        {
                            if !peers.admit(
                                address.ip(),
                                token.clone(),
                                guard.sessions_per_address,
                                guard.sessions.as_ref(),
                            ) {
                                return (End::PerAddress, Some(token));
                            }
                            self.waiting
                                .push((token, Instant::now() + guard.activation_timeout));
                        }
                        if !write(&mut self.client_write, &chunk).await {
                            return (End::ClientLeft, None);
                        }
                    }
                }
                () = tokio::time::sleep_until(deadline.unwrap_or_else(Instant::now)),
                    if deadline.is_some() =>
                {
                    let now = Instant::now();
                    self.waiting
                        .retain(|(token, _)| guard.sessions.state(token) == SessionState::Waiting);
                    if self.waiting.iter().any(|(_, due)| *due <= now) {
                        return (End::NotActivated, None);
                    }
                }
            }
        }
    }

    /// Ends the client's side, sends the server a CloseSession on the client's channel for
    /// each session in `to_close`, and reads the server's answers to every request still
    /// open (at most [`CLOSE_WAIT`]): a session created meanwhile (requests sent before
    /// the client left) is closed too. Counts and logs them.
    async fn close_sessions(
        &mut self,
        address: SocketAddr,
        mut to_close: Vec<(NodeId, Refusal)>,
        peers: &Peers,
    ) {
        let _ = self.client_write.shutdown().await;
        let until = Instant::now() + CLOSE_WAIT;
        let mut closed: Vec<&'static str> = Vec::new();
        let mut buffer = vec![0; RELAY_BUFFER];
        loop {
            for (token, reason) in to_close.drain(..) {
                peers.refusals(reason).fetch_add(1, Ordering::Relaxed);
                closed.push(reason.label());
                let request = self
                    .channel
                    .zip(self.client.next())
                    .and_then(|(channel, next)| {
                        chunks::close_session(channel, next, &token).map(|chunk| (next, chunk))
                    });
                let Some((next, chunk)) = request else {
                    tracing::warn!(
                        "OPC UA: cannot close a session of {address} on its channel; it ends \
                         with its session timeout"
                    );
                    continue;
                };
                if !write(&mut self.server_write, &chunk).await {
                    break;
                }
                self.client.sent(next);
            }
            if self.client.unanswered(&self.server) == 0 {
                break;
            }
            let read = tokio::time::timeout_at(until, self.server_read.read(&mut buffer)).await;
            let Ok(Ok(n @ 1..)) = read else { break };
            self.from_server.push(&buffer[..n]);
            while let Ok(Some(chunk)) = self.from_server.next_chunk() {
                if let Some(token) = self.server.see(&chunk) {
                    to_close.push((token, Refusal::Abandoned));
                }
            }
        }
        let due = (!closed.is_empty())
            .then(|| {
                peers
                    .closings
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .count(Instant::now())
            })
            .flatten();
        if let Some(times) = due {
            tracing::warn!(
                "OPC UA: closed {} session(s) of {address} ({}); {times} connection(s) had \
                 sessions closed since the last report (counts in /healthz, opcua.refused)",
                closed.len(),
                closed.join(", ")
            );
        }
    }
}

/// Writes `bytes` within [`WRITE_LIMIT`]; false when the other side is gone or stuck.
async fn write(to: &mut OwnedWriteHalf, bytes: &[u8]) -> bool {
    matches!(
        tokio::time::timeout(WRITE_LIMIT, to.write_all(bytes)).await,
        Ok(Ok(()))
    )
}

#[cfg(test)]
mod tests;
