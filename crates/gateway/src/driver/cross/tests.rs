use std::collections::HashSet;

use super::*;
use crate::driver::machine::StatePoints;
use crate::point::DeviceId;
use crate::testing::reading as value;
use jbus::cross::device::CrossTwin;
use wire::device::SharedModel;

fn config(unit: i64) -> DriverConfig {
    DriverConfig {
        states: Default::default(),
        id: DeviceId::new("cross1").unwrap(),
        protocol: super::KIND,
        address: Some(unit),
        timeout: Some(Duration::from_millis(200)),
        retries: Some(1),
        endpoint: None,
        settings: Default::default(),
    }
}

fn rig(unit: i64) -> (CrossDriver, SharedModel<CrossTwin>) {
    let twin = SharedModel::new(CrossTwin::new(UnitId::jbus(1).unwrap(), 7));
    let (a, b) = tokio::io::duplex(1024);
    tokio::spawn(link::serve::serve_stream(b, twin.line(), None));
    let mut driver = CrossDriver::new(&config(unit)).unwrap();
    driver.attach(SharedLine::new(link::Line::from_stream(
        a,
        "cross",
        Some(DEFAULT_SERIAL),
    )));
    (driver, twin)
}

fn number(readings: &[Reading], name: &str) -> f64 {
    value(readings, name)
        .unwrap()
        .as_number()
        .unwrap_or_else(|| panic!("{name} is not a number"))
}

#[test]
fn every_point_has_a_unique_id_and_a_known_group_and_none_is_writable() {
    let driver = CrossDriver::new(&config(1)).unwrap();
    let points = driver.points();
    let ids: HashSet<_> = points.iter().map(|p| &p.id).collect();
    assert_eq!(ids.len(), points.len());
    assert!(points.iter().all(|p| p.group == LIVE || p.group == RATINGS));
    assert!(points.iter().all(|p| p.writable.is_none()));
    let feed = points.iter().find(|p| p.id.name() == "load_feed").unwrap();
    assert_eq!(
        feed.label(&Value::Number(2.0)),
        Some("supplied by source 2 (S2) through static switch S2-SW")
    );
}

#[test]
fn unit_numbers_outside_1_to_255_are_refused() {
    assert!(check_address(Some(1)).is_ok());
    assert!(check_address(Some(255)).is_ok());
    assert!(check_address(Some(0)).unwrap_err().contains("1 to 255"));
    assert!(check_address(Some(256)).is_err());
    assert!(check_address(None).is_err());
}

#[tokio::test(start_paused = true)]
async fn a_healthy_switch_feeds_the_load_from_source_1_with_measures_in_their_units() {
    let (mut driver, _twin) = rig(1);
    let live = driver.poll(LIVE).await.unwrap();
    assert_eq!(
        live.len(),
        DEFS.iter().filter(|d| d.group() == LIVE).count() + StatePoints::COUNT
    );
    assert_eq!(value(&live, "load_feed"), Ok(Value::Number(1.0)));
    assert_eq!(
        value(&live, "machine_state"),
        Ok(Value::Text("load on S1".into()))
    );
    assert_eq!(
        value(&live, "machine_state_code"),
        Ok(Value::Number(1100.0))
    );
    assert_eq!(value(&live, "s1_alarms"), Ok(Value::Text("none".into())));
    let v = number(&live, "s1_voltage_u");
    assert!((220.0..240.0).contains(&v), "{v}");
    let f = number(&live, "output_frequency");
    assert!((49.5..50.5).contains(&f), "{f}");
    assert!(number(&live, "load_power") > 0.0);
    let ratings = driver.poll(RATINGS).await.unwrap();
    assert_eq!(number(&ratings, "rated_current"), 100.0);
    assert!(driver.take_events().is_empty());
}

#[tokio::test(start_paused = true)]
async fn a_live_poll_cut_after_the_state_hands_over_the_states_points() {
    let twin = SharedModel::new(CrossTwin::new(UnitId::jbus(1).unwrap(), 7));
    let (a, b) = tokio::io::duplex(1024);
    let device = testkit::Tricky::new(twin.line(), []).silent_after(std::sync::Arc::new(1.into()));
    tokio::spawn(link::serve::serve_stream(b, device, None));
    let mut driver = CrossDriver::new(&config(1)).unwrap();
    driver.attach(SharedLine::new(link::Line::from_stream(
        a,
        "cross",
        Some(DEFAULT_SERIAL),
    )));
    let down = driver.poll(LIVE).await.unwrap_err();
    assert_eq!(down.kind, ErrorKind::Timeout, "{down}");
    let partial = driver.take_partial();
    let state_points = DEFS
        .iter()
        .filter(|d| d.group() == LIVE && !matches!(d.show, Show::Measure(..)))
        .count();
    assert!(state_points > 0);
    assert_eq!(
        partial.len(),
        state_points,
        "the state's points, no measure"
    );
    assert_eq!(value(&partial, "load_feed"), Ok(Value::Number(1.0)));
    assert!(partial.iter().all(|r| r.value.is_ok()));
    assert!(driver.take_partial().is_empty(), "taken once");
}

#[tokio::test(start_paused = true)]
async fn losing_source_1_is_a_transfer_event_and_its_alarms_appear_and_clear() {
    let (mut driver, twin) = rig(1);
    driver.poll(LIVE).await.unwrap();
    twin.lock().fail_source(Source::S1);
    let live = driver.poll(LIVE).await.unwrap();
    assert_eq!(value(&live, "load_feed"), Ok(Value::Number(2.0)));
    let alarms = value(&live, "s1_alarms").unwrap();
    assert!(
        matches!(&alarms, Value::Text(t) if t.contains("S1 failure")),
        "{alarms:?}"
    );
    let spec = driver
        .points()
        .into_iter()
        .find(|p| p.id.name() == "s1_alarms")
        .unwrap();
    assert!(spec.is_alarm(&alarms));
    let events = driver.take_events();
    assert_eq!(events.len(), 1, "{events:?}");
    assert_eq!(events[0].kind, EventKind::StateChanged);
    assert!(
        events[0]
            .message
            .starts_with("load transferred from source 1 (S1) to source 2 (S2)"),
        "{}",
        events[0].message
    );
    let fields = serde_json::Value::Object(events[0].fields.clone());
    assert_eq!(fields["from"], "source 1 (S1)", "{fields}");
    assert_eq!(fields["to"], "source 2 (S2)", "{fields}");
    assert!(
        fields["feed"].is_string() && fields["was"].is_string(),
        "{fields}"
    );
    twin.lock().restore_source(Source::S1);
    let live = driver.poll(LIVE).await.unwrap();
    assert_eq!(value(&live, "s1_alarms"), Ok(Value::Text("none".into())));
    let back = driver.take_events();
    assert!(
        back[0]
            .message
            .contains("from source 2 (S2) to source 1 (S1)"),
        "{back:?}"
    );
}

#[tokio::test(start_paused = true)]
async fn the_transfer_event_is_the_load_change_jbus_cross_detects_as_cellbus_watch_prints_it() {
    let (mut driver, twin) = rig(1);
    let now = || tokio::time::Instant::now().into_std();
    driver.poll(LIVE).await.unwrap();
    let before = Discrete::of(&twin.lock().reading(now()).internal);
    twin.lock().fail_source(Source::S1);
    driver.poll(LIVE).await.unwrap();
    let after = Discrete::of(&twin.lock().reading(now()).internal);
    let changes = after.changes_since(&before);
    let load = changes
        .iter()
        .find(|c| matches!(c, Change::Load { .. }))
        .expect("the load moved");
    let Transfer { from, to } = load.transfer().expect("to the other source");
    // `cellbus cross watch` prints the change as it is shown…
    assert_eq!(load.to_string(), format!("load {}", after.load()));
    // …and the driver records the same transfer as its one event.
    let events = driver.take_events();
    assert_eq!(events.len(), 1, "{events:?}");
    assert!(
        events[0]
            .message
            .starts_with(&format!("load transferred from {from} to {to}: ")),
        "{}",
        events[0].message
    );
}

#[test]
fn a_three_phase_quantity_is_one_point_per_phase_with_its_unit() {
    let driver = CrossDriver::new(&config(1)).unwrap();
    let points = driver.points();
    for (name, title) in [
        ("s1_voltage_u", "S1 voltage U"),
        ("s1_voltage_w", "S1 voltage W"),
        ("output_current_full_scale_v", "Output current full scale V"),
    ] {
        let point = points.iter().find(|p| p.id.name() == name).unwrap();
        assert_eq!(point.name, title);
        assert!(point.unit.is_some(), "{name} has a unit");
    }
    let revision = points
        .iter()
        .find(|p| p.id.name() == "protocol_revision")
        .unwrap();
    assert_eq!(
        (revision.unit.as_deref(), revision.group.as_ref()),
        (None, RATINGS)
    );
}

#[tokio::test(start_paused = true)]
async fn another_unit_number_is_a_timeout_naming_the_unit() {
    let (mut driver, _twin) = rig(9);
    let err = driver.poll(LIVE).await.unwrap_err();
    assert_eq!(err.kind, ErrorKind::Timeout);
    assert!(err.message.contains("unit 9"), "{err}");
}
