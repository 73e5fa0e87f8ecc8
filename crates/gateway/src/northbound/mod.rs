//! The gateway's northbound side: interfaces that publish the cell to other systems.
//!
//! The rule every interface here follows: it reads only from the cell's one change stream
//! ([`Cell::subscribe`](crate::cell::Cell::subscribe), plus
//! [`Cell::devices`](crate::cell::Cell::devices) for births) and writes only through the
//! cell's one guarded write path; it never polls a device or knows a field protocol.
//!
//! - [`mqtt`]: the cell on an MQTT broker (rumqttc), as a Sparkplug B edge node
//!   ([`sparkplug::EdgeNode`]) or as plain JSON, with store and forward.
//! - OPC UA, the cell as an OPC UA server (async-opcua), is a crate of its own
//!   (`cellbus-opcua`, in `crates/opcua`) behind the binary's `opcua` feature: it
//!   implements [`Northbound`] with only what this crate makes public.
//! - [`cfx`]: the cell's placement machines as IPC-CFX endpoints over AMQP 1.0
//!   (fe2o3-amqp), behind this crate's `cfx` feature (on by default).
//!
#[cfg(feature = "cfx")]
pub mod cfx;
pub mod mqtt;
#[cfg(test)]
mod tests;
pub mod tls;

use std::fmt;
use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;

use tokio::sync::watch;
use tokio::task::JoinHandle;

use crate::cell::Cell;
use crate::config::{CellConfig, TableReader};
use crate::http::WritePolicy;
use crate::options::ServeOptions;

/// This machine's host name as an id (a Sparkplug id: no `/`, `+`, `#`), else `cellbus`:
/// the MQTT edge node's default id and the OPC UA application URI's host part.
pub fn default_edge_node_id() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .map(|h| h.trim().to_owned())
        .filter(|h| sparkplug::Id::new(h.as_str()).is_ok())
        .unwrap_or_else(|| "cellbus".to_owned())
}

/// An interface that serves the cell to other systems: what `serve` asks of each. It is
/// listed once in a [`Registry`](crate::plugins::Registry) (the gateway's own in
/// [`crate::plugins::builtin`], another crate's by the binary through
/// [`Registry::with_interface`](crate::plugins::Registry::with_interface)); `serve` starts
/// every one the config or the options ask for and stops them in turn. It reads only the
/// cell's change stream and writes only through the cell's write path.
pub trait Northbound: Sync + fmt::Debug {
    /// Its name in logs and messages (`mqtt`).
    fn name(&self) -> &'static str;

    /// The reader of its table in the config file (`[mqtt]`).
    fn table(&self) -> &'static dyn TableReader;

    /// Starts it when its table or the options ask for it (`Ok(None)`: not asked for).
    /// An error stops the gateway's start: a port taken, a password variable not set.
    fn start<'a>(&'a self, start: Start<'a>) -> BoxStart<'a>;
}

/// What [`Northbound::start`] returns.
pub type BoxStart<'a> = Pin<Box<dyn Future<Output = anyhow::Result<Option<Running>>> + Send + 'a>>;

/// What an interface starts with.
#[derive(Debug, Clone)]
pub struct Start<'a> {
    /// The live cell: its change stream, its points, its write path.
    pub cell: &'a Arc<Cell>,
    /// The checked configuration (the interface's table is in
    /// [`CellConfig::interfaces`]).
    pub config: &'a CellConfig,
    /// What `cellbus serve` was asked for.
    pub options: &'a ServeOptions,
    /// Whether this is the demo cell (no config file).
    pub demo: bool,
    /// Who may write.
    pub writes: &'a WritePolicy,
    /// Turns true when the gateway stops.
    pub stopped: watch::Receiver<bool>,
}

/// A started interface.
#[derive(Debug)]
pub struct Running {
    /// Its name.
    pub name: &'static str,
    /// Where clients reach it, printed under `listening on …` at start
    /// (`opcua on opc.tcp://…`); `None` for an interface that connects out (MQTT).
    pub url: Option<String>,
    /// Ends when it has stopped.
    pub task: JoinHandle<()>,
}
