//! The terminal's text of an analysis: what `gyrocal fit` prints of a fit, and `gyrocal run`
//! at the end of a sweep. Rendering, like the pages: the numbers are the analysis's.

use std::fmt::Write as _;

use gyrocal_fit::display::{
    metric_words, quantity_words, significant, value_as_with_u, value_pm_u,
};
use gyrocal_fit::{Analysis, Fit, Method, Model, NeuronStatus, ResidualDetail, TrainingData};

/// A coefficient ± its standard error, in the one rule of every `±` ([`value_pm_u`]); the
/// units are in the heading.
fn pm(v: Option<f64>, se: Option<f64>) -> String {
    match v {
        Some(v) => value_pm_u(v, se, ""),
        None => "-".to_string(),
    }
}

fn fit_label(f: &Fit) -> String {
    format!("{} {}", f.method, f.model)
}

/// Appends the human-readable summary and per-rate table of `a` to `out` (what `gyrocal fit`
/// prints, and `gyrocal run` at the end of a sweep).
pub fn fit_summary(out: &mut String, a: &Analysis) {
    let source = a.source.as_deref().unwrap_or("<data>");
    let weighted = a.fits.first().is_some_and(|f| f.weighted);
    let _ = writeln!(
        out,
        "== {source}: {} points, {}",
        a.points,
        if weighted {
            "weighted by 1/σ² (σ = volts_std/√n)"
        } else {
            "unweighted"
        }
    );
    let _ = writeln!(out);
    for s in &a.skipped {
        let _ = writeln!(out, "not fitted: {} — {}", s.model, s.reason);
    }
    if !a.skipped.is_empty() {
        let _ = writeln!(out);
    }
    let _ = writeln!(
        out,
        "fits (K, K+, K− in V/(°/s); K0 in V; K2 in V/(°/s)²; K3 in V/(°/s)³; ± one standard error)"
    );
    for f in &a.fits {
        let c = &f.coefficients;
        let s = &f.std_errors;
        let mut line = format!("  {:<24}", fit_label(f));
        match f.model {
            Model::Split => {
                let _ = write!(
                    line,
                    " K+ = {}  K− = {}  K0 = {}",
                    pm(c.k_pos, s.k_pos),
                    pm(c.k_neg, s.k_neg),
                    pm(c.k0, s.k0)
                );
            }
            _ => {
                let _ = write!(line, " K = {}  K0 = {}", pm(c.k1, s.k1), pm(c.k0, s.k0));
                if c.k2.is_some() {
                    let _ = write!(line, "  K2 = {}", pm(c.k2, s.k2));
                }
                if c.k3.is_some() {
                    let _ = write!(line, "  K3 = {}", pm(c.k3, s.k3));
                }
            }
        }
        let _ = writeln!(out, "{line}");
        let _ = writeln!(
            out,
            "  {:<24} SSE {} V²  RMS {:.4} mV  max|r| {:.4} mV  R² {:.10}",
            "",
            significant(f.sse, 5),
            f.rms_residual * 1e3,
            f.max_abs_residual * 1e3,
            f.r_squared
        );
        if let Some(t) = &f.neuron {
            let status = match t.status {
                NeuronStatus::Converged => format!(
                    "converged after {} passes ({} online with momentum, {} full-batch)",
                    t.online_passes + t.batch_passes,
                    t.online_passes,
                    t.batch_passes
                ),
                NeuronStatus::MaxPasses => format!(
                    "NOT CONVERGED: stopped at the limit of {} passes",
                    t.online_passes + t.batch_passes
                ),
                NeuronStatus::Diverged { pass } => format!(
                    "DIVERGED at pass {pass} (η = {}): the result is the last finite weights, not a fit",
                    t.eta
                ),
            };
            let _ = writeln!(out, "  {:<24} {status}", "");
            // online passes on summaries of a large data set: say which, and over how many
            let online = match t.training_data {
                TrainingData::RateBins { bins, points } => {
                    Some((format!("{bins} rate bins (continuous rates, above"), points))
                }
                TrainingData::RateMeans { rates, points } => {
                    Some((format!("the {rates} rates (above"), points))
                }
                _ => None,
            };
            if let Some((means_of, points)) = online {
                let limit = t
                    .online_pass_limit
                    .map(|l| format!(", online passes limited to {l}"))
                    .unwrap_or_default();
                let _ = writeln!(
                    out,
                    "  {:<24} online passes on the means of {means_of} {} points), batch passes and errors over all {points} points{limit}",
                    "",
                    gyrocal_fit::neuron::RATE_MEANS_ABOVE_POINTS
                );
            }
        }
    }
    let _ = writeln!(out);

    let ls = a.fit(Method::LeastSquares, Model::Linear);
    let nn = a.fit(Method::Neuron, Model::Linear);
    if let (Some(ls), Some(nn)) = (ls, nn) {
        let rel = if ls.sse > 0.0 {
            (nn.sse - ls.sse) / ls.sse
        } else {
            nn.sse - ls.sse
        };
        let verdict = if !nn.converged {
            format!(
                "the neuron did not converge; its SSE is {:.3}× that of least squares",
                nn.sse / ls.sse.max(f64::MIN_POSITIVE)
            )
        } else if rel.abs() <= 1e-9 {
            "the neuron reaches the least-squares line (SSE equal within 10⁻⁹ relative): \
             it is the same estimate, not a better one"
                .to_string()
        } else if rel > 0.0 {
            format!(
                "the neuron's SSE is larger by {} relative: least squares fits better",
                significant(rel, 4)
            )
        } else {
            "the neuron's SSE is below least squares only by rounding: the same estimate"
                .to_string()
        };
        let dk = (nn.scale_factor - ls.scale_factor) / ls.scale_factor;
        let _ = writeln!(
            out,
            "neuron vs least squares (linear): {verdict}; ΔK/K = {}",
            significant(dk, 3)
        );
        let _ = writeln!(out);
    }
    if let Some(best) = a.best_model {
        let why = match &a.model_selection {
            Some(sel) => {
                let tests: Vec<String> = sel
                    .tests
                    .iter()
                    .map(|t| format!("{t}{}", if t.significant { " significant" } else { "" }))
                    .collect();
                format!(
                    "the simplest model whose added terms are significant, {} at level {}: {}",
                    sel.method,
                    sel.level,
                    tests.join("; ")
                )
            }
            None => "chosen by an earlier gyrocal (smallest residual standard error)".to_string(),
        };
        let _ = writeln!(out, "best model: {best} ({why})");
        if let (Some(lin), Some(b)) = (ls, a.fit(Method::LeastSquares, best))
            && best != Model::Linear
            && b.sse > 0.0
        {
            let _ = writeln!(
                out,
                "  it reduces the SSE of the line {:.1}-fold",
                lin.sse / b.sse
            );
        }
        let _ = writeln!(out);
    }

    // Per-rate table in the paper's layout.
    let best_fit = a.best_model.and_then(|m| a.fit(Method::LeastSquares, m));
    let mut header = format!("{:>10} {:>14}", "rate [°/s]", "measured [V]");
    if ls.is_some() {
        let _ = write!(header, " {:>17}", "LS resid. [mV]");
    }
    if nn.is_some() {
        let _ = write!(header, " {:>17}", "neuron resid. [mV]");
    }
    if let Some(b) = best_fit {
        let _ = write!(header, " {:>17}", format!("{} resid. [mV]", b.model));
    }
    let per_rate = a.fits.first().is_some_and(|f| !f.rate_residuals.is_empty());
    if per_rate {
        // One row per distinct rate (per rate bin on continuous data): the mean output and
        // the mean residuals.
        if let (ResidualDetail::PerRateBin, Some(b)) = (a.residual_detail, &a.rate_bins) {
            let _ = writeln!(
                out,
                "continuous rates ({} distinct, more than {}): one row per rate bin, {} bins of {:.4} °/s over [{}, {}] °/s (empty bins left out); the rate is the mean rate of the bin's points, the figures above are over every point",
                a.distinct_rates
                    .map_or_else(|| "?".to_string(), |d| d.to_string()),
                gyrocal_fit::RATE_GROUPS_MAX,
                b.bins,
                b.width_dps,
                b.lo_dps,
                b.hi_dps
            );
        }
        let mut header = format!("{:>10} {:>9} {:>14}", "rate [°/s]", "n", "mean [V]");
        if ls.is_some() {
            let _ = write!(header, " {:>17}", "LS mean r. [mV]");
        }
        if nn.is_some() {
            let _ = write!(header, " {:>17}", "neuron mean r. [mV]");
        }
        if let Some(b) = best_fit {
            let _ = write!(header, " {:>17}", format!("{} mean r. [mV]", b.model));
        }
        let _ = writeln!(out, "{header}");
        let Some(base) = a.fits.first() else {
            return;
        };
        for (i, r) in base.rate_residuals.iter().enumerate() {
            // A schedule's rates as written; a bin's mean rate to 0.1 m°/s.
            let rate = if r.rate_min_dps.is_some() {
                format!("{:.4}", r.rate_dps)
            } else {
                r.rate_dps.to_string()
            };
            let mut row = format!("{rate:>10} {:>9} {:>14.7}", r.n, r.mean_volts);
            for f in [ls, nn, best_fit].into_iter().flatten() {
                if let Some(fr) = f.rate_residuals.get(i) {
                    let _ = write!(row, " {:>+17.4}", fr.mean_residual * 1e3);
                }
            }
            let _ = writeln!(out, "{row}");
        }
    } else {
        let _ = writeln!(out, "{header}");
    }
    for i in 0..a.points {
        let Some(r) = a.fits.first().and_then(|f| f.residuals.get(i)) else {
            break;
        };
        let mut row = format!("{:>10} {:>14.7}", r.rate_dps, r.volts);
        for f in [ls, nn, best_fit].into_iter().flatten() {
            let _ = write!(row, " {:>+17.4}", f.residuals[i].residual * 1e3);
        }
        let _ = writeln!(out, "{row}");
    }
    let _ = writeln!(out);

    let m = &a.metrics;
    let unc = a.uncertainty.as_ref();
    // Each figure rounded as it is beside its U below (and on the certificate): the same
    // quantity with the same decimals wherever it is read.
    let like = |key: &str, v: f64| value_as_with_u(v, unc.and_then(|u| u.expanded(key)));
    let _ = writeln!(out, "metrics (least squares)");
    let _ = writeln!(
        out,
        "  scale factor K        {} V/(°/s)",
        like("scale_factor", m.scale_factor)
    );
    let _ = writeln!(
        out,
        "  bias K0               {} V = {:.4} °/s = {} °/h",
        like("bias_v", m.bias_volts),
        m.bias_dps,
        like("bias_dph", m.bias_dph)
    );
    let _ = writeln!(
        out,
        "  nonlinearity          {} ppm of F_m = {:.4} V (max |line − F_j| / max |F_j|)",
        like("nonlinearity_ppm", m.nonlinearity_ppm),
        m.full_scale_output
    );
    match (
        m.asymmetry_ppm,
        m.scale_factor_positive,
        m.scale_factor_negative,
    ) {
        (Some(asym), Some(kp), Some(kn)) => {
            let _ = writeln!(
                out,
                "  asymmetry             {} ppm (GJB two lines; K+ = {}, K− = {} V/(°/s))",
                like("asymmetry_ppm", asym),
                like("k_pos", kp),
                like("k_neg", kn)
            );
        }
        _ => {
            let reason = m
                .not_computed
                .iter()
                .find(|n| n.metric == "asymmetry_ppm")
                .map_or("needs both turning directions", |n| n.reason.as_str());
            let _ = writeln!(out, "  asymmetry             not computed: {reason}");
        }
    }
    if let Some(c) = &m.asymmetry_common_k2 {
        let _ = writeln!(
            out,
            "  asymmetry, common K2  {} (U, k = 2; one fit K0 + K+·ω⁺ + K−·ω⁻ + K2·ω², K2 = {} V/(°/s)²: not biased by the even-order term as the line pair above is){}",
            value_pm_u(
                c.asymmetry_ppm,
                unc.and_then(|u| u.expanded("asymmetry_common_k2"))
                    .or(Some(2.0 * c.asymmetry_std_error_ppm)),
                "ppm"
            ),
            significant(c.k2, 4),
            crate::certificate::few_dof(c.degrees_of_freedom)
        );
    }
    if let Some(r) = m.repeatability_ppm {
        let _ = writeln!(
            out,
            "  repeatability         {} ppm",
            like("repeatability_ppm", r)
        );
    }
    let _ = writeln!(out);
    if let Some(u) = unc {
        let _ = writeln!(
            out,
            "expanded uncertainty (k = {}; budget in fit.json and the report)",
            u.coverage_factor
        );
        let mut rows: Vec<(String, String)> = u
            .quantities
            .iter()
            .map(|q| {
                (
                    quantity_words(&q.quantity).0,
                    format!(
                        "{}{}",
                        value_pm_u(q.value, Some(q.expanded_uncertainty), &q.unit),
                        q.relative_expanded_ppm
                            .map_or_else(String::new, |r| format!(" ({} ppm)", significant(r, 3)))
                    ),
                )
            })
            .collect();
        rows.extend(u.metrics.entries.iter().map(|e| {
            let text = match e.interval {
                Some([lo, hi]) => format!(
                    "{} {} (95 % interval {} .. {})",
                    value_as_with_u(e.value, Some(e.expanded_uncertainty)),
                    e.unit,
                    significant(lo, 3),
                    significant(hi, 3)
                ),
                None => value_pm_u(e.value, Some(e.expanded_uncertainty), &e.unit),
            };
            (metric_words(&e.metric).0, text)
        }));
        let width = rows
            .iter()
            .map(|(n, _)| n.chars().count())
            .max()
            .unwrap_or(0);
        for (name, text) in rows {
            let _ = writeln!(out, "  {name:<width$}  {text}");
        }
        let _ = writeln!(out);
    }
    if let Some(acc) = &a.acceptance {
        let _ = writeln!(out, "{}", verdict_line(acc));
        let width = acc
            .checks
            .iter()
            .map(|c| c.quantity.title().chars().count())
            .max()
            .unwrap_or(0);
        for c in &acc.checks {
            let _ = writeln!(
                out,
                "  {:<width$}  {:<13} {}",
                c.quantity.title(),
                c.verdict.label(),
                check_text(c)
            );
        }
        let _ = writeln!(out);
    }
}

/// What a check's line says after its verdict: the reason when there is one (it begins with
/// the value ± U, or says why there is no value), else the value ± U.
pub fn check_text(c: &gyrocal_fit::acceptance::Check) -> String {
    if let Some(r) = &c.reason {
        return r.clone();
    }
    match (c.value, c.interval) {
        (Some(v), Some([lo, hi])) => format!(
            "{} {} (95 % interval {} .. {})",
            value_as_with_u(v, c.expanded_uncertainty),
            c.unit,
            significant(lo, 3),
            significant(hi, 3)
        ),
        (Some(v), None) => value_pm_u(v, c.expanded_uncertainty, &c.unit),
        (None, _) => "not measured".to_string(),
    }
}

/// "verdict: FAIL (simple rule): nonlinearity" — the run's verdict and the quantities that
/// make it, in words.
pub fn verdict_line(acc: &gyrocal_fit::acceptance::Acceptance) -> String {
    let deciding: Vec<String> = acc.deciding().map(|c| c.quantity.title()).collect();
    format!(
        "verdict: {} ({} rule){}",
        acc.verdict.label(),
        acc.rule.as_str(),
        if deciding.is_empty() {
            String::new()
        } else {
            format!(": {}", deciding.join(", "))
        }
    )
}
