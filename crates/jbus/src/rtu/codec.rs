//! The RTU frame layer: `unit function data… CRC`, CRC-16/MODBUS low byte first.
//!
//! RTU frames carry no length: a frame's length follows from its function code and, for
//! variable frames, its byte count, so the decoders know when a frame is complete without
//! timing. A frame whose CRC does not match loses its first byte and the scan goes on from
//! the next one, which finds the next frame after any damage.
//!
//! Two codecs, one per direction, because the same function code frames differently:
//! [`RequestCodec`] decodes what a server receives, [`ResponseCodec`] what a client
//! receives. Both encode too.
//!
//! A request with a function outside the eight framed here (JBUS 7, 8, 11–14, 17, 20–24,
//! 43, …) must still be answered with exception 1 when its CRC is good. Functions the
//! Modbus standard gives a fixed or byte-counted request layout are framed by it; for
//! others the request decoder takes the shortest run of 4 to 8 bytes that ends in a valid
//! CRC ([`OTHER_FUNCTION_SCAN`]), which finds the usual short frames (the JBUS manual's
//! own example is `01 09 00 00 00 00 CRC`) and gives up after 8 bytes. A function byte with
//! the exception bit (0x80) set is never a request.

use wire::checksum::CRC16_MODBUS;
use wire::{Codec, Resync};

use super::request::{ByteField, OtherFunction, RequestAdu, RequestPdu};
use super::response::{PackedBits, RegisterValues, Response, ResponseAdu};
use super::value::{EXCEPTION_BIT, Exception, ExceptionCode, FunctionCode};

/// The longest RTU frame the Modbus standard allows (a server's answer to 125 registers
/// is 255 bytes). The decoders accept frames up to the length a byte count can express.
pub const MAX_ADU: usize = 256;

/// The shortest frame: unit, function and the two CRC bytes.
pub const MIN_ADU: usize = 4;

/// Length of a CRC.
pub const CRC_LEN: usize = 2;

/// The longest request of an unknown layout the request decoder looks for by its CRC.
pub const OTHER_FUNCTION_SCAN: usize = 8;

/// Why the front of the buffer is not a frame.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum DecodeError {
    /// The CRC received is not the CRC of the bytes: a damaged frame, or not a frame.
    #[error(
        "CRC mismatch in a {len}-byte frame for unit {unit}, function {function}: the bytes give 0x{expected:04X}, the frame carries 0x{actual:04X}"
    )]
    Crc {
        /// The unit byte.
        unit: u8,
        /// The function byte.
        function: u8,
        /// The frame length the function code implies.
        len: usize,
        /// The CRC of the frame's bytes.
        expected: u16,
        /// The CRC the frame carries.
        actual: u16,
    },
    /// The function byte is not one whose frame length this side knows.
    #[error(
        "no frame starts here: function byte {function} (0x{function:02X}) after unit {unit} is not one this side can frame"
    )]
    UnknownFunction {
        /// The unit byte.
        unit: u8,
        /// The function byte.
        function: u8,
    },
    /// The CRC is good but the content is not valid Modbus.
    #[error("{len}-byte frame for unit {unit}, function {function} has a good CRC but {problem}")]
    Malformed {
        /// The unit byte.
        unit: u8,
        /// The function byte.
        function: u8,
        /// The frame's length (dropped whole: its CRC shows where it ends).
        len: usize,
        /// What is wrong.
        problem: Malformed,
    },
}

/// What is wrong in a frame with a good CRC.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum Malformed {
    /// A read response's byte count is not one a read can produce.
    #[error("its byte count {byte_count} is not valid for {what} (allowed: {allowed})")]
    ByteCount {
        /// The byte count received.
        byte_count: u8,
        /// What the bytes hold.
        what: &'static str,
        /// The valid byte counts.
        allowed: &'static str,
    },
    /// A write-coil echo with a value other than on (0xFF00) or off (0x0000).
    #[error("its coil value 0x{value:04X} is neither on (0xFF00) nor off (0x0000)")]
    CoilValue {
        /// The value received.
        value: u16,
    },
    /// An exception response with code 0, which does not exist.
    #[error("its exception code is 0, which does not exist")]
    ExceptionCodeZero,
    /// The data is longer than any request of this function can be.
    #[error("it holds {len} data bytes, more than {max}")]
    TooLong {
        /// Data bytes received.
        len: usize,
        /// The most allowed.
        max: usize,
    },
}

impl Resync for DecodeError {
    fn drop_len(&self) -> usize {
        match self {
            Self::Crc { .. } | Self::UnknownFunction { .. } => 1,
            Self::Malformed { len, .. } => (*len).max(1),
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
    type Frame = RequestAdu;
    type Error = DecodeError;

    fn decode(&self, buf: &[u8]) -> Result<Option<(RequestAdu, usize)>, DecodeError> {
        decode_request(buf)
    }

    fn encode(&self, frame: &RequestAdu, out: &mut Vec<u8>) {
        encode_request(frame, out);
    }
}

impl Codec for ResponseCodec {
    type Frame = ResponseAdu;
    type Error = DecodeError;

    fn decode(&self, buf: &[u8]) -> Result<Option<(ResponseAdu, usize)>, DecodeError> {
        decode_response(buf)
    }

    fn encode(&self, frame: &ResponseAdu, out: &mut Vec<u8>) {
        encode_response(frame, out);
    }
}

impl RequestAdu {
    /// The frame's bytes, CRC included.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(MIN_ADU + 8);
        encode_request(self, &mut out);
        out
    }
}

impl ResponseAdu {
    /// The frame's bytes, CRC included.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(MIN_ADU + 8);
        encode_response(self, &mut out);
        out
    }
}

/// A frame of a capture in which requests and responses alternate.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Sniffed {
    /// A request (only a request's layout gives a good CRC).
    Request(RequestAdu),
    /// A response (only a response's layout gives a good CRC).
    Response(ResponseAdu),
    /// Bytes that are both: a write of one coil or register and its echo are the same
    /// bytes, so only the order in the capture tells them apart.
    Either {
        /// The bytes read as a request.
        request: RequestAdu,
        /// The bytes read as a response.
        response: ResponseAdu,
    },
}

/// Decodes a capture of both directions (for annotated dumps): each frame is taken as a
/// request or a response, whichever layout ends in a good CRC. Encodes requests and
/// responses as their own codecs do (`Either` as the request).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SniffCodec;

impl Codec for SniffCodec {
    type Frame = Sniffed;
    type Error = DecodeError;

    fn decode(&self, buf: &[u8]) -> Result<Option<(Sniffed, usize)>, DecodeError> {
        match (decode_request(buf), decode_response(buf)) {
            (Ok(Some((request, a))), Ok(Some((response, b)))) => Ok(Some(match a.cmp(&b) {
                std::cmp::Ordering::Equal => (Sniffed::Either { request, response }, a),
                std::cmp::Ordering::Less => (Sniffed::Request(request), a),
                std::cmp::Ordering::Greater => (Sniffed::Response(response), b),
            })),
            (Ok(Some((request, len))), _) => Ok(Some((Sniffed::Request(request), len))),
            (_, Ok(Some((response, len)))) => Ok(Some((Sniffed::Response(response), len))),
            (Ok(None), _) | (_, Ok(None)) => Ok(None),
            // The error that drops fewer bytes; on a tie, a bad CRC (the bytes frame as a
            // damaged frame of that side) over a function the other side cannot frame.
            (Err(request), Err(response)) => {
                Err(match response.drop_len().cmp(&request.drop_len()) {
                    std::cmp::Ordering::Less => response,
                    std::cmp::Ordering::Equal
                        if matches!(response, DecodeError::Crc { .. })
                            && !matches!(request, DecodeError::Crc { .. }) =>
                    {
                        response
                    }
                    _ => request,
                })
            }
        }
    }

    fn encode(&self, frame: &Sniffed, out: &mut Vec<u8>) {
        match frame {
            Sniffed::Request(request) | Sniffed::Either { request, .. } => {
                encode_request(request, out)
            }
            Sniffed::Response(response) => encode_response(response, out),
        }
    }
}

/// Decodes one request from the front of `buf` (see [`RequestCodec`]).
pub fn decode_request(buf: &[u8]) -> Result<Option<(RequestAdu, usize)>, DecodeError> {
    let &[unit, function, ..] = buf else {
        return Ok(None);
    };
    let byte_at = |at: usize| buf.get(at).map(|&n| usize::from(n));
    let len = match function {
        1..=6 => 8,
        15 | 16 => match byte_at(6) {
            Some(n) => 9 + n,
            None => return Ok(None),
        },
        // The Modbus standard's layouts of functions this crate does not serve.
        7 | 11 | 12 | 17 => 4,
        8 => 8,
        20 | 21 => match byte_at(2) {
            Some(n) => 5 + n,
            None => return Ok(None),
        },
        22 => 10,
        23 => match byte_at(10) {
            Some(n) => 13 + n,
            None => return Ok(None),
        },
        24 => 6,
        // The exception bit marks responses: no request has it.
        f if f & EXCEPTION_BIT != 0 => return Err(DecodeError::UnknownFunction { unit, function }),
        _ => return scan_other_function(buf, unit, function),
    };
    let Some(frame) = buf.get(..len) else {
        return Ok(None);
    };
    let body = check_crc(frame)?;
    let pdu = parse_request(body).ok_or_else(|| malformed_too_long(body, len))?;
    Ok(Some((RequestAdu { unit, pdu }, len)))
}

/// Decodes one response from the front of `buf` (see [`ResponseCodec`]).
pub fn decode_response(buf: &[u8]) -> Result<Option<(ResponseAdu, usize)>, DecodeError> {
    let &[unit, function, ..] = buf else {
        return Ok(None);
    };
    let len = match function {
        f if f & EXCEPTION_BIT != 0 => 5,
        1..=4 => match buf.get(2) {
            Some(&n) => 5 + usize::from(n),
            None => return Ok(None),
        },
        5 | 6 | 15 | 16 => 8,
        _ => return Err(DecodeError::UnknownFunction { unit, function }),
    };
    let Some(frame) = buf.get(..len) else {
        return Ok(None);
    };
    let body = check_crc(frame)?;
    let malformed = |problem| DecodeError::Malformed {
        unit,
        function,
        len,
        problem,
    };
    let response = parse_response(body).map_err(malformed)?;
    Ok(Some((ResponseAdu { unit, response }, len)))
}

/// Appends a request frame to `out`.
pub fn encode_request(frame: &RequestAdu, out: &mut Vec<u8>) {
    let start = out.len();
    encode_request_body(frame, out);
    append_crc(out, start);
}

/// Appends a request's unit, function and data, without a CRC (Modbus TCP frames the
/// same bytes behind its own header).
pub(crate) fn encode_request_body(frame: &RequestAdu, out: &mut Vec<u8>) {
    out.push(frame.unit);
    out.push(frame.pdu.function_byte());
    match &frame.pdu {
        RequestPdu::ReadCoils { address, count }
        | RequestPdu::ReadDiscreteInputs { address, count }
        | RequestPdu::ReadHoldingRegisters { address, count }
        | RequestPdu::ReadInputRegisters { address, count } => {
            out.extend_from_slice(&address.to_be_bytes());
            out.extend_from_slice(&count.to_be_bytes());
        }
        RequestPdu::WriteSingleCoil { address, value }
        | RequestPdu::WriteSingleRegister { address, value } => {
            out.extend_from_slice(&address.to_be_bytes());
            out.extend_from_slice(&value.to_be_bytes());
        }
        RequestPdu::WriteMultipleCoils {
            address,
            count,
            data,
        }
        | RequestPdu::WriteMultipleRegisters {
            address,
            count,
            data,
        } => {
            out.extend_from_slice(&address.to_be_bytes());
            out.extend_from_slice(&count.to_be_bytes());
            out.push(data.byte_count());
            out.extend_from_slice(data.as_bytes());
        }
        RequestPdu::Other(other) => out.extend_from_slice(other.data()),
    }
}

/// Appends a response frame to `out`.
pub fn encode_response(frame: &ResponseAdu, out: &mut Vec<u8>) {
    let start = out.len();
    encode_response_body(frame, out);
    append_crc(out, start);
}

/// Appends a response's unit, function and data, without a CRC.
pub(crate) fn encode_response_body(frame: &ResponseAdu, out: &mut Vec<u8>) {
    out.push(frame.unit);
    match &frame.response {
        Response::Exception(e) => {
            out.push(e.function.get() | EXCEPTION_BIT);
            out.push(e.code.get());
        }
        response => {
            out.push(response.function().get());
            match response {
                Response::ReadCoils(bits) | Response::ReadDiscreteInputs(bits) => {
                    out.push(bits.byte_count());
                    out.extend_from_slice(bits.as_bytes());
                }
                Response::ReadHoldingRegisters(r) | Response::ReadInputRegisters(r) => {
                    out.push(r.byte_count());
                    out.reserve(2 * r.values().len() + CRC_LEN);
                    for value in r.values() {
                        out.extend_from_slice(&value.to_be_bytes());
                    }
                }
                Response::WriteSingleCoil(w) => {
                    out.extend_from_slice(&w.address.to_be_bytes());
                    let value = if w.value {
                        super::COIL_ON
                    } else {
                        super::COIL_OFF
                    };
                    out.extend_from_slice(&value.to_be_bytes());
                }
                Response::WriteSingleRegister(w) => {
                    out.extend_from_slice(&w.address.to_be_bytes());
                    out.extend_from_slice(&w.value.to_be_bytes());
                }
                Response::WriteMultipleCoils { address, count }
                | Response::WriteMultipleRegisters { address, count } => {
                    out.extend_from_slice(&address.to_be_bytes());
                    out.extend_from_slice(&count.to_be_bytes());
                }
                Response::Exception(_) => {}
            }
        }
    }
}

/// The first complete frame with a good CRC anywhere in `buf`: `(offset, frame, length)`.
///
/// Without timing, bytes that look like the head of a long frame (a garbage byte followed
/// by `0x10` and a large byte count, say) hold a decoder up until that many bytes have
/// come. A client that sees the line fall silent (3.5 character times) with bytes still
/// buffered can look past them with this, then drop `offset + length` bytes.
pub fn find_frame<C: Codec>(codec: &C, buf: &[u8]) -> Option<(usize, C::Frame, usize)> {
    (0..buf.len()).find_map(|offset| match codec.decode(buf.get(offset..)?) {
        Ok(Some((frame, len))) => Some((offset, frame, len)),
        _ => None,
    })
}

/// Appends the CRC of `out[start..]`, low byte first.
pub fn append_crc(out: &mut Vec<u8>, start: usize) {
    let crc = CRC16_MODBUS.checksum(out.get(start..).unwrap_or_default());
    out.extend_from_slice(&crc.to_le_bytes());
}

/// Whether `frame` (CRC included) ends in the CRC of the bytes before it.
pub fn crc_is_good(frame: &[u8]) -> bool {
    check_crc(frame).is_ok()
}

/// The frame without its CRC if the CRC is good.
fn check_crc(frame: &[u8]) -> Result<&[u8], DecodeError> {
    let (unit, function) = (
        frame.first().copied().unwrap_or(0),
        frame.get(1).copied().unwrap_or(0),
    );
    let Some(split) = frame.len().checked_sub(CRC_LEN) else {
        return Err(DecodeError::Crc {
            unit,
            function,
            len: frame.len(),
            expected: 0,
            actual: 0,
        });
    };
    let (body, crc) = frame.split_at(split);
    let expected = CRC16_MODBUS.checksum(body);
    let actual = match *crc {
        [lo, hi] => u16::from_le_bytes([lo, hi]),
        _ => 0,
    };
    if expected == actual {
        Ok(body)
    } else {
        Err(DecodeError::Crc {
            unit,
            function,
            len: frame.len(),
            expected,
            actual,
        })
    }
}

/// A request of a function with no known layout: the shortest 4–8 byte run with a good CRC.
fn scan_other_function(
    buf: &[u8],
    unit: u8,
    function: u8,
) -> Result<Option<(RequestAdu, usize)>, DecodeError> {
    let longest = buf.len().min(OTHER_FUNCTION_SCAN);
    for len in MIN_ADU..=longest {
        if let Some(frame) = buf.get(..len)
            && let Ok(body) = check_crc(frame)
        {
            let data = body.get(2..).unwrap_or_default().to_vec();
            let other =
                OtherFunction::new(function, data).map_err(|_| malformed_too_long(body, len))?;
            return Ok(Some((
                RequestAdu {
                    unit,
                    pdu: RequestPdu::Other(other),
                },
                len,
            )));
        }
    }
    if buf.len() < OTHER_FUNCTION_SCAN {
        Ok(None)
    } else {
        Err(DecodeError::UnknownFunction { unit, function })
    }
}

fn malformed_too_long(body: &[u8], len: usize) -> DecodeError {
    DecodeError::Malformed {
        unit: body.first().copied().unwrap_or(0),
        function: body.get(1).copied().unwrap_or(0),
        len,
        problem: Malformed::TooLong {
            len: body.len().saturating_sub(2),
            max: OtherFunction::MAX_DATA,
        },
    }
}

/// Reads big-endian fields from a frame body whose length the function code fixed.
struct Fields<'a>(&'a [u8]);

impl<'a> Fields<'a> {
    fn u8(&mut self) -> Option<u8> {
        let (&first, rest) = self.0.split_first()?;
        self.0 = rest;
        Some(first)
    }

    fn u16(&mut self) -> Option<u16> {
        Some(u16::from_be_bytes([self.u8()?, self.u8()?]))
    }

    fn rest(self) -> &'a [u8] {
        self.0
    }
}

/// Parses a request body (unit, function, data) whose length and CRC were checked.
/// `None` only if the data is longer than any request of another function can be.
pub(crate) fn parse_request(body: &[u8]) -> Option<RequestPdu> {
    let mut f = Fields(body);
    let (_unit, function) = (f.u8()?, f.u8()?);
    Some(match function {
        1 => RequestPdu::ReadCoils {
            address: f.u16()?,
            count: f.u16()?,
        },
        2 => RequestPdu::ReadDiscreteInputs {
            address: f.u16()?,
            count: f.u16()?,
        },
        3 => RequestPdu::ReadHoldingRegisters {
            address: f.u16()?,
            count: f.u16()?,
        },
        4 => RequestPdu::ReadInputRegisters {
            address: f.u16()?,
            count: f.u16()?,
        },
        5 => RequestPdu::WriteSingleCoil {
            address: f.u16()?,
            value: f.u16()?,
        },
        6 => RequestPdu::WriteSingleRegister {
            address: f.u16()?,
            value: f.u16()?,
        },
        15 | 16 => {
            let (address, count, _byte_count) = (f.u16()?, f.u16()?, f.u8()?);
            let data = ByteField::new(f.rest().to_vec()).ok()?;
            if function == 15 {
                RequestPdu::WriteMultipleCoils {
                    address,
                    count,
                    data,
                }
            } else {
                RequestPdu::WriteMultipleRegisters {
                    address,
                    count,
                    data,
                }
            }
        }
        _ => RequestPdu::Other(OtherFunction::new(function, f.rest().to_vec()).ok()?),
    })
}

/// Parses a response body (unit, function, data) whose length and CRC were checked.
pub(crate) fn parse_response(body: &[u8]) -> Result<Response, Malformed> {
    // The length checks made these fields present; a short body reads as zeros, which the
    // checks below refuse or which cannot occur.
    let mut f = Fields(body);
    let (_unit, function) = (f.u8().unwrap_or(0), f.u8().unwrap_or(0));
    if function & EXCEPTION_BIT != 0 {
        let code =
            ExceptionCode::new(f.u8().unwrap_or(0)).map_err(|_| Malformed::ExceptionCodeZero)?;
        return Ok(Response::Exception(Exception {
            function: FunctionCode::of_exception(function),
            code,
        }));
    }
    let mut word = || f.u16().unwrap_or(0);
    match function {
        1 | 2 => {
            let byte_count = body.get(2).copied().unwrap_or(0);
            let data = body.get(3..).unwrap_or_default().to_vec();
            let bits = PackedBits::from_bytes(data).map_err(|_| Malformed::ByteCount {
                byte_count,
                what: "coils or discrete inputs",
                allowed: "1 to 250",
            })?;
            Ok(if function == 1 {
                Response::ReadCoils(bits)
            } else {
                Response::ReadDiscreteInputs(bits)
            })
        }
        3 | 4 => {
            let byte_count = body.get(2).copied().unwrap_or(0);
            let data = body.get(3..).unwrap_or_default();
            let bad = Malformed::ByteCount {
                byte_count,
                what: "registers",
                allowed: "an even number from 2 to 250",
            };
            if data.len() % 2 != 0 {
                return Err(bad);
            }
            let values = data
                .chunks_exact(2)
                .map(|b| u16::from_be_bytes([b[0], b[1]]))
                .collect();
            let registers = RegisterValues::new(values).map_err(|_| bad)?;
            Ok(if function == 3 {
                Response::ReadHoldingRegisters(registers)
            } else {
                Response::ReadInputRegisters(registers)
            })
        }
        5 => {
            let address = word();
            let value = match word() {
                super::COIL_ON => true,
                super::COIL_OFF => false,
                value => return Err(Malformed::CoilValue { value }),
            };
            Ok(Response::WriteSingleCoil(super::WriteCoil {
                address,
                value,
            }))
        }
        6 => Ok(Response::WriteSingleRegister(super::WriteRegister {
            address: word(),
            value: word(),
        })),
        15 => Ok(Response::WriteMultipleCoils {
            address: word(),
            count: word(),
        }),
        _ => Ok(Response::WriteMultipleRegisters {
            address: word(),
            count: word(),
        }),
    }
}

#[cfg(test)]
mod tests;
