//! `cellbus historian`: the runtime, from [`Options`] to a clean stop.
//!
//! Three tasks: the MQTT link ([`crate::mqtt`]), the writer ([`crate::writer`]) and, with
//! `--listen`, the HTTP API ([`crate::http`]). They share the counters and the health.
//!
//! Stopping (Ctrl-C, SIGTERM): STATE offline and a clean disconnect first (the edge nodes
//! store from then on), then the rows still pending are committed (within the writer's
//! grace), then the HTTP server ends.

use std::future::Future;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};

use anyhow::{Context as _, bail};
use kit::mqtt::{MqttTls, parse_broker};
use rumqttc::Transport;
use sparkplug::{Host, Id, Sharing};
use tokio::sync::{mpsc, watch};

use crate::http::{self, AppState};
use crate::metrics::{Health, Metrics};
use crate::mqtt::{Broker, Link};
use crate::writer::{DbState, Limits, Writer};

/// The host id by default (`spBv1.0/STATE/cellbus-historian`).
pub const DEFAULT_HOST_ID: &str = "cellbus-historian";

/// Messages queued between the MQTT task and the writer (each a small batch).
const ROWS_QUEUE: usize = 4096;

/// What `cellbus historian` was asked for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Options {
    /// The broker: `mqtt://HOST[:PORT]` or `mqtts://HOST[:PORT]`.
    pub mqtt: String,
    /// TLS files for `mqtts://` (the system's roots without a CA file).
    pub tls: MqttTls,
    /// The broker's user name, if any.
    pub username: Option<String>,
    /// The environment variable holding the broker's password.
    pub password_env: Option<String>,
    /// `postgres://USER@HOST:PORT/DB` (a password in it, or in `PGPASSWORD`).
    pub database: String,
    /// The Sparkplug host id (the edge nodes' `primary_host`).
    pub host_id: String,
    /// Only this Sparkplug group; every group when `None`.
    pub group: Option<String>,
    /// Share the data with other historians through `$share/{name}/…`.
    pub share: Option<String>,
    /// Where the plant API listens, if anywhere.
    pub listen: Option<SocketAddr>,
    /// The writer's bounds.
    pub limits: Limits,
    /// What the Sparkplug host keeps at most: edge nodes, metrics per node and in all.
    pub host_limits: sparkplug::host::Limits,
}

/// A started historian: arguments checked, HTTP port bound.
pub struct Historian {
    options: Options,
    broker: Broker,
    host: Host,
    listener: Option<tokio::net::TcpListener>,
    addr: Option<SocketAddr>,
}

impl Historian {
    /// Checks the options (ids, broker URL, TLS files, password variable) and binds the
    /// HTTP port; nothing is connected yet.
    ///
    /// # Errors
    ///
    /// A bad id, URL or TLS file, a password variable that is not set, a port that
    /// cannot be bound.
    pub async fn start(options: Options) -> anyhow::Result<Historian> {
        let id = |what: &str, text: &str| {
            Id::new(text).map_err(|e| anyhow::anyhow!("{what} {text:?}: {e}"))
        };
        let host_id = id("--host-id", &options.host_id)?;
        let group = options
            .group
            .as_deref()
            .map(|g| id("--group", g))
            .transpose()?;
        let sharing = match &options.share {
            Some(name) => Sharing::Shared {
                name: id("--share", name)?,
            },
            None => Sharing::Alone,
        };
        let parsed = parse_broker(&options.mqtt).map_err(|m| anyhow::anyhow!("--mqtt: {m}"))?;
        check_database(&options.database)?;
        let transport = if parsed.tls {
            let config = kit::mqtt::tls::client_config(&options.tls).context("MQTT TLS")?;
            kit::mqtt::tls::transport(&config)
        } else {
            if options.tls.ca_file.is_some() || options.tls.client.is_some() {
                bail!(
                    "--ca-file and --client-cert are for mqtts://; the broker is {}",
                    options.mqtt
                );
            }
            Transport::Tcp
        };
        let credentials = match (&options.username, &options.password_env) {
            (Some(user), Some(var)) => {
                let password = std::env::var(var).map_err(|_| {
                    anyhow::anyhow!("the MQTT password's environment variable {var} is not set")
                })?;
                Some((user.clone(), password))
            }
            (Some(user), None) => Some((user.clone(), String::new())),
            (None, _) => None,
        };
        let broker = Broker {
            host: parsed.host,
            port: parsed.port,
            transport,
            credentials,
        };
        let (listener, addr) = match options.listen {
            Some(listen) => {
                let listener = tokio::net::TcpListener::bind(listen)
                    .await
                    .with_context(|| format!("cannot listen on {listen}"))?;
                let addr = listener.local_addr()?;
                if !addr.ip().is_loopback() {
                    tracing::warn!(
                        "the historian's API listens on {addr}, beyond this machine: it has no \
                         token; put it behind the plant's proxy"
                    );
                }
                (Some(listener), Some(addr))
            }
            None => (None, None),
        };
        Ok(Historian {
            host: Host::new(host_id, group, sharing).with_limits(options.host_limits),
            options,
            broker,
            listener,
            addr,
        })
    }

    /// `mqtt://HOST:PORT` (or `mqtts://`): the broker, for the first line printed.
    pub fn broker_url(&self) -> String {
        let scheme = if matches!(self.broker.transport, Transport::Tcp) {
            "mqtt"
        } else {
            "mqtts"
        };
        format!("{scheme}://{}:{}", self.broker.host, self.broker.port)
    }

    /// The HTTP API's address, with `--listen`.
    pub fn local_addr(&self) -> Option<SocketAddr> {
        self.addr
    }

    /// Runs until `shutdown` resolves, then stops cleanly (see the module's docs).
    ///
    /// # Errors
    ///
    /// What no retry fixes: PostgreSQL refusing the login, a database whose schema is
    /// newer than this historian's.
    pub async fn run(self, shutdown: impl Future<Output = ()>) -> anyhow::Result<()> {
        let metrics = Arc::new(Metrics::new());
        let health = Arc::new(Health::new());
        let (stop_tx, stop) = watch::channel(false);
        let (db_tx, db) = watch::channel(DbState::Failing("not connected yet".to_owned()));
        let (rows_tx, rows_rx) = mpsc::channel(ROWS_QUEUE);
        let writer = Writer::new(
            self.options.database.clone(),
            rows_rx,
            db_tx,
            Arc::clone(&health),
            Arc::clone(&metrics),
            self.options.limits,
        );
        let mut writer = tokio::spawn(writer.run());
        let link = Link {
            broker: self.broker,
            host: Arc::new(Mutex::new(self.host)),
            rows: rows_tx,
            db,
            metrics: Arc::clone(&metrics),
            health: Arc::clone(&health),
        };
        let mut mqtt = tokio::spawn(link.run(stop.clone()));
        let server = self.listener.map(|listener| {
            let state = Arc::new(AppState {
                url: self.options.database.clone(),
                reader: tokio::sync::Mutex::new(None),
                metrics: Arc::clone(&metrics),
                health: Arc::clone(&health),
            });
            tokio::spawn(kit::http::server::serve(
                listener,
                http::router(state),
                kit::http::server::Limits::default(),
                stop.clone(),
            ))
        });
        tokio::pin!(shutdown);
        let early = tokio::select! {
            () = &mut shutdown => None,
            ended = &mut writer => Some(ended),
        };
        let _ = stop_tx.send(true);
        if let Some(ended) = early {
            // The writer only ends early on what no retry fixes.
            mqtt.abort();
            if let Some(server) = server {
                server.abort();
            }
            return match ended {
                Ok(Ok(())) => bail!("the writer stopped"),
                Ok(Err(e)) => Err(e).context("PostgreSQL"),
                Err(e) => Err(e).context("the writer task"),
            };
        }
        let _ = (&mut mqtt).await;
        match writer.await {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(e).context("PostgreSQL"),
            Err(e) => return Err(e).context("the writer task"),
        }
        if let Some(server) = server {
            let _ = server.await;
        }
        Ok(())
    }
}

/// Refuses a `--database` that is no PostgreSQL connection string, before anything starts
/// (a bad argument, exit 2, not a refused login), with the store's own reading of it.
fn check_database(text: &str) -> anyhow::Result<()> {
    crate::store::parse_url(text).map_err(|e| anyhow::anyhow!("--database: {e}"))?;
    Ok(())
}

#[cfg(test)]
mod database_tests {
    use super::check_database;

    #[test]
    fn a_database_that_is_not_postgresql_is_refused_without_repeating_it() {
        assert!(check_database("postgres://cellbus@127.0.0.1:5432/plant").is_ok());
        assert!(check_database("host=127.0.0.1 user=cellbus").is_ok());
        for (database, why) in [
            ("mysql://u:secret@h/db", "mysql:// is not PostgreSQL"),
            (
                "postgres://u:secret@h:notaport/db",
                "not a PostgreSQL connection string",
            ),
        ] {
            let refusal = check_database(database).unwrap_err().to_string();
            assert!(
                refusal.contains(why) && !refusal.contains("secret"),
                "{refusal}"
            );
        }
    }
}
