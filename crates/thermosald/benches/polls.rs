//! Polls per second on a simulated 9600-baud line, in real time, against the theoretical
//! limit of the protocol's timing (question + 200 ms + answer + 40 ms release).
//!
//! The twin runs in-process behind `link`'s serve loop paced at 9600 8N1 (requests heard
//! when their last character arrives, answers leaving at the line's character rate), over an
//! in-memory duplex and over loopback TCP (the path `cellbus sim thermosald --baud 9600`
//! serves). The client is the real one: it waits out every window the regulators need.
//!
//! The rate is steady-state: answers counted between the first and the last answer seen
//! (each poll's 40 ms release included, none cut off at the ends).
//!
//! `cargo bench -p thermosald --bench polls` (about 30 s; `POLLS_SECONDS=N` per case,
//! default 5). Under `cargo test` (no `--bench` flag) each case runs for 1 s: a smoke run.

use std::time::Duration;

use link::serve::{serve_stream, serve_tcp};
use link::{Line, SerialSettings, SharedLine};
use thermosald::client::{Client, ClientConfig};
use thermosald::device::RegulatorBus;
use thermosald::exchange::LineTiming;
use thermosald::frame::Address;
use thermosald::tables::{Table, runtime};
use tokio::time::Instant;
use wire::device::SharedModel;

const LINE: SerialSettings = SerialSettings::new_8n1(9600);

#[derive(Clone, Copy)]
enum Poll {
    /// One run-time item (the temperature): 9-byte question, 12-byte answer.
    Item,
    /// The whole run-time table: 9-byte question, 30-byte answer.
    Table,
}

impl Poll {
    fn reply_len(self) -> usize {
        match self {
            Poll::Item => 12,
            Poll::Table => 30,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Poll::Item => "one item",
            Poll::Table => "run-time table",
        }
    }
}

#[derive(Clone, Copy)]
enum Transport {
    Duplex,
    Tcp,
}

fn main() {
    let seconds = testkit::bench_seconds("POLLS_SECONDS", 5);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("a tokio runtime");
    println!("Thermosald polls on a simulated 9600 8N1 line, {seconds} s per case (real time)\n");
    let timing = LineTiming::RS485_9600_8N1;
    let char_ms = timing.char_time().as_secs_f64() * 1000.0;
    for poll in [Poll::Item, Poll::Table] {
        let cycle = timing.poll_cycle(9, poll.reply_len()).as_secs_f64() * 1000.0;
        println!(
            "limit, {}: 9 chars x {char_ms:.4} ms + 200 ms + {} chars x {char_ms:.4} ms + 40 ms \
             = {cycle:.3} ms per poll = {:.3} polls/s",
            poll.name(),
            poll.reply_len(),
            1000.0 / cycle
        );
    }
    println!();
    println!(
        "{:<40} {:>6} {:>9} {:>9} {:>9} {:>9}",
        "case", "polls", "cycle ms", "polls/s", "limit", "of limit"
    );
    let cases = [
        (1, Poll::Item, Transport::Duplex),
        (1, Poll::Table, Transport::Duplex),
        (3, Poll::Item, Transport::Duplex),
        (3, Poll::Table, Transport::Duplex),
        (1, Poll::Table, Transport::Tcp),
        (3, Poll::Table, Transport::Tcp),
    ];
    for (regulators, poll, transport) in cases {
        let answers = runtime.block_on(measure(
            regulators,
            poll,
            transport,
            Duration::from_secs(seconds),
        ));
        let (Some(first), Some(last)) = (answers.first(), answers.last()) else {
            println!("{regulators} regulator(s), {}: no answers", poll.name());
            continue;
        };
        let cycles = (answers.len() - 1) as f64;
        let cycle = (*last - *first).as_secs_f64() / cycles;
        let rate = 1.0 / cycle;
        let limit = LineTiming::RS485_9600_8N1.polls_per_second(9, poll.reply_len());
        let via = match transport {
            Transport::Duplex => "duplex",
            Transport::Tcp => "TCP",
        };
        println!(
            "{:<40} {:>6} {:>9.1} {rate:>9.3} {limit:>9.3} {:>8.1}%",
            format!("{regulators} regulator(s), {}, {via}", poll.name()),
            answers.len(),
            cycle * 1000.0,
            100.0 * rate / limit
        );
    }
}

/// Polls `regulators` regulators on one line, each client in its own task, for `duration`;
/// returns when each answer arrived, in order.
async fn measure(
    regulators: u8,
    poll: Poll,
    transport: Transport,
    duration: Duration,
) -> Vec<Instant> {
    let addresses: Vec<Address> = (0..regulators)
        .map(|a| Address::new(a).expect("0-2 are addresses"))
        .collect();
    let twin = RegulatorBus::new(&addresses, std::time::Instant::now())
        .expect("distinct addresses")
        .paced(LineTiming::RS485_9600_8N1);
    let model = SharedModel::new(twin);
    let line = match transport {
        Transport::Duplex => {
            let (ours, theirs) = tokio::io::duplex(4096);
            tokio::spawn(serve_stream(theirs, model.line(), Some(LINE)));
            Line::from_stream(ours, "duplex", Some(LINE))
        }
        Transport::Tcp => {
            let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
                .await
                .expect("a loopback port");
            let port = listener.local_addr().expect("bound").port();
            tokio::spawn(serve_tcp(listener, move || model.line(), Some(LINE)));
            let url = format!("tcp://127.0.0.1:{port}?baud=9600");
            let endpoint = link::Endpoint::parse(&url, LINE).expect("a valid URL");
            Line::open(&endpoint).await.expect("the simulator listens")
        }
    };
    let line = SharedLine::new(line);
    let until = Instant::now() + duration;
    let tasks: Vec<_> = addresses
        .iter()
        .map(|&address| {
            let mut client = Client::new(line.clone(), ClientConfig::new(address));
            tokio::spawn(async move {
                let temperature = Table::Runtime
                    .item(runtime::TEMPERATURE)
                    .expect("item 1 exists");
                let mut answers = Vec::new();
                while Instant::now() < until {
                    let answered = match poll {
                        Poll::Item => client.read_item(temperature).await.map(drop),
                        Poll::Table => client.read_table(Table::Runtime).await.map(drop),
                    };
                    match answered {
                        Ok(()) => answers.push(Instant::now()),
                        Err(e) => eprintln!("poll failed: {e}"),
                    }
                }
                answers
            })
        })
        .collect();
    let mut answers = Vec::new();
    for task in tasks {
        answers.extend(task.await.expect("the poll task ends"));
    }
    answers.sort();
    answers
}
