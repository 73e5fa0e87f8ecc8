//! What `cellbus serve` was asked for: the options every part of the gateway may read (the
//! interfaces take their flags from here when they start).

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use crate::northbound::mqtt::config::MqttMode;

/// Address the gateway listens on by default: loopback only.
pub const DEFAULT_LISTEN: SocketAddr =
    SocketAddr::new(std::net::IpAddr::V4(std::net::Ipv4Addr::LOCALHOST), 8080);

/// Data directory by default, relative to the working directory.
pub const DEFAULT_DATA_DIR: &str = "cellbus-data";

/// History kept by default: 30 days.
pub const DEFAULT_RETAIN: Duration = Duration::from_secs(30 * 24 * 3600);

/// Audit rows kept by default: 365 days (never less than the history).
pub const DEFAULT_RETAIN_AUDIT: Duration = Duration::from_secs(365 * 24 * 3600);

/// A mistake in the options `cellbus serve` was given (the CLI exits 2 for it), as opposed
/// to a failure to start (a port in use, a data directory that cannot be made).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct OptionError(pub String);

/// What `cellbus serve` was asked for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ServeOptions {
    /// Where to listen (default 127.0.0.1:8080; port 0 for any free port).
    pub listen: SocketAddr,
    /// The cell's configuration; `None` starts the demo cell.
    pub config: Option<PathBuf>,
    /// Where the history database lives (default `./cellbus-data`).
    pub data_dir: PathBuf,
    /// How long history is kept (default 30 days).
    pub retain: Duration,
    /// How long audit rows are kept (default 365 days; never less than `retain`).
    pub retain_audit: Duration,
    /// Whether `POST /api/devices/{id}/write` is allowed.
    pub allow_writes: bool,
    /// The write token; else `CELLBUS_TOKEN`, else the config's `token`.
    pub token: Option<String>,
    /// The read token every API route then needs; else `CELLBUS_READ_TOKEN`, else the
    /// config's `read_token`; none: reading is open.
    pub read_token: Option<String>,
    /// `--mqtt mqtt://HOST:PORT` (or `mqtts://HOST:PORT`, TLS): publish the cell as a
    /// Sparkplug B edge node to this broker (the demo cell as group `cellbus`, edge node
    /// `demo`); with a config, it replaces the `[mqtt]` table's broker (keeping its TLS
    /// files for `mqtts://`; without a table, TLS trusts the system's roots).
    pub mqtt: Option<String>,
    /// `--mqtt-mode`: Sparkplug B or JSON, overriding the `[mqtt]` table's `mode`.
    pub mqtt_mode: Option<MqttMode>,
    /// `--mqtt-node`: the Sparkplug edge node id, overriding the `[mqtt]` table's.
    pub mqtt_node: Option<String>,
    /// `--mqtt-primary-host`: the Sparkplug primary host whose STATE gates the births.
    pub mqtt_primary_host: Option<String>,
    /// `--opcua IP:PORT`: serve the cell over OPC UA there (port 0: any free port); with
    /// a config, it replaces the `[opcua]` table's endpoint.
    pub opcua: Option<SocketAddr>,
}

impl Default for ServeOptions {
    fn default() -> Self {
        Self {
            listen: DEFAULT_LISTEN,
            config: None,
            data_dir: PathBuf::from(DEFAULT_DATA_DIR),
            retain: DEFAULT_RETAIN,
            retain_audit: DEFAULT_RETAIN_AUDIT,
            allow_writes: false,
            token: None,
            read_token: None,
            mqtt: None,
            mqtt_mode: None,
            mqtt_node: None,
            mqtt_primary_host: None,
            opcua: None,
        }
    }
}
