//! A sweep's part of the report ([`super`]): the end of a complete sweep (its fit stored,
//! its text, its certificate `report.html`). Its report is the certificate, which combines
//! runs and takes acceptance limits: no page of its own.

use gyrocal_files::RunDir;

use super::{Ending, KindPages};
use crate::ReportError;

/// A sweep: its fit, and the certificate.
pub(crate) static PAGES: KindPages = KindPages {
    ending: sweep_ending,
    own_page: None,
};

/// The end of a complete sweep: the fit stored in `fit.json` (with the run's records), its
/// text, and `report.html` when `pages`.
fn sweep_ending(run: &mut RunDir, pages: bool) -> Result<Ending, ReportError> {
    let analysis = gyrocal_analysis::sweep::fit_run(run, &gyrocal_fit::Options::default())
        .map_err(|e| ReportError::Analysis(e.into()))?;
    let mut end = Ending::default();
    let m = run.manifest();
    end.json
        .insert("fit".into(), serde_json::json!(m.fit_summary));
    end.json
        .insert("acceptance".into(), serde_json::json!(m.acceptance));
    crate::text::fit_summary(&mut end.results, &analysis);
    if pages {
        // the data and the fit are safe on disk already: a report failure is a warning
        match crate::write_run_report(run.path()) {
            Ok(path) => {
                end.page_line = Some(format!("report: {}", path.display()));
                end.json.insert("report".into(), serde_json::json!(path));
            }
            Err(e) => end.warnings.push(format!("no report: {e}")),
        }
    }
    Ok(end)
}
