//! Device listings written straight into one buffer: `/api/devices`, `/api/devices/{id}`
//! and the event stream's snapshot.
//!
//! The JSON is the one [`DeviceView`](crate::cell::DeviceView)'s derived `Serialize` gives
//! (a test compares the two byte for byte), without building views, cloning strings or a
//! `serde_json::Value` tree in between. A device's description — its points' names, units,
//! kinds, enumeration labels, groups, write ranges and poll periods — does not change while
//! the cell runs (a new configuration is a new cell and a new router), so it is serialised
//! once, when the router is built, into a [`PointsTemplate`]: for each point the JSON before
//! its live part and the JSON after it. Devices whose descriptions are the same apart from
//! their id (a thousand JBC stations) share one template; the device id is spliced in
//! where each point id starts. A listing then copies those bytes and writes only the live
//! part (value, label, quality, time, error, alarm, status), each device under its state's
//! read lock for the few microseconds that takes, so a poller waits at most that long.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;

use serde::Serialize;
use serde_json::ser::{CompactFormatter, Formatter};

use crate::cell::{DeviceEntry, DeviceState, DeviceStatus, Roster, judge_staleness};
use crate::point::{Quality, Value};
use crate::time::{Timestamp, duration_millis};

/// A field of a device in `/api/devices`, by its name there.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Field {
    Id,
    Name,
    Protocol,
    Line,
    Address,
    Status,
    Since,
    Error,
    LastOk,
    Failures,
    NextTryAt,
    NextTryInMs,
    Groups,
    Points,
}

impl Field {
    /// Every field, in the order of [`Field::NAMES`].
    const ALL: [Field; 14] = [
        Field::Id,
        Field::Name,
        Field::Protocol,
        Field::Line,
        Field::Address,
        Field::Status,
        Field::Since,
        Field::Error,
        Field::LastOk,
        Field::Failures,
        Field::NextTryAt,
        Field::NextTryInMs,
        Field::Groups,
        Field::Points,
    ];

    /// The fields' names, as `?fields=` takes them.
    pub(crate) const NAMES: [&'static str; 14] = [
        "id",
        "name",
        "protocol",
        "line",
        "address",
        "status",
        "since",
        "error",
        "last_ok",
        "failures",
        "next_try_at",
        "next_try_in_ms",
        "groups",
        "points",
    ];

    fn bit(self) -> u16 {
        1 << self as u16
    }
}

/// The fields a listing shows; `id` always.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Fields(u16);

impl Fields {
    /// Every field.
    pub(crate) const ALL: Fields = Fields(u16::MAX);

    /// The fields named in `list` (names separated by commas, blanks around them ignored),
    /// and `id`; the first unknown name is the error.
    pub(crate) fn parse(list: &str) -> Result<Fields, String> {
        let mut bits = Field::Id.bit();
        for name in list.split(',').map(str::trim) {
            let field = Field::NAMES
                .iter()
                .position(|n| *n == name)
                .map(|i| Field::ALL[i])
                .ok_or_else(|| name.to_owned())?;
            bits |= field.bit();
        }
        Ok(Fields(bits))
    }

    fn has(self, field: Field) -> bool {
        self.0 & field.bit() != 0
    }
}

/// One point's fixed JSON around its live part.
#[derive(Debug, PartialEq)]
struct PointTemplate {
    /// From just after the device id in the point id (`.air_temperature","name":…,"value":`),
    /// or, when not spliced, from the object's start.
    head: Box<[u8]>,
    /// From `,"period_ms":` to the object's end.
    tail: Box<[u8]>,
    /// Its poll group's period, to judge staleness.
    period: Duration,
}

/// The fixed JSON of a device's groups and points.
#[derive(Debug, PartialEq)]
pub(crate) struct PointsTemplate {
    /// Whether each point starts with `{"id":"` and the device's id (every point id is
    /// `<device>.<point>`); when not, each head holds its whole id.
    splice: bool,
    /// The groups' array: `[{"name":"live","period_ms":1000},…]`.
    groups: Box<[u8]>,
    points: Box<[PointTemplate]>,
}

impl PointsTemplate {
    /// The template of `device`'s description.
    fn of(device: &DeviceEntry) -> PointsTemplate {
        let prefix = format!("{}.", device.id);
        let splice = device
            .points
            .iter()
            .all(|p| p.id.as_str().starts_with(&prefix));
        let mut groups = b"[".to_vec();
        for (i, group) in device.groups.iter().enumerate() {
            if i > 0 {
                groups.push(b',');
            }
            groups.extend_from_slice(b"{\"name\":");
            json(&mut groups, &group.name);
            groups.extend_from_slice(b",\"period_ms\":");
            json(&mut groups, &duration_millis(group.period));
            groups.push(b'}');
        }
        groups.push(b']');
        let points = device
            .points
            .iter()
            .map(|spec| {
                let mut head = Vec::new();
                if splice {
                    // The rest of the id after the device's: `.air_temperature"`.
                    json(&mut head, &spec.id.as_str()[device.id.as_str().len()..]);
                    head.remove(0);
                } else {
                    head.extend_from_slice(b"{\"id\":");
                    json(&mut head, &spec.id);
                }
                head.extend_from_slice(b",\"name\":");
                json(&mut head, &spec.name);
                head.extend_from_slice(b",\"unit\":");
                json(&mut head, &spec.unit);
                head.extend_from_slice(b",\"value\":");
                let period = device.period(&spec.group);
                let mut tail = b",\"period_ms\":".to_vec();
                json(&mut tail, &duration_millis(period));
                tail.extend_from_slice(b",\"kind\":");
                json(&mut tail, &spec.kind);
                tail.extend_from_slice(b",\"group\":");
                json(&mut tail, &spec.group);
                tail.extend_from_slice(b",\"writable\":");
                json(&mut tail, &spec.writable);
                tail.push(b'}');
                PointTemplate {
                    head: head.into(),
                    tail: tail.into(),
                    period,
                }
            })
            .collect();
        PointsTemplate {
            splice,
            groups: groups.into(),
            points,
        }
    }

    /// The bytes that tell two templates apart (for sharing equal ones).
    fn key(&self) -> Vec<u8> {
        let mut key = vec![u8::from(self.splice)];
        let mut part = |bytes: &[u8]| {
            key.extend_from_slice(&(bytes.len() as u64).to_le_bytes());
            key.extend_from_slice(bytes);
        };
        part(&self.groups);
        for point in &self.points {
            part(&point.head);
            part(&point.tail);
            part(&point.period.as_nanos().to_le_bytes());
        }
        key
    }
}

/// About the bytes of a device's fields besides its groups and points.
const DEVICE_LIVE_BYTES: usize = 400;

/// About the bytes of a point's live part (value, label, quality, time, alarm).
const POINT_LIVE_BYTES: usize = 110;

/// A device and its template.
#[derive(Debug)]
struct Listed {
    entry: Arc<DeviceEntry>,
    points: Arc<PointsTemplate>,
}

/// The cell's devices, in id order, each with the template of its description.
#[derive(Debug)]
pub(crate) struct Listing {
    devices: Vec<Listed>,
    /// Templates held, after sharing.
    templates: usize,
    /// About the bytes a full listing takes (the first one's buffer is that big at once).
    size_estimate: usize,
}

impl Listing {
    /// Serialises every device's description once; equal ones are shared.
    pub(crate) fn new(roster: &Roster) -> Listing {
        let mut shared: HashMap<Vec<u8>, Arc<PointsTemplate>> = HashMap::new();
        let devices: Vec<Listed> = roster
            .devices()
            .map(|entry| {
                let template = PointsTemplate::of(entry);
                let points = Arc::clone(
                    shared
                        .entry(template.key())
                        .or_insert_with(|| Arc::new(template)),
                );
                Listed {
                    entry: Arc::clone(entry),
                    points,
                }
            })
            .collect();
        let size_estimate = devices
            .iter()
            .map(|d| {
                let id = d.entry.id.as_str().len();
                DEVICE_LIVE_BYTES
                    + d.points.groups.len()
                    + d.points
                        .points
                        .iter()
                        .map(|p| id + p.head.len() + p.tail.len() + POINT_LIVE_BYTES)
                        .sum::<usize>()
            })
            .sum();
        Listing {
            devices,
            templates: shared.len(),
            size_estimate,
        }
    }

    /// About the bytes a full listing takes.
    pub(crate) fn size_estimate(&self) -> usize {
        self.size_estimate
    }

    /// How many devices.
    pub(crate) fn len(&self) -> usize {
        self.devices.len()
    }

    /// How many distinct templates the devices share.
    pub(crate) fn templates(&self) -> usize {
        self.templates
    }

    /// The devices, in id order (the cell's).
    pub(crate) fn entries(&self) -> impl Iterator<Item = ListedDevice<'_>> {
        self.devices.iter().map(ListedDevice)
    }

    /// A device by id.
    pub(crate) fn get(&self, id: &str) -> Option<ListedDevice<'_>> {
        self.devices
            .binary_search_by(|d| d.entry.id.as_str().cmp(id))
            .ok()
            .map(|i| ListedDevice(&self.devices[i]))
    }
}

/// One device of a [`Listing`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct ListedDevice<'a>(&'a Listed);

impl ListedDevice<'_> {
    /// Its id.
    pub(crate) fn id(&self) -> &str {
        self.0.entry.id.as_str()
    }

    /// Writes the device's JSON object with `fields` (in the order of the view's fields),
    /// its live part read at `now` under one look at its state.
    pub(crate) fn write(&self, out: &mut Vec<u8>, fields: Fields, now: Timestamp) {
        let Listed { entry, points } = self.0;
        let mut first = true;
        let mut key = |out: &mut Vec<u8>, name: &[u8]| {
            out.extend_from_slice(if first { b"{\"" } else { b",\"" });
            first = false;
            out.extend_from_slice(name);
            out.extend_from_slice(b"\":");
        };
        if fields.has(Field::Name) {
            key(out, b"name");
            json(out, &entry.name);
        }
        if fields.has(Field::Protocol) {
            key(out, b"protocol");
            json(out, &entry.protocol);
        }
        if fields.has(Field::Line) {
            key(out, b"line");
            json(out, &entry.line);
        }
        if fields.has(Field::Address) {
            key(out, b"address");
            json(out, &entry.address);
        }
        // The id is always there; device ids need no escaping.
        key(out, b"id");
        out.push(b'"');
        out.extend_from_slice(entry.id.as_str().as_bytes());
        out.push(b'"');
        let state = entry.read();
        let DeviceState {
            status,
            since,
            error,
            last_ok,
            failures,
            next_try_at,
            points: live,
        } = &*state;
        if fields.has(Field::Status) {
            key(out, b"status");
            out.extend_from_slice(match status {
                DeviceStatus::Connecting => b"\"connecting\"",
                DeviceStatus::Up => b"\"up\"",
                DeviceStatus::Down => b"\"down\"",
            });
        }
        if fields.has(Field::Since) {
            key(out, b"since");
            timestamp(out, *since);
        }
        if fields.has(Field::Error) {
            key(out, b"error");
            json(out, error);
        }
        if fields.has(Field::LastOk) {
            key(out, b"last_ok");
            optional_timestamp(out, *last_ok);
        }
        if fields.has(Field::Failures) {
            key(out, b"failures");
            json(out, failures);
        }
        if fields.has(Field::NextTryAt) {
            key(out, b"next_try_at");
            optional_timestamp(out, *next_try_at);
        }
        if fields.has(Field::NextTryInMs) {
            key(out, b"next_try_in_ms");
            match next_try_at {
                Some(t) => json(out, &(t.0 - now.0).max(0)),
                None => out.extend_from_slice(b"null"),
            }
        }
        if fields.has(Field::Groups) {
            key(out, b"groups");
            out.extend_from_slice(&points.groups);
        }
        if fields.has(Field::Points) {
            key(out, b"points");
            out.push(b'[');
            for (i, (template, point)) in points.points.iter().zip(live).enumerate() {
                if i > 0 {
                    out.push(b',');
                }
                if points.splice {
                    out.extend_from_slice(b"{\"id\":\"");
                    out.extend_from_slice(entry.id.as_str().as_bytes());
                }
                out.extend_from_slice(&template.head);
                match &point.value {
                    Some(Value::Number(n)) => number(out, *n),
                    Some(Value::Text(t)) => json(out, t),
                    None => out.extend_from_slice(b"null"),
                }
                out.extend_from_slice(b",\"text\":");
                match point.value.as_ref().and_then(|v| entry.points[i].label(v)) {
                    Some(label) => json(out, label),
                    None => out.extend_from_slice(b"null"),
                }
                out.extend_from_slice(b",\"quality\":");
                let quality = point
                    .quality
                    .map(|q| judge_staleness(q, point.t, template.period, now));
                out.extend_from_slice(match quality {
                    Some(Quality::Good) => b"\"good\"",
                    Some(Quality::Stale) => b"\"stale\"",
                    Some(Quality::Bad) => b"\"bad\"",
                    None => b"null",
                });
                out.extend_from_slice(b",\"t\":");
                optional_timestamp(out, point.t);
                out.extend_from_slice(b",\"error\":");
                match point.error.as_deref() {
                    Some(error) => json(out, error),
                    None => out.extend_from_slice(b"null"),
                }
                out.extend_from_slice(if point.alarm {
                    b",\"alarm\":true"
                } else {
                    b",\"alarm\":false"
                });
                out.extend_from_slice(&template.tail);
            }
            out.push(b']');
        }
        drop(state);
        out.push(b'}');
    }
}

/// Writes `value` as serde_json writes it (into a `Vec`, which cannot fail).
fn json(out: &mut Vec<u8>, value: &(impl Serialize + ?Sized)) {
    // Serialising these types into memory has no way to fail: no maps with non-string
    // keys, no I/O.
    let _ = serde_json::to_writer(&mut *out, value);
}

/// A number as serde_json writes an `f64`: `null` when not finite.
fn number(out: &mut Vec<u8>, n: f64) {
    if n.is_finite() {
        let _ = CompactFormatter.write_f64(out, n);
    } else {
        out.extend_from_slice(b"null");
    }
}

/// A time as its `Serialize` writes it.
fn timestamp(out: &mut Vec<u8>, t: Timestamp) {
    match t.rfc3339_millis() {
        Some(text) => {
            out.push(b'"');
            out.extend_from_slice(&text);
            out.push(b'"');
        }
        None => json(out, &t),
    }
}

fn optional_timestamp(out: &mut Vec<u8>, t: Option<Timestamp>) {
    match t {
        Some(t) => timestamp(out, t),
        None => out.extend_from_slice(b"null"),
    }
}

/// Writes `{"devices":[…],` for `devices` with `fields`, read at `now`; the caller ends the
/// object ([`field`]).
pub(crate) fn devices_array<'a>(
    out: &mut Vec<u8>,
    devices: impl Iterator<Item = ListedDevice<'a>>,
    fields: Fields,
    now: Timestamp,
) {
    out.extend_from_slice(b"{\"devices\":[");
    for (i, device) in devices.enumerate() {
        if i > 0 {
            out.push(b',');
        }
        device.write(out, fields, now);
    }
    out.extend_from_slice(b"],");
}

/// Writes `"key":value` for the rest of a listing's object (after [`devices_array`]).
pub(crate) fn field(out: &mut Vec<u8>, key: &str, value: &(impl Serialize + ?Sized), last: bool) {
    json(out, key);
    out.push(b':');
    json(out, value);
    out.push(if last { b'}' } else { b',' });
}

/// Bytes to reserve for a full listing: the last one's size or, before the first, the
/// estimate, and a little more.
pub(crate) fn capacity(last: usize, estimate: usize) -> usize {
    let expected = if last > 0 { last } else { estimate };
    expected + expected / 8 + 256
}
