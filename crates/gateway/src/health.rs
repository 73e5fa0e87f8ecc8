//! The gateway's health as `/healthz` says it: `ok`, `degraded` or `failing`, with the
//! reasons.
//!
//! - `failing` (HTTP 503): the history cannot be written (off since the start, or commits
//!   failing), or no device answers (at least one has failed and none is up).
//! - `degraded` (HTTP 200): something is wrong but the gateway does its job for the rest:
//!   a device down, a line not open, a device's own link down (a Panasonic machine's
//!   events), an interface's link down (the MQTT broker).
//! - `ok` (HTTP 200): none of these. Devices not polled yet (the first seconds) are not a
//!   problem.
//!
//! Each reason is one line in words, naming the device, line or interface and why.

use serde::Serialize;

use crate::cell::{Cell, DeviceStatus};
use crate::store::HistoryState;

/// The overall state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// Everything works.
    Ok,
    /// Something is wrong; the rest works.
    Degraded,
    /// The gateway cannot do its job: no device answers or the history cannot be written.
    Failing,
}

/// The gateway's health: its state and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Health {
    /// The overall state.
    pub status: Status,
    /// Why it is not `ok`, most serious first.
    pub reasons: Vec<String>,
}

/// What the judgement reads, gathered from the cell (or made up by a test).
#[derive(Debug, Clone, Default)]
pub struct Facts {
    /// Every device: its id, its status and, when down, why.
    pub devices: Vec<(String, DeviceStatus, Option<String>)>,
    /// Every line that failed or could not be opened: its name and why (a line still
    /// opening is not one).
    pub lines_closed: Vec<(String, String)>,
    /// The history's state.
    pub history: Option<HistoryState>,
    /// Each interface whose link is down: its name and why.
    pub interfaces_down: Vec<(String, String)>,
    /// Each device's own link that is down (a Panasonic machine's events): device, link,
    /// why.
    pub links_down: Vec<(String, String, String)>,
    /// Why the last reload of the configuration was refused (the one in force stays).
    pub config_refused: Option<String>,
}

impl Facts {
    /// Reads the cell's devices, lines and interfaces, and the history's state.
    pub fn of(cell: &Cell, history: HistoryState) -> Self {
        let devices = cell
            .device_entries()
            .map(|d| {
                // Each device's status alone, read in place; words only for one that is
                // down (a thousand devices' views made a health check take 16 ms).
                let state = d.read();
                let why = match (state.status, &state.error) {
                    (DeviceStatus::Down, Some(e)) => {
                        Some(crate::oplog::describe(e, d.protocol.hint(e.kind)))
                    }
                    _ => None,
                };
                (d.id.to_string(), state.status, why)
            })
            .collect();
        let lines_closed = cell
            .lines()
            .iter()
            .filter(|l| !l.state.open)
            .filter_map(|l| Some((l.name.clone(), l.state.error.clone()?)))
            .collect();
        let interfaces_down = cell
            .interfaces()
            .into_iter()
            .filter_map(|(name, status)| Some((name.to_owned(), status.problem()?)))
            .collect();
        let links_down = cell
            .links_down()
            .into_iter()
            .map(|(device, link, why)| (device.to_string(), link, why))
            .collect();
        Facts {
            devices,
            lines_closed,
            history: Some(history),
            interfaces_down,
            links_down,
            config_refused: cell.config_status().error,
        }
    }
}

/// Judges the facts.
pub fn judge(facts: &Facts) -> Health {
    let mut failing = Vec::new();
    let mut degraded = Vec::new();
    match &facts.history {
        Some(HistoryState::Off(why)) => {
            failing.push(format!("the history is off, nothing is recorded: {why}"))
        }
        Some(HistoryState::Failing(why)) => {
            failing.push(format!("the history cannot be written: {why}"))
        }
        Some(HistoryState::Ok | HistoryState::Opening) | None => {}
    }
    let up = facts
        .devices
        .iter()
        .filter(|(_, status, _)| *status == DeviceStatus::Up)
        .count();
    let down: Vec<_> = facts
        .devices
        .iter()
        .filter(|(_, status, _)| *status == DeviceStatus::Down)
        .collect();
    if up == 0 && !down.is_empty() {
        failing.push(format!(
            "no device answers ({} of {} have failed)",
            down.len(),
            facts.devices.len()
        ));
    }
    for (id, _, why) in &down {
        degraded.push(match why {
            Some(why) => format!("device {id} is down: {why}"),
            None => format!("device {id} is down"),
        });
    }
    for (name, why) in &facts.lines_closed {
        degraded.push(format!("line {name} is not open: {why}"));
    }
    for (device, link, why) in &facts.links_down {
        degraded.push(format!("device {device}'s {link} link is down: {why}"));
    }
    for (name, why) in &facts.interfaces_down {
        degraded.push(format!("{name}: {why}"));
    }
    if let Some(why) = &facts.config_refused {
        degraded.push(format!(
            "the configuration file was changed but not reloaded: {why}"
        ));
    }
    let status = if !failing.is_empty() {
        Status::Failing
    } else if !degraded.is_empty() {
        Status::Degraded
    } else {
        Status::Ok
    };
    failing.append(&mut degraded);
    Health {
        status,
        reasons: failing,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn device(id: &str, status: DeviceStatus) -> (String, DeviceStatus, Option<String>) {
        let why = (status == DeviceStatus::Down).then(|| "no answer in 500 ms".to_owned());
        (id.to_owned(), status, why)
    }

    /// `jbc1` and `jbc2` in these states, the history written.
    fn stations(jbc1: DeviceStatus, jbc2: DeviceStatus) -> Facts {
        Facts {
            devices: vec![device("jbc1", jbc1), device("jbc2", jbc2)],
            history: Some(HistoryState::Ok),
            ..Facts::default()
        }
    }

    #[test]
    fn a_cell_whose_devices_answer_with_its_history_written_is_ok() {
        let facts = stations(DeviceStatus::Up, DeviceStatus::Connecting);
        assert_eq!(
            judge(&facts),
            Health {
                status: Status::Ok,
                reasons: vec![]
            }
        );
    }

    #[test]
    fn some_devices_down_a_line_closed_or_a_link_lost_is_degraded_with_each_reason() {
        let facts = Facts {
            lines_closed: vec![("bench".into(), "no such port".into())],
            interfaces_down: vec![("mqtt".into(), "broker link down: refused".into())],
            links_down: vec![("jbc1".into(), "events".into(), "refused".into())],
            ..stations(DeviceStatus::Up, DeviceStatus::Down)
        };
        let health = judge(&facts);
        assert_eq!(health.status, Status::Degraded);
        assert_eq!(
            health.reasons,
            [
                "device jbc2 is down: no answer in 500 ms",
                "line bench is not open: no such port",
                "device jbc1's events link is down: refused",
                "mqtt: broker link down: refused",
            ]
        );
    }

    #[test]
    fn no_device_answering_or_a_history_that_cannot_be_written_is_failing() {
        let none_answers = stations(DeviceStatus::Down, DeviceStatus::Connecting);
        let health = judge(&none_answers);
        assert_eq!(health.status, Status::Failing);
        assert_eq!(health.reasons[0], "no device answers (1 of 2 have failed)");
        let full_disk = Facts {
            devices: vec![device("jbc1", DeviceStatus::Up)],
            history: Some(HistoryState::Failing("database or disk is full".into())),
            ..Facts::default()
        };
        let health = judge(&full_disk);
        assert_eq!(health.status, Status::Failing);
        assert_eq!(
            health.reasons,
            ["the history cannot be written: database or disk is full"]
        );
    }

    #[test]
    fn devices_not_polled_yet_are_not_a_problem() {
        let starting = Facts {
            devices: vec![device("jbc1", DeviceStatus::Connecting)],
            history: Some(HistoryState::Opening),
            ..Facts::default()
        };
        assert_eq!(judge(&starting).status, Status::Ok);
    }
}

#[cfg(test)]
mod cell_tests {
    use super::*;
    use crate::config::{CellConfig, LineConfig};
    use crate::event::{Event, EventKind, fields};
    use crate::point::DeviceId;
    use crate::store::{Store, StoreOptions};
    use crate::time::Timestamp;

    #[test]
    fn a_devices_own_link_is_a_reason_while_its_events_say_it_is_down() {
        let dir = tempfile::tempdir().unwrap();
        let store = Store::open(dir.path(), StoreOptions::default()).unwrap();
        let config = CellConfig {
            lines: vec![LineConfig {
                name: "lan".into(),
                endpoint: link::Endpoint::parse(
                    "tcp://127.0.0.1:4001",
                    link::SerialSettings::new_8n1(9600),
                )
                .unwrap(),
                devices: vec![crate::testing::device("jbc1", 1)],
                reopen_after_timeouts: 0,
            }],
            ..CellConfig::default()
        };
        let cell = crate::testing::unopened_cell(&config, &store);
        let link_event = |state: &str| Event {
            t: Timestamp::now(),
            kind: EventKind::DeviceEvent,
            line: Some("lan".into()),
            device: Some(DeviceId::new("jbc1").unwrap()),
            point: None,
            message: format!("events link {state}"),
            fields: fields([
                ("link", serde_json::json!("events")),
                ("state", serde_json::json!(state)),
                ("error", serde_json::json!("connection refused")),
            ]),
        };
        cell.emit(link_event("down"));
        let facts = Facts::of(&cell, HistoryState::Ok);
        assert_eq!(
            judge(&facts).reasons,
            ["device jbc1's events link is down: connection refused"]
        );
        cell.emit(link_event("up"));
        assert!(Facts::of(&cell, HistoryState::Ok).links_down.is_empty());
    }
}
