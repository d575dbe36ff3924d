//! Why an analysis failed, and whose fault it is ([`ErrorKind`]): the CLI exits 2 for bad
//! input and 1 for a failure of the environment without matching messages.

use std::path::PathBuf;

use gyrocal_files::rundir::{RunError, RunErrorKind};

/// Whose fault an analysis error is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorKind {
    /// The input: a missing, unreadable or malformed file, data that cannot be analysed, a
    /// run directory another process holds.
    Input,
    /// The environment: a full disk, a temporary directory that fails halfway.
    Environment,
}

/// Why the drift analysis of a record failed. Every variant names the file (and the line where
/// one is at fault). The messages are those `gyrocal allan` has always printed.
#[derive(Debug, thiserror::Error)]
pub enum DriftError {
    /// A data file for an Allan analysis is missing, garbled or unusable (names the line when one
    /// is at fault).
    #[error("{}{}: {message}", path.display(), line.map(|l| format!(": line {l}")).unwrap_or_default())]
    Data {
        /// The file (or the path given).
        path: PathBuf,
        /// 1-based line, when one line is at fault.
        line: Option<u64>,
        /// What is wrong.
        message: String,
    },
    /// A file could not be read, or a temporary file written.
    #[error("{}: cannot {action}: {source}", path.display())]
    Io {
        /// The file (or the temporary directory).
        path: PathBuf,
        /// What was being done.
        action: &'static str,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The path exists but is neither a directory nor a regular file (a device, a pipe).
    #[error(
        "{}: not a run directory or a regular file (a device or a pipe is not read)",
        path.display()
    )]
    NotAFile {
        /// The path given.
        path: PathBuf,
    },
    /// The run directory could not be read or its result not written.
    #[error(transparent)]
    Run(#[from] RunError),
}

impl DriftError {
    /// Whose fault it is: a file that cannot be read is the input's; a temporary file that
    /// cannot be written, the environment's.
    pub fn kind(&self) -> ErrorKind {
        match self {
            DriftError::Data { .. } | DriftError::NotAFile { .. } => ErrorKind::Input,
            DriftError::Io { action, .. } if *action == "read" => ErrorKind::Input,
            DriftError::Io { .. } => ErrorKind::Environment,
            DriftError::Run(e) => run_kind(e),
        }
    }

    /// True when the error comes from the input (missing, unreadable or malformed files):
    /// `kind() == ErrorKind::Input`, as the report's errors say it.
    pub fn is_input_error(&self) -> bool {
        self.kind() == ErrorKind::Input
    }
}

/// A run directory's error as an analysis error kind (a run another process holds is the
/// input's: give another directory or wait).
pub(crate) fn run_kind(e: &RunError) -> ErrorKind {
    match e.kind() {
        RunErrorKind::Input | RunErrorKind::Busy => ErrorKind::Input,
        _ => ErrorKind::Environment,
    }
}

/// Why [`crate::sweep::fit_run`] failed.
#[derive(Debug, thiserror::Error)]
pub enum FitRunError {
    /// Reading or writing the run directory.
    #[error(transparent)]
    Run(#[from] RunError),
    /// The fit itself (too few points, ...).
    #[error("fit: {0}")]
    Fit(#[from] gyrocal_fit::FitError),
    /// Serialising the analysis.
    #[error("fit result could not be serialised: {0}")]
    Json(String),
}

impl FitRunError {
    /// Whose fault it is: data that cannot determine a line is the input's.
    pub fn kind(&self) -> ErrorKind {
        match self {
            FitRunError::Run(e) => run_kind(e),
            FitRunError::Fit(_) => ErrorKind::Input,
            FitRunError::Json(_) => ErrorKind::Environment,
        }
    }
}

/// Why [`crate::analyse`] failed: the analysis of the run's kind.
#[derive(Debug, thiserror::Error)]
pub enum AnalysisError {
    /// Reading the run directory.
    #[error(transparent)]
    Run(#[from] RunError),
    /// The scale-factor fit of a sweep.
    #[error(transparent)]
    Sweep(#[from] FitRunError),
    /// The Allan analysis of a drift record.
    #[error(transparent)]
    Drift(#[from] DriftError),
    /// The analysis of a temperature series.
    #[error(transparent)]
    Series(#[from] crate::series::SeriesError),
}

impl AnalysisError {
    /// Whose fault it is.
    pub fn kind(&self) -> ErrorKind {
        match self {
            AnalysisError::Run(e) => run_kind(e),
            AnalysisError::Sweep(e) => e.kind(),
            AnalysisError::Drift(e) => e.kind(),
            AnalysisError::Series(e) => e.kind(),
        }
    }
}
