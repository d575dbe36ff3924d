//! The standard scale-factor metrics (IEEE 1431, IEEE 952, GJB 2426A).

use serde::{Deserialize, Serialize};

use crate::asymmetry::{self, AsymmetryCommonK2};
use crate::data::{Columns, Dataset, Weighting};
use crate::error::FitError;
use crate::lsq::{Prepared, check, fit_prepared};
use crate::model::{Fit, Model};
use crate::nonlinearity::NonlinearityUncertainty;

/// How [`Metrics::nonlinearity_ppm`] is normalised (also written into the JSON).
pub const NONLINEARITY_NORMALISATION: &str = "max_j |K*W_j + F0 - F_j| / max_j |F_j| (least-squares line K, F0; largest absolute output in the range)";

/// Seconds per hour: converts °/s to °/h.
const SECONDS_PER_HOUR: f64 = 3600.0;

/// The metrics of one data set, from least-squares fits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Scale factor K of the least-squares line, V/(°/s).
    pub scale_factor: f64,
    /// Bias F0 of the least-squares line, V.
    pub bias_volts: f64,
    /// Nonlinearity: the largest absolute deviation from the least-squares line divided by the
    /// largest absolute output `F_m`, in ppm.
    pub nonlinearity_ppm: f64,
    /// The normalisation of `nonlinearity_ppm`, in words ([`NONLINEARITY_NORMALISATION`]).
    pub nonlinearity_normalisation: String,
    /// `F_m`, the largest absolute output, V.
    pub full_scale_output: f64,
    /// Asymmetry `|K+ − K−| / ((K+ + K−)/2)`, ppm; null when the data lacks one direction.
    pub asymmetry_ppm: Option<f64>,
    /// K+ from the `ω ≥ 0` points, V/(°/s).
    pub scale_factor_positive: Option<f64>,
    /// K− from the `ω ≤ 0` points, V/(°/s).
    pub scale_factor_negative: Option<f64>,
    /// Bias as a rate, `F0/K`, °/s.
    pub bias_dps: f64,
    /// Bias as a rate, °/h.
    pub bias_dph: f64,
    /// Repeatability `std(K_i, ddof=1)/mean(K_i)` over several data sets, ppm; null for one.
    pub repeatability_ppm: Option<f64>,
    /// The number of data sets (passes) `repeatability_ppm` is computed over: the degrees of
    /// freedom of its own uncertainty ([`Metrics::set_repeatability`]). Absent for one data
    /// set, and in documents written before this field existed (whose repeatability then
    /// has no uncertainty).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub repeatability_passes: Option<usize>,
    /// The expanded uncertainty of `nonlinearity_ppm`, by Monte Carlo over the points' noise
    /// ([`crate::nonlinearity`]). Absent when it could not be made (with a [`NotComputed`]
    /// entry `nonlinearity_uncertainty`), from [`Metrics::compute`] (which fits the line
    /// only), and in documents written before this field existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nonlinearity_uncertainty: Option<NonlinearityUncertainty>,
    /// The asymmetry without the even-order bias of `asymmetry_ppm`: one joint fit
    /// `K0 + K+·ω⁺ + K−·ω⁻ + K2·ω²` with its standard errors ([`AsymmetryCommonK2`]).
    /// Absent (with a [`NotComputed`] entry `asymmetry_common_k2`) when the data cannot
    /// determine it, and in documents written before this field existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub asymmetry_common_k2: Option<AsymmetryCommonK2>,
    /// Correlation coefficient of the least-squares line's scale factor K and bias F0
    /// (dimensionless, −1..1; `−Σwω / √(Σw·Σwω²)`): near zero for rates symmetric about zero.
    /// Absent when the line has no standard errors (two points), and in documents written
    /// before this field existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale_factor_bias_correlation: Option<f64>,
    /// The metrics above that are null because the data cannot support them, with the reason
    /// (e.g. `asymmetry_ppm` when the data has one turning direction only). Empty when every
    /// metric the data set can have was computed (a single data set's `repeatability_ppm` is
    /// null without an entry: it needs several). Absent in documents written before this
    /// field existed.
    #[serde(default)]
    pub not_computed: Vec<NotComputed>,
}

/// A metric that could not be computed, and why. In JSON:
/// `{"metric": "asymmetry_ppm", "reason": "..."}`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct NotComputed {
    /// The metric's key in [`Metrics`] (`asymmetry_ppm`, `scale_factor_positive`, ...).
    pub metric: String,
    /// Why, in words.
    pub reason: String,
}

impl Metrics {
    /// Computes the metrics of one data set (repeatability is left `None`; see
    /// [`repeatability_ppm`]).
    ///
    /// The line and the two half-lines are least-squares fits with the given weighting. The
    /// asymmetry, K+ and K− are `None`, with the reason in [`Metrics::not_computed`], when the
    /// split model cannot be fitted (one direction missing).
    pub fn compute(data: &Dataset, weighting: Weighting) -> Result<Self, FitError> {
        check(data, Model::Linear)?;
        let cols = Columns::from_dataset(data);
        let prep = Prepared::new(&cols, weighting, true)?;
        let line = fit_prepared(&prep, Model::Linear)?;
        let split = prep
            .check(Model::Split)
            .and_then(|()| fit_prepared(&prep, Model::Split));
        Ok(Self::from_fits(&prep, &line, split.as_ref()))
    }

    /// The metrics from the least-squares line and split fit (or why the split model could
    /// not be fitted) of prepared data.
    pub(crate) fn from_fits(
        prep: &Prepared<'_>,
        line: &Fit,
        split: Result<&Fit, &FitError>,
    ) -> Self {
        let k = line.scale_factor;
        let f0 = line.bias;
        let fm = prep.volts().iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        let max_dev = line.max_abs_residual;
        let nonlinearity_ppm = if fm > 0.0 { max_dev / fm * 1e6 } else { 0.0 };
        let mut not_computed = Vec::new();
        let (kp, kn) = match split {
            Ok(s) => (s.coefficients.k_pos, s.coefficients.k_neg),
            Err(e) => {
                for metric in [
                    "asymmetry_ppm",
                    "scale_factor_positive",
                    "scale_factor_negative",
                ] {
                    not_computed.push(NotComputed {
                        metric: metric.to_string(),
                        reason: format!("needs the split model: {e}"),
                    });
                }
                (None, None)
            }
        };
        let asymmetry_ppm = match (kp, kn) {
            (Some(p), Some(n)) if p + n != 0.0 => Some((p - n).abs() / ((p + n) / 2.0).abs() * 1e6),
            (Some(_), Some(_)) => {
                not_computed.push(NotComputed {
                    metric: "asymmetry_ppm".to_string(),
                    reason: "K+ + K- is zero: the mean scale factor is zero".to_string(),
                });
                None
            }
            _ => None,
        };
        let bias_dps = if k != 0.0 { f0 / k } else { 0.0 };
        let asymmetry_common_k2 = match asymmetry::fit(prep) {
            Ok(a) => Some(a),
            Err(reason) => {
                not_computed.push(NotComputed {
                    metric: "asymmetry_common_k2".to_string(),
                    reason,
                });
                None
            }
        };
        let scale_factor_bias_correlation = line
            .std_errors
            .k1
            .and_then(|_| line_correlation(prep.rates(), prep.sigmas));
        Self {
            scale_factor: k,
            bias_volts: f0,
            nonlinearity_ppm,
            nonlinearity_normalisation: NONLINEARITY_NORMALISATION.to_string(),
            full_scale_output: fm,
            asymmetry_ppm,
            scale_factor_positive: kp,
            scale_factor_negative: kn,
            bias_dps,
            bias_dph: bias_dps * SECONDS_PER_HOUR,
            repeatability_ppm: None,
            repeatability_passes: None,
            nonlinearity_uncertainty: None,
            asymmetry_common_k2,
            scale_factor_bias_correlation,
            not_computed,
        }
    }
}

impl Metrics {
    /// Sets the repeatability from the scale factors `K_i` of the passes (or data sets) and
    /// records how many there were, so its uncertainty can be evaluated
    /// ([`repeatability_ppm`]; `None` for fewer than two).
    pub fn set_repeatability(&mut self, scale_factors: &[f64]) {
        self.repeatability_ppm = repeatability_ppm(scale_factors);
        self.repeatability_passes = self.repeatability_ppm.map(|_| scale_factors.len());
    }
}

/// Correlation of the slope and intercept of a (weighted) least-squares line through points
/// at `rates`: `−x̄_w / √(S_xx/Σw + x̄_w²)` with `x̄_w` the weighted mean rate and `S_xx` the
/// weighted sum of squares about it (the closed form of `−Σwx/√(Σw·Σwx²)`, stable for rates
/// far from zero). `None` when the rates do not vary.
fn line_correlation(rates: &[f64], sigmas: Option<&[f64]>) -> Option<f64> {
    let w = |i: usize| sigmas.map_or(1.0, |s| 1.0 / (s[i] * s[i]));
    let sw: f64 = (0..rates.len()).map(w).sum();
    if sw.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let mean = rates.iter().enumerate().map(|(i, x)| w(i) * x).sum::<f64>() / sw;
    let sxx: f64 = rates
        .iter()
        .enumerate()
        .map(|(i, x)| w(i) * (x - mean) * (x - mean))
        .sum();
    let denom = (sxx / sw + mean * mean).sqrt();
    (denom > 0.0 && sxx > 0.0)
        .then(|| (-mean / denom).clamp(-1.0, 1.0))
        .filter(|c| c.is_finite())
}

/// Repeatability of the scale factor over several runs: `std(K_i, ddof=1) / mean(K_i)` in ppm.
///
/// `None` for fewer than two values or a zero mean.
pub fn repeatability_ppm(scale_factors: &[f64]) -> Option<f64> {
    let q = scale_factors.len();
    if q < 2 {
        return None;
    }
    let mean = scale_factors.iter().sum::<f64>() / q as f64;
    if mean == 0.0 || !mean.is_finite() {
        return None;
    }
    let var = scale_factors
        .iter()
        .map(|k| (k - mean).powi(2))
        .sum::<f64>()
        / (q - 1) as f64;
    Some(var.sqrt() / mean.abs() * 1e6)
}
