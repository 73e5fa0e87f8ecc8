//! A real PostgreSQL for tests and benches: a throwaway cluster made by Debian's server
//! binaries (`initdb`, `pg_ctl`) in a temporary directory, on a free loopback port, trusting
//! the user `cellbus`, and stopped (immediately) on drop.
//!
//! The binaries are taken from the newest `/usr/lib/postgresql/*/bin` (Debian's place) or
//! from `PATH`. `initdb` refuses to run as root, so as root every server command runs as the
//! user `postgres` (`runuser`), which then owns the temporary directory.
//!
//! [`Postgres::restart`] is a crash and a recovery (an immediate stop, then a start on the
//! same data and port): every client loses its connection, and what was committed stays.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// How long a start may take before the test fails (it takes about three seconds).
const START_LIMIT: Duration = Duration::from_secs(60);

/// The superuser that `initdb` creates and that every connection uses (no password).
pub const USER: &str = "cellbus";

/// The system user that runs the server when the tests run as root.
const SYSTEM_USER: &str = "postgres";

/// A running PostgreSQL cluster; stopped (immediate mode) and deleted when dropped.
#[derive(Debug)]
pub struct Postgres {
    bin: PathBuf,
    dir: tempfile::TempDir,
    port: u16,
    settings: Vec<(String, String)>,
    running: bool,
}

impl Postgres {
    /// Creates a cluster in a temporary directory, starts it on a free loopback port and
    /// waits until it accepts connections.
    ///
    /// # Panics
    ///
    /// When PostgreSQL's server binaries are not installed (the message says what to
    /// install), or the cluster cannot be created or does not start within a minute.
    pub fn start() -> Self {
        Self::start_with(&[])
    }

    /// As [`Postgres::start`], with server settings (`("synchronous_commit", "off")`)
    /// given to the server as `-c NAME=VALUE`; they stay across restarts.
    ///
    /// # Panics
    ///
    /// As [`Postgres::start`].
    pub fn start_with(settings: &[(&str, &str)]) -> Self {
        let bin = bin_dir();
        let dir = tempfile::tempdir().expect("a temporary directory for PostgreSQL");
        let mut cluster = Self {
            bin,
            dir,
            port: 0,
            settings: settings
                .iter()
                .map(|(k, v)| ((*k).to_owned(), (*v).to_owned()))
                .collect(),
            running: false,
        };
        cluster.init();
        let deadline = Instant::now() + START_LIMIT;
        loop {
            // A fresh port for every try: one that another process took between the pick
            // and the server's bind is not tried again.
            cluster.port = crate::free_port();
            if cluster.try_start() {
                return cluster;
            }
            assert!(
                Instant::now() < deadline,
                "PostgreSQL did not start on loopback within {START_LIMIT:?}; its log:\n{}",
                cluster.log()
            );
        }
    }

    /// The server's port on 127.0.0.1.
    pub fn port(&self) -> u16 {
        self.port
    }

    /// `postgres://cellbus@127.0.0.1:PORT/postgres`: the cluster's default database.
    pub fn url(&self) -> String {
        self.url_for("postgres")
    }

    /// `postgres://cellbus@127.0.0.1:PORT/{database}`.
    pub fn url_for(&self, database: &str) -> String {
        format!("postgres://{USER}@127.0.0.1:{}/{database}", self.port)
    }

    /// Creates the database `name` (letters, digits and `_`) and returns its URL: one
    /// cluster can serve many tests, each in its own database.
    ///
    /// # Panics
    ///
    /// When the name is not a plain identifier, or `psql` fails (its error is shown).
    pub fn create_database(&self, name: &str) -> String {
        assert!(
            !name.is_empty()
                && name
                    .chars()
                    .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_'),
            "a database name of lowercase letters, digits and _, not {name:?}"
        );
        self.psql("postgres", &format!("CREATE DATABASE {name}"));
        self.url_for(name)
    }

    /// Runs `sql` in `database` with `psql` and returns what it printed (unaligned, tuples
    /// only: one row a line, columns separated by `|`).
    ///
    /// # Panics
    ///
    /// When `psql` cannot run or the statement fails (its error is shown).
    pub fn psql(&self, database: &str, sql: &str) -> String {
        let out = Command::new(self.bin.join("psql"))
            .args(["-X", "-q", "-A", "-t", "-v", "ON_ERROR_STOP=1"])
            .args(["-h", "127.0.0.1", "-p", &self.port.to_string(), "-U", USER])
            .args(["-d", database, "-c", sql])
            .stdin(Stdio::null())
            .output()
            .unwrap_or_else(|e| panic!("cannot run {}: {e}", self.bin.join("psql").display()));
        assert!(
            out.status.success(),
            "psql {sql:?} in {database} failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    }

    /// A crash and a recovery: stops the server at once (no checkpoint, every client cut
    /// off) and starts it again on the same data and port.
    ///
    /// # Panics
    ///
    /// When it does not start again within a minute.
    pub fn restart(&mut self) {
        self.stop();
        self.start_again();
    }

    /// The start of an outage: stops the server at once (`pg_ctl -m immediate stop`);
    /// clients lose their connections and new ones are refused.
    pub fn stop(&mut self) {
        if !self.running {
            return;
        }
        let data = self.data_dir();
        let out = self.server_command("pg_ctl", |c| {
            c.arg("-D")
                .arg(&data)
                .args(["-m", "immediate", "-w", "stop"]);
        });
        if out.status.success() {
            self.running = false;
        } else {
            eprintln!(
                "pg_ctl stop failed: {}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
    }

    /// The end of an outage begun by [`Postgres::stop`]: starts the server again on the
    /// same data and port (waiting while the port is still held).
    ///
    /// # Panics
    ///
    /// When it does not start within a minute.
    pub fn start_again(&mut self) {
        if self.running {
            return;
        }
        let deadline = Instant::now() + START_LIMIT;
        while !self.try_start() {
            assert!(
                Instant::now() < deadline,
                "PostgreSQL did not start again on 127.0.0.1:{} within {START_LIMIT:?}; \
                 its log:\n{}",
                self.port,
                self.log()
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// The server's log so far (for a failing test's message).
    pub fn log(&self) -> String {
        std::fs::read_to_string(self.log_path()).unwrap_or_default()
    }

    fn data_dir(&self) -> PathBuf {
        self.dir.path().join("data")
    }

    fn log_path(&self) -> PathBuf {
        self.dir.path().join("postgres.log")
    }

    /// `initdb`: a cluster trusting local connections, superuser `cellbus`, UTF-8.
    fn init(&mut self) {
        if running_as_root() {
            // The server runs as `postgres`: it must own the directory it writes in.
            let status = Command::new("chown")
                .arg(format!("{SYSTEM_USER}:"))
                .arg(self.dir.path())
                .status()
                .expect("chown can run");
            assert!(
                status.success(),
                "cannot give {} to the user {SYSTEM_USER} (does it exist? Debian's \
                 postgresql package creates it)",
                self.dir.path().display()
            );
        }
        let data = self.data_dir();
        let out = self.server_command("initdb", |c| {
            c.arg("-D")
                .arg(&data)
                .args(["-A", "trust", "-U", USER, "-E", "UTF8", "--no-sync"])
                .arg("--locale=C");
        });
        assert!(
            out.status.success(),
            "initdb failed: {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }

    /// `pg_ctl start` on the current port; whether the server accepts connections.
    fn try_start(&mut self) -> bool {
        let mut options = format!(
            "-p {} -k {} -c listen_addresses=127.0.0.1",
            self.port,
            self.dir.path().display()
        );
        for (name, value) in &self.settings {
            options.push_str(&format!(" -c {name}={value}"));
        }
        let (data, log) = (self.data_dir(), self.log_path());
        let out = self.server_command("pg_ctl", |c| {
            c.arg("-D")
                .arg(&data)
                .arg("-l")
                .arg(&log)
                .args(["-o", &options, "-w", "-t", "60", "start"]);
        });
        self.running = out.status.success();
        self.running
    }

    /// Runs one of the server's binaries, as `postgres` when we are root.
    fn server_command(&self, name: &str, args: impl FnOnce(&mut Command)) -> Output {
        let binary = self.bin.join(name);
        let mut command = if running_as_root() {
            let mut c = Command::new("runuser");
            c.args(["-u", SYSTEM_USER, "--"]).arg(&binary);
            c
        } else {
            Command::new(&binary)
        };
        args(&mut command);
        command
            .stdin(Stdio::null())
            .output()
            .unwrap_or_else(|e| panic!("cannot run {}: {e}", binary.display()))
    }
}

impl Drop for Postgres {
    fn drop(&mut self) {
        self.stop();
    }
}

/// Whether this process runs as root (the owner of `/proc/self` is the effective user).
fn running_as_root() -> bool {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata("/proc/self").is_ok_and(|m| m.uid() == 0)
}

/// The directory of PostgreSQL's server binaries: the newest
/// `/usr/lib/postgresql/VERSION/bin` with an `initdb`, or the one in `PATH`.
fn bin_dir() -> PathBuf {
    newest_debian_bin(Path::new("/usr/lib/postgresql"))
        .or_else(|| {
            std::env::var_os("PATH")
                .into_iter()
                .flat_map(|p| std::env::split_paths(&p).collect::<Vec<_>>())
                .find(|dir| dir.join("initdb").exists() && dir.join("pg_ctl").exists())
        })
        .unwrap_or_else(|| {
            panic!(
                "the PostgreSQL tests need PostgreSQL's server binaries (initdb, pg_ctl, \
                 psql), found neither in /usr/lib/postgresql/*/bin nor in PATH: install \
                 Debian's package (apt-get install -y postgresql; scripts/test does it)"
            )
        })
}

/// The `bin` of the highest numbered version under `root` that has an `initdb`.
fn newest_debian_bin(root: &Path) -> Option<PathBuf> {
    std::fs::read_dir(root)
        .ok()?
        .filter_map(Result::ok)
        .filter_map(|entry| {
            let version = entry.file_name().to_str()?.parse::<f64>().ok()?;
            let bin = entry.path().join("bin");
            bin.join("initdb").exists().then_some((version, bin))
        })
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, bin)| bin)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cluster_keeps_committed_rows_across_a_crash_and_answers_on_the_same_port() {
        let mut pg = Postgres::start();
        let url = pg.create_database("kept");
        assert!(url.ends_with(&format!(":{}/kept", pg.port())), "{url}");
        pg.psql(
            "kept",
            "CREATE TABLE t (x int); INSERT INTO t VALUES (1), (2)",
        );
        let port = pg.port();
        pg.restart();
        assert_eq!(pg.port(), port);
        assert_eq!(pg.psql("kept", "SELECT sum(x) FROM t").trim(), "3");
    }

    #[test]
    fn a_stopped_cluster_refuses_connections_until_it_starts_again() {
        let mut pg = Postgres::start();
        pg.stop();
        assert!(
            std::net::TcpStream::connect((std::net::Ipv4Addr::LOCALHOST, pg.port())).is_err(),
            "nothing listens while stopped"
        );
        pg.start_again();
        assert_eq!(pg.psql("postgres", "SELECT 40 + 2").trim(), "42");
    }

    #[test]
    fn the_newest_version_directory_with_an_initdb_is_chosen() {
        let root = tempfile::tempdir().expect("a temporary directory");
        for version in ["9.6", "15", "13"] {
            let bin = root.path().join(version).join("bin");
            std::fs::create_dir_all(&bin).expect("a bin directory");
            std::fs::write(bin.join("initdb"), "").expect("an initdb");
        }
        std::fs::create_dir_all(root.path().join("16/bin")).expect("a bin without initdb");
        assert_eq!(
            newest_debian_bin(root.path()),
            Some(root.path().join("15/bin"))
        );
    }
}
