use super::*;
use crate::cross::bits::{Flags, NamedBit};
use crate::cross::map::read_plan;
use crate::cross::state::Feed;
use crate::rtu::codec::{append_crc, decode_response};
use crate::rtu::{Addressed, Answer, ResponseAdu, check_response};
use wire::device::SharedModel;
use wire::{Codec, Device};

/// The word with exactly these bits set.
fn flags<B: NamedBit>(bits: &[B]) -> Flags<B> {
    bits.iter().copied().collect()
}

fn unit2() -> UnitId {
    UnitId::new(2).expect("unit 2")
}

fn twin() -> CrossTwin {
    CrossTwin::new(unit2(), 7)
}

/// Sends `request` bytes to the twin and decodes its answer, if any.
fn exchange(twin: &mut CrossTwin, bytes: &[u8], now: Instant) -> Option<(Duration, ResponseAdu)> {
    let input = match RequestCodec.decode(bytes) {
        Ok(Some((adu, len))) => {
            assert_eq!(len, bytes.len());
            Ok(adu)
        }
        Ok(None) => panic!("incomplete request {bytes:02X?}"),
        Err(e) => Err(e),
    };
    let mut out = twin.handle(input, now);
    assert!(out.len() <= 1);
    let tx = out.pop()?;
    let (adu, len) = decode_response(&tx.bytes)
        .expect("the twin sends valid frames")
        .expect("whole frame");
    assert_eq!(len, tx.bytes.len());
    Some((tx.delay, adu))
}

fn read_state(twin: &mut CrossTwin, now: Instant) -> CrossState {
    let mut blocks = Vec::new();
    for (start, count) in read_plan() {
        let request = Addressed::new(
            unit2(),
            Request::read_holding_registers(start, count).expect("plan"),
        );
        let (_, response) = exchange(twin, &request.to_adu().to_bytes(), now).expect("an answer");
        match check_response(&request, &response) {
            Ok(Answer::Registers(words)) => blocks.push((start, words)),
            other => panic!("read of 0x{start:02X}+{count}: {other:?}"),
        }
    }
    CrossState::from_blocks(&blocks).expect("the plan covers the map")
}

fn refusal(twin: &mut CrossTwin, frame: &[u8]) -> Option<ExceptionCode> {
    let mut bytes = frame.to_vec();
    append_crc(&mut bytes, 0);
    match exchange(twin, &bytes, Instant::now()) {
        Some((
            _,
            ResponseAdu {
                response: Response::Exception(e),
                ..
            },
        )) => {
            assert_eq!(e.function.get(), frame[1] & !EXCEPTION_BIT);
            Some(e.code)
        }
        Some((_, other)) => panic!("expected an exception, got {other:?}"),
        None => None,
    }
}

// --- Consistency of the state ---

#[test]
fn healthy_twin_feeds_the_load_from_s1_with_everything_normal() {
    let mut twin = twin();
    let state = read_state(&mut twin, Instant::now());
    let s = &state.internal;
    assert_eq!(state.feed(), Feed::StaticSwitch(Source::S1));
    assert!(state.alarms().is_empty(), "{:?}", state.alarms());
    assert!(s.s1.on.contains(S1On::Normal) && s.s2.on.contains(S2On::Normal));
    assert_eq!(s.s1_switch.on, flags(&[S1SwitchOn::LoadOnSource1]));
    assert_eq!(s.s2_switch.off, flags(&[S2SwitchOff::LoadOnSource1]));
    assert_eq!(s.load.on, flags(&[LoadOn::OutputNormal]));
    assert_eq!(s.system.on, flags(&[SystemOn::Normal]));
    assert_eq!(
        state.mimic.on,
        flags(&[
            Element::S1,
            Element::S2,
            Element::S1Switch,
            Element::Load,
            Element::System,
            Element::Is1,
            Element::Is2,
            Element::Iout
        ])
    );
    assert_eq!(
        state.mimic.off,
        flags(&[Element::S2Switch, Element::Iby1, Element::Iby2])
    );
    assert!(state.mimic.alarm.is_clear());
    let lit: Vec<u8> = state.mimic.segments.lit().map(Segment::number).collect();
    assert_eq!(lit, vec![1, 2, 3, 4, 6, 7, 9, 11, 13, 14, 15]);
    assert_eq!(state.ratings.protocol_revision, 5);
    let m = &state.measures;
    for v in m
        .s1_voltage
        .to_array()
        .into_iter()
        .chain(m.s2_voltage.to_array())
        .chain(m.output_voltage.to_array())
    {
        assert!((2270..=2330).contains(&v.raw()), "{v}");
    }
    assert!(
        (4997..=5003).contains(&m.s1_frequency.raw()),
        "{}",
        m.s1_frequency
    );
    assert_eq!(m.output_frequency, m.s1_frequency);
    // 40 kVA over three phases at 230 V: about 58 A per phase.
    for a in m.output_current.to_array() {
        assert!((540..=620).contains(&a.raw()), "{a}");
    }
    assert!(
        (390..=410).contains(&m.load_power.raw()),
        "{}",
        m.load_power
    );
}

#[test]
fn preferred_source_failure_transfers_the_load_and_every_word_follows() {
    let mut twin = twin();
    twin.fail_source(Source::S1);
    assert_eq!(twin.conducting(), Some(Source::S2));
    assert_eq!(twin.transfers(), 1);
    let state = read_state(&mut twin, Instant::now());
    let s = &state.internal;
    assert_eq!(state.feed(), Feed::StaticSwitch(Source::S2));
    assert!(state.on_reserve_line());
    assert_eq!(
        s.s1.alarm,
        flags(&[S1Alarm::Failure, S1Alarm::VoltageFault])
    );
    assert!(!s.s1.on.contains(S1On::Normal));
    assert!(s.s2.on.contains(S2On::Normal) && s.s2.alarm.is_clear());
    assert_eq!(s.s1_switch.on, Flags::empty());
    assert_eq!(s.s1_switch.off, flags(&[S1SwitchOff::LoadOnSource2]));
    assert_eq!(s.s2_switch.on, flags(&[S2SwitchOn::LoadOnSource2]));
    assert_eq!(s.s2_switch.off, Flags::empty());
    assert_eq!(
        s.load.on,
        flags(&[LoadOn::OutputNormal, LoadOn::OnReserveLine])
    );
    assert!(s.load.alarm.is_clear());
    assert!(s.system.alarm.contains(SystemAlarm::SourcesOutOfSync));
    assert!(!s.system.on.contains(SystemOn::Normal));
    let lamps = |e| state.mimic.lamps(e);
    assert_eq!(
        lamps(Element::S1),
        Lamps {
            on: false,
            off: false,
            alarm: true
        }
    );
    assert_eq!(
        lamps(Element::S1Switch),
        Lamps {
            on: false,
            off: true,
            alarm: false
        }
    );
    assert_eq!(
        lamps(Element::S2Switch),
        Lamps {
            on: true,
            off: false,
            alarm: false
        }
    );
    assert_eq!(
        lamps(Element::Load),
        Lamps {
            on: true,
            off: false,
            alarm: false
        }
    );
    assert_eq!(
        lamps(Element::System),
        Lamps {
            on: false,
            off: false,
            alarm: true
        }
    );
    let lit: Vec<u8> = state.mimic.segments.lit().map(Segment::number).collect();
    assert_eq!(lit, vec![6, 7, 8, 9, 12, 13, 14, 15]);
    let m = &state.measures;
    assert_eq!(m.s1_voltage, Phases::all(Volts::from_raw(0)));
    assert_eq!(m.s1_frequency, Hertz::from_raw(0));
    assert_eq!(m.output_frequency, m.s2_frequency);
    for (out, s2) in m
        .output_voltage
        .to_array()
        .into_iter()
        .zip(m.s2_voltage.to_array())
    {
        assert!(out <= s2 && s2.raw() - out.raw() <= 10, "{out} from {s2}");
    }
    assert!((390..=410).contains(&m.load_power.raw()));
    assert_eq!(m.phase_error, Degrees::from_raw(0));
}

#[test]
fn status_in_words_after_a_transfer_names_the_source_alarms_and_units() {
    let mut twin = twin();
    twin.fail_source(Source::S1);
    let text = read_state(&mut twin, Instant::now()).to_string();
    assert!(
        text.contains("load: supplied by source 2 (S2) through static switch S2-SW (reserve line)"),
        "{text}"
    );
    assert!(
        text.contains("alarms: S1 failure, S1 voltage fault, sources out of synchronisation"),
        "{text}"
    );
    assert!(
        text.contains("source 1  U 0.0 V, V 0.0 V, W 0.0 V, 0.00 Hz"),
        "{text}"
    );
    for unit in [
        " V,",
        " Hz",
        " A,",
        " kVA",
        "°C",
        "JBUS protocol revision 5",
    ] {
        assert!(text.contains(unit), "{unit} missing from {text}");
    }
}

#[test]
fn restored_preferred_source_takes_the_load_back() {
    let mut twin = twin();
    twin.fail_source(Source::S1);
    twin.restore_source(Source::S1);
    assert_eq!(twin.conducting(), Some(Source::S1));
    assert_eq!(twin.transfers(), 2);
    let state = read_state(&mut twin, Instant::now());
    assert_eq!(state.feed(), Feed::StaticSwitch(Source::S1));
    assert!(state.alarms().is_empty());
    assert!(!state.on_reserve_line());
}

#[test]
fn reserve_source_failure_does_not_move_the_load() {
    let mut twin = twin();
    twin.fail_source_with(Source::S2, SourceFault::FrequencyDrift);
    assert_eq!(twin.conducting(), Some(Source::S1));
    assert_eq!(twin.transfers(), 0);
    let state = read_state(&mut twin, Instant::now());
    assert_eq!(
        state.internal.s2.alarm,
        flags(&[S2Alarm::Failure, S2Alarm::FrequencyFault])
    );
    assert!((4690..=4710).contains(&state.measures.s2_frequency.raw()));
    assert_eq!(state.feed(), Feed::StaticSwitch(Source::S1));
}

#[test]
fn both_sources_lost_leaves_the_load_not_supplied() {
    let mut twin = twin();
    twin.fail_source(Source::S1);
    twin.fail_source(Source::S2);
    assert_eq!(twin.conducting(), None);
    let state = read_state(&mut twin, Instant::now());
    assert_eq!(state.feed(), Feed::NotSupplied);
    assert!(state.internal.load.alarm.contains(LoadAlarm::NotSupplied));
    assert_eq!(
        state.mimic.lamps(Element::Load),
        Lamps {
            on: false,
            off: false,
            alarm: true
        }
    );
    assert_eq!(
        state.measures.output_voltage,
        Phases::all(Volts::from_raw(0))
    );
    assert_eq!(state.measures.load_power, KiloVoltAmperes::from_raw(0));
    assert!(state.mimic.segments.lit().all(|s| s.number() != 13));
    // Source 2 comes back: the load goes to it even though S1 is preferred.
    twin.restore_source(Source::S2);
    assert_eq!(
        read_state(&mut twin, Instant::now()).feed(),
        Feed::StaticSwitch(Source::S2)
    );
}

#[test]
fn degraded_source_keeps_the_load_when_the_other_is_gone() {
    let mut twin = twin();
    twin.fail_source(Source::S2);
    twin.fail_source_with(Source::S1, SourceFault::Undervoltage);
    assert_eq!(twin.conducting(), Some(Source::S1));
    let state = read_state(&mut twin, Instant::now());
    assert_eq!(state.internal.load.on, flags(&[LoadOn::OnBadSource]));
    assert!((1760..=1830).contains(&state.measures.output_voltage.u.raw()));
}

#[test]
fn s2_preferred_twin_feeds_from_s2() {
    let mut twin = twin();
    twin.set_preferred(Source::S2);
    assert_eq!(twin.conducting(), Some(Source::S2));
    let state = read_state(&mut twin, Instant::now());
    assert_eq!(state.feed(), Feed::StaticSwitch(Source::S2));
    assert!(!state.on_reserve_line());
}

#[test]
fn opening_the_feeding_input_breaker_transfers_the_load() {
    let mut twin = twin();
    twin.set_breaker(Breaker::Is1, false);
    assert_eq!(twin.conducting(), Some(Source::S2));
    let state = read_state(&mut twin, Instant::now());
    assert!(state.internal.s1.off.contains(S1Off::BreakerOpen));
    assert!(state.internal.s1.on.contains(S1On::Normal));
    assert_eq!(
        state.mimic.lamps(Element::Is1),
        Lamps {
            on: false,
            off: true,
            alarm: false
        }
    );
    assert_eq!(
        state.mimic.lamps(Element::S1),
        Lamps {
            on: false,
            off: true,
            alarm: false
        }
    );
}

#[test]
fn open_output_breaker_disconnects_the_load() {
    let mut twin = twin();
    twin.set_breaker(Breaker::Iout, false);
    let state = read_state(&mut twin, Instant::now());
    assert_eq!(state.feed(), Feed::OutputBreakerOpen);
    assert!(state.internal.load.alarm.is_clear());
    assert_eq!(
        state.mimic.lamps(Element::Load),
        Lamps {
            on: false,
            off: true,
            alarm: false
        }
    );
    assert_eq!(
        state.measures.output_current,
        Phases::all(Amperes::from_raw(0))
    );
    assert!(
        state.measures.output_voltage.u.raw() > 2000,
        "the bus stays live"
    );
}

#[test]
fn closed_bypass_feeds_the_load_and_raises_its_alarm() {
    let mut twin = twin();
    twin.set_breaker(Breaker::Iby2, true);
    let state = read_state(&mut twin, Instant::now());
    assert_eq!(state.feed(), Feed::Bypass(Source::S2));
    assert!(
        state
            .internal
            .system
            .alarm
            .contains(SystemAlarm::BypassS2Closed)
    );
    assert!(state.on_reserve_line());
    assert!(state.mimic.segments.is_lit(Segment::new(10).expect("10")));
}

#[test]
fn overload_times_out_after_a_minute_of_device_time() {
    let mut twin = twin();
    twin.set_load(80.0);
    let start = Instant::now();
    let first = twin.reading(start);
    assert!(first.internal.load.on.contains(LoadOn::OutputOverload));
    assert!(
        first
            .internal
            .s1_switch
            .on
            .contains(S1SwitchOn::SourceOverload)
    );
    assert!(!first.internal.load.on.contains(LoadOn::OverloadTimeout));
    let later = twin.reading(start + OVERLOAD_TIMEOUT);
    assert!(later.internal.load.on.contains(LoadOn::OverloadTimeout));
    twin.set_load(10.0);
    let relieved = twin.reading(start + OVERLOAD_TIMEOUT * 2).internal.load.on;
    assert_eq!(relieved, flags(&[LoadOn::OutputNormal]));
}

#[test]
fn measures_carry_noise_that_the_seed_reproduces() {
    let now = Instant::now();
    let (mut a, mut b, mut c) = (twin(), twin(), CrossTwin::new(unit2(), 8));
    let readings_a: Vec<Measures> = (0..5).map(|_| a.reading(now).measures).collect();
    let readings_b: Vec<Measures> = (0..5).map(|_| b.reading(now).measures).collect();
    let readings_c: Vec<Measures> = (0..5).map(|_| c.reading(now).measures).collect();
    assert_eq!(readings_a, readings_b);
    assert_ne!(readings_a, readings_c);
    assert!(
        readings_a
            .windows(2)
            .any(|w| w[0].s1_voltage != w[1].s1_voltage)
    );
}

// --- Refusals, exactly as the manual says ---

#[test]
fn every_function_but_3_gets_exception_1() {
    let mut twin = twin();
    for frame in [
        vec![2, 1, 0, 0, 0, 1],
        vec![2, 2, 0, 0, 0, 1],
        vec![2, 4, 0, 0x46, 0, 1],
        vec![2, 5, 0, 0, 0xFF, 0],
        vec![2, 6, 0, 0, 0, 1],
        vec![2, 15, 0, 0, 0, 1, 1, 1],
        vec![2, 16, 0, 0, 0, 1, 2, 0, 1],
        vec![2, 7],
        vec![2, 8, 0, 0, 0xA5, 0x37],
        vec![2, 9, 0, 0, 0, 0],
        vec![2, 17],
        vec![2, 22, 0, 4, 0, 0xF2, 0, 0x25],
        vec![2, 0x2B, 0x0E, 1, 0],
    ] {
        assert_eq!(
            refusal(&mut twin, &frame),
            Some(ExceptionCode::ILLEGAL_FUNCTION),
            "function {}",
            frame[1]
        );
    }
}

#[test]
fn the_manuals_function_9_example_gets_89_01() {
    let mut twin = CrossTwin::new(UnitId::new(1).expect("1"), 0);
    let mut bytes = vec![1, 9, 0, 0, 0, 0];
    append_crc(&mut bytes, 0);
    let out = twin.handle(
        RequestCodec.decode(&bytes).map(|r| r.expect("whole").0),
        Instant::now(),
    );
    let mut expected = vec![1, 0x89, 1];
    append_crc(&mut expected, 0);
    assert_eq!(out, vec![Transmit::after(REPLY_DELAY, expected)]);
}

#[test]
fn reads_touching_undefined_addresses_get_exception_2() {
    let mut twin = twin();
    for (start, count) in [
        (0x12u16, 1u16),
        (0x13, 1),
        (0x11, 2),
        (0x10, 5),
        (0x18, 1),
        (0x1D, 1),
        (0x17, 2),
        (0x2E, 2),
        (0x2F, 1),
        (0x45, 1),
        (0x45, 2),
        (0x59, 2),
        (0x5A, 1),
        (0x81, 1),
        (0x00, 125),
        (0x1000, 10),
        (0xFFFF, 1),
    ] {
        let frame = [
            2,
            3,
            (start >> 8) as u8,
            start as u8,
            (count >> 8) as u8,
            count as u8,
        ];
        assert_eq!(
            refusal(&mut twin, &frame),
            Some(ExceptionCode::ILLEGAL_DATA_ADDRESS),
            "0x{start:02X}+{count}"
        );
    }
    // Running past 0xFFFF is an address error too.
    assert_eq!(
        refusal(&mut twin, &[2, 3, 0xFF, 0xF0, 0, 100]),
        Some(ExceptionCode::ILLEGAL_DATA_ADDRESS)
    );
}

#[test]
fn counts_of_0_or_above_125_get_exception_3() {
    let mut twin = twin();
    for count in [0u16, 126, 0x7D + 1, 1000, 0xFFFF] {
        let frame = [2, 3, 0, 0, (count >> 8) as u8, count as u8];
        assert_eq!(
            refusal(&mut twin, &frame),
            Some(ExceptionCode::ILLEGAL_DATA_VALUE),
            "count {count}"
        );
    }
    // The count is checked before the addresses.
    assert_eq!(
        refusal(&mut twin, &[2, 3, 0, 0x12, 0, 0]),
        Some(ExceptionCode::ILLEGAL_DATA_VALUE)
    );
}

#[test]
fn defined_reads_of_any_size_within_an_area_are_answered() {
    let mut twin = twin();
    for (start, count) in [
        (0x00u16, 18u16),
        (0x05, 3),
        (0x14, 4),
        (0x17, 1),
        (0x1E, 17),
        (0x2E, 1),
        (0x46, 20),
        (0x59, 1),
    ] {
        let request = Addressed::new(
            unit2(),
            Request::read_holding_registers(start, count).expect("valid"),
        );
        let (_, response) =
            exchange(&mut twin, &request.to_adu().to_bytes(), Instant::now()).expect("answer");
        assert!(
            matches!(check_response(&request, &response), Ok(Answer::Registers(w)) if w.len() == usize::from(count))
        );
    }
}

#[test]
fn bad_crc_another_unit_and_broadcast_get_silence() {
    let mut twin = twin();
    let now = Instant::now();
    let good = Addressed::new(
        unit2(),
        Request::read_holding_registers(0, 18).expect("valid"),
    )
    .to_adu()
    .to_bytes();
    let mut bad = good.clone();
    bad[7] ^= 0x01;
    assert!(
        twin.handle(RequestCodec.decode(&bad).map(|r| r.expect("whole").0), now)
            .is_empty()
    );
    let other = Addressed::new(
        UnitId::new(3).expect("3"),
        Request::read_holding_registers(0, 18).expect("valid"),
    );
    assert!(exchange(&mut twin, &other.to_adu().to_bytes(), now).is_none());
    let mut broadcast = vec![0, 3, 0, 0, 0, 18];
    append_crc(&mut broadcast, 0);
    assert!(exchange(&mut twin, &broadcast, now).is_none());
    let mut broadcast_write = vec![0, 6, 0, 0, 0, 1];
    append_crc(&mut broadcast_write, 0);
    assert!(exchange(&mut twin, &broadcast_write, now).is_none());
    // The exception bit in a request's function byte: no valid answer, silence.
    assert_eq!(refusal(&mut twin, &[2, 0x83, 0, 0]), None);
    assert!(exchange(&mut twin, &good, now).is_some());
}

#[test]
fn jbus_unit_255_is_served() {
    let unit = UnitId::jbus(255).expect("JBUS allows 255");
    let mut twin = CrossTwin::new(unit, 1);
    let request = Addressed::new(
        unit,
        Request::read_holding_registers(0x2E, 1).expect("valid"),
    );
    let (delay, response) =
        exchange(&mut twin, &request.to_adu().to_bytes(), Instant::now()).expect("answer");
    assert_eq!(delay, REPLY_DELAY);
    assert_eq!(
        check_response(&request, &response),
        Ok(Answer::Registers(vec![PROTOCOL_REVISION]))
    );
}

#[test]
fn a_shared_twin_answers_a_stream_split_anywhere() {
    let model = SharedModel::new(twin().with_reply_delay(Duration::from_millis(3)));
    let mut line = model.line();
    let request = Addressed::new(
        unit2(),
        Request::read_holding_registers(0x46, 20).expect("valid"),
    );
    let bytes = request.to_adu().to_bytes();
    let now = Instant::now();
    let mut replies = Vec::new();
    for chunk in bytes.chunks(3) {
        replies.extend(line.receive(chunk, now));
    }
    assert_eq!(replies.len(), 1);
    assert_eq!(replies[0].delay, Duration::from_millis(3));
    model.lock().fail_source(Source::S1);
    assert_eq!(model.lock().conducting(), Some(Source::S2));
}
