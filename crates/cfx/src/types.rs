//! The values CFX messages are made of, each as the SDK writes it in JSON: an endpoint's
//! handle, a resource state code, a time with its offset, a duration (.NET's `TimeSpan`)
//! and the enumerations a placement machine's messages use (written as their names).

use std::fmt;
use std::time::Duration;

use serde::{Deserialize, Serialize, Serializer};

/// Why a value cannot be what CFX wants.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ValueError {
    /// A handle that is empty, too long, or has blanks or control characters.
    #[error(
        "CFX handle {0:?} cannot be used: it must be 1 to 256 characters without blanks or control characters, by convention Vendor.Model.Serial"
    )]
    Handle(String),
    /// A number that is not a CFX resource state.
    #[error(
        "{0} is not a CFX resource state (SEMI E10/E58 codes such as 1100 productive, 2000 standby, 5000 unscheduled down)"
    )]
    State(u32),
}

/// An endpoint's CFX handle (`Panasonic.BM221.SN1234`): the `Source` of what it
/// publishes and the address its requests come to.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct Handle(String);

impl Handle {
    /// The handle `text`, checked.
    pub fn new(text: &str) -> Result<Self, ValueError> {
        let fine = !text.is_empty()
            && text.chars().count() <= 256
            && !text.chars().any(|c| c.is_whitespace() || c.is_control());
        if fine {
            Ok(Self(text.to_owned()))
        } else {
            Err(ValueError::Handle(text.to_owned()))
        }
    }

    /// The handle as text.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl TryFrom<String> for Handle {
    type Error = ValueError;

    fn try_from(text: String) -> Result<Self, Self::Error> {
        Handle::new(&text)
    }
}

impl From<Handle> for String {
    fn from(handle: Handle) -> String {
        handle.0
    }
}

impl fmt::Display for Handle {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// The codes of CFX's `ResourceState` (SDK `CFX/Structures/ResourceState.cs`): the
/// thousands are the SEMI E10 category, the hundreds the E58 sub-state.
const STATES: [u16; 37] = [
    1000, 1100, 1200, 1300, 1400, // productive
    2000, 2100, 2200, 2201, 2202, 2300, 2400, 2500, // standby
    3000, 3100, 3200, // engineering
    4000, 4100, 4200, 4300, 4400, 4500, 4600, 4700, // scheduled down
    5000, 5100, 5200, 5300, 5400, 5500, 5600, // unscheduled down
    6000, 6100, 6200, 6300, 6400, 6500, // non-scheduled
];

/// A resource state: a SEMI E10/E58 code as CFX numbers them (written as the number).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(try_from = "u32", into = "u16")]
pub struct ResourceState(u16);

impl ResourceState {
    /// Productive, regular work.
    pub const PRODUCTIVE: ResourceState = ResourceState(1100);
    /// Standby.
    pub const STANDBY: ResourceState = ResourceState(2000);
    /// Unscheduled down.
    pub const UNSCHEDULED_DOWN: ResourceState = ResourceState(5000);

    /// The state of `code`, if CFX has it.
    pub fn new(code: u32) -> Result<Self, ValueError> {
        STATES
            .iter()
            .find(|&&c| u32::from(c) == code)
            .map(|&c| ResourceState(c))
            .ok_or(ValueError::State(code))
    }

    /// The code.
    pub fn code(self) -> u16 {
        self.0
    }
}

impl TryFrom<u32> for ResourceState {
    type Error = ValueError;

    fn try_from(code: u32) -> Result<Self, Self::Error> {
        ResourceState::new(code)
    }
}

impl From<ResourceState> for u16 {
    fn from(state: ResourceState) -> u16 {
        state.0
    }
}

/// A moment as CFX writes it: ISO 8601 with seven decimals and the zone's offset
/// (`2018-03-26T16:52:25.3769532-04:00`), the time something happened.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Time(jiff::Zoned);

impl Time {
    /// `at` in the zone `zone` (the cell's time zone, or UTC).
    pub fn new(at: jiff::Timestamp, zone: &jiff::tz::TimeZone) -> Self {
        Self(at.to_zoned(zone.clone()))
    }

    /// The moment.
    pub fn timestamp(&self) -> jiff::Timestamp {
        self.0.timestamp()
    }
}

impl fmt::Display for Time {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0.strftime("%Y-%m-%dT%H:%M:%S%.7f%:z"))
    }
}

impl Serialize for Time {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for Time {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let text = String::deserialize(deserializer)?;
        let at: jiff::Timestamp = text.parse().map_err(serde::de::Error::custom)?;
        // Kept in UTC: the offset it was written with is not needed to compare or store it.
        Ok(Time(at.to_zoned(jiff::tz::TimeZone::UTC)))
    }
}

/// A duration as .NET's `TimeSpan` writes it: `hh:mm:ss`, `d.hh:mm:ss` past a day, with
/// `.fffffff` when it has a fraction of a second (to 100 ns).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct TimeSpan(pub Duration);

impl fmt::Display for TimeSpan {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let seconds = self.0.as_secs();
        let (days, hours) = (seconds / 86_400, seconds / 3600 % 24);
        let (minutes, secs) = (seconds / 60 % 60, seconds % 60);
        if days > 0 {
            write!(f, "{days}.")?;
        }
        write!(f, "{hours:02}:{minutes:02}:{secs:02}")?;
        let ticks = self.0.subsec_nanos() / 100;
        if ticks > 0 {
            write!(f, ".{ticks:07}")?;
        }
        Ok(())
    }
}

impl Serialize for TimeSpan {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for TimeSpan {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let text = String::deserialize(deserializer)?;
        parse_time_span(&text)
            .map(TimeSpan)
            .ok_or_else(|| serde::de::Error::custom(format!("{text:?} is not a TimeSpan")))
    }
}

/// `[d.]hh:mm:ss[.fffffff]`.
fn parse_time_span(text: &str) -> Option<Duration> {
    let (days, rest) = match text.split_once('.') {
        Some((days, rest)) if !days.contains(':') => (days.parse::<u64>().ok()?, rest),
        _ => (0, text),
    };
    let (clock, fraction) = match rest.split_once('.') {
        Some((clock, fraction)) => (clock, fraction),
        None => (rest, ""),
    };
    let mut parts = clock.split(':').map(|p| p.parse::<u64>().ok());
    let (h, m, s) = (parts.next()??, parts.next()??, parts.next()??);
    if parts.next().is_some() || m > 59 || s > 59 || fraction.len() > 7 {
        return None;
    }
    let nanos = if fraction.is_empty() {
        0
    } else {
        let digits: u32 = fraction.parse().ok()?;
        digits * 10u32.pow(9 - u32::try_from(fraction.len()).ok()?)
    };
    Some(Duration::new(days * 86_400 + h * 3600 + m * 60 + s, nanos))
}

/// What caused a fault (SDK `FaultCause`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum FaultCause {
    /// The machine failed mechanically.
    MechanicalFailure,
    /// A material needs refilling (parts exhausted).
    Refill,
    /// A component is missing.
    MissingComponent,
    /// The process failed (a pickup, a recognition).
    ProcessError,
    /// Its software failed.
    SoftwareFailure,
    /// A component was rejected.
    RejectedComponent,
}

/// How grave a fault is (SDK `FaultSeverity`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum FaultSeverity {
    /// For information.
    Information,
    /// A warning.
    Warning,
    /// An error (the machine stops).
    Error,
    /// An alarm.
    Alarm,
}

/// What kind of SMT placement fault (SDK `SMTPlacementFaultType`, the values a
/// Panasonic BM's error stops map to).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum PlacementFaultType {
    /// A feeder ran out of parts.
    PartsExhaust,
    /// A part was not picked up.
    PickupError,
    /// A part was not recognised.
    RecognitionError,
    /// A part was not placed.
    PlacementError,
    /// A head fault.
    HeadError,
    /// A nozzle fault.
    NozzleError,
    /// A feeder fault.
    FeederError,
    /// A fiducial was not found.
    FiducialError,
    /// A part was dropped.
    ComponentDropped,
}

/// How a work transaction ended (SDK `WorkResult`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum WorkResult {
    /// Completed.
    Completed,
    /// Failed.
    Failed,
    /// Aborted.
    Aborted,
    /// Skipped.
    Skipped,
}

/// A request's result (SDK `StatusResult`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum StatusResult {
    /// Done.
    Success,
    /// Not done.
    Failed,
}

/// A request's result with its code and words (SDK `RequestResult`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "PascalCase")]
pub struct RequestResult {
    /// Success or failed.
    pub result: StatusResult,
    /// 0, or the endpoint's own code.
    pub result_code: i32,
    /// Words, or `null`.
    pub message: Option<String>,
}

impl RequestResult {
    /// Success.
    pub fn success() -> Self {
        Self {
            result: StatusResult::Success,
            result_code: 0,
            message: None,
        }
    }

    /// Failed, for `why`.
    pub fn failed(why: &str) -> Self {
        Self {
            result: StatusResult::Failed,
            result_code: 0,
            message: Some(why.to_owned()),
        }
    }
}
