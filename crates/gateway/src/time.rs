//! Wall-clock timestamps as the history and the API carry them: [`kit::time`], shared with
//! the historian.

pub use kit::time::*;
