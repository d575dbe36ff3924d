//! The scale-factor analysis of a sweep: a run directory's steps fitted (`gyrocal-fit`), the
//! calibration records attached (the uncertainty budget from the station file, the verdict
//! against the plan's `[acceptance]`), and the analysis stored in `fit.json` through the run
//! directory (atomically, under the run's lock, its SHA-256 in the manifest's `fit_summary`).
//!
//! Moved here from `gyrocal-files` (issue 23): the files crate keeps the formats, the analysis
//! of what they hold lives with the drift analysis, behind one dispatch on the kind
//! ([`crate::analyse`]).

use std::path::Path;

use gyrocal_files::plan::Plan;
use gyrocal_files::rundir::{Manifest, RunData, RunDir, STEPS_CSV, StepRecord, load};
use gyrocal_files::station;

use crate::FitRunError;

/// The fitting crate's data set from a run's recorded steps: the demanded rate (as in the
/// method; the measured rate is reported separately), the mean voltage, its spread and count
/// (so least squares can weight by the standard error of each mean).
pub fn dataset_from_steps(steps: &[StepRecord], source: &str) -> gyrocal_fit::Dataset {
    gyrocal_fit::Dataset {
        source: Some(source.to_string()),
        points: steps
            .iter()
            .map(|s| gyrocal_fit::Point {
                rate_dps: s.rate_dps,
                volts: s.volts,
                volts_std: s.volts_std,
                n: Some(s.n),
                line: None,
            })
            .collect(),
    }
}

/// Fits a run directory's steps with `options`, stores the analysis in `fit.json` (referenced
/// from the manifest with its hash and headline figures), and returns it. With the default options, models the data cannot determine are
/// skipped and listed in the analysis (`skipped`), so a complete run always gets its
/// `fit.json`; only data that cannot determine a line is an error.
///
/// When the plan repeats its schedule (`repeat` > 1), the repeatability
/// `std(K_i, ddof = 1) / mean(K_i)` is computed from the least-squares line of each pass on
/// its own and reported in the metrics; the other figures come from all passes together.
pub fn fit_run(
    run: &mut RunDir,
    options: &gyrocal_fit::Options,
) -> Result<gyrocal_fit::Analysis, FitRunError> {
    let data = load(run.path())?;
    let mut analysis = fit_steps(run.path(), &data.steps, options)?;
    attach_records(&mut analysis, run.manifest());
    run.set_fit(analysis.clone())?;
    Ok(analysis)
}

/// What [`fit_run`] stores, computed from a run read with [`gyrocal_files::load`] without
/// writing anything: the fit of its steps (with the repeatability of its passes) and the
/// records of its manifest attached.
pub fn analyse_steps(
    dir: &Path,
    data: &RunData,
    options: &gyrocal_fit::Options,
) -> Result<gyrocal_fit::Analysis, FitRunError> {
    let mut analysis = fit_steps(dir, &data.steps, options)?;
    attach_records(&mut analysis, &data.manifest);
    Ok(analysis)
}

/// The fit of a run's steps, with the repeatability across its passes (see [`fit_run`]).
fn fit_steps(
    dir: &Path,
    steps: &[StepRecord],
    options: &gyrocal_fit::Options,
) -> Result<gyrocal_fit::Analysis, FitRunError> {
    let source = dir.join(STEPS_CSV).display().to_string();
    let mut analysis = gyrocal_fit::analyze(&dataset_from_steps(steps, &source), options)?;
    let passes: std::collections::BTreeSet<u32> = steps.iter().map(|s| s.pass).collect();
    if passes.len() > 1 {
        let mut ks = Vec::with_capacity(passes.len());
        let mut failed = None;
        for pass in &passes {
            let steps: Vec<StepRecord> =
                steps.iter().filter(|s| s.pass == *pass).cloned().collect();
            match gyrocal_fit::fit_least_squares(
                &dataset_from_steps(&steps, &source),
                gyrocal_fit::Model::Linear,
                options.weighting,
            ) {
                Ok(line) => {
                    tracing::info!(pass, k = line.scale_factor, "scale factor of one pass");
                    ks.push(line.scale_factor);
                }
                // A pass that cannot determine a line (e.g. an incomplete run's last pass)
                // costs the repeatability, never the fit of the whole run.
                Err(e) => {
                    failed = Some(format!("pass {pass}: {e}"));
                    break;
                }
            }
        }
        match failed {
            None => analysis.metrics.set_repeatability(&ks),
            Some(reason) => {
                tracing::warn!(%reason, "no repeatability");
                analysis
                    .metrics
                    .not_computed
                    .push(gyrocal_fit::NotComputed {
                        metric: "repeatability_ppm".to_string(),
                        reason: format!("needs a line per pass: {reason}"),
                    });
            }
        }
    }
    Ok(analysis)
}

/// The calibration records of a fit: the expanded uncertainty from the station's accuracy
/// classes (the statistical part alone without a station) and the verdict against the plan's
/// `[acceptance]` limits.
pub fn attach_records(analysis: &mut gyrocal_fit::Analysis, m: &Manifest) {
    let (inputs, missing) = uncertainty_inputs(m);
    analysis.attach_uncertainty(&inputs);
    if let Some(u) = &mut analysis.uncertainty {
        u.not_included.extend(missing);
    }
    analysis.acceptance = m
        .plan
        .acceptance()
        .and_then(|spec| analysis.evaluate_acceptance(spec));
}

/// The multimeter's range the readings were taken on, V: the plan's fixed range.
fn meter_range(m: &Manifest) -> f64 {
    m.plan.dmm().range_v
}

/// What the station says about the instruments' accuracy, as the budget's inputs, and what
/// it leaves out (in words, for the budget's "not included").
pub fn uncertainty_inputs(
    m: &Manifest,
) -> (gyrocal_fit::uncertainty::UncertaintyInputs, Vec<String>) {
    use gyrocal_fit::uncertainty::{MeterAccuracy, TableRateAccuracy, UncertaintyInputs};
    let mut inputs = UncertaintyInputs::default();
    let mut missing = Vec::new();
    let Some(st) = &m.station else {
        missing.push(
            "the multimeter's and the rate table's accuracy (no station file: instruments not identified)"
                .to_string(),
        );
        return (inputs, missing);
    };
    let range = meter_range(m);
    let meter_name = st.multimeter.as_ref().map_or_else(
        || "multimeter".to_string(),
        |r| format!("{} {}", r.model, r.asset_id),
    );
    match st.meter_accuracy() {
        Some(station::MeterAccuracySpec::Explicit { gain_pct, offset_pct }) => {
            inputs.meter = Some(MeterAccuracy::from_percent(
                format!("{meter_name}: {gain_pct} % of reading + {offset_pct} % of range (station file)"),
                gain_pct,
                offset_pct,
                range,
            ));
        }
        Some(station::MeterAccuracySpec::Period(p)) => {
            if m.plan.dmm().model.is_truevolt() {
                missing.push(format!(
                    "{meter_name}: the Truevolt's DC V specification is not built in; give gain_pct and offset_pct in the station file"
                ));
            } else {
                let period = match p {
                    station::SpecPeriod::Hours24 => gyrocal_hp34401a::facts::SpecPeriod::Hours24,
                    station::SpecPeriod::Days90 => gyrocal_hp34401a::facts::SpecPeriod::Days90,
                    station::SpecPeriod::Year1 => gyrocal_hp34401a::facts::SpecPeriod::Year1,
                };
                match gyrocal_hp34401a::facts::dcv_accuracy(range, period) {
                    Some((gain_pct, offset_pct)) => {
                        inputs.meter = Some(MeterAccuracy::from_percent(
                            format!(
                                "{meter_name}: 34401A DC V {} specification, {range} V range: {gain_pct} % of reading + {offset_pct} % of range",
                                p.as_str()
                            ),
                            gain_pct,
                            offset_pct,
                            range,
                        ));
                    }
                    None => missing.push(format!(
                        "{meter_name}: no 34401A DC V specification for the {range} V range"
                    )),
                }
            }
        }
        None => missing.push(format!(
            "{meter_name}: the station file gives no accuracy class (accuracy, or gain_pct and offset_pct)"
        )),
    }
    match st.table_rate_accuracy_ppm() {
        Some(ppm) => {
            let label = st
                .table
                .as_ref()
                .map(|r| format!("{} {}: rate accuracy (station file)", r.model, r.asset_id));
            inputs.table_rate = Some(TableRateAccuracy::rectangular(ppm, label.as_deref()));
        }
        None => missing.push(
            "the rate table's rate accuracy (rate_accuracy_ppm not in the station file)"
                .to_string(),
        ),
    }
    (inputs, missing)
}

/// One line per default model the sweep's schedule cannot support: the fit will skip it
/// (`gyrocal check` and `gyrocal run` say so before the run).
///
/// Also: rates the table's hold check cannot tell from rest (within its at-rate tolerance of
/// zero), and a schedule that leaves the common-K2 asymmetry fit fewer than
/// [`MIN_ASYMMETRY_DOF`] degrees of freedom (a 5-step plan leaves it 1: its U then rests on one
/// residual, and the figure can come out with the wrong sign).
pub fn plan_warnings(plan: &Plan, path: &Path) -> Vec<String> {
    let rates: Vec<f64> = plan.schedule().iter().map(|s| s.rate_dps).collect();
    let mut distinct = rates.clone();
    distinct.sort_by(f64::total_cmp);
    distinct.dedup();
    let list: Vec<String> = distinct.iter().map(f64::to_string).collect();
    let mut out = model_warnings(path, &rates, &distinct, &list);
    let tolerance = plan.table().rate_tolerance_dps;
    let at_rest: Vec<String> = distinct
        .iter()
        .filter(|r| **r != 0.0 && r.abs() <= tolerance)
        .map(f64::to_string)
        .collect();
    if plan.has_table() && !at_rest.is_empty() {
        out.push(format!(
            "{}: {} °/s is within the table's at-rate tolerance (±{tolerance} °/s) of zero: its hold check cannot tell such a rate from rest; lower [table] rate_tolerance_dps or leave the rate out",
            path.display(),
            at_rest.join(", ")
        ));
    }
    let both_signs = rates.iter().any(|r| *r > 0.0) && rates.iter().any(|r| *r < 0.0);
    // K0, K+, K−, K2 over one mean per step
    let dof = rates.len().saturating_sub(4);
    if both_signs && dof < MIN_ASYMMETRY_DOF {
        out.push(format!(
            "{}: {} steps leave the common-K2 asymmetry fit (K0, K+, K−, K2) {dof} degree{} of freedom (at least {MIN_ASYMMETRY_DOF} wanted): its asymmetry and U rest on too few residuals to be trusted; add rates or passes",
            path.display(),
            rates.len(),
            if dof == 1 { "" } else { "s" }
        ));
    }
    out
}

/// The fewest degrees of freedom the common-K2 asymmetry fit should have before its figure and
/// its U are worth reporting without a warning.
pub const MIN_ASYMMETRY_DOF: usize = 3;

/// One line per default model the schedule cannot support.
fn model_warnings(path: &Path, rates: &[f64], distinct: &[f64], list: &[String]) -> Vec<String> {
    gyrocal_fit::unsupported_models(rates, &gyrocal_fit::Options::default().models)
        .into_iter()
        .map(|s| {
            format!(
                "{}: the schedule has {} distinct rates ({} °/s): the fit will skip the {} model: {}{}",
                path.display(),
                distinct.len(),
                list.join(", "),
                s.model,
                s.reason,
                if s.model == gyrocal_fit::Model::Split {
                    " (so no asymmetry, K+ or K-)"
                } else {
                    ""
                }
            )
        })
        .collect()
}

/// The headline figures of a sweep ([`crate::Figures`]) from its fit document (`fit`: the
/// run's `fit.json`, or the fit a format-1 manifest embedded) and its manifest `m` (the
/// headline figures it records, for a fit document that lacks them). Read typed and
/// leniently: a figure the document lacks, or holds in another form, is `None`; the others
/// are still read.
pub fn figures(fit: &serde_json::Value, m: &Manifest) -> crate::Figures {
    use serde::Deserialize as _;
    let v = view::Fit::deserialize(fit).unwrap_or_default();
    let lsq = |model: &str| {
        v.fits.iter().find(|f| {
            f.method.as_deref() == Some("least-squares") && f.model.as_deref() == Some(model)
        })
    };
    let linear = lsq("linear");
    let common = &v.metrics.asymmetry_common_k2;
    let u = |q: &str| {
        v.uncertainty
            .quantities
            .iter()
            .find(|x| x.quantity.as_deref() == Some(q))
            .and_then(|x| x.expanded_uncertainty)
    };
    let summary = m.fit_summary.as_ref();
    let metrics = &v.metrics;
    crate::Figures {
        scale_factor: metrics.scale_factor.or(summary.map(|s| s.scale_factor)),
        scale_factor_std_error: summary
            .and_then(|s| s.scale_factor_std_error)
            .or_else(|| linear.and_then(|l| l.std_errors.k1)),
        bias_v: metrics.bias_volts.or(summary.map(|s| s.bias_volts)),
        bias_v_std_error: summary
            .and_then(|s| s.bias_std_error)
            .or_else(|| linear.and_then(|l| l.std_errors.k0)),
        bias_dph: metrics.bias_dph,
        k_pos: metrics.scale_factor_positive,
        k_neg: metrics.scale_factor_negative,
        k2: common
            .k2
            .or_else(|| lsq("quadratic").and_then(|q| q.coefficients.k2)),
        nonlinearity_ppm: metrics.nonlinearity_ppm,
        asymmetry_ppm: metrics.asymmetry_ppm,
        asymmetry_common_k2_ppm: common.asymmetry_ppm,
        repeatability_ppm: metrics.repeatability_ppm,
        u_scale_factor: u("scale_factor"),
        u_bias_v: u("bias_v"),
        u_bias_dph: u("bias_dph"),
        u_k_pos: u("k_pos"),
        u_k_neg: u("k_neg"),
        best_model: v.best_model.clone(),
        ..crate::Figures::default()
    }
}

/// The parts of a fit document [`figures`] reads. Every field is lenient: absent, `null` or
/// of another type, it reads as its default, so one odd field (a fit written by an earlier
/// gyrocal) costs that figure, not the others.
mod view {
    use serde::de::DeserializeOwned;
    use serde::{Deserialize, Deserializer};

    /// Any JSON value, read as `T` when it is one, else `T`'s default.
    fn lenient<'de, D: Deserializer<'de>, T: DeserializeOwned + Default>(
        d: D,
    ) -> Result<T, D::Error> {
        let v = serde_json::Value::deserialize(d)?;
        Ok(serde_json::from_value(v).unwrap_or_default())
    }

    /// A finite number, else `None`.
    fn number<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
        let v = serde_json::Value::deserialize(d)?;
        Ok(v.as_f64().filter(|x| x.is_finite()))
    }

    /// Non-empty text (a number as its decimal form), else `None`.
    fn text<'de, D: Deserializer<'de>>(d: D) -> Result<Option<String>, D::Error> {
        Ok(match serde_json::Value::deserialize(d)? {
            serde_json::Value::String(s) if !s.is_empty() => Some(s),
            serde_json::Value::Number(n) => Some(n.to_string()),
            _ => None,
        })
    }

    #[derive(Deserialize, Default)]
    #[serde(default)]
    pub(super) struct Fit {
        #[serde(deserialize_with = "lenient")]
        pub metrics: Metrics,
        #[serde(deserialize_with = "lenient")]
        pub fits: Vec<OneFit>,
        #[serde(deserialize_with = "lenient")]
        pub uncertainty: Uncertainty,
        #[serde(deserialize_with = "text")]
        pub best_model: Option<String>,
    }

    #[derive(Deserialize, Default)]
    #[serde(default)]
    pub(super) struct Metrics {
        #[serde(deserialize_with = "number")]
        pub scale_factor: Option<f64>,
        #[serde(deserialize_with = "number")]
        pub bias_volts: Option<f64>,
        #[serde(deserialize_with = "number")]
        pub bias_dph: Option<f64>,
        #[serde(deserialize_with = "number")]
        pub scale_factor_positive: Option<f64>,
        #[serde(deserialize_with = "number")]
        pub scale_factor_negative: Option<f64>,
        #[serde(deserialize_with = "number")]
        pub nonlinearity_ppm: Option<f64>,
        #[serde(deserialize_with = "number")]
        pub asymmetry_ppm: Option<f64>,
        #[serde(deserialize_with = "number")]
        pub repeatability_ppm: Option<f64>,
        #[serde(deserialize_with = "lenient")]
        pub asymmetry_common_k2: CommonK2,
    }

    #[derive(Deserialize, Default)]
    #[serde(default)]
    pub(super) struct CommonK2 {
        #[serde(deserialize_with = "number")]
        pub k2: Option<f64>,
        #[serde(deserialize_with = "number")]
        pub asymmetry_ppm: Option<f64>,
    }

    #[derive(Deserialize, Default)]
    #[serde(default)]
    pub(super) struct OneFit {
        #[serde(deserialize_with = "text")]
        pub method: Option<String>,
        #[serde(deserialize_with = "text")]
        pub model: Option<String>,
        #[serde(deserialize_with = "lenient")]
        pub std_errors: Coefficients,
        #[serde(deserialize_with = "lenient")]
        pub coefficients: Coefficients,
    }

    #[derive(Deserialize, Default)]
    #[serde(default)]
    pub(super) struct Coefficients {
        #[serde(deserialize_with = "number")]
        pub k0: Option<f64>,
        #[serde(deserialize_with = "number")]
        pub k1: Option<f64>,
        #[serde(deserialize_with = "number")]
        pub k2: Option<f64>,
    }

    #[derive(Deserialize, Default)]
    #[serde(default)]
    pub(super) struct Uncertainty {
        #[serde(deserialize_with = "lenient")]
        pub quantities: Vec<Quantity>,
    }

    #[derive(Deserialize, Default)]
    #[serde(default)]
    pub(super) struct Quantity {
        #[serde(deserialize_with = "text")]
        pub quantity: Option<String>,
        #[serde(deserialize_with = "number")]
        pub expanded_uncertainty: Option<f64>,
    }
}

/// The sweep's part of the analysis crate's one dispatch.
pub struct Kind;

impl crate::KindAnalysis for Kind {
    type Output = gyrocal_fit::Analysis;
    type Options = gyrocal_fit::Options;

    fn plan_warnings(plan: &Plan, path: &Path) -> Vec<String> {
        plan_warnings(plan, path)
    }

    fn analyse(
        dir: &Path,
        data: &RunData,
        opts: &gyrocal_fit::Options,
    ) -> Result<gyrocal_fit::Analysis, crate::AnalysisError> {
        Ok(analyse_steps(dir, data, opts)?)
    }

    fn analyse_run(
        run: &mut RunDir,
        opts: &gyrocal_fit::Options,
    ) -> Result<gyrocal_fit::Analysis, crate::AnalysisError> {
        Ok(fit_run(run, opts)?)
    }

    fn figures(
        _dir: &Path,
        m: &Manifest,
        fit: Option<&serde_json::Value>,
    ) -> Result<Option<crate::Figures>, crate::AnalysisError> {
        Ok(fit.map(|fit| figures(fit, m)))
    }
}
