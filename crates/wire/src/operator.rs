//! Operator commands of a simulated device: the words an operator types to provoke what
//! happens at the real device (a feeder runs out, a band breaks), parsed from a table.
//!
//! Each simulator crate defines its command enum next to its twin and implements
//! [`CommandSet`] for it: a [`Syntax`] table (what `help` lists) and `from_words`, which
//! takes the arguments one by one from [`Words`]. [`parse`] does the rest the same way for
//! every device: the command name is looked up case-insensitively, `help [COMMAND]` (or
//! `?`) is every device's, and words left over are refused. Errors say what was typed and
//! what would have been accepted, in words an operator can act on.

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
    pub fn usage(&self) -> String {
        if self.args.is_empty() {
            self.name.to_owned()
        } else {
            format!("{} {}", self.name, self.args)
        }
    }
}

/// `help` itself: every device has it, after its own commands.
pub const HELP: Syntax = Syntax {
    name: "help",
    args: "[COMMAND]",
    help: "lists the commands, or explains one",
};

/// A line that is not a command of this device.
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

impl ParseError {
    /// A name `from_words` does not know: refused as an unknown command (a table entry
    /// without its parse is a slip that each device's tests catch).
    pub fn unknown(word: &str) -> Self {
        ParseError::Unknown {
            word: word.to_owned(),
        }
    }
}

/// Implements `FromStr` for a [`CommandSet`] through [`parse`], so the command is parsed
/// with `line.parse()`.
#[macro_export]
macro_rules! operator_from_str {
    ($command:ty) => {
        impl ::std::str::FromStr for $command {
            type Err = $crate::operator::ParseError;

            /// A command as typed, in any case; `help [COMMAND]` is every device's.
            fn from_str(line: &str) -> ::std::result::Result<Self, Self::Err> {
                $crate::operator::parse(line)
            }
        }
    };
}

/// A device's operator command set.
pub trait CommandSet: Sized {
    /// Every command but `help`, in the order `help` lists them.
    const TABLE: &'static [Syntax];

    /// The command `syntax` with its arguments taken from `words` (words left over are
    /// refused by [`parse`]).
    fn from_words(syntax: &'static Syntax, words: &mut Words<'_>) -> Result<Self, ParseError>;

    /// The request for help: the whole list (`None`) or one command's entry.
    fn help(about: Option<&'static Syntax>) -> Self;
}

/// The arguments of one command, taken one by one.
#[derive(Debug)]
pub struct Words<'a> {
    syntax: &'static Syntax,
    rest: std::str::SplitWhitespace<'a>,
}

impl Words<'_> {
    /// The next word, or [`ParseError::Missing`] naming `what`.
    pub fn word(&mut self, what: &'static str) -> Result<&str, ParseError> {
        self.rest.next().ok_or_else(|| ParseError::Missing {
            command: self.syntax.name,
            what,
            usage: self.syntax.usage(),
        })
    }

    /// The next word, if any.
    pub fn optional(&mut self) -> Option<&str> {
        self.rest.next()
    }

    /// The next word as a number from `min` to `max` (decimal, any unsigned type).
    pub fn number<T>(&mut self, what: &'static str, min: T, max: T) -> Result<T, ParseError>
    where
        T: Copy + Into<u32> + TryFrom<u32>,
    {
        let text = self.word(what)?;
        text.parse::<u32>()
            .ok()
            .filter(|n| (min.into()..=max.into()).contains(n))
            .and_then(|n| T::try_from(n).ok())
            .ok_or_else(|| ParseError::BadNumber {
                what,
                text: text.to_owned(),
                min: min.into(),
                max: max.into(),
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

/// Parses one command line for the device `C`. Command names are case-insensitive;
/// surrounding white space is ignored; an empty line is an unknown command.
pub fn parse<C: CommandSet>(line: &str) -> Result<C, ParseError> {
    let mut rest = line.split_whitespace();
    let first = rest.next().unwrap_or_default();
    let lookup = |word: &str| {
        C::TABLE
            .iter()
            .find(|s| s.name.eq_ignore_ascii_case(word))
            .ok_or_else(|| ParseError::unknown(word))
    };
    if first.eq_ignore_ascii_case(HELP.name) || first == "?" {
        let mut words = Words {
            syntax: &HELP,
            rest,
        };
        let about = words.optional().map(lookup).transpose()?;
        words.end()?;
        return Ok(C::help(about));
    }
    let syntax = lookup(first)?;
    let mut words = Words { syntax, rest };
    let command = C::from_words(syntax, &mut words)?;
    words.end()?;
    Ok(command)
}

/// Every row `help` shows for the device `C`: its commands, then `help`.
pub fn help_rows<C: CommandSet>() -> impl Iterator<Item = &'static Syntax> {
    C::TABLE.iter().chain([&HELP])
}

/// The one-line answer to `help` (every command's usage) or `help COMMAND` (its usage and
/// what it does).
pub fn help_line<C: CommandSet>(about: Option<&'static Syntax>) -> String {
    match about {
        Some(syntax) => format!("{}: {}", syntax.usage(), syntax.help),
        None => {
            let all: Vec<String> = C::TABLE.iter().map(Syntax::usage).collect();
            format!("commands: {}; `help COMMAND` explains one", all.join(" | "))
        }
    }
}

/// The table entries of `C` its `from_words` does not know (each typed alone parses or
/// asks for its argument, never "unknown"): empty for a consistent command set.
pub fn unparsed_entries<C: CommandSet>() -> Vec<&'static str> {
    C::TABLE
        .iter()
        .filter(|syntax| matches!(parse::<C>(syntax.name), Err(ParseError::Unknown { .. })))
        .map(|syntax| syntax.name)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A device with a lamp: `on`, `dim N`.
    #[derive(Debug, PartialEq)]
    enum Lamp {
        On,
        Dim(u32),
        Help(Option<&'static Syntax>),
    }

    impl CommandSet for Lamp {
        const TABLE: &'static [Syntax] = &[
            Syntax {
                name: "on",
                args: "",
                help: "switches the lamp on",
            },
            Syntax {
                name: "dim",
                args: "N",
                help: "dims the lamp to N percent",
            },
        ];

        fn from_words(syntax: &'static Syntax, words: &mut Words<'_>) -> Result<Self, ParseError> {
            match syntax.name {
                "on" => Ok(Lamp::On),
                "dim" => Ok(Lamp::Dim(words.number("a percentage", 0u32, 100)?)),
                other => Err(ParseError::unknown(other)),
            }
        }

        fn help(about: Option<&'static Syntax>) -> Self {
            Lamp::Help(about)
        }
    }

    crate::operator_from_str!(Lamp);

    #[test]
    fn a_command_is_found_whatever_its_case_and_spacing() {
        assert_eq!("  ON \r\n".parse::<Lamp>(), Ok(Lamp::On));
        assert_eq!(parse::<Lamp>("dim\t40"), Ok(Lamp::Dim(40)));
    }

    #[test]
    fn help_and_question_mark_ask_for_the_list_or_one_entry() {
        assert_eq!(parse::<Lamp>("help"), Ok(Lamp::Help(None)));
        assert_eq!(parse::<Lamp>("?"), Ok(Lamp::Help(None)));
        assert_eq!(
            parse::<Lamp>("help DIM"),
            Ok(Lamp::Help(Some(&Lamp::TABLE[1])))
        );
        assert_eq!(
            help_line::<Lamp>(Some(&Lamp::TABLE[1])),
            "dim N: dims the lamp to N percent"
        );
        assert_eq!(
            help_line::<Lamp>(None),
            "commands: on | dim N; `help COMMAND` explains one"
        );
        let rows: Vec<&str> = help_rows::<Lamp>().map(|s| s.name).collect();
        assert_eq!(rows, ["on", "dim", "help"]);
        assert!(unparsed_entries::<Lamp>().is_empty());
    }

    #[test]
    fn a_missing_extra_or_bad_argument_is_refused_with_the_usage() {
        for (line, usage) in [
            ("dim", "`dim` needs a percentage: dim N"),
            ("on now", "`on` does not take `now`: on"),
            (
                "dim 101",
                "a percentage `101` is not a number from 0 to 100",
            ),
            (
                "help off",
                "unknown command `off`; `help` lists the commands",
            ),
        ] {
            let refusal = parse::<Lamp>(line).map_err(|e| e.to_string());
            assert_eq!(refusal, Err(usage.to_owned()), "{line:?}");
        }
    }
}
