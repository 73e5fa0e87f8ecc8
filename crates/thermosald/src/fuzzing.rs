//! Fuzz bodies, shared by `fuzz/fuzz_targets/thermosald_decode.rs` and a unit test.

use std::time::{Duration, Instant};

use wire::device::Model;
use wire::{Codec, Deframer};

use crate::frame::FrameCodec;
use crate::request::Request;

/// Decodes `data` as a byte stream; checks that every frame found encodes to bytes that
/// decode to the same frame, whole and nothing else; parses each as a request; and feeds
/// everything to a simulated line. Panics only if one of those checks fails.
pub fn decode(data: &[u8]) {
    let mut deframer = Deframer::new(FrameCodec);
    deframer.push(data);
    let start = Instant::now();
    let mut line = crate::device::RegulatorBus::new(
        &[crate::Address::new(0).expect("0 is an address")],
        start,
    )
    .expect("one regulator is a valid line");
    let mut at = start;
    while let Some(input) = deframer.next_frame() {
        if let Ok(frame) = &input {
            let bytes = frame.to_bytes();
            match FrameCodec.decode(&bytes) {
                Ok(Some((again, used))) => {
                    assert_eq!(&again, frame, "decode(encode(frame)) differs from frame");
                    assert_eq!(
                        used,
                        bytes.len(),
                        "decode did not take the whole encoded frame"
                    );
                }
                other => panic!("encoded frame {frame} does not decode: {other:?}"),
            }
            if let Ok(request) = Request::parse(frame) {
                assert_eq!(
                    Request::parse(&request.to_frame(frame.target())).as_ref(),
                    Ok(&request)
                );
            }
        }
        at += Duration::from_millis(300);
        let _ = line.handle(input, at);
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn fuzz_body_survives_a_few_inputs() {
        for input in [
            &b""[..],
            b"%",
            b"%053Q990\n",
            b"junk%011Q030125\n%$10Q000003\n%012Q99",
            b"%0\n%99Q99\n%Z53Q990\n%053X990\n%0530990\n%053Q99012\n%053Q990abc\n",
            b"%099Q000000\n%$10Q000002\n%215Q000000\n%253Q990\n",
            &[
                0x25, 0xff, 0x00, 0x0a, 0x25, 0x30, 0x35, 0x33, 0x51, 0x39, 0x39, 0x30, 0x0a,
            ],
        ] {
            super::decode(input);
        }
    }
}
