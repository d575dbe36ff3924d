//! Helpers shared by the CLI tests that include this module (`mod common;`): the binary with
//! a clean environment, the configs directory, and reading a run directory's JSON files.

#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)] // each test file uses a subset

use std::path::{Path, PathBuf};
use std::process::Command;

/// The gyrocal binary, without the caller's log filter or station file (a test names its own).
pub fn gyrocal() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_gyrocal"));
    c.env_remove("RUST_LOG")
        .env_remove("GYROCAL_STATION")
        // no catalog unless a test names one (never the user's own)
        .env("GYROCAL_CATALOG", "off")
        // no default station file from the user's config directory
        .env(
            "XDG_CONFIG_HOME",
            std::env::temp_dir().join("gyrocal-tests-no-config"),
        );
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
