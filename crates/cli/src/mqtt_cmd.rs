//! `cellbus mqtt sub`: what a broker carries, as a plant engineer wants to see it. The
//! decoding into words and JSON is `sparkplug::describe`; this module connects,
//! subscribes and prints.

use std::collections::HashMap;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{Context as _, anyhow};
use clap::{Args, Subcommand};
use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS, SubscribeFilter, SubscribeReasonCode};
use sparkplug::node::rebirth_request;
use sparkplug::{Describer, Description, Id, MessageKind, Timestamp};

use crate::output::{self, usage};

/// Births are large: accept packets up to this size.
const MAX_PACKET: usize = 16 << 20;

#[derive(Debug, Subcommand)]
pub enum MqttCommand {
    /// Subscribe and print every message as it arrives: Sparkplug B payloads decoded into
    /// metrics (data messages' aliases named from the births seen by this run), STATE as
    /// its JSON, anything else as text (hex if it is not UTF-8).
    ///
    /// Births are not retained: started after a node was born, this sees its data by alias
    /// only (`alias 52: double_value 25.0`) until the node's next birth. Start it first, or
    /// give --rebirth to ask each such node for its births (an NCMD Node Control/Rebirth,
    /// which a cellbus gateway answers).
    ///
    /// Exit codes: 0 after --count messages, 1 when the broker cannot be reached or goes
    /// away or --timeout passes without a message, 2 bad arguments.
    Sub(SubArgs),
}

#[derive(Debug, Args)]
pub struct SubArgs {
    /// The broker: mqtt://HOST[:PORT] (port 1883 by default) or mqtts://HOST[:PORT] (TLS,
    /// port 8883 by default).
    #[arg(long, value_name = "URL")]
    broker: String,
    /// For mqtts://: the CA certificates (PEM) that sign the broker's; without it, the
    /// system's roots.
    #[arg(long, value_name = "FILE")]
    ca_file: Option<std::path::PathBuf>,
    /// For mqtts://: a client certificate (PEM) to show a broker that asks for one.
    #[arg(long, value_name = "FILE", requires = "client_key")]
    client_cert: Option<std::path::PathBuf>,
    /// The client certificate's private key (PEM).
    #[arg(long, value_name = "FILE", requires = "client_cert")]
    client_key: Option<std::path::PathBuf>,
    #[command(flatten)]
    watch: crate::output::Watch,
    /// The MQTT user name.
    #[arg(long)]
    username: Option<String>,
    /// The environment variable that holds the password (never the password itself).
    #[arg(long, value_name = "VAR", requires = "username")]
    password_env: Option<String>,
    /// When a node's data names a metric by an alias whose birth this run has not seen, ask
    /// the node for a rebirth (NCMD `Node Control/Rebirth`; at most once a minute per node).
    /// Needs a broker account that may publish NCMD.
    #[arg(long)]
    rebirth: bool,
    /// MQTT topic filters, subscribed with QoS 1.
    #[arg(value_name = "TOPIC", default_value = "spBv1.0/#")]
    topics: Vec<String>,
}

pub async fn run(command: MqttCommand) -> anyhow::Result<ExitCode> {
    match command {
        MqttCommand::Sub(args) => sub(args).await,
    }
}

async fn sub(args: SubArgs) -> anyhow::Result<ExitCode> {
    let kit::mqtt::Broker { host, port, tls } =
        kit::mqtt::parse_broker(&args.broker).map_err(|m| usage(format!("--broker: {m}")))?;
    let scheme = if tls { "mqtts" } else { "mqtt" };
    let broker = format!("{scheme}://{host}:{port}");
    let transport = if tls {
        let files = kit::mqtt::MqttTls {
            ca_file: args.ca_file.clone(),
            client: args
                .client_cert
                .clone()
                .zip(args.client_key.clone())
                .map(|(cert, key)| kit::mqtt::MqttClientCert { cert, key }),
        };
        let config = kit::mqtt::tls::client_config(&files)
            .map_err(|e| usage(format!("--broker {broker}: {e}")))?;
        Some(kit::mqtt::tls::transport(&config))
    } else {
        if args.ca_file.is_some() || args.client_cert.is_some() {
            return Err(usage(format!(
                "--ca-file, --client-cert and --client-key are for mqtts://; the broker is {broker}"
            )));
        }
        None
    };
    for topic in &args.topics {
        if !rumqttc::valid_filter(topic) {
            return Err(usage(format!(
                "{topic:?} is not an MQTT topic filter (`#` only last, `+` and `#` only as whole levels)"
            )));
        }
    }
    let password = match &args.password_env {
        Some(var) => Some(std::env::var(var).map_err(|_| {
            usage(format!(
                "--password-env {var}: the environment variable {var} is not set (or not UTF-8)"
            ))
        })?),
        None => None,
    };
    let mut options = MqttOptions::new(client_id(), host, port);
    options
        .set_clean_session(true)
        .set_keep_alive(Duration::from_secs(30))
        .set_max_packet_size(MAX_PACKET, MAX_PACKET);
    if let Some(transport) = transport {
        options.set_transport(transport);
    }
    if let Some(user) = &args.username {
        options.set_credentials(user, password.unwrap_or_default());
    }
    let (client, mut eventloop) = AsyncClient::new(options, 16);
    let filters: Vec<SubscribeFilter> = args
        .topics
        .iter()
        .map(|t| SubscribeFilter::new(t.clone(), QoS::AtLeastOnce))
        .collect();

    let mut describer = Describer::new();
    let mut unborn = Unborn::default();
    let mut connected = false;
    let mut received = 0u64;
    let mut deadline = args
        .watch
        .timeout
        .map(|limit| tokio::time::Instant::now() + limit);
    loop {
        let event = match (deadline, args.watch.timeout) {
            (Some(deadline), Some(_)) => {
                match tokio::time::timeout_at(deadline, eventloop.poll()).await {
                    Ok(event) => event,
                    Err(_) => {
                        return Err(args.watch.silence(
                            received,
                            &format!("from {broker} on {}", args.topics.join(" ")),
                        ));
                    }
                }
            }
            _ => eventloop.poll().await,
        };
        match event {
            Ok(Event::Incoming(Packet::ConnAck(_))) => {
                connected = true;
                client
                    .subscribe_many(filters.clone())
                    .await
                    .with_context(|| format!("cannot subscribe on {broker}"))?;
            }
            Ok(Event::Incoming(Packet::SubAck(ack))) => {
                if let Some(i) = ack
                    .return_codes
                    .iter()
                    .position(|c| matches!(c, SubscribeReasonCode::Failure))
                {
                    let topic = args.topics.get(i).map_or("?", String::as_str);
                    return Err(anyhow!(
                        "broker {broker} refused the subscription to {topic}"
                    ));
                }
                // On stderr: stdout is for the messages only.
                eprintln!(
                    "cellbus: subscribed to {} on {broker}",
                    args.topics.join(" ")
                );
            }
            Ok(Event::Incoming(Packet::Publish(p))) => {
                let description = describer.describe(&p.topic, &p.payload);
                if let Some(node) = unborn_node(&description) {
                    unborn.meet(node, args.rebirth, &client).await;
                }
                if args.watch.json {
                    output::line(description.to_json())?;
                } else {
                    output::line(description.to_text())?;
                }
                received += 1;
                deadline = args
                    .watch
                    .timeout
                    .map(|limit| tokio::time::Instant::now() + limit);
                if args.watch.done(received) {
                    // Acknowledge what came (QoS 1) and leave politely, within a bound.
                    let _ = client.try_disconnect();
                    let _ = tokio::time::timeout(Duration::from_secs(1), async {
                        while eventloop.poll().await.is_ok() {}
                    })
                    .await;
                    return Ok(ExitCode::SUCCESS);
                }
            }
            Ok(_) => {}
            Err(e) if connected => {
                return Err(anyhow!("lost the connection to broker {broker}: {e}"));
            }
            Err(e) => return Err(anyhow!("cannot connect to broker {broker}: {e}")),
        }
    }
}

/// The node (group, edge node) of a data message that names a metric by an alias whose
/// birth was not seen.
fn unborn_node(description: &Description) -> Option<(String, String)> {
    let Description::Sparkplug(message) = description else {
        return None;
    };
    let by_alias_only = message
        .metrics
        .iter()
        .any(|m| m.name.is_none() && m.alias.is_some());
    (message.kind == MessageKind::Data && by_alias_only)
        .then(|| (message.group.clone(), message.edge_node.clone()))
}

/// The nodes met with unborn aliases: told once each, or asked for a rebirth at most once
/// a minute each.
#[derive(Debug, Default)]
struct Unborn {
    met: HashMap<(String, String), tokio::time::Instant>,
}

/// How often one node is asked for a rebirth at the most.
const REBIRTH_EVERY: Duration = Duration::from_secs(60);

impl Unborn {
    async fn meet(&mut self, (group, node): (String, String), rebirth: bool, client: &AsyncClient) {
        let now = tokio::time::Instant::now();
        let key = (group.clone(), node.clone());
        match self.met.get(&key) {
            Some(_) if !rebirth => return,
            Some(at) if now.duration_since(*at) < REBIRTH_EVERY => return,
            _ => {}
        }
        self.met.insert(key, now);
        if !rebirth {
            eprintln!(
                "cellbus: node {group}/{node} names metrics by alias and its birth was not seen \
                 (births are not retained): start `cellbus mqtt sub` before the node, or add \
                 --rebirth to ask it for one"
            );
            return;
        }
        let (Ok(group_id), Ok(node_id)) = (Id::new(&group), Id::new(&node)) else {
            return;
        };
        let millis = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_millis()).unwrap_or(u64::MAX));
        let request = rebirth_request(&group_id, &node_id, Timestamp::from_millis(millis));
        match client
            .publish(
                request.topic.to_string(),
                QoS::AtMostOnce,
                false,
                request.payload,
            )
            .await
        {
            Ok(()) => eprintln!(
                "cellbus: node {group}/{node}'s birth was not seen: asked it for a rebirth ({})",
                request.topic
            ),
            Err(e) => eprintln!("cellbus: cannot ask node {group}/{node} for a rebirth: {e}"),
        }
    }
}

/// A client id no other client of the broker has: the broker would drop the older one.
fn client_id() -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    format!("cellbus-sub-{}-{nanos:x}", std::process::id())
}
