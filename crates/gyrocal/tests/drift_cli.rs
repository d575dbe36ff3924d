//! Drift plans (`[plan] kind = "drift"`) as a lab runs them: a static record at rest in
//! durable segments, killed and resumed, ending with the table at rest.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use std::path::Path;
use std::time::{Duration, Instant};

use common::steps_done as segments_done;
use common::{RunOutput, config, gyrocal, json, run_json};

/// configs/drift.toml, shortened to `segments` segments of `readings` readings.
fn short_drift(dir: &Path, segments: u32, readings: u32) -> std::path::PathBuf {
    common::plans::write(dir, "drift.toml", &common::plans::drift(segments, readings))
}

/// `t_s` of every reading, in file order.
fn times(dir: &Path) -> Vec<f64> {
    let mut r = csv::Reader::from_path(dir.join("samples.csv")).unwrap();
    let i = r
        .headers()
        .unwrap()
        .iter()
        .position(|c| c == "t_s")
        .unwrap();
    r.records()
        .map(|rec| rec.unwrap()[i].parse().unwrap())
        .collect()
}

#[test]
fn a_drift_plan_is_a_record_at_rest_not_a_sweep() {
    let tmp = tempfile::tempdir().unwrap();
    // every rate must be 0
    let bad = tmp.path().join("bad.toml");
    std::fs::write(
        &bad,
        std::fs::read_to_string(config("drift.toml"))
            .unwrap()
            .replace("rates_dps = [0]", "rates_dps = [0, 5]"),
    )
    .unwrap();
    let o = gyrocal().arg("check").arg(&bad).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("rates_dps") && err.contains("drift"), "{err}");
    // an unknown kind is named with the two there are
    std::fs::write(
        &bad,
        std::fs::read_to_string(config("drift.toml"))
            .unwrap()
            .replace("kind = \"drift\"", "kind = \"drfit\""),
    )
    .unwrap();
    let o = gyrocal().arg("check").arg(&bad).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("plan.kind") || err.contains("kind"), "{err}");
    assert!(
        err.contains("scale_factor") && err.contains("drift"),
        "{err}"
    );
    // the full 3-hour plan is estimated at about 3 h
    let o = gyrocal()
        .args(["check", "--json"])
        .arg(config("drift.toml"))
        .output()
        .unwrap();
    assert!(o.status.success());
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let s = doc["estimated_s"].as_f64().expect("estimated_s");
    assert!((3.0 * 3600.0..3.3 * 3600.0).contains(&s), "{s} s");
}

#[test]
fn a_killed_drift_record_resumes_with_a_gap_and_the_table_at_rest() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = short_drift(tmp.path(), 16, 300);
    let out = tmp.path().join("run");
    // paced so the kill lands part-way (16 × 300 readings ≈ 100 s of run clock)
    let mut child = gyrocal()
        .arg("run")
        .arg(&plan)
        .args(["--simulate", "--sim-time-scale", "100", "--out"])
        .arg(&out)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    while segments_done(&out) < 4 {
        assert!(t0.elapsed() < Duration::from_secs(60), "no progress");
        if child.try_wait().unwrap().is_some() {
            panic!("the run ended before it was killed");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap(); // SIGKILL: no chance to clean up
    child.wait().unwrap();
    let kept = segments_done(&out);
    assert!((4..16).contains(&kept), "{kept} segments kept");

    let RunOutput { code, doc, stderr } = run_json(&[&"--simulate", &"--resume", &out]);
    assert_eq!(code, Some(0), "{stderr}");
    assert_eq!(doc["status"], "complete");
    assert_eq!(doc["table"]["at_rest"], true, "{doc:#}");
    let m = json(&out, "manifest.json");
    assert_eq!(m["resumes"].as_array().unwrap().len(), 1);
    // every finished segment is there once; the interruption is a gap in t_s
    assert_eq!(segments_done(&out), 16);
    let t = times(&out);
    assert_eq!(t.len(), 16 * 300, "no reading lost or doubled");
    let dts: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    let mut sorted = dts.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    let back: Vec<(usize, f64, f64)> = t
        .windows(2)
        .enumerate()
        .filter(|(_, w)| w[1] <= w[0])
        .map(|(i, w)| (i, w[0], w[1]))
        .collect();
    assert!(
        back.is_empty(),
        "time runs forward across the resume: {back:?}"
    );
    let gaps = dts.iter().filter(|d| **d > 10.0 * median).count();
    assert!(
        gaps >= 1,
        "the resume shows as a gap (median interval {median} s)"
    );
    // no scale-factor fit for a record at rest
    assert!(!out.join("fit.json").exists());
}

#[test]
fn a_three_hour_simulated_drift_run_survives_a_kill_and_its_allan_analysis_finds_the_gyro() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("run");
    // the whole 3-hour plan in virtual time, killed part-way at full speed
    let mut child = gyrocal()
        .arg("run")
        .arg(config("drift.toml"))
        .args(["--simulate", "--out"])
        .arg(&out)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    while segments_done(&out) < 40 {
        assert!(t0.elapsed() < Duration::from_secs(120), "no progress");
        if child.try_wait().unwrap().is_some() {
            panic!("the run ended before it was killed");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(segments_done(&out) < 167, "killed part-way");
    let RunOutput { code, doc, stderr } = run_json(&[&"--simulate", &"--resume", &out]);
    assert_eq!(code, Some(0), "{stderr}");
    assert_eq!(doc["status"], "complete");
    assert_eq!(doc["table"]["at_rest"], true);
    assert!(t0.elapsed() < Duration::from_secs(90), "seconds, not hours");
    // the run wrote its Allan analysis; the record is analysed whole (segments joined)
    assert!(out.join("allan.html").is_file());
    let a = json(&out, "allan.json");
    assert_eq!(a["unit"], "deg/h", "{}", a["unit"]);
    // the plan's [drift] axis and latitude: the run's own analysis removes the Earth rate
    assert_eq!(a["earth_rate"]["axis"], "up", "{}", a["earth_rate"]);
    let analysed = a["analysed"]["samples"].as_u64().unwrap();
    assert!(analysed > 400_000, "{analysed} samples analysed of 501000");
    // configs/drift.toml's gyro: ARW 0.02 °/√h, bias instability 1 °/h, RRW 3 °/h/√h: the
    // five-term fit finds all three within their 95 % interval taken jointly (Bonferroni: three
    // intervals of 98.3 %, k = 2.39 on the standard uncertainty; three separate 95 % intervals
    // would miss one in seven records of a true gyro). This record's bias instability is
    // 2.02 σ off since its first 240 s are no longer cut as a false warm-up.
    let nt = &a["noise_terms"];
    let fitted = nt["fit"]["terms"].as_array().expect("a five-term fit");
    for (term, set) in [
        ("angle_random_walk", 0.02),
        ("bias_instability", 1.0),
        ("rate_random_walk", 3.0),
    ] {
        let q = &fitted
            .iter()
            .find(|t| t["term"] == term)
            .unwrap_or_else(|| panic!("{term} fitted"))["value"];
        let (v, u) = (
            q["value"].as_f64().unwrap(),
            q["uncertainty"].as_f64().unwrap(),
        );
        assert!(
            (v - set).abs() <= JOINT_95_K * u && u < 0.3 * set,
            "fit {term}: {v} ± {u} (1σ), set {set}"
        );
    }
    // the Earth rate along the vertical axis at 45° N is removed from the bias: what is left
    // is the simulated gyro's own bias, K0/K = 0.0088/0.3612 × 3600 = 87.7 °/h (its bias
    // instability and rate random walk move the mean of one record by a few °/h)
    let o = gyrocal()
        .arg("allan")
        .arg(&out)
        .args(["--json", "--axis", "up", "--latitude", "45"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let e: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let e = &e["earth_rate"];
    let component = e["component_dph"].as_f64().unwrap();
    assert!((component - 15.041 * 45f64.to_radians().sin()).abs() < 1e-9);
    let (measured, own) = (
        e["bias_measured_dph"].as_f64().unwrap(),
        e["bias_dph"].as_f64().unwrap(),
    );
    let truth = 0.0088 / 0.3612 * 3600.0;
    assert!(
        (own - truth).abs() < 5.0 && (own - truth).abs() < (measured - truth).abs(),
        "bias {measured} °/h measured, {own} °/h without the Earth rate, gyro's own {truth}"
    );
    // and the slope reads where the curve has a region of the term's slope. Bias instability is
    // read at the curve's minimum, where the angle and rate random walks add to the flicker
    // floor: what it reads for a true gyro is that minimum ÷ 0.664, not the set B (here 7.6 %
    // above it, a property of the method, not of this record)
    for (term, set) in [
        ("angle_random_walk", 0.02),
        ("bias_instability", b_read_at_minimum(0.02, 1.0, 3.0)),
    ] {
        let q = &nt[term]["value"];
        let (v, u) = (
            q["value"].as_f64().unwrap(),
            q["uncertainty"].as_f64().unwrap(),
        );
        assert!(
            (v - set).abs() <= JOINT_95_K * u && u < 0.2 * set,
            "{term}: {v} ± {u} (1σ), set {set}"
        );
    }
}

/// What reading bias instability at the Allan curve's minimum gives for a gyro of angle random
/// walk `n` °/√h, bias instability `b` °/h and rate random walk `k` °/h/√h: the minimum over τ of
/// σ(τ)² = (60 n)²/τ + (0.664 b)² + k² (τ/3600)/3, divided by 0.664 (IEEE 952 Annex C).
fn b_read_at_minimum(n: f64, b: f64, k: f64) -> f64 {
    let sigma2 =
        |tau: f64| (60.0 * n).powi(2) / tau + (0.664 * b).powi(2) + k * k * tau / 3600.0 / 3.0;
    let min = (0..4000)
        .map(|i| 10f64.powf(-2.0 + i as f64 * 6.0 / 4000.0))
        .map(sigma2)
        .fold(f64::INFINITY, f64::min);
    min.sqrt() / 0.664
}

/// The coverage factor of three intervals that hold together 95 % of the time (Bonferroni:
/// each 1 − 0.05/3 two-sided, z = 2.394).
const JOINT_95_K: f64 = 2.394;

/// configs/drift.toml shortened to 40 segments (≈ 44 min), with a gyro whose bias settles
/// from 200 °/h over τ = 120 s, a warm-up criterion and the table's servo off.
fn servo_off_drift(dir: &Path) -> std::path::PathBuf {
    let path = short_drift(dir, 40, 3000);
    // configs/drift.toml's [drift] already names the axis (up) and the latitude (45° N)
    let mut text = std::fs::read_to_string(&path)
        .unwrap()
        .replace("table = \"hold\"", "table = \"servo_off\"");
    text.push_str(
        "warmup_dph = 200\nwarmup_tau_s = 120\n\n[warmup]\nwindow_s = 60\nmax_s = 1800\n",
    );
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn a_drift_record_with_the_servo_off_finds_its_warm_up_while_it_records() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = servo_off_drift(tmp.path());
    let out = tmp.path().join("run");
    let RunOutput { code, doc, stderr } = run_json(&[&plan, &"--simulate", &"--out", &out]);
    assert_eq!(code, Some(0), "{stderr}");
    assert_eq!(doc["status"], "complete");
    assert_eq!(doc["table"]["at_rest"], true, "{}", doc["table"]);
    // the operator saw the warm-up end and the running deviation
    assert!(stderr.contains("warm-up complete after"), "{stderr}");
    assert!(stderr.contains("running ADEV at τ"), "{stderr}");
    // the warm-up: 200 °/h decaying over 120 s is 0.02 V · e^(−t/120); consecutive 60 s means
    // differ by 0.0079 V · e^(−t/120), below the readings' white-noise tolerance (≈ 4e-5 V)
    // from t ≈ 630 s; the flicker noise of the settled gyro can delay it by a few windows
    let w = &doc["warmup"];
    assert_eq!(w["complete"], true, "{w}");
    assert_eq!(w["mode"], "in_record");
    assert_eq!(w["ended_by"], "criterion", "{w}");
    let time = w["time_s"].as_f64().unwrap();
    assert!((480.0..=1200.0).contains(&time), "warm-up {time} s");
    // the servo was off: every segment's table rate is at rest, the table OFF at the end
    let mut r = csv::Reader::from_path(out.join("steps.csv")).unwrap();
    let col = r
        .headers()
        .unwrap()
        .iter()
        .position(|c| c == "rate_meas_max_dps")
        .unwrap();
    let mut rows = 0;
    for rec in r.records() {
        let v: f64 = rec.unwrap()[col].parse().unwrap();
        assert!(v.abs() < 0.005, "table moved: {v} °/s");
        rows += 1;
    }
    assert_eq!(rows, 40);
    assert!(stderr.contains("mode OFF"), "{stderr}");
    // the servo was switched off (the interlock opened, the controller's orderly shutdown)
    // and never switched on again
    assert_eq!(
        doc["simulated_bench"]["table"]["interlock_closed"], false,
        "{}",
        doc["simulated_bench"]
    );
    // the run's Allan analysis cuts the same warm-up (the criterion and tolerance the run
    // used, applied to the whole record) and removes the Earth rate the plan's axis sees
    let a = json(&out, "allan.json");
    let cut = a["warmup"]["time_s"].as_f64().unwrap();
    assert!((cut - time).abs() <= 61.0, "analysis {cut} s, run {time} s");
    // the page says whose record it is, and that it is simulated
    assert_eq!(a["run"]["dut_serial"], "SIM-GYRO-11", "{}", a["run"]);
    assert!(a["run"]["table"].as_str().unwrap().contains("servo off"));
    let page = std::fs::read_to_string(out.join("allan.html")).unwrap();
    assert!(page.contains("id=\"simulated\""), "banner");
    assert!(page.contains("<strong id=\"dut-serial\">SIM-GYRO-11</strong>"));
    // `gyrocal report` on a drift run writes its Allan page, not a scale-factor certificate
    std::fs::remove_file(out.join("allan.html")).unwrap();
    let o = gyrocal()
        .arg("report")
        .arg(&out)
        .args(["--json"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(r["kind"], "drift");
    assert!(out.join("allan.html").is_file());
    assert!(
        !out.join("report.html").exists(),
        "no line fitted to a record at rest"
    );
    let o = gyrocal()
        .arg("report")
        .arg(&out)
        .args(["-o"])
        .arg(tmp.path().join("x.html"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("gyrocal allan"));
    let e = &a["earth_rate"];
    assert_eq!(e["axis"], "up");
    let component = e["component_dph"].as_f64().unwrap();
    assert!((component - 15.041 * 45f64.to_radians().sin()).abs() < 1e-9);
    let truth = 0.0088 / 0.3612 * 3600.0;
    let own = e["bias_dph"].as_f64().unwrap();
    assert!(
        (own - truth).abs() < 5.0,
        "bias {own} °/h, gyro's own {truth}"
    );
}

#[test]
fn a_table_fault_during_a_servo_off_drift_record_ends_with_the_table_at_rest_and_resumes() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = servo_off_drift(tmp.path());
    let out = tmp.path().join("run");
    let o = gyrocal()
        .arg("run")
        .arg(&plan)
        .args([
            "--simulate",
            "--json",
            "--sim-fault",
            "table:fault@t=300s",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_ne!(o.status.code(), Some(0), "{stderr}");
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(doc["status"], "failed", "{doc}");
    assert_eq!(doc["table"]["at_rest"], true, "{}", doc["table"]);
    // the warm-up was not over: the resume watches it again, and the record completes
    assert_eq!(doc["warmup"]["complete"], false, "{}", doc["warmup"]);
    let done = segments_done(&out);
    assert!((3..40).contains(&done), "{done} segments before the fault");
    let RunOutput { code, doc, stderr } = run_json(&[&"--simulate", &"--resume", &out]);
    assert_eq!(code, Some(0), "{stderr}");
    assert_eq!(doc["table"]["at_rest"], true);
    assert_eq!(doc["warmup"]["complete"], true, "{}", doc["warmup"]);
    assert_eq!(segments_done(&out), 40);
}

/// configs/drift.toml on a bench without a table: `[drift] table = "none"`, no `[table]`.
fn tableless_drift(dir: &Path, segments: u32) -> std::path::PathBuf {
    let path = short_drift(dir, segments, 3000);
    let text = std::fs::read_to_string(&path).unwrap();
    let start = text.find("\n[table]").unwrap();
    let end = text[start..].find("\n[dmm]").unwrap() + start;
    let text = format!("{}{}", &text[..start], &text[end..])
        .replace("table = \"hold\"", "table = \"none\"");
    assert!(!text.lines().any(|l| l.trim() == "[table]"));
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn a_drift_record_on_a_bench_without_a_table_opens_no_table() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = tableless_drift(tmp.path(), 10);
    let o = gyrocal().arg("check").arg(&plan).output().unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(text.contains("table: none"), "{text}");
    let o = gyrocal()
        .args(["check", "--json"])
        .arg(&plan)
        .output()
        .unwrap();
    let check: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(check["table"].is_null(), "{}", check["table"]);
    assert_eq!(check["drift"]["table"], "none");
    let out = tmp.path().join("run");
    let RunOutput { code, doc, stderr } = run_json(&[&plan, &"--simulate", &"--out", &out]);
    assert_eq!(code, Some(0), "{stderr}");
    assert_eq!(doc["status"], "complete");
    assert_eq!(doc["table"]["none"], true, "{}", doc["table"]);
    assert!(stderr.contains("no rate table in this plan"), "{stderr}");
    assert!(
        !stderr.contains("table at rest"),
        "never claims a rest it did not see"
    );
    // no table rate was measured: the segments' table columns are empty, not 0
    let mut r = csv::Reader::from_path(out.join("steps.csv")).unwrap();
    let col = r
        .headers()
        .unwrap()
        .iter()
        .position(|c| c == "rate_meas_dps")
        .unwrap();
    let rows: Vec<_> = r.records().map(|x| x.unwrap()[col].to_string()).collect();
    assert_eq!(rows.len(), 10);
    assert!(rows.iter().all(String::is_empty), "{rows:?}");
    // the record is analysed as any other
    let a = json(&out, "allan.json");
    assert_eq!(a["unit"], "deg/h");
    assert_eq!(a["earth_rate"]["axis"], "up");
    // on instruments only the meter is opened: a missing meter is the only thing named
    let o = gyrocal()
        .arg("run")
        .arg(&plan)
        .args(["--dmm-port", "/dev/gyrocal-no-such-meter", "--out"])
        .arg(tmp.path().join("real"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_ne!(o.status.code(), Some(0), "{err}");
    assert!(err.contains("gyrocal-no-such-meter"), "{err}");
    assert!(!err.contains("rate table at"), "{err}");
}

#[test]
fn a_meter_fault_in_a_record_without_a_table_fails_cleanly_and_resumes() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = tableless_drift(tmp.path(), 10);
    let out = tmp.path().join("run");
    let o = gyrocal()
        .arg("run")
        .arg(&plan)
        .args([
            "--simulate",
            "--json",
            "--sim-fault",
            "dmm:disconnect@reading10000",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_ne!(o.status.code(), Some(0), "{stderr}");
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(doc["status"], "failed", "{doc}");
    assert_eq!(doc["table"]["none"], true);
    assert_eq!(
        segments_done(&out),
        3,
        "the segments before the fault are kept"
    );
    let RunOutput { code, stderr, .. } = run_json(&[&"--simulate", &"--resume", &out]);
    assert_eq!(code, Some(0), "{stderr}");
    assert_eq!(segments_done(&out), 10);
}

/// `gyrocal check` of the 3 h drift plan summarises its 167 identical segments in three lines
/// (the first, the range, the last) instead of 167 rows; `--json` still lists every step.
#[test]
fn check_of_a_drift_plan_summarises_its_identical_segments() {
    let o = gyrocal()
        .arg("check")
        .arg(config("drift.toml"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("… steps 2–166 the same as step 1"), "{text}");
    let rows = text
        .lines()
        // a step row: step, pass, rate, samples, ramp, dwell, acquire, at
        .filter(|l| {
            l.split_whitespace().count() == 8
                && l.split_whitespace().all(|f| f.parse::<f64>().is_ok())
        })
        .count();
    assert_eq!(rows, 2, "{text}");
    assert!(text.contains("167 steps, 501000 readings"), "{text}");
    let o = gyrocal()
        .arg("check")
        .arg(config("drift.toml"))
        .arg("--json")
        .output()
        .unwrap();
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(doc["steps"].as_array().unwrap().len(), 167);
}
