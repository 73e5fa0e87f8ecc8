//! The cellbus gateway (work in progress).
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod driver;
pub mod point;
pub mod store;
pub mod time;
