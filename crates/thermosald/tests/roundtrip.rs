//! Property tests: every frame and request round-trips, whatever the chunking of the stream
//! and whatever noise and half messages surround it.

use proptest::collection::vec;
use proptest::prelude::*;
use proptest::sample::select;
use thermosald::frame::{Count, Direction, Frame, FrameCodec, MessageNumber, RawValue, Target};
use thermosald::request::{Command, Read, Request, Write};
use thermosald::tables::{Item, Table};
use wire::{Codec, Deframer};

use crate::common::addr;

fn target() -> impl Strategy<Value = Target> {
    prop_oneof![
        (0u8..=7).prop_map(|a| Target::Address(addr(a))),
        Just(Target::Assign)
    ]
}

fn count() -> impl Strategy<Value = Count> {
    prop_oneof![
        Just(Count::All),
        (0u8..=98).prop_map(|i| Count::item(i).expect("below 99"))
    ]
}

fn raw() -> impl Strategy<Value = RawValue> {
    (0u16..=999).prop_map(|v| RawValue::new(v).expect("three digits"))
}

prop_compose! {
    fn frame()(
        target in target(),
        message in 0u8..=99,
        query in any::<bool>(),
        count in count(),
        data in vec(raw(), 0..=25),
    ) -> Frame {
        let direction = if query { Direction::Query } else { Direction::Reply };
        let message = MessageNumber::new(message).expect("two digits");
        Frame::new(target, message, direction, count, data).expect("at most 25 items")
    }
}

/// Bytes that are not a message start.
fn noise() -> impl Strategy<Value = Vec<u8>> {
    vec(
        any::<u8>().prop_filter("not a message start", |b| *b != b'%'),
        0..12,
    )
}

fn writable_items() -> Vec<&'static Item> {
    Table::ALL
        .iter()
        .flat_map(|t| t.items())
        .filter(|i| i.writable())
        .collect()
}

fn request() -> impl Strategy<Value = Request> {
    let set_address = (0u8..=7).prop_map(|a| Request::SetAddress(addr(a)));
    let read = (
        select(Table::ALL.to_vec()),
        any::<Option<prop::sample::Index>>(),
    )
        .prop_map(|(table, index)| {
            Request::Read(match index {
                None => Read::all(table),
                Some(i) => Read::item(&table.items()[i.index(table.len())]),
            })
        });
    let write_item =
        (select(writable_items()), any::<prop::sample::Index>()).prop_map(|(item, i)| {
            let span = usize::from(item.raw_max() - item.raw_min()) + 1;
            let raw = RawValue::new(item.raw_min() + i.index(span) as u16).expect("in range");
            Request::Write(Write::item(item, raw).expect("writable and in range"))
        });
    let write_table = (
        select(vec![Table::Machine, Table::Settings, Table::Service]),
        vec(any::<prop::sample::Index>(), 25),
    )
        .prop_map(|(table, picks)| {
            let values = table
                .items()
                .iter()
                .zip(picks)
                .map(|(item, i)| {
                    let span = usize::from(item.raw_max() - item.raw_min()) + 1;
                    RawValue::new(item.raw_min() + i.index(span) as u16).expect("in range")
                })
                .collect();
            Request::Write(Write::whole(table, values).expect("one value per item, in range"))
        });
    let command = select(vec![
        Command::ClearFaults,
        Command::Balance,
        Command::SaveEeprom,
        Command::LoadEeprom,
        Command::MasterReset,
    ])
    .prop_map(Request::Command);
    prop_oneof![set_address, read, write_item, write_table, command]
}

proptest! {
    #[test]
    fn every_frame_decodes_to_itself(frame in frame()) {
        let bytes = frame.to_bytes();
        prop_assert_eq!(bytes.len(), frame.wire_len());
        prop_assert_eq!(FrameCodec.decode(&bytes), Ok(Some((frame, bytes.len()))));
    }

    #[test]
    fn a_frame_cut_short_asks_for_more_bytes(frame in frame(), cut in any::<prop::sample::Index>()) {
        let bytes = frame.to_bytes();
        let cut = cut.index(bytes.len() - 1) + 1;
        prop_assert_eq!(FrameCodec.decode(&bytes[..cut]), Ok(None));
    }

    #[test]
    fn frames_survive_noise_half_messages_and_any_chunking(
        items in vec((noise(), any::<Option<prop::sample::Index>>(), frame()), 1..6),
        trailing in noise(),
        cuts in vec(any::<prop::sample::Index>(), 0..10),
    ) {
        let mut stream = Vec::new();
        let mut expected = Vec::new();
        for (noise, half, frame) in items {
            stream.extend(noise);
            if let Some(half) = half {
                // A message that broke off: '%' and part of a header, no LF.
                let bytes = frame.to_bytes();
                stream.extend_from_slice(&bytes[..1 + half.index(bytes.len() - 2)]);
            }
            stream.extend(frame.to_bytes());
            expected.push(frame);
        }
        stream.extend(trailing);

        let mut cuts: Vec<usize> = cuts.iter().map(|c| c.index(stream.len() + 1)).collect();
        cuts.sort_unstable();
        let mut deframer = Deframer::new(FrameCodec);
        let mut found = Vec::new();
        let mut from = 0;
        for cut in cuts.into_iter().chain([stream.len()]) {
            deframer.push(&stream[from..cut]);
            from = cut;
            while let Some(input) = deframer.next_frame() {
                if let Ok(frame) = input {
                    found.push(frame);
                }
            }
        }
        prop_assert_eq!(found, expected);
    }

    #[test]
    fn random_bytes_never_panic_and_what_decodes_re_encodes(bytes in vec(any::<u8>(), 0..200)) {
        let mut deframer = Deframer::new(FrameCodec);
        deframer.push(&bytes);
        while let Some(input) = deframer.next_frame() {
            if let Ok(frame) = input {
                let again = frame.to_bytes();
                prop_assert_eq!(FrameCodec.decode(&again), Ok(Some((frame, again.len()))));
            }
        }
    }

    #[test]
    fn every_request_parses_back_from_its_frame(request in request(), target in 0u8..=7) {
        let target = match request {
            Request::SetAddress(_) if target == 0 => Target::Assign,
            _ => Target::Address(addr(target)),
        };
        let frame = request.to_frame(target);
        prop_assert_eq!(frame.direction(), Direction::Query);
        let bytes = frame.to_bytes();
        prop_assert_eq!(FrameCodec.decode(&bytes), Ok(Some((frame.clone(), bytes.len()))));
        prop_assert_eq!(Request::parse(&frame), Ok(request));
    }
}
