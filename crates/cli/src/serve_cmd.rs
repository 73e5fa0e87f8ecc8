//! `cellbus serve` and `cellbus config …`: the gateway, and its configuration file.

use gateway::northbound::mqtt::MqttFlags;
use gateway::options::Flags;
use gateway::plugins::Registry;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use clap::{Args, Subcommand};

use crate::output::{self, usage};

#[derive(Debug, Args)]
pub struct ServeArgs {
    /// Where the web page, the API and /metrics listen. Port 0 picks a free port. The
    /// first line printed is `listening on http://IP:PORT`.
    #[arg(long, value_name = "IP:PORT", default_value_t = gateway::DEFAULT_LISTEN)]
    pub listen: SocketAddr,
    /// The cell's configuration (TOML; `cellbus config example` prints one). Without it,
    /// a simulated demo cell runs in this process.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Where the history database is kept.
    #[arg(long, value_name = "DIR", default_value = gateway::DEFAULT_DATA_DIR)]
    pub data: PathBuf,
    /// How long history (samples and events) is kept: `30d`, `12h`, `6months`; at least
    /// `1h` (`m` is minutes). Deleted hourly, in chunks; the freed space goes back to the
    /// file system.
    #[arg(long, value_name = "AGE", default_value = "30d", value_parser = parse_retain)]
    pub retain: Duration,
    /// How long the audit log of write attempts is kept: `365d`, `2y`; at least `1d`. Never
    /// less than --retain (the longer wins).
    #[arg(long, value_name = "AGE", default_value = "365d", value_parser = parse_retain_audit)]
    pub retain_audit: Duration,
    /// Accept `POST /api/devices/{id}/write`, with `Authorization: Bearer <token>` (the
    /// token from --token, CELLBUS_TOKEN or the configuration).
    #[arg(long)]
    pub allow_writes: bool,
    /// The write token (prefer CELLBUS_TOKEN, which does not show in the process list).
    #[arg(long, value_name = "TOKEN")]
    pub token: Option<String>,
    /// Require this token (or the write token) on every API route and /metrics, as
    /// `Authorization: Bearer <token>`; the page asks for it once. Prefer
    /// CELLBUS_READ_TOKEN, or read_token in the configuration. Without one, anyone who
    /// can reach the port reads the cell.
    #[arg(long, value_name = "TOKEN")]
    pub read_token: Option<String>,
    /// Publish the cell to this MQTT broker (mqtt://HOST:PORT, or mqtts://HOST:PORT for
    /// TLS: the [mqtt] table's ca_file, else the system's roots), as a Sparkplug B edge
    /// node or as JSON (--mqtt-mode). The demo cell publishes as group `cellbus`, edge node
    /// `demo` (JSON under `cellbus/demo/`); with --config it replaces the [mqtt] table's
    /// broker.
    #[arg(long, value_name = "URL")]
    pub mqtt: Option<String>,
    /// What to publish on MQTT: `sparkplug` (Sparkplug B 3.0, the default) or `json` (one
    /// retained topic per point).
    #[arg(long, value_name = "MODE", value_parser = parse_mqtt_mode)]
    pub mqtt_mode: Option<gateway::northbound::mqtt::config::MqttMode>,
    /// The Sparkplug edge node id (default: the [mqtt] table's, else this machine's host
    /// name; `demo` for the demo cell).
    #[arg(long, value_name = "ID")]
    pub mqtt_node: Option<String>,
    /// Wait for this Sparkplug primary host application to be online (its
    /// spBv1.0/STATE/ID message) before publishing; while it is away, store and forward.
    #[arg(long, value_name = "ID")]
    pub mqtt_primary_host: Option<String>,
    /// Publish the cell's placement machines as IPC-CFX endpoints over AMQP 1.0 to this
    /// broker and address: amqp://HOST:PORT/ADDRESS (a queue; RabbitMQ 3.x exchanges as
    /// amqp://HOST:PORT//exchange/NAME). The demo's machine is `cellbus.demo.placer1`;
    /// with --config it replaces the [cfx] table's broker and address.
    // A build without IPC-CFX hides the two flags and refuses them in words
    // (`interface_flags`).
    #[cfg_attr(not(feature = "cfx"), arg(hide = true))]
    #[arg(long, value_name = "URL")]
    pub cfx: Option<String>,
    /// Answer the CFX endpoints' requests (AreYouThere, WhoIsThere, GetEndpointInformation)
    /// on this address over AMQP 1.0, each at its handle (port 0 picks a free port; a line
    /// `cfx on amqp://IP:PORT` is printed).
    #[cfg_attr(not(feature = "cfx"), arg(hide = true))]
    #[arg(long, value_name = "IP:PORT")]
    pub cfx_listen: Option<SocketAddr>,
    /// Serve the cell over OPC UA on this address (port 0 picks a free port); the second
    /// line printed is `opcua on opc.tcp://IP:PORT`. The demo cell on loopback offers
    /// security None and anonymous reading next to Basic256Sha256, and the user `operator`
    /// whose password is the write token; with --config it replaces the [opcua] table's
    /// endpoint (without a table: Basic256Sha256 only, anonymous reading while writes are
    /// off).
    // A build without OPC UA hides the flag and refuses it in words (`interface_flags`).
    #[cfg_attr(not(feature = "opcua"), arg(hide = true))]
    #[arg(long, value_name = "IP:PORT")]
    pub opcua: Option<SocketAddr>,
}

/// The device kinds and interfaces of this build of `cellbus`: the gateway's own, and OPC
/// UA when built with the `opcua` feature (the default). `serve` and `config check` both
/// read the configuration with it, so they accept the same files.
pub fn registry() -> Registry {
    #[cfg(feature = "opcua")]
    let registry = gateway::plugins::builtin().with_interface(&cellbus_opcua::Opcua);
    #[cfg(not(feature = "opcua"))]
    let registry = without_opcua(gateway::plugins::builtin());
    registry
}

/// Why a build without the `opcua` feature refuses a config's `[opcua]` table.
#[cfg(any(test, not(feature = "opcua")))]
const NO_OPCUA_TABLE: &str = "this build of cellbus has no OPC UA interface (it was built \
     without the `opcua` feature): remove the [opcua] table, or use a build with OPC UA";

/// Why a build without the `opcua` feature refuses `serve --opcua`.
#[cfg(not(feature = "opcua"))]
const NO_OPCUA_FLAG: &str = "--opcua: this build of cellbus has no OPC UA interface (it was \
     built without the `opcua` feature): leave the flag out, or use a build with OPC UA";

/// Why a build without the `cfx` feature refuses `serve --cfx` and `--cfx-listen` (its
/// `[cfx]` table is refused by `gateway::plugins::builtin`).
#[cfg(not(feature = "cfx"))]
const NO_CFX_FLAG: &str = "--cfx, --cfx-listen: this build of cellbus has no IPC-CFX \
     interface (it was built without the `cfx` feature): leave the flags out, or use a \
     build with IPC-CFX";

/// `registry` as a build without OPC UA has it: a config's `[opcua]` table is refused in
/// those words, not as a table nobody knows.
#[cfg(any(test, not(feature = "opcua")))]
fn without_opcua(registry: Registry) -> Registry {
    registry.with_interface_left_out("opcua", NO_OPCUA_TABLE)
}

/// What the command line says to the interfaces of this build.
fn interface_flags(args: &ServeArgs) -> anyhow::Result<Flags> {
    let flags = Flags::default().with(MqttFlags {
        broker: args.mqtt.clone(),
        mode: args.mqtt_mode,
        node: args.mqtt_node.clone(),
        primary_host: args.mqtt_primary_host.clone(),
    });
    #[cfg(feature = "cfx")]
    let flags = flags.with(gateway::northbound::cfx::CfxFlags {
        url: args.cfx.clone(),
        listen: args.cfx_listen,
    });
    #[cfg(not(feature = "cfx"))]
    if args.cfx.is_some() || args.cfx_listen.is_some() {
        return Err(usage(NO_CFX_FLAG));
    }
    #[cfg(feature = "opcua")]
    let flags = flags.with(cellbus_opcua::OpcuaFlags { listen: args.opcua });
    #[cfg(not(feature = "opcua"))]
    if args.opcua.is_some() {
        return Err(usage(NO_OPCUA_FLAG));
    }
    Ok(flags)
}

/// The shortest `--retain`: anything shorter is most likely a slip (`30m` is 30 minutes, not
/// months) that would delete the history a minute after the start.
const MIN_RETAIN: Duration = Duration::from_secs(3600);
/// The shortest `--retain-audit`.
const MIN_RETAIN_AUDIT: Duration = Duration::from_secs(24 * 3600);

fn parse_retain(text: &str) -> Result<Duration, String> {
    parse_age(text, MIN_RETAIN, "history")
}

fn parse_retain_audit(text: &str) -> Result<Duration, String> {
    parse_age(text, MIN_RETAIN_AUDIT, "audit log")
}

/// An age of at least `least`, in humantime's words.
fn parse_age(text: &str, least: Duration, what: &str) -> Result<Duration, String> {
    let age = humantime::parse_duration(text)
        .map_err(|e| format!("{e}; give an age such as 30d, 12h or 6months"))?;
    if age < least {
        return Err(format!(
            "{text} would keep less than {} of {what}; ages are in s, min or m (minutes), h, \
             d, w, months (or M) and y",
            humantime::format_duration(least)
        ));
    }
    Ok(age)
}

fn parse_mqtt_mode(text: &str) -> Result<gateway::northbound::mqtt::config::MqttMode, String> {
    gateway::northbound::mqtt::config::MqttMode::parse(text)
}

#[derive(Debug, Subcommand)]
pub enum ConfigCommand {
    /// Check a configuration file and say what it describes, or what is wrong and where.
    Check {
        /// The file.
        file: PathBuf,
    },
    /// Print an example configuration for a real cell.
    Example {
        /// Instead: a configuration that reads the example energy meter `cellbus sim modbus
        /// --example energy-meter --framing tcp` serves, at this endpoint.
        #[arg(long, value_name = "ENDPOINT", num_args = 0..=1, default_missing_value = "modbus-tcp://127.0.0.1:5020")]
        modbus_meter: Option<String>,
    },
    /// Print a CSV register list (name,title,table,address,type,order,scale,offset,unit,
    /// writable_min,writable_max; columns in any order) as [[line.device.register]] tables.
    ImportCsv {
        /// The CSV file.
        file: PathBuf,
    },
}

pub async fn serve(args: ServeArgs) -> anyhow::Result<ExitCode> {
    let registry = registry();
    let flags = interface_flags(&args)?;
    if let Some(path) = &args.config {
        // A bad file is a usage error (exit 2), reported before anything starts.
        gateway::config::check_config(path, &registry.config).map_err(usage)?;
    }
    let options = gateway::ServeOptions {
        listen: args.listen,
        config: args.config,
        data_dir: args.data,
        retain: args.retain,
        retain_audit: args.retain_audit,
        allow_writes: args.allow_writes,
        token: args.token,
        read_token: args.read_token,
        flags,
    };
    gateway::serve(options, &registry, shutdown_signal()).await?;
    Ok(ExitCode::SUCCESS)
}

pub fn config(command: ConfigCommand) -> anyhow::Result<ExitCode> {
    match command {
        ConfigCommand::Example { modbus_meter: None } => {
            print!("{}", gateway::EXAMPLE_CONFIG);
            Ok(ExitCode::SUCCESS)
        }
        ConfigCommand::Example {
            modbus_meter: Some(endpoint),
        } => {
            let text = gateway::driver::modbus::config::example_meter_config(&endpoint)
                .map_err(anyhow::Error::msg)?;
            print!("{text}");
            Ok(ExitCode::SUCCESS)
        }
        ConfigCommand::ImportCsv { file } => {
            let registers =
                gateway::driver::modbus::config::registers_from_csv(&file).map_err(usage)?;
            print!(
                "{}",
                gateway::driver::modbus::config::registers_toml(&registers)
            );
            for overlap in gateway::driver::modbus::config::overlapping_registers(&registers) {
                eprintln!("warning: {}: {overlap}", file.display());
            }
            Ok(ExitCode::SUCCESS)
        }
        ConfigCommand::Check { file } => {
            let plugins = registry().config;
            let cell = gateway::config::check_config(&file, &plugins).map_err(usage)?;
            let devices: usize = cell.lines.iter().map(|line| line.devices.len()).sum();
            let interfaces = plugins.interfaces_of(&cell);
            let count = |n: usize, what: &str| match n {
                1 => format!("1 {what}"),
                n => format!("{n} {what}s"),
            };
            output::line(format!(
                "{}: ok, {}, {}, {}",
                file.display(),
                count(cell.lines.len(), "line"),
                count(devices, "device"),
                match interfaces.len() {
                    0 => "no interfaces beyond HTTP".to_owned(),
                    1 => "1 interface".to_owned(),
                    n => format!("{n} interfaces"),
                }
            ))?;
            let loads = gateway::load::line_loads(&cell);
            for line in &cell.lines {
                let load = match loads.iter().find(|l| l.line == line.name) {
                    Some(load) => {
                        format!(" (its polls need about {:.0} % of it)", load.share * 100.0)
                    }
                    None => String::new(),
                };
                output::line(format!("  line {} on {}{load}", line.name, line.endpoint))?;
                for device in &line.devices {
                    let driver = &device.driver;
                    let address = match driver.address {
                        Some(address) => format!(", address {address}"),
                        None => String::new(),
                    };
                    output::line(format!(
                        "    {} ({}{address}): {}",
                        driver.id, driver.protocol, device.name
                    ))?;
                }
            }
            for (table, words) in interfaces {
                output::line(format!("  [{table}] {words}").trim_end().to_owned())?;
            }
            let shifts = &cell.shifts;
            let each: Vec<String> = shifts.shifts().iter().map(ToString::to_string).collect();
            output::line(format!(
                "  shifts ({}): {}",
                shifts.zone_name(),
                each.join("; ")
            ))?;
            for alarm in &cell.alarms {
                output::line(format!("  alarm on {}", alarm.describe()))?;
            }
            let overloaded = loads.iter().filter_map(gateway::load::LineLoad::warning);
            for warning in cell
                .warnings()
                .into_iter()
                .chain(cell.absent_ports())
                .chain(overloaded)
            {
                output::line(format!("warning: {warning}"))?;
            }
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// Resolves on Ctrl-C or SIGTERM, so the gateway can flush its history before exiting.
pub async fn shutdown_signal() {
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut signal) => {
                signal.recv().await;
            }
            Err(e) => {
                tracing::warn!(
                    "cannot listen for SIGTERM ({e}); Ctrl-C still stops the gateway cleanly"
                );
                std::future::pending::<()>().await;
            }
        }
    };
    tokio::select! {
        _ = tokio::signal::ctrl_c() => {}
        () = terminate => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CELL: &str = "[[line]]\nname = \"rework\"\nendpoint = \"tcp://127.0.0.1:1\"\n\
                        [[line.device]]\nid = \"jbc1\"\nprotocol = \"jbc\"\n\n[opcua]\n";

    #[test]
    fn a_build_without_opcua_refuses_an_opcua_table_where_it_is_and_says_why() {
        let registry = without_opcua(gateway::plugins::builtin());
        let refused = gateway::config::parse_config(
            CELL,
            std::path::Path::new("cell.toml"),
            &registry.config,
        )
        .expect_err("the [opcua] table is refused");
        let shown = refused.to_string();
        assert_eq!(refused.position(), Some((8, 2)), "{shown}");
        assert_eq!(
            shown.lines().next(),
            Some(format!("cell.toml:8:2: {NO_OPCUA_TABLE}").as_str())
        );
        assert!(
            shown.contains("no OPC UA interface (it was built without the `opcua` feature)"),
            "{shown}"
        );
    }

    #[cfg(not(feature = "cfx"))]
    #[test]
    fn a_build_without_cfx_refuses_a_cfx_table_where_it_is_and_says_why() {
        let cell = CELL.replace("[opcua]", "[cfx]");
        let refused = gateway::config::parse_config(
            &cell,
            std::path::Path::new("cell.toml"),
            &registry().config,
        )
        .expect_err("the [cfx] table is refused");
        let shown = refused.to_string();
        assert_eq!(refused.position(), Some((8, 2)), "{shown}");
        assert_eq!(
            shown.lines().next(),
            Some(format!("cell.toml:8:2: {}", gateway::plugins::NO_CFX_TABLE).as_str())
        );
    }

    #[cfg(feature = "opcua")]
    #[test]
    fn a_build_with_opcua_reads_the_opcua_table() {
        let cell = gateway::config::parse_config(
            CELL,
            std::path::Path::new("cell.toml"),
            &registry().config,
        )
        .expect("the [opcua] table is read");
        assert!(cell.interfaces.contains_key("opcua"), "{cell:?}");
    }
}
