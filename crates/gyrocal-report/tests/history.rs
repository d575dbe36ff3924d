//! A gyro's history page (`gyrocal history SERIAL -o FILE.html`), rendered from the catalog's
//! typed history. The renderer and its test moved here from gyrocal-catalog (the catalog now
//! only stores and queries); the end-to-end page is also checked in
//! crates/gyrocal/tests/catalog_cli.rs.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use gyrocal_catalog::{Calibration, CheckRow, History, Results, RunRow};

fn run(serial: &str, day: u32, kind: &str, simulated: bool) -> RunRow {
    RunRow {
        id: format!("{day:02}0123456789abcdef"),
        directory: format!("/runs/{serial}/{day}"),
        host: Some("bench".into()),
        station_id: Some("ST-1".into()),
        plan_name: "quick".into(),
        plan_hash: "ab".repeat(32),
        kind: kind.into(),
        dut_serial: Some(serial.into()),
        dut_model: None,
        operator: None,
        customer: None,
        status: "complete".into(),
        reason: None,
        started_utc: format!("2026-01-{day:02}T10:00:00.000Z"),
        ended_utc: None,
        simulated,
        verdict: Some("pass".into()),
        acceptance_rule: None,
        steps_total: 5,
        steps_done: 5,
        ambient_c: None,
        humidity_pct: None,
        gyrocal_version: None,
    }
}

fn sweep(serial: &str, day: u32, k: f64, simulated: bool) -> Calibration {
    Calibration {
        run: run(serial, day, "scale_factor", simulated),
        results: Some(Results {
            scale_factor: Some(k),
            u_scale_factor: Some(3.6e-5),
            bias_dph: Some(10.0 + f64::from(day)),
            u_bias_dph: Some(1.0),
            ..Results::default()
        }),
        checks: vec![CheckRow {
            quantity: "scale_factor".into(),
            value: Some(k),
            max: Some(0.365),
            verdict: Some("pass".into()),
            ..CheckRow::default()
        }],
        rates_dps: vec![-10.0, -1.0, 0.0, 1.0, 10.0],
        series: None,
    }
}

/// Three calibrations of one gyro as the catalog test imports them (two real, one simulated).
fn three(serial: &str) -> History {
    History::of(
        serial,
        true,
        vec![
            sweep(serial, 1, 0.3600, false),
            sweep(serial, 5, 0.3601, false),
            sweep(serial, 7, 0.3602, true),
        ],
    )
}

#[test]
fn history_page_has_the_trend_plots_and_names_the_gyro() {
    let a = "A-0421";
    let with_sim = three(a);
    assert_eq!(with_sim.calibrations.len(), 3);
    let html = gyrocal_report::history::render(&with_sim);
    assert!(html.contains("<svg") && html.contains(a));
}

#[test]
fn history_page_is_on_the_shared_page_with_one_stylesheet() {
    let html = gyrocal_report::history::render(&three("A-0421"));
    assert!(html.starts_with("<!DOCTYPE html>"));
    assert_eq!(html.matches("<style>").count(), 1, "one stylesheet");
    assert!(html.contains(gyrocal_report::page::STYLESHEET));
    assert!(html.contains("<h1>Calibration history of gyro A-0421</h1>"));
    assert!(html.contains("3 complete calibration(s), simulated runs included."));
    assert!(html.contains("<h2>Calibrations</h2>"));
    assert!(!html.contains("<h2>Drift tests</h2>"), "no drift run");
    assert!(html.ends_with("</body>\n</html>\n"));
}

#[test]
fn history_page_escapes_what_came_from_the_catalog() {
    let serial = "<b>A&'\"";
    let mut h = three(serial);
    h.calibrations[0].run.plan_name = "<script>x</script>".into();
    let html = gyrocal_report::history::render(&h);
    assert!(!html.contains("<script>x"), "plan name escaped");
    assert!(html.contains("&lt;script&gt;x&lt;/script&gt;"));
    assert!(!html.contains("<b>A"), "serial escaped");
    assert!(html.contains("&lt;b&gt;A&amp;&#39;&quot;"));
}

#[test]
fn drift_tests_get_their_own_table() {
    let mut d = sweep("D-1", 9, 0.36, false);
    d.run.kind = "drift".into();
    d.results = Some(Results {
        arw_deg_rt_h: Some(0.01),
        u_arw_deg_rt_h: Some(0.001),
        drift_duration_s: Some(7200.0),
        ..Results::default()
    });
    let html = gyrocal_report::history::render(&History::of("D-1", false, vec![d]));
    assert!(html.contains("<h2>Drift tests</h2>"));
    assert!(!html.contains("<h2>Calibrations</h2>"));
    // the record's length in hours, as a number cell
    assert!(html.contains("<td class=\"num\">2.000000</td>"), "{html}");
}

/// The `<text>` contents of an SVG (the tick labels, the legend, the axis titles).
fn texts(svg: &str) -> Vec<String> {
    let doc = roxmltree::Document::parse(svg).unwrap();
    doc.descendants()
        .filter(|n| n.has_tag_name("text"))
        .filter_map(|n| n.text().map(|s| s.trim().to_string()))
        .collect()
}

/// The SVG of the trend titled `label`.
fn trend_svg<'a>(html: &'a str, label: &str) -> &'a str {
    let at = html.find(&format!("<h3>{label}")).unwrap();
    let start = html[at..].find("<svg").unwrap() + at;
    let end = html[start..].find("</svg>").unwrap() + start + 6;
    &html[start..end]
}

fn k_series(ks: &[f64], max: f64, marginal_max: f64) -> History {
    let cals = ks
        .iter()
        .enumerate()
        .map(|(i, k)| {
            let mut c = sweep("K-1", u32::try_from(i).unwrap() + 1, *k, false);
            c.checks[0].max = Some(max);
            c.checks[0].marginal_max = Some(marginal_max);
            c
        })
        .collect();
    History::of("K-1", false, cals)
}

#[test]
fn limits_marginal_limits_and_points_beyond_them_are_drawn_and_marked() {
    // 0.36120 is beyond the marginal limit 0.36115, 0.36130 beyond the limit 0.36125
    let h = k_series(&[0.36100, 0.36105, 0.36120, 0.36130], 0.36125, 0.36115);
    let html = gyrocal_report::history::render(&h);
    let svg = trend_svg(&html, "Scale factor K (");
    let t = texts(svg);
    for entry in [
        "acceptance limit",
        "marginal limit",
        "marginal (beyond a marginal limit)",
        "outside the acceptance limits",
    ] {
        assert!(t.iter().any(|s| s == entry), "{entry} in the legend: {t:?}");
    }
    // the out-of-limit point is a red triangle, the marginal one an orange diamond
    assert!(svg.contains("fill=\"#C81E2D\""), "a red marker");
    assert!(svg.contains("fill=\"#E68200\""), "an orange marker");
    // and readable ticks: no exponent form
    assert!(
        t.iter().all(|s| !s.contains("e-") && !s.contains("e+")),
        "{t:?}"
    );
    assert!(t.iter().any(|s| s == "0.3610"), "{t:?}");
}

#[test]
fn the_k_plot_is_scaled_to_the_data_and_names_a_far_limit() {
    // K within 2e-4 of 0.3600 (± 3.6e-5), the limit at 0.365: 25 times the spread away
    let html = gyrocal_report::history::render(&three("A-0421"));
    let svg = trend_svg(&html, "Scale factor K (");
    let t = texts(svg);
    assert!(
        t.iter()
            .any(|s| s == "acceptance limit 0.365 above the plot (not drawn)"),
        "{t:?}"
    );
    // the y ticks span about the data (0.35996..0.36024), not the limit
    let ticks: Vec<f64> = t.iter().filter_map(|s| s.parse::<f64>().ok()).collect();
    let hi = ticks.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    assert!(hi < 0.3604, "{ticks:?}");
}

#[test]
fn no_control_band_below_five_earlier_calibrations_and_the_page_says_so() {
    let html = gyrocal_report::history::render(&three("A-0421"));
    assert!(
        html.contains("No control band: 2 earlier calibration(s), 5 needed"),
        "{html}"
    );
    assert!(!html.contains("control band: mean ± 3σ"));
    let h = k_series(
        &[0.3610, 0.36101, 0.36099, 0.36100, 0.36102, 0.36100],
        0.37,
        0.369,
    );
    let html = gyrocal_report::history::render(&h);
    assert!(html.contains("Control band (mean ± 3σ of the 5 earlier calibrations)"));
    let svg = trend_svg(&html, "Scale factor K (");
    assert!(
        texts(svg)
            .iter()
            .any(|s| s == "control band: mean ± 3σ of 5 earlier")
    );
}

#[test]
fn the_date_is_not_repeated_along_the_axis() {
    let mut h = three("A-0421");
    // two calibrations on the 5th
    let mut second = h.calibrations[1].clone();
    second.run.started_utc = "2026-01-05T15:30:00.000Z".into();
    second.run.id = "05b".into();
    h.calibrations.insert(2, second);
    let h = History::of("A-0421", true, h.calibrations);
    let html = gyrocal_report::history::render(&h);
    let t = texts(trend_svg(&html, "Scale factor K ("));
    assert_eq!(t.iter().filter(|s| *s == "2026-01-05").count(), 1, "{t:?}");
    assert!(t.iter().any(|s| s == "15:30"), "{t:?}");
}

#[test]
fn calibrations_of_another_plan_are_named_and_kept_out_of_the_repeatability() {
    let mut cals: Vec<Calibration> = (1..=3).map(|d| sweep("P-1", d, 0.3600, false)).collect();
    let mut other = sweep("P-1", 4, 0.3700, false);
    other.rates_dps = (-9..=9).map(f64::from).collect();
    other.run.plan_name = "paper".into();
    other.run.plan_hash = "cd".repeat(32);
    cals.insert(1, other);
    // a different seed: another plan hash, the same rates
    cals[3].run.plan_hash = "ef".repeat(32);
    let html = gyrocal_report::history::render(&History::of("P-1", false, cals));
    assert!(html.contains("<h2>Plans</h2>"), "{html}");
    assert!(html.contains("paper (plan B)"));
    assert!(html.contains(
        "over 3 calibrations of plan A (the latest calibration's; 1 calibration(s) of other plans left out)"
    ));
    let t = texts(trend_svg(&html, "Scale factor K ("));
    assert!(
        t.iter().any(|s| s == "another plan (not in the band)"),
        "{t:?}"
    );
}

#[test]
fn a_calibration_shows_when_it_started_to_the_minute_and_the_full_stamp_on_hover() {
    let mut h = three("A-0421");
    h.calibrations[0].run.started_utc = "2026-01-05T15:30:12.345Z".into();
    h.calibrations[1].run.started_utc = "not a time <b>".into();
    let html = gyrocal_report::history::render(&History::of("A-0421", true, h.calibrations));
    assert!(
        html.contains(
            "<td class=\"when\" title=\"2026-01-05T15:30:12.345Z\">2026-01-05 15:30</td>"
        ),
        "{html}"
    );
    // a stamp that does not read is shown as it is, escaped
    assert!(html.contains(">not a time &lt;b&gt;</td>"), "{html}");
}

#[test]
fn one_calibration_says_a_repeatability_needs_two_not_a_dash_over_one() {
    let one = History::of("S-1", false, vec![sweep("S-1", 1, 0.36, false)]);
    let html = gyrocal_report::history::render(&one);
    assert!(
        html.contains("Needs two calibrations or more (1 so far)"),
        "{html}"
    );
    assert!(!html.contains("over 1 calibrations"), "{html}");
    // two give the spread
    let two = History::of(
        "S-1",
        false,
        vec![sweep("S-1", 1, 0.36, false), sweep("S-1", 2, 0.3601, false)],
    );
    let html = gyrocal_report::history::render(&two);
    assert!(html.contains("std/mean over 2 calibrations"), "{html}");
}
