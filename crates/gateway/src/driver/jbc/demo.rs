//! The demo cell's JBC station: one JTSE at address 01 on its own RS-232 line (19200 8E1),
//! worked by a scripted operator: set points, tool on and off through a second connection,
//! as a cell controller would; the suction pedal and an occasional tool fault at the
//! station itself.

use std::time::Duration;

use jbc::client::{Client, ClientConfig};
use jbc::code::{Code, Port, ToolError};
use jbc::device::{Station, StationConfig};
use link::{Endpoint, Line, SharedLine};
use wire::device::SharedModel;

use crate::demo::{DemoCell, Starting, device};

/// Starts the station `jbc1`, its operator and the line `jbc1-rs232` that polls it.
pub fn start(demo: &mut DemoCell) -> Starting<'_> {
    Box::pin(async move {
        let model = SharedModel::new(Station::new(StationConfig::default()));
        let endpoint = demo
            .serve_model(model.clone(), super::DEFAULT_SERIAL, "JBC station")
            .await?;
        demo.spawn(operate(endpoint.clone(), model));
        let station = device(
            "jbc1",
            super::KIND,
            Some(super::DEFAULT_ADDRESS),
            "Rework station (JBC JTSE)",
        )?;
        demo.add_line("jbc1-rs232".to_owned(), endpoint, vec![station]);
        Ok(())
    })
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
async fn operate(endpoint: Endpoint, model: SharedModel<Station>) {
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
