//! Run-time control of a simulator: commands typed on its standard input, one per line,
//! while it serves (a test or a demo operator switches modes, pauses a feeder, breaks a
//! band…).
//!
//! Every line gets exactly one answer line on stdout: `ok: …` saying in words what
//! happened, or `error: …` saying what was wrong. Nothing typed stops the simulator; the end
//! of input (stdin closed, `/dev/null`) only ends the control channel. Blank lines and lines
//! starting with `#` are ignored (scripts may carry comments). `help` lists the commands,
//! `help COMMAND` explains one.
//!
//! The commands, their words and their effects are the device crates'
//! (`panasonic::operator`, `thermosald::device::operator`); this module is only the
//! channel: [`spawn`] reads stdin on its own thread, so a blocked read of a terminal never
//! holds up the simulator, and [`answer`] gives each line its `ok:`/`error:` line.

use std::io::{BufRead, IsTerminal};
use std::time::Instant;

use panasonic::server::Control;
use thermosald::device::{RegulatorBus, operator as sealer};
use wire::device::SharedModel;
use wire::operator::{CommandSet, help_rows, parse};

use crate::output;

/// The commands for a simulator's `--help`: one per line with what it does.
pub fn long_help<C: CommandSet>() -> String {
    let mut text = String::from(
        "Control while it serves: type commands on stdin, one per line; each gets one line \
         on stdout, `ok: …` or `error: …` (it never stops the simulator). End of input ends \
         only the control channel.\n",
    );
    for syntax in help_rows::<C>() {
        text.push_str(&format!("  {}\n      {}\n", syntax.usage(), syntax.help));
    }
    text
}

/// The answer to one typed line: `Some("ok: …" | "error: …")`, `None` for a blank line or
/// a `#` comment. `act` carries a command out and says what happened, or why not.
pub fn answer<C: CommandSet>(
    line: &str,
    act: &mut impl FnMut(C) -> Result<String, String>,
) -> Option<String> {
    let line = line.trim();
    if line.is_empty() || line.starts_with('#') {
        return None;
    }
    let result = parse::<C>(line)
        .map_err(|err| err.to_string())
        .and_then(act);
    Some(match result {
        Ok(done) => format!("ok: {done}"),
        Err(why) => format!("error: {why}"),
    })
}

/// Reads commands from stdin on a thread of its own and answers each on stdout, until the
/// end of input (or until stdout is gone).
pub fn spawn<C, F>(mut act: F)
where
    C: CommandSet + 'static,
    F: FnMut(C) -> Result<String, String> + Send + 'static,
{
    if std::io::stdin().is_terminal() {
        eprintln!("cellbus: type control commands here, one per line; `help` lists them");
    }
    let spawned = std::thread::Builder::new()
        .name("sim-control".into())
        .spawn(move || {
            let mut input = std::io::stdin().lock();
            let mut bytes = Vec::new();
            loop {
                bytes.clear();
                match input.read_until(b'\n', &mut bytes) {
                    Ok(0) => break,
                    Ok(_) => {}
                    Err(err) => {
                        tracing::debug!("control channel: cannot read stdin ({err}): it ends here");
                        break;
                    }
                }
                let line = String::from_utf8_lossy(&bytes);
                if let Some(reply) = answer::<C>(&line, &mut act)
                    && output::line(reply).is_err()
                {
                    break;
                }
            }
            tracing::debug!("control channel: end of input; the simulator keeps serving");
        });
    if let Err(err) = spawned {
        tracing::warn!("no control channel: cannot start its thread: {err}");
    }
}

/// Starts the Panasonic twin's control channel on stdin.
pub fn panasonic(control: Control) {
    spawn(move |command| control.apply(command).map_err(|err| err.to_string()));
}

/// Starts the Thermosald line's control channel on stdin.
pub fn thermosald(model: SharedModel<RegulatorBus>) {
    spawn(move |command| {
        sealer::apply(&mut model.lock(), command, Instant::now()).map_err(|err| err.to_string())
    });
}

#[cfg(test)]
mod tests {
    use panasonic::operator::Command;

    use super::*;

    #[test]
    fn blank_lines_and_comments_get_no_answer() {
        for line in ["", "   ", "\n", "# remote first", "  # indented"] {
            assert_eq!(answer::<Command>(line, &mut |_| Ok(String::new())), None);
        }
    }

    #[test]
    fn answers_are_one_line_starting_ok_or_error() {
        let mut act = |command: Command| match command {
            Command::Stop => Ok("stopped".to_owned()),
            _ => Err("feeder 99 does not exist".to_owned()),
        };
        assert_eq!(answer("stop", &mut act), Some("ok: stopped".into()));
        assert_eq!(
            answer("pause-feeder 99", &mut act),
            Some("error: feeder 99 does not exist".into())
        );
        assert!(
            answer("bogus", &mut act)
                .expect("an answer")
                .starts_with("error: unknown command `bogus`")
        );
    }

    #[test]
    fn the_long_help_lists_every_command_and_help_itself() {
        let text = long_help::<sealer::Command>();
        for name in [
            "fault ADDR",
            "repair ADDR",
            "power-cycle ADDR",
            "status",
            "help",
        ] {
            assert!(text.contains(name), "{text}");
        }
    }
}
