//! What `series.json` holds ([`SeriesDocument`]) and its `catalog` member ([`CatalogSeries`]),
//! whose shape is the contract with the catalog (which defines its own serde structs for it:
//! the catalog depends on this crate, not the other way round).

use serde::{Deserialize, Serialize};

use crate::tempco::{Hysteresis, TempFit};

/// The document's format version.
pub const SERIES_FORMAT: u32 = 1;

/// One temperature of the series, analysed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SeriesPoint {
    /// 0-based index into the plan's `temperatures_c`.
    pub series_point: usize,
    /// The chamber's setpoint, °C.
    pub setpoint_c: f64,
    /// The gyro's (product) temperature during the point's tests: minimum, mean, maximum, °C.
    pub temp_min_c: f64,
    /// Mean, °C (the temperature the point is plotted and modelled at).
    pub temp_mean_c: f64,
    /// Maximum, °C.
    pub temp_max_c: f64,
    /// Scale factor K (fit.json's unit, V/(°/s)) of the sweep, when one was run.
    pub k: Option<f64>,
    /// Its expanded uncertainty (k = 2).
    pub u_k: Option<f64>,
    /// K's weight in the model in temperature, as an expanded uncertainty (k = 2): the
    /// least-squares line's covariance from the readings' own spread, before it is scaled by
    /// the sweep's residual scatter. The scaled U (`u_k`) rests on a few residuals and varies
    /// by a factor of two from sweep to sweep; as weights it made the sensitivity's U cover
    /// the truth ~93 % instead of 95 % (Monte Carlo in the tests).
    #[serde(default)]
    pub u_k_weight: Option<f64>,
    /// Bias as a rate, °/h: the bias record's when there is one, else the sweep's `K0/K·3600`.
    pub bias_dph: Option<f64>,
    /// Its expanded uncertainty (k = 2), °/h.
    pub u_bias_dph: Option<f64>,
    /// Where the bias comes from: `"bias record"` or `"sweep"`.
    pub bias_from: Option<String>,
    /// The sweep's nonlinearity, ppm.
    pub nonlinearity_ppm: Option<f64>,
    /// Its expanded uncertainty (k = 2), ppm.
    pub u_nonlinearity_ppm: Option<f64>,
    /// The sweep's model chosen by the nested F-test.
    pub best_model: Option<String>,
    /// Why a figure could not be computed at this temperature, in words.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

/// A sensitivity over the range with its expanded uncertainty.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sensitivity {
    /// The value (ppm/°C for K, °/h/°C for the bias).
    pub value: f64,
    /// Its expanded uncertainty.
    pub u: f64,
    /// Its coverage factor (Student's t with few points, 2 without residual freedom).
    pub coverage_factor: f64,
    /// The unit.
    pub unit: String,
    /// Order of the model it is the slope of (1 line, 2 parabola).
    pub model_order: usize,
}

/// One acceptance limit on a sensitivity, judged by the guarded rule.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TempcoVerdict {
    /// `k_tempco_ppm_per_c_max` or `bias_tempco_dph_per_c_max`.
    pub limit_key: String,
    /// The limit on the magnitude.
    pub max: f64,
    /// The sensitivity's magnitude judged.
    pub value: Option<f64>,
    /// Its expanded uncertainty.
    pub u: Option<f64>,
    /// `pass` (|value| + U ≤ max), `fail` (|value| − U > max) or `indeterminate`.
    pub verdict: String,
}

/// The analysis of a temperature series: what `series.json` holds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SeriesDocument {
    /// [`SERIES_FORMAT`].
    pub format: u32,
    /// The temperature K is referred to for ppm/°C (the series' first setpoint unless given).
    pub reference_c: f64,
    /// Every temperature, in the order measured.
    pub points: Vec<SeriesPoint>,
    /// K in temperature (absent with fewer than two temperatures with a sweep).
    pub k_model: Option<TempFit>,
    /// The bias (°/h) in temperature.
    pub bias_model: Option<TempFit>,
    /// Sensitivity of K over the range, ppm/°C relative to K at [`SeriesDocument::reference_c`].
    pub k_tempco_ppm_per_c: Option<Sensitivity>,
    /// Sensitivity of the bias over the range, °/h/°C.
    pub bias_tempco_dph_per_c: Option<Sensitivity>,
    /// Revisits of K, in ppm of the first visit's K.
    pub hysteresis_k_ppm: Vec<Hysteresis>,
    /// Revisits of the bias, °/h.
    pub hysteresis_bias_dph: Vec<Hysteresis>,
    /// The verdicts against the plan's limits on the sensitivities.
    pub acceptance: Vec<TempcoVerdict>,
    /// The overall verdict (`fail` if any, else `indeterminate` if any, else `pass`; absent
    /// without limits).
    pub verdict: Option<String>,
    /// What could not be computed, in words.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
    /// The figures the catalog keeps (shape fixed by the contract with the catalog).
    pub catalog: CatalogSeries,
}

/// One temperature as the catalog keeps it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CatalogPoint {
    /// 0-based index into `temperatures_c`.
    pub series_point: usize,
    /// Setpoint, °C.
    pub setpoint_c: f64,
    /// The gyro's minimum temperature during the point's tests, °C.
    pub temp_min_c: f64,
    /// Mean, °C.
    pub temp_mean_c: f64,
    /// Maximum, °C.
    pub temp_max_c: f64,
    /// K, fit.json's unit.
    pub k: Option<f64>,
    /// U(K), k = 2.
    pub u_k: Option<f64>,
    /// Bias, °/h.
    pub bias_dph: Option<f64>,
    /// U(bias), °/h.
    pub u_bias_dph: Option<f64>,
    /// Nonlinearity, ppm.
    pub nonlinearity_ppm: Option<f64>,
}

/// The `catalog` member of `series.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CatalogSeries {
    /// Every temperature.
    pub points: Vec<CatalogPoint>,
    /// K's sensitivity, ppm/°C.
    pub k_tempco_ppm_per_c: Option<f64>,
    /// Its U (k as stated in series.json).
    pub u_k_tempco_ppm_per_c: Option<f64>,
    /// The bias's sensitivity, °/h/°C.
    pub bias_tempco_dph_per_c: Option<f64>,
    /// Its U.
    pub u_bias_tempco_dph_per_c: Option<f64>,
    /// 1 or 2.
    pub k_model_order: Option<usize>,
    /// 1 or 2.
    pub bias_model_order: Option<usize>,
    /// The largest hysteresis of K in magnitude, ppm (null when no temperature is revisited).
    pub hysteresis_k_ppm: Option<f64>,
    /// The largest hysteresis of the bias in magnitude, °/h.
    pub hysteresis_bias_dph: Option<f64>,
    /// The lowest gyro temperature of the series, °C.
    pub t_min_c: Option<f64>,
    /// The highest, °C.
    pub t_max_c: Option<f64>,
}
