//! The sealing band: its resistance from the service data, and its temperature over time.
//!
//! # Electrical model
//!
//! From the service data (items 0–8):
//!
//! - cross-section `A` (mm²) = width × thickness for a flat band; when either is 0, a round
//!   wire: `A = π/4 × gauge²`;
//! - one band: `R₁ = ρ × (L / 1000) / A` with `ρ` in Ω·mm²/m and `L` in mm;
//! - the circuit: `R₂₀ = R₁ × series / parallel` (at 20 °C);
//! - hot: `R(T) = R₂₀ × (1 + α × (T − 20 °C))`, `α` = [`TCR_PER_K`];
//! - theoretical current `I = J × A × parallel` (`J` in A/mm²), voltage `U = I × R₂₀`, power
//!   `P = U × I`: service items 9–12, recomputed whenever the service data change.
//!
//! While the regulator fires the band it applies the set voltage (service item 15), so
//! `I = U / R(T)` and `P = U × I`. The twin does not model phase-angle control: a hold at a
//! set point shows the full voltage.
//!
//! # Thermal model
//!
//! Kinematic, so it can be integrated exactly between any two instants: while heating, the
//! band follows the heating ramp (machine item 1, degrees per 10 ms) linearly; while not
//! fired it cools toward ambient by Newton's law, `T(t) = Tₐ + (T₀ − Tₐ) e^(−t/τ)`; at a set
//! point it holds.

use std::time::Duration;

use crate::frame::RawValue;
use crate::tables::service;

/// Temperature coefficient of resistance of the band alloy, per kelvin. Impulse bands use
/// alloys whose resistance rises with temperature so the regulator can measure it; 1100
/// ppm/K is typical of them. The spec gives none: this is the twin's choice.
pub const TCR_PER_K: f64 = 0.0011;
/// The temperature at which resistivity and the band's resistance are given.
pub const REFERENCE_C: f64 = 20.0;
/// Below this distance two temperatures are the same (°C).
pub(crate) const EPSILON_C: f64 = 1e-9;

/// The band as the service data describe it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BandDesign {
    /// Width, mm.
    pub width: f64,
    /// Thickness, mm.
    pub thickness: f64,
    /// Round wire diameter, mm (used when width or thickness is 0).
    pub gauge: f64,
    /// Length of one band, mm.
    pub length: f64,
    /// Bands in parallel.
    pub parallel: f64,
    /// Bands in series.
    pub series: f64,
    /// Resistivity, Ω·mm²/m.
    pub resistivity: f64,
    /// Rated current density, A/mm².
    pub current_density: f64,
}

impl BandDesign {
    /// The design in the service table (all 17 items, raw).
    pub fn from_service(table: &[RawValue]) -> Self {
        let value = |index: u8| {
            crate::tables::Table::Service
                .item(index)
                .ok()
                .zip(table.get(usize::from(index)))
                .map_or(0.0, |(item, raw)| item.from_raw(*raw))
        };
        Self {
            width: value(service::WIDTH),
            thickness: value(service::THICKNESS),
            gauge: value(service::WIRE_GAUGE),
            length: value(service::LENGTH),
            parallel: value(service::IN_PARALLEL),
            series: value(service::IN_SERIES),
            resistivity: value(service::RESISTIVITY),
            current_density: value(service::CURRENT_DENSITY),
        }
    }

    /// Cross-section of one band, mm².
    pub fn cross_section(&self) -> f64 {
        if self.width > 0.0 && self.thickness > 0.0 {
            self.width * self.thickness
        } else {
            std::f64::consts::FRAC_PI_4 * self.gauge * self.gauge
        }
    }

    /// Resistance of the circuit at 20 °C, Ω: infinite without a cross-section or a band in
    /// parallel (no circuit), 0 without length, resistivity or a band in series.
    pub fn resistance_20(&self) -> f64 {
        let area = self.cross_section();
        if area <= 0.0 || self.parallel <= 0.0 {
            return f64::INFINITY;
        }
        self.resistivity * (self.length / 1000.0) / area * self.series / self.parallel
    }

    /// Maximum theoretical current, A.
    pub fn theoretical_current(&self) -> f64 {
        self.current_density * self.cross_section() * self.parallel
    }

    /// Theoretical voltage, V.
    pub fn theoretical_voltage(&self) -> f64 {
        self.theoretical_current() * self.resistance_20()
    }

    /// Theoretical power, VA.
    pub fn theoretical_power(&self) -> f64 {
        self.theoretical_voltage() * self.theoretical_current()
    }
}

/// Resistance at `temperature` of a circuit with `r20` at 20 °C.
pub fn resistance_at(r20: f64, temperature: f64) -> f64 {
    r20 * (1.0 + TCR_PER_K * (temperature - REFERENCE_C))
}

/// What the band does over one stretch of time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Motion {
    /// Fired, rising at `rate` °C/s toward `target`.
    Ramp { target: f64, rate: f64 },
    /// Fired, holding its temperature.
    Hold,
    /// Not fired, cooling toward ambient; `stop_at` is a set point where firing resumes.
    Cool { stop_at: Option<f64> },
}

impl Motion {
    /// How the band moves from `temperature` when the regulator aims for `target` (`None`:
    /// not firing) at `rate` °C/s.
    pub(crate) fn choose(temperature: f64, target: Option<f64>, rate: f64, ambient: f64) -> Motion {
        match target {
            None => Motion::Cool { stop_at: None },
            Some(target) if temperature < target - EPSILON_C => Motion::Ramp { target, rate },
            Some(target) if temperature > target + EPSILON_C => Motion::Cool {
                stop_at: (target > ambient).then_some(target),
            },
            Some(_) => Motion::Hold,
        }
    }

    /// Whether the regulator fires the band.
    pub(crate) fn fired(self) -> bool {
        !matches!(self, Motion::Cool { .. })
    }

    /// When the motion reaches its end (a set point), from `temperature`; `None` if never.
    pub(crate) fn reaches_after(
        self,
        temperature: f64,
        ambient: f64,
        tau: Duration,
    ) -> Option<Duration> {
        let seconds = match self {
            Motion::Ramp { target, rate } if rate > 0.0 => (target - temperature) / rate,
            Motion::Cool {
                stop_at: Some(stop),
            } if temperature - ambient > 0.0 && stop > ambient => {
                tau.as_secs_f64() * ((temperature - ambient) / (stop - ambient)).ln()
            }
            _ => return None,
        };
        Duration::try_from_secs_f64(seconds.max(0.0)).ok()
    }

    /// The temperature after `elapsed` from `temperature` (before any end is reached).
    pub(crate) fn after(
        self,
        temperature: f64,
        elapsed: Duration,
        ambient: f64,
        tau: Duration,
    ) -> f64 {
        let t = elapsed.as_secs_f64();
        match self {
            Motion::Ramp { target, rate } => (temperature + rate * t).min(target),
            Motion::Hold => temperature,
            Motion::Cool { stop_at } => {
                let cooled = ambient + (temperature - ambient) * (-t / tau.as_secs_f64()).exp();
                stop_at.map_or(cooled, |stop| cooled.max(stop))
            }
        }
    }

    /// The temperature when the end is reached.
    pub(crate) fn end_temperature(self, temperature: f64) -> f64 {
        match self {
            Motion::Ramp { target, .. } => target,
            Motion::Cool {
                stop_at: Some(stop),
            } => stop,
            _ => temperature,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn design() -> BandDesign {
        BandDesign {
            width: 5.0,
            thickness: 0.2,
            gauge: 0.0,
            length: 500.0,
            parallel: 1.0,
            series: 1.0,
            resistivity: 0.5,
            current_density: 40.0,
        }
    }

    #[test]
    fn a_flat_band_resistance_is_resistivity_times_length_over_cross_section() {
        // 0.5 Ω·mm²/m × 0.5 m / (5 mm × 0.2 mm) = 0.25 Ω.
        assert!((design().resistance_20() - 0.25).abs() < 1e-12);
        assert!((design().theoretical_current() - 40.0).abs() < 1e-9);
        assert!((design().theoretical_voltage() - 10.0).abs() < 1e-9);
        assert!((design().theoretical_power() - 400.0).abs() < 1e-9);
    }

    #[test]
    fn bands_in_series_add_and_bands_in_parallel_share() {
        let two_in_series = BandDesign {
            series: 2.0,
            ..design()
        };
        let two_in_parallel = BandDesign {
            parallel: 2.0,
            ..design()
        };
        assert!((two_in_series.resistance_20() - 0.5).abs() < 1e-12);
        assert!((two_in_parallel.resistance_20() - 0.125).abs() < 1e-12);
        assert!((two_in_parallel.theoretical_current() - 80.0).abs() < 1e-9);
    }

    #[test]
    fn a_round_wire_uses_the_gauge_when_the_band_has_no_width() {
        let wire = BandDesign {
            width: 0.0,
            gauge: 1.0,
            ..design()
        };
        let area = std::f64::consts::FRAC_PI_4;
        assert!((wire.cross_section() - area).abs() < 1e-12);
        assert!((wire.resistance_20() - 0.5 * 0.5 / area).abs() < 1e-12);
    }

    #[test]
    fn a_band_without_cross_section_is_an_open_circuit() {
        let nothing = BandDesign {
            width: 0.0,
            gauge: 0.0,
            ..design()
        };
        assert!(nothing.resistance_20().is_infinite());
    }

    #[test]
    fn resistance_rises_with_temperature() {
        assert!((resistance_at(0.25, 20.0) - 0.25).abs() < 1e-12);
        assert!((resistance_at(0.25, 180.0) - 0.25 * (1.0 + 0.0011 * 160.0)).abs() < 1e-12);
    }

    #[test]
    fn cooling_reaches_a_set_point_after_tau_times_the_log_ratio() {
        let tau = Duration::from_millis(800);
        let motion = Motion::choose(180.0, Some(80.0), 200.0, 20.0);
        assert_eq!(
            motion,
            Motion::Cool {
                stop_at: Some(80.0)
            }
        );
        let after = motion
            .reaches_after(180.0, 20.0, tau)
            .expect("reaches the set point");
        assert!((after.as_secs_f64() - 0.8 * (160.0f64 / 60.0).ln()).abs() < 1e-6);
        let halfway = motion.after(180.0, after / 2, 20.0, tau);
        assert!(halfway > 80.0 && halfway < 180.0);
    }

    #[test]
    fn a_ramp_rises_linearly_and_stops_at_its_target() {
        let motion = Motion::choose(80.0, Some(180.0), 200.0, 20.0);
        assert_eq!(
            motion.reaches_after(80.0, 20.0, Duration::from_secs(1)),
            Some(Duration::from_millis(500))
        );
        assert!(
            (motion.after(
                80.0,
                Duration::from_millis(250),
                20.0,
                Duration::from_secs(1)
            ) - 130.0)
                .abs()
                < 1e-9
        );
        assert!(motion.fired());
    }
}
