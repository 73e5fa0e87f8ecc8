//! A device's machine state as points: what a driver reports after the poll of the group
//! that reads its state ([`StatePoints`]). The states, their codes and the points' names
//! are the core's ([`crate::production::states`]).

use std::sync::Arc;

use super::{DriverConfig, Reading};
use crate::point::{EnumState, PointDescription, PointId, PointKind, PointSpec, Value};
use crate::production::StateCode;
use crate::production::states::{CODE_POINT, REASON_POINT, STATE_POINT, StateDef, point_id};

/// A device's state points: the specs to list and the readings of a state.
#[derive(Debug, Clone)]
pub struct StatePoints {
    ids: [PointId; 3],
    /// The kind's states with the codes in force for this device, and the points'
    /// descriptions: shared by every device with the same ones (a thousand stations hold
    /// one copy).
    shared: Arc<Shared>,
}

/// What devices with the same states and codes share.
#[derive(Debug, PartialEq)]
struct Shared {
    table: Box<[(&'static str, StateCode)]>,
    descriptions: [Arc<PointDescription>; 3],
}

/// Every [`Shared`] made so far: a few per kind (one unless the config moves codes).
static SHARED: std::sync::Mutex<Vec<Arc<Shared>>> = std::sync::Mutex::new(Vec::new());

impl StatePoints {
    /// How many points a device with states gets.
    pub const COUNT: usize = 3;

    /// The state points of the device `config` describes, whose kind reports `states`,
    /// read by its poll group `group`.
    pub fn new(config: &DriverConfig, states: &[StateDef], group: &'static str) -> Self {
        let table: Box<[(&'static str, StateCode)]> = states
            .iter()
            .map(|s| {
                let code = config
                    .states
                    .get(s.name)
                    .copied()
                    .or_else(|| StateCode::new(i64::from(s.code)).ok())
                    .unwrap_or(StateCode::UNKNOWN);
                (s.name, code)
            })
            .collect();
        let mut codes: Vec<StateCode> = table.iter().map(|(_, c)| *c).collect();
        codes.sort();
        codes.dedup();
        let describe = |name: &'static str, kind: PointKind| {
            Arc::new(PointDescription {
                name: name.into(),
                unit: None,
                kind,
                group: group.into(),
                writable: None,
                alarm: None,
            })
        };
        let descriptions = [
            describe("Machine state", PointKind::Text),
            describe(
                "Machine state (E10)",
                PointKind::Enum {
                    states: codes
                        .iter()
                        .map(|c| EnumState {
                            value: i64::from(c.get()),
                            label: format!("{c} {}", c.words()).into(),
                        })
                        .collect(),
                },
            ),
            describe("Machine state reason", PointKind::Text),
        ];
        let made = Shared {
            table,
            descriptions,
        };
        let shared = {
            let mut all = SHARED
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            match all.iter().find(|s| ***s == made) {
                Some(found) => Arc::clone(found),
                None => {
                    let made = Arc::new(made);
                    all.push(Arc::clone(&made));
                    made
                }
            }
        };
        let id = |name| point_id(&config.id, name);
        Self {
            ids: [id(STATE_POINT), id(CODE_POINT), id(REASON_POINT)],
            shared,
        }
    }

    /// The three points' specs, to append to the driver's.
    pub fn specs(&self) -> Vec<PointSpec> {
        self.ids
            .iter()
            .zip(&self.shared.descriptions)
            .map(|(id, d)| PointSpec::new(id.clone(), Arc::clone(d)))
            .collect()
    }

    /// The readings of the state at `index` in the kind's list, with the device's reason.
    pub fn readings(&self, index: usize, reason: Option<String>) -> Vec<Reading> {
        let (name, code) = self
            .shared
            .table
            .get(index)
            .copied()
            .unwrap_or(("unknown", StateCode::UNKNOWN));
        let values = [
            Value::Text(name.to_owned()),
            Value::Number(f64::from(code.get())),
            Value::Text(reason.unwrap_or_default()),
        ];
        self.ids
            .iter()
            .zip(values)
            .map(|(id, value)| Reading {
                point: id.clone(),
                value: Ok(value),
            })
            .collect()
    }

    /// The ids of the three points: the state, its code, its reason.
    pub fn ids(&self) -> &[PointId; 3] {
        &self.ids
    }
}

/// The good number a poll read for point `name`, if it read one: what a driver judges
/// its state from.
pub fn number_in(readings: &[Reading], name: &str) -> Option<f64> {
    readings
        .iter()
        .find(|r| r.point.name() == name)
        .and_then(|r| r.value.as_ref().ok())
        .and_then(Value::as_number)
}
