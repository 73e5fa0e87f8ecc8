//! The cellbus gateway: `cellbus serve` polls the cell, keeps its history and serves it over
//! HTTP, a live web page and Prometheus metrics.
//!
//! ```text
//!  config / demo ──► Cell ──► one LineTask per line ──► Driver per device ──► protocol client ──► link
//!                     │            │ value changes, events
//!                     │            ▼
//!                     │         Store (SQLite, writer thread) ◄── history, events, audit queries
//!                     ▼
//!                   HTTP (axum): API, SSE, /metrics, web page
//! ```
//!
//! - [`serve`] / [`Gateway`]: the whole thing, from [`ServeOptions`] to a graceful stop.
//! - [`config`]: the cell's TOML configuration, [`check_config`] and [`EXAMPLE_CONFIG`];
//!   interfaces and device kinds read their own tables and keys.
//! - [`driver`]: the device kinds, one module each, mapping a device onto points: JBC,
//!   Thermosald (several regulators on one line), CROSS (JBUS) and Panasonic (a TCP
//!   machine whose client keeps its own connections and whose R messages become events)
//!   and generic Modbus (registers named in the config).
//! - [`northbound`]: the interfaces behind [`northbound::Northbound`]: MQTT here, OPC UA
//!   in a crate of its own (`cellbus-opcua`) that the `cellbus` binary includes through
//!   its `opcua` feature.
//! - [`plugins`]: the registry naming the gateway's device kinds and interfaces, to which
//!   a binary adds others; DESIGN.md, "Adding a device kind" and "Adding an interface",
//!   has the steps.
//! - [`scheduler`]: one task per line, strict serialisation, exponential backoff of silent
//!   devices with prompt promotion, line reopening.
//! - [`cell`]: the live state (values with time and quality), the change stream.
//! - [`store`]: SQLite history (WAL, FULL sync, batched writer thread, retention,
//!   downsampled queries).
//! - [`http`]: the API, described at `/api/openapi.json`, and the web page at `/`.
//! - [`metrics`]: Prometheus metrics.
//! - [`demo`]: the simulated cell `serve` starts without a configuration (each kind's twin
//!   from its own `driver::<kind>::demo`).
//! - [`oplog`]: what the operator reads on stderr: events at their kind's level, ups and
//!   downs throttled, hints.
//! - [`health`]: `/healthz`'s judgement: ok, degraded or failing, with reasons.
//! - [`load`]: each serial line's share of its time the configured polls need.
//! - [`fuzzing`]: the bodies of the fuzz targets over the configuration, query times and
//!   query strings.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod alarm;
pub mod cell;
pub mod config;
pub mod demo;
pub mod driver;
pub mod event;
pub mod fuzzing;
pub mod health;
pub mod http;
pub mod load;
pub mod metrics;
pub mod northbound;
pub mod oplog;
pub mod options;
pub mod plugins;
pub mod point;
pub mod pollers;
pub mod production;
pub mod reload;
pub mod scheduler;
pub mod serve;
pub mod service;
pub mod store;
pub mod time;
pub mod write;

#[cfg(test)]
mod testing;

pub use config::{CellConfig, ConfigError, EXAMPLE_CONFIG};
pub use plugins::{check_config, parse_config};
pub use serve::{
    DEFAULT_DATA_DIR, DEFAULT_LISTEN, DEFAULT_RETAIN, Gateway, MALLOC_ARENAS,
    MALLOC_MMAP_THRESHOLD, OptionError, ServeOptions, TOKEN_ENV, serve, tune_malloc,
};
