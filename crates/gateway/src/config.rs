//! The cell's configuration (TOML): lines, the devices on them, and how often to poll.
//!
//! ```toml
//! token = "change-me"                   # optional; CELLBUS_TOKEN and --token win over it
//! read_token = "look-only"              # optional; then every API route needs it (or the
//!                                       # write token); CELLBUS_READ_TOKEN wins over it
//!
//! [[line]]
//! name = "rework"                       # unique; a-z, 0-9, _ and -
//! endpoint = "serial:///dev/ttyUSB0?baud=19200&framing=8E1"
//! reopen_after_timeouts = 3             # every device timed out this often in a row:
//!                                       # close and reopen the line (0: never)
//!
//! [[line.device]]
//! id = "jbc1"                           # unique in the cell; used in URLs and point ids
//! name = "Rework station 1"             # words for people (default: the id)
//! protocol = "jbc"
//! address = 1                           # JBC: 0-99, or "none" for the form without addresses;
//!                                       # thermosald: 0-7; cross: JBUS unit 1-255
//! timeout = "500ms"                     # per reply (protocol default if left out)
//! retries = 2                           # after a failed attempt (protocol default)
//! period = "2s"                         # for every poll group not listed in [poll]
//! poll = { live = "1s", info = "5m" }   # per poll group
//! event_port = 49153                    # panasonic only: Port 2 (the endpoint names Port 1)
//!
//! [[line.device.register]]              # modbus only: one table per register
//! name = "supply_temperature"           # see `driver::modbus` for every field
//! address = 0x10
//! ```
//!
//! Every table refuses fields it does not know. A file that does not parse or does not make
//! sense is refused whole, with the file, line and column and what is wrong
//! ([`ConfigError`]). [`EXAMPLE_CONFIG`] is a commented example for a real cell.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::fmt;
use std::ops::{Range, RangeInclusive};
use std::path::{Path, PathBuf};
use std::time::Duration;

use link::Endpoint;
use serde::Deserialize;
use toml::Spanned;

use jbus::data::{DataType, Format, Order, Scaling};
use jbus::rtu::{ReadBitCount, ReadRegisterCount};

use crate::driver::modbus::{ModbusOptions, RegisterConfig, RegisterList, RegisterTable};
use crate::driver::{self, DriverConfig, Protocol};
use crate::point::{Deadband, DeviceId};

mod register_csv;

/// An example configuration for a real cell (`cellbus config example` prints it); the
/// same file is `crates/gateway/examples/cell.toml`.
pub const EXAMPLE_CONFIG: &str = include_str!("../examples/cell.toml");

/// Shortest poll period accepted.
pub const MIN_PERIOD: Duration = Duration::from_millis(50);
/// Longest poll period accepted.
pub const MAX_PERIOD: Duration = Duration::from_secs(24 * 3600);
/// Longest reply timeout accepted.
pub const MAX_TIMEOUT: Duration = Duration::from_secs(60);
/// Most retries accepted.
pub const MAX_RETRIES: u8 = 10;
/// A line is closed and reopened when every device on it has timed out this many times in
/// a row (a serial server's session or an adapter can hang while the devices are fine).
pub const DEFAULT_REOPEN_AFTER_TIMEOUTS: u32 = 3;
/// Largest `reopen_after_timeouts` accepted.
pub const MAX_REOPEN_AFTER_TIMEOUTS: u32 = 1000;

/// A checked configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct CellConfig {
    /// The file it came from, if any (the demo cell has none).
    pub source: Option<PathBuf>,
    /// The token writes need, if the file sets one.
    pub token: Option<String>,
    /// The token every API route needs, if the file sets one.
    pub read_token: Option<String>,
    /// The lines, in file order.
    pub lines: Vec<LineConfig>,
    /// The northbound MQTT (Sparkplug B) connection, if the file has an `[mqtt]` table.
    pub mqtt: Option<MqttConfig>,
    /// The OPC UA server, if the file has an `[opcua]` table.
    pub opcua: Option<OpcuaConfig>,
}

/// Default keep-alive of the MQTT connection.
pub const DEFAULT_MQTT_KEEP_ALIVE: Duration = Duration::from_secs(30);
/// Default Sparkplug group id.
pub const DEFAULT_MQTT_GROUP: &str = "cellbus";

/// The `[mqtt]` table: where the broker is and who the edge node is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MqttConfig {
    /// The broker's host.
    pub host: String,
    /// The broker's port.
    pub port: u16,
    /// The Sparkplug group id.
    pub group_id: String,
    /// The Sparkplug edge node id.
    pub edge_node_id: String,
    /// The MQTT client id.
    pub client_id: String,
    /// The user name, if the broker wants one.
    pub username: Option<String>,
    /// The environment variable holding the password (never the password itself).
    pub password_env: Option<String>,
    /// The MQTT keep-alive.
    pub keep_alive: Duration,
    /// What is published: Sparkplug B or plain JSON.
    pub mode: MqttMode,
    /// JSON mode's topic prefix (`cellbus/{edge_node_id}` by default).
    pub prefix: String,
    /// Whether DCMD writes are carried out (also needs `--allow-writes`).
    pub commands: bool,
    /// The Sparkplug primary host application whose STATE gates the births, if any.
    pub primary_host: Option<String>,
    /// The most stored changes sent after an outage (the newest are kept).
    pub max_backlog: u64,
    /// The most metrics one DCMD may carry; a larger command is refused whole.
    pub max_command_metrics: usize,
    /// JSON mode: how often the retained point messages are read back and another
    /// client's put right.
    pub check_retained: Duration,
    /// TLS to the broker (`mqtts://`); `None` for `mqtt://`.
    pub tls: Option<MqttTls>,
}

/// TLS to the broker (`mqtts://`): whom to trust and what to show. The files are PEM; a
/// relative path in the config file is relative to the file's directory.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct MqttTls {
    /// `ca_file`: the CA certificates that sign the broker's; `None`: the system's roots.
    pub ca_file: Option<PathBuf>,
    /// `client_cert` and `client_key`: the certificate (chain) and private key the gateway
    /// shows a broker that asks for one.
    pub client: Option<MqttClientCert>,
}

/// A client certificate for the broker: `client_cert` and `client_key`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MqttClientCert {
    /// The certificate, then any intermediates (PEM).
    pub cert: PathBuf,
    /// Its private key (PEM: PKCS#8, PKCS#1 or SEC1).
    pub key: PathBuf,
}

/// A broker URL, read by [`parse_broker`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Broker {
    /// The host.
    pub host: String,
    /// The port (1883 for `mqtt://`, 8883 for `mqtts://` when the URL has none).
    pub port: u16,
    /// `mqtts://`: TLS.
    pub tls: bool,
}

/// What the gateway publishes on MQTT.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MqttMode {
    /// A Sparkplug B 3.0 edge node.
    #[default]
    Sparkplug,
    /// One retained JSON message per point under a prefix, for Node-RED, Telegraf and
    /// home-made consumers.
    Json,
}

impl MqttMode {
    /// Reads `sparkplug` or `json`.
    pub fn parse(text: &str) -> Result<Self, String> {
        match text.trim().to_ascii_lowercase().as_str() {
            "sparkplug" => Ok(Self::Sparkplug),
            "json" => Ok(Self::Json),
            other => Err(format!(
                "MQTT mode {other:?} is not one cellbus knows; write \"sparkplug\" or \"json\""
            )),
        }
    }

    /// `sparkplug` or `json`.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Sparkplug => "sparkplug",
            Self::Json => "json",
        }
    }
}

/// Default of `max_backlog`: stored changes sent after an outage.
pub const DEFAULT_MQTT_BACKLOG: u64 = 1_000_000;
/// Default of `check_retained`: JSON mode reads its retained point messages back this
/// often (each check brings one message a point).
pub const DEFAULT_MQTT_CHECK_RETAINED: Duration = Duration::from_secs(600);
/// Default of `max_command_metrics`: writes in one DCMD. An operator's screen sets a few
/// values at once; a thousand in one command is a flood.
pub const DEFAULT_MQTT_COMMAND_METRICS: usize = 64;

impl MqttConfig {
    /// The broker at `url` (`mqtt://host:port`, or `mqtts://host:port` trusting the
    /// system's roots) with every other field at its default and the edge node id
    /// `edge_node_id`.
    pub fn for_broker(url: &str, edge_node_id: &str) -> Result<Self, String> {
        let Broker { host, port, tls } = parse_broker(url)?;
        Ok(Self {
            host,
            port,
            group_id: DEFAULT_MQTT_GROUP.to_owned(),
            edge_node_id: edge_node_id.to_owned(),
            client_id: format!("cellbus-{edge_node_id}"),
            username: None,
            password_env: None,
            keep_alive: DEFAULT_MQTT_KEEP_ALIVE,
            mode: MqttMode::Sparkplug,
            prefix: format!("cellbus/{edge_node_id}"),
            commands: false,
            primary_host: None,
            max_backlog: DEFAULT_MQTT_BACKLOG,
            max_command_metrics: DEFAULT_MQTT_COMMAND_METRICS,
            check_retained: DEFAULT_MQTT_CHECK_RETAINED,
            tls: tls.then(MqttTls::default),
        })
    }
}

/// The longest MQTT client id: an MQTT string is at most 65,535 bytes.
const MAX_CLIENT_ID: usize = 65_535;

/// Reads `mqtt://host[:port]` (port 1883 by default) or `mqtts://host[:port]` (TLS, port
/// 8883 by default).
pub fn parse_broker(given: &str) -> Result<Broker, String> {
    // Errors show the URL without its user name and password.
    let text = &hide_userinfo(given);
    let url = url::Url::parse(given.trim())
        .map_err(|e| format!("broker {text:?} is not a URL ({e}); write mqtt://host:1883"))?;
    let (tls, default_port) = match url.scheme() {
        "mqtt" => (false, 1883),
        "mqtts" => (true, 8883),
        other => {
            return Err(format!(
                "broker {text:?} has scheme {other:?}; write mqtt://host:1883 or mqtts://host:8883"
            ));
        }
    };
    let host = url
        .host_str()
        .filter(|h| !h.is_empty())
        .ok_or_else(|| format!("broker {text:?} names no host; write mqtt://host:1883"))?;
    if url.path().len() > 1 || url.query().is_some() || !url.username().is_empty() {
        return Err(format!(
            "broker {text:?}: write only mqtt://host:port (user name and password go in username and password_env)"
        ));
    }
    let host = host
        .trim_start_matches('[')
        .trim_end_matches(']')
        .to_owned();
    let port = url.port().unwrap_or(default_port);
    if port == 0 {
        return Err(format!(
            "broker {text:?}: port 0 is not a port a broker listens on; write mqtt://host:1883"
        ));
    }
    Ok(Broker { host, port, tls })
}

/// `text` with what comes before an `@` in a URL's authority (a user name and a password)
/// shown as `(hidden)`.
fn hide_userinfo(text: &str) -> String {
    let Some((scheme, rest)) = text.split_once("://") else {
        return text.to_owned();
    };
    let end = rest.find(['/', '?', '#']).unwrap_or(rest.len());
    match rest[..end].rfind('@') {
        Some(at) => format!("{scheme}://(hidden){}", &rest[at..]),
        None => text.to_owned(),
    }
}

/// This machine's host name as a Sparkplug id, else `cellbus`.
pub fn default_edge_node_id() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .map(|h| h.trim().to_owned())
        .filter(|h| sparkplug::Id::new(h.as_str()).is_ok())
        .unwrap_or_else(|| "cellbus".to_owned())
}

/// One physical line (a serial port, a serial server's TCP port).
#[derive(Debug, Clone, PartialEq)]
pub struct LineConfig {
    /// Its name (`bench-a`), unique.
    pub name: String,
    /// Where it is.
    pub endpoint: Endpoint,
    /// The devices on it, polled in turn.
    pub devices: Vec<DeviceConfig>,
    /// Close and reopen the line when every device on it has timed out this many times in
    /// a row (0: never).
    pub reopen_after_timeouts: u32,
}

/// One device on a line.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceConfig {
    /// What its driver needs.
    pub driver: DriverConfig,
    /// Words for people (`Rework station 1`).
    pub name: String,
    /// Period for every group not named in `groups`.
    pub period: Option<Duration>,
    /// Periods of named poll groups.
    pub groups: BTreeMap<String, Duration>,
    /// Deadband of its numeric points that name none of their own (`deadband` or
    /// `deadband_percent` in the device table).
    pub deadband: Option<Deadband>,
}

/// Why a configuration was refused.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ConfigError {
    /// The file could not be read (missing, not a file, larger than [`MAX_CONFIG`], not
    /// UTF-8).
    #[error("config {path} {why}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why, in words that follow the path (`cannot be read: …`, `is not a file`).
        why: String,
    },
    /// The file is not valid, at a place in it.
    #[error("{}", self.describe())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// Line, from 1.
        line: usize,
        /// Column, from 1.
        column: usize,
        /// What is wrong.
        message: String,
        /// The text of the line, for the caret display.
        source_line: String,
    },
    /// A register list (`registers_csv`) that is not valid, at a row (its line in the
    /// file, the header being row 1) and column.
    #[error("{}: row {row}: {message}", path.display())]
    Csv {
        /// The CSV file.
        path: PathBuf,
        /// The row (line of the file), from 1.
        row: u64,
        /// What is wrong, naming the column.
        message: String,
    },
}

impl ConfigError {
    fn describe(&self) -> String {
        match self {
            ConfigError::Read { .. } | ConfigError::Csv { .. } => self.to_string(),
            ConfigError::Invalid {
                path,
                line,
                column,
                message,
                source_line,
            } => {
                let gutter = line.to_string().len();
                format!(
                    "{}:{line}:{column}: {message}\n{:gutter$} |\n{line} | {source_line}\n{:gutter$} | {:>column$}",
                    path.display(),
                    "",
                    "",
                    "^"
                )
            }
        }
    }

    /// Where the error is: `(line, column)`, from 1.
    pub fn position(&self) -> Option<(usize, usize)> {
        match self {
            ConfigError::Invalid { line, column, .. } => Some((*line, *column)),
            ConfigError::Read { .. } | ConfigError::Csv { .. } => None,
        }
    }
}

/// Largest configuration file, or CSV register list given to `cellbus config import-csv`.
pub const MAX_CONFIG: u64 = 16 << 20;

/// Reads and checks the configuration at `path`.
pub fn check_config(path: &Path) -> Result<CellConfig, ConfigError> {
    parse_config(&read_text(path)?, path)
}

/// The text of the file at `path`: at most [`MAX_CONFIG`] bytes of UTF-8.
fn read_text(path: &Path) -> Result<String, ConfigError> {
    let unreadable = |why: String| ConfigError::Read {
        path: path.to_owned(),
        why,
    };
    read_bounded_text(path, MAX_CONFIG).map_err(unreadable)
}

/// toml's message, in words where it speaks of Rust's types: a whole number beyond 64 bits
/// is "invalid type: integer `…` as i128, expected any value".
fn plain_toml_message(message: &str) -> String {
    let message = message.trim_end();
    message
        .strip_prefix("invalid type: integer `")
        .and_then(|rest| rest.split_once("` as i128"))
        .map_or_else(
            || message.to_owned(),
            |(number, _)| {
                format!(
                    "{number} is too large: no number in the configuration is beyond {}",
                    i64::MAX
                )
            },
        )
}

/// Device ids the gateway's own objects use: the OPC UA node ids of the `Cell` folder and
/// the `Gateway` object, and the source of the gateway's own events.
pub const RESERVED_DEVICE_IDS: [&str; 2] = ["cell", "gateway"];

/// Checks configuration text; `path` names it in errors.
pub fn parse_config(text: &str, path: &Path) -> Result<CellConfig, ConfigError> {
    let at = |span: Range<usize>, message: String| locate(text, path, span, message);
    let raw: RawConfig = toml::from_str(text)
        .map_err(|e| at(e.span().unwrap_or(0..0), plain_toml_message(e.message())))?;
    if raw.line.is_empty() {
        return Err(at(
            0..0,
            "no [[line]]: a cell needs at least one line with a device on it (see `cellbus config example`)"
                .into(),
        ));
    }
    let mut lines = Vec::new();
    let mut line_names = HashSet::new();
    // The serial port each line holds, with the line's name: one port carries one line.
    let mut ports: HashMap<String, String> = HashMap::new();
    let mut device_ids = HashSet::new();
    let mut csv_lists = CsvRegisterLists::default();
    for line in raw.line {
        let name = line.name.get_ref();
        DeviceId::new(name).map_err(|e| {
            at(
                line.name.span(),
                format!("line name {name:?} is not valid: {}", e.rule),
            )
        })?;
        if !line_names.insert(name.clone()) {
            return Err(at(
                line.name.span(),
                format!("line name {name:?} is used twice"),
            ));
        }
        let Some(first) = line.device.first() else {
            return Err(at(
                line.name.span(),
                format!("line {name:?} has no devices; add a [[line.device]] under it"),
            ));
        };
        let protocol = protocol_of(&first.protocol).map_err(|m| at(first.protocol.span(), m))?;
        let endpoint = Endpoint::parse(line.endpoint.get_ref(), protocol.default_serial())
            .map_err(|e| at(line.endpoint.span(), e.to_string()))?;
        if let Endpoint::Tcp { port: 0, .. } = endpoint {
            return Err(at(
                line.endpoint.span(),
                "port 0 is not a port a device listens on; give the serial server's or the device's port".into(),
            ));
        }
        if let Endpoint::Serial { path, .. } = &endpoint
            && let Some(first) = ports.insert(path.clone(), name.clone())
        {
            return Err(at(
                line.endpoint.span(),
                format!(
                    "line {name:?} is on serial port {path}, as line {first:?} is: two lines on \
                     one port would interleave their requests; put the devices of both on one line"
                ),
            ));
        }
        if endpoint.is_mbap() && !matches!(protocol, Protocol::Modbus | Protocol::Cross) {
            return Err(at(
                line.endpoint.span(),
                format!(
                    "modbus-tcp:// is for Modbus devices (modbus, cross); a {} line is serial:// or tcp://",
                    protocol.as_str()
                ),
            ));
        }
        if protocol.owns_connections() && !matches!(endpoint, Endpoint::Tcp { .. }) {
            return Err(at(
                line.endpoint.span(),
                format!(
                    "a {} machine is reached over TCP: write tcp://host:{} (its Port 1)",
                    protocol.as_str(),
                    panasonic::DEFAULT_COMMAND_PORT
                ),
            ));
        }
        let mut devices = Vec::new();
        let mut addresses = HashSet::new();
        for device in line.device {
            let this = protocol_of(&device.protocol).map_err(|m| at(device.protocol.span(), m))?;
            if !this.shares_line_with(protocol) {
                return Err(at(
                    device.protocol.span(),
                    format!(
                        "line {name:?} carries {} devices; a {} device needs a line of its own",
                        protocol.as_str(),
                        this.as_str()
                    ),
                ));
            }
            let id_span = device.id.span();
            let address_span = device
                .address
                .as_ref()
                .map_or(id_span.clone(), Spanned::span);
            let device = check_device(device, this, &endpoint, path, &mut csv_lists, &at)?;
            if let Some(address) = device.driver.address
                && !addresses.insert(address)
            {
                return Err(at(
                    address_span,
                    format!(
                        "address {address} is used twice on line {name:?}: both devices would answer the same requests"
                    ),
                ));
            }
            if !device_ids.insert(device.driver.id.clone()) {
                return Err(at(
                    id_span,
                    format!("device id {:?} is used twice", device.driver.id.as_str()),
                ));
            }
            devices.push(device);
        }
        if protocol.owns_connections()
            && let Some(second) = devices.get(1)
        {
            return Err(at(
                line.name.span(),
                format!(
                    "line {name:?} has {} {} machines: each machine is its own TCP server and needs a [[line]] of its own (device {:?})",
                    devices.len(),
                    protocol.as_str(),
                    second.driver.id.as_str()
                ),
            ));
        }
        let reopen_after_timeouts = match &line.reopen_after_timeouts {
            None => DEFAULT_REOPEN_AFTER_TIMEOUTS,
            Some(k) => u32::try_from(*k.get_ref())
                .ok()
                .filter(|k| *k <= MAX_REOPEN_AFTER_TIMEOUTS)
                .ok_or_else(|| {
                    at(
                        k.span(),
                        format!(
                            "reopen_after_timeouts {} is out of range: 0 (never) to {MAX_REOPEN_AFTER_TIMEOUTS}",
                            k.get_ref()
                        ),
                    )
                })?,
        };
        lines.push(LineConfig {
            name: name.clone(),
            endpoint,
            devices,
            reopen_after_timeouts,
        });
    }
    for (key, token) in [("token", &raw.token), ("read_token", &raw.read_token)] {
        if let Some(token) = token
            && token.get_ref().trim().is_empty()
        {
            return Err(at(
                token.span(),
                format!("{key} is empty; remove it or set a secret"),
            ));
        }
        if let Some(token) = token
            && let Some(fault) = crate::write::token_fault(token.get_ref().trim())
        {
            return Err(at(token.span(), format!("{key} cannot be used: {fault}")));
        }
    }
    if let (Some(token), Some(read_token)) = (&raw.token, &raw.read_token)
        && token.get_ref().trim() == read_token.get_ref().trim()
    {
        return Err(at(
            read_token.span(),
            format!("read_token cannot be used: {}", crate::serve::SAME_TOKENS),
        ));
    }
    let mqtt = raw.mqtt.map(|m| check_mqtt(m, path, &at)).transpose()?;
    let opcua = raw.opcua.map(|o| check_opcua(o, &at)).transpose()?;
    Ok(CellConfig {
        source: Some(path.to_owned()),
        token: raw.token.map(Spanned::into_inner),
        read_token: raw.read_token.map(Spanned::into_inner),
        lines,
        mqtt,
        opcua,
    })
}

fn check_mqtt(
    raw: RawMqtt,
    path: &Path,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<MqttConfig, ConfigError> {
    let Broker { host, port, tls } =
        parse_broker(raw.broker.get_ref()).map_err(|m| at(raw.broker.span(), m))?;
    let tls = check_mqtt_tls(&raw, tls, path, at)?;
    let group_id =
        id_opt(&raw.group_id, "group_id", at)?.unwrap_or_else(|| DEFAULT_MQTT_GROUP.to_owned());
    let edge_node_id =
        id_opt(&raw.edge_node_id, "edge_node_id", at)?.unwrap_or_else(default_edge_node_id);
    let client_id = match raw.client_id {
        Some(c) if c.get_ref().trim().is_empty() => {
            return Err(at(
                c.span(),
                "client_id is empty; remove it for the default".into(),
            ));
        }
        Some(c) if c.get_ref().len() > MAX_CLIENT_ID => {
            return Err(at(
                c.span(),
                format!(
                    "client_id is {} bytes; MQTT carries at most {MAX_CLIENT_ID}",
                    c.get_ref().len()
                ),
            ));
        }
        Some(c) => c.into_inner(),
        None => format!("cellbus-{edge_node_id}"),
    };
    if let Some(env) = &raw.password_env
        && env.get_ref().trim().is_empty()
    {
        return Err(at(
            env.span(),
            "password_env is empty; name the environment variable holding the password".into(),
        ));
    }
    let keep_alive = match &raw.keep_alive {
        Some(text) => duration(
            text,
            Duration::from_secs(5),
            Duration::from_secs(3600),
            "keep_alive",
            at,
        )?,
        None => DEFAULT_MQTT_KEEP_ALIVE,
    };
    let mode = match &raw.mode {
        Some(text) => MqttMode::parse(text.get_ref()).map_err(|m| at(text.span(), m))?,
        None => MqttMode::Sparkplug,
    };
    let prefix = match &raw.prefix {
        Some(text) => {
            let p = text.get_ref().trim_end_matches('/');
            if p.is_empty() || p.contains(['+', '#', '\0']) || p.starts_with('$') {
                return Err(at(
                    text.span(),
                    format!(
                        "prefix {:?} is not a usable topic prefix; write words separated by / \
                         without +, # or a leading $",
                        text.get_ref()
                    ),
                ));
            }
            p.to_owned()
        }
        None => format!("cellbus/{edge_node_id}"),
    };
    let primary_host = id_opt(&raw.primary_host, "primary_host", at)?;
    let max_backlog = match &raw.max_backlog {
        Some(n) => bounded(n, 1..=100_000_000, "max_backlog", " stored changes", at)?,
        None => DEFAULT_MQTT_BACKLOG,
    };
    let max_command_metrics = match &raw.max_command_metrics {
        Some(n) => bounded(
            n,
            1..=10_000,
            "max_command_metrics",
            " metrics in one command",
            at,
        )?,
        None => DEFAULT_MQTT_COMMAND_METRICS,
    };
    let check_retained = match &raw.check_retained {
        Some(text) => duration(
            text,
            Duration::from_secs(10),
            Duration::from_secs(24 * 3600),
            "check_retained",
            at,
        )?,
        None => DEFAULT_MQTT_CHECK_RETAINED,
    };
    Ok(MqttConfig {
        host,
        port,
        group_id,
        edge_node_id,
        client_id,
        username: raw.username.map(Spanned::into_inner),
        password_env: raw.password_env.map(Spanned::into_inner),
        keep_alive,
        mode,
        prefix,
        commands: raw.commands.map(Spanned::into_inner).unwrap_or(false),
        primary_host,
        max_backlog,
        max_command_metrics,
        check_retained,
        tls,
    })
}

/// An optional Sparkplug id (no `/`, `+`, `#`).
fn id_opt(
    field: &Option<Spanned<String>>,
    what: &str,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<Option<String>, ConfigError> {
    field
        .as_ref()
        .map(|text| {
            sparkplug::Id::new(text.get_ref().as_str())
                .map(|_| text.get_ref().clone())
                .map_err(|e| {
                    at(
                        text.span(),
                        format!("{what} {:?} is not valid: {e}", text.get_ref()),
                    )
                })
        })
        .transpose()
}

/// The `[mqtt]` table's TLS keys, for an `mqtts://` broker (`tls`). The files are read
/// here, so `cellbus config check` reports a missing file or bad PEM; the gateway reads
/// them again when it starts.
fn check_mqtt_tls(
    raw: &RawMqtt,
    tls: bool,
    path: &Path,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<Option<MqttTls>, ConfigError> {
    let keys = [
        ("ca_file", &raw.ca_file),
        ("client_cert", &raw.client_cert),
        ("client_key", &raw.client_key),
    ];
    if !tls {
        if let Some((key, Some(value))) = keys.iter().find(|(_, v)| v.is_some()) {
            return Err(at(
                value.span(),
                format!(
                    "{key} is for TLS: the broker is mqtt://; write mqtts://host:8883 or remove {key}"
                ),
            ));
        }
        return Ok(None);
    }
    let base = path.parent().unwrap_or(Path::new(""));
    for (key, value) in keys {
        if let Some(value) = value
            && value.get_ref().trim().is_empty()
        {
            return Err(at(
                value.span(),
                format!("{key} is empty; name a PEM file or remove {key}"),
            ));
        }
    }
    let file = |value: &Spanned<String>| base.join(value.get_ref().trim());
    let client = match (&raw.client_cert, &raw.client_key) {
        (Some(cert), Some(key)) => Some(MqttClientCert {
            cert: file(cert),
            key: file(key),
        }),
        (None, None) => None,
        (Some(cert), None) => {
            return Err(at(
                cert.span(),
                "client_cert needs client_key (its private key, PEM)".into(),
            ));
        }
        (None, Some(key)) => {
            return Err(at(
                key.span(),
                "client_key needs client_cert (its certificate, PEM)".into(),
            ));
        }
    };
    let tls = MqttTls {
        ca_file: raw.ca_file.as_ref().map(file),
        client,
    };
    crate::northbound::mqtt::tls::check_files(&tls).map_err(|e| {
        let span = match e.key {
            "ca_file" => raw.ca_file.as_ref(),
            "client_cert" => raw.client_cert.as_ref(),
            "client_key" => raw.client_key.as_ref(),
            _ => None,
        }
        .map_or(raw.broker.span(), Spanned::span);
        at(span, e.message)
    })?;
    Ok(Some(tls))
}

/// Largest register list read from a CSV file.
pub const MAX_REGISTERS_CSV: u64 = 4 << 20;

/// The bytes of the regular file at `path`, refused when larger than `max` (a config that
/// names `/dev/zero` or a huge file must not hang or exhaust the gateway); the error says
/// why in words.
pub fn read_bounded(path: &Path, max: u64) -> Result<Vec<u8>, String> {
    use std::io::Read as _;
    let file = std::fs::File::open(path).map_err(|e| format!("cannot be read: {e}"))?;
    let meta = file
        .metadata()
        .map_err(|e| format!("cannot be read: {e}"))?;
    if !meta.is_file() {
        return Err("is not a file".into());
    }
    let mut bytes = Vec::new();
    file.take(max + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| format!("cannot be read: {e}"))?;
    if bytes.len() as u64 > max {
        return Err(format!("is larger than {} MiB", max >> 20));
    }
    Ok(bytes)
}

/// The text of the file at `path`, as [`read_bounded`] reads it, refused unless UTF-8.
fn read_bounded_text(path: &Path, max: u64) -> Result<String, String> {
    String::from_utf8(read_bounded(path, max)?).map_err(|e| {
        format!(
            "is not UTF-8 text (byte {} is not)",
            e.utf8_error().valid_up_to() + 1
        )
    })
}

fn protocol_of(text: &Spanned<String>) -> Result<Protocol, String> {
    Protocol::parse(text.get_ref()).ok_or_else(|| {
        format!(
            "protocol {:?} is not one the gateway speaks; known: {}",
            text.get_ref(),
            Protocol::KNOWN
        )
    })
}

fn check_device(
    raw: RawDevice,
    protocol: Protocol,
    endpoint: &Endpoint,
    path: &Path,
    csv_lists: &mut CsvRegisterLists,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<DeviceConfig, ConfigError> {
    let id = DeviceId::new(raw.id.get_ref()).map_err(|e| {
        at(
            raw.id.span(),
            format!("device id {:?} is not valid: {}", raw.id.get_ref(), e.rule),
        )
    })?;
    if RESERVED_DEVICE_IDS.contains(&id.as_str()) {
        return Err(at(
            raw.id.span(),
            format!(
                "device id {:?} is taken by the gateway's own objects (the OPC UA server's \
                 Cell folder and Gateway object, the gateway's events); choose another",
                id.as_str()
            ),
        ));
    }
    let address = match &raw.address {
        None => protocol.default_address(),
        Some(spanned) => match spanned.get_ref() {
            RawAddress::Number(n) => Some(*n),
            RawAddress::Text(t) if t == "none" => None,
            RawAddress::Text(t) => {
                return Err(at(
                    spanned.span(),
                    format!("address {t:?} is not a number; write a number or \"none\""),
                ));
            }
        },
    };
    if let Err(message) = protocol.check_address(address) {
        let span = raw.address.as_ref().map_or(raw.id.span(), Spanned::span);
        return Err(at(span, message));
    }
    let timeout = raw
        .timeout
        .as_ref()
        .map(|t| duration(t, Duration::from_millis(1), MAX_TIMEOUT, "timeout", at))
        .transpose()?;
    let retries = raw
        .retries
        .as_ref()
        .map(|r| match u8::try_from(*r.get_ref()) {
            Ok(n) if n <= MAX_RETRIES => Ok(n),
            _ => Err(at(
                r.span(),
                format!(
                    "retries {} is out of range: 0 to {MAX_RETRIES}",
                    r.get_ref()
                ),
            )),
        })
        .transpose()?;
    let period = raw
        .period
        .as_ref()
        .map(|p| duration(p, MIN_PERIOD, MAX_PERIOD, "period", at))
        .transpose()?;
    let event_port = match &raw.event_port {
        None => None,
        Some(port) if protocol != Protocol::Panasonic => {
            return Err(at(
                port.span(),
                format!(
                    "event_port is for Panasonic machines only, not {} devices",
                    protocol.as_str()
                ),
            ));
        }
        Some(port) => Some(
            u16::try_from(*port.get_ref())
                .ok()
                .filter(|&p| p != 0)
                .ok_or_else(|| {
                    at(
                        port.span(),
                        format!(
                            "event_port {} is out of range: 1 to 65535 (the machine's default is {})",
                            port.get_ref(),
                            panasonic::DEFAULT_EVENT_PORT
                        ),
                    )
                })?,
        ),
    };
    let deadband = check_deadband(&raw.deadband, &raw.deadband_percent, at)?;
    let modbus = check_modbus_options(&raw, protocol, at)?;
    let registers = check_registers(&raw, protocol, path, deadband, csv_lists, at)?;
    let driver_config = DriverConfig {
        id: id.clone(),
        protocol,
        address,
        timeout,
        retries,
        event_port,
        endpoint: (protocol.owns_connections() || endpoint.is_mbap()).then(|| endpoint.clone()),
        registers,
        modbus,
    };
    let known: Vec<String> = driver::build(&driver_config)
        .map_err(|m| at(raw.id.span(), m))?
        .groups()
        .into_iter()
        .map(|g| g.name)
        .collect();
    let mut groups = BTreeMap::new();
    for (group, text) in &raw.poll {
        if !known.contains(group) {
            return Err(at(
                text.span(),
                format!(
                    "{} devices have no poll group {group:?}; groups: {}",
                    protocol.as_str(),
                    known.join(", ")
                ),
            ));
        }
        let what = format!("poll period of {group}");
        groups.insert(
            group.clone(),
            duration(text, MIN_PERIOD, MAX_PERIOD, &what, at)?,
        );
    }
    Ok(DeviceConfig {
        name: raw.name.unwrap_or_else(|| id.to_string()),
        driver: driver_config,
        period,
        groups,
        deadband,
    })
}

/// Longest pacing delay accepted (`delay_between_requests`, `delay_after_connect`).
pub const MAX_PACING_DELAY: Duration = Duration::from_secs(60);

/// A deadband from `deadband` (absolute) or `deadband_percent`, never both.
fn check_deadband(
    absolute: &Option<Spanned<f64>>,
    percent: &Option<Spanned<f64>>,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<Option<Deadband>, ConfigError> {
    match (absolute, percent) {
        (Some(_), Some(p)) => Err(at(
            p.span(),
            "deadband and deadband_percent both given: choose one".into(),
        )),
        (Some(d), None) => {
            let band = *d.get_ref();
            if band.is_finite() && band >= 0.0 {
                Ok(Some(Deadband::Absolute(band)))
            } else {
                Err(at(
                    d.span(),
                    format!("deadband {band} must be a number of at least 0 (in the point's unit)"),
                ))
            }
        }
        (None, Some(p)) => {
            let percent = *p.get_ref();
            if percent > 0.0 && percent <= 100.0 {
                Ok(Some(Deadband::Percent(percent)))
            } else {
                Err(at(
                    p.span(),
                    format!("deadband_percent {percent} is out of range: above 0, at most 100"),
                ))
            }
        }
        (None, None) => Ok(None),
    }
}

/// The device-level Modbus settings: request sizes and pacing.
fn check_modbus_options(
    raw: &RawDevice,
    protocol: Protocol,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<ModbusOptions, ConfigError> {
    let spans = [
        (
            "max_registers_per_request",
            raw.max_registers_per_request.as_ref().map(Spanned::span),
        ),
        (
            "max_bits_per_request",
            raw.max_bits_per_request.as_ref().map(Spanned::span),
        ),
        (
            "one_request_per_register",
            raw.one_request_per_register.as_ref().map(Spanned::span),
        ),
        (
            "delay_between_requests",
            raw.delay_between_requests.as_ref().map(Spanned::span),
        ),
        (
            "delay_after_connect",
            raw.delay_after_connect.as_ref().map(Spanned::span),
        ),
        (
            "registers_csv",
            raw.registers_csv.as_ref().map(Spanned::span),
        ),
    ];
    if protocol != Protocol::Modbus {
        if let Some((field, Some(span))) = spans.into_iter().find(|(_, span)| span.is_some()) {
            return Err(at(
                span,
                format!(
                    "{field} is for modbus devices only, not {} devices",
                    protocol.as_str()
                ),
            ));
        }
        return Ok(ModbusOptions::default());
    }
    let mut options = ModbusOptions::default();
    if let Some(n) = &raw.max_registers_per_request {
        options.plan.max_registers = u16::try_from(*n.get_ref())
            .ok()
            .and_then(|n| ReadRegisterCount::new(n).ok())
            .ok_or_else(|| {
                at(
                    n.span(),
                    format!(
                        "max_registers_per_request {} is out of range: 1 to {}",
                        n.get_ref(),
                        ReadRegisterCount::MAX
                    ),
                )
            })?;
    }
    if let Some(n) = &raw.max_bits_per_request {
        options.plan.max_bits = u16::try_from(*n.get_ref())
            .ok()
            .and_then(|n| ReadBitCount::new(n).ok())
            .ok_or_else(|| {
                at(
                    n.span(),
                    format!(
                        "max_bits_per_request {} is out of range: 1 to {}",
                        n.get_ref(),
                        ReadBitCount::MAX
                    ),
                )
            })?;
    }
    if let Some(one) = &raw.one_request_per_register {
        options.plan.one_request_per_item = *one.get_ref();
    }
    if let Some(d) = &raw.delay_between_requests {
        options.delay_between_requests = duration(
            d,
            Duration::ZERO,
            MAX_PACING_DELAY,
            "delay_between_requests",
            at,
        )?;
    }
    if let Some(d) = &raw.delay_after_connect {
        options.delay_after_connect = duration(
            d,
            Duration::ZERO,
            MAX_PACING_DELAY,
            "delay_after_connect",
            at,
        )?;
    }
    Ok(options)
}

/// The register lists read from `registers_csv` files so far, by file and the device's
/// deadband (which the registers take): a thousand meters naming one file share one list
/// (each parsing its own copy was two thirds of the heap with 100 registers a meter).
#[derive(Default)]
struct CsvRegisterLists(HashMap<(PathBuf, String), RegisterList>);

/// The registers of a generic Modbus device: its `[[line.device.register]]` tables, or
/// the rows of its `registers_csv` file (relative to the config file's directory), read
/// once for every device that names it with the same deadband.
fn check_registers(
    raw: &RawDevice,
    protocol: Protocol,
    path: &Path,
    deadband: Option<Deadband>,
    csv_lists: &mut CsvRegisterLists,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<RegisterList, ConfigError> {
    if protocol != Protocol::Modbus {
        return match raw.register.first() {
            Some(first) => Err(at(
                first.name.span(),
                format!(
                    "registers are named for modbus devices only; {} devices have their points built in",
                    protocol.as_str()
                ),
            )),
            None => Ok(RegisterList::default()),
        };
    }
    match (&raw.registers_csv, raw.register.first()) {
        (Some(csv), Some(_)) => Err(at(
            csv.span(),
            "registers_csv and [[line.device.register]] tables both given: name the registers in one place"
                .into(),
        )),
        (Some(csv), None) => {
            let file = path
                .parent()
                .unwrap_or_else(|| Path::new(""))
                .join(csv.get_ref().trim());
            let key = (file.clone(), format!("{deadband:?}"));
            if let Some(list) = csv_lists.0.get(&key) {
                return Ok(list.clone());
            }
            let text = read_bounded_text(&file, MAX_REGISTERS_CSV).map_err(|why| {
                    at(
                        csv.span(),
                        format!("registers_csv {}: {why}", file.display()),
                    )
                })?;
            let table = register_csv::CsvRegisters::parse(&text, &file)?;
            if table.rows.is_empty() {
                return Err(at(
                    csv.span(),
                    format!(
                        "registers_csv {} names no registers, only its header: a modbus \
                         device needs at least one",
                        file.display()
                    ),
                ));
            }
            let list = RegisterList::from(check_register_list(
                &table.rows,
                deadband,
                &|span, message| table.error(span, message),
            )?);
            csv_lists.0.insert(key, list.clone());
            Ok(list)
        }
        (None, Some(_)) => check_register_list(&raw.register, deadband, at).map(Into::into),
        (None, None) => Err(at(
            raw.id.span(),
            "a modbus device needs its registers: add [[line.device.register]] tables with name and address, or registers_csv"
                .into(),
        )),
    }
}

/// The registers of a CSV register list (`cellbus config import-csv`), checked as a
/// device's would be.
pub fn registers_from_csv(file: &Path) -> Result<Vec<RegisterConfig>, ConfigError> {
    let text = read_text(file)?;
    let table = register_csv::CsvRegisters::parse(&text, file)?;
    check_register_list(&table.rows, None, &|span, message| {
        table.error(span, message)
    })
}

/// `registers` as `[[line.device.register]]` tables (defaults left out).
pub fn registers_toml(registers: &[RegisterConfig]) -> String {
    register_csv::to_toml(registers)
}

/// Most pairs of registers [`overlapping_registers`] names for one list.
pub const MAX_OVERLAPS_NAMED: usize = 20;

/// Registers of one list that share a register (a `float32` at 100 and another at 101),
/// one sentence per pair, in address order: how an address off by one shows. The file is
/// still valid (reading a `uint32` and its low word apart can be meant), so these are
/// warnings. Bits (`bit:N`, coils, discrete inputs) are left out: several of one
/// register is what they are for. At most [`MAX_OVERLAPS_NAMED`] pairs are named, then
/// one sentence says there are more (a list of thousands at one address stays quick).
pub fn overlapping_registers(registers: &[RegisterConfig]) -> Vec<String> {
    let mut words: Vec<&RegisterConfig> = registers.iter().filter(|r| !r.is_bool()).collect();
    words.sort_by_key(|r| (r.table, r.address));
    let end = |r: &RegisterConfig| u32::from(r.address) + u32::from(r.length());
    let span = |r: &RegisterConfig| match r.length() {
        1 => format!("{} {}", r.table.as_str(), r.address),
        _ => format!("{} {}–{}", r.table.as_str(), r.address, end(r) - 1),
    };
    let mut found = Vec::new();
    for (i, a) in words.iter().enumerate() {
        let later = words[i + 1..]
            .iter()
            .take_while(|b| b.table == a.table && u32::from(b.address) < end(a));
        for b in later {
            if found.len() == MAX_OVERLAPS_NAMED {
                found.push(format!(
                    "more registers share a register (the first {MAX_OVERLAPS_NAMED} pairs \
                     are named)"
                ));
                return found;
            }
            let shared_end = end(a).min(end(b)) - 1;
            let shared = if shared_end == u32::from(b.address) {
                format!("register {}", b.address)
            } else {
                format!("registers {}–{shared_end}", b.address)
            };
            found.push(format!(
                "registers {:?} ({}) and {:?} ({}) share {} {shared}",
                a.name,
                span(a),
                b.name,
                span(b),
                a.table.as_str()
            ));
        }
    }
    found
}

impl CellConfig {
    /// What the file allows but is likely a mistake, one sentence each, naming the device:
    /// Modbus registers that share a register ([`overlapping_registers`]). Devices with
    /// the same register list (one `registers_csv`) are named once, with how many more.
    pub fn warnings(&self) -> Vec<String> {
        let mut lists: Vec<(&DriverConfig, usize)> = Vec::new();
        for device in self.lines.iter().flat_map(|line| &line.devices) {
            let driver = &device.driver;
            if driver.registers.is_empty() {
                continue;
            }
            match lists
                .iter_mut()
                .find(|(first, _)| first.registers == driver.registers)
            {
                Some((_, more)) => *more += 1,
                None => lists.push((driver, 0)),
            }
        }
        let mut warnings = Vec::new();
        for (driver, more) in lists {
            let who = match more {
                0 => format!("device {:?}", driver.id.as_str()),
                n => format!(
                    "device {:?} (and {n} more with the same registers)",
                    driver.id.as_str()
                ),
            };
            for overlap in overlapping_registers(&driver.registers) {
                warnings.push(format!("{who}: {overlap}"));
            }
        }
        warnings
    }
}

fn check_register_list(
    raw: &[RawRegister],
    deadband: Option<Deadband>,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<Vec<RegisterConfig>, ConfigError> {
    let mut names = HashSet::new();
    let mut registers = Vec::new();
    for r in raw {
        let name = r.name.get_ref();
        if !names.insert(name.clone()) {
            return Err(at(
                r.name.span(),
                format!("register name {name:?} is used twice"),
            ));
        }
        registers.push(check_register(r, deadband, at)?);
    }
    Ok(registers)
}

/// One register, with `deadband` (the device's) when it names none.
fn check_register(
    r: &RawRegister,
    deadband: Option<Deadband>,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<RegisterConfig, ConfigError> {
    let name = r.name.get_ref();
    DeviceId::new(name).map_err(|e| {
        at(
            r.name.span(),
            format!("register name {name:?} is not valid: {}", e.rule),
        )
    })?;
    let address = u16::try_from(*r.address.get_ref()).map_err(|_| {
        at(
            r.address.span(),
            format!(
                "register {name}: address {} is out of range: 0 to 65535",
                r.address.get_ref()
            ),
        )
    })?;
    let table = match &r.table {
        None => RegisterTable::Holding,
        Some(t) => RegisterTable::parse(t.get_ref()).ok_or_else(|| {
            at(
                t.span(),
                format!(
                    "register {name}: table {:?} is not one a register can be in: write {}",
                    t.get_ref(),
                    RegisterTable::CHOICES
                ),
            )
        })?,
    };
    if table.holds_bits() {
        let word_fields = [
            ("type", r.data_type.as_ref().map(Spanned::span)),
            ("order", r.order.as_ref().map(Spanned::span)),
            ("scale", r.scale.as_ref().map(Spanned::span)),
            ("offset", r.offset.as_ref().map(Spanned::span)),
            ("signed", r.signed.as_ref().map(Spanned::span)),
        ];
        if let Some((field, Some(span))) = word_fields.into_iter().find(|(_, s)| s.is_some()) {
            return Err(at(
                span,
                format!(
                    "register {name}: {field} is for holding and input registers; a {} is a single bit (off or on)",
                    table.as_str()
                ),
            ));
        }
    }
    let data_type = match (&r.data_type, &r.signed) {
        (Some(_), Some(signed)) => {
            return Err(at(
                signed.span(),
                format!(
                    "register {name}: signed is the old way of saying type = \"int16\"; give type only"
                ),
            ));
        }
        (Some(t), None) => t
            .get_ref()
            .trim()
            .parse::<DataType>()
            .map_err(|e| at(t.span(), format!("register {name}: {e}")))?,
        (None, Some(signed)) if *signed.get_ref() => DataType::Int16,
        (None, _) => DataType::Uint16,
    };
    let order = match &r.order {
        None => Order::default(),
        Some(o) => o
            .get_ref()
            .parse::<Order>()
            .map_err(|e| at(o.span(), format!("register {name}: {e}")))?,
    };
    if !data_type.is_number() {
        for (field, value) in [("scale", &r.scale), ("offset", &r.offset)] {
            if let Some(v) = value {
                return Err(at(
                    v.span(),
                    format!(
                        "register {name}: {field} is for numbers; a {data_type} register is not one"
                    ),
                ));
            }
        }
    }
    let scale = match &r.scale {
        None => 1.0,
        Some(s) if s.get_ref().is_finite() && *s.get_ref() > 0.0 => *s.get_ref(),
        Some(s) => {
            return Err(at(
                s.span(),
                format!(
                    "register {name}: scale {} must be a number above 0",
                    s.get_ref()
                ),
            ));
        }
    };
    let offset = match &r.offset {
        None => 0.0,
        Some(o) if o.get_ref().is_finite() => *o.get_ref(),
        Some(o) => {
            return Err(at(
                o.span(),
                format!("register {name}: offset {} must be a number", o.get_ref()),
            ));
        }
    };
    let scaling = Scaling::new(scale, offset).map_err(|e| {
        let span = r.scale.as_ref().map_or(r.name.span(), Spanned::span);
        at(span, format!("register {name}: {e}"))
    })?;
    let own_deadband = check_deadband(&r.deadband, &r.deadband_percent, at)?;
    let mut register = RegisterConfig {
        name: name.clone(),
        title: r.title.clone().unwrap_or_else(|| name.clone()),
        table,
        address,
        format: Format::new(data_type, order).scaled(scaling),
        unit: r.unit.clone(),
        writable: None,
        deadband: None,
    };
    if u32::from(address) + u32::from(register.length()) > 0x1_0000 {
        return Err(at(
            r.address.span(),
            format!("register {name}: a {data_type} at {address} runs past the last address 65535"),
        ));
    }
    if own_deadband.is_some() && !register.is_numeric() {
        let span = r
            .deadband
            .as_ref()
            .or(r.deadband_percent.as_ref())
            .map_or(r.name.span(), Spanned::span);
        return Err(at(
            span,
            format!("register {name}: a deadband is for numbers; this register is not one"),
        ));
    }
    register.deadband = if register.is_numeric() {
        own_deadband.or(deadband)
    } else {
        None
    };
    if let Some(w) = &r.writable {
        register.writable = check_writable(&register, w, at)?;
    }
    Ok(register)
}

/// The write range of a register: coils are on/off, holding registers of any number type
/// take a range within what they hold.
fn check_writable(
    register: &RegisterConfig,
    w: &Spanned<RawWritable>,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<Option<(f64, f64)>, ConfigError> {
    let name = &register.name;
    match register.table {
        RegisterTable::Input | RegisterTable::Discrete => {
            return Err(at(
                w.span(),
                format!(
                    "register {name}: only holding registers and coils can be written; {} are read-only",
                    register.table.table()
                ),
            ));
        }
        RegisterTable::Holding if !register.is_numeric() => {
            return Err(at(
                w.span(),
                format!(
                    "register {name}: a {} register is read-only here; numbers and coils can be written",
                    register.format.data_type
                ),
            ));
        }
        _ => {}
    }
    let (low, high) = register.representable();
    match w.get_ref() {
        RawWritable::Flag(false) => Ok(None),
        RawWritable::Flag(true) => Ok(Some((low, high))),
        RawWritable::Range(range) => {
            if range.min < range.max && range.min >= low && range.max <= high {
                Ok(Some(if register.is_bool() {
                    (0.0, 1.0)
                } else {
                    (range.min, range.max)
                }))
            } else {
                Err(at(
                    w.span(),
                    format!(
                        "register {name}: writable range {} to {} must be increasing and within what the register holds ({low} to {high})",
                        range.min, range.max
                    ),
                ))
            }
        }
    }
}

/// An integer key within `range`, or an error at its place:
/// `{what} {n} is outside {min}–{max}{unit}`.
fn bounded<T>(
    n: &Spanned<i64>,
    range: RangeInclusive<T>,
    what: &str,
    unit: &str,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<T, ConfigError>
where
    T: TryFrom<i64> + PartialOrd + fmt::Display,
{
    T::try_from(*n.get_ref())
        .ok()
        .filter(|value| range.contains(value))
        .ok_or_else(|| {
            at(
                n.span(),
                format!(
                    "{what} {} is outside {}–{}{unit}",
                    n.get_ref(),
                    range.start(),
                    range.end()
                ),
            )
        })
}

fn duration(
    text: &Spanned<String>,
    min: Duration,
    max: Duration,
    what: &str,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<Duration, ConfigError> {
    let d = humantime::parse_duration(text.get_ref().trim()).map_err(|e| {
        at(
            text.span(),
            format!(
                "{what} {:?} is not a duration ({e}); write e.g. 500ms, 2s or 5m",
                text.get_ref()
            ),
        )
    })?;
    if d < min || d > max {
        return Err(at(
            text.span(),
            format!(
                "{what} {} is out of range: {} to {}",
                humantime::format_duration(d),
                humantime::format_duration(min),
                humantime::format_duration(max)
            ),
        ));
    }
    Ok(d)
}

/// An error at a byte range of the text.
fn locate(text: &str, path: &Path, span: Range<usize>, message: String) -> ConfigError {
    let start = span.start.min(text.len());
    let before = text.get(..start).unwrap_or("");
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let column = text
        .get(line_start..start)
        .map_or(1, |s| s.chars().count() + 1);
    let source_line = hide_secret(
        text.get(line_start..)
            .and_then(|rest| rest.lines().next())
            .unwrap_or(""),
    );
    ConfigError::Invalid {
        path: path.to_owned(),
        line,
        column,
        message,
        source_line,
    }
}

/// The line as shown under an error, with the value of a secret (`token = …`,
/// `password = …`) hidden: error messages end up in logs and support tickets.
fn hide_secret(line: &str) -> String {
    let Some((key, _)) = line.split_once('=') else {
        return line.to_owned();
    };
    let name = key.trim().trim_matches(['"', '\'']).to_ascii_lowercase();
    if ["token", "password", "secret"]
        .iter()
        .any(|word| name.contains(word))
    {
        format!("{key}= \"(hidden)\"")
    } else if let Some((key, value)) = line.split_once('=') {
        // A URL's user name and password (`broker = "mqtt://user:pw@host"`).
        format!("{key}={}", hide_userinfo(value))
    } else {
        line.to_owned()
    }
}

impl fmt::Display for LineConfig {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} ({})", self.name, self.endpoint)
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    token: Option<Spanned<String>>,
    read_token: Option<Spanned<String>>,
    #[serde(default)]
    line: Vec<RawLine>,
    mqtt: Option<RawMqtt>,
    opcua: Option<RawOpcua>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMqtt {
    broker: Spanned<String>,
    group_id: Option<Spanned<String>>,
    edge_node_id: Option<Spanned<String>>,
    client_id: Option<Spanned<String>>,
    username: Option<Spanned<String>>,
    password_env: Option<Spanned<String>>,
    keep_alive: Option<Spanned<String>>,
    mode: Option<Spanned<String>>,
    prefix: Option<Spanned<String>>,
    commands: Option<Spanned<bool>>,
    primary_host: Option<Spanned<String>>,
    max_backlog: Option<Spanned<i64>>,
    max_command_metrics: Option<Spanned<i64>>,
    check_retained: Option<Spanned<String>>,
    ca_file: Option<Spanned<String>>,
    client_cert: Option<Spanned<String>>,
    client_key: Option<Spanned<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLine {
    name: Spanned<String>,
    endpoint: Spanned<String>,
    reopen_after_timeouts: Option<Spanned<i64>>,
    #[serde(default)]
    device: Vec<RawDevice>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDevice {
    id: Spanned<String>,
    name: Option<String>,
    protocol: Spanned<String>,
    address: Option<Spanned<RawAddress>>,
    timeout: Option<Spanned<String>>,
    retries: Option<Spanned<i64>>,
    period: Option<Spanned<String>>,
    #[serde(default)]
    poll: BTreeMap<String, Spanned<String>>,
    event_port: Option<Spanned<i64>>,
    deadband: Option<Spanned<f64>>,
    deadband_percent: Option<Spanned<f64>>,
    max_registers_per_request: Option<Spanned<i64>>,
    max_bits_per_request: Option<Spanned<i64>>,
    one_request_per_register: Option<Spanned<bool>>,
    delay_between_requests: Option<Spanned<String>>,
    delay_after_connect: Option<Spanned<String>>,
    registers_csv: Option<Spanned<String>>,
    #[serde(default)]
    register: Vec<RawRegister>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRegister {
    name: Spanned<String>,
    title: Option<String>,
    table: Option<Spanned<String>>,
    address: Spanned<i64>,
    #[serde(rename = "type")]
    data_type: Option<Spanned<String>>,
    order: Option<Spanned<String>>,
    scale: Option<Spanned<f64>>,
    offset: Option<Spanned<f64>>,
    unit: Option<String>,
    signed: Option<Spanned<bool>>,
    writable: Option<Spanned<RawWritable>>,
    deadband: Option<Spanned<f64>>,
    deadband_percent: Option<Spanned<f64>>,
}

/// `writable = true`, or `writable = { min = …, max = … }`.
#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum RawWritable {
    Flag(bool),
    Range(RawRange),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRange {
    min: f64,
    max: f64,
}

#[derive(Debug, Deserialize)]
#[serde(
    untagged,
    expecting = "the address must be a whole number (see the protocol's range) or \"none\""
)]
enum RawAddress {
    Number(i64),
    Text(String),
}

// ----- [opcua]: the OPC UA server (northbound::opcua) -----

/// Where the OPC UA server listens by default: loopback only.
pub const DEFAULT_OPCUA_ENDPOINT: &str = "opc.tcp://127.0.0.1:4840";
/// The OPC UA application name by default.
pub const DEFAULT_OPCUA_APPLICATION_NAME: &str = "cellbus";
/// How long a client has by default to activate the session it created: clients activate
/// at once (milliseconds later); a session never activated holds one of the server's
/// session slots for nothing.
pub const DEFAULT_OPCUA_ACTIVATION_TIMEOUT: Duration = Duration::from_secs(5);
/// The longest session timeout granted by default: a client that vanishes (cable pulled)
/// holds its session and its subscriptions this long at most; clients keep a session alive
/// with their publish requests or reads well within a minute.
pub const DEFAULT_OPCUA_SESSION_TIMEOUT: Duration = Duration::from_secs(60);
/// Sessions at once from one IP address by default: a SCADA, an HMI and an engineering
/// tool on one computer need a few; ten leave room and keep one computer from taking the
/// server's 100.
pub const DEFAULT_OPCUA_SESSIONS_PER_ADDRESS: usize = 10;
/// Monitored items at once by default, all sessions and nodes together: ten clients
/// watching 10,000 points each, about 135 MB of the server's memory (1.35 kB an item).
pub const DEFAULT_OPCUA_MAX_MONITORED_ITEMS: u64 = 100_000;

/// The `[opcua]` table: the OPC UA server, its security and its users.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OpcuaConfig {
    /// The host of the endpoint URL (and the address bound).
    pub host: String,
    /// The port (0: any free port).
    pub port: u16,
    /// The application's name (also the certificate's common name).
    pub application_name: String,
    /// The application's URI (in its certificate).
    pub application_uri: String,
    /// The endpoints offered: security policy and mode, in the file's order.
    pub security: Vec<OpcuaSecurity>,
    /// Whether anonymous sessions (read-only) are allowed; `None`: only while writes are off.
    pub anonymous: Option<bool>,
    /// Whether every client certificate is trusted (tests only); else the client's
    /// certificate must be in `<data>/opcua/pki/trusted` (rejected ones land in
    /// `<data>/opcua/pki/rejected`).
    pub trust_all_clients: bool,
    /// Who may log in with a user name and password.
    pub users: Vec<OpcuaUser>,
    /// How long a client has to activate the session it created before the gateway closes
    /// it (`activation_timeout`).
    pub activation_timeout: Duration,
    /// The longest session timeout granted (`session_timeout`): a session without a
    /// request for this long is closed.
    pub session_timeout: Duration,
    /// Sessions at once from one IP address (`sessions_per_address`).
    pub sessions_per_address: usize,
    /// Monitored items at once, all sessions and nodes together (`max_monitored_items`).
    pub max_monitored_items: u64,
}

/// One endpoint's security: a policy and a message mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct OpcuaSecurity {
    /// The security policy.
    pub policy: OpcuaPolicy,
    /// Signed, or signed and encrypted (`None` only with the policy `None`).
    pub mode: OpcuaMode,
}

/// An OPC UA security policy the server offers (the deprecated Basic128Rsa15 and Basic256
/// are not).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum OpcuaPolicy {
    /// No security: plain text, no client certificate; only when the config says so.
    None,
    /// Basic256Sha256.
    Basic256Sha256,
    /// Aes128_Sha256_RsaOaep.
    Aes128Sha256RsaOaep,
    /// Aes256_Sha256_RsaPss.
    Aes256Sha256RsaPss,
}

/// An OPC UA message security mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum OpcuaMode {
    /// Plain (policy `None` only).
    None,
    /// Signed.
    Sign,
    /// Signed and encrypted.
    SignAndEncrypt,
}

/// A user of the OPC UA server.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OpcuaUser {
    /// The user name.
    pub name: String,
    /// The environment variable holding the password (never the password itself).
    pub password_env: String,
    /// Whether the user may write (with `--allow-writes`).
    pub write: bool,
}

impl OpcuaSecurity {
    /// The default endpoints: Basic256Sha256, signed and signed and encrypted.
    pub const DEFAULT: [OpcuaSecurity; 2] = [
        OpcuaSecurity {
            policy: OpcuaPolicy::Basic256Sha256,
            mode: OpcuaMode::Sign,
        },
        OpcuaSecurity {
            policy: OpcuaPolicy::Basic256Sha256,
            mode: OpcuaMode::SignAndEncrypt,
        },
    ];

    /// No security.
    pub const NONE: OpcuaSecurity = OpcuaSecurity {
        policy: OpcuaPolicy::None,
        mode: OpcuaMode::None,
    };

    /// Reads `None`, or a policy and a mode: `Basic256Sha256 SignAndEncrypt`.
    pub fn parse(text: &str) -> Result<Self, String> {
        let words: Vec<&str> = text.split_whitespace().collect();
        let policy = |word: &str| match word.to_ascii_lowercase().replace('_', "").as_str() {
            "none" => Some(OpcuaPolicy::None),
            "basic256sha256" => Some(OpcuaPolicy::Basic256Sha256),
            "aes128sha256rsaoaep" => Some(OpcuaPolicy::Aes128Sha256RsaOaep),
            "aes256sha256rsapss" => Some(OpcuaPolicy::Aes256Sha256RsaPss),
            _ => None,
        };
        let mode = |word: &str| match word.to_ascii_lowercase().as_str() {
            "sign" => Some(OpcuaMode::Sign),
            "signandencrypt" => Some(OpcuaMode::SignAndEncrypt),
            _ => None,
        };
        let hint = "write \"None\" or a policy and a mode: \"Basic256Sha256 SignAndEncrypt\", \
                    \"Basic256Sha256 Sign\" (policies: Basic256Sha256, Aes128Sha256RsaOaep, \
                    Aes256Sha256RsaPss)";
        match words.as_slice() {
            [word] if policy(word) == Some(OpcuaPolicy::None) => Ok(Self::NONE),
            [p, m] => match (policy(p), mode(m)) {
                (Some(OpcuaPolicy::None), _) => Err(format!(
                    "security {text:?}: None has no mode; write \"None\""
                )),
                (Some(policy), Some(mode)) => Ok(Self { policy, mode }),
                _ => Err(format!("security {text:?} is not known; {hint}")),
            },
            _ => Err(format!("security {text:?} is not known; {hint}")),
        }
    }
}

impl fmt::Display for OpcuaSecurity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let policy = match self.policy {
            OpcuaPolicy::None => return f.write_str("None"),
            OpcuaPolicy::Basic256Sha256 => "Basic256Sha256",
            OpcuaPolicy::Aes128Sha256RsaOaep => "Aes128Sha256RsaOaep",
            OpcuaPolicy::Aes256Sha256RsaPss => "Aes256Sha256RsaPss",
        };
        let mode = match self.mode {
            OpcuaMode::None => "None",
            OpcuaMode::Sign => "Sign",
            OpcuaMode::SignAndEncrypt => "SignAndEncrypt",
        };
        write!(f, "{policy} {mode}")
    }
}

impl OpcuaConfig {
    /// A server at `host:port` with the defaults: Basic256Sha256 Sign and SignAndEncrypt,
    /// no users, anonymous reading while writes are off.
    pub fn at(host: &str, port: u16) -> Self {
        let application_name = DEFAULT_OPCUA_APPLICATION_NAME.to_owned();
        Self {
            host: host.to_owned(),
            port,
            application_uri: default_application_uri(&application_name),
            application_name,
            security: OpcuaSecurity::DEFAULT.to_vec(),
            anonymous: None,
            trust_all_clients: false,
            users: Vec::new(),
            activation_timeout: DEFAULT_OPCUA_ACTIVATION_TIMEOUT,
            session_timeout: DEFAULT_OPCUA_SESSION_TIMEOUT,
            sessions_per_address: DEFAULT_OPCUA_SESSIONS_PER_ADDRESS,
            max_monitored_items: DEFAULT_OPCUA_MAX_MONITORED_ITEMS,
        }
    }

    /// The endpoint URL (`opc.tcp://host:port`).
    pub fn endpoint(&self) -> String {
        format!("opc.tcp://{}:{}", url_host(&self.host), self.port)
    }
}

/// Reads `opc.tcp://host[:port]` (port 4840 by default) into host and port.
pub fn parse_opcua_endpoint(text: &str) -> Result<(String, u16), String> {
    let url = url::Url::parse(text.trim()).map_err(|e| {
        format!("endpoint {text:?} is not a URL ({e}); write opc.tcp://127.0.0.1:4840")
    })?;
    if url.scheme() != "opc.tcp" {
        return Err(format!(
            "endpoint {text:?} has scheme {:?}; write opc.tcp://host:4840",
            url.scheme()
        ));
    }
    let host = url
        .host_str()
        .ok_or_else(|| format!("endpoint {text:?} names no host; write opc.tcp://host:4840"))?;
    if !matches!(url.path(), "" | "/") || url.query().is_some() || !url.username().is_empty() {
        return Err(format!(
            "endpoint {text:?}: write only opc.tcp://host:port (no path, query or user)"
        ));
    }
    let host = host
        .trim_start_matches('[')
        .trim_end_matches(']')
        .to_owned();
    Ok((host, url.port().unwrap_or(4840)))
}

fn url_host(host: &str) -> String {
    if host.contains(':') {
        format!("[{host}]")
    } else {
        host.to_owned()
    }
}

/// `urn:cellbus:<host name>:<application name>`.
fn default_application_uri(application_name: &str) -> String {
    format!("urn:{}:{application_name}", default_edge_node_id())
}

fn check_opcua(
    raw: RawOpcua,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<OpcuaConfig, ConfigError> {
    let (host, port) = match &raw.endpoint {
        Some(text) => parse_opcua_endpoint(text.get_ref()).map_err(|m| at(text.span(), m))?,
        None => parse_opcua_endpoint(DEFAULT_OPCUA_ENDPOINT)
            .expect("the default OPC UA endpoint is a valid URL"),
    };
    let nonempty = |field: &Option<Spanned<String>>, key: &str| match field {
        Some(text) if text.get_ref().trim().is_empty() => Err(at(
            text.span(),
            format!("{key} is empty; remove it for the default"),
        )),
        Some(text) => Ok(Some(text.get_ref().trim().to_owned())),
        None => Ok(None),
    };
    let application_name = nonempty(&raw.application_name, "application_name")?
        .unwrap_or_else(|| DEFAULT_OPCUA_APPLICATION_NAME.to_owned());
    let application_uri = match nonempty(&raw.application_uri, "application_uri")? {
        Some(uri) if !uri.contains(':') => {
            let span = raw.application_uri.as_ref().map_or(0..0, Spanned::span);
            return Err(at(
                span,
                format!("application_uri {uri:?} is not a URI; write urn:plant:cellbus"),
            ));
        }
        Some(uri) => uri,
        None => default_application_uri(&application_name),
    };
    let security = match &raw.security {
        None => OpcuaSecurity::DEFAULT.to_vec(),
        Some(list) if list.get_ref().is_empty() => {
            return Err(at(
                list.span(),
                "security is empty: the server would offer no endpoint; remove it for \
                 Basic256Sha256 Sign and SignAndEncrypt"
                    .into(),
            ));
        }
        Some(list) => {
            let mut seen = HashSet::new();
            let mut security = Vec::new();
            for text in list.get_ref() {
                let s = OpcuaSecurity::parse(text.get_ref()).map_err(|m| at(text.span(), m))?;
                if !seen.insert(s) {
                    return Err(at(text.span(), format!("security {s} is listed twice")));
                }
                security.push(s);
            }
            security
        }
    };
    let mut users = Vec::new();
    let mut names = HashSet::new();
    for user in raw.user {
        let name = user.name.get_ref().trim();
        if name.is_empty() {
            return Err(at(user.name.span(), "the user name is empty".into()));
        }
        if !names.insert(name.to_owned()) {
            return Err(at(
                user.name.span(),
                format!("user {name:?} is listed twice"),
            ));
        }
        let env = user.password_env.get_ref().trim();
        if env.is_empty() {
            return Err(at(
                user.password_env.span(),
                "password_env is empty; name the environment variable holding the password".into(),
            ));
        }
        if !security.iter().any(|s| s.policy != OpcuaPolicy::None) {
            return Err(at(
                user.name.span(),
                "users log in only on a secure endpoint (their passwords would cross the \
                 network in clear); add \"Basic256Sha256 SignAndEncrypt\" to security"
                    .into(),
            ));
        }
        users.push(OpcuaUser {
            name: name.to_owned(),
            password_env: env.to_owned(),
            write: user.write.map(Spanned::into_inner).unwrap_or(false),
        });
    }
    let activation_timeout = match &raw.activation_timeout {
        Some(text) => duration(
            text,
            Duration::from_secs(1),
            Duration::from_secs(60),
            "activation_timeout",
            at,
        )?,
        None => DEFAULT_OPCUA_ACTIVATION_TIMEOUT,
    };
    let session_timeout = match &raw.session_timeout {
        Some(text) => duration(
            text,
            Duration::from_secs(10),
            Duration::from_secs(3600),
            "session_timeout",
            at,
        )?,
        None => DEFAULT_OPCUA_SESSION_TIMEOUT,
    };
    let sessions_per_address = match &raw.sessions_per_address {
        Some(n) => bounded(
            n,
            1..=OPCUA_MAX_SESSIONS,
            "sessions_per_address",
            " (the server's sessions at once)",
            at,
        )?,
        None => DEFAULT_OPCUA_SESSIONS_PER_ADDRESS,
    };
    let max_monitored_items = match &raw.max_monitored_items {
        Some(n) => bounded(
            n,
            1..=10_000_000,
            "max_monitored_items",
            " (each costs about 1.35 kB of memory)",
            at,
        )?,
        None => DEFAULT_OPCUA_MAX_MONITORED_ITEMS,
    };
    Ok(OpcuaConfig {
        host,
        port,
        application_name,
        application_uri,
        security,
        anonymous: raw.anonymous.map(Spanned::into_inner),
        trust_all_clients: raw
            .trust_all_clients
            .map(Spanned::into_inner)
            .unwrap_or(false),
        users,
        activation_timeout,
        session_timeout,
        sessions_per_address,
        max_monitored_items,
    })
}

/// Sessions the OPC UA server holds at once (every client's, activated or not).
pub const OPCUA_MAX_SESSIONS: usize = 100;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawOpcua {
    endpoint: Option<Spanned<String>>,
    application_name: Option<Spanned<String>>,
    application_uri: Option<Spanned<String>>,
    security: Option<Spanned<Vec<Spanned<String>>>>,
    anonymous: Option<Spanned<bool>>,
    trust_all_clients: Option<Spanned<bool>>,
    activation_timeout: Option<Spanned<String>>,
    session_timeout: Option<Spanned<String>>,
    sessions_per_address: Option<Spanned<i64>>,
    max_monitored_items: Option<Spanned<i64>>,
    #[serde(default)]
    user: Vec<RawOpcuaUser>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawOpcuaUser {
    name: Spanned<String>,
    password_env: Spanned<String>,
    write: Option<Spanned<bool>>,
}

#[cfg(test)]
mod opcua_tests {
    use super::*;

    const LINE: &str = "[[line]]\nname = \"l\"\nendpoint = \"tcp://127.0.0.1:1\"\n\
                        [[line.device]]\nid = \"jbc1\"\nprotocol = \"jbc\"\naddress = 1\n";

    fn parse(opcua: &str) -> Result<Option<OpcuaConfig>, ConfigError> {
        parse_config(&format!("{LINE}{opcua}"), Path::new("cell.toml")).map(|c| c.opcua)
    }

    #[test]
    fn an_empty_opcua_table_gets_the_secure_defaults_on_loopback() {
        let config = parse("[opcua]\n").unwrap().unwrap();
        assert_eq!((config.host.as_str(), config.port), ("127.0.0.1", 4840));
        assert_eq!(config.endpoint(), "opc.tcp://127.0.0.1:4840");
        assert_eq!(config.security, OpcuaSecurity::DEFAULT.to_vec());
        assert_eq!(config.anonymous, None);
        assert!(!config.trust_all_clients);
        assert!(config.application_uri.starts_with("urn:"));
        assert_eq!(parse("").unwrap(), None);
    }

    #[test]
    fn security_none_is_offered_only_when_listed() {
        let config = parse("[opcua]\nsecurity = [\"None\", \"Basic256Sha256 SignAndEncrypt\"]\n")
            .unwrap()
            .unwrap();
        assert_eq!(
            config.security,
            vec![OpcuaSecurity::NONE, OpcuaSecurity::DEFAULT[1]]
        );
    }

    #[test]
    fn a_bad_security_entry_is_refused_at_its_line_and_column() {
        let e = parse("[opcua]\nsecurity = [\"None\", \"Basic128 Sign\"]\n").unwrap_err();
        assert_eq!(e.position(), Some((9, 21)), "{e}");
        assert!(e.to_string().contains("Basic128 Sign"), "{e}");
    }

    #[test]
    fn users_are_read_with_their_password_variable_and_write_right() {
        let config = parse(
            "[opcua]\nendpoint = \"opc.tcp://0.0.0.0:4841\"\n\
             [[opcua.user]]\nname = \"op\"\npassword_env = \"OP_PW\"\nwrite = true\n\
             [[opcua.user]]\nname = \"viewer\"\npassword_env = \"VIEW_PW\"\n",
        )
        .unwrap()
        .unwrap();
        assert_eq!(config.port, 4841);
        assert_eq!(
            config.users,
            vec![
                OpcuaUser {
                    name: "op".into(),
                    password_env: "OP_PW".into(),
                    write: true
                },
                OpcuaUser {
                    name: "viewer".into(),
                    password_env: "VIEW_PW".into(),
                    write: false
                },
            ]
        );
    }

    #[test]
    fn users_on_an_insecure_only_server_and_wrong_endpoints_are_refused() {
        let e = parse(
            "[opcua]\nsecurity = [\"None\"]\n[[opcua.user]]\nname = \"op\"\npassword_env = \"P\"\n",
        )
        .unwrap_err();
        assert!(e.to_string().contains("secure endpoint"), "{e}");
        let e = parse("[opcua]\nendpoint = \"http://127.0.0.1:4840\"\n").unwrap_err();
        assert_eq!(e.position(), Some((9, 12)), "{e}");
        let e = parse("[opcua]\nendpont = \"opc.tcp://127.0.0.1:4840\"\n").unwrap_err();
        assert!(e.to_string().contains("endpont"), "{e}");
    }

    #[test]
    fn the_session_and_monitored_item_limits_have_safe_defaults_and_are_read() {
        let config = parse("[opcua]\n").unwrap().unwrap();
        assert_eq!(config.activation_timeout, Duration::from_secs(5));
        assert_eq!(config.session_timeout, Duration::from_secs(60));
        assert_eq!(config.sessions_per_address, 10);
        assert_eq!(config.max_monitored_items, 100_000);
        let config = parse(
            "[opcua]\nactivation_timeout = \"2s\"\nsession_timeout = \"5m\"\n\
             sessions_per_address = 3\nmax_monitored_items = 20000\n",
        )
        .unwrap()
        .unwrap();
        assert_eq!(config.activation_timeout, Duration::from_secs(2));
        assert_eq!(config.session_timeout, Duration::from_secs(300));
        assert_eq!(config.sessions_per_address, 3);
        assert_eq!(config.max_monitored_items, 20_000);
    }

    #[test]
    fn the_examples_opcua_table_uncommented_parses_with_the_defaults_it_shows() {
        let table: String = EXAMPLE_CONFIG
            .lines()
            .skip_while(|l| *l != "# [opcua]")
            .take_while(|l| !l.starts_with("# [[opcua.user]]"))
            .map(|l| l.strip_prefix("# ").unwrap_or(l.trim_start_matches('#')))
            .map(|l| format!("{l}\n"))
            .collect();
        assert!(table.contains("max_monitored_items"), "{table}");
        let config = parse(&table).unwrap().unwrap();
        let defaults = OpcuaConfig::at("127.0.0.1", 4840);
        assert_eq!(config.activation_timeout, defaults.activation_timeout);
        assert_eq!(config.session_timeout, defaults.session_timeout);
        assert_eq!(config.sessions_per_address, defaults.sessions_per_address);
        assert_eq!(config.max_monitored_items, defaults.max_monitored_items);
    }

    #[test]
    fn a_bad_session_or_monitored_item_limit_is_refused_naming_the_key_at_its_place() {
        for (line, column, key) in [
            ("activation_timeout = \"0s\"", 22, "activation_timeout"),
            ("activation_timeout = \"soon\"", 22, "activation_timeout"),
            ("session_timeout = \"2h\"", 19, "session_timeout"),
            ("sessions_per_address = 0", 24, "sessions_per_address"),
            ("sessions_per_address = 101", 24, "sessions_per_address"),
            ("max_monitored_items = -1", 23, "max_monitored_items"),
            ("max_monitored_items = 10000001", 23, "max_monitored_items"),
            ("max_monitored_item = 5", 1, "max_monitored_item"),
        ] {
            let e = parse(&format!("[opcua]\n{line}\n")).unwrap_err();
            assert_eq!(e.position(), Some((9, column)), "{line}: {e}");
            assert!(e.to_string().contains(key), "{line}: {e}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<CellConfig, ConfigError> {
        parse_config(text, Path::new("cell.toml"))
    }

    /// Parses `text`, expecting an error at `line:column` whose message contains `words`.
    fn refused(text: &str, line: usize, column: usize, words: &str) {
        let err = parse(text).expect_err("the config must be refused");
        let shown = err.to_string();
        assert_eq!(err.position(), Some((line, column)), "{shown}");
        assert!(
            shown.starts_with(&format!("cell.toml:{line}:{column}: ")),
            "{shown}"
        );
        assert!(shown.contains(words), "{shown}");
    }

    const ONE: &str = r#"
[[line]]
name = "rework"
endpoint = "serial:///dev/ttyUSB0"

[[line.device]]
id = "jbc1"
protocol = "jbc"
"#;

    #[test]
    fn the_example_config_parses_into_its_lines_and_devices() {
        let config = parse(EXAMPLE_CONFIG).unwrap();
        assert!(!config.lines.is_empty());
        let devices: usize = config.lines.iter().map(|l| l.devices.len()).sum();
        assert!(devices >= 2, "the example shows more than one device");
        assert!(
            config
                .lines
                .iter()
                .any(|l| matches!(l.endpoint, Endpoint::Serial { .. }))
        );
        assert!(
            config
                .lines
                .iter()
                .any(|l| matches!(l.endpoint, Endpoint::Tcp { .. }))
        );
    }

    #[test]
    fn a_config_that_is_not_a_file_too_large_or_not_text_is_refused_without_reading_it_all() {
        let dir = tempfile::tempdir().unwrap();
        let why = |path: &Path| match check_config(path) {
            Err(e @ ConfigError::Read { .. }) => e.to_string(),
            other => panic!("{other:?}"),
        };
        assert_eq!(
            why(Path::new("/dev/zero")),
            "config /dev/zero is not a file"
        );
        let big = dir.path().join("big.toml");
        let file = std::fs::File::create(&big).unwrap();
        file.set_len(MAX_CONFIG + 1).unwrap();
        assert!(
            why(&big).ends_with("big.toml is larger than 16 MiB"),
            "{}",
            why(&big)
        );
        let latin1 = dir.path().join("latin1.toml");
        std::fs::write(&latin1, b"# caf\xe9\n").unwrap();
        assert!(
            why(&latin1).ends_with("latin1.toml is not UTF-8 text (byte 6 is not)"),
            "{}",
            why(&latin1)
        );
        let missing = dir.path().join("missing.toml");
        assert!(
            why(&missing).contains("missing.toml cannot be read: "),
            "{}",
            why(&missing)
        );
    }

    #[test]
    fn the_example_file_in_examples_is_the_one_built_in() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/cell.toml");
        assert_eq!(std::fs::read_to_string(&path).unwrap(), EXAMPLE_CONFIG);
        check_config(&path).unwrap();
    }

    #[test]
    fn a_minimal_config_takes_the_protocol_defaults() {
        let config = parse(ONE).unwrap();
        let line = &config.lines[0];
        assert_eq!(line.name, "rework");
        assert_eq!(
            line.endpoint.line_settings(),
            Some(link::SerialSettings::new_8e1(19200)),
            "JBC's 19200 8E1 when the URL says nothing"
        );
        let device = &line.devices[0];
        assert_eq!(device.name, "jbc1");
        assert_eq!(device.driver.address, Some(1));
        assert_eq!(device.driver.timeout, None);
        assert!(device.groups.is_empty());
    }

    #[test]
    fn periods_addresses_and_retries_are_read() {
        let config = parse(&format!(
            "token = \"t0k\"\n{ONE}address = \"none\"\ntimeout = \"300ms\"\nretries = 1\nperiod = \"2s\"\npoll = {{ live = \"500ms\", info = \"5m\" }}\n"
        ))
        .unwrap();
        let device = &config.lines[0].devices[0];
        assert_eq!(config.token.as_deref(), Some("t0k"));
        assert_eq!(device.driver.address, None);
        assert_eq!(device.driver.timeout, Some(Duration::from_millis(300)));
        assert_eq!(device.driver.retries, Some(1));
        assert_eq!(device.period, Some(Duration::from_secs(2)));
        assert_eq!(device.groups["live"], Duration::from_millis(500));
        assert_eq!(device.groups["info"], Duration::from_secs(300));
    }

    #[test]
    fn unknown_fields_are_refused_where_they_are() {
        refused(
            &format!("{ONE}colour = \"red\"\n"),
            9,
            1,
            "unknown field `colour`",
        );
        refused(
            "[[line]]\nname = \"a\"\nendpoint = \"tcp://h:1\"\nspeed = 9600\n",
            4,
            1,
            "unknown field `speed`",
        );
    }

    #[test]
    fn toml_syntax_errors_name_line_and_column() {
        refused("[[line]\nname = \"a\"\n", 1, 8, "expected `]`");
    }

    #[test]
    fn semantic_errors_point_at_the_offending_value() {
        refused(
            &ONE.replace("\"jbc\"", "\"profibus\""),
            8,
            12,
            "known: jbc, thermosald, cross, panasonic, modbus",
        );
        refused(
            &ONE.replace("serial:///dev/ttyUSB0", "serial:///dev/ttyUSB0?baud=fast"),
            4,
            12,
            "option baud=",
        );
        refused(&format!("{ONE}address = 100\n"), 9, 11, "0 to 99");
        refused(
            &format!("{ONE}address = \"one\"\n"),
            9,
            11,
            "write a number or \"none\"",
        );
        refused(
            &format!("{ONE}timeout = \"soon\"\n"),
            9,
            11,
            "not a duration",
        );
        refused(
            &format!("{ONE}period = \"1ms\"\n"),
            9,
            10,
            "out of range: 50ms",
        );
        refused(&format!("{ONE}retries = 99\n"), 9, 11, "0 to 10");
        refused(
            &format!("{ONE}poll = {{ fast = \"1s\" }}\n"),
            9,
            17,
            "groups: live, settings, info",
        );
        refused(
            &ONE.replace("\"jbc1\"", "\"JBC 1\""),
            7,
            6,
            "device id \"JBC 1\" is not valid",
        );
        refused(&ONE.replace("\"rework\"", "\"re work\""), 3, 8, "line name");
        refused(
            &format!(
                "{ONE}\n{}",
                ONE.replace("\"rework\"", "\"two\"")
                    .replace("ttyUSB0", "ttyUSB1")
            ),
            16,
            6,
            "\"jbc1\" is used twice",
        );
        refused(
            &format!("{ONE}\n{}", ONE.replace("\"jbc1\"", "\"jbc2\"")),
            12,
            8,
            "line name \"rework\" is used twice",
        );
        refused("token = \"x\"\n", 1, 1, "no [[line]]");
        refused(
            "[[line]]\nname = \"a\"\nendpoint = \"tcp://h:1\"\n",
            2,
            8,
            "has no devices",
        );
        refused(
            &ONE.replace("[[line]]", "token = \" \"\n[[line]]"),
            2,
            9,
            "token is empty",
        );
    }

    const SEALERS: &str = r#"
[[line]]
name = "sealers"
endpoint = "tcp://192.0.2.1:4001"

[[line.device]]
id = "sealer0"
protocol = "thermosald"
address = 0
"#;

    #[test]
    fn thermosald_and_cross_devices_take_their_protocols_defaults() {
        let config = parse(&format!(
            "{SEALERS}\n[[line.device]]\nid = \"sealer7\"\nprotocol = \"thermosald\"\naddress = 7\n\n[[line]]\nname = \"mains\"\nendpoint = \"serial:///dev/ttyUSB1\"\n[[line.device]]\nid = \"cross1\"\nprotocol = \"cross\"\npoll = {{ ratings = \"10m\" }}\n"
        ))
        .unwrap();
        let sealers = &config.lines[0];
        assert_eq!(sealers.endpoint.line_settings(), None, "TCP without ?baud=");
        assert_eq!(sealers.devices.len(), 2);
        assert_eq!(sealers.devices[1].driver.address, Some(7));
        let mains = &config.lines[1];
        assert_eq!(
            mains.endpoint.line_settings(),
            Some(link::SerialSettings::new_8n1(9600)),
            "JBUS's 9600 8N1 when the URL says nothing"
        );
        assert_eq!(mains.devices[0].driver.protocol, Protocol::Cross);
        assert_eq!(
            mains.devices[0].driver.address,
            Some(1),
            "unit 1 by default"
        );
        assert_eq!(mains.devices[0].groups["ratings"], Duration::from_secs(600));
    }

    #[test]
    fn thermosald_and_cross_mistakes_are_refused_where_they_are() {
        refused(
            &SEALERS.replace("address = 0", "address = 8"),
            9,
            11,
            "address 8 is out of range: 0 to 7",
        );
        refused(
            &SEALERS.replace("address = 0", "address = \"none\""),
            9,
            11,
            "needs its address",
        );
        refused(
            &format!(
                "{SEALERS}\n[[line.device]]\nid = \"sealer9\"\nprotocol = \"thermosald\"\naddress = 0\n"
            ),
            14,
            11,
            "address 0 is used twice on line \"sealers\"",
        );
        refused(
            &format!("{SEALERS}\n[[line.device]]\nid = \"jbc1\"\nprotocol = \"jbc\"\n"),
            13,
            12,
            "a jbc device needs a line of its own",
        );
        refused(
            &format!("{SEALERS}poll = {{ fast = \"1s\" }}\n"),
            10,
            17,
            "groups: live, settings, machine, service",
        );
        let cross = SEALERS
            .replace("thermosald", "cross")
            .replace("sealer0", "cross1");
        refused(
            &cross,
            9,
            11,
            "JBUS unit number 0 is out of range: 1 to 255",
        );
        refused(
            &cross.replace("address = 0", "address = 300"),
            9,
            11,
            "1 to 255",
        );
    }

    const PLACER: &str = r#"
[[line]]
name = "placement"
endpoint = "tcp://192.0.2.50:49152"

[[line.device]]
id = "placer1"
protocol = "panasonic"
"#;

    #[test]
    fn a_panasonic_machine_takes_its_ports_from_the_endpoint_and_event_port() {
        let config = parse(PLACER).unwrap();
        let driver = &config.lines[0].devices[0].driver;
        assert_eq!(driver.address, None);
        assert_eq!(driver.event_port, None, "49153 by default");
        assert_eq!(driver.endpoint, Some(config.lines[0].endpoint.clone()));
        let config = parse(&format!("{PLACER}event_port = 50000\n")).unwrap();
        assert_eq!(config.lines[0].devices[0].driver.event_port, Some(50000));
    }

    #[test]
    fn panasonic_mistakes_are_refused_where_they_are() {
        refused(
            &PLACER.replace("tcp://192.0.2.50:49152", "serial:///dev/ttyS0"),
            4,
            12,
            "is reached over TCP: write tcp://host:49152",
        );
        refused(&format!("{PLACER}address = 3\n"), 9, 11, "has no address");
        refused(
            &format!("{PLACER}event_port = 70000\n"),
            9,
            14,
            "event_port 70000 is out of range: 1 to 65535",
        );
        refused(
            &format!("{ONE}event_port = 49153\n"),
            9,
            14,
            "event_port is for Panasonic machines only",
        );
        refused(
            &format!("{PLACER}\n[[line.device]]\nid = \"placer2\"\nprotocol = \"panasonic\"\n"),
            3,
            8,
            "each machine is its own TCP server and needs a [[line]] of its own",
        );
    }

    const CHILLER: &str = r#"
[[line]]
name = "utilities"
endpoint = "tcp://192.0.2.60:4001"

[[line.device]]
id = "chiller1"
protocol = "modbus"
address = 17

[[line.device.register]]
name = "supply"
table = "input"
address = 0x10
scale = 0.1
unit = "°C"
signed = true

[[line.device.register]]
name = "setpoint"
address = 0x20
scale = 0.1
writable = { min = 5.0, max = 30.0 }
"#;

    #[test]
    fn modbus_registers_are_read_from_their_tables() {
        let config = parse(CHILLER).unwrap();
        let driver = &config.lines[0].devices[0].driver;
        assert_eq!(driver.address, Some(17));
        assert_eq!(driver.registers.len(), 2);
        let supply = &driver.registers[0];
        assert_eq!(
            (
                supply.table,
                supply.address,
                supply.format.scaling.scale(),
                supply.format.data_type
            ),
            (RegisterTable::Input, 0x10, 0.1, DataType::Int16),
            "the old signed = true is an int16"
        );
        assert_eq!(driver.registers[1].format.data_type, DataType::Uint16);
        assert_eq!(supply.unit.as_deref(), Some("°C"));
        assert_eq!(driver.registers[1].writable, Some((5.0, 30.0)));
    }

    /// A Modbus TCP line of meters `ids`, each with the registers `registers`
    /// (`(name, table, address, type)`, no type written when it is empty).
    fn meters(ids: &[&str], registers: &[(&str, &str, u16, &str)]) -> String {
        let mut toml =
            "[[line]]\nname = \"utilities\"\nendpoint = \"modbus-tcp://192.0.2.61\"\n".to_owned();
        for (unit, id) in ids.iter().enumerate() {
            toml += &format!(
                "\n[[line.device]]\nid = \"{id}\"\nprotocol = \"modbus\"\naddress = {}\n",
                unit + 1
            );
            for (name, table, address, data_type) in registers {
                toml += &format!(
                    "[[line.device.register]]\nname = \"{name}\"\ntable = \"{table}\"\n\
                     address = {address}\n"
                );
                if !data_type.is_empty() {
                    toml += &format!("type = \"{data_type}\"\n");
                }
            }
        }
        toml
    }

    #[test]
    fn registers_that_share_a_register_are_warned_about_with_names_and_addresses() {
        let config = parse(&meters(
            &["meter1"],
            &[
                ("voltage", "holding", 100, "float32"),
                ("current", "holding", 101, "float32"),
                ("energy", "holding", 300, "uint64"),
                ("energy_low", "holding", 302, "uint32"),
                ("status", "holding", 200, "uint16"),
                ("running", "holding", 200, "bit:0"),
                ("tripped", "holding", 200, "bit:1"),
                ("frequency", "input", 100, "float32"),
                ("alarm", "coil", 100, ""),
                ("reset", "coil", 100, ""),
            ],
        ))
        .unwrap();
        assert_eq!(
            config.warnings(),
            [
                "device \"meter1\": registers \"voltage\" (holding 100–101) and \"current\" \
                 (holding 101–102) share holding register 101",
                "device \"meter1\": registers \"energy\" (holding 300–303) and \"energy_low\" \
                 (holding 302–303) share holding registers 302–303",
            ],
            "bits of one register, another table and coils are not warned about"
        );
        assert!(parse(CHILLER).unwrap().warnings().is_empty());
        assert!(
            parse(EXAMPLE_CONFIG).unwrap().warnings().is_empty(),
            "the example has no overlap"
        );
    }

    #[test]
    fn a_list_of_many_registers_at_one_address_names_a_few_pairs_and_says_there_are_more() {
        let registers: Vec<RegisterConfig> = (0..50_000)
            .map(|i| RegisterConfig::holding(&format!("r{i}"), 7))
            .collect();
        let overlaps = overlapping_registers(&registers);
        assert_eq!(overlaps.len(), MAX_OVERLAPS_NAMED + 1);
        assert_eq!(
            overlaps[0],
            "registers \"r0\" (holding 7) and \"r1\" (holding 7) share holding register 7"
        );
        assert_eq!(
            overlaps[MAX_OVERLAPS_NAMED],
            "more registers share a register (the first 20 pairs are named)"
        );
    }

    #[test]
    fn devices_with_the_same_overlapping_registers_are_warned_about_once() {
        let config = parse(&meters(
            &["meter1", "meter2", "meter3"],
            &[("a", "input", 0, "uint32"), ("b", "input", 1, "uint16")],
        ))
        .unwrap();
        assert_eq!(
            config.warnings(),
            [
                "device \"meter1\" (and 2 more with the same registers): registers \"a\" \
              (input 0–1) and \"b\" (input 1) share input register 1"
            ]
        );
    }

    #[test]
    fn a_modbus_tcp_line_parses_and_gives_its_modbus_devices_the_endpoint() {
        let config =
            parse(&CHILLER.replace("tcp://192.0.2.60:4001", "modbus-tcp://192.0.2.60:502"))
                .unwrap();
        let line = &config.lines[0];
        assert!(line.endpoint.is_mbap());
        assert_eq!(
            line.devices[0]
                .driver
                .endpoint
                .as_ref()
                .map(Endpoint::is_mbap),
            Some(true),
            "the driver frames Modbus TCP"
        );
        let raw = parse(CHILLER).unwrap();
        assert_eq!(raw.lines[0].devices[0].driver.endpoint, None);
    }

    #[test]
    fn a_modbus_tcp_endpoint_for_a_device_that_is_not_modbus_is_refused() {
        refused(
            &ONE.replace("serial:///dev/ttyUSB0", "modbus-tcp://192.0.2.9"),
            4,
            12,
            "modbus-tcp:// is for Modbus devices (modbus, cross); a jbc line",
        );
    }

    #[test]
    fn modbus_register_mistakes_are_refused_where_they_are() {
        refused(
            &CHILLER.replace("table = \"input\"", "table = \"coils\""),
            13,
            9,
            "write \"holding\", \"input\", \"coil\" or \"discrete\"",
        );
        refused(
            &CHILLER.replace("address = 0x20", "address = 70000"),
            21,
            11,
            "register setpoint: address 70000 is out of range: 0 to 65535",
        );
        refused(
            &CHILLER.replace("name = \"setpoint\"", "name = \"supply\""),
            20,
            8,
            "register name \"supply\" is used twice",
        );
        refused(
            &CHILLER.replace("min = 5.0, max = 30.0", "min = 5.0, max = 9000.0"),
            23,
            12,
            "within what the register holds",
        );
        refused(
            &CHILLER.replace("scale = 0.1\nunit", "scale = 0.0\nunit"),
            15,
            9,
            "scale 0 must be a number above 0",
        );
        refused(
            &format!("{ONE}\n[[line.device.register]]\nname = \"x\"\naddress = 1\n"),
            11,
            8,
            "registers are named for modbus devices only",
        );
        let bare = CHILLER.split("[[line.device.register]]").next().unwrap();
        refused(bare, 7, 6, "needs its registers");
    }

    const METER: &str = r#"
[[line]]
name = "utilities"
endpoint = "modbus-tcp://192.0.2.61"

[[line.device]]
id = "meter1"
protocol = "modbus"
max_registers_per_request = 60
max_bits_per_request = 800
one_request_per_register = true
delay_between_requests = "50ms"
delay_after_connect = "1s"
deadband = 0.5

[[line.device.register]]
name = "voltage"
table = "input"
address = 0x0100
type = "float32"
order = "CDAB"
unit = "V"

[[line.device.register]]
name = "energy"
table = "input"
address = 0x0200
type = "uint32"
scale = 0.01
offset = 5
deadband_percent = 1

[[line.device.register]]
name = "limit"
address = 0x0300
type = "int32"
writable = { min = -1000, max = 1000 }

[[line.device.register]]
name = "pump"
table = "coil"
address = 3
writable = true

[[line.device.register]]
name = "door"
table = "discrete"
address = 0x20

[[line.device.register]]
name = "label"
address = 0x0400
type = "string:4"
"#;

    #[test]
    fn modbus_types_orders_tables_pacing_and_deadbands_are_read() {
        let config = parse(METER).unwrap();
        let device = &config.lines[0].devices[0];
        let driver = &device.driver;
        assert_eq!(device.deadband, Some(Deadband::Absolute(0.5)));
        let options = driver.modbus;
        assert_eq!(options.plan.max_registers.get(), 60);
        assert_eq!(options.plan.max_bits.get(), 800);
        assert!(options.plan.one_request_per_item);
        assert_eq!(options.delay_between_requests, Duration::from_millis(50));
        assert_eq!(options.delay_after_connect, Duration::from_secs(1));
        let r = |name: &str| driver.registers.iter().find(|r| r.name == name).unwrap();
        assert_eq!(
            r("voltage").format,
            Format::new(DataType::Float32, Order::Cdab)
        );
        assert_eq!(
            r("voltage").deadband,
            Some(Deadband::Absolute(0.5)),
            "the device's deadband"
        );
        assert_eq!(r("energy").format.scaling, Scaling::new(0.01, 5.0).unwrap());
        assert_eq!(r("energy").deadband, Some(Deadband::Percent(1.0)));
        assert_eq!(r("limit").writable, Some((-1000.0, 1000.0)));
        assert_eq!(
            (r("pump").table, r("pump").writable),
            (RegisterTable::Coil, Some((0.0, 1.0)))
        );
        assert_eq!(r("door").table, RegisterTable::Discrete);
        assert_eq!(r("door").deadband, None, "bits have no deadband");
        assert_eq!(r("label").deadband, None, "text has no deadband");
        let defaults = parse(CHILLER).unwrap();
        let chiller = &defaults.lines[0].devices[0];
        assert_eq!(chiller.deadband, None);
        assert_eq!(chiller.driver.modbus, ModbusOptions::default());
        assert_eq!(chiller.driver.modbus.plan.max_registers.get(), 125);
        assert_eq!(chiller.driver.modbus.plan.max_bits.get(), 2000);
    }

    #[test]
    fn a_deadband_applies_to_any_protocol() {
        let config = parse(&format!("{ONE}deadband_percent = 2\n")).unwrap();
        assert_eq!(
            config.lines[0].devices[0].deadband,
            Some(Deadband::Percent(2.0))
        );
    }

    #[test]
    fn modbus_field_mistakes_are_refused_naming_register_field_and_place() {
        let cases: [(&str, &str, usize, usize, &str); 14] = [
            (
                "type = \"float32\"\norder",
                "type = \"float33\"\norder",
                20,
                8,
                "register voltage: `float33` is not a data type",
            ),
            (
                "order = \"CDAB\"",
                "order = \"ACBD\"",
                21,
                9,
                "register voltage: `ACBD` is not a byte order",
            ),
            (
                "offset = 5",
                "offset = nan",
                30,
                10,
                "register energy: offset NaN must be a number",
            ),
            (
                "deadband_percent = 1\n",
                "deadband_percent = 1\ndeadband = 2\n",
                31,
                20,
                "deadband and deadband_percent both given",
            ),
            (
                "deadband_percent = 1\n",
                "deadband_percent = 150\n",
                31,
                20,
                "deadband_percent 150 is out of range",
            ),
            (
                "deadband = 0.5",
                "deadband = -1",
                14,
                12,
                "deadband -1 must be a number of at least 0",
            ),
            (
                "max_registers_per_request = 60",
                "max_registers_per_request = 126",
                9,
                29,
                "max_registers_per_request 126 is out of range: 1 to 125",
            ),
            (
                "max_bits_per_request = 800",
                "max_bits_per_request = 0",
                10,
                24,
                "max_bits_per_request 0 is out of range: 1 to 2000",
            ),
            (
                "delay_between_requests = \"50ms\"",
                "delay_between_requests = \"fast\"",
                12,
                26,
                "delay_between_requests \"fast\" is not a duration",
            ),
            (
                "delay_after_connect = \"1s\"",
                "delay_after_connect = \"2m\"",
                13,
                23,
                "delay_after_connect 2m is out of range",
            ),
            (
                "table = \"discrete\"\naddress = 0x20\n",
                "table = \"discrete\"\naddress = 0x20\nwritable = true\n",
                49,
                12,
                "register door: only holding registers and coils can be written; discrete inputs are read-only",
            ),
            (
                "type = \"string:4\"\n",
                "type = \"string:4\"\nwritable = true\n",
                54,
                12,
                "register label: a string:4 register is read-only here",
            ),
            (
                "table = \"coil\"\naddress = 3\n",
                "table = \"coil\"\naddress = 3\ntype = \"int16\"\n",
                43,
                8,
                "register pump: type is for holding and input registers; a coil is a single bit",
            ),
            (
                "address = 0x0400",
                "address = 65534",
                52,
                11,
                "register label: a string:4 at 65534 runs past the last address 65535",
            ),
        ];
        for (from, to, line, column, words) in cases {
            assert!(METER.contains(from), "{from}");
            refused(&METER.replacen(from, to, 1), line, column, words);
        }
        refused(
            &CHILLER.replace("signed = true", "signed = true\ntype = \"int32\""),
            17,
            10,
            "register supply: signed is the old way of saying type = \"int16\"; give type only",
        );
        refused(
            &format!("{ONE}one_request_per_register = true\n"),
            9,
            28,
            "one_request_per_register is for modbus devices only, not jbc devices",
        );
        refused(
            &format!("{ONE}registers_csv = \"x.csv\"\n"),
            9,
            17,
            "registers_csv is for modbus devices only",
        );
        refused(
            &METER.replace(
                "deadband = 0.5",
                "deadband = 0.5\nregisters_csv = \"meter.csv\"",
            ),
            15,
            17,
            "registers_csv and [[line.device.register]] tables both given",
        );
    }

    fn csv_cell(dir: &Path, csv: &str) -> Result<CellConfig, ConfigError> {
        std::fs::write(dir.join("meter.csv"), csv).unwrap();
        let toml = String::from(
            "[[line]]\nname = \"utilities\"\nendpoint = \"modbus-tcp://192.0.2.61\"\n\n\
             [[line.device]]\nid = \"meter1\"\nprotocol = \"modbus\"\nregisters_csv = \"meter.csv\"\n",
        );
        let path = dir.join("cell.toml");
        std::fs::write(&path, toml).unwrap();
        check_config(&path)
    }

    #[test]
    fn meters_naming_one_registers_csv_share_its_registers_and_their_point_descriptions() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(
            dir.path().join("meter.csv"),
            "address,name,type,table\n0,voltage,uint16,input\n1,current,uint16,input\n",
        )
        .unwrap();
        let device = |id: &str, unit: u8, extra: &str| {
            format!(
                "[[line.device]]\nid = \"{id}\"\nprotocol = \"modbus\"\naddress = {unit}\n\
                 registers_csv = \"meter.csv\"\n{extra}\n"
            )
        };
        let toml = format!(
            "[[line]]\nname = \"utilities\"\nendpoint = \"modbus-tcp://192.0.2.61\"\n\n{}{}{}",
            device("meter1", 1, ""),
            device("meter2", 2, ""),
            device("meter3", 3, "deadband = 0.5"),
        );
        let path = dir.path().join("cell.toml");
        std::fs::write(&path, toml).unwrap();
        let config = check_config(&path).unwrap();
        let points: Vec<Vec<crate::point::PointSpec>> = config.lines[0]
            .devices
            .iter()
            .map(|d| driver::build(&d.driver).unwrap().points())
            .collect();
        let shared = |a: usize, b: usize| {
            points[a]
                .iter()
                .zip(&points[b])
                .all(|(a, b)| std::sync::Arc::ptr_eq(&a.description, &b.description))
        };
        assert_eq!(points[0][1].id.as_str(), "meter1.current");
        assert_eq!(points[1][1].id.as_str(), "meter2.current");
        assert!(shared(0, 1), "one file, one deadband: one list");
        assert!(!shared(0, 2), "another deadband is another list");
        let deadbands: Vec<_> = config.lines[0]
            .devices
            .iter()
            .map(|d| d.driver.registers[0].deadband)
            .collect();
        assert_eq!(
            deadbands,
            [None, None, Some(Deadband::Absolute(0.5))],
            "each device keeps its own deadband"
        );
    }

    #[test]
    fn a_csv_register_list_is_read_relative_to_the_config_file_with_columns_in_any_order() {
        let dir = tempfile::tempdir().unwrap();
        let config = csv_cell(
            dir.path(),
            "# a meter\nunit,address,name,type,order,table,scale,writable_min,writable_max,title\n\
             V,0x0000,voltage_l1,float32,CDAB,input,,,,Voltage L1-N\n\
             kW,256,limit,uint16,,,0.1,0,200,\n",
        )
        .unwrap();
        let registers = &config.lines[0].devices[0].driver.registers;
        assert_eq!(registers.len(), 2);
        assert_eq!(registers[0].title, "Voltage L1-N");
        assert_eq!(registers[0].table, RegisterTable::Input);
        assert_eq!(
            registers[0].format,
            Format::new(DataType::Float32, Order::Cdab)
        );
        assert_eq!(registers[1].address, 256);
        assert_eq!(registers[1].table, RegisterTable::Holding, "empty: default");
        assert_eq!(registers[1].writable, Some((0.0, 200.0)));
        assert_eq!(registers[1].unit.as_deref(), Some("kW"));
    }

    #[test]
    fn a_registers_csv_with_a_header_and_no_rows_is_refused_like_a_device_without_registers() {
        let dir = tempfile::tempdir().unwrap();
        for csv in ["name,address\n", "# a meter\nname,address\n# no rows yet\n"] {
            let err = csv_cell(dir.path(), csv).unwrap_err().to_string();
            assert!(
                err.contains("meter.csv names no registers") && err.contains("cell.toml:"),
                "{csv:?}: {err}"
            );
        }
    }

    #[test]
    fn two_lines_on_one_serial_port_are_refused_but_a_tcp_server_decides_for_itself() {
        let two = |first: &str, second: &str, protocol: &str| {
            format!(
                "[[line]]\nname = \"a\"\nendpoint = \"{first}\"\n[[line.device]]\nid = \"d1\"\n\
                 protocol = \"{protocol}\"\naddress = 1\n\
                 [[line]]\nname = \"b\"\nendpoint = \"{second}\"\n[[line.device]]\nid = \"d2\"\n\
                 protocol = \"{protocol}\"\naddress = 2\n"
            )
        };
        refused(
            &two("serial:///dev/ttyUSB0", "/dev/ttyUSB0", "cross"),
            10,
            12,
            "line \"b\" is on serial port /dev/ttyUSB0, as line \"a\" is",
        );
        // A serial server may take one connection or several, and a simulator serves each
        // connection a bus of its own: its answer, not the configuration, decides.
        parse(&two("tcp://moxa:4001", "tcp://moxa:4001", "cross"))
            .expect("two connections to one TCP server");
        refused(
            &two("tcp://moxa:0", "tcp://moxa:4002", "cross"),
            3,
            12,
            "port 0 is not a port a device listens on",
        );
        parse(&two("modbus-tcp://plc", "modbus-tcp://plc", "cross"))
            .expect("a Modbus TCP server serves several connections");
    }

    #[test]
    fn an_address_of_the_wrong_type_is_told_in_words_not_rust_types() {
        for address in ["1.5", "true"] {
            refused(
                &format!("{ONE}address = {address}\n"),
                9,
                11,
                "the address must be a whole number (see the protocol's range) or \"none\"",
            );
        }
    }

    #[test]
    fn a_registers_csv_that_is_not_a_small_file_is_refused_without_reading_it_all() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cell.toml");
        for (csv, words) in [
            ("/dev/zero", "is not a file"),
            (".", "is not a file"),
            ("missing.csv", "cannot be read"),
        ] {
            std::fs::write(
                &path,
                format!(
                    "[[line]]\nname = \"utilities\"\nendpoint = \"modbus-tcp://192.0.2.61\"\n\n\
                     [[line.device]]\nid = \"meter1\"\nprotocol = \"modbus\"\nregisters_csv = \"{csv}\"\n"
                ),
            )
            .unwrap();
            let error = check_config(&path).unwrap_err().to_string();
            assert!(error.contains(words), "{csv}: {error}");
        }
        let big = dir.path().join("big.csv");
        std::fs::write(&big, vec![b'a'; (MAX_REGISTERS_CSV + 1) as usize]).unwrap();
        let error = read_bounded(&big, MAX_REGISTERS_CSV).unwrap_err();
        assert!(error.contains("larger than 4 MiB"), "{error}");
    }

    #[test]
    fn csv_mistakes_name_the_file_row_and_column() {
        let dir = tempfile::tempdir().unwrap();
        let header = "name,table,address,type\n";
        for (rows, words) in [
            (
                "a,input,0x10,float32\nb,input,0x1G,float32\n",
                "meter.csv: row 3: column \"address\": \"0x1G\" is not an address",
            ),
            (
                "a,input,0x10,float32\nb,inputs,0x12,float32\n",
                "meter.csv: row 3: column \"table\": register b: table \"inputs\" is not one",
            ),
            (
                "a,input,0x10,float99\n",
                "meter.csv: row 2: column \"type\": register a: `float99` is not a data type",
            ),
            (
                "a,input,0x10,float32\na,input,0x12,float32\n",
                "meter.csv: row 3: column \"name\": register name \"a\" is used twice",
            ),
            (
                ",input,0x10,float32\n",
                "meter.csv: row 2: column \"name\": empty",
            ),
            ("a,input,0x10\n", "meter.csv: row 2: "),
        ] {
            let err = csv_cell(dir.path(), &format!("{header}{rows}")).unwrap_err();
            let shown = err.to_string();
            assert!(shown.contains(words), "{shown}\nwanted: {words}");
        }
        let err = csv_cell(dir.path(), "name,adress\n")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("row 1: column \"adress\" is not one cellbus knows"),
            "{err}"
        );
        let err = csv_cell(dir.path(), "name,title\n")
            .unwrap_err()
            .to_string();
        assert!(err.contains("row 1: no column \"address\""), "{err}");
        std::fs::remove_file(dir.path().join("meter.csv")).unwrap();
        let err = check_config(&dir.path().join("cell.toml")).unwrap_err();
        assert_eq!(err.position(), Some((8, 17)), "{err}");
        assert!(
            err.to_string().contains("registers_csv")
                && err.to_string().contains("meter.csv: cannot be read"),
            "{err}"
        );
    }

    #[test]
    fn the_example_energy_meter_csv_becomes_toml_that_parses_to_the_same_registers() {
        let csv = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/energy-meter.csv");
        let registers = registers_from_csv(&csv).unwrap();
        assert!(registers.len() >= 12, "{}", registers.len());
        let toml = registers_toml(&registers);
        let config = parse(&format!(
            "[[line]]\nname = \"l\"\nendpoint = \"modbus-tcp://192.0.2.61\"\n\n\
             [[line.device]]\nid = \"meter1\"\nprotocol = \"modbus\"\n\n{toml}"
        ))
        .unwrap();
        assert_eq!(*config.lines[0].devices[0].driver.registers, *registers);
    }

    #[test]
    fn no_mqtt_table_means_no_mqtt() {
        assert_eq!(parse(ONE).unwrap().mqtt, None);
    }

    #[test]
    fn an_mqtt_table_is_read_with_its_defaults() {
        let text =
            format!("{ONE}\n[mqtt]\nbroker = \"mqtt://broker.local\"\nedge_node_id = \"cell-7\"\n");
        let mqtt = parse(&text).unwrap().mqtt.unwrap();
        assert_eq!((mqtt.host.as_str(), mqtt.port), ("broker.local", 1883));
        assert_eq!(mqtt.group_id, "cellbus");
        assert_eq!(mqtt.client_id, "cellbus-cell-7");
        assert_eq!(mqtt.keep_alive, DEFAULT_MQTT_KEEP_ALIVE);
        assert_eq!((mqtt.username, mqtt.password_env), (None, None));
    }

    #[test]
    fn mqtt_mistakes_are_refused_where_they_are() {
        let at = |table: &str| format!("{ONE}\n[mqtt]\n{table}");
        refused(
            &at("broker = \"http://b\"\n"),
            11,
            10,
            "write mqtt://host:1883",
        );
        refused(
            &at("broker = \"mqtt://b\"\npassword = \"x\"\n"),
            12,
            1,
            "unknown field `password`",
        );
        refused(
            &at("broker = \"mqtt://b\"\ngroup_id = \"a/b\"\n"),
            12,
            12,
            "group_id",
        );
        refused(
            &at("broker = \"mqtt://b\"\nkeep_alive = \"1ms\"\n"),
            12,
            14,
            "keep_alive",
        );
        refused(
            &at("broker = \"mqtt://b:0\"\n"),
            11,
            10,
            "port 0 is not a port a broker listens on",
        );
        refused(
            &at(&format!(
                "broker = \"mqtt://b\"\nclient_id = \"{}\"\n",
                "c".repeat(70_000)
            )),
            12,
            13,
            "client_id is 70000 bytes; MQTT carries at most 65535",
        );
    }

    #[test]
    fn the_mqtt_modes_commands_primary_host_and_backlog_are_read_with_their_defaults() {
        let text = format!("{ONE}\n[mqtt]\nbroker = \"mqtt://b\"\nedge_node_id = \"cell-7\"\n");
        let mqtt = parse(&text).unwrap().mqtt.unwrap();
        assert_eq!(mqtt.mode, MqttMode::Sparkplug);
        assert_eq!(mqtt.prefix, "cellbus/cell-7");
        assert!(!mqtt.commands);
        assert_eq!(mqtt.primary_host, None);
        assert_eq!(mqtt.max_backlog, DEFAULT_MQTT_BACKLOG);
        assert_eq!(mqtt.max_command_metrics, DEFAULT_MQTT_COMMAND_METRICS);
        assert_eq!(mqtt.check_retained, DEFAULT_MQTT_CHECK_RETAINED);
        let text = format!(
            "{ONE}\n[mqtt]\nbroker = \"mqtt://b\"\nmode = \"JSON\"\nprefix = \"plant/cell7/\"\n\
             commands = true\nprimary_host = \"scada\"\nmax_backlog = 5000\n\
             max_command_metrics = 8\ncheck_retained = \"1h\"\n"
        );
        let mqtt = parse(&text).unwrap().mqtt.unwrap();
        assert_eq!(mqtt.mode, MqttMode::Json);
        assert_eq!(mqtt.prefix, "plant/cell7", "a trailing / is dropped");
        assert!(mqtt.commands);
        assert_eq!(mqtt.primary_host.as_deref(), Some("scada"));
        assert_eq!(mqtt.max_backlog, 5000);
        assert_eq!(mqtt.max_command_metrics, 8);
        assert_eq!(mqtt.check_retained, Duration::from_secs(3600));
    }

    #[test]
    fn mqtt_mode_prefix_primary_host_and_backlog_mistakes_are_refused_where_they_are() {
        let at = |line: &str| format!("{ONE}\n[mqtt]\nbroker = \"mqtt://b\"\n{line}\n");
        refused(
            &at("mode = \"xml\""),
            12,
            8,
            "write \"sparkplug\" or \"json\"",
        );
        refused(&at("prefix = \"a/#\""), 12, 10, "not a usable topic prefix");
        refused(&at("primary_host = \"a+b\""), 12, 16, "primary_host");
        refused(&at("max_backlog = 0"), 12, 15, "outside 1–100000000");
        refused(&at("max_command_metrics = 0"), 12, 23, "outside 1–10000");
        refused(&at("check_retained = \"1s\""), 12, 18, "out of range");
        refused(&at("commands = \"yes\""), 12, 12, "bool");
    }

    #[test]
    fn an_mqtts_broker_takes_port_8883_and_trusts_the_systems_roots_by_default() {
        let text = format!("{ONE}\n[mqtt]\nbroker = \"mqtts://broker.local\"\n");
        let mqtt = parse(&text).unwrap().mqtt.unwrap();
        assert_eq!((mqtt.host.as_str(), mqtt.port), ("broker.local", 8883));
        assert_eq!(mqtt.tls, Some(MqttTls::default()));
        let cli = MqttConfig::for_broker("mqtts://b:18883", "cell").unwrap();
        assert_eq!((cli.port, cli.tls), (18883, Some(MqttTls::default())));
        let plain = MqttConfig::for_broker("mqtt://b", "cell").unwrap();
        assert_eq!((plain.port, plain.tls), (1883, None));
    }

    #[test]
    fn tls_keys_with_an_mqtt_broker_are_refused_naming_the_key() {
        let at = |table: &str| format!("{ONE}\n[mqtt]\nbroker = \"mqtt://b\"\n{table}");
        refused(&at("ca_file = \"ca.pem\"\n"), 12, 11, "ca_file is for TLS");
        refused(
            &at("client_key = \"k.pem\"\n"),
            12,
            14,
            "client_key is for TLS",
        );
    }

    #[test]
    fn a_client_cert_without_its_key_is_refused_and_the_other_way_round() {
        let at = |table: &str| format!("{ONE}\n[mqtt]\nbroker = \"mqtts://b\"\n{table}");
        refused(
            &at("client_cert = \"c.pem\"\n"),
            12,
            15,
            "client_cert needs client_key",
        );
        refused(
            &at("client_key = \"k.pem\"\n"),
            12,
            14,
            "client_key needs client_cert",
        );
    }

    #[test]
    fn tls_files_are_read_relative_to_the_config_file_and_named_when_missing() {
        let text = format!("{ONE}\n[mqtt]\nbroker = \"mqtts://b\"\nca_file = \"certs/ca.pem\"\n");
        let err = parse_config(&text, Path::new("/nonexistent/cellbus/cell.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains(":12:11: ca_file /nonexistent/cellbus/certs/ca.pem: cannot be read"),
            "{err}"
        );
    }

    #[test]
    fn tls_files_that_are_not_pem_are_refused_without_showing_a_key() {
        let dir = tempfile::tempdir().unwrap();
        let key = rcgen::KeyPair::generate().unwrap();
        let cert = rcgen::CertificateParams::new(vec!["gateway".to_owned()])
            .unwrap()
            .self_signed(&key)
            .unwrap();
        std::fs::write(dir.path().join("ca.pem"), cert.pem()).unwrap();
        std::fs::write(dir.path().join("gateway.pem"), cert.pem()).unwrap();
        std::fs::write(dir.path().join("gateway.key"), key.serialize_pem()).unwrap();
        std::fs::write(dir.path().join("notes.txt"), "no PEM here").unwrap();
        let secret = key.serialize_pem().replace("PRIVATE KEY", "PRIVAT KEY");
        std::fs::write(dir.path().join("mangled.key"), &secret).unwrap();
        let path = dir.path().join("cell.toml");
        let at = |table: &str| format!("{ONE}\n[mqtt]\nbroker = \"mqtts://b\"\n{table}");

        let good = parse_config(
            &at("ca_file = \"ca.pem\"\nclient_cert = \"gateway.pem\"\nclient_key = \"gateway.key\"\n"),
            &path,
        )
        .unwrap();
        let tls = good.mqtt.unwrap().tls.unwrap();
        assert_eq!(tls.ca_file, Some(dir.path().join("ca.pem")));
        assert_eq!(
            tls.client,
            Some(MqttClientCert {
                cert: dir.path().join("gateway.pem"),
                key: dir.path().join("gateway.key"),
            })
        );

        let err = parse_config(&at("ca_file = \"notes.txt\"\n"), &path)
            .unwrap_err()
            .to_string();
        assert!(err.contains("notes.txt holds no certificate"), "{err}");
        let err = parse_config(
            &at("client_cert = \"gateway.pem\"\nclient_key = \"mangled.key\"\n"),
            &path,
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains(":13:14: client_key "), "{err}");
        assert!(err.contains("mangled.key: "), "{err}");
        let body: String = secret.lines().filter(|l| !l.starts_with("-----")).collect();
        assert!(!err.contains(&body[..16]), "{err}");
    }

    #[test]
    fn the_error_shows_the_line_with_a_caret_under_the_column() {
        let err = parse(&format!("{ONE}address = 100\n"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("9 | address = 100\n  |           ^"), "{err}");
    }

    #[test]
    fn a_number_beyond_64_bits_is_called_too_large_not_an_i128() {
        let text = ONE.replace(
            "protocol = \"jbc\"",
            "protocol = \"jbc\"\naddress = 99999999999999999999999",
        );
        refused(
            &text,
            9,
            11,
            "99999999999999999999999 is too large: no number in the configuration is beyond \
             9223372036854775807",
        );
        assert_eq!(plain_toml_message("expected a table\n"), "expected a table");
    }

    #[test]
    fn device_ids_the_gateways_own_objects_use_are_refused() {
        for id in RESERVED_DEVICE_IDS {
            let text = ONE.replace("id = \"jbc1\"", &format!("id = \"{id}\""));
            refused(&text, 7, 6, "is taken by the gateway's own objects");
        }
    }

    #[test]
    fn a_broker_url_with_a_user_and_password_is_refused_without_showing_them() {
        let err = parse_broker("mqtt://user:pw@127.0.0.1:1883").unwrap_err();
        assert!(!err.contains("pw") && !err.contains("user:"), "{err}");
        assert!(err.contains("mqtt://(hidden)@127.0.0.1:1883"), "{err}");
        let text = format!("[mqtt]\nbroker = \"mqtt://user:pw@127.0.0.1:1883\"\n{ONE}");
        let shown = parse(&text).unwrap_err().to_string();
        assert!(!shown.contains("pw"), "{shown}");
        assert_eq!(
            hide_userinfo("mqtt://host:1883/a@b"),
            "mqtt://host:1883/a@b"
        );
    }

    #[test]
    fn a_missing_file_is_named() {
        let err = check_config(Path::new("/nonexistent/cell.toml")).unwrap_err();
        assert!(err.to_string().contains("/nonexistent/cell.toml"), "{err}");
    }

    #[test]
    fn a_read_token_equal_to_the_write_token_is_refused_without_showing_either() {
        let text = format!("token = \"s3cret\"\nread_token = \" s3cret\"\n{ONE}");
        refused(
            &text,
            2,
            14,
            "read_token cannot be used: the read token is the write token",
        );
        let shown = parse(&text).unwrap_err().to_string();
        assert!(!shown.contains("s3cret"), "{shown}");
        let text = format!("token = \"s3cret\"\nread_token = \"look\"\n{ONE}");
        assert_eq!(parse(&text).unwrap().read_token.as_deref(), Some("look"));
    }

    #[test]
    fn an_error_on_the_token_line_does_not_show_the_token() {
        let err = parse(&format!("token = \"s3cret-value\n{ONE}")).unwrap_err();
        let shown = err.to_string();
        assert!(!shown.contains("s3cret"), "{shown}");
        assert!(shown.contains("token = \"(hidden)\""), "{shown}");
        assert_eq!(hide_secret("name = \"rework\""), "name = \"rework\"");
    }
}
