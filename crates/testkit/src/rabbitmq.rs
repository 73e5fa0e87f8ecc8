//! A real AMQP 1.0 broker for tests: Debian's RabbitMQ 3.10 with its `rabbitmq_amqp1_0`
//! plugin, a node of its own in a temporary directory (its database, logs, Erlang cookie
//! and port mapper), listening on a free loopback port, stopped on drop.
//!
//! The node's Erlang port mapper (`epmd`) and distribution port are on free ports too, so
//! a test's broker never meets another's or the machine's own RabbitMQ. Clients connect
//! from loopback with SASL ANONYMOUS (the plugin's default user, `guest`) or PLAIN
//! `guest`/`guest`. The node starts with a durable topic exchange whose every message goes
//! to a durable queue (a publisher writes to `/exchange/NAME`, a consumer reads
//! `/amq/queue/NAME`): what a consumer has not taken survives a restart of the node.
//!
//! [`RabbitMq::start_tls`] adds a TLS listener (AMQP over TLS, `amqps://`) on a second
//! port, with the certificate and key given; it asks clients for no certificate.
//!
//! [`RabbitMq::stop`] is a clean stop (SIGTERM: durable queues and their persistent
//! messages are kept); [`RabbitMq::start_again`] starts the node again on the same
//! directory and ports.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// How long a start may take before the test fails (it takes about seven seconds).
const START_LIMIT: Duration = Duration::from_secs(90);

/// Debian's place for the server's scripts.
const BIN: &str = "/usr/lib/rabbitmq/bin";

/// A running RabbitMQ node; stopped when dropped.
#[derive(Debug)]
pub struct RabbitMq {
    child: Option<Child>,
    dir: tempfile::TempDir,
    port: u16,
    tls_port: Option<u16>,
    dist_port: u16,
    epmd_port: u16,
}

impl RabbitMq {
    /// Starts a node with the AMQP 1.0 plugin on a free loopback port, with the durable
    /// topic exchange `exchange` bound (`#`) to the durable queue `queue`, and waits until
    /// it accepts connections.
    ///
    /// # Panics
    ///
    /// When RabbitMQ is not installed (the message says what to install) or does not
    /// start within 90 s (its log is shown).
    pub fn start(exchange: &str, queue: &str) -> Self {
        Self::launched(exchange, queue, None)
    }

    /// As [`RabbitMq::start`], with a TLS listener on [`RabbitMq::tls_port`] showing the
    /// certificate `cert` (PEM, its chain after it) with the private key `key`.
    ///
    /// # Panics
    ///
    /// As [`RabbitMq::start`].
    pub fn start_tls(exchange: &str, queue: &str, cert: &Path, key: &Path) -> Self {
        Self::launched(exchange, queue, Some((cert, key)))
    }

    fn launched(exchange: &str, queue: &str, tls: Option<(&Path, &Path)>) -> Self {
        assert!(
            Path::new(BIN).join("rabbitmq-server").exists(),
            "RabbitMQ is not installed: run scripts/test, which installs it, or \
             `apt-get install rabbitmq-server` (Debian 12: 3.10 with the AMQP 1.0 plugin)"
        );
        let dir = tempfile::tempdir().expect("a temporary directory for RabbitMQ");
        let mut node = Self {
            child: None,
            dir,
            port: crate::free_port(),
            tls_port: tls.map(|_| crate::free_port()),
            dist_port: crate::free_port(),
            epmd_port: crate::free_port(),
        };
        std::fs::write(node.path("enabled_plugins"), "[rabbitmq_amqp1_0].\n")
            .expect("the plugins file is written");
        std::fs::write(node.path("definitions.json"), definitions(exchange, queue))
            .expect("the definitions file is written");
        let mut conf = format!(
            "listeners.tcp.1 = 127.0.0.1:{}\nload_definitions = {}\n",
            node.port,
            node.path("definitions.json").display()
        );
        if let (Some((cert, key)), Some(port)) = (tls, node.tls_port) {
            conf.push_str(&format!(
                "listeners.ssl.1 = 127.0.0.1:{port}\nssl_options.certfile = {}\n\
                 ssl_options.keyfile = {}\nssl_options.verify = verify_none\n\
                 ssl_options.fail_if_no_peer_cert = false\n",
                cert.display(),
                key.display()
            ));
        }
        std::fs::write(node.path("rabbitmq.conf"), conf).expect("the config file is written");
        node.start_again();
        node
    }

    /// The AMQP port on 127.0.0.1.
    pub fn port(&self) -> u16 {
        self.port
    }

    /// The AMQP over TLS port on 127.0.0.1, if it was started with TLS.
    pub fn tls_port(&self) -> Option<u16> {
        self.tls_port
    }

    /// The start of an outage: stops the node cleanly (SIGTERM); every client loses its
    /// connection, durable queues keep their persistent messages.
    pub fn stop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = Command::new("kill")
                .arg("-TERM")
                .arg(child.id().to_string())
                .status();
            let _ = child.wait();
        }
    }

    /// Starts the node (again) on the same directory and ports, and waits until it accepts
    /// connections.
    ///
    /// # Panics
    ///
    /// When it does not start within 90 s.
    pub fn start_again(&mut self) {
        if self.child.is_some() {
            return;
        }
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(self.path("server.log"))
            .expect("the server log opens");
        let mut command = Command::new(Path::new(BIN).join("rabbitmq-server"));
        self.environment(&mut command);
        let child = command
            .stdin(Stdio::null())
            .stdout(log.try_clone().expect("the log file"))
            .stderr(log)
            .spawn()
            .expect("rabbitmq-server starts");
        self.child = Some(child);
        let deadline = Instant::now() + START_LIMIT;
        while std::net::TcpStream::connect(("127.0.0.1", self.port)).is_err() {
            assert!(
                Instant::now() < deadline,
                "RabbitMQ did not start on 127.0.0.1:{} within {START_LIMIT:?}; its log:\n{}",
                self.port,
                self.log()
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// What the node wrote so far (for a failing test's message).
    pub fn log(&self) -> String {
        let mut out = std::fs::read_to_string(self.path("server.log")).unwrap_or_default();
        if let Ok(entries) = std::fs::read_dir(self.path("log")) {
            for entry in entries.flatten() {
                out.push_str(&std::fs::read_to_string(entry.path()).unwrap_or_default());
            }
        }
        out
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    /// The node's environment: everything in its directory, every port its own.
    fn environment(&self, command: &mut Command) {
        let dir = self.dir.path();
        command
            .env("HOME", dir)
            .env(
                "RABBITMQ_NODENAME",
                format!("cellbus{}@localhost", self.port),
            )
            .env("RABBITMQ_NODE_IP_ADDRESS", "127.0.0.1")
            .env("RABBITMQ_NODE_PORT", self.port.to_string())
            .env("RABBITMQ_DIST_PORT", self.dist_port.to_string())
            .env("ERL_EPMD_PORT", self.epmd_port.to_string())
            .env("ERL_EPMD_ADDRESS", "127.0.0.1")
            .env("RABBITMQ_MNESIA_BASE", dir.join("mnesia"))
            .env("RABBITMQ_LOG_BASE", dir.join("log"))
            .env("RABBITMQ_CONFIG_FILE", dir.join("rabbitmq"))
            .env("RABBITMQ_ENABLED_PLUGINS_FILE", dir.join("enabled_plugins"))
            .env("RABBITMQ_PLUGINS_EXPAND_DIR", dir.join("plugins-expand"))
            .env("RABBITMQ_PID_FILE", dir.join("pid"));
    }
}

/// The node's definitions: the user `guest` (password `guest`; definitions loaded at boot
/// replace the default user), its permissions, and `exchange` → `queue`.
fn definitions(exchange: &str, queue: &str) -> String {
    // RabbitMQ's SHA-256 hash of "guest" with the salt 90 8d c6 0a: base64(salt ‖
    // sha256(salt ‖ "guest")).
    const GUEST: &str = "kI3GCrswBLNZQzHJJ95QLoyfAVooYhnvf7jbqiW9BjOYUloe";
    format!(
        r##"{{
  "users": [{{"name": "guest", "password_hash": "{GUEST}",
             "hashing_algorithm": "rabbit_password_hashing_sha256", "tags": ["administrator"]}}],
  "vhosts": [{{"name": "/"}}],
  "permissions": [{{"user": "guest", "vhost": "/", "configure": ".*", "write": ".*", "read": ".*"}}],
  "exchanges": [{{"name": "{exchange}", "vhost": "/", "type": "topic", "durable": true,
                 "auto_delete": false, "internal": false, "arguments": {{}}}}],
  "queues": [{{"name": "{queue}", "vhost": "/", "durable": true, "auto_delete": false,
              "arguments": {{}}}}],
  "bindings": [{{"source": "{exchange}", "vhost": "/", "destination": "{queue}",
                "destination_type": "queue", "routing_key": "#", "arguments": {{}}}}]
}}"##
    )
}

impl Drop for RabbitMq {
    fn drop(&mut self) {
        self.stop();
        // The node's port mapper outlives it (a daemon of its own): it is stopped too.
        let epmd = Path::new("/usr/bin/epmd");
        let _ = Command::new(if epmd.exists() {
            epmd
        } else {
            Path::new("epmd")
        })
        .args(["-port", &self.epmd_port.to_string(), "-kill"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status();
    }
}
