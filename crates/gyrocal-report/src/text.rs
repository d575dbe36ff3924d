//! The terminal's text of an analysis: what `gyrocal fit` prints of a fit, and `gyrocal run`
//! at the end of a sweep. Rendering, like the pages: the numbers are the analysis's.

use std::fmt::Write as _;

use gyrocal_fit::{Analysis, Fit, Method, Model, NeuronStatus, ResidualDetail, TrainingData};

fn pm(v: Option<f64>, se: Option<f64>, digits: usize) -> String {
    match (v, se) {
        (Some(v), Some(se)) => format!("{v:.digits$} ± {se:.1e}"),
        (Some(v), None) => format!("{v:.digits$}"),
        _ => "-".to_string(),
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
    let _ = writeln!(out, "fits (K [V/(°/s)], K0 [V]; ± one standard error)");
    for f in &a.fits {
        let c = &f.coefficients;
        let s = &f.std_errors;
        let mut line = format!("  {:<24}", fit_label(f));
        match f.model {
            Model::Split => {
                let _ = write!(
                    line,
                    " K+ = {}  K- = {}  K0 = {}",
                    pm(c.k_pos, s.k_pos, 7),
                    pm(c.k_neg, s.k_neg, 7),
                    pm(c.k0, s.k0, 6)
                );
            }
            _ => {
                let _ = write!(
                    line,
                    " K = {}  K0 = {}",
                    pm(c.k1, s.k1, 7),
                    pm(c.k0, s.k0, 6)
                );
                if c.k2.is_some() {
                    let _ = write!(line, "  K2 = {}", pm(c.k2, s.k2, 9));
                }
                if c.k3.is_some() {
                    let _ = write!(line, "  K3 = {}", pm(c.k3, s.k3, 11));
                }
            }
        }
        let _ = writeln!(out, "{line}");
        let _ = writeln!(
            out,
            "  {:<24} SSE {:.4e} V²  RMS {:.4} mV  max|r| {:.4} mV  R² {:.10}",
            "",
            f.sse,
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
            "the neuron reaches the least-squares line (SSE equal within 1e-9 relative): \
             it is the same estimate, not a better one"
                .to_string()
        } else if rel > 0.0 {
            format!(
                "the neuron's SSE is larger by {:.3e} relative: least squares fits better",
                rel
            )
        } else {
            "the neuron's SSE is below least squares only by rounding: the same estimate"
                .to_string()
        };
        let dk = (nn.scale_factor - ls.scale_factor) / ls.scale_factor;
        let _ = writeln!(
            out,
            "neuron vs least squares (linear): {verdict}; ΔK/K = {dk:.2e}"
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
    let _ = writeln!(out, "metrics (least squares)");
    let _ = writeln!(out, "  scale factor K        {:.7} V/(°/s)", m.scale_factor);
    let _ = writeln!(
        out,
        "  bias K0               {:.6} V = {:.4} °/s = {:.1} °/h",
        m.bias_volts, m.bias_dps, m.bias_dph
    );
    let _ = writeln!(
        out,
        "  nonlinearity          {:.1} ppm of F_m = {:.4} V (max |line − F_j| / max |F_j|)",
        m.nonlinearity_ppm, m.full_scale_output
    );
    match (
        m.asymmetry_ppm,
        m.scale_factor_positive,
        m.scale_factor_negative,
    ) {
        (Some(asym), Some(kp), Some(kn)) => {
            let _ = writeln!(
                out,
                "  asymmetry             {asym:.1} ppm (K+ = {kp:.7}, K- = {kn:.7} V/(°/s))"
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
            "  asymmetry, common K2  {:.1} ± {:.1} ppm (1σ; one fit K0 + K+·ω⁺ + K−·ω⁻ + K2·ω², K2 = {:.3e} V/(°/s)²: not biased by the even-order term as the line pair above is){}",
            c.asymmetry_ppm,
            c.asymmetry_std_error_ppm,
            c.k2,
            crate::certificate::few_dof(c.degrees_of_freedom)
        );
    }
    if let Some(r) = m.repeatability_ppm {
        let _ = writeln!(out, "  repeatability         {r:.1} ppm");
    }
    let _ = writeln!(out);
    if let Some(u) = &a.uncertainty {
        let _ = writeln!(
            out,
            "expanded uncertainty (k = {}; budget in fit.json and the report)",
            u.coverage_factor
        );
        for q in &u.quantities {
            let _ = writeln!(
                out,
                "  {:<20}  {:.7e} ± {:.2e} {}{}",
                q.quantity,
                q.value,
                q.expanded_uncertainty,
                q.unit,
                q.relative_expanded_ppm
                    .map_or_else(String::new, |r| format!(" ({r:.1} ppm)"))
            );
        }
        let _ = writeln!(out);
    }
    if let Some(acc) = &a.acceptance {
        let _ = writeln!(out, "{}", verdict_line(acc));
        for c in &acc.checks {
            let _ = writeln!(
                out,
                "  {:<18} {:<13} {}{}",
                c.quantity.name(),
                c.verdict.label(),
                c.value
                    .map_or_else(|| "not measured".into(), |v| format!("{v:.7e} {}", c.unit)),
                c.reason
                    .as_deref()
                    .map_or_else(String::new, |r| format!(": {r}"))
            );
        }
        let _ = writeln!(out);
    }
}

/// "verdict: FAIL (simple rule): nonlinearity_ppm" — the run's verdict and the quantities
/// that make it.
pub fn verdict_line(acc: &gyrocal_fit::acceptance::Acceptance) -> String {
    let deciding: Vec<&str> = acc.deciding().map(|c| c.quantity.name()).collect();
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
