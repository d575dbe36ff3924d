//! A temperature series end to end through `gyrocal run`: the whole 25 → −20 → 60 → 25 °C
//! series of `configs/series.toml` on the simulated bench (the real Watlow F4 driver over the
//! simulated controller's Modbus RTU) in virtual time, the gyro's temperature coefficients
//! recovered within their stated U, the chamber left in its safe state and the table at rest;
//! and over pseudo-terminals against `gyrocal sim --chamber watlow_f4`: SIGINT during a soak.
//! (A kill mid-soak with its resume, and a chamber alarm mid-sweep over pseudo-terminals, are
//! tested in gyrocal-run's series_sim with a scripted chamber; their end-to-end forms here are
//! not finished.)
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod common;

use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};

use common::sim::Sim;
use common::{RunOutput, config, final_table_state, gyrocal, json, run_json, steps_done};

/// The simulated gyro's coefficients in `configs/series.toml` (`[simulation]`).
const K_TEMPCO_PPM_PER_C: f64 = 30.0;
const BIAS_TEMPCO_DPH_PER_C: f64 = 1.5;

/// temps.csv's rows: (t_s, series_point, phase).
fn temps(dir: &Path) -> Vec<(f64, u32, String)> {
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

fn assert_sensitivities_recovered(dir: &Path) {
    let s = json(dir, "series.json");
    let c = &s["catalog"];
    let (k, uk) = (
        c["k_tempco_ppm_per_c"].as_f64().unwrap(),
        c["u_k_tempco_ppm_per_c"].as_f64().unwrap(),
    );
    let (b, ub) = (
        c["bias_tempco_dph_per_c"].as_f64().unwrap(),
        c["u_bias_tempco_dph_per_c"].as_f64().unwrap(),
    );
    assert!(
        (k - K_TEMPCO_PPM_PER_C).abs() <= uk,
        "K's tempco {k} ± {uk} ppm/°C misses the simulated {K_TEMPCO_PPM_PER_C}"
    );
    assert!(
        (b - BIAS_TEMPCO_DPH_PER_C).abs() <= ub,
        "the bias's tempco {b} ± {ub} °/h/°C misses the simulated {BIAS_TEMPCO_DPH_PER_C}"
    );
    // a test's U is not so wide that anything passes: a tenth of the coefficient or less
    assert!(
        uk < 0.5 * K_TEMPCO_PPM_PER_C && ub < 0.5 * BIAS_TEMPCO_DPH_PER_C,
        "{c:#}"
    );
    assert_eq!(c["points"].as_array().unwrap().len(), 4, "{c:#}");
}

#[test]
fn a_simulated_series_recovers_the_gyros_tempcos_and_leaves_both_machines_safe() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let t0 = Instant::now();
    let RunOutput { code, doc, stderr } =
        run_json(&[&config("series.toml"), &"--simulate", &"--out", &dir]);
    assert_eq!(code, Some(0), "{stderr}");
    assert_eq!(doc["status"], "complete", "{doc:#}");
    // hours on the run clock, seconds of wall time (virtual time)
    let wall = t0.elapsed();
    assert!(wall < Duration::from_secs(60), "{wall:?}");
    assert_eq!(steps_done(&dir), 20);
    assert_sensitivities_recovered(&dir);
    assert!(dir.join("series.html").is_file());
    // the temperatures of all four points logged, and the safe state at the end
    let t = temps(&dir);
    for p in 0..4 {
        assert!(
            t.iter().any(|(_, q, ph)| *q == p && ph == "measure"),
            "point {p}"
        );
    }
    assert!(
        stderr.contains("chamber: setpoint 23 °C (ambient), in control: confirmed"),
        "{stderr}"
    );
    assert!(
        stderr.contains("simulated chamber at the end: setpoint 23.0 °C, mode Constant"),
        "{stderr}"
    );
    assert_eq!(final_table_state(&stderr)["stopped"], true, "{stderr}");
    let m = json(&dir, "manifest.json");
    assert_eq!(m["chamber"]["safe_confirmed"], true, "{:#}", m["chamber"]);
}

/// A short series for real-time runs over pseudo-terminals: 25 → 35 °C, a soak of 3 s (a
/// wide band: the run's criterion, not the physics, is under test here), two rates.
fn short_series(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(config("series.toml")).unwrap();
    let mut out = String::new();
    for line in text.lines() {
        let key = line.split('=').next().unwrap_or("").trim();
        let replaced = match key {
            "rates_dps" => "rates_dps = [0, 10]".to_string(),
            "samples_per_rate" => "samples_per_rate = 20".to_string(),
            "settle_s" => "settle_s = 0.5".to_string(),
            "temperatures_c" => "temperatures_c = [25, 35]".to_string(),
            "band_c" => "band_c = 30".to_string(),
            "stability_c_per_min" => "stability_c_per_min = 1000".to_string(),
            "soak_min" => "soak_min = 0.05".to_string(),
            "max_wait_min" => "max_wait_min = 5".to_string(),
            "poll_s" => "poll_s = 0.5".to_string(),
            "ramp_c_per_min" => "ramp_c_per_min = 100".to_string(),
            _ => line.to_string(),
        };
        out.push_str(&replaced);
        out.push('\n');
    }
    let path = dir.join("short-series.toml");
    std::fs::write(&path, out).unwrap();
    path
}

fn sim_with_chamber(plan: &Path, extra: &[&str]) -> Sim {
    let mut args: Vec<&dyn AsRef<std::ffi::OsStr>> = vec![
        &"--config",
        &plan,
        &"--chamber",
        &"watlow_f4",
        &"--time-scale",
        &"20",
    ];
    for e in extra {
        args.push(e);
    }
    Sim::start(&args)
}

fn run_on(sim: &Sim, plan: &Path, dir: &Path) -> std::process::Command {
    let mut c = gyrocal();
    c.arg("run")
        .arg(plan)
        .args(["--dmm-port", sim.dmm(), "--table-port", sim.table()])
        .args(["--chamber-port", sim.info()["chamber"].as_str().unwrap()])
        .arg("--out")
        .arg(dir);
    c
}

#[test]
fn sigint_during_a_soak_leaves_the_table_at_rest_and_the_chamber_safe() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = short_series(tmp.path());
    // a soak long enough to be interrupted in
    let text = std::fs::read_to_string(&plan)
        .unwrap()
        .replace("soak_min = 0.05", "soak_min = 2");
    std::fs::write(&plan, text).unwrap();
    let dir = tmp.path().join("run");
    let sim = sim_with_chamber(&plan, &[]);
    let mut child = run_on(&sim, &plan, &dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    while !temps(&dir).iter().any(|(_, _, ph)| ph == "soak") {
        assert!(t0.elapsed() < Duration::from_secs(60), "no soak");
        assert!(
            child.try_wait().unwrap().is_none(),
            "ended before the signal"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let pid = nix::unistd::Pid::from_raw(i32::try_from(child.id()).unwrap());
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGINT).unwrap();
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_ne!(out.status.code(), Some(0), "{stderr}");
    assert!(
        stderr.contains("chamber: setpoint 23 °C (ambient), in control: confirmed"),
        "{stderr}"
    );
    let state = sim.finish();
    assert_eq!(state["table"]["stopped"], true, "{state:#}");
    assert_eq!(state["chamber"]["setpoint_c"], 23.0, "{state:#}");
    let m = json(&dir, "manifest.json");
    assert_eq!(m["status"], "aborted", "{:#}", m["status"]);
}
