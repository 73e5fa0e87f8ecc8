//! The JTSE's commands and the meaning of their data, from both editions of the protocol.
//!
//! A [`Code`] is one control code (`ST1`, `A11`, `SMN`…) with its spec meaning: whether it
//! can be read or written, its unit, its words. [`interpret`] turns the data a station
//! answers into a [`Reading`] with words (`350 °C`, `No tool (9)`, `tool on, cooling off,
//! suction off`). The spec's tables are enums here: [`Tool`], [`ToolError`],
//! [`StationError`], [`NakReason`], [`PortStatus`], [`WorkMode`].
//!
//! Only port 1 exists on a JTSE: a code naming another port does not parse (the CLI refuses
//! it before the wire), while a station receiving one answers NAK 4.
//!
//! - `port`: ports and tools.
//! - `codes`: the control codes.
//! - `value`: units, values and [`interpret`].
//! - `table`: the spec's tables as enums.

mod codes;
mod port;
mod table;
mod value;

pub use codes::*;
pub use port::*;
pub use table::*;
pub use value::*;

#[cfg(test)]
mod tests;
