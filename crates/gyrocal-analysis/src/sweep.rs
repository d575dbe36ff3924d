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
pub fn plan_warnings(plan: &Plan, path: &Path) -> Vec<String> {
    let rates: Vec<f64> = plan.schedule().iter().map(|s| s.rate_dps).collect();
    let mut distinct = rates.clone();
    distinct.sort_by(f64::total_cmp);
    distinct.dedup();
    let list: Vec<String> = distinct.iter().map(f64::to_string).collect();
    gyrocal_fit::unsupported_models(&rates, &gyrocal_fit::Options::default().models)
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
