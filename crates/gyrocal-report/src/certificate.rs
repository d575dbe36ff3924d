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

use gyrocal_files::{Manifest, Plan};

use crate::html::esc;
use crate::input::Input;

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

/// The instruments used, as they identified themselves (the station file adds asset ids and
/// calibration records).
pub(crate) fn instruments(html: &mut String, m: &Manifest) {
    let _ = writeln!(
        html,
        "<h2 id=\"instruments\">Instruments</h2>\n<table class=\"cert\" id=\"instruments-table\">\n<tr><th>Role</th><th>Identity (as reported)</th></tr>"
    );
    for (role, id) in [
        ("Multimeter", &m.instruments.dmm),
        ("Rate table", &m.instruments.table),
    ] {
        let _ = writeln!(
            html,
            "<tr><td>{role}</td><td>{}</td></tr>",
            id.as_deref().map_or_else(|| "—".into(), esc)
        );
    }
    html.push_str("</table>\n<p class=\"note\" id=\"instruments-not-identified\">Instruments not identified: no station file gave their asset ids, serial numbers and calibration certificates, so this report does not establish traceability.</p>\n");
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

#[cfg(test)]
mod tests {
    use super::*;

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
