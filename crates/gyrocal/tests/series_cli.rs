//! A temperature series end to end through `gyrocal run`: the whole 25 → −20 → 60 → 25 °C
//! series of `configs/series.toml` on the simulated bench (the real Watlow F4 driver over the
//! simulated controller's Modbus RTU) in virtual time, the gyro's temperature coefficients
//! recovered within their stated U, the chamber left in its safe state and the table at rest;
//! and over pseudo-terminals (and Modbus TCP) against `gyrocal sim --chamber watlow_f4`, the
//! issue's "Done when" end to end: SIGINT during a soak; SIGKILL mid-soak and the resume that
//! soaks again; a door alarm mid-sweep, the resume refused while it is latched and completing
//! once it is reset at the chamber's panel; the chamber over Modbus TCP; a chamber silent at
//! the end ("could NOT be confirmed", exit 1). Faults are placed by the meter's reading count
//! or the table's stop count (`chamber:door@reading65`), never by wall time, and every wait
//! on a run is bounded and says what the run printed.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod common;

use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

use common::series::{
    RUN_LIMIT, SAFE_LINE, assert_completed, printed_resume, run_on, run_printed, said,
    short_series, sim_with_chamber, step_numbers, temps,
};
use common::sim::{Sim, output_within};
use common::{RunOutput, config, final_table_state, gyrocal, json, run_json, steps_done};

/// The simulated gyro's coefficients in `configs/series.toml` (`[simulation]`).
const K_TEMPCO_PPM_PER_C: f64 = 30.0;
const BIAS_TEMPCO_DPH_PER_C: f64 = 1.5;

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

/// The first "Done when" on the whole 25 → −20 → 60 → 25 °C series in virtual time
/// (paced at 10000 s a second so the kill can land: the soak at −20 °C lasts hours of run
/// clock, about a second of wall time; this pace made every paced series fail before the
/// paced clock's jumps were bounded, see `execute::pace`): SIGKILL once temps.csv shows that soak, then `gyrocal
/// run --simulate --resume DIR` (the simulated bench starts afresh at room temperature): the
/// resume soaks again at −20 °C before it measures there, every step once, the run clock
/// monotone across the sessions, and the analysis of both sessions' steps recovers the
/// tempcos within their U, with the chamber confirmed safe and the table at rest.
#[test]
fn a_whole_series_killed_mid_soak_resumes_and_recovers_the_tempcos() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let mut child = gyrocal()
        .arg("run")
        .arg(config("series.toml"))
        .args(["--simulate", "--sim-time-scale", "10000", "--out"])
        .arg(&dir)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let (t_kill, rows_before) = kill_in_the_second_soak(&mut child, &dir);
    assert_eq!(step_numbers(&dir), [1, 2, 3, 4, 5], "the sweep at 25 °C");

    let RunOutput { code, doc, stderr } = run_json(&[&"--simulate", &"--resume", &dir]);
    assert_eq!(code, Some(0), "{stderr}");
    assert_eq!(doc["status"], "complete", "{doc:#}");
    assert_eq!(step_numbers(&dir), (1..=20).collect::<Vec<u32>>());
    let after = temps(&dir);
    for w in after.windows(2) {
        assert!(w[1].0 >= w[0].0, "temps.csv's run clock went back: {w:?}");
    }
    let resumed = &after[rows_before..];
    let soaked = resumed
        .iter()
        .position(|(t, p, ph)| *p == 1 && ph == "soak" && *t >= t_kill)
        .unwrap_or_else(|| panic!("no soak at -20 °C on resume"));
    let measured = resumed
        .iter()
        .position(|(_, p, ph)| *p == 1 && ph == "measure")
        .unwrap_or_else(|| panic!("no measurement at -20 °C"));
    assert!(soaked < measured);
    assert_sensitivities_recovered(&dir);
    assert!(stderr.contains(SAFE_LINE), "{stderr}");
    assert_eq!(final_table_state(&stderr)["stopped"], true, "{stderr}");
    let m = json(&dir, "manifest.json");
    assert_eq!(
        m["resumes"].as_array().unwrap().len(),
        1,
        "{:#}",
        m["resumes"]
    );
    assert_eq!(m["chamber"]["safe_confirmed"], true, "{:#}", m["chamber"]);
}

/// The resume command a run against `sim` prints in its ending (the ports repeated, the
/// chamber's too, so the resume reaches the same instruments).
fn resume_command(sim: &Sim, dir: &Path) -> String {
    format!(
        "gyrocal run --dmm-port {} --table-port {} --chamber-port {} --resume {}",
        sim.dmm(),
        sim.table(),
        sim.chamber(),
        dir.display()
    )
}

/// SIGKILL (no ending, no safe state) once temps.csv shows the soak at the series' second
/// temperature; the run clock of temps.csv's last row, which must be that soak's, and the
/// number of its rows.
fn kill_in_the_second_soak(child: &mut std::process::Child, dir: &Path) -> (f64, usize) {
    wait_for_phase(child, dir, 1, "soak");
    child.kill().unwrap();
    child.wait().unwrap();
    let before = temps(dir);
    let (t_kill, point, phase) = before.last().unwrap().clone();
    assert_eq!((point, phase.as_str()), (1, "soak"), "{before:?}");
    (t_kill, before.len())
}

/// Blocks until temps.csv has a row of `point` in `phase`, failing if the run ended first.
fn wait_for_phase(child: &mut std::process::Child, dir: &Path, point: u32, phase: &str) {
    let t0 = Instant::now();
    while !temps(dir)
        .iter()
        .any(|(_, p, ph)| *p == point && ph == phase)
    {
        assert!(
            t0.elapsed() < RUN_LIMIT,
            "no {phase} at temperature {}",
            point + 1
        );
        if let Some(status) = child.try_wait().unwrap() {
            panic!(
                "the run ended ({status}) before temperature {}'s {phase}: {:?}",
                point + 1,
                temps(dir)
            );
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[test]
fn sigint_during_a_soak_leaves_the_table_at_rest_and_the_chamber_safe() {
    let tmp = tempfile::tempdir().unwrap();
    // a soak long enough to be interrupted in
    let plan = short_series(tmp.path(), &[("soak_min", "2")]);
    let dir = tmp.path().join("run");
    let sim = sim_with_chamber(&plan, &[]);
    let mut child = run_on(&sim, &plan, &dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    wait_for_phase(&mut child, &dir, 0, "soak");
    let pid = nix::unistd::Pid::from_raw(i32::try_from(child.id()).unwrap());
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGINT).unwrap();
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "{stderr}");
    assert!(stderr.contains(SAFE_LINE), "{stderr}");
    // the resume the ending gives reaches the same chamber: --chamber-port repeated
    assert_eq!(
        printed_resume(&stderr),
        resume_command(&sim, &dir),
        "{stderr}"
    );
    let state = sim.finish();
    assert_eq!(state["table"]["stopped"], true, "{state:#}");
    assert_eq!(state["chamber"]["setpoint_c"], 23.0, "{state:#}");
    let m = json(&dir, "manifest.json");
    assert_eq!(m["status"], "aborted", "{:#}", m["status"]);
}

/// The first "Done when", over pseudo-terminals: killed (SIGKILL: no ending, no safe
/// state) while soaking at the second temperature, the run is resumed with `gyrocal run
/// --resume DIR` alone (what `gyrocal runs` says of a killed run: the ports, the chamber's
/// too, are in its manifest); the resume soaks again at that temperature before it measures,
/// and completes with both machines safe.
#[test]
fn a_series_killed_mid_soak_soaks_again_on_resume_and_completes() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = short_series(tmp.path(), &[]);
    let dir = tmp.path().join("run");
    let sim = sim_with_chamber(&plan, &[]);
    let mut child = run_on(&sim, &plan, &dir)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // the kill waits on what the run directory shows, not on wall time
    let (t_kill, rows_before) = kill_in_the_second_soak(&mut child, &dir);
    assert_eq!(
        step_numbers(&dir),
        [1, 2, 3],
        "the first temperature's sweep"
    );
    // no ending, so no resume command printed: the run directory has what a resume needs,
    // every port the run was given (the chamber's too) in the manifest's plan
    let m = json(&dir, "manifest.json");
    assert_eq!(m["status"], "running");
    assert_eq!(
        m["plan"]["chamber"]["port"],
        sim.chamber(),
        "{:#}",
        m["plan"]
    );
    assert_eq!(m["plan"]["dmm"]["port"], sim.dmm(), "{:#}", m["plan"]);
    let ended = run_printed(&format!("gyrocal run --resume {}", dir.display()));
    assert_completed(&ended, &dir);
    let after = temps(&dir);
    let resumed = &after[rows_before..];
    // the resumed session soaked at 26 °C again, after the kill, before measuring there
    let soaked = resumed
        .iter()
        .position(|(t, p, ph)| *p == 1 && ph == "soak" && *t >= t_kill)
        .unwrap_or_else(|| panic!("no soak at 26 °C on resume: {resumed:?}"));
    let measured = resumed
        .iter()
        .position(|(_, p, ph)| *p == 1 && ph == "measure")
        .unwrap_or_else(|| panic!("no measurement at 26 °C: {resumed:?}"));
    assert!(soaked < measured, "{resumed:?}");
    let m = json(&dir, "manifest.json");
    assert_eq!(
        m["resumes"].as_array().unwrap().len(),
        1,
        "{:#}",
        m["resumes"]
    );
    let state = sim.finish();
    assert_eq!(state["table"]["stopped"], true, "{state:#}");
    assert_eq!(state["chamber"]["setpoint_c"], 23.0, "{state:#}");
}

/// A door opened during the sweep at the second temperature (once the meter has taken its
/// 65th reading: the 5th of the first step at 26 °C), over pseudo-terminals: the run stops
/// saying so, the table at rest, the step under way not recorded, the chamber confirmed
/// safe. The resume it prints is refused while the alarm is latched (the same words); the
/// operator resets it at the chamber's panel (SIGUSR1 to the simulator) and the same resume
/// completes.
#[test]
fn a_door_alarm_mid_sweep_stops_the_run_and_the_resume_completes_once_reset() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = short_series(tmp.path(), &[]);
    let dir = tmp.path().join("run");
    let sim = sim_with_chamber(&plan, &["--fault", "chamber:door@reading65"]);
    let first = output_within(&mut run_on(&sim, &plan, &dir), RUN_LIMIT);
    assert_eq!(first.code, Some(1), "{}", said(&first));
    let alarm_line = first
        .stderr
        .lines()
        .find(|l| l.contains("chamber alarm: door open during step "))
        .unwrap_or_else(|| panic!("the alarm not said:\n{}", said(&first)));
    let step: u32 = alarm_line
        .split("during step ")
        .nth(1)
        .and_then(|r| r.split(',').next())
        .and_then(|n| n.trim().parse().ok())
        .unwrap_or_else(|| panic!("{alarm_line}"));
    assert!(alarm_line.contains("which is not recorded"), "{alarm_line}");
    // a step at 26 °C, not recorded; the ones before it are
    assert!(step >= 4, "{alarm_line}");
    assert_eq!(step_numbers(&dir), (1..step).collect::<Vec<_>>());
    assert!(
        said(&first).contains("the table is at rest"),
        "{}",
        said(&first)
    );
    assert!(said(&first).contains(SAFE_LINE), "{}", said(&first));
    let resume = printed_resume(&said(&first));
    assert_eq!(resume, resume_command(&sim, &dir));

    // the alarm is latched: the resume stops at once, saying so, the table still at rest
    let refused = run_printed(&resume);
    assert_eq!(refused.code, Some(1), "{}", said(&refused));
    assert!(
        said(&refused).contains("chamber alarm: door open")
            && said(&refused).contains("cleared at the chamber"),
        "{}",
        said(&refused)
    );
    assert!(
        said(&refused).contains("the table is at rest"),
        "{}",
        said(&refused)
    );
    assert_eq!(step_numbers(&dir), (1..step).collect::<Vec<_>>());

    let reset = sim.reset_chamber_alarms();
    assert_eq!(
        reset["cleared"],
        serde_json::json!(["door open"]),
        "{reset}"
    );
    let ended = run_printed(&resume);
    assert_completed(&ended, &dir);
    let state = sim.finish();
    assert_eq!(state["table"]["stopped"], true, "{state:#}");
    assert_eq!(
        state["chamber"]["alarms"],
        serde_json::json!([]),
        "{state:#}"
    );
    assert_eq!(state["faults"][0]["fired"], true, "{state:#}");
}

/// The chamber over Modbus TCP (`gyrocal sim --chamber-tcp`), named in the plan's
/// `[chamber] port` (no --chamber-port): the series completes with the chamber confirmed.
#[test]
fn a_series_with_the_chamber_on_modbus_tcp_completes_with_it_confirmed() {
    let tmp = tempfile::tempdir().unwrap();
    let sim_plan = short_series(tmp.path(), &[]);
    let sim = sim_with_chamber(&sim_plan, &["--chamber-tcp", "0"]);
    let addr = sim.chamber().to_string();
    assert!(addr.starts_with("tcp://127.0.0.1:"), "{addr}");
    let port = format!("\"{addr}\"");
    let plan = short_series(tmp.path(), &[("chamber.port", &port)]);
    let dir = tmp.path().join("run");
    let ended = output_within(
        gyrocal()
            .arg("run")
            .arg(&plan)
            .args(["--dmm-port", sim.dmm(), "--table-port", sim.table()])
            .arg("--out")
            .arg(&dir),
        RUN_LIMIT,
    );
    assert_completed(&ended, &dir);
    let state = sim.finish();
    assert_eq!(state["chamber"]["setpoint_c"], 23.0, "{state:#}");
    assert!(
        state["chamber"]["requests_seen"].as_u64().unwrap() > 20,
        "{state:#}"
    );
    assert_eq!(state["table"]["stopped"], true, "{state:#}");
}

/// The chamber falls silent at the end (at the table's first stop command: the schedule's
/// last step done): every step is recorded, but the chamber's safe state could not be
/// confirmed, which the ending says plainly, with exit 1 and the table at rest.
#[test]
fn a_chamber_silent_at_the_end_is_said_not_confirmed_with_exit_1() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = short_series(tmp.path(), &[]);
    let dir = tmp.path().join("run");
    let sim = sim_with_chamber(&plan, &["--fault", "chamber:silent@stop1"]);
    let ended = output_within(&mut run_on(&sim, &plan, &dir), RUN_LIMIT);
    assert_eq!(ended.code, Some(1), "{}", said(&ended));
    assert!(
        said(&ended).contains("all steps recorded, but chamber: setpoint 23 °C (ambient), in control could NOT be confirmed"),
        "{}",
        said(&ended)
    );
    assert!(!said(&ended).contains(SAFE_LINE), "{}", said(&ended));
    assert_eq!(step_numbers(&dir), [1, 2, 3, 4, 5, 6]);
    let m = json(&dir, "manifest.json");
    assert_eq!(m["chamber"]["safe_confirmed"], false, "{:#}", m["chamber"]);
    let state = sim.finish();
    assert_eq!(state["table"]["stopped"], true, "{state:#}");
    assert_eq!(state["faults"][0]["fired"], true, "{state:#}");
}
