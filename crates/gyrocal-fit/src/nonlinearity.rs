//! The expanded uncertainty of the nonlinearity, by Monte Carlo over the readings' noise
//! (JCGM 101:2008, propagation of distributions).
//!
//! # Why Monte Carlo
//!
//! The nonlinearity is `max_j |D_j − (K·ω_j + K0)| / max_j |D_j|`: a maximum of absolute
//! residuals of a fitted line. It has no useful derivative (the point that is largest changes
//! with the noise) and its estimate is biased upwards by the noise (the noise adds to the
//! largest residual more often than it subtracts from it; with a perfectly linear gyro the
//! measured nonlinearity is the largest noise residual, never 0). The first-order GUM formula
//! cannot give either effect, so the distribution is propagated numerically instead.
//!
//! # How
//!
//! 1. A **reference curve** `c_j`: the least-squares fit of the model the nested F-tests chose
//!    ([`crate::Analysis::best_model`]; the linear model when that is the split model), at
//!    the measured rates. It is the best estimate of the gyro's noise-free outputs that the
//!    data support.
//! 2. The **noise** of each point: its standard error (a run's step mean: `σ/√n`, the same
//!    figure the fit weights by) scaled up by the reference fit's Birge ratio
//!    `√(χ²/(N − p))` when that is above 1 (so noise the standard errors do not show, such as
//!    a slow drift between steps, is counted, as the fit's own standard errors count it). An
//!    unweighted data set has one noise figure: the reference fit's residual standard error.
//! 3. [`NONLINEARITY_MC_REPLICATES`] synthetic data sets `c_j + σ_j·z_j` (`z` standard normal
//!    from a generator seeded with [`NONLINEARITY_MC_SEED`]: the same data always give the
//!    same figures), each fitted with the same weighted least-squares line and its
//!    nonlinearity computed exactly as the metric is.
//! 4. The spread of those nonlinearities is the standard uncertainty `u`; their mean minus the
//!    reference curve's own nonlinearity is the noise bias `b` of the estimate. The measured
//!    value is reported as the metric defines it (not corrected), so the bias is added to the
//!    expanded uncertainty: `U = k·u + |b|` with `k = 2` (GUM F.2.4.5, an uncorrected
//!    systematic effect). The interval `value ± U` then covers the noise-free nonlinearity
//!    both when the gyro is far from linear (b ≈ 0) and when the noise makes the whole
//!    figure (b ≈ the value).
//!
//! What it does not cover: the instruments' type B errors (a meter gain or a table scale
//! error scales every output or rate alike and leaves the ratio unchanged, to first order;
//! a meter linearity error is not in its stated accuracy model), and curvature finer than the
//! chosen model (it stays in the measured value, and is only not used for the bias).

use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};

use crate::lsq::Prepared;
use crate::model::{Fit, Model};

/// Synthetic data sets of the Monte Carlo (fewer on very large data sets, see
/// [`MONTE_CARLO_WORK_MAX`]). 2000 give the standard uncertainty within about 2 % (relative
/// standard deviation of a standard deviation from M samples: `1/√(2M)`).
pub const NONLINEARITY_MC_REPLICATES: usize = 2000;

/// Seed of the Monte Carlo's normal deviates: fixed, so an analysis is reproducible.
pub const NONLINEARITY_MC_SEED: u64 = 0x6779_726f_6361_6c31; // "gyrocal1"

/// Most `replicates × points` one analysis spends on the Monte Carlo (about a second);
/// above [`NONLINEARITY_MC_REPLICATES`] · points it uses fewer replicates.
pub const MONTE_CARLO_WORK_MAX: usize = 40_000_000;

/// Fewest replicates worth a figure; a data set so large that the work limit allows fewer
/// gets no Monte Carlo (with the reason).
pub const MONTE_CARLO_REPLICATES_MIN: usize = 200;

/// The method, in words, as written in [`NonlinearityUncertainty::method`].
pub const NONLINEARITY_MC_METHOD: &str = "Monte Carlo (JCGM 101): synthetic data sets = the F-test-chosen model's least-squares curve + normal noise of each point's standard error (scaled up by that fit's Birge ratio when above 1), each fitted with the weighted least-squares line and its nonlinearity computed as the metric is; u = standard deviation of those nonlinearities, b = their mean − the curve's own nonlinearity (the noise bias of a maximum of residuals), U = 2u + |b| (the bias is not corrected, so it is added: GUM F.2.4.5); seeded, deterministic";

/// The Monte Carlo's result for [`crate::Metrics::nonlinearity_ppm`]. In JSON:
///
/// ```json
/// {"method": "Monte Carlo (JCGM 101): ...", "reference_model": "quadratic",
///  "reference_nonlinearity_ppm": 925.1, "noise": "...", "noise_scale": 1.0,
///  "replicates": 2000, "seed": 7456116480822832177,
///  "standard_uncertainty_ppm": 6.3, "noise_bias_ppm": 4.1, "coverage_factor": 2.0,
///  "expanded_uncertainty_ppm": 16.7}
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NonlinearityUncertainty {
    /// [`NONLINEARITY_MC_METHOD`].
    pub method: String,
    /// The model whose least-squares curve is the noise-free reference.
    pub reference_model: Model,
    /// The nonlinearity of that reference curve, ppm.
    pub reference_nonlinearity_ppm: f64,
    /// Where each point's noise comes from, in words.
    pub noise: String,
    /// The factor the points' standard errors were multiplied by (the Birge ratio when above
    /// 1, else 1; for unweighted data the residual standard error itself, V).
    pub noise_scale: f64,
    /// Synthetic data sets.
    pub replicates: usize,
    /// Seed of the generator.
    pub seed: u64,
    /// `u`: standard deviation of the synthetic nonlinearities, ppm.
    pub standard_uncertainty_ppm: f64,
    /// `b`: mean of the synthetic nonlinearities minus the reference's, ppm (positive: the
    /// noise makes the measured nonlinearity larger).
    pub noise_bias_ppm: f64,
    /// `k` (2).
    pub coverage_factor: f64,
    /// `U = k·u + |b|`, ppm.
    pub expanded_uncertainty_ppm: f64,
}

/// The weighted least-squares line through fixed rates, refitted many times: the rates'
/// weighted mean and spread are computed once.
struct LineFitter<'a> {
    rates: &'a [f64],
    weights: Vec<f64>,
    sum_w: f64,
    mean_rate: f64,
    sxx: f64,
}

impl<'a> LineFitter<'a> {
    fn new(rates: &'a [f64], sigmas: Option<&[f64]>) -> Option<Self> {
        let weights: Vec<f64> = match sigmas {
            Some(s) => s.iter().map(|s| 1.0 / (s * s)).collect(),
            None => vec![1.0; rates.len()],
        };
        let sum_w: f64 = weights.iter().sum();
        if !(sum_w.is_finite() && sum_w > 0.0) {
            return None;
        }
        let mean_rate = rates.iter().zip(&weights).map(|(x, w)| w * x).sum::<f64>() / sum_w;
        let sxx: f64 = rates
            .iter()
            .zip(&weights)
            .map(|(x, w)| w * (x - mean_rate) * (x - mean_rate))
            .sum();
        (sxx.is_finite() && sxx > 0.0).then_some(Self {
            rates,
            weights,
            sum_w,
            mean_rate,
            sxx,
        })
    }

    /// The nonlinearity (ppm) of `volts` at these rates: the largest absolute residual of
    /// the weighted least-squares line over the largest absolute output (0 when every output
    /// is 0), as [`crate::Metrics`] defines it.
    fn nonlinearity_ppm(&self, volts: &[f64]) -> f64 {
        let mut swy = 0.0;
        let mut sxy = 0.0;
        for ((x, y), w) in self.rates.iter().zip(volts).zip(&self.weights) {
            swy += w * y;
            sxy += w * (x - self.mean_rate) * y;
        }
        let slope = sxy / self.sxx;
        let intercept = swy / self.sum_w - slope * self.mean_rate;
        let mut dev = 0.0_f64;
        let mut fm = 0.0_f64;
        for (x, y) in self.rates.iter().zip(volts) {
            dev = dev.max((y - (intercept + slope * x)).abs());
            fm = fm.max(y.abs());
        }
        if fm > 0.0 { dev / fm * 1e6 } else { 0.0 }
    }
}

/// Number of coefficients of `model`'s fit (for the residual degrees of freedom).
fn coefficients(model: Model) -> usize {
    match model {
        Model::Linear => 2,
        Model::Quadratic => 3,
        Model::Cubic | Model::Split => 4,
    }
}

/// Standard normal deviates by the Box–Muller transform (two per pair of uniforms), so the
/// figures depend only on the seeded generator.
struct Normals {
    rng: StdRng,
    spare: Option<f64>,
}

impl Normals {
    fn new(seed: u64) -> Self {
        Self {
            rng: StdRng::seed_from_u64(seed),
            spare: None,
        }
    }

    fn next(&mut self) -> f64 {
        if let Some(z) = self.spare.take() {
            return z;
        }
        // 1 − u lies in (0, 1]: the logarithm is finite.
        let u1 = 1.0 - self.rng.random::<f64>();
        let u2 = self.rng.random::<f64>();
        let r = (-2.0 * u1.ln()).sqrt();
        let t = std::f64::consts::TAU * u2;
        self.spare = Some(r * t.sin());
        r * t.cos()
    }
}

/// The Monte Carlo of the nonlinearity of prepared data, with `reference` the least-squares
/// fit of the chosen model; or why it cannot be made (in words).
pub(crate) fn monte_carlo(
    prep: &Prepared<'_>,
    reference: &Fit,
) -> Result<NonlinearityUncertainty, String> {
    let n = prep.len();
    let rates = prep.rates();
    let volts = prep.volts();
    let p = coefficients(reference.model);
    if n <= p {
        return Err(format!(
            "the {} model has {p} coefficients and the data {n} points: no residual degrees of freedom to estimate the noise",
            reference.model
        ));
    }
    let replicates = NONLINEARITY_MC_REPLICATES.min(MONTE_CARLO_WORK_MAX / n.max(1));
    if replicates < MONTE_CARLO_REPLICATES_MIN {
        return Err(format!(
            "{n} points are too many for the Monte Carlo ({MONTE_CARLO_REPLICATES_MIN} replicates would exceed {MONTE_CARLO_WORK_MAX} point-fits); fit the rate means (a run's steps.csv) instead"
        ));
    }
    let fitter = LineFitter::new(rates, prep.sigmas)
        .ok_or_else(|| "the rates do not vary (or the weights are not usable)".to_string())?;
    let curve: Vec<f64> = rates.iter().map(|&w| reference.predict(w)).collect();
    let dof = (n - p) as f64;
    let (sigmas, noise_scale, noise): (Vec<f64>, f64, String) = match prep.sigmas {
        Some(s) => {
            let chi2: f64 = volts
                .iter()
                .zip(&curve)
                .zip(s)
                .map(|((y, c), s)| ((y - c) / s).powi(2))
                .sum();
            let birge = (chi2 / dof).sqrt();
            let scale = if birge.is_finite() {
                birge.max(1.0)
            } else {
                1.0
            };
            (
                s.iter().map(|s| s * scale).collect(),
                scale,
                format!(
                    "each point's standard error × {scale:.3} (the {} fit's Birge ratio √(χ²/ν) = {birge:.3}, ν = {}, taken when above 1)",
                    reference.model,
                    n - p
                ),
            )
        }
        None => {
            let sse: f64 = volts
                .iter()
                .zip(&curve)
                .map(|(y, c)| (y - c) * (y - c))
                .sum();
            let s = (sse / dof).sqrt();
            (
                vec![s; n],
                s,
                format!(
                    "unweighted data: every point gets the {} fit's residual standard error, {s:.4e} V (ν = {})",
                    reference.model,
                    n - p
                ),
            )
        }
    };
    if sigmas.iter().any(|s| !s.is_finite()) {
        return Err("the noise of the points is not finite".to_string());
    }
    let reference_nl = fitter.nonlinearity_ppm(&curve);
    let mut normals = Normals::new(NONLINEARITY_MC_SEED);
    let mut synthetic = vec![0.0; n];
    // Welford's running mean and variance.
    let (mut mean, mut m2) = (0.0_f64, 0.0_f64);
    for i in 0..replicates {
        for ((y, c), s) in synthetic.iter_mut().zip(&curve).zip(&sigmas) {
            *y = c + s * normals.next();
        }
        let nl = fitter.nonlinearity_ppm(&synthetic);
        let delta = nl - mean;
        mean += delta / (i + 1) as f64;
        m2 += delta * (nl - mean);
    }
    let u = (m2 / (replicates - 1) as f64).sqrt();
    let bias = mean - reference_nl;
    let coverage_factor = crate::uncertainty::COVERAGE_FACTOR;
    let expanded = coverage_factor * u + bias.abs();
    if !(u.is_finite() && bias.is_finite() && reference_nl.is_finite()) {
        return Err("the Monte Carlo gave non-finite figures".to_string());
    }
    Ok(NonlinearityUncertainty {
        method: NONLINEARITY_MC_METHOD.to_string(),
        reference_model: reference.model,
        reference_nonlinearity_ppm: reference_nl,
        noise,
        noise_scale,
        replicates,
        seed: NONLINEARITY_MC_SEED,
        standard_uncertainty_ppm: u,
        noise_bias_ppm: bias,
        coverage_factor,
        expanded_uncertainty_ppm: expanded,
    })
}

/// The nonlinearity of prepared data by this module's line fit (a check that the Monte Carlo
/// computes the metric exactly as [`crate::Metrics`] does).
#[cfg(test)]
pub(crate) fn nonlinearity_of(prep: &Prepared<'_>) -> Option<f64> {
    LineFitter::new(prep.rates(), prep.sigmas).map(|f| f.nonlinearity_ppm(prep.volts()))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;
    use crate::data::{Columns, Dataset, Point, Weighting};
    use crate::lsq::fit_prepared;

    fn data(sigma: Option<f64>) -> Dataset {
        let rates = [0.0, 1.0, -1.0, 5.0, -5.0, 10.0, -10.0, 20.0, -20.0];
        Dataset {
            source: None,
            points: rates
                .iter()
                .enumerate()
                .map(|(i, &w)| Point {
                    rate_dps: w,
                    // a bowl and a little deterministic scatter
                    volts: 0.0088 + 0.3612 * w + 2e-5 * w * w + 1e-4 * ((i * 7 % 5) as f64 - 2.0),
                    volts_std: sigma,
                    n: sigma.map(|_| 100),
                    line: None,
                })
                .collect(),
        }
    }

    #[test]
    fn the_line_fit_gives_the_metrics_nonlinearity_weighted_or_not() {
        for sigma in [None, Some(0.002)] {
            let cols = Columns::from_dataset(&data(sigma));
            let prep = Prepared::new(&cols, Weighting::Auto, true).unwrap();
            assert_eq!(prep.sigmas.is_some(), sigma.is_some());
            let line = fit_prepared(&prep, Model::Linear).unwrap();
            let m = crate::Metrics::from_fits(
                &prep,
                &line,
                Err(&crate::FitError::Unsupported(String::new())),
            );
            let mine = nonlinearity_of(&prep).unwrap();
            assert!(
                (mine - m.nonlinearity_ppm).abs() <= 1e-9 * m.nonlinearity_ppm,
                "{mine} vs {}",
                m.nonlinearity_ppm
            );
        }
    }

    #[test]
    fn the_same_data_give_the_same_figures() {
        let cols = Columns::from_dataset(&data(Some(0.002)));
        let prep = Prepared::new(&cols, Weighting::Auto, true).unwrap();
        let quad = fit_prepared(&prep, Model::Quadratic).unwrap();
        let a = monte_carlo(&prep, &quad).unwrap();
        let b = monte_carlo(&prep, &quad).unwrap();
        assert_eq!(a, b);
        assert_eq!(a.replicates, NONLINEARITY_MC_REPLICATES);
        assert!(a.standard_uncertainty_ppm > 0.0);
        assert!(
            (a.expanded_uncertainty_ppm
                - (2.0 * a.standard_uncertainty_ppm + a.noise_bias_ppm.abs()))
            .abs()
                < 1e-12
        );
    }

    #[test]
    fn without_residual_degrees_of_freedom_there_is_no_figure() {
        let d = Dataset::from_pairs([(0.0, 0.0), (1.0, 0.36), (-1.0, -0.36)]);
        let cols = Columns::from_dataset(&d);
        let prep = Prepared::new(&cols, Weighting::Auto, true).unwrap();
        let quad = fit_prepared(&prep, Model::Quadratic).unwrap();
        let e = monte_carlo(&prep, &quad).unwrap_err();
        assert!(e.contains("no residual degrees of freedom"), "{e}");
    }

    #[test]
    fn normals_have_unit_variance() {
        let mut g = Normals::new(1);
        let n = 200_000;
        let xs: Vec<f64> = (0..n).map(|_| g.next()).collect();
        let mean = xs.iter().sum::<f64>() / n as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
        assert!(mean.abs() < 0.01, "{mean}");
        assert!((var - 1.0).abs() < 0.01, "{var}");
    }
}
