//! A twin of Thermosald ISC regulators on one RS-485 line: a [`wire::device::Model`].
//!
//! A [`RegulatorBus`] holds several [`Regulator`]s, each with its own sealing band, memory
//! and faults ([`band`] documents the physics, [`regulator`] the behaviour). Serve it with
//! `wire::device::SharedModel::new(line).line()`. [`operator`] holds the commands an
//! operator gives the line while it serves (`fault 1 open-band`, `power-cycle 2`).
//!
//! # Silence
//!
//! The protocol has no negative answer: the twin answers nothing, and logs why (`debug!`
//! for traffic that is simply not for it, `warn!` for what a master got wrong), when
//!
//! - the bytes are not a message (noise, a half message, a malformed one);
//! - the message is a response (`R`), not a question;
//! - no regulator has the address (or the only one there has its serial interface disabled,
//!   machine item 13 = 0);
//! - the message number is unknown or 13, `$` comes with another message than 10, an item
//!   index is beyond the table, a write carries the wrong number of items;
//! - the message arrives while the regulators are not listening (see timing).
//!
//! # Timing
//!
//! The end of a message is the `now` at which [`wire::device::Model::handle`] receives it:
//! the serve loop hands bytes over as they arrive (or, when it paces the line, when their
//! last character would have arrived), so the call that completes a message is its end.
//! After the end of any whole message (good or malformed) the regulators listen again
//! [`LISTEN_AFTER_MESSAGE`] later. An answer leaves [`ANSWER_AFTER_RECEPTION`] after the
//! end of the question, as a [`Transmit`] with that delay; the line is released
//! [`RELEASE_AFTER_ANSWER`] after the answer's end. That end is the moment the answer is
//! handed to the serve loop (it writes at once over TCP), or, after
//! [`RegulatorBus::paced`], that moment plus the answer's wire time (a serve loop that paces
//! replies at the line's rate). A message that ends before the line is free again is
//! ignored and logged, as a real regulator would miss it; on a paced line, so is one that
//! began (its end minus its wire time) before the line was free.
//!
//! When several regulators answer the same message (`$` reaches every one; two that took
//! the same address), their answers overlap on the wire: identical answers are
//! indistinguishable from one, different ones are merged bit by bit (a 0 bit wins, as on a
//! line where any driver pulling low is seen) and logged as a collision.

pub mod band;
pub mod operator;
pub mod regulator;

use std::time::Instant;

use wire::device::{Model, Transmit};

use crate::exchange::{
    ANSWER_AFTER_RECEPTION, LISTEN_AFTER_MESSAGE, LineTiming, RELEASE_AFTER_ANSWER,
};
use crate::frame::{Address, DecodeError, Direction, Frame, FrameCodec, Target};
use crate::request::{Message, Request};

pub use regulator::{Calibration, Phase, Regulator, RegulatorConfig, Status};

/// Several regulators on one simulated RS-485 line.
#[derive(Debug, Clone)]
pub struct RegulatorBus {
    regulators: Vec<Regulator>,
    listening_from: Option<Instant>,
    pace: Option<LineTiming>,
}

impl RegulatorBus {
    /// Commissioned regulators at `addresses` with the default [`RegulatorConfig`], their
    /// clocks starting at `now`. Refused: no address, or one given twice.
    pub fn new(addresses: &[Address], now: Instant) -> Result<Self, BusError> {
        Self::with_config(addresses, RegulatorConfig::default(), now)
    }

    /// Like [`RegulatorBus::new`] with `config` for every regulator.
    pub fn with_config(
        addresses: &[Address],
        config: RegulatorConfig,
        now: Instant,
    ) -> Result<Self, BusError> {
        if addresses.is_empty() {
            return Err(BusError::NoRegulators);
        }
        for (i, address) in addresses.iter().enumerate() {
            if addresses[..i].contains(address) {
                return Err(BusError::DuplicateAddress { address: *address });
            }
        }
        let regulators = addresses
            .iter()
            .map(|a| Regulator::new(*a, config, now))
            .collect();
        Ok(Self::from_regulators(regulators))
    }

    /// A line with these regulators (any addresses, also none or the same twice, as after
    /// careless commissioning).
    pub fn from_regulators(regulators: Vec<Regulator>) -> Self {
        Self {
            regulators,
            listening_from: None,
            pace: None,
        }
    }

    /// Counts each answer's wire time at `timing` before the line is released, and hears a
    /// message only if it began (its end minus its wire time) once the line was free. Use it
    /// exactly when the serve loop paces the line at the same rate (`link`'s `pace`): then
    /// the master receives each answer at the end of its wire time and
    /// [`crate::exchange::earliest_next_send`] agrees with the twin. Over an unpaced loop
    /// answers arrive 200 ms after the question, and a paced twin would still think the
    /// line busy for the answer's wire time.
    pub fn paced(mut self, timing: LineTiming) -> Self {
        self.pace = Some(timing);
        self
    }

    /// The regulators, in the order given.
    pub fn regulators(&self) -> &[Regulator] {
        &self.regulators
    }

    /// The regulators, to provoke faults, power-cycle or inspect them.
    pub fn regulators_mut(&mut self) -> &mut [Regulator] {
        &mut self.regulators
    }

    /// The (first) regulator at `address`.
    pub fn regulator_mut(&mut self, address: Address) -> Option<&mut Regulator> {
        self.regulators
            .iter_mut()
            .find(|r| r.address() == Some(address))
    }

    /// Power-cycles every regulator at `now` (a mains interruption on the cabinet).
    pub fn power_cycle(&mut self, now: Instant) {
        for regulator in &mut self.regulators {
            regulator.power_cycle(now);
        }
        self.listening_from = None;
    }

    /// When the regulators listen again; `None` if they have been listening all along.
    pub fn listening_from(&self) -> Option<Instant> {
        self.listening_from
    }

    /// Handles one decoded message that ended at `now`; the bytes to answer, if any.
    fn handle_frame(&mut self, frame: Frame, now: Instant) -> Option<Vec<u8>> {
        // On a paced line the message began its wire time before its end; it is heard only
        // if it began once the regulators listened.
        let start = self
            .pace
            .and_then(|t| now.checked_sub(t.wire_time(frame.wire_len())))
            .unwrap_or(now);
        if let Some(from) = self.listening_from.filter(|from| start < *from) {
            tracing::warn!(
                %frame,
                early_by = ?from - start,
                "message inside the regulators' turnaround (40 ms after a message, 200 ms before and 40 ms after an answer): ignored"
            );
            return None;
        }
        self.listening_from = Some(now + LISTEN_AFTER_MESSAGE);
        if frame.direction() == Direction::Reply {
            tracing::debug!(%frame, "a response on the line, not a question: silence");
            return None;
        }
        let listeners: Vec<usize> = self
            .regulators
            .iter()
            .enumerate()
            .filter(|(_, r)| r.serial_enabled() && hears(r, frame.target()))
            .map(|(i, _)| i)
            .collect();
        if listeners.is_empty() {
            tracing::debug!(%frame, target = %frame.target(), "no listening regulator at this address: silence");
            return None;
        }
        let request = match Request::parse(&frame) {
            Ok(request) => request,
            Err(error) => {
                tracing::warn!(%frame, %error, "message not understood: silence");
                return None;
            }
        };
        if frame.target() == Target::Assign && listeners.len() > 1 {
            tracing::warn!(
                regulators = listeners.len(),
                "address assignment heard by several regulators: all take it"
            );
        }
        let answers: Vec<Vec<u8>> = self
            .regulators
            .iter_mut()
            .enumerate()
            .filter(|(i, _)| listeners.contains(i))
            .filter_map(|(_, regulator)| regulator.respond(&frame, &request, now))
            .map(|reply| reply.to_bytes())
            .collect();
        if request.message() == Message::MasterReset {
            tracing::info!(%frame, "master reset done");
        }
        let answer = superimpose(&answers)?;
        let wire = self
            .pace
            .map_or(std::time::Duration::ZERO, |t| t.wire_time(answer.len()));
        self.listening_from = Some(now + ANSWER_AFTER_RECEPTION + wire + RELEASE_AFTER_ANSWER);
        Some(answer)
    }
}

impl Model for RegulatorBus {
    type Codec = FrameCodec;

    fn codec(&self) -> FrameCodec {
        FrameCodec
    }

    /// A regulator restarts listening [`LISTEN_AFTER_MESSAGE`] after a message; the same
    /// silence inside a message ends it (on an unpaced line, the short default).
    fn frame_gap(&self, char_time: Option<std::time::Duration>) -> std::time::Duration {
        char_time.map_or(wire::device::UNPACED_FRAME_GAP, |_| LISTEN_AFTER_MESSAGE)
    }

    fn handle(&mut self, input: Result<Frame, DecodeError>, now: Instant) -> Vec<Transmit> {
        match input {
            Ok(frame) => self
                .handle_frame(frame, now)
                .map(|bytes| Transmit::after(ANSWER_AFTER_RECEPTION, bytes))
                .into_iter()
                .collect(),
            Err(error) => {
                if error.is_whole_message() && self.listening_from.is_none_or(|from| now >= from) {
                    self.listening_from = Some(now + LISTEN_AFTER_MESSAGE);
                }
                tracing::warn!(%error, "bytes that are not a message: silence");
                Vec::new()
            }
        }
    }
}

/// A line that cannot be built.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum BusError {
    /// No address given.
    #[error("a simulated line needs at least one regulator address")]
    NoRegulators,
    /// An address given twice.
    #[error("address {address} is given twice; each regulator on a line needs its own")]
    DuplicateAddress {
        /// The address.
        address: Address,
    },
}

/// Whether `regulator` hears a message for `target`: `$` reaches every regulator, an
/// address only the one that has it.
fn hears(regulator: &Regulator, target: Target) -> bool {
    match target {
        Target::Assign => true,
        Target::Address(address) => regulator.address() == Some(address),
    }
}

/// Answers sent at the same time, as the master hears them.
fn superimpose(answers: &[Vec<u8>]) -> Option<Vec<u8>> {
    let (first, rest) = answers.split_first()?;
    if rest.iter().all(|a| a == first) {
        return Some(first.clone());
    }
    tracing::warn!(
        answers = answers.len(),
        "several regulators answered at once: collision"
    );
    let len = answers.iter().map(Vec::len).max().unwrap_or(0);
    Some(
        (0..len)
            .map(|i| {
                answers
                    .iter()
                    .map(|a| a.get(i).copied().unwrap_or(0xFF))
                    .fold(0xFF, |acc, b| acc & b)
            })
            .collect(),
    )
}
