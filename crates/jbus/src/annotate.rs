//! Frames of a capture in words, for annotated dumps (`cellbus decode modbus`).
//!
//! A capture of a serial line holds both directions. [`SniffCodec`] tells requests and
//! responses apart by their layout; a write of one coil or register and its echo are the
//! same bytes, so [`Annotator`] takes such a frame as the answer when it follows a request
//! and as a request otherwise.
//!
//! A capture has no timing, so a damaged frame's bytes can look like the head of a long
//! frame and hide the good frames behind it. [`CaptureCodec`] decodes a whole capture: it
//! drops the bytes up to the next good frame in one run, named by the first reason.

use std::cell::Cell;
use std::fmt::Write as _;

use wire::{Codec, Resync};

use crate::rtu::request::counted;
use crate::rtu::{
    BROADCAST_UNIT, DecodeError, FunctionCode, Request, RequestAdu, RequestPdu, Response,
    ResponseAdu, SniffCodec, Sniffed, find_frame, unpack_bits,
};

/// Decodes a whole capture of both directions: [`SniffCodec`], except that bytes which
/// make no good frame are dropped in one run up to the next good frame. Give it the whole
/// capture at once: at the end of a live stream it could take a frame still arriving for
/// bytes cut short.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CaptureCodec;

/// A run of bytes of a capture that make no good frame.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub struct Dropped {
    /// Why the first of them is not a frame; `None` when they start a frame that the next
    /// good frame cuts short.
    pub first: Option<DecodeError>,
    /// How many bytes.
    pub len: usize,
}

impl std::fmt::Display for Dropped {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let len = self.len;
        let bytes = if len == 1 { "byte" } else { "bytes" };
        match &self.first {
            Some(e @ DecodeError::Crc { .. }) => write!(f, "{len} {bytes} dropped, CRC bad: {e}"),
            Some(e) => write!(f, "{len} {bytes} dropped: {e}"),
            None => write!(
                f,
                "{len} {bytes} dropped: they start a frame that the next good frame cuts short"
            ),
        }
    }
}

impl Resync for Dropped {
    fn drop_len(&self) -> usize {
        self.len.max(1)
    }
}

impl Codec for CaptureCodec {
    type Frame = Sniffed;
    type Error = Dropped;

    fn decode(&self, buf: &[u8]) -> Result<Option<(Sniffed, usize)>, Dropped> {
        let first = match SniffCodec.decode(buf) {
            Ok(Some(frame)) => return Ok(Some(frame)),
            Ok(None) => None,
            Err(e) => Some(e),
        };
        let next_frame = buf
            .get(1..)
            .and_then(|rest| find_frame(&SniffCodec, rest))
            .map(|(offset, _, _)| 1 + offset);
        match (next_frame, first) {
            (Some(len), first) => Err(Dropped { first, len }),
            // Nothing good follows: the head of a frame cut short by the end of the capture.
            (None, None) => Ok(None),
            // Nothing good follows: drop the run of bad bytes up to what may be a frame's head.
            (None, Some(first)) => {
                // A frame with a bad CRC goes whole, not byte by byte.
                let mut len = match first {
                    DecodeError::Crc { len, .. } if len <= buf.len() => len,
                    _ => first.drop_len(),
                };
                while let Some(rest) = buf.get(len..).filter(|rest| !rest.is_empty()) {
                    match SniffCodec.decode(rest) {
                        Err(e) => len += e.drop_len(),
                        Ok(_) => break,
                    }
                }
                Err(Dropped {
                    first: Some(first),
                    len: len.min(buf.len()),
                })
            }
        }
    }

    fn encode(&self, frame: &Sniffed, out: &mut Vec<u8>) {
        SniffCodec.encode(frame, out);
    }
}

/// Which way a frame went.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Direction {
    /// From the master to a unit.
    Request,
    /// From a unit to the master.
    Response,
}

/// Describes the frames of one capture in order, remembering the direction of the last one.
#[derive(Debug, Default)]
pub struct Annotator {
    last: Cell<Option<Direction>>,
}

impl Annotator {
    /// An annotator at the start of a capture.
    pub fn new() -> Self {
        Self::default()
    }

    /// The next frame of the capture in words: direction, unit, function, addresses,
    /// values, CRC.
    pub fn describe(&self, frame: &Sniffed) -> String {
        let after_request = self.last.get() == Some(Direction::Request);
        let (direction, text) = match frame {
            Sniffed::Request(request) => (Direction::Request, describe_request(request)),
            Sniffed::Response(response) => (Direction::Response, describe_response(response)),
            Sniffed::Either { response, .. } if after_request => {
                (Direction::Response, describe_response(response))
            }
            Sniffed::Either { request, .. } => (Direction::Request, describe_request(request)),
        };
        self.last.set(Some(direction));
        let mut bytes = Vec::new();
        SniffCodec.encode(frame, &mut bytes);
        let crc = match bytes.as_slice() {
            [.., low, high] => u16::from_le_bytes([*low, *high]),
            _ => 0,
        };
        format!("{text}; CRC 0x{crc:04X} good")
    }
}

/// A request in words: `request to unit 2, function 3 (read holding registers): 18
/// registers from 0 (0x0000)`.
pub fn describe_request(adu: &RequestAdu) -> String {
    let to = if adu.unit == BROADCAST_UNIT {
        "broadcast to every unit (no answer)".to_owned()
    } else {
        format!("to unit {}", adu.unit)
    };
    let function = function_text(adu.pdu.function_byte());
    let what = match adu.pdu.to_request() {
        Ok(request) => request_details(&request),
        Err(code) => match &adu.pdu {
            RequestPdu::Other(other) => format!(
                "{} data bytes {}; a server refuses it with {code}",
                other.data().len(),
                hex(other.data())
            ),
            pdu => format!("{pdu:?}; a server refuses it with {code}"),
        },
    };
    format!("request {to}, function {function}: {what}")
}

/// A response in words: `response from unit 2, function 3 (read holding registers): 2
/// registers: 2301 2298`.
pub fn describe_response(adu: &ResponseAdu) -> String {
    let from = format!("response from unit {}", adu.unit);
    let function = adu.response.function();
    match &adu.response {
        Response::Exception(e) => format!("{from}, function {function} refused: {}", e.code),
        Response::ReadCoils(bits) | Response::ReadDiscreteInputs(bits) => {
            let bytes = bits.as_bytes();
            format!(
                "{from}, function {function}: {} of bits {} (bits from the first address \
                 on: {}; the request says how many count)",
                wire::words::Bytes(bytes.len()),
                hex(bytes),
                bit_text(&unpack_bits(bytes, bytes.len() * 8))
            )
        }
        Response::ReadHoldingRegisters(values) | Response::ReadInputRegisters(values) => {
            format!(
                "{from}, function {function}: {}: {}",
                counted(values.values().len(), "registers"),
                word_text(values.values())
            )
        }
        Response::WriteSingleCoil(_)
        | Response::WriteSingleRegister(_)
        | Response::WriteMultipleCoils { .. }
        | Response::WriteMultipleRegisters { .. } => {
            format!("{from}, function {function}: {}", adu.response)
        }
    }
}

fn function_text(byte: u8) -> String {
    FunctionCode::new(byte).map_or_else(|_| format!("0x{byte:02X}"), |f| f.to_string())
}

fn request_details(request: &Request) -> String {
    match request {
        Request::ReadCoils(r) => range_text("coils", r.address(), r.count().get()),
        Request::ReadDiscreteInputs(r) => {
            range_text("discrete inputs", r.address(), r.count().get())
        }
        Request::ReadHoldingRegisters(r) => {
            range_text("holding registers", r.address(), r.count().get())
        }
        Request::ReadInputRegisters(r) => {
            range_text("input registers", r.address(), r.count().get())
        }
        Request::WriteSingleCoil(_) | Request::WriteSingleRegister(_) => request.to_string(),
        Request::WriteMultipleCoils(w) => format!(
            "{}: {}",
            range_text("coils", w.address(), w.count().get()),
            bit_text(w.values())
        ),
        Request::WriteMultipleRegisters(w) => format!(
            "{}: {}",
            range_text("registers", w.address(), w.count().get()),
            word_text(w.values())
        ),
    }
}

fn range_text(what: &str, address: u16, count: u16) -> String {
    let last = u32::from(address) + u32::from(count) - 1;
    let count = counted(count, what);
    format!("{count} from {address} (0x{address:04X}) to {last} (0x{last:04X})")
}

fn bit_text(bits: &[bool]) -> String {
    let text: Vec<&str> = bits.iter().map(|&b| if b { "1" } else { "0" }).collect();
    text.join(" ")
}

fn word_text(words: &[u16]) -> String {
    let mut text = String::new();
    for (i, word) in words.iter().enumerate() {
        if i > 0 {
            text.push(' ');
        }
        let _ = write!(text, "{word}");
    }
    text
}

fn hex(bytes: &[u8]) -> String {
    let text: Vec<String> = bytes.iter().map(|b| format!("{b:02X}")).collect();
    text.join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rtu::{Addressed, RegisterValues, UnitId};

    fn read_request() -> Sniffed {
        Sniffed::Request(
            Addressed::new(
                UnitId::new(2).expect("2"),
                Request::read_holding_registers(0x46, 2).expect("valid"),
            )
            .to_adu(),
        )
    }

    #[test]
    fn a_read_and_its_answer_are_told_apart_with_addresses_values_and_crc() {
        let annotator = Annotator::new();
        let text = annotator.describe(&read_request());
        assert!(
            text.starts_with("request to unit 2, function 3 (read holding registers): 2 holding registers from 70 (0x0046) to 71 (0x0047)"),
            "{text}"
        );
        assert!(text.ends_with("good"), "{text}");
        let answer = Sniffed::Response(ResponseAdu {
            unit: 2,
            response: Response::ReadHoldingRegisters(
                RegisterValues::new(vec![2301, 2298]).expect("2"),
            ),
        });
        let text = annotator.describe(&answer);
        assert!(
            text.starts_with(
                "response from unit 2, function 3 (read holding registers): 2 registers: 2301 2298"
            ),
            "{text}"
        );
    }

    #[test]
    fn a_write_and_its_identical_echo_are_request_then_response() {
        let write = Addressed::new(
            UnitId::new(1).expect("1"),
            Request::write_single_register(4, 77),
        )
        .to_adu()
        .to_bytes();
        let annotator = Annotator::new();
        let (frame, _) = SniffCodec.decode(&write).expect("valid").expect("whole");
        assert!(matches!(frame, Sniffed::Either { .. }));
        assert!(annotator.describe(&frame).starts_with("request to unit 1"));
        assert!(
            annotator
                .describe(&frame)
                .starts_with("response from unit 1")
        );
        assert!(annotator.describe(&frame).starts_with("request to unit 1"));
    }

    #[test]
    fn a_damaged_frame_is_dropped_in_one_run_and_the_frames_behind_it_survive() {
        let good = match read_request() {
            Sniffed::Request(adu) => adu.to_bytes(),
            _ => unreachable!("read_request is a request"),
        };
        let mut damaged = good.clone();
        if let Some(last) = damaged.last_mut() {
            *last ^= 0xFF;
        }
        // The damaged frame's tail reads as the head of a long frame (unit 0, function 2).
        let mut capture = damaged.clone();
        capture.extend_from_slice(&good);
        let mut deframer = wire::Deframer::new(CaptureCodec);
        deframer.push(&capture);
        match deframer.next_frame() {
            Some(Err(dropped)) => {
                assert_eq!(dropped.len, 8);
                assert!(dropped.to_string().contains("CRC bad"), "{dropped}");
            }
            other => panic!("expected a dropped run, got {other:?}"),
        }
        assert!(matches!(
            deframer.next_frame(),
            Some(Ok(Sniffed::Request(_)))
        ));
        assert!(deframer.next_frame().is_none());
        assert!(deframer.buffered().is_empty());
    }

    #[test]
    fn garbage_at_the_end_of_a_capture_is_one_run_up_to_what_may_be_a_frames_head() {
        let mut deframer = wire::Deframer::new(CaptureCodec);
        // Function 0 exists in no direction, but a request of an unknown function may be
        // 4 to 8 bytes long: fewer than 8 bytes at the end may still be one.
        let garbage = [
            0x05, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
        ];
        deframer.push(&garbage);
        let dropped = match deframer.next_frame() {
            Some(Err(dropped)) => dropped,
            other => panic!("expected a dropped run, got {other:?}"),
        };
        assert!(deframer.next_frame().is_none());
        assert_eq!(dropped.len + deframer.buffered().len(), garbage.len());
        assert!(deframer.buffered().len() < crate::rtu::codec::OTHER_FUNCTION_SCAN);
    }

    #[test]
    fn a_damaged_exception_at_the_end_of_a_capture_is_dropped_whole_as_a_bad_crc() {
        let mut deframer = wire::Deframer::new(CaptureCodec);
        // Exception 2 from unit 2 to a function-3 read, its CRC (30 F1) damaged.
        deframer.push(&[0x02, 0x83, 0x02, 0x30, 0xF0]);
        match deframer.next_frame() {
            Some(Err(Dropped {
                first:
                    Some(DecodeError::Crc {
                        unit: 2,
                        function: 0x83,
                        len: 5,
                        ..
                    }),
                len: 5,
            })) => {}
            other => panic!("expected the 5 bytes dropped for their CRC, got {other:?}"),
        }
        assert!(deframer.next_frame().is_none());
        assert!(deframer.buffered().is_empty());
    }

    #[test]
    fn an_exception_says_its_number_and_meaning() {
        let text = describe_response(&ResponseAdu {
            unit: 2,
            response: Response::exception(
                FunctionCode::READ_HOLDING_REGISTERS,
                crate::rtu::ExceptionCode::ILLEGAL_DATA_ADDRESS,
            ),
        });
        assert!(
            text.contains("refused: exception 2 (illegal data address"),
            "{text}"
        );
    }
}
