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
    use super::super::chunks::testing::{NONE, chunk, create_session_response, open, plain_msg};
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
