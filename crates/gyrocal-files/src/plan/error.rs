//! What can be wrong with a plan, and where: [`PlanError`] (with its [`PlanErrorKind`]) and
//! the [`Location`] every error carries (the file, and the line and column when known).

use std::fmt;
use std::path::{Path, PathBuf};

use super::source::line_col;

/// Where in a plan source an error is: the file (or another origin such as a manifest) and,
/// when known, the 1-based line and column.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Location {
    /// The file the plan came from (or a label such as `manifest.json`).
    pub file: PathBuf,
    /// 1-based line, when the error could be placed.
    pub line: Option<u32>,
    /// 1-based column (in characters), when the error could be placed.
    pub column: Option<u32>,
}

impl Location {
    /// The place of byte `offset` of `src`, the text of `file` (line and column 1-based;
    /// without an offset, the file alone).
    pub(crate) fn in_text(file: &Path, src: &str, offset: Option<usize>) -> Location {
        let (line, column) = match offset {
            Some(o) => {
                let (l, c) = line_col(src, o);
                (Some(l), Some(c))
            }
            None => (None, None),
        };
        Location {
            file: file.to_path_buf(),
            line,
            column,
        }
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if let Some(line) = self.line {
            write!(f, ":{line}")?;
            if let Some(column) = self.column {
                write!(f, ":{column}")?;
            }
        }
        Ok(())
    }
}

/// Everything that can be wrong with a plan. Every variant names the file; the TOML variants
/// also the line, the column and the section or key.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// The file could not be read (or is not UTF-8 text).
    #[error("{}: cannot read the {document}: {source}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// What the file was to be: `plan` or `acceptance file`.
        document: &'static str,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is larger than [`MAX_PLAN_BYTES`](super::MAX_PLAN_BYTES) (or endless).
    #[error(
        "{}: larger than the {} KiB limit for {} {document} ({} {document} is a few kilobytes); is it the right file?",
        path.display(),
        cap / 1024,
        article(document),
        article(document)
    )]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// What the file was to be: `plan` or `acceptance file`.
        document: &'static str,
        /// The limit, bytes.
        cap: u64,
    },
    /// TOML syntax error, unknown or missing section, unknown key (stage 1).
    #[error("{location}: {}{message}", section.as_ref().map(|s| format!("[{s}] ")).unwrap_or_default())]
    Syntax {
        /// Where.
        location: Location,
        /// The section (`plan`, `table`, `dmm`, `simulation`) the error is in, when known.
        section: Option<String>,
        /// What `toml`/serde said (names the key for unknown and missing keys).
        message: String,
    },
    /// A missing key or a value of the wrong kind (stage 1), or a value that parses but is not
    /// acceptable (stage 2).
    #[error("{location}: [{section}] {key} {message}")]
    Invalid {
        /// Where (the offending value, when the file had it).
        location: Location,
        /// The section (`plan`, `table`, `dmm`, `simulation`).
        section: String,
        /// The key, e.g. `acceleration_dps2` or `rates_dps[3]`.
        key: String,
        /// What is wrong, e.g. `must be > 0 (got 0)`.
        message: String,
    },
}

/// The kind of a [`PlanError`], for callers that act on it (exit codes, retries).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PlanErrorKind {
    /// The file could not be read ([`PlanError::Read`]).
    Read,
    /// The file is too large ([`PlanError::TooLarge`]).
    TooLarge,
    /// TOML syntax, an unknown or missing section or key ([`PlanError::Syntax`]).
    Syntax,
    /// A value that is not acceptable ([`PlanError::Invalid`]).
    Invalid,
}

/// `a` or `an` before a document's name.
fn article(word: &str) -> &'static str {
    if word.starts_with(['a', 'e', 'i', 'o', 'u']) {
        "an"
    } else {
        "a"
    }
}

/// The plan document's name in read errors.
pub(super) const PLAN_DOCUMENT: &str = "plan";

/// A standalone acceptance file's name in read errors.
pub(super) const ACCEPTANCE_DOCUMENT: &str = "acceptance file";

impl PlanError {
    /// What kind of error this is.
    pub fn kind(&self) -> PlanErrorKind {
        match self {
            PlanError::Read { .. } => PlanErrorKind::Read,
            PlanError::TooLarge { .. } => PlanErrorKind::TooLarge,
            PlanError::Syntax { .. } => PlanErrorKind::Syntax,
            PlanError::Invalid { .. } => PlanErrorKind::Invalid,
        }
    }

    /// The location of the error, when it has one (not for [`PlanError::Read`] and
    /// [`PlanError::TooLarge`]).
    pub fn location(&self) -> Option<&Location> {
        match self {
            PlanError::Read { .. } | PlanError::TooLarge { .. } => None,
            PlanError::Syntax { location, .. } | PlanError::Invalid { location, .. } => {
                Some(location)
            }
        }
    }
}
