//! Modbus TCP, without I/O: the same requests and responses as [`crate::rtu`], each behind
//! an MBAP header instead of a CRC.
//!
//! ```text
//! transaction id (2) | protocol id = 0 (2) | length (2) | unit id (1) | function, data…
//! ```
//!
//! - [`codec`]: the frames, both directions ([`RequestCodec`], [`ResponseCodec`]). The
//!   length field says where a frame ends; it must agree with what the function code and
//!   its counts imply. A header with a protocol id other than 0 or an impossible length
//!   is not a header: one byte is dropped and the scan goes on.
//! - [`server`]: [`MbapServer`] serves any RTU device model over Modbus TCP, as a serial
//!   gateway (a Moxa MGate, an Anybus) does: it answers every unit its model answers and
//!   echoes each request's transaction id.
//!
//! A client's round: give each request a new transaction id ([`TransactionId::next`],
//! wrapping), send `Mbap { transaction, adu: addressed.to_adu() }.to_bytes()`, and accept
//! the first response with the same transaction id and unit for which
//! [`check_response`](crate::rtu::check_response) says `Ok`; responses to other
//! transactions are late answers to earlier requests and are dropped. Several units share
//! one connection: the unit id travels in each frame.

pub mod codec;
pub mod server;

pub use codec::{
    DecodeError, FrameProblem, HEADER_LEN, MAX_LENGTH, MIN_LENGTH, PROTOCOL_ID, RequestCodec,
    ResponseCodec,
};
pub use server::MbapServer;

use crate::rtu::{RequestAdu, ResponseAdu};

/// A Modbus TCP transaction identifier: pairs a response with its request.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TransactionId(pub u16);

impl TransactionId {
    /// The id after this one (65535 is followed by 0).
    pub const fn next(self) -> Self {
        Self(self.0.wrapping_add(1))
    }
}

impl std::fmt::Display for TransactionId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.0)
    }
}

/// A Modbus message (a [`RequestAdu`] or a [`ResponseAdu`], whose unit is the MBAP unit
/// id) with its transaction id: one Modbus TCP frame. The protocol id (0) and the length
/// are not stored: encoding writes them from the message.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Mbap<A> {
    /// The transaction the frame belongs to.
    pub transaction: TransactionId,
    /// The unit and the PDU.
    pub adu: A,
}

/// A request as Modbus TCP carries it.
pub type TcpRequest = Mbap<RequestAdu>;

/// A response as Modbus TCP carries it.
pub type TcpResponse = Mbap<ResponseAdu>;

impl Mbap<RequestAdu> {
    /// The frame's bytes, MBAP header included.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(HEADER_LEN + 8);
        codec::encode_request(self, &mut out);
        out
    }
}

impl Mbap<ResponseAdu> {
    /// The frame's bytes, MBAP header included.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(HEADER_LEN + 8);
        codec::encode_response(self, &mut out);
        out
    }
}
