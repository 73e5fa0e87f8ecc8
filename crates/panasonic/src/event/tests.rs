use super::*;
use proptest::prelude::*;

fn parse(text: &str) -> Result<Event, EventError> {
    Event::parse(&Message::new(text).expect("valid text"))
}

#[test]
fn every_event_of_the_manual_parses_from_its_text() {
    let name = ProgramName::new("ABC").expect("valid");
    let cases = [
        ("R0CT", Event::BoardFinished { time: None }),
        (
            "R0CT0023",
            Event::BoardFinished {
                time: Some(BoardTime(23)),
            },
        ),
        ("R0EP", Event::ProductionFinished { time: None }),
        (
            "R0EP9999",
            Event::ProductionFinished {
                time: Some(BoardTime(9999)),
            },
        ),
        ("R1ST", Event::Started),
        ("R1RE", Event::ResetDone),
        ("R1RC", Event::RecoveryStarted),
        (
            "R1HB00ABC123",
            Event::Heartbeat {
                id: KeepAliveId::new("ABC123").expect("valid"),
            },
        ),
        ("R1SE", Event::Se { program: None }),
        (
            "R1SEPABC",
            Event::Se {
                program: Some(name.clone()),
            },
        ),
        (
            "R1SENG",
            Event::SeNg {
                program: None,
                error: None,
            },
        ),
        (
            "R1SENGPABC",
            Event::SeNg {
                program: Some(name.clone()),
                error: None,
            },
        ),
        (
            "R1SENGPABC            E001XY1234",
            Event::SeNg {
                program: Some(name),
                error: SeNgDetail::new("001", "XY1234"),
            },
        ),
        (
            "R2E03S012N003Z015M0T000",
            Event::Error(ErrorInfo::new(3, 12, 3, 15).expect("valid")),
        ),
        (
            "R2E03S012N003Z015M0T000000042",
            Event::Error(
                ErrorInfo::new(3, 12, 3, 15)
                    .and_then(|e| e.with_detail("000042"))
                    .expect("valid"),
            ),
        ),
        ("R3GDCT", Event::RecoveryOk),
        ("R3NGCT", Event::RecoveryRetry),
        ("R3NGEP", Event::RecoveryStop),
    ];
    for (text, event) in cases {
        assert_eq!(parse(text).as_ref(), Ok(&event), "{text}");
        assert_eq!(event.wire(), text);
    }
}

#[test]
fn parts_exhaustion_reads_as_such_in_words() {
    let Ok(Event::Error(info)) = parse("R2E03S012N003Z015M0T000") else {
        panic!("an R2 event")
    };
    assert!(info.is_parts_exhausted());
    assert_eq!(
        (
            info.step(),
            info.nozzle(),
            info.feeder(),
            info.m(),
            info.t()
        ),
        (12, 3, 15, 0, 0)
    );
    assert_eq!(
        Event::Error(info).describe(),
        "parts exhausted at step 12, nozzle 3, feeder 15: machine stopped"
    );
}

#[test]
fn malformed_and_unknown_events_say_which() {
    assert_eq!(
        parse("R0CT12"),
        Err(EventError::Malformed {
            command: "R0CT12".into(),
            kind: "R0CT"
        })
    );
    assert_eq!(
        parse("R0CTabcd"),
        Err(EventError::Malformed {
            command: "R0CTabcd".into(),
            kind: "R0CT"
        })
    );
    assert_eq!(
        parse("R1HB00AB"),
        Err(EventError::Malformed {
            command: "R1HB00AB".into(),
            kind: "R1HB"
        })
    );
    assert!(matches!(
        parse("R2E03S012N003Z015M0T00"),
        Err(EventError::Malformed { kind: "R2", .. })
    ));
    assert!(matches!(
        parse("R2E03S012N003Z015M0T000ABC"),
        Err(EventError::Malformed { kind: "R2", .. })
    ));
    assert!(matches!(
        parse("R2E03X012N003Z015M0T000"),
        Err(EventError::Malformed { kind: "R2", .. })
    ));
    assert_eq!(
        parse("R9XX"),
        Err(EventError::Unknown {
            command: "R9XX".into()
        })
    );
    let with_data = Message::with_data("R1ST", b"x".to_vec()).expect("valid");
    assert_eq!(
        Event::parse(&with_data),
        Err(EventError::UnexpectedData {
            command: "R1ST".into(),
            size: 1
        })
    );
}

#[test]
fn error_info_refuses_fields_that_do_not_fit() {
    assert_eq!(
        ErrorInfo::new(100, 0, 0, 0),
        Err(ErrorInfoError::OutOfRange {
            field: 'E',
            value: 100,
            max: 99
        })
    );
    assert_eq!(
        ErrorInfo::new(3, 1000, 0, 0),
        Err(ErrorInfoError::OutOfRange {
            field: 'S',
            value: 1000,
            max: 999
        })
    );
    assert!(matches!(
        ErrorInfo::new(3, 1, 1, 1).and_then(|e| e.with_detail("short")),
        Err(ErrorInfoError::Detail { .. })
    ));
    assert_eq!(
        BoardTime::new(10_000),
        Err(BoardTimeError {
            seconds: 10_000,
            max: 9999
        })
    );
    assert_eq!(BoardTime::saturating(123_456).seconds(), 9999);
}

pub(crate) fn arb_event() -> impl Strategy<Value = Event> {
    let name = "[!-~][ -~]{0,13}[!-~]".prop_map(|n| ProgramName::new(&n).expect("valid"));
    let time = prop::option::of((0u64..=9999).prop_map(|s| BoardTime::new(s).expect("in range")));
    prop_oneof![
        time.clone().prop_map(|time| Event::BoardFinished { time }),
        time.prop_map(|time| Event::ProductionFinished { time }),
        Just(Event::Started),
        Just(Event::ResetDone),
        Just(Event::RecoveryStarted),
        "[!-~]{6}".prop_map(|id| Event::Heartbeat {
            id: KeepAliveId::new(&id).expect("valid")
        }),
        prop::option::of(name.clone()).prop_map(|program| Event::Se { program }),
        prop::option::of((name, prop::option::of(("[0-9]{3}", "[!-~]{6}")))).prop_map(|p| {
            match p {
                None => Event::SeNg {
                    program: None,
                    error: None,
                },
                Some((program, error)) => Event::SeNg {
                    program: Some(program),
                    error: error.and_then(|(c, d)| SeNgDetail::new(&c, &d)),
                },
            }
        }),
        (
            0u8..100,
            0u16..1000,
            0u16..1000,
            0u16..1000,
            0u8..10,
            0u16..1000,
            prop::option::of("[!-~]{6}")
        )
            .prop_map(|(c, s, n, z, m, t, d)| Event::Error(
                ErrorInfo::from_parts(c, s, n, z, m, t, d.as_deref()).expect("in range")
            )),
        Just(Event::RecoveryOk),
        Just(Event::RecoveryRetry),
        Just(Event::RecoveryStop),
    ]
}

proptest! {
    #[test]
    fn events_round_trip(event in arb_event()) {
        prop_assert_eq!(Event::parse(&event.to_message()), Ok(event));
    }
}
