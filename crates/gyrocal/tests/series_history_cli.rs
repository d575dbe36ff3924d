//! A gyro's temperature series in `gyrocal history` (issue 26): two series run directories,
//! written by the real run-directory writer (`gyrocal run --simulate`) with a `series.json` of
//! the contract's shape beside them, are catalogued with `gyrocal catalog import`; the history
//! prints each series' sensitivities with their U and their trend, in the terminal, the JSON
//! and the page.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use std::path::Path;
use std::process::Output;

use common::config;
/// The binary with none of the user's files, its default catalog in the test's `data_home`.
use common::gyrocal_with_data_home as gyrocal;

fn ok(out: &Output) -> String {
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    stdout
}

/// A run directory of `serial` by the real writer, with a series.json whose `catalog` member
/// says K's sensitivity is `k_tc` ± 4 ppm/°C and the bias's `bias_tc` ± 0.3 °/h/°C over
/// 25 → −20 → 60 → 25 °C.
fn series_run(data_home: &Path, dir: &Path, serial: &str, k_tc: f64, bias_tc: f64) {
    ok(&gyrocal(data_home)
        .args([
            "run",
            "--simulate",
            "--catalog",
            "off",
            "--dut-serial",
            serial,
            "--out",
        ])
        .arg(dir)
        .arg(config("quick.toml"))
        .output()
        .unwrap());
    let point = |i: i64, t: f64| {
        serde_json::json!({
            "series_point": i, "setpoint_c": t, "temp_min_c": t - 0.3, "temp_mean_c": t,
            "temp_max_c": t + 0.2, "k": 0.36 * (1.0 + k_tc * 1e-6 * (t - 25.0)), "u_k": 3.6e-5,
            "bias_dph": 36.0 + bias_tc * (t - 25.0), "u_bias_dph": 2.0, "nonlinearity_ppm": 110.0,
        })
    };
    let doc = serde_json::json!({
        "verdict": "pass",
        "catalog": {
            "points": [point(0, 25.0), point(1, -20.0), point(2, 60.0), point(3, 25.0)],
            "k_tempco_ppm_per_c": k_tc, "u_k_tempco_ppm_per_c": 4.0,
            "bias_tempco_dph_per_c": bias_tc, "u_bias_tempco_dph_per_c": 0.3,
            "k_model_order": 1, "bias_model_order": 1,
            "hysteresis_k_ppm": 12.0, "hysteresis_bias_dph": 0.15,
            "t_min_c": -20.3, "t_max_c": 60.2,
        },
    });
    std::fs::write(
        dir.join("series.json"),
        serde_json::to_vec_pretty(&doc).unwrap(),
    )
    .unwrap();
}

#[test]
fn history_shows_each_series_sensitivities_with_u_and_their_trend() {
    let tmp = tempfile::tempdir().unwrap();
    let data_home = tmp.path().join("data");
    let serial = "TC-0042";
    let runs = tmp.path().join("runs");
    series_run(&data_home, &runs.join("s1"), serial, 30.0, 1.5);
    series_run(&data_home, &runs.join("s2"), serial, 36.5, 1.2);
    let imported = ok(&gyrocal(&data_home)
        .args(["catalog", "import"])
        .arg(runs.join("s1"))
        .arg(runs.join("s2"))
        .output()
        .unwrap());
    assert!(imported.contains("2 run(s) imported"), "{imported}");

    // the terminal: a series table with the sensitivities ± U, then their trends
    let text = ok(&gyrocal(&data_home)
        .args(["history", serial, "--include-simulated"])
        .output()
        .unwrap());
    assert!(text.contains("temperature series:"), "{text}");
    let rows: Vec<&str> = text
        .lines()
        .filter(|l| l.contains(&*runs.to_string_lossy()))
        .collect();
    assert_eq!(rows.len(), 2, "one line per series, no sweep line:\n{text}");
    assert!(rows[0].contains("30.00 ± 4.0"), "{}", rows[0]);
    assert!(rows[0].contains("1.500 ± 0.30"), "{}", rows[0]);
    assert!(rows[0].contains("-20.3 .. 60.2"), "{}", rows[0]);
    assert!(rows[1].contains("36.50 ± 4.0"), "{}", rows[1]);
    let k_trend = text
        .lines()
        .find(|l| l.starts_with("trend of K's temperature sensitivity"))
        .unwrap_or_else(|| panic!("no K sensitivity trend:\n{text}"));
    // 30 → 36.5: +6.5 ppm/°C, more than the two U's combined (√(4² + 4²) = 5.7)
    assert!(
        k_trend.contains("over 2 series")
            && k_trend.contains("30 → 36.5 ppm/°C")
            && k_trend.contains("+6.50")
            && k_trend.contains("MORE than the U of the two: 5.7"),
        "{k_trend}"
    );
    let bias_trend = text
        .lines()
        .find(|l| l.starts_with("trend of the bias's temperature sensitivity"))
        .unwrap_or_else(|| panic!("no bias sensitivity trend:\n{text}"));
    // 1.5 → 1.2: −0.3 °/h/°C, within √(0.3² + 0.3²) = 0.42
    assert!(
        bias_trend.contains("−0.300") && bias_trend.contains("within the U of the two: 0.42"),
        "{bias_trend}"
    );

    // the JSON: each calibration's series and the sensitivities' trend with U
    let out = gyrocal(&data_home)
        .args(["history", serial, "--include-simulated", "--json"])
        .output()
        .unwrap();
    let h: serde_json::Value = serde_json::from_str(&ok(&out)).unwrap();
    let cals = h["calibrations"].as_array().unwrap();
    assert_eq!(cals.len(), 2);
    assert_eq!(cals[1]["series"]["k_tempco_ppm_per_c"], 36.5);
    assert_eq!(cals[1]["series"]["u_k_tempco_ppm_per_c"], 4.0);
    let setpoints: Vec<f64> = cals[0]["series"]["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["setpoint_c"].as_f64().unwrap())
        .collect();
    assert_eq!(setpoints, vec![25.0, -20.0, 60.0, 25.0]);
    let trend = h["trends"]
        .as_array()
        .unwrap()
        .iter()
        .find(|t| t["quantity"] == "bias_tempco_dph_per_c")
        .expect("a bias sensitivity trend");
    let values: Vec<(f64, f64)> = trend["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            (
                p["value"].as_f64().unwrap(),
                p["expanded_uncertainty"].as_f64().unwrap(),
            )
        })
        .collect();
    assert_eq!(values, vec![(1.5, 0.3), (1.2, 0.3)]);

    // the page: the series table, each temperature, and the sensitivities' trend plots
    let page = tmp.path().join("history.html");
    ok(&gyrocal(&data_home)
        .args(["history", serial, "--include-simulated", "-o"])
        .arg(&page)
        .output()
        .unwrap());
    let html = std::fs::read_to_string(&page).unwrap();
    assert!(html.contains("<h2>Temperature series</h2>"), "series table");
    assert!(
        html.contains("36.50 ± 4.0"),
        "K sensitivity with U on the page"
    );
    assert!(
        html.contains("Temperature sensitivity of K (series) (ppm/°C)"),
        "its trend plot"
    );
    assert!(
        html.contains("-20.30 / -20.00 / -19.80"),
        "the cold point's temperatures"
    );
    assert!(
        !html.contains("<h2>Calibrations</h2>"),
        "no sweep table for series"
    );
}

#[test]
fn a_series_json_of_another_shape_is_refused_naming_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let data_home = tmp.path().join("data");
    let dir = tmp.path().join("runs/s1");
    series_run(&data_home, &dir, "TC-BAD", 30.0, 1.5);
    let text = std::fs::read_to_string(dir.join("series.json")).unwrap();
    std::fs::write(
        dir.join("series.json"),
        text.replace("\"k_tempco_ppm_per_c\"", "\"k_tempco\""),
    )
    .unwrap();
    let out = gyrocal(&data_home)
        .args(["catalog", "import"])
        .arg(&dir)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("series.json") && stderr.contains("k_tempco"),
        "{stderr}"
    );
}

/// A station file with the meter and the table, `chamber` appended (a `[chamber]` or nothing).
fn station_file(dir: &Path, chamber: &str) -> std::path::PathBuf {
    let path = dir.join("station.toml");
    let text = format!(
        "id = \"bench-9\"\nlab = \"Lab\"\naddress = \"1 Road\"\n\n\
         [multimeter]\nmodel = \"HP 34401A\"\nasset_id = \"DMM-07\"\nserial = \"3146A12345\"\n\
         certificate = \"C-1\"\ncalibrated = 2025-04-12\ndue = 2099-04-12\n\n\
         [table]\nmodel = \"ACL\"\nasset_id = \"RT-01\"\nserial = \"T-1\"\ncertificate = \"C-2\"\n\
         calibrated = 2024-11-07\ndue = 2099-11-07\n\n{chamber}"
    );
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn check_says_a_series_needs_the_chamber_s_record_and_its_calibration() {
    let tmp = tempfile::tempdir().unwrap();
    let data_home = tmp.path().join("data");
    let check = |station: &Path, plan: &str| {
        let out = gyrocal(&data_home)
            .args(["check", "--station"])
            .arg(station)
            .arg(config(plan))
            .output()
            .unwrap();
        ok(&out);
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    // no [chamber]: the series is warned of, the sweep is not
    let plain = station_file(tmp.path(), "");
    let said = check(&plain, "series.toml");
    assert!(
        said.contains("station bench-9")
            && said.contains("has no [chamber] section")
            && said.contains("thermal chamber"),
        "{said}"
    );
    assert!(!check(&plain, "quick.toml").contains("[chamber]"));
    // an overdue chamber: `gyrocal run` would refuse the series; said at check
    let overdue = station_file(
        tmp.path(),
        "[chamber]\nmodel = \"Espec SH-641\"\nasset_id = \"TC-03\"\nserial = \"S-1\"\n\
         certificate = \"C-3\"\ncalibrated = 2020-01-01\ndue = 2021-01-01\n",
    );
    let said = check(&overdue, "series.toml");
    assert!(
        said.contains("the chamber TC-03 was due for calibration on 2021-01-01")
            && said.contains("will refuse"),
        "{said}"
    );
    assert!(
        !said.contains("has no [chamber]"),
        "the record is there: {said}"
    );
    // the sweep on the same bench does not use the chamber: no word of it
    assert!(!check(&overdue, "quick.toml").contains("TC-03"));
}
