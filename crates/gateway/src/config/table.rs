//! What every part of the configuration shares: its errors, located at a file, line and
//! column ([`ConfigError`]); a table of the file handed to the plug-in that owns it
//! ([`Table`]: an interface's `[mqtt]`, a device kind's own keys); what a plug-in read
//! from it, kept in the checked configuration for the plug-in to take back
//! ([`Settings`]); and the checks of durations and bounded numbers every table uses.
//!
//! It imports nothing of the gateway: the cell's skeleton (`config`), the device kinds
//! (`driver::*`) and the interfaces (`northbound::*`) all build on it.

use std::any::Any;
use std::collections::HashMap;
use std::fmt;
use std::ops::{Range, RangeInclusive};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use serde::de::DeserializeOwned;
use toml::Spanned;
use toml::de::{DeTable, DeValue};

pub use kit::bounded::read_bounded;
pub use kit::mqtt::hide_userinfo;

/// Why a configuration was refused.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ConfigError {
    /// The file could not be read (missing, not a file, larger than [`MAX_CONFIG`], not
    /// UTF-8).
    #[error("config {path} {why}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why, in words that follow the path (`cannot be read: …`, `is not a file`).
        why: String,
    },
    /// The file is not valid, at a place in it.
    #[error("{}", self.describe())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// Line, from 1.
        line: usize,
        /// Column, from 1.
        column: usize,
        /// What is wrong.
        message: String,
        /// The text of the line, for the caret display.
        source_line: String,
    },
    /// A register list (`registers_csv`) that is not valid, at a row (its line in the
    /// file, the header being row 1) and column.
    #[error("{}: row {row}: {message}", path.display())]
    Csv {
        /// The CSV file.
        path: PathBuf,
        /// The row (line of the file), from 1.
        row: u64,
        /// What is wrong, naming the column.
        message: String,
    },
    /// More than one mistake, in the order of the file.
    #[error("{}", self.describe())]
    Several(Vec<ConfigError>),
}

impl ConfigError {
    /// `errors` as one error: `None` for none, the error itself for one, [`Several`]
    /// (sorted by line and column) for more.
    ///
    /// [`Several`]: ConfigError::Several
    pub fn all(mut errors: Vec<ConfigError>) -> Option<ConfigError> {
        match errors.len() {
            0 => None,
            1 => errors.pop(),
            _ => {
                errors.sort_by_key(|e| e.position().unwrap_or((0, 0)));
                Some(ConfigError::Several(errors))
            }
        }
    }

    /// Each mistake (one, or each of [`ConfigError::Several`]).
    pub fn each(&self) -> &[ConfigError] {
        match self {
            ConfigError::Several(errors) => errors,
            one => std::slice::from_ref(one),
        }
    }

    fn describe(&self) -> String {
        match self {
            ConfigError::Read { .. } | ConfigError::Csv { .. } => self.to_string(),
            ConfigError::Several(errors) => {
                let each: Vec<String> = errors.iter().map(ToString::to_string).collect();
                format!("{} mistakes:\n{}", errors.len(), each.join("\n"))
            }
            ConfigError::Invalid {
                path,
                line,
                column,
                message,
                source_line,
            } => {
                let gutter = line.to_string().len();
                format!(
                    "{}:{line}:{column}: {message}\n{:gutter$} |\n{line} | {source_line}\n{:gutter$} | {:>column$}",
                    path.display(),
                    "",
                    "",
                    "^"
                )
            }
        }
    }

    /// Where the error is: `(line, column)`, from 1.
    pub fn position(&self) -> Option<(usize, usize)> {
        match self {
            ConfigError::Invalid { line, column, .. } => Some((*line, *column)),
            ConfigError::Several(errors) => errors.first().and_then(ConfigError::position),
            ConfigError::Read { .. } | ConfigError::Csv { .. } => None,
        }
    }
}

/// Largest configuration file, or CSV register list given to `cellbus config import-csv`.
pub const MAX_CONFIG: u64 = 16 << 20;

/// The text of the file at `path`: at most [`MAX_CONFIG`] bytes of UTF-8.
pub fn read_text(path: &Path) -> Result<String, ConfigError> {
    let unreadable = |why: String| ConfigError::Read {
        path: path.to_owned(),
        why,
    };
    read_bounded_text(path, MAX_CONFIG).map_err(unreadable)
}

/// The text of the file at `path`, as [`read_bounded`] reads it, refused unless UTF-8.
pub fn read_bounded_text(path: &Path, max: u64) -> Result<String, String> {
    String::from_utf8(read_bounded(path, max)?).map_err(|e| {
        format!(
            "is not UTF-8 text (byte {} is not)",
            e.utf8_error().valid_up_to() + 1
        )
    })
}

/// toml's message, in words where it speaks of Rust's types: a whole number beyond 64 bits
/// is "invalid type: integer `…` as i128, expected any value".
pub(crate) fn plain_toml_message(message: &str) -> String {
    let message = message.trim_end();
    message
        .strip_prefix("invalid type: integer `")
        .and_then(|rest| rest.split_once("` as i128"))
        .map_or_else(
            || message.to_owned(),
            |(number, _)| {
                format!(
                    "{number} is too large: no number in the configuration is beyond {}",
                    i64::MAX
                )
            },
        )
}

/// An integer key within `range`, or an error at its place:
/// `{what} {n} is outside {min}–{max}{unit}`.
pub fn bounded<T>(
    n: &Spanned<i64>,
    range: RangeInclusive<T>,
    what: &str,
    unit: &str,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<T, ConfigError>
where
    T: TryFrom<i64> + PartialOrd + fmt::Display,
{
    T::try_from(*n.get_ref())
        .ok()
        .filter(|value| range.contains(value))
        .ok_or_else(|| {
            at(
                n.span(),
                format!(
                    "{what} {} is outside {}–{}{unit}",
                    n.get_ref(),
                    range.start(),
                    range.end()
                ),
            )
        })
}

/// A duration key (`500ms`, `2s`, `5m`) within `min..=max`, or an error at its place.
pub fn duration(
    text: &Spanned<String>,
    min: Duration,
    max: Duration,
    what: &str,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<Duration, ConfigError> {
    let d = humantime::parse_duration(text.get_ref().trim()).map_err(|e| {
        at(
            text.span(),
            format!(
                "{what} {:?} is not a duration ({e}); write e.g. 500ms, 2s or 5m",
                text.get_ref()
            ),
        )
    })?;
    if d < min || d > max {
        return Err(at(
            text.span(),
            format!(
                "{what} {} is out of range: {} to {}",
                humantime::format_duration(d),
                humantime::format_duration(min),
                humantime::format_duration(max)
            ),
        ));
    }
    Ok(d)
}

/// An error at a byte range of the text.
pub fn locate(text: &str, path: &Path, span: Range<usize>, message: String) -> ConfigError {
    let start = span.start.min(text.len());
    let before = text.get(..start).unwrap_or("");
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let column = text
        .get(line_start..start)
        .map_or(1, |s| s.chars().count() + 1);
    let source_line = hide_secret(
        text.get(line_start..)
            .and_then(|rest| rest.lines().next())
            .unwrap_or(""),
    );
    ConfigError::Invalid {
        path: path.to_owned(),
        line,
        column,
        message,
        source_line,
    }
}

/// The line as shown under an error, with the value of a secret (`token = …`,
/// `password = …`) hidden: error messages end up in logs and support tickets.
pub(crate) fn hide_secret(line: &str) -> String {
    let Some((key, _)) = line.split_once('=') else {
        return line.to_owned();
    };
    let name = key.trim().trim_matches(['"', '\'']).to_ascii_lowercase();
    if ["token", "password", "secret"]
        .iter()
        .any(|word| name.contains(word))
    {
        format!("{key}= \"(hidden)\"")
    } else if let Some((key, value)) = line.split_once('=') {
        // A URL's user name and password (`broker = "mqtt://user:pw@host"`).
        format!("{key}={}", hide_userinfo(value))
    } else {
        line.to_owned()
    }
}

/// A table of the configuration handed to the plug-in that owns it: an interface's
/// `[mqtt]`, or the keys of a `[[line.device]]` that only its device kind knows. It reads
/// into the plug-in's own serde type with every position kept, so its errors name the
/// file, line and column as the cell's own do.
#[derive(Debug, Clone)]
pub struct Table<'a> {
    text: &'a str,
    path: &'a Path,
    value: Spanned<DeValue<'a>>,
}

impl<'a> Table<'a> {
    /// `value`, a part of `text` (the file at `path`).
    pub fn new(text: &'a str, path: &'a Path, value: Spanned<DeValue<'a>>) -> Self {
        Self { text, path, value }
    }

    /// The keys of a `[[line.device]]`, for its kind: `table` with only `keys`, at the
    /// device's place in the file.
    pub(crate) fn keys_of(
        text: &'a str,
        path: &'a Path,
        span: Range<usize>,
        table: DeTable<'a>,
    ) -> Self {
        Self::new(text, path, Spanned::new(span, DeValue::Table(table)))
    }

    /// Reads the table into `T` (a serde type that refuses unknown fields, with
    /// `Spanned` fields where a later check needs to point at a value).
    pub fn read<T: DeserializeOwned>(&self) -> Result<T, ConfigError> {
        T::deserialize(toml::de::ValueDeserializer::from(self.value.clone())).map_err(|e| {
            self.at(
                e.span().unwrap_or_else(|| self.value.span()),
                plain_toml_message(e.message()),
            )
        })
    }

    /// An error at `span` of the file.
    pub fn at(&self, span: Range<usize>, message: String) -> ConfigError {
        locate(self.text, self.path, span, message)
    }

    /// The file the table is in (files it names are relative to its directory).
    pub fn path(&self) -> &Path {
        self.path
    }
}

/// What a plug-in read from its table, kept in the checked configuration until the
/// plug-in takes it back by its type ([`Settings::get`]). Empty for a device kind without
/// keys of its own.
#[derive(Clone, Default)]
pub struct Settings(Option<Arc<dyn Setting>>);

/// A value [`Settings`] can hold: any plain configuration type.
trait Setting: Any + fmt::Debug + Send + Sync {
    fn as_any(&self) -> &dyn Any;
    fn same(&self, other: &dyn Setting) -> bool;
}

impl<T: Any + fmt::Debug + PartialEq + Send + Sync> Setting for T {
    fn as_any(&self) -> &dyn Any {
        self
    }

    fn same(&self, other: &dyn Setting) -> bool {
        other.as_any().downcast_ref::<T>() == Some(self)
    }
}

impl Settings {
    /// Holds `value`.
    pub fn new<T: Any + fmt::Debug + PartialEq + Send + Sync>(value: T) -> Self {
        Self(Some(Arc::new(value)))
    }

    /// The value, if it is a `T`.
    pub fn get<T: Any>(&self) -> Option<&T> {
        self.0.as_deref().and_then(|s| s.as_any().downcast_ref())
    }
}

impl PartialEq for Settings {
    fn eq(&self, other: &Self) -> bool {
        match (&self.0, &other.0) {
            (None, None) => true,
            (Some(a), Some(b)) => Arc::ptr_eq(a, b) || a.same(b.as_ref()),
            _ => false,
        }
    }
}

impl fmt::Debug for Settings {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.0 {
            Some(value) => value.fmt(f),
            None => f.write_str("(none)"),
        }
    }
}

/// What plug-ins keep between the devices of one file while it is read (a register list
/// read once for the thousand meters that name it), one value of each type.
#[derive(Default)]
pub struct Scratch(HashMap<std::any::TypeId, Box<dyn Any>>);

impl Scratch {
    /// The `T` of this reading, made at its first use.
    pub fn get<T: Any + Default>(&mut self) -> &mut T {
        self.0
            .entry(std::any::TypeId::of::<T>())
            .or_insert_with(|| Box::new(T::default()))
            .downcast_mut()
            .expect("a scratch value is stored under its own type")
    }
}

impl fmt::Debug for Scratch {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Scratch({} values)", self.0.len())
    }
}
