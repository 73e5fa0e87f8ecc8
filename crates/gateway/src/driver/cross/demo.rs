//! The demo cell's transfer switch: one CROSS at JBUS unit 1 on its own RS-485 line (9600
//! 8N1); every two minutes source 1 fails for 40 s (an outage, then an undervoltage), so
//! the load transfers to source 2 and back.

use std::time::Duration;

use jbus::cross::Source;
use jbus::cross::device::{CrossTwin, SourceFault};
use wire::device::SharedModel;

use crate::demo::{DemoCell, Starting, device};

/// Starts the switch `cross1`, the mains trouble it rides through and the line
/// `cross1-rs485` that polls it.
pub fn start(demo: &mut DemoCell) -> Starting<'_> {
    Box::pin(async move {
        let unit = jbus::rtu::UnitId::jbus(1).map_err(|e| std::io::Error::other(e.to_string()))?;
        let model = SharedModel::new(CrossTwin::new(unit, 1));
        let endpoint = demo
            .serve_model(model.clone(), super::DEFAULT_SERIAL, "CROSS")
            .await?;
        demo.spawn(operate(model));
        let switch = device(
            "cross1",
            super::KIND,
            Some(1),
            "Transfer switch (Chloride CROSS)",
        )?;
        demo.add_line("cross1-rs485".to_owned(), endpoint, vec![switch]);
        Ok(())
    })
}

/// The mains trouble the CROSS rides through, forever.
async fn operate(model: SharedModel<CrossTwin>) {
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
