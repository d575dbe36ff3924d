//! A run's headline figures, whatever its kind ([`Figures`]): what an index of runs (the
//! catalog's `results` row) keeps of the results a run's analysis wrote. Read typed and
//! leniently from the results file by the kind's module ([`crate::sweep::figures`] from
//! `fit.json`, [`crate::drift::DriftFigures`] from `allan.json`), through the one dispatch on
//! the kind ([`crate::figures`]), so the catalog reads no result file of its own.

use serde::{Deserialize, Serialize};

/// The headline figures of a run and their expanded uncertainties (k = 2): a sweep's fit
/// (scale factor, bias, asymmetry, nonlinearity, ...) or a drift record's noise terms, each
/// field optional (absent for a kind that has no such figure, or when the run's results file
/// lacks it). What an index of runs keeps: the catalog's `results` row.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Figures {
    /// Scale factor K, V/(°/s).
    pub scale_factor: Option<f64>,
    /// Standard error of K from the fit, V/(°/s).
    pub scale_factor_std_error: Option<f64>,
    /// Bias K0, V.
    pub bias_v: Option<f64>,
    /// Standard error of K0, V.
    pub bias_v_std_error: Option<f64>,
    /// Bias as a rate, °/h.
    pub bias_dph: Option<f64>,
    /// Scale factor of the positive direction K+, V/(°/s).
    pub k_pos: Option<f64>,
    /// Scale factor of the negative direction K−, V/(°/s).
    pub k_neg: Option<f64>,
    /// Second-order coefficient K2, V/(°/s)² (common-K2 model when present, else the
    /// quadratic least-squares fit).
    pub k2: Option<f64>,
    /// Nonlinearity, ppm.
    pub nonlinearity_ppm: Option<f64>,
    /// Asymmetry (GJB, split lines), ppm.
    pub asymmetry_ppm: Option<f64>,
    /// Asymmetry with a common K2, ppm.
    pub asymmetry_common_k2_ppm: Option<f64>,
    /// Repeatability of K over the passes, ppm.
    pub repeatability_ppm: Option<f64>,
    /// Expanded uncertainty of K, V/(°/s).
    pub u_scale_factor: Option<f64>,
    /// Expanded uncertainty of K0, V.
    pub u_bias_v: Option<f64>,
    /// Expanded uncertainty of the bias, °/h.
    pub u_bias_dph: Option<f64>,
    /// Expanded uncertainty of K+, V/(°/s).
    pub u_k_pos: Option<f64>,
    /// Expanded uncertainty of K−, V/(°/s).
    pub u_k_neg: Option<f64>,
    /// The model the fit chose.
    pub best_model: Option<String>,
    /// A drift test's angle random walk N, °/√h (five-term fit).
    #[serde(default)]
    pub arw_deg_rt_h: Option<f64>,
    /// Expanded uncertainty (k = 2) of N, °/√h.
    #[serde(default)]
    pub u_arw_deg_rt_h: Option<f64>,
    /// A drift test's bias instability B, °/h (five-term fit).
    #[serde(default)]
    pub bias_instability_dph: Option<f64>,
    /// Expanded uncertainty (k = 2) of B, °/h.
    #[serde(default)]
    pub u_bias_instability_dph: Option<f64>,
    /// A drift test's rate random walk K, °/h/√h (five-term fit).
    #[serde(default)]
    pub rrw_dph_rt_h: Option<f64>,
    /// Expanded uncertainty (k = 2) of K, °/h/√h.
    #[serde(default)]
    pub u_rrw_dph_rt_h: Option<f64>,
    /// A drift test's bias, °/h (the Earth rate removed when the run's axis and latitude were
    /// known).
    #[serde(default)]
    pub drift_bias_dph: Option<f64>,
    /// Expanded uncertainty (k = 2) of the drift bias, °/h.
    #[serde(default)]
    pub u_drift_bias_dph: Option<f64>,
    /// GJB bias stability over 100 s windows, °/h.
    #[serde(default)]
    pub bias_stability_100s_dph: Option<f64>,
    /// The analysed record's length, s (after gaps and warm-up).
    #[serde(default)]
    pub drift_duration_s: Option<f64>,
}
