//! The five estimators as kernels over the prefix sums `P` (phase / τ0) of a rate record.
//!
//! Each kernel is one pass over `P` for one averaging factor, reading it as a few sequential
//! streams a block at a time ([`crate::phase`]: the same code from memory and from a file, so
//! the same bits); allantools' definitions (on phase x = τ0·P with N+1 points) are reproduced
//! term for term:
//!
//! | estimator | terms n | σ² |
//! |---|---|---|
//! | OADEV | `N+1−2m` | `Σ (P[i+2m] − 2P[i+m] + P[i])² / (2 m² n)` |
//! | ADEV | ⌊N/m⌋ − 1 | same sum with stride m |
//! | MDEV | `N+1−3m+1` | `Σ_j (Σ_{i=j}^{j+m−1} P[i+2m] − 2P[i+m] + P[i])² / (2 m⁴ n)` |
//! | OHDEV | `N+1−3m` | `Σ (P[i+3m] − 3P[i+2m] + 3P[i+m] − P[i])² / (6 m² n)` |
//! | TOTDEV | `N−1` | `Σ_{k=1}^{N−1} (P*[k−m] − 2P[k] + P*[k+m])² / (2 m² n), P* reflected at both ends` |

use crate::phase::{BLOCK, PhaseCursor, PhaseSource, infallible};
use crate::sum::{Neumaier, block_sum_sq};

/// Which member of the Allan-variance family.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum Estimator {
    /// Overlapping Allan deviation (allantools `oadev`; the default and first choice).
    #[default]
    Oadev,
    /// Non-overlapping Allan deviation (allantools `adev`).
    Adev,
    /// Modified Allan deviation (allantools `mdev`).
    Mdev,
    /// Overlapping Hadamard deviation (allantools `ohdev`; insensitive to a linear rate drift).
    Ohdev,
    /// Total deviation (allantools `totdev`; reflected record, better confidence at long τ).
    Totdev,
}

impl Estimator {
    /// Every estimator, in declaration order.
    pub const ALL: [Estimator; 5] = [
        Estimator::Oadev,
        Estimator::Adev,
        Estimator::Mdev,
        Estimator::Ohdev,
        Estimator::Totdev,
    ];

    /// allantools' name of the estimator.
    pub fn name(self) -> &'static str {
        match self {
            Estimator::Oadev => "oadev",
            Estimator::Adev => "adev",
            Estimator::Mdev => "mdev",
            Estimator::Ohdev => "ohdev",
            Estimator::Totdev => "totdev",
        }
    }

    /// Order of the phase difference (2 for the Allan family, 3 for Hadamard).
    pub fn difference_order(self) -> u32 {
        match self {
            Estimator::Ohdev => 3,
            _ => 2,
        }
    }

    /// Stable32's stop ratio: the longest useful τ is T divided by this (adev 5, oadev 4, mdev 4,
    /// ohdev 4, totdev 2). Informative only: [`crate::Point::beyond_quarter`] always flags τ > T/4.
    pub fn stop_ratio(self) -> f64 {
        match self {
            Estimator::Adev => 5.0,
            Estimator::Totdev => 2.0,
            _ => 4.0,
        }
    }

    /// Number of terms the estimator averages at factor `m` on `n` rate samples (0 if none).
    pub fn n_terms(self, n: usize, m: usize) -> usize {
        let np = n + 1;
        match self {
            Estimator::Oadev => np.saturating_sub(2 * m),
            Estimator::Adev => {
                if m == 0 || 2 * m > n {
                    0
                } else {
                    (n - 2 * m) / m + 1
                }
            }
            Estimator::Mdev => {
                if 3 * m > np {
                    0
                } else {
                    np - 3 * m + 1
                }
            }
            Estimator::Ohdev => np.saturating_sub(3 * m),
            Estimator::Totdev => np.saturating_sub(2),
        }
    }

    /// The deviation at averaging factor `m` from prefix sums `p` (N+1 values), in the unit of the
    /// rate samples, with its number of terms; `None` when fewer than two terms remain (allantools
    /// drops those points) or `m` is 0 or too large.
    pub fn deviation(self, p: &[f64], m: usize) -> Option<(f64, usize)> {
        infallible(self.deviation_in(p, m))
    }

    /// [`Estimator::deviation`] from prefix sums anywhere ([`PhaseSource`]: memory or a file):
    /// the same code, so the same bits, whatever the source.
    pub fn deviation_in<S: PhaseSource + ?Sized>(
        self,
        p: &S,
        m: usize,
    ) -> Result<Option<(f64, usize)>, S::Error> {
        let points = p.points();
        if points < 2 || m == 0 {
            return Ok(None);
        }
        let n = self.n_terms(points - 1, m);
        if n < 2 {
            return Ok(None);
        }
        let mf = m as f64;
        let var = match self {
            Estimator::Oadev => oadev_sum(p, m, n)? / (2.0 * mf * mf * n as f64),
            Estimator::Adev => adev_sum(p, m, n)? / (2.0 * mf * mf * n as f64),
            Estimator::Ohdev => ohdev_sum(p, m, n)? / (6.0 * mf * mf * n as f64),
            Estimator::Mdev => mdev_sum(p, m, n)? / (2.0 * mf * mf * mf * mf * n as f64),
            Estimator::Totdev => totdev_sum(p, m)? / (2.0 * mf * mf * n as f64),
        };
        Ok(Some((var.sqrt(), n)))
    }
}

/// Σ (P[i+2m] − 2P[i+m] + P[i])², i < n: three streams.
fn oadev_sum<S: PhaseSource + ?Sized>(p: &S, m: usize, n: usize) -> Result<f64, S::Error> {
    let (mut ca, mut cb, mut cc) = (p.cursor(0), p.cursor(m), p.cursor(2 * m));
    let mut total = Neumaier::default();
    let mut done = 0;
    while done < n {
        let l = BLOCK.min(n - done);
        let (a, b, c) = (ca.next(l)?, cb.next(l)?, cc.next(l)?);
        total.add(block_sum_sq(l, |i| c[i] - 2.0 * b[i] + a[i]));
        done += l;
    }
    Ok(total.value())
}

/// Σ (P[km+2m] − 2P[km+m] + P[km])², k < n: the series decimated by m, gathered a block at a
/// time.
fn adev_sum<S: PhaseSource + ?Sized>(p: &S, m: usize, n: usize) -> Result<f64, S::Error> {
    let mut q = vec![0.0; BLOCK.min(n) + 2];
    let mut total = Neumaier::default();
    let mut done = 0;
    while done < n {
        let l = BLOCK.min(n - done);
        p.gather(done * m, m, &mut q[..l + 2])?;
        total.add(block_sum_sq(l, |i| q[i + 2] - 2.0 * q[i + 1] + q[i]));
        done += l;
    }
    Ok(total.value())
}

/// Σ (P[i+3m] − 3P[i+2m] + 3P[i+m] − P[i])², i < n: four streams.
fn ohdev_sum<S: PhaseSource + ?Sized>(p: &S, m: usize, n: usize) -> Result<f64, S::Error> {
    let (mut ca, mut cb, mut cc, mut cd) =
        (p.cursor(0), p.cursor(m), p.cursor(2 * m), p.cursor(3 * m));
    let mut total = Neumaier::default();
    let mut done = 0;
    while done < n {
        let l = BLOCK.min(n - done);
        let (a, b, c, d) = (ca.next(l)?, cb.next(l)?, cc.next(l)?, cd.next(l)?);
        total.add(block_sum_sq(l, |i| d[i] - 3.0 * c[i] + 3.0 * b[i] - a[i]));
        done += l;
    }
    Ok(total.value())
}

/// Error-free two-sum update of a running (hi, lo) sum.
#[inline]
fn two_sum_add(hi: &mut f64, lo: &mut f64, v: f64) {
    let s = *hi + v;
    let bp = s - *hi;
    let err = (*hi - (s - bp)) + (v - bp);
    *hi = s;
    *lo += err;
}

/// Σ_j term_j² for MDEV, the inner window sums slid along with a two-sum (error-free)
/// compensation: each second difference D(i) = P[i+2m] − 2P[i+m] + P[i] enters the running
/// window once and leaves once with the same rounding, so the window sum carries only the
/// rounding of the ≤ m differences inside it, never an accumulated drift. Streams at 0, m, 2m,
/// 3m: D(j) leaves as D(j+m) enters.
fn mdev_sum<S: PhaseSource + ?Sized>(p: &S, m: usize, n: usize) -> Result<f64, S::Error> {
    let mut hi = 0.0f64;
    let mut lo = 0.0f64;
    {
        let (mut ca, mut cb, mut cc) = (p.cursor(0), p.cursor(m), p.cursor(2 * m));
        let mut done = 0;
        while done < m {
            let l = BLOCK.min(m - done);
            let (a, b, c) = (ca.next(l)?, cb.next(l)?, cc.next(l)?);
            for k in 0..l {
                two_sum_add(&mut hi, &mut lo, c[k] - 2.0 * b[k] + a[k]);
            }
            done += l;
        }
    }
    let mut total = Neumaier::default();
    let mut block = 0.0;
    let (mut c0, mut c1, mut c2, mut c3) =
        (p.cursor(0), p.cursor(m), p.cursor(2 * m), p.cursor(3 * m));
    // j = 0 .. n−2 slide the window; j = n−1 only adds its term
    let mut j = 0;
    while j + 1 < n {
        let l = BLOCK.min(n - 1 - j);
        let (a, b, c, d) = (c0.next(l)?, c1.next(l)?, c2.next(l)?, c3.next(l)?);
        for k in 0..l {
            let t = hi + lo;
            block += t * t;
            if (j + k) % 1024 == 1023 {
                total.add(block);
                block = 0.0;
            }
            two_sum_add(&mut hi, &mut lo, d[k] - 2.0 * c[k] + b[k]);
            two_sum_add(&mut hi, &mut lo, -(c[k] - 2.0 * b[k] + a[k]));
        }
        j += l;
    }
    let t = hi + lo;
    block += t * t;
    if (n - 1) % 1024 == 1023 {
        total.add(block);
        block = 0.0;
    }
    total.add(block);
    Ok(total.value())
}

/// `out[i]` = x*[start + i] for the phase reflected about both ends
/// (x*[−j] = 2x[0] − x[j], x*[N+j] = 2x[N] − x[N−j]; `last` = N).
fn reflected<S: PhaseSource + ?Sized>(
    p: &S,
    start: isize,
    ends: (f64, f64),
    last: usize,
    out: &mut [f64],
) -> Result<(), S::Error> {
    let (x0, xn) = ends;
    let last_i = last as isize;
    let mut j = start;
    let mut o = 0usize;
    let len = out.len();
    if j < 0 && o < len {
        // x*[j] = 2x0 − x[−j], −j descending
        let cnt = ((-j) as usize).min(len - o);
        let hi = (-j) as usize; // index of x for out[o]
        let lo = hi + 1 - cnt;
        let part = &mut out[o..o + cnt];
        p.read_at(lo, part)?;
        part.reverse();
        for v in part.iter_mut() {
            *v = 2.0 * x0 - *v;
        }
        o += cnt;
        j += cnt as isize;
    }
    if o < len && j <= last_i {
        let cnt = ((last_i - j + 1) as usize).min(len - o);
        p.read_at(j as usize, &mut out[o..o + cnt])?;
        o += cnt;
        j += cnt as isize;
    }
    if o < len {
        // x*[j] = 2xn − x[2N − j], 2N − j descending
        let cnt = len - o;
        let hi = (2 * last_i - j) as usize;
        let lo = hi + 1 - cnt;
        let part = &mut out[o..];
        p.read_at(lo, part)?;
        part.reverse();
        for v in part.iter_mut() {
            *v = 2.0 * xn - *v;
        }
    }
    Ok(())
}

/// Σ for TOTDEV: phase points k = 1..=N−1 (of 0..=N), reflected about both ends
/// (x*[−j] = 2x[0] − x[j], x*[N+j] = 2x[N] − x[N−j]).
fn totdev_sum<S: PhaseSource + ?Sized>(p: &S, m: usize) -> Result<f64, S::Error> {
    let last = p.points() - 1; // N
    let count = last.saturating_sub(1);
    let mut one = [0.0];
    p.read_at(0, &mut one)?;
    let x0 = one[0];
    p.read_at(last, &mut one)?;
    let xn = one[0];
    let cap = BLOCK.min(count);
    let (mut left, mut mid, mut right) = (vec![0.0; cap], vec![0.0; cap], vec![0.0; cap]);
    let mut total = Neumaier::default();
    let mut done = 0;
    while done < count {
        let l = BLOCK.min(count - done);
        let k0 = done + 1;
        p.read_at(k0, &mut mid[..l])?;
        reflected(p, k0 as isize - m as isize, (x0, xn), last, &mut left[..l])?;
        reflected(p, (k0 + m) as isize, (x0, xn), last, &mut right[..l])?;
        total.add(block_sum_sq(l, |i| left[i] - 2.0 * mid[i] + right[i]));
        done += l;
    }
    Ok(total.value())
}
