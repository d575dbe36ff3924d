//! The neuron's training curve and the error surface over (scale factor, bias) of one run.

use std::fmt::Write as _;

use gyrocal_fit::{Analysis, Method, Model};

use super::summary::ls_linear;
use super::{Doc, file_name, suffix};
use crate::{ReportError, plots};

/// Side of the error-surface grid the report draws.
const SURFACE_GRID: usize = 81;

pub(super) fn training_and_surface(
    doc: &mut Doc,
    a: &Analysis,
    run: Option<usize>,
) -> Result<(), ReportError> {
    let sfx = suffix(run);
    let ls = ls_linear(a);
    let nn = a.fit(Method::Neuron, Model::Linear);
    let _ = writeln!(doc.html, "<h2 id=\"training{sfx}\">Neuron training</h2>");
    match nn {
        Some(f) if f.neuron.as_ref().is_some_and(|t| !t.pass_errors.is_empty()) => {
            let (eta, alpha) = f.neuron.as_ref().map_or((0.0, 0.0), |t| (t.eta, t.alpha));
            doc.figure(
                file_name("training.svg", run),
                plots::training_plot(f, ls.map(|l| l.sse))?,
                &format!(
                    "Sum of squared residuals after each training pass (log scale): online passes with the paper's momentum rule (η = {eta}, α = {alpha}, step decaying over the passes), then full-batch passes. The dashed line is the least-squares SSE, the lowest a straight line can reach."
                ),
            );
        }
        _ => doc
            .html
            .push_str("<p class=\"note\">No neuron training trace in this fit.</p>\n"),
    }
    let _ = writeln!(doc.html, "<h2 id=\"surface{sfx}\">Error surface</h2>");
    // Drawn on a finer grid than fit.json's (81 × 81 instead of its 41 × 41, for smoother level
    // boundaries) over the same window; without a surface in the fit, over gyrocal-fit's default
    // window. The points are the fit's own (rate, measured output) pairs.
    let surface = ls.map(|l| {
        let data = gyrocal_fit::Dataset {
            source: None,
            points: l
                .residuals
                .iter()
                .map(|r| gyrocal_fit::Point::new(r.rate_dps, r.volts))
                .collect(),
        };
        match &a.error_surface {
            Some(s) if s.weights.len() >= 2 && s.thresholds.len() >= 2 => {
                let half = |v: &[f64]| (v[v.len() - 1] - v[0]) / 2.0;
                gyrocal_fit::ErrorSurface::grid(
                    &data,
                    s.center_weight,
                    s.center_threshold,
                    half(&s.weights),
                    half(&s.thresholds),
                    SURFACE_GRID,
                )
            }
            _ => gyrocal_fit::ErrorSurface::around(
                &data,
                a.metrics.scale_factor,
                a.metrics.bias_volts,
                SURFACE_GRID,
            ),
        }
    });
    match (surface, ls) {
        (Some(s), Some(l)) => {
            let neuron = nn.map(|f| (f.scale_factor, f.bias));
            let distance = neuron.map_or_else(String::new, |(k, k0)| {
                format!(
                    " The neuron's result differs from the least-squares optimum by ΔK = {} V/(°/s) and ΔK0 = {} V.",
                    gyrocal_fit::display::significant(k - l.scale_factor, 3),
                    gyrocal_fit::display::significant(k0 - l.bias, 3)
                )
            });
            doc.figure(
                file_name("surface.svg", run),
                plots::surface_plot(&s, (l.scale_factor, l.bias), neuron)?,
                &format!(
                    "Unweighted sum of squared residuals of the line D = K·ω + K0 on a grid around the least-squares optimum (filled levels, evenly spaced in √SSE). The cross is the least-squares optimum, the circle the neuron's result.{distance}"
                ),
            );
        }
        _ => doc
            .html
            .push_str("<p class=\"note\">No least-squares line: no error surface.</p>\n"),
    }
    Ok(())
}
