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
    let af = af.max(1);
    let mut v: Vec<f64> = x.iter().step_by(af).copied().collect();
    if v.len() < MIN_POINTS {
        return None;
    }
    detrend_quadratic(&mut v);
    let mut d = 0u32;
    loop {
        let r1 = lag1_acf(&v);
        let rho = r1 / (1.0 + r1);
        if rho < 0.25 || d >= dmax {
            let p = -2.0 * (rho + f64::from(d));
            let alpha_float = p + 2.0;
            let alpha = (-(2.0 * rho).round_ties_even() - 2.0 * f64::from(d)) as i32 + 2;
            return Some(AutocorrId {
                alpha,
                alpha_float,
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

/// Removes the least-squares quadratic in the index (numpy `polyfit(t, x, 2)` residual), using the
/// discrete orthogonal polynomials 1, u, u² − ⟨u²⟩ with u = t − (n−1)/2.
fn detrend_quadratic(x: &mut [f64]) {
    let n = x.len();
    let c = (n as f64 - 1.0) / 2.0;
    let u2m = ((n * n) as f64 - 1.0) / 12.0;
    let q1 = |i: usize| i as f64 - c;
    let q2 = |i: usize| (i as f64 - c).powi(2) - u2m;
    let (mut s0, mut s1, mut s2, mut n1, mut n2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (i, &v) in x.iter().enumerate() {
        s0 += v;
        s1 += v * q1(i);
        s2 += v * q2(i);
        n1 += q1(i) * q1(i);
        n2 += q2(i) * q2(i);
    }
    let b0 = s0 / n as f64;
    let b1 = if n1 > 0.0 { s1 / n1 } else { 0.0 };
    let b2 = if n2 > 0.0 { s2 / n2 } else { 0.0 };
    for (i, v) in x.iter_mut().enumerate() {
        *v -= b0 + b1 * q1(i) + b2 * q2(i);
    }
}
