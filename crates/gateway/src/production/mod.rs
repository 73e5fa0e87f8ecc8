//! The cell's production: machine states on the SEMI E10 scale, shifts, and OEE.
//!
//! - [`e10`]: the categories and the IPC-CFX codes.
//! - [`states`]: a device's state points (`machine_state`, `machine_state_code`,
//!   `machine_state_reason`), which drivers report through `driver::machine::StatePoints`, and
//!   the intervals the history makes of them.
//! - [`shift`]: the `[[shift]]` tables and `time_zone`: planned production time.
//! - [`oee`]: the breakdown of a range by state, its stops and its OEE, sans IO.
//! - [`report`]: a range's report from the history (`/api/production`, `/api/states`).
//! - [`keeper`]: the current shift's OEE as points of each producing device, the time
//!   per category for the metrics, and the gap a stopped gateway leaves.
//!
//! A device kind says which states it reports ([`crate::driver::DeviceKind::machine_states`])
//! and, if it counts what it makes, which of its points are the counters
//! ([`crate::driver::DeviceKind::production`]); the core names no kind.

use std::collections::BTreeMap;
use std::time::Duration;

use std::sync::Arc;

use crate::point::{DeviceId, PointDescription, PointKind, PointSpec};

pub mod config;
pub mod e10;
pub mod keeper;
pub mod oee;
pub mod report;
pub mod shift;
pub mod states;

pub use e10::{Category, StateCode};
pub use shift::Shifts;
pub use states::StateDef;

/// The points of a device kind that count its production, by their names.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ProductionPoints {
    /// Boards (units) finished, a counter.
    pub boards: &'static str,
    /// The machine's own plan, if it has one.
    pub planned: Option<&'static str>,
    /// Pickups (attempts), a counter, for the placement yield.
    pub pickups: Option<&'static str>,
    /// Parts placed, a counter, for the placement yield.
    pub placed: Option<&'static str>,
    /// The selected program (text), for its ideal cycle.
    pub program: Option<&'static str>,
    /// The event that reports a unit's cycle time: its `event` field and the field with
    /// the seconds (`board_finished`, `board_time_s`).
    pub cycle_event: Option<(&'static str, &'static str)>,
}

/// A device's `[line.device.production]` table.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ProductionSettings {
    /// The ideal cycle of every program without its own.
    pub ideal_cycle: Option<Duration>,
    /// Ideal cycles by program.
    pub ideal_cycle_by_program: BTreeMap<String, Duration>,
    /// Stops shorter than this count as run time (a speed loss).
    pub micro_stop: Option<Duration>,
    /// A counter point (`aoi1.good_boards`) of good boards, for quality.
    pub good_boards: Option<crate::point::PointId>,
}

/// A producing device: its kind's counters and its settings.
#[derive(Debug, Clone, PartialEq)]
pub struct Producer {
    /// The kind's production points.
    pub points: ProductionPoints,
    /// The config's settings.
    pub settings: ProductionSettings,
}

/// What the cell knows of its production: its shifts, which devices report states, and
/// which produce.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Plan {
    /// The shifts.
    pub shifts: Shifts,
    /// Devices that report machine states.
    pub with_states: Vec<DeviceId>,
    /// Devices that count production.
    pub producers: BTreeMap<DeviceId, Producer>,
}

impl Plan {
    /// A plan of `shifts`, without devices yet.
    pub fn new(shifts: Shifts) -> Self {
        Plan {
            shifts,
            ..Plan::default()
        }
    }

    /// Adds `device`, whose kind reports `states` and counts `production` with the
    /// config's `settings`.
    pub fn add(
        &mut self,
        device: &DeviceId,
        states: &[StateDef],
        production: Option<&ProductionPoints>,
        settings: Option<ProductionSettings>,
    ) {
        if !states.is_empty() {
            self.with_states.push(device.clone());
        }
        if let Some(points) = production {
            self.producers.insert(
                device.clone(),
                Producer {
                    points: *points,
                    settings: settings.unwrap_or_default(),
                },
            );
        }
    }

    /// Whether `device` reports machine states.
    pub fn has_states(&self, device: &str) -> bool {
        self.with_states.iter().any(|d| d.as_str() == device)
    }
}

/// The OEE points a producing device gets (the current shift so far), with their words.
pub const OEE_POINTS: [(&str, &str); 4] = [
    ("oee", "OEE (this shift)"),
    ("oee_availability", "Availability (this shift)"),
    ("oee_performance", "Performance (this shift)"),
    ("oee_quality", "Quality (this shift)"),
];

/// Whether a device's point `name` is one of its production points (its machine state,
/// its OEE): interfaces that group points put them together (OPC UA's `Production`
/// folder).
pub fn is_production_point(name: &str) -> bool {
    [
        states::STATE_POINT,
        states::CODE_POINT,
        states::REASON_POINT,
    ]
    .contains(&name)
        || OEE_POINTS.iter().any(|(point, _)| *point == name)
}

/// The poll group of the OEE points: not polled, kept by the [`keeper`].
pub const OEE_GROUP: &str = "oee";

/// How often the keeper works out the current shift's OEE.
pub const OEE_PERIOD: Duration = Duration::from_secs(10);

/// The OEE points' specs for `device` (ratios 0–1, kept by the keeper).
pub fn oee_specs(device: &DeviceId) -> Vec<PointSpec> {
    OEE_POINTS
        .iter()
        .map(|(name, words)| {
            PointSpec::new(
                states::point_id(device, name),
                Arc::new(PointDescription {
                    name: (*words).into(),
                    unit: None,
                    kind: PointKind::Numeric,
                    group: OEE_GROUP.into(),
                    writable: None,
                    alarm: None,
                }),
            )
        })
        .collect()
}
