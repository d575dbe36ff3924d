//! A gyro's history as one self-contained HTML page: the calibrations with their results and
//! uncertainties, the day-to-day repeatability, and a trend plot (SVG, plotters) per quantity
//! with its acceptance limits and control band. A temperature series has its own table (the
//! sensitivities of K and of the bias with their U, the range, the hysteresis) and, per
//! series, its temperatures; its sensitivities' trends are plotted with the others.
//!
//! The catalog stores and queries ([`gyrocal_catalog::Catalog::history`] computes the
//! repeatability, trends and control bands into a typed [`History`]); this module only renders
//! it, on the shared [`crate::page`] skeleton, stylesheet and escaper (`gyrocal history -o`).

use gyrocal_files::num::significant;
use std::fmt::Write as _;

use plotters::prelude::*;

use gyrocal_catalog::{History, Limits, MIN_BAND_POINTS, Trend, describe_plan};

use crate::page::{Page, esc};
use crate::plots::axis::LinearAxis;
use crate::plots::legend::{Legend, Placement, Swatch, diamond, norm_lin};

const WIDTH: u32 = 860;
const HEIGHT: u32 = 320;
const FONT: &str = "sans-serif";

/// `v` to 6 significant digits without trailing zeros (`0.3616`, not `3.6160e-1`).
fn short(v: f64) -> String {
    gyrocal_fit::display::trimmed(v, 6)
}

fn num(v: Option<f64>) -> String {
    v.map_or_else(|| "—".to_string(), |x| significant(x, 7))
}

/// A figure in ppm to 0.1 ppm, as the terminal's metrics print it: a column of nonlinearities
/// and asymmetries with the same decimals (never `931.3412` beside `2098.372`).
fn ppm(v: Option<f64>) -> String {
    v.map_or_else(|| "—".to_string(), |x| format!("{x:.1}"))
}

/// A value ± its expanded uncertainty, rounded as on the certificate.
fn with_u(v: Option<f64>, u: Option<f64>) -> String {
    match (v, u) {
        (Some(v), Some(u)) => gyrocal_fit::display::value_pm_u(v, Some(u), ""),
        (v, _) => num(v),
    }
}

/// A table cell for when a run started: `YYYY-MM-DD HH:MM` (UTC, the column says so), read
/// whole, with the full stamp as its title; a stamp that does not read is shown as it is.
fn when_cell(utc: &str) -> String {
    let short = gyrocal_files::parse_rfc3339_utc(utc)
        .and_then(|_| Some(format!("{} {}", utc.get(..10)?, utc.get(11..16)?)));
    format!(
        "<td class=\"when\" title=\"{}\">{}</td>",
        esc(utc),
        esc(short.as_deref().unwrap_or(utc))
    )
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
    // each calibration with its plan's name (and letter, with several plans)
    let named = |i: usize, c: &gyrocal_catalog::Calibration| -> String {
        match h.plan_of.get(i) {
            Some(p) if h.plans.len() > 1 => {
                format!("{} (plan {})", c.run.plan_name, plan_letter(*p))
            }
            _ => c.run.plan_name.clone(),
        }
    };
    let sweeps: Vec<_> = h
        .calibrations
        .iter()
        .enumerate()
        .filter(|(_, c)| c.run.kind != "drift" && !is_series(c))
        .map(|(i, c)| (c, named(i, c)))
        .collect();
    let drifts: Vec<_> = h
        .calibrations
        .iter()
        .enumerate()
        .filter(|(_, c)| c.run.kind == "drift")
        .map(|(i, c)| (c, named(i, c)))
        .collect();
    let several_plans = h.plans.len() > 1;
    if several_plans {
        out.push_str("<h2>Plans</h2><p class=\"note\">Calibrations are compared (repeatability, control bands) only with calibrations of the same plan: the same kind of test at the same demanded rates. A different simulation seed is the same plan.</p><ul>");
        for (i, p) in h.plans.iter().enumerate() {
            let _ = write!(
                out,
                "<li>plan {}: {}</li>",
                plan_letter(i),
                esc(&describe_plan(p))
            );
        }
        out.push_str("</ul>");
    }
    if !sweeps.is_empty() {
        let r = &h.repeatability;
        let of_plan = match (several_plans, r.plan) {
            (true, Some(p)) => format!(
                " of plan {} (the latest calibration's; {} calibration(s) of other plans left out)",
                plan_letter(p),
                r.other_plans
            ),
            _ => String::new(),
        };
        if r.n < 2 {
            // as `gyrocal history` says it: a spread needs two calibrations
            let _ = write!(
                out,
                "<h2>Repeatability from calibration to calibration</h2>\
                 <p class=\"note\">Needs two calibrations or more{of_plan} ({} so far).</p>",
                r.n
            );
        } else {
            let _ = write!(
                out,
                "<h2>Repeatability from calibration to calibration</h2><ul>\
                 <li>scale factor: mean {} V/(°/s), {} ppm (std/mean over {} calibrations{})</li>\
                 <li>bias: mean {} °/h, std {} °/h</li></ul>",
                num(r.scale_factor_mean),
                r.scale_factor_ppm
                    .map_or("—".to_string(), |v| format!("{v:.2}")),
                r.n,
                of_plan,
                num(r.bias_dph_mean),
                num(r.bias_dph),
            );
        }
        out.push_str(
            "<h2>Calibrations</h2><table class=\"history\"><tr><th>started (UTC)</th><th>run</th><th>station</th>\
             <th>plan</th><th>K ± U (V/(°/s))</th><th>bias ± U (°/h)</th><th>nonlinearity (ppm)</th>\
             <th>asymmetry (ppm)</th><th>verdict</th><th>sim.</th></tr>",
        );
        for (c, plan) in &sweeps {
            let res = c.results.clone().unwrap_or_default();
            let _ = write!(
                out,
                "<tr>{}<td title=\"{}\">{}</td><td>{}</td>\
                 <td class=\"plan\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td>{}</td><td>{}</td></tr>",
                when_cell(&c.run.started_utc),
                esc(&c.run.directory),
                esc(&c.run.id.chars().take(12).collect::<String>()),
                esc(c.run.station_id.as_deref().unwrap_or("")),
                esc(plan),
                with_u(res.scale_factor, res.u_scale_factor),
                with_u(res.bias_dph, res.u_bias_dph),
                ppm(res.nonlinearity_ppm),
                ppm(res.asymmetry_ppm),
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
        for (c, plan) in &drifts {
            let res = c.results.clone().unwrap_or_default();
            let _ = write!(
                out,
                "<tr>{}<td title=\"{}\">{}</td><td>{}</td>\
                 <td class=\"plan\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td>{}</td></tr>",
                when_cell(&c.run.started_utc),
                esc(&c.run.directory),
                esc(&c.run.id.chars().take(12).collect::<String>()),
                esc(c.run.station_id.as_deref().unwrap_or("")),
                esc(plan),
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
    let series: Vec<_> = h
        .calibrations
        .iter()
        .enumerate()
        .filter(|(_, c)| is_series(c))
        .map(|(i, c)| (c, named(i, c)))
        .collect();
    series_tables(&mut out, &series);
    out.push_str("<h2>Trends</h2>");
    for t in &h.trends {
        let _ = write!(out, "<h3>{} ({})</h3>", esc(&t.label), esc(&t.unit));
        match trend_svg(t) {
            Ok(svg) => out.push_str(&svg),
            Err(e) => {
                let _ = write!(out, "<p>(no plot: {})</p>", esc(&e));
            }
        }
        match &t.band {
            Some(b) => {
                let _ = write!(
                    out,
                    "<p>Control band (mean ± 3σ of the {} earlier calibrations{}): {} .. {} {}{}</p>",
                    b.n,
                    if several_plans { " of its plan" } else { "" },
                    short(b.low),
                    short(b.high),
                    esc(&t.unit),
                    if t.latest_outside_band {
                        " <span class=\"warn\">the latest is outside</span>"
                    } else {
                        ""
                    }
                );
            }
            None => {
                let _ = write!(
                    out,
                    "<p class=\"note\">No control band: {} earlier calibration(s){}, {} needed (with fewer, σ is too uncertain: mean ± 3σ of 2 earlier values flags about 1 in 4 calibrations of an unchanged gyro).</p>",
                    t.band_candidates,
                    if several_plans {
                        " of the latest one's plan"
                    } else {
                        ""
                    },
                    MIN_BAND_POINTS
                );
            }
        }
    }
    Page::close(&mut out, None);
    out
}

/// Whether `c` is a temperature series (its kind, or the series' figures the catalog holds).
fn is_series(c: &gyrocal_catalog::Calibration) -> bool {
    c.series.is_some() || c.run.kind == gyrocal_files::station::SERIES_KIND
}

/// The temperature series: one row each (sensitivities ± U, range, models, hysteresis), then
/// each series' temperatures.
fn series_tables(out: &mut String, series: &[(&gyrocal_catalog::Calibration, String)]) {
    if series.is_empty() {
        return;
    }
    out.push_str(
        "<h2>Temperature series</h2><p class=\"note\">Sensitivities over each series' range \
         (for a quadratic model, the slope at the range's mid-temperature), expanded \
         uncertainties at k = 2; hysteresis where a temperature was revisited.</p>\
         <table class=\"history\" id=\"series-table\"><tr><th>started (UTC)</th><th>run</th>\
         <th>station</th><th>plan</th><th>K sensitivity ± U (ppm/°C)</th>\
         <th>bias sensitivity ± U (°/h/°C)</th><th>range (°C)</th><th>model order K, bias</th>\
         <th>hysteresis K (ppm)</th><th>hysteresis bias (°/h)</th><th>sim.</th></tr>",
    );
    for (c, plan) in series {
        let s = c.series.as_ref();
        let f = |g: fn(&gyrocal_catalog::SeriesRecord) -> Option<f64>| s.and_then(g);
        let order = |o: Option<i64>| o.map_or("—".to_string(), |o| o.to_string());
        let _ = write!(
            out,
            "<tr>{}<td title=\"{}\">{}</td><td>{}</td><td class=\"plan\">{}</td>\
             <td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td>\
             <td>{}, {}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td>{}</td></tr>",
            when_cell(&c.run.started_utc),
            esc(&c.run.directory),
            esc(&c.run.id.chars().take(12).collect::<String>()),
            esc(c.run.station_id.as_deref().unwrap_or("")),
            esc(plan),
            with_u(f(|s| s.k_tempco_ppm_per_c), f(|s| s.u_k_tempco_ppm_per_c)),
            with_u(
                f(|s| s.bias_tempco_dph_per_c),
                f(|s| s.u_bias_tempco_dph_per_c)
            ),
            match (f(|s| s.t_min_c), f(|s| s.t_max_c)) {
                (Some(a), Some(b)) => format!("{a:.1} .. {b:.1}"),
                _ => "—".to_string(),
            },
            order(s.and_then(|s| s.k_model_order)),
            order(s.and_then(|s| s.bias_model_order)),
            ppm(f(|s| s.hysteresis_k_ppm)),
            num(f(|s| s.hysteresis_bias_dph)),
            if c.run.simulated { "yes" } else { "" },
        );
    }
    out.push_str("</table>");
    for (c, _) in series {
        let Some(s) = &c.series else { continue };
        let _ = write!(
            out,
            "<h3>Series of {}: each temperature</h3><table class=\"history\">\
             <tr><th>series_point</th><th>setpoint (°C)</th><th>gyro min / mean / max (°C)</th>\
             <th>K ± U (V/(°/s))</th><th>bias ± U (°/h)</th><th>nonlinearity (ppm)</th></tr>",
            esc(&c.run.started_utc)
        );
        for p in &s.points {
            let t = |v: Option<f64>| v.map_or("—".to_string(), |v| format!("{v:.2}"));
            let _ = write!(
                out,
                "<tr><td>{}</td><td class=\"num\">{}</td><td class=\"num\">{} / {} / {}</td>\
                 <td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td></tr>",
                p.series_point,
                short(p.setpoint_c),
                t(p.temp_min_c),
                t(p.temp_mean_c),
                t(p.temp_max_c),
                with_u(p.k, p.u_k),
                with_u(p.bias_dph, p.u_bias_dph),
                ppm(p.nonlinearity_ppm),
            );
        }
        out.push_str("</table>");
    }
}

/// A letter per plan (`A`, `B`, ...; `Z` and on past 26), as the page names them.
fn plan_letter(i: usize) -> String {
    char::from_u32(u32::from(b'A') + u32::try_from(i.min(25)).unwrap_or(25))
        .map_or_else(|| "?".to_string(), |c| c.to_string())
}

/// Where a point stands against the limits drawn on its plot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Standing {
    /// Within the marginal limits (or within the limits when there are no marginal ones).
    Inside,
    /// Between a marginal limit and its acceptance limit.
    Marginal,
    /// Beyond an acceptance limit.
    Outside,
}

fn standing(v: f64, l: Option<&Limits>) -> Standing {
    let Some(l) = l else {
        return Standing::Inside;
    };
    if l.min.is_some_and(|m| v < m) || l.max.is_some_and(|m| v > m) {
        Standing::Outside
    } else if l.marginal_min.is_some_and(|m| v < m) || l.marginal_max.is_some_and(|m| v > m) {
        Standing::Marginal
    } else {
        Standing::Inside
    }
}

const LIMIT_RED: RGBColor = RGBColor(200, 30, 45);
const MARGINAL_ORANGE: RGBColor = RGBColor(230, 130, 0);
const BAND_BLUE: RGBColor = RGBColor(60, 110, 200);
const OTHER_PLAN: RGBColor = RGBColor(150, 150, 150);

/// Width of a tick label of `chars` characters at the history's 12 px font, px (generous).
fn label_px(chars: usize) -> f64 {
    chars as f64 * 7.0
}

/// The labels under the points, `spacing` px apart: the date at the first calibration of a
/// day, the time (UTC) at the others of that day, so that a date is never repeated along the
/// axis; a label that would run into the one before it is left out (a date never is: the
/// time before it gives way).
fn x_labels(points: &[gyrocal_catalog::TrendPoint], spacing: f64) -> Vec<String> {
    let mut last_day = String::new();
    let full: Vec<(String, bool)> = points
        .iter()
        .map(|p| {
            let day: String = p.started_utc.chars().take(10).collect();
            if day == last_day {
                (p.started_utc.chars().skip(11).take(5).collect(), false)
            } else {
                last_day.clone_from(&day);
                (day, true)
            }
        })
        .collect();
    let mut out = vec![String::new(); full.len()];
    let mut last: Option<usize> = None;
    for (i, (label, is_date)) in full.iter().enumerate() {
        let fits = |j: usize, other: &str| {
            (i - j) as f64 * spacing
                >= (label_px(other.chars().count()) + label_px(label.chars().count())) / 2.0 + 6.0
        };
        match last {
            Some(j) if !fits(j, &out[j]) => {
                if *is_date && !full[j].1 {
                    // the date wins over the time before it
                    out[j].clear();
                    let before = out[..j].iter().rposition(|s| !s.is_empty());
                    if before.is_none_or(|k| fits(k, &out[k])) {
                        out[i].clone_from(label);
                        last = Some(i);
                    }
                }
            }
            _ => {
                out[i].clone_from(label);
                last = Some(i);
            }
        }
    }
    out
}

/// The y range of a trend: its values with their uncertainties and its band, padded; a limit
/// is taken in only when that keeps the data at least a third of the height (a limit far
/// from the data is named in the legend as above or below the plot instead, so the spread of
/// the calibrations stays visible).
fn y_range(t: &Trend) -> (f64, f64) {
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
    let ys: Vec<f64> = ys.into_iter().filter(|v| v.is_finite()).collect();
    let mut lo = ys.iter().copied().fold(f64::INFINITY, f64::min);
    let mut hi = ys.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !(lo.is_finite() && hi.is_finite()) {
        return (-1.0, 1.0);
    }
    let span = if hi > lo {
        hi - lo
    } else {
        lo.abs().max(1e-12) * 1e-3
    };
    if let Some(l) = &t.limits {
        for v in [l.min, l.max, l.marginal_min, l.marginal_max]
            .into_iter()
            .flatten()
            .filter(|v| v.is_finite())
        {
            let (nlo, nhi) = (lo.min(v), hi.max(v));
            if nhi - nlo <= 3.0 * span {
                (lo, hi) = (nlo, nhi);
            }
        }
    }
    let pad = (hi - lo).max(span) * 0.1;
    (lo - pad, hi + pad)
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
    let (y0, y1) = y_range(t);
    let ya = LinearAxis::new(y0, y1, 6);
    let (x0, x1) = (-0.5, n as f64 - 0.5);
    let limits = t.limits.as_ref();
    let in_view = |v: f64| v >= y0 && v <= y1;
    // the legend, with the entries of what is drawn
    let mut legend = Legend::new();
    let mut standings = [false; 3];
    let mut other_plan = false;
    for p in &t.points {
        if p.plan == t.plan {
            standings[standing(p.value, limits) as usize] = true;
        } else {
            other_plan = true;
        }
    }
    if standings[Standing::Inside as usize] {
        legend.add("calibration ± U (k = 2)", Swatch::Dot(BLACK));
    }
    if standings[Standing::Marginal as usize] {
        legend.add(
            "marginal (beyond a marginal limit)",
            Swatch::Diamond(MARGINAL_ORANGE),
        );
    }
    if standings[Standing::Outside as usize] {
        legend.add("outside the acceptance limits", Swatch::Triangle(LIMIT_RED));
    }
    if other_plan {
        legend.add("another plan (not in the band)", Swatch::Dot(OTHER_PLAN));
    }
    let mut offscale: Vec<String> = Vec::new();
    if let Some(l) = limits {
        let acc: Vec<f64> = [l.min, l.max].into_iter().flatten().collect();
        let marg: Vec<f64> = [l.marginal_min, l.marginal_max]
            .into_iter()
            .flatten()
            .collect();
        for (vals, name) in [(&acc, "acceptance"), (&marg, "marginal")] {
            for v in vals.iter().filter(|v| !in_view(**v)) {
                offscale.push(format!(
                    "{name} limit {} {} the plot",
                    short(*v).replace('-', "−"),
                    if *v > y1 { "above" } else { "below" }
                ));
            }
        }
        if acc.iter().any(|v| in_view(*v)) {
            legend.add(
                "acceptance limit",
                Swatch::Line {
                    color: LIMIT_RED,
                    width: 2,
                    dashed: true,
                },
            );
        }
        if marg.iter().any(|v| in_view(*v)) {
            legend.add(
                "marginal limit",
                Swatch::Line {
                    color: MARGINAL_ORANGE,
                    width: 1,
                    dashed: true,
                },
            );
        }
    }
    for o in &offscale {
        legend.add(format!("{o} (not drawn)"), Swatch::Band(WHITE.mix(0.0)));
    }
    if let Some(b) = &t.band {
        legend.add(
            format!("control band: mean ± 3σ of {} earlier", b.n),
            Swatch::Band(BAND_BLUE.mix(0.25)),
        );
    }
    // what the legend must not cover: every point and its bar
    let (margin, x_area, y_area) = (10u32, 36u32, 90u32);
    let area = (
        f64::from(WIDTH - 2 * margin - y_area),
        f64::from(HEIGHT - 2 * margin - x_area),
    );
    let mut data: Vec<(f64, f64)> = Vec::new();
    for (i, p) in t.points.iter().enumerate() {
        let u = p.expanded_uncertainty.unwrap_or(0.0);
        for v in [p.value - u, p.value, p.value + u] {
            data.push((norm_lin(i as f64, x0, x1), norm_lin(v, y0, y1)));
        }
    }
    let placement = legend.place(&data, area);
    let right = match placement {
        Placement::Outside => legend.width() as u32 + 24,
        Placement::Corner(_) => 0,
    };
    let labels = x_labels(&t.points, (area.0 - f64::from(right)) / n.max(1) as f64);
    let mut chart = ChartBuilder::on(root)
        .margin(margin)
        .margin_right(margin + right)
        .x_label_area_size(x_area)
        .y_label_area_size(y_area)
        .build_cartesian_2d(
            LinearAxis::with_ticks(x0, x1, (0..n).map(|i| i as f64).collect()).coord(),
            ya.coord(),
        )?;
    chart
        .configure_mesh()
        .x_desc("calibration (date, or time UTC when on the same day)")
        .y_desc(format!("{} ({})", t.label, ya.scaled_unit(&t.unit)))
        .x_label_formatter(&|x| {
            let i = x.round();
            if (x - i).abs() < 1e-6 && i >= 0.0 {
                labels.get(i as usize).cloned().unwrap_or_default()
            } else {
                String::new()
            }
        })
        .y_label_formatter(&|y| ya.label(*y))
        .label_style((FONT, 12))
        .light_line_style(RGBColor(240, 240, 240))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()?;
    if let Some(b) = &t.band {
        // from the first calibration of the band's plan: the others are not in it
        let from = t
            .points
            .iter()
            .position(|p| p.plan == t.plan)
            .map_or(x0, |i| i as f64 - 0.5);
        chart.draw_series(std::iter::once(Rectangle::new(
            [(from, b.low.max(y0)), (x1, b.high.min(y1))],
            BAND_BLUE.mix(0.25).filled(),
        )))?;
        if in_view(b.mean) {
            chart.draw_series(LineSeries::new(
                vec![(from, b.mean), (x1, b.mean)],
                BAND_BLUE.stroke_width(1),
            ))?;
        }
    }
    if let Some(l) = limits {
        for v in [l.min, l.max].into_iter().flatten().filter(|v| in_view(*v)) {
            chart.draw_series(DashedLineSeries::new(
                vec![(x0, v), (x1, v)],
                8,
                5,
                LIMIT_RED.stroke_width(2),
            ))?;
        }
        for v in [l.marginal_min, l.marginal_max]
            .into_iter()
            .flatten()
            .filter(|v| in_view(*v))
        {
            chart.draw_series(DashedLineSeries::new(
                vec![(x0, v), (x1, v)],
                4,
                4,
                MARGINAL_ORANGE.stroke_width(1),
            ))?;
        }
    }
    chart.draw_series(LineSeries::new(
        t.points
            .iter()
            .enumerate()
            .map(|(i, p)| (i as f64, p.value)),
        BLACK.mix(0.25).stroke_width(1),
    ))?;
    chart.draw_series(t.points.iter().enumerate().filter_map(|(i, p)| {
        let u = p.expanded_uncertainty?;
        let c = if p.plan == t.plan { BLACK } else { OTHER_PLAN };
        Some(ErrorBar::new_vertical(
            i as f64,
            (p.value - u).max(y0),
            p.value,
            (p.value + u).min(y1),
            c.stroke_width(1),
            6,
        ))
    }))?;
    for (i, p) in t.points.iter().enumerate() {
        let at = chart.backend_coord(&(i as f64, p.value));
        if p.plan != t.plan {
            root.draw(&Circle::new(at, 4, OTHER_PLAN.filled()))?;
            continue;
        }
        match standing(p.value, limits) {
            Standing::Inside => root.draw(&Circle::new(at, 4, BLACK.filled()))?,
            Standing::Marginal => root.draw(&diamond(at, 6, MARGINAL_ORANGE))?,
            Standing::Outside => {
                root.draw(&TriangleMarker::new(at, 7, LIMIT_RED.filled()))?;
            }
        }
    }
    legend.draw(root, chart.plotting_area().get_pixel_range(), placement)?;
    Ok(())
}
