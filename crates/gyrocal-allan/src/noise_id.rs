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

use crate::phase::{BLOCK, PhaseSource, infallible};

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

/// [`autocorr_noise_id`] on phase anywhere ([`PhaseSource`]: memory or a file), in sequential
/// passes over the decimated series with no copy of it: one for the quadratic, then two per
/// difference order (the mean, then the lag-1 sums), each value of the differenced series
/// recomputed from the last d+1 residuals with the same operations as differencing in place, so
/// the result is the same bits from memory and from a file.
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
    let mut d = 0u32;
    loop {
        let r1 = lag1_acf_in(x, af, len, &quad, d)?;
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

/// Calls `f` with the decimated series `x[0], x[af], …` (`len` values) in order.
fn for_each_decimated<S: PhaseSource + ?Sized>(
    x: &S,
    af: usize,
    len: usize,
    mut f: impl FnMut(usize, f64),
) -> Result<(), S::Error> {
    let mut buf = vec![0.0; BLOCK.min(len)];
    let mut done = 0;
    while done < len {
        let l = BLOCK.min(len - done);
        x.gather(done * af, af, &mut buf[..l])?;
        for (k, &v) in buf[..l].iter().enumerate() {
            f(done + k, v);
        }
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
    fn q1(&self, i: usize) -> f64 {
        i as f64 - self.c
    }
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
        for_each_decimated(x, af, n, |i, v| {
            s0 += v;
            s1 += v * q.q1(i);
            s2 += v * q.q2(i);
            n1 += q.q1(i) * q.q1(i);
            n2 += q.q2(i) * q.q2(i);
        })?;
        q.b = [
            s0 / n as f64,
            if n1 > 0.0 { s1 / n1 } else { 0.0 },
            if n2 > 0.0 { s2 / n2 } else { 0.0 },
        ];
        Ok(q)
    }

    /// The residual of value `v` at index `i`.
    fn residual(&self, i: usize, v: f64) -> f64 {
        v - (self.b[0] + self.b[1] * self.q1(i) + self.b[2] * self.q2(i))
    }
}

/// Calls `f` with the residual series differenced `d` times (`len − d` values) in order: each
/// value from the last d+1 residuals, differenced as `v[i] = v[i+1] − v[i]` in place would.
fn for_each_differenced<S: PhaseSource + ?Sized>(
    x: &S,
    af: usize,
    len: usize,
    quad: &Quadratic,
    d: u32,
    mut f: impl FnMut(f64),
) -> Result<(), S::Error> {
    let d = d as usize;
    let mut window = vec![0.0; d + 1];
    let mut tmp = vec![0.0; d + 1];
    for_each_decimated(x, af, len, |i, v| {
        window.copy_within(1.., 0);
        window[d] = quad.residual(i, v);
        if i < d {
            return;
        }
        tmp.copy_from_slice(&window);
        for level in 1..=d {
            for k in 0..=d - level {
                tmp[k] = tmp[k + 1] - tmp[k];
            }
        }
        f(tmp[0]);
    })
}

/// [`lag1_acf`] of the residual series differenced `d` times, in two passes.
fn lag1_acf_in<S: PhaseSource + ?Sized>(
    x: &S,
    af: usize,
    len: usize,
    quad: &Quadratic,
    d: u32,
) -> Result<f64, S::Error> {
    let count = len - d as usize;
    let mut s = crate::sum::Neumaier::default();
    for_each_differenced(x, af, len, quad, d, |v| s.add(v))?;
    let mu = s.value() / count as f64;
    let mut a = 0.0;
    let mut b = 0.0;
    let mut prev: Option<f64> = None;
    for_each_differenced(x, af, len, quad, d, |v| {
        if let Some(p) = prev {
            a += (p - mu) * (v - mu);
        }
        b += (v - mu) * (v - mu);
        prev = Some(v);
    })?;
    Ok(a / b)
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
