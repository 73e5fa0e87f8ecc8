//! Words of named state bits: the six operating conditions (words 0x00–0x11).
//!
//! Each condition has three words, at consecutive addresses: off state, alarm state, on
//! state. A bit is 1 when active; bits the manual marks reserved are kept (a device may
//! set them) but have no name.

use std::fmt;
use std::marker::PhantomData;

/// A named bit of one state word.
pub trait NamedBit: Copy + Eq + fmt::Debug + 'static {
    /// Every named bit of the word, lowest first.
    const ALL: &'static [Self];
    /// The bit's position, 0–15.
    fn bit(self) -> u8;
    /// What the bit means when it is 1, in the manual's words.
    fn describe(self) -> &'static str;
}

/// A 16-bit state word whose bits are named by `B`.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct Flags<B> {
    word: u16,
    bits: PhantomData<fn() -> B>,
}

impl<B: NamedBit> Flags<B> {
    /// No bit set.
    pub const fn empty() -> Self {
        Self {
            word: 0,
            bits: PhantomData,
        }
    }

    /// The word as read from the device, reserved bits included.
    pub const fn from_word(word: u16) -> Self {
        Self {
            word,
            bits: PhantomData,
        }
    }

    /// The word as the device sends it.
    pub const fn word(self) -> u16 {
        self.word
    }

    /// Whether `bit` is set.
    pub fn contains(self, bit: B) -> bool {
        self.word & mask(bit) != 0
    }

    /// Sets or clears `bit`.
    pub fn set(&mut self, bit: B, on: bool) {
        if on {
            self.word |= mask(bit);
        } else {
            self.word &= !mask(bit);
        }
    }

    /// The word with `bit` set too.
    pub fn with(mut self, bit: B) -> Self {
        self.set(bit, true);
        self
    }

    /// The named bits that are set, lowest first.
    pub fn active(self) -> impl Iterator<Item = B> {
        B::ALL.iter().copied().filter(move |&b| self.contains(b))
    }

    /// Whether no named bit is set (reserved bits are not looked at).
    pub fn is_clear(self) -> bool {
        self.active().next().is_none()
    }

    /// The reserved bits that are set (the manual says: don't care).
    pub fn reserved(self) -> u16 {
        self.word & !B::ALL.iter().fold(0, |m, &b| m | mask(b))
    }
}

impl<B: NamedBit> Default for Flags<B> {
    fn default() -> Self {
        Self::empty()
    }
}

impl<B: NamedBit> FromIterator<B> for Flags<B> {
    fn from_iter<I: IntoIterator<Item = B>>(iter: I) -> Self {
        iter.into_iter().fold(Self::empty(), Self::with)
    }
}

impl<B: NamedBit> fmt::Debug for Flags<B> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut list = f.debug_set();
        list.entries(self.active());
        if self.reserved() != 0 {
            list.entry(&format_args!("reserved 0x{:04X}", self.reserved()));
        }
        list.finish()
    }
}

/// The descriptions of the set bits, separated by commas, or "none".
impl<B: NamedBit> fmt::Display for Flags<B> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut first = true;
        for bit in self.active() {
            if !first {
                f.write_str(", ")?;
            }
            f.write_str(bit.describe())?;
            first = false;
        }
        if first {
            f.write_str("none")?;
        }
        Ok(())
    }
}

fn mask<B: NamedBit>(bit: B) -> u16 {
    1u16.checked_shl(bit.bit().into()).unwrap_or(0)
}

/// Defines an enum of named bits.
macro_rules! named_bits {
    ($(#[$doc:meta])* $name:ident { $($variant:ident = $bit:literal => $text:literal,)* }) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum $name {
            $(#[doc = concat!("Bit ", stringify!($bit), ": ", $text, ".")] $variant,)*
        }

        impl $crate::cross::bits::NamedBit for $name {
            const ALL: &'static [Self] = &[$(Self::$variant),*];
            fn bit(self) -> u8 {
                match self { $(Self::$variant => $bit,)* }
            }
            fn describe(self) -> &'static str {
                match self { $(Self::$variant => $text,)* }
            }
        }

        impl std::fmt::Display for $name {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str($crate::cross::bits::NamedBit::describe(*self))
            }
        }
    };
}
pub(crate) use named_bits;

/// A word with no named bits (the SYSTEM off-state word is all reserved).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum NoBits {}

impl NamedBit for NoBits {
    const ALL: &'static [Self] = &[];
    fn bit(self) -> u8 {
        match self {}
    }
    fn describe(self) -> &'static str {
        match self {}
    }
}

/// One operating condition: its off-state, alarm-state and on-state words.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Condition<Off: NamedBit, Alarm: NamedBit, On: NamedBit> {
    /// Off-state word (first address).
    pub off: Flags<Off>,
    /// Alarm-state word (second address).
    pub alarm: Flags<Alarm>,
    /// On-state word (third address).
    pub on: Flags<On>,
}

impl<Off: NamedBit, Alarm: NamedBit, On: NamedBit> Condition<Off, Alarm, On> {
    /// From the three words as read, off first.
    pub const fn from_words(words: [u16; 3]) -> Self {
        Self {
            off: Flags::from_word(words[0]),
            alarm: Flags::from_word(words[1]),
            on: Flags::from_word(words[2]),
        }
    }

    /// The three words as the device sends them, off first.
    pub const fn to_words(&self) -> [u16; 3] {
        [self.off.word(), self.alarm.word(), self.on.word()]
    }
}

impl<Off: NamedBit, Alarm: NamedBit, On: NamedBit> Default for Condition<Off, Alarm, On> {
    fn default() -> Self {
        Self {
            off: Flags::empty(),
            alarm: Flags::empty(),
            on: Flags::empty(),
        }
    }
}

named_bits!(
    /// S1 off-state word (0x00).
    S1Off {
        BreakerOpen = 0 => "S1 breaker open",
    }
);
named_bits!(
    /// S1 alarm-state word (0x01).
    S1Alarm {
        Failure = 0 => "S1 failure",
        FrequencyFault = 1 => "S1 frequency fault",
        VoltageFault = 2 => "S1 voltage fault",
        WrongPhaseRotation = 3 => "S1 wrong phase rotation",
        ExternalFailure = 4 => "external S1 failure",
        TrippingCoilActive = 5 => "S1 tripping coil active",
    }
);
named_bits!(
    /// S1 on-state word (0x02).
    S1On {
        Normal = 0 => "S1 normal",
    }
);
named_bits!(
    /// S2 off-state word (0x03).
    S2Off {
        BreakerOpen = 0 => "S2 breaker open",
    }
);
named_bits!(
    /// S2 alarm-state word (0x04).
    S2Alarm {
        Failure = 0 => "S2 failure",
        FrequencyFault = 1 => "S2 frequency fault",
        VoltageFault = 2 => "S2 voltage fault",
        WrongPhaseRotation = 3 => "S2 wrong phase rotation",
        ExternalFailure = 4 => "external S2 failure",
        TrippingCoilActive = 5 => "S2 tripping coil active",
    }
);
named_bits!(
    /// S2 on-state word (0x05).
    S2On {
        Normal = 0 => "S2 normal",
    }
);
named_bits!(
    /// S1 static switch (S1-SW) off-state word (0x06).
    S1SwitchOff {
        LoadOnSource2 = 0 => "load on source 2",
    }
);
named_bits!(
    /// S1 static switch (S1-SW) alarm-state word (0x07). The SCR-short bits put the S1-SW
    /// mimic lamp on alarm only while source 2 supplies the load.
    S1SwitchAlarm {
        ScrOpen = 0 => "S1 SCR open",
        NeutralScrOpen = 1 => "S1 neutral SCR open",
        PhaseScrShort = 2 => "S1 phase SCR short",
        NeutralScrShort = 3 => "S1 neutral SCR short",
    }
);
named_bits!(
    /// S1 static switch (S1-SW) on-state word (0x08).
    S1SwitchOn {
        LoadOnSource1 = 0 => "load on source 1",
        PhaseOverheating = 1 => "S1 phase overheating",
        NeutralOverheating = 2 => "S1 neutral overheating",
        PhaseScrShort = 3 => "S1 phase SCR short",
        NeutralScrShort = 4 => "S1 neutral SCR short",
        NeutralOvercurrent = 5 => "S1 neutral overcurrent",
        SourceOverload = 6 => "S1 source overload",
    }
);
named_bits!(
    /// S2 static switch (S2-SW) off-state word (0x09).
    S2SwitchOff {
        LoadOnSource1 = 0 => "load on source 1",
    }
);
named_bits!(
    /// S2 static switch (S2-SW) alarm-state word (0x0A). The SCR-short bits put the S2-SW
    /// mimic lamp on alarm only while source 1 supplies the load.
    S2SwitchAlarm {
        ScrOpen = 0 => "S2 SCR open",
        NeutralScrOpen = 1 => "S2 neutral SCR open",
        PhaseScrShort = 2 => "S2 phase SCR short",
        NeutralScrShort = 3 => "S2 neutral SCR short",
    }
);
named_bits!(
    /// S2 static switch (S2-SW) on-state word (0x0B).
    S2SwitchOn {
        LoadOnSource2 = 0 => "load on source 2",
        PhaseOverheating = 1 => "S2 phase overheating",
        NeutralOverheating = 2 => "S2 neutral overheating",
        PhaseScrShort = 3 => "S2 phase SCR short",
        NeutralScrShort = 4 => "S2 neutral SCR short",
        NeutralOvercurrent = 5 => "S2 neutral overcurrent",
        SourceOverload = 6 => "S2 source overload",
    }
);
named_bits!(
    /// LOAD off-state word (0x0C).
    LoadOff {
        OutputBreakerOpen = 0 => "output breaker open",
    }
);
named_bits!(
    /// LOAD alarm-state word (0x0D).
    LoadAlarm {
        NotSupplied = 0 => "load not supplied",
    }
);
named_bits!(
    /// LOAD on-state word (0x0E).
    LoadOn {
        OutputNormal = 0 => "output normal",
        OnReserveLine = 1 => "load on reserve line",
        OutputOverload = 2 => "output overload",
        OverloadTimeout = 3 => "overload time out",
        OnBadSource = 4 => "load on bad source",
    }
);
named_bits!(
    /// SYSTEM alarm-state word (0x10).
    SystemAlarm {
        EpoActive = 0 => "emergency power off (E.P.O.) active",
        SourcesOutOfSync = 1 => "sources out of synchronisation",
        PreferredOvercurrentInhibit = 2 => "preferred source overcurrent inhibit",
        ReserveOvercurrentInhibit = 3 => "reserve source overcurrent inhibit",
        ExternalSourceSelection = 4 => "external source selection switch",
        ExternalPreferredFailure = 5 => "external preferred source failure",
        ExternalReserveFailure = 6 => "external reserve source failure",
        ExternalTransferInhibit = 7 => "external transfer inhibit",
        ExternalCommandConflict = 8 => "external command conflict",
        Overcurrent = 9 => "overcurrent",
        TransferInhibit = 10 => "transfer inhibit",
        DataSetupLost = 11 => "data setup lost",
        AuxPowerFailure = 12 => "auxiliary power failure",
        BypassS1Closed = 13 => "bypass S1 closed",
        BypassS2Closed = 14 => "bypass S2 closed",
    }
);
named_bits!(
    /// SYSTEM on-state word (0x11).
    SystemOn {
        Normal = 0 => "system normal",
        ManualCommandEnabled = 1 => "manual command enabled",
        ControlOverride = 2 => "control override",
        EpoTestEnabled = 3 => "E.P.O. test enabled",
    }
);

/// S1 operating condition (words 0x00–0x02).
pub type S1Condition = Condition<S1Off, S1Alarm, S1On>;
/// S2 operating condition (words 0x03–0x05).
pub type S2Condition = Condition<S2Off, S2Alarm, S2On>;
/// S1 static switch operating condition (words 0x06–0x08).
pub type S1SwitchCondition = Condition<S1SwitchOff, S1SwitchAlarm, S1SwitchOn>;
/// S2 static switch operating condition (words 0x09–0x0B).
pub type S2SwitchCondition = Condition<S2SwitchOff, S2SwitchAlarm, S2SwitchOn>;
/// LOAD operating condition (words 0x0C–0x0E).
pub type LoadCondition = Condition<LoadOff, LoadAlarm, LoadOn>;
/// SYSTEM operating condition (words 0x0F–0x11; the off word has no named bit).
pub type SystemCondition = Condition<NoBits, SystemAlarm, SystemOn>;

/// The internal-state area (words 0x00–0x11): the six operating conditions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct InternalState {
    /// Source 1.
    pub s1: S1Condition,
    /// Source 2.
    pub s2: S2Condition,
    /// Static switch of source 1.
    pub s1_switch: S1SwitchCondition,
    /// Static switch of source 2.
    pub s2_switch: S2SwitchCondition,
    /// The load (output).
    pub load: LoadCondition,
    /// The system.
    pub system: SystemCondition,
}

impl InternalState {
    /// Number of words in the area.
    pub const LEN: usize = 18;

    /// From the area's 18 words (0x00–0x11).
    pub fn from_words(words: &[u16; Self::LEN]) -> Self {
        let three = |at: usize| [words[at], words[at + 1], words[at + 2]];
        Self {
            s1: Condition::from_words(three(0)),
            s2: Condition::from_words(three(3)),
            s1_switch: Condition::from_words(three(6)),
            s2_switch: Condition::from_words(three(9)),
            load: Condition::from_words(three(12)),
            system: Condition::from_words(three(15)),
        }
    }

    /// The area's 18 words.
    pub fn to_words(&self) -> [u16; Self::LEN] {
        let parts = [
            self.s1.to_words(),
            self.s2.to_words(),
            self.s1_switch.to_words(),
            self.s2_switch.to_words(),
            self.load.to_words(),
            self.system.to_words(),
        ];
        let mut words = [0; Self::LEN];
        for (slot, word) in words.iter_mut().zip(parts.iter().flatten()) {
            *slot = *word;
        }
        words
    }

    /// Descriptions of every active alarm bit (the five alarm words), in address order.
    pub fn alarms(&self) -> Vec<&'static str> {
        let mut out = Vec::new();
        out.extend(self.s1.alarm.active().map(NamedBit::describe));
        out.extend(self.s2.alarm.active().map(NamedBit::describe));
        out.extend(self.s1_switch.alarm.active().map(NamedBit::describe));
        out.extend(self.s2_switch.alarm.active().map(NamedBit::describe));
        out.extend(self.load.alarm.active().map(NamedBit::describe));
        out.extend(self.system.alarm.active().map(NamedBit::describe));
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flags_name_the_set_bits_and_keep_reserved_ones() {
        let alarm = Flags::<S1Alarm>::from_word(0b1000_0000_0000_0101);
        assert!(alarm.contains(S1Alarm::Failure));
        assert!(alarm.contains(S1Alarm::VoltageFault));
        assert!(!alarm.contains(S1Alarm::FrequencyFault));
        assert_eq!(
            alarm.active().collect::<Vec<_>>(),
            vec![S1Alarm::Failure, S1Alarm::VoltageFault]
        );
        assert_eq!(alarm.reserved(), 0x8000);
        assert_eq!(alarm.to_string(), "S1 failure, S1 voltage fault");
        assert_eq!(Flags::<S1Alarm>::empty().to_string(), "none");
    }

    #[test]
    fn every_named_bit_has_its_own_position() {
        fn distinct<B: NamedBit>() {
            let mut seen = 0u16;
            for &b in B::ALL {
                assert!(b.bit() < 16);
                assert_eq!(seen & (1 << b.bit()), 0, "{b:?}");
                seen |= 1 << b.bit();
            }
        }
        distinct::<S1Alarm>();
        distinct::<S2Alarm>();
        distinct::<S1SwitchOn>();
        distinct::<S2SwitchOn>();
        distinct::<S1SwitchAlarm>();
        distinct::<LoadOn>();
        distinct::<SystemAlarm>();
        distinct::<SystemOn>();
        assert_eq!(SystemAlarm::ALL.len(), 15);
        assert_eq!(SystemAlarm::BypassS2Closed.bit(), 14);
    }

    #[test]
    fn internal_state_words_round_trip_in_address_order() {
        let words: [u16; 18] = std::array::from_fn(|i| i as u16 * 3 + 1);
        let state = InternalState::from_words(&words);
        assert_eq!(state.s2.off.word(), words[3]);
        assert_eq!(state.system.on.word(), words[17]);
        assert_eq!(state.to_words(), words);
    }
}
