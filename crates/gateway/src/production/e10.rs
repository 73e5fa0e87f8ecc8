//! The SEMI E10 scale of equipment states, numbered as IPC-CFX numbers them
//! (`ResourceState`): the thousands are the E10 category, the hundreds the E58 sub-state.

use std::fmt;

use serde::Serialize;

/// An E10 category: where a moment of the equipment's time goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Category {
    /// Doing its work (1000).
    Productive,
    /// Able to work, waiting (2000): no operator, no product, blocked, starved.
    Standby,
    /// Running experiments or tests (3000).
    Engineering,
    /// Down on purpose (4000): maintenance, setup, change of consumables by plan.
    ScheduledDown,
    /// Down by failure (5000): repair, out of consumables, out-of-spec input.
    UnscheduledDown,
    /// Not planned to work (6000): outside the shifts, shut down.
    NonScheduled,
    /// No data: the device did not answer or the gateway was not running (code 0, not on
    /// the E10 scale).
    Unknown,
}

impl Category {
    /// Every category, in E10 order, then unknown.
    pub const ALL: [Category; 7] = [
        Category::Productive,
        Category::Standby,
        Category::Engineering,
        Category::ScheduledDown,
        Category::UnscheduledDown,
        Category::NonScheduled,
        Category::Unknown,
    ];

    /// The name in the API and the metrics (`unscheduled_down`).
    pub fn as_str(self) -> &'static str {
        match self {
            Category::Productive => "productive",
            Category::Standby => "standby",
            Category::Engineering => "engineering",
            Category::ScheduledDown => "scheduled_down",
            Category::UnscheduledDown => "unscheduled_down",
            Category::NonScheduled => "non_scheduled",
            Category::Unknown => "unknown",
        }
    }

    /// The category's own code (its thousands), 0 for unknown.
    pub fn code(self) -> StateCode {
        StateCode(match self {
            Category::Productive => 1000,
            Category::Standby => 2000,
            Category::Engineering => 3000,
            Category::ScheduledDown => 4000,
            Category::UnscheduledDown => 5000,
            Category::NonScheduled => 6000,
            Category::Unknown => 0,
        })
    }

    /// Whether time in it is a stop of planned production (anything but productive and
    /// non-scheduled).
    pub fn is_stop(self) -> bool {
        !matches!(self, Category::Productive | Category::NonScheduled)
    }
}

impl fmt::Display for Category {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The E58 sub-states IPC-CFX numbers (`CFX/Structures/ResourceState.cs`), with the
/// categories' own codes.
const KNOWN: [(u16, &str); 42] = [
    (1000, "productive"),
    (1100, "regular work"),
    (1200, "work for third parties"),
    (1300, "rework"),
    (1400, "engineering runs"),
    (2000, "standby"),
    (2100, "no operator"),
    (2200, "no product"),
    (2201, "no product: blocked"),
    (2202, "no product: starved"),
    (2300, "no support tool"),
    (2400, "associated cluster module down"),
    (2500, "no host"),
    (3000, "engineering"),
    (3100, "process engineering"),
    (3200, "equipment engineering"),
    (4000, "scheduled down"),
    (4100, "maintenance delay"),
    (4200, "supplier delay"),
    (4300, "preventive maintenance"),
    (4400, "change of consumables"),
    (4500, "setup"),
    (4600, "production test"),
    (4700, "facilities related"),
    (5000, "unscheduled down"),
    (5100, "maintenance delay"),
    (5200, "supplier delay"),
    (5300, "repair"),
    (5400, "out-of-spec input"),
    (5500, "change of consumables"),
    (5600, "facilities related"),
    (6000, "non-scheduled"),
    (6100, "unworked shift"),
    (6200, "installation"),
    (6300, "modification"),
    (6400, "training"),
    (6500, "shutdown or start-up"),
    (0, "unknown"),
    // Codes kept by older CFX versions under other words; still valid on the scale.
    (2203, "no product: unbalanced line"),
    (3300, "software engineering"),
    (4800, "scheduled downtime for quality"),
    (5700, "unscheduled downtime for quality"),
];

/// A code on the IPC-CFX scale (1100 regular work … 6500 shutdown), or 0 for unknown:
/// only codes of the scale can be made.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(transparent)]
pub struct StateCode(u16);

impl StateCode {
    /// The code for no data.
    pub const UNKNOWN: StateCode = StateCode(0);

    /// The code `n`, if it is on the scale; the error names the nearest codes.
    pub fn new(n: i64) -> Result<Self, String> {
        if let Some((code, _)) = KNOWN.iter().find(|(code, _)| i64::from(*code) == n) {
            return Ok(StateCode(*code));
        }
        let bucket: Vec<String> = KNOWN
            .iter()
            .filter(|(code, _)| *code != 0 && i64::from(*code / 1000) == n / 1000)
            .map(|(code, words)| format!("{code} {words}"))
            .collect();
        Err(if bucket.is_empty() {
            format!(
                "{n} is not a SEMI E10 state code: 1000 productive, 2000 standby, 3000 engineering, 4000 scheduled down, 5000 unscheduled down, 6000 non-scheduled, or one of their sub-states (1100, 2200, 5500…)"
            )
        } else {
            format!(
                "{n} is not a SEMI E10 state code; the codes of its thousand are {}",
                bucket.join(", ")
            )
        })
    }

    /// The code a stored number holds: unknown when it is off the scale.
    pub fn of_number(n: f64) -> StateCode {
        StateCode::new(n as i64).unwrap_or(StateCode::UNKNOWN)
    }

    /// The number.
    pub fn get(self) -> u16 {
        self.0
    }

    /// Its E10 category: the thousands.
    pub fn category(self) -> Category {
        match self.0 / 1000 {
            1 => Category::Productive,
            2 => Category::Standby,
            3 => Category::Engineering,
            4 => Category::ScheduledDown,
            5 => Category::UnscheduledDown,
            6 => Category::NonScheduled,
            _ => Category::Unknown,
        }
    }

    /// Its words (`change of consumables`).
    pub fn words(self) -> &'static str {
        KNOWN
            .iter()
            .find(|(code, _)| *code == self.0)
            .map_or("unknown", |(_, words)| words)
    }
}

impl fmt::Display for StateCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_code_belongs_to_the_category_of_its_thousands() {
        assert_eq!(
            StateCode::new(5500).unwrap().category(),
            Category::UnscheduledDown
        );
        assert_eq!(StateCode::new(2202).unwrap().category(), Category::Standby);
        assert_eq!(
            StateCode::new(1100).unwrap().category(),
            Category::Productive
        );
        assert_eq!(StateCode::UNKNOWN.category(), Category::Unknown);
    }

    #[test]
    fn every_category_code_is_on_the_scale_and_names_its_category() {
        for category in Category::ALL {
            let code = StateCode::new(i64::from(category.code().get())).unwrap();
            assert_eq!(code.category(), category);
        }
    }

    #[test]
    fn a_code_off_the_scale_is_refused_with_the_codes_of_its_thousand() {
        let error = StateCode::new(5550).unwrap_err();
        assert!(error.contains("5500 change of consumables"), "{error}");
        let error = StateCode::new(7000).unwrap_err();
        assert!(error.contains("1000 productive"), "{error}");
    }
}
