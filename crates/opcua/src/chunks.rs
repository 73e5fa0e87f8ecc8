//! The OPC UA messages the relay sees, sans-IO: whole chunks, and on plain channels the
//! sessions they create.
//!
//! Every OPC UA TCP message starts with its type and size (OPC UA Part 6, 7.1.2), so
//! [`Framer`] cuts each direction into whole chunks and the relay forwards whole chunks
//! only: it can put a message of its own between two of the client's. On a channel with
//! security policy None the chunks are plain text: [`ClientSide`] follows the client's
//! sequence numbers, [`created_session`] reads the authentication token of a CreateSession
//! response, and [`close_session`] writes the CloseSession request the relay sends for a
//! session that was never activated. (Signed or encrypted chunks cannot be read or added
//! to by the relay; sessions on such channels need a trusted client certificate.)

use std::io::Cursor;

use ::opcua::types::{
    BinaryDecodable, BinaryEncodable, CloseSessionRequest, ContextOwned, DateTime, NodeId,
    ObjectId, RequestHeader, ResponseHeader,
};

/// The length of a message header: type (3), chunk type (1), size (4).
pub const HEADER_LEN: usize = 8;
/// The header, secure channel id, token id, sequence number and request id of a plain
/// (security None) `MSG` or `CLO` chunk; its body follows.
const PLAIN_HEADER_LEN: usize = 24;
/// The largest chunk the relay passes. async-opcua's buffers are 65,535 bytes, and the
/// server refuses larger chunks from clients and sends none larger; this leaves room.
pub const MAX_CHUNK: usize = 1 << 20;
/// The security policy URI of plain channels.
const POLICY_NONE: &[u8] = b"http://opcfoundation.org/UA/SecurityPolicy#None";
/// `CreateSessionResponse_Encoding_DefaultBinary` (464) as the four-byte node id a body
/// starts with: encoding 0x01, namespace 0, 464 little-endian.
const CREATE_SESSION_RESPONSE: [u8; 4] = [0x01, 0x00, 0xD0, 0x01];
/// The last sequence number before the legacy wrap-around (Part 6, 6.7.2.4), after which
/// the relay does not add messages.
const LAST_SEQUENCE: u32 = u32::MAX - 1025;

/// Cuts one direction's bytes into whole chunks.
#[derive(Debug, Default)]
pub struct Framer {
    buffer: Vec<u8>,
    /// Where the next chunk starts in `buffer` (the bytes before were handed out).
    start: usize,
}

/// A chunk header the relay will not pass.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("an OPC UA chunk of {size} bytes (the relay passes {HEADER_LEN} to {MAX_CHUNK})")]
pub struct BadChunk {
    /// The size the header announced.
    pub size: u32,
}

impl Framer {
    /// Takes the next bytes of the stream.
    pub fn push(&mut self, bytes: &[u8]) {
        // The bytes handed out go when they are half the buffer (no move per chunk).
        if self.start > 0 && self.start * 2 >= self.buffer.len() {
            self.buffer.drain(..self.start);
            self.start = 0;
        }
        self.buffer.extend_from_slice(bytes);
    }

    /// The next whole chunk, `Ok(None)` until it is all in, or the header's size when it
    /// is too small or too large (the connection is then broken).
    pub fn next_chunk(&mut self) -> Result<Option<Vec<u8>>, BadChunk> {
        let pending = &self.buffer[self.start..];
        let Some(size) = pending.get(4..HEADER_LEN) else {
            return Ok(None);
        };
        let size = u32::from_le_bytes([size[0], size[1], size[2], size[3]]);
        let len = size as usize;
        if !(HEADER_LEN..=MAX_CHUNK).contains(&len) {
            return Err(BadChunk { size });
        }
        let Some(chunk) = pending.get(..len) else {
            return Ok(None);
        };
        let chunk = chunk.to_vec();
        self.start += len;
        Ok(Some(chunk))
    }
}

/// What the client has sent on its channel, as far as the relay needs it to add a message.
#[derive(Debug, Clone, Default)]
pub struct ClientSide {
    plain: Option<bool>,
    last_sequence: Option<u32>,
    token_id: u32,
    request_id: u32,
    /// Whole requests sent on the plain channel (their last chunks), the relay's too.
    requests: u64,
}

/// The numbers of the next message the relay may send on the client's behalf.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Next {
    /// The channel's current security token id.
    pub token_id: u32,
    /// The sequence number the server expects next.
    pub sequence: u32,
    /// A request id after the client's.
    pub request_id: u32,
}

impl ClientSide {
    /// Takes one whole chunk the client sent (and the relay passed on).
    pub fn see(&mut self, chunk: &[u8]) {
        match chunk.get(..3) {
            Some(b"OPN") => self.see_open(chunk),
            Some(b"MSG" | b"CLO") if self.plain == Some(true) => {
                let (Some(token_id), Some(sequence), Some(request_id)) =
                    (u32_at(chunk, 12), u32_at(chunk, 16), u32_at(chunk, 20))
                else {
                    return;
                };
                self.token_id = token_id;
                self.sequenced(sequence, request_id);
                // A CloseSecureChannel has no answer.
                if chunk.starts_with(b"MSGF") {
                    self.requests += 1;
                }
            }
            _ => {}
        }
    }

    /// Whether the channel is plain (security policy None), as its OpenSecureChannel said.
    pub fn is_plain(&self) -> bool {
        self.plain == Some(true)
    }

    /// The numbers of a message the relay adds now; `None` on a secure channel, before the
    /// client's first message, or near the sequence numbers' wrap-around.
    pub fn next(&self) -> Option<Next> {
        let last = self.last_sequence.filter(|_| self.is_plain())?;
        (last < LAST_SEQUENCE).then(|| Next {
            token_id: self.token_id,
            sequence: last + 1,
            request_id: self.request_id.wrapping_add(1),
        })
    }

    /// Counts a message the relay added.
    pub fn sent(&mut self, next: Next) {
        self.sequenced(next.sequence, next.request_id);
        self.requests += 1;
    }

    /// Requests on the plain channel the server has not answered yet (by `server`'s count).
    pub fn unanswered(&self, server: &ServerSide) -> u64 {
        self.requests.saturating_sub(server.responses)
    }

    /// An OpenSecureChannel chunk: after the channel id, the asymmetric security header
    /// (policy URI, sender certificate, receiver thumbprint), then the sequence header.
    fn see_open(&mut self, chunk: &[u8]) {
        let mut at = 12;
        let mut field = || {
            let len = i32::from_le_bytes(chunk.get(at..at + 4)?.try_into().ok()?);
            let len = usize::try_from(len).unwrap_or(0);
            let bytes = chunk.get(at + 4..at + 4 + len)?;
            at += 4 + len;
            Some(bytes)
        };
        let Some(policy) = field() else {
            self.plain = Some(false);
            return;
        };
        let plain = policy == POLICY_NONE;
        if self.plain.is_none() {
            self.plain = Some(plain);
        }
        if !self.is_plain() || !plain {
            self.plain = Some(false);
            return;
        }
        let (Some(_), Some(_)) = (field(), field()) else {
            return;
        };
        if let (Some(sequence), Some(request_id)) = (u32_at(chunk, at), u32_at(chunk, at + 4)) {
            self.sequenced(sequence, request_id);
        }
    }

    fn sequenced(&mut self, sequence: u32, request_id: u32) {
        self.last_sequence = Some(sequence);
        self.request_id = self.request_id.max(request_id);
    }
}

/// Whether a server chunk on a plain channel starts a new message (the previous one
/// ended), for [`created_session`], which reads first chunks only.
#[derive(Debug, Clone, Default)]
pub struct ServerSide {
    mid_message: bool,
    /// Whole responses seen.
    responses: u64,
}

impl ServerSide {
    /// Takes one whole chunk the server sent on a plain channel; the authentication token
    /// of the session it created, when it is a good CreateSession response.
    pub fn see(&mut self, chunk: &[u8]) -> Option<NodeId> {
        if chunk.get(..3) != Some(b"MSG") {
            return None;
        }
        let first = !self.mid_message;
        self.mid_message = chunk.get(3) == Some(&b'C');
        if !self.mid_message {
            self.responses += 1;
        }
        if first {
            created_session(chunk.get(PLAIN_HEADER_LEN..)?)
        } else {
            None
        }
    }
}

/// The authentication token of a good CreateSession response's body (its first chunk is
/// enough: the token comes before the certificate and the endpoints).
pub fn created_session(body: &[u8]) -> Option<NodeId> {
    if body.get(..4)? != CREATE_SESSION_RESPONSE {
        return None;
    }
    let context = ContextOwned::default();
    let context = context.context();
    let mut read = Cursor::new(&body[4..]);
    let header = ResponseHeader::decode(&mut read, &context).ok()?;
    if !header.service_result.is_good() {
        return None;
    }
    let _session_id = NodeId::decode(&mut read, &context).ok()?;
    NodeId::decode(&mut read, &context).ok()
}

/// A plain `MSG` chunk on `channel` carrying a CloseSession request (subscriptions
/// deleted) for the session with authentication token `token`.
pub fn close_session(channel: u32, next: Next, token: &NodeId) -> Option<Vec<u8>> {
    let context = ContextOwned::default();
    let context = context.context();
    let request = CloseSessionRequest {
        request_header: RequestHeader::new(token, &DateTime::now(), next.request_id),
        delete_subscriptions: true,
    };
    let mut body = Vec::new();
    NodeId::from(ObjectId::CloseSessionRequest_Encoding_DefaultBinary)
        .encode(&mut body, &context)
        .ok()?;
    request.encode(&mut body, &context).ok()?;
    let size = u32::try_from(PLAIN_HEADER_LEN + body.len()).ok()?;
    let mut chunk = Vec::with_capacity(PLAIN_HEADER_LEN + body.len());
    chunk.extend_from_slice(b"MSGF");
    for n in [size, channel, next.token_id, next.sequence, next.request_id] {
        chunk.extend_from_slice(&n.to_le_bytes());
    }
    chunk.extend_from_slice(&body);
    Some(chunk)
}

fn u32_at(bytes: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(bytes.get(at..at + 4)?.try_into().ok()?))
}

/// Chunks as clients and servers send them, for the tests of the relay.
#[cfg(test)]
pub(crate) mod testing {
    use super::*;
    use ::opcua::types::{ByteString, CreateSessionResponse, StatusCode};

    /// The security policy URI of plain channels.
    pub(crate) const NONE: &[u8] = POLICY_NONE;

    pub(crate) fn chunk(kind: &[u8; 4], fields: &[u8]) -> Vec<u8> {
        let mut c = kind.to_vec();
        c.extend_from_slice(&((HEADER_LEN + fields.len()) as u32).to_le_bytes());
        c.extend_from_slice(fields);
        c
    }

    fn string(bytes: Option<&[u8]>) -> Vec<u8> {
        match bytes {
            None => (-1_i32).to_le_bytes().to_vec(),
            Some(b) => {
                let mut s = (b.len() as i32).to_le_bytes().to_vec();
                s.extend_from_slice(b);
                s
            }
        }
    }

    pub(crate) fn open(policy: &[u8], sequence: u32, request: u32) -> Vec<u8> {
        let mut fields = 0_u32.to_le_bytes().to_vec();
        fields.extend(string(Some(policy)));
        fields.extend(string(None));
        fields.extend(string(None));
        fields.extend_from_slice(&sequence.to_le_bytes());
        fields.extend_from_slice(&request.to_le_bytes());
        chunk(b"OPNF", &fields)
    }

    pub(crate) fn plain_msg(
        kind: &[u8; 4],
        token: u32,
        sequence: u32,
        request: u32,
        body: &[u8],
    ) -> Vec<u8> {
        let mut fields = Vec::new();
        for n in [7_u32, token, sequence, request] {
            fields.extend_from_slice(&n.to_le_bytes());
        }
        fields.extend_from_slice(body);
        chunk(kind, &fields)
    }

    pub(crate) fn create_session_response(status: StatusCode) -> (NodeId, Vec<u8>) {
        let token = token();
        let mut header = ResponseHeader::new_good(1);
        header.service_result = status;
        let response = CreateSessionResponse {
            response_header: header,
            session_id: NodeId::new(1, 5),
            authentication_token: token.clone(),
            ..Default::default()
        };
        let context = ContextOwned::default();
        let mut body = Vec::new();
        NodeId::from(ObjectId::CreateSessionResponse_Encoding_DefaultBinary)
            .encode(&mut body, &context.context())
            .unwrap();
        response.encode(&mut body, &context.context()).unwrap();
        (token, body)
    }

    /// The authentication token [`create_session_response`] carries.
    pub(crate) fn token() -> NodeId {
        NodeId::new(0, ByteString::from(vec![9_u8; 32]))
    }
}

#[cfg(test)]
mod tests {
    use super::testing::*;
    use super::*;
    use ::opcua::types::{ByteString, StatusCode};

    #[test]
    fn the_framer_gives_whole_chunks_however_the_bytes_are_split() {
        let stream: Vec<u8> = [chunk(b"HELF", &[1; 20]), chunk(b"MSGF", &[2; 30])].concat();
        for split in 0..stream.len() {
            let mut framer = Framer::default();
            let mut chunks = Vec::new();
            for part in [&stream[..split], &stream[split..]] {
                framer.push(part);
                while let Some(c) = framer.next_chunk().unwrap() {
                    chunks.push(c);
                }
            }
            assert_eq!(chunks.concat(), stream, "{split}");
            assert_eq!(chunks.len(), 2, "{split}");
        }
    }

    #[test]
    fn the_framer_gives_many_chunks_pushed_piece_by_piece_in_order() {
        let chunks: Vec<Vec<u8>> = (0..50_u8)
            .map(|n| chunk(b"MSGF", &vec![n; usize::from(n)]))
            .collect();
        let stream = chunks.concat();
        let mut framer = Framer::default();
        let mut got = Vec::new();
        for piece in stream.chunks(7) {
            framer.push(piece);
            while let Some(c) = framer.next_chunk().unwrap() {
                got.push(c);
            }
        }
        assert_eq!(got, chunks);
    }

    #[test]
    fn the_framer_refuses_sizes_below_a_header_or_above_the_cap() {
        let mut framer = Framer::default();
        framer.push(b"MSGF\x07\0\0\0");
        assert_eq!(framer.next_chunk(), Err(BadChunk { size: 7 }));
        let mut framer = Framer::default();
        framer.push(b"MSGF\0\0\x20\0");
        assert_eq!(framer.next_chunk(), Err(BadChunk { size: 0x20_0000 }));
    }

    #[test]
    fn the_next_message_follows_the_clients_sequence_on_a_plain_channel_only() {
        let mut client = ClientSide::default();
        assert_eq!(client.next(), None);
        client.see(&open(POLICY_NONE, 1, 1));
        assert!(client.is_plain());
        client.see(&plain_msg(b"MSGF", 3, 2, 2, &[0; 10]));
        client.see(&plain_msg(b"MSGF", 3, 3, 5, &[0; 10]));
        let next = client.next().unwrap();
        assert_eq!(
            next,
            Next {
                token_id: 3,
                sequence: 4,
                request_id: 6
            }
        );
        client.sent(next);
        assert_eq!(client.next().map(|n| n.sequence), Some(5));
        // Three requests (the OpenSecureChannel is not one), the server answered one.
        let mut server = ServerSide::default();
        server.see(&plain_msg(b"MSGF", 3, 1, 2, &[0; 10]));
        assert_eq!(client.unanswered(&server), 2);

        let mut secure = ClientSide::default();
        secure.see(&open(
            b"http://opcfoundation.org/UA/SecurityPolicy#Basic256Sha256",
            1,
            1,
        ));
        secure.see(&plain_msg(b"MSGF", 3, 2, 2, &[0; 10]));
        assert!(!secure.is_plain());
        assert_eq!(secure.next(), None);
    }

    #[test]
    fn a_good_create_session_response_gives_its_token_and_a_bad_one_nothing() {
        let (token, body) = create_session_response(StatusCode::Good);
        let mut server = ServerSide::default();
        assert_eq!(server.see(&plain_msg(b"MSGF", 1, 1, 1, &body)), Some(token));
        let (_, bad) = create_session_response(StatusCode::BadTooManySessions);
        assert_eq!(server.see(&plain_msg(b"MSGF", 1, 2, 2, &bad)), None);
        // The second chunk of a message is not read as the start of one.
        let (_, body) = create_session_response(StatusCode::Good);
        assert_eq!(server.see(&plain_msg(b"MSGC", 1, 3, 3, &[0; 8])), None);
        assert_eq!(server.see(&plain_msg(b"MSGF", 1, 4, 3, &body)), None);
    }

    #[test]
    fn the_close_session_chunk_decodes_as_the_servers_would() {
        let token = NodeId::new(0, ByteString::from(vec![4_u8; 32]));
        let next = Next {
            token_id: 2,
            sequence: 9,
            request_id: 11,
        };
        let chunk = close_session(7, next, &token).unwrap();
        assert_eq!(&chunk[..4], b"MSGF");
        assert_eq!(u32_at(&chunk, 4), Some(chunk.len() as u32));
        assert_eq!(
            [8, 12, 16, 20].map(|at| u32_at(&chunk, at)),
            [Some(7), Some(2), Some(9), Some(11)]
        );
        let context = ContextOwned::default();
        let mut read = Cursor::new(&chunk[PLAIN_HEADER_LEN..]);
        let kind = NodeId::decode(&mut read, &context.context()).unwrap();
        assert_eq!(kind, ObjectId::CloseSessionRequest_Encoding_DefaultBinary);
        let request = CloseSessionRequest::decode(&mut read, &context.context()).unwrap();
        assert_eq!(request.request_header.authentication_token, token);
        assert!(request.delete_subscriptions);
    }

    #[test]
    fn random_bytes_never_panic() {
        let mut rng = fastrand::Rng::with_seed(43);
        for _ in 0..2_000 {
            let len = rng.usize(0..80);
            let bytes: Vec<u8> = (0..len).map(|_| rng.u8(..)).collect();
            let mut client = ClientSide::default();
            let mut server = ServerSide::default();
            for kind in [b"OPNF", b"MSGF", b"MSGC"] {
                let c = chunk(kind, &bytes);
                client.see(&c);
                server.see(&c);
                let _ = created_session(&bytes);
            }
            let mut framer = Framer::default();
            framer.push(&bytes);
            while let Ok(Some(_)) = framer.next_chunk() {}
        }
    }
}
