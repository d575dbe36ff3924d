//! Where the estimators read a record's prefix sums `P[0..=N]`: a slice in memory or a file
//! ([`crate::disk::SampleFile`]), through one interface, so both run the **same** code and give
//! the same bits.
//!
//! Every kernel reads `P` as a few sequential streams at fixed offsets (`P[i]`, `P[i+m]`,
//! `P[i+2m]`, …) in blocks of at most [`BLOCK`] values ([`PhaseSource::cursor`]), plus a few
//! short random reads ([`PhaseSource::read_at`], [`PhaseSource::gather`]) for the decimated and
//! reflected series. A slice hands out sub-slices (no copy); a file reads each stream through a
//! buffer of its own, so the memory of a computation is a handful of buffers whatever N.

use std::convert::Infallible;

/// The most values a kernel asks a cursor for at once; also the block of the compensated sums
/// of squares (so the blocks, and the rounding, are the same from memory and from a file).
pub const BLOCK: usize = 1024;

/// A sequence of f64 (a record's prefix sums) that the estimators can read.
pub trait PhaseSource {
    /// What reading can fail with ([`Infallible`] for memory).
    type Error: Into<crate::Error>;
    /// A sequential reader from some index on.
    type Cursor<'a>: PhaseCursor<Error = Self::Error>
    where
        Self: 'a;

    /// Number of values (N+1 for a record of N samples).
    fn points(&self) -> usize;

    /// A reader of the values from index `start` on.
    fn cursor(&self, start: usize) -> Self::Cursor<'_>;

    /// Copies the values `start..start + out.len()` into `out`.
    fn read_at(&self, start: usize, out: &mut [f64]) -> Result<(), Self::Error>;

    /// Copies the values `start`, `start + stride`, `start + 2·stride`, … into `out`
    /// (`stride` ≥ 1).
    fn gather(&self, start: usize, stride: usize, out: &mut [f64]) -> Result<(), Self::Error>;
}

/// A sequential reader of a [`PhaseSource`].
pub trait PhaseCursor {
    /// What reading can fail with.
    type Error;

    /// The next `len` values (`len` ≤ [`BLOCK`]). Asking beyond the end is a bug of the caller:
    /// an error for a file, a panic for a slice (as indexing past its end).
    fn next(&mut self, len: usize) -> Result<&[f64], Self::Error>;
}

/// The cursor of a slice: hands out sub-slices, no copy.
#[derive(Debug, Clone)]
pub struct SliceCursor<'a> {
    rest: &'a [f64],
}

impl PhaseCursor for SliceCursor<'_> {
    type Error = Infallible;

    #[inline]
    fn next(&mut self, len: usize) -> Result<&[f64], Infallible> {
        let (head, tail) = self.rest.split_at(len);
        self.rest = tail;
        Ok(head)
    }
}

impl PhaseSource for [f64] {
    type Error = Infallible;
    type Cursor<'a> = SliceCursor<'a>;

    fn points(&self) -> usize {
        self.len()
    }

    fn cursor(&self, start: usize) -> SliceCursor<'_> {
        SliceCursor {
            rest: &self[start..],
        }
    }

    fn read_at(&self, start: usize, out: &mut [f64]) -> Result<(), Infallible> {
        out.copy_from_slice(&self[start..start + out.len()]);
        Ok(())
    }

    fn gather(&self, start: usize, stride: usize, out: &mut [f64]) -> Result<(), Infallible> {
        if stride <= 1 {
            return self.read_at(start, out);
        }
        let span = &self[start..start + (out.len().saturating_sub(1)) * stride + 1];
        for (o, v) in out.iter_mut().zip(span.iter().step_by(stride)) {
            *o = *v;
        }
        Ok(())
    }
}

/// A rate record as the curve, the noise identification and the bias figures see it: τ0, N,
/// the mean and the prefix sums of `y − ȳ` ([`crate::Record`] in memory,
/// [`crate::DiskRecord`] in a file).
pub trait RateRecord {
    /// Where the prefix sums are.
    type Phase: PhaseSource + ?Sized;

    /// Sample interval τ0, s.
    fn tau0_s(&self) -> f64;
    /// Number of rate samples N.
    fn samples(&self) -> usize;
    /// Mean of the rate samples.
    fn mean(&self) -> f64;
    /// The prefix sums `P[0..=N]`.
    fn phase(&self) -> &Self::Phase;
}

impl RateRecord for crate::Record {
    type Phase = [f64];

    fn tau0_s(&self) -> f64 {
        crate::Record::tau0_s(self)
    }
    fn samples(&self) -> usize {
        self.len()
    }
    fn mean(&self) -> f64 {
        crate::Record::mean(self)
    }
    fn phase(&self) -> &[f64] {
        self.prefix()
    }
}

/// The value of a computation that cannot fail (read from memory).
pub(crate) fn infallible<T>(r: Result<T, Infallible>) -> T {
    match r {
        Ok(v) => v,
        Err(never) => match never {},
    }
}
