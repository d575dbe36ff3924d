//! Several runs in one report: each run's scale factor with its standard error, and the
//! repeatability (or, for runs of different plans, the spread that is not one).

use gyrocal_fit::display::value_and_u;
use std::fmt::Write as _;

use gyrocal_files::Status;
use gyrocal_fit::{Analysis, MultiAnalysis};

use super::banners::PlansDiffer;
use super::summary::ls_linear;
use super::{Doc, esc, opt};
use crate::input::Input;
use crate::{ReportError, plots};

pub(super) fn repeatability(
    doc: &mut Doc,
    inputs: &[Input],
    plans: Option<&PlansDiffer>,
) -> Result<(), ReportError> {
    let analyses: Vec<Analysis> = inputs
        .iter()
        .filter_map(|i| i.analysis.as_ref().ok().cloned())
        .collect();
    let multi = MultiAnalysis::from_analyses(analyses);
    if plans.is_some() {
        let _ = writeln!(
            doc.html,
            "<h2 id=\"repeatability\">Scale factor across {} runs of different plans</h2>",
            inputs.len()
        );
    } else {
        let _ = writeln!(
            doc.html,
            "<h2 id=\"repeatability\">Repeatability over {} runs</h2>",
            inputs.len()
        );
    }
    doc.html.push_str("<table class=\"repeatability\">\n<tr><th>run</th><th>source</th><th>K (V/(°/s))</th><th>std error</th><th>K0 (V)</th><th>status</th></tr>\n");
    let mut ks = Vec::new();
    for (i, input) in inputs.iter().enumerate() {
        let status = input.manifest.as_ref().map_or("—", |m| match m.status {
            Status::Complete => "complete",
            Status::Running => "running",
            Status::Aborted => "aborted",
            Status::Failed => "failed",
        });
        match &input.analysis {
            Ok(a) => {
                let se = ls_linear(a).and_then(|f| f.std_errors.k1);
                ks.push((a.metrics.scale_factor, se));
                let _ = writeln!(
                    doc.html,
                    "<tr><td class=\"num\">{}</td><td><code>{}</code></td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{:.6}</td><td>{status}</td></tr>",
                    i + 1,
                    esc(&input.path.display().to_string()),
                    value_and_u(a.metrics.scale_factor, se).0,
                    opt(se, |s| value_and_u(a.metrics.scale_factor, Some(s)).1),
                    a.metrics.bias_volts
                );
            }
            Err(e) => {
                let _ = writeln!(
                    doc.html,
                    "<tr><td class=\"num\">{}</td><td><code>{}</code></td><td colspan=\"3\">no fit: {}</td><td>{status}</td></tr>",
                    i + 1,
                    esc(&input.path.display().to_string()),
                    esc(e)
                );
            }
        }
    }
    doc.html.push_str("</table>\n");
    if plans.is_some() {
        let _ = writeln!(
            doc.html,
            "<p id=\"spread-across-plans\">No repeatability: the runs follow different plans. The spread std(K<sub>i</sub>, ddof = 1) / mean(K<sub>i</sub>) across them is {} ppm over {} fitted runs; it mixes the plans' differences with drift and is not a repeatability figure. Report the runs of each plan together for that.</p>",
            opt(multi.repeatability_ppm, |v| format!("{v:.1}")),
            multi.scale_factors.len()
        );
    } else {
        let _ = writeln!(
            doc.html,
            "<p>Repeatability K<sub>r</sub> = std(K<sub>i</sub>, ddof = 1) / mean(K<sub>i</sub>) = <strong id=\"sum-repeatability\">{}</strong> ppm over {} fitted runs.</p>",
            opt(multi.repeatability_ppm, |v| format!("{v:.1}")),
            multi.scale_factors.len()
        );
    }
    if !ks.is_empty() {
        doc.figure(
            "repeatability.svg".to_string(),
            plots::repeatability_plot(&ks)?,
            if plans.is_some() {
                "Least-squares scale factor of each run with ± one standard error, and their mean. The runs follow different plans: differences between them are not only drift."
            } else {
                "Least-squares scale factor of each run with ± one standard error, and their mean. Scatter well beyond the error bars is drift between runs (temperature, turn-on), not measurement noise."
            },
        );
    }
    Ok(())
}
