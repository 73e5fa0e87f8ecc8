//! `cellbus thermosald …`, `cellbus sim thermosald` and `cellbus decode thermosald`:
//! Thermosald ISC impulse-sealer regulators on an RS-485 line.

use std::process::ExitCode;
use std::time::Duration;

use clap::{Args, Subcommand};
use link::{Line, SerialSettings, SharedLine};
use serde_json::{Map, json};
use thermosald::client::{self, Client, ClientConfig, ClientError, DEFAULT_RETRIES};
use thermosald::device::RegulatorBus;
use thermosald::exchange::{ANSWER_AFTER_RECEPTION, LineTiming};
use thermosald::frame::{Address, FrameCodec, Target};
use thermosald::tables::{Item, Reading, Table, Unit, runtime};
use thermosald::{Request, diagnostic};
use wire::device::SharedModel;

use crate::output::{self, usage};
use crate::rounds::{Rounds, StopArgs};
use crate::sim::ServeArgs;

/// The regulators' line: 9600 baud, 8 data bits, no parity, 1 stop bit (the spec's only
/// framing).
pub const THERMOSALD_LINE: SerialSettings = SerialSettings::new_8n1(9600);

#[derive(Debug, Args)]
#[command(
    after_help = "Tables and items: `cellbus thermosald read --help` lists them, \
    `cellbus thermosald write --help` the writable ones with their ranges. Options go before \
    or after the subcommand."
)]
pub struct ThermosaldArgs {
    /// Where the RS-485 line is (needed): serial:///dev/ttyUSB0, a device path (/dev/ttyUSB0,
    /// or pty/sealers relative to the working directory), or tcp://host:port (a serial server
    /// or `cellbus sim thermosald`). Serial default: 9600 baud, 8N1. RS-485 adapters:
    /// `?rs485=rts` (or `dtr`, `rts+dtr`) holds that line at 1 while sending, `&echo=discard`
    /// drops the adapter's local echo.
    #[arg(long, value_name = "URL", global = true)]
    pub endpoint: Option<String>,
    #[command(flatten)]
    pub output: output::JsonArg,
    /// The regulator's address, 0–7; `$` to assign an address (set-address only, with one
    /// regulator powered); several for watch: 0,1,2.
    #[arg(long, default_value = "0", value_name = "N", global = true)]
    pub address: String,
    /// Time to wait for each answer [default: 500ms at 9600 baud, longer on slower lines;
    /// scan: 422ms]. A regulator answers 200 ms after the question.
    #[arg(long, value_parser = crate::output::parse_timeout, global = true)]
    pub timeout: Option<Duration>,
    /// Retries after no answer, a damaged answer or one of the wrong shape. An echo that
    /// differs from what was sent is retried once, then reported.
    #[arg(long, default_value_t = DEFAULT_RETRIES, global = true)]
    pub retries: u8,
    #[command(subcommand)]
    pub action: ThermosaldAction,
}

#[derive(Debug, Subcommand)]
pub enum ThermosaldAction {
    /// Read a data table (machine, settings, runtime, service), or one item of it.
    #[command(after_help = items_help())]
    Read {
        /// The table: machine, settings, runtime or service.
        table: String,
        /// One item, by index (15) or name ("sealing temperature"), listed below.
        #[arg(long, value_name = "I")]
        item: Option<String>,
    },
    /// Write one item in its unit (°C, A, 12.5 for a ×10 gain); checked against the item's
    /// range before anything is sent. The regulator's echo must match.
    #[command(after_help = writable_help())]
    Write {
        /// The table: machine, settings or service.
        table: String,
        /// The item, by index (15) or name ("sealing temperature"), listed below.
        item: String,
        /// The value in the item's unit.
        #[arg(allow_negative_numbers = true)]
        value: f64,
    },
    /// Clear latched faults whose cause is gone (message 14).
    ClearFaults,
    /// Start automatic balancing (message 15); diagnostic 36 shows while it runs.
    Balance,
    /// Save the working data to EEPROM (message 16); writes are volatile until then.
    EepromSave,
    /// Load the working data from EEPROM (message 17).
    EepromLoad,
    /// Give the regulator a new address (message 10); with --address '$' every powered
    /// regulator takes it, so power one at a time.
    SetAddress {
        /// The new address, 0–7.
        new: Address,
    },
    /// Master reset (message 99): factory data, no address until one is set, diagnostic 35
    /// until balancing.
    MasterReset {
        /// Confirm: the regulator's data and address are lost.
        #[arg(long)]
        yes: bool,
    },
    /// Find which of addresses 0–7 answer, one question each, as fast as the line allows.
    Scan,
    /// Show temperature, fault and power of one or several addresses (--address 0,1,2)
    /// every --interval, until --count rounds, --for a while, or Ctrl-C.
    Watch {
        /// Time between rounds.
        #[arg(long, default_value = "1s", value_parser = crate::rounds::parse_period)]
        interval: Duration,
        #[command(flatten)]
        stop: StopArgs,
    },
}

/// `read --help`'s list: each table's items by index and name.
fn items_help() -> String {
    const WIDTH: usize = 96;
    let mut help = String::from("Items, by index or name:");
    for table in Table::ALL {
        let mut line = format!("  {table}:");
        for item in table.items() {
            let entry = format!(" {} {},", item.index(), item.name());
            if line.chars().count() + entry.chars().count() > WIDTH {
                help.push('\n');
                help.push_str(line.trim_end());
                line = String::from("   ");
            }
            line.push_str(&entry);
        }
        help.push('\n');
        help.push_str(line.trim_end_matches(','));
    }
    help
}

/// `write --help`'s list: the writable items of each table with their ranges.
fn writable_help() -> String {
    let mut help = String::from("Writable items, by index or name:");
    for table in Table::ALL {
        for item in table.items().iter().filter(|item| item.writable()) {
            let unit = match item.unit() {
                Unit::None => String::new(),
                unit => format!(" {}", unit.symbol()),
            };
            let decimals = item.scale().decimals();
            help.push_str(&format!(
                "\n  {table} {:>2}  {}: {:.decimals$} to {:.decimals$}{unit}",
                item.index(),
                item.name(),
                item.min(),
                item.max(),
            ));
        }
    }
    help
}

#[derive(Debug, Args)]
#[command(after_help = crate::sim_control::long_help::<thermosald::device::operator::Command>())]
pub struct SimThermosaldArgs {
    #[command(flatten)]
    pub serve: ServeArgs,
    /// The regulators on the simulated line, each with its own band and memory: 0,1,2.
    #[arg(long, value_delimiter = ',', default_value = "0", value_name = "N,…")]
    pub addresses: Vec<Address>,
}

pub async fn run(args: ThermosaldArgs) -> anyhow::Result<ExitCode> {
    // Everything is checked before the line is opened: a bad argument never reaches it.
    let endpoint = output::serial_endpoint(
        args.endpoint.as_deref(),
        THERMOSALD_LINE,
        "a Thermosald regulator",
    )?;
    if let Some(timeout) = args.timeout.filter(|t| *t <= ANSWER_AFTER_RECEPTION) {
        return Err(usage(format!(
            "--timeout {} can never see an answer: a regulator answers {} ms after the question",
            humantime::format_duration(timeout),
            ANSWER_AFTER_RECEPTION.as_millis()
        )));
    }
    let targets = parse_targets(&args.address)?;
    let action = Action::from_args(args.action, &targets)?;
    let mut line = Line::open(&endpoint).await?;
    // Another master (an earlier run) may have had an answer moments ago.
    client::quiet_after_open(&mut line);
    let line = SharedLine::new(line);
    let config = |target: Target| ClientConfig {
        timeout: args.timeout,
        retries: args.retries,
        ..ClientConfig::new(target)
    };
    let json = args.output.json;
    match action {
        Action::Scan => scan(&line, args.timeout, json).await,
        Action::Watch {
            addresses,
            interval,
            stop,
        } => {
            let clients = addresses
                .into_iter()
                .map(|a| Client::new(line.clone(), config(a.into())))
                .collect();
            watch(clients, Rounds::new(interval, stop), json).await
        }
        Action::One(target, one) => {
            let mut client = Client::new(line, config(target));
            match one {
                One::Read(read) => read_cmd(&mut client, read, json).await,
                One::Write(item, value) => write_cmd(&mut client, item, value, json).await,
                One::Request(request) => request_cmd(&mut client, request, json).await,
            }
        }
    }
}

enum Action {
    One(Target, One),
    Scan,
    Watch {
        addresses: Vec<Address>,
        interval: Duration,
        stop: StopArgs,
    },
}

enum One {
    Read(thermosald::Read),
    Write(&'static Item, f64),
    Request(Request),
}

impl Action {
    fn from_args(action: ThermosaldAction, targets: &[Target]) -> anyhow::Result<Self> {
        let addresses = || -> anyhow::Result<Vec<Address>> {
            targets
                .iter()
                .map(|t| match t {
                    Target::Address(a) => Ok(*a),
                    Target::Assign => Err(usage("--address '$' is only for set-address")),
                })
                .collect()
        };
        let one = |one: One| -> anyhow::Result<Action> {
            match (targets, &one) {
                ([Target::Assign], One::Request(Request::SetAddress(_))) => {
                    Ok(Action::One(Target::Assign, one))
                }
                ([target @ Target::Address(_)], _) => Ok(Action::One(*target, one)),
                ([Target::Assign], _) => Err(usage("--address '$' is only for set-address")),
                _ => Err(usage(
                    "this command talks to one regulator: give one --address (several are for watch)",
                )),
            }
        };
        let table = |name: &str| name.parse::<Table>().map_err(usage);
        Ok(match action {
            ThermosaldAction::Read { table: t, item } => {
                let table = table(&t)?;
                let read = match item {
                    Some(key) => thermosald::Read::item(table.lookup(&key).map_err(usage)?),
                    None => thermosald::Read::all(table),
                };
                one(One::Read(read))?
            }
            ThermosaldAction::Write {
                table: t,
                item,
                value,
            } => {
                let item = table(&t)?.lookup(&item).map_err(usage)?;
                // Refused here, before the line is opened: range, step, read-only.
                thermosald::Write::value(item, value)
                    .map_err(|e| usage(format!("{e}; nothing was sent")))?;
                one(One::Write(item, value))?
            }
            ThermosaldAction::ClearFaults => {
                one(One::Request(thermosald::Command::ClearFaults.into()))?
            }
            ThermosaldAction::Balance => one(One::Request(thermosald::Command::Balance.into()))?,
            ThermosaldAction::EepromSave => {
                one(One::Request(thermosald::Command::SaveEeprom.into()))?
            }
            ThermosaldAction::EepromLoad => {
                one(One::Request(thermosald::Command::LoadEeprom.into()))?
            }
            ThermosaldAction::SetAddress { new } => one(One::Request(Request::SetAddress(new)))?,
            ThermosaldAction::MasterReset { yes: false } => {
                return Err(usage(
                    "master reset erases the regulator's data and address; add --yes to do it",
                ));
            }
            ThermosaldAction::MasterReset { yes: true } => {
                one(One::Request(thermosald::Command::MasterReset.into()))?
            }
            ThermosaldAction::Scan => Action::Scan,
            ThermosaldAction::Watch { interval, stop } => Action::Watch {
                addresses: addresses()?,
                interval,
                stop,
            },
        })
    }
}

/// `0`, `0,1,2` or `$`.
fn parse_targets(text: &str) -> anyhow::Result<Vec<Target>> {
    let mut targets = Vec::new();
    for part in text.split(',').map(str::trim) {
        let target = if part == "$" {
            Target::Assign
        } else {
            Target::Address(part.parse::<Address>().map_err(usage)?)
        };
        if targets.contains(&target) {
            return Err(usage(format!("--address {part} is given twice")));
        }
        targets.push(target);
    }
    Ok(targets)
}

/// `regulator 3`, or `every regulator listening to '$'`.
fn who(target: Target) -> String {
    match target {
        Target::Address(a) => format!("regulator {a}"),
        Target::Assign => "every regulator listening to '$'".to_owned(),
    }
}

async fn read_cmd(
    client: &mut Client,
    read: thermosald::Read,
    json: bool,
) -> anyhow::Result<ExitCode> {
    let values = client.read(read).await.map_err(output::failure)?;
    let readings: Vec<Reading> = values.readings().collect();
    if json {
        let mut object = Map::new();
        for reading in &readings {
            object.insert(reading.item().index().to_string(), reading_json(reading));
        }
        output::line(serde_json::Value::Object(object))?;
        return Ok(ExitCode::SUCCESS);
    }
    let table = read.table();
    if let [reading] = readings.as_slice() {
        let item = reading.item();
        output::line(format!(
            "{}, {table} item {}, {}: {}",
            who(client.target()),
            item.index(),
            item.name(),
            shown(reading)
        ))?;
        return Ok(ExitCode::SUCCESS);
    }
    output::line(format!("{}, {table} data:", who(client.target())))?;
    let width = readings
        .iter()
        .map(|r| r.item().name().chars().count())
        .max()
        .unwrap_or(0);
    for reading in &readings {
        let item = reading.item();
        output::line(format!(
            "{:>3}  {:<width$}  {}",
            item.index(),
            item.name(),
            shown(reading)
        ))?;
    }
    Ok(ExitCode::SUCCESS)
}

async fn write_cmd(
    client: &mut Client,
    item: &'static Item,
    value: f64,
    json: bool,
) -> anyhow::Result<ExitCode> {
    let echoed = client.write(item, value).await.map_err(output::failure)?;
    if json {
        let mut object = json!({
            "table": item.table().name(),
            "item": item.index(),
        });
        if let (serde_json::Value::Object(object), serde_json::Value::Object(reading)) =
            (&mut object, reading_json(&echoed))
        {
            object.extend(reading);
            object.insert("ok".into(), json!(true));
        }
        output::line(object)?;
    } else {
        output::line(format!(
            "{} echoed {} item {}, {} = {}",
            who(client.target()),
            item.table(),
            item.index(),
            item.name(),
            shown(&echoed)
        ))?;
    }
    Ok(ExitCode::SUCCESS)
}

async fn request_cmd(
    client: &mut Client,
    request: Request,
    json: bool,
) -> anyhow::Result<ExitCode> {
    let asked = who(client.target());
    let message = request.message();
    let new_address = match &request {
        Request::SetAddress(new) => Some(*new),
        _ => None,
    };
    match new_address {
        Some(new) => client.set_address(new).await,
        None => client.request(request.clone()).await.map(drop),
    }
    .map_err(output::failure)?;
    if json {
        let mut object = json!({
            "message": message.number().get(),
            "command": message.description(),
            "ok": true,
        });
        if let Some(new) = new_address {
            object["address"] = json!(new.get());
        }
        output::line(object)?;
        return Ok(ExitCode::SUCCESS);
    }
    let what = match request {
        Request::SetAddress(new) => {
            format!("now answers at address {new} (eeprom-save keeps it after a power cycle)")
        }
        Request::Command(thermosald::Command::ClearFaults) => {
            "cleared its faults whose cause is gone; run-time item 2 shows what remains".into()
        }
        Request::Command(thermosald::Command::Balance) => {
            "started automatic balancing: diagnostic 36 shows until it is done".into()
        }
        Request::Command(thermosald::Command::SaveEeprom) => {
            "saved its working data to EEPROM".into()
        }
        Request::Command(thermosald::Command::LoadEeprom) => {
            "loaded its working data from EEPROM".into()
        }
        Request::Command(thermosald::Command::MasterReset) => {
            "is back to factory data: it has no address now (assign one with --address '$' \
             set-address N) and shows diagnostic 35 until balanced"
                .into()
        }
        other => format!("echoed {}", other.message()),
    };
    output::line(format!(
        "{asked} {what} (message {}: {})",
        message.number(),
        message.description()
    ))?;
    Ok(ExitCode::SUCCESS)
}

async fn scan(
    line: &SharedLine,
    timeout: Option<Duration>,
    json: bool,
) -> anyhow::Result<ExitCode> {
    let started = tokio::time::Instant::now();
    let probes = client::scan(line, timeout).await?;
    let took = started.elapsed();
    let (endpoint, timing) = {
        let line = line.lock().await;
        let timing = line
            .settings()
            .and_then(|s| LineTiming::new(s.baud, s.bits_per_char()).ok())
            .unwrap_or_default();
        (line.name().to_owned(), timing)
    };
    let waited = timeout.unwrap_or_else(|| client::probe_timeout(&timing));
    let found: Vec<u8> = probes
        .iter()
        .filter(|p| p.answered())
        .map(|p| p.address.get())
        .collect();
    if json {
        let mut addresses = Map::new();
        for probe in &probes {
            let entry = match &probe.outcome {
                Ok(reading) => json!({
                    "answers": true,
                    "fault": reading.raw().get(),
                    "text": diagnostic::describe(reading.raw().get()),
                }),
                Err(e) => json!({ "answers": probe.answered(), "error": e.to_string() }),
            };
            addresses.insert(probe.address.get().to_string(), entry);
        }
        output::line(json!({
            "answering": found,
            "elapsed_ms": took.as_millis() as u64,
            "addresses": addresses,
        }))?;
    } else {
        for probe in &probes {
            let text = match &probe.outcome {
                Ok(reading) => format!(
                    "answers, fault/warning {} ({})",
                    reading.raw().get(),
                    diagnostic::describe(reading.raw().get())
                ),
                Err(ClientError::NoAnswer { last, .. }) if probe.answered() => {
                    format!("something answers, but {last}")
                }
                Err(ClientError::NoAnswer { .. }) => "no answer".to_owned(),
                Err(e) => format!("answers wrongly: {e}"),
            };
            output::line(format!("address {}: {text}", probe.address))?;
        }
        let list = found
            .iter()
            .map(u8::to_string)
            .collect::<Vec<_>>()
            .join(", ");
        output::line(format!(
            "{} of 8 addresses answer{} on {endpoint}; the scan took {:.2} s ({} baud: one \
             question per address, {:.0} ms for one that answers, {:.0} ms for a silent one)",
            found.len(),
            if found.is_empty() {
                String::new()
            } else {
                format!(" ({list})")
            },
            took.as_secs_f64(),
            timing.baud(),
            timing.poll_cycle(9, 12).as_secs_f64() * 1000.0,
            waited.as_secs_f64() * 1000.0
        ))?;
    }
    Ok(ExitCode::SUCCESS)
}

async fn watch(
    mut clients: Vec<Client>,
    mut rounds: Rounds,
    json: bool,
) -> anyhow::Result<ExitCode> {
    let item = |index| {
        Table::Runtime
            .item(index)
            .expect("the watched run-time items exist")
    };
    let (temperature, fault, power) = (
        item(runtime::TEMPERATURE),
        item(runtime::FAULT),
        item(runtime::POWER),
    );
    if !json {
        output::line(format!(
            "{:<9} {:>7} {:>12} {:>9}  fault/warning",
            "time", "address", "temperature", "power"
        ))?;
    }
    let mut failures = 0u64;
    while rounds.next().await {
        for client in &mut clients {
            let address = match client.target() {
                Target::Address(a) => a.get(),
                Target::Assign => continue,
            };
            let values = client.read_table(Table::Runtime).await;
            let elapsed = rounds.elapsed();
            let values = match values {
                Ok(values) => values,
                Err(e @ ClientError::Line { .. }) => return Err(e.into()),
                Err(e) => {
                    // A dead regulator must not stop the watch of the others.
                    failures += 1;
                    if json {
                        output::line(json!({
                            "elapsed_ms": elapsed.as_millis() as u64,
                            "address": address,
                            "error": e.to_string(),
                        }))?;
                    } else {
                        output::line(format!(
                            "{:<9} {address:>7}  error: {e}",
                            format!("{:.1} s", elapsed.as_secs_f64())
                        ))?;
                    }
                    continue;
                }
            };
            let get = |item| values.get(item).expect("the whole run-time table was read");
            let (t, f, p) = (get(temperature), get(fault), get(power));
            let code = f.raw().get();
            if json {
                output::line(json!({
                    "elapsed_ms": elapsed.as_millis() as u64,
                    "address": address,
                    "temperature": number(&t),
                    "fault": code,
                    "fault_text": diagnostic::describe(code),
                    "power": number(&p),
                }))?;
            } else {
                output::line(format!(
                    "{:<9} {address:>7} {:>12} {:>9}  {code} {}",
                    format!("{:.1} s", elapsed.as_secs_f64()),
                    t.to_string(),
                    p.to_string(),
                    diagnostic::describe(code)
                ))?;
            }
        }
    }
    Ok(if failures == 0 {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}

/// A reading as text, with the fault number in words and a note when out of range.
fn shown(reading: &Reading) -> String {
    let item = reading.item();
    let mut text = reading.to_string();
    if item.table() == Table::Runtime && item.index() == runtime::FAULT {
        text.push_str(&format!(" ({})", diagnostic::describe(reading.raw().get())));
    }
    if !reading.in_range() {
        text.push_str(" (outside the item's range)");
    }
    text
}

/// A reading's value as a JSON number: an integer for whole-unit items, else a decimal.
fn number(reading: &Reading) -> serde_json::Value {
    if reading.item().scale().decimals() == 0 {
        json!(reading.value().round() as i64)
    } else {
        json!(reading.value())
    }
}

/// `{"name":"Set sealing temperature","value":180,"unit":"°C","raw":"180"}`: the issue's
/// shape, nothing more (`watch --json` gives the fault number in words).
fn reading_json(reading: &Reading) -> serde_json::Value {
    let item = reading.item();
    let object = json!({
        "name": item.name(),
        "value": number(reading),
        "unit": match item.unit() {
            Unit::None => serde_json::Value::Null,
            unit => json!(unit.symbol()),
        },
        "raw": reading.raw().to_string(),
    });
    object
}

/// `cellbus sim thermosald`: regulators on one simulated line.
pub async fn sim(args: SimThermosaldArgs) -> anyhow::Result<ExitCode> {
    let mut twin = RegulatorBus::new(&args.addresses, std::time::Instant::now()).map_err(usage)?;
    if let Some(baud) = args.serve.baud {
        // The twin counts its answers' wire time exactly when the serve loop paces the line.
        let timing = LineTiming::new(baud, THERMOSALD_LINE.bits_per_char()).map_err(usage)?;
        twin = twin.paced(timing);
    }
    let model = SharedModel::new(twin);
    let control = model.clone();
    crate::sim::serve_with(
        &args.serve,
        THERMOSALD_LINE,
        "tcp",
        move || model.line(),
        || crate::sim_control::thermosald(control),
    )
    .await
}

/// `cellbus decode thermosald`: the common input, whose arguments may also be messages as
/// text (`%051Q990`).
pub fn decode(input: crate::decode::Input) -> anyhow::Result<ExitCode> {
    if input.file.is_none() && input.hex.is_empty() {
        return Err(usage(
            "give the messages as text (%051Q990), as hex bytes, or --file FILE",
        ));
    }
    let bytes = if input.file.is_none() && input.hex.iter().any(|arg| arg.contains('%')) {
        text_bytes(&input.hex)
    } else {
        input.bytes()?
    };
    crate::decode::dump(FrameCodec, &bytes, thermosald::request::describe)
}

/// Messages typed as text: `\n` (backslash, n) is the LF, and one is added to an argument
/// that does not end with it.
fn text_bytes(args: &[String]) -> Vec<u8> {
    let mut bytes = Vec::new();
    for arg in args {
        let text = arg.replace("\\n", "\n");
        bytes.extend_from_slice(text.as_bytes());
        if !text.ends_with('\n') {
            bytes.push(b'\n');
        }
    }
    bytes
}

#[cfg(test)]
mod tests;
