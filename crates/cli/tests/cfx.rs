//! The demo's placement machine as an IPC-CFX endpoint, received by a consumer nobody
//! here wrote: python-qpid-proton listening for AMQP 1.0 (`tests/cfx/receiver.py`). A
//! demo minute brings the endpoint's `EndpointConnected`, its state changes, a board's
//! `WorkStarted`/`WorkCompleted`, a parts-exhausted `FaultOccurred` and its `FaultCleared`,
//! each with the SDK's envelope and AMQP properties.

mod common;

use std::collections::HashSet;
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use common::{Gateway, require_python};
use serde_json::Value;
use testkit::RabbitMq;

/// The version scripts/test installs.
const PIP: &str = "python-qpid-proton==0.40.0";

/// A demo minute and a half: the first parts exhaustion comes at about 52 s, its clearing
/// 15 s later (generous for CI's two loaded cores). Also the bound of each wait after the
/// receiver's outage.
const WITHIN: Duration = Duration::from_secs(240);

const HANDLE: &str = "cellbus.demo.placer1";

/// A process killed when dropped.
struct Killed(Child);

impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The receiver, killed when dropped.
struct Receiver {
    child: Child,
    lines: mpsc::Receiver<String>,
}

impl Drop for Receiver {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Starts the receiver on `port` (0: a free one); its port.
fn start_receiver(port: u16) -> (Receiver, u16) {
    let (receiver, first) = spawn_receiver(&[&port.to_string()]);
    let port = first
        .strip_prefix("listening on ")
        .and_then(|p| p.parse().ok())
        .unwrap_or_else(|| panic!("not a port: {first}"));
    (receiver, port)
}

/// Starts the receiver as a consumer of `address` at the broker `url`.
fn start_consumer(url: &str, address: &str) -> Receiver {
    let (receiver, first) = spawn_receiver(&["--from", url, address]);
    assert_eq!(first, format!("receiving from {address}"));
    receiver
}

/// Runs `receiver.py` with `args`; the receiver and its first line.
fn spawn_receiver(args: &[&str]) -> (Receiver, String) {
    require_python(
        "import proton",
        "IPC-CFX interoperability test",
        "python-qpid-proton",
        &format!("run scripts/test, which installs it, or: python3 -m pip install {PIP}"),
    );
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/cfx/receiver.py");
    let mut child = Command::new("python3")
        .arg(script)
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("python3 runs the receiver");
    let stdout = child.stdout.take().expect("piped");
    let (tx, lines) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    let first = lines
        .recv_timeout(Duration::from_secs(60))
        .expect("the receiver says where it listens");
    (Receiver { child, lines }, first)
}

#[test]
fn a_demo_minute_reaches_a_proton_receiver_as_cfx_messages_with_the_sdks_envelope_and_properties() {
    let (receiver, port) = start_receiver(0);
    let data = tempfile::tempdir().unwrap();
    let url = format!("amqp://127.0.0.1:{port}/cfx");
    let gateway = Gateway::start_with(data.path(), &["--cfx", &url]);

    let wanted = [
        "CFX.EndpointConnected",
        "CFX.ResourcePerformance.StationStateChanged",
        "CFX.Production.WorkStarted",
        "CFX.Production.WorkCompleted",
        "CFX.ResourcePerformance.FaultOccurred",
        "CFX.ResourcePerformance.FaultCleared",
        "CFX.Heartbeat",
        // The program, read once at the start (whether before or after the interface took
        // the change stream).
        "CFX.Production.RecipeActivated",
    ];
    let started = Instant::now();
    let mut messages: Vec<Value> = Vec::new();
    while !wanted
        .iter()
        .all(|name| messages.iter().any(|m| m["body"]["MessageName"] == *name))
    {
        let left = WITHIN.saturating_sub(started.elapsed());
        let line = receiver.lines.recv_timeout(left).unwrap_or_else(|_| {
            let seen: Vec<_> = messages
                .iter()
                .map(|m| m["body"]["MessageName"].clone())
                .collect();
            panic!("not every kind of message came in {WITHIN:?}; seen: {seen:?}")
        });
        messages.push(serde_json::from_str(&line).unwrap());
    }
    assert_eq!(messages[0]["body"]["MessageName"], "CFX.EndpointConnected");

    let mut ids = HashSet::new();
    for m in &messages {
        let envelope = &m["body"];
        let name = envelope["MessageName"].as_str().unwrap();
        assert_eq!(m["address"], "cfx", "{m}");
        assert_eq!(envelope["Version"], "2.1", "{m}");
        assert_eq!(envelope["Source"], HANDLE, "{m}");
        assert_eq!(
            envelope["MessageBody"]["$type"],
            format!("{name}, CFX"),
            "{m}"
        );
        assert_eq!(m["message_id"], envelope["UniqueID"], "{m}");
        assert_eq!(m["subject"], format!("{HANDLE}.{name}"), "{m}");
        assert_eq!(
            m["content_type"], "application/json; charset=\"utf-8\"",
            "{m}"
        );
        assert_eq!(m["reply_to"], HANDLE, "{m}");
        assert_eq!(m["durable"], true, "{m}");
        let properties = &m["properties"];
        assert_eq!(properties["cfx-message"], name, "{m}");
        assert_eq!(properties["cfx-handle"], HANDLE, "{m}");
        assert_eq!(
            properties["cfx-topic"],
            name.rsplit_once('.').unwrap().0,
            "{m}"
        );
        assert_eq!(properties["cfx-target"], Value::Null, "{m}");
        let stamp = envelope["TimeStamp"].as_str().unwrap();
        assert!(
            stamp.len() == "2026-11-29T20:00:00.0000000+00:00".len(),
            "{stamp}"
        );
        assert!(
            ids.insert(envelope["UniqueID"].to_string()),
            "sent twice: {m}"
        );
    }

    let body = |name: &str| -> Vec<&Value> {
        messages
            .iter()
            .filter(|m| m["body"]["MessageName"] == name)
            .map(|m| &m["body"]["MessageBody"])
            .collect()
    };
    let fault = body("CFX.ResourcePerformance.FaultOccurred")[0]["Fault"].clone();
    assert_eq!(fault["PlacementFaultType"], "PartsExhaust", "{fault}");
    assert_eq!(fault["MaterialLocation"]["LocationName"], "7", "{fault}");
    assert!(
        body("CFX.ResourcePerformance.FaultCleared")
            .iter()
            .any(|c| c["FaultOccurrenceId"] == fault["FaultOccurrenceId"]),
        "the fault is cleared by its occurrence id"
    );
    let completed = body("CFX.Production.WorkCompleted")[0];
    assert!(
        body("CFX.Production.WorkStarted")
            .iter()
            .any(|s| s["TransactionID"] == completed["TransactionID"]),
        "a board's start and end share their transaction"
    );
    assert!(
        body("CFX.ResourcePerformance.StationStateChanged")
            .iter()
            .any(|s| s["NewState"] == 5500 || s["NewState"] == 5000),
        "the machine stopped for the parts"
    );
    let health = gateway.get_json("/healthz");
    // (Followed by how many messages wait, while some do.)
    assert!(
        health["cfx"]
            .as_str()
            .is_some_and(|s| s.starts_with(&format!("connected to amqp://127.0.0.1:{port}/cfx"))),
        "{health}"
    );

    // The receiver goes away for a while: what the machine does meanwhile waits, and comes
    // once each, in order, after a new EndpointConnected, when a receiver is back.
    drop(receiver);
    let down = Instant::now();
    loop {
        let health = gateway.get_json("/healthz");
        if health["cfx"]
            .as_str()
            .is_some_and(|l| l.starts_with("disconnected"))
        {
            assert_eq!(health["status"], "degraded", "{health}");
            break;
        }
        assert!(
            down.elapsed() < WITHIN,
            "the link never went down: {health}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    // At least one board's time (the demo finishes one about every 20 s while it runs).
    std::thread::sleep(Duration::from_secs(25));
    let reconnected = now_text();
    let (receiver, _) = start_receiver(port);
    let back = Instant::now();
    let mut after: Vec<Value> = Vec::new();
    // Until something made after the reconnection arrives: all before it waited.
    while !after.iter().any(|m| {
        m["body"]["MessageName"] != "CFX.EndpointConnected"
            && m["body"]["TimeStamp"].as_str() > Some(reconnected.as_str())
    }) {
        let left = WITHIN.saturating_sub(back.elapsed());
        let Ok(line) = receiver.lines.recv_timeout(left) else {
            panic!("nothing made after the reconnection came; got {after:#?}")
        };
        after.push(serde_json::from_str(&line).unwrap());
    }
    assert_eq!(after[0]["body"]["MessageName"], "CFX.EndpointConnected");
    for m in &after {
        assert!(
            ids.insert(m["body"]["UniqueID"].to_string()),
            "sent twice: {m}"
        );
    }
    let waited: Vec<&Value> = after[1..]
        .iter()
        .map(|m| &m["body"])
        .filter(|b| b["TimeStamp"].as_str() < Some(reconnected.as_str()))
        .collect();
    assert!(
        waited.iter().any(|b| b["MessageName"] != "CFX.Heartbeat"),
        "nothing waited for the link: {after:#?}"
    );
    assert!(
        waited.iter().all(|b| b["MessageName"] != "CFX.Heartbeat"),
        "heartbeats are not kept while the link is down: {after:#?}"
    );
    // In the order they happened (a board's start is dated back by its time).
    let times: Vec<&str> = waited
        .iter()
        .filter(|b| b["MessageName"] != "CFX.Production.WorkStarted")
        .map(|b| b["TimeStamp"].as_str().unwrap())
        .collect();
    let mut sorted = times.clone();
    sorted.sort_unstable();
    assert_eq!(times, sorted, "in the order they happened");
}

/// Through a broker nobody here wrote (Debian's RabbitMQ 3.10 with its AMQP 1.0 plugin,
/// publishing to `/exchange/cfx` as a CFX line on RabbitMQ 3.x does): the broker is
/// stopped, the gateway goes on making messages and is killed (`kill -9`) while it is
/// down, the broker comes back and the gateway starts again on the same data. Every board
/// and parts exhaustion the gateway recorded before the kill reaches the consumer, each
/// message once, with what waited in the order it happened.
#[test]
fn through_rabbitmq_a_broker_restart_and_a_gateway_killed_meanwhile_lose_no_message() {
    let mut broker = RabbitMq::start("cfx", "mes");
    let broker_url = format!("amqp://127.0.0.1:{}", broker.port());
    let consumer = start_consumer(&broker_url, "/amq/queue/mes");
    let data = tempfile::tempdir().unwrap();
    let cfx = format!("{broker_url}//exchange/cfx");
    let args = ["--cfx", cfx.as_str()];
    let began = common::now_ms();
    let gateway = Gateway::start_with(data.path(), &args);

    let mut received: Vec<Value> = Vec::new();
    let mut take = |until: &dyn Fn(&[Value]) -> bool, what: &str| {
        let started = Instant::now();
        while !until(&received) {
            let left = WITHIN.saturating_sub(started.elapsed());
            let Ok(line) = consumer.lines.recv_timeout(left) else {
                panic!("{what} did not come in {WITHIN:?}; got {received:#?}")
            };
            received.push(serde_json::from_str(&line).unwrap());
        }
    };
    let named =
        |name: &'static str| move |r: &[Value]| r.iter().any(|m| m["body"]["MessageName"] == name);
    take(
        &named("CFX.ResourcePerformance.StationStateChanged"),
        "a state",
    );

    // The broker goes away; the gateway keeps what it makes until a board is finished.
    broker.stop();
    let stopped = common::now_ms();
    wait_for(&gateway, "the link down and a board kept", |g| {
        let health = g.get_json("/healthz");
        let down = health["cfx"]
            .as_str()
            .is_some_and(|l| l.starts_with("disconnected"));
        // A board finished more than the second the check below leaves out.
        let settled = common::now_ms() - 1500;
        down && waiting(g) > 0 && !events(g, "board_finished", stopped, settled).is_empty()
    });
    drop(gateway); // kill -9
    let killed = common::now_ms();

    broker.start_again();
    let gateway = Gateway::start_with(data.path(), &args);
    let restarted = now_text();
    // Until something made after the restart arrives: all before it was sent before it.
    take(
        &|r: &[Value]| {
            r.iter().any(|m| {
                m["body"]["MessageName"] != "CFX.EndpointConnected"
                    && m["body"]["TimeStamp"].as_str() > Some(restarted.as_str())
            })
        },
        "a message made after the restart",
    );
    wait_for(&gateway, "nothing waiting", |g| waiting(g) == 0);

    // A message in flight when the broker stopped may come twice (accepted by the queue,
    // its verdict lost with the connection: it is sent again): then with its id and
    // content, so that a receiver drops the second.
    let mut by_id = std::collections::HashMap::new();
    for m in &received {
        assert_eq!(m["properties"]["cfx-handle"], HANDLE, "{m}");
        if let Some(first) = by_id.insert(m["body"]["UniqueID"].to_string(), &m["body"]) {
            assert_eq!(first, &m["body"], "one id, two messages");
        }
    }
    let mut seen = HashSet::new();
    received.retain(|m| seen.insert(m["body"]["UniqueID"].to_string()));
    // Every board and parts exhaustion recorded before the kill (but its last second,
    // which the outbox and the history commit apart) has its message.
    let times = |name: &str| -> Vec<i64> {
        received
            .iter()
            .filter(|m| m["body"]["MessageName"] == name)
            .map(|m| envelope_ms(&m["body"]))
            .collect()
    };
    let completed = times("CFX.Production.WorkCompleted");
    let boards = events(&gateway, "board_finished", began, killed - 1000);
    assert!(!boards.is_empty(), "no board before the kill");
    for t in &boards {
        assert!(
            completed.contains(t),
            "the board of {t} has no WorkCompleted: {completed:?}"
        );
    }
    let faults = times("CFX.ResourcePerformance.FaultOccurred");
    for t in events(&gateway, "parts_exhausted", began, killed - 1000) {
        assert!(
            faults.contains(&t),
            "the exhaustion of {t} has no FaultOccurred"
        );
    }
    // What waited through the outage and the kill came after the restart, in order.
    let waited: Vec<i64> = received
        .iter()
        .map(|m| &m["body"])
        .filter(|b| {
            b["MessageName"] != "CFX.Production.WorkStarted"
                && b["MessageName"] != "CFX.EndpointConnected"
                && b["MessageName"] != "CFX.EndpointShuttingDown"
        })
        .map(envelope_ms)
        .filter(|t| (stopped..killed).contains(t))
        .collect();
    assert!(!waited.is_empty(), "nothing made during the outage came");
    // The restarted gateway's station went on from what it knew: its first state change
    // is not one from the unknown (6000) again.
    let from_unknown = received
        .iter()
        .filter(|m| m["body"]["MessageBody"]["OldState"] == 6000)
        .count();
    assert_eq!(
        from_unknown, 1,
        "the station forgot its state across the restart"
    );
    assert!(waited.is_sorted(), "in the order they happened: {waited:?}");
}

/// SASL PLAIN with the password from the environment (`username`, `password_env`): the
/// broker takes the right one and refuses a wrong one, which `/healthz` says.
#[test]
fn with_a_user_and_the_password_in_the_environment_the_broker_takes_the_gateway() {
    let broker = RabbitMq::start("cfx", "mes");
    let consumer = start_consumer(
        &format!("amqp://127.0.0.1:{}", broker.port()),
        "/amq/queue/mes",
    );
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("cell.toml");
    std::fs::write(
        &config,
        format!(
            "[cfx]\nbroker = \"amqp://127.0.0.1:{}\"\naddress = \"/exchange/cfx\"\n\
             username = \"guest\"\npassword_env = \"CELLBUS_CFX_PASSWORD\"\n\
             [cfx.handles]\nplacer1 = \"Panasonic.BM221.SN1\"\n\n\
             [[line]]\nname = \"lan\"\nendpoint = \"tcp://127.0.0.1:{}\"\n\
             [[line.device]]\nid = \"placer1\"\nprotocol = \"panasonic\"\n",
            broker.port(),
            testkit::free_port()
        ),
    )
    .unwrap();
    let start = |password: &str, data: &str| {
        Gateway::start_with_env(
            &dir.path().join(data),
            &["--config", config.to_str().unwrap()],
            &[("CELLBUS_CFX_PASSWORD", password)],
        )
    };

    let refused = start("not the password", "refused");
    wait_for(&refused, "the login refused", |g| {
        // 503: the machine is not there either.
        let (_, body) = g.get("/healthz");
        let health: Value = serde_json::from_str(&body).unwrap();
        health["cfx"].as_str().is_some_and(|l| {
            l.starts_with("disconnected: cannot connect")
                && l.contains(
                    "the broker refused the user guest with the password in CELLBUS_CFX_PASSWORD",
                )
        })
    });
    drop(refused);

    let _taken = start("guest", "taken");
    let started = Instant::now();
    loop {
        let left = WITHIN.saturating_sub(started.elapsed());
        let line = consumer
            .lines
            .recv_timeout(left)
            .expect("the gateway's EndpointConnected");
        let m: Value = serde_json::from_str(&line).unwrap();
        if m["body"]["MessageName"] == "CFX.EndpointConnected" {
            assert_eq!(m["body"]["Source"], "Panasonic.BM221.SN1");
            break;
        }
    }
}

/// Polls `gateway` until `ready` (at most [`WITHIN`]).
fn wait_for(gateway: &Gateway, what: &str, ready: impl Fn(&Gateway) -> bool) {
    let started = Instant::now();
    while !ready(gateway) {
        assert!(started.elapsed() < WITHIN, "{what}: not within {WITHIN:?}");
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// `cellbus_cfx_waiting`: the messages kept in the outbox.
fn waiting(gateway: &Gateway) -> i64 {
    let (status, metrics) = gateway.get("/metrics");
    assert_eq!(status, 200);
    metrics
        .lines()
        .find_map(|l| l.strip_prefix("cellbus_cfx_waiting "))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("no cellbus_cfx_waiting in {metrics}"))
}

/// The times (ms) of the placement machine's device events named `name` in the
/// gateway's history, in `[from, to]`.
fn events(gateway: &Gateway, name: &str, from: i64, to: i64) -> Vec<i64> {
    let answer = gateway.get_json("/api/events?device=placer1&kind=device_event&limit=1000");
    answer["events"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| e["fields"]["event"] == name)
        .map(|e| common::rfc3339_ms(e["t"].as_str().unwrap()))
        .filter(|t| (from..=to).contains(t))
        .collect()
}

/// An envelope's `TimeStamp` in ms since the epoch.
fn envelope_ms(envelope: &Value) -> i64 {
    let stamp = envelope["TimeStamp"].as_str().unwrap();
    stamp
        .parse::<jiff::Timestamp>()
        .unwrap_or_else(|e| panic!("{stamp}: {e}"))
        .as_millisecond()
}

/// Now as the envelopes write it, in the machine's zone (the demo cell's): compared as
/// text with their `TimeStamp`s.
fn now_text() -> String {
    jiff::Timestamp::now()
        .to_zoned(jiff::tz::TimeZone::system())
        .strftime("%Y-%m-%dT%H:%M:%S%.7f%:z")
        .to_string()
}

#[test]
fn the_endpoint_answers_a_proton_requester_at_its_handle_and_refuses_what_it_does_not_support() {
    let (_receiver, port) = start_receiver(0);
    let data = tempfile::tempdir().unwrap();
    let url = format!("amqp://127.0.0.1:{port}/cfx");
    let mut command = common::cellbus();
    command
        .args(["serve", "--listen", "127.0.0.1:0", "--data"])
        .arg(data.path())
        .args(["--cfx", &url, "--cfx-listen", "127.0.0.1:0"]);
    let (mut child, mut stdout, _) = common::start_listening(&mut command, "listening on http://");
    let listener = common::line_after(&mut stdout, "cfx on ");
    assert!(listener.starts_with("amqp://127.0.0.1:"), "{listener}");
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/cfx/requester.py");
    let names = [
        "CFX.AreYouThereRequest",
        "CFX.WhoIsThereRequest",
        "CFX.GetEndpointInformationRequest",
        "CFX.Production.GetActiveRecipeRequest",
    ];
    let out = Command::new("python3")
        .arg(script)
        .arg(&listener)
        .arg(HANDLE)
        .args(names)
        .output()
        .expect("python3 runs the requester");
    let _ = child.kill();
    let _ = child.wait();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let answers: Vec<Value> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let answer = |request: usize| {
        answers
            .iter()
            .find(|a| a["correlation_id"] == format!("request-{request}"))
            .unwrap_or_else(|| panic!("no answer to request {request}: {answers:#?}"))
    };
    let expected = [
        "CFX.AreYouThereResponse",
        "CFX.WhoIsThereResponse",
        "CFX.GetEndpointInformationResponse",
        "CFX.NotSupportedResponse",
    ];
    for (request, name) in expected.iter().enumerate() {
        let a = answer(request);
        let envelope = &a["body"];
        assert_eq!(envelope["MessageName"], *name, "{a}");
        assert_eq!(envelope["Source"], HANDLE, "{a}");
        assert_eq!(envelope["Target"], "MES.Line1.Host", "{a}");
        assert_eq!(envelope["RequestID"], format!("request-{request}"), "{a}");
        assert_eq!(a["to"], "MES.Line1.Host", "{a}");
        assert_eq!(a["properties"]["cfx-target"], "MES.Line1.Host", "{a}");
    }
    let there = &answer(0)["body"]["MessageBody"];
    assert_eq!(there["Result"]["Result"], "Success");
    assert_eq!(there["RequestNetworkUri"], format!("{listener}/"));
    assert_eq!(there["RequestTargetAddress"], HANDLE);
    let info = &answer(2)["body"]["MessageBody"]["EndpointInformation"];
    assert_eq!(info["CFXHandle"], HANDLE, "{info}");
    assert_eq!(info["ModelNumber"], "panasonic", "{info}");
    let refused = &answer(3)["body"]["MessageBody"]["RequestResult"];
    assert_eq!(refused["Result"], "Failed", "{refused}");
    assert!(
        refused["Message"]
            .as_str()
            .unwrap()
            .contains("CFX.Production.GetActiveRecipeRequest is not supported"),
        "{refused}"
    );
}

#[test]
fn cfx_sub_as_the_receiver_prints_what_the_gateway_sends_and_from_a_source_address_each_envelope_of_a_batch()
 {
    // As the receiver, for serve --cfx: the endpoint's first messages, in words.
    let (sub, mut out, endpoint) = common::start_listening(
        common::cellbus().args([
            "cfx",
            "sub",
            "--listen",
            "127.0.0.1:0",
            "--count",
            "2",
            "--timeout",
            "120s",
        ]),
        "listening on ",
    );
    let sub = Killed(sub);
    let data = tempfile::tempdir().unwrap();
    let url = format!("{endpoint}/cfx");
    let gateway = Gateway::start_with(data.path(), &["--cfx", &url]);
    let first = common::line_after(&mut out, "");
    assert!(
        first.contains(&format!(" {HANDLE} CFX.EndpointConnected {{")),
        "{first}"
    );
    drop(gateway);
    drop(sub);

    // From an address (python-qpid-proton as the source): a batch is two lines.
    require_python(
        "import proton",
        "IPC-CFX interoperability test",
        "python-qpid-proton",
        &format!("run scripts/test, which installs it, or: python3 -m pip install {PIP}"),
    );
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/cfx/source.py");
    let (source, _, port) =
        common::start_listening(Command::new("python3").arg(script), "listening on ");
    let _source = Killed(source);
    let out = common::run_within(
        &[
            "cfx",
            "sub",
            &format!("amqp://127.0.0.1:{port}/cfx"),
            "--count",
            "2",
            "--json",
            "--timeout",
            "60s",
        ],
        Duration::from_secs(90),
    );
    assert!(out.status.success(), "{}", common::stderr(&out));
    let lines: Vec<Value> = common::stdout(&out)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let names: Vec<&str> = lines
        .iter()
        .map(|l| l["envelope"]["MessageName"].as_str().unwrap_or_default())
        .collect();
    assert_eq!(
        names[..3],
        [
            "CFX.ResourcePerformance.StationOffline",
            "CFX.ResourcePerformance.StationOnline",
            "CFX.EndpointShuttingDown"
        ]
    );

    // Nobody there: exit 1, saying so.
    let out = common::run_within(
        &["cfx", "sub", "amqp://127.0.0.1:1/cfx", "--timeout", "20s"],
        Duration::from_secs(60),
    );
    assert_eq!(out.status.code(), Some(1));
    common::assert_stderr_has(&out, "cannot connect to amqp://127.0.0.1:1");
}
