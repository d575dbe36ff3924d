//! gyrocal-analysis: what a run's data say. Synchronous, no runtime, no I/O beyond the run
//! directory (and the bounded-memory path's unnamed temporary files).
//!
//! - One module per kind of test ([`sweep`], [`drift`], [`series`]), each with a `Kind` implementing
//!   [`KindAnalysis`]: its analysis, its result file written through the run directory, its
//!   headline figures, its warnings about a plan. The modules, [`Options`], [`Analysis`] and
//!   the one dispatch on the kind ([`analyse`], [`analyse_run`], [`figures`],
//!   [`plan_warnings`]) are generated from the one list of kinds
//!   ([`gyrocal_files::for_each_test_kind`]), so adding a kind of test is its module here,
//!   not an arm in this file, and the binary and the catalog never ask which kind a run is.
//! - [`RunKind`]: the kind of a run (its plan's, [`gyrocal_files::plan::PlanKind`]).
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
//! - [`series`]: a temperature series (`series.json`): each temperature's sweep and bias
//!   record, K and the bias modelled in temperature ([`tempco`]: line or parabola chosen by
//!   the nested F-test, the sensitivities with U, hysteresis), the verdict against the
//!   limits on the sensitivities, and the `catalog` member the catalog reads.
//!
//! Rendering is not here: the report crate turns a [`gyrocal_fit::Analysis`] into
//! `report.html` and an [`drift::AllanDocument`] into `allan.html`.

#![deny(missing_docs)]

use std::path::Path;

use gyrocal_files::plan::Plan;
use gyrocal_files::rundir::{Manifest, RunData, RunDir};

mod error;
mod figures;
pub mod tempco;

pub use error::{AnalysisError, DriftError, ErrorKind, FitRunError};
pub use figures::Figures;

/// What kind of test a run is: its plan's kind ([`RunKind::of`], [`RunKind::of_dir`]), and
/// the result file its analysis writes ([`RunKind::result_file`]).
pub use gyrocal_files::plan::PlanKind as RunKind;

/// A kind of test's analysis: what each kind's module provides (as its `Kind`), so that the
/// one dispatch on the kind is generated from the one list of kinds.
pub trait KindAnalysis {
    /// What the analysis of a run of this kind is.
    type Output: std::fmt::Debug + Clone;
    /// How to analyse it.
    type Options: std::fmt::Debug + Clone + Default;
    /// What the analysis will not be able to do with a run of `plan` (at `path`, for the
    /// messages): one line each.
    fn plan_warnings(plan: &Plan, path: &Path) -> Vec<String>;
    /// Analyses the run in `dir` (read as `data`), writing nothing.
    fn analyse(
        dir: &Path,
        data: &RunData,
        opts: &Self::Options,
    ) -> Result<Self::Output, AnalysisError>;
    /// Analyses the run that just ended (its [`RunDir`] still open) and writes the result
    /// through the run directory (atomically, under the run's lock, its SHA-256 in the
    /// manifest).
    fn analyse_run(run: &mut RunDir, opts: &Self::Options) -> Result<Self::Output, AnalysisError>;
    /// The headline figures of the run in `dir` (manifest `m`; `fit`: its fit document when it
    /// has one), read typed from its result file; `Ok(None)` when it has no results yet.
    fn figures(
        dir: &Path,
        m: &Manifest,
        fit: Option<&serde_json::Value>,
    ) -> Result<Option<Figures>, AnalysisError>;
}

/// The kinds' modules and the one dispatch on the kind, from the one list of kinds.
macro_rules! kinds {
    ($($module:ident => $variant:ident),* $(,)?) => {
        $(pub mod $module;)*

        /// How to analyse a run: the options of each kind's analysis, one field per kind,
        /// named as its module (only the run's kind's apply).
        #[derive(Debug, Clone, Default)]
        pub struct Options {
            $(
                #[doc = concat!("The options of the `", stringify!($module), "` kind's analysis.")]
                pub $module: <$module::Kind as KindAnalysis>::Options,
            )*
        }

        /// The analysis of a run, by its kind.
        #[derive(Debug, Clone)]
        pub enum Analysis {
            $(
                #[doc = concat!("The analysis of a run of the `", stringify!($module), "` kind.")]
                $variant(Box<<$module::Kind as KindAnalysis>::Output>),
            )*
        }

        impl Analysis {
            /// The kind of run this analysis is of.
            pub fn kind(&self) -> RunKind {
                match self {
                    $(Analysis::$variant(_) => RunKind::$variant,)*
                }
            }
        }

        /// What the analysis will not be able to do with a run of `plan` (at `path`, for the
        /// messages): one line each, said by `gyrocal check` and before `gyrocal run` starts.
        pub fn plan_warnings(plan: &Plan, path: &Path) -> Vec<String> {
            match RunKind::of_plan(plan) {
                $(RunKind::$variant => <$module::Kind as KindAnalysis>::plan_warnings(plan, path),)*
            }
        }

        /// Analyses the run in `dir` by its kind, writing nothing (a sweep's steps fitted with
        /// the run's records attached, as [`sweep::fit_run`] would store them; a drift
        /// record's Allan analysis, as `allan.json` holds it).
        pub fn analyse(dir: &Path, opts: &Options) -> Result<Analysis, AnalysisError> {
            let data = gyrocal_files::load(dir)?;
            match RunKind::of(&data.manifest) {
                $(RunKind::$variant => Ok(Analysis::$variant(Box::new(
                    <$module::Kind as KindAnalysis>::analyse(dir, &data, &opts.$module)?,
                ))),)*
            }
        }

        /// Analyses the run that just ended (its [`RunDir`] still open) by its kind and writes
        /// the result through the run directory (`fit.json` for a sweep, `allan.json` for a
        /// drift record; each atomically, under the run's lock, its SHA-256 in the
        /// manifest). A page (`allan.html`, `report.html`) is the report crate's to write.
        pub fn analyse_run(run: &mut RunDir, opts: &Options) -> Result<Analysis, AnalysisError> {
            match RunKind::of(run.manifest()) {
                $(RunKind::$variant => Ok(Analysis::$variant(Box::new(
                    <$module::Kind as KindAnalysis>::analyse_run(run, &opts.$module)?,
                ))),)*
            }
        }

        /// The headline figures of the run in `dir` (manifest `m`), read typed from the
        /// results file of its kind: a sweep's from its fit document (`fit`: the run's
        /// `fit.json`, or the fit a format-1 manifest embedded; `None` when it has none), a
        /// drift record's from its `allan.json`. `Ok(None)` when the run has no results yet;
        /// an error naming the file when `allan.json` cannot be read.
        pub fn figures(
            dir: &Path,
            m: &Manifest,
            fit: Option<&serde_json::Value>,
        ) -> Result<Option<Figures>, AnalysisError> {
            match RunKind::of(m) {
                $(RunKind::$variant => <$module::Kind as KindAnalysis>::figures(dir, m, fit),)*
            }
        }
    };
}
gyrocal_files::for_each_test_kind!(kinds);
