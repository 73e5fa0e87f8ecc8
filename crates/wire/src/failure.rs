//! One taxonomy of failures for every client: what kind of thing went wrong, so the CLI's
//! exit codes and messages and the gateway's metrics and quality read the same answer.
//!
//! Every client error implements [`Failure`]. The kinds separate our own mistakes
//! ([`FailureKind::Usage`]: a request the crate refused to build) from what the device and
//! its line did, so a bad request is never booked as a device refusal.

use std::fmt;

/// What kind of failure ended a request.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum FailureKind {
    /// Our own request or settings were wrong: refused before anything reached the wire.
    Usage,
    /// The device understood the request and said no (a NAK, an exception, a value it
    /// kept).
    Refused,
    /// No answer in time.
    Timeout,
    /// Damaged or meaningless answers.
    Damaged,
    /// Trouble on the line that does not close it (an adapter echo that differs,
    /// transmission errors the device reported).
    Line,
    /// The line or connection is gone (closed, an I/O error) and must be reopened.
    Disconnected,
}

impl FailureKind {
    /// Every kind.
    pub const ALL: [FailureKind; 6] = [
        FailureKind::Usage,
        FailureKind::Refused,
        FailureKind::Timeout,
        FailureKind::Damaged,
        FailureKind::Line,
        FailureKind::Disconnected,
    ];

    /// The name (`timeout`).
    pub fn as_str(self) -> &'static str {
        match self {
            FailureKind::Usage => "usage",
            FailureKind::Refused => "refused",
            FailureKind::Timeout => "timeout",
            FailureKind::Damaged => "damaged",
            FailureKind::Line => "line",
            FailureKind::Disconnected => "disconnected",
        }
    }

    /// Whether the device, its absence or its line is the cause, rather than our request.
    pub fn is_device_side(self) -> bool {
        self != FailureKind::Usage
    }
}

impl fmt::Display for FailureKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// An error that knows its [`FailureKind`]: every client error implements it.
pub trait Failure: std::error::Error {
    /// What kind of failure this is.
    fn kind(&self) -> FailureKind;
}

impl<F: Failure> Failure for Box<F> {
    fn kind(&self) -> FailureKind {
        (**self).kind()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_usage_is_our_own_doing() {
        let ours: Vec<FailureKind> = FailureKind::ALL
            .into_iter()
            .filter(|k| !k.is_device_side())
            .collect();
        assert_eq!(ours, [FailureKind::Usage]);
    }

    #[test]
    fn kinds_have_distinct_names() {
        let mut names: Vec<&str> = FailureKind::ALL.iter().map(|k| k.as_str()).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), FailureKind::ALL.len());
    }
}
