//! The twin against the host state machine, over simulated time.

use std::time::{Duration, Instant};

use super::*;
use crate::command::KeepAliveId;
use crate::conversation::{ConversationError, HostConversation, Next, Outcome};
use crate::production::ProductionData;
use crate::reply::{Refusal, Reply};

/// A host and a twin joined by Port 1, with Port 2 read as typed events, and a clock.
struct Rig {
    machine: Machine,
    host: HostConversation,
    now: Instant,
}

impl Rig {
    /// The commands of the machine's replies on port 1 to the message `text`.
    fn replies_to(&mut self, text: &str) -> Vec<String> {
        let bytes = Message::new(text).expect("valid").to_bytes();
        self.machine
            .handle_port1(&bytes, self.now)
            .iter()
            .map(|m| m.command().to_owned())
            .collect()
    }

    fn new(config: MachineConfig) -> Rig {
        let now = Instant::now();
        let mut machine = Machine::new(config).expect("valid config");
        machine.host_connected_on_port2(true, now);
        Rig {
            machine,
            host: HostConversation::new(),
            now,
        }
    }

    fn remote() -> Rig {
        Rig::new(MachineConfig {
            remote: true,
            ..quiet_config()
        })
    }

    /// Runs one Port 1 exchange to its end, as bytes.
    fn exchange(&mut self, command: Command) -> Result<Outcome, ConversationError> {
        let mut to_machine = vec![self.host.start(&command)?];
        for _ in 0..4 {
            let mut replies = Vec::new();
            for message in to_machine.drain(..) {
                replies.extend(self.machine.handle_port1(&message.to_bytes(), self.now));
            }
            for reply in replies {
                match self.host.handle(reply) {
                    Next::Send(ack) => to_machine.push(ack),
                    Next::Done { send, outcome } => {
                        self.close(send);
                        return Ok(outcome);
                    }
                    Next::Failed { send, error } => {
                        self.close(send);
                        return Err(error);
                    }
                }
            }
        }
        panic!("exchange {command} did not end");
    }

    fn close(&mut self, send: Option<Message>) {
        if let Some(last) = send {
            let after = self.machine.handle_port1(&last.to_bytes(), self.now);
            assert!(
                after.is_empty(),
                "the machine does not answer the host's closing message: {after:?}"
            );
        }
        assert!(
            !self.machine.in_conversation(),
            "the machine left conversation mode"
        );
    }

    fn refusal(&mut self, command: Command) -> Reply {
        match self.exchange(command) {
            Err(ConversationError::Refused(Refusal { reply, .. })) => reply,
            other => panic!("expected a refusal, got {other:?}"),
        }
    }

    fn status(&mut self) -> MachineStatus {
        match self.exchange(Command::Status) {
            Ok(Outcome::Status(status)) => status,
            other => panic!("expected a status, got {other:?}"),
        }
    }

    fn production(&mut self, scope: ProductionScope, clear: bool) -> ProductionData {
        match self.exchange(Command::Production(ProductionRequest { scope, clear })) {
            Ok(Outcome::Production(data)) => data,
            other => panic!("expected production data, got {other:?}"),
        }
    }

    fn wait(&mut self, duration: Duration) {
        self.now += duration;
    }

    fn events(&mut self) -> Vec<Event> {
        self.machine
            .poll_events(self.now)
            .iter()
            .map(|m| Event::parse(m).expect("the twin sends valid R messages"))
            .collect()
    }
}

/// Default config without misses, so runs are exact.
fn quiet_config() -> MachineConfig {
    MachineConfig {
        miss_rate: 0.0,
        reel_size: 100_000,
        ..MachineConfig::default()
    }
}

fn name(text: &str) -> ProgramName {
    ProgramName::new(text).expect("valid name")
}

/// A program text of `steps` step lines.
fn program(steps: usize) -> Vec<u8> {
    let mut text = b"%HEADER\r\nNAME=T\r\n%STEP\r\n".to_vec();
    for step in 0..steps {
        text.extend(format!("{:04},X0,Y0\r\n", step + 1).bytes());
    }
    text.extend(b"*\r\n");
    text
}

fn download(target: Target, data: Vec<u8>) -> Command {
    Command::Download { target, data }
}

fn count(events: &[Event], wanted: impl Fn(&Event) -> bool) -> usize {
    events.iter().filter(|e| wanted(e)).count()
}

#[test]
fn status_is_ready_with_the_configured_mode() {
    let mut rig = Rig::new(quiet_config());
    assert_eq!(
        rig.status(),
        MachineStatus {
            state: RunState::Ready,
            mode: ControlMode::Online
        }
    );
    rig.machine.set_mode(ControlMode::Remote);
    assert_eq!(
        rig.status(),
        MachineStatus {
            state: RunState::Ready,
            mode: ControlMode::Remote
        }
    );
}

#[test]
fn c2st_request_bytes_get_the_d1_reply_bytes_of_the_fact_sheet() {
    let mut rig = Rig::remote();
    rig.machine
        .operator_start(Some(StopMode::Continuous), rig.now)
        .expect("a program is selected");
    let request = Message::new("C2ST").expect("valid").to_bytes();
    let replies = rig.machine.handle_port1(&request, rig.now);
    let mut expected = b"D1".to_vec();
    expected.extend([b' '; 254]);
    expected.extend([0, 0, 0, 3]);
    expected.extend(b"001");
    expected.extend([0, 0, 0]);
    assert_eq!(
        replies.iter().map(Message::to_bytes).collect::<Vec<_>>(),
        vec![expected]
    );
}

#[test]
fn remote_control_outside_remote_mode_is_refused_with_a4e00() {
    let mut rig = Rig::new(quiet_config());
    assert_eq!(
        rig.refusal(Command::Start(Some(StopMode::Continuous))),
        Reply::OPERATION_ERROR
    );
    assert_eq!(rig.refusal(Command::Reset), Reply::OPERATION_ERROR);
    assert_eq!(rig.status().state, RunState::Ready, "nothing started");
    assert!(rig.events().is_empty());
}

#[test]
fn remote_start_answers_a2_then_sends_r1st_on_port_2() {
    let mut rig = Rig::remote();
    assert_eq!(
        rig.exchange(Command::Start(Some(StopMode::Continuous))),
        Ok(Outcome::Finished)
    );
    assert_eq!(rig.events(), vec![Event::Started]);
    assert_eq!(
        rig.status(),
        MachineStatus {
            state: RunState::Run,
            mode: ControlMode::Remote
        }
    );
    assert_eq!(rig.machine.stop_mode(), StopMode::Continuous);
    assert_eq!(
        rig.refusal(Command::Start(None)),
        Reply::OPERATION_ERROR,
        "already running"
    );
    assert_eq!(
        rig.refusal(Command::Reset),
        Reply::OPERATION_ERROR,
        "no reset while running"
    );
}

#[test]
fn continuous_production_counts_boards_and_sends_r0ct_with_the_board_time() {
    let mut rig = Rig::remote();
    rig.exchange(Command::Start(Some(StopMode::Continuous)))
        .expect("started");
    // Demo board: 4 s loading + 120 × 0.15 s = 22 s.
    rig.wait(Duration::from_secs(600));
    let events = rig.events();
    let boards: Vec<_> = events
        .iter()
        .filter(|e| matches!(e, Event::BoardFinished { .. }))
        .collect();
    assert_eq!(boards.len(), 27, "600 s / 22 s per board");
    assert!(boards.iter().all(|e| **e
        == Event::BoardFinished {
            time: Some(BoardTime::new(22).expect("fits"))
        }));
    assert_eq!(rig.machine.boards_produced(), 27);
    let data = rig.production(ProductionScope::GrandTotal, false);
    assert_eq!(data.count(Counter::Product1), Some(27));
    assert_eq!(
        data.count(Counter::Mount),
        Some(27 * 120 + 13),
        "the 28th board: 2 s of placing after 4 s of loading"
    );
    assert_eq!(data.rate(RateKind::Mount), Some(Rate::FULL));
    assert_eq!(
        data.header.start.map(|t| t.to_string()).as_deref(),
        Some("2026/01/05 08/00/00")
    );
    assert_eq!(
        data.header.end.map(|t| t.to_string()).as_deref(),
        Some("2026/01/05 08/10/00")
    );
    assert_eq!(rig.status().state, RunState::Run);
}

#[test]
fn the_short_r0_form_comes_without_the_extended_format() {
    let mut rig = Rig::new(MachineConfig {
        remote: true,
        extended_format: false,
        ..quiet_config()
    });
    rig.exchange(Command::Start(Some(StopMode::Continuous)))
        .expect("started");
    rig.wait(Duration::from_secs(23));
    assert_eq!(
        rig.events(),
        vec![Event::Started, Event::BoardFinished { time: None }]
    );
}

#[test]
fn eop_mode_builds_one_board_then_sends_r0ep_and_stops() {
    let mut rig = Rig::remote();
    rig.exchange(Command::Start(Some(StopMode::EndOfProgram)))
        .expect("started");
    rig.wait(Duration::from_secs(100));
    let time = Some(BoardTime::new(22).expect("fits"));
    assert_eq!(
        rig.events(),
        vec![Event::Started, Event::ProductionFinished { time }]
    );
    assert_eq!(rig.status().state, RunState::Ready);
    assert_eq!(rig.machine.boards_produced(), 1);
}

#[test]
fn one_block_mode_stops_after_every_block_and_sends_r0ep_after_the_last() {
    let mut rig = Rig::remote();
    rig.exchange(download(Target::Product(name("THREE")), program(3)))
        .expect("stored");
    rig.machine
        .select_program(&name("THREE"), rig.now)
        .expect("stored program");
    for block in 1..=3 {
        rig.exchange(Command::Start(Some(StopMode::OneBlock)))
            .expect("started");
        rig.wait(Duration::from_secs(10));
        assert_eq!(
            rig.status().state,
            RunState::Ready,
            "stopped after block {block}"
        );
        let finished = count(&rig.events(), |e| {
            matches!(e, Event::ProductionFinished { .. })
        });
        assert_eq!(
            finished,
            usize::from(block == 3),
            "R0EP only after the EOP block"
        );
    }
    assert_eq!(rig.machine.boards_produced(), 1);
}

#[test]
fn parts_exhaustion_sends_r2e03_and_stops_with_error_until_reset() {
    let config = MachineConfig {
        remote: true,
        reel_size: 10,
        feeders: 20,
        ..quiet_config()
    };
    let mut rig = Rig::new(config);
    rig.exchange(Command::Start(Some(StopMode::Continuous)))
        .expect("started");
    rig.wait(Duration::from_secs(3600));
    let events = rig.events();
    let Some(Event::Error(info)) = events.last() else {
        panic!("the run ends with an error: {events:?}")
    };
    assert!(info.is_parts_exhausted());
    assert_eq!(
        rig.machine.feeder_remaining(info.feeder()),
        Ok(0),
        "the feeder named in Z is empty"
    );
    assert_eq!(info.detail().map(str::len), Some(6), "extended format");
    assert_eq!(rig.status().state, RunState::Error);
    assert_eq!(
        rig.machine.next_event_at(),
        None,
        "nothing runs in an error stop"
    );

    assert_eq!(
        rig.refusal(Command::Start(None)),
        Reply::OPERATION_ERROR,
        "an error stop needs a reset"
    );
    assert_eq!(rig.exchange(Command::Reset), Ok(Outcome::Finished));
    assert_eq!(
        rig.status().state,
        RunState::Ready,
        "3.3-11: RESET gives Ready even with the cause still there"
    );
    assert!(rig.events().is_empty(), "R1RE takes a while");
    rig.wait(Duration::from_secs(3));
    assert_eq!(rig.events(), vec![Event::ResetDone]);

    let data = rig.production(ProductionScope::GrandTotal, false);
    assert_eq!(data.count(Counter::PartsExhaustCount), Some(1));
    assert!(data.count(Counter::PartsExhaustTime).is_some_and(|t| t > 0));

    rig.machine.clear(rig.now);
    rig.exchange(Command::Start(None))
        .expect("restarts after clearing");
    assert_eq!(
        rig.machine.stop_mode(),
        StopMode::Continuous,
        "C5ST keeps the previous stop mode"
    );
    assert_eq!(rig.status().state, RunState::Run);
}

#[test]
fn a_paused_feeder_runs_out_at_its_first_pick() {
    let mut rig = Rig::remote();
    rig.machine
        .pause_feeder(3, rig.now)
        .expect("feeder 3 exists");
    rig.exchange(Command::Start(Some(StopMode::Continuous)))
        .expect("started");
    rig.wait(Duration::from_secs(30));
    let events = rig.events();
    let expected = ErrorInfo::new(PARTS_EXHAUSTED, 3, 3, 3)
        .and_then(|e| e.with_detail("000001"))
        .expect("valid");
    assert_eq!(events, vec![Event::Started, Event::Error(expected)]);
    assert_eq!(
        rig.machine.pause_feeder(21, rig.now),
        Err(TwinError::NoSuchFeeder {
            feeder: 21,
            feeders: 20
        })
    );
}

#[test]
fn recoveries_send_r1rc_then_one_r3_each_and_are_counted() {
    let config = MachineConfig {
        remote: true,
        miss_rate: 0.05,
        seed: 7,
        ..quiet_config()
    };
    let mut rig = Rig::new(config);
    let mut events = Vec::new();
    for _ in 0..20 {
        if rig.status().state != RunState::Run {
            rig.exchange(Command::Start(Some(StopMode::Continuous)))
                .expect("restart after a pick-up error stop");
        }
        rig.wait(Duration::from_secs(120));
        events.extend(rig.events());
    }
    let started = count(&events, |e| *e == Event::RecoveryStarted);
    let ok = count(&events, |e| *e == Event::RecoveryOk);
    let retry = count(&events, |e| *e == Event::RecoveryRetry);
    let stop = count(&events, |e| *e == Event::RecoveryStop);
    assert!(started > 20, "about 5 % of picks miss: {started}");
    assert_eq!(
        started,
        ok + retry + stop,
        "every R1RC has its R3 while parts last"
    );
    assert!(ok > retry && ok > stop);
    let data = rig.production(ProductionScope::GrandTotal, false);
    let lost = data.count(Counter::PickupMiss).unwrap_or(0)
        + data.count(Counter::RecognitionError1).unwrap_or(0);
    assert_eq!(lost as usize, started);
    assert_eq!(
        data.count(Counter::PickupError).map(|n| n as usize),
        Some(stop)
    );
    assert!(
        data.rate(RateKind::Pickup)
            .is_some_and(|r| r < Rate::FULL && r.percent() > 90.0)
    );
}

#[test]
fn the_same_seed_gives_the_same_run() {
    let run = |seed| {
        let mut rig = Rig::new(MachineConfig {
            remote: true,
            miss_rate: 0.05,
            reel_size: 200,
            seed,
            ..quiet_config()
        });
        rig.exchange(Command::Start(Some(StopMode::Continuous)))
            .expect("started");
        rig.wait(Duration::from_secs(1800));
        rig.events()
    };
    assert_eq!(run(11), run(11));
    assert_ne!(run(11), run(12));
}

#[test]
fn downloading_the_selected_program_is_refused_with_a4e00() {
    let mut rig = Rig::remote();
    let selected = name(DEMO_PROGRAM);
    assert_eq!(
        rig.refusal(download(Target::Product(selected.clone()), program(5))),
        Reply::OPERATION_ERROR
    );
    assert_eq!(
        rig.machine.program_text(&selected).map(|t| t.entries()),
        Some(DEMO_STEPS),
        "unchanged"
    );
}

#[test]
fn a_downloaded_program_uploads_unchanged_and_is_listed_with_its_date() {
    let mut rig = Rig::remote();
    rig.wait(Duration::from_secs(86_400 + 60));
    let text = program(42);
    assert_eq!(
        rig.exchange(download(Target::Product(name("BOARD-7")), text.clone())),
        Ok(Outcome::Downloaded)
    );
    assert_eq!(
        rig.exchange(Command::Upload {
            target: Target::Product(name("BOARD-7"))
        }),
        Ok(Outcome::Uploaded(text))
    );
    let Ok(Outcome::ProgramList(list)) = rig.exchange(Command::ProgramList) else {
        panic!("a program list")
    };
    let names: Vec<_> = list
        .0
        .iter()
        .map(|e| (e.name.as_str().to_owned(), e.date.to_string()))
        .collect();
    assert_eq!(
        names,
        vec![
            ("BOARD-7".into(), "26/01/06".into()),
            (DEMO_PROGRAM.into(), "26/01/05".into())
        ]
    );
}

#[test]
fn a_download_is_stored_only_when_the_host_closes_it_with_a2() {
    let mut rig = Rig::remote();
    let command = download(Target::Product(name("HALF")), program(2));
    let bytes = command.to_message().expect("fits").to_bytes();
    assert_eq!(
        rig.machine.handle_port1(&bytes, rig.now),
        vec![Message::new("A0").expect("valid")]
    );
    assert!(
        rig.machine.program_text(&name("HALF")).is_none(),
        "not before A2"
    );
    rig.machine.port1_closed();
    assert!(
        rig.machine.program_text(&name("HALF")).is_none(),
        "dropped with the connection"
    );
    assert_eq!(rig.exchange(command), Ok(Outcome::Downloaded));
    assert!(rig.machine.program_text(&name("HALF")).is_some());
}

#[test]
fn unknown_programs_get_a3_on_upload_and_delete() {
    let mut rig = Rig::remote();
    let target = Target::Product(name("NOPE"));
    assert_eq!(
        rig.refusal(Command::Upload {
            target: target.clone()
        }),
        Reply::NoSuchProgram
    );
    assert_eq!(
        rig.refusal(Command::Delete { target }),
        Reply::NoSuchProgram
    );
    assert_eq!(
        rig.refusal(Command::Upload {
            target: Target::PartLibrary
        }),
        Reply::NoSuchProgram,
        "never downloaded"
    );
}

#[test]
fn delete_removes_a_program_but_not_the_selected_one_or_a_library() {
    let mut rig = Rig::remote();
    rig.exchange(download(Target::Product(name("OLD")), program(1)))
        .expect("stored");
    assert_eq!(
        rig.exchange(Command::Delete {
            target: Target::Product(name("OLD"))
        }),
        Ok(Outcome::Finished)
    );
    assert!(rig.machine.program_text(&name("OLD")).is_none());
    assert_eq!(
        rig.refusal(Command::Delete {
            target: Target::Product(name(DEMO_PROGRAM))
        }),
        Reply::OPERATION_ERROR
    );
    assert_eq!(
        rig.refusal(Command::Delete {
            target: Target::PartLibrary
        }),
        Reply::OPERATION_ERROR
    );
}

#[test]
fn c3_names_the_selected_program_or_answers_a4e01() {
    let mut rig = Rig::remote();
    assert_eq!(
        rig.exchange(Command::CurrentProgram),
        Ok(Outcome::CurrentProgram(name(DEMO_PROGRAM)))
    );
    let mut bare = Rig::new(MachineConfig {
        demo_program: false,
        ..quiet_config()
    });
    assert_eq!(bare.refusal(Command::CurrentProgram), Reply::PROTOCOL_ERROR);
    assert_eq!(
        bare.refusal(Command::Start(None)),
        Reply::OPERATION_ERROR,
        "online, and nothing to run"
    );
}

#[test]
fn storage_limits_are_enforced_counting_what_is_stored() {
    let mut rig = Rig::new(MachineConfig {
        demo_program: false,
        ..quiet_config()
    });
    for i in 0..MAX_PROGRAMS {
        rig.exchange(download(
            Target::Product(name(&format!("P{i:03}"))),
            program(1),
        ))
        .expect("within 100");
    }
    assert_eq!(
        rig.refusal(download(Target::Product(name("ONE-MORE")), program(1))),
        Reply::OPERATION_ERROR
    );
    assert_eq!(
        rig.exchange(download(Target::Product(name("P000")), program(2))),
        Ok(Outcome::Downloaded),
        "replacing a stored program adds none"
    );
    assert_eq!(
        rig.refusal(download(Target::Product(name("P001")), program(5001))),
        Reply::OPERATION_ERROR
    );
    assert_eq!(
        rig.exchange(download(Target::Product(name("P001")), program(5000))),
        Ok(Outcome::Downloaded)
    );
    assert_eq!(
        rig.refusal(download(Target::NozzleLibrary, program(100))),
        Reply::OPERATION_ERROR
    );
    assert_eq!(
        rig.exchange(download(Target::NozzleLibrary, program(99))),
        Ok(Outcome::Downloaded)
    );
    assert_eq!(
        rig.refusal(download(Target::PartLibrary, program(1001))),
        Reply::OPERATION_ERROR
    );
    assert_eq!(
        rig.refusal(download(Target::MarkLibrary, program(501))),
        Reply::OPERATION_ERROR
    );
    assert_eq!(
        rig.refusal(download(Target::SupplyLibrary, program(501))),
        Reply::OPERATION_ERROR
    );
    assert_eq!(
        rig.exchange(Command::Upload {
            target: Target::NozzleLibrary
        }),
        Ok(Outcome::Uploaded(program(99)))
    );
}

#[test]
fn downloads_without_the_end_mark_get_a4e01() {
    let mut rig = Rig::remote();
    assert_eq!(
        rig.refusal(download(
            Target::Product(name("X")),
            b"%HEADER\r\n".to_vec()
        )),
        Reply::PROTOCOL_ERROR
    );
}

#[test]
fn machine_data_download_changes_the_condition_data() {
    let mut rig = Rig::remote();
    let data = b"%HEADER\r\nNAME=G\r\n&CONDITIONDATA1\r\n1010001,1,1,0,0\r\n*\r\n".to_vec();
    assert_eq!(
        rig.exchange(download(Target::MachineData, data.clone())),
        Ok(Outcome::Downloaded)
    );
    assert!(
        rig.machine.condition_data().pass_through && rig.machine.condition_data().evaluation_mode
    );
    assert_eq!(
        rig.exchange(Command::Upload {
            target: Target::MachineData
        }),
        Ok(Outcome::Uploaded(data))
    );
    let bad = b"%HEADER\r\n&CONDITIONDATA1\r\n1010001,7\r\n*\r\n".to_vec();
    assert_eq!(
        rig.refusal(download(Target::MachineData, bad)),
        Reply::PROTOCOL_ERROR
    );
}

#[test]
fn malformed_bytes_get_one_a4e01_and_the_next_command_is_answered() {
    let mut rig = Rig::remote();
    let mut bytes = b"\x00\x01garbage\r\nXYZ".to_vec();
    let mut broken = Message::new("C2ST").expect("valid").to_bytes();
    broken[262] = 0x7F;
    bytes.extend(broken);
    bytes.extend(Message::new("C2ST").expect("valid").to_bytes());
    let replies = rig.machine.handle_port1(&bytes, rig.now);
    let texts: Vec<_> = replies.iter().map(Message::command).collect();
    assert_eq!(texts, vec!["A4E01", "D1"]);
}

#[test]
fn unknown_commands_get_a4e01_and_bad_keep_alives_a4e00() {
    let mut rig = Rig::remote();
    assert_eq!(rig.replies_to("C5SP"), vec!["A4E01"]);
    assert_eq!(rig.replies_to("C2HB00AB"), vec!["A4E00"]);
    assert!(rig.events().is_empty(), "no R1HB for a bad keep-alive");
}

#[test]
fn a_command_in_the_middle_of_an_exchange_gets_a4e00() {
    let mut rig = Rig::remote();
    assert_eq!(rig.replies_to("C1RP"), vec!["D0"]);
    assert_eq!(rig.replies_to("C2ST"), vec!["A4E00"]);
    assert_eq!(
        rig.replies_to("C2ST"),
        vec!["D1"],
        "the abandoned exchange is gone"
    );
}

#[test]
fn keep_alive_answers_a2_on_port_1_and_r1hb_with_the_same_id_on_port_2() {
    let mut rig = Rig::remote();
    let id = KeepAliveId::new("ABC123").expect("valid");
    assert_eq!(
        rig.exchange(Command::KeepAlive(id.clone())),
        Ok(Outcome::Finished)
    );
    assert_eq!(rig.events(), vec![Event::Heartbeat { id }]);
    let wire = Event::Heartbeat {
        id: KeepAliveId::new("ABC123").expect("valid"),
    }
    .wire();
    assert_eq!(wire, "R1HB00ABC123");
}

#[test]
fn without_r_commands_no_r1hb_comes_back() {
    let mut rig = Rig::new(MachineConfig {
        events_enabled: false,
        ..quiet_config()
    });
    let id = KeepAliveId::new("ABC123").expect("valid");
    assert_eq!(rig.exchange(Command::KeepAlive(id)), Ok(Outcome::Finished));
    assert!(rig.events().is_empty());
}

#[test]
fn r_messages_wait_in_a_40_message_buffer_oldest_dropped_and_arrive_in_order() {
    let mut rig = Rig::remote();
    rig.machine.host_connected_on_port2(false, rig.now);
    for n in 1..=50 {
        rig.exchange(Command::KeepAlive(KeepAliveId::sequence(n)))
            .expect("port 1 works");
    }
    assert!(rig.events().is_empty(), "nobody listens on Port 2");
    assert_eq!(rig.machine.pending_events(), EVENT_BUFFER_LEN);
    assert_eq!(rig.machine.dropped_events(), 10);
    rig.machine.host_connected_on_port2(true, rig.now);
    let ids: Vec<u64> = rig
        .events()
        .into_iter()
        .map(|e| match e {
            Event::Heartbeat { id } => id.as_str().parse().expect("numeric id"),
            other => panic!("unexpected {other:?}"),
        })
        .collect();
    assert_eq!(ids, (11..=50).collect::<Vec<_>>());
}

#[test]
fn production_while_nobody_listens_keeps_the_last_40_events() {
    let mut rig = Rig::remote();
    rig.exchange(Command::Start(Some(StopMode::Continuous)))
        .expect("started");
    rig.machine.host_connected_on_port2(false, rig.now);
    rig.wait(Duration::from_secs(22 * 100));
    rig.machine.host_connected_on_port2(true, rig.now);
    let events = rig.events();
    assert_eq!(events.len(), EVENT_BUFFER_LEN);
    assert!(
        events
            .iter()
            .all(|e| matches!(e, Event::BoardFinished { .. })),
        "R1ST was the oldest, dropped"
    );
    assert_eq!(rig.machine.dropped_events(), 100 - 40 + 1);
}

#[test]
fn a_listening_host_gets_every_event_however_many() {
    let mut rig = Rig::remote();
    rig.exchange(Command::Start(Some(StopMode::Continuous)))
        .expect("started");
    rig.wait(Duration::from_secs(22 * 100));
    assert_eq!(rig.events().len(), 101);
    assert_eq!(rig.machine.dropped_events(), 0);
}

#[test]
fn clearing_follows_the_scopes_of_the_manual() {
    let mut rig = Rig::remote();
    rig.exchange(Command::Start(Some(StopMode::Continuous)))
        .expect("started");
    rig.wait(Duration::from_secs(44));
    let boards = |data: &ProductionData| data.count(Counter::Product1);
    assert_eq!(
        boards(&rig.production(ProductionScope::GrandTotal, true)),
        Some(2)
    );
    assert_eq!(
        boards(&rig.production(ProductionScope::GrandTotal, false)),
        Some(0),
        "C1M900 cleared it"
    );
    assert_eq!(
        boards(&rig.production(ProductionScope::Nozzle, false)),
        Some(2),
        "C1M900 leaves nozzles"
    );
    assert_eq!(
        boards(&rig.production(ProductionScope::CurrentTotal, true)),
        Some(2)
    );
    for scope in [
        ProductionScope::CurrentTotal,
        ProductionScope::Nozzle,
        ProductionScope::Feeder,
    ] {
        assert_eq!(
            boards(&rig.production(scope, false)),
            Some(0),
            "C1M900P clears {scope:?}"
        );
    }
    rig.wait(Duration::from_secs(22));
    assert_eq!(
        boards(&rig.production(ProductionScope::Feeder, true)),
        Some(1)
    );
    assert_eq!(
        boards(&rig.production(ProductionScope::Feeder, false)),
        Some(0)
    );
    assert_eq!(
        boards(&rig.production(ProductionScope::Nozzle, false)),
        Some(1),
        "C1Z900 leaves nozzles"
    );
    let data = rig.production(ProductionScope::GrandTotal, false);
    assert_eq!(data.header.name.as_deref(), Some("M000"));
    assert_eq!(
        data.header.start.map(|t| t.to_string()).as_deref(),
        Some("2026/01/05 08/00/44")
    );
}

#[test]
fn a_forced_error_sends_r2_and_stops_with_error() {
    let mut rig = Rig::remote();
    rig.exchange(Command::Start(Some(StopMode::Continuous)))
        .expect("started");
    rig.wait(Duration::from_secs(5));
    rig.machine.force_error(12, rig.now).expect("a valid code");
    let events = rig.events();
    assert!(
        matches!(events.last(), Some(Event::Error(info)) if info.code() == 12 && info.step() == 7)
    );
    assert_eq!(rig.status().state, RunState::Error);
    assert_eq!(
        rig.machine.force_error(100, rig.now),
        Err(TwinError::BadErrorCode { code: 100 })
    );
}

#[test]
fn selecting_a_program_sends_r1se_and_an_unknown_one_r1seng() {
    let mut rig = Rig::remote();
    rig.exchange(download(Target::Product(name("NEXT")), program(3)))
        .expect("stored");
    rig.machine
        .select_program(&name("NEXT"), rig.now)
        .expect("stored");
    assert_eq!(
        rig.machine.select_program(&name("GONE"), rig.now),
        Err(TwinError::UnknownProgram { name: name("GONE") })
    );
    assert_eq!(
        rig.events(),
        vec![
            Event::Se {
                program: Some(name("NEXT"))
            },
            Event::SeNg {
                program: Some(name("GONE")),
                error: None
            }
        ]
    );
    assert_eq!(
        rig.exchange(Command::CurrentProgram),
        Ok(Outcome::CurrentProgram(name("NEXT")))
    );
}

#[test]
fn time_never_runs_backwards() {
    let mut rig = Rig::remote();
    rig.exchange(Command::Start(Some(StopMode::Continuous)))
        .expect("started");
    let start = rig.now;
    rig.wait(Duration::from_secs(44));
    assert_eq!(
        count(&rig.events(), |e| matches!(e, Event::BoardFinished { .. })),
        2
    );
    assert!(
        rig.machine.poll_events(start).is_empty(),
        "an earlier now changes nothing"
    );
    assert_eq!(rig.machine.boards_produced(), 2);
}

#[test]
fn next_event_at_tells_when_the_run_needs_polling() {
    let mut rig = Rig::remote();
    assert_eq!(rig.machine.next_event_at(), None, "idle");
    rig.exchange(Command::Start(Some(StopMode::Continuous)))
        .expect("started");
    let first_block = rig.now + Duration::from_millis(4150);
    assert_eq!(rig.machine.next_event_at(), Some(first_block));
}

#[test]
fn invalid_configurations_are_refused() {
    let bad = |config| Machine::new(config).err();
    assert!(matches!(
        bad(MachineConfig {
            miss_rate: 1.5,
            ..MachineConfig::default()
        }),
        Some(ConfigError::OutOfRange { .. })
    ));
    assert!(matches!(
        bad(MachineConfig {
            feeders: 0,
            ..MachineConfig::default()
        }),
        Some(ConfigError::OutOfRange { .. })
    ));
    assert!(matches!(
        bad(MachineConfig {
            placement_time: Duration::ZERO,
            ..MachineConfig::default()
        }),
        Some(ConfigError::ZeroDuration {
            what: "placement_time"
        })
    ));
}

#[test]
fn the_twin_can_be_shared_across_server_tasks() {
    fn send<T: Send + 'static>() {}
    send::<Machine>();
}

#[test]
fn a_command_stamped_earlier_than_the_twins_time_acts_at_the_twins_time() {
    let mut rig = Rig::remote();
    let early = rig.now;
    rig.wait(Duration::from_secs(100));
    assert!(rig.events().is_empty());
    let start = Command::Start(Some(StopMode::Continuous))
        .to_message()
        .expect("fits")
        .to_bytes();
    let replies = rig.machine.handle_port1(&start, early);
    assert_eq!(replies, vec![Message::new("A2").expect("valid")]);
    assert_eq!(
        rig.machine.next_event_at(),
        Some(rig.now + Duration::from_millis(4150))
    );
}

#[test]
fn requeued_events_go_out_first_and_in_order_to_the_next_host() {
    let mut rig = Rig::remote();
    for n in 1..=3 {
        rig.exchange(Command::KeepAlive(KeepAliveId::sequence(n)))
            .expect("port 1 works");
    }
    let sent = rig.machine.poll_events(rig.now);
    assert_eq!(sent.len(), 3);
    rig.machine.host_connected_on_port2(false, rig.now);
    rig.exchange(Command::KeepAlive(KeepAliveId::sequence(4)))
        .expect("port 1 works");
    rig.machine.requeue_events(sent);
    rig.machine.host_connected_on_port2(true, rig.now);
    let ids: Vec<String> = rig
        .events()
        .into_iter()
        .map(|e| match e {
            Event::Heartbeat { id } => id.as_str().to_owned(),
            other => panic!("unexpected {other:?}"),
        })
        .collect();
    assert_eq!(ids, ["000001", "000002", "000003", "000004"]);
}

#[test]
fn requeued_events_obey_the_buffer_rule_while_nobody_listens() {
    let mut rig = Rig::remote();
    rig.exchange(Command::KeepAlive(KeepAliveId::sequence(1)))
        .expect("port 1 works");
    let sent = rig.machine.poll_events(rig.now);
    rig.machine.host_connected_on_port2(false, rig.now);
    for n in 2..=41 {
        rig.exchange(Command::KeepAlive(KeepAliveId::sequence(n)))
            .expect("port 1 works");
    }
    rig.machine.requeue_events(sent);
    assert_eq!(rig.machine.pending_events(), EVENT_BUFFER_LEN);
    assert_eq!(
        rig.machine.dropped_events(),
        1,
        "the requeued one was the oldest"
    );
}
