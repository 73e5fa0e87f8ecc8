use super::*;
use crate::testing::CheckThenWrite;
use crate::testing::reading as value;
use jbus::data::Order;
use jbus::slave::{Slave, SlaveMap};
use wire::device::SharedModel;

fn register(name: &str, table: RegisterTable, address: u16) -> RegisterConfig {
    RegisterConfig {
        table,
        ..RegisterConfig::holding(name, address)
    }
}

fn typed(name: &str, table: RegisterTable, address: u16, data_type: &str) -> RegisterConfig {
    RegisterConfig {
        format: Format::new(data_type.parse().unwrap(), Order::Abcd),
        ..register(name, table, address)
    }
}

fn scaled(register: RegisterConfig, scale: f64) -> RegisterConfig {
    RegisterConfig {
        format: register
            .format
            .scaled(jbus::data::Scaling::new(scale, 0.0).unwrap()),
        ..register
    }
}

fn registers() -> Vec<RegisterConfig> {
    vec![
        RegisterConfig {
            unit: Some("°C".into()),
            ..scaled(typed("supply", RegisterTable::Input, 100, "int16"), 0.1)
        },
        register("flow", RegisterTable::Input, 101),
        RegisterConfig {
            writable: Some((5.0, 30.0)),
            ..scaled(register("setpoint", RegisterTable::Holding, 0), 0.1)
        },
        register("mode", RegisterTable::Holding, 7),
    ]
}

const MAP: &str = "unit 17\nholding 0 = 215\nholding 7 = 2\ninput 100 = 0xFFF6 42\n";

fn rig_with(
    map: &str,
    registers: impl Into<RegisterList>,
    options: ModbusOptions,
) -> (ModbusDriver, SharedModel<Slave>) {
    let slave = SharedModel::new(Slave::new(SlaveMap::parse(map).unwrap()));
    let (a, b) = tokio::io::duplex(1024);
    tokio::spawn(link::serve::serve_stream(b, slave.line(), None));
    let mut driver = ModbusDriver::new(&DriverConfig {
        states: Default::default(),
        id: DeviceId::new("chiller1").unwrap(),
        protocol: super::KIND,
        address: Some(17),
        timeout: Some(Duration::from_millis(200)),
        retries: Some(1),
        endpoint: None,
        settings: Settings::new(ModbusSettings {
            registers: registers.into(),
            options,
        }),
    })
    .unwrap();
    driver.attach(SharedLine::new(link::Line::from_stream(
        a,
        "modbus",
        Some(DEFAULT_SERIAL),
    )));
    (driver, slave)
}

/// The options of `one_request_per_register = true`.
fn one_request_per_register() -> ModbusOptions {
    ModbusOptions {
        plan: PlanOptions {
            one_request_per_item: true,
            ..PlanOptions::default()
        },
        ..ModbusOptions::default()
    }
}

/// How long `driver` takes to poll its one group.
async fn timed_poll(driver: &mut ModbusDriver) -> Duration {
    let started = Instant::now();
    driver.poll(LIVE).await.unwrap();
    started.elapsed()
}

fn rig() -> (ModbusDriver, SharedModel<Slave>) {
    rig_with(MAP, registers(), ModbusOptions::default())
}

fn spans(driver: &ModbusDriver) -> Vec<(Table, u16, u16)> {
    driver
        .plan()
        .reads()
        .iter()
        .map(|r| (r.table(), r.address(), r.count()))
        .collect()
}

#[tokio::test(start_paused = true)]
async fn registers_close_together_in_one_table_are_planned_into_one_read() {
    let (driver, _slave) = rig_with(MAP, registers(), ModbusOptions::default());
    assert_eq!(
        spans(&driver),
        vec![
            (Table::HoldingRegisters, 0, 8),
            (Table::InputRegisters, 100, 2),
        ]
    );
}

#[tokio::test(start_paused = true)]
async fn one_request_per_register_reads_every_register_alone() {
    let options = one_request_per_register();
    let (mut driver, _slave) = rig_with(MAP, registers(), options);
    assert_eq!(driver.plan().reads().len(), 4);
    let live = driver.poll(LIVE).await.unwrap();
    assert_eq!(value(&live, "mode"), Ok(Value::Number(2.0)));
    assert_eq!(driver.requests_per_poll(), Some(4));
}

#[tokio::test(start_paused = true)]
async fn registers_are_read_scaled_and_signed_as_configured() {
    let (mut driver, _slave) = rig();
    let live = driver.poll(LIVE).await.unwrap();
    assert_eq!(value(&live, "supply"), Ok(Value::Number(-1.0)));
    assert_eq!(value(&live, "flow"), Ok(Value::Number(42.0)));
    assert_eq!(value(&live, "setpoint"), Ok(Value::Number(21.5)));
    assert_eq!(value(&live, "mode"), Ok(Value::Number(2.0)));
}

#[tokio::test(start_paused = true)]
async fn a_merged_read_refused_for_a_hole_is_split_once_and_the_poll_goes_on() {
    // Holding 0 and 7 are one planned read of 8 registers; 1-6 do not exist.
    let (mut driver, slave) = rig();
    let live = driver.poll(LIVE).await.unwrap();
    assert_eq!(value(&live, "setpoint"), Ok(Value::Number(21.5)));
    assert_eq!(value(&live, "mode"), Ok(Value::Number(2.0)));
    assert_eq!(value(&live, "supply"), Ok(Value::Number(-1.0)));
    // The refused read, its two parts, and the input registers.
    assert_eq!(driver.requests_per_poll(), Some(4));
    assert_eq!(
        spans(&driver),
        vec![
            (Table::HoldingRegisters, 0, 1),
            (Table::HoldingRegisters, 7, 1),
            (Table::InputRegisters, 100, 2),
        ]
    );
    driver.poll(LIVE).await.unwrap();
    assert_eq!(driver.requests_per_poll(), Some(3), "the split is kept");
    drop(slave);
}

#[tokio::test(start_paused = true)]
async fn devices_of_one_register_list_share_its_plan_until_one_splits_a_read() {
    let list = RegisterList::from(registers());
    let (mut first, _first) = rig_with(MAP, list.clone(), ModbusOptions::default());
    let (second, _second) = rig_with(MAP, list.clone(), ModbusOptions::default());
    assert!(Arc::ptr_eq(&first.plan, &second.plan));
    // Holding 1-6 do not exist: the first device splits its merged read.
    first.poll(LIVE).await.unwrap();
    assert_eq!(spans(&first).len(), 3);
    assert_eq!(
        spans(&second),
        vec![
            (Table::HoldingRegisters, 0, 8),
            (Table::InputRegisters, 100, 2),
        ],
        "the other device keeps the plan as made"
    );
    let alone = one_request_per_register();
    let (third, _third) = rig_with(MAP, list, alone);
    assert_eq!(third.plan().reads().len(), 4, "other options, another plan");
}

#[tokio::test(start_paused = true)]
async fn a_register_the_device_does_not_have_is_bad_with_the_exception_in_words() {
    let mut registers = registers();
    registers.push(register("ghost", RegisterTable::Holding, 500));
    let (mut driver, _slave) = rig_with(MAP, registers, ModbusOptions::default());
    let live = driver.poll(LIVE).await.unwrap();
    let ghost = value(&live, "ghost").unwrap_err();
    assert_eq!(ghost.kind, ErrorKind::Refused, "{ghost}");
    assert!(ghost.message.contains("illegal data address"), "{ghost}");
    assert_eq!(value(&live, "flow"), Ok(Value::Number(42.0)));
    assert_eq!(value(&live, "mode"), Ok(Value::Number(2.0)));
}

/// A device that answers a request with an exception when `refuse` says so (a read
/// that covers a register it fails on, a unit behind a gateway that is not there),
/// and is `inner` otherwise.
struct Refusing<D> {
    inner: D,
    refuse: fn(&jbus::rtu::RequestPdu) -> Option<ExceptionCode>,
}

impl<D: wire::Device> wire::Device for Refusing<D> {
    fn receive(&mut self, bytes: &[u8], now: std::time::Instant) -> Vec<wire::Transmit> {
        if let Ok(Some((adu, _))) = jbus::rtu::codec::decode_request(bytes)
            && let Some(code) = (self.refuse)(&adu.pdu)
        {
            let answer = jbus::rtu::ResponseAdu {
                unit: adu.unit,
                response: jbus::rtu::Response::exception(
                    jbus::rtu::FunctionCode::of_exception(adu.pdu.function_byte()),
                    code,
                ),
            };
            let mut out = Vec::new();
            jbus::rtu::codec::encode_response(&answer, &mut out);
            return vec![wire::Transmit::now(out)];
        }
        self.inner.receive(bytes, now)
    }
}

fn rig_refusing(
    registers: Vec<RegisterConfig>,
    refuse: fn(&jbus::rtu::RequestPdu) -> Option<ExceptionCode>,
) -> ModbusDriver {
    let slave = SharedModel::new(Slave::new(SlaveMap::parse(MAP).unwrap()));
    let (a, b) = tokio::io::duplex(1024);
    let device = Refusing {
        inner: slave.line(),
        refuse,
    };
    tokio::spawn(link::serve::serve_stream(b, device, None));
    let (mut driver, _) = rig_with(MAP, registers, ModbusOptions::default());
    driver.attach(SharedLine::new(link::Line::from_stream(
        a,
        "modbus",
        Some(DEFAULT_SERIAL),
    )));
    driver
}

#[tokio::test(start_paused = true)]
async fn a_poll_that_fails_midway_hands_over_what_its_answered_reads_gave() {
    // Holding 0-7 all defined, so the first read is answered whole.
    const FULL: &str = "unit 17\nholding 0 = 215 0 0 0 0 0 0 2\ninput 100 = 0xFFF6 42\n";
    let slave = SharedModel::new(Slave::new(SlaveMap::parse(FULL).unwrap()));
    let (a, b) = tokio::io::duplex(1024);
    let device = testkit::Tricky::new(slave.line(), []).silent_after(std::sync::Arc::new(1.into()));
    tokio::spawn(link::serve::serve_stream(b, device, None));
    let (mut driver, _) = rig_with(FULL, registers(), ModbusOptions::default());
    driver.attach(SharedLine::new(link::Line::from_stream(
        a,
        "modbus",
        Some(DEFAULT_SERIAL),
    )));
    assert_eq!(driver.plan.reads().len(), 2, "holding 0-7, input 100-101");
    let in_first_read =
        |driver: &ModbusDriver, i: usize| driver.plan.locate(i).is_some_and(|at| at.read == 0);
    let first: Vec<String> = (0..driver.registers.len())
        .filter(|&i| in_first_read(&driver, i))
        .map(|i| driver.registers[i].name.to_string())
        .collect();
    assert_eq!(first, ["setpoint", "mode"]);

    let down = driver.poll(LIVE).await.unwrap_err();
    assert_eq!(down.kind, ErrorKind::Timeout, "{down}");
    let partial = driver.take_partial();
    let names: Vec<String> = partial.iter().map(|r| r.point.name().to_owned()).collect();
    assert_eq!(
        names, first,
        "the first read's registers, none of the second's"
    );
    assert_eq!(value(&partial, "setpoint"), Ok(Value::Number(21.5)));
    assert_eq!(value(&partial, "mode"), Ok(Value::Number(2.0)));
    assert!(driver.take_partial().is_empty(), "taken once");
}

#[tokio::test(start_paused = true)]
async fn a_merged_read_refused_with_exception_4_is_split_so_only_the_failing_register_is_bad() {
    // Holding 0-7 are one read; the device fails on holding 7 (exception 4).
    let mut driver = rig_refusing(registers(), |pdu| match *pdu {
        jbus::rtu::RequestPdu::ReadHoldingRegisters { address, count }
            if address <= 7 && 7 < address + count =>
        {
            Some(ExceptionCode::SERVER_DEVICE_FAILURE)
        }
        _ => None,
    });
    let live = driver.poll(LIVE).await.unwrap();
    assert_eq!(value(&live, "setpoint"), Ok(Value::Number(21.5)));
    let mode = value(&live, "mode").unwrap_err();
    assert_eq!(mode.kind, ErrorKind::Refused, "{mode}");
    assert!(mode.message.contains("exception 4"), "{mode}");
    assert_eq!(value(&live, "flow"), Ok(Value::Number(42.0)));
}

#[tokio::test(start_paused = true)]
async fn a_unit_a_modbus_gateway_says_does_not_answer_is_down_not_up_with_bad_points() {
    let mut driver = rig_refusing(registers(), |_| Some(ExceptionCode::GATEWAY_TARGET_FAILED));
    let down = driver.poll(LIVE).await.unwrap_err();
    assert_eq!(down.kind, ErrorKind::Timeout, "{down}");
    assert!(down.message.contains("did not answer"), "{down}");
    let mut driver = rig_refusing(registers(), |_| {
        Some(ExceptionCode::GATEWAY_PATH_UNAVAILABLE)
    });
    assert_eq!(
        driver.poll(LIVE).await.unwrap_err().kind,
        ErrorKind::Timeout
    );
}

const TYPED: &str = "unit 17\n\
    input 0x0100 float32 CDAB = 229.7 -1.5\n\
    input 0x0104 int32 = -70000\n\
    holding 0x0200 float32 = 12.5\n\
    holding 0x0300 string:4 = \"PUMP 7\"\n\
    holding 0x0310 = 0x0008\n\
    coil 3 = 1 0\n\
    discrete 0x20 = 0 1\n";

fn typed_registers() -> Vec<RegisterConfig> {
    vec![
        RegisterConfig {
            format: Format::new(DataType::Float32, Order::Cdab),
            unit: Some("V".into()),
            ..register("voltage", RegisterTable::Input, 0x0100)
        },
        RegisterConfig {
            format: Format::new(DataType::Float32, Order::Cdab),
            ..register("current", RegisterTable::Input, 0x0102)
        },
        typed("energy", RegisterTable::Input, 0x0104, "int32"),
        RegisterConfig {
            writable: Some((0.0, 100.0)),
            ..typed("limit", RegisterTable::Holding, 0x0200, "float32")
        },
        typed("label", RegisterTable::Holding, 0x0300, "string:4"),
        typed("alarm_bit", RegisterTable::Holding, 0x0310, "bit:3"),
        RegisterConfig {
            writable: Some((0.0, 1.0)),
            ..register("pump", RegisterTable::Coil, 3)
        },
        register("door", RegisterTable::Discrete, 0x21),
    ]
}

#[tokio::test(start_paused = true)]
async fn typed_registers_coils_and_discrete_inputs_are_read_as_their_kinds() {
    let (mut driver, _slave) = rig_with(TYPED, typed_registers(), ModbusOptions::default());
    let live = driver.poll(LIVE).await.unwrap();
    assert_eq!(value(&live, "voltage"), Ok(Value::Number(229.7)));
    assert_eq!(value(&live, "current"), Ok(Value::Number(-1.5)));
    assert_eq!(value(&live, "energy"), Ok(Value::Number(-70000.0)));
    assert_eq!(value(&live, "limit"), Ok(Value::Number(12.5)));
    assert_eq!(value(&live, "label"), Ok(Value::Text("PUMP 7".into())));
    assert_eq!(value(&live, "alarm_bit"), Ok(Value::Number(1.0)));
    assert_eq!(value(&live, "pump"), Ok(Value::Number(1.0)));
    assert_eq!(value(&live, "door"), Ok(Value::Number(1.0)));
    let points = driver.points();
    let kind = |name: &str| {
        points
            .iter()
            .find(|p| p.id.name() == name)
            .unwrap()
            .kind
            .clone()
    };
    assert_eq!(kind("voltage"), PointKind::Numeric);
    assert_eq!(kind("label"), PointKind::Text);
    for on_off in ["pump", "door", "alarm_bit"] {
        assert!(
            matches!(kind(on_off), PointKind::Enum { ref states } if states.len() == 2),
            "{on_off}"
        );
    }
}

#[tokio::test(start_paused = true)]
async fn a_float_is_written_with_function_16_and_a_coil_with_function_5() {
    let (mut driver, slave) = rig_with(TYPED, typed_registers(), ModbusOptions::default());
    let points = driver.points();
    let point = |name: &str| points.iter().find(|p| p.id.name() == name).unwrap();
    driver
        .check_then_write(point("limit"), &Value::Number(42.25))
        .await
        .unwrap();
    let words = {
        let slave = slave.lock();
        [
            slave.get(Table::HoldingRegisters, 0x0200).unwrap(),
            slave.get(Table::HoldingRegisters, 0x0201).unwrap(),
        ]
    };
    assert_eq!(
        Format::new(DataType::Float32, Order::Abcd).decode(&words),
        Ok(TypedValue::Float(42.25))
    );
    driver
        .check_then_write(point("pump"), &Value::Text("off".into()))
        .await
        .unwrap();
    assert_eq!(slave.lock().get(Table::Coils, 3), Some(0));
    let err = driver
        .check_then_write(point("voltage"), &Value::Number(1.0))
        .await
        .unwrap_err();
    assert!(matches!(err, WriteError::Invalid(_)), "{err}");
    // Within the range, but a float32 would hold 0: refused with that reason.
    let err = driver
        .check_then_write(point("limit"), &Value::Number(1e-50))
        .await
        .unwrap_err();
    assert!(
        matches!(
            &err,
            WriteError::Invalid(crate::point::ValueError::NotRepresentable { .. })
        ) && err.to_string().contains("too small for float32"),
        "{err}"
    );
}

#[tokio::test(start_paused = true)]
async fn a_write_is_checked_against_range_and_step_then_sent_as_the_register_word() {
    let (mut driver, slave) = rig();
    let points = driver.points();
    let setpoint = points.iter().find(|p| p.id.name() == "setpoint").unwrap();
    let err = driver
        .check_then_write(setpoint, &Value::Number(31.0))
        .await
        .unwrap_err();
    assert!(matches!(err, WriteError::Invalid(_)), "{err}");
    let err = driver
        .check_then_write(setpoint, &Value::Number(22.25))
        .await
        .unwrap_err();
    assert!(err.to_string().contains("multiple of 0.1"), "{err}");
    assert_eq!(slave.lock().get(Table::HoldingRegisters, 0), Some(215));
    driver
        .check_then_write(setpoint, &Value::Number(22.5))
        .await
        .unwrap();
    assert_eq!(slave.lock().get(Table::HoldingRegisters, 0), Some(225));
    let mode = points.iter().find(|p| p.id.name() == "mode").unwrap();
    assert!(
        driver
            .check_then_write(mode, &Value::Number(1.0))
            .await
            .is_err()
    );
}

#[tokio::test(start_paused = true)]
async fn requests_are_paced_after_the_line_is_attached_and_between_each_other() {
    let options = ModbusOptions {
        delay_between_requests: Duration::from_millis(50),
        delay_after_connect: Duration::from_secs(2),
        ..one_request_per_register()
    };
    let (mut driver, _slave) = rig_with(MAP, registers(), options);
    let first = timed_poll(&mut driver).await;
    // 2 s after the attach, then 3 gaps of 50 ms between the 4 requests.
    assert!(
        first >= Duration::from_millis(2150) && first < Duration::from_millis(2500),
        "{first:?}"
    );
    let second = timed_poll(&mut driver).await;
    assert!(
        second >= Duration::from_millis(150) && second < Duration::from_millis(500),
        "{second:?}"
    );
}
