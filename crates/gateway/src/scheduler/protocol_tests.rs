//! The scheduler with the Thermosald and CROSS drivers, against their twins on in-memory
//! lines, with tokio's clock paused: three regulators share one line, a CROSS has its own,
//! and what they do becomes values and events.

use std::sync::Arc;
use std::time::Duration;

use jbus::cross::Source;
use jbus::cross::device::CrossTwin;
use link::{Endpoint, Line};
use thermosald::Address;
use thermosald::device::RegulatorBus;
use thermosald::diagnostic::Fault;
use thermosald::tables::Table;
use tokio::sync::watch;
use wire::device::SharedModel;

use super::*;
use crate::cell::{Cell, DeviceStatus};
use crate::config::{CellConfig, DeviceConfig, LineConfig};
use crate::driver::{DriverConfig, Kind};
use crate::event::EventKind;
use crate::metrics::Metrics;
use crate::point::{DeviceId, ValueError};
use crate::store::{EventFilter, Store, StoreOptions};
use crate::testing::{point, value};

struct Rig {
    cell: Arc<Cell>,
    regulators: SharedModel<RegulatorBus>,
    cross: SharedModel<CrossTwin>,
    _shutdown: watch::Sender<bool>,
    _store: Store,
    _dir: tempfile::TempDir,
}

fn device(id: &str, protocol: Kind, address: i64) -> DeviceConfig {
    let driver = DriverConfig {
        address: Some(address),
        ..DriverConfig::new(DeviceId::new(id).unwrap(), protocol)
    };
    DeviceConfig::new(driver, format!("Device {id}"))
}

fn opener<M>(model: SharedModel<M>, settings: link::SerialSettings) -> Opener
where
    M: wire::device::Model + Send + 'static,
    wire::device::ModelLine<M>: wire::device::Device + Send + 'static,
{
    Arc::new(move || {
        let (a, b) = tokio::io::duplex(4096);
        tokio::spawn(link::serve::serve_stream(b, model.line(), None));
        Box::pin(async move { Ok(Line::from_stream(a, "memory", Some(settings))) })
    })
}

/// Like [`opener`], with every line's answers damaged at random by a
/// [`wire::device::FaultInjector`].
fn faulty_opener<M>(
    model: SharedModel<M>,
    settings: link::SerialSettings,
    seed: u64,
    rate: f64,
) -> Opener
where
    M: wire::device::Model + Send + 'static,
    wire::device::ModelLine<M>: wire::device::Device + Send + 'static,
{
    Arc::new(move || {
        let (a, b) = tokio::io::duplex(4096);
        let injector = wire::device::FaultInjector::new(model.line(), seed, rate)
            .expect("the tests give a rate between 0 and 1");
        tokio::spawn(link::serve::serve_stream(b, injector, None));
        Box::pin(async move { Ok(Line::from_stream(a, "memory", Some(settings))) })
    })
}

fn rig() -> Rig {
    rig_with(None)
}

/// The rig, with the regulators' answers damaged at random (`(seed, rate)`, as
/// `cellbus sim thermosald --fault-rate`) when asked.
fn rig_with(regulator_faults: Option<(u64, f64)>) -> Rig {
    let dir = tempfile::tempdir().unwrap();
    let store = Store::open(dir.path(), StoreOptions::default()).unwrap();
    let addresses: Vec<Address> = (0..3).map(|a| Address::new(a).unwrap()).collect();
    let regulators = SharedModel::new(
        RegulatorBus::new(&addresses, tokio::time::Instant::now().into_std()).unwrap(),
    );
    let cross = SharedModel::new(CrossTwin::new(jbus::rtu::UnitId::jbus(1).unwrap(), 3));
    let sealing = crate::driver::thermosald::DEFAULT_SERIAL;
    let jbus_line = crate::driver::cross::DEFAULT_SERIAL;
    let config = CellConfig {
        lines: vec![
            LineConfig {
                reopen_after_timeouts: crate::config::DEFAULT_REOPEN_AFTER_TIMEOUTS,
                name: "sealers".into(),
                endpoint: Endpoint::parse("tcp://127.0.0.1:9", sealing).unwrap(),
                devices: (0..3)
                    .map(|a| device(&format!("sealer{a}"), crate::driver::thermosald::KIND, a))
                    .collect(),
            },
            LineConfig {
                reopen_after_timeouts: crate::config::DEFAULT_REOPEN_AFTER_TIMEOUTS,
                name: "mains".into(),
                endpoint: Endpoint::parse("tcp://127.0.0.1:9", jbus_line).unwrap(),
                devices: vec![device("cross1", crate::driver::cross::KIND, 1)],
            },
        ],
        ..CellConfig::default()
    };
    let (cell, tasks) = crate::scheduler::build_with_openers(
        &config,
        store.handle(),
        Arc::new(Metrics::new()),
        |line| match line.name.as_str() {
            "sealers" => match regulator_faults {
                Some((seed, rate)) => faulty_opener(regulators.clone(), sealing, seed, rate),
                None => opener(regulators.clone(), sealing),
            },
            _ => opener(cross.clone(), jbus_line),
        },
    )
    .unwrap();
    let (shutdown, stop) = watch::channel(false);
    tokio::spawn(crate::alarm::keeper::run(Arc::clone(&cell), stop.clone()));
    for task in tasks {
        tokio::spawn(task.run(stop.clone()));
    }
    Rig {
        cell,
        regulators,
        cross,
        _shutdown: shutdown,
        _store: store,
        _dir: dir,
    }
}

async fn events(cell: &Cell, device: &str) -> Vec<(String, String)> {
    cell.store().flush().await.unwrap();
    cell.store()
        .events(&EventFilter {
            device: Some(device.into()),
            limit: 50,
            ..EventFilter::default()
        })
        .unwrap()
        .into_iter()
        .filter(|e| e.kind != "device_up")
        .map(|e| (e.kind, e.message))
        .collect()
}

#[tokio::test(start_paused = true)]
async fn three_regulators_on_one_line_and_a_cross_are_all_read_with_good_values() {
    let rig = rig();
    tokio::time::sleep(Duration::from_secs(20)).await;
    for entry in rig.cell.device_entries() {
        let state = entry.read();
        assert_eq!(state.status, DeviceStatus::Up, "{}", entry.id);
        for (spec, p) in entry.points.iter().zip(&state.points) {
            assert_eq!(p.quality, Some(Quality::Good), "{} {p:?}", spec.id);
            assert!(p.value.is_some(), "{}", spec.id);
        }
    }
    // Each regulator answers for itself.
    for a in 0..3 {
        assert_eq!(
            value(&rig.cell, &format!("sealer{a}.address")),
            Some(Value::Number(f64::from(a)))
        );
    }
}

#[tokio::test(start_paused = true)]
async fn a_regulator_fault_appearing_and_clearing_is_recorded_as_events() {
    let rig = rig();
    tokio::time::sleep(Duration::from_secs(5)).await;
    let now = || tokio::time::Instant::now().into_std();
    let address = Address::new(1).unwrap();
    rig.regulators
        .lock()
        .regulator_mut(address)
        .unwrap()
        .provoke(Fault::OpenBand, now());
    tokio::time::sleep(Duration::from_secs(5)).await;
    assert_eq!(value(&rig.cell, "sealer1.fault"), Some(Value::Number(1.0)));
    {
        let mut line = rig.regulators.lock();
        let regulator = line.regulator_mut(address).unwrap();
        regulator.remove_cause(Fault::OpenBand, now());
        regulator.power_cycle(now());
    }
    tokio::time::sleep(Duration::from_secs(5)).await;
    assert_eq!(
        events(&rig.cell, "sealer1").await,
        vec![
            (
                "alarm_cleared".to_owned(),
                "Device sealer1: Fault/warning number back to ready".to_owned()
            ),
            (
                "alarm_raised".to_owned(),
                "Device sealer1: Fault/warning number is sealing band open".to_owned()
            ),
        ]
    );
    assert!(events(&rig.cell, "sealer0").await.is_empty());
}

#[tokio::test(start_paused = true)]
async fn a_cross_transfer_and_its_alarms_are_recorded_as_events() {
    let rig = rig();
    tokio::time::sleep(Duration::from_secs(3)).await;
    rig.cross.lock().fail_source(Source::S1);
    tokio::time::sleep(Duration::from_secs(3)).await;
    assert_eq!(
        value(&rig.cell, "cross1.load_feed"),
        Some(Value::Number(2.0))
    );
    rig.cross.lock().restore_source(Source::S1);
    tokio::time::sleep(Duration::from_secs(3)).await;
    let events = events(&rig.cell, "cross1").await;
    let transfers: Vec<&str> = events
        .iter()
        .filter(|(kind, _)| kind == EventKind::StateChanged.as_str())
        .map(|(_, m)| m.as_str())
        .collect();
    assert_eq!(transfers.len(), 2, "{events:?}");
    assert!(
        transfers[1]
            .starts_with("Device cross1: load transferred from source 1 (S1) to source 2 (S2)"),
        "{transfers:?}"
    );
    assert!(
        transfers[0].contains("from source 2 (S2) to source 1 (S1)"),
        "{transfers:?}"
    );
    assert!(
        events.iter().any(|(kind, m)| kind == "alarm_raised"
            && m.starts_with("Device cross1: Source 1 alarms is S1 failure")),
        "{events:?}"
    );
    assert!(
        events.iter().any(|(kind, m)| kind == "alarm_cleared"
            && m == "Device cross1: Source 1 alarms back to none"),
        "{events:?}"
    );
}

#[tokio::test(start_paused = true)]
async fn writes_outside_the_range_or_the_regulators_limit_are_refused_before_the_wire() {
    let rig = rig();
    tokio::time::sleep(Duration::from_secs(12)).await;
    let settings = || {
        rig.regulators.lock().regulators_mut()[0]
            .table(Table::Settings, tokio::time::Instant::now().into_std())
    };
    let before = settings();
    let sealing = point("sealer0.sealing_temperature");
    let max = value(&rig.cell, "sealer0.max_working_temperature")
        .and_then(|v| v.as_number())
        .unwrap();
    // Each write: point, value and how it is refused.
    type Refusal = fn(&WriteError) -> bool;
    let refusals: [(&str, f64, Refusal); 4] = [
        ("sealer0.sealing_temperature", 1200.0, |e| {
            matches!(e, WriteError::Invalid(ValueError::OutOfRange { .. }))
        }),
        ("sealer0.sealing_temperature", max + 1.0, |e| {
            e.to_string().contains("maximum working temperature")
        }),
        ("sealer0.kint_gain", 1.25, |e| {
            matches!(e, WriteError::Invalid(ValueError::NotAStep { .. }))
        }),
        ("cross1.load_power", 1.0, |e| {
            matches!(e, WriteError::Invalid(ValueError::ReadOnly { .. }))
        }),
    ];
    for (name, number, refusal) in refusals {
        let err = rig
            .cell
            .write(&point(name), &Value::Number(number))
            .await
            .unwrap_err();
        assert!(refusal(&err), "{name} = {number}: {err}");
    }
    assert_eq!(settings(), before, "nothing reached the regulator");

    // A value in range goes out and is read back at once.
    rig.cell
        .write(&sealing, &Value::Number(max - 10.0))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_secs(2)).await;
    assert_eq!(
        value(&rig.cell, "sealer0.sealing_temperature"),
        Some(Value::Number(max - 10.0))
    );
}

/// A Panasonic twin on its two loopback ports, polled by a line task that opens nothing
/// itself; returns the cell and the running twin.
async fn panasonic_rig() -> (
    Arc<Cell>,
    tokio::sync::broadcast::Receiver<crate::cell::LiveMessage>,
    panasonic::server::RunningTwin,
    watch::Sender<bool>,
    Store,
    tempfile::TempDir,
) {
    let dir = tempfile::tempdir().unwrap();
    let store = Store::open(dir.path(), StoreOptions::default()).unwrap();
    let any: std::net::SocketAddr = "127.0.0.1:0".parse().unwrap();
    let machine = panasonic::Machine::new(panasonic::MachineConfig::default()).unwrap();
    let twin = panasonic::server::TwinServer::bind(any, any, machine)
        .await
        .unwrap()
        .spawn()
        .unwrap();
    let text = format!(
        "[[line]]\nname = \"placement\"\nendpoint = \"tcp://127.0.0.1:{}\"\n[[line.device]]\nid = \"placer1\"\nname = \"Placer\"\nprotocol = \"panasonic\"\nevent_port = {}\n",
        twin.command_addr().port(),
        twin.event_addr().port()
    );
    let config = crate::plugins::parse_config(&text, std::path::Path::new("cell.toml")).unwrap();
    let (cell, tasks) =
        crate::scheduler::build(&config, store.handle(), Arc::new(Metrics::new())).unwrap();
    let live = cell.subscribe();
    let (shutdown, stop) = watch::channel(false);
    tokio::spawn(crate::alarm::keeper::run(Arc::clone(&cell), stop.clone()));
    for task in tasks {
        tokio::spawn(task.run(stop.clone()));
    }
    (cell, live, twin, shutdown, store, dir)
}

/// Waits (generously, on the live stream: no sleeps) for an event `matches` accepts.
async fn wait_for_event(
    live: &mut tokio::sync::broadcast::Receiver<crate::cell::LiveMessage>,
    matches: impl Fn(&crate::event::Event) -> bool,
) -> crate::event::Event {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    loop {
        let message = tokio::time::timeout_at(deadline, live.recv())
            .await
            .expect("the event within 30 s")
            .expect("the cell runs");
        if let crate::cell::LiveMessage::Event(event) = message
            && matches(&event)
        {
            return *event;
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_panasonic_machines_r_messages_and_state_changes_are_recorded_as_events() {
    let (cell, mut live, twin, _shutdown, _store, _dir) = panasonic_rig().await;
    // The first status read: the driver is connected to both ports.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    loop {
        let message = tokio::time::timeout_at(deadline, live.recv())
            .await
            .expect("a first status within 30 s")
            .unwrap();
        if let crate::cell::LiveMessage::Value(view) = message
            && view.id == point("placer1.state")
        {
            break;
        }
    }
    twin.control()
        .operator_start(Some(panasonic::StopMode::Continuous))
        .unwrap();
    // The state change (seen by a status poll) and the R1ST (drained after that poll) may
    // be recorded in either order.
    let mut seen = Vec::new();
    while !(seen
        .iter()
        .any(|e: &crate::event::Event| e.kind == EventKind::StateChanged)
        && seen
            .iter()
            .any(|e| e.kind == EventKind::DeviceEvent && e.message.contains("R1ST")))
    {
        seen.push(
            wait_for_event(&mut live, |e| {
                matches!(e.kind, EventKind::StateChanged | EventKind::DeviceEvent)
            })
            .await,
        );
    }
    let started = seen
        .iter()
        .find(|e| e.kind == EventKind::DeviceEvent && e.message.contains("R1ST"))
        .unwrap();
    assert!(
        started.message.starts_with("Placer: R message R1ST"),
        "{}",
        started.message
    );
    let running = seen
        .iter()
        .find(|e| e.kind == EventKind::StateChanged)
        .unwrap();
    assert_eq!(running.message, "Placer: machine went from ready to run");
    assert_eq!(running.point, Some(point("placer1.state")));
    twin.control().force_error(3).unwrap();
    let alarm = wait_for_event(&mut live, |e| e.kind == EventKind::AlarmRaised).await;
    assert_eq!(alarm.message, "Placer: Run state is error stop");
    let entry = cell.device_entry("placer1").unwrap();
    assert_eq!(entry.read().status, DeviceStatus::Up);
    assert_eq!(value(&cell, "placer1.state"), Some(Value::Number(2.0)));
}

#[tokio::test(start_paused = true)]
async fn a_line_that_damages_half_the_answers_raises_no_false_alarm_and_stores_no_wrong_setting() {
    let rig = rig_with(Some((20261, 0.5)));
    tokio::time::sleep(Duration::from_secs(600)).await;
    let mut checked = 0;
    for a in 0..3u8 {
        let device = format!("sealer{a}");
        let alarms: Vec<_> = events(&rig.cell, &device)
            .await
            .into_iter()
            // A regulator that gave no valid answer in three attempts is not answering (an
            // alarm of its own); none may get a fault it does not have.
            .filter(|(kind, message)| kind == "alarm_raised" && !message.contains("not answering"))
            .collect();
        assert!(alarms.is_empty(), "{device}: {alarms:?}");
        let entry = rig.cell.device_entry(&device).unwrap();
        for spec in entry.points.iter().filter(|p| p.group != "live") {
            let table: Table = spec.group.parse().unwrap();
            let item = Table::find(table, &spec.name).unwrap();
            let raw = rig.regulators.lock().regulators_mut()[usize::from(a)]
                .table(table, tokio::time::Instant::now().into_std())[usize::from(item.index())];
            let truth = match spec.kind {
                crate::point::PointKind::Numeric => item.from_raw(raw),
                _ => f64::from(raw.get()),
            };
            let history = rig
                .cell
                .store()
                .history(
                    &spec.id,
                    crate::time::Timestamp::now().minus(Duration::from_secs(86_400)),
                    crate::time::Timestamp::now().plus(Duration::from_secs(86_400)),
                    None,
                )
                .unwrap();
            let crate::store::Series::Samples(samples) = history.series else {
                panic!("raw samples asked");
            };
            for sample in samples.iter().filter(|s| s.quality == Quality::Good) {
                checked += 1;
                assert_eq!(sample.value, Some(Value::Number(truth)), "{}", spec.id);
            }
        }
    }
    assert!(checked > 100, "{checked}");
}
