//! The CROSS register map: four areas, every address named, and the reads that fetch them.
//!
//! | area | addresses | |
//! |---|---|---|
//! | internal state | 0x00–0x11 | six operating conditions × off/alarm/on words |
//! | (undefined) | 0x12–0x13 | |
//! | mimic diagram | 0x14–0x17 | segments; on, off, alarm status |
//! | (undefined) | 0x18–0x1D | |
//! | ratings | 0x1E–0x2E | rated current, full scales, protocol revision |
//! | (undefined) | 0x2F–0x45 | |
//! | measures | 0x46–0x59 | voltages, frequencies, currents, power, phase error, air |
//! | (undefined) | 0x5A and above | |
//!
//! All areas are read with function 3; a read touching an undefined address is refused
//! with exception 2.

use std::fmt;
use std::ops::RangeInclusive;

use crate::rtu::{ReadRegisterCount, Request};

/// Addresses of every word, named as in the manual.
pub mod addr {
    /// S1 off-state word.
    pub const S1_OFF: u16 = 0x00;
    /// S1 alarm-state word.
    pub const S1_ALARM: u16 = 0x01;
    /// S1 on-state word.
    pub const S1_ON: u16 = 0x02;
    /// S2 off-state word.
    pub const S2_OFF: u16 = 0x03;
    /// S2 alarm-state word.
    pub const S2_ALARM: u16 = 0x04;
    /// S2 on-state word.
    pub const S2_ON: u16 = 0x05;
    /// S1-SW off-state word.
    pub const S1_SW_OFF: u16 = 0x06;
    /// S1-SW alarm-state word.
    pub const S1_SW_ALARM: u16 = 0x07;
    /// S1-SW on-state word.
    pub const S1_SW_ON: u16 = 0x08;
    /// S2-SW off-state word.
    pub const S2_SW_OFF: u16 = 0x09;
    /// S2-SW alarm-state word.
    pub const S2_SW_ALARM: u16 = 0x0A;
    /// S2-SW on-state word.
    pub const S2_SW_ON: u16 = 0x0B;
    /// LOAD off-state word.
    pub const LOAD_OFF: u16 = 0x0C;
    /// LOAD alarm-state word.
    pub const LOAD_ALARM: u16 = 0x0D;
    /// LOAD on-state word.
    pub const LOAD_ON: u16 = 0x0E;
    /// SYSTEM off-state word (all bits reserved).
    pub const SYSTEM_OFF: u16 = 0x0F;
    /// SYSTEM alarm-state word.
    pub const SYSTEM_ALARM: u16 = 0x10;
    /// SYSTEM on-state word.
    pub const SYSTEM_ON: u16 = 0x11;

    /// Mimic diagram: segment word.
    pub const MIMIC_SEGMENTS: u16 = 0x14;
    /// Mimic diagram: on-status word.
    pub const MIMIC_ON: u16 = 0x15;
    /// Mimic diagram: off-status word.
    pub const MIMIC_OFF: u16 = 0x16;
    /// Mimic diagram: alarm-status word.
    pub const MIMIC_ALARM: u16 = 0x17;

    /// Rated current [tenths of A].
    pub const RATED_CURRENT: u16 = 0x1E;
    /// Full scale VS1 U, V, W [tenths of V].
    pub const FULL_SCALE_VS1_U: u16 = 0x1F;
    /// Full scale VS2 U, V, W [tenths of V].
    pub const FULL_SCALE_VS2_U: u16 = 0x22;
    /// Full scale Vout U, V, W [tenths of V].
    pub const FULL_SCALE_VOUT_U: u16 = 0x25;
    /// Full scale Iout U, V, W (whole amperes).
    pub const FULL_SCALE_IOUT_U: u16 = 0x28;
    /// Full scale Iout neutral (whole amperes).
    pub const FULL_SCALE_IOUT_NEUTRAL: u16 = 0x2B;
    /// Full scale neutral voltage [tenths of V].
    pub const FULL_SCALE_NEUTRAL_VOLTAGE: u16 = 0x2C;
    /// Full scale inlet air temperature [tenths of °C].
    pub const FULL_SCALE_INLET_AIR: u16 = 0x2D;
    /// JBUS protocol revision.
    pub const PROTOCOL_REVISION: u16 = 0x2E;

    /// VS1 U, V, W [tenths of V].
    pub const VS1_U: u16 = 0x46;
    /// FS1 [hundredths of Hz].
    pub const FS1: u16 = 0x49;
    /// VS2 U, V, W [tenths of V].
    pub const VS2_U: u16 = 0x4A;
    /// FS2 [hundredths of Hz].
    pub const FS2: u16 = 0x4D;
    /// Vout U, V, W [tenths of V].
    pub const VOUT_U: u16 = 0x4E;
    /// Iout U, V, W [tenths of A].
    pub const IOUT_U: u16 = 0x51;
    /// Iout neutral [tenths of A].
    pub const IOUT_NEUTRAL: u16 = 0x54;
    /// Neutral voltage [tenths of V].
    pub const NEUTRAL_VOLTAGE: u16 = 0x55;
    /// F out [hundredths of Hz].
    pub const FOUT: u16 = 0x56;
    /// Load power [tenths of kVA].
    pub const LOAD_POWER: u16 = 0x57;
    /// Phase error [tenths of a degree].
    pub const PHASE_ERROR: u16 = 0x58;
    /// Inlet air temperature [tenths of °C].
    pub const INLET_AIR: u16 = 0x59;
}

/// One defined area of the map.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Area {
    /// 0x00–0x11: the six operating conditions.
    InternalState,
    /// 0x14–0x17: the mimic diagram.
    MimicDiagram,
    /// 0x1E–0x2E: ratings.
    Ratings,
    /// 0x46–0x59: measures.
    Measures,
}

impl Area {
    /// Every area, in address order.
    pub const ALL: [Self; 4] = [
        Self::InternalState,
        Self::MimicDiagram,
        Self::Ratings,
        Self::Measures,
    ];

    /// The area's addresses.
    pub const fn addresses(self) -> RangeInclusive<u16> {
        match self {
            Self::InternalState => 0x00..=0x11,
            Self::MimicDiagram => 0x14..=0x17,
            Self::Ratings => 0x1E..=0x2E,
            Self::Measures => 0x46..=0x59,
        }
    }

    /// The first address.
    pub const fn start(self) -> u16 {
        *self.addresses().start()
    }

    /// Number of words.
    pub const fn words(self) -> u16 {
        *self.addresses().end() - *self.addresses().start() + 1
    }

    /// The area holding `address`, if it is defined.
    pub fn of(address: u16) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|area| area.addresses().contains(&address))
    }
}

impl fmt::Display for Area {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::InternalState => "internal state",
            Self::MimicDiagram => "mimic diagram",
            Self::Ratings => "ratings",
            Self::Measures => "measures",
        })
    }
}

/// One past the last defined address: the register image holds words 0x00–0x59.
pub const MAP_LEN: usize = 0x5A;

/// Whether `address` is defined.
pub fn is_defined(address: u16) -> bool {
    Area::of(address).is_some()
}

/// Whether every address of `count` words from `start` is defined (an empty block is not).
pub fn block_is_defined(start: u16, count: u16) -> bool {
    let end = u32::from(start) + u32::from(count);
    count > 0 && (u32::from(start)..end).all(|a| u16::try_from(a).is_ok_and(is_defined))
}

/// The fewest function-3 reads, as `(first address, word count)`, that cover every defined
/// address and touch no undefined one: one read per run of defined addresses, split at 125
/// words. For the CROSS that is one read per area.
pub fn read_plan() -> Vec<(u16, u16)> {
    let max = usize::from(ReadRegisterCount::MAX);
    let mut plan = Vec::new();
    let mut run: Option<(u16, usize)> = None;
    for address in 0..=u16::try_from(MAP_LEN).unwrap_or(u16::MAX) {
        match (&mut run, is_defined(address)) {
            (Some((_, len)), true) if *len < max => *len += 1,
            (Some((start, len)), _) => {
                plan.push((*start, u16::try_from(*len).unwrap_or(u16::MAX)));
                run = is_defined(address).then_some((address, 1));
            }
            (None, true) => run = Some((address, 1)),
            (None, false) => {}
        }
    }
    if let Some((start, len)) = run {
        plan.push((start, u16::try_from(len).unwrap_or(u16::MAX)));
    }
    plan
}

/// [`read_plan`] as function-3 requests.
pub fn read_requests() -> Vec<Request> {
    read_plan()
        .into_iter()
        .map(|(start, count)| {
            Request::read_holding_registers(start, count)
                .expect("the plan's reads are 1-125 words within the map")
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_map_has_the_manuals_undefined_gaps() {
        for undefined in [0x12, 0x13, 0x18, 0x1D, 0x2F, 0x45, 0x5A, 0x81, 0xFFFF] {
            assert!(!is_defined(undefined), "0x{undefined:02X}");
        }
        for defined in [0x00, 0x11, 0x14, 0x17, 0x1E, 0x2E, 0x46, 0x59] {
            assert!(is_defined(defined), "0x{defined:02X}");
        }
        assert_eq!(
            Area::ALL
                .iter()
                .map(|a| usize::from(a.words()))
                .sum::<usize>(),
            18 + 4 + 17 + 20
        );
    }

    #[test]
    fn read_plan_is_one_read_per_area() {
        assert_eq!(
            read_plan(),
            vec![(0x00, 18), (0x14, 4), (0x1E, 17), (0x46, 20)]
        );
        assert_eq!(read_requests().len(), 4);
    }

    #[test]
    fn read_plan_covers_every_defined_address_and_no_undefined_one() {
        let mut covered = [false; 0x1_0000];
        for (start, count) in read_plan() {
            assert!((1..=125).contains(&count));
            assert!(
                block_is_defined(start, count),
                "read 0x{start:02X}+{count} touches an undefined address"
            );
            for a in start..start + count {
                assert!(!covered[usize::from(a)], "0x{a:02X} read twice");
                covered[usize::from(a)] = true;
            }
        }
        for a in 0..=u16::MAX {
            assert_eq!(covered[usize::from(a)], is_defined(a), "0x{a:04X}");
        }
    }

    #[test]
    fn read_plan_is_minimal() {
        // Each read covers one run of defined addresses at most (a gap would be touched),
        // so no plan has fewer reads than the sum over runs of ceil(run / 125).
        let mut runs = Vec::new();
        let mut current = 0usize;
        for a in 0..=u16::MAX {
            if is_defined(a) {
                current += 1;
            } else if current > 0 {
                runs.push(current);
                current = 0;
            }
        }
        let lower_bound: usize = runs.iter().map(|r| r.div_ceil(125)).sum();
        assert_eq!(read_plan().len(), lower_bound);
    }

    #[test]
    fn blocks_are_checked_word_by_word() {
        assert!(block_is_defined(0x00, 18));
        assert!(!block_is_defined(0x00, 19));
        assert!(!block_is_defined(0x10, 5));
        assert!(block_is_defined(0x59, 1));
        assert!(!block_is_defined(0x59, 2));
        assert!(!block_is_defined(0x46, 0));
        assert!(!block_is_defined(0xFFFF, 0xFFFF));
    }
}
