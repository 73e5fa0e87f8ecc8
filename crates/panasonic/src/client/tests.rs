//! The client against the twin server over loopback TCP (port 0), under paused time: an
//! hour of production and keep-alives runs in milliseconds, and time-outs are exact.

use std::net::SocketAddr;

use super::*;
use crate::command::ProductionScope;
use crate::production::Counter;
use crate::reply::A4Reason;
use crate::reply::Reply;
use crate::server::{PortFault, RunningTwin, TwinServer};
use crate::status::{ControlMode, RunState};
use crate::twin::{DEMO_PROGRAM, Machine, MachineConfig};

fn local() -> SocketAddr {
    SocketAddr::from(([127, 0, 0, 1], 0))
}

/// A twin with no pick misses (so runs are plain), in Remote mode unless told.
fn quiet(remote: bool) -> MachineConfig {
    MachineConfig {
        remote,
        miss_rate: 0.0,
        ..MachineConfig::default()
    }
}

async fn twin(config: MachineConfig) -> RunningTwin {
    let machine = Machine::new(config).expect("a valid twin");
    TwinServer::bind(local(), local(), machine)
        .await
        .expect("binds to loopback")
        .spawn()
        .expect("knows its addresses")
}

/// Both ports, the given keep-alive, short backoff.
fn config(twin: &RunningTwin, keep_alive: Option<KeepAliveConfig>) -> ClientConfig {
    ClientConfig {
        command_port: twin.command_addr().port(),
        event_port: Some(twin.event_addr().port()),
        keep_alive,
        ..ClientConfig::new("127.0.0.1")
    }
}

async fn connect(config: ClientConfig) -> (Client, Events) {
    Client::connect(config).await.expect("connects")
}

/// A quiet twin in remote mode, and a client (no keep-alive) that started it and saw R1ST.
async fn running() -> (RunningTwin, Client, Events) {
    let twin = twin(quiet(true)).await;
    let (client, mut events) = connect(config(&twin, None)).await;
    client.start(None).await.expect("started");
    assert_eq!(event(&mut events).await, Event::Started);
    (twin, client, events)
}

fn name(text: &str) -> ProgramName {
    ProgramName::new(text).expect("a valid name")
}

fn program(steps: usize) -> Vec<u8> {
    let mut text = String::from("%HEADER\r\nNAME=TEST\r\n%STEP\r\n");
    for step in 1..=steps {
        text.push_str(&format!("{step:04},X010.00,Y010.00,R000,Z001\r\n"));
    }
    text.push_str("*\r\n");
    text.into_bytes()
}

/// The next notice, within ten minutes of (virtual) time.
async fn notice(events: &mut Events) -> Notice {
    tokio::time::timeout(Duration::from_secs(600), events.next())
        .await
        .expect("a notice within 10 minutes")
        .expect("the client is alive")
}

/// Waits for the next notice, which must say `port` is connected.
async fn expect_connected(events: &mut Events, port: Port) {
    let next = notice(events).await;
    assert!(
        matches!(&next, Notice::Connected { port: p, .. } if *p == port),
        "{next}"
    );
}

/// Waits for the next notice, which must say `port`'s connection is gone.
async fn expect_disconnected(events: &mut Events, port: Port) {
    let next = notice(events).await;
    assert!(
        matches!(&next, Notice::Disconnected { port: p, .. } if *p == port),
        "{next}"
    );
}

/// The next R message, within ten minutes of (virtual) time.
async fn event(events: &mut Events) -> Event {
    tokio::time::timeout(Duration::from_secs(600), events.next_event())
        .await
        .expect("an R message within 10 minutes")
        .expect("the client is alive")
}

/// Everything the stream holds now, after letting the tasks run.
async fn drain(events: &mut Events) -> Vec<Notice> {
    tokio::time::sleep(Duration::from_millis(1)).await;
    let mut out = Vec::new();
    while let Ok(Some(notice)) = tokio::time::timeout(Duration::ZERO, events.next()).await {
        out.push(notice);
    }
    out
}

fn refusal(error: ClientError) -> Refusal {
    match error {
        ClientError::Refused(refusal) => refusal,
        other => panic!("expected a refusal, got {other}"),
    }
}

#[tokio::test(start_paused = true)]
async fn status_program_and_list_come_from_the_twin() {
    let twin = twin(quiet(false)).await;
    let (client, _events) = connect(config(&twin, None)).await;
    let status = client.status().await.expect("C2ST answered");
    assert_eq!(
        status,
        MachineStatus {
            state: RunState::Ready,
            mode: ControlMode::Online
        }
    );
    assert_eq!(
        client.current_program().await.expect("C3 answered"),
        name(DEMO_PROGRAM)
    );
    let list = client.program_list().await.expect("C1RP answered");
    assert_eq!(list.0.len(), 1);
    assert_eq!(list.0[0].name, name(DEMO_PROGRAM));
    assert_eq!(list.0[0].date.to_string(), "26/01/05");
}

#[tokio::test(start_paused = true)]
async fn download_upload_and_delete_a_program() {
    let twin = twin(quiet(false)).await;
    let (client, _events) = connect(config(&twin, None)).await;
    let target = Target::Product(name("PCB-42"));
    client
        .download(target.clone(), program(12))
        .await
        .expect("C0 accepted");
    assert_eq!(
        client.upload(target.clone()).await.expect("C1 answered"),
        program(12)
    );
    let names: Vec<String> = client
        .program_list()
        .await
        .expect("listed")
        .0
        .into_iter()
        .map(|e| e.name.to_string())
        .collect();
    assert_eq!(names, [DEMO_PROGRAM, "PCB-42"]);
    client.delete(target.clone()).await.expect("C0R accepted");
    let gone = refusal(client.upload(target).await.expect_err("deleted"));
    assert_eq!(gone.reply, Reply::NoSuchProgram);
    assert_eq!(
        gone.meaning(),
        "program \"PCB-42\" does not exist on the machine"
    );
}

#[tokio::test(start_paused = true)]
async fn machine_data_download_c0g_changes_the_condition_data() {
    let twin = twin(quiet(false)).await;
    let (client, _events) = connect(config(&twin, None)).await;
    let data = b"%HEADER\r\n&CONDITIONDATA1\r\n1010001,1,0,1,0\r\n*\r\n".to_vec();
    client
        .download(Target::MachineData, data)
        .await
        .expect("C0G accepted");
    // The machine stores a download when the host's closing A2 arrives, which the host
    // cannot see; the next exchange on Port 1 (one at a time, in order) comes after it.
    let uploaded = client
        .upload(Target::MachineData)
        .await
        .expect("C1G answered");
    assert!(
        String::from_utf8_lossy(&uploaded).contains("1010001,1,0,1,0"),
        "{uploaded:?}"
    );
    let condition = twin.control().with(|machine, _| machine.condition_data());
    assert!(condition.pass_through && condition.offset_manual_mark);
    assert!(!condition.evaluation_mode && !condition.evaluation_h_down);
}

#[tokio::test(start_paused = true)]
async fn downloading_the_selected_program_is_refused_in_words() {
    let twin = twin(quiet(false)).await;
    let (client, _events) = connect(config(&twin, None)).await;
    let refused = refusal(
        client
            .download(Target::Product(name(DEMO_PROGRAM)), program(3))
            .await
            .expect_err("the selected program"),
    );
    assert_eq!(refused.reply, Reply::OPERATION_ERROR);
    assert!(
        refused.meaning().contains("selected or being edited"),
        "{}",
        refused.meaning()
    );
}

#[tokio::test(start_paused = true)]
async fn remote_start_gets_a2_then_r1st_then_boards_on_port_2() {
    let twin = twin(quiet(true)).await;
    let (client, mut events) = connect(config(&twin, None)).await;
    expect_connected(&mut events, Port::Event).await;
    let started = Instant::now();
    client
        .start(Some(StopMode::Continuous))
        .await
        .expect("C5STCT answered A2");
    assert_eq!(event(&mut events).await, Event::Started);
    assert_eq!(started.elapsed(), Duration::ZERO, "R1ST comes at once");
    assert_eq!(client.status().await.expect("C2ST").state, RunState::Run);
    // A 120-step board: 4 s loading + 120 × 0.15 s.
    assert!(matches!(
        event(&mut events).await,
        Event::BoardFinished { time: Some(t) } if t.seconds() == 22
    ));
    assert_eq!(started.elapsed(), Duration::from_secs(22));
    assert!(matches!(
        event(&mut events).await,
        Event::BoardFinished { .. }
    ));
    assert_eq!(started.elapsed(), Duration::from_secs(44));
}

#[tokio::test(start_paused = true)]
async fn start_in_online_mode_is_refused_with_the_reason_in_words() {
    let twin = twin(quiet(false)).await;
    let (client, _events) = connect(config(&twin, None)).await;
    let error = client.start(None).await.expect_err("C5 needs Remote mode");
    assert!(error.is_device_error());
    assert!(
        error
            .to_string()
            .starts_with("machine refused C5ST: operation error (A4E00)"),
        "{error}"
    );
    assert!(error.to_string().contains("Remote mode"), "{error}");
    twin.control().set_mode(ControlMode::Remote);
    client.start(None).await.expect("accepted in Remote mode");
}

#[tokio::test(start_paused = true)]
async fn reset_after_an_error_stop_gets_a2_and_r1re_later() {
    let (twin, client, mut events) = running().await;
    twin.control().force_error(7).expect("a valid error code");
    assert!(matches!(event(&mut events).await, Event::Error(info) if info.code() == 7));
    assert_eq!(client.status().await.expect("C2ST").state, RunState::Error);
    let refused = refusal(client.start(None).await.expect_err("in an error stop"));
    assert_eq!(refused.reply, Reply::OPERATION_ERROR);
    let reset = Instant::now();
    client.reset().await.expect("C5RE answered A2");
    assert_eq!(client.status().await.expect("C2ST").state, RunState::Ready);
    assert_eq!(event(&mut events).await, Event::ResetDone);
    assert_eq!(reset.elapsed(), Duration::from_secs(3));
}

#[tokio::test(start_paused = true)]
async fn a_paused_feeder_stops_the_run_with_parts_exhausted() {
    let (twin, client, mut events) = running().await;
    twin.control().pause_feeder(1).expect("feeder 1 exists");
    match event(&mut events).await {
        Event::Error(info) => {
            assert!(info.is_parts_exhausted());
            assert_eq!(info.feeder(), 1);
        }
        other => panic!("expected R2E03, got {other}"),
    }
    assert_eq!(client.status().await.expect("C2ST").state, RunState::Error);
}

#[tokio::test(start_paused = true)]
async fn c3_without_a_selected_program_is_a4e01_in_words() {
    let twin = twin(MachineConfig {
        demo_program: false,
        ..quiet(false)
    })
    .await;
    let (client, _events) = connect(config(&twin, None)).await;
    let refused = refusal(
        client
            .current_program()
            .await
            .expect_err("nothing selected"),
    );
    assert_eq!(refused.reply, Reply::Invalid(A4Reason::ProtocolError));
    assert_eq!(
        refused.meaning(),
        "protocol error (A4E01): no product program is selected"
    );
}

#[tokio::test(start_paused = true)]
async fn production_data_is_kept_or_cleared() {
    let twin = twin(quiet(true)).await;
    let (client, mut events) = connect(config(&twin, None)).await;
    client
        .start(Some(StopMode::Continuous))
        .await
        .expect("started");
    for _ in 0..3 {
        event(&mut events).await;
    }
    let grand = |clear| ProductionRequest {
        scope: ProductionScope::GrandTotal,
        clear,
    };
    let kept = client.production(grand(false)).await.expect("C1M000");
    assert_eq!(kept.count(Counter::Product1), Some(2));
    assert_eq!(kept.count(Counter::Mount), Some(240));
    let cleared = client.production(grand(true)).await.expect("C1M900");
    assert_eq!(cleared.count(Counter::Product1), Some(2));
    let after = client.production(grand(false)).await.expect("C1M000");
    assert_eq!(after.count(Counter::Product1), Some(0));
    assert_eq!(after.header.name.as_deref(), Some("M000"));
}

#[tokio::test(start_paused = true)]
async fn keep_alive_runs_every_30_s_and_both_ports_answer() {
    let twin = twin(quiet(false)).await;
    let (_client, mut events) = connect(config(&twin, Some(KeepAliveConfig::default()))).await;
    let started = Instant::now();
    let mut echoes = Vec::new();
    while echoes.len() < 3 {
        match notice(&mut events).await {
            Notice::Event(Event::Heartbeat { id }) => {
                echoes.push((id.to_string(), started.elapsed()));
            }
            Notice::Connected { .. } => {}
            other => panic!("unexpected {other}"),
        }
    }
    assert_eq!(
        echoes,
        [
            ("000001".to_owned(), Duration::from_secs(30)),
            ("000002".to_owned(), Duration::from_secs(60)),
            ("000003".to_owned(), Duration::from_secs(90)),
        ]
    );
}

#[tokio::test(start_paused = true)]
async fn keep_alive_on_demand_reports_both_ports() {
    let twin = twin(quiet(false)).await;
    let (client, _events) = connect(config(&twin, None)).await;
    let report = client.keep_alive().await.expect("both ports answer");
    assert_eq!(report.id.as_str(), "H00001");
    assert_eq!(report.port2, Some(Duration::ZERO));
    twin.control().break_port(Port::Event, PortFault::Silent);
    let error = client.keep_alive().await.expect_err("Port 2 is silent");
    assert!(matches!(error, ClientError::NoEcho { .. }), "{error}");
    assert!(
        error
            .to_string()
            .contains("no R1HB00H00002 came back on Port 2"),
        "{error}"
    );
}

#[tokio::test(start_paused = true)]
async fn a_silent_port_2_is_found_dead_by_the_keep_alive_and_reconnected() {
    let twin = twin(quiet(false)).await;
    let (client, mut events) = connect(config(&twin, Some(KeepAliveConfig::default()))).await;
    expect_connected(&mut events, Port::Event).await;
    expect_connected(&mut events, Port::Command).await;
    twin.control().connected(Port::Event).await;
    twin.control().break_port(Port::Event, PortFault::Silent);
    let started = Instant::now();
    // The check at 30 s gets its A2 but no R1HB: dead at 40 s, reconnected at once.
    assert_eq!(
        notice(&mut events).await,
        Notice::KeepAliveFailed {
            id: KeepAliveId::sequence(1),
            port1: false,
            port2: true
        }
    );
    assert_eq!(started.elapsed(), Duration::from_secs(40));
    expect_disconnected(&mut events, Port::Event).await;
    expect_connected(&mut events, Port::Event).await;
    assert_eq!(started.elapsed(), Duration::from_millis(40_500));
    assert_eq!(
        twin.control().fault(Port::Event),
        None,
        "a new connection ends the silence"
    );
    // The next check, 30 s after the failed one, works on the new connection.
    assert_eq!(
        event(&mut events).await,
        Event::Heartbeat {
            id: KeepAliveId::sequence(2)
        }
    );
    assert_eq!(started.elapsed(), Duration::from_secs(60));
    client.status().await.expect("Port 1 was never affected");
}

#[tokio::test(start_paused = true)]
async fn a_silent_port_1_is_found_dead_by_the_keep_alive_and_reconnected() {
    let twin = twin(quiet(false)).await;
    let (client, mut events) = connect(config(&twin, Some(KeepAliveConfig::default()))).await;
    // The host's connection is up before the server accepted it: a fault set earlier
    // would act on no connection (and the late accept would end the silence).
    twin.control().connected(Port::Command).await;
    twin.control().break_port(Port::Command, PortFault::Silent);
    let started = Instant::now();
    let mut seen = Vec::new();
    loop {
        match notice(&mut events).await {
            Notice::KeepAliveFailed { port1, port2, .. } => {
                // C2HB unanswered (the machine heard nothing), so no R1HB either.
                assert!(port1 && port2);
                assert_eq!(started.elapsed(), Duration::from_secs(40));
                seen.push("dead");
            }
            Notice::Disconnected { port, .. } => seen.push(match port {
                Port::Command => "port 1 closed",
                Port::Event => "port 2 closed",
            }),
            Notice::Connected {
                port: Port::Command,
                ..
            } if !seen.is_empty() => {
                seen.push("port 1 reconnected");
                break;
            }
            _ => {}
        }
    }
    // The C2HB's own 5 s answer time-out closes Port 1 first (at 35 s).
    assert_eq!(seen[0], "port 1 closed");
    assert!(seen.contains(&"dead"), "{seen:?}");
    assert_eq!(twin.control().fault(Port::Command), None);
    assert_eq!(
        client.status().await.expect("Port 1 works again").mode,
        ControlMode::Online
    );
}

#[tokio::test(start_paused = true)]
async fn a_lost_answer_to_a_status_request_is_asked_again_on_a_new_connection() {
    let twin = twin(quiet(false)).await;
    let (client, _events) = connect(config(&twin, None)).await;
    client.status().await.expect("connected and answered");
    twin.control().break_port(Port::Command, PortFault::Silent);
    let started = Instant::now();
    let status = client
        .status()
        .await
        .expect("answered on the second attempt");
    assert_eq!(status.state, RunState::Ready);
    assert_eq!(started.elapsed(), DEFAULT_TIMEOUT);
}

#[tokio::test(start_paused = true)]
async fn a_lost_answer_to_a_start_is_not_repeated_and_says_why() {
    let twin = twin(quiet(true)).await;
    let (client, _events) = connect(config(&twin, None)).await;
    client.status().await.expect("connected");
    twin.control().break_port(Port::Command, PortFault::Silent);
    let error = client.start(None).await.expect_err("no answer");
    let text = error.to_string();
    assert!(
        text.starts_with(&format!(
            "no answer to C5ST from the machine at tcp://127.0.0.1:{} (Port 1) after 1 attempt of 5s each (last: no answer); not repeated",
            twin.command_addr().port()
        )),
        "{text}"
    );
    assert_eq!(
        twin.control().status().state,
        RunState::Ready,
        "never started"
    );
}

#[tokio::test(start_paused = true)]
async fn a_second_host_on_port_1_is_turned_away_and_the_first_keeps_working() {
    let twin = twin(quiet(false)).await;
    let (first, _events) = connect(config(&twin, None)).await;
    first.status().await.expect("the first host holds Port 1");
    let second = ClientConfig::commands_only("127.0.0.1", twin.command_addr().port());
    let (second, _) = connect(second).await;
    let error = second.status().await.expect_err("turned away");
    let text = error.to_string();
    assert!(text.contains("after 2 attempts"), "{text}");
    assert!(text.contains("is another host connected?"), "{text}");
    first
        .status()
        .await
        .expect("the first host is still served");
    drop(first);
    tokio::time::sleep(Duration::from_millis(1)).await;
    second
        .status()
        .await
        .expect("served once the first host left");
}

#[tokio::test(start_paused = true)]
async fn a_closed_port_is_named_with_what_to_check() {
    let listener = std::net::TcpListener::bind(local()).expect("binds");
    let port = listener.local_addr().expect("bound").port();
    drop(listener);
    let config = ClientConfig::commands_only("127.0.0.1", port);
    let (client, _) = connect(config).await;
    let error = client.status().await.expect_err("nobody listens");
    let text = error.to_string();
    assert!(
        text.starts_with(&format!(
            "Port 1 (commands): cannot connect to tcp://127.0.0.1:{port}"
        )),
        "{text}"
    );
    assert!(error.is_device_error());
}

#[tokio::test(start_paused = true)]
async fn the_event_stream_survives_a_cut_port_2() {
    let twin = twin(quiet(true)).await;
    let (client, mut events) = connect(config(&twin, None)).await;
    notice(&mut events).await;
    // Cut the connection the server holds, not one it has yet to accept.
    twin.control().connected(Port::Event).await;
    twin.control().cut(Port::Event);
    expect_disconnected(&mut events, Port::Event).await;
    expect_connected(&mut events, Port::Event).await;
    client.start(None).await.expect("started");
    assert_eq!(event(&mut events).await, Event::Started);
}

#[tokio::test(start_paused = true)]
async fn a_dropped_port_2_loses_no_r_message_beyond_the_buffer_rule() {
    let machine = MachineConfig {
        seed: 7,
        ..quiet(true)
    };
    let keep_alive = KeepAliveConfig::default();
    // What the machine says in two hours to a host that always listens, starts it at 0 and
    // checks the link every 30 s: the keep-alive echoes number the stream.
    let reference = {
        let t0 = std::time::Instant::now();
        let mut machine = Machine::new(machine.clone()).expect("valid");
        machine.host_connected_on_port2(true, t0);
        let bytes = |command: Command| command.to_message().expect("fits").to_bytes();
        machine.handle_port1(&bytes(Command::Start(Some(StopMode::Continuous))), t0);
        for n in 1..240 {
            let at = t0 + keep_alive.interval * u32::try_from(n).expect("small");
            machine.handle_port1(&bytes(Command::KeepAlive(KeepAliveId::sequence(n))), at);
        }
        machine
            .poll_events(t0 + Duration::from_secs(7200))
            .iter()
            .map(|m| Event::parse(m).expect("the twin sends valid R messages"))
            .collect::<Vec<_>>()
    };
    let twin = twin(machine).await;
    let (client, mut events) = connect(config(&twin, Some(keep_alive))).await;
    client
        .start(Some(StopMode::Continuous))
        .await
        .expect("started");
    // Ten minutes of production, then Port 2 goes down for half an hour (about 80 boards
    // and 60 echoes), then comes back; the host reconnects with backoff.
    tokio::time::sleep(Duration::from_secs(600)).await;
    twin.control().break_port(Port::Event, PortFault::Down);
    tokio::time::sleep(Duration::from_secs(1800)).await;
    twin.control().heal(Port::Event);
    tokio::time::sleep(Duration::from_secs(1200)).await;
    twin.control().stop();
    let mut heard = Vec::new();
    let mut notices = Vec::new();
    for notice in drain(&mut events).await {
        match notice {
            Notice::Event(event) => heard.push(event),
            Notice::Missed { count } => panic!("the test reader missed {count} notices"),
            other => notices.push(other),
        }
    }
    let dropped = twin.control().with(|machine, _| machine.dropped_events());
    let dropped = usize::try_from(dropped).expect("small");
    assert!(dropped > 0, "the outage outlasted the buffer");
    // What was heard is the reference with exactly one gap of `dropped` messages.
    let gap = heard
        .iter()
        .zip(&reference)
        .position(|(a, b)| a != b)
        .expect("the outage lost the oldest messages");
    assert!(
        heard.len() - gap > crate::twin::EVENT_BUFFER_LEN,
        "the 40 buffered messages and the later ones arrived"
    );
    assert_eq!(
        heard[gap..],
        reference[gap + dropped..gap + dropped + (heard.len() - gap)],
        "after the gap, every message in order"
    );
    let port2 = |n: &&Notice| match n {
        Notice::Connected { port, .. }
        | Notice::Disconnected { port, .. }
        | Notice::ConnectFailed { port, .. } => *port == Port::Event,
        _ => false,
    };
    let port2: Vec<&Notice> = notices.iter().filter(port2).collect();
    assert!(
        port2
            .iter()
            .filter(|n| matches!(n, Notice::Disconnected { .. }))
            .count()
            >= 2,
        "the drop, then reconnections turned away while the port was down"
    );
    assert!(matches!(port2.last(), Some(Notice::Connected { .. })));
    assert!(notices.iter().any(|n| matches!(
        n,
        Notice::KeepAliveFailed {
            port1: false,
            port2: true,
            ..
        }
    )));
}

#[test]
fn a_port_1_that_never_stops_talking_still_ends_the_attempt_at_its_timeout() {
    let ended = testkit::ends_within(Duration::from_secs(60), || async {
        let event = Event::Heartbeat {
            id: KeepAliveId::sequence(1),
        };
        let line = link::Line::from_stream(
            testkit::Chatter::after_request(event.to_message().to_bytes()),
            "chatty",
            None,
        );
        let mut port1 = port1::Port1 {
            line: Some(line),
            ..port1::Port1::default()
        };
        let command = Command::Status;
        let request = command.to_message().expect("fits").to_bytes();
        let attempt = port1
            .attempt(&command, &request, Duration::from_millis(20))
            .await;
        match attempt {
            Ok(_) => "answered".to_owned(),
            Err(port1::Failure::Trouble(trouble)) => format!("trouble: {trouble:?}"),
            Err(port1::Failure::Refused(_)) => "refused".to_owned(),
            Err(port1::Failure::Protocol(e)) => format!("protocol: {e}"),
        }
    });
    let ended = ended.expect("the attempt ends although Port 1 never falls silent");
    assert_eq!(
        ended, "trouble: Silence",
        "R messages on Port 1 are skipped: no answer came"
    );
}
