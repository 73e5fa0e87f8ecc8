//! Bounds on what anyone can make a server keep, log or read: names cut to a stored
//! length ([`cut`]), log lines at most once an interval ([`LogThrottle`]), files read up to
//! a size ([`read_bounded`]).

use std::path::Path;
use std::time::Duration;

use tokio::time::Instant;

/// Longest stored text of a client, device or point as the request named them.
pub const MAX_NAME: usize = 128;

/// At most one log line about refused unauthorised writes (or another flood) this often.
pub const LOG_EVERY: Duration = Duration::from_secs(10);

/// `text` cut to at most `max` bytes (on a character boundary), with `…` when cut.
pub fn cut(text: &str, max: usize) -> String {
    if text.len() <= max {
        return text.to_owned();
    }
    let mut end = max.saturating_sub('…'.len_utf8());
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    format!("{}…", &text[..end])
}

/// Something anyone can cause by the thousand (a refused write, command or connection),
/// logged at most once every [`LOG_EVERY`] with how many there were since the last line.
#[derive(Debug, Default)]
pub struct LogThrottle {
    last_log: Option<Instant>,
    unlogged: u64,
}

impl LogThrottle {
    /// Counts one at `now`; returns how many to report when a log line is due.
    pub fn count(&mut self, now: Instant) -> Option<u64> {
        self.unlogged += 1;
        if self.last_log.is_some_and(|t| now < t + LOG_EVERY) {
            return None;
        }
        self.last_log = Some(now);
        Some(std::mem::take(&mut self.unlogged))
    }

    /// Nothing counted since the last line, which is older than [`LOG_EVERY`].
    pub fn is_quiet(&self, now: Instant) -> bool {
        self.unlogged == 0 && self.last_log.is_none_or(|t| now >= t + LOG_EVERY)
    }
}

/// The bytes of the regular file at `path`, refused when larger than `max` (a config that
/// names `/dev/zero` or a huge file must not hang or exhaust the program); the error says
/// why in words.
pub fn read_bounded(path: &Path, max: u64) -> Result<Vec<u8>, String> {
    use std::io::Read as _;
    let file = std::fs::File::open(path).map_err(|e| format!("cannot be read: {e}"))?;
    let meta = file
        .metadata()
        .map_err(|e| format!("cannot be read: {e}"))?;
    if !meta.is_file() {
        return Err("is not a file".into());
    }
    let mut bytes = Vec::new();
    file.take(max + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| format!("cannot be read: {e}"))?;
    if bytes.len() as u64 > max {
        return Err(format!("is larger than {} MiB", max >> 20));
    }
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_text_is_cut_on_a_character_boundary_with_an_ellipsis() {
        assert_eq!(cut("short", 8), "short");
        assert_eq!(cut("abcdefghij", 8), "abcde…");
        // `é` is two bytes: the cut falls before it, not inside it.
        assert_eq!(cut("abcdéfgh", 8), "abcd…");
        assert!(cut(&"x".repeat(1000), MAX_NAME).len() <= MAX_NAME);
    }

    #[test]
    fn a_throttle_logs_the_first_at_once_then_once_an_interval_with_the_count() {
        let mut throttle = LogThrottle::default();
        let t0 = Instant::now();
        assert!(throttle.is_quiet(t0));
        assert_eq!(throttle.count(t0), Some(1));
        for _ in 0..9 {
            assert_eq!(throttle.count(t0), None);
        }
        assert!(!throttle.is_quiet(t0 + LOG_EVERY));
        assert_eq!(throttle.count(t0 + LOG_EVERY), Some(10));
        assert!(throttle.is_quiet(t0 + 2 * LOG_EVERY));
    }

    #[test]
    fn files_larger_than_the_bound_or_not_files_are_refused_in_words() {
        let dir = tempfile::tempdir().unwrap();
        let big = dir.path().join("big.csv");
        let max = 4 << 20;
        std::fs::write(&big, vec![b'a'; (max + 1) as usize]).unwrap();
        let error = read_bounded(&big, max).unwrap_err();
        assert!(error.contains("larger than 4 MiB"), "{error}");
        assert_eq!(read_bounded(dir.path(), max).unwrap_err(), "is not a file");
        let missing = read_bounded(&dir.path().join("none"), max).unwrap_err();
        assert!(missing.starts_with("cannot be read: "), "{missing}");
        std::fs::write(&big, b"ok").unwrap();
        assert_eq!(read_bounded(&big, max).unwrap(), b"ok");
    }
}
