//! Fuzz bodies, shared by the fuzz targets in `fuzz/` and the unit tests that run them.
//!
//! Each body must not panic on any input and checks that what decodes re-encodes to
//! bytes that decode to the same frame. Random bytes rarely carry a good CRC, so each
//! body also runs the input with a correct CRC appended, which takes the fuzzer past the
//! CRC check into the parsers.

use wire::{Codec, Deframer, Resync};

use crate::cross::device::CrossTwin;
use crate::rtu::codec::append_crc;
use crate::rtu::{Addressed, RequestCodec, ResponseCodec, SniffCodec, UnitId, check_response};
use crate::slave::Slave;

/// Decodes `data` as requests (the server's side), checks every frame round-trips, checks
/// typed requests round-trip, and feeds the frames to the CROSS twin and a generic server.
pub fn decode_request(data: &[u8]) {
    for input in [data.to_vec(), with_crc(data)] {
        run_requests(&input);
    }
}

/// Decodes `data` as responses (the client's side), checks every frame round-trips, and
/// checks them against a few requests; then sniffs it as a capture of both directions.
pub fn decode_response(data: &[u8]) {
    for input in [data.to_vec(), with_crc(data)] {
        run_responses(&input);
        run_sniffer(&input);
    }
}

fn run_sniffer(data: &[u8]) {
    let mut deframer = Deframer::new(SniffCodec);
    deframer.push(data);
    while let Some(result) = deframer.next_frame() {
        if let Err(error) = result {
            assert!(error.drop_len() >= 1);
        }
    }
    // The capture decoder and its annotations, as `cellbus decode modbus` runs them.
    let annotator = crate::annotate::Annotator::new();
    let mut deframer = Deframer::new(crate::annotate::CaptureCodec);
    deframer.push(data);
    let mut consumed = 0;
    while let Some(chunk) = deframer.next_chunk() {
        match chunk {
            wire::codec::Chunk::Frame { frame, raw } => {
                assert!(annotator.describe(&frame).ends_with("good"));
                consumed += raw.len();
            }
            wire::codec::Chunk::Skipped { error, raw } => {
                assert_eq!(error.len, raw.len());
                consumed += raw.len();
            }
        }
    }
    assert_eq!(consumed + deframer.buffered().len(), data.len());
}

fn with_crc(data: &[u8]) -> Vec<u8> {
    let mut framed = data.to_vec();
    append_crc(&mut framed, 0);
    framed
}

fn run_requests(data: &[u8]) {
    let codec = RequestCodec;
    let unit = UnitId::new(1).expect("1 is a unit number");
    let mut twin = CrossTwin::new(unit, 0);
    let mut slave = Slave::all_writable(unit);
    let now = std::time::Instant::now();
    let mut deframer = Deframer::new(codec);
    deframer.push(data);
    while let Some(result) = deframer.next_frame() {
        match &result {
            Ok(frame) => {
                round_trip(&codec, frame);
                if let Ok(request) = frame.pdu.to_request() {
                    assert_eq!(
                        request.to_pdu().to_request(),
                        Ok(request.clone()),
                        "typed request round trip"
                    );
                    let adu = Addressed::new(unit, request).to_adu();
                    round_trip(&codec, &adu);
                }
            }
            Err(error) => assert!(error.drop_len() >= 1),
        }
        use wire::device::Model;
        twin.handle(result.clone(), now);
        slave.handle(result, now);
    }
}

fn run_responses(data: &[u8]) {
    let codec = ResponseCodec;
    let unit = UnitId::jbus(data.first().copied().unwrap_or(1).max(1))
        .expect("1-255 is a JBUS unit number");
    let requests = crate::cross::read_requests();
    let mut deframer = Deframer::new(codec);
    deframer.push(data);
    while let Some(result) = deframer.next_frame() {
        match result {
            Ok(frame) => {
                round_trip(&codec, &frame);
                for request in &requests {
                    let _ = check_response(&Addressed::new(unit, request.clone()), &frame);
                }
            }
            Err(error) => assert!(error.drop_len() >= 1),
        }
    }
}

/// Encodes `frame`, decodes the bytes, and checks the same frame comes back whole.
fn round_trip<C: Codec>(codec: &C, frame: &C::Frame)
where
    C::Frame: PartialEq + std::fmt::Debug,
    C::Error: std::fmt::Debug,
{
    let mut bytes = Vec::new();
    codec.encode(frame, &mut bytes);
    match codec.decode(&bytes) {
        Ok(Some((again, len))) => {
            assert_eq!(&again, frame, "decode(encode(frame)) differs");
            assert_eq!(len, bytes.len(), "the re-encoded frame decodes whole");
        }
        other => panic!("re-encoded frame {bytes:02X?} does not decode: {other:?}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fuzz_bodies_survive_sample_inputs() {
        let samples: [&[u8]; 8] = [
            &[],
            &[0x01],
            &[0x01, 0x03, 0x00, 0x00, 0x00, 0x0A, 0xC5, 0xCD],
            &[0x02, 0x03, 0x00, 0x00, 0x00, 0x00],
            &[
                0x01, 0x10, 0x00, 0x01, 0x00, 0x02, 0x04, 0x00, 0x0A, 0x01, 0x02,
            ],
            &[0x01, 0x83, 0x02],
            &[0x11, 0x01, 0x05, 0xCD, 0x6B, 0xB2, 0x0E, 0x1B],
            &[0xFF; 300],
        ];
        for sample in samples {
            decode_request(sample);
            decode_response(sample);
        }
    }

    #[test]
    fn fuzz_bodies_survive_seeded_random_inputs() {
        let mut rng = fastrand::Rng::with_seed(5);
        for _ in 0..2000 {
            let len = rng.usize(0..40);
            let data: Vec<u8> = (0..len).map(|_| rng.u8(..)).collect();
            decode_request(&data);
            decode_response(&data);
        }
    }
}
