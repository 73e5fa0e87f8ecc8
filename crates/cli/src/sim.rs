//! `cellbus sim …`: simulated devices on a TCP port or a PTY.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicU64, Ordering};

use anyhow::Context;
use clap::{Args, Subcommand};
use link::SerialSettings;
use link::serve::{Pty, serve_tcp};
use wire::Device;
use wire::device::{FaultInjector, WithFrameGap};

use crate::output::{self, usage};

#[derive(Debug, Subcommand)]
pub enum SimCommand {
    /// A JBC JTSE hot-air station (address 01, robot mode on, JT tool connected).
    Jbc(SimJbcArgs),
    /// A Chloride CROSS static transfer switch on JBUS (unit 2, 9600 8N1; S1 preferred and
    /// feeding a 40 kVA load; answers function 3 only, exactly as its manual says).
    Cross(crate::jbus_cmd::SimCrossArgs),
    /// A generic Modbus RTU server (functions 1-6, 15, 16; unit 1; every address writable,
    /// or the tables of a map file).
    Modbus(crate::jbus_cmd::SimModbusArgs),
    /// Thermosald ISC regulators on one RS-485 line (address 0, or --addresses 0,1,2), each
    /// with its own sealing band, memory and faults; 9600 8N1, answers 200 ms after a question.
    Thermosald(crate::thermosald_cmd::SimThermosaldArgs),
    /// A Panasonic BM placement machine (host computer protocol): Port 1 for C commands,
    /// Port 2 for R messages; a demo program selected, boards every 22 s when running.
    Panasonic(crate::panasonic_cmd::SimPanasonicArgs),
}

/// Where and how a simulator serves its device.
#[derive(Debug, Clone, Args)]
pub struct ServeArgs {
    /// Listen for TCP connections here; each connection is a line to the same device.
    /// Prints `listening on tcp://IP:PORT` first. Port 0 picks a free port.
    #[arg(long, value_name = "IP:PORT", conflicts_with = "pty")]
    pub listen: Option<SocketAddr>,
    /// Create a pseudo-terminal and link its device end at PATH, so any serial program can
    /// open PATH as a port. Prints `listening on PATH` first.
    #[arg(long, value_name = "PATH")]
    pub pty: Option<PathBuf>,
    /// Seed for everything random in the simulator (measurement noise, injected faults):
    /// the same seed gives the same run.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Share of replies, from 0 to 1, that meet a line fault: dropped, late, a flipped bit,
    /// or garbage before it.
    #[arg(long, value_name = "F", default_value_t = 0.0)]
    pub fault_rate: f64,
    /// Behave like a serial line of this speed (bit/s): requests are heard when their last
    /// character would have arrived and replies leave at the line's character rate.
    #[arg(long, value_name = "B")]
    pub baud: Option<u32>,
    /// Silence after which a half-received frame is dropped, as a real device's receiver
    /// does. Default: the protocol's gap at --baud (3.5 characters for Modbus RTU, 10 for
    /// JBC, 40 ms for Thermosald), 5 ms on an unpaced line.
    #[arg(long, value_name = "DURATION", value_parser = humantime::parse_duration)]
    pub frame_gap: Option<std::time::Duration>,
}

#[derive(Debug, Args)]
pub struct SimJbcArgs {
    #[command(flatten)]
    pub serve: ServeArgs,
    /// The station's address on the line (00–99).
    #[arg(long, default_value = "01")]
    pub address: jbc::frame::Address,
    /// Frames carry no address fields (the station's "address off" setting).
    #[arg(long)]
    pub no_address: bool,
}

pub async fn run(command: SimCommand) -> anyhow::Result<ExitCode> {
    match command {
        SimCommand::Jbc(args) => {
            let config = jbc::device::StationConfig {
                address: (!args.no_address).then_some(args.address),
                ..jbc::device::StationConfig::default()
            };
            let station = wire::device::SharedModel::new(jbc::device::Station::new(config));
            serve(&args.serve, SerialSettings::new_8e1(19200), move || {
                station.line()
            })
            .await
        }
        SimCommand::Cross(args) => crate::jbus_cmd::sim_cross(args).await,
        SimCommand::Modbus(args) => crate::jbus_cmd::sim_modbus(args).await,
        SimCommand::Thermosald(args) => crate::thermosald_cmd::sim(args).await,
        SimCommand::Panasonic(args) => crate::panasonic_cmd::sim(args).await,
    }
}

/// Serves one device per connection (each a line to the same model) until interrupted.
pub async fn serve<D, F>(
    args: &ServeArgs,
    framing: SerialSettings,
    make: F,
) -> anyhow::Result<ExitCode>
where
    D: Device,
    F: Fn() -> D + Send + 'static,
{
    serve_with(args, framing, "tcp", make, || ()).await
}

/// Like [`serve`], printing `listening on SCHEME://IP:PORT` (`modbus-tcp` for a device
/// that frames Modbus TCP itself) and calling `listening` right after that line is out (to
/// start a control channel whose answers must come after it).
pub async fn serve_with<D, F>(
    args: &ServeArgs,
    framing: SerialSettings,
    scheme: &str,
    make: F,
    listening: impl FnOnce(),
) -> anyhow::Result<ExitCode>
where
    D: Device,
    F: Fn() -> D + Send + 'static,
{
    if !(0.0..=1.0).contains(&args.fault_rate) {
        return Err(usage(format!(
            "--fault-rate {} is not between 0 and 1",
            args.fault_rate
        )));
    }
    let pace = match args.baud {
        Some(baud) if link::endpoint::BAUD_RANGE.contains(&baud) => {
            Some(SerialSettings { baud, ..framing })
        }
        Some(baud) => {
            return Err(usage(format!(
                "--baud {baud} is not a serial speed (50 to 4000000 bit/s)"
            )));
        }
        None => None,
    };
    let (seed, rate, frame_gap) = (args.seed, args.fault_rate, args.frame_gap);
    let connection = AtomicU64::new(0);
    // Each line gets its own fault sequence, reproducible from the seed and its order.
    let faulty = move || {
        let n = connection.fetch_add(1, Ordering::Relaxed);
        let device = FaultInjector::new(make(), seed.wrapping_add(n), rate)
            .expect("fault rate checked above");
        WithFrameGap::new(device, frame_gap)
    };
    let served = if let Some(path) = &args.pty {
        let pty =
            Pty::create(path).with_context(|| format!("cannot serve on {}", path.display()))?;
        output::line(format!("listening on {}", pty.link().display()))?;
        listening();
        tokio::select! {
            served = pty.serve(faulty(), pace) => served.context("the PTY failed"),
            _ = tokio::signal::ctrl_c() => Ok(()),
        }
    } else {
        let addr = args
            .listen
            .unwrap_or_else(|| SocketAddr::from(([127, 0, 0, 1], 0)));
        let listener = tokio::net::TcpListener::bind(addr).await.map_err(|e| {
            let hint = if e.kind() == std::io::ErrorKind::AddrInUse {
                "; the port is taken, try --listen 127.0.0.1:0"
            } else {
                ""
            };
            anyhow::anyhow!("cannot listen on {addr}: {e}{hint}")
        })?;
        output::line(format!(
            "listening on {scheme}://{}",
            listener.local_addr()?
        ))?;
        listening();
        tokio::select! {
            served = serve_tcp(listener, faulty, pace) => served.context("the listener failed"),
            _ = tokio::signal::ctrl_c() => Ok(()),
        }
    };
    served.map(|()| ExitCode::SUCCESS)
}
