use crate::testing::CheckThenWrite;
use std::collections::HashSet;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use super::*;
use crate::driver::machine::StatePoints;
use crate::testing::reading as value;
use thermosald::device::RegulatorBus;
use wire::Transmit;
use wire::device::{Device, FaultInjector, ModelLine, SharedModel};

fn config(id: &str, address: i64) -> DriverConfig {
    DriverConfig {
        states: Default::default(),
        id: DeviceId::new(id).unwrap(),
        protocol: super::KIND,
        address: Some(address),
        timeout: None,
        retries: Some(1),
        endpoint: None,
        settings: Default::default(),
    }
}

fn address(n: u8) -> Address {
    Address::new(n).unwrap()
}

/// Drivers for regulators 0, 1 and 2 on one simulated RS-485 line.
fn rig(addresses: &[u8]) -> (Vec<ThermosaldDriver>, SharedModel<RegulatorBus>) {
    let list: Vec<Address> = addresses.iter().map(|&a| address(a)).collect();
    let twin = RegulatorBus::new(&list, tokio::time::Instant::now().into_std()).unwrap();
    let model = SharedModel::new(twin);
    let (a, b) = tokio::io::duplex(1024);
    tokio::spawn(link::serve::serve_stream(b, model.line(), None));
    let line = SharedLine::new(link::Line::from_stream(a, "rs485", Some(DEFAULT_SERIAL)));
    let drivers = addresses
        .iter()
        .map(|&n| {
            let mut d = ThermosaldDriver::new(&config(&format!("sealer{n}"), n.into())).unwrap();
            d.attach(line.clone());
            d
        })
        .collect();
    (drivers, model)
}

/// The reading of a point, if the poll gave one (a value whose two reads disagreed
/// gives none: the point keeps what it has).
fn recorded(readings: &[Reading], name: &str) -> Option<Result<Value, DeviceError>> {
    readings
        .iter()
        .find(|r| r.point.name() == name)
        .map(|r| r.value.clone())
}

fn spec(driver: &ThermosaldDriver, name: &str) -> PointSpec {
    driver
        .points()
        .into_iter()
        .find(|p| p.id.name() == name)
        .unwrap()
}

#[test]
fn every_point_names_an_item_with_a_unit_and_a_known_group() {
    let driver = ThermosaldDriver::new(&config("sealer0", 0)).unwrap();
    let groups: Vec<String> = driver.groups().into_iter().map(|g| g.name).collect();
    let points = driver.points();
    assert_eq!(points.len(), POINTS.len() + StatePoints::COUNT);
    for p in &points {
        assert!(groups.contains(&p.group.to_string()), "{}", p.id);
    }
    let ids: HashSet<_> = points.iter().map(|p| &p.id).collect();
    assert_eq!(ids.len(), points.len(), "point ids are unique");
    let temperature = spec(&driver, "temperature");
    assert_eq!(temperature.unit.as_deref(), Some("°C"));
    assert_eq!(temperature.group, LIVE);
    assert_eq!(spec(&driver, "power").unit.as_deref(), Some("VA"));
    assert!(spec(&driver, "address").writable.is_none());
    assert!(spec(&driver, "serial_enabled").writable.is_none());
    let kint = spec(&driver, "kint_gain").writable.unwrap();
    assert_eq!(kint.step, Some(0.1));
    assert!(!kint.integer);
}

#[test]
fn regulator_addresses_outside_0_to_7_are_refused() {
    assert!(check_address(Some(0)).is_ok());
    assert!(check_address(Some(7)).is_ok());
    assert!(check_address(Some(8)).unwrap_err().contains("0 to 7"));
    assert!(
        check_address(None)
            .unwrap_err()
            .contains("needs its address")
    );
    assert!(ThermosaldDriver::new(&config("sealer9", 9)).is_err());
}

#[tokio::test(start_paused = true)]
async fn three_regulators_on_one_line_each_answer_their_own_polls() {
    let (mut drivers, _model) = rig(&[0, 1, 2]);
    for driver in &mut drivers {
        let live = driver.poll(LIVE).await.unwrap();
        assert_eq!(live.len(), 6 + StatePoints::COUNT);
        assert!(matches!(value(&live, "temperature"), Ok(Value::Number(t)) if t > 0.0));
        assert_eq!(value(&live, "fault"), Ok(Value::Number(0.0)));
        assert_eq!(
            value(&live, "machine_state"),
            Ok(Value::Text("sealing".into())),
            "the twin's packaging machine seals every 3 s"
        );
        for group in [SETTINGS, MACHINE, SERVICE] {
            let readings = driver.poll(group).await.unwrap();
            assert!(readings.iter().all(|r| r.value.is_ok()), "{readings:?}");
        }
    }
    let machine = drivers[2].poll(MACHINE).await.unwrap();
    assert_eq!(value(&machine, "address"), Ok(Value::Number(2.0)));
}

#[tokio::test(start_paused = true)]
async fn a_provoked_fault_shows_as_its_number_and_words() {
    let (mut drivers, model) = rig(&[0, 1]);
    model
        .lock()
        .regulator_mut(address(1))
        .unwrap()
        .provoke(Fault::OpenBand, tokio::time::Instant::now().into_std());
    let live = drivers[1].poll(LIVE).await.unwrap();
    assert_eq!(value(&live, "fault"), Ok(Value::Number(1.0)));
    let fault = spec(&drivers[1], "fault");
    assert_eq!(fault.label(&Value::Number(1.0)), Some("sealing band open"));
    assert!(fault.is_alarm(&Value::Number(1.0)));
    let other = drivers[0].poll(LIVE).await.unwrap();
    assert_eq!(value(&other, "fault"), Ok(Value::Number(0.0)));
}

#[tokio::test(start_paused = true)]
async fn a_set_point_write_reaches_the_regulator_and_reads_back() {
    let (mut drivers, _model) = rig(&[0]);
    let driver = &mut drivers[0];
    let sealing = spec(driver, "sealing_temperature");
    driver
        .check_then_write(&sealing, &Value::Number(150.0))
        .await
        .unwrap();
    let kint = spec(driver, "kint_gain");
    driver
        .check_then_write(&kint, &Value::Number(12.5))
        .await
        .unwrap();
    let settings = driver.poll(SETTINGS).await.unwrap();
    assert_eq!(
        value(&settings, "sealing_temperature"),
        Ok(Value::Number(150.0))
    );
    let machine = driver.poll(MACHINE).await.unwrap();
    assert_eq!(value(&machine, "kint_gain"), Ok(Value::Number(12.5)));
}

#[tokio::test(start_paused = true)]
async fn writes_out_of_range_between_steps_or_above_the_working_limit_never_reach_the_wire() {
    let (mut drivers, model) = rig(&[0]);
    let driver = &mut drivers[0];
    driver.poll(SETTINGS).await.unwrap();
    let before = model.lock().regulators_mut()[0]
        .table(Table::Settings, tokio::time::Instant::now().into_std());
    let sealing = spec(driver, "sealing_temperature");
    let err = driver
        .check_then_write(&sealing, &Value::Number(1000.0))
        .await
        .unwrap_err();
    assert!(
        matches!(err, WriteError::Invalid(ValueError::OutOfRange { .. })),
        "{err}"
    );
    let max = driver
        .max_working()
        .expect("confirmed by the settings poll");
    let err = driver
        .check_then_write(&sealing, &Value::Number(max + 1.0))
        .await
        .unwrap_err();
    assert!(
        err.to_string().contains("maximum working temperature"),
        "{err}"
    );
    let kint = spec(driver, "kint_gain");
    let err = driver
        .check_then_write(&kint, &Value::Number(12.55))
        .await
        .unwrap_err();
    assert!(
        matches!(err, WriteError::Invalid(ValueError::NotAStep { .. })),
        "{err}"
    );
    let address = spec(driver, "address");
    let err = driver
        .check_then_write(&address, &Value::Number(3.0))
        .await
        .unwrap_err();
    assert!(
        matches!(err, WriteError::Invalid(ValueError::ReadOnly { .. })),
        "{err}"
    );
    let after = model.lock().regulators_mut()[0]
        .table(Table::Settings, tokio::time::Instant::now().into_std());
    assert_eq!(before, after, "nothing was written");
}

#[tokio::test(start_paused = true)]
async fn a_regulator_that_is_not_on_the_line_times_out() {
    let (_drivers, model) = rig(&[0]);
    let (a, b) = tokio::io::duplex(1024);
    tokio::spawn(link::serve::serve_stream(b, model.line(), None));
    let mut driver = ThermosaldDriver::new(&config("sealer5", 5)).unwrap();
    driver.attach(SharedLine::new(link::Line::from_stream(
        a,
        "rs485",
        Some(DEFAULT_SERIAL),
    )));
    let err = driver.poll(LIVE).await.unwrap_err();
    assert_eq!(err.kind, ErrorKind::Timeout, "{err}");
    assert!(err.message.contains('5'), "{err}");
}

/// A digit to damage in the next whole-table answer to a table's read: `mask` flipped
/// into digit `digit` (0 = hundreds) of item `index`.
#[derive(Debug, Clone, Copy)]
struct Damage {
    table: Table,
    index: u8,
    digit: usize,
    mask: u8,
}

impl Damage {
    /// Byte offset of the damaged digit: `%`, address, 2-digit message, `R`, 2-digit
    /// count, the unused byte, then 3 digits per item.
    fn offset(&self) -> usize {
        8 + 3 * usize::from(self.index) + self.digit
    }

    fn matches(&self, answer: &[u8]) -> bool {
        let message = self.table.read_message().number().to_string();
        answer.get(2..4) == Some(message.as_bytes()) && answer.get(5..7) == Some(b"99")
    }
}

/// The line as the driver under test hears it: the twin behind `D` (a fault injector,
/// or the twin's own line), every question counted, chosen answers damaged once.
struct Tap<D> {
    inner: Arc<Mutex<D>>,
    questions: Arc<AtomicUsize>,
    damage: Arc<Mutex<Vec<Damage>>>,
}

impl<D: Device> Device for Tap<D> {
    fn receive(&mut self, bytes: &[u8], now: std::time::Instant) -> Vec<Transmit> {
        // The master sends only questions, each ending in LF.
        let questions = bytes.iter().filter(|&&b| b == b'\n').count();
        self.questions.fetch_add(questions, Ordering::SeqCst);
        let mut replies = self.inner.lock().unwrap().receive(bytes, now);
        let mut damage = self.damage.lock().unwrap();
        for reply in &mut replies {
            if let Some(i) = damage.iter().position(|d| d.matches(&reply.bytes)) {
                let d = damage.remove(i);
                reply.bytes[d.offset()] ^= d.mask;
            }
        }
        replies
    }
}

/// Regulator 0's driver on a line to its twin through a [`Tap`].
struct Bench<D> {
    driver: ThermosaldDriver,
    model: SharedModel<RegulatorBus>,
    device: Arc<Mutex<D>>,
    questions: Arc<AtomicUsize>,
    damage: Arc<Mutex<Vec<Damage>>>,
}

fn bench<D: Device>(retries: u8, wrap: impl FnOnce(ModelLine<RegulatorBus>) -> D) -> Bench<D> {
    let twin = RegulatorBus::new(&[address(0)], tokio::time::Instant::now().into_std()).unwrap();
    let model = SharedModel::new(twin);
    let device = Arc::new(Mutex::new(wrap(model.line())));
    let questions = Arc::new(AtomicUsize::new(0));
    let damage = Arc::new(Mutex::new(Vec::new()));
    let tap = Tap {
        inner: Arc::clone(&device),
        questions: Arc::clone(&questions),
        damage: Arc::clone(&damage),
    };
    let (a, b) = tokio::io::duplex(1024);
    tokio::spawn(link::serve::serve_stream(b, tap, None));
    let mut driver = ThermosaldDriver::new(&DriverConfig {
        retries: Some(retries),
        ..config("sealer0", 0)
    })
    .unwrap();
    driver.attach(SharedLine::new(link::Line::from_stream(
        a,
        "rs485",
        Some(DEFAULT_SERIAL),
    )));
    Bench {
        driver,
        model,
        device,
        questions,
        damage,
    }
}

impl<D> Bench<D> {
    /// Damages the next whole-table answer of `table` at one digit of item `index`.
    fn damage_next(&self, table: Table, index: u8, digit: usize, mask: u8) {
        self.damage.lock().unwrap().push(Damage {
            table,
            index,
            digit,
            mask,
        });
    }

    /// Polls `group`, returning its readings and the questions it cost.
    async fn poll_counted(&mut self, group: &str) -> (Vec<Reading>, usize) {
        let before = self.questions.load(Ordering::SeqCst);
        let readings = self.driver.poll(group).await.unwrap();
        (readings, self.questions.load(Ordering::SeqCst) - before)
    }

    /// The twin's true raw value of a table's item now.
    fn truth(&self, table: Table, index: u8) -> RawValue {
        let now = tokio::time::Instant::now().into_std();
        let mut line = self.model.lock();
        let regulator = &mut line.regulators_mut()[0];
        match table {
            Table::Runtime => RawValue::new(regulator.fault_number(now)).unwrap(),
            _ => regulator.table(table, now)[usize::from(index)],
        }
    }
}

/// Another master on the same twin (the regulator's panel, a PLC) writes `value` to
/// `item` over its own line, away from the driver's exchanges.
async fn set_on_the_twin(model: &SharedModel<RegulatorBus>, item: &'static Item, value: f64) {
    tokio::time::sleep(Duration::from_millis(300)).await;
    let (a, b) = tokio::io::duplex(1024);
    tokio::spawn(link::serve::serve_stream(b, model.line(), None));
    let line = SharedLine::new(link::Line::from_stream(a, "panel", Some(DEFAULT_SERIAL)));
    let mut panel = Client::new(line, ClientConfig::new(address(0)));
    panel.write(item, value).await.unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;
}

fn settings_item(index: u8) -> &'static Item {
    Table::Settings.item(index).unwrap()
}

#[tokio::test(start_paused = true)]
async fn a_reading_outside_its_items_range_is_bad_and_says_which_value_and_range() {
    let mut bench = bench(1, |line| line);
    // Mains frequency 050 Hz, its tens digit 5 damaged into 7: 70 Hz, outside 50–60 Hz.
    bench.damage_next(Table::Machine, 6, 1, 0b10);
    let (machine, _) = bench.poll_counted(MACHINE).await;
    let err = value(&machine, "mains_frequency").unwrap_err();
    assert_eq!(err.kind, ErrorKind::Decode, "{err}");
    for fact in ["Mains frequency", "70 Hz", "50 Hz to 60 Hz"] {
        assert!(err.message.contains(fact), "{fact:?} in {err}");
    }
    assert_eq!(value(&machine, "kint_gain"), Ok(Value::Number(5.0)));
    // Confirmed items keep their confirmed value out of it: the same digit damaged
    // again is bad again, never good.
    let (machine, _) = bench.poll_counted(MACHINE).await;
    assert_eq!(value(&machine, "mains_frequency"), Ok(Value::Number(50.0)));
    bench.damage_next(Table::Machine, 6, 1, 0b10);
    let (machine, _) = bench.poll_counted(MACHINE).await;
    assert!(value(&machine, "mains_frequency").is_err());
}

#[tokio::test(start_paused = true)]
async fn a_corrupted_setting_is_not_recorded_until_a_second_read_confirms_it() {
    let mut bench = bench(1, |line| line);
    // The first answer says 350 °C for the maximum working temperature (its hundreds
    // digit 2 damaged into 3); the confirming read says 250 °C.
    bench.damage_next(Table::Settings, settings::MAXIMUM_WORKING_TEMPERATURE, 0, 1);
    let (readings, questions) = bench.poll_counted(SETTINGS).await;
    let err = value(&readings, "max_working_temperature").unwrap_err();
    assert_eq!(err.kind, ErrorKind::Decode);
    assert!(err.message.contains("350 °C, then 250 °C"), "{err}");
    assert_eq!(
        value(&readings, "sealing_temperature"),
        Ok(Value::Number(180.0))
    );
    assert_eq!(
        questions, 2,
        "the table read, then the table again to confirm"
    );
    assert_eq!(bench.driver.max_working(), None);

    // A set point above the true limit is refused: the limit is confirmed first.
    let sealing = spec(&bench.driver, "sealing_temperature");
    let err = bench
        .driver
        .check_then_write(&sealing, &Value::Number(300.0))
        .await
        .unwrap_err();
    assert!(
        err.to_string().contains("maximum working temperature"),
        "{err}"
    );
    assert_eq!(bench.driver.max_working(), Some(250.0));
    assert_eq!(
        bench.truth(Table::Settings, settings::SEALING_TEMPERATURE),
        RawValue::new(180).unwrap()
    );

    // Once confirmed, the same damage is not recorded: the point keeps its value.
    let (readings, _) = bench.poll_counted(SETTINGS).await;
    assert_eq!(
        value(&readings, "max_working_temperature"),
        Ok(Value::Number(250.0))
    );
    bench.damage_next(Table::Settings, settings::MAXIMUM_WORKING_TEMPERATURE, 0, 1);
    let (readings, questions) = bench.poll_counted(SETTINGS).await;
    assert_eq!(recorded(&readings, "max_working_temperature"), None);
    assert_eq!(questions, 2, "the table read, then the item to confirm");
    assert_eq!(bench.driver.max_working(), Some(250.0));
}

#[tokio::test(start_paused = true)]
async fn the_damaged_digits_of_the_issue_are_never_recorded_as_good() {
    // bands_in_series 1 → 5, kd_gain 0 → 40, kint_gain 5.0 → 5.8, as seen with
    // `cellbus sim thermosald --fault-rate 0.5`.
    let cases = [
        (
            SERVICE,
            Table::Service,
            service::IN_SERIES,
            2,
            0b100,
            "bands_in_series",
            1.0,
        ),
        (MACHINE, Table::Machine, 11, 1, 0b100, "kd_gain", 0.0),
        (
            MACHINE,
            Table::Machine,
            machine::KINT_GAIN,
            2,
            0b1000,
            "kint_gain",
            5.0,
        ),
    ];
    let mut bench = bench(1, |line| line);
    for (group, table, index, digit, mask, point, truth) in cases {
        bench.poll_counted(group).await;
        bench.damage_next(table, index, digit, mask);
        let (readings, questions) = bench.poll_counted(group).await;
        assert_eq!(recorded(&readings, point), None, "{point}");
        assert_eq!(questions, 2, "{point}: one confirming read");
        let (readings, _) = bench.poll_counted(group).await;
        assert_eq!(value(&readings, point), Ok(Value::Number(truth)), "{point}");
    }
}

#[tokio::test(start_paused = true)]
async fn a_new_fault_number_is_raised_only_after_a_confirming_read() {
    let mut bench = bench(1, |line| line);
    let (live, questions) = bench.poll_counted(LIVE).await;
    assert_eq!(value(&live, "fault"), Ok(Value::Number(0.0)));
    assert_eq!(questions, 2, "the first fault number is confirmed too");
    // A damaged 000 → 001 ("sealing band open") is not taken for a fault.
    bench.damage_next(Table::Runtime, runtime::FAULT, 2, 1);
    let (live, questions) = bench.poll_counted(LIVE).await;
    assert_eq!(recorded(&live, "fault"), None);
    assert!(matches!(value(&live, "temperature"), Ok(Value::Number(_))));
    assert_eq!(questions, 2);
    // A real fault is, once read twice.
    bench
        .model
        .lock()
        .regulator_mut(address(0))
        .unwrap()
        .provoke(Fault::OpenBand, tokio::time::Instant::now().into_std());
    let (live, questions) = bench.poll_counted(LIVE).await;
    assert_eq!(value(&live, "fault"), Ok(Value::Number(1.0)));
    assert_eq!(questions, 2);
    let (_, questions) = bench.poll_counted(LIVE).await;
    assert_eq!(questions, 1, "an unchanged fault number costs nothing more");
}

#[tokio::test(start_paused = true)]
async fn a_real_change_is_recorded_after_one_confirming_read_and_limits_the_writes() {
    let mut bench = bench(1, |line| line);
    bench.poll_counted(SETTINGS).await;
    let max_working = settings_item(settings::MAXIMUM_WORKING_TEMPERATURE);
    set_on_the_twin(&bench.model, max_working, 200.0).await;
    let (readings, questions) = bench.poll_counted(SETTINGS).await;
    assert_eq!(
        value(&readings, "max_working_temperature"),
        Ok(Value::Number(200.0))
    );
    assert_eq!(questions, 2);
    assert_eq!(bench.driver.max_working(), Some(200.0));
    let sealing = spec(&bench.driver, "sealing_temperature");
    let err = bench
        .driver
        .check_then_write(&sealing, &Value::Number(220.0))
        .await
        .unwrap_err();
    assert!(
        err.to_string().contains("maximum working temperature"),
        "{err}"
    );
    // A write the regulator echoed is confirmed by its echo: no second read follows.
    bench
        .driver
        .check_then_write(&sealing, &Value::Number(190.0))
        .await
        .unwrap();
    let (readings, questions) = bench.poll_counted(SETTINGS).await;
    assert_eq!(
        value(&readings, "sealing_temperature"),
        Ok(Value::Number(190.0))
    );
    assert_eq!(questions, 1);
}

#[tokio::test(start_paused = true)]
async fn in_a_steady_state_every_poll_is_one_exchange() {
    let mut bench = bench(1, |line| line);
    for group in [LIVE, SETTINGS, MACHINE, SERVICE] {
        bench.poll_counted(group).await;
    }
    let before = bench.questions.load(Ordering::SeqCst);
    let mut polls = 0;
    for _ in 0..10 {
        for group in [LIVE, SETTINGS, MACHINE, SERVICE] {
            let (readings, _) = bench.poll_counted(group).await;
            assert!(readings.iter().all(|r| r.value.is_ok()), "{readings:?}");
            polls += 1;
        }
        tokio::time::sleep(Duration::from_secs(2)).await;
    }
    assert_eq!(bench.questions.load(Ordering::SeqCst) - before, polls);
}

#[tokio::test(start_paused = true)]
async fn under_heavy_line_damage_no_wrong_confirmed_value_is_ever_recorded_as_good() {
    let mut bench = bench(2, |line| FaultInjector::new(line, 20261, 0.5).unwrap());
    let groups = [LIVE, SETTINGS, LIVE, MACHINE, LIVE, SERVICE];
    let sealing = settings_item(settings::SEALING_TEMPERATURE);
    let (mut polls, mut failed, mut checked, mut wrong, mut bad, mut kept) = (0, 0, 0, 0, 0, 0);
    for round in 0..400usize {
        let group = groups[round % groups.len()];
        let table = table_of(group).unwrap();
        let truths: Vec<(&Def, RawValue)> = POINTS
            .iter()
            // Every settings, machine and service point, and the fault number.
            .filter(|d| d.table == table && (table != Table::Runtime || d.index == runtime::FAULT))
            .map(|d| (d, bench.truth(table, d.index)))
            .collect();
        polls += 1;
        match bench.driver.poll(group).await {
            Err(_) => failed += 1,
            Ok(readings) => {
                for (def, truth) in truths {
                    match recorded(&readings, def.name) {
                        None => kept += 1,
                        Some(Ok(v)) => {
                            checked += 1;
                            if v != def.value(def.item().reading(truth)) {
                                wrong += 1;
                                eprintln!("{}: {v:?}, the twin has {truth:?}", def.name);
                            }
                        }
                        Some(Err(_)) => bad += 1,
                    }
                }
            }
        }
        // The truth changes between polls: a fault comes and goes, the panel changes
        // the sealing temperature.
        let now = tokio::time::Instant::now().into_std();
        match round % 60 {
            20 => bench.model.lock().regulators_mut()[0].provoke(Fault::OpenBand, now),
            40 => {
                let mut line = bench.model.lock();
                line.regulators_mut()[0].remove_cause(Fault::OpenBand, now);
                line.regulators_mut()[0].power_cycle(now);
            }
            50 => set_on_the_twin(&bench.model, sealing, 150.0 + (round % 7) as f64).await,
            _ => {}
        }
        // Longer than the latest a delayed answer can come, so it never meets a change.
        tokio::time::sleep(Duration::from_secs(3)).await;
    }
    let injected = bench.device.lock().unwrap().injected();
    eprintln!(
        "{polls} polls ({failed} without an answer), {checked} confirmed values recorded \
         as good, {wrong} of them wrong, {kept} kept (two reads disagreed), {bad} bad; \
         faults injected: {injected:?}; \
         questions: {}",
        bench.questions.load(Ordering::SeqCst)
    );
    assert!(injected.corrupted > 50, "{injected:?}");
    assert!(checked > 1000, "{checked}");
    assert_eq!(wrong, 0);
}

#[test]
fn a_bit_flip_in_a_run_time_answer_passes_as_another_measurement_in_at_most_a_quarter_of_its_bits()
{
    // A run-time answer while sealing, as the twin gives it 1.5 s into its first impulse.
    let t0 = std::time::Instant::now();
    let mut twin = RegulatorBus::new(&[address(0)], t0).unwrap();
    let data = twin.regulators_mut()[0].table(Table::Runtime, t0 + Duration::from_millis(3500));
    let digits: String = data.iter().map(|raw| format!("{:03}", raw.get())).collect();
    let answer = format!("%053R990{digits}\n").into_bytes();
    let read = thermosald::Exchange::new(
        Target::Address(address(0)),
        Read::all(Table::Runtime).into(),
    )
    .unwrap();
    // For each single-bit flip: the items whose value changed in an answer the client
    // takes.
    let mut changed_by_item = [0usize; tables::RUNTIME_ITEMS];
    let bits = answer.len() * 8;
    for bit in 0..bits {
        let mut damaged = answer.clone();
        damaged[bit / 8] ^= 1 << (bit % 8);
        let mut deframer = wire::Deframer::new(thermosald::FrameCodec);
        deframer.push(&damaged);
        while let Some(input) = deframer.next_frame() {
            let Ok(frame) = input else { continue };
            if let thermosald::exchange::Classified::Answer(thermosald::exchange::Answer::Values(
                values,
            )) = read.classify(&frame)
            {
                let differing: Vec<usize> = (0..data.len())
                    .filter(|&i| values.raw().get(i) != data.get(i))
                    .collect();
                assert!(differing.len() <= 1, "one flip, one digit: {differing:?}");
                for i in differing {
                    changed_by_item[i] += 1;
                }
            }
        }
    }
    let fault = changed_by_item[usize::from(runtime::FAULT)];
    let measured: usize = POINTS
        .iter()
        .filter(|d| d.table == Table::Runtime && d.meaning == Meaning::Quantity)
        .map(|d| changed_by_item[usize::from(d.index)])
        .sum();
    eprintln!(
        "run-time answer {:?}: of its {bits} single-bit flips, {measured} pass as another \
         measurement, {fault} as another fault number (confirmed by a second read)",
        String::from_utf8_lossy(&answer)
    );
    // 2 to 4 of a digit's 8 bits give another digit; 15 measurement digits in 240 bits.
    assert_eq!(fault, 12, "000: each digit has 4 flips to another digit");
    assert!(measured * 4 <= bits, "{measured} of {bits}");
}
