//! `cellbus`: talk to the cell's devices, simulate them, decode captures.
//!
//! This crate only parses arguments, calls the library crates and prints; no protocol
//! logic lives here.
#![forbid(unsafe_code)]

#[cfg(feature = "cfx")]
mod cfx_cmd;
mod decode;
mod demo;
#[cfg(feature = "historian")]
mod historian_cmd;
mod jbc_cmd;
mod jbus_cmd;
mod mqtt_cmd;
mod output;
mod panasonic_cmd;
mod rounds;
mod serve_cmd;
mod sim;
mod sim_control;
mod thermosald_cmd;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// cellbus: a toolkit and gateway for a production cell's serial and legacy-protocol devices.
///
/// The device commands (jbc, modbus, cross, thermosald, panasonic) take their options
/// before or after the subcommand: `cellbus jbc --json read ST1` is `cellbus jbc read ST1
/// --json`. Their watches (and `panasonic events`) take --count N and --for DURATION, and
/// stop at Ctrl-C.
///
/// Exit codes: 0 done, 1 the device refused, did not answer, or the line failed, 2 bad
/// arguments or configuration.
#[derive(Debug, Parser)]
#[command(
    name = "cellbus",
    version,
    propagate_version = true,
    max_term_width = 100
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// How much cellbus logs on stderr: error, warn, info, debug or trace. Default: info for
    /// `serve` and `historian` (devices and lines going down and coming back, the first
    /// round's summary), warn for the others; debug shows protocol detail. RUST_LOG (e.g.
    /// `RUST_LOG=gateway::scheduler=debug,rumqttc=info`) sets it per module, libraries
    /// included; this option wins over it.
    #[arg(long, global = true, value_name = "LEVEL")]
    log_level: Option<tracing::level_filters::LevelFilter>,
    /// How log lines look: `text` (one line each, in colour only on a terminal; journald
    /// adds the time of its own) or `json` (one JSON object a line, for log shippers).
    #[arg(long, global = true, value_name = "FORMAT", default_value = "text")]
    log_format: LogFormat,
}

/// The form of the log lines (`--log-format`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum LogFormat {
    /// Lines for people.
    Text,
    /// One JSON object a line: time, level, target, message and fields.
    Json,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the gateway: poll the cell, keep its history, serve it over HTTP, a live web
    /// page and Prometheus metrics. Without --config, a simulated demo cell.
    Serve(serve_cmd::ServeArgs),
    /// Run the plant historian: a Sparkplug B primary host that takes every gateway's data
    /// off the plant's MQTT broker into PostgreSQL (views cellbus_samples, cellbus_events,
    /// cellbus_points, cellbus_states, cellbus_alarms), and serves the gateway's history API for the whole
    /// plant.
    ///
    /// Exit codes: 0 stopped by Ctrl-C or SIGTERM (pending rows committed), 1 PostgreSQL
    /// refused the login or the schema is newer, 2 bad arguments.
    #[cfg(feature = "historian")]
    Historian(historian_cmd::HistorianArgs),
    /// Check or print a gateway configuration file.
    #[command(subcommand)]
    Config(serve_cmd::ConfigCommand),
    /// Run a simulated JBC station and a live view of it in the terminal (no hardware).
    Demo(demo::DemoArgs),
    /// Talk to a JBC JTSE hot-air station (RS-232 robot protocol).
    Jbc(jbc_cmd::JbcArgs),
    /// Talk to any Modbus RTU / JBUS or Modbus TCP device: read and write coils and registers (functions
    /// 1-6, 15, 16). Serial defaults: 9600 baud, 8N1.
    Modbus(jbus_cmd::ModbusArgs),
    /// Read a Chloride CROSS static transfer switch over JBUS: its state in words, or its
    /// changes live. Serial defaults: 9600 baud, 8N1, unit 2.
    Cross(jbus_cmd::CrossArgs),
    /// Talk to Thermosald ISC impulse-sealer regulators on RS-485 (addresses 0-7): read and
    /// write their data, commands, scan, watch. Serial defaults: 9600 baud, 8N1.
    Thermosald(thermosald_cmd::ThermosaldArgs),
    /// Talk to a Panasonic BM placement machine over its host computer protocol (TCP Port 1
    /// for commands, Port 2 for its R messages): status, programs, production data,
    /// remote start and reset, events.
    Panasonic(panasonic_cmd::PanasonicArgs),
    /// Watch an MQTT broker: `mqtt sub` prints what the gateway (or anyone) publishes,
    /// Sparkplug B decoded into metrics.
    #[command(subcommand)]
    Mqtt(mqtt_cmd::MqttCommand),
    /// Watch IPC-CFX messages on AMQP 1.0: `cfx sub` prints what the gateway's placement
    /// machines (or any CFX endpoint) publish, from a broker's address or as the receiver.
    #[cfg(feature = "cfx")]
    #[command(subcommand)]
    Cfx(cfx_cmd::CfxCommand),
    /// Run a simulated device on a TCP port or a PTY.
    #[command(subcommand)]
    Sim(sim::SimCommand),
    /// Split a captured byte stream into annotated frames.
    #[command(subcommand)]
    Decode(decode::DecodeCommand),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    #[cfg(feature = "historian")]
    let service = matches!(cli.command, Command::Serve(_) | Command::Historian(_));
    #[cfg(not(feature = "historian"))]
    let service = matches!(cli.command, Command::Serve(_));
    init_logging(cli.log_level, cli.log_format, service);
    if matches!(cli.command, Command::Serve(_) | Command::Demo(_)) {
        // The gateway's malloc, set before the runtime starts its threads.
        gateway::tune_malloc();
    }
    let runtime = match tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
    {
        Ok(runtime) => runtime,
        Err(e) => {
            eprintln!("cellbus: cannot start the async runtime: {e}");
            return ExitCode::from(1);
        }
    };
    let result = runtime.block_on(async {
        match cli.command {
            Command::Serve(args) => serve_cmd::serve(args).await,
            Command::Config(command) => serve_cmd::config(command),
            #[cfg(feature = "historian")]
            Command::Historian(args) => historian_cmd::run(args).await,
            Command::Demo(args) => demo::run(args).await,
            Command::Jbc(args) => jbc_cmd::run(args).await,
            Command::Modbus(args) => jbus_cmd::run_modbus(args).await,
            Command::Cross(args) => jbus_cmd::run_cross(args).await,
            Command::Thermosald(args) => thermosald_cmd::run(args).await,
            Command::Panasonic(args) => panasonic_cmd::run(args).await,
            Command::Mqtt(command) => mqtt_cmd::run(command).await,
            #[cfg(feature = "cfx")]
            Command::Cfx(command) => cfx_cmd::run(command).await,
            Command::Sim(command) => sim::run(command).await,
            Command::Decode(command) => decode::run(command),
        }
    });
    // Simulators and watchers may leave tasks blocked on I/O: do not wait for them.
    runtime.shutdown_background();
    match result {
        Ok(code) => code,
        Err(err) if output::is_broken_pipe(&err) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("cellbus: {}", output::describe(&err));
            output::exit_code_for(&err)
        }
    }
}

/// cellbus's own crates, which `--log-level` sets (libraries stay at warn).
const OWN_CRATES: [&str; 12] = [
    "cellbus",
    "cellbus_opcua",
    "gateway",
    "historian",
    "kit",
    "link",
    "jbc",
    "jbus",
    "thermosald",
    "panasonic",
    "sparkplug",
    "wire",
];

/// Logs go to stderr, so stdout stays for results; colour only on a terminal (and not with
/// NO_COLOR set), so a journal or a file gets plain lines.
fn init_logging(
    level: Option<tracing::level_filters::LevelFilter>,
    format: LogFormat,
    service: bool,
) {
    let own = |level: tracing::level_filters::LevelFilter| {
        let mut filter = tracing_subscriber::EnvFilter::new("warn");
        for name in OWN_CRATES {
            if let Ok(directive) = format!("{name}={level}").parse() {
                filter = filter.add_directive(directive);
            }
        }
        filter
    };
    let filter = match level {
        Some(level) => own(level),
        None => tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| {
            if service {
                // The demo cell's simulators connecting and disconnecting is not news.
                let mut filter = own(tracing::level_filters::LevelFilter::INFO);
                for quiet in ["link::serve=warn", "panasonic::server=warn"] {
                    if let Ok(directive) = quiet.parse() {
                        filter = filter.add_directive(directive);
                    }
                }
                filter
            } else {
                own(tracing::level_filters::LevelFilter::WARN)
            }
        }),
    };
    let colour = std::io::IsTerminal::is_terminal(&std::io::stderr())
        && std::env::var_os("NO_COLOR").is_none_or(|v| v.is_empty());
    let logs = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr);
    match format {
        LogFormat::Text => logs.with_ansi(colour).init(),
        LogFormat::Json => logs.json().with_ansi(false).init(),
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_command_line_definitions_are_consistent() {
        <super::Cli as clap::CommandFactory>::command().debug_assert();
    }
}
