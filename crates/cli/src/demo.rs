//! `cellbus demo`: a simulated JBC station and a live view of it, no hardware needed.
//!
//! The station runs in this process behind a real TCP listener on loopback, and the view
//! talks to it through the same client and line code a real station gets. Another
//! terminal can talk to the same station: the address is printed first.

use std::process::ExitCode;
use std::time::Duration;

use clap::Args;
use jbc::client::{Client, ClientConfig};
use jbc::code::Code;
use link::{Endpoint, Line, SharedLine};

use crate::jbc_cmd::JBC_LINE;
use crate::output;

#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Stop after this long (default: run until interrupted).
    #[arg(long, value_parser = humantime::parse_duration)]
    pub duration: Option<Duration>,
    /// Time between readings.
    #[arg(long, default_value = "1s", value_parser = humantime::parse_duration)]
    pub interval: Duration,
}

/// The demo's script: set point and tool state, each held for a while.
const SCRIPT: [(i32, bool, Duration); 4] = [
    (350, true, Duration::from_secs(40)),
    (350, false, Duration::from_secs(20)),
    (420, true, Duration::from_secs(40)),
    (300, false, Duration::from_secs(20)),
];

pub async fn run(args: DemoArgs) -> anyhow::Result<ExitCode> {
    let station = wire::device::SharedModel::new(jbc::device::Station::new(
        jbc::device::StationConfig::default(),
    ));
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
    let url = format!("tcp://{}", listener.local_addr()?);
    tokio::spawn(link::serve::serve_tcp(
        listener,
        move || station.line(),
        None,
    ));
    output::line(format!("simulated JBC station listening on {url}"))?;
    output::line(format!(
        "(try in another terminal: cellbus jbc --endpoint {url} status)"
    ))?;

    let line = Line::open(&Endpoint::parse(&url, JBC_LINE)?).await?;
    let mut client = Client::new(SharedLine::new(line), ClientConfig::default());
    let code = |text: &str| -> Code { text.parse().expect("the demo's codes are valid") };
    let (set_temp, tool, air, external, power, status) = (
        code("ST1"),
        code("PS1"),
        code("AT1"),
        code("ET1"),
        code("PP1"),
        code("PS1"),
    );

    output::line(format!(
        "{:>6}  {:>9} {:>10} {:>10} {:>7}  status",
        "time", "set", "air", "external", "power"
    ))?;
    let started = tokio::time::Instant::now();
    let mut ticker = tokio::time::interval(args.interval.max(Duration::from_millis(50)));
    let mut step = usize::MAX;
    let mut step_ends = started;
    loop {
        tokio::select! {
            _ = ticker.tick() => {}
            _ = tokio::signal::ctrl_c() => return Ok(ExitCode::SUCCESS),
        }
        let now = tokio::time::Instant::now();
        if args
            .duration
            .is_some_and(|d| now.duration_since(started) >= d)
        {
            return Ok(ExitCode::SUCCESS);
        }
        if now >= step_ends {
            step = step.wrapping_add(1) % SCRIPT.len();
            let (temperature, on, hold) = SCRIPT[step];
            client.write(set_temp, temperature).await?;
            client.write(tool, i32::from(on)).await?;
            step_ends = now + hold;
        }
        let set = client.read(set_temp).await?;
        let readings = (
            client.read(air).await?,
            client.read(external).await?,
            client.read(power).await?,
        );
        let state = client.read(status).await?;
        output::line(format!(
            "{:>5}s  {:>9} {:>10} {:>10} {:>7}  {state}",
            now.duration_since(started).as_secs(),
            set.to_string(),
            readings.0.to_string(),
            readings.1.to_string(),
            readings.2.to_string(),
        ))?;
    }
}
