use super::*;
use crate::frame::{Data, RawCode};

#[test]
fn every_code_round_trips_through_its_wire_characters() {
    for code in Code::all() {
        assert_eq!(Code::from_raw(code.raw()), Some(code), "{code}");
        assert_eq!(code.to_string().parse::<Code>(), Ok(code));
    }
    assert_eq!(Code::all().len(), 26);
}

#[test]
fn codes_parse_in_any_case() {
    assert_eq!("st1".parse(), Ok(Code::SelectAirTemp(Port::One)));
    assert_eq!("a11".parse(), Ok(Code::AdjustTemp(Port::One, Tool::Jt)));
    assert_eq!("A12".parse(), Ok(Code::AdjustTemp(Port::One, Tool::Te)));
    assert_eq!("Smn".parse(), Ok(Code::StationModel));
    assert_eq!("RST".parse(), Ok(Code::ResetSettings));
    assert_eq!("SER".parse(), Ok(Code::StationError));
    assert_eq!("SE1".parse(), Ok(Code::SelectExternalTemp(Port::One)));
}

#[test]
fn a_code_for_port_three_is_refused_with_a_suggestion() {
    let err = "ST3".parse::<Code>().unwrap_err();
    assert_eq!(
        err,
        CodeError::NoSuchPort {
            text: "ST3".into(),
            port: '3',
            suggestion: "ST1".into()
        }
    );
    assert!(err.to_string().contains("only port 1"), "{err}");
    for text in ["PP3", "A21"] {
        let parsed = text.parse::<Code>();
        assert!(
            matches!(parsed, Err(CodeError::NoSuchPort { .. })),
            "{text}: {parsed:?}"
        );
    }
}

#[test]
fn adjust_codes_exist_only_for_jt_and_te() {
    assert_eq!(
        "A10".parse::<Code>(),
        Err(CodeError::NoSuchTool {
            text: "A10".into(),
            tool: '0'
        })
    );
    assert!(matches!(
        "A13".parse::<Code>(),
        Err(CodeError::NoSuchTool { .. })
    ));
    assert_eq!(
        Code::AdjustTemp(Port::One, Tool::None).raw().to_string(),
        "A10"
    );
    assert_eq!(
        Code::from_raw(Code::AdjustTemp(Port::One, Tool::None).raw()),
        None
    );
}

#[test]
fn unknown_codes_name_the_text_and_list_the_known_ones() {
    let err = "XYZ".parse::<Code>().unwrap_err();
    let text = err.to_string();
    assert!(text.contains("\"XYZ\""), "{text}");
    assert!(
        text.contains("ST1") && text.contains("A12") && text.contains("SC1"),
        "{text}"
    );
    for text in ["RST1", "", "STX", "é1"] {
        let unknown = CodeError::Unknown { text: text.into() };
        assert_eq!(text.parse::<Code>(), Err(unknown), "{text:?}");
    }
}

#[test]
fn wire_codes_are_case_exact() {
    let lower = RawCode::new(*b"st1").expect("printable");
    assert_eq!(Code::from_raw(lower), None);
}

#[test]
fn access_follows_the_command_list() {
    use Code::*;
    let p = Port::One;
    for code in [
        SelectAirTemp(p),
        WorkMode(p),
        PortStatus(p),
        AdjustTemp(p, Tool::Te),
        MinExternalTemp,
    ] {
        assert!(code.readable() && code.writable(), "{code}");
    }
    for code in [
        AirTemp(p),
        ExternalTemp(p),
        PortPower(p),
        PortError(p),
        ConnectedTool(p),
    ] {
        assert!(code.readable() && !code.writable(), "{code}");
    }
    for code in [
        StationModel,
        StationError,
        PluggedHours(p),
        WorkHours(p),
        ToolCycles(p),
        SuctionCycles(p),
    ] {
        assert!(code.readable() && !code.writable(), "{code}");
    }
    for code in [ResetParameters, ResetSettings] {
        assert!(!code.readable() && code.writable(), "{code}");
    }
}

#[test]
fn units_and_words_follow_the_spec() {
    assert_eq!(Code::SelectAirTemp(Port::One).unit(), Some(Unit::Celsius));
    assert_eq!(
        Code::PortPower(Port::One).unit().map(Unit::symbol),
        Some("‰")
    );
    assert_eq!(
        Code::WorkHours(Port::One).unit().map(Unit::symbol),
        Some("h")
    );
    assert_eq!(
        Code::ToolCycles(Port::One).unit().map(Unit::symbol),
        Some("cycles")
    );
    assert_eq!(Code::PortStatus(Port::One).unit(), None);
    assert_eq!(
        Code::SelectAirTemp(Port::One).describe(),
        "selected air temperature"
    );
}

/// What the station's `text` for `code` reads as, in words.
fn shown(code: Code, text: &str) -> String {
    interpret(code, &data(text)).unwrap().to_string()
}

fn data(text: &str) -> Data {
    Data::from_bytes(text.as_bytes().try_into().expect("5 bytes")).expect("printable")
}

#[test]
fn interpret_gives_quantities_with_units() {
    let r = interpret(Code::SelectAirTemp(Port::One), &data("00350")).unwrap();
    assert_eq!(r.to_string(), "350 °C");
    assert_eq!(r.value(), Value::Number(350));
    assert_eq!(r.unit(), Some(Unit::Celsius));
    let r = interpret(Code::AdjustTemp(Port::One, Tool::Jt), &data("-0050")).unwrap();
    assert_eq!(r.to_string(), "-50 °C");
    assert_eq!(shown(Code::PortPower(Port::One), "00412"), "412 ‰");
}

#[test]
fn interpret_gives_table_values_in_words() {
    let p = Port::One;
    assert_eq!(shown(Code::ConnectedTool(p), "00001"), "JT");
    assert_eq!(shown(Code::PortError(p), "00009"), "No tool (9)");
    assert_eq!(
        shown(Code::PortStatus(p), "00001"),
        "tool on, cooling off, suction off"
    );
    assert_eq!(
        shown(Code::PortStatus(p), "00110"),
        "tool off, cooling on, suction on"
    );
    assert_eq!(
        shown(Code::WorkMode(p), "00000"),
        "Manual mode (profiles off)"
    );
    assert_eq!(shown(Code::StationError, "00004"), "Mains frequency (4)");
    let model = interpret(Code::StationModel, &data(" JTSE")).unwrap();
    assert_eq!(model.to_string(), "JTSE");
    assert_eq!(model.value(), Value::Text("JTSE".into()));
}

#[test]
fn interpret_refuses_values_outside_the_tables() {
    let p = Port::One;
    assert_eq!(
        interpret(Code::PortError(p), &data("00011")),
        Err(InterpretError::UnknownValue {
            code: Code::PortError(p),
            value: 11,
            known: "0 to 10"
        })
    );
    assert!(matches!(
        interpret(Code::PortStatus(p), &data("00002")),
        Err(InterpretError::UnknownValue { .. })
    ));
    assert!(matches!(
        interpret(Code::PortStatus(p), &data("01000")),
        Err(InterpretError::UnknownValue { .. })
    ));
    assert!(matches!(
        interpret(Code::AirTemp(p), &data(" JTSE")),
        Err(InterpretError::NotANumber { .. })
    ));
    assert_eq!(
        interpret(Code::ResetParameters, &Data::ZERO),
        Err(InterpretError::NoReading {
            code: Code::ResetParameters
        })
    );
}

#[test]
fn nak_reasons_keep_unknown_numbers_and_know_which_to_retry() {
    for n in [1, 2, 3, 4, 5, 6, 99999, 7, 42, -1] {
        assert_eq!(NakReason::from_code(n).code(), n);
    }
    assert_eq!(NakReason::from_code(7), NakReason::Other(7));
    assert!(NakReason::Bcc.is_transmission_error());
    assert!(NakReason::Format.is_transmission_error());
    for r in [
        NakReason::OutOfRange,
        NakReason::ControlCode,
        NakReason::NotInRobotMode,
        NakReason::Other(1),
    ] {
        assert!(!r.is_transmission_error(), "{r}");
    }
    assert!(NakReason::OutOfRange.to_string().ends_with("(3)"));
}

#[test]
fn port_status_digits_map_to_bits_and_back() {
    for n in [0, 1, 10, 11, 100, 101, 110, 111] {
        assert_eq!(
            PortStatus::from_number(n).map(PortStatus::to_number),
            Some(n)
        );
    }
    for n in [2, 20, 200, 1000, -1, 99999] {
        assert_eq!(PortStatus::from_number(n), None, "{n}");
    }
}

#[test]
fn tables_round_trip_their_numbers() {
    for e in ToolError::ALL {
        assert_eq!(ToolError::from_code(e.code()), Some(*e));
    }
    for e in StationError::ALL {
        assert_eq!(StationError::from_code(e.code()), Some(*e));
    }
    assert_eq!(ToolError::ALL.len(), 11);
    assert_eq!(StationError::ALL.len(), 7);
    for t in Tool::ALL {
        assert_eq!(Tool::from_number(t.number()), Some(t));
    }
}
