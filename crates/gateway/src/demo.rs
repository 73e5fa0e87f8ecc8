//! The demo cell `cellbus serve` starts without a configuration.
//!
//! Each simulated device runs in this process behind its own TCP listener(s) on 127.0.0.1
//! (an ephemeral port; nothing else is opened to the network), served by
//! [`link::serve::serve_tcp`] at the speed of its real serial line. The gateway polls it
//! through the same `tcp://` endpoint, `link` line and protocol client a real device behind
//! a serial server gets: nothing short-cuts the protocol.
//!
//! The cell is alive, driven by scripted operators on timers through each twin's own
//! provocation API (never through the gateway); the sealers' and the placement machine's
//! operators give the same commands `cellbus sim` takes on its stdin
//! (`thermosald::device::operator`, `panasonic::operator`):
//!
//! - one JBC JTSE station ([`start_jbc_station`]): set points, tool on and off through a
//!   second connection, as a cell controller would; the suction pedal and an occasional
//!   tool fault at the station itself;
//! - three Thermosald regulators sharing one RS-485 line ([`start_thermosald_line`]):
//!   sealing cycles run at 3, 4 and 5 s, so temperature, current and power move; every
//!   three minutes regulator 2's supply sags and it latches a fault until it is switched
//!   off and on;
//! - one CROSS transfer switch ([`start_cross`]): every two minutes source 1 fails (an
//!   outage, then an undervoltage) for 40 s, so the load transfers to source 2 and back;
//! - one Panasonic placement machine ([`start_panasonic`]), its twin on two loopback TCP
//!   ports: the operator starts a run, a feeder runs out of parts (error stop, R2E03),
//!   is refilled and the machine reset to ready, every 75 s; boards and R messages flow.
//!
//! Adding a device is one `start_*` function and one line in [`DemoCell::start`].

use std::time::Duration;

use jbc::client::{Client, ClientConfig};
use jbc::code::{Code, Port, ToolError};
use jbc::device::{Station, StationConfig};
use jbus::cross::Source;
use jbus::cross::device::{CrossTwin, SourceFault};
use link::{Endpoint, Line, SerialSettings, SharedLine};
use panasonic::operator::Command as PanelCommand;
use panasonic::server::{Control, RunningTwin, TwinServer};
use panasonic::status::StopMode;
use panasonic::{Machine, MachineConfig};
use thermosald::Address;
use thermosald::device::operator::{self as sealer, Command as SealerCommand};
use thermosald::device::{Regulator, RegulatorBus, RegulatorConfig};
use thermosald::diagnostic::Fault;
use thermosald::exchange::LineTiming;
use tokio::net::TcpListener;
use tokio::task::JoinHandle;
use wire::device::SharedModel;

use crate::config::{CellConfig, DeviceConfig, LineConfig};
use crate::driver::jbc::DEFAULT_SERIAL;
use crate::driver::{DriverConfig, Kind};
use crate::point::DeviceId;

/// The running simulators of the demo cell; they stop when it is dropped.
#[derive(Debug)]
pub struct DemoCell {
    /// The configuration that polls them.
    pub config: CellConfig,
    /// The JBC station models, for tests and for a look inside.
    pub stations: Vec<SharedModel<Station>>,
    /// The Thermosald lines (each with its regulators).
    pub regulators: Vec<SharedModel<RegulatorBus>>,
    /// The CROSS twins.
    pub crosses: Vec<SharedModel<CrossTwin>>,
    /// The Panasonic machines, served on their two ports (their `control()` is the panel).
    pub machines: Vec<RunningTwin>,
    tasks: Vec<JoinHandle<()>>,
}

impl DemoCell {
    /// Starts every simulated device and its operator.
    pub async fn start() -> std::io::Result<Self> {
        let mut demo = DemoCell {
            config: CellConfig::default(),
            stations: Vec::new(),
            regulators: Vec::new(),
            crosses: Vec::new(),
            machines: Vec::new(),
            tasks: Vec::new(),
        };
        start_jbc_station(&mut demo, "jbc1", "Rework station (JBC JTSE)").await?;
        start_thermosald_line(&mut demo, "sealers-rs485").await?;
        start_cross(&mut demo, "cross1", "Transfer switch (Chloride CROSS)").await?;
        start_panasonic(&mut demo, "placer1", "Placement machine (Panasonic BM)").await?;
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

/// Serves `model` on an ephemeral loopback port at the speed of `serial`, and returns the
/// endpoint that reaches it as a serial server's port would.
async fn serve_model<M>(
    demo: &mut DemoCell,
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
    demo.tasks.push(tokio::spawn(async move {
        if let Err(e) = link::serve::serve_tcp(listener, move || model.line(), Some(serial)).await {
            tracing::error!("demo {what} stopped: {e}");
        }
    }));
    let url = format!(
        "tcp://{addr}?baud={}&framing={}",
        serial.baud,
        serial.framing()
    );
    Endpoint::parse(&url, serial).map_err(|e| std::io::Error::other(e.to_string()))
}

fn device_id(id: &str) -> std::io::Result<DeviceId> {
    DeviceId::new(id).map_err(|e| std::io::Error::other(e.to_string()))
}

fn device(id: DeviceId, protocol: Kind, address: i64, name: &str) -> DeviceConfig {
    let driver = DriverConfig {
        address: Some(address),
        ..DriverConfig::new(id, protocol)
    };
    DeviceConfig::new(driver, name)
}

/// A JTSE at address 01 on its own RS-232 line (19200 8E1), with an operator.
pub async fn start_jbc_station(demo: &mut DemoCell, id: &str, name: &str) -> std::io::Result<()> {
    let model = SharedModel::new(Station::new(StationConfig::default()));
    let endpoint = serve_model(demo, model.clone(), DEFAULT_SERIAL, "JBC station").await?;
    demo.tasks
        .push(tokio::spawn(operate_jbc(endpoint.clone(), model.clone())));
    demo.stations.push(model);
    let id = device_id(id)?;
    demo.config.lines.push(LineConfig {
        reopen_after_timeouts: crate::config::DEFAULT_REOPEN_AFTER_TIMEOUTS,
        name: format!("{id}-rs232"),
        endpoint,
        devices: vec![device(
            id,
            crate::driver::jbc::KIND,
            crate::driver::jbc::DEFAULT_ADDRESS,
            name,
        )],
    });
    Ok(())
}

/// Sealing rhythms of the demo regulators: three packaging machines at their own pace.
const SEAL_PERIODS: [Duration; 3] = [
    Duration::from_secs(3),
    Duration::from_secs(4),
    Duration::from_secs(5),
];

/// Three Thermosald regulators (addresses 0, 1, 2) sharing one RS-485 line (9600 8N1),
/// sealing at their own rhythms; every few minutes the third one's supply sags, so it
/// latches "sealing temperature not reached" until the operator fixes the supply and
/// switches it off and on.
pub async fn start_thermosald_line(demo: &mut DemoCell, line: &str) -> std::io::Result<()> {
    let now = tokio::time::Instant::now().into_std();
    let mut regulators = Vec::new();
    let mut devices = Vec::new();
    for (n, period) in (0u8..).zip(SEAL_PERIODS) {
        let address = Address::new(n).map_err(|e| std::io::Error::other(e.to_string()))?;
        let config = RegulatorConfig {
            seal_period: Some(period),
            ..RegulatorConfig::default()
        };
        regulators.push(Regulator::new(address, config, now));
        devices.push(device(
            device_id(&format!("sealer{n}"))?,
            crate::driver::thermosald::KIND,
            i64::from(n),
            &format!("Sealer {n} (Thermosald ISC, address {n})"),
        ));
    }
    let serial = crate::driver::thermosald::DEFAULT_SERIAL;
    let timing = LineTiming::new(serial.baud, serial.bits_per_char())
        .map_err(|e| std::io::Error::other(e.to_string()))?;
    let model = SharedModel::new(RegulatorBus::from_regulators(regulators).paced(timing));
    let endpoint = serve_model(demo, model.clone(), serial, "Thermosald line").await?;
    demo.tasks
        .push(tokio::spawn(operate_sealers(model.clone())));
    demo.regulators.push(model);
    demo.config.lines.push(LineConfig {
        reopen_after_timeouts: crate::config::DEFAULT_REOPEN_AFTER_TIMEOUTS,
        name: line.to_owned(),
        endpoint,
        devices,
    });
    Ok(())
}

/// The sealers' supply trouble, repeated: every 3 minutes regulator 2's supply sags for
/// half a minute; then the operator repairs it and switches it off and on, with the same
/// commands `cellbus sim thermosald` takes on its stdin.
async fn operate_sealers(model: SharedModel<RegulatorBus>) {
    let Ok(address) = Address::new(2) else {
        return;
    };
    let act = |command: SealerCommand| {
        let now = tokio::time::Instant::now().into_std();
        if let Err(e) = sealer::apply(&mut model.lock(), command, now) {
            tracing::warn!("demo sealer operator: {e}");
        }
    };
    loop {
        tokio::time::sleep(Duration::from_secs(60)).await;
        act(SealerCommand::Fault {
            address,
            kind: Fault::TemperatureNotReached,
        });
        tokio::time::sleep(Duration::from_secs(30)).await;
        act(SealerCommand::Repair { address });
        act(SealerCommand::PowerCycle { address });
        tokio::time::sleep(Duration::from_secs(90)).await;
    }
}

/// A CROSS at JBUS unit 1 on its own RS-485 line (9600 8N1); every two minutes source 1
/// fails for 40 s (an outage, then an undervoltage), so the load transfers to source 2
/// and back.
pub async fn start_cross(demo: &mut DemoCell, id: &str, name: &str) -> std::io::Result<()> {
    let unit = jbus::rtu::UnitId::jbus(1).map_err(|e| std::io::Error::other(e.to_string()))?;
    let model = SharedModel::new(CrossTwin::new(unit, 1));
    let serial = crate::driver::cross::DEFAULT_SERIAL;
    let endpoint = serve_model(demo, model.clone(), serial, "CROSS").await?;
    demo.tasks.push(tokio::spawn(operate_cross(model.clone())));
    demo.crosses.push(model);
    let id = device_id(id)?;
    demo.config.lines.push(LineConfig {
        reopen_after_timeouts: crate::config::DEFAULT_REOPEN_AFTER_TIMEOUTS,
        name: format!("{id}-rs485"),
        endpoint,
        devices: vec![device(id, crate::driver::cross::KIND, 1, name)],
    });
    Ok(())
}

/// A Panasonic placement machine: its twin served on two ephemeral loopback ports (Port 1
/// commands, Port 2 R messages) by `panasonic::server`, with an operator at its panel who
/// starts a production run, lets a feeder run out of parts (an error stop), refills it and
/// presses RESET, over and over.
pub async fn start_panasonic(demo: &mut DemoCell, id: &str, name: &str) -> std::io::Result<()> {
    let machine =
        Machine::new(MachineConfig::default()).map_err(|e| std::io::Error::other(e.to_string()))?;
    let any = std::net::SocketAddr::from(([127, 0, 0, 1], 0));
    let twin = TwinServer::bind(any, any, machine).await?.spawn()?;
    let (command, event) = (twin.command_addr(), twin.event_addr());
    demo.tasks
        .push(tokio::spawn(operate_panasonic(twin.control().clone())));
    demo.machines.push(twin);
    let endpoint = Endpoint::Tcp {
        host: command.ip().to_string(),
        port: command.port(),
        line: None,
        framing: link::TcpFraming::Raw,
    };
    let id = device_id(id)?;
    let mut device = device(id.clone(), crate::driver::panasonic::KIND, 0, name);
    device.driver.address = None;
    device.driver.settings = crate::config::Settings::new(crate::driver::panasonic::Keys {
        event_port: Some(event.port()),
    });
    device.driver.endpoint = Some(endpoint.clone());
    demo.config.lines.push(LineConfig {
        reopen_after_timeouts: crate::config::DEFAULT_REOPEN_AFTER_TIMEOUTS,
        name: format!("{id}-lan"),
        endpoint,
        devices: vec![device],
    });
    Ok(())
}

/// The feeder the demo operator lets run out.
const EMPTY_FEEDER: u16 = 7;

/// The placement operator's routine, forever: about 50 s running, 15 s in error, 10 s
/// ready; the same commands `cellbus sim panasonic` takes on its stdin.
async fn operate_panasonic(control: Control) {
    let act = |command: PanelCommand| {
        if let Err(e) = control.apply(command) {
            tracing::warn!("demo placement operator: {e}");
        }
    };
    loop {
        tokio::time::sleep(Duration::from_secs(10)).await;
        act(PanelCommand::Start(Some(StopMode::Continuous)));
        tokio::time::sleep(Duration::from_secs(50)).await;
        act(PanelCommand::PauseFeeder(EMPTY_FEEDER));
        tokio::time::sleep(Duration::from_secs(15)).await;
        act(PanelCommand::ResumeFeeder(EMPTY_FEEDER));
        act(PanelCommand::RefillFeeder(EMPTY_FEEDER));
        act(PanelCommand::Clear);
    }
}

/// The mains trouble the CROSS rides through, forever.
async fn operate_cross(model: SharedModel<CrossTwin>) {
    let faults = [SourceFault::Outage, SourceFault::Undervoltage];
    loop {
        for fault in faults {
            tokio::time::sleep(Duration::from_secs(80)).await;
            model.lock().fail_source_with(Source::S1, fault);
            tokio::time::sleep(Duration::from_secs(40)).await;
            model.lock().restore_source(Source::S1);
        }
    }
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
