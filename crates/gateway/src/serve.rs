//! `cellbus serve`: the whole gateway, from options to a graceful stop.

use std::future::Future;
use std::io::Write;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use tokio::sync::watch;

use crate::cell::{Cell, DeviceStatus, LiveMessage, NotRunning};
use crate::config::{CellConfig, SAME_TOKENS, check_config, token_fault};
use crate::demo::DemoCell;
use crate::event::{Event, EventKind};
use crate::http::{self, WritePolicy};
use crate::metrics::Metrics;
use crate::northbound::{Running, Start};
pub use crate::options::{
    DEFAULT_DATA_DIR, DEFAULT_LISTEN, DEFAULT_RETAIN, DEFAULT_RETAIN_AUDIT, OptionError,
    ServeOptions,
};
use crate::plugins::Registry;
use crate::pollers::Pollers;
use crate::reload::Reloader;
use crate::store::lock::{DataLock, LockError};
use crate::store::{HistoryState, Store, StoreOptions};
use crate::time::Timestamp;

/// Environment variable holding the write token.
pub const TOKEN_ENV: &str = "CELLBUS_TOKEN";
/// Environment variable holding the read token.
pub const READ_TOKEN_ENV: &str = "CELLBUS_READ_TOKEN";

/// How long line tasks get to finish their request at shutdown.
const STOP_GRACE: Duration = crate::pollers::STOP_GRACE;

/// Malloc arenas of the gateway's process. glibc's default, one for each thread that
/// allocates while another holds the lock (up to eight per core), kept a heap each for the
/// runtime's workers, the poller and the history writer, each with its own free memory:
/// one arena was about 1 MiB less at its peak with 1,000 stations, at the same CPU per poll
/// (`load` bench).
pub const MALLOC_ARENAS: u16 = 1;

/// Blocks of this size or more get their own `mmap`, returned to the kernel when freed.
/// glibc's default threshold starts here but rises to the size of each large block freed,
/// after which the growing vectors and hash tables of the cell and the history writer came
/// from the heap and left holes in it as they moved: fixed, the gateway's peak anonymous
/// memory was 1.2–1.5 MiB lower at 1,000 stations (`load` bench).
pub const MALLOC_MMAP_THRESHOLD: u32 = 128 << 10;

/// Sets malloc up for the gateway's process ([`MALLOC_ARENAS`], [`MALLOC_MMAP_THRESHOLD`]);
/// `false` where it could not be (not glibc). Call it first, before a runtime or any other
/// thread starts: a thread keeps the arena it was given. `cellbus serve` and the `load`
/// bench both do, so the bench measures what the binary does.
pub fn tune_malloc() -> bool {
    let arenas = malloc_tune::set_arena_max(MALLOC_ARENAS);
    let mmap = malloc_tune::set_mmap_threshold(MALLOC_MMAP_THRESHOLD);
    arenas && mmap
}

/// Runs the gateway with the device kinds and interfaces of `registry` until `shutdown`
/// resolves (Ctrl-C, SIGTERM), then stops the pollers, commits the history and returns.
///
/// Its first line on standard output, once the port is bound, is exactly
/// `listening on http://IP:PORT`; other tools wait for it. Each interface that listens
/// adds one, `NAME on URL` (OPC UA: `opcua on opc.tcp://IP:PORT`).
pub async fn serve(
    options: ServeOptions,
    registry: &Registry,
    shutdown: impl Future<Output = ()>,
) -> anyhow::Result<()> {
    let gateway = Gateway::start_with(options, registry).await?;
    {
        let mut out = std::io::stdout().lock();
        writeln!(out, "listening on http://{}", gateway.local_addr())
            .and_then(|()| {
                gateway
                    .interfaces
                    .iter()
                    .filter_map(|i| Some((i.name, i.url.as_ref()?)))
                    .try_for_each(|(name, url)| writeln!(out, "{name} on {url}"))
            })
            .and_then(|()| out.flush())
            .context("cannot write to standard output")?;
    }
    crate::service::ready(&format!("listening on http://{}", gateway.local_addr()));
    gateway.run(shutdown).await
}

/// A started gateway: port bound, history open, lines being polled.
#[derive(Debug)]
pub struct Gateway {
    listener: tokio::net::TcpListener,
    addr: SocketAddr,
    cell: Arc<Cell>,
    store: Store,
    writes: WritePolicy,
    stop: watch::Sender<bool>,
    pollers: Arc<Pollers>,
    reloader: Arc<Reloader>,
    /// `SIGHUP`s, caught from the start (its default would end the process), handled
    /// once the gateway runs.
    #[cfg(unix)]
    hangups: Option<tokio::signal::unix::Signal>,
    interfaces: Vec<Running>,
    _demo: Option<DemoCell>,
    _lock: Option<DataLock>,
}

impl Gateway {
    /// Reads the configuration (or starts the demo cell), starts the history, binds the
    /// port and starts polling.
    ///
    /// The history never stops the start: its file is opened and checked on its own
    /// thread; a damaged file is moved aside (a `history_reset` event names it), and a data
    /// directory that cannot be used turns the history off (a `history_failed` event,
    /// `/healthz` failing, history queries 503) while live values are served. A data
    /// directory another gateway holds is refused (see [`crate::store::lock`]).
    ///
    /// It has the gateway crate's own device kinds and interfaces
    /// ([`crate::plugins::builtin`]); [`Gateway::start_with`] takes others.
    pub async fn start(options: ServeOptions) -> anyhow::Result<Self> {
        Self::start_with(options, &crate::plugins::builtin()).await
    }

    /// [`Gateway::start`] with the device kinds and interfaces of `registry` (the
    /// binary's adds OPC UA; a test may add a kind of its own).
    pub async fn start_with(options: ServeOptions, registry: &Registry) -> anyhow::Result<Self> {
        let (config, demo) = match &options.config {
            Some(path) => {
                let config = check_config(path, &registry.config)?;
                for warning in config.warnings() {
                    tracing::warn!("{}: {warning}", path.display());
                }
                (config, None)
            }
            None => {
                let demo = DemoCell::start(&registry.demos)
                    .await
                    .context("cannot start the demo cell's simulators on 127.0.0.1")?;
                (demo.config.clone(), Some(demo))
            }
        };
        let writes = write_policy(&options, &config)?;
        let who = match &options.config {
            Some(path) => format!("cellbus serve --config {}", path.display()),
            None => "cellbus serve (the demo cell)".to_owned(),
        };
        // A directory that cannot be used turns the history off (the store says why).
        let lock = match DataLock::take(&options.data_dir, &who) {
            Ok(lock) => Some(lock),
            Err(held @ LockError::Held { .. }) => return Err(OptionError(held.to_string()).into()),
            Err(LockError::Unusable { .. }) => None,
        };
        let store = Store::start(
            &options.data_dir,
            StoreOptions {
                retain: options.retain,
                retain_audit: options.retain_audit,
                ..StoreOptions::default()
            },
        );
        let listener = bind(options.listen).await?;
        let addr = listener
            .local_addr()
            .context("cannot read the bound address")?;
        if let Some(warning) = exposure_warning(addr, &writes) {
            tracing::warn!("{warning}");
        }
        let metrics = Arc::new(Metrics::new());
        #[cfg(unix)]
        let hangups = match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::hangup()) {
            Ok(signal) => Some(signal),
            Err(e) => {
                tracing::warn!("cannot catch SIGHUP, so the configuration cannot be reloaded: {e}");
                None
            }
        };
        let (cell, tasks) = crate::scheduler::build(&config, store.handle(), metrics)
            .map_err(anyhow::Error::msg)?;
        // Lines asked for more polls than they can carry, from the drivers just built.
        if let Some(path) = &config.source {
            for (line, task) in config.lines.iter().zip(&tasks) {
                let Some(serial) = crate::load::serial_line(line) else {
                    continue;
                };
                if let Some(warning) = task.load(serial).warning() {
                    tracing::warn!("{}: {warning}", path.display());
                }
            }
        }
        cell.emit(Event::of_gateway(
            EventKind::GatewayStarted,
            format!(
                "gateway started on http://{addr} with {} (devices: {}, lines: {}); writes {}",
                match &config.source {
                    Some(path) => format!("config {}", path.display()),
                    None => "the demo cell".to_owned(),
                },
                config.lines.iter().map(|l| l.devices.len()).sum::<usize>(),
                config.lines.len(),
                if writes.enabled {
                    "enabled"
                } else {
                    "disabled"
                },
            ),
        ));
        report_history_off(&cell, options.data_dir.clone());
        // The states of the time this gateway did not see are unknown: marked before the
        // first poll.
        {
            let (cell, dir) = (Arc::clone(&cell), options.data_dir.clone());
            tokio::task::spawn_blocking(move || crate::production::keeper::close_gap(&cell, &dir))
                .await
                .context("the production keeper's start failed")?;
        }
        let (stop, stopped) = watch::channel(false);
        // The alarms as the history left them, before a poll or an interface sees them.
        crate::alarm::keeper::restore(&cell).await;
        let heartbeat = crate::service::Heartbeat::default();
        let pollers = Arc::new(Pollers::start(tasks, stopped.clone(), heartbeat.clone())?);
        let reloader = Arc::new(Reloader::new(
            Arc::clone(&cell),
            Arc::clone(&pollers),
            registry.config.clone(),
            Arc::new(crate::scheduler::line_opener),
            config.clone(),
        ));
        tokio::spawn(crate::service::watchdog(
            heartbeat,
            cell.store().clone(),
            stopped.clone(),
        ));
        tokio::spawn(crate::alarm::keeper::run(
            Arc::clone(&cell),
            stopped.clone(),
        ));
        tokio::spawn(crate::production::keeper::run(
            Arc::clone(&cell),
            options.data_dir.clone(),
            stopped.clone(),
        ));
        tokio::spawn(first_round(Arc::clone(&cell)));
        // Every interface this gateway has shows in `/healthz`: `null` until it runs.
        for interface in &registry.interfaces {
            cell.set_interface(interface.name(), Arc::new(NotRunning), false);
        }
        let mut interfaces = Vec::new();
        for interface in &registry.interfaces {
            let start = Start {
                cell: &cell,
                config: &config,
                options: &options,
                demo: demo.is_some(),
                writes: &writes,
                stopped: stopped.clone(),
            };
            if let Some(running) = interface.start(start).await? {
                interfaces.push(running);
            }
        }
        Ok(Self {
            listener,
            addr,
            cell,
            store,
            writes,
            stop,
            pollers,
            reloader,
            #[cfg(unix)]
            hangups,
            interfaces,
            _demo: demo,
            _lock: lock,
        })
    }

    /// Reloads the configuration (what `SIGHUP` does): see [`crate::reload`].
    pub fn reloader(&self) -> &Arc<Reloader> {
        &self.reloader
    }

    /// The address the gateway listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Where clients reach the interface `name` (`opcua`), when it runs and listens.
    pub fn url_of(&self, name: &str) -> Option<&str> {
        self.interfaces
            .iter()
            .find(|i| i.name == name)
            .and_then(|i| i.url.as_deref())
    }

    /// The live cell.
    pub fn cell(&self) -> &Arc<Cell> {
        &self.cell
    }

    /// Serves HTTP until `shutdown` resolves, then stops polling and commits the history.
    pub async fn run(self, shutdown: impl Future<Output = ()>) -> anyhow::Result<()> {
        let Gateway {
            listener,
            cell,
            store,
            writes,
            stop,
            pollers,
            reloader,
            #[cfg(unix)]
            hangups,
            interfaces,
            _demo,
            // Held until the history is committed and the gateway has stopped.
            _lock,
            ..
        } = self;
        #[cfg(unix)]
        if let Some(hangups) = hangups {
            tokio::spawn(crate::reload::on_hangup(
                reloader,
                hangups,
                stop.subscribe(),
            ));
        }
        #[cfg(not(unix))]
        drop(reloader);
        let app = http::router(Arc::clone(&cell), writes, stop.subscribe());
        let server = http::server::serve(
            listener,
            app,
            http::server::Limits::default(),
            stop.subscribe(),
        );
        tokio::pin!(server);
        let served = tokio::select! {
            served = &mut server => served,
            () = shutdown => {
                crate::service::stopping();
                // Ends the event streams and starts the graceful stop of the server.
                let _ = stop.send(true);
                server.await
            }
        };
        let _ = stop.send(true);
        if !pollers.stopped(STOP_GRACE).await {
            tracing::warn!("the line tasks did not stop in {STOP_GRACE:?}");
        }
        for interface in interfaces {
            if tokio::time::timeout(STOP_GRACE, interface.task)
                .await
                .is_err()
            {
                tracing::warn!(
                    "the {} interface did not stop in {STOP_GRACE:?}",
                    interface.name
                );
            }
        }
        cell.emit(Event::of_gateway(
            EventKind::GatewayStopped,
            "gateway stopped".to_owned(),
        ));
        let flushed = cell.store().flush().await;
        // With the history off there is nothing to commit; its start already said why.
        let history_off = matches!(
            cell.store().health(Timestamp::now()).history,
            HistoryState::Off(_)
        );
        drop(cell);
        tokio::task::spawn_blocking(move || store.close())
            .await
            .context("the history writer did not stop cleanly")?;
        served.context("the HTTP server failed")?;
        if !history_off {
            flushed.context("the history could not be committed at shutdown")?;
        }
        Ok(())
    }
}

/// The first round's summary is logged at the latest this long after the start, naming the
/// devices that have not answered yet.
pub const FIRST_ROUND_LIMIT: Duration = Duration::from_secs(60);

/// Waits for the first round of polls and logs which devices answer (at the latest after
/// [`FIRST_ROUND_LIMIT`]).
async fn first_round(cell: Arc<Cell>) {
    use tokio::sync::broadcast::error::RecvError;
    let mut live = cell.subscribe();
    let deadline = tokio::time::Instant::now() + FIRST_ROUND_LIMIT;
    // Counted again only when a device's status may have changed: value changes, most of
    // the stream, pass by.
    let mut waiting = undecided(&cell);
    while waiting {
        match tokio::time::timeout_at(deadline, live.recv()).await {
            Ok(Ok(LiveMessage::Device(_)) | Err(RecvError::Lagged(_))) => {
                waiting = undecided(&cell);
            }
            Ok(Ok(_)) => {}
            Ok(Err(RecvError::Closed)) | Err(_) => break,
        }
    }
    let (level, line) = first_round_line(&cell);
    if level == tracing::Level::WARN {
        tracing::warn!("{line}");
    } else {
        tracing::info!("{line}");
    }
}

/// Whether a device has not been polled yet.
fn undecided(cell: &Cell) -> bool {
    cell.device_entries()
        .any(|d| d.read().status == DeviceStatus::Connecting)
}

/// The first round's line, and its level (a warning when a device does not answer).
pub fn first_round_line(cell: &Cell) -> (tracing::Level, String) {
    let mut up = Vec::new();
    let mut not = Vec::new();
    for device in cell.device_entries() {
        let summary = device.summary();
        match (summary.status, &summary.error) {
            (DeviceStatus::Up, _) => up.push(device.id.to_string()),
            (_, Some(error)) => not.push(format!(
                "{} on line {}: {}",
                device.id,
                device.line,
                crate::oplog::describe(error, device.protocol.hint(error.kind))
            )),
            (_, None) => not.push(format!(
                "{} on line {}: no answer yet after {} s",
                device.id,
                device.line,
                FIRST_ROUND_LIMIT.as_secs()
            )),
        }
    }
    let total = up.len() + not.len();
    if not.is_empty() {
        return (tracing::Level::INFO, format!("all {total} devices answer"));
    }
    let answering = if up.is_empty() {
        String::new()
    } else {
        format!(" ({})", up.join(", "))
    };
    (
        tracing::Level::WARN,
        format!(
            "{} of {total} devices answer{answering}; not answering: {}",
            up.len(),
            not.join("; ")
        ),
    )
}

/// Once the history has opened (or failed to), emits a `history_failed` event if it is off,
/// so the event stream and the log say so; polling does not wait for it.
fn report_history_off(cell: &Arc<Cell>, data_dir: PathBuf) {
    let cell = Arc::clone(cell);
    tokio::task::spawn_blocking(move || {
        // Waits (bounded) for the writer's open.
        let _ = cell.store().wait_open();
        let HistoryState::Off(reason) = cell.store().health(Timestamp::now()).history else {
            return;
        };
        cell.emit(Event::of_gateway(
            EventKind::HistoryFailed,
            format!(
                "history is off (data directory {}): {reason}; live values are served but not \
                 stored; fix the data directory and restart",
                data_dir.display()
            ),
        ));
    });
}

/// What to tell the user who listens beyond this machine: every read route (values,
/// history, the audit log with client addresses, the lines' endpoints) answers anyone who
/// can reach the port, and without a token nobody can write but nobody is kept out either.
pub fn exposure_warning(addr: SocketAddr, writes: &http::WritePolicy) -> Option<String> {
    if addr.ip().is_loopback() {
        return None;
    }
    if writes.read_token.is_some() {
        return None;
    }
    let writes = match (&writes.enabled, &writes.token) {
        (true, Some(_)) => "writes need the token",
        _ => "writes are off",
    };
    Some(format!(
        "listening on {addr}, beyond this machine: the API and the page (values, history, the \
         audit log with client addresses, the lines' endpoints) answer anyone who can reach \
         this port ({writes}); set a read token ({READ_TOKEN_ENV} or read_token in the \
         config) to require one, or keep it behind a firewall"
    ))
}

/// Binds the listening port, saying what to do when it is taken.
async fn bind(addr: SocketAddr) -> anyhow::Result<tokio::net::TcpListener> {
    tokio::net::TcpListener::bind(addr).await.map_err(|e| {
        let hint = match e.kind() {
            std::io::ErrorKind::AddrInUse => format!(
                "port {} is already in use (another cellbus serve, or another program); \
                 choose another with --listen, e.g. --listen 127.0.0.1:0 for any free port",
                addr.port()
            ),
            std::io::ErrorKind::PermissionDenied => format!(
                "permission denied; ports below 1024 need privileges: try --listen {}:8080, \
                 or --listen 127.0.0.1:0 for any free port",
                addr.ip()
            ),
            std::io::ErrorKind::AddrNotAvailable => format!(
                "{} is not an address of this machine; try --listen 127.0.0.1:0",
                addr.ip()
            ),
            _ => "try --listen 127.0.0.1:0 for any free port".to_owned(),
        };
        anyhow::anyhow!("cannot listen on {addr}: {e}; {hint}")
    })
}

/// Who may write: `--allow-writes` and a token from the options, the environment or the
/// config, in that order.
fn write_policy(options: &ServeOptions, config: &CellConfig) -> Result<WritePolicy, OptionError> {
    let token = options
        .token
        .clone()
        .or_else(|| std::env::var(TOKEN_ENV).ok())
        .or_else(|| config.token.clone())
        .map(|t| t.trim().to_owned());
    check_token(token.as_deref(), "write token", TOKEN_ENV, "token")?;
    if options.allow_writes && token.is_none() {
        return Err(OptionError(format!(
            "--allow-writes needs a token for clients to send as Authorization: Bearer <token>; \
             set {TOKEN_ENV} or token = \"...\" in the config"
        )));
    }
    let read_token = options
        .read_token
        .clone()
        .or_else(|| std::env::var(READ_TOKEN_ENV).ok())
        .or_else(|| config.read_token.clone())
        .map(|t| t.trim().to_owned());
    check_token(
        read_token.as_deref(),
        "read token",
        READ_TOKEN_ENV,
        "read_token",
    )?;
    if token.is_some() && read_token == token {
        return Err(OptionError(SAME_TOKENS.to_owned()));
    }
    Ok(WritePolicy {
        enabled: options.allow_writes,
        token,
        read_token,
    })
}

/// Refuses an empty token, or one no client could send.
fn check_token(token: Option<&str>, what: &str, env: &str, key: &str) -> Result<(), OptionError> {
    let Some(token) = token else {
        return Ok(());
    };
    if token.is_empty() {
        return Err(OptionError(format!(
            "the {what} is empty; set a non-empty {env} or {key} in the config"
        )));
    }
    match token_fault(token) {
        Some(fault) => Err(OptionError(format!("the {what} cannot be used: {fault}"))),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn listening_beyond_loopback_is_warned_about_and_loopback_is_not() {
        let off = http::WritePolicy {
            enabled: false,
            token: None,
            read_token: None,
        };
        assert_eq!(
            exposure_warning("127.0.0.1:8080".parse().unwrap(), &off),
            None
        );
        let warning = exposure_warning("0.0.0.0:8080".parse().unwrap(), &off).unwrap();
        assert!(warning.contains("beyond this machine"), "{warning}");
        assert!(warning.contains("audit log"), "{warning}");
    }
}
