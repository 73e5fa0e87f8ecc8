//! Opening the writer's connection: the directory, the file, `PRAGMA quick_check`, and a
//! damaged file moved aside for a new one.

use std::path::{Path, PathBuf};

use rusqlite::{Connection, ErrorCode};

use crate::time::Timestamp;

use super::*;

/// The writer's open connection, and the damaged file it replaced, if any.
pub(super) struct Opened {
    pub(super) conn: Connection,
    /// Where a damaged file was moved, and what was wrong with it.
    pub(super) moved_aside: Option<(PathBuf, String)>,
}

/// The database's path in `dir`, creating the directory if need be.
pub(super) fn database_path(dir: &Path) -> Result<std::path::PathBuf, StoreError> {
    std::fs::create_dir_all(dir).map_err(|source| StoreError::Directory {
        path: dir.to_owned(),
        source,
    })?;
    Ok(dir.join(DB_FILE))
}

/// Opens `dir/cellbus.db` for writing: creates the directory, checks the file and creates
/// the tables. A file that is not a database or fails `quick_check` is moved aside.
pub(super) fn open_writer(dir: &Path) -> Result<Opened, StoreError> {
    let path = database_path(dir)?;
    let sqlite = |source| StoreError::Sqlite {
        path: path.clone(),
        source,
    };
    let fault = match open_checked(&path) {
        Ok(conn) => {
            return Ok(Opened {
                conn,
                moved_aside: None,
            });
        }
        Err(Checked::Damaged(fault)) => fault,
        Err(Checked::Failed(source)) => return Err(sqlite(source)),
    };
    let aside = move_aside(&path, Timestamp::now()).map_err(|source| StoreError::MoveAside {
        path: path.clone(),
        fault: fault.clone(),
        source,
    })?;
    tracing::error!(
        "history {}: {fault}; moved aside as {} and started a new file",
        path.display(),
        aside.display()
    );
    match open_checked(&path) {
        Ok(conn) => Ok(Opened {
            conn,
            moved_aside: Some((aside, fault)),
        }),
        Err(Checked::Damaged(fault)) => Err(StoreError::Unavailable {
            reason: format!(
                "a new history file {} is damaged too: {fault}",
                path.display()
            ),
        }),
        Err(Checked::Failed(source)) => Err(sqlite(source)),
    }
}

enum Checked {
    /// Not a database, or `quick_check` found faults: move it aside.
    Damaged(String),
    /// Anything else (permissions, I/O): not the file's fault.
    Failed(rusqlite::Error),
}

fn open_checked(path: &Path) -> Result<Connection, Checked> {
    let damaged_or_failed = |e: rusqlite::Error| match e.sqlite_error_code() {
        Some(ErrorCode::NotADatabase | ErrorCode::DatabaseCorrupt) => {
            Checked::Damaged(e.to_string())
        }
        _ => Checked::Failed(e),
    };
    let mut conn = Connection::open(path).map_err(damaged_or_failed)?;
    // Only a new file takes it: SQLite fixes auto_vacuum when the first table is created.
    conn.pragma_update(None, "auto_vacuum", "INCREMENTAL")
        .map_err(damaged_or_failed)?;
    configure_writer(&conn).map_err(damaged_or_failed)?;
    // A damaged page can also make the check itself fail.
    let report = quick_check(&conn).map_err(|e| match damaged_or_failed(e) {
        Checked::Damaged(fault) => Checked::Damaged(format!("quick_check failed: {fault}")),
        failed => failed,
    })?;
    if report != "ok" {
        return Err(Checked::Damaged(format!("quick_check found: {report}")));
    }
    migrate(&mut conn).map_err(damaged_or_failed)?;
    Ok(conn)
}

/// `PRAGMA quick_check`: `ok` or its findings (the first ten).
fn quick_check(conn: &Connection) -> rusqlite::Result<String> {
    let mut stmt = conn.prepare("PRAGMA quick_check(10)")?;
    let lines = stmt
        .query_map([], |r| r.get::<_, String>(0))?
        .collect::<Result<Vec<_>, _>>()?;
    Ok(lines.join("; "))
}

/// Renames `path` (and its `-wal` and `-shm`) to `<path>.corrupt-<UTC time>`; returns the
/// new name of the database file.
pub(super) fn move_aside(path: &Path, now: Timestamp) -> std::io::Result<PathBuf> {
    let stamp = compact_utc(now);
    let mut aside = PathBuf::from(format!("{}.corrupt-{stamp}", path.display()));
    let mut n = 1;
    while aside.exists() {
        n += 1;
        aside = PathBuf::from(format!("{}.corrupt-{stamp}-{n}", path.display()));
    }
    for suffix in ["-wal", "-shm"] {
        let from = PathBuf::from(format!("{}{suffix}", path.display()));
        if from.exists() {
            std::fs::rename(&from, format!("{}{suffix}", aside.display()))?;
        }
    }
    std::fs::rename(path, &aside)?;
    Ok(aside)
}

/// `20261125T064500Z`: the RFC 3339 time without separators or fraction.
fn compact_utc(t: Timestamp) -> String {
    let text = t.to_string();
    let seconds = text.split('.').next().unwrap_or(&text);
    let mut compact: String = seconds
        .chars()
        .filter(|c| !matches!(c, '-' | ':'))
        .collect();
    compact.push('Z');
    compact
}
