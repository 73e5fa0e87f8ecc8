//! What `cellbus serve` was asked for: the options every part of the gateway may read (the
//! interfaces take their flags from here when they start).

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use crate::config::Settings;

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
#[derive(Debug, Clone, PartialEq)]
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
    /// What the command line says to the interfaces (`--mqtt …`, `--opcua …`): each
    /// interface's own type, which it takes back with [`Flags::get`].
    pub flags: Flags,
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
            flags: Flags::default(),
        }
    }
}

/// The interfaces' command-line flags, one value of each interface's own type.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Flags(Vec<Settings>);

impl Flags {
    /// With `flags` (an interface's own type).
    pub fn with<T: std::any::Any + std::fmt::Debug + PartialEq + Send + Sync>(
        mut self,
        flags: T,
    ) -> Self {
        self.0.push(Settings::new(flags));
        self
    }

    /// The flags of type `T`, if given.
    pub fn get<T: std::any::Any>(&self) -> Option<&T> {
        self.0.iter().find_map(Settings::get)
    }
}
