//! The calibration report's document on the shared [`crate::page`] skeleton and stylesheet:
//! inline SVG, tables. Every string that came from a file goes through [`esc`].

use std::fmt::Write as _;

mod banners;
mod figures;
mod metadata;
mod repeatability;
mod summary;

use banners::{banner, identification, plans_differ, simulated_banner};
use figures::training_and_surface;
use metadata::metadata;
use repeatability::repeatability;
use summary::{best_rule_text, estimators, residual_table, summary};

use crate::input::Input;
use crate::page::Page;
/// The one escaper ([`crate::page::esc`]), for the report's sections.
pub(crate) use crate::page::esc;
use crate::{Report, ReportError, certificate, plots};

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
        .with_sub(format!(
            "{} · gyrocal-report {}",
            esc(&title),
            env!("CARGO_PKG_VERSION")
        ))
        .with_css(page_css)
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

fn suffix(run: Option<usize>) -> String {
    run.map_or_else(String::new, |r| format!("-run{r}"))
}

fn file_name(base: &str, run: Option<usize>) -> String {
    match run {
        Some(r) => format!("run{r}-{base}"),
        None => base.to_string(),
    }
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
            "Residual (measured − fitted) of every fit against the rate, on one scale. Left axis in the unit its title names (V, mV or µV); right axis the same residual divided by the least-squares scale factor K, i.e. as an input-rate error. A bowl shape in the linear residuals (positive at both ends, negative in the middle) is an even-order nonlinearity that the quadratic model captures.",
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
