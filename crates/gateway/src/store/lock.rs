//! One gateway per data directory: `cellbus serve` holds an exclusive lock on
//! `DIR/cellbus.lock` while it runs. Two gateways on one directory would write one history
//! and publish with one Sparkplug `bdSeq`; the second is refused, naming the first. The
//! lock is the kernel's (`flock`), released when the process ends however it ends, so a
//! `kill -9` leaves nothing to clean: the file stays, unlocked, and the next start takes it.

use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};

/// The lock file's name in the data directory.
pub const LOCK_FILE: &str = "cellbus.lock";

/// The data directory, held by this process until dropped.
#[derive(Debug)]
pub struct DataLock {
    _file: File,
    path: PathBuf,
}

/// Why the data directory could not be taken.
#[derive(Debug, thiserror::Error)]
pub enum LockError {
    /// Another process holds it.
    #[error(
        "the data directory {dir} is in use by another cellbus ({holder}); two gateways on one directory would share its history and Sparkplug bdSeq: stop the other one, or give this one its own --data"
    )]
    Held {
        /// The directory.
        dir: PathBuf,
        /// What the other process wrote in the lock file.
        holder: String,
    },
    /// The directory or the lock file cannot be used (the history then says why).
    #[error("cannot lock {path}: {source}")]
    Unusable {
        /// The lock file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

impl DataLock {
    /// Takes `dir` (created if missing) for this process; `who` is written in the lock
    /// file for the next one to read (`cellbus serve on http://…`).
    pub fn take(dir: &Path, who: &str) -> Result<Self, LockError> {
        let path = dir.join(LOCK_FILE);
        let unusable = |source| LockError::Unusable {
            path: path.clone(),
            source,
        };
        std::fs::create_dir_all(dir).map_err(unusable)?;
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(unusable)?;
        match file.try_lock() {
            Ok(()) => {}
            Err(TryLockError::WouldBlock) => {
                let mut holder = String::new();
                // What it wrote; a lock file cut short still names the directory.
                let _ = file.take(1024).read_to_string(&mut holder);
                let holder = holder.trim();
                return Err(LockError::Held {
                    dir: dir.to_owned(),
                    holder: if holder.is_empty() {
                        "it has not said which".to_owned()
                    } else {
                        holder.to_owned()
                    },
                });
            }
            Err(TryLockError::Error(e)) => return Err(unusable(e)),
        }
        let me = format!(
            "pid {}, {who}, since {}",
            std::process::id(),
            crate::time::Timestamp::now()
        );
        file.set_len(0).map_err(unusable)?;
        file.rewind().map_err(unusable)?;
        file.write_all(me.as_bytes()).map_err(unusable)?;
        Ok(DataLock { _file: file, path })
    }

    /// The lock file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_taker_is_refused_naming_the_first_until_the_first_lets_go() {
        let dir = tempfile::tempdir().unwrap();
        let first = DataLock::take(dir.path(), "cellbus serve on http://127.0.0.1:8080").unwrap();
        let refused = DataLock::take(dir.path(), "cellbus serve on http://127.0.0.1:8081")
            .unwrap_err()
            .to_string();
        assert!(
            refused.contains(&format!("pid {}", std::process::id()))
                && refused.contains("cellbus serve on http://127.0.0.1:8080")
                && refused.contains("in use by another cellbus"),
            "{refused}"
        );
        drop(first);
        let second = DataLock::take(dir.path(), "cellbus serve on http://127.0.0.1:8081").unwrap();
        let written = std::fs::read_to_string(second.path()).unwrap();
        assert!(
            written.contains("8081") && !written.contains("8080"),
            "{written}"
        );
    }

    #[test]
    fn a_missing_directory_is_made() {
        let dir = tempfile::tempdir().unwrap();
        let data = dir.path().join("new").join("data");
        DataLock::take(&data, "test").unwrap();
        assert!(data.join(LOCK_FILE).is_file());
    }
}
