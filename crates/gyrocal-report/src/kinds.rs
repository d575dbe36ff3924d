//! The report crate's one dispatch on a run's kind ([`gyrocal_analysis::RunKind`]): each kind's
//! page module says, in one [`KindPages`], what the end of a complete run of that kind writes
//! and says ([`end_of_run`]) and whether its report is a page of its own, written alone into
//! the run directory ([`own_page`]), instead of the calibration certificate (which combines
//! runs and takes acceptance limits). The kinds' modules and the dispatch are generated from
//! the one list of kinds: adding a kind of test is its module in `kinds/`, no arm here; the
//! binary and the catalog never ask which kind a run is.

use std::path::{Path, PathBuf};

use gyrocal_analysis::RunKind;
use gyrocal_files::RunDir;

use crate::ReportError;

/// What a kind's page module provides.
pub(crate) struct KindPages {
    /// The end of a complete run: analyse, write the result and (when `pages`) its page
    /// through the run directory, and say so.
    pub(crate) ending: fn(&mut RunDir, bool) -> Result<Ending, ReportError>,
    /// `None` when the kind's report is the certificate.
    pub(crate) own_page: Option<OwnPage>,
}

/// The kinds' modules (`kinds/sweep.rs`, `kinds/drift.rs`, each with its [`KindPages`] as
/// `PAGES`) and the one match on the kind in this crate, from the one list of kinds
/// ([`gyrocal_files::for_each_test_kind`]).
macro_rules! kinds {
    ($($module:ident => $variant:ident),* $(,)?) => {
        $(mod $module;)*

        /// The kind's pages.
        fn pages(kind: RunKind) -> &'static KindPages {
            match kind {
                $(RunKind::$variant => &$module::PAGES,)*
            }
        }
    };
}
gyrocal_files::for_each_test_kind!(kinds);

/// What the end of a complete run wrote and has to say.
#[derive(Debug, Clone, Default)]
pub struct Ending {
    /// The results for the operator's terminal (empty: nothing to say).
    pub results: String,
    /// The line saying where the run's page is, when one was written.
    pub page_line: Option<String>,
    /// The run's page, when one was written.
    pub page: Option<PathBuf>,
    /// The run's result in one line (its headline figure with U, k = 2, and the verdict when
    /// judged), when it has one.
    pub result: Option<String>,
    /// What `gyrocal run --json` adds to its document, by key (the headline figures, the
    /// files written).
    pub json: serde_json::Map<String, serde_json::Value>,
    /// Warnings: the run is complete and its data are safe, but a page or an analysis could
    /// not be written (each says how to write it again).
    pub warnings: Vec<String>,
}

/// The end of the complete run `run` (its [`RunDir`] still open), by its kind: its analysis
/// written through the run directory (`fit.json`, `allan.json`), and its page when `pages`
/// (`report.html`, `allan.html`). An error only when the analysis a run must have (a sweep's
/// fit) cannot be made; a page that cannot be written is a warning in the [`Ending`].
pub fn end_of_run(run: &mut RunDir, pages_too: bool) -> Result<Ending, ReportError> {
    (pages(RunKind::of(run.manifest())).ending)(run, pages_too)
}

/// A kind whose report is a page of its own, written alone into its run directory (a drift
/// record's Allan page): no other inputs, no `--out`, no other acceptance limits.
pub struct OwnPage {
    /// The kind's name, as a plan writes it (`drift`).
    pub kind: &'static str,
    /// The run's files the page reads, checked against the run's record first
    /// ([`crate::check_run`]).
    pub files_read: &'static [&'static str],
    /// What the page is, for the line that names it ("a drift record: the Allan analysis").
    pub what: &'static str,
    /// Why it takes no other inputs, `--out` or `--acceptance` (the run directory given).
    pub alone: fn(&Path) -> String,
    /// Writes the page (and the analysis it shows) into the run directory, `notes` first
    /// among its notes; returns the files written.
    pub write: fn(&Path, &[String]) -> Result<Vec<PathBuf>, ReportError>,
}

/// The own page of the run in `dir`, or `None` when its report is the certificate (a sweep,
/// a bare steps CSV, anything that is not a readable run directory).
pub fn own_page(dir: &Path) -> Option<&'static OwnPage> {
    pages(RunKind::of_dir(dir)?).own_page.as_ref()
}
