//! The registry: the device kinds and the interfaces of the gateway crate, each named by
//! one line here. Nothing in the core names them; it reads them from here (the config
//! through [`builtin`], `serve` through [`Registry::interfaces`]). An interface of a crate
//! of its own (OPC UA: `cellbus-opcua`) is added by the binary that includes it
//! ([`Registry::with_interface`]).

use std::path::Path;

use crate::config::{self, CellConfig, ConfigError, Plugins};
use crate::demo::DemoStart;
use crate::driver::{cross, jbc, modbus, panasonic, thermosald};
use crate::northbound::{self, Northbound};

/// What the gateway can speak to and serve: the config's device kinds and interface
/// tables, and the interfaces `serve` starts.
#[derive(Clone, Debug)]
pub struct Registry {
    /// The device kinds and the interface tables a config file may name.
    pub config: Plugins,
    /// The interfaces, started in this order when configured.
    pub interfaces: Vec<&'static dyn Northbound>,
    /// The kinds' parts of the demo cell `serve` starts without a configuration, in this
    /// order.
    pub demos: Vec<DemoStart>,
}

impl Registry {
    /// With the interface `interface` too, started after those already listed; a config
    /// file may then have its table.
    pub fn with_interface(mut self, interface: &'static dyn Northbound) -> Self {
        self.config = self.config.with_table(interface.table());
        self.interfaces.push(interface);
        self
    }

    /// Without the interface whose table is `table`, which this build was made without:
    /// a config file naming the table is refused where the table is, with `why`.
    pub fn with_interface_left_out(mut self, table: &'static str, why: &'static str) -> Self {
        self.config = self.config.with_table_left_out(table, why);
        self
    }
}

/// The gateway crate's own device kinds and interfaces (MQTT; IPC-CFX with the `cfx`
/// feature, and without it a config's `[cfx]` table is refused in words).
pub fn builtin() -> Registry {
    let config = Plugins::default()
        .with_kind(jbc::KIND)
        .with_kind(thermosald::KIND)
        .with_kind(cross::KIND)
        .with_kind(panasonic::KIND)
        .with_kind(modbus::KIND);
    let demos: Vec<DemoStart> = vec![
        jbc::demo::start,
        thermosald::demo::start,
        cross::demo::start,
        panasonic::demo::start,
    ];
    let registry = Registry {
        config,
        interfaces: Vec::new(),
        demos,
    }
    .with_interface(&northbound::mqtt::Mqtt);
    #[cfg(feature = "cfx")]
    let registry = registry.with_interface(&northbound::cfx::Cfx);
    #[cfg(not(feature = "cfx"))]
    let registry = registry.with_interface_left_out("cfx", NO_CFX_TABLE);
    registry
}

/// Why a build without the `cfx` feature refuses a config's `[cfx]` table.
#[cfg(not(feature = "cfx"))]
pub const NO_CFX_TABLE: &str = "this build of cellbus has no IPC-CFX interface (it was built \
     without the `cfx` feature): remove the [cfx] table, or use a build with IPC-CFX";

/// Reads and checks the configuration at `path` with the gateway crate's own kinds and
/// interfaces.
pub fn check_config(path: &Path) -> Result<CellConfig, ConfigError> {
    config::check_config(path, &builtin().config)
}

/// Checks configuration text (`path` names it in errors) with the gateway crate's own
/// kinds and interfaces.
pub fn parse_config(text: &str, path: &Path) -> Result<CellConfig, ConfigError> {
    config::parse_config(text, path, &builtin().config)
}
