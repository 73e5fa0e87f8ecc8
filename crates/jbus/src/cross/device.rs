//! A twin of a Chloride CROSS static transfer switch, for tests and the simulator.
//!
//! Two three-phase sources (230 V, 50 Hz) feed one load through two static switches
//! (S1-SW, S2-SW); each source has an input breaker (IS1, IS2) and a manual bypass (IBY1,
//! IBY2); the output breaker (IOUT) connects the load. The preferred source feeds the load
//! while it is healthy. [`CrossTwin::fail_source`] takes a source away: if it was feeding
//! the load, the twin transfers the load to the other source at once, and retransfers it
//! when [`CrossTwin::restore_source`] brings the preferred source back. Every reading is
//! computed from that physical state, so state words, mimic lamps, segments and measures
//! always agree; measures carry seeded noise (about ±0.4 % on voltages, ±0.02 Hz).
//!
//! The twin answers as the manual says and nothing more: function 3 on defined addresses;
//! any other function gets exception 1, a read touching an undefined address exception 2,
//! a count of 0 or above 125 exception 3 (checked before the addresses, as Modbus orders
//! it); a frame with a bad CRC, for another unit or broadcast (unit 0) gets silence, as
//! does a request whose function byte has the exception bit set (no valid answer exists).
//! Answers leave [`REPLY_DELAY`] after the request.
//!
//! The manual's picture of the mimic diagram is lost, so the twin numbers its segments
//! along the circuit, as follows (a segment is lit while energised):
//!
//! | segment | part of the circuit |
//! |---|---|
//! | 1 / 6 | S1 / S2 incoming line (the source has voltage) |
//! | 2 / 7 | from IS1 / IS2 to the static switch (input breaker closed) |
//! | 3 / 8 | from S1-SW / S2-SW to the output bus (the switch conducts) |
//! | 4 / 9 | S1 / S2 bypass line up to IBY1 / IBY2 |
//! | 5 / 10 | from IBY1 / IBY2 to the output bus (bypass closed) |
//! | 11 / 12 | output bus on the S1 / S2 side (fed by segment 3 or 5 / 8 or 10) |
//! | 13 | output bus up to IOUT |
//! | 14 | from IOUT to the load (output breaker closed) |
//! | 15 | the load (it draws power) |

use std::fmt;
use std::time::{Duration, Instant};

use wire::Transmit;
use wire::device::Model;

use super::bits::{
    InternalState, LoadAlarm, LoadOff, LoadOn, S1Alarm, S1Off, S1On, S1SwitchOff, S1SwitchOn,
    S2Alarm, S2Off, S2On, S2SwitchOff, S2SwitchOn, SystemAlarm, SystemOn,
};
use super::map::{MAP_LEN, block_is_defined};
use super::measure::{
    Amperes, Celsius, Degrees, Hertz, KiloVoltAmperes, Measures, Phases, Ratings, Volts,
    WholeAmperes,
};
use super::mimic::{Element, Lamps, Mimic, Segment, Segments};
use super::state::{CrossState, Source};
use crate::rtu::{
    DecodeError, EXCEPTION_BIT, ExceptionCode, FunctionCode, RegisterValues, Request, RequestAdu,
    RequestCodec, RequestPdu, Response, UnitId,
};

/// How long after a request the twin's answer leaves: 5 ms, the order of a small
/// controller's turnaround (the manual gives none).
pub const REPLY_DELAY: Duration = Duration::from_millis(5);

/// How long an output overload lasts before the LOAD "overload time out" bit comes on.
pub const OVERLOAD_TIMEOUT: Duration = Duration::from_secs(60);

/// The JBUS protocol revision the twin reports (word 0x2E): the manual's.
pub const PROTOCOL_REVISION: u16 = 5;

/// Nominal phase voltage of both sources, in volts.
pub const NOMINAL_VOLTAGE: f64 = 230.0;
/// Nominal frequency of both sources, in hertz.
pub const NOMINAL_FREQUENCY: f64 = 50.0;
/// Rated current of the twin, in amperes (word 0x1E).
pub const RATED_CURRENT: f64 = 100.0;

/// How a source fails.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SourceFault {
    /// No voltage at all (alarms: failure, voltage fault).
    Outage,
    /// Voltage well below tolerance, about 180 V (alarms: failure, voltage fault).
    Undervoltage,
    /// Frequency out of tolerance, about 47 Hz (alarms: failure, frequency fault).
    FrequencyDrift,
}

/// A breaker or bypass of the switch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Breaker {
    /// IS1: source 1 input breaker (closed by default).
    Is1,
    /// IS2: source 2 input breaker (closed by default).
    Is2,
    /// IBY1: source 1 manual bypass (open by default).
    Iby1,
    /// IBY2: source 2 manual bypass (open by default).
    Iby2,
    /// IOUT: output breaker (closed by default).
    Iout,
}

impl Breaker {
    const fn index(self) -> usize {
        match self {
            Self::Is1 => 0,
            Self::Is2 => 1,
            Self::Iby1 => 2,
            Self::Iby2 => 3,
            Self::Iout => 4,
        }
    }

    const fn input(source: Source) -> Self {
        match source {
            Source::S1 => Self::Is1,
            Source::S2 => Self::Is2,
        }
    }

    const fn bypass(source: Source) -> Self {
        match source {
            Source::S1 => Self::Iby1,
            Source::S2 => Self::Iby2,
        }
    }
}

impl fmt::Display for Breaker {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Is1 => "IS1",
            Self::Is2 => "IS2",
            Self::Iby1 => "IBY1",
            Self::Iby2 => "IBY2",
            Self::Iout => "IOUT",
        })
    }
}

/// A simulated CROSS on one unit number.
#[derive(Debug, Clone)]
pub struct CrossTwin {
    unit: UnitId,
    rng: fastrand::Rng,
    reply_delay: Duration,
    preferred: Source,
    faults: [Option<SourceFault>; 2],
    closed: [bool; 5],
    load_kva: f64,
    conducting: Option<Source>,
    transfers: u64,
    overload_since: Option<Instant>,
}

impl CrossTwin {
    /// A healthy switch answering as `unit` (JBUS numbers up to 255 allowed), with noise
    /// seeded by `seed`: S1 preferred and feeding a 40 kVA load, input and output breakers
    /// closed, bypasses open.
    pub fn new(unit: UnitId, seed: u64) -> Self {
        let mut twin = Self {
            unit,
            rng: fastrand::Rng::with_seed(seed),
            reply_delay: REPLY_DELAY,
            preferred: Source::S1,
            faults: [None, None],
            closed: [true, true, false, false, true],
            load_kva: 40.0,
            conducting: None,
            transfers: 0,
            overload_since: None,
        };
        twin.settle();
        twin
    }

    /// The same twin answering after `delay` instead of [`REPLY_DELAY`].
    pub fn with_reply_delay(mut self, delay: Duration) -> Self {
        self.reply_delay = delay;
        self
    }

    /// The unit number it answers to.
    pub fn unit(&self) -> UnitId {
        self.unit
    }

    /// The preferred source.
    pub fn preferred(&self) -> Source {
        self.preferred
    }

    /// Makes `source` the preferred one; the load moves to it if it is healthy.
    pub fn set_preferred(&mut self, source: Source) {
        self.preferred = source;
        self.settle();
    }

    /// Takes `source` away (an outage); the load transfers if it was on it.
    pub fn fail_source(&mut self, source: Source) {
        self.fail_source_with(source, SourceFault::Outage);
    }

    /// Makes `source` fail in the given way; the load transfers if it was on it and the
    /// other source is healthy (else it stays on a source that still has voltage: "load on
    /// bad source").
    pub fn fail_source_with(&mut self, source: Source, fault: SourceFault) {
        self.faults[source.index()] = Some(fault);
        self.settle();
    }

    /// Brings `source` back; the load retransfers to it if it is the preferred source.
    pub fn restore_source(&mut self, source: Source) {
        self.faults[source.index()] = None;
        self.settle();
    }

    /// The fault of `source`, if it has one.
    pub fn fault(&self, source: Source) -> Option<SourceFault> {
        self.faults[source.index()]
    }

    /// Opens or closes a breaker or bypass; the load transfers if its source's input
    /// breaker opens.
    pub fn set_breaker(&mut self, breaker: Breaker, closed: bool) {
        self.closed[breaker.index()] = closed;
        self.settle();
    }

    /// Whether a breaker or bypass is closed.
    pub fn is_closed(&self, breaker: Breaker) -> bool {
        self.closed[breaker.index()]
    }

    /// Sets the load's apparent power in kVA (negative counts as 0). The twin's rating is
    /// 100 A per phase, about 69 kVA.
    pub fn set_load(&mut self, kva: f64) {
        self.load_kva = if kva.is_finite() { kva.max(0.0) } else { 0.0 };
    }

    /// The source whose static switch conducts, if any.
    pub fn conducting(&self) -> Option<Source> {
        self.conducting
    }

    /// How many times the load moved from one source to the other.
    pub fn transfers(&self) -> u64 {
        self.transfers
    }

    /// A fresh reading of every word at `now`, noise included (each call draws new noise).
    pub fn reading(&mut self, now: Instant) -> CrossState {
        let measures = self.measure();
        let overload = self.output_current_overload(&measures);
        self.overload_since = match (overload, self.overload_since) {
            (true, None) => Some(now),
            (true, since) => since,
            (false, _) => None,
        };
        let overload_timed_out = self
            .overload_since
            .is_some_and(|since| now.saturating_duration_since(since) >= OVERLOAD_TIMEOUT);
        let internal = self.internal_state(overload, overload_timed_out);
        let mimic = self.mimic(&internal);
        CrossState {
            internal,
            mimic,
            ratings: Self::ratings(),
            measures,
        }
    }

    /// The answer to a request for this unit, or `None` for silence.
    pub fn answer(&mut self, pdu: &RequestPdu, now: Instant) -> Option<Response> {
        let function = pdu.function_byte();
        if function & EXCEPTION_BIT != 0 {
            return None;
        }
        let refuse = |code| {
            Some(Response::exception(
                FunctionCode::of_exception(function),
                code,
            ))
        };
        if !matches!(pdu, RequestPdu::ReadHoldingRegisters { .. }) {
            return refuse(ExceptionCode::ILLEGAL_FUNCTION);
        }
        let read = match pdu.to_request() {
            Ok(Request::ReadHoldingRegisters(read)) => read,
            Ok(_) => return refuse(ExceptionCode::ILLEGAL_FUNCTION),
            Err(code) => return refuse(code),
        };
        let (start, count) = (read.address(), read.count().get());
        if !block_is_defined(start, count) {
            return refuse(ExceptionCode::ILLEGAL_DATA_ADDRESS);
        }
        let image = self.reading(now).to_image();
        let words = image
            .get(usize::from(start)..usize::from(start) + usize::from(count))?
            .to_vec();
        RegisterValues::new(words)
            .ok()
            .map(Response::ReadHoldingRegisters)
    }

    // --- The physics ---

    /// Whether `source` can take the load: healthy, input breaker closed.
    fn usable(&self, source: Source) -> bool {
        self.faults[source.index()].is_none() && self.is_closed(Breaker::input(source))
    }

    /// Whether `source` has voltage at all.
    fn has_voltage(&self, source: Source) -> bool {
        self.faults[source.index()] != Some(SourceFault::Outage)
    }

    /// Whether `source` can keep a load it already has: voltage present, breaker closed.
    fn live(&self, source: Source) -> bool {
        self.has_voltage(source) && self.is_closed(Breaker::input(source))
    }

    /// Moves the load to where the switch's logic puts it after any change.
    fn settle(&mut self) {
        let (preferred, reserve) = (self.preferred, self.preferred.other());
        let target = match self.conducting {
            Some(s) if self.usable(s) => Some(if s != preferred && self.usable(preferred) {
                preferred
            } else {
                s
            }),
            Some(s) if self.usable(s.other()) => Some(s.other()),
            Some(s) if self.live(s) => Some(s),
            _ if self.usable(preferred) => Some(preferred),
            _ if self.usable(reserve) => Some(reserve),
            _ => None,
        };
        if let (Some(from), Some(to)) = (self.conducting, target)
            && from != to
        {
            self.transfers += 1;
        }
        self.conducting = target;
    }

    /// The source feeding the output bus, and through what: a closed bypass on a source
    /// with voltage takes precedence over the static switches.
    fn feeding(&self) -> Option<Source> {
        [Source::S1, Source::S2]
            .into_iter()
            .find(|&s| self.is_closed(Breaker::bypass(s)) && self.has_voltage(s))
            .or(self.conducting)
    }

    /// Whether the load draws power: something feeds the bus and IOUT is closed.
    fn supplied(&self) -> bool {
        self.feeding().is_some() && self.is_closed(Breaker::Iout)
    }

    fn noise(&mut self, amplitude: f64) -> f64 {
        (self.rng.f64() * 2.0 - 1.0) * amplitude
    }

    fn source_voltage(&mut self, source: Source) -> [f64; 3] {
        let level = match self.faults[source.index()] {
            None | Some(SourceFault::FrequencyDrift) => NOMINAL_VOLTAGE,
            Some(SourceFault::Undervoltage) => NOMINAL_VOLTAGE * 0.78,
            Some(SourceFault::Outage) => return [0.0; 3],
        };
        std::array::from_fn(|_| level * (1.0 + self.noise(0.004)))
    }

    fn source_frequency(&mut self, source: Source) -> f64 {
        match self.faults[source.index()] {
            None | Some(SourceFault::Undervoltage) => NOMINAL_FREQUENCY + self.noise(0.02),
            Some(SourceFault::FrequencyDrift) => 47.0 + self.noise(0.05),
            Some(SourceFault::Outage) => 0.0,
        }
    }

    fn measure(&mut self) -> Measures {
        let volts = [
            self.source_voltage(Source::S1),
            self.source_voltage(Source::S2),
        ];
        let hertz = [
            self.source_frequency(Source::S1),
            self.source_frequency(Source::S2),
        ];
        let (bus_volts, bus_hertz) = match self.feeding() {
            Some(s) => (volts[s.index()].map(|v| v * 0.998), hertz[s.index()]),
            None => ([0.0; 3], 0.0),
        };
        let amps = if self.supplied() {
            let per_phase = self.load_kva * 1000.0 / 3.0;
            let mut amps = [0.0; 3];
            for (a, v) in amps.iter_mut().zip(bus_volts) {
                *a = if v > 1.0 {
                    per_phase / v * (1.0 + self.noise(0.03))
                } else {
                    0.0
                };
            }
            amps
        } else {
            [0.0; 3]
        };
        let kva: f64 = bus_volts.iter().zip(amps).map(|(v, a)| v * a).sum::<f64>() / 1000.0;
        let neutral_amps = if self.supplied() {
            (amps.iter().sum::<f64>() / 3.0 * 0.04 + self.noise(0.3)).max(0.0)
        } else {
            0.0
        };
        let neutral_volts = if self.supplied() {
            (0.4 + self.noise(0.2)).max(0.0)
        } else {
            0.0
        };
        let phase_error = match self.faults {
            [
                None | Some(SourceFault::Undervoltage),
                None | Some(SourceFault::Undervoltage),
            ] => 0.3 + self.noise(1.2),
            [Some(SourceFault::FrequencyDrift), _] | [_, Some(SourceFault::FrequencyDrift)] => {
                self.noise(180.0)
            }
            _ => 0.0,
        };
        let inlet_air = 23.0 + 6.0 * (self.load_kva / Self::rated_kva()).min(2.0) + self.noise(0.3);
        let phases_of = |values: [f64; 3]| Phases {
            u: Volts::from_value(values[0]),
            v: Volts::from_value(values[1]),
            w: Volts::from_value(values[2]),
        };
        Measures {
            s1_voltage: phases_of(volts[0]),
            s1_frequency: Hertz::from_value(hertz[0]),
            s2_voltage: phases_of(volts[1]),
            s2_frequency: Hertz::from_value(hertz[1]),
            output_voltage: phases_of(bus_volts),
            output_current: Phases {
                u: Amperes::from_value(amps[0]),
                v: Amperes::from_value(amps[1]),
                w: Amperes::from_value(amps[2]),
            },
            neutral_current: Amperes::from_value(neutral_amps),
            neutral_voltage: Volts::from_value(neutral_volts),
            output_frequency: Hertz::from_value(bus_hertz),
            load_power: KiloVoltAmperes::from_value(kva),
            phase_error: Degrees::from_value(phase_error),
            inlet_air: Celsius::from_value(inlet_air),
        }
    }

    fn rated_kva() -> f64 {
        3.0 * NOMINAL_VOLTAGE * RATED_CURRENT / 1000.0
    }

    fn output_current_overload(&self, measures: &Measures) -> bool {
        let rated = Amperes::from_value(RATED_CURRENT);
        measures
            .output_current
            .to_array()
            .iter()
            .any(|&a| a > rated)
    }

    fn ratings() -> Ratings {
        Ratings {
            rated_current: Amperes::from_value(RATED_CURRENT),
            s1_voltage_full_scale: Phases::all(Volts::from_value(300.0)),
            s2_voltage_full_scale: Phases::all(Volts::from_value(300.0)),
            output_voltage_full_scale: Phases::all(Volts::from_value(300.0)),
            output_current_full_scale: Phases::all(WholeAmperes::from_value(150.0)),
            neutral_current_full_scale: WholeAmperes::from_value(150.0),
            neutral_voltage_full_scale: Volts::from_value(50.0),
            inlet_air_full_scale: Celsius::from_value(100.0),
            protocol_revision: PROTOCOL_REVISION,
        }
    }

    fn internal_state(&self, overload: bool, overload_timed_out: bool) -> InternalState {
        let mut s = InternalState::default();
        let fault_bits = |fault: Option<SourceFault>| match fault {
            None => (false, false, false),
            Some(SourceFault::Outage | SourceFault::Undervoltage) => (true, false, true),
            Some(SourceFault::FrequencyDrift) => (true, true, false),
        };

        let (failure, frequency, voltage) = fault_bits(self.faults[0]);
        s.s1.off
            .set(S1Off::BreakerOpen, !self.is_closed(Breaker::Is1));
        s.s1.alarm.set(S1Alarm::Failure, failure);
        s.s1.alarm.set(S1Alarm::FrequencyFault, frequency);
        s.s1.alarm.set(S1Alarm::VoltageFault, voltage);
        s.s1.on.set(S1On::Normal, !failure);

        let (failure, frequency, voltage) = fault_bits(self.faults[1]);
        s.s2.off
            .set(S2Off::BreakerOpen, !self.is_closed(Breaker::Is2));
        s.s2.alarm.set(S2Alarm::Failure, failure);
        s.s2.alarm.set(S2Alarm::FrequencyFault, frequency);
        s.s2.alarm.set(S2Alarm::VoltageFault, voltage);
        s.s2.on.set(S2On::Normal, !failure);

        let on = |source| self.conducting == Some(source);
        s.s1_switch
            .off
            .set(S1SwitchOff::LoadOnSource2, on(Source::S2));
        s.s1_switch
            .on
            .set(S1SwitchOn::LoadOnSource1, on(Source::S1));
        s.s1_switch
            .on
            .set(S1SwitchOn::SourceOverload, on(Source::S1) && overload);
        s.s2_switch
            .off
            .set(S2SwitchOff::LoadOnSource1, on(Source::S1));
        s.s2_switch
            .on
            .set(S2SwitchOn::LoadOnSource2, on(Source::S2));
        s.s2_switch
            .on
            .set(S2SwitchOn::SourceOverload, on(Source::S2) && overload);

        let iout = self.is_closed(Breaker::Iout);
        let supplied = self.supplied();
        let bad_source = self
            .feeding()
            .is_some_and(|f| self.faults[f.index()].is_some());
        s.load.off.set(LoadOff::OutputBreakerOpen, !iout);
        s.load.alarm.set(LoadAlarm::NotSupplied, iout && !supplied);
        s.load.on.set(LoadOn::OutputNormal, supplied && !bad_source);
        s.load.on.set(
            LoadOn::OnReserveLine,
            supplied && self.feeding() != Some(self.preferred),
        );
        s.load.on.set(LoadOn::OutputOverload, supplied && overload);
        s.load
            .on
            .set(LoadOn::OverloadTimeout, supplied && overload_timed_out);
        s.load.on.set(LoadOn::OnBadSource, supplied && bad_source);

        s.system.alarm.set(
            SystemAlarm::SourcesOutOfSync,
            self.faults.iter().any(Option::is_some),
        );
        s.system
            .alarm
            .set(SystemAlarm::BypassS1Closed, self.is_closed(Breaker::Iby1));
        s.system
            .alarm
            .set(SystemAlarm::BypassS2Closed, self.is_closed(Breaker::Iby2));
        s.system.on.set(SystemOn::Normal, s.alarms().is_empty());
        s
    }

    fn mimic(&self, s: &InternalState) -> Mimic {
        let mut mimic = Mimic::default();
        let lamp = |on: bool, alarm: bool| Lamps {
            on: on && !alarm,
            off: !on && !alarm,
            alarm,
        };
        mimic.set_lamps(
            Element::S1,
            lamp(
                s.s1.on.contains(S1On::Normal) && self.is_closed(Breaker::Is1),
                !s.s1.alarm.is_clear(),
            ),
        );
        mimic.set_lamps(
            Element::S2,
            lamp(
                s.s2.on.contains(S2On::Normal) && self.is_closed(Breaker::Is2),
                !s.s2.alarm.is_clear(),
            ),
        );
        mimic.set_lamps(
            Element::S1Switch,
            lamp(
                self.conducting == Some(Source::S1),
                !s.s1_switch.alarm.is_clear(),
            ),
        );
        mimic.set_lamps(
            Element::S2Switch,
            lamp(
                self.conducting == Some(Source::S2),
                !s.s2_switch.alarm.is_clear(),
            ),
        );
        mimic.set_lamps(
            Element::Load,
            lamp(
                self.supplied(),
                s.load.alarm.contains(LoadAlarm::NotSupplied),
            ),
        );
        mimic.set_lamps(
            Element::System,
            lamp(
                s.system.on.contains(SystemOn::Normal),
                !s.system.alarm.is_clear(),
            ),
        );
        for (element, breaker) in [
            (Element::Is1, Breaker::Is1),
            (Element::Is2, Breaker::Is2),
            (Element::Iby1, Breaker::Iby1),
            (Element::Iby2, Breaker::Iby2),
            (Element::Iout, Breaker::Iout),
        ] {
            mimic.set_lamps(element, lamp(self.is_closed(breaker), false));
        }

        let mut lit = [false; 16];
        for (source, base) in [(Source::S1, 0), (Source::S2, 5)] {
            let incoming = self.has_voltage(source);
            lit[base + 1] = incoming;
            lit[base + 2] = incoming && self.is_closed(Breaker::input(source));
            lit[base + 3] = lit[base + 2] && self.conducting == Some(source);
            lit[base + 4] = incoming;
            lit[base + 5] = incoming && self.is_closed(Breaker::bypass(source));
        }
        lit[11] = lit[3] || lit[5];
        lit[12] = lit[8] || lit[10];
        lit[13] = lit[11] || lit[12];
        lit[14] = lit[13] && self.is_closed(Breaker::Iout);
        lit[15] = lit[14] && self.load_kva > 0.0;
        let mut segments = Segments::default();
        for segment in Segment::all() {
            segments.set(segment, lit[usize::from(segment.number())]);
        }
        mimic.segments = segments;
        mimic
    }

    /// The register image at `now` (words 0x00–0x59, undefined ones 0).
    pub fn image(&mut self, now: Instant) -> [u16; MAP_LEN] {
        self.reading(now).to_image()
    }
}

impl Model for CrossTwin {
    type Codec = RequestCodec;

    fn codec(&self) -> RequestCodec {
        RequestCodec
    }

    fn handle(&mut self, input: Result<RequestAdu, DecodeError>, now: Instant) -> Vec<Transmit> {
        // A bad CRC or bytes that frame nothing: the CROSS does not answer.
        let Ok(adu) = input else { return Vec::new() };
        // Broadcast (unit 0) or another unit's request: silence.
        if adu.unit != self.unit.get() {
            return Vec::new();
        }
        match self.answer(&adu.pdu, now) {
            Some(response) => crate::slave::reply(adu.unit, response, self.reply_delay),
            None => Vec::new(),
        }
    }
}

#[cfg(test)]
mod tests;
