//! Ratings (words 0x1E–0x2E) and measures (words 0x46–0x59), with their units and scaling.
//!
//! Each quantity keeps the register's integer (tenths of a volt, hundredths of a hertz,
//! ...) and shows itself scaled with its unit. Temperatures and the phase error are read
//! as signed (two's complement) words: a phase error or an air temperature can be below
//! zero, and no positive reading comes near 0x8000 (3276.8 °C or degrees).

use std::fmt;

/// Defines a fixed-point quantity type.
macro_rules! quantity {
    ($(#[$doc:meta])* $name:ident, $raw:ty, $decimals:literal, $unit:literal) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
        pub struct $name($raw);

        impl $name {
            /// Decimal places of the register's integer.
            pub const DECIMALS: u32 = $decimals;
            /// The unit.
            pub const UNIT: &'static str = $unit;

            /// From the register's integer.
            pub const fn from_raw(raw: $raw) -> Self {
                Self(raw)
            }

            /// The register's integer.
            pub const fn raw(self) -> $raw {
                self.0
            }

            /// From the register word as read.
            #[allow(clippy::cast_possible_wrap, reason = "signed quantities are two's complement words")]
            pub const fn from_word(word: u16) -> Self {
                Self(word as $raw)
            }

            /// The register word as the device sends it.
            #[allow(clippy::cast_sign_loss, reason = "signed quantities are two's complement words")]
            pub const fn to_word(self) -> u16 {
                self.0 as u16
            }

            /// The value in its unit.
            pub fn value(self) -> f64 {
                f64::from(self.0) / 10f64.powi(Self::DECIMALS as i32)
            }

            /// The nearest representable quantity to `value` (in its unit), saturating at
            /// the register's range.
            pub fn from_value(value: f64) -> Self {
                // `as` saturates on overflow and maps NaN to 0.
                Self((value * 10f64.powi(Self::DECIMALS as i32)).round() as $raw)
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                fixed(f, i32::from(self.0), Self::DECIMALS)?;
                if Self::UNIT.starts_with('°') && Self::UNIT.len() == '°'.len_utf8() {
                    f.write_str(Self::UNIT)
                } else {
                    write!(f, " {}", Self::UNIT)
                }
            }
        }
    };
}

/// Writes `raw / 10^decimals` with exactly `decimals` places.
fn fixed(f: &mut fmt::Formatter<'_>, raw: i32, decimals: u32) -> fmt::Result {
    let scale = 10i32.pow(decimals);
    let sign = if raw < 0 { "-" } else { "" };
    let (whole, part) = (
        raw.unsigned_abs() / scale.unsigned_abs(),
        raw.unsigned_abs() % scale.unsigned_abs(),
    );
    if decimals == 0 {
        write!(f, "{sign}{whole}")
    } else {
        write!(f, "{sign}{whole}.{part:0width$}", width = decimals as usize)
    }
}

quantity!(
    /// A voltage in tenths of a volt.
    Volts, u16, 1, "V"
);
quantity!(
    /// A current in tenths of an ampere.
    Amperes, u16, 1, "A"
);
quantity!(
    /// A current in whole amperes (the output current full scales).
    WholeAmperes, u16, 0, "A"
);
quantity!(
    /// A frequency in hundredths of a hertz.
    Hertz, u16, 2, "Hz"
);
quantity!(
    /// An apparent power in tenths of a kVA.
    KiloVoltAmperes, u16, 1, "kVA"
);
quantity!(
    /// A temperature in tenths of a degree Celsius, signed.
    Celsius, i16, 1, "°C"
);
quantity!(
    /// An angle in tenths of a degree, signed.
    Degrees, i16, 1, "°"
);

/// One value per phase: U, V, W (three consecutive registers).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Phases<T> {
    /// Phase U.
    pub u: T,
    /// Phase V.
    pub v: T,
    /// Phase W.
    pub w: T,
}

impl<T: Copy> Phases<T> {
    /// The same value on every phase.
    pub const fn all(value: T) -> Self {
        Self {
            u: value,
            v: value,
            w: value,
        }
    }

    /// U, V, W.
    pub const fn to_array(self) -> [T; 3] {
        [self.u, self.v, self.w]
    }

    /// Each phase's value through `f` (a quantity's value in its unit).
    pub fn map<U>(self, f: impl Fn(T) -> U) -> Phases<U> {
        Phases {
            u: f(self.u),
            v: f(self.v),
            w: f(self.w),
        }
    }
}

impl<T: fmt::Display> fmt::Display for Phases<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "U {}, V {}, W {}", self.u, self.v, self.w)
    }
}

fn phases<T>(words: &[u16], at: usize, from: fn(u16) -> T) -> Phases<T> {
    let word = |i: usize| words.get(at + i).copied().unwrap_or(0);
    Phases {
        u: from(word(0)),
        v: from(word(1)),
        w: from(word(2)),
    }
}

fn put_phases<T: Copy>(words: &mut [u16], at: usize, values: Phases<T>, to: fn(T) -> u16) {
    for (i, value) in values.to_array().into_iter().enumerate() {
        if let Some(slot) = words.get_mut(at + i) {
            *slot = to(value);
        }
    }
}

/// The ratings area (words 0x1E–0x2E): the switch's rated current, the full scales of its
/// measures and the JBUS protocol revision.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Ratings {
    /// 0x1E: rated current.
    pub rated_current: Amperes,
    /// 0x1F–0x21: full scale of the source 1 voltages.
    pub s1_voltage_full_scale: Phases<Volts>,
    /// 0x22–0x24: full scale of the source 2 voltages.
    pub s2_voltage_full_scale: Phases<Volts>,
    /// 0x25–0x27: full scale of the output voltages.
    pub output_voltage_full_scale: Phases<Volts>,
    /// 0x28–0x2A: full scale of the output currents (whole amperes).
    pub output_current_full_scale: Phases<WholeAmperes>,
    /// 0x2B: full scale of the output neutral current (whole amperes).
    pub neutral_current_full_scale: WholeAmperes,
    /// 0x2C: full scale of the neutral voltage (the manual's "Neutral ? V"; the symbol is
    /// lost in the text, most likely neutral to earth).
    pub neutral_voltage_full_scale: Volts,
    /// 0x2D: full scale of the inlet air temperature.
    pub inlet_air_full_scale: Celsius,
    /// 0x2E: revision of the JBUS protocol (5 for the manual at hand).
    pub protocol_revision: u16,
}

impl Ratings {
    /// Number of words in the area.
    pub const LEN: usize = 17;

    /// From the area's 17 words (0x1E–0x2E).
    pub fn from_words(words: &[u16; Self::LEN]) -> Self {
        Self {
            rated_current: Amperes::from_word(words[0]),
            s1_voltage_full_scale: phases(words, 1, Volts::from_word),
            s2_voltage_full_scale: phases(words, 4, Volts::from_word),
            output_voltage_full_scale: phases(words, 7, Volts::from_word),
            output_current_full_scale: phases(words, 10, WholeAmperes::from_word),
            neutral_current_full_scale: WholeAmperes::from_word(words[13]),
            neutral_voltage_full_scale: Volts::from_word(words[14]),
            inlet_air_full_scale: Celsius::from_word(words[15]),
            protocol_revision: words[16],
        }
    }

    /// The area's 17 words.
    pub fn to_words(&self) -> [u16; Self::LEN] {
        let mut words = [0; Self::LEN];
        words[0] = self.rated_current.to_word();
        put_phases(&mut words, 1, self.s1_voltage_full_scale, Volts::to_word);
        put_phases(&mut words, 4, self.s2_voltage_full_scale, Volts::to_word);
        put_phases(
            &mut words,
            7,
            self.output_voltage_full_scale,
            Volts::to_word,
        );
        put_phases(
            &mut words,
            10,
            self.output_current_full_scale,
            WholeAmperes::to_word,
        );
        words[13] = self.neutral_current_full_scale.to_word();
        words[14] = self.neutral_voltage_full_scale.to_word();
        words[15] = self.inlet_air_full_scale.to_word();
        words[16] = self.protocol_revision;
        words
    }
}

impl fmt::Display for Ratings {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "rated current {}, JBUS protocol revision {}",
            self.rated_current, self.protocol_revision
        )?;
        writeln!(f, "full scale source 1    {}", self.s1_voltage_full_scale)?;
        writeln!(f, "full scale source 2    {}", self.s2_voltage_full_scale)?;
        writeln!(
            f,
            "full scale output      {}",
            self.output_voltage_full_scale
        )?;
        writeln!(
            f,
            "full scale current     {}, neutral {}",
            self.output_current_full_scale, self.neutral_current_full_scale
        )?;
        write!(
            f,
            "full scale neutral voltage {}, inlet air {}",
            self.neutral_voltage_full_scale, self.inlet_air_full_scale
        )
    }
}

/// The measures area (words 0x46–0x59).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Measures {
    /// 0x46–0x48: source 1 voltages.
    pub s1_voltage: Phases<Volts>,
    /// 0x49: source 1 frequency.
    pub s1_frequency: Hertz,
    /// 0x4A–0x4C: source 2 voltages.
    pub s2_voltage: Phases<Volts>,
    /// 0x4D: source 2 frequency.
    pub s2_frequency: Hertz,
    /// 0x4E–0x50: output voltages.
    pub output_voltage: Phases<Volts>,
    /// 0x51–0x53: output currents.
    pub output_current: Phases<Amperes>,
    /// 0x54: output neutral current.
    pub neutral_current: Amperes,
    /// 0x55: neutral voltage (the manual's "Neutral ? V").
    pub neutral_voltage: Volts,
    /// 0x56: output frequency.
    pub output_frequency: Hertz,
    /// 0x57: load power.
    pub load_power: KiloVoltAmperes,
    /// 0x58: phase error between the sources.
    pub phase_error: Degrees,
    /// 0x59: inlet air temperature.
    pub inlet_air: Celsius,
}

impl Measures {
    /// Number of words in the area.
    pub const LEN: usize = 20;

    /// From the area's 20 words (0x46–0x59).
    pub fn from_words(words: &[u16; Self::LEN]) -> Self {
        Self {
            s1_voltage: phases(words, 0, Volts::from_word),
            s1_frequency: Hertz::from_word(words[3]),
            s2_voltage: phases(words, 4, Volts::from_word),
            s2_frequency: Hertz::from_word(words[7]),
            output_voltage: phases(words, 8, Volts::from_word),
            output_current: phases(words, 11, Amperes::from_word),
            neutral_current: Amperes::from_word(words[14]),
            neutral_voltage: Volts::from_word(words[15]),
            output_frequency: Hertz::from_word(words[16]),
            load_power: KiloVoltAmperes::from_word(words[17]),
            phase_error: Degrees::from_word(words[18]),
            inlet_air: Celsius::from_word(words[19]),
        }
    }

    /// The area's 20 words.
    pub fn to_words(&self) -> [u16; Self::LEN] {
        let mut words = [0; Self::LEN];
        put_phases(&mut words, 0, self.s1_voltage, Volts::to_word);
        words[3] = self.s1_frequency.to_word();
        put_phases(&mut words, 4, self.s2_voltage, Volts::to_word);
        words[7] = self.s2_frequency.to_word();
        put_phases(&mut words, 8, self.output_voltage, Volts::to_word);
        put_phases(&mut words, 11, self.output_current, Amperes::to_word);
        words[14] = self.neutral_current.to_word();
        words[15] = self.neutral_voltage.to_word();
        words[16] = self.output_frequency.to_word();
        words[17] = self.load_power.to_word();
        words[18] = self.phase_error.to_word();
        words[19] = self.inlet_air.to_word();
        words
    }
}

impl fmt::Display for Measures {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "source 1  {}, {}", self.s1_voltage, self.s1_frequency)?;
        writeln!(f, "source 2  {}, {}", self.s2_voltage, self.s2_frequency)?;
        writeln!(
            f,
            "output    {}, {}",
            self.output_voltage, self.output_frequency
        )?;
        writeln!(
            f,
            "current   {}, neutral {}",
            self.output_current, self.neutral_current
        )?;
        writeln!(
            f,
            "load      {}, neutral voltage {}",
            self.load_power, self.neutral_voltage
        )?;
        write!(
            f,
            "phase error {}, inlet air {}",
            self.phase_error, self.inlet_air
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantities_show_their_scale_and_unit() {
        assert_eq!(Volts::from_raw(2301).to_string(), "230.1 V");
        assert_eq!(Amperes::from_raw(5).to_string(), "0.5 A");
        assert_eq!(WholeAmperes::from_raw(150).to_string(), "150 A");
        assert_eq!(Hertz::from_raw(5002).to_string(), "50.02 Hz");
        assert_eq!(Hertz::from_raw(7).to_string(), "0.07 Hz");
        assert_eq!(KiloVoltAmperes::from_raw(601).to_string(), "60.1 kVA");
        assert_eq!(Celsius::from_raw(248).to_string(), "24.8 °C");
        assert_eq!(Degrees::from_raw(-3).to_string(), "-0.3°");
    }

    #[test]
    fn temperature_and_phase_error_words_are_signed() {
        assert_eq!(Celsius::from_word(0xFFF6).raw(), -10);
        assert_eq!(Celsius::from_raw(-10).to_word(), 0xFFF6);
        assert_eq!(Degrees::from_word(0x8000).to_string(), "-3276.8°");
        assert_eq!(Volts::from_word(0xFFFF).to_string(), "6553.5 V");
    }

    #[test]
    fn from_value_rounds_and_saturates() {
        assert_eq!(Volts::from_value(230.04).raw(), 2300);
        assert_eq!(Volts::from_value(230.05).raw(), 2301);
        assert_eq!(Volts::from_value(-5.0).raw(), 0);
        assert_eq!(Volts::from_value(1e9).raw(), u16::MAX);
        assert_eq!(Hertz::from_value(49.987).raw(), 4999);
        assert!((Hertz::from_raw(5000).value() - 50.0).abs() < 1e-9);
    }

    #[test]
    fn ratings_and_measures_words_round_trip() {
        let ratings: [u16; 17] = std::array::from_fn(|i| 100 + i as u16);
        assert_eq!(Ratings::from_words(&ratings).to_words(), ratings);
        assert_eq!(Ratings::from_words(&ratings).protocol_revision, 116);
        let measures: [u16; 20] = std::array::from_fn(|i| 0xFF00 + i as u16);
        assert_eq!(Measures::from_words(&measures).to_words(), measures);
        assert_eq!(Measures::from_words(&measures).inlet_air.to_word(), 0xFF13);
    }
}
