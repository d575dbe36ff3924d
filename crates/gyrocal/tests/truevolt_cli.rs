//! `gyrocal run` with a Keysight Truevolt, as a user runs it: the paper plan on the simulated
//! Truevolt in virtual time (two models, both table dialects), long steps that exceed a small
//! memory, faults, and a real TCP socket to `gyrocal sim --dmm 34461a`.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::Duration;

use common::{config, final_table_state, gyrocal, manifest};

/// `configs/keysight-34461a.toml` with text replaced, written to `dir/name`.
fn plan_with(dir: &Path, name: &str, edits: &[(&str, &str)]) -> PathBuf {
    let text = common::plans::config_with("keysight-34461a.toml", edits);
    common::plans::write(dir, name, &text)
}

const PAPER_RATES: &str = "rates_dps = [0, 0.1, -0.1, 0.3, -0.3, 0.7, -0.7, 1, -1, 3, -3, 7, -7, 10, -10, 15, -15, 20, -20]";

fn csv_rows(path: &Path) -> Vec<BTreeMap<String, String>> {
    let mut r = csv::Reader::from_path(path).unwrap();
    r.deserialize().map(Result::unwrap).collect()
}

struct Done {
    ok: bool,
    stdout: String,
    stderr: String,
}

fn run_simulated(plan: &Path, dir: &Path, extra: &[&str]) -> Done {
    let out = gyrocal()
        .args(["run", "--simulate", "--no-report", "--out"])
        .arg(dir)
        .args(extra)
        .arg(plan)
        .output()
        .unwrap();
    Done {
        ok: out.status.success(),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

/// Every step recorded once with `per_step` readings; the retries in steps.csv add up to the
/// manifest's.
fn check_complete(dir: &Path, steps: usize, per_step: usize) -> serde_json::Value {
    let m = manifest(dir);
    assert_eq!(m["status"], "complete", "{m}");
    let rows = csv_rows(&dir.join("steps.csv"));
    assert_eq!(rows.len(), steps);
    let samples = csv_rows(&dir.join("samples.csv"));
    assert_eq!(
        samples.len(),
        steps * per_step,
        "no lost or duplicated sample"
    );
    let retries: u64 = rows
        .iter()
        .map(|r| r["retries"].parse::<u64>().unwrap())
        .sum();
    assert_eq!(
        retries as usize,
        m["retries"].as_array().unwrap().len(),
        "steps.csv and manifest.json count the same retries: {}",
        m["retries"]
    );
    m
}

/// The paper plan on a 34461A and a 34465A, on the ACL and the Aerosmith table: complete, 19
/// steps of 500 readings, K within tolerance of the simulated truth, and the ratio elapsed /
/// physical bound printed (the meter adds about a millisecond a step to it).
#[test]
fn paper_plan_on_truevolts_with_both_tables() {
    let tmp = tempfile::tempdir().unwrap();
    for (model, dialect) in [
        ("34461a", "acl"),
        ("34465a", "acl"),
        ("34461a", "aerosmith"),
        ("34465a", "aerosmith"),
    ] {
        let plan = plan_with(
            tmp.path(),
            &format!("{model}-{dialect}.toml"),
            &[
                ("model = \"34461a\"", &format!("model = \"{model}\"")),
                ("dialect = \"acl\"", &format!("dialect = \"{dialect}\"")),
            ],
        );
        let dir = tmp.path().join(format!("{model}-{dialect}"));
        let done = run_simulated(&plan, &dir, &[]);
        assert!(
            done.ok,
            "{model} {dialect}: {}\n{}",
            done.stdout, done.stderr
        );
        let m = check_complete(&dir, 19, 500);
        assert_eq!(m["retries"].as_array().unwrap().len(), 0);
        let fit: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("fit.json")).unwrap()).unwrap();
        let quad = fit["fits"]
            .as_array()
            .unwrap()
            .iter()
            .find(|f| f["method"] == "least-squares" && f["model"] == "quadratic")
            .unwrap();
        let k = quad["scale_factor"].as_f64().unwrap();
        let sk = quad["std_errors"]["k1"].as_f64().unwrap();
        assert!(
            (k - 0.3612).abs() < 3.0 * sk + 0.3612 * 1e-4,
            "{model} {dialect}: K {k} ± {sk}"
        );
        let ratio = m["timing"]["ratio"].as_f64().unwrap();
        println!("{model} {dialect}: ratio elapsed/bound {ratio:.5}");
        assert!(ratio < 1.01, "{model} {dialect}: {}", m["timing"]);
        assert!(
            done.stdout.contains("acquisition stream"),
            "{}",
            done.stdout
        );
        assert_eq!(final_table_state(&done.stderr)["stopped"], true);
    }
}

/// A 10,000-reading step: one INIT drained while it measures, on a 34461A (its memory holds
/// the step) and on a 34460A (memory 1,000: drained while it fills, nothing lost).
#[test]
fn ten_thousand_reading_steps_on_a_34461a_and_a_34460a() {
    let tmp = tempfile::tempdir().unwrap();
    for model in ["34461a", "34460a"] {
        let plan = plan_with(
            tmp.path(),
            &format!("{model}.toml"),
            &[
                ("model = \"34461a\"", &format!("model = \"{model}\"")),
                (PAPER_RATES, "rates_dps = [0, 1]"),
                ("samples_per_rate = 500", "samples_per_rate = 10000"),
            ],
        );
        let dir = tmp.path().join(model);
        let done = run_simulated(&plan, &dir, &[]);
        assert!(done.ok, "{model}: {}\n{}", done.stdout, done.stderr);
        let m = check_complete(&dir, 2, 10_000);
        let ratio = m["timing"]["ratio"].as_f64().unwrap();
        println!("{model} 2 x 10,000: ratio elapsed/bound {ratio:.5}");
        assert!(ratio < 1.01, "{}", m["timing"]);
    }
}

/// A plan whose NPLC the model lacks is refused before anything opens, naming the file, the
/// key and the model.
#[test]
fn an_nplc_the_model_lacks_is_refused_naming_file_key_and_model() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = plan_with(tmp.path(), "bad.toml", &[("nplc = 1", "nplc = 0.06")]);
    for sub in ["check", "run"] {
        let mut cmd = gyrocal();
        cmd.arg(sub).arg(&plan);
        if sub == "run" {
            cmd.args(["--simulate", "--out"])
                .arg(tmp.path().join("never"));
        }
        let out = cmd.output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.contains("bad.toml"), "{err}");
        assert!(err.contains("[dmm] nplc"), "{err}");
        assert!(err.contains("34461A"), "{err}");
    }
    // the 34465A offers it
    let plan = plan_with(
        tmp.path(),
        "ok.toml",
        &[
            ("nplc = 1", "nplc = 0.06"),
            ("model = \"34461a\"", "model = \"34465a\""),
        ],
    );
    let out = gyrocal().arg("check").arg(&plan).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // and the 34401A does not
    let text = std::fs::read_to_string(config("paper.toml"))
        .unwrap()
        .replace("nplc = 1", "nplc = 0.06");
    let p = tmp.path().join("hp.toml");
    std::fs::write(&p, text).unwrap();
    let out = gyrocal().arg("check").arg(&p).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("hp.toml") && err.contains("[dmm] nplc") && err.contains("34401A"),
        "{err}"
    );
}

fn quick(tmp: &Path, name: &str) -> PathBuf {
    plan_with(
        tmp,
        name,
        &[
            (PAPER_RATES, "rates_dps = [0, 1, -1, 10, -10]"),
            ("samples_per_rate = 500", "samples_per_rate = 200"),
        ],
    )
}

/// A garbled reply: recovered (reconnect, ABOR) and counted once, the same in steps.csv and
/// manifest.json.
#[test]
fn a_garbled_reply_is_recovered_and_counted_once() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = quick(tmp.path(), "q.toml");
    let dir = tmp.path().join("garble");
    let done = run_simulated(&plan, &dir, &["--sim-fault", "dmm:garble@reading300"]);
    assert!(done.ok, "{}", done.stderr);
    assert!(
        done.stderr.contains("dmm:garble@reading300: fired"),
        "{}",
        done.stderr
    );
    let m = check_complete(&dir, 5, 200);
    let retries = m["retries"].as_array().unwrap();
    assert_eq!(retries.len(), 1, "{m}");
    assert_eq!(retries[0]["step"], 1, "{m}");
    assert_eq!(retries[0]["instrument"], "dmm", "{m}");
    let rows = csv_rows(&dir.join("steps.csv"));
    assert_eq!(rows[1]["retries"], "1");
}

/// A meter gone silent: the run fails, names the meter, and the table is brought to rest.
#[test]
fn a_silent_meter_fails_the_run_with_the_table_at_rest() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = quick(tmp.path(), "q.toml");
    let dir = tmp.path().join("silent");
    let done = run_simulated(&plan, &dir, &["--sim-fault", "dmm:timeout@t=30sx1000"]);
    assert!(!done.ok, "{}", done.stderr);
    let m = manifest(&dir);
    assert_eq!(m["status"], "failed", "{m}");
    let reason = m["reason"].as_str().unwrap();
    assert!(reason.contains("did not come back"), "{reason}");
    let end = final_table_state(&done.stderr);
    assert_eq!(end["stopped"], true, "{end}");
    assert_eq!(end["demanded_dps"].as_f64(), Some(0.0), "{end}");
}

/// A power cycle: the meter's memory and settings are lost; the link is re-established, the
/// configuration sent again, the lost readings measured again, and the run completes.
#[test]
fn a_power_cycle_loses_readings_that_are_measured_again() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = quick(tmp.path(), "q.toml");
    let dir = tmp.path().join("power");
    let done = run_simulated(
        &plan,
        &dir,
        &["--sim-fault", "dmm:powercycle@reading450/3s"],
    );
    assert!(done.ok, "{}", done.stderr);
    let m = check_complete(&dir, 5, 200);
    let retries = m["retries"].as_array().unwrap();
    assert_eq!(retries.len(), 1, "{m}");
    assert!(
        retries[0]["message"]
            .as_str()
            .unwrap()
            .contains("re-established"),
        "{m}"
    );
}

/// Over a real TCP socket: `gyrocal sim --dmm 34461a` serves the Truevolt on
/// tcp://127.0.0.1:P, and `gyrocal run` with the plan's port pointing there runs to completion.
#[test]
fn over_tcp_gyrocal_sim_and_gyrocal_run() {
    let tmp = tempfile::tempdir().unwrap();
    let mut sim = gyrocal()
        .args([
            "sim",
            "--dmm",
            "34461a",
            "--time-scale",
            "50",
            "--seed",
            "3",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(sim.stdout.take().unwrap()).lines();
    let hello: serde_json::Value = serde_json::from_str(&lines.next().unwrap().unwrap()).unwrap();
    let dmm = hello["dmm"].as_str().unwrap().to_string();
    let table = hello["table"].as_str().unwrap().to_string();
    assert!(dmm.starts_with("tcp://127.0.0.1:"), "{hello}");
    let plan = plan_with(
        tmp.path(),
        "tcp.toml",
        &[
            (PAPER_RATES, "rates_dps = [0, 5, -5]"),
            ("samples_per_rate = 500", "samples_per_rate = 50"),
            ("settle_s = 10", "settle_s = 0"),
            (
                "port = \"tcp://192.0.2.10:5025\"",
                &format!("port = \"{dmm}\""),
            ),
            ("port = \"/dev/ttyUSB1\"", &format!("port = \"{table}\"")),
            ("stability_window_s = 2", "stability_window_s = 0.2"),
            ("acceleration_dps2 = 10", "acceleration_dps2 = 100"),
        ],
    );
    let dir = tmp.path().join("run");
    let out = gyrocal()
        .args(["run", "--no-report", "--out"])
        .arg(&dir)
        .arg(&plan)
        .output()
        .unwrap();
    let _ = nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(i32::try_from(sim.id()).unwrap()),
        nix::sys::signal::Signal::SIGTERM,
    );
    let _ = sim.wait();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    let m = manifest(&dir);
    assert_eq!(m["status"], "complete", "{m}");
    assert_eq!(csv_rows(&dir.join("samples.csv")).len(), 150);
    let _ = Duration::ZERO;
}
