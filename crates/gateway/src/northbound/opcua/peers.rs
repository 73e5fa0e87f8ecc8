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
    closings: Mutex<crate::write::LogThrottle>,
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
    let mut refused = crate::write::LogThrottle::default();
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
mod tests {
    use super::*;

    fn message(kind: &[u8; 3], body: &[u8]) -> Vec<u8> {
        let mut m = kind.to_vec();
        m.push(b'F');
        m.extend_from_slice(&((HEADER_LEN + body.len()) as u32).to_le_bytes());
        m.extend_from_slice(body);
        m
    }

    /// A server whose sessions are in `states`; any other is gone.
    struct States(Vec<(NodeId, SessionState)>);

    impl SessionStates for States {
        fn state(&self, token: &NodeId) -> SessionState {
            self.0
                .iter()
                .find(|(t, _)| t == token)
                .map_or(SessionState::Gone, |(_, s)| *s)
        }
    }

    fn guard(states: &[(NodeId, SessionState)]) -> Guard {
        Guard {
            activation_timeout: Duration::from_secs(5),
            sessions_per_address: 2,
            sessions: Arc::new(States(states.to_vec())),
        }
    }

    /// One end of a relayed connection, read chunk by chunk.
    struct Side {
        stream: TcpStream,
        framer: Framer,
    }

    impl Side {
        fn new(stream: TcpStream) -> Self {
            Self {
                stream,
                framer: Framer::default(),
            }
        }

        async fn send(&mut self, chunk: &[u8]) {
            self.stream.write_all(chunk).await.unwrap();
        }

        /// The next whole chunk, or None once the other side closed (60 s at most).
        async fn chunk(&mut self) -> Option<Vec<u8>> {
            let next = async {
                let mut buffer = [0_u8; 4096];
                loop {
                    if let Ok(Some(chunk)) = self.framer.next_chunk() {
                        return Some(chunk);
                    }
                    match self.stream.read(&mut buffer).await {
                        Ok(0) | Err(_) => return None,
                        Ok(n) => self.framer.push(&buffer[..n]),
                    }
                }
            };
            tokio::time::timeout(Duration::from_secs(60), next)
                .await
                .expect("the relay answers or closes within 60 s")
        }
    }

    /// A relay guarded by `guard` to a scripted server; the client has opened a plain
    /// channel (id 7, sequence numbers 1 and 2) and created the session `testing::token()`.
    async fn session_created(guard: Guard) -> (Arc<Peers>, Side, Side, watch::Sender<bool>) {
        use super::super::chunks::testing::{
            NONE, chunk, create_session_response, open, plain_msg,
        };
        let server = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let peers = Arc::new(Peers::default());
        let (stop, stopped) = watch::channel(false);
        let server_addr = server.local_addr().unwrap();
        tokio::spawn(relay(
            listener,
            server_addr,
            Arc::clone(&peers),
            guard,
            stopped,
        ));
        let mut client = Side::new(TcpStream::connect(addr).await.unwrap());
        let mut upstream = Side::new(server.accept().await.unwrap().0);
        let mut exchange = async |request: Vec<u8>, answer: Vec<u8>| {
            client.send(&request).await;
            assert_eq!(upstream.chunk().await.as_deref(), Some(&request[..]));
            upstream.send(&answer).await;
            assert_eq!(client.chunk().await.as_deref(), Some(&answer[..]));
        };
        exchange(chunk(b"HELF", &[0; 24]), chunk(b"ACKF", &[0; 20])).await;
        let mut opened = 7_u32.to_le_bytes().to_vec();
        opened.extend_from_slice(&[0xAA; 40]);
        exchange(open(NONE, 1, 1), chunk(b"OPNF", &opened)).await;
        let (_, created) = create_session_response(::opcua::types::StatusCode::Good);
        exchange(
            plain_msg(b"MSGF", 1, 2, 2, &[0; 10]),
            plain_msg(b"MSGF", 1, 1, 2, &created),
        )
        .await;
        (peers, client, upstream, stop)
    }

    /// Checks that `chunk` is a CloseSession for `testing::token()` with `sequence`.
    fn is_close_session(chunk: &[u8], sequence: u32) {
        use ::opcua::types::{BinaryDecodable, CloseSessionRequest, ContextOwned};
        assert_eq!(&chunk[..4], b"MSGF");
        assert_eq!(chunk[16..20], sequence.to_le_bytes());
        let context = ContextOwned::default();
        let mut body = std::io::Cursor::new(&chunk[24..]);
        let _kind = NodeId::decode(&mut body, &context.context()).unwrap();
        let request = CloseSessionRequest::decode(&mut body, &context.context()).unwrap();
        assert_eq!(
            request.request_header.authentication_token,
            super::super::chunks::testing::token()
        );
    }

    #[tokio::test]
    async fn a_session_left_waiting_when_its_client_closes_the_channel_is_closed_on_it() {
        use super::super::chunks::testing::{plain_msg, token};
        let (peers, mut client, mut upstream, _stop) =
            session_created(guard(&[(token(), SessionState::Waiting)])).await;
        client.send(&plain_msg(b"CLOF", 1, 3, 3, &[0; 4])).await;
        // Not the CLO: a CloseSession first, next in the client's sequence.
        let close = upstream.chunk().await.expect("a CloseSession");
        is_close_session(&close, 4);
        upstream.send(&plain_msg(b"MSGF", 1, 2, 4, &[0; 8])).await;
        assert_eq!(upstream.chunk().await, None, "then the channel is closed");
        assert_eq!(client.chunk().await, None);
        assert_eq!(peers.refused(Refusal::Abandoned), 1);
    }

    #[tokio::test]
    async fn a_session_not_activated_in_time_is_closed_with_its_connection() {
        use super::super::chunks::testing::{plain_msg, token};
        let mut quick = guard(&[(token(), SessionState::Waiting)]);
        quick.activation_timeout = Duration::from_millis(50);
        let (peers, mut client, mut upstream, _stop) = session_created(quick).await;
        let close = upstream.chunk().await.expect("a CloseSession");
        is_close_session(&close, 3);
        upstream.send(&plain_msg(b"MSGF", 1, 2, 3, &[0; 8])).await;
        assert_eq!(client.chunk().await, None, "the client is cut off");
        assert_eq!(upstream.chunk().await, None);
        assert_eq!(peers.refused(Refusal::NotActivated), 1);
    }

    #[tokio::test]
    async fn an_activated_session_is_left_alone_when_its_client_leaves() {
        use super::super::chunks::testing::token;
        let mut quick = guard(&[(token(), SessionState::Activated)]);
        quick.activation_timeout = Duration::from_millis(50);
        let (peers, client, mut upstream, _stop) = session_created(quick).await;
        drop(client);
        assert_eq!(
            upstream.chunk().await,
            None,
            "closed without a CloseSession"
        );
        for reason in [
            Refusal::NotActivated,
            Refusal::Abandoned,
            Refusal::PerAddress,
        ] {
            assert_eq!(peers.refused(reason), 0);
        }
    }

    #[test]
    fn an_address_gets_sessions_up_to_its_cap_and_gone_sessions_free_their_places() {
        let token = |n: u32| NodeId::new(0, n);
        let peers = Peers::default();
        let one: IpAddr = "192.0.2.1".parse().unwrap();
        let two: IpAddr = "192.0.2.2".parse().unwrap();
        let live = States(vec![
            (token(1), SessionState::Activated),
            (token(2), SessionState::Waiting),
            (token(3), SessionState::Waiting),
        ]);
        assert!(peers.admit(one, token(1), 2, &live));
        assert!(peers.admit(one, token(2), 2, &live));
        assert!(!peers.admit(one, token(3), 2, &live));
        assert!(peers.admit(two, token(3), 2, &live));
        // Session 1 closes: its address may have one more.
        let later = States(vec![
            (token(2), SessionState::Waiting),
            (token(3), SessionState::Waiting),
        ]);
        assert!(peers.admit(one, token(4), 2, &later));
        assert_eq!(Refusal::PerAddress.label(), "per_address");
    }

    fn server_bytes() -> Vec<u8> {
        let mut bytes = message(b"ACK", &[0; 20]);
        let mut open = 7_u32.to_le_bytes().to_vec();
        open.extend_from_slice(&[0xAA; 100]);
        bytes.extend(message(b"OPN", &open));
        bytes.extend(message(b"MSG", &[1, 0, 0, 0, 9, 9]));
        bytes
    }

    #[tokio::test]
    async fn connections_beyond_the_cap_are_closed_and_a_slot_freed_is_taken_again() {
        let server = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let server_addr = server.local_addr().unwrap();
        // The server side accepts and holds every connection, as a server waiting for a
        // Hello does.
        let held = tokio::spawn(async move {
            let mut held = Vec::new();
            while let Ok((socket, _)) = server.accept().await {
                held.push(socket);
            }
        });
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let peers = std::sync::Arc::new(Peers::default());
        let (stop, stopped) = watch::channel(false);
        tokio::spawn(relay(
            listener,
            server_addr,
            std::sync::Arc::clone(&peers),
            guard(&[]),
            stopped,
        ));
        let mut open = Vec::new();
        for _ in 0..MAX_CONNECTIONS {
            open.push(TcpStream::connect(addr).await.unwrap());
        }
        let relayed = tokio::time::timeout(std::time::Duration::from_secs(60), async {
            while peers.connections() < MAX_CONNECTIONS as u64 {
                tokio::task::yield_now().await;
            }
        });
        relayed
            .await
            .expect("every connection up to the cap is relayed");
        // One more is closed at once: its read ends.
        let closed_at_once = |mut extra: TcpStream| async move {
            let mut byte = [0u8; 1];
            tokio::time::timeout(std::time::Duration::from_secs(60), extra.read(&mut byte))
                .await
                .expect("closed, not held")
                .map_or(true, |n| n == 0)
        };
        let extra = TcpStream::connect(addr).await.unwrap();
        assert!(closed_at_once(extra).await);
        // A client leaves; the next one is relayed.
        drop(open.pop());
        let freed = tokio::time::timeout(std::time::Duration::from_secs(60), async {
            while peers.connections() == MAX_CONNECTIONS as u64 {
                tokio::task::yield_now().await;
            }
        });
        freed.await.expect("the slot is freed");
        let mut next = TcpStream::connect(addr).await.unwrap();
        next.write_all(b"HEL").await.unwrap();
        let waited = tokio::time::timeout(
            std::time::Duration::from_millis(200),
            next.read(&mut [0u8; 1]),
        )
        .await;
        assert!(
            waited.is_err(),
            "relayed and waiting for the server, not closed"
        );
        stop.send(true).unwrap();
        held.abort();
    }

    #[test]
    fn the_channel_id_is_read_from_the_open_response_after_the_ack() {
        let mut sniffer = ChannelSniffer::new();
        assert_eq!(sniffer.feed(&server_bytes()), Sniffed::Channel(7));
    }

    #[test]
    fn the_server_bytes_split_anywhere_give_the_same_channel() {
        let bytes = server_bytes();
        for split in 0..bytes.len() {
            let mut sniffer = ChannelSniffer::new();
            sniffer.feed(&bytes[..split]);
            assert_eq!(
                sniffer.feed(&bytes[split..]),
                Sniffed::Channel(7),
                "{split}"
            );
        }
        let mut sniffer = ChannelSniffer::new();
        for b in &bytes {
            sniffer.feed(std::slice::from_ref(b));
        }
        assert_eq!(sniffer.state(), Sniffed::Channel(7));
    }

    #[test]
    fn an_error_or_a_bad_header_before_the_channel_gives_up() {
        let mut sniffer = ChannelSniffer::new();
        assert_eq!(sniffer.feed(&message(b"ERR", &[0; 8])), Sniffed::GaveUp);
        let mut sniffer = ChannelSniffer::new();
        assert_eq!(sniffer.feed(b"ACKF\x02\0\0\0"), Sniffed::GaveUp);
        let mut sniffer = ChannelSniffer::new();
        assert_eq!(sniffer.feed(b"OPNF\x0b\0\0\0\x07\0\0\0"), Sniffed::GaveUp);
    }

    #[test]
    fn endless_acks_stop_being_watched() {
        let mut sniffer = ChannelSniffer::new();
        let ack = message(b"ACK", &[0; 4096]);
        let mut state = Sniffed::Waiting;
        for _ in 0..(SNIFF_LIMIT / 4096 + 2) {
            state = sniffer.feed(&ack);
        }
        assert_eq!(state, Sniffed::GaveUp);
    }

    #[test]
    fn random_bytes_never_panic() {
        let mut rng = fastrand::Rng::with_seed(14);
        for _ in 0..2_000 {
            let len = rng.usize(0..64);
            let mut bytes: Vec<u8> = (0..len).map(|_| rng.u8(..)).collect();
            if rng.bool() {
                bytes.splice(0..0, b"ACKF\x0c\0\0\0\0\0\0\0OPNF".iter().copied());
            }
            let mut sniffer = ChannelSniffer::new();
            for chunk in bytes.chunks(rng.usize(1..8)) {
                sniffer.feed(chunk);
            }
        }
    }
}
