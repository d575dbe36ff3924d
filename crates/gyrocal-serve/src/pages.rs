//! The HTML pages: the dashboard, a run's page, the frame around a gyro's history.
//!
//! Every text that comes from a file (a serial, a plan's name, a reason) goes through
//! [`esc`]; the live parts are fragments rendered here too (the browser's script swaps them
//! in on a server-sent event), so escaping happens in one place, never in JavaScript.

use std::fmt::Write as _;
use std::path::Path;

use gyrocal_run::live::StepSummary;

use crate::runs::{RunDetail, RunView, encode};

/// HTML-escapes text for element content and quoted attribute values.
pub fn esc(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// The script every page loads (`/live.js`): on a server-sent event (any run changed),
/// fetch the page's live fragment again and swap it in; at most one fetch at a time, and a
/// refresh every 10 s without events (a run becomes stale without any file changing; the
/// fragment is bounded whatever the run's length, see [`crate::plots`], so this costs little).
pub const LIVE_JS: &str = r#"(function () {
  var box = document.getElementById('live');
  if (!box) return;
  var url = box.getAttribute('data-part'), busy = false, again = false;
  function refresh() {
    if (busy) { again = true; return; }
    busy = true;
    fetch(url, { credentials: 'same-origin' }).then(function (r) {
      return r.ok ? r.text() : null;
    }).then(function (html) {
      if (html !== null) box.innerHTML = html;
    }).catch(function () {}).then(function () {
      busy = false;
      if (again) { again = false; refresh(); }
    });
  }
  var es = new EventSource('/api/events');
  es.addEventListener('run', refresh);
  setInterval(refresh, 10000);
})();
"#;

const STYLE: &str = "body{font-family:system-ui,sans-serif;margin:1em;max-width:110em;\
overflow-wrap:break-word}\
table{border-collapse:collapse;width:100%}td,th{border-bottom:1px solid #ccc;padding:.3em .5em;\
text-align:left;font-variant-numeric:tabular-nums}th{background:#eee}\
#state{max-width:70em}#state tbody{display:grid;grid-template-columns:repeat(auto-fill,minmax(22em,1fr))}\
#state tr{display:flex}#state th{flex:0 0 8.5em}#state td{flex:1}\
.stale{color:#a00;font-weight:bold}.pass{color:#070}.fail{color:#a00}.marginal{color:#a60}\
.wrap{overflow-x:auto}svg{max-width:100%;height:auto}\
.plots{display:flex;flex-wrap:wrap;gap:0 1.5em}\
figure{margin:1em 0;flex:1 1 30em;max-width:50em;min-width:0}\
figure svg{display:block;width:100%;height:auto}\
figcaption{color:#444;font-size:.9em}.note{color:#555;font-style:italic;flex:1 1 100%}\
@media (max-width:40em){body{margin:.3em}td,th{padding:.2em}#state th{flex-basis:7em}}";

/// The most step rows a run page lists (the newest; the rest are in `steps.csv`): the page
/// stays the same size whatever the run's length.
pub const STEP_ROWS_MAX: usize = 30;

/// A whole page around `body`.
pub fn page(title: &str, body: &str) -> String {
    format!(
        "<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\">\
         <meta name=\"viewport\" content=\"width=device-width,initial-scale=1\">\
         <title>{}</title><style>{STYLE}</style></head><body>\
         <p><a href=\"/\">gyrocal · all runs</a></p>{body}\
         <script src=\"/live.js\"></script></body></html>",
        esc(title)
    )
}

fn opt(v: Option<&str>) -> String {
    v.map_or_else(|| "—".to_string(), esc)
}

fn volts(v: Option<f64>) -> String {
    v.filter(|v| v.is_finite())
        .map_or_else(|| "—".to_string(), |v| format!("{v:.6} V"))
}

fn duration(s: Option<f64>) -> String {
    match s.filter(|s| s.is_finite() && *s >= 0.0) {
        None => "—".into(),
        Some(s) => {
            let s = s.round() as u64;
            format!("{}:{:02}:{:02}", s / 3600, (s / 60) % 60, s % 60)
        }
    }
}

fn gyro_link(serial: Option<&str>) -> String {
    match serial {
        Some(s) => format!("<a href=\"/gyro/{}\">{}</a>", encode(s), esc(s)),
        None => "—".into(),
    }
}

fn verdict(v: Option<&str>) -> String {
    match v {
        Some(v) => format!(
            "<span class=\"verdict {}\">{}</span>",
            esc(&v
                .to_ascii_lowercase()
                .replace(|c: char| !c.is_ascii_alphanumeric(), "")),
            esc(v)
        ),
        None => "—".into(),
    }
}

/// The dashboard's live part: running runs, stale runs, the runs finished today.
pub fn dashboard_part(runs: &[RunView], today: &str, catalog: Option<&str>) -> String {
    let mut h = String::new();
    let running: Vec<_> = runs
        .iter()
        .filter(|r| r.status == "running" && !r.stale)
        .collect();
    let stale: Vec<_> = runs.iter().filter(|r| r.stale).collect();
    let finished: Vec<_> = runs
        .iter()
        .filter(|r| r.status != "running")
        .filter(|r| {
            r.ended_utc
                .as_deref()
                .or(r.updated_utc.as_deref())
                .is_some_and(|t| t.starts_with(today))
        })
        .collect();
    let _ = write!(h, "<h2>Running now ({})</h2>", running.len());
    if running.is_empty() {
        h.push_str("<p>No run is running.</p>");
    } else {
        h.push_str(
            "<div class=\"wrap\"><table id=\"running\"><tr><th>Station</th><th>Gyro</th>\
             <th>Plan</th><th>Phase</th><th>Step</th><th>ETA</th><th>Last reading</th>\
             <th>Running mean</th><th>Table</th></tr>",
        );
        for r in running {
            let _ = write!(
                h,
                "<tr class=\"run\" data-run=\"{}\"><td>{}</td><td>{}</td><td><a href=\"{}\">{}</a></td>\
                 <td class=\"phase\">{}</td><td class=\"step\">{}/{}</td><td>{}</td><td>{}</td>\
                 <td>{}</td><td>{}</td></tr>",
                esc(&r.key.name),
                opt(r.station.as_deref()),
                gyro_link(r.gyro_serial.as_deref()),
                esc(&r.href),
                esc(&r.plan_name),
                esc(&r.phase),
                r.steps_done,
                r.steps,
                duration(r.eta_s),
                volts(r.last_reading_v),
                volts(r.running_mean_v),
                opt(r.table.as_deref()),
            );
        }
        h.push_str("</table></div>");
    }
    if !stale.is_empty() {
        let _ = write!(h, "<h2>Stale ({})</h2><ul id=\"stale\">", stale.len());
        for r in stale {
            let _ = write!(
                h,
                "<li><span class=\"stale\">STALE</span> <a href=\"{}\">{}</a> ({}, gyro {}): \
                 {}; step {}/{}</li>",
                esc(&r.href),
                esc(&r.key.name),
                esc(&r.plan_name),
                opt(r.gyro_serial.as_deref()),
                opt(r.stale_reason.as_deref()),
                r.steps_done,
                r.steps
            );
        }
        h.push_str("</ul>");
    }
    let _ = write!(h, "<h2>Finished today ({})</h2>", finished.len());
    if finished.is_empty() {
        h.push_str("<p>No run finished today.</p>");
    } else {
        h.push_str(
            "<div class=\"wrap\"><table id=\"finished\"><tr><th>Ended (UTC)</th><th>Gyro</th>\
             <th>Plan</th><th>Status</th><th>Verdict</th><th>Steps</th></tr>",
        );
        for r in finished {
            let _ = write!(
                h,
                "<tr class=\"run\" data-run=\"{}\"><td>{}</td><td>{}</td><td><a href=\"{}\">{}</a></td>\
                 <td>{}</td><td>{}</td><td>{}/{}</td></tr>",
                esc(&r.key.name),
                opt(r.ended_utc.as_deref()),
                gyro_link(r.gyro_serial.as_deref()),
                esc(&r.href),
                esc(&r.plan_name),
                esc(&r.status),
                verdict(r.verdict.as_deref()),
                r.steps_done,
                r.steps
            );
        }
        h.push_str("</table></div>");
    }
    if let Some(c) = catalog {
        let _ = write!(h, "<p>Catalog: {}</p>", esc(c));
    }
    h
}

/// The dashboard page.
pub fn dashboard(part: &str) -> String {
    page(
        "gyrocal runs",
        &format!(
            "<h1>gyrocal runs</h1><div id=\"live\" data-part=\"/part/dashboard\">{part}</div>"
        ),
    )
}

/// The least-squares line through `(x, y)`: `(slope, intercept)`, `None` below two distinct
/// x.
pub fn fit_line(points: &[(f64, f64)]) -> Option<(f64, f64)> {
    let n = points.len() as f64;
    if points.len() < 2 {
        return None;
    }
    let mx = points.iter().map(|p| p.0).sum::<f64>() / n;
    let my = points.iter().map(|p| p.1).sum::<f64>() / n;
    let sxx: f64 = points.iter().map(|p| (p.0 - mx).powi(2)).sum();
    if sxx <= 0.0 || !sxx.is_finite() {
        return None;
    }
    let sxy: f64 = points.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let k = sxy / sxx;
    Some((k, my - k * mx))
}

/// The plot of the mean voltage against the rate (a drift record: against the run clock),
/// with the fitted line of a sweep: an SVG of numbers only, bounded by the step count.
pub fn plot(steps: &[StepSummary], drift: bool) -> String {
    let pts: Vec<(f64, f64)> = steps
        .iter()
        .map(|s| (if drift { s.t_end_s } else { s.rate_dps }, s.volts))
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .collect();
    let (w, h, m) = (640.0, 360.0, 50.0);
    let mut svg = format!(
        "<svg id=\"plot\" xmlns=\"http://www.w3.org/2000/svg\" viewBox=\"0 0 {w} {h}\" \
         width=\"{w}\" height=\"{h}\" data-points=\"{}\"><rect x=\"{m}\" y=\"10\" width=\"{}\" \
         height=\"{}\" fill=\"none\" stroke=\"#888\"/>",
        pts.len(),
        w - m - 10.0,
        h - m - 10.0
    );
    let xl = if drift {
        "run clock (s)"
    } else {
        "rate (°/s)"
    };
    let _ = write!(
        svg,
        "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\" font-size=\"12\">{xl}</text>\
         <text x=\"12\" y=\"{}\" font-size=\"12\" transform=\"rotate(-90 12 {})\" \
         text-anchor=\"middle\">mean output (V)</text>",
        (w + m) / 2.0,
        h - 12.0,
        h / 2.0,
        h / 2.0
    );
    if pts.is_empty() {
        svg.push_str("</svg>");
        return svg;
    }
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for (x, y) in &pts {
        x0 = x0.min(*x);
        x1 = x1.max(*x);
        y0 = y0.min(*y);
        y1 = y1.max(*y);
    }
    if x1 - x0 <= 0.0 {
        (x0, x1) = (x0 - 1.0, x1 + 1.0);
    }
    if y1 - y0 <= 0.0 {
        (y0, y1) = (y0 - 1e-6, y1 + 1e-6);
    }
    let sx = |x: f64| m + (x - x0) / (x1 - x0) * (w - m - 10.0);
    let sy = |y: f64| 10.0 + (y1 - y) / (y1 - y0) * (h - m - 10.0);
    let _ = write!(
        svg,
        "<text x=\"{m}\" y=\"{}\" font-size=\"11\">{x0:.4}</text>\
         <text x=\"{}\" y=\"{}\" font-size=\"11\" text-anchor=\"end\">{x1:.4}</text>\
         <text x=\"{}\" y=\"18\" font-size=\"11\">{y1:.6}</text>\
         <text x=\"{}\" y=\"{}\" font-size=\"11\">{y0:.6}</text>",
        h - m + 14.0,
        w - 10.0,
        h - m + 14.0,
        m + 4.0,
        m + 4.0,
        h - m - 4.0
    );
    if !drift && let Some((k, b)) = fit_line(&pts) {
        let _ = write!(
            svg,
            "<line class=\"fit\" x1=\"{:.2}\" y1=\"{:.2}\" x2=\"{:.2}\" y2=\"{:.2}\" \
             stroke=\"#c33\" stroke-width=\"1.5\"/>",
            sx(x0),
            sy(k * x0 + b),
            sx(x1),
            sy(k * x1 + b)
        );
    }
    for (x, y) in &pts {
        let _ = write!(
            svg,
            "<circle class=\"pt\" cx=\"{:.2}\" cy=\"{:.2}\" r=\"3\" fill=\"#236\"/>",
            sx(*x),
            sy(*y)
        );
    }
    svg.push_str("</svg>");
    svg
}

/// A run page's live part: its state, the plots ([`crate::plots`], reading `dir`'s
/// `allan.json` and `temps.csv`), the last steps, its files.
pub fn run_part(d: &RunDetail, dir: Option<&Path>) -> String {
    let v = &d.view;
    let mut h = String::new();
    let _ = write!(
        h,
        "<table id=\"state\"><tr><th>Status</th><td id=\"status\">{}{}</td></tr>\
         <tr><th>Phase</th><td id=\"phase\">{}</td></tr>\
         <tr><th>Step</th><td id=\"step\">{}/{}</td></tr>\
         <tr><th>ETA</th><td>{}</td></tr><tr><th>Last reading</th><td>{}</td></tr>\
         <tr><th>Running mean</th><td>{}</td></tr><tr><th>Table</th><td>{}</td></tr>\
         <tr><th>Verdict</th><td id=\"verdict\">{}</td></tr>\
         <tr><th>Plan</th><td>{} ({})</td></tr>\
         <tr><th>Station</th><td>{}</td></tr><tr><th>Gyro</th><td>{}</td></tr>\
         <tr><th>Started (UTC)</th><td>{}</td></tr><tr><th>Updated (UTC)</th><td>{}</td></tr></table>",
        esc(&v.status),
        if v.stale {
            format!(
                " <span class=\"stale\">STALE: {}</span>",
                opt(v.stale_reason.as_deref())
            )
        } else {
            String::new()
        },
        esc(&v.phase),
        v.steps_done,
        v.steps,
        duration(v.eta_s),
        volts(v.last_reading_v),
        volts(v.running_mean_v),
        opt(v.table.as_deref()),
        verdict(v.verdict.as_deref()),
        esc(&v.plan_name),
        esc(&v.plan_kind),
        opt(v.station.as_deref()),
        gyro_link(v.gyro_serial.as_deref()),
        opt(v.started_utc.as_deref()),
        opt(v.updated_utc.as_deref()),
    );
    if let Some(r) = &v.reason {
        let _ = write!(h, "<p>Reason: {}</p>", esc(r));
    }
    h.push_str(&crate::plots::for_run(
        &v.plan_kind,
        &d.step_summaries,
        &d.adev_v,
        dir,
    ));
    let total = d.step_summaries.len();
    let shown = &d.step_summaries[total.saturating_sub(STEP_ROWS_MAX)..];
    h.push_str("<h2>Steps</h2>");
    if shown.len() < total {
        let _ = write!(
            h,
            "<p id=\"steps-note\">The last {} of {total} steps; every step is in \
             <a href=\"{}/files/steps.csv\">steps.csv</a>.</p>",
            shown.len(),
            esc(&v.href)
        );
    }
    h.push_str(
        "<div class=\"wrap\"><table id=\"steps\"><tr><th>Step</th><th>Rate °/s</th>\
         <th>Mean V</th><th>σ V</th><th>n</th><th>Overloads</th><th>Run clock s</th></tr>",
    );
    for s in shown {
        let _ = write!(
            h,
            "<tr class=\"steprow\"><td>{}</td><td>{:+}</td><td>{:.7}</td><td>{}</td><td>{}</td>\
             <td>{}</td><td>{:.1}</td></tr>",
            s.number,
            s.rate_dps,
            s.volts,
            s.volts_std
                .map_or_else(|| "—".into(), |x| format!("{x:.3e}")),
            s.n,
            s.overloads,
            s.t_end_s
        );
    }
    h.push_str("</table></div>");
    if v.has_report {
        let _ = write!(
            h,
            "<p><a id=\"report\" href=\"{}/report.html\">The run's report (certificate)</a></p>",
            esc(&v.href)
        );
    }
    if !d.files.is_empty() {
        h.push_str("<h2>Files</h2><ul>");
        for f in &d.files {
            let _ = write!(
                h,
                "<li><a href=\"{}/files/{}\">{}</a></li>",
                esc(&v.href),
                encode(f),
                esc(f)
            );
        }
        h.push_str("</ul>");
    }
    h
}

/// A run's page (`dir`: its run directory, for the plots).
pub fn run_page(d: &RunDetail, dir: Option<&Path>) -> String {
    let v = &d.view;
    page(
        &format!("{} · {}", v.plan_name, v.key.name),
        &format!(
            "<h1>{} <small>{}</small></h1><div id=\"live\" data-part=\"/part{}\">{}</div>",
            esc(&v.plan_name),
            esc(&v.key.name),
            esc(&v.href),
            run_part(d, dir)
        ),
    )
}

/// A plain message page (not found, no catalog).
pub fn message(title: &str, text: &str) -> String {
    page(
        title,
        &format!("<h1>{}</h1><p>{}</p>", esc(title), esc(text)),
    )
}
