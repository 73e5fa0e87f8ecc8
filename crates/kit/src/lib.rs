//! The vocabulary and kits the cellbus gateway and the plant historian share, so that the
//! historian (and `cellbus mqtt sub`) need not depend on the gateway: no SQLite, no OPC UA,
//! no device protocol here.
//!
//! - [`time`]: [`Timestamp`](time::Timestamp), milliseconds since the epoch, with the time
//!   forms people type (RFC 3339, `now`, `-1h`).
//! - [`value`]: a point's [`Value`](value::Value) and its [`Quality`](value::Quality), the
//!   one quality of the gateway and the historian (Sparkplug's wire enum stays in the
//!   `sparkplug` crate).
//! - [`history`]: the history API's query, range, time and limit checks, and its answer's
//!   series (raw samples or buckets).
//! - [`http`]: the APIs' error answer and the hardened HTTP server loop.
//! - [`mqtt`]: broker URLs, the TLS files and rustls setup, the largest packet accepted.
//! - [`bounded`]: names cut to a stored length, throttled log lines, files read up to a
//!   size.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod bounded;
pub mod history;
pub mod http;
pub mod mqtt;
pub mod time;
pub mod value;
