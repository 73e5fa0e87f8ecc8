//! `cellbus modbus …`, `cellbus cross …`, `cellbus sim cross|modbus` and `cellbus decode
//! modbus`: JBUS / Modbus RTU devices and the Chloride CROSS static transfer switch.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use clap::{Args, Subcommand};
use jbus::client::{
    Client, ClientConfig, ClientError, DEFAULT_RETRIES, DEFAULT_TIMEOUT, DEFAULT_TURNAROUND,
    Framing, UnitRefusal,
};
use jbus::cross::device::CrossTwin;
use jbus::cross::{Amount, CrossState, Discrete, MEASURES, NamedBit, Quantity, RATINGS, Source};
use jbus::data::{DataType, Format, Order, TypedValue};
use jbus::rtu::{Addressed, Answer, Broadcast, Request, UnitId, Write};
use jbus::slave::{Slave, SlaveMap};
use link::{Endpoint, Line, SerialSettings, SharedLine};
use serde_json::{Map, Value, json};
use wire::device::SharedModel;

use crate::output::{self, usage};
use crate::rounds::{Rounds, StopArgs};
use crate::sim::{ServeArgs, serve};

/// The CROSS's line defaults (also the defaults for any Modbus line): 9600 baud, 8 data
/// bits, no parity, 1 stop bit.
pub const JBUS_LINE: SerialSettings = SerialSettings::new_8n1(9600);

/// The CROSS's unit number unless told otherwise: the manual's own example reads "slave
/// n° 2". A real switch answers to the number set on it.
pub const DEFAULT_CROSS_UNIT: u8 = 2;

/// The generic simulator's unit number unless its map or `--unit` says otherwise.
pub const DEFAULT_SLAVE_UNIT: u8 = 1;

/// How the client reaches the line, shared by `modbus` and `cross`.
#[derive(Debug, Args)]
pub struct LineArgs {
    /// Where the line is (needed): serial:///dev/ttyUSB0?baud=9600&framing=8N1, a device path
    /// (/dev/ttyUSB0, or pty/cross relative to the working directory), tcp://host:port (a
    /// serial server or `cellbus sim`), optionally tcp://host:port?baud=9600 to keep the
    /// serial line's timing behind it, or modbus-tcp://host[:502] for Modbus TCP (a PLC, a
    /// Modbus gateway, `cellbus sim … --framing tcp`). Serial defaults: 9600 baud, 8N1.
    #[arg(long, value_name = "URL", global = true)]
    pub endpoint: Option<String>,
    #[command(flatten)]
    pub output: output::JsonArg,
    /// Time to wait for each answer, on top of the frames' time on the wire [default: 500ms;
    /// scan: 200ms].
    #[arg(long, value_parser = crate::output::parse_timeout, global = true)]
    pub timeout: Option<Duration>,
    /// Retries after no answer, a damaged answer or one that does not match (never after an
    /// exception: that is the device's answer).
    #[arg(long, default_value_t = DEFAULT_RETRIES, global = true)]
    pub retries: u8,
}

impl LineArgs {
    fn endpoint(&self) -> anyhow::Result<Endpoint> {
        output::endpoint(
            self.endpoint.as_deref(),
            JBUS_LINE,
            "serial:///dev/ttyUSB0, a device path, tcp://host:port or modbus-tcp://host:port",
        )
    }

    fn config(&self) -> ClientConfig {
        ClientConfig {
            timeout: self.timeout.unwrap_or(DEFAULT_TIMEOUT),
            retries: self.retries,
            turnaround: DEFAULT_TURNAROUND,
            framing: Framing::Rtu,
        }
    }
}

/// A client on `endpoint`, framing Modbus TCP when the endpoint is `modbus-tcp://`.
async fn open(endpoint: &Endpoint, config: ClientConfig) -> anyhow::Result<Client> {
    let line = Line::open(endpoint).await?;
    let config = ClientConfig {
        framing: Framing::of(endpoint),
        ..config
    };
    Ok(Client::new(SharedLine::new(line), config))
}

// --- cellbus modbus ---

#[derive(Debug, Args)]
#[command(
    after_help = "Addresses are 0-based protocol addresses, as on the wire: holding \
    register 40001 in Modicon numbering is address 0 of the holding registers, input register \
    30001 address 0 of the input registers. An address that looks like a Modicon number gets a \
    warning and is used as given. Options go before or after the subcommand."
)]
pub struct ModbusArgs {
    #[command(flatten)]
    pub line: LineArgs,
    /// The unit number: 1–247 (JBUS devices: up to 255); 0 sends a write to every unit of
    /// a serial line at once (broadcast: nobody answers; not over Modbus TCP). Needed by
    /// every action but `scan`.
    #[arg(long, value_name = "N", global = true)]
    pub unit: Option<u8>,
    #[command(subcommand)]
    pub action: ModbusAction,
}

/// What `cellbus modbus` does. Addresses are the 0-based protocol addresses of the wire,
/// decimal or 0x hex.
#[derive(Debug, Subcommand)]
pub enum ModbusAction {
    /// Function 3: read COUNT values (1–125 registers in all) of holding registers from
    /// ADDRESS: plain registers, or values of --type.
    ReadHolding(TypedRead),
    /// Function 4: read COUNT values (1–125 registers in all) of input registers from
    /// ADDRESS: plain registers, or values of --type.
    ReadInput(TypedRead),
    /// Function 1: read COUNT (1–2000) coils from ADDRESS.
    ReadCoils(Read),
    /// Function 2: read COUNT (1–2000) discrete inputs from ADDRESS.
    ReadDiscrete(Read),
    /// Function 6: write VALUE (0–65535, or -32768–-1 as two's complement) to the holding
    /// register at ADDRESS.
    WriteRegister {
        /// The register's protocol address, from 0 (register 40001 is 0), decimal or 0x hex.
        address: ProtocolAddress,
        /// The value: 0–65535, 0x hex, or -32768–-1 as two's complement.
        #[arg(value_parser = parse_word, allow_negative_numbers = true)]
        value: u16,
    },
    /// Function 16: write values to the holding registers from ADDRESS on (1–123
    /// registers in all): plain registers (0–65535, 0x hex, or -32768–-1), or values of
    /// --type, each encoded in its registers.
    WriteRegisters {
        /// The first register's protocol address, from 0 (register 40001 is 0), decimal or
        /// 0x hex.
        address: ProtocolAddress,
        #[command(flatten)]
        typed: TypeArgs,
        /// The values, one register each (0–65535, 0x hex, -32768–-1), or values of --type;
        /// after `--` when the first is negative.
        #[arg(value_name = "VALUE", allow_negative_numbers = true, required = true)]
        values: Vec<String>,
    },
    /// Function 5: switch the coil at ADDRESS on or off.
    WriteCoil {
        /// The coil's protocol address, from 0 (coil 00001 is 0), decimal or 0x hex.
        address: ProtocolAddress,
        /// on or off (1 or 0).
        #[arg(value_parser = parse_on_off, value_name = "on|off", action = clap::ArgAction::Set)]
        state: bool,
    },
    /// Function 15: write 1–1968 coils from ADDRESS on, each 1 or 0.
    WriteCoils {
        /// The first coil's protocol address, from 0 (coil 00001 is 0), decimal or 0x hex.
        address: ProtocolAddress,
        /// The coils' new states, 1 (on) or 0 (off), one per coil.
        #[arg(value_parser = parse_bit_value, value_name = "1|0", required = true)]
        values: Vec<bool>,
    },
    /// List the units that answer: one read of holding register 0 per unit, one attempt
    /// each (an exception is an answer too). `--json` gives {"units":[…]}.
    Scan {
        /// The units to try: FIRST-LAST or one number, within 1–255.
        #[arg(long, value_name = "FIRST-LAST", default_value = "1-247", value_parser = parse_units)]
        units: std::ops::RangeInclusive<u8>,
    },
}

/// ADDRESS and COUNT of a read.
#[derive(Debug, Clone, Copy, Args)]
pub struct Read {
    /// The first protocol address, from 0, decimal or 0x hex. Not the Modicon number:
    /// holding register 40001 and input register 30001 are address 0 of their tables.
    pub address: ProtocolAddress,
    /// How many: registers, or values of --type (1–125 registers in all); coils or
    /// discrete inputs (1–2000).
    #[arg(value_parser = parse_address)]
    pub count: u16,
}

/// A read of registers: ADDRESS, COUNT and the values' type.
#[derive(Debug, Clone, Copy, Args)]
pub struct TypedRead {
    #[command(flatten)]
    pub read: Read,
    #[command(flatten)]
    pub typed: TypeArgs,
}

/// A protocol address as typed: decimal or 0x hex, 0–65535. Modicon numbering (holding
/// register 40001, coil 00001) is not taken off it, only warned about
/// ([`modicon_warning`]), so it keeps how it was written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ProtocolAddress {
    pub value: u16,
    pub written: Written,
}

/// How an address was written: Modicon numbers are decimal, coils with five digits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Written {
    /// `0x9C41`: nobody writes Modicon numbers in hex.
    Hex,
    /// `40001`, `17`.
    Decimal,
    /// `00017`: five digits with leading zeros, the way Modicon numbers coils.
    FiveDigits,
}

impl std::str::FromStr for ProtocolAddress {
    type Err = String;
    fn from_str(text: &str) -> Result<Self, String> {
        let written = if text.starts_with("0x") || text.starts_with("0X") {
            Written::Hex
        } else if text.len() == 5 && text.starts_with('0') {
            Written::FiveDigits
        } else {
            Written::Decimal
        };
        Ok(Self {
            value: parse_address(text)?,
            written,
        })
    }
}

/// A warning for an address that looks like a Modicon register number (holding register
/// 40001, input register 30001, discrete input 10001, coil 00001) rather than the 0-based
/// protocol address the command takes; the command still uses the address as given. Coil
/// numbers are only recognised written with five digits (`00017`): 1–9999 are ordinary
/// coil addresses too.
pub fn modicon_warning(action: &ModbusAction) -> Option<String> {
    use ModbusAction::*;
    let (address, registers, verb) = match action {
        ReadHolding(TypedRead { read, .. }) | ReadInput(TypedRead { read, .. }) => {
            (read.address, true, "reads")
        }
        ReadCoils(read) | ReadDiscrete(read) => (read.address, false, "reads"),
        WriteRegister { address, .. } | WriteRegisters { address, .. } => {
            (*address, true, "writes")
        }
        WriteCoil { address, .. } | WriteCoils { address, .. } => (*address, false, "writes"),
        Scan { .. } => return None,
    };
    let value = address.value;
    let (table, first) = match (value, address.written) {
        (_, Written::Hex) => return None,
        (30001..=39999, _) if registers => ("input register", 30001),
        (40001..=49999, _) if registers => ("holding register", 40001),
        (1..=9999, Written::FiveDigits) if !registers => ("coil", 1),
        (10001..=19999, _) if !registers => ("discrete input", 10001),
        _ => return None,
    };
    let number = match address.written {
        Written::FiveDigits => format!("{value:05}"),
        _ => value.to_string(),
    };
    Some(format!(
        "{number} looks like Modicon {table} {number}, which is protocol address {} of the \
         {table}s; addresses here are 0-based protocol addresses, so this {verb} address \
         {value} as asked",
        value - first
    ))
}

/// The type of each value a read or write of registers carries.
#[derive(Debug, Clone, Copy, Args)]
pub struct TypeArgs {
    /// Each value's type: int16, uint16, int32, uint32, int64, uint64, float32, float64,
    /// string:N (N registers of ASCII), bit:N (bit N, 0–15, of each register; reads only).
    /// Default: plain registers.
    #[arg(long = "type", value_name = "TYPE")]
    pub data_type: Option<DataType>,
    /// Byte and word order of each value: ABCD (default: big-endian), CDAB (words
    /// swapped), BADC (bytes swapped in each word), DCBA (both).
    #[arg(long, value_name = "ORDER")]
    pub order: Option<Order>,
}

impl TypeArgs {
    /// The format asked for, if --type or --order was given (the type defaults to uint16,
    /// the order to ABCD).
    fn format(&self) -> Option<Format> {
        (self.data_type.is_some() || self.order.is_some()).then(|| {
            Format::new(
                self.data_type.unwrap_or_default(),
                self.order.unwrap_or_default(),
            )
        })
    }
}

impl ModbusAction {
    /// The format of the values, for the actions that take --type.
    fn format(&self) -> Option<Format> {
        match self {
            Self::ReadHolding(TypedRead { typed, .. })
            | Self::ReadInput(TypedRead { typed, .. })
            | Self::WriteRegisters { typed, .. } => typed.format(),
            _ => None,
        }
    }
}

/// What `cellbus modbus` sends, checked before the line is opened.
enum Send {
    To(Addressed),
    Broadcast(Broadcast),
}

pub async fn run_modbus(args: ModbusArgs) -> anyhow::Result<ExitCode> {
    let endpoint = args.line.endpoint()?;
    if let ModbusAction::Scan { units } = &args.action {
        if let Some(unit) = args.unit {
            return Err(usage(format!(
                "scan tries the units of --units (1-247 unless given), not --unit; \
                 to try unit {unit} alone: scan --units {unit}"
            )));
        }
        return scan(&endpoint, &args.line, units.clone()).await;
    }
    let Some(unit) = args.unit else {
        return Err(usage("--unit N is needed: the unit number to ask (1-247)"));
    };
    if unit == 0 && Framing::of(&endpoint) == Framing::Tcp {
        return Err(usage(
            "--unit 0 is a serial broadcast, which Modbus TCP does not carry (a server may \
             answer it as a request of its own); give the device's unit number, often 1 or 255",
        ));
    }
    // Build the request before opening the line: bad arguments never touch the device.
    let request = modbus_request(&args.action)?;
    if let Some(warning) = modicon_warning(&args.action) {
        eprintln!("cellbus: warning: {warning}");
    }
    let send = if unit == 0 {
        match request {
            Request::WriteSingleCoil(w) => Send::Broadcast(Broadcast(Write::SingleCoil(w))),
            Request::WriteSingleRegister(w) => Send::Broadcast(Broadcast(Write::SingleRegister(w))),
            Request::WriteMultipleCoils(w) => Send::Broadcast(Broadcast(Write::MultipleCoils(w))),
            Request::WriteMultipleRegisters(w) => {
                Send::Broadcast(Broadcast(Write::MultipleRegisters(w)))
            }
            _ => {
                return Err(usage(
                    "--unit 0 is a broadcast, which nobody answers: only writes can be broadcast; \
                     give the unit number of the device to read",
                ));
            }
        }
    } else {
        Send::To(Addressed::new(UnitId::jbus(unit).map_err(usage)?, request))
    };
    let mut client = open(&endpoint, args.line.config()).await?;
    match send {
        Send::Broadcast(write) => {
            client.broadcast(&write).await?;
            let request = Request::from(write.0.clone());
            if args.line.output.json {
                output::line(values_json(
                    0,
                    &request,
                    written_json(&args.action, &request)?,
                ))?;
            } else {
                output::line(format!(
                    "broadcast to every unit (no answer is expected): {request}"
                ))?;
            }
        }
        Send::To(addressed) => {
            let answer = match client.request(&addressed).await {
                Ok(answer) => answer,
                Err(err) => return Err(refusal(err, &addressed, args.line.output.json)?),
            };
            print_answer(&addressed, &answer, &args.action, args.line.output.json)?;
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// The request, or a usage error.
fn modbus_request(action: &ModbusAction) -> anyhow::Result<Request> {
    let format = action.format();
    match action {
        ModbusAction::ReadHolding(TypedRead { read, .. }) => {
            Request::read_holding_registers(read.address.value, registers_for(read.count, format)?)
        }
        ModbusAction::ReadInput(TypedRead { read, .. }) => {
            Request::read_input_registers(read.address.value, registers_for(read.count, format)?)
        }
        ModbusAction::ReadCoils(read) => Request::read_coils(read.address.value, read.count),
        ModbusAction::ReadDiscrete(read) => {
            Request::read_discrete_inputs(read.address.value, read.count)
        }
        &ModbusAction::WriteRegister { address, value } => {
            Ok(Request::write_single_register(address.value, value))
        }
        ModbusAction::WriteRegisters {
            address, values, ..
        } => Request::write_multiple_registers(address.value, registers_to_write(values, format)?),
        &ModbusAction::WriteCoil { address, state } => {
            Ok(Request::write_single_coil(address.value, state))
        }
        ModbusAction::WriteCoils { address, values } => {
            Request::write_multiple_coils(address.value, values.clone())
        }
        ModbusAction::Scan { .. } => unreachable!("scan sends no single request"),
    }
    .map_err(usage)
}

/// How many registers COUNT values of the format take (COUNT registers without one).
fn registers_for(count: u16, format: Option<Format>) -> anyhow::Result<u16> {
    let Some(format) = format else {
        return Ok(count);
    };
    let registers = u32::from(count) * u32::from(format.registers());
    u16::try_from(registers)
        .ok()
        .filter(|&r| r <= jbus::rtu::ReadRegisterCount::MAX)
        .ok_or_else(|| {
            usage(format!(
                "{count} values of {} take {registers} registers, and one read takes at most {}",
                format.data_type,
                jbus::rtu::ReadRegisterCount::MAX
            ))
        })
}

/// The registers that carry the values of `write-registers`.
fn registers_to_write(values: &[String], format: Option<Format>) -> anyhow::Result<Vec<u16>> {
    let Some(format) = format else {
        return values
            .iter()
            .map(|v| parse_word(v).map_err(usage))
            .collect();
    };
    let mut registers = Vec::new();
    for value in values {
        registers.extend(format.encode_text(value).map_err(usage)?);
    }
    Ok(registers)
}

/// A typed value as JSON: a number, a string or a boolean.
fn typed_json(value: &TypedValue) -> Value {
    match value {
        TypedValue::Int(i) => json!(i),
        TypedValue::Uint(u) => json!(u),
        TypedValue::Float(f) => json!(f),
        TypedValue::Text(text) => json!(text),
        TypedValue::Bool(b) => json!(b),
    }
}

/// The timeout of each unit's read in a scan unless `--timeout` says otherwise.
const SCAN_TIMEOUT: Duration = Duration::from_millis(200);

/// `cellbus modbus scan`: the units in `units` that answer a read of holding register 0.
async fn scan(
    endpoint: &Endpoint,
    line: &LineArgs,
    units: std::ops::RangeInclusive<u8>,
) -> anyhow::Result<ExitCode> {
    let config = ClientConfig {
        timeout: line.timeout.unwrap_or(SCAN_TIMEOUT),
        retries: 0,
        ..line.config()
    };
    let mut client = open(endpoint, config).await?;
    let (first, last) = (*units.start(), *units.end());
    let mut answering = Vec::new();
    for number in units {
        let unit = UnitId::jbus(number).map_err(usage)?;
        match client.read_holding_registers(unit, 0, 1).await {
            Ok(_) => answering.push((number, None)),
            // A Modbus gateway's "no path" or "no answer from the target" is no answer.
            Err(ClientError::Refused { refusal, .. })
                if !refusal.exception.code.is_target_silent() =>
            {
                answering.push((number, Some(refusal.exception.code)));
            }
            Err(err @ ClientError::Line { .. }) => return Err(output::failure(err)),
            Err(err) => tracing::debug!(unit = number, "no answer: {err}"),
        }
    }
    if line.output.json {
        let units: Vec<u8> = answering.iter().map(|(n, _)| *n).collect();
        output::line(json!({ "units": units }))?;
    } else if answering.is_empty() {
        output::line(format!("no unit of {first}-{last} answered on {endpoint}"))?;
    } else {
        for (number, refused) in &answering {
            match refused {
                None => output::line(format!("unit {number} answers"))?,
                Some(code) => output::line(format!(
                    "unit {number} answers (refused the read of holding register 0: {code})"
                ))?,
            }
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// `FIRST-LAST` or one unit number, within 1–255, first no greater than last.
fn parse_units(text: &str) -> Result<std::ops::RangeInclusive<u8>, String> {
    let bad = || {
        format!(
            "{text:?} is not a range of unit numbers: write FIRST-LAST within 1-255, e.g. 1-247"
        )
    };
    let (first, last) = match text.split_once('-') {
        Some((first, last)) => (first.trim(), last.trim()),
        None => (text.trim(), text.trim()),
    };
    let first: u8 = first.parse().map_err(|_| bad())?;
    let last: u8 = last.parse().map_err(|_| bad())?;
    if first == 0 || first > last {
        return Err(bad());
    }
    Ok(first..=last)
}

/// An exception also goes to stdout as JSON when asked, so scripts see its number.
fn refusal(err: ClientError, request: &Addressed, json: bool) -> anyhow::Result<anyhow::Error> {
    if let (true, Some(UnitRefusal { exception, .. })) = (json, err.refusal()) {
        output::line(json!({
            "unit": request.unit.get(),
            "address": request.request.address(),
            "exception": {
                "code": exception.code.get(),
                "meaning": exception.code.meaning(),
            },
        }))?;
    }
    Ok(output::failure(err))
}

fn print_answer(
    request: &Addressed,
    answer: &Answer,
    action: &ModbusAction,
    json: bool,
) -> anyhow::Result<()> {
    let unit = request.unit.get();
    let address = request.request.address();
    match (answer, action.format()) {
        (Answer::Registers(values), Some(format)) => {
            return print_typed(unit, address, values, format, json);
        }
        (Answer::Written | Answer::Exception(_), Some(_)) if json => {
            output::line(values_json(
                unit,
                &request.request,
                written_json(action, &request.request)?,
            ))?;
            return Ok(());
        }
        _ => {}
    }
    match (answer, json) {
        (Answer::Registers(values), true) => {
            output::line(json!({ "unit": unit, "address": address, "values": values }))?;
        }
        (Answer::Bits(bits), true) => {
            output::line(json!({ "unit": unit, "address": address, "values": bits }))?;
        }
        (Answer::Registers(values), false) => {
            for (a, value) in (address..=u16::MAX).zip(values) {
                output::line(format!("{a:>5} (0x{a:04X}) = {value:>5} (0x{value:04X})"))?;
            }
        }
        (Answer::Bits(bits), false) => {
            for (a, &bit) in (address..=u16::MAX).zip(bits) {
                let state = if bit { "1 (on)" } else { "0 (off)" };
                output::line(format!("{a:>5} (0x{a:04X}) = {state}"))?;
            }
        }
        (Answer::Written | Answer::Exception(_), true) => {
            output::line(values_json(
                unit,
                &request.request,
                written_values(&request.request),
            ))?;
        }
        (Answer::Written | Answer::Exception(_), false) => {
            output::line(format!("unit {unit} acknowledged: {}", request.request))?;
        }
    }
    Ok(())
}

/// Registers read as values of `format`: one line each (its first register's address and
/// the value), or `{"unit","address","type","values"}`; registers that hold no value of
/// the type are an error, and with `--json` also `{"unit","address","type","registers",
/// "error"}` on stdout.
fn print_typed(
    unit: u8,
    address: u16,
    registers: &[u16],
    format: Format,
    json: bool,
) -> anyhow::Result<()> {
    let width = usize::from(format.registers());
    let decoded = registers
        .chunks(width)
        .map(|chunk| format.decode(chunk))
        .collect::<Result<Vec<_>, _>>();
    let values = match decoded {
        Ok(values) => values,
        Err(error) => {
            // Scripts still get the registers that came, with what is wrong with them.
            if json {
                output::line(json!({
                    "unit": unit,
                    "address": address,
                    "type": format.data_type.to_string(),
                    "registers": registers,
                    "error": error.to_string(),
                }))?;
            }
            return Err(anyhow::Error::new(error).context(format!(
                "unit {unit}, registers from {address} (0x{address:04X}) as {}",
                format.data_type
            )));
        }
    };
    if json {
        let values: Vec<Value> = values.iter().map(typed_json).collect();
        output::line(json!({
            "unit": unit,
            "address": address,
            "type": format.data_type.to_string(),
            "values": values,
        }))?;
        return Ok(());
    }
    for (index, value) in values.iter().enumerate() {
        let a = usize::from(address) + index * width;
        output::line(format!("{a:>5} (0x{a:04X}) = {value}"))?;
    }
    Ok(())
}

/// What a write carried, as JSON: the typed values as given with --type, else the
/// registers or coils.
fn written_json(action: &ModbusAction, request: &Request) -> anyhow::Result<Value> {
    if let (ModbusAction::WriteRegisters { values, .. }, Some(format)) = (action, action.format()) {
        let typed = values
            .iter()
            .map(|v| format.data_type.parse_value(v).map(|t| typed_json(&t)))
            .collect::<Result<Vec<_>, _>>()
            .map_err(usage)?;
        return Ok(json!(typed));
    }
    Ok(written_values(request))
}

fn values_json(unit: u8, request: &Request, values: Value) -> Value {
    json!({ "unit": unit, "address": request.address(), "values": values })
}

/// The values a write carries, as JSON (registers as numbers, coils as booleans).
fn written_values(request: &Request) -> Value {
    match request {
        Request::WriteSingleCoil(w) => json!([w.value]),
        Request::WriteSingleRegister(w) => json!([w.value]),
        Request::WriteMultipleCoils(w) => json!(w.values()),
        Request::WriteMultipleRegisters(w) => json!(w.values()),
        _ => json!([]),
    }
}

/// An address or count: decimal or `0x` hex, 0–65535.
fn parse_address(text: &str) -> Result<u16, String> {
    let parsed = match text.strip_prefix("0x").or_else(|| text.strip_prefix("0X")) {
        Some(hex) => u16::from_str_radix(hex, 16),
        None => text.parse(),
    };
    parsed.map_err(|_| format!("{text:?} is not a number from 0 to 65535 (decimal or 0x hex)"))
}

/// A register value: 0–65535 (decimal or 0x hex), or -32768–-1 as two's complement.
fn parse_word(text: &str) -> Result<u16, String> {
    if let Some(negative) = text.strip_prefix('-') {
        return negative
            .parse::<u16>()
            .ok()
            .filter(|&n| (1..=0x8000).contains(&n))
            .map(|n| 0u16.wrapping_sub(n))
            .ok_or_else(|| format!("{text:?} is below -32768, the lowest 16-bit value"));
    }
    parse_address(text).map_err(|_| {
        format!("{text:?} is not a register value: 0 to 65535, 0x hex, or -32768 to -1")
    })
}

fn parse_on_off(text: &str) -> Result<bool, String> {
    match text.to_ascii_lowercase().as_str() {
        "on" | "1" | "true" => Ok(true),
        "off" | "0" | "false" => Ok(false),
        _ => Err(format!("{text:?} is not a coil state: write on or off")),
    }
}

fn parse_bit_value(text: &str) -> Result<bool, String> {
    match text {
        "1" => Ok(true),
        "0" => Ok(false),
        _ => Err(format!("{text:?} is not a coil value: write 1 or 0")),
    }
}

// --- cellbus cross ---

#[derive(Debug, Args)]
pub struct CrossArgs {
    #[command(flatten)]
    pub line: LineArgs,
    /// The switch's unit number (1–255), as set on it.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_CROSS_UNIT, global = true)]
    pub unit: u8,
    #[command(subcommand)]
    pub action: CrossAction,
}

#[derive(Debug, Subcommand)]
pub enum CrossAction {
    /// The switch's state in words: what feeds the load, active alarms, states, the mimic
    /// diagram, measures and ratings with their units (4 reads of function 3).
    Status,
    /// Read the switch every --interval and print what changes: the load's source, alarms
    /// raised and cleared, states, and the measures at each change; the first line gives
    /// the state at the start. Measures alone (which always move a little) are not changes.
    /// Runs until --count rounds, --for a while, --changes changes, or Ctrl-C.
    Watch {
        /// Time between readings.
        #[arg(long, default_value = "1s", value_parser = crate::rounds::parse_period)]
        interval: Duration,
        #[command(flatten)]
        stop: StopArgs,
        /// Stop after this many changes (the state at the start is not one).
        #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
        changes: Option<u64>,
    },
}

pub async fn run_cross(args: CrossArgs) -> anyhow::Result<ExitCode> {
    let endpoint = args.line.endpoint()?;
    let unit = UnitId::jbus(args.unit).map_err(usage)?;
    let mut client = open(&endpoint, args.line.config()).await?;
    match args.action {
        CrossAction::Status => {
            let state = jbus::cross::read(&mut client, unit)
                .await
                .map_err(output::failure)
                .with_context(|| format!("reading the CROSS at unit {unit} on {endpoint}"))?;
            if args.line.output.json {
                output::line(cross_json(unit, &state))?;
            } else {
                output::line(format!("Chloride CROSS, unit {unit} on {endpoint}"))?;
                output::line(state.to_string().trim_end())?;
            }
            Ok(ExitCode::SUCCESS)
        }
        CrossAction::Watch {
            interval,
            stop,
            changes,
        } => {
            let rounds = Rounds::new(interval, stop);
            watch(&mut client, unit, rounds, changes, args.line.output.json).await
        }
    }
}

async fn watch(
    client: &mut Client,
    unit: UnitId,
    mut rounds: Rounds,
    stop_after: Option<u64>,
    json: bool,
) -> anyhow::Result<ExitCode> {
    let mut last: Option<Discrete> = None;
    let mut lost = false;
    let mut seen = 0u64;
    while rounds.next().await {
        let elapsed = rounds.elapsed();
        match jbus::cross::read(client, unit).await {
            Ok(state) => {
                let now = Discrete::of(&state.internal);
                let mut events = Vec::new();
                if std::mem::take(&mut lost) {
                    events.push("contact restored".to_owned());
                }
                match &last {
                    // The state at the start is not a change.
                    None => {
                        events.push(format!("load {}", now.load()));
                        let alarms: Vec<&str> = now.alarms().collect();
                        events.push(if alarms.is_empty() {
                            "alarms: none".to_owned()
                        } else {
                            format!("alarms: {}", alarms.join(", "))
                        });
                        print_watch(elapsed, &events, Some(&state), json)?;
                    }
                    Some(before) => {
                        events.extend(now.changes_since(before).iter().map(ToString::to_string));
                        if !events.is_empty() {
                            print_watch(elapsed, &events, Some(&state), json)?;
                            seen += 1;
                        }
                    }
                }
                last = Some(now);
            }
            Err(err @ ClientError::Line { .. }) => return Err(err.into()),
            Err(err) => {
                if !lost {
                    lost = true;
                    print_watch(elapsed, &[format!("contact lost: {err}")], None, json)?;
                    seen += 1;
                }
            }
        }
        if stop_after.is_some_and(|n| seen >= n) {
            return Ok(ExitCode::SUCCESS);
        }
    }
    Ok(ExitCode::SUCCESS)
}

fn print_watch(
    elapsed: Duration,
    events: &[String],
    state: Option<&CrossState>,
    json: bool,
) -> anyhow::Result<()> {
    if json {
        let mut object = Map::new();
        object.insert("elapsed_ms".into(), json!(elapsed.as_millis() as u64));
        object.insert("changes".into(), json!(events));
        if let Some(state) = state {
            object.insert("state".into(), state_json(state));
        }
        output::line(Value::Object(object))?;
        return Ok(());
    }
    let time = format!("{:.1} s", elapsed.as_secs_f64());
    for event in events {
        output::line(format!("{time:<9} {event}"))?;
    }
    if let Some(state) = state {
        let m = &state.measures;
        output::line(format!(
            "{:<9} S1 {} {}, S2 {} {}, output {} {} {}",
            "",
            m.s1_voltage.u,
            m.s1_frequency,
            m.s2_voltage.u,
            m.s2_frequency,
            m.output_voltage.u,
            m.output_frequency,
            m.load_power
        ))?;
    }
    Ok(())
}

/// `cellbus cross status --json`: the state with the unit number.
fn cross_json(unit: UnitId, state: &CrossState) -> Value {
    let mut object = Map::new();
    object.insert("unit".into(), json!(unit.get()));
    if let Value::Object(rest) = state_json(state) {
        object.extend(rest);
    }
    Value::Object(object)
}

/// The state as JSON: words for the discrete parts; each measure and rating of
/// `jbus::cross::points` under its name, as `{"value":…,"unit":…}` or `{"u":…,"v":…,"w":…,
/// "unit":…}` (a plain number when it has no unit).
fn state_json(state: &CrossState) -> Value {
    let feed = state.feed();
    let source = feed.source().map(|s| match s {
        Source::S1 => "S1",
        Source::S2 => "S2",
    });
    let mimic: Map<String, Value> = jbus::cross::Element::ALL
        .iter()
        .map(|&e| (e.to_string(), json!(state.mimic.lamps(e).to_string())))
        .collect();
    json!({
        "load": feed.to_string(),
        "source": source,
        "reserve_line": state.on_reserve_line(),
        "alarms": state.alarms(),
        "states": state.conditions(),
        "mimic": {
            "lamps": mimic,
            "segments_lit": state.mimic.segments.lit().map(|s| s.number()).collect::<Vec<_>>(),
        },
        "measures": quantities_json(MEASURES, &state.measures),
        "ratings": quantities_json(RATINGS, &state.ratings),
    })
}

/// `{name: amount}` for every quantity of an area.
fn quantities_json<A>(quantities: &[Quantity<A>], area: &A) -> Value {
    let object: Map<String, Value> = quantities
        .iter()
        .map(|q| (q.name.to_owned(), amount_json((q.read)(area), q.unit)))
        .collect();
    Value::Object(object)
}

fn amount_json(amount: Amount, unit: Option<&str>) -> Value {
    let mut object = match amount {
        Amount::Count(count) => return json!(count),
        Amount::One(value) => json!({ "value": value }),
        Amount::Phases(phases) => json!({ "u": phases.u, "v": phases.v, "w": phases.w }),
    };
    if let (Some(unit), Value::Object(fields)) = (unit, &mut object) {
        fields.insert("unit".into(), json!(unit));
    }
    object
}

// --- cellbus sim cross | modbus ---

/// How a Modbus simulator frames its messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SimFraming {
    /// Modbus RTU frames (with their CRC), as on a serial line or behind a serial server.
    Rtu,
    /// Modbus TCP (MBAP header, no CRC); needs --listen.
    Tcp,
}

#[derive(Debug, Args)]
pub struct SimCrossArgs {
    #[command(flatten)]
    pub serve: ServeArgs,
    /// rtu: RTU frames over TCP or the PTY; tcp: Modbus TCP (prints `listening on
    /// modbus-tcp://IP:PORT`), answering every unit the simulator answers on RTU.
    #[arg(long, value_enum, default_value_t = SimFraming::Rtu)]
    pub framing: SimFraming,
    /// The switch's unit number (1–255).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_CROSS_UNIT)]
    pub unit: u8,
    /// Make source 1 fail after this long and come back after as long again, over and over,
    /// so the switch transfers the load back and forth (for `cross watch` and demos).
    #[arg(long, value_name = "DURATION", value_parser = humantime::parse_duration)]
    pub cycle_outage: Option<Duration>,
}

#[derive(Debug, Args)]
pub struct SimModbusArgs {
    #[command(flatten)]
    pub serve: ServeArgs,
    /// rtu: RTU frames over TCP or the PTY; tcp: Modbus TCP (prints `listening on
    /// modbus-tcp://IP:PORT`), answering every unit the simulator answers on RTU.
    #[arg(long, value_enum, default_value_t = SimFraming::Rtu)]
    pub framing: SimFraming,
    /// The unit number (1–255); overrides the map's `unit` line. Default: the map's, or 1.
    #[arg(long, value_name = "N")]
    pub unit: Option<u8>,
    /// Which coils, discrete inputs, holding and input registers exist, with their first
    /// values (lines like `holding 0x0000 = 1 2 3`, `coil 10 = 1 0 1`, `unit 17`, typed
    /// `holding 0x0100 float32 CDAB = 229.7` or `input 0x20 string:4 = "PUMP 7"`; see the
    /// jbus crate's slave::map). Without it every address of every table exists, holds 0,
    /// and coils and holding registers are writable.
    #[arg(long, value_name = "FILE", conflicts_with = "example")]
    pub map: Option<PathBuf>,
    /// Serve an example device shipped with cellbus instead of a map file:
    /// `energy-meter`, a 3-phase meter's float32 input registers (the registers of
    /// `cellbus config example --modbus-meter`).
    #[arg(long, value_enum, value_name = "NAME")]
    pub example: Option<SimExample>,
    /// With --framing tcp: answer as a serial-to-Ethernet gateway (a Moxa MGate) does for
    /// a unit that does not answer, with exception 11 (gateway target failed to respond)
    /// after this long, instead of silence.
    #[arg(long, value_name = "DURATION", value_parser = humantime::parse_duration)]
    pub gateway_timeout: Option<Duration>,
}

/// The example devices `cellbus sim modbus --example` serves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SimExample {
    /// A 3-phase energy meter: float32 input registers, ABCD.
    EnergyMeter,
}

/// Refuses Modbus TCP on a PTY: a serial line has no MBAP.
fn check_framing(serve: &ServeArgs, framing: SimFraming) -> anyhow::Result<()> {
    if framing == SimFraming::Tcp && serve.pty.is_some() {
        return Err(usage(
            "--framing tcp is Modbus TCP, which a serial line (--pty) does not carry: use --listen, or --framing rtu",
        ));
    }
    Ok(())
}

/// Serves the RTU device `make` gives, in `framing`; over Modbus TCP, silence is answered
/// with exception 11 after `gateway_timeout`, when given.
async fn serve_modbus<D, F>(
    serve_args: &ServeArgs,
    framing: SimFraming,
    gateway_timeout: Option<Duration>,
    make: F,
) -> anyhow::Result<ExitCode>
where
    D: wire::Device,
    F: Fn() -> D + std::marker::Send + 'static,
{
    match framing {
        SimFraming::Rtu => serve(serve_args, JBUS_LINE, make).await,
        SimFraming::Tcp => {
            let mbap = move || {
                let server = jbus::tcp::MbapServer::new(make());
                match gateway_timeout {
                    Some(after) => server.answering_silence(after),
                    None => server,
                }
            };
            crate::sim::serve_with(serve_args, JBUS_LINE, "modbus-tcp", mbap, || ()).await
        }
    }
}

pub async fn sim_cross(args: SimCrossArgs) -> anyhow::Result<ExitCode> {
    check_framing(&args.serve, args.framing)?;
    let unit = UnitId::jbus(args.unit).map_err(usage)?;
    if args.cycle_outage.is_some_and(|d| d.is_zero()) {
        return Err(usage("--cycle-outage must be longer than 0"));
    }
    let twin = SharedModel::new(CrossTwin::new(unit, args.serve.seed));
    if let Some(period) = args.cycle_outage {
        let twin = twin.clone();
        tokio::spawn(async move {
            loop {
                tokio::time::sleep(period).await;
                twin.lock().fail_source(Source::S1);
                tokio::time::sleep(period).await;
                twin.lock().restore_source(Source::S1);
            }
        });
    }
    serve_modbus(&args.serve, args.framing, None, move || twin.line()).await
}

pub async fn sim_modbus(args: SimModbusArgs) -> anyhow::Result<ExitCode> {
    check_framing(&args.serve, args.framing)?;
    if args.gateway_timeout.is_some() && args.framing != SimFraming::Tcp {
        return Err(usage(
            "--gateway-timeout is how a Modbus TCP gateway answers for a silent unit: give \
             --framing tcp too",
        ));
    }
    let map = match (&args.map, args.example) {
        (Some(path), _) => {
            let text = std::fs::read_to_string(path)
                .map_err(|e| usage(format!("cannot read the map {}: {e}", path.display())))?;
            SlaveMap::parse(&text).map_err(|e| usage(format!("map {}: {e}", path.display())))?
        }
        (None, Some(SimExample::EnergyMeter)) => {
            SlaveMap::parse(gateway::driver::modbus::config::EXAMPLE_METER_MAP)
                .map_err(|e| anyhow::anyhow!("the shipped energy meter map: {e}"))?
        }
        (None, None) => SlaveMap::all_writable(UnitId::jbus(DEFAULT_SLAVE_UNIT).map_err(usage)?),
    };
    let map = match args.unit {
        Some(number) => map.with_unit(UnitId::jbus(number).map_err(usage)?),
        None => map,
    };
    let slave = SharedModel::new(Slave::new(map));
    serve_modbus(&args.serve, args.framing, args.gateway_timeout, move || {
        slave.line()
    })
    .await
}

#[cfg(test)]
mod tests;
