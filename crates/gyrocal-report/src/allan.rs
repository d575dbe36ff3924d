//! The drift page (`allan.html`, `gyrocal allan -o FILE`): an [`AllanDocument`] rendered as a
//! self-contained HTML page (inline CSS and SVG). The analysis itself is
//! `gyrocal_analysis::drift` (issue 23: the report crate only renders); this module takes its
//! typed result.
//!
//! The names of the analysis's types are re-exported here only for the page's callers'
//! convenience where they are part of what is rendered ([`AllanDocument`]); everything else is
//! imported from `gyrocal_analysis::drift`.

use std::fmt::Write as _;

use gyrocal_allan::{NoiseTerms, Term};
use gyrocal_analysis::DriftError;
pub use gyrocal_analysis::drift::AllanDocument;
use gyrocal_analysis::drift::{RunHeader, Warmup, fmt_num};
use gyrocal_fit::display::{display_unit, value_pm_u};
use plotters::prelude::*;

use std::fs;
use std::path::{Path, PathBuf};

use crate::page::{Page, esc};
use crate::plots::axis::{LinearAxis, LogAxis};
use crate::plots::legend::{Legend, Placement, Swatch, densify, norm_lin, norm_log};
use crate::{ALLAN_HTML, ALLAN_JSON, ReportError, write_atomic};

/// The analysis's number format (4 significant digits), the page's too.
fn fmt_g(v: f64) -> String {
    fmt_num(v)
}

/// The analysis's errors as the report's, with the same messages and the same kind (input or
/// environment), so `gyrocal report` and `gyrocal allan` say and exit as before the move.
impl From<DriftError> for ReportError {
    fn from(e: DriftError) -> ReportError {
        match e {
            DriftError::Data {
                path,
                line,
                message,
            } => ReportError::Data {
                path,
                line,
                message,
            },
            DriftError::Io {
                path,
                action,
                source,
            } => ReportError::Io {
                path,
                action,
                source,
            },
            DriftError::NotAFile { path } => ReportError::NotAFile { path },
            DriftError::Run(e) => ReportError::Run(e),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The page

const FONT: &str = "sans-serif";
const LIGHT: RGBColor = RGBColor(235, 235, 235);
const BOLD: RGBColor = RGBColor(205, 205, 205);
const BLUE: RGBColor = RGBColor(31, 119, 180);
const TERM_COLORS: [RGBColor; 5] = [
    RGBColor(148, 103, 189),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(214, 39, 40),
    RGBColor(140, 86, 75),
];

type PlotResult = Result<(), Box<dyn std::error::Error>>;

fn draw(name: &str, f: impl FnOnce(&mut String) -> PlotResult) -> Result<String, ReportError> {
    let mut s = String::new();
    f(&mut s).map_err(|e| ReportError::Plot {
        name: name.to_string(),
        message: e.to_string(),
    })?;
    Ok(s)
}

/// Short name of a term.
pub fn term_name(t: Term) -> &'static str {
    match t {
        Term::Quantization => "quantization Q",
        Term::AngleRandomWalk => "angle random walk N",
        Term::BiasInstability => "bias instability B",
        Term::RateRandomWalk => "rate random walk K",
        Term::RateRamp => "rate ramp R",
    }
}

/// The noise type of a power-law exponent α, with the gyro term it corresponds to.
pub fn noise_name(alpha: i32) -> &'static str {
    match alpha {
        2 => "white PM (quantization)",
        1 => "flicker PM",
        0 => "white FM (ARW)",
        -1 => "flicker FM (bias inst.)",
        -2 => "random-walk FM (RRW)",
        _ => "?",
    }
}

fn basis(t: Term, tau: f64) -> f64 {
    match t {
        Term::Quantization => tau.powi(-2),
        Term::AngleRandomWalk => 1.0 / tau,
        Term::BiasInstability => 1.0,
        Term::RateRandomWalk => tau,
        Term::RateRamp => tau * tau,
    }
}

fn log_grid(lo: f64, hi: f64, n: usize) -> impl Iterator<Item = f64> {
    let (a, b) = (lo.ln(), hi.ln());
    (0..n).map(move |i| (a + (b - a) * i as f64 / (n - 1) as f64).exp())
}

/// Size of the σ(τ) plot, px.
const CURVE_SIZE: (u32, u32) = (800, 520);

/// The σ(τ) plot: log axes labelled at every decade ([`LogAxis`]), the legend where it covers
/// no point ([`Legend::place`]).
pub(crate) fn curve_plot(doc: &AllanDocument) -> Result<String, ReportError> {
    draw("allan.svg", |s| {
        let root = SVGBackend::with_string(s, CURVE_SIZE).into_drawing_area();
        root.fill(&WHITE)?;
        let pts: Vec<_> = doc
            .curve
            .points
            .iter()
            .filter(|p| p.deviation.is_finite() && p.deviation > 0.0)
            .collect();
        let (mut x0, mut x1) = (f64::INFINITY, 0.0f64);
        let (mut y0, mut y1) = (f64::INFINITY, 0.0f64);
        for p in &pts {
            x0 = x0.min(p.tau_s);
            x1 = x1.max(p.tau_s);
            for v in [p.deviation, p.ci95.0, p.ci95.1] {
                if v.is_finite() && v > 0.0 {
                    y0 = y0.min(v);
                    y1 = y1.max(v);
                }
            }
        }
        if !(x0.is_finite() && x1 > 0.0 && y0.is_finite() && y1 > 0.0) {
            (x0, x1, y0, y1) = (0.1, 10.0, 0.1, 10.0);
        }
        // the plotting area, px: the frame less the margins, the caption and the label areas
        let (margin, x_area, y_area, caption) = (12u32, 48u32, 80u32, 36u32);
        let area_w = f64::from(CURVE_SIZE.0 - 2 * margin - y_area);
        let area_h = f64::from(CURVE_SIZE.1 - 2 * margin - x_area - caption);
        let ya = LogAxis::new(y0 / 1.1, y1 * 1.1, area_h);
        let unit = doc.unit.replace("deg", "°");
        let fit = doc.noise_terms.as_ref().and_then(|n| n.fit.as_ref());
        // the legend, with the same entries the series below draw
        let mut legend = Legend::new();
        let minimum = pts
            .iter()
            .min_by(|a, b| a.deviation.total_cmp(&b.deviation));
        let guide = RGBColor(150, 150, 150);
        if minimum.is_some() {
            legend.add(
                "slope guides −½, 0, +½",
                Swatch::Line {
                    color: guide,
                    width: 1,
                    dashed: true,
                },
            );
        }
        if let Some(fit) = fit {
            for (k, term) in Term::ALL.iter().enumerate() {
                if fit.coefficients[k] > 0.0 {
                    legend.add(
                        term_name(*term),
                        Swatch::Line {
                            color: TERM_COLORS[k],
                            width: 1,
                            dashed: false,
                        },
                    );
                }
            }
            legend.add(
                "five-term model (weighted fit)",
                Swatch::Line {
                    color: BLACK,
                    width: 2,
                    dashed: false,
                },
            );
        }
        legend.add("σ(τ) with 95 % interval (pale: τ > T/4)", Swatch::Dot(BLUE));
        // what the legend must not cover: the points, their intervals and the model's curve,
        // on a trial x axis as wide as the plot would be with the legend inside
        let placement = {
            let xa = LogAxis::new(x0 / 1.5, x1 * 1.5, area_w);
            let nx = |t: f64| norm_log(t, xa.lo, xa.hi);
            let ny = |v: f64| norm_log(v.clamp(ya.lo, ya.hi), ya.lo, ya.hi);
            let mut data: Vec<(f64, f64)> = Vec::new();
            for p in &pts {
                for v in [p.deviation, p.ci95.0, p.ci95.1] {
                    if v.is_finite() && v > 0.0 {
                        data.push((nx(p.tau_s), ny(v)));
                    }
                }
            }
            if let Some(fit) = fit {
                let line: Vec<(f64, f64)> = log_grid(xa.lo, xa.hi, 100)
                    .map(|t| (t, fit.variance(t).sqrt()))
                    .filter(|p| p.1.is_finite() && p.1 >= ya.lo && p.1 <= ya.hi)
                    .map(|(t, v)| (nx(t), ny(v)))
                    .collect();
                data.extend(densify(&line, 4));
            }
            legend.place(&data, (area_w, area_h))
        };
        // room on the right for the last decade's label (centred on the frame), or the legend
        let right = match placement {
            Placement::Outside => legend.width() as u32 + 24,
            Placement::Corner(_) => 24,
        };
        let xa = LogAxis::new(x0 / 1.5, x1 * 1.5, area_w - f64::from(right));
        let (x0, x1, y0, y1) = (xa.lo, xa.hi, ya.lo, ya.hi);
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!(
                    "{} of the rate record",
                    doc.curve.estimator.name().to_uppercase()
                ),
                (FONT, 20),
            )
            .margin(margin)
            .margin_right(margin + right)
            .x_label_area_size(x_area)
            .y_label_area_size(y_area)
            .build_cartesian_2d(xa.coord(), ya.coord())?;
        chart
            .configure_mesh()
            .x_desc("averaging time τ (s)")
            .y_desc(format!("σ(τ) ({unit})"))
            .x_label_formatter(&|v| xa.label(*v))
            .y_label_formatter(&|v| ya.label(*v))
            .axis_desc_style((FONT, 16))
            .label_style((FONT, 14))
            .light_line_style(LIGHT)
            .bold_line_style(BOLD)
            .draw()?;
        let within = |y: f64| y >= y0 && y <= y1 && y.is_finite();
        // slope guides through the minimum
        if let Some(pm) = minimum {
            for slope in [-0.5f64, 0.0, 0.5] {
                let line: Vec<(f64, f64)> = log_grid(x0, x1, 60)
                    .map(|t| (t, pm.deviation * (t / pm.tau_s).powf(slope)))
                    .filter(|p| within(p.1))
                    .collect();
                chart.draw_series(DashedLineSeries::new(line, 5, 5, guide.stroke_width(1)))?;
            }
        }
        // the fitted model and its terms
        if let Some(fit) = fit {
            for (k, term) in Term::ALL.iter().enumerate() {
                let c = fit.coefficients[k];
                if c <= 0.0 {
                    continue;
                }
                let line: Vec<(f64, f64)> = log_grid(x0, x1, 120)
                    .map(|t| (t, (c * basis(*term, t)).sqrt()))
                    .filter(|p| within(p.1))
                    .collect();
                chart.draw_series(LineSeries::new(line, TERM_COLORS[k].stroke_width(1)))?;
            }
            let line: Vec<(f64, f64)> = log_grid(x0, x1, 200)
                .map(|t| (t, fit.variance(t).sqrt()))
                .filter(|p| within(p.1))
                .collect();
            chart.draw_series(LineSeries::new(line, BLACK.stroke_width(2)))?;
        }
        let faded = BLUE.mix(0.35);
        chart.draw_series(
            pts.iter()
                .filter(|p| p.ci95.0.is_finite() && p.ci95.1.is_finite())
                .map(|p| {
                    let style = if p.beyond_quarter {
                        faded.stroke_width(1)
                    } else {
                        BLUE.stroke_width(1)
                    };
                    ErrorBar::new_vertical(
                        p.tau_s,
                        p.ci95.0.max(y0),
                        p.deviation,
                        p.ci95.1.min(y1),
                        style,
                        6,
                    )
                }),
        )?;
        chart.draw_series(pts.iter().map(|p| {
            let c = if p.beyond_quarter {
                faded.filled()
            } else {
                BLUE.filled()
            };
            Circle::new((p.tau_s, p.deviation), 3, c)
        }))?;
        legend.draw(&root, chart.plotting_area().get_pixel_range(), placement)?;
        root.present()?;
        Ok(())
    })
}

fn warmup_plot(doc: &AllanDocument, w: &Warmup) -> Result<String, ReportError> {
    draw("warmup.svg", |s| {
        let size = (800u32, 400u32);
        let root = SVGBackend::with_string(s, size).into_drawing_area();
        root.fill(&WHITE)?;
        let (mut x0, mut x1, mut y0, mut y1) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        for &(t, m) in &w.curve {
            x0 = x0.min(t);
            x1 = x1.max(t);
            y0 = y0.min(m);
            y1 = y1.max(m);
        }
        if !(x0.is_finite() && x1 > x0) {
            (x0, x1) = (0.0, 1.0);
        }
        if !(y0.is_finite() && y1 > y0) {
            let c = if y0.is_finite() { y0 } else { 0.0 };
            (y0, y1) = (c - 1.0, c + 1.0);
        }
        let pad = (y1 - y0) * 0.08;
        let (xa, ya) = (
            LinearAxis::new(x0, x1, 8),
            LinearAxis::new(y0 - pad, y1 + pad, 6),
        );
        let unit = doc.unit.replace("deg", "°");
        let tw = doc.segments[doc.analysed.segment].t_s.0 + w.time_s;
        let red = RGBColor(214, 39, 40);
        let mut legend = Legend::new();
        legend.add(
            "window means",
            Swatch::Line {
                color: BLUE,
                width: 2,
                dashed: false,
            },
        );
        legend.add(
            format!("warm-up complete: {} s ({})", fmt_g(w.time_s), w.ended_by),
            Swatch::Line {
                color: red,
                width: 2,
                dashed: true,
            },
        );
        let (margin, x_area, y_area, caption) = (12u32, 48u32, 90u32, 34u32);
        let area = (
            f64::from(size.0 - 2 * margin - y_area),
            f64::from(size.1 - 2 * margin - caption - x_area),
        );
        let line: Vec<(f64, f64)> = w
            .curve
            .iter()
            .map(|&(t, m)| (norm_lin(t, xa.lo, xa.hi), norm_lin(m, ya.lo, ya.hi)))
            .collect();
        let placement = legend.place(&densify(&line, 3), area);
        let right = match placement {
            Placement::Outside => legend.width() as u32 + 24,
            Placement::Corner(_) => 0,
        };
        let mut chart = ChartBuilder::on(&root)
            .caption("Warm-up: rolling mean of the output", (FONT, 20))
            .margin(margin)
            .margin_right(margin + right)
            .x_label_area_size(x_area)
            .y_label_area_size(y_area)
            .build_cartesian_2d(xa.coord(), ya.coord())?;
        chart
            .configure_mesh()
            .x_desc("time (s)")
            .y_desc(format!(
                "{} s mean ({})",
                fmt_g(w.window_s),
                ya.scaled_unit(&unit)
            ))
            .x_label_formatter(&|v| xa.label(*v))
            .y_label_formatter(&|v| ya.label(*v))
            .axis_desc_style((FONT, 16))
            .label_style((FONT, 14))
            .light_line_style(LIGHT)
            .bold_line_style(BOLD)
            .draw()?;
        chart.draw_series(LineSeries::new(
            w.curve.iter().copied(),
            BLUE.stroke_width(2),
        ))?;
        chart.draw_series(DashedLineSeries::new(
            [(tw, ya.lo), (tw, ya.hi)],
            6,
            4,
            red.stroke_width(2),
        ))?;
        legend.draw(&root, chart.plotting_area().get_pixel_range(), placement)?;
        root.present()?;
        Ok(())
    })
}

fn q(v: &gyrocal_allan::Quantity) -> String {
    esc(&pm(v))
}

/// A figure ± its uncertainty in the one rule of every `±` (gyrocal_fit::display), its unit
/// spelled as on the pages (`°/√h`, not the file's `deg/sqrt(h)`).
pub fn pm(v: &gyrocal_allan::Quantity) -> String {
    value_pm_u(v.value, Some(v.uncertainty), &v.unit)
}

/// A note of the analysis as a person reads it: a term named by its code name
/// (`RateRamp: ...`, as allan.json records it) is named in words (`rate ramp R: ...`), and
/// units in the file's ASCII spelling get their symbols.
pub fn note_words(n: &str) -> String {
    let mut s = n.to_string();
    for t in Term::ALL {
        let code = format!("{t:?}:");
        if let Some(rest) = s.strip_prefix(&code) {
            s = format!("{}:{rest}", term_name(t));
        }
    }
    // "local slope +1 ± 0.15" is a tolerance, not a value with its uncertainty: said so
    const SLOPE: &str = "local slope ";
    if let Some(i) = s.find(SLOPE) {
        let after = &s[i + SLOPE.len()..];
        let mut words = after.splitn(4, ' ');
        if let (Some(slope), Some("±"), Some(tol)) = (words.next(), words.next(), words.next()) {
            let rest = words.next().map_or_else(String::new, |r| format!(" {r}"));
            s = format!("{}a local slope within {tol} of {slope}{rest}", &s[..i]);
        }
    }
    s.replace("deg/h/sqrt(h)", "°/h/√h")
        .replace("deg/sqrt(h)", "°/√h")
        .replace("deg/h", "°/h")
}

/// The rows of the noise-term table: (term, slope read, five-term fit), plain text.
pub fn noise_term_rows(nt: &NoiseTerms) -> Vec<(Term, String, String)> {
    let plain = pm;
    Term::ALL
        .iter()
        .enumerate()
        .map(|(k, &t)| {
            let read = match t {
                Term::Quantization => nt.quantization.as_ref(),
                Term::AngleRandomWalk => nt.angle_random_walk.as_ref(),
                Term::RateRandomWalk => nt.rate_random_walk.as_ref(),
                Term::RateRamp => nt.rate_ramp.as_ref(),
                Term::BiasInstability => None,
            };
            let slope = match (t, read) {
                (Term::BiasInstability, _) => match &nt.bias_instability {
                    Some(b) => format!(
                        "{} (σ_min {} at τ = {} s{})",
                        plain(&b.value),
                        fmt_g(b.sigma_min.value),
                        fmt_g(b.tau_min_s),
                        if b.flat {
                            ""
                        } else {
                            "; not flat there: indicative"
                        }
                    ),
                    None => "-".into(),
                },
                (_, Some(r)) => format!(
                    "{} (line over τ {}–{} s, read at τ = {} s{})",
                    plain(&r.value),
                    fmt_g(r.tau_range_s.0),
                    fmt_g(r.tau_range_s.1),
                    fmt_g(r.read_at_tau_s),
                    if r.extrapolated { ", extrapolated" } else { "" }
                ),
                (_, None) => "- (no region of that slope)".into(),
            };
            let fit = nt
                .fit
                .as_ref()
                .and_then(|f| f.terms.get(k))
                .map_or("-".into(), |ft| {
                    if ft.at_zero {
                        format!(
                            "0 (held at zero; 1σ could be {} {})",
                            fmt_g(ft.value.uncertainty),
                            display_unit(&ft.value.unit)
                        )
                    } else {
                        plain(&ft.value)
                    }
                });
            (t, slope, fit)
        })
        .collect()
}

/// The head of a run's page: whose record, where, by whom, when, with what; a simulated record
/// says so first.
fn render_run_header(h: &mut String, r: &RunHeader) {
    if r.simulated {
        h.push_str("<div class=\"banner caution\" id=\"simulated\"><strong>SIMULATED</strong>: this record was taken on gyrocal's simulated bench, not on instruments; it is not a measurement of a gyro.</div>\n");
    }
    h.push_str("<h2 id=\"run\">The record</h2>\n<table>\n");
    let mut row = |k: &str, v: String| {
        let _ = writeln!(h, "<tr><th>{}</th><td>{v}</td></tr>", esc(k));
    };
    row(
        "gyro",
        match (&r.dut_serial, &r.dut_model) {
            (Some(s), Some(m)) => {
                format!("<strong id=\"dut-serial\">{}</strong> ({})", esc(s), esc(m))
            }
            (Some(s), None) => format!("<strong id=\"dut-serial\">{}</strong>", esc(s)),
            (None, Some(m)) => format!("{} (serial not given)", esc(m)),
            (None, None) => "not identified (give --dut-serial, or [dut] in the plan)".into(),
        },
    );
    row(
        "station",
        r.station.as_deref().map_or("not identified".into(), esc),
    );
    row("operator", r.operator.as_deref().map_or("-".into(), esc));
    row(
        "performed (UTC)",
        format!(
            "{} to {}",
            esc(&r.started_utc),
            r.ended_utc.as_deref().map_or("(not ended)".into(), esc)
        ),
    );
    row(
        "plan",
        format!(
            "{} (hash <code>{}</code>), {}",
            esc(&r.plan_name),
            esc(r.plan_hash.get(..12).unwrap_or(&r.plan_hash)),
            esc(&r.status)
        ),
    );
    row(
        "multimeter",
        r.multimeter.as_deref().map_or("-".into(), esc),
    );
    row("rate table", esc(&r.table));
    if !r.deviations.is_empty() {
        row(
            "deviations",
            r.deviations
                .iter()
                .map(|d| esc(d))
                .collect::<Vec<_>>()
                .join("<br>"),
        );
    }
    h.push_str("</table>\n");
}

/// The self-contained HTML page of an Allan analysis: the σ(τ) plot with 95 % bars, the fitted
/// five-term model, each term and slope guides; the noise-term table; bias and bias stability;
/// the warm-up curve; the curve table; the notes.
pub fn render_allan(doc: &AllanDocument) -> Result<String, ReportError> {
    let mut h = String::with_capacity(64 * 1024);
    let name = doc.input.display().to_string();
    let unit = doc.unit.replace("deg", "°");
    let title = format!("Allan analysis: {name}");
    let sub = format!(
        "<code>{}</code>: column <code>{}</code>{}, {} rows",
        esc(&doc.file.display().to_string()),
        esc(&doc.value_column),
        doc.time_column
            .as_ref()
            .map(|t| format!(", time <code>{}</code>", esc(t)))
            .unwrap_or_default(),
        doc.rows
    );
    Page::new(&title, "Allan analysis of a gyro rate record")
        .with_sub(sub)
        .open(&mut h);
    if let Some(r) = &doc.run {
        render_run_header(&mut h, r);
    }
    h.push_str("<table>\n");
    let mut row = |k: &str, v: String| {
        let _ = writeln!(h, "<tr><th>{}</th><td>{v}</td></tr>", esc(k));
    };
    row("estimator", esc(doc.curve.estimator.name()));
    row("deviation unit", esc(&unit));
    row(
        "scale factor",
        doc.scale_factor
            .as_ref()
            .map_or("none (input unit)".into(), |k| {
                format!("{} V/(°/s) ({})", k.v_per_dps, esc(&k.source))
            }),
    );
    row(
        "τ0",
        format!("{} s ({})", fmt_g(doc.tau0_s), esc(&doc.tau0_source)),
    );
    row(
        "analysed",
        format!(
            "segment {} of {}: {} samples, t = {} s to {} s, T = {} s ({} h)",
            doc.analysed.segment + 1,
            doc.segments.len(),
            doc.analysed.samples,
            fmt_g(doc.analysed.t_s.0),
            fmt_g(doc.analysed.t_s.1),
            fmt_g(doc.analysed.duration_s),
            fmt_g(doc.analysed.duration_s / 3600.0)
        ),
    );
    row(
        "warm-up",
        doc.warmup.as_ref().map_or("not detected".into(), |w| {
            format!(
                "{} s ({}; window {} s, tolerance {} {})",
                fmt_g(w.time_s),
                esc(&w.ended_by),
                fmt_g(w.window_s),
                fmt_g(w.tolerance),
                esc(&unit)
            )
        }),
    );
    h.push_str("</table>\n");
    if !doc.notes.is_empty() {
        h.push_str("<div class=\"banner caution\"><ul>\n");
        for n in &doc.notes {
            let _ = writeln!(h, "<li>{}</li>", esc(&note_words(n)));
        }
        h.push_str("</ul></div>\n");
    }
    let _ = write!(
        h,
        "<h2 id=\"curve\">Stability curve</h2>\n<figure>{}<figcaption>{} with 95 % chi-squared intervals (Greenhall EDF); pale points are τ > T/4 (too few averages to trust). Lines: the five-term model fitted by weighted least squares and each of its terms; dashed: slopes −½, 0, +½ through the minimum.</figcaption></figure>\n",
        curve_plot(doc)?,
        esc(doc.curve.estimator.name())
    );
    h.push_str("<h2 id=\"terms\">Noise terms (IEEE 952)</h2>\n");
    match &doc.noise_terms {
        Some(nt) => {
            h.push_str("<table id=\"noise-terms\">\n<tr><th>term</th><th>slope read (± 1σ)</th><th>five-term fit (± 1σ)</th></tr>\n");
            for (t, slope, fit) in noise_term_rows(nt) {
                let _ = writeln!(
                    h,
                    "<tr><td>{}</td><td>{}</td><td>{}</td></tr>",
                    esc(term_name(t)),
                    esc(&slope),
                    esc(&fit)
                );
            }
            h.push_str("</table>\n");
            if let Some(f) = &nt.fit {
                let _ = writeln!(
                    h,
                    "<p class=\"note\">Fit over {} points (τ ≤ T/4), reduced χ² = {}. N read at τ = 1 s on the −½ line, K at τ = 3 s on the +½ line, B = σ_min / 0.6643.</p>",
                    f.points_used,
                    fmt_g(f.chi2_reduced)
                );
            }
            for n in &nt.notes {
                let _ = writeln!(h, "<p class=\"note\">{}</p>", esc(&note_words(n)));
            }
        }
        None => h.push_str("<p class=\"banner caution\">No noise terms: the curve is not a rate in °/h. Give the scale factor (<code>--scale-factor K</code>, V/(°/s)).</p>\n"),
    }
    h.push_str(
        "<h2 id=\"bias\">Bias and bias stability (GJB 2426A)</h2>\n<table id=\"bias-table\">\n",
    );
    let _ = writeln!(
        h,
        "<tr><th>bias (mean)</th><td class=\"num\">{}</td></tr>",
        q(&doc.bias.bias)
    );
    if let Some(e) = &doc.earth_rate {
        let _ = writeln!(
            h,
            "<tr><th>bias without the Earth rate</th><td class=\"num\" id=\"bias-earth-removed\">{} °/h (Earth rate along the {:?} axis at latitude {}°: {} °/h removed)</td></tr>",
            fmt_num(e.bias_dph),
            e.axis,
            fmt_g(e.latitude_deg),
            fmt_num(e.component_dph)
        );
    }
    for (label, st) in [
        ("bias stability, 10 s", &doc.bias.stability_10s),
        ("bias stability, 100 s", &doc.bias.stability_100s),
    ] {
        let v = st
            .as_ref()
            .map_or("- (fewer than two windows)".into(), |s| {
                format!("{} ({} windows)", q(&s.stability), s.windows)
            });
        let _ = writeln!(h, "<tr><th>{label}</th><td class=\"num\">{v}</td></tr>");
    }
    h.push_str("</table>\n");
    if let Some(w) = &doc.warmup {
        let _ = write!(
            h,
            "<h2 id=\"warmup\">Warm-up (IEEE 1431 §12.6)</h2>\n<figure>{}<figcaption>Means of consecutive {} s windows; the warm-up is complete when two consecutive means differ by less than {} {} ({}). The analysis uses the record after it.</figcaption></figure>\n",
            warmup_plot(doc, w)?,
            fmt_g(w.window_s),
            fmt_g(w.tolerance),
            esc(&unit),
            esc(&w.tolerance_source)
        );
    }
    h.push_str("<h2 id=\"points\">Curve</h2>\n<table id=\"curve-table\">\n<tr><th>τ (s)</th><th>m</th><th>σ</th><th>68 % interval</th><th>95 % interval</th><th>edf</th><th>noise</th></tr>\n");
    for p in &doc.curve.points {
        let _ = writeln!(
            h,
            "<tr{}><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{} – {}</td><td class=\"num\">{} – {}</td><td class=\"num\">{}</td><td>{}{}</td></tr>",
            if p.beyond_quarter {
                " class=\"beyond\""
            } else {
                ""
            },
            fmt_g(p.tau_s),
            p.m,
            fmt_g(p.deviation),
            fmt_g(p.ci68.0),
            fmt_g(p.ci68.1),
            fmt_g(p.ci95.0),
            fmt_g(p.ci95.1),
            fmt_g(p.edf),
            noise_name(p.noise_alpha),
            if p.beyond_quarter { " (τ > T/4)" } else { "" }
        );
    }
    let _ = write!(
        h,
        "</table>\n<p class=\"note\">Deviations in {}. Made by gyrocal allan {}.</p>\n",
        esc(&unit),
        env!("CARGO_PKG_VERSION")
    );
    Page::close(&mut h, None);
    Ok(h)
}

// ---------------------------------------------------------------------------------------------
// The drift record's files: its analysis (allan.json) and its page (allan.html), written
// through the run directory; the end of a drift run and its report (see `crate::kinds`).

/// The files of a drift run its Allan analysis reads (the record, its steps, the scale factor
/// from fit.json) and the analysis it replaces (`allan.json`: an edited one is not silently
/// overwritten).
pub const DRIFT_FILES_READ: [&str; 4] = [
    gyrocal_files::rundir::SAMPLES_CSV,
    gyrocal_files::rundir::STEPS_CSV,
    gyrocal_files::rundir::FIT_JSON,
    crate::ALLAN_JSON,
];

/// The call for the end of a drift run: analyses `run_dir` ([`gyrocal_analysis::drift::analyse_input`]) and writes
/// `run_dir/allan.json` (the [`gyrocal_analysis::drift::AllanDocument`], as `gyrocal allan --json` prints it) and
/// `run_dir/allan.html` ([`render_allan`]). A run directory (one with a manifest) is
/// opened for its results ([`gyrocal_files::RunResults`]: under its lock, each file recorded
/// with its SHA-256 in the manifest; see [`write_allan_into`]); a directory without a manifest
/// (a bare `samples.csv`) just gets the two files, each atomically. Returns the document and
/// the paths written (JSON first).
pub fn write_run_allan(
    run_dir: &Path,
    opts: &gyrocal_analysis::drift::AllanOptions,
) -> Result<(gyrocal_analysis::drift::AllanDocument, Vec<PathBuf>), ReportError> {
    write_run_allan_noted(run_dir, opts, &[])
}

/// [`write_run_allan`] with `notes` put first among the page's notes (e.g. the banners of
/// `gyrocal report --allow-modified`).
pub fn write_run_allan_noted(
    run_dir: &Path,
    opts: &gyrocal_analysis::drift::AllanOptions,
    notes: &[String],
) -> Result<(gyrocal_analysis::drift::AllanDocument, Vec<PathBuf>), ReportError> {
    if fs::symlink_metadata(run_dir.join(gyrocal_files::rundir::MANIFEST_JSON)).is_ok() {
        let mut run = gyrocal_files::RunResults::open(run_dir)?;
        return write_allan_into(&mut run, opts, notes);
    }
    let _span = tracing::info_span!("allan", dir = %run_dir.display()).entered();
    let (doc, json, html) = allan_files(run_dir, opts, notes)?;
    let (jp, hp) = (run_dir.join(ALLAN_JSON), run_dir.join(ALLAN_HTML));
    write_atomic(&jp, json.as_bytes())?;
    write_atomic(&hp, html.as_bytes()).map_err(|e| ReportError::PartlyWritten {
        written: vec![jp.clone()],
        failed: Box::new(e),
    })?;
    tracing::info!(json = %jp.display(), html = %hp.display(), "allan analysis written");
    Ok((doc, vec![jp, hp]))
}

/// The Allan analysis of the run `run` writes (a run that just ended, its [`gyrocal_files::RunDir`]
/// still open, or a [`gyrocal_files::RunResults`]): `allan.json` then `allan.html`, each through
/// the run directory (atomically, under the run's lock, its SHA-256 recorded in the manifest),
/// `notes` first among the page's notes. When `allan.html` cannot be written after
/// `allan.json` was, the error is [`ReportError::PartlyWritten`]: the analysis is on disk, the
/// page is not (see [`ReportError::allan_warning`]).
pub fn write_allan_into(
    run: &mut dyn gyrocal_files::WriteResult,
    opts: &gyrocal_analysis::drift::AllanOptions,
    notes: &[String],
) -> Result<(gyrocal_analysis::drift::AllanDocument, Vec<PathBuf>), ReportError> {
    let dir = run.dir().to_path_buf();
    let _span = tracing::info_span!("allan", dir = %dir.display()).entered();
    let (doc, json, html) = allan_files(&dir, opts, notes)?;
    let jp = dir.join(ALLAN_JSON);
    if let Err(e) = run.write_result(ALLAN_JSON, json.as_bytes()) {
        // the file may have landed before its record failed (the manifest could not be
        // stored): say so rather than "no Allan analysis"
        let landed = gyrocal_files::rundir::sha256_file(&jp)
            .is_ok_and(|h| h == gyrocal_files::rundir::sha256_hex(json.as_bytes()));
        return Err(if landed {
            ReportError::PartlyWritten {
                written: vec![jp],
                failed: Box::new(e.into()),
            }
        } else {
            e.into()
        });
    }
    run.write_result(ALLAN_HTML, html.as_bytes())
        .map_err(|e| ReportError::PartlyWritten {
            written: vec![jp.clone()],
            failed: Box::new(e.into()),
        })?;
    let hp = dir.join(ALLAN_HTML);
    tracing::info!(json = %jp.display(), html = %hp.display(), "allan analysis written and recorded");
    Ok((doc, vec![jp, hp]))
}

/// The analysis of `dir` with `notes` first, as JSON and as the page.
fn allan_files(
    dir: &Path,
    opts: &gyrocal_analysis::drift::AllanOptions,
    notes: &[String],
) -> Result<(gyrocal_analysis::drift::AllanDocument, String, String), ReportError> {
    let mut doc = gyrocal_analysis::drift::analyse_input(dir, opts)?;
    if !notes.is_empty() {
        doc.notes.splice(0..0, notes.iter().cloned());
    }
    let json = serde_json::to_string_pretty(&doc).map_err(|e| ReportError::Plot {
        name: ALLAN_JSON.into(),
        message: e.to_string(),
    })?;
    let html = render_allan(&doc)?;
    Ok((doc, json, html))
}

impl ReportError {
    /// The operator's warning when a drift run's Allan analysis could not be written at the
    /// end of the run, worded by what was written: "no Allan analysis" only when nothing was.
    pub fn allan_warning(&self) -> String {
        match self {
            ReportError::PartlyWritten { written, failed } if !written.is_empty() => format!(
                "the Allan analysis is in {}, but its page could not be written: {failed}",
                written
                    .iter()
                    .map(|p| p.display().to_string())
                    .collect::<Vec<_>>()
                    .join(" and ")
            ),
            other => format!("no Allan analysis: {other}"),
        }
    }
}
