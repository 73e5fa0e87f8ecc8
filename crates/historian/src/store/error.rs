//! What can go wrong between the historian and PostgreSQL, sorted by what the runtime does
//! about it: reconnect and retry (the connection is lost or the server is starting), or
//! stop and tell (bad URL, refused login, bad data, a schema too new).

use std::error::Error as _;
use std::fmt::Write as _;

use tokio_postgres::error::{DbError, SqlState};

/// An error of the store, with the statement or step it happened in.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum StoreError {
    /// The database URL cannot be read (it is not echoed: it may hold a password).
    #[error(
        "the database URL is not a PostgreSQL connection string ({source}); write \
         postgres://USER@HOST:PORT/DB"
    )]
    BadUrl {
        /// The parser's complaint.
        source: tokio_postgres::Error,
    },
    /// A URL of another scheme (`mysql://…`), which libpq's parser would call only an
    /// unexpected end.
    #[error("{scheme}:// is not PostgreSQL; write postgres://USER@HOST:PORT/DB")]
    NotPostgres {
        /// The scheme given.
        scheme: String,
    },
    /// No connection could be made.
    #[error("cannot connect to PostgreSQL at {target}: {reason}")]
    Connect {
        /// `user@host:port/db`.
        target: String,
        /// What went wrong, in words (with the SQLSTATE when the server said it).
        reason: String,
        /// Whether trying again later may work: nothing listens yet, the connection was
        /// cut, or the server is starting or recovering. A refused login or a missing
        /// database is not transient.
        transient: bool,
        /// The client's error.
        source: tokio_postgres::Error,
    },
    /// The connection broke (the server stopped, crashed or cut this session): reconnect
    /// and write the same batch again; what was not committed was rolled back.
    #[error("lost the connection to PostgreSQL while {during}: {reason}")]
    ConnectionLost {
        /// The step (`copying samples into the staging table`).
        during: &'static str,
        /// What the client or the server said.
        reason: String,
        /// The client's error.
        source: tokio_postgres::Error,
    },
    /// The server refused a statement; nothing of the batch was committed.
    #[error("PostgreSQL refused {during}: {reason}")]
    Refused {
        /// The step.
        during: &'static str,
        /// The SQLSTATE (`23505`), when the server gave one.
        code: Option<String>,
        /// The server's message, detail and hint.
        reason: String,
        /// The client's error.
        source: tokio_postgres::Error,
    },
    /// The database was migrated by a newer historian than this one.
    #[error(
        "the database's cellbus schema is version {found}, newer than this historian's \
         {known}: run the newer cellbus historian"
    )]
    SchemaTooNew {
        /// The version in `cellbus_schema`.
        found: i32,
        /// The newest version this build knows.
        known: i32,
    },
}

impl StoreError {
    /// Whether the connection is gone or could not be made for a reason that may pass
    /// (PostgreSQL stopped, restarting or recovering): the runtime should connect again,
    /// with a backoff, and retry the same batch (duplicates are not stored twice).
    pub fn is_connection_lost(&self) -> bool {
        match self {
            StoreError::ConnectionLost { .. } => true,
            StoreError::Connect { transient, .. } => *transient,
            _ => false,
        }
    }

    /// Whether writing the same batch again may succeed: the connection is lost (connect
    /// first), or the server gave up on the transaction for a reason that passes
    /// (SQLSTATE 40001 serialization failure, 40P01 deadlock, 55P03 lock not available,
    /// 53xxx insufficient resources such as a full disk).
    pub fn is_retryable(&self) -> bool {
        match self {
            StoreError::Refused {
                code: Some(code), ..
            } => matches!(code.as_str(), "40001" | "40P01" | "55P03") || code.starts_with("53"),
            _ => self.is_connection_lost(),
        }
    }

    /// Whether the server refused the data itself (SQLSTATE class 22, data exception, or
    /// 23, integrity constraint violation): retrying the same batch will fail again.
    pub fn is_bad_data(&self) -> bool {
        matches!(self, StoreError::Refused { code: Some(code), .. }
            if code.starts_with("22") || code.starts_with("23"))
    }

    /// The error of a statement run in the step `during`.
    pub(crate) fn statement(during: &'static str, source: tokio_postgres::Error) -> Self {
        let reason = describe(&source);
        if is_lost(&source) {
            return StoreError::ConnectionLost {
                during,
                reason,
                source,
            };
        }
        StoreError::Refused {
            during,
            code: source.code().map(|c| c.code().to_owned()),
            reason,
            source,
        }
    }

    /// The error of a connection attempt to `target`.
    pub(crate) fn connect(target: String, source: tokio_postgres::Error) -> Self {
        let transient = is_lost(&source)
            || source.as_db_error().is_none() && io_error(&source).is_some()
            || source.code() == Some(&SqlState::CANNOT_CONNECT_NOW);
        StoreError::Connect {
            target,
            reason: describe(&source),
            transient,
            source,
        }
    }
}

/// Whether an error means the session is gone: the client saw the connection close or an
/// I/O error, or the server ended the session (SQLSTATE class 08, or 57P01–57P03: shut
/// down by an administrator, crash of another backend, cannot connect now).
fn is_lost(e: &tokio_postgres::Error) -> bool {
    if e.is_closed() || io_error(e).is_some() {
        return true;
    }
    e.code().is_some_and(|code| {
        code.code().starts_with("08")
            || *code == SqlState::ADMIN_SHUTDOWN
            || *code == SqlState::CRASH_SHUTDOWN
            || *code == SqlState::CANNOT_CONNECT_NOW
    })
}

/// The I/O error under a client error, if any.
fn io_error(e: &tokio_postgres::Error) -> Option<&std::io::Error> {
    let mut cause = e.source();
    while let Some(c) = cause {
        if let Some(io) = c.downcast_ref::<std::io::Error>() {
            return Some(io);
        }
        cause = c.source();
    }
    None
}

/// The facts of an error in one line: the server's `ERROR 23505: message (detail; hint)`,
/// or the client's words with their causes.
fn describe(e: &tokio_postgres::Error) -> String {
    if let Some(db) = e.as_db_error() {
        return describe_db(db);
    }
    let mut text = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        let words = c.to_string();
        if !text.contains(&words) {
            let _ = write!(text, ": {words}");
        }
        cause = c.source();
    }
    text
}

fn describe_db(db: &DbError) -> String {
    let mut text = format!("{} {}: {}", db.severity(), db.code().code(), db.message());
    let extra: Vec<&str> = [db.detail(), db.hint()].into_iter().flatten().collect();
    if !extra.is_empty() {
        let _ = write!(text, " ({})", extra.join("; "));
    }
    text
}
