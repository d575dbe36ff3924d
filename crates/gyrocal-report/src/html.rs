//! The calibration report's document on the shared [`crate::page`] skeleton and stylesheet:
//! inline SVG, tables. Every string that came from a file goes through [`esc`].

use std::fmt::Write as _;

use gyrocal_files::Status;
use gyrocal_fit::{Analysis, Fit, Method, Model, MultiAnalysis, NeuronStatus};

use crate::input::{FitSource, Input};
use crate::page::Page;
/// The escaper, from [`crate::page`] (kept at this path for the drift page's `use`).
pub(crate) use crate::page::esc;
use crate::{Report, ReportError, certificate, plots};

/// Side of the error-surface grid the report draws.
const SURFACE_GRID: usize = 81;

fn opt(v: Option<f64>, f: impl Fn(f64) -> String) -> String {
    v.filter(|v| v.is_finite())
        .map_or_else(|| "—".to_string(), f)
}

/// The document being built: HTML and the plots collected on the way.
struct Doc {
    html: String,
    svgs: Vec<(String, String)>,
}

impl Doc {
    /// Adds a figure: the SVG inline and in the list of files.
    fn figure(&mut self, file: String, svg: String, caption: &str) {
        let _ = write!(
            self.html,
            "<figure id=\"fig-{}\">\n{svg}\n<figcaption>{caption} <span class=\"note\">(also <code>{}</code>)</span></figcaption>\n</figure>\n",
            esc(file.trim_end_matches(".svg")),
            esc(&file)
        );
        self.svgs.push((file, svg));
    }
}

/// "Gyro under test: serial …, model …; operator …, customer …; ambient … °C, … % RH", as
/// the operator entered them (a run that names no gyro says so).
fn identification(html: &mut String, input: &Input, which: Option<usize>) {
    let Some(m) = &input.manifest else {
        return;
    };
    let prefix = which.map_or(String::new(), |n| format!("Run {n}: "));
    let mut parts = Vec::new();
    match &m.dut {
        Some(d) => {
            if let Some(s) = &d.serial {
                parts.push(format!("serial <strong>{}</strong>", esc(s)));
            }
            if let Some(s) = &d.model {
                parts.push(format!("model {}", esc(s)));
            }
        }
        None => parts.push("not named (no --dut-serial)".into()),
    }
    let mut who = Vec::new();
    if let Some(c) = &m.context {
        if let Some(o) = &c.operator {
            who.push(format!("operator {}", esc(o)));
        }
        if let Some(o) = &c.customer {
            who.push(format!("customer {}", esc(o)));
        }
        if let Some(t) = c.ambient_c {
            who.push(format!("ambient {t} °C"));
        }
        if let Some(h) = c.humidity_pct {
            who.push(format!("{h} % RH"));
        }
    }
    let who = if who.is_empty() {
        String::new()
    } else {
        format!("; {}", who.join(", "))
    };
    let _ = writeln!(
        html,
        "<p class=\"dut\">{prefix}Gyro under test: {}{who}</p>",
        parts.join(", ")
    );
}

pub(crate) fn render(inputs: &[Input]) -> Result<Report, ReportError> {
    let mut doc = Doc {
        html: String::new(),
        svgs: Vec::new(),
    };
    let many = inputs.len() > 1;
    let plans = plans_differ(inputs);
    let mut warnings = Vec::new();
    if let Some(p) = &plans {
        warnings.push(p.warning());
    }
    let simulated = inputs
        .iter()
        .any(|i| i.manifest.as_ref().is_some_and(|m| m.simulated));
    let title = match inputs {
        [one] => match &one.manifest {
            Some(m) => format!("Calibration report: {}", m.plan.name()),
            None => format!("Calibration report: {}", one.path.display()),
        },
        _ => format!("Calibration report: {} runs", inputs.len()),
    };
    let title = if simulated {
        format!("SIMULATED · {title}")
    } else {
        title
    };
    // One run directory: the report is a certificate (ISO/IEC 17025 §7.8) with an id on
    // every printed page. Several inputs or a bare CSV: a comparison, without one.
    let cert = match inputs {
        [one] => one.manifest.as_ref().map(|m| {
            // limits applied at report time are part of what the report states
            let extra = match (&one.acceptance_from, &one.analysis) {
                (Some(_), Ok(a)) => serde_json::to_string(&a.acceptance).unwrap_or_default(),
                _ => String::new(),
            };
            (one, m, certificate::report_id(m, &extra))
        }),
        _ => None,
    };
    let page_css = cert
        .as_ref()
        .map_or_else(String::new, |(_, _, id)| certificate::page_css(id));
    Page::new(&title, "Gyro scale-factor calibration report")
        .sub(format!(
            "{} · gyrocal-report {}",
            esc(&title),
            env!("CARGO_PKG_VERSION")
        ))
        .extra_css(page_css)
        .open(&mut doc.html);
    // The gyro under test and who ran it: on the first page, before any number (a
    // certificate's head says it in full, below the banners).
    if cert.is_none() {
        for (i, input) in inputs.iter().enumerate() {
            identification(&mut doc.html, input, many.then_some(i + 1));
        }
    }
    // Banners first: a simulated or incomplete run, or runs of different plans, must be seen
    // before any number.
    for (i, input) in inputs.iter().enumerate() {
        simulated_banner(&mut doc.html, input, many.then_some(i + 1));
    }
    for (i, input) in inputs.iter().enumerate() {
        banner(&mut doc.html, input, many.then_some(i + 1));
        for note in &input.notes {
            warnings.push(note.clone());
            let _ = writeln!(
                doc.html,
                "<div class=\"banner\" role=\"alert\">{}</div>",
                esc(note)
            );
        }
    }
    if let Some(p) = &plans {
        let _ = writeln!(
            doc.html,
            "<div class=\"banner plans\" role=\"alert\" id=\"banner-plans\">{}</div>",
            esc(&p.warning())
        );
    }
    if let Some((input, m, id)) = &cert {
        certificate::head(&mut doc.html, input, m, id, &certificate::issued_now());
        // the verdict and the results with their uncertainty on the first page
        let analysis = input.analysis.as_ref().ok();
        let acceptance = analysis.and_then(|a| a.acceptance.as_ref());
        certificate::verdict_box(&mut doc.html, acceptance, &acceptance_source(input));
        if let Some(a) = analysis {
            certificate::results(&mut doc.html, a);
        }
        certificate::acceptance_table(&mut doc.html, acceptance);
    }
    if many {
        repeatability(&mut doc, inputs, plans.as_ref())?;
    }
    for (i, input) in inputs.iter().enumerate() {
        let run = many.then_some(i + 1);
        if let Some(r) = run {
            let _ = writeln!(
                doc.html,
                "<h2 id=\"run{r}\">Run {r}: <code>{}</code></h2>",
                esc(&input.path.display().to_string())
            );
        }
        one(&mut doc, input, run, cert.is_some())?;
    }
    if let Some((_, _, id)) = &cert {
        certificate::closing(&mut doc.html);
        certificate::end_mark(&mut doc.html, id);
    }
    Page::close(&mut doc.html, None);
    let acceptance = match inputs {
        [one] => one
            .analysis
            .as_ref()
            .ok()
            .and_then(|a| a.acceptance.clone()),
        _ => None,
    };
    Ok(Report {
        html: doc.html,
        svgs: doc.svgs,
        warnings,
        acceptance,
    })
}

/// Where an input's verdict comes from, for the verdict box.
fn acceptance_source(input: &Input) -> String {
    input.acceptance_from.clone().unwrap_or_else(|| {
        "from the plan's <code>[acceptance]</code> section, evaluated when the run was fitted"
            .to_string()
    })
}

/// Runs of different plans given to one report.
pub(crate) struct PlansDiffer {
    /// Each run's plan hash (`None`: a bare CSV, plan unknown), in input order.
    hashes: Vec<Option<String>>,
}

impl PlansDiffer {
    fn distinct(&self) -> usize {
        let mut known: Vec<&str> = self.hashes.iter().flatten().map(String::as_str).collect();
        known.sort_unstable();
        known.dedup();
        known.len()
    }

    /// The sentence for stderr and the report.
    pub(crate) fn warning(&self) -> String {
        let runs: Vec<String> = self
            .hashes
            .iter()
            .enumerate()
            .map(|(i, h)| match h {
                Some(h) => format!("run {} plan {}", i + 1, h.get(..12).unwrap_or(h)),
                None => format!("run {} plan unknown (a CSV file)", i + 1),
            })
            .collect();
        format!(
            "the runs come from {} different plans ({}): the spread of their scale factors is \
             not the repeatability of one plan (different rates, readings or settings change K \
             as well as drift does)",
            self.distinct().max(2),
            runs.join(", ")
        )
    }
}

/// `Some` when the inputs do not all follow one plan (by plan hash). A bare CSV has no plan:
/// it differs only from nothing, and is named as unknown when run directories disagree.
fn plans_differ(inputs: &[Input]) -> Option<PlansDiffer> {
    let hashes: Vec<Option<String>> = inputs
        .iter()
        .map(|i| i.manifest.as_ref().map(|m| m.plan_hash.clone()))
        .collect();
    let d = PlansDiffer { hashes };
    (d.distinct() > 1).then_some(d)
}

/// The banner of a simulated run: it comes first, so that simulated numbers are never
/// mistaken for a calibration. In virtual time it explains why the run clock and the wall
/// clock disagree.
fn simulated_banner(html: &mut String, input: &Input, run: Option<usize>) {
    let Some(m) = &input.manifest else { return };
    if !m.simulated {
        return;
    }
    let which = run.map_or_else(String::new, |r| format!("Run {r}: "));
    let mut text = format!(
        "<strong>SIMULATED.</strong> {which}These data come from gyrocal's simulated bench (a \
         simulated rate table and multimeter with a modelled gyroscope), not from an instrument: \
         they calibrate nothing."
    );
    if m.virtual_time {
        let wall = match (
            gyrocal_files::parse_rfc3339_utc(&m.started_utc),
            m.ended_utc
                .as_deref()
                .and_then(gyrocal_files::parse_rfc3339_utc),
        ) {
            (Some(a), Some(b)) => b
                .duration_since(a)
                .ok()
                .map(|d| format!("{:.1} s", d.as_secs_f64())),
            _ => None,
        };
        let _ = write!(
            text,
            " It ran in <em>virtual time</em>: the simulation skipped every wait, so the run \
             clock counts the {:.1} s a real bench would have taken (the elapsed time, every \
             <code>t_s</code> and the <code>t_utc</code> times derived from it) while the \
             simulation itself took {} of wall-clock time (started to ended{}).",
            m.elapsed_s,
            wall.as_deref().unwrap_or("a fraction of that"),
            match m.resumes.len() {
                0 => String::new(),
                n => format!(", including the pauses between its {} sessions", n + 1),
            }
        );
    }
    let _ = writeln!(
        html,
        "<div class=\"banner simulated\" role=\"note\" id=\"simulated{}\">{text}</div>",
        suffix(run)
    );
}

fn suffix(run: Option<usize>) -> String {
    run.map_or_else(String::new, |r| format!("-run{r}"))
}

fn file_name(base: &str, run: Option<usize>) -> String {
    match run {
        Some(r) => format!("run{r}-{base}"),
        None => base.to_string(),
    }
}

fn banner(html: &mut String, input: &Input, run: Option<usize>) {
    let Some(m) = &input.manifest else { return };
    if m.status == Status::Complete {
        return;
    }
    let status = match m.status {
        Status::Running => "running (or the program stopped without closing the run)",
        Status::Complete => "complete",
        Status::Aborted => "aborted",
        Status::Failed => "failed",
    };
    let which = run.map_or_else(String::new, |r| format!("Run {r}: "));
    let _ = writeln!(
        html,
        "<div class=\"banner\" role=\"alert\" id=\"banner{}\">{which}INCOMPLETE RUN: status {status}{}. {} of {} steps done; every figure and number below uses only the finished steps.</div>",
        suffix(run),
        m.reason
            .as_deref()
            .map_or_else(String::new, |r| format!(": {}", esc(r))),
        m.steps_done.len(),
        m.steps_total,
    );
}

fn one(doc: &mut Doc, input: &Input, run: Option<usize>, cert: bool) -> Result<(), ReportError> {
    let sfx = suffix(run);
    let a = match &input.analysis {
        Ok(a) => Some(a),
        Err(e) => {
            let _ = writeln!(
                doc.html,
                "<h2 id=\"summary{sfx}\">Summary</h2>\n<p class=\"banner\">No fit: {}</p>",
                esc(e)
            );
            None
        }
    };
    if cert && let Some(m) = &input.manifest {
        certificate::conditions(&mut doc.html, m);
        certificate::instruments(&mut doc.html, m);
        certificate::deviations(&mut doc.html, input, m);
    }
    if let Some(a) = a {
        if cert {
            certificate::uncertainty(&mut doc.html, a);
        }
        summary(&mut doc.html, a, &sfx, input);
    }
    if let Some(a) = a {
        let _ = writeln!(doc.html, "<h2 id=\"fit{sfx}\">Fit</h2>");
        let best_rule = best_rule_text(a);
        doc.figure(
            file_name("fit.svg", run),
            plots::fit_plot(a)?,
            &format!(
                "Mean gyro output at each step against the applied rate, with the least-squares line, the neuron's line and the best model. {best_rule} At this scale the lines coincide; the residuals below show how they differ."
            ),
        );
        let _ = writeln!(doc.html, "<h2 id=\"residuals{sfx}\">Residuals</h2>");
        doc.figure(
            file_name("residuals.svg", run),
            plots::residuals_plot(a)?,
            "Residual (measured − fitted) of every fit against the rate, on one scale. Left axis in volts; right axis the same residual divided by the least-squares scale factor K, i.e. as an input-rate error. A bowl shape in the linear residuals (positive at both ends, negative in the middle) is an even-order nonlinearity that the quadratic model captures.",
        );
        residual_table(&mut doc.html, a, &sfx);
        estimators(&mut doc.html, a, &sfx);
        training_and_surface(doc, a, run)?;
    }
    let _ = writeln!(doc.html, "<h2 id=\"noise{sfx}\">Noise and rate table</h2>");
    if input.steps.iter().any(|s| s.volts_std.is_some()) {
        doc.figure(
            file_name("noise.svg", run),
            plots::noise_plot(&input.steps)?,
            "Standard deviation of the individual readings at each step against the rate. Growth with |rate| points at rate noise of the table or scale-factor noise; a flat line is the gyro's and the meter's own noise.",
        );
    } else {
        doc.html
            .push_str("<p class=\"note\">The data has no per-step standard deviation (volts_std): no noise plot.</p>\n");
    }
    if input.steps.iter().any(|s| s.rate_meas_dps.is_some()) {
        doc.figure(
            file_name("rate-error.svg", run),
            plots::rate_error_plot(&input.steps)?,
            "Mean rate the table measured during each acquisition minus the demanded rate, with ± its standard deviation during the step. This error enters the calibration as an error of the input.",
        );
    } else {
        doc.html.push_str("<p class=\"note\">The run did not record the table's measured rate: no rate-error plot.</p>\n");
    }
    metadata(&mut doc.html, input, &sfx);
    Ok(())
}

fn best_rule_text(a: &Analysis) -> String {
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

fn ls_linear(a: &Analysis) -> Option<&Fit> {
    a.fit(Method::LeastSquares, Model::Linear)
}

fn summary(html: &mut String, a: &Analysis, sfx: &str, input: &Input) {
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
    row(
        "k",
        "Scale factor K",
        format!("{:.7}", m.scale_factor),
        se_k.map(|s| format!("{s:.2e}")),
        "V/(°/s)",
        "least-squares line D = K·ω + K0".into(),
    );
    row(
        "k0",
        "Bias K0",
        format!("{:.6}", m.bias_volts),
        se_k0.map(|s| format!("{s:.2e}")),
        "V",
        "intercept of the same line".into(),
    );
    row(
        "nonlinearity",
        "Nonlinearity",
        format!("{:.1}", m.nonlinearity_ppm),
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
        opt(m.asymmetry_ppm, |v| format!("{v:.1}")),
        None,
        "ppm",
        format!("|K+ − K−| / ((K+ + K−)/2){}", why("asymmetry_ppm")),
    );
    row(
        "k-pos",
        "K+ (ω ≥ 0)",
        opt(m.scale_factor_positive, |v| format!("{v:.7}")),
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
        opt(m.scale_factor_negative, |v| format!("{v:.7}")),
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
        format!("{:.2}", m.bias_dph),
        None,
        "°/h",
        "K0 / K × 3600".into(),
    );
    row(
        "repeatability",
        "Repeatability",
        opt(m.repeatability_ppm, |v| format!("{v:.1}")),
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

fn residual_table(html: &mut String, a: &Analysis, sfx: &str) {
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

fn estimators(html: &mut String, a: &Analysis, sfx: &str) {
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
            "<tr{}><td>{}</td><td class=\"num\">{:.7}</td><td class=\"num\">{:.6}</td><td class=\"num\">{:.4e}</td><td class=\"num\">{:.4}</td><td class=\"num\">{:.4}</td><td class=\"num\">{}</td><td>{status}</td></tr>",
            if best { " class=\"best\"" } else { "" },
            plots::fit_name(f),
            f.scale_factor,
            f.bias,
            f.sse,
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
                    "The neuron reached the least-squares line: its SSE equals least squares' to rounding (relative difference {rel:.1e}). That is what a converged linear neuron must do, since the least-squares line is the minimum of this error; it is not better, only equal. "
                );
            } else {
                let _ = write!(
                    out,
                    "The neuron's SSE is <strong>larger</strong> than least squares' by {:.3} % ({:.4e} V² against {:.4e} V²): it stopped near, not at, the minimum. Least squares is the better estimate of the straight line. ",
                    rel * 100.0,
                    nn.sse,
                    ls.sse
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

fn training_and_surface(
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
                    " The neuron's result differs from the least-squares optimum by ΔK = {:.2e} V/(°/s) and ΔK0 = {:.2e} V.",
                    k - l.scale_factor,
                    k0 - l.bias
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

fn metadata(html: &mut String, input: &Input, sfx: &str) {
    let _ = writeln!(
        html,
        "<h2 id=\"metadata{sfx}\">Run</h2>\n<table class=\"metadata\">"
    );
    let mut row = |k: &str, v: String| {
        let _ = writeln!(html, "<tr><th>{k}</th><td>{v}</td></tr>");
    };
    row(
        "source",
        format!("<code>{}</code>", esc(&input.path.display().to_string())),
    );
    let Some(m) = &input.manifest else {
        row(
            "run metadata",
            "none: a bare CSV data set (give the run directory for the plan, instruments and times)".into(),
        );
        html.push_str("</table>\n");
        return;
    };
    let status = match m.status {
        Status::Running => "running",
        Status::Complete => "complete",
        Status::Aborted => "aborted",
        Status::Failed => "failed",
    };
    row("status", format!("<strong>{status}</strong>"));
    if let Some(r) = &m.reason {
        row("reason", esc(r));
    }
    row("plan", esc(m.plan.name()));
    row(
        "plan hash (SHA-256)",
        format!("<code>{}</code>", esc(&m.plan_hash)),
    );
    row(
        "steps",
        format!("{} of {} done", m.steps_done.len(), m.steps_total),
    );
    row(
        "multimeter",
        m.instruments.dmm.as_deref().map_or_else(|| "—".into(), esc),
    );
    row(
        "rate table",
        m.instruments
            .table
            .as_deref()
            .map_or_else(|| "—".into(), esc),
    );
    row("simulated", if m.simulated { "yes" } else { "no" }.into());
    row("started (UTC)", esc(&m.started_utc));
    row(
        "ended (UTC)",
        m.ended_utc.as_deref().map_or_else(|| "—".into(), esc),
    );
    let e = m.elapsed_s.max(0.0);
    row(
        if m.virtual_time {
            "elapsed (run clock, virtual)"
        } else {
            "elapsed (run clock)"
        },
        format!(
            "{e:.1} s ({}:{:02}:{:02})",
            (e / 3600.0).floor(),
            ((e % 3600.0) / 60.0).floor(),
            (e % 60.0).floor()
        ),
    );
    if let Some(t) = &m.timing {
        row(
            "timing",
            format!(
                "schedule {:.1} s (first demand to the stop command; the elapsed time adds \
                 connecting before it and the table's stop after it), physical bound {:.1} s, \
                 schedule / bound = {:.3}{}",
                t.elapsed_s,
                t.bound_s,
                t.ratio,
                t.acquisition
                    .as_deref()
                    .map_or_else(String::new, |a| format!(", acquisition {}", esc(a)))
            ),
        );
    }
    row("gyrocal version", esc(&m.gyrocal_version));
    let resumes = if m.resumes.is_empty() {
        "0".to_string()
    } else {
        let list: Vec<String> = m
            .resumes
            .iter()
            .map(|r| {
                format!(
                    "<li>{}: from step {}, {} steps kept, {} samples dropped; previous status {:?}{}</li>",
                    esc(&r.at_utc),
                    r.from_step.map_or_else(|| "—".into(), |s| s.to_string()),
                    r.steps_done,
                    r.samples_dropped,
                    r.previous_status,
                    r.previous_reason
                        .as_deref()
                        .map_or_else(String::new, |p| format!(" ({})", esc(p)))
                )
            })
            .collect();
        format!("{}<ul>{}</ul>", m.resumes.len(), list.concat())
    };
    row("resumes", resumes);
    let retries = if m.retries.is_empty() {
        "0".to_string()
    } else {
        let list: Vec<String> = m
            .retries
            .iter()
            .take(50)
            .map(|r| {
                format!(
                    "<li>t = {:.1} s, step {}, {}: {}</li>",
                    r.t_s,
                    // the plan's step number, as the run's display said it
                    r.step.map_or_else(|| "—".into(), |s| (s + 1).to_string()),
                    esc(&r.instrument),
                    esc(&r.message)
                )
            })
            .collect();
        let more = if m.retries.len() > 50 {
            format!("<li>… and {} more</li>", m.retries.len() - 50)
        } else {
            String::new()
        };
        format!("{}<ul>{}{more}</ul>", m.retries.len(), list.concat())
    };
    row("retries", retries);
    html.push_str("</table>\n");
}

fn repeatability(
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
                    "<tr><td class=\"num\">{}</td><td><code>{}</code></td><td class=\"num\">{:.7}</td><td class=\"num\">{}</td><td class=\"num\">{:.6}</td><td>{status}</td></tr>",
                    i + 1,
                    esc(&input.path.display().to_string()),
                    a.metrics.scale_factor,
                    opt(se, |s| format!("{s:.2e}")),
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
