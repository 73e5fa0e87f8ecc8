//! MQTT backlog drain benchmark: the time the gateway's Sparkplug B publisher takes to
//! send the changes stored during an outage (1,000,000 by default) to a local mosquitto,
//! until a subscriber has received every one of them as a historical metric; with the
//! publisher's CPU share and peak memory. Draining the backlog is publishing alone (no
//! polling), so this also measures how many metric updates per second the publisher can
//! send at most.
//!
//! ```text
//! cargo bench -p gateway --bench mqtt_backlog                         # 1,000,000 changes, 1,000 devices
//! cargo bench -p gateway --bench mqtt_backlog -- --run 20             # 20 changes per read
//! cargo bench -p gateway --bench mqtt_backlog -- --help               # every option
//! ```
//!
//! # How it runs
//!
//! - **The history of an outage.** A generated `cell.toml` of JBC stations (20 per line;
//!   the lines are never opened: no device is polled), its [`Cell`], and the gateway's own
//!   [`Store`] in a temporary directory, into which the bench writes `--changes` value
//!   changes of the stations' numeric live points, as polling would have stored them:
//!   each read of a station stores `--run` changes at one read time, the stations read
//!   in turn, one read per millisecond (1,000 stations read each second), all after the
//!   forwarded mark `mqtt.forwarded_until` in the `settings` table and before now.
//! - **The drain.** A mosquitto on a free loopback port (testkit's), a subscriber in a
//!   process of its own (the bench again, with `--mqtt-counter PORT`:
//!   `support/mqtt_counter.rs`) that decodes every payload (prost) and counts metrics,
//!   and then [`gateway::northbound::mqtt::start`] as `cellbus serve` runs it, with
//!   `max_backlog` = `--changes`. On connect it publishes NBIRTH, a DBIRTH per device,
//!   then the stored changes as historical DDATA (consecutive changes of one device in
//!   one message, at most 500 metrics each, read from the history in pages of 5,000).
//!   Measured: from the start of the publisher to the arrival of the last historical
//!   metric at the subscriber; the CPU time (user + system) of this process (the gateway:
//!   the publisher, the runtime, the idle history writer; not the subscriber or the
//!   broker, whose CPU is printed apart) and its peak RSS (`VmHWM`, reset after the
//!   history was written, where the kernel allows).
//! - **Delivery.** Births and data go out with QoS 0 and mosquitto drops QoS 0 messages
//!   for a subscriber whose queue is full (`max_queued_messages`, 1,000 by default;
//!   testkit's config sets `message_size_limit 0`, no size limit): the report compares
//!   what the gateway published with what the subscriber received and prints mosquitto's
//!   `$SYS` dropped count.
//!
//! Under `cargo test --benches` (no `--bench` flag) it runs a smoke test: 5,000 changes
//! of 10 devices.

use std::fmt::Write as _;
use std::path::Path;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use gateway::cell::Cell;
use gateway::metrics::Metrics;
use gateway::northbound::mqtt::config::MqttConfig;
use gateway::northbound::mqtt::forward::FORWARDED_KEY;
use gateway::point::{PointId, PointKind, Quality, Value};
use gateway::store::{Sample, Store, StoreOptions};
use gateway::time::Timestamp;

#[path = "support/helper.rs"]
mod helper;
#[path = "support/mqtt_counter.rs"]
mod mqtt_counter;
#[path = "support/process.rs"]
mod process;

use mqtt_counter::{Counter, Counts, unix_micros};
use process::{ProcessUse, reset_peak_rss, ticks_per_second};

const DEFAULT_CHANGES: u64 = 1_000_000;
const DEFAULT_DEVICES: usize = 1_000;
/// Changes stored by one read of a station when `--run` is not given: a JTSE's live
/// group has five numeric points, and while it heats most of them change every second.
const DEFAULT_RUN: usize = 4;
/// Stations per generated line.
const PER_LINE: usize = 20;
/// The longest the drain may stall (no new historical metric) before the bench fails.
const STALL_LIMIT: Duration = Duration::from_secs(60);
/// How often the drain's progress is read.
const POLL: Duration = Duration::from_millis(10);

const USAGE: &str = "\
MQTT backlog drain benchmark: stored changes sent as historical Sparkplug DDATA

usage: cargo bench -p gateway --bench mqtt_backlog -- [options]

  --changes N    stored changes to send (default 1000000)
  --devices N    JBC stations they belong to (default 1000)
  --run K        changes per read of a station, stored at one read time and so sent in
                 one message (default 4; at most the 5 numeric live points of a station)
  --burst B      reads of one station in a row before the next station's (default 1:
                 the stations take turns; 100 with --run 5 makes 500-metric messages)
";

fn main() -> ExitCode {
    let raw: Vec<String> = std::env::args().skip(1).collect();
    if let Some(code) = mqtt_counter::run_if_asked(&raw, "mqtt_backlog") {
        return code;
    }
    // `cargo bench` passes --bench; `cargo test --benches` does not: then a smoke run.
    let benching = raw.iter().any(|a| a == "--bench");
    let rest: Vec<String> = raw.into_iter().filter(|a| a != "--bench").collect();
    if rest.iter().any(|a| a == "--help" || a == "-h") {
        print!("{USAGE}");
        return ExitCode::SUCCESS;
    }
    let mut args = match Args::parse(&rest) {
        Ok(args) => args,
        Err(message) => {
            eprintln!("mqtt_backlog: {message}\n\n{USAGE}");
            return ExitCode::from(2);
        }
    };
    if !benching && rest.is_empty() {
        args = Args {
            changes: 5_000,
            devices: 10,
            ..args
        };
        println!(
            "mqtt_backlog: smoke run (cargo bench -p gateway --bench mqtt_backlog for the benchmark)"
        );
    }
    match run(&args) {
        Ok(report) => {
            print!("{report}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("mqtt_backlog: {e:#}");
            ExitCode::from(1)
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct Args {
    changes: u64,
    devices: usize,
    run: usize,
    burst: u64,
}

impl Args {
    fn parse(raw: &[String]) -> Result<Args, String> {
        let mut args = Args {
            changes: DEFAULT_CHANGES,
            devices: DEFAULT_DEVICES,
            run: DEFAULT_RUN,
            burst: 1,
        };
        let mut it = raw.iter();
        while let Some(flag) = it.next() {
            let value = it.next().ok_or_else(|| format!("{flag} needs a value"))?;
            let number = value
                .replace('_', "")
                .parse::<u64>()
                .ok()
                .filter(|n| *n >= 1)
                .ok_or_else(|| format!("{flag} {value:?}: a whole number from 1"))?;
            match flag.as_str() {
                "--changes" => args.changes = number,
                "--devices" => {
                    args.devices = usize::try_from(number).map_err(|e| e.to_string())?;
                }
                "--run" => args.run = usize::try_from(number).map_err(|e| e.to_string())?,
                "--burst" => args.burst = number,
                other => return Err(format!("unknown option {other:?}")),
            }
        }
        Ok(args)
    }
}

/// The cell: `devices` JBC stations, 20 per line, on lines that are never opened.
fn config_text(devices: usize) -> String {
    let mut text = String::from("# Generated by the MQTT backlog benchmark.\n");
    for d in 0..devices {
        let (line, address) = (d / PER_LINE, d % PER_LINE + 1);
        if address == 1 {
            let _ = write!(
                text,
                "\n[[line]]\nname = \"line{line:03}\"\nendpoint = \"tcp://127.0.0.1:9\"\n"
            );
        }
        let _ = write!(
            text,
            "\n[[line.device]]\nid = \"l{line:03}-jbc{address:02}\"\nprotocol = \"jbc\"\naddress = {address}\n"
        );
    }
    text
}

/// What was stored.
struct Stored {
    changes: u64,
    points: usize,
    took: Duration,
    bytes: u64,
}

/// Writes the changes of an outage into the history and puts the forwarded mark before
/// them.
fn store_backlog(
    cell: &Cell,
    store: &Store,
    data_dir: &Path,
    args: &Args,
    runtime: &tokio::runtime::Runtime,
) -> anyhow::Result<Stored> {
    let started = Instant::now();
    // Per device, its numeric live points (what changes while a station works).
    let devices: Vec<Vec<PointId>> = cell
        .device_entries()
        .map(|d| {
            d.points
                .iter()
                .filter(|p| p.group == "live" && p.kind == PointKind::Numeric)
                .map(|p| p.id.clone())
                .collect::<Vec<_>>()
        })
        .filter(|points| !points.is_empty())
        .collect();
    let most = devices.iter().map(Vec::len).min().unwrap_or(0);
    if devices.is_empty() || args.run > most {
        bail!(
            "--run {}: a station has {most} numeric live points, so at most {most} changes per read",
            args.run
        );
    }
    let reads = args.changes.div_ceil(args.run as u64);
    // One read a millisecond, ending a second before now.
    let now = Timestamp::now().0;
    let first = now - 1_000 - i64::try_from(reads).unwrap_or(i64::MAX);
    gateway::store::write_setting(data_dir, FORWARDED_KEY, first - 5_000)
        .context("cannot store the forwarded mark")?;
    let handle = store.handle();
    let mut written = 0_u64;
    for read in 0..reads {
        let turn = read / args.burst;
        let device = &devices[(turn % devices.len() as u64) as usize];
        let round = (turn / devices.len() as u64) * args.burst + read % args.burst;
        let t = Timestamp(first + i64::try_from(read).unwrap_or(0));
        for k in 0..args.run {
            if written == args.changes {
                break;
            }
            let point = &device[(round as usize * args.run + k) % device.len()];
            handle.sample(Sample {
                point: point.clone(),
                t,
                value: Some(Value::Number(20.0 + (written % 400) as f64)),
                quality: Quality::Good,
            });
            written += 1;
            if written.is_multiple_of(50_000) {
                // Commit as it goes: the writer queues at most MAX_PENDING_ROWS.
                runtime.block_on(handle.flush())?;
            }
        }
    }
    runtime.block_on(handle.flush())?;
    let stats = handle.stats();
    if stats
        .samples_written
        .load(std::sync::atomic::Ordering::Relaxed)
        < written
    {
        bail!("the history did not take every change");
    }
    let bytes = std::fs::metadata(data_dir.join(gateway::store::DB_FILE)).map_or(0, |m| m.len());
    Ok(Stored {
        changes: written,
        points: devices.iter().map(Vec::len).sum(),
        took: started.elapsed(),
        bytes,
    })
}

/// Everything measured.
struct Report {
    args: Args,
    cores: usize,
    stored: Stored,
    /// From the publisher's start to its first message at the subscriber.
    first_after: Duration,
    /// From the publisher's start to the last historical metric at the subscriber.
    drain: Duration,
    /// What the subscriber received while draining (births included).
    received: Counts,
    gateway: ProcessUse,
    broker: ProcessUse,
    counter: ProcessUse,
    peak_reset: bool,
    load: String,
    published: u64,
    forwarded: u64,
    totals: Counts,
}

fn run(args: &Args) -> anyhow::Result<Report> {
    let ticks = ticks_per_second();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let dir = tempfile::tempdir().context("cannot create a temporary directory")?;
    let config_path = dir.path().join("cell.toml");
    std::fs::write(&config_path, config_text(args.devices))?;
    let config = gateway::check_config(&config_path)?;
    let data_dir = dir.path().join("data");
    std::fs::create_dir_all(&data_dir)?;
    // The same runtime as `cellbus serve`: multi-threaded, one worker per core.
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("cannot start the runtime")?;
    let store = Store::open(&data_dir, StoreOptions::default())?;
    let metrics = Arc::new(Metrics::new());
    // The line tasks are dropped, never run: nothing is polled.
    let (cell, _tasks) = gateway::scheduler::build(&config, store.handle(), Arc::clone(&metrics))
        .map_err(anyhow::Error::msg)?;
    let stored = store_backlog(&cell, &store, &data_dir, args, &runtime)?;

    let broker = testkit::Mosquitto::start();
    let mut counter = Counter::start(broker.port())?;
    let broker_pid = broker
        .pid()
        .context("mosquitto is not running")?
        .to_string();
    let counter_pid = counter.pid().to_string();
    let mut mqtt =
        MqttConfig::for_broker(&broker.url(), "backlogbench").map_err(anyhow::Error::msg)?;
    mqtt.max_backlog = stored.changes;

    let load = loadavg();
    let peak_reset = reset_peak_rss();
    let gateway_before = ProcessUse::of("self", ticks)?;
    let broker_before = ProcessUse::of(&broker_pid, ticks)?;
    let counter_before = ProcessUse::of(&counter_pid, ticks)?;
    let received_before = counter.counts()?;
    let (stop, stopped) = tokio::sync::watch::channel(false);
    let started_us = unix_micros();
    let started = Instant::now();
    let task = {
        let _entered = runtime.enter();
        gateway::northbound::mqtt::start(Arc::clone(&cell), mqtt, data_dir.clone(), false, stopped)?
    };
    let mut last = (received_before.historical, Instant::now());
    let received = loop {
        std::thread::sleep(POLL);
        let counts = counter.counts()?;
        if counts.historical >= stored.changes {
            break counts;
        }
        if counts.historical > last.0 {
            last = (counts.historical, Instant::now());
        } else if last.1.elapsed() > STALL_LIMIT {
            bail!(
                "the drain stalled: {} of {} historical metrics received after {:.1} s",
                counts.historical,
                stored.changes,
                started.elapsed().as_secs_f64()
            );
        }
    };
    let gateway_after = ProcessUse::of("self", ticks)?;
    let broker_after = ProcessUse::of(&broker_pid, ticks)?;
    let counter_after = ProcessUse::of(&counter_pid, ticks)?;
    let micros = |us: u64| Duration::from_micros(us.saturating_sub(started_us));
    let drain = micros(received.last_historical_us);
    let first_after = micros(received.first_us);
    // A graceful stop: the NDEATH, then DISCONNECT.
    let _ = stop.send(true);
    runtime
        .block_on(async { tokio::time::timeout(Duration::from_secs(10), task).await })
        .context("the MQTT task did not stop in 10 s")?
        .context("the MQTT task failed")?;
    let mqtt_metrics = &gateway::northbound::mqtt::status::status(&cell).metrics;
    let forwarded = mqtt_metrics.forwarded.get();
    let published_total = mqtt_metrics.published.get();
    let mut totals = counter.counts()?;
    for _ in 0..50 {
        std::thread::sleep(Duration::from_millis(100));
        let now = counter.counts()?;
        if now == totals && now.messages >= published_total {
            break;
        }
        totals = now;
    }
    drop(cell);
    runtime.shutdown_timeout(Duration::from_secs(5));
    store.close();
    Ok(Report {
        args: *args,
        cores,
        stored,
        first_after,
        drain,
        received: Counts {
            messages: received.messages - received_before.messages,
            bytes: received.bytes - received_before.bytes,
            metrics: received.metrics - received_before.metrics,
            ddata: received.ddata - received_before.ddata,
            historical: received.historical - received_before.historical,
            ..received
        },
        gateway: gateway_after.without(&gateway_before),
        broker: broker_after.without(&broker_before),
        counter: counter_after.without(&counter_before),
        peak_reset,
        load,
        published: published_total,
        forwarded,
        totals: Counts {
            messages: totals.messages - received_before.messages,
            ..totals
        },
    })
}

fn loadavg() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .map(|l| l.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|| "unknown".into())
}

fn mib(kib: u64) -> f64 {
    kib as f64 / 1024.0
}

impl std::fmt::Display for Report {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let secs = self.drain.as_secs_f64().max(1e-9);
        let share = |p: &ProcessUse| p.cpu.as_secs_f64() / secs;
        writeln!(f, "MQTT backlog drain benchmark")?;
        writeln!(
            f,
            "  backlog      {} stored changes of {} numeric points on {} JBC stations, {} per read, {} read(s) of a station in a row; written in {:.1} s, database {:.0} MB; machine: {} cores, load average {} before the drain",
            self.stored.changes,
            self.stored.points,
            self.args.devices,
            self.args.run,
            self.args.burst,
            self.stored.took.as_secs_f64(),
            self.stored.bytes as f64 / 1e6,
            self.cores,
            self.load
        )?;
        let r = &self.received;
        writeln!(
            f,
            "  drain        {:.2} s from the publisher's start to the last historical metric at the subscriber (first message after {:.0} ms): {:.0} historical metrics/s",
            secs,
            self.first_after.as_secs_f64() * 1000.0,
            r.historical as f64 / secs
        )?;
        writeln!(
            f,
            "  messages     {} received while draining ({} DDATA, {:.0} messages/s), {:.1} metrics and {:.0} B per DDATA on average, {} MB in all",
            r.messages,
            r.ddata,
            r.messages as f64 / secs,
            r.historical as f64 / r.ddata.max(1) as f64,
            r.bytes as f64 / r.messages.max(1) as f64,
            r.bytes / 1_000_000
        )?;
        writeln!(
            f,
            "  gateway      CPU {:.2} cores while draining ({:.0} % of the machine, {:.2} µs per metric), peak RSS {:.1} MiB{}",
            share(&self.gateway),
            share(&self.gateway) * 100.0 / self.cores as f64,
            self.gateway.cpu.as_secs_f64() * 1e6 / r.historical.max(1) as f64,
            mib(self.gateway.peak_rss_kib),
            if self.peak_reset {
                " (reset after writing the history)"
            } else {
                " (including writing the history: the peak could not be reset)"
            }
        )?;
        writeln!(
            f,
            "  others       mosquitto CPU {:.2} cores, peak RSS {:.1} MiB; subscriber CPU {:.2} cores (processes of their own)",
            share(&self.broker),
            mib(self.broker.peak_rss_kib),
            share(&self.counter)
        )?;
        writeln!(
            f,
            "  delivery     {} messages published, {} received ({} lost), {} undecodable; cellbus_mqtt_forwarded {}; broker's $SYS dropped count {}",
            self.published,
            self.totals.messages,
            self.published.saturating_sub(self.totals.messages),
            self.totals.bad,
            self.forwarded,
            self.totals.dropped
        )
    }
}
