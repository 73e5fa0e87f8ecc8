//! Programs and their names: what C0/C1/C0R/C3/C1RP carry (3.3-1 … 3.3-12).
//!
//! - [`ProgramName`]: the 15-character name of a product program; on the wire `P` + name,
//!   padded with blanks to 15 characters where a fixed width is used (C3, C1RP).
//! - [`Target`]: what a transfer is about: a product program (named) or one of the
//!   libraries or the machine data (unnamed).
//! - [`ProgramList`] / [`ProgramListEntry`]: the C1RP answer, `yy/mm/dd` + `P` + 15
//!   characters per entry.
//! - [`ProgramText`]: a program or library as transferred, `%HEADER` … `*` CRLF, with the
//!   entry count the storage limits apply to.
//! - [`ConditionData`]: the one line of machine data `C0G` may change.
//!
//! The program data format itself is in a separate Panasonic manual we do not have
//! ("Prg./DATA FORMAT"); what this module assumes about it is marked \[?\] and kept small.

use std::fmt;
use std::str::FromStr;

use serde::Serialize;

use crate::calendar::{CalendarParseError, PROGRAM_DATE_LEN, ProgramDate};

/// Longest program name (3.3-12: "Fixed at 15 characters").
pub const PROGRAM_NAME_LEN: usize = 15;
/// Width of `P` + name in fixed-width fields.
pub const PROGRAM_FIELD_LEN: usize = 1 + PROGRAM_NAME_LEN;

/// Most product programs a machine stores (3.3-4).
pub const MAX_PROGRAMS: usize = 100;
/// Most steps in one product program (3.3-4).
pub const MAX_STEPS: usize = 5000;
/// Most entries in the part library (3.3-4).
pub const MAX_PART_LIBRARY: usize = 1000;
/// Most entries in the mark library (3.3-4).
pub const MAX_MARK_LIBRARY: usize = 500;
/// Most entries in the supply library (3.3-4).
pub const MAX_SUPPLY_LIBRARY: usize = 500;
/// Most entries in the nozzle library (3.3-4).
pub const MAX_NOZZLE_LIBRARY: usize = 99;

/// Line end inside data fields.
pub const CRLF: &[u8] = b"\r\n";
/// The line that ends every data block (`*` CRLF).
pub const END_MARK: &[u8] = b"*\r\n";

/// The name of a product program: 1 to 15 printable ASCII characters.
///
/// Trailing blanks are padding on the wire and cannot be told from the name (fact sheet
/// §6), so [`ProgramName::new`] drops them: `"ABC  "` and `"ABC"` are the same program.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(transparent)]
pub struct ProgramName(String);

/// A text that cannot be a program name.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ProgramNameError {
    /// Empty, or only blanks.
    #[error("a program name needs at least one character")]
    Empty,
    /// Longer than 15 characters.
    #[error("program name {name:?} has {len} characters; the machine allows {max}")]
    TooLong {
        /// The name given.
        name: String,
        /// Its length.
        len: usize,
        /// The limit (15).
        max: usize,
    },
    /// A character outside printable ASCII.
    #[error(
        "program name {name:?} has {found:?} at position {offset}; only printable ASCII is allowed"
    )]
    BadChar {
        /// The name given.
        name: String,
        /// Position.
        offset: usize,
        /// The character.
        found: char,
    },
    /// The `P` in front of a name on the wire is missing.
    #[error("{field:?} is not a product program field: it must start with P")]
    NotAProduct {
        /// The field.
        field: String,
    },
}

impl ProgramName {
    /// A program name; trailing blanks are dropped.
    pub fn new(name: &str) -> Result<ProgramName, ProgramNameError> {
        let trimmed = name.trim_end_matches(' ');
        if trimmed.is_empty() {
            return Err(ProgramNameError::Empty);
        }
        if let Some((offset, found)) = trimmed
            .char_indices()
            .find(|&(_, c)| !(' '..='~').contains(&c))
        {
            return Err(ProgramNameError::BadChar {
                name: name.to_owned(),
                offset,
                found,
            });
        }
        if trimmed.len() > PROGRAM_NAME_LEN {
            return Err(ProgramNameError::TooLong {
                name: name.to_owned(),
                len: trimmed.len(),
                max: PROGRAM_NAME_LEN,
            });
        }
        Ok(ProgramName(trimmed.to_owned()))
    }

    /// The name, without padding.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// Appends `P` + the name padded with blanks to 15 characters (16 bytes).
    pub fn write_field(&self, out: &mut Vec<u8>) {
        out.push(b'P');
        out.extend_from_slice(self.0.as_bytes());
        out.extend(std::iter::repeat_n(b' ', PROGRAM_NAME_LEN - self.0.len()));
    }

    /// `P` + the name padded to 15 characters.
    pub fn to_field(&self) -> String {
        format!("P{:<width$}", self.0, width = PROGRAM_NAME_LEN)
    }

    /// Reads `P` + name, padded or not (as C3, C1RP and commands carry it).
    pub fn parse_field(field: &[u8]) -> Result<ProgramName, ProgramNameError> {
        let text = String::from_utf8_lossy(field);
        match text.strip_prefix('P') {
            Some(name) => ProgramName::new(name),
            None => Err(ProgramNameError::NotAProduct {
                field: text.into_owned(),
            }),
        }
    }
}

impl FromStr for ProgramName {
    type Err = ProgramNameError;

    fn from_str(name: &str) -> Result<ProgramName, ProgramNameError> {
        ProgramName::new(name)
    }
}

impl fmt::Display for ProgramName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// The kinds of data a C0/C1 transfer is about, by their identifier letter (3.3-1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub enum TargetKind {
    /// `P`: a product program (named).
    Product,
    /// `L`: the part library.
    PartLibrary,
    /// `B`: the mark library.
    MarkLibrary,
    /// `V`: the nozzle library.
    NozzleLibrary,
    /// `Y`: the supply library.
    SupplyLibrary,
    /// `G`: machine data.
    MachineData,
}

impl TargetKind {
    /// Every kind, in the manual's order.
    pub const ALL: [TargetKind; 6] = [
        TargetKind::Product,
        TargetKind::PartLibrary,
        TargetKind::MarkLibrary,
        TargetKind::NozzleLibrary,
        TargetKind::SupplyLibrary,
        TargetKind::MachineData,
    ];

    /// The identifier letter.
    pub const fn letter(self) -> char {
        match self {
            TargetKind::Product => 'P',
            TargetKind::PartLibrary => 'L',
            TargetKind::MarkLibrary => 'B',
            TargetKind::NozzleLibrary => 'V',
            TargetKind::SupplyLibrary => 'Y',
            TargetKind::MachineData => 'G',
        }
    }

    /// The kind for an identifier letter.
    pub fn from_letter(letter: char) -> Option<TargetKind> {
        TargetKind::ALL
            .into_iter()
            .find(|kind| kind.letter() == letter)
    }

    /// The most entries one item of this kind holds: steps for a program, entries for a
    /// library; `None` for machine data.
    pub const fn entry_limit(self) -> Option<usize> {
        match self {
            TargetKind::Product => Some(MAX_STEPS),
            TargetKind::PartLibrary => Some(MAX_PART_LIBRARY),
            TargetKind::MarkLibrary => Some(MAX_MARK_LIBRARY),
            TargetKind::NozzleLibrary => Some(MAX_NOZZLE_LIBRARY),
            TargetKind::SupplyLibrary => Some(MAX_SUPPLY_LIBRARY),
            TargetKind::MachineData => None,
        }
    }

    /// What it is, in words.
    pub const fn describe(self) -> &'static str {
        match self {
            TargetKind::Product => "product program",
            TargetKind::PartLibrary => "part library",
            TargetKind::MarkLibrary => "mark library",
            TargetKind::NozzleLibrary => "nozzle library",
            TargetKind::SupplyLibrary => "supply library",
            TargetKind::MachineData => "machine data",
        }
    }
}

/// What a transfer is about: a named product program, or an unnamed library or machine data.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize)]
pub enum Target {
    /// `P` + name.
    Product(ProgramName),
    /// `L`.
    PartLibrary,
    /// `B`.
    MarkLibrary,
    /// `V`.
    NozzleLibrary,
    /// `Y`.
    SupplyLibrary,
    /// `G`.
    MachineData,
}

/// A target field that is not one.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum TargetError {
    /// Nothing after the command.
    #[error("the command names no program or library")]
    Missing,
    /// An identifier letter the manual does not list.
    #[error("{letter:?} is not a program type (P, L, B, V, Y or G)")]
    UnknownKind {
        /// The letter found.
        letter: char,
    },
    /// A library or machine data with a name after it.
    #[error("the {kind} carries no name, but {extra:?} follows its letter")]
    UnexpectedName {
        /// What the letter names.
        kind: &'static str,
        /// The text after the letter.
        extra: String,
    },
    /// A bad program name.
    #[error(transparent)]
    Name(#[from] ProgramNameError),
}

impl Target {
    /// The kind.
    pub fn kind(&self) -> TargetKind {
        match self {
            Target::Product(_) => TargetKind::Product,
            Target::PartLibrary => TargetKind::PartLibrary,
            Target::MarkLibrary => TargetKind::MarkLibrary,
            Target::NozzleLibrary => TargetKind::NozzleLibrary,
            Target::SupplyLibrary => TargetKind::SupplyLibrary,
            Target::MachineData => TargetKind::MachineData,
        }
    }

    /// The program name, for a product program.
    pub fn program(&self) -> Option<&ProgramName> {
        match self {
            Target::Product(name) => Some(name),
            _ => None,
        }
    }

    /// The text after the command: `PABC` (name not padded, as in the manual's
    /// `C0P123456789ABC`), or the library letter.
    pub fn to_wire(&self) -> String {
        match self {
            Target::Product(name) => format!("P{name}"),
            other => other.kind().letter().to_string(),
        }
    }

    /// Reads the text after the command.
    pub fn parse(text: &str) -> Result<Target, TargetError> {
        let mut chars = text.chars();
        let letter = chars.next().ok_or(TargetError::Missing)?;
        let rest = chars.as_str();
        let kind = TargetKind::from_letter(letter).ok_or(TargetError::UnknownKind { letter })?;
        let unnamed = |target: Target| {
            if rest.is_empty() {
                Ok(target)
            } else {
                Err(TargetError::UnexpectedName {
                    kind: kind.describe(),
                    extra: rest.to_owned(),
                })
            }
        };
        match kind {
            TargetKind::Product => Ok(Target::Product(ProgramName::new(rest)?)),
            TargetKind::PartLibrary => unnamed(Target::PartLibrary),
            TargetKind::MarkLibrary => unnamed(Target::MarkLibrary),
            TargetKind::NozzleLibrary => unnamed(Target::NozzleLibrary),
            TargetKind::SupplyLibrary => unnamed(Target::SupplyLibrary),
            TargetKind::MachineData => unnamed(Target::MachineData),
        }
    }
}

impl fmt::Display for Target {
    /// `product program ABC`, `part library`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Target::Product(name) => write!(f, "product program {name}"),
            other => f.write_str(other.kind().describe()),
        }
    }
}

/// One line of the program list: when the program was registered or last revised, and
/// its name. On the wire: `yy/mm/dd` + `P` + 15 characters + CRLF (26 bytes).
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize)]
pub struct ProgramListEntry {
    /// Date registered or revised.
    pub date: ProgramDate,
    /// The program.
    pub name: ProgramName,
}

/// Bytes of one program list entry on the wire, CRLF included.
pub const PROGRAM_LIST_ENTRY_LEN: usize = PROGRAM_DATE_LEN + PROGRAM_FIELD_LEN + CRLF.len();

/// The C1RP answer: every stored product program.
#[derive(Debug, Clone, Default, PartialEq, Eq, Hash, Serialize)]
#[serde(transparent)]
pub struct ProgramList(pub Vec<ProgramListEntry>);

/// A data block that is not a program list.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ProgramListError {
    /// The `*` CRLF end mark is missing.
    #[error("the program list does not end with the \"*\" line")]
    MissingEnd,
    /// A line that is not `yy/mm/dd` + `P` + name.
    #[error("program list line {line} ({text:?}) is not a date followed by P and a name")]
    BadLine {
        /// 1-based line number.
        line: usize,
        /// The line of text as the machine sent it.
        text: String,
    },
    /// A line with a bad date.
    #[error("program list line {line}: {source}")]
    BadDate {
        /// 1-based line number.
        line: usize,
        /// What is wrong with the date.
        source: CalendarParseError,
    },
    /// A line with a bad name.
    #[error("program list line {line}: {source}")]
    BadName {
        /// 1-based line number.
        line: usize,
        /// What is wrong with the name.
        source: ProgramNameError,
    },
    /// Lines after the end mark.
    #[error("the program list has data after its \"*\" end line")]
    TrailingData,
}

impl ProgramList {
    /// Appends the data block: one 26-byte line per entry, then `*` CRLF.
    /// 3.3-10's example of three programs is 81 bytes.
    pub fn write(&self, out: &mut Vec<u8>) {
        for entry in &self.0 {
            entry.date.write(out);
            entry.name.write_field(out);
            out.extend_from_slice(CRLF);
        }
        out.extend_from_slice(END_MARK);
    }

    /// The data block.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.0.len() * PROGRAM_LIST_ENTRY_LEN + END_MARK.len());
        self.write(&mut out);
        out
    }

    /// Reads a data block. Lines may end in CRLF or LF; names may or may not be padded.
    pub fn parse(data: &[u8]) -> Result<ProgramList, ProgramListError> {
        let mut entries = Vec::new();
        let mut lines = lines(data).enumerate();
        for (index, line) in lines.by_ref() {
            let number = index + 1;
            if line == b"*" {
                return match lines.next() {
                    None => Ok(ProgramList(entries)),
                    Some(_) => Err(ProgramListError::TrailingData),
                };
            }
            let bad_line = || ProgramListError::BadLine {
                line: number,
                text: String::from_utf8_lossy(line).into_owned(),
            };
            let (date, name) = line
                .split_at_checked(PROGRAM_DATE_LEN)
                .ok_or_else(bad_line)?;
            if name.first() != Some(&b'P') {
                return Err(bad_line());
            }
            let date = ProgramDate::parse(date).map_err(|source| ProgramListError::BadDate {
                line: number,
                source,
            })?;
            let name =
                ProgramName::parse_field(name).map_err(|source| ProgramListError::BadName {
                    line: number,
                    source,
                })?;
            entries.push(ProgramListEntry { date, name });
        }
        Err(ProgramListError::MissingEnd)
    }
}

/// The lines of a data block: split at LF, a CR before it removed. A final line without
/// LF is a line too; nothing after a final LF is.
pub(crate) fn lines(data: &[u8]) -> impl Iterator<Item = &[u8]> {
    let body = data.strip_suffix(b"\n").unwrap_or(data);
    let empty = data.is_empty();
    body.split(|&b| b == b'\n')
        .map(|line| line.strip_suffix(b"\r").unwrap_or(line))
        .filter(move |_| !empty)
}

/// A program, library or machine data block as transferred: bytes ending in `*` CRLF.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct ProgramText(Vec<u8>);

/// Data that is not a program text.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ProgramTextError {
    /// The `*` CRLF end mark is missing.
    #[error("the data ({len} bytes) does not end with the \"*\" CR LF end mark")]
    MissingEnd {
        /// Length of the data.
        len: usize,
    },
}

impl ProgramText {
    /// Checks the end mark.
    pub fn new(data: Vec<u8>) -> Result<ProgramText, ProgramTextError> {
        match data.strip_suffix(END_MARK) {
            Some(body) if body.is_empty() || body.ends_with(b"\n") => Ok(ProgramText(data)),
            _ => Err(ProgramTextError::MissingEnd { len: data.len() }),
        }
    }

    /// The bytes.
    pub fn as_bytes(&self) -> &[u8] {
        &self.0
    }

    /// The bytes, by value.
    pub fn into_bytes(self) -> Vec<u8> {
        self.0
    }

    /// How many steps (program) or entries (library) the text holds, for the limits of
    /// 3.3-4.
    ///
    /// \[?\] The data format is in a manual we do not have. We count every non-empty line
    /// that is not in the `%HEADER` section, not a section mark (`%…`), not a sub-section
    /// mark (`&…`, as in machine data's `&CONDITIONDATA1`) and not the `*` end mark.
    pub fn entries(&self) -> usize {
        let mut in_header = false;
        let mut count = 0;
        for line in lines(&self.0) {
            match line.first() {
                None => {}
                Some(b'%') => in_header = line == HEADER_SECTION.as_bytes(),
                Some(b'&') => {}
                Some(b'*') if line == b"*" => {}
                Some(_) if !in_header => count += 1,
                Some(_) => {}
            }
        }
        count
    }

    /// The value of a `KEY=VALUE` line of the `%HEADER` section, e.g. `NAME`.
    pub fn header_value(&self, key: &str) -> Option<String> {
        let mut in_header = false;
        for line in lines(&self.0) {
            if line.first() == Some(&b'%') {
                in_header = line == HEADER_SECTION.as_bytes();
            } else if in_header
                && let Some(value) = line
                    .strip_prefix(key.as_bytes())
                    .and_then(|rest| rest.strip_prefix(b"="))
            {
                return Some(String::from_utf8_lossy(value).into_owned());
            }
        }
        None
    }
}

/// The header section mark.
pub const HEADER_SECTION: &str = "%HEADER";

/// The sub-section of machine data that `C0G` may change (3.3-4).
pub const CONDITION_DATA_MARK: &str = "&CONDITIONDATA1";
/// The fixed data number that starts the condition line (3.3-4 example).
pub const CONDITION_DATA_NUMBER: u32 = 1_010_001;

/// The part of the operating-condition data a host may change with `C0G` (3.3-4): the
/// line after `&CONDITIONDATA1`, e.g. `1010001,1,1,0,0`.
///
/// \[I\] Which flag sits in which position is inferred from the order the manual lists them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub struct ConditionData {
    /// Pass-through (boards go through without placement).
    pub pass_through: bool,
    /// Evaluation mode.
    pub evaluation_mode: bool,
    /// Offset manual mark position.
    pub offset_manual_mark: bool,
    /// Evaluation-mode condition "H down/away".
    pub evaluation_h_down: bool,
}

/// Machine data that is not a `&CONDITIONDATA1` block.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ConditionDataError {
    /// No `&CONDITIONDATA1` line followed by a data line.
    #[error("the machine data has no {CONDITION_DATA_MARK} line followed by a data line")]
    Missing,
    /// The data line is not `1010001,f,f,f,f` with flags 0 or 1.
    #[error(
        "condition data line {line:?} is not \"{CONDITION_DATA_NUMBER},f,f,f,f\" with flags 0 or 1"
    )]
    BadLine {
        /// The line found.
        line: String,
    },
}

impl ConditionData {
    /// Reads the line after `&CONDITIONDATA1` in a machine data block.
    pub fn parse(data: &[u8]) -> Result<ConditionData, ConditionDataError> {
        let mut all = lines(data);
        all.by_ref()
            .find(|line| *line == CONDITION_DATA_MARK.as_bytes())
            .ok_or(ConditionDataError::Missing)?;
        let line = all.next().ok_or(ConditionDataError::Missing)?;
        let bad = || ConditionDataError::BadLine {
            line: String::from_utf8_lossy(line).into_owned(),
        };
        let fields: Vec<&[u8]> = line.split(|&b| b == b',').collect();
        let [number, a, b, c, d] = fields.as_slice() else {
            return Err(bad());
        };
        if wire::ascii::parse_unsigned(number) != Some(CONDITION_DATA_NUMBER) {
            return Err(bad());
        }
        let flag = |field: &[u8]| match field {
            b"0" => Ok(false),
            b"1" => Ok(true),
            _ => Err(bad()),
        };
        Ok(ConditionData {
            pass_through: flag(a)?,
            evaluation_mode: flag(b)?,
            offset_manual_mark: flag(c)?,
            evaluation_h_down: flag(d)?,
        })
    }

    /// The condition line, e.g. `1010001,1,1,0,0`.
    pub fn line(&self) -> String {
        let f = |on: bool| if on { '1' } else { '0' };
        format!(
            "{CONDITION_DATA_NUMBER},{},{},{},{}",
            f(self.pass_through),
            f(self.evaluation_mode),
            f(self.offset_manual_mark),
            f(self.evaluation_h_down)
        )
    }

    /// A machine data block carrying this condition data, as `C0G` sends it and `C1G` returns
    /// it: `%HEADER` / `NAME=G` / `&CONDITIONDATA1` / the line / `*`, lines ending in CRLF.
    pub fn to_text(&self) -> ProgramText {
        let text = format!(
            "{HEADER_SECTION}\r\nNAME=G\r\n{CONDITION_DATA_MARK}\r\n{}\r\n*\r\n",
            self.line()
        );
        ProgramText(text.into_bytes())
    }
}

#[cfg(test)]
mod tests;
