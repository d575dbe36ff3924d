//! A warm-up before a scale-factor sweep (`[warmup]`, IEEE 1431 §12.6): the table holds
//! 0 °/s, the readings' window means are watched until two agree within the tolerance (or the
//! maximum comes), and only then does the sweep start. Simulated bench, virtual time.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use std::path::{Path, PathBuf};

use common::{RunOutput, config, json, run_json};

/// configs/quick.toml with a gyro whose bias settles from 200 °/h over τ = 120 s and a
/// `[warmup]` section (`extra` keys appended to it).
fn plan_with_warmup(dir: &Path, extra: &str) -> PathBuf {
    let mut text = std::fs::read_to_string(config("quick.toml")).unwrap();
    text.push_str("warmup_dph = 200\nwarmup_tau_s = 120\n\n[warmup]\nwindow_s = 60\n");
    text.push_str(extra);
    let path = dir.join("plan.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn run(args: &[&str], plan_or_dir: &Path) -> (Option<i32>, serde_json::Value, String) {
    let mut all: Vec<&dyn AsRef<std::ffi::OsStr>> = args
        .iter()
        .filter(|a| **a != "--json")
        .map(|a| a as &dyn AsRef<std::ffi::OsStr>)
        .collect();
    all.push(&plan_or_dir);
    let RunOutput { code, doc, stderr } = run_json(&all);
    (code, doc, stderr)
}

/// `t_start_s` of the first step in steps.csv.
fn first_step_start(dir: &Path) -> f64 {
    let mut r = csv::Reader::from_path(dir.join("steps.csv")).unwrap();
    let col = r
        .headers()
        .unwrap()
        .iter()
        .position(|c| c == "t_start_s")
        .unwrap();
    r.records()
        .map(|rec| rec.unwrap()[col].parse::<f64>().unwrap())
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn the_sweep_waits_for_the_warm_up() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = plan_with_warmup(tmp.path(), "max_s = 1800\n");
    let out = tmp.path().join("run");
    let (code, doc, stderr) = run(
        &["--simulate", "--json", "--out", out.to_str().unwrap()],
        &plan,
    );
    assert_eq!(code, Some(0), "{stderr}");
    assert_eq!(doc["table"]["at_rest"], true);
    let w = &doc["warmup"];
    assert_eq!(w["mode"], "before_sweep");
    assert_eq!(w["complete"], true, "{w}");
    assert_eq!(w["ended_by"], "criterion");
    // 0.02 V · e^(−t/120) settles below the white-noise tolerance (≈ 1.1e-4 V for σ 2 mV
    // over 60 s windows) at t ≈ 510 s; the pair starts a window earlier
    let time = w["time_s"].as_f64().unwrap();
    assert!((360.0..=900.0).contains(&time), "warm-up {time} s");
    assert!(stderr.contains("warm-up complete after"), "{stderr}");
    // the sweep began after it: the warm-up's start + its time + the window that confirmed it
    let started = w["started_s"].as_f64().unwrap();
    let first = first_step_start(&out);
    assert!(
        first >= started + time + 60.0,
        "first step at {first} s, warm-up {started} + {time} s"
    );
    // and the calibration is the settled gyro's: its bias is that of the same gyro without a
    // warm-up transient, while the same sweep started cold carries the transient's offset
    let bias = |dir: &Path| {
        json(dir, "fit.json")["metrics"]["bias_volts"]
            .as_f64()
            .unwrap()
    };
    let warm = bias(&out);
    let settled_plan = tmp.path().join("settled.toml");
    std::fs::write(
        &settled_plan,
        std::fs::read_to_string(&plan)
            .unwrap()
            .replace("warmup_dph = 200", "warmup_dph = 0"),
    )
    .unwrap();
    let cold_plan = tmp.path().join("cold.toml");
    let text = std::fs::read_to_string(&plan).unwrap();
    let cold = text.split("[warmup]").next().unwrap();
    std::fs::write(&cold_plan, cold).unwrap();
    let other = |p: &Path, name: &str| {
        let dir = tmp.path().join(name);
        let (code, _, stderr) = run(&["--simulate", "--json", "--out", dir.to_str().unwrap()], p);
        assert_eq!(code, Some(0), "{stderr}");
        bias(&dir)
    };
    let settled = other(&settled_plan, "settled");
    let cold = other(&cold_plan, "cold");
    assert!(
        (warm - settled).abs() < 3e-4,
        "bias after the warm-up {warm} V, settled gyro {settled} V"
    );
    assert!(
        (cold - settled).abs() > 1e-3,
        "a cold start shows the transient: {cold} V vs {settled} V"
    );
    // the manifest keeps the warm-up curve
    let m = json(&out, "manifest.json");
    assert!(m["warmup"]["means"].as_array().unwrap().len() >= 3);
}

#[test]
fn a_warm_up_that_never_settles_ends_at_its_maximum_and_says_so() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = plan_with_warmup(tmp.path(), "tolerance_v = 1e-9\nmax_s = 240\n");
    let out = tmp.path().join("run");
    let (code, doc, stderr) = run(
        &["--simulate", "--json", "--out", out.to_str().unwrap()],
        &plan,
    );
    assert_eq!(code, Some(0), "{stderr}");
    let w = &doc["warmup"];
    assert_eq!(w["ended_by"], "max", "{w}");
    assert_eq!(w["tolerance_source"], "plan");
    let time = w["time_s"].as_f64().unwrap();
    assert!((time - 240.0).abs() < 5.0, "{time}");
    assert!(stderr.contains("WITHOUT settling"), "{stderr}");
}

#[test]
fn a_table_fault_during_the_warm_up_ends_at_rest_and_the_resume_warms_up_again() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = plan_with_warmup(tmp.path(), "max_s = 1800\n");
    let out = tmp.path().join("run");
    let (code, doc, stderr) = run(
        &[
            "--simulate",
            "--json",
            "--sim-fault",
            "table:fault@t=150s",
            "--out",
            out.to_str().unwrap(),
        ],
        &plan,
    );
    assert_ne!(code, Some(0), "{stderr}");
    assert_eq!(doc["status"], "failed", "{doc}");
    assert_eq!(doc["table"]["at_rest"], true, "{}", doc["table"]);
    assert_eq!(doc["steps_done"], 0);
    assert_eq!(doc["warmup"]["complete"], false, "{}", doc["warmup"]);
    let first_start = doc["warmup"]["started_s"].as_f64().unwrap();
    let (code, doc, stderr) = run(
        &["--simulate", "--json", "--resume", out.to_str().unwrap()],
        &plan,
    );
    assert_eq!(code, Some(0), "{stderr}");
    assert_eq!(doc["table"]["at_rest"], true);
    assert_eq!(doc["status"], "complete");
    let w = &doc["warmup"];
    assert_eq!(w["complete"], true, "{w}");
    assert!(w["started_s"].as_f64().unwrap() > first_start, "{w}");
}
