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

use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, PoisonError};

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::watch;

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

/// The clients' addresses by secure channel id, and the open connections.
#[derive(Debug, Default)]
pub struct Peers {
    by_channel: Mutex<HashMap<u32, SocketAddr>>,
    connections: AtomicU64,
}

impl Peers {
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
/// recording its address by secure channel id in `peers`, until `stop` turns true.
pub async fn relay(
    listener: TcpListener,
    server: SocketAddr,
    peers: std::sync::Arc<Peers>,
    mut stop: watch::Receiver<bool>,
) {
    let slots = std::sync::Arc::new(tokio::sync::Semaphore::new(MAX_CONNECTIONS));
    let mut refused = crate::write::LogThrottle::default();
    loop {
        let accepted = tokio::select! {
            accepted = listener.accept() => accepted,
            _ = stop.wait_for(|stopped| *stopped) => return,
        };
        match accepted {
            Ok((client, address)) => {
                let Ok(slot) = std::sync::Arc::clone(&slots).try_acquire_owned() else {
                    drop(client);
                    if let Some(count) = refused.count(tokio::time::Instant::now()) {
                        tracing::warn!(
                            "OPC UA: {MAX_CONNECTIONS} client connections are open; closed \
                             {count} more since the last report (the latest from {address})"
                        );
                    }
                    continue;
                };
                let peers = std::sync::Arc::clone(&peers);
                tokio::spawn(async move {
                    let _slot = slot;
                    peers.connections.fetch_add(1, Ordering::Relaxed);
                    let channel = relay_one(client, address, server, &peers).await;
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

/// Relays one connection until either side closes; returns the secure channel id it
/// recorded.
async fn relay_one(
    client: TcpStream,
    address: SocketAddr,
    server: SocketAddr,
    peers: &Peers,
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
    let (mut client_read, mut client_write) = client.into_split();
    let (mut server_read, mut server_write) = upstream.into_split();
    let mut channel = None;
    let to_server = tokio::io::copy(&mut client_read, &mut server_write);
    let to_client = async {
        let mut sniffer = ChannelSniffer::new();
        let mut buffer = vec![0; RELAY_BUFFER];
        loop {
            let n = server_read.read(&mut buffer).await?;
            if n == 0 {
                return Ok::<(), std::io::Error>(());
            }
            if sniffer.state() == Sniffed::Waiting {
                if let Sniffed::Channel(id) = sniffer.feed(&buffer[..n]) {
                    peers.lock().insert(id, address);
                    channel = Some(id);
                }
            }
            client_write.write_all(&buffer[..n]).await?;
        }
    };
    tokio::select! {
        _ = to_server => {}
        _ = to_client => {}
    }
    channel
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
