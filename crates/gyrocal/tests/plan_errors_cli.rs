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
