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
    end.result = Some(result_line(&analysis, m));
    if pages {
        // the data and the fit are safe on disk already: a report failure is a warning
        match crate::write_run_report(run.path()) {
            Ok(path) => {
                end.page_line = Some(format!("report: {}", path.display()));
                end.page = Some(path.clone());
                end.json.insert("report".into(), serde_json::json!(path));
            }
            Err(e) => end.warnings.push(format!("no report: {e}")),
        }
    }
    Ok(end)
}

/// "result: K = 0.36120 ± 0.00015 V/(°/s) (k = 2); verdict PASS (guarded rule)": the scale
/// factor as the certificate prints a value with its U, and the verdict when the plan has
/// acceptance limits.
fn result_line(analysis: &gyrocal_fit::Analysis, m: &gyrocal_files::Manifest) -> String {
    let figures = serde_json::to_value(analysis)
        .map(|v| gyrocal_analysis::sweep::figures(&v, m))
        .unwrap_or_default();
    let k = match figures.scale_factor {
        Some(k) => {
            let text = gyrocal_fit::display::value_pm_u(k, figures.u_scale_factor, "V/(°/s)");
            if figures.u_scale_factor.is_some() {
                format!("K = {text} (k = 2)")
            } else {
                format!("K = {text} (no uncertainty budget)")
            }
        }
        None => "no scale factor".to_string(),
    };
    let verdict = match &m.acceptance {
        Some(a) => format!("; verdict {} ({} rule)", a.verdict.label(), a.rule.as_str()),
        None => "; no acceptance limits in the plan".to_string(),
    };
    format!("result: {k}{verdict}")
}
