//! One alarm's state by ISA-18.2 / IEC 62682, sans IO: the process condition (active or
//! not), the operator's acknowledgement, shelving with an expiry, out of service, and the
//! chattering measure. Every change says what an interface shows and the journal keeps.
//!
//! | state | condition | acknowledged | annunciated |
//! |---|---|---|---|
//! | normal | inactive | yes | no |
//! | unacknowledged | active | no | yes |
//! | acknowledged | active | yes | yes |
//! | returned unacknowledged | inactive | no | yes |
//! | shelved | either | kept | no, until unshelved or expired |
//! | out of service | either | kept | no |
//!
//! Transitions (ISA-18.2 figure 5): normal → unacknowledged on activation; unacknowledged
//! → acknowledged by the operator, → returned unacknowledged when the condition clears;
//! acknowledged → normal when it clears; returned unacknowledged → normal when
//! acknowledged, → unacknowledged when it activates again. A shelved or out-of-service
//! alarm follows its condition silently; when it comes back it shows as the condition
//! then is: active is unacknowledged (annunciated again), inactive is normal.

use std::time::Duration;

use serde::Serialize;

use crate::time::Timestamp;

/// The states of ISA-18.2's state diagram.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum State {
    /// Inactive and acknowledged.
    Normal,
    /// Active, not acknowledged.
    Unacknowledged,
    /// Active, acknowledged.
    Acknowledged,
    /// Back to normal before anyone acknowledged it.
    ReturnedUnacknowledged,
}

impl State {
    /// Its name in the API, the journal and the interfaces (`returned_unacknowledged`).
    pub fn as_str(self) -> &'static str {
        match self {
            State::Normal => "normal",
            State::Unacknowledged => "unacknowledged",
            State::Acknowledged => "acknowledged",
            State::ReturnedUnacknowledged => "returned_unacknowledged",
        }
    }

    /// Whether the condition is active.
    pub fn active(self) -> bool {
        matches!(self, State::Unacknowledged | State::Acknowledged)
    }

    /// Whether it waits for an acknowledgement.
    pub fn unacknowledged(self) -> bool {
        matches!(self, State::Unacknowledged | State::ReturnedUnacknowledged)
    }
}

/// Why an operator's action does not apply (an HTTP 409, a Bad status in OPC UA).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Refused {
    /// Acknowledging an alarm nobody needs to acknowledge.
    #[error("the alarm is already acknowledged (it is {0})")]
    NothingToAcknowledge(&'static str),
    /// Unshelving an alarm that is not shelved.
    #[error("the alarm is not shelved")]
    NotShelved,
    /// Shelving or acknowledging an alarm out of service, or taking it out again.
    #[error("the alarm is out of service; return it to service first")]
    OutOfService,
    /// Returning an alarm to service that is in service.
    #[error("the alarm is in service")]
    InService,
    /// A shelving that ends before it begins, or lasts longer than allowed.
    #[error("a shelving lasts from 1 s to {}; asked {}", humantime::format_duration(*max), humantime::format_duration(*asked))]
    ShelveDuration {
        /// What was asked.
        asked: Duration,
        /// The longest allowed.
        max: Duration,
    },
}

/// What changed, for the journal and the interfaces.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Change {
    /// The condition became active (annunciated unless shelved or out of service).
    Activated,
    /// The condition cleared.
    Cleared,
    /// The operator acknowledged it.
    Acknowledged,
    /// The operator shelved it.
    Shelved,
    /// Shelved on its own, for chattering.
    ShelvedForChattering,
    /// The operator unshelved it.
    Unshelved,
    /// Its shelving ran out.
    ShelveExpired,
    /// Taken out of service.
    RemovedFromService,
    /// Back in service.
    ReturnedToService,
}

impl Change {
    /// The name in the journal and the API (`activated`).
    pub fn as_str(self) -> &'static str {
        match self {
            Change::Activated => "activated",
            Change::Cleared => "cleared",
            Change::Acknowledged => "acknowledged",
            Change::Shelved => "shelved",
            Change::ShelvedForChattering => "shelved_for_chattering",
            Change::Unshelved => "unshelved",
            Change::ShelveExpired => "shelve_expired",
            Change::RemovedFromService => "removed_from_service",
            Change::ReturnedToService => "returned_to_service",
        }
    }
}

/// Chattering: more than `activations` in `window` (ISA-18.2's "chattering alarm"),
/// optionally shelved on its own for `shelve`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChatterRule {
    /// Activations allowed in the window.
    pub activations: u32,
    /// The window.
    pub window: Duration,
    /// Shelve it for this long when it chatters (`None`: count only).
    pub shelve: Option<Duration>,
}

/// The longest an operator may shelve an alarm.
pub const MAX_SHELVE: Duration = Duration::from_secs(7 * 24 * 3600);

/// One alarm's state and counts.
#[derive(Debug, Clone, PartialEq)]
pub struct Alarm {
    state: State,
    /// The condition as last seen (it goes on while shelved or out of service).
    active: bool,
    shelved_until: Option<Timestamp>,
    out_of_service: bool,
    /// When it first became active since it was last normal.
    pub first_active: Option<Timestamp>,
    /// When it last became active.
    pub last_active: Option<Timestamp>,
    /// Activations since the gateway started keeping it.
    pub count: u64,
    /// Times it was found chattering.
    pub chattered: u64,
    /// Recent activations, for the chatter rule.
    recent: Vec<Timestamp>,
    chatter: Option<ChatterRule>,
}

impl Alarm {
    /// A normal alarm, with its chatter rule if it has one.
    pub fn new(chatter: Option<ChatterRule>) -> Self {
        Self {
            state: State::Normal,
            active: false,
            shelved_until: None,
            out_of_service: false,
            first_active: None,
            last_active: None,
            count: 0,
            chattered: 0,
            recent: Vec::new(),
            chatter,
        }
    }

    /// Its ISA-18.2 state.
    pub fn state(&self) -> State {
        self.state
    }

    /// Until when it is shelved, if it is.
    pub fn shelved_until(&self) -> Option<Timestamp> {
        self.shelved_until
    }

    /// Whether it is out of service.
    pub fn out_of_service(&self) -> bool {
        self.out_of_service
    }

    /// Whether its condition is active (also while shelved or out of service).
    pub fn active(&self) -> bool {
        self.active
    }

    /// Puts it back as it was saved (after a restart). The chatter rule's recent
    /// activations are not saved: its window starts again.
    pub fn restore(
        &mut self,
        state: State,
        active: bool,
        shelved_until: Option<Timestamp>,
        out_of_service: bool,
        (first_active, last_active): (Option<Timestamp>, Option<Timestamp>),
        (count, chattered): (u64, u64),
    ) {
        self.state = state;
        self.active = active;
        self.shelved_until = shelved_until;
        self.out_of_service = out_of_service;
        self.first_active = first_active;
        self.last_active = last_active;
        self.count = count;
        self.chattered = chattered;
    }

    /// Whether an operator is shown it: not normal, not shelved, in service.
    pub fn annunciated(&self) -> bool {
        self.state != State::Normal && self.shelved_until.is_none() && !self.out_of_service
    }

    /// Whether it is suppressed from view (shelved or out of service).
    fn silenced(&self) -> bool {
        self.shelved_until.is_some() || self.out_of_service
    }

    /// The condition is `active` at `now`: what changed, if anything.
    pub fn condition(&mut self, active: bool, now: Timestamp) -> Vec<Change> {
        if active == self.active {
            return Vec::new();
        }
        self.active = active;
        let mut changes = Vec::new();
        if active {
            self.count += 1;
            self.last_active = Some(now);
            if self.state == State::Normal {
                self.first_active = Some(now);
            }
            changes.push(Change::Activated);
            if !self.silenced() {
                self.state = State::Unacknowledged;
            }
            if self.chatters(now) {
                self.chattered += 1;
                if let Some(shelve) = self.chatter.and_then(|c| c.shelve)
                    && !self.silenced()
                {
                    self.shelved_until = Some(now.plus(shelve));
                    changes.push(Change::ShelvedForChattering);
                }
            }
        } else {
            changes.push(Change::Cleared);
            if !self.silenced() {
                self.state = match self.state {
                    State::Acknowledged | State::Normal => State::Normal,
                    State::Unacknowledged | State::ReturnedUnacknowledged => {
                        State::ReturnedUnacknowledged
                    }
                };
            }
        }
        changes
    }

    /// Whether this activation makes more than the rule allows in its window.
    fn chatters(&mut self, now: Timestamp) -> bool {
        let Some(rule) = self.chatter else {
            return false;
        };
        let since = now.minus(rule.window);
        self.recent.retain(|t| *t > since);
        self.recent.push(now);
        self.recent.len() > rule.activations as usize
    }

    /// The operator acknowledges it.
    pub fn acknowledge(&mut self) -> Result<Change, Refused> {
        if self.out_of_service {
            return Err(Refused::OutOfService);
        }
        self.state = match self.state {
            State::Unacknowledged => State::Acknowledged,
            State::ReturnedUnacknowledged => State::Normal,
            State::Acknowledged => {
                return Err(Refused::NothingToAcknowledge("active, acknowledged"));
            }
            State::Normal => return Err(Refused::NothingToAcknowledge("normal")),
        };
        Ok(Change::Acknowledged)
    }

    /// The operator shelves it for `duration` from `now`.
    pub fn shelve(&mut self, duration: Duration, now: Timestamp) -> Result<Change, Refused> {
        if self.out_of_service {
            return Err(Refused::OutOfService);
        }
        if duration < Duration::from_secs(1) || duration > MAX_SHELVE {
            return Err(Refused::ShelveDuration {
                asked: duration,
                max: MAX_SHELVE,
            });
        }
        self.shelved_until = Some(now.plus(duration));
        Ok(Change::Shelved)
    }

    /// The operator unshelves it: it shows as its condition now is.
    pub fn unshelve(&mut self) -> Result<Change, Refused> {
        if self.shelved_until.take().is_none() {
            return Err(Refused::NotShelved);
        }
        self.resume();
        Ok(Change::Unshelved)
    }

    /// Takes it out of service, or back (`false`).
    pub fn set_out_of_service(&mut self, out: bool) -> Option<Change> {
        if out == self.out_of_service {
            return None;
        }
        self.out_of_service = out;
        if out {
            return Some(Change::RemovedFromService);
        }
        self.resume();
        Some(Change::ReturnedToService)
    }

    /// Time passes: a shelving that ran out ends.
    pub fn tick(&mut self, now: Timestamp) -> Option<Change> {
        let until = self.shelved_until?;
        if now < until {
            return None;
        }
        self.shelved_until = None;
        self.resume();
        Some(Change::ShelveExpired)
    }

    /// Back from shelving or out of service: active is annunciated again, unacknowledged;
    /// inactive is normal (unless it was waiting for an acknowledgement already).
    fn resume(&mut self) {
        if self.silenced() {
            return;
        }
        self.state = match (self.active, self.state) {
            (true, _) => State::Unacknowledged,
            (false, State::ReturnedUnacknowledged) => State::ReturnedUnacknowledged,
            (false, _) => State::Normal,
        };
    }
}

#[cfg(test)]
mod tests;
