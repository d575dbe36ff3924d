//! The temperature series' page (`series.html`) on the certificate's layout: the report id
//! on every printed page, the item and the method, the verdict against the limits on the
//! sensitivities, the per-temperature table (setpoint, the gyro's min/mean/max temperature
//! during the tests, K ± U, bias ± U, nonlinearity), the sensitivities with U, the plots
//! (K(T) and bias(T) with their models, the models' residuals, the temperature history of
//! the whole run), the hysteresis, the instruments (the chamber among them), the closing
//! statements and the end mark.

use std::fmt::Write as _;
use std::path::Path;

use gyrocal_analysis::series::{Sensitivity, SeriesDocument, TempcoVerdict};
use gyrocal_analysis::tempco::TempFit;
use gyrocal_files::Manifest;
use gyrocal_fit::display::value_pm_u;

use crate::ReportError;
use crate::certificate;
use crate::page::{Page, esc};
use crate::plots::series::{HistoryRow, Measured, figure_plot, history_plot, residuals_plot};

/// The chamber's line in the instruments table: (model, port / address, identity), when the
/// run had one.
#[derive(Debug, Clone, Default)]
pub struct ChamberLine {
    /// The controller's model as the plan names it (`watlow_f4`, `espec`).
    pub model: String,
    /// The port or address it was driven through.
    pub port: String,
    /// What the run recorded of it (its identity, the safe state it was left in and whether
    /// that was confirmed), when anything.
    pub record: Option<String>,
}

/// At most this many points of the temperature history are drawn (a long series polled every
/// 10 s has tens of thousands; the plot is 800 px wide).
const HISTORY_POINTS_MAX: usize = 2000;

fn pm(v: Option<f64>, u: Option<f64>, unit: &str) -> String {
    v.map_or_else(|| "—".to_string(), |v| esc(&value_pm_u(v, u, unit)))
}

fn sensitivity_text(s: Option<&Sensitivity>) -> String {
    s.map_or_else(
        || "not determined".to_string(),
        |s| {
            format!(
                "{} (k = {:.2}, {} model)",
                esc(&value_pm_u(s.value, Some(s.u), &s.unit)),
                s.coverage_factor,
                if s.model_order == 2 {
                    "quadratic"
                } else {
                    "linear"
                }
            )
        },
    )
}

fn model_text(f: Option<&TempFit>) -> String {
    let Some(f) = f else {
        return "—".to_string();
    };
    let m = f.chosen();
    let mut t = format!(
        "{} in T − {:.1} °C; {} residual degree{} of freedom",
        if m.order == 2 { "quadratic" } else { "linear" },
        m.t_mid_c,
        m.dof,
        if m.dof == 1 { "" } else { "s" }
    );
    if let Some(s) = &f.selection.stopped {
        let _ = write!(t, "; {}", esc(s));
    }
    t
}

fn verdict_row(v: &TempcoVerdict) -> String {
    let name = match v.limit_key.as_str() {
        "k_tempco_ppm_per_c_max" => "|K sensitivity| ≤ max (ppm/°C)",
        "bias_tempco_dph_per_c_max" => "|bias sensitivity| ≤ max (°/h/°C)",
        other => other,
    };
    format!(
        "<tr><td>{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"v-{}\"><strong>{}</strong></td></tr>",
        esc(name),
        v.max,
        v.value.map_or_else(|| "—".into(), |x| format!("{x:.4}")),
        v.u.map_or_else(|| "—".into(), |x| format!("{x:.4}")),
        esc(&v.verdict),
        esc(&v.verdict.to_uppercase())
    )
}

/// Keeps at most [`HISTORY_POINTS_MAX`] rows, evenly (the first and last kept).
fn thin(rows: &[HistoryRow]) -> Vec<HistoryRow> {
    if rows.len() <= HISTORY_POINTS_MAX {
        return rows.to_vec();
    }
    let every = rows.len().div_ceil(HISTORY_POINTS_MAX);
    let mut out: Vec<HistoryRow> = rows.iter().step_by(every).copied().collect();
    if let Some(last) = rows.last() {
        out.push(*last);
    }
    out
}

/// Renders `series.html` for the run in `dir` (manifest `m`) from its analysis `doc`, its
/// temperature history `history` (from temps.csv) and its chamber.
pub fn render_series(
    doc: &SeriesDocument,
    m: &Manifest,
    dir: &Path,
    history: &[HistoryRow],
    chamber: Option<&ChamberLine>,
) -> Result<String, ReportError> {
    let json = serde_json::to_string(doc).unwrap_or_default();
    let id = certificate::report_id(m, &json);
    let title = format!("Temperature series {id}");
    let mut html = String::new();
    let mut sub = format!("Run <code>{}</code>", esc(&dir.display().to_string()));
    if let Some(s) = m.dut.as_ref().and_then(|d| d.serial.as_deref()) {
        let _ = write!(sub, ", gyro serial <strong>{}</strong>", esc(s));
    }
    Page::new(
        &title,
        "Temperature series: scale factor and bias against temperature",
    )
    .with_sub(sub)
    .with_css(certificate::page_css(&id))
    .open(&mut html);
    if m.simulated {
        html.push_str("<div class=\"banner simulated\"><strong>SIMULATED</strong> — these figures come from the simulated bench, not from a gyro.</div>\n");
    }
    let _ = writeln!(
        html,
        "<table class=\"cert\" id=\"cert-head\">\n<tr><th>Report id</th><td><strong id=\"report-id\">{}</strong></td></tr>\n<tr><th>Method</th><td>temperature series, plan “{}” (SHA-256 <code>{}</code>), gyrocal {}; K and the bias fitted at every temperature by the sweep's fit, modelled in the gyro's measured temperature (weighted least squares, the model chosen by nested F-test)</td></tr>\n<tr><th>Performed</th><td>{}</td></tr>\n<tr><th>Reference temperature</th><td>{} °C (K's sensitivity is relative to K there)</td></tr>\n</table>",
        esc(&id),
        esc(m.plan.name()),
        esc(m.plan_hash.get(..16).unwrap_or(&m.plan_hash)),
        esc(&m.gyrocal_version),
        esc(&m.ended_utc.as_ref().map_or_else(
            || format!("from {} (not ended)", certificate::local(&m.started_utc)),
            |e| format!(
                "{} to {}",
                certificate::local(&m.started_utc),
                certificate::local(e)
            )
        )),
        doc.reference_c
    );
    // the verdict first, as on the certificate
    match doc.verdict.as_deref() {
        None => html.push_str("<div class=\"verdict verdict-none\" id=\"series-verdict\"><strong>No verdict</strong>: the plan's <code>[acceptance]</code> gives no limit on the sensitivities (<code>k_tempco_ppm_per_c_max</code>, <code>bias_tempco_dph_per_c_max</code>).</div>\n"),
        Some(v) => {
            let _ = writeln!(
                html,
                "<div class=\"verdict verdict-{0}\" id=\"series-verdict\"><span class=\"verdict-word\">Verdict: {1}</span> — guarded rule: a sensitivity passes when its magnitude plus its U is within the limit, fails when its magnitude less its U is beyond it.</div>",
                esc(v),
                esc(&v.to_uppercase())
            );
            html.push_str("<table id=\"series-acceptance\"><tr><th>Limit</th><th>max</th><th>|value|</th><th>U</th><th>verdict</th></tr>\n");
            for a in &doc.acceptance {
                html.push_str(&verdict_row(a));
                html.push('\n');
            }
            html.push_str("</table>\n");
        }
    }
    let _ = writeln!(
        html,
        "<h2 id=\"sensitivities\">Sensitivities over the range</h2>\n<table class=\"cert results\" id=\"sensitivity-table\">\n<tr><th>Scale factor K</th><td>{}</td></tr>\n<tr><th>Bias</th><td>{}</td></tr>\n<tr><th>K's model</th><td>{}</td></tr>\n<tr><th>The bias's model</th><td>{}</td></tr>\n</table>\n<p class=\"note\">The sensitivity is the slope of the chosen model at the middle of the measured range (for a line, its slope). Its U (k as stated: Student's t for the residual degrees of freedom, since a series has few temperatures) comes from the scatter of the points about the model, each point weighted by its own U.</p>",
        sensitivity_text(doc.k_tempco_ppm_per_c.as_ref()),
        sensitivity_text(doc.bias_tempco_dph_per_c.as_ref()),
        model_text(doc.k_model.as_ref()),
        model_text(doc.bias_model.as_ref()),
    );
    html.push_str("<h2 id=\"temperatures\">Results at each temperature</h2>\n<table class=\"results\" id=\"series-table\">\n<tr><th>#</th><th>Setpoint (°C)</th><th>Gyro min (°C)</th><th>Gyro mean (°C)</th><th>Gyro max (°C)</th><th>K ± U (k = 2)</th><th>Bias ± U (k = 2)</th><th>Nonlinearity ± U</th></tr>\n");
    for p in &doc.points {
        let mut bias = pm(p.bias_dph, p.u_bias_dph, "°/h");
        if let Some(from) = &p.bias_from {
            let _ = write!(bias, " <span class=\"note\">({})</span>", esc(from));
        }
        let mut nl = pm(p.nonlinearity_ppm, p.u_nonlinearity_ppm, "ppm");
        for n in &p.notes {
            let _ = write!(nl, "<br><span class=\"warn\">{}</span>", esc(n));
        }
        let _ = writeln!(
            html,
            "<tr><td class=\"num\">{}</td><td class=\"num\">{:.1}</td><td class=\"num\">{:.2}</td><td class=\"num\">{:.2}</td><td class=\"num\">{:.2}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td>{}</td></tr>",
            p.series_point,
            p.setpoint_c,
            p.temp_min_c,
            p.temp_mean_c,
            p.temp_max_c,
            pm(p.k, p.u_k, "V/(°/s)"),
            bias,
            nl
        );
    }
    html.push_str("</table>\n");
    // the plots
    let k_ref = doc
        .k_model
        .as_ref()
        .map(|f| f.chosen().value(doc.reference_c))
        .filter(|k| *k != 0.0 && k.is_finite());
    html.push_str("<h2 id=\"plots\">Plots</h2>\n");
    if let Some(k_ref) = k_ref {
        let to_ppm = move |k: f64| (k / k_ref - 1.0) * 1e6;
        let pts: Vec<Measured> = doc
            .points
            .iter()
            .filter_map(|p| Some((p.temp_mean_c, to_ppm(p.k?), p.u_k? / k_ref.abs() * 1e6)))
            .collect();
        let model = doc.k_model.as_ref().map(|f| {
            (
                f.chosen(),
                &to_ppm as &dyn Fn(f64) -> f64,
                format!(
                    "{} model: {}",
                    if f.chosen().order == 2 {
                        "quadratic"
                    } else {
                        "linear"
                    },
                    doc.k_tempco_ppm_per_c
                        .as_ref()
                        .map_or_else(String::new, |s| value_pm_u(s.value, Some(s.u), &s.unit))
                ),
            )
        });
        let svg = figure_plot(
            "series-k.svg",
            "Scale factor against temperature",
            &format!("K − K({} °C) (ppm)", doc.reference_c),
            &pts,
            model,
        )?;
        let _ = writeln!(
            html,
            "<figure id=\"plot-k\">{svg}<figcaption>K at each temperature as ppm from the model's K at {} °C = {} V/(°/s), with U (k = 2), against the gyro's mean temperature during the sweep; the line is the chosen model.</figcaption></figure>",
            doc.reference_c,
            esc(&format!("{k_ref:.7}"))
        );
    }
    let bias_pts: Vec<Measured> = doc
        .points
        .iter()
        .filter_map(|p| Some((p.temp_mean_c, p.bias_dph?, p.u_bias_dph?)))
        .collect();
    if !bias_pts.is_empty() {
        let ident = |y: f64| y;
        let model = doc.bias_model.as_ref().map(|f| {
            (
                f.chosen(),
                &ident as &dyn Fn(f64) -> f64,
                format!(
                    "{} model: {}",
                    if f.chosen().order == 2 {
                        "quadratic"
                    } else {
                        "linear"
                    },
                    doc.bias_tempco_dph_per_c
                        .as_ref()
                        .map_or_else(String::new, |s| value_pm_u(s.value, Some(s.u), &s.unit))
                ),
            )
        });
        let svg = figure_plot(
            "series-bias.svg",
            "Bias against temperature",
            "bias (°/h)",
            &bias_pts,
            model,
        )?;
        let _ = writeln!(
            html,
            "<figure id=\"plot-bias\">{svg}<figcaption>The bias as a rate at each temperature with U (k = 2); the line is the chosen model.</figcaption></figure>"
        );
    }
    let mut resid = Vec::new();
    for (label, fit, ys) in [
        (
            "K",
            doc.k_model.as_ref(),
            doc.points
                .iter()
                .filter_map(|p| Some((p.temp_mean_c, p.k?, p.u_k?)))
                .collect::<Vec<_>>(),
        ),
        ("bias", doc.bias_model.as_ref(), bias_pts.clone()),
    ] {
        if let Some(f) = fit {
            let m = f.chosen();
            let pts: Vec<(f64, f64)> = ys
                .iter()
                .filter(|p| p.2 > 0.0)
                .map(|&(t, y, u)| (t, (y - m.value(t)) / u))
                .collect();
            if !pts.is_empty() {
                resid.push((format!("{label}: residual of its model / U"), pts));
            }
        }
    }
    if !resid.is_empty() {
        let svg = residuals_plot(&resid)?;
        let _ = writeln!(
            html,
            "<figure id=\"plot-residuals\">{svg}<figcaption>Each point's departure from its model in units of its own U (k = 2): within ±1 the model describes the point within its uncertainty; a revisited temperature far outside is hysteresis.</figcaption></figure>"
        );
    }
    if !history.is_empty() {
        let svg = history_plot(&thin(history))?;
        let _ = writeln!(
            html,
            "<figure id=\"plot-history\">{svg}<figcaption>The chamber's setpoint, its air and the gyro (product) temperature through the whole run, as logged in temps.csv.</figcaption></figure>"
        );
    }
    // hysteresis
    html.push_str("<h2 id=\"hysteresis\">Hysteresis</h2>\n");
    if doc.hysteresis_k_ppm.is_empty() && doc.hysteresis_bias_dph.is_empty() {
        html.push_str("<p class=\"note\">No temperature was revisited: the series does not measure hysteresis.</p>\n");
    } else {
        html.push_str("<table class=\"results\" id=\"hysteresis-table\"><tr><th>Figure</th><th>Setpoint (°C)</th><th>Visits</th><th>Later − first ± U (k = 2)</th></tr>\n");
        for (what, unit, list) in [
            ("K", "ppm", &doc.hysteresis_k_ppm),
            ("bias", "°/h", &doc.hysteresis_bias_dph),
        ] {
            for h in list {
                let _ = writeln!(
                    html,
                    "<tr><td>{what}</td><td class=\"num\">{:.1}</td><td class=\"num\">#{} → #{}</td><td class=\"num\">{}</td></tr>",
                    h.setpoint_c,
                    doc.points.get(h.first).map_or(h.first, |p| p.series_point),
                    doc.points.get(h.later).map_or(h.later, |p| p.series_point),
                    esc(&value_pm_u(h.difference, Some(h.u), unit))
                );
            }
        }
        html.push_str("</table>\n<p class=\"note\">The difference between the later visit and the first, corrected to the first visit's measured temperature by the model's slope.</p>\n");
    }
    for n in &doc.notes {
        let _ = writeln!(html, "<p class=\"note warn\">{}</p>", esc(n));
    }
    certificate::instruments(&mut html, m);
    match chamber {
        Some(c) => {
            let _ = writeln!(
                html,
                "<table class=\"cert\" id=\"chamber-table\"><tr><th>Thermal chamber</th><td>{} on <code>{}</code>{}</td></tr></table>",
                esc(&c.model),
                esc(&c.port),
                c.record
                    .as_ref()
                    .map_or_else(|| "; not identified (no identity recorded, not in the station file)".to_string(), |r| format!("; {}", esc(r)))
            );
        }
        None => html.push_str("<p class=\"note\" id=\"chamber-table\">No thermal chamber recorded for this run.</p>\n"),
    }
    certificate::closing(&mut html);
    certificate::end_mark(&mut html, &id);
    Page::close(&mut html, Some("made by gyrocal"));
    Ok(html)
}

/// The run files the series page reads (checked against the run's record first).
pub const SERIES_FILES_READ: [&str; 3] = ["manifest.json", "steps.csv", "temps.csv"];

/// "result: K −60.3 ± 8.1 ppm/°C, bias 0.59 ± 0.29 °/h/°C (k = 4.30), verdict PASS": the
/// sensitivities with U as the page prints them.
pub fn result_line(doc: &SeriesDocument) -> String {
    let s = |name: &str, s: Option<&Sensitivity>| {
        s.map(|s| {
            format!(
                "{name} {} (k = {:.2})",
                value_pm_u(s.value, Some(s.u), &s.unit),
                s.coverage_factor
            )
        })
    };
    let parts: Vec<String> = [
        s("K", doc.k_tempco_ppm_per_c.as_ref()),
        s("bias", doc.bias_tempco_dph_per_c.as_ref()),
    ]
    .into_iter()
    .flatten()
    .collect();
    let mut line = if parts.is_empty() {
        "result: no sensitivity could be computed (see the notes)".to_string()
    } else {
        format!("result: sensitivities over the range: {}", parts.join(", "))
    };
    if let Some(v) = &doc.verdict {
        let _ = write!(line, "; verdict {}", v.to_uppercase());
    }
    line
}

/// The temperature history of the run in `dir` for the page (temps.csv), or why there is
/// none (a note for the page).
fn history_of(dir: &Path) -> (Vec<HistoryRow>, Option<String>) {
    match gyrocal_files::rundir::temps::read_temps(dir) {
        Ok(rows) => (
            rows.iter()
                .map(|r| (r.t_s, Some(r.setpoint_c), Some(r.air_c), r.product_c))
                .collect(),
            None,
        ),
        Err(e) => (Vec::new(), Some(format!("no temperature history: {e}"))),
    }
}

/// The chamber's line from the plan (and the station file's record, when it has one).
fn chamber_of(m: &Manifest) -> Option<ChamberLine> {
    let c = m.plan.chamber()?;
    let rec = m.chamber.as_ref();
    let mut said = Vec::new();
    if let Some(id) = rec.and_then(|r| r.identity.as_deref()) {
        said.push(format!("identified as {id}"));
    }
    if let Some(safe) = rec.and_then(|r| r.safe_state.as_deref()) {
        let confirmed = match rec.and_then(|r| r.safe_confirmed) {
            Some(true) => "confirmed",
            _ => "could NOT be confirmed",
        };
        said.push(format!("left in its safe state: {safe} ({confirmed})"));
    }
    Some(ChamberLine {
        model: c.model.as_str().to_string(),
        port: c.port.to_string(),
        record: (!said.is_empty()).then(|| said.join("; ")),
    })
}

/// Analyses the series `run` holds and writes `series.json` through it (no page).
pub fn write_analysis_into(
    run: &mut dyn gyrocal_files::WriteResult,
) -> Result<(SeriesDocument, Vec<std::path::PathBuf>), ReportError> {
    let dir = run.dir().to_path_buf();
    let data = gyrocal_files::load(&dir)?;
    let doc = gyrocal_analysis::series::analyse_run_data(&dir, &data, &Default::default())
        .map_err(gyrocal_analysis::AnalysisError::from)?;
    let jp = gyrocal_analysis::series::write_document(run, &doc)?;
    Ok((doc, vec![jp]))
}

/// Analyses the series `run` holds and writes `series.json` then `series.html` through it
/// (atomically, under the run's lock, each recorded with its SHA-256), `notes` first among
/// the analysis's notes. When the page fails after the analysis was written, the error is
/// [`ReportError::PartlyWritten`].
pub fn write_series_into(
    run: &mut dyn gyrocal_files::WriteResult,
    notes: &[String],
) -> Result<(SeriesDocument, Vec<std::path::PathBuf>), ReportError> {
    let dir = run.dir().to_path_buf();
    let data = gyrocal_files::load(&dir)?;
    let mut doc = gyrocal_analysis::series::analyse_run_data(&dir, &data, &Default::default())
        .map_err(gyrocal_analysis::AnalysisError::from)?;
    if !notes.is_empty() {
        doc.notes.splice(0..0, notes.iter().cloned());
    }
    let (history, missing) = history_of(&dir);
    if let Some(n) = missing {
        doc.notes.push(n);
    }
    let jp = gyrocal_analysis::series::write_document(run, &doc)?;
    render_series(
        &doc,
        &data.manifest,
        &dir,
        &history,
        chamber_of(&data.manifest).as_ref(),
    )
    .and_then(|html| {
        run.write_result(SERIES_HTML, html.as_bytes())
            .map_err(ReportError::from)
    })
    .map_err(|e| ReportError::PartlyWritten {
        written: vec![jp.clone()],
        failed: Box::new(e),
    })?;
    Ok((doc, vec![jp, dir.join(SERIES_HTML)]))
}

/// The series page's file name in the run directory.
pub const SERIES_HTML: &str = "series.html";
