//! The OPC UA interface in a running gateway, over real loopback sockets: `/healthz` and
//! `/metrics` show it, or show it as not running.

use std::net::SocketAddr;
use std::time::Duration;

use gateway::plugins::Registry;
use gateway::{Gateway, ServeOptions};
use testkit::get_response;

/// The registry of the `cellbus` binary built with OPC UA.
fn registry() -> Registry {
    gateway::plugins::builtin().with_interface(&cellbus_opcua::Opcua)
}

/// The demo cell on a free loopback port, its history in `dir`.
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

/// A gateway running until [`Serving::stop`].
struct Serving {
    stop: tokio::sync::oneshot::Sender<()>,
    run: tokio::task::JoinHandle<anyhow::Result<()>>,
}

impl Serving {
    /// Runs a started gateway until it is stopped.
    fn start(gateway: Gateway) -> Serving {
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let run = tokio::spawn(gateway.run(async {
            let _ = stopped.await;
        }));
        Serving { stop, run }
    }

    /// Stops the gateway and gives how its run ended (within 30 s).
    async fn stop(self) -> anyhow::Result<()> {
        self.stop.send(()).unwrap();
        tokio::time::timeout(Duration::from_secs(30), self.run)
            .await
            .expect("serve stops within 30 s")
            .unwrap()
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_opcua_server_not_asked_for_is_null_in_healthz_not_left_out() {
    let dir = tempfile::tempdir().unwrap();
    let gateway = Gateway::start_with(options(dir.path()), &registry())
        .await
        .unwrap();
    assert_eq!(gateway.url_of("opcua"), None);
    let addr = gateway.local_addr();
    let serving = Serving::start(gateway);

    let (status, health) = get(addr, "/healthz").await;
    assert_eq!(status, "HTTP/1.1 200 OK");
    assert!(health["opcua"].is_null(), "no OPC UA server: {health}");
    for interface in ["mqtt", "opcua"] {
        assert!(
            health.as_object().unwrap().contains_key(interface),
            "an interface that does not run is null, not left out: {health}"
        );
    }

    serving.stop().await.unwrap();
}

/// Polls `/healthz` until its `opcua.connections` is `want` (bounded).
async fn wait_for_opcua_connections(addr: SocketAddr, want: u64) -> serde_json::Value {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    loop {
        let (_, health) = get(addr, "/healthz").await;
        if health["opcua"]["connections"] == want {
            return health;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "/healthz never showed {want} OPC UA connections: {health}"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn healthz_and_metrics_show_the_opcua_server_and_its_open_connections() {
    let dir = tempfile::tempdir().unwrap();
    let gateway = Gateway::start_with(
        ServeOptions {
            flags: gateway::options::Flags::default().with(cellbus_opcua::OpcuaFlags {
                listen: Some("127.0.0.1:0".parse().unwrap()),
            }),
            ..options(dir.path())
        },
        &registry(),
    )
    .await
    .unwrap();
    let addr = gateway.local_addr();
    let url = gateway.url_of("opcua").unwrap().to_owned();
    let serving = Serving::start(gateway);

    let health = wait_for_opcua_connections(addr, 0).await;
    assert_eq!(health["opcua"]["endpoint"], url.as_str());
    assert_eq!(health["opcua"]["sessions"], 0);
    assert_eq!(health["opcua"]["subscriptions"], 0);
    assert_eq!(health["opcua"]["monitored_items"], 0);
    // A client's TCP connection (no OPC UA spoken yet) is counted while it is open.
    let port = url.rsplit(':').next().unwrap().parse::<u16>().unwrap();
    let client = tokio::net::TcpStream::connect(("127.0.0.1", port))
        .await
        .unwrap();
    wait_for_opcua_connections(addr, 1).await;
    let metrics = get_response(addr, "/metrics").await;
    assert!(
        metrics.lines().any(|l| l == "cellbus_opcua_connections 1"),
        "{metrics}"
    );
    assert!(
        metrics.lines().any(|l| l == "cellbus_opcua_sessions 0"),
        "{metrics}"
    );
    drop(client);
    wait_for_opcua_connections(addr, 0).await;

    serving.stop().await.unwrap();
}
