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

use crate::data::{Columns, Dataset, Point};

/// The longest line [`parse_columns`] accepts: 1 MiB. A longer one (an endless input without
/// newlines such as `/dev/zero`, a binary file) is refused with [`InputError::LineTooLong`]
/// after reading at most that much.
pub const MAX_LINE_BYTES: usize = 1024 * 1024;

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
            | InputError::LineTooLong { line, .. }
            | InputError::TooManyRows { line, .. }
            | InputError::OutOfMemory { line, .. }
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

/// Parses a CSV data set from `reader` into column arrays, streaming: the fast path of
/// `gyrocal fit` for files of millions of rows.
///
/// The format and the errors are those of [`parse_csv`] (same messages, same lines), with
/// these differences: the input is read in 1 MiB chunks and never held whole, so its size is
/// not capped; instead a line may not exceed [`MAX_LINE_BYTES`] and there may be at most
/// [`MAX_ROWS`] data rows, and running out of memory is an error
/// ([`InputError::OutOfMemory`]), not an abort. Memory is the columns used (16 bytes a row,
/// 8 more with `volts_std`); other columns are skipped without being stored. Quoted fields
/// are unquoted, but a quoted field may not contain a comma or a line break (data files hold
/// numbers). Cells are parsed from bytes with the standard library's float parser, which is
/// the Eisel–Lemire/fast-float algorithm (Rust ≥ 1.55), so no extra crate is needed.
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
    mut reader: R,
    source: &str,
    max_rows: u64,
) -> Result<Columns, InputError> {
    let file = source.to_string();
    let mut parser = ColumnParser {
        file: &file,
        max_rows,
        header: None,
        rates: Vec::new(),
        volts: Vec::new(),
        sigmas: None,
        last_line: None,
    };
    let mut buf = vec![0_u8; MAX_LINE_BYTES];
    let mut filled = 0_usize;
    let mut line = 0_u64;
    loop {
        if filled == buf.len() {
            return Err(InputError::LineTooLong {
                file,
                line: line + 1,
                cap: MAX_LINE_BYTES,
            });
        }
        let got = match reader.read(&mut buf[filled..]) {
            Ok(k) => k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => {
                return Err(InputError::Csv {
                    file,
                    line: line + 1,
                    message: format!("cannot read: {e}"),
                });
            }
        };
        let eof = got == 0;
        let scan_from = filled;
        filled += got;
        let mut start = 0_usize;
        let mut from = scan_from;
        while let Some(k) = buf[from..filled].iter().position(|&b| b == b'\n') {
            let end = from + k;
            line += 1;
            parser.line(&buf[start..end], line)?;
            start = end + 1;
            from = start;
        }
        if eof {
            if start < filled {
                line += 1;
                parser.line(&buf[start..filled], line)?;
            }
            break;
        }
        buf.copy_within(start..filled, 0);
        filled -= start;
    }
    if parser.header.is_none() {
        return Err(InputError::NoHeader { file });
    }
    let ColumnParser {
        rates,
        volts,
        sigmas,
        last_line,
        ..
    } = parser;
    Ok(Columns {
        source: Some(file),
        rates,
        volts,
        sigmas,
        last_line,
    })
}

/// Where the columns are, once the header is read.
struct Header {
    fields: usize,
    rate: usize,
    volts: usize,
    std: Option<usize>,
    n: Option<usize>,
}

struct ColumnParser<'a> {
    file: &'a str,
    max_rows: u64,
    header: Option<Header>,
    rates: Vec<f64>,
    volts: Vec<f64>,
    sigmas: Option<Vec<f64>>,
    last_line: Option<u64>,
}

/// A cell: surrounding whitespace trimmed, surrounding quotes removed.
fn cell(raw: &[u8]) -> &[u8] {
    let t = raw.trim_ascii();
    if t.len() >= 2 && t[0] == b'"' && t[t.len() - 1] == b'"' {
        t[1..t.len() - 1].trim_ascii()
    } else {
        t
    }
}

fn grow<T>(v: &mut Vec<T>) -> bool {
    v.len() < v.capacity() || v.try_reserve(v.len().max(1 << 16)).is_ok()
}

impl ColumnParser<'_> {
    fn line(&mut self, raw: &[u8], line: u64) -> Result<(), InputError> {
        let raw = raw.strip_suffix(b"\r").unwrap_or(raw);
        if raw.is_empty() || raw[0] == b'#' {
            return Ok(());
        }
        let Some(h) = &self.header else {
            return self.header(raw, line);
        };
        let file = self.file;
        let (mut rate, mut volts, mut std, mut n) = (None, None, None, None);
        let mut fields = 0_usize;
        let mut all_empty = true;
        for (j, f) in raw.split(|&b| b == b',').enumerate() {
            fields += 1;
            let c = cell(f);
            all_empty &= c.is_empty();
            if j == h.rate {
                rate = Some(c);
            } else if j == h.volts {
                volts = Some(c);
            } else if Some(j) == h.std {
                std = Some(c);
            } else if Some(j) == h.n {
                n = Some(c);
            }
        }
        if fields != h.fields {
            return Err(InputError::Csv {
                file: file.to_string(),
                line,
                message: format!(
                    "expected {} fields like the header, found {fields}",
                    h.fields
                ),
            });
        }
        // A row of empty cells (e.g. a trailing ",,") is skipped like a blank line.
        if all_empty {
            return Ok(());
        }
        let bad = |column: &'static str, value: &[u8], reason: &'static str| InputError::BadValue {
            file: file.to_string(),
            line,
            column,
            value: String::from_utf8_lossy(value).into_owned(),
            reason,
        };
        let number = |text: Option<&[u8]>, column: &'static str| -> Result<f64, InputError> {
            let text = text.unwrap_or(b"");
            if text.is_empty() {
                return Err(bad(column, text, "missing value"));
            }
            let v: f64 = std::str::from_utf8(text)
                .ok()
                .and_then(|t| t.parse().ok())
                .ok_or_else(|| bad(column, text, "not a number"))?;
            if !v.is_finite() {
                return Err(bad(column, text, "not a finite number"));
            }
            Ok(v)
        };
        let rate_dps = number(rate, "rate_dps")?;
        let volts_v = number(volts, "volts")?;
        let volts_std = match std {
            Some(c) if !c.is_empty() => {
                let s = number(Some(c), "volts_std")?;
                if s < 0.0 {
                    return Err(bad("volts_std", c, "negative"));
                }
                Some(s)
            }
            _ => None,
        };
        let n = match n {
            Some(c) if !c.is_empty() => {
                let v: u64 = std::str::from_utf8(c)
                    .ok()
                    .and_then(|t| t.parse().ok())
                    .filter(|v| *v > 0)
                    .ok_or_else(|| bad("n", c, "not a positive whole number"))?;
                Some(v)
            }
            _ => None,
        };
        if self.rates.len() as u64 >= self.max_rows {
            return Err(InputError::TooManyRows {
                file: file.to_string(),
                line,
                cap: self.max_rows,
            });
        }
        let rows = self.rates.len() as u64;
        let room =
            grow(&mut self.rates) && grow(&mut self.volts) && self.sigmas.as_mut().is_none_or(grow);
        if !room {
            return Err(InputError::OutOfMemory {
                file: file.to_string(),
                line,
                rows,
            });
        }
        self.rates.push(rate_dps);
        self.volts.push(volts_v);
        if let Some(s) = &mut self.sigmas {
            let p = Point {
                rate_dps,
                volts: volts_v,
                volts_std,
                n,
                line: None,
            };
            s.push(p.sigma().unwrap_or(f64::NAN));
        }
        self.last_line = Some(line);
        Ok(())
    }

    fn header(&mut self, raw: &[u8], line: u64) -> Result<(), InputError> {
        let file = self.file;
        let text = std::str::from_utf8(raw).map_err(|_| InputError::Csv {
            file: file.to_string(),
            line,
            message: "not valid UTF-8".to_string(),
        })?;
        let headers: Vec<&str> = text
            .split(',')
            .map(|f| std::str::from_utf8(cell(f.as_bytes())).unwrap_or(""))
            .collect();
        if headers.len() == 1 && headers[0].is_empty() {
            return Err(InputError::NoHeader {
                file: file.to_string(),
            });
        }
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
                    file: file.to_string(),
                    line,
                    name: name.to_string(),
                    first: i + 1,
                    second: j + 1,
                });
            }
        }
        let find = |name: &str| headers.iter().position(|h| h.eq_ignore_ascii_case(name));
        let missing = |column| InputError::MissingColumn {
            file: file.to_string(),
            line,
            column,
            found: headers.join(", "),
        };
        let rate = find("rate_dps").ok_or_else(|| missing("rate_dps"))?;
        let volts = find("volts").ok_or_else(|| missing("volts"))?;
        let std = find("volts_std");
        self.header = Some(Header {
            fields: headers.len(),
            rate,
            volts,
            std,
            n: find("n"),
        });
        if std.is_some() {
            self.sigmas = Some(Vec::new());
        }
        Ok(())
    }
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
    fn endless_inputs_end_in_bounded_memory() {
        let zeros = std::io::repeat(0).take(10 * MAX_LINE_BYTES as u64);
        let e = parse_columns(zeros, "/dev/zero").unwrap_err();
        assert!(matches!(e, InputError::LineTooLong { line: 1, .. }), "{e}");
        let text = format!("rate_dps,volts\n{}", "1,2\n".repeat(20));
        let e = parse_columns_limited(text.as_bytes(), "rows.csv", 10).unwrap_err();
        assert_eq!(
            e.to_string(),
            "rows.csv: line 12: more than 10 data rows, the limit that keeps memory bounded; average the samples per step or split the file"
        );
    }
}
