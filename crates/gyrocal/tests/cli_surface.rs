//! The command line's surface as an operator and a script meet it: clean streams (no colour
//! codes when not a terminal, no log lines unless asked for), short options and comma lists,
//! shell completions and the man page generated from the real definitions.

#![allow(clippy::unwrap_used)] // test helpers: a panic is a failed test

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn gyrocal(args: &[&str], env: &[(&str, &str)]) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_gyrocal"));
    cmd.args(args).env_remove("RUST_LOG");
    for (k, v) in env {
        cmd.env(k, v);
    }
    cmd.output().unwrap()
}

fn config(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../configs")
        .join(name)
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
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
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
