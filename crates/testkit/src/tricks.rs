//! A device behind a line that plays scripted tricks on its replies: drop the next one,
//! damage a byte, delay it, replace it, put bytes or the request's echo before it. One
//! fault-injecting line for every client's tests; the protocol-specific tricks (a NAK, an
//! exception, another unit) are "replace with these bytes", built by each test.
//!
//! [`Tricky`] wraps any [`wire::Device`] and notes on a [`Tap`] what it heard and said,
//! with the time, so tests can count requests and check the line's timing.
//! [`Tricky::silent_after`] cuts the line after a number of answers (a cable pulled in
//! the middle of a poll).

use std::collections::VecDeque;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

use wire::{Device, LineTiming, Transmit};

/// What the line does to the device's next reply.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Trick {
    /// Swallow it.
    Drop,
    /// XOR one byte with `mask` (a checksum bit, a digit turned into a letter); a reply
    /// too short for `at` is left alone.
    Flip {
        /// Which byte.
        at: At,
        /// The bits to flip.
        mask: u8,
    },
    /// Send it this much later.
    Delay(Duration),
    /// Send these bytes instead.
    Replace(Vec<u8>),
    /// Send these bytes first, at the same time (noise, another device's frame).
    Before(Vec<u8>),
    /// Send the request's own bytes back at once first (an adapter's local echo).
    EchoFirst,
}

impl Trick {
    /// Flips the lowest bit of the last byte: a checksum (BCC, CRC) that no longer fits.
    pub fn corrupt_last() -> Self {
        Trick::Flip {
            at: At::End(1),
            mask: 0x01,
        }
    }
}

/// A byte's position in a reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum At {
    /// Counted from the first byte (0 is the first).
    Start(usize),
    /// Counted back from the end (1 is the last).
    End(usize),
}

/// Bytes on the tricky line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Traffic {
    /// Whether the device sent them (else the client did).
    pub from_device: bool,
    /// When the device got them, or when they were scheduled to leave it.
    pub at: Instant,
    /// The bytes.
    pub bytes: Vec<u8>,
}

/// What a [`Tricky`] device heard and said; clones share it.
#[derive(Debug, Clone, Default)]
pub struct Tap(Arc<Mutex<TapLog>>);

#[derive(Debug, Default)]
struct TapLog {
    traffic: Vec<Traffic>,
    replies: usize,
}

impl Tap {
    /// How many requests (inputs) reached the device.
    pub fn requests(&self) -> usize {
        self.lock()
            .traffic
            .iter()
            .filter(|t| !t.from_device)
            .count()
    }

    /// How many replies the device gave, before any trick.
    pub fn replies(&self) -> usize {
        self.lock().replies
    }

    /// When the `index`th request (from 0) reached the device.
    pub fn request_at(&self, index: usize) -> Option<Instant> {
        self.lock()
            .traffic
            .iter()
            .filter(|t| !t.from_device)
            .nth(index)
            .map(|t| t.at)
    }

    /// Everything, in order.
    pub fn traffic(&self) -> Vec<Traffic> {
        self.lock().traffic.clone()
    }

    fn lock(&self) -> MutexGuard<'_, TapLog> {
        self.0.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// A device whose replies go through a queue of tricks, one trick per reply.
#[derive(Debug)]
pub struct Tricky<D> {
    inner: D,
    tricks: VecDeque<Trick>,
    tap: Tap,
    /// Answers still let through ([`Tricky::silent_after`]); none: no limit.
    answers_left: Option<Arc<AtomicUsize>>,
}

impl<D: Device> Tricky<D> {
    /// `inner` behind a line that plays `tricks` on its next replies, in order.
    pub fn new(inner: D, tricks: impl IntoIterator<Item = Trick>) -> Self {
        Self {
            inner,
            tricks: tricks.into_iter().collect(),
            tap: Tap::default(),
            answers_left: None,
        }
    }

    /// Lets the device answer only while `answers` is above 0, one less for each request
    /// it answers: at 0 it falls silent, as when a cable is pulled in the middle of a poll.
    /// The count is shared, so a test can set it while the device runs (`usize::MAX`: no
    /// limit).
    pub fn silent_after(mut self, answers: Arc<AtomicUsize>) -> Self {
        self.answers_left = Some(answers);
        self
    }

    /// What the device heard and said.
    pub fn tap(&self) -> Tap {
        self.tap.clone()
    }
}

impl<D: Device> Device for Tricky<D> {
    fn set_timing(&mut self, timing: LineTiming) {
        self.inner.set_timing(timing);
    }

    fn receive(&mut self, bytes: &[u8], now: Instant) -> Vec<Transmit> {
        let mut replies = self.inner.receive(bytes, now);
        let answered = replies.len();
        if let Some(left) = &self.answers_left
            && !replies.is_empty()
        {
            match left.load(Ordering::SeqCst) {
                usize::MAX => {}
                0 => replies.clear(),
                n => left.store(n - 1, Ordering::SeqCst),
            }
        }
        let mut out = Vec::with_capacity(replies.len());
        for mut tx in replies {
            match self.tricks.pop_front() {
                None => out.push(tx),
                Some(Trick::Drop) => {}
                Some(Trick::Flip { at, mask }) => {
                    let index = match at {
                        At::Start(i) => Some(i),
                        At::End(back) => tx.bytes.len().checked_sub(back),
                    };
                    if let Some(byte) = index.and_then(|i| tx.bytes.get_mut(i)) {
                        *byte ^= mask;
                    }
                    out.push(tx);
                }
                Some(Trick::Delay(by)) => {
                    tx.delay += by;
                    out.push(tx);
                }
                Some(Trick::Replace(bytes)) => {
                    tx.bytes = bytes;
                    out.push(tx);
                }
                Some(Trick::Before(bytes)) => {
                    out.push(Transmit::after(tx.delay, bytes));
                    out.push(tx);
                }
                Some(Trick::EchoFirst) => {
                    out.push(Transmit::now(bytes.to_vec()));
                    out.push(tx);
                }
            }
        }
        let mut log = self.tap.lock();
        log.replies += answered;
        log.traffic.push(Traffic {
            from_device: false,
            at: now,
            bytes: bytes.to_vec(),
        });
        log.traffic.extend(out.iter().map(|tx| Traffic {
            from_device: true,
            at: now + tx.delay,
            bytes: tx.bytes.clone(),
        }));
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Answers every input with `ok`.
    struct Ok;

    impl Device for Ok {
        fn receive(&mut self, _: &[u8], _: Instant) -> Vec<Transmit> {
            vec![Transmit::after(Duration::from_millis(5), b"ok".to_vec())]
        }
    }

    fn replies(device: &mut Tricky<Ok>) -> Vec<Vec<u8>> {
        device
            .receive(b"q", Instant::now())
            .into_iter()
            .map(|tx| tx.bytes)
            .collect()
    }

    #[test]
    fn tricks_apply_to_the_next_replies_in_order_then_replies_pass() {
        let mut device = Tricky::new(
            Ok,
            [
                Trick::Drop,
                Trick::corrupt_last(),
                Trick::Replace(b"no".to_vec()),
                Trick::Before(b"~".to_vec()),
                Trick::EchoFirst,
            ],
        );
        let tap = device.tap();
        assert!(replies(&mut device).is_empty());
        assert_eq!(replies(&mut device), [b"oj".to_vec()]);
        assert_eq!(replies(&mut device), [b"no".to_vec()]);
        assert_eq!(replies(&mut device), [b"~".to_vec(), b"ok".to_vec()]);
        assert_eq!(replies(&mut device), [b"q".to_vec(), b"ok".to_vec()]);
        assert_eq!(replies(&mut device), [b"ok".to_vec()]);
        assert_eq!(tap.requests(), 6);
        assert_eq!(tap.replies(), 6);
    }

    #[test]
    fn a_device_silent_after_two_answers_answers_two_then_none_until_the_count_is_raised() {
        let left = Arc::new(AtomicUsize::new(2));
        let mut device = Tricky::new(Ok, []).silent_after(Arc::clone(&left));
        assert_eq!(replies(&mut device), [b"ok".to_vec()]);
        assert_eq!(replies(&mut device), [b"ok".to_vec()]);
        assert!(replies(&mut device).is_empty());
        assert!(replies(&mut device).is_empty());
        left.store(usize::MAX, Ordering::SeqCst);
        assert_eq!(replies(&mut device), [b"ok".to_vec()]);
        assert_eq!(
            left.load(Ordering::SeqCst),
            usize::MAX,
            "no limit is not counted down"
        );
    }

    #[test]
    fn a_delayed_reply_leaves_later_and_the_tap_says_when() {
        let mut device = Tricky::new(Ok, [Trick::Delay(Duration::from_millis(10))]);
        let now = Instant::now();
        let out = device.receive(b"q", now);
        assert_eq!(out[0].delay, Duration::from_millis(15));
        let traffic = device.tap().traffic();
        assert_eq!(traffic[1].at, now + Duration::from_millis(15));
        assert!(traffic[1].from_device);
    }
}
