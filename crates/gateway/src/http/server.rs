//! The HTTP server loop with the limits an exposed gateway needs: [`kit::http::server`],
//! shared with the historian.

pub use kit::http::server::*;
