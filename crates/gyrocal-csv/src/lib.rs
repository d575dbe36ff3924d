//! The one CSV reader of gyrocal's data files: `gyrocal fit` (rate, volts tables),
//! `gyrocal report` (a bare steps CSV) and `gyrocal allan` (a drift record or any time series)
//! all read through it, so a file is refused or accepted the same way everywhere.
//!
//! Two ways in, one format, one splitter (`split`), the same errors:
//!
//! * [`ChunkedReader`] (and [`read_columns`], its in-memory form): the data files' reader.
//!   Blocks of 1 MiB parsed in parallel into `f64` columns typed by the caller ([`Spec`],
//!   [`Cell`]), the numbers parsed straight from the bytes, no allocation per row, memory
//!   bounded by the block size whatever the file's length (see its module, `chunked`).
//!   A 10⁷-row `t_s,volts` record (258 MB) takes about 0.6 s of CPU (0.35 s of wall time on
//!   two idle cores), against 1.0 s for the line reader below with the standard library's
//!   parser (`examples/read_record.rs`,
//!   `benches/reader.rs`, `bench/README.md`).
//! * [`Reader`]: the line reader, a [`Row`] at a time, for small files and callers that want
//!   the cells as text.
//!
//! What it guarantees, whatever the file:
//!
//! * **Regular files only** ([`open`]): a named pipe would block the open until a writer comes
//!   (forever, from a shell), a device such as `/dev/zero` never ends. Both are refused before
//!   anything is read, naming the file.
//! * **Bounded lines** ([`MAX_LINE_BYTES`], 1 MiB by default): a line is read into a buffer
//!   that never grows past the limit, so a 3 GB file without a newline is refused after
//!   reading at most the limit (plus the 64 KiB read buffer), before or after a valid header.
//!   The error names the file and the line and never echoes the line.
//! * **A UTF-8 byte-order mark** at the start of the file (Excel writes one) is skipped: the
//!   first column is `rate_dps`, not `\u{feff}rate_dps`.
//! * **Every error names the file and the line** (1-based, counting every line: comments,
//!   blank lines and the header included).
//!
//! The format: lines end with `\n` (a `\r` before it is dropped); lines that are blank or start
//! with `#` are comments; the first other line is the header; every data row has the header's
//! number of fields. A line without quotes is split at its commas; any other line is split with
//! `csv-core` (the `csv` crate's own parser), which gives the same fields for a plain line:
//! quoted fields may hold commas and doubled quotes, but not line breaks (data files
//! hold numbers, and one record per line is what keeps lines, records and memory bounded
//! together). Cells are trimmed of ASCII whitespace and of surrounding quotes. Column names are
//! found case-insensitively; a name given twice is an error naming both positions. A number is
//! what the standard library's `f64` parser accepts (any surrounding whitespace trimmed), to the
//! same bits (`number`).
//!
//! [`Lines`] is the layer below: the bounded, numbered lines of any text format (the free-form
//! record reader of `gyrocal-allan` uses it).

use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

#[cfg(test)]
mod chunk_tests;
mod chunked;
mod error;
mod number;
mod split;

pub use chunked::{Cell, Chunk, ChunkedReader, Columns, Options, Spec, read_columns};
pub use error::{Error, ErrorKind, Problem};
use split::Splitter;

/// The longest line read by default: 1 MiB. Data lines are tens of bytes; a header of
/// thousands of columns still fits.
pub const MAX_LINE_BYTES: usize = 1024 * 1024;

/// The read buffer: 64 KiB.
const READ_BUFFER: usize = 64 * 1024;

/// The UTF-8 byte-order mark.
const BOM: &[u8] = b"\xEF\xBB\xBF";

/// What a path that is not a regular file is.
fn what_it_is(t: &std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt as _;
        if t.is_fifo() {
            return "a named pipe (FIFO)";
        }
        if t.is_char_device() || t.is_block_device() {
            return "a device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if t.is_dir() {
        "a directory"
    } else {
        "not a file"
    }
}

/// Opens a data file for reading: a regular file only. The type is checked before the file
/// is opened (opening a named pipe blocks until a writer comes) and again on the open file
/// (in case the path was replaced in between).
pub fn open(path: &Path) -> Result<File, Error> {
    let file = path.display().to_string();
    let meta = std::fs::metadata(path).map_err(|source| {
        if source.kind() == std::io::ErrorKind::NotFound {
            Error::NotFound { file: file.clone() }
        } else {
            Error::Open {
                file: file.clone(),
                source,
            }
        }
    })?;
    if !meta.is_file() {
        return Err(Error::NotAFile {
            file,
            what: what_it_is(&meta.file_type()),
        });
    }
    let f = File::open(path).map_err(|source| Error::Open {
        file: file.clone(),
        source,
    })?;
    let meta = f.metadata().map_err(|source| Error::Open {
        file: file.clone(),
        source,
    })?;
    if !meta.is_file() {
        return Err(Error::NotAFile {
            file,
            what: what_it_is(&meta.file_type()),
        });
    }
    Ok(f)
}

/// The numbered lines of a text input, each at most a bounded length, a UTF-8 byte-order
/// mark at the start dropped, a `\r` before the `\n` dropped.
pub struct Lines<R> {
    inner: BufReader<R>,
    file: String,
    line: u64,
    buf: Vec<u8>,
    max_line: usize,
    max_bytes: Option<u64>,
    bytes: u64,
    /// The current line's text within `buf` (byte-order mark and `\r` dropped).
    text: std::ops::Range<usize>,
}

impl<R: Read> Lines<R> {
    /// Lines of `reader`; `file` names it in errors.
    pub fn new(reader: R, file: impl Into<String>) -> Lines<R> {
        Lines {
            inner: BufReader::with_capacity(READ_BUFFER, reader),
            file: file.into(),
            line: 0,
            buf: Vec::new(),
            max_line: MAX_LINE_BYTES,
            max_bytes: None,
            bytes: 0,
            text: 0..0,
        }
    }

    /// Another line limit than [`MAX_LINE_BYTES`].
    pub fn with_max_line(mut self, bytes: usize) -> Lines<R> {
        self.max_line = bytes;
        self
    }

    /// Refuse the input ([`Error::TooLarge`]) once more than `bytes` were read.
    pub fn with_max_bytes(mut self, bytes: u64) -> Lines<R> {
        self.max_bytes = Some(bytes);
        self
    }

    /// The name used in errors.
    pub fn file(&self) -> &str {
        &self.file
    }

    /// The number of the last line returned (0 before the first).
    pub fn line_number(&self) -> u64 {
        self.line
    }

    /// The next line and its number, without its terminator; `None` at the end.
    pub fn next_line(&mut self) -> Result<Option<(u64, &[u8])>, Error> {
        Ok(self.advance()?.map(|line| (line, self.current())))
    }

    /// The text of the line [`Lines::advance`] read last.
    fn current(&self) -> &[u8] {
        self.buf.get(self.text.clone()).unwrap_or_default()
    }

    /// Reads the next line; its number, or `None` at the end.
    fn advance(&mut self) -> Result<Option<u64>, Error> {
        self.buf.clear();
        self.text = 0..0;
        let mut any = false;
        loop {
            let available = match self.inner.fill_buf() {
                Ok(b) => b,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(source) => {
                    return Err(Error::Read {
                        file: self.file.clone(),
                        line: self.line + 1,
                        source,
                    });
                }
            };
            if available.is_empty() {
                if !any {
                    return Ok(None);
                }
                break;
            }
            any = true;
            let newline = available.iter().position(|&b| b == b'\n');
            let take = newline.unwrap_or(available.len());
            if self.buf.len() + take > self.max_line {
                return Err(Error::LineTooLong {
                    file: self.file.clone(),
                    line: self.line + 1,
                    cap: self.max_line,
                });
            }
            self.buf.extend_from_slice(&available[..take]);
            let used = take + usize::from(newline.is_some());
            self.inner.consume(used);
            self.bytes += used as u64;
            if let Some(cap) = self.max_bytes
                && self.bytes > cap
            {
                return Err(Error::TooLarge {
                    file: self.file.clone(),
                    cap,
                });
            }
            if newline.is_some() {
                break;
            }
        }
        self.line += 1;
        let start = if self.line == 1 && self.buf.starts_with(BOM) {
            BOM.len()
        } else {
            0
        };
        let end = if self.buf.len() > start && self.buf.ends_with(b"\r") {
            self.buf.len() - 1
        } else {
            self.buf.len()
        };
        self.text = start..end;
        Ok(Some(self.line))
    }
}

/// Whether a line is a comment or blank (skipped before and after the header).
pub fn is_comment_or_blank(line: &[u8]) -> bool {
    line.first() == Some(&b'#') || line.iter().all(u8::is_ascii_whitespace)
}

/// A cell as read: surrounding ASCII whitespace trimmed, then surrounding quotes (a field
/// quoted after a space, which CSV does not unquote), then whitespace again.
fn cell(raw: &[u8]) -> &[u8] {
    let t = raw.trim_ascii();
    if t.len() >= 2 && t[0] == b'"' && t[t.len() - 1] == b'"' {
        t[1..t.len() - 1].trim_ascii()
    } else {
        t
    }
}

/// The header of a CSV file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Header {
    names: Vec<String>,
    line: u64,
}

impl Header {
    /// The column names, trimmed and unquoted, as written.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// The header's line.
    pub fn line(&self) -> u64 {
        self.line
    }

    /// The 0-based position of the column `name`, compared case-insensitively.
    pub fn find(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|h| h.eq_ignore_ascii_case(name))
    }

    /// The names, comma-separated (for messages).
    pub fn joined(&self) -> String {
        self.names.join(", ")
    }
}

/// One data row: its line and its fields.
#[derive(Debug, Clone, Copy)]
pub struct Row<'a> {
    line: u64,
    data: &'a [u8],
    ends: &'a [usize],
    /// Bytes between a field's end and the next field's start: 1 for a line split where it
    /// lies (the comma), 0 for `csv-core`'s unquoted output.
    sep: usize,
}

impl<'a> Row<'a> {
    /// The row's line (1-based, every line counted).
    pub fn line(&self) -> u64 {
        self.line
    }

    /// The number of fields.
    pub fn len(&self) -> usize {
        self.ends.len()
    }

    /// Whether the row has no field (never, for a row the reader returns).
    pub fn is_empty(&self) -> bool {
        self.ends.is_empty()
    }

    /// Field `i`, trimmed and unquoted.
    pub fn get(&self, i: usize) -> Option<&'a [u8]> {
        let end = *self.ends.get(i)?;
        let start = match i.checked_sub(1) {
            None => 0,
            Some(j) => self.ends.get(j)? + self.sep,
        };
        self.data.get(start..end).map(cell)
    }

    /// Field `i` as text; `None` when absent or not UTF-8.
    pub fn text(&self, i: usize) -> Option<&'a str> {
        self.get(i).and_then(|b| std::str::from_utf8(b).ok())
    }

    /// Whether every cell is empty (a trailing `,,` line), which readers skip like a blank line.
    pub fn all_empty(&self) -> bool {
        (0..self.len()).all(|i| self.get(i).is_none_or(<[u8]>::is_empty))
    }
}

/// A CSV file read line by line: the header, then the data rows (see the crate docs). The
/// simple reader, for small files and row-by-row callers; long records go through
/// [`ChunkedReader`], which reads the same format the same way, chunk by chunk.
pub struct Reader<R> {
    lines: Lines<R>,
    splitter: Splitter,
    header: Option<Header>,
}

impl Reader<File> {
    /// Opens `path` ([`open`]: a regular file only) and reads it; errors name the path as given.
    pub fn open(path: &Path) -> Result<Reader<File>, Error> {
        Ok(Reader::new(open(path)?, path.display().to_string()))
    }
}

impl<R: Read> Reader<R> {
    /// A CSV reader of `reader`; `file` names it in errors.
    pub fn new(reader: R, file: impl Into<String>) -> Reader<R> {
        Reader {
            lines: Lines::new(reader, file),
            splitter: Splitter::default(),
            header: None,
        }
    }

    /// Another line limit than [`MAX_LINE_BYTES`].
    pub fn with_max_line(mut self, bytes: usize) -> Reader<R> {
        self.lines = self.lines.with_max_line(bytes);
        self
    }

    /// Refuse the input ([`Error::TooLarge`]) once more than `bytes` were read.
    pub fn with_max_bytes(mut self, bytes: u64) -> Reader<R> {
        self.lines = self.lines.with_max_bytes(bytes);
        self
    }

    /// The name used in errors.
    pub fn file(&self) -> &str {
        self.lines.file()
    }

    /// The next line that is not a comment or blank, split into fields.
    fn next_record(&mut self) -> Result<Option<Row<'_>>, Error> {
        let line = loop {
            match self.lines.advance()? {
                None => return Ok(None),
                Some(line) if !is_comment_or_blank(self.lines.current()) => break line,
                Some(_) => {}
            }
        };
        Ok(Some(self.splitter.split(self.lines.current(), line)))
    }

    /// The header: the first line that is neither blank nor a comment. Read once; later calls
    /// return it again.
    pub fn header(&mut self) -> Result<&Header, Error> {
        if self.header.is_none() {
            let file = self.lines.file().to_string();
            let Some(row) = self.next_record()? else {
                return Err(Error::NoHeader { file });
            };
            let header = Header::of_row(&row, &file)?;
            self.header = Some(header);
        }
        // set just above when it was not
        self.header.as_ref().ok_or_else(|| Error::NoHeader {
            file: self.lines.file().to_string(),
        })
    }

    /// The next data row (comments and blank lines skipped), with as many fields as the header;
    /// `None` at the end. Reads the header first when [`Reader::header`] was not called.
    pub fn next_row(&mut self) -> Result<Option<Row<'_>>, Error> {
        let expected = self.header()?.names.len();
        let file = self.lines.file().to_string();
        let Some(row) = self.next_record()? else {
            return Ok(None);
        };
        if row.len() != expected {
            return Err(Error::FieldCount {
                file,
                line: row.line(),
                expected,
                found: row.len(),
            });
        }
        Ok(Some(row))
    }
}

impl Header {
    /// The header of a file from its first row: the names UTF-8, not all empty, none twice
    /// (compared case-insensitively).
    fn of_row(row: &Row<'_>, file: &str) -> Result<Header, Error> {
        let line = row.line();
        let mut names = Vec::with_capacity(row.len());
        for i in 0..row.len() {
            let name = std::str::from_utf8(row.get(i).unwrap_or_default()).map_err(|_| {
                Error::NotUtf8 {
                    file: file.to_string(),
                    line,
                }
            })?;
            names.push(name.to_string());
        }
        if names.iter().all(String::is_empty) {
            return Err(Error::NoHeader {
                file: file.to_string(),
            });
        }
        for (j, name) in names.iter().enumerate() {
            if name.is_empty() {
                continue;
            }
            if let Some(i) = names
                .iter()
                .take(j)
                .position(|h| h.eq_ignore_ascii_case(name))
            {
                return Err(Error::DuplicateColumn {
                    file: file.to_string(),
                    line,
                    name: name.clone(),
                    first: i + 1,
                    second: j + 1,
                });
            }
        }
        Ok(Header { names, line })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// Each data row's line and cells.
    type Rows = Vec<(u64, Vec<String>)>;

    fn rows(text: &[u8]) -> Result<(Vec<String>, Rows), Error> {
        let mut r = Reader::new(text, "t.csv");
        let names = r.header()?.names().to_vec();
        let mut out = Vec::new();
        while let Some(row) = r.next_row()? {
            let cells = (0..row.len())
                .map(|i| String::from_utf8_lossy(row.get(i).unwrap()).into_owned())
                .collect();
            out.push((row.line(), cells));
        }
        Ok((names, out))
    }

    #[test]
    fn lines_are_counted_through_comments_and_blanks() {
        let (names, rows) =
            rows(b"# c\n\n Rate_DPS , \"volts\"\r\n1,2\n# mid\n\n  \n\"3\", \"4\" \n5,\"6,5\"")
                .unwrap();
        assert_eq!(names, ["Rate_DPS", "volts"]);
        assert_eq!(
            rows,
            [
                (4, vec!["1".into(), "2".into()]),
                (8, vec!["3".into(), "4".into()]),
                (9, vec!["5".into(), "6,5".into()]),
            ]
        );
    }

    #[test]
    fn a_byte_order_mark_is_skipped() {
        let (names, rows) = rows(b"\xEF\xBB\xBFrate_dps,volts\n1,2\n").unwrap();
        assert_eq!(names, ["rate_dps", "volts"]);
        assert_eq!(rows.len(), 1);
    }

    #[test]
    fn a_long_line_is_refused_without_reading_on_or_echoing_it() {
        // an endless input: the reader must stop by itself
        let endless = std::io::repeat(b'7');
        let mut r = Reader::new(endless, "big.csv").with_max_line(4096);
        let e = r.header().unwrap_err();
        assert_eq!(e.kind(), ErrorKind::LineTooLong);
        assert_eq!(
            e.to_string(),
            "big.csv: line 1: longer than the 4 KiB limit for a line; is it a CSV data file?"
        );
        // after a valid header
        let after = (&b"t_s,volts\n0,1\n"[..]).chain(std::io::repeat(b'7'));
        let mut r = Reader::new(after, "big.csv").with_max_line(4096);
        r.header().unwrap();
        assert_eq!(r.next_row().unwrap().unwrap().line(), 2);
        let e = r.next_row().unwrap_err();
        assert_eq!((e.kind(), e.line()), (ErrorKind::LineTooLong, Some(3)));
        assert!(!e.to_string().contains("777"));
    }

    #[test]
    fn errors_name_the_file_and_line() {
        let e = rows(b"a,b\n1,2\n3\n").unwrap_err();
        assert_eq!(
            e.to_string(),
            "t.csv: line 3: expected 2 fields like the header, found 1"
        );
        assert_eq!(e.detail(), "expected 2 fields like the header, found 1");
        let e = rows(b"# only\n\n").unwrap_err();
        assert_eq!(e.kind(), ErrorKind::NoHeader);
        let e = rows(b"a,B,b\n").unwrap_err();
        assert_eq!(
            e.to_string(),
            "t.csv: line 1: the header names column `b` twice (columns 2 and 3); which one is meant is ambiguous"
        );
        let e = rows(b"\n\xFF,a\n").unwrap_err();
        assert_eq!((e.kind(), e.line()), (ErrorKind::NotUtf8, Some(2)));
        // a byte cap: the first row fits, the input as a whole does not
        let mut r = Reader::new(&b"a\n1\n2\n3\n"[..], "t.csv").with_max_bytes(5);
        let mut last = Ok(());
        for _ in 0..4 {
            if let Err(e) = r.next_row() {
                last = Err(e);
                break;
            }
        }
        assert_eq!(last.unwrap_err().kind(), ErrorKind::TooLarge);
    }

    #[test]
    fn only_regular_files_are_opened() {
        let dir = tempfile::tempdir().unwrap();
        let e = open(dir.path()).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::NotAFile);
        let e = open(&dir.path().join("missing.csv")).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::NotFound);
        #[cfg(unix)]
        {
            let e = open(Path::new("/dev/zero")).unwrap_err();
            assert_eq!(e.kind(), ErrorKind::NotAFile);
            assert!(e.to_string().contains("a device"), "{e}");
        }
        let path = dir.path().join("ok.csv");
        std::fs::write(&path, "a\n1\n").unwrap();
        let mut r = Reader::open(&path).unwrap();
        assert_eq!(r.next_row().unwrap().unwrap().text(0), Some("1"));
    }
}
