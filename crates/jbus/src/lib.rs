//! The jbus protocol (work in progress).
#![forbid(unsafe_code)]
#![warn(missing_docs)]
