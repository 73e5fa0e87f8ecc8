//! Running the `cellbus` binary from tests.

#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Output, Stdio};

/// The built `cellbus` binary.
pub fn cellbus() -> Command {
    Command::new(env!("CARGO_BIN_EXE_cellbus"))
}

/// A running simulator, killed when dropped.
pub struct Sim {
    child: Child,
    /// What it printed on its first line after `listening on `.
    pub endpoint: String,
}

impl Sim {
    /// Starts `cellbus sim ARGS…` and waits for its `listening on …` line.
    pub fn start(args: &[&str]) -> Sim {
        let mut child = cellbus()
            .arg("sim")
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("cellbus runs");
        let stdout = child.stdout.take().expect("stdout is piped");
        let mut first = String::new();
        BufReader::new(stdout)
            .read_line(&mut first)
            .expect("the simulator prints a line");
        let endpoint = first
            .trim_end()
            .strip_prefix("listening on ")
            .unwrap_or_else(|| panic!("first line is `listening on …`, got {first:?}"))
            .to_owned();
        Sim { child, endpoint }
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Runs `cellbus ARGS…` to completion.
pub fn run(args: &[&str]) -> Output {
    cellbus()
        .args(args)
        .stdin(Stdio::null())
        .output()
        .expect("cellbus runs")
}

/// Stdout as text.
pub fn stdout(output: &Output) -> String {
    String::from_utf8_lossy(&output.stdout).into_owned()
}

/// Stderr as text.
pub fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}
