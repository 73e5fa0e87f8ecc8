//! The CROSS's quantities as named points: name, title, unit, and how each is taken from
//! its area ([`Measures`] or [`Ratings`]).
//!
//! `cellbus cross status --json` shows them under their names (one value, or one per
//! phase); the gateway's CROSS driver makes one point of each value (`s1_voltage_u`).
//! Units come from the quantity types (`Volts::UNIT`), so a value and its unit cannot
//! disagree.

use std::fmt;

use super::measure::{
    Amperes, Celsius, Degrees, Hertz, KiloVoltAmperes, Measures, Phases, Ratings, Volts,
    WholeAmperes,
};

/// One of the three phases.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Phase {
    /// Phase U.
    U,
    /// Phase V.
    V,
    /// Phase W.
    W,
}

impl Phase {
    /// U, V, W.
    pub const ALL: [Phase; 3] = [Phase::U, Phase::V, Phase::W];

    /// `u`, `v` or `w`, for names and JSON keys.
    pub const fn key(self) -> &'static str {
        match self {
            Phase::U => "u",
            Phase::V => "v",
            Phase::W => "w",
        }
    }

    /// This phase's value of `phases`.
    pub fn of<T: Copy>(self, phases: Phases<T>) -> T {
        match self {
            Phase::U => phases.u,
            Phase::V => phases.v,
            Phase::W => phases.w,
        }
    }
}

/// `U`, `V` or `W`.
impl fmt::Display for Phase {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Phase::U => "U",
            Phase::V => "V",
            Phase::W => "W",
        })
    }
}

/// What a quantity holds, in its unit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Amount {
    /// One value.
    One(f64),
    /// One value per phase.
    Phases(Phases<f64>),
    /// A whole number without a unit (the protocol revision).
    Count(u16),
}

impl Amount {
    /// The value of `phase` (`None`: the one value); `None` when there is no such value.
    pub fn get(self, phase: Option<Phase>) -> Option<f64> {
        match (self, phase) {
            (Amount::One(value), None) => Some(value),
            (Amount::Count(count), None) => Some(f64::from(count)),
            (Amount::Phases(phases), Some(phase)) => Some(phase.of(phases)),
            _ => None,
        }
    }

    /// Every value: `(None, value)` for one value, `(Some(phase), value)` for each phase.
    pub fn values(self) -> Vec<(Option<Phase>, f64)> {
        match self {
            Amount::One(value) => vec![(None, value)],
            Amount::Count(count) => vec![(None, f64::from(count))],
            Amount::Phases(phases) => Phase::ALL
                .iter()
                .map(|&phase| (Some(phase), phase.of(phases)))
                .collect(),
        }
    }
}

/// One quantity of an area `A`.
#[derive(Debug, Clone, Copy)]
pub struct Quantity<A> {
    /// Its name, in `snake_case` (`s1_voltage`).
    pub name: &'static str,
    /// What it is, for a person (`S1 voltage`).
    pub title: &'static str,
    /// Its unit; `None` for a plain number.
    pub unit: Option<&'static str>,
    /// Takes it from the decoded area.
    pub read: fn(&A) -> Amount,
}

/// The measures area (0x46–0x59), in address order.
pub const MEASURES: &[Quantity<Measures>] = &[
    Quantity {
        name: "s1_voltage",
        title: "S1 voltage",
        unit: Some(Volts::UNIT),
        read: |m| volts(m.s1_voltage),
    },
    Quantity {
        name: "s1_frequency",
        title: "S1 frequency",
        unit: Some(Hertz::UNIT),
        read: |m| Amount::One(m.s1_frequency.value()),
    },
    Quantity {
        name: "s2_voltage",
        title: "S2 voltage",
        unit: Some(Volts::UNIT),
        read: |m| volts(m.s2_voltage),
    },
    Quantity {
        name: "s2_frequency",
        title: "S2 frequency",
        unit: Some(Hertz::UNIT),
        read: |m| Amount::One(m.s2_frequency.value()),
    },
    Quantity {
        name: "output_voltage",
        title: "Output voltage",
        unit: Some(Volts::UNIT),
        read: |m| volts(m.output_voltage),
    },
    Quantity {
        name: "output_current",
        title: "Output current",
        unit: Some(Amperes::UNIT),
        read: |m| Amount::Phases(m.output_current.map(Amperes::value)),
    },
    Quantity {
        name: "neutral_current",
        title: "Neutral current",
        unit: Some(Amperes::UNIT),
        read: |m| Amount::One(m.neutral_current.value()),
    },
    Quantity {
        name: "neutral_voltage",
        title: "Neutral voltage",
        unit: Some(Volts::UNIT),
        read: |m| Amount::One(m.neutral_voltage.value()),
    },
    Quantity {
        name: "output_frequency",
        title: "Output frequency",
        unit: Some(Hertz::UNIT),
        read: |m| Amount::One(m.output_frequency.value()),
    },
    Quantity {
        name: "load_power",
        title: "Load power",
        unit: Some(KiloVoltAmperes::UNIT),
        read: |m| Amount::One(m.load_power.value()),
    },
    Quantity {
        name: "phase_error",
        title: "Phase error between the sources",
        unit: Some(Degrees::UNIT),
        read: |m| Amount::One(m.phase_error.value()),
    },
    Quantity {
        name: "inlet_air",
        title: "Inlet air temperature",
        unit: Some(Celsius::UNIT),
        read: |m| Amount::One(m.inlet_air.value()),
    },
];

/// The ratings area (0x1E–0x2E), in address order.
pub const RATINGS: &[Quantity<Ratings>] = &[
    Quantity {
        name: "rated_current",
        title: "Rated current",
        unit: Some(Amperes::UNIT),
        read: |r| Amount::One(r.rated_current.value()),
    },
    Quantity {
        name: "s1_voltage_full_scale",
        title: "S1 voltage full scale",
        unit: Some(Volts::UNIT),
        read: |r| volts(r.s1_voltage_full_scale),
    },
    Quantity {
        name: "s2_voltage_full_scale",
        title: "S2 voltage full scale",
        unit: Some(Volts::UNIT),
        read: |r| volts(r.s2_voltage_full_scale),
    },
    Quantity {
        name: "output_voltage_full_scale",
        title: "Output voltage full scale",
        unit: Some(Volts::UNIT),
        read: |r| volts(r.output_voltage_full_scale),
    },
    Quantity {
        name: "output_current_full_scale",
        title: "Output current full scale",
        unit: Some(WholeAmperes::UNIT),
        read: |r| Amount::Phases(r.output_current_full_scale.map(WholeAmperes::value)),
    },
    Quantity {
        name: "neutral_current_full_scale",
        title: "Neutral current full scale",
        unit: Some(WholeAmperes::UNIT),
        read: |r| Amount::One(r.neutral_current_full_scale.value()),
    },
    Quantity {
        name: "neutral_voltage_full_scale",
        title: "Neutral voltage full scale",
        unit: Some(Volts::UNIT),
        read: |r| Amount::One(r.neutral_voltage_full_scale.value()),
    },
    Quantity {
        name: "inlet_air_full_scale",
        title: "Inlet air full scale",
        unit: Some(Celsius::UNIT),
        read: |r| Amount::One(r.inlet_air_full_scale.value()),
    },
    Quantity {
        name: "protocol_revision",
        title: "JBUS protocol revision",
        unit: None,
        read: |r| Amount::Count(r.protocol_revision),
    },
];

fn volts(phases: Phases<Volts>) -> Amount {
    Amount::Phases(phases.map(Volts::value))
}

#[cfg(test)]
mod tests {
    use std::collections::HashSet;

    use super::*;

    #[test]
    fn every_quantity_has_its_own_name() {
        let names: HashSet<&str> = MEASURES
            .iter()
            .map(|q| q.name)
            .chain(RATINGS.iter().map(|q| q.name))
            .collect();
        assert_eq!(names.len(), MEASURES.len() + RATINGS.len());
    }

    #[test]
    fn a_quantity_reads_its_register_scaled_in_its_unit() {
        let mut measures = Measures::from_words(&[0; Measures::LEN]);
        measures.s1_voltage.v = Volts::from_raw(2301);
        measures.s1_frequency = Hertz::from_raw(5002);
        let voltage = &MEASURES[0];
        assert_eq!((voltage.name, voltage.unit), ("s1_voltage", Some("V")));
        assert_eq!(
            (voltage.read)(&measures).values(),
            [
                (Some(Phase::U), 0.0),
                (Some(Phase::V), 230.1),
                (Some(Phase::W), 0.0)
            ]
        );
        let frequency = &MEASURES[1];
        assert_eq!(frequency.unit, Some("Hz"));
        assert_eq!((frequency.read)(&measures), Amount::One(50.02));
        assert_eq!((voltage.read)(&measures).get(Some(Phase::V)), Some(230.1));
        assert_eq!((voltage.read)(&measures).get(None), None);
    }

    #[test]
    fn the_protocol_revision_is_a_count_without_a_unit() {
        let mut ratings = Ratings::from_words(&[0; Ratings::LEN]);
        ratings.protocol_revision = 5;
        let revision = RATINGS
            .iter()
            .find(|q| q.name == "protocol_revision")
            .expect("listed");
        assert_eq!(revision.unit, None);
        assert_eq!((revision.read)(&ratings), Amount::Count(5));
    }
}
