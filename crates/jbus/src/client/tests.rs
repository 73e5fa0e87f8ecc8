use std::time::Instant as StdInstant;

use link::SerialSettings;
use testkit::{Tap, Trick, Tricky};
use wire::device::{Device, SharedModel};

use super::*;
use crate::cross::device::{CrossTwin, REPLY_DELAY};
use crate::cross::{Feed, Source};
use crate::rtu::{FunctionCode, RegisterValues, Response, Write, WriteRegister};
use crate::slave::{DEFAULT_REPLY_DELAY, Slave, SlaveMap, Table};

/// Bytes before the answer that look like the head of a 255-byte answer.
fn long_head() -> Trick {
    Trick::Before(vec![0x07, 0x03, 0xFA])
}

/// Another unit's answer before the answer.
fn stray_first() -> Trick {
    let stray = ResponseAdu {
        unit: 99,
        response: Response::ReadHoldingRegisters(
            RegisterValues::new(vec![1, 2]).expect("2 values"),
        ),
    };
    Trick::Before(stray.to_bytes())
}

/// `unit` answers function 3 with exception `code` instead.
fn refuse(unit: u8, code: u8) -> Trick {
    let refusal = ResponseAdu {
        unit,
        response: Response::exception(
            FunctionCode::READ_HOLDING_REGISTERS,
            ExceptionCode::new(code).expect("test codes are 1-255"),
        ),
    };
    Trick::Replace(refusal.to_bytes())
}

struct Bench {
    client: Client,
    tap: Tap,
}

impl Bench {
    fn requests(&self) -> usize {
        self.tap.requests()
    }

    fn heard_at(&self, index: usize) -> StdInstant {
        self.tap.request_at(index).expect("heard")
    }
}

/// A client on a line (`settings` if it has a speed) to `device`, with `tricks`.
fn bench<D: Device>(
    device: D,
    tricks: Vec<Trick>,
    settings: Option<SerialSettings>,
    config: ClientConfig,
) -> Bench {
    let device = Tricky::new(device, tricks);
    let tap = device.tap();
    let (ours, theirs) = tokio::io::duplex(4096);
    tokio::spawn(link::serve::serve_stream(theirs, device, None));
    let line = SharedLine::new(Line::from_stream(ours, "test line", settings));
    Bench {
        client: Client::new(line, config),
        tap,
    }
}

fn unit(number: u8) -> UnitId {
    UnitId::new(number).expect("test unit")
}

fn twin() -> SharedModel<CrossTwin> {
    SharedModel::new(CrossTwin::new(unit(2), 7))
}

fn slave() -> SharedModel<Slave> {
    SharedModel::new(Slave::all_writable(unit(1)))
}

fn at_9600() -> Option<SerialSettings> {
    Some(SerialSettings::new_8n1(9600))
}

#[tokio::test(start_paused = true)]
async fn every_function_reads_and_writes_a_generic_server() {
    let server = slave();
    let mut b = bench(server.line(), vec![], None, ClientConfig::default());
    let c = &mut b.client;
    c.write_single_coil(unit(1), 3, true)
        .await
        .expect("written");
    c.write_multiple_coils(unit(1), 10, &[true, false, true, true])
        .await
        .expect("written");
    assert_eq!(
        c.read_coils(unit(1), 2, 12).await.expect("read"),
        [
            false, true, false, false, false, false, false, false, true, false, true, true
        ]
    );
    c.write_single_register(unit(1), 100, 0xBEEF)
        .await
        .expect("written");
    c.write_multiple_registers(unit(1), 101, &[1, 2, 3])
        .await
        .expect("written");
    assert_eq!(
        c.read_holding_registers(unit(1), 100, 4)
            .await
            .expect("read"),
        [0xBEEF, 1, 2, 3]
    );
    {
        let mut s = server.lock();
        s.set(Table::DiscreteInputs, 7, 1);
        s.set(Table::InputRegisters, 30, 4242);
    }
    assert_eq!(
        c.read_discrete_inputs(unit(1), 6, 3).await.expect("read"),
        [false, true, false]
    );
    assert_eq!(
        c.read_input_registers(unit(1), 30, 2).await.expect("read"),
        [4242, 0]
    );
    assert_eq!(b.requests(), 8);
}

#[tokio::test(start_paused = true)]
async fn cross_read_decodes_the_twin_in_four_requests_and_sees_a_transfer() {
    let cross = twin();
    let mut b = bench(cross.line(), vec![], at_9600(), ClientConfig::default());
    let state = crate::cross::read(&mut b.client, unit(2))
        .await
        .expect("read");
    assert_eq!(state.feed(), Feed::StaticSwitch(Source::S1));
    assert!(state.alarms().is_empty(), "{:?}", state.alarms());
    assert_eq!(b.requests(), 4);
    cross.lock().fail_source(Source::S1);
    let state = crate::cross::read(&mut b.client, unit(2))
        .await
        .expect("read");
    assert_eq!(state.feed(), Feed::StaticSwitch(Source::S2));
    assert!(
        state.alarms().iter().any(|a| a.contains("S1 failure")),
        "{:?}",
        state.alarms()
    );
}

#[tokio::test(start_paused = true)]
async fn an_exception_is_reported_at_once_in_words_and_never_retried() {
    let mut b = bench(twin().line(), vec![], None, ClientConfig::default());
    let started = Instant::now();
    let err = b
        .client
        .read_holding_registers(unit(2), 0x12, 2)
        .await
        .expect_err("0x12 is undefined");
    assert_eq!(
        exception_code(&err),
        Some(ExceptionCode::ILLEGAL_DATA_ADDRESS)
    );
    assert_eq!(
        err.to_string(),
        "unit 2 refused \"read 2 holding registers from 18 (0x0012)\": exception 2 \
         (illegal data address: the request touches an address the device does not have)"
    );
    assert!(err.is_device_error());
    assert_eq!(err.kind(), FailureKind::Refused);
    assert_eq!(b.requests(), 1);
    assert_eq!(started.elapsed(), REPLY_DELAY);
}

#[tokio::test(start_paused = true)]
async fn the_cross_refuses_any_function_but_3_with_exception_1() {
    let mut b = bench(twin().line(), vec![], None, ClientConfig::default());
    let err = b
        .client
        .read_input_registers(unit(2), 0, 1)
        .await
        .expect_err("function 4 is unknown to a CROSS");
    assert!(
        matches!(
            err,
            ClientError::Refused {
                refusal: UnitRefusal {
                    unit: 2,
                    exception: Exception {
                        function: FunctionCode::READ_INPUT_REGISTERS,
                        code: ExceptionCode::ILLEGAL_FUNCTION
                    },
                    ..
                },
                ..
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("illegal function"), "{err}");
}

#[tokio::test(start_paused = true)]
async fn exception_3_is_reported_with_its_number_and_meaning() {
    let mut b = bench(
        slave().line(),
        vec![refuse(1, 3)],
        None,
        ClientConfig::default(),
    );
    let err = b
        .client
        .read_holding_registers(unit(1), 0, 100)
        .await
        .expect_err("refused");
    assert_eq!(
        exception_code(&err),
        Some(ExceptionCode::ILLEGAL_DATA_VALUE)
    );
    assert!(
        err.to_string().contains("exception 3 (illegal data value"),
        "{err}"
    );
    assert_eq!(b.requests(), 1);
}

#[tokio::test(start_paused = true)]
async fn an_address_missing_from_a_slave_map_is_exception_2() {
    let map = SlaveMap::parse("unit 5\nholding 0 = 1 2 3\n").expect("valid map");
    let server = SharedModel::new(Slave::new(map));
    let mut b = bench(server.line(), vec![], None, ClientConfig::default());
    assert_eq!(
        b.client
            .read_holding_registers(unit(5), 0, 3)
            .await
            .expect("defined"),
        [1, 2, 3]
    );
    let err = b
        .client
        .write_single_register(unit(5), 3, 9)
        .await
        .expect_err("3 is not in the map");
    assert_eq!(
        exception_code(&err),
        Some(ExceptionCode::ILLEGAL_DATA_ADDRESS)
    );
}

#[tokio::test(start_paused = true)]
async fn a_late_answer_waiting_on_the_line_is_dropped_not_taken_for_the_answer() {
    use tokio::io::AsyncWriteExt as _;
    let (ours, mut theirs) = tokio::io::duplex(4096);
    // An answer to the same request that came too late for an earlier exchange.
    let stale = ResponseAdu {
        unit: 1,
        response: Response::ReadHoldingRegisters(
            RegisterValues::new(vec![0xDEAD, 0xBEEF]).expect("2 values"),
        ),
    };
    theirs.write_all(&stale.to_bytes()).await.expect("buffered");
    tokio::spawn(link::serve::serve_stream(theirs, slave().line(), None));
    let line = SharedLine::new(Line::from_stream(ours, "test line", None));
    let mut client = Client::new(line, ClientConfig::default());
    let started = Instant::now();
    let words = client
        .read_holding_registers(unit(1), 0, 2)
        .await
        .expect("the server answers");
    assert_eq!(words, [0, 0], "the server's registers, not the stale ones");
    assert_eq!(
        started.elapsed(),
        DEFAULT_REPLY_DELAY,
        "no wait to drop them"
    );
}

#[tokio::test(start_paused = true)]
async fn a_lost_answer_is_retried_after_the_timeout() {
    let mut b = bench(
        twin().line(),
        vec![Trick::Drop],
        None,
        ClientConfig::default(),
    );
    let started = Instant::now();
    b.client
        .read_holding_registers(unit(2), 0x46, 20)
        .await
        .expect("answered on the second attempt");
    assert_eq!(started.elapsed(), DEFAULT_TIMEOUT + REPLY_DELAY);
    assert_eq!(b.requests(), 2);
}

#[tokio::test(start_paused = true)]
async fn a_dead_unit_gives_up_after_every_attempt_naming_endpoint_unit_and_attempts() {
    let mut b = bench(twin().line(), vec![], None, ClientConfig::default());
    let started = Instant::now();
    let err = b
        .client
        .read_holding_registers(unit(9), 0, 1)
        .await
        .expect_err("nobody is unit 9");
    assert_eq!(started.elapsed(), DEFAULT_TIMEOUT * 3);
    assert_eq!(
        err.to_string(),
        "no valid answer from unit 9 on test line to \"read 1 holding register from 0 \
         (0x0000)\" after 3 attempts of 500 ms each (last: no reply)"
    );
    assert_eq!(b.requests(), 3);
}

#[tokio::test(start_paused = true)]
async fn the_timeout_counts_the_wire_time_of_request_and_answer() {
    let mut b = bench(twin().line(), vec![], at_9600(), ClientConfig::default());
    let err = b
        .client
        .read_holding_registers(unit(9), 0, 125)
        .await
        .expect_err("nobody is unit 9");
    // 8 + 255 bytes at 1.0417 ms each.
    let ClientError::NoAnswer { timeout, .. } = err else {
        panic!("{err}")
    };
    assert_eq!(timeout, DEFAULT_TIMEOUT + Duration::from_nanos(273_958_333));
}

#[tokio::test(start_paused = true)]
async fn a_damaged_answer_is_retried_when_the_line_falls_quiet_not_after_the_timeout() {
    let mut b = bench(
        twin().line(),
        vec![Trick::corrupt_last()],
        None,
        ClientConfig::default(),
    );
    let started = Instant::now();
    b.client
        .read_holding_registers(unit(2), 0x00, 18)
        .await
        .expect("answered on the second attempt");
    assert_eq!(started.elapsed(), REPLY_DELAY + MIN_QUIET_GAP + REPLY_DELAY);
    assert_eq!(b.requests(), 2);
}

#[tokio::test(start_paused = true)]
async fn damage_on_every_attempt_is_reported_as_the_last_trouble() {
    let mut b = bench(
        twin().line(),
        vec![Trick::corrupt_last(); 3],
        None,
        ClientConfig::default(),
    );
    let err = b
        .client
        .read_holding_registers(unit(2), 0x14, 4)
        .await
        .expect_err("damaged every time");
    assert!(
        matches!(
            err,
            ClientError::NoAnswer {
                attempts: 3,
                last: Trouble::Damaged(Damage::Rtu(DecodeError::Crc { .. }))
                    | Trouble::Incomplete { .. },
                ..
            }
        ),
        "{err}"
    );
}

#[tokio::test(start_paused = true)]
async fn bytes_that_look_like_a_long_frame_do_not_hold_the_answer_back() {
    let mut b = bench(
        twin().line(),
        vec![long_head()],
        None,
        ClientConfig::default(),
    );
    let started = Instant::now();
    let words = b
        .client
        .read_holding_registers(unit(2), 0x1E, 17)
        .await
        .expect("found behind the garbage");
    assert_eq!(words.len(), 17);
    // Found when the line fell quiet, on the first attempt.
    assert_eq!(started.elapsed(), REPLY_DELAY + MIN_QUIET_GAP);
    assert_eq!(b.requests(), 1);
}

#[tokio::test(start_paused = true)]
async fn an_answer_that_does_not_match_is_skipped() {
    let mut b = bench(
        twin().line(),
        vec![stray_first()],
        None,
        ClientConfig::default(),
    );
    let words = b
        .client
        .read_holding_registers(unit(2), 0x2E, 1)
        .await
        .expect("the real answer follows");
    assert_eq!(words, [crate::cross::device::PROTOCOL_REVISION]);
    assert_eq!(b.requests(), 1);
}

#[tokio::test(start_paused = true)]
async fn an_answer_from_another_unit_is_never_accepted() {
    // The answer to the read below, from unit 3 (with a good CRC).
    let wrong_unit = Trick::Replace(
        ResponseAdu {
            unit: 3,
            response: Response::ReadHoldingRegisters(
                RegisterValues::new(vec![crate::cross::device::PROTOCOL_REVISION])
                    .expect("1 value"),
            ),
        }
        .to_bytes(),
    );
    let mut b = bench(
        twin().line(),
        vec![wrong_unit; 3],
        None,
        ClientConfig::default(),
    );
    let err = b
        .client
        .read_holding_registers(unit(2), 0x2E, 1)
        .await
        .expect_err("only wrong units answered");
    assert!(
        matches!(
            err,
            ClientError::NoAnswer {
                last: Trouble::Mismatch(Mismatch::UnitId {
                    expected: 2,
                    actual: 3
                }),
                ..
            }
        ),
        "{err}"
    );
    assert_eq!(b.requests(), 3);
}

/// Time from the end of the first answer to the second request.
async fn gap_between_exchanges(settings: Option<SerialSettings>) -> Duration {
    let mut b = bench(slave().line(), vec![], settings, ClientConfig::default());
    b.client
        .read_holding_registers(unit(1), 0, 1)
        .await
        .expect("read");
    b.client
        .read_holding_registers(unit(1), 0, 1)
        .await
        .expect("read");
    let answered = b.heard_at(0) + DEFAULT_REPLY_DELAY;
    b.heard_at(1).duration_since(answered)
}

#[tokio::test(start_paused = true)]
async fn each_request_waits_3_5_character_times_after_the_last_frame() {
    let gap = gap_between_exchanges(at_9600()).await;
    let silence = Duration::from_nanos(3_645_834);
    // tokio's timers tick in milliseconds: the wait ends on the next tick.
    assert!(
        gap >= silence && gap < silence + Duration::from_millis(1),
        "{gap:?}"
    );
}

#[tokio::test(start_paused = true)]
async fn above_19200_baud_the_silence_is_1_75_ms() {
    let gap = gap_between_exchanges(Some(SerialSettings::new_8e1(38_400))).await;
    let silence = Duration::from_micros(1_750);
    assert!(
        gap >= silence && gap < silence + Duration::from_millis(1),
        "{gap:?}"
    );
}

#[tokio::test(start_paused = true)]
async fn a_line_without_a_speed_has_no_silence() {
    assert_eq!(gap_between_exchanges(None).await, Duration::ZERO);
}

#[tokio::test(start_paused = true)]
async fn a_broadcast_is_never_answered_and_the_line_stays_quiet_for_the_turnaround() {
    let server = slave();
    let mut b = bench(server.line(), vec![], at_9600(), ClientConfig::default());
    let started = Instant::now();
    let write = Broadcast(Write::SingleRegister(WriteRegister {
        address: 4,
        value: 77,
    }));
    b.client.broadcast(&write).await.expect("sent");
    assert_eq!(started.elapsed(), Duration::ZERO, "no wait for an answer");
    assert_eq!(
        b.client
            .read_holding_registers(unit(1), 4, 1)
            .await
            .expect("read"),
        [77]
    );
    assert_eq!(server.lock().counters().broadcasts, 1);
    let quiet = b.heard_at(1).duration_since(b.heard_at(0));
    // 8 bytes on the wire, the turnaround, the silence.
    let least =
        Duration::from_nanos(8_333_334) + DEFAULT_TURNAROUND + Duration::from_nanos(3_645_834);
    assert!(
        quiet >= least && quiet < least + Duration::from_millis(1),
        "{quiet:?}"
    );
}

#[tokio::test(start_paused = true)]
async fn a_dead_unit_delays_the_others_on_its_line_only_by_its_own_timeouts() {
    let cross = twin();
    let server = slave();
    let bus = wire::device::Bus(vec![Box::new(cross.line()), Box::new(server.line())]);
    let b = bench(bus, vec![], None, ClientConfig::default());
    let mut dead = b.client.clone();
    let mut alive = b.client.clone();
    let started = Instant::now();
    let dead_task = tokio::spawn(async move { dead.read_holding_registers(unit(9), 0, 1).await });
    tokio::task::yield_now().await;
    let alive_task = tokio::spawn(async move {
        let state = crate::cross::read(&mut alive, unit(2)).await;
        let first = Instant::now();
        let words = alive.read_holding_registers(unit(1), 0, 2).await;
        (state, first, words)
    });
    let dead_result = dead_task.await.expect("task ran");
    let (state, first, words) = alive_task.await.expect("task ran");
    assert!(matches!(
        dead_result,
        Err(ClientError::NoAnswer { ref device, .. }) if device == "unit 9"
    ));
    assert_eq!(state.expect("read").feed(), Feed::StaticSwitch(Source::S1));
    assert_eq!(words.expect("read"), [0, 0]);
    // The dead unit's three timeouts, then the CROSS's four reads, then one more.
    assert_eq!(
        first.duration_since(started),
        DEFAULT_TIMEOUT * 3 + REPLY_DELAY * 4
    );
    assert_eq!(Instant::now().duration_since(first), DEFAULT_REPLY_DELAY);
    // 3 attempts for the dead unit, 4 + 1 requests for the others, never interleaved.
    assert_eq!(b.requests(), 8);
}

#[tokio::test(start_paused = true)]
async fn a_closed_line_fails_at_once_naming_it() {
    let (ours, theirs) = tokio::io::duplex(64);
    drop(theirs);
    let line = SharedLine::new(Line::from_stream(ours, "gone line", None));
    let mut client = Client::new(line, ClientConfig::default());
    let err = client
        .read_holding_registers(unit(1), 0, 1)
        .await
        .expect_err("closed");
    assert!(matches!(err, ClientError::Line { .. }), "{err}");
    assert!(err.to_string().contains("gone line"), "{err}");
}

// --- Modbus TCP ---

fn over_tcp() -> ClientConfig {
    ClientConfig {
        framing: Framing::Tcp,
        ..ClientConfig::default()
    }
}

/// `device` (RTU) served over Modbus TCP, with `tricks` on its MBAP replies.
fn tcp_bench<D: Device>(device: D, tricks: Vec<Trick>) -> Bench {
    bench(
        crate::tcp::MbapServer::new(device),
        tricks,
        None,
        over_tcp(),
    )
}

/// Unit 1's answer to a read of `values.len()` holding registers, in transaction `t`.
fn registers_in(t: u16, values: Vec<u16>) -> Vec<u8> {
    Mbap {
        transaction: TransactionId(t),
        adu: ResponseAdu {
            unit: 1,
            response: Response::ReadHoldingRegisters(
                RegisterValues::new(values).expect("test values"),
            ),
        },
    }
    .to_bytes()
}

/// The transaction ids of the requests the device heard.
fn transactions(tap: &Tap) -> Vec<u16> {
    tap.traffic()
        .iter()
        .filter(|t| !t.from_device)
        .map(|t| u16::from_be_bytes([t.bytes[0], t.bytes[1]]))
        .collect()
}

#[tokio::test(start_paused = true)]
async fn every_function_reads_and_writes_a_generic_server_over_modbus_tcp() {
    let server = slave();
    let mut b = tcp_bench(server.line(), vec![]);
    let c = &mut b.client;
    c.write_single_coil(unit(1), 3, true)
        .await
        .expect("written");
    c.write_multiple_coils(unit(1), 10, &[true, false, true])
        .await
        .expect("written");
    assert_eq!(
        c.read_coils(unit(1), 2, 10).await.expect("read"),
        [
            false, true, false, false, false, false, false, false, true, false
        ]
    );
    c.write_single_register(unit(1), 100, 0xBEEF)
        .await
        .expect("written");
    c.write_multiple_registers(unit(1), 101, &[1, 2])
        .await
        .expect("written");
    assert_eq!(
        c.read_holding_registers(unit(1), 100, 3)
            .await
            .expect("read"),
        [0xBEEF, 1, 2]
    );
    server.lock().set(Table::InputRegisters, 30, 4242);
    assert_eq!(
        c.read_input_registers(unit(1), 30, 1).await.expect("read"),
        [4242]
    );
    assert_eq!(
        c.read_discrete_inputs(unit(1), 0, 2).await.expect("read"),
        [false, false]
    );
    assert_eq!(b.requests(), 8);
    assert_eq!(transactions(&b.tap), [1, 2, 3, 4, 5, 6, 7, 8]);
}

#[tokio::test(start_paused = true)]
async fn a_response_with_another_transaction_id_is_dropped_and_the_right_one_after_it_taken() {
    // A late answer to an earlier transaction, same unit and function, other values.
    let stale = Trick::Before(registers_in(0x7777, vec![0xDEAD, 0xBEEF]));
    let mut b = tcp_bench(slave().line(), vec![stale]);
    let started = Instant::now();
    let words = b
        .client
        .read_holding_registers(unit(1), 0, 2)
        .await
        .expect("the right answer follows");
    assert_eq!(words, [0, 0], "the server's registers, not the stale ones");
    assert_eq!(b.requests(), 1, "not retried");
    assert_eq!(started.elapsed(), DEFAULT_REPLY_DELAY);
}

#[tokio::test(start_paused = true)]
async fn only_responses_of_another_transaction_are_no_answer() {
    let stale = Trick::Replace(registers_in(0x7777, vec![1, 2]));
    let mut b = tcp_bench(slave().line(), vec![stale; 3]);
    let err = b
        .client
        .read_holding_registers(unit(1), 0, 2)
        .await
        .expect_err("never the right transaction");
    assert!(
        matches!(
            err,
            ClientError::NoAnswer {
                attempts: 3,
                last: Trouble::Others {
                    frames: 1,
                    from: None
                },
                ..
            }
        ),
        "{err}"
    );
    assert!(
        err.to_string()
            .ends_with("(last: no reply, only a frame that answers something else)"),
        "{err}"
    );
    assert_eq!(
        transactions(&b.tap),
        [1, 1, 1],
        "retries repeat the request"
    );
}

#[tokio::test(start_paused = true)]
async fn two_units_share_one_modbus_tcp_connection() {
    let first = SharedModel::new(Slave::all_writable(unit(1)));
    let second = SharedModel::new(Slave::all_writable(unit(2)));
    let bus = wire::device::Bus(vec![Box::new(first.line()), Box::new(second.line())]);
    let mut b = tcp_bench(bus, vec![]);
    let c = &mut b.client;
    c.write_single_register(unit(1), 5, 111)
        .await
        .expect("unit 1");
    c.write_single_register(unit(2), 5, 222)
        .await
        .expect("unit 2");
    assert_eq!(
        c.read_holding_registers(unit(1), 5, 1).await.expect("1"),
        [111]
    );
    assert_eq!(
        c.read_holding_registers(unit(2), 5, 1).await.expect("2"),
        [222]
    );
    assert_eq!(first.lock().get(Table::HoldingRegisters, 5), Some(111));
    assert_eq!(second.lock().get(Table::HoldingRegisters, 5), Some(222));
    let err = c
        .read_holding_registers(unit(3), 5, 1)
        .await
        .expect_err("nobody is unit 3");
    assert!(err.to_string().contains("unit 3"), "{err}");
}

#[tokio::test(start_paused = true)]
async fn a_half_modbus_tcp_frame_then_silence_is_retried_when_the_line_falls_quiet() {
    let whole = registers_in(1, vec![0, 0]);
    let half = Trick::Replace(whole[..9].to_vec());
    let mut b = tcp_bench(slave().line(), vec![half]);
    let started = Instant::now();
    let words = b
        .client
        .read_holding_registers(unit(1), 0, 2)
        .await
        .expect("answered on the second attempt");
    assert_eq!(words, [0, 0]);
    assert_eq!(b.requests(), 2);
    assert_eq!(
        started.elapsed(),
        DEFAULT_REPLY_DELAY + MIN_QUIET_GAP + DEFAULT_REPLY_DELAY
    );
}

#[tokio::test(start_paused = true)]
async fn a_half_modbus_tcp_frame_every_time_is_reported_as_incomplete() {
    let half = Trick::Replace(registers_in(1, vec![0, 0])[..9].to_vec());
    let mut b = tcp_bench(slave().line(), vec![half; 3]);
    let err = b
        .client
        .read_holding_registers(unit(1), 0, 2)
        .await
        .expect_err("never whole");
    assert!(
        matches!(
            err,
            ClientError::NoAnswer {
                last: Trouble::Incomplete { bytes: 9 },
                ..
            }
        ),
        "{err}"
    );
}

#[tokio::test(start_paused = true)]
async fn an_exception_over_modbus_tcp_is_the_units_refusal() {
    let map = SlaveMap::parse("unit 1\nholding 0 = 1 2 3\n").expect("valid map");
    let mut b = tcp_bench(SharedModel::new(Slave::new(map)).line(), vec![]);
    let err = b
        .client
        .read_holding_registers(unit(1), 2, 2)
        .await
        .expect_err("3 is not in the map");
    assert_eq!(
        exception_code(&err),
        Some(ExceptionCode::ILLEGAL_DATA_ADDRESS)
    );
    assert_eq!(b.requests(), 1);
}

#[tokio::test(start_paused = true)]
async fn clones_share_the_transaction_ids_which_wrap_after_65535() {
    let mut b = tcp_bench(slave().line(), vec![]);
    b.client.transaction.store(65534, Ordering::Relaxed);
    let mut clone = b.client.clone();
    b.client
        .read_coils(unit(1), 0, 1)
        .await
        .expect("transaction 65535");
    clone
        .read_coils(unit(1), 0, 1)
        .await
        .expect("transaction 0");
    b.client
        .read_coils(unit(1), 0, 1)
        .await
        .expect("transaction 1");
    assert_eq!(transactions(&b.tap), [65535, 0, 1]);
}

#[test]
fn a_modbus_tcp_endpoint_asks_for_tcp_framing() {
    let line = link::SerialSettings::new_8n1(9600);
    let mbap = Endpoint::parse("modbus-tcp://127.0.0.1:502", line).expect("valid");
    let raw = Endpoint::parse("tcp://127.0.0.1:4001", line).expect("valid");
    assert_eq!(Framing::of(&mbap), Framing::Tcp);
    assert_eq!(Framing::of(&raw), Framing::Rtu);
}

#[tokio::test(start_paused = true)]
async fn an_invalid_request_never_reaches_the_wire() {
    let mut b = bench(slave().line(), vec![], None, ClientConfig::default());
    let err = b
        .client
        .read_holding_registers(unit(1), 0, 126)
        .await
        .expect_err("126 registers is too many");
    assert!(matches!(err, ClientError::Request(_)), "{err}");
    assert!(!err.is_device_error());
    assert_eq!(err.kind(), FailureKind::Usage, "our mistake, not a refusal");
    assert_eq!(b.requests(), 0);
}
