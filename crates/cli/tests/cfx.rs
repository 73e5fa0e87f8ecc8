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
    require_python(
        "import proton",
        "IPC-CFX interoperability test",
        "python-qpid-proton",
        &format!("run scripts/test, which installs it, or: python3 -m pip install {PIP}"),
    );
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/cfx/receiver.py");
    let mut child = Command::new("python3")
        .arg(script)
        .arg(port.to_string())
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
    let port = first
        .strip_prefix("listening on ")
        .and_then(|p| p.parse().ok())
        .unwrap_or_else(|| panic!("not a port: {first}"));
    (Receiver { child, lines }, port)
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
    assert_eq!(
        health["cfx"],
        format!("connected to amqp://127.0.0.1:{port}/cfx"),
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
