//! The twin on TCP: a [`Machine`] served on its two ports, as a placement machine serves
//! its host.
//!
//! `link`'s serve loop runs one-port request/response devices (a [`wire::Device`] per
//! connection); a placement machine has two ports with different jobs and sends R messages
//! on its own schedule, so this server drives the twin with tokio directly.
//!
//! - **Port 1** (commands): one host at a time. A second connection while one is open is
//!   accepted, logged and closed at once \[?\] (the fact sheet's "refused politely"). The
//!   bytes go to [`Machine::handle_port1`], which answers garbage with `A4E01` and
//!   resynchronises on the next message; when the host's connection goes (closed, reset,
//!   an error), [`Machine::port1_closed`] forgets its half message and open exchange.
//! - **Port 2** (events): the R messages of [`Machine::poll_events`], polled when
//!   [`Machine::next_event_at`] says, and at once after every Port 1 message and control
//!   action. While no host listens, the twin keeps the last 40, oldest dropped, and they
//!   go out in order when a host connects. R messages whose write fails go back to the
//!   twin's buffer ([`Machine::requeue_events`]). A new Port 2 connection takes over from
//!   an open one \[?\]: a host that reconnects after its keep-alive found Port 2 dead must
//!   be heard even when the machine has not noticed that the old connection is gone; R
//!   messages never go to two hosts.
//! - **Time** is tokio's, handed to the twin as `now`, so the server runs under paused time
//!   in tests: an hour of production in milliseconds.
//! - **[`Control`]** is the operator's side for tests and demos (mode, program, start and
//!   stop, feeders, errors) and a way to break a port ([`PortFault`], [`Control::cut`]).

use std::fmt;
use std::io;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{Notify, watch};
use tokio::task::{JoinHandle, JoinSet};
use tokio::time::Instant;

use crate::Port;
use crate::message::Message;
use crate::operator;
use crate::program::ProgramName;
use crate::status::{ControlMode, MachineStatus, StopMode};
use crate::twin::{Machine, TwinError};

/// Pause after a failed accept (out of file descriptors, …) before trying again.
const ACCEPT_RETRY: Duration = Duration::from_millis(100);
/// Times the Port 1 listener yields, before turning a second host away, so that a host's
/// just-closed connection is seen closed first.
const GRACE_YIELDS: usize = 4;
/// Read buffer of a connection: a 64 KiB read takes a large download in few steps.
const READ_BUFFER: usize = 64 * 1024;

/// A way a port can fail, for tests and demos of the host's recovery.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PortFault {
    /// The port is down: its connection is closed, and every new one is closed at once,
    /// until [`Control::heal`]. On Port 2 the twin then buffers R messages (40, oldest
    /// dropped), as when no host listens.
    Down,
    /// The connection stays open but nothing passes (a half-open connection, a cable
    /// pulled where neither side notices): on Port 1 the machine hears nothing; on Port 2
    /// what it sends is lost. Lasts until the host opens a new connection on that port.
    Silent,
}

/// A port's fault and how many times it was cut.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct PortState {
    fault: Option<PortFault>,
    /// Bumped by every [`Control::cut`]: connections opened before it close.
    cuts: u64,
}

/// One `T` for each port.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct PerPort<T> {
    command: T,
    event: T,
}

impl<T: Copy> PerPort<T> {
    fn port(&self, port: Port) -> T {
        match port {
            Port::Command => self.command,
            Port::Event => self.event,
        }
    }

    fn port_mut(&mut self, port: Port) -> &mut T {
        match port {
            Port::Command => &mut self.command,
            Port::Event => &mut self.event,
        }
    }
}

/// Each port's fault.
type Faults = PerPort<PortState>;

/// What the server's tasks and the control handles share.
struct Shared {
    machine: Mutex<Machine>,
    /// Wakes the Port 2 task: R messages may be due.
    wake: Notify,
    faults: watch::Sender<Faults>,
    /// Whether a host is connected on Port 1 and on Port 2, as the server sees it.
    hosts: watch::Sender<Hosts>,
}

/// Which ports have a host connection the server has accepted.
type Hosts = PerPort<bool>;

impl Shared {
    fn new(machine: Machine) -> Shared {
        Shared {
            machine: Mutex::new(machine),
            wake: Notify::new(),
            faults: watch::Sender::new(Faults::default()),
            hosts: watch::Sender::new(Hosts::default()),
        }
    }

    /// The twin. A panic while it was locked leaves it usable: every twin method keeps
    /// it consistent before it could panic, and a simulator should keep serving.
    fn machine(&self) -> MutexGuard<'_, Machine> {
        self.machine.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn fault(&self, port: Port) -> Option<PortFault> {
        self.faults.borrow().port(port).fault
    }

    /// Records that the server accepted (`true`) or let go (`false`) a host on `port`.
    fn host(&self, port: Port, connected: bool) {
        self.hosts.send_if_modified(|hosts| {
            let was = std::mem::replace(hosts.port_mut(port), connected);
            was != connected
        });
    }

    /// A new connection ends a [`PortFault::Silent`].
    fn new_connection(&self, port: Port) {
        self.faults.send_if_modified(|faults| {
            let state = faults.port_mut(port);
            let silent = state.fault == Some(PortFault::Silent);
            if silent {
                state.fault = None;
            }
            silent
        });
    }
}

/// The twin's time: tokio's clock (virtual under paused time), as the twin takes it.
fn now() -> std::time::Instant {
    Instant::now().into_std()
}

/// The operator's side of a served twin, for tests and demos. Cheap to clone; every action
/// wakes the server so that the R messages it causes go out at once.
#[derive(Clone)]
pub struct Control {
    shared: Arc<Shared>,
}

impl fmt::Debug for Control {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Control")
            .field("status", &self.shared.machine().status())
            .field("faults", &*self.shared.faults.borrow())
            .finish()
    }
}

impl Control {
    /// Runs `act` on the twin at the current time, then wakes the server.
    pub fn with<T>(&self, act: impl FnOnce(&mut Machine, std::time::Instant) -> T) -> T {
        let result = act(&mut self.shared.machine(), now());
        self.shared.wake.notify_one();
        result
    }

    /// What C2ST would answer now.
    pub fn status(&self) -> MachineStatus {
        self.with(|machine, _| machine.status())
    }

    /// Switches between Online and Remote (the mode switch at the machine).
    pub fn set_mode(&self, mode: ControlMode) {
        self.with(|machine, _| machine.set_mode(mode));
    }

    /// Selects a stored program at the panel (`R1SE`, or `R1SENG` for an unknown one).
    pub fn select_program(&self, name: &ProgramName) -> Result<(), TwinError> {
        self.with(|machine, now| machine.select_program(name, now))
    }

    /// Starts the machine at the panel, in any mode (`R1ST`).
    pub fn operator_start(&self, mode: Option<StopMode>) -> Result<(), TwinError> {
        self.with(|machine, now| machine.operator_start(mode, now))
    }

    /// Stops the machine at the panel (Ready).
    pub fn stop(&self) {
        self.with(|machine, now| machine.stop(now));
    }

    /// Stops feeding from feeder `feeder`: its next pick runs out (`R2E03`, error stop).
    pub fn pause_feeder(&self, feeder: u16) -> Result<(), TwinError> {
        self.with(|machine, now| machine.pause_feeder(feeder, now))
    }

    /// Feeds from feeder `feeder` again.
    pub fn resume_feeder(&self, feeder: u16) -> Result<(), TwinError> {
        self.with(|machine, now| machine.resume_feeder(feeder, now))
    }

    /// Loads a full reel on feeder `feeder`.
    pub fn refill_feeder(&self, feeder: u16) -> Result<(), TwinError> {
        self.with(|machine, now| machine.refill_feeder(feeder, now))
    }

    /// Stops the machine with error `code` (`R2E<code>…`, status Error).
    pub fn force_error(&self, code: u8) -> Result<(), TwinError> {
        self.with(|machine, now| machine.force_error(code, now))
    }

    /// Clears every cause of an error and presses RESET (Ready).
    pub fn clear(&self) {
        self.with(|machine, now| machine.clear(now));
    }

    /// Carries out an operator command at the panel now (see [`operator::apply`]).
    pub fn apply(&self, command: operator::Command) -> Result<String, TwinError> {
        self.with(|machine, now| operator::apply(machine, command, now))
    }

    /// Closes the port's current connection once; the host may reconnect at once.
    pub fn cut(&self, port: Port) {
        self.shared
            .faults
            .send_modify(|faults| faults.port_mut(port).cuts += 1);
    }

    /// Breaks a port until [`heal`](Self::heal) (or, for [`PortFault::Silent`], until the
    /// host reconnects).
    pub fn break_port(&self, port: Port, fault: PortFault) {
        self.shared
            .faults
            .send_modify(|faults| faults.port_mut(port).fault = Some(fault));
        self.shared.wake.notify_one();
    }

    /// Ends a port's fault.
    pub fn heal(&self, port: Port) {
        self.shared
            .faults
            .send_modify(|faults| faults.port_mut(port).fault = None);
        self.shared.wake.notify_one();
    }

    /// The port's fault, if any.
    pub fn fault(&self, port: Port) -> Option<PortFault> {
        self.shared.fault(port)
    }

    /// Whether the server has a host connection on `port` (accepted and not yet gone).
    pub fn is_connected(&self, port: Port) -> bool {
        self.shared.hosts.borrow().port(port)
    }

    /// Waits until the server has accepted a host connection on `port`.
    ///
    /// A host's connection is complete (the host may send) before the server has accepted
    /// it, so a test that breaks or cuts a port right after the host connected must wait
    /// for this first: otherwise the fault acts on no connection, and the late accept ends
    /// a [`PortFault::Silent`] before it began.
    pub async fn connected(&self, port: Port) {
        let mut hosts = self.shared.hosts.subscribe();
        // The sender lives in `Shared`, which this handle keeps alive: never an error.
        let _ = hosts.wait_for(|hosts| hosts.port(port)).await;
    }
}

/// A twin bound to its two ports, ready to [`run`](Self::run) or [`spawn`](Self::spawn).
pub struct TwinServer {
    command: TcpListener,
    event: TcpListener,
    shared: Arc<Shared>,
}

impl fmt::Debug for TwinServer {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("TwinServer")
            .field("command", &self.command.local_addr().ok())
            .field("event", &self.event.local_addr().ok())
            .finish()
    }
}

impl TwinServer {
    /// Listens on `command` (Port 1) and `event` (Port 2); port 0 picks a free port.
    pub async fn bind(
        command: SocketAddr,
        event: SocketAddr,
        machine: Machine,
    ) -> io::Result<TwinServer> {
        let bind = |addr: SocketAddr, port: Port| async move {
            TcpListener::bind(addr).await.map_err(|e| {
                io::Error::new(e.kind(), format!("cannot listen on {addr} for {port}: {e}"))
            })
        };
        let command = bind(command, Port::Command).await?;
        let event = bind(event, Port::Event).await?;
        Ok(TwinServer::from_listeners(command, event, machine))
    }

    /// Serves on listeners the caller bound.
    pub fn from_listeners(
        command: TcpListener,
        event: TcpListener,
        machine: Machine,
    ) -> TwinServer {
        TwinServer {
            command,
            event,
            shared: Arc::new(Shared::new(machine)),
        }
    }

    /// Where Port 1 listens.
    pub fn command_addr(&self) -> io::Result<SocketAddr> {
        self.command.local_addr()
    }

    /// Where Port 2 listens.
    pub fn event_addr(&self) -> io::Result<SocketAddr> {
        self.event.local_addr()
    }

    /// A control handle for the twin.
    pub fn control(&self) -> Control {
        Control {
            shared: Arc::clone(&self.shared),
        }
    }

    /// Serves both ports until the future is dropped. Failed accepts are logged and
    /// retried; a host's trouble never stops the server.
    pub async fn run(self) {
        let TwinServer {
            command,
            event,
            shared,
        } = self;
        tokio::join!(
            serve_commands(command, Arc::clone(&shared)),
            serve_events(event, shared)
        );
    }

    /// Runs the server on a task; dropping the returned handle stops it.
    pub fn spawn(self) -> io::Result<RunningTwin> {
        let command_addr = self.command_addr()?;
        let event_addr = self.event_addr()?;
        let control = self.control();
        Ok(RunningTwin {
            task: tokio::spawn(self.run()),
            control,
            command_addr,
            event_addr,
        })
    }
}

/// A twin served on a task: stopped when dropped.
#[derive(Debug)]
pub struct RunningTwin {
    task: JoinHandle<()>,
    control: Control,
    command_addr: SocketAddr,
    event_addr: SocketAddr,
}

impl RunningTwin {
    /// The operator's side.
    pub fn control(&self) -> &Control {
        &self.control
    }

    /// Where Port 1 listens.
    pub fn command_addr(&self) -> SocketAddr {
        self.command_addr
    }

    /// Where Port 2 listens.
    pub fn event_addr(&self) -> SocketAddr {
        self.event_addr
    }
}

impl Drop for RunningTwin {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// Port 1: one host at a time; a second one is closed at once.
async fn serve_commands(listener: TcpListener, shared: Arc<Shared>) {
    let mut host: JoinSet<()> = JoinSet::new();
    loop {
        tokio::select! {
            biased;
            Some(ended) = host.join_next() => {
                if let Err(error) = ended {
                    tracing::error!(%error, "the Port 1 connection task failed");
                    shared.machine().port1_closed();
                    shared.host(Port::Command, false);
                }
            }
            accepted = listener.accept() => {
                let (stream, peer) = match accepted {
                    Ok(accepted) => accepted,
                    Err(error) => {
                        tracing::warn!(%error, "Port 1: cannot accept a connection");
                        tokio::time::sleep(ACCEPT_RETRY).await;
                        continue;
                    }
                };
                if !host.is_empty() {
                    // A host that reconnects closes its old connection just before: let
                    // that connection's task see the close before judging the new one.
                    for _ in 0..GRACE_YIELDS {
                        tokio::task::yield_now().await;
                        if host.try_join_next().is_some() {
                            break;
                        }
                    }
                }
                if shared.fault(Port::Command) == Some(PortFault::Down) {
                    tracing::info!(%peer, "Port 1 is down (a fault set by the control): closing the new connection");
                } else if !host.is_empty() {
                    tracing::warn!(%peer, "a second host on Port 1: closing its connection (the machine serves one host at a time)");
                } else {
                    shared.new_connection(Port::Command);
                    shared.host(Port::Command, true);
                    tracing::info!(%peer, "host connected on Port 1");
                    host.spawn(port1_connection(stream, peer, Arc::clone(&shared)));
                }
            }
        }
    }
}

/// Serves one host on Port 1 until it leaves (or a fault closes the connection).
async fn port1_connection(stream: TcpStream, peer: SocketAddr, shared: Arc<Shared>) {
    stream.set_nodelay(true).ok();
    let mut faults = shared.faults.subscribe();
    let cuts = faults.borrow_and_update().command.cuts;
    let (mut reader, mut writer) = stream.into_split();
    let mut buf = vec![0u8; READ_BUFFER];
    let why = loop {
        tokio::select! {
            read = reader.read(&mut buf) => match read {
                Ok(0) => break "the host closed the connection".to_owned(),
                Err(error) => break format!("connection error: {error}"),
                Ok(n) => {
                    if shared.fault(Port::Command) == Some(PortFault::Silent) {
                        tracing::debug!(bytes = n, "Port 1 is silent (a fault): the machine hears nothing");
                        continue;
                    }
                    let replies = shared.machine().handle_port1(buf.get(..n).unwrap_or_default(), now());
                    shared.wake.notify_one();
                    if let Err(error) = writer.write_all(&concat(&replies)).await {
                        break format!("cannot send the reply: {error}");
                    }
                }
            },
            changed = faults.changed() => {
                if changed.is_err() {
                    break "the server stopped".to_owned();
                }
                let state = faults.borrow_and_update().command;
                if state.fault == Some(PortFault::Down) {
                    break "Port 1 went down (a fault set by the control)".to_owned();
                }
                if state.cuts != cuts {
                    break "Port 1 was cut (by the control)".to_owned();
                }
            }
        }
    };
    shared.machine().port1_closed();
    shared.host(Port::Command, false);
    tracing::info!(%peer, "host left Port 1: {why}");
}

/// The host listening on Port 2.
struct EventHost {
    reader: OwnedReadHalf,
    writer: OwnedWriteHalf,
    peer: SocketAddr,
    /// [`PortState::cuts`] when it connected.
    cuts: u64,
}

/// Port 2: R messages to the newest host, buffered by the twin while none listens.
async fn serve_events(listener: TcpListener, shared: Arc<Shared>) {
    let mut host: Option<EventHost> = None;
    let mut faults = shared.faults.subscribe();
    let mut buf = vec![0u8; 4096];
    loop {
        let next = shared.machine().next_event_at().map(Instant::from_std);
        tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok((stream, peer)) => {
                    if shared.fault(Port::Event) == Some(PortFault::Down) {
                        tracing::info!(%peer, "Port 2 is down (a fault set by the control): closing the new connection");
                        continue;
                    }
                    stream.set_nodelay(true).ok();
                    match host.take() {
                        Some(old) => tracing::warn!(%peer, old = %old.peer, "a new host connection on Port 2 takes over from the open one, which is closed"),
                        None => tracing::info!(%peer, "host connected on Port 2"),
                    }
                    shared.new_connection(Port::Event);
                    let (reader, writer) = stream.into_split();
                    let cuts = faults.borrow().event.cuts;
                    host = Some(EventHost { reader, writer, peer, cuts });
                    shared.machine().host_connected_on_port2(true, now());
                    shared.host(Port::Event, true);
                }
                Err(error) => {
                    tracing::warn!(%error, "Port 2: cannot accept a connection");
                    tokio::time::sleep(ACCEPT_RETRY).await;
                }
            },
            read = read_host(&mut host, &mut buf), if host.is_some() => match read {
                Ok(n) if n > 0 => shared.machine().handle_port2(buf.get(..n).unwrap_or_default()),
                ended => {
                    let why = match ended {
                        Err(error) => format!("connection error: {error}"),
                        Ok(_) => "the host closed the connection".to_owned(),
                    };
                    leave_port2(&shared, &mut host, &why);
                }
            },
            () = sleep_until(next), if next.is_some() => {}
            () = shared.wake.notified() => {}
            changed = faults.changed() => {
                if changed.is_err() {
                    return;
                }
                let state = faults.borrow_and_update().event;
                let closed = host.as_ref().is_some_and(|h| state.fault == Some(PortFault::Down) || state.cuts != h.cuts);
                if closed {
                    leave_port2(&shared, &mut host, "closed by a fault set by the control");
                }
            }
        }
        deliver(&shared, &mut host).await;
    }
}

/// Reads from the Port 2 host; never completes without one.
async fn read_host(host: &mut Option<EventHost>, buf: &mut [u8]) -> io::Result<usize> {
    match host {
        Some(host) => host.reader.read(buf).await,
        None => std::future::pending().await,
    }
}

async fn sleep_until(at: Option<Instant>) {
    match at {
        Some(at) => tokio::time::sleep_until(at).await,
        None => std::future::pending().await,
    }
}

/// The Port 2 host is gone: the twin buffers from now on.
fn leave_port2(shared: &Shared, host: &mut Option<EventHost>, why: &str) {
    if let Some(old) = host.take() {
        tracing::info!(peer = %old.peer, "host left Port 2: {why}");
    }
    shared.machine().host_connected_on_port2(false, now());
    shared.host(Port::Event, false);
}

/// Sends the R messages due now to the Port 2 host.
async fn deliver(shared: &Shared, host: &mut Option<EventHost>) {
    let messages = shared.machine().poll_events(now());
    if messages.is_empty() {
        return;
    }
    let Some(current) = host.as_mut() else {
        // poll_events gives nothing while no host listens: the twin keeps them.
        shared.machine().requeue_events(messages);
        return;
    };
    if shared.fault(Port::Event) == Some(PortFault::Silent) {
        tracing::debug!(
            lost = messages.len(),
            "Port 2 is silent (a fault): R messages lost"
        );
        return;
    }
    for message in &messages {
        tracing::debug!(%message, "R message sent");
    }
    if let Err(error) = current.writer.write_all(&concat(&messages)).await {
        let why = format!("cannot send R messages: {error}");
        leave_port2(shared, host, &why);
        // Back to the buffer for the next host (a failed write reached nobody).
        shared.machine().requeue_events(messages);
    }
}

/// Messages as one write.
fn concat(messages: &[Message]) -> Vec<u8> {
    messages.iter().flat_map(Message::to_bytes).collect()
}
