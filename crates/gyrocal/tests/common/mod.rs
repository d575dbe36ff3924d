//! Helpers shared by the CLI tests that include this module (`mod common;`): the binary with
//! a clean environment (none of the user's files: see [`isolated`]), the configs directory,
//! and reading a run directory's JSON files.

#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)] // each test file uses a subset

use std::path::{Path, PathBuf};
use std::process::Command;

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
    for (name, _) in std::env::vars_os() {
        if users_own(&name) {
            c.env_remove(name);
        }
    }
    c
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

/// A file under `configs/`.
pub fn config(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../configs")
        .join(name)
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
