//! Machine status (C2ST, 3.3-11) and the stop modes of remote start (C5ST, 3.3-13).

use std::fmt;

use serde::Serialize;

/// Width of the C2ST answer (`mmn`).
pub const STATUS_LEN: usize = 3;

/// What the machine is doing: the `mm` of the C2ST answer.
///
/// - **Run** (`00`): running in AUTO mode, including waiting for a board.
/// - **Ready** (`01`): everything else: normal stop; after RESET following an error until
///   Run; after a pick-up or recognition error stop; SEMI or MANU mode.
/// - **Error** (`02`): stopped by an error (parts exhaustion included) until RESET is
///   pressed. Pick-up and recognition errors do not count.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RunState {
    /// `00`.
    Run,
    /// `01`.
    Ready,
    /// `02`: error stop.
    Error,
}

impl RunState {
    /// The two digits on the wire.
    pub const fn code(self) -> &'static str {
        match self {
            RunState::Run => "00",
            RunState::Ready => "01",
            RunState::Error => "02",
        }
    }

    /// In words.
    pub const fn describe(self) -> &'static str {
        match self {
            RunState::Run => "run",
            RunState::Ready => "ready",
            RunState::Error => "error stop",
        }
    }
}

/// Who controls the machine: the `n` of the C2ST answer. C5 commands need [`Remote`].
///
/// [`Remote`]: ControlMode::Remote
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ControlMode {
    /// `0`: the host may transfer data; the operator runs the machine.
    Online,
    /// `1`: the host may also start and reset the machine (C5).
    Remote,
}

impl ControlMode {
    /// The digit on the wire.
    pub const fn code(self) -> char {
        match self {
            ControlMode::Online => '0',
            ControlMode::Remote => '1',
        }
    }

    /// In words.
    pub const fn describe(self) -> &'static str {
        match self {
            ControlMode::Online => "online",
            ControlMode::Remote => "remote",
        }
    }
}

/// The C2ST answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub struct MachineStatus {
    /// Run, ready or error.
    pub state: RunState,
    /// Online or remote.
    pub mode: ControlMode,
}

/// A C2ST answer that is not `mmn`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "machine status {found:?} is not 3 characters \"mmn\" with mm = 00, 01 or 02 and n = 0 or 1"
)]
pub struct StatusError {
    /// The data found.
    pub found: String,
}

impl MachineStatus {
    /// The three characters on the wire, e.g. `001` for Run + Remote.
    pub fn to_bytes(self) -> [u8; STATUS_LEN] {
        let [a, b] = match self.state {
            RunState::Run => *b"00",
            RunState::Ready => *b"01",
            RunState::Error => *b"02",
        };
        [a, b, self.mode.code() as u8]
    }

    /// Reads the three characters.
    pub fn parse(data: &[u8]) -> Result<MachineStatus, StatusError> {
        let state = match data.get(..2) {
            Some(b"00") => Some(RunState::Run),
            Some(b"01") => Some(RunState::Ready),
            Some(b"02") => Some(RunState::Error),
            _ => None,
        };
        let mode = match data.get(2..) {
            Some(b"0") => Some(ControlMode::Online),
            Some(b"1") => Some(ControlMode::Remote),
            _ => None,
        };
        match (state, mode) {
            (Some(state), Some(mode)) => Ok(MachineStatus { state, mode }),
            _ => Err(StatusError {
                found: String::from_utf8_lossy(data).into_owned(),
            }),
        }
    }
}

impl fmt::Display for MachineStatus {
    /// `run, remote`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}, {}", self.state.describe(), self.mode.describe())
    }
}

/// Where the machine stops when started remotely (C5ST**, 3.3-13).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum StopMode {
    /// `BL`: stop after every block (1BLOCK).
    OneBlock,
    /// `EP`: stop at the end of the program (EOP): one board.
    EndOfProgram,
    /// `CT`: continuous production.
    Continuous,
}

impl StopMode {
    /// Every mode.
    pub const ALL: [StopMode; 3] = [
        StopMode::OneBlock,
        StopMode::EndOfProgram,
        StopMode::Continuous,
    ];

    /// The two letters after `C5ST`.
    pub const fn code(self) -> &'static str {
        match self {
            StopMode::OneBlock => "BL",
            StopMode::EndOfProgram => "EP",
            StopMode::Continuous => "CT",
        }
    }

    /// The mode for its two letters.
    pub fn from_code(code: &str) -> Option<StopMode> {
        StopMode::ALL.into_iter().find(|mode| mode.code() == code)
    }

    /// In words.
    pub const fn describe(self) -> &'static str {
        match self {
            StopMode::OneBlock => "1-block stop",
            StopMode::EndOfProgram => "EOP stop",
            StopMode::Continuous => "continuous",
        }
    }
}

impl std::str::FromStr for StopMode {
    type Err = String;

    /// `bl`, `ep` or `ct`, in either case (as the CLI takes it).
    fn from_str(text: &str) -> Result<StopMode, String> {
        StopMode::from_code(&text.to_ascii_uppercase())
            .ok_or_else(|| format!("{text:?} is not a stop mode: use bl (1 block), ep (end of program) or ct (continuous)"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn status_001_is_run_and_remote_as_in_the_manual() {
        // 3.3-12: D1, size 3, data "001".
        let status = MachineStatus::parse(b"001").expect("valid status");
        assert_eq!(
            status,
            MachineStatus {
                state: RunState::Run,
                mode: ControlMode::Remote
            }
        );
        assert_eq!(&status.to_bytes(), b"001");
        assert_eq!(status.to_string(), "run, remote");
    }

    #[test]
    fn every_status_round_trips() {
        for state in [RunState::Run, RunState::Ready, RunState::Error] {
            for mode in [ControlMode::Online, ControlMode::Remote] {
                let status = MachineStatus { state, mode };
                assert_eq!(MachineStatus::parse(&status.to_bytes()), Ok(status));
            }
        }
        assert_eq!(
            &MachineStatus {
                state: RunState::Error,
                mode: ControlMode::Online
            }
            .to_bytes(),
            b"020"
        );
    }

    #[test]
    fn status_parsing_refuses_other_codes_and_lengths() {
        for bad in [&b"031"[..], b"002", b"01", b"0010", b"", b"0 1"] {
            assert!(MachineStatus::parse(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn stop_modes_read_their_codes_in_either_case() {
        assert_eq!("bl".parse(), Ok(StopMode::OneBlock));
        assert_eq!("EP".parse(), Ok(StopMode::EndOfProgram));
        assert_eq!("ct".parse(), Ok(StopMode::Continuous));
        assert!("xx".parse::<StopMode>().is_err());
    }
}
