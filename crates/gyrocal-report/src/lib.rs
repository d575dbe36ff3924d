//! gyrocal-report: the calibration report a gyro lab reads before it trusts the numbers.
//!
//! One self-contained HTML file (inline CSS, inline SVG; no script, no font, no network) with
//! the figures of the paper this project follows and the standard metrics around them:
//!
//! * measured output vs rate with the least-squares and neuron lines and the best model;
//! * residuals vs rate of every fit on one scale, in volts and in °/s equivalent;
//! * the neuron's training error per pass (log scale) against the least-squares minimum;
//! * the error surface over (scale factor, bias) as a filled contour map with both optima;
//! * per-step noise vs rate and the table's measured rate error vs rate;
//! * for several runs, the scale factor per run with error bars (repeatability);
//!
//! plus the summary, the per-rate residual table, an estimator comparison (SSE, RMS,
//! max |residual| of every fit, stated honestly) and the run's metadata. Every plot is also
//! written as a separate `.svg` file next to the HTML.
//!
//! # Entry points
//!
//! * [`write_run_report`]: what the run sequencer calls at the end of a run: reads the run
//!   directory, uses its `fit.json` (or fits `steps.csv` when there is none) and writes
//!   `report.html` and the `.svg` files into it.
//! * [`load_input`] reads a run directory or a bare steps CSV into an [`Input`];
//!   [`render`] turns one or more inputs into a [`Report`] (several inputs: repeatability);
//!   [`Report::write`] writes it. [`render_run`] and [`render_steps_csv`] are the one-input
//!   shortcuts.
//!
//! # What it is not
//!
//! No numerics of its own beyond plotting (contour levels, axis ranges): every number comes from
//! `gyrocal-fit` (from `fit.json` when the run has one, so the report and the JSON agree).
//! It never writes anything but the report and its SVG files.

#![deny(missing_docs)]

pub mod allan;
mod certificate;
mod html;
mod input;
mod plots;

use std::fs;
use std::path::{Path, PathBuf};

pub use input::{FitSource, Input, load_input};

use gyrocal_files::rundir::REPORT_HTML;

/// Why a report could not be made. Every variant names the file concerned.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// The run directory could not be read (missing or malformed manifest.json or steps.csv).
    #[error(transparent)]
    Run(#[from] gyrocal_files::RunError),
    /// A bare CSV data set could not be parsed.
    #[error(transparent)]
    Input(#[from] gyrocal_fit::input::InputError),
    /// A file could not be read or written.
    #[error("{}: cannot {action}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What was being done.
        action: &'static str,
        /// The I/O error.
        source: std::io::Error,
    },
    /// `fit.json` (or the manifest's fit) is not a `gyrocal fit --json` document.
    #[error("{}: not a gyrocal fit document: {message}", path.display())]
    FitDocument {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The path is neither a run directory nor a file.
    #[error(
        "{}: no such run directory or steps CSV (a run directory holds manifest.json and steps.csv)",
        path.display()
    )]
    NotFound {
        /// The path given.
        path: PathBuf,
    },
    /// The path exists but is neither a directory nor a regular file (a device, a pipe).
    #[error(
        "{}: not a run directory or a regular file (a device or a pipe is not read)",
        path.display()
    )]
    NotAFile {
        /// The path given.
        path: PathBuf,
    },
    /// A data file for an Allan analysis is missing, garbled or unusable (names the line when one
    /// is at fault).
    #[error("{}{}: {message}", path.display(), line.map(|l| format!(": line {l}")).unwrap_or_default())]
    Data {
        /// The file (or the path given).
        path: PathBuf,
        /// 1-based line, when one line is at fault.
        line: Option<u64>,
        /// What is wrong.
        message: String,
    },
    /// No input was given.
    #[error("nothing to report: give at least one run directory or steps CSV")]
    NoInput,
    /// A plot could not be drawn (a plotters backend error; not expected with finite data).
    #[error("{name}: cannot draw the plot: {message}")]
    Plot {
        /// The plot's file name.
        name: String,
        /// The backend's message.
        message: String,
    },
}

impl ReportError {
    /// True when the error comes from the user's input files (missing, unreadable or
    /// malformed), as opposed to a failure to write the report.
    pub fn is_input_error(&self) -> bool {
        match self {
            ReportError::Run(_)
            | ReportError::Input(_)
            | ReportError::FitDocument { .. }
            | ReportError::NotFound { .. }
            | ReportError::NotAFile { .. }
            | ReportError::Data { .. }
            | ReportError::NoInput => true,
            ReportError::Io { action, .. } => *action == "read",
            ReportError::Plot { .. } => false,
        }
    }
}

/// A rendered report: the HTML document and its plots.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// The self-contained HTML document (the plots are inlined).
    pub html: String,
    /// The plots as `(file name, SVG document)`, e.g. `("fit.svg", "<svg ...")`, in the order
    /// they appear in the HTML.
    pub svgs: Vec<(String, String)>,
    /// What the reader must be told besides the report (the report says it too), e.g. that
    /// the runs come from different plans; the CLI prints each on stderr.
    pub warnings: Vec<String>,
    /// The verdict against acceptance limits of a one-run report (the run's own, or the one
    /// [`apply_acceptance`] re-evaluated); `None` without limits or with several inputs.
    pub acceptance: Option<gyrocal_fit::acceptance::Acceptance>,
}

impl Report {
    /// Writes the HTML to `html_path` and every plot next to it (same directory), each file
    /// atomically (temporary file, then rename). Returns the paths written, HTML first.
    pub fn write(&self, html_path: &Path) -> Result<Vec<PathBuf>, ReportError> {
        let dir = match html_path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let mut written = Vec::with_capacity(self.svgs.len() + 1);
        write_atomic(html_path, self.html.as_bytes())?;
        written.push(html_path.to_path_buf());
        for (name, svg) in &self.svgs {
            let path = dir.join(name);
            let mut doc = String::with_capacity(svg.len() + 40);
            doc.push_str("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
            doc.push_str(svg);
            write_atomic(&path, doc.as_bytes())?;
            written.push(path);
        }
        Ok(written)
    }
}

fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), ReportError> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "report".to_string());
    let tmp = path.with_file_name(format!(".{name}.tmp"));
    fs::write(&tmp, bytes).map_err(|source| ReportError::Io {
        path: tmp.clone(),
        action: "write",
        source,
    })?;
    fs::rename(&tmp, path).map_err(|source| ReportError::Io {
        path: path.to_path_buf(),
        action: "write",
        source,
    })
}

/// Renders the report of one or more inputs. With several, each gets its own sections (plot
/// files prefixed `run1-`, `run2-`, ...) and the report adds the repeatability across them;
/// when their plans differ (by plan hash) it says so instead of calling their spread a
/// repeatability, and [`Report::warnings`] says it too.
pub fn render(inputs: &[Input]) -> Result<Report, ReportError> {
    if inputs.is_empty() {
        return Err(ReportError::NoInput);
    }
    html::render(inputs)
}

/// Re-evaluates one input's acceptance against `spec` (limits from `source`, e.g. a file given
/// to `gyrocal report --acceptance`): the verdict the report shows and returns in
/// [`Report::acceptance`]. The run's own `fit.json` is not changed (its checksum is in the
/// manifest); the report's id changes with the limits applied.
pub fn apply_acceptance(
    input: &mut Input,
    spec: &gyrocal_fit::acceptance::AcceptanceSpec,
    source: &str,
) {
    if let Ok(a) = &mut input.analysis {
        a.acceptance = a.evaluate_acceptance(spec);
        input.acceptance_from = Some(format!(
            "from <code>{}</code>, re-evaluated when this report was made (the run's own verdict, if any, is in its fit.json)",
            html::esc(source)
        ));
    }
}

/// Renders the report of one run directory.
pub fn render_run(run_dir: &Path) -> Result<Report, ReportError> {
    render(&[input::load_run(run_dir)?])
}

/// Renders the report of a bare steps CSV (columns `rate_dps`, `volts`, optional `volts_std`,
/// `n`, `rate_meas_dps`; a run's `steps.csv` qualifies).
pub fn render_steps_csv(path: &Path) -> Result<Report, ReportError> {
    render(&[input::load_csv(path)?])
}

/// Renders the report of several inputs (run directories or steps CSVs), with repeatability.
pub fn render_many(paths: &[PathBuf]) -> Result<Report, ReportError> {
    let inputs = paths
        .iter()
        .map(|p| load_input(p))
        .collect::<Result<Vec<_>, _>>()?;
    render(&inputs)
}

/// The call for the end of a run: reads `run_dir` (its `fit.json`, or fits `steps.csv` when there
/// is none), writes `run_dir/report.html` and the plots (`fit.svg`, `residuals.svg`, ...) next to
/// it, and returns the path of the HTML. Works for incomplete runs too (the report says so at the
/// top).
pub fn write_run_report(run_dir: &Path) -> Result<PathBuf, ReportError> {
    let _span = tracing::info_span!("report", dir = %run_dir.display()).entered();
    let report = render_run(run_dir)?;
    let path = run_dir.join(REPORT_HTML);
    report.write(&path)?;
    tracing::info!(path = %path.display(), plots = report.svgs.len(), "report written");
    Ok(path)
}

/// File name of the Allan analysis document in a run directory.
pub const ALLAN_JSON: &str = "allan.json";
/// File name of the Allan page in a run directory.
pub const ALLAN_HTML: &str = "allan.html";

/// The call for the end of a drift run: analyses `run_dir` ([`allan::analyse_input`]) and writes
/// `run_dir/allan.json` (the [`allan::AllanDocument`], as `gyrocal allan --json` prints it) and
/// `run_dir/allan.html` ([`allan::render_allan`]), each atomically. Returns the document and the
/// paths written (JSON first).
pub fn write_run_allan(
    run_dir: &Path,
    opts: &allan::AllanOptions,
) -> Result<(allan::AllanDocument, Vec<PathBuf>), ReportError> {
    let _span = tracing::info_span!("allan", dir = %run_dir.display()).entered();
    let doc = allan::analyse_input(run_dir, opts)?;
    let json = serde_json::to_string_pretty(&doc).map_err(|e| ReportError::Plot {
        name: ALLAN_JSON.into(),
        message: e.to_string(),
    })?;
    let html = allan::render_allan(&doc)?;
    let (jp, hp) = (run_dir.join(ALLAN_JSON), run_dir.join(ALLAN_HTML));
    write_atomic(&jp, json.as_bytes())?;
    write_atomic(&hp, html.as_bytes())?;
    tracing::info!(json = %jp.display(), html = %hp.display(), "allan analysis written");
    Ok((doc, vec![jp, hp]))
}
