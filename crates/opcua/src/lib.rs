//! The cell as an OPC UA server (async-opcua): `Objects/Cell/{line}/{device}/{point}`,
//! values with their quality from the change stream, writes through the audited write
//! path, HistoryRead from the history.
//!
//! An interface of the gateway in a crate of its own: [`Opcua`] implements
//! [`Northbound`] with what the `gateway` crate makes public, and the `cellbus` binary adds
//! it to its registry (`gateway::plugins::builtin().with_interface(&Opcua)`) when built
//! with its `opcua` feature (the default). A build without it leaves async-opcua out.
//!
//! - [`space`]: the sans-IO mapping (node ids, data types, status codes, units, times).
//! - [`nodes`]: the in-memory node manager of the cell's folders, devices, alarms and
//!   gateway object; the points' writes and history reads.
//! - [`points`]: the node manager of the points, made when asked from the cell's state.
//! - [`history`]: HistoryRead raw and processed (Average, Minimum, Maximum), sans-IO.
//! - [`alarms`]: the alarms, sans-IO: each alarm's state as variables, the methods that
//!   acknowledge, shelve and unshelve them (why not Alarms & Conditions: there).
//! - [`auth`]: anonymous sessions read only; users log in on secure endpoints.
//! - [`peers`]: the gateway accepts the clients and relays them to the server on
//!   loopback, to know each secure channel's client address (for the audit log), to close
//!   sessions not activated in time and to cap the sessions of one address.
//! - [`chunks`]: the relay's sans-IO view of the messages (whole chunks; on plain channels
//!   the sessions created, and the CloseSession it sends).
//! - [`items`]: every node manager wrapped to cap the server's monitored items.
//! - [`config`]: the `[opcua]` table.
//! - [`status`]: the server's state in `/healthz` and `/metrics`.
//! - [`fuzzing`]: the bodies of the fuzz targets over the relay's sniffer and chunk reader.
//!
//! One task follows [`Cell::subscribe`] and sets the variables' values (a point's value goes
//! straight to the items that monitor it); subscriptions and monitored items are the
//! server's own over those values (no second polling). A point's
//! monitored item asked to sample at its poll period or faster gets
//! [`points::EVERY_CHANGE_MS`]: every change, with the time it was read. `/healthz` and
//! `/metrics` read the server's connections, sessions, subscriptions and monitored items
//! through the probe it registers with the cell ([`status`]; [`state`] reads it). The same
//! task raises each of the gateway's events as a BaseEventType event on the device's
//! object (the gateway object for the gateway's own), which the server also delivers to
//! event subscriptions on the Server object. The
//! application certificate is made on first start in `<data>/opcua/pki/own/cert.der`
//! (key in `private/`); client certificates are trusted when they are in
//! `pki/trusted`, and an unknown one is put in `pki/rejected` for an
//! administrator to move.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod alarms;
pub mod auth;
pub mod chunks;
pub mod config;
pub mod fuzzing;
pub mod history;
pub mod items;
pub mod nodes;
pub mod peers;
pub mod points;
pub mod space;
pub mod status;

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use ::opcua::crypto::{CertificateStore, SecurityPolicy, X509Data};
use ::opcua::server::diagnostics::DiagnosticsNodeManagerBuilder;
use ::opcua::server::node_manager::memory::{CoreNodeManagerBuilder, InMemoryNodeManagerBuilder};
use ::opcua::server::{ANONYMOUS_USER_TOKEN_ID, ServerBuilder, ServerEndpoint, ServerHandle};
use ::opcua::types::{
    ApplicationDescription, ApplicationType, BuildInfo, DataValue, DateTime, LocalizedText,
    MessageSecurityMode, UAString, VariableId, Variant,
};
use anyhow::Context;
use tokio::sync::{broadcast, watch};
use tokio::task::JoinHandle;

use self::auth::{User, Users};
use self::config::{OpcuaConfig, OpcuaMode, OpcuaPolicy, OpcuaSecurity};
use self::items::{Capped, ItemCount, capped, capped_yielding};
use self::nodes::CellManager;
use self::peers::{Guard, Peers, Refusal, SessionState, SessionStates};
use self::points::PointTable;
use self::space::ids;
use gateway::cell::{Cell, LiveMessage, Roster};
use gateway::config::{CellConfig, TableReader};
use gateway::event::EventKind;
use gateway::http::WritePolicy;
use gateway::northbound::{BoxStart, Northbound, Running, Start};
use gateway::options::ServeOptions;
use gateway::point::DeviceId;
use gateway::time::Timestamp;
pub use status::{OpcuaProbe, OpcuaRefused, OpcuaState, state};

/// How often the gateway object's history row count is refreshed.
const GATEWAY_TICK: Duration = Duration::from_secs(10);
/// How long the server may take to start listening behind the relay.
const SERVER_START: Duration = Duration::from_secs(10);
/// The path of every endpoint.
const ENDPOINT_PATH: &str = "/";

/// A started OPC UA server.
#[derive(Debug)]
pub struct Started {
    /// The address it listens on (the actual port when 0 was asked).
    pub addr: SocketAddr,
    /// The endpoint URL clients use.
    pub url: String,
    /// Ends when the server has stopped.
    pub task: JoinHandle<()>,
}

/// What the server needs besides the `[opcua]` table.
#[derive(Debug, Clone)]
pub struct Options {
    /// The data directory (`<data>/opcua/pki` holds the certificates).
    pub data_dir: PathBuf,
    /// `--allow-writes`.
    pub allow_writes: bool,
    /// The users with their passwords, read at start.
    pub users: Vec<User>,
    /// Whether anonymous sessions are allowed (read only).
    pub anonymous: bool,
}

/// The users of `config` with their passwords from the environment; fails naming the
/// variable that is not set.
pub fn users_of(config: &OpcuaConfig) -> anyhow::Result<Vec<User>> {
    config
        .users
        .iter()
        .map(|u| {
            let password = std::env::var(&u.password_env).with_context(|| {
                format!(
                    "the OPC UA password of user {:?}: environment variable {} is not set",
                    u.name, u.password_env
                )
            })?;
            Ok(User {
                name: u.name.clone(),
                password,
                write: u.write,
            })
        })
        .collect()
}

/// Binds the endpoint, makes the application certificate if there is none, and serves
/// `cell` until `stop` turns true.
pub async fn start(
    cell: Arc<Cell>,
    config: OpcuaConfig,
    options: Options,
    mut stop: watch::Receiver<bool>,
) -> anyhow::Result<Started> {
    let bind_to = format!("{}:{}", config.host, config.port);
    let listener = tokio::net::TcpListener::bind(&bind_to)
        .await
        .with_context(|| {
            format!(
                "cannot listen for OPC UA on {bind_to}; choose another port with --opcua \
                 (127.0.0.1:0 for any free port) or endpoint in [opcua]"
            )
        })?;
    let addr = listener
        .local_addr()
        .context("cannot read the OPC UA server's bound address")?;
    // The server itself listens on loopback behind the relay (see `peers`).
    let inner = tokio::net::TcpListener::bind((std::net::Ipv4Addr::LOCALHOST, 0))
        .await
        .context("cannot listen on loopback for the OPC UA server behind the relay")?;
    let inner_addr = inner
        .local_addr()
        .context("cannot read the OPC UA server's loopback address")?;
    let config = OpcuaConfig {
        port: addr.port(),
        ..config
    };
    let url = config.endpoint();
    let pki = options.data_dir.join("opcua").join("pki");
    let pki_for_cert = pki.clone();
    let cert_config = config.clone();
    tokio::task::spawn_blocking(move || ensure_certificate(&pki_for_cert, &cert_config))
        .await
        .context("the certificate task failed")??;
    let users = Users::new(options.users, options.anonymous, options.allow_writes);
    let peers = Arc::new(Peers::default());
    let items = Arc::new(ItemCount::new(config.max_monitored_items));
    let points = PointTable::new(Arc::clone(&cell));
    let (server, handle) = builder(&config, &pki, &url, users.clone(), &items)
        .with_node_manager(capped_yielding(
            nodes::builder(
                Arc::clone(&cell),
                users.clone(),
                Arc::clone(&peers),
                Arc::clone(&points),
            ),
            Arc::clone(&items),
            Arc::clone(&points),
        ))
        .with_node_manager(capped(
            points::builder(Arc::clone(&points), users, Arc::clone(&peers)),
            Arc::clone(&items),
        ))
        .build()
        .map_err(|e| anyhow::anyhow!("the OPC UA server's configuration is refused: {e}"))?;
    let manager =
        cell_manager(&handle).context("the OPC UA server has no node manager for the cell")?;
    status::register(
        &cell,
        probe(url.clone(), handle.clone(), items, Arc::clone(&peers)),
    );
    let ns = manager.inner().namespace();
    let live = cell.subscribe();
    let follow = tokio::spawn(follow(
        Arc::clone(&cell),
        handle.clone(),
        manager,
        points,
        ns,
        live,
        stop.clone(),
    ));
    // Clients wait in the listener's backlog until the server's own port is put back.
    let (open, opened) = tokio::sync::oneshot::channel::<()>();
    let relay_stop = stop.clone();
    let guard = Guard {
        activation_timeout: config.activation_timeout,
        sessions_per_address: config.sessions_per_address,
        sessions: Arc::new(ServerSessions(handle.clone())),
    };
    let relay = tokio::spawn(async move {
        if opened.await.is_ok() {
            peers::relay(listener, inner_addr, peers, guard, relay_stop).await;
        }
    });
    let rejected = tokio::spawn(trim_rejected_every(pki.join("rejected"), stop.clone()));
    let cancel = handle.clone();
    let task = tokio::spawn(async move {
        let run = server.run_with(inner);
        tokio::pin!(run);
        tokio::select! {
            ended = &mut run => {
                if let Err(e) = ended {
                    tracing::error!("the OPC UA server stopped: {e}");
                }
            }
            () = stopped(&mut stop) => {
                cancel.cancel();
                if let Err(e) = run.await {
                    tracing::error!("the OPC UA server stopped: {e}");
                }
            }
        }
        follow.abort();
        relay.abort();
        rejected.abort();
    });
    // `run_with` records the loopback listener's port as the server's, and endpoint
    // descriptions (GetEndpoints, CreateSession) are built from it: put the clients' port
    // back once it has, before the relay lets clients in.
    let info = Arc::clone(handle.info());
    let deadline = tokio::time::Instant::now() + SERVER_START;
    while info.port.load(Ordering::Relaxed) != inner_addr.port()
        && tokio::time::Instant::now() < deadline
    {
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
    info.port.store(addr.port(), Ordering::Relaxed);
    let _ = open.send(());
    tracing::info!(
        "OPC UA server on {url} ({})",
        config
            .security
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(Started { addr, url, task })
}

/// The cell's node manager, inside its [`Capped`] wrapper.
fn cell_manager(handle: &ServerHandle) -> Option<Arc<CellManager>> {
    handle.node_managers().iter().find_map(|manager| {
        let capped = Arc::clone(manager)
            .into_any_arc()
            .downcast::<Capped>()
            .ok()?;
        Arc::clone(capped.inner())
            .into_any_arc()
            .downcast::<CellManager>()
            .ok()
    })
}

fn builder(
    config: &OpcuaConfig,
    pki: &Path,
    url: &str,
    users: Users,
    items: &Arc<ItemCount>,
) -> ServerBuilder {
    let anonymous = users.anonymous();
    let mut builder = ServerBuilder::new()
        // async-opcua's own node managers (namespace 0, diagnostics) again, their
        // monitored items counted with the cell's.
        .without_node_managers()
        .with_node_manager(capped(
            InMemoryNodeManagerBuilder::new(CoreNodeManagerBuilder),
            Arc::clone(items),
        ))
        .with_node_manager(capped(DiagnosticsNodeManagerBuilder, Arc::clone(items)))
        .application_name(config.application_name.clone())
        .application_uri(config.application_uri.clone())
        .product_uri("urn:cellbus")
        .build_info(BuildInfo {
            product_uri: "urn:cellbus".into(),
            manufacturer_name: "cellbus".into(),
            product_name: "cellbus gateway".into(),
            software_version: env!("CARGO_PKG_VERSION").into(),
            build_number: env!("CARGO_PKG_VERSION").into(),
            build_date: DateTime::now(),
        })
        .pki_dir(pki)
        .create_sample_keypair(false)
        .trust_client_certs(config.trust_all_clients)
        .host(config.host.clone())
        .port(config.port)
        .discovery_urls(vec![url.to_owned()])
        // async-opcua's default of 20 let 20 anonymous readers lock out everyone else,
        // the operator included (sessions are counted before anyone says who they are).
        .max_sessions(MAX_SESSIONS)
        // The longest session timeout granted (a client asking for an hour gets this).
        .max_session_timeout_ms(
            u64::try_from(config.session_timeout.as_millis()).unwrap_or(u64::MAX),
        )
        // For the session and subscription counts of /healthz and /metrics.
        .diagnostics_enabled(true)
        .with_authenticator(Arc::new(users));
    let tokens: Vec<String> = if anonymous {
        vec![ANONYMOUS_USER_TOKEN_ID.to_owned()]
    } else {
        Vec::new()
    };
    for security in &config.security {
        let (policy, mode) = opc_security(security);
        builder = builder.add_endpoint(
            endpoint_id(security),
            ServerEndpoint::new(ENDPOINT_PATH, policy, mode, &tokens),
        );
    }
    builder
}

/// Reads the server's state for `/healthz` and `/metrics`: sessions and subscriptions
/// from async-opcua's diagnostics summary, monitored items from their count, connections
/// and sessions refused from the relay.
fn probe(
    endpoint: String,
    handle: ServerHandle,
    items: Arc<ItemCount>,
    peers: Arc<Peers>,
) -> OpcuaProbe {
    OpcuaProbe::new(move || {
        let count = |id: VariableId| match handle.info().summary().get(id).and_then(|v| v.value) {
            Some(Variant::UInt32(n)) => u64::from(n),
            _ => 0,
        };
        OpcuaState {
            endpoint: endpoint.clone(),
            connections: peers.connections(),
            sessions: count(VariableId::Server_ServerDiagnostics_ServerDiagnosticsSummary_CurrentSessionCount),
            subscriptions: count(
                VariableId::Server_ServerDiagnostics_ServerDiagnosticsSummary_CurrentSubscriptionCount,
            ),
            monitored_items: items.current(),
            refused: OpcuaRefused {
                sessions_not_activated: peers.refused(Refusal::NotActivated),
                sessions_abandoned: peers.refused(Refusal::Abandoned),
                sessions_per_address: peers.refused(Refusal::PerAddress),
                monitored_items: items.refused(),
            },
        }
    })
}

/// The server's sessions as the relay looks them up: async-opcua's session manager by
/// authentication token.
struct ServerSessions(ServerHandle);

impl SessionStates for ServerSessions {
    fn state(&self, token: &::opcua::types::NodeId) -> SessionState {
        let session = self.0.session_manager().read().find_by_token(token);
        match session {
            None => SessionState::Gone,
            Some(session) if session.read().is_activated() => SessionState::Activated,
            Some(_) => SessionState::Waiting,
        }
    }
}

/// The endpoint's id in the server's configuration.
fn endpoint_id(security: &OpcuaSecurity) -> String {
    security.to_string().replace(' ', "_")
}

fn opc_security(security: &OpcuaSecurity) -> (SecurityPolicy, MessageSecurityMode) {
    let policy = match security.policy {
        OpcuaPolicy::None => SecurityPolicy::None,
        OpcuaPolicy::Basic256Sha256 => SecurityPolicy::Basic256Sha256,
        OpcuaPolicy::Aes128Sha256RsaOaep => SecurityPolicy::Aes128Sha256RsaOaep,
        OpcuaPolicy::Aes256Sha256RsaPss => SecurityPolicy::Aes256Sha256RsaPss,
    };
    let mode = match security.mode {
        OpcuaMode::None => MessageSecurityMode::None,
        OpcuaMode::Sign => MessageSecurityMode::Sign,
        OpcuaMode::SignAndEncrypt => MessageSecurityMode::SignAndEncrypt,
    };
    (policy, mode)
}

/// Certificates kept in `pki/rejected`: async-opcua files every unknown client
/// certificate there, and anyone who reaches the port can send a new one each time.
pub const REJECTED_KEPT: usize = 64;
/// How often `pki/rejected` is cut back to [`REJECTED_KEPT`] files.
const REJECTED_TRIM_EVERY: Duration = Duration::from_secs(60);

/// Cuts `pki/rejected` back every [`REJECTED_TRIM_EVERY`] until `stop`.
async fn trim_rejected_every(dir: std::path::PathBuf, mut stop: watch::Receiver<bool>) {
    loop {
        tokio::select! {
            () = tokio::time::sleep(REJECTED_TRIM_EVERY) => {}
            () = stopped(&mut stop) => return,
        }
        let dir = dir.clone();
        match tokio::task::spawn_blocking(move || trim_rejected(&dir, REJECTED_KEPT)).await {
            Ok(Ok(0)) | Err(_) => {}
            Ok(Ok(n)) => tracing::warn!(
                "OPC UA: deleted {n} rejected client certificate(s), the oldest, keeping the \
                 newest {REJECTED_KEPT}"
            ),
            Ok(Err(e)) => tracing::warn!("OPC UA: cannot cut back pki/rejected: {e}"),
        }
    }
}

/// Deletes all but the `keep` newest files of `dir` (by modification time); returns how
/// many went.
fn trim_rejected(dir: &Path, keep: usize) -> std::io::Result<usize> {
    let mut files: Vec<(std::time::SystemTime, std::path::PathBuf)> = std::fs::read_dir(dir)?
        .flatten()
        .filter(|e| e.file_type().is_ok_and(|t| t.is_file()))
        .map(|e| {
            let modified = e
                .metadata()
                .and_then(|m| m.modified())
                .unwrap_or(std::time::SystemTime::UNIX_EPOCH);
            (modified, e.path())
        })
        .collect();
    if files.len() <= keep {
        return Ok(0);
    }
    files.sort();
    let old = files.len() - keep;
    for (_, path) in &files[..old] {
        std::fs::remove_file(path)?;
    }
    Ok(old)
}

/// Sessions at once (of every client, anonymous or not).
pub const MAX_SESSIONS: usize = config::OPCUA_MAX_SESSIONS;

/// Makes the private key's folder and files readable by this user only (on every start:
/// a key made by an earlier version, under a umask of 022, was readable by all).
#[cfg(unix)]
fn keep_private(private: &Path) -> anyhow::Result<()> {
    use std::os::unix::fs::PermissionsExt;
    let set = |path: &Path, mode: u32| {
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode))
            .map_err(|e| anyhow::anyhow!("cannot make {} private: {e}", path.display()))
    };
    set(private, 0o700)?;
    for entry in std::fs::read_dir(private)
        .map_err(|e| anyhow::anyhow!("cannot read {}: {e}", private.display()))?
        .flatten()
    {
        if entry.file_type().is_ok_and(|t| t.is_file()) {
            set(&entry.path(), 0o600)?;
        }
    }
    Ok(())
}

#[cfg(not(unix))]
fn keep_private(_private: &Path) -> anyhow::Result<()> {
    Ok(())
}

/// Makes the self-signed application certificate and its key on first start, and the
/// trusted and rejected folders; the key is readable by this user only.
fn ensure_certificate(pki: &Path, config: &OpcuaConfig) -> anyhow::Result<()> {
    ensure_keypair(pki, config)?;
    keep_private(&pki.join("private"))
}

fn ensure_keypair(pki: &Path, config: &OpcuaConfig) -> anyhow::Result<()> {
    let store = CertificateStore::new(pki);
    store.ensure_pki_path().map_err(|e| {
        anyhow::anyhow!(
            "cannot make the OPC UA certificate folders in {}: {e}",
            pki.display()
        )
    })?;
    if store.read_own_cert().is_ok() && store.read_own_pkey().is_ok() {
        return Ok(());
    }
    let description = ApplicationDescription {
        application_uri: UAString::from(config.application_uri.as_str()),
        application_name: LocalizedText::new("", &config.application_name),
        application_type: ApplicationType::Server,
        product_uri: UAString::from("urn:cellbus"),
        gateway_server_uri: UAString::null(),
        discovery_profile_uri: UAString::null(),
        discovery_urls: None,
    };
    let mut names = vec![config.host.clone()];
    names.extend(X509Data::computer_hostnames());
    let data = X509Data::from((description, Some(names)));
    store
        .create_and_store_application_instance_cert(&data, false)
        .map_err(|e| {
            anyhow::anyhow!(
                "cannot make the OPC UA application certificate in {}: {e}",
                pki.display()
            )
        })?;
    tracing::info!(
        "made the OPC UA application certificate {}",
        store.own_certificate_path().display()
    );
    Ok(())
}

/// Follows the change stream and sets the variables; after a lag, sets every value again
/// from the cell.
async fn follow(
    cell: Arc<Cell>,
    handle: ServerHandle,
    manager: Arc<CellManager>,
    points: Arc<PointTable>,
    ns: u16,
    mut live: broadcast::Receiver<LiveMessage>,
    mut stop: watch::Receiver<bool>,
) {
    let subscriptions = Arc::clone(handle.subscriptions());
    // Event ids: this task's start and the event's number.
    let started = Timestamp::now();
    let mut numbered: u64 = 0;
    let mut tick = tokio::time::interval(GATEWAY_TICK);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    // Changes between the address space's build and this subscription are caught up here.
    let mut laid_out = cell.roster();
    points.notify_all(&subscriptions, &laid_out);
    loop {
        tokio::select! {
            message = live.recv() => match message {
                Ok(LiveMessage::Value(view)) => points.notify(&subscriptions, &view),
                Ok(LiveMessage::Device(summary)) => {
                    points.notify_device(&subscriptions, &summary, DateTime::now());
                }
                Ok(LiveMessage::Event(event)) => {
                    // The new nodes are there before clients hear of the reload.
                    if event.kind == EventKind::ConfigReloaded {
                        let changed = gateway::reload::devices_in(&event, "changed");
                        laid_out = follow_roster(&cell, &handle, &manager, ns, &changed);
                        points.notify_all(&subscriptions, &laid_out);
                    }
                    if let Some(view) = changed_alarm(&event).and_then(|a| cell.alarms.view(a)) {
                        points.notify_alarm(&subscriptions, &view, DateTime::now());
                    }
                    numbered += 1;
                    let id = space::event_id(started, numbered);
                    let raised = space::cell_event(ns, &event, id, Timestamp::now());
                    subscriptions.notify_events(std::iter::once((
                        &raised as &dyn ::opcua::nodes::Event,
                        &raised.base.source_node,
                    )));
                }
                Err(broadcast::error::RecvError::Lagged(missed)) => {
                    tracing::warn!("the OPC UA server missed {missed} changes; reading the cell again");
                    // A reload's event may be among them: its changed devices are those
                    // whose entry is not the one laid out (some perhaps only restarted).
                    let roster = cell.roster();
                    if !Arc::ptr_eq(&roster, &laid_out) {
                        let changed: Vec<DeviceId> = roster
                            .devices()
                            .filter(|d| {
                                laid_out
                                    .device(d.id.as_str())
                                    .is_some_and(|was| !Arc::ptr_eq(was, d))
                            })
                            .map(|d| d.id.clone())
                            .collect();
                        laid_out = follow_roster(&cell, &handle, &manager, ns, &changed);
                    }
                    points.notify_all(&subscriptions, &laid_out);
                }
                Err(broadcast::error::RecvError::Closed) => return,
            },
            _ = tick.tick() => {
                let rows = cell.store().stats().rows_written();
                set_value(
                    &manager,
                    &subscriptions,
                    &ids::gateway(ns, Some(nodes::HISTORY_ROWS)),
                    DataValue::new_now(Variant::UInt64(rows)),
                );
            }
            () = stopped(&mut stop) => return,
        }
    }
}

/// Brings the address space to the cell's roster in force (see
/// [`nodes::CellNodes::follow_roster`]), `changed` the devices a reload changed, and sets
/// the gateway's `Lines`; returns the roster laid out.
fn follow_roster(
    cell: &Cell,
    handle: &ServerHandle,
    manager: &CellManager,
    ns: u16,
    changed: &[DeviceId],
) -> Arc<Roster> {
    let roster = cell.roster();
    {
        let types = handle.type_tree().read();
        let mut space = manager.address_space().write();
        manager
            .inner()
            .follow_roster(&mut space, &*types, &roster, changed);
    }
    set_value(
        manager,
        handle.subscriptions(),
        &ids::gateway(ns, Some(nodes::LINES)),
        DataValue::new_now(nodes::line_names(&roster)),
    );
    roster
}

/// The alarm an event of the alarm journal changed (`alarm_raised`, `alarm_cleared`,
/// `alarm_changed`: its `alarm` field), if it is one.
fn changed_alarm(event: &gateway::event::Event) -> Option<&str> {
    matches!(
        event.kind,
        EventKind::AlarmRaised | EventKind::AlarmCleared | EventKind::AlarmChanged
    )
    .then(|| event.fields.get("alarm").and_then(|a| a.as_str()))
    .flatten()
}

/// Resolves once `stop` turns true (or its sender is gone).
async fn stopped(stop: &mut watch::Receiver<bool>) {
    let _ = stop.wait_for(|stopped| *stopped).await;
}

/// Sets a variable of the in-memory space (the gateway object's).
fn set_value(
    manager: &CellManager,
    subscriptions: &::opcua::server::SubscriptionCache,
    node: &::opcua::types::NodeId,
    value: DataValue,
) {
    if let Err(status) = manager.set_value(subscriptions, node, None, value) {
        tracing::warn!("the OPC UA value of {node} was not set: {status}");
    }
}

/// What the command line says to the OPC UA interface (in [`ServeOptions::flags`]).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct OpcuaFlags {
    /// `--opcua IP:PORT`: serve the cell over OPC UA there (port 0: any free port); with
    /// a config, it replaces the `[opcua]` table's endpoint.
    pub listen: Option<SocketAddr>,
}

/// The OPC UA interface: the cell as an OPC UA server.
#[derive(Debug)]
pub struct Opcua;

impl Northbound for Opcua {
    fn name(&self) -> &'static str {
        "opcua"
    }

    fn table(&self) -> &'static dyn TableReader {
        &config::OpcuaTable
    }

    fn start<'a>(&'a self, start: Start<'a>) -> BoxStart<'a> {
        Box::pin(async move {
            let Some((config, options)) =
                opcua_config(start.options, start.config, start.demo, start.writes)?
            else {
                return Ok(None);
            };
            let started =
                self::start(Arc::clone(start.cell), config, options, start.stopped).await?;
            Ok(Some(Running {
                name: "opcua",
                url: Some(started.url),
                task: started.task,
            }))
        })
    }
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
) -> anyhow::Result<Option<(OpcuaConfig, Options)>> {
    let listen = options.flags.get::<OpcuaFlags>().and_then(|f| f.listen);
    let table = match (listen, config.interface::<OpcuaConfig>("opcua")) {
        (None, None) => return Ok(None),
        (None, Some(table)) => table.clone(),
        (Some(addr), Some(table)) => OpcuaConfig {
            host: addr.ip().to_string(),
            port: addr.port(),
            ..table.clone()
        },
        (Some(addr), None) => OpcuaConfig::at(&addr.ip().to_string(), addr.port()),
    };
    let mut users = users_of(&table)?;
    let loopback = table
        .host
        .parse::<std::net::IpAddr>()
        .is_ok_and(|ip| ip.is_loopback());
    let mut table = table;
    let anonymous = if demo && config.interface::<OpcuaConfig>("opcua").is_none() && loopback {
        table.security.insert(0, OpcuaSecurity::NONE);
        if let Some(token) = &writes.token {
            users.push(auth::User {
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
        Options {
            data_dir: options.data_dir.clone(),
            allow_writes: options.allow_writes,
            users,
            anonymous,
        },
    )))
}

#[cfg(test)]
mod tests;
