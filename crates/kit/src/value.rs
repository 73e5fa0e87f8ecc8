//! A point's value and how far it can be trusted: what the gateway reads, stores and
//! serves, and what the historian stores and serves again.

use std::fmt;

use serde::{Deserialize, Serialize};

/// A point's value: a number (enumerations are numbers with labels) or text.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Value {
    /// A number.
    Number(f64),
    /// Text (a model name, a program name).
    Text(String),
}

impl Value {
    /// The number, if it is one.
    pub fn as_number(&self) -> Option<f64> {
        match self {
            Value::Number(n) => Some(*n),
            Value::Text(_) => None,
        }
    }
}

impl fmt::Display for Value {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Value::Number(n) => write!(f, "{n}"),
            Value::Text(t) => f.write_str(t),
        }
    }
}

/// How far a point's current value (or a stored sample) can be trusted. Sparkplug carries
/// it as the `Quality` property (192 / 500 / 0: `sparkplug::metric::Quality`, the wire's
/// enum, which the historian maps to this one where it ingests).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Quality {
    /// Read at its last poll.
    Good,
    /// The last good value is older than its poll period allows (the line is slow or busy).
    Stale,
    /// The last read failed (the point carries the error), or the node or device died.
    Bad,
}

impl Quality {
    /// The number stored in the history (0 good, 1 stale, 2 bad): the gateway's SQLite
    /// column and the historian's `samples.quality`.
    pub fn code(self) -> i64 {
        match self {
            Quality::Good => 0,
            Quality::Stale => 1,
            Quality::Bad => 2,
        }
    }

    /// The quality for a stored number; unknown numbers read as bad (as the historian's
    /// view does).
    pub fn from_code(code: i64) -> Self {
        match code {
            0 => Quality::Good,
            1 => Quality::Stale,
            _ => Quality::Bad,
        }
    }

    /// The word the API and the historian's view `cellbus_samples` show (`good`, `stale`,
    /// `bad`).
    pub fn as_str(self) -> &'static str {
        match self {
            Quality::Good => "good",
            Quality::Stale => "stale",
            Quality::Bad => "bad",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_quality_survives_its_stored_code_and_unknown_codes_read_as_bad() {
        for q in [Quality::Good, Quality::Stale, Quality::Bad] {
            assert_eq!(Quality::from_code(q.code()), q);
            assert_eq!(serde_json::to_value(q).unwrap(), q.as_str());
        }
        assert_eq!(Quality::from_code(7), Quality::Bad);
        assert_eq!(Quality::from_code(-1), Quality::Bad);
    }

    #[test]
    fn values_serialise_as_plain_numbers_and_text() {
        assert_eq!(serde_json::to_string(&Value::Number(21.5)).unwrap(), "21.5");
        assert_eq!(
            serde_json::to_string(&Value::Text("P-7".into())).unwrap(),
            "\"P-7\""
        );
        assert_eq!(Value::Text("x".into()).as_number(), None);
    }
}
