//! Station model tests: every refusal, the physics over explicit time, resets, counters.

use std::time::{Duration, Instant};

use wire::device::{Model, SharedModel};
use wire::{Codec, Device, Transmit};

use super::*;
use crate::code::{Port, Reading, interpret};
use crate::message::{Match, Request, match_reply};

const P: Port = Port::One;
const TO_STATION: Route = Route {
    source: Address::ROBOT,
    target: Address::STATION,
};

fn secs(s: u64) -> Duration {
    Duration::from_secs(s)
}

/// A station and a clock that only moves when the test says.
struct Bench {
    station: Station,
    t0: Instant,
    now: Instant,
}

impl Bench {
    fn new(config: StationConfig) -> Bench {
        let t0 = Instant::now();
        let mut station = Station::new(config);
        station.advance(t0);
        Bench {
            station,
            t0,
            now: t0,
        }
    }

    fn factory() -> Bench {
        Bench::new(StationConfig::default())
    }

    fn wait(&mut self, d: Duration) {
        self.now += d;
        self.station.advance(self.now);
    }

    fn route(&self) -> Option<Route> {
        self.station.address().map(|a| Route {
            source: Address::ROBOT,
            target: a,
        })
    }

    /// Sends `request` as the client would and returns what the reply means for it.
    fn ask(&mut self, request: Request) -> Match {
        let frame = request.to_frame(self.route());
        match self.station.reply_to(Ok(frame), self.now) {
            Some(reply) => match_reply(&request, self.route(), &reply),
            None => panic!("no reply to {request}"),
        }
    }

    fn read(&mut self, code: Code) -> Reading {
        match self.ask(Request::read(code).expect("readable")) {
            Match::Answer(Some(data)) => interpret(code, &data).expect("meaningful data"),
            other => panic!("read {code}: {other:?}"),
        }
    }

    fn read_number(&mut self, code: Code) -> i32 {
        match self.read(code).value() {
            crate::code::Value::Number(n) => n,
            other => panic!("{code}: {other:?}"),
        }
    }

    fn write(&mut self, code: Code, value: i32) -> Match {
        self.ask(Request::write(code, value).expect("a valid request"))
    }

    /// Sends raw bytes through a line to the model and returns what it sends back.
    fn bytes(&mut self, bytes: &[u8]) -> Vec<Transmit> {
        let mut out = Vec::new();
        let mut deframer = wire::Deframer::new(self.station.codec());
        deframer.push(bytes);
        while let Some(input) = deframer.next_frame() {
            out.extend(self.station.handle(input, self.now));
        }
        out
    }
}

fn decode_one(tx: &Transmit) -> Frame {
    match FrameCodec.decode(&tx.bytes) {
        Ok(Some((frame, len))) if len == tx.bytes.len() => frame,
        other => panic!("not one frame: {other:?} from {:?}", tx.bytes),
    }
}

fn raw(text: &str) -> RawCode {
    text.parse().expect("three printable characters")
}

fn request_frame(route: Option<Route>, header: Header, code: &str, data: Option<Data>) -> Frame {
    Frame {
        route,
        header,
        code: raw(code),
        data,
    }
}

// ---- answers -----------------------------------------------------------------------------

#[test]
fn station_answers_a_read_with_its_address_as_source_and_the_robots_as_target() {
    let mut b = Bench::factory();
    let tx = b.bytes(b"\x020001RST1\x03\x64");
    assert_eq!(tx.len(), 1);
    assert_eq!(tx[0].delay, REPLY_DELAY);
    // specs/README.md: `STX 01 00 A ST1 00350 ETX BCC`.
    assert_eq!(tx[0].bytes, b"\x020100AST100350\x03\x41");
}

#[test]
fn station_answers_the_robot_at_whatever_address_it_uses() {
    let mut b = Bench::factory();
    let robot = Address::new(42).unwrap();
    let frame = request_frame(
        Some(Route {
            source: robot,
            target: Address::STATION,
        }),
        Header::Read,
        "CT1",
        None,
    );
    let reply = b.station.reply_to(Ok(frame), b.now).expect("a reply");
    assert_eq!(
        reply.route,
        Some(Route {
            source: Address::STATION,
            target: robot
        })
    );
}

#[test]
fn station_without_address_answers_without_address() {
    let mut b = Bench::new(StationConfig {
        address: None,
        ..StationConfig::default()
    });
    let tx = b.bytes(b"\x02RST1\x03\x65");
    assert_eq!(tx.iter().map(decode_one).collect::<Vec<_>>().len(), 1);
    assert_eq!(tx[0].bytes, b"\x02AST100350\x03\x40");
}

#[test]
fn station_model_reads_blank_padded_jtse() {
    let mut b = Bench::factory();
    let tx = b.bytes(b"\x020001RSMN\x03\x02");
    assert_eq!(tx[0].bytes, b"\x020100ASMN JTSE\x03\x39");
    assert_eq!(b.read(Code::StationModel), Reading::Model("JTSE".into()));
}

#[test]
fn writes_are_acknowledged_without_data_and_read_back() {
    let mut b = Bench::factory();
    let tx = b.bytes(b"\x020001WST100375\x03\x50");
    assert_eq!(tx[0].bytes, b"\x020100AST1\x03\x77");
    assert_eq!(b.read_number(Code::SelectAirTemp(P)), 375);
    assert_eq!(
        b.write(Code::AdjustTemp(P, Tool::Jt), -50),
        Match::Answer(None)
    );
    assert_eq!(b.read_number(Code::AdjustTemp(P, Tool::Jt)), -50);
    assert_eq!(b.read_number(Code::AdjustTemp(P, Tool::Te)), 0);
    assert_eq!(b.write(Code::WorkMode(P), 1), Match::Answer(None));
    assert_eq!(
        b.read(Code::WorkMode(P)).to_string(),
        "Profile mode (profiles on)"
    );
}

#[test]
fn every_readable_code_answers_meaningful_data() {
    let mut b = Bench::factory();
    for code in Code::all().into_iter().filter(|c| c.readable()) {
        let reading = b.read(code);
        assert!(!reading.to_string().is_empty(), "{code}");
    }
}

#[test]
fn a_shared_model_serves_lines_with_their_own_half_frames() {
    let model = SharedModel::new(Station::new(StationConfig::default()));
    let (mut a, mut c) = (model.line(), model.line());
    let now = Instant::now();
    assert!(a.receive(b"\x020001RS", now).is_empty());
    assert!(c.receive(b"\x020001WST1", now).is_empty());
    assert_eq!(
        a.receive(b"T1\x03\x64", now)[0].bytes,
        b"\x020100AST100350\x03\x41"
    );
    assert_eq!(
        c.receive(b"00375\x03\x50", now)[0].bytes,
        b"\x020100AST1\x03\x77"
    );
    assert_eq!(model.lock().settings().air_temp, 375);
}

// ---- refusals ----------------------------------------------------------------------------

#[test]
fn robot_mode_off_refuses_every_command_with_nak_5() {
    let mut b = Bench::new(StationConfig {
        robot_mode: false,
        ..StationConfig::default()
    });
    for code in Code::all() {
        let request = if code.readable() {
            Request::read(code)
        } else {
            Request::write(code, 0)
        };
        assert_eq!(
            b.ask(request.unwrap()),
            Match::Refused(NakReason::NotInRobotMode),
            "{code}"
        );
    }
    b.station.set_robot_mode(true);
    assert_eq!(b.read_number(Code::SelectAirTemp(P)), 350);
}

#[test]
fn unknown_codes_and_other_ports_get_nak_4_echoing_the_code() {
    let mut b = Bench::factory();
    let tx = b.bytes(b"\x020001RST3\x03\x66");
    assert_eq!(tx[0].bytes, b"\x020100NST300004\x03\x4e");
    for code in ["XYZ", "PP3", "A10", "A13", "st1", "A21"] {
        let reply = b.station.reply_to(
            Ok(request_frame(Some(TO_STATION), Header::Read, code, None)),
            b.now,
        );
        let reply = reply.expect("a NAK");
        assert_eq!(
            (
                reply.header,
                reply.code,
                reply.data.and_then(|d| d.as_number())
            ),
            (Header::Nak, raw(code), Some(4))
        );
    }
}

#[test]
fn reading_an_action_or_writing_a_measurement_gets_nak_4() {
    let mut b = Bench::factory();
    let read_reset = request_frame(Some(TO_STATION), Header::Read, "RSP", None);
    let reply = b.station.reply_to(Ok(read_reset), b.now).unwrap();
    assert_eq!(
        reply.data.and_then(|d| d.as_number()),
        Some(NakReason::CONTROL_CODE)
    );
    for code in [
        "AT1", "ET1", "PP1", "PE1", "CT1", "SMN", "SER", "OH1", "WH1", "TC1", "SC1",
    ] {
        let write = request_frame(
            Some(TO_STATION),
            Header::Write,
            code,
            Some(Data::number(1).unwrap()),
        );
        let reply = b.station.reply_to(Ok(write), b.now).unwrap();
        assert_eq!(
            (reply.header, reply.data.and_then(|d| d.as_number())),
            (Header::Nak, Some(4)),
            "{code}"
        );
    }
}

#[test]
fn writes_outside_the_limits_get_nak_3_and_change_nothing() {
    let mut b = Bench::factory();
    let refused = Match::Refused(NakReason::OutOfRange);
    assert_eq!(b.write(Code::SelectAirTemp(P), 451), refused);
    assert_eq!(b.write(Code::SelectAirTemp(P), 149), refused);
    assert_eq!(b.write(Code::SelectAirTemp(P), -50), refused);
    assert_eq!(b.write(Code::SelectAirFlow(P), 101), refused);
    assert_eq!(b.write(Code::SelectAirFlow(P), 9), refused);
    assert_eq!(b.write(Code::SelectExternalTemp(P), 351), refused);
    assert_eq!(b.write(Code::AdjustTemp(P, Tool::Te), 51), refused);
    assert_eq!(b.write(Code::MaxAirTemp, 451), refused);
    assert_eq!(b.write(Code::MinAirTemp, 149), refused);
    assert_eq!(b.settings(), Settings::FACTORY);
    // The limits move the selection's range.
    assert_eq!(b.write(Code::MaxAirTemp, 300), Match::Answer(None));
    assert_eq!(
        b.read_number(Code::SelectAirTemp(P)),
        300,
        "selection pulled under the new maximum"
    );
    assert_eq!(b.write(Code::SelectAirTemp(P), 301), refused);
    assert_eq!(
        b.write(Code::MinAirTemp, 301),
        refused,
        "minimum above maximum"
    );
    assert_eq!(b.write(Code::MinAirFlow, 40), Match::Answer(None));
    assert_eq!(b.write(Code::SelectAirFlow(P), 39), refused);
    assert_eq!(
        b.write(Code::MaxAirFlow, 39),
        refused,
        "maximum below minimum"
    );
}

#[test]
fn port_status_takes_only_0_and_1_on_the_wire() {
    let mut b = Bench::factory();
    for value in [10, 100, 111, 2] {
        let frame = request_frame(
            Some(TO_STATION),
            Header::Write,
            "PS1",
            Some(Data::number(value).unwrap()),
        );
        let reply = b.station.reply_to(Ok(frame), b.now).unwrap();
        assert_eq!(reply.data.and_then(|d| d.as_number()), Some(3), "{value}");
    }
    let frame = request_frame(
        Some(TO_STATION),
        Header::Write,
        "WM1",
        Some(Data::number(2).unwrap()),
    );
    assert_eq!(
        b.station
            .reply_to(Ok(frame), b.now)
            .unwrap()
            .data
            .and_then(|d| d.as_number()),
        Some(3)
    );
}

#[test]
fn a_frame_with_a_bad_bcc_gets_nak_1() {
    let mut b = Bench::factory();
    let tx = b.bytes(b"\x020001RST1\x03\x65");
    assert_eq!(tx[0].bytes, b"\x020100NST100001\x03\x49");
}

#[test]
fn frames_of_the_wrong_format_get_nak_2() {
    let mut b = Bench::factory();
    let nak2 = |tx: Vec<Transmit>| {
        let f = decode_one(&tx[0]);
        (f.header, f.data.and_then(|d| d.as_number()))
    };
    // 15 bytes: the data lost a digit.
    assert_eq!(
        nak2(b.bytes(&framed(b"0001WST10035"))),
        (Header::Nak, Some(2))
    );
    // An unknown header.
    assert_eq!(nak2(b.bytes(&framed(b"0001XST1"))), (Header::Nak, Some(2)));
    // Data that is not printable.
    assert_eq!(
        nak2(b.bytes(&framed(b"0001WST100\x0150"))),
        (Header::Nak, Some(2))
    );
    // A read with data, a write without.
    assert_eq!(
        nak2(b.bytes(&framed(b"0001RST100350"))),
        (Header::Nak, Some(2))
    );
    assert_eq!(nak2(b.bytes(&framed(b"0001WST1"))), (Header::Nak, Some(2)));
    // A write whose data is not a number.
    assert_eq!(
        nak2(b.bytes(&framed(b"0001WST1  350"))),
        (Header::Nak, Some(2))
    );
}

#[test]
fn format_errors_come_before_robot_mode() {
    let mut b = Bench::new(StationConfig {
        robot_mode: false,
        ..StationConfig::default()
    });
    let tx = b.bytes(b"\x020001RST1\x03\x65");
    assert_eq!(decode_one(&tx[0]).data.and_then(|d| d.as_number()), Some(1));
}

#[test]
fn frames_for_another_address_get_silence() {
    let mut b = Bench::factory();
    assert!(b.bytes(&framed(b"0002RST1")).is_empty());
    // Even a damaged one.
    let mut damaged = framed(b"0002RST1");
    let last = damaged.len() - 1;
    damaged[last] ^= 0x10;
    assert!(b.bytes(&damaged).is_empty());
    // And a damaged frame whose address cannot be read.
    assert!(b.bytes(&framed(b"0?01RST1")).is_empty());
}

#[test]
fn noise_and_broken_off_frames_get_silence() {
    let mut b = Bench::factory();
    assert!(b.bytes(b"hello\x03\xff").is_empty());
    assert!(b.bytes(b"\x020001RS\x02").is_empty());
    assert!(
        b.bytes(&framed(b"RS\x00\x01")).is_empty(),
        "no printable code to echo"
    );
}

#[test]
fn an_addressed_station_ignores_frames_without_address() {
    let mut b = Bench::factory();
    assert!(b.bytes(b"\x02RST1\x03\x65").is_empty());
}

#[test]
fn a_station_without_address_refuses_addressed_frames_with_nak_2() {
    let mut b = Bench::new(StationConfig {
        address: None,
        ..StationConfig::default()
    });
    let tx = b.bytes(b"\x020001RST1\x03\x64");
    let reply = decode_one(&tx[0]);
    assert_eq!(reply.route, None);
    assert_eq!(
        (
            reply.header,
            reply.code,
            reply.data.and_then(|d| d.as_number())
        ),
        (Header::Nak, raw("ST1"), Some(2))
    );
}

#[test]
fn a_station_never_answers_an_answer() {
    let mut b = Bench::factory();
    assert!(b.bytes(&framed(b"0001AST100350")).is_empty());
    assert!(b.bytes(&framed(b"0001NST100004")).is_empty());
}

// ---- resets ------------------------------------------------------------------------------

#[test]
fn reset_parameters_restores_factory_values() {
    let mut b = Bench::factory();
    for (code, value) in [
        (Code::MaxAirTemp, 400),
        (Code::SelectAirTemp(P), 220),
        (Code::SelectAirFlow(P), 80),
        (Code::SelectExternalTemp(P), 100),
        (Code::AdjustTemp(P, Tool::Jt), 12),
        (Code::WorkMode(P), 1),
        (Code::MinExternalTemp, 90),
    ] {
        assert_eq!(b.write(code, value), Match::Answer(None), "{code}");
    }
    assert_ne!(b.settings(), Settings::FACTORY);
    assert_eq!(b.write(Code::ResetParameters, 0), Match::Answer(None));
    assert_eq!(b.settings(), Settings::FACTORY);
    assert_eq!(b.read_number(Code::SelectAirTemp(P)), 350);
    assert_eq!(b.read_number(Code::MaxAirTemp), 450);
}

#[test]
fn reset_settings_restores_limits_and_work_mode_and_keeps_selections() {
    let mut b = Bench::factory();
    b.write(Code::SelectAirTemp(P), 220);
    b.write(Code::AdjustTemp(P, Tool::Te), -7);
    b.write(Code::MaxAirTemp, 300);
    b.write(Code::MinAirFlow, 30);
    b.write(Code::WorkMode(P), 1);
    assert_eq!(b.write(Code::ResetSettings, 0), Match::Answer(None));
    let s = b.settings();
    assert_eq!(
        (s.max_air_temp, s.min_air_flow, s.work_mode),
        (450, 10, WorkMode::Manual)
    );
    assert_eq!((s.air_temp, s.adjust_te), (220, -7));
}

#[test]
fn resets_keep_the_tool_state_and_the_counters() {
    let mut b = Bench::factory();
    b.write(Code::PortStatus(P), 1);
    b.wait(secs(3 * 3600));
    b.write(Code::ResetParameters, 0);
    b.write(Code::ResetSettings, 0);
    assert!(b.station.port_status().tool_on);
    assert_eq!(b.station.counters().work_hours, 3);
}

// ---- physics -----------------------------------------------------------------------------

#[test]
fn the_tool_heats_to_the_set_point_in_about_half_a_minute() {
    let mut b = Bench::factory();
    assert_eq!(b.read_number(Code::AirTemp(P)), 25);
    assert_eq!(b.read_number(Code::PortPower(P)), 0);
    assert_eq!(b.write(Code::PortStatus(P), 1), Match::Answer(None));
    assert_eq!(
        b.read_number(Code::PortPower(P)),
        1000,
        "full power far from the set point"
    );
    b.wait(secs(2));
    let early = b.read_number(Code::AirTemp(P));
    assert!((100..300).contains(&early), "after 2 s: {early} °C");
    b.wait(secs(8));
    let later = b.read_number(Code::AirTemp(P));
    assert!(later > early && later < 350, "after 10 s: {later} °C");
    b.wait(secs(20));
    let settled = b.read_number(Code::AirTemp(P));
    assert!((348..=350).contains(&settled), "after 30 s: {settled} °C");
    let holding = b.read_number(Code::PortPower(P));
    assert!((200..700).contains(&holding), "holding power {holding} ‰");
    assert_eq!(
        b.read(Code::PortStatus(P)).to_string(),
        "tool on, cooling off, suction off"
    );
}

#[test]
fn the_adjust_temperature_offsets_where_the_air_settles() {
    let mut b = Bench::factory();
    b.write(Code::AdjustTemp(P, Tool::Jt), 20);
    b.write(Code::SelectAirTemp(P), 300);
    b.write(Code::PortStatus(P), 1);
    b.wait(secs(120));
    assert_eq!(b.read_number(Code::AirTemp(P)), 320);
}

#[test]
fn the_board_follows_the_air_more_slowly_and_stays_below_it() {
    let mut b = Bench::factory();
    b.write(Code::PortStatus(P), 1);
    b.wait(secs(10));
    let (air, board) = (
        b.read_number(Code::AirTemp(P)),
        b.read_number(Code::ExternalTemp(P)),
    );
    assert!(
        board < air - 100,
        "after 10 s: air {air} °C, board {board} °C"
    );
    b.wait(secs(600));
    let board = b.read_number(Code::ExternalTemp(P));
    // 50 % flow: the board reaches 70 % of the air's rise over ambient.
    assert_eq!(board, 25 + (0.7f64 * 325.0).round() as i32);
}

#[test]
fn turning_the_tool_off_cools_with_the_pump_until_below_100_degrees() {
    let mut b = Bench::factory();
    b.write(Code::PortStatus(P), 1);
    b.wait(secs(60));
    b.write(Code::PortStatus(P), 0);
    assert_eq!(
        b.read(Code::PortStatus(P)).to_string(),
        "tool off, cooling on, suction off"
    );
    assert_eq!(b.read_number(Code::PortPower(P)), 0);
    let mut cooled_after = None;
    for s in 1..=120 {
        b.wait(secs(1));
        if !b.station.port_status().cooling {
            cooled_after = Some(s);
            break;
        }
    }
    let cooled_after = cooled_after.expect("cooling ends within two minutes");
    assert!(
        (10..=30).contains(&cooled_after),
        "cooling took {cooled_after} s"
    );
    let air = b.read_number(Code::AirTemp(P));
    assert!(
        (95..100).contains(&air),
        "cooling stops just under 100 °C: {air}"
    );
    b.wait(secs(3600));
    assert_eq!(b.read_number(Code::AirTemp(P)), 25);
    assert_eq!(b.read_number(Code::ExternalTemp(P)), 25);
}

#[test]
fn an_earlier_now_is_ignored() {
    let mut b = Bench::factory();
    b.write(Code::PortStatus(P), 1);
    b.wait(secs(5));
    let air = b.station.air_temperature(b.now);
    assert_eq!(b.station.air_temperature(b.t0), air);
    assert_eq!(b.station.air_temperature(b.now - secs(1)), air);
}

#[test]
fn integration_does_not_depend_on_how_often_the_model_is_asked() {
    let mut once = Bench::factory();
    let mut often = Bench::factory();
    for b in [&mut once, &mut often] {
        b.write(Code::PortStatus(P), 1);
    }
    once.wait(Duration::from_millis(7300));
    for _ in 0..73 {
        often.wait(Duration::from_millis(100));
    }
    let (a, c) = (
        once.station.air_temperature(once.now),
        often.station.air_temperature(often.now),
    );
    assert!((a - c).abs() < 0.5, "{a} vs {c}");
}

#[test]
fn counters_advance_over_simulated_hours() {
    let mut b = Bench::factory();
    b.wait(secs(2 * 3600));
    b.write(Code::PortStatus(P), 1);
    b.wait(secs(5 * 3600 + 1800));
    b.write(Code::PortStatus(P), 0);
    b.write(Code::PortStatus(P), 1);
    b.write(Code::PortStatus(P), 1); // already on: not a new cycle
    b.wait(secs(1800));
    b.station.set_suction(true);
    b.station.set_suction(true);
    b.station.set_suction(false);
    b.station.set_suction(true);
    assert_eq!(b.read_number(Code::PluggedHours(P)), 8);
    assert_eq!(b.read_number(Code::WorkHours(P)), 6);
    assert_eq!(b.read(Code::ToolCycles(P)).to_string(), "2 cycles");
    assert_eq!(b.read_number(Code::SuctionCycles(P)), 2);
    assert_eq!(b.read(Code::WorkHours(P)).to_string(), "6 h");
    assert!(b.station.port_status().suction);
}

#[test]
fn a_year_of_idle_time_is_cheap_and_counts_plugged_hours() {
    let mut b = Bench::factory();
    for _ in 0..365 {
        b.wait(secs(24 * 3600));
    }
    assert_eq!(b.station.counters().plugged_hours, 365 * 24);
    assert_eq!(b.station.counters().work_hours, 0);
}

// ---- faults ------------------------------------------------------------------------------

#[test]
fn a_disconnected_tool_reads_no_tool_and_does_not_heat() {
    let mut b = Bench::factory();
    b.station.disconnect_tool();
    assert_eq!(b.read(Code::ConnectedTool(P)), Reading::Tool(Tool::None));
    assert_eq!(b.read(Code::PortError(P)).to_string(), "No tool (9)");
    b.write(Code::PortStatus(P), 1);
    b.wait(secs(60));
    assert_eq!(b.read_number(Code::AirTemp(P)), 25);
    assert_eq!(b.read_number(Code::PortPower(P)), 0);
    assert_eq!(b.read_number(Code::ToolCycles(P)), 0, "no tool, no cycle");
    b.station.connect_tool(Tool::Te);
    assert_eq!(b.read(Code::ConnectedTool(P)).to_string(), "TE");
    assert_eq!(b.read(Code::PortError(P)).to_string(), "OK (0)");
    b.wait(secs(60));
    assert!(
        b.read_number(Code::AirTemp(P)) > 300,
        "the tool heats once plugged in"
    );
}

#[test]
fn a_tool_error_is_reported_and_stops_the_heater() {
    let mut b = Bench::factory();
    b.write(Code::PortStatus(P), 1);
    b.wait(secs(60));
    b.station.set_tool_error(ToolError::HeaterMalfunction);
    assert_eq!(
        b.read(Code::PortError(P)),
        Reading::ToolError(ToolError::HeaterMalfunction)
    );
    assert_eq!(b.read_number(Code::PortPower(P)), 0);
    b.wait(secs(120));
    assert!(b.read_number(Code::AirTemp(P)) < 100);
}

#[test]
fn a_station_error_is_reported_and_stops_the_heater() {
    let mut b = Bench::factory();
    b.station.set_station_error(StationError::MainsFrequency);
    assert_eq!(
        b.read(Code::StationError).to_string(),
        "Mains frequency (4)"
    );
    b.write(Code::PortStatus(P), 1);
    b.wait(secs(30));
    assert_eq!(b.read_number(Code::AirTemp(P)), 25);
    b.station.set_station_error(StationError::Ok);
    b.wait(secs(30));
    assert!(b.read_number(Code::AirTemp(P)) > 300);
}

// ---- helpers -----------------------------------------------------------------------------

impl Bench {
    fn settings(&self) -> Settings {
        *self.station.settings()
    }
}

fn framed(body: &[u8]) -> Vec<u8> {
    let mut out = vec![crate::frame::STX];
    out.extend_from_slice(body);
    out.push(crate::frame::ETX);
    let bcc = out.iter().fold(0u8, |acc, b| acc ^ b);
    out.push(bcc);
    out
}
