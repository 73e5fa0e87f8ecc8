//! The cell's devices and lines at one moment ([`Roster`], replaced whole by a reload), and
//! a point's spec found in it ([`PointRef`]).

use std::collections::BTreeMap;
use std::sync::Arc;

use super::{DeviceEntry, LineEntry};
use crate::point::{DeviceId, PointSpec};

/// The devices and lines of the cell at one moment.
#[derive(Debug, Default)]
pub struct Roster {
    pub(super) devices: BTreeMap<DeviceId, Arc<DeviceEntry>>,
    pub(super) lines: Vec<Arc<LineEntry>>,
}

impl Roster {
    /// Every device, by id.
    pub fn devices(&self) -> impl Iterator<Item = &Arc<DeviceEntry>> {
        self.devices.values()
    }

    /// A device by id.
    pub fn device(&self, id: &str) -> Option<&Arc<DeviceEntry>> {
        DeviceId::new(id).ok().and_then(|id| self.devices.get(&id))
    }

    /// Every line, in the configuration's order.
    pub fn lines(&self) -> &[Arc<LineEntry>] {
        &self.lines
    }

    /// The roster of `lines`, each with its devices.
    pub(crate) fn of(lines: Vec<(Arc<LineEntry>, Vec<Arc<DeviceEntry>>)>) -> Result<Self, String> {
        let mut roster = Roster::default();
        for (line, devices) in lines {
            for device in devices {
                let id = device.id.clone();
                if roster.devices.insert(id.clone(), device).is_some() {
                    return Err(format!("device id {id} is used twice"));
                }
            }
            roster.lines.push(line);
        }
        Ok(roster)
    }
}

/// A point's spec, found in the roster in force (it stays valid after a reload).
#[derive(Debug, Clone)]
pub struct PointRef {
    pub(super) device: Arc<DeviceEntry>,
    pub(super) index: usize,
}

impl std::ops::Deref for PointRef {
    type Target = PointSpec;

    fn deref(&self) -> &PointSpec {
        &self.device.points[self.index]
    }
}
