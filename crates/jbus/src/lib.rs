//! JBUS (Modbus RTU) without I/O, and the Chloride CROSS static transfer switch.
//!
//! - [`rtu`]: the generic Modbus RTU layer every Modbus device on the plant's lines
//!   speaks: frames both directions, typed requests and responses, the check that a
//!   response answers a request, line timing.
//! - [`cross`]: the CROSS's register map as named, scaled values ([`cross::CrossState`]),
//!   the fewest reads that fetch it ([`cross::read_plan`]), and a twin of the switch
//!   ([`cross::device::CrossTwin`]) with its transfers and its exact refusals.
//! - [`slave`]: a generic Modbus server model (coils, discrete inputs, holding and input
//!   registers from a small map file, or everything writable), to test the generic layer.
//! - [`client`]: the async master over a `link` line: one request in flight per line,
//!   timeouts, retries, the inter-frame silence, answers checked before they are accepted.
//! - [`annotate`]: frames of a capture in words, requests and responses told apart.
//! - [`data`]: values spanning registers (16-, 32-, 64-bit integers, floats, strings,
//!   bits) in a device's byte and word order, with a linear scale.
//! - [`plan`]: the fewest reads that fetch a set of wanted registers and bits, split
//!   further when a device refuses a merged range.
//!
//! Apart from [`client`], nothing here reads a clock or touches a port: time comes in as
//! `now`, bytes through `wire::Codec`s and `wire::device::Model`s, which the `link` crate
//! serves.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod annotate;
#[cfg(feature = "io")]
pub mod client;
pub mod cross;
pub mod data;
pub mod plan;
pub mod rtu;
pub mod slave;
pub mod tcp;
#[cfg(test)]
mod test_util;

#[doc(hidden)]
pub mod fuzzing;
