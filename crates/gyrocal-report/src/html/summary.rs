//! The numbers of one run: the summary table with each metric's definition, the per-rate
//! residual table, the estimator comparison and the plain-words verdict on neuron vs least
//! squares. Formatting only: every figure comes from the run's `Analysis` (gyrocal-fit).

use gyrocal_fit::display::value_and_u;
use std::fmt::Write as _;

use gyrocal_fit::{Analysis, Fit, Method, Model, NeuronStatus};

use super::{esc, opt};
use crate::input::{FitSource, Input};
use crate::plots;

pub(super) fn best_rule_text(a: &Analysis) -> String {
    match a.best_model {
        Some(m) => match &a.model_selection {
            Some(sel) => format!(
                "Best model: {m}, the simplest least-squares model whose added terms are significant ({} at the {} level: a higher order is taken only when it lowers the SSE by more than noise would), so extra coefficients that only fit noise are not chosen.",
                esc(&sel.method),
                sel.level
            ),
            None => format!(
                "Best model: {m} (chosen by an earlier gyrocal, by the smallest residual standard error)."
            ),
        },
        None => "No best model: no least-squares model had degrees of freedom left.".to_string(),
    }
}

pub(super) fn ls_linear(a: &Analysis) -> Option<&Fit> {
    a.fit(Method::LeastSquares, Model::Linear)
}

pub(super) fn summary(html: &mut String, a: &Analysis, sfx: &str, input: &Input) {
    let m = &a.metrics;
    let lin = ls_linear(a);
    let se_k = lin.and_then(|f| f.std_errors.k1);
    let se_k0 = lin.and_then(|f| f.std_errors.k0);
    let weighted = lin.is_some_and(|f| f.weighted);
    let _ = writeln!(html, "<h2 id=\"summary{sfx}\">Summary</h2>");
    let _ = writeln!(
        html,
        "<p class=\"note\">{} points from <code>{}</code>; least-squares line {}. Fit {}.</p>",
        a.points,
        esc(&input.path.display().to_string()),
        if weighted {
            "weighted by 1/σ² (σ = volts_std/√n)"
        } else {
            "unweighted"
        },
        match &input.fit_source {
            FitSource::FitJson(p) =>
                format!("read from <code>{}</code>", esc(&p.display().to_string())),
            FitSource::Manifest(p) => format!(
                "read from the manifest <code>{}</code>",
                esc(&p.display().to_string())
            ),
            FitSource::Computed =>
                "computed by the report (gyrocal-fit, default options)".to_string(),
        }
    );
    if !a.skipped.is_empty() {
        let _ = writeln!(html, "<ul class=\"skipped\" id=\"skipped{sfx}\">");
        for s in &a.skipped {
            let _ = writeln!(
                html,
                "<li>not fitted: {} — {}</li>",
                esc(s.model.name()),
                esc(&s.reason)
            );
        }
        html.push_str("</ul>\n");
    }
    // The reason a metric is missing, appended to its definition.
    let why = |metric: &str| {
        m.not_computed
            .iter()
            .find(|n| n.metric == metric)
            .map_or_else(String::new, |n| {
                format!(" <strong>Not computed: {}</strong>", esc(&n.reason))
            })
    };
    html.push_str("<table class=\"summary\">\n<tr><th>Quantity</th><th>Value</th><th>Std error</th><th>Unit</th><th>Definition</th></tr>\n");
    let mut row = |key: &str,
                   name: &str,
                   value: String,
                   se: Option<String>,
                   unit: &str,
                   def: String| {
        let se_cell = match se {
            Some(s) => format!("<td class=\"num\" id=\"sum-{key}-se{sfx}\">{s}</td>"),
            None => "<td class=\"num\">—</td>".to_string(),
        };
        let _ = writeln!(
            html,
            "<tr><td>{name}</td><td class=\"num\" id=\"sum-{key}{sfx}\">{value}</td>{se_cell}<td>{unit}</td><td class=\"note\">{def}</td></tr>"
        );
    };
    // Each figure rounded as beside its U in the results (the same quantity, the same
    // decimals); a figure without a U to 7 significant digits.
    let unc = a.uncertainty.as_ref();
    let like = |key: &str, v: f64| value_and_u(v, unc.and_then(|u| u.expanded(key))).0;
    // value and standard error in the one rule of every ± (gyrocal_fit::display)
    let (k, k_se) = value_and_u(m.scale_factor, se_k);
    let (k0, k0_se) = value_and_u(m.bias_volts, se_k0);
    row(
        "k",
        "Scale factor K",
        k,
        se_k.map(|_| k_se),
        "V/(°/s)",
        "least-squares line D = K·ω + K0".into(),
    );
    row(
        "k0",
        "Bias K0",
        k0,
        se_k0.map(|_| k0_se),
        "V",
        "intercept of the same line".into(),
    );
    row(
        "nonlinearity",
        "Nonlinearity",
        like("nonlinearity_ppm", m.nonlinearity_ppm),
        None,
        "ppm",
        format!(
            "{} (F<sub>m</sub> = {:.4} V)",
            esc(&m.nonlinearity_normalisation),
            m.full_scale_output
        ),
    );
    row(
        "asymmetry",
        "Asymmetry",
        opt(m.asymmetry_ppm, |v| like("asymmetry_ppm", v)),
        None,
        "ppm",
        format!("|K+ − K−| / ((K+ + K−)/2){}", why("asymmetry_ppm")),
    );
    row(
        "k-pos",
        "K+ (ω ≥ 0)",
        opt(m.scale_factor_positive, |v| like("k_pos", v)),
        None,
        "V/(°/s)",
        format!(
            "least-squares line of the ω ≥ 0 points{}",
            why("scale_factor_positive")
        ),
    );
    row(
        "k-neg",
        "K− (ω ≤ 0)",
        opt(m.scale_factor_negative, |v| like("k_neg", v)),
        None,
        "V/(°/s)",
        format!(
            "least-squares line of the ω ≤ 0 points{}",
            why("scale_factor_negative")
        ),
    );
    row(
        "bias-dps",
        "Bias as a rate",
        format!("{:.5}", m.bias_dps),
        None,
        "°/s",
        "K0 / K (includes the vertical Earth rate)".into(),
    );
    row(
        "bias-dph",
        "Bias as a rate",
        like("bias_dph", m.bias_dph),
        None,
        "°/h",
        "K0 / K × 3600".into(),
    );
    row(
        "repeatability",
        "Repeatability",
        opt(m.repeatability_ppm, |v| like("repeatability_ppm", v)),
        None,
        "ppm",
        format!(
            "std(K<sub>i</sub>, ddof = 1) / mean(K<sub>i</sub>) over the runs in this report (— for one run){}",
            why("repeatability_ppm")
        ),
    );
    row(
        "best-model",
        "Best model",
        a.best_model.map_or_else(|| "—".into(), |m| m.to_string()),
        None,
        "",
        a.model_selection.as_ref().map_or_else(
            || "chosen by an earlier gyrocal (smallest residual standard error)".to_string(),
            |sel| {
                let tests: Vec<String> = sel.tests.iter().map(ToString::to_string).collect();
                format!(
                    "the simplest model whose added terms are significant ({}, level {}): {}",
                    esc(&sel.method),
                    sel.level,
                    tests.join("; ")
                )
            },
        ),
    );
    html.push_str("</table>\n");
}

pub(super) fn residual_table(html: &mut String, a: &Analysis, sfx: &str) {
    let ls = ls_linear(a);
    let nn = a.fit(Method::Neuron, Model::Linear);
    let best = a.best_model.and_then(|m| a.fit(Method::LeastSquares, m));
    let Some(base) = ls.or(nn).or(a.fits.first()) else {
        return;
    };
    let mut order: Vec<usize> = (0..base.residuals.len()).collect();
    order.sort_by(|&i, &j| {
        base.residuals[i]
            .rate_dps
            .total_cmp(&base.residuals[j].rate_dps)
    });
    let _ = writeln!(
        html,
        "<h3 id=\"residual-table{sfx}\">Residual per rate</h3>\n<p class=\"note\">The paper's layout: rate, measured output and each estimator's fit error (measured − fitted), sorted by rate.</p>"
    );
    let best_head = best.map_or_else(
        || "best model".to_string(),
        |f| format!("best model ({})", f.model),
    );
    let _ = writeln!(
        html,
        "<table class=\"residuals\">\n<tr><th>rate (°/s)</th><th>measured (V)</th><th>least squares (mV)</th><th>neuron (mV)</th><th>{best_head} (mV)</th></tr>"
    );
    let cell = |f: Option<&Fit>, i: usize| {
        f.and_then(|f| f.residuals.get(i))
            .map_or_else(|| "—".to_string(), |r| format!("{:.4}", r.residual * 1e3))
    };
    for i in order {
        let r = &base.residuals[i];
        let _ = writeln!(
            html,
            "<tr><td class=\"num\">{}</td><td class=\"num\">{:.6}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td></tr>",
            r.rate_dps,
            r.volts,
            cell(ls, i),
            cell(nn, i),
            cell(best, i)
        );
    }
    html.push_str("</table>\n");
}

pub(super) fn estimators(html: &mut String, a: &Analysis, sfx: &str) {
    let _ = writeln!(
        html,
        "<h3 id=\"estimators{sfx}\">Estimator comparison</h3>\n<table class=\"estimators\">\n<tr><th>fit</th><th>K (V/(°/s))</th><th>K0 (V)</th><th>SSE (V²)</th><th>RMS residual (mV)</th><th>max |residual| (mV)</th><th>residual std error (mV)</th><th>status</th></tr>"
    );
    for f in &a.fits {
        let best = f.method == Method::LeastSquares && Some(f.model) == a.best_model;
        let status = match &f.neuron {
            Some(t) => match t.status {
                NeuronStatus::Converged => format!(
                    "converged ({} online + {} batch passes)",
                    t.online_passes, t.batch_passes
                ),
                NeuronStatus::MaxPasses => format!(
                    "NOT converged: pass limit ({} online + {} batch passes)",
                    t.online_passes, t.batch_passes
                ),
                NeuronStatus::Diverged { pass } => format!("DIVERGED at pass {pass}"),
            },
            None if best => "exact (QR); best model".to_string(),
            None => "exact (QR)".to_string(),
        };
        let _ = writeln!(
            html,
            "<tr{}><td>{}</td><td class=\"num\">{:.7}</td><td class=\"num\">{:.6}</td><td class=\"num\">{}</td><td class=\"num\">{:.4}</td><td class=\"num\">{:.4}</td><td class=\"num\">{}</td><td>{status}</td></tr>",
            if best { " class=\"best\"" } else { "" },
            plots::fit_name(f),
            f.scale_factor,
            f.bias,
            gyrocal_fit::display::significant(f.sse, 5),
            f.rms_residual * 1e3,
            f.max_abs_residual * 1e3,
            opt(f.residual_std_error, |v| format!("{:.4}", v * 1e3)),
        );
    }
    html.push_str("</table>\n");
    let _ = writeln!(html, "<p id=\"verdict{sfx}\">{}</p>", verdict(a));
}

/// The comparison in words. The neuron is never called better when its SSE is larger; it cannot
/// be smaller than the least-squares SSE except by rounding.
pub(crate) fn verdict(a: &Analysis) -> String {
    let mut out = String::new();
    match (ls_linear(a), a.fit(Method::Neuron, Model::Linear)) {
        (Some(ls), Some(nn)) => {
            let rel = if ls.sse > 0.0 {
                (nn.sse - ls.sse) / ls.sse
            } else {
                nn.sse - ls.sse
            };
            if rel <= 1e-9 {
                let _ = write!(
                    out,
                    "The neuron reached the least-squares line: its SSE equals least squares' to rounding (relative difference {}). That is what a converged linear neuron must do, since the least-squares line is the minimum of this error; it is not better, only equal. ",
                    gyrocal_fit::display::significant(rel, 2)
                );
            } else {
                let _ = write!(
                    out,
                    "The neuron's SSE is <strong>larger</strong> than least squares' by {:.3} % ({} V² against {} V²): it stopped near, not at, the minimum. Least squares is the better estimate of the straight line. ",
                    rel * 100.0,
                    gyrocal_fit::display::significant(nn.sse, 5),
                    gyrocal_fit::display::significant(ls.sse, 5)
                );
            }
        }
        (Some(_), None) => out.push_str("The neuron was not run on this data. "),
        _ => {}
    }
    if let (Some(ls), Some(m)) = (ls_linear(a), a.best_model)
        && m != Model::Linear
        && let Some(b) = a.fit(Method::LeastSquares, m)
        && ls.rms_residual > 0.0
    {
        let _ = write!(
            out,
            "The real improvement is the model: the {m} model's RMS residual is {:.1} % of the straight line's ({:.4} mV against {:.4} mV).",
            b.rms_residual / ls.rms_residual * 100.0,
            b.rms_residual * 1e3,
            ls.rms_residual * 1e3
        );
    } else if a.best_model == Some(Model::Linear) {
        out.push_str(
            "No higher-order term is significant: the linear model is adequate for this data.",
        );
    }
    out
}
