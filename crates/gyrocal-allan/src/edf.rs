//! Equivalent degrees of freedom and chi-squared confidence intervals.
//!
//! [`edf_greenhall`] is Greenhall & Riley's algorithm ("Uncertainty of stability variances based
//! on finite differences", 35th PTTI, 2003), ported line by line from allantools
//! `ci.edf_greenhall` so that the values agree to rounding; the one case allantools leaves
//! unimplemented (white PM, unmodified variance, K = ⌈M/S⌉ ≤ d) is computed with the exact basic
//! sum (Greenhall's eq. 10), which every case approximates.

use statrs::distribution::{ChiSquared, Continuous, ContinuousCDF};

/// allantools' "one sigma" coverage, erf(1/√2) = 0.682689…
pub const ONE_SIGMA_COVERAGE: f64 = 0.682_689_492_137_085_9;

fn sw(t: f64, alpha: i32) -> f64 {
    match alpha {
        2 => -t.abs(),
        1 => {
            if t == 0.0 {
                0.0
            } else {
                t * t * t.abs().ln()
            }
        }
        0 => (t * t * t).abs(),
        -1 => {
            if t == 0.0 {
                0.0
            } else {
                t.powi(4) * t.abs().ln()
            }
        }
        -2 => t.powi(5).abs(),
        -3 => {
            if t == 0.0 {
                0.0
            } else {
                t.powi(6) * t.abs().ln()
            }
        }
        _ => t.powi(7).abs(),
    }
}

fn sx(t: f64, f: f64, alpha: i32) -> f64 {
    if f.is_infinite() {
        return sw(t, alpha + 2);
    }
    let a = 2.0 * sw(t, alpha);
    let b = sw(t - 1.0 / f, alpha);
    let c = sw(t + 1.0 / f, alpha);
    f * f * (a - b - c)
}

fn sz(t: f64, f: f64, alpha: i32, d: u32) -> f64 {
    match d {
        1 => 2.0 * sx(t, f, alpha) - sx(t - 1.0, f, alpha) - sx(t + 1.0, f, alpha),
        2 => {
            6.0 * sx(t, f, alpha) - 4.0 * sx(t - 1.0, f, alpha) - 4.0 * sx(t + 1.0, f, alpha)
                + sx(t - 2.0, f, alpha)
                + sx(t + 2.0, f, alpha)
        }
        _ => {
            20.0 * sx(t, f, alpha) - 15.0 * sx(t - 1.0, f, alpha) - 15.0 * sx(t + 1.0, f, alpha)
                + 6.0 * sx(t - 2.0, f, alpha)
                + 6.0 * sx(t + 2.0, f, alpha)
                - sx(t - 3.0, f, alpha)
                - sx(t + 3.0, f, alpha)
        }
    }
}

fn basic_sum(j: f64, m: f64, s: f64, f: f64, alpha: i32, d: u32) -> f64 {
    let first = sz(0.0, f, alpha, d).powi(2);
    let second = (1.0 - j / m) * sz(j / s, f, alpha, d).powi(2);
    let mut third = 0.0;
    let jn = j as i64;
    for k in 1..jn {
        let k = k as f64;
        third += 2.0 * (1.0 - k / m) * sz(k / s, f, alpha, d).powi(2);
    }
    first + second + third
}

fn table1(alpha: i32, d: u32) -> (f64, f64) {
    const T: [[(f64, f64); 3]; 7] = [
        [
            (2.0 / 3.0, 1.0 / 3.0),
            (7.0 / 9.0, 1.0 / 2.0),
            (22.0 / 25.0, 2.0 / 3.0),
        ],
        [(0.840, 0.345), (0.997, 0.616), (1.141, 0.843)],
        [(1.079, 0.368), (1.033, 0.607), (1.184, 0.848)],
        [(-1.0, -1.0), (1.048, 0.534), (1.180, 0.816)],
        [(-1.0, -1.0), (1.302, 0.535), (1.175, 0.777)],
        [(-1.0, -1.0), (-1.0, -1.0), (1.194, 0.703)],
        [(-1.0, -1.0), (-1.0, -1.0), (1.489, 0.702)],
    ];
    T[(2 - alpha) as usize][(d - 1) as usize]
}

fn table2(alpha: i32, d: u32) -> (f64, f64) {
    const T: [[(f64, f64); 3]; 7] = [
        [
            (3.0 / 2.0, 1.0 / 2.0),
            (35.0 / 18.0, 1.0),
            (231.0 / 100.0, 3.0 / 2.0),
        ],
        [(78.6, 25.2), (790.0, 410.0), (9950.0, 6520.0)],
        [
            (2.0 / 3.0, 1.0 / 6.0),
            (2.0 / 3.0, 1.0 / 3.0),
            (7.0 / 9.0, 1.0 / 2.0),
        ],
        [(-1.0, -1.0), (0.852, 0.375), (0.997, 0.617)],
        [(-1.0, -1.0), (1.079, 0.368), (1.033, 0.607)],
        [(-1.0, -1.0), (-1.0, -1.0), (1.053, 0.553)],
        [(-1.0, -1.0), (-1.0, -1.0), (1.302, 0.535)],
    ];
    T[(2 - alpha) as usize][(d - 1) as usize]
}

fn table3(d: u32) -> (f64, f64) {
    [(6.0, 4.0), (15.23, 12.0), (47.8, 40.0)][(d - 1) as usize]
}

fn binom(n: u32, k: u32) -> f64 {
    (0..k).fold(1.0, |acc, i| acc * f64::from(n - i) / f64::from(i + 1))
}

/// Greenhall's equivalent degrees of freedom.
///
/// `alpha`: noise exponent (+2 white PM … −4), `d`: difference order (1, 2 = Allan, 3 =
/// Hadamard), `m`: averaging factor, `n_phase`: number of phase points (N+1 for N rate samples),
/// `overlapping`/`modified` as for allantools. Returns `None` where the algorithm is undefined
/// (α + 2d ≤ 1, α outside −4..=2, d outside 1..=3, m = 0, or too few points).
pub fn edf_greenhall(
    alpha: i32,
    d: u32,
    m: usize,
    n_phase: usize,
    overlapping: bool,
    modified: bool,
) -> Option<f64> {
    if !(1..=3).contains(&d) || !(-4..=2).contains(&alpha) || alpha + 2 * d as i32 <= 1 || m == 0 {
        return None;
    }
    let df = f64::from(d);
    let mf = m as f64;
    let nf = n_phase as f64;
    let f = if modified { 1.0 } else { mf };
    let s = if overlapping { mf } else { 1.0 };
    let l = mf / f + mf * df;
    let big_m = 1.0 + (s * (nf - l) / mf).floor();
    if big_m < 1.0 {
        return None;
    }
    let j = big_m.min((df + 1.0) * s);
    let j_max = 100.0;
    let r = big_m / s;
    let inv = if modified {
        if j <= j_max {
            (1.0 / (sz(0.0, 1.0, alpha, d).powi(2) * big_m)) * basic_sum(j, big_m, s, 1.0, alpha, d)
        } else if r > df + 1.0 {
            let (a0, a1) = table1(alpha, d);
            (1.0 / r) * (a0 - a1 / r)
        } else {
            let m_prime = j_max / r;
            (1.0 / (sz(0.0, f, alpha, d).powi(2) * j_max))
                * basic_sum(j_max, j_max, m_prime, 1.0, alpha, d)
        }
    } else if alpha <= 0 {
        if j <= j_max {
            let m_prime = if mf * (df + 1.0) <= j_max {
                mf
            } else {
                f64::INFINITY
            };
            (1.0 / (sz(0.0, m_prime, alpha, d).powi(2) * big_m))
                * basic_sum(j, big_m, s, m_prime, alpha, d)
        } else if r > df + 1.0 {
            let (a0, a1) = table2(alpha, d);
            (1.0 / r) * (a0 - a1 / r)
        } else {
            let m_prime = j_max / r;
            (1.0 / (sz(0.0, f64::INFINITY, alpha, d).powi(2) * j_max))
                * basic_sum(j_max, j_max, m_prime, f64::INFINITY, alpha, d)
        }
    } else if alpha == 1 {
        if j <= j_max {
            (1.0 / (sz(0.0, mf, 1, d).powi(2) * big_m)) * basic_sum(j, big_m, s, mf, 1, d)
        } else if r > df + 1.0 {
            let (a0, a1) = table2(alpha, d);
            let (b0, b1) = table3(d);
            (1.0 / ((b0 + b1 * mf.ln()).powi(2) * r)) * (a0 - a1 / r)
        } else {
            let m_prime = j_max / r;
            let (b0, b1) = table3(d);
            (1.0 / ((b0 + b1 * mf.ln()).powi(2) * j_max))
                * basic_sum(j_max, j_max, m_prime, m_prime, 1, d)
        }
    } else {
        // alpha == 2, unmodified
        let k = r.ceil();
        if k <= df {
            // not in allantools: the exact basic sum (eq. 10) with F = m
            if j <= j_max {
                (1.0 / (sz(0.0, mf, 2, d).powi(2) * big_m)) * basic_sum(j, big_m, s, mf, 2, d)
            } else {
                return None;
            }
        } else {
            let a0 = binom(4 * d, 2 * d) / binom(2 * d, d).powi(2);
            let a1 = df / 2.0;
            (1.0 / big_m) * (a0 - a1 / r)
        }
    };
    let edf = 1.0 / inv;
    (edf.is_finite() && edf > 0.0).then_some(edf)
}

/// EDF of the total variance (NIST SP 1065 Table 7, as allantools `edf_totdev`):
/// b·(N/m) − c for white FM (1.50, 0), flicker FM (1.17, 0.22), random-walk FM (0.93, 0.36), with
/// N the number of rate samples (T/τ = N/m); other α use [`edf_simple`]. `None` if not positive.
pub fn edf_totdev(n: usize, m: usize, alpha: i32) -> Option<f64> {
    let (b, c) = match alpha {
        0 => (1.50, 0.0),
        -1 => (1.17, 0.22),
        -2 => (0.93, 0.36),
        _ => return edf_simple(n, m, alpha),
    };
    let edf = b * (n as f64 / m as f64) - c;
    (edf.is_finite() && edf > 0.0).then_some(edf)
}

/// The simple EDF approximations for the non-overlapping ADEV (NIST SP 1065 Table 5, allantools
/// `edf_simple`); `n` phase samples. Unknown α gives N − 1. `None` if not positive.
pub fn edf_simple(n: usize, m: usize, alpha: i32) -> Option<f64> {
    let nf = n as f64;
    let mf = m as f64;
    let edf = match alpha {
        2 => (nf + 1.0) * (nf - 2.0 * mf) / (2.0 * (nf - mf)),
        0 => {
            ((3.0 * (nf - 1.0) / (2.0 * mf)) - (2.0 * (nf - 2.0) / nf))
                * ((4.0 * mf * mf) / ((4.0 * mf * mf) + 5.0))
        }
        1 => {
            let a = (nf - 1.0) / (2.0 * mf);
            let b = (2.0 * mf + 1.0) * (nf - 1.0) / 4.0;
            (a.ln() * b.ln()).sqrt().exp()
        }
        -1 => {
            if m == 1 {
                2.0 * (nf - 2.0) / (2.3 * nf - 4.9)
            } else {
                5.0 * nf * nf / (4.0 * mf * (nf + 3.0 * mf))
            }
        }
        -2 => {
            let a = (nf - 2.0) / (mf * (nf - 3.0).powi(2));
            let b = (nf - 1.0).powi(2);
            let c = 3.0 * mf * (nf - 1.0);
            let d = 4.0 * mf * mf;
            a * (b - c + d)
        }
        _ => nf - 1.0,
    };
    (edf.is_finite() && edf > 0.0).then_some(edf)
}

/// The `p`-quantile of the chi-squared distribution with `df` degrees of freedom: safeguarded
/// Newton iteration on statrs' CDF (on the survival function in the upper tail) inside a
/// bisection bracket, to full double precision. `None` for `df` ≤ 0 or `p` outside (0, 1).
pub fn chi2_quantile(p: f64, df: f64) -> Option<f64> {
    if !(p > 0.0 && p < 1.0 && df > 0.0 && df.is_finite()) {
        return None;
    }
    let dist = ChiSquared::new(df).ok()?;
    // increasing in x, zero at the quantile
    let g = |x: f64| {
        if p < 0.5 {
            dist.cdf(x) - p
        } else {
            (1.0 - p) - dist.sf(x)
        }
    };
    let mut lo = df.max(1.0);
    let mut hi = lo;
    while g(lo) > 0.0 {
        lo /= 4.0;
        if lo < 1e-300 {
            return Some(lo);
        }
    }
    while g(hi) < 0.0 {
        hi *= 2.0;
        if !hi.is_finite() {
            return None;
        }
    }
    let mut x = if lo > 0.0 { (lo * hi).sqrt() } else { hi / 2.0 };
    for _ in 0..200 {
        let gx = g(x);
        if gx == 0.0 {
            return Some(x);
        }
        if gx < 0.0 {
            lo = x;
        } else {
            hi = x;
        }
        let pdf = dist.pdf(x);
        let newton = x - gx / pdf;
        let next = if pdf > 0.0 && newton > lo && newton < hi {
            newton
        } else if hi / lo > 4.0 {
            (lo * hi).sqrt()
        } else {
            0.5 * (lo + hi)
        };
        if (next - x).abs() <= 4.0 * f64::EPSILON * x {
            return Some(next);
        }
        x = next;
    }
    Some(x)
}

/// The two-sided `coverage` interval (e.g. 0.95) of a deviation `dev` with `edf` degrees of
/// freedom, NIST SP 1065 eq. 45 as allantools `confidence_interval`:
/// σ·√(edf/χ²_{1−q}(edf)) … σ·√(edf/χ²_{q}(edf)), q = min(c, 1−c)/2.
pub fn confidence_interval(dev: f64, edf: f64, coverage: f64) -> Option<(f64, f64)> {
    let lo_p = coverage.min(1.0 - coverage).abs() / 2.0;
    let hi_p = 1.0 - lo_p;
    let chi_lo = chi2_quantile(lo_p, edf)?;
    let chi_hi = chi2_quantile(hi_p, edf)?;
    let var = dev * dev;
    Some(((edf * var / chi_hi).sqrt(), (edf * var / chi_lo).sqrt()))
}
