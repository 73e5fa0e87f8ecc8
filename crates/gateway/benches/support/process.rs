//! CPU time and peak memory of a process, from `/proc`, and the end of a helper process,
//! for the benches.

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};

/// CPU time and peak memory of a process, from `/proc`.
#[derive(Debug, Clone, Copy, Default)]
pub struct ProcessUse {
    /// User and system CPU time.
    pub cpu: Duration,
    /// The user part of `cpu` (the rest is the kernel's work for the process: system calls,
    /// and what the kernel accounts to it while it runs, such as loopback TCP delivering
    /// what it sends to the receiving socket).
    pub user: Duration,
    /// Peak resident set size (`VmHWM`).
    pub peak_rss_kib: u64,
}

impl ProcessUse {
    /// Of process `pid` (`self` for this one).
    pub fn of(pid: &str, ticks_per_second: u64) -> anyhow::Result<Self> {
        let stat = std::fs::read_to_string(format!("/proc/{pid}/stat"))
            .with_context(|| format!("cannot read /proc/{pid}/stat"))?;
        // Fields after the command name (which may hold spaces) in parentheses: state is
        // field 3, utime 14, stime 15.
        let after = stat
            .rsplit_once(')')
            .map(|(_, rest)| rest)
            .context("/proc/PID/stat without a command name")?;
        let fields: Vec<&str> = after.split_whitespace().collect();
        let ticks = |n: usize| -> anyhow::Result<u64> {
            fields
                .get(n - 3)
                .and_then(|f| f.parse().ok())
                .with_context(|| format!("/proc/{pid}/stat field {n}"))
        };
        let user = ticks(14)?;
        let total = user + ticks(15)?;
        let status = std::fs::read_to_string(format!("/proc/{pid}/status"))
            .with_context(|| format!("cannot read /proc/{pid}/status"))?;
        let peak_rss_kib = status
            .lines()
            .find_map(|l| l.strip_prefix("VmHWM:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
            .context("no VmHWM in /proc/PID/status")?;
        Ok(Self {
            cpu: Duration::from_secs_f64(total as f64 / ticks_per_second as f64),
            user: Duration::from_secs_f64(user as f64 / ticks_per_second as f64),
            peak_rss_kib,
        })
    }
}

impl ProcessUse {
    /// This use without the CPU time of `part` (one of its threads, or the same process
    /// earlier: the CPU time between two readings); the peak RSS is this one's.
    pub fn without(self, part: &ProcessUse) -> Self {
        Self {
            cpu: self.cpu.saturating_sub(part.cpu),
            user: self.user.saturating_sub(part.user),
            peak_rss_kib: self.peak_rss_kib,
        }
    }
}

/// Clock ticks per second of `/proc/PID/stat` (USER_HZ; 100 on Linux unless `getconf`
/// says otherwise).
pub fn ticks_per_second() -> u64 {
    Command::new("getconf")
        .arg("CLK_TCK")
        .output()
        .ok()
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .and_then(|s| s.trim().parse().ok())
        .filter(|t| *t > 0)
        .unwrap_or(100)
}

/// Resets the peak RSS of this process to its current RSS (`/proc/self/clear_refs`), so
/// that a setup phase's memory does not count; whether the kernel allowed it.
#[allow(dead_code)] // not every bench has a setup phase
pub fn reset_peak_rss() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

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
