//! The catalog's errors, each with a [`CatalogError::kind`].

use std::path::PathBuf;

/// What kind of failure, for callers that decide without matching every variant (the run
/// hook retries [`ErrorKind::Unreachable`] later; the CLI says "bad input" for
/// [`ErrorKind::BadUrl`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum ErrorKind {
    /// The catalog URL is malformed or names an unknown backend.
    BadUrl,
    /// The directory holds no readable run.
    NotARun,
    /// The database cannot be reached (connection refused, timeout, DNS, pool closed).
    Unreachable,
    /// The database answered with an error.
    Database,
    /// The schema could not be brought to this version.
    Migration,
    /// A local file or directory could not be read or created.
    Io,
    /// The SQLite file is damaged (`PRAGMA quick_check` failed, or SQLite said so): nothing
    /// is read from it; `gyrocal catalog rebuild` moves it aside and rebuilds it.
    Damaged,
    /// A listing command was pointed at an SQLite file that does not exist (it creates
    /// nothing: a run or `gyrocal catalog import` does).
    NotFound,
}

/// Everything that can go wrong with the catalog. Messages name the catalog by its URL with
/// the password replaced by `***` (see [`crate::CatalogUrl::redacted`]), never the password.
#[derive(Debug, thiserror::Error)]
pub enum CatalogError {
    /// The URL does not parse.
    #[error("catalog URL {url}: {message}")]
    BadUrl {
        /// The URL, redacted.
        url: String,
        /// What is wrong.
        message: String,
    },
    /// A directory that is not (or not yet) a readable run directory.
    #[error("{}: not a readable gyrocal run directory: {message}", path.display())]
    NotARun {
        /// The directory.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// The database cannot be reached.
    #[error("catalog {url} is unreachable: {message}")]
    Unreachable {
        /// The URL, redacted.
        url: String,
        /// The driver's message (password removed).
        message: String,
    },
    /// The database refused a statement.
    #[error("catalog {url}: {message}")]
    Database {
        /// The URL, redacted.
        url: String,
        /// The driver's message (password removed).
        message: String,
    },
    /// The migrations failed.
    #[error("catalog {url}: cannot bring the schema up to date: {message}")]
    Migration {
        /// The URL, redacted.
        url: String,
        /// The driver's message (password removed).
        message: String,
    },
    /// A local file operation failed.
    #[error("{}: cannot {action}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// What was being done.
        action: &'static str,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The SQLite file is damaged. Listing from it could show a shorter history than the
    /// run directories hold, so nothing is read; the message names the file and the repair.
    #[error(
        "catalog {} is damaged ({message}); nothing is read from it, since a damaged file can \
         hide runs. The run directories hold every run: `gyrocal catalog rebuild ROOT` (ROOT: the \
         directory holding them) rebuilds the catalog from them, first moving the file aside \
         (kept) when SQLite finds its pages damaged",
        path.display()
    )]
    Damaged {
        /// The database file.
        path: PathBuf,
        /// SQLite's own words: the error and what `PRAGMA quick_check` found.
        message: String,
    },
    /// A listing command's SQLite catalog does not exist.
    #[error(
        "no catalog at {}: nothing has been indexed there (a run indexes itself; \
         `gyrocal catalog import DIR` or `gyrocal catalog rebuild ROOT` creates the catalog)",
        path.display()
    )]
    NotFound {
        /// The file that is not there.
        path: PathBuf,
    },
}

impl CatalogError {
    /// The kind of failure.
    pub fn kind(&self) -> ErrorKind {
        match self {
            CatalogError::BadUrl { .. } => ErrorKind::BadUrl,
            CatalogError::NotARun { .. } => ErrorKind::NotARun,
            CatalogError::Unreachable { .. } => ErrorKind::Unreachable,
            CatalogError::Database { .. } => ErrorKind::Database,
            CatalogError::Migration { .. } => ErrorKind::Migration,
            CatalogError::Io { .. } => ErrorKind::Io,
            CatalogError::Damaged { .. } => ErrorKind::Damaged,
            CatalogError::NotFound { .. } => ErrorKind::NotFound,
        }
    }
}
