//! Property tests of the RTU layer, both directions, and of the two server models.

use std::time::Instant;

use jbus::cross::device::CrossTwin;
use jbus::cross::{self, CrossState};
use jbus::rtu::codec::append_crc;
use jbus::rtu::{
    Addressed, Answer, ByteField, DecodeError, ExceptionCode, FunctionCode, OtherFunction,
    PackedBits, RegisterValues, Request, RequestAdu, RequestCodec, RequestPdu, Response,
    ResponseAdu, ResponseCodec, UnitId, WriteCoil, WriteRegister, check_response,
};
use jbus::slave::Slave;
use proptest::prelude::*;
use wire::device::Model;
use wire::{Codec, Deframer};

// --- Strategies ---

fn unit() -> impl Strategy<Value = UnitId> {
    prop_oneof![
        (1u8..=247).prop_map(|n| UnitId::new(n).expect("1-247")),
        (248u8..=255).prop_map(|n| UnitId::jbus(n).expect("248-255 are JBUS units")),
    ]
}

/// Any valid typed request.
fn request() -> impl Strategy<Value = Request> {
    let read =
        |max: u16| (any::<u16>(), 1..=max).prop_map(move |(a, n)| (a.min(u16::MAX - (n - 1)), n));
    prop_oneof![
        read(2000).prop_map(|(a, n)| Request::read_coils(a, n).expect("in range")),
        read(2000).prop_map(|(a, n)| Request::read_discrete_inputs(a, n).expect("in range")),
        read(125).prop_map(|(a, n)| Request::read_holding_registers(a, n).expect("in range")),
        read(125).prop_map(|(a, n)| Request::read_input_registers(a, n).expect("in range")),
        (any::<u16>(), any::<bool>()).prop_map(|(a, v)| Request::write_single_coil(a, v)),
        (any::<u16>(), any::<u16>()).prop_map(|(a, v)| Request::write_single_register(a, v)),
        (any::<u16>(), prop::collection::vec(any::<bool>(), 1..=1968)).prop_map(|(a, v)| {
            let a = a.min(u16::MAX - (v.len() as u16 - 1));
            Request::write_multiple_coils(a, v).expect("in range")
        }),
        (any::<u16>(), prop::collection::vec(any::<u16>(), 1..=123)).prop_map(|(a, v)| {
            let a = a.min(u16::MAX - (v.len() as u16 - 1));
            Request::write_multiple_registers(a, v).expect("in range")
        }),
    ]
}

/// A request of another function with the standard's layout (never found by CRC scan).
fn other_function() -> impl Strategy<Value = OtherFunction> {
    let bytes = |n: usize| prop::collection::vec(any::<u8>(), n);
    prop_oneof![
        prop::sample::select(vec![7u8, 11, 12, 17])
            .prop_map(|f| OtherFunction::new(f, vec![]).expect("not framed")),
        bytes(4).prop_map(|d| OtherFunction::new(8, d).expect("8")),
        bytes(6).prop_map(|d| OtherFunction::new(22, d).expect("22")),
        bytes(2).prop_map(|d| OtherFunction::new(24, d).expect("24")),
        (
            prop::sample::select(vec![20u8, 21]),
            prop::collection::vec(any::<u8>(), 0..=255)
        )
            .prop_map(|(f, d)| {
                let mut data = vec![d.len() as u8];
                data.extend(d);
                OtherFunction::new(f, data).expect("20/21")
            }),
        (bytes(8), prop::collection::vec(any::<u8>(), 0..=255)).prop_map(|(head, d)| {
            let mut data = head;
            data.push(d.len() as u8);
            data.extend(d);
            OtherFunction::new(23, data).expect("23")
        }),
    ]
}

/// Any request frame as a server may receive it: any unit, any counts.
fn raw_request() -> impl Strategy<Value = RequestAdu> {
    let field = prop::collection::vec(any::<u8>(), 0..=255)
        .prop_map(|b| ByteField::new(b).expect("at most 255"));
    let pdu = prop_oneof![
        (any::<u16>(), any::<u16>())
            .prop_map(|(address, count)| RequestPdu::ReadCoils { address, count }),
        (any::<u16>(), any::<u16>())
            .prop_map(|(address, count)| RequestPdu::ReadDiscreteInputs { address, count }),
        (any::<u16>(), any::<u16>())
            .prop_map(|(address, count)| RequestPdu::ReadHoldingRegisters { address, count }),
        (any::<u16>(), any::<u16>())
            .prop_map(|(address, count)| RequestPdu::ReadInputRegisters { address, count }),
        (any::<u16>(), any::<u16>())
            .prop_map(|(address, value)| RequestPdu::WriteSingleCoil { address, value }),
        (any::<u16>(), any::<u16>())
            .prop_map(|(address, value)| RequestPdu::WriteSingleRegister { address, value }),
        (any::<u16>(), any::<u16>(), field.clone()).prop_map(|(address, count, data)| {
            RequestPdu::WriteMultipleCoils {
                address,
                count,
                data,
            }
        }),
        (any::<u16>(), any::<u16>(), field).prop_map(|(address, count, data)| {
            RequestPdu::WriteMultipleRegisters {
                address,
                count,
                data,
            }
        }),
        other_function().prop_map(RequestPdu::Other),
    ];
    (any::<u8>(), pdu).prop_map(|(unit, pdu)| RequestAdu { unit, pdu })
}

/// Any valid response.
fn response() -> impl Strategy<Value = Response> {
    let bits = prop::collection::vec(any::<u8>(), 1..=250)
        .prop_map(|b| PackedBits::from_bytes(b).expect("1-250"));
    let registers = prop::collection::vec(any::<u16>(), 1..=125)
        .prop_map(|v| RegisterValues::new(v).expect("1-125"));
    prop_oneof![
        bits.clone().prop_map(Response::ReadCoils),
        bits.prop_map(Response::ReadDiscreteInputs),
        registers.clone().prop_map(Response::ReadHoldingRegisters),
        registers.prop_map(Response::ReadInputRegisters),
        (any::<u16>(), any::<bool>())
            .prop_map(|(address, value)| Response::WriteSingleCoil(WriteCoil { address, value })),
        (any::<u16>(), any::<u16>()).prop_map(|(address, value)| Response::WriteSingleRegister(
            WriteRegister { address, value }
        )),
        (any::<u16>(), any::<u16>())
            .prop_map(|(address, count)| Response::WriteMultipleCoils { address, count }),
        (any::<u16>(), any::<u16>())
            .prop_map(|(address, count)| Response::WriteMultipleRegisters { address, count }),
        (0u8..=127, 1u8..=255).prop_map(|(f, c)| Response::exception(
            FunctionCode::new(f).expect("0-127"),
            ExceptionCode::new(c).expect("1-255")
        )),
    ]
}

fn response_adu() -> impl Strategy<Value = ResponseAdu> {
    (any::<u8>(), response()).prop_map(|(unit, response)| ResponseAdu { unit, response })
}

fn garbage() -> impl Strategy<Value = Vec<u8>> {
    prop::collection::vec(any::<u8>(), 0..12)
}

// --- Helpers ---

fn encode<C: Codec>(codec: &C, frame: &C::Frame) -> Vec<u8> {
    let mut out = Vec::new();
    codec.encode(frame, &mut out);
    out
}

/// Everything the deframer yields for `stream` pushed in chunks cut at `cuts`.
fn deframe<C: Codec + Clone>(
    codec: &C,
    stream: &[u8],
    cuts: &[usize],
) -> Vec<Result<C::Frame, C::Error>> {
    let mut deframer = Deframer::new(codec.clone());
    let mut out = Vec::new();
    let mut at = 0;
    let mut cuts: Vec<usize> = cuts.iter().map(|c| c % (stream.len() + 1)).collect();
    cuts.sort_unstable();
    for cut in cuts.into_iter().chain([stream.len()]) {
        deframer.push(&stream[at..cut.max(at)]);
        at = cut.max(at);
        out.extend(std::iter::from_fn(|| deframer.next_frame()));
    }
    out
}

/// Frames with garbage before, between and after, then the line carrying on.
///
/// RTU frames have no end marker: garbage that looks like the head of a long frame (a
/// byte count of 200, say) holds the decoder up until that many bytes have come, which
/// on a live line they do. The stream ends with [`LINE_GOES_ON`] zero bytes for that
/// (zeros frame nothing: function 0 is unknown, and no run of zeros has a good CRC).
fn stream_of<C: Codec>(codec: &C, frames: &[C::Frame], garbage: &[Vec<u8>]) -> Vec<u8> {
    let mut stream = garbage.first().cloned().unwrap_or_default();
    for (i, frame) in frames.iter().enumerate() {
        stream.extend(encode(codec, frame));
        stream.extend(garbage.get(i + 1).cloned().unwrap_or_default());
    }
    stream.extend([0; LINE_GOES_ON]);
    stream
}

/// Longer than the longest frame a garbage head can announce (13 + 255 bytes).
const LINE_GOES_ON: usize = 270;

/// Checks the frames come out of garbage, unless garbage happened to form a frame with a
/// good CRC (about 1 in 65536 per try), which shows as a frame that was not sent.
fn frames_survive<C: Codec>(
    decoded: Vec<Result<C::Frame, C::Error>>,
    sent: &[C::Frame],
) -> Result<(), TestCaseError>
where
    C::Frame: PartialEq + std::fmt::Debug,
{
    let frames: Vec<C::Frame> = decoded.into_iter().filter_map(Result::ok).collect();
    if frames.iter().any(|f| !sent.contains(f)) {
        return Err(TestCaseError::reject(
            "garbage formed a frame with a good CRC",
        ));
    }
    prop_assert!(
        frames.as_slice() == sent,
        "sent {:?}, decoded {:?}",
        sent,
        frames
    );
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, max_global_rejects: 10_000, ..ProptestConfig::default() })]

    #[test]
    fn every_request_round_trips_through_its_bytes(adu in raw_request()) {
        let bytes = encode(&RequestCodec, &adu);
        prop_assert_eq!(RequestCodec.decode(&bytes), Ok(Some((adu, bytes.len()))));
    }

    #[test]
    fn every_response_round_trips_through_its_bytes(adu in response_adu()) {
        let bytes = encode(&ResponseCodec, &adu);
        prop_assert_eq!(ResponseCodec.decode(&bytes), Ok(Some((adu, bytes.len()))));
    }

    #[test]
    fn typed_requests_survive_the_wire_and_the_servers_check(unit in unit(), request in request()) {
        let addressed = Addressed::new(unit, request.clone());
        let bytes = addressed.to_adu().to_bytes();
        let (adu, len) = RequestCodec.decode(&bytes).expect("valid").expect("whole");
        prop_assert_eq!(len, bytes.len());
        prop_assert_eq!(adu.unit, unit.get());
        prop_assert_eq!(adu.pdu.to_request(), Ok(request));
    }

    #[test]
    fn a_request_prefix_asks_for_more_bytes(adu in raw_request(), cut in any::<usize>()) {
        let bytes = encode(&RequestCodec, &adu);
        let cut = cut % bytes.len();
        prop_assert_eq!(RequestCodec.decode(&bytes[..cut]), Ok(None));
    }

    #[test]
    fn a_response_prefix_asks_for_more_bytes(adu in response_adu(), cut in any::<usize>()) {
        let bytes = encode(&ResponseCodec, &adu);
        let cut = cut % bytes.len();
        prop_assert_eq!(ResponseCodec.decode(&bytes[..cut]), Ok(None));
    }

    #[test]
    fn request_streams_split_anywhere_give_the_same_frames(
        frames in prop::collection::vec(raw_request(), 1..5),
        garbage in prop::collection::vec(garbage(), 6),
        cuts in prop::collection::vec(any::<usize>(), 0..12),
    ) {
        let stream = stream_of(&RequestCodec, &frames, &garbage);
        let whole = deframe(&RequestCodec, &stream, &[]);
        prop_assert_eq!(&deframe(&RequestCodec, &stream, &cuts), &whole);
        frames_survive::<RequestCodec>(whole, &frames)?;
    }

    #[test]
    fn response_streams_split_anywhere_give_the_same_frames(
        frames in prop::collection::vec(response_adu(), 1..5),
        garbage in prop::collection::vec(garbage(), 6),
        cuts in prop::collection::vec(any::<usize>(), 0..12),
    ) {
        let stream = stream_of(&ResponseCodec, &frames, &garbage);
        let whole = deframe(&ResponseCodec, &stream, &[]);
        prop_assert_eq!(&deframe(&ResponseCodec, &stream, &cuts), &whole);
        frames_survive::<ResponseCodec>(whole, &frames)?;
    }

    #[test]
    fn response_garbage_that_frames_nothing_never_costs_a_frame(
        frames in prop::collection::vec(response(), 1..5),
        units in prop::collection::vec(0x20u8..=0x7F, 5),
        garbage in prop::collection::vec(prop::collection::vec(0x20u8..=0x7F, 0..12), 6),
        cuts in prop::collection::vec(any::<usize>(), 0..12),
    ) {
        // Unit numbers and garbage from 0x20-0x7F: no such byte is a response function,
        // so garbage is dropped byte by byte without a CRC ever being tried on it.
        let frames: Vec<ResponseAdu> =
            frames.into_iter().zip(units).map(|(response, unit)| ResponseAdu { unit, response }).collect();
        let stream = stream_of(&ResponseCodec, &frames, &garbage);
        let decoded = deframe(&ResponseCodec, &stream, &cuts);
        let tried_a_crc = decoded.iter().any(|r| matches!(r, Err(DecodeError::Crc { .. })));
        prop_assert!(!tried_a_crc, "a CRC was checked on garbage");
        let got: Vec<ResponseAdu> = decoded.into_iter().filter_map(Result::ok).collect();
        prop_assert_eq!(got, frames);
    }

    #[test]
    fn a_damaged_frame_never_decodes_and_the_next_one_does(
        adu in response_adu(),
        flip in any::<usize>(),
        bit in 0u8..8,
    ) {
        let mut bytes = encode(&ResponseCodec, &adu);
        let at = flip % bytes.len();
        bytes[at] ^= 1 << bit;
        let good = encode(&ResponseCodec, &adu);
        let mut stream = bytes.clone();
        stream.extend_from_slice(&good);
        stream.extend([0; LINE_GOES_ON]);
        let frames: Vec<ResponseAdu> = deframe(&ResponseCodec, &stream, &[]).into_iter().filter_map(Result::ok).collect();
        // CRC-16 catches every single-bit error, so only the good copy can come out, unless
        // bytes of the damaged frame happen to form another frame with a good CRC that
        // swallows part of the good one (about 1 in 65536 per try: discarded).
        if frames.iter().any(|f| f != &adu) {
            return Err(TestCaseError::reject("the damaged bytes formed a frame with a good CRC"));
        }
        prop_assert_eq!(frames.len(), 1);
        prop_assert_eq!(&frames[0], &adu);
    }

    #[test]
    fn the_generic_server_answers_every_valid_request_as_check_response_expects(
        unit in unit(),
        request in request(),
    ) {
        let mut slave = Slave::all_writable(unit);
        let addressed = Addressed::new(unit, request.clone());
        let out = slave.handle(Ok(addressed.to_adu()), Instant::now());
        prop_assert_eq!(out.len(), 1);
        let (response, _) = ResponseCodec.decode(&out[0].bytes).expect("valid").expect("whole");
        let answer = check_response(&addressed, &response).expect("the answer matches");
        match request {
            Request::ReadCoils(r) | Request::ReadDiscreteInputs(r) => {
                prop_assert_eq!(answer, Answer::Bits(vec![false; usize::from(r.count().get())]));
            }
            Request::ReadHoldingRegisters(r) | Request::ReadInputRegisters(r) => {
                prop_assert_eq!(answer, Answer::Registers(vec![0; usize::from(r.count().get())]));
            }
            _ => prop_assert_eq!(answer, Answer::Written),
        }
    }

    #[test]
    fn writes_to_the_generic_server_read_back(address in any::<u16>(), values in prop::collection::vec(any::<u16>(), 1..=123)) {
        let unit = UnitId::new(1).expect("1");
        let address = address.min(u16::MAX - (values.len() as u16 - 1));
        let mut slave = Slave::all_writable(unit);
        let write = Addressed::new(unit, Request::write_multiple_registers(address, values.clone()).expect("valid"));
        slave.handle(Ok(write.to_adu()), Instant::now());
        let read = Addressed::new(unit, Request::read_holding_registers(address, values.len() as u16).expect("valid"));
        let out = slave.handle(Ok(read.to_adu()), Instant::now());
        let (response, _) = ResponseCodec.decode(&out[0].bytes).expect("valid").expect("whole");
        prop_assert_eq!(check_response(&read, &response), Ok(Answer::Registers(values)));
    }

    #[test]
    fn the_cross_twin_answers_any_read_exactly_as_the_manual_says(
        address in 0u16..0x70,
        count in 0u16..140,
        seed in any::<u64>(),
    ) {
        let unit = UnitId::new(2).expect("2");
        let mut twin = CrossTwin::new(unit, seed);
        let mut bytes = vec![2, 3];
        bytes.extend(address.to_be_bytes());
        bytes.extend(count.to_be_bytes());
        append_crc(&mut bytes, 0);
        let (adu, _) = RequestCodec.decode(&bytes).expect("valid").expect("whole");
        let out = twin.handle(Ok(adu), Instant::now());
        prop_assert_eq!(out.len(), 1);
        let (response, _) = ResponseCodec.decode(&out[0].bytes).expect("valid").expect("whole");
        let expected_refusal = if count == 0 || count > 125 {
            Some(ExceptionCode::ILLEGAL_DATA_VALUE)
        } else if !cross::block_is_defined(address, count) {
            Some(ExceptionCode::ILLEGAL_DATA_ADDRESS)
        } else {
            None
        };
        match (expected_refusal, response.response) {
            (Some(code), Response::Exception(e)) => {
                prop_assert_eq!(e.code, code);
                prop_assert_eq!(e.function, FunctionCode::READ_HOLDING_REGISTERS);
            }
            (None, Response::ReadHoldingRegisters(values)) => prop_assert_eq!(values.values().len(), usize::from(count)),
            (expected, got) => prop_assert!(false, "expected refusal {:?}, got {:?}", expected, got),
        }
    }

    #[test]
    fn the_cross_twin_state_stays_consistent_through_any_sequence_of_events(
        events in prop::collection::vec((0u8..6, any::<bool>()), 0..20),
        seed in any::<u64>(),
    ) {
        use jbus::cross::Feed;
        use jbus::cross::device::{Breaker, SourceFault};
        use jbus::cross::state::Source;
        let mut twin = CrossTwin::new(UnitId::new(1).expect("1"), seed);
        for (event, flag) in events {
            let source = if flag { Source::S1 } else { Source::S2 };
            match event {
                0 => twin.fail_source(source),
                1 => twin.restore_source(source),
                2 => twin.fail_source_with(source, SourceFault::FrequencyDrift),
                3 => twin.set_preferred(source),
                4 => twin.set_breaker(if flag { Breaker::Is1 } else { Breaker::Is2 }, !twin.is_closed(if flag { Breaker::Is1 } else { Breaker::Is2 })),
                _ => twin.restore_source(source.other()),
            }
            let state: CrossState = twin.reading(Instant::now());
            let s = &state.internal;
            // The two static switches never both conduct, and the off words mirror them.
            let on1 = s.s1_switch.on.word() & 1 != 0;
            let on2 = s.s2_switch.on.word() & 1 != 0;
            prop_assert!(!(on1 && on2));
            prop_assert_eq!(s.s2_switch.off.word() & 1 != 0, on1);
            prop_assert_eq!(s.s1_switch.off.word() & 1 != 0, on2);
            // The feed agrees with the twin, and the output follows the feeding source.
            let m = &state.measures;
            match state.feed() {
                Feed::StaticSwitch(src) => {
                    prop_assert_eq!(twin.conducting(), Some(src));
                    let f = if src == Source::S1 { m.s1_frequency } else { m.s2_frequency };
                    prop_assert_eq!(m.output_frequency, f);
                    prop_assert!(m.load_power.raw() > 0);
                }
                Feed::NotSupplied => {
                    prop_assert_eq!(twin.conducting(), None);
                    prop_assert_eq!(m.load_power.raw(), 0);
                }
                other => prop_assert!(false, "no breaker event opens IOUT or closes a bypass: {:?}", other),
            }
            // System normal exactly when no alarm is active; each element shows one lamp.
            prop_assert_eq!(s.system.on.word() & 1 != 0, state.alarms().is_empty());
            let mimic = &state.mimic;
            prop_assert_eq!(mimic.on.word() | mimic.off.word() | mimic.alarm.word(), 0x07FF);
            prop_assert_eq!(mimic.on.word() & mimic.off.word(), 0);
            prop_assert_eq!(mimic.on.word() & mimic.alarm.word(), 0);
            prop_assert_eq!(mimic.off.word() & mimic.alarm.word(), 0);
            // What a client decodes from the twin's words is what the twin computed.
            prop_assert_eq!(CrossState::from_image(&state.to_image()), state);
        }
    }
}

// --- Modbus TCP (MBAP) ---

mod tcp {
    use super::*;
    use jbus::tcp::{self, Mbap, TransactionId};

    /// Any request frame that fits an MBAP frame (a unit id and 253 PDU bytes at most).
    fn request() -> impl Strategy<Value = Mbap<RequestAdu>> {
        (any::<u16>(), raw_request())
            .prop_map(|(t, adu)| Mbap {
                transaction: TransactionId(t),
                adu,
            })
            .prop_filter("fits an MBAP frame", |frame| {
                frame.to_bytes().len() <= 6 + 254
            })
    }

    fn response() -> impl Strategy<Value = Mbap<ResponseAdu>> {
        (any::<u16>(), response_adu()).prop_map(|(t, adu)| Mbap {
            transaction: TransactionId(t),
            adu,
        })
    }

    /// Bytes of 0xFF before and between frames: a protocol id is never 0 in them, and the
    /// bytes next to a frame never make a valid length, so they frame nothing.
    fn filler() -> impl Strategy<Value = Vec<u8>> {
        (0usize..12).prop_map(|n| vec![0xFF; n])
    }

    fn stream<C: Codec>(codec: &C, frames: &[C::Frame], filler: &[Vec<u8>]) -> Vec<u8> {
        let mut stream = Vec::new();
        for (i, frame) in frames.iter().enumerate() {
            stream.extend(filler.get(i).cloned().unwrap_or_default());
            stream.extend(encode(codec, frame));
        }
        stream
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

        #[test]
        fn every_tcp_request_round_trips_through_its_bytes(frame in request()) {
            let bytes = encode(&tcp::RequestCodec, &frame);
            prop_assert_eq!(tcp::RequestCodec.decode(&bytes), Ok(Some((frame, bytes.len()))));
        }

        #[test]
        fn every_tcp_response_round_trips_through_its_bytes(frame in response()) {
            let bytes = encode(&tcp::ResponseCodec, &frame);
            prop_assert_eq!(tcp::ResponseCodec.decode(&bytes), Ok(Some((frame, bytes.len()))));
        }

        #[test]
        fn a_tcp_prefix_asks_for_more_bytes(request in request(), response in response(), cut in any::<usize>()) {
            let bytes = encode(&tcp::RequestCodec, &request);
            prop_assert_eq!(tcp::RequestCodec.decode(&bytes[..cut % bytes.len()]), Ok(None));
            let bytes = encode(&tcp::ResponseCodec, &response);
            prop_assert_eq!(tcp::ResponseCodec.decode(&bytes[..cut % bytes.len()]), Ok(None));
        }

        #[test]
        fn tcp_request_streams_split_anywhere_give_the_frames_sent(
            frames in prop::collection::vec(request(), 1..5),
            filler in prop::collection::vec(filler(), 5),
            cuts in prop::collection::vec(any::<usize>(), 0..12),
        ) {
            let stream = stream(&tcp::RequestCodec, &frames, &filler);
            let got: Vec<_> = deframe(&tcp::RequestCodec, &stream, &cuts)
                .into_iter()
                .filter_map(Result::ok)
                .collect();
            prop_assert_eq!(got, frames);
        }

        #[test]
        fn tcp_response_streams_split_anywhere_give_the_frames_sent(
            frames in prop::collection::vec(response(), 1..5),
            filler in prop::collection::vec(filler(), 5),
            cuts in prop::collection::vec(any::<usize>(), 0..12),
        ) {
            let stream = stream(&tcp::ResponseCodec, &frames, &filler);
            let got: Vec<_> = deframe(&tcp::ResponseCodec, &stream, &cuts)
                .into_iter()
                .filter_map(Result::ok)
                .collect();
            prop_assert_eq!(got, frames);
        }

        #[test]
        fn tcp_and_rtu_carry_the_same_request(unit in unit(), request in super::request(), t in any::<u16>()) {
            let adu = Addressed::new(unit, request).to_adu();
            let frame = Mbap { transaction: TransactionId(t), adu: adu.clone() };
            let bytes = frame.to_bytes();
            let rtu = adu.to_bytes();
            // The MBAP body is the RTU frame without its CRC.
            prop_assert_eq!(&bytes[6..], &rtu[..rtu.len() - 2]);
            prop_assert_eq!(usize::from(u16::from_be_bytes([bytes[4], bytes[5]])), rtu.len() - 2);
        }
    }
}
