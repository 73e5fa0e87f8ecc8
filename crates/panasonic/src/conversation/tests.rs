use super::*;
use crate::command::{KeepAliveId, ProductionRequest, ProductionScope};
use crate::program::Target;
use crate::status::{ControlMode, RunState};

fn message(text: &str) -> Message {
    Message::new(text).expect("valid text")
}

fn data(text: &str, data: &[u8]) -> Message {
    Message::with_data(text, data.to_vec()).expect("valid")
}

fn name(text: &str) -> ProgramName {
    ProgramName::new(text).expect("valid")
}

#[test]
fn host_status_exchange_is_c2st_d1_a2() {
    let mut host = HostConversation::new();
    assert_eq!(
        host.start(&Command::Status).map(|m| m.command().to_owned()),
        Ok("C2ST".to_owned())
    );
    assert_eq!(host.pending(), Some("C2ST"));
    let next = host.handle(data("D1", b"001"));
    assert_eq!(
        next,
        Next::Done {
            send: Some(message("A2")),
            outcome: Outcome::Status(MachineStatus {
                state: RunState::Run,
                mode: ControlMode::Remote
            }),
        }
    );
    assert!(host.is_idle());
}

#[test]
fn host_upload_exchange_is_c1_d0_a0_a2() {
    let mut host = HostConversation::new();
    host.start(&Command::Upload {
        target: Target::Product(name("ABC")),
    })
    .expect("idle");
    let text = b"%HEADER\r\n*\r\n";
    assert_eq!(host.handle(data("D0", text)), Next::Send(message("A0")));
    assert!(!host.is_idle(), "waits for the machine's A2");
    assert_eq!(
        host.handle(message("A2")),
        Next::Done {
            send: None,
            outcome: Outcome::Uploaded(text.to_vec())
        }
    );
    assert!(host.is_idle());
}

#[test]
fn host_download_exchange_is_c0_a0_a2() {
    let mut host = HostConversation::new();
    let command = Command::Download {
        target: Target::Product(name("ABC")),
        data: b"*\r\n".to_vec(),
    };
    let sent = host.start(&command).expect("idle");
    assert_eq!((sent.command(), sent.data()), ("C0PABC", &b"*\r\n"[..]));
    assert_eq!(
        host.handle(message("A0")),
        Next::Done {
            send: Some(message("A2")),
            outcome: Outcome::Downloaded
        }
    );
}

#[test]
fn host_no_data_commands_end_with_a2() {
    for command in [
        Command::Start(None),
        Command::Reset,
        Command::KeepAlive(KeepAliveId::new("ABC123").expect("valid")),
        Command::Delete {
            target: Target::Product(name("X")),
        },
    ] {
        let mut host = HostConversation::new();
        host.start(&command).expect("idle");
        assert_eq!(
            host.handle(message("A2")),
            Next::Done {
                send: None,
                outcome: Outcome::Finished
            },
            "{command}"
        );
    }
}

#[test]
fn host_reads_typed_program_lists_production_data_and_names() {
    let mut host = HostConversation::new();
    host.start(&Command::ProgramList).expect("idle");
    assert_eq!(
        host.handle(data("D0", b"03/01/30PABC            \r\n*\r\n")),
        Next::Send(message("A0"))
    );
    let Next::Done {
        outcome: Outcome::ProgramList(list),
        ..
    } = host.handle(message("A2"))
    else {
        panic!("a program list")
    };
    assert_eq!(list.0[0].name, name("ABC"));

    host.start(&Command::Production(ProductionRequest {
        scope: ProductionScope::GrandTotal,
        clear: false,
    }))
    .expect("idle");
    assert_eq!(
        host.handle(data("D0", b"%HEADER\r\nNAME=M000\r\n*\r\n")),
        Next::Send(message("A0"))
    );
    assert!(matches!(
        host.handle(message("A2")),
        Next::Done {
            outcome: Outcome::Production(_),
            ..
        }
    ));

    host.start(&Command::CurrentProgram).expect("idle");
    assert_eq!(
        host.handle(data("D1", b"PABC            ")),
        Next::Done {
            send: Some(message("A2")),
            outcome: Outcome::CurrentProgram(name("ABC"))
        }
    );
}

#[test]
fn host_turns_a3_and_a4_into_refusals_with_meaning() {
    let mut host = HostConversation::new();
    host.start(&Command::Upload {
        target: Target::Product(name("NOPE")),
    })
    .expect("idle");
    let Next::Failed { send: None, error } = host.handle(message("A3")) else {
        panic!("refused")
    };
    assert!(error.is_refusal());
    assert_eq!(
        error.to_string(),
        "machine refused C1PNOPE: program \"NOPE\" does not exist on the machine"
    );

    host.start(&Command::Start(Some(crate::status::StopMode::Continuous)))
        .expect("idle after a refusal");
    let Next::Failed { error, .. } = host.handle(message("A4E00")) else {
        panic!("refused")
    };
    assert!(error.to_string().contains("Remote mode"), "{error}");

    host.start(&Command::CurrentProgram).expect("idle");
    let Next::Failed { error, .. } = host.handle(message("A4E01")) else {
        panic!("refused")
    };
    assert!(
        error.to_string().contains("no product program is selected"),
        "{error}"
    );
}

#[test]
fn host_runs_one_exchange_at_a_time() {
    let mut host = HostConversation::new();
    host.start(&Command::Status).expect("idle");
    assert_eq!(
        host.start(&Command::Reset),
        Err(ConversationError::Busy {
            pending: "C2ST".into(),
            refused: "C5RE".into()
        })
    );
    host.abort();
    assert!(host.start(&Command::Reset).is_ok());
}

#[test]
fn host_answers_unreadable_data_with_a4e01() {
    let mut host = HostConversation::new();
    host.start(&Command::Status).expect("idle");
    let Next::Failed { send, error } = host.handle(data("D1", b"9")) else {
        panic!("bad data")
    };
    assert_eq!(send, Some(message("A4E01")));
    assert!(matches!(error, ConversationError::BadData { .. }));
    assert!(host.is_idle());
}

#[test]
fn host_reports_out_of_sequence_messages() {
    let mut host = HostConversation::new();
    assert_eq!(
        host.handle(message("A2")),
        Next::Failed {
            send: None,
            error: ConversationError::NotInConversation { got: "A2".into() }
        }
    );
    host.start(&Command::Reset).expect("idle");
    assert!(matches!(
        host.handle(message("A0")),
        Next::Failed {
            send: None,
            error: ConversationError::Unexpected {
                expected: "A2, A3 or A4",
                ..
            }
        }
    ));
    host.start(&Command::Upload {
        target: Target::PartLibrary,
    })
    .expect("idle");
    assert_eq!(host.handle(data("D0", b"*\r\n")), Next::Send(message("A0")));
    assert!(matches!(
        host.handle(data("D0", b"*\r\n")),
        Next::Failed {
            send: Some(_),
            error: ConversationError::Unexpected { expected: "A2", .. }
        }
    ));
}

#[test]
fn host_refuses_to_start_a_command_that_cannot_be_sent() {
    let mut host = HostConversation::new();
    let huge = Command::Download {
        target: Target::PartLibrary,
        data: vec![b'x'; crate::message::MAX_DATA_LEN + 1],
    };
    assert!(matches!(
        host.start(&huge),
        Err(ConversationError::Message(MessageError::DataTooLong { .. }))
    ));
    assert!(host.is_idle());
}

#[test]
fn machine_d0_exchange_ends_with_its_own_a2_after_the_hosts_a0() {
    let mut machine = MachineConversation::new();
    assert_eq!(
        machine.receive(Ok(message("C1RP"))),
        MachineStep::Command(Command::ProgramList)
    );
    let d0 = machine.answer(MachineAnswer::Data(b"*\r\n".to_vec()));
    assert_eq!(d0.command(), "D0");
    assert!(!machine.is_idle());
    assert_eq!(
        machine.receive(Ok(message("A0"))),
        MachineStep::Reply(message("A2"))
    );
    assert!(machine.is_idle());
}

#[test]
fn machine_d1_exchange_ends_quietly_with_the_hosts_a2() {
    let mut machine = MachineConversation::new();
    assert_eq!(
        machine.receive(Ok(message("C2ST"))),
        MachineStep::Command(Command::Status)
    );
    assert_eq!(
        machine.answer(MachineAnswer::Value(b"011".to_vec())),
        data("D1", b"011")
    );
    assert_eq!(machine.receive(Ok(message("A2"))), MachineStep::Quiet);
    assert!(machine.is_idle());
}

#[test]
fn machine_commits_a_download_only_when_the_host_closes_it() {
    let mut machine = MachineConversation::new();
    let command = Command::Download {
        target: Target::MachineData,
        data: b"*\r\n".to_vec(),
    };
    let MachineStep::Command(received) = machine.receive(Ok(command.to_message().expect("fits")))
    else {
        panic!("a command")
    };
    assert_eq!(
        machine.answer(MachineAnswer::Received(received)),
        message("A0")
    );
    assert_eq!(
        machine.receive(Ok(message("A2"))),
        MachineStep::Commit(command)
    );
}

#[test]
fn machine_refuses_a_command_in_the_middle_of_an_exchange_and_abandons_it() {
    let mut machine = MachineConversation::new();
    let _ = machine.receive(Ok(message("C2ST")));
    let _ = machine.answer(MachineAnswer::Value(b"010".to_vec()));
    assert_eq!(
        machine.receive(Ok(message("C3P"))),
        MachineStep::Reply(message("A4E00"))
    );
    assert!(machine.is_idle());
    assert_eq!(
        machine.receive(Ok(message("C3P"))),
        MachineStep::Command(Command::CurrentProgram)
    );
}

#[test]
fn machine_treats_a_wrong_acknowledgement_as_a_protocol_error() {
    let mut machine = MachineConversation::new();
    let _ = machine.receive(Ok(message("C1RP")));
    let _ = machine.answer(MachineAnswer::Data(b"*\r\n".to_vec()));
    assert_eq!(
        machine.receive(Ok(message("A2"))),
        MachineStep::Reply(message("A4E01"))
    );
    assert!(machine.is_idle());
}

#[test]
fn machine_accepts_the_hosts_refusal_of_its_data_quietly() {
    let mut machine = MachineConversation::new();
    let _ = machine.receive(Ok(message("C1RP")));
    let _ = machine.answer(MachineAnswer::Data(b"*\r\n".to_vec()));
    assert_eq!(machine.receive(Ok(message("A4E01"))), MachineStep::Quiet);
    assert!(machine.is_idle());
}

#[test]
fn machine_ignores_stray_acknowledgements_and_refuses_stray_data() {
    let mut machine = MachineConversation::new();
    assert_eq!(machine.receive(Ok(message("A2"))), MachineStep::Quiet);
    assert_eq!(
        machine.receive(Ok(data("D0", b"x"))),
        MachineStep::Reply(message("A4E01"))
    );
    assert_eq!(
        machine.receive(Ok(message("R1ST"))),
        MachineStep::Reply(message("A4E01"))
    );
    assert_eq!(
        machine.receive(Ok(message("C9ZZ"))),
        MachineStep::Reply(message("A4E01"))
    );
    assert_eq!(
        machine.receive(Ok(message("C2HB00BAD"))),
        MachineStep::Reply(message("A4E00"))
    );
}

#[test]
fn machine_answers_one_a4e01_per_run_of_bad_bytes() {
    let mut machine = MachineConversation::new();
    let error = || Err(DecodeError::NotAStart { byte: 0, drop: 1 });
    assert_eq!(
        machine.receive(error()),
        MachineStep::Reply(message("A4E01"))
    );
    assert_eq!(machine.receive(error()), MachineStep::Quiet);
    assert_eq!(
        machine.receive(Ok(message("C2ST"))),
        MachineStep::Command(Command::Status)
    );
    let _ = machine.answer(MachineAnswer::Value(b"010".to_vec()));
    assert_eq!(
        machine.receive(error()),
        MachineStep::Reply(message("A4E01")),
        "a new run"
    );
    assert!(machine.is_idle(), "the open exchange is abandoned");
}

#[test]
fn host_and_machine_state_machines_agree_on_every_flow() {
    let flows: Vec<(Command, MachineAnswer)> = vec![
        (Command::Status, MachineAnswer::Value(b"010".to_vec())),
        (Command::ProgramList, MachineAnswer::Data(b"*\r\n".to_vec())),
        (Command::Reset, MachineAnswer::Finished),
        (
            Command::Download {
                target: Target::PartLibrary,
                data: b"*\r\n".to_vec(),
            },
            MachineAnswer::Received(Command::Download {
                target: Target::PartLibrary,
                data: b"*\r\n".to_vec(),
            }),
        ),
        (
            Command::Upload {
                target: Target::Product(name("X")),
            },
            MachineAnswer::NoSuchProgram,
        ),
        (
            Command::Start(None),
            MachineAnswer::Refused(A4Reason::OperationError),
        ),
    ];
    for (command, answer) in flows {
        let mut host = HostConversation::new();
        let mut machine = MachineConversation::new();
        let mut to_machine = vec![host.start(&command).expect("idle")];
        let mut finished = false;
        let mut answer = Some(answer);
        for _ in 0..6 {
            let mut to_host = Vec::new();
            for m in to_machine.drain(..) {
                match machine.receive(Ok(m)) {
                    MachineStep::Command(_) => {
                        to_host.push(machine.answer(answer.take().expect("one command")))
                    }
                    MachineStep::Reply(reply) => to_host.push(reply),
                    MachineStep::Commit(_) | MachineStep::Quiet => {}
                }
            }
            for m in to_host {
                match host.handle(m) {
                    Next::Send(ack) => to_machine.push(ack),
                    Next::Done { send, .. } | Next::Failed { send, .. } => {
                        to_machine.extend(send);
                        finished = true;
                    }
                }
            }
        }
        assert!(finished, "{command}");
        assert!(
            host.is_idle() && machine.is_idle(),
            "{command}: both sides idle at the end"
        );
    }
}
