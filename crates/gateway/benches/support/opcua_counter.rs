//! A counting OPC UA subscriber for the load bench, in a process of its own so that the
//! gateway's CPU share is the gateway's alone.
//!
//! The bench re-executes itself with [`FLAG`] `URL ITEMS`: that child connects to the
//! gateway's OPC UA server (async-opcua's client, security None, anonymous), reads the
//! point ids in the file `ITEMS` (one a line), and monitors each point's value: one
//! subscription per [`ITEMS_PER_SUBSCRIPTION`] points (async-opcua's default limits: 1,000
//! monitored items a subscription and a call, 10 subscriptions a session), publishing
//! every [`PUBLISHING_INTERVAL`], sampling interval 0 (every change), queue of 10,
//! trigger StatusValue. It
//! counts the data-change notifications and how long after its source time each arrived
//! (the delay, in a histogram of milliseconds), and keeps each one's source time. It prints
//! `ready N` (N items created) once every item is created, then answers each line on its
//! standard input: `reset` empties the delay histogram (the initial values arrive first),
//! `between FROM TO` gets the notifications whose source time (ms since 1970) is in
//! `[FROM, TO)` (to set against the history's changes of the same window), anything else
//! gets one line of counts. It ends when its standard input closes. [`Counter`] is the
//! parent's side.

use std::io::{BufRead, Write};
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use anyhow::{Context, bail};

use super::helper::{Helper, numbers};
use opcua::client::{ClientBuilder, DataChangeCallback, IdentityToken};
use opcua::crypto::SecurityPolicy;
use opcua::types::{
    DataChangeFilter, DataChangeTrigger, DataValue, ExtensionObject, MessageSecurityMode,
    MonitoredItemCreateRequest, MonitoringMode, MonitoringParameters, NodeId, ReadValueId,
    TimestampsToReturn, UserTokenPolicy,
};

/// The flag (followed by the endpoint URL and the items file) that makes the process the
/// counter.
pub const FLAG: &str = "--opcua-counter";
/// Monitored items per subscription (and per CreateMonitoredItems call).
pub const ITEMS_PER_SUBSCRIPTION: usize = 1000;
/// How often each subscription publishes.
pub const PUBLISHING_INTERVAL: Duration = Duration::from_millis(500);
/// The sampling interval asked for: as fast as the server samples (every change the
/// gateway reads, whatever the poll period; `--live-period` may be below 1 s).
const SAMPLING_MS: f64 = 0.0;
/// The delay histogram's range, in milliseconds (later ones count in the last bucket).
const DELAY_BUCKETS: usize = 10_000;
const READY: &str = "ready";

/// What the counter saw.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counts {
    /// Data-change notifications since the items were created (initial values included).
    pub notifications: u64,
    /// Notifications in the delay histogram (since the last `reset`).
    pub timed: u64,
    /// Median delay from source time to arrival, ms.
    pub p50_ms: u64,
    /// 99th percentile of the delay, ms.
    pub p99_ms: u64,
    /// The longest delay, ms.
    pub max_ms: u64,
}

impl Counts {
    fn line(&self) -> String {
        format!(
            "{} {} {} {} {}",
            self.notifications, self.timed, self.p50_ms, self.p99_ms, self.max_ms
        )
    }

    fn parse(line: &str) -> Option<Self> {
        let n = numbers(line)?;
        let [notifications, timed, p50_ms, p99_ms, max_ms] = n[..] else {
            return None;
        };
        Some(Self {
            notifications,
            timed,
            p50_ms,
            p99_ms,
            max_ms,
        })
    }
}

struct Shared {
    notifications: AtomicU64,
    delays: Vec<AtomicU64>,
    /// Each notification's source time, ms since 1970.
    sources: std::sync::Mutex<Vec<i64>>,
}

impl Shared {
    fn new() -> Self {
        Self {
            notifications: AtomicU64::new(0),
            delays: (0..DELAY_BUCKETS).map(|_| AtomicU64::new(0)).collect(),
            sources: std::sync::Mutex::new(Vec::new()),
        }
    }

    fn count(&self, value: &DataValue) {
        self.notifications.fetch_add(1, Ordering::Relaxed);
        let Some(source) = value.source_timestamp else {
            return;
        };
        self.sources
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .push(source.as_chrono().timestamp_millis());
        let now = opcua::types::DateTime::now();
        let delay_ms = (now.checked_ticks() - source.checked_ticks()).max(0) / 10_000;
        let bucket =
            usize::try_from(delay_ms).map_or(DELAY_BUCKETS - 1, |d| d.min(DELAY_BUCKETS - 1));
        self.delays[bucket].fetch_add(1, Ordering::Relaxed);
    }

    fn between(&self, from: i64, to: i64) -> u64 {
        let sources = self
            .sources
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        sources.iter().filter(|t| (from..to).contains(*t)).count() as u64
    }

    fn reset(&self) {
        for bucket in &self.delays {
            bucket.store(0, Ordering::Relaxed);
        }
    }

    fn counts(&self) -> Counts {
        let delays: Vec<u64> = self
            .delays
            .iter()
            .map(|b| b.load(Ordering::Relaxed))
            .collect();
        let timed: u64 = delays.iter().sum();
        let rank = |p: f64| {
            let want = ((timed as f64) * p).ceil().max(1.0) as u64;
            let mut seen = 0;
            for (ms, n) in delays.iter().enumerate() {
                seen += n;
                if seen >= want {
                    return ms as u64;
                }
            }
            0
        };
        Counts {
            notifications: self.notifications.load(Ordering::Relaxed),
            timed,
            p50_ms: rank(0.5),
            p99_ms: rank(0.99),
            max_ms: delays.iter().rposition(|n| *n > 0).unwrap_or(0) as u64,
        }
    }
}

/// The child process: subscribes, then counts until its standard input closes.
pub fn run(url: &str, items: &str) -> anyhow::Result<()> {
    let points: Vec<String> = std::fs::read_to_string(items)
        .with_context(|| format!("cannot read the items file {items}"))?
        .lines()
        .map(str::to_owned)
        .collect();
    let shared = Arc::new(Shared::new());
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .context("the counter's runtime")?;
    let pki = tempfile::tempdir().context("a directory for the client's PKI")?;
    let created = runtime.block_on(subscribe(url, &points, pki.path(), Arc::clone(&shared)))?;
    let mut stdout = std::io::stdout().lock();
    writeln!(stdout, "{READY} {created}")?;
    stdout.flush()?;
    for line in std::io::stdin().lock().lines() {
        let Ok(line) = line else { break };
        let words: Vec<&str> = line.split_whitespace().collect();
        if let ["between", from, to] = words[..] {
            let (from, to) = (from.parse().unwrap_or(0), to.parse().unwrap_or(0));
            writeln!(stdout, "{}", shared.between(from, to))?;
            stdout.flush()?;
            continue;
        }
        if line.trim() == "reset" {
            shared.reset();
        }
        writeln!(stdout, "{}", shared.counts().line())?;
        stdout.flush()?;
    }
    runtime.shutdown_background();
    Ok(())
}

/// Connects and creates the monitored items; returns how many were created. The session
/// lives on in the runtime's tasks.
async fn subscribe(
    url: &str,
    points: &[String],
    pki: &std::path::Path,
    shared: Arc<Shared>,
) -> anyhow::Result<usize> {
    let mut client = ClientBuilder::new()
        .application_name("cellbus load bench counter")
        .application_uri("urn:cellbus:bench:counter")
        .product_uri("urn:cellbus:bench:counter")
        .pki_dir(pki)
        .create_sample_keypair(false)
        .trust_server_certs(true)
        .session_retry_limit(3)
        // A publish response carries every notification a subscription queued: far more
        // than async-opcua's default limit of 1,000 array elements and 5 chunks.
        .max_array_length(1 << 20)
        .max_message_size(64 << 20)
        .max_chunk_count(4096)
        .client()
        .map_err(|e| anyhow::anyhow!("the OPC UA client's configuration: {}", e.join(", ")))?;
    let (session, event_loop) = client
        .connect_to_matching_endpoint(
            (
                url,
                SecurityPolicy::None.to_str(),
                MessageSecurityMode::None,
                UserTokenPolicy::anonymous(),
            ),
            IdentityToken::Anonymous,
        )
        .await
        .with_context(|| format!("cannot connect to {url}"))?;
    event_loop.spawn();
    if !tokio::time::timeout(Duration::from_secs(30), session.wait_for_connection())
        .await
        .unwrap_or(false)
    {
        bail!("no OPC UA session with {url} in 30 s");
    }
    let ns = session
        .get_namespace_index(cellbus_opcua::space::NAMESPACE_URI)
        .await
        .context("the cell's namespace")?;
    let mut created = 0;
    for (chunk, points) in points.chunks(ITEMS_PER_SUBSCRIPTION).enumerate() {
        let counting = Arc::clone(&shared);
        let subscription = session
            .create_subscription(
                PUBLISHING_INTERVAL,
                60,
                10,
                0,
                0,
                true,
                DataChangeCallback::new(move |value, _item| counting.count(&value)),
            )
            .await
            .with_context(|| format!("subscription {chunk}"))?;
        let requests: Vec<MonitoredItemCreateRequest> = points
            .iter()
            .enumerate()
            .map(|(i, point)| MonitoredItemCreateRequest {
                item_to_monitor: ReadValueId::from(NodeId::new(ns, point.clone())),
                monitoring_mode: MonitoringMode::Reporting,
                requested_parameters: MonitoringParameters {
                    client_handle: (chunk * ITEMS_PER_SUBSCRIPTION + i) as u32 + 1,
                    sampling_interval: SAMPLING_MS,
                    // OPC UA's default trigger, said explicitly: without a filter,
                    // async-opcua 0.19 reports value changes only (not Good → stale).
                    filter: ExtensionObject::from_message(DataChangeFilter {
                        trigger: DataChangeTrigger::StatusValue,
                        deadband_type: 0,
                        deadband_value: 0.0,
                    }),
                    queue_size: 10,
                    discard_oldest: true,
                },
            })
            .collect();
        let results = session
            .create_monitored_items(subscription, TimestampsToReturn::Both, requests)
            .await
            .with_context(|| format!("the monitored items of subscription {chunk}"))?;
        created += results
            .iter()
            .filter(|r| r.result.status_code.is_good())
            .count();
    }
    Ok(created)
}

/// The parent's side: the counter process, ended when dropped.
pub struct Counter {
    helper: Helper,
    /// Monitored items the server created.
    pub created: usize,
}

impl Counter {
    /// Starts the counter on the server at `url` for the points in the file `items` and
    /// waits until its items are created.
    pub fn start(url: &str, items: &std::path::Path) -> anyhow::Result<Self> {
        let exe = std::env::current_exe().context("cannot find the bench's own executable")?;
        let mut command = Command::new(exe);
        command.arg(FLAG).arg(url).arg(items);
        let mut helper = Helper::start(command, "OPC UA counter")?;
        let line = helper.read_line()?;
        let created = line
            .strip_prefix(READY)
            .and_then(|n| n.trim().parse().ok())
            .with_context(|| format!("the OPC UA counter did not start (it said {line:?})"))?;
        Ok(Self { helper, created })
    }

    /// What it counted so far; `reset` empties the delay histogram first.
    pub fn counts(&mut self, reset: bool) -> anyhow::Result<Counts> {
        let line = self.helper.ask(if reset { "reset" } else { "?" })?;
        Counts::parse(&line).with_context(|| format!("unexpected counts {line:?}"))
    }

    /// Notifications whose source time (ms since 1970) is in `[from, to)`, once what the
    /// server sent has arrived: after two publishing intervals and a second, then once the
    /// count stops moving, waiting at most `limit`. Ask while the server still runs.
    pub fn settled_between(&mut self, from: i64, to: i64, limit: Duration) -> anyhow::Result<u64> {
        let deadline = std::time::Instant::now() + limit;
        std::thread::sleep(2 * PUBLISHING_INTERVAL + Duration::from_secs(1));
        let mut last = self.between(from, to)?;
        loop {
            std::thread::sleep(PUBLISHING_INTERVAL);
            let now = self.between(from, to)?;
            if now == last || std::time::Instant::now() > deadline {
                return Ok(now);
            }
            last = now;
        }
    }

    fn between(&mut self, from: i64, to: i64) -> anyhow::Result<u64> {
        let line = self.helper.ask(&format!("between {from} {to}"))?;
        line.parse()
            .with_context(|| format!("unexpected count {line:?}"))
    }

    /// Its process id.
    pub fn pid(&self) -> u32 {
        self.helper.pid()
    }
}

/// When `args` make this process the counter child (`FLAG URL ITEMS`): runs it and gives
/// the exit code.
pub fn run_if_asked(args: &[String], bench: &str) -> Option<std::process::ExitCode> {
    let at = args.iter().position(|a| a == FLAG)?;
    let counted = match (args.get(at + 1), args.get(at + 2)) {
        (Some(url), Some(items)) => run(url, items),
        _ => Err(anyhow::anyhow!(
            "{FLAG} needs the endpoint URL and the items file"
        )),
    };
    Some(match counted {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{bench}: OPC UA counter: {e:#}");
            std::process::ExitCode::from(1)
        }
    })
}
