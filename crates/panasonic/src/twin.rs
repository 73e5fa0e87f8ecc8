//! A placement-machine twin: the server side of the protocol as a pure model.
//!
//! [`Machine`] holds what a BM machine holds for the host: a program store within the
//! manual's limits (100 programs, 5000 steps, library sizes), a selected program, the
//! online/remote mode, a stop mode, feeders with parts, production counters, and a
//! production run that advances with the `now` it is given. It speaks both ports:
//!
//! - **Port 1**: [`Machine::handle_port1`] takes bytes (or [`Machine::handle_message`] a
//!   decoded message) and returns the replies, following [`MachineConversation`]'s rules
//!   and refusing exactly as the manual says (below).
//! - **Port 2**: [`Machine::poll_events`] returns the R messages produced up to `now`,
//!   while a host listens ([`Machine::host_connected_on_port2`]); while none does, they wait
//!   in a buffer of [`EVENT_BUFFER_LEN`] (about 40 in the manual), the oldest dropped first,
//!   and are delivered in order when a host connects.
//!
//! Choices for the server around the twin (fact sheet, "What the product decides"):
//! - **One host per port \[?\]:** the twin keeps one Port 1 conversation and one Port 2
//!   listener. A server should refuse a second Port 1 connection politely (accept, log,
//!   close) rather than queue it, and call [`Machine::port1_closed`] when the host's
//!   connection goes, so a half message or an open exchange does not outlive it.
//! - **R messages in both modes \[?\]:** 3.4.6's table of which R messages go out in Online
//!   and Remote mode is garbled in our copy; the twin sends them in both, when its R-command
//!   switch ([`MachineConfig::events_enabled`]) is on.
//! - **Buffer while nobody listens \[I\]:** the ~40-message rule applies while no host is
//!   connected to Port 2; a listening host gets every message at the next poll.
//!
//! Nothing here reads a clock, sleeps or touches a socket; randomness comes from a seeded
//! `fastrand` generator, so a seed and the same inputs give the same run. A TCP server
//! around it calls [`Machine::next_event_at`] to know when to poll again.
//!
//! ## Refusals
//!
//! | situation | answer |
//! |---|---|
//! | C5 (start, reset) in Online mode | `A4E00` |
//! | C5ST while running, in an error stop, or with no (or an empty) program selected | `A4E00` |
//! | C5RE while running \[I\] | `A4E00` |
//! | C0 of the selected program | `A4E00` |
//! | C0 beyond 100 programs, 5000 steps or a library's size | `A4E00` |
//! | C0R of the selected program, or of a library or machine data \[I\] | `A4E00` |
//! | C1/C0R of a program that does not exist, C1 of a library never downloaded | `A3` |
//! | C3 with no program selected | `A4E01` |
//! | C0 data without the `*` CRLF end mark, or C0G without valid condition data \[I\] | `A4E01` |
//! | malformed C2HB (3.5-2) | `A4E00` |
//! | unknown command, undecodable bytes, out-of-sequence messages | `A4E01` (see [`conversation`](crate::conversation)) |
//!
//! ## Production model
//!
//! A board is the selected program's steps, one block per step: the board is loaded
//! ([`MachineConfig::load_time`]), then each step picks a part from feeder
//! `1 + step % feeders` and places it ([`MachineConfig::placement_time`]). A pick misses
//! with [`MachineConfig::miss_rate`] (a pick-up miss or a recognition error; the part is
//! lost): the machine sends `R1RC`, spends [`MachineConfig::recovery_time`], and then
//! `R3GDCT` (85 %, the part is placed), `R3NGCT` (10 %, it tries again) or `R3NGEP` (5 %,
//! a pick-up error stop: status Ready, as 3.3-11 says pick-up errors are not Error). An
//! empty or paused feeder stops the machine with `R2E03` (status Error); if that happens
//! right after a recovery, no R3 is sent (3.4-7). A finished board gives `R0CT[time]` in
//! CONT mode (the next board starts at once), `R0EP[time]` in EOP or 1-BLOCK mode (the
//! machine stops, Ready). In 1-BLOCK mode the machine also stops after every block.
//!
//! \[?\] The program data format is not in the pages we have: the twin's demo program uses
//! an invented step line (`0001,X012.50,Y008.00,R000,Z001`), and it counts steps as
//! [`ProgramText::entries`] does. Per-nozzle and per-feeder breakdowns of C1N/C1Z are
//! not modelled: those answers carry the same counters, cleared separately.

use std::collections::{BTreeMap, VecDeque};
use std::time::{Duration, Instant};

use wire::Deframer;

use crate::calendar::{ProgramDate, Timestamp};
use crate::command::{Command, ProductionRequest, ProductionScope};
use crate::conversation::{MachineAnswer, MachineConversation, MachineStep};
use crate::event::{BoardTime, ErrorInfo, Event, PARTS_EXHAUSTED};
use crate::message::{DecodeError, Message, MessageCodec};
use crate::production::{
    Counter, MACHINE_BM, PANASONIC_FORMAT, ProductionData, ProductionHeader, Rate, RateKind,
};
use crate::program::{
    ConditionData, MAX_PROGRAMS, ProgramList, ProgramListEntry, ProgramName, ProgramText, Target,
};
use crate::reply::A4Reason;
use crate::status::{ControlMode, MachineStatus, RunState, StopMode};

/// R messages kept while no host listens on Port 2 ("about 40", 3.2-2, 3.5-2).
pub const EVENT_BUFFER_LEN: usize = 40;
/// Nozzles on the head; step `n` uses nozzle `1 + n % HEAD_NOZZLES` (twin's model).
pub const HEAD_NOZZLES: usize = 8;
/// Name of the demo program.
pub const DEMO_PROGRAM: &str = "DEMO-BOARD";
/// Steps of the demo program.
pub const DEMO_STEPS: usize = 120;

/// Share of recoveries that succeed (`R3GDCT`).
const RECOVERY_OK_SHARE: f64 = 0.85;
/// Share of recoveries that fail and retry (`R3NGCT`); the rest stop (`R3NGEP`).
const RECOVERY_RETRY_SHARE: f64 = 0.10;
/// Share of lost parts that are pick-up misses; the rest are recognition errors.
const MISS_SHARE: f64 = 0.7;

/// How the twin is built.
#[derive(Debug, Clone, PartialEq)]
pub struct MachineConfig {
    /// Seed of the random generator (misses, recoveries, initial reel fill).
    pub seed: u64,
    /// Start in Remote mode (else Online).
    pub remote: bool,
    /// The machine's R-command switch (3.2-2): when off, nothing goes to Port 2, not even R1HB.
    pub events_enabled: bool,
    /// The extended-format switch (3.4-7): board times on R0, program names on R1SE,
    /// details on R2.
    pub extended_format: bool,
    /// R messages kept while no host listens on Port 2.
    pub event_buffer: usize,
    /// Calendar time at the first `now` the twin sees (for START/END and program dates).
    pub clock: Timestamp,
    /// Store and select a demo program ([`DEMO_PROGRAM`], [`DEMO_STEPS`] steps).
    pub demo_program: bool,
    /// Board loading and unloading time, per board.
    pub load_time: Duration,
    /// Time per placement (block).
    pub placement_time: Duration,
    /// Time an automatic recovery takes.
    pub recovery_time: Duration,
    /// Time from C5RE to R1RE.
    pub reset_time: Duration,
    /// Feeders in use (Z numbers 1..=feeders).
    pub feeders: u16,
    /// Parts on a full reel; feeders start between a quarter and a full reel.
    pub reel_size: u32,
    /// Probability that a pick loses its part (0–1).
    pub miss_rate: f64,
    /// Boards planned (PRODUCTPLAN1).
    pub production_plan: u32,
}

impl Default for MachineConfig {
    /// Online, R commands on in extended format, 40-message buffer, a demo program
    /// selected; 4 s loading, 0.15 s per placement (a 120-step board in 22 s), 20 feeders
    /// of 2000 parts, 1 pick in 500 lost.
    fn default() -> Self {
        MachineConfig {
            seed: 0,
            remote: false,
            events_enabled: true,
            extended_format: true,
            event_buffer: EVENT_BUFFER_LEN,
            clock: Timestamp::new(2026, 1, 5, 8, 0, 0).expect("a valid calendar date"),
            demo_program: true,
            load_time: Duration::from_secs(4),
            placement_time: Duration::from_millis(150),
            recovery_time: Duration::from_secs(2),
            reset_time: Duration::from_secs(3),
            feeders: 20,
            reel_size: 2000,
            miss_rate: 0.002,
            production_plan: 0,
        }
    }
}

/// A configuration the twin cannot run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ConfigError {
    /// A number out of its range.
    #[error("machine config {what} = {value} is out of range {min}..={max}")]
    OutOfRange {
        /// Which setting.
        what: &'static str,
        /// The value.
        value: f64,
        /// Lowest allowed.
        min: f64,
        /// Highest allowed.
        max: f64,
    },
    /// A duration that must be above zero.
    #[error("machine config {what} must be longer than zero")]
    ZeroDuration {
        /// Which setting.
        what: &'static str,
    },
}

impl MachineConfig {
    fn check(&self) -> Result<(), ConfigError> {
        let range = |what, value: f64, min: f64, max: f64| {
            if (min..=max).contains(&value) {
                Ok(())
            } else {
                Err(ConfigError::OutOfRange {
                    what,
                    value,
                    min,
                    max,
                })
            }
        };
        range("miss_rate", self.miss_rate, 0.0, 1.0)?;
        range("feeders", self.feeders.into(), 1.0, 999.0)?;
        range("reel_size", self.reel_size.into(), 1.0, 9_999_999.0)?;
        range("event_buffer", self.event_buffer as f64, 1.0, 100_000.0)?;
        for (what, duration) in [
            ("placement_time", self.placement_time),
            ("load_time", self.load_time),
        ] {
            if duration.is_zero() {
                return Err(ConfigError::ZeroDuration { what });
            }
        }
        Ok(())
    }
}

/// A control request the twin cannot carry out.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum TwinError {
    /// No such program stored.
    #[error("program {name} is not stored on the machine")]
    UnknownProgram {
        /// The name.
        name: ProgramName,
    },
    /// Not while the machine runs.
    #[error("the machine is running: stop it first")]
    Running,
    /// Not in an error stop: reset first.
    #[error("the machine is in an error stop: reset or clear it first")]
    ErrorStop,
    /// No program selected, or one without steps.
    #[error("no program with steps is selected")]
    NothingToRun,
    /// No such feeder.
    #[error("feeder {feeder} does not exist: the machine has feeders 1 to {feeders}")]
    NoSuchFeeder {
        /// The feeder asked for.
        feeder: u16,
        /// How many there are.
        feeders: u16,
    },
    /// An error code that does not fit R2.
    #[error("error code {code} does not fit R2 (0 to 99)")]
    BadErrorCode {
        /// The code.
        code: u8,
    },
}

#[derive(Debug, Clone, PartialEq, Eq)]
struct StoredProgram {
    text: ProgramText,
    steps: usize,
    date: ProgramDate,
}

/// The board being built: kept across stops so a restart continues it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Progress {
    board_started: Instant,
    next_block: usize,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Feeder {
    remaining: u32,
    paused: bool,
}

/// One set of production counters, with the moment it was last cleared.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Counters {
    since: Instant,
    boards: u64,
    pickups: u64,
    mounts: u64,
    misses: u64,
    recognition_errors: u64,
    pickup_error_stops: u64,
    exhaust_stops: u64,
    exhaust_seconds: u64,
}

impl Counters {
    fn new(since: Instant) -> Counters {
        Counters {
            since,
            boards: 0,
            pickups: 0,
            mounts: 0,
            misses: 0,
            recognition_errors: 0,
            pickup_error_stops: 0,
            exhaust_stops: 0,
            exhaust_seconds: 0,
        }
    }
}

/// Grand total (C1M), current total (C1M…P), nozzle (C1N) and feeder (C1Z) counters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct CounterSets([Counters; 4]);

impl CounterSets {
    fn add(&mut self, f: impl Fn(&mut Counters)) {
        self.0.iter_mut().for_each(f);
    }

    fn get(&self, scope: ProductionScope) -> &Counters {
        &self.0[Self::index(scope)]
    }

    fn clear(&mut self, scope: ProductionScope, now: Instant) {
        self.0[Self::index(scope)] = Counters::new(now);
    }

    fn index(scope: ProductionScope) -> usize {
        match scope {
            ProductionScope::GrandTotal => 0,
            ProductionScope::CurrentTotal => 1,
            ProductionScope::Nozzle => 2,
            ProductionScope::Feeder => 3,
        }
    }
}

/// The placement-machine twin. See the [module documentation](self).
#[derive(Debug, Clone)]
pub struct Machine {
    config: MachineConfig,
    rng: fastrand::Rng,
    epoch: Option<Instant>,
    clock_now: Option<Instant>,
    port1: Deframer<MessageCodec>,
    conversation: MachineConversation,
    programs: BTreeMap<ProgramName, StoredProgram>,
    libraries: BTreeMap<&'static str, ProgramText>,
    condition: ConditionData,
    selected: Option<ProgramName>,
    mode: ControlMode,
    state: RunState,
    stop_mode: StopMode,
    /// When the next block is placed, while running.
    due: Option<Instant>,
    progress: Option<Progress>,
    feeders: Vec<Feeder>,
    counters: Option<CounterSets>,
    exhausted_since: Option<Instant>,
    scheduled: Vec<(Instant, Event)>,
    events: VecDeque<Message>,
    port2_connected: bool,
    dropped_events: u64,
}

impl Machine {
    /// A twin; fails only for a configuration it cannot run.
    pub fn new(config: MachineConfig) -> Result<Machine, ConfigError> {
        config.check()?;
        let mut rng = fastrand::Rng::with_seed(config.seed);
        let low = (config.reel_size / 4).max(1);
        let feeders = (0..config.feeders)
            .map(|_| Feeder {
                remaining: rng.u32(low..=config.reel_size),
                paused: false,
            })
            .collect();
        let mut machine = Machine {
            mode: if config.remote {
                ControlMode::Remote
            } else {
                ControlMode::Online
            },
            rng,
            epoch: None,
            clock_now: None,
            port1: Deframer::new(MessageCodec),
            conversation: MachineConversation::new(),
            programs: BTreeMap::new(),
            libraries: BTreeMap::new(),
            condition: ConditionData {
                pass_through: false,
                evaluation_mode: false,
                offset_manual_mark: false,
                evaluation_h_down: false,
            },
            selected: None,
            state: RunState::Ready,
            stop_mode: StopMode::Continuous,
            due: None,
            progress: None,
            feeders,
            counters: None,
            exhausted_since: None,
            scheduled: Vec::new(),
            events: VecDeque::new(),
            port2_connected: false,
            dropped_events: 0,
            config,
        };
        if machine.config.demo_program {
            let name = ProgramName::new(DEMO_PROGRAM).expect("the demo name is valid");
            let text = demo_program_text(DEMO_STEPS, machine.config.feeders);
            let date = machine.config.clock.date();
            machine.programs.insert(
                name.clone(),
                StoredProgram {
                    steps: text.entries(),
                    text,
                    date,
                },
            );
            machine.selected = Some(name);
        }
        Ok(machine)
    }

    // -----------------------------------------------------------------------------------
    // Getters

    /// The configuration.
    pub fn config(&self) -> &MachineConfig {
        &self.config
    }

    /// What C2ST would answer.
    pub fn status(&self) -> MachineStatus {
        MachineStatus {
            state: self.state,
            mode: self.mode,
        }
    }

    /// The selected program.
    pub fn selected(&self) -> Option<&ProgramName> {
        self.selected.as_ref()
    }

    /// The stop mode set by the last start.
    pub fn stop_mode(&self) -> StopMode {
        self.stop_mode
    }

    /// Stored programs, as C1RP would list them.
    pub fn programs(&self) -> ProgramList {
        ProgramList(
            self.programs
                .iter()
                .map(|(name, program)| ProgramListEntry {
                    date: program.date,
                    name: name.clone(),
                })
                .collect(),
        )
    }

    /// The text of a stored program.
    pub fn program_text(&self, name: &ProgramName) -> Option<&ProgramText> {
        self.programs.get(name).map(|p| &p.text)
    }

    /// The operating-condition data (changed by C0G).
    pub fn condition_data(&self) -> ConditionData {
        self.condition
    }

    /// Boards finished since the grand total was last cleared.
    pub fn boards_produced(&self) -> u64 {
        self.counters
            .map_or(0, |c| c.get(ProductionScope::GrandTotal).boards)
    }

    /// Parts left on feeder `feeder` (1-based Z number).
    pub fn feeder_remaining(&self, feeder: u16) -> Result<u32, TwinError> {
        Ok(self.feeders[self.feeder_index(feeder)?].remaining)
    }

    /// R messages dropped because the buffer was full while no host listened.
    pub fn dropped_events(&self) -> u64 {
        self.dropped_events
    }

    /// R messages waiting for [`poll_events`](Self::poll_events).
    pub fn pending_events(&self) -> usize {
        self.events.len()
    }

    /// Whether a host listens on Port 2.
    pub fn is_port2_connected(&self) -> bool {
        self.port2_connected
    }

    /// Whether an exchange is open on Port 1.
    pub fn in_conversation(&self) -> bool {
        !self.conversation.is_idle()
    }

    /// When the production run or a pending R message next needs `poll_events`.
    pub fn next_event_at(&self) -> Option<Instant> {
        let scheduled = self.scheduled.first().map(|(at, _)| *at);
        match (self.due, scheduled) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    // -----------------------------------------------------------------------------------
    // Port 1

    /// Takes bytes from the host on Port 1 at `now`; returns the replies to send, in order.
    pub fn handle_port1(&mut self, bytes: &[u8], now: Instant) -> Vec<Message> {
        self.port1.push(bytes);
        let mut replies = Vec::new();
        while let Some(input) = self.port1.next_frame() {
            replies.extend(self.handle_message(input, now));
        }
        replies
    }

    /// Takes one decoded message (or the error for dropped bytes) at `now`.
    pub fn handle_message(
        &mut self,
        input: Result<Message, DecodeError>,
        now: Instant,
    ) -> Vec<Message> {
        let now = self.advance(now);
        match self.conversation.receive(input) {
            MachineStep::Command(command) => {
                tracing::debug!(%command, "Port 1 command");
                let answer = self.decide(command, now);
                vec![self.conversation.answer(answer)]
            }
            MachineStep::Reply(reply) => vec![reply],
            MachineStep::Commit(command) => {
                self.commit(command, now);
                Vec::new()
            }
            MachineStep::Quiet => Vec::new(),
        }
    }

    /// The host's Port 1 connection closed: forget its half message and open exchange.
    pub fn port1_closed(&mut self) {
        self.port1.clear();
        self.conversation.reset();
    }

    // -----------------------------------------------------------------------------------
    // Port 2

    /// A host started (`true`) or stopped (`false`) listening on Port 2 at `now`. Events up
    /// to `now` are produced first, so they go by the old state.
    pub fn host_connected_on_port2(&mut self, connected: bool, now: Instant) {
        self.advance(now);
        self.port2_connected = connected;
        if !connected {
            self.trim_events();
        }
    }

    /// The R messages produced up to `now`, in order, while a host listens; nothing (they
    /// stay buffered) while none does.
    pub fn poll_events(&mut self, now: Instant) -> Vec<Message> {
        self.advance(now);
        if self.port2_connected {
            self.events.drain(..).collect()
        } else {
            Vec::new()
        }
    }

    /// R messages that [`poll_events`](Self::poll_events) gave but that could not be sent
    /// (the host's connection failed while they were written) go back to the front of the
    /// buffer, in order, for the next host; the buffer rule applies to them as to any other.
    pub fn requeue_events(&mut self, messages: Vec<Message>) {
        for message in messages.into_iter().rev() {
            self.events.push_front(message);
        }
        if !self.port2_connected {
            self.trim_events();
        }
    }

    /// Takes bytes from the host on Port 2: an optional `A2` after an R message, ignored
    /// (3.4-1 says no answer is needed).
    pub fn handle_port2(&mut self, bytes: &[u8]) {
        tracing::trace!(len = bytes.len(), "bytes from the host on Port 2 ignored");
    }

    // -----------------------------------------------------------------------------------
    // Control (the operator's side, for tests and demos)

    /// Switches between Online and Remote.
    pub fn set_mode(&mut self, mode: ControlMode) {
        self.mode = mode;
    }

    /// Selects a stored program (the operator's choice at the machine). Sends `R1SE`; an
    /// unknown name sends `R1SENG` and fails \[I\].
    pub fn select_program(&mut self, name: &ProgramName, now: Instant) -> Result<(), TwinError> {
        self.advance(now);
        let program = self.config.extended_format.then(|| name.clone());
        if self.state == RunState::Run {
            return Err(TwinError::Running);
        }
        if !self.programs.contains_key(name) {
            self.emit(Event::SeNg {
                program,
                error: None,
            });
            return Err(TwinError::UnknownProgram { name: name.clone() });
        }
        if self.selected.as_ref() != Some(name) {
            self.progress = None;
        }
        self.selected = Some(name.clone());
        self.emit(Event::Se { program });
        Ok(())
    }

    /// The operator starts the machine at the panel (any mode), like C5ST.
    pub fn operator_start(
        &mut self,
        mode: Option<StopMode>,
        now: Instant,
    ) -> Result<(), TwinError> {
        let now = self.advance(now);
        self.start(mode, now)
    }

    /// The operator stops the machine: Ready; the board in progress continues on the next
    /// start.
    pub fn stop(&mut self, now: Instant) {
        self.advance(now);
        if self.state == RunState::Run {
            self.state = RunState::Ready;
            self.due = None;
        }
    }

    /// Stops feeding from feeder `feeder` (1-based): the next pick from it exhausts.
    pub fn pause_feeder(&mut self, feeder: u16, now: Instant) -> Result<(), TwinError> {
        self.advance(now);
        let index = self.feeder_index(feeder)?;
        self.feeders[index].paused = true;
        Ok(())
    }

    /// Feeds from feeder `feeder` again.
    pub fn resume_feeder(&mut self, feeder: u16, now: Instant) -> Result<(), TwinError> {
        self.advance(now);
        let index = self.feeder_index(feeder)?;
        self.feeders[index].paused = false;
        Ok(())
    }

    /// Loads a full reel on feeder `feeder`.
    pub fn refill_feeder(&mut self, feeder: u16, now: Instant) -> Result<(), TwinError> {
        self.advance(now);
        let index = self.feeder_index(feeder)?;
        self.feeders[index].remaining = self.config.reel_size;
        Ok(())
    }

    /// Stops the machine with error `code` (sends `R2E<code>…`; status Error).
    pub fn force_error(&mut self, code: u8, now: Instant) -> Result<(), TwinError> {
        self.advance(now);
        let info = self
            .error_info(code, self.current_block())
            .ok_or(TwinError::BadErrorCode { code })?;
        self.emit(Event::Error(info));
        self.state = RunState::Error;
        self.due = None;
        Ok(())
    }

    /// The operator clears every cause and presses RESET: empty feeders get a full reel,
    /// paused ones resume, an error stop becomes Ready.
    pub fn clear(&mut self, now: Instant) {
        let now = self.advance(now);
        let reel = self.config.reel_size;
        for feeder in &mut self.feeders {
            feeder.paused = false;
            if feeder.remaining == 0 {
                feeder.remaining = reel;
            }
        }
        self.leave_error(now);
    }

    // -----------------------------------------------------------------------------------
    // Commands

    fn decide(&mut self, command: Command, now: Instant) -> MachineAnswer {
        use MachineAnswer::{Data, Finished, NoSuchProgram, Refused, Value};
        const OPERATION: MachineAnswer = Refused(A4Reason::OperationError);
        const PROTOCOL: MachineAnswer = Refused(A4Reason::ProtocolError);
        if command.is_remote_control() && self.mode != ControlMode::Remote {
            return OPERATION;
        }
        match command {
            Command::Download { target, data } => match self.check_download(&target, data) {
                Ok(data) => MachineAnswer::Received(Command::Download { target, data }),
                Err(reason) => Refused(reason),
            },
            Command::Delete {
                target: Target::Product(name),
            } => {
                if !self.programs.contains_key(&name) {
                    NoSuchProgram
                } else if self.selected.as_ref() == Some(&name) {
                    OPERATION
                } else {
                    self.programs.remove(&name);
                    Finished
                }
            }
            Command::Delete { .. } => OPERATION,
            Command::Upload { target } => match self.upload(&target) {
                Some(data) => Data(data),
                None => NoSuchProgram,
            },
            Command::Production(request) => Data(self.production_data(request, now).to_bytes()),
            Command::ProgramList => Data(self.programs().to_bytes()),
            Command::Status => Value(self.status().to_bytes().to_vec()),
            Command::KeepAlive(id) => {
                self.emit(Event::Heartbeat { id });
                Finished
            }
            Command::CurrentProgram => match &self.selected {
                Some(name) => {
                    let mut field = Vec::new();
                    name.write_field(&mut field);
                    Value(field)
                }
                None => PROTOCOL,
            },
            Command::Start(mode) => match self.start(mode, now) {
                Ok(()) => Finished,
                Err(_) => OPERATION,
            },
            Command::Reset => {
                if self.state == RunState::Run {
                    return OPERATION;
                }
                self.leave_error(now);
                self.scheduled
                    .push((now + self.config.reset_time, Event::ResetDone));
                self.scheduled.sort_by_key(|(at, _)| *at);
                Finished
            }
        }
    }

    /// Checks a download before `A0`; returns the data to keep.
    fn check_download(&self, target: &Target, data: Vec<u8>) -> Result<Vec<u8>, A4Reason> {
        let text = ProgramText::new(data).map_err(|_| A4Reason::ProtocolError)?;
        match target {
            Target::Product(name) => {
                if self.selected.as_ref() == Some(name) {
                    return Err(A4Reason::OperationError);
                }
                if !self.programs.contains_key(name) && self.programs.len() >= MAX_PROGRAMS {
                    return Err(A4Reason::OperationError);
                }
            }
            Target::MachineData => {
                ConditionData::parse(text.as_bytes()).map_err(|_| A4Reason::ProtocolError)?;
            }
            _ => {}
        }
        match target.kind().entry_limit() {
            Some(limit) if text.entries() > limit => Err(A4Reason::OperationError),
            _ => Ok(text.into_bytes()),
        }
    }

    /// Stores a download the host closed with `A2`.
    fn commit(&mut self, command: Command, now: Instant) {
        let Command::Download { target, data } = command else {
            return;
        };
        let Ok(text) = ProgramText::new(data) else {
            return;
        };
        match target {
            Target::Product(name) => {
                let date = self.calendar(now).date();
                let steps = text.entries();
                self.programs
                    .insert(name, StoredProgram { text, steps, date });
            }
            Target::MachineData => {
                if let Ok(condition) = ConditionData::parse(text.as_bytes()) {
                    self.condition = condition;
                }
            }
            library => {
                self.libraries.insert(library.kind().describe(), text);
            }
        }
    }

    fn upload(&self, target: &Target) -> Option<Vec<u8>> {
        match target {
            Target::Product(name) => self.programs.get(name).map(|p| p.text.as_bytes().to_vec()),
            Target::MachineData => Some(self.condition.to_text().into_bytes()),
            library => self
                .libraries
                .get(library.kind().describe())
                .map(|t| t.as_bytes().to_vec()),
        }
    }

    fn production_data(&mut self, request: ProductionRequest, now: Instant) -> ProductionData {
        let counters = *self.counter_sets(now).get(request.scope);
        let ongoing = self
            .exhausted_since
            .map_or(0, |since| now.saturating_duration_since(since).as_secs());
        let mut data = ProductionData {
            header: ProductionHeader {
                name: Some(request.code()),
                machine: Some(MACHINE_BM.to_owned()),
                start: Some(self.calendar(counters.since)),
                end: Some(self.calendar(now)),
                format: Some(PANASONIC_FORMAT.to_owned()),
                other: Vec::new(),
            },
            sections: Vec::new(),
        };
        data.set_count(Counter::ProductPlan1, self.config.production_plan.into());
        data.set_count(Counter::ProductPlan2, 0);
        data.set_count(Counter::Product1, counters.boards);
        data.set_count(Counter::Product2, 0);
        let picked = counters.pickups.saturating_sub(counters.misses);
        data.set_rate(RateKind::Pickup, Rate::ratio(picked, counters.pickups));
        data.set_rate(
            RateKind::Mount,
            Rate::ratio(counters.mounts, counters.pickups),
        );
        let figures = [
            (Counter::PartsExhaustCount, counters.exhaust_stops),
            (
                Counter::PartsExhaustTime,
                counters.exhaust_seconds + ongoing,
            ),
            (Counter::Pickup, counters.pickups),
            (Counter::Mount, counters.mounts),
            (Counter::PickupError, counters.pickup_error_stops),
            (Counter::PickupMiss, counters.misses),
            (Counter::RecognitionError1, counters.recognition_errors),
            (Counter::RecognitionError2, 0),
            (Counter::BoardRecognitionError1, 0),
            (Counter::BoardRecognitionError2, 0),
        ];
        for (counter, value) in figures {
            data.set_count(counter, value);
        }
        if request.clear {
            let sets = self.counter_sets(now);
            match request.scope {
                ProductionScope::CurrentTotal => {
                    for scope in [
                        ProductionScope::CurrentTotal,
                        ProductionScope::Nozzle,
                        ProductionScope::Feeder,
                    ] {
                        sets.clear(scope, now);
                    }
                }
                scope => sets.clear(scope, now),
            }
        }
        data
    }

    // -----------------------------------------------------------------------------------
    // Production run

    fn start(&mut self, mode: Option<StopMode>, now: Instant) -> Result<(), TwinError> {
        match self.state {
            RunState::Run => return Err(TwinError::Running),
            RunState::Error => return Err(TwinError::ErrorStop),
            RunState::Ready => {}
        }
        if self.selected_steps() == 0 {
            return Err(TwinError::NothingToRun);
        }
        if let Some(mode) = mode {
            self.stop_mode = mode;
        }
        let due = match self.progress {
            Some(_) => now + self.config.placement_time,
            None => {
                self.progress = Some(Progress {
                    board_started: now,
                    next_block: 0,
                });
                now + self.config.load_time + self.config.placement_time
            }
        };
        self.state = RunState::Run;
        self.due = Some(due);
        self.emit(Event::Started);
        Ok(())
    }

    /// Runs everything due up to `now`, in time order; returns `now`, or the latest time
    /// already reached if `now` is earlier (time never runs backwards).
    fn advance(&mut self, now: Instant) -> Instant {
        let epoch = *self.epoch.get_or_insert(now);
        let now = now.max(self.clock_now.unwrap_or(epoch));
        self.clock_now = Some(now);
        self.counter_sets(epoch);
        loop {
            let scheduled = self
                .scheduled
                .first()
                .map(|(at, _)| *at)
                .filter(|at| *at <= now);
            let block = self.due.filter(|at| *at <= now);
            match (scheduled, block) {
                (Some(at), Some(due)) if at <= due => self.emit_scheduled(),
                (Some(_), None) => self.emit_scheduled(),
                (_, Some(due)) => self.place_block(due),
                (None, None) => break,
            }
        }
        now
    }

    fn emit_scheduled(&mut self) {
        if !self.scheduled.is_empty() {
            let (_, event) = self.scheduled.remove(0);
            self.emit(event);
        }
    }

    /// Places the next block at `at`, with misses, recoveries and exhaustion.
    fn place_block(&mut self, at: Instant) {
        let steps = self.selected_steps();
        let Some(progress) = self.progress.filter(|_| steps > 0) else {
            self.due = None;
            self.state = RunState::Ready;
            return;
        };
        let block = progress.next_block;
        let feeder = block % self.feeders.len();
        let mut t = at;
        loop {
            if !self.has_part(feeder) {
                self.parts_exhausted(block, t);
                return;
            }
            self.count(t, |c| c.pickups += 1);
            if self.rng.f64() >= self.config.miss_rate {
                self.take_part(feeder);
                self.count(t, |c| c.mounts += 1);
                break;
            }
            self.take_part(feeder);
            if self.rng.f64() < MISS_SHARE {
                self.count(t, |c| c.misses += 1);
            } else {
                self.count(t, |c| c.recognition_errors += 1);
            }
            self.emit(Event::RecoveryStarted);
            t += self.config.recovery_time;
            if !self.has_part(feeder) {
                self.parts_exhausted(block, t);
                return;
            }
            let roll = self.rng.f64();
            if roll < RECOVERY_OK_SHARE {
                self.emit(Event::RecoveryOk);
                self.take_part(feeder);
                self.count(t, |c| {
                    c.pickups += 1;
                    c.mounts += 1;
                });
                break;
            } else if roll < RECOVERY_OK_SHARE + RECOVERY_RETRY_SHARE {
                self.emit(Event::RecoveryRetry);
            } else {
                self.emit(Event::RecoveryStop);
                self.count(t, |c| c.pickup_error_stops += 1);
                self.state = RunState::Ready;
                self.due = None;
                return;
            }
        }
        let next_block = block + 1;
        if next_block < steps {
            self.progress = Some(Progress {
                next_block,
                ..progress
            });
            if self.stop_mode == StopMode::OneBlock {
                self.state = RunState::Ready;
                self.due = None;
            } else {
                self.due = Some(t + self.config.placement_time);
            }
            return;
        }
        self.count(t, |c| c.boards += 1);
        let seconds = t
            .saturating_duration_since(progress.board_started)
            .as_secs_f64()
            .round() as u64;
        let time = self
            .config
            .extended_format
            .then(|| BoardTime::saturating(seconds));
        if self.stop_mode == StopMode::Continuous {
            self.emit(Event::BoardFinished { time });
            self.progress = Some(Progress {
                board_started: t,
                next_block: 0,
            });
            self.due = Some(t + self.config.load_time + self.config.placement_time);
        } else {
            self.emit(Event::ProductionFinished { time });
            self.progress = None;
            self.state = RunState::Ready;
            self.due = None;
        }
    }

    fn parts_exhausted(&mut self, block: usize, at: Instant) {
        if let Some(info) = self.error_info(PARTS_EXHAUSTED, block) {
            self.emit(Event::Error(info));
        }
        self.count(at, |c| c.exhaust_stops += 1);
        self.exhausted_since = Some(at);
        self.state = RunState::Error;
        self.due = None;
    }

    /// R2 fields for an error at `block`: step, nozzle and feeder of that block; the
    /// extension (extended format) carries the board number, as the meaning of those six
    /// characters is not in the pages we have \[?\].
    fn error_info(&self, code: u8, block: usize) -> Option<ErrorInfo> {
        let three = |n: usize| u16::try_from(n % 1000).unwrap_or(0);
        let info = ErrorInfo::new(
            code,
            three(block + 1),
            three(block % HEAD_NOZZLES + 1),
            three(block % self.feeders.len() + 1),
        )
        .ok()?;
        if self.config.extended_format {
            let board = self.boards_produced() + 1;
            info.with_detail(&format!("{:06}", board % 1_000_000)).ok()
        } else {
            Some(info)
        }
    }

    fn leave_error(&mut self, now: Instant) {
        if let Some(since) = self.exhausted_since.take() {
            let seconds = now.saturating_duration_since(since).as_secs();
            self.count(now, |c| c.exhaust_seconds += seconds);
        }
        if self.state == RunState::Error {
            self.state = RunState::Ready;
        }
    }

    fn current_block(&self) -> usize {
        self.progress.map_or(0, |p| p.next_block)
    }

    fn selected_steps(&self) -> usize {
        self.selected
            .as_ref()
            .and_then(|name| self.programs.get(name))
            .map_or(0, |p| p.steps)
    }

    fn has_part(&self, feeder: usize) -> bool {
        self.feeders
            .get(feeder)
            .is_some_and(|f| !f.paused && f.remaining > 0)
    }

    fn take_part(&mut self, feeder: usize) {
        if let Some(f) = self.feeders.get_mut(feeder) {
            f.remaining = f.remaining.saturating_sub(1);
        }
    }

    fn feeder_index(&self, feeder: u16) -> Result<usize, TwinError> {
        let feeders = self.config.feeders;
        if (1..=feeders).contains(&feeder) {
            Ok(usize::from(feeder - 1))
        } else {
            Err(TwinError::NoSuchFeeder { feeder, feeders })
        }
    }

    fn counter_sets(&mut self, now: Instant) -> &mut CounterSets {
        self.counters
            .get_or_insert_with(|| CounterSets([Counters::new(now); 4]))
    }

    fn count(&mut self, now: Instant, f: impl Fn(&mut Counters)) {
        self.counter_sets(now).add(f);
    }

    fn calendar(&self, at: Instant) -> Timestamp {
        let epoch = self.epoch.unwrap_or(at);
        self.config
            .clock
            .plus_seconds(at.saturating_duration_since(epoch).as_secs())
    }

    // -----------------------------------------------------------------------------------
    // Port 2 buffer

    fn emit(&mut self, event: Event) {
        if !self.config.events_enabled {
            return;
        }
        tracing::debug!(%event, "R message");
        self.events.push_back(event.to_message());
        if !self.port2_connected {
            self.trim_events();
        }
    }

    fn trim_events(&mut self) {
        while self.events.len() > self.config.event_buffer {
            self.events.pop_front();
            self.dropped_events += 1;
        }
    }
}

/// A demo program of `steps` steps over `feeders` feeders, in the twin's invented step
/// format \[?\].
fn demo_program_text(steps: usize, feeders: u16) -> ProgramText {
    let mut text = format!("%HEADER\r\nNAME={DEMO_PROGRAM}\r\nMACHINE={MACHINE_BM}\r\n%STEP\r\n");
    for step in 0..steps {
        let x = 5.0 + (step % 12) as f64 * 12.5;
        let y = 8.0 + (step / 12) as f64 * 9.0;
        let angle = (step % 4) * 90;
        let z = step % usize::from(feeders.max(1)) + 1;
        text.push_str(&format!(
            "{:04},X{x:06.2},Y{y:06.2},R{angle:03},Z{z:03}\r\n",
            step + 1
        ));
    }
    text.push_str("*\r\n");
    ProgramText::new(text.into_bytes()).expect("the demo text ends with the end mark")
}

#[cfg(test)]
mod tests;
