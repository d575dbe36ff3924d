//! A temperature series in the catalog (schema version 3), on SQLite (always) and PostgreSQL
//! (when GYROCAL_TEST_POSTGRES_URL is set): a run directory with a `series.json` keeps its
//! sensitivities and per-temperature points, a run without one is catalogued as before, a
//! run imported again replaces its points, and a `series.json` of another shape is refused
//! naming the file.
//!
//! The run directories are the real writer's (tests/common) with a `series.json` of the
//! contract's shape written beside the sweep's files: the catalog reads the file whatever
//! the run's kind.

#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::path::{Path, PathBuf};

use common::{Spec, clone_run};
use gyrocal_catalog::{Catalog, CatalogUrl, ErrorKind};

/// A serial no other test (or earlier run on the shared PostgreSQL database) uses.
fn uniq(serial: &str) -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos();
    format!("{serial}-{}-{nanos}", std::process::id())
}

/// series.json with the `catalog` member of the contract: 25 → −20 → 60 → 25 °C, K's
/// sensitivity `k_tc` ppm/°C, the bias's `bias_tc` °/h/°C, and the rest of the analysis beside
/// it (which the catalog ignores).
fn series_json(k_tc: f64, bias_tc: f64) -> serde_json::Value {
    let point = |i: i64, t: f64| {
        serde_json::json!({
            "series_point": i, "setpoint_c": t, "temp_min_c": t - 0.2, "temp_mean_c": t + 0.01,
            "temp_max_c": t + 0.1, "k": 0.36 * (1.0 + k_tc * 1e-6 * (t - 25.0)), "u_k": 3.6e-5,
            "bias_dph": 36.0 + bias_tc * (t - 25.0), "u_bias_dph": 2.0,
            "nonlinearity_ppm": if i == 1 { serde_json::Value::Null } else { 120.0.into() },
        })
    };
    serde_json::json!({
        "points": [{"the analysis' own": "shape"}],
        "verdict": "pass",
        "catalog": {
            "points": [point(0, 25.0), point(1, -20.0), point(2, 60.0), point(3, 25.0)],
            "k_tempco_ppm_per_c": k_tc, "u_k_tempco_ppm_per_c": 4.0,
            "bias_tempco_dph_per_c": bias_tc, "u_bias_tempco_dph_per_c": 0.3,
            "k_model_order": 1, "bias_model_order": 2,
            "hysteresis_k_ppm": 12.0, "hysteresis_bias_dph": null,
            "t_min_c": -20.2, "t_max_c": 60.1,
        },
    })
}

fn series_run(dest: &Path, serial: &str, day: u32, k_tc: f64, bias_tc: f64) -> PathBuf {
    let dir = clone_run(dest, &Spec::new(serial, day, 0.36));
    std::fs::write(
        dir.join("series.json"),
        serde_json::to_vec_pretty(&series_json(k_tc, bias_tc)).unwrap(),
    )
    .unwrap();
    dir
}

async fn series_are_kept(catalog: &Catalog, root: &Path) {
    let serial = uniq("TC-1");
    let first = series_run(&root.join("s1"), &serial, 1, 30.0, 1.5);
    let plain = clone_run(&root.join("p"), &Spec::new(&serial, 2, 0.3601));
    let second = series_run(&root.join("s2"), &serial, 3, 33.0, 1.2);
    for d in [&first, &plain, &second] {
        catalog.import_dir(d).await.unwrap();
    }
    // imported again: its rows replaced, not doubled (the points' key would refuse a double)
    catalog.import_dir(&second).await.unwrap();

    let h = catalog.history(&serial, false).await.unwrap();
    assert_eq!(h.calibrations.len(), 3);
    assert!(
        h.calibrations[1].series.is_none(),
        "a run without series.json"
    );
    let s = h.calibrations[2]
        .series
        .as_ref()
        .expect("the second series");
    assert_eq!(s.k_tempco_ppm_per_c, Some(33.0));
    assert_eq!(s.u_k_tempco_ppm_per_c, Some(4.0));
    assert_eq!(s.bias_tempco_dph_per_c, Some(1.2));
    assert_eq!(s.u_bias_tempco_dph_per_c, Some(0.3));
    assert_eq!((s.k_model_order, s.bias_model_order), (Some(1), Some(2)));
    assert_eq!(s.hysteresis_k_ppm, Some(12.0));
    assert_eq!(s.hysteresis_bias_dph, None);
    assert_eq!((s.t_min_c, s.t_max_c), (Some(-20.2), Some(60.1)));
    // the points in the plan's order, the revisited 25 °C its own point
    let setpoints: Vec<f64> = s.points.iter().map(|p| p.setpoint_c).collect();
    assert_eq!(setpoints, vec![25.0, -20.0, 60.0, 25.0]);
    let cold = &s.points[1];
    assert_eq!(cold.series_point, 1);
    assert_eq!(cold.temp_min_c, Some(-20.2));
    assert_eq!(cold.bias_dph, Some(36.0 + 1.2 * -45.0));
    assert_eq!(cold.nonlinearity_ppm, None);
    // the same as read from the file
    let from_file = gyrocal_catalog::read_series(&second).unwrap().unwrap();
    assert_eq!(s, &from_file);

    // the sensitivities' trend over the gyro's series, with their U
    let k_tc = h
        .trends
        .iter()
        .find(|t| t.quantity == "k_tempco_ppm_per_c")
        .expect("a trend of K's sensitivity");
    let seen: Vec<_> = k_tc
        .points
        .iter()
        .map(|p| (p.value, p.expanded_uncertainty))
        .collect();
    assert_eq!(seen, vec![(30.0, Some(4.0)), (33.0, Some(4.0))]);

    // a series.json rewritten with fewer points replaces the run's points
    let mut doc = series_json(31.0, 1.5);
    doc["catalog"]["points"].as_array_mut().unwrap().truncate(2);
    std::fs::write(first.join("series.json"), serde_json::to_vec(&doc).unwrap()).unwrap();
    catalog.import_dir(&first).await.unwrap();
    let h = catalog.history(&serial, false).await.unwrap();
    let s = h.calibrations[0].series.as_ref().unwrap();
    assert_eq!(s.points.len(), 2);
    assert_eq!(s.k_tempco_ppm_per_c, Some(31.0));

    // a series.json without the catalog's member is refused, naming the file
    std::fs::write(first.join("series.json"), br#"{"verdict": "pass"}"#).unwrap();
    let e = catalog.import_dir(&first).await.unwrap_err();
    assert_eq!(e.kind(), ErrorKind::NotARun);
    let m = e.to_string();
    assert!(
        m.contains("series.json") && m.contains("\"catalog\""),
        "{m}"
    );
    // and what the catalog held for the run is left as it was
    let h = catalog.history(&serial, false).await.unwrap();
    assert_eq!(h.calibrations[0].series.as_ref().unwrap().points.len(), 2);
}

#[tokio::test]
async fn sqlite_keeps_a_series_and_its_points() {
    let tmp = tempfile::tempdir().unwrap();
    let url = CatalogUrl::Sqlite(tmp.path().join("catalog.sqlite"));
    let catalog = Catalog::open(&url).await.unwrap();
    series_are_kept(&catalog, tmp.path()).await;
    catalog.close().await;
}

#[tokio::test]
async fn postgres_keeps_a_series_and_its_points() {
    let Ok(url) = std::env::var("GYROCAL_TEST_POSTGRES_URL") else {
        eprintln!("note: GYROCAL_TEST_POSTGRES_URL is not set; PostgreSQL test skipped");
        return;
    };
    let catalog = Catalog::open(&CatalogUrl::parse(&url).unwrap())
        .await
        .unwrap();
    let tmp = tempfile::tempdir().unwrap();
    series_are_kept(&catalog, tmp.path()).await;
    catalog.close().await;
}
