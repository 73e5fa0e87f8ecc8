//! Helpers shared by the tests.

use std::time::{Duration, Instant};

use thermosald::device::RegulatorBus;
use thermosald::frame::{Address, Frame, FrameCodec};
use wire::device::{Model, Transmit};
use wire::{Codec, Deframer};

pub fn addr(n: u8) -> Address {
    Address::new(n).expect("test addresses are 0-7")
}

pub fn ms(n: u64) -> Duration {
    Duration::from_millis(n)
}

/// Decodes exactly one frame that fills `bytes`.
pub fn decode_one(bytes: &[u8]) -> Frame {
    match FrameCodec.decode(bytes) {
        Ok(Some((frame, used))) => {
            assert_eq!(
                used,
                bytes.len(),
                "the frame should fill {:?}",
                String::from_utf8_lossy(bytes)
            );
            frame
        }
        other => panic!(
            "{:?} does not decode: {other:?}",
            String::from_utf8_lossy(bytes)
        ),
    }
}

/// Feeds `bytes` to the line model at `now` through a deframer, as the serve loop does.
pub fn send(line: &mut RegulatorBus, bytes: &[u8], now: Instant) -> Vec<Transmit> {
    let mut deframer = Deframer::new(FrameCodec);
    deframer.push(bytes);
    let mut out = Vec::new();
    while let Some(input) = deframer.next_frame() {
        out.extend(line.handle(input, now));
    }
    out
}

/// The only answer to `bytes` at `now`, decoded; panics on silence.
pub fn ask(line: &mut RegulatorBus, bytes: &[u8], now: Instant) -> Frame {
    let out = send(line, bytes, now);
    assert_eq!(
        out.len(),
        1,
        "expected one answer to {:?}, got {out:?}",
        String::from_utf8_lossy(bytes)
    );
    decode_one(&out[0].bytes)
}
