//! Why a CSV file could not be read: [`Error`], every variant naming the file, and
//! [`ErrorKind`] for callers that branch on it.

/// What kind of problem an [`Error`] is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ErrorKind {
    /// The file does not exist.
    NotFound,
    /// The path is a pipe, a device, a directory or a socket.
    NotAFile,
    /// Opening or reading failed (permissions, I/O).
    Read,
    /// A line longer than the limit.
    LineTooLong,
    /// The input is larger than the reader's byte limit.
    TooLarge,
    /// The header is not UTF-8 text.
    NotUtf8,
    /// No header line.
    NoHeader,
    /// Two columns of the same name.
    DuplicateColumn,
    /// A row with another number of fields than the header.
    FieldCount,
    /// A column asked for is not in the header.
    MissingColumn,
    /// A cell of a typed column is not what the column holds (empty, not a number, ...).
    Value,
}

/// What is wrong with a cell of a typed column ([`Error::Value`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Problem {
    /// The cell is empty (a required number).
    Empty,
    /// The cell is not a number.
    NotANumber,
    /// A number, but not finite (`inf`, `NaN`, `1e999`).
    NotFinite(f64),
    /// A negative number where only zero or more is meant.
    Negative,
    /// Not a positive whole number (a count).
    NotACount,
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Problem::Empty => "missing value",
            Problem::NotANumber => "not a number",
            Problem::NotFinite(_) => "not a finite number",
            Problem::Negative => "negative",
            Problem::NotACount => "not a positive whole number",
        })
    }
}

/// Why a CSV file could not be read. Every variant names the file; all but the file-level
/// ones name the line.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// No such file.
    #[error("{file}: cannot open: no such file")]
    NotFound {
        /// The file.
        file: String,
    },
    /// Not a regular file.
    #[error("{file}: {what}, not a regular file: a data file is read only from a regular file")]
    NotAFile {
        /// The file.
        file: String,
        /// What it is: `a named pipe (FIFO)`, `a device`, ...
        what: &'static str,
    },
    /// The file could not be opened.
    #[error("{file}: cannot open: {source}")]
    Open {
        /// The file.
        file: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// Reading failed.
    #[error("{file}: line {line}: cannot read: {source}")]
    Read {
        /// The file.
        file: String,
        /// The line being read.
        line: u64,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A line longer than the limit (or a file without newlines).
    #[error(
        "{file}: line {line}: longer than the {} KiB limit for a line; is it a CSV data file?",
        cap / 1024
    )]
    LineTooLong {
        /// The file.
        file: String,
        /// The line.
        line: u64,
        /// The limit, bytes.
        cap: usize,
    },
    /// More bytes than [`crate::Reader::with_max_bytes`] allows.
    #[error(
        "{file}: larger than the {} MiB limit for a data file; is it the right file?",
        cap / (1024 * 1024)
    )]
    TooLarge {
        /// The file.
        file: String,
        /// The limit, bytes.
        cap: u64,
    },
    /// The header is not UTF-8 text.
    #[error("{file}: line {line}: not valid UTF-8")]
    NotUtf8 {
        /// The file.
        file: String,
        /// The line.
        line: u64,
    },
    /// The input is empty, or only comments and blank lines, or the header names no column.
    #[error("{file}: line 1: no header line")]
    NoHeader {
        /// The file.
        file: String,
    },
    /// Two columns have the same name (compared case-insensitively, as columns are found).
    #[error(
        "{file}: line {line}: the header names column `{name}` twice (columns {first} and {second}); which one is meant is ambiguous"
    )]
    DuplicateColumn {
        /// The file.
        file: String,
        /// The header's line.
        line: u64,
        /// The name as written the second time.
        name: String,
        /// 1-based position of the first column of that name.
        first: usize,
        /// 1-based position of the second.
        second: usize,
    },
    /// A row with another number of fields than the header.
    #[error("{file}: line {line}: expected {expected} fields like the header, found {found}")]
    FieldCount {
        /// The file.
        file: String,
        /// The row's line.
        line: u64,
        /// The header's number of fields.
        expected: usize,
        /// The row's.
        found: usize,
    },
    /// A column asked for is not in the header.
    #[error("{file}: line {line}: the header has no `{name}` column (columns: {found})")]
    MissingColumn {
        /// The file.
        file: String,
        /// The header's line.
        line: u64,
        /// The column asked for.
        name: String,
        /// The header's columns, comma-separated.
        found: String,
    },
    /// A cell of a typed column is not what the column holds.
    #[error("{file}: line {line}: column `{column}`: {problem}: `{text}`")]
    Value {
        /// The file.
        file: String,
        /// The row's line.
        line: u64,
        /// The column's name as the header writes it.
        column: String,
        /// The cell as read (trimmed, unquoted; not UTF-8 shown lossily), at most 200 bytes.
        text: String,
        /// What is wrong with it.
        problem: Problem,
    },
}

impl Error {
    /// What kind of problem this is.
    pub fn kind(&self) -> ErrorKind {
        match self {
            Error::NotFound { .. } => ErrorKind::NotFound,
            Error::NotAFile { .. } => ErrorKind::NotAFile,
            Error::Open { .. } | Error::Read { .. } => ErrorKind::Read,
            Error::LineTooLong { .. } => ErrorKind::LineTooLong,
            Error::TooLarge { .. } => ErrorKind::TooLarge,
            Error::NotUtf8 { .. } => ErrorKind::NotUtf8,
            Error::NoHeader { .. } => ErrorKind::NoHeader,
            Error::DuplicateColumn { .. } => ErrorKind::DuplicateColumn,
            Error::FieldCount { .. } => ErrorKind::FieldCount,
            Error::MissingColumn { .. } => ErrorKind::MissingColumn,
            Error::Value { .. } => ErrorKind::Value,
        }
    }

    /// The file named.
    pub fn file(&self) -> &str {
        match self {
            Error::NotFound { file }
            | Error::NotAFile { file, .. }
            | Error::Open { file, .. }
            | Error::Read { file, .. }
            | Error::LineTooLong { file, .. }
            | Error::TooLarge { file, .. }
            | Error::NotUtf8 { file, .. }
            | Error::NoHeader { file }
            | Error::DuplicateColumn { file, .. }
            | Error::FieldCount { file, .. }
            | Error::MissingColumn { file, .. }
            | Error::Value { file, .. } => file,
        }
    }

    /// The line named, when one is at fault (a missing header is line 1).
    pub fn line(&self) -> Option<u64> {
        match self {
            Error::NotFound { .. }
            | Error::NotAFile { .. }
            | Error::Open { .. }
            | Error::TooLarge { .. } => None,
            Error::NoHeader { .. } => Some(1),
            Error::Read { line, .. }
            | Error::LineTooLong { line, .. }
            | Error::NotUtf8 { line, .. }
            | Error::DuplicateColumn { line, .. }
            | Error::FieldCount { line, .. }
            | Error::MissingColumn { line, .. }
            | Error::Value { line, .. } => Some(*line),
        }
    }

    /// The message without the `file: line N: ` prefix, for callers that put the file and
    /// line in their own error.
    pub fn detail(&self) -> String {
        let full = self.to_string();
        let mut rest = full
            .strip_prefix(self.file())
            .and_then(|r| r.strip_prefix(": "))
            .unwrap_or(&full);
        if let Some(line) = self.line() {
            let prefix = format!("line {line}: ");
            rest = rest.strip_prefix(prefix.as_str()).unwrap_or(rest);
        }
        rest.to_string()
    }
}
