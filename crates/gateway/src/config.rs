//! The cell's configuration (TOML): lines, the devices on them, and how often to poll.
//!
//! Parsing and checking live in this module; see [`EXAMPLE_CONFIG`] for the format.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Duration;

use link::Endpoint;

use crate::driver::DriverConfig;

/// A checked configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct CellConfig {
    /// The file it came from, if any (the demo cell has none).
    pub source: Option<PathBuf>,
    /// The token writes need, if the file sets one.
    pub token: Option<String>,
    /// The lines, in file order.
    pub lines: Vec<LineConfig>,
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
}
