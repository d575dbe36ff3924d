//! Scale-factor asymmetry without the even-order bias: one joint least-squares fit
//! `D = K0 + K+·ω⁺ + K−·ω⁻ + K2·ω²` (`ω⁺ = max(ω, 0)`, `ω⁻ = min(ω, 0)`).
//!
//! The GJB 2426A asymmetry fits a separate line to each turning direction. An even-order term
//! `K2·ω²` then tilts the two lines in opposite directions (on `0..ω_max` the chord of `ω²`
//! has slope about `ω_max`), so a gyro with K2 = 2e-5 V/(°/s)² and K = 0.36 V/(°/s) over
//! ±20 °/s shows about 2000 ppm of asymmetry whatever its true asymmetry. Fitting one common
//! `K0` and `K2` with the two scale factors removes that bias; the asymmetry's standard error
//! follows from the fit's covariance, including the correlation of K+ and K−.

use serde::{Deserialize, Serialize};

use crate::lsq::{DesignRow, Prepared, solve_design};

/// The model of [`AsymmetryCommonK2`], as written in its `model` field.
pub const ASYMMETRY_COMMON_K2_MODEL: &str = "K0 + K+·ω⁺ + K−·ω⁻ + K2·ω²";

/// Units of the fields of [`AsymmetryCommonK2`], as written in its `units` field.
pub const ASYMMETRY_COMMON_K2_UNITS: &str = "k0 V; k_pos, k_neg V/(°/s); k2 V/(°/s)²; asymmetry ppm; ω in °/s (ω⁺ = max(ω,0), ω⁻ = min(ω,0))";

/// The joint fit `D = K0 + K+·ω⁺ + K−·ω⁻ + K2·ω²` and the asymmetry it gives,
/// `(K+ − K−) / ((K+ + K−)/2)` in ppm (signed). In JSON:
///
/// ```json
/// {"model": "K0 + K+·ω⁺ + K−·ω⁻ + K2·ω²", "units": "...",
///  "k0": 0.0088, "k_pos": 0.361218, "k_neg": 0.361182, "k2": 2e-5,
///  "k0_std_error": 1e-5, "k_pos_std_error": 2e-6, "k_neg_std_error": 2e-6,
///  "k2_std_error": 1e-7, "k_pos_k_neg_correlation": -0.6,
///  "asymmetry_ppm": 100.0, "asymmetry_std_error_ppm": 15.0,
///  "points": 19, "degrees_of_freedom": 15}
/// ```
///
/// Standard errors are scaled by the observed residual variance, as for the other fits, and
/// the fit uses the same weighting.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AsymmetryCommonK2 {
    /// [`crate::ASYMMETRY_COMMON_K2_MODEL`].
    pub model: String,
    /// [`crate::ASYMMETRY_COMMON_K2_UNITS`].
    #[serde(default)]
    pub units: String,
    /// Bias K0, V.
    pub k0: f64,
    /// Scale factor for `ω ≥ 0`, K+, V/(°/s).
    pub k_pos: f64,
    /// Scale factor for `ω ≤ 0`, K−, V/(°/s).
    pub k_neg: f64,
    /// Common second-order coefficient K2, V/(°/s)².
    pub k2: f64,
    /// Standard error of `k0`, V.
    pub k0_std_error: f64,
    /// Standard error of `k_pos`, V/(°/s).
    pub k_pos_std_error: f64,
    /// Standard error of `k_neg`, V/(°/s).
    pub k_neg_std_error: f64,
    /// Standard error of `k2`, V/(°/s)².
    pub k2_std_error: f64,
    /// Correlation coefficient of K+ and K− (dimensionless, −1..1).
    pub k_pos_k_neg_correlation: f64,
    /// Asymmetry `(K+ − K−) / ((K+ + K−)/2)`, ppm, signed (positive: K+ larger).
    pub asymmetry_ppm: f64,
    /// Standard error of `asymmetry_ppm` by first-order propagation with the covariance of
    /// K+ and K−, ppm.
    pub asymmetry_std_error_ppm: f64,
    /// Points fitted.
    pub points: usize,
    /// Residual degrees of freedom `points − 4`.
    pub degrees_of_freedom: usize,
}

/// The joint fit of prepared data, or why it cannot be made (in words, for
/// [`crate::NotComputed`]).
pub(crate) fn fit(prep: &Prepared<'_>) -> Result<AsymmetryCommonK2, String> {
    let pos = prep.index.positive;
    let neg = prep.index.negative;
    let distinct = prep.index.distinct;
    if pos == 0 || neg == 0 {
        return Err(format!(
            "needs both turning directions: the data have {pos} positive and {neg} negative distinct rate(s)"
        ));
    }
    if distinct < 4 {
        return Err(format!(
            "the model has 4 coefficients and needs at least 4 distinct rates; the data have {distinct}"
        ));
    }
    if prep.len() <= 4 {
        return Err(format!(
            "the model has 4 coefficients and needs more than 4 points for standard errors; the data have {}",
            prep.len()
        ));
    }
    let rates = prep.rates();
    let volts = prep.volts();
    let sigmas = prep.sigmas;
    let rows = || {
        rates
            .iter()
            .zip(volts)
            .enumerate()
            .map(move |(i, (&w, &d))| {
                let wt = sigmas.map_or(1.0, |s| 1.0 / s[i]);
                let row: DesignRow<4> = ([1.0, w.max(0.0), w.min(0.0), w * w], d, wt);
                row
            })
    };
    let sol = solve_design::<4, _>(rows)?;
    let Some(cov) = sol.cov else {
        return Err("no residual degrees of freedom for standard errors".to_string());
    };
    let [k0, kp, kn, k2] = sol.coef;
    let se = |j: usize| cov[j][j].max(0.0).sqrt();
    let sum = kp + kn;
    if sum == 0.0 {
        return Err("K+ + K- is zero: the mean scale factor is zero".to_string());
    }
    let asymmetry_ppm = 2.0 * (kp - kn) / sum * 1e6;
    // ∂A/∂K+ = 4K−/(K+ + K−)², ∂A/∂K− = −4K+/(K+ + K−)² (A as a fraction).
    let gp = 4.0 * kn / (sum * sum) * 1e6;
    let gn = -4.0 * kp / (sum * sum) * 1e6;
    let var = gp * gp * cov[1][1] + gn * gn * cov[2][2] + 2.0 * gp * gn * cov[1][2];
    let denom = (cov[1][1] * cov[2][2]).sqrt();
    let correlation = if denom > 0.0 {
        (cov[1][2] / denom).clamp(-1.0, 1.0)
    } else {
        0.0
    };
    let out = AsymmetryCommonK2 {
        model: ASYMMETRY_COMMON_K2_MODEL.to_string(),
        units: ASYMMETRY_COMMON_K2_UNITS.to_string(),
        k0,
        k_pos: kp,
        k_neg: kn,
        k2,
        k0_std_error: se(0),
        k_pos_std_error: se(1),
        k_neg_std_error: se(2),
        k2_std_error: se(3),
        k_pos_k_neg_correlation: correlation,
        asymmetry_ppm,
        asymmetry_std_error_ppm: var.max(0.0).sqrt(),
        points: sol.points,
        degrees_of_freedom: sol.dof,
    };
    let finite = [
        out.k0_std_error,
        out.k_pos_std_error,
        out.k_neg_std_error,
        out.k2_std_error,
        out.asymmetry_ppm,
        out.asymmetry_std_error_ppm,
    ]
    .iter()
    .all(|v| v.is_finite());
    if finite {
        Ok(out)
    } else {
        Err("the fit gave non-finite figures".to_string())
    }
}
