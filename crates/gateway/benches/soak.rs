//! The noise soak bench: the real gateway polls every serial device kind (JBC, Thermosald,
//! CROSS, generic Modbus) over loopback TCP through seeded noisy lines, then through a total
//! outage, and prints what a user would ask of it: requests and damaged frames, wrong
//! values taken as good (must be 0), polls answered, the longest a device stayed down while
//! its line was merely noisy, and the recovery time after the outage.
//!
//! ```text
//! nice cargo bench -p gateway --bench soak -- --requests 1000000 --groups 8
//! ```
//!
//! The soak itself is `tests/soak/rig.rs`, which the short soak test runs too.

#[path = "../tests/soak/rig.rs"]
mod rig;

use std::process::ExitCode;
use std::time::Duration;

use rig::{SoakOptions, Transport};
use testkit::NoiseConfig;

const USAGE: &str = "\
usage: cargo bench -p gateway --bench soak -- [options]

  --requests N      requests to send over the noisy lines (default 100000)
  --groups G        copies of the cell's lines: a JBC line, a line of 3 Thermosald
                    regulators, a CROSS + Modbus server line (default 4)
  --noise F         the field report's noise times F (default 1: a flipped bit in 0.2 %
                    of the bytes, a byte lost or inserted in 0.03 %, rarer duplicates,
                    lost frames and bursts)
  --seed S          seed of the noise and the twins (default 1)
  --period D        every device's poll period (default 50ms)
  --timeout D       JBC and Modbus reply timeout (default 200ms)
  --outage D        the total outage after the noise (default 10s)
  --memory          in-memory lines instead of loopback TCP

A million requests:
  nice cargo bench -p gateway --bench soak -- --requests 1000000 --groups 8
";

fn main() -> ExitCode {
    let raw: Vec<String> = std::env::args().skip(1).collect();
    // `cargo bench` passes --bench; `cargo test --benches` does not: then a smoke run.
    let benching = raw.iter().any(|a| a == "--bench");
    let rest: Vec<String> = raw.into_iter().filter(|a| a != "--bench").collect();
    if rest.iter().any(|a| a == "--help" || a == "-h") {
        print!("{USAGE}");
        return ExitCode::SUCCESS;
    }
    let mut options = match parse(&rest) {
        Ok(options) => options,
        Err(message) => {
            eprintln!("soak: {message}\n\n{USAGE}");
            return ExitCode::from(2);
        }
    };
    if !benching && rest.is_empty() {
        options.requests = 500;
        options.groups = 1;
        options.calm = Duration::from_secs(2);
        options.outage = Duration::from_secs(2);
        println!("soak: smoke run (cargo bench -p gateway --bench soak for the benchmark)");
    }
    let runtime = match tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
    {
        Ok(runtime) => runtime,
        Err(e) => {
            eprintln!("soak: cannot start the runtime: {e}");
            return ExitCode::from(1);
        }
    };
    println!(
        "soak: {} requests over {} groups of lines ({:?}), noise {:?}, seed {}",
        options.requests, options.groups, options.transport, options.noise, options.seed
    );
    match runtime.block_on(rig::run(options)) {
        Ok(report) => {
            for line in report.lines() {
                println!("{line}");
            }
            if report.wrong_total() > 0 {
                eprintln!("soak: wrong values were taken as good");
                return ExitCode::from(1);
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("soak: {e}");
            ExitCode::from(1)
        }
    }
}

fn parse(raw: &[String]) -> Result<SoakOptions, String> {
    let mut options = SoakOptions {
        requests: 100_000,
        groups: 4,
        transport: Transport::Tcp,
        ..SoakOptions::default()
    };
    let mut it = raw.iter();
    while let Some(flag) = it.next() {
        if flag == "--memory" {
            options.transport = Transport::Memory;
            continue;
        }
        let value = it
            .next()
            .ok_or_else(|| format!("{flag} needs a value"))?
            .as_str();
        let number = |what: &str| -> Result<u64, String> {
            value
                .replace('_', "")
                .parse()
                .map_err(|_| format!("{flag} takes {what}, not {value:?}"))
        };
        let duration = || {
            humantime::parse_duration(value)
                .map_err(|e| format!("{flag} takes a duration like 50ms: {e}"))
        };
        match flag.as_str() {
            "--requests" => options.requests = number("a count")?,
            "--groups" => {
                options.groups = usize::try_from(number("a count")?)
                    .ok()
                    .filter(|g| (1..=100).contains(g))
                    .ok_or_else(|| format!("{flag} takes 1 to 100"))?;
            }
            "--seed" => options.seed = number("a number")?,
            "--noise" => {
                let factor: f64 = value
                    .parse()
                    .ok()
                    .filter(|f: &f64| f.is_finite() && *f >= 0.0)
                    .ok_or_else(|| format!("{flag} takes a factor like 1 or 2.5"))?;
                options.noise = NoiseConfig::FIELD.scaled(factor);
            }
            "--period" => options.period = duration()?,
            "--timeout" => options.timeout = duration()?,
            "--outage" => options.outage = duration()?,
            _ => return Err(format!("unknown option {flag}")),
        }
    }
    Ok(options)
}
