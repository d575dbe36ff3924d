//! The short temperature series the pseudo-terminal tests run against `gyrocal sim --chamber
//! watlow_f4` (`series_cli.rs`, `series_faults_cli.rs`): the plan, the simulator, the run
//! with every port on its command line, and what the run printed.

use std::path::{Path, PathBuf};
use std::time::Duration;

use super::sim::{Ended, Sim, output_within};
use super::{config, gyrocal, json};

/// What a run ends with when the chamber is confirmed in its safe state.
pub const SAFE_LINE: &str = "chamber: setpoint 23 °C (ambient), in control: confirmed";
/// ... and when it could not be confirmed.
pub const NOT_CONFIRMED: &str =
    "chamber: setpoint 23 °C (ambient), in control could NOT be confirmed";

/// A short series for real-time runs over pseudo-terminals against a simulator at 600 sim
/// seconds a second (the gyro's case, 20 min behind the air, settles in about 2 s): 23 → 26 °C,
/// three rates of 20 readings at each (readings 1–60 at 23 °C, 61–120 at 26 °C: three rates
/// so that each temperature's K has a U, and the series its tempcos), the soak's criterion
/// (±1 °C, 60 °C/min, 1.2 s: on the run clock, which is the wall clock here) met in a few
/// seconds, `overrides` (key or section.key, value) on top. About 10 s a run.
pub fn short_series(dir: &Path, overrides: &[(&str, &str)]) -> PathBuf {
    let text = std::fs::read_to_string(config("series.toml")).unwrap();
    let mut set: Vec<(&str, &str)> = vec![
        ("rates_dps", "[0, 10, -10]"),
        ("samples_per_rate", "20"),
        ("settle_s", "0.1"),
        ("stability_window_s", "0.3"),
        ("acceleration_dps2", "100"),
        ("temperatures_c", "[23, 26]"),
        ("band_c", "1"),
        ("stability_c_per_min", "60"),
        ("soak_min", "0.02"),
        ("max_wait_min", "5"),
        ("poll_s", "0.2"),
        ("ramp_c_per_min", "100"),
    ];
    set.extend_from_slice(overrides);
    let mut out = String::new();
    let mut section = "";
    for line in text.lines() {
        if let Some(name) = line
            .trim()
            .strip_prefix('[')
            .and_then(|l| l.strip_suffix(']'))
        {
            section = name;
        }
        let key = line.split('=').next().unwrap_or("").trim();
        let dotted = format!("{section}.{key}");
        match set.iter().rev().find(|(k, _)| *k == key || *k == dotted) {
            Some((_, v)) => out.push_str(&format!("{key} = {v}")),
            None => out.push_str(line),
        }
        out.push('\n');
    }
    let path = dir.join("short-series.toml");
    std::fs::write(&path, out).unwrap();
    path
}

/// `gyrocal sim` with the plan's bench and a Watlow F4 chamber, at 600 sim seconds a second.
pub fn sim_with_chamber(plan: &Path, extra: &[&str]) -> Sim {
    let mut args: Vec<&dyn AsRef<std::ffi::OsStr>> = vec![
        &"--config",
        &plan,
        &"--chamber",
        &"watlow_f4",
        &"--time-scale",
        &"600",
    ];
    for e in extra {
        args.push(e);
    }
    Sim::start(&args)
}

/// `gyrocal run PLAN` against the simulator, every port given on the command line.
pub fn run_on(sim: &Sim, plan: &Path, dir: &Path) -> std::process::Command {
    let mut c = gyrocal();
    c.arg("run")
        .arg(plan)
        .args(["--dmm-port", sim.dmm(), "--table-port", sim.table()])
        .args(["--chamber-port", sim.chamber()])
        .arg("--out")
        .arg(dir);
    c
}

/// The resume command printed in `stderr` ("resume with: gyrocal run ...").
pub fn printed_resume(stderr: &str) -> String {
    let line = stderr
        .lines()
        .find_map(|l| l.split("resume with: ").nth(1))
        .unwrap_or_else(|| panic!("no resume command in:\n{stderr}"));
    line.trim().to_string()
}

/// Runs a printed `gyrocal run ...` command word for word (the binary for "gyrocal").
pub fn run_printed(command: &str) -> Ended {
    let words: Vec<&str> = command.split_whitespace().collect();
    assert_eq!(words.first(), Some(&"gyrocal"), "{command}");
    output_within(gyrocal().args(&words[1..]), RUN_LIMIT)
}

/// The bound on one session of a run here (a few seconds on a quiet machine).
pub const RUN_LIMIT: Duration = Duration::from_secs(120);

/// steps.csv's step numbers (`step_no`), in file order.
pub fn step_numbers(dir: &Path) -> Vec<u32> {
    let text = std::fs::read_to_string(dir.join("steps.csv")).unwrap_or_default();
    text.lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect()
}

/// Everything a run printed: the human ending of a complete run is on stdout (stderr without
/// `--json` has only warnings and the failures' words).
pub fn said(e: &Ended) -> String {
    format!("{}{}", e.stdout, e.stderr)
}

/// What every completed series here shows: exit 0, each of the 6 steps once in steps.csv,
/// temps.csv's run clock never going back (across sessions too), the chamber confirmed in its
/// safe state (said, and in the manifest), the series' analysis written with its tempcos and
/// each temperature measured with the gyro within the band of its setpoint.
pub fn assert_completed(ended: &Ended, dir: &Path) {
    let text = said(ended);
    assert_eq!(ended.code, Some(0), "{text}");
    assert!(text.contains(SAFE_LINE), "{text}");
    assert!(
        text.contains("result: sensitivities over the range: K "),
        "{text}"
    );
    assert_eq!(
        step_numbers(dir),
        [1, 2, 3, 4, 5, 6],
        "no step lost or twice"
    );
    let t = temps(dir);
    for w in t.windows(2) {
        assert!(w[1].0 >= w[0].0, "temps.csv's run clock went back: {w:?}");
    }
    let m = json(dir, "manifest.json");
    assert_eq!(m["status"], "complete", "{:#}", m["status"]);
    assert_eq!(m["chamber"]["safe_confirmed"], true, "{:#}", m["chamber"]);
    let c = json(dir, "series.json")["catalog"].clone();
    let points = c["points"].as_array().unwrap();
    assert_eq!(points.len(), 2, "{c:#}");
    for p in points {
        let (set, mean) = (
            p["setpoint_c"].as_f64().unwrap(),
            p["temp_mean_c"].as_f64().unwrap(),
        );
        assert!(
            (mean - set).abs() <= 1.0,
            "measured outside the band: {p:#}"
        );
    }
    for key in [
        "k_tempco_ppm_per_c",
        "u_k_tempco_ppm_per_c",
        "bias_tempco_dph_per_c",
    ] {
        assert!(c[key].as_f64().is_some_and(f64::is_finite), "{key}: {c:#}");
    }
}

/// temps.csv's rows: (t_s, series_point, phase).
pub fn temps(dir: &Path) -> Vec<(f64, u32, String)> {
    let Ok(text) = std::fs::read_to_string(dir.join("temps.csv")) else {
        return Vec::new();
    };
    text.lines()
        .skip(1)
        .filter_map(|l| {
            let c: Vec<&str> = l.split(',').collect();
            Some((
                c.first()?.parse().ok()?,
                c.get(4)?.parse().ok()?,
                c.get(5)?.to_string(),
            ))
        })
        .collect()
}
