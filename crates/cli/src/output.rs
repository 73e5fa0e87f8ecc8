//! Exit codes and printing shared by the subcommands.

use std::io::Write;
use std::process::ExitCode;
use std::time::Duration;

use wire::{Failure, FailureKind};

/// A mistake in what the user asked (exit code 2), as opposed to a device or line failure
/// (exit code 1).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct UsageError(pub String);

/// Makes a usage error (exit code 2) from anything printable.
pub fn usage(message: impl std::fmt::Display) -> anyhow::Error {
    UsageError(message.to_string()).into()
}

/// `--json` of the device commands (jbc, modbus, cross, thermosald, panasonic): global,
/// so it goes before or after the subcommand like their other options.
#[derive(Debug, Clone, Copy, clap::Args)]
pub struct JsonArg {
    /// Print JSON instead of text: one object per answer, one per line for a watch.
    #[arg(long, global = true)]
    pub json: bool,
}

/// The `--endpoint` a device command needs. Clap cannot require an option that may come
/// after the subcommand, so a missing one is refused here (exit 2); `examples` lists what
/// this command's devices take.
pub fn endpoint(
    given: Option<&str>,
    defaults: link::SerialSettings,
    examples: &str,
) -> anyhow::Result<link::Endpoint> {
    let Some(text) = given else {
        return Err(usage(format!("--endpoint URL is needed: {examples}")));
    };
    link::Endpoint::parse(text, defaults).map_err(usage)
}

/// The shortest and longest `--timeout` of the clients.
const TIMEOUTS: (Duration, Duration) = (Duration::from_millis(1), Duration::from_secs(3600));

/// A client's `--timeout`: from 1 ms to 1 h. `0s` would report every device as silent
/// (a scan would find nobody), and an hour is more than any device here needs.
pub fn parse_timeout(text: &str) -> Result<Duration, String> {
    let timeout = humantime::parse_duration(text).map_err(|e| format!("{e}; e.g. 500ms"))?;
    if !(TIMEOUTS.0..=TIMEOUTS.1).contains(&timeout) {
        return Err(format!("{text} is not a timeout from 1ms to 1h"));
    }
    Ok(timeout)
}

/// The `--endpoint` of a device that does not speak Modbus (`what`: "a JBC station"):
/// serial or raw TCP; a `modbus-tcp://` one is refused.
pub fn serial_endpoint(
    given: Option<&str>,
    defaults: link::SerialSettings,
    what: &str,
) -> anyhow::Result<link::Endpoint> {
    let endpoint = endpoint(
        given,
        defaults,
        "serial:///dev/ttyUSB0, a device path, or tcp://host:port",
    )?;
    if endpoint.is_mbap() {
        return Err(usage(format!(
            "{endpoint}: modbus-tcp:// is for Modbus devices; {what} is reached over serial:// or tcp://"
        )));
    }
    Ok(endpoint)
}

/// A client's error as the command's error, classified by its [`Failure::kind`]: our own
/// bad request is a usage error (exit 2), anything the device or its line did exits 1.
pub fn failure<E: Failure + Send + Sync + 'static>(error: E) -> anyhow::Error {
    if error.kind() == FailureKind::Usage {
        usage(error)
    } else {
        error.into()
    }
}

/// 2 for usage errors (ours, and the options `cellbus serve` refuses), 1 for everything
/// else (the device refused, timed out, the line failed).
pub fn exit_code_for(err: &anyhow::Error) -> ExitCode {
    if err
        .chain()
        .any(|cause| cause.is::<UsageError>() || cause.is::<gateway::OptionError>())
    {
        ExitCode::from(2)
    } else {
        ExitCode::from(1)
    }
}

/// `err` and its causes in words, each cause once: many errors already say their cause
/// (`cannot connect to tcp://…: Connection refused`), and anyhow's `{:#}` would repeat it
/// after them.
pub fn describe(err: &anyhow::Error) -> String {
    let mut words = String::new();
    for cause in err.chain() {
        let text = cause.to_string();
        if words.contains(&text) {
            continue;
        }
        if !words.is_empty() {
            words.push_str(": ");
        }
        words.push_str(&text);
    }
    words
}

/// A closed stdout (`cellbus … | head`) is not an error.
pub fn is_broken_pipe(err: &anyhow::Error) -> bool {
    err.chain().any(|cause| {
        cause
            .downcast_ref::<std::io::Error>()
            .is_some_and(|e| e.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

/// Prints one line to stdout and flushes it, so programs reading our output see it at once.
pub fn line(text: impl std::fmt::Display) -> std::io::Result<()> {
    let mut out = std::io::stdout().lock();
    writeln!(out, "{text}")?;
    out.flush()
}

/// Parses bytes written as hex: `02 52 53`, `025253`, `0x02,0x52`; whitespace, commas and
/// colons separate.
pub fn parse_hex(words: &[String]) -> anyhow::Result<Vec<u8>> {
    let mut bytes = Vec::new();
    for word in words
        .iter()
        .flat_map(|w| w.split(|c: char| c.is_whitespace() || c == ',' || c == ':'))
    {
        let digits = word
            .strip_prefix("0x")
            .or_else(|| word.strip_prefix("0X"))
            .unwrap_or(word);
        if digits.is_empty() {
            continue;
        }
        if digits.len() % 2 != 0 {
            return Err(usage(format!(
                "{word:?} is not hex bytes: it has an odd number of digits"
            )));
        }
        for pair in digits.as_bytes().chunks(2) {
            let text = std::str::from_utf8(pair).unwrap_or("??");
            let byte = u8::from_str_radix(text, 16).map_err(|_| {
                usage(format!(
                    "{word:?} is not hex bytes: {text:?} is not a hex byte"
                ))
            })?;
            bytes.push(byte);
        }
    }
    Ok(bytes)
}

/// Bytes as text a person can read: printable ASCII as is, others as `<STX>` or `<0xNN>`.
pub fn printable(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|&b| match b {
            0x02 => "<STX>".to_owned(),
            0x03 => "<ETX>".to_owned(),
            b'\n' => "<LF>".to_owned(),
            b'\r' => "<CR>".to_owned(),
            0x20..=0x7E => (b as char).to_string(),
            _ => format!("<0x{b:02X}>"),
        })
        .collect()
}

/// Bytes as spaced hex.
pub fn hex(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_error_that_already_says_its_cause_is_not_followed_by_it_again() {
        let line = link::LineError::Closed;
        let said = format!("line tcp://x failed: {line}");
        #[derive(Debug, thiserror::Error)]
        #[error("{said}")]
        struct Failed {
            said: String,
            #[source]
            line: link::LineError,
        }
        let err = anyhow::Error::new(Failed { said, line }).context("reading ST1");
        assert_eq!(
            describe(&err),
            "reading ST1: line tcp://x failed: the line was closed by the other end"
        );
        let plain = anyhow::anyhow!("no such file").context("cannot read the map m");
        assert_eq!(describe(&plain), "cannot read the map m: no such file");
    }

    #[test]
    fn hex_input_accepts_spaced_packed_and_prefixed_bytes() {
        let words = [
            "02 52".to_owned(),
            "5354".to_owned(),
            "0x31,0x03".to_owned(),
        ];
        assert_eq!(
            parse_hex(&words).unwrap(),
            vec![0x02, 0x52, 0x53, 0x54, 0x31, 0x03]
        );
    }

    #[test]
    fn hex_input_with_a_bad_digit_names_it() {
        let err = parse_hex(&["02 5G".to_owned()]).unwrap_err();
        assert!(err.to_string().contains("\"5G\""), "{err}");
        assert_eq!(exit_code_for(&err), ExitCode::from(2));
        assert!(
            parse_hex(&["123".to_owned()])
                .unwrap_err()
                .to_string()
                .contains("odd number")
        );
    }

    #[test]
    fn a_request_the_client_refused_to_build_exits_2_not_as_a_device_refusal() {
        let request = jbc::message::Request::write("AT1".parse().expect("a code"), 100)
            .expect_err("AT1 is read-only");
        let err = failure(jbc::client::ClientError::from(request));
        assert_eq!(exit_code_for(&err), ExitCode::from(2));

        let count = jbus::rtu::Request::read_holding_registers(0, 126).expect_err("too many");
        let err = failure(jbus::client::ClientError::from(count));
        assert_eq!(exit_code_for(&err), ExitCode::from(2));
    }

    #[test]
    fn a_device_refusal_exits_1() {
        let refusal = jbc::client::Refusal {
            request: "WST1 00900".to_owned(),
            reason: jbc::code::NakReason::OutOfRange,
            number: 3,
        };
        let err = failure(jbc::client::ClientError::Exchange(
            wire::ExchangeError::Refused {
                endpoint: "tcp://127.0.0.1:1".to_owned(),
                refusal,
            },
        ));
        assert_eq!(exit_code_for(&err), ExitCode::from(1));
        assert_eq!(
            err.to_string(),
            "station refused WST1 00900: out of range (00003)"
        );
    }

    #[test]
    fn printable_marks_control_bytes() {
        assert_eq!(printable(b"\x02RST1\x03\xFF"), "<STX>RST1<ETX><0xFF>");
    }
}

/// How long a watching command (`mqtt sub`, `cfx sub`) runs: `--json`, `--count` and
/// `--timeout`.
#[derive(Debug, clap::Args)]
pub struct Watch {
    /// One JSON object per message and line, instead of words.
    #[arg(long)]
    pub json: bool,
    /// Exit (0) after this many messages.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub count: Option<u64>,
    /// Exit (1) when no message arrives within this time (`10s`, `2m`), counted from the
    /// start and again from each message.
    #[arg(long, value_name = "DURATION", value_parser = humantime::parse_duration)]
    pub timeout: Option<std::time::Duration>,
}

impl Watch {
    /// Whether `received` messages are all that was asked for.
    pub fn done(&self, received: u64) -> bool {
        self.count.is_some_and(|count| received >= count)
    }

    /// The error of a silence as long as `--timeout` after `received` messages, from
    /// `where_from` (`from mqtt://… on spBv1.0/#`).
    pub fn silence(&self, received: u64, where_from: &str) -> anyhow::Error {
        let what = if received == 0 {
            "no message".to_owned()
        } else {
            format!("no further message after {received}")
        };
        let within = self
            .timeout
            .map(|limit| format!(" within {}", humantime::format_duration(limit)))
            .unwrap_or_default();
        anyhow::anyhow!("{what} {where_from}{within}")
    }
}
