//! What an operator can do at the panel of the placement-machine twin while it serves:
//! the mode switch, START and STOP, a feeder running out, an error stop, RESET.
//!
//! `cellbus sim panasonic` reads these commands on its standard input and the gateway's
//! demo cell scripts them; both parse with [`str::parse`] and carry them out with
//! [`apply`] (on a served twin: [`crate::server::Control::apply`]), so the words and
//! their effects are the same everywhere:
//!
//! ```
//! use std::time::Instant;
//! use panasonic::operator::{Command, apply};
//! use panasonic::{Machine, MachineConfig};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let mut machine = Machine::new(MachineConfig::default())?;
//! let command: Command = "remote".parse()?;
//! let done = apply(&mut machine, command, Instant::now())?;
//! assert!(done.starts_with("mode remote"));
//! # Ok(())
//! # }
//! ```

use std::time::Instant;

use wire::operator::{CommandSet, ParseError, Syntax, Words, help_line};

use crate::status::{ControlMode, StopMode};
use crate::twin::{Machine, TwinError};

/// One operator command at the machine's panel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// Mode switch to Online (the host may read and transfer, not start).
    Online,
    /// Mode switch to Remote (the host may also start and reset, C5).
    Remote,
    /// START at the panel, in this stop mode or the previous one.
    Start(Option<StopMode>),
    /// STOP at the panel.
    Stop,
    /// The feeder stops feeding: its next pick runs out.
    PauseFeeder(u16),
    /// The feeder feeds again.
    ResumeFeeder(u16),
    /// A full reel on the feeder.
    RefillFeeder(u16),
    /// An error stop with this R2 code (0 to [`MAX_ERROR_CODE`]).
    Error(u8),
    /// Every error cause cleared, RESET pressed.
    Clear,
    /// What the machine is doing.
    Status,
    /// The list of commands, or one command explained.
    Help(Option<&'static Syntax>),
}

/// The highest error code R2 carries (two digits).
pub const MAX_ERROR_CODE: u8 = 99;

/// A feeder number's name in errors; any from 1 to 65535 is typed, the twin says which
/// of them exist.
const FEEDER: &str = "feeder number";

impl CommandSet for Command {
    const TABLE: &'static [Syntax] = &[
        Syntax {
            name: "online",
            args: "",
            help: "mode switch to Online: the host may transfer data; C5 start/reset are refused",
        },
        Syntax {
            name: "remote",
            args: "",
            help: "mode switch to Remote: the host may also start and reset the machine (C5)",
        },
        Syntax {
            name: "start",
            args: "[bl|ep|ct]",
            help: "START at the panel (any mode), stopping after 1 block, at the end of the \
                   program or never (default: as before); R1ST follows",
        },
        Syntax {
            name: "stop",
            args: "",
            help: "STOP at the panel: the machine stops and is ready",
        },
        Syntax {
            name: "pause-feeder",
            args: "N",
            help: "feeder N stops feeding: its next pick runs out (R2E03, error stop)",
        },
        Syntax {
            name: "resume-feeder",
            args: "N",
            help: "feeder N feeds again",
        },
        Syntax {
            name: "refill-feeder",
            args: "N",
            help: "a full reel is loaded on feeder N",
        },
        Syntax {
            name: "error",
            args: "CODE",
            help: "an error stop with code 0 to 99 (R2E<code> on Port 2, status error)",
        },
        Syntax {
            name: "clear",
            args: "",
            help: "every error cause is cleared and RESET pressed: the machine is ready",
        },
        Syntax {
            name: "status",
            args: "",
            help: "state, mode, program, boards produced and stop mode",
        },
    ];

    fn from_words(syntax: &'static Syntax, words: &mut Words<'_>) -> Result<Self, ParseError> {
        Ok(match syntax.name {
            "online" => Command::Online,
            "remote" => Command::Remote,
            "start" => Command::Start(words.optional().map(stop_mode).transpose()?),
            "stop" => Command::Stop,
            "pause-feeder" => Command::PauseFeeder(words.number(FEEDER, 1, u16::MAX)?),
            "resume-feeder" => Command::ResumeFeeder(words.number(FEEDER, 1, u16::MAX)?),
            "refill-feeder" => Command::RefillFeeder(words.number(FEEDER, 1, u16::MAX)?),
            "error" => Command::Error(words.number("error code", 0, MAX_ERROR_CODE)?),
            "clear" => Command::Clear,
            "status" => Command::Status,
            other => return Err(ParseError::unknown(other)),
        })
    }

    fn help(about: Option<&'static Syntax>) -> Self {
        Command::Help(about)
    }
}

wire::operator_from_str!(Command);

/// Carries out `command` on `machine` at `now`; says in words what happened, or why the
/// machine refused.
pub fn apply(machine: &mut Machine, command: Command, now: Instant) -> Result<String, TwinError> {
    Ok(match command {
        Command::Online => {
            machine.set_mode(ControlMode::Online);
            "mode online: the host may transfer data; C5 start/reset are refused".to_owned()
        }
        Command::Remote => {
            machine.set_mode(ControlMode::Remote);
            "mode remote: the host may also start and reset the machine (C5)".to_owned()
        }
        Command::Start(mode) => {
            machine.operator_start(mode, now)?;
            format!(
                "started at the panel in {} mode; R1ST goes out on Port 2",
                machine.stop_mode().describe()
            )
        }
        Command::Stop => {
            machine.stop(now);
            format!(
                "stopped at the panel: {}",
                machine.status().state.describe()
            )
        }
        Command::PauseFeeder(feeder) => {
            machine.pause_feeder(feeder, now)?;
            format!("feeder {feeder} paused: its next pick runs out (R2E03, error stop)")
        }
        Command::ResumeFeeder(feeder) => {
            machine.resume_feeder(feeder, now)?;
            format!("feeder {feeder} feeds again")
        }
        Command::RefillFeeder(feeder) => {
            machine.refill_feeder(feeder, now)?;
            let parts = machine.feeder_remaining(feeder)?;
            format!("feeder {feeder} refilled: {parts} parts on the reel")
        }
        Command::Error(code) => {
            machine.force_error(code, now)?;
            format!("error stop with code {code:02}: R2E{code:02} goes out on Port 2")
        }
        Command::Clear => {
            machine.clear(now);
            format!(
                "error causes cleared and RESET pressed: {}",
                machine.status().state.describe()
            )
        }
        Command::Status => status(machine),
        Command::Help(about) => help_line::<Command>(about),
    })
}

/// State, mode, program, boards produced and stop mode on one line.
fn status(machine: &Machine) -> String {
    let status = machine.status();
    let program = machine
        .selected()
        .map_or_else(|| "no program".to_owned(), |p| format!("program {p}"));
    format!(
        "{}, {}; {program} selected; {} boards produced; stop mode {}",
        status.state.describe(),
        status.mode.describe(),
        machine.boards_produced(),
        machine.stop_mode().describe()
    )
}

/// A stop mode as typed: `bl`, `ep` or `ct`.
fn stop_mode(text: &str) -> Result<StopMode, ParseError> {
    text.parse::<StopMode>().map_err(|_| ParseError::BadChoice {
        what: "a stop mode",
        text: text.to_owned(),
        choices: "bl (1 block), ep (end of program) or ct (continuous)",
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::MachineConfig;

    fn parsed(line: &str) -> Result<Command, ParseError> {
        line.parse()
    }

    fn error(line: &str) -> String {
        parsed(line).map_err(|e| e.to_string()).expect_err(line)
    }

    fn machine() -> Machine {
        Machine::new(MachineConfig::default()).expect("the default configuration is valid")
    }

    #[test]
    fn panel_commands_parse_into_typed_commands() {
        let cases = [
            ("online", Command::Online),
            ("remote", Command::Remote),
            ("start", Command::Start(None)),
            ("start ep", Command::Start(Some(StopMode::EndOfProgram))),
            ("START CT", Command::Start(Some(StopMode::Continuous))),
            ("stop", Command::Stop),
            ("pause-feeder 3", Command::PauseFeeder(3)),
            ("  resume-feeder   12 ", Command::ResumeFeeder(12)),
            ("refill-feeder 1\r\n", Command::RefillFeeder(1)),
            ("error 3", Command::Error(3)),
            ("error 99", Command::Error(99)),
            ("clear", Command::Clear),
            ("status", Command::Status),
            ("help", Command::Help(None)),
        ];
        for (line, command) in cases {
            assert_eq!(parsed(line), Ok(command), "{line:?}");
        }
    }

    #[test]
    fn every_table_entry_is_parsed_by_from_words() {
        assert_eq!(wire::operator::unparsed_entries::<Command>(), [""; 0]);
    }

    #[test]
    fn a_bad_feeder_number_says_what_was_typed_and_the_range() {
        for text in ["x", "0", "-1", "70000"] {
            assert_eq!(
                parsed(&format!("pause-feeder {text}")),
                Err(ParseError::BadNumber {
                    what: "feeder number",
                    text: text.into(),
                    min: 1,
                    max: 65535
                })
            );
        }
        assert_eq!(
            error("pause-feeder x"),
            "feeder number `x` is not a number from 1 to 65535"
        );
    }

    #[test]
    fn an_error_code_above_99_is_refused_before_the_twin_sees_it() {
        assert_eq!(
            error("error 100"),
            "error code `100` is not a number from 0 to 99"
        );
    }

    #[test]
    fn a_missing_argument_extra_word_or_bad_stop_mode_is_refused_with_the_usage() {
        assert_eq!(
            error("refill-feeder"),
            "`refill-feeder` needs feeder number: refill-feeder N"
        );
        assert_eq!(error("status now"), "`status` does not take `now`: status");
        assert_eq!(
            error("start fast"),
            "`fast` is not a stop mode: use bl (1 block), ep (end of program) or ct (continuous)"
        );
        assert_eq!(
            error("repair 1"),
            "unknown command `repair`; `help` lists the commands"
        );
    }

    #[test]
    fn the_twin_refuses_a_feeder_it_does_not_have_in_words() {
        let mut machine = machine();
        let now = Instant::now();
        let refused = apply(&mut machine, Command::PauseFeeder(9999), now).expect_err("no feeder");
        assert!(matches!(
            refused,
            TwinError::NoSuchFeeder { feeder: 9999, .. }
        ));
        assert!(
            refused.to_string().contains("feeder 9999 does not exist"),
            "{refused}"
        );
    }

    #[test]
    fn remote_then_status_says_ready_and_remote() {
        let mut machine = machine();
        let now = Instant::now();
        let done = apply(&mut machine, Command::Remote, now).expect("remote");
        assert!(done.starts_with("mode remote"), "{done}");
        let status = apply(&mut machine, Command::Status, now).expect("status");
        assert!(status.starts_with("ready, remote"), "{status}");
    }

    #[test]
    fn feeders_can_be_paused_and_refilled_and_clear_ends_an_error_stop() {
        let mut machine = machine();
        let now = Instant::now();
        let start = apply(
            &mut machine,
            Command::Start(Some(StopMode::Continuous)),
            now,
        )
        .expect("started");
        assert!(
            start.starts_with("started at the panel in continuous mode"),
            "{start}"
        );
        let pause = apply(&mut machine, Command::PauseFeeder(1), now).expect("paused");
        assert!(pause.starts_with("feeder 1 paused"), "{pause}");
        apply(&mut machine, Command::ResumeFeeder(1), now).expect("feeds again");
        let refill = apply(&mut machine, Command::RefillFeeder(1), now).expect("refilled");
        assert!(refill.starts_with("feeder 1 refilled: "), "{refill}");
        let stop = apply(&mut machine, Command::Error(5), now).expect("error stop");
        assert_eq!(stop, "error stop with code 05: R2E05 goes out on Port 2");
        let clear = apply(&mut machine, Command::Clear, now).expect("cleared");
        assert_eq!(clear, "error causes cleared and RESET pressed: ready");
    }
}
