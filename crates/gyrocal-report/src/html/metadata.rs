//! The run's metadata table: plan, instruments, station, times, files (everything read from
//! the manifest is escaped).

use std::fmt::Write as _;

use gyrocal_files::Status;

use super::esc;
use crate::input::Input;

pub(super) fn metadata(html: &mut String, input: &Input, sfx: &str) {
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
