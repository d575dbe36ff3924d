//! The five estimators as kernels over the prefix sums `P` (phase / τ0) of a rate record.
//!
//! Each kernel is one pass over `P` for one averaging factor, without temporaries; allantools'
//! definitions (on phase x = τ0·P with N+1 points) are reproduced term for term:
//!
//! | estimator | terms n | σ² |
//! |---|---|---|
//! | OADEV | `N+1−2m` | `Σ (P[i+2m] − 2P[i+m] + P[i])² / (2 m² n)` |
//! | ADEV | ⌊N/m⌋ − 1 | same sum with stride m |
//! | MDEV | `N+1−3m+1` | `Σ_j (Σ_{i=j}^{j+m−1} P[i+2m] − 2P[i+m] + P[i])² / (2 m⁴ n)` |
//! | OHDEV | `N+1−3m` | `Σ (P[i+3m] − 3P[i+2m] + 3P[i+m] − P[i])² / (6 m² n)` |
//! | TOTDEV | `N−1` | `Σ_{k=1}^{N−1} (P*[k−m] − 2P[k] + P*[k+m])² / (2 m² n), P* reflected at both ends` |

use crate::sum::sum_sq;

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
        if p.len() < 2 || m == 0 {
            return None;
        }
        let n = self.n_terms(p.len() - 1, m);
        if n < 2 {
            return None;
        }
        let mf = m as f64;
        let var = match self {
            Estimator::Oadev => {
                let (a, b, c) = (&p[..n], &p[m..m + n], &p[2 * m..2 * m + n]);
                sum_sq(n, |i| c[i] - 2.0 * b[i] + a[i]) / (2.0 * mf * mf * n as f64)
            }
            Estimator::Adev => {
                sum_sq(n, |k| {
                    let i = k * m;
                    p[i + 2 * m] - 2.0 * p[i + m] + p[i]
                }) / (2.0 * mf * mf * n as f64)
            }
            Estimator::Ohdev => {
                let (a, b, c, d) = (
                    &p[..n],
                    &p[m..m + n],
                    &p[2 * m..2 * m + n],
                    &p[3 * m..3 * m + n],
                );
                sum_sq(n, |i| d[i] - 3.0 * c[i] + 3.0 * b[i] - a[i]) / (6.0 * mf * mf * n as f64)
            }
            Estimator::Mdev => mdev_sum(p, m, n) / (2.0 * mf * mf * mf * mf * n as f64),
            Estimator::Totdev => totdev_sum(p, m) / (2.0 * mf * mf * n as f64),
        };
        Some((var.sqrt(), n))
    }
}

/// Σ_j term_j² for MDEV, the inner window sums slid along with a two-sum (error-free)
/// compensation: each second difference D(i) enters the running window once and leaves once with
/// the same rounding, so the window sum carries only the rounding of the ≤ m differences inside
/// it, never an accumulated drift.
fn mdev_sum(p: &[f64], m: usize, n: usize) -> f64 {
    let d = |i: usize| p[i + 2 * m] - 2.0 * p[i + m] + p[i];
    let mut hi = 0.0f64;
    let mut lo = 0.0f64;
    let add = |hi: &mut f64, lo: &mut f64, v: f64| {
        let s = *hi + v;
        let bp = s - *hi;
        let err = (*hi - (s - bp)) + (v - bp);
        *hi = s;
        *lo += err;
    };
    for i in 0..m {
        add(&mut hi, &mut lo, d(i));
    }
    let mut total = crate::sum::Neumaier::default();
    let mut block = 0.0;
    for j in 0..n {
        let t = hi + lo;
        block += t * t;
        if j % 1024 == 1023 {
            total.add(block);
            block = 0.0;
        }
        if j + 1 < n {
            add(&mut hi, &mut lo, d(j + m));
            add(&mut hi, &mut lo, -d(j));
        }
    }
    total.add(block);
    total.value()
}

/// Σ for TOTDEV: phase points k = 1..=N−1 (of 0..=N), reflected about both ends
/// (x*[−j] = 2x[0] − x[j], x*[N+j] = 2x[N] − x[N−j]).
fn totdev_sum(p: &[f64], m: usize) -> f64 {
    let last = p.len() - 1; // N
    let x0 = p[0];
    let xn = p[last];
    let xs = |k: isize| -> f64 {
        if k < 0 {
            2.0 * x0 - p[(-k) as usize]
        } else if (k as usize) > last {
            2.0 * xn - p[2 * last - k as usize]
        } else {
            p[k as usize]
        }
    };
    let mi = m as isize;
    sum_sq(last.saturating_sub(1), |i| {
        let k = i as isize + 1;
        xs(k - mi) - 2.0 * p[k as usize] + xs(k + mi)
    })
}
