//! The demo cell `cellbus serve` starts without a configuration.
//!
//! Each simulated device runs in this process behind its own TCP listener(s) on 127.0.0.1
//! (an ephemeral port; nothing else is opened to the network), served by
//! [`link::serve::serve_tcp`] at the speed of its real serial line. The gateway polls it
//! through the same `tcp://` endpoint, `link` line and protocol client a real device behind
//! a serial server gets: nothing short-cuts the protocol.
//!
//! The cell is alive, driven by scripted operators on timers through each twin's own
//! provocation API (never through the gateway). Each device kind that has a twin adds it
//! from its own `demo` module (`driver::jbc::demo`, …), listed in the registry
//! ([`crate::plugins::Registry::demos`]); this module only gives them the listener, the
//! task list and the configuration they join. Adding a kind's demo twin is one
//! [`DemoStart`] function in its folder and one `with_demo` line in the registry.

use std::future::Future;
use std::pin::Pin;

use link::{Endpoint, SerialSettings};
use tokio::net::TcpListener;
use tokio::task::JoinHandle;
use wire::device::SharedModel;

use crate::config::{CellConfig, DEFAULT_REOPEN_AFTER_TIMEOUTS, DeviceConfig, LineConfig};
use crate::driver::{DriverConfig, Kind};
use crate::point::DeviceId;

/// A device kind's part of the demo cell: starts its twins and operators in `demo` and adds
/// the lines that poll them to `demo.config`.
pub type DemoStart = for<'a> fn(&'a mut DemoCell) -> Starting<'a>;

/// What a [`DemoStart`] returns: the start, to be awaited.
pub type Starting<'a> = Pin<Box<dyn Future<Output = std::io::Result<()>> + Send + 'a>>;

/// The running simulators of the demo cell; they stop when it is dropped.
#[derive(Debug, Default)]
pub struct DemoCell {
    /// The configuration that polls them.
    pub config: CellConfig,
    tasks: Vec<JoinHandle<()>>,
}

impl DemoCell {
    /// Starts every kind's simulated devices and operators, in the order given.
    pub async fn start(kinds: &[DemoStart]) -> std::io::Result<Self> {
        let mut demo = DemoCell::default();
        for start in kinds {
            start(&mut demo).await?;
        }
        Ok(demo)
    }

    /// Runs `task` (an operator, a twin's server) for as long as the demo cell lives.
    pub fn spawn(&mut self, task: impl Future<Output = ()> + Send + 'static) {
        self.tasks.push(tokio::spawn(task));
    }

    /// Keeps `thing` (a twin whose servers stop when it is dropped) for as long as the demo
    /// cell lives.
    pub fn keep(&mut self, thing: impl Send + 'static) {
        self.spawn(async move {
            let _kept = thing;
            std::future::pending::<()>().await;
        });
    }

    /// Adds a line the gateway polls, with its devices.
    pub fn add_line(&mut self, name: String, endpoint: Endpoint, devices: Vec<DeviceConfig>) {
        self.config.lines.push(LineConfig {
            reopen_after_timeouts: DEFAULT_REOPEN_AFTER_TIMEOUTS,
            name,
            endpoint,
            devices,
        });
    }

    /// Serves `model` on an ephemeral loopback port at the speed of `serial` for as long as
    /// the demo cell lives, and returns the endpoint that reaches it as a serial server's
    /// port would.
    pub async fn serve_model<M>(
        &mut self,
        model: SharedModel<M>,
        serial: SerialSettings,
        what: &'static str,
    ) -> std::io::Result<Endpoint>
    where
        M: wire::device::Model + Send + 'static,
        wire::device::ModelLine<M>: wire::device::Device + Send + 'static,
    {
        let listener = TcpListener::bind(("127.0.0.1", 0)).await?;
        let addr = listener.local_addr()?;
        self.spawn(async move {
            if let Err(e) =
                link::serve::serve_tcp(listener, move || model.line(), Some(serial)).await
            {
                tracing::error!("demo {what} stopped: {e}");
            }
        });
        let url = format!(
            "tcp://{addr}?baud={}&framing={}",
            serial.baud,
            serial.framing()
        );
        Endpoint::parse(&url, serial).map_err(|e| std::io::Error::other(e.to_string()))
    }
}

impl Drop for DemoCell {
    fn drop(&mut self) {
        for task in &self.tasks {
            task.abort();
        }
    }
}

/// A demo device of `kind` named `id` (a valid device id), at `address` where the kind has
/// one.
pub fn device(
    id: &str,
    kind: Kind,
    address: Option<i64>,
    name: &str,
) -> std::io::Result<DeviceConfig> {
    let id = DeviceId::new(id).map_err(|e| std::io::Error::other(e.to_string()))?;
    let driver = DriverConfig {
        states: Default::default(),
        address,
        ..DriverConfig::new(id, kind)
    };
    Ok(DeviceConfig::new(driver, name))
}
