//! What every cellbus protocol shares, without I/O and without a clock.
//!
//! - [`checksum`]: the XOR block check of the JBC protocol and CRC-16/MODBUS.
//! - [`codec`]: the [`Codec`] trait every protocol's frame layer implements, and the
//!   [`Deframer`] that turns a byte stream into frames, resynchronising on bad input.
//! - [`scan`]: a scanner for streams framed by a start and an end byte (`STX … ETX`,
//!   `% … LF`).
//! - [`ascii`]: fixed-width ASCII numbers as the serial protocols carry them.
//! - [`backoff`]: waits that double after each failure, up to a cap.
//! - [`calendar`]: the calendar date of a day count.
//! - [`exchange`]: one request/response exchange with retries as a sans-IO state machine,
//!   judged by a protocol's [`exchange::Matcher`]; `link` drives it on a line.
//! - [`failure`]: the kinds of failure every client error reports ([`FailureKind`]).
//! - [`device`]: the interface between a simulated device and the line that serves it,
//!   and seeded [`device::FaultInjector`] for realistic line trouble.
//! - [`operator`]: the operator commands a simulated device takes while it serves (a
//!   command table, one parser, `help`), each device's set defined next to its twin.
//! - [`words`]: counts as messages say them ([`words::Bytes`]: "1 byte", "8 bytes").
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod ascii;
pub mod backoff;
pub mod calendar;
pub mod checksum;
pub mod codec;
pub mod device;
pub mod exchange;
pub mod failure;
pub mod operator;
pub mod scan;
#[cfg(test)]
mod test_lines;
pub mod words;

pub use codec::{Codec, Deframer, Resync};
pub use device::{Device, LineTiming, Transmit};
pub use exchange::{Exchange, ExchangeError, Matcher, Policy, Trouble, Verdict};
pub use failure::{Failure, FailureKind};
