use super::*;
use crate::program::ProgramName;
use proptest::prelude::*;

fn parse(text: &str) -> Result<Command, CommandError> {
    Command::parse(&Message::new(text).expect("valid command text"))
}

fn name(text: &str) -> ProgramName {
    ProgramName::new(text).expect("valid name")
}

#[test]
fn download_example_c0p123456789abc_carries_the_unpadded_name() {
    // 3.3-2: "C0P123456789ABC".
    let data = b"%HEADER\r\nNAME=123456789ABC\r\n*\r\n".to_vec();
    let message = Message::with_data("C0P123456789ABC", data.clone()).expect("valid");
    let command = Command::parse(&message).expect("a download");
    assert_eq!(
        command,
        Command::Download {
            target: Target::Product(name("123456789ABC")),
            data
        }
    );
    assert_eq!(command.to_message(), Ok(message));
}

#[test]
fn machine_data_download_is_c0g() {
    let message = Message::with_data(
        "C0G",
        b"&CONDITIONDATA1\r\n1010001,1,1,0,0\r\n*\r\n".to_vec(),
    )
    .expect("valid");
    assert!(matches!(
        Command::parse(&message),
        Ok(Command::Download {
            target: Target::MachineData,
            ..
        })
    ));
}

#[test]
fn every_command_of_the_manual_parses_from_its_text() {
    let cases = [
        (
            "C0RPABC",
            Command::Delete {
                target: Target::Product(name("ABC")),
            },
        ),
        (
            "C1PABC",
            Command::Upload {
                target: Target::Product(name("ABC")),
            },
        ),
        (
            "C1L",
            Command::Upload {
                target: Target::PartLibrary,
            },
        ),
        (
            "C1M000",
            Command::Production(ProductionRequest {
                scope: ProductionScope::GrandTotal,
                clear: false,
            }),
        ),
        (
            "C1M900",
            Command::Production(ProductionRequest {
                scope: ProductionScope::GrandTotal,
                clear: true,
            }),
        ),
        (
            "C1M000P",
            Command::Production(ProductionRequest {
                scope: ProductionScope::CurrentTotal,
                clear: false,
            }),
        ),
        (
            "C1M900P",
            Command::Production(ProductionRequest {
                scope: ProductionScope::CurrentTotal,
                clear: true,
            }),
        ),
        (
            "C1N900",
            Command::Production(ProductionRequest {
                scope: ProductionScope::Nozzle,
                clear: true,
            }),
        ),
        (
            "C1Z000",
            Command::Production(ProductionRequest {
                scope: ProductionScope::Feeder,
                clear: false,
            }),
        ),
        ("C1RP", Command::ProgramList),
        ("C2ST", Command::Status),
        (
            "C2HB00ABC123",
            Command::KeepAlive(KeepAliveId::new("ABC123").expect("valid id")),
        ),
        ("C3P", Command::CurrentProgram),
        ("C5ST", Command::Start(None)),
        ("C5STBL", Command::Start(Some(StopMode::OneBlock))),
        ("C5STEP", Command::Start(Some(StopMode::EndOfProgram))),
        ("C5STCT", Command::Start(Some(StopMode::Continuous))),
        ("C5RE", Command::Reset),
    ];
    for (text, command) in cases {
        assert_eq!(parse(text).as_ref(), Ok(&command), "{text}");
        assert_eq!(command.wire(), text);
    }
}

#[test]
fn a_bare_c3_is_read_as_c3p() {
    assert_eq!(parse("C3"), Ok(Command::CurrentProgram));
}

#[test]
fn unknown_and_malformed_commands_say_why_and_pick_their_refusal() {
    assert_eq!(
        parse("C9XX"),
        Err(CommandError::Unknown {
            command: "C9XX".into()
        })
    );
    assert_eq!(
        parse("C5SP"),
        Err(CommandError::Unknown {
            command: "C5SP".into()
        })
    );
    assert_eq!(
        parse("C5HB00ABC123"),
        Err(CommandError::Unknown {
            command: "C5HB00ABC123".into()
        })
    );
    assert_eq!(
        parse("C1M123"),
        Err(CommandError::Unknown {
            command: "C1M123".into()
        })
    );
    assert_eq!(
        parse("C3L"),
        Err(CommandError::Unknown {
            command: "C3L".into()
        })
    );
    assert!(matches!(parse("C1X"), Err(CommandError::Target { .. })));
    assert!(matches!(
        parse("C0P0123456789ABCDEF"),
        Err(CommandError::Target { .. })
    ));
    for bad in ["C2HB", "C2HB01ABC123", "C2HB00ABC12", "C2HB00ABC1234"] {
        let error = parse(bad).expect_err(bad);
        assert_eq!(
            error,
            CommandError::KeepAlive {
                command: bad.into()
            }
        );
        assert_eq!(
            error.refusal(),
            Reply::Invalid(A4Reason::OperationError),
            "3.5-2: a bad C2HB gets A4E00"
        );
    }
    assert_eq!(
        parse("C9XX").map_err(|e| e.refusal()),
        Err(Reply::Invalid(A4Reason::ProtocolError))
    );
}

#[test]
fn data_is_required_on_downloads_and_refused_elsewhere() {
    assert_eq!(
        parse("C0PABC"),
        Err(CommandError::MissingData {
            command: "C0PABC".into()
        })
    );
    let status_with_data = Message::with_data("C2ST", b"x".to_vec()).expect("valid");
    assert_eq!(
        Command::parse(&status_with_data),
        Err(CommandError::UnexpectedData {
            command: "C2ST".into(),
            size: 1
        })
    );
}

#[test]
fn only_commands_that_change_nothing_are_repeatable() {
    let repeatable: Vec<String> = [
        Command::Status,
        Command::CurrentProgram,
        Command::ProgramList,
        Command::Upload {
            target: Target::Product(name("ABC")),
        },
        Command::KeepAlive(KeepAliveId::sequence(1)),
        Command::Production(ProductionRequest {
            scope: ProductionScope::GrandTotal,
            clear: false,
        }),
        Command::Production(ProductionRequest {
            scope: ProductionScope::CurrentTotal,
            clear: true,
        }),
        Command::Download {
            target: Target::MachineData,
            data: b"*\r\n".to_vec(),
        },
        Command::Delete {
            target: Target::Product(name("ABC")),
        },
        Command::Start(None),
        Command::Reset,
    ]
    .iter()
    .filter(|command| command.is_repeatable())
    .map(Command::wire)
    .collect();
    assert_eq!(
        repeatable,
        ["C2ST", "C3P", "C1RP", "C1PABC", "C2HB00000001", "C1M000"]
    );
}

fn arb_target() -> impl Strategy<Value = Target> {
    prop_oneof![
        "[!-~][ -~]{0,13}[!-~]".prop_map(|n| Target::Product(ProgramName::new(&n).expect("valid"))),
        Just(Target::PartLibrary),
        Just(Target::MarkLibrary),
        Just(Target::NozzleLibrary),
        Just(Target::SupplyLibrary),
        Just(Target::MachineData),
    ]
}

pub(crate) fn arb_command() -> impl Strategy<Value = Command> {
    prop_oneof![
        (arb_target(), prop::collection::vec(any::<u8>(), 1..200))
            .prop_map(|(target, data)| Command::Download { target, data }),
        arb_target().prop_map(|target| Command::Delete { target }),
        arb_target().prop_map(|target| Command::Upload { target }),
        prop::sample::select(ProductionRequest::ALL.to_vec()).prop_map(Command::Production),
        Just(Command::ProgramList),
        Just(Command::Status),
        "[!-~]{6}".prop_map(|id| Command::KeepAlive(KeepAliveId::new(&id).expect("valid"))),
        Just(Command::CurrentProgram),
        prop::option::of(prop::sample::select(StopMode::ALL.to_vec())).prop_map(Command::Start),
        Just(Command::Reset),
    ]
}

proptest! {
    #[test]
    fn commands_round_trip_through_messages_and_bytes(command in arb_command()) {
        let message = command.to_message().expect("every command fits a message");
        prop_assert_eq!(Command::parse(&message), Ok(command.clone()));
        let bytes = message.to_bytes();
        let decoded = wire::Codec::decode(&crate::message::MessageCodec, &bytes).expect("valid").expect("complete").0;
        prop_assert_eq!(Command::parse(&decoded), Ok(command));
    }
}
