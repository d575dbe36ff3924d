//! A gyro's history as one self-contained HTML page: the calibrations with their results and
//! uncertainties, the day-to-day repeatability, and a trend plot (SVG, plotters) per quantity
//! with its acceptance limits and control band.
//!
//! The catalog stores and queries ([`gyrocal_catalog::Catalog::history`] computes the
//! repeatability, trends and control bands into a typed [`History`]); this module only renders
//! it, on the shared [`crate::page`] skeleton, stylesheet and escaper (`gyrocal history -o`).

use gyrocal_files::num::{significant, value_and_u};
use std::fmt::Write as _;

use plotters::prelude::*;

use gyrocal_catalog::{History, Trend};

use crate::page::{Page, esc};

const WIDTH: u32 = 860;
const HEIGHT: u32 = 320;
const FONT: &str = "sans-serif";

fn num(v: Option<f64>) -> String {
    v.map_or_else(|| "—".to_string(), |x| significant(x, 7))
}

/// A value ± its expanded uncertainty, rounded as on the certificate.
fn with_u(v: Option<f64>, u: Option<f64>) -> String {
    match (v, u) {
        (Some(v), Some(u)) => {
            let (v, u) = value_and_u(v, Some(u));
            format!("{v} ± {u}")
        }
        (v, _) => num(v),
    }
}

/// The history page of `h` (`gyrocal history SERIAL -o FILE.html`).
pub fn render(h: &History) -> String {
    let mut out = String::new();
    let title = format!("Calibration history of gyro {}", h.serial);
    Page::new(&title, &title)
        .with_sub(format!(
            "{} complete calibration(s){}.",
            h.calibrations.len(),
            if h.include_simulated {
                ", simulated runs included"
            } else {
                "; simulated runs excluded"
            }
        ))
        .open(&mut out);
    for w in &h.warnings {
        let _ = write!(out, "<p class=\"warn\">Warning: {}</p>", esc(w));
    }
    let sweeps: Vec<_> = h
        .calibrations
        .iter()
        .filter(|c| c.run.kind != "drift")
        .collect();
    let drifts: Vec<_> = h
        .calibrations
        .iter()
        .filter(|c| c.run.kind == "drift")
        .collect();
    if !sweeps.is_empty() {
        let r = &h.repeatability;
        let _ = write!(
            out,
            "<h2>Repeatability from calibration to calibration</h2><ul>\
             <li>scale factor: mean {} V/(°/s), {} ppm (std/mean over {} calibrations)</li>\
             <li>bias: mean {} °/h, std {} °/h</li></ul>",
            num(r.scale_factor_mean),
            r.scale_factor_ppm
                .map_or("—".to_string(), |v| format!("{v:.2}")),
            r.n,
            num(r.bias_dph_mean),
            num(r.bias_dph),
        );
        out.push_str(
            "<h2>Calibrations</h2><table class=\"history\"><tr><th>started (UTC)</th><th>run</th><th>station</th>\
             <th>plan</th><th>K ± U (V/(°/s))</th><th>bias ± U (°/h)</th><th>nonlinearity (ppm)</th>\
             <th>asymmetry (ppm)</th><th>verdict</th><th>sim.</th></tr>",
        );
        for c in &sweeps {
            let res = c.results.clone().unwrap_or_default();
            let _ = write!(
                out,
                "<tr><td>{}</td><td title=\"{}\">{}</td><td>{}</td>\
                 <td>{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td>{}</td><td>{}</td></tr>",
                esc(&c.run.started_utc),
                esc(&c.run.directory),
                esc(&c.run.id.chars().take(12).collect::<String>()),
                esc(c.run.station_id.as_deref().unwrap_or("")),
                esc(&c.run.plan_name),
                with_u(res.scale_factor, res.u_scale_factor),
                with_u(res.bias_dph, res.u_bias_dph),
                num(res.nonlinearity_ppm),
                num(res.asymmetry_ppm),
                esc(c.run.verdict.as_deref().unwrap_or("")),
                if c.run.simulated { "yes" } else { "" },
            );
        }
        out.push_str("</table>");
    }
    if !drifts.is_empty() {
        out.push_str(
            "<h2>Drift tests</h2><table class=\"history\"><tr><th>started (UTC)</th><th>run</th><th>station</th>\
             <th>plan</th><th>N ± U (°/√h)</th><th>B ± U (°/h)</th><th>K ± U (°/h/√h)</th>\
             <th>bias ± U (°/h)</th><th>record (h)</th><th>sim.</th></tr>",
        );
        for c in &drifts {
            let res = c.results.clone().unwrap_or_default();
            let _ = write!(
                out,
                "<tr><td>{}</td><td title=\"{}\">{}</td><td>{}</td>\
                 <td>{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td>{}</td></tr>",
                esc(&c.run.started_utc),
                esc(&c.run.directory),
                esc(&c.run.id.chars().take(12).collect::<String>()),
                esc(c.run.station_id.as_deref().unwrap_or("")),
                esc(&c.run.plan_name),
                with_u(res.arw_deg_rt_h, res.u_arw_deg_rt_h),
                with_u(res.bias_instability_dph, res.u_bias_instability_dph),
                with_u(res.rrw_dph_rt_h, res.u_rrw_dph_rt_h),
                with_u(res.drift_bias_dph, res.u_drift_bias_dph),
                num(res.drift_duration_s.map(|s| s / 3600.0)),
                if c.run.simulated { "yes" } else { "" },
            );
        }
        out.push_str("</table>");
    }
    out.push_str("<h2>Trends</h2>");
    for t in &h.trends {
        let _ = write!(out, "<h3>{} ({})</h3>", esc(&t.label), esc(&t.unit));
        match trend_svg(t) {
            Ok(svg) => out.push_str(&svg),
            Err(e) => {
                let _ = write!(out, "<p>(no plot: {})</p>", esc(&e));
            }
        }
        if let Some(b) = &t.band {
            let _ = write!(
                out,
                "<p>Control band (mean ± 3σ of the {} earlier calibrations): {} .. {}{}</p>",
                b.n,
                significant(b.low, 7),
                significant(b.high, 7),
                if t.latest_outside_band {
                    " <span class=\"warn\">the latest is outside</span>"
                } else {
                    ""
                }
            );
        }
    }
    Page::close(&mut out, None);
    out
}

fn trend_svg(t: &Trend) -> Result<String, String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (WIDTH, HEIGHT)).into_drawing_area();
        draw(&root, t).map_err(|e| e.to_string())?;
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(svg)
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    t: &Trend,
) -> Result<(), Box<dyn std::error::Error + 'static>>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let n = t.points.len();
    let mut ys: Vec<f64> = Vec::new();
    for p in &t.points {
        let u = p.expanded_uncertainty.unwrap_or(0.0);
        ys.push(p.value - u);
        ys.push(p.value + u);
    }
    if let Some(b) = &t.band {
        ys.push(b.low);
        ys.push(b.high);
    }
    if let Some(l) = &t.limits {
        ys.extend(l.min);
        ys.extend(l.max);
    }
    let ys: Vec<f64> = ys.into_iter().filter(|v| v.is_finite()).collect();
    let lo = ys.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = ys.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let pad = if hi > lo {
        (hi - lo) * 0.08
    } else {
        lo.abs().max(1e-12) * 1e-3
    };
    let (y0, y1) = (lo - pad, hi + pad);
    let x1 = n as f64 - 0.5;
    let dates: Vec<String> = t
        .points
        .iter()
        .map(|p| p.started_utc.chars().take(10).collect())
        .collect();
    let mut chart = ChartBuilder::on(root)
        .margin(10)
        .x_label_area_size(36)
        .y_label_area_size(90)
        .build_cartesian_2d(-0.5..x1, y0..y1)?;
    chart
        .configure_mesh()
        .x_desc("calibration")
        .y_desc(format!("{} ({})", t.label, t.unit))
        .x_labels(n.min(10))
        .x_label_formatter(&|x| {
            let i = x.round();
            if (x - i).abs() < 1e-6 && i >= 0.0 {
                dates.get(i as usize).cloned().unwrap_or_default()
            } else {
                String::new()
            }
        })
        .y_label_formatter(&|y| format!("{y:.4e}"))
        .label_style((FONT, 12))
        .draw()?;
    if let Some(b) = &t.band {
        chart.draw_series(std::iter::once(Rectangle::new(
            [(-0.5, b.low), (x1, b.high)],
            RGBColor(120, 170, 230).mix(0.25).filled(),
        )))?;
        chart.draw_series(LineSeries::new(
            vec![(-0.5, b.mean), (x1, b.mean)],
            RGBColor(60, 110, 200).stroke_width(1),
        ))?;
    }
    if let Some(l) = &t.limits {
        for v in [l.min, l.max].into_iter().flatten() {
            chart.draw_series(DashedLineSeries::new(
                vec![(-0.5, v), (x1, v)],
                6,
                4,
                RED.stroke_width(2),
            ))?;
        }
    }
    chart.draw_series(t.points.iter().enumerate().filter_map(|(i, p)| {
        let u = p.expanded_uncertainty?;
        Some(ErrorBar::new_vertical(
            i as f64,
            p.value - u,
            p.value,
            p.value + u,
            BLACK.stroke_width(1),
            6,
        ))
    }))?;
    chart.draw_series(LineSeries::new(
        t.points
            .iter()
            .enumerate()
            .map(|(i, p)| (i as f64, p.value)),
        BLACK.mix(0.4).stroke_width(1),
    ))?;
    chart.draw_series(t.points.iter().enumerate().map(|(i, p)| {
        let outside = i + 1 == n && t.latest_outside_band;
        let color = if outside { RED } else { BLACK };
        Circle::new((i as f64, p.value), 4, color.filled())
    }))?;
    Ok(())
}
