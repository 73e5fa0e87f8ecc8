//! The demo cell's alarms through the real binary: sealer 0's band passes its 120 °C limit
//! in every sealing cycle, so its alarm chatters; an operator shelves it with a comment,
//! the gateway is killed (`kill -9`) and started again on the same data, and the alarm is
//! still shelved until the same time, the journal saying who shelved it and why.

mod common;

use std::time::{Duration, Instant};

use common::Gateway;
use serde_json::Value;

/// How long the demo may take to have sealer 0's alarm activate twice (it seals every
/// 3 s; generous for CI's two loaded cores).
const WITHIN: Duration = Duration::from_secs(120);

const TOKEN: &str = "alarm-test-token";
const CHATTERING: &str = "sealer0.temperature:high";

/// The alarm `id` as `/api/alarms` lists it, if it does.
fn listed(gateway: &Gateway, id: &str) -> Option<Value> {
    let list = gateway.get_json("/api/alarms?device=sealer0&limit=100");
    list["alarms"]
        .as_array()
        .unwrap()
        .iter()
        .find(|a| a["id"] == id)
        .cloned()
}

#[test]
fn a_shelved_chattering_alarm_stays_shelved_across_a_kill_9_and_the_journal_says_who_and_why() {
    let data = tempfile::tempdir().unwrap();
    let args = ["--allow-writes"];
    let gateway = Gateway::start_with_token(data.path(), &args, Some(TOKEN));
    let started = Instant::now();
    let alarm = loop {
        if let Some(alarm) = listed(&gateway, CHATTERING)
            && alarm["count"].as_u64().unwrap_or(0) >= 2
        {
            break alarm;
        }
        assert!(started.elapsed() < WITHIN, "{CHATTERING} never chattered");
        std::thread::sleep(Duration::from_millis(250));
    };
    assert_eq!(alarm["priority"], "low", "{alarm}");
    assert_eq!(alarm["source"], "limit", "{alarm}");

    // Without the token, nothing happens; with it, shelved for an hour.
    let path = format!("/api/alarms/{CHATTERING}/shelve");
    let body = r#"{"duration": "1h", "by": "anna", "comment": "chatters every seal"}"#;
    let (status, answer) = gateway.post(&path, "wrong", body);
    assert_eq!(status, 401, "{answer}");
    let (status, answer) = gateway.post(&path, TOKEN, body);
    assert_eq!(status, 200, "{answer}");
    let shelved: Value = serde_json::from_str(&answer).unwrap();
    let until = shelved["alarm"]["shelved_until"].clone();
    assert!(until.is_string(), "{shelved}");
    let (status, answer) = gateway.post("/api/alarms/sealer0.nothing:high/ack", TOKEN, "");
    assert_eq!(status, 404, "{answer}");

    drop(gateway); // kill -9
    let gateway = Gateway::start_with_token(data.path(), &args, Some(TOKEN));
    // Put back as soon as the alarms run (they start with the polls).
    let restarted = Instant::now();
    let restored = loop {
        if let Some(alarm) = listed(&gateway, CHATTERING) {
            break alarm;
        }
        assert!(restarted.elapsed() < WITHIN, "{CHATTERING} not restored");
        std::thread::sleep(Duration::from_millis(100));
    };
    assert_eq!(restored["shelved_until"], until, "{restored}");
    // Nobody acknowledged it: it still waits for that (shelving does not acknowledge).
    assert_eq!(restored["acknowledged"], false, "{restored}");
    assert!(restored["count"].as_u64().unwrap() >= 2, "{restored}");
    let journal = gateway.get_json(&format!("/api/alarms/journal?alarm={CHATTERING}&limit=500"));
    let shelving = journal["entries"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["changes"] == serde_json::json!(["shelved"]))
        .unwrap_or_else(|| panic!("no shelving in the journal: {journal}"));
    assert_eq!(shelving["comment"], "chatters every seal");
    assert!(
        shelving["by"]
            .as_str()
            .unwrap()
            .starts_with("anna (http 127.0.0.1:"),
        "{shelving}"
    );
    assert_eq!(shelving["kind"], "alarm_changed");

    // Unshelved, it shows as its condition is; unshelving it again does not apply.
    let unshelve = format!("/api/alarms/{CHATTERING}/unshelve");
    let (status, answer) = gateway.post(&unshelve, TOKEN, r#"{"comment": "band fixed"}"#);
    assert_eq!(status, 200, "{answer}");
    let (status, answer) = gateway.post(&unshelve, TOKEN, "");
    assert_eq!(status, 409, "{answer}");
    assert!(answer.contains("not shelved"), "{answer}");
}
