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
/// 15 s later (generous for CI's two loaded cores).
const WITHIN: Duration = Duration::from_secs(240);

const HANDLE: &str = "cellbus.demo.placer1";

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

/// Starts the receiver; its port.
fn receiver() -> (Receiver, u16) {
    require_python(
        "import proton",
        "IPC-CFX interoperability test",
        "python-qpid-proton",
        &format!("run scripts/test, which installs it, or: python3 -m pip install {PIP}"),
    );
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/cfx/receiver.py");
    let mut child = Command::new("python3")
        .arg(script)
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
    let (receiver, port) = receiver();
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
}
