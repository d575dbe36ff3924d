//! Which model the data support: nested F-tests up the polynomial chain
//! linear → quadratic → cubic.
//!
//! The smallest residual standard error `sqrt(SSE/(N − p))` is not a test: it prefers the
//! bigger model whenever its extra coefficient reduces the SSE by more than one residual
//! variance (`F > 1`), which pure noise does about a third of the time at each step. The
//! nested F-test asks instead whether the reduction is larger than noise would give at a
//! stated level ([`MODEL_SELECTION_LEVEL`]):
//!
//! ```text
//! F = ((SSE_r − SSE_f) / (p_f − p_r)) / (SSE_f / (N − p_f)),   F ~ F(p_f − p_r, N − p_f)
//! ```
//!
//! starting from the linear model and moving up while the step is significant; the first
//! non-significant step stops the climb. Weighted fits use `χ² = Σ r²/σ²` in place of the SSE.
//!
//! The split model (separate K± lines) is not a candidate: its two lines share the zero-rate
//! points, so it is not one least-squares model of the data nested with the polynomials. The
//! joint fit `K0 + K+·ω⁺ + K−·ω⁻ + K2·ω²` ([`crate::AsymmetryCommonK2`]) is the model that
//! tests asymmetry.

use serde::{Deserialize, Serialize};
use statrs::distribution::{ContinuousCDF, FisherSnedecor};

use crate::model::{Fit, Method, Model};

/// Significance level of every step of the model selection: a step up is taken when its
/// F-test p-value is below it.
pub const MODEL_SELECTION_LEVEL: f64 = 0.05;

/// The name of the selection method, as written in [`ModelSelection::method`].
pub const MODEL_SELECTION_METHOD: &str = "nested F-test";

/// Why the split model is not in the chain (written in [`ModelSelection::note`] when it was
/// fitted).
pub const SPLIT_NOT_A_CANDIDATE: &str = "split (separate K+ and K- lines) is not a candidate: its two lines share the zero-rate points, so it is not one least-squares model nested with the polynomials; metrics.asymmetry_common_k2 (K0 + K+·ω⁺ + K−·ω⁻ + K2·ω²) is the model that tests asymmetry";

/// How [`crate::Analysis::best_model`] was chosen. In JSON:
///
/// ```json
/// {"method": "nested F-test", "level": 0.05, "sse_unit": "V^2",
///  "tests": [{"reduced": "linear", "full": "quadratic", "sse_reduced": 1.2e-3,
///             "sse_full": 3.1e-6, "f": 6100.0, "df1": 1, "df2": 16,
///             "p_value": 1.1e-21, "significant": true}],
///  "chosen": "quadratic", "stopped": "..."}
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelSelection {
    /// [`MODEL_SELECTION_METHOD`].
    pub method: String,
    /// Significance level of each step ([`MODEL_SELECTION_LEVEL`]).
    pub level: f64,
    /// Unit of `sse_reduced`/`sse_full`: `"V^2"` (unweighted fits) or `"1"` (weighted fits:
    /// χ² = Σ r²/σ², dimensionless).
    pub sse_unit: String,
    /// The steps tested, in order (empty when only one polynomial model was fitted).
    pub tests: Vec<NestedTest>,
    /// The model chosen: the last model reached by a significant step (linear when none).
    pub chosen: Model,
    /// Why the climb stopped, in words.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stopped: Option<String>,
    /// Remarks, e.g. that the split model is not a candidate ([`SPLIT_NOT_A_CANDIDATE`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

/// One step of the selection: the reduced model against the full model that contains it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NestedTest {
    /// The smaller model.
    pub reduced: Model,
    /// The larger model.
    pub full: Model,
    /// Residual sum of squares of the reduced model ([`ModelSelection::sse_unit`]).
    pub sse_reduced: f64,
    /// Residual sum of squares of the full model ([`ModelSelection::sse_unit`]).
    pub sse_full: f64,
    /// The F statistic (dimensionless); absent when it is undefined or infinite (see `note`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub f: Option<f64>,
    /// Numerator degrees of freedom `p_f − p_r`.
    pub df1: usize,
    /// Denominator degrees of freedom `N − p_f`.
    pub df2: usize,
    /// `P(F(df1, df2) ≥ f)`; absent when it cannot be computed (see `note`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub p_value: Option<f64>,
    /// Whether the full model is significantly better (`p_value < level`).
    pub significant: bool,
    /// Why `f` or `p_value` is absent, or how an exact fit was treated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

impl std::fmt::Display for NestedTest {
    /// `linear → quadratic: F = 15668.000, p = 0.000` (`—` where there is no F or p).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let or_dash = |v: Option<f64>| v.map_or_else(|| "—".to_string(), |v| format!("{v:.3}"));
        write!(
            f,
            "{} → {}: F = {}, p = {}",
            self.reduced,
            self.full,
            or_dash(self.f),
            or_dash(self.p_value)
        )
    }
}

/// Chooses among the least-squares polynomial fits in `fits` (others are ignored) by nested
/// F-tests at [`MODEL_SELECTION_LEVEL`]. `points` is N; `rounding_floor` is the (weighted)
/// SSE below which a fit counts as exact (rounding noise), in the unit of the fits' SSE
/// (χ² for weighted fits). `None` when no polynomial model was fitted.
pub(crate) fn select(fits: &[Fit], points: usize, rounding_floor: f64) -> Option<ModelSelection> {
    let mut cands: Vec<&Fit> = fits
        .iter()
        .filter(|f| f.method == Method::LeastSquares && f.model != Model::Split)
        .collect();
    cands.sort_by_key(|f| f.model);
    cands.dedup_by_key(|f| f.model);
    let first = *cands.first()?;
    let weighted = first.weighted;
    let note = fits
        .iter()
        .any(|f| f.method == Method::LeastSquares && f.model == Model::Split)
        .then(|| SPLIT_NOT_A_CANDIDATE.to_string());
    let mut chosen = first;
    let mut tests = Vec::new();
    let mut stopped = None;
    for &full in &cands[1..] {
        let t = nested_test(chosen, full, points, rounding_floor);
        let significant = t.significant;
        let why = match (t.p_value, &t.note) {
            (_, Some(n)) => n.clone(),
            (Some(p), None) => format!("p = {p:.3e} is not below {MODEL_SELECTION_LEVEL}"),
            (None, None) => "no p-value".to_string(),
        };
        tests.push(t);
        if significant {
            chosen = full;
        } else {
            stopped = Some(format!(
                "{} → {} is not significant ({why}): {} kept",
                chosen.model, full.model, chosen.model
            ));
            break;
        }
    }
    if stopped.is_none() {
        stopped = Some(if tests.is_empty() {
            format!("{} is the only polynomial model fitted", chosen.model)
        } else {
            format!("{} is the largest polynomial model fitted", chosen.model)
        });
    }
    Some(ModelSelection {
        method: MODEL_SELECTION_METHOD.to_string(),
        level: MODEL_SELECTION_LEVEL,
        sse_unit: if weighted { "1" } else { "V^2" }.to_string(),
        tests,
        chosen: chosen.model,
        stopped,
        note,
    })
}

/// The residual sum of squares the test uses: χ² for weighted fits, the SSE otherwise.
fn test_sse(f: &Fit) -> f64 {
    if f.weighted {
        f.chi_squared.unwrap_or(f.sse)
    } else {
        f.sse
    }
}

fn nested_test(reduced: &Fit, full: &Fit, points: usize, floor: f64) -> NestedTest {
    let pr = reduced.model.coefficient_count();
    let pf = full.model.coefficient_count();
    let df1 = pf.saturating_sub(pr);
    let df2 = points.saturating_sub(pf);
    let sse_r = test_sse(reduced);
    let sse_f = test_sse(full);
    let mut t = NestedTest {
        reduced: reduced.model,
        full: full.model,
        sse_reduced: sse_r,
        sse_full: sse_f,
        f: None,
        df1,
        df2,
        p_value: None,
        significant: false,
        note: None,
    };
    if df1 == 0 {
        t.note = Some("the models have the same number of coefficients".to_string());
    } else if df2 == 0 {
        t.note = Some(format!(
            "no residual degrees of freedom: the {} model has as many coefficients as there are points",
            full.model
        ));
    } else if sse_f <= floor {
        if sse_r <= floor {
            t.note = Some(
                "both fits are exact to rounding: the extra coefficients explain nothing"
                    .to_string(),
            );
        } else {
            t.p_value = Some(0.0);
            t.significant = true;
            t.note = Some(format!(
                "the {} model fits exactly (SSE at rounding level): F is infinite",
                full.model
            ));
        }
    } else {
        let f = ((sse_r - sse_f).max(0.0) / df1 as f64) / (sse_f / df2 as f64);
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
    }
    t
}
