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
}

/// A device model that handles whole frames.
pub trait Model: Send + 'static {
    /// Decodes what arrives from the line.
    type Codec: Codec + Clone + Send + 'static;

    /// The codec for a new line.
    fn codec(&self) -> Self::Codec;

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

    /// A new line to the model, with its own deframer.
    pub fn line(&self) -> ModelLine<M> {
        let codec = self.lock().codec();
        ModelLine {
            model: self.clone(),
            deframer: Deframer::new(codec),
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
}

impl<M: Model> Device for ModelLine<M>
where
    <M::Codec as Codec>::Frame: Send,
    <M::Codec as Codec>::Error: Send,
{
    fn receive(&mut self, bytes: &[u8], now: Instant) -> Vec<Transmit> {
        self.deframer.push(bytes);
        let mut out = Vec::new();
        while let Some(input) = self.deframer.next_frame() {
            out.extend(self.model.lock().handle(input, now));
        }
        out
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
            Ok(buf
                .iter()
                .position(|&b| b == b'\n')
                .map(|i| (buf[..i].to_vec(), i + 1)))
        }
        fn encode(&self, frame: &Vec<u8>, out: &mut Vec<u8>) {
            out.extend_from_slice(frame);
            out.push(b'\n');
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
