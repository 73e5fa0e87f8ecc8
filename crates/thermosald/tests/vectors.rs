//! Byte vectors built from thermosald-isc-rs485.txt ("TRANSMISSION PROTOCOL": `%`, address
//! `$30+0`–`$30+7` or `$`, message number tens and units, `Q`/`R`, data count tens and
//! units (`99` = all data), one unused byte, 3-digit data items, `LF`), one per message.

use thermosald::frame::{Count, Direction, Frame, MessageNumber, RawValue, Target};
use thermosald::request::{Command, Message, Read, Request, RequestError, Write, describe};
use thermosald::tables::{Table, settings};

use crate::common::{addr, decode_one};

fn raw(v: u16) -> RawValue {
    RawValue::new(v).expect("three digits")
}

/// Builds `request` for `target`, checks its bytes, decodes them back, and parses the
/// request back.
fn check(request: Request, target: Target, expected: &[u8]) {
    let frame = request.to_frame(target);
    assert_eq!(
        String::from_utf8_lossy(&frame.to_bytes()),
        String::from_utf8_lossy(expected),
        "encoding of {request:?}"
    );
    assert_eq!(frame.to_bytes(), expected);
    let decoded = decode_one(expected);
    assert_eq!(decoded, frame);
    assert_eq!(Request::parse(&decoded), Ok(request));
}

// Address byte: "$30+0 - $30+7", i.e. ASCII '0'..'7'; '$' (0x24) assigns an address.
const ADDRESS_0: u8 = 0x30;
const ADDRESS_5: u8 = 0x35;

#[test]
fn address_characters_are_hex_30_plus_the_address() {
    for n in 0..=7u8 {
        assert_eq!(addr(n).to_ascii(), 0x30 + n);
    }
    assert_eq!(Target::Assign.to_ascii(), b'$');
    assert_eq!(ADDRESS_0, b'0');
}

#[test]
fn set_logic_address_3_through_dollar() {
    // % $ 1 0 Q | count 00 | unused 0 | Data0 = 003 (the new address) | LF
    let bytes = [
        b'%', b'$', b'1', b'0', b'Q', b'0', b'0', b'0', b'0', b'0', b'3', 0x0A,
    ];
    check(Request::SetAddress(addr(3)), Target::Assign, &bytes);
}

#[test]
fn write_machine_kint_gain_12_5() {
    // KINT Gain (x10) is machine item 3, [xx.x]: 12.5 travels as 125.
    let item = Table::Machine.find("KINT gain").expect("item 3");
    let request = Request::Write(Write::value(item, 12.5).expect("12.5 fits"));
    check(request, addr(0).into(), b"%011Q030125\n");
}

#[test]
fn write_settings_sealing_temperature_180() {
    let item = Table::Settings
        .item(settings::SEALING_TEMPERATURE)
        .expect("item 15");
    check(
        Request::Write(Write::value(item, 180.0).expect("fits")),
        addr(0).into(),
        b"%012Q150180\n",
    );
}

#[test]
fn write_whole_settings_table() {
    let values: Vec<RawValue> = [0, 0, 0, 0, 0, 100, 0, 0, 0, 0, 0, 250, 5, 20, 80, 180]
        .map(raw)
        .to_vec();
    let request =
        Request::Write(Write::whole(Table::Settings, values).expect("16 values in range"));
    check(
        request,
        addr(1).into(),
        b"%112Q990000000000000000100000000000000000250005020080180\n",
    );
}

#[test]
fn clear_faults_at_address_0() {
    check(
        Request::Command(Command::ClearFaults),
        addr(0).into(),
        b"%014Q000000\n",
    );
}

#[test]
fn automatic_balancing_at_address_5() {
    let bytes = [
        b'%', ADDRESS_5, b'1', b'5', b'Q', b'0', b'0', b'0', b'0', b'0', b'0', b'\n',
    ];
    check(Request::Command(Command::Balance), addr(5).into(), &bytes);
}

#[test]
fn write_data_on_eeprom() {
    check(
        Request::Command(Command::SaveEeprom),
        addr(2).into(),
        b"%216Q000000\n",
    );
}

#[test]
fn read_data_from_eeprom() {
    check(
        Request::Command(Command::LoadEeprom),
        addr(2).into(),
        b"%217Q000000\n",
    );
}

#[test]
fn write_commissioning_set_voltage_24() {
    let item = Table::Service.find("set voltage").expect("item 15");
    check(
        Request::Write(Write::value(item, 24.0).expect("fits")),
        addr(7).into(),
        b"%718Q150024\n",
    );
}

#[test]
fn read_whole_machine_data() {
    check(
        Request::Read(Read::all(Table::Machine)),
        addr(0).into(),
        b"%051Q990\n",
    );
}

#[test]
fn read_one_settings_item() {
    check(
        Request::Read(Read::index(Table::Settings, 15).expect("exists")),
        addr(0).into(),
        b"%052Q150\n",
    );
}

#[test]
fn read_whole_run_time_data() {
    check(
        Request::Read(Read::all(Table::Runtime)),
        addr(3).into(),
        b"%353Q990\n",
    );
}

#[test]
fn read_start_up_data() {
    check(
        Request::Read(Read::all(Table::Service)),
        addr(0).into(),
        b"%058Q990\n",
    );
}

#[test]
fn master_reset() {
    check(
        Request::Command(Command::MasterReset),
        addr(0).into(),
        b"%099Q000000\n",
    );
}

#[test]
fn message_13_is_refused_as_unused() {
    let thirteen = MessageNumber::new(13).expect("two digits");
    assert_eq!(
        Message::from_number(thirteen),
        Err(RequestError::UnusedMessage { number: 13 })
    );
    let frame = decode_one(b"%013Q000000\n");
    assert_eq!(
        Request::parse(&frame),
        Err(RequestError::UnusedMessage { number: 13 })
    );
}

#[test]
fn unknown_message_numbers_are_refused() {
    let frame = decode_one(b"%020Q000000\n");
    assert_eq!(
        Request::parse(&frame),
        Err(RequestError::UnknownMessage { number: 20 })
    );
}

#[test]
fn every_message_number_of_the_spec_maps_to_its_message() {
    let numbers = [10, 11, 12, 14, 15, 16, 17, 18, 51, 52, 53, 58, 99];
    for (number, message) in numbers.into_iter().zip(Message::ALL) {
        assert_eq!(message.number().get(), number);
        assert_eq!(
            Message::from_number(MessageNumber::new(number).expect("valid")),
            Ok(message)
        );
    }
}

#[test]
fn a_single_item_reply_carries_the_item_with_r() {
    // Reply to %052Q150: same address, message and count, 'R', data 180.
    let frame = decode_one(b"%052R150180\n");
    assert_eq!(frame.direction(), Direction::Reply);
    assert_eq!(frame.count(), Count::item(15).expect("index"));
    assert_eq!(frame.data(), &[raw(180)]);
}

#[test]
fn a_whole_run_time_reply_carries_seven_items() {
    let bytes = b"%053R990000180000375029010034\n";
    let frame = decode_one(bytes);
    assert_eq!(bytes.len(), 30);
    assert_eq!(frame.count(), Count::All);
    assert_eq!(
        frame.data(),
        [0, 180, 0, 375, 29, 10, 34].map(raw).as_slice()
    );
}

#[test]
fn the_echo_of_a_write_is_the_question_with_r() {
    let sent = decode_one(b"%011Q030125\n");
    let echo = decode_one(b"%011R030125\n");
    assert_eq!(sent.clone().with_direction(Direction::Reply), echo);
}

#[test]
fn any_unused_byte_is_accepted_and_zero_is_sent() {
    let frame = decode_one(b"%053Q99 \n");
    assert_eq!(frame.to_bytes(), b"%053Q990\n");
}

#[test]
fn the_longest_message_is_the_whole_machine_table() {
    let mut bytes = b"%051R990".to_vec();
    bytes.extend(std::iter::repeat_n(b'7', 75));
    bytes.push(b'\n');
    assert_eq!(bytes.len(), thermosald::frame::MAX_LEN);
    assert_eq!(decode_one(&bytes).data().len(), 25);
    let too_many = Frame::new(
        Target::Address(addr(0)),
        MessageNumber::new(51).expect("valid"),
        Direction::Reply,
        Count::All,
        vec![RawValue::ZERO; 26],
    );
    assert_eq!(
        too_many,
        Err(thermosald::frame::FrameError::TooManyItems { items: 26, max: 25 })
    );
}

#[test]
fn messages_are_described_in_words_for_annotated_dumps() {
    let said = |bytes: &[u8]| describe(&decode_one(bytes));
    assert_eq!(
        said(b"%052R150180\n"),
        "address 0, message 52 (read settings data), response, item 15: Set sealing temperature = 180 °C"
    );
    assert_eq!(
        said(b"%052Q150\n"),
        "address 0, message 52 (read settings data), question, item 15 (Set sealing temperature)"
    );
    assert_eq!(
        said(b"%011Q030125\n"),
        "address 0, message 11 (write machine data), question, item 3: KINT gain = 12.5"
    );
    assert_eq!(
        said(b"%$10Q000003\n"),
        "address assignment '$', message 10 (write logic address), question, new address 3"
    );
    assert_eq!(
        said(b"%514R000000\n"),
        "address 5, message 14 (clear faults), response"
    );
    assert_eq!(
        said(b"%053R990000035000000025000000\n"),
        "address 0, message 53 (read run-time data), response, whole table: Not used = 0; \
         Current temperature = 35 °C; Fault/warning number = 0 (ready); Maximum current = 0.0 A; \
         Resistance = 0.25 Ω; Actual voltage = 0 V; Power = 0 VA"
    );
    assert_eq!(
        said(b"%013Q000000\n"),
        "address 0, message 13 (not used), question, data 000"
    );
    assert_eq!(
        said(b"%020Q000\n"),
        "address 0, message 20 (unknown), question"
    );
    assert_eq!(
        said(b"%053Q070\n"),
        "address 0, message 53 (read run-time data), question, item 7 (beyond the runtime table)"
    );
    assert_eq!(
        said(b"%051R990001\n"),
        "address 0, message 51 (read machine data), response, whole table, 1 data item(s) where 25 belong, data 001"
    );
}
