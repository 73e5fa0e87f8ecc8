//! Events: what happened in the cell, for the event log (drivers, the scheduler and the
//! gateway make them; the store keeps them).
//!
//! An event is words for people (`message`) and [`Fields`] for programs: which feeder ran
//! out, the board's cycle time, the state a transfer switch went to. Whoever reads events
//! (OEE, alarms, IPC-CFX, the historian) takes the fields and never parses the words.

use serde::Serialize;

use crate::point::{DeviceId, PointId};
use crate::time::Timestamp;

/// What happened, for the event log.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EventKind {
    /// The gateway started.
    GatewayStarted,
    /// The gateway stopped.
    GatewayStopped,
    /// A line was opened.
    LineUp,
    /// A line failed or could not be opened.
    LineDown,
    /// A line was closed and reopened because every device on it stopped answering.
    LineReopened,
    /// A device answered again.
    DeviceUp,
    /// A device stopped answering.
    DeviceDown,
    /// A point went into alarm (a tool error appeared, a limit was crossed).
    AlarmRaised,
    /// A point came out of alarm.
    AlarmCleared,
    /// An alarm was acknowledged, shelved or unshelved, or its shelving ran out (the
    /// alarm journal's other entries; `alarm_raised` and `alarm_cleared` are its
    /// activations and returns to normal).
    AlarmChanged,
    /// A write was made.
    Write,
    /// A device changed state on its own: a CROSS transferred its load, a machine went
    /// from run to error.
    StateChanged,
    /// A device reported something unsolicited (a Panasonic R message).
    DeviceEvent,
    /// History commits started failing (a full disk, a damaged file), or the history could
    /// not be opened at start; live values go on.
    HistoryFailed,
    /// History commits work again after failing.
    HistoryRecovered,
    /// A damaged history file was moved aside at start and a new one started.
    HistoryReset,
    /// An interface's link came up (MQTT: connected to the broker, births follow); its
    /// `interface` field names it.
    InterfaceUp,
    /// An interface's link was lost or refused (MQTT: the broker); its `interface` field
    /// names it.
    InterfaceDown,
    /// The configuration was reloaded (SIGHUP): its `added`, `removed` and `changed`
    /// fields list device ids, `restart_needed` what only a restart applies.
    ConfigReloaded,
    /// A reload was refused: the file fails its check (`error`); the configuration in
    /// force stays.
    ConfigRefused,
}

impl EventKind {
    /// Every kind, for filters and the API description.
    pub const ALL: [EventKind; 20] = [
        EventKind::GatewayStarted,
        EventKind::GatewayStopped,
        EventKind::LineUp,
        EventKind::LineDown,
        EventKind::LineReopened,
        EventKind::DeviceUp,
        EventKind::DeviceDown,
        EventKind::AlarmRaised,
        EventKind::AlarmCleared,
        EventKind::AlarmChanged,
        EventKind::Write,
        EventKind::StateChanged,
        EventKind::DeviceEvent,
        EventKind::HistoryFailed,
        EventKind::HistoryRecovered,
        EventKind::HistoryReset,
        EventKind::InterfaceUp,
        EventKind::InterfaceDown,
        EventKind::ConfigReloaded,
        EventKind::ConfigRefused,
    ];

    /// The name stored and printed (`device_down`).
    pub fn as_str(self) -> &'static str {
        match self {
            EventKind::GatewayStarted => "gateway_started",
            EventKind::GatewayStopped => "gateway_stopped",
            EventKind::LineUp => "line_up",
            EventKind::LineDown => "line_down",
            EventKind::LineReopened => "line_reopened",
            EventKind::DeviceUp => "device_up",
            EventKind::DeviceDown => "device_down",
            EventKind::AlarmRaised => "alarm_raised",
            EventKind::AlarmCleared => "alarm_cleared",
            EventKind::AlarmChanged => "alarm_changed",
            EventKind::Write => "write",
            EventKind::StateChanged => "state_changed",
            EventKind::DeviceEvent => "device_event",
            EventKind::HistoryFailed => "history_failed",
            EventKind::HistoryRecovered => "history_recovered",
            EventKind::HistoryReset => "history_reset",
            EventKind::InterfaceUp => "interface_up",
            EventKind::InterfaceDown => "interface_down",
            EventKind::ConfigReloaded => "config_reloaded",
            EventKind::ConfigRefused => "config_refused",
        }
    }

    /// How grave an event of this kind is, 1 to 1000 (OPC UA's scale): the severity of
    /// OPC UA events and of the `severity` property of Sparkplug events.
    ///
    /// | kind | severity |
    /// |---|---|
    /// | alarm_raised, device_down, line_down, history_failed | 700 |
    /// | history_reset | 600 |
    /// | state_changed (a transfer, a machine's state), line_reopened, interface_down, config_refused | 500 |
    /// | device_event (an R message) | 400 |
    /// | alarm_cleared, alarm_changed, device_up, line_up, history_recovered | 300 |
    /// | write, gateway_started, gateway_stopped, interface_up, config_reloaded | 200 |
    pub fn severity(self) -> u16 {
        match self {
            EventKind::AlarmRaised
            | EventKind::DeviceDown
            | EventKind::LineDown
            | EventKind::HistoryFailed => 700,
            EventKind::HistoryReset => 600,
            EventKind::StateChanged
            | EventKind::LineReopened
            | EventKind::InterfaceDown
            | EventKind::ConfigRefused => 500,
            EventKind::DeviceEvent => 400,
            EventKind::AlarmCleared
            | EventKind::AlarmChanged
            | EventKind::DeviceUp
            | EventKind::LineUp
            | EventKind::HistoryRecovered => 300,
            EventKind::Write
            | EventKind::GatewayStarted
            | EventKind::GatewayStopped
            | EventKind::InterfaceUp
            | EventKind::ConfigReloaded => 200,
        }
    }

    /// The kind for a stored name.
    pub fn parse(text: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.as_str() == text)
    }
}

/// An event's structured facts: names in snake_case, values numbers, text or booleans
/// (`{"feeder": 7, "nozzle": 7, "step": 87}`). Empty for events that have none.
pub type Fields = serde_json::Map<String, serde_json::Value>;

/// Fields from `(name, value)` pairs, leaving out the `null` ones (a fact the device did
/// not give).
pub fn fields<const N: usize>(pairs: [(&str, serde_json::Value); N]) -> Fields {
    pairs
        .into_iter()
        .filter(|(_, value)| !value.is_null())
        .map(|(name, value)| (name.to_owned(), value))
        .collect()
}

/// An event to record.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Event {
    /// When.
    pub t: Timestamp,
    /// What kind.
    pub kind: EventKind,
    /// The line, if it concerns one.
    pub line: Option<String>,
    /// The device, if it concerns one.
    pub device: Option<DeviceId>,
    /// The point, if it concerns one.
    pub point: Option<PointId>,
    /// Words for the event log.
    pub message: String,
    /// The facts for programs (empty when the event has none).
    pub fields: Fields,
}

impl Event {
    /// An event of the gateway itself (no line, device or point), now.
    pub fn of_gateway(kind: EventKind, message: String) -> Self {
        Self {
            t: Timestamp::now(),
            kind,
            line: None,
            device: None,
            point: None,
            message,
            fields: Fields::new(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_event_kind_has_a_severity_alarms_above_transfers_above_clears_above_writes() {
        for kind in EventKind::ALL {
            assert!((1..=1000).contains(&kind.severity()), "{kind:?}");
        }
        assert_eq!(EventKind::AlarmRaised.severity(), 700);
        assert_eq!(EventKind::DeviceDown.severity(), 700);
        assert_eq!(EventKind::StateChanged.severity(), 500);
        assert_eq!(EventKind::DeviceEvent.severity(), 400);
        assert_eq!(EventKind::AlarmCleared.severity(), 300);
        assert_eq!(EventKind::DeviceUp.severity(), 300);
        assert_eq!(EventKind::Write.severity(), 200);
    }
}
