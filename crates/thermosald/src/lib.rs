//! Thermosald ISC/RS485 impulse-sealer temperature regulators, sans-IO.
//!
//! Up to eight regulators (addresses 0–7) share one RS-485 line at 9600 8N1; the master
//! (controller) asks, a regulator answers 200 ms later. This crate has no I/O and no clock:
//!
//! - [`frame`]: the `% addr msg Q/R count _ data… LF` layout, a resynchronising
//!   [`wire::Codec`], typed [`frame::Address`], [`frame::Target`], [`frame::MessageNumber`].
//! - [`request`]: one typed request per message number (13 is refused).
//! - [`tables`]: machine, settings, run-time and service data as named, scaled, ranged
//!   items; `set sealing temperature = 180` becomes the wire digits `180`.
//! - [`diagnostic`]: fault/warning numbers (35, 36 and the twin's faults) in words.
//! - [`exchange`]: the master's side of one exchange (is this frame my answer, an echo
//!   mismatch, or someone else's?) and the line timing (40/200/40 ms).
//! - [`device`]: a twin of a line of regulators with a sealing band's physics, faults,
//!   calibration and EEPROM, as a [`wire::device::Model`].
//!
//! Sources: thermosald-isc-rs485.txt and the "Thermosald ISC/RS485: decisions" in
//! specs/README.md; where both are silent, the module docs say what this crate chose.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod device;
pub mod diagnostic;
pub mod exchange;
pub mod frame;
pub mod request;
pub mod tables;

#[doc(hidden)]
pub mod fuzzing;

pub use frame::{Address, Direction, Frame, FrameCodec, MessageNumber, RawValue, Target};
pub use request::{Command, Message, Read, Request, Write};
pub use tables::{Item, Table};
