//! The bounded-memory path of [`super::analyse_input`]: the record goes to temporary files and
//! everything is computed from them through fixed-size buffers, with the same numbers as the
//! in-memory path.
//!
//! # Design
//! The CSV is read exactly as on the in-memory path (same passes, same checks, same segment
//! choice); only where the numbers are kept changes:
//!
//! * the time intervals of pass 1 (for the median τ0) and the values of pass 2 go into a
//!   [`Spill`]: a vector until the memory budget is reached, then an unnamed temporary file
//!   ([`gyrocal_allan::disk::SampleFile`], 8 bytes a value) that vanishes when closed;
//! * the median of a spilled pass 1 is the same order statistic as the in-memory
//!   `select_nth_unstable_by(mid, f64::total_cmp)`, found by a radix selection over the file
//!   (four passes of 16 bits of the total-order key, 512 KiB of counters) — the same value,
//!   bit for bit;
//! * the warm-up ([`detect_warmup_file`]) streams the analysed segment twice (the white-noise
//!   σ, then the window means) through the one warm-up function of both paths, so its window
//!   means, tolerance and cut are the same bits;
//! * the record after the warm-up becomes a [`gyrocal_allan::DiskRecord`] (its prefix sums in a
//!   second temporary file, built with the same compensated sums as `Record::from_vec`), and the
//!   curve, the noise identification and the bias figures run on it through the estimators'
//!   one code path for memory and files ([`gyrocal_allan::phase`]).
//!
//! Memory: the CSV reader's 64 KiB, a 1 MiB write buffer, a few read buffers of 64 KiB, the
//! radix counters, the segment list (a few dozen bytes a gap) and the document: nothing that
//! grows with the number of samples. Disk: 8 bytes a sample for the values (all segments), 8
//! for the prefix sums of the analysed part, 8 an interval during pass 1 (freed before pass 2).
//!
//! The warm-up is written once (`detect_warmup_in`, over chunks: a slice in memory, the
//! file's buffers here); `tests/drift_bounded.rs` compares the two paths' documents field by
//! field.
//!
//! # Measured
//! `/usr/bin/time -v gyrocal allan big.csv [--streaming]`, release build, 2 cores, the record
//! from `examples/allan_big_csv.rs` (`t_s,rate_dph` at τ0 = 0.01 s, octave OADEV, the same
//! output from both paths):
//!
//! | rows | path | peak resident memory (max RSS) | wall time |
//! |---|---|---|---|
//! | 2·10⁶ | in memory | 22.3 MiB | 0.59 s |
//! | 2·10⁶ | bounded (`--streaming`) | 8.1 MiB | 0.69 s |
//! | 2·10⁷ | in memory | 159 MiB | 6.1–6.3 s |
//! | 2·10⁷ | bounded (`--streaming`) | 7.7–8.3 MiB | 7.1–7.4 s |
//! | 2·10⁷ | bounded (`--max-memory-mib 100`: switched in pass 1) | 57.3 MiB | 7.2 s |
//!
//! (TOTDEV on 2·10⁷ rows: 160 MiB and 6.4 s in memory, 8.0 MiB and 8.0 s bounded. Before the
//! bounded path existed the in-memory path took 312 MiB and 5.6 s on 2·10⁷ rows: the noise
//! identification copied the record.) The in-memory path takes 8.4 bytes a sample (glibc grows
//! a large vector in place); the budget counts 16 for allocators that copy.

use std::fs::File;
use std::io;
use std::ops::Range;
use std::path::Path;

use gyrocal_allan::disk::{SampleFile, SampleWriter};
use serde::{Deserialize, Serialize};

use super::{Warmup, WarmupOptions, fmt_g};
use crate::DriftError;

/// Default memory budget of the in-memory path, MiB (`--max-memory-mib`).
pub const DEFAULT_MAX_MEMORY_MIB: u64 = 1024;

/// Bytes a sample takes on the in-memory path at its peak, at most: the value (8 bytes) and as
/// much again while its vector doubles (measured: 8.4 bytes with glibc, which grows a large
/// vector in place). The in-memory path holds every sample of the record (all segments) at
/// once; when that would exceed the budget, the bounded path runs.
pub const IN_MEMORY_BYTES_PER_SAMPLE: u64 = 16;

/// Which path analysed the record.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AnalysisPath {
    /// Every value in memory.
    #[default]
    InMemory,
    /// The values in temporary files, read through fixed-size buffers.
    Bounded,
}

/// Which path analysed the record, and why ([`super::AllanDocument::memory`]).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct MemoryUse {
    /// `in_memory` or `bounded`.
    pub path: AnalysisPath,
    /// Why: `--streaming`, or the record's size against the budget.
    pub reason: String,
    /// The in-memory path's budget, bytes.
    pub budget_bytes: u64,
    /// Samples of the record (every segment): what the in-memory path holds.
    pub record_samples: usize,
}

fn mib(bytes: f64) -> String {
    fmt_g(bytes / (1024.0 * 1024.0))
}

/// The [`MemoryUse`] of an analysis.
pub(super) fn memory_use(
    bounded: bool,
    forced: bool,
    record_samples: usize,
    budget_bytes: u64,
) -> MemoryUse {
    let need = record_samples as f64 * IN_MEMORY_BYTES_PER_SAMPLE as f64;
    let (path, reason) = match (bounded, forced) {
        (true, true) => (AnalysisPath::Bounded, "--streaming".to_string()),
        (true, false) => (
            AnalysisPath::Bounded,
            format!(
                "the record's {record_samples} samples would take about {} MiB in memory, more than the --max-memory-mib budget of {} MiB",
                mib(need),
                mib(budget_bytes as f64)
            ),
        ),
        (false, _) => (
            AnalysisPath::InMemory,
            format!(
                "the record's {record_samples} samples take about {} MiB in memory, within the --max-memory-mib budget of {} MiB",
                mib(need),
                mib(budget_bytes as f64)
            ),
        ),
    };
    MemoryUse {
        path,
        reason,
        budget_bytes,
        record_samples,
    }
}

/// An unnamed temporary file in `dir`.
pub(super) fn temp_file(dir: &Path) -> Result<File, DriftError> {
    tempfile::tempfile_in(dir).map_err(|source| DriftError::Io {
        path: dir.to_path_buf(),
        action: "create a temporary file in",
        source,
    })
}

/// An I/O error on the temporary files in `dir`.
pub(super) fn temp_err(dir: &Path, source: io::Error) -> DriftError {
    DriftError::Io {
        path: dir.to_path_buf(),
        action: "write or read a temporary file in",
        source,
    }
}

/// Values kept in memory up to `cap`, then in a temporary file.
pub(super) struct Spill<'a> {
    mem: Vec<f64>,
    cap: usize,
    disk: Option<SampleWriter>,
    dir: &'a Path,
}

/// What a [`Spill`] holds at the end.
pub(super) enum Samples {
    /// In memory: the in-memory path.
    Memory(Vec<f64>),
    /// In a temporary file: the bounded path.
    Disk(SampleFile),
}

impl<'a> Spill<'a> {
    /// At most `cap` values in memory (0: straight to a file); the file, if any, in `dir`.
    pub(super) fn new(cap: usize, dir: &'a Path) -> Spill<'a> {
        Spill {
            mem: Vec::new(),
            cap,
            disk: None,
            dir,
        }
    }

    /// Appends a value.
    #[inline]
    pub(super) fn push(&mut self, v: f64) -> Result<(), DriftError> {
        if self.disk.is_none() && self.mem.len() >= self.cap {
            let mut w =
                SampleWriter::new(temp_file(self.dir)?).map_err(|e| temp_err(self.dir, e))?;
            w.extend_from_slice(&self.mem)
                .map_err(|e| temp_err(self.dir, e))?;
            self.mem = Vec::new();
            self.disk = Some(w);
        }
        match &mut self.disk {
            Some(w) => w.push(v).map_err(|e| temp_err(self.dir, e)),
            None => {
                self.mem.push(v);
                Ok(())
            }
        }
    }

    /// Values so far.
    pub(super) fn len(&self) -> usize {
        self.disk.as_ref().map_or(self.mem.len(), SampleWriter::len)
    }

    /// True once the values went to a file.
    pub(super) fn spilled(&self) -> bool {
        self.disk.is_some()
    }

    /// The values.
    pub(super) fn finish(self) -> Result<Samples, DriftError> {
        match self.disk {
            Some(w) => Ok(Samples::Disk(
                w.finish().map_err(|e| temp_err(self.dir, e))?,
            )),
            None => Ok(Samples::Memory(self.mem)),
        }
    }
}

/// The key ordering u64 as `f64::total_cmp` orders the values.
fn total_key(v: f64) -> u64 {
    let b = v.to_bits();
    if b >> 63 == 1 { !b } else { b | (1 << 63) }
}

fn from_total_key(k: u64) -> f64 {
    if k >> 63 == 1 {
        f64::from_bits(k & !(1 << 63))
    } else {
        f64::from_bits(!k)
    }
}

/// The `k`-th smallest value (0-based) of a file in `f64::total_cmp` order: what
/// `select_nth_unstable_by(k, f64::total_cmp)` puts at `k`. Four passes, 16 bits of the key
/// each. `None` when `k` is out of range.
pub(super) fn kth_smallest(file: &SampleFile, k: usize) -> io::Result<Option<f64>> {
    if k >= file.len() {
        return Ok(None);
    }
    let mut prefix = 0u64;
    let mut rank = k as u64;
    let mut hist = vec![0u64; 1 << 16];
    for shift in [48u32, 32, 16, 0] {
        hist.fill(0);
        let mut chunks = file.chunks(0..file.len())?;
        while let Some(c) = chunks.next_chunk()? {
            for &v in c {
                let key = total_key(v);
                if shift == 48 || key >> (shift + 16) == prefix >> (shift + 16) {
                    hist[((key >> shift) & 0xFFFF) as usize] += 1;
                }
            }
        }
        let mut below = 0u64;
        let mut found = false;
        for (digit, &count) in hist.iter().enumerate() {
            if below + count > rank {
                prefix |= (digit as u64) << shift;
                rank -= below;
                found = true;
                break;
            }
            below += count;
        }
        if !found {
            return Ok(None);
        }
    }
    Ok(Some(from_total_key(prefix)))
}

/// The warm-up of `range` of `file`: `warmup::detect_warmup_in` over the file's buffers.
#[allow(clippy::too_many_arguments)]
pub(super) fn detect_warmup_file(
    file: &SampleFile,
    range: Range<usize>,
    tau0: f64,
    t0: f64,
    factor: f64,
    opts: &WarmupOptions,
    notes: &mut Vec<String>,
) -> io::Result<Option<Warmup>> {
    let base = range.start;
    let chunks = |r: Range<usize>, f: &mut dyn FnMut(&[f64])| -> io::Result<()> {
        let mut c = file.chunks(base + r.start..base + r.end)?;
        while let Some(x) = c.next_chunk()? {
            f(x);
        }
        Ok(())
    };
    super::warmup::detect_warmup_in(chunks, range.len(), tau0, t0, factor, opts, notes)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]

    use super::*;

    #[test]
    fn the_radix_median_is_the_in_memory_order_statistic() {
        let mut v: Vec<f64> = vec![
            0.1,
            0.1,
            0.10000000000002274,
            -0.0,
            0.0,
            -3.5,
            1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            -1e-300,
            0.099999999,
        ];
        for i in 0..200 {
            v.push(0.1 + (i % 7) as f64 * 1e-12 - 3e-12);
        }
        let dir = tempfile::tempdir().unwrap();
        let mut w = SampleWriter::new(temp_file(dir.path()).unwrap()).unwrap();
        w.extend_from_slice(&v).unwrap();
        let f = w.finish().unwrap();
        for k in 0..v.len() {
            let mut m = v.clone();
            let (_, want, _) = m.select_nth_unstable_by(k, f64::total_cmp);
            let got = kth_smallest(&f, k).unwrap().unwrap();
            assert_eq!(got.to_bits(), want.to_bits(), "k = {k}");
        }
        assert_eq!(kth_smallest(&f, v.len()).unwrap(), None);
        for x in [0.0, -0.0, 1.5, -2.25, f64::MAX, f64::MIN_POSITIVE] {
            assert_eq!(from_total_key(total_key(x)).to_bits(), x.to_bits());
        }
    }

    #[test]
    fn a_spill_keeps_the_values_in_order_across_the_switch() {
        let dir = tempfile::tempdir().unwrap();
        let mut s = Spill::new(5, dir.path());
        for i in 0..12 {
            s.push(i as f64).unwrap();
        }
        assert!(s.spilled());
        assert_eq!(s.len(), 12);
        let Samples::Disk(f) = s.finish().unwrap() else {
            panic!("not spilled")
        };
        let mut out = vec![0.0; 12];
        f.read_values(0, &mut out).unwrap();
        assert_eq!(out, (0..12).map(|i| i as f64).collect::<Vec<_>>());
        let mut s = Spill::new(5, dir.path());
        s.push(1.0).unwrap();
        assert!(matches!(s.finish().unwrap(), Samples::Memory(v) if v == [1.0]));
    }
}
