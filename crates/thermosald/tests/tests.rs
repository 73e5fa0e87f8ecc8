//! Integration tests of the thermosald crate: one test binary (see Cargo.toml).

#[cfg(feature = "io")]
mod client;
mod common;
mod exchange;
mod roundtrip;
mod tables;
mod twin;
mod twin_line;
mod vectors;
