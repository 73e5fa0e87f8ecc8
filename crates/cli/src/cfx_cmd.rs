//! `cellbus cfx sub`: the IPC-CFX messages on an AMQP 1.0 address, as a line engineer wants
//! to see them. The AMQP is the gateway's (`gateway::northbound::cfx::listen`), the JSON
//! the `cfx` crate's; this module prints.

use std::net::SocketAddr;
use std::process::ExitCode;

use anyhow::anyhow;
use clap::{Args, Subcommand};
use gateway::northbound::cfx::config::parse_url;
use gateway::northbound::cfx::listen::{self, Taken};
use tokio::sync::mpsc;

use crate::output::usage;

#[derive(Debug, Subcommand)]
pub enum CfxCommand {
    /// Print every CFX message as it arrives: time, source, message name and body (or
    /// the whole envelope as JSON with --json). Either take them from a broker's address
    /// (amqp://HOST:PORT/ADDRESS, as the line's MES does), or be the receiver yourself
    /// with --listen IP:PORT (no broker: point `cellbus serve --cfx amqp://IP:PORT/any`
    /// at it).
    ///
    /// Exit codes: 0 after --count messages, 1 when the broker cannot be reached, the
    /// link ends, or --timeout passes without a message, 2 bad arguments.
    Sub(SubArgs),
}

#[derive(Debug, Args)]
pub struct SubArgs {
    /// The broker and address: amqp://HOST[:PORT]/ADDRESS (port 5672 by default; an
    /// address starting with / after a second slash: amqp://mes//exchange/cfx).
    #[arg(
        value_name = "URL",
        required_unless_present = "listen",
        conflicts_with = "listen"
    )]
    url: Option<String>,
    /// Be the receiver: listen on this address (port 0 picks a free one; the first line
    /// printed is `listening on amqp://IP:PORT`) and print what any sender sends.
    #[arg(long, value_name = "IP:PORT")]
    listen: Option<SocketAddr>,
    /// --json: one object per envelope and line, with the message's subject.
    #[command(flatten)]
    watch: crate::output::Watch,
    /// The SASL PLAIN user name.
    #[arg(long, requires = "url")]
    username: Option<String>,
    /// The environment variable that holds the password (never the password itself).
    #[arg(long, value_name = "VAR", requires = "username")]
    password_env: Option<String>,
}

pub async fn run(command: CfxCommand) -> anyhow::Result<ExitCode> {
    match command {
        CfxCommand::Sub(args) => sub(args).await,
    }
}

async fn sub(args: SubArgs) -> anyhow::Result<ExitCode> {
    let (tx, mut rx) = mpsc::channel::<Taken>(256);
    let source = match (&args.listen, &args.url) {
        (Some(addr), _) => format!("on {addr}"),
        (None, Some(url)) => url.clone(),
        (None, None) => String::new(),
    };
    match (&args.listen, &args.url) {
        (Some(addr), _) => {
            let socket = tokio::net::TcpListener::bind(addr)
                .await
                .map_err(|e| anyhow!("cannot listen on {addr}: {e}"))?;
            let local = socket.local_addr()?;
            println!("listening on amqp://{local}");
            tokio::spawn(listen::receive(socket, tx));
        }
        (None, Some(url)) => {
            let parsed = parse_url(url).map_err(usage)?;
            if parsed.tls {
                return Err(usage(format!(
                    "{url}: cfx sub reads amqp:// only; read the broker's plain listener, or receive the gateway's messages yourself with --listen"
                )));
            }
            let (host, port) = (parsed.host, parsed.port);
            let address = parsed.address.ok_or_else(|| {
                usage(format!(
                    "{url}: no address; write amqp://HOST:PORT/ADDRESS (a queue, or //exchange/NAME)"
                ))
            })?;
            let credentials = match (&args.username, &args.password_env) {
                (Some(user), Some(var)) => Some((
                    user.clone(),
                    std::env::var(var).map_err(|_| {
                        usage(format!(
                            "--password-env {var}: the environment variable {var} is not set (or not UTF-8)"
                        ))
                    })?,
                )),
                (Some(user), None) => Some((user.clone(), String::new())),
                _ => None,
            };
            tokio::spawn(listen::subscribe(
                format!("amqp://{host}:{port}"),
                address,
                credentials,
                tx,
            ));
        }
        (None, None) => return Err(usage("give amqp://HOST:PORT/ADDRESS or --listen IP:PORT")),
    }
    let mut received = 0u64;
    loop {
        let taken = match args.watch.timeout {
            Some(limit) => match tokio::time::timeout(limit, rx.recv()).await {
                Ok(taken) => taken,
                Err(_) => return Err(args.watch.silence(received, &format!("from {source}"))),
            },
            None => rx.recv().await,
        };
        let (subject, bytes) = match taken {
            Some(Ok(taken)) => taken,
            Some(Err(why)) => return Err(anyhow!(why)),
            None => return Err(anyhow!("the receiver stopped")),
        };
        for line in lines(subject.as_deref(), &bytes, args.watch.json) {
            println!("{line}");
        }
        received += 1;
        if args.watch.done(received) {
            return Ok(ExitCode::SUCCESS);
        }
    }
}

/// A message's lines: one per envelope (a batch has several), or why it is not CFX.
fn lines(subject: Option<&str>, bytes: &[u8], json: bool) -> Vec<String> {
    let not_cfx = |why: String| {
        vec![format!(
            "{why} (subject {subject:?}, {} bytes)",
            bytes.len()
        )]
    };
    let value: serde_json::Value = match serde_json::from_slice(bytes) {
        Ok(value) => value,
        Err(e) => return not_cfx(format!("not a CFX envelope: {e}")),
    };
    let items = match value {
        serde_json::Value::Array(items) => items,
        one => vec![one],
    };
    items
        .into_iter()
        .map(|item| {
            let envelope = match serde_json::from_value::<cfx::Received>(item.clone()) {
                Ok(envelope) => envelope,
                Err(e) => return not_cfx(format!("not a CFX envelope: {e}")).remove(0),
            };
            if json {
                return serde_json::json!({"subject": subject, "envelope": item}).to_string();
            }
            let mut body = envelope.message_body;
            if let Some(object) = body.as_object_mut() {
                object.remove("$type");
            }
            format!(
                "{} {} {} {}",
                envelope
                    .time_stamp
                    .map_or_else(|| "-".to_owned(), |t| t.to_string()),
                envelope.source.as_deref().unwrap_or("-"),
                envelope.message_name,
                body
            )
        })
        .collect()
}
