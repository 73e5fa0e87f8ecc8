//! The `[mqtt]` table: where the broker is, who the edge node is, and how it publishes.
//!
//! ```toml
//! [mqtt]
//! broker = "mqtt://broker.plant:1883"   # or mqtts://host:8883 (TLS)
//! group_id = "cellbus"                  # Sparkplug group (default cellbus)
//! edge_node_id = "cell-7"               # default: this machine's host name
//! ```
//!
//! Read and checked here, beside the interface's code; the cell's config hands the table
//! over through [`TableReader`].

use std::ops::Range;
use std::path::Path;
use std::time::Duration;

use serde::Deserialize;
use toml::Spanned;

use crate::config::{ConfigError, Settings, Table, TableReader, bounded, duration};
use crate::northbound::tls::{TlsKeys, check_tls};
pub use kit::mqtt::{Broker, MqttClientCert, MqttTls, parse_broker};

/// The `[mqtt]` table's reader.
#[derive(Debug)]
pub struct MqttTable;

impl TableReader for MqttTable {
    fn table(&self) -> &'static str {
        "mqtt"
    }

    fn read(&self, table: &Table<'_>) -> Result<Settings, ConfigError> {
        let raw: RawMqtt = table.read()?;
        check_mqtt(raw, table.path(), &|span, message| table.at(span, message)).map(Settings::new)
    }

    fn environment(&self, settings: &Settings) -> Vec<(&'static str, String)> {
        settings
            .get::<MqttConfig>()
            .and_then(|mqtt| mqtt.password_env.clone())
            .map(|var| ("[mqtt] password_env", var))
            .into_iter()
            .collect()
    }

    fn summary(&self, settings: &Settings) -> String {
        let Some(mqtt) = settings.get::<MqttConfig>() else {
            return String::new();
        };
        let scheme = if mqtt.tls.is_some() { "mqtts" } else { "mqtt" };
        match mqtt.mode {
            MqttMode::Sparkplug => format!(
                "Sparkplug B to {scheme}://{}:{} as {}/{}",
                mqtt.host, mqtt.port, mqtt.group_id, mqtt.edge_node_id
            ),
            MqttMode::Json => format!(
                "JSON to {scheme}://{}:{} under {}",
                mqtt.host, mqtt.port, mqtt.prefix
            ),
        }
    }
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

fn check_mqtt(
    raw: RawMqtt,
    path: &Path,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<MqttConfig, ConfigError> {
    let Broker { host, port, tls } =
        parse_broker(raw.broker.get_ref()).map_err(|m| at(raw.broker.span(), m))?;
    let keys = TlsKeys {
        broker: &raw.broker,
        ca_file: raw.ca_file.as_ref(),
        client_cert: raw.client_cert.as_ref(),
        client_key: raw.client_key.as_ref(),
    };
    let tls = check_tls(&keys, tls, "mqtts://host:8883", path, at)?;
    let group_id =
        id_opt(&raw.group_id, "group_id", at)?.unwrap_or_else(|| DEFAULT_MQTT_GROUP.to_owned());
    let edge_node_id = id_opt(&raw.edge_node_id, "edge_node_id", at)?
        .unwrap_or_else(crate::northbound::default_edge_node_id);
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

#[cfg(test)]
#[path = "config_tests.rs"]
mod tests;
