//! The Modbus TCP frame layer: an MBAP header (transaction id, protocol id 0, length, unit
//! id) before the function code and data; no CRC.
//!
//! Unlike RTU, a frame carries its length. The decoders still check it against what the
//! function code and its counts imply, so a frame that does not add up is refused whole
//! (its length says where the next one starts). A header whose protocol id is not 0 or
//! whose length is impossible (under 2 or over 254: a unit id and a 253-byte PDU at most)
//! is not a header at all: the decoders drop one byte and look again, as after noise.
//!
//! Requests of a function outside the eight framed here are kept whole
//! ([`RequestPdu::Other`]) so a server can refuse them with exception 1.

use wire::{Codec, Resync};

use super::{Mbap, TransactionId};
use crate::rtu::codec::{encode_request_body, encode_response_body, parse_request, parse_response};
use crate::rtu::request::OtherFunction;
use crate::rtu::{EXCEPTION_BIT, Malformed, RequestAdu, ResponseAdu};

/// The MBAP header's length, the unit id included: transaction id, protocol id, length
/// (2 bytes each) and the unit id.
pub const HEADER_LEN: usize = 7;

/// The length field counts from the unit id on; this many bytes come before it.
const BEFORE_UNIT: usize = 6;

/// The only protocol id: Modbus.
pub const PROTOCOL_ID: u16 = 0;

/// The smallest length field: a unit id and a function code.
pub const MIN_LENGTH: u16 = 2;

/// The largest length field: a unit id and the longest PDU (253 bytes).
pub const MAX_LENGTH: u16 = 254;

/// Why the front of the buffer is not a Modbus TCP frame.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum DecodeError {
    /// The protocol id is not 0: not an MBAP header (or the stream is out of step).
    #[error(
        "no MBAP header here: protocol id {protocol} after transaction id {transaction} is not 0 (Modbus)"
    )]
    Protocol {
        /// The transaction id bytes, as read.
        transaction: u16,
        /// The protocol id found.
        protocol: u16,
    },
    /// The length field cannot be a Modbus frame's.
    #[error(
        "no MBAP header here: length {length} after transaction id {transaction} is not from {MIN_LENGTH} to {MAX_LENGTH}"
    )]
    Length {
        /// The transaction id bytes, as read.
        transaction: u16,
        /// The length found.
        length: u16,
    },
    /// A frame with a sound header whose content is not Modbus this side can take.
    #[error(
        "{len}-byte Modbus TCP frame (transaction {transaction}, unit {unit}, function {function}) {problem}"
    )]
    Frame {
        /// The transaction id.
        transaction: u16,
        /// The unit id.
        unit: u8,
        /// The function byte.
        function: u8,
        /// The whole frame's length, header included (dropped whole).
        len: usize,
        /// What is wrong.
        problem: FrameProblem,
    },
}

/// What is wrong inside a Modbus TCP frame whose header is sound.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum FrameProblem {
    /// The function byte is not one this side can take (a response of an unknown function,
    /// a request with the exception bit set).
    #[error("has a function this side cannot take")]
    UnknownFunction,
    /// The length field disagrees with the function code and its counts.
    #[error("carries {actual} PDU bytes, but its function and counts make {expected}")]
    Length {
        /// PDU bytes the function and counts imply.
        expected: usize,
        /// PDU bytes the length field gives.
        actual: usize,
    },
    /// The content is not valid Modbus.
    #[error("is not valid Modbus: {0}")]
    Malformed(Malformed),
}

impl Resync for DecodeError {
    fn drop_len(&self) -> usize {
        match self {
            Self::Protocol { .. } | Self::Length { .. } => 1,
            Self::Frame { len, .. } => (*len).max(1),
        }
    }
}

/// Decodes requests (what a server receives) and encodes them (what a client sends).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RequestCodec;

/// Decodes responses (what a client receives) and encodes them (what a server sends).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ResponseCodec;

impl Codec for RequestCodec {
    type Frame = Mbap<RequestAdu>;
    type Error = DecodeError;

    fn decode(&self, buf: &[u8]) -> Result<Option<(Self::Frame, usize)>, DecodeError> {
        decode_request(buf)
    }

    fn encode(&self, frame: &Self::Frame, out: &mut Vec<u8>) {
        encode_request(frame, out);
    }
}

impl Codec for ResponseCodec {
    type Frame = Mbap<ResponseAdu>;
    type Error = DecodeError;

    fn decode(&self, buf: &[u8]) -> Result<Option<(Self::Frame, usize)>, DecodeError> {
        decode_response(buf)
    }

    fn encode(&self, frame: &Self::Frame, out: &mut Vec<u8>) {
        encode_response(frame, out);
    }
}

/// A frame whose header is sound: its transaction id, its body (unit id, function, data)
/// and its whole length.
struct Framed<'a> {
    transaction: u16,
    body: &'a [u8],
    len: usize,
}

impl Framed<'_> {
    fn error(&self, problem: FrameProblem) -> DecodeError {
        DecodeError::Frame {
            transaction: self.transaction,
            unit: self.body.first().copied().unwrap_or(0),
            function: self.body.get(1).copied().unwrap_or(0),
            len: self.len,
            problem,
        }
    }

    /// Checks that the body has the length `expected` (unit id included) implies.
    fn expect_body(&self, expected: usize) -> Result<(), DecodeError> {
        if self.body.len() == expected {
            Ok(())
        } else {
            Err(self.error(FrameProblem::Length {
                expected: expected.saturating_sub(1),
                actual: self.body.len().saturating_sub(1),
            }))
        }
    }
}

/// The header at the front of `buf`, and the frame once all of it is there.
fn frame(buf: &[u8]) -> Result<Option<Framed<'_>>, DecodeError> {
    let word =
        |at: usize| -> Option<u16> { Some(u16::from_be_bytes([*buf.get(at)?, *buf.get(at + 1)?])) };
    let (Some(transaction), Some(protocol)) = (word(0), word(2)) else {
        return Ok(None);
    };
    if protocol != PROTOCOL_ID {
        return Err(DecodeError::Protocol {
            transaction,
            protocol,
        });
    }
    let Some(length) = word(4) else {
        return Ok(None);
    };
    if !(MIN_LENGTH..=MAX_LENGTH).contains(&length) {
        return Err(DecodeError::Length {
            transaction,
            length,
        });
    }
    let len = BEFORE_UNIT + usize::from(length);
    Ok(buf.get(BEFORE_UNIT..len).map(|body| Framed {
        transaction,
        body,
        len,
    }))
}

/// Decodes one request from the front of `buf` (see [`RequestCodec`]).
pub fn decode_request(buf: &[u8]) -> Result<Option<(Mbap<RequestAdu>, usize)>, DecodeError> {
    let Some(framed) = frame(buf)? else {
        return Ok(None);
    };
    let body = framed.body;
    let (unit, function) = (body.first().copied(), body.get(1).copied());
    let (Some(unit), Some(function)) = (unit, function) else {
        // The length field is at least 2: cannot happen.
        return Err(framed.error(FrameProblem::Length {
            expected: 1,
            actual: body.len().saturating_sub(1),
        }));
    };
    match function {
        1..=6 => framed.expect_body(6)?,
        15 | 16 => framed.expect_body(7 + body.get(6).map_or(0, |&n| usize::from(n)))?,
        f if f & EXCEPTION_BIT != 0 => return Err(framed.error(FrameProblem::UnknownFunction)),
        // Another function: the length field is all there is to go by.
        _ => {}
    }
    let pdu = parse_request(body).ok_or_else(|| {
        framed.error(FrameProblem::Malformed(Malformed::TooLong {
            len: body.len().saturating_sub(2),
            max: OtherFunction::MAX_DATA,
        }))
    })?;
    Ok(Some((
        Mbap {
            transaction: TransactionId(framed.transaction),
            adu: RequestAdu { unit, pdu },
        },
        framed.len,
    )))
}

/// Decodes one response from the front of `buf` (see [`ResponseCodec`]).
pub fn decode_response(buf: &[u8]) -> Result<Option<(Mbap<ResponseAdu>, usize)>, DecodeError> {
    let Some(framed) = frame(buf)? else {
        return Ok(None);
    };
    let body = framed.body;
    let (Some(&unit), Some(&function)) = (body.first(), body.get(1)) else {
        return Err(framed.error(FrameProblem::Length {
            expected: 1,
            actual: body.len().saturating_sub(1),
        }));
    };
    match function {
        f if f & EXCEPTION_BIT != 0 => framed.expect_body(3)?,
        1..=4 => framed.expect_body(3 + body.get(2).map_or(0, |&n| usize::from(n)))?,
        5 | 6 | 15 | 16 => framed.expect_body(6)?,
        _ => return Err(framed.error(FrameProblem::UnknownFunction)),
    }
    let response =
        parse_response(body).map_err(|problem| framed.error(FrameProblem::Malformed(problem)))?;
    Ok(Some((
        Mbap {
            transaction: TransactionId(framed.transaction),
            adu: ResponseAdu { unit, response },
        },
        framed.len,
    )))
}

/// Appends a request frame to `out`.
pub fn encode_request(frame: &Mbap<RequestAdu>, out: &mut Vec<u8>) {
    encode_with_header(frame.transaction, out, |out| {
        encode_request_body(&frame.adu, out);
    });
}

/// Appends a response frame to `out`.
pub fn encode_response(frame: &Mbap<ResponseAdu>, out: &mut Vec<u8>) {
    encode_with_header(frame.transaction, out, |out| {
        encode_response_body(&frame.adu, out);
    });
}

/// Writes the header, then the body `body` appends, then the body's length into the header.
fn encode_with_header(
    transaction: TransactionId,
    out: &mut Vec<u8>,
    body: impl FnOnce(&mut Vec<u8>),
) {
    let start = out.len();
    out.extend_from_slice(&transaction.0.to_be_bytes());
    out.extend_from_slice(&PROTOCOL_ID.to_be_bytes());
    out.extend_from_slice(&[0, 0]);
    body(out);
    let length = out.len() - start - BEFORE_UNIT;
    // Frames of the eight functions are at most 254 bytes long; only an `Other` request
    // could be longer, and a length that does not fit is written as the most it can say.
    let length = u16::try_from(length).unwrap_or(u16::MAX).to_be_bytes();
    if let Some(field) = out.get_mut(start + 4..start + BEFORE_UNIT) {
        field.copy_from_slice(&length);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rtu::{
        Addressed, ExceptionCode, FunctionCode, RegisterValues, Request, Response, UnitId,
    };

    use crate::test_util::{good_frames, hex};

    fn one_request(bytes: &[u8]) -> Mbap<RequestAdu> {
        match decode_request(bytes) {
            Ok(Some((frame, len))) if len == bytes.len() => frame,
            other => panic!("expected one whole request in {bytes:02X?}, got {other:?}"),
        }
    }

    fn one_response(bytes: &[u8]) -> Mbap<ResponseAdu> {
        match decode_response(bytes) {
            Ok(Some((frame, len))) if len == bytes.len() => frame,
            other => panic!("expected one whole response in {bytes:02X?}, got {other:?}"),
        }
    }

    fn unit(n: u8) -> UnitId {
        UnitId::new(n).expect("test unit")
    }

    // --- The Modbus application protocol specification's examples, in an MBAP header ---

    #[test]
    fn spec_example_read_holding_registers_108_to_110_frames_as_the_guide_shows() {
        // Request PDU 03 006B 0003 (registers 108-110), transaction 0x0001, unit 0x11.
        let request = Mbap {
            transaction: TransactionId(1),
            adu: Addressed::new(
                unit(0x11),
                Request::read_holding_registers(0x6B, 3).expect("3"),
            )
            .to_adu(),
        };
        let bytes = hex("00 01 00 00 00 06 11 03 00 6B 00 03");
        assert_eq!(request.to_bytes(), bytes);
        assert_eq!(one_request(&bytes), request);
        // Response PDU 03 06 022B 0000 0064: 555, 0, 100.
        let response = Mbap {
            transaction: TransactionId(1),
            adu: ResponseAdu {
                unit: 0x11,
                response: Response::ReadHoldingRegisters(
                    RegisterValues::new(vec![555, 0, 100]).expect("3 values"),
                ),
            },
        };
        let bytes = hex("00 01 00 00 00 09 11 03 06 02 2B 00 00 00 64");
        assert_eq!(response.to_bytes(), bytes);
        assert_eq!(one_response(&bytes), response);
    }

    #[test]
    fn spec_example_write_multiple_registers_and_its_answer() {
        // Request PDU 10 0001 0002 04 000A 0102; response PDU 10 0001 0002.
        let request = Mbap {
            transaction: TransactionId(0x1501),
            adu: Addressed::new(
                UnitId::jbus(0xFF).expect("255 on JBUS"),
                Request::write_multiple_registers(1, vec![0x000A, 0x0102]).expect("2"),
            )
            .to_adu(),
        };
        let bytes = hex("15 01 00 00 00 0B FF 10 00 01 00 02 04 00 0A 01 02");
        assert_eq!(request.to_bytes(), bytes);
        assert_eq!(one_request(&bytes), request);
        let answer = one_response(&hex("15 01 00 00 00 06 FF 10 00 01 00 02"));
        assert_eq!(answer.transaction, TransactionId(0x1501));
        assert_eq!(
            answer.adu.response,
            Response::WriteMultipleRegisters {
                address: 1,
                count: 2
            }
        );
    }

    #[test]
    fn an_exception_frames_in_three_pdu_bytes() {
        let bytes = hex("00 07 00 00 00 03 01 83 02");
        let answer = one_response(&bytes);
        assert_eq!(
            answer.adu.response,
            Response::exception(
                FunctionCode::READ_HOLDING_REGISTERS,
                ExceptionCode::ILLEGAL_DATA_ADDRESS
            )
        );
        assert_eq!(answer.to_bytes(), bytes);
    }

    #[test]
    fn a_request_of_another_function_is_kept_whole_by_its_length() {
        // Function 43 / 14 (read device identification), which RTU could only guess at.
        let bytes = hex("00 02 00 00 00 05 01 2B 0E 01 00");
        let request = one_request(&bytes);
        assert_eq!(
            request.adu.pdu,
            crate::rtu::RequestPdu::Other(
                OtherFunction::new(0x2B, vec![0x0E, 0x01, 0x00]).expect("43 is not framed")
            )
        );
        assert_eq!(request.to_bytes(), bytes);
    }

    // --- Framing behaviour ---

    #[test]
    fn decoders_wait_for_every_byte_of_a_frame() {
        let bytes = hex("00 01 00 00 00 09 11 03 06 02 2B 00 00 00 64");
        for cut in 0..bytes.len() {
            assert_eq!(decode_response(&bytes[..cut]), Ok(None), "cut at {cut}");
        }
        let bytes = hex("00 01 00 00 00 06 11 03 00 6B 00 03");
        for cut in 0..bytes.len() {
            assert_eq!(decode_request(&bytes[..cut]), Ok(None), "cut at {cut}");
        }
    }

    #[test]
    fn a_protocol_id_other_than_0_drops_one_byte() {
        let err = decode_request(&hex("00 01 00 01 00 06 11 03 00 6B 00 03")).expect_err("not 0");
        assert_eq!(
            err,
            DecodeError::Protocol {
                transaction: 1,
                protocol: 1
            }
        );
        assert_eq!(err.drop_len(), 1);
    }

    #[test]
    fn an_absurd_length_drops_one_byte_before_the_body_arrives() {
        for length in [0u16, 1, 255, 0xFFFF] {
            let [hi, lo] = length.to_be_bytes();
            let err = decode_response(&[0, 1, 0, 0, hi, lo]).expect_err("impossible length");
            assert_eq!(
                err,
                DecodeError::Length {
                    transaction: 1,
                    length
                }
            );
            assert_eq!(err.drop_len(), 1);
            assert!(err.to_string().contains("from 2 to 254"), "{err}");
        }
    }

    #[test]
    fn a_length_that_disagrees_with_the_counts_drops_the_whole_frame() {
        // A read answer announcing 6 bytes of registers in a frame that carries 4.
        let bytes = hex("00 01 00 00 00 07 11 03 06 02 2B 00 00");
        let err = decode_response(&bytes).expect_err("disagrees");
        assert_eq!(
            err,
            DecodeError::Frame {
                transaction: 1,
                unit: 0x11,
                function: 3,
                len: 13,
                problem: FrameProblem::Length {
                    expected: 8,
                    actual: 6
                }
            }
        );
        assert_eq!(err.drop_len(), bytes.len());
    }

    #[test]
    fn a_response_of_an_unknown_function_is_dropped_whole() {
        let err = decode_response(&hex("00 01 00 00 00 03 01 07 00")).expect_err("unknown");
        assert!(
            matches!(
                err,
                DecodeError::Frame {
                    problem: FrameProblem::UnknownFunction,
                    len: 9,
                    ..
                }
            ),
            "{err}"
        );
    }

    #[test]
    fn an_exception_code_0_is_malformed() {
        let err = decode_response(&hex("00 01 00 00 00 03 01 83 00")).expect_err("code 0");
        assert!(matches!(
            err,
            DecodeError::Frame {
                problem: FrameProblem::Malformed(Malformed::ExceptionCodeZero),
                ..
            }
        ));
    }

    #[test]
    fn the_deframer_resyncs_after_garbage_and_a_bad_header() {
        let good = hex("00 05 00 00 00 06 01 03 00 00 00 0A");
        let mut stream = hex("FF 00 13 00 09 00 07 00 06");
        stream.extend_from_slice(&good);
        assert_eq!(good_frames(RequestCodec, &stream), vec![one_request(&good)]);
    }

    #[test]
    fn transaction_ids_wrap_after_65535() {
        assert_eq!(TransactionId(65535).next(), TransactionId(0));
        assert_eq!(TransactionId(7).next(), TransactionId(8));
    }
}
