//! `cellbus serve`: the whole gateway, from options to a graceful stop.

use std::future::Future;
use std::io::Write;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use tokio::sync::watch;
use tokio::task::JoinHandle;

use crate::cell::Cell;
use crate::config::{
    CellConfig, MqttConfig, MqttMode, OpcuaConfig, OpcuaSecurity, check_config,
    default_edge_node_id, parse_broker,
};
use crate::demo::DemoCell;
use crate::event::{Event, EventKind};
use crate::http::{self, WritePolicy};
use crate::metrics::Metrics;
use crate::northbound;
use crate::scheduler::LineTask;
use crate::store::{HistoryState, Store, StoreOptions};
use crate::time::Timestamp;

/// Address the gateway listens on by default: loopback only.
pub const DEFAULT_LISTEN: SocketAddr =
    SocketAddr::new(std::net::IpAddr::V4(std::net::Ipv4Addr::LOCALHOST), 8080);

/// Data directory by default, relative to the working directory.
pub const DEFAULT_DATA_DIR: &str = "cellbus-data";

/// History kept by default: 30 days.
pub const DEFAULT_RETAIN: Duration = Duration::from_secs(30 * 24 * 3600);

/// Audit rows kept by default: 365 days (never less than the history).
pub const DEFAULT_RETAIN_AUDIT: Duration = Duration::from_secs(365 * 24 * 3600);

/// The demo cell's Sparkplug edge node id (its group is `cellbus`).
pub const DEMO_EDGE_NODE: &str = "demo";

/// A mistake in the options `cellbus serve` was given (the CLI exits 2 for it), as opposed
/// to a failure to start (a port in use, a data directory that cannot be made).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct OptionError(pub String);

/// Environment variable holding the write token.
pub const TOKEN_ENV: &str = "CELLBUS_TOKEN";
/// Environment variable holding the read token.
pub const READ_TOKEN_ENV: &str = "CELLBUS_READ_TOKEN";

/// How long line tasks get to finish their request at shutdown.
const STOP_GRACE: Duration = Duration::from_secs(5);

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

/// What `cellbus serve` was asked for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ServeOptions {
    /// Where to listen (default 127.0.0.1:8080; port 0 for any free port).
    pub listen: SocketAddr,
    /// The cell's configuration; `None` starts the demo cell.
    pub config: Option<PathBuf>,
    /// Where the history database lives (default `./cellbus-data`).
    pub data_dir: PathBuf,
    /// How long history is kept (default 30 days).
    pub retain: Duration,
    /// How long audit rows are kept (default 365 days; never less than `retain`).
    pub retain_audit: Duration,
    /// Whether `POST /api/devices/{id}/write` is allowed.
    pub allow_writes: bool,
    /// The write token; else `CELLBUS_TOKEN`, else the config's `token`.
    pub token: Option<String>,
    /// The read token every API route then needs; else `CELLBUS_READ_TOKEN`, else the
    /// config's `read_token`; none: reading is open.
    pub read_token: Option<String>,
    /// `--mqtt mqtt://HOST:PORT` (or `mqtts://HOST:PORT`, TLS): publish the cell as a
    /// Sparkplug B edge node to this broker (the demo cell as group `cellbus`, edge node
    /// `demo`); with a config, it replaces the `[mqtt]` table's broker (keeping its TLS
    /// files for `mqtts://`; without a table, TLS trusts the system's roots).
    pub mqtt: Option<String>,
    /// `--mqtt-mode`: Sparkplug B or JSON, overriding the `[mqtt]` table's `mode`.
    pub mqtt_mode: Option<MqttMode>,
    /// `--mqtt-node`: the Sparkplug edge node id, overriding the `[mqtt]` table's.
    pub mqtt_node: Option<String>,
    /// `--mqtt-primary-host`: the Sparkplug primary host whose STATE gates the births.
    pub mqtt_primary_host: Option<String>,
    /// `--opcua IP:PORT`: serve the cell over OPC UA there (port 0: any free port); with
    /// a config, it replaces the `[opcua]` table's endpoint.
    pub opcua: Option<SocketAddr>,
}

impl Default for ServeOptions {
    fn default() -> Self {
        Self {
            listen: DEFAULT_LISTEN,
            config: None,
            data_dir: PathBuf::from(DEFAULT_DATA_DIR),
            retain: DEFAULT_RETAIN,
            retain_audit: DEFAULT_RETAIN_AUDIT,
            allow_writes: false,
            token: None,
            read_token: None,
            mqtt: None,
            mqtt_mode: None,
            mqtt_node: None,
            mqtt_primary_host: None,
            opcua: None,
        }
    }
}

/// Runs the gateway until `shutdown` resolves (Ctrl-C, SIGTERM), then stops the pollers,
/// commits the history and returns.
///
/// Its first line on standard output, once the port is bound, is exactly
/// `listening on http://IP:PORT`; other tools wait for it. With OPC UA, the second is
/// `opcua on opc.tcp://IP:PORT`.
pub async fn serve(
    options: ServeOptions,
    shutdown: impl Future<Output = ()>,
) -> anyhow::Result<()> {
    let gateway = Gateway::start(options).await?;
    {
        let mut out = std::io::stdout().lock();
        writeln!(out, "listening on http://{}", gateway.local_addr())
            .and_then(|()| match &gateway.opcua {
                Some(opcua) => writeln!(out, "opcua on {}", opcua.url),
                None => Ok(()),
            })
            .and_then(|()| out.flush())
            .context("cannot write to standard output")?;
    }
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
    pollers: Pollers,
    mqtt: Option<JoinHandle<()>>,
    opcua: Option<northbound::opcua::Started>,
    _demo: Option<DemoCell>,
}

impl Gateway {
    /// Reads the configuration (or starts the demo cell), starts the history, binds the
    /// port and starts polling.
    ///
    /// The history never stops the start: its file is opened and checked on its own
    /// thread; a damaged file is moved aside (a `history_reset` event names it), and a data
    /// directory that cannot be used turns the history off (a `history_failed` event,
    /// `/healthz` degraded, history queries 503) while live values are served.
    pub async fn start(options: ServeOptions) -> anyhow::Result<Self> {
        let (config, demo) = match &options.config {
            Some(path) => {
                let config = check_config(path)?;
                for warning in config.warnings() {
                    tracing::warn!("{}: {warning}", path.display());
                }
                (config, None)
            }
            None => {
                let demo = DemoCell::start()
                    .await
                    .context("cannot start the demo cell's simulators on 127.0.0.1")?;
                (demo.config.clone(), Some(demo))
            }
        };
        let writes = write_policy(&options, &config)?;
        let mqtt = mqtt_config(&options, &config, demo.is_some())?;
        let opcua = opcua_config(&options, &config, demo.is_some(), &writes)?;
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
        let (cell, tasks) =
            Cell::new(&config, store.handle(), metrics).map_err(anyhow::Error::msg)?;
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
        let (stop, stopped) = watch::channel(false);
        let pollers = Pollers::start(tasks, stopped.clone())?;
        let mqtt = mqtt
            .map(|config| {
                northbound::mqtt::start(
                    Arc::clone(&cell),
                    config,
                    options.data_dir.clone(),
                    options.allow_writes,
                    stopped.clone(),
                )
            })
            .transpose()?;
        let opcua = match opcua {
            Some((config, opcua_options)) => Some(
                northbound::opcua::start(Arc::clone(&cell), config, opcua_options, stopped.clone())
                    .await?,
            ),
            None => None,
        };
        Ok(Self {
            listener,
            addr,
            cell,
            store,
            writes,
            stop,
            pollers,
            mqtt,
            opcua,
            _demo: demo,
        })
    }

    /// The address the gateway listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// The OPC UA endpoint URL, when the server runs.
    pub fn opcua_url(&self) -> Option<&str> {
        self.opcua.as_ref().map(|o| o.url.as_str())
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
            mqtt,
            opcua,
            _demo,
            ..
        } = self;
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
                // Ends the event streams and starts the graceful stop of the server.
                let _ = stop.send(true);
                server.await
            }
        };
        let _ = stop.send(true);
        if tokio::time::timeout(STOP_GRACE, pollers.stopped)
            .await
            .is_err()
        {
            tracing::warn!("the line tasks did not stop in {STOP_GRACE:?}");
        }
        if let Some(mqtt) = mqtt
            && tokio::time::timeout(STOP_GRACE, mqtt).await.is_err()
        {
            tracing::warn!("the MQTT task did not stop in {STOP_GRACE:?}");
        }
        if let Some(opcua) = opcua
            && tokio::time::timeout(STOP_GRACE, opcua.task).await.is_err()
        {
            tracing::warn!("the OPC UA server did not stop in {STOP_GRACE:?}");
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

/// The line tasks, on a thread of their own with a single-threaded runtime.
///
/// A poll is a chain of short exchanges, each waiting a few milliseconds for its reply.
/// On the multi-threaded runtime each reply woke one worker, which often woke the other
/// to share the work (a futex wake and two thread switches for a few microseconds of
/// work); on one thread, the I/O driver hands every reply that arrived to its task
/// without any. In the load bench (1,000 JBC stations) this alone took the CPU per point
/// read from 11.0 to 9.0 µs (runs back to back). It also keeps polling away from the HTTP, MQTT and OPC UA work on the
/// main runtime: a large API answer no longer delays a poll. One thread polls every line
/// (a thousand stations take about a tenth of a core).
#[derive(Debug)]
struct Pollers {
    /// Resolves when every line task has ended (or the thread is gone).
    stopped: tokio::sync::oneshot::Receiver<()>,
}

impl Pollers {
    /// Starts `tasks` on the pollers' thread; they end when `stop` turns true.
    fn start(tasks: Vec<LineTask>, stop: watch::Receiver<bool>) -> anyhow::Result<Self> {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .context("cannot start the pollers' runtime")?;
        let (ended, stopped) = tokio::sync::oneshot::channel();
        std::thread::Builder::new()
            .name("cellbus-poll".into())
            .spawn(move || {
                runtime.block_on(async move {
                    let running: Vec<_> = tasks
                        .into_iter()
                        .map(|task| tokio::spawn(task.run(stop.clone())))
                        .collect();
                    for task in running {
                        if let Err(e) = task.await {
                            tracing::error!("a line task failed: {e}");
                        }
                    }
                });
                let _ = ended.send(());
            })
            .context("cannot start the pollers' thread")?;
        Ok(Self { stopped })
    }
}

/// The MQTT connection to make, if any: `--mqtt` (the demo cell's, or replacing the
/// config's broker), else the config's `[mqtt]` table; `--mqtt-mode`, `--mqtt-node` and
/// `--mqtt-primary-host` override the table's fields.
fn mqtt_config(
    options: &ServeOptions,
    config: &CellConfig,
    demo: bool,
) -> anyhow::Result<Option<MqttConfig>> {
    let mut mqtt = match (&options.mqtt, &config.mqtt) {
        (None, None) => {
            if options.mqtt_mode.is_some()
                || options.mqtt_node.is_some()
                || options.mqtt_primary_host.is_some()
            {
                return Err(OptionError(
                    "--mqtt-mode, --mqtt-node and --mqtt-primary-host need a broker: give \
                     --mqtt URL or an [mqtt] table in the configuration"
                        .to_owned(),
                )
                .into());
            }
            return Ok(None);
        }
        (None, Some(table)) => table.clone(),
        (Some(url), Some(table)) => {
            let broker = parse_broker(url).map_err(|m| OptionError(format!("--mqtt: {m}")))?;
            MqttConfig {
                host: broker.host,
                port: broker.port,
                // mqtts:// keeps the table's CA and client certificate, if it has them.
                tls: broker.tls.then(|| table.tls.clone().unwrap_or_default()),
                ..table.clone()
            }
        }
        (Some(url), None) => {
            let node = match &options.mqtt_node {
                Some(node) => node.clone(),
                None if demo => DEMO_EDGE_NODE.to_owned(),
                None => default_edge_node_id(),
            };
            MqttConfig::for_broker(url, &node).map_err(|m| OptionError(format!("--mqtt: {m}")))?
        }
    };
    if let Some(mode) = options.mqtt_mode {
        mqtt.mode = mode;
    }
    if let Some(node) = &options.mqtt_node {
        sparkplug::Id::new(node.as_str())
            .map_err(|e| OptionError(format!("--mqtt-node {node:?}: {e}")))?;
        if mqtt.prefix == format!("cellbus/{}", mqtt.edge_node_id) {
            mqtt.prefix = format!("cellbus/{node}");
        }
        if mqtt.client_id == format!("cellbus-{}", mqtt.edge_node_id) {
            mqtt.client_id = format!("cellbus-{node}");
        }
        mqtt.edge_node_id.clone_from(node);
    }
    if let Some(host) = &options.mqtt_primary_host {
        sparkplug::Id::new(host.as_str())
            .map_err(|e| OptionError(format!("--mqtt-primary-host {host:?}: {e}")))?;
        mqtt.primary_host = Some(host.clone());
    }
    Ok(Some(mqtt))
}

/// The demo cell's OPC UA user: its password is the write token.
pub const DEMO_OPCUA_USER: &str = "operator";

/// The OPC UA server to start, if any: `--opcua` (the demo cell's, or replacing the
/// config's endpoint), else the config's `[opcua]` table. The demo cell on loopback also
/// offers security None, anonymous reading, and the user `operator` whose password is the
/// write token (writing with `--allow-writes`). Elsewhere anonymous reading is on only
/// while writes are off, unless the table says otherwise.
fn opcua_config(
    options: &ServeOptions,
    config: &CellConfig,
    demo: bool,
    writes: &WritePolicy,
) -> anyhow::Result<Option<(OpcuaConfig, northbound::opcua::Options)>> {
    let table = match (options.opcua, &config.opcua) {
        (None, None) => return Ok(None),
        (None, Some(table)) => table.clone(),
        (Some(addr), Some(table)) => OpcuaConfig {
            host: addr.ip().to_string(),
            port: addr.port(),
            ..table.clone()
        },
        (Some(addr), None) => OpcuaConfig::at(&addr.ip().to_string(), addr.port()),
    };
    let mut users = northbound::opcua::users_of(&table)?;
    let loopback = table
        .host
        .parse::<std::net::IpAddr>()
        .is_ok_and(|ip| ip.is_loopback());
    let mut table = table;
    let anonymous = if demo && config.opcua.is_none() && loopback {
        table.security.insert(0, OpcuaSecurity::NONE);
        if let Some(token) = &writes.token {
            users.push(northbound::opcua::auth::User {
                name: DEMO_OPCUA_USER.to_owned(),
                password: token.clone(),
                write: true,
            });
        }
        true
    } else {
        table.anonymous.unwrap_or(!options.allow_writes)
    };
    Ok(Some((
        table,
        northbound::opcua::Options {
            data_dir: options.data_dir.clone(),
            allow_writes: options.allow_writes,
            users,
            anonymous,
        },
    )))
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

/// Why a read token equal to the write token is refused.
pub(crate) const SAME_TOKENS: &str = "the read token is the write token, so everyone who may \
     read could also write; give readers a token of their own, or no read token";

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
    match crate::write::token_fault(token) {
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
