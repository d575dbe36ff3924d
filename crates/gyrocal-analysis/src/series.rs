//! A temperature series' analysis: NOT YET WRITTEN (a placeholder, so the kind builds; helper
//! "analysis" replaces this file). Every call says so plainly as an error; nothing here
//! pretends to a result.

use std::path::Path;

use gyrocal_files::plan::Plan;
use gyrocal_files::rundir::{Manifest, RunData, RunDir};

use crate::{AnalysisError, DriftError};

/// What every call says until the analysis exists.
pub const NOT_WRITTEN: &str = "the temperature series analysis is not yet written";

fn not_written(dir: &Path) -> AnalysisError {
    AnalysisError::Drift(DriftError::Data {
        path: dir.to_path_buf(),
        line: None,
        message: NOT_WRITTEN.into(),
    })
}

/// A temperature series (placeholder: every analysis is an error saying it is not written).
pub struct Kind;

impl crate::KindAnalysis for Kind {
    type Output = ();
    type Options = ();

    fn plan_warnings(_plan: &Plan, path: &Path) -> Vec<String> {
        vec![format!(
            "{}: {NOT_WRITTEN}: the run records its steps and temperatures, nothing analyses them yet",
            path.display()
        )]
    }

    fn analyse(dir: &Path, _data: &RunData, _opts: &()) -> Result<(), AnalysisError> {
        Err(not_written(dir))
    }

    fn analyse_run(run: &mut RunDir, _opts: &()) -> Result<(), AnalysisError> {
        Err(not_written(run.path()))
    }

    fn figures(
        _dir: &Path,
        _m: &Manifest,
        _fit: Option<&serde_json::Value>,
    ) -> Result<Option<crate::Figures>, AnalysisError> {
        Ok(None)
    }
}
