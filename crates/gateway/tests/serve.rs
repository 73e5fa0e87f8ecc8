//! `serve` end to end over real loopback sockets: the demo cell comes alive, the API shows
//! it, a stop commits the history; bad starts say what to do.

use std::net::SocketAddr;
use std::time::Duration;

use gateway::store::{EventFilter, Series, Store, StoreOptions};
use gateway::time::Timestamp;
use gateway::{Gateway, ServeOptions};
mod running;
use testkit::get_response;

fn options(dir: &std::path::Path) -> ServeOptions {
    ServeOptions {
        listen: "127.0.0.1:0".parse().unwrap(),
        data_dir: dir.join("data"),
        ..ServeOptions::default()
    }
}

/// GETs `path` and returns the status line and the JSON body.
async fn get(addr: SocketAddr, path: &str) -> (String, serde_json::Value) {
    let response = get_response(addr, path).await;
    let (head, body) = response.split_once("\r\n\r\n").unwrap();
    let status = head.lines().next().unwrap().to_owned();
    (
        status,
        serde_json::from_str(body).unwrap_or(serde_json::Value::Null),
    )
}

fn device<'a>(devices: &'a serde_json::Value, id: &str) -> &'a serde_json::Value {
    devices["devices"]
        .as_array()
        .unwrap()
        .iter()
        .find(|d| d["id"] == id)
        .unwrap_or_else(|| panic!("no device {id}"))
}

fn point<'a>(devices: &'a serde_json::Value, id: &str) -> &'a serde_json::Value {
    let (d, _) = id.split_once('.').unwrap();
    device(devices, d)["points"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["id"] == id)
        .unwrap()
}

/// The devices of the demo cell.
const DEMO: [&str; 6] = ["cross1", "jbc1", "placer1", "sealer0", "sealer1", "sealer2"];

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn serve_without_a_config_runs_a_live_demo_cell_and_stops_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let gateway = Gateway::start(options(dir.path())).await.unwrap();
    let addr = gateway.local_addr();
    assert_eq!(addr.ip().to_string(), "127.0.0.1");
    assert_ne!(addr.port(), 0);
    let serving = run_until_stopped(gateway);

    // The station answers through the protocol and its air temperature moves: the demo
    // operator turns the tool on at once. Poll the API with a generous deadline.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
    let mut first: Option<f64> = None;
    loop {
        assert!(
            tokio::time::Instant::now() < deadline,
            "no live change within 60 s"
        );
        let (status, devices) = get(addr, "/api/devices").await;
        assert_eq!(status, "HTTP/1.1 200 OK");
        let air = point(&devices, "jbc1.air_temperature");
        if let Some(t) = air["value"].as_f64() {
            assert_eq!(device(&devices, "jbc1")["status"], "up");
            assert_eq!(air["quality"], "good");
            match first {
                None => first = Some(t),
                Some(f) if (t - f).abs() >= 5.0 => break,
                Some(_) => {}
            }
        }
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
    // Every demo device is up with every point read good (the slow groups are read at
    // start too), and the sealers' temperatures move with their seal cycles.
    let mut temperatures = std::collections::HashSet::new();
    loop {
        let (_, devices) = get(addr, "/api/devices").await;
        let ids: Vec<&str> = devices["devices"]
            .as_array()
            .unwrap()
            .iter()
            .map(|d| d["id"].as_str().unwrap())
            .collect();
        assert_eq!(ids, DEMO);
        let all_good = DEMO.iter().all(|id| {
            let d = device(&devices, id);
            d["status"] == "up"
                && d["points"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .all(|p| p["quality"] == "good" && !p["value"].is_null())
        });
        if let Some(t) = point(&devices, "sealer0.temperature")["value"].as_f64() {
            temperatures.insert(t.to_bits());
        }
        if all_good && temperatures.len() >= 2 {
            break;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "not every demo device shows good values within 60 s: {devices}"
        );
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
    let (status, lines) = get(addr, "/api/lines").await;
    assert_eq!(status, "HTTP/1.1 200 OK");
    assert_eq!(lines["lines"].as_array().unwrap().len(), 4);
    assert!(
        lines["lines"]
            .as_array()
            .unwrap()
            .iter()
            .all(|l| l["open"] == true)
    );
    let (status, health) = get(addr, "/healthz").await;
    assert_eq!(status, "HTTP/1.1 200 OK");
    assert_eq!(health["devices_up"], DEMO.len());
    for interface in gateway::plugins::builtin().interfaces {
        assert!(
            health.as_object().unwrap().contains_key(interface.name())
                && health[interface.name()].is_null(),
            "an interface that does not run is null, not left out: {health}"
        );
    }

    serving.stop().await.unwrap();

    // Everything was committed: the history shows the rise, the events the start and stop.
    let store = Store::open(&dir.path().join("data"), StoreOptions::default()).unwrap();
    let h = store.handle();
    assert_eq!(h.integrity_check().unwrap(), "ok");
    let history = h
        .history(
            &gateway::point::PointId::parse("jbc1.air_temperature").unwrap(),
            Timestamp(0),
            Timestamp(i64::MAX),
            None,
        )
        .unwrap();
    let Series::Samples(samples) = history.series else {
        panic!("raw samples expected")
    };
    assert!(samples.len() >= 2, "{} samples", samples.len());
    assert_ne!(
        samples.first().unwrap().value,
        samples.last().unwrap().value
    );
    let events = h
        .events(&EventFilter {
            limit: 100,
            ..EventFilter::default()
        })
        .unwrap();
    let kinds: Vec<&str> = events.iter().map(|e| e.kind.as_str()).collect();
    assert_eq!(kinds.first(), Some(&"gateway_stopped"), "{kinds:?}");
    assert_eq!(kinds.last(), Some(&"gateway_started"), "{kinds:?}");
    assert!(kinds.contains(&"line_up"), "{kinds:?}");
}

/// Why the gateway refuses to start with `options`.
async fn refusal(options: ServeOptions) -> String {
    Gateway::start(options).await.unwrap_err().to_string()
}

#[tokio::test]
async fn a_taken_port_is_reported_with_the_way_out() {
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let dir = tempfile::tempdir().unwrap();
    let err = refusal(ServeOptions {
        listen: taken.local_addr().unwrap(),
        ..options(dir.path())
    })
    .await;
    assert!(err.contains("already in use"), "{err}");
    assert!(err.contains("--listen 127.0.0.1:0"), "{err}");
}

#[tokio::test]
async fn a_bad_config_is_refused_at_start_with_file_line_and_reason() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cell.toml");
    std::fs::write(
        &path,
        "[[line]]\nname = \"a\"\nendpoint = \"tcp://127.0.0.1:1\"\n[[line.device]]\nid = \"x\"\nprotocol = \"jbc\"\naddress = 250\n",
    )
    .unwrap();
    let err = refusal(ServeOptions {
        config: Some(path.clone()),
        ..options(dir.path())
    })
    .await;
    assert!(
        err.starts_with(&format!("{}:7:11: ", path.display())),
        "{err}"
    );
    assert!(err.contains("0 to 99"), "{err}");
}

#[tokio::test]
async fn writes_without_a_token_are_refused_at_start() {
    if std::env::var_os(gateway::TOKEN_ENV).is_some() {
        // The environment supplies a token; this start would be valid.
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let err = refusal(ServeOptions {
        allow_writes: true,
        ..options(dir.path())
    })
    .await;
    assert!(err.contains("--allow-writes needs a token"), "{err}");
    assert!(err.contains("CELLBUS_TOKEN"), "{err}");
}

/// Waits (bounded) until the JBC station's air temperature is served live, good.
async fn wait_for_live_value(addr: SocketAddr) {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
    loop {
        let (status, devices) = get(addr, "/api/devices").await;
        assert_eq!(status, "HTTP/1.1 200 OK");
        let air = point(&devices, "jbc1.air_temperature");
        if air["value"].is_number() && air["quality"] == "good" {
            return;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "no live value within 60 s: {devices}"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// A started gateway running on a task of its own until [`Serving::stop`].
struct Serving {
    stop: tokio::sync::oneshot::Sender<()>,
    run: tokio::task::JoinHandle<anyhow::Result<()>>,
}

impl Serving {
    /// Stops the gateway and gives how its run ended (within 30 s).
    async fn stop(self) -> anyhow::Result<()> {
        self.stop.send(()).unwrap();
        tokio::time::timeout(Duration::from_secs(30), self.run)
            .await
            .expect("serve stops within 30 s")
            .unwrap()
    }
}

/// Runs a started gateway until it is stopped.
fn run_until_stopped(gateway: Gateway) -> Serving {
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let run = tokio::spawn(gateway.run(async {
        let _ = stopped.await;
    }));
    Serving { stop, run }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unusable_data_directory_leaves_live_values_served_and_reports_the_fault() {
    let dir = tempfile::tempdir().unwrap();
    // A regular file where the data directory should be: refused even to root (a chmod
    // 0555 directory is not).
    let data = dir.path().join("data");
    std::fs::write(&data, b"not a directory").unwrap();
    // Before the fix the gateway stopped here, exit 1.
    let gateway = Gateway::start(options(dir.path())).await.unwrap();
    let addr = gateway.local_addr();
    let serving = run_until_stopped(gateway);
    wait_for_live_value(addr).await;

    let (status, health) = get(addr, "/healthz").await;
    assert_eq!(status, "HTTP/1.1 503 Service Unavailable");
    assert_eq!(health["status"], "failing", "{health}");
    let history = health["history"].as_str().unwrap();
    assert!(history.starts_with("off: "), "{health}");
    assert!(history.contains(&data.display().to_string()), "{health}");
    assert!(history.contains("os error"), "{health}");
    assert!(
        health["history_rows_dropped"].as_u64().unwrap() > 0,
        "{health}"
    );

    let (status, body) = get(addr, "/api/history?point=jbc1.air_temperature").await;
    assert_eq!(status, "HTTP/1.1 503 Service Unavailable", "{body}");
    let error = body["error"].as_str().unwrap();
    assert!(error.contains("history is off"), "{error}");
    assert!(error.contains(&data.display().to_string()), "{error}");
    assert!(error.contains("os error"), "{error}");

    serving
        .stop()
        .await
        .expect("a stop with the history off is clean");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_garbage_history_file_is_moved_aside_and_the_gateway_serves_on() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    std::fs::create_dir(&data).unwrap();
    let garbage: Vec<u8> = (0..8192u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 11) as u8)
        .collect();
    std::fs::write(data.join("cellbus.db"), &garbage).unwrap();
    // Before the fix: "file is not a database", exit 1.
    let gateway = Gateway::start(options(dir.path())).await.unwrap();
    let addr = gateway.local_addr();
    let serving = run_until_stopped(gateway);
    wait_for_live_value(addr).await;

    let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
    let reset = loop {
        let (status, body) = get(addr, "/api/events?kind=history_reset").await;
        assert_eq!(status, "HTTP/1.1 200 OK", "{body}");
        if let Some(event) = body["events"].as_array().and_then(|e| e.first()) {
            break event.clone();
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "no history_reset event within 60 s"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    let message = reset["message"].as_str().unwrap();
    assert!(message.contains("cellbus.db.corrupt-"), "{message}");
    let aside: Vec<_> = std::fs::read_dir(&data)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n.starts_with("cellbus.db.corrupt-"))
        .collect();
    assert_eq!(aside.len(), 1, "{aside:?}");
    assert!(message.contains(&aside[0]), "{message}");
    assert_eq!(std::fs::read(data.join(&aside[0])).unwrap(), garbage);
    let (_, health) = get(addr, "/healthz").await;
    assert_eq!(health["status"], "ok", "{health}");
    assert_eq!(health["history"], "ok", "{health}");

    serving.stop().await.unwrap();
}
