//! Small values that must survive a restart (the Sparkplug `bdSeq`), in the `settings`
//! table of the history database. Read and written on their own short connection, on the
//! caller's thread: they are few and written once per MQTT connection. Callers wait for
//! the writer's open first ([`StoreHandle::wait_open`](super::StoreHandle::wait_open)), so
//! a damaged file is moved aside before a setting touches it.

use std::path::Path;

use rusqlite::{Connection, OptionalExtension};

use super::{StoreError, schema};

const CREATE: &str =
    "CREATE TABLE IF NOT EXISTS settings (key TEXT PRIMARY KEY, value INTEGER NOT NULL)";

/// The value stored under `key` in the database in `dir`, if any.
pub fn read_setting(dir: &Path, key: &str) -> Result<Option<i64>, StoreError> {
    let (path, conn) = connect(dir)?;
    conn.query_row("SELECT value FROM settings WHERE key = ?1", [key], |r| {
        r.get(0)
    })
    .optional()
    .map_err(|source| StoreError::Sqlite { path, source })
}

/// Stores `value` under `key` in the database in `dir`, committed when this returns.
pub fn write_setting(dir: &Path, key: &str, value: i64) -> Result<(), StoreError> {
    let (path, conn) = connect(dir)?;
    conn.execute(
        "INSERT INTO settings (key, value) VALUES (?1, ?2)
         ON CONFLICT(key) DO UPDATE SET value = excluded.value",
        rusqlite::params![key, value],
    )
    .map(drop)
    .map_err(|source| StoreError::Sqlite { path, source })
}

/// A short connection of its own to the database in `dir`, set up as the writer's is, with
/// the `settings` table there.
pub(super) fn connect(dir: &Path) -> Result<(std::path::PathBuf, Connection), StoreError> {
    let path = super::open::database_path(dir)?;
    let sqlite = |source| StoreError::Sqlite {
        path: path.clone(),
        source,
    };
    let conn = Connection::open(&path).map_err(sqlite)?;
    // Patience from the first statement: the writer may hold the file.
    conn.busy_timeout(std::time::Duration::from_secs(5))
        .map_err(sqlite)?;
    // As the writer's open does: should this connection create the file, it keeps the
    // incremental vacuum the retention relies on.
    conn.pragma_update(None, "auto_vacuum", "INCREMENTAL")
        .map_err(sqlite)?;
    schema::configure(&conn).map_err(sqlite)?;
    conn.execute_batch(CREATE).map_err(sqlite)?;
    Ok((path, conn))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_setting_written_is_read_back_by_a_new_connection() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(read_setting(dir.path(), "mqtt.bd_seq").unwrap(), None);
        write_setting(dir.path(), "mqtt.bd_seq", 7).unwrap();
        write_setting(dir.path(), "mqtt.bd_seq", 8).unwrap();
        assert_eq!(read_setting(dir.path(), "mqtt.bd_seq").unwrap(), Some(8));
    }

    #[test]
    fn a_file_the_settings_create_keeps_the_incremental_vacuum() {
        let dir = tempfile::tempdir().unwrap();
        write_setting(dir.path(), "mqtt.bd_seq", 1).unwrap();
        let conn = Connection::open(dir.path().join(super::super::DB_FILE)).unwrap();
        let mode: i64 = conn
            .pragma_query_value(None, "auto_vacuum", |r| r.get(0))
            .unwrap();
        assert_eq!(mode, 2, "INCREMENTAL");
    }
}
