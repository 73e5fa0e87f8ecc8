//! Fuzz bodies, kept in the library so a unit test runs them and they cannot rot.
//! `fuzz/fuzz_targets/panasonic_decode.rs` calls [`decode`].

use std::time::{Duration, Instant};

use wire::{Codec, Deframer};

use crate::command::Command;
use crate::conversation::HostConversation;
use crate::event::Event;
use crate::message::MessageCodec;
use crate::packet::Packet;
use crate::reply::Reply;
use crate::twin::{Machine, MachineConfig};

/// Decodes `data` as a Port 1/Port 2 stream. Must not panic; checks that every message
/// re-encodes and decodes to itself, and that every typed message round-trips.
pub fn decode(data: &[u8]) {
    let mut deframer = Deframer::new(MessageCodec);
    deframer.push(data);
    let mut host = HostConversation::new();
    while let Some(result) = deframer.next_frame() {
        let Ok(message) = result else { continue };
        let bytes = message.to_bytes();
        let again = MessageCodec.decode(&bytes);
        assert_eq!(
            again,
            Ok(Some((message.clone(), bytes.len()))),
            "decode → encode → decode changed the message"
        );
        match Packet::classify(&message) {
            Packet::Command(command) => {
                let encoded = command
                    .to_message()
                    .expect("a command decoded from a message fits one");
                assert_eq!(Command::parse(&encoded), Ok(command), "command round trip");
            }
            Packet::Reply(reply) => {
                let encoded = reply
                    .to_message()
                    .expect("a reply decoded from a message fits one");
                assert_eq!(Reply::parse(&encoded), Ok(reply), "reply round trip");
            }
            Packet::Event(event) => assert_eq!(
                Event::parse(&event.to_message()),
                Ok(event),
                "event round trip"
            ),
            Packet::Unknown { .. } => {}
        }
        if host.is_idle() {
            let _ = host.start(&Command::Status);
        }
        let _ = host.handle(message);
    }
}

/// Feeds `data` to a twin's Port 1 in slices at advancing times. Must not panic.
pub fn twin(data: &[u8]) {
    let config = MachineConfig {
        remote: true,
        miss_rate: 0.05,
        reel_size: 50,
        ..MachineConfig::default()
    };
    let Ok(mut machine) = Machine::new(config) else {
        return;
    };
    let start = Instant::now();
    machine.host_connected_on_port2(true, start);
    for (i, chunk) in data.chunks(97).enumerate() {
        let now = start + Duration::from_secs(7 * i as u64);
        for reply in machine.handle_port1(chunk, now) {
            let bytes = reply.to_bytes();
            assert!(
                matches!(MessageCodec.decode(&bytes), Ok(Some(_))),
                "the twin sends decodable messages"
            );
        }
        let _ = machine.poll_events(now);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::message::Message;

    fn samples() -> Vec<Vec<u8>> {
        let message = |text: &str, data: &[u8]| {
            Message::with_data(text, data.to_vec())
                .expect("valid")
                .to_bytes()
        };
        let mut stream = Vec::new();
        for bytes in [
            message("C2ST", b""),
            message("D1", b"001"),
            message("A2", b""),
            message("C1RP", b""),
            message("D0", b"03/01/30PABC            \r\n*\r\n"),
            message("A0", b""),
            message("R2E03S012N003Z015M0T000000042", b""),
            message("C0PABC", b"%HEADER\r\n1,2\r\n*\r\n"),
            message("C5STCT", b""),
            message("C2HB00ABC123", b""),
            message("X", b"junk"),
        ] {
            stream.extend(bytes);
        }
        let mut ascii_terminated = message("R0CT0021", b"");
        let len = ascii_terminated.len();
        ascii_terminated[len - 3..].copy_from_slice(b"000");
        vec![
            Vec::new(),
            stream.clone(),
            stream[..stream.len() / 2].to_vec(),
            [b"\x00garbage\xff".to_vec(), stream].concat(),
            ascii_terminated,
            vec![b'C'; 300],
            [b"D0".to_vec(), vec![b' '; 254], vec![0xFF; 4]].concat(),
        ]
    }

    #[test]
    fn fuzz_decode_body_survives_sample_inputs() {
        for sample in samples() {
            decode(&sample);
        }
    }

    proptest::proptest! {
        #[test]
        fn fuzz_bodies_survive_random_bytes(data in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..2000)) {
            decode(&data);
            twin(&data);
        }

        #[test]
        fn fuzz_bodies_survive_valid_messages_with_flipped_bytes(
            flips in proptest::collection::vec((0usize..4000, proptest::prelude::any::<u8>()), 0..6),
        ) {
            let mut data = samples().swap_remove(1);
            for (at, byte) in flips {
                let at = at % data.len();
                data[at] = byte;
            }
            decode(&data);
            twin(&data);
        }
    }

    #[test]
    fn fuzz_twin_body_survives_sample_inputs() {
        for sample in samples() {
            twin(&sample);
        }
    }
}
