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
