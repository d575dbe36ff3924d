//! The chamber's link faults through a whole temperature series, over pseudo-terminals (and
//! Modbus TCP) against `gyrocal sim --chamber watlow_f4`: what the driver does with a CRC
//! error, a Modbus exception and a slow reply is proved at the driver level in
//! `crates/gyrocal-chamber/tests`; here is what an operator sees of them in a run. Each
//! fault is placed by a count (the meter's reading, the chamber's request), never by wall
//! time; every test asserts the table at rest and the chamber's ending line.
//!
//! The short series and its helpers are `common::series`, shared with `series_cli.rs`.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod common;

use std::path::Path;

use common::json;
use common::series::{
    NOT_CONFIRMED, RUN_LIMIT, SAFE_LINE, assert_completed, printed_resume, run_on, run_printed,
    said, short_series, sim_with_chamber, step_numbers,
};
use common::sim::{Sim, output_within};

/// A retry's step is one at 26 °C: the manifest's step is the schedule's index, 3 to 5 for
/// steps 4 to 6. The fault fires at the chamber's first request after the meter's 65th
/// reading (the 5th of step 4); on a loaded machine that request may be the next step's.
fn assert_at_26(step: Option<u64>, retries: &[(Option<u64>, String)]) {
    assert!(matches!(step, Some(3..=5)), "{retries:?}");
}

/// The step a failed run said it did not record ("step N/6 …: not recorded"), which must be
/// one at 26 °C (4 to 6, for the same reason), with every step before it recorded once.
fn assert_stopped_at_26(text: &str, dir: &Path) -> u32 {
    let line = text
        .lines()
        .find(|l| l.starts_with("step ") && l.contains(": not recorded ("))
        .unwrap_or_else(|| panic!("no step said not recorded:\n{text}"));
    let n: u32 = line
        .strip_prefix("step ")
        .and_then(|r| r.split('/').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{line}"));
    assert!((4..=6).contains(&n), "{line}");
    assert_eq!(step_numbers(dir), (1..n).collect::<Vec<_>>(), "{line}");
    n
}

/// The one retry whose message has `cause` (one reply corrupted, one retry; a reply late on a
/// loaded machine may add a retry of its own, "no reply within", which is not counted here).
fn the_one_retry<'a>(retries: &'a [(Option<u64>, String)], cause: &str) -> (Option<u64>, &'a str) {
    let hit: Vec<&(Option<u64>, String)> =
        retries.iter().filter(|(_, m)| m.contains(cause)).collect();
    assert_eq!(hit.len(), 1, "one reply corrupted, one retry: {retries:?}");
    (hit[0].0, hit[0].1.as_str())
}

/// The manifest's retries against the chamber: (step, message).
fn chamber_retries(dir: &Path) -> Vec<(Option<u64>, String)> {
    json(dir, "manifest.json")["retries"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| r["instrument"] == "chamber")
        .map(|r| {
            (
                r["step"].as_u64(),
                r["message"].as_str().unwrap().to_string(),
            )
        })
        .collect()
}

/// The simulator's end: the table stopped, the chamber at its ambient setpoint, every fault
/// fired.
fn assert_sim_safe(sim: Sim) -> serde_json::Value {
    let state = sim.finish();
    assert_eq!(state["table"]["stopped"], true, "{state:#}");
    assert_eq!(state["chamber"]["setpoint_c"], 23.0, "{state:#}");
    for f in state["faults"].as_array().unwrap() {
        assert_eq!(f["fired"], true, "{state:#}");
    }
    state
}

/// One CRC error on a read of the chamber during a step at 26 °C (the chamber's first
/// request after the meter's 65th reading): the read is asked again, the retry is in the
/// manifest against that step and said on the progress lines, like the meter's garbled
/// reply; the run completes, every step once.
#[test]
fn a_crc_error_on_a_chamber_read_is_asked_again_and_the_series_completes() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = short_series(tmp.path(), &[]);
    let dir = tmp.path().join("run");
    let sim = sim_with_chamber(&plan, &["--fault", "chamber:crc@reading65"]);
    let ended = output_within(&mut run_on(&sim, &plan, &dir), RUN_LIMIT);
    assert_completed(&ended, &dir);
    let retries = chamber_retries(&dir);
    let (step, message) = the_one_retry(&retries, "CRC error");
    assert_at_26(step, &retries);
    assert!(
        message.contains("CRC error") && message.contains("asked again (attempt 2 of 3)"),
        "{message}"
    );
    assert!(
        said(&ended).contains("retry (chamber): "),
        "{}",
        said(&ended)
    );
    assert_sim_safe(sim);
}

/// The same over Modbus TCP (`gyrocal sim --chamber-tcp`), where a corrupted reply is one
/// whose MBAP protocol identifier is not 0: asked again, noted, the series completes.
#[test]
fn a_corrupted_modbus_tcp_reply_is_asked_again_and_the_series_completes() {
    let tmp = tempfile::tempdir().unwrap();
    let sim_plan = short_series(tmp.path(), &[]);
    let sim = sim_with_chamber(
        &sim_plan,
        &["--chamber-tcp", "0", "--fault", "chamber:crc@reading65"],
    );
    let addr = sim.chamber().to_string();
    assert!(addr.starts_with("tcp://127.0.0.1:"), "{addr}");
    let dir = tmp.path().join("run");
    let ended = output_within(&mut run_on(&sim, &sim_plan, &dir), RUN_LIMIT);
    assert_completed(&ended, &dir);
    let retries = chamber_retries(&dir);
    let (step, message) = the_one_retry(&retries, "protocol identifier");
    assert_at_26(step, &retries);
    assert!(
        message.contains("Modbus TCP")
            && message.contains("protocol identifier")
            && message.contains("asked again (attempt 2 of 3)"),
        "{message}"
    );
    assert_sim_safe(sim);
}

/// A CRC error on the echo of a setpoint write (the chamber's 15th request: the first
/// setpoint of the first soak's ramp, after connect's 4 reads and two readings of 5). By the
/// Modbus protocol a write of one register (function 06) sets it to a value, so writing the
/// same setpoint again leaves the controller as one write would: gyrocal writes it again
/// (noted like a read's retry) and reads it back, and the series completes. Before this test
/// the write was never repeated and the run failed at once, 0 steps recorded.
#[test]
fn a_crc_error_on_a_setpoint_writes_echo_is_written_again_and_the_series_completes() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = short_series(tmp.path(), &[]);
    let dir = tmp.path().join("run");
    let sim = sim_with_chamber(&plan, &["--fault", "chamber:crc@request15"]);
    let ended = output_within(&mut run_on(&sim, &plan, &dir), RUN_LIMIT);
    assert_completed(&ended, &dir);
    let retries = chamber_retries(&dir);
    let (step, message) = the_one_retry(&retries, "CRC error");
    assert_eq!(step, None, "during the soak, before any step: {retries:?}");
    assert!(
        message.contains("write register 300 = ")
            && message.contains("CRC error")
            && message.contains("written again, the same value (attempt 2 of 3)"),
        "the fault must hit the setpoint's write: {message}"
    );
    assert!(
        said(&ended).contains("retry (chamber): "),
        "{}",
        said(&ended)
    );
    assert_sim_safe(sim);
}

/// The line in which a failed run names the chamber as the cause.
fn the_chamber_failure(text: &str) -> &str {
    text.lines()
        .find(|l| l.starts_with("gyrocal: run failed: chamber: "))
        .unwrap_or_else(|| panic!("no chamber failure said:\n{text}"))
}

/// A Modbus exception (4, slave device failure) on a read of the chamber during a step at
/// 26 °C: an instrument error naming the chamber's port, the register and the exception; the
/// table brought to rest, the chamber confirmed in its safe state, exit 1, that step not
/// recorded;
/// the printed resume completes with every step once.
#[test]
fn a_modbus_exception_mid_step_stops_the_run_and_the_resume_completes() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = short_series(tmp.path(), &[]);
    let dir = tmp.path().join("run");
    let sim = sim_with_chamber(&plan, &["--fault", "chamber:exception@reading65"]);
    let first = output_within(&mut run_on(&sim, &plan, &dir), RUN_LIMIT);
    let text = said(&first);
    assert_eq!(first.code, Some(1), "{text}");
    let failed = the_chamber_failure(&text);
    assert!(
        failed.contains(&format!("{} (Watlow F4", sim.chamber()))
            && failed.contains("the controller refused `read register")
            && failed.contains("Modbus exception 4 (slave device failure)"),
        "{failed}"
    );
    assert_stopped_at_26(&text, &dir);
    assert!(text.contains("the table is at rest"), "{text}");
    assert!(text.contains(SAFE_LINE), "{text}");
    let m = json(&dir, "manifest.json");
    assert_eq!(m["status"], "failed", "{:#}", m["status"]);
    assert_eq!(m["chamber"]["safe_confirmed"], true, "{:#}", m["chamber"]);

    let ended = run_printed(&printed_resume(&text));
    assert_completed(&ended, &dir);
    assert_sim_safe(sim);
}

/// Every chamber reply from the meter's 65th reading on held back 120 sim seconds (0.2 s of
/// wall time at 600 sim seconds a second), well within the F4's 1 s reply timeout: the
/// replies are late, nothing more; the series completes with the chamber confirmed.
#[test]
fn slow_chamber_replies_within_the_deadline_only_slow_the_series() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = short_series(tmp.path(), &[]);
    let dir = tmp.path().join("run");
    let sim = sim_with_chamber(&plan, &["--fault", "chamber:slow@reading65/120s"]);
    let ended = output_within(&mut run_on(&sim, &plan, &dir), RUN_LIMIT);
    assert_completed(&ended, &dir);
    assert_sim_safe(sim);
}

/// Every chamber reply from the meter's 65th reading on held back 3000 sim seconds (5 s of
/// wall time), beyond the F4's three attempts of 1 s: the chamber is treated as silent. The
/// run stops saying so, the step under way (at 26 °C) not recorded, the table at rest; the
/// safe state cannot be read back, so the ending says the chamber could NOT be confirmed,
/// and the exit is 1.
#[test]
fn slow_chamber_replies_beyond_the_deadline_are_a_silent_chamber() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = short_series(tmp.path(), &[]);
    let dir = tmp.path().join("run");
    let sim = sim_with_chamber(&plan, &["--fault", "chamber:slow@reading65/3000s"]);
    let ended = output_within(&mut run_on(&sim, &plan, &dir), RUN_LIMIT);
    let text = said(&ended);
    assert_eq!(ended.code, Some(1), "{text}");
    let failed = the_chamber_failure(&text);
    assert!(
        failed.contains("no answer to `read register")
            && failed.contains("(asked 3 times; the chamber is silent)"),
        "{failed}"
    );
    assert_stopped_at_26(&text, &dir);
    assert!(text.contains("the table is at rest"), "{text}");
    assert!(text.contains(NOT_CONFIRMED), "{text}");
    assert!(!text.contains(SAFE_LINE), "{text}");
    let m = json(&dir, "manifest.json");
    assert_eq!(m["chamber"]["safe_confirmed"], false, "{:#}", m["chamber"]);
    // the chamber executes what it is sent and answers late: where its setpoint ends depends
    // on how far it got, so only the table is asserted here
    let state = sim.finish();
    assert_eq!(state["table"]["stopped"], true, "{state:#}");
    assert_eq!(state["faults"][0]["fired"], true, "{state:#}");
}
