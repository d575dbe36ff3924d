//! Records larger than memory: f64 arrays in files ([`SampleFile`]) and a rate record whose
//! prefix sums live in one ([`DiskRecord`]).
//!
//! A [`DiskRecord`] is built from samples already in a [`SampleFile`] in two sequential passes
//! (the compensated mean, then the compensated prefix sums of `y − ȳ` written to a second file),
//! with the same arithmetic in the same order as [`crate::Record::from_vec`], so its prefix sums
//! are bit for bit those of the in-memory record. The estimators, the noise identification and
//! the bias figures then read it through [`crate::phase::PhaseSource`], the interface the
//! in-memory record goes through too: the whole analysis gives the same bits from a file as
//! from memory.
//!
//! # Memory
//! Every reader has a buffer of [`SampleFile::buffer_len`] values (default
//! [`DEFAULT_BUFFER`], 64 KiB, plus as much for the bytes read); a kernel holds at most seven
//! (MDEV), the writer one of [`WRITE_BUFFER_BYTES`]. Nothing grows with N.
//!
//! # Why files read with `pread`, not a memory map
//! A map would let the batch code index a `&[f64]`, but every page it touches counts in the
//! process's resident set until the kernel needs the memory back (the peak resident size grows
//! with the record), mapping a file is `unsafe` (the workspace denies it) and a file shortened
//! under the map is a SIGBUS. Reading with `pread` into small buffers keeps the resident set
//! fixed; the file's pages stay in the page cache, which the kernel reclaims as it likes, and
//! the estimators read each stream sequentially, which the kernel reads ahead.
//!
//! # Format
//! Little-endian IEEE 754 binary64, back to back, from offset 0; no header. The files are the
//! caller's (typically unnamed temporary files: they vanish when closed, even after a crash).

use std::fs::File;
use std::io::{self, BufWriter, Seek, Write};
use std::ops::Range;

use crate::error::{Error, Result};
use crate::phase::{BLOCK, PhaseCursor, PhaseSource};
use crate::sum::Neumaier;

/// Values per read buffer by default (64 KiB of f64).
pub const DEFAULT_BUFFER: usize = 8192;
/// Bytes of the writer's buffer (1 MiB).
pub const WRITE_BUFFER_BYTES: usize = 1 << 20;

#[cfg(unix)]
fn read_exact_at(file: &File, buf: &mut [u8], offset: u64) -> io::Result<()> {
    std::os::unix::fs::FileExt::read_exact_at(file, buf, offset)
}

#[cfg(windows)]
fn read_exact_at(file: &File, mut buf: &mut [u8], mut offset: u64) -> io::Result<()> {
    use std::os::windows::fs::FileExt;
    while !buf.is_empty() {
        match file.seek_read(buf, offset) {
            Ok(0) => {
                return Err(io::Error::new(
                    io::ErrorKind::UnexpectedEof,
                    "the sample file ends early",
                ));
            }
            Ok(n) => {
                buf = &mut buf[n..];
                offset += n as u64;
            }
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

#[cfg(not(any(unix, windows)))]
fn read_exact_at(mut file: &File, buf: &mut [u8], offset: u64) -> io::Result<()> {
    use std::io::{Read, SeekFrom};
    file.seek(SeekFrom::Start(offset))?;
    file.read_exact(buf)
}

fn decode(bytes: &[u8], out: &mut [f64]) {
    for (o, b) in out.iter_mut().zip(bytes.chunks_exact(8)) {
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        *o = f64::from_le_bytes(a);
    }
}

fn past_end(what: &str) -> io::Error {
    io::Error::new(
        io::ErrorKind::UnexpectedEof,
        format!("{what} beyond the end of the sample file"),
    )
}

/// Appends f64 values to a file; [`SampleWriter::finish`] gives the [`SampleFile`].
#[derive(Debug)]
pub struct SampleWriter {
    out: BufWriter<File>,
    len: usize,
}

impl SampleWriter {
    /// A writer into `file`, emptied first.
    pub fn new(mut file: File) -> io::Result<SampleWriter> {
        file.set_len(0)?;
        file.rewind()?;
        Ok(SampleWriter {
            out: BufWriter::with_capacity(WRITE_BUFFER_BYTES, file),
            len: 0,
        })
    }

    /// Appends one value.
    #[inline]
    pub fn push(&mut self, v: f64) -> io::Result<()> {
        self.out.write_all(&v.to_le_bytes())?;
        self.len += 1;
        Ok(())
    }

    /// Appends values.
    pub fn extend_from_slice(&mut self, values: &[f64]) -> io::Result<()> {
        for &v in values {
            self.push(v)?;
        }
        Ok(())
    }

    /// Values written so far.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True before the first value.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Flushes and gives the file to read.
    pub fn finish(self) -> io::Result<SampleFile> {
        let len = self.len;
        let file = self
            .out
            .into_inner()
            .map_err(io::IntoInnerError::into_error)?;
        Ok(SampleFile {
            file,
            len,
            buffer: DEFAULT_BUFFER,
        })
    }
}

/// An array of f64 in a file, read with positioned reads through small buffers.
#[derive(Debug)]
pub struct SampleFile {
    file: File,
    len: usize,
    buffer: usize,
}

impl SampleFile {
    /// Number of values.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when it holds no value.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Values per read buffer.
    pub fn buffer_len(&self) -> usize {
        self.buffer
    }

    /// Sets the values per read buffer (at least [`BLOCK`]; small buffers exercise the refills in
    /// tests, large ones make fewer system calls).
    pub fn with_buffer_len(mut self, values: usize) -> SampleFile {
        self.buffer = values.max(BLOCK);
        self
    }

    /// Copies the values `start..start + out.len()` into `out`.
    pub fn read_values(&self, start: usize, out: &mut [f64]) -> io::Result<()> {
        if start.checked_add(out.len()).is_none_or(|e| e > self.len) {
            return Err(past_end("reading"));
        }
        let mut bytes = vec![0u8; out.len().min(self.buffer) * 8];
        let mut done = 0;
        while done < out.len() {
            let k = (out.len() - done).min(self.buffer);
            let b = &mut bytes[..k * 8];
            read_exact_at(&self.file, b, ((start + done) * 8) as u64)?;
            decode(b, &mut out[done..done + k]);
            done += k;
        }
        Ok(())
    }

    /// The values of `range` in order, a buffer at a time.
    pub fn chunks(&self, range: Range<usize>) -> io::Result<SampleChunks<'_>> {
        if range.start > range.end || range.end > self.len {
            return Err(past_end("a range"));
        }
        Ok(SampleChunks {
            file: self,
            next: range.start,
            end: range.end,
            bytes: Vec::new(),
            values: Vec::new(),
        })
    }
}

/// Sequential reading of a range of a [`SampleFile`] ([`SampleFile::chunks`]).
#[derive(Debug)]
pub struct SampleChunks<'a> {
    file: &'a SampleFile,
    next: usize,
    end: usize,
    bytes: Vec<u8>,
    values: Vec<f64>,
}

impl SampleChunks<'_> {
    /// Index (in the file) of the first value the next chunk holds.
    pub fn position(&self) -> usize {
        self.next
    }

    /// The next values (at most a buffer), `None` at the end of the range.
    pub fn next_chunk(&mut self) -> io::Result<Option<&[f64]>> {
        if self.next >= self.end {
            return Ok(None);
        }
        let k = (self.end - self.next).min(self.file.buffer);
        self.bytes.resize(k * 8, 0);
        self.values.resize(k, 0.0);
        read_exact_at(&self.file.file, &mut self.bytes, (self.next * 8) as u64)?;
        decode(&self.bytes, &mut self.values);
        self.next += k;
        Ok(Some(&self.values))
    }
}

/// The cursor of a [`SampleFile`]: its own buffer, refilled with positioned reads.
#[derive(Debug)]
pub struct FileCursor<'a> {
    file: &'a SampleFile,
    /// index in the file of the next value to load
    next: usize,
    buf: Vec<f64>,
    bytes: Vec<u8>,
    start: usize,
    end: usize,
}

impl PhaseCursor for FileCursor<'_> {
    type Error = io::Error;

    fn next(&mut self, len: usize) -> io::Result<&[f64]> {
        if self.end - self.start < len {
            if self.buf.is_empty() {
                let cap = self.file.buffer.max(len);
                self.buf = vec![0.0; cap];
                self.bytes = vec![0u8; cap * 8];
            }
            self.buf.copy_within(self.start..self.end, 0);
            self.end -= self.start;
            self.start = 0;
            let want = (self.buf.len() - self.end).min(self.file.len.saturating_sub(self.next));
            if self.end + want < len {
                return Err(past_end("a cursor read"));
            }
            let b = &mut self.bytes[..want * 8];
            read_exact_at(&self.file.file, b, (self.next * 8) as u64)?;
            decode(b, &mut self.buf[self.end..self.end + want]);
            self.next += want;
            self.end += want;
        }
        let s = &self.buf[self.start..self.start + len];
        self.start += len;
        Ok(s)
    }
}

impl PhaseSource for SampleFile {
    type Error = io::Error;
    type Cursor<'a> = FileCursor<'a>;

    fn points(&self) -> usize {
        self.len
    }

    fn cursor(&self, start: usize) -> FileCursor<'_> {
        FileCursor {
            file: self,
            next: start,
            buf: Vec::new(),
            bytes: Vec::new(),
            start: 0,
            end: 0,
        }
    }

    fn read_at(&self, start: usize, out: &mut [f64]) -> io::Result<()> {
        self.read_values(start, out)
    }

    fn gather(&self, start: usize, stride: usize, out: &mut [f64]) -> io::Result<()> {
        if out.is_empty() {
            return Ok(());
        }
        let stride = stride.max(1);
        if stride == 1 {
            return self.read_values(start, out);
        }
        let span = (out.len() - 1)
            .checked_mul(stride)
            .and_then(|s| s.checked_add(start + 1))
            .ok_or_else(|| past_end("gathering"))?;
        if stride > self.buffer / 4 {
            // far apart: one small read each
            for (k, o) in out.iter_mut().enumerate() {
                self.read_values(start + k * stride, std::slice::from_mut(o))?;
            }
            return Ok(());
        }
        // close together: read the span sequentially and pick
        let mut chunks = self.chunks(start..span)?;
        let mut want = start;
        let mut k = 0;
        while k < out.len() {
            let first = chunks.position();
            let Some(c) = chunks.next_chunk()? else {
                return Err(past_end("gathering"));
            };
            let last = first + c.len();
            while k < out.len() && want < last {
                out[k] = c[want - first];
                k += 1;
                want += stride;
            }
        }
        Ok(())
    }
}

/// A rate record whose prefix sums are in a file: what [`crate::Record`] is in memory, for
/// records larger than memory. [`crate::compute_record`], [`crate::bias_figures_in`] and the
/// noise identification accept either and give the same bits.
#[derive(Debug)]
pub struct DiskRecord {
    tau0_s: f64,
    mean: f64,
    prefix: SampleFile,
}

impl DiskRecord {
    /// The record of the samples `range` of `values` taken every `tau0_s` seconds; the prefix
    /// sums are written to `prefix_file` (emptied first; N+1 values, 8 bytes each).
    ///
    /// Errors as [`crate::Record::from_vec`] ([`Error::Empty`], [`Error::NonFinite`] with the
    /// index within `range`, [`Error::InvalidParameter`] for τ0 or a range past the end), and
    /// [`Error::Io`].
    pub fn from_samples(
        values: &SampleFile,
        range: Range<usize>,
        prefix_file: File,
        tau0_s: f64,
    ) -> Result<DiskRecord> {
        crate::record::check_tau0(tau0_s)?;
        if range.end > values.len() || range.start > range.end {
            return Err(Error::InvalidParameter {
                name: "sample range end",
                value: range.end as f64,
                why: "must lie within the sample file",
            });
        }
        if range.is_empty() {
            return Err(Error::Empty);
        }
        // pass 1: the compensated mean (as sum::mean), checking every value
        let mut sum = Neumaier::default();
        let mut chunks = values.chunks(range.clone())?;
        let mut index = 0usize;
        while let Some(c) = chunks.next_chunk()? {
            for &v in c {
                if !v.is_finite() {
                    return Err(Error::NonFinite { index, value: v });
                }
                sum.add(v);
                index += 1;
            }
        }
        let n = range.len();
        let mean = sum.value() / n as f64;
        // pass 2: the prefix sums of y − ȳ (as Record::from_vec)
        let mut out = SampleWriter::new(prefix_file)?;
        out.push(0.0)?;
        let mut acc = Neumaier::default();
        let mut chunks = values.chunks(range)?;
        while let Some(c) = chunks.next_chunk()? {
            for &v in c {
                acc.add(v - mean);
                out.push(acc.value())?;
            }
        }
        let prefix = out.finish()?.with_buffer_len(values.buffer_len());
        Ok(DiskRecord {
            tau0_s,
            mean,
            prefix,
        })
    }

    /// Sample interval τ0 in seconds.
    pub fn tau0_s(&self) -> f64 {
        self.tau0_s
    }

    /// Number of rate samples N.
    pub fn len(&self) -> usize {
        self.prefix.len() - 1
    }

    /// Always false (a record holds at least one sample).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Mean of the rate samples.
    pub fn mean(&self) -> f64 {
        self.mean
    }

    /// Record length T = N·τ0 in seconds.
    pub fn duration_s(&self) -> f64 {
        self.len() as f64 * self.tau0_s
    }

    /// The file of the prefix sums `P[0..=N]`.
    pub fn prefix(&self) -> &SampleFile {
        &self.prefix
    }
}

impl crate::phase::RateRecord for DiskRecord {
    type Phase = SampleFile;

    fn tau0_s(&self) -> f64 {
        self.tau0_s
    }
    fn samples(&self) -> usize {
        self.len()
    }
    fn mean(&self) -> f64 {
        self.mean
    }
    fn phase(&self) -> &SampleFile {
        &self.prefix
    }
}
