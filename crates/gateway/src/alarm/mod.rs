//! Alarms an operator works with, by ISA-18.2: each alarm's state ([`state`]), the limit
//! alarms on numeric points ([`limit`]) the config's `[[alarm]]` tables set ([`config`]),
//! and the task that runs them on the change stream ([`keeper`]).

pub mod book;
pub mod config;
pub mod keeper;
pub mod limit;
pub mod state;

use serde::Serialize;

/// An alarm's priority, 1 (low) to 4 (urgent).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Priority {
    /// 1.
    Low,
    /// 2.
    Medium,
    /// 3.
    High,
    /// 4.
    Urgent,
}

impl Priority {
    /// Every priority, lowest first.
    pub const ALL: [Priority; 4] = [
        Priority::Low,
        Priority::Medium,
        Priority::High,
        Priority::Urgent,
    ];

    /// Its name (`high`).
    pub fn as_str(self) -> &'static str {
        match self {
            Priority::Low => "low",
            Priority::Medium => "medium",
            Priority::High => "high",
            Priority::Urgent => "urgent",
        }
    }

    /// Its number, 1 to 4.
    pub fn number(self) -> u8 {
        self as u8 + 1
    }

    /// A priority as the config writes it: a name, or 1 to 4.
    pub fn parse(text: &str) -> Option<Priority> {
        Priority::ALL
            .into_iter()
            .find(|p| p.as_str() == text || p.number().to_string() == text)
    }
}
