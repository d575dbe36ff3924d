//! Errors of this crate: one enum, each variant with its context, and a [`ErrorKind`] to branch on.

/// What went wrong, without the details (for callers that branch on the category).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[non_exhaustive]
pub enum ErrorKind {
    /// No samples at all.
    Empty,
    /// Fewer samples than the computation needs.
    TooShort,
    /// A sample or a parameter is NaN or infinite.
    NonFinite,
    /// A parameter is out of its domain (sample interval ≤ 0, window shorter than τ0, ...).
    InvalidParameter,
    /// The τ set selects no averaging factor the record supports.
    NoTaus,
    /// Input text could not be parsed, or its time column is not evenly spaced.
    Parse,
    /// Reading the input failed.
    Io,
}

/// An error of gyrocal-allan.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The record holds no sample.
    #[error("the record is empty")]
    Empty,
    /// The record is too short for the computation.
    #[error("{what} needs at least {needed} samples, the record has {got}")]
    TooShort {
        /// The computation that needed more samples.
        what: &'static str,
        /// Samples needed.
        needed: usize,
        /// Samples present.
        got: usize,
    },
    /// Sample `index` (0-based) is NaN or infinite.
    #[error("sample {index} is not finite ({value})")]
    NonFinite {
        /// Index of the first offending sample.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// A parameter is out of its domain.
    #[error("invalid {name}: {value} ({why})")]
    InvalidParameter {
        /// The parameter.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What is required.
        why: &'static str,
    },
    /// The τ set selects no averaging factor for this record.
    #[error("no averaging factor of the τ set fits a record of {n} samples")]
    NoTaus {
        /// Number of rate samples.
        n: usize,
    },
    /// A line of the input could not be parsed.
    #[error("line {line}: {msg}")]
    Parse {
        /// 1-based line number.
        line: usize,
        /// What is wrong with it.
        msg: String,
    },
    /// Reading the input failed.
    #[error("reading the record: {0}")]
    Io(#[from] std::io::Error),
}

impl Error {
    /// The category of this error.
    pub fn kind(&self) -> ErrorKind {
        match self {
            Error::Empty => ErrorKind::Empty,
            Error::TooShort { .. } => ErrorKind::TooShort,
            Error::NonFinite { .. } => ErrorKind::NonFinite,
            Error::InvalidParameter { .. } => ErrorKind::InvalidParameter,
            Error::NoTaus { .. } => ErrorKind::NoTaus,
            Error::Parse { .. } => ErrorKind::Parse,
            Error::Io(_) => ErrorKind::Io,
        }
    }
}

impl From<std::convert::Infallible> for Error {
    fn from(never: std::convert::Infallible) -> Error {
        match never {}
    }
}

/// Result of this crate.
pub type Result<T> = std::result::Result<T, Error>;
