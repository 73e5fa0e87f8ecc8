use super::*;

#[test]
fn reads_may_end_at_the_last_address_but_not_run_past_it() {
    assert!(Request::read_holding_registers(0xFFFF, 1).is_ok());
    assert_eq!(
        Request::read_holding_registers(0xFFFF, 2),
        Err(InvalidValue::PastLastAddress {
            what: "registers",
            address: 0xFFFF,
            count: 2
        })
    );
    assert!(Request::read_coils(0xF830, 2000).is_ok());
    assert!(Request::read_coils(0xF831, 2000).is_err());
}

#[test]
fn writes_refuse_empty_and_oversized_blocks() {
    assert!(Request::write_multiple_registers(0, vec![]).is_err());
    assert!(Request::write_multiple_registers(0, vec![0; 123]).is_ok());
    assert!(Request::write_multiple_registers(0, vec![0; 124]).is_err());
    assert!(Request::write_multiple_coils(0, vec![true; 1968]).is_ok());
    assert!(Request::write_multiple_coils(0, vec![true; 1969]).is_err());
    assert!(Request::write_multiple_coils(0xFFFF, vec![true; 2]).is_err());
}

#[test]
fn bits_pack_first_coil_into_the_lowest_bit() {
    // Modbus application protocol, function 15 example: coils 20..29 = 1 0 1 1 0 0 1 1, 1 0.
    let bits = [
        true, false, true, true, false, false, true, true, true, false,
    ];
    assert_eq!(pack_bits(&bits), vec![0xCD, 0x01]);
    assert_eq!(unpack_bits(&[0xCD, 0x01], 10), bits.to_vec());
}

#[test]
fn a_server_refuses_counts_out_of_range_with_exception_3() {
    for pdu in [
        // No register.
        RequestPdu::ReadHoldingRegisters {
            address: 0,
            count: 0,
        },
        // One more than a response carries.
        RequestPdu::ReadHoldingRegisters {
            address: 0,
            count: 126,
        },
        // A coil is 0x0000 or 0xFF00.
        RequestPdu::WriteSingleCoil {
            address: 0,
            value: 0x1234,
        },
        // Two registers in three bytes.
        RequestPdu::WriteMultipleRegisters {
            address: 0,
            count: 2,
            data: ByteField::new(vec![0, 1, 0]).expect("3 bytes"),
        },
    ] {
        assert_eq!(
            pdu.to_request(),
            Err(ExceptionCode::ILLEGAL_DATA_VALUE),
            "{pdu:?}"
        );
    }
}

#[test]
fn a_server_refuses_a_block_past_0xffff_with_exception_2_and_other_functions_with_1() {
    let past = RequestPdu::ReadInputRegisters {
        address: 0xFFF0,
        count: 100,
    };
    assert_eq!(past.to_request(), Err(ExceptionCode::ILLEGAL_DATA_ADDRESS));
    let other =
        RequestPdu::Other(OtherFunction::new(9, vec![0, 0, 0, 0]).expect("9 is not framed"));
    assert_eq!(other.to_request(), Err(ExceptionCode::ILLEGAL_FUNCTION));
}

#[test]
fn other_function_refuses_the_eight_framed_codes() {
    assert!(OtherFunction::new(3, vec![]).is_err());
    assert!(OtherFunction::new(16, vec![]).is_err());
    assert!(OtherFunction::new(7, vec![]).is_ok());
    assert!(OtherFunction::new(7, vec![0; 265]).is_err());
}

#[test]
fn broadcast_frames_go_to_unit_0() {
    let adu = Broadcast(Write::SingleRegister(WriteRegister {
        address: 1,
        value: 2,
    }))
    .to_adu();
    assert!(adu.is_broadcast());
    assert_eq!(
        adu.pdu,
        RequestPdu::WriteSingleRegister {
            address: 1,
            value: 2
        }
    );
}

#[test]
fn valid_wire_requests_become_typed_requests_and_back() {
    let requests = [
        Request::read_coils(10, 13).expect("valid"),
        Request::read_discrete_inputs(0, 2000).expect("valid"),
        Request::read_holding_registers(0x0805, 6).expect("valid"),
        Request::read_input_registers(8, 1).expect("valid"),
        Request::write_single_coil(172, true),
        Request::write_single_register(1, 3),
        Request::write_multiple_coils(
            19,
            vec![
                true, false, true, true, false, false, true, true, true, false,
            ],
        )
        .expect("valid"),
        Request::write_multiple_registers(1, vec![0x000A, 0x0102]).expect("valid"),
    ];
    for request in requests {
        assert_eq!(
            request.to_pdu().to_request(),
            Ok(request.clone()),
            "{request}"
        );
    }
}
