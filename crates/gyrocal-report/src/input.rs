//! What a report is made from: a run directory or a bare steps CSV, read and fitted.

use std::path::{Path, PathBuf};

use gyrocal_files::Manifest;
use gyrocal_files::rundir::{FIT_JSON, MANIFEST_JSON, MAX_FIT_BYTES};
use gyrocal_fit::{Analysis, Dataset, MultiAnalysis, Options};

use crate::ReportError;

/// Where the input's fit came from.
#[derive(Debug, Clone, PartialEq)]
pub enum FitSource {
    /// The run's `fit.json` (the numbers are exactly the run's).
    FitJson(PathBuf),
    /// The `fit` member of a manifest of format 1, which embedded the whole fit (no
    /// `fit.json` on disk).
    Manifest(PathBuf),
    /// Fitted by the report from the data with `gyrocal-fit`'s default options.
    Computed,
}

/// One step's acquisition figures, for the noise and rate-error plots.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepStats {
    /// Demanded rate, °/s.
    pub rate_dps: f64,
    /// Standard deviation of the readings, V.
    pub volts_std: Option<f64>,
    /// Mean measured table rate, °/s.
    pub rate_meas_dps: Option<f64>,
    /// Standard deviation of the measured table rate, °/s.
    pub rate_meas_std_dps: Option<f64>,
}

/// One input of a report: the data, its fit and, for a run directory, the manifest.
#[derive(Debug, Clone, PartialEq)]
pub struct Input {
    /// The path given (run directory or CSV file).
    pub path: PathBuf,
    /// The run's manifest (run directories only).
    pub manifest: Option<Manifest>,
    /// The data set the fit uses (one point per finished step).
    pub data: Dataset,
    /// Per-step acquisition figures, in step order.
    pub steps: Vec<StepStats>,
    /// The analysis, or why none could be made (e.g. an aborted run with one step).
    pub analysis: Result<Analysis, String>,
    /// Where the analysis came from.
    pub fit_source: FitSource,
    /// What the reader must know about the input's files (e.g. a `fit.json` that no longer
    /// matches the hash its manifest recorded); shown at the top of the report.
    pub notes: Vec<String>,
    /// Where the analysis's acceptance verdict came from, when not from the run's own plan
    /// (`gyrocal report --acceptance FILE`: the limits re-evaluated at report time). HTML.
    pub acceptance_from: Option<String>,
}

/// Reads a run directory (a directory) or a steps CSV (a file).
pub fn load_input(path: &Path) -> Result<Input, ReportError> {
    if path.is_dir() {
        load_run(path)
    } else if path.is_file() {
        load_csv(path)
    } else if path.exists() {
        // a device or a pipe (/dev/zero): never read an endless input
        Err(ReportError::NotAFile {
            path: path.to_path_buf(),
        })
    } else {
        Err(ReportError::NotFound {
            path: path.to_path_buf(),
        })
    }
}

/// Reads a run directory: manifest, finished steps, and `fit.json` (or the manifest's fit, or a
/// fit computed here when the run has none).
pub(crate) fn load_run(dir: &Path) -> Result<Input, ReportError> {
    if !dir.is_dir() {
        return Err(ReportError::NotFound {
            path: dir.to_path_buf(),
        });
    }
    let run = gyrocal_files::load(dir)?;
    let data = gyrocal_analysis::sweep::dataset_from_steps(&run.steps, &dir.display().to_string());
    let steps = run
        .steps
        .iter()
        .map(|s| StepStats {
            rate_dps: s.rate_dps,
            volts_std: s.volts_std,
            rate_meas_dps: s.rate_meas_dps,
            rate_meas_std_dps: s.rate_meas_std_dps,
        })
        .collect();
    let fit_path = dir.join(FIT_JSON);
    let mut notes = Vec::new();
    let (analysis, fit_source) = if fit_path.exists() {
        let bytes = gyrocal_files::rundir::read_capped(&fit_path, MAX_FIT_BYTES)?;
        if let Some(s) = &run.manifest.fit_summary
            && s.sha256 != gyrocal_files::rundir::sha256_hex(&bytes)
        {
            notes.push(format!(
                "{} is not the file the run wrote: its SHA-256 differs from the one the \
                 manifest recorded ({}); it was edited or replaced since, and the fit below is \
                 that file's",
                fit_path.display(),
                s.sha256
            ));
        }
        let value: serde_json::Value =
            serde_json::from_slice(&bytes).map_err(|e| ReportError::FitDocument {
                path: fit_path.clone(),
                message: e.to_string(),
            })?;
        (
            Ok(analysis_from_json(&fit_path, value)?),
            FitSource::FitJson(fit_path),
        )
    } else if let Some(analysis) = run.manifest.legacy_fit.clone() {
        (Ok(analysis), FitSource::Manifest(dir.join(MANIFEST_JSON)))
    } else {
        // the report's own fit gets the run's records as `fit_run` would give them
        let mut analysis = fit(&data);
        if let Ok(a) = &mut analysis {
            gyrocal_analysis::sweep::attach_records(a, &run.manifest);
        }
        (analysis, FitSource::Computed)
    };
    Ok(Input {
        path: dir.to_path_buf(),
        manifest: Some(run.manifest),
        data,
        steps,
        analysis,
        fit_source,
        notes,
        acceptance_from: None,
    })
}

/// Reads a bare steps CSV and fits it.
pub(crate) fn load_csv(path: &Path) -> Result<Input, ReportError> {
    // gyrocal's one CSV reader (chunked: a regular file only, bounded lines, a byte-order mark
    // skipped), in one pass with the optional measured-rate columns; bounded by rows
    // (`gyrocal fit`'s limit), not by the file's bytes
    let read = gyrocal_fit::input::read_dataset(path, &["rate_meas_dps", "rate_meas_std_dps"])?;
    let data = read.data;
    let measured = |k: usize, i: usize| {
        read.extras
            .get(k)
            .and_then(Option::as_ref)
            .and_then(|c| c.get(i).copied())
            .filter(|v| v.is_finite())
    };
    // the standard deviation only beside a measured rate, as the steps CSV writes them
    let has_meas = read.extras.first().is_some_and(Option::is_some);
    let steps = data
        .points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let (m, s) = if has_meas {
                (measured(0, i), measured(1, i))
            } else {
                (None, None)
            };
            StepStats {
                rate_dps: p.rate_dps,
                volts_std: p.volts_std,
                rate_meas_dps: m,
                rate_meas_std_dps: s,
            }
        })
        .collect();
    let analysis = fit(&data);
    if let Err(message) = &analysis {
        // A CSV is only data: when even a line cannot be fitted, there is nothing to report.
        return Err(ReportError::FitDocument {
            path: path.to_path_buf(),
            message: message.clone(),
        });
    }
    Ok(Input {
        path: path.to_path_buf(),
        manifest: None,
        data,
        steps,
        analysis,
        fit_source: FitSource::Computed,
        notes: Vec::new(),
        acceptance_from: None,
    })
}

/// A run's fit document: an [`Analysis`], or a [`MultiAnalysis`] of one file.
fn analysis_from_json(path: &Path, value: serde_json::Value) -> Result<Analysis, ReportError> {
    match serde_json::from_value::<Analysis>(value.clone()) {
        Ok(a) => Ok(a),
        Err(e) => match serde_json::from_value::<MultiAnalysis>(value) {
            Ok(m) if m.files.len() == 1 => {
                Ok(m.files
                    .into_iter()
                    .next()
                    .ok_or_else(|| ReportError::FitDocument {
                        path: path.to_path_buf(),
                        message: "no analysis".into(),
                    })?)
            }
            _ => Err(ReportError::FitDocument {
                path: path.to_path_buf(),
                message: e.to_string(),
            }),
        },
    }
}

/// Fits the data with the default options: models the data cannot determine are skipped and
/// listed in the analysis (as `gyrocal fit` and a run do); an error only when not even a line
/// can be fitted.
pub(crate) fn fit(data: &Dataset) -> Result<Analysis, String> {
    gyrocal_fit::analyze(data, &Options::default()).map_err(|e| e.to_string())
}
