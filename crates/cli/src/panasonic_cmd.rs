//! `cellbus panasonic …`, `cellbus sim panasonic` and `cellbus decode panasonic`: the host
//! computer protocol of Panasonic BM placement machines over TCP (Port 1 for C commands,
//! Port 2 for the machine's R messages).

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use clap::{Args, Subcommand};
use panasonic::client::{Client, ClientConfig, DEFAULT_RETRIES, Notice};
use panasonic::message::{COMMAND_LEN, HEADER_LEN, TERMINATOR_LEN};
use panasonic::packet::{Annotated, Packet, annotate};
use panasonic::server::TwinServer;
use panasonic::{
    ControlMode, DEFAULT_COMMAND_PORT, Event, Machine, MachineConfig, ProductionRequest,
    ProductionScope, ProgramName, StopMode, Target,
};
use serde_json::{Value, json};

use crate::output::{self, printable, usage};
use crate::rounds::{Stop, StopArgs};

/// Data bytes shown per message by `decode` (the rest is counted).
const DATA_SHOWN: usize = 120;

#[derive(Debug, Args)]
#[command(
    after_help = "--json: status {\"state\":\"run\",\"mode\":\"remote\"}, program \
    {\"program\":\"NAME\"}, programs [{\"date\":\"yy/mm/dd\",\"name\":\"NAME\"}], production \
    {\"header\",\"sections\"}, events one object per R message, the others what was done. \
    Options go before or after the subcommand."
)]
pub struct PanasonicArgs {
    /// The machine (needed): HOST or HOST:PORT of Port 1 (commands; default port 49152).
    /// IPv6 in brackets: [::1]:49152.
    #[arg(long, value_name = "HOST[:PORT]", global = true)]
    pub host: Option<String>,
    #[command(flatten)]
    pub output: output::JsonArg,
    /// Port 2 (the machine's R messages), for `events`. Default: Port 1's number + 1
    /// (49153 for the default 49152).
    #[arg(long, value_name = "P", global = true)]
    pub events_port: Option<u16>,
    /// Time to wait for each answer of the machine.
    #[arg(long, default_value = "5s", value_parser = crate::output::parse_timeout, global = true)]
    pub timeout: Duration,
    /// Retries, on a new connection, of a command that changes nothing (status, names,
    /// lists, uploads) after a lost answer; a download, delete, start or reset is never
    /// repeated.
    #[arg(long, default_value_t = DEFAULT_RETRIES, global = true)]
    pub retries: u8,
    #[command(subcommand)]
    pub action: PanasonicAction,
}

#[derive(Debug, Subcommand)]
pub enum PanasonicAction {
    /// C2ST: run, ready or error stop; online or remote.
    Status,
    /// C3: the selected product program.
    Program,
    /// C1RP: the stored product programs with the date each was registered or revised.
    Programs,
    /// C1M000 (or C1M900 with --clear): production management data, grand total.
    Production {
        /// Clear the counters after reading them (C1M900; nozzle and feeder totals stay).
        #[arg(long)]
        clear: bool,
    },
    /// C1: a product program as the machine stores it, to stdout or --out FILE.
    Upload {
        /// The program's name (1 to 15 characters).
        name: String,
        /// Write the program to this file instead of stdout.
        #[arg(long, value_name = "FILE")]
        out: Option<PathBuf>,
    },
    /// C0: stores FILE on the machine as product program NAME (refused for the selected
    /// program and over the machine's limits).
    Download {
        /// The program's name (1 to 15 characters).
        name: String,
        /// The program text (%HEADER … "*" line).
        file: PathBuf,
    },
    /// C0R: deletes product program NAME.
    Delete {
        /// The program's name.
        name: String,
    },
    /// C5ST: starts the machine (Remote mode only); R1ST follows on Port 2.
    Start {
        /// Stop mode: bl (1 block), ep (end of program) or ct (continuous); default: the
        /// previous one.
        #[arg(long, value_name = "bl|ep|ct")]
        mode: Option<StopMode>,
    },
    /// C5RE: resets the machine (Remote mode only); R1RE follows on Port 2 when done.
    Reset,
    /// Prints the machine's R messages from Port 2 as they arrive, in words, until --count
    /// messages, --for a while, or Ctrl-C; reconnects when the connection is lost. Leaves
    /// Port 1 free for other commands (no keep-alive).
    #[command(mut_arg("count", |count| {
        count.help("Stop after N R messages, at least 1 (default: until --for or Ctrl-C)")
    }))]
    Events {
        #[command(flatten)]
        stop: StopArgs,
    },
}

/// `cellbus sim panasonic`.
#[derive(Debug, Args)]
#[command(after_help = crate::sim_control::long_help::<panasonic::operator::Command>())]
pub struct SimPanasonicArgs {
    /// Port 1 (commands). Prints `listening on tcp://IP:PORT` first. Port 0 picks a free port.
    #[arg(long, value_name = "IP:PORT", default_value = "127.0.0.1:49152")]
    pub listen: SocketAddr,
    /// Port 2 (R messages). Prints `events on tcp://IP:PORT` second. Default: the
    /// --listen address with the next port number (a free port when --listen has port 0).
    #[arg(long, value_name = "IP:PORT")]
    pub events_listen: Option<SocketAddr>,
    /// Start in Remote mode, so the host may start and reset the machine (C5).
    #[arg(long)]
    pub remote: bool,
    /// The operator starts production at once (continuous mode): boards finish every
    /// 22 s and R0CT messages flow without a host command.
    #[arg(long)]
    pub run: bool,
    /// Seed for everything random in the twin (pick-up misses, recoveries, reel fill).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// `cellbus decode panasonic` takes the common input.
pub type DecodeInput = crate::decode::Input;

pub async fn run(args: PanasonicArgs) -> anyhow::Result<ExitCode> {
    // Everything is checked before the machine is touched: bad arguments exit 2.
    let Some(host) = &args.host else {
        return Err(usage(
            "--host HOST[:PORT] is needed: the machine's address, e.g. 192.168.0.20",
        ));
    };
    let (host, command_port) = split_host(host)?;
    let action = Action::from_args(args.action)?;
    let events_port = match args.events_port {
        Some(port) => port,
        None => command_port.checked_add(1).ok_or_else(|| {
            usage(format!(
                "Port 1 is {command_port}: give Port 2 with --events-port"
            ))
        })?,
    };
    let mut config = ClientConfig::commands_only(host, command_port);
    config.timeout = args.timeout;
    config.retries = args.retries;
    let json = args.output.json;
    if let Action::Events(stop) = action {
        config.event_port = Some(events_port);
        return events(config, json, stop).await;
    }
    let (client, _events) = Client::connect(config).await.map_err(output::failure)?;
    // What a command that only acts prints: words, or with --json the JSON object.
    let done =
        |words: String, object: Value| output::line(if json { object.to_string() } else { words });
    match action {
        Action::Status => {
            let status = client.status().await.map_err(output::failure)?;
            if json {
                output::line(serde_json::to_string(&status)?)?;
            } else {
                output::line(format!("state: {}", status.state.describe()))?;
                output::line(format!("mode:  {}", status.mode.describe()))?;
            }
        }
        Action::Program => {
            let name = client.current_program().await.map_err(output::failure)?;
            if json {
                output::line(json!({ "program": name }))?;
            } else {
                output::line(name)?;
            }
        }
        Action::Programs => {
            let list = client.program_list().await.map_err(output::failure)?;
            if json {
                output::line(serde_json::to_string(&list)?)?;
            } else {
                for entry in &list.0 {
                    output::line(format!("{}  {}", entry.date, entry.name))?;
                }
            }
        }
        Action::Production { clear } => {
            let request = ProductionRequest {
                scope: ProductionScope::GrandTotal,
                clear,
            };
            let data = client.production(request).await.map_err(output::failure)?;
            if json {
                output::line(serde_json::to_string(&data)?)?;
            } else {
                print_production(&data)?;
                if clear {
                    output::line("(counters cleared after reading)")?;
                }
            }
        }
        Action::Upload { name, out } => {
            let data = client
                .upload(Target::Product(name.clone()))
                .await
                .map_err(output::failure)?;
            match out {
                Some(path) => {
                    std::fs::write(&path, &data)
                        .with_context(|| format!("cannot write {}", path.display()))?;
                    done(
                        format!(
                            "{} written to {}",
                            wire::words::Bytes(data.len()),
                            path.display()
                        ),
                        json!({ "program": name, "bytes": data.len(), "file": path }),
                    )?;
                }
                None if json => output::line(json!({
                    "program": name,
                    "text": String::from_utf8_lossy(&data),
                }))?,
                None => {
                    use std::io::Write;
                    let mut stdout = std::io::stdout().lock();
                    stdout.write_all(&data)?;
                    stdout.flush()?;
                }
            }
        }
        Action::Download { name, data } => {
            let len = data.len();
            client
                .download(Target::Product(name.clone()), data)
                .await
                .map_err(output::failure)?;
            done(
                format!("program {name} stored on the machine ({len} bytes)"),
                json!({ "program": name, "bytes": len, "stored": true }),
            )?;
        }
        Action::Delete { name } => {
            client
                .delete(Target::Product(name.clone()))
                .await
                .map_err(output::failure)?;
            done(
                format!("program {name} deleted"),
                json!({ "program": name, "deleted": true }),
            )?;
        }
        Action::Start { mode } => {
            client.start(mode).await.map_err(output::failure)?;
            let how = mode.map_or_else(
                || "in the previous stop mode".to_owned(),
                |m| format!("in {} mode", m.describe()),
            );
            done(
                format!("machine started {how} (A2); R1ST follows on Port 2"),
                json!({ "started": true, "mode": mode.map(|m| m.describe()) }),
            )?;
        }
        Action::Reset => {
            client.reset().await.map_err(output::failure)?;
            done(
                "reset accepted (A2); R1RE follows on Port 2 when done".to_owned(),
                json!({ "reset": true }),
            )?;
        }
        Action::Events(_) => unreachable!("handled above"),
    }
    Ok(ExitCode::SUCCESS)
}

/// A subcommand with its arguments checked.
enum Action {
    Status,
    Program,
    Programs,
    Production {
        clear: bool,
    },
    Upload {
        name: ProgramName,
        out: Option<PathBuf>,
    },
    Download {
        name: ProgramName,
        data: Vec<u8>,
    },
    Delete {
        name: ProgramName,
    },
    Start {
        mode: Option<StopMode>,
    },
    Reset,
    Events(StopArgs),
}

impl Action {
    fn from_args(action: PanasonicAction) -> anyhow::Result<Action> {
        let name = |text: &str| {
            text.parse::<ProgramName>()
                .map_err(|e| usage(format!("{text:?}: {e}")))
        };
        Ok(match action {
            PanasonicAction::Status => Action::Status,
            PanasonicAction::Program => Action::Program,
            PanasonicAction::Programs => Action::Programs,
            PanasonicAction::Production { clear } => Action::Production { clear },
            PanasonicAction::Upload { name: n, out } => Action::Upload {
                name: name(&n)?,
                out,
            },
            PanasonicAction::Download { name: n, file } => {
                let data = std::fs::read(&file)
                    .map_err(|e| usage(format!("cannot read {}: {e}", file.display())))?;
                Action::Download {
                    name: name(&n)?,
                    data,
                }
            }
            PanasonicAction::Delete { name: n } => Action::Delete { name: name(&n)? },
            PanasonicAction::Start { mode } => Action::Start { mode },
            PanasonicAction::Reset => Action::Reset,
            PanasonicAction::Events { stop } => Action::Events(stop),
        })
    }
}

/// `HOST`, `HOST:PORT`, `[IPv6]` or `[IPv6]:PORT`.
fn split_host(text: &str) -> anyhow::Result<(String, u16)> {
    let port = |p: &str| {
        p.parse::<u16>().map_err(|_| {
            usage(format!(
                "--host {text:?}: {p:?} is not a TCP port (0-65535)"
            ))
        })
    };
    if let Some((scheme, _)) = text.split_once("://") {
        return Err(usage(format!(
            "--host {text:?}: give the machine's host or HOST:PORT, without {scheme}:// \
             (e.g. 192.168.0.20 or 192.168.0.20:49152)"
        )));
    }
    let (host, port) = if let Some(rest) = text.strip_prefix('[') {
        let (host, after) = rest
            .split_once(']')
            .ok_or_else(|| usage(format!("--host {text:?}: missing ']'")))?;
        match after.strip_prefix(':') {
            Some(p) => (host, port(p)?),
            None if after.is_empty() => (host, DEFAULT_COMMAND_PORT),
            None => return Err(usage(format!("--host {text:?}: junk after ']'"))),
        }
    } else {
        match text.split_once(':') {
            Some((host, p)) if !p.contains(':') => (host, port(p)?),
            Some(_) => {
                return Err(usage(format!(
                    "--host {text:?}: write an IPv6 address in brackets, e.g. [::1]:49152"
                )));
            }
            None => (text, DEFAULT_COMMAND_PORT),
        }
    };
    if host.is_empty() {
        return Err(usage(format!("--host {text:?} names no host")));
    }
    Ok((host.to_owned(), port))
}

/// Production data as sections of `KEY  value` lines.
fn print_production(data: &panasonic::ProductionData) -> anyhow::Result<()> {
    let header = &data.header;
    if let Some(name) = &header.name {
        output::line(format!("data:  {name}"))?;
    }
    if let (Some(start), Some(end)) = (&header.start, &header.end) {
        output::line(format!("since: {start}\nuntil: {end}"))?;
    }
    for section in &data.sections {
        output::line(&section.name)?;
        for field in &section.fields {
            output::line(format!("  {:<16} {}", field.key, field.value))?;
        }
    }
    Ok(())
}

/// Prints R messages from Port 2 until `stop` says (`--count` counts R messages).
async fn events(config: ClientConfig, json: bool, stop: StopArgs) -> anyhow::Result<ExitCode> {
    let (client, mut stream) = Client::connect(config).await.map_err(output::failure)?;
    let count = stop.count;
    let mut stop = Stop::new(stop.duration);
    let printed = async {
        let mut seen = 0;
        while count.is_none_or(|n| seen < n) {
            let Some(notice) = stream.next().await else {
                break;
            };
            if show(&notice, json)? {
                seen += 1;
            }
        }
        anyhow::Ok(())
    };
    tokio::select! {
        printed = printed => printed?,
        () = stop.wait() => {}
    }
    drop(client);
    Ok(ExitCode::SUCCESS)
}

/// Prints one notice: R messages on stdout, connection news on stderr. True for an R
/// message.
fn show(notice: &Notice, json: bool) -> anyhow::Result<bool> {
    let Notice::Event(event) = notice else {
        eprintln!("cellbus: {notice}");
        return Ok(false);
    };
    if json {
        output::line(event_json(event))?;
    } else {
        output::line(event)?;
    }
    Ok(true)
}

/// `{"event":"started","wire":"R1ST","text":"machine started"}`.
fn event_json(event: &Event) -> Value {
    let mut value = serde_json::to_value(event).unwrap_or_else(|_| json!({}));
    if let Value::Object(map) = &mut value {
        map.insert("wire".to_owned(), json!(event.wire()));
        map.insert("text".to_owned(), json!(event.describe()));
    }
    value
}

/// `cellbus sim panasonic`: the twin on its two ports until interrupted.
pub async fn sim(args: SimPanasonicArgs) -> anyhow::Result<ExitCode> {
    let events_listen = args.events_listen.unwrap_or_else(|| {
        let port = match args.listen.port() {
            0 => 0,
            port => port.saturating_add(1),
        };
        SocketAddr::new(args.listen.ip(), port)
    });
    let machine = Machine::new(MachineConfig {
        seed: args.seed,
        remote: args.remote,
        ..MachineConfig::default()
    })
    .map_err(usage)?;
    let server = TwinServer::bind(args.listen, events_listen, machine)
        .await
        .map_err(|e| {
            let hint = if e.kind() == std::io::ErrorKind::AddrInUse {
                "; the port is taken, try --listen 127.0.0.1:0"
            } else {
                ""
            };
            anyhow::anyhow!("{e}{hint}")
        })?;
    output::line(format!("listening on tcp://{}", server.command_addr()?))?;
    output::line(format!("events on tcp://{}", server.event_addr()?))?;
    let control = server.control();
    if args.run {
        control
            .operator_start(Some(StopMode::Continuous))
            .context("the twin cannot start")?;
    }
    let mode = match control.status().mode {
        ControlMode::Remote => "remote (C5 start/reset accepted)",
        ControlMode::Online => "online (C5 refused; --remote to allow)",
    };
    eprintln!(
        "cellbus: Panasonic BM twin, {}, mode {mode}; program {} selected",
        control.status().state.describe(),
        panasonic::twin::DEMO_PROGRAM
    );
    crate::sim_control::panasonic(control);
    tokio::select! {
        () = server.run() => {}
        _ = tokio::signal::ctrl_c() => {}
    }
    Ok(ExitCode::SUCCESS)
}

/// `cellbus decode panasonic`: each message with its meaning and layout; exits 1 when
/// anything in the capture is not a message we understand.
pub fn decode(input: DecodeInput) -> anyhow::Result<ExitCode> {
    let bytes = input.bytes()?;
    let mut bad = 0;
    for annotation in annotate(&bytes) {
        output::line(&annotation)?;
        let raw = bytes
            .get(annotation.offset..annotation.offset + annotation.len)
            .unwrap_or_default();
        match &annotation.item {
            Annotated::Message(packet) => {
                if matches!(packet, Packet::Unknown { .. }) {
                    bad += 1;
                }
                output::line(format!("       {}", layout(raw)))?;
            }
            Annotated::Skipped(_) | Annotated::Incomplete => {
                bad += 1;
                let shown = raw.get(..DATA_SHOWN).unwrap_or(raw);
                output::line(format!("       {}", output::hex(shown)))?;
            }
        }
    }
    Ok(if bad == 0 {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}

/// `command "C2ST" + 252 blanks | size 0 | terminator 00 00 00`.
fn layout(raw: &[u8]) -> String {
    let field = raw.get(..COMMAND_LEN).unwrap_or(raw);
    let text_len = field
        .iter()
        .rposition(|&b| b != b' ')
        .map_or(0, |last| last + 1);
    let (text, blanks) = field.split_at(text_len);
    let size = raw
        .get(COMMAND_LEN..HEADER_LEN)
        .map(output::hex)
        .unwrap_or_default();
    let end = raw.len().saturating_sub(TERMINATOR_LEN).max(HEADER_LEN);
    let data = raw.get(HEADER_LEN..end).unwrap_or_default();
    let terminator = raw.get(end..).map(output::hex).unwrap_or_default();
    let mut out = format!(
        "command \"{}\" + {} blanks | size {size} ({} bytes)",
        printable(text),
        blanks.len(),
        data.len()
    );
    if !data.is_empty() {
        let shown = data.get(..DATA_SHOWN).unwrap_or(data);
        out.push_str(&format!(" | data \"{}\"", printable(shown)));
        if data.len() > shown.len() {
            out.push_str(&format!(" … ({} more bytes)", data.len() - shown.len()));
        }
    }
    out.push_str(&format!(" | terminator {terminator}"));
    out
}
