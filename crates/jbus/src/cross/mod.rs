//! The Chloride CROSS static transfer switch over JBUS: its register map as named, typed,
//! scaled values, and a twin of the switch.
//!
//! The CROSS answers function 3 only, on four areas (see [`map`]). `read` (with the `io`
//! feature) reads them through the client with the requests of [`read_plan`] (one per
//! area); any other
//! master decodes its answers with [`CrossState::from_blocks`]:
//!
//! ```
//! use jbus::cross::{CrossState, read_plan};
//! # let words = |start: u16, count: u16| vec![0u16; count as usize];
//! let blocks: Vec<(u16, Vec<u16>)> =
//!     read_plan().into_iter().map(|(start, count)| (start, words(start, count))).collect();
//! let state = CrossState::from_blocks(&blocks).expect("every area read");
//! println!("{state}"); // which source feeds the load, alarms, measures with units
//! ```
//!
//! - [`bits`]: the six operating conditions (S1, S2, S1-SW, S2-SW, LOAD, SYSTEM), each an
//!   off, alarm and on word of named bits.
//! - [`mimic`]: the mimic diagram's 15 segments and the lamps of its 11 elements.
//! - [`measure`]: ratings and measures with their units and scaling.
//! - [`state`]: [`CrossState`], all of it, shown in words.
//! - [`points`]: the measures and ratings as named points with their units
//!   ([`MEASURES`], [`RATINGS`]), for `cellbus cross status --json` and the gateway.
//! - [`change`]: what changed between two readings (a transfer, alarms raised and
//!   cleared), for `cellbus cross watch` and the gateway's events.
//! - [`device`]: [`device::CrossTwin`], the simulated switch.

pub mod bits;
pub mod change;
pub mod device;
pub mod map;
pub mod measure;
pub mod mimic;
pub mod points;
pub mod state;

pub use bits::{Condition, Flags, InternalState, NamedBit};
pub use change::{Change, Discrete, Load, Transfer};
pub use map::{Area, MAP_LEN, addr, block_is_defined, is_defined, read_plan, read_requests};
pub use measure::{
    Amperes, Celsius, Degrees, Hertz, KiloVoltAmperes, Measures, Phases, Ratings, Volts,
    WholeAmperes,
};
pub use mimic::{Element, Lamps, Mimic, Segment, Segments};
pub use points::{Amount, MEASURES, Phase, Quantity, RATINGS};
pub use state::{CrossState, Feed, MissingWord, Source};

#[cfg(feature = "io")]
use crate::client::{Client, ClientError};
#[cfg(feature = "io")]
use crate::rtu::UnitId;

/// Reads the whole state of a CROSS at `unit` through `client`: one function-3 read per
/// block of [`read_plan`], decoded into named, scaled values.
#[cfg(feature = "io")]
pub async fn read(client: &mut Client, unit: UnitId) -> Result<CrossState, ClientError> {
    let mut image = [0u16; MAP_LEN];
    for (start, count) in read_plan() {
        let words = client.read_holding_registers(unit, start, count).await?;
        // The client checked the answer's count against the request.
        for (slot, word) in image.iter_mut().skip(usize::from(start)).zip(words) {
            *slot = word;
        }
    }
    Ok(CrossState::from_image(&image))
}
