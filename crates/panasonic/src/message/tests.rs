use super::*;
use proptest::prelude::*;
use wire::Deframer;

fn decode_all(bytes: &[u8]) -> Vec<Result<Message, DecodeError>> {
    let mut deframer = Deframer::new(MessageCodec);
    deframer.push(bytes);
    std::iter::from_fn(|| deframer.next_frame()).collect()
}

/// Fact sheet §2: "C2ST" + 252 blanks | 00 00 00 00 | 00 00 00 → 263 bytes.
fn c2st_request_bytes() -> Vec<u8> {
    let mut bytes = b"C2ST".to_vec();
    bytes.extend([0x20; 252]);
    bytes.extend([0x00, 0x00, 0x00, 0x00]);
    bytes.extend([0x00, 0x00, 0x00]);
    bytes
}

/// Fact sheet §2: "D1" + 254 blanks | 00 00 00 03 | 30 30 31 | 00 00 00 → 266 bytes.
fn d1_001_reply_bytes() -> Vec<u8> {
    let mut bytes = b"D1".to_vec();
    bytes.extend([0x20; 254]);
    bytes.extend([0x00, 0x00, 0x00, 0x03]);
    bytes.extend([0x30, 0x30, 0x31]);
    bytes.extend([0x00, 0x00, 0x00]);
    bytes
}

/// Asserts that `bytes` are `message` on the wire: what it encodes to and what decodes to
/// it, whole.
fn is_the_wire_form_of(message: Message, bytes: &[u8]) {
    assert_eq!(message.to_bytes(), bytes);
    assert_eq!(MessageCodec.decode(bytes), Ok(Some((message, bytes.len()))));
}

#[test]
fn c2st_request_is_263_bytes_exactly_as_in_the_fact_sheet() {
    let bytes = c2st_request_bytes();
    assert_eq!(bytes.len(), 263);
    is_the_wire_form_of(Message::new("C2ST").expect("valid command"), &bytes);
}

#[test]
fn d1_reply_001_is_266_bytes_exactly_as_in_the_fact_sheet() {
    let bytes = d1_001_reply_bytes();
    assert_eq!(bytes.len(), 266);
    let message = Message::with_data("D1", b"001".to_vec()).expect("valid reply");
    is_the_wire_form_of(message, &bytes);
}

#[test]
fn a2_closing_a_d1_exchange_is_a2_254_blanks_and_seven_nul_bytes() {
    // Fact sheet §2: "A2" + 254 spaces | 00000000 | 000000.
    let mut bytes = b"A2".to_vec();
    bytes.extend([b' '; 254]);
    bytes.extend([0; 7]);
    assert_eq!(Message::new("A2").expect("valid").to_bytes(), bytes);
}

#[test]
fn d1_reply_of_the_c3_example_carries_16_bytes_pabc_padded() {
    // 3.3-12: D1, data size 16, data "PABC" (+ 12 blanks), terminator.
    let mut bytes = b"D1".to_vec();
    bytes.extend([b' '; 254]);
    bytes.extend([0x00, 0x00, 0x00, 0x10]);
    bytes.extend(b"PABC            ");
    bytes.extend([0x00; 3]);
    assert_eq!(bytes.len(), 279);
    let message = Message::with_data("D1", b"PABC            ".to_vec()).expect("valid");
    is_the_wire_form_of(message, &bytes);
}

#[test]
fn decode_waits_for_every_prefix_of_a_message() {
    let bytes = d1_001_reply_bytes();
    for end in 0..bytes.len() {
        assert_eq!(
            MessageCodec.decode(&bytes[..end]),
            Ok(None),
            "prefix of {end} bytes"
        );
    }
}

#[test]
fn decode_takes_one_message_and_leaves_the_next() {
    let mut bytes = c2st_request_bytes();
    bytes.extend(d1_001_reply_bytes());
    let (first, used) = MessageCodec
        .decode(&bytes)
        .expect("valid")
        .expect("complete");
    assert_eq!((first.command(), used), ("C2ST", 263));
    let results = decode_all(&bytes);
    assert_eq!(results.len(), 2);
    assert_eq!(results[1].as_ref().map(Message::data), Ok(&b"001"[..]));
}

#[test]
fn decode_accepts_an_ascii_zero_terminator_and_remembers_it() {
    let mut bytes = d1_001_reply_bytes();
    let len = bytes.len();
    bytes[len - 3..].copy_from_slice(b"000");
    let (message, _) = MessageCodec
        .decode(&bytes)
        .expect("accepted")
        .expect("complete");
    assert_eq!(message.terminator(), Terminator::AsciiZero);
    assert_eq!(message.to_bytes(), bytes, "re-encodes byte for byte");
}

#[test]
fn decode_rejects_a_wrong_terminator_and_says_what_it_found() {
    let mut bytes = d1_001_reply_bytes();
    let len = bytes.len();
    bytes[len - 3..].copy_from_slice(&[0x00, 0x0D, 0x0A]);
    assert_eq!(
        MessageCodec.decode(&bytes),
        // No capital letter follows the D, so no message can start in these bytes.
        Err(DecodeError::Terminator {
            command: "D1".into(),
            size: 3,
            found: [0x00, 0x0D, 0x0A],
            drop: 266
        })
    );
}

#[test]
fn decode_rejects_a_mixed_terminator() {
    let mut bytes = c2st_request_bytes();
    bytes[262] = b'0';
    assert!(matches!(
        MessageCodec.decode(&bytes),
        Err(DecodeError::Terminator { .. })
    ));
}

#[test]
fn decode_refuses_a_hostile_size_at_once_without_waiting_for_the_data() {
    let mut bytes = b"C0PHOSTILE".to_vec();
    bytes.resize(COMMAND_LEN, b' ');
    bytes.extend(u32::MAX.to_be_bytes());
    let error = MessageCodec.decode(&bytes).expect_err("size above the cap");
    assert_eq!(
        error,
        // The next possible start is the P of "C0P".
        DecodeError::DataTooLong {
            command: "C0PHOSTILE".into(),
            size: u32::MAX,
            max: MAX_DATA_LEN,
            drop: 2
        }
    );
    assert!(error.to_string().contains("4194304-byte limit"), "{error}");
}

#[test]
fn decode_accepts_data_of_exactly_the_cap_and_refuses_one_more_byte() {
    let mut header = b"D0".to_vec();
    header.resize(COMMAND_LEN, b' ');
    let mut at_cap = header.clone();
    at_cap.extend((MAX_DATA_LEN as u32).to_be_bytes());
    assert_eq!(MessageCodec.decode(&at_cap), Ok(None), "waits for the data");
    let mut above = header;
    above.extend((MAX_DATA_LEN as u32 + 1).to_be_bytes());
    assert!(matches!(
        MessageCodec.decode(&above),
        Err(DecodeError::DataTooLong { .. })
    ));
}

/// `garbage` before a C2ST request is refused in one step, as `error`, and the request
/// decodes after it.
fn assert_one_error_then_c2st(garbage: &[u8], error: DecodeError) {
    let mut bytes = garbage.to_vec();
    bytes.extend(c2st_request_bytes());
    assert_eq!(MessageCodec.decode(&bytes), Err(error));
    let results = decode_all(&bytes);
    assert_eq!(results.len(), 2);
    assert_eq!(results[1].as_ref().map(Message::command), Ok("C2ST"));
}

#[test]
fn decode_skips_a_run_of_garbage_up_to_the_next_capital_letter() {
    assert_one_error_then_c2st(
        b"\x00\x01xyz\r\n",
        DecodeError::NotAStart {
            byte: 0x00,
            drop: 7,
        },
    );
}

#[test]
fn decode_skips_past_a_control_byte_inside_the_command_field_in_one_step() {
    assert_one_error_then_c2st(
        b"ABC\x00def",
        DecodeError::CommandField {
            offset: 3,
            byte: 0x00,
            drop: 7,
        },
    );
}

#[test]
fn capital_letters_before_a_message_cost_one_error_each_and_the_message_survives() {
    let mut bytes = b"XY".to_vec();
    bytes.extend(c2st_request_bytes());
    let results = decode_all(&bytes);
    assert_eq!(results.len(), 3, "{results:?}");
    assert!(results[0].is_err() && results[1].is_err());
    assert_eq!(results[2].as_ref().map(Message::command), Ok("C2ST"));
}

#[test]
fn a_message_whose_size_is_too_small_is_dropped_and_the_next_one_is_found() {
    // D1 claims 1 byte but carries 3: its "terminator" is "01\0".
    let mut broken = d1_001_reply_bytes();
    broken[259] = 1;
    let mut bytes = broken;
    bytes.extend(c2st_request_bytes());
    let results = decode_all(&bytes);
    assert!(matches!(results[0], Err(DecodeError::Terminator { .. })));
    let good: Vec<_> = results.iter().filter_map(|r| r.as_ref().ok()).collect();
    assert_eq!(good.len(), 1);
    assert_eq!(good[0].command(), "C2ST");
}

#[test]
fn message_new_trims_padding_and_refuses_what_cannot_be_sent() {
    assert_eq!(Message::new("C2ST   ").expect("valid").command(), "C2ST");
    assert_eq!(Message::new("   "), Err(MessageError::EmptyCommand));
    assert_eq!(
        Message::new("c2st"),
        Err(MessageError::CommandStart { found: 'c' })
    );
    assert_eq!(
        Message::new("C2\tST"),
        Err(MessageError::CommandChar {
            offset: 2,
            found: '\t'
        })
    );
    assert_eq!(
        Message::new("Cé"),
        Err(MessageError::CommandChar {
            offset: 1,
            found: 'é'
        })
    );
    let long = "C".repeat(257);
    assert_eq!(
        Message::new(&long),
        Err(MessageError::CommandTooLong { len: 257, max: 256 })
    );
    assert!(Message::new(&long[..256]).is_ok());
    assert_eq!(
        Message::with_data("D0", vec![0; MAX_DATA_LEN + 1]),
        Err(MessageError::DataTooLong {
            len: MAX_DATA_LEN + 1,
            max: MAX_DATA_LEN
        })
    );
}

#[test]
fn errors_always_drop_at_least_one_byte() {
    for error in [
        DecodeError::NotAStart { byte: 0, drop: 0 },
        DecodeError::CommandField {
            offset: 0,
            byte: 0,
            drop: 0,
        },
    ] {
        assert_eq!(error.drop_len(), 1);
    }
}

fn arb_message() -> impl Strategy<Value = Message> {
    (
        "[A-Z][ -~]{0,40}",
        prop::collection::vec(any::<u8>(), 0..600),
        prop::bool::ANY,
    )
        .prop_filter_map("command must survive trimming", |(command, data, ascii)| {
            let terminator = if ascii {
                Terminator::AsciiZero
            } else {
                Terminator::Nul
            };
            Message::with_data(&command, data)
                .ok()
                .map(|m| m.with_terminator(terminator))
        })
}

fn chunked(bytes: &[u8], cuts: &[usize]) -> Vec<Result<Message, DecodeError>> {
    let mut deframer = Deframer::new(MessageCodec);
    let mut out = Vec::new();
    let mut at = 0;
    let mut cuts: Vec<usize> = cuts.iter().map(|c| c % (bytes.len() + 1)).collect();
    cuts.sort_unstable();
    for cut in cuts.into_iter().chain([bytes.len()]) {
        deframer.push(&bytes[at..cut]);
        at = cut;
        out.extend(std::iter::from_fn(|| deframer.next_frame()));
    }
    out
}

proptest! {
    #[test]
    fn messages_round_trip(message in arb_message()) {
        let bytes = message.to_bytes();
        prop_assert_eq!(bytes.len(), message.encoded_len());
        prop_assert_eq!(MessageCodec.decode(&bytes), Ok(Some((message, bytes.len()))));
    }

    #[test]
    fn messages_split_anywhere_decode_the_same(
        messages in prop::collection::vec(arb_message(), 1..5),
        cuts in prop::collection::vec(any::<usize>(), 0..12),
    ) {
        let bytes: Vec<u8> = messages.iter().flat_map(Message::to_bytes).collect();
        let decoded: Vec<Message> = chunked(&bytes, &cuts).into_iter().collect::<Result<_, _>>().expect("clean stream");
        prop_assert_eq!(decoded, messages);
    }

    #[test]
    fn garbage_before_between_and_after_messages_never_hides_them(
        messages in prop::collection::vec(arb_message(), 1..4),
        garbage in prop::collection::vec(prop::collection::vec(any::<u8>(), 0..40), 5),
        cuts in prop::collection::vec(any::<usize>(), 0..8),
    ) {
        // Garbage ends in a NUL so that it cannot run into the next message's command field.
        let mut bytes = Vec::new();
        for (message, junk) in messages.iter().zip(&garbage) {
            bytes.extend(junk);
            if !junk.is_empty() { bytes.push(0); }
            bytes.extend(message.to_bytes());
        }
        bytes.extend(&garbage[4]);
        let decoded: Vec<Message> = chunked(&bytes, &cuts).into_iter().filter_map(Result::ok).collect();
        // Garbage may itself look like a message only if it carries a capital letter, a
        // clean size and a terminator in the right place; 40 random bytes cannot.
        prop_assert_eq!(decoded, messages);
    }

    #[test]
    fn any_size_field_is_handled_without_panic_or_overallocation(size in any::<u32>(), tail in prop::collection::vec(any::<u8>(), 0..64)) {
        let mut bytes = b"D0".to_vec();
        bytes.resize(COMMAND_LEN, b' ');
        bytes.extend(size.to_be_bytes());
        bytes.extend(&tail);
        match MessageCodec.decode(&bytes) {
            Ok(None) => prop_assert!(size as usize <= MAX_DATA_LEN && (size as usize) + 3 > tail.len()),
            Ok(Some((message, used))) => {
                prop_assert_eq!(message.data().len(), size as usize);
                prop_assert_eq!(used, MIN_MESSAGE_LEN + size as usize);
            }
            Err(DecodeError::DataTooLong { .. }) => prop_assert!(size as usize > MAX_DATA_LEN),
            Err(DecodeError::Terminator { .. }) => prop_assert!((size as usize) + 3 <= tail.len()),
            Err(other) => prop_assert!(false, "unexpected {other:?}"),
        }
    }

    #[test]
    fn random_bytes_never_panic_and_errors_drop_within_the_buffer(bytes in prop::collection::vec(any::<u8>(), 0..600)) {
        match MessageCodec.decode(&bytes) {
            Ok(Some((_, used))) => prop_assert!(used <= bytes.len()),
            Ok(None) => {}
            Err(error) => prop_assert!((1..=bytes.len()).contains(&error.drop_len())),
        }
    }
}
