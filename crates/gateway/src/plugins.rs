//! The registry: the device kinds and the interfaces this build of the gateway has, each
//! named by one line here. Nothing in the core names them; it reads them from here (the
//! config through [`builtin`], `serve` through [`Registry::interfaces`]).

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

/// The gateway's own device kinds and interfaces.
pub fn builtin() -> Registry {
    let interfaces: Vec<&'static dyn Northbound> =
        vec![&northbound::mqtt::Mqtt, &northbound::opcua::Opcua];
    let mut config = Plugins::default()
        .with_kind(jbc::KIND)
        .with_kind(thermosald::KIND)
        .with_kind(cross::KIND)
        .with_kind(panasonic::KIND)
        .with_kind(modbus::KIND);
    for interface in &interfaces {
        config = config.with_table(interface.table());
    }
    let demos: Vec<DemoStart> = vec![
        jbc::demo::start,
        thermosald::demo::start,
        cross::demo::start,
        panasonic::demo::start,
    ];
    Registry {
        config,
        interfaces,
        demos,
    }
}

/// Reads and checks the configuration at `path` with the gateway's own kinds and
/// interfaces.
pub fn check_config(path: &Path) -> Result<CellConfig, ConfigError> {
    config::check_config(path, &builtin().config)
}

/// Checks configuration text (`path` names it in errors) with the gateway's own kinds and
/// interfaces.
pub fn parse_config(text: &str, path: &Path) -> Result<CellConfig, ConfigError> {
    config::parse_config(text, path, &builtin().config)
}
