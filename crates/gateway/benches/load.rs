//! Gateway load benchmark: N simulated devices over M lines, polled by the real gateway at
//! the drivers' periods; prints polls, points and history rows per second, the poll
//! periods achieved, the gateway's CPU share and its peak memory.
//!
//! ```text
//! cargo bench -p gateway --bench load                                   # 100 devices, 10 lines, 10 s
//! nice cargo bench -p gateway --bench load -- --devices 1000 --lines 50 --seconds 60
//! nice cargo bench -p gateway --bench load -- --devices 1000 --lines 50 --seconds 60 --mqtt
//! cargo bench -p gateway --bench load -- --mix modbus=1 --devices 1000 --lines 50 --seconds 30
//! cargo bench -p gateway --bench load -- --help                         # every option
//! ```
//!
//! # How it runs
//!
//! - **Two processes.** The bench re-executes itself with `--simulators`: that child process
//!   runs every simulated device, one TCP listener on 127.0.0.1 per line (a PTY per
//!   serial line with `--serial`). The parent runs the gateway exactly as `cellbus serve
//!   --config` does: a generated `cell.toml` (checked by [`gateway::check_config`]),
//!   [`Gateway::start`] on a multi-threaded tokio runtime like the CLI's, the real
//!   scheduler, drivers, protocol clients and lines (`tcp://`, or `serial://`), the
//!   SQLite history in a temporary directory, the HTTP server listening on a free port. So
//!   the CPU share and peak RSS printed for the gateway are the gateway's own: this bench's
//!   sampler, which reads the point timestamps ten times a second, runs on a thread whose
//!   CPU time is left out (its few kB of memory are in); the simulators' figures are
//!   printed apart. Both processes share the machine's cores.
//! - **Lines are multi-drop buses.** Each line is one TCP endpoint behind which a [`Bus`]
//!   hands every byte to all the stations on that line (each with its own deframer, as on
//!   a real RS-485 line where every device hears everything); only the addressed station
//!   answers (the station model is silent to frames for other addresses). The gateway
//!   polls the stations of a line in turn over one connection, as it would a real bus.
//!   Real JBC stations are RS-232, one per port: here they stand in for a multi-drop
//!   device with a JTSE's points. Thermosald regulators (`--mix thermosald=1`, addresses
//!   0–7, at most 8 a line) and CROSS switches (`--mix cross=1`, JBUS units 1, 2, …) are
//!   multi-drop RS-485 devices: their lines are buses of their twins
//!   ([`thermosald::device::RegulatorBus`], [`jbus::cross::device::CrossTwin`]).
//! - **Serial ports** (`--serial`). The serial kinds' lines (JBC, Thermosald, CROSS) are
//!   pseudo-terminals instead: the simulator process creates one per line
//!   ([`link::serve::Pty`]) and serves the line's bus on its master end; the gateway
//!   opens the other end as `serial://`, through tokio-serial, as it would a port of a
//!   multi-port serial card: the serial path (the port's settings, the kernel's tty layer)
//!   under load. The `cost` line's kernel time is
//!   then the gateway's reads and writes on ttys instead of on sockets.
//! - **Modbus lines** (`--mix modbus=1`) are Modbus TCP gateways: one `modbus-tcp://`
//!   listener per line, a [`jbus::tcp::MbapServer`] in front of a bus of generic Modbus
//!   servers ([`jbus::slave::Slave`], units 1, 2, …), so the gateway polls every unit of
//!   the line over one connection, one request at a time, as behind a Moxa MGate. Each
//!   device has 100 `float32` input registers (0, 2, … 198, word order CDAB), named in a
//!   register list every device shares (`registers_csv`), which the gateway plans into two
//!   reads (of at most 125 registers) per poll of its 1 s `live` group. Its process moves
//!   15 of its 100 points a second (each point every 6.7 s, a small random step): 15 %.
//!   `--baud` does not pace Modbus TCP lines.
//! - **Timing.** By default the lines are not paced (a serial server at loopback speed) and
//!   the stations answer after [`DEFAULT_REPLY_DELAY`] instead of the model's 5 ms, so that
//!   20 stations fit on one line at the driver's periods (live 1 s, settings 10 s, info
//!   60 s: about ten reads per station per second). `--baud 19200 --reply-delay 5ms` gives
//!   a JTSE's real wire timing; a line then carries only about four stations at those
//!   periods, and the report shows the periods the scheduler could keep. A Thermosald
//!   regulator answers 200 ms after each question and the line is quiet 40 ms after it
//!   (the protocol's timing, kept by the client and the twin whatever `--reply-delay`
//!   says): about four exchanges a second a line, one per regulator and table read. Six
//!   regulators a line keep the driver's 2 s live period; eight do about 80 % of the live
//!   polls due. A CROSS switch answers
//!   after `--reply-delay` (its model's own is 5 ms); its driver reads it in four requests
//!   a second (live) and more once a minute (ratings).
//! - **A working cell.** An operator script in the simulator process works every station
//!   (set points, tool on and off, the suction pedal, an occasional air-flow fault), each
//!   on its own phase, so temperatures move and the history grows as in production; the
//!   Modbus devices' values drift (above); the regulators seal at their own rhythms (3 to
//!   4 s); each CROSS loses source 1 for 40 s of every 2 minutes (an outage, then an
//!   undervoltage) and transfers to source 2 and back.
//! - **Measured** over `--seconds` after `--warmup` (connections, first reads of every
//!   group): counters from the gateway's own metrics ([`gateway::metrics::Metrics`]) and
//!   history writer ([`gateway::store::StoreStats`]); CPU time (user + system) from
//!   `/proc/PID/stat` over wall time; peak RSS from `VmHWM` in `/proc/PID/status`. The
//!   `cost` line divides the gateway's CPU time by the polls done, the points read good and
//!   the value changes stored: the whole cost of a poll from the scheduler to the history
//!   commit (line I/O, drivers, live state, change stream, history writer), per protocol
//!   when the mix has one kind (`--mix jbc=1`, `--mix cross=1`, …), and splits a point's
//!   cost into user and kernel time (the kernel's includes what loopback TCP does for the
//!   simulators' sockets inside the gateway's sends).
//! - **Heavy GETs.** After the window, while the cell is still polled, `/metrics`, the full
//!   `/api/devices`, two filtered listings and `/healthz` are each fetched five times over
//!   fresh connections, time to the last byte: the report gives the first, the median and
//!   the fastest.
//! - **Heap profiles.** `--no-scrapes` leaves out the timed GETs after the window (a full
//!   `/api/devices` builds megabytes), so a heap profiler's peak is the polling's:
//!   `heaptrack target/release/deps/load-* --bench --devices 1000 --lines 50 --seconds 20
//!   --no-scrapes` (the simulator process is started without the profiler's preload).
//!
//! # Adding device kinds
//!
//! The device mix is `--mix jbc=1` (weights per line). A kind is one [`Kind`] variant with
//! its arms in [`Kind::parse`], [`Kind::protocol`], [`Kind::max_per_line`],
//! [`Kind::framing`], [`Kind::scheme`] and [`simulate_line`] (its
//! simulator models behind the bus, and their operator); [`config_text`] for keys of its
//! own. A Panasonic machine (`--mix panasonic=1`) is not a device on a bus: its twin
//! ([`panasonic::server::TwinServer`]) listens on two ports of its own (commands, R
//! messages), one machine a line, served by `simulate_machine`; the simulator process
//! prints the event port after the line's endpoint, and the config names it
//! (`event_port`). Its operator starts a run, lets a feeder run out and clears the error
//! stop, 85 s a round.
//!
//! # MQTT
//!
//! With `--mqtt` the gateway also publishes the cell as a Sparkplug B edge node
//! (`--mqtt URL` of `cellbus serve`, edge node `loadbench`) to a mosquitto the bench
//! starts on a free loopback port (testkit's), and a third process (the bench again, with
//! `--mqtt-counter PORT`: `support/mqtt_counter.rs`) subscribes to `spBv1.0/#`, decodes
//! every payload (prost) and counts messages and metrics. The broker and the subscriber
//! are processes of their own, so the gateway's CPU share is still its own: the cost of
//! publishing is the difference between a run with `--mqtt` and one without. The report
//! adds the messages the gateway handed to its client (`cellbus_mqtt_published`), the
//! messages and metrics the subscriber received, both processes' CPU, and after the
//! stop the totals published and received (a difference is a message lost, e.g. dropped
//! by mosquitto for a slow subscriber; its `$SYS` dropped count is printed too).
//! `--live-period 200ms` polls the live group faster than the driver's 1 s, for more
//! value changes per second. The publisher alone, without polling, is measured by the
//! `mqtt_backlog` bench.
//!
//! # OPC UA
//!
//! With `--opcua` the gateway also serves the cell over OPC UA (security None, anonymous,
//! on a free loopback port) and a third process (the bench again, with `--opcua-counter
//! URL ITEMS`: `support/opcua_counter.rs`, async-opcua's client) monitors `--opcua-items`
//! points (10,000 by default: the live group's points first, as evenly over the devices as
//! they go, e.g. 1,000 stations × 10 points) in subscriptions of 1,000 items publishing
//! every 500 ms, and counts the data-change notifications and their delay from source
//! time to arrival. The report adds notifications/s received against the changes/s the
//! history holds for those points in the window (counted in the history after the stop),
//! the delay's p50/p99/max, the counter's CPU, and `cellbus_opcua_monitored_items`. The
//! cost of serving is the difference between runs with `--opcua` and without.
//!
//! Under `cargo test --benches` (no `--bench` flag) it runs a one-second smoke test with
//! one device of each kind on a line of its own (a JTSE, a Thermosald regulator and a
//! CROSS, each on a serial port, as `--serial` makes it; a Modbus unit behind a Modbus TCP
//! gateway; a Panasonic machine), publishing to MQTT and serving OPC UA to a client
//! monitoring 100 points, and fails unless every kind answered, each Modbus poll took two
//! reads, and the OPC UA client got its items and, by source time, every change the
//! history holds for them in the window.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::io::{Read, Write};
use std::path::PathBuf;
use std::process::{Command, ExitCode};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use gateway::cell::Cell;
use gateway::driver::ErrorKind;
use gateway::metrics::{DeviceLabels, LineLabels, PollResult};
use gateway::point::Quality;
use gateway::{Gateway, ServeOptions};
use jbc::code::{Code, Port, ToolError};
use jbc::device::{Station, StationConfig};
use jbc::frame::{Address, Route};
use jbc::message::{Reply, Request};
use jbus::cross::Source;
use jbus::cross::device::{CrossTwin, SourceFault};
use jbus::data::{DataType, Order, TypedValue};
use jbus::rtu::UnitId;
use jbus::slave::{Slave, SlaveMap, Table};
use jbus::tcp::MbapServer;
use link::SerialSettings;
use panasonic::operator::Command as PanelCommand;
use panasonic::server::{Control, RunningTwin, TwinServer};
use panasonic::status::StopMode;
use panasonic::{Machine, MachineConfig};
use thermosald::device::{Regulator, RegulatorBus, RegulatorConfig};
use thermosald::exchange::LineTiming;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use wire::device::{Bus, Device, SharedModel};

#[path = "support/helper.rs"]
mod helper;
#[path = "support/mqtt_counter.rs"]
mod mqtt_counter;
#[path = "support/opcua_counter.rs"]
mod opcua_counter;
#[path = "support/process.rs"]
mod process;

use helper::Helper;
use mqtt_counter::Counter;
use process::{ProcessUse, ticks_per_second};

/// How far into the measured window `--alarm-flood` starts.
const FLOOD_INTO_WINDOW: Duration = Duration::from_secs(5);

/// Devices simulated when `--devices` is not given.
const DEFAULT_DEVICES: usize = 100;
/// Lines when `--lines` is not given.
const DEFAULT_LINES: usize = 10;
/// Measured time when `--seconds` is not given.
const DEFAULT_SECONDS: Duration = Duration::from_secs(10);
/// Time before measuring: lines open, every group read once.
const DEFAULT_WARMUP: Duration = Duration::from_secs(5);
/// Station processing time before each reply, unless `--reply-delay` says otherwise.
const DEFAULT_REPLY_DELAY: Duration = Duration::from_millis(1);
/// How often the sampler reads the point timestamps.
const SAMPLE_EVERY: Duration = Duration::from_millis(100);
/// How often the simulated operators act.
const OPERATOR_TICK: Duration = Duration::from_millis(250);
/// One round of the operator's routine.
const ROUTINE: Duration = Duration::from_secs(120);
/// Points (`float32` input registers 0, 2, … 198) of each simulated Modbus device.
const MODBUS_POINTS: usize = 100;
/// Word order of the simulated Modbus devices' `float32` values (as many meters have it).
const MODBUS_ORDER: Order = Order::Cdab;
/// Points of a simulated Modbus device that take a new value each second: 15 of its 100.
const MODBUS_CHANGES_PER_SECOND: f64 = 15.0;
/// The register list every simulated Modbus device shares (`registers_csv`), next to the
/// generated `cell.toml`.
const MODBUS_CSV: &str = "modbus-registers.csv";
/// Monitored items of the OPC UA counter when `--opcua-items` is not given.
const DEFAULT_OPCUA_ITEMS: usize = 10_000;

/// Times each GET after the window is made, one after another on fresh connections: the
/// report gives the first (a cold buffer), the median and the fastest.
const SCRAPE_REPEATS: usize = 5;
/// The flag that makes the process the simulators' one.
const SIMULATORS_FLAG: &str = "--simulators";
/// What the simulator process prints once every line listens.
const READY: &str = "ready";

const USAGE: &str = "\
gateway load benchmark: simulated devices polled by the real gateway

usage: cargo bench -p gateway --bench load -- [options]

  --devices N         simulated devices (default 100)
  --lines M           lines they share, each a multi-drop bus (default 10)
  --seconds S         measured time, e.g. 60 or 60s (default 10 s)
  --warmup S          time before measuring (default 5 s)
  --mix KIND=W,...    device kinds, by weight per line (default jbc=1; known: jbc,
                      modbus: 100 float32 points behind a Modbus TCP gateway,
                      thermosald: at most 8 a line, cross, panasonic: one a
                      line)
  --baud B|none       pace each serial line like one of B baud (default none:
                      loopback speed; Modbus TCP lines are never paced)
  --serial            serial lines (JBC, Thermosald, CROSS) are serial ports
                      (pseudo-terminals the simulator process creates, which the
                      gateway opens as serial://) instead of tcp:// to a serial
                      server
  --reply-delay D     station processing time before each reply (default 1ms; the
                      JTSE model's own is 5ms)
  --live-period D     poll period of the live group (default: the driver's, 1s; at
                      least 50ms)
  --alarm-flood       every JBC station raises a tool error at once 5 s into the
                      window and holds it (an alarm flood); the report
                      counts the alarms and times the alarm list and journal
  --no-scrapes        skip the timed GETs after the window (/api/devices builds
                      megabytes: leave them out of a heap profile of the polling)
  --mqtt              also publish the cell as a Sparkplug B edge node to a local
                      mosquitto, with a subscriber counting what arrives (both in
                      processes of their own)
  --opcua             also serve the cell over OPC UA, with a client in a process of
                      its own monitoring --opcua-items points and counting what arrives
  --modbus-changes N  points of each Modbus meter that change a second (default 15, at
                      most 100)
  --opcua-items N     points the OPC UA client monitors (default 10000; at most
                      10000: ten subscriptions of 1000, async-opcua's limits)
  --bare              the floor instead of the gateway: a bare loop on one thread
                      sends the JBC driver's requests to the same stations at the
                      same periods and reads each reply to its last byte, with no
                      parsing, state or history (JBC over TCP only)

1,000 devices over 50 lines for a minute:
  nice cargo bench -p gateway --bench load -- --devices 1000 --lines 50 --seconds 60
1,000 Modbus devices x 100 float32 points at 1 s:
  cargo bench -p gateway --bench load -- --mix modbus=1 --devices 1000 --lines 50 --seconds 30
400 Thermosald regulators, 8 on each of 50 RS-485 lines:
  cargo bench -p gateway --bench load -- --mix thermosald=1 --devices 400 --lines 50 --seconds 30
What the same requests cost without the gateway, at 1,000 stations:
  cargo bench -p gateway --bench load -- --devices 1000 --lines 50 --seconds 30 --bare
";

fn main() -> ExitCode {
    let raw: Vec<String> = std::env::args().skip(1).collect();
    if let Some(code) = mqtt_counter::run_if_asked(&raw, "load") {
        return code;
    }
    if let Some(code) = opcua_counter::run_if_asked(&raw, "load") {
        return code;
    }
    // `cargo bench` passes --bench; `cargo test --benches` does not: then a smoke run.
    let benching = raw.iter().any(|a| a == "--bench");
    let simulators = raw.iter().any(|a| a == SIMULATORS_FLAG);
    let rest: Vec<String> = raw
        .into_iter()
        .filter(|a| a != "--bench" && a != SIMULATORS_FLAG)
        .collect();
    if rest.iter().any(|a| a == "--help" || a == "-h") {
        print!("{USAGE}");
        return ExitCode::SUCCESS;
    }
    let mut args = match Args::parse(&rest) {
        Ok(args) => args,
        Err(message) => {
            eprintln!("load: {message}\n\n{USAGE}");
            return ExitCode::from(2);
        }
    };
    let smoke = !benching && !simulators && rest.is_empty();
    if smoke {
        // A line of each kind, so CI goes through every simulator and driver path: the
        // serial kinds' lines serial ports, the Modbus line a TCP connection.
        args = Args {
            devices: 5,
            lines: 5,
            seconds: Duration::from_secs(1),
            warmup: Duration::from_secs(1),
            mix: vec![
                (Kind::Jbc, 1),
                (Kind::Modbus, 1),
                (Kind::Thermosald, 1),
                (Kind::Cross, 1),
                (Kind::Panasonic, 1),
            ],
            serial: true,
            mqtt: true,
            opcua: true,
            opcua_items: 100,
            ..args
        };
        println!("load: smoke run (cargo bench -p gateway --bench load for the benchmark)");
    }
    if !simulators {
        // This process is the gateway: its malloc set up as `cellbus serve` sets it.
        gateway::tune_malloc();
    }
    let result = if simulators {
        run_simulators(&args)
    } else if args.bare {
        run_bare(&args).map(|report| print!("{report}"))
    } else {
        run_bench(&args).and_then(|report| {
            print!("{report}");
            if !smoke {
                return Ok(());
            }
            report.check_smoke()?;
            // And the floor, on two stations of one line.
            let bare = Args {
                devices: 2,
                lines: 1,
                mix: vec![(Kind::Jbc, 1)],
                serial: false,
                mqtt: false,
                opcua: false,
                bare: true,
                ..args.clone()
            };
            run_bare(&bare).map(|report| print!("{report}"))
        })
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("load: {e:#}");
            ExitCode::from(1)
        }
    }
}

// ---- arguments ---------------------------------------------------------------------------

#[derive(Debug, Clone, PartialEq)]
struct Args {
    devices: usize,
    lines: usize,
    seconds: Duration,
    warmup: Duration,
    mix: Vec<(Kind, u32)>,
    baud: Option<u32>,
    /// Serial lines (JBC, Thermosald, CROSS) over pseudo-terminals (`serial://`) instead of TCP.
    serial: bool,
    reply_delay: Duration,
    live_period: Option<Duration>,
    mqtt: bool,
    opcua: bool,
    opcua_items: usize,
    /// Points of each Modbus meter that take a new value each second.
    modbus_changes: f64,
    /// Whether to time the heavy GETs after the window (off for a heap profile of the
    /// polling alone: `/api/devices` builds megabytes).
    scrapes: bool,
    /// Every JBC station's tool error at once, 5 s into the window (an alarm flood).
    alarm_flood: bool,
    /// The floor instead of the gateway: the same requests sent by a bare loop.
    bare: bool,
}

impl Args {
    fn parse(raw: &[String]) -> Result<Args, String> {
        let mut args = Args {
            devices: DEFAULT_DEVICES,
            lines: DEFAULT_LINES,
            seconds: DEFAULT_SECONDS,
            warmup: DEFAULT_WARMUP,
            mix: vec![(Kind::Jbc, 1)],
            baud: None,
            serial: false,
            reply_delay: DEFAULT_REPLY_DELAY,
            live_period: None,
            mqtt: false,
            opcua: false,
            opcua_items: DEFAULT_OPCUA_ITEMS,
            modbus_changes: MODBUS_CHANGES_PER_SECOND,
            scrapes: true,
            alarm_flood: false,
            bare: false,
        };
        let mut it = raw.iter();
        while let Some(flag) = it.next() {
            // The switches, which take no value.
            let switch = match flag.as_str() {
                "--mqtt" => Some((&mut args.mqtt, true)),
                "--opcua" => Some((&mut args.opcua, true)),
                "--no-scrapes" => Some((&mut args.scrapes, false)),
                "--alarm-flood" => Some((&mut args.alarm_flood, true)),
                "--serial" => Some((&mut args.serial, true)),
                "--bare" => Some((&mut args.bare, true)),
                _ => None,
            };
            if let Some((field, value)) = switch {
                *field = value;
                continue;
            }
            let value = it
                .next()
                .ok_or_else(|| format!("{flag} needs a value"))?
                .as_str();
            match flag.as_str() {
                "--devices" => args.devices = count(flag, value)?,
                "--lines" => args.lines = count(flag, value)?,
                "--seconds" => args.seconds = seconds(flag, value)?,
                "--warmup" => args.warmup = seconds(flag, value)?,
                "--mix" => args.mix = mix(value)?,
                "--modbus-changes" => {
                    args.modbus_changes = count(flag, value)? as f64;
                    if args.modbus_changes > MODBUS_POINTS as f64 {
                        return Err(format!(
                            "--modbus-changes {value}: at most {MODBUS_POINTS} (a meter's points)"
                        ));
                    }
                }
                "--opcua-items" => {
                    args.opcua_items = count(flag, value)?;
                    let most = 10 * opcua_counter::ITEMS_PER_SUBSCRIPTION;
                    if args.opcua_items > most {
                        return Err(format!(
                            "--opcua-items {value}: at most {most} (ten subscriptions of {})",
                            opcua_counter::ITEMS_PER_SUBSCRIPTION
                        ));
                    }
                }
                "--baud" => {
                    args.baud = match value {
                        "none" => None,
                        text => Some(
                            text.parse::<u32>()
                                .ok()
                                .filter(|b| (300..=1_000_000).contains(b))
                                .ok_or_else(|| {
                                    format!("--baud {text:?}: a speed from 300 to 1000000, or none")
                                })?,
                        ),
                    }
                }
                "--reply-delay" => {
                    args.reply_delay = humantime::parse_duration(value)
                        .map_err(|e| format!("--reply-delay {value:?}: {e}; e.g. 1ms"))?;
                }
                "--live-period" => {
                    let period = humantime::parse_duration(value)
                        .map_err(|e| format!("--live-period {value:?}: {e}; e.g. 200ms"))?;
                    if period < gateway::config::MIN_PERIOD {
                        return Err(format!("--live-period {value}: at least 50ms"));
                    }
                    args.live_period = Some(period);
                }
                other => return Err(format!("unknown option {other:?}")),
            }
        }
        if args.seconds.is_zero() {
            return Err("--seconds must be more than 0".into());
        }
        if args.lines > args.devices {
            return Err(format!(
                "{} lines need at least {} devices (one per line), not {}",
                args.lines, args.lines, args.devices
            ));
        }
        if args.bare
            && (args.mix.iter().any(|(kind, _)| *kind != Kind::Jbc)
                || args.serial
                || args.baud.is_some()
                || args.mqtt
                || args.opcua)
        {
            return Err("--bare sends JBC requests over TCP at loopback speed: \
                        leave out --mix other than jbc, --serial, --baud, --mqtt and --opcua"
                .into());
        }
        plan(&args)?;
        Ok(args)
    }

    /// The arguments the simulator process needs.
    fn for_simulators(&self) -> Vec<String> {
        let mix = self
            .mix
            .iter()
            .map(|(k, w)| format!("{}={w}", k.protocol()))
            .collect::<Vec<_>>()
            .join(",");
        let mut args: Vec<String> = vec![
            SIMULATORS_FLAG.into(),
            "--devices".into(),
            self.devices.to_string(),
            "--lines".into(),
            self.lines.to_string(),
            "--mix".into(),
            mix,
            "--baud".into(),
            self.baud.map_or("none".into(), |b| b.to_string()),
            "--reply-delay".into(),
            format!("{}us", self.reply_delay.as_micros()),
            "--modbus-changes".into(),
            self.modbus_changes.to_string(),
        ];
        if self.serial {
            args.push("--serial".into());
        }
        if self.alarm_flood {
            args.extend([
                "--alarm-flood".into(),
                "--warmup".into(),
                format!("{}ms", self.warmup.as_millis()),
            ]);
        }
        args
    }
}

fn count(flag: &str, value: &str) -> Result<usize, String> {
    value
        .parse::<usize>()
        .ok()
        .filter(|n| *n >= 1)
        .ok_or_else(|| format!("{flag} {value:?}: a whole number from 1"))
}

fn seconds(flag: &str, value: &str) -> Result<Duration, String> {
    if let Ok(s) = value.parse::<f64>() {
        if (0.0..=86_400.0).contains(&s) {
            return Ok(Duration::from_secs_f64(s));
        }
        return Err(format!("{flag} {value}: from 0 to 86400 seconds"));
    }
    humantime::parse_duration(value).map_err(|e| format!("{flag} {value:?}: {e}; e.g. 60 or 60s"))
}

fn mix(value: &str) -> Result<Vec<(Kind, u32)>, String> {
    let mut mix = Vec::new();
    for part in value.split(',') {
        let (name, weight) = part.split_once('=').unwrap_or((part, "1"));
        let kind = Kind::parse(name.trim()).ok_or_else(|| {
            format!(
                "--mix: {name:?} is not a device kind the bench simulates; known: {}",
                Kind::KNOWN
            )
        })?;
        let weight = weight
            .trim()
            .parse::<u32>()
            .ok()
            .filter(|w| *w >= 1)
            .ok_or_else(|| format!("--mix: the weight of {name} must be a whole number from 1"))?;
        mix.push((kind, weight));
    }
    Ok(mix)
}

// ---- device kinds and the plan of lines --------------------------------------------------

/// A kind of simulated device.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Kind {
    /// JBC JTSE hot-air station.
    Jbc,
    /// A generic Modbus device ([`jbus::slave::Slave`]) with [`MODBUS_POINTS`] `float32`
    /// input registers, behind a Modbus TCP gateway: the line is one `modbus-tcp://`
    /// endpoint answering every unit on it.
    Modbus,
    /// Thermosald ISC impulse-sealer regulator (addresses 0–7 on an RS-485 line), sealing
    /// at its own rhythm.
    Thermosald,
    /// Chloride CROSS static transfer switch (JBUS units 1, 2, … on an RS-485 line).
    Cross,
    /// Panasonic placement machine: its own two TCP ports (commands, R messages), one
    /// machine a line.
    Panasonic,
}

impl Kind {
    const KNOWN: &'static str = "jbc, modbus, thermosald, cross, panasonic";

    fn parse(name: &str) -> Option<Kind> {
        match name {
            "jbc" => Some(Kind::Jbc),
            "modbus" => Some(Kind::Modbus),
            "thermosald" => Some(Kind::Thermosald),
            "cross" => Some(Kind::Cross),
            "panasonic" => Some(Kind::Panasonic),
            _ => None,
        }
    }

    /// The protocol name in the config.
    fn protocol(self) -> &'static str {
        match self {
            Kind::Jbc => "jbc",
            Kind::Modbus => "modbus",
            Kind::Thermosald => "thermosald",
            Kind::Cross => "cross",
            Kind::Panasonic => "panasonic",
        }
    }

    /// Most devices on one line: the addresses the protocol has for them.
    fn max_per_line(self) -> usize {
        match self {
            // 01-99; 00 is the robot's (the gateway's) own address.
            Kind::Jbc => usize::from(Address::MAX),
            // Units 1-247 (the CROSS's JBUS would take 248-255 too).
            Kind::Modbus | Kind::Cross => usize::from(jbus::rtu::UnitId::MAX),
            // Addresses 0-7.
            Kind::Thermosald => usize::from(thermosald::Address::MAX) + 1,
            // A machine is its own TCP server.
            Kind::Panasonic => 1,
        }
    }

    /// The device address of the `index`-th device on a line.
    fn address(self, index: usize) -> i64 {
        match self {
            Kind::Jbc | Kind::Modbus | Kind::Cross => index as i64 + 1,
            Kind::Thermosald | Kind::Panasonic => index as i64,
        }
    }

    /// The character framing of the kind's serial lines, at a given baud rate; `None` for
    /// a kind on a network (Modbus TCP, a placement machine).
    fn framing(self) -> Option<fn(u32) -> SerialSettings> {
        match self {
            Kind::Jbc => Some(SerialSettings::new_8e1),
            Kind::Thermosald | Kind::Cross => Some(SerialSettings::new_8n1),
            Kind::Modbus | Kind::Panasonic => None,
        }
    }

    /// The line's character framing at `baud`, when the line is paced; `None` for a line
    /// that is not serial, which `--baud` leaves at loopback speed.
    fn line_serial(self, baud: u32) -> Option<SerialSettings> {
        self.framing().map(|framing| framing(baud))
    }

    /// Whether the kind's lines are serial lines, which `--serial` turns into serial ports.
    fn is_serial(self) -> bool {
        self.framing().is_some()
    }

    /// The scheme of the line's TCP endpoint in the config.
    fn scheme(self) -> &'static str {
        match self {
            Kind::Jbc | Kind::Thermosald | Kind::Cross | Kind::Panasonic => "tcp",
            Kind::Modbus => "modbus-tcp",
        }
    }
}

/// One line of the bench: its kind and how many devices it carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct LinePlan {
    kind: Kind,
    devices: usize,
}

impl LinePlan {
    /// The `i`-th device's address as its protocol's type, made by `make` ([`plan`] keeps
    /// the devices within the addresses the protocol has).
    fn address<T, E>(&self, i: usize, make: impl FnOnce(u8) -> Result<T, E>) -> anyhow::Result<T> {
        let address = self.kind.address(i);
        u8::try_from(address)
            .ok()
            .and_then(|a| make(a).ok())
            .with_context(|| format!("{} address {address} out of range", self.kind.protocol()))
    }
}

/// Spreads the devices over the lines (as evenly as whole numbers allow) and the kinds
/// over the lines by weight.
fn plan(args: &Args) -> Result<Vec<LinePlan>, String> {
    let cycle: Vec<Kind> = args
        .mix
        .iter()
        .flat_map(|(kind, weight)| std::iter::repeat_n(*kind, *weight as usize))
        .collect();
    if cycle.is_empty() {
        return Err("--mix names no device kind".into());
    }
    let base = args.devices / args.lines;
    let extra = args.devices % args.lines;
    let mut lines = Vec::with_capacity(args.lines);
    for i in 0..args.lines {
        let kind = cycle[i % cycle.len()];
        let devices = base + usize::from(i < extra);
        if devices > kind.max_per_line() {
            return Err(format!(
                "{devices} {} devices on one line: at most {} have addresses; use more lines",
                kind.protocol(),
                kind.max_per_line()
            ));
        }
        lines.push(LinePlan { kind, devices });
    }
    Ok(lines)
}

// ---- the simulator process ---------------------------------------------------------------

/// What an operator does to the devices of a line, every [`OPERATOR_TICK`].
type Operator = Box<dyn FnMut(std::time::Instant) + Send>;

/// Makes a bus of a line's simulated devices for each connection, sharing the models.
type BusFactory = Arc<dyn Fn() -> Bus + Send + Sync>;

/// One line's simulated devices, and their operator.
enum SimulatedLine {
    /// Devices on a bus, which the simulator process serves on a listener or a PTY.
    Bus(BusFactory, Operator),
    /// A machine serving its own ports (kept while the simulators run), and where.
    Machine(RunningTwin, LineEndpoint, Operator),
}

/// The simulated devices of one line and their operator; `pace` is the line's character
/// timing when the serve loop paces it.
async fn simulate_line(
    plan: LinePlan,
    line: usize,
    reply_delay: Duration,
    pace: Option<SerialSettings>,
    flood: Option<Duration>,
    modbus_changes: f64,
) -> anyhow::Result<SimulatedLine> {
    match plan.kind {
        Kind::Jbc => {
            let mut stations = Vec::with_capacity(plan.devices);
            for i in 0..plan.devices {
                let address = plan.address(i, Address::new)?;
                let model = SharedModel::new(Station::new(StationConfig {
                    address: Some(address),
                    reply_delay,
                    ..StationConfig::default()
                }));
                stations.push((model, address, phase(line, i), JbcOperator::default()));
            }
            let models: Vec<SharedModel<Station>> =
                stations.iter().map(|(m, ..)| m.clone()).collect();
            let bus = Arc::new(move || bus_of(&models));
            let started = std::time::Instant::now();
            let operator = Box::new(move |now: std::time::Instant| {
                let elapsed = now.saturating_duration_since(started);
                let flooded = flood.is_some_and(|at| elapsed >= at);
                for (model, address, phase, op) in &mut stations {
                    op.act(model, *address, elapsed + *phase, now, flooded);
                }
            });
            Ok(SimulatedLine::Bus(bus, operator))
        }
        Kind::Modbus => {
            let mut devices = Vec::with_capacity(plan.devices);
            for i in 0..plan.devices {
                let unit = plan.address(i, UnitId::new)?;
                let map = SlaveMap::parse(&format!(
                    "unit {}\ninput 0..={}\n",
                    unit.get(),
                    2 * MODBUS_POINTS - 1
                ))
                .context("the simulated Modbus device's map")?;
                let mut slave = Slave::new(map).with_reply_delay(reply_delay);
                let operator =
                    ModbusOperator::new(&mut slave, (line * 1000 + i) as u64, modbus_changes);
                devices.push((SharedModel::new(slave), operator));
            }
            let models: Vec<SharedModel<Slave>> = devices.iter().map(|(m, _)| m.clone()).collect();
            // A Modbus TCP gateway: MBAP off the connection, RTU frames to every unit of
            // its line, the addressed unit's answer back behind the request's header. (A
            // one-device bus, to keep one type for every kind's connections.)
            let bus = Arc::new(move || {
                Bus(vec![
                    Box::new(MbapServer::new(bus_of(&models))) as Box<dyn Device>
                ])
            });
            let mut last = std::time::Instant::now();
            let operator = Box::new(move |now: std::time::Instant| {
                let elapsed = now.saturating_duration_since(last);
                last = now;
                for (model, op) in &mut devices {
                    op.act(&mut model.lock(), elapsed);
                }
            });
            Ok(SimulatedLine::Bus(bus, operator))
        }
        Kind::Thermosald => {
            // The regulators answer 200 ms after a question whatever `--reply-delay` says:
            // the protocol fixes it. Each seals at its own rhythm (3 to 4 s), so its
            // temperatures move as in production; the machine is the operator.
            let now = std::time::Instant::now();
            let mut regulators = Vec::with_capacity(plan.devices);
            for i in 0..plan.devices {
                let address = plan.address(i, thermosald::Address::new)?;
                let config = RegulatorConfig {
                    seal_period: Some(Duration::from_millis(
                        3_000 + ((line * 7 + i) % 8) as u64 * 125,
                    )),
                    ..RegulatorConfig::default()
                };
                regulators.push(Regulator::new(address, config, now));
            }
            let mut regulators = RegulatorBus::from_regulators(regulators);
            if let Some(serial) = pace {
                let timing = LineTiming::new(serial.baud, serial.bits_per_char())
                    .context("the Thermosald line's timing")?;
                regulators = regulators.paced(timing);
            }
            let model = SharedModel::new(regulators);
            let bus = Arc::new(move || Bus(vec![Box::new(model.line()) as Box<dyn Device>]));
            Ok(SimulatedLine::Bus(
                bus,
                Box::new(|_: std::time::Instant| {}),
            ))
        }
        Kind::Cross => {
            let mut switches = Vec::with_capacity(plan.devices);
            for i in 0..plan.devices {
                let unit = plan.address(i, UnitId::jbus)?;
                let model = SharedModel::new(
                    CrossTwin::new(unit, (line * 1000 + i) as u64).with_reply_delay(reply_delay),
                );
                switches.push((model, phase(line, i), CrossOperator::default()));
            }
            let models: Vec<SharedModel<CrossTwin>> =
                switches.iter().map(|(m, ..)| m.clone()).collect();
            let bus = Arc::new(move || bus_of(&models));
            let started = std::time::Instant::now();
            let operator = Box::new(move |now: std::time::Instant| {
                let elapsed = now.saturating_duration_since(started);
                for (model, phase, op) in &mut switches {
                    op.act(model, elapsed + *phase);
                }
            });
            Ok(SimulatedLine::Bus(bus, operator))
        }
        Kind::Panasonic => simulate_machine(line).await,
    }
}

/// A Panasonic machine's twin served on two ports of 127.0.0.1 (Port 1 commands, Port 2 R
/// messages), and its operator.
async fn simulate_machine(line: usize) -> anyhow::Result<SimulatedLine> {
    let machine = Machine::new(MachineConfig::default()).map_err(anyhow::Error::msg)?;
    let any = std::net::SocketAddr::from(([127, 0, 0, 1], 0));
    let twin = TwinServer::bind(any, any, machine)
        .await
        .context("cannot listen for a Panasonic machine")?
        .spawn()
        .context("cannot start a Panasonic machine")?;
    let endpoint = LineEndpoint {
        url: format!("tcp://127.0.0.1:{}", twin.command_addr().port()),
        event_port: Some(twin.event_addr().port()),
    };
    let mut operator = PlacementOperator {
        control: twin.control().clone(),
        done: None,
    };
    let started = std::time::Instant::now();
    let phase = phase(line, 0);
    let operator = Box::new(move |now: std::time::Instant| {
        operator.act(now.saturating_duration_since(started) + phase);
    });
    Ok(SimulatedLine::Machine(twin, endpoint, operator))
}

/// The feeder the placement operator lets run out.
const EMPTY_FEEDER: u16 = 7;

/// A placement machine's operator, 85 s a round: starts a continuous run at 10 s, lets a
/// feeder run out at 60 s (an error stop), refills it and clears the error at 75 s.
struct PlacementOperator {
    control: Control,
    /// The (round, step) last done.
    done: Option<(u64, usize)>,
}

impl PlacementOperator {
    const ROUND: u64 = 85;
    /// Seconds into the round of each step.
    const STEPS: [u64; 3] = [10, 60, 75];

    fn act(&mut self, at: Duration) {
        let round = at.as_secs() / Self::ROUND;
        let into = at.as_secs() % Self::ROUND;
        let Some(step) = Self::STEPS.iter().rposition(|&s| s <= into) else {
            return;
        };
        if self.done == Some((round, step)) {
            return;
        }
        self.done = Some((round, step));
        let commands: &[PanelCommand] = match step {
            0 => &[PanelCommand::Start(Some(StopMode::Continuous))],
            1 => &[PanelCommand::PauseFeeder(EMPTY_FEEDER)],
            _ => &[
                PanelCommand::ResumeFeeder(EMPTY_FEEDER),
                PanelCommand::RefillFeeder(EMPTY_FEEDER),
                PanelCommand::Clear,
            ],
        };
        for &command in commands {
            // A refusal (a start while the machine is stopped by an error the bench
            // started in) changes nothing; the next round tries again.
            let _ = self.control.apply(command);
        }
    }
}

/// A bus of the models' lines (each connection gets a new one, sharing the models).
fn bus_of<M>(models: &[SharedModel<M>]) -> Bus
where
    M: wire::device::Model + Send + 'static,
    wire::device::ModelLine<M>: Device + Send + 'static,
{
    Bus(models
        .iter()
        .map(|m| Box::new(m.line()) as Box<dyn Device>)
        .collect())
}

/// Where the `i`-th device of `line` starts in its operator's [`ROUTINE`]: the phases
/// spread the devices' routines over the round.
fn phase(line: usize, i: usize) -> Duration {
    Duration::from_millis(((line * 97 + i * 7919) % ROUTINE.as_millis() as usize) as u64)
}

/// The mains a CROSS rides through, 120 s a round: source 1 fails for the last 40 s of
/// each (an outage in one round, an undervoltage in the next), so the load transfers to
/// source 2 and back.
#[derive(Debug, Default)]
struct CrossOperator {
    failed: bool,
}

impl CrossOperator {
    fn act(&mut self, model: &SharedModel<CrossTwin>, at: Duration) {
        let round = at.as_secs() / ROUTINE.as_secs();
        let fail = at.as_secs() % ROUTINE.as_secs() >= 80;
        if fail == self.failed {
            return;
        }
        self.failed = fail;
        let mut twin = model.lock();
        if fail {
            let fault = if round.is_multiple_of(2) {
                SourceFault::Outage
            } else {
                SourceFault::Undervoltage
            };
            twin.fail_source_with(Source::S1, fault);
        } else {
            twin.restore_source(Source::S1);
        }
    }
}

/// The process behind one simulated Modbus device: [`MODBUS_CHANGES_PER_SECOND`] of its
/// points (`--modbus-changes`) take a new value each second, in turn, each a small random
/// step from the last (a slow process: temperatures, pressures, flows), so every point
/// changes every `MODBUS_POINTS / MODBUS_CHANGES_PER_SECOND` seconds.
struct ModbusOperator {
    /// Points changed a second.
    rate: f64,
    values: Vec<f32>,
    next: usize,
    due: f64,
    rng: fastrand::Rng,
}

impl ModbusOperator {
    /// The operator of `slave`, whose registers it fills with their first values.
    fn new(slave: &mut Slave, seed: u64, rate: f64) -> Self {
        let mut rng = fastrand::Rng::with_seed(seed);
        let values: Vec<f32> = (0..MODBUS_POINTS)
            .map(|_| (rng.f32() * 1000.0).round() / 10.0)
            .collect();
        for (point, &value) in values.iter().enumerate() {
            write_float32(slave, point, value);
        }
        // Devices start at different fractions of a change, not all in step.
        let due = rng.f64();
        Self {
            rate,
            values,
            next: 0,
            due,
            rng,
        }
    }

    fn act(&mut self, slave: &mut Slave, elapsed: Duration) {
        self.due += self.rate * elapsed.as_secs_f64();
        while self.due >= 1.0 {
            self.due -= 1.0;
            // 37 and 100 have no common factor: every point in turn, spread over the map.
            let point = (self.next * 37) % MODBUS_POINTS;
            self.next += 1;
            let step = (self.rng.f32() - 0.5) * 2.0;
            let value = ((self.values[point] + step) * 100.0).round() / 100.0;
            self.values[point] = value;
            write_float32(slave, point, value);
        }
    }
}

/// Puts `value` in the two input registers of `point`, in [`MODBUS_ORDER`].
fn write_float32(slave: &mut Slave, point: usize, value: f32) {
    let words = DataType::Float32
        .encode(MODBUS_ORDER, &TypedValue::Float(f64::from(value)))
        .expect("any f32 encodes as a float32");
    for (register, word) in (point * 2..).zip(words) {
        let address = u16::try_from(register).expect("the map's registers are below 200");
        assert!(
            slave.set(Table::InputRegisters, address, word),
            "register {address} is mapped"
        );
    }
}

/// What the operator of one JTSE last did.
#[derive(Debug, Default)]
struct JbcOperator {
    heat: Option<(i32, i32)>,
    suction: bool,
    fault: bool,
    refused: bool,
}

impl JbcOperator {
    /// The routine, 120 s a round: heat to 350 °C, off, heat to 420 °C with the suction
    /// pedal pressed for a while, an air-flow fault in one round of three, off; with
    /// `flooded`, the fault all the time.
    fn act(
        &mut self,
        model: &SharedModel<Station>,
        address: Address,
        at: Duration,
        now: std::time::Instant,
        flooded: bool,
    ) {
        let round = at.as_secs() / ROUTINE.as_secs();
        let s = at.as_secs() % ROUTINE.as_secs();
        let heat = match s {
            0..45 => Some((350, 60)),
            60..95 => Some((420, 80)),
            _ => None,
        };
        let suction = (70..75).contains(&s);
        let fault = flooded || (round.is_multiple_of(3) && (85..90).contains(&s));
        let mut station = model.lock();
        station.advance(now);
        if heat != self.heat {
            let writes: &[(Code, i32)] = match heat {
                Some((celsius, flow)) => &[
                    (Code::SelectAirTemp(Port::One), celsius),
                    (Code::SelectAirFlow(Port::One), flow),
                    (Code::PortStatus(Port::One), 1),
                ],
                None => &[(Code::PortStatus(Port::One), 0)],
            };
            let route = Route {
                source: Address::ROBOT,
                target: address,
            };
            for &(code, value) in writes {
                let accepted = Request::write(code, value).ok().is_some_and(|request| {
                    let reply = station.reply_to(Ok(request.to_frame(Some(route))), now);
                    reply.is_some_and(|frame| {
                        matches!(Reply::from_frame(&frame), Ok(Reply::Ack { .. }))
                    })
                });
                if !accepted && !self.refused {
                    self.refused = true;
                    eprintln!("load: station {address:?} refused the operator's {code}");
                }
            }
            self.heat = heat;
        }
        if suction != self.suction {
            station.set_suction(suction);
            self.suction = suction;
        }
        if fault != self.fault {
            station.set_tool_error(if fault {
                ToolError::InsufficientAirFlow
            } else {
                ToolError::Ok
            });
            self.fault = fault;
        }
    }
}

/// The child process: serves every line, prints `line I ENDPOINT` for each (see
/// [`LineEndpoint`]) and then `ready`, and runs until its standard input closes (the bench
/// ends or dies).
fn run_simulators(args: &Args) -> anyhow::Result<()> {
    let plans = plan(args).map_err(anyhow::Error::msg)?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("cannot start the simulators' runtime")?;
    // Where the pseudo-terminals of `--serial` are linked; removed when the process ends.
    let links = args
        .serial
        .then(tempfile::tempdir)
        .transpose()
        .context("cannot create a temporary directory")?;
    runtime.block_on(async {
        let mut operators = Vec::new();
        let mut machines = Vec::new();
        let mut out = String::new();
        for (i, plan) in plans.iter().enumerate() {
            let pace = args.baud.and_then(|b| plan.kind.line_serial(b));
            let (bus, operator) = match simulate_line(
                *plan,
                i,
                args.reply_delay,
                pace,
                // A few seconds into the window (the simulators start just before the
                // gateway).
                args.alarm_flood.then_some(args.warmup + FLOOD_INTO_WINDOW),
                args.modbus_changes,
            )
            .await?
            {
                SimulatedLine::Bus(bus, operator) => (bus, operator),
                SimulatedLine::Machine(twin, endpoint, operator) => {
                    machines.push(twin);
                    operators.push(operator);
                    writeln!(out, "line {i} {endpoint}").expect("writing to a String cannot fail");
                    continue;
                }
            };
            let pty_dir = links.as_ref().filter(|_| plan.kind.is_serial());
            let url = if let Some(dir) = pty_dir {
                let link = dir.path().join(format!("line{i:02}"));
                let pty = link::serve::Pty::create(&link)
                    .with_context(|| format!("cannot create the PTY of line {i}"))?;
                let device = bus();
                tokio::spawn(async move {
                    if let Err(e) = pty.serve(device, pace).await {
                        eprintln!("load: simulated line {i} stopped: {e}");
                    }
                });
                format!("serial://{}", link.display())
            } else {
                let listener = tokio::net::TcpListener::bind(("127.0.0.1", 0))
                    .await
                    .context("cannot listen on 127.0.0.1")?;
                let port = listener.local_addr()?.port();
                tokio::spawn(async move {
                    if let Err(e) = link::serve::serve_tcp(listener, move || bus(), pace).await {
                        eprintln!("load: simulated line {i} stopped: {e}");
                    }
                });
                format!("{}://127.0.0.1:{port}", plan.kind.scheme())
            };
            operators.push(operator);
            let endpoint = LineEndpoint {
                url,
                event_port: None,
            };
            writeln!(out, "line {i} {endpoint}").expect("writing to a String cannot fail");
        }
        tokio::spawn(async move {
            let mut tick = tokio::time::interval(OPERATOR_TICK);
            loop {
                tick.tick().await;
                let now = std::time::Instant::now();
                for operator in &mut operators {
                    operator(now);
                }
            }
        });
        {
            let mut stdout = std::io::stdout().lock();
            writeln!(stdout, "{out}{READY}").and_then(|()| stdout.flush())?;
        }
        // Until the bench closes our standard input (or dies).
        tokio::task::spawn_blocking(|| {
            let mut sink = Vec::new();
            let _ = std::io::stdin().read_to_end(&mut sink);
        })
        .await
        .context("the standard input watcher failed")?;
        drop(machines);
        anyhow::Ok(())
    })?;
    runtime.shutdown_background();
    Ok(())
}

/// Where the gateway reaches a simulated line, as the simulator process prints it: the
/// line's URL (without its serial settings), and a placement machine's event port after
/// it.
#[derive(Debug, Clone, PartialEq, Eq)]
struct LineEndpoint {
    url: String,
    event_port: Option<u16>,
}

impl LineEndpoint {
    /// Reads what [`LineEndpoint`]'s `Display` printed.
    fn parse(text: &str) -> Option<Self> {
        let mut words = text.split(' ');
        let url = words.next()?.to_owned();
        let event_port = words.next().map(str::parse).transpose().ok()?;
        words.next().is_none().then_some(Self { url, event_port })
    }
}

impl std::fmt::Display for LineEndpoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.url)?;
        match self.event_port {
            Some(port) => write!(f, " {port}"),
            None => Ok(()),
        }
    }
}

/// The simulator process, ended when dropped (see [`Helper`]).
struct Simulators {
    helper: Helper,
    /// Each line's endpoint.
    endpoints: Vec<LineEndpoint>,
}

impl Simulators {
    fn start(args: &Args) -> anyhow::Result<Self> {
        let exe = std::env::current_exe().context("cannot find the bench's own executable")?;
        let mut command = Command::new(exe);
        command
            .args(args.for_simulators())
            // A heap profiler preloaded into the bench (heaptrack) profiles the gateway
            // only, not the simulators too.
            .env_remove("LD_PRELOAD");
        let mut simulators = Simulators {
            helper: Helper::start(command, "simulator")?,
            endpoints: Vec::new(),
        };
        loop {
            let line = simulators
                .helper
                .read_line()
                .context("the simulator process ended before it was ready")?;
            if line == READY {
                return Ok(simulators);
            }
            let endpoint = line
                .strip_prefix("line ")
                .and_then(|rest| rest.split_once(' '))
                .and_then(|(_, endpoint)| LineEndpoint::parse(endpoint))
                .with_context(|| format!("unexpected line from the simulators: {line:?}"))?;
            simulators.endpoints.push(endpoint);
        }
    }

    fn pid(&self) -> u32 {
        self.helper.pid()
    }
}

// ---- the gateway and the measurement -----------------------------------------------------

/// The cell configuration for the simulated lines, as a file for `cellbus serve --config`
/// (Modbus devices name [`MODBUS_CSV`], written by [`modbus_csv`] next to it).
fn config_text(args: &Args, plans: &[LinePlan], endpoints: &[LineEndpoint]) -> String {
    let mut text = String::from("# Generated by the gateway load benchmark.\n");
    for (i, (plan, endpoint)) in plans.iter().zip(endpoints).enumerate() {
        let timing = args
            .baud
            .and_then(|b| plan.kind.line_serial(b))
            .map_or(String::new(), |serial| {
                format!("?baud={}&framing={}", serial.baud, serial.framing())
            });
        let _ = write!(
            text,
            "\n[[line]]\nname = \"line{i:02}\"\nendpoint = \"{}{timing}\"\n",
            endpoint.url
        );
        for d in 0..plan.devices {
            let address = plan.kind.address(d);
            let _ = write!(
                text,
                "\n[[line.device]]\nid = \"l{i:02}-{kind}{address:02}\"\nprotocol = \"{kind}\"\n",
                kind = plan.kind.protocol()
            );
            match endpoint.event_port {
                Some(port) => {
                    let _ = writeln!(text, "event_port = {port}");
                }
                None => {
                    let _ = writeln!(text, "address = {address}");
                }
            }
            if plan.kind == Kind::Modbus {
                let _ = writeln!(text, "registers_csv = \"{MODBUS_CSV}\"");
            }
            if let Some(period) = args.live_period {
                let _ = writeln!(text, "poll = {{ live = \"{}ms\" }}", period.as_millis());
            }
        }
    }
    if args.opcua {
        // The endpoint is `--opcua 127.0.0.1:0`'s; the counter reads anonymously.
        text.push_str("\n[opcua]\nsecurity = [\"None\"]\nanonymous = true\n");
    }
    text
}

/// The points the OPC UA counter monitors: of each device, its live group's points
/// first, as many per device as `items` needs, at most `items` in all.
fn opcua_items(cell: &Cell, items: usize) -> Vec<String> {
    let devices = cell.devices();
    let per_device = items.div_ceil(devices.len().max(1));
    let mut chosen = Vec::with_capacity(items);
    for device in &devices {
        let mut points: Vec<_> = device.points.iter().collect();
        points.sort_by_key(|p| p.group != gateway::driver::jbc::LIVE);
        chosen.extend(
            points
                .into_iter()
                .take(per_device)
                .map(|p| p.view.id.as_str().to_owned()),
        );
    }
    chosen.truncate(items);
    chosen
}

/// Changes the history holds for `points` in `[from, to)` (ms since 1970).
fn stored_changes(
    data_dir: &std::path::Path,
    points: &[String],
    from: i64,
    to: i64,
) -> anyhow::Result<u64> {
    let conn = rusqlite::Connection::open(data_dir.join(gateway::store::DB_FILE))?;
    let mut stmt = conn.prepare(
        "SELECT count(*) FROM samples WHERE point = (SELECT id FROM points WHERE name = ?1) \
         AND t >= ?2 AND t < ?3",
    )?;
    let mut changes = 0u64;
    for point in points {
        let n: i64 = stmt.query_row(rusqlite::params![point, from, to], |r| r.get(0))?;
        changes += u64::try_from(n).unwrap_or(0);
    }
    Ok(changes)
}

/// The register list of the simulated Modbus devices: [`MODBUS_POINTS`] `float32` input
/// registers, `p00` at 0, `p01` at 2, …
fn modbus_csv() -> String {
    let mut text = String::from("name,table,address,type,order\n");
    for point in 0..MODBUS_POINTS {
        let _ = writeln!(
            text,
            "p{point:02},input,{},float32,{MODBUS_ORDER}",
            point * 2
        );
    }
    text
}

/// The gateway's counters at one moment.
#[derive(Debug, Clone, Default)]
struct Counters {
    at: Option<Instant>,
    polls_ok: u64,
    polls_failed: u64,
    timeouts: u64,
    errors: HashMap<ErrorKind, u64>,
    value_changes: u64,
    events: u64,
    rows: u64,
    samples: u64,
    commits: u64,
    busy: Vec<f64>,
    /// Answered polls per protocol, since the start.
    polls_by_protocol: HashMap<&'static str, u64>,
    /// Each Modbus device's `cellbus_modbus_requests_per_poll`, with its polls (answered
    /// and failed) since the start.
    modbus_requests: Vec<(i64, u64)>,
    gateway: ProcessUse,
    simulators: ProcessUse,
    mqtt: Option<MqttCounters>,
    opcua: Option<OpcuaCounters>,
}

/// With `--opcua`: the counting client's side at one moment.
#[derive(Debug, Clone, Copy, Default)]
struct OpcuaCounters {
    /// What the client received.
    received: opcua_counter::Counts,
    /// The client's process.
    client: ProcessUse,
    /// When (ms since 1970), to count the history's changes of the monitored points.
    t_ms: i64,
    /// `cellbus_opcua_monitored_items` as the gateway counts them.
    monitored_items: u64,
    /// `cellbus_opcua_connections`: client connections through the gateway's relay.
    connections: u64,
}

/// With `--mqtt`: the broker and the counting subscriber, each a process of its own.
struct MqttSide {
    // Dropped first: the counter ends before the broker it listens to.
    counter: Counter,
    broker: testkit::Mosquitto,
}

impl MqttSide {
    fn start() -> anyhow::Result<Self> {
        let broker = testkit::Mosquitto::start();
        let counter = Counter::start(broker.port())?;
        Ok(Self { broker, counter })
    }

    /// The subscriber's counts once they stop moving (everything published has arrived),
    /// waiting at most `limit`.
    fn settled(&mut self, limit: Duration) -> anyhow::Result<mqtt_counter::Counts> {
        let deadline = Instant::now() + limit;
        let mut last = self.counter.counts()?;
        loop {
            std::thread::sleep(Duration::from_millis(200));
            let now = self.counter.counts()?;
            if now == last || Instant::now() > deadline {
                return Ok(now);
            }
            last = now;
        }
    }
}

/// The MQTT side's counters at one moment.
#[derive(Debug, Clone, Copy, Default)]
struct MqttCounters {
    /// Messages the gateway handed to its MQTT client (`cellbus_mqtt_published`).
    published: u64,
    /// What the subscriber received.
    received: mqtt_counter::Counts,
    broker: ProcessUse,
    counter: ProcessUse,
}

impl Counters {
    fn take(
        cell: &Cell,
        simulators: u32,
        ticks: u64,
        sampler: ProcessUse,
        mqtt: Option<&mut MqttSide>,
        opcua: Option<(&mut opcua_counter::Counter, bool)>,
    ) -> anyhow::Result<Self> {
        let opcua = match opcua {
            Some((counter, reset)) => Some(OpcuaCounters {
                received: counter.counts(reset)?,
                client: ProcessUse::of(&counter.pid().to_string(), ticks)?,
                t_ms: gateway::time::Timestamp::now().0,
                monitored_items: cellbus_opcua::state(cell).map_or(0, |o| o.monitored_items),
                connections: cellbus_opcua::state(cell).map_or(0, |o| o.connections),
            }),
            None => None,
        };
        let metrics = cell.metrics();
        let stats = cell.store().stats();
        let mqtt = match mqtt {
            Some(side) => Some(MqttCounters {
                published: gateway::northbound::mqtt::status::status(cell)
                    .metrics
                    .published
                    .get(),
                received: side.counter.counts()?,
                broker: match side.broker.pid() {
                    Some(pid) => ProcessUse::of(&pid.to_string(), ticks)?,
                    None => ProcessUse::default(),
                },
                counter: ProcessUse::of(&side.counter.pid().to_string(), ticks)?,
            }),
            None => None,
        };
        let mut c = Counters {
            at: Some(Instant::now()),
            gateway: ProcessUse::of("self", ticks)?.without(&sampler),
            simulators: ProcessUse::of(&simulators.to_string(), ticks)?,
            mqtt,
            opcua,
            value_changes: metrics.value_changes.get(),
            events: metrics.events.get(),
            rows: stats.rows_written(),
            samples: stats.samples_written.load(Ordering::Relaxed),
            commits: stats.commits.load(Ordering::Relaxed),
            ..Counters::default()
        };
        for line in cell.lines() {
            c.busy.push(
                metrics
                    .line_busy_seconds
                    .get_or_create(&LineLabels {
                        line: line.name.clone(),
                    })
                    .get(),
            );
            for device in &line.devices {
                let ok = metrics.poll_count(&line.name, device.as_str(), PollResult::ok);
                let failed = metrics.poll_count(&line.name, device.as_str(), PollResult::error);
                c.polls_ok += ok;
                c.polls_failed += failed;
                if let Some(entry) = cell.device_entry(device.as_str()) {
                    *c.polls_by_protocol
                        .entry(entry.protocol.name())
                        .or_default() += ok;
                    if entry.protocol == gateway::driver::modbus::KIND {
                        let requests = metrics
                            .modbus_requests_per_poll
                            .get_or_create(&DeviceLabels {
                                line: line.name.clone(),
                                device: device.as_str().to_owned(),
                            })
                            .get();
                        c.modbus_requests.push((requests, ok + failed));
                    }
                }
                c.timeouts += metrics.timeout_count(&line.name, device.as_str());
                for kind in ErrorKind::ALL {
                    *c.errors.entry(kind).or_default() +=
                        metrics.error_count(&line.name, device.as_str(), kind.as_str());
                }
            }
        }
        Ok(c)
    }
}

/// Per poll group: good reads seen, points they carried, intervals between reads.
#[derive(Debug, Clone, Default)]
struct GroupSeen {
    period: Duration,
    devices: usize,
    reads: u64,
    points: u64,
    intervals_ms: Intervals,
}

/// Poll intervals in whole milliseconds, counted per value: the sampler runs inside the
/// measured gateway process, and a list of every interval grew to megabytes in long runs
/// (a few hundred distinct values here).
#[derive(Debug, Clone, Default)]
struct Intervals(std::collections::BTreeMap<i64, u64>);

impl Intervals {
    fn add(&mut self, ms: i64) {
        *self.0.entry(ms).or_default() += 1;
    }

    fn len(&self) -> u64 {
        self.0.values().sum()
    }

    fn max(&self) -> Option<i64> {
        self.0.keys().next_back().copied()
    }

    /// The `p`th percentile, ranked as in a sorted list of every interval.
    fn percentile(&self, p: f64) -> Option<i64> {
        let n = self.len();
        if n == 0 {
            return None;
        }
        let rank = (((p / 100.0) * (n - 1) as f64).round() as u64).min(n - 1);
        let mut below = 0;
        for (&ms, &count) in &self.0 {
            below += count;
            if rank < below {
                return Some(ms);
            }
        }
        self.max()
    }
}

/// Follows the time stamp of one point per device and group: each new good time stamp is
/// one answered poll of that group, and the time since the previous one the period kept.
///
/// It runs on a thread of its own, whose CPU time [`Counters::take`] leaves out of the
/// gateway's: reading 3,000 time stamps ten times a second was 2–3 % of the gateway's CPU
/// at 1,000 stations, counted as the gateway's own while it ran on the runtime's workers.
struct Sampler {
    measuring: Arc<AtomicBool>,
    stop: Arc<AtomicBool>,
    /// Its thread in `/proc` (`self/task/TID`), for its CPU time.
    task: String,
    thread: std::thread::JoinHandle<Vec<(String, GroupSeen)>>,
}

/// One point the sampler follows: the first of its device's group.
struct Watch {
    group: usize,
    device: Arc<gateway::cell::DeviceEntry>,
    point: usize,
    points: u64,
    last: Option<i64>,
}

impl Sampler {
    fn start(cell: Arc<Cell>) -> anyhow::Result<Self> {
        let mut groups: Vec<(String, GroupSeen)> = Vec::new();
        let mut watches = Vec::new();
        for device in cell.device_entries() {
            for g in &device.groups {
                let Some(point) = device.points.iter().position(|p| p.group == g.name) else {
                    continue;
                };
                let points = device.points.iter().filter(|p| p.group == g.name).count();
                // Per kind of device: a Modbus device's live group is not a JTSE's.
                let name = format!("{} {}", device.protocol.name(), g.name);
                let group = match groups
                    .iter()
                    .position(|(n, seen)| *n == name && seen.period == g.period)
                {
                    Some(i) => i,
                    None => {
                        groups.push((
                            name,
                            GroupSeen {
                                period: g.period,
                                ..GroupSeen::default()
                            },
                        ));
                        groups.len() - 1
                    }
                };
                groups[group].1.devices += 1;
                watches.push(Watch {
                    group,
                    device: Arc::clone(&device),
                    point,
                    points: points as u64,
                    last: None,
                });
            }
        }
        let measuring = Arc::new(AtomicBool::new(false));
        let stop = Arc::new(AtomicBool::new(false));
        let (flag, stopped) = (Arc::clone(&measuring), Arc::clone(&stop));
        let (tid_tx, tid_rx) = std::sync::mpsc::channel();
        let thread = std::thread::Builder::new()
            .name("bench-sampler".into())
            .spawn(move || {
                // `/proc/thread-self` is `PID/task/TID`.
                let _ = tid_tx.send(std::fs::read_link("/proc/thread-self"));
                let mut next = std::time::Instant::now();
                while !stopped.load(Ordering::Relaxed) {
                    next += SAMPLE_EVERY;
                    std::thread::sleep(next.saturating_duration_since(std::time::Instant::now()));
                    sample(&mut watches, &mut groups, flag.load(Ordering::Relaxed));
                }
                groups
            })
            .context("cannot start the sampler's thread")?;
        let path = tid_rx
            .recv()
            .context("the sampler's thread ended at once")?
            .context("cannot read /proc/thread-self")?;
        let tid = path
            .file_name()
            .and_then(|t| t.to_str())
            .with_context(|| format!("/proc/thread-self is {}", path.display()))?;
        Ok(Self {
            measuring,
            stop,
            task: format!("self/task/{tid}"),
            thread,
        })
    }

    /// Starts counting (at the start of the window).
    fn measure(&self) {
        self.measuring.store(true, Ordering::Relaxed);
    }

    /// Its CPU time so far.
    fn usage(&self, ticks: u64) -> anyhow::Result<ProcessUse> {
        ProcessUse::of(&self.task, ticks)
    }

    /// Stops counting (at the end of the window) and returns what was seen.
    fn finish(self) -> anyhow::Result<Vec<(String, GroupSeen)>> {
        self.measuring.store(false, Ordering::Relaxed);
        self.stop.store(true, Ordering::Relaxed);
        self.thread
            .join()
            .map_err(|_| anyhow::anyhow!("the sampler's thread panicked"))
    }
}

/// One round of the sampler: each watched point's time stamp, counted when it is new and
/// good while `measuring`.
fn sample(watches: &mut [Watch], groups: &mut [(String, GroupSeen)], measuring: bool) {
    for w in watches {
        let (t, good) = {
            let state = w.device.read();
            match state.points.get(w.point) {
                Some(p) => (p.t.map(|t| t.0), p.quality == Some(Quality::Good)),
                None => (None, false),
            }
        };
        if t == w.last {
            continue;
        }
        if measuring && good {
            let seen = &mut groups[w.group].1;
            seen.reads += 1;
            seen.points += w.points;
            if let (Some(now), Some(before)) = (t, w.last) {
                seen.intervals_ms.add(now - before);
            }
        }
        w.last = if good { t } else { None };
    }
}

/// Times one GET on the gateway's HTTP port; returns the status line, the body's size and
/// the time to the last byte.
async fn get(addr: std::net::SocketAddr, path: &str) -> anyhow::Result<(String, usize, Duration)> {
    let started = Instant::now();
    let mut stream = tokio::net::TcpStream::connect(addr).await?;
    stream
        .write_all(
            format!("GET {path} HTTP/1.1\r\nHost: bench\r\nConnection: close\r\n\r\n").as_bytes(),
        )
        .await?;
    let mut response = Vec::new();
    stream.read_to_end(&mut response).await?;
    let took = started.elapsed();
    let text = String::from_utf8_lossy(&response);
    let (head, body) = text.split_once("\r\n\r\n").unwrap_or((&text, ""));
    let status = head.lines().next().unwrap_or("").to_owned();
    Ok((status, body.len(), took))
}

/// Everything measured.
struct Report {
    args: Args,
    plans: Vec<LinePlan>,
    host: Host,
    window: Duration,
    before: Counters,
    after: Counters,
    groups: Vec<(String, GroupSeen)>,
    scrapes: Vec<(String, String, usize, Vec<Duration>)>,
    stop_took: Duration,
    rows_at_stop: u64,
    integrity: String,
    /// With `--mqtt`, after the stop: messages the gateway published in all, and what the
    /// subscriber received in all.
    mqtt_totals: Option<(u64, mqtt_counter::Counts)>,
    /// With `--opcua`: what was monitored, stored and received.
    opcua_totals: Option<OpcuaTotals>,
    /// With `--alarm-flood`: the alarms at the window's end, in words.
    alarms: Option<String>,
}

/// With `--opcua`, after the stop.
struct OpcuaTotals {
    /// Points monitored.
    points: usize,
    /// Monitored items the server created.
    created: usize,
    /// Changes the history holds for those points in the measured window.
    stored: u64,
    /// Notifications the client received whose source time is in the window.
    received: u64,
}

fn run_bench(args: &Args) -> anyhow::Result<Report> {
    let plans = plan(args).map_err(anyhow::Error::msg)?;
    let ticks = ticks_per_second();
    let mut host = Host::before();
    let simulators = Simulators::start(args)?;
    if simulators.endpoints.len() != plans.len() {
        bail!(
            "the simulators opened {} lines, not {}",
            simulators.endpoints.len(),
            plans.len()
        );
    }
    let dir = tempfile::tempdir().context("cannot create a temporary directory")?;
    let config = dir.path().join("cell.toml");
    std::fs::write(&config, config_text(args, &plans, &simulators.endpoints))
        .context("cannot write the generated cell.toml")?;
    std::fs::write(dir.path().join(MODBUS_CSV), modbus_csv())
        .context("cannot write the generated register list")?;
    let data_dir: PathBuf = dir.path().join("data");
    let mut mqtt = if args.mqtt {
        Some(MqttSide::start()?)
    } else {
        None
    };
    let options = ServeOptions {
        listen: "127.0.0.1:0".parse().expect("a valid socket address"),
        config: Some(config),
        data_dir: data_dir.clone(),
        flags: gateway::options::Flags::default()
            .with(gateway::northbound::mqtt::MqttFlags {
                broker: mqtt.as_ref().map(|m| m.broker.url()),
                node: mqtt.as_ref().map(|_| "loadbench".to_owned()),
                ..Default::default()
            })
            .with(cellbus_opcua::OpcuaFlags {
                listen: args
                    .opcua
                    .then(|| "127.0.0.1:0".parse().expect("a valid socket address")),
            }),
        ..ServeOptions::default()
    };
    // The same runtime as `cellbus serve`: multi-threaded, one worker per core.
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("cannot start the runtime")?;
    let pid = simulators.pid();
    let items_file = dir.path().join("opcua-items.txt");
    let report = runtime.block_on(async {
        // The binary's interfaces: the gateway's own and OPC UA.
        let registry = gateway::plugins::builtin().with_interface(&cellbus_opcua::Opcua);
        let gateway = Gateway::start_with(options, &registry).await?;
        let addr = gateway.local_addr();
        let gateway_opcua = gateway.url_of("opcua").map(str::to_owned);
        let cell = Arc::clone(gateway.cell());
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let run = tokio::spawn(gateway.run(async {
            let _ = stopped.await;
        }));
        let sampler = Sampler::start(Arc::clone(&cell))?;
        let mut opcua = match gateway_opcua {
            Some(url) => {
                let points = opcua_items(&cell, args.opcua_items);
                let file = items_file.clone();
                std::fs::write(&file, points.join("\n"))
                    .context("cannot write the OPC UA counter's items")?;
                let counter =
                    tokio::task::spawn_blocking(move || opcua_counter::Counter::start(&url, &file))
                        .await
                        .context("the OPC UA counter's start failed")??;
                Some((counter, points))
            }
            None => None,
        };
        tokio::time::sleep(args.warmup).await;
        let published = gateway::northbound::mqtt::status::status(&cell)
            .metrics
            .published
            .clone();
        let before = Counters::take(
            &cell,
            pid,
            ticks,
            sampler.usage(ticks)?,
            mqtt.as_mut(),
            opcua.as_mut().map(|(c, _)| (c, true)),
        )?;
        sampler.measure();
        tokio::time::sleep(args.seconds).await;
        let after = Counters::take(
            &cell,
            pid,
            ticks,
            sampler.usage(ticks)?,
            mqtt.as_mut(),
            opcua.as_mut().map(|(c, _)| (c, false)),
        )?;
        let groups = sampler.finish()?;
        let load_after = Host::load();
        // The window's notifications, counted by source time while the server still runs
        // (the last changes of the window are published after it).
        let opcua = match (opcua, &before.opcua, &after.opcua) {
            (Some((mut counter, points)), Some(b), Some(a)) => {
                let (from, to) = (b.t_ms, a.t_ms);
                let received = tokio::task::spawn_blocking(move || {
                    counter
                        .settled_between(from, to, Duration::from_secs(10))
                        .map(|n| (counter, n))
                })
                .await
                .context("the OPC UA counter failed")??;
                Some((received.0.created, received.1, points))
            }
            _ => None,
        };
        // After the window: what a dashboard and a Prometheus scrape cost with this cell.
        let mut scrapes = Vec::new();
        let mut paths: Vec<&str> = if args.scrapes {
            vec![
                "/metrics",
                "/api/devices",
                "/api/devices?fields=id,status,line",
                "/api/devices?line=line00",
                "/healthz",
            ]
        } else {
            Vec::new()
        };
        if args.alarm_flood {
            // What the page's banner, list and journal ask for during the flood.
            paths.extend([
                "/api/alarms?limit=1",
                "/api/alarms?limit=50",
                "/api/alarms?limit=50&offset=500",
                "/api/alarms/journal?limit=100",
            ]);
        }
        let alarms = args.alarm_flood.then(|| {
            let counts = cell.alarms.counts();
            let sum =
                |f: fn(&gateway::alarm::book::Counts) -> u64| counts.iter().map(f).sum::<u64>();
            format!(
                "{} alarms kept, {} active, {} unacknowledged at the window's end",
                cell.alarms.with(|book| book.len()),
                sum(|c| c.active),
                sum(|c| c.unacknowledged)
            )
        });
        for &path in &paths {
            let mut times = Vec::with_capacity(SCRAPE_REPEATS);
            let (status, size, took) = get(addr, path).await?;
            times.push(took);
            for _ in 1..SCRAPE_REPEATS {
                times.push(get(addr, path).await?.2);
            }
            scrapes.push((path.to_owned(), status, size, times));
        }
        drop(cell);
        let stopping = Instant::now();
        let _ = stop.send(());
        run.await.context("the gateway task failed")??;
        let stop_took = stopping.elapsed();
        anyhow::Ok((
            before, after, groups, load_after, scrapes, stop_took, published, opcua, alarms,
        ))
    })?;
    runtime.shutdown_timeout(Duration::from_secs(5));
    drop(simulators);
    let (before, after, groups, load_after, scrapes, stop_took, published, opcua, alarms) = report;
    host.load_after = load_after;
    let mqtt_totals = match &mut mqtt {
        Some(side) => Some((published.get(), side.settled(Duration::from_secs(10))?)),
        None => None,
    };
    drop(mqtt);
    // Reopen the history the gateway closed: every row it committed is there.
    let store = gateway::store::Store::open(&data_dir, gateway::store::StoreOptions::default())?;
    let integrity = store.handle().integrity_check()?;
    let rows_at_stop = store_rows(&data_dir)?;
    drop(store);
    let opcua_totals = match (opcua, &before.opcua, &after.opcua) {
        (Some((created, received, points)), Some(b), Some(a)) => Some(OpcuaTotals {
            points: points.len(),
            created,
            stored: stored_changes(&data_dir, &points, b.t_ms, a.t_ms)?,
            received,
        }),
        _ => None,
    };
    if after.polls_ok <= before.polls_ok {
        bail!(
            "no poll was answered in the measured window: the gateway or the simulators are stuck"
        );
    }
    let window = after.at.zip(before.at).map_or(args.seconds, |(a, b)| a - b);
    Ok(Report {
        args: args.clone(),
        plans,
        host,
        window,
        before,
        after,
        groups,
        scrapes,
        alarms,
        stop_took,
        rows_at_stop,
        integrity,
        mqtt_totals,
        opcua_totals,
    })
}

// ---- the floor: a bare exchange loop ------------------------------------------------------

/// What the bare loop did, counted as it goes.
#[derive(Debug, Default)]
struct BareCounts {
    exchanges: std::sync::atomic::AtomicU64,
    polls: std::sync::atomic::AtomicU64,
    points: std::sync::atomic::AtomicU64,
}

/// [`BareCounts`] at one moment, with the process's CPU time.
#[derive(Debug, Clone, Copy)]
struct BareTake {
    at: Instant,
    exchanges: u64,
    polls: u64,
    points: u64,
    process: ProcessUse,
}

impl BareCounts {
    fn take(&self, ticks: u64) -> anyhow::Result<BareTake> {
        Ok(BareTake {
            at: Instant::now(),
            exchanges: self.exchanges.load(Ordering::Relaxed),
            polls: self.polls.load(Ordering::Relaxed),
            points: self.points.load(Ordering::Relaxed),
            process: ProcessUse::of("self", ticks)?,
        })
    }
}

/// `--bare`: the floor under the gateway's cost. One thread with a current-thread runtime
/// (as the gateway's pollers have) runs a task per line that sends, at each group's
/// period, every station's requests for that group, the very bytes the JBC client sends
/// (the codes and periods [`gateway::driver::jbc::group_reads`] gives), each under a
/// timeout as any client needs, and reads the reply up to its last byte. Nothing is
/// parsed, kept or stored. The process's CPU time over the window, divided by the
/// exchanges and points, is what the requests cost with nothing of the gateway around
/// them: the gateway's figure less this one is all the gateway adds.
fn run_bare(args: &Args) -> anyhow::Result<BareReport> {
    let plans = plan(args).map_err(anyhow::Error::msg)?;
    let ticks = ticks_per_second();
    let simulators = Simulators::start(args)?;
    let mut groups = gateway::driver::jbc::group_reads();
    if let Some(period) = args.live_period {
        for group in groups
            .iter_mut()
            .filter(|g| g.group == gateway::driver::jbc::LIVE)
        {
            group.period = period;
        }
    }
    let mut lines = Vec::with_capacity(plans.len());
    for (plan, endpoint) in plans.iter().zip(&simulators.endpoints) {
        let addr = endpoint
            .url
            .strip_prefix("tcp://")
            .with_context(|| format!("a JBC line that is not tcp://: {}", endpoint.url))?
            .to_owned();
        // Each group's requests, station after station, as the client encodes them.
        let mut requests: Vec<Vec<Vec<u8>>> = vec![Vec::new(); groups.len()];
        for d in 0..plan.devices {
            let route = Route {
                source: Address::ROBOT,
                target: plan.address(d, Address::new)?,
            };
            for (g, group) in groups.iter().enumerate() {
                for &code in &group.codes {
                    let request = Request::read(code)
                        .map_err(|e| anyhow::anyhow!("a read of {code:?}: {e}"))?;
                    requests[g].push(request.to_frame(Some(route)).to_bytes());
                }
            }
        }
        lines.push((addr, plan.devices, requests));
    }
    let counts = Arc::new(BareCounts::default());
    let (stop, stopped) = tokio::sync::watch::channel(false);
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("cannot start the bare loop's runtime")?;
    let thread = {
        let counts = Arc::clone(&counts);
        let groups: Arc<[gateway::driver::jbc::GroupReads]> = groups.into();
        std::thread::Builder::new()
            .name("bare-poll".into())
            .spawn(move || {
                runtime.block_on(async move {
                    let tasks: Vec<_> = lines
                        .into_iter()
                        .map(|(addr, stations, requests)| {
                            tokio::spawn(bare_line(
                                addr,
                                stations,
                                requests,
                                Arc::clone(&groups),
                                Arc::clone(&counts),
                                stopped.clone(),
                            ))
                        })
                        .collect();
                    for task in tasks {
                        task.await.context("a bare line task panicked")??;
                    }
                    anyhow::Ok(())
                })
            })
            .context("cannot start the bare loop's thread")?
    };
    let mut host = Host::before();
    std::thread::sleep(args.warmup);
    let before = counts.take(ticks)?;
    let simulators_before = ProcessUse::of(&simulators.pid().to_string(), ticks)?;
    std::thread::sleep(args.seconds);
    let after = counts.take(ticks)?;
    let simulators_after = ProcessUse::of(&simulators.pid().to_string(), ticks)?;
    host.load_after = Host::load();
    let _ = stop.send(true);
    thread
        .join()
        .map_err(|_| anyhow::anyhow!("the bare loop's thread panicked"))??;
    drop(simulators);
    if after.exchanges <= before.exchanges {
        bail!("no exchange was done in the measured window: the simulators are stuck");
    }
    Ok(BareReport {
        args: args.clone(),
        host,
        before,
        after,
        simulators: simulators_after.without(&simulators_before),
    })
}

/// A line of the bare loop: each group at its period (the first at once), every station
/// of the line in turn, one request at a time.
async fn bare_line(
    addr: String,
    stations: usize,
    requests: Vec<Vec<Vec<u8>>>,
    groups: Arc<[gateway::driver::jbc::GroupReads]>,
    counts: Arc<BareCounts>,
    mut stop: tokio::sync::watch::Receiver<bool>,
) -> anyhow::Result<()> {
    let timeout = jbc::client::ClientConfig::default().timeout;
    let mut stream = tokio::net::TcpStream::connect(&addr)
        .await
        .with_context(|| format!("cannot connect to the simulated line at {addr}"))?;
    stream.set_nodelay(true)?;
    let mut due: Vec<tokio::time::Instant> = vec![tokio::time::Instant::now(); groups.len()];
    let mut reply = [0u8; 64];
    loop {
        let (g, &at) = due
            .iter()
            .enumerate()
            .min_by_key(|(_, at)| **at)
            .context("the driver has no groups")?;
        tokio::select! {
            _ = tokio::time::sleep_until(at) => {}
            _ = stop.changed() => return Ok(()),
        }
        for request in &requests[g] {
            let exchange = async {
                stream.write_all(request).await?;
                let mut len = 0;
                loop {
                    let n = stream.read(&mut reply[len..]).await?;
                    if n == 0 {
                        bail!("the simulated line at {addr} closed");
                    }
                    len += n;
                    // A frame ends one byte (the BCC) after its ETX.
                    if let Some(etx) = reply[..len].iter().position(|&b| b == jbc::frame::ETX)
                        && len > etx + 1
                    {
                        return anyhow::Ok(());
                    }
                    if len == reply.len() {
                        bail!("a reply longer than {len} bytes from {addr}");
                    }
                }
            };
            tokio::time::timeout(timeout, exchange)
                .await
                .with_context(|| format!("no reply from {addr} within {timeout:?}"))??;
            counts.exchanges.fetch_add(1, Ordering::Relaxed);
        }
        counts.polls.fetch_add(stations as u64, Ordering::Relaxed);
        counts
            .points
            .fetch_add((stations * groups[g].points) as u64, Ordering::Relaxed);
        // The next poll one period after this one was due, or now if the line is behind.
        due[g] = (at + groups[g].period).max(tokio::time::Instant::now());
    }
}

/// What `--bare` prints.
struct BareReport {
    args: Args,
    host: Host,
    before: BareTake,
    after: BareTake,
    simulators: ProcessUse,
}

impl std::fmt::Display for BareReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (a, b) = (&self.after, &self.before);
        let secs = (a.at - b.at).as_secs_f64();
        let exchanges = a.exchanges - b.exchanges;
        let polls = a.polls - b.polls;
        let points = a.points - b.points;
        let window = a.process.without(&b.process);
        let cpu_us = window.cpu.as_secs_f64() * 1e6;
        let user_us = window.user.as_secs_f64() * 1e6;
        let per = |us: f64, n: u64| us / n.max(1) as f64;
        writeln!(f, "gateway load benchmark: the floor (--bare, no gateway)")?;
        writeln!(
            f,
            "  cell         {} JBC stations on {} line{}; lines not paced (loopback speed), reply delay {}",
            self.args.devices,
            self.args.lines,
            if self.args.lines == 1 { "" } else { "s" },
            humantime::format_duration(self.args.reply_delay),
        )?;
        self.host.write_run(f, secs, &self.args)?;
        writeln!(
            f,
            "  work         {:.0} exchanges/s, {:.0} polls/s, {:.0} points/s (what the gateway's polls would give)",
            exchanges as f64 / secs,
            polls as f64 / secs,
            points as f64 / secs,
        )?;
        writeln!(
            f,
            "  bare loop    CPU {:.2} cores, peak RSS {:.1} MiB",
            window.cpu.as_secs_f64() / secs,
            mib(a.process.peak_rss_kib)
        )?;
        writeln!(
            f,
            "  cost         {:.1} µs CPU per poll, {:.2} µs per point (user {:.2}, kernel {:.2}), {:.2} µs per exchange",
            per(cpu_us, polls),
            per(cpu_us, points),
            per(user_us, points),
            per(cpu_us - user_us, points),
            per(cpu_us, exchanges),
        )?;
        let s = self.simulators.cpu.as_secs_f64() / secs;
        writeln!(
            f,
            "  simulators   CPU {:.2} cores ({:.0} % of the machine) (separate process)",
            s,
            s * 100.0 / self.host.cores as f64,
        )
    }
}

impl Report {
    /// What the smoke run must show: every kind of device answered, and each Modbus
    /// device's 100 `float32` points (200 registers) took two reads (at most 125 each).
    fn check_smoke(&self) -> anyhow::Result<()> {
        for (kind, _) in &self.args.mix {
            let answered = self
                .after
                .polls_by_protocol
                .get(kind.protocol())
                .copied()
                .unwrap_or(0);
            if answered == 0 {
                bail!("no {} device answered a poll", kind.protocol());
            }
        }
        let reads = i64::try_from((2 * MODBUS_POINTS).div_ceil(125)).unwrap_or(i64::MAX);
        if let Some(OpcuaTotals {
            points, created, ..
        }) = self.opcua_totals
            && created != points
        {
            bail!("the OPC UA server created {created} monitored items of {points}");
        }
        if let Some(a) = &self.after.opcua
            && a.connections == 0
        {
            bail!("the OPC UA client is not connected through the gateway's relay");
        }
        if let Some(totals) = &self.opcua_totals
            && (totals.received != totals.stored || totals.stored == 0)
        {
            bail!(
                "the OPC UA client received {} notifications of the {} changes the history holds for its points in the window",
                totals.received,
                totals.stored
            );
        }
        if let Some((requests, _)) = self
            .after
            .modbus_requests
            .iter()
            .find(|(requests, _)| *requests != reads)
        {
            bail!("a Modbus device took {requests} requests per poll, not {reads}");
        }
        Ok(())
    }
}

/// Rows in the history tables.
fn store_rows(data_dir: &std::path::Path) -> anyhow::Result<u64> {
    let conn = rusqlite::Connection::open(data_dir.join(gateway::store::DB_FILE))?;
    let mut rows = 0u64;
    for table in ["samples", "events"] {
        let n: i64 = conn.query_row(&format!("SELECT count(*) FROM {table}"), [], |r| r.get(0))?;
        rows += u64::try_from(n).unwrap_or(0);
    }
    Ok(rows)
}

// ---- the report --------------------------------------------------------------------------

/// The machine a run measured on: its cores, and its load average before and after.
struct Host {
    cores: usize,
    load_before: String,
    load_after: String,
}

impl Host {
    /// The machine at the start of a run (its load after is filled in at the end).
    fn before() -> Self {
        Self {
            cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
            load_before: Self::load(),
            load_after: String::new(),
        }
    }

    /// The load average now (1, 5 and 15 minutes).
    fn load() -> String {
        std::fs::read_to_string("/proc/loadavg")
            .ok()
            .map(|l| l.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
            .unwrap_or_else(|| "unknown".into())
    }

    /// A report's `run` line: the window, the warm-up and the machine's load around them.
    fn write_run(
        &self,
        f: &mut std::fmt::Formatter<'_>,
        secs: f64,
        args: &Args,
    ) -> std::fmt::Result {
        writeln!(
            f,
            "  run          {secs:.1} s measured after {} s warm-up; machine: {} cores, load average {} before, {} after",
            args.warmup.as_secs_f64(),
            self.cores,
            self.load_before,
            self.load_after
        )
    }
}

fn mib(kib: u64) -> f64 {
    kib as f64 / 1024.0
}

impl std::fmt::Display for Report {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let secs = self.window.as_secs_f64();
        let rate = |a: u64, b: u64| a.saturating_sub(b) as f64 / secs;
        let (a, b) = (&self.after, &self.before);
        let kinds: Vec<String> = self
            .args
            .mix
            .iter()
            .map(|(k, w)| format!("{}×{w}", k.protocol()))
            .collect();
        let most = self.plans.iter().map(|p| p.devices).max().unwrap_or(0);
        let least = self.plans.iter().map(|p| p.devices).min().unwrap_or(0);
        writeln!(f, "gateway load benchmark")?;
        writeln!(
            f,
            "  cell         {} devices ({}) on {} lines, {}{} per line; lines {}, reply delay {}, live period {}{}",
            self.args.devices,
            kinds.join(", "),
            self.args.lines,
            least,
            if most == least {
                String::new()
            } else {
                format!("-{most}")
            },
            self.args
                .baud
                .map_or("not paced (loopback speed)".to_owned(), |b| format!(
                    "paced at {b} baud"
                ))
                + if self.args.serial {
                    ", serial lines on serial ports (PTYs)"
                } else {
                    ""
                },
            humantime::format_duration(self.args.reply_delay),
            self.args
                .live_period
                .map_or("1s (the driver's)".to_owned(), |p| {
                    humantime::format_duration(p).to_string()
                }),
            match (self.args.mqtt, self.args.opcua) {
                (true, true) =>
                    "; publishing to a local mosquitto (--mqtt); serving OPC UA (--opcua)",
                (true, false) => "; publishing to a local mosquitto (--mqtt)",
                (false, true) => "; serving OPC UA (--opcua)",
                (false, false) => "",
            },
        )?;
        self.host.write_run(f, secs, &self.args)?;
        let polls = rate(a.polls_ok, b.polls_ok);
        let failed = rate(a.polls_failed, b.polls_failed);
        writeln!(
            f,
            "  polls        {polls:.0}/s answered, {failed:.1}/s failed (timeouts {}, errors {})",
            a.timeouts.saturating_sub(b.timeouts),
            ErrorKind::ALL
                .iter()
                .map(|k| format!(
                    "{k} {}",
                    a.errors
                        .get(k)
                        .copied()
                        .unwrap_or(0)
                        .saturating_sub(b.errors.get(k).copied().unwrap_or(0))
                ))
                .collect::<Vec<_>>()
                .join(", ")
        )?;
        let points: u64 = self.groups.iter().map(|(_, g)| g.points).sum();
        writeln!(
            f,
            "  points       {:.0}/s read good; {:.0}/s value changes",
            points as f64 / secs,
            rate(a.value_changes, b.value_changes),
        )?;
        writeln!(
            f,
            "  history      {:.0} rows/s committed ({:.0} samples/s, {:.1} commits/s, {:.1} events/s); {} rows on disk after stop, integrity {}",
            rate(a.rows, b.rows),
            rate(a.samples, b.samples),
            rate(a.commits, b.commits),
            rate(a.events, b.events),
            self.rows_at_stop,
            self.integrity
        )?;
        if !a.modbus_requests.is_empty() {
            let per_poll: Vec<i64> = a.modbus_requests.iter().map(|(r, _)| *r).collect();
            let mean = per_poll.iter().sum::<i64>() as f64 / per_poll.len() as f64;
            // Requests sent in the window: each device's polls times its reads per poll.
            let requests: u64 = a
                .modbus_requests
                .iter()
                .zip(&b.modbus_requests)
                .map(|((r, after), (_, before))| {
                    u64::try_from(*r).unwrap_or(0) * after.saturating_sub(*before)
                })
                .sum();
            writeln!(
                f,
                "  modbus       {mean:.2} requests per poll (cellbus_modbus_requests_per_poll: {} to {} over {} devices), {:.0} requests/s",
                per_poll.iter().min().copied().unwrap_or(0),
                per_poll.iter().max().copied().unwrap_or(0),
                per_poll.len(),
                requests as f64 / secs,
            )?;
        }
        for (name, g) in &self.groups {
            let intervals = &g.intervals_ms;
            let period = g.period.as_millis() as i64;
            let show = |p: Option<i64>| p.map_or("-".to_owned(), |v| format!("{v}"));
            writeln!(
                f,
                "  {name:<15} period {} ms: {:.1} polls/s of {:.1} due; interval p50 {} ms, p99 {} ms, max {} ms ({} intervals)",
                period,
                g.reads as f64 / secs,
                g.devices as f64 / g.period.as_secs_f64(),
                show(intervals.percentile(50.0)),
                show(intervals.percentile(99.0)),
                show(intervals.max()),
                intervals.len()
            )?;
        }
        let busy: Vec<f64> = a
            .busy
            .iter()
            .zip(&b.busy)
            .map(|(x, y)| (x - y) / secs)
            .collect();
        let mean = busy.iter().sum::<f64>() / busy.len().max(1) as f64;
        let max = busy.iter().copied().fold(0.0, f64::max);
        let polls_done = (a.polls_ok + a.polls_failed).saturating_sub(b.polls_ok + b.polls_failed);
        let busy_total: f64 = busy.iter().sum::<f64>() * secs;
        writeln!(
            f,
            "  lines        busy {:.0} % on average, {:.0} % at most; a poll of a group took {:.1} ms on average",
            mean * 100.0,
            max * 100.0,
            busy_total * 1000.0 / polls_done.max(1) as f64
        )?;
        // Cores a process used over the window.
        let cpu = |x: &ProcessUse, y: &ProcessUse| x.without(y).cpu.as_secs_f64() / secs;
        let window = a.gateway.without(&b.gateway);
        let g = window.cpu.as_secs_f64() / secs;
        let s = cpu(&a.simulators, &b.simulators);
        writeln!(
            f,
            "  gateway      CPU {:.2} cores ({:.0} % of the machine), peak RSS {:.1} MiB",
            g,
            g * 100.0 / self.host.cores as f64,
            mib(a.gateway.peak_rss_kib)
        )?;
        // The gateway's whole CPU time (scheduler, drivers, clients, line I/O, live state,
        // history writer and commits, HTTP idle; not this bench's sampler) over the work
        // done.
        let gateway_us = window.cpu.as_secs_f64() * 1e6;
        let user_us = window.user.as_secs_f64() * 1e6;
        let changes = a.value_changes.saturating_sub(b.value_changes);
        let point = |us: f64| us / points.max(1) as f64;
        writeln!(
            f,
            "  cost         {:.1} µs CPU per poll, {:.2} µs per point read (user {:.2}, kernel {:.2}), {:.2} µs per value change{}",
            gateway_us / polls_done.max(1) as f64,
            point(gateway_us),
            point(user_us),
            point(gateway_us - user_us),
            gateway_us / changes.max(1) as f64,
            if self.args.mix.len() > 1 {
                " (the mix's average; --mix KIND=1 for one protocol's)"
            } else {
                ""
            }
        )?;
        writeln!(
            f,
            "  simulators   CPU {:.2} cores ({:.0} % of the machine), peak RSS {:.1} MiB (separate process)",
            s,
            s * 100.0 / self.host.cores as f64,
            mib(a.simulators.peak_rss_kib)
        )?;
        if let (Some(ma), Some(mb)) = (&a.mqtt, &b.mqtt) {
            let (ra, rb) = (&ma.received, &mb.received);
            let messages = rate(ra.messages, rb.messages);
            let metrics = rate(ra.metrics, rb.metrics);
            writeln!(
                f,
                "  mqtt         gateway published {:.0} messages/s (cellbus_mqtt_published) for {:.0} value changes/s",
                rate(ma.published, mb.published),
                rate(a.value_changes, b.value_changes),
            )?;
            writeln!(
                f,
                "  subscriber   received {messages:.0} messages/s ({:.0} DDATA/s), {metrics:.0} metrics/s ({:.1} per message, {:.0} B per message), {} historical, {} undecodable; CPU {:.2} cores (separate process)",
                rate(ra.ddata, rb.ddata),
                metrics / messages.max(f64::MIN_POSITIVE),
                ra.bytes.saturating_sub(rb.bytes) as f64
                    / ra.messages.saturating_sub(rb.messages).max(1) as f64,
                ra.historical.saturating_sub(rb.historical),
                ra.bad.saturating_sub(rb.bad),
                cpu(&ma.counter, &mb.counter),
            )?;
            writeln!(
                f,
                "  mosquitto    CPU {:.2} cores, peak RSS {:.1} MiB (separate process)",
                cpu(&ma.broker, &mb.broker),
                mib(ma.broker.peak_rss_kib)
            )?;
        }
        if let Some((published, received)) = &self.mqtt_totals {
            writeln!(
                f,
                "  mqtt totals  {published} messages published, {} received ({} lost); broker's $SYS dropped count {}",
                received.messages,
                published.saturating_sub(received.messages),
                received.dropped
            )?;
        }
        if let (Some(oa), Some(ob), Some(totals)) = (&a.opcua, &b.opcua, &self.opcua_totals) {
            writeln!(
                f,
                "  opcua        {} of {} monitored items created ({} counted by the gateway, over {} relayed connection(s)); the client received {:.0} notifications/s",
                totals.created,
                totals.points,
                oa.monitored_items,
                oa.connections,
                rate(oa.received.notifications, ob.received.notifications),
            )?;
            writeln!(
                f,
                "  opcua window the history holds {} changes of those points ({:.0}/s), the client received {} notifications with a source time in the window ({:.2} %)",
                totals.stored,
                totals.stored as f64 / secs,
                totals.received,
                totals.received as f64 * 100.0 / (totals.stored as f64).max(f64::MIN_POSITIVE),
            )?;
            writeln!(
                f,
                "  opcua client delay from source time to arrival p50 {} ms, p99 {} ms, max {} ms ({} notifications); CPU {:.2} cores, peak RSS {:.1} MiB (separate process)",
                oa.received.p50_ms,
                oa.received.p99_ms,
                oa.received.max_ms,
                oa.received.timed,
                cpu(&oa.client, &ob.client),
                mib(oa.client.peak_rss_kib),
            )?;
        }
        if let Some(alarms) = &self.alarms {
            writeln!(f, "  alarms       {alarms}")?;
        }
        for (path, status, size, times) in &self.scrapes {
            let ms = |d: Duration| d.as_secs_f64() * 1000.0;
            let mut sorted = times.clone();
            sorted.sort_unstable();
            writeln!(
                f,
                "  GET {path:<12} {status}, {:.0} kB in {:.1} ms; median {:.1} ms, min {:.1} ms of {}",
                *size as f64 / 1000.0,
                ms(times[0]),
                ms(sorted[sorted.len() / 2]),
                ms(sorted[0]),
                sorted.len(),
            )?;
        }
        writeln!(
            f,
            "  stop         {:.0} ms (pollers stopped, history committed)",
            self.stop_took.as_secs_f64() * 1000.0
        )
    }
}
