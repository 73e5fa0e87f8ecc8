//! Frame layer tests: the spec's byte examples as named vectors, every refusal, and
//! property tests (round trips, random split points, garbage around frames).

use proptest::prelude::*;
use wire::{Codec, Deframer, Resync};

use super::*;

const ROBOT_TO_STATION: Route = Route {
    source: Address::ROBOT,
    target: Address::STATION,
};
const STATION_TO_ROBOT: Route = Route {
    source: Address::STATION,
    target: Address::ROBOT,
};

fn code(text: &str) -> RawCode {
    text.parse().expect("three printable characters")
}

fn data(text: &str) -> Data {
    Data::from_bytes(text.as_bytes().try_into().expect("five bytes")).expect("printable")
}

fn frame(route: Option<Route>, header: Header, c: &str, d: Option<&str>) -> Frame {
    Frame {
        route,
        header,
        code: code(c),
        data: d.map(data),
    }
}

/// Asserts that `frame` encodes to exactly `bytes` and that `bytes` decode to `frame`.
fn assert_vector(frame: Frame, bytes: &[u8]) {
    assert_eq!(frame.to_bytes(), bytes, "encoding {frame}");
    assert_eq!(
        FrameCodec.decode(bytes),
        Ok(Some((frame, bytes.len()))),
        "decoding {bytes:02X?}"
    );
    assert_eq!(frame.wire_len(), bytes.len());
}

/// STX + body + ETX + the XOR of all of it, computed here independently of the codec.
fn framed(body: &[u8]) -> Vec<u8> {
    let mut out = vec![STX];
    out.extend_from_slice(body);
    out.push(ETX);
    let bcc = out.iter().fold(0u8, |acc, b| acc ^ b);
    out.push(bcc);
    out
}

// ---- spec vectors ------------------------------------------------------------------------

#[test]
fn jbc_read_air_temp_port1_with_address() {
    // "RST1" from the robot (00) to the station (01).
    assert_vector(
        frame(Some(ROBOT_TO_STATION), Header::Read, "ST1", None),
        &[
            0x02, b'0', b'0', b'0', b'1', b'R', b'S', b'T', b'1', 0x03, 0x64,
        ],
    );
}

#[test]
fn jbc_read_air_temp_port1_without_address() {
    assert_vector(
        frame(None, Header::Read, "ST1", None),
        &[0x02, b'R', b'S', b'T', b'1', 0x03, 0x65],
    );
}

#[test]
fn jbc_answer_air_temp_350_with_address() {
    // specs/README.md: `STX 01 00 A ST1 00350 ETX BCC` for a station at 01 and a robot at 00.
    assert_vector(
        frame(Some(STATION_TO_ROBOT), Header::Ack, "ST1", Some("00350")),
        b"\x020100AST100350\x03\x41",
    );
}

#[test]
fn jbc_answer_air_temp_350_without_address() {
    assert_vector(
        frame(None, Header::Ack, "ST1", Some("00350")),
        b"\x02AST100350\x03\x40",
    );
}

#[test]
fn jbc_write_air_temp_375_is_zero_padded() {
    // "in order to send 375 the data will be sent is 00375".
    assert_eq!(Data::number(375).unwrap().as_bytes(), b"00375");
    assert_vector(
        frame(Some(ROBOT_TO_STATION), Header::Write, "ST1", Some("00375")),
        b"\x020001WST100375\x03\x50",
    );
    assert_vector(
        frame(None, Header::Write, "ST1", Some("00375")),
        b"\x02WST100375\x03\x51",
    );
}

#[test]
fn jbc_write_minus_50_puts_the_sign_first() {
    // "In order to send -50, the data will be sent is -0050".
    let minus_50 = Data::number(-50).unwrap();
    assert_eq!(minus_50.as_bytes(), b"-0050");
    assert_eq!(minus_50.as_number(), Some(-50));
    assert_vector(
        frame(Some(ROBOT_TO_STATION), Header::Write, "A11", Some("-0050")),
        b"\x020001WA11-0050\x03\x3e",
    );
    assert_vector(
        frame(Some(STATION_TO_ROBOT), Header::Ack, "A11", Some("-0050")),
        b"\x020100AA11-0050\x03\x28",
    );
}

#[test]
fn jbc_data_12345_is_sent_most_significant_digit_first() {
    assert_eq!(Data::number(12345).unwrap().as_bytes(), b"12345");
}

#[test]
fn jbc_answer_station_model_is_blank_padded_jtse() {
    // 4.9.18: blanks occupy the most significant bytes, as in " JTSE".
    let model = Data::text("JTSE").unwrap();
    assert_eq!(model.as_bytes(), b" JTSE");
    assert_eq!(model.as_text(), "JTSE");
    assert_eq!(model.as_number(), None);
    assert_vector(
        frame(Some(STATION_TO_ROBOT), Header::Ack, "SMN", Some(" JTSE")),
        b"\x020100ASMN JTSE\x03\x39",
    );
}

#[test]
fn jbc_read_station_model_has_a_check_byte_equal_to_stx() {
    // The BCC of `STX 00 01 R SMN ETX` is 0x02: the scanner must take it as the check byte.
    let bytes = b"\x020001RSMN\x03\x02";
    assert_vector(
        frame(Some(ROBOT_TO_STATION), Header::Read, "SMN", None),
        bytes,
    );
    let mut deframer = Deframer::new(FrameCodec);
    deframer.push(bytes);
    deframer.push(bytes);
    assert!(matches!(deframer.next_frame(), Some(Ok(_))));
    assert!(matches!(deframer.next_frame(), Some(Ok(_))));
    assert!(deframer.next_frame().is_none());
}

#[test]
fn jbc_ack_of_a_write_carries_no_data() {
    assert_vector(
        frame(Some(STATION_TO_ROBOT), Header::Ack, "ST1", None),
        b"\x020100AST1\x03\x77",
    );
    assert_vector(frame(None, Header::Ack, "ST1", None), b"\x02AST1\x03\x76");
}

#[test]
fn jbc_nak_control_code_for_port_3_echoes_the_code() {
    // The spec's example "WST3" names a port a JTSE does not have: NAK 00004.
    assert_vector(
        frame(Some(STATION_TO_ROBOT), Header::Nak, "ST3", Some("00004")),
        b"\x020100NST300004\x03\x4e",
    );
}

#[test]
fn jbc_nak_bcc_error_carries_00001() {
    assert_vector(
        frame(Some(STATION_TO_ROBOT), Header::Nak, "ST1", Some("00001")),
        b"\x020100NST100001\x03\x49",
    );
}

#[test]
fn jbc_write_port_status_tool_on() {
    assert_vector(
        frame(Some(ROBOT_TO_STATION), Header::Write, "PS1", Some("00001")),
        b"\x020001WPS100001\x03\x54",
    );
}

/// Every control field of the later edition's command list (4.8), with the examples'
/// typo ports left out (they are refused by the station, not by the frame layer).
const COMMAND_LIST: [&str; 37] = [
    "RST1", "WST1", "RSF1", "WSF1", "RSE1", "WSE1", "RAT1", "RET1", "RWM1", "WWM1", "RPP1", "RPE1",
    "RPS1", "WPS1", "RCT1", "RA11", "WA11", "RSMN", "RMAT", "WMAT", "RMIT", "WMIT", "RMAF", "WMAF",
    "RMIF", "WMIF", "RMAE", "WMAE", "RMIE", "WMIE", "RSER", "WRST", "WRSP", "ROH1", "RWH1", "RTC1",
    "RSC1",
];

#[test]
fn jbc_every_command_of_the_list_frames_and_parses_as_a_known_code() {
    for control in COMMAND_LIST {
        let (header, c) = control.split_at(1);
        let header = Header::from_byte(header.as_bytes()[0]).expect("R or W");
        let mut body = b"0001".to_vec();
        body.extend_from_slice(control.as_bytes());
        if header == Header::Write {
            body.extend_from_slice(b"00000");
        }
        let bytes = framed(&body);
        let data = (header == Header::Write).then_some("00000");
        assert_vector(frame(Some(ROBOT_TO_STATION), header, c, data), &bytes);
        let known = crate::code::Code::from_raw(code(c)).expect("a JTSE code");
        assert_eq!(known.to_string(), c);
        match header {
            Header::Read => assert!(known.readable(), "{control}"),
            _ => assert!(known.writable(), "{control}"),
        }
    }
}

#[test]
fn jbc_spec_typo_ports_decode_as_raw_codes_but_are_not_known_codes() {
    for typo in ["RST3", "RPP3", "WST3"] {
        let mut body = b"0001".to_vec();
        body.extend_from_slice(typo.as_bytes());
        if typo.starts_with('W') {
            body.extend_from_slice(b"00350");
        }
        let (frame, _) = FrameCodec.decode(&framed(&body)).unwrap().unwrap();
        assert_eq!(crate::code::Code::from_raw(frame.code), None, "{typo}");
    }
}

// ---- refusals ----------------------------------------------------------------------------

#[test]
fn decode_rejects_frame_with_wrong_bcc() {
    let mut bytes = b"\x020001RST1\x03\x64".to_vec();
    bytes[10] = 0x65;
    let err = FrameCodec.decode(&bytes).unwrap_err();
    let head = FrameHead {
        route: Some(ROBOT_TO_STATION),
        code: code("ST1"),
    };
    assert_eq!(
        err,
        DecodeError::Bcc {
            expected: 0x64,
            actual: 0x65,
            len: 11,
            head: Some(head)
        }
    );
    assert_eq!(err.drop_len(), 11);
    assert_eq!(NakReason::from(&err), NakReason::Bcc);
    assert!(
        err.to_string().contains("0x64") && err.to_string().contains("0x65"),
        "{err}"
    );
}

#[test]
fn decode_salvages_the_code_of_a_damaged_frame_without_address() {
    let mut bytes = b"\x02WST100375\x03\x51".to_vec();
    bytes[7] = b'8'; // 00385: one digit hit on the line
    let err = FrameCodec.decode(&bytes).unwrap_err();
    assert_eq!(
        err.head(),
        Some(&FrameHead {
            route: None,
            code: code("ST1")
        })
    );
}

#[test]
fn decode_keeps_the_next_frame_when_a_check_byte_was_lost() {
    // `STX 00 01 R ST1 ETX` lost its BCC; the next frame's STX stands in for it.
    let mut stream = b"\x020001RST1\x03".to_vec();
    stream.extend_from_slice(&framed(b"0001RSF1"));
    let mut deframer = Deframer::new(FrameCodec);
    deframer.push(&stream);
    let first = deframer.next_frame().expect("an error").unwrap_err();
    assert!(
        matches!(
            first,
            DecodeError::Bcc {
                actual: STX,
                len: 10,
                ..
            }
        ),
        "{first:?}"
    );
    let second = deframer
        .next_frame()
        .expect("a frame")
        .expect("the next frame intact");
    assert_eq!(second.code, code("SF1"));
}

#[test]
fn decode_waits_for_every_prefix_of_a_frame() {
    for bytes in [&b"\x020100AST100350\x03\x41"[..], b"\x02RST1\x03\x65"] {
        for end in 0..bytes.len() {
            assert_eq!(
                FrameCodec.decode(&bytes[..end]),
                Ok(None),
                "prefix of {end} bytes"
            );
        }
    }
}

#[test]
fn decode_reports_garbage_up_to_the_next_start() {
    let mut bytes = b"xyz".to_vec();
    bytes.extend_from_slice(b"\x02RST1\x03\x65");
    assert_eq!(
        FrameCodec.decode(&bytes),
        Err(DecodeError::Garbage { len: 3 })
    );
    assert_eq!(
        FrameCodec.decode(b"\x03\x03"),
        Err(DecodeError::Garbage { len: 2 })
    );
}

#[test]
fn decode_drops_a_start_that_breaks_off() {
    assert_eq!(
        FrameCodec.decode(b"\x020001R\x02RST1\x03\x65"),
        Err(DecodeError::Unterminated { len: 6 })
    );
    let long = [b"\x02".as_slice(), &[b'0'; 20]].concat();
    assert!(matches!(
        FrameCodec.decode(&long),
        Err(DecodeError::Unterminated { .. })
    ));
}

#[test]
fn decode_rejects_frames_of_the_wrong_length() {
    // 8 bytes (a code of 4 characters) and 13 bytes (data of 6).
    let eight = framed(b"RST11");
    assert_eq!(
        FrameCodec.decode(&eight),
        Err(DecodeError::Length {
            len: 8,
            head: Some(FrameHead {
                route: None,
                code: code("ST1")
            })
        })
    );
    let thirteen = framed(b"0001RST1");
    assert!(
        FrameCodec.decode(&thirteen).is_ok(),
        "11 bytes is a valid addressed read"
    );
    let fifteen = framed(b"0001WST10035");
    let err = FrameCodec.decode(&fifteen).unwrap_err();
    assert_eq!(
        err,
        DecodeError::Length {
            len: 15,
            head: Some(FrameHead {
                route: Some(ROBOT_TO_STATION),
                code: code("ST1")
            })
        }
    );
    assert_eq!(NakReason::from(&err), NakReason::Format);
    assert_eq!(
        FrameCodec.decode(&framed(b"")),
        Err(DecodeError::Length { len: 3, head: None })
    );
}

#[test]
fn decode_rejects_an_unknown_header() {
    let bytes = framed(b"0001XST1");
    assert_eq!(
        FrameCodec.decode(&bytes),
        Err(DecodeError::Header {
            byte: b'X',
            len: 11,
            head: Some(FrameHead {
                route: Some(ROBOT_TO_STATION),
                code: code("ST1")
            })
        })
    );
}

#[test]
fn decode_rejects_address_fields_that_are_not_digits() {
    let bytes = framed(b"0A01RST1");
    let err = FrameCodec.decode(&bytes).unwrap_err();
    assert_eq!(
        err,
        DecodeError::Address {
            text: "0A01".into(),
            len: 11,
            head: Some(FrameHead {
                route: None,
                code: code("ST1")
            })
        }
    );
    assert_eq!(NakReason::from(&err), NakReason::Format);
}

#[test]
fn decode_rejects_unprintable_code_and_data_bytes() {
    assert_eq!(
        FrameCodec.decode(&framed(b"RS\x00\x01")),
        Err(DecodeError::Code { byte: 0x00, len: 7 })
    );
    let err = FrameCodec.decode(&framed(b"WST1003\x7f0")).unwrap_err();
    assert_eq!(
        err,
        DecodeError::Data {
            byte: 0x7f,
            len: 12,
            head: Some(FrameHead {
                route: None,
                code: code("ST1")
            })
        }
    );
}

#[test]
fn unknown_codes_decode_so_a_station_can_refuse_them() {
    let (f, _) = FrameCodec.decode(&framed(b"0001RXYZ")).unwrap().unwrap();
    assert_eq!(f.code.to_string(), "XYZ");
}

#[test]
fn frames_print_for_humans() {
    assert_eq!(
        frame(Some(STATION_TO_ROBOT), Header::Ack, "SMN", Some(" JTSE")).to_string(),
        "01→00 A SMN [ JTSE]"
    );
    assert_eq!(frame(None, Header::Read, "ST1", None).to_string(), "R ST1");
}

// ---- values -------------------------------------------------------------------------------

#[test]
fn addresses_parse_from_one_or_two_digits_and_print_as_two() {
    assert_eq!("1".parse::<Address>().map(Address::get), Ok(1));
    assert_eq!("01".parse::<Address>().map(Address::get), Ok(1));
    assert_eq!("99".parse::<Address>().map(Address::get), Ok(99));
    assert_eq!("7".parse::<Address>().unwrap().to_string(), "07");
    assert_eq!(
        "100".parse::<Address>(),
        Err(AddressError::OutOfRange {
            value: 100,
            max: 99
        })
    );
    assert_eq!(
        "".parse::<Address>(),
        Err(AddressError::NotANumber { text: "".into() })
    );
    assert!(matches!(
        "-1".parse::<Address>(),
        Err(AddressError::NotANumber { .. })
    ));
    assert!(matches!(
        " 1".parse::<Address>(),
        Err(AddressError::NotANumber { .. })
    ));
    assert!(matches!(
        "99999999999999999999999".parse::<Address>(),
        Err(AddressError::OutOfRange { .. })
    ));
    assert_eq!(
        Address::new(100),
        Err(AddressError::OutOfRange {
            value: 100,
            max: 99
        })
    );
    assert_eq!(Address::new(42).map(Address::to_ascii), Ok(*b"42"));
}

#[test]
fn data_numbers_cover_minus_9999_to_99999() {
    assert_eq!(Data::number(-9999).unwrap().as_bytes(), b"-9999");
    assert_eq!(Data::number(99999).unwrap().as_bytes(), b"99999");
    assert_eq!(Data::number(0).unwrap(), Data::ZERO);
    assert_eq!(
        Data::number(100_000),
        Err(FieldError::NumberOutOfRange {
            value: 100_000,
            min: -9999,
            max: 99999
        })
    );
    assert!(Data::number(-10_000).is_err());
}

#[test]
fn data_text_is_right_aligned_ascii_of_at_most_five() {
    assert_eq!(Data::text("").unwrap().as_bytes(), b"     ");
    assert_eq!(Data::text("ABCDE").unwrap().as_bytes(), b"ABCDE");
    assert!(matches!(
        Data::text("ABCDEF"),
        Err(FieldError::Length { len: 6, max: 5, .. })
    ));
    assert!(matches!(
        Data::text("é"),
        Err(FieldError::NotPrintable { .. })
    ));
    assert!(matches!(
        Data::from_bytes(*b"0\n000"),
        Err(FieldError::NotPrintable { byte: b'\n', .. })
    ));
}

#[test]
fn raw_codes_are_three_printable_characters() {
    assert!(RawCode::new(*b"ST1").is_ok());
    assert!(RawCode::new(*b"S\x03T").is_err());
    assert!(matches!(
        "ST".parse::<RawCode>(),
        Err(FieldError::Length { len: 2, .. })
    ));
}

// ---- properties ---------------------------------------------------------------------------

fn arb_address() -> impl Strategy<Value = Address> {
    (0u8..=99).prop_map(|a| Address::new(a).expect("0..=99"))
}

fn arb_route() -> impl Strategy<Value = Option<Route>> {
    proptest::option::of(
        (arb_address(), arb_address()).prop_map(|(source, target)| Route { source, target }),
    )
}

fn arb_header() -> impl Strategy<Value = Header> {
    prop_oneof![
        Just(Header::Read),
        Just(Header::Write),
        Just(Header::Ack),
        Just(Header::Nak)
    ]
}

fn printable() -> impl Strategy<Value = u8> {
    0x20u8..=0x7e
}

fn arb_data() -> impl Strategy<Value = Data> {
    prop_oneof![
        (DATA_MIN..=DATA_MAX).prop_map(|n| Data::number(n).expect("in range")),
        "[A-Z ]{0,5}".prop_map(|t| Data::text(&t).expect("ASCII, at most 5")),
        proptest::array::uniform5(printable())
            .prop_map(|b| Data::from_bytes(b).expect("printable")),
    ]
}

fn arb_frame() -> impl Strategy<Value = Frame> {
    (
        arb_route(),
        arb_header(),
        proptest::array::uniform3(printable()),
        proptest::option::of(arb_data()),
    )
        .prop_map(|(route, header, code, data)| Frame {
            route,
            header,
            code: RawCode::new(code).expect("printable"),
            data,
        })
}

/// Noise that holds no frame start (a stray STX would legitimately eat the next frame).
fn noise() -> impl Strategy<Value = Vec<u8>> {
    proptest::collection::vec(any::<u8>().prop_filter("no STX", |b| *b != STX), 0..20)
}

fn decode_all(chunks: &[&[u8]]) -> Vec<Result<Frame, DecodeError>> {
    let mut deframer = Deframer::new(FrameCodec);
    let mut out = Vec::new();
    for chunk in chunks {
        deframer.push(chunk);
        out.extend(std::iter::from_fn(|| deframer.next_frame()));
    }
    out
}

proptest! {
    #[test]
    fn every_frame_round_trips(frame in arb_frame()) {
        let bytes = frame.to_bytes();
        prop_assert_eq!(bytes.len(), frame.wire_len());
        prop_assert_eq!(FrameCodec.decode(&bytes), Ok(Some((frame, bytes.len()))));
    }

    #[test]
    fn frames_survive_noise_and_any_split(
        parts in proptest::collection::vec((noise(), arb_frame()), 1..6),
        tail in noise(),
        splits in proptest::collection::vec(any::<prop::sample::Index>(), 0..8),
    ) {
        let mut stream = Vec::new();
        let mut expected = Vec::new();
        for (garbage, frame) in &parts {
            stream.extend_from_slice(garbage);
            stream.extend_from_slice(&frame.to_bytes());
            expected.push(*frame);
        }
        stream.extend_from_slice(&tail);

        let mut cuts: Vec<usize> = splits.iter().map(|i| i.index(stream.len() + 1)).collect();
        cuts.sort_unstable();
        let mut chunks = Vec::new();
        let mut from = 0;
        for cut in cuts {
            chunks.push(&stream[from..cut]);
            from = cut;
        }
        chunks.push(&stream[from..]);

        // Runs of noise may be reported in more pieces when split; the frames never change.
        let frames = |results: Vec<Result<Frame, DecodeError>>| -> Vec<Frame> {
            results.into_iter().filter_map(Result::ok).collect()
        };
        prop_assert_eq!(frames(decode_all(&chunks)), expected.clone());
        prop_assert_eq!(frames(decode_all(&[&stream])), expected);
    }

    #[test]
    fn decoder_never_panics_and_frames_re_encode_to_their_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
        crate::fuzzing::decode(&bytes);
        match FrameCodec.decode(&bytes) {
            Ok(Some((frame, len))) => prop_assert_eq!(frame.to_bytes(), bytes[..len].to_vec()),
            Ok(None) => prop_assert!(bytes.len() < MAX_LEN),
            Err(e) => prop_assert!(e.drop_len() >= 1 && e.drop_len() <= bytes.len()),
        }
    }

    #[test]
    fn a_flipped_bit_is_never_taken_for_the_original_frame(frame in arb_frame(), at in any::<prop::sample::Index>(), bit in 0u8..8) {
        let mut bytes = frame.to_bytes();
        let i = at.index(bytes.len());
        bytes[i] ^= 1 << bit;
        let decoded = decode_all(&[&bytes]);
        prop_assert!(!decoded.contains(&Ok(frame)), "{:?}", decoded);
    }
}
