//! What an operator can do to the regulators of a simulated line while it serves: provoke
//! a fault's physical cause, repair it, switch a regulator off and on, look at them all.
//!
//! `cellbus sim thermosald` reads these commands on its standard input and the gateway's
//! demo cell scripts them; both parse with [`str::parse`] and carry them out with
//! [`apply`], so the words and their effects are the same everywhere:
//!
//! ```
//! use std::time::Instant;
//! use thermosald::Address;
//! use thermosald::device::RegulatorBus;
//! use thermosald::device::operator::{Command, apply};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let now = Instant::now();
//! let mut line = RegulatorBus::new(&[Address::new(1)?], now)?;
//! let command: Command = "fault 1 open-band".parse()?;
//! let done = apply(&mut line, command, now)?;
//! assert!(done.ends_with("fault number now 1 (sealing band open)"));
//! # Ok(())
//! # }
//! ```

use std::fmt;
use std::time::Instant;

use wire::operator::{CommandSet, ParseError, Syntax, Words, help_line};

use super::{Phase, Regulator, RegulatorBus};
use crate::diagnostic::{self, Fault};
use crate::frame::{Address, RawValue};

/// One operator command for a line of regulators.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// Provokes the physical cause of `kind` at the regulator at `address`.
    Fault {
        /// Which regulator.
        address: Address,
        /// Which cause.
        kind: Fault,
    },
    /// Removes every fault cause of the regulator: clear-faults (14) then clears it.
    Repair {
        /// Which regulator.
        address: Address,
    },
    /// Switches the regulator off and on (working data reloaded from EEPROM).
    PowerCycle {
        /// Which regulator.
        address: Address,
    },
    /// Every regulator's phase, temperature and fault.
    Status,
    /// The list of commands, or one command explained.
    Help(Option<&'static Syntax>),
}

/// Why a command could not be carried out.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Refused {
    /// No regulator on the line answers to the address.
    #[error("no regulator at address {address} on this line (addresses: {})", Listed(.on_line))]
    NoRegulator {
        /// The address asked for.
        address: Address,
        /// The addresses of the regulators on the line.
        on_line: Vec<Address>,
    },
}

/// A fault cause as typed: `open-band`, `short`, `over-current`, `not-reached`.
const FAULT_WORDS: [(&str, Fault); 4] = [
    ("open-band", Fault::OpenBand),
    ("short", Fault::ShortCircuit),
    ("over-current", Fault::OverCurrent),
    ("not-reached", Fault::TemperatureNotReached),
];

impl CommandSet for Command {
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
        Ok(match syntax.name {
            "fault" => {
                let address = address(words)?;
                let text = words.word("a fault cause")?;
                let kind = FAULT_WORDS
                    .iter()
                    .find(|(word, _)| word.eq_ignore_ascii_case(text))
                    .map(|(_, fault)| *fault)
                    .ok_or_else(|| ParseError::BadChoice {
                        what: "a fault cause",
                        text: text.to_owned(),
                        choices: "open-band, short, over-current or not-reached",
                    })?;
                Command::Fault { address, kind }
            }
            "repair" => Command::Repair {
                address: address(words)?,
            },
            "power-cycle" => Command::PowerCycle {
                address: address(words)?,
            },
            "status" => Command::Status,
            other => return Err(ParseError::unknown(other)),
        })
    }

    fn help(about: Option<&'static Syntax>) -> Self {
        Command::Help(about)
    }
}

wire::operator_from_str!(Command);

/// Carries out `command` on the regulators of `line` at `now`; says in words what happened
/// and the fault number the regulator shows now, or why nothing happened.
pub fn apply(line: &mut RegulatorBus, command: Command, now: Instant) -> Result<String, Refused> {
    let (address, done): (Address, fn(&mut Regulator, Instant) -> String) = match command {
        Command::Status => return Ok(status(line, now)),
        Command::Help(about) => return Ok(help_line::<Command>(about)),
        Command::Fault { address, kind } => {
            let regulator = regulator_at(line, address)?;
            regulator.provoke(kind, now);
            let done = format!(
                "regulator {address}: cause of \"{}\" provoked",
                kind.description()
            );
            return Ok(with_fault_number(regulator, done, now));
        }
        Command::Repair { address } => (address, |regulator, now| {
            for fault in Fault::ALL {
                regulator.remove_cause(fault, now);
            }
            "every fault cause removed; clear-faults (message 14) clears a latched fault".to_owned()
        }),
        Command::PowerCycle { address } => (address, |regulator, now| {
            regulator.power_cycle(now);
            "switched off and on, working data reloaded from EEPROM".to_owned()
        }),
    };
    let regulator = regulator_at(line, address)?;
    let done = format!("regulator {address}: {}", done(regulator, now));
    Ok(with_fault_number(regulator, done, now))
}

/// The regulator's address as typed: 0 to 7.
fn address(words: &mut Words<'_>) -> Result<Address, ParseError> {
    let number = words.number("regulator address", Address::MIN, Address::MAX)?;
    Address::new(number).map_err(|_| ParseError::BadNumber {
        what: "regulator address",
        text: number.to_string(),
        min: u32::from(Address::MIN),
        max: u32::from(Address::MAX),
    })
}

/// One line on every regulator: phase, measured temperature, fault number in words.
fn status(line: &mut RegulatorBus, now: Instant) -> String {
    let all: Vec<String> = line
        .regulators_mut()
        .iter_mut()
        .map(|regulator| {
            let who = regulator
                .address()
                .map_or_else(|| "no address".to_owned(), |a| a.to_string());
            let status = regulator.status(now);
            // What the regulator reports (run-time item 1): 0–999 °C, so a shorted band's
            // far lower reckoning shows as 0, never as -616 or -0.
            let temperature = status.measured_temperature.map_or_else(
                || "no temperature".to_owned(),
                |t| format!("{} °C", RawValue::saturating(t).get()),
            );
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

/// The regulator at `address`, or which addresses the line has.
fn regulator_at(line: &mut RegulatorBus, address: Address) -> Result<&mut Regulator, Refused> {
    let on_line: Vec<Address> = line
        .regulators()
        .iter()
        .filter_map(Regulator::address)
        .collect();
    line.regulator_mut(address)
        .ok_or(Refused::NoRegulator { address, on_line })
}

/// `done` followed by the fault number the regulator shows now.
fn with_fault_number(regulator: &mut Regulator, done: String, now: Instant) -> String {
    let fault = regulator.fault_number(now);
    format!(
        "{done}; fault number now {fault} ({})",
        diagnostic::describe(fault)
    )
}

/// Addresses separated by commas.
struct Listed<'a>(&'a [Address]);

impl fmt::Display for Listed<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (n, address) in self.0.iter().enumerate() {
            if n > 0 {
                f.write_str(", ")?;
            }
            write!(f, "{address}")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn address(n: u8) -> Address {
        Address::new(n).expect("a valid address")
    }

    fn parsed(line: &str) -> Result<Command, ParseError> {
        line.parse()
    }

    #[test]
    fn a_fault_command_names_the_regulator_and_the_kind() {
        let cases = [
            ("fault 1 open-band", 1, Fault::OpenBand),
            ("fault 0 short", 0, Fault::ShortCircuit),
            ("FAULT 7 Over-Current", 7, Fault::OverCurrent),
            ("fault 2 not-reached", 2, Fault::TemperatureNotReached),
        ];
        for (line, n, kind) in cases {
            assert_eq!(
                parsed(line),
                Ok(Command::Fault {
                    address: address(n),
                    kind
                }),
                "{line:?}"
            );
        }
    }

    #[test]
    fn repair_power_cycle_status_and_help_parse_into_their_commands() {
        assert_eq!(
            parsed("repair 1"),
            Ok(Command::Repair {
                address: address(1)
            })
        );
        assert_eq!(
            parsed(" power-cycle   4 \n"),
            Ok(Command::PowerCycle {
                address: address(4)
            })
        );
        assert_eq!(parsed("status"), Ok(Command::Status));
        assert_eq!(parsed("help"), Ok(Command::Help(None)));
        assert_eq!(
            parsed("help fault"),
            Ok(Command::Help(Some(&Command::TABLE[0])))
        );
    }

    #[test]
    fn status_shows_the_temperature_the_regulator_reports_even_with_a_shorted_band() {
        let now = Instant::now();
        let mut line = RegulatorBus::new(&[address(1)], now).expect("one regulator");
        let shown = apply(&mut line, Command::Status, now).expect("a status");
        assert!(shown.starts_with("regulator 1: "), "{shown}");
        assert!(shown.contains(" °C, fault "), "{shown}");
        let short = Command::Fault {
            address: address(1),
            kind: Fault::ShortCircuit,
        };
        apply(&mut line, short, now).expect("provoked");
        let later = now + std::time::Duration::from_secs(1);
        let reckoned = line.regulators_mut()[0]
            .status(later)
            .measured_temperature
            .expect("a shorted band is measured");
        assert!(reckoned < -100.0, "{reckoned}");
        let shown = apply(&mut line, Command::Status, later).expect("a status");
        assert!(shown.contains(", 0 °C, fault "), "{shown}");
    }

    #[test]
    fn every_table_entry_is_parsed_by_from_words() {
        assert_eq!(wire::operator::unparsed_entries::<Command>(), [""; 0]);
    }

    #[test]
    fn a_bad_cause_address_or_missing_word_is_refused_in_the_control_channels_words() {
        let error = |line: &str| parsed(line).map_err(|e| e.to_string()).expect_err(line);
        assert_eq!(
            error("fault 1 melted"),
            "`melted` is not a fault cause: use open-band, short, over-current or not-reached"
        );
        assert_eq!(
            error("fault 9 short"),
            "regulator address `9` is not a number from 0 to 7"
        );
        assert_eq!(
            error("repair x"),
            "regulator address `x` is not a number from 0 to 7"
        );
        assert_eq!(
            error("fault 1"),
            "`fault` needs a fault cause: fault ADDR open-band|short|over-current|not-reached"
        );
        assert_eq!(
            error("repair 1 2"),
            "`repair` does not take `2`: repair ADDR"
        );
        assert_eq!(
            error("remote"),
            "unknown command `remote`; `help` lists the commands"
        );
    }

    #[test]
    fn an_open_band_latches_fault_1_and_repair_leaves_it_for_clear_faults() {
        let now = Instant::now();
        let mut line = RegulatorBus::new(&[address(1), address(2)], now).expect("two regulators");
        let fault = Command::Fault {
            address: address(1),
            kind: Fault::OpenBand,
        };
        assert_eq!(
            apply(&mut line, fault, now),
            Ok(
                "regulator 1: cause of \"sealing band open\" provoked; fault number now 1 \
                (sealing band open)"
                    .to_owned()
            )
        );
        let repair = Command::Repair {
            address: address(1),
        };
        let done = apply(&mut line, repair, now).expect("repaired");
        assert!(
            done.ends_with("fault number now 1 (sealing band open)"),
            "{done}"
        );
        let status = apply(&mut line, Command::Status, now).expect("status");
        assert!(
            status.contains("regulator 2: ") && status.contains("fault 0 (ready)"),
            "{status}"
        );
        let cycle = Command::PowerCycle {
            address: address(1),
        };
        let done = apply(&mut line, cycle, now).expect("power cycled");
        assert!(done.ends_with("fault number now 0 (ready)"), "{done}");
    }

    #[test]
    fn a_command_for_an_absent_regulator_names_the_addresses_on_the_line() {
        let now = Instant::now();
        let mut line = RegulatorBus::new(&[address(1), address(2)], now).expect("two regulators");
        let refused = apply(
            &mut line,
            Command::Repair {
                address: address(5),
            },
            now,
        )
        .expect_err("nobody at 5");
        assert_eq!(
            refused,
            Refused::NoRegulator {
                address: address(5),
                on_line: vec![address(1), address(2)]
            }
        );
        assert_eq!(
            refused.to_string(),
            "no regulator at address 5 on this line (addresses: 1, 2)"
        );
    }

    #[test]
    fn help_is_answered_by_apply_on_one_line() {
        let now = Instant::now();
        let mut line = RegulatorBus::new(&[address(1)], now).expect("one regulator");
        let list = apply(&mut line, Command::Help(None), now).expect("help");
        assert!(!list.contains('\n'), "{list}");
        assert!(list.contains("power-cycle ADDR"), "{list}");
    }
}
