//! The async client against the twin over an in-memory line, in paused (virtual) time: the
//! line's timing windows, retries, echo checks, and several regulators on one line.

use std::time::{Duration, Instant as StdInstant};

use link::{Line, SerialSettings, SharedLine};
use testkit::{At, Tap, Trick, Tricky};
use thermosald::client::{
    Client, ClientConfig, ClientError, DEFAULT_TIMEOUT, Probe, Trouble, probe_timeout, scan,
};
use thermosald::device::RegulatorBus;
use thermosald::diagnostic::{self, Fault};
use thermosald::exchange::{LineTiming, RELEASE_AFTER_ANSWER};
use thermosald::frame::{Address, Direction, Frame, RawValue, Target};
use thermosald::request::Read;
use thermosald::tables::{Table, runtime, settings};
use tokio::time::Instant;
use wire::device::SharedModel;
use wire::{Failure, FailureKind};

use crate::common::{addr, ms};

/// A damaged whole message: a digit of its message number turned into a letter.
fn damage() -> Trick {
    Trick::Flip {
        at: At::Start(2),
        mask: 0x40,
    }
}

/// Line noise before the answer.
fn noise() -> Trick {
    Trick::Before(b"\xFF\x00~~".to_vec())
}

/// An answer from address 7 to the same read before the answer.
fn stray_first(read: Read) -> Trick {
    let query = thermosald::Exchange::new(addr(7).into(), read.into()).expect("a valid read");
    let query = query.query();
    let stray = Frame::new(
        query.target(),
        query.message(),
        Direction::Reply,
        query.count(),
        vec![RawValue::new(123).expect("3 digits"); read.items().len()],
    )
    .expect("a valid answer");
    Trick::Before(stray.to_bytes())
}

/// One message on the simulated wire.
#[derive(Debug, Clone, Copy)]
struct Message {
    question: bool,
    start: StdInstant,
    end: StdInstant,
}

struct Bench {
    line: SharedLine,
    twin: SharedModel<RegulatorBus>,
    tap: Tap,
    pace: Option<LineTiming>,
}

impl Bench {
    /// Regulators at `addresses` behind an unpaced in-memory line (answers arrive exactly
    /// 200 ms after the question).
    fn new(addresses: &[u8], tricks: Vec<Trick>) -> Bench {
        Self::build(addresses, tricks, None)
    }

    /// The same on a 9600-baud line: the serve loop and the twin both count wire time.
    fn paced(addresses: &[u8]) -> Bench {
        Self::build(addresses, vec![], Some(SerialSettings::new_8n1(9600)))
    }

    fn build(addresses: &[u8], tricks: Vec<Trick>, pace: Option<SerialSettings>) -> Bench {
        let addresses: Vec<Address> = addresses.iter().map(|a| addr(*a)).collect();
        let timing = pace.map(|_| LineTiming::RS485_9600_8N1);
        let mut twin = RegulatorBus::new(&addresses, Instant::now().into_std()).expect("distinct");
        if let Some(timing) = timing {
            twin = twin.paced(timing);
        }
        let twin = SharedModel::new(twin);
        let device = Tricky::new(twin.line(), tricks);
        let tap = device.tap();
        let (ours, theirs) = tokio::io::duplex(1024);
        tokio::spawn(link::serve::serve_stream(theirs, device, pace));
        Bench {
            line: SharedLine::new(Line::from_stream(ours, "test line", pace)),
            twin,
            tap,
            pace: timing,
        }
    }

    fn client(&self, address: u8) -> Client {
        Client::new(self.line.clone(), ClientConfig::new(addr(address)))
    }

    fn questions(&self) -> usize {
        self.tap.requests()
    }

    fn answered(&self) -> usize {
        self.tap.replies()
    }

    fn wire(&self, len: usize) -> Duration {
        self.pace.map_or(Duration::ZERO, |t| t.wire_time(len))
    }

    /// Every message with the time it took the wire: a paced serve loop hands a question
    /// over when its last character arrived; answers sent back to back follow each other.
    fn log(&self) -> Vec<Message> {
        let mut log = Vec::new();
        let mut free = None;
        for traffic in self.tap.traffic() {
            if traffic.from_device {
                let start = free.map_or(traffic.at, |f: StdInstant| f.max(traffic.at));
                let end = start + self.wire(traffic.bytes.len());
                log.push(Message {
                    question: false,
                    start,
                    end,
                });
                free = Some(end);
            } else {
                log.push(Message {
                    question: true,
                    start: traffic.at - self.wire(traffic.bytes.len()),
                    end: traffic.at,
                });
                free = Some(traffic.at);
            }
        }
        log
    }

    /// No message starts inside the 40 ms after the end of the previous one; no question
    /// while an answer is pending.
    fn assert_line_discipline(&self) {
        let mut log = self.log();
        log.sort_by_key(|m| m.start);
        for pair in log.windows(2) {
            let (before, next) = (pair[0], pair[1]);
            if !next.question {
                continue;
            }
            assert!(
                next.start >= before.end + RELEASE_AFTER_ANSWER,
                "a question started {:?} after the end of the previous message",
                next.start.saturating_duration_since(before.end)
            );
        }
    }
}

fn item(table: Table, index: u8) -> &'static thermosald::Item {
    table.item(index).expect("the item exists")
}

#[tokio::test(start_paused = true)]
async fn a_write_then_a_read_go_through_the_regulator() {
    let b = Bench::new(&[0], vec![]);
    let mut client = b.client(0);
    let sealing = Table::Settings.find("sealing temperature").unwrap();
    let echoed = client.write(sealing, 175.0).await.expect("echoed");
    assert_eq!(echoed.to_string(), "175 °C");
    let reading = client.read_item(sealing).await.expect("answered");
    assert_eq!(reading.to_string(), "175 °C");
    assert_eq!(reading.raw(), RawValue::new(175).unwrap());
}

#[tokio::test(start_paused = true)]
async fn a_whole_table_read_gives_every_item_named_and_scaled() {
    let b = Bench::new(&[2], vec![]);
    let values = b.client(2).read_table(Table::Service).await.expect("read");
    assert_eq!(values.raw().len(), Table::Service.len());
    let width = values
        .get(item(Table::Service, 0))
        .expect("item 0 is in the table");
    assert_eq!(width.to_string(), "5.0 mm");
}

#[tokio::test(start_paused = true)]
async fn polls_follow_each_other_40_ms_after_each_answer_and_never_sooner() {
    let b = Bench::new(&[0], vec![]);
    let mut client = b.client(0);
    let started = Instant::now();
    for _ in 0..10 {
        client
            .read_item(item(Table::Runtime, runtime::TEMPERATURE))
            .await
            .expect("answered");
    }
    // Ten answers 200 ms after their questions, nine 40 ms releases in between.
    assert_eq!(started.elapsed(), ms(10 * 200 + 9 * 40));
    assert_eq!(b.questions(), 10);
    assert_eq!(b.answered(), 10);
    b.assert_line_discipline();
}

/// Asserts that `polls` polls took `elapsed`, what the line allows (`expected`): tokio's
/// timers tick in whole milliseconds, so up to 1 ms per poll on top.
fn took_what_the_line_allows(elapsed: Duration, expected: Duration, polls: u64) {
    assert!(
        elapsed >= expected && elapsed <= expected + ms(polls),
        "took {elapsed:?}, the line allows {expected:?}"
    );
}

#[tokio::test(start_paused = true)]
async fn on_a_paced_9600_baud_line_polls_run_at_the_theoretical_limit() {
    let b = Bench::paced(&[0]);
    let mut client = b.client(0);
    let timing = LineTiming::RS485_9600_8N1;
    let started = Instant::now();
    for _ in 0..4 {
        client.read_table(Table::Runtime).await.expect("answered");
    }
    // Each poll: 9-byte question, 200 ms, 30-byte answer, 40 ms release (none after the last).
    let expected = timing.poll_cycle(9, 30) * 4 - RELEASE_AFTER_ANSWER;
    took_what_the_line_allows(started.elapsed(), expected, 4);
    assert_eq!(b.answered(), 4);
    b.assert_line_discipline();
}

#[tokio::test(start_paused = true)]
async fn every_client_on_a_shared_line_respects_the_windows_the_others_opened() {
    let b = Bench::paced(&[0, 1, 2]);
    let poll = |mut client: Client| async move {
        for _ in 0..3 {
            client.read_table(Table::Runtime).await.expect("answered");
        }
    };
    let started = Instant::now();
    tokio::join!(poll(b.client(0)), poll(b.client(1)), poll(b.client(2)));
    let expected = LineTiming::RS485_9600_8N1.poll_cycle(9, 30) * 9 - RELEASE_AFTER_ANSWER;
    took_what_the_line_allows(started.elapsed(), expected, 9);
    assert_eq!(b.answered(), 9);
    b.assert_line_discipline();
}

#[tokio::test(start_paused = true)]
async fn a_lost_answer_is_retried_after_the_timeout() {
    let b = Bench::new(&[0], vec![Trick::Drop]);
    let started = Instant::now();
    b.client(0)
        .read_table(Table::Runtime)
        .await
        .expect("answered on the second attempt");
    assert_eq!(started.elapsed(), DEFAULT_TIMEOUT + ms(200));
    assert_eq!(b.questions(), 2);
    b.assert_line_discipline();
}

#[tokio::test(start_paused = true)]
async fn a_silent_address_gives_up_after_every_attempt_with_the_facts() {
    let b = Bench::new(&[0], vec![]);
    let started = Instant::now();
    let err = b
        .client(5)
        .read_table(Table::Runtime)
        .await
        .expect_err("nobody is at 5");
    assert_eq!(started.elapsed(), DEFAULT_TIMEOUT * 3);
    assert_eq!(
        err.to_string(),
        "no valid answer from regulator 5 on test line after 3 attempts of 500 ms each (last: no reply)"
    );
    assert!(matches!(
        err,
        ClientError::NoAnswer {
            attempts: 3,
            last: Trouble::Silence,
            ..
        }
    ));
    assert!(err.is_device_error());
}

#[tokio::test(start_paused = true)]
async fn a_damaged_answer_is_retried_once_the_line_is_free_without_waiting_for_the_timeout() {
    let b = Bench::new(&[0], vec![damage()]);
    let started = Instant::now();
    b.client(0)
        .read_table(Table::Settings)
        .await
        .expect("answered on the second attempt");
    // 200 ms to the damaged answer, 40 ms release, 200 ms to the good one.
    assert_eq!(started.elapsed(), ms(440));
    assert_eq!(b.questions(), 2);
    b.assert_line_discipline();
}

#[tokio::test(start_paused = true)]
async fn damage_on_every_attempt_is_reported_as_the_last_trouble() {
    let b = Bench::new(&[0], vec![damage(), damage(), damage()]);
    let err = b
        .client(0)
        .read_table(Table::Settings)
        .await
        .expect_err("damaged every time");
    assert!(
        matches!(
            err,
            ClientError::NoAnswer {
                last: Trouble::Damaged(_),
                ..
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("damaged reply"), "{err}");
}

#[tokio::test(start_paused = true)]
async fn noise_and_other_addresses_answers_are_skipped_never_taken_for_the_answer() {
    let sealing = item(Table::Settings, settings::SEALING_TEMPERATURE);
    let b = Bench::new(&[0], vec![noise(), stray_first(Read::item(sealing))]);
    let mut client = b.client(0);
    client.write(sealing, 190.0).await.expect("echoed");
    let reading = client.read_item(sealing).await.expect("answered");
    assert_eq!(reading.to_string(), "190 °C");
    assert_eq!(b.questions(), 2, "neither needed a retry");
    b.assert_line_discipline();
}

#[tokio::test(start_paused = true)]
async fn the_adapters_local_echo_of_the_question_is_not_taken_for_the_answer() {
    let b = Bench::new(&[0], vec![Trick::EchoFirst, Trick::EchoFirst]);
    let mut client = b.client(0);
    let sealing = item(Table::Settings, settings::SEALING_TEMPERATURE);
    client
        .write(sealing, 170.0)
        .await
        .expect("echoed by the regulator");
    let reading = client.read_item(sealing).await.expect("answered");
    assert_eq!(reading.to_string(), "170 °C");
    assert_eq!(b.questions(), 2, "neither needed a retry");
}

#[tokio::test(start_paused = true)]
async fn an_echo_damaged_once_on_the_line_is_retried_and_the_write_succeeds() {
    // 185 becomes 180: still a valid message, but not what the regulator said.
    let flip_digit = Trick::Flip {
        at: At::End(2),
        mask: b'5' ^ b'0',
    };
    let b = Bench::new(&[0], vec![flip_digit]);
    let sealing = item(Table::Settings, settings::SEALING_TEMPERATURE);
    b.client(0)
        .write(sealing, 185.0)
        .await
        .expect("echoed on the second attempt");
    assert_eq!(b.questions(), 2);
}

#[tokio::test(start_paused = true)]
async fn an_echo_that_differs_twice_is_reported_with_what_was_sent_and_what_came_back() {
    let b = Bench::new(&[0], vec![]);
    // 300 °C is within the item's range, but above the maximum working temperature
    // (250 °C): the regulator keeps 180 °C and echoes it.
    let sealing = item(Table::Settings, settings::SEALING_TEMPERATURE);
    let err = b
        .client(0)
        .write(sealing, 300.0)
        .await
        .expect_err("the regulator keeps its value");
    assert_eq!(
        err.to_string(),
        "echo mismatch from regulator 0 on test line: sent %012Q150300, it echoed %012R150180; \
         it kept Set sealing temperature = 180 °C, not 300 °C"
    );
    assert!(matches!(err, ClientError::Refused { .. }));
    assert_eq!(err.kind(), FailureKind::Refused);
    assert_eq!(b.questions(), 2, "retried once, then reported");
}

#[tokio::test(start_paused = true)]
async fn with_no_retries_an_echo_mismatch_is_reported_at_once() {
    let b = Bench::new(&[0], vec![]);
    let config = ClientConfig {
        retries: 0,
        ..ClientConfig::new(addr(0))
    };
    let mut client = Client::new(b.line.clone(), config);
    let sealing = item(Table::Settings, settings::SEALING_TEMPERATURE);
    let err = client.write(sealing, 300.0).await.expect_err("kept 180");
    assert!(matches!(err, ClientError::Refused { .. }), "{err}");
    assert_eq!(b.questions(), 1);
}

#[tokio::test(start_paused = true)]
async fn an_invalid_write_never_reaches_the_wire() {
    let b = Bench::new(&[0], vec![]);
    let mut client = b.client(0);
    let sealing = item(Table::Settings, settings::SEALING_TEMPERATURE);
    let err = client
        .write(sealing, 1000.0)
        .await
        .expect_err("four digits");
    assert!(matches!(err, ClientError::Request(_)), "{err}");
    assert!(!err.is_device_error());
    assert_eq!(err.kind(), FailureKind::Usage, "our mistake, not a refusal");
    let kint = Table::Machine.find("KINT gain").unwrap();
    assert!(
        client.write(kint, 12.55).await.is_err(),
        "not a step of 0.1"
    );
    let temperature = item(Table::Runtime, runtime::TEMPERATURE);
    assert!(client.write(temperature, 20.0).await.is_err(), "read-only");
    assert_eq!(b.questions(), 0);
}

#[tokio::test(start_paused = true)]
async fn a_dead_regulator_delays_the_others_by_at_most_its_own_timeout() {
    let b = Bench::new(&[0, 1], vec![]);
    let (mut dead, live0, live1) = (b.client(5), b.client(0), b.client(1));
    let dead_run = async {
        let started = Instant::now();
        let err = dead
            .read_table(Table::Runtime)
            .await
            .expect_err("no one at 5");
        assert!(matches!(err, ClientError::NoAnswer { attempts: 3, .. }));
        started.elapsed()
    };
    let poll = |mut client: Client| async move {
        let mut longest = Duration::ZERO;
        for _ in 0..6 {
            let asked = Instant::now();
            client.read_table(Table::Runtime).await.expect("alive");
            longest = longest.max(asked.elapsed());
        }
        longest
    };
    let (dead_took, longest0, longest1) = tokio::join!(dead_run, poll(live0), poll(live1));
    // Holding the line for all three attempts would delay the others by 1.5 s.
    let bound = DEFAULT_TIMEOUT + ms(240) + ms(240);
    assert!(longest0 <= bound, "regulator 0 waited {longest0:?}");
    assert!(longest1 <= bound, "regulator 1 waited {longest1:?}");
    // The dead regulator's attempts interleave with the others' polls.
    assert!(dead_took > DEFAULT_TIMEOUT * 3, "{dead_took:?}");
    assert_eq!(b.answered(), 12);
    b.assert_line_discipline();
}

#[tokio::test(start_paused = true)]
async fn clear_faults_clears_a_fault_once_its_cause_is_gone() {
    let b = Bench::new(&[0], vec![]);
    let mut client = b.client(0);
    let fault = item(Table::Runtime, runtime::FAULT);
    b.twin
        .lock()
        .regulator_mut(addr(0))
        .unwrap()
        .provoke(Fault::OpenBand, Instant::now().into_std());
    let reading = client.read_item(fault).await.unwrap();
    assert_eq!(reading.raw().get(), Fault::OpenBand.code());
    client.clear_faults().await.expect("echoed");
    assert_eq!(
        client.read_item(fault).await.unwrap().raw().get(),
        Fault::OpenBand.code(),
        "the band is still open"
    );
    b.twin
        .lock()
        .regulator_mut(addr(0))
        .unwrap()
        .remove_cause(Fault::OpenBand, Instant::now().into_std());
    client.clear_faults().await.expect("echoed");
    assert_eq!(
        client.read_item(fault).await.unwrap().raw().get(),
        diagnostic::NONE
    );
}

#[tokio::test(start_paused = true)]
async fn writes_are_volatile_until_saved_to_eeprom() {
    let b = Bench::new(&[0], vec![]);
    let mut client = b.client(0);
    let preheat = item(Table::Settings, settings::PRE_HEATING_TEMPERATURE);
    client.write(preheat, 95.0).await.unwrap();
    client.load_eeprom().await.expect("echoed");
    assert_eq!(
        client.read_item(preheat).await.unwrap().to_string(),
        "80 °C"
    );
    client.write(preheat, 95.0).await.unwrap();
    client.save_eeprom().await.expect("echoed");
    client.write(preheat, 70.0).await.unwrap();
    client.load_eeprom().await.expect("echoed");
    assert_eq!(
        client.read_item(preheat).await.unwrap().to_string(),
        "95 °C"
    );
}

#[tokio::test(start_paused = true)]
async fn after_a_master_reset_an_address_is_assigned_with_dollar_and_balancing_clears_35() {
    let b = Bench::new(&[0], vec![]);
    let mut client = b.client(0);
    let fault = item(Table::Runtime, runtime::FAULT);
    client.master_reset().await.expect("echoed");
    // No address now: the regulator answers only '$'.
    let err = client.read_item(fault).await.expect_err("no address");
    assert!(matches!(err, ClientError::NoAnswer { .. }), "{err}");

    let mut commissioning = Client::new(b.line.clone(), ClientConfig::new(Target::Assign));
    commissioning
        .set_address(addr(3))
        .await
        .expect("echoed by $");
    assert_eq!(commissioning.target(), Target::Address(addr(3)));
    let code = commissioning.read_item(fault).await.unwrap().raw().get();
    assert_eq!(code, diagnostic::CALIBRATION_REQUEST);

    commissioning.balance().await.expect("echoed");
    let code = commissioning.read_item(fault).await.unwrap().raw().get();
    assert_eq!(code, diagnostic::CALIBRATION_IN_PROGRESS);
    tokio::time::sleep(Duration::from_secs(120)).await;
    let code = commissioning.read_item(fault).await.unwrap().raw().get();
    assert_eq!(code, diagnostic::NONE, "balanced");
}

#[tokio::test(start_paused = true)]
async fn dollar_carries_only_address_assignment() {
    let b = Bench::new(&[0], vec![]);
    let mut client = Client::new(b.line.clone(), ClientConfig::new(Target::Assign));
    let err = client.clear_faults().await.expect_err("refused");
    assert!(matches!(err, ClientError::Request(_)), "{err}");
    assert_eq!(b.questions(), 0);
}

#[test]
fn a_probe_that_heard_only_line_noise_found_nobody_but_a_damaged_answer_counts() {
    let probe = |last: Trouble| Probe {
        address: Address::new(3).unwrap(),
        outcome: Err(ClientError::NoAnswer {
            endpoint: "test".into(),
            device: "regulator 3".into(),
            request: None,
            attempts: 1,
            timeout: ms(400),
            last,
        }),
    };
    assert!(!probe(Trouble::Silence).answered());
    assert!(!probe(Trouble::Noise { bytes: 12 }).answered());
    assert!(probe(Trouble::Incomplete { bytes: 12 }).answered());
}

#[tokio::test(start_paused = true)]
async fn a_scan_finds_the_regulators_with_one_attempt_per_address() {
    let b = Bench::new(&[0, 2, 5], vec![]);
    let started = Instant::now();
    let probes = scan(&b.line, None).await.expect("the line works");
    let elapsed = started.elapsed();
    let found: Vec<u8> = probes
        .iter()
        .filter(|p| p.answered())
        .map(|p| p.address.get())
        .collect();
    assert_eq!(found, [0, 2, 5]);
    assert_eq!(b.questions(), 8, "one question per address");
    // Three answers (200 ms each, then 40 ms release), five silent addresses.
    let silent = probe_timeout(&LineTiming::RS485_9600_8N1);
    assert_eq!(silent, Duration::from_nanos(421_875_000));
    let least = ms(3 * 200) + silent * 5;
    assert!(
        elapsed >= least && elapsed <= least + ms(3 * 40 + 8),
        "took {elapsed:?}"
    );
    b.assert_line_discipline();
}

/// A second line to the same regulators (another master, or the next `cellbus` run), opened
/// right after the first one's answer.
fn second_line(b: &Bench) -> Line {
    let (ours, theirs) = tokio::io::duplex(1024);
    tokio::spawn(link::serve::serve_stream(theirs, b.twin.line(), None));
    Line::from_stream(ours, "second line", None)
}

#[tokio::test(start_paused = true)]
async fn a_line_just_opened_waits_the_release_time_so_its_first_question_is_heard() {
    let b = Bench::new(&[0], vec![]);
    let temperature = item(Table::Runtime, runtime::TEMPERATURE);
    b.client(0).read_item(temperature).await.expect("answered");

    // Without the quiet time, the question falls inside the regulator's 40 ms release and is
    // ignored: it costs a whole timeout.
    let hasty = SharedLine::new(second_line(&b));
    let started = Instant::now();
    Client::new(hasty, ClientConfig::new(addr(0)))
        .read_item(temperature)
        .await
        .expect("answered on the retry");
    assert_eq!(started.elapsed(), DEFAULT_TIMEOUT + ms(200));

    let mut line = second_line(&b);
    thermosald::client::quiet_after_open(&mut line);
    let started = Instant::now();
    Client::new(SharedLine::new(line), ClientConfig::new(addr(0)))
        .read_item(temperature)
        .await
        .expect("answered at once");
    assert_eq!(
        started.elapsed(),
        thermosald::client::QUIET_AFTER_OPEN + ms(200)
    );
}
