//! A JBC JTSE hot-air station as a pure model: frames in, replies out, time as a parameter.
//!
//! The [`Station`] answers the robot exactly as the spec (and `specs/README.md`) says:
//! acknowledgements with the station's address as source and the robot's as target, NAKs
//! that echo the refused code and carry the communication-error number. Behind the
//! protocol sits a small physical model, integrated lazily from the last time seen to the
//! `now` of each call, so tests can run hours of station time in microseconds:
//!
//! - With the tool on (`WPS1 00001`), the air heats toward the selected temperature plus the
//!   tool's adjust temperature with a first-order lag ([`TAU_HEAT`]); the power (‰) is a
//!   holding share that grows with set point and air flow, plus a proportional part that
//!   saturates at 1000 ‰ when the air is far below the set point.
//! - With the tool off, the air pump cools the tool ([`TAU_COOL`]) and the port status shows
//!   cooling until the air is below [`COOLING_UNTIL`]; below that the tool cools in still air
//!   ([`TAU_NATURAL`]).
//! - The external thermocouple (on the board) follows the air with more lag ([`TAU_BOARD`]),
//!   reaching a share of the air's rise over ambient that grows with the air flow.
//! - Counters: plugged hours (a tool is connected), work hours (the heater works), tool
//!   cycles (the robot turns the tool on), suction cycles (the vacuum pick-up turns on).
//!
//! Not modelled: regulation on the external thermocouple and profile mode (the selected
//! external temperature and the work mode are stored, limited and read back), sleep and
//! hibernation (the spec says the robot decides the tool status).
//!
//! # Refusals, in the order they are checked
//!
//! 1. Bytes that are not a frame at all (noise, a start without an end): silence.
//! 2. With addresses on (factory default): a frame whose target is not the station's
//!    address, or that has no addresses, or whose addresses are damaged: silence (it cannot
//!    be known to be for this station). Without addresses: every frame is for the station
//!    (the line is point to point).
//! 3. A damaged frame: NAK 1 (BCC) or NAK 2 (length, header, address or data bytes), echoing
//!    the code as received; a frame too damaged to show a printable code: silence.
//! 4. An `A` or `N` frame: silence (a station never answers an answer, which also keeps two
//!    models wired together from talking forever).
//! 5. Without addresses on, a frame that carries addresses: NAK 2 (a wrong length for this
//!    station's form).
//! 6. `R` with data or `W` without data: NAK 2.
//! 7. Robot mode off: NAK 5.
//! 8. A code the station does not know (also `ST3` and other ports, `A10`, lower case),
//!    a read of a write-only code, a write of a read-only code: NAK 4.
//! 9. A write whose data is not a number: NAK 2; a value outside the limits: NAK 3.
//!
//! Damaged frames (1, 2) are checked before robot mode (NAK 5): the data link layer answers
//! them before the application layer sees anything.

use std::ops::RangeInclusive;
use std::time::{Duration, Instant};

use wire::Codec;
use wire::device::{Model, Transmit};

use crate::code::{Code, NakReason, PortStatus, StationError, Tool, ToolError, WorkMode};
use crate::frame::{
    Address, DATA_MAX, DATA_MIN, Data, DecodeError, Frame, FrameCodec, Header, RawCode, Route,
};
use crate::message::Reply;

/// How long the station takes to answer a frame (processing only; the line's byte time is
/// added by whoever serves the model).
pub const REPLY_DELAY: Duration = Duration::from_millis(5);

/// The model name the station answers to `RSMN` (sent right-aligned: `" JTSE"`).
pub const MODEL_NAME: &str = "JTSE";

/// Room temperature the tool and the board start at and cool toward (°C).
pub const AMBIENT_CELSIUS: f64 = 25.0;

/// Air temperatures the station can select and limit (°C): `MIT` and `MAT` stay inside.
pub const AIR_TEMP_RANGE: RangeInclusive<i32> = 150..=450;
/// Air flows the station can select and limit (%): `MIF` and `MAF` stay inside.
pub const AIR_FLOW_RANGE: RangeInclusive<i32> = 10..=100;
/// External temperatures the station can select and limit (°C): `MIE` and `MAE` stay inside.
pub const EXTERNAL_TEMP_RANGE: RangeInclusive<i32> = 25..=450;
/// Adjust temperatures a tool accepts (°C), the offset between the thermocouple and the
/// temperature at the nozzle.
pub const ADJUST_TEMP_RANGE: RangeInclusive<i32> = -50..=50;

/// Time constant of the air heating toward the set point.
pub const TAU_HEAT: Duration = Duration::from_secs(5);
/// Time constant of the air cooling while the pump blows (cooling on).
pub const TAU_COOL: Duration = Duration::from_secs(12);
/// Time constant of the tool cooling in still air (tool off, cooling off).
pub const TAU_NATURAL: Duration = Duration::from_secs(90);
/// Time constant of the board (external thermocouple) following the air.
pub const TAU_BOARD: Duration = Duration::from_secs(30);
/// The pump keeps cooling the tool until the air is below this (°C).
pub const COOLING_UNTIL: f64 = 100.0;

/// Longest integration step; the model is integrated in steps no longer than this.
const MAX_STEP: f64 = 0.25;
/// When air and board are this close to where they are heading, they are put there and
/// integration stops early (so idle hours cost nothing).
const SETTLED: f64 = 0.005;
/// The board's share of the air's rise over ambient at the lowest and highest air flow.
const BOARD_SHARE: RangeInclusive<f64> = 0.5..=0.9;
/// Holding power per degree of set point above ambient, at full air flow (‰/°C).
const HOLD_PERMILLE_PER_DEGREE: f64 = 2.0;
/// Share of the holding power that does not depend on the air flow.
const HOLD_BASE_SHARE: f64 = 0.4;
/// Proportional power per degree below the set point (‰/°C).
const GAIN_PERMILLE_PER_DEGREE: f64 = 8.0;
/// Full power.
const FULL_POWER: f64 = 1000.0;
/// Seconds in an hour, for the hour counters.
const SECONDS_PER_HOUR: u64 = 3600;

/// How a [`Station`] starts.
#[derive(Debug, Clone, PartialEq)]
pub struct StationConfig {
    /// The station's address, or `None` for the form without address.
    pub address: Option<Address>,
    /// Whether robot mode is on (otherwise every command gets NAK 5).
    pub robot_mode: bool,
    /// The tool connected at start.
    pub tool: Tool,
    /// Room temperature (°C).
    pub ambient_celsius: f64,
    /// Processing time before each reply.
    pub reply_delay: Duration,
}

impl Default for StationConfig {
    /// Factory settings: address 01, robot mode on, a JT tool, 25 °C, [`REPLY_DELAY`].
    fn default() -> Self {
        StationConfig {
            address: Some(Address::STATION),
            robot_mode: true,
            tool: Tool::Jt,
            ambient_celsius: AMBIENT_CELSIUS,
            reply_delay: REPLY_DELAY,
        }
    }
}

/// The station's parameters: what `WRSP` restores to factory values (all of it) and `WRST`
/// resets in part (limits and work mode).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Settings {
    /// Selected air temperature (°C), within [`Self::min_air_temp`]..=[`Self::max_air_temp`].
    pub air_temp: i32,
    /// Selected air flow (%), within the air flow limits.
    pub air_flow: i32,
    /// Selected external temperature (°C), within the external limits.
    pub external_temp: i32,
    /// Work mode.
    pub work_mode: WorkMode,
    /// Adjust temperature of the JT tool (°C).
    pub adjust_jt: i32,
    /// Adjust temperature of the TE tool (°C).
    pub adjust_te: i32,
    /// Highest selectable air temperature (°C).
    pub max_air_temp: i32,
    /// Lowest selectable air temperature (°C).
    pub min_air_temp: i32,
    /// Highest selectable air flow (%).
    pub max_air_flow: i32,
    /// Lowest selectable air flow (%).
    pub min_air_flow: i32,
    /// Highest selectable external temperature (°C).
    pub max_external_temp: i32,
    /// Lowest selectable external temperature (°C).
    pub min_external_temp: i32,
}

impl Settings {
    /// Factory values: 350 °C, 50 % flow, 150 °C external, manual mode, no adjustment, and
    /// the full ranges as limits except external (50–350 °C).
    pub const FACTORY: Settings = Settings {
        air_temp: 350,
        air_flow: 50,
        external_temp: 150,
        work_mode: WorkMode::Manual,
        adjust_jt: 0,
        adjust_te: 0,
        max_air_temp: *AIR_TEMP_RANGE.end(),
        min_air_temp: *AIR_TEMP_RANGE.start(),
        max_air_flow: *AIR_FLOW_RANGE.end(),
        min_air_flow: *AIR_FLOW_RANGE.start(),
        max_external_temp: 350,
        min_external_temp: 50,
    };

    /// What `WRST` does: limits and work mode back to factory, selections kept but pulled
    /// inside the restored limits.
    fn reset_settings(&mut self) {
        let factory = Settings::FACTORY;
        self.max_air_temp = factory.max_air_temp;
        self.min_air_temp = factory.min_air_temp;
        self.max_air_flow = factory.max_air_flow;
        self.min_air_flow = factory.min_air_flow;
        self.max_external_temp = factory.max_external_temp;
        self.min_external_temp = factory.min_external_temp;
        self.work_mode = factory.work_mode;
        self.clamp_selections();
    }

    /// Pulls the selections inside the limits (after a limit moved).
    fn clamp_selections(&mut self) {
        self.air_temp = self.air_temp.clamp(self.min_air_temp, self.max_air_temp);
        self.air_flow = self.air_flow.clamp(self.min_air_flow, self.max_air_flow);
        self.external_temp = self
            .external_temp
            .clamp(self.min_external_temp, self.max_external_temp);
    }

    fn adjust(&self, tool: Tool) -> i32 {
        match tool {
            Tool::Jt => self.adjust_jt,
            Tool::Te => self.adjust_te,
            Tool::None => 0,
        }
    }
}

impl Default for Settings {
    fn default() -> Self {
        Settings::FACTORY
    }
}

/// The station's counters, as `OH1`, `WH1`, `TC1`, `SC1` read them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Counters {
    /// Whole hours with a tool plugged in.
    pub plugged_hours: u64,
    /// Whole hours with the heater working.
    pub work_hours: u64,
    /// Times the robot turned the tool on.
    pub tool_cycles: u64,
    /// Times the suction turned on.
    pub suction_cycles: u64,
}

/// A simulated JBC JTSE station. See the module documentation for its behaviour.
#[derive(Debug, Clone)]
pub struct Station {
    config: StationConfig,
    robot_mode: bool,
    settings: Settings,
    tool: Tool,
    tool_error: ToolError,
    station_error: StationError,
    tool_on: bool,
    suction: bool,
    air: f64,
    board: f64,
    last: Option<Instant>,
    plugged: Duration,
    working: Duration,
    tool_cycles: u64,
    suction_cycles: u64,
}

impl Station {
    /// A station at rest at room temperature, with factory settings and the tool off.
    pub fn new(config: StationConfig) -> Station {
        Station {
            robot_mode: config.robot_mode,
            settings: Settings::FACTORY,
            tool: config.tool,
            tool_error: ToolError::Ok,
            station_error: StationError::Ok,
            tool_on: false,
            suction: false,
            air: config.ambient_celsius,
            board: config.ambient_celsius,
            last: None,
            plugged: Duration::ZERO,
            working: Duration::ZERO,
            tool_cycles: 0,
            suction_cycles: 0,
            config,
        }
    }

    // ---- getters ------------------------------------------------------------------------

    /// How the station was configured.
    pub fn config(&self) -> &StationConfig {
        &self.config
    }

    /// The station's address, `None` in the form without address.
    pub fn address(&self) -> Option<Address> {
        self.config.address
    }

    /// Whether robot mode is on.
    pub fn robot_mode(&self) -> bool {
        self.robot_mode
    }

    /// The current parameters.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// The connected tool.
    pub fn tool(&self) -> Tool {
        self.tool
    }

    /// The port error as `PE1` reads it: `No tool` without a tool, otherwise the tool's error.
    pub fn port_error(&self) -> ToolError {
        if self.tool == Tool::None {
            ToolError::NoTool
        } else {
            self.tool_error
        }
    }

    /// The station error as `SER` reads it.
    pub fn station_error(&self) -> StationError {
        self.station_error
    }

    /// The port status as of the last time the model saw (tool on as the robot set it,
    /// cooling while the pump cools a hot tool, suction).
    pub fn port_status(&self) -> PortStatus {
        PortStatus {
            tool_on: self.tool_on,
            cooling: self.cooling(),
            suction: self.suction,
        }
    }

    /// The counters as of the last time the model saw.
    pub fn counters(&self) -> Counters {
        Counters {
            plugged_hours: self.plugged.as_secs() / SECONDS_PER_HOUR,
            work_hours: self.working.as_secs() / SECONDS_PER_HOUR,
            tool_cycles: self.tool_cycles,
            suction_cycles: self.suction_cycles,
        }
    }

    /// The air temperature at the tool's thermocouple at `now` (°C).
    pub fn air_temperature(&mut self, now: Instant) -> f64 {
        self.advance(now);
        self.air
    }

    /// The temperature at the external thermocouple at `now` (°C).
    pub fn external_temperature(&mut self, now: Instant) -> f64 {
        self.advance(now);
        self.board
    }

    /// The power supplied to the tool at `now` (‰ of the station's maximum).
    pub fn port_power(&mut self, now: Instant) -> i32 {
        self.advance(now);
        self.power()
    }

    // ---- inputs -------------------------------------------------------------------------

    /// Brings the physics and the counters up to `now`. A `now` earlier than the last one
    /// seen is ignored (time never runs backwards in the model). The first call only sets
    /// the clock.
    pub fn advance(&mut self, now: Instant) {
        let Some(last) = self.last else {
            self.last = Some(now);
            return;
        };
        if now <= last {
            return;
        }
        let elapsed = now - last;
        self.last = Some(now);
        if self.tool != Tool::None {
            self.plugged += elapsed;
        }
        if self.heating() {
            self.working += elapsed;
        }
        self.integrate(elapsed.as_secs_f64());
    }

    /// Answers one decoded frame (or bytes the codec dropped) at `now`: the reply frame, or
    /// `None` for silence. [`Model::handle`] is this plus the encoding and the delay.
    pub fn reply_to(&mut self, input: Result<Frame, DecodeError>, now: Instant) -> Option<Frame> {
        self.advance(now);
        match input {
            Ok(frame) => self.answer(&frame),
            Err(error) => self.answer_damaged(&error),
        }
    }

    // ---- faults and the operator's hand ---------------------------------------------------
    // These take effect at the last time the model saw (call `advance` first to move it).

    /// Unplugs the tool: `CT1` reads 0 and `PE1` reads 9 (No tool); nothing heats.
    pub fn disconnect_tool(&mut self) {
        self.tool = Tool::None;
    }

    /// Plugs in `tool` (`Tool::None` unplugs).
    pub fn connect_tool(&mut self, tool: Tool) {
        self.tool = tool;
    }

    /// Turns robot mode on or off at the station's keys; off, every command gets NAK 5.
    pub fn set_robot_mode(&mut self, on: bool) {
        self.robot_mode = on;
    }

    /// Makes the tool report `error` on `PE1`; any error but OK stops the heater.
    pub fn set_tool_error(&mut self, error: ToolError) {
        self.tool_error = error;
    }

    /// Makes the station report `error` on `SER`; any error but OK stops the heater.
    pub fn set_station_error(&mut self, error: StationError) {
        self.station_error = error;
    }

    /// Turns the vacuum pick-up on or off (a pedal at the station); each turn-on counts a
    /// suction cycle.
    pub fn set_suction(&mut self, on: bool) {
        if on && !self.suction {
            self.suction_cycles += 1;
        }
        self.suction = on;
    }

    // ---- protocol -----------------------------------------------------------------------

    /// The route of a reply to a frame that came on `incoming`, or `None` for silence.
    fn reply_route(&self, incoming: Option<Route>) -> Option<Option<Route>> {
        match (self.config.address, incoming) {
            (Some(own), Some(route)) if route.target == own => Some(Some(route.reversed())),
            (Some(_), _) => None,
            (None, _) => Some(None),
        }
    }

    fn answer_damaged(&self, error: &DecodeError) -> Option<Frame> {
        let head = error.head()?;
        let route = self.reply_route(head.route)?;
        Some(nak(head.code, NakReason::from(error), route))
    }

    fn answer(&mut self, frame: &Frame) -> Option<Frame> {
        let route = self.reply_route(frame.route)?;
        let refuse = |reason| Some(nak(frame.code, reason, route));
        let request_has_data = match frame.header {
            Header::Ack | Header::Nak => return None,
            Header::Read => false,
            Header::Write => true,
        };
        if self.config.address.is_none() && frame.route.is_some() {
            return refuse(NakReason::Format);
        }
        if frame.data.is_some() != request_has_data {
            return refuse(NakReason::Format);
        }
        if !self.robot_mode {
            return refuse(NakReason::NotInRobotMode);
        }
        let Some(code) = Code::from_raw(frame.code) else {
            return refuse(NakReason::ControlCode);
        };
        let answer = match frame.data {
            None if code.readable() => Reply::Ack {
                code: frame.code,
                data: Some(self.read(code)),
            },
            Some(data) if code.writable() => {
                let Some(value) = data.as_number() else {
                    return refuse(NakReason::Format);
                };
                match self.write(code, value) {
                    Ok(()) => Reply::Ack {
                        code: frame.code,
                        data: None,
                    },
                    Err(reason) => return refuse(reason),
                }
            }
            _ => return refuse(NakReason::ControlCode),
        };
        Some(answer.to_frame(route))
    }

    /// The data a read of `code` answers.
    fn read(&self, code: Code) -> Data {
        let s = &self.settings;
        let value: i64 = match code {
            Code::StationModel => {
                return Data::text(MODEL_NAME)
                    .expect("the model name is four printable characters");
            }
            Code::SelectAirTemp(_) => s.air_temp.into(),
            Code::SelectAirFlow(_) => s.air_flow.into(),
            Code::SelectExternalTemp(_) => s.external_temp.into(),
            Code::AirTemp(_) => self.air.round() as i64,
            Code::ExternalTemp(_) => self.board.round() as i64,
            Code::WorkMode(_) => s.work_mode.number().into(),
            Code::PortPower(_) => self.power().into(),
            Code::PortError(_) => self.port_error().code().into(),
            Code::PortStatus(_) => self.port_status().to_number().into(),
            Code::ConnectedTool(_) => self.tool.number().into(),
            Code::AdjustTemp(_, tool) => s.adjust(tool).into(),
            Code::MaxAirTemp => s.max_air_temp.into(),
            Code::MinAirTemp => s.min_air_temp.into(),
            Code::MaxAirFlow => s.max_air_flow.into(),
            Code::MinAirFlow => s.min_air_flow.into(),
            Code::MaxExternalTemp => s.max_external_temp.into(),
            Code::MinExternalTemp => s.min_external_temp.into(),
            Code::StationError => self.station_error.code().into(),
            Code::PluggedHours(_) => saturate(self.counters().plugged_hours),
            Code::WorkHours(_) => saturate(self.counters().work_hours),
            Code::ToolCycles(_) => saturate(self.tool_cycles),
            Code::SuctionCycles(_) => saturate(self.suction_cycles),
            // Write-only: never read (checked before).
            Code::ResetParameters | Code::ResetSettings => 0,
        };
        let clamped = value.clamp(DATA_MIN.into(), DATA_MAX.into()) as i32;
        Data::number(clamped).expect("clamped into the data field's range")
    }

    /// Applies a write of `value` to `code`, or says why not (NAK 3 out of range).
    fn write(&mut self, code: Code, value: i32) -> Result<(), NakReason> {
        let s = &mut self.settings;
        let within = |range: RangeInclusive<i32>| {
            if range.contains(&value) {
                Ok(value)
            } else {
                Err(NakReason::OutOfRange)
            }
        };
        match code {
            Code::SelectAirTemp(_) => s.air_temp = within(s.min_air_temp..=s.max_air_temp)?,
            Code::SelectAirFlow(_) => s.air_flow = within(s.min_air_flow..=s.max_air_flow)?,
            Code::SelectExternalTemp(_) => {
                s.external_temp = within(s.min_external_temp..=s.max_external_temp)?;
            }
            Code::WorkMode(_) => {
                s.work_mode = WorkMode::from_number(value).ok_or(NakReason::OutOfRange)?;
            }
            Code::AdjustTemp(_, Tool::Jt) => s.adjust_jt = within(ADJUST_TEMP_RANGE)?,
            Code::AdjustTemp(_, Tool::Te) => s.adjust_te = within(ADJUST_TEMP_RANGE)?,
            Code::MaxAirTemp => {
                s.max_air_temp = within(s.min_air_temp..=*AIR_TEMP_RANGE.end())?;
                s.clamp_selections();
            }
            Code::MinAirTemp => {
                s.min_air_temp = within(*AIR_TEMP_RANGE.start()..=s.max_air_temp)?;
                s.clamp_selections();
            }
            Code::MaxAirFlow => {
                s.max_air_flow = within(s.min_air_flow..=*AIR_FLOW_RANGE.end())?;
                s.clamp_selections();
            }
            Code::MinAirFlow => {
                s.min_air_flow = within(*AIR_FLOW_RANGE.start()..=s.max_air_flow)?;
                s.clamp_selections();
            }
            Code::MaxExternalTemp => {
                s.max_external_temp = within(s.min_external_temp..=*EXTERNAL_TEMP_RANGE.end())?;
                s.clamp_selections();
            }
            Code::MinExternalTemp => {
                s.min_external_temp = within(*EXTERNAL_TEMP_RANGE.start()..=s.max_external_temp)?;
                s.clamp_selections();
            }
            // The data of the resets carries no meaning: any number is taken.
            Code::ResetParameters => *s = Settings::FACTORY,
            Code::ResetSettings => s.reset_settings(),
            Code::PortStatus(_) => {
                let on = match value {
                    0 => false,
                    1 => true,
                    _ => return Err(NakReason::OutOfRange),
                };
                if on && !self.tool_on && self.tool != Tool::None {
                    self.tool_cycles += 1;
                }
                self.tool_on = on;
            }
            // Read-only codes and A10 never get here (checked before).
            Code::AdjustTemp(_, Tool::None)
            | Code::AirTemp(_)
            | Code::ExternalTemp(_)
            | Code::PortPower(_)
            | Code::PortError(_)
            | Code::ConnectedTool(_)
            | Code::StationModel
            | Code::StationError
            | Code::PluggedHours(_)
            | Code::WorkHours(_)
            | Code::ToolCycles(_)
            | Code::SuctionCycles(_) => return Err(NakReason::ControlCode),
        }
        Ok(())
    }

    // ---- physics ------------------------------------------------------------------------

    /// Whether the heater works: the robot turned the tool on, a tool is plugged in and
    /// neither the tool nor the station reports an error.
    fn heating(&self) -> bool {
        self.tool_on
            && self.tool != Tool::None
            && self.tool_error == ToolError::Ok
            && self.station_error == StationError::Ok
    }

    /// Whether the pump cools a hot tool (heater off).
    fn cooling(&self) -> bool {
        !self.heating() && self.tool != Tool::None && self.air >= COOLING_UNTIL
    }

    /// Where the air heads while heating (°C).
    fn set_point(&self) -> f64 {
        f64::from(self.settings.air_temp + self.settings.adjust(self.tool))
    }

    /// Share of full air flow, 0–1.
    fn flow_share(&self) -> f64 {
        f64::from(self.settings.air_flow) / f64::from(*AIR_FLOW_RANGE.end())
    }

    fn power(&self) -> i32 {
        if !self.heating() {
            return 0;
        }
        let ambient = self.config.ambient_celsius;
        let set_point = self.set_point();
        let flow = HOLD_BASE_SHARE + (1.0 - HOLD_BASE_SHARE) * self.flow_share();
        let hold = HOLD_PERMILLE_PER_DEGREE * (set_point - ambient).max(0.0) * flow;
        let push = GAIN_PERMILLE_PER_DEGREE * (set_point - self.air);
        (hold + push).clamp(0.0, FULL_POWER).round() as i32
    }

    fn integrate(&mut self, mut seconds: f64) {
        let ambient = self.config.ambient_celsius;
        let board_share =
            BOARD_SHARE.start() + (BOARD_SHARE.end() - BOARD_SHARE.start()) * self.flow_share();
        while seconds > 0.0 {
            let step = seconds.min(MAX_STEP);
            seconds -= step;
            let heating = self.heating();
            let cooling = self.cooling();
            let (air_target, tau) = if heating {
                (self.set_point(), TAU_HEAT)
            } else if cooling {
                (ambient, TAU_COOL)
            } else {
                (ambient, TAU_NATURAL)
            };
            let blowing = heating || cooling;
            self.air += (air_target - self.air) * lag(step, tau);
            let board_target = if blowing {
                ambient + board_share * (self.air - ambient)
            } else {
                ambient
            };
            self.board += (board_target - self.board) * lag(step, TAU_BOARD);
            // Once both have arrived, nothing changes until the next command: stop early.
            let final_board = if blowing {
                ambient + board_share * (air_target - ambient)
            } else {
                ambient
            };
            if (self.air - air_target).abs() < SETTLED
                && (self.board - final_board).abs() < SETTLED
                && (!cooling || air_target >= COOLING_UNTIL)
            {
                self.air = air_target;
                self.board = final_board;
                break;
            }
        }
    }
}

impl Model for Station {
    type Codec = FrameCodec;

    fn codec(&self) -> FrameCodec {
        FrameCodec
    }

    /// The protocol sets no gap; a pause of [`FRAME_GAP_CHARS`] characters inside a frame
    /// ends it, as a station's receive timeout would.
    fn frame_gap(&self, char_time: Option<Duration>) -> Duration {
        char_time.map_or(wire::device::UNPACED_FRAME_GAP, |c| c * FRAME_GAP_CHARS)
    }

    fn handle(&mut self, input: Result<Frame, DecodeError>, now: Instant) -> Vec<Transmit> {
        let Some(reply) = self.reply_to(input, now) else {
            return Vec::new();
        };
        let mut bytes = Vec::with_capacity(reply.wire_len());
        FrameCodec.encode(&reply, &mut bytes);
        vec![Transmit::after(self.config.reply_delay, bytes)]
    }
}

/// Characters of silence after which the twin forgets a half-received frame (the spec
/// sets none; at 19200 baud 8E1 this is 5.7 ms).
pub const FRAME_GAP_CHARS: u32 = 10;

/// The share of the remaining distance a first-order lag covers in `step` seconds.
fn lag(step: f64, tau: Duration) -> f64 {
    1.0 - (-step / tau.as_secs_f64()).exp()
}

fn saturate(counter: u64) -> i64 {
    i64::try_from(counter).unwrap_or(i64::MAX)
}

/// A NAK for `code` with `reason`.
fn nak(code: RawCode, reason: NakReason, route: Option<Route>) -> Frame {
    Reply::Nak { code, reason }.to_frame(route)
}

#[cfg(test)]
mod tests;
