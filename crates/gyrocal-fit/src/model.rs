//! Models, methods and the result of one fit.

use std::fmt;

use serde::{Deserialize, Serialize};

use crate::neuron::NeuronStatus;

/// The instrument model fitted to the data.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Model {
    /// `D = K0 + K1·ω` (the paper's model).
    Linear,
    /// `D = K0 + K1·ω + K2·ω²`: captures an even-order nonlinearity.
    Quadratic,
    /// `D = K0 + K1·ω + K2·ω² + K3·ω³`.
    Cubic,
    /// Separate least-squares lines for `ω ≥ 0` (`K0+ + K+·ω`) and `ω ≤ 0` (`K0- + K-·ω`), the
    /// zero-rate points in both; gives the scale factors of the two turning directions.
    Split,
}

impl Model {
    /// Every model, in the order reports list them.
    pub const ALL: [Model; 4] = [Model::Linear, Model::Quadratic, Model::Cubic, Model::Split];

    /// Number of coefficients the model estimates (two lines of two for the split model).
    pub fn coefficient_count(self) -> usize {
        match self {
            Model::Linear => 2,
            Model::Quadratic => 3,
            Model::Cubic | Model::Split => 4,
        }
    }

    /// Polynomial degree (1 for the split model, whose halves are lines).
    pub fn degree(self) -> usize {
        match self {
            Model::Linear | Model::Split => 1,
            Model::Quadratic => 2,
            Model::Cubic => 3,
        }
    }

    /// The name used on the command line and in JSON.
    pub fn name(self) -> &'static str {
        match self {
            Model::Linear => "linear",
            Model::Quadratic => "quadratic",
            Model::Cubic => "cubic",
            Model::Split => "split",
        }
    }
}

impl fmt::Display for Model {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The estimator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Least squares by QR (any model).
    LeastSquares,
    /// The paper's single neuron trained by gradient descent with momentum (linear model only).
    Neuron,
}

impl Method {
    /// The name used on the command line and in JSON.
    pub fn name(self) -> &'static str {
        match self {
            Method::LeastSquares => "least-squares",
            Method::Neuron => "neuron",
        }
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Model coefficients (or their standard errors); keys that do not apply are `None` and are
/// omitted from JSON.
///
/// Units: `k0` V, `k1` V/(°/s), `k2` V/(°/s)², `k3` V/(°/s)³, `k_pos`/`k_neg` V/(°/s),
/// `k0_pos`/`k0_neg` V.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Coefficients {
    /// Bias (constant term). For the split model, the mean of the two lines' intercepts.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k0: Option<f64>,
    /// Linear term: the scale factor of the polynomial models.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k1: Option<f64>,
    /// Quadratic term.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k2: Option<f64>,
    /// Cubic term.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k3: Option<f64>,
    /// Split model: scale factor of the `ω ≥ 0` line.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k_pos: Option<f64>,
    /// Split model: scale factor of the `ω ≤ 0` line.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k_neg: Option<f64>,
    /// Split model: intercept of the `ω ≥ 0` line.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k0_pos: Option<f64>,
    /// Split model: intercept of the `ω ≤ 0` line.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k0_neg: Option<f64>,
}

impl Coefficients {
    /// Polynomial coefficients `[k0, k1, k2, k3]` with absent ones as 0.
    pub fn polynomial(&self) -> [f64; 4] {
        [
            self.k0.unwrap_or(0.0),
            self.k1.unwrap_or(0.0),
            self.k2.unwrap_or(0.0),
            self.k3.unwrap_or(0.0),
        ]
    }
}

/// One point's fit: measured, fitted and residual (measured − fitted).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Residual {
    /// Applied rate, °/s.
    pub rate_dps: f64,
    /// Measured output, V.
    pub volts: f64,
    /// Output predicted by the fit, V.
    pub fitted: f64,
    /// `volts − fitted`, V.
    pub residual: f64,
}

/// One rate's fit, summarised over the points measured at that rate (in place of per-point
/// residuals on large data sets; see [`crate::Options::point_residuals_max`]); on continuous
/// data (more than [`crate::RATE_GROUPS_MAX`] distinct rates) one rate bin's
/// ([`crate::RateBins`]), with the bin's edges.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RateResidual {
    /// Applied rate, °/s (for a bin: the mean rate of its points).
    pub rate_dps: f64,
    /// Points at that rate (in that bin).
    pub n: u64,
    /// Mean measured output at that rate, V.
    pub mean_volts: f64,
    /// Output predicted by the fit at that rate, V (for a bin: the mean of the fit over its
    /// points).
    pub fitted: f64,
    /// `mean_volts − fitted`, V (for a bin: the mean residual of its points).
    pub mean_residual: f64,
    /// Largest `|volts − fitted|` over the points at that rate, V.
    pub max_abs_residual: f64,
    /// A bin's lower edge, °/s (absent for a rate of a schedule).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rate_min_dps: Option<f64>,
    /// A bin's upper edge, °/s (absent for a rate of a schedule).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rate_max_dps: Option<f64>,
}

/// What the neuron's online passes presented.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "kind")]
pub enum TrainingData {
    /// Every point, once per online pass (the paper's rule).
    #[default]
    Points,
    /// Above [`crate::neuron::RATE_MEANS_ABOVE_POINTS`] points: each distinct rate's mean
    /// output once per online pass, its cost weighted by the points (and weights) it averages.
    /// The batch passes and the pass errors use every point (through the data's sufficient
    /// statistics), so the minimum, the SSE and the pass errors are those of all points.
    RateMeans {
        /// Distinct rates presented per online pass.
        rates: usize,
        /// Points they average.
        points: usize,
    },
    /// As `RateMeans`, on continuous data (more than [`crate::RATE_GROUPS_MAX`] distinct
    /// rates): each non-empty rate bin's ([`crate::RateBins`]) mean rate and mean output once
    /// per online pass, its cost weighted by the points (and weights) it averages. The batch
    /// passes and the pass errors use every point, so the minimum, the SSE and the pass errors
    /// are those of all points, exactly as with rate means.
    RateBins {
        /// Non-empty bins presented per online pass.
        bins: usize,
        /// Points they average.
        points: usize,
    },
}

/// How the neuron was trained and what happened (present on neuron fits only).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NeuronTrace {
    /// Converged, stopped at the pass limit, or diverged.
    pub status: NeuronStatus,
    /// Passes of online updates (the paper's rule).
    pub online_passes: u64,
    /// Full-batch finishing passes.
    pub batch_passes: u64,
    /// Sum of squared residuals after every pass, in V² (comparable with the fits' `sse`).
    pub pass_errors: Vec<f64>,
    /// Learning rate η used.
    pub eta: f64,
    /// Momentum α used.
    pub alpha: f64,
    /// Seed of the initial weight and threshold.
    pub seed: u64,
    /// Initial weight (scale factor), V/(°/s).
    pub initial_weight: f64,
    /// Initial threshold (bias), V.
    pub initial_threshold: f64,
    /// What the online passes presented (absent in documents written before this field
    /// existed: points).
    #[serde(default)]
    pub training_data: TrainingData,
    /// The online-pass limit when it was lowered below `max_online_passes` to bound the cost
    /// on data with very many distinct rates ([`crate::neuron::ONLINE_PRESENTATIONS_MAX`]
    /// presentations in all).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub online_pass_limit: Option<u64>,
}

/// The result of fitting one model by one method.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Fit {
    /// Estimator.
    pub method: Method,
    /// Model.
    pub model: Model,
    /// Scale factor K, V/(°/s): `k1` for the polynomial models, `(k_pos + k_neg)/2` for split.
    pub scale_factor: f64,
    /// Bias K0, V.
    pub bias: f64,
    /// The coefficients.
    pub coefficients: Coefficients,
    /// Standard errors of the coefficients (absent when there are no degrees of freedom left,
    /// and for the neuron, which does not estimate them).
    pub std_errors: Coefficients,
    /// Whether the points were weighted by `1/σ²`.
    pub weighted: bool,
    /// Sum of squared residuals, V² (unweighted, whatever the fit's weights).
    pub sse: f64,
    /// Weighted sum of squared residuals `Σ r²/σ²` (χ²), present on weighted fits.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chi_squared: Option<f64>,
    /// `sqrt(sse / N)`, V.
    pub rms_residual: f64,
    /// Residual standard error `sqrt(sse / (N − p))`, V; absent when `N = p`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub residual_std_error: Option<f64>,
    /// Largest absolute residual, V.
    pub max_abs_residual: f64,
    /// Coefficient of determination `1 − sse/Σ(D − mean D)²`.
    pub r_squared: f64,
    /// Per-point fit, in data order; empty when the analysis summarised residuals per rate
    /// instead (see [`crate::Analysis::residual_detail`]).
    #[serde(default)]
    pub residuals: Vec<Residual>,
    /// Per-rate fit, increasing rate: present instead of `residuals` on large data sets.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub rate_residuals: Vec<RateResidual>,
    /// Number of training passes (neuron only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub passes: Option<u64>,
    /// Whether the estimator reached its solution (always true for least squares).
    pub converged: bool,
    /// Training details (neuron only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub neuron: Option<NeuronTrace>,
}

impl Fit {
    /// Output predicted by the fit at rate `rate_dps` (°/s), V.
    pub fn predict(&self, rate_dps: f64) -> f64 {
        predict(self.model, &self.coefficients, rate_dps)
    }

    /// Compensation: the rate (°/s) that produces output `volts` according to this fit.
    ///
    /// Linear: `(D − K0)/K`. Split: the line whose side of zero the output falls on; outputs
    /// between the two lines' intercepts map to 0.
    /// Quadratic and cubic: Newton's method on the polynomial from the linear guess, which finds
    /// the root on the calibrated branch. `None` when no root is found (e.g. `D` outside the
    /// range a quadratic can produce) or the scale factor is zero.
    pub fn compensate(&self, volts: f64) -> Option<f64> {
        compensate(self.model, &self.coefficients, volts)
    }
}

pub(crate) fn predict(model: Model, c: &Coefficients, w: f64) -> f64 {
    match model {
        Model::Split => {
            if w > 0.0 {
                c.k0_pos.unwrap_or(0.0) + c.k_pos.unwrap_or(0.0) * w
            } else if w < 0.0 {
                c.k0_neg.unwrap_or(0.0) + c.k_neg.unwrap_or(0.0) * w
            } else {
                c.k0.unwrap_or(0.0)
            }
        }
        _ => {
            let [k0, k1, k2, k3] = c.polynomial();
            k0 + w * (k1 + w * (k2 + w * k3))
        }
    }
}

pub(crate) fn compensate(model: Model, c: &Coefficients, d: f64) -> Option<f64> {
    let finite = |x: f64| if x.is_finite() { Some(x) } else { None };
    match model {
        Model::Split => {
            let (k0p, kp, k0n, kn) = (c.k0_pos?, c.k_pos?, c.k0_neg?, c.k_neg?);
            if kp == 0.0 || kn == 0.0 {
                return None;
            }
            // Outputs between the two intercepts belong to neither line away from zero.
            if d >= k0p.min(k0n) && d <= k0p.max(k0n) {
                return Some(0.0);
            }
            let wp = (d - k0p) / kp;
            finite(if wp > 0.0 { wp } else { (d - k0n) / kn })
        }
        _ => {
            let [k0, k1, k2, k3] = c.polynomial();
            if k1 == 0.0 {
                return None;
            }
            let mut w = (d - k0) / k1;
            if k2 == 0.0 && k3 == 0.0 {
                return finite(w);
            }
            for _ in 0..100 {
                let f = k0 + w * (k1 + w * (k2 + w * k3)) - d;
                let df = k1 + w * (2.0 * k2 + 3.0 * k3 * w);
                if df == 0.0 || !df.is_finite() {
                    return None;
                }
                let step = f / df;
                w -= step;
                if !w.is_finite() {
                    return None;
                }
                if step.abs() <= 1e-15 * w.abs().max(1e-12) {
                    return Some(w);
                }
            }
            // Newton converges quadratically near a simple root; no convergence in 100 steps
            // means there is no root near the linear guess.
            let f = k0 + w * (k1 + w * (k2 + w * k3)) - d;
            if f.abs() <= 1e-12 * d.abs().max(1e-12) {
                Some(w)
            } else {
                None
            }
        }
    }
}
