//! The demo cell's sealers: three Thermosald regulators (addresses 0, 1, 2) sharing one
//! RS-485 line (9600 8N1), sealing at their own rhythms (3, 4 and 5 s), so temperature,
//! current and power move; every three minutes regulator 2's supply sags and it latches
//! "sealing temperature not reached" until the operator fixes the supply and switches it
//! off and on, with the commands `cellbus sim thermosald` takes on its stdin
//! (`thermosald::device::operator`).

use std::time::Duration;

use thermosald::Address;
use thermosald::device::operator::{self as sealer, Command as SealerCommand};
use thermosald::device::{Regulator, RegulatorBus, RegulatorConfig};
use thermosald::diagnostic::Fault;
use thermosald::exchange::LineTiming;
use wire::device::SharedModel;

use crate::alarm::Priority;
use crate::alarm::config::AlarmConfig;
use crate::alarm::limit::Limits;
use crate::alarm::state::ChatterRule;
use crate::demo::{DemoCell, Starting, device};
use crate::point::PointId;

/// Sealing rhythms of the demo regulators: three packaging machines at their own pace.
const SEAL_PERIODS: [Duration; 3] = [
    Duration::from_secs(3),
    Duration::from_secs(4),
    Duration::from_secs(5),
];

/// Starts the regulators `sealer0` to `sealer2`, their operator and the line
/// `sealers-rs485` that polls them.
pub fn start(demo: &mut DemoCell) -> Starting<'_> {
    Box::pin(async move {
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
                &format!("sealer{n}"),
                super::KIND,
                Some(i64::from(n)),
                &format!("Sealer {n} (Thermosald ISC, address {n})"),
            )?);
        }
        let serial = super::DEFAULT_SERIAL;
        let timing = LineTiming::new(serial.baud, serial.bits_per_char())
            .map_err(|e| std::io::Error::other(e.to_string()))?;
        let model = SharedModel::new(RegulatorBus::from_regulators(regulators).paced(timing));
        let endpoint = demo
            .serve_model(model.clone(), serial, "Thermosald line")
            .await?;
        demo.spawn(operate(model));
        demo.add_line("sealers-rs485".to_owned(), endpoint, devices);
        demo.config.alarms.push(chattering_limit()?);
        Ok(())
    })
}

/// A limit alarm that chatters, to be shelved: sealer 0's band passes 120 °C in every
/// sealing cycle (every 3 s), so the alarm activates and clears again and again; its
/// chatter rule counts it (more than 5 activations a minute) without shelving it.
fn chattering_limit() -> std::io::Result<AlarmConfig> {
    let point =
        PointId::parse("sealer0.temperature").map_err(|e| std::io::Error::other(e.to_string()))?;
    Ok(AlarmConfig {
        point,
        limits: Limits {
            high: Some(120.0),
            deadband: 5.0,
            ..Limits::default()
        },
        priority: Priority::Low,
        message: Some("Band above 120 °C".to_owned()),
        category: Some("process".to_owned()),
        chatter: Some(ChatterRule {
            activations: 5,
            window: Duration::from_secs(60),
            shelve: None,
        }),
    })
}

/// The sealers' supply trouble, repeated: every 3 minutes regulator 2's supply sags for
/// half a minute; then the operator repairs it and switches it off and on, with the same
/// commands `cellbus sim thermosald` takes on its stdin.
async fn operate(model: SharedModel<RegulatorBus>) {
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
