//! The whole state of a CROSS, decoded from the words of its four areas.

use std::fmt;

use super::bits::{
    InternalState, LoadAlarm, LoadOff, LoadOn, NamedBit, S1SwitchOn, S2SwitchOn, SystemAlarm,
};
use super::map::{Area, MAP_LEN};
use super::measure::{Measures, Ratings};
use super::mimic::Mimic;

/// One of the two sources.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Source {
    /// Source 1 (S1).
    S1,
    /// Source 2 (S2).
    S2,
}

impl Source {
    /// The other source.
    pub const fn other(self) -> Self {
        match self {
            Self::S1 => Self::S2,
            Self::S2 => Self::S1,
        }
    }

    /// 0 for S1, 1 for S2.
    pub const fn index(self) -> usize {
        match self {
            Self::S1 => 0,
            Self::S2 => 1,
        }
    }
}

impl fmt::Display for Source {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::S1 => "source 1 (S1)",
            Self::S2 => "source 2 (S2)",
        })
    }
}

/// What feeds the load, as the state words tell it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Feed {
    /// A source through its static switch (S1-SW or S2-SW).
    StaticSwitch(Source),
    /// A source through its manual bypass (IBY1 or IBY2 closed).
    Bypass(Source),
    /// The output breaker (IOUT) is open: the load is disconnected.
    OutputBreakerOpen,
    /// Nothing: the LOAD alarm "load not supplied" is on, or no switch conducts.
    NotSupplied,
}

impl Feed {
    /// The source that feeds the load, through its static switch or its bypass; `None`
    /// when the load is disconnected or not supplied.
    pub const fn source(self) -> Option<Source> {
        match self {
            Self::StaticSwitch(s) | Self::Bypass(s) => Some(s),
            Self::OutputBreakerOpen | Self::NotSupplied => None,
        }
    }
}

impl fmt::Display for Feed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::StaticSwitch(s) => {
                let switch = if *s == Source::S1 { "S1-SW" } else { "S2-SW" };
                write!(f, "supplied by {s} through static switch {switch}")
            }
            Self::Bypass(s) => {
                let bypass = if *s == Source::S1 { "IBY1" } else { "IBY2" };
                write!(f, "supplied by {s} through manual bypass {bypass}")
            }
            Self::OutputBreakerOpen => f.write_str("disconnected: output breaker open"),
            Self::NotSupplied => f.write_str("NOT SUPPLIED"),
        }
    }
}

/// A defined word missing from the blocks given to [`CrossState::from_blocks`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("word 0x{address:02X} of the {area} area was not read: read every area of `read_plan()`")]
pub struct MissingWord {
    /// The first defined address missing.
    pub address: u16,
    /// Its area.
    pub area: Area,
}

/// Every defined word of a CROSS, named and scaled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct CrossState {
    /// Words 0x00–0x11: the six operating conditions.
    pub internal: InternalState,
    /// Words 0x14–0x17: the mimic diagram.
    pub mimic: Mimic,
    /// Words 0x1E–0x2E: ratings.
    pub ratings: Ratings,
    /// Words 0x46–0x59: measures.
    pub measures: Measures,
}

impl CrossState {
    /// Decodes the state from blocks of consecutive words read, as `(first address,
    /// words)`, e.g. the answers to [`read_plan`](super::read_plan). Blocks may overlap or
    /// hold undefined words (ignored); every defined word must be in one.
    pub fn from_blocks(blocks: &[(u16, Vec<u16>)]) -> Result<Self, MissingWord> {
        let mut image = [None; MAP_LEN];
        for (start, words) in blocks {
            for (offset, &word) in words.iter().enumerate() {
                if let Some(slot) = image.get_mut(usize::from(*start) + offset) {
                    *slot = Some(word);
                }
            }
        }
        let mut words = [0u16; MAP_LEN];
        for area in Area::ALL {
            for address in area.addresses() {
                let slot = usize::from(address);
                words[slot] = image[slot].ok_or(MissingWord { address, area })?;
            }
        }
        Ok(Self::from_image(&words))
    }

    /// Decodes the state from the register image, words 0x00–0x59 (undefined ones ignored).
    pub fn from_image(words: &[u16; MAP_LEN]) -> Self {
        Self {
            internal: InternalState::from_words(&area_words(words, Area::InternalState)),
            mimic: Mimic::from_words(&area_words(words, Area::MimicDiagram)),
            ratings: Ratings::from_words(&area_words(words, Area::Ratings)),
            measures: Measures::from_words(&area_words(words, Area::Measures)),
        }
    }

    /// The register image, words 0x00–0x59; undefined words are 0.
    pub fn to_image(&self) -> [u16; MAP_LEN] {
        let mut image = [0; MAP_LEN];
        put(&mut image, Area::InternalState, &self.internal.to_words());
        put(&mut image, Area::MimicDiagram, &self.mimic.to_words());
        put(&mut image, Area::Ratings, &self.ratings.to_words());
        put(&mut image, Area::Measures, &self.measures.to_words());
        image
    }

    /// What feeds the load.
    pub fn feed(&self) -> Feed {
        self.internal.feed()
    }

    /// Descriptions of every active alarm bit.
    pub fn alarms(&self) -> Vec<&'static str> {
        self.internal.alarms()
    }

    /// Descriptions of the active bits of the on-state and off-state words (the states
    /// that are not alarms: "S1 normal", "load on reserve line", "S2 breaker open", ...).
    pub fn conditions(&self) -> Vec<&'static str> {
        self.internal.conditions()
    }

    /// Whether the load is on the reserve (non-preferred) line, per the LOAD on-state word.
    pub fn on_reserve_line(&self) -> bool {
        self.internal.on_reserve_line()
    }
}

/// What the internal-state area alone tells (the gateway's live poll reads no other area).
impl InternalState {
    /// What feeds the load.
    pub fn feed(&self) -> Feed {
        let s = self;
        if s.load.off.contains(LoadOff::OutputBreakerOpen) {
            Feed::OutputBreakerOpen
        } else if s.load.alarm.contains(LoadAlarm::NotSupplied) {
            Feed::NotSupplied
        } else if s.system.alarm.contains(SystemAlarm::BypassS1Closed) {
            Feed::Bypass(Source::S1)
        } else if s.system.alarm.contains(SystemAlarm::BypassS2Closed) {
            Feed::Bypass(Source::S2)
        } else if s.s1_switch.on.contains(S1SwitchOn::LoadOnSource1) {
            Feed::StaticSwitch(Source::S1)
        } else if s.s2_switch.on.contains(S2SwitchOn::LoadOnSource2) {
            Feed::StaticSwitch(Source::S2)
        } else {
            Feed::NotSupplied
        }
    }

    /// Descriptions of the active bits of the on-state and off-state words (the states
    /// that are not alarms: "S1 normal", "load on reserve line", "S2 breaker open", ...).
    pub fn conditions(&self) -> Vec<&'static str> {
        let s = self;
        let mut out = Vec::new();
        out.extend(s.s1.on.active().map(NamedBit::describe));
        out.extend(s.s1.off.active().map(NamedBit::describe));
        out.extend(s.s2.on.active().map(NamedBit::describe));
        out.extend(s.s2.off.active().map(NamedBit::describe));
        out.extend(
            s.s1_switch
                .on
                .active()
                .filter(|&b| b != S1SwitchOn::LoadOnSource1)
                .map(NamedBit::describe),
        );
        out.extend(
            s.s2_switch
                .on
                .active()
                .filter(|&b| b != S2SwitchOn::LoadOnSource2)
                .map(NamedBit::describe),
        );
        out.extend(s.load.on.active().map(NamedBit::describe));
        out.extend(s.load.off.active().map(NamedBit::describe));
        out.extend(s.system.on.active().map(NamedBit::describe));
        out
    }

    /// Whether the load is on the reserve (non-preferred) line, per the LOAD on-state word.
    pub fn on_reserve_line(&self) -> bool {
        self.load.on.contains(LoadOn::OnReserveLine)
    }
}

/// In words: which source feeds the load, active alarms, states, the mimic diagram's
/// lamps, measures with units and ratings.
impl fmt::Display for CrossState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let reserve = if self.on_reserve_line() {
            " (reserve line)"
        } else {
            ""
        };
        writeln!(f, "load: {}{reserve}", self.feed())?;
        let alarms = self.alarms();
        writeln!(
            f,
            "alarms: {}",
            if alarms.is_empty() {
                "none".to_owned()
            } else {
                alarms.join(", ")
            }
        )?;
        writeln!(f, "states: {}", self.conditions().join(", "))?;
        writeln!(f, "mimic: {}", self.mimic)?;
        writeln!(f, "measures:")?;
        for line in self.measures.to_string().lines() {
            writeln!(f, "  {line}")?;
        }
        writeln!(f, "ratings:")?;
        for line in self.ratings.to_string().lines() {
            writeln!(f, "  {line}")?;
        }
        Ok(())
    }
}

fn area_words<const N: usize>(image: &[u16; MAP_LEN], area: Area) -> [u16; N] {
    std::array::from_fn(|i| {
        image
            .get(usize::from(area.start()) + i)
            .copied()
            .unwrap_or(0)
    })
}

fn put(image: &mut [u16; MAP_LEN], area: Area, words: &[u16]) {
    for (slot, &word) in image.iter_mut().skip(usize::from(area.start())).zip(words) {
        *slot = word;
    }
}

#[cfg(test)]
mod tests {
    use super::super::bits::{Flags, S1Alarm, S2SwitchOff};
    use super::super::map::read_plan;
    use super::*;

    fn sample() -> CrossState {
        let image: [u16; MAP_LEN] =
            std::array::from_fn(|i| (i as u16).wrapping_mul(0x1357) ^ 0x2468);
        let mut state = CrossState::from_image(&image);
        state.internal.s2_switch.off = Flags::empty().with(S2SwitchOff::LoadOnSource1);
        state
    }

    #[test]
    fn image_round_trips_and_leaves_undefined_words_zero() {
        let state = sample();
        let image = state.to_image();
        assert_eq!(CrossState::from_image(&image), state);
        for undefined in [0x12, 0x13, 0x18, 0x1D, 0x2F, 0x45] {
            assert_eq!(image[undefined], 0);
        }
    }

    #[test]
    fn from_blocks_reads_the_read_plan_blocks() {
        let state = sample();
        let image = state.to_image();
        let blocks: Vec<(u16, Vec<u16>)> = read_plan()
            .into_iter()
            .map(|(start, count)| {
                (
                    start,
                    image[usize::from(start)..usize::from(start + count)].to_vec(),
                )
            })
            .collect();
        assert_eq!(CrossState::from_blocks(&blocks), Ok(state));
    }

    #[test]
    fn from_blocks_names_the_first_missing_word() {
        let blocks = vec![
            (0x00, vec![0; 18]),
            (0x14, vec![0; 4]),
            (0x1E, vec![0; 17]),
            (0x46, vec![0; 19]),
        ];
        assert_eq!(
            CrossState::from_blocks(&blocks),
            Err(MissingWord {
                address: 0x59,
                area: Area::Measures
            })
        );
        let blocks = vec![(0xFFFF, vec![0; 100])];
        assert_eq!(
            CrossState::from_blocks(&blocks),
            Err(MissingWord {
                address: 0x00,
                area: Area::InternalState
            })
        );
    }

    #[test]
    fn feed_follows_the_switch_words() {
        let mut state = CrossState::default();
        assert_eq!(state.feed(), Feed::NotSupplied);
        state.internal.s2_switch.on = Flags::empty().with(S2SwitchOn::LoadOnSource2);
        assert_eq!(state.feed(), Feed::StaticSwitch(Source::S2));
        state.internal.system.alarm = Flags::empty().with(SystemAlarm::BypassS1Closed);
        assert_eq!(state.feed(), Feed::Bypass(Source::S1));
        state.internal.load.off = Flags::empty().with(LoadOff::OutputBreakerOpen);
        assert_eq!(state.feed(), Feed::OutputBreakerOpen);
    }

    #[test]
    fn display_says_what_feeds_the_load_and_the_alarms() {
        let mut state = CrossState::default();
        state.internal.s1_switch.on = Flags::empty().with(S1SwitchOn::LoadOnSource1);
        state.internal.s1.alarm = Flags::empty().with(S1Alarm::Failure);
        let text = state.to_string();
        assert!(
            text.contains("load: supplied by source 1 (S1) through static switch S1-SW"),
            "{text}"
        );
        assert!(text.contains("alarms: S1 failure"), "{text}");
        assert!(text.contains("0.00 Hz"), "{text}");
    }
}
