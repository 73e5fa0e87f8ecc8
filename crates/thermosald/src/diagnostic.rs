//! Fault/warning numbers: run-time data item 2.
//!
//! The spec names two diagnostics: 35 CALIBRATING REQUEST (after a master reset, until
//! automatic balancing runs) and 36 CALIBRATING IN PROGRESS (during balancing). It does not
//! list the fault numbers; the four faults below are numbered by this crate (1–4) and the
//! twin in [`crate::device`] reports them. A real regulator's manual may number them
//! differently: [`describe`] says "unknown" for anything else rather than guessing.

/// No fault, no warning: the regulator is ready to work.
pub const NONE: u16 = 0;
/// Diagnostic 35, CALIBRATING REQUEST: shown after a master reset until balancing (15).
pub const CALIBRATION_REQUEST: u16 = 35;
/// Diagnostic 36, CALIBRATING IN PROGRESS: shown while automatic balancing runs.
pub const CALIBRATION_IN_PROGRESS: u16 = 36;

/// A fault the regulator latches; clear faults (14) clears it once its cause is gone.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Fault {
    /// The sealing band circuit is open (broken band, loose terminal).
    OpenBand,
    /// Part of the band is bypassed: its resistance is below the calibrated value divided
    /// by the partial short-circuit factor (machine item 8).
    ShortCircuit,
    /// The band current exceeds the set maximum current (service item 13).
    OverCurrent,
    /// The band did not reach the sealing temperature within the sealing impulse.
    TemperatureNotReached,
}

impl Fault {
    /// Every fault, most serious first (the order in which the twin reports them).
    pub const ALL: [Fault; 4] = [
        Fault::OpenBand,
        Fault::ShortCircuit,
        Fault::OverCurrent,
        Fault::TemperatureNotReached,
    ];

    /// The fault/warning number (this crate's numbering; see the module doc).
    pub const fn code(self) -> u16 {
        match self {
            Fault::OpenBand => 1,
            Fault::ShortCircuit => 2,
            Fault::OverCurrent => 3,
            Fault::TemperatureNotReached => 4,
        }
    }

    /// The fault with this number.
    pub fn from_code(code: u16) -> Option<Fault> {
        Fault::ALL.into_iter().find(|f| f.code() == code)
    }

    /// What the fault means, for an operator.
    pub const fn description(self) -> &'static str {
        match self {
            Fault::OpenBand => "sealing band open",
            Fault::ShortCircuit => "sealing band short circuit",
            Fault::OverCurrent => "over-current",
            Fault::TemperatureNotReached => "sealing temperature not reached",
        }
    }
}

/// A fault/warning number in words (for `watch` and logs).
pub fn describe(code: u16) -> &'static str {
    match code {
        NONE => "ready",
        CALIBRATION_REQUEST => "calibration request",
        CALIBRATION_IN_PROGRESS => "calibration in progress",
        other => Fault::from_code(other).map_or("unknown fault", Fault::description),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fault_numbers_are_distinct_and_differ_from_the_spec_diagnostics() {
        for (i, a) in Fault::ALL.iter().enumerate() {
            assert_eq!(Fault::from_code(a.code()), Some(*a));
            assert!(![NONE, CALIBRATION_REQUEST, CALIBRATION_IN_PROGRESS].contains(&a.code()));
            for b in &Fault::ALL[i + 1..] {
                assert_ne!(a.code(), b.code());
            }
        }
    }

    #[test]
    fn diagnostics_are_described_in_words() {
        assert_eq!(describe(35), "calibration request");
        assert_eq!(describe(36), "calibration in progress");
        assert_eq!(describe(0), "ready");
        assert_eq!(describe(1), "sealing band open");
        assert_eq!(describe(77), "unknown fault");
    }
}
