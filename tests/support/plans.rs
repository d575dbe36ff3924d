//! Test plans written once for every crate's tests: the minimal sweep plan a library test
//! parses (no `[simulation]`, the bench sections down to their required keys), and the
//! shipped plans of `configs/` shortened or changed by exact text replacements.
//!
//! Included, not a crate: each test crate says
//!
//! ```ignore
//! #[path = "../../../tests/support/plans.rs"] // "../../tests/..." from sim/
//! mod plans;
//! ```
//!
//! (inside its `tests/common` where it has one). It needs nothing but `std`, so it costs no
//! dev-dependency and no workspace member, and a crate's tests build without another crate
//! of helpers being compiled first. A replacement that finds nothing panics naming the text
//! and the file: a shipped plan edited under a test's feet fails the test, instead of the
//! test silently running the unshortened plan (a 3 h drift record).

#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)] // each test binary uses a subset

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The `[table]` and `[dmm]` sections of a minimal plan: the required keys only (the ports
/// of the usual USB adapters; no test opens them), every other key at its default.
pub const MINIMAL_BENCH: &str = "[table]\nport = \"/dev/ttyUSB1\"\nmax_rate_dps = 20\n\
                                 acceleration_dps2 = 10\n[dmm]\nport = \"/dev/ttyUSB0\"\n";

/// The TOML of a minimal scale-factor plan named `name`: `rates_dps` as listed (written as
/// Rust prints them: `[0, 1, -1, 2.5]`), `samples_per_rate`, and [`MINIMAL_BENCH`]. Append
/// sections (`[acceptance]`, `[dut]`, ...) to the returned text.
pub fn sweep(name: &str, rates_dps: &[f64], samples_per_rate: u64) -> String {
    let mut text = String::new();
    let rates: Vec<String> = rates_dps.iter().map(|r| r.to_string()).collect();
    writeln!(text, "[plan]\nname = \"{name}\"").unwrap();
    writeln!(text, "rates_dps = [{}]", rates.join(", ")).unwrap();
    writeln!(text, "samples_per_rate = {samples_per_rate}").unwrap();
    text.push_str(MINIMAL_BENCH);
    text
}

/// The workspace's root directory (the one with `Cargo.lock`), found from the test crate's
/// own directory, whatever its depth (`crates/NAME`, `sim`).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .find(|d| d.join("Cargo.lock").is_file())
        .expect("a workspace root above CARGO_MANIFEST_DIR")
        .to_path_buf()
}

/// A file under `configs/`.
pub fn config(name: &str) -> PathBuf {
    workspace_root().join("configs").join(name)
}

/// The text of the shipped plan `configs/NAME` with each `(from, to)` replaced (every
/// occurrence). Panics, naming the file and the text, when a `from` is not in the plan.
pub fn config_with(name: &str, replacements: &[(&str, &str)]) -> String {
    let path = config(name);
    let mut text =
        std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    for (from, to) in replacements {
        assert!(
            text.contains(from),
            "{}: no {from:?} to replace (the shipped plan changed?)",
            path.display()
        );
        text = text.replace(from, to);
    }
    text
}

/// `configs/quick.toml` (5 rates, 50 readings, with its `[simulation]`) with other rates,
/// given as the TOML array's text (`"[0, 5, -5]"`).
pub fn quick_with_rates(rates: &str) -> String {
    config_with(
        "quick.toml",
        &[(
            "rates_dps = [0, 1, -1, 10, -10]",
            &format!("rates_dps = {rates}"),
        )],
    )
}

/// `configs/drift.toml` (a drift record held at 0 °/s, with its `[simulation]`) shortened to
/// `segments` segments of `readings` readings.
pub fn drift(segments: u32, readings: u32) -> String {
    config_with(
        "drift.toml",
        &[
            (
                "samples_per_rate = 3000",
                &format!("samples_per_rate = {readings}"),
            ),
            ("repeat = 167", &format!("repeat = {segments}")),
        ],
    )
}

/// Writes `text` to `dir/name` and returns the path.
pub fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    path
}
