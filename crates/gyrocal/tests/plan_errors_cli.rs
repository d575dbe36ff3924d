//! Plan errors as an operator meets them through the binary (issue 12): `gyrocal check` names
//! the file, the line, the right `[section]` and key, what is allowed and what to do; a port
//! that is not a terminal says so.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use std::path::{Path, PathBuf};
use std::process::Output;

use common::gyrocal;

fn quick() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/quick.toml")
}

/// quick.toml with `find` (which must occur) replaced, written as `bad.toml` in `dir`.
fn bad_plan(dir: &Path, find: &str, replace: &str) -> PathBuf {
    let text = std::fs::read_to_string(quick()).unwrap();
    assert!(text.contains(find), "quick.toml has no {find:?}");
    let path = dir.join("bad.toml");
    std::fs::write(&path, text.replacen(find, replace, 1)).unwrap();
    path
}

/// 1-based line of the first line of `path` that is exactly `line` (trimmed).
fn line_of(path: &Path, line: &str) -> usize {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .position(|l| l.trim() == line)
        .unwrap()
        + 1
}

fn check(path: &Path) -> (Output, String) {
    let out = gyrocal().arg("check").arg(path).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    (out, err)
}

/// Exit 2, the file and line first, then every `needle`; no jargon, no panic.
fn assert_refused(path: &Path, line: usize, needles: &[&str]) {
    let (out, err) = check(path);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains(&format!("{}:{line}:", path.display())),
        "should name {}:{line}: {err}",
        path.display()
    );
    for needle in needles {
        assert!(err.contains(needle), "should say {needle:?}: {err}");
    }
    for jargon in [
        "u32",
        "f64",
        "expected",
        "invalid type",
        "missing field",
        "panicked",
    ] {
        assert!(!err.contains(jargon), "{jargon:?} in: {err}");
    }
}

#[test]
fn a_dmm_without_port_names_dmm_port_and_its_line() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = bad_plan(tmp.path(), "port = \"/dev/ttyUSB0\"\n", "");
    let line = line_of(&plan, "[dmm]");
    assert_refused(
        &plan,
        line,
        &[
            "[dmm] port is missing (required)",
            "add a line such as port = \"/dev/ttyUSB0\" under [dmm]",
        ],
    );
    assert!(!check(&plan).1.contains("[table]"));
}

#[test]
fn a_misspelt_section_gets_did_you_mean() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = bad_plan(tmp.path(), "[table]", "[tabel]");
    let line = line_of(&plan, "[tabel]");
    assert_refused(
        &plan,
        line,
        &["unknown section [tabel]: did you mean [table]?"],
    );
    assert!(!check(&plan).1.contains("[plan] unknown"));
    // a misspelt key, likewise
    let plan = bad_plan(tmp.path(), "rates_dps = ", "rate_dps = ");
    let line = line_of(&plan, "rate_dps = [0, 1, -1, 10, -10]");
    assert_refused(
        &plan,
        line,
        &["[plan] unknown key `rate_dps`: did you mean `rates_dps`?"],
    );
}

#[test]
fn samples_per_rate_says_what_is_wanted_in_words() {
    let tmp = tempfile::tempdir().unwrap();
    for (value, says) in [
        ("\"five\"", "= \"five\" is text, not a number"),
        ("-3", "= -3 is out of range"),
        ("2.5", "= 2.5 is not a whole number"),
    ] {
        let plan = bad_plan(
            tmp.path(),
            "samples_per_rate = 50",
            &format!("samples_per_rate = {value}"),
        );
        let line = line_of(&plan, &format!("samples_per_rate = {value}"));
        assert_refused(
            &plan,
            line,
            &[
                &format!("[plan] samples_per_rate {says}"),
                "write a whole number from 1 to 1000000",
            ],
        );
    }
}

#[test]
fn a_timeout_not_above_the_window_is_one_clear_sentence() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = bad_plan(
        tmp.path(),
        "at_rate_timeout_s = 60",
        "at_rate_timeout_s = 2",
    );
    let line = line_of(&plan, "at_rate_timeout_s = 2");
    assert_refused(
        &plan,
        line,
        &[
            "[table] at_rate_timeout_s = 2 must be greater than stability_window_s = 2 \
           (the rate must hold for the window before the timeout ends): raise \
           at_rate_timeout_s or lower stability_window_s",
        ],
    );
}

#[test]
fn a_regular_file_as_port_is_not_a_serial_port() {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("notes.txt");
    std::fs::write(&file, "not a port\n").unwrap();
    let dir = tmp.path().join("run");
    let out = gyrocal()
        .arg("run")
        .arg(quick())
        .arg("--dmm-port")
        .arg(&file)
        .args(["--table-port", "/dev/null-table", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert_ne!(out.status.code(), None, "{err}");
    assert!(
        err.contains(&format!(
            "{} is not a serial port (not a terminal device: it is a regular file)",
            file.display()
        )),
        "{err}"
    );
    assert!(!err.contains("typewriter"), "{err}");
    assert!(
        !dir.exists(),
        "no run directory for a port that never opened"
    );
}

/// `gyrocal check --json` on the plan `text` (written into `dir`): its warnings and its
/// human text.
fn check_warnings(dir: &Path, name: &str, text: &str) -> (Vec<String>, String) {
    let path = common::plans::write(dir, name, text);
    let o = gyrocal()
        .arg("check")
        .arg(&path)
        .arg("--json")
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let warnings = doc["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w.as_str().unwrap().to_string())
        .collect();
    let human = gyrocal().arg("check").arg(&path).output().unwrap();
    (
        warnings,
        String::from_utf8_lossy(&human.stdout).into_owned(),
    )
}

/// What an operator expects `check` to say before a run: a rate the table cannot tell from
/// rest, a fit with too few degrees of freedom for its asymmetry, a plan longer than a day,
/// and the acceptance limits the run will be judged by.
#[test]
fn check_warns_of_what_the_run_could_not_do_and_prints_the_acceptance_limits() {
    let tmp = tempfile::tempdir().unwrap();
    // 0.0005 °/s is inside the default ±0.001 °/s at-rate tolerance
    let (w, _) = check_warnings(
        tmp.path(),
        "slow.toml",
        &common::plans::sweep("slow", &[0.0, 0.0005, -0.0005, 1.0, -1.0, 10.0, -10.0], 10),
    );
    assert!(
        w.iter()
            .any(|w| w.contains("0.0005, 0.0005") || w.contains("-0.0005, 0.0005")),
        "{w:?}"
    );
    assert!(
        w.iter()
            .any(|w| w.contains("at-rate tolerance (±0.001 °/s)")),
        "{w:?}"
    );

    // five steps: the common-K2 asymmetry keeps one degree of freedom
    let (w, _) = check_warnings(
        tmp.path(),
        "five.toml",
        &common::plans::sweep("five", &[0.0, 1.0, -1.0, 10.0, -10.0], 10),
    );
    assert!(w.iter().any(|w| w.contains("1 degree of freedom")), "{w:?}");
    // nine steps: enough, no such warning
    let (w, _) = check_warnings(
        tmp.path(),
        "nine.toml",
        &common::plans::sweep(
            "nine",
            &[0.0, 1.0, -1.0, 3.0, -3.0, 10.0, -10.0, 20.0, -20.0],
            10,
        ),
    );
    assert!(!w.iter().any(|w| w.contains("degree")), "{w:?}");

    // 19 rates × 10^6 readings of 21.5 ms: days
    let (w, _) = check_warnings(
        tmp.path(),
        "long.toml",
        &common::plans::sweep(
            "long",
            &[0.0, 1.0, -1.0, 3.0, -3.0, 10.0, -10.0, 20.0, -20.0],
            1_000_000,
        ),
    );
    assert!(w.iter().any(|w| w.contains("longer than a day")), "{w:?}");

    let limited = common::plans::sweep(
        "limited",
        &[0.0, 1.0, -1.0, 3.0, -3.0, 10.0, -10.0, 20.0, -20.0],
        10,
    ) + "[acceptance]\ndecision_rule = \"guarded\"\n[acceptance.scale_factor]\nmin = 0.35\nmax = 0.37\nmarginal_min = 0.355\nmarginal_max = 0.365\n";
    let (_, text) = check_warnings(tmp.path(), "limited.toml", &limited);
    assert!(text.contains("acceptance (guarded rule):"), "{text}");
    assert!(
        text.contains("scale_factor") && text.contains("0.35 to 0.37"),
        "{text}"
    );
    assert!(text.contains("marginal outside 0.355 to 0.365"), "{text}");
    let (_, text) = check_warnings(
        tmp.path(),
        "none.toml",
        &common::plans::sweep("none", &[0.0, 1.0, -1.0], 10),
    );
    assert!(text.contains("acceptance: none"), "{text}");
}
