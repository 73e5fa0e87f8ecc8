//! The only cellbus crate that touches the OS.
//!
//! - [`Endpoint`]: where a line is, as a URL (`serial:///dev/ttyUSB0?baud=19200&framing=8E1`,
//!   `tcp://host:port` for ser2net-style serial servers and simulators, `modbus-tcp://host:502`
//!   for Modbus TCP), with its serial
//!   settings and RS-485 options.
//! - [`Line`]: an open line to send and receive bytes, with RS-485 direction control and
//!   local-echo discarding; [`SharedLine`] queues the devices that share one line.
//! - [`exchange`]: drives a sans-IO [`wire::Exchange`] (request, answer, retries) on a
//!   line.
//! - [`serve`]: puts a simulated [`wire::Device`] on a TCP listener or a PTY, optionally at
//!   the speed of a real serial line.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod endpoint;
pub mod exchange;
pub mod line;
pub mod serve;

pub use endpoint::{
    DataBits, Endpoint, EndpointError, Parity, SerialSettings, StopBits, TcpFraming,
};
pub use exchange::LineExchangeError;
pub use line::{Line, LineError, OpenError, SharedLine};
