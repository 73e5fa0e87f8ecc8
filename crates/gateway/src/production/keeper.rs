//! What the gateway keeps of production while it runs: each producing device's OEE of the
//! current shift as points (so every interface carries it), the time each device spends
//! per E10 category (the metrics), and a mark of when it was last running, so that the
//! time a stopped gateway did not see is unknown, not the last state stretched over it.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::registry::Registry;
use std::sync::atomic::AtomicU64;
use tokio::sync::{broadcast, watch};

use super::e10::{Category, StateCode};
use super::states::{self, CODE_POINT};
use super::{OEE_PERIOD, report};
use crate::cell::{Cell, LiveMessage};
use crate::driver::Reading;
use crate::event::EventKind;
use crate::point::{Quality, Value};
use crate::store::{HistoryState, Sample, read_setting, write_setting};
use crate::time::Timestamp;

/// The setting holding when the gateway last ran, ms since the epoch.
pub const ALIVE_SETTING: &str = "production_alive_ms";

/// Labels of the time per E10 category.
#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
struct StateLabels {
    device: String,
    category: String,
}

/// Labels of the OEE gauges.
#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
struct OeeLabels {
    device: String,
    part: String,
    window: String,
}

/// The keeper's metrics, registered when it starts.
#[derive(Debug, Clone, Default)]
struct ProductionMetrics {
    /// Seconds each device spent in each E10 category.
    state_seconds: Family<StateLabels, Counter<f64, AtomicU64>>,
    /// The OEE of each producing device's current shift, and its parts.
    oee: Family<OeeLabels, Gauge<f64, AtomicU64>>,
}

impl ProductionMetrics {
    fn register(&self, registry: &mut Registry) {
        registry.register(
            "device_state_seconds",
            "Time the device spent in each SEMI E10 category (unknown: no data)",
            self.state_seconds.clone(),
        );
        registry.register(
            "oee_ratio",
            "OEE of the current shift so far and its parts (availability, performance, quality), 0-1",
            self.oee.clone(),
        );
    }

    /// Counts `seconds` of `device` in `category`.
    fn add(&self, device: &str, category: Category, seconds: f64) {
        self.state_seconds
            .get_or_create(&StateLabels {
                device: device.to_owned(),
                category: category.as_str().to_owned(),
            })
            .inc_by(seconds);
    }

    /// Sets `part` of `device`'s OEE this shift (NaN: not known).
    fn set_oee(&self, device: &str, part: &str, value: f64) {
        self.oee
            .get_or_create(&OeeLabels {
                device: device.to_owned(),
                part: part.to_owned(),
                window: "shift".to_owned(),
            })
            .set(value);
    }
}

/// How often the time per category is brought up to date for the metrics.
const CLOCK_TICK: Duration = Duration::from_secs(5);

/// Before the first poll: the devices' states since the gateway last ran are unknown. For
/// each state point whose last stored change is a good value, a bad one is stored just
/// after the later of that change and the gateway's last mark of life, so the interval it
/// began ends there; the reason point's carries [`states::GATEWAY_DOWN`], so the time up
/// to the first poll counts as no data, not as a device that did not answer. Blocking (the
/// history's queries).
pub fn close_gap(cell: &Cell, data_dir: &Path) {
    let store = cell.store();
    if store.wait_open().is_err()
        || matches!(store.health(Timestamp::now()).history, HistoryState::Off(_))
    {
        return;
    }
    let alive = read_setting(data_dir, ALIVE_SETTING).ok().flatten();
    let now = Timestamp::now();
    for device in &cell.production().with_states {
        for name in [states::STATE_POINT, CODE_POINT, states::REASON_POINT] {
            let point = states::point_id(device, name);
            let Ok(Some(last)) = store.history_nearest(&point, now, false) else {
                continue;
            };
            if last.quality == Quality::Bad || last.value.is_none() {
                continue;
            }
            let t = Timestamp(alive.unwrap_or(last.t.0).max(last.t.0) + 1);
            if t >= now {
                continue;
            }
            let value =
                (name == states::REASON_POINT).then(|| Value::Text(states::GATEWAY_DOWN.into()));
            store.sample(Sample {
                point,
                t,
                value,
                quality: Quality::Bad,
            });
        }
    }
}

/// Runs until `stop` turns true: the OEE points every [`OEE_PERIOD`], the metrics' time
/// per category, and the mark of life in `data_dir`.
pub async fn run(cell: Arc<Cell>, data_dir: PathBuf, mut stop: watch::Receiver<bool>) {
    let metrics = ProductionMetrics::default();
    cell.metrics()
        .register(|registry| metrics.register(registry));
    let mut changes = cell.subscribe();
    let mut clocks = Clocks::new(&cell, metrics.clone());
    let mut oee = tokio::time::interval(OEE_PERIOD);
    oee.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut tick = tokio::time::interval(CLOCK_TICK);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            _ = stop.changed() => break,
            _ = oee.tick() => {
                let cell = Arc::clone(&cell);
                let dir = data_dir.clone();
                let metrics = metrics.clone();
                let _ = tokio::task::spawn_blocking(move || {
                    let _ = write_setting(&dir, ALIVE_SETTING, Timestamp::now().0);
                    current_oee(&cell, &metrics);
                })
                .await;
            }
            _ = tick.tick() => clocks.flush(),
            message = changes.recv() => match message {
                Ok(LiveMessage::Value(view)) if view.id.name() == CODE_POINT => {
                    let code = match (view.quality, view.value.as_ref().and_then(Value::as_number)) {
                        (Some(Quality::Good | Quality::Stale), Some(n)) => StateCode::of_number(n),
                        _ => StateCode::UNKNOWN,
                    };
                    clocks.set(view.id.device(), code.category());
                }
                Ok(LiveMessage::Event(event)) if event.kind == EventKind::ConfigReloaded => {
                    clocks.follow(&cell);
                }
                Err(broadcast::error::RecvError::Closed) => break,
                _ => {}
            },
        }
    }
    clocks.flush();
}

/// Each producing device's OEE of the shift it is in, so far, as its OEE points and
/// gauges. Outside every shift the points keep the last shift's figures.
fn current_oee(cell: &Cell, metrics: &ProductionMetrics) {
    let now = Timestamp::now();
    let plan = cell.production();
    let Some(shift) = plan.shifts.at(now) else {
        return;
    };
    for device in plan.producers.keys() {
        let Some(entry) = cell.device_entry(device.as_str()) else {
            continue;
        };
        let Ok(report) =
            report::production(cell.store(), &plan, device, (shift.start, now), None, now)
        else {
            continue;
        };
        let Some(oee) = report.production else {
            continue;
        };
        let parts = [
            ("oee", oee.oee),
            ("availability", oee.availability),
            ("performance", oee.performance),
            ("quality", oee.quality),
        ];
        let mut readings = Vec::new();
        for ((part, value), (name, _)) in parts.into_iter().zip(super::OEE_POINTS) {
            metrics.set_oee(device.as_str(), part, value.unwrap_or(f64::NAN));
            if let Some(value) = value {
                readings.push(Reading {
                    point: states::point_id(device, name),
                    value: Ok(Value::Number((value * 10_000.0).round() / 10_000.0)),
                });
            }
        }
        crate::scheduler::apply_readings(cell, &entry, readings);
    }
}

/// The time each device with states has spent per category since the last flush.
struct Clocks {
    running: HashMap<String, (Category, Instant)>,
    metrics: ProductionMetrics,
}

impl Clocks {
    fn new(cell: &Cell, metrics: ProductionMetrics) -> Self {
        let now = Instant::now();
        let running = cell
            .production()
            .with_states
            .iter()
            .map(|d| (d.to_string(), (Category::Unknown, now)))
            .collect();
        Self { running, metrics }
    }

    /// Follows a reload: a device added with states starts unknown, one removed (or no
    /// longer with states) has its time counted and is dropped.
    fn follow(&mut self, cell: &Cell) {
        self.flush();
        let plan = cell.production();
        self.running
            .retain(|device, _| plan.with_states.iter().any(|d| d.as_str() == device));
        let now = Instant::now();
        for device in &plan.with_states {
            self.running
                .entry(device.to_string())
                .or_insert((Category::Unknown, now));
        }
    }

    /// `device` is now in `category`: the time in the last one is counted.
    fn set(&mut self, device: &str, category: Category) {
        let now = Instant::now();
        if let Some((was, since)) = self.running.get_mut(device) {
            let seconds = now.duration_since(*since).as_secs_f64();
            self.metrics.add(device, *was, seconds);
            *was = category;
            *since = now;
        }
    }

    /// Counts the time up to now in each device's category.
    fn flush(&mut self) {
        let now = Instant::now();
        for (device, (category, since)) in &mut self.running {
            let seconds = now.duration_since(*since).as_secs_f64();
            self.metrics.add(device, *category, seconds);
            *since = now;
        }
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;
    use std::time::Duration;

    use super::*;
    use crate::metrics::Metrics;
    use crate::point::PointId;
    use crate::store::{Store, StoreOptions};
    use crate::testing::config::{ONE, parse};

    #[tokio::test]
    async fn the_time_a_stopped_gateway_did_not_see_is_no_data_not_the_last_state_stretched() {
        let dir = tempfile::tempdir().unwrap();
        let store = Store::open(dir.path(), StoreOptions::default()).unwrap();
        let config = parse(ONE).unwrap();
        let (cell, _plans) = Cell::new(&config, store.handle(), Arc::new(Metrics::new())).unwrap();
        // The station was in use an hour ago; the gateway's last mark of life was 10 s later.
        let was = Timestamp::now().minus(Duration::from_secs(3600));
        for (name, value) in [
            (states::STATE_POINT, Value::Text("in use".into())),
            (CODE_POINT, Value::Number(1100.0)),
            (states::REASON_POINT, Value::Text(String::new())),
        ] {
            cell.store().sample(Sample {
                point: PointId::parse(&format!("jbc1.{name}")).unwrap(),
                t: was,
                value: Some(value),
                quality: Quality::Good,
            });
        }
        cell.store().flush().await.unwrap();
        let alive = was.plus(Duration::from_secs(10));
        write_setting(dir.path(), ALIVE_SETTING, alive.0).unwrap();

        let path = dir.path().to_owned();
        let closing = Arc::clone(&cell);
        tokio::task::spawn_blocking(move || close_gap(&closing, &path))
            .await
            .unwrap();
        cell.store().flush().await.unwrap();

        let device = crate::point::DeviceId::new("jbc1").unwrap();
        let now = Timestamp::now();
        let report = report::states(cell.store(), &device, was, now, now).unwrap();
        let seen: Vec<(&str, Option<&str>)> = report
            .intervals
            .iter()
            .map(|i| (i.state.as_str(), i.reason.as_deref()))
            .collect();
        assert_eq!(
            seen,
            [("in use", None), ("unknown", Some(states::NO_DATA))],
            "{report:?}"
        );
        assert_eq!(report.intervals[0].end, Timestamp(alive.0 + 1));
        // A second start finds the gap already closed and adds nothing.
        let path = dir.path().to_owned();
        let again = Arc::clone(&cell);
        tokio::task::spawn_blocking(move || close_gap(&again, &path))
            .await
            .unwrap();
        cell.store().flush().await.unwrap();
        let report = report::states(cell.store(), &device, was, now, now).unwrap();
        assert_eq!(report.intervals.len(), 2);
    }
}
