use super::*;
use crate::driver::ErrorKind;
use crate::driver::machine::StatePoints;
use crate::testing::CheckThenWrite;
use crate::testing::reading as value;
use jbc::device::{Station, StationConfig};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use wire::device::SharedModel;

fn config(address: Option<i64>) -> DriverConfig {
    DriverConfig {
        states: Default::default(),
        id: DeviceId::new("jbc1").unwrap(),
        protocol: super::KIND,
        address,
        timeout: Some(Duration::from_millis(200)),
        retries: Some(1),
        endpoint: None,
        settings: Default::default(),
    }
}

/// A driver attached to a station model over an in-memory line.
fn rig(station: StationConfig, address: Option<i64>) -> (JbcDriver, SharedModel<Station>) {
    let model = SharedModel::new(Station::new(station));
    let (a, b) = tokio::io::duplex(1024);
    tokio::spawn(link::serve::serve_stream(b, model.line(), None));
    let mut driver = JbcDriver::new(&config(address)).unwrap();
    driver.attach(SharedLine::new(link::Line::from_stream(a, "test", None)));
    (driver, model)
}

/// A station whose answers to one code can be damaged past the block check: bit
/// `mask` flipped in two characters of the data field (`at`, counted from its first),
/// which leaves the XOR unchanged.
struct Damaging {
    station: wire::device::ModelLine<Station>,
    code: [u8; 3],
    mask: u8,
    at: [usize; 2],
    damage: Arc<AtomicUsize>,
    requests: Arc<AtomicUsize>,
}

impl wire::Device for Damaging {
    fn receive(&mut self, bytes: &[u8], now: std::time::Instant) -> Vec<wire::Transmit> {
        self.requests.fetch_add(1, Ordering::SeqCst);
        let asks = bytes.windows(3).any(|w| w == self.code);
        let mut replies = self.station.receive(bytes, now);
        if asks && self.damage.load(Ordering::SeqCst) > 0 {
            self.damage.fetch_sub(1, Ordering::SeqCst);
            for reply in &mut replies {
                // ... data(5) ETX BCC
                let data = reply.bytes.len() - 7;
                for at in self.at {
                    reply.bytes[data + at] ^= self.mask;
                }
            }
        }
        replies
    }
}

struct DamageRig {
    driver: JbcDriver,
    model: SharedModel<Station>,
    damage: Arc<AtomicUsize>,
    requests: Arc<AtomicUsize>,
}

fn damaging_rig(code: Code, mask: u8, at: [usize; 2]) -> DamageRig {
    let model = SharedModel::new(Station::new(StationConfig::default()));
    let (damage, requests) = (Arc::new(AtomicUsize::new(0)), Arc::new(AtomicUsize::new(0)));
    let device = Damaging {
        station: model.line(),
        code: *code.raw().as_bytes(),
        mask,
        at,
        damage: Arc::clone(&damage),
        requests: Arc::clone(&requests),
    };
    let (a, b) = tokio::io::duplex(1024);
    tokio::spawn(link::serve::serve_stream(b, device, None));
    let mut driver = JbcDriver::new(&config(Some(1))).unwrap();
    driver.attach(SharedLine::new(link::Line::from_stream(a, "test", None)));
    DamageRig {
        driver,
        model,
        damage,
        requests,
    }
}

/// Another master sets `code` on the station, over a line of its own.
async fn another_master_writes(model: &SharedModel<Station>, code: Code, value: i32) {
    let (a, b) = tokio::io::duplex(1024);
    tokio::spawn(link::serve::serve_stream(b, model.line(), None));
    let mut client = Client::new(
        SharedLine::new(link::Line::from_stream(a, "other", None)),
        ClientConfig::default(),
    );
    client.write(code, value).await.unwrap();
}

#[tokio::test(start_paused = true)]
async fn a_set_point_damaged_past_the_block_check_is_not_recorded() {
    let set_point = Code::SelectAirTemp(PORT);
    let mut rig = damaging_rig(set_point, 0x01, [2, 3]);
    let first = rig.driver.poll(LIVE).await.unwrap();
    assert_eq!(
        value(&first, "air_temperature_setpoint"),
        Ok(Value::Number(350.0))
    );
    // 00350 arrives as 00240: plausible, and its block check still holds.
    rig.damage.store(1, Ordering::SeqCst);
    let damaged = rig.driver.poll(LIVE).await.unwrap();
    assert!(
        damaged
            .iter()
            .all(|r| r.point.name() != "air_temperature_setpoint"),
        "the damaged set point is not recorded: {damaged:?}"
    );
    let after = rig.driver.poll(LIVE).await.unwrap();
    assert_eq!(
        value(&after, "air_temperature_setpoint"),
        Ok(Value::Number(350.0))
    );
}

#[tokio::test(start_paused = true)]
async fn a_damaged_value_outside_what_the_station_can_show_is_bad() {
    let adjust = Code::AdjustTemp(PORT, Tool::Jt);
    let mut rig = damaging_rig(adjust, 0x08, [0, 2]);
    // 00000 arrives as 80800, the soak's find.
    rig.damage.store(1, Ordering::SeqCst);
    let readings = rig.driver.poll(SETTINGS).await.unwrap();
    let error = value(&readings, "adjust_jt").unwrap_err();
    assert_eq!(error.kind, ErrorKind::Decode);
    assert!(error.message.contains("80800"), "{error}");
    assert!(error.message.contains("damaged"), "{error}");
}

#[tokio::test(start_paused = true)]
async fn a_real_change_is_recorded_after_one_confirming_read_and_a_steady_station_costs_none() {
    let set_point = Code::SelectAirTemp(PORT);
    let mut rig = damaging_rig(set_point, 0x01, [2, 3]);
    rig.driver.poll(LIVE).await.unwrap();
    let codes = {
        let mut codes: Vec<Code> = POINTS
            .iter()
            .filter(|d| d.group == LIVE)
            .map(|d| d.code)
            .collect();
        codes.dedup();
        codes.len()
    };
    let before = rig.requests.load(Ordering::SeqCst);
    for _ in 0..5 {
        rig.driver.poll(LIVE).await.unwrap();
    }
    assert_eq!(rig.requests.load(Ordering::SeqCst) - before, 5 * codes);
    another_master_writes(&rig.model, set_point, 300).await;
    let before = rig.requests.load(Ordering::SeqCst);
    let changed = rig.driver.poll(LIVE).await.unwrap();
    assert_eq!(
        value(&changed, "air_temperature_setpoint"),
        Ok(Value::Number(300.0))
    );
    assert_eq!(rig.requests.load(Ordering::SeqCst) - before, codes + 1);
}

#[test]
fn every_station_shares_one_description_per_point_and_has_its_own_ids() {
    let one = JbcDriver::new(&config(Some(1))).unwrap().points();
    let two = JbcDriver::new(&DriverConfig {
        id: DeviceId::new("jbc2").unwrap(),
        ..config(Some(2))
    })
    .unwrap()
    .points();
    assert_eq!(one.len(), POINTS.len() + StatePoints::COUNT);
    for (a, b) in one.iter().zip(&two) {
        assert!(Arc::ptr_eq(&a.description, &b.description), "{}", a.id);
        assert_eq!(a.id.name(), b.id.name());
        assert_eq!((a.id.device(), b.id.device()), ("jbc1", "jbc2"));
    }
}

#[test]
fn every_point_has_a_valid_id_and_belongs_to_a_known_group() {
    let driver = JbcDriver::new(&config(Some(1))).unwrap();
    let groups: Vec<String> = driver.groups().into_iter().map(|g| g.name).collect();
    let points = driver.points();
    assert_eq!(points.len(), POINTS.len() + StatePoints::COUNT);
    for p in &points {
        assert_eq!(p.id.device(), "jbc1");
        assert!(groups.contains(&p.group.to_string()), "{}", p.id);
    }
    let ids: std::collections::HashSet<_> = points.iter().map(|p| &p.id).collect();
    assert_eq!(ids.len(), points.len(), "point ids are unique");
}

#[test]
fn the_group_plans_read_every_point_once_with_its_own_code_in_points_order() {
    let mut seen = Vec::new();
    for plan in PLANS.iter() {
        let mut last = None;
        for &(index, read) in &plan.points {
            let def = &POINTS[index];
            assert_eq!(def.group, plan.group, "{}", def.name);
            assert_eq!(plan.reads[read].code, def.code, "{}", def.name);
            assert!(
                plan.reads[read].defs.iter().any(|d| d.name == def.name),
                "{}",
                def.name
            );
            assert!(last < Some(index), "{} out of order", def.name);
            last = Some(index);
            seen.push(index);
        }
    }
    seen.sort_unstable();
    assert_eq!(seen, (0..POINTS.len()).collect::<Vec<_>>());
}

#[test]
fn station_addresses_outside_0_to_99_are_refused() {
    assert!(check_address(Some(0)).is_ok());
    assert!(check_address(Some(99)).is_ok());
    assert!(check_address(None).is_ok());
    let err = check_address(Some(100)).unwrap_err();
    assert!(err.contains("0 to 99"), "{err}");
    assert!(JbcDriver::new(&config(Some(-1))).is_err());
}

#[tokio::test(start_paused = true)]
async fn a_live_poll_reads_temperatures_status_digits_and_errors() {
    let (mut driver, model) = rig(StationConfig::default(), Some(1));
    model.lock().set_tool_error(ToolError::HeaterMalfunction);
    let readings = driver.poll(LIVE).await.unwrap();
    assert_eq!(
        readings.len(),
        POINTS.iter().filter(|d| d.group == LIVE).count() + StatePoints::COUNT
    );
    assert!(matches!(value(&readings, "air_temperature"), Ok(Value::Number(t)) if t < 100.0));
    assert_eq!(value(&readings, "tool_on"), Ok(Value::Number(0.0)));
    assert_eq!(value(&readings, "tool_error"), Ok(Value::Number(3.0)));
    assert_eq!(value(&readings, "connected_tool"), Ok(Value::Number(1.0)));
    assert_eq!(
        value(&readings, "machine_state"),
        Ok(Value::Text("tool error".into()))
    );
    assert_eq!(
        value(&readings, "machine_state_reason"),
        Ok(Value::Text("Heater malfunction: replace heater".into()))
    );
    let info = driver.poll(INFO).await.unwrap();
    assert_eq!(value(&info, "model"), Ok(Value::Text("JTSE".into())));
}

#[tokio::test(start_paused = true)]
async fn group_reads_says_what_each_group_reads_and_gives() {
    let (mut driver, _model) = rig(StationConfig::default(), Some(1));
    let groups = driver.groups();
    let reads = group_reads();
    assert_eq!(
        reads
            .iter()
            .map(|r| (r.group, r.period))
            .collect::<Vec<_>>(),
        groups
            .iter()
            .map(|g| (g.name.as_str(), g.period))
            .collect::<Vec<_>>()
    );
    for read in &reads {
        let readings = driver.poll(read.group).await.unwrap();
        let states = if read.group == LIVE {
            StatePoints::COUNT
        } else {
            0
        };
        assert_eq!(readings.len(), read.points + states, "{}", read.group);
        for (i, code) in read.codes.iter().enumerate() {
            assert!(
                !read.codes[..i].contains(code),
                "{}: {code:?} twice",
                read.group
            );
        }
        // Every code named is one a point of the group is read with, and back.
        for point in POINTS.iter().filter(|d| d.group == read.group) {
            assert!(read.codes.contains(&point.code), "{}", point.name);
        }
        assert!(
            read.codes
                .iter()
                .all(|c| POINTS.iter().any(|d| d.group == read.group && d.code == *c))
        );
        // A code's points are neighbours in the group (what a poll that fails midway
        // hands over relies on): the codes in point order change once per code.
        let mut in_order: Vec<Code> = POINTS
            .iter()
            .filter(|d| d.group == read.group)
            .map(|d| d.code)
            .collect();
        in_order.dedup();
        assert_eq!(in_order, read.codes, "{}", read.group);
    }
}

#[tokio::test(start_paused = true)]
async fn the_form_without_addresses_works_too() {
    let station = StationConfig {
        address: None,
        ..StationConfig::default()
    };
    let (mut driver, _model) = rig(station, None);
    let readings = driver.poll(SETTINGS).await.unwrap();
    assert!(readings.iter().all(|r| r.value.is_ok()), "{readings:?}");
}

/// `driver`'s point `name`.
fn spec(driver: &JbcDriver, name: &str) -> PointSpec {
    driver
        .points()
        .into_iter()
        .find(|p| p.id.name() == name)
        .expect("a point of the station")
}

#[tokio::test(start_paused = true)]
async fn turning_the_tool_on_heats_the_air_toward_the_set_point() {
    let (mut driver, model) = rig(StationConfig::default(), Some(1));
    driver
        .check_then_write(
            &spec(&driver, "air_temperature_setpoint"),
            &Value::Number(300.0),
        )
        .await
        .unwrap();
    driver
        .check_then_write(&spec(&driver, "tool_on"), &Value::Text("on".into()))
        .await
        .unwrap();
    assert!(model.lock().port_status().tool_on);
    tokio::time::sleep(Duration::from_secs(30)).await;
    let readings = driver.poll(LIVE).await.unwrap();
    assert_eq!(value(&readings, "tool_on"), Ok(Value::Number(1.0)));
    assert_eq!(
        value(&readings, "air_temperature_setpoint"),
        Ok(Value::Number(300.0))
    );
    assert!(
        matches!(value(&readings, "air_temperature"), Ok(Value::Number(t)) if t > 250.0),
        "{readings:?}"
    );
}

#[tokio::test(start_paused = true)]
async fn a_set_point_outside_the_stations_own_limits_never_reaches_the_wire() {
    let (mut driver, model) = rig(StationConfig::default(), Some(1));
    driver
        .check_then_write(&spec(&driver, "max_air_temperature"), &Value::Number(300.0))
        .await
        .unwrap();
    driver.poll(SETTINGS).await.unwrap();
    let before = model.lock().settings().air_temp;
    let err = driver
        .check_then_write(
            &spec(&driver, "air_temperature_setpoint"),
            &Value::Number(400.0),
        )
        .await
        .unwrap_err();
    assert!(
        matches!(err, WriteError::Invalid(ValueError::OutOfRange { max, .. }) if max == 300.0),
        "{err}"
    );
    assert!(err.to_string().contains("MIT/MAT"), "{err}");
    assert_eq!(model.lock().settings().air_temp, before);
    // The JTSE's own range is checked even before any limits were read.
    let err = driver
        .check_then_write(&spec(&driver, "air_flow_setpoint"), &Value::Number(5.0))
        .await
        .unwrap_err();
    assert!(matches!(err, WriteError::Invalid(_)), "{err}");
}

#[tokio::test(start_paused = true)]
async fn a_station_polled_in_every_group_confirms_its_codes_in_the_list_made_for_them() {
    let (mut driver, _model) = rig(StationConfig::default(), Some(1));
    let made = driver.confirmed.0.capacity();
    for group in driver.groups() {
        driver.poll(&group.name).await.unwrap();
    }
    let setpoint = spec(&driver, "air_temperature_setpoint");
    driver
        .check_then_write(&setpoint, &Value::Number(300.0))
        .await
        .unwrap();
    assert_eq!(driver.confirmed.0.len(), *CONFIRMABLE_CODES);
    assert_eq!(driver.confirmed.0.capacity(), made, "never grown");
}

#[tokio::test(start_paused = true)]
async fn a_silent_station_is_a_timeout_and_a_refusal_marks_only_its_point() {
    let (mut driver, model) = rig(StationConfig::default(), Some(1));
    model.lock().set_robot_mode(false);
    // Not in robot mode: every read gets NAK 5, point by point.
    let readings = driver.poll(INFO).await.unwrap();
    assert!(
        readings
            .iter()
            .all(|r| matches!(&r.value, Err(e) if e.kind == ErrorKind::Refused))
    );
    // A station at another address never answers.
    let (mut driver, _model) = rig(StationConfig::default(), Some(7));
    let err = driver.poll(LIVE).await.unwrap_err();
    assert_eq!(err.kind, ErrorKind::Timeout);
    assert!(err.message.contains("07"), "{err}");
}

#[tokio::test]
async fn polling_before_the_line_is_attached_says_so() {
    let mut driver = JbcDriver::new(&config(Some(1))).unwrap();
    let err = driver.poll(LIVE).await.unwrap_err();
    assert_eq!(err.kind, ErrorKind::Disconnected);
}
