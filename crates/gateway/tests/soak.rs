//! The short noise soak: the real gateway and every serial device kind over seeded noisy
//! in-memory lines, in paused time. The bench (`cargo bench -p gateway --bench soak`) runs
//! the long one over loopback TCP.

mod soak {
    pub mod rig;
}

use std::time::Duration;

use soak::rig::{SoakOptions, Transport, run};
use testkit::NoiseConfig;

#[tokio::test(start_paused = true)]
async fn a_noisy_cell_publishes_no_wrong_value_and_recovers_from_an_outage() {
    let report = run(SoakOptions {
        seed: 11,
        // Twice the field report's noise, so a few thousand requests meet every kind.
        noise: NoiseConfig::FIELD.scaled(2.0),
        requests: 10_000,
        transport: Transport::Memory,
        ..SoakOptions::default()
    })
    .await
    .expect("the soak runs");
    let text = report.lines().join("\n");
    assert!(report.requests >= 10_000, "{text}");
    assert!(
        report.line.damaged_chunks > 100,
        "the noise reached the frames\n{text}"
    );
    assert_eq!(
        report.wrong_total(),
        0,
        "wrong values taken as good\n{text}"
    );
    assert_eq!(report.missed_messages, 0, "{text}");
    for protocol in ["jbc", "thermosald", "cross", "modbus"] {
        assert!(
            report.judged_points.get(protocol).is_some_and(|n| *n > 0),
            "no {protocol} point judged\n{text}"
        );
    }
    assert!(report.answered_share() > 0.8, "{text}");
    eprintln!("{text}");
    assert!(
        report.longest_down <= Duration::from_secs(15),
        "a device stayed down too long on a merely noisy line\n{text}"
    );
    let recovery = report
        .recovery
        .expect("every device answers after the outage");
    assert!(recovery <= Duration::from_secs(15), "{text}");
}
