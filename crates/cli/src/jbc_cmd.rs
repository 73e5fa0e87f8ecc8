//! `cellbus jbc …`: read, write, status and watch a JBC station.

use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use clap::{Args, Subcommand};
use jbc::client::{Client, ClientConfig, DEFAULT_RETRIES};
use jbc::code::{Code, Reading, Value};
use jbc::frame::{Address, Route};
use link::{Line, SerialSettings, SharedLine};
use serde_json::{Map, json};

use crate::output::{self, usage};
use crate::rounds::{Rounds, StopArgs};

/// The station's line defaults: 19200 baud, 8 data bits, even parity, 1 stop bit.
pub const JBC_LINE: SerialSettings = SerialSettings::new_8e1(19200);

#[derive(Debug, Args)]
#[command(
    after_help = "The codes: `cellbus jbc read --help` lists those to read, \
    `cellbus jbc write --help` those to write. Options go before or after the subcommand."
)]
pub struct JbcArgs {
    /// Where the station is (needed): serial:///dev/ttyUSB0?baud=19200&framing=8E1, a
    /// device path (/dev/ttyUSB0, or pty/jbc1 relative to the working directory), or
    /// tcp://host:port (a serial server or `cellbus sim jbc`). Serial defaults: 19200 baud,
    /// 8E1.
    #[arg(long, value_name = "URL", global = true)]
    pub endpoint: Option<String>,
    #[command(flatten)]
    pub output: output::JsonArg,
    /// The station's address (00–99).
    #[arg(long, default_value = "01", global = true)]
    pub address: Address,
    /// Our own (the robot's) address (00–99).
    #[arg(long, default_value = "00", global = true)]
    pub robot_address: Address,
    /// Send frames without address fields (the station's "address off" setting).
    #[arg(long, global = true, conflicts_with_all = ["address", "robot_address"])]
    pub no_address: bool,
    /// Time to wait for each reply.
    #[arg(long, default_value = "500ms", value_parser = crate::output::parse_timeout, global = true)]
    pub timeout: Duration,
    /// Retries after a timeout or a damaged frame (never after a refusal).
    #[arg(long, default_value_t = DEFAULT_RETRIES, global = true)]
    pub retries: u8,
    #[command(subcommand)]
    pub action: JbcAction,
}

#[derive(Debug, Subcommand)]
pub enum JbcAction {
    /// Read one value: CODE as in the manual without the R, e.g. ST1, AT1, A11, SMN, MAT.
    #[command(after_help = codes_help("Codes to read", Code::readable))]
    Read {
        /// The code to read, without the R (listed below).
        code: String,
    },
    /// Write one value: CODE without the W (ST1, SF1, PS1, MAT, …) and the value in the
    /// code's unit (°C, %, ‰); RSP resets to factory values and takes 0.
    #[command(after_help = codes_help("Codes to write", Code::writable))]
    Write {
        /// The code to write, without the W (listed below).
        code: String,
        /// The value, in the code's unit: 380 for 380 °C; PS1 takes 1 (tool on) or 0.
        #[arg(allow_negative_numbers = true)]
        value: i32,
    },
    /// Read every readable value of the station.
    Status,
    /// Show air temperature, external temperature, power and port status every
    /// --interval, until --count rounds, --for a while, or Ctrl-C.
    Watch {
        /// Time between readings.
        #[arg(long, default_value = "500ms", value_parser = crate::rounds::parse_period)]
        interval: Duration,
        #[command(flatten)]
        stop: StopArgs,
    },
}

/// The codes `keep` picks, one per line with their words and unit, for `--help`.
fn codes_help(title: &str, keep: fn(Code) -> bool) -> String {
    let mut help = format!("{title} (port 1; any case):");
    for code in Code::all().into_iter().filter(|&code| keep(code)) {
        let unit = code.unit().map(|u| format!(", {u}")).unwrap_or_default();
        help.push_str(&format!("\n  {code}  {}{unit}", code.describe()));
    }
    help
}

pub async fn run(args: JbcArgs) -> anyhow::Result<ExitCode> {
    let endpoint = output::serial_endpoint(args.endpoint.as_deref(), JBC_LINE, "a JBC station")?;
    let route = (!args.no_address).then_some(Route {
        source: args.robot_address,
        target: args.address,
    });
    let config = ClientConfig {
        route,
        timeout: args.timeout,
        retries: args.retries,
    };
    // Parse codes before opening the line: a bad argument never touches the device.
    let action = Action::from_args(args.action)?;
    let line = Line::open(&endpoint).await?;
    let mut client = Client::new(SharedLine::new(line), config);
    let json = args.output.json;
    match action {
        Action::Read(code) => read(&mut client, code, json).await,
        Action::Write(code, value) => write(&mut client, code, value, json).await,
        Action::Status => status(&mut client, json).await,
        Action::Watch(interval, stop) => watch(&mut client, interval, stop, json).await,
    }
}

enum Action {
    Read(Code),
    Write(Code, i32),
    Status,
    Watch(Duration, StopArgs),
}

impl Action {
    fn from_args(action: JbcAction) -> anyhow::Result<Self> {
        let code = |text: &str| text.parse::<Code>().map_err(usage);
        Ok(match action {
            JbcAction::Read { code: c } => Self::Read(code(&c)?),
            JbcAction::Write { code: c, value } => Self::Write(code(&c)?, value),
            JbcAction::Status => Self::Status,
            JbcAction::Watch { interval, stop } => Self::Watch(interval, stop),
        })
    }
}

async fn read(client: &mut Client, code: Code, json: bool) -> anyhow::Result<ExitCode> {
    let reading = client.read(code).await.map_err(output::failure)?;
    if json {
        output::line(reading_json(code, &reading))?;
    } else {
        output::line(format!("{} ({code}): {reading}", code.describe()))?;
    }
    Ok(ExitCode::SUCCESS)
}

async fn write(
    client: &mut Client,
    code: Code,
    value: i32,
    json: bool,
) -> anyhow::Result<ExitCode> {
    client.write(code, value).await.map_err(output::failure)?;
    if json {
        output::line(json!({ "code": code.to_string(), "value": value, "ok": true }))?;
    } else {
        // Say the value the way a read shows it: `380 °C`, `tool on, cooling off, …`.
        let shown = jbc::frame::Data::number(value)
            .ok()
            .and_then(|data| jbc::code::interpret(code, &data).ok())
            .map_or_else(|| value.to_string(), |reading| reading.to_string());
        output::line(format!(
            "A{code} acknowledged: {} set to {shown}",
            code.describe()
        ))?;
    }
    Ok(ExitCode::SUCCESS)
}

async fn status(client: &mut Client, json: bool) -> anyhow::Result<ExitCode> {
    let mut object = Map::new();
    let mut failures = 0;
    let codes: Vec<Code> = Code::all().into_iter().filter(|c| c.readable()).collect();
    let width = codes
        .iter()
        .map(|c| c.describe().chars().count())
        .max()
        .unwrap_or(0);
    for code in codes {
        let reading = client.read(code).await;
        match (&reading, json) {
            (Ok(reading), true) => {
                object.insert(code.to_string(), reading_json(code, reading));
            }
            (Err(e), true) => {
                object.insert(code.to_string(), json!({ "error": e.to_string() }));
            }
            (Ok(reading), false) => {
                output::line(format!("{code:<4} {:<width$}  {reading}", code.describe()))?
            }
            (Err(e), false) => {
                output::line(format!("{code:<4} {:<width$}  error: {e}", code.describe()))?
            }
        }
        if let Err(e) = reading {
            failures += 1;
            if matches!(
                e,
                jbc::client::ClientError::Exchange(
                    jbc::client::ExchangeError::NoAnswer { .. }
                        | jbc::client::ExchangeError::Line { .. }
                )
            ) {
                // A station that does not answer one read will not answer the others.
                return Err(e).context("reading the station's status");
            }
        }
    }
    if json {
        output::line(serde_json::Value::Object(object))?;
    }
    Ok(if failures == 0 {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}

async fn watch(
    client: &mut Client,
    interval: Duration,
    stop: StopArgs,
    json: bool,
) -> anyhow::Result<ExitCode> {
    const WATCHED: [&str; 4] = ["AT1", "ET1", "PP1", "PS1"];
    let codes: Vec<Code> = WATCHED
        .iter()
        .map(|c| c.parse().expect("the watched codes are valid"))
        .collect();
    if !json {
        output::line(format!(
            "{:<12} {:>14} {:>14} {:>8}  status",
            "time", "air", "external", "power"
        ))?;
    }
    let mut rounds = Rounds::new(interval, stop);
    while rounds.next().await {
        let mut readings = Vec::with_capacity(codes.len());
        for &code in &codes {
            readings.push(client.read(code).await.map_err(output::failure)?);
        }
        let elapsed = format!("{:.1} s", rounds.elapsed().as_secs_f64());
        if json {
            let mut object = Map::new();
            object.insert(
                "elapsed_ms".into(),
                json!(rounds.elapsed().as_millis() as u64),
            );
            for (code, reading) in codes.iter().zip(&readings) {
                object.insert(code.to_string(), reading_json(*code, reading));
            }
            output::line(serde_json::Value::Object(object))?;
        } else {
            output::line(format!(
                "{:<12} {:>14} {:>14} {:>8}  {}",
                elapsed.to_string(),
                readings[0].to_string(),
                readings[1].to_string(),
                readings[2].to_string(),
                readings[3]
            ))?;
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// `{"code":"ST1","value":350,"unit":"°C"}`; enumerations add `"text"` with their meaning.
fn reading_json(code: Code, reading: &Reading) -> serde_json::Value {
    let value = match reading.value() {
        Value::Number(n) => json!(n),
        Value::Text(text) => json!(text),
    };
    let mut object = json!({
        "code": code.to_string(),
        "value": value,
        "unit": reading.unit().map(|u| u.symbol()),
    });
    if reading.unit().is_none() && !matches!(reading.value(), Value::Text(_)) {
        object["text"] = json!(reading.to_string());
    }
    object
}
