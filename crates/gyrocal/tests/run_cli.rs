//! `gyrocal run` and `gyrocal check` as a user runs them: the binary, the simulated bench in
//! virtual time, signals, resume, and bad plans.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

use common::{config, final_table_state, gyrocal, manifest, steps_done};

/// (step_no, sample_no) of every sample row (counted from 1, as the files count).
fn samples(dir: &Path) -> Vec<(usize, u64)> {
    let mut r = csv::Reader::from_path(dir.join("samples.csv")).unwrap();
    let h = r.headers().unwrap().clone();
    let si = h.iter().position(|c| c == "step_no").unwrap();
    let ii = h.iter().position(|c| c == "sample_no").unwrap();
    r.records()
        .map(|rec| {
            let rec = rec.unwrap();
            (rec[si].parse().unwrap(), rec[ii].parse().unwrap())
        })
        .collect()
}

/// The steps recorded in steps.csv, sorted, as 0-based schedule indices (the file's
/// `step_no` counts from 1: its first column, minus one).
fn step_indices(dir: &Path) -> Vec<usize> {
    let mut r = csv::Reader::from_path(dir.join("steps.csv")).unwrap();
    assert_eq!(&r.headers().unwrap()[0], "step_no");
    let mut v: Vec<usize> = r
        .records()
        .map(|rec| rec.unwrap()[0].parse::<usize>().unwrap() - 1)
        .collect();
    v.sort_unstable();
    v
}

fn spawn_run(plan: &Path, args: &[&str]) -> Child {
    gyrocal()
        .arg("run")
        .arg(plan)
        .arg("--simulate")
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Waits until `dir` has at least `k` finished steps, then sends `sig`.
fn interrupt_after(child: &mut Child, dir: &Path, k: usize, sig: Signal) {
    let t0 = Instant::now();
    while steps_done(dir) < k {
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "run did not reach step {k}"
        );
        if let Some(status) = child.try_wait().unwrap() {
            panic!("run ended early with {status}");
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    kill(Pid::from_raw(child.id() as i32), sig).unwrap();
}

/// `gyrocal run PLAN --simulate --resume DIR`, which must succeed; returns its stderr.
fn resume_simulated(plan: &Path, dir: &Path) -> String {
    let out = gyrocal()
        .arg("run")
        .arg(plan)
        .args(["--simulate", "--resume"])
        .arg(dir)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{stderr}");
    stderr
}

fn check_complete(dir: &Path, steps: usize, per_step: u64) {
    let m = manifest(dir);
    assert_eq!(m["status"], "complete", "{m}");
    assert_eq!(
        step_indices(dir),
        (0..steps).collect::<Vec<_>>(),
        "every rate exactly once"
    );
    let s = samples(dir);
    assert_eq!(
        s.len() as u64,
        steps as u64 * per_step,
        "no lost or duplicated sample"
    );
    let mut seen = std::collections::BTreeSet::new();
    for key in &s {
        assert!(seen.insert(*key), "duplicated sample {key:?}");
    }
    assert!(dir.join("fit.json").exists());
}

#[test]
fn paper_plan_runs_in_virtual_time_and_recovers_the_gyro() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let out = gyrocal()
        .args(["run", "--simulate", "--out"])
        .arg(&dir)
        .arg(config("paper.toml"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    check_complete(&dir, 19, 500);
    let fit: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("fit.json")).unwrap()).unwrap();
    let lin = fit["fits"]
        .as_array()
        .unwrap()
        .iter()
        .find(|f| f["method"] == "least-squares" && f["model"] == "quadratic")
        .unwrap();
    // paper.toml's [simulation]: K = 0.3612 (asymmetry 100 ppm about it), K0 = 0.0088 V plus
    // the Earth rate at 45.75° (10.77 °/h = 0.00299 °/s, times K)
    let k = lin["scale_factor"].as_f64().unwrap();
    let k0 = lin["bias"].as_f64().unwrap();
    let sk = lin["std_errors"]["k1"].as_f64().unwrap();
    let sk0 = lin["std_errors"]["k0"].as_f64().unwrap();
    let earth = 15.041 / 3600.0 * 45.75f64.to_radians().sin();
    let true_k0 = 0.0088 + 0.3612 * earth + 2e-5 * earth * earth;
    assert!(
        (k - 0.3612).abs() < 3.0 * sk + 0.3612 * 1e-4,
        "K {k} ± {sk}"
    );
    // the asymmetry's |ω| shape leaks into a quadratic's K0 by a few tenths of a mV
    assert!(
        (k0 - true_k0).abs() < 3.0 * sk0 + 2e-4,
        "K0 {k0} vs {true_k0} ± {sk0}"
    );
    assert!(stdout.contains("ratio"), "{stdout}");
    let m = manifest(&dir);
    assert!(
        m["timing"]["ratio"].as_f64().unwrap() < 1.03,
        "{}",
        m["timing"]
    );
    assert_eq!(final_table_state(&stderr)["stopped"], true);
    assert!(dir.join("report.html").exists());
}

#[test]
fn sigint_mid_run_stops_the_table_and_the_run_resumes_to_completion() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let plan = config("paper.toml");
    // a step chosen at random (from the clock): the test must hold wherever it lands
    let k = 1
        + (std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .subsec_nanos() as usize)
            % 15;
    let mut child = spawn_run(&plan, &["--out", dir.to_str().unwrap()]);
    interrupt_after(&mut child, &dir, k, Signal::SIGINT);
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "{stderr}");
    let m = manifest(&dir);
    assert_eq!(m["status"], "aborted", "{m}");
    assert!(steps_done(&dir) >= k && steps_done(&dir) < 19);
    let table = final_table_state(&stderr);
    assert_eq!(table["demanded_dps"].as_f64(), Some(0.0), "{table}");
    assert_ne!(table["mode"], "Rate", "{table}");
    // at rest when gyrocal let go of the bench, not merely sent a stop
    assert_eq!(table["stopped"], true, "{table}");
    assert!(stderr.contains("table at rest"), "{stderr}");
    // one numbering, the plan's, in every line: step n/19 started, step n done
    let done = steps_done(&dir);
    for n in 1..=done {
        assert!(
            stderr.contains(&format!("step {n}/19 ")),
            "step {n}/19 in:\n{stderr}"
        );
        assert!(stderr.contains(&format!("  step {n} done: ")), "{stderr}");
    }
    // a step cut short is named, with what was discarded
    if let Some(l) = stderr.lines().find(|l| l.contains("not recorded (")) {
        assert!(
            l.starts_with(&format!("step {}/19 ", done + 1)) && l.contains("measured again"),
            "{l}"
        );
    }

    let resumed = resume_simulated(&plan, &dir);
    check_complete(&dir, 19, 500);
    assert_eq!(manifest(&dir)["resumes"].as_array().unwrap().len(), 1);
    // the resumed session goes on with the same numbers
    let first = resumed
        .lines()
        .find(|l| l.starts_with("step "))
        .unwrap_or_else(|| panic!("no step line in:\n{resumed}"));
    assert!(
        first.starts_with(&format!("step {}/19 ", done + 1)),
        "{first}"
    );
    assert!(resumed.contains("  step 19 done: "), "{resumed}");
}

#[test]
fn sigkill_mid_run_loses_nothing_recorded_and_resumes() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let plan = config("paper.toml");
    let k = 1
        + (std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .subsec_nanos() as usize
            / 7)
            % 15;
    let mut child = spawn_run(&plan, &["--out", dir.to_str().unwrap()]);
    interrupt_after(&mut child, &dir, k, Signal::SIGKILL);
    let _ = child.wait().unwrap();
    assert_eq!(manifest(&dir)["status"], "running");
    let before = step_indices(&dir);
    assert!(before.len() >= k);

    resume_simulated(&plan, &dir);
    check_complete(&dir, 19, 500);
    let m = manifest(&dir);
    assert_eq!(
        m["resumes"][0]["steps_done"].as_u64(),
        Some(before.len() as u64)
    );
}

#[test]
fn resume_with_a_changed_plan_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let out = gyrocal()
        .arg("run")
        .arg(config("quick.toml"))
        .args(["--simulate", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(out.status.success());
    let changed = tmp.path().join("changed.toml");
    let text = std::fs::read_to_string(config("quick.toml"))
        .unwrap()
        .replace("samples_per_rate = 50", "samples_per_rate = 60");
    std::fs::write(&changed, text).unwrap();
    let out = gyrocal()
        .arg("run")
        .arg(&changed)
        .args(["--simulate", "--resume"])
        .arg(&dir)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    // the key that changed, with both values, not two hashes
    assert!(
        err.contains("[plan] samples_per_rate: 50 (run) vs 60 (this plan)"),
        "{err}"
    );
}

/// A failed run's closing hint is a command that works as printed: `gyrocal run --simulate
/// --resume DIR`, with no plan (the run's own is in its manifest); the resumed session
/// completes the run.
#[test]
fn a_run_resumes_from_its_directory_alone_with_the_printed_command() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let out = gyrocal()
        .arg("run")
        .arg(config("quick.toml"))
        .args(["--simulate", "--sim-fault", "table:trip@demand3", "-o"])
        .arg(&dir)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    let hint = stderr
        .lines()
        .find_map(|l| {
            l.split_once("resume with: ")
                .map(|(_, c)| c.trim().to_string())
        })
        .unwrap_or_else(|| panic!("no resume hint in:\n{stderr}"));
    assert_eq!(
        hint,
        format!("gyrocal run --simulate --resume {}", dir.display())
    );
    let words: Vec<&str> = hint.split(' ').skip(1).collect();
    let out = gyrocal().args(&words).output().unwrap();
    let resumed = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{resumed}");
    check_complete(&dir, 5, 50);
    assert!(resumed.contains("step 5 done"), "{resumed}");

    // a directory that is not a run says so
    let out = gyrocal()
        .args(["run", "--simulate", "--resume"])
        .arg(tmp.path())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("is not a gyrocal run directory"), "{err}");
}

/// When the plan itself must change (every reading overloaded: the range is too small), the
/// run cannot be resumed, and gyrocal does not suggest it.
#[test]
fn an_overloaded_range_is_not_followed_by_a_resume_that_cannot_work() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = bad_plan(tmp.path(), "range_v = 10", "range_v = 0.1");
    let dir = tmp.path().join("run");
    let out = gyrocal()
        .arg("run")
        .arg(&plan)
        .args(["--simulate", "-o"])
        .arg(&dir)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("is range_v too small?"), "{stderr}");
    assert!(!stderr.contains("resume with"), "{stderr}");
    assert!(stderr.contains("start a new run"), "{stderr}");
}

fn bad_plan(dir: &Path, find: &str, replace: &str) -> PathBuf {
    let text = std::fs::read_to_string(config("quick.toml")).unwrap();
    assert!(text.contains(find), "quick.toml has no {find:?}");
    let path = dir.join("bad.toml");
    std::fs::write(&path, text.replacen(find, replace, 1)).unwrap();
    path
}

fn line_of(path: &Path, needle: &str) -> usize {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .position(|l| l.contains(needle))
        .unwrap()
        + 1
}

#[test]
fn malformed_plans_exit_2_naming_file_line_and_key() {
    let tmp = tempfile::tempdir().unwrap();
    let cases = [
        ("settle_s = 2", "settle_s = = 2", "settle_s", None),
        (
            "repeat = 1",
            "repeat = 1\nrepeats = 2",
            "repeats",
            Some("repeats"),
        ),
        (
            "max_rate_dps = 20",
            "max_rate_dps = 5",
            "rates_dps",
            Some("rates_dps"),
        ),
        (
            "acceleration_dps2 = 10",
            "acceleration_dps2 = 0",
            "acceleration_dps2",
            Some("acceleration_dps2"),
        ),
        ("nplc = 1", "nplc = 2", "nplc", Some("nplc")),
    ];
    for (find, replace, line_key, key) in cases {
        let path = bad_plan(tmp.path(), find, replace);
        let line = line_of(&path, line_key);
        for sub in ["check", "run"] {
            let mut cmd = gyrocal();
            cmd.arg(sub).arg(&path);
            if sub == "run" {
                cmd.args(["--simulate", "--out"])
                    .arg(tmp.path().join("never"));
            }
            let out = cmd.output().unwrap();
            let err = String::from_utf8_lossy(&out.stderr);
            assert_eq!(out.status.code(), Some(2), "{sub} {replace:?}: {err}");
            assert!(
                err.contains(&format!("bad.toml:{line}:")),
                "{sub} {replace:?} should name line {line}: {err}"
            );
            if let Some(key) = key {
                assert!(
                    err.contains(key),
                    "{sub} {replace:?} should name {key}: {err}"
                );
            }
            assert!(!err.contains("panicked"), "{err}");
        }
        assert!(
            !tmp.path().join("never").exists(),
            "no run directory for a bad plan"
        );
    }
    let out = gyrocal()
        .arg("check")
        .arg(tmp.path().join("missing.toml"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("missing.toml"));
}

#[test]
fn check_prints_the_schedule_and_its_duration() {
    let out = gyrocal()
        .arg("check")
        .arg(config("paper.toml"))
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("19 steps, 9500 readings"), "{text}");
    assert!(text.contains("physical bound"), "{text}");
    // one row per step, in the plan's order
    let rows: Vec<Vec<&str>> = text
        .lines()
        .map(|l| l.split_whitespace().collect::<Vec<_>>())
        .filter(|f| f.len() >= 8 && f.iter().take(7).all(|x| x.parse::<f64>().is_ok()))
        .collect();
    let rates: Vec<f64> = rows.iter().map(|f| f[2].parse().unwrap()).collect();
    assert_eq!(rates.len(), 19, "{text}");
    assert_eq!(&rates[..5], &[0.0, 0.1, -0.1, 0.3, -0.3], "{text}");
    assert_eq!(rows.len(), 19, "{text}");
}

#[test]
fn a_port_that_does_not_open_is_named_and_leaves_no_run_directory() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let missing = tmp.path().join("ttyNOPE");
    let out = gyrocal()
        .arg("run")
        .arg(config("quick.toml"))
        .arg("--dmm-port")
        .arg(&missing)
        .args(["--table-port", "/dev/null-table", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("opening the multimeter") && err.contains("ttyNOPE"),
        "{err}"
    );
    // the cause is said once, not once per layer
    assert_eq!(err.matches("No such file or directory").count(), 1, "{err}");
    assert!(
        !dir.exists(),
        "a run that never started leaves no directory to clean up"
    );
    // and the same --out works once the instrument is there
    let out = gyrocal()
        .arg("run")
        .arg(config("quick.toml"))
        .args(["--simulate", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn several_runs_make_one_report_with_repeatability_in_a_new_directory() {
    let tmp = tempfile::tempdir().unwrap();
    let mut dirs = Vec::new();
    for seed in [1, 2] {
        let plan = tmp.path().join(format!("quick-{seed}.toml"));
        let text = std::fs::read_to_string(config("quick.toml")).unwrap();
        std::fs::write(&plan, text.replace("seed = 1", &format!("seed = {seed}"))).unwrap();
        let dir = tmp.path().join(format!("run{seed}"));
        let out = gyrocal()
            .arg("run")
            .arg(&plan)
            .args(["--simulate", "--no-report", "--out"])
            .arg(&dir)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        dirs.push(dir);
    }
    let html = tmp.path().join("reports/both/report.html");
    let out = gyrocal()
        .arg("report")
        .args(&dirs)
        .arg("--out")
        .arg(&html)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(html.exists());
    assert!(html.with_file_name("repeatability.svg").exists());
}

#[test]
fn simulated_faults_rehearse_what_a_run_does_when_an_instrument_misbehaves() {
    let tmp = tempfile::tempdir().unwrap();
    // a garbled reading in step 1: retried, and the run completes
    let dir = tmp.path().join("garble");
    let out = gyrocal()
        .arg("run")
        .arg(config("quick.toml"))
        .args([
            "--simulate",
            "--sim-fault",
            "dmm:garble@reading75",
            "--no-report",
            "--out",
        ])
        .arg(&dir)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("simulated fault dmm:garble@reading75: fired"),
        "{err}"
    );
    let m = manifest(&dir);
    assert_eq!(m["status"], "complete");
    assert_eq!(m["retries"][0]["step"], 1, "{}", m["retries"]);
    // the run's own log tells the story, with the bytes the meter sent
    let log = std::fs::read_to_string(dir.join("run.log")).unwrap();
    assert!(log.contains("step{index=1"), "{log}");
    assert!(log.contains("expected a reading"), "{log}");

    // a rate trip during the third demand: the run fails with the table's words, table parked
    let dir = tmp.path().join("trip");
    let out = gyrocal()
        .arg("run")
        .arg(config("quick.toml"))
        .args(["--simulate", "--sim-fault", "table:trip@demand3", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    let m = manifest(&dir);
    assert_eq!(m["status"], "failed");
    assert!(
        m["reason"].as_str().unwrap().contains("trip"),
        "{}",
        m["reason"]
    );
    assert_eq!(
        final_table_state(&err)["demanded_dps"].as_f64(),
        Some(0.0),
        "{err}"
    );

    // a malformed spec is bad input
    let out = gyrocal()
        .arg("run")
        .arg(config("quick.toml"))
        .args(["--simulate", "--sim-fault", "dmm:explode@reading1", "--out"])
        .arg(tmp.path().join("never"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--sim-fault"));
}

#[test]
fn a_simulated_run_cannot_be_resumed_on_the_instruments() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let mut child = spawn_run(&config("paper.toml"), &["--out", dir.to_str().unwrap()]);
    interrupt_after(&mut child, &dir, 1, Signal::SIGINT);
    assert_eq!(child.wait().unwrap().code(), Some(130));
    let out = gyrocal()
        .arg("run")
        .arg(config("paper.toml"))
        .args([
            "--dmm-port",
            "/dev/null-dmm",
            "--table-port",
            "/dev/null-table",
            "--resume",
        ])
        .arg(&dir)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("mix simulated and measured data"), "{err}");
    assert_eq!(
        manifest(&dir)["status"],
        "aborted",
        "the refused resume changed nothing"
    );
}

#[test]
fn the_aerosmith_dialect_runs_the_same_plan_on_the_simulated_bench() {
    // the plan's [table] dialect picks the driver and the simulated table's wire
    let tmp = tempfile::tempdir().unwrap();
    let (out, dir, _) =
        run_quick_variant(tmp.path(), "dialect = \"acl\"", "dialect = \"aerosmith\"");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(stderr.contains("rate table: Ideal Aerosmith"), "{stderr}");
    assert!(stderr.contains("table at rest"), "{stderr}");
    check_complete(&dir, 5, 50);
    assert_eq!(final_table_state(&stderr)["stopped"], true);
}

#[test]
fn a_meter_behind_a_prologix_controller_runs_the_same_plan() {
    // `prologix:` in [dmm] port: the real Prologix transport in front of the 34401A driver,
    // a simulated controller in front of the simulated meter (GPIB mode: no SYST:REM)
    let tmp = tempfile::tempdir().unwrap();
    let (out, dir, text) = run_quick_variant(
        tmp.path(),
        "port = \"/dev/ttyUSB0\"",
        "port = \"prologix:/dev/ttyUSB0?addr=22\"",
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    check_complete(&dir, 5, 50);
    assert!(stderr.contains("table at rest"), "{stderr}");
    // a bad GPIB address is refused before anything opens, naming the key
    let bad = tmp.path().join("bad.toml");
    std::fs::write(&bad, text.replace("addr=22", "addr=31")).unwrap();
    let out = gyrocal()
        .args(["check", bad.to_str().unwrap()])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("dmm.port") && stderr.contains("0..=30"),
        "{stderr}"
    );
}

/// quick.toml with `from` replaced by `to`, run with `--simulate` into `tmp/run`: the output,
/// the run directory and the plan's text.
fn run_quick_variant(tmp: &Path, from: &str, to: &str) -> (std::process::Output, PathBuf, String) {
    let text = std::fs::read_to_string(config("quick.toml"))
        .unwrap()
        .replace(from, to);
    assert!(text.contains(to), "quick.toml has no {from:?}");
    let plan = tmp.join("variant.toml");
    std::fs::write(&plan, &text).unwrap();
    let dir = tmp.join("run");
    let out = gyrocal()
        .args([
            "run",
            plan.to_str().unwrap(),
            "--simulate",
            "--no-report",
            "--out",
        ])
        .arg(&dir)
        .output()
        .unwrap();
    (out, dir, text)
}
