//! The simulated line: several regulators, silence, the 40/200/40 ms timing, and a sans-IO
//! master polling it at the theoretical limit.

use std::time::{Duration, Instant};

use thermosald::device::{BusError, Regulator, RegulatorBus, RegulatorConfig};
use thermosald::diagnostic::Fault;
use thermosald::exchange::{
    ANSWER_AFTER_RECEPTION, Answer, Classified, Exchange, LineActivity, LineTiming,
    earliest_next_send,
};
use thermosald::frame::FrameCodec;
use thermosald::request::Read;
use thermosald::tables::{Table, runtime, settings};
use wire::Deframer;
use wire::device::{Device, FaultInjector, SharedModel, Transmit};

use crate::common::{addr, ask, decode_one, ms, send};

fn line(addresses: &[u8]) -> (RegulatorBus, Instant) {
    let t0 = Instant::now();
    let addresses: Vec<_> = addresses.iter().map(|a| addr(*a)).collect();
    (
        RegulatorBus::new(&addresses, t0).expect("distinct addresses"),
        t0,
    )
}

#[test]
fn a_line_needs_distinct_addresses() {
    let t0 = Instant::now();
    assert_eq!(
        RegulatorBus::new(&[], t0).err(),
        Some(BusError::NoRegulators)
    );
    assert_eq!(
        RegulatorBus::new(&[addr(1), addr(2), addr(1)], t0).err(),
        Some(BusError::DuplicateAddress { address: addr(1) })
    );
}

#[test]
fn the_answer_leaves_200_ms_after_the_question() {
    let (mut line, t0) = line(&[0]);
    let out = send(&mut line, b"%052Q150\n", t0);
    assert_eq!(
        out,
        vec![Transmit::after(
            ANSWER_AFTER_RECEPTION,
            b"%052R150180\n".to_vec()
        )]
    );
    assert_eq!(out[0].delay, ms(200));
}

#[test]
fn a_message_within_40_ms_after_the_previous_one_is_ignored() {
    let (mut line, t0) = line(&[0]);
    // A question to an absent regulator: silence, but the others needed 40 ms to listen again.
    assert!(send(&mut line, b"%353Q990\n", t0).is_empty());
    assert!(send(&mut line, b"%053Q990\n", t0 + ms(39)).is_empty());
    // The ignored message did not restart the 40 ms.
    assert_eq!(send(&mut line, b"%053Q990\n", t0 + ms(40)).len(), 1);
}

#[test]
fn a_message_while_an_answer_is_pending_or_before_the_release_is_ignored() {
    let (mut line, t0) = line(&[0]);
    assert_eq!(send(&mut line, b"%053Q990\n", t0).len(), 1);
    assert!(
        send(&mut line, b"%053Q990\n", t0 + ms(100)).is_empty(),
        "answer pending"
    );
    assert!(
        send(&mut line, b"%053Q990\n", t0 + ms(239)).is_empty(),
        "inside the 40 ms release"
    );
    assert_eq!(line.listening_from(), Some(t0 + ms(240)));
    assert_eq!(send(&mut line, b"%053Q990\n", t0 + ms(240)).len(), 1);
}

#[test]
fn a_paced_line_counts_the_answer_on_the_wire_before_releasing() {
    let (line, t0) = line(&[0]);
    let mut line = line.paced(LineTiming::RS485_9600_8N1);
    // 12-byte answer at 9600 8N1: 12.5 ms on the wire, so free at 200 + 12.5 + 40 ms; the
    // next 9-byte question must start then, so it ends 9.375 ms later.
    assert_eq!(send(&mut line, b"%052Q150\n", t0).len(), 1);
    assert_eq!(
        line.listening_from(),
        Some(t0 + Duration::from_micros(252_500))
    );
    assert!(
        send(
            &mut line,
            b"%052Q150\n",
            t0 + Duration::from_micros(261_874)
        )
        .is_empty()
    );
    assert_eq!(
        send(
            &mut line,
            b"%052Q150\n",
            t0 + Duration::from_micros(261_875)
        )
        .len(),
        1
    );
}

#[test]
fn two_questions_back_to_back_get_one_answer() {
    let (mut line, t0) = line(&[0, 1]);
    let out = send(&mut line, b"%053Q990\n%153Q990\n", t0);
    assert_eq!(out.len(), 1);
    assert_eq!(decode_one(&out[0].bytes).target(), addr(0).into());
}

#[test]
fn noise_before_a_question_does_not_delay_it() {
    let (mut line, t0) = line(&[0]);
    assert_eq!(send(&mut line, b"\x00\xff~53Q\n%053Q990\n", t0).len(), 1);
}

#[test]
fn the_protocol_has_no_negative_answer_only_silence() {
    let (mut line, t0) = line(&[0, 1]);
    let cases: [(&str, &[u8]); 10] = [
        ("absent address", b"%553Q990\n"),
        ("malformed address", b"%953Q990\n"),
        ("data not digits", b"%012Q1501x0\n"),
        ("unknown message number", b"%020Q000000\n"),
        ("unused message 13", b"%013Q000000\n"),
        ("a response, not a question", b"%053R990\n"),
        ("'$' with a read", b"%$53Q990\n"),
        ("item beyond the table", b"%053Q070\n"),
        ("whole-table write with too few items", b"%012Q990180\n"),
        ("address assignment beyond 7", b"%$10Q000008\n"),
    ];
    let mut now = t0;
    for (why, bytes) in cases {
        assert!(
            send(&mut line, bytes, now).is_empty(),
            "{why}: expected silence"
        );
        // The line still works 40 ms later: the silence was the message's fault.
        now += ms(40);
        assert_eq!(send(&mut line, b"%152Q150\n", now).len(), 1, "after {why}");
        now += ms(240);
    }
}

#[test]
fn each_regulator_keeps_its_own_state() {
    let (mut line, t0) = line(&[0, 1, 2]);
    line.regulator_mut(addr(1))
        .expect("present")
        .provoke(Fault::OpenBand, t0 + ms(500));
    ask(&mut line, b"%212Q150150\n", t0 + ms(600));
    let mut now = t0 + ms(1000);
    let mut faults = Vec::new();
    let mut sealing = Vec::new();
    for a in 0..3u8 {
        faults.push(
            ask(&mut line, format!("%{a}53Q990\n").as_bytes(), now).data()
                [usize::from(runtime::FAULT)]
            .get(),
        );
        now += ms(300);
        sealing.push(ask(&mut line, format!("%{a}52Q150\n").as_bytes(), now).data()[0].get());
        now += ms(300);
    }
    assert_eq!(faults, [0, Fault::OpenBand.code(), 0]);
    assert_eq!(sealing, [180, 180, 150]);
}

#[test]
fn address_assignment_reaches_every_powered_regulator_and_their_echoes_overlap_into_one() {
    let t0 = Instant::now();
    let config = RegulatorConfig::default();
    let mut line = RegulatorBus::from_regulators(vec![
        Regulator::from_factory(config, t0),
        Regulator::from_factory(config, t0),
    ]);
    let out = send(&mut line, b"%$10Q000003\n", t0);
    assert_eq!(
        out,
        vec![Transmit::after(ms(200), b"%$10R000003\n".to_vec())]
    );
    assert!(
        line.regulators()
            .iter()
            .all(|r| r.address() == Some(addr(3)))
    );
}

#[test]
fn different_answers_at_once_collide_into_something_neither_sent() {
    let t0 = Instant::now();
    let config = RegulatorConfig::default();
    let mut line = RegulatorBus::from_regulators(vec![
        Regulator::new(addr(0), config, t0),
        Regulator::new(addr(0), config, t0),
    ]);
    line.regulators_mut()[1].provoke(Fault::OpenBand, t0);
    let out = send(&mut line, b"%053Q990\n", t0 + ms(500));
    assert_eq!(out.len(), 1);
    let mut one = RegulatorBus::new(&[addr(0)], t0).expect("one regulator");
    let clean = send(&mut one, b"%053Q990\n", t0 + ms(500));
    assert_ne!(out[0].bytes, clean[0].bytes);
}

#[test]
fn a_question_split_into_chunks_is_answered_when_its_last_byte_arrives() {
    let t0 = Instant::now();
    let model = SharedModel::new(RegulatorBus::new(&[addr(0)], t0).expect("one regulator"));
    let mut device = model.line();
    assert!(device.receive(b"%05", t0).is_empty());
    assert!(device.receive(b"2Q1", t0 + ms(3)).is_empty());
    let out = device.receive(b"50\n", t0 + ms(6));
    assert_eq!(
        out,
        vec![Transmit::after(ms(200), b"%052R150180\n".to_vec())]
    );
    assert_eq!(model.lock().listening_from(), Some(t0 + ms(6) + ms(240)));
}

#[test]
fn the_twin_works_behind_seeded_fault_injection() {
    let t0 = Instant::now();
    let model = SharedModel::new(RegulatorBus::new(&[addr(0)], t0).expect("one regulator"));
    let mut device = FaultInjector::new(model.line(), 42, 0.5).expect("valid rate");
    let mut answered = 0;
    for i in 0..40u32 {
        let out = device.receive(b"%053Q990\n", t0 + ms(300) * i);
        let mut deframer = Deframer::new(FrameCodec);
        for tx in out {
            deframer.push(&tx.bytes);
        }
        while let Some(input) = deframer.next_frame() {
            if input.is_ok() {
                answered += 1;
            }
        }
    }
    let injected = device.injected();
    assert!(
        answered > 0 && answered < 40,
        "{answered} answered, {injected:?}"
    );
}

/// A sans-IO master on a paced 9600-baud line: it sends each question as soon as
/// `earliest_next_send` allows, the question takes its wire time, the twin answers 200 ms
/// after its end, the answer takes its wire time. Returns polls per second of model time.
fn poll_rate(exchanges: &[Exchange], polls: u32) -> f64 {
    let timing = LineTiming::RS485_9600_8N1;
    let t0 = Instant::now();
    let mut line = RegulatorBus::new(&[addr(0), addr(1), addr(2)], t0)
        .expect("three regulators")
        .paced(timing);
    let mut send_at = t0;
    for n in 0..polls {
        let exchange = &exchanges[n as usize % exchanges.len()];
        let query = exchange.query_bytes();
        let question_end = send_at + timing.wire_time(query.len());
        let out = send(&mut line, &query, question_end);
        assert_eq!(out.len(), 1, "poll {n} was not answered");
        let answer_end = question_end + out[0].delay + timing.wire_time(out[0].bytes.len());
        let answer = decode_one(&out[0].bytes);
        assert!(matches!(
            exchange.classify(&answer),
            Classified::Answer(Answer::Values(_))
        ));
        send_at = earliest_next_send(LineActivity::Answered { ended: answer_end }, &timing);
    }
    f64::from(polls) / (send_at - t0).as_secs_f64()
}

#[test]
fn a_master_keeping_the_timing_polls_at_the_theoretical_limit_and_never_faster() {
    let timing = LineTiming::RS485_9600_8N1;
    let reads = |read: Read| -> Vec<Exchange> {
        (0..3)
            .map(|a| Exchange::new(addr(a).into(), read.into()).expect("addressed"))
            .collect()
    };
    let one_item =
        reads(Read::index(Table::Settings, settings::SEALING_TEMPERATURE).expect("exists"));
    let whole_runtime = reads(Read::all(Table::Runtime));
    let single = poll_rate(&one_item, 100);
    let table = poll_rate(&whole_runtime, 100);
    assert!(
        (single - timing.polls_per_second(9, 12)).abs() < 1e-6,
        "{single}"
    );
    assert!(
        (table - timing.polls_per_second(9, 30)).abs() < 1e-6,
        "{table}"
    );
    assert!((single - 3.8186).abs() < 1e-3 && (table - 3.5635).abs() < 1e-3);
}

#[test]
fn a_master_starting_1_ms_too_early_on_a_paced_line_is_not_heard() {
    let timing = LineTiming::RS485_9600_8N1;
    let t0 = Instant::now();
    let mut line = RegulatorBus::new(&[addr(0)], t0)
        .expect("one regulator")
        .paced(timing);
    let out = send(&mut line, b"%053Q990\n", t0);
    let answer_end = t0 + out[0].delay + timing.wire_time(out[0].bytes.len());
    let next = earliest_next_send(LineActivity::Answered { ended: answer_end }, &timing);
    // The question ends its wire time after it starts.
    let question = timing.wire_time(9);
    assert!(
        send(
            &mut line,
            b"%053Q990\n",
            next - Duration::from_millis(1) + question
        )
        .is_empty()
    );
    assert_eq!(send(&mut line, b"%053Q990\n", next + question).len(), 1);
}
