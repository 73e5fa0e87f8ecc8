//! A gateway running in the test's process, for the MQTT tests: started from
//! `ServeOptions`, stopped gracefully, and a bounded wait on its MQTT state.

#![allow(dead_code)] // each test binary uses its share

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};

use gateway::cell::Cell;
use gateway::northbound::mqtt::MqttLink;
use gateway::{Gateway, ServeOptions};
use tokio::sync::oneshot;
use tokio::task::JoinHandle;

/// Generous: a loaded 2-core machine.
pub const LIMIT: Duration = Duration::from_secs(60);

/// A running gateway.
pub struct Running {
    pub cell: Arc<Cell>,
    /// Reloads its configuration, as `SIGHUP` does.
    pub reloader: Arc<gateway::reload::Reloader>,
    pub addr: SocketAddr,
    stop: oneshot::Sender<()>,
    task: JoinHandle<anyhow::Result<()>>,
}

impl Running {
    /// Starts the gateway of `options` (listening on a free loopback port).
    pub async fn start(options: ServeOptions) -> Running {
        let gateway = Gateway::start(ServeOptions {
            listen: "127.0.0.1:0".parse().unwrap(),
            ..options
        })
        .await
        .unwrap();
        let cell = Arc::clone(gateway.cell());
        let reloader = Arc::clone(gateway.reloader());
        let addr = gateway.local_addr();
        let (stop, stopped) = oneshot::channel::<()>();
        let task = tokio::spawn(gateway.run(async {
            let _ = stopped.await;
        }));
        Running {
            cell,
            reloader,
            addr,
            stop,
            task,
        }
    }

    /// Stops it as Ctrl-C would and waits for the end.
    pub async fn stop(self) {
        let _ = self.stop.send(());
        self.task.await.unwrap().unwrap();
    }

    /// Waits (bounded polling) until the MQTT state is `wanted`.
    pub async fn wait_for_link(&self, what: &str, wanted: impl Fn(&Option<MqttLink>) -> bool) {
        let deadline = Instant::now() + LIMIT;
        while !wanted(&gateway::northbound::mqtt::link(&self.cell)) {
            assert!(
                Instant::now() < deadline,
                "MQTT never {what}: {:?}",
                gateway::northbound::mqtt::link(&self.cell)
            );
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    }
}
