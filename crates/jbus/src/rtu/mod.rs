//! Generic Modbus RTU (JBUS), without I/O: what any Modbus device on the plant's lines
//! speaks, the CROSS included.
//!
//! - [`value`]: unit numbers, counts, function and exception codes, each valid by
//!   construction.
//! - [`request`] and [`response`]: typed messages, one variant per function (1, 2, 3, 4,
//!   5, 6, 15, 16), plus the wire form of a request that a server checks itself.
//! - [`codec`]: the frames, both directions, CRC-16/MODBUS low byte first.
//! - [`exchange`]: whether a response answers the request in flight.
//! - [`timing`]: character time and inter-frame silence at a line's speed and format.
//!
//! A client's round: build an [`Addressed`] request, send `addressed.to_adu().to_bytes()`
//! after the line's [`LineTiming::inter_frame_silence`], feed what comes back to a
//! `wire::Deframer<ResponseCodec>`, and accept the first frame for which
//! [`check_response`] says `Ok`. A [`Broadcast`] is sent the same way and answered by
//! nobody. A server decodes with [`RequestCodec`], ignores frames for other units, and
//! checks the request with [`RequestPdu::to_request`].

pub mod codec;
pub mod exchange;
pub mod request;
pub mod response;
pub mod timing;
pub mod value;

pub use codec::{
    DecodeError, MAX_ADU, Malformed, RequestCodec, ResponseCodec, SniffCodec, Sniffed, find_frame,
};
pub use exchange::{Answer, EchoField, Mismatch, check_response};
pub use request::{
    Addressed, Broadcast, ByteField, COIL_OFF, COIL_ON, OtherFunction, ReadBits, ReadRegisters,
    Request, RequestAdu, RequestPdu, Write, WriteCoil, WriteCoils, WriteRegister, WriteRegisters,
    pack_bits, packed_len, unpack_bits,
};
pub use response::{PackedBits, RegisterValues, Response, ResponseAdu};
pub use timing::{LineTiming, char_time, inter_frame_silence};
pub use value::{
    ADDRESS_SPACE, BROADCAST_UNIT, EXCEPTION_BIT, Exception, ExceptionCode, FunctionCode,
    InvalidValue, ReadBitCount, ReadRegisterCount, UnitId, UnitProblem, WriteBitCount,
    WriteRegisterCount, check_unit,
};
