//! `cellbus decode …`: split a captured byte stream into annotated frames.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::{Args, Subcommand};
use wire::codec::Chunk;
use wire::{Codec, Deframer};

use crate::output::{self, hex, printable, usage};

#[derive(Debug, Subcommand)]
pub enum DecodeCommand {
    /// JBC robot-protocol frames (STX … ETX BCC).
    Jbc(Input),
    /// Modbus RTU / JBUS frames of both directions (unit, function, addresses, values, CRC;
    /// requests and responses told apart).
    Modbus(Input),
    /// Thermosald ISC messages (% address message Q/R count data LF), as text or hex.
    #[command(mut_arg("hex", |arg| arg.value_name("TEXT|HEX").help(
        "Messages as text, one per argument (`%051Q990`, with a trailing `\\n` or without), \
         or bytes in hex (`25 30 35 31 51 39 39 30 0A`)"
    )))]
    Thermosald(Input),
    /// Panasonic BM host-protocol messages (256-byte command field, size, data,
    /// terminator): C commands, A/D replies and R messages in words.
    Panasonic(Input),
}

/// Where the captured bytes come from.
#[derive(Debug, Args)]
pub struct Input {
    /// Bytes in hex: `02 52 53 54 31 03 41` or `0252535431…`.
    #[arg(value_name = "HEX", conflicts_with = "file")]
    pub hex: Vec<String>,
    /// A binary capture file (what a serial sniffer or `socat -x` saved); - reads standard
    /// input.
    #[arg(long, value_name = "FILE")]
    pub file: Option<PathBuf>,
}

/// The bytes of a capture file, or of standard input for `-`.
pub(crate) fn read_capture(path: &std::path::Path) -> anyhow::Result<Vec<u8>> {
    if path.as_os_str() == "-" {
        let mut bytes = Vec::new();
        std::io::Read::read_to_end(&mut std::io::stdin().lock(), &mut bytes)
            .context("cannot read standard input")?;
        return Ok(bytes);
    }
    std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))
}

impl Input {
    pub(crate) fn bytes(&self) -> anyhow::Result<Vec<u8>> {
        match &self.file {
            Some(path) => read_capture(path),
            None if self.hex.is_empty() => {
                Err(usage("give the bytes as hex arguments or --file FILE"))
            }
            None => output::parse_hex(&self.hex),
        }
    }
}

pub fn run(command: DecodeCommand) -> anyhow::Result<ExitCode> {
    match command {
        DecodeCommand::Jbc(input) => dump(
            jbc::frame::FrameCodec,
            &input.bytes()?,
            jbc::annotate::describe,
        ),
        DecodeCommand::Modbus(input) => {
            let annotator = jbus::annotate::Annotator::new();
            dump(jbus::annotate::CaptureCodec, &input.bytes()?, |frame| {
                annotator.describe(frame)
            })
        }
        DecodeCommand::Thermosald(input) => crate::thermosald_cmd::decode(input),
        DecodeCommand::Panasonic(input) => crate::panasonic_cmd::decode(input),
    }
}

/// Prints each frame and each run of dropped bytes in the stream, with its offset.
/// Exits 1 when anything in the stream was not a good frame.
pub(crate) fn dump<C: Codec>(
    codec: C,
    bytes: &[u8],
    describe: impl Fn(&C::Frame) -> String,
) -> anyhow::Result<ExitCode>
where
    C::Error: std::fmt::Display,
{
    let mut deframer = Deframer::new(codec);
    deframer.push(bytes);
    let (mut offset, mut bad) = (0, 0);
    while let Some(chunk) = deframer.next_chunk() {
        match chunk {
            Chunk::Frame { frame, raw } => {
                output::line(format!(
                    "@{offset:<5} frame    {}\n       {}\n       {}",
                    printable(&raw),
                    hex(&raw),
                    describe(&frame)
                ))?;
                offset += raw.len();
            }
            Chunk::Skipped { error, raw } => {
                bad += 1;
                output::line(format!(
                    "@{offset:<5} dropped  {}\n       {}\n       {error}",
                    printable(&raw),
                    hex(&raw)
                ))?;
                offset += raw.len();
            }
        }
    }
    let rest = deframer.buffered();
    if !rest.is_empty() {
        bad += 1;
        output::line(format!(
            "@{offset:<5} partial  {}\n       {}\n       incomplete frame at the end of the capture",
            printable(rest),
            hex(rest)
        ))?;
    }
    Ok(if bad == 0 {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}
