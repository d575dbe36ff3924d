//! Power-law noise identification by the lag-1 autocorrelation (Riley & Greenhall, "Power law
//! noise identification using the lag 1 autocorrelation", EFTF 2004), as allantools
//! `autocorr_noise_id(x, af, data_type="phase")`.

/// How the noise type of a point was decided.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NoiseIdMethod {
    /// Lag-1 autocorrelation of the phase decimated by m (≥ 30 points after decimation).
    Lag1Autocorrelation,
    /// Too few points for the autocorrelation: the dominant term, at this τ, of the five-term gyro
    /// model fitted to the curve (Q → α=+2, N → 0, B → −1, K and R → −2, clamped to what the
    /// estimator's EDF supports).
    ModelDominantTerm,
    /// Neither: the α of the nearest point identified by the autocorrelation.
    NearestIdentified,
    /// Nothing to go on (e.g. a single point): white FM (α = 0) assumed.
    AssumedWhiteFm,
}

use crate::phase::{BLOCK, PhaseCursor, PhaseSource, infallible};
use crate::sum::neumaier_add;

/// Result of [`autocorr_noise_id`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct AutocorrId {
    /// Integer noise exponent α (S_y ∝ f^α), as allantools' `alpha_int`.
    pub alpha: i32,
    /// The non-integer estimate p + 2.
    pub alpha_float: f64,
    /// Number of differences taken.
    pub d: u32,
    /// ρ = r1 / (1 + r1) of the final series.
    pub rho: f64,
}

/// Minimum series length (after decimation) for the autocorrelation method, as allantools.
pub const MIN_POINTS: usize = 30;

/// Lag-1 autocorrelation noise identification on phase `x` (any scale: pass the prefix sums of a
/// rate record) at averaging factor `af`: decimate by `af`, remove a quadratic, difference up to
/// `dmax` times while ρ ≥ 0.25. `None` if fewer than [`MIN_POINTS`] points remain.
pub fn autocorr_noise_id(x: &[f64], af: usize, dmax: u32) -> Option<AutocorrId> {
    infallible(autocorr_noise_id_in(x, af, dmax))
}

/// [`autocorr_noise_id`] on phase anywhere ([`PhaseSource`]: memory or a file), in three
/// sequential passes over the decimated series with no copy of it: the quadratic, then the mean
/// of every difference order that may be needed, then their lag-1 sums. Each value of a
/// differenced series is recomputed from the last d+1 residuals with the same operations as
/// differencing in place, and each order's sums run in index order as [`lag1_acf`]'s, so the
/// result is the same bits from memory and from a file (and as differencing a copy).
pub fn autocorr_noise_id_in<S: PhaseSource + ?Sized>(
    x: &S,
    af: usize,
    dmax: u32,
) -> Result<Option<AutocorrId>, S::Error> {
    let af = af.max(1);
    let points = x.points();
    let len = if points == 0 {
        0
    } else {
        (points - 1) / af + 1
    };
    if len < MIN_POINTS {
        return Ok(None);
    }
    let quad = Quadratic::fit(x, af, len)?;
    // the orders the loop below can reach: up to dmax, and while two values remain
    let levels = (dmax as usize).min(len - 2);
    let r1 = lag1_acfs(x, af, len, &quad, levels)?;
    let mut d = 0u32;
    loop {
        let r1 = r1[d as usize];
        let rho = r1 / (1.0 + r1);
        if rho < 0.25 || d >= dmax {
            let p = -2.0 * (rho + f64::from(d));
            let alpha_float = p + 2.0;
            let alpha = (-(2.0 * rho).round_ties_even() - 2.0 * f64::from(d)) as i32 + 2;
            return Ok(Some(AutocorrId {
                alpha,
                alpha_float,
                d,
                rho,
            }));
        }
        d += 1;
        if len - d as usize <= 1 {
            return Ok(None);
        }
    }
}

/// Calls `f` with the decimated series `x[0], x[af], …` (`len` values) a chunk at a time, with
/// the index of the chunk's first value (no copy from memory when `af` = 1).
fn for_each_decimated<S: PhaseSource + ?Sized>(
    x: &S,
    af: usize,
    len: usize,
    mut f: impl FnMut(usize, &[f64]),
) -> Result<(), S::Error> {
    let mut done = 0;
    if af == 1 {
        let mut c = x.cursor(0);
        while done < len {
            let l = BLOCK.min(len - done);
            f(done, c.next(l)?);
            done += l;
        }
        return Ok(());
    }
    let mut buf = vec![0.0; BLOCK.min(len)];
    while done < len {
        let l = BLOCK.min(len - done);
        x.gather(done * af, af, &mut buf[..l])?;
        f(done, &buf[..l]);
        done += l;
    }
    Ok(())
}

/// The least-squares quadratic in the index (numpy `polyfit(t, x, 2)`), in the discrete
/// orthogonal polynomials 1, u, u² − ⟨u²⟩ with u = t − (n−1)/2.
struct Quadratic {
    c: f64,
    u2m: f64,
    b: [f64; 3],
}

impl Quadratic {
    #[inline]
    fn q1(&self, i: usize) -> f64 {
        i as f64 - self.c
    }
    #[inline]
    fn q2(&self, i: usize) -> f64 {
        (i as f64 - self.c).powi(2) - self.u2m
    }

    fn fit<S: PhaseSource + ?Sized>(x: &S, af: usize, n: usize) -> Result<Quadratic, S::Error> {
        let mut q = Quadratic {
            c: (n as f64 - 1.0) / 2.0,
            u2m: ((n * n) as f64 - 1.0) / 12.0,
            b: [0.0; 3],
        };
        let (mut s0, mut s1, mut s2, mut n1, mut n2) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for_each_decimated(x, af, n, |i0, chunk| {
            for (k, &v) in chunk.iter().enumerate() {
                let i = i0 + k;
                s0 += v;
                s1 += v * q.q1(i);
                s2 += v * q.q2(i);
                n1 += q.q1(i) * q.q1(i);
                n2 += q.q2(i) * q.q2(i);
            }
        })?;
        q.b = [
            s0 / n as f64,
            if n1 > 0.0 { s1 / n1 } else { 0.0 },
            if n2 > 0.0 { s2 / n2 } else { 0.0 },
        ];
        Ok(q)
    }

    /// The residual of value `v` at index `i`.
    #[inline]
    fn residual(&self, i: usize, v: f64) -> f64 {
        v - (self.b[0] + self.b[1] * self.q1(i) + self.b[2] * self.q2(i))
    }
}

/// Per-order state of the difference passes: an array when the number of orders is known at
/// compile time (the loops unroll), a vector otherwise; one code for both.
trait Lanes: Clone {
    fn zeros(n: usize) -> Self;
    fn get(&self) -> &[f64];
    fn get_mut(&mut self) -> &mut [f64];
}

impl<const N: usize> Lanes for [f64; N] {
    fn zeros(_: usize) -> Self {
        [0.0; N]
    }
    #[inline]
    fn get(&self) -> &[f64] {
        self
    }
    #[inline]
    fn get_mut(&mut self) -> &mut [f64] {
        self
    }
}

impl Lanes for Vec<f64> {
    fn zeros(n: usize) -> Self {
        vec![0.0; n]
    }
    #[inline]
    fn get(&self) -> &[f64] {
        self
    }
    #[inline]
    fn get_mut(&mut self) -> &mut [f64] {
        self
    }
}

/// Calls `f(values, i, ready)` for every index i of the residual series: `values[ℓ]` is the value of
/// difference order ℓ at index i − ℓ (from the residuals i − ℓ ..= i, differenced as
/// `v[j] = v[j+1] − v[j]` in place would), for the orders ℓ ≤ `ready` = min(i, top) that index
/// completes. `B` holds top + 1 values.
fn for_each_differenced<B: Lanes, S: PhaseSource + ?Sized>(
    x: &S,
    af: usize,
    len: usize,
    quad: &Quadratic,
    top: usize,
    mut f: impl FnMut(&B, usize, usize),
) -> Result<(), S::Error> {
    let mut window = B::zeros(top + 1);
    let mut out = B::zeros(top + 1);
    for_each_decimated(x, af, len, |i0, chunk| {
        for (k, &v) in chunk.iter().enumerate() {
            let i = i0 + k;
            let w = window.get_mut();
            w.copy_within(1.., 0);
            w[top] = quad.residual(i, v);
            let mut t = window.clone();
            let (t, o) = (t.get_mut(), out.get_mut());
            o[0] = t[top];
            if i >= top {
                // the steady state, with bounds the compiler knows for an array: unrolled
                for level in 1..t.len() {
                    for j in 0..t.len() - level {
                        t[j] = t[j + 1] - t[j];
                    }
                    o[level] = t[t.len() - 1 - level];
                }
                f(&out, i, top);
            } else {
                for level in 1..=i {
                    for j in top - i..=top - level {
                        t[j] = t[j + 1] - t[j];
                    }
                    o[level] = t[top - level];
                }
                f(&out, i, i);
            }
        }
    })
}

/// [`lag1_acf`] of the residual series differenced 0..=`top` times: the means in one pass, the
/// lag-1 sums in a second (each order's sums in index order, as [`lag1_acf`]'s).
fn lag1_acfs<S: PhaseSource + ?Sized>(
    x: &S,
    af: usize,
    len: usize,
    quad: &Quadratic,
    top: usize,
) -> Result<Vec<f64>, S::Error> {
    match top {
        0 => lag1_acfs_in::<[f64; 1], S>(x, af, len, quad, top),
        1 => lag1_acfs_in::<[f64; 2], S>(x, af, len, quad, top),
        2 => lag1_acfs_in::<[f64; 3], S>(x, af, len, quad, top),
        3 => lag1_acfs_in::<[f64; 4], S>(x, af, len, quad, top),
        _ => lag1_acfs_in::<Vec<f64>, S>(x, af, len, quad, top),
    }
}

fn lag1_acfs_in<B: Lanes, S: PhaseSource + ?Sized>(
    x: &S,
    af: usize,
    len: usize,
    quad: &Quadratic,
    top: usize,
) -> Result<Vec<f64>, S::Error> {
    // Neumaier sums per order (as sum::mean), kept as two lanes
    let (mut sum, mut comp) = (B::zeros(top + 1), B::zeros(top + 1));
    for_each_differenced::<B, S>(x, af, len, quad, top, |v, _, ready| {
        let (s, c, v) = (sum.get_mut(), comp.get_mut(), v.get());
        // every order once the window is full (a bound known for an array), else the ready ones
        let n = if ready == top { v.len() } else { ready + 1 };
        for l in 0..n {
            neumaier_add(&mut s[l], &mut c[l], v[l]);
        }
    })?;
    let mut mu = B::zeros(top + 1);
    for l in 0..=top {
        mu.get_mut()[l] = (sum.get()[l] + comp.get()[l]) / (len - l) as f64;
    }
    let (mut a, mut b, mut prev) = (B::zeros(top + 1), B::zeros(top + 1), B::zeros(top + 1));
    for_each_differenced::<B, S>(x, af, len, quad, top, |v, i, ready| {
        let (a, b, prev, mu, v) = (a.get_mut(), b.get_mut(), prev.get_mut(), mu.get(), v.get());
        let n = if ready == top { v.len() } else { ready + 1 };
        for l in 0..n {
            let m = mu[l];
            // order l's first value comes at index l: no pair before it
            if i > l {
                a[l] += (prev[l] - m) * (v[l] - m);
            }
            b[l] += (v[l] - m) * (v[l] - m);
            prev[l] = v[l];
        }
    })?;
    Ok((0..=top).map(|l| a.get()[l] / b.get()[l]).collect())
}

/// Lag-1 autocorrelation with the mean removed (allantools `lag1_acf`).
pub fn lag1_acf(x: &[f64]) -> f64 {
    let mu = crate::sum::mean(x);
    let mut a = 0.0;
    let mut b = 0.0;
    for w in x.windows(2) {
        a += (w[0] - mu) * (w[1] - mu);
    }
    for &v in x {
        b += (v - mu) * (v - mu);
    }
    a / b
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    /// The method as first written: decimate into a copy, detrend it in place, difference it in
    /// place. The streamed passes must give the same bits for every difference order.
    fn in_place(x: &[f64], af: usize, dmax: u32) -> Option<AutocorrId> {
        let mut v: Vec<f64> = x.iter().step_by(af.max(1)).copied().collect();
        if v.len() < MIN_POINTS {
            return None;
        }
        let n = v.len();
        let c = (n as f64 - 1.0) / 2.0;
        let u2m = ((n * n) as f64 - 1.0) / 12.0;
        let q1 = |i: usize| i as f64 - c;
        let q2 = |i: usize| (i as f64 - c).powi(2) - u2m;
        let (mut s0, mut s1, mut s2, mut n1, mut n2) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (i, &v) in v.iter().enumerate() {
            s0 += v;
            s1 += v * q1(i);
            s2 += v * q2(i);
            n1 += q1(i) * q1(i);
            n2 += q2(i) * q2(i);
        }
        let b0 = s0 / n as f64;
        let b1 = if n1 > 0.0 { s1 / n1 } else { 0.0 };
        let b2 = if n2 > 0.0 { s2 / n2 } else { 0.0 };
        for (i, v) in v.iter_mut().enumerate() {
            *v -= b0 + b1 * q1(i) + b2 * q2(i);
        }
        let mut d = 0u32;
        loop {
            let r1 = lag1_acf(&v);
            let rho = r1 / (1.0 + r1);
            if rho < 0.25 || d >= dmax {
                let p = -2.0 * (rho + f64::from(d));
                let alpha = (-(2.0 * rho).round_ties_even() - 2.0 * f64::from(d)) as i32 + 2;
                return Some(AutocorrId {
                    alpha,
                    alpha_float: p + 2.0,
                    d,
                    rho,
                });
            }
            for i in 0..v.len() - 1 {
                v[i] = v[i + 1] - v[i];
            }
            v.pop();
            d += 1;
            if v.len() < 2 {
                return None;
            }
        }
    }

    #[test]
    fn the_streamed_passes_give_the_in_place_bits_for_every_order() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut rnd = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        // white noise integrated 0 to 6 times: the higher, the more differences it takes
        let mut series = vec![(0..3_000).map(|_| rnd()).collect::<Vec<f64>>()];
        for k in 0..6 {
            let mut acc = 0.0;
            let next: Vec<f64> = series[k]
                .iter()
                .map(|v| {
                    acc += v;
                    acc
                })
                .collect();
            series.push(next);
        }
        let mut orders = std::collections::BTreeSet::new();
        for x in &series {
            for af in [1usize, 2, 5, 31, 100] {
                for dmax in [0u32, 1, 2, 3, 4, 6, 9] {
                    let want = in_place(x, af, dmax);
                    let got = autocorr_noise_id(x, af, dmax);
                    assert_eq!(
                        format!("{want:?}"),
                        format!("{got:?}"),
                        "af {af} dmax {dmax}"
                    );
                    if let Some(id) = got {
                        orders.insert(id.d);
                    }
                }
            }
        }
        // the orders the test reached, the vector lanes (d > 3) among them
        assert!(orders.iter().any(|&d| d > 3), "{orders:?}");
        assert!(orders.contains(&0) && orders.contains(&2), "{orders:?}");
    }
}
