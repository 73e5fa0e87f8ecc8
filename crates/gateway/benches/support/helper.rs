//! A bench's helper process: the bench's own executable run as a child (the simulators,
//! the counters), talking in lines.

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};

/// How long a helper process gets to end by itself once its standard input is closed.
const HELPER_GRACE: Duration = Duration::from_secs(5);

/// A bench's helper process (the simulators, the counters): the bench's own executable
/// started with a flag, talking in lines over its standard input and output, and running
/// until its standard input closes. Dropping it closes that input, gives the child
/// [`HELPER_GRACE`] to end and remove what it made (its temporary directories: a child
/// killed outright left them in `/tmp`), then kills it if it still runs.
pub struct Helper {
    child: Child,
    stdin: Option<ChildStdin>,
    stdout: BufReader<ChildStdout>,
}

impl Helper {
    /// Starts `command` with piped input and output (`what` names it in errors).
    pub fn start(mut command: Command, what: &str) -> anyhow::Result<Self> {
        let mut child = command
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .with_context(|| format!("cannot start the {what} process"))?;
        let stdin = child.stdin.take();
        let stdout = child.stdout.take().map(BufReader::new);
        let stdout = stdout.with_context(|| format!("the {what} process has no output"))?;
        Ok(Self {
            child,
            stdin,
            stdout,
        })
    }

    /// The next line the helper writes, without its line end; an error once it has ended.
    pub fn read_line(&mut self) -> anyhow::Result<String> {
        let mut line = String::new();
        if self.stdout.read_line(&mut line)? == 0 {
            bail!("the helper process ended");
        }
        Ok(line.trim_end().to_owned())
    }

    /// Sends `question` as a line and gives the line the helper answers.
    pub fn ask(&mut self, question: &str) -> anyhow::Result<String> {
        let stdin = self
            .stdin
            .as_mut()
            .context("the helper's input is closed")?;
        writeln!(stdin, "{question}")?;
        stdin.flush()?;
        self.read_line()
    }

    /// Its process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }
}

impl Drop for Helper {
    fn drop(&mut self) {
        drop(self.stdin.take());
        let deadline = Instant::now() + HELPER_GRACE;
        while let Ok(None) = self.child.try_wait() {
            if Instant::now() >= deadline {
                break;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The whitespace-separated numbers of a helper's answer line; `None` if one is not a
/// number.
pub fn numbers(line: &str) -> Option<Vec<u64>> {
    line.split_whitespace()
        .map(str::parse)
        .collect::<Result<_, _>>()
        .ok()
}
