//! The chunked, column-typed reader: long records at the speed of the disk, in bounded memory.
//!
//! [`ChunkedReader`] reads the same format as [`crate::Reader`], with the same guarantees and
//! the same errors (a regular file only, bounded lines, a byte-order mark skipped, every line
//! counted, the file and the line in every error), but it does not hand out rows: the caller
//! says which columns it wants and how their cells read ([`Spec`], [`Cell`]), and gets them as
//! `f64` columns, a [`Chunk`] at a time. Why it is fast:
//!
//! * the file is read in blocks of [`Options::chunk_bytes`] (1 MiB), each cut after its last
//!   complete line; lines are found with `memchr`, split where they lie (no copy, no
//!   allocation per row: see `split`) and only the wanted cells are parsed, with `fast-float2`
//!   straight from the bytes (see `number`);
//! * blocks are parsed in parallel, [`Options::threads`] at a time (one per core by default,
//!   at most 4), each into its own columns, handed out in file order; line numbers are counted
//!   within each block and offset once the blocks before it are counted, so they are exact.
//!
//! Memory is bounded whatever the file's length: per thread a block (plus at most one line
//! carried over to the next, [`Options::max_line`]) and its columns (8 bytes a cell, 8 a row
//! for the line). [`read_columns`] is the in-memory convenience: every row of the columns
//! named, in vectors.
//!
//! Errors come in file order: the rows before a bad line are handed out first, then the error,
//! as the line reader would have found it.

use std::fs::File;
use std::io::Read;
use std::path::Path;

use crate::number;
use crate::split::Splitter;
use crate::{BOM, Error, Header, MAX_LINE_BYTES, Problem, Row, is_comment_or_blank};

/// How a [`ChunkedReader`] reads.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Options {
    /// The longest line, bytes ([`MAX_LINE_BYTES`]): a longer one is [`Error::LineTooLong`].
    pub max_line: usize,
    /// Refuse the input ([`Error::TooLarge`]) once more than this many bytes were read.
    pub max_bytes: Option<u64>,
    /// Bytes read at a time per thread (1 MiB; 1 byte to 256 MiB).
    pub chunk_bytes: usize,
    /// Blocks parsed in parallel (the cores available, at most 4; 1 to 64; 1: no thread is
    /// started).
    pub threads: usize,
}

/// The default block: 1 MiB, some 40 000 rows of a `t_s,volts` record.
pub const CHUNK_BYTES: usize = 1024 * 1024;

impl Default for Options {
    fn default() -> Options {
        Options {
            max_line: MAX_LINE_BYTES,
            max_bytes: None,
            chunk_bytes: CHUNK_BYTES,
            threads: std::thread::available_parallelism().map_or(1, |n| n.get().min(4)),
        }
    }
}

/// How the cells of a column read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cell {
    /// A finite number, required: an empty cell is [`Problem::Empty`].
    Number,
    /// A finite number or an empty cell (NaN).
    OptionalNumber,
    /// A finite number ≥ 0 or an empty cell (NaN).
    OptionalNonNegative,
    /// A whole number > 0 or an empty cell: read it with [`Chunk::count`].
    OptionalCount,
    /// Whatever number the cell holds (infinite included), NaN when it holds none; never an
    /// error (a column that is only informative).
    Lenient,
}

/// The columns wanted and the rows skipped: positions in the header ([`Header::find`]).
#[derive(Debug, Clone, Default)]
pub struct Spec {
    columns: Vec<(usize, Cell)>,
    flag: Option<usize>,
    skip_empty: bool,
}

impl Spec {
    /// No column yet.
    pub fn new() -> Spec {
        Spec::default()
    }

    /// Adds the column at `index` (0-based), read as `cell`; [`Chunk::column`] numbers the
    /// columns in the order they were added. Cells are checked in that order too: the first
    /// bad one of a row is the error.
    pub fn column(mut self, index: usize, cell: Cell) -> Spec {
        self.columns.push((index, cell));
        self
    }

    /// Rows whose cell at `index` is `1` (an overload flag) are skipped before their cells
    /// are read, and counted ([`Chunk::skipped`]).
    pub fn skip_flagged(mut self, index: usize) -> Spec {
        self.flag = Some(index);
        self
    }

    /// Rows whose every cell is empty (a trailing `,,` line) are skipped like blank lines.
    pub fn skip_empty_rows(mut self) -> Spec {
        self.skip_empty = true;
        self
    }

    /// The number of columns.
    pub fn len(&self) -> usize {
        self.columns.len()
    }

    /// Whether no column was added.
    pub fn is_empty(&self) -> bool {
        self.columns.is_empty()
    }
}

/// A block of rows, as typed columns.
#[derive(Debug, Clone, Default)]
pub struct Chunk {
    columns: Vec<Vec<f64>>,
    lines: Vec<u64>,
    skipped: u64,
}

impl Chunk {
    /// The rows kept (not skipped).
    pub fn len(&self) -> usize {
        self.lines.len()
    }

    /// Whether no row was kept.
    pub fn is_empty(&self) -> bool {
        self.lines.is_empty()
    }

    /// Column `k` of the [`Spec`] (in the order added); empty when there is no such column.
    pub fn column(&self, k: usize) -> &[f64] {
        self.columns.get(k).map_or(&[], Vec::as_slice)
    }

    /// The line of each row kept (1-based, every line counted).
    pub fn lines(&self) -> &[u64] {
        &self.lines
    }

    /// The count in column `k` ([`Cell::OptionalCount`]) of row `i`; `None` for an empty cell.
    pub fn count(&self, k: usize, i: usize) -> Option<u64> {
        self.column(k)
            .get(i)
            .map(|v| v.to_bits())
            .filter(|&n| n != 0)
    }

    /// Rows skipped by [`Spec::skip_flagged`].
    pub fn skipped(&self) -> u64 {
        self.skipped
    }

    fn clear(&mut self, columns: usize) {
        self.columns.resize_with(columns, Vec::new);
        self.columns.iter_mut().for_each(Vec::clear);
        self.lines.clear();
        self.skipped = 0;
    }

    fn offset_lines(&mut self, base: u64) {
        self.lines.iter_mut().for_each(|l| *l += base);
    }
}

/// An error found within a block, its line counted from the block's start.
#[derive(Debug)]
enum Local {
    LineTooLong {
        line: u64,
    },
    FieldCount {
        line: u64,
        found: usize,
    },
    Value {
        line: u64,
        column: usize,
        text: String,
        problem: Problem,
    },
}

/// An error of the reading, before the blocks it follows are counted: its line, when it has
/// one, is the one after the last line counted.
#[derive(Debug)]
enum Pending {
    /// An error without a line.
    Ready(Error),
    /// Reading failed.
    Read(std::io::Error),
    /// A line without end past the limit.
    LineTooLong,
}

impl Pending {
    fn at(self, file: &str, line: u64, cap: usize) -> Error {
        match self {
            Pending::Ready(e) => e,
            Pending::Read(source) => Error::Read {
                file: file.to_string(),
                line,
                source,
            },
            Pending::LineTooLong => Error::LineTooLong {
                file: file.to_string(),
                line,
                cap,
            },
        }
    }
}

/// One thread's block: its bytes, its columns, what went wrong.
#[derive(Debug, Default)]
struct Slot {
    raw: Vec<u8>,
    len: usize,
    chunk: Chunk,
    lines: u64,
    error: Option<Local>,
    splitter: Splitter,
    cells: Vec<f64>,
    /// A line's commas (the fast path's field ends).
    ends: Vec<usize>,
}

/// A CSV file read in blocks into typed columns (see the module docs).
pub struct ChunkedReader<R> {
    src: R,
    file: String,
    opts: Options,
    header: Header,
    /// Bytes after the last complete line of the last block, the start of the next.
    carry: Vec<u8>,
    eof: bool,
    bytes_read: u64,
    /// Lines counted so far (handed out or skipped).
    line_base: u64,
    slots: Vec<Slot>,
    /// Slots of the current batch handed out so far, and how many there are.
    cursor: usize,
    ready: usize,
    /// The error that comes after the current batch.
    pending: Option<Error>,
    done: bool,
}

impl ChunkedReader<File> {
    /// Opens `path` ([`crate::open`]: a regular file only) and reads its header; errors name the
    /// path as given.
    pub fn open(path: &Path, opts: Options) -> Result<ChunkedReader<File>, Error> {
        ChunkedReader::new(crate::open(path)?, path.display().to_string(), opts)
    }
}

impl<R: Read> ChunkedReader<R> {
    /// A reader of `src`, its header read; `file` names it in errors.
    pub fn new(src: R, file: impl Into<String>, opts: Options) -> Result<ChunkedReader<R>, Error> {
        // bounds that keep a caller's typing error from asking for terabytes or thousands of
        // threads: blocks of 1 byte to 256 MiB, 1 to 64 threads
        let opts = Options {
            chunk_bytes: opts.chunk_bytes.clamp(1, 1 << 28),
            threads: opts.threads.clamp(1, 64),
            ..opts
        };
        let mut r = ChunkedReader {
            src,
            file: file.into(),
            header: Header {
                names: Vec::new(),
                line: 0,
            },
            carry: Vec::new(),
            eof: false,
            bytes_read: 0,
            line_base: 0,
            slots: (0..opts.threads).map(|_| Slot::default()).collect(),
            opts,
            cursor: 0,
            ready: 0,
            pending: None,
            done: false,
        };
        r.header = r.read_header()?;
        Ok(r)
    }

    /// The header.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The name used in errors.
    pub fn file(&self) -> &str {
        &self.file
    }

    /// The position of column `name` in the header, or [`Error::MissingColumn`].
    pub fn require(&self, name: &str) -> Result<usize, Error> {
        self.header.find(name).ok_or_else(|| Error::MissingColumn {
            file: self.file.clone(),
            line: self.header.line,
            name: name.to_string(),
            found: self.header.joined(),
        })
    }

    /// The first line that is neither blank nor a comment, as a [`Header`]; what follows it
    /// stays in `carry` for the data.
    fn read_header(&mut self) -> Result<Header, Error> {
        let mut slot = Slot::default();
        loop {
            match self.fill(&mut slot) {
                Ok(true) => {}
                Ok(false) => {
                    return Err(Error::NoHeader {
                        file: self.file.clone(),
                    });
                }
                Err(p) => return Err(p.at(&self.file, self.line_base + 1, self.opts.max_line)),
            }
            let raw = slot.raw.get(..slot.len).unwrap_or_default();
            let mut pos = 0;
            while pos < raw.len() {
                let end = memchr::memchr(b'\n', &raw[pos..]).map_or(raw.len(), |i| pos + i);
                let mut text = &raw[pos..end];
                pos = end + 1;
                self.line_base += 1;
                let line = self.line_base;
                if text.len() > self.opts.max_line {
                    return Err(Error::LineTooLong {
                        file: self.file.clone(),
                        line,
                        cap: self.opts.max_line,
                    });
                }
                if line == 1 {
                    text = text.strip_prefix(BOM).unwrap_or(text);
                }
                let text = strip_cr(text);
                if is_comment_or_blank(text) {
                    continue;
                }
                let row = slot.splitter.split(text, line);
                let header = Header::of_row(&row, &self.file)?;
                // the rest of the block comes before what was carried over
                let mut rest = raw.get(pos..).unwrap_or_default().to_vec();
                rest.extend_from_slice(&self.carry);
                self.carry = rest;
                return Ok(header);
            }
        }
    }

    /// Reads the next block into `slot`: the carried-over bytes, then at least
    /// [`Options::chunk_bytes`] more (or up to the end), cut after the last complete line; what
    /// follows is carried over. `false` when there is nothing left.
    fn fill(&mut self, slot: &mut Slot) -> Result<bool, Pending> {
        slot.len = 0;
        let carried = self.carry.len();
        if slot.raw.len() < carried {
            slot.raw.resize(carried, 0);
        }
        slot.raw[..carried].copy_from_slice(&self.carry);
        slot.len = carried;
        self.carry.clear();
        let mut target = carried + self.opts.chunk_bytes;
        loop {
            if slot.raw.len() < target {
                slot.raw.resize(target, 0);
            }
            while !self.eof && slot.len < target {
                match self.src.read(&mut slot.raw[slot.len..target]) {
                    Ok(0) => self.eof = true,
                    Ok(n) => {
                        slot.len += n;
                        self.bytes_read += n as u64;
                        if let Some(cap) = self.opts.max_bytes
                            && self.bytes_read > cap
                        {
                            return Err(Pending::Ready(Error::TooLarge {
                                file: self.file.clone(),
                                cap,
                            }));
                        }
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                    Err(source) => return Err(Pending::Read(source)),
                }
            }
            if self.eof {
                return Ok(slot.len > 0);
            }
            match memchr::memrchr(b'\n', &slot.raw[..slot.len]) {
                Some(p) => {
                    self.carry.extend_from_slice(&slot.raw[p + 1..slot.len]);
                    slot.len = p + 1;
                    return Ok(true);
                }
                None if slot.len > self.opts.max_line => return Err(Pending::LineTooLong),
                None => target += self.opts.chunk_bytes,
            }
        }
    }
}

impl<R: Read> ChunkedReader<R> {
    /// The next block of rows as `spec`'s columns, in file order; `None` at the end. The rows
    /// before a bad line come first, in their block, then the error; after an error, `None`.
    pub fn next_chunk(&mut self, spec: &Spec) -> Result<Option<&Chunk>, Error> {
        if self.cursor >= self.ready {
            if let Some(e) = self.pending.take() {
                self.done = true;
                return Err(e);
            }
            if self.done {
                return Ok(None);
            }
            self.refill(spec);
            if self.ready == 0 {
                if let Some(e) = self.pending.take() {
                    self.done = true;
                    return Err(e);
                }
                self.done = true;
                return Ok(None);
            }
        }
        let i = self.cursor;
        self.cursor += 1;
        Ok(self.slots.get(i).map(|s| &s.chunk))
    }

    /// Reads up to one block per thread, parses them in parallel and counts their lines; an
    /// error ends the batch at its block and waits in `pending`.
    fn refill(&mut self, spec: &Spec) {
        self.cursor = 0;
        self.ready = 0;
        let mut slots = std::mem::take(&mut self.slots);
        let mut filled = 0;
        let mut fill_error = None;
        for slot in slots.iter_mut() {
            if self.eof && self.carry.is_empty() {
                break;
            }
            match self.fill(slot) {
                Ok(true) => filled += 1,
                Ok(false) => break,
                Err(p) => {
                    fill_error = Some(p);
                    break;
                }
            }
        }
        let expected = self.header.names.len();
        let max_line = self.opts.max_line;
        let (first, rest) = slots.split_at_mut(filled.min(1));
        let rest = rest.get_mut(..filled.saturating_sub(1)).unwrap_or_default();
        // a block per thread; where a thread cannot be started (a process limit), its block
        // is parsed here afterwards
        let mut not_started = vec![false; rest.len()];
        std::thread::scope(|scope| {
            for (slot, failed) in rest.iter_mut().zip(not_started.iter_mut()) {
                let work = move || slot.parse(spec, expected, max_line);
                *failed = std::thread::Builder::new()
                    .spawn_scoped(scope, work)
                    .is_err();
            }
            first
                .iter_mut()
                .for_each(|s| s.parse(spec, expected, max_line));
        });
        for (slot, _) in rest.iter_mut().zip(&not_started).filter(|(_, f)| **f) {
            slot.parse(spec, expected, max_line);
        }
        for slot in slots.iter_mut().take(filled) {
            let base = self.line_base;
            slot.chunk.offset_lines(base);
            self.ready += 1;
            if let Some(local) = slot.error.take() {
                self.pending = Some(self.resolve(local, base, spec));
                self.slots = slots;
                return;
            }
            self.line_base += slot.lines;
        }
        if let Some(p) = fill_error {
            self.pending = Some(p.at(&self.file, self.line_base + 1, max_line));
        }
        self.slots = slots;
    }

    /// A block's error, its line counted from the start of the file.
    fn resolve(&self, local: Local, base: u64, spec: &Spec) -> Error {
        let file = self.file.clone();
        match local {
            Local::LineTooLong { line } => Error::LineTooLong {
                file,
                line: base + line,
                cap: self.opts.max_line,
            },
            Local::FieldCount { line, found } => Error::FieldCount {
                file,
                line: base + line,
                expected: self.header.names.len(),
                found,
            },
            Local::Value {
                line,
                column,
                text,
                problem,
            } => Error::Value {
                file,
                line: base + line,
                column: spec
                    .columns
                    .get(column)
                    .and_then(|(i, _)| self.header.names.get(*i))
                    .cloned()
                    .unwrap_or_default(),
                text,
                problem,
            },
        }
    }
}

impl Slot {
    /// Parses the block's complete lines into `self.chunk`, counting lines from 1; stops at
    /// the first error (`self.error`), the rows before it kept.
    ///
    /// A block without a quote (every block of a logger's record) is scanned once for its
    /// commas and newlines together (`memchr2`, SIMD), each line's fields where they lie; a
    /// line with a carriage return other than the one before its newline goes through the
    /// splitter. A block with a quote goes line by line through the splitter.
    fn parse(&mut self, spec: &Spec, expected: usize, max_line: usize) {
        self.chunk.clear(spec.columns.len());
        let raw = self.raw.get(..self.len).unwrap_or_default();
        let mut rows = Rows {
            spec,
            expected,
            max_line,
            has_cr: memchr::memchr(b'\r', raw).is_some(),
            chunk: &mut self.chunk,
            cells: &mut self.cells,
            splitter: &mut self.splitter,
        };
        let (lines, error) = if memchr::memchr(b'"', raw).is_none() {
            rows.plain_block(raw, &mut self.ends)
        } else {
            rows.quoted_block(raw)
        };
        self.lines = lines;
        self.error = error;
    }
}

/// What a block's rows go through: the spec, the limits, where the values go.
struct Rows<'a> {
    spec: &'a Spec,
    expected: usize,
    max_line: usize,
    has_cr: bool,
    chunk: &'a mut Chunk,
    cells: &'a mut Vec<f64>,
    splitter: &'a mut Splitter,
}

impl Rows<'_> {
    /// A block without quotes: the lines counted, and the error that ended it.
    fn plain_block(&mut self, raw: &[u8], commas: &mut Vec<usize>) -> (u64, Option<Local>) {
        let mut line = 0u64;
        let mut start = 0usize;
        commas.clear();
        for pos in memchr::memchr2_iter(b',', b'\n', raw) {
            if raw.get(pos) == Some(&b',') {
                commas.push(pos - start);
                continue;
            }
            line += 1;
            if let Err(e) = self.plain_line(raw.get(start..pos).unwrap_or_default(), line, commas) {
                return (line, Some(e));
            }
            start = pos + 1;
            commas.clear();
        }
        if start < raw.len() {
            line += 1;
            if let Err(e) = self.plain_line(raw.get(start..).unwrap_or_default(), line, commas) {
                return (line, Some(e));
            }
        }
        (line, None)
    }

    /// One line of a block without quotes, `commas` its commas' positions.
    fn plain_line(&mut self, text: &[u8], line: u64, commas: &mut Vec<usize>) -> Result<(), Local> {
        if text.len() > self.max_line {
            return Err(Local::LineTooLong { line });
        }
        let text = if self.has_cr { strip_cr(text) } else { text };
        if is_comment_or_blank(text) {
            return Ok(());
        }
        if self.has_cr && memchr::memchr(b'\r', text).is_some() {
            let row = self.splitter.split(text, line);
            return row_into(&row, self.spec, self.expected, self.chunk, self.cells);
        }
        commas.push(text.len());
        let row = Row {
            line,
            data: text,
            ends: commas,
            sep: 1,
        };
        row_into(&row, self.spec, self.expected, self.chunk, self.cells)
    }

    /// A block with quotes, line by line through the splitter.
    fn quoted_block(&mut self, raw: &[u8]) -> (u64, Option<Local>) {
        let mut pos = 0;
        let mut line = 0u64;
        while pos < raw.len() {
            let end = memchr::memchr(b'\n', &raw[pos..]).map_or(raw.len(), |i| pos + i);
            let text = raw.get(pos..end).unwrap_or_default();
            pos = end + 1;
            line += 1;
            if text.len() > self.max_line {
                return (line, Some(Local::LineTooLong { line }));
            }
            let text = strip_cr(text);
            if is_comment_or_blank(text) {
                continue;
            }
            let row = self.splitter.split(text, line);
            if let Err(e) = row_into(&row, self.spec, self.expected, self.chunk, self.cells) {
                return (line, Some(e));
            }
        }
        (line, None)
    }
}

/// One data row into the chunk's columns (or skipped, or the error it is).
fn row_into(
    row: &Row<'_>,
    spec: &Spec,
    expected: usize,
    chunk: &mut Chunk,
    cells: &mut Vec<f64>,
) -> Result<(), Local> {
    let line = row.line();
    if row.len() != expected {
        return Err(Local::FieldCount {
            line,
            found: row.len(),
        });
    }
    if let Some(f) = spec.flag
        && row.get(f) == Some(b"1")
    {
        chunk.skipped += 1;
        return Ok(());
    }
    if spec.skip_empty && row.all_empty() {
        return Ok(());
    }
    cells.clear();
    for (k, &(i, cell)) in spec.columns.iter().enumerate() {
        let raw_cell = row.get(i).unwrap_or_default();
        match read_cell(raw_cell, cell) {
            Ok(v) => cells.push(v),
            Err(problem) => {
                return Err(Local::Value {
                    line,
                    column: k,
                    text: shown(raw_cell),
                    problem,
                });
            }
        }
    }
    for (col, &v) in chunk.columns.iter_mut().zip(cells.iter()) {
        col.push(v);
    }
    chunk.lines.push(line);
    Ok(())
}

/// A cell as `cell` reads it.
fn read_cell(raw: &[u8], cell: Cell) -> Result<f64, Problem> {
    match cell {
        Cell::Number => number::finite(raw),
        Cell::OptionalNumber if raw.is_empty() => Ok(f64::NAN),
        Cell::OptionalNumber => number::finite(raw),
        Cell::OptionalNonNegative if raw.is_empty() => Ok(f64::NAN),
        Cell::OptionalNonNegative => match number::finite(raw)? {
            v if v < 0.0 => Err(Problem::Negative),
            v => Ok(v),
        },
        Cell::OptionalCount if raw.is_empty() => Ok(f64::from_bits(0)),
        Cell::OptionalCount => number::count(raw).map(f64::from_bits),
        Cell::Lenient => Ok(number::any_number(raw).unwrap_or(f64::NAN)),
    }
}

/// A cell for an error message: lossy UTF-8, at most 200 bytes (a cell may be a megabyte).
fn shown(cell: &[u8]) -> String {
    const MAX: usize = 200;
    match cell.get(..MAX) {
        Some(head) if cell.len() > MAX => format!("{}…", String::from_utf8_lossy(head)),
        _ => String::from_utf8_lossy(cell).into_owned(),
    }
}

/// Every row of some columns, in memory ([`read_columns`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Columns {
    /// The file's header.
    pub header: Header,
    /// The columns' names as asked for.
    pub names: Vec<String>,
    /// One vector per name, a value per row.
    pub values: Vec<Vec<f64>>,
    /// The line of each row.
    pub lines: Vec<u64>,
}

impl Columns {
    /// The column asked for as `name` (compared case-insensitively).
    pub fn get(&self, name: &str) -> Option<&[f64]> {
        self.names
            .iter()
            .position(|n| n.eq_ignore_ascii_case(name))
            .and_then(|k| self.values.get(k))
            .map(Vec::as_slice)
    }
}

/// Reads the columns `names` of the CSV file at `path`, every cell a finite number
/// ([`Cell::Number`]), into memory: the in-memory caller's way to a file. A name not in the
/// header is [`Error::MissingColumn`]; the other errors are [`ChunkedReader`]'s.
///
/// ```
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// let dir = tempfile::tempdir()?;
/// let path = dir.path().join("drift.csv");
/// std::fs::write(&path, "\u{feff}t_s,volts\r\n0,0.0125\r\n# paused\r\n0.01,0.0126\r\n")?;
/// let cols = gyrocal_csv::read_columns(&path, &["t_s", "volts"], gyrocal_csv::Options::default())?;
/// assert_eq!(cols.get("volts"), Some(&[0.0125, 0.0126][..]));
/// assert_eq!(cols.lines, [2, 4]);
/// # Ok(()) }
/// ```
pub fn read_columns(path: &Path, names: &[&str], opts: Options) -> Result<Columns, Error> {
    let mut rdr = ChunkedReader::open(path, opts)?;
    let mut spec = Spec::new();
    for name in names {
        spec = spec.column(rdr.require(name)?, Cell::Number);
    }
    let mut values = vec![Vec::new(); names.len()];
    let mut lines = Vec::new();
    while let Some(chunk) = rdr.next_chunk(&spec)? {
        for (k, v) in values.iter_mut().enumerate() {
            v.extend_from_slice(chunk.column(k));
        }
        lines.extend_from_slice(chunk.lines());
    }
    Ok(Columns {
        header: rdr.header().clone(),
        names: names.iter().map(|n| (*n).to_string()).collect(),
        values,
        lines,
    })
}

/// `text` without one `\r` at its end.
fn strip_cr(text: &[u8]) -> &[u8] {
    text.strip_suffix(b"\r").unwrap_or(text)
}
