//! gyrocal-files: the files a calibration is made of, on paper and on disk. Synchronous, no
//! instrument and no async code: the sequencer writes these formats, and the report, the fit
//! and the CLI read them without pulling in drivers, a runtime or the simulator.
//!
//! - [`plan`]: the operator's test plan. A TOML file is parsed into raw serde structs that
//!   reject unknown keys and keep every value's position, then validated into a typed
//!   [`Plan`] (instrument limits, durations, enums, ports) whose errors name the file, the
//!   line, the column and the key. The plan expands into a stable [`Step`] schedule and has a
//!   content hash that a resume checks.
//! - [`rundir`]: the durable run directory. Every raw reading is appended to `samples.csv` and
//!   flushed per chunk; every finished step is appended to `steps.csv` and fsynced (after the
//!   samples) before the sequencer moves on; `manifest.json` is replaced atomically at every
//!   change. After a crash, even a `SIGKILL` in the middle of a write,
//!   [`RunDir::open_for_resume`] keeps every finished step, drops the partial step's readings
//!   and a torn last line, and tells the sequencer where to continue. The file formats are
//!   documented in [`rundir`]; [`num`] says how computed numbers are written.
//! - [`steps`]: the step vocabulary a plan compiles to (one dispatch on its kind) and the run
//!   engine executes without asking which kind of plan it runs.
//! - [`station`]: the bench a run is made on: laboratory, conditions and the instruments'
//!   calibration records (traceability, due dates), from a station file.
//! - [`fit_run`]: a run directory's steps fitted, the analysis stored beside them.
//! - [`open`]: data files are opened only when they are regular files (never a device, a FIFO
//!   or a directory); [`atomic`]: a file replaced atomically, its temporary file removed on
//!   any failure.

pub mod atomic;
pub mod num;
pub mod open;
pub mod plan;
pub mod rundir;
pub mod station;
pub mod steps;
mod time;

pub use plan::{
    Acquire, Acquisition, DmmModel, DmmSettings, Framing, Location, Plan, PlanDoc, PlanDut,
    PlanError, PlanErrorKind, PlanKind, Port, Simulation, Step, TableDialect, TableSettings,
    acceptance_from_toml_str, load_acceptance,
};
pub use rundir::{
    Deviation, Dut, FitSummary, Instruments, Manifest, Resume, Retry, RunContext, RunData, RunDir,
    RunError, RunErrorKind, RunMeta, RunResults, Sample, SampleRow, Status, StepRecord, Timing,
    WriteResult, load, load_fit, load_samples,
};
pub use station::{
    InstrumentRecord, MeterAccuracySpec, Overdue, STATION_ENV, SpecPeriod, Station, StationError,
    StationErrorKind,
};
pub use time::{ClockAnchor, parse_rfc3339_utc, rfc3339_utc};

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
    let source = run.path().join("steps.csv").display().to_string();
    let mut analysis = gyrocal_fit::analyze(&dataset_from_steps(&data.steps, &source), options)?;
    let passes: std::collections::BTreeSet<u32> = data.steps.iter().map(|s| s.pass).collect();
    if passes.len() > 1 {
        let mut ks = Vec::with_capacity(passes.len());
        let mut failed = None;
        for pass in &passes {
            let steps: Vec<StepRecord> = data
                .steps
                .iter()
                .filter(|s| s.pass == *pass)
                .cloned()
                .collect();
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
    attach_records(&mut analysis, run.manifest());
    run.set_fit(analysis.clone())?;
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

/// Why [`fit_run`] failed.
#[derive(Debug, thiserror::Error)]
pub enum FitRunError {
    /// Reading or writing the run directory.
    #[error(transparent)]
    Run(#[from] RunError),
    /// The fit itself (too few points, ...).
    #[error("fit: {0}")]
    Fit(#[from] gyrocal_fit::FitError),
    /// Serialising the analysis.
    #[error("fit result could not be serialised: {0}")]
    Json(String),
}
