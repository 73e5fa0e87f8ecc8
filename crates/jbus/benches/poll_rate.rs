//! Poll cycles per second reading a Chloride CROSS over a simulated 9600-baud line, in real
//! time: our client against the theoretical limit of the line and against pymodbus.
//!
//! One poll cycle is what `jbus::cross::read` does: one function-3 read per area of
//! `cross::read_plan` (four reads). The twin runs in-process behind `link`'s serve loop on
//! loopback TCP, paced at the CROSS's 9600 8N1 (requests heard when their last character
//! arrives, answers leaving at the line's character rate): exactly what
//! `cellbus sim cross --listen 127.0.0.1:0 --baud 9600` serves.
//!
//! - **ours**: `jbus::cross::read` over `tcp://127.0.0.1:PORT?baud=9600`, so the client
//!   keeps the 3.5-character silence before every request, as on the wire.
//! - **theory**: computed from the frames' lengths and printed with its arithmetic.
//! - **pymodbus**: `benches/poll_rate_pymodbus.py`, pymodbus's synchronous client with the
//!   RTU framer over TCP, the same reads against the same listener. Skipped with a message
//!   when python3 or pymodbus is missing (`scripts/test` installs pymodbus 3.16.1).
//!
//! Rates are steady-state: cycles counted between the end of the first and the end of the
//! last cycle. `cargo bench -p jbus --bench poll_rate` (about 25 s; `POLL_SECONDS=N` per
//! side, default 8). Under `cargo test` (no `--bench` flag) each side runs for 1 s: a smoke
//! run.

use std::process::Command;
use std::time::Duration;

use jbus::client::{Client, ClientConfig, expected_answer_len};
use jbus::cross::device::{CrossTwin, REPLY_DELAY};
use jbus::cross::{read_plan, read_requests};
use jbus::rtu::{Addressed, LineTiming, Request, UnitId};
use link::serve::serve_tcp;
use link::{Endpoint, Line, SerialSettings, SharedLine};
use tokio::time::Instant;
use wire::device::{FaultInjector, SharedModel};

/// The CROSS's line: 9600 baud, 8 data bits, no parity, 1 stop bit (the manual's setting).
const LINE: SerialSettings = SerialSettings::new_8n1(9600);
/// The unit the twin answers to (the manual's example, `cellbus sim cross`'s default).
const UNIT: u8 = 2;
/// The simulator's seed (`cellbus sim cross --seed`'s default).
const SEED: u64 = 1;

fn main() {
    let seconds = testkit::bench_seconds("POLL_SECONDS", 8);
    let unit = UnitId::jbus(UNIT).expect("2 is a unit number");
    let plan = read_requests();

    println!(
        "CROSS poll cycles on a simulated 9600 8N1 line ({seconds} s per client, real time)\n"
    );
    let theory = Theory::new(&plan);
    theory.print(&plan);

    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("a tokio runtime");
    // The simulator, as `cellbus sim cross --listen 127.0.0.1:0 --baud 9600` serves it.
    let port = runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
            .await
            .expect("a loopback port");
        let port = listener.local_addr().expect("bound").port();
        let twin = SharedModel::new(CrossTwin::new(unit, SEED));
        let make = move || FaultInjector::new(twin.line(), SEED, 0.0).expect("0 is a fault rate");
        tokio::spawn(serve_tcp(listener, make, Some(LINE)));
        port
    });

    println!(
        "\n{:<36} {:>7} {:>9} {:>9} {:>9}",
        "client", "cycles", "cycle ms", "cycles/s", "of theory"
    );
    let row = |name: &str, cycles: &str, cycle: Duration| {
        let rate = 1.0 / cycle.as_secs_f64();
        println!(
            "{name:<36} {cycles:>7} {:>9.2} {rate:>9.3} {:>8.1}%",
            cycle.as_secs_f64() * 1000.0,
            100.0 * rate / theory.twin_rate()
        );
        rate
    };
    let measured = |name: &str, cycles: usize, span: Duration| {
        if cycles < 2 || span.is_zero() {
            println!("{name:<36} {cycles:>7}  (too few cycles to time)");
            return None;
        }
        Some(row(name, &cycles.to_string(), span / (cycles - 1) as u32))
    };
    row("theory: this twin, silences kept", "-", theory.twin_cycle());
    row("theory: no master silences", "-", theory.unsilenced_cycle());

    // Ours, told the line's speed (it keeps the 3.5-character silence before each request),
    // and ours on a bare TCP URL (no speed, no silence: what pymodbus does over TCP).
    let mut ours = Vec::new();
    for (name, url) in [
        (
            "ours, tcp://…?baud=9600",
            format!("tcp://127.0.0.1:{port}?baud=9600"),
        ),
        (
            "ours, tcp://… (no silences)",
            format!("tcp://127.0.0.1:{port}"),
        ),
    ] {
        let ends = runtime.block_on(poll_with_ours(&url, unit, Duration::from_secs(seconds)));
        let span = match (ends.first(), ends.last()) {
            (Some(first), Some(last)) => *last - *first,
            _ => Duration::ZERO,
        };
        ours.push(measured(name, ends.len(), span));
    }

    // The simulator keeps running on the runtime's workers while pymodbus polls it.
    let theirs = match poll_with_pymodbus(port, unit, seconds) {
        Ok(Pymodbus {
            version,
            cycles,
            span,
            errors,
        }) => {
            let rate = measured(
                &format!("pymodbus {version} (sync, RTU framer)"),
                cycles,
                span,
            );
            if errors > 0 {
                println!(
                    "  pymodbus: {errors} cycle(s) with an error or a timeout were not counted"
                );
            }
            rate
        }
        Err(why) => {
            println!("pymodbus comparison skipped: {why}");
            None
        }
    };

    println!();
    if let Some(Some(silenced)) = ours.first() {
        println!(
            "ours (silences kept) / theory of this twin: {:.3}; / line limit: {:.3}",
            silenced / theory.twin_rate(),
            silenced * theory.line_cycle().as_secs_f64()
        );
    }
    if let Some(Some(bare)) = ours.get(1) {
        println!(
            "ours (no silences) / theory without master silences: {:.3}",
            bare * theory.unsilenced_cycle().as_secs_f64()
        );
        if let Some(theirs) = theirs {
            println!(
                "ours (no silences) / pymodbus (no silences): {:.3}",
                bare / theirs
            );
        }
    }
    if let (Some(Some(silenced)), Some(theirs)) = (ours.first(), theirs) {
        println!("ours (silences kept) / pymodbus: {:.3}", silenced / theirs);
    }
    runtime.shutdown_timeout(Duration::from_secs(1));
}

/// The fastest a poll cycle can go on the line, from the frames' lengths.
struct Theory {
    timing: LineTiming,
    /// Characters of the requests and the answers of one cycle.
    request_chars: usize,
    answer_chars: usize,
    exchanges: usize,
}

impl Theory {
    fn new(plan: &[Request]) -> Self {
        let unit = UnitId::jbus(UNIT).expect("2 is a unit number");
        Self {
            timing: LineTiming::new(LINE.baud, LINE.bits_per_char()).expect("9600 8N1 is a line"),
            request_chars: plan
                .iter()
                .map(|r| Addressed::new(unit, r.clone()).to_adu().to_bytes().len())
                .sum(),
            answer_chars: plan.iter().map(expected_answer_len).sum(),
            exchanges: plan.len(),
        }
    }

    /// Frames plus a 3.5-character silence before each of them (the master's before every
    /// request, the slave's before every answer).
    fn line_cycle(&self) -> Duration {
        self.timing
            .transmit_time(self.request_chars + self.answer_chars)
            + self.timing.inter_frame_silence() * (2 * self.exchanges) as u32
    }

    /// Frames, the master's silence before each request and the twin's reply delay before
    /// each answer (the delay is longer than the slave's 3.5-character silence).
    fn twin_cycle(&self) -> Duration {
        self.timing
            .transmit_time(self.request_chars + self.answer_chars)
            + self.timing.inter_frame_silence() * self.exchanges as u32
            + REPLY_DELAY.max(self.timing.inter_frame_silence()) * self.exchanges as u32
    }

    /// Frames and the twin's reply delay only: a client that sends its next request the
    /// moment an answer ends (pymodbus over TCP; ours on a URL without the line's speed).
    fn unsilenced_cycle(&self) -> Duration {
        self.timing
            .transmit_time(self.request_chars + self.answer_chars)
            + REPLY_DELAY.max(self.timing.inter_frame_silence()) * self.exchanges as u32
    }

    fn line_rate(&self) -> f64 {
        1.0 / self.line_cycle().as_secs_f64()
    }

    fn twin_rate(&self) -> f64 {
        1.0 / self.twin_cycle().as_secs_f64()
    }

    fn print(&self, plan: &[Request]) {
        let ms = |d: Duration| d.as_secs_f64() * 1000.0;
        let silence = self.timing.inter_frame_silence();
        let n = self.exchanges;
        let unit = UnitId::jbus(UNIT).expect("2 is a unit number");
        println!(
            "line: {} baud, 8N1 (the CROSS's setting) = {} bits per character: {:.4} ms per \
             character; 3.5-character silence = {:.4} ms",
            self.timing.baud(),
            self.timing.bits_per_char(),
            ms(self.timing.char_time()),
            ms(silence)
        );
        println!("one cycle = cross::read = {n} function-3 reads (the read plan):");
        for request in plan {
            let asked = Addressed::new(unit, request.clone())
                .to_adu()
                .to_bytes()
                .len();
            let answer = expected_answer_len(request);
            println!("  {request}: request {asked} + answer {answer} characters");
        }
        let frames = self.request_chars + self.answer_chars;
        let wire = self.timing.transmit_time(frames);
        println!(
            "frames: {} + {} = {frames} characters = {:.3} ms",
            self.request_chars,
            self.answer_chars,
            ms(wire)
        );
        println!(
            "line limit (a silence of 3.5 characters before each of the {} frames): \
             {frames} + {} x 3.5 = {} characters = {:.3} ms -> {:.3} cycles/s",
            2 * n,
            2 * n,
            frames as f64 + 7.0 * n as f64,
            ms(self.line_cycle()),
            self.line_rate()
        );
        let delay = REPLY_DELAY.max(silence);
        println!(
            "this twin answers {:.0} ms after a request's last character (REPLY_DELAY, which \
             covers the slave's silence):",
            ms(REPLY_DELAY)
        );
        println!(
            "  silences kept: {:.3} + {n} x {:.3} + {n} x {:.3} = {:.3} ms -> {:.3} cycles/s",
            ms(wire),
            ms(silence),
            ms(delay),
            ms(self.twin_cycle()),
            self.twin_rate()
        );
        println!(
            "  no master silences: {:.3} + {n} x {:.3} = {:.3} ms -> {:.3} cycles/s",
            ms(wire),
            ms(delay),
            ms(self.unsilenced_cycle()),
            1.0 / self.unsilenced_cycle().as_secs_f64()
        );
        println!(
            "(the simulator's timers, like every tokio timer, fire on 1 ms ticks: each of its \
             waits — request heard, reply delay, reply sent — ends up to 1 ms late)"
        );
    }
}

/// Polls with our client for `duration`; returns when each cycle ended.
async fn poll_with_ours(url: &str, unit: UnitId, duration: Duration) -> Vec<Instant> {
    let endpoint = Endpoint::parse(url, LINE).expect("a valid URL");
    let line = Line::open(&endpoint).await.expect("the simulator listens");
    let mut client = Client::new(SharedLine::new(line), ClientConfig::default());
    let until = Instant::now() + duration;
    let mut ends = Vec::new();
    while Instant::now() < until {
        match jbus::cross::read(&mut client, unit).await {
            Ok(_) => ends.push(Instant::now()),
            Err(e) => println!("  ours: a cycle failed: {e}"),
        }
    }
    ends
}

struct Pymodbus {
    version: String,
    cycles: usize,
    span: Duration,
    errors: usize,
}

/// Runs `benches/poll_rate_pymodbus.py` against the simulator; `Err` says why it could not.
fn poll_with_pymodbus(port: u16, unit: UnitId, seconds: u64) -> Result<Pymodbus, String> {
    let hint = "python3 -m pip install pymodbus==3.16.1 (scripts/test does)";
    let probe = Command::new("python3")
        .args(["-c", "import pymodbus"])
        .output()
        .map_err(|e| format!("python3 cannot run ({e}); {hint}"))?;
    if !probe.status.success() {
        return Err(format!("pymodbus is not installed for python3; {hint}"));
    }
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/benches/poll_rate_pymodbus.py");
    // The same reads as `cross::read`: the plan's blocks, as ADDRESS:COUNT.
    let blocks = read_plan()
        .into_iter()
        .map(|(address, count)| format!("{address}:{count}"));
    let out = Command::new("python3")
        .arg(script)
        .args([
            port.to_string(),
            unit.get().to_string(),
            seconds.to_string(),
        ])
        .args(blocks)
        .output()
        .map_err(|e| format!("python3 cannot run {script}: {e}"))?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    if !out.status.success() {
        return Err(format!(
            "{script} failed: {}{}",
            stdout.trim(),
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    // "pymodbus 3.16.1 cycles N seconds S errors E"
    let words: Vec<&str> = stdout.split_whitespace().collect();
    let field = |name: &str| {
        words
            .iter()
            .position(|w| *w == name)
            .and_then(|i| words.get(i + 1))
            .copied()
            .ok_or_else(|| format!("{script} printed no {name}: {stdout}"))
    };
    let number = |name: &str| {
        field(name)?
            .parse::<f64>()
            .map_err(|e| format!("{script} printed a bad {name}: {e}"))
    };
    Ok(Pymodbus {
        version: field("pymodbus")?.to_owned(),
        cycles: number("cycles")? as usize,
        span: Duration::from_secs_f64(number("seconds")?),
        errors: number("errors")? as usize,
    })
}
