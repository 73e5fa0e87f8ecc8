//! The audited part of the one guarded write path, shared by every interface that writes
//! (`POST /api/devices/{id}/write`, an MQTT `DCMD`).
//!
//! Each interface first decides who may write (HTTP: `--allow-writes` and the token; MQTT:
//! `--allow-writes` and `commands = true`) and refuses the rest without storing anything.
//! From there on every attempt goes through an [`Attempt`]:
//!
//! 1. A request the gateway refuses before the wire (unknown point, wrong kind of value,
//!    outside the point's range or step) is one `refused` audit row.
//! 2. A valid write commits an `attempted` row before it goes to the line, then a second
//!    row records how it ended (`accepted`, `refused` by the device, `failed`), and the
//!    accepted write is a `write` event.
//!
//! Every stored field is cut to a bounded length, so no request can grow the audit table
//! by more than a few kB. Each row is committed before the caller hears the answer.

use std::sync::Arc;

use crate::cell::{Cell, CheckedWrite};
use crate::driver::{ErrorKind, WriteError};
use crate::event::{Event, EventKind};
use crate::point::{PointId, Value};
use crate::store::{AuditEntry, AuditResult};
use crate::time::Timestamp;

// Bounds on names and logs, shared with the historian.
pub use kit::bounded::{LOG_EVERY, LogThrottle, MAX_NAME, cut};

/// Longest stored value as given (its JSON text).
pub const MAX_VALUE: usize = 256;
/// Longest stored detail.
pub const MAX_DETAIL: usize = 1024;

/// Writes refused before anything is stored (writes off, a wrong token, DCMDs without
/// `commands = true`): anyone who reaches the interface can send them by the thousand, so
/// they are counted (`cellbus_writes_total{result="unauthorised"}`) and logged at most once
/// every [`LOG_EVERY`], with how many there were.
#[derive(Debug, Default)]
pub struct Unauthorised {
    log: LogThrottle,
}

impl Unauthorised {
    /// Counts one refusal at `now`; returns how many to report when a log line is due.
    pub fn refused(&mut self, cell: &Cell, now: tokio::time::Instant) -> Option<u64> {
        cell.metrics()
            .writes
            .get_or_create(&crate::metrics::WriteLabels {
                result: "unauthorised".to_owned(),
            })
            .inc();
        self.log.count(now)
    }
}

/// Most sources [`RowThrottle`] follows at once; past it, the sources whose last row is
/// older than [`LOG_EVERY`] are forgotten, and a new source beyond that shares one slot.
pub const THROTTLED_SOURCES: usize = 256;

/// Refused commands of an authorised interface (an undecodable or refused MQTT DCMD):
/// anyone who can publish on the topic sends them at their own rate, so each source (a
/// topic) gets at most one audit row every [`LOG_EVERY`], which says how many were refused
/// since its last row. Commands that reach a device are never throttled.
#[derive(Debug, Default)]
pub struct RowThrottle {
    sources: std::collections::HashMap<String, LogThrottle>,
    /// The shared slot of the sources past [`THROTTLED_SOURCES`].
    others: LogThrottle,
}

impl RowThrottle {
    /// Counts one refusal from `source` at `now`; when a row is due, how many refusals it
    /// stands for (this one and those not written since the source's last row).
    pub fn count(&mut self, source: &str, now: tokio::time::Instant) -> Option<u64> {
        if let Some(throttle) = self.sources.get_mut(source) {
            return throttle.count(now);
        }
        if self.sources.len() >= THROTTLED_SOURCES {
            self.sources.retain(|_, t| !t.is_quiet(now));
        }
        if self.sources.len() >= THROTTLED_SOURCES {
            return self.others.count(now);
        }
        let mut throttle = LogThrottle::default();
        let due = throttle.count(now);
        self.sources.insert(source.to_owned(), throttle);
        due
    }
}

/// An authorised write attempt on its way to the audit table.
#[derive(Debug)]
pub struct Attempt {
    cell: Arc<Cell>,
    /// Who asks, in words (`127.0.0.1:50312`, `mqtt DCMD spBv1.0/…`).
    client: String,
    /// The device as the request named it.
    device: String,
    /// The point as the request named it, then its full id once known.
    point: String,
    /// The value as given.
    new: serde_json::Value,
}

/// A write the device took.
#[derive(Debug, Clone, PartialEq)]
pub struct Accepted {
    /// The point.
    pub point: PointId,
    /// The value before, if one was known.
    pub old: Option<Value>,
    /// The value written (as checked: an integer point's value is whole).
    pub new: Value,
    /// Words for the audit log and the event: `jbc1.air_temperature set to 350 °C (was …) by …`.
    pub detail: String,
}

impl Attempt {
    /// An attempt by `client` to set `point` of `device` to `new` (all as the request gave
    /// them).
    pub fn new(
        cell: Arc<Cell>,
        client: impl Into<String>,
        device: impl Into<String>,
        point: impl Into<String>,
        new: serde_json::Value,
    ) -> Self {
        Self {
            cell,
            client: client.into(),
            device: device.into(),
            point: point.into(),
            new,
        }
    }

    /// The point is known: its rows name it by its full id (`meter1.setpoint`) from now on.
    pub fn names(&mut self, point: &PointId) {
        self.point = point.to_string();
    }

    /// Records a refusal before the wire (`detail` says why).
    pub async fn refuse(&self, detail: &str, old: Option<Value>) {
        self.record(AuditResult::Refused, old, detail).await;
    }

    /// The gate's check ([`Cell::check_write`]: the point looked up once, the value checked
    /// once against its spec); a refusal is recorded and returned. The point's rows name it
    /// by its full id from now on.
    pub async fn check(
        &mut self,
        point: &PointId,
        value: &Value,
    ) -> Result<CheckedWrite, WriteError> {
        self.names(point);
        match self.cell.check_write(point, value) {
            Ok(write) => Ok(write),
            Err(error) => {
                // A value outside the point's range never reaches the wire, nor an
                // `attempted` row.
                let old = self
                    .cell
                    .device_entry(point.device())
                    .and_then(|d| d.point_index(point.name()).map(|i| (d, i)))
                    .and_then(|(d, i)| d.read().points.get(i).and_then(|p| p.value.clone()));
                self.refuse(&error.to_string(), old).await;
                Err(error)
            }
        }
    }

    /// [`Attempt::check`], then [`Attempt::carry_out_checked`]. Run it in a task of its own
    /// when the caller may leave before the answer: the write and its record then run to
    /// the end.
    pub async fn carry_out(mut self, point: PointId, value: Value) -> Result<Accepted, WriteError> {
        let write = self.check(&point, &value).await?;
        self.carry_out_checked(write).await
    }

    /// Records the attempt, has the line's task write, and records how it ended: the one
    /// way a write reaches a device.
    pub async fn carry_out_checked(mut self, write: CheckedWrite) -> Result<Accepted, WriteError> {
        let point = write.point().clone();
        self.names(&point);
        let old = write.old();
        let asked = format!("{point} to be set to {} by {}", write.value(), self.client);
        self.record(AuditResult::Attempted, old.clone(), &asked)
            .await;
        match self.cell.write_checked(&write).await {
            Ok(outcome) => {
                let spec = write.spec();
                let shown = |v: &Value| {
                    let label = spec.label(v).map(str::to_owned);
                    let unit = spec.unit.clone();
                    label.unwrap_or_else(|| match unit {
                        Some(u) => format!("{v} {u}"),
                        None => v.to_string(),
                    })
                };
                let detail = format!(
                    "{point} set to {}{} by {}",
                    shown(&outcome.new),
                    outcome
                        .old
                        .as_ref()
                        .map(|o| format!(" (was {})", shown(o)))
                        .unwrap_or_default(),
                    self.client
                );
                // The audit row first (whoever sees the event finds it committed), then the event,
                // committed before the caller hears the answer.
                self.record(AuditResult::Accepted, outcome.old.clone(), &detail)
                    .await;
                self.cell.emit(Event {
                    t: Timestamp::now(),
                    kind: EventKind::Write,
                    line: Some(write.line().to_owned()),
                    device: Some(write.device().clone()),
                    point: Some(point.clone()),
                    message: detail.clone(),
                    fields: crate::event::fields([
                        ("value", serde_json::json!(outcome.new)),
                        ("was", serde_json::json!(outcome.old)),
                        ("by", serde_json::json!(self.client)),
                    ]),
                });
                if let Err(e) = self.cell.store().flush().await {
                    tracing::error!("write event not committed: {e}");
                }
                Ok(Accepted {
                    point,
                    old: outcome.old,
                    new: outcome.new,
                    detail,
                })
            }
            Err(error) => {
                let result = match &error {
                    WriteError::Invalid(_) | WriteError::UnknownPoint { .. } => {
                        AuditResult::Refused
                    }
                    WriteError::Device(e)
                        if matches!(e.kind, ErrorKind::Usage | ErrorKind::Refused) =>
                    {
                        AuditResult::Refused
                    }
                    _ => AuditResult::Failed,
                };
                self.record(result, old, &error.to_string()).await;
                Err(error)
            }
        }
    }

    /// Writes the audit row and waits for its commit, so an answered request is on disk.
    async fn record(&self, result: AuditResult, old: Option<Value>, detail: &str) {
        let store = self.cell.store();
        let new = match &self.new {
            serde_json::Value::String(text) => serde_json::Value::String(cut(text, MAX_VALUE)),
            other => {
                let text = other.to_string();
                if text.len() > MAX_VALUE {
                    serde_json::Value::String(cut(&text, MAX_VALUE))
                } else {
                    other.clone()
                }
            }
        };
        store.audit(AuditEntry {
            t: Timestamp::now(),
            client: cut(&self.client, MAX_NAME),
            device: cut(&self.device, MAX_NAME),
            point: cut(&self.point, MAX_NAME),
            old,
            new,
            result,
            detail: cut(detail, MAX_DETAIL),
        });
        self.cell
            .metrics()
            .writes
            .get_or_create(&crate::metrics::WriteLabels {
                result: result.as_str().to_owned(),
            })
            .inc();
        if let Err(e) = store.flush().await {
            tracing::error!("audit row not committed: {e}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_source_gets_one_row_an_interval_and_the_next_row_counts_what_was_left_out() {
        let mut throttle = RowThrottle::default();
        let t0 = tokio::time::Instant::now();
        assert_eq!(
            throttle.count("a", t0),
            Some(1),
            "the first is written at once"
        );
        for _ in 0..99 {
            assert_eq!(throttle.count("a", t0), None);
        }
        assert_eq!(
            throttle.count("b", t0),
            Some(1),
            "another source has its own"
        );
        assert_eq!(throttle.count("a", t0 + LOG_EVERY), Some(100));
    }

    #[test]
    fn sources_past_the_cap_share_one_slot_until_quiet_ones_are_forgotten() {
        let mut throttle = RowThrottle::default();
        let t0 = tokio::time::Instant::now();
        for n in 0..THROTTLED_SOURCES {
            assert_eq!(throttle.count(&format!("topic/{n}"), t0), Some(1));
        }
        assert_eq!(throttle.count("one more", t0), Some(1));
        assert_eq!(throttle.count("and another", t0), None, "the shared slot");
        assert_eq!(throttle.sources.len(), THROTTLED_SOURCES, "bounded");
        // An interval later the quiet sources are forgotten and new ones get a slot.
        let later = t0 + LOG_EVERY;
        assert_eq!(throttle.count("a new one", later), Some(1));
        assert_eq!(throttle.sources.len(), 1);
    }
}
