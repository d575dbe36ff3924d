//! Helpers shared by the CLI tests that include this module (`mod common;`): the binary with
//! a clean environment (none of the user's files: see [`isolated`]; every test that starts
//! the binary, or a shell that execs it, starts here), the test plans written once for every
//! crate ([`plans`], `tests/support/plans.rs`), the configs directory, reading a run
//! directory's JSON files, where the simulated table ended ([`final_table_state`]) and the
//! run directories kept from an earlier release ([`fixture_rundir`]).

#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)] // each test file uses a subset

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

#[path = "../../../../tests/support/plans.rs"]
pub mod plans;

#[path = "../../../../tests/support/stations.rs"]
pub mod stations;

pub mod series;
pub mod serve;
pub mod sim;

/// True for the environment variables through which gyrocal finds a user's own files: its
/// catalog and station file (`GYROCAL_*`) and the directories of their defaults (`HOME`,
/// `XDG_*`), and the caller's log filter (`RUST_LOG`).
fn users_own(name: &std::ffi::OsStr) -> bool {
    let name = name.to_string_lossy();
    name == "HOME" || name == "RUST_LOG" || name.starts_with("GYROCAL_") || name.starts_with("XDG_")
}

/// The gyrocal binary with none of the user's files, whatever the environment says: no
/// `HOME`, no `XDG_*` directories (so no default station file and no default catalog), no
/// `GYROCAL_*` variables, no log filter. A test that wants a catalog or a station names its
/// own (`--catalog`, `--station`, or [`gyrocal_with_data_home`]). Every test that runs the
/// binary starts from here: a test run must never add runs to a user's catalog (one
/// `cargo nextest run` once added four) nor read a user's station file.
pub fn isolated() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_gyrocal"));
    remove_users_own(&mut c);
    c
}

/// Removes from `c`'s environment every variable through which gyrocal finds a user's own
/// files (see [`isolated`]): for a command that starts the binary another way (a shell
/// that sets a limit and execs it).
pub fn remove_users_own(c: &mut Command) {
    for (name, _) in std::env::vars_os() {
        if users_own(&name) {
            c.env_remove(name);
        }
    }
}

/// [`isolated`], and no catalog unless the test names one (`--catalog` or
/// `GYROCAL_CATALOG`): a run indexes itself nowhere.
pub fn gyrocal() -> Command {
    let mut c = isolated();
    c.env("GYROCAL_CATALOG", "off");
    c
}

/// [`isolated`], with the default catalog in `data_home` (`XDG_DATA_HOME`, a directory of
/// the test's own): `data_home/gyrocal/catalog.sqlite`.
pub fn gyrocal_with_data_home(data_home: &Path) -> Command {
    let mut c = isolated();
    c.env("XDG_DATA_HOME", data_home);
    c
}

/// `gyrocal ARGS` run to its end (through [`gyrocal`]: no catalog, none of the user's files).
pub fn gyrocal_output(args: &[&str]) -> Output {
    gyrocal().args(args).output().unwrap()
}

/// A file under `configs/`.
pub fn config(name: &str) -> PathBuf {
    plans::config(name)
}

/// A run directory's manifest.json.
pub fn manifest(dir: &Path) -> serde_json::Value {
    json(dir, "manifest.json")
}

/// How many steps (a drift record's segments) `dir/steps.csv` records; 0 before it exists.
pub fn steps_done(dir: &Path) -> usize {
    std::fs::read_to_string(dir.join("steps.csv"))
        .map(|s| s.lines().skip(1).filter(|l| !l.trim().is_empty()).count())
        .unwrap_or(0)
}

/// A JSON file of a run directory.
pub fn json(dir: &Path, name: &str) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join(name))
        .unwrap_or_else(|e| panic!("{}: {e}", dir.join(name).display()));
    serde_json::from_str(&text).unwrap()
}

/// The text of `s` between the first occurrence of `from` and the next `to` after it.
pub fn between<'a>(s: &'a str, from: &str, to: &str) -> &'a str {
    let i = s.find(from).unwrap_or_else(|| panic!("{from:?} not found"));
    let rest = &s[i..];
    let j = rest.find(to).unwrap_or(rest.len());
    &rest[..j]
}

/// What `gyrocal run ... --json` gave: the exit code, its JSON document (`Null` when it
/// printed none) and the human text on stderr.
pub struct RunOutput {
    pub code: Option<i32>,
    pub doc: serde_json::Value,
    pub stderr: String,
}

/// `gyrocal run --json` with `args` (a plan or `--resume DIR`, `--simulate`, `--out DIR`, ...).
pub fn run_json(args: &[&dyn AsRef<std::ffi::OsStr>]) -> RunOutput {
    let o = gyrocal()
        .args(["run", "--json"])
        .args(args.iter().map(|a| a.as_ref()))
        .output()
        .unwrap();
    RunOutput {
        code: o.status.code(),
        doc: serde_json::from_slice(&o.stdout).unwrap_or(serde_json::Value::Null),
        stderr: String::from_utf8_lossy(&o.stderr).into_owned(),
    }
}

/// The simulated table's state at the end of a run, from gyrocal's closing line
/// `simulated table at the end: mode Off, demand +0 °/s, at rest`: `mode`, `demanded_dps`
/// and `stopped` (true when the line ends with "at rest"). Panics (a failed test) when the
/// line is missing: a simulated run must always say where its table ended.
pub fn final_table_state(stderr: &str) -> serde_json::Value {
    let line = stderr
        .lines()
        .find_map(|l| l.strip_prefix("simulated table at the end: "))
        .unwrap_or_else(|| panic!("no final table state in:\n{stderr}"));
    let mode = line
        .strip_prefix("mode ")
        .and_then(|r| r.split(',').next())
        .unwrap_or_else(|| panic!("no mode in {line:?}"));
    let demand: f64 = line
        .split("demand ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no demand in {line:?}"));
    serde_json::json!({
        "mode": mode,
        "demanded_dps": demand,
        "stopped": line.ends_with(", at rest"),
    })
}

/// A run directory kept as a fixture under `tests/fixtures/rundirs/` (written by an earlier
/// release, see the README there), copied into `into` so a test may resume or report it
/// without touching the kept one; returns the copy's path (`into/name`).
pub fn fixture_rundir(name: &str, into: &Path) -> PathBuf {
    let from = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/fixtures/rundirs")
        .join(name);
    let to = into.join(name);
    copy_dir(&from, &to);
    to
}

/// Copies the regular files of the directory `from` into a new directory `to` (no
/// subdirectories: a run directory has none).
pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap_or_else(|e| panic!("{}: {e}", to.display()));
    for entry in std::fs::read_dir(from).unwrap_or_else(|e| panic!("{}: {e}", from.display())) {
        let entry = entry.unwrap();
        assert!(
            entry.file_type().unwrap().is_file(),
            "{}: not a regular file",
            entry.path().display()
        );
        std::fs::copy(entry.path(), to.join(entry.file_name()))
            .unwrap_or_else(|e| panic!("{}: {e}", entry.path().display()));
    }
}

/// The PostgreSQL server the catalog tests use (`GYROCAL_TEST_POSTGRES_URL`, which `.ci/run`
/// sets), or `None` after saying the test is skipped (a machine without one).
pub fn postgres_url() -> Option<String> {
    let url = std::env::var("GYROCAL_TEST_POSTGRES_URL").ok();
    if url.is_none() {
        eprintln!("note: GYROCAL_TEST_POSTGRES_URL is not set; PostgreSQL test skipped");
    }
    url
}
