//! The command line's surface as an operator and a script meet it: clean streams (no colour
//! codes when not a terminal, no log lines unless asked for), short options and comma lists,
//! shell completions and the man page generated from the real definitions.

#![allow(clippy::unwrap_used)] // test helpers: a panic is a failed test

mod common;

use std::path::{Path, PathBuf};
use std::process::Output;

use common::config;

/// `gyrocal ARGS` (through tests/common: no log filter, no catalog, none of the user's
/// files) with the variables `env` set.
fn gyrocal(args: &[&str], env: &[(&str, &str)]) -> Output {
    let mut cmd = common::gyrocal();
    cmd.args(args);
    for (k, v) in env {
        cmd.env(k, v);
    }
    cmd.output().unwrap()
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// A simulated run with a retried multimeter fault: the retry is told in gyrocal's own words,
/// the driver's log lines are not mixed in unless asked for, and nothing carries colour codes
/// when stderr is a file.
#[test]
fn redirected_output_is_plain_text_and_the_log_needs_v() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = config("quick.toml");
    let dir = tmp.path().join("quiet");
    let args = |d: &Path| {
        vec![
            "run".to_string(),
            plan.to_str().unwrap().to_string(),
            "--simulate".into(),
            "--sim-fault".into(),
            "dmm:garble@reading60".into(),
            "-o".into(),
            d.to_str().unwrap().to_string(),
        ]
    };
    let a = args(&dir);
    let a: Vec<&str> = a.iter().map(String::as_str).collect();
    let out = gyrocal(&a, &[]);
    let stderr = text(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(dir.join("manifest.json").is_file(), "-o is --out");
    assert!(stderr.contains("retry (dmm)"), "{stderr}");
    assert!(
        !stderr.contains('\u{1b}'),
        "colour codes in redirected output:\n{stderr}"
    );
    for level in [" WARN ", " INFO ", " ERROR ", " DEBUG "] {
        assert!(!stderr.contains(level), "log line without -v:\n{stderr}");
    }
    // the log is still kept with the run
    let log = std::fs::read_to_string(dir.join("run.log")).unwrap();
    assert!(log.contains(" WARN ") || log.contains(" INFO "), "{log}");

    let dir = tmp.path().join("verbose");
    let a = args(&dir);
    let mut a: Vec<&str> = a.iter().map(String::as_str).collect();
    a.push("-v");
    let out = gyrocal(&a, &[]);
    let stderr = text(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains(" INFO "), "-v shows the log:\n{stderr}");
    assert!(!stderr.contains('\u{1b}'), "{stderr}");
}

#[test]
fn fit_takes_comma_lists_of_models_and_methods() {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/paper-shaped.csv");
    let out = gyrocal(
        &[
            "fit",
            "--json",
            "--model",
            "linear,quadratic",
            "--method",
            "least-squares",
            data.to_str().unwrap(),
        ],
        &[],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    // one file: the first of `files` (fit --json has one shape for any number of files)
    let v = serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap()["files"][0].take();
    let models: Vec<&str> = v["fits"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["model"].as_str().unwrap())
        .collect();
    assert_eq!(models, ["linear", "quadratic"], "{v}");
}

#[test]
fn completions_and_man_pages_come_from_the_real_options() {
    let out = gyrocal(&["completions", "bash"], &[]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let script = text(&out.stdout);
    for word in [
        "gyrocal",
        "run",
        "check",
        "--resume",
        "--simulate",
        "report",
    ] {
        assert!(
            script.contains(word),
            "{word} missing from the bash completion"
        );
    }
    let out = gyrocal(&["completions", "tcsh"], &[]);
    assert_eq!(
        out.status.code(),
        Some(2),
        "an unknown shell is a usage error"
    );

    let out = gyrocal(&["man"], &[]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let page = text(&out.stdout);
    assert!(
        page.starts_with(".ie") || page.contains(".TH gyrocal"),
        "{page}"
    );
    assert!(page.contains("completions"), "{page}");

    let tmp = tempfile::tempdir().unwrap();
    let out = gyrocal(&["man", "-o", tmp.path().to_str().unwrap()], &[]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    for page in ["gyrocal.1", "gyrocal-run.1", "gyrocal-check.1"] {
        let p = tmp.path().join(page);
        let roff = std::fs::read_to_string(&p).unwrap();
        assert!(roff.contains(".TH"), "{}", p.display());
    }
}

/// `gyrocal run --json`: stdout is one JSON document a script can act on, complete or not;
/// the human text goes to stderr.
#[test]
fn run_json_is_one_document_whatever_the_outcome() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = config("quick.toml");
    let dir = tmp.path().join("ok");
    let out = gyrocal(
        &[
            "run",
            plan.to_str().unwrap(),
            "--simulate",
            "--json",
            "-o",
            dir.to_str().unwrap(),
        ],
        &[],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("{e}: {}", text(&out.stdout)));
    assert_eq!(doc["status"], "complete", "{doc}");
    assert_eq!(doc["exit_code"], 0, "{doc}");
    assert_eq!(doc["table"]["at_rest"], true, "{doc}");
    assert_eq!(doc["steps_done"], 5, "{doc}");
    assert_eq!(doc["steps_total"], 5, "{doc}");
    assert_eq!(doc["simulated"], true, "{doc}");
    assert_eq!(doc["simulated_bench"]["table"]["stopped"], true, "{doc}");
    let k = doc["fit"]["scale_factor"].as_f64().unwrap();
    assert!((k - 0.3612).abs() < 0.001, "{doc}");
    assert!(doc["resume_command"].is_null(), "{doc}");
    assert!(
        text(&out.stderr).contains("scale factor"),
        "the human fit on stderr"
    );

    let dir = tmp.path().join("failed");
    let out = gyrocal(
        &[
            "run",
            plan.to_str().unwrap(),
            "--simulate",
            "--json",
            "--sim-fault",
            "table:trip@demand3",
            "-o",
            dir.to_str().unwrap(),
        ],
        &[],
    );
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stderr));
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(doc["status"], "failed", "{doc}");
    assert_eq!(doc["exit_code"], 1, "{doc}");
    assert_eq!(doc["steps_done"], 2, "{doc}");
    assert_eq!(
        doc["resume_command"],
        format!("gyrocal run --simulate --resume {}", dir.display()),
        "{doc}"
    );
    assert!(
        doc["reason"].as_str().unwrap().contains("rate table"),
        "{doc}"
    );
}

/// `gyrocal check --json`: the schedule with the plan's step numbers, the estimate, warnings.
#[test]
fn check_json_is_one_document_with_the_schedule() {
    let out = gyrocal(
        &["check", config("paper.toml").to_str().unwrap(), "--json"],
        &[],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let steps = doc["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 19);
    // counted from 1 like the terminal and the run directory's files (`step_no`, `pass_no`)
    assert_eq!(steps[0]["step_no"], 1);
    assert_eq!(steps[0]["pass_no"], 1);
    assert_eq!(steps[18]["step_no"], 19);
    for old in ["number", "index", "pass"] {
        assert!(steps[18].get(old).is_none(), "{old} in {}", steps[18]);
    }
    assert_eq!(doc["readings"], 19 * 500);
    let (est, bound) = (
        doc["estimated_s"].as_f64().unwrap(),
        doc["bound_s"].as_f64().unwrap(),
    );
    assert!(bound > 600.0 && est >= bound && est < bound * 1.01, "{doc}");
    assert_eq!(doc["dmm"]["acquisition"], "stream");
}

/// `gyrocal report --json`: one document with the report's path and every file written.
#[test]
fn report_json_is_one_document_with_the_files_written() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let plan = config("quick.toml");
    let out = gyrocal(
        &[
            "run",
            plan.to_str().unwrap(),
            "--simulate",
            "--no-report",
            "-o",
            dir.to_str().unwrap(),
        ],
        &[],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let out = gyrocal(&["report", dir.to_str().unwrap(), "--json"], &[]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let report = PathBuf::from(doc["report"].as_str().unwrap());
    assert_eq!(report, dir.join("report.html"), "{doc}");
    let files = doc["files"].as_array().unwrap();
    assert!(files.len() > 1, "the HTML and its plots: {doc}");
    for f in files {
        assert!(Path::new(f.as_str().unwrap()).is_file(), "{f}");
    }
}

/// `--sim-time-scale X` paces the one virtual clock at X simulated seconds per real second:
/// the run's own waits (dwells, at-rate windows) speed up with the instruments, and the run
/// clock still counts simulated time. quick.toml is about 25 simulated seconds, 10 of them
/// the run's own waits (2 s per step): at 50 it takes about 0.5 s (1 ms pacing steps, a few
/// ms each on a loaded machine); a run whose waits stayed real would take more than 10 s.
/// (Loose bounds: wall time on a loaded machine.)
#[test]
fn sim_time_scale_paces_the_runs_own_waits_too() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let plan = config("quick.toml");
    let t0 = std::time::Instant::now();
    let out = gyrocal(
        &[
            "run",
            plan.to_str().unwrap(),
            "--simulate",
            "--sim-time-scale",
            "50",
            "--no-report",
            "-o",
            dir.to_str().unwrap(),
        ],
        &[],
    );
    let wall = t0.elapsed().as_secs_f64();
    assert!(out.status.success(), "{}", text(&out.stderr));
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("manifest.json")).unwrap()).unwrap();
    let run_clock = m["elapsed_s"].as_f64().unwrap();
    assert!((20.0..40.0).contains(&run_clock), "run clock {run_clock} s");
    assert!(
        wall >= run_clock / 50.0 * 0.9,
        "paced, not as fast as possible: {wall} s"
    );
    assert!(wall < 9.0, "the run's own waits are paced too: {wall} s");
    assert_eq!(m["virtual_time"], true);
}

/// SIGINT to a run whose virtual clock is paced (`--sim-time-scale`, the clock advanced in
/// bounded jumps while the run's tasks run between them): the stop goes through the same
/// ending as an unpaced run's, and the simulated table ends at rest, said on the terminal and
/// in the manifest's status.
#[test]
fn sigint_to_a_paced_run_leaves_the_simulated_table_at_rest() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let mut child = common::gyrocal()
        .arg("run")
        .arg(config("quick.toml"))
        .args(["--simulate", "--sim-time-scale", "20", "--no-report", "-o"])
        .arg(&dir)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = std::time::Instant::now();
    while common::steps_done(&dir) < 1 {
        assert!(t0.elapsed().as_secs() < 60, "no step recorded");
        assert!(child.try_wait().unwrap().is_none(), "the run ended early");
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    let pid = nix::unistd::Pid::from_raw(i32::try_from(child.id()).unwrap());
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGINT).unwrap();
    let out = child.wait_with_output().unwrap();
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "{stderr}");
    assert_eq!(
        common::final_table_state(&stderr)["stopped"],
        true,
        "{stderr}"
    );
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(m["status"], "aborted", "{m:#}");
    assert_eq!(m["virtual_time"], true);
}
