//! The runs known through the catalog (`live_runs`, another bench's) as the dashboard shows
//! them beside the roots' runs: a run in both once (from its directory), a running row not
//! updated for longer than the stale limit marked stale, its page under `/live/HOST/RUN_ID`
//! with the steps its state carries.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::time::{Duration, SystemTime};

use gyrocal_catalog::LiveRow;
use gyrocal_serve::runs::{self, RunKey, RunView, STALE_AFTER};

fn row(run_id: &str, host: &str, updated: SystemTime, status: &str) -> LiveRow {
    let state = serde_json::json!({
        "format": 1, "run_id": run_id, "station": "bench-9", "gyro_serial": "SN-9",
        "plan_name": "paper", "plan_kind": "scale_factor", "phase": "acquiring",
        "step": 3, "steps": 19, "steps_done": 2, "eta_s": 50.0,
        "last_reading_v": 0.1, "running_mean_v": 0.1, "table": null,
        "step_summaries": [
            {"number": 1, "rate_dps": 0.0, "volts": 0.0, "volts_std": null, "n": 10, "overloads": 0, "t_end_s": 1.0},
            {"number": 2, "rate_dps": 1.0, "volts": 0.05, "volts_std": null, "n": 10, "overloads": 0, "t_end_s": 2.0}
        ],
        "status": status, "reason": null, "verdict": null, "pid": 1, "hostname": host,
        "updated_utc": gyrocal_files::rfc3339_utc(updated)
    });
    LiveRow {
        run_id: run_id.into(),
        host: host.into(),
        station_id: Some("bench-9".into()),
        dut_serial: Some("SN-9".into()),
        plan_name: "paper".into(),
        kind: "scale_factor".into(),
        phase: "acquiring".into(),
        step: 3,
        steps: 19,
        steps_done: 2,
        eta_s: Some(50.0),
        last_reading_v: Some(0.1),
        running_mean_v: Some(0.1),
        table_state: None,
        status: status.into(),
        verdict: None,
        updated_utc: gyrocal_files::rfc3339_utc(updated),
        state_json: state.to_string(),
    }
}

fn local(name: &str) -> RunView {
    let now = SystemTime::now();
    let mut d = runs::from_row(&row(name, "here", now, "running"), now).view;
    d.key = RunKey::local(0, name.into());
    d.href = d.key.href();
    d
}

#[test]
fn a_run_in_a_root_and_in_the_catalog_is_shown_once_from_its_directory() {
    let now = SystemTime::now();
    let rows = vec![
        row("both-1", "bench-a", now, "running"),
        row("remote-1", "bench-b", now, "running"),
    ];
    let all = runs::merge(vec![local("both-1")], &rows, now);
    let names: Vec<(&str, Option<&str>)> = all
        .iter()
        .map(|v| (v.key.name.as_str(), v.key.host.as_deref()))
        .collect();
    assert_eq!(names, vec![("both-1", None), ("remote-1", Some("bench-b"))]);
    assert_eq!(all[0].href, "/run/0/both-1");
    assert_eq!(all[1].href, "/live/bench-b/remote-1");
    assert_eq!((all[1].steps_done, all[1].steps), (2, 19));
}

#[test]
fn a_running_row_older_than_the_stale_limit_is_stale_and_an_ended_one_is_not() {
    let now = SystemTime::now();
    let old = now - STALE_AFTER - Duration::from_secs(5);
    let stale = runs::from_row(&row("old-1", "bench-c", old, "running"), now);
    assert!(stale.view.stale);
    assert_eq!(stale.view.phase, "stale");
    assert!(stale.view.stale_reason.unwrap().contains("bench-c"));
    let fresh = runs::from_row(&row("new-1", "bench-c", now, "running"), now);
    assert!(!fresh.view.stale);
    let ended = runs::from_row(&row("done-1", "bench-c", old, "complete"), now);
    assert!(!ended.view.stale);
    // the steps come from the row's state
    assert_eq!(fresh.step_summaries.len(), 2);
    assert_eq!(fresh.step_summaries[1].rate_dps, 1.0);
}

#[test]
fn a_row_whose_state_does_not_read_is_shown_from_its_columns() {
    let now = SystemTime::now();
    let mut r = row("garbled-1", "bench-d", now, "running");
    r.state_json = "{not json".into();
    let d = runs::from_row(&r, now);
    assert_eq!((d.view.steps_done, d.view.plan_name.as_str()), (2, "paper"));
    assert!(d.step_summaries.is_empty());
}

#[test]
fn a_row_shows_when_its_run_started_and_ended_and_an_older_state_shows_neither() {
    let now = SystemTime::now();
    let mut r = row("done-2", "bench-e", now, "complete");
    let mut state: serde_json::Value = serde_json::from_str(&r.state_json).unwrap();
    state["started_utc"] = "2026-12-07T08:00:00.000Z".into();
    state["ended_utc"] = "2026-12-07T08:12:30.500Z".into();
    r.state_json = state.to_string();
    let d = runs::from_row(&r, now).view;
    assert_eq!(d.started_utc.as_deref(), Some("2026-12-07T08:00:00.000Z"));
    assert_eq!(d.ended_utc.as_deref(), Some("2026-12-07T08:12:30.500Z"));
    // a state written before these members existed still reads, without them
    let older = runs::from_row(&row("done-3", "bench-e", now, "complete"), now).view;
    assert_eq!((older.started_utc, older.ended_utc), (None, None));
    assert_eq!(older.status, "complete");
}
