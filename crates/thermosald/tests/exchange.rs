//! The master's side: classifying frames, timing, timeouts.

use std::time::{Duration, Instant};

use thermosald::exchange::{
    ANSWER_AFTER_RECEPTION, Answer, Classified, DEFAULT_REPLY_TIMEOUT, Exchange, ExchangeError,
    LISTEN_AFTER_MESSAGE, LineActivity, LineTiming, NotOurs, RELEASE_AFTER_ANSWER,
    earliest_next_send, wire_time,
};
use thermosald::frame::{Count, MessageNumber, Target};
use thermosald::request::{Command, Message, Read, Request, RequestError, Write};
use thermosald::tables::{Table, settings};

use crate::common::{addr, decode_one, ms};

fn read_sealing_temperature() -> Exchange {
    let read = Read::index(Table::Settings, settings::SEALING_TEMPERATURE).expect("exists");
    Exchange::new(addr(0).into(), Request::Read(read)).expect("addressed read")
}

fn write_sealing_temperature(value: f64) -> Exchange {
    let item = Table::Settings
        .item(settings::SEALING_TEMPERATURE)
        .expect("exists");
    Exchange::new(
        addr(0).into(),
        Write::value(item, value).expect("fits").into(),
    )
    .expect("addressed write")
}

#[test]
fn a_read_answer_gives_named_scaled_values() {
    let exchange = read_sealing_temperature();
    assert_eq!(exchange.query_bytes(), b"%052Q150\n");
    let Classified::Answer(Answer::Values(values)) =
        exchange.classify(&decode_one(b"%052R150180\n"))
    else {
        panic!("expected values");
    };
    let readings: Vec<String> = values
        .readings()
        .map(|r| format!("{} = {r}", r.item().name()))
        .collect();
    assert_eq!(readings, ["Set sealing temperature = 180 °C"]);
}

#[test]
fn a_whole_table_answer_gives_every_item() {
    let exchange =
        Exchange::new(addr(3).into(), Read::all(Table::Runtime).into()).expect("addressed");
    let answer = exchange.classify(&decode_one(b"%353R990000180000375029010034\n"));
    let Classified::Answer(Answer::Values(values)) = answer else {
        panic!("expected values, got {answer:?}")
    };
    assert_eq!(values.table(), Table::Runtime);
    let shown: Vec<String> = values.readings().map(|r| r.to_string()).collect();
    assert_eq!(
        shown,
        ["0", "180 °C", "0", "37.5 A", "0.29 Ω", "10 V", "340 VA"]
    );
    let temperature = Table::Runtime.find("temperature").expect("exists");
    assert_eq!(values.get(temperature).map(|r| r.value()), Some(180.0));
}

#[test]
fn a_matching_echo_confirms_a_write() {
    let exchange = write_sealing_temperature(180.0);
    assert_eq!(
        exchange.classify(&decode_one(b"%012R150180\n")),
        Classified::Answer(Answer::Echoed)
    );
}

#[test]
fn an_echo_that_differs_is_a_mismatch_carrying_both_messages() {
    let exchange = write_sealing_temperature(200.0);
    let echo = decode_one(b"%012R150180\n");
    let outcome = exchange.classify(&echo);
    assert_eq!(
        outcome,
        Classified::Mismatch(ExchangeError::EchoMismatch {
            sent: exchange.query().clone(),
            received: echo
        })
    );
    let Classified::Mismatch(error) = outcome else {
        unreachable!()
    };
    assert_eq!(
        error.to_string(),
        "echo mismatch: sent %012Q150200, the regulator echoed %012R150180"
    );
}

#[test]
fn a_command_echo_must_match_too() {
    let exchange = Exchange::new(addr(1).into(), Command::ClearFaults.into()).expect("addressed");
    assert_eq!(
        exchange.classify(&decode_one(b"%114R000000\n")),
        Classified::Answer(Answer::Echoed)
    );
    assert!(matches!(
        exchange.classify(&decode_one(b"%114R000001\n")),
        Classified::Mismatch(_)
    ));
}

#[test]
fn whole_table_write_echoes_are_compared_on_writable_items_only() {
    let values = thermosald::frame::RawValue::new(0)
        .map(|z| vec![z; 17])
        .expect("zero");
    let exchange = Exchange::new(
        addr(0).into(),
        Write::whole(Table::Service, values).expect("valid").into(),
    )
    .expect("addressed");
    // The regulator computes items 9-12 itself: its echo shows them, and that is not a mismatch.
    let mut echo = b"%018R990".to_vec();
    for i in 0..17 {
        echo.extend_from_slice(if (9..=12).contains(&i) {
            b"123"
        } else {
            b"000"
        });
    }
    echo.push(b'\n');
    assert_eq!(
        exchange.classify(&decode_one(&echo)),
        Classified::Answer(Answer::Echoed)
    );
    echo[8..11].copy_from_slice(b"001");
    assert!(matches!(
        exchange.classify(&decode_one(&echo)),
        Classified::Mismatch(ExchangeError::EchoMismatch { .. })
    ));
}

#[test]
fn frames_from_other_addresses_or_messages_or_questions_are_not_ours() {
    let exchange = read_sealing_temperature();
    assert_eq!(
        exchange.classify(&decode_one(b"%152R150180\n")),
        Classified::NotOurs(NotOurs::OtherTarget {
            expected: addr(0).into(),
            actual: addr(1).into()
        })
    );
    assert_eq!(
        exchange.classify(&decode_one(b"%053R150180\n")),
        Classified::NotOurs(NotOurs::OtherMessage {
            expected: MessageNumber::new(52).expect("valid"),
            actual: MessageNumber::new(53).expect("valid"),
        })
    );
    // The local echo of our own question from an RS-485 adapter.
    assert_eq!(
        exchange.classify(exchange.query()),
        Classified::NotOurs(NotOurs::Query {
            message: MessageNumber::new(52).expect("valid")
        })
    );
}

#[test]
fn a_read_answer_of_the_wrong_shape_is_a_mismatch() {
    let exchange = read_sealing_temperature();
    assert_eq!(
        exchange.classify(&decode_one(b"%052R990180\n")),
        Classified::Mismatch(ExchangeError::ReplyShape {
            message: Message::ReadSettings,
            expected_count: Count::item(15).expect("index"),
            actual_count: Count::All,
            expected_items: 1,
            actual_items: 1,
        })
    );
    assert!(matches!(
        exchange.classify(&decode_one(b"%052R150\n")),
        Classified::Mismatch(_)
    ));
}

#[test]
fn dollar_is_only_for_address_assignment() {
    assert_eq!(
        Exchange::new(Target::Assign, Command::ClearFaults.into()),
        Err(RequestError::AssignOnlySetsAddress {
            message: Message::ClearFaults
        })
    );
    let exchange = Exchange::new(Target::Assign, Request::SetAddress(addr(4))).expect("assignment");
    assert_eq!(exchange.query_bytes(), b"%$10Q000004\n");
    assert_eq!(
        exchange.classify(&decode_one(b"%$10R000004\n")),
        Classified::Answer(Answer::Echoed)
    );
}

#[test]
fn wire_time_is_ten_bits_per_character_at_8n1() {
    assert_eq!(wire_time(1, 9600), Duration::from_nanos(1_041_666));
    assert_eq!(wire_time(96, 9600), ms(100));
    assert_eq!(
        LineTiming::RS485_9600_8N1.wire_time(960),
        Duration::from_secs(1)
    );
    assert_eq!(
        LineTiming::new(1200, 11).expect("valid").wire_time(12),
        ms(110)
    );
    assert!(LineTiming::new(0, 10).is_err());
}

#[test]
fn the_line_is_free_40_ms_after_an_answer_or_any_message() {
    let t = Instant::now();
    let timing = LineTiming::RS485_9600_8N1;
    assert_eq!(RELEASE_AFTER_ANSWER, ms(40));
    assert_eq!(LISTEN_AFTER_MESSAGE, ms(40));
    assert_eq!(
        earliest_next_send(LineActivity::Answered { ended: t }, &timing),
        t + ms(40)
    );
    assert_eq!(
        earliest_next_send(LineActivity::Traffic { ended: t }, &timing),
        t + ms(40)
    );
}

#[test]
fn after_an_unanswered_question_the_master_waits_out_the_whole_answer_window() {
    let t = Instant::now();
    let timing = LineTiming::RS485_9600_8N1;
    // 200 ms + 12 characters (12.5 ms) + 40 ms.
    let next = earliest_next_send(
        LineActivity::Unanswered {
            ended: t,
            reply_len: 12,
        },
        &timing,
    );
    assert_eq!(
        next,
        t + ANSWER_AFTER_RECEPTION + ms(12) + Duration::from_micros(500) + ms(40)
    );
}

#[test]
fn reply_timeouts_default_to_500_ms_and_grow_on_slow_lines() {
    let read_machine =
        Exchange::new(addr(0).into(), Read::all(Table::Machine).into()).expect("addressed");
    assert_eq!(read_machine.reply_len(), 84);
    assert_eq!(
        read_machine.reply_timeout(&LineTiming::RS485_9600_8N1),
        DEFAULT_REPLY_TIMEOUT
    );
    assert_eq!(DEFAULT_REPLY_TIMEOUT, ms(500));
    let slow = LineTiming::new(1200, 10).expect("valid");
    // 9 + 84 characters at 1200 baud = 775 ms, + 200 ms + 200 ms margin.
    assert_eq!(read_machine.reply_timeout(&slow), ms(1175));
    assert_eq!(read_sealing_temperature().reply_len(), 12);
    assert_eq!(write_sealing_temperature(180.0).reply_len(), 12);
}

#[test]
fn the_theoretical_poll_limit_at_9600_8n1() {
    let timing = LineTiming::RS485_9600_8N1;
    // One item: 9-byte question, 12-byte answer: 9.375 + 200 + 12.5 + 40 = 261.875 ms.
    assert_eq!(timing.poll_cycle(9, 12), Duration::from_micros(261_875));
    assert!((timing.polls_per_second(9, 12) - 3.8186).abs() < 1e-3);
    // Whole run-time table: 30-byte answer: 9.375 + 200 + 31.25 + 40 = 280.625 ms.
    assert_eq!(timing.poll_cycle(9, 30), Duration::from_micros(280_625));
    assert!((timing.polls_per_second(9, 30) - 3.5635).abs() < 1e-3);
}
