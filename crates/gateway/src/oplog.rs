//! What the gateway tells its operator on stderr, at the default log level (`info` for
//! cellbus's own messages).
//!
//! Every event goes to the history and the event stream; the log gets what someone
//! watching the terminal or the journal must know, at a level by kind ([`level_of`]):
//! a device or a line going down, the history failing and an interface's link lost are
//! warnings; coming back, the start and the stop are info; alarms, state changes, device
//! events and writes are debug (they are data: the page, `/api/events` and the interfaces
//! carry them). A device going down is told with what to check (its kind's
//! [`DeviceKind::hint`](crate::driver::DeviceKind::hint), in the event's `hint` field). A
//! device down because its line is, is left to the line's warning (debug). A
//! device or line that keeps going down and up is logged at most
//! [`BURST`] times in [`WINDOW`], then once more to say it goes on ([`Throttle`]).
//!
//! After the first round of polls, `serve` logs one line saying which devices answer and,
//! for the others, why not and what to check ([`describe`]).

use std::collections::HashMap;
use std::sync::{Mutex, PoisonError};
use std::time::{Duration, Instant};

use tracing::Level;

use crate::driver::DeviceError;
use crate::event::{Event, EventKind};

/// How many up/down lines one device or line may log in a [`WINDOW`].
pub const BURST: u32 = 5;

/// The window of the throttle.
pub const WINDOW: Duration = Duration::from_secs(600);

/// The level an event of `kind` is logged at.
pub fn level_of(kind: EventKind) -> Level {
    match kind {
        EventKind::LineDown
        | EventKind::DeviceDown
        | EventKind::HistoryFailed
        | EventKind::HistoryReset
        | EventKind::InterfaceDown => Level::WARN,
        // A file that fails its check: the log says why, as `config check` would.
        EventKind::ConfigRefused => Level::ERROR,
        EventKind::GatewayStarted
        | EventKind::GatewayStopped
        | EventKind::LineUp
        | EventKind::LineReopened
        | EventKind::DeviceUp
        | EventKind::HistoryRecovered
        | EventKind::InterfaceUp
        | EventKind::ConfigReloaded => Level::INFO,
        EventKind::AlarmRaised
        | EventKind::AlarmCleared
        | EventKind::AlarmChanged
        | EventKind::Write
        | EventKind::StateChanged
        | EventKind::DeviceEvent => Level::DEBUG,
    }
}

/// A device's failure in words, with what to check (`hint`: its kind's
/// [`DeviceKind::hint`](crate::driver::DeviceKind::hint)).
pub fn describe(error: &DeviceError, hint: Option<&str>) -> String {
    match hint {
        Some(hint) => format!("{} ({}; {hint})", error.message, error.kind),
        None => format!("{} ({})", error.message, error.kind),
    }
}

/// Whether a line may be logged for one device or line now.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decision {
    /// Log it.
    Log {
        /// Changes left out since the last one logged.
        quiet: u32,
    },
    /// Log it and say that further changes are not logged until the window ends.
    LastOne,
    /// Leave it out.
    Quiet,
}

/// Counts the up/down lines of each device and line in windows of [`WINDOW`].
#[derive(Debug, Default)]
pub struct Throttle {
    keys: HashMap<String, Window>,
}

#[derive(Debug)]
struct Window {
    started: Instant,
    logged: u32,
    quiet: u32,
}

impl Throttle {
    /// Decides for one more change of `key` at `now`.
    pub fn decide(&mut self, key: &str, now: Instant) -> Decision {
        let window = self.keys.entry(key.to_owned()).or_insert(Window {
            started: now,
            logged: 0,
            quiet: 0,
        });
        let mut quiet = 0;
        if now.duration_since(window.started) >= WINDOW {
            quiet = window.quiet;
            *window = Window {
                started: now,
                logged: 0,
                quiet: 0,
            };
        }
        window.logged += 1;
        match window.logged {
            n if n < BURST => Decision::Log { quiet },
            n if n == BURST => Decision::LastOne,
            _ => {
                window.quiet += 1;
                Decision::Quiet
            }
        }
    }
}

/// Logs `event` at its kind's level, throttled per device or line for ups and downs.
pub fn log(throttle: &Mutex<Throttle>, event: &Event) {
    let updown = matches!(
        event.kind,
        EventKind::DeviceUp | EventKind::DeviceDown | EventKind::LineUp | EventKind::LineDown
    );
    let key = match (&event.device, &event.line) {
        (Some(device), _) if updown => Some(format!("device {device}")),
        (None, Some(line)) if updown => Some(format!("line {line}")),
        _ => None,
    };
    let mut message = event.message.clone();
    if event.kind == EventKind::DeviceDown
        && let Some(hint) = event.fields.get("hint").and_then(|h| h.as_str())
    {
        message = format!("{message}; {hint}");
    }
    if let Some(key) = key {
        let decision = throttle
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .decide(&key, Instant::now());
        match decision {
            Decision::Log { quiet: 0 } => {}
            Decision::Log { quiet } => {
                message = format!("{message} ({quiet} more up/down changes of {key} not logged)")
            }
            Decision::LastOne => {
                message = format!(
                    "{message}; {key} keeps changing: its next changes are not logged for {} min (/api/events has them all)",
                    WINDOW.as_secs() / 60
                )
            }
            Decision::Quiet => return,
        }
    }
    let kind = event.kind.as_str();
    // A device's own link going down or up (a Panasonic machine's Port 2): told like a
    // device's.
    let link = event
        .fields
        .get("link")
        .and(event.fields.get("state"))
        .and_then(|state| state.as_str());
    // A device down because its line is: the line's own warning says it once for all of
    // them (a line of 50 devices would otherwise be 50 warnings).
    let line_down = event.kind == EventKind::DeviceDown
        && event.fields.get("error_kind").and_then(|k| k.as_str()) == Some("disconnected");
    let level = match (event.kind, link) {
        (EventKind::DeviceEvent, Some("down")) => Level::WARN,
        (EventKind::DeviceEvent, Some("up")) => Level::INFO,
        _ if line_down => Level::DEBUG,
        _ => level_of(event.kind),
    };
    match level {
        Level::ERROR => tracing::error!(kind, "{message}"),
        Level::WARN => tracing::warn!(kind, "{message}"),
        Level::INFO => tracing::info!(kind, "{message}"),
        _ => tracing::debug!(kind, "{message}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::driver::ErrorKind;

    #[test]
    fn a_flapping_device_logs_a_burst_then_says_it_goes_on_then_is_quiet_until_the_window_ends() {
        let mut throttle = Throttle::default();
        let t0 = Instant::now();
        for n in 0..BURST - 1 {
            assert_eq!(
                throttle.decide("device jbc1", t0 + Duration::from_secs(u64::from(n))),
                Decision::Log { quiet: 0 }
            );
        }
        assert_eq!(throttle.decide("device jbc1", t0), Decision::LastOne);
        assert_eq!(throttle.decide("device jbc1", t0), Decision::Quiet);
        assert_eq!(throttle.decide("device jbc1", t0), Decision::Quiet);
        assert_eq!(
            throttle.decide("device jbc2", t0),
            Decision::Log { quiet: 0 },
            "another device has its own window"
        );
        assert_eq!(
            throttle.decide("device jbc1", t0 + WINDOW),
            Decision::Log { quiet: 2 },
            "the next window's first line counts what was left out"
        );
    }

    #[test]
    fn each_event_kind_has_the_level_an_operator_expects() {
        assert_eq!(level_of(EventKind::DeviceDown), Level::WARN);
        assert_eq!(level_of(EventKind::LineDown), Level::WARN);
        assert_eq!(level_of(EventKind::HistoryFailed), Level::WARN);
        assert_eq!(level_of(EventKind::InterfaceDown), Level::WARN);
        assert_eq!(level_of(EventKind::DeviceUp), Level::INFO);
        assert_eq!(level_of(EventKind::GatewayStarted), Level::INFO);
        assert_eq!(level_of(EventKind::DeviceEvent), Level::DEBUG);
        assert_eq!(level_of(EventKind::AlarmRaised), Level::DEBUG);
    }

    #[test]
    fn a_timeout_is_described_with_what_to_check() {
        let error = DeviceError::new(ErrorKind::Timeout, "no answer in 300 ms");
        let text = describe(&error, error.kind.hint());
        assert!(
            text.starts_with("no answer in 300 ms (timeout; check"),
            "{text}"
        );
        assert!(text.contains("`address`"), "{text}");
    }
}
