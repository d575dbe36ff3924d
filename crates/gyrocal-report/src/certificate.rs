//! The certificate part of a single run's report (ISO/IEC 17025 §7.8, see
//! `shared/docs/records.md`): a unique report id on every printed page with "page x of y",
//! the laboratory, customer and gyro identified on the first page with the verdict, the
//! method and the test conditions, the environment, the instruments that make the result
//! traceable, the deviations from the method, the statement that the results relate only to
//! the item calibrated, the signature lines and a clear end of report.
//!
//! Why local time: a certificate is read by people at the lab, who date their records in
//! local time; the UTC offset is printed beside every time so it stays unambiguous. The run
//! directory keeps UTC (the source of truth); only the rendering converts.

use std::fmt::Write as _;

use gyrocal_files::num::{significant, value_and_u};
use gyrocal_files::{Manifest, Plan};
use gyrocal_fit::acceptance::{Acceptance, Check, Quantity, Verdict};
use gyrocal_fit::display::{metric_words, plain, quantity_words, value_pm_u};
use gyrocal_fit::{Analysis, Method, Model};

use crate::input::Input;
use crate::page::esc;

/// Prefix of report ids.
const REPORT_ID_PREFIX: &str = "GC";

/// The report's unique identification: `GC-` and 12 hex digits of a SHA-256 over what the
/// report states (the plan hash, the run's start, the gyro's serial, the data files' checksums
/// and `extra`: the acceptance limits applied). The same run and limits give the same id;
/// any change to them, a new id — so two different reports never share one.
pub(crate) fn report_id(m: &Manifest, extra: &str) -> String {
    let mut text = String::new();
    let _ = write!(
        text,
        "{}\n{}\n{}\n",
        m.plan_hash,
        m.started_utc,
        m.dut
            .as_ref()
            .and_then(|d| d.serial.as_deref())
            .unwrap_or("")
    );
    for (name, sum) in &m.checksums {
        let _ = writeln!(text, "{name} {sum}");
    }
    if let Some(f) = &m.fit_summary {
        let _ = writeln!(text, "fit {}", f.sha256);
    }
    text.push_str(extra);
    let hash = gyrocal_files::rundir::sha256_hex(text.as_bytes());
    format!("{REPORT_ID_PREFIX}-{}", hash.get(..12).unwrap_or(&hash))
}

/// A time as the reader's clock shows it: `2026-11-23 20:45:02 +01:00 (CET)`. `utc` is what
/// the manifest holds (RFC 3339); text that is not a time is shown as written.
pub(crate) fn local(utc: &str) -> String {
    local_in(utc, jiff::tz::TimeZone::system())
}

fn local_in(utc: &str, tz: jiff::tz::TimeZone) -> String {
    match utc.parse::<jiff::Timestamp>() {
        Ok(t) => local_zoned(&t.to_zoned(tz)),
        Err(_) => utc.to_string(),
    }
}

fn local_zoned(z: &jiff::Zoned) -> String {
    z.strftime("%Y-%m-%d %H:%M:%S %:z (%Z)").to_string()
}

/// The time of issue: now, in local time.
pub(crate) fn issued_now() -> String {
    local_zoned(&jiff::Zoned::now())
}

/// Print layout: A4, the report id top left, "Page x of y" bottom right (CSS page-margin
/// boxes with the `pages` counter, which Chromium prints).
pub(crate) fn page_css(id: &str) -> String {
    // the id is hex and a dash; escape quotes anyway, it goes into a CSS string
    let id = id.replace(['"', '\\'], "");
    format!(
        "@page {{ size: A4; margin: 16mm 14mm 18mm;\n  @top-left {{ content: \"Calibration report {id}\"; font-size: 8pt; color: #333; }}\n  @top-right {{ content: \"gyrocal\"; font-size: 8pt; color: #333; }}\n  @bottom-right {{ content: \"Page \" counter(page) \" of \" counter(pages); font-size: 8pt; }}\n  @bottom-left {{ content: \"{id}\"; font-size: 8pt; }} }}\n"
    )
}

/// One row of a two-column table, skipped when the value is absent.
fn row(html: &mut String, key: &str, value: Option<String>) {
    if let Some(v) = value {
        let _ = writeln!(html, "<tr><th>{key}</th><td>{v}</td></tr>");
    }
}

/// The first lines of the certificate: id, laboratory, customer, the gyro, the method and the
/// dates. Everything from a file is escaped.
pub(crate) fn head(html: &mut String, input: &Input, m: &Manifest, id: &str, issued: &str) {
    let _ = writeln!(
        html,
        "<table class=\"cert\" id=\"cert-head\">\n<tr><th>Report id</th><td><strong id=\"report-id\">{}</strong></td></tr>",
        esc(id)
    );
    if let Some(st) = &m.station {
        row(
            html,
            "Laboratory",
            Some(format!(
                "<strong id=\"lab\">{}</strong>, {}; station {}",
                esc(&st.lab),
                esc(&st.address),
                esc(&st.id)
            )),
        );
    }
    let ctx = m.context.as_ref();
    row(
        html,
        "Customer",
        Some(
            ctx.and_then(|c| c.customer.as_deref())
                .map_or_else(|| "not named".to_string(), esc),
        ),
    );
    let dut = m.dut.clone().unwrap_or_default();
    let mut item = Vec::new();
    if let Some(s) = &dut.manufacturer {
        item.push(esc(s));
    }
    if let Some(s) = &dut.model {
        item.push(format!("model {}", esc(s)));
    }
    item.push(match &dut.serial {
        Some(s) => format!("serial <strong id=\"dut-serial\">{}</strong>", esc(s)),
        None => "<strong>serial not given</strong> (plan <code>[dut]</code> or --dut-serial)"
            .to_string(),
    });
    row(html, "Item calibrated", Some(item.join(", ")));
    row(html, "Condition", dut.condition.as_deref().map(esc));
    row(html, "Notes", dut.notes.as_deref().map(esc));
    row(
        html,
        "Method",
        Some(format!(
            "rate-table scale-factor calibration, plan “{}” (SHA-256 <code>{}</code>), gyrocal {}",
            esc(m.plan.name()),
            esc(m.plan_hash.get(..16).unwrap_or(&m.plan_hash)),
            esc(&m.gyrocal_version)
        )),
    );
    let performed = match &m.ended_utc {
        Some(end) => format!("{} to {}", esc(&local(&m.started_utc)), esc(&local(end))),
        None => format!("from {} (not ended)", esc(&local(&m.started_utc))),
    };
    row(html, "Performed", Some(performed));
    row(html, "Issued", Some(esc(issued)));
    row(
        html,
        "Operator",
        ctx.and_then(|c| c.operator.as_deref()).map(esc),
    );
    row(
        html,
        "Run directory",
        Some(format!(
            "<code>{}</code>",
            esc(&input.path.display().to_string())
        )),
    );
    html.push_str("</table>\n");
}

/// The environment as entered (`--ambient-c`, `--humidity-pct`): not measured by gyrocal.
pub(crate) fn environment(m: &Manifest) -> String {
    let ctx = m.context.as_ref();
    let mut parts = Vec::new();
    if let Some(t) = ctx.and_then(|c| c.ambient_c) {
        parts.push(format!("ambient {t} °C"));
    }
    if let Some(h) = ctx.and_then(|c| c.humidity_pct) {
        parts.push(format!("{h} % RH"));
    }
    if parts.is_empty() {
        "not recorded".to_string()
    } else {
        format!("{} (as entered, not measured by gyrocal)", parts.join(", "))
    }
}

/// Every plan setting that affects the measurement.
pub(crate) fn conditions(html: &mut String, m: &Manifest) {
    let p: &Plan = &m.plan;
    let t = p.table();
    let d = p.dmm();
    let _ = writeln!(
        html,
        "<h2 id=\"conditions\">Test conditions</h2>\n<table class=\"cert\" id=\"conditions-table\">"
    );
    let rates: Vec<String> = p.rates_dps().iter().map(|r| format!("{r}")).collect();
    row(
        html,
        "Rates applied",
        Some(format!(
            "{} °/s ({} rates × {} pass{} = {} steps)",
            rates.join(", "),
            rates.len(),
            p.repeat(),
            if p.repeat() == 1 { "" } else { "es" },
            p.step_count()
        )),
    );
    row(
        html,
        "Readings per rate",
        Some(if p.whole_revolutions() > 0 {
            format!(
                "{} (at least; whole table turns: {} per non-zero rate)",
                p.samples_per_rate(),
                p.whole_revolutions()
            )
        } else {
            p.samples_per_rate().to_string()
        }),
    );
    row(
        html,
        "Settle after at-rate",
        Some(format!("{} s", p.settle().as_secs_f64())),
    );
    row(
        html,
        "Rate table",
        Some(format!(
            "{} dialect; acceleration {} °/s²; at-rate tolerance ±{} °/s held for {} s (timeout {} s); rate limit {} °/s",
            esc(t.dialect.as_str()),
            t.acceleration_dps2,
            t.rate_tolerance_dps,
            t.stability_window.as_secs_f64(),
            t.at_rate_timeout.as_secs_f64(),
            t.max_rate_dps
        )),
    );
    row(
        html,
        "Multimeter",
        Some(format!(
            "{}; DC voltage, {} V range; {} NPLC at {} Hz mains; autozero {}; acquisition {}",
            esc(d.model.as_str()),
            d.range_v,
            d.nplc,
            d.line_hz,
            if d.autozero { "on" } else { "off" },
            esc(d.acquisition.as_str())
        )),
    );
    row(html, "Environment", Some(esc(&environment(m))));
    html.push_str("</table>\n");
}

/// The instruments used: as they identified themselves, and with the station file's
/// records (asset id, serial, calibration certificate and dates, accuracy class), which make
/// the result traceable. Without a station file the report says so. A run with a chamber (a
/// temperature series) lists it too, from the station's
/// `[chamber]`: the gyro's temperatures the results are stated at were read through its
/// controller, so the certificate names it and its calibration.
pub(crate) fn instruments(html: &mut String, m: &Manifest) {
    let _ = writeln!(html, "<h2 id=\"instruments\">Instruments</h2>");
    // a series' chamber, as it identified itself (none yet: a series stopped before it)
    let chamber_id = m.chamber.as_ref().and_then(|c| c.identity.clone());
    let chamber_identity =
        (m.chamber.is_some() || m.plan.chamber().is_some()).then_some(&chamber_id);
    let Some(st) = &m.station else {
        html.push_str("<table class=\"cert\" id=\"instruments-table\">\n<tr><th>Role</th><th>Identity (as reported)</th></tr>\n");
        let chamber = chamber_identity.map(|id| ("Thermal chamber", id));
        for (role, id) in [
            ("Multimeter", &m.instruments.dmm),
            ("Rate table", &m.instruments.table),
        ]
        .into_iter()
        .chain(chamber)
        {
            let _ = writeln!(
                html,
                "<tr><td>{role}</td><td>{}</td></tr>",
                id.as_deref().map_or_else(|| "—".into(), esc)
            );
        }
        html.push_str("</table>\n<p class=\"note\" id=\"instruments-not-identified\">Instruments not identified: no station file gave their asset ids, serial numbers and calibration certificates, so this report does not establish traceability.</p>\n");
        return;
    };
    html.push_str("<table class=\"cert\" id=\"instruments-table\">\n<tr><th>Role</th><th>Model</th><th>Asset id</th><th>Serial</th><th>Calibration certificate</th><th>Calibrated</th><th>Due</th><th>Accuracy</th><th>Identity (as reported)</th></tr>\n");
    let chamber = chamber_identity.map(|id| ("Thermal chamber", st.chamber.as_ref(), id));
    for (role, record, reported) in [
        ("Multimeter", st.multimeter.as_ref(), &m.instruments.dmm),
        ("Rate table", st.table.as_ref(), &m.instruments.table),
    ]
    .into_iter()
    .chain(chamber)
    {
        // an identity breaks after its commas, not inside a model name
        let reported = reported
            .as_deref()
            .map_or_else(|| "—".into(), |r| esc(r).replace(',', ",<wbr>"));
        match record {
            Some(r) => {
                let mut acc = Vec::new();
                if let Some(p) = r.accuracy {
                    acc.push(format!("DC V {} specification", esc(p.as_str())));
                }
                if let (Some(g), Some(o)) = (r.gain_pct, r.offset_pct) {
                    acc.push(format!("{g} % of reading + {o} % of range"));
                }
                if let Some(ppm) = r.rate_accuracy_ppm {
                    acc.push(format!("rate {ppm} ppm"));
                }
                let _ = writeln!(
                    html,
                    "<tr><td>{role}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{reported}</td></tr>",
                    esc(&r.model),
                    esc(&r.asset_id),
                    esc(&r.serial),
                    esc(&r.certificate),
                    r.calibrated,
                    r.due,
                    if acc.is_empty() {
                        "—".to_string()
                    } else {
                        acc.join("; ")
                    },
                );
            }
            None => {
                let _ = writeln!(
                    html,
                    "<tr><td>{role}</td><td colspan=\"7\"><strong>not in the station file</strong>: not identified</td><td>{reported}</td></tr>"
                );
            }
        }
    }
    html.push_str("</table>\n");
}

/// The deviations from the method: those recorded during the run, then those the record
/// shows (resumes, retries, models not fitted, an incomplete or simulated run).
pub(crate) fn deviations(html: &mut String, input: &Input, m: &Manifest) {
    let mut items: Vec<String> = m
        .deviations
        .iter()
        .map(|d| format!("{} ({})", esc(&d.text), esc(&local(&d.at_utc))))
        .collect();
    if m.simulated {
        items.push(
            "<strong>SIMULATED</strong>: the data come from gyrocal's simulated bench, not from instruments"
                .into(),
        );
    }
    if m.status != gyrocal_files::Status::Complete {
        items.push(format!(
            "incomplete run: {} of {} steps done",
            m.steps_done.len(),
            m.steps_total
        ));
    }
    if !m.resumes.is_empty() {
        items.push(format!(
            "the run was interrupted and resumed {} time{} (steps already recorded were kept, partial steps measured again)",
            m.resumes.len(),
            if m.resumes.len() == 1 { "" } else { "s" }
        ));
    }
    if !m.retries.is_empty() {
        items.push(format!(
            "{} instrument exchange{} retried (listed under Run)",
            m.retries.len(),
            if m.retries.len() == 1 {
                " was"
            } else {
                "s were"
            }
        ));
    }
    if let Ok(a) = &input.analysis {
        for s in &a.skipped {
            items.push(format!(
                "model {} not fitted: {}",
                esc(s.model.name()),
                esc(&s.reason)
            ));
        }
    }
    let _ = writeln!(html, "<h2 id=\"deviations\">Deviations</h2>");
    if items.is_empty() {
        html.push_str("<p id=\"deviations-list\">None.</p>\n");
    } else {
        let _ = writeln!(
            html,
            "<ul id=\"deviations-list\">\n<li>{}</li>\n</ul>",
            items.join("</li>\n<li>")
        );
    }
}

/// The verdict box of the first page: the run's verdict, the quantities that make it, and the
/// decision rule; or why there is none.
pub(crate) fn verdict_box(html: &mut String, acceptance: Option<&Acceptance>, source: &str) {
    let Some(acc) = acceptance else {
        html.push_str("<div class=\"verdict verdict-none\" id=\"acceptance-verdict\"><strong>No verdict</strong>: no acceptance limits were given (a plan's <code>[acceptance]</code> section, or <code>gyrocal report RUN --acceptance FILE</code>).</div>\n");
        return;
    };
    let deciding: Vec<String> = acc
        .deciding()
        .map(|c| {
            let mut t = format!("<strong>{}</strong>", esc(&check_label(c)));
            if let Some(r) = &c.reason {
                let _ = write!(t, " ({})", esc(r));
            }
            t
        })
        .collect();
    let what = match acc.verdict {
        Verdict::Pass => format!(
            "all {} quantit{} within the limits",
            acc.checks.len(),
            if acc.checks.len() == 1 { "y" } else { "ies" }
        ),
        Verdict::Fail => format!("outside the limits: {}", deciding.join("; ")),
        Verdict::Marginal => format!(
            "inside the limits but outside the marginal band: {}",
            deciding.join("; ")
        ),
        Verdict::Indeterminate => format!("cannot be decided: {}", deciding.join("; ")),
    };
    let _ = writeln!(
        html,
        "<div class=\"verdict verdict-{}\" id=\"acceptance-verdict\"><span class=\"verdict-word\">Verdict: {}</span> — {what}. Decision rule: <strong>{}</strong> ({}). Limits {}.</div>",
        acc.verdict.as_str(),
        acc.verdict.label(),
        acc.rule.as_str(),
        esc(acc.rule.description()),
        source
    );
}

/// A quantity's name for people, from the one table of display names
/// ([`gyrocal_fit::display::QUANTITIES`]): the asymmetries name their figure, as the results
/// table does.
pub(crate) fn quantity_label(q: Quantity) -> String {
    q.title()
}

/// A check's quantity for people. A check recorded before checks named their figure judged
/// the GJB two-line figure under `asymmetry_ppm`, and is labelled so.
pub(crate) fn check_label(c: &Check) -> String {
    match (c.quantity, &c.figure) {
        (Quantity::AsymmetryPpm, None) => {
            "asymmetry (GJB two lines: recorded when asymmetry_ppm limited that figure)".into()
        }
        (q, _) => quantity_label(q),
    }
}

/// The acceptance table: every limited quantity with its value, U, limits and verdict.
pub(crate) fn acceptance_table(html: &mut String, acceptance: Option<&Acceptance>) {
    let Some(acc) = acceptance else {
        return;
    };
    let _ = writeln!(
        html,
        "<table class=\"cert\" id=\"acceptance-table\">\n<caption>Acceptance: decision rule {}</caption>\n<tr><th>Quantity</th><th>Value</th><th>U (k = 2)</th><th>Unit</th><th>Limits</th><th>Marginal band</th><th>Verdict</th></tr>",
        acc.rule.as_str()
    );
    for c in &acc.checks {
        let q = c.quantity.name();
        let (v, u) = match (c.value, c.interval) {
            (Some(v), Some(i)) => (value_and_u(v, c.expanded_uncertainty).0, interval_text(i)),
            (Some(v), None) => value_and_u(v, c.expanded_uncertainty),
            (None, _) => ("not measured".to_string(), "—".to_string()),
        };
        // limits as the specification wrote them (shortest form: 0.35, not 0.3500000)
        let range = |lo: Option<f64>, hi: Option<f64>| match (lo, hi) {
            (None, None) => "—".to_string(),
            (Some(a), None) => format!("≥ {}", plain(a)),
            (None, Some(b)) => format!("≤ {}", plain(b)),
            (Some(a), Some(b)) => format!("{} to {}", plain(a), plain(b)),
        };
        let reason = c.reason.as_deref().map_or_else(String::new, |r| {
            format!("<br><span class=\"note\">{}</span>", esc(r))
        });
        let _ = writeln!(
            html,
            "<tr><td>{}</td><td class=\"num\" id=\"acc-{q}\">{v}</td><td class=\"num\">{u}</td><td>{}</td><td>{}</td><td>{}</td><td id=\"acc-{q}-verdict\" class=\"v-{}\"><strong>{}</strong>{reason}</td></tr>",
            esc(&check_label(c)),
            esc(&c.unit),
            range(c.min, c.max),
            range(c.marginal_min, c.marginal_max),
            c.verdict.as_str(),
            c.verdict.label()
        );
    }
    html.push_str("</table>\n");
}

/// The results of the first page: each reported quantity with its unit and expanded
/// uncertainty (k = 2), the unbiased asymmetry beside the GJB figure, and the model chosen.
pub(crate) fn results(html: &mut String, a: &Analysis) {
    let m = &a.metrics;
    let unc = a.uncertainty.as_ref();
    html.push_str("<table class=\"cert results\" id=\"results\">\n<caption>Results (U: expanded uncertainty, k = 2, about 95 % coverage)</caption>\n<tr><th>Quantity</th><th>Value</th><th>U (k = 2)</th><th>Unit</th><th>Note</th></tr>\n");
    let mut row = |key: &str,
                   name: &str,
                   v: Option<f64>,
                   u: Option<f64>,
                   unit: &str,
                   note: String| {
        let (vs, us) = match v {
            Some(v) => value_and_u(v, u),
            None => ("—".to_string(), "—".to_string()),
        };
        let _ = writeln!(
            html,
            "<tr><td>{name}</td><td class=\"num\" id=\"res-{key}\">{vs}</td><td class=\"num\" id=\"res-{key}-u\">{us}</td><td>{unit}</td><td class=\"note\">{note}</td></tr>"
        );
    };
    let q = |key: &str| unc.and_then(|u| u.quantity(key));
    let value = |key: &str, fallback: Option<f64>| q(key).map(|x| x.value).or(fallback);
    let expanded = |key: &str| q(key).map(|x| x.expanded_uncertainty);
    row(
        "scale_factor",
        "Scale factor K",
        value("scale_factor", Some(m.scale_factor)),
        expanded("scale_factor"),
        "V/(°/s)",
        "line D = K·ω + K0".into(),
    );
    row(
        "bias_v",
        "Bias K0",
        value("bias_v", Some(m.bias_volts)),
        expanded("bias_v"),
        "V",
        "intercept of that line".into(),
    );
    row(
        "bias_dph",
        "Bias as a rate",
        value("bias_dph", Some(m.bias_dph)),
        expanded("bias_dph"),
        "°/h",
        "K0/K, incl. the Earth rate".into(),
    );
    row(
        "k_pos",
        "K+ (ω ≥ 0)",
        value("k_pos", m.scale_factor_positive),
        expanded("k_pos"),
        "V/(°/s)",
        "ω ≥ 0 line (GJB)".into(),
    );
    row(
        "k_neg",
        "K− (ω ≤ 0)",
        value("k_neg", m.scale_factor_negative),
        expanded("k_neg"),
        "V/(°/s)",
        "ω ≤ 0 line (GJB)".into(),
    );
    let metric_u = |key: &str| {
        unc.and_then(|u| u.metrics.entries.iter().find(|e| e.metric == key))
            .map(|e| e.expanded_uncertainty)
    };
    row(
        "nonlinearity_ppm",
        "Nonlinearity",
        Some(m.nonlinearity_ppm),
        metric_u("nonlinearity_ppm"),
        "ppm",
        "max |residual| / max |output|".into(),
    );
    match &m.asymmetry_common_k2 {
        Some(c) => row(
            "asymmetry_common_k2",
            "Asymmetry (common K2)",
            Some(c.asymmetry_ppm),
            metric_u("asymmetry_common_k2").or(Some(2.0 * c.asymmetry_std_error_ppm)),
            "ppm",
            format!(
                "one fit with K2: unbiased; the result (acceptance key asymmetry_ppm){}",
                few_dof(c.degrees_of_freedom)
            ),
        ),
        None => row(
            "asymmetry_common_k2",
            "Asymmetry (common K2)",
            None,
            None,
            "ppm",
            "not computed".into(),
        ),
    }
    row(
        "asymmetry_ppm",
        "Asymmetry (GJB)",
        m.asymmetry_ppm,
        metric_u("asymmetry_ppm"),
        "ppm",
        "two lines: absorbs K2·ω² (acceptance key asymmetry_gjb_ppm)".into(),
    );
    let quad = a.fit(Method::LeastSquares, Model::Quadratic);
    row(
        "k2",
        "Second-order coefficient K2",
        quad.and_then(|f| f.coefficients.k2),
        metric_u("k2").or_else(|| quad.and_then(|f| f.std_errors.k2).map(|s| 2.0 * s)),
        "V/(°/s)²",
        "quadratic fit; U = 2σ".into(),
    );
    if let Some(r) = m.repeatability_ppm {
        row(
            "repeatability_ppm",
            "Repeatability",
            Some(r),
            metric_u("repeatability_ppm"),
            "ppm",
            "std(K per pass)/mean".into(),
        );
    }
    html.push_str("</table>\n");
    let chosen = match (&a.model_selection, a.best_model) {
        (Some(sel), _) => format!(
            "Model chosen: <strong>{}</strong>, the simplest model whose added terms are significant ({} at the {} level).",
            sel.chosen,
            esc(&sel.method),
            sel.level
        ),
        (None, Some(b)) => format!("Best model: <strong>{b}</strong>."),
        (None, None) => {
            "No model choice: no least-squares model had degrees of freedom left.".into()
        }
    };
    let _ = writeln!(html, "<p class=\"note\" id=\"model-choice\">{chosen}</p>");
}

/// The uncertainty budget: the method in words, then one table per quantity.
pub(crate) fn uncertainty(html: &mut String, a: &Analysis) {
    let _ = writeln!(html, "<h2 id=\"uncertainty\">Measurement uncertainty</h2>");
    let Some(u) = &a.uncertainty else {
        html.push_str("<p class=\"note\">No uncertainty budget: the fit was stored by an earlier gyrocal version.</p>\n");
        return;
    };
    let _ = writeln!(
        html,
        "<p class=\"note\" id=\"uncertainty-method\">{}. Coverage factor k = {}.</p>",
        esc(&u.method),
        u.coverage_factor
    );
    for q in &u.quantities {
        let figure = value_pm_u(q.value, Some(q.expanded_uncertainty), &q.unit);
        let (name, _) = quantity_words(&q.quantity);
        let _ = writeln!(
            html,
            "<table class=\"budget\" id=\"budget-{}\">\n<caption>{} = {} (k = {}){}{}</caption>\n<tr><th>Source</th><th>Type</th><th>Distribution</th><th>Stated</th><th>Divisor</th><th>Sensitivity</th><th>Standard uncertainty ({})</th><th>Relative (ppm)</th><th>ν</th></tr>",
            esc(&q.quantity),
            esc(&capitalised(&name)),
            esc(&figure),
            u.coverage_factor,
            q.relative_expanded_ppm
                .map_or_else(String::new, |r| format!(", {} ppm", significant(r, 3))),
            q.effective_degrees_of_freedom
                .map_or_else(String::new, |d| format!(
                    ", ν<sub>eff</sub> = {}",
                    significant(d, 3)
                )),
            esc(&q.unit),
        );
        for r in &q.rows {
            let _ = writeln!(
                html,
                "<tr><td>{}</td><td>{}</td><td>{}</td><td class=\"num\">{} {}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td></tr>",
                esc(&r.source),
                esc(&format!("{:?}", r.kind)),
                esc(&format!("{:?}", r.distribution).to_lowercase()),
                significant(r.stated, 4),
                esc(&r.stated_unit),
                significant(r.divisor, 4),
                significant(r.sensitivity, 4),
                significant(r.standard_uncertainty, 3),
                r.relative_ppm
                    .map_or_else(|| "—".into(), |x| significant(x, 3)),
                r.degrees_of_freedom
                    .map_or_else(|| "∞".into(), |x| significant(x, 3)),
            );
        }
        let _ = writeln!(
            html,
            "<tr class=\"combined\"><td colspan=\"6\"><strong>Combined standard uncertainty (root-sum-of-squares)</strong></td><td class=\"num\"><strong>{}</strong></td><td></td><td></td></tr>\n</table>",
            significant(q.standard_uncertainty, 3)
        );
    }
    metric_budget(html, u);
    if !u.not_included.is_empty() {
        let _ = writeln!(
            html,
            "<p class=\"note\" id=\"uncertainty-not-included\">Not included in the budget: {}.</p>",
            u.not_included
                .iter()
                .map(|s| esc(s))
                .collect::<Vec<_>>()
                .join("; ")
        );
    }
}

/// `s` with its first letter in capitals, as a table's first column or a caption begins.
fn capitalised(s: &str) -> String {
    let mut c = s.chars();
    c.next()
        .map(|f| f.to_uppercase().chain(c).collect())
        .unwrap_or_default()
}

/// A coverage interval that is not `value ± U`, for the U column.
fn interval_text([lo, hi]: [f64; 2]) -> String {
    format!(
        "95 % interval {} .. {}",
        significant(lo, 3),
        significant(hi, 3)
    )
}

/// The metrics' uncertainties: each one's value, U and the method that gave it (analytic or
/// Monte Carlo), and the metrics without one with the reason. A verdict under the guarded
/// rule uses exactly these figures.
fn metric_budget(html: &mut String, u: &gyrocal_fit::Uncertainty) {
    let m = &u.metrics;
    if m.entries.is_empty() && m.not_available.is_empty() {
        return;
    }
    let _ = writeln!(
        html,
        "<table class=\"budget\" id=\"budget-metrics\">\n<caption>Metrics: expanded uncertainty (k = {}) and how it was evaluated</caption>\n<tr><th>Metric</th><th>Value</th><th>U (k = {})</th><th>Unit</th><th>Method</th><th>From</th></tr>",
        u.coverage_factor, u.coverage_factor
    );
    for e in &m.entries {
        let (v, mut uu) = value_and_u(e.value, Some(e.expanded_uncertainty));
        if let Some(i) = e.interval {
            uu = interval_text(i);
        }
        let method = if e.method.is_empty() {
            "not recorded (an earlier gyrocal version)"
        } else {
            e.method.as_str()
        };
        let _ = writeln!(
            html,
            "<tr id=\"budget-metric-{}\"><td>{}</td><td class=\"num\">{v}</td><td class=\"num\">{uu}</td><td>{}</td><td>{}</td><td class=\"note\">{}</td></tr>",
            esc(&e.metric),
            esc(&capitalised(&metric_words(&e.metric).0)),
            esc(&e.unit),
            esc(method),
            esc(&e.from)
        );
    }
    for n in &m.not_available {
        let _ = writeln!(
            html,
            "<tr id=\"budget-metric-{}\"><td>{}</td><td>—</td><td>—</td><td></td><td colspan=\"2\" class=\"note\">no uncertainty: {}</td></tr>",
            esc(&n.metric),
            esc(&capitalised(&metric_words(&n.metric).0)),
            esc(&n.reason)
        );
    }
    html.push_str("</table>\n");
}

/// The closing statements and the signature lines.
pub(crate) fn closing(html: &mut String) {
    html.push_str(
        "<p class=\"statement\" id=\"statement\">The results relate only to the item calibrated. This report shall not be reproduced except in full without the written approval of the laboratory.</p>\n\
         <table class=\"signatures\" id=\"signatures\">\n<tr><th>Prepared by</th><td></td><th>Date</th><td></td></tr>\n<tr><th>Approved by</th><td></td><th>Date</th><td></td></tr>\n</table>\n",
    );
}

/// The end-of-report mark.
pub(crate) fn end_mark(html: &mut String, id: &str) {
    let _ = writeln!(
        html,
        "<p class=\"end\" id=\"end-of-report\">— End of report {} —</p>",
        esc(id)
    );
}

/// What the certificate and the terminal say beside the common-K2 asymmetry when its fit has
/// fewer than [`gyrocal_analysis::sweep::MIN_ASYMMETRY_DOF`] degrees of freedom (the warning
/// `gyrocal check` gives before such a run), else nothing.
pub(crate) fn few_dof(dof: usize) -> String {
    if dof < gyrocal_analysis::sweep::MIN_ASYMMETRY_DOF {
        format!(
            "; only {dof} degree{} of freedom: too few residuals for this figure and its U to be trusted",
            if dof == 1 { "" } else { "s" }
        )
    } else {
        String::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_asymmetry_check_names_the_figure_it_judged() {
        use gyrocal_fit::acceptance::{Limits, Measured, Rule, check};
        let limits = Limits {
            max: Some(500.0),
            ..Limits::default()
        };
        let c = check(
            Rule::Guarded,
            Quantity::AsymmetryPpm,
            &limits,
            Measured::new(15.0, 131.0),
        );
        assert_eq!(check_label(&c), "asymmetry (common K2, unbiased)");
        let g = check(
            Rule::Guarded,
            Quantity::AsymmetryGjbPpm,
            &limits,
            Measured::new(2098.0, 300.0),
        );
        assert!(check_label(&g).contains("GJB"));
        // a check recorded before checks named their figure judged the GJB figure
        let old = Check { figure: None, ..c };
        assert!(check_label(&old).starts_with("asymmetry (GJB two lines"));
        let mut html = String::new();
        acceptance_table(
            &mut html,
            Some(&Acceptance {
                verdict: Verdict::Fail,
                rule: Rule::Guarded,
                checks: vec![old, g],
            }),
        );
        assert!(
            html.contains("recorded when asymmetry_ppm limited that figure"),
            "{html}"
        );
    }

    /// The manifest of a new run of the plan `toml` on bench-5, whose station file has a
    /// `[chamber]`.
    fn manifest_on_bench_5(toml: &str) -> Manifest {
        let station = gyrocal_files::station::Station::from_toml_str(
            "id = \"bench-5\"\nlab = \"Lab\"\naddress = \"Road\"\n\
             [multimeter]\nmodel = \"HP 34401A\"\nasset_id = \"DMM-1\"\nserial = \"S1\"\n\
             certificate = \"C1\"\ncalibrated = 2026-01-01\ndue = 2099-01-01\n\
             [chamber]\nmodel = \"Thermotron SE-600 (Watlow F4)\"\nasset_id = \"TC-07\"\n\
             serial = \"SE600-1187\"\ncertificate = \"C-TC-7\"\ncalibrated = 2026-03-02\n\
             due = 2099-03-02\n",
            std::path::Path::new("station.toml"),
        )
        .unwrap();
        let plan =
            gyrocal_files::Plan::from_toml_str(toml, std::path::Path::new("p.toml")).unwrap();
        let tmp = tempfile::tempdir().unwrap();
        let meta = gyrocal_files::RunMeta {
            station: Some(station),
            ..gyrocal_files::RunMeta::default()
        };
        let run = gyrocal_files::RunDir::create(&tmp.path().join("run"), &plan, meta).unwrap();
        run.manifest().clone()
    }

    const BASE: &str = "[plan]\nname = \"p\"\nrates_dps = [0, 10, -10]\nsamples_per_rate = 5\n\
        settle_s = 0\n[table]\ndialect = \"acl\"\nport = \"/dev/ttyUSB1\"\nmax_rate_dps = 20\n\
        acceleration_dps2 = 10\n[dmm]\nport = \"/dev/ttyUSB0\"\nrange_v = 10\nnplc = 1\n\
        autozero = false\nline_hz = 50\n";

    #[test]
    fn a_series_certificate_lists_the_chamber_with_its_record_and_a_sweep_s_does_not() {
        let series = format!(
            "{}[series]\ntemperatures_c = [25, 60]\nmeasure = \"sweep\"\n[chamber]\nmodel = \"watlow_f4\"\n\
             port = \"/dev/ttyUSB2\"\n",
            BASE.replace(
                "name = \"p\"",
                "kind = \"temperature_series\"\nname = \"p\""
            )
        );
        let mut m = manifest_on_bench_5(&series);
        m.chamber = Some(gyrocal_files::rundir::ChamberRecord {
            identity: Some("Watlow F4 (°C, 1 decimal) on /dev/ttyUSB2".into()),
            ..Default::default()
        });
        let mut html = String::new();
        instruments(&mut html, &m);
        let row = html
            .lines()
            .find(|l| l.starts_with("<tr><td>Thermal chamber</td>"))
            .unwrap_or_else(|| panic!("no chamber row: {html}"))
            // an identity breaks after its commas
            .replace(",<wbr>", ",");
        for cell in [
            "Thermotron SE-600 (Watlow F4)",
            "TC-07",
            "SE600-1187",
            "C-TC-7",
            "2099-03-02",
            "Watlow F4 (°C, 1 decimal) on /dev/ttyUSB2",
        ] {
            assert!(row.contains(cell), "{cell} not in {row}");
        }
        // the station has no [table]: said as before, the chamber row after it
        assert!(html.find("Rate table") < html.find("Thermal chamber"));

        // a sweep on the same station: the chamber is not its instrument
        let mut html = String::new();
        instruments(&mut html, &manifest_on_bench_5(BASE));
        assert!(
            html.contains("Multimeter") && !html.contains("chamber"),
            "{html}"
        );

        // a series without a station file: the chamber's identity as reported
        m.station = None;
        let mut html = String::new();
        instruments(&mut html, &m);
        assert!(
            html.contains("<tr><td>Thermal chamber</td><td>Watlow F4 (°C, 1 decimal) on /dev/ttyUSB2</td></tr>"),
            "{html}"
        );
    }

    #[test]
    fn times_are_shown_in_the_zone_with_the_offset() {
        let tz = jiff::tz::TimeZone::fixed(jiff::tz::offset(2));
        let shown = local_in("2026-11-23T19:33:33.123Z", tz);
        assert!(
            shown.starts_with("2026-11-23 21:33:33 +02:00"),
            "shown as {shown}"
        );
        let shown = local_in(
            "2026-12-31T23:30:00Z",
            jiff::tz::TimeZone::fixed(jiff::tz::offset(-5)),
        );
        assert!(
            shown.starts_with("2026-12-31 18:30:00 -05:00"),
            "shown as {shown}"
        );
        // not a time: shown as written, never a panic
        assert_eq!(local_in("yesterday", jiff::tz::TimeZone::UTC), "yesterday");
    }
}
