//! The demo cell's placement machine: a Panasonic BM twin served on two loopback TCP ports
//! (Port 1 commands, Port 2 R messages) by `panasonic::server`, with an operator at its
//! panel who starts a production run, lets a feeder run out of parts (an error stop,
//! R2E03), refills it and presses RESET, every 75 s, with the commands `cellbus sim
//! panasonic` takes on its stdin (`panasonic::operator`); boards and R messages flow.

use std::time::Duration;

use link::Endpoint;
use panasonic::operator::Command as PanelCommand;
use panasonic::server::{Control, TwinServer};
use panasonic::status::StopMode;
use panasonic::{Machine, MachineConfig};

use crate::config::Settings;
use crate::demo::{DemoCell, Starting, device};

/// Starts the machine `placer1`, its operator and the line `placer1-lan` that reaches it.
pub fn start(demo: &mut DemoCell) -> Starting<'_> {
    Box::pin(async move {
        let machine = Machine::new(MachineConfig::default())
            .map_err(|e| std::io::Error::other(e.to_string()))?;
        let any = std::net::SocketAddr::from(([127, 0, 0, 1], 0));
        let twin = TwinServer::bind(any, any, machine).await?.spawn()?;
        let (command, event) = (twin.command_addr(), twin.event_addr());
        demo.spawn(operate(twin.control().clone()));
        demo.keep(twin);
        let endpoint = Endpoint::Tcp {
            host: command.ip().to_string(),
            port: command.port(),
            line: None,
            framing: link::TcpFraming::Raw,
        };
        let mut machine = device(
            "placer1",
            super::KIND,
            None,
            "Placement machine (Panasonic BM)",
        )?;
        machine.driver.settings = Settings::new(super::Keys {
            event_port: Some(event.port()),
        });
        machine.driver.endpoint = Some(endpoint.clone());
        // The twin places a board in about 22 s; the plan's ideal is 20 s.
        machine.production = Some(crate::production::ProductionSettings {
            ideal_cycle: Some(DEMO_IDEAL_CYCLE),
            ..Default::default()
        });
        demo.add_line("placer1-lan".to_owned(), endpoint, vec![machine]);
        Ok(())
    })
}

/// The ideal cycle the demo's placement machine is measured against.
pub const DEMO_IDEAL_CYCLE: Duration = Duration::from_secs(20);

/// The feeder the demo operator lets run out.
const EMPTY_FEEDER: u16 = 7;

/// The placement operator's routine, forever: about 50 s running, 15 s in error, 10 s
/// ready; the same commands `cellbus sim panasonic` takes on its stdin. The first start
/// comes after 2 s, so the first parts exhaustion falls within the demo's first minute.
async fn operate(control: Control) {
    let act = |command: PanelCommand| {
        if let Err(e) = control.apply(command) {
            tracing::warn!("demo placement operator: {e}");
        }
    };
    tokio::time::sleep(Duration::from_secs(2)).await;
    loop {
        act(PanelCommand::Start(Some(StopMode::Continuous)));
        tokio::time::sleep(Duration::from_secs(50)).await;
        act(PanelCommand::PauseFeeder(EMPTY_FEEDER));
        tokio::time::sleep(Duration::from_secs(15)).await;
        act(PanelCommand::ResumeFeeder(EMPTY_FEEDER));
        act(PanelCommand::RefillFeeder(EMPTY_FEEDER));
        act(PanelCommand::Clear);
        tokio::time::sleep(Duration::from_secs(10)).await;
    }
}
