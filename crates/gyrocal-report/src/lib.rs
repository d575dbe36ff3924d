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
//! Every page (this report, the drift page of [`allan`], a gyro's [`history`]) is built on
//! [`page`]: one skeleton, one stylesheet, one HTML escaper.
//!
//! # What it is not
//!
//! No numerics of its own beyond plotting (contour levels, axis ranges): every number comes from
//! `gyrocal-fit` (from `fit.json` when the run has one, so the report and the JSON agree).
//! It never writes anything but the report and its SVG files.

#![deny(missing_docs)]

pub mod allan;
mod certificate;
pub mod history;
mod html;
mod input;
mod kinds;
pub mod live;
pub mod page;
mod plots;
pub mod series_page;
pub mod text;

use std::fs;
use std::path::{Path, PathBuf};

pub use allan::{DRIFT_FILES_READ, write_allan_into, write_run_allan, write_run_allan_noted};
pub use input::{FitSource, Input, load_input};
pub use kinds::{Ending, OwnPage, end_of_run, own_page};

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
    /// The analysis a complete run must have could not be made (a sweep's fit).
    #[error(transparent)]
    Analysis(#[from] gyrocal_analysis::AnalysisError),
    /// Files of the run differ from the run's own record of them (SHA-256 in its manifest),
    /// or the record is missing: the report is refused rather than issued from files nobody
    /// vouches for (`gyrocal report --allow-modified` makes it with a banner naming them).
    #[error(
        "{}: {}; the report is not made from files that differ from the run's record (give --allow-modified to make it anyway, with a banner naming them)",
        path.display(),
        differences.join("; ")
    )]
    Modified {
        /// The run directory.
        path: PathBuf,
        /// Each difference, a sentence naming the file.
        differences: Vec<String>,
    },
    /// Some of the files were written, then one could not be: what was written is on disk
    /// (and recorded), the rest is not.
    #[error(
        "{}; written: {}",
        failed,
        if written.is_empty() { "nothing".to_string() } else { written.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ") }
    )]
    PartlyWritten {
        /// The files written before the failure.
        written: Vec<PathBuf>,
        /// The failure.
        failed: Box<ReportError>,
    },
}

impl ReportError {
    /// True when the error comes from the user's input files (missing, unreadable or
    /// malformed), as opposed to a failure to write the report.
    pub fn is_input_error(&self) -> bool {
        match self {
            // a full disk while writing a run's result is the environment's, not the input's
            ReportError::Run(e) => matches!(
                e.kind(),
                gyrocal_files::RunErrorKind::Input | gyrocal_files::RunErrorKind::Busy
            ),
            ReportError::Modified { .. } => false,
            ReportError::Analysis(e) => e.kind() == gyrocal_analysis::ErrorKind::Input,
            ReportError::PartlyWritten { failed, .. } => failed.is_input_error(),
            ReportError::Input(_)
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

/// Writes a file of the report atomically ([`gyrocal_files::atomic`]): on any failure (a full
/// disk) its temporary file is removed and the old file, if any, stays.
fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), ReportError> {
    gyrocal_files::atomic::write_atomic(path, bytes).map_err(|e| ReportError::Io {
        path: e.path,
        action: "write",
        source: e.source,
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
            page::esc(source)
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
pub const ALLAN_JSON: &str = gyrocal_files::rundir::ALLAN_JSON;
/// File name of the Allan page in a run directory.
pub const ALLAN_HTML: &str = gyrocal_files::rundir::ALLAN_HTML;

/// The files of a scale-factor run its report reads: checked against the run's record by
/// [`check_run`] before the report is made.
pub const SWEEP_FILES_READ: [&str; 2] = [
    gyrocal_files::rundir::STEPS_CSV,
    gyrocal_files::rundir::FIT_JSON,
];
/// The files of a run a report reads, checked against the run's record by [`check_run`].
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RunCheck {
    /// Files that differ from the record, each a sentence naming the file: the report is
    /// refused ([`ReportError::Modified`]) unless the caller allows it, then each is a banner.
    pub differences: Vec<String>,
    /// What could not be checked (a run written before checksums were recorded): said on the
    /// report, never a refusal.
    pub unchecked: Vec<String>,
}

/// Checks the files of the run in `run_dir` that a report reads (`files`, e.g.
/// [`SWEEP_FILES_READ`]) against the run's record (see
/// [`gyrocal_files::rundir::check_files`]). Each file is opened only when it is a regular
/// file.
pub fn check_run(run_dir: &Path, files: &[&str]) -> Result<RunCheck, ReportError> {
    let mut out = RunCheck::default();
    for d in gyrocal_files::rundir::check_files(run_dir, files)? {
        if d.differs {
            out.differences.push(d.text);
        } else {
            out.unchecked.push(d.text);
        }
    }
    Ok(out)
}

impl RunCheck {
    /// The refusal when files differ and `allow_modified` is not given; else the notes for
    /// the report's banners (the differences first, each as [`modified_note`]).
    pub fn notes(self, run_dir: &Path, allow_modified: bool) -> Result<Vec<String>, ReportError> {
        if !self.differences.is_empty() && !allow_modified {
            return Err(ReportError::Modified {
                path: run_dir.to_path_buf(),
                differences: self.differences,
            });
        }
        Ok(self
            .differences
            .iter()
            .map(|d| modified_note(d))
            .chain(self.unchecked.iter().map(|u| format!("NOT CHECKED: {u}.")))
            .collect())
    }
}

/// The banner text of a report made from files that differ from the run's record
/// (`gyrocal report --allow-modified`).
pub fn modified_note(difference: &str) -> String {
    format!(
        "MODIFIED SINCE THE RUN: {difference}. The figures below come from the files as they are now, not as the run recorded them."
    )
}

/// Loads the inputs of a report (run directories or steps CSVs), each run directory checked
/// first against its record ([`check_run`] over [`SWEEP_FILES_READ`]): a difference refuses
/// the report ([`ReportError::Modified`]) unless `allow_modified`, which puts a banner naming
/// each difference on the report instead ([`Input::notes`]); what could not be checked is
/// said there too.
pub fn load_inputs_checked(
    paths: &[PathBuf],
    allow_modified: bool,
) -> Result<Vec<Input>, ReportError> {
    let mut inputs = Vec::with_capacity(paths.len());
    for p in paths {
        let is_run = p.is_dir()
            && fs::symlink_metadata(p.join(gyrocal_files::rundir::MANIFEST_JSON)).is_ok();
        let notes = if is_run {
            check_run(p, &SWEEP_FILES_READ)?.notes(p, allow_modified)?
        } else {
            Vec::new()
        };
        let mut input = load_input(p)?;
        // fit.json's own note (the report always adds it) says the same as ours
        let fit = p
            .join(gyrocal_files::rundir::FIT_JSON)
            .display()
            .to_string();
        let fit_noted = input.notes.iter().any(|n| n.contains(&fit));
        let fit_note = format!(
            "MODIFIED SINCE THE RUN: {}",
            gyrocal_files::rundir::FIT_JSON
        );
        let ours = notes
            .into_iter()
            .filter(|n| !(fit_noted && n.starts_with(&fit_note)));
        input.notes.splice(0..0, ours);
        inputs.push(input);
    }
    Ok(inputs)
}
