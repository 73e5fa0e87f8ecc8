//! The cellbus gateway (work in progress).
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod cell;
pub mod config;
pub mod driver;
pub mod http;
pub mod metrics;
pub mod point;
pub mod scheduler;
pub mod store;
pub mod time;

#[cfg(test)]
mod testing;
