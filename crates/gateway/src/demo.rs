//! The demo cell `cellbus serve` starts without a configuration.
//!
//! Each simulated device runs in this process behind its own TCP listener on 127.0.0.1
//! (an ephemeral port; nothing else is opened to the network), served by
//! [`link::serve::serve_tcp`] at the speed of its real serial line. The gateway polls it
//! through the same `tcp://` endpoint, `link` line and protocol client a real device behind
//! a serial server gets: nothing short-cuts the protocol.
//!
//! The cell is alive: a scripted operator works each station (set points, tool on and off
//! through a second connection, as a cell controller would; the suction pedal and an
//! occasional tool fault at the station itself), so temperatures rise and fall, alarms come
//! and go.
//!
//! Landed: one JBC JTSE station. Thermosald regulators (three on one RS-485 line), the
//! CROSS transfer switch and the Panasonic machine join when their crates have clients:
//! each is one `start_*` function like [`start_jbc_station`] and one line in
//! [`DemoCell::start`].

use std::collections::BTreeMap;
use std::time::Duration;

use jbc::client::{Client, ClientConfig};
use jbc::code::{Code, Port, ToolError};
use jbc::device::{Station, StationConfig};
use link::{Endpoint, Line, SharedLine};
use tokio::net::TcpListener;
use tokio::task::JoinHandle;
use wire::device::SharedModel;

use crate::config::{CellConfig, DeviceConfig, LineConfig};
use crate::driver::jbc::DEFAULT_SERIAL;
use crate::driver::{DriverConfig, Protocol};
use crate::point::DeviceId;

/// The running simulators of the demo cell; they stop when it is dropped.
#[derive(Debug)]
pub struct DemoCell {
    /// The configuration that polls them.
    pub config: CellConfig,
    /// The JBC station models, for tests and for a look inside.
    pub stations: Vec<SharedModel<Station>>,
    tasks: Vec<JoinHandle<()>>,
}

impl DemoCell {
    /// Starts every simulated device and its operator.
    pub async fn start() -> std::io::Result<Self> {
        let mut demo = DemoCell {
            config: CellConfig {
                source: None,
                token: None,
                lines: Vec::new(),
            },
            stations: Vec::new(),
            tasks: Vec::new(),
        };
        start_jbc_station(&mut demo, "jbc1", "Rework station (JBC JTSE)").await?;
        Ok(demo)
    }
}

impl Drop for DemoCell {
    fn drop(&mut self) {
        for task in &self.tasks {
            task.abort();
        }
    }
}

/// A JTSE at address 01 on its own RS-232 line (19200 8E1), with an operator.
pub async fn start_jbc_station(demo: &mut DemoCell, id: &str, name: &str) -> std::io::Result<()> {
    let model = SharedModel::new(Station::new(StationConfig::default()));
    let listener = TcpListener::bind(("127.0.0.1", 0)).await?;
    let addr = listener.local_addr()?;
    let served = model.clone();
    demo.tasks.push(tokio::spawn(async move {
        if let Err(e) =
            link::serve::serve_tcp(listener, move || served.line(), Some(DEFAULT_SERIAL)).await
        {
            tracing::error!("demo station stopped: {e}");
        }
    }));
    let url = format!(
        "tcp://{addr}?baud={}&framing={}",
        DEFAULT_SERIAL.baud,
        DEFAULT_SERIAL.framing()
    );
    let endpoint =
        Endpoint::parse(&url, DEFAULT_SERIAL).map_err(|e| std::io::Error::other(e.to_string()))?;
    demo.tasks
        .push(tokio::spawn(operate_jbc(endpoint.clone(), model.clone())));
    demo.stations.push(model);
    let id = DeviceId::new(id).map_err(|e| std::io::Error::other(e.to_string()))?;
    demo.config.lines.push(LineConfig {
        name: format!("{id}-rs232"),
        endpoint,
        devices: vec![DeviceConfig {
            driver: DriverConfig {
                id,
                protocol: Protocol::Jbc,
                address: Some(crate::driver::jbc::DEFAULT_ADDRESS),
                timeout: None,
                retries: None,
            },
            name: name.to_owned(),
            period: None,
            groups: BTreeMap::new(),
        }],
    });
    Ok(())
}

/// One step of the rework operator's routine.
#[derive(Debug, Clone, Copy)]
enum Step {
    /// Set the air temperature and flow, turn the tool on.
    Heat { celsius: i32, flow: i32 },
    /// Press or release the suction pedal at the station.
    Suction(bool),
    /// Turn the tool off (the station cools it).
    Off,
    /// A fault appears at the tool (or clears with `ToolError::Ok`).
    Fault(ToolError),
    /// Wait.
    Hold(Duration),
}

/// The routine, repeated: about 100 s per round, two temperatures, one fault per round.
const ROUTINE: &[Step] = &[
    Step::Heat {
        celsius: 350,
        flow: 60,
    },
    Step::Hold(Duration::from_secs(15)),
    Step::Suction(true),
    Step::Hold(Duration::from_secs(3)),
    Step::Suction(false),
    Step::Hold(Duration::from_secs(7)),
    Step::Off,
    Step::Hold(Duration::from_secs(15)),
    Step::Heat {
        celsius: 420,
        flow: 80,
    },
    Step::Hold(Duration::from_secs(20)),
    Step::Fault(ToolError::InsufficientAirFlow),
    Step::Hold(Duration::from_secs(8)),
    Step::Fault(ToolError::Ok),
    Step::Off,
    Step::Hold(Duration::from_secs(30)),
];

/// Works the station through its own connection, like a cell controller, forever.
async fn operate_jbc(endpoint: Endpoint, model: SharedModel<Station>) {
    let mut client = None;
    loop {
        for step in ROUTINE {
            if client.is_none() {
                client = match Line::open(&endpoint).await {
                    Ok(line) => Some(Client::new(SharedLine::new(line), ClientConfig::default())),
                    Err(e) => {
                        tracing::warn!("demo operator cannot reach the station: {e}");
                        tokio::time::sleep(Duration::from_secs(5)).await;
                        continue;
                    }
                };
            }
            let Some(station) = client.as_mut() else {
                continue;
            };
            let result = match *step {
                Step::Heat { celsius, flow } => {
                    let mut r = station.write(Code::SelectAirTemp(Port::One), celsius).await;
                    if r.is_ok() {
                        r = station.write(Code::SelectAirFlow(Port::One), flow).await;
                    }
                    if r.is_ok() {
                        r = station.write(Code::PortStatus(Port::One), 1).await;
                    }
                    r
                }
                Step::Off => station.write(Code::PortStatus(Port::One), 0).await,
                Step::Suction(on) => {
                    model.lock().set_suction(on);
                    Ok(())
                }
                Step::Fault(error) => {
                    model.lock().set_tool_error(error);
                    Ok(())
                }
                Step::Hold(d) => {
                    tokio::time::sleep(d).await;
                    Ok(())
                }
            };
            if let Err(e) = result {
                tracing::warn!("demo operator: {e}");
                client = None;
            }
        }
    }
}
