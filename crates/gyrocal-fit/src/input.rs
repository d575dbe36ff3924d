//! Reading a data set from CSV.
//!
//! The format: a header line, then one row per rate. The columns `rate_dps` (°/s) and `volts`
//! (V) are required and found by name (case-insensitive, any order); `volts_std` (V, the standard
//! deviation of the readings) and `n` (number of readings averaged) are optional and enable
//! weighting; other columns are ignored. Lines starting with `#` are comments. Empty
//! `volts_std`/`n` cells mean "not given".
//!
//! This module parses from any [`Read`]; it never opens files. Errors name the source (the name
//! the caller passes, usually the file name) and the line. A column name that appears twice
//! (case-insensitively) is an error naming both positions. The input is read whole, up to
//! [`MAX_INPUT_BYTES`] (64 MiB, several hundred thousand rows; a calibration's steps CSV is a
//! few kilobytes): a larger or endless input (`/dev/zero`) is an error after reading at most
//! that much, never a memory exhaustion.

use std::io::Read;

use crate::data::{Dataset, Point};

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

impl InputError {
    /// The line the error refers to.
    pub fn line(&self) -> u64 {
        match self {
            InputError::NoHeader { .. } | InputError::TooLarge { .. } => 1,
            InputError::MissingColumn { line, .. }
            | InputError::DuplicateColumn { line, .. }
            | InputError::BadValue { line, .. }
            | InputError::Csv { line, .. } => *line,
        }
    }
}

/// Parses a CSV data set from `reader`; `source` names it in errors and in
/// [`Dataset::source`].
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
    let file = source.to_string();
    // The csv reader's own line count skips comment lines after the header, so lines are
    // computed from byte offsets over the whole input (calibration files are small; the cap
    // keeps a wrong or endless file from exhausting memory).
    let mut bytes = Vec::new();
    reader
        .take(MAX_INPUT_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| InputError::Csv {
            file: file.clone(),
            line: 1,
            message: format!("cannot read: {e}"),
        })?;
    if bytes.len() as u64 > MAX_INPUT_BYTES {
        return Err(InputError::TooLarge {
            file,
            cap: MAX_INPUT_BYTES,
        });
    }
    let newlines: Vec<u64> = bytes
        .iter()
        .enumerate()
        .filter(|(_, b)| **b == b'\n')
        .map(|(i, _)| i as u64)
        .collect();
    // A record's position is where the reader started looking for it, which may be a comment
    // or blank line before it: skip those to reach the record's own line.
    let line_of = |pos: &csv::Position| -> u64 {
        let mut line = newlines.partition_point(|&nl| nl < pos.byte());
        loop {
            let start = if line == 0 {
                0
            } else {
                newlines[line - 1] as usize + 1
            };
            let end = newlines.get(line).map_or(bytes.len(), |&nl| nl as usize);
            let text = bytes.get(start..end).unwrap_or(&[]);
            let skip = text.first() == Some(&b'#') || text.iter().all(u8::is_ascii_whitespace);
            if !skip || line >= newlines.len() {
                return line as u64 + 1;
            }
            line += 1;
        }
    };
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .comment(Some(b'#'))
        .trim(csv::Trim::All)
        .flexible(false)
        .from_reader(bytes.as_slice());
    let csv_err = |e: csv::Error, fallback_line: u64| {
        let line = e.position().map_or(fallback_line, line_of);
        let message = match e.kind() {
            csv::ErrorKind::UnequalLengths {
                expected_len, len, ..
            } => {
                format!("expected {expected_len} fields like the header, found {len}")
            }
            csv::ErrorKind::Utf8 { .. } => "not valid UTF-8".to_string(),
            _ => e.to_string(),
        };
        InputError::Csv {
            file: file.clone(),
            line,
            message,
        }
    };
    let headers = rdr.headers().map_err(|e| csv_err(e, 1))?.clone();
    if headers.is_empty() || (headers.len() == 1 && headers[0].is_empty()) {
        return Err(InputError::NoHeader { file });
    }
    let header_line = headers.position().map_or(1, line_of);
    for (j, name) in headers.iter().enumerate() {
        if name.is_empty() {
            continue;
        }
        if let Some(i) = headers
            .iter()
            .take(j)
            .position(|h| h.eq_ignore_ascii_case(name))
        {
            return Err(InputError::DuplicateColumn {
                file,
                line: header_line,
                name: name.to_string(),
                first: i + 1,
                second: j + 1,
            });
        }
    }
    let find = |name: &str| headers.iter().position(|h| h.eq_ignore_ascii_case(name));
    let found = headers.iter().collect::<Vec<_>>().join(", ");
    let missing = |column| InputError::MissingColumn {
        file: file.clone(),
        line: header_line,
        column,
        found: found.clone(),
    };
    let rate_col = find("rate_dps").ok_or_else(|| missing("rate_dps"))?;
    let volts_col = find("volts").ok_or_else(|| missing("volts"))?;
    let std_col = find("volts_std");
    let n_col = find("n");

    let mut points = Vec::new();
    let mut record = csv::StringRecord::new();
    let mut last_line = header_line;
    loop {
        match rdr.read_record(&mut record) {
            Ok(false) => break,
            Ok(true) => {}
            Err(e) => return Err(csv_err(e, last_line + 1)),
        }
        let line = record.position().map_or(last_line + 1, line_of);
        last_line = line;
        // A row of empty cells (e.g. a trailing ",,") is skipped like a blank line.
        if record.iter().all(str::is_empty) {
            continue;
        }
        let bad = |column: &'static str, value: &str, reason: &'static str| InputError::BadValue {
            file: file.clone(),
            line,
            column,
            value: value.to_string(),
            reason,
        };
        let number = |col: usize, column: &'static str| -> Result<f64, InputError> {
            let text = record.get(col).unwrap_or("");
            if text.is_empty() {
                return Err(bad(column, text, "missing value"));
            }
            let v: f64 = text
                .parse()
                .map_err(|_| bad(column, text, "not a number"))?;
            if !v.is_finite() {
                return Err(bad(column, text, "not a finite number"));
            }
            Ok(v)
        };
        let rate_dps = number(rate_col, "rate_dps")?;
        let volts = number(volts_col, "volts")?;
        let volts_std = match std_col {
            Some(c) if !record.get(c).unwrap_or("").is_empty() => {
                let s = number(c, "volts_std")?;
                if s < 0.0 {
                    return Err(bad("volts_std", record.get(c).unwrap_or(""), "negative"));
                }
                Some(s)
            }
            _ => None,
        };
        let n = match n_col {
            Some(c) if !record.get(c).unwrap_or("").is_empty() => {
                let text = record.get(c).unwrap_or("");
                let n: u64 = text
                    .parse()
                    .map_err(|_| bad("n", text, "not a positive whole number"))?;
                if n == 0 {
                    return Err(bad("n", text, "not a positive whole number"));
                }
                Some(n)
            }
            _ => None,
        };
        points.push(Point {
            rate_dps,
            volts,
            volts_std,
            n,
            line: Some(line),
        });
    }
    Ok(Dataset {
        source: Some(file),
        points,
    })
}
