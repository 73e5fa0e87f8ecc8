//! A counting Sparkplug B subscriber for the MQTT benches, in a process of its own so
//! that the gateway's CPU share is the gateway's alone.
//!
//! The bench re-executes itself with [`FLAG`] `PORT`: that child connects to the broker
//! on 127.0.0.1:`PORT` (rumqttc, clean session), subscribes to `spBv1.0/#` and to
//! mosquitto's `$SYS/broker/publish/messages/dropped` with QoS 0, decodes every payload
//! with the `sparkplug` crate's protobuf types (prost) and counts messages, metrics and
//! historical metrics; nothing else. It prints `ready` once the broker acknowledged both
//! subscriptions, then answers each line on its standard input with one line of counts,
//! and ends when its standard input closes. [`Counter`] is the parent's side.

use std::io::{BufRead, Write};
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use anyhow::{Context, bail};

use super::helper::{Helper, numbers};
use prost::Message as _;
use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};
use sparkplug::proto::Payload;

/// The flag (followed by the broker's port) that makes the process the counter.
pub const FLAG: &str = "--mqtt-counter";
/// mosquitto's count of messages it dropped (QoS 0 to a client whose queue is full, …);
/// updated every `sys_interval` (10 s by default).
const DROPPED_TOPIC: &str = "$SYS/broker/publish/messages/dropped";
const READY: &str = "ready";

/// What the counter saw since it subscribed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counts {
    /// Sparkplug messages (every kind).
    pub messages: u64,
    /// Their payload bytes.
    pub bytes: u64,
    /// Metrics in them.
    pub metrics: u64,
    /// DDATA messages.
    pub ddata: u64,
    /// Metrics with `is_historical`.
    pub historical: u64,
    /// Payloads that did not decode.
    pub bad: u64,
    /// mosquitto's dropped-message count at its last `$SYS` update.
    pub dropped: u64,
    /// When the last historical metric arrived, µs since the Unix epoch (0: none yet).
    pub last_historical_us: u64,
    /// When the first message arrived, µs since the Unix epoch (0: none yet).
    pub first_us: u64,
}

impl Counts {
    const FIELDS: usize = 9;

    fn line(&self) -> String {
        format!(
            "{} {} {} {} {} {} {} {} {}",
            self.messages,
            self.bytes,
            self.metrics,
            self.ddata,
            self.historical,
            self.bad,
            self.dropped,
            self.last_historical_us,
            self.first_us
        )
    }

    fn parse(line: &str) -> Option<Self> {
        let n = numbers(line)?;
        if n.len() != Self::FIELDS {
            return None;
        }
        Some(Self {
            messages: n[0],
            bytes: n[1],
            metrics: n[2],
            ddata: n[3],
            historical: n[4],
            bad: n[5],
            dropped: n[6],
            last_historical_us: n[7],
            first_us: n[8],
        })
    }
}

/// Microseconds since the Unix epoch (the clock both processes share).
pub fn unix_micros() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX))
}

#[derive(Default)]
struct Shared {
    messages: AtomicU64,
    bytes: AtomicU64,
    metrics: AtomicU64,
    ddata: AtomicU64,
    historical: AtomicU64,
    bad: AtomicU64,
    dropped: AtomicU64,
    last_historical_us: AtomicU64,
    first_us: AtomicU64,
}

impl Shared {
    fn counts(&self) -> Counts {
        let get = |a: &AtomicU64| a.load(Ordering::Relaxed);
        Counts {
            messages: get(&self.messages),
            bytes: get(&self.bytes),
            metrics: get(&self.metrics),
            ddata: get(&self.ddata),
            historical: get(&self.historical),
            bad: get(&self.bad),
            dropped: get(&self.dropped),
            last_historical_us: get(&self.last_historical_us),
            first_us: get(&self.first_us),
        }
    }

    fn count(&self, topic: &str, payload: &[u8]) {
        if topic == DROPPED_TOPIC {
            if let Some(n) = std::str::from_utf8(payload)
                .ok()
                .and_then(|t| t.trim().parse().ok())
            {
                self.dropped.store(n, Ordering::Relaxed);
            }
            return;
        }
        let now = unix_micros();
        let _ = self
            .first_us
            .compare_exchange(0, now, Ordering::Relaxed, Ordering::Relaxed);
        self.messages.fetch_add(1, Ordering::Relaxed);
        self.bytes
            .fetch_add(payload.len() as u64, Ordering::Relaxed);
        if topic.split('/').nth(2) == Some("DDATA") {
            self.ddata.fetch_add(1, Ordering::Relaxed);
        }
        let Ok(decoded) = Payload::decode(payload) else {
            self.bad.fetch_add(1, Ordering::Relaxed);
            return;
        };
        let historical = decoded
            .metrics
            .iter()
            .filter(|m| m.is_historical == Some(true))
            .count() as u64;
        self.metrics
            .fetch_add(decoded.metrics.len() as u64, Ordering::Relaxed);
        if historical > 0 {
            self.historical.fetch_add(historical, Ordering::Relaxed);
            self.last_historical_us.store(now, Ordering::Relaxed);
        }
    }
}

/// The child process: counts until its standard input closes.
pub fn run(port: u16) -> anyhow::Result<()> {
    let shared = Arc::new(Shared::default());
    let (ready_tx, ready_rx) = std::sync::mpsc::channel::<()>();
    let counting = Arc::clone(&shared);
    std::thread::Builder::new()
        .name("mqtt-counter".into())
        .spawn(move || {
            let runtime = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .expect("the counter's runtime");
            runtime.block_on(subscribe(port, counting, ready_tx));
        })
        .context("cannot start the counter's thread")?;
    ready_rx
        .recv_timeout(Duration::from_secs(30))
        .context("the broker did not acknowledge the counter's subscriptions in 30 s")?;
    let mut stdout = std::io::stdout().lock();
    writeln!(stdout, "{READY}")?;
    stdout.flush()?;
    for line in std::io::stdin().lock().lines() {
        if line.is_err() {
            break;
        }
        writeln!(stdout, "{}", shared.counts().line())?;
        stdout.flush()?;
    }
    Ok(())
}

async fn subscribe(port: u16, shared: Arc<Shared>, ready: std::sync::mpsc::Sender<()>) {
    let mut options = MqttOptions::new(
        format!("cellbus-bench-counter-{}", std::process::id()),
        "127.0.0.1",
        port,
    );
    options
        .set_clean_session(true)
        .set_keep_alive(Duration::from_secs(30))
        .set_max_packet_size(64 << 20, 64 << 20);
    let (client, mut eventloop) = AsyncClient::new(options, 16);
    let mut acks = 0;
    loop {
        match eventloop.poll().await {
            Ok(Event::Incoming(Packet::ConnAck(_))) => {
                for filter in ["spBv1.0/#", DROPPED_TOPIC] {
                    let _ = client.try_subscribe(filter, QoS::AtMostOnce);
                }
            }
            Ok(Event::Incoming(Packet::SubAck(_))) => {
                acks += 1;
                if acks == 2 {
                    let _ = ready.send(());
                }
            }
            Ok(Event::Incoming(Packet::Publish(p))) => shared.count(&p.topic, &p.payload),
            Ok(_) => {}
            Err(e) => {
                eprintln!("mqtt counter: {e}");
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
        }
    }
}

/// The parent's side: the counter process, ended when dropped.
pub struct Counter {
    helper: Helper,
}

impl Counter {
    /// Starts the counter on the broker at 127.0.0.1:`port` and waits until it is
    /// subscribed.
    pub fn start(port: u16) -> anyhow::Result<Self> {
        let exe = std::env::current_exe().context("cannot find the bench's own executable")?;
        let mut command = Command::new(exe);
        command.args([FLAG.to_owned(), port.to_string()]);
        let mut helper = Helper::start(command, "MQTT counter")?;
        let line = helper.read_line()?;
        if line != READY {
            bail!("the MQTT counter did not start (it said {line:?})");
        }
        Ok(Self { helper })
    }

    /// What it counted so far.
    pub fn counts(&mut self) -> anyhow::Result<Counts> {
        let line = self.helper.ask("?")?;
        Counts::parse(&line).with_context(|| format!("unexpected counts {line:?}"))
    }

    /// Its process id.
    pub fn pid(&self) -> u32 {
        self.helper.pid()
    }
}

/// When `args` make this process the counter child (`FLAG PORT`): runs it and gives the
/// exit code (`bench` names the bench in an error).
pub fn run_if_asked(args: &[String], bench: &str) -> Option<std::process::ExitCode> {
    let counted = port_in(args)?.map_err(anyhow::Error::msg).and_then(run);
    Some(match counted {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{bench}: MQTT counter: {e:#}");
            std::process::ExitCode::from(1)
        }
    })
}

/// The child's arguments: `FLAG PORT` anywhere in `args`.
pub fn port_in(args: &[String]) -> Option<Result<u16, String>> {
    let at = args.iter().position(|a| a == FLAG)?;
    Some(
        args.get(at + 1)
            .and_then(|p| p.parse().ok())
            .ok_or_else(|| format!("{FLAG} needs the broker's port")),
    )
}
