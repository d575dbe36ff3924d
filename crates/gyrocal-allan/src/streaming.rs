//! Octave OADEV over a record fed in chunks (larger than memory).

use crate::curve::{Curve, RawPoint, complete};
use crate::error::{Error, Result};
use crate::estimators::Estimator;
use crate::sum::{Neumaier, sum_sq};

/// Streaming overlapping Allan deviation at octave τ (m = 1, 2, 4, … ≤ `max_m`).
///
/// For every estimator and τ set on a record larger than memory, with the same bits as in
/// memory, use a [`crate::DiskRecord`] instead: this accumulator keeps 2·`max_m` + 1 phase
/// values (half the record for τ up to T/4) and rounds differently from the batch path.
///
/// Feed rate samples with [`Streaming::push`] in chunks of any size; [`Streaming::deviations`]
/// gives, for every octave m ≤ `max_m`, the same deviation and number of terms as
/// [`crate::deviations`] with [`Estimator::Oadev`] and [`crate::TauSet::Octave`] on the whole
/// record (to rounding: the tests require 1e-9 relative; the batch path subtracts the exact mean,
/// the stream a running linear trend, and the second difference is invariant to both).
///
/// **Memory bound**: the accumulator keeps the last 2·`max_m` + 1 phase values and compacts its
/// buffer when it doubles, so it holds at most 2·(2·`max_m` + 1) + (chunk length) f64, plus a few
/// words per octave — independent of the record length. Choose `max_m` = τ_max/τ0 for the longest
/// τ wanted (τ ≤ T/4 needs `max_m` ≥ N/4 for a record of N samples).
///
/// **Precision**: the phase is a Neumaier-compensated running sum of y − offset; at every
/// compaction the buffer's linear trend is folded into the offset so the stored phase stays near
/// zero whatever the bias (the batch path does the same by subtracting the mean first).
#[derive(Debug, Clone)]
pub struct Streaming {
    tau0_s: f64,
    max_m: usize,
    /// rate subtracted before integration (first sample, then re-centred)
    offset: Option<f64>,
    acc: Neumaier,
    /// phase points x[base .. base + buf.len()] (x[0] = 0)
    buf: Vec<f64>,
    base: usize,
    octaves: Vec<Octave>,
}

#[derive(Debug, Clone)]
struct Octave {
    m: usize,
    /// next start index i of a term x[i+2m] − 2x[i+m] + x[i]
    next: usize,
    sum: Neumaier,
}

impl Streaming {
    /// An accumulator for samples every `tau0_s` seconds, octave factors up to `max_m` (at least 1).
    pub fn new(tau0_s: f64, max_m: usize) -> Streaming {
        let max_m = max_m.max(1);
        let octaves = (0..=max_m.ilog2())
            .map(|k| Octave {
                m: 1 << k,
                next: 0,
                sum: Neumaier::default(),
            })
            .collect();
        Streaming {
            tau0_s,
            max_m,
            offset: None,
            acc: Neumaier::default(),
            buf: vec![0.0],
            base: 0,
            octaves,
        }
    }

    /// Number of rate samples pushed so far.
    pub fn len(&self) -> usize {
        self.base + self.buf.len() - 1
    }

    /// True before the first sample.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Phase values currently held (for the memory bound).
    pub fn buffered(&self) -> usize {
        self.buf.len()
    }

    /// Appends rate samples. Non-finite samples are an error ([`Error::NonFinite`], with the
    /// sample's index in the whole stream) and leave the accumulator unchanged.
    pub fn push(&mut self, chunk: &[f64]) -> Result<()> {
        if let Some((i, &v)) = chunk.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(Error::NonFinite {
                index: self.len() + i,
                value: v,
            });
        }
        let Some(&first) = chunk.first() else {
            return Ok(());
        };
        let offset = *self.offset.get_or_insert(first);
        self.buf.reserve(chunk.len());
        for &y in chunk {
            self.acc.add(y - offset);
            self.buf.push(self.acc.value());
        }
        let last = self.base + self.buf.len() - 1; // global index of the newest phase point
        for o in &mut self.octaves {
            let m = o.m;
            if last < 2 * m || o.next + 2 * m > last {
                continue;
            }
            let count = last - 2 * m + 1 - o.next;
            let s = o.next - self.base;
            let x = &self.buf;
            o.sum.add(sum_sq(count, |i| {
                x[s + i + 2 * m] - 2.0 * x[s + i + m] + x[s + i]
            }));
            o.next += count;
        }
        self.compact();
        Ok(())
    }

    fn compact(&mut self) {
        let keep = 2 * self.max_m + 1;
        if self.buf.len() < 2 * keep {
            return;
        }
        let drop = self.buf.len() - keep;
        // every octave's next start is ≥ newest − 2m + 1 ≥ newest − 2·max_m + 1, inside the kept part
        self.buf.drain(..drop);
        self.base += drop;
        // fold the kept phase's linear trend into the offset
        let n = self.buf.len();
        if n >= 2 {
            let x0 = self.buf[0];
            let slope = (self.buf[n - 1] - x0) / (n - 1) as f64;
            for (j, v) in self.buf.iter_mut().enumerate() {
                *v -= x0 + slope * j as f64;
            }
            let newest = self.buf[n - 1];
            self.acc = Neumaier::default();
            self.acc.add(newest);
            if let Some(o) = self.offset.as_mut() {
                *o += slope;
            }
        }
    }

    /// The octave OADEV points so far (m ≤ `max_m` with at least two terms).
    pub fn deviations(&self) -> Result<Vec<RawPoint>> {
        let n = self.len();
        if n < crate::curve::MIN_SAMPLES {
            return Err(if n == 0 {
                Error::Empty
            } else {
                Error::TooShort {
                    what: "a stability curve",
                    needed: crate::curve::MIN_SAMPLES,
                    got: n,
                }
            });
        }
        let pts: Vec<RawPoint> = self
            .octaves
            .iter()
            .filter(|o| o.next >= 2)
            .map(|o| {
                let mf = o.m as f64;
                RawPoint {
                    tau_s: mf * self.tau0_s,
                    m: o.m,
                    deviation: (o.sum.value() / (2.0 * mf * mf * o.next as f64)).sqrt(),
                    n_terms: o.next,
                }
            })
            .collect();
        if pts.is_empty() {
            return Err(Error::NoTaus { n });
        }
        Ok(pts)
    }

    /// The curve with EDF and intervals; without the record the noise type comes from the fitted
    /// model ([`crate::NoiseIdMethod::ModelDominantTerm`]), never from the autocorrelation.
    pub fn curve(&self) -> Result<Curve> {
        let raw = self.deviations()?;
        let n = self.len();
        Ok(Curve {
            estimator: Estimator::Oadev,
            tau0_s: self.tau0_s,
            n_samples: n,
            points: crate::phase::infallible(complete::<[f64]>(
                Estimator::Oadev,
                self.tau0_s,
                n,
                &raw,
                None,
            )),
        })
    }
}
