use super::*;
use crate::rtu::{Request, UnitId};
use wire::Deframer;

use crate::test_util::{good_frames, hex};

fn one_request(bytes: &[u8]) -> RequestAdu {
    match decode_request(bytes) {
        Ok(Some((adu, len))) if len == bytes.len() => adu,
        other => panic!("expected one whole request in {bytes:02X?}, got {other:?}"),
    }
}

fn one_response(bytes: &[u8]) -> ResponseAdu {
    match decode_response(bytes) {
        Ok(Some((adu, len))) if len == bytes.len() => adu,
        other => panic!("expected one whole response in {bytes:02X?}, got {other:?}"),
    }
}

// --- The CROSS manual's byte examples (chloride-cross-jbus.txt) ---

#[test]
fn cross_crc_example_frame_0207_gives_crc_4112_sent_41_12() {
    let mut frame = vec![0x02, 0x07];
    append_crc(&mut frame, 0);
    assert_eq!(frame, hex("02 07 41 12"));
    assert!(crc_is_good(&frame));
}

#[test]
fn standard_crc_check_value_of_123456789_is_4b37() {
    assert_eq!(wire::checksum::crc16_modbus(b"123456789"), 0x4B37);
    let mut frame = b"123456789".to_vec();
    append_crc(&mut frame, 0);
    assert_eq!(frame[9..], [0x37, 0x4B]);
}

#[test]
fn cross_example_read_words_0805_to_080a_of_slave_2() {
    // "Reading of words from 805 to 80A of slave n° 2. Request: 2 3 0805 6 CRC 16".
    let request = Addressed::new(
        UnitId::new(2).expect("unit 2"),
        Request::read_holding_registers(0x0805, 6).expect("6 words"),
    );
    let bytes = request.to_adu().to_bytes();
    assert_eq!(bytes[..6], hex("02 03 08 05 00 06"));
    assert!(crc_is_good(&bytes));
    assert_eq!(one_request(&bytes), request.to_adu());
    // "Response: 2 3 0C XXX ..... YYY CRC 16": 12 bytes, six words.
    let values = vec![0x0805, 0x0806, 0x0807, 0x0808, 0x0809, 0x080A];
    let response = ResponseAdu {
        unit: 2,
        response: Response::ReadHoldingRegisters(
            RegisterValues::new(values.clone()).expect("6 values"),
        ),
    };
    let bytes = response.to_bytes();
    assert_eq!(bytes[..3], hex("02 03 0C"));
    assert_eq!(bytes.len(), 3 + 12 + 2);
    assert_eq!(one_response(&bytes), response);
}

#[test]
fn cross_example_function_9_request_decodes_as_another_function() {
    // "Request: 1 9 0 0 0 0 CRC 16": a function the slave does not have.
    let mut bytes = hex("01 09 00 00 00 00");
    append_crc(&mut bytes, 0);
    let adu = one_request(&bytes);
    assert_eq!(adu.unit, 1);
    assert_eq!(adu.pdu.function_byte(), 9);
    assert_eq!(
        adu.pdu,
        RequestPdu::Other(OtherFunction::new(9, vec![0; 4]).expect("9 is not framed"))
    );
    assert_eq!(adu.to_bytes(), bytes);
}

#[test]
fn cross_example_exception_response_89_01() {
    // "Response: 1 89H 1 CRC 16": function 9 refused with exception 1.
    let mut bytes = hex("01 89 01");
    append_crc(&mut bytes, 0);
    let adu = one_response(&bytes);
    assert_eq!(
        adu,
        ResponseAdu {
            unit: 1,
            response: Response::exception(
                FunctionCode::new(9).expect("9"),
                ExceptionCode::ILLEGAL_FUNCTION
            )
        }
    );
    assert_eq!(adu.to_bytes(), bytes);
}

// --- Standard Modbus vectors with their CRCs (Modbus over serial line guide) ---

#[test]
fn read_holding_registers_request_01_03_0000_000a_has_crc_c5_cd() {
    let bytes = hex("01 03 00 00 00 0A C5 CD");
    assert_eq!(
        one_request(&bytes),
        RequestAdu {
            unit: 1,
            pdu: RequestPdu::ReadHoldingRegisters {
                address: 0,
                count: 10
            }
        }
    );
}

#[test]
fn read_coils_request_11_01_0013_0025_has_crc_0e_84() {
    let bytes = hex("11 01 00 13 00 25 0E 84");
    assert_eq!(
        one_request(&bytes),
        RequestAdu {
            unit: 17,
            pdu: RequestPdu::ReadCoils {
                address: 0x13,
                count: 0x25
            }
        }
    );
}

#[test]
fn write_single_coil_request_and_echo_round_trip() {
    let bytes = hex("11 05 00 AC FF 00 4E 8B");
    assert_eq!(
        one_request(&bytes),
        RequestAdu {
            unit: 17,
            pdu: RequestPdu::WriteSingleCoil {
                address: 0xAC,
                value: 0xFF00
            }
        }
    );
    let echo = one_response(&bytes);
    assert_eq!(
        echo.response,
        Response::WriteSingleCoil(crate::rtu::WriteCoil {
            address: 0xAC,
            value: true
        })
    );
}

// --- Framing behaviour ---

#[test]
fn decoders_wait_for_every_byte_of_a_frame() {
    let request = hex("11 01 00 13 00 25 0E 84");
    for cut in 0..request.len() {
        assert_eq!(decode_request(&request[..cut]), Ok(None), "cut at {cut}");
    }
    let response = ResponseAdu {
        unit: 3,
        response: Response::ReadInputRegisters(RegisterValues::new(vec![1, 2, 3]).expect("3")),
    }
    .to_bytes();
    for cut in 0..response.len() {
        assert_eq!(decode_response(&response[..cut]), Ok(None), "cut at {cut}");
    }
}

#[test]
fn decode_rejects_frame_with_wrong_crc_and_drops_one_byte() {
    let bytes = hex("01 03 00 00 00 0A C5 CE");
    let err = decode_request(&bytes).expect_err("bad CRC");
    assert_eq!(
        err,
        DecodeError::Crc {
            unit: 1,
            function: 3,
            len: 8,
            expected: 0xCDC5,
            actual: 0xCEC5
        }
    );
    assert_eq!(err.drop_len(), 1);
}

#[test]
fn response_decoder_drops_one_byte_of_an_unknown_function() {
    let err = decode_response(&hex("01 07 00")).expect_err("unknown");
    assert_eq!(
        err,
        DecodeError::UnknownFunction {
            unit: 1,
            function: 7
        }
    );
    assert_eq!(err.drop_len(), 1);
}

#[test]
fn request_decoder_gives_up_on_an_unknown_function_after_8_bytes_without_a_good_crc() {
    let bytes = hex("01 09 00 00 00 00 00 00");
    assert_eq!(decode_request(&bytes[..7]), Ok(None));
    assert_eq!(
        decode_request(&bytes),
        Err(DecodeError::UnknownFunction {
            unit: 1,
            function: 9
        })
    );
}

#[test]
fn request_decoder_frames_the_standard_layout_of_unserved_functions() {
    // Function 22, mask write register: 10 bytes.
    let mut bytes = hex("01 16 00 04 00 F2 00 25");
    append_crc(&mut bytes, 0);
    let adu = one_request(&bytes);
    assert_eq!(adu.pdu.to_request(), Err(ExceptionCode::ILLEGAL_FUNCTION));
    // Function 23 with 4 bytes to write: 13 + 4 bytes.
    let mut bytes = hex("01 17 00 03 00 06 00 0E 00 02 04 00 FF 00 FF");
    append_crc(&mut bytes, 0);
    assert_eq!(one_request(&bytes).pdu.function_byte(), 23);
}

#[test]
fn response_with_a_good_crc_but_odd_register_byte_count_is_dropped_whole() {
    let mut bytes = hex("01 03 03 00 01 02");
    append_crc(&mut bytes, 0);
    let err = decode_response(&bytes).expect_err("odd byte count");
    assert!(matches!(
        err,
        DecodeError::Malformed {
            len: 8,
            problem: Malformed::ByteCount { byte_count: 3, .. },
            ..
        }
    ));
    assert_eq!(err.drop_len(), 8);
}

#[test]
fn response_with_zero_bytes_of_registers_is_malformed() {
    let mut bytes = hex("01 04 00");
    append_crc(&mut bytes, 0);
    assert!(matches!(
        decode_response(&bytes),
        Err(DecodeError::Malformed { .. })
    ));
}

#[test]
fn exception_response_with_code_0_is_malformed() {
    let mut bytes = hex("01 83 00");
    append_crc(&mut bytes, 0);
    assert!(matches!(
        decode_response(&bytes),
        Err(DecodeError::Malformed {
            problem: Malformed::ExceptionCodeZero,
            ..
        })
    ));
}

#[test]
fn write_coil_echo_with_a_bad_value_is_malformed() {
    let mut bytes = hex("01 05 00 01 12 34");
    append_crc(&mut bytes, 0);
    assert!(matches!(
        decode_response(&bytes),
        Err(DecodeError::Malformed {
            problem: Malformed::CoilValue { value: 0x1234 },
            ..
        })
    ));
}

#[test]
fn server_decoder_keeps_counts_a_client_could_not_send() {
    let mut bytes = hex("01 03 00 00 00 00");
    append_crc(&mut bytes, 0);
    let adu = one_request(&bytes);
    assert_eq!(
        adu.pdu,
        RequestPdu::ReadHoldingRegisters {
            address: 0,
            count: 0
        }
    );
    assert_eq!(adu.pdu.to_request(), Err(ExceptionCode::ILLEGAL_DATA_VALUE));
}

#[test]
fn deframer_finds_frames_after_garbage_and_a_damaged_frame() {
    let good = hex("01 03 00 00 00 0A C5 CD");
    let mut stream = hex("FF 00 13");
    stream.extend_from_slice(&hex("01 03 00 00 00 0A C5 CE"));
    stream.extend_from_slice(&good);
    assert_eq!(good_frames(RequestCodec, &stream), vec![one_request(&good)]);
}

#[test]
fn find_frame_looks_past_a_garbage_head_that_holds_the_decoder_up() {
    // `07 03 FA`: a read-response head announcing 250 bytes.
    let mut buf = hex("07 03 FA");
    let good = ResponseAdu {
        unit: 7,
        response: Response::ReadHoldingRegisters(RegisterValues::new(vec![42]).expect("1")),
    };
    buf.extend(good.to_bytes());
    assert_eq!(decode_response(&buf), Ok(None), "held up by the head");
    let (offset, frame, len) = find_frame(&ResponseCodec, &buf).expect("found");
    assert_eq!((offset, len), (3, 7));
    assert_eq!(frame, good);
    assert_eq!(find_frame(&ResponseCodec, &hex("01 02 03")), None);
}

#[test]
fn sniffing_a_capture_tells_requests_from_responses() {
    let unit = UnitId::new(1).expect("1");
    let read = Addressed::new(unit, Request::read_holding_registers(0, 2).expect("valid")).to_adu();
    let registers = ResponseAdu {
        unit: 1,
        response: Response::ReadHoldingRegisters(RegisterValues::new(vec![5, 6]).expect("2")),
    };
    let write = Addressed::new(
        unit,
        Request::write_multiple_registers(4, vec![1, 2, 3]).expect("valid"),
    )
    .to_adu();
    let written = ResponseAdu {
        unit: 1,
        response: Response::WriteMultipleRegisters {
            address: 4,
            count: 3,
        },
    };
    let single = Addressed::new(unit, Request::write_single_register(9, 9)).to_adu();
    let refused = ResponseAdu {
        unit: 1,
        response: Response::exception(
            FunctionCode::READ_COILS,
            ExceptionCode::ILLEGAL_DATA_ADDRESS,
        ),
    };
    let mut capture = Vec::new();
    for bytes in [
        read.to_bytes(),
        registers.to_bytes(),
        write.to_bytes(),
        written.to_bytes(),
        single.to_bytes(),
        single.to_bytes(),
        refused.to_bytes(),
    ] {
        capture.extend(bytes);
    }
    let mut deframer = Deframer::new(SniffCodec);
    deframer.push(&capture);
    let frames: Vec<Sniffed> = std::iter::from_fn(|| deframer.next_frame())
        .map(|f| f.expect("clean capture"))
        .collect();
    let echo = Sniffed::Either {
        request: single.clone(),
        response: ResponseAdu {
            unit: 1,
            response: Response::WriteSingleRegister(crate::rtu::WriteRegister {
                address: 9,
                value: 9,
            }),
        },
    };
    assert_eq!(
        frames,
        vec![
            Sniffed::Request(read),
            Sniffed::Response(registers),
            Sniffed::Request(write),
            Sniffed::Response(written),
            echo.clone(),
            echo,
            Sniffed::Response(refused),
        ]
    );
}

use crate::rtu::Addressed;
