//! Protocol drivers: one small module per protocol maps a device onto points.
//!
//! A [`Driver`] describes its device's points and poll groups, reads a group when the
//! scheduler asks, and writes a point. It talks through its protocol crate's client over
//! a [`link::SharedLine`] the scheduler attaches; it never opens lines, keeps no history
//! and reads no clock. Errors are classified by the client errors' own
//! [`wire::Failure::kind`] ([`DeviceError::of`], mapped to [`ErrorKind`]) so the metrics can
//! count timeouts apart from refusals, line trouble and our own bad requests.
//!
//! This module is the vocabulary the core shares with the drivers: [`DeviceKind`] (what a
//! kind of device tells the config and the line tasks), [`Driver`] (one device's points,
//! polls and writes), [`DeviceError`], [`WriteError`], [`ErrorKind`], [`PollGroup`]. It
//! names no protocol. The kinds live in their own modules: [`jbc`] (JBC JTSE hot-air
//! station), [`thermosald`] (ISC impulse-sealer regulators, several on one RS-485 line),
//! [`cross`] (Chloride CROSS transfer switch over JBUS), [`panasonic`] (placement machine
//! over TCP) and [`modbus`] (any Modbus RTU / JBUS device with its registers named in the
//! config), each registered by one line in [`crate::plugins`]; DESIGN.md, "Adding a device
//! kind", has the steps.
//!
//! A kind whose client keeps its own connections (Panasonic: two TCP ports, keep-alive,
//! reconnection) says so with [`DeviceKind::owns_connections`]: its line task opens
//! nothing, the driver ignores [`Driver::attach`] and connects on its first poll from
//! [`DriverConfig::endpoint`].
//!
//! State transitions a driver sees between polls (a CROSS transfer) and unsolicited
//! messages are reported through [`Driver::take_events`]; a point going into or out of
//! alarm (a regulator fault) needs no code in the driver: its [`crate::point::AlarmRule`]
//! is enough.

use std::fmt;
use std::future::Future;
use std::pin::Pin;
use std::time::Duration;

use link::{SerialSettings, SharedLine};
use serde::Serialize;
use wire::{Failure, FailureKind};

use crate::config::table::{ConfigError, Scratch, Settings, Table};
use crate::event::EventKind;
use crate::point::{Checked, DeviceId, PointId, PointSpec, Value, ValueError};

pub mod cross;
pub mod jbc;
pub mod machine;
pub mod modbus;
pub mod panasonic;
pub mod thermosald;

/// A boxed future, so drivers of different protocols can sit in one list.
pub type BoxFuture<'a, T> = Pin<Box<dyn Future<Output = T> + Send + 'a>>;

/// A protocol driver for one device.
pub trait Driver: Send {
    /// Every point of the device.
    fn points(&self) -> Vec<PointSpec>;

    /// The poll groups and their default periods.
    fn groups(&self) -> Vec<PollGroup>;

    /// Gives the driver the line to talk on (again, after the scheduler reopened it).
    fn attach(&mut self, line: SharedLine);

    /// Reads every point of `group`. `Err` means the device did not answer at all (it is
    /// then backed off); a point the device refused comes back as a failed reading.
    fn poll<'a>(&'a mut self, group: &'a str) -> BoxFuture<'a, Result<Vec<Reading>, DeviceError>>;

    /// Writes `value` to `point`. `value` passed the point's spec
    /// ([`PointSpec::check_write`]); the driver checks only what depends on the device's
    /// state (limits it read) before the wire.
    fn write<'a>(
        &'a mut self,
        point: &'a PointSpec,
        value: &'a Checked,
    ) -> BoxFuture<'a, Result<(), WriteError>>;

    /// Events the device caused since the last call: state transitions the driver saw
    /// between two polls (a CROSS transfer, a machine going from run to error) and
    /// unsolicited messages (Panasonic R events). The scheduler drains them after every
    /// poll and write and records them with the device and line. Most drivers have none:
    /// points crossing into or out of alarm are recorded by the scheduler itself.
    fn take_events(&mut self) -> Vec<DeviceEvent> {
        Vec::new()
    }

    /// The good readings a poll got before it failed: a meter's first reads answered, then
    /// the line dropped or the meter fell silent. The scheduler takes them after every
    /// `Err` from [`Driver::poll`] and records them before it marks the device down, so
    /// what was read is kept. Drivers that read a group in one request have none.
    fn take_partial(&mut self) -> Vec<Reading> {
        Vec::new()
    }

    /// The deadband of `point` when the device's own table sets it (a Modbus register's
    /// `deadband`, which already falls back to the device's); `None`: the device's.
    fn deadband(&self, point: &str) -> Option<Option<crate::point::Deadband>> {
        let _ = point;
        None
    }

    /// How many requests the last poll sent, for drivers that plan their reads (generic
    /// Modbus); shown in `/metrics` as `cellbus_modbus_requests_per_poll`.
    fn requests_per_poll(&self) -> Option<u64> {
        None
    }

    /// The least time one poll of `group` holds a serial line of `serial`: its requests'
    /// and answers' time on the wire and the waits the protocol requires, with no retry.
    /// `cellbus config check` adds them up per line against the periods asked. `None`
    /// where the driver cannot tell (the default).
    fn poll_time(&self, group: &str, serial: SerialSettings) -> Option<Duration> {
        let _ = (group, serial);
        None
    }
}

/// The least time Modbus RTU reads hold a serial line of `serial`, given each answer's
/// data bytes: per read, 3.5 characters of silence, the 8-byte request, 3.5 again and the
/// answer of 5 bytes and its data.
pub fn rtu_reads_time(serial: SerialSettings, data: impl IntoIterator<Item = usize>) -> Duration {
    let chars: usize = data.into_iter().map(|bytes| 7 + 8 + 5 + bytes).sum();
    serial.time_for(chars)
}

/// Something a device did that is worth an entry in the event log.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DeviceEvent {
    /// What kind of event ([`EventKind::StateChanged`], [`EventKind::DeviceEvent`], or an
    /// alarm kind).
    pub kind: EventKind,
    /// The point it concerns (its name, without the device), if one.
    pub point: Option<&'static str>,
    /// What happened, in words, without the device's name (the scheduler puts it in
    /// front): `load transferred from source 1 (S1) to source 2 (S2)`.
    pub message: String,
    /// When it happened, for an event that arrived on its own (a Panasonic R message);
    /// `None`: when the scheduler collects it, right after the poll that saw it.
    pub at: Option<crate::time::Timestamp>,
    /// The facts for programs ([`crate::event::Fields`]).
    pub fields: crate::event::Fields,
}

/// A group of points read together, at one period.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct PollGroup {
    /// Its name (`live`, `settings`, `info`), used in the config to set its period.
    pub name: String,
    /// How often it is read.
    pub period: Duration,
}

impl PollGroup {
    /// The groups of a driver, from `(name, default period)` pairs.
    pub(crate) fn list(groups: &[(&str, Duration)]) -> Vec<PollGroup> {
        groups
            .iter()
            .map(|&(name, period)| PollGroup {
                name: name.to_owned(),
                period,
            })
            .collect()
    }
}

/// The ids of `device`'s points named in a driver's own table, whose names follow the id
/// rules (a driver's tests build one, so a bad name fails them). Made once per device: its readings clone them,
/// so a reading, the point's spec and its history row share one text, and the scheduler
/// finds a reading's point by pointer.
pub(crate) fn point_ids<'a>(
    device: &DeviceId,
    names: impl IntoIterator<Item = &'a str>,
) -> Box<[PointId]> {
    names
        .into_iter()
        .map(|name| PointId::new(device, name).expect("a driver's point names follow the id rules"))
        .collect()
}

/// An enumeration's states from `(value, label)` pairs.
pub(crate) fn enum_states<V: Into<i64>, L: Into<crate::point::Words>>(
    items: impl IntoIterator<Item = (V, L)>,
) -> crate::point::PointKind {
    crate::point::PointKind::Enum {
        states: items
            .into_iter()
            .map(|(value, label)| crate::point::EnumState {
                value: value.into(),
                label: label.into(),
            })
            .collect(),
    }
}

/// One point's outcome in a poll.
#[derive(Debug, Clone, PartialEq)]
pub struct Reading {
    /// The point.
    pub point: PointId,
    /// Its value, or why the device would not give it.
    pub value: Result<Value, DeviceError>,
}

/// How a request to a device failed, for metrics and for what the scheduler does next:
/// the clients' [`FailureKind`], mapped one to one ([`From<FailureKind>`]) under the
/// labels the metrics and the API have always used.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ErrorKind {
    /// Our own request was wrong: refused before the wire, never the device's doing.
    Usage,
    /// No answer in time.
    Timeout,
    /// The device answered no (a NAK, an exception).
    Refused,
    /// Damaged or meaningless answers.
    Decode,
    /// Trouble on the line that does not close it (an echo mismatch, transmission errors
    /// the device reported).
    Line,
    /// The line is gone (closed, an I/O error): the scheduler reopens it.
    Disconnected,
}

impl ErrorKind {
    /// Every kind, for metric labels.
    pub const ALL: [ErrorKind; 6] = [
        ErrorKind::Usage,
        ErrorKind::Timeout,
        ErrorKind::Refused,
        ErrorKind::Decode,
        ErrorKind::Line,
        ErrorKind::Disconnected,
    ];

    /// What to check when a device fails this way, whatever its kind (a line's own errors
    /// carry their hints).
    pub fn hint(self) -> Option<&'static str> {
        match self {
            ErrorKind::Timeout => Some(
                "check that it is powered and cabled, the line's baud rate and framing, and the device's `address` in the config",
            ),
            ErrorKind::Decode => Some(
                "check the line's baud rate and framing, and that no other device answers at the same address",
            ),
            ErrorKind::Line => Some("check the wiring (RS-485: A/B swapped, termination)"),
            ErrorKind::Refused => Some(
                "the device answered but refused the request: check the `address` and that it is the configured protocol",
            ),
            ErrorKind::Usage | ErrorKind::Disconnected => None,
        }
    }

    /// The label (`timeout`).
    pub fn as_str(self) -> &'static str {
        match self {
            ErrorKind::Usage => "usage",
            ErrorKind::Timeout => "timeout",
            ErrorKind::Refused => "refused",
            ErrorKind::Decode => "decode",
            ErrorKind::Line => "line",
            ErrorKind::Disconnected => "disconnected",
        }
    }
}

impl From<FailureKind> for ErrorKind {
    /// The one place a client's failure becomes a gateway error kind.
    fn from(kind: FailureKind) -> Self {
        match kind {
            FailureKind::Usage => ErrorKind::Usage,
            FailureKind::Refused => ErrorKind::Refused,
            FailureKind::Timeout => ErrorKind::Timeout,
            FailureKind::Damaged => ErrorKind::Decode,
            FailureKind::Line => ErrorKind::Line,
            FailureKind::Disconnected => ErrorKind::Disconnected,
            // A kind added to the taxonomy later is line trouble until mapped here.
            _ => ErrorKind::Line,
        }
    }
}

impl fmt::Display for ErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A device or its line failed a request. The message is the protocol client's own
/// (which names the endpoint, the device and what happened); the kind classifies it. It
/// is cloneable text because one failure marks many points and travels to the API.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error, Serialize)]
#[error("{message}")]
pub struct DeviceError {
    /// What kind of failure.
    pub kind: ErrorKind,
    /// The client's words.
    pub message: String,
}

impl DeviceError {
    /// A failure of `kind`, described by `error`.
    pub fn new(kind: ErrorKind, error: impl fmt::Display) -> Self {
        Self {
            kind,
            message: error.to_string(),
        }
    }

    /// A client's failure, classified by its own [`Failure::kind`]: the only classifier.
    pub fn of(error: &impl Failure) -> Self {
        Self::new(error.kind().into(), error)
    }

    /// A request before the scheduler attached the line.
    pub(crate) fn not_attached() -> Self {
        Self::new(
            ErrorKind::Disconnected,
            "the line is not open yet (the gateway is connecting)",
        )
    }
}

/// Why a write did not happen.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum WriteError {
    /// Refused before the wire.
    #[error(transparent)]
    Invalid(#[from] ValueError),
    /// The device refused it or did not answer.
    #[error(transparent)]
    Device(#[from] DeviceError),
    /// The point is not one of this device's.
    #[error("{point} is not a point of this device")]
    UnknownPoint {
        /// The point named in the write.
        point: PointId,
    },
    /// The device's poller is not running (the gateway is stopping).
    #[error("the poller of line {line} is not running; the gateway may be stopping")]
    NotRunning {
        /// The name of the line whose task is not running.
        line: String,
    },
}

/// A kind of device the gateway speaks to: everything the core asks of a driver module
/// (the config's checks, the line tasks, the API), so the core names no protocol. Each
/// kind is a unit type in its own module, listed once in [`crate::plugins`].
pub trait DeviceKind: Send + Sync + 'static {
    /// Its name in the config (`protocol = "jbc"`) and the API.
    fn name(&self) -> &'static str;

    /// Serial settings a line URL leaves out.
    fn default_serial(&self) -> SerialSettings;

    /// The address a device has when the config names none.
    fn default_address(&self) -> Option<i64>;

    /// Checks a device address; `Err` says what the kind accepts.
    fn check_address(&self, address: Option<i64>) -> Result<(), String>;

    /// Its poll groups, with their default periods: the names `poll = { … }` may use.
    fn groups(&self) -> &'static [(&'static str, Duration)];

    /// `Some(how to write its endpoint)` when its client keeps its own connections
    /// (Panasonic: two TCP ports, reconnection and keep-alive in the client): its line
    /// must be `tcp://`, carries one device, and the line task opens nothing for it, only
    /// schedules the polls; the driver connects on its first poll from
    /// [`DriverConfig::endpoint`].
    fn owns_connections(&self) -> Option<&'static str> {
        None
    }

    /// What to check when one of its devices fails this way, for the log, `/healthz` and
    /// the event's `hint` field. By default [`ErrorKind::hint`], with the unit number and
    /// `cellbus modbus scan` for a Modbus kind that times out.
    fn hint(&self, error: ErrorKind) -> Option<&'static str> {
        match error {
            ErrorKind::Timeout if self.speaks_modbus() => Some(
                "check the unit number (`address`; `cellbus modbus scan` lists the units that answer), that it is powered and cabled, and the line's baud rate and framing",
            ),
            _ => error.hint(),
        }
    }

    /// Whether it speaks Modbus: it may sit on a `modbus-tcp://` line and share a line
    /// with the other Modbus kinds (all JBUS on one RS-485 pair, one client each).
    fn speaks_modbus(&self) -> bool {
        false
    }

    /// Whether its driver plans its reads ([`Driver::requests_per_poll`]), so the metrics
    /// keep a gauge for it.
    fn plans_reads(&self) -> bool {
        false
    }

    /// The keys of a `[[line.device]]` table that only this kind takes (beyond `id`,
    /// `protocol`, `address` and the other keys every device has).
    fn keys(&self) -> &'static [&'static str] {
        &[]
    }

    /// Reads those keys: `table` holds only them (maybe none). What it returns comes back
    /// to [`DeviceKind::build`] in [`DriverConfig::settings`].
    fn read_keys(
        &self,
        table: &Table<'_>,
        device: &DeviceContext,
        scratch: &mut Scratch,
    ) -> Result<Settings, ConfigError> {
        let _ = (table, device, scratch);
        Ok(Settings::default())
    }

    /// The error for one of this kind's keys given to a device of the kind `other`: where
    /// it points (the value, by default) and what it says.
    fn foreign_key(
        &self,
        key: &str,
        value: &toml::Spanned<toml::de::DeValue<'_>>,
        other: &str,
    ) -> (std::ops::Range<usize>, String) {
        foreign_key(self.name(), key, value, other)
    }

    /// Checks what depends on the whole device once its keys are read (a Modbus read
    /// plan that cannot be made); `Err` says why in words, shown at the device's id.
    fn check(&self, config: &DriverConfig) -> Result<(), String> {
        let _ = config;
        Ok(())
    }

    /// What the file allows for these devices but is likely a mistake, one sentence each
    /// naming the device (Modbus registers that share a register).
    fn warnings(&self, devices: &[&DriverConfig]) -> Vec<String> {
        let _ = devices;
        Vec::new()
    }

    /// The driver for a device; `Err` says, in words, why the config cannot work (a
    /// Modbus read plan that cannot be made), and the config check shows it at the device.
    fn build(&self, config: &DriverConfig) -> Result<Box<dyn Driver>, String>;

    /// The machine states its devices report on the SEMI E10 scale, with their default
    /// codes; none by default. Its drivers report them through
    /// [`machine::StatePoints`]; a device's `states` table in the config moves
    /// one to another code.
    fn machine_states(&self) -> &'static [crate::production::StateDef] {
        &[]
    }

    /// Which of its points count what it produces, if it produces (the placement machine's
    /// boards): the gateway works out its OEE from them.
    fn production(&self) -> Option<&'static crate::production::ProductionPoints> {
        None
    }
}

/// A device kind told by its facts alone, as most are: a kind with keys of its own or
/// more to say (Modbus, Panasonic) implements [`DeviceKind`] itself.
#[derive(Debug)]
pub struct Described {
    /// Its name in the config.
    pub name: &'static str,
    /// Serial settings a line URL leaves out.
    pub serial: SerialSettings,
    /// The address a device has when the config names none.
    pub address: Option<i64>,
    /// Checks a device address.
    pub check_address: fn(Option<i64>) -> Result<(), String>,
    /// The poll groups with their default periods.
    pub groups: &'static [(&'static str, Duration)],
    /// Whether it speaks Modbus ([`DeviceKind::speaks_modbus`]).
    pub speaks_modbus: bool,
    /// The driver for a device.
    pub build: fn(&DriverConfig) -> Result<Box<dyn Driver>, String>,
    /// The machine states it reports ([`DeviceKind::machine_states`]).
    pub machine_states: &'static [crate::production::StateDef],
}

impl DeviceKind for Described {
    fn name(&self) -> &'static str {
        self.name
    }

    fn default_serial(&self) -> SerialSettings {
        self.serial
    }

    fn default_address(&self) -> Option<i64> {
        self.address
    }

    fn check_address(&self, address: Option<i64>) -> Result<(), String> {
        (self.check_address)(address)
    }

    fn groups(&self) -> &'static [(&'static str, Duration)] {
        self.groups
    }

    fn machine_states(&self) -> &'static [crate::production::StateDef] {
        self.machine_states
    }

    fn speaks_modbus(&self) -> bool {
        self.speaks_modbus
    }

    fn build(&self, config: &DriverConfig) -> Result<Box<dyn Driver>, String> {
        (self.build)(config)
    }
}

/// The default of [`DeviceKind::foreign_key`]: `key`, one of `kind`'s own, on a device of
/// the kind `other`, shown at its value.
pub fn foreign_key(
    kind: &str,
    key: &str,
    value: &toml::Spanned<toml::de::DeValue<'_>>,
    other: &str,
) -> (std::ops::Range<usize>, String) {
    (
        value.span(),
        format!("{key} is for {kind} devices only, not {other} devices"),
    )
}

/// A JBUS (Modbus) unit number from the config, checked by [`jbus::rtu::check_unit`] into
/// its typed form; the words name the device (`a CROSS`), what its number is called
/// (`JBUS unit number`) and who never answers broadcast (`which the CROSS never answers`).
pub fn jbus_unit(
    address: Option<i64>,
    device: &str,
    number_name: &str,
    silent: &str,
) -> Result<jbus::rtu::UnitId, String> {
    use jbus::rtu::{UnitId, UnitProblem};
    jbus::rtu::check_unit(address).map_err(|problem| match problem {
        UnitProblem::Missing => format!(
            "{device} needs its {number_name}, {} to {}",
            UnitId::MIN,
            UnitId::JBUS_MAX
        ),
        UnitProblem::OutOfRange { number } => format!(
            "{number_name} {number} is out of range: {} to {} (0 is broadcast, {silent})",
            UnitId::MIN,
            UnitId::JBUS_MAX
        ),
    })
}

/// What a kind knows of the device whose keys it reads.
#[derive(Debug, Clone)]
pub struct DeviceContext {
    /// Where the device's id is in the file: for errors about the device as a whole.
    pub id_span: std::ops::Range<usize>,
    /// The device's deadband for its numeric points (`deadband`, `deadband_percent`).
    pub deadband: Option<crate::point::Deadband>,
}

/// A device kind, as the config, the line tasks and the API hold it: compared, hashed and
/// shown by its name.
#[derive(Clone, Copy)]
pub struct Kind(&'static dyn DeviceKind);

impl Kind {
    /// The handle of `kind`.
    pub const fn new(kind: &'static dyn DeviceKind) -> Self {
        Self(kind)
    }
}

impl std::ops::Deref for Kind {
    type Target = dyn DeviceKind;

    fn deref(&self) -> &Self::Target {
        self.0
    }
}

impl PartialEq for Kind {
    fn eq(&self, other: &Self) -> bool {
        self.0.name() == other.0.name()
    }
}

impl Eq for Kind {}

impl std::hash::Hash for Kind {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        self.0.name().hash(state);
    }
}

impl fmt::Debug for Kind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.0.name())
    }
}

impl fmt::Display for Kind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.0.name())
    }
}

impl Serialize for Kind {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.0.name())
    }
}

/// What the config says about one device, for its driver.
#[derive(Debug, Clone, PartialEq)]
pub struct DriverConfig {
    /// The device's id.
    pub id: DeviceId,
    /// Its kind (the config's `protocol`).
    pub protocol: Kind,
    /// Its address on the line, if the kind has addresses.
    pub address: Option<i64>,
    /// Time to wait for each reply, if not the kind's default.
    pub timeout: Option<Duration>,
    /// Retries after a failed attempt, if not the kind's default.
    pub retries: Option<u8>,
    /// The line's endpoint, for kinds whose client keeps its own connections
    /// ([`DeviceKind::owns_connections`]) and for Modbus devices on a `modbus-tcp://` line
    /// (their client frames Modbus TCP).
    pub endpoint: Option<link::Endpoint>,
    /// What the kind read from its own keys ([`DeviceKind::read_keys`]): a Modbus
    /// device's registers, a Panasonic machine's event port.
    pub settings: Settings,
    /// The codes the config's `states` table gives some of its machine states.
    pub states: crate::production::states::StateOverrides,
}

impl DriverConfig {
    /// A device `id` of `kind` at the kind's default address, with every other field at
    /// its default.
    pub fn new(id: DeviceId, protocol: Kind) -> Self {
        Self {
            id,
            protocol,
            address: protocol.default_address(),
            timeout: None,
            retries: None,
            endpoint: None,
            settings: Settings::default(),
            states: Default::default(),
        }
    }

    /// The driver for the device.
    pub fn build(&self) -> Result<Box<dyn Driver>, String> {
        self.protocol.build(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_request_a_client_refused_to_build_is_usage_never_a_device_refusal() {
        let jbc = ::jbc::message::Request::write("AT1".parse().expect("a code"), 100)
            .expect_err("AT1 is read-only");
        let jbc = DeviceError::of(&::jbc::client::ClientError::from(jbc));
        assert_eq!(jbc.kind, ErrorKind::Usage, "{jbc}");

        let sealing = ::thermosald::Table::Settings
            .find("sealing temperature")
            .expect("an item");
        let thermosald = ::thermosald::Write::value(sealing, 1000.0).expect_err("four digits");
        let thermosald = DeviceError::of(&::thermosald::client::ClientError::from(thermosald));
        assert_eq!(thermosald.kind, ErrorKind::Usage, "{thermosald}");

        let jbus = ::jbus::rtu::Request::read_holding_registers(0, 126).expect_err("too many");
        let jbus = DeviceError::of(&::jbus::client::ClientError::from(jbus));
        assert_eq!(jbus.kind, ErrorKind::Usage, "{jbus}");

        let panasonic = ::panasonic::client::ClientError::Config(
            ::panasonic::keepalive::KeepAliveConfigError::IntervalTooShort {
                interval: Duration::from_millis(1),
                min: Duration::from_secs(1),
            },
        );
        assert_eq!(DeviceError::of(&panasonic).kind, ErrorKind::Usage);
    }

    #[test]
    fn every_failure_kind_maps_to_its_own_error_kind() {
        let mut kinds: Vec<ErrorKind> = FailureKind::ALL.into_iter().map(Into::into).collect();
        kinds.sort_by_key(|k| k.as_str());
        kinds.dedup();
        assert_eq!(kinds.len(), FailureKind::ALL.len());
        assert_eq!(kinds.len(), ErrorKind::ALL.len());
    }
}
