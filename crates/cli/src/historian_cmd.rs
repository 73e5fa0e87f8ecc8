//! `cellbus historian`: the plant historian, a Sparkplug B primary host that stores every
//! gateway's data in PostgreSQL. The work is `historian::Historian`; this module reads the
//! arguments and prints the first lines.

use std::io::Write as _;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context as _;
use clap::Args;

use crate::output::usage;

#[derive(Debug, Args)]
pub struct HistorianArgs {
    /// The plant's broker: mqtt://HOST[:PORT] (1883 by default) or mqtts://HOST[:PORT]
    /// (TLS, 8883 by default). The first line printed is `historian on mqtt://HOST:PORT`.
    #[arg(long, value_name = "URL")]
    mqtt: String,
    /// PostgreSQL: postgres://USER@HOST:PORT/DB (libpq options after `?`, e.g.
    /// `options=-c%20synchronous_commit%3Doff`). A password is taken from the URL or, when
    /// it has none, from PGPASSWORD (better: it does not show in the process list). The
    /// schema is created or migrated on first connection.
    #[arg(long, value_name = "URL")]
    database: String,
    /// The Sparkplug host id: STATE is published on spBv1.0/STATE/ID. Give the gateways
    /// the same id (`cellbus serve --mqtt-primary-host ID`) so they store and forward
    /// while the historian (or its database) is away.
    #[arg(long, value_name = "ID", default_value = historian::DEFAULT_HOST_ID)]
    host_id: String,
    /// Follow only this Sparkplug group (default: every group).
    #[arg(long, value_name = "G")]
    group: Option<String>,
    /// Share the gateways' data with other historians through the MQTT shared
    /// subscription $share/NAME/… (each data message reaches one of them; births and
    /// deaths reach all). Give each historian its own --host-id; the gateways name one of
    /// them as their primary host.
    #[arg(long, value_name = "NAME")]
    share: Option<String>,
    /// Serve the plant API (/api/history, /api/points, /api/events, /healthz, /metrics)
    /// here; port 0 picks a free port. The second line printed is
    /// `listening on http://IP:PORT`.
    #[arg(long, value_name = "IP:PORT")]
    listen: Option<SocketAddr>,
    /// For mqtts://: the CA certificates (PEM) that sign the broker's; without it, the
    /// system's roots.
    #[arg(long, value_name = "FILE")]
    ca_file: Option<PathBuf>,
    /// For mqtts://: a client certificate (PEM) for a broker that asks for one.
    #[arg(long, value_name = "FILE", requires = "client_key")]
    client_cert: Option<PathBuf>,
    /// The client certificate's private key (PEM).
    #[arg(long, value_name = "FILE", requires = "client_cert")]
    client_key: Option<PathBuf>,
    /// The MQTT user name.
    #[arg(long)]
    username: Option<String>,
    /// The environment variable that holds the MQTT password (never the password itself).
    #[arg(long, value_name = "VAR", requires = "username")]
    password_env: Option<String>,
    /// Most samples waiting for their commit; past it new rows are dropped and the
    /// historian goes offline until PostgreSQL catches up (the gateways send them again).
    #[arg(long, value_name = "N", default_value_t = 500_000,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
    max_pending: usize,
    /// Samples and events older than this (by the historian's clock) are refused and
    /// counted as dropped: a gateway clock gone wrong, or a rogue birth naming a day per
    /// metric, would otherwise create a day partition for each day it names. Raise it to
    /// take a longer backlog.
    #[arg(long, value_name = "DURATION", default_value = "31days", value_parser = parse_max_age)]
    max_age: std::time::Duration,
    /// Most gateways (Sparkplug edge nodes) followed at once. A birth from one more is
    /// refused, logged and counted (cellbus_historian_births_refused_total) until a
    /// gateway that died 10 minutes ago or more is forgotten. Raise it for a larger plant.
    #[arg(long, value_name = "N", default_value_t = 1_000,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
    max_nodes: usize,
    /// Most points of all gateways together (every metric of their current births). A
    /// birth past it is refused whole: that gateway or device is not recorded, and it is
    /// asked to send its birth again only every 5 minutes. Each point costs the historian
    /// a few hundred bytes of memory.
    #[arg(long, value_name = "N", default_value_t = 250_000,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
    max_points: usize,
    /// Most points of one gateway (its own metrics and all its devices'). A birth past it
    /// is refused whole, as for --max-points. A large plant gateway has up to 100,000.
    #[arg(long, value_name = "N", default_value_t = 100_000,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
    max_node_points: usize,
}

/// `--max-age`: a duration longer than 0 (0 would refuse every sample, live ones too).
fn parse_max_age(text: &str) -> Result<std::time::Duration, String> {
    match humantime::parse_duration(text) {
        Ok(d) if d.is_zero() => Err("0 would refuse every sample, live ones too: give the \
             oldest age to keep, e.g. 31days"
            .to_owned()),
        Ok(d) => Ok(d),
        Err(e) => Err(format!("{e}; e.g. 31days")),
    }
}

pub async fn run(args: HistorianArgs) -> anyhow::Result<ExitCode> {
    let options = historian::Options {
        mqtt: args.mqtt,
        tls: kit::mqtt::MqttTls {
            ca_file: args.ca_file,
            client: args
                .client_cert
                .zip(args.client_key)
                .map(|(cert, key)| kit::mqtt::MqttClientCert { cert, key }),
        },
        username: args.username,
        password_env: args.password_env,
        database: args.database,
        host_id: args.host_id,
        group: args.group,
        share: args.share,
        listen: args.listen,
        limits: historian::writer::Limits {
            max_pending: args.max_pending,
            max_age: args.max_age,
            point_cache: args.max_points,
            ..historian::writer::Limits::default()
        },
        host_limits: sparkplug::host::Limits {
            max_nodes: args.max_nodes,
            max_points: args.max_points,
            max_node_points: args.max_node_points,
        },
    };
    let started = historian::Historian::start(options)
        .await
        .map_err(|e| usage(format!("{e:#}")))?;
    {
        let mut out = std::io::stdout().lock();
        writeln!(out, "historian on {}", started.broker_url())
            .and_then(|()| match started.local_addr() {
                Some(addr) => writeln!(out, "listening on http://{addr}"),
                None => Ok(()),
            })
            .and_then(|()| out.flush())
            .context("cannot write to standard output")?;
    }
    started.run(crate::serve_cmd::shutdown_signal()).await?;
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::parse_max_age;

    #[test]
    fn the_default_limits_of_nodes_and_points_are_the_hosts() {
        // The flags' defaults are numbers for clap; they must stay the host's.
        use clap::Parser as _;
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            args: super::HistorianArgs,
        }
        let cli = Cli::parse_from([
            "cellbus",
            "--mqtt",
            "mqtt://h",
            "--database",
            "postgres://h",
        ]);
        let defaults = sparkplug::host::Limits::default();
        assert_eq!(
            (
                cli.args.max_nodes,
                cli.args.max_points,
                cli.args.max_node_points
            ),
            (
                defaults.max_nodes,
                defaults.max_points,
                defaults.max_node_points
            )
        );
        assert_eq!(cli.args.max_points, historian::store::DEFAULT_POINT_CACHE);
    }

    #[test]
    fn the_default_max_age_is_the_writers() {
        // `--max-age`'s default is text for clap; it must stay the writer's constant.
        assert_eq!(
            parse_max_age("31days"),
            Ok(historian::writer::DEFAULT_MAX_AGE)
        );
    }
}
