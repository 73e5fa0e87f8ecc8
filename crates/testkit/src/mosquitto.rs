//! A real MQTT broker for tests: Debian's `mosquitto` on a free loopback port, started
//! from a config file in a temporary directory and killed on drop.
//!
//! It keeps its sessions on disk across [`Mosquitto::restart`] and queues QoS 0 messages
//! for a subscriber with a persistent session, so a test subscriber that reconnects after
//! the outage still receives what a faster client published before it was back: the test
//! can judge what was sent without racing the client under test.

use std::net::{Ipv4Addr, SocketAddr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// How long a start may take before the test fails (it takes about a second).
const START_LIMIT: Duration = Duration::from_secs(20);

/// A running mosquitto; killed when dropped.
#[derive(Debug)]
pub struct Mosquitto {
    child: Option<Child>,
    port: u16,
    dir: tempfile::TempDir,
}

impl Mosquitto {
    /// Starts mosquitto on a free loopback port and waits until it accepts connections.
    ///
    /// # Panics
    ///
    /// When mosquitto is not installed (the message says what to install) or does not
    /// start in 20 s.
    pub fn start() -> Self {
        let port = TcpListener::bind((Ipv4Addr::LOCALHOST, 0))
            .and_then(|l| l.local_addr())
            .expect("a free loopback port")
            .port();
        let dir = tempfile::tempdir().expect("a temporary directory for mosquitto");
        let mut broker = Self {
            child: None,
            port,
            dir,
        };
        broker.launch();
        broker
    }

    /// The broker's port on 127.0.0.1.
    pub fn port(&self) -> u16 {
        self.port
    }

    /// `mqtt://127.0.0.1:PORT`.
    pub fn url(&self) -> String {
        format!("mqtt://127.0.0.1:{}", self.port)
    }

    /// Kills the broker (an outage: every client loses its connection).
    pub fn kill(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }

    /// An outage: stops the broker (SIGTERM, so it saves its sessions; every client loses
    /// its connection) and starts it again on the same port.
    pub fn restart(&mut self) {
        self.stop();
        self.launch();
    }

    /// The end of an outage begun by [`Mosquitto::stop`]: starts the broker again on the
    /// same port, with the sessions it saved.
    pub fn start_again(&mut self) {
        if self.child.is_none() {
            self.launch();
        }
    }

    /// The start of an outage: stops the broker (SIGTERM, so it saves its sessions; every
    /// client loses its connection).
    pub fn stop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let stopped = Command::new("kill")
                .arg("-TERM")
                .arg(child.id().to_string())
                .status()
                .is_ok_and(|s| s.success());
            if !stopped {
                let _ = child.kill();
            }
            let _ = child.wait();
        }
    }

    fn launch(&mut self) {
        let binary = binary();
        let config = self.dir.path().join("mosquitto.conf");
        std::fs::write(
            &config,
            format!(
                "listener {} 127.0.0.1\nallow_anonymous true\nuser root\n\
                 persistence true\npersistence_location {}/\nqueue_qos0_messages true\n\
                 message_size_limit 0\n",
                self.port,
                self.dir.path().display()
            ),
        )
        .expect("mosquitto's config file can be written");
        let deadline = Instant::now() + START_LIMIT;
        loop {
            let child = Command::new(&binary)
                .arg("-c")
                .arg(&config)
                .stdin(Stdio::null())
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .unwrap_or_else(|e| panic!("cannot start {}: {e}", binary.display()));
            self.child = Some(child);
            if wait_for_port(self.port, self.child.as_mut().expect("just set"), deadline) {
                return;
            }
            // The port may still be held by the previous broker's socket: try again.
            self.kill();
            assert!(
                Instant::now() < deadline,
                "mosquitto did not accept connections on 127.0.0.1:{} within {START_LIMIT:?}",
                self.port
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }
}

impl Drop for Mosquitto {
    fn drop(&mut self) {
        self.kill();
    }
}

/// The mosquitto binary, from PATH or Debian's place.
fn binary() -> PathBuf {
    let debian = Path::new("/usr/sbin/mosquitto");
    if debian.exists() {
        return debian.to_owned();
    }
    std::env::var_os("PATH")
        .into_iter()
        .flat_map(|p| std::env::split_paths(&p).collect::<Vec<_>>())
        .map(|dir| dir.join("mosquitto"))
        .find(|p| p.exists())
        .unwrap_or_else(|| {
            panic!(
                "the MQTT tests need the mosquitto broker: install Debian's package \
                 (apt-get install -y mosquitto; scripts/test does it)"
            )
        })
}

/// Whether the broker accepts TCP connections before `deadline`; false if it exited.
fn wait_for_port(port: u16, child: &mut Child, deadline: Instant) -> bool {
    let addr = SocketAddr::from((Ipv4Addr::LOCALHOST, port));
    while Instant::now() < deadline {
        if TcpStream::connect_timeout(&addr, Duration::from_millis(200)).is_ok() {
            return true;
        }
        if matches!(child.try_wait(), Ok(Some(_))) {
            return false;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    false
}
