//! IPC-CFX catch-up benchmark: how fast the gateway sends the messages its outbox kept
//! through an outage (10,000 by default) once the receiver is back, each waiting for the
//! receiver's verdict as in normal running; and what that means for a 2-minute outage.
//!
//! ```text
//! cargo bench -p gateway --bench cfx_backlog                    # 10,000 kept messages
//! cargo bench -p gateway --bench cfx_backlog -- --messages 50000
//! ```
//!
//! # How it runs
//!
//! The gateway's outbox (`store::Outbox`, channel `cfx`) in a temporary data directory is
//! filled with `--messages` `WorkCompleted` envelopes of one handle, as a placement machine
//! would have made them during an outage. Then an AMQP 1.0 receiver (cellbus's own, the
//! one `cellbus cfx sub --listen` runs, in this process) listens on a free loopback port,
//! and the demo gateway starts with `--cfx` to it, as `cellbus serve` runs it. Measured:
//! from the gateway's start to the arrival of the last kept message; messages per second;
//! the CPU time of this process (gateway and receiver, with the demo cell polling).
//!
//! Under `cargo test --benches` (no `--bench` flag) it runs a smoke test of 200 messages.

use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use gateway::northbound::cfx::{CfxFlags, NAME, listen};
use gateway::options::Flags;
use gateway::store::Outbox;
use gateway::{Gateway, ServeOptions};

const DEFAULT_MESSAGES: u64 = 10_000;
/// The longest the catch-up may stall (no new message) before the bench fails.
const STALL_LIMIT: Duration = Duration::from_secs(60);

/// What a line of 20 placement machines makes in 2 minutes: each finishes a board about
/// every 20 s (WorkStarted and WorkCompleted), changes state about twice a minute, and
/// has a fault and its clearing about once a minute.
const TWO_MINUTES_OF_A_LINE: u64 = 20 * 2 * (6 + 2 + 2);

fn main() -> ExitCode {
    let raw: Vec<String> = std::env::args().skip(1).collect();
    let benching = raw.iter().any(|a| a == "--bench");
    let messages = match raw.iter().position(|a| a == "--messages") {
        Some(i) => match raw.get(i + 1).and_then(|n| n.parse().ok()) {
            Some(n) if n > 0 => n,
            _ => {
                eprintln!("cfx_backlog: --messages wants a whole number above 0");
                return ExitCode::from(2);
            }
        },
        None if benching => DEFAULT_MESSAGES,
        None => {
            println!(
                "cfx_backlog: smoke run (cargo bench -p gateway --bench cfx_backlog for the benchmark)"
            );
            200
        }
    };
    let runtime = tokio::runtime::Runtime::new().expect("a tokio runtime");
    match runtime.block_on(run(messages)) {
        Ok(report) => {
            print!("{report}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("cfx_backlog: {e:#}");
            ExitCode::from(1)
        }
    }
}

async fn run(messages: u64) -> anyhow::Result<String> {
    let dir = tempfile::tempdir()?;
    let data = dir.path().join("data");
    std::fs::create_dir_all(&data)?;
    let handle = cfx::Handle::new("Bench.BM221.placer1")?;
    let zone = jiff::tz::TimeZone::UTC;
    let mut outbox = Outbox::open(&data, NAME)?;
    let bodies: Vec<Vec<u8>> = (0..messages)
        .map(|i| {
            let at = jiff::Timestamp::from_millisecond(1_795_000_000_000 + i as i64 * 100)
                .expect("a time");
            let message = cfx::Message::WorkCompleted(cfx::messages::WorkCompleted::board(
                uuid::Uuid::from_u128(u128::from(i)),
            ));
            cfx::Envelope::new(handle.clone(), cfx::Time::new(at, &zone), message).to_bytes()
        })
        .collect();
    for chunk in bodies.chunks(10_000) {
        outbox.keep(chunk, None, u64::MAX)?;
    }
    drop(outbox);

    let socket = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
    let port = socket.local_addr()?.port();
    let (tx, mut received) = tokio::sync::mpsc::channel(10_000);
    tokio::spawn(listen::receive(socket, tx));

    let cpu = testkit::process_cpu();
    let started = Instant::now();
    let gateway = Gateway::start(ServeOptions {
        listen: "127.0.0.1:0".parse()?,
        data_dir: data,
        flags: Flags::default().with(CfxFlags {
            url: Some(format!("amqp://127.0.0.1:{port}/cfx")),
            listen: None,
        }),
        ..ServeOptions::default()
    })
    .await?;
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let running = tokio::spawn(gateway.run(async {
        let _ = stopped.await;
    }));
    let mut kept_arrived = 0;
    while kept_arrived < messages {
        let Ok(taken) = tokio::time::timeout(STALL_LIMIT, received.recv()).await else {
            bail!("{kept_arrived} of {messages} arrived, then nothing for {STALL_LIMIT:?}");
        };
        let (_, body) = taken
            .context("the receiver stopped")?
            .map_err(|e| anyhow::anyhow!("the receiver: {e}"))?;
        for envelope in cfx::Received::decode(&body)? {
            if envelope.source.as_deref() == Some(handle.as_str()) {
                kept_arrived += 1;
            }
        }
    }
    let took = started.elapsed();
    let cpu = testkit::process_cpu() - cpu;
    let _ = stop.send(());
    running.await??;
    let rate = messages as f64 / took.as_secs_f64();
    Ok(format!(
        "cfx_backlog: {messages} kept messages sent to a loopback AMQP 1.0 receiver in {:.2} s \
         (gateway start included): {rate:.0} messages/s, one verdict awaited each; CPU {:.2} s \
         ({:.0} µs a message)\n\
         cfx_backlog: a 2-minute outage of a line of 20 placement machines (about \
         {TWO_MINUTES_OF_A_LINE} messages) is caught up in about {:.2} s\n",
        took.as_secs_f64(),
        cpu.as_secs_f64(),
        cpu.as_secs_f64() * 1e6 / messages as f64,
        TWO_MINUTES_OF_A_LINE as f64 / rate,
    ))
}
