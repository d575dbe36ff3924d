//! gyrocal-analysis: what a run's data say. Synchronous, no runtime, no I/O beyond the run
//! directory (and the bounded-memory path's unnamed temporary files).
//!
//! - [`RunKind`]: the **one** read of a run's kind outside the plan crate. Every consumer that
//!   must treat a sweep and a drift record differently (the end of `gyrocal run`, `gyrocal
//!   report`, the catalog) asks it here, so adding a kind of test is one arm here, not a
//!   search through the binary.
//! - [`analyse`]: the analysis of a run directory by its kind, as an [`Analysis`]: the
//!   scale-factor fit of a sweep ([`sweep`]) or the Allan analysis of a drift record
//!   ([`drift`]). [`analyse_run`] does the same at the end of a run and writes the result
//!   through the run directory (`fit.json` or `allan.json`: atomically, under the run's lock,
//!   with its SHA-256 in the manifest, so `gyrocal verify` checks it).
//! - [`sweep`]: a run's steps fitted (`gyrocal-fit`), the calibration records attached (the
//!   uncertainty budget, the acceptance verdict), `fit.json`.
//! - [`drift`]: the Allan analysis of a record (a run's `samples.csv` or any CSV):
//!   [`drift::AllanDocument`], what `allan.json` holds; [`drift::DriftFigures`], its headline
//!   figures read back typed (the catalog's).
//!
//! Rendering is not here: the report crate turns a [`gyrocal_fit::Analysis`] into
//! `report.html` and an [`drift::AllanDocument`] into `allan.html`.

#![deny(missing_docs)]

use std::path::Path;

use gyrocal_files::plan::{Plan, PlanKind};
use gyrocal_files::rundir::{ALLAN_JSON, FIT_JSON, Manifest, RunDir};

pub mod drift;
mod error;
mod figures;
pub mod sweep;

pub use error::{AnalysisError, DriftError, ErrorKind, FitRunError};
pub use figures::Figures;

/// What the analysis will not be able to do with a run of `plan` (at `path`, for the
/// messages): one line each, said by `gyrocal check` and before `gyrocal run` starts.
pub fn plan_warnings(plan: &Plan, path: &Path) -> Vec<String> {
    match RunKind::of_plan(plan) {
        RunKind::Sweep => sweep::plan_warnings(plan, path),
        // a drift record is analysed by Allan deviation, not fitted
        RunKind::Drift => Vec::new(),
    }
}

/// What kind of analysis a run gets: the one dispatch on a run's kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RunKind {
    /// A sweep of rates: the scale-factor fit (`fit.json`), the report (`report.html`).
    Sweep,
    /// A static record: the Allan analysis (`allan.json`), its page (`allan.html`).
    Drift,
}

impl RunKind {
    /// The kind of the run whose manifest is `m` (its plan's kind).
    pub fn of(m: &Manifest) -> RunKind {
        RunKind::of_plan(&m.plan)
    }

    /// The kind of analysis a run of `plan` will get.
    pub fn of_plan(plan: &Plan) -> RunKind {
        match plan.kind() {
            PlanKind::ScaleFactor => RunKind::Sweep,
            PlanKind::Drift => RunKind::Drift,
        }
    }

    /// The kind of the run in `dir`, or `None` when `dir` is not a readable run directory (a
    /// file, a directory without a manifest, a malformed one: the caller's own reading says
    /// why).
    pub fn of_dir(dir: &Path) -> Option<RunKind> {
        if !dir.is_dir() {
            return None;
        }
        gyrocal_files::load(dir)
            .ok()
            .map(|r| RunKind::of(&r.manifest))
    }

    /// The result file the analysis of this kind writes into the run directory.
    pub fn result_file(self) -> &'static str {
        match self {
            RunKind::Sweep => FIT_JSON,
            RunKind::Drift => ALLAN_JSON,
        }
    }
}

/// How to analyse a run: the options of each kind's analysis (only the run's kind's apply).
#[derive(Debug, Clone, Default)]
pub struct Options {
    /// The scale-factor fit of a sweep.
    pub fit: gyrocal_fit::Options,
    /// The Allan analysis of a drift record.
    pub allan: drift::AllanOptions,
}

/// The analysis of a run, by its kind.
#[derive(Debug, Clone)]
pub enum Analysis {
    /// A sweep's scale-factor fit, with the run's calibration records attached.
    Sweep(Box<gyrocal_fit::Analysis>),
    /// A drift record's Allan analysis.
    Drift(Box<drift::AllanDocument>),
}

impl Analysis {
    /// The kind of run this analysis is of.
    pub fn kind(&self) -> RunKind {
        match self {
            Analysis::Sweep(_) => RunKind::Sweep,
            Analysis::Drift(_) => RunKind::Drift,
        }
    }
}

/// Analyses the run in `dir` by its kind, writing nothing: a sweep's steps fitted with the
/// run's records attached (as [`sweep::fit_run`] would store them), a drift record's Allan
/// analysis (as `allan.json` holds it).
pub fn analyse(dir: &Path, opts: &Options) -> Result<Analysis, AnalysisError> {
    let data = gyrocal_files::load(dir)?;
    match RunKind::of(&data.manifest) {
        RunKind::Sweep => Ok(Analysis::Sweep(Box::new(sweep::analyse_steps(
            dir, &data, &opts.fit,
        )?))),
        RunKind::Drift => Ok(Analysis::Drift(Box::new(drift::analyse_input(
            dir,
            &opts.allan,
        )?))),
    }
}

/// Analyses the run that just ended (its [`RunDir`] still open) by its kind and writes the
/// result through the run directory: `fit.json` for a sweep ([`sweep::fit_run`]),
/// `allan.json` for a drift record ([`drift::write_document`]); each atomically, under the
/// run's lock, its SHA-256 in the manifest. (A drift record's page, `allan.html`, is the
/// report crate's to render and write.)
pub fn analyse_run(run: &mut RunDir, opts: &Options) -> Result<Analysis, AnalysisError> {
    match RunKind::of(run.manifest()) {
        RunKind::Sweep => Ok(Analysis::Sweep(Box::new(sweep::fit_run(run, &opts.fit)?))),
        RunKind::Drift => {
            let doc = drift::analyse_input(run.path(), &opts.allan)?;
            drift::write_document(run, &doc)?;
            Ok(Analysis::Drift(Box::new(doc)))
        }
    }
}

/// The headline figures of the run in `dir` (manifest `m`), read typed from the results file
/// of its kind: a sweep's from its fit document (`fit`: the run's `fit.json`, or the fit a
/// format-1 manifest embedded; `None` when it has none), a drift record's from its
/// `allan.json`. `Ok(None)` when the run has no results yet; an error naming the file when
/// `allan.json` cannot be read.
pub fn figures(
    dir: &Path,
    m: &Manifest,
    fit: Option<&serde_json::Value>,
) -> Result<Option<Figures>, AnalysisError> {
    Ok(match RunKind::of(m) {
        RunKind::Sweep => fit.map(|fit| sweep::figures(fit, m)),
        RunKind::Drift => drift::DriftFigures::load(dir)?.map(|d| d.figures()),
    })
}
