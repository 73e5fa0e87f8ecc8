//! Thermosald ISC/RS485 impulse-sealer temperature regulators: a sans-IO core and an async
//! client.
//!
//! Up to eight regulators (addresses 0–7) share one RS-485 line at 9600 8N1; the master
//! (controller) asks, a regulator answers 200 ms later. Apart from [`client`], which talks
//! over a `link` line, the modules have no I/O and no clock:
//!
//! - [`frame`]: the `% addr msg Q/R count _ data… LF` layout, a resynchronising
//!   [`wire::Codec`], typed [`frame::Address`], [`frame::Target`], [`frame::MessageNumber`].
//! - [`request`]: one typed request per message number (13 is refused).
//! - [`tables`]: machine, settings, run-time and service data as named, scaled, ranged
//!   items; `set sealing temperature = 180` becomes the wire digits `180`.
//! - [`diagnostic`]: fault/warning numbers (35, 36 and the twin's faults) in words.
//! - [`exchange`]: the master's side of one exchange (is this frame my answer, an echo
//!   mismatch, or someone else's?) and the line timing (40/200/40 ms).
//! - [`client`]: the async master over a `link` line: timing windows, timeout, retries,
//!   echo checks, several regulators sharing one line.
//! - [`device`]: a twin of a line of regulators with a sealing band's physics, faults,
//!   calibration and EEPROM, as a [`wire::device::Model`].
//!
//! ```
//! use std::time::{Duration, Instant};
//! use thermosald::exchange::{Answer, Classified, Exchange};
//! use thermosald::{Address, FrameCodec, Read, Table, Write, device::RegulatorBus};
//! use wire::{Codec, device::Model};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let address = Address::new(0)?;
//! let sealing = Table::Settings.find("sealing temperature")?;
//! let write = Exchange::new(address.into(), Write::value(sealing, 180.0)?.into())?;
//! assert_eq!(write.query_bytes(), b"%012Q150180\n");
//!
//! // The twin answers 200 ms after the question; the master checks the echo.
//! let t0 = Instant::now();
//! let mut line = RegulatorBus::new(&[address], t0)?;
//! let answer = line.handle(Ok(write.query().clone()), t0).remove(0);
//! assert_eq!(answer.delay, Duration::from_millis(200));
//! let (echo, _) = FrameCodec.decode(&answer.bytes)?.ok_or("a whole frame")?;
//! assert_eq!(write.classify(&echo), Classified::Answer(Answer::Echoed));
//!
//! // A read 240 ms later (the line's turnaround) gives named, scaled values.
//! let read = Exchange::new(address.into(), Read::all(Table::Runtime).into())?;
//! let answer = line.handle(Ok(read.query().clone()), t0 + Duration::from_millis(240)).remove(0);
//! let (reply, _) = FrameCodec.decode(&answer.bytes)?.ok_or("a whole frame")?;
//! if let Classified::Answer(Answer::Values(values)) = read.classify(&reply) {
//!     for reading in values.readings() {
//!         println!("{:>2} {} = {reading}", reading.item().index(), reading.item().name());
//!     }
//! }
//! # Ok(())
//! # }
//! ```
//!
//! Sources: thermosald-isc-rs485.txt and the "Thermosald ISC/RS485: decisions" in
//! specs/README.md; where both are silent, the module docs say what this crate chose.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

#[cfg(feature = "io")]
pub mod client;
pub mod device;
pub mod diagnostic;
pub mod exchange;
pub mod frame;
pub mod request;
pub mod tables;

#[doc(hidden)]
pub mod fuzzing;

pub use exchange::Exchange;
pub use frame::{Address, Direction, Frame, FrameCodec, MessageNumber, RawValue, Target};
pub use request::{Command, Message, Read, Request, Write};
pub use tables::{Item, Table};
