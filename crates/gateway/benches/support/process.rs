//! CPU time and peak memory of a process, from `/proc`, for the benches.

use std::process::Command;
use std::time::Duration;

use anyhow::Context;

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
