//! The demo cell's production through the real binary: the placement machine runs,
//! finishes boards and runs out of parts within its first minutes, and what
//! `/api/production` says of a range agrees with `/api/states`, `/metrics` and the
//! device's OEE points.

mod common;

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use common::Gateway;
use serde_json::Value;

/// How long the demo may take to finish a board and run out of parts: its operator starts
/// the machine after 2 s and lets a feeder run out after 50 s of running (generous: CI's
/// two cores run other tests meanwhile).
const WITHIN: Duration = Duration::from_secs(180);

fn seconds_between(from: &Value, to: &Value) -> f64 {
    let t = |v: &Value| {
        v.as_str()
            .unwrap()
            .parse::<jiff::Timestamp>()
            .unwrap()
            .as_millisecond() as f64
            / 1000.0
    };
    t(to) - t(from)
}

#[test]
fn the_demo_placers_production_agrees_with_its_states_metrics_and_points() {
    let data = tempfile::tempdir().unwrap();
    let gateway = Gateway::start(data.path());
    let started = Instant::now();
    // The shift under way, until it has a board and a parts-exhausted stop.
    let production = loop {
        let p = gateway.get_json("/api/production?device=placer1");
        let stopped = p["stops"].as_array().is_some_and(|stops| {
            stops.iter().any(|s| {
                s["reason"]
                    .as_str()
                    .unwrap()
                    .starts_with("parts exhausted: feeder 7")
            })
        });
        if stopped && p["boards"].as_f64().unwrap_or(0.0) >= 1.0 {
            break p;
        }
        assert!(started.elapsed() < WITHIN, "no board and stop yet: {p}");
        std::thread::sleep(Duration::from_millis(500));
    };
    assert_eq!(production["shift"]["name"], "day", "{production}");

    // The same range, asked of both routes.
    let (from, to) = (&production["from"], &production["to"]);
    let range = format!(
        "device=placer1&from={}&to={}",
        from.as_str().unwrap(),
        to.as_str().unwrap()
    );
    let production = gateway.get_json(&format!("/api/production?{range}"));
    let states = gateway.get_json(&format!("/api/states?{range}"));
    let span = seconds_between(from, to);

    let mut by_state: BTreeMap<String, f64> = BTreeMap::new();
    for i in states["intervals"].as_array().unwrap() {
        *by_state
            .entry(i["state"].as_str().unwrap().to_owned())
            .or_default() += seconds_between(&i["start"], &i["end"]);
    }
    let total: f64 = by_state.values().sum();
    assert!(
        (total - span).abs() < 0.01,
        "intervals {total} s of {span} s"
    );
    let listed: f64 = production["states"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["seconds"].as_f64().unwrap())
        .sum();
    assert!(
        (listed - span).abs() < 0.01,
        "states {listed} s of {span} s"
    );
    for s in production["states"].as_array().unwrap() {
        let state = s["state"].as_str().unwrap();
        let seconds = s["seconds"].as_f64().unwrap();
        assert!(
            (by_state[state] - seconds).abs() < 0.01,
            "{state}: {seconds} s, the intervals {} s",
            by_state[state]
        );
    }

    // Availability = run / planned; performance = 20 s ideal × boards / run.
    let run: f64 = production["states"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|s| s["category"] == "productive")
        .map(|s| s["seconds"].as_f64().unwrap())
        .sum();
    let planned = production["planned_s"].as_f64().unwrap();
    let availability = production["availability"].as_f64().unwrap();
    assert!((availability - run / planned).abs() < 1e-9, "{production}");
    let boards = production["boards"].as_f64().unwrap();
    let performance = production["performance"].as_f64().unwrap();
    assert!(
        (performance - 20.0 * boards / run).abs() < 1e-9,
        "{production}"
    );
    assert_eq!(
        production["basis"]["performance"],
        "ideal cycle 20 s, from the config"
    );
    let oee = production["oee"].as_f64().unwrap();
    let quality = production["quality"].as_f64().unwrap();
    assert!((oee - availability * performance * quality).abs() < 1e-9);
    // Time before the gateway's first poll is no data: not planned, not a stop.
    assert!(production["unobserved_s"].as_f64().unwrap() > 0.0);
    assert!(
        production["stops"]
            .as_array()
            .unwrap()
            .iter()
            .all(|s| s["category"] != "unknown"),
        "{production}"
    );
    assert!(production["mttr_s"].as_f64().unwrap() > 0.0, "{production}");

    // The keeper's figures of the shift reach the points and the metrics.
    let keeper = Instant::now();
    loop {
        let device = gateway.get_json("/api/devices/placer1");
        let oee_point = device["points"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p["id"] == "placer1.oee")
            .cloned()
            .unwrap();
        let (_, metrics) = gateway.get("/metrics");
        let gauge =
            metrics.contains("cellbus_oee_ratio{device=\"placer1\",part=\"oee\",window=\"shift\"}");
        let seconds = metrics.contains(
            "cellbus_device_state_seconds_total{device=\"placer1\",category=\"productive\"}",
        );
        if oee_point["value"].is_number() && gauge && seconds {
            let value = oee_point["value"].as_f64().unwrap();
            assert!((0.0..=1.5).contains(&value), "{oee_point}");
            break;
        }
        assert!(
            keeper.elapsed() < Duration::from_secs(60),
            "no OEE point or metrics: {oee_point}"
        );
        std::thread::sleep(Duration::from_millis(500));
    }
}
