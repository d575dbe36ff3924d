//! Models in temperature: a figure measured at several temperatures (the scale factor K, the
//! bias) fitted as a line or a parabola in the temperature actually measured, the model chosen
//! by significance, the sensitivity over the range with its uncertainty, and the hysteresis
//! where a temperature is revisited. Pure numerics: no files.
//!
//! # Why it is shaped this way
//!
//! * **The measured temperature, not the setpoint.** Each point sits at the gyro's mean
//!   temperature during its test (a chamber at −20 °C may leave the gyro at −19.4 °C): the
//!   setpoint only names the point.
//! * **Weighted least squares, scaled by the scatter.** Each point is weighted by its own
//!   stated uncertainty (`1/u²`), so a noisy temperature pulls the line less. The coefficients'
//!   covariance is `(AᵀWA)⁻¹` scaled by the observed reduced chi-square `χ²/ν` (`ν = N − p`),
//!   and the expanded uncertainty uses Student's `t(0.975, ν)` as the coverage factor: with
//!   four temperatures and a line, `ν = 2` and `k = 4.30`. The scatter of the points about the
//!   model is what a lab sees repeat; the points' stated U contain type B parts (the meter's
//!   gain, the table's rate) common to every temperature that do not scatter the points, so
//!   taken alone they would misstate a slope. With no residual degree of freedom (two
//!   temperatures and a line) the stated U alone is used, at `k = 2`, and said so.
//! * **Chosen as the rate models are.** The parabola is a candidate only with four distinct
//!   temperatures and five points (two residual degrees of freedom: with one, the F-test
//!   takes it exactly when its residual is small by chance and its U then undercovers). It
//!   is taken only when the nested F-test of
//!   linear → quadratic (weighted: `χ²` for the SSE) is significant at
//!   [`gyrocal_fit::MODEL_SELECTION_LEVEL`] — the same rule as [`gyrocal_fit::selection`], the
//!   same [`gyrocal_fit::NestedTest`] record.
//! * **Centred at mid-range.** `y = c0 + c1·(T − Tm) + c2·(T − Tm)²` with `Tm` the middle of
//!   the measured range: `c1` is then the slope at mid-range (the sensitivity over the range,
//!   also for a parabola) and the normal equations stay well conditioned.
//!
//! Monte Carlo in the tests checks the stated U covers the truth about 95 % of the time.

mod hysteresis;
#[cfg(test)]
mod tests;

pub use hysteresis::{Hysteresis, hysteresis};

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use statrs::distribution::{ContinuousCDF, FisherSnedecor, StudentsT};

use gyrocal_fit::{MODEL_SELECTION_LEVEL, Model, ModelSelection, NestedTest};

/// The fewest distinct temperatures for which the parabola is a candidate.
pub const QUADRATIC_MIN_TEMPERATURES: usize = 4;

/// The coverage factor used when there is no residual degree of freedom (the stated U alone).
pub const COVERAGE_FACTOR: f64 = 2.0;

/// How the coefficients' uncertainty is obtained, as written in [`TempModel::uncertainty_method`].
pub const SCATTER_METHOD: &str = "weighted least squares (weights 1/u² from each point's stated U); covariance (AᵀWA)⁻¹ scaled by the observed reduced chi-square χ²/ν; expanded U with Student's t(0.975, ν), ν = N − p";

/// The method when the model has as many coefficients as there are points.
pub const STATED_METHOD: &str = "weighted least squares with no residual degree of freedom: covariance (AᵀWA)⁻¹ from the points' stated U alone, expanded with k = 2 (the scatter about the model cannot be seen)";

/// One figure measured at one temperature.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TempPoint {
    /// The gyro's mean temperature during the test, °C.
    pub t_c: f64,
    /// The figure (K in its unit, the bias in °/h).
    pub y: f64,
    /// Its expanded uncertainty (k = 2), same unit; must be positive.
    pub u: f64,
}

/// Why no model in temperature could be fitted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TempcoError {
    /// Fewer than two distinct temperatures.
    #[error("a model in temperature needs at least two distinct temperatures ({0} given)")]
    TooFewTemperatures(usize),
    /// A point is not finite or its uncertainty is not positive.
    #[error("point {index} ({t_c} °C): {what}")]
    BadPoint {
        /// 0-based index of the point.
        index: usize,
        /// Its temperature.
        t_c: f64,
        /// What is wrong.
        what: &'static str,
    },
    /// The normal equations are singular (should not happen with distinct temperatures).
    #[error("the model in temperature cannot be solved (singular normal equations)")]
    Singular,
}

/// A polynomial in temperature fitted to [`TempPoint`]s, with its uncertainty.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TempModel {
    /// 1 (line) or 2 (parabola).
    pub order: usize,
    /// The centre `Tm` of the measured range, °C: the model is in `T − Tm`.
    pub t_mid_c: f64,
    /// `c0, c1[, c2]` of `y = c0 + c1·(T − Tm) + c2·(T − Tm)²`.
    pub coefficients: Vec<f64>,
    /// Expanded uncertainty of each coefficient (at [`TempModel::coverage_factor`]).
    pub coefficient_u: Vec<f64>,
    /// Standard covariance of the coefficients (row-major, `order + 1` square).
    pub covariance: Vec<f64>,
    /// The coverage factor of every U of this model.
    pub coverage_factor: f64,
    /// Residual degrees of freedom `N − p`.
    pub dof: usize,
    /// `χ² = Σ ((y − ŷ)/u_std)²` with each point's standard uncertainty.
    pub chi_squared: f64,
    /// [`SCATTER_METHOD`] or [`STATED_METHOD`].
    pub uncertainty_method: String,
    /// The residuals `y − ŷ`, in the order of the points.
    pub residuals: Vec<f64>,
}

impl TempModel {
    fn cov(&self, i: usize, j: usize) -> f64 {
        let n = self.order + 1;
        self.covariance.get(i * n + j).copied().unwrap_or(0.0)
    }

    /// The model's value at `t_c`.
    pub fn value(&self, t_c: f64) -> f64 {
        let d = t_c - self.t_mid_c;
        self.coefficients
            .iter()
            .rev()
            .fold(0.0, |acc, c| acc * d + c)
    }

    /// The slope at `t_c`, per °C.
    pub fn slope(&self, t_c: f64) -> f64 {
        let d = t_c - self.t_mid_c;
        let c1 = self.coefficients.get(1).copied().unwrap_or(0.0);
        let c2 = self.coefficients.get(2).copied().unwrap_or(0.0);
        c1 + 2.0 * c2 * d
    }

    /// The sensitivity over the range: the slope at mid-range (per °C) with its expanded U.
    pub fn sensitivity(&self) -> (f64, f64) {
        let c1 = self.coefficients.get(1).copied().unwrap_or(0.0);
        (c1, self.coverage_factor * self.cov(1, 1).max(0.0).sqrt())
    }

    /// The slope at mid-range relative to the model's value at `t_ref_c`, in ppm/°C, with its
    /// expanded U (the correlation of slope and value propagated). `None` when the value at
    /// the reference is zero.
    pub fn relative_sensitivity_ppm(&self, t_ref_c: f64) -> Option<(f64, f64)> {
        let y = self.value(t_ref_c);
        if y == 0.0 || !y.is_finite() {
            return None;
        }
        let c1 = self.coefficients.get(1).copied().unwrap_or(0.0);
        let d = t_ref_c - self.t_mid_c;
        let n = self.order + 1;
        // f = c1 / y(Tref), y = Σ c_i dⁱ: ∂f/∂c_i = δ_i1 / y − c1·dⁱ / y²
        let grad: Vec<f64> = (0..n)
            .map(|i| {
                let own = if i == 1 { 1.0 / y } else { 0.0 };
                own - c1 * d.powi(i as i32) / (y * y)
            })
            .collect();
        let mut var = 0.0;
        for (i, gi) in grad.iter().enumerate() {
            for (j, gj) in grad.iter().enumerate() {
                var += gi * gj * self.cov(i, j);
            }
        }
        Some((
            c1 / y * 1e6,
            self.coverage_factor * var.max(0.0).sqrt() * 1e6,
        ))
    }

    /// The standard uncertainty of the slope at `t_c`.
    pub fn slope_std_u(&self, t_c: f64) -> f64 {
        let d = t_c - self.t_mid_c;
        let var = if self.order >= 2 {
            self.cov(1, 1) + 4.0 * d * self.cov(1, 2) + 4.0 * d * d * self.cov(2, 2)
        } else {
            self.cov(1, 1)
        };
        var.max(0.0).sqrt()
    }
}

/// The models in temperature of one figure: the line, the parabola when the points allow one,
/// the choice between them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TempFit {
    /// The line.
    pub linear: TempModel,
    /// The parabola (absent with fewer than [`QUADRATIC_MIN_TEMPERATURES`] distinct
    /// temperatures or fewer than five points).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quadratic: Option<TempModel>,
    /// How the model was chosen (the nested F-test).
    pub selection: ModelSelection,
}

impl TempFit {
    /// The model chosen by [`TempFit::selection`].
    pub fn chosen(&self) -> &TempModel {
        match (&self.selection.chosen, &self.quadratic) {
            (Model::Quadratic, Some(q)) => q,
            _ => &self.linear,
        }
    }
}

fn check(points: &[TempPoint]) -> Result<usize, TempcoError> {
    for (index, p) in points.iter().enumerate() {
        let bad = |what| TempcoError::BadPoint {
            index,
            t_c: p.t_c,
            what,
        };
        if !p.t_c.is_finite() {
            return Err(bad("the temperature is not a number"));
        }
        if !p.y.is_finite() {
            return Err(bad("the value is not a number"));
        }
        if !(p.u.is_finite() && p.u > 0.0) {
            return Err(bad("its uncertainty is not a positive number"));
        }
    }
    let mut ts: Vec<f64> = points.iter().map(|p| p.t_c).collect();
    ts.sort_by(f64::total_cmp);
    ts.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    Ok(ts.len())
}

/// Two measured temperatures closer than this count as one temperature for the model's
/// choice (a revisit at 25.3 °C after 25.1 °C is the same temperature, not a third one).
pub const SAME_TEMPERATURE_C: f64 = 1.0;

/// How many temperatures the points hold, those within [`SAME_TEMPERATURE_C`] of the
/// previous (in ascending order) counted once.
pub fn temperatures_apart(points: &[TempPoint]) -> usize {
    let mut ts: Vec<f64> = points
        .iter()
        .map(|p| p.t_c)
        .filter(|t| t.is_finite())
        .collect();
    ts.sort_by(f64::total_cmp);
    ts.dedup_by(|a, b| (*a - *b).abs() < SAME_TEMPERATURE_C);
    ts.len()
}

/// Fits `points` as a polynomial of `order` (1 or 2) in temperature. See the module's notes.
pub fn fit_order(points: &[TempPoint], order: usize) -> Result<TempModel, TempcoError> {
    let distinct = check(points)?;
    if distinct < order + 1 {
        return Err(TempcoError::TooFewTemperatures(distinct));
    }
    let (lo, hi) = points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.t_c), hi.max(p.t_c))
        });
    let t_mid_c = 0.5 * (lo + hi);
    // Scale T − Tm by the half-range so the columns are of order one.
    let half = (0.5 * (hi - lo)).max(1e-9);
    let n = points.len();
    let p = order + 1;
    let mut a = DMatrix::<f64>::zeros(n, p);
    let mut b = DVector::<f64>::zeros(n);
    for (i, pt) in points.iter().enumerate() {
        let sd = pt.u / COVERAGE_FACTOR;
        let x = (pt.t_c - t_mid_c) / half;
        for j in 0..p {
            a[(i, j)] = x.powi(j as i32) / sd;
        }
        b[i] = pt.y / sd;
    }
    let ata = a.transpose() * &a;
    let inv = ata.try_inverse().ok_or(TempcoError::Singular)?;
    let c_scaled = &inv * (a.transpose() * &b);
    let resid_w = &b - &a * &c_scaled;
    let chi_squared = resid_w.norm_squared();
    let dof = n - p;
    let (scale, coverage_factor, method) = if dof == 0 {
        (1.0, COVERAGE_FACTOR, STATED_METHOD)
    } else {
        let t = StudentsT::new(0.0, 1.0, dof as f64)
            .map(|d| d.inverse_cdf(0.975))
            .unwrap_or(COVERAGE_FACTOR);
        (chi_squared / dof as f64, t, SCATTER_METHOD)
    };
    // back to unscaled coefficients: c_j = c_scaled_j / half^j
    let unscale = |j: usize| half.powi(j as i32);
    let coefficients: Vec<f64> = (0..p).map(|j| c_scaled[j] / unscale(j)).collect();
    let mut covariance = vec![0.0; p * p];
    for i in 0..p {
        for j in 0..p {
            covariance[i * p + j] = inv[(i, j)] * scale / (unscale(i) * unscale(j));
        }
    }
    let coefficient_u = (0..p)
        .map(|j| coverage_factor * covariance[j * p + j].max(0.0).sqrt())
        .collect();
    let mut model = TempModel {
        order,
        t_mid_c,
        coefficients,
        coefficient_u,
        covariance,
        coverage_factor,
        dof,
        chi_squared,
        uncertainty_method: method.to_string(),
        residuals: Vec::new(),
    };
    model.residuals = points.iter().map(|pt| pt.y - model.value(pt.t_c)).collect();
    Ok(model)
}

/// Fits the line and, with at least [`QUADRATIC_MIN_TEMPERATURES`] temperatures apart
/// ([`temperatures_apart`]) and five points, the parabola, and chooses
/// between them by the nested F-test on `χ²` (see the module's notes).
pub fn fit(points: &[TempPoint]) -> Result<TempFit, TempcoError> {
    let linear = fit_order(points, 1)?;
    let distinct = temperatures_apart(points);
    // A parabola is a candidate only with four distinct temperatures and two residual degrees
    // of freedom: with one (four points), the F-test picks it exactly when its residual is
    // small by chance, and its U (t with one degree of freedom over that small residual) then
    // covers the truth far less than 95 % of the time (Monte Carlo in the series tests).
    let quadratic = if distinct >= QUADRATIC_MIN_TEMPERATURES && points.len() >= 5 {
        fit_order(points, 2).ok()
    } else {
        None
    };
    let mut tests = Vec::new();
    let mut chosen = Model::Linear;
    let stopped = match &quadratic {
        None => format!(
            "linear: a parabola needs {QUADRATIC_MIN_TEMPERATURES} distinct temperatures and two residual degrees of freedom ({distinct} distinct, {} points)",
            points.len()
        ),
        Some(q) => {
            let t = nested_test(&linear, q, points.len());
            let why = match (t.p_value, &t.note) {
                (_, Some(n)) => n.clone(),
                (Some(p), None) => format!("p = {p:.3e}"),
                (None, None) => "no p-value".to_string(),
            };
            let s = if t.significant {
                chosen = Model::Quadratic;
                format!("linear → quadratic is significant ({why}): quadratic chosen")
            } else {
                format!("linear → quadratic is not significant ({why}): linear kept")
            };
            tests.push(t);
            s
        }
    };
    Ok(TempFit {
        linear,
        quadratic,
        selection: ModelSelection {
            method: gyrocal_fit::selection::MODEL_SELECTION_METHOD.to_string(),
            level: MODEL_SELECTION_LEVEL,
            sse_unit: "1".to_string(),
            tests,
            chosen,
            stopped: Some(stopped),
            note: None,
        },
    })
}

fn nested_test(reduced: &TempModel, full: &TempModel, n: usize) -> NestedTest {
    let df1 = full.order - reduced.order;
    let df2 = n.saturating_sub(full.order + 1);
    let mut t = NestedTest {
        reduced: Model::Linear,
        full: Model::Quadratic,
        sse_reduced: reduced.chi_squared,
        sse_full: full.chi_squared,
        f: None,
        df1,
        df2,
        p_value: None,
        significant: false,
        note: None,
    };
    if df2 == 0 {
        t.note = Some(
            "no residual degrees of freedom: the parabola has as many coefficients as there are points"
                .to_string(),
        );
        return t;
    }
    if full.chi_squared <= 1e-24 {
        t.note = Some("the parabola fits exactly: nothing to test against".to_string());
        return t;
    }
    let f = ((reduced.chi_squared - full.chi_squared).max(0.0) / df1 as f64)
        / (full.chi_squared / df2 as f64);
    match FisherSnedecor::new(df1 as f64, df2 as f64) {
        Ok(d) if f.is_finite() => {
            let p = d.sf(f);
            t.f = Some(f);
            if p.is_finite() {
                t.p_value = Some(p);
                t.significant = p < MODEL_SELECTION_LEVEL;
            } else {
                t.note = Some("the p-value could not be computed".to_string());
            }
        }
        _ => t.note = Some("the F statistic could not be computed".to_string()),
    }
    t
}
