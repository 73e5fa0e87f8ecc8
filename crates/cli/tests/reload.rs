//! Reloading the configuration of a running gateway (`SIGHUP`, what `systemctl reload
//! cellbus` sends), through the real binary and real simulators: a device added, one
//! removed and one changed while the others poll on without a gap (their line never
//! closes); a broken file changes nothing and `/healthz` says why; a good file again
//! clears that.

mod common;

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use common::{Gateway, Sim};
use serde_json::Value;

/// How long a change may take to show (generous for CI's two loaded cores).
const WITHIN: Duration = Duration::from_secs(120);

/// A line `line` with the JBC station `id` served by `sim`, with `extra` keys for it.
fn station(line: &str, id: &str, sim: &Sim, extra: &str) -> String {
    format!(
        "[[line]]\nname = \"{line}\"\nendpoint = \"{}\"\n\n[[line.device]]\nid = \"{id}\"\n\
         protocol = \"jbc\"\n{extra}\n",
        sim.endpoint
    )
}

/// Every device by id, as `/api/devices` lists it (without its points).
fn devices(gateway: &Gateway) -> BTreeMap<String, Value> {
    let listing = gateway.get_json("/api/devices?fields=id,name,status,since,line");
    listing["devices"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| (d["id"].as_str().unwrap().to_owned(), d.clone()))
        .collect()
}

/// The events of `kind` stored so far.
fn events(gateway: &Gateway, kind: &str) -> Vec<Value> {
    gateway.get_json(&format!("/api/events?kind={kind}&from=-1h"))["events"]
        .as_array()
        .unwrap()
        .clone()
}

/// The good polls of `device` so far (`cellbus_polls_total`), `None` when `/metrics` has
/// no such series.
fn polls(gateway: &Gateway, device: &str) -> Option<u64> {
    let (status, text) = gateway.get("/metrics");
    assert_eq!(status, 200, "{text}");
    text.lines()
        .find(|l| {
            l.starts_with("cellbus_polls_total{")
                && l.contains(&format!("device=\"{device}\""))
                && l.contains("result=\"ok\"")
        })
        .and_then(|l| l.rsplit(' ').next()?.parse().ok())
}

/// Waits until `ready` gives something, saying `what` did not happen otherwise.
fn wait_for<T>(what: &str, mut ready: impl FnMut() -> Option<T>) -> T {
    let started = Instant::now();
    loop {
        if let Some(found) = ready() {
            return found;
        }
        assert!(started.elapsed() < WITHIN, "{what} did not happen");
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Whether every device of `ids` is up, and no other is listed.
fn exactly_up(gateway: &Gateway, ids: &[&str]) -> Option<BTreeMap<String, Value>> {
    let devices = devices(gateway);
    let listed: Vec<&str> = devices.keys().map(String::as_str).collect();
    let up = ids
        .iter()
        .all(|id| devices.get(*id).is_some_and(|d| d["status"] == "up"));
    (listed == ids && up).then_some(devices)
}

#[test]
fn a_sighup_adds_removes_and_changes_devices_while_the_others_poll_on_and_a_broken_file_changes_nothing()
 {
    let sims: Vec<Sim> = (0..4)
        .map(|_| Sim::start(&["jbc", "--listen", "127.0.0.1:0"]))
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cell.toml");
    let first = [
        station("a", "jbc_a", &sims[0], ""),
        station("b", "jbc_b", &sims[1], ""),
        station("c", "jbc_c", &sims[2], ""),
    ]
    .concat();
    std::fs::write(&path, &first).unwrap();
    let config = path.to_str().unwrap();
    let gateway = Gateway::start_with(&dir.path().join("data"), &["--config", config]);
    let before = wait_for("the three stations answering", || {
        exactly_up(&gateway, &["jbc_a", "jbc_b", "jbc_c"])
    });
    let loaded = gateway.get_json("/healthz")["config"].clone();
    assert_eq!(loaded["path"], config, "{loaded}");
    assert!(loaded["error"].is_null(), "{loaded}");
    let polls_before = polls(&gateway, "jbc_a").unwrap();

    // b removed, c renamed, d added; a as it was.
    let second = [
        station("a", "jbc_a", &sims[0], ""),
        station("c", "jbc_c", &sims[2], "name = \"Rework station C\""),
        station("d", "jbc_d", &sims[3], ""),
    ]
    .concat();
    std::fs::write(&path, &second).unwrap();
    gateway.hang_up();
    let after = wait_for("the reload", || {
        exactly_up(&gateway, &["jbc_a", "jbc_c", "jbc_d"])
    });
    assert_eq!(after["jbc_c"]["name"], "Rework station C");
    let reloaded = wait_for("the config_reloaded event", || {
        events(&gateway, "config_reloaded").pop()
    });
    let fields = &reloaded["fields"];
    assert_eq!(fields["added"], serde_json::json!(["jbc_d"]), "{reloaded}");
    assert_eq!(
        fields["removed"],
        serde_json::json!(["jbc_b"]),
        "{reloaded}"
    );
    assert_eq!(
        fields["changed"],
        serde_json::json!(["jbc_c"]),
        "{reloaded}"
    );
    assert_eq!(fields["lines_kept"], serde_json::json!(["a"]), "{reloaded}");

    // Station a was never stopped: up since the start, its line opened once, polled on.
    assert_eq!(after["jbc_a"]["since"], before["jbc_a"]["since"]);
    let opened: Vec<Value> = events(&gateway, "line_up")
        .into_iter()
        .filter(|e| e["line"] == "a")
        .collect();
    assert_eq!(opened.len(), 1, "line a was opened again: {opened:?}");
    assert!(
        events(&gateway, "device_down")
            .iter()
            .all(|e| e["device"] != "jbc_a"),
        "station a went down"
    );
    wait_for("station a polled after the reload", || {
        (polls(&gateway, "jbc_a")? > polls_before).then_some(())
    });
    // The removed station's series are gone from /metrics.
    assert_eq!(polls(&gateway, "jbc_b"), None);
    let health = gateway.get_json("/healthz");
    assert!(health["config"]["error"].is_null(), "{health}");
    assert_ne!(
        health["config"]["loaded_at"], loaded["loaded_at"],
        "{health}"
    );

    // A broken file changes nothing, and says why.
    std::fs::write(&path, format!("{second}\nbaudrate = 9600\n")).unwrap();
    gateway.hang_up();
    let refused = wait_for("the config_refused event", || {
        events(&gateway, "config_refused").pop()
    });
    let error = refused["fields"]["error"].as_str().unwrap().to_owned();
    assert!(error.contains("baudrate"), "{refused}");
    let health = gateway.get_json("/healthz");
    assert_eq!(health["config"]["error"], error.as_str(), "{health}");
    assert_eq!(health["status"], "degraded", "{health}");
    assert!(
        health["reasons"].to_string().contains("not reloaded"),
        "{health}"
    );
    let polls_refused = polls(&gateway, "jbc_a").unwrap();
    wait_for("station a polled after the refused reload", || {
        (polls(&gateway, "jbc_a")? > polls_refused).then_some(())
    });
    let listed: Vec<String> = devices(&gateway).into_keys().collect();
    assert_eq!(listed, ["jbc_a", "jbc_c", "jbc_d"]);

    // The good file again: loaded, the error gone.
    std::fs::write(&path, &second).unwrap();
    gateway.hang_up();
    wait_for("the error cleared by a good reload", || {
        let health = gateway.get_json("/healthz");
        (health["config"]["error"].is_null() && health["status"] == "ok").then_some(())
    });
    wait_for("the second config_reloaded event", || {
        (events(&gateway, "config_reloaded").len() == 2).then_some(())
    });
}

#[test]
fn a_demo_gateway_sent_sighup_keeps_running_and_has_no_file_to_reload() {
    let data = tempfile::tempdir().unwrap();
    let gateway = Gateway::start(data.path());
    gateway.hang_up();
    gateway.hang_up();
    let health = gateway.get_json("/healthz");
    assert!(health["config"]["path"].is_null(), "{health}");
    assert!(health["config"]["error"].is_null(), "{health}");
}
