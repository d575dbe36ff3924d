//! What can go wrong with a run directory ([`RunError`]) and whose fault it is
//! ([`RunErrorKind`]): every variant names the file, and the line where there is one.
#[allow(unused_imports)]
use super::*;

/// Everything that can go wrong with a run directory. Every variant names the file (and the
/// line where there is one).
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// An I/O operation failed.
    #[error("{}: cannot {action}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// What was being done (`create`, `write`, `sync`, ...).
        action: &'static str,
        /// The I/O error.
        source: std::io::Error,
    },
    /// Another process (or another open `RunDir`) is writing this run directory.
    #[error("{}: the run directory is in use by another gyrocal process", path.display())]
    Locked {
        /// The directory.
        path: PathBuf,
    },
    /// `create` was given a directory that already holds files.
    #[error("{}: the run directory exists and is not empty (use --resume to continue it)", path.display())]
    NotEmpty {
        /// The directory.
        path: PathBuf,
    },
    /// A file of the run directory is larger than gyrocal ever writes it (or endless).
    #[error(
        "{}: larger than the {} MiB limit for this file; it is not a file gyrocal wrote",
        path.display(),
        cap / (1024 * 1024)
    )]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// The limit, bytes.
        cap: u64,
    },
    /// A CSV row or header that does not parse or does not fit the plan.
    #[error("{}:{line}: {message}", path.display())]
    Csv {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: u64,
        /// What is wrong.
        message: String,
    },
    /// The manifest does not parse (or its plan does not validate).
    #[error("{}:{line}:{column}: {message}", path.display())]
    Json {
        /// The file.
        path: PathBuf,
        /// 1-based line (0 when unknown).
        line: usize,
        /// 1-based column (0 when unknown).
        column: usize,
        /// What is wrong.
        message: String,
    },
    /// The files contradict each other (or the manifest contradicts itself).
    #[error("{}: {message}", path.display())]
    Inconsistent {
        /// The file found wrong.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// `--resume` with a plan whose hash differs from the run's.
    #[error(
        "{}: the plan changed since this run started: {}; resume without a plan (the run's own is in its manifest) or start a new run",
        path.display(),
        if changes.is_empty() { format!("plan hash {run_hash} vs {plan_hash}") } else { changes.join("; ") }
    )]
    PlanChanged {
        /// The manifest.
        path: PathBuf,
        /// Hash recorded in the run.
        run_hash: String,
        /// Hash of the plan given now.
        plan_hash: String,
        /// What differs, one entry per key: `[dmm] range_v: 10 (run) vs 100 (this plan)`.
        changes: Vec<String>,
    },
    /// A directory that holds no run (no `manifest.json`).
    #[error(
        "{} is not a gyrocal run directory (it has no manifest.json); give the directory a run wrote",
        path.display()
    )]
    NotARun {
        /// The directory.
        path: PathBuf,
    },
    /// `--resume` of a run that is already complete.
    #[error("{}: the run is already complete; nothing to resume", path.display())]
    AlreadyComplete {
        /// The manifest.
        path: PathBuf,
    },
    /// The caller broke the writing protocol (wrong step, index gap, count mismatch, NaN).
    #[error("{}: {message}", path.display())]
    Protocol {
        /// The file that would have been written.
        path: PathBuf,
        /// What was wrong with the call.
        message: String,
    },
}

/// What kind of [`RunError`] it is: whose the fault is, so the CLI picks its exit code (2 for
/// bad input, 1 for a failure of the environment) without matching messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RunErrorKind {
    /// The files or the arguments: a malformed or inconsistent file, a directory that holds
    /// no run, a path that does not exist or may not be written, a changed plan.
    Input,
    /// Another process is writing the run directory.
    Busy,
    /// The system failed: the disk is full, a quota is exhausted, an I/O error. Nothing the
    /// operator typed is wrong; the same command succeeds once the cause is removed.
    Environment,
    /// gyrocal broke its own writing protocol (a bug).
    Internal,
}

impl RunError {
    /// The kind of error. An I/O error is [`RunErrorKind::Input`] when it says the path is
    /// wrong (not found, permission denied, read-only file system, not a directory, ...) and
    /// [`RunErrorKind::Environment`] otherwise (a full disk, an exhausted quota, an I/O error).
    pub fn kind(&self) -> RunErrorKind {
        match self {
            RunError::Io { source, .. } => io_kind(source),
            RunError::Locked { .. } => RunErrorKind::Busy,
            RunError::Protocol { .. } => RunErrorKind::Internal,
            RunError::NotEmpty { .. }
            | RunError::TooLarge { .. }
            | RunError::Csv { .. }
            | RunError::Json { .. }
            | RunError::Inconsistent { .. }
            | RunError::PlanChanged { .. }
            | RunError::NotARun { .. }
            | RunError::AlreadyComplete { .. } => RunErrorKind::Input,
        }
    }
}

/// Whose fault an I/O error is (see [`RunError::kind`]).
pub(super) fn io_kind(e: &std::io::Error) -> RunErrorKind {
    use std::io::ErrorKind as K;
    match e.kind() {
        K::NotFound
        | K::PermissionDenied
        | K::AlreadyExists
        | K::InvalidInput
        | K::InvalidData
        | K::NotADirectory
        | K::IsADirectory
        | K::DirectoryNotEmpty
        | K::ReadOnlyFilesystem
        | K::InvalidFilename
        | K::NotSeekable => RunErrorKind::Input,
        _ => RunErrorKind::Environment,
    }
}

/// A data file [`open_regular`] refused or could not open, as a run-directory error naming it.
pub(super) fn opened(e: crate::open::OpenError) -> RunError {
    match e {
        crate::open::OpenError::NotRegular { path, what } => RunError::Inconsistent {
            path,
            message: format!(
                "not a regular file (it is {what}); a run directory's files are regular files"
            ),
        },
        crate::open::OpenError::Io { path, source } => RunError::Io {
            path,
            action: "read",
            source,
        },
    }
}

pub(super) fn io(path: &Path, action: &'static str) -> impl FnOnce(std::io::Error) -> RunError {
    let path = path.to_path_buf();
    move |source| RunError::Io {
        path,
        action,
        source,
    }
}
