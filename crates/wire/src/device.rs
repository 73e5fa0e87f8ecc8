//! The interface between a simulated device and the line that serves it.
//!
//! A simulator is a pure model: bytes in, replies out, time as a parameter. The `link`
//! crate's serve loop feeds it bytes from a TCP connection or a PTY and sends what it
//! returns after the delay it asks for. Nothing here reads a clock or touches the OS.
//!
//! Most devices are a [`Model`] that handles decoded frames; [`SharedModel::line`] gives
//! each connection its own [`Deframer`] in front of the one shared model, so two
//! connections to a simulator never mix their half frames. [`FaultInjector`] wraps any
//! device with seeded, reproducible line trouble.
//!
//! A real serial device forgets a half-received frame once the line has been quiet for its
//! inter-frame gap (3.5 characters for Modbus RTU), so one damaged request cannot make it
//! wait forever for bytes that never come. A [`ModelLine`] does the same: input that
//! arrives after a silence of [`Model::frame_gap`] (or the gap a user chose, see
//! [`LineTiming`]) starts afresh. The serve loop tells each device its line's timing once,
//! before any input ([`Device::set_timing`]).

use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

use crate::codec::{Codec, Deframer};

/// Bytes a device sends, `delay` after the input that caused them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Transmit {
    /// How long after the input the first byte leaves.
    pub delay: Duration,
    /// The bytes.
    pub bytes: Vec<u8>,
}

impl Transmit {
    /// Bytes to send at once.
    pub fn now(bytes: Vec<u8>) -> Self {
        Self {
            delay: Duration::ZERO,
            bytes,
        }
    }

    /// Bytes to send after `delay`.
    pub fn after(delay: Duration, bytes: Vec<u8>) -> Self {
        Self { delay, bytes }
    }
}

/// A simulated device as one line sees it.
pub trait Device: Send + 'static {
    /// Takes bytes received from the line at `now` and returns what to send.
    fn receive(&mut self, bytes: &[u8], now: Instant) -> Vec<Transmit>;

    /// The timing of the line the device is served on, told once before any input.
    /// A device that frames by silence chooses its gap from it; others ignore it.
    fn set_timing(&mut self, timing: LineTiming) {
        let _ = timing;
    }
}

/// How a device's line carries characters, for the gap after which a half frame is dropped.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LineTiming {
    /// The time one character takes on the line; `None` on an unpaced line (loopback TCP),
    /// where a frame's bytes arrive together.
    pub char_time: Option<Duration>,
    /// A gap the user chose (`cellbus sim --frame-gap`), instead of the protocol's.
    pub frame_gap: Option<Duration>,
}

impl LineTiming {
    /// A line whose characters take `char_time` each (`None`: unpaced).
    pub fn paced(char_time: Option<Duration>) -> Self {
        Self {
            char_time,
            frame_gap: None,
        }
    }
}

/// The gap after which a device on an unpaced line (loopback TCP, where a frame's bytes
/// arrive in one burst) drops a half-received frame, unless the user chose another.
pub const UNPACED_FRAME_GAP: Duration = Duration::from_millis(5);

/// Modbus RTU's inter-frame silence for a line whose characters take `char_time`: 3.5
/// characters, and a fixed 1.75 ms above 19200 baud (where 3.5 characters would be shorter
/// than UARTs and drivers can time), as the Modbus serial line guide says.
pub fn silence_3_5_chars(char_time: Duration) -> Duration {
    // 3.5 characters at 19200 baud and 11 bits per character.
    const FLOOR: Duration = Duration::from_micros(1750);
    (char_time * 7 / 2).max(FLOOR)
}

/// A device model that handles whole frames.
pub trait Model: Send + 'static {
    /// Decodes what arrives from the line.
    type Codec: Codec + Clone + Send + 'static;

    /// The codec for a new line.
    fn codec(&self) -> Self::Codec;

    /// How long the line must be quiet before a half-received frame is dropped, on a line
    /// whose characters take `char_time` (`None`: unpaced, see [`UNPACED_FRAME_GAP`]).
    /// By default Modbus RTU's rule, 3.5 characters ([`silence_3_5_chars`]).
    fn frame_gap(&self, char_time: Option<Duration>) -> Duration {
        char_time.map_or(UNPACED_FRAME_GAP, silence_3_5_chars)
    }

    /// Handles a decoded frame, or bytes the codec dropped, at `now`.
    fn handle(
        &mut self,
        input: Result<<Self::Codec as Codec>::Frame, <Self::Codec as Codec>::Error>,
        now: Instant,
    ) -> Vec<Transmit>;
}

/// One model shared by every line that reaches it (each TCP connection to a simulator is a
/// line to the same device).
#[derive(Debug)]
pub struct SharedModel<M>(Arc<Mutex<M>>);

impl<M> Clone for SharedModel<M> {
    fn clone(&self) -> Self {
        Self(Arc::clone(&self.0))
    }
}

impl<M: Model> SharedModel<M> {
    /// Shares `model`.
    pub fn new(model: M) -> Self {
        Self(Arc::new(Mutex::new(model)))
    }

    /// A new line to the model, with its own deframer, unpaced until told otherwise
    /// ([`Device::set_timing`]).
    pub fn line(&self) -> ModelLine<M> {
        let (codec, gap) = {
            let model = self.lock();
            (model.codec(), model.frame_gap(None))
        };
        ModelLine {
            model: self.clone(),
            deframer: Deframer::new(codec),
            gap,
            char_time: None,
            last_input: None,
            dropped_partial: 0,
        }
    }

    /// The model, for inspection or to provoke a fault from a test or a control channel.
    /// A panic while it was held does not make it unusable: the model is plain data.
    pub fn lock(&self) -> MutexGuard<'_, M> {
        self.0.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// A line to a [`SharedModel`].
#[derive(Debug)]
pub struct ModelLine<M: Model> {
    model: SharedModel<M>,
    deframer: Deframer<M::Codec>,
    /// Silence after which a half frame is dropped.
    gap: Duration,
    /// The time a character takes on a paced line: input is handed over when its last
    /// character has arrived, so its first one started this much earlier per byte.
    char_time: Option<Duration>,
    /// When the last input arrived.
    last_input: Option<Instant>,
    dropped_partial: u64,
}

impl<M: Model> ModelLine<M> {
    /// The silence after which this line drops a half-received frame.
    pub fn frame_gap(&self) -> Duration {
        self.gap
    }

    /// How many half frames were dropped after a silence.
    pub fn dropped_partial(&self) -> u64 {
        self.dropped_partial
    }
}

impl<M: Model> Device for ModelLine<M>
where
    <M::Codec as Codec>::Frame: Send,
    <M::Codec as Codec>::Error: Send,
{
    fn set_timing(&mut self, timing: LineTiming) {
        self.char_time = timing.char_time;
        self.gap = timing
            .frame_gap
            .unwrap_or_else(|| self.model.lock().frame_gap(timing.char_time));
    }

    fn receive(&mut self, bytes: &[u8], now: Instant) -> Vec<Transmit> {
        let wire = self.char_time.map_or(Duration::ZERO, |c| {
            c.saturating_mul(u32::try_from(bytes.len()).unwrap_or(u32::MAX))
        });
        let first_char = now.checked_sub(wire).unwrap_or(now);
        let quiet = self
            .last_input
            .is_some_and(|last| first_char.saturating_duration_since(last) >= self.gap);
        self.last_input = Some(now);
        if quiet && !self.deframer.buffered().is_empty() {
            // The line fell silent inside a frame: as a real device, forget it and
            // take what arrives now as the start of a new one.
            self.dropped_partial += 1;
            self.deframer.clear();
        }
        self.deframer.push(bytes);
        let mut out = Vec::new();
        while let Some(input) = self.deframer.next_frame() {
            out.extend(self.model.lock().handle(input, now));
        }
        out
    }
}

/// Several devices on one line (an RS-485 pair): each hears every byte, and their
/// replies go out as each asks.
pub struct Bus(pub Vec<Box<dyn Device>>);

impl Device for Bus {
    fn set_timing(&mut self, timing: LineTiming) {
        for device in &mut self.0 {
            device.set_timing(timing);
        }
    }

    fn receive(&mut self, bytes: &[u8], now: Instant) -> Vec<Transmit> {
        self.0
            .iter_mut()
            .flat_map(|device| device.receive(bytes, now))
            .collect()
    }
}

/// A device whose line drops half frames after a gap the user chose, whatever the line's
/// pace (`cellbus sim --frame-gap`); with no gap chosen, the protocol's.
#[derive(Debug, Clone)]
pub struct WithFrameGap<D> {
    inner: D,
    gap: Option<Duration>,
}

impl<D> WithFrameGap<D> {
    /// Wraps `inner`, whose half frames are then dropped after `gap` of silence (`None`:
    /// the protocol's gap for the line's pace).
    pub fn new(inner: D, gap: Option<Duration>) -> Self {
        Self { inner, gap }
    }
}

impl<D: Device> Device for WithFrameGap<D> {
    fn set_timing(&mut self, timing: LineTiming) {
        self.inner.set_timing(LineTiming {
            frame_gap: self.gap.or(timing.frame_gap),
            ..timing
        });
    }

    fn receive(&mut self, bytes: &[u8], now: Instant) -> Vec<Transmit> {
        self.inner.receive(bytes, now)
    }
}

/// A fault rate that is not a probability.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("fault rate {0} is not between 0 and 1")]
pub struct BadFaultRate(pub f64);

/// Seeded, reproducible line trouble between a device and its line: dropped replies,
/// late replies, flipped bits and garbage between frames. Each reply meets a fault with
/// probability `rate`; the same seed gives the same faults for the same traffic.
#[derive(Debug, Clone)]
pub struct FaultInjector<D> {
    inner: D,
    rate: f64,
    rng: fastrand::Rng,
    late_by: Duration,
    injected: FaultCounts,
}

/// How many faults of each kind were injected.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FaultCounts {
    /// Replies never sent.
    pub dropped: u64,
    /// Replies sent late.
    pub delayed: u64,
    /// Replies with one bit flipped.
    pub corrupted: u64,
    /// Replies preceded by random bytes.
    pub garbage: u64,
}

impl<D> FaultInjector<D> {
    /// Wraps `inner`; `rate` is the share of replies that meet a fault (0 = none).
    pub fn new(inner: D, seed: u64, rate: f64) -> Result<Self, BadFaultRate> {
        if !(0.0..=1.0).contains(&rate) {
            return Err(BadFaultRate(rate));
        }
        Ok(Self {
            inner,
            rate,
            rng: fastrand::Rng::with_seed(seed),
            late_by: Duration::from_secs(2),
            injected: FaultCounts::default(),
        })
    }

    /// How late a delayed reply is at most (default 2 s, beyond the clients' timeouts).
    pub fn with_late_by(mut self, late_by: Duration) -> Self {
        self.late_by = late_by;
        self
    }

    /// Faults injected so far.
    pub fn injected(&self) -> FaultCounts {
        self.injected
    }

    /// The wrapped device.
    pub fn inner(&self) -> &D {
        &self.inner
    }

    fn disturb(&mut self, mut tx: Transmit) -> Option<Transmit> {
        if self.rate == 0.0 || self.rng.f64() >= self.rate {
            return Some(tx);
        }
        match self.rng.u8(0..4) {
            0 => {
                self.injected.dropped += 1;
                None
            }
            1 => {
                self.injected.delayed += 1;
                let late_ms = self.late_by.as_millis().max(1) as u64;
                tx.delay += Duration::from_millis(self.rng.u64(late_ms / 4..=late_ms));
                Some(tx)
            }
            2 if !tx.bytes.is_empty() => {
                self.injected.corrupted += 1;
                let at = self.rng.usize(..tx.bytes.len());
                tx.bytes[at] ^= 1 << self.rng.u8(0..8);
                Some(tx)
            }
            _ => {
                self.injected.garbage += 1;
                let mut bytes: Vec<u8> =
                    (0..self.rng.usize(1..8)).map(|_| self.rng.u8(..)).collect();
                bytes.append(&mut tx.bytes);
                tx.bytes = bytes;
                Some(tx)
            }
        }
    }
}

impl<D: Device> Device for FaultInjector<D> {
    fn set_timing(&mut self, timing: LineTiming) {
        self.inner.set_timing(timing);
    }

    fn receive(&mut self, bytes: &[u8], now: Instant) -> Vec<Transmit> {
        let replies = self.inner.receive(bytes, now);
        replies
            .into_iter()
            .filter_map(|tx| self.disturb(tx))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Echoes every chunk it receives.
    struct Echo;

    impl Device for Echo {
        fn receive(&mut self, bytes: &[u8], _now: Instant) -> Vec<Transmit> {
            vec![Transmit::now(bytes.to_vec())]
        }
    }

    fn run(seed: u64, rate: f64) -> (Vec<Vec<Transmit>>, FaultCounts) {
        let mut device = FaultInjector::new(Echo, seed, rate).expect("valid rate");
        let now = Instant::now();
        let out = (0..400u16)
            .map(|i| device.receive(&i.to_be_bytes(), now))
            .collect();
        (out, device.injected())
    }

    #[test]
    fn fault_injection_with_the_same_seed_gives_the_same_faults() {
        assert_eq!(run(7, 0.5), run(7, 0.5));
        assert_ne!(run(7, 0.5).0, run(8, 0.5).0);
    }

    #[test]
    fn fault_injection_at_rate_zero_changes_nothing() {
        let (out, counts) = run(1, 0.0);
        assert_eq!(counts, FaultCounts::default());
        for (i, replies) in out.iter().enumerate() {
            assert_eq!(
                replies,
                &vec![Transmit::now((i as u16).to_be_bytes().to_vec())]
            );
        }
    }

    #[test]
    fn fault_injection_at_rate_one_injects_every_kind() {
        let (out, counts) = run(3, 1.0);
        assert_eq!(
            counts.dropped + counts.delayed + counts.corrupted + counts.garbage,
            400
        );
        assert!(
            counts.dropped > 50
                && counts.delayed > 50
                && counts.corrupted > 50
                && counts.garbage > 50
        );
        assert_eq!(
            out.iter().filter(|r| r.is_empty()).count() as u64,
            counts.dropped
        );
    }

    #[test]
    fn fault_rates_outside_zero_to_one_are_refused() {
        assert_eq!(
            FaultInjector::new(Echo, 0, 1.5).err(),
            Some(BadFaultRate(1.5))
        );
        assert!(FaultInjector::new(Echo, 0, -0.1).is_err());
        assert!(FaultInjector::new(Echo, 0, f64::NAN).is_err());
    }

    struct Counter {
        frames: usize,
    }

    #[derive(Clone)]
    struct Lines;

    impl Codec for Lines {
        type Frame = Vec<u8>;
        type Error = std::convert::Infallible;
        fn decode(&self, buf: &[u8]) -> Result<Option<(Vec<u8>, usize)>, Self::Error> {
            Ok(crate::test_lines::decode_line(buf))
        }
        fn encode(&self, frame: &Vec<u8>, out: &mut Vec<u8>) {
            crate::test_lines::encode_line(frame, out);
        }
    }

    impl crate::Resync for std::convert::Infallible {
        fn drop_len(&self) -> usize {
            match *self {}
        }
    }

    impl Model for Counter {
        type Codec = Lines;
        fn codec(&self) -> Lines {
            Lines
        }
        fn handle(
            &mut self,
            input: Result<Vec<u8>, std::convert::Infallible>,
            _now: Instant,
        ) -> Vec<Transmit> {
            let Ok(frame) = input;
            self.frames += 1;
            vec![Transmit::now(frame)]
        }
    }

    #[test]
    fn a_half_frame_is_dropped_after_the_line_falls_silent() {
        let model = SharedModel::new(Counter { frames: 0 });
        let mut line = model.line();
        let start = Instant::now();
        // A damaged request that never ends, then silence, then a good request.
        assert!(
            line.receive(b"long frame without its end", start)
                .is_empty()
        );
        let later = start + UNPACED_FRAME_GAP;
        assert_eq!(
            line.receive(b"ask\n", later),
            vec![Transmit::now(b"ask".to_vec())]
        );
        assert_eq!(line.dropped_partial(), 1);
    }

    #[test]
    fn a_frame_split_by_less_than_the_gap_is_kept_whole() {
        let model = SharedModel::new(Counter { frames: 0 });
        let mut line = model.line();
        let start = Instant::now();
        assert!(line.receive(b"hel", start).is_empty());
        let soon = start + UNPACED_FRAME_GAP / 2;
        assert_eq!(
            line.receive(b"lo\n", soon),
            vec![Transmit::now(b"hello".to_vec())]
        );
        assert_eq!(line.dropped_partial(), 0);
    }

    #[test]
    fn on_a_paced_line_the_gap_is_measured_from_the_first_character_of_new_input() {
        let model = SharedModel::new(Counter { frames: 0 });
        let mut line = model.line();
        let char_time = Duration::from_millis(1);
        line.set_timing(LineTiming::paced(Some(char_time)));
        assert_eq!(line.frame_gap(), Duration::from_micros(3500));
        let start = Instant::now();
        assert!(line.receive(b"hel", start).is_empty());
        // 20 characters arriving back to back: handed over 20 ms later, no silence.
        let rest = b"lo, a long tail....\n";
        assert_eq!(rest.len(), 20);
        let out = line.receive(rest, start + char_time * 20);
        assert_eq!(out.len(), 1);
        assert_eq!(line.dropped_partial(), 0);
    }

    #[test]
    fn a_gap_the_user_chose_replaces_the_protocols() {
        let model = SharedModel::new(Counter { frames: 0 });
        let mut line = model.line();
        line.set_timing(LineTiming {
            char_time: Some(Duration::from_millis(1)),
            frame_gap: Some(Duration::from_millis(50)),
        });
        assert_eq!(line.frame_gap(), Duration::from_millis(50));
    }

    #[test]
    fn the_modbus_silence_is_three_and_a_half_characters_and_at_least_1_75_ms() {
        // 9600 baud, 11 bits: 1.146 ms a character.
        let slow = Duration::from_micros(1146);
        assert_eq!(silence_3_5_chars(slow), Duration::from_micros(4011));
        // 115200 baud: 3.5 characters would be 0.33 ms.
        assert_eq!(
            silence_3_5_chars(Duration::from_micros(95)),
            Duration::from_micros(1750)
        );
    }

    #[test]
    fn lines_to_a_shared_model_keep_their_half_frames_apart() {
        let model = SharedModel::new(Counter { frames: 0 });
        let (mut a, mut b) = (model.line(), model.line());
        let now = Instant::now();
        assert!(a.receive(b"hel", now).is_empty());
        assert!(b.receive(b"wor", now).is_empty());
        assert_eq!(
            a.receive(b"lo\n", now),
            vec![Transmit::now(b"hello".to_vec())]
        );
        assert_eq!(
            b.receive(b"ld\n", now),
            vec![Transmit::now(b"world".to_vec())]
        );
        assert_eq!(model.lock().frames, 2);
    }
}
