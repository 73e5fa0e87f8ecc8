//! A real MQTT broker for tests: Debian's `mosquitto` on a free loopback port, started
//! from a config file in a temporary directory and killed on drop.
//!
//! It keeps its sessions on disk across [`Mosquitto::restart`] and queues QoS 0 messages
//! for a subscriber with a persistent session, so a test subscriber that reconnects after
//! the outage still receives what a faster client published before it was back: the test
//! can judge what was sent without racing the client under test.
//!
//! [`Mosquitto::start_tls`] adds a TLS listener on a second port, with the plain one kept
//! for the test's own subscriber. [`Mosquitto::start_with_access`] turns anonymous clients
//! away and applies a password file and an ACL file (see [`password_file`]).

use std::net::{Ipv4Addr, TcpListener};
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
    /// The TLS listener's port and files.
    tls: Option<(u16, TlsFiles)>,
    /// The password file and the ACL file, when clients must log in.
    access: Option<(PathBuf, PathBuf)>,
}

/// The PEM files of a TLS listener.
#[derive(Debug, Clone)]
pub struct TlsFiles {
    /// The CA certificates that sign the clients' certificates.
    pub ca: PathBuf,
    /// The broker's certificate.
    pub cert: PathBuf,
    /// Its private key.
    pub key: PathBuf,
    /// Whether a client must show a certificate signed by `ca`.
    pub require_certificate: bool,
}

impl Mosquitto {
    /// Starts mosquitto on a free loopback port and waits until it accepts connections.
    ///
    /// # Panics
    ///
    /// When mosquitto is not installed (the message says what to install) or does not
    /// start in 20 s.
    pub fn start() -> Self {
        Self::launched(None, None)
    }

    /// Starts mosquitto with a plain listener on [`Mosquitto::port`] and a TLS listener
    /// with `files` on [`Mosquitto::tls_port`], both on loopback, and waits until both
    /// accept connections.
    ///
    /// # Panics
    ///
    /// As [`Mosquitto::start`].
    pub fn start_tls(files: &TlsFiles) -> Self {
        Self::launched(Some(files.clone()), None)
    }

    /// Starts mosquitto on a free loopback port where clients must log in with a user of
    /// `password_file` (mosquitto's format, [`password_file`] makes one) and may publish
    /// and subscribe only as `acl_file` (mosquitto's `acl_file` format) allows; anonymous
    /// clients are refused.
    ///
    /// # Panics
    ///
    /// As [`Mosquitto::start`].
    pub fn start_with_access(password_file: &Path, acl_file: &Path) -> Self {
        Self::launched(None, Some((password_file.to_owned(), acl_file.to_owned())))
    }

    fn launched(files: Option<TlsFiles>, access: Option<(PathBuf, PathBuf)>) -> Self {
        let dir = tempfile::tempdir().expect("a temporary directory for mosquitto");
        let mut broker = Self {
            child: None,
            port: 0,
            dir,
            tls: None,
            access,
        };
        let deadline = Instant::now() + START_LIMIT;
        loop {
            // Fresh ports for every try: a port that another process took between the
            // pick and mosquitto's bind (a client's or a server's, of a test running
            // alongside) is not tried again.
            let (plain, tls) = two_free_ports();
            broker.port = plain;
            broker.tls = files.clone().map(|files| (tls, files));
            if broker.try_launch(deadline) {
                return broker;
            }
            assert!(
                Instant::now() < deadline,
                "mosquitto did not start on loopback within {START_LIMIT:?}"
            );
        }
    }

    /// The broker's (plain) port on 127.0.0.1.
    pub fn port(&self) -> u16 {
        self.port
    }

    /// The TLS listener's port on 127.0.0.1.
    ///
    /// # Panics
    ///
    /// When the broker was not started with [`Mosquitto::start_tls`].
    pub fn tls_port(&self) -> u16 {
        self.tls
            .as_ref()
            .expect("a broker started with Mosquitto::start_tls")
            .0
    }

    /// The broker's process id, while it runs (benches read its CPU time from `/proc`).
    pub fn pid(&self) -> Option<u32> {
        self.child.as_ref().map(Child::id)
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

    /// Starts the broker again on its ports.
    fn launch(&mut self) {
        let deadline = Instant::now() + START_LIMIT;
        while !self.try_launch(deadline) {
            // A port may still be held by the previous broker's socket: try again.
            assert!(
                Instant::now() < deadline,
                "mosquitto did not start again on 127.0.0.1:{} within {START_LIMIT:?}",
                self.port
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Starts mosquitto on its ports; whether it runs (every listener open) before
    /// `deadline`.
    fn try_launch(&mut self, deadline: Instant) -> bool {
        let binary = binary();
        let config = self.dir.path().join("mosquitto.conf");
        let log = self.dir.path().join("mosquitto.log");
        let access = match &self.access {
            Some((passwords, acl)) => format!(
                "allow_anonymous false\npassword_file {}\nacl_file {}\n",
                passwords.display(),
                acl.display()
            ),
            None => "allow_anonymous true\n".to_owned(),
        };
        let mut text = format!(
            "listener {} 127.0.0.1\n{access}user root\n\
             persistence true\npersistence_location {}/\nqueue_qos0_messages true\n\
             message_size_limit 0\nlog_dest file {}\n",
            self.port,
            self.dir.path().display(),
            log.display()
        );
        if let Some((port, files)) = &self.tls {
            text.push_str(&format!(
                "listener {port} 127.0.0.1\ncafile {}\ncertfile {}\nkeyfile {}\n\
                 require_certificate {}\n",
                files.ca.display(),
                files.cert.display(),
                files.key.display(),
                files.require_certificate
            ));
        }
        std::fs::write(&config, text).expect("mosquitto's config file can be written");
        let _ = std::fs::remove_file(&log);
        let child = Command::new(&binary)
            .arg("-c")
            .arg(&config)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {}: {e}", binary.display()));
        let child = self.child.insert(child);
        if wait_until_running(&log, child, deadline) {
            return true;
        }
        self.kill();
        false
    }
}

impl Drop for Mosquitto {
    fn drop(&mut self) {
        self.kill();
    }
}

/// Writes a mosquitto password file at `path` with `users` (name, password), hashed by
/// Debian's `mosquitto_passwd` (from the mosquitto package).
///
/// # Panics
///
/// When `mosquitto_passwd` is missing or fails.
pub fn password_file(path: &Path, users: &[(&str, &str)]) {
    std::fs::write(path, "").expect("the password file can be written");
    for (user, password) in users {
        let status = Command::new("mosquitto_passwd")
            .arg("-b")
            .arg(path)
            .args([user, password])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .status()
            .unwrap_or_else(|e| {
                panic!("cannot run mosquitto_passwd (Debian's mosquitto package has it): {e}")
            });
        assert!(status.success(), "mosquitto_passwd failed for {user}");
    }
}

/// Two different free loopback ports (both held at once while picked).
fn two_free_ports() -> (u16, u16) {
    let bind = || TcpListener::bind((Ipv4Addr::LOCALHOST, 0)).expect("a free loopback port");
    let (a, b) = (bind(), bind());
    let port = |l: &TcpListener| l.local_addr().expect("a bound port").port();
    (port(&a), port(&b))
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

/// Whether mosquitto logs that it runs (after opening every listener; a port taken
/// makes it exit instead) before `deadline`; false if it exited.
fn wait_until_running(log: &Path, child: &mut Child, deadline: Instant) -> bool {
    while Instant::now() < deadline {
        if std::fs::read_to_string(log).is_ok_and(|text| text.contains(" running")) {
            return true;
        }
        if matches!(child.try_wait(), Ok(Some(_))) {
            return false;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    false
}
