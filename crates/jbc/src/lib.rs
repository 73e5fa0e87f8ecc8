//! The JBC station–robot protocol, sans I/O, for the JTSE hot-air station.
//!
//! - [`frame`]: the byte layout (`STX [src dst] hdr code [data] ETX BCC`), both forms,
//!   and the [`frame::FrameCodec`] that decodes a byte stream with resynchronisation.
//! - [`code`]: the commands of both editions of the spec as a typed [`code::Code`], the
//!   spec's tables (tools, tool and station errors, NAK reasons, port status, work mode) and
//!   [`code::interpret`], which turns a station's data into a reading with words and units.
//! - [`message`]: [`message::Request`] (checked reads and writes), [`message::Reply`], and
//!   [`message::match_reply`], which says whether a frame answers the request in flight.
//! - [`client`]: the async client over a [`link`] line: timeouts, retries, resync.
//! - [`annotate`]: frames in words, for dumps of captured traffic.
//! - [`device`]: [`device::Station`], a JTSE twin (heating curve, counters, exact NAKs) as a
//!   pure [`wire::device::Model`] with time as a parameter.
//!
//! Spec: `specs/jbc-jtse-control-unit-programmers-guide.txt` and
//! `specs/jbc-protocol-station-robot.txt`, with the decisions in `specs/README.md`.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod annotate;
#[cfg(feature = "io")]
pub mod client;
pub mod code;
pub mod device;
pub mod frame;
pub mod message;

pub use code::{Code, NakReason, Reading, interpret};
pub use device::{Station, StationConfig};
pub use frame::{Address, Data, DecodeError, Frame, FrameCodec, Header, RawCode, Route};
pub use message::{Match, Reply, Request, match_reply};

/// Bodies of the fuzz targets in `fuzz/`, here so that a unit test runs them too.
#[doc(hidden)]
pub mod fuzzing {
    use std::time::{Duration, Instant};

    use wire::{Codec, Deframer, device::Model};

    use crate::device::{Station, StationConfig};
    use crate::frame::FrameCodec;

    /// Decodes arbitrary bytes; every frame must re-encode to the bytes it came from and
    /// decode again to itself; a station must take every frame and error without panicking.
    pub fn decode(data: &[u8]) {
        let mut deframer = Deframer::new(FrameCodec);
        let mut station = Station::new(StationConfig::default());
        let mut bare = Station::new(StationConfig {
            address: None,
            ..StationConfig::default()
        });
        let start = Instant::now();
        deframer.push(data);
        let mut frames = 0u32;
        while let Some(chunk) = deframer.next_chunk() {
            let now = start + Duration::from_millis(u64::from(frames) * 100);
            frames += 1;
            match chunk {
                wire::codec::Chunk::Frame { frame, raw } => {
                    let mut encoded = Vec::new();
                    FrameCodec.encode(&frame, &mut encoded);
                    assert_eq!(
                        encoded, raw,
                        "a decoded frame must re-encode to its own bytes"
                    );
                    let again = FrameCodec.decode(&encoded);
                    assert_eq!(
                        again,
                        Ok(Some((frame, encoded.len()))),
                        "re-decoding must give the same frame"
                    );
                    for replies in [station.handle(Ok(frame), now), bare.handle(Ok(frame), now)] {
                        check_replies(&replies);
                    }
                }
                wire::codec::Chunk::Skipped { error, raw } => {
                    assert!(
                        !raw.is_empty(),
                        "a decode error must drop at least one byte"
                    );
                    for replies in [
                        station.handle(Err(error.clone()), now),
                        bare.handle(Err(error), now),
                    ] {
                        check_replies(&replies);
                    }
                }
            }
        }
        // Whatever is left is a frame start waiting for its end, never more than one frame.
        assert!(deframer.buffered().len() < crate::frame::MAX_LEN);
    }

    /// A station's reply is at most one well-formed frame.
    fn check_replies(replies: &[wire::Transmit]) {
        assert!(replies.len() <= 1, "a station answers a frame at most once");
        for reply in replies {
            let decoded = FrameCodec.decode(&reply.bytes);
            assert!(
                matches!(decoded, Ok(Some((_, len))) if len == reply.bytes.len()),
                "a station's reply must be one valid frame: {:?}",
                reply.bytes
            );
        }
    }
}

#[cfg(test)]
mod fuzz_tests {
    #[test]
    fn fuzz_body_survives_sample_inputs() {
        let samples: &[&[u8]] = &[
            b"",
            b"\x02",
            b"\x020001RST1\x03\x64",
            b"\x020001RSMN\x03\x02\x020001RST1\x03\x64",
            b"noise\x02RST1\x03\x65\x02\x02\x03\x03\xff",
            b"\x020001WST100375\x03\x51",
            b"\x020001WPS1\x80\x80\x80\x80\x80\x03\x00",
            &[0x02; 40],
            &[0x03; 40],
        ];
        for sample in samples {
            super::fuzzing::decode(sample);
        }
    }

    #[test]
    fn fuzz_body_survives_pseudo_random_inputs() {
        let mut rng = fastrand::Rng::with_seed(0x1bc);
        let alphabet = b"\x02\x030123456789RWANSTEPMAIFH -\xff";
        for _ in 0..2000 {
            let len = rng.usize(0..64);
            let data: Vec<u8> = (0..len)
                .map(|_| alphabet[rng.usize(..alphabet.len())])
                .collect();
            super::fuzzing::decode(&data);
        }
    }
}
