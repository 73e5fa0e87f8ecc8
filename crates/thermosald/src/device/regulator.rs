//! One regulator: working memory and EEPROM, calibration, sealing cycles and faults.

use std::collections::BTreeSet;
use std::time::{Duration, Instant};

use crate::device::band::{self, BandDesign, Motion, REFERENCE_C, TCR_PER_K};
use crate::diagnostic::{self, Fault};
use crate::frame::{Address, Direction, Frame, MAX_RAW, RawValue};
use crate::request::{Command, Request, Selection, Write};
use crate::tables::{self, Item, Table, machine, runtime, service, settings};

/// The twin's own settings: the packaging machine around the regulator and the physics
/// constants the spec does not give.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegulatorConfig {
    /// Time between the starts of two sealing impulses (the packaging machine's rhythm).
    /// `None` (or zero): no sealing, the band holds the pre-heating temperature.
    pub seal_period: Option<Duration>,
    /// How long the machine asks for sealing heat in each cycle; the regulator cuts it at
    /// the maximum sealing time (machine item 7).
    pub impulse: Duration,
    /// Time constant of the band's cooling toward ambient (Newton's law).
    pub cooling: Duration,
    /// Ambient temperature, °C.
    pub ambient: f64,
    /// How long balancing measures once the band has cooled below the balancing gradient.
    pub measurement: Duration,
}

impl Default for RegulatorConfig {
    /// A 3 s sealing rhythm with 0.8 s impulses, τ = 0.8 s, 20 °C ambient, 3 s measurement.
    fn default() -> Self {
        Self {
            seal_period: Some(Duration::from_secs(3)),
            impulse: Duration::from_millis(800),
            cooling: Duration::from_millis(800),
            ambient: REFERENCE_C,
            measurement: Duration::from_secs(3),
        }
    }
}

/// The result of automatic balancing: the band's resistance at a known temperature. The
/// regulator measures temperature through the band's resistance relative to it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calibration {
    /// Band circuit resistance when balancing measured, Ω.
    pub resistance: f64,
    /// The temperature the band had then, by the settings (item 13), °C.
    pub temperature: f64,
}

/// What a regulator is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// No calibration (after a master reset): diagnostic 35, the band is not fired.
    Uncalibrated,
    /// Automatic balancing: diagnostic 36, the band cools while the regulator measures.
    Balancing,
    /// A latched fault: the band is not fired until the fault is cleared.
    Faulted(Fault),
    /// Heating to or holding the pre-heating temperature.
    PreHeating,
    /// A sealing impulse: heating to or holding the sealing temperature.
    Sealing,
    /// Between impulses, cooling down to the pre-heating temperature.
    Cooling,
}

/// A regulator's state and measurements at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Status {
    /// What it is doing.
    pub phase: Phase,
    /// The fault/warning number (run-time item 2).
    pub fault: u16,
    /// The band's true temperature, °C.
    pub band_temperature: f64,
    /// The temperature the regulator measures through the band's resistance, °C; `None`
    /// with an open band.
    pub measured_temperature: Option<f64>,
    /// Band circuit resistance, Ω (infinite when open).
    pub resistance: f64,
    /// Voltage applied to the band now, V (0 when not fired).
    pub voltage: f64,
    /// Current now, A.
    pub current: f64,
    /// Power now, VA.
    pub power: f64,
    /// The highest current since the current sealing cycle began, A.
    pub peak_current: f64,
}

/// One simulated Thermosald ISC regulator with its sealing band.
///
/// Physics are integrated lazily: every call that takes `now` first brings the band up to
/// that instant (exactly, segment by segment; see [`band`]). An earlier `now` than already
/// seen is treated as the latest seen: model time never runs backwards.
#[derive(Debug, Clone)]
pub struct Regulator {
    config: RegulatorConfig,
    working: Memory,
    eeprom: Memory,
    clock: Instant,
    temperature: f64,
    mode: Mode,
    latched: Option<Fault>,
    provoked: BTreeSet<Fault>,
    peak_current: f64,
}

impl Regulator {
    /// A commissioned regulator at `address`: factory data, calibrated at ambient, saved to
    /// EEPROM, its band at ambient temperature and about to pre-heat; the first sealing
    /// impulse starts one period after `now`.
    pub fn new(address: Address, config: RegulatorConfig, now: Instant) -> Self {
        let mut regulator = Self::from_factory(config, now);
        regulator.working.set_address(address);
        let resistance = regulator.resistance_at(regulator.temperature);
        let ambient = regulator.ambient();
        regulator.working.calibration = Some(Calibration {
            resistance,
            temperature: ambient,
        });
        regulator.eeprom = regulator.working.clone();
        regulator.mode = Mode::Running { origin: now };
        regulator
    }

    /// A regulator as a master reset leaves it: factory data, no address (it answers only
    /// address assignment to `$`), no calibration (diagnostic 35).
    pub fn from_factory(config: RegulatorConfig, now: Instant) -> Self {
        let ambient = if config.ambient.is_finite() {
            config.ambient
        } else {
            REFERENCE_C
        };
        Self {
            config,
            working: Memory::factory(),
            eeprom: Memory::factory(),
            clock: now,
            temperature: ambient,
            mode: Mode::Uncalibrated,
            latched: None,
            provoked: BTreeSet::new(),
            peak_current: 0.0,
        }
    }

    /// The twin's settings.
    pub fn config(&self) -> &RegulatorConfig {
        &self.config
    }

    /// The logic address (machine item 14), `None` until one is assigned after a master
    /// reset.
    pub fn address(&self) -> Option<Address> {
        self.working.address()
    }

    /// Whether the serial interface answers (machine item 13 = 1).
    pub fn serial_enabled(&self) -> bool {
        self.working.get(Table::Machine, machine::SERIAL_ENABLING) != RawValue::ZERO
    }

    /// The working calibration, if balanced.
    pub fn calibration(&self) -> Option<Calibration> {
        self.working.calibration
    }

    /// A table's values at `now`, as message 51/52/53/58 would return them.
    pub fn table(&mut self, table: Table, now: Instant) -> Vec<RawValue> {
        self.advance(now);
        self.table_now(table)
    }

    /// A table's values as saved in EEPROM (run-time data: empty).
    pub fn eeprom(&self, table: Table) -> Vec<RawValue> {
        self.eeprom.table(table).to_vec()
    }

    /// State and measurements at `now`.
    pub fn status(&mut self, now: Instant) -> Status {
        self.advance(now);
        self.status_now()
    }

    /// The fault/warning number at `now` (run-time item 2).
    pub fn fault_number(&mut self, now: Instant) -> u16 {
        self.advance(now);
        self.fault_code()
    }

    /// Provokes the physical cause of `fault` at `now`:
    ///
    /// - [`Fault::OpenBand`]: the band breaks (infinite resistance); latched at once;
    /// - [`Fault::ShortCircuit`]: 70 % of the band is bypassed ([`SHORTED_SHARE`] remains),
    ///   so its resistance drops below the calibrated value divided by the partial
    ///   short-circuit factor; latched at once;
    /// - [`Fault::OverCurrent`]: the supply gives [`OVER_VOLTAGE`] × the set voltage (wrong
    ///   transformer tap), so `U / R` exceeds the set maximum current; latched as soon as
    ///   the band is fired;
    /// - [`Fault::TemperatureNotReached`]: the supply sags to [`WEAK_SUPPLY`] × the set
    ///   voltage, so the band heats at a tenth of the ramp; latched at the end of the next
    ///   sealing impulse that falls short of the sealing temperature.
    pub fn provoke(&mut self, fault: Fault, now: Instant) {
        self.advance(now);
        self.provoked.insert(fault);
        tracing::info!(address = ?self.address(), ?fault, "fault cause provoked");
        self.detect();
    }

    /// Removes the physical cause of `fault`. A latched fault stays until cleared (14).
    pub fn remove_cause(&mut self, fault: Fault, now: Instant) {
        self.advance(now);
        self.provoked.remove(&fault);
        tracing::info!(address = ?self.address(), ?fault, "fault cause removed");
        self.detect();
    }

    /// Switches the regulator off and on at `now`: working data reload from EEPROM,
    /// latched faults are forgotten (and found again if their cause is still there), the
    /// sealing rhythm restarts. The band keeps its temperature.
    pub fn power_cycle(&mut self, now: Instant) {
        self.advance(now);
        self.working = self.eeprom.clone();
        self.latched = None;
        self.peak_current = 0.0;
        self.mode = match self.working.calibration {
            Some(_) => Mode::Running { origin: self.clock },
            None => Mode::Uncalibrated,
        };
        tracing::info!(address = ?self.address(), "power cycle: EEPROM data reloaded");
        self.detect();
    }

    /// Answers a request addressed to this regulator at `now` (the end of the question):
    /// the echo or the data, with the question's address. `None`: silence.
    pub(crate) fn respond(
        &mut self,
        query: &Frame,
        request: &Request,
        now: Instant,
    ) -> Option<Frame> {
        self.advance(now);
        let echo = query.clone().with_direction(Direction::Reply);
        let reply = match request {
            Request::SetAddress(address) => {
                self.working.set_address(*address);
                tracing::info!(%address, "logic address set (volatile until saved)");
                Some(echo)
            }
            Request::Read(read) => {
                let table = self.table_now(read.table());
                let data = match read.selection() {
                    Selection::All => table,
                    Selection::Item(item) => table
                        .get(usize::from(item.index()))
                        .copied()
                        .into_iter()
                        .collect(),
                };
                echo.with_data(data).ok()
            }
            Request::Write(write) => {
                let held = self.write(write);
                echo.with_data(held).ok()
            }
            Request::Command(command) => {
                self.command(*command);
                Some(echo)
            }
        };
        self.detect();
        reply
    }

    fn write(&mut self, write: &Write) -> Vec<RawValue> {
        let table = write.table();
        for (item, raw) in write.values() {
            if self.accepts(item, raw) {
                self.working.set(table, item.index(), raw);
                if table == Table::Machine && item.index() == machine::ADDRESS {
                    self.working.addressed = true;
                }
            } else if write.selection() != Selection::All || item.writable() {
                let held = self.working.get(table, item.index());
                tracing::debug!(%table, item = item.name(), %raw, %held, "value refused; the echo shows the value kept");
            }
        }
        if table == Table::Service {
            self.working.recompute_theoretical();
        }
        write
            .values()
            .map(|(item, _)| self.working.get(table, item.index()))
            .collect()
    }

    /// Whether the regulator stores `raw` in `item`: writable, in range, and set points not
    /// above the maximum working temperature.
    fn accepts(&self, item: &Item, raw: RawValue) -> bool {
        if !item.writable() || !item.accepts(raw) {
            return false;
        }
        let is_set_point = item.table() == Table::Settings
            && matches!(
                item.index(),
                settings::PRE_HEATING_TEMPERATURE | settings::SEALING_TEMPERATURE
            );
        !is_set_point
            || raw
                <= self
                    .working
                    .get(Table::Settings, settings::MAXIMUM_WORKING_TEMPERATURE)
    }

    fn command(&mut self, command: Command) {
        let now = self.clock;
        match command {
            Command::ClearFaults => self.clear_faults(now),
            Command::Balance => self.start_balancing(now),
            Command::SaveEeprom => {
                self.eeprom = self.working.clone();
                tracing::info!(address = ?self.address(), "working data saved to EEPROM");
            }
            Command::LoadEeprom => {
                self.working = self.eeprom.clone();
                self.mode = match (self.working.calibration, self.mode) {
                    (None, _) => Mode::Uncalibrated,
                    (Some(_), Mode::Uncalibrated) => Mode::Running { origin: now },
                    (Some(_), mode) => mode,
                };
                tracing::info!(address = ?self.address(), "working data loaded from EEPROM");
            }
            Command::MasterReset => {
                self.working = Memory::factory();
                self.eeprom = Memory::factory();
                self.latched = None;
                self.peak_current = 0.0;
                self.mode = Mode::Uncalibrated;
                tracing::info!("master reset: factory data, no address, calibration request (35)");
            }
        }
    }

    fn clear_faults(&mut self, now: Instant) {
        let Some(fault) = self.latched else { return };
        if self.cause_present(fault) {
            tracing::debug!(
                ?fault,
                "clear faults: the cause is still there, the fault stays"
            );
            return;
        }
        self.latched = None;
        if let Mode::Running { .. } = self.mode {
            self.mode = Mode::Running { origin: now };
        }
        tracing::info!(?fault, "fault cleared");
    }

    /// Balancing waits until the band cools slower than the balancing gradient (settings
    /// item 12, °C per 10 s; at least 1): with Newton cooling the gradient is `(T − Tₐ)/τ`,
    /// so the wait is `τ × ln((T − Tₐ) / (g × τ / 10 s))`. Then it measures for
    /// [`RegulatorConfig::measurement`].
    fn start_balancing(&mut self, now: Instant) {
        if let Some(fault) = self.latched {
            tracing::warn!(?fault, "balancing refused while a fault is latched");
            return;
        }
        let gradient_per_s = self
            .working
            .value(Table::Settings, settings::COOLING_GRADIENT)
            .max(1.0)
            / 10.0;
        let tau = self.tau().as_secs_f64();
        let stable_excess = gradient_per_s * tau;
        let excess = self.temperature - self.ambient();
        let wait = if excess > stable_excess {
            tau * (excess / stable_excess).ln()
        } else {
            0.0
        };
        let wait = Duration::try_from_secs_f64(wait).unwrap_or(Duration::ZERO);
        // A measurement time too long for the clock: balancing cannot end.
        let Some(until) = now.checked_add(wait.saturating_add(self.config.measurement)) else {
            tracing::warn!(measurement = ?self.config.measurement, "balancing measurement time out of range");
            return;
        };
        self.mode = Mode::Balancing { until };
        tracing::info!(?wait, measurement = ?self.config.measurement, "automatic balancing started (36)");
    }

    /// Brings the band up to `now`, segment by segment: each segment ends at the next
    /// control change (impulse end, cycle start, balancing end) or when the band reaches a
    /// set point, whichever is first.
    fn advance(&mut self, now: Instant) {
        loop {
            self.detect();
            let t = self.clock;
            if t >= now {
                return;
            }
            let control = self.control(t);
            let motion = self.motion(&control);
            if motion.fired() {
                self.peak_current = self.peak_current.max(self.current_fired(self.temperature));
            }
            let reached = motion
                .reaches_after(self.temperature, self.ambient(), self.tau())
                .and_then(|after| t.checked_add(after));
            let event_at = control.event.map(|(at, _)| at);
            let end = [Some(now), reached, event_at]
                .into_iter()
                .flatten()
                .min()
                .unwrap_or(now);
            self.temperature = if reached == Some(end) {
                motion.end_temperature(self.temperature)
            } else {
                motion.after(self.temperature, end - t, self.ambient(), self.tau())
            };
            self.clock = end;
            if let Some((at, event)) = control.event
                && at == end
            {
                self.on_event(event, end);
            }
        }
    }

    fn on_event(&mut self, event: Event, at: Instant) {
        match event {
            Event::CycleStart => self.peak_current = 0.0,
            Event::ImpulseEnd => {
                let set_point = self
                    .working
                    .value(Table::Settings, settings::SEALING_TEMPERATURE);
                let measured = self.measured(self.temperature).unwrap_or(f64::NEG_INFINITY);
                if measured < set_point - NOT_REACHED_TOLERANCE_C && self.latched.is_none() {
                    tracing::warn!(
                        measured,
                        set_point,
                        "sealing temperature not reached within the impulse"
                    );
                    self.latched = Some(Fault::TemperatureNotReached);
                }
            }
            Event::BalancingDone => {
                let resistance = self.resistance_at(self.temperature);
                if resistance.is_finite() && resistance > 0.0 {
                    let temperature = self
                        .working
                        .value(Table::Settings, settings::BALANCING_TEMPERATURE);
                    self.working.calibration = Some(Calibration {
                        resistance,
                        temperature,
                    });
                    self.mode = Mode::Running { origin: at };
                    tracing::info!(resistance, temperature, "automatic balancing done");
                } else {
                    self.mode = Mode::Uncalibrated;
                    tracing::warn!("automatic balancing found no band to measure");
                }
            }
        }
    }

    /// Latches the most serious fault whose cause is present (over-current only while the
    /// band is fired). Temperature not reached is latched at an impulse's end instead.
    fn detect(&mut self) {
        if self.latched.is_some() {
            return;
        }
        let fired = self.motion(&self.control(self.clock)).fired();
        let found = [Fault::OpenBand, Fault::ShortCircuit, Fault::OverCurrent]
            .into_iter()
            .find(|&fault| (fault != Fault::OverCurrent || fired) && self.cause_present(fault));
        if let Some(fault) = found {
            tracing::warn!(address = ?self.address(), ?fault, code = fault.code(), "fault latched");
            self.latched = Some(fault);
        }
    }

    fn cause_present(&self, fault: Fault) -> bool {
        match fault {
            Fault::OpenBand => !self.r20().is_finite(),
            Fault::ShortCircuit => {
                let factor = self
                    .working
                    .value(Table::Machine, machine::PARTIAL_SHORT_CIRCUIT_FACTOR)
                    .max(1.0);
                let resistance = self.resistance_at(self.temperature);
                resistance.is_finite() && resistance < self.reference().resistance / factor
            }
            Fault::OverCurrent => {
                self.current_fired(self.temperature)
                    > self
                        .working
                        .value(Table::Service, service::SET_MAXIMUM_CURRENT)
            }
            Fault::TemperatureNotReached => self.provoked.contains(&Fault::TemperatureNotReached),
        }
    }

    /// What the regulator aims for at `t`, and the next control change.
    fn control(&self, t: Instant) -> Control {
        let off = |event| Control {
            stage: Stage::Off,
            target: None,
            event,
        };
        if self.latched.is_some() {
            return off(None);
        }
        let origin = match self.mode {
            Mode::Uncalibrated => return off(None),
            Mode::Balancing { until } => return off(Some((until, Event::BalancingDone))),
            Mode::Running { origin } => origin,
        };
        let pre_heat = self.true_for(
            self.working
                .value(Table::Settings, settings::PRE_HEATING_TEMPERATURE),
        );
        let Some(period) = self.period() else {
            return Control {
                stage: Stage::PreHeat,
                target: pre_heat,
                event: None,
            };
        };
        let since = t.saturating_duration_since(origin);
        let into_cycle = Duration::from_nanos((since.as_nanos() % period.as_nanos()) as u64);
        let cycle_start = t - into_cycle;
        // The impulse is at most the maximum sealing time (99.9 s): no overflow.
        let impulse_end = cycle_start + self.impulse();
        if since >= period && t < impulse_end {
            let seal = self.true_for(
                self.working
                    .value(Table::Settings, settings::SEALING_TEMPERATURE),
            );
            Control {
                stage: Stage::Seal,
                target: seal,
                event: Some((impulse_end, Event::ImpulseEnd)),
            }
        } else {
            Control {
                stage: Stage::PreHeat,
                target: pre_heat,
                event: cycle_start
                    .checked_add(period)
                    .map(|at| (at, Event::CycleStart)),
            }
        }
    }

    fn motion(&self, control: &Control) -> Motion {
        Motion::choose(
            self.temperature,
            control.target,
            self.ramp_rate(),
            self.ambient(),
        )
    }

    fn status_now(&self) -> Status {
        let control = self.control(self.clock);
        let motion = self.motion(&control);
        let phase = match (self.latched, self.mode, control.stage) {
            (Some(fault), _, _) => Phase::Faulted(fault),
            (None, Mode::Uncalibrated, _) => Phase::Uncalibrated,
            (None, Mode::Balancing { .. }, _) => Phase::Balancing,
            (None, Mode::Running { .. }, Stage::Seal) => Phase::Sealing,
            (None, Mode::Running { .. }, _) if !motion.fired() => Phase::Cooling,
            (None, Mode::Running { .. }, _) => Phase::PreHeating,
        };
        let resistance = self.resistance_at(self.temperature);
        let (voltage, current) = if motion.fired() {
            (
                self.supplied_voltage(),
                self.current_fired(self.temperature),
            )
        } else {
            (0.0, 0.0)
        };
        Status {
            phase,
            fault: self.fault_code(),
            band_temperature: self.temperature,
            measured_temperature: self.measured(self.temperature),
            resistance,
            voltage,
            current,
            power: voltage * current,
            peak_current: self.peak_current,
        }
    }

    fn fault_code(&self) -> u16 {
        match (self.latched, self.mode) {
            (Some(fault), _) => fault.code(),
            (None, Mode::Uncalibrated) => diagnostic::CALIBRATION_REQUEST,
            (None, Mode::Balancing { .. }) => diagnostic::CALIBRATION_IN_PROGRESS,
            (None, Mode::Running { .. }) => diagnostic::NONE,
        }
    }

    /// Run-time data (53) from the status:
    /// temperature = measured °C (0 with an open band); fault number; maximum current =
    /// peak A × 10; resistance = Ω × 100 (999 when open); voltage V; power = VA / 10.
    fn runtime_now(&self) -> Vec<RawValue> {
        let status = self.status_now();
        let resistance = if status.resistance.is_finite() {
            status.resistance * 100.0
        } else {
            f64::from(MAX_RAW)
        };
        let mut values = vec![RawValue::ZERO; tables::RUNTIME_ITEMS];
        let mut put = |index: u8, value: f64| {
            if let Some(slot) = values.get_mut(usize::from(index)) {
                *slot = RawValue::saturating(value);
            }
        };
        put(
            runtime::TEMPERATURE,
            status.measured_temperature.unwrap_or(0.0),
        );
        put(runtime::FAULT, f64::from(status.fault));
        put(runtime::MAXIMUM_CURRENT, status.peak_current * 10.0);
        put(runtime::RESISTANCE, resistance);
        put(runtime::VOLTAGE, status.voltage);
        put(runtime::POWER, status.power / 10.0);
        values
    }

    fn table_now(&self, table: Table) -> Vec<RawValue> {
        match table {
            Table::Runtime => self.runtime_now(),
            other => self.working.table(other).to_vec(),
        }
    }

    // --- physics helpers -------------------------------------------------------------

    fn ambient(&self) -> f64 {
        if self.config.ambient.is_finite() {
            self.config.ambient
        } else {
            REFERENCE_C
        }
    }

    fn tau(&self) -> Duration {
        self.config.cooling.max(Duration::from_millis(1))
    }

    fn period(&self) -> Option<Duration> {
        self.config.seal_period.filter(|p| !p.is_zero())
    }

    /// The sealing impulse: the machine's demand, cut at the maximum sealing time.
    fn impulse(&self) -> Duration {
        let limit = self
            .working
            .value(Table::Machine, machine::MAXIMUM_SEALING_TIME);
        let limit = Duration::try_from_secs_f64(limit).unwrap_or(Duration::ZERO);
        self.config.impulse.min(limit)
    }

    /// The band circuit at 20 °C, with any provoked open or short.
    fn r20(&self) -> f64 {
        if self.provoked.contains(&Fault::OpenBand) {
            return f64::INFINITY;
        }
        let design = BandDesign::from_service(self.working.table(Table::Service)).resistance_20();
        if self.provoked.contains(&Fault::ShortCircuit) {
            design * SHORTED_SHARE
        } else {
            design
        }
    }

    fn resistance_at(&self, temperature: f64) -> f64 {
        band::resistance_at(self.r20(), temperature)
    }

    /// Supply factor of the provoked supply troubles.
    fn supply_factor(&self) -> f64 {
        let mut factor = 1.0;
        if self.provoked.contains(&Fault::OverCurrent) {
            factor *= OVER_VOLTAGE;
        }
        if self.provoked.contains(&Fault::TemperatureNotReached) {
            factor *= WEAK_SUPPLY;
        }
        factor
    }

    /// The voltage on the band when fired: set voltage (service item 15) × supply factor.
    fn supplied_voltage(&self) -> f64 {
        self.working.value(Table::Service, service::SET_VOLTAGE) * self.supply_factor()
    }

    /// `I = U / R(T)` when fired.
    fn current_fired(&self, temperature: f64) -> f64 {
        let resistance = self.resistance_at(temperature);
        if resistance.is_finite() && resistance > 0.0 {
            self.supplied_voltage() / resistance
        } else {
            0.0
        }
    }

    /// Machine item 1 is degrees per 10 ms; a weak supply (power ∝ U²) slows it, a strong
    /// one cannot speed it up (the regulator follows its ramp).
    fn ramp_rate(&self) -> f64 {
        let per_10ms = self.working.value(Table::Machine, machine::HEATING_RAMP);
        per_10ms * 100.0 * self.supply_factor().powi(2).min(1.0)
    }

    /// The calibration, or before balancing the design's resistance at 20 °C.
    fn reference(&self) -> Calibration {
        self.working.calibration.unwrap_or_else(|| Calibration {
            resistance: BandDesign::from_service(self.working.table(Table::Service))
                .resistance_20(),
            temperature: REFERENCE_C,
        })
    }

    /// The regulator's measurement: `M = T_ref + (R(T) / R_ref − 1) / α`.
    fn measured(&self, temperature: f64) -> Option<f64> {
        let reference = self.reference();
        let resistance = self.resistance_at(temperature);
        let measured =
            reference.temperature + (resistance / reference.resistance - 1.0) / TCR_PER_K;
        (resistance.is_finite() && measured.is_finite()).then_some(measured)
    }

    /// The true temperature at which the regulator measures `measured`: the inverse of
    /// [`Self::measured`]. `None` if the band cannot be measured.
    fn true_for(&self, measured: f64) -> Option<f64> {
        let reference = self.reference();
        let resistance =
            reference.resistance * (1.0 + TCR_PER_K * (measured - reference.temperature));
        let r20 = self.r20();
        let temperature = REFERENCE_C + (resistance / r20 - 1.0) / TCR_PER_K;
        (r20 > 0.0 && temperature.is_finite()).then_some(temperature)
    }
}

/// The voltage factor of a provoked over-current (a wrong transformer tap).
pub const OVER_VOLTAGE: f64 = 1.5;
/// The voltage factor of a provoked weak supply (temperature not reached).
pub const WEAK_SUPPLY: f64 = 0.3;
/// The share of the band's resistance left by a provoked short circuit.
pub const SHORTED_SHARE: f64 = 0.3;
/// How far below the sealing set point an impulse may end before "temperature not reached".
pub const NOT_REACHED_TOLERANCE_C: f64 = 1.0;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    Uncalibrated,
    Balancing { until: Instant },
    Running { origin: Instant },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stage {
    Off,
    PreHeat,
    Seal,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Event {
    CycleStart,
    ImpulseEnd,
    BalancingDone,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Control {
    stage: Stage,
    /// The true temperature aimed for; `None`: the band is not fired.
    target: Option<f64>,
    event: Option<(Instant, Event)>,
}

/// Working data or the EEPROM copy: the three writable tables, whether an address has been
/// assigned, and the calibration.
#[derive(Debug, Clone, PartialEq)]
struct Memory {
    machine: Vec<RawValue>,
    settings: Vec<RawValue>,
    service: Vec<RawValue>,
    addressed: bool,
    calibration: Option<Calibration>,
}

impl Memory {
    /// Factory data: the twin's defaults (the spec refers to the use and maintenance manual
    /// for them), no address, no calibration.
    fn factory() -> Self {
        let raw = |values: &[u16]| {
            values
                .iter()
                .map(|&v| RawValue::saturating(f64::from(v)))
                .collect()
        };
        let mut memory = Self {
            machine: raw(&FACTORY_MACHINE),
            settings: raw(&FACTORY_SETTINGS),
            service: raw(&FACTORY_SERVICE),
            addressed: false,
            calibration: None,
        };
        memory.recompute_theoretical();
        memory
    }

    fn table(&self, table: Table) -> &[RawValue] {
        match table {
            Table::Machine => &self.machine,
            Table::Settings => &self.settings,
            Table::Service => &self.service,
            Table::Runtime => &[],
        }
    }

    fn get(&self, table: Table, index: u8) -> RawValue {
        self.table(table)
            .get(usize::from(index))
            .copied()
            .unwrap_or(RawValue::ZERO)
    }

    /// The scaled value of an item.
    fn value(&self, table: Table, index: u8) -> f64 {
        table
            .item(index)
            .map_or(0.0, |item| item.from_raw(self.get(table, index)))
    }

    fn set(&mut self, table: Table, index: u8, raw: RawValue) {
        let values = match table {
            Table::Machine => &mut self.machine,
            Table::Settings => &mut self.settings,
            Table::Service => &mut self.service,
            Table::Runtime => return,
        };
        if let Some(slot) = values.get_mut(usize::from(index)) {
            *slot = raw;
        }
    }

    fn address(&self) -> Option<Address> {
        let raw = self.get(Table::Machine, machine::ADDRESS).get();
        self.addressed
            .then(|| u8::try_from(raw).ok().and_then(|a| Address::new(a).ok()))
            .flatten()
    }

    fn set_address(&mut self, address: Address) {
        self.set(
            Table::Machine,
            machine::ADDRESS,
            RawValue::saturating(f64::from(address.get())),
        );
        self.addressed = true;
    }

    /// Service items 9–12 from the band design (see [`band`]).
    fn recompute_theoretical(&mut self) {
        let design = BandDesign::from_service(&self.service);
        let raws = [
            (service::THEORETICAL_CURRENT, design.theoretical_current()),
            (
                service::THEORETICAL_RESISTANCE,
                design.resistance_20() * 100.0,
            ),
            (service::THEORETICAL_VOLTAGE, design.theoretical_voltage()),
            (
                service::THEORETICAL_POWER,
                design.theoretical_power() / 10.0,
            ),
        ];
        for (index, value) in raws {
            let value = if value.is_finite() {
                value
            } else {
                f64::from(MAX_RAW)
            };
            self.set(Table::Service, index, RawValue::saturating(value));
        }
    }
}

/// Factory machine data: ramp 2 °C/10 ms, KV 10, KINT 5.0, threshold 20, unit 0 (°C),
/// 50 Hz, maximum sealing time 2.0 s, partial short-circuit factor 1.5, nominal 40 A,
/// serial enabled, address 0, burn-in 200 °C for 60 s, item 23 = 1 (the spec's `(0001)`).
const FACTORY_MACHINE: [u16; tables::MACHINE_ITEMS] = [
    0, 2, 10, 50, 20, 0, 50, 20, 15, 0, 40, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 200, 60, 1, 0,
];
/// Factory settings: heating factor 1.00, maximum working temperature 250 °C, balancing
/// gradient 5 °C/10 s at 20 °C, pre-heating 80 °C, sealing 180 °C.
const FACTORY_SETTINGS: [u16; tables::SETTINGS_ITEMS] =
    [0, 0, 0, 0, 0, 100, 0, 0, 0, 0, 0, 250, 5, 20, 80, 180];
/// Factory service data: one 5.0 × 0.20 × 500 mm band of 0.500 Ω·mm²/m at 40 A/mm²,
/// duty cycle 50.0 %; (9–12 computed: 40 A, 0.25 Ω, 10 V, 400 VA); set maximum current
/// 45 A, set resistance 0.25 Ω, set voltage 10 V, set power 450 VA.
const FACTORY_SERVICE: [u16; tables::SERVICE_ITEMS] = [
    50, 20, 0, 500, 1, 1, 500, 40, 500, 0, 0, 0, 0, 45, 25, 10, 45,
];

#[cfg(test)]
mod tests;
