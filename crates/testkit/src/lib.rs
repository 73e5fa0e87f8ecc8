//! Test and bench tools shared by the cellbus crates.
//!
//! - [`noise`]: [`Noise`], a seeded, sans-IO byte mangler with the trouble of a bad
//!   serial line (flipped bits, lost, inserted and duplicated bytes, whole chunks lost,
//!   bursts), and its counts.
//! - [`proxy`]: a noisy line between two byte streams ([`noisy_pipe`]) or between a TCP
//!   client and a server ([`NoisyProxy`]), in both directions, with an outage switch that
//!   loses everything (a pulled cable).
//! - [`tricks`]: [`Tricky`], any simulated device behind a line that plays scripted
//!   tricks on its next replies (drop, damage, delay, replace, bytes or an echo before),
//!   for client tests.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod noise;
pub mod proxy;
pub mod tricks;

pub use noise::{Noise, NoiseConfig, NoiseCounts};
pub use proxy::{LineControl, NoisyProxy, noisy_pipe};
pub use tricks::{At, Tap, Trick, Tricky};
