//! `gyrocal report` as a user runs it: files written, default output in a run directory, and
//! one-line errors naming the file with exit code 2 (never a panic).

// Helpers outside #[test] functions may unwrap too: a panic there is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::path::{Path, PathBuf};
use std::process::Output;

/// `gyrocal ARGS` run to its end, through tests/common.
use common::gyrocal_output as gyrocal;

use gyrocal_files::{Plan, RunDir, RunMeta, Sample, Status, StepRecord};

fn example() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/paper-shaped.csv")
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn assert_user_error(out: &Output, must_name: &str) {
    let err = stderr(out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains(must_name), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "one line: {err}");
}

/// A small complete run: 5 rates, 3 readings each, no fit.json (the report fits it).
fn small_run(dir: &Path) {
    let plan = Plan::from_toml_str(
        &common::plans::sweep("cli test", &[0.0, 5.0, -5.0, 10.0, -10.0], 3),
        Path::new("cli.toml"),
    )
    .unwrap();
    let mut rd = RunDir::create(
        dir,
        &plan,
        RunMeta {
            gyrocal_version: "test".into(),
            ..RunMeta::default()
        },
    )
    .unwrap();
    let schedule = rd.schedule().to_vec();
    for (i, s) in schedule.iter().enumerate() {
        let w = s.rate_dps;
        let v = [
            0.0088 + 0.3612 * w + 1e-4,
            0.0088 + 0.3612 * w - 1e-4,
            0.0088 + 0.3612 * w,
        ];
        let samples: Vec<Sample> = v
            .iter()
            .enumerate()
            .map(|(j, &v)| Sample {
                index: j as u64,
                t_s: i as f64 + j as f64 * 0.1,
                volts: Some(v + 1e-5 * w * w),
            })
            .collect();
        rd.append_samples(s.index, &samples).unwrap();
        rd.append_step(StepRecord {
            step: s.index,
            pass: s.pass,
            rate_dps: w,
            rate_meas_dps: None,
            rate_meas_std_dps: None,
            rate_meas_min_dps: None,
            rate_meas_max_dps: None,
            rate_samples: None,
            volts: 0.0088 + 0.3612 * w + 1e-5 * w * w,
            volts_std: Some(1e-4),
            n: 3,
            overloads: 0,
            retries: 0,
            t_start_s: i as f64,
            t_end_s: i as f64 + 0.3,
            series: None,
        })
        .unwrap();
    }
    rd.finish(Status::Complete, None, 5.0).unwrap();
}

#[test]
fn report_of_a_steps_csv_writes_the_html_and_the_plots() {
    let tmp = tempfile::tempdir().unwrap();
    let out_path = tmp.path().join("out").join("cal.html");
    std::fs::create_dir_all(out_path.parent().unwrap()).unwrap();
    let out = gyrocal(&[
        "report",
        example().to_str().unwrap(),
        "--out",
        out_path.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let html = std::fs::read_to_string(&out_path).unwrap();
    assert!(html.contains("id=\"summary\""));
    for f in [
        "fit.svg",
        "residuals.svg",
        "training.svg",
        "surface.svg",
        "noise.svg",
    ] {
        assert!(out_path.with_file_name(f).is_file(), "{f}");
    }
    assert!(String::from_utf8_lossy(&out.stdout).contains("cal.html"));
}

#[test]
fn report_of_a_run_directory_defaults_to_report_html_in_it() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    small_run(&dir);
    let out = gyrocal(&["report", dir.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(html.contains("cli test"));
    assert!(dir.join("surface.svg").is_file());
}

#[test]
fn missing_input_exits_2_naming_it() {
    let out = gyrocal(&["report", "/nonexistent/run-7"]);
    assert_user_error(&out, "/nonexistent/run-7");
}

#[test]
fn malformed_csv_exits_2_naming_the_file_and_line() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("bad-steps.csv");
    std::fs::write(&path, "rate_dps,volts\n0,0.0088\n1,oops\n-1,-0.35\n").unwrap();
    let out = gyrocal(&[
        "report",
        path.to_str().unwrap(),
        "--out",
        tmp.path().join("r.html").to_str().unwrap(),
    ]);
    assert_user_error(&out, "bad-steps.csv");
    assert!(stderr(&out).contains("line 3"), "{}", stderr(&out));
    assert!(!tmp.path().join("r.html").exists());
}

#[test]
fn run_directory_without_steps_csv_exits_2_naming_it() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    small_run(&dir);
    std::fs::remove_file(dir.join("steps.csv")).unwrap();
    let out = gyrocal(&["report", dir.to_str().unwrap()]);
    assert_user_error(&out, "steps.csv");
}

/// configs/quick.toml with `rates_dps` replaced, written into `dir`.
fn plan_with_rates(dir: &Path, rates: &str) -> PathBuf {
    common::plans::write(dir, "plan.toml", &common::plans::quick_with_rates(rates))
}

/// Checks the plan (which must warn about `model`), runs it on the simulated bench (which must
/// complete with exit 0) and returns the run directory.
fn run_skipping(tmp: &Path, rates: &str, model: &str) -> PathBuf {
    let plan = plan_with_rates(tmp, rates);
    let out = gyrocal(&["check", plan.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(
        err.contains("warning:")
            && err.contains("plan.toml")
            && err.contains(&format!("the fit will skip the {model} model")),
        "{err}"
    );
    let dir = tmp.join("run");
    let out = gyrocal(&[
        "run",
        plan.to_str().unwrap(),
        "--simulate",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains(&format!("not fitted: {model} — ")), "{text}");
    dir
}

#[test]
fn a_complete_run_with_three_rates_fits_reports_and_names_the_skipped_cubic() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = run_skipping(tmp.path(), "[0, 10, -10]", "cubic");
    let fit: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("fit.json")).unwrap()).unwrap();
    assert_eq!(fit["skipped"][0]["model"], "cubic");
    assert_eq!(fit["skipped"].as_array().unwrap().len(), 1);
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(
        html.contains(
            "not fitted: cubic — the cubic model has 4 coefficients and needs at least 4 distinct rates; the data have 3"
        ),
        "report.html does not name the skipped model"
    );
    // The same data as a bare CSV, through the report's own fit.
    let out = gyrocal(&[
        "report",
        dir.join("steps.csv").to_str().unwrap(),
        "--out",
        tmp.path().join("csv.html").to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let html = std::fs::read_to_string(tmp.path().join("csv.html")).unwrap();
    assert!(html.contains("not fitted: cubic — "));
}

#[test]
fn a_complete_run_in_one_direction_fits_and_says_why_there_is_no_asymmetry() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = run_skipping(tmp.path(), "[0, 1, 10, 15]", "split");
    let fit: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("fit.json")).unwrap()).unwrap();
    assert_eq!(fit["skipped"][0]["model"], "split");
    assert!(fit["metrics"]["asymmetry_ppm"].is_null());
    assert_eq!(fit["metrics"]["not_computed"][0]["metric"], "asymmetry_ppm");
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(html.contains("not fitted: split — the split model needs both turning directions"));
    assert!(html.contains("Not computed: needs the split model"));
}

#[test]
fn a_run_directory_left_half_created_is_reused_by_out_and_by_resume() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = plan_with_rates(tmp.path(), "[0, 10, -10, 1, -1]");
    // What an interrupted creation leaves: the lock and the CSV headers, no manifest.
    let half = |name: &str| {
        let dir = tmp.path().join(name);
        std::fs::create_dir(&dir).unwrap();
        std::fs::write(dir.join(".lock"), b"").unwrap();
        std::fs::write(dir.join("samples.csv"), b"").unwrap();
        // a torn header
        std::fs::write(dir.join("steps.csv"), b"step,pass").unwrap();
        dir
    };
    for (name, flag) in [("again", "--out"), ("resumed", "--resume")] {
        let dir = half(name);
        let out = gyrocal(&[
            "run",
            plan.to_str().unwrap(),
            "--simulate",
            flag,
            dir.to_str().unwrap(),
        ]);
        assert_eq!(out.status.code(), Some(0), "{flag}: {}", stderr(&out));
        let m: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.join("manifest.json")).unwrap()).unwrap();
        assert_eq!(m["status"], "complete", "{flag}");
        assert_eq!(m["steps_done"].as_array().unwrap().len(), 5, "{flag}");
        assert!(dir.join("fit.json").is_file() && dir.join("report.html").is_file());
    }
}

#[test]
fn check_refuses_endless_and_out_of_range_plans_with_exit_2() {
    let started = std::time::Instant::now();
    let out = gyrocal(&["check", "/dev/zero"]);
    assert_user_error(&out, "/dev/zero: cannot read the plan");
    assert!(stderr(&out).contains("a device"), "{}", stderr(&out));
    assert!(started.elapsed() < std::time::Duration::from_secs(20));
    let tmp = tempfile::tempdir().unwrap();
    let plan = plan_with_rates(tmp.path(), "[0, 1, -1, 10, -10]");
    let text = std::fs::read_to_string(&plan)
        .unwrap()
        .replace("samples_per_rate = 50", "samples_per_rate = 1000000000000");
    std::fs::write(&plan, text).unwrap();
    let out = gyrocal(&["check", plan.to_str().unwrap()]);
    assert_user_error(
        &out,
        "[plan] samples_per_rate = 1000000000000 is out of range: write a whole number from 1 to 1000000",
    );
    assert!(stderr(&out).contains("plan.toml:"), "{}", stderr(&out));
}

#[test]
fn report_of_an_endless_input_exits_2_at_once() {
    let started = std::time::Instant::now();
    let out = gyrocal(&["report", "/dev/zero", "--out", "/nonexistent/r.html"]);
    assert_user_error(&out, "/dev/zero: not a run directory or a regular file");
    assert!(started.elapsed() < std::time::Duration::from_secs(20));
}

#[test]
fn report_input_with_a_duplicated_column_exits_2_naming_both() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("dup.csv");
    std::fs::write(&path, "rate_dps,volts,rate_dps\n0,0.0088,0\n1,0.37,1\n").unwrap();
    let out = gyrocal(&[
        "report",
        path.to_str().unwrap(),
        "--out",
        tmp.path().join("r.html").to_str().unwrap(),
    ]);
    assert_user_error(
        &out,
        "dup.csv: line 1: the header names column `rate_dps` twice (columns 1 and 3)",
    );
}

#[test]
fn a_run_whose_directory_fails_half_way_leaves_nothing_behind() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = plan_with_rates(tmp.path(), "[0, 1, -1, 10, -10]");
    // A path whose lock and CSV files can be created but whose manifest cannot (its temporary
    // file's path exceeds PATH_MAX): the creation fails half way, as on a full disk.
    let base = tmp.path().join("runs");
    let mut dir = base.clone();
    while dir.as_os_str().len() + 201 < 4080 {
        dir.push("d".repeat(200));
    }
    let rest = 4080 - dir.as_os_str().len() - 1;
    dir.push("r".repeat(rest));
    let out = gyrocal(&[
        "run",
        plan.to_str().unwrap(),
        "--simulate",
        "--out",
        dir.to_str().unwrap(),
    ]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains(".manifest.json.tmp"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(!base.exists(), "the failed creation left files behind");
}
