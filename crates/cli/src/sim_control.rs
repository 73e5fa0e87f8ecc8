//! Run-time control of a simulator: commands typed on its standard input, one per line,
//! while it serves (a test or a demo operator switches modes, pauses a feeder, breaks a
//! band…).
//!
//! Every line gets exactly one answer line on stdout: `ok: …` saying in words what
//! happened, or `error: …` saying what was wrong. Nothing typed stops the simulator; the end
//! of input (stdin closed, `/dev/null`) only ends the control channel. Blank lines and lines
//! starting with `#` are ignored (scripts may carry comments). `help` lists the commands,
//! `help COMMAND` explains one.
//!
//! Parsing is per device from a command table ([`Commands::TABLE`]) into typed commands
//! ([`PanasonicCommand`], [`ThermosaldCommand`]); [`spawn`] runs the channel on its own
//! thread, so a blocked read of a terminal never holds up the simulator.

use std::io::{BufRead, IsTerminal};
use std::time::Instant;

use panasonic::server::Control;
use panasonic::{ControlMode, StopMode};
use thermosald::device::{Line as Twin, Phase, Regulator};
use thermosald::diagnostic::{self, Fault};
use thermosald::frame::Address;
use wire::device::SharedModel;

use crate::output;

/// One command of a device's table: how it is written and what it does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Syntax {
    /// The first word.
    pub name: &'static str,
    /// Its arguments as `help` shows them (`N`, `[bl|ep|ct]`), empty if none.
    pub args: &'static str,
    /// What it does, for `help COMMAND`.
    pub help: &'static str,
}

impl Syntax {
    /// `name args`, as typed.
    fn usage(&self) -> String {
        if self.args.is_empty() {
            self.name.to_owned()
        } else {
            format!("{} {}", self.name, self.args)
        }
    }
}

/// A line that is not a command of this simulator.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ParseError {
    /// The first word is not in the table.
    #[error("unknown command `{word}`; `help` lists the commands")]
    Unknown {
        /// What was typed.
        word: String,
    },
    /// An argument is missing.
    #[error("`{command}` needs {what}: {usage}")]
    Missing {
        /// The command.
        command: &'static str,
        /// What is missing, in words.
        what: &'static str,
        /// How the command is written.
        usage: String,
    },
    /// More words than the command takes.
    #[error("`{command}` does not take `{word}`: {usage}")]
    Extra {
        /// The command.
        command: &'static str,
        /// The first word too many.
        word: String,
        /// How the command is written.
        usage: String,
    },
    /// An argument that should be a number is not, or is outside its range.
    #[error("{what} `{text}` is not a number from {min} to {max}")]
    BadNumber {
        /// What the argument is.
        what: &'static str,
        /// What was typed.
        text: String,
        /// The lowest accepted.
        min: u32,
        /// The highest accepted.
        max: u32,
    },
    /// An argument that is not one of its choices.
    #[error("`{text}` is not {what}: use {choices}")]
    BadChoice {
        /// What the argument is.
        what: &'static str,
        /// What was typed.
        text: String,
        /// The accepted words.
        choices: &'static str,
    },
}

/// A typed line: nothing, a request for help, or a device command.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Input<C> {
    /// A blank line or a `#` comment: no answer.
    Blank,
    /// `help`, or `help COMMAND` (the command's table entry).
    Help(Option<&'static Syntax>),
    /// A command for the device.
    Command(C),
}

/// A device's command set.
pub trait Commands: Sized {
    /// Every command, in the order `help` lists them.
    const TABLE: &'static [Syntax];

    /// The command `syntax` with its arguments taken from `words`.
    fn from_words(syntax: &'static Syntax, words: &mut Words<'_>) -> Result<Self, ParseError>;
}

/// The arguments of one command, taken one by one.
#[derive(Debug)]
pub struct Words<'a> {
    syntax: &'static Syntax,
    rest: std::str::SplitWhitespace<'a>,
}

impl Words<'_> {
    /// The next word, or [`ParseError::Missing`] naming `what`.
    fn word(&mut self, what: &'static str) -> Result<&str, ParseError> {
        self.rest.next().ok_or_else(|| ParseError::Missing {
            command: self.syntax.name,
            what,
            usage: self.syntax.usage(),
        })
    }

    /// The next word, if any.
    fn optional(&mut self) -> Option<&str> {
        self.rest.next()
    }

    /// The next word as a number from `min` to `max`.
    fn number(&mut self, what: &'static str, min: u32, max: u32) -> Result<u32, ParseError> {
        let text = self.word(what)?;
        text.parse::<u32>()
            .ok()
            .filter(|n| (min..=max).contains(n))
            .ok_or_else(|| ParseError::BadNumber {
                what,
                text: text.to_owned(),
                min,
                max,
            })
    }

    /// Refuses anything left over.
    fn end(mut self) -> Result<(), ParseError> {
        match self.rest.next() {
            None => Ok(()),
            Some(word) => Err(ParseError::Extra {
                command: self.syntax.name,
                word: word.to_owned(),
                usage: self.syntax.usage(),
            }),
        }
    }
}

/// Parses one typed line for the device `C`. Command names are case-insensitive.
pub fn parse<C: Commands>(line: &str) -> Result<Input<C>, ParseError> {
    let line = line.trim();
    if line.is_empty() || line.starts_with('#') {
        return Ok(Input::Blank);
    }
    let mut rest = line.split_whitespace();
    let first = rest.next().unwrap_or_default();
    let lookup = |word: &str| {
        C::TABLE
            .iter()
            .find(|s| s.name.eq_ignore_ascii_case(word))
            .ok_or_else(|| ParseError::Unknown {
                word: word.to_owned(),
            })
    };
    if first.eq_ignore_ascii_case(HELP.name) || first == "?" {
        let mut words = Words {
            syntax: &HELP,
            rest,
        };
        let about = words.optional().map(lookup).transpose()?;
        words.end()?;
        return Ok(Input::Help(about));
    }
    let syntax = lookup(first)?;
    let mut words = Words { syntax, rest };
    let command = C::from_words(syntax, &mut words)?;
    words.end()?;
    Ok(Input::Command(command))
}

/// A table entry its device's `from_words` does not know (a slip when adding a command; the
/// test `every_table_entry_is_parsed_by_its_device` catches it): refused as unknown.
fn unparsed(name: &str) -> ParseError {
    ParseError::Unknown {
        word: name.to_owned(),
    }
}

/// `help` itself (every device has it).
const HELP: Syntax = Syntax {
    name: "help",
    args: "[COMMAND]",
    help: "lists the commands, or explains one",
};

/// The one-line answer to `help` / `help COMMAND`.
pub fn help<C: Commands>(about: Option<&'static Syntax>) -> String {
    match about {
        Some(syntax) => format!("{}: {}", syntax.usage(), syntax.help),
        None => {
            let all: Vec<String> = C::TABLE.iter().map(Syntax::usage).collect();
            format!("commands: {}; `help COMMAND` explains one", all.join(" | "))
        }
    }
}

/// The commands for a simulator's `--help`: one per line with what it does.
pub fn long_help<C: Commands>() -> String {
    let mut text = String::from(
        "Control while it serves: type commands on stdin, one per line; each gets one line \
         on stdout, `ok: …` or `error: …` (it never stops the simulator). End of input ends \
         only the control channel.\n",
    );
    for syntax in C::TABLE.iter().chain([&HELP]) {
        text.push_str(&format!("  {}\n      {}\n", syntax.usage(), syntax.help));
    }
    text
}

/// The answer to one typed line: `Some("ok: …" | "error: …")`, `None` for a blank line.
pub fn answer<C: Commands>(
    line: &str,
    act: &mut impl FnMut(C) -> Result<String, String>,
) -> Option<String> {
    let result = match parse::<C>(line) {
        Ok(Input::Blank) => return None,
        Ok(Input::Help(about)) => Ok(help::<C>(about)),
        Ok(Input::Command(command)) => act(command),
        Err(err) => Err(err.to_string()),
    };
    Some(match result {
        Ok(done) => format!("ok: {done}"),
        Err(why) => format!("error: {why}"),
    })
}

/// Reads commands from stdin on a thread of its own and answers each on stdout, until the
/// end of input (or until stdout is gone). `act` carries a command out and says what
/// happened, or why it could not.
pub fn spawn<C, F>(mut act: F)
where
    C: Commands + 'static,
    F: FnMut(C) -> Result<String, String> + Send + 'static,
{
    if std::io::stdin().is_terminal() {
        eprintln!("cellbus: type control commands here, one per line; `help` lists them");
    }
    let spawned = std::thread::Builder::new()
        .name("sim-control".into())
        .spawn(move || {
            let mut input = std::io::stdin().lock();
            let mut bytes = Vec::new();
            loop {
                bytes.clear();
                match input.read_until(b'\n', &mut bytes) {
                    Ok(0) => break,
                    Ok(_) => {}
                    Err(err) => {
                        tracing::debug!("control channel: cannot read stdin ({err}): it ends here");
                        break;
                    }
                }
                let line = String::from_utf8_lossy(&bytes);
                if let Some(reply) = answer::<C>(&line, &mut act)
                    && output::line(reply).is_err()
                {
                    break;
                }
            }
            tracing::debug!("control channel: end of input; the simulator keeps serving");
        });
    if let Err(err) = spawned {
        tracing::warn!("no control channel: cannot start its thread: {err}");
    }
}

// ---------------------------------------------------------------------------------------
// Panasonic BM placement machine

/// What an operator can do to the Panasonic twin while it serves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PanasonicCommand {
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
    /// An error stop with this R2 code (0 to 99).
    Error(u8),
    /// Every error cause cleared, RESET pressed.
    Clear,
    /// What the machine is doing.
    Status,
}

/// The highest error code R2 carries (two digits).
pub const MAX_ERROR_CODE: u8 = 99;
/// The highest feeder number typed (the twin says which of them exist).
const MAX_FEEDER: u32 = u16::MAX as u32;

impl Commands for PanasonicCommand {
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
        let feeder = |words: &mut Words<'_>| {
            words
                .number("feeder number", 1, MAX_FEEDER)
                .map(|n| u16::try_from(n).expect("MAX_FEEDER fits u16"))
        };
        Ok(match syntax.name {
            "online" => PanasonicCommand::Online,
            "remote" => PanasonicCommand::Remote,
            "start" => PanasonicCommand::Start(
                words
                    .optional()
                    .map(|text| {
                        text.parse::<StopMode>().map_err(|_| ParseError::BadChoice {
                            what: "a stop mode",
                            text: text.to_owned(),
                            choices: "bl (1 block), ep (end of program) or ct (continuous)",
                        })
                    })
                    .transpose()?,
            ),
            "stop" => PanasonicCommand::Stop,
            "pause-feeder" => PanasonicCommand::PauseFeeder(feeder(words)?),
            "resume-feeder" => PanasonicCommand::ResumeFeeder(feeder(words)?),
            "refill-feeder" => PanasonicCommand::RefillFeeder(feeder(words)?),
            "error" => PanasonicCommand::Error(
                u8::try_from(words.number("error code", 0, u32::from(MAX_ERROR_CODE))?)
                    .expect("at most MAX_ERROR_CODE"),
            ),
            "clear" => PanasonicCommand::Clear,
            "status" => PanasonicCommand::Status,
            other => return Err(unparsed(other)),
        })
    }
}

/// Carries out `command` on the served twin; says what happened or why not.
pub fn panasonic_act(control: &Control, command: PanasonicCommand) -> Result<String, String> {
    let refused = |err: panasonic::twin::TwinError| err.to_string();
    Ok(match command {
        PanasonicCommand::Online => {
            control.set_mode(ControlMode::Online);
            "mode online: the host may transfer data; C5 start/reset are refused".to_owned()
        }
        PanasonicCommand::Remote => {
            control.set_mode(ControlMode::Remote);
            "mode remote: the host may also start and reset the machine (C5)".to_owned()
        }
        PanasonicCommand::Start(mode) => {
            control.operator_start(mode).map_err(refused)?;
            let how = control.with(|machine, _| machine.stop_mode().describe());
            format!("started at the panel in {how} mode; R1ST goes out on Port 2")
        }
        PanasonicCommand::Stop => {
            control.stop();
            format!(
                "stopped at the panel: {}",
                control.status().state.describe()
            )
        }
        PanasonicCommand::PauseFeeder(feeder) => {
            control.pause_feeder(feeder).map_err(refused)?;
            format!("feeder {feeder} paused: its next pick runs out (R2E03, error stop)")
        }
        PanasonicCommand::ResumeFeeder(feeder) => {
            control.resume_feeder(feeder).map_err(refused)?;
            format!("feeder {feeder} feeds again")
        }
        PanasonicCommand::RefillFeeder(feeder) => {
            control.refill_feeder(feeder).map_err(refused)?;
            let parts = control
                .with(|machine, _| machine.feeder_remaining(feeder))
                .map_err(refused)?;
            format!("feeder {feeder} refilled: {parts} parts on the reel")
        }
        PanasonicCommand::Error(code) => {
            control.force_error(code).map_err(refused)?;
            format!("error stop with code {code:02}: R2E{code:02} goes out on Port 2")
        }
        PanasonicCommand::Clear => {
            control.clear();
            format!(
                "error causes cleared and RESET pressed: {}",
                control.status().state.describe()
            )
        }
        PanasonicCommand::Status => control.with(|machine, _| {
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
        }),
    })
}

/// Starts the Panasonic twin's control channel on stdin.
pub fn panasonic(control: Control) {
    spawn(move |command| panasonic_act(&control, command));
}

// ---------------------------------------------------------------------------------------
// Thermosald ISC regulators

/// A fault cause as typed: `open-band`, `short`, `over-current`, `not-reached`.
const FAULT_WORDS: [(&str, Fault); 4] = [
    ("open-band", Fault::OpenBand),
    ("short", Fault::ShortCircuit),
    ("over-current", Fault::OverCurrent),
    ("not-reached", Fault::TemperatureNotReached),
];

/// What an operator can do to the Thermosald regulators while they serve.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ThermosaldCommand {
    /// Provokes the physical cause of `fault` at the regulator at `address`.
    Fault {
        /// Which regulator.
        address: Address,
        /// Which cause.
        fault: Fault,
    },
    /// Removes every fault cause of the regulator: clear-faults (14) then clears it.
    Repair(Address),
    /// Switches the regulator off and on (working data reloaded from EEPROM).
    PowerCycle(Address),
    /// Every regulator's phase, temperature and fault.
    Status,
}

impl Commands for ThermosaldCommand {
    const TABLE: &'static [Syntax] = &[
        Syntax {
            name: "fault",
            args: "ADDR open-band|short|over-current|not-reached",
            help: "provokes the cause at regulator ADDR: the band breaks or is partly \
                   bypassed, the supply gives too much or too little voltage",
        },
        Syntax {
            name: "repair",
            args: "ADDR",
            help: "removes every fault cause at regulator ADDR; clear-faults (message 14) \
                   then clears its latched fault",
        },
        Syntax {
            name: "power-cycle",
            args: "ADDR",
            help: "switches regulator ADDR off and on: working data reload from EEPROM, \
                   latched faults go (and come back if their cause remains)",
        },
        Syntax {
            name: "status",
            args: "",
            help: "every regulator's phase, measured temperature and fault number",
        },
    ];

    fn from_words(syntax: &'static Syntax, words: &mut Words<'_>) -> Result<Self, ParseError> {
        let address = |words: &mut Words<'_>| {
            let number = words.number(
                "regulator address",
                u32::from(Address::MIN),
                u32::from(Address::MAX),
            )?;
            Ok(u8::try_from(number)
                .ok()
                .and_then(|n| Address::new(n).ok())
                .expect("checked against Address::MIN..=MAX"))
        };
        Ok(match syntax.name {
            "fault" => {
                let address = address(words)?;
                let text = words.word("a fault cause")?;
                let fault = FAULT_WORDS
                    .iter()
                    .find(|(word, _)| word.eq_ignore_ascii_case(text))
                    .map(|(_, fault)| *fault)
                    .ok_or_else(|| ParseError::BadChoice {
                        what: "a fault cause",
                        text: text.to_owned(),
                        choices: "open-band, short, over-current or not-reached",
                    })?;
                ThermosaldCommand::Fault { address, fault }
            }
            "repair" => ThermosaldCommand::Repair(address(words)?),
            "power-cycle" => ThermosaldCommand::PowerCycle(address(words)?),
            "status" => ThermosaldCommand::Status,
            other => return Err(unparsed(other)),
        })
    }
}

/// A phase in words.
fn phase_words(phase: Phase) -> String {
    match phase {
        Phase::Uncalibrated => "not calibrated".to_owned(),
        Phase::Balancing => "balancing".to_owned(),
        Phase::Faulted(fault) => format!("stopped by a fault ({})", fault.description()),
        Phase::PreHeating => "pre-heating".to_owned(),
        Phase::Sealing => "sealing".to_owned(),
        Phase::Cooling => "cooling".to_owned(),
    }
}

/// Carries out `command` on the regulators at `now`; says what happened or why not.
pub fn thermosald_act(
    twin: &mut Twin,
    command: ThermosaldCommand,
    now: Instant,
) -> Result<String, String> {
    let (address, done): (Address, fn(&mut Regulator, Instant) -> String) = match command {
        ThermosaldCommand::Status => return Ok(thermosald_status(twin, now)),
        ThermosaldCommand::Fault { address, fault } => {
            let regulator = regulator_at(twin, address)?;
            regulator.provoke(fault, now);
            let done = format!(
                "regulator {address}: cause of \"{}\" provoked",
                fault.description()
            );
            return Ok(with_fault_number(regulator, done, now));
        }
        ThermosaldCommand::Repair(address) => (address, |regulator, now| {
            for fault in Fault::ALL {
                regulator.remove_cause(fault, now);
            }
            "every fault cause removed; clear-faults (message 14) clears a latched fault".to_owned()
        }),
        ThermosaldCommand::PowerCycle(address) => (address, |regulator, now| {
            regulator.power_cycle(now);
            "switched off and on, working data reloaded from EEPROM".to_owned()
        }),
    };
    let regulator = regulator_at(twin, address)?;
    let done = format!("regulator {address}: {}", done(regulator, now));
    Ok(with_fault_number(regulator, done, now))
}

/// One line on every regulator: phase, measured temperature, fault number in words.
fn thermosald_status(twin: &mut Twin, now: Instant) -> String {
    let all: Vec<String> = twin
        .regulators_mut()
        .iter_mut()
        .map(|regulator| {
            let who = regulator
                .address()
                .map_or_else(|| "no address".to_owned(), |a| a.to_string());
            let status = regulator.status(now);
            let temperature = status
                .measured_temperature
                .map_or_else(|| "no temperature".to_owned(), |t| format!("{t:.0} °C"));
            format!(
                "regulator {who}: {}, {temperature}, fault {} ({})",
                phase_words(status.phase),
                status.fault,
                diagnostic::describe(status.fault)
            )
        })
        .collect();
    all.join("; ")
}

/// The regulator at `address`, or why there is none.
fn regulator_at(twin: &mut Twin, address: Address) -> Result<&mut Regulator, String> {
    let on_line: Vec<String> = twin
        .regulators()
        .iter()
        .filter_map(|r| r.address().map(|a| a.to_string()))
        .collect();
    twin.regulator_mut(address).ok_or_else(|| {
        format!(
            "no regulator at address {address} on this line (addresses: {})",
            on_line.join(", ")
        )
    })
}

/// `done` followed by the fault number the regulator shows now.
fn with_fault_number(regulator: &mut Regulator, done: String, now: Instant) -> String {
    let fault = regulator.fault_number(now);
    format!(
        "{done}; fault number now {fault} ({})",
        diagnostic::describe(fault)
    )
}

/// Starts the Thermosald line's control channel on stdin.
pub fn thermosald(model: SharedModel<Twin>) {
    spawn(move |command| thermosald_act(&mut model.lock(), command, Instant::now()));
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pana(line: &str) -> Result<Input<PanasonicCommand>, ParseError> {
        parse(line)
    }

    fn thermo(line: &str) -> Result<Input<ThermosaldCommand>, ParseError> {
        parse(line)
    }

    fn address(n: u8) -> Address {
        Address::new(n).expect("a valid address")
    }

    #[test]
    fn panasonic_commands_parse_into_typed_commands() {
        let cases = [
            ("online", PanasonicCommand::Online),
            ("remote", PanasonicCommand::Remote),
            ("start", PanasonicCommand::Start(None)),
            (
                "start ep",
                PanasonicCommand::Start(Some(StopMode::EndOfProgram)),
            ),
            (
                "START CT",
                PanasonicCommand::Start(Some(StopMode::Continuous)),
            ),
            ("stop", PanasonicCommand::Stop),
            ("pause-feeder 3", PanasonicCommand::PauseFeeder(3)),
            ("  resume-feeder   12 ", PanasonicCommand::ResumeFeeder(12)),
            ("refill-feeder 1\r\n", PanasonicCommand::RefillFeeder(1)),
            ("error 3", PanasonicCommand::Error(3)),
            ("error 99", PanasonicCommand::Error(99)),
            ("clear", PanasonicCommand::Clear),
            ("status", PanasonicCommand::Status),
        ];
        for (line, command) in cases {
            assert_eq!(pana(line), Ok(Input::Command(command)), "{line:?}");
        }
    }

    #[test]
    fn thermosald_commands_parse_into_typed_commands() {
        let cases = [
            (
                "fault 1 open-band",
                ThermosaldCommand::Fault {
                    address: address(1),
                    fault: Fault::OpenBand,
                },
            ),
            (
                "fault 0 short",
                ThermosaldCommand::Fault {
                    address: address(0),
                    fault: Fault::ShortCircuit,
                },
            ),
            (
                "fault 7 over-current",
                ThermosaldCommand::Fault {
                    address: address(7),
                    fault: Fault::OverCurrent,
                },
            ),
            (
                "fault 2 not-reached",
                ThermosaldCommand::Fault {
                    address: address(2),
                    fault: Fault::TemperatureNotReached,
                },
            ),
            ("repair 1", ThermosaldCommand::Repair(address(1))),
            ("power-cycle 4", ThermosaldCommand::PowerCycle(address(4))),
            ("status", ThermosaldCommand::Status),
        ];
        for (line, command) in cases {
            assert_eq!(thermo(line), Ok(Input::Command(command)), "{line:?}");
        }
    }

    #[test]
    fn every_table_entry_is_parsed_by_its_device() {
        // Alone, a command parses or asks for its argument: never "unknown".
        for syntax in PanasonicCommand::TABLE {
            let parsed = pana(syntax.name);
            assert!(
                !matches!(parsed, Err(ParseError::Unknown { .. })),
                "{parsed:?}"
            );
        }
        for syntax in ThermosaldCommand::TABLE {
            let parsed = thermo(syntax.name);
            assert!(
                !matches!(parsed, Err(ParseError::Unknown { .. })),
                "{parsed:?}"
            );
        }
    }

    #[test]
    fn blank_lines_and_comments_get_no_answer() {
        for line in ["", "   ", "\n", "# remote first", "  # indented"] {
            assert_eq!(pana(line), Ok(Input::Blank), "{line:?}");
            assert_eq!(
                answer::<PanasonicCommand>(line, &mut |_| Ok(String::new())),
                None
            );
        }
    }

    #[test]
    fn an_unknown_command_is_refused_and_points_to_help() {
        let err = pana("launch").expect_err("not a command");
        assert_eq!(
            err,
            ParseError::Unknown {
                word: "launch".into()
            }
        );
        assert_eq!(
            err.to_string(),
            "unknown command `launch`; `help` lists the commands"
        );
        // Each device knows only its own commands.
        assert!(matches!(thermo("remote"), Err(ParseError::Unknown { .. })));
        assert!(matches!(pana("repair 1"), Err(ParseError::Unknown { .. })));
    }

    #[test]
    fn a_bad_feeder_number_says_what_was_typed_and_the_range() {
        for text in ["x", "0", "-1", "70000"] {
            let err = pana(&format!("pause-feeder {text}")).expect_err("bad feeder");
            assert_eq!(
                err,
                ParseError::BadNumber {
                    what: "feeder number",
                    text: text.into(),
                    min: 1,
                    max: 65535
                }
            );
        }
        assert_eq!(
            pana("pause-feeder x").expect_err("bad").to_string(),
            "feeder number `x` is not a number from 1 to 65535"
        );
    }

    #[test]
    fn an_error_code_above_99_is_refused_before_the_twin_sees_it() {
        let err = pana("error 100").expect_err("three digits");
        assert_eq!(
            err.to_string(),
            "error code `100` is not a number from 0 to 99"
        );
    }

    #[test]
    fn a_missing_argument_names_it_and_shows_the_usage() {
        assert_eq!(
            pana("refill-feeder").expect_err("no feeder").to_string(),
            "`refill-feeder` needs feeder number: refill-feeder N"
        );
        assert_eq!(
            thermo("fault 1").expect_err("no cause").to_string(),
            "`fault` needs a fault cause: fault ADDR open-band|short|over-current|not-reached"
        );
    }

    #[test]
    fn extra_words_are_refused_rather_than_ignored() {
        assert_eq!(
            pana("status now").expect_err("extra").to_string(),
            "`status` does not take `now`: status"
        );
        assert!(matches!(
            thermo("repair 1 2"),
            Err(ParseError::Extra { .. })
        ));
    }

    #[test]
    fn a_bad_stop_mode_or_fault_cause_lists_the_choices() {
        let err = pana("start fast").expect_err("no such mode");
        assert_eq!(
            err.to_string(),
            "`fast` is not a stop mode: use bl (1 block), ep (end of program) or ct (continuous)"
        );
        let err = thermo("fault 1 melted").expect_err("no such cause");
        assert_eq!(
            err.to_string(),
            "`melted` is not a fault cause: use open-band, short, over-current or not-reached"
        );
    }

    #[test]
    fn a_regulator_address_beyond_7_is_refused_with_the_range() {
        assert_eq!(
            thermo("repair 8").expect_err("address 8").to_string(),
            "regulator address `8` is not a number from 0 to 7"
        );
    }

    #[test]
    fn help_lists_every_command_on_one_line_and_explains_one() {
        let list = help::<PanasonicCommand>(None);
        assert!(!list.contains('\n'), "{list}");
        for syntax in PanasonicCommand::TABLE {
            assert!(list.contains(&syntax.usage()), "{list}");
        }
        assert_eq!(pana("help"), Ok(Input::Help(None)));
        let Ok(Input::Help(Some(about))) = thermo("help fault") else {
            panic!("help fault explains fault");
        };
        assert!(help::<ThermosaldCommand>(Some(about)).starts_with("fault ADDR open-band"));
        assert!(matches!(
            thermo("help nope"),
            Err(ParseError::Unknown { .. })
        ));
    }

    #[test]
    fn answers_are_one_line_starting_ok_or_error() {
        let mut act = |command: PanasonicCommand| match command {
            PanasonicCommand::Stop => Ok("stopped".to_owned()),
            _ => Err("feeder 99 does not exist".to_owned()),
        };
        assert_eq!(answer("stop", &mut act), Some("ok: stopped".into()));
        assert_eq!(
            answer("pause-feeder 99", &mut act),
            Some("error: feeder 99 does not exist".into())
        );
        assert!(
            answer("bogus", &mut act)
                .expect("an answer")
                .starts_with("error: unknown command `bogus`")
        );
    }

    #[tokio::test]
    async fn the_twin_refuses_a_feeder_it_does_not_have_in_words() {
        let machine =
            panasonic::Machine::new(panasonic::MachineConfig::default()).expect("default config");
        {
            let server = panasonic::server::TwinServer::bind(
                "127.0.0.1:0".parse().expect("addr"),
                "127.0.0.1:0".parse().expect("addr"),
                machine,
            )
            .await
            .expect("bound");
            let control = server.control();
            let err = panasonic_act(&control, PanasonicCommand::PauseFeeder(9999))
                .expect_err("no such feeder");
            assert!(err.contains("feeder 9999 does not exist"), "{err}");
            let done = panasonic_act(&control, PanasonicCommand::Remote).expect("remote");
            assert!(done.starts_with("mode remote"), "{done}");
            let status = panasonic_act(&control, PanasonicCommand::Status).expect("status");
            assert!(status.starts_with("ready, remote"), "{status}");
        }
    }

    #[test]
    fn an_open_band_latches_fault_1_and_repair_leaves_it_for_clear_faults() {
        let now = Instant::now();
        let mut twin = Twin::new(&[address(1), address(2)], now).expect("two regulators");
        let done = thermosald_act(
            &mut twin,
            ThermosaldCommand::Fault {
                address: address(1),
                fault: Fault::OpenBand,
            },
            now,
        )
        .expect("provoked");
        assert!(
            done.ends_with("fault number now 1 (sealing band open)"),
            "{done}"
        );
        let done = thermosald_act(&mut twin, ThermosaldCommand::Repair(address(1)), now)
            .expect("repaired");
        assert!(
            done.ends_with("fault number now 1 (sealing band open)"),
            "{done}"
        );
        let status = thermosald_act(&mut twin, ThermosaldCommand::Status, now).expect("status");
        assert!(
            status.contains("regulator 2: ") && status.contains("fault 0 (ready)"),
            "{status}"
        );
        let done = thermosald_act(&mut twin, ThermosaldCommand::PowerCycle(address(1)), now)
            .expect("power cycled");
        assert!(done.ends_with("fault number now 0 (ready)"), "{done}");
        let err = thermosald_act(&mut twin, ThermosaldCommand::Repair(address(5)), now)
            .expect_err("nobody at 5");
        assert_eq!(
            err,
            "no regulator at address 5 on this line (addresses: 1, 2)"
        );
    }
}
