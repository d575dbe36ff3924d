//! Expanded uncertainty (k = 2) of the scale factor, the bias and the turning-direction scale
//! factors: a GUM budget written into the analysis (`records.md`, "Uncertainty budget").
//!
//! Every quantity's budget is a list of rows, one per source: the fit's statistical standard
//! error (type A, from the least-squares covariance, `N − p` degrees of freedom) and the
//! instruments' stated accuracies (type B: the multimeter's `% of reading` gain and `% of
//! range` offset, the table's rate accuracy in ppm), each divided by its distribution's
//! divisor (rectangular `√3`) and multiplied by its sensitivity coefficient. The rows are
//! combined by root-sum-of-squares, the effective degrees of freedom by Welch–Satterthwaite,
//! and the expanded uncertainty is `U = 2·u`.
//!
//! How each instrument error enters:
//!
//! * **meter gain** (fraction `g` of every reading): every output scales by `1 + g`, so K, K0,
//!   K+ and K− scale by `1 + g` (`u(K) = |K|·g/√3`), while the bias as a rate `K0/K` is
//!   unchanged (sensitivity 0) and so is the asymmetry.
//! * **meter offset** (fraction of range): a constant added to every reading, an error of K0
//!   (`u = offset·range/√3`, V) and so of the bias as a rate (`·3600/|K|`, °/h), not of K.
//! * **table rate accuracy** (ppm of rate): every rate scales by `1 + ε`, so K, K+ and K− are
//!   off by the relative `ε`, K0 not at all, and the bias as a rate by the relative `ε`.
//!
//! The metrics (ratios, where the meter gain and the table scale cancel) get an expanded
//! uncertainty each in [`MetricUncertainties`], with the method named
//! ([`MetricUncertainty::method`]): the asymmetries analytically from their fit's
//! covariance, the nonlinearity by Monte Carlo ([`crate::nonlinearity`]), the repeatability
//! analytically from the passes, K2 from the quadratic fit. Every quantity an acceptance
//! limit can name has one, so the guarded rule decides on evidence.

use serde::{Deserialize, Serialize};

use crate::analysis::Analysis;
use crate::metrics::NotComputed;
use crate::model::{Fit, Method, Model};

/// The coverage factor of every expanded uncertainty here.
pub const COVERAGE_FACTOR: f64 = 2.0;

/// How the budget is computed, as written in [`Uncertainty::method`].
pub const UNCERTAINTY_METHOD: &str = "GUM (JCGM 100:2008): standard uncertainties of uncorrelated sources combined by root-sum-of-squares; type A from the least-squares fit covariance (scaled by the observed residual variance, N − p degrees of freedom; the bias as a rate uses the K–K0 correlation of the fit); type B from stated limits: rectangular a/√3, triangular a/√6, normal a/k; effective degrees of freedom by Welch–Satterthwaite (type B infinite); expanded uncertainty U = k·u with k = 2 (about 95 % coverage for large degrees of freedom)";

/// Seconds per hour.
const SECONDS_PER_HOUR: f64 = 3600.0;

/// What the budget knows about the instruments. Either may be absent: its rows are then left
/// out and [`Uncertainty::not_included`] says so. In JSON:
/// `{"meter": {...}, "table_rate": {...}}`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct UncertaintyInputs {
    /// The multimeter's DC voltage accuracy.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub meter: Option<MeterAccuracy>,
    /// The rate table's rate accuracy.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table_rate: Option<TableRateAccuracy>,
}

/// A multimeter's DC voltage accuracy, `±(gain·reading + offset·range)`, taken as the limits
/// of a rectangular distribution. In JSON: `{"label": "HP 34401A 10 V range, 1 year",
/// "gain_fraction": 3.5e-5, "offset_fraction": 5e-6, "range_v": 10.0}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeterAccuracy {
    /// What the figures are (instrument, range, calibration period), for the budget.
    pub label: String,
    /// Gain term as a fraction of the reading (dimensionless; `0.0035 %` is `3.5e-5`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gain_fraction: Option<f64>,
    /// Offset term as a fraction of the range (dimensionless; `0.0005 %` is `5e-6`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub offset_fraction: Option<f64>,
    /// The range the readings were taken on, V (needed for the offset term).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub range_v: Option<f64>,
}

impl MeterAccuracy {
    /// From a datasheet's `±(gain_pct % of reading + offset_pct % of range)` on the
    /// `range_v` (V) range, e.g. the 34401A's 10 V range over one year:
    /// `MeterAccuracy::from_percent("HP 34401A 10 V, 1 year", 0.0035, 0.0005, 10.0)`.
    pub fn from_percent(
        label: impl Into<String>,
        gain_pct: f64,
        offset_pct: f64,
        range_v: f64,
    ) -> Self {
        Self {
            label: label.into(),
            gain_fraction: Some(gain_pct / 100.0),
            offset_fraction: Some(offset_pct / 100.0),
            range_v: Some(range_v),
        }
    }
}

/// The distribution a stated limit is taken to have.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Distribution {
    /// Equally likely anywhere within `±a` (manufacturer's limits): divisor `√3`.
    #[default]
    Rectangular,
    /// Triangular within `±a`: divisor `√6`.
    Triangular,
    /// Normal, `a` an expanded uncertainty with coverage factor `k` (default 2): divisor `k`.
    /// Type A rows (a standard error, divisor 1) are marked normal too.
    Normal,
}

impl Distribution {
    /// The divisor turning a stated limit into a standard uncertainty (`k` for normal,
    /// default 2).
    pub fn divisor(self, coverage_factor: Option<f64>) -> f64 {
        match self {
            Distribution::Rectangular => 3.0_f64.sqrt(),
            Distribution::Triangular => 6.0_f64.sqrt(),
            Distribution::Normal => coverage_factor.unwrap_or(2.0),
        }
    }
}

/// The table's rate accuracy: a relative error of every applied rate. In JSON:
/// `{"ppm": 10.0, "distribution": "rectangular", "label": "table datasheet"}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TableRateAccuracy {
    /// The stated limit (or expanded uncertainty, for a normal distribution), ppm of rate.
    pub ppm: f64,
    /// How `ppm` is distributed.
    #[serde(default)]
    pub distribution: Distribution,
    /// Coverage factor of `ppm` when the distribution is normal (default 2); ignored otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coverage_factor: Option<f64>,
    /// Where the figure comes from (datasheet, calibration certificate).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub label: Option<String>,
}

impl TableRateAccuracy {
    /// A datasheet limit of `±ppm` of rate, rectangular.
    pub fn rectangular(ppm: f64, label: Option<&str>) -> Self {
        Self {
            ppm,
            distribution: Distribution::Rectangular,
            coverage_factor: None,
            label: label.map(str::to_string),
        }
    }
}

/// Type A (statistics of the data) or type B (other information, here stated accuracies).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum EvaluationType {
    /// Evaluated statistically, from the fit.
    A,
    /// Evaluated from stated information.
    B,
}

/// One source in a quantity's budget. `standard_uncertainty = stated / divisor ·
/// |sensitivity|`, in the quantity's unit. In JSON: `{"source": "meter gain (...)",
/// "type": "B", "distribution": "rectangular", "stated": 0.0035, "stated_unit": "% of
/// reading", "divisor": 1.732, "sensitivity": 5e-4, "standard_uncertainty": 1.0e-6,
/// "relative_ppm": 20.2}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BudgetRow {
    /// The source, in words.
    pub source: String,
    /// Type A or B.
    #[serde(rename = "type")]
    pub kind: EvaluationType,
    /// Distribution of the stated value.
    pub distribution: Distribution,
    /// The stated value (a limit, or a standard error for type A), in `stated_unit`.
    pub stated: f64,
    /// Unit of `stated` (e.g. `% of reading`, `ppm of rate`, `V`, `V/(°/s)`).
    pub stated_unit: String,
    /// The divisor of `stated` (√3 rectangular, 1 for a standard error).
    pub divisor: f64,
    /// Sensitivity coefficient: the quantity's change per unit of `stated_unit`, in the
    /// quantity's unit per `stated_unit`.
    pub sensitivity: f64,
    /// This row's standard uncertainty, in the quantity's unit.
    pub standard_uncertainty: f64,
    /// `standard_uncertainty / |value|`, ppm (scale factors only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub relative_ppm: Option<f64>,
    /// Degrees of freedom (type A); absent means infinite (type B).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub degrees_of_freedom: Option<f64>,
}

/// The budget of one quantity.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct QuantityUncertainty {
    /// `scale_factor`, `bias_v`, `bias_dph`, `k_pos` or `k_neg`.
    pub quantity: String,
    /// Unit of `value` and the uncertainties (`V/(°/s)`, `V`, `°/h`).
    pub unit: String,
    /// The fit the value and its type A term come from.
    pub from: String,
    /// The value, in `unit`.
    pub value: f64,
    /// Combined standard uncertainty `u` (root-sum-of-squares of the rows), in `unit`.
    pub standard_uncertainty: f64,
    /// Expanded uncertainty `U = k·u`, in `unit`.
    pub expanded_uncertainty: f64,
    /// `U / |value|`, ppm (scale factors only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub relative_expanded_ppm: Option<f64>,
    /// Welch–Satterthwaite effective degrees of freedom; absent means infinite.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub effective_degrees_of_freedom: Option<f64>,
    /// The budget.
    pub rows: Vec<BudgetRow>,
}

/// The expanded uncertainty of a metric.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MetricUncertainty {
    /// The metric's key in [`crate::Metrics`] (`asymmetry_common_k2`, `asymmetry_ppm`,
    /// `nonlinearity_ppm`, `repeatability_ppm`) or `k2`.
    pub metric: String,
    /// Its value, in `unit`.
    pub value: f64,
    /// Its expanded uncertainty (k = 2), in `unit`.
    pub expanded_uncertainty: f64,
    /// Where it comes from and which sources it includes, in words.
    pub from: String,
    /// How U was evaluated, in a few words (`analytic: ...`, `Monte Carlo: ...`). Empty in
    /// documents written before this field existed.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub method: String,
    /// Unit of `value` and `expanded_uncertainty` (absent in documents written before this
    /// field existed: ppm).
    #[serde(default = "ppm", skip_serializing_if = "is_ppm")]
    pub unit: String,
    /// The coverage interval `[low, high]` (about 95 %) when it is not `value ± U`: a
    /// skewed distribution (the repeatability's). `expanded_uncertainty` is then its wider
    /// half, `max(high − value, value − low)`, for display; a verdict uses the interval.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub interval: Option<[f64; 2]>,
}

fn ppm() -> String {
    "ppm".to_string()
}

fn is_ppm(u: &str) -> bool {
    u == "ppm"
}

/// The `p` quantile of the chi-square distribution with `nu` degrees of freedom: the root of
/// `P(ν/2, x/2) = p` (the regularized lower incomplete gamma function) by bisection, to a
/// relative 1e-12. `None` when it cannot be bracketed.
fn chi_squared_quantile(nu: f64, p: f64) -> Option<f64> {
    use statrs::function::gamma::gamma_lr;
    let cdf = |x: f64| gamma_lr(nu / 2.0, x / 2.0);
    let mut hi = nu.max(1.0);
    while cdf(hi) < p {
        hi *= 2.0;
        if !hi.is_finite() || hi > 1e12 {
            return None;
        }
    }
    let mut lo = 0.0;
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if cdf(mid) < p {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-12 * hi {
            break;
        }
    }
    let x = 0.5 * (lo + hi);
    (x.is_finite() && x > 0.0).then_some(x)
}

/// The 95 % coverage interval of the true repeatability given `s` (ppm) measured over
/// `passes` passes: the exact confidence interval of a normal standard deviation,
/// `s·√(ν/χ²(0.975; ν)) .. s·√(ν/χ²(0.025; ν))` with `ν = q − 1`. Skewed (with 3 passes
/// it is 0.52·s .. 6.3·s): the first-order `u(s) = s/√(2ν)` of GUM E.4.3 would cover the
/// truth in only about 78 % of 3-pass runs. `None` for fewer than two passes or a value that
/// is not finite.
pub fn repeatability_interval(s: f64, passes: usize) -> Option<[f64; 2]> {
    if passes < 2 || !s.is_finite() {
        return None;
    }
    let nu = (passes - 1) as f64;
    let (lo_q, hi_q) = (
        chi_squared_quantile(nu, 0.975)?,
        chi_squared_quantile(nu, 0.025)?,
    );
    let s = s.abs();
    let interval = [s * (nu / lo_q).sqrt(), s * (nu / hi_q).sqrt()];
    interval
        .iter()
        .all(|v| v.is_finite() && *v >= 0.0)
        .then_some(interval)
}

/// The metrics' uncertainties, and the metrics without one (with the reason).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct MetricUncertainties {
    /// Metrics with an expanded uncertainty.
    pub entries: Vec<MetricUncertainty>,
    /// Metrics without one, and why.
    pub not_available: Vec<NotComputed>,
}

/// The uncertainty budget of an analysis. In JSON:
/// `{"coverage_factor": 2.0, "method": "...", "inputs": {...}, "quantities": [...],
/// "not_included": [...], "metrics": {"entries": [...], "not_available": [...]}}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Uncertainty {
    /// [`COVERAGE_FACTOR`].
    pub coverage_factor: f64,
    /// [`UNCERTAINTY_METHOD`].
    pub method: String,
    /// The instrument figures used.
    pub inputs: UncertaintyInputs,
    /// One budget per quantity.
    pub quantities: Vec<QuantityUncertainty>,
    /// What the budget does not contain, in words.
    pub not_included: Vec<String>,
    /// The metrics' uncertainties.
    pub metrics: MetricUncertainties,
}

impl Uncertainty {
    /// The expanded uncertainty of `key`: a quantity (`scale_factor`, `bias_v`, `bias_dph`,
    /// `k_pos`, `k_neg`) or a metric in [`MetricUncertainties::entries`].
    pub fn expanded(&self, key: &str) -> Option<f64> {
        self.quantities
            .iter()
            .find(|q| q.quantity == key)
            .map(|q| q.expanded_uncertainty)
            .or_else(|| {
                self.metrics
                    .entries
                    .iter()
                    .find(|m| m.metric == key)
                    .map(|m| m.expanded_uncertainty)
            })
    }

    /// The coverage interval of metric `key` when it is not `value ± U`
    /// ([`MetricUncertainty::interval`]).
    pub fn interval(&self, key: &str) -> Option<[f64; 2]> {
        self.metrics
            .entries
            .iter()
            .find(|m| m.metric == key)
            .and_then(|m| m.interval)
    }

    /// The budget of quantity `key`.
    pub fn quantity(&self, key: &str) -> Option<&QuantityUncertainty> {
        self.quantities.iter().find(|q| q.quantity == key)
    }
}

impl Analysis {
    /// Computes the uncertainty budget ([`compute`]) and stores it in
    /// [`Analysis::uncertainty`].
    pub fn attach_uncertainty(&mut self, inputs: &UncertaintyInputs) {
        self.uncertainty = Some(compute(self, inputs));
    }

    /// The expanded uncertainty (k = 2) of `key` (see [`Uncertainty::expanded`]), when a
    /// budget is attached and has it.
    pub fn expanded_uncertainty(&self, key: &str) -> Option<f64> {
        self.uncertainty.as_ref()?.expanded(key)
    }
}

/// A non-negative finite figure, or why not.
fn usable(x: f64, what: &str) -> Result<f64, String> {
    if x.is_finite() && x >= 0.0 {
        Ok(x)
    } else {
        Err(format!(
            "{what}: {x} is not a finite non-negative number; not included"
        ))
    }
}

/// The type B sources, checked once.
struct Sources {
    gain: Option<(f64, String)>,
    offset: Option<(f64, String)>,
    table: Option<(f64, f64, Distribution, String)>,
}

fn sources(inputs: &UncertaintyInputs, not_included: &mut Vec<String>) -> Sources {
    let mut s = Sources {
        gain: None,
        offset: None,
        table: None,
    };
    match &inputs.meter {
        None => not_included.push("multimeter accuracy: not given".to_string()),
        Some(m) => {
            match m.gain_fraction.map(|g| usable(g, "meter gain")) {
                Some(Ok(g)) => s.gain = Some((g, format!("meter gain ({})", m.label))),
                Some(Err(e)) => not_included.push(e),
                None => not_included.push(format!("meter gain ({}): not given", m.label)),
            }
            match (m.offset_fraction, m.range_v) {
                (Some(o), Some(r)) => match (usable(o, "meter offset"), usable(r, "meter range")) {
                    (Ok(o), Ok(r)) => {
                        s.offset = Some((
                            o * r,
                            format!(
                                "meter offset ({}: {} % of the {} V range)",
                                m.label,
                                o * 100.0,
                                r
                            ),
                        ));
                    }
                    (Err(e), _) | (_, Err(e)) => not_included.push(e),
                },
                (Some(_), None) => not_included.push(format!(
                    "meter offset ({}): the range is not given",
                    m.label
                )),
                (None, _) => not_included.push(format!("meter offset ({}): not given", m.label)),
            }
        }
    }
    match &inputs.table_rate {
        None => not_included.push("table rate accuracy: not given".to_string()),
        Some(t) => {
            let divisor = t.distribution.divisor(t.coverage_factor);
            match usable(t.ppm, "table rate accuracy") {
                Ok(ppm) if divisor.is_finite() && divisor > 0.0 => {
                    let label = t
                        .label
                        .as_deref()
                        .map_or("table rate accuracy".to_string(), |l| {
                            format!("table rate accuracy ({l})")
                        });
                    s.table = Some((ppm, divisor, t.distribution, label));
                }
                Ok(_) => not_included.push(format!(
                    "table rate accuracy: coverage factor {:?} is not usable; not included",
                    t.coverage_factor
                )),
                Err(e) => not_included.push(e),
            }
        }
    }
    s
}

fn type_a(source: String, unit: &str, se: f64, dof: usize) -> BudgetRow {
    BudgetRow {
        source,
        kind: EvaluationType::A,
        distribution: Distribution::Normal,
        stated: se,
        stated_unit: unit.to_string(),
        divisor: 1.0,
        sensitivity: 1.0,
        standard_uncertainty: se,
        relative_ppm: None,
        degrees_of_freedom: Some(dof as f64),
    }
}

fn type_b(
    source: String,
    distribution: Distribution,
    stated: f64,
    stated_unit: &str,
    divisor: f64,
    sensitivity: f64,
) -> BudgetRow {
    BudgetRow {
        source,
        kind: EvaluationType::B,
        distribution,
        stated,
        stated_unit: stated_unit.to_string(),
        divisor,
        sensitivity,
        standard_uncertainty: stated / divisor * sensitivity.abs(),
        relative_ppm: None,
        degrees_of_freedom: None,
    }
}

/// Combines rows into a quantity: RSS, Welch–Satterthwaite, `U = 2u`, relative figures for
/// scale factors. Non-finite rows are dropped (with a note) so nothing here is NaN.
fn combine(
    quantity: &str,
    unit: &str,
    from: String,
    value: f64,
    mut rows: Vec<BudgetRow>,
    relative: bool,
    not_included: &mut Vec<String>,
) -> QuantityUncertainty {
    rows.retain(|r| {
        let ok = r.standard_uncertainty.is_finite() && r.sensitivity.is_finite();
        if !ok {
            not_included.push(format!(
                "{quantity}: {} gave a non-finite figure; not included",
                r.source
            ));
        }
        ok
    });
    let rel = |u: f64| (relative && value != 0.0).then(|| u / value.abs() * 1e6);
    for r in &mut rows {
        r.relative_ppm = rel(r.standard_uncertainty);
    }
    let u = rows
        .iter()
        .map(|r| r.standard_uncertainty * r.standard_uncertainty)
        .sum::<f64>()
        .sqrt();
    let ws: f64 = rows
        .iter()
        .filter_map(|r| {
            let nu = r.degrees_of_freedom?;
            (nu > 0.0 && r.standard_uncertainty > 0.0).then(|| r.standard_uncertainty.powi(4) / nu)
        })
        .sum();
    let effective = (ws > 0.0 && u > 0.0)
        .then(|| u.powi(4) / ws)
        .filter(|v| v.is_finite());
    let expanded = COVERAGE_FACTOR * u;
    QuantityUncertainty {
        quantity: quantity.to_string(),
        unit: unit.to_string(),
        from,
        value,
        standard_uncertainty: u,
        expanded_uncertainty: expanded,
        relative_expanded_ppm: rel(expanded),
        effective_degrees_of_freedom: effective,
        rows,
    }
}

/// Points of a split fit on one side of zero (`ω ≥ 0` or `ω ≤ 0`), from its residuals.
fn side_points(fit: &Fit, positive: bool) -> usize {
    let on = |w: f64| if positive { w >= 0.0 } else { w <= 0.0 };
    if fit.residuals.is_empty() {
        fit.rate_residuals
            .iter()
            .filter(|r| on(r.rate_dps))
            .map(|r| r.n as usize)
            .sum()
    } else {
        fit.residuals.iter().filter(|r| on(r.rate_dps)).count()
    }
}

/// The scale-factor-like rows shared by K, K+ and K−: meter gain and table rate, both
/// relative errors of the scale factor.
fn relative_rows(k: f64, s: &Sources) -> Vec<BudgetRow> {
    let mut rows = Vec::new();
    if let Some((g, label)) = &s.gain {
        rows.push(type_b(
            label.clone(),
            Distribution::Rectangular,
            g * 100.0,
            "% of reading",
            3.0_f64.sqrt(),
            k.abs() / 100.0,
        ));
    }
    if let Some((ppm, divisor, dist, label)) = &s.table {
        rows.push(type_b(
            label.clone(),
            *dist,
            *ppm,
            "ppm of rate",
            *divisor,
            k.abs() * 1e-6,
        ));
    }
    rows
}

/// The uncertainty budget of `analysis` with the instrument figures in `inputs`.
///
/// Quantities: `scale_factor` and `bias_v` (the least-squares line, the reported K and K0),
/// `bias_dph` (`K0/K·3600`), and `k_pos`/`k_neg` when the split model was fitted (the GJB
/// separate lines). Metrics: the joint-fit asymmetry (`asymmetry_common_k2`) and the GJB
/// `asymmetry_ppm`, type A only (the meter gain and the table rate scale K+ and K− alike).
pub fn compute(analysis: &Analysis, inputs: &UncertaintyInputs) -> Uncertainty {
    let mut not_included = Vec::new();
    let s = sources(inputs, &mut not_included);
    let m = &analysis.metrics;
    let sqrt3 = 3.0_f64.sqrt();
    let mut quantities = Vec::new();
    let line = analysis.fit(Method::LeastSquares, Model::Linear);
    let line_from = "least-squares linear fit (the reported K and K0)".to_string();
    let dof_line = analysis.points.saturating_sub(2);
    let k = m.scale_factor;
    let k0 = m.bias_volts;
    let se_k = line.and_then(|f| f.std_errors.k1).filter(|v| v.is_finite());
    let se_k0 = line.and_then(|f| f.std_errors.k0).filter(|v| v.is_finite());
    if se_k.is_none() {
        not_included.push(
            "the statistical (type A) terms of K, K0 and the bias: the linear fit has no standard errors (no residual degrees of freedom, or the linear model was not in the analysis)"
                .to_string(),
        );
    }

    // Scale factor.
    let mut rows = Vec::new();
    if let Some(se) = se_k {
        rows.push(type_a(
            "fit statistics (standard error of K)".to_string(),
            "V/(°/s)",
            se,
            dof_line,
        ));
    }
    rows.extend(relative_rows(k, &s));
    quantities.push(combine(
        "scale_factor",
        "V/(°/s)",
        line_from.clone(),
        k,
        rows,
        true,
        &mut not_included,
    ));

    // Bias, V.
    let mut rows = Vec::new();
    if let Some(se) = se_k0 {
        rows.push(type_a(
            "fit statistics (standard error of K0)".to_string(),
            "V",
            se,
            dof_line,
        ));
    }
    if let Some((v, label)) = &s.offset {
        rows.push(type_b(
            label.clone(),
            Distribution::Rectangular,
            *v,
            "V",
            sqrt3,
            1.0,
        ));
    }
    if let Some((g, label)) = &s.gain {
        rows.push(type_b(
            label.clone(),
            Distribution::Rectangular,
            g * 100.0,
            "% of reading",
            sqrt3,
            k0.abs() / 100.0,
        ));
    }
    quantities.push(combine(
        "bias_v",
        "V",
        line_from.clone(),
        k0,
        rows,
        false,
        &mut not_included,
    ));

    // Bias as a rate, °/h: B = K0/K·3600.
    if k != 0.0 {
        let b = m.bias_dph;
        let mut rows = Vec::new();
        if let (Some(sk), Some(sk0)) = (se_k, se_k0) {
            let rho = m.scale_factor_bias_correlation.unwrap_or(0.0);
            // ∂B/∂K0 = 3600/K, ∂B/∂K = −3600·K0/K².
            let d0 = SECONDS_PER_HOUR / k;
            let dk = -SECONDS_PER_HOUR * k0 / (k * k);
            let var = d0 * d0 * sk0 * sk0 + dk * dk * sk * sk + 2.0 * d0 * dk * rho * sk0 * sk;
            rows.push(type_a(
                format!("fit statistics (K0 and K with their correlation {rho:.3}, propagated)"),
                "°/h",
                var.max(0.0).sqrt(),
                dof_line,
            ));
        }
        if let Some((v, label)) = &s.offset {
            rows.push(type_b(
                label.clone(),
                Distribution::Rectangular,
                *v,
                "V",
                sqrt3,
                SECONDS_PER_HOUR / k.abs(),
            ));
        }
        if let Some((g, label)) = &s.gain {
            rows.push(type_b(
                format!("{label}: K0 and K scale alike, so K0/K does not change"),
                Distribution::Rectangular,
                g * 100.0,
                "% of reading",
                sqrt3,
                0.0,
            ));
        }
        if let Some((ppm, divisor, dist, label)) = &s.table {
            rows.push(type_b(
                label.clone(),
                *dist,
                *ppm,
                "ppm of rate",
                *divisor,
                b.abs() * 1e-6,
            ));
        }
        quantities.push(combine(
            "bias_dph",
            "°/h",
            format!("{line_from}: K0/K·3600"),
            b,
            rows,
            false,
            &mut not_included,
        ));
    } else {
        not_included.push("bias_dph: the scale factor is zero".to_string());
    }

    // K+ and K− from the GJB separate lines.
    match analysis.fit(Method::LeastSquares, Model::Split) {
        Some(split) => {
            for (key, positive, value, se) in [
                (
                    "k_pos",
                    true,
                    split.coefficients.k_pos,
                    split.std_errors.k_pos,
                ),
                (
                    "k_neg",
                    false,
                    split.coefficients.k_neg,
                    split.std_errors.k_neg,
                ),
            ] {
                let Some(value) = value else { continue };
                let dof = side_points(split, positive).saturating_sub(2);
                let mut rows = Vec::new();
                match se.filter(|v| v.is_finite()) {
                    Some(se) => rows.push(type_a(
                        format!("fit statistics (standard error of {key})"),
                        "V/(°/s)",
                        se,
                        dof,
                    )),
                    None => not_included.push(format!(
                        "{key}: the split fit has no standard error (no residual degrees of freedom)"
                    )),
                }
                rows.extend(relative_rows(value, &s));
                let side = if positive { "ω ≥ 0" } else { "ω ≤ 0" };
                quantities.push(combine(
                    key,
                    "V/(°/s)",
                    format!("least-squares split fit (GJB separate lines), the {side} line"),
                    value,
                    rows,
                    true,
                    &mut not_included,
                ));
            }
        }
        None => not_included
            .push("k_pos, k_neg: the split model was not fitted in this analysis".to_string()),
    }

    for what in [
        "table axis alignment (cosine error of the input rate) and wobble",
        "temperature of the gyro and of the instruments (and the meter's temperature coefficient outside its specified band)",
        "the Earth-rate component along the input axis (it enters the bias)",
        "the meter's autozero-off and reading-speed errors (not in its stated accuracy)",
        "run-to-run repeatability (see metrics.repeatability_ppm)",
    ] {
        not_included.push(what.to_string());
    }
    if let Some(best) = analysis.best_model.filter(|b| *b != Model::Linear) {
        not_included.push(format!(
            "a separate lack-of-fit term for the linear model: the data support the {best} model, and the linear fit's residual variance (so its type A terms) already carries the unmodelled curvature"
        ));
    }

    Uncertainty {
        coverage_factor: COVERAGE_FACTOR,
        method: UNCERTAINTY_METHOD.to_string(),
        inputs: echo(inputs),
        quantities,
        not_included,
        metrics: metric_uncertainties(analysis),
    }
}

/// The inputs as written into the budget: non-finite figures (which JSON cannot carry) are
/// left out; `not_included` already says they were not used.
fn echo(inputs: &UncertaintyInputs) -> UncertaintyInputs {
    let finite = |x: Option<f64>| x.filter(|v| v.is_finite());
    UncertaintyInputs {
        meter: inputs.meter.as_ref().map(|m| MeterAccuracy {
            label: m.label.clone(),
            gain_fraction: finite(m.gain_fraction),
            offset_fraction: finite(m.offset_fraction),
            range_v: finite(m.range_v),
        }),
        table_rate: inputs
            .table_rate
            .as_ref()
            .filter(|t| t.ppm.is_finite())
            .map(|t| TableRateAccuracy {
                coverage_factor: finite(t.coverage_factor),
                ..t.clone()
            }),
    }
}

fn metric_uncertainties(analysis: &Analysis) -> MetricUncertainties {
    let m = &analysis.metrics;
    let mut out = MetricUncertainties::default();
    let missing = |metric: &str, reason: String| NotComputed {
        metric: metric.to_string(),
        reason,
    };
    match &m.asymmetry_common_k2 {
        Some(a) => out.entries.push(MetricUncertainty {
            metric: "asymmetry_common_k2".to_string(),
            value: a.asymmetry_ppm,
            expanded_uncertainty: COVERAGE_FACTOR * a.asymmetry_std_error_ppm,
            from: "joint fit K0 + K+·ω⁺ + K−·ω⁻ + K2·ω², type A with the K+/K− covariance (meter gain and table rate scale K+ and K− alike and cancel)".to_string(),
            method: "analytic: first-order propagation of the joint fit's covariance, U = 2σ".to_string(),
            unit: ppm(),
            interval: None,
        }),
        None => out.not_available.push(missing(
            "asymmetry_common_k2",
            "the joint fit was not computed (see metrics.not_computed)".to_string(),
        )),
    }
    let split = analysis.fit(Method::LeastSquares, Model::Split);
    let gjb = split.and_then(|f| {
        let (p, n) = (f.coefficients.k_pos?, f.coefficients.k_neg?);
        let (sp, sn) = (f.std_errors.k_pos?, f.std_errors.k_neg?);
        let sum = p + n;
        if sum == 0.0 {
            return None;
        }
        let a = 2.0 * (p - n) / sum;
        let gp = 4.0 * n / (sum * sum);
        let gn = -4.0 * p / (sum * sum);
        let u = (gp * gp * sp * sp + gn * gn * sn * sn).sqrt() * 1e6;
        (a.is_finite() && u.is_finite()).then_some((a.abs() * 1e6, u))
    });
    match gjb {
        Some((value, u)) => out.entries.push(MetricUncertainty {
            metric: "asymmetry_ppm".to_string(),
            value,
            expanded_uncertainty: COVERAGE_FACTOR * u,
            from: "split fit (GJB separate lines), type A with K+ and K− taken as independent (they share the zero-rate points); it does not cover the bias from an even-order term (see asymmetry_common_k2)".to_string(),
            method: "analytic: first-order propagation of the two lines' standard errors, U = 2σ".to_string(),
            unit: ppm(),
            interval: None,
        }),
        None => out.not_available.push(missing(
            "asymmetry_ppm",
            "needs the split fit with standard errors".to_string(),
        )),
    }
    match &m.nonlinearity_uncertainty {
        Some(nl) => out.entries.push(MetricUncertainty {
            metric: "nonlinearity_ppm".to_string(),
            value: m.nonlinearity_ppm,
            expanded_uncertainty: nl.expanded_uncertainty_ppm,
            from: format!(
                "{} replicates around the {} fit (its own nonlinearity {:.1} ppm); noise: {}; u = {:.3} ppm, noise bias b = {:+.3} ppm, U = 2u + |b|; type A only (the meter gain and the table scale leave the ratio unchanged)",
                nl.replicates,
                nl.reference_model,
                nl.reference_nonlinearity_ppm,
                nl.noise,
                nl.standard_uncertainty_ppm,
                nl.noise_bias_ppm
            ),
            method: format!(
                "Monte Carlo (JCGM 101) over the points' noise through the line fit and the nonlinearity, seed {:#x}",
                nl.seed
            ),
            unit: ppm(),
            interval: None,
        }),
        None => out.not_available.push(missing(
            "nonlinearity_ppm",
            m.not_computed
                .iter()
                .find(|n| n.metric == "nonlinearity_uncertainty")
                .map_or_else(
                    || "the Monte Carlo was not made (a document written before it existed; `gyrocal fit RUN/steps.csv` computes it)".to_string(),
                    |n| format!("the Monte Carlo could not be made: {}", n.reason),
                ),
        )),
    }
    if let Some(r) = m.repeatability_ppm {
        match m
            .repeatability_passes
            .and_then(|q| repeatability_interval(r, q).map(|i| (q, i)))
        {
            Some((q, [lo, hi])) => out.entries.push(MetricUncertainty {
                metric: "repeatability_ppm".to_string(),
                value: r,
                expanded_uncertainty: (hi - r).max(r - lo),
                from: format!(
                    "the standard deviation of {q} passes' K (ν = {}): 95 % interval {lo:.3} .. {hi:.3} ppm",
                    q - 1
                ),
                method: "analytic: the exact chi-square confidence interval of a normal standard deviation (skewed; U is its wider half)"
                    .to_string(),
                unit: ppm(),
                interval: Some([lo, hi]),
            }),
            None => out.not_available.push(missing(
                "repeatability_ppm",
                "the number of passes is not recorded (a document written before it was)".to_string(),
            )),
        }
    }
    let quad = analysis.fit(Method::LeastSquares, Model::Quadratic);
    if let Some((k2, se)) = quad.and_then(|f| Some((f.coefficients.k2?, f.std_errors.k2?)))
        && k2.is_finite()
        && se.is_finite()
    {
        out.entries.push(MetricUncertainty {
            metric: "k2".to_string(),
            value: k2,
            expanded_uncertainty: COVERAGE_FACTOR * se,
            from: "quadratic least-squares fit, type A (scaled by the observed residual variance)"
                .to_string(),
            method: "analytic: the fit's standard error, U = 2σ".to_string(),
            unit: "V/(°/s)²".to_string(),
            interval: None,
        });
    }
    out
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::chi_squared_quantile;

    #[test]
    fn chi_squared_quantiles_match_the_tables() {
        // NIST/SEMATECH e-Handbook, table 1.3.6.7.4 (lower and upper 2.5 % points)
        for (nu, p, x) in [
            (1.0, 0.025, 0.000982),
            (1.0, 0.975, 5.024),
            (2.0, 0.025, 0.0506),
            (2.0, 0.975, 7.378),
            (9.0, 0.025, 2.700),
            (9.0, 0.975, 19.023),
        ] {
            let q = chi_squared_quantile(nu, p).unwrap();
            assert!(
                (q - x).abs() <= 0.001 * x.max(1.0),
                "ν = {nu}, p = {p}: {q}"
            );
        }
    }
}
