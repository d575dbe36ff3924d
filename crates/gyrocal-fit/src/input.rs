//! Reading a data set from CSV.
//!
//! The format: a header line, then one row per rate. The columns `rate_dps` (°/s) and `volts`
//! (V) are required and found by name (case-insensitive, any order); `volts_std` (V, the standard
//! deviation of the readings) and `n` (number of readings averaged) are optional and enable
//! weighting; other columns are ignored. Lines starting with `#` are comments. Empty
//! `volts_std`/`n` cells mean "not given".
//!
//! The text is read by `gyrocal-csv`'s chunked reader, the one CSV reader of `gyrocal fit`,
//! `gyrocal report` and `gyrocal allan` (blocks parsed in parallel into typed columns, the
//! numbers straight from the bytes, no allocation per row): lines are bounded ([`MAX_LINE_BYTES`]: a file without newlines is
//! refused after reading that much, before or after a valid header), a UTF-8 byte-order mark
//! (Excel's) is skipped, every error names the source (the name the caller passes, usually the
//! file name) and the line, counted over every line (comments and blank lines included). A
//! column name that appears twice (case-insensitively) is an error naming both positions.
//! [`read_csv`] and [`read_columns`] open a path, a regular file only (a named pipe or a
//! device is refused before anything is read); [`parse_csv`] and [`parse_columns`] parse any
//! [`Read`].
//!
//! [`parse_csv`] keeps every row as a [`Point`] and reads at most [`MAX_INPUT_BYTES`] (64 MiB,
//! several hundred thousand rows; a calibration's steps CSV is a few kilobytes);
//! [`parse_columns`] keeps only the columns and reads up to [`MAX_ROWS`] rows; [`read_dataset`]
//! (`gyrocal report`'s bare CSV) keeps every row as a [`Point`], and more columns if asked,
//! up to [`MAX_ROWS`] rows whatever the file's size.

use std::io::Read;
use std::path::Path;

use gyrocal_csv::{Cell, Chunk, ChunkedReader, Header, Problem, Spec};

use crate::data::{Columns, Dataset, Point};

/// The longest line accepted: 1 MiB (`gyrocal_csv::MAX_LINE_BYTES`). A longer one (an endless
/// input without newlines, a binary file) is refused with [`InputError::LineTooLong`] after
/// reading at most that much.
pub const MAX_LINE_BYTES: usize = gyrocal_csv::MAX_LINE_BYTES;

/// The most data rows [`parse_columns`] reads: 2²⁵ = 33 554 432 (about 1 GB of CSV; the columns
/// take 16 bytes a row, 24 with `volts_std`). More is refused with [`InputError::TooManyRows`],
/// so an endless stream of valid rows ends in bounded memory and time.
pub const MAX_ROWS: u64 = 1 << 25;

/// The most bytes [`parse_csv`] reads: 64 MiB. A larger input is refused with
/// [`InputError::TooLarge`].
pub const MAX_INPUT_BYTES: u64 = 64 * 1024 * 1024;

/// Why a CSV input could not be read. Every variant names the source; most name the line.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InputError {
    /// The input is empty or has only comments: no header.
    #[error("{file}: line 1: no header line (expected columns rate_dps, volts)")]
    NoHeader {
        /// Source name.
        file: String,
    },
    /// A required column is missing from the header.
    #[error("{file}: line {line}: the header has no `{column}` column (columns: {found})")]
    MissingColumn {
        /// Source name.
        file: String,
        /// Line of the header.
        line: u64,
        /// The missing column.
        column: &'static str,
        /// The columns that are there, comma-separated.
        found: String,
    },
    /// Two columns have the same name (compared case-insensitively, as columns are found).
    #[error(
        "{file}: line {line}: the header names column `{name}` twice (columns {first} and {second}); which one is meant is ambiguous"
    )]
    DuplicateColumn {
        /// Source name.
        file: String,
        /// Line of the header.
        line: u64,
        /// The name as written the second time.
        name: String,
        /// 1-based position of the first column of that name.
        first: usize,
        /// 1-based position of the second.
        second: usize,
    },
    /// The input is larger than [`MAX_INPUT_BYTES`] (or endless).
    #[error(
        "{file}: larger than the {} MiB limit for a data file (a steps CSV is a few kilobytes); is it the right file?",
        cap / (1024 * 1024)
    )]
    TooLarge {
        /// Source name.
        file: String,
        /// The limit, bytes.
        cap: u64,
    },
    /// A line is longer than [`MAX_LINE_BYTES`] (or the input is endless without newlines).
    #[error(
        "{file}: line {line}: longer than the {} KiB limit for a line; is it a CSV data file?",
        cap / 1024
    )]
    LineTooLong {
        /// Source name.
        file: String,
        /// The line.
        line: u64,
        /// The limit, bytes.
        cap: usize,
    },
    /// More data rows than the limit ([`MAX_ROWS`] for `gyrocal fit`).
    #[error(
        "{file}: line {line}: more than {cap} data rows, the limit that keeps memory bounded; average the samples per step or split the file"
    )]
    TooManyRows {
        /// Source name.
        file: String,
        /// The first line over the limit.
        line: u64,
        /// The limit, rows.
        cap: u64,
    },
    /// Memory for the columns could not be allocated (e.g. under `ulimit -v`).
    #[error(
        "{file}: line {line}: out of memory after {rows} data rows; average the samples per step, split the file or allow more memory"
    )]
    OutOfMemory {
        /// Source name.
        file: String,
        /// The line being read.
        line: u64,
        /// Rows read.
        rows: u64,
    },
    /// A cell is not a valid value.
    #[error("{file}: line {line}: column `{column}`: {reason}: `{value}`")]
    BadValue {
        /// Source name.
        file: String,
        /// Line of the row.
        line: u64,
        /// Column name.
        column: &'static str,
        /// The cell's text.
        value: String,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// The file could not be opened: missing, not a regular file (a named pipe, a device), or
    /// not readable. The message names the file.
    #[error("{message}")]
    Open {
        /// Source name.
        file: String,
        /// What is wrong, naming the file.
        message: String,
    },
    /// The CSV itself is malformed (e.g. a row with a different number of fields) or could not
    /// be read.
    #[error("{file}: line {line}: {message}")]
    Csv {
        /// Source name.
        file: String,
        /// Line where the problem was detected.
        line: u64,
        /// The reader's description.
        message: String,
    },
}

/// What kind of problem an [`InputError`] is, for callers that branch on it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum InputErrorKind {
    /// The file could not be opened (missing, not a regular file, not readable).
    Open,
    /// The input is too large, a line too long, too many rows, or memory ran out: a limit.
    Limit,
    /// The header: missing, a required column absent, a column named twice.
    Header,
    /// A cell is not a valid value.
    Value,
    /// The CSV is malformed (a row with another number of fields, not UTF-8) or unreadable.
    Csv,
}

impl InputError {
    /// What kind of problem this is.
    pub fn kind(&self) -> InputErrorKind {
        match self {
            InputError::Open { .. } => InputErrorKind::Open,
            InputError::TooLarge { .. }
            | InputError::LineTooLong { .. }
            | InputError::TooManyRows { .. }
            | InputError::OutOfMemory { .. } => InputErrorKind::Limit,
            InputError::NoHeader { .. }
            | InputError::MissingColumn { .. }
            | InputError::DuplicateColumn { .. } => InputErrorKind::Header,
            InputError::BadValue { .. } => InputErrorKind::Value,
            InputError::Csv { .. } => InputErrorKind::Csv,
        }
    }

    /// The line the error refers to.
    pub fn line(&self) -> u64 {
        match self {
            InputError::NoHeader { .. } | InputError::TooLarge { .. } | InputError::Open { .. } => {
                1
            }
            InputError::MissingColumn { line, .. }
            | InputError::DuplicateColumn { line, .. }
            | InputError::BadValue { line, .. }
            | InputError::LineTooLong { line, .. }
            | InputError::TooManyRows { line, .. }
            | InputError::OutOfMemory { line, .. }
            | InputError::Csv { line, .. } => *line,
        }
    }
}

/// The error of `gyrocal-csv`, as this module's.
fn from_csv(e: gyrocal_csv::Error) -> InputError {
    use gyrocal_csv::Error as E;
    match e {
        E::NoHeader { file } => InputError::NoHeader { file },
        E::LineTooLong { file, line, cap } => InputError::LineTooLong { file, line, cap },
        E::TooLarge { file, cap } => InputError::TooLarge { file, cap },
        E::DuplicateColumn {
            file,
            line,
            name,
            first,
            second,
        } => InputError::DuplicateColumn {
            file,
            line,
            name,
            first,
            second,
        },
        E::Value {
            file,
            line,
            column,
            text,
            problem,
        } => InputError::BadValue {
            file,
            line,
            column: ["rate_dps", "volts", "volts_std", "n"]
                .into_iter()
                .find(|c| c.eq_ignore_ascii_case(&column))
                .unwrap_or("rate_dps"),
            value: text,
            reason: match problem {
                Problem::Empty => "missing value",
                Problem::NotANumber => "not a number",
                Problem::NotFinite(_) => "not a finite number",
                Problem::Negative => "negative",
                Problem::NotACount => "not a positive whole number",
            },
        },
        e @ (E::NotFound { .. } | E::NotAFile { .. } | E::Open { .. }) => InputError::Open {
            file: e.file().to_string(),
            message: e.to_string(),
        },
        e => InputError::Csv {
            file: e.file().to_string(),
            line: e.line().unwrap_or(1),
            message: e.detail(),
        },
    }
}

/// Where the columns are, once the header is read.
struct Cols {
    rate: usize,
    volts: usize,
    std: Option<usize>,
    n: Option<usize>,
}

impl Cols {
    fn of(header: &Header, file: &str) -> Result<Cols, InputError> {
        let missing = |column| InputError::MissingColumn {
            file: file.to_string(),
            line: header.line(),
            column,
            found: header.joined(),
        };
        Ok(Cols {
            rate: header.find("rate_dps").ok_or_else(|| missing("rate_dps"))?,
            volts: header.find("volts").ok_or_else(|| missing("volts"))?,
            std: header.find("volts_std"),
            n: header.find("n"),
        })
    }

    /// The typed columns: rate, volts, then `volts_std` (≥ 0 or empty) and `n` (a count or
    /// empty) when present, then `extra` (any number, NaN otherwise); rows of empty cells (a
    /// trailing `,,`) skipped like blank lines. Cells are checked in that order.
    fn spec(&self, extra: &[Option<usize>]) -> Spec {
        let mut spec = Spec::new()
            .column(self.rate, Cell::Number)
            .column(self.volts, Cell::Number);
        if let Some(c) = self.std {
            spec = spec.column(c, Cell::OptionalNonNegative);
        }
        if let Some(c) = self.n {
            spec = spec.column(c, Cell::OptionalCount);
        }
        for c in extra.iter().flatten() {
            spec = spec.column(*c, Cell::Lenient);
        }
        spec.skip_empty_rows()
    }

    /// The spec's column of `extra[j]`.
    fn extra_column(&self, j: usize) -> usize {
        2 + usize::from(self.std.is_some()) + usize::from(self.n.is_some()) + j
    }

    /// Row `i` of a chunk read with [`Cols::spec`].
    fn point(&self, chunk: &Chunk, i: usize) -> Point {
        let k_std = 2;
        let k_n = 2 + usize::from(self.std.is_some());
        Point {
            rate_dps: chunk.column(0).get(i).copied().unwrap_or(f64::NAN),
            volts: chunk.column(1).get(i).copied().unwrap_or(f64::NAN),
            volts_std: self
                .std
                .and_then(|_| chunk.column(k_std).get(i).copied())
                .filter(|s| !s.is_nan()),
            n: self.n.and_then(|_| chunk.count(k_n, i)),
            line: chunk.lines().get(i).copied(),
        }
    }
}

/// The reader of `reader` (gyrocal's chunked reader), and where its columns are.
fn open_reader<R: Read>(
    reader: R,
    source: &str,
    max_bytes: Option<u64>,
) -> Result<(ChunkedReader<R>, Cols), InputError> {
    let opts = gyrocal_csv::Options {
        max_bytes,
        ..gyrocal_csv::Options::default()
    };
    let rdr = ChunkedReader::new(reader, source, opts).map_err(from_csv)?;
    let cols = Cols::of(rdr.header(), source)?;
    Ok((rdr, cols))
}

/// Reads every data point of `reader` (at most `max_bytes`), handing each to `sink`.
fn read_points<R: Read>(
    reader: R,
    source: &str,
    max_bytes: Option<u64>,
    mut sink: impl FnMut(Point) -> Result<(), InputError>,
) -> Result<(), InputError> {
    let (mut rdr, cols) = open_reader(reader, source, max_bytes)?;
    let spec = cols.spec(&[]);
    while let Some(chunk) = rdr.next_chunk(&spec).map_err(from_csv)? {
        for i in 0..chunk.len() {
            sink(cols.point(chunk, i))?;
        }
    }
    Ok(())
}

/// Opens a data file for reading (a regular file only); errors name it.
fn open(path: &Path) -> Result<std::fs::File, InputError> {
    gyrocal_csv::open(path).map_err(from_csv)
}

/// Reads the CSV data set at `path` ([`parse_csv`]), named in errors as given. A regular file
/// only: a missing file, a named pipe or a device is [`InputError::Open`], before anything is
/// read.
pub fn read_csv(path: &Path) -> Result<Dataset, InputError> {
    parse_csv(open(path)?, &path.display().to_string())
}

/// Reads the CSV data set at `path` into columns ([`parse_columns`]), named in errors as given.
/// A regular file only, as [`read_csv`].
pub fn read_columns(path: &Path) -> Result<Columns, InputError> {
    parse_columns(open(path)?, &path.display().to_string())
}

/// Parses a CSV data set from `reader`; `source` names it in errors and in
/// [`Dataset::source`]. At most [`MAX_INPUT_BYTES`] are read.
///
/// Each [`Point::line`] is the line the row was read from (1-based, comments counted).
///
/// ```
/// let csv = "# a comment\nVolts,Rate_DPS,temp\n0.0088,0,25\n0.3700,1,25\n";
/// let data = gyrocal_fit::input::parse_csv(csv.as_bytes(), "example.csv").unwrap();
/// assert_eq!(data.len(), 2);
/// assert_eq!(data.points[1].rate_dps, 1.0);
/// assert_eq!(data.points[1].line, Some(4));
/// ```
pub fn parse_csv<R: Read>(reader: R, source: &str) -> Result<Dataset, InputError> {
    let mut points = Vec::new();
    read_points(reader, source, Some(MAX_INPUT_BYTES), |p| {
        points.push(p);
        Ok(())
    })?;
    Ok(Dataset {
        source: Some(source.to_string()),
        points,
    })
}

/// Parses a CSV data set from `reader` into column arrays, streaming: the fast path of
/// `gyrocal fit` for files of millions of rows.
///
/// The format and the errors are those of [`parse_csv`] (same reader, same messages, same
/// lines), with these differences: the input's size is not capped; instead there may be at
/// most [`MAX_ROWS`] data rows, and running out of memory is an error
/// ([`InputError::OutOfMemory`]), not an abort. Memory is the columns used (16 bytes a row,
/// 8 more with `volts_std`) and one line; other columns are not stored.
///
/// ```
/// let csv = "# a comment\nVolts,Rate_DPS,temp\n0.0088,0,25\n0.3700,1,25\n";
/// let data = gyrocal_fit::input::parse_columns(csv.as_bytes(), "example.csv").unwrap();
/// assert_eq!(data.rates, [0.0, 1.0]);
/// assert_eq!(data.last_line, Some(4));
/// ```
pub fn parse_columns<R: Read>(reader: R, source: &str) -> Result<Columns, InputError> {
    parse_columns_limited(reader, source, MAX_ROWS)
}

/// [`parse_columns`] with a row limit other than [`MAX_ROWS`].
pub fn parse_columns_limited<R: Read>(
    reader: R,
    source: &str,
    max_rows: u64,
) -> Result<Columns, InputError> {
    let (mut rdr, cols) = open_reader(reader, source, None)?;
    let spec = cols.spec(&[]);
    let mut rates: Vec<f64> = Vec::new();
    let mut volts: Vec<f64> = Vec::new();
    let mut sigmas: Option<Vec<f64>> = cols.std.map(|_| Vec::new());
    let mut last_line = None;
    let mut sink = |p: Point| {
        let line = p.line.unwrap_or(0);
        let rows = rates.len() as u64;
        if rows >= max_rows {
            return Err(InputError::TooManyRows {
                file: source.to_string(),
                line,
                cap: max_rows,
            });
        }
        let room = grow(&mut rates) && grow(&mut volts) && sigmas.as_mut().is_none_or(grow);
        if !room {
            return Err(InputError::OutOfMemory {
                file: source.to_string(),
                line,
                rows,
            });
        }
        rates.push(p.rate_dps);
        volts.push(p.volts);
        if let Some(s) = &mut sigmas {
            s.push(p.sigma().unwrap_or(f64::NAN));
        }
        last_line = Some(line);
        Ok(())
    };
    while let Some(chunk) = rdr.next_chunk(&spec).map_err(from_csv)? {
        for i in 0..chunk.len() {
            sink(cols.point(chunk, i))?;
        }
    }
    Ok(Columns {
        source: Some(source.to_string()),
        rates,
        volts,
        sigmas,
        last_line,
    })
}

/// A data set read by [`read_dataset`], and the extra columns asked for.
#[derive(Debug, Clone, PartialEq)]
pub struct DatasetWithExtras {
    /// The points, as [`parse_csv`] reads them.
    pub data: Dataset,
    /// For each extra column asked for: `None` when the header has no such column, else a
    /// value per point (NaN where the cell holds no number).
    pub extras: Vec<Option<Vec<f64>>>,
}

/// Reads the CSV data set at `path` as [`parse_csv`] does, without its byte limit: at most
/// [`MAX_ROWS`] rows ([`InputError::TooManyRows`]), running out of memory an error
/// ([`InputError::OutOfMemory`]), and in the same pass the columns `extra` (optional, any
/// number, never an error: informative columns such as a report's measured rate). A regular
/// file only, as [`read_csv`].
pub fn read_dataset(path: &Path, extra: &[&str]) -> Result<DatasetWithExtras, InputError> {
    let source = path.display().to_string();
    let (mut rdr, cols) = open_reader(open(path)?, &source, None)?;
    let found: Vec<Option<usize>> = extra.iter().map(|e| rdr.header().find(e)).collect();
    let spec = cols.spec(&found);
    let mut points: Vec<Point> = Vec::new();
    let mut extras: Vec<Option<Vec<f64>>> = found.iter().map(|f| f.map(|_| Vec::new())).collect();
    while let Some(chunk) = rdr.next_chunk(&spec).map_err(from_csv)? {
        for i in 0..chunk.len() {
            let p = cols.point(chunk, i);
            let line = p.line.unwrap_or(0);
            let rows = points.len() as u64;
            if rows >= MAX_ROWS {
                return Err(InputError::TooManyRows {
                    file: source,
                    line,
                    cap: MAX_ROWS,
                });
            }
            if !(grow(&mut points) && extras.iter_mut().flatten().all(grow)) {
                return Err(InputError::OutOfMemory {
                    file: source,
                    line,
                    rows,
                });
            }
            points.push(p);
            let mut j = 0;
            for (e, f) in extras.iter_mut().zip(&found) {
                if let Some(e) = e {
                    let k = cols.extra_column(j);
                    e.push(chunk.column(k).get(i).copied().unwrap_or(f64::NAN));
                }
                j += usize::from(f.is_some());
            }
        }
    }
    Ok(DatasetWithExtras {
        data: Dataset {
            source: Some(source),
            points,
        },
        extras,
    })
}

fn grow<T>(v: &mut Vec<T>) -> bool {
    v.len() < v.capacity() || v.try_reserve(v.len().max(1 << 16)).is_ok()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn columns_match_the_row_parser() {
        let csv = "# c\n\nrate_dps, Volts ,volts_std,n,x\r\n-1,-0.35,1e-4,10,a\n# mid\n,,,,\n0,0.0088,,,b\n\"2\",0.73,2e-4,,c";
        let rows = parse_csv(csv.as_bytes(), "f.csv").unwrap();
        let cols = parse_columns(csv.as_bytes(), "f.csv").unwrap();
        assert_eq!(cols.rates, rows.rates());
        assert_eq!(cols.volts, rows.volts());
        assert_eq!(cols.last_line, rows.last_line());
        let s = cols.sigmas.unwrap();
        assert_eq!(s[0], 1e-4 / 10f64.sqrt());
        assert!(s[1].is_nan());
        assert_eq!(s[2], 2e-4);
    }

    #[test]
    fn errors_match_the_row_parser() {
        for csv in [
            "",
            "# only\n",
            "rate,volts\n1,2\n",
            "rate_dps,volts,VOLTS\n1,2,3\n",
            "rate_dps,volts\n# c\n1,2\n2,x\n",
            "rate_dps,volts\n1,2\n3\n",
            "rate_dps,volts\n1,nan\n",
            "rate_dps,volts,volts_std\n1,2,-1\n",
            "rate_dps,volts,n\n1,2,0\n",
            "rate_dps,volts\n1,\n",
        ] {
            let a = parse_csv(csv.as_bytes(), "f.csv").unwrap_err();
            let b = parse_columns(csv.as_bytes(), "f.csv").unwrap_err();
            assert_eq!(a.to_string(), b.to_string(), "{csv:?}");
        }
    }

    #[test]
    fn kinds_sort_the_errors() {
        let kind = |csv: &str| parse_csv(csv.as_bytes(), "k.csv").unwrap_err().kind();
        assert_eq!(kind(""), InputErrorKind::Header);
        assert_eq!(kind("rate,volts\n"), InputErrorKind::Header);
        assert_eq!(kind("rate_dps,volts\n1,x\n"), InputErrorKind::Value);
        assert_eq!(kind("rate_dps,volts\n1\n"), InputErrorKind::Csv);
        let e = read_csv(Path::new("/nonexistent/k.csv")).unwrap_err();
        assert_eq!(e.kind(), InputErrorKind::Open);
        assert_eq!(
            e.to_string(),
            "/nonexistent/k.csv: cannot open: no such file"
        );
    }

    #[test]
    fn a_byte_order_mark_is_not_part_of_the_first_column() {
        // Excel's "CSV UTF-8" starts with EF BB BF
        let csv = "\u{feff}rate_dps,volts\n0,0.0088\n1,0.37\n";
        let rows = parse_csv(csv.as_bytes(), "excel.csv").unwrap();
        let cols = parse_columns(csv.as_bytes(), "excel.csv").unwrap();
        assert_eq!(rows.rates(), [0.0, 1.0]);
        assert_eq!(cols.rates, [0.0, 1.0]);
    }

    #[test]
    fn endless_inputs_end_in_bounded_memory() {
        let zeros = std::io::repeat(0).take(10 * MAX_LINE_BYTES as u64);
        let e = parse_columns(zeros, "/dev/zero").unwrap_err();
        assert!(matches!(e, InputError::LineTooLong { line: 1, .. }), "{e}");
        // after a valid header and a row, in both parsers
        let after = || (&b"rate_dps,volts\n0,1\n"[..]).chain(std::io::repeat(b'7'));
        for e in [
            parse_columns(after(), "big.csv").unwrap_err(),
            parse_csv(after(), "big.csv").unwrap_err(),
        ] {
            assert_eq!(
                e.to_string(),
                "big.csv: line 3: longer than the 1024 KiB limit for a line; is it a CSV data file?"
            );
        }
        let text = format!("rate_dps,volts\n{}", "1,2\n".repeat(20));
        let e = parse_columns_limited(text.as_bytes(), "rows.csv", 10).unwrap_err();
        assert_eq!(
            e.to_string(),
            "rows.csv: line 12: more than 10 data rows, the limit that keeps memory bounded; average the samples per step or split the file"
        );
    }
}
