//! What changed in a CROSS between two readings: the load moved (a transfer, when it went
//! to the other source), alarms raised and cleared, states on and off.
//!
//! Measures always move a little and are never changes. `cellbus cross watch` prints
//! every [`Change`]; the gateway's CROSS driver records a change of what feeds the load as
//! an event. Both take the changes from [`Discrete::changes_since`]:
//!
//! ```
//! use std::time::Instant;
//! use jbus::cross::{Discrete, Source};
//! use jbus::cross::device::CrossTwin;
//! use jbus::rtu::UnitId;
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let mut twin = CrossTwin::new(UnitId::jbus(1)?, 7);
//! let before = Discrete::of(&twin.reading(Instant::now()).internal);
//! twin.fail_source(Source::S1);
//! let after = Discrete::of(&twin.reading(Instant::now()).internal);
//! let changes = after.changes_since(&before);
//! let transfer = changes.iter().find_map(|c| c.transfer()).ok_or("a transfer")?;
//! assert_eq!((transfer.from, transfer.to), (Source::S1, Source::S2));
//! # Ok(())
//! # }
//! ```

use std::collections::BTreeSet;
use std::fmt;

use super::bits::InternalState;
use super::state::{Feed, Source};

/// What feeds the load, and whether that is the reserve line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Load {
    /// What feeds it.
    pub feed: Feed,
    /// Whether it is on the reserve (non-preferred) line.
    pub reserve_line: bool,
}

/// `supplied by source 1 (S1) through static switch S1-SW (reserve line)`.
impl fmt::Display for Load {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.feed)?;
        if self.reserve_line {
            f.write_str(" (reserve line)")?;
        }
        Ok(())
    }
}

/// The load moved from one source to the other.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Transfer {
    /// The source that fed it.
    pub from: Source,
    /// The source that feeds it now.
    pub to: Source,
}

/// One change between two readings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Change {
    /// What feeds the load changed, or only whether it is the reserve line.
    Load {
        /// Before.
        was: Load,
        /// Now.
        now: Load,
    },
    /// An alarm bit came on.
    AlarmRaised(&'static str),
    /// An alarm bit went off.
    AlarmCleared(&'static str),
    /// A state bit (not an alarm) came on.
    StateOn(&'static str),
    /// A state bit went off.
    StateOff(&'static str),
}

impl Change {
    /// The transfer, when the load went from one source to the other (through a static
    /// switch or a bypass).
    pub fn transfer(&self) -> Option<Transfer> {
        let Change::Load { was, now } = self else {
            return None;
        };
        match (was.feed.source(), now.feed.source()) {
            (Some(from), Some(to)) if from != to => Some(Transfer { from, to }),
            _ => None,
        }
    }
}

/// `load …`, `alarm raised: …`, `alarm cleared: …`, `now: …`, `no longer: …`.
impl fmt::Display for Change {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Change::Load { now, .. } => write!(f, "load {now}"),
            Change::AlarmRaised(alarm) => write!(f, "alarm raised: {alarm}"),
            Change::AlarmCleared(alarm) => write!(f, "alarm cleared: {alarm}"),
            Change::StateOn(state) => write!(f, "now: {state}"),
            Change::StateOff(state) => write!(f, "no longer: {state}"),
        }
    }
}

/// The parts of a CROSS's state whose changes are reported: what feeds the load, the
/// active alarms and states (in words, sorted). Taken from the internal-state area alone.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Discrete {
    load: Load,
    alarms: BTreeSet<&'static str>,
    states: BTreeSet<&'static str>,
}

impl Discrete {
    /// The discrete parts of the internal-state area.
    pub fn of(internal: &InternalState) -> Self {
        Self {
            load: Load {
                feed: internal.feed(),
                reserve_line: internal.on_reserve_line(),
            },
            alarms: internal.alarms().into_iter().collect(),
            states: internal.conditions().into_iter().collect(),
        }
    }

    /// What feeds the load.
    pub fn load(&self) -> Load {
        self.load
    }

    /// The active alarms, sorted.
    pub fn alarms(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.alarms.iter().copied()
    }

    /// What changed from `before` to `self`: the load first, then alarms raised and
    /// cleared, then states on and off; empty when nothing did.
    pub fn changes_since(&self, before: &Self) -> Vec<Change> {
        let mut out = Vec::new();
        if self.load != before.load {
            out.push(Change::Load {
                was: before.load,
                now: self.load,
            });
        }
        came_and_went(
            &mut out,
            (&before.alarms, &self.alarms),
            Change::AlarmRaised,
            Change::AlarmCleared,
        );
        came_and_went(
            &mut out,
            (&before.states, &self.states),
            Change::StateOn,
            Change::StateOff,
        );
        out
    }
}

/// Appends what is in `now` and was not in `was` (as `came`), then what was and is no
/// more (as `went`), each in sorted order.
fn came_and_went(
    out: &mut Vec<Change>,
    (was, now): (&BTreeSet<&'static str>, &BTreeSet<&'static str>),
    came: fn(&'static str) -> Change,
    went: fn(&'static str) -> Change,
) {
    out.extend(now.difference(was).map(|&s| came(s)));
    out.extend(was.difference(now).map(|&s| went(s)));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cross::device::CrossTwin;
    use crate::rtu::UnitId;

    fn twin() -> CrossTwin {
        CrossTwin::new(UnitId::jbus(1).expect("unit 1"), 7)
    }

    fn discrete(twin: &mut CrossTwin) -> Discrete {
        Discrete::of(&twin.reading(std::time::Instant::now()).internal)
    }

    #[test]
    fn losing_source_1_is_a_transfer_to_source_2_named_in_words() {
        let mut twin = twin();
        let before = discrete(&mut twin);
        twin.fail_source(Source::S1);
        let changes = discrete(&mut twin).changes_since(&before);
        let first = changes.first().expect("the load moved");
        assert_eq!(
            first.transfer(),
            Some(Transfer {
                from: Source::S1,
                to: Source::S2
            })
        );
        assert_eq!(
            first.to_string(),
            "load supplied by source 2 (S2) through static switch S2-SW (reserve line)"
        );
        assert!(
            changes.contains(&Change::AlarmRaised("S1 failure")),
            "{changes:?}"
        );
        assert!(changes[1..].iter().all(|c| c.transfer().is_none()));
    }

    #[test]
    fn nothing_changed_is_no_change() {
        let mut twin = twin();
        let now = discrete(&mut twin);
        assert!(now.changes_since(&now.clone()).is_empty());
    }

    #[test]
    fn changes_are_the_load_then_alarms_then_states_in_words() {
        let mut twin = twin();
        let healthy = discrete(&mut twin);
        twin.fail_source(Source::S1);
        let failed = discrete(&mut twin);
        let back: Vec<String> = healthy
            .changes_since(&failed)
            .iter()
            .map(ToString::to_string)
            .collect();
        assert_eq!(
            back.first().map(String::as_str),
            Some("load supplied by source 1 (S1) through static switch S1-SW")
        );
        assert!(
            back.contains(&"alarm cleared: S1 failure".to_owned()),
            "{back:?}"
        );
        let kinds: Vec<u8> = healthy
            .changes_since(&failed)
            .iter()
            .map(|c| match c {
                Change::Load { .. } => 0,
                Change::AlarmRaised(_) | Change::AlarmCleared(_) => 1,
                Change::StateOn(_) | Change::StateOff(_) => 2,
            })
            .collect();
        assert!(kinds.is_sorted(), "{kinds:?}");
    }

    #[test]
    fn a_move_to_the_bypass_of_the_same_source_is_not_a_transfer() {
        let was = Load {
            feed: Feed::StaticSwitch(Source::S1),
            reserve_line: false,
        };
        let now = Load {
            feed: Feed::Bypass(Source::S1),
            reserve_line: false,
        };
        assert_eq!(Change::Load { was, now }.transfer(), None);
        let gone = Load {
            feed: Feed::NotSupplied,
            reserve_line: false,
        };
        assert_eq!(Change::Load { was, now: gone }.transfer(), None);
    }
}
