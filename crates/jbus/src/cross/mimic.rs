//! The mimic diagram (words 0x14–0x17): which of the 15 line segments are lit, and the
//! on/off/alarm lamps of the 11 elements.

use std::fmt;

use super::bits::{Flags, NamedBit, named_bits};
use crate::rtu::InvalidValue;

/// One of the 15 segments of the mimic diagram (bit `n - 1` of word 0x14).
///
/// The manual's picture of the diagram did not survive in the text, so segments are known
/// by number only; [`crate::cross::device`] documents which segment the twin lights for
/// which part of the circuit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Segment(u8);

impl Segment {
    /// The first segment.
    pub const FIRST: u8 = 1;
    /// The last segment.
    pub const LAST: u8 = 15;

    /// Segment `number`, 1–15.
    pub fn new(number: u8) -> Result<Self, InvalidValue> {
        if (Self::FIRST..=Self::LAST).contains(&number) {
            Ok(Self(number))
        } else {
            Err(InvalidValue::out_of_range(
                "mimic segment",
                number,
                Self::FIRST.into(),
                Self::LAST.into(),
            ))
        }
    }

    /// The segment's number, 1–15.
    pub const fn number(self) -> u8 {
        self.0
    }

    /// Every segment, 1 to 15.
    pub fn all() -> impl Iterator<Item = Self> {
        (Self::FIRST..=Self::LAST).map(Self)
    }
}

/// The segment word (0x14): bit `n - 1` is 1 while segment `n` is lit (active).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Segments(u16);

impl Segments {
    /// From the word as read.
    pub const fn from_word(word: u16) -> Self {
        Self(word)
    }

    /// The word as the device sends it.
    pub const fn word(self) -> u16 {
        self.0
    }

    /// Whether `segment` is lit.
    pub fn is_lit(self, segment: Segment) -> bool {
        self.0 & (1 << (segment.0 - 1)) != 0
    }

    /// Lights or darkens `segment`.
    pub fn set(&mut self, segment: Segment, lit: bool) {
        let mask = 1 << (segment.0 - 1);
        if lit {
            self.0 |= mask;
        } else {
            self.0 &= !mask;
        }
    }

    /// The lit segments, lowest first.
    pub fn lit(self) -> impl Iterator<Item = Segment> {
        Segment::all().filter(move |&s| self.is_lit(s))
    }
}

impl fmt::Display for Segments {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let lit: Vec<String> = self.lit().map(|s| s.0.to_string()).collect();
        if lit.is_empty() {
            f.write_str("none lit")
        } else {
            write!(f, "{} lit", lit.join(" "))
        }
    }
}

named_bits!(
    /// An element of the mimic diagram: bit positions in the on, off and alarm status
    /// words (0x15, 0x16, 0x17).
    Element {
        S1 = 0 => "S1",
        S2 = 1 => "S2",
        S1Switch = 2 => "S1-SW",
        S2Switch = 3 => "S2-SW",
        Load = 4 => "LOAD",
        System = 5 => "SYSTEM",
        Is1 = 6 => "IS1",
        Is2 = 7 => "IS2",
        Iby1 = 8 => "IBY1",
        Iby2 = 9 => "IBY2",
        Iout = 10 => "IOUT",
    }
);

/// The lamps of one element: on, off and alarm, as the three status words show them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Lamps {
    /// Its bit in the on-status word (0x15).
    pub on: bool,
    /// Its bit in the off-status word (0x16).
    pub off: bool,
    /// Its bit in the alarm-status word (0x17).
    pub alarm: bool,
}

impl fmt::Display for Lamps {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let names: Vec<&str> = [(self.on, "on"), (self.off, "off"), (self.alarm, "alarm")]
            .into_iter()
            .filter_map(|(lit, name)| lit.then_some(name))
            .collect();
        if names.is_empty() {
            f.write_str("dark")
        } else {
            f.write_str(&names.join("+"))
        }
    }
}

/// The mimic-diagram area (words 0x14–0x17).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Mimic {
    /// Segment word (0x14).
    pub segments: Segments,
    /// On-status word (0x15).
    pub on: Flags<Element>,
    /// Off-status word (0x16).
    pub off: Flags<Element>,
    /// Alarm-status word (0x17).
    pub alarm: Flags<Element>,
}

impl Mimic {
    /// Number of words in the area.
    pub const LEN: usize = 4;

    /// From the area's four words (0x14–0x17).
    pub fn from_words(words: &[u16; Self::LEN]) -> Self {
        Self {
            segments: Segments::from_word(words[0]),
            on: Flags::from_word(words[1]),
            off: Flags::from_word(words[2]),
            alarm: Flags::from_word(words[3]),
        }
    }

    /// The area's four words.
    pub fn to_words(&self) -> [u16; Self::LEN] {
        [
            self.segments.word(),
            self.on.word(),
            self.off.word(),
            self.alarm.word(),
        ]
    }

    /// The lamps of `element`.
    pub fn lamps(&self, element: Element) -> Lamps {
        Lamps {
            on: self.on.contains(element),
            off: self.off.contains(element),
            alarm: self.alarm.contains(element),
        }
    }

    /// Sets the lamps of `element`.
    pub fn set_lamps(&mut self, element: Element, lamps: Lamps) {
        self.on.set(element, lamps.on);
        self.off.set(element, lamps.off);
        self.alarm.set(element, lamps.alarm);
    }
}

impl fmt::Display for Mimic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let lamps: Vec<String> = Element::ALL
            .iter()
            .map(|&e| format!("{e} {}", self.lamps(e)))
            .collect();
        write!(f, "{}; segments {}", lamps.join(", "), self.segments)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segment_n_is_bit_n_minus_1() {
        let segments = Segments::from_word(0b0100_0000_0000_0001);
        assert!(segments.is_lit(Segment::new(1).expect("1")));
        assert!(segments.is_lit(Segment::new(15).expect("15")));
        assert!(!segments.is_lit(Segment::new(2).expect("2")));
        assert_eq!(segments.to_string(), "1 15 lit");
        assert!(Segment::new(0).is_err());
        assert!(Segment::new(16).is_err());
    }

    #[test]
    fn status_words_are_on_then_off_then_alarm() {
        let mimic = Mimic::from_words(&[0, 1 << 4, 1 << 1, 1 << 1]);
        assert_eq!(
            mimic.lamps(Element::Load),
            Lamps {
                on: true,
                off: false,
                alarm: false
            }
        );
        assert_eq!(
            mimic.lamps(Element::S2),
            Lamps {
                on: false,
                off: true,
                alarm: true
            }
        );
        assert_eq!(mimic.lamps(Element::Iout).to_string(), "dark");
        assert_eq!(mimic.to_words(), [0, 1 << 4, 1 << 1, 1 << 1]);
    }
}
