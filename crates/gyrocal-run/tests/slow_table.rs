//! A table whose replies come late (a controller busy with a profile, a serial converter with a
//! deep buffer, a network bridge), in virtual time against the simulated bench: a late reply is
//! never taken for another query's, the deadlines adapt to a table that is slow but alive and
//! the operator is told, and whatever happens the run ends with the table at rest — or says
//! plainly that it could not confirm it, and only when it truly could not.

#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)] // test helpers

mod common;

use std::path::Path;
use std::time::Duration;

use common::{new_run, plan_from, plan_with_rates, table_config};
use gyrocal_acl::AclTable;
use gyrocal_aerosmith::{AerosmithConfig, AerosmithTable};
use gyrocal_files::{Plan, Status, load};
use gyrocal_run::{Event, Phase, RunSummary, Sequencer, SequencerOptions, StopRequest, TableRest};
use gyrocal_sim::bench::Bench;
use gyrocal_sim::from_plan::bench_config;
use gyrocal_sim::table::{SimMode, TableHandle};
use gyrocal_table::RateTable;
use tokio::sync::{mpsc, watch};
use tokio::time::Instant;

type Hook = Box<dyn FnMut(&Event, &TableHandle) -> Option<StopRequest> + Send>;

/// Runs `plan` on a fresh simulated bench (34401A, and the table of the plan's dialect: ACL or
/// Aerosmith); `hook` sees every event with the simulated table in hand (to make it slow) and
/// may ask for a stop.
async fn run(plan: &Plan, dir: &Path, hook: Hook) -> (RunSummary, Vec<Event>, TableHandle) {
    // RUST_LOG=gyrocal_acl=debug shows the late replies and the markers
    let _ = tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_test_writer()
        .try_init();
    let bench = Bench::spawn(bench_config(plan));
    let sim = bench.handle.table.clone();
    let dmm = common::hp34401a(bench.dmm, plan);
    let acl = table_config(plan);
    let (summary, events) = if plan.table().dialect == gyrocal_files::TableDialect::Aerosmith {
        let config = AerosmithConfig {
            policy: acl.policy(),
            ..AerosmithConfig::default()
        };
        let table = AerosmithTable::new(bench.table, config);
        drive(plan, dir, hook, dmm, table, sim.clone()).await
    } else {
        let table = AclTable::new(bench.table, acl);
        drive(plan, dir, hook, dmm, table, sim.clone()).await
    };
    (summary, events, sim)
}

async fn drive<T: RateTable + 'static>(
    plan: &Plan,
    dir: &Path,
    mut hook: Hook,
    dmm: gyrocal_hp34401a::Hp34401aMeter<gyrocal_link::StreamTransport<tokio::io::DuplexStream>>,
    table: T,
    sim: TableHandle,
) -> (RunSummary, Vec<Event>) {
    let (events_tx, mut events) = mpsc::unbounded_channel();
    let mut seq = Sequencer::new(
        plan.clone(),
        dmm,
        table,
        new_run(plan, dir),
        SequencerOptions::default(),
    )
    .with_events(events_tx);
    let (stop_tx, stop_rx) = watch::channel(StopRequest::None);
    let seen = tokio::spawn(async move {
        let mut all = Vec::new();
        while let Some(e) = events.recv().await {
            if let Some(req) = hook(&e, &sim) {
                let _ = stop_tx.send(req);
            }
            all.push(e);
        }
        all
    });
    let summary = seq.run(stop_rx).await;
    drop(seq);
    (summary, seen.await.unwrap())
}

/// Makes every table reply late by `delay` from the moment step `step` starts acquiring.
fn slow_from_step(step: usize, delay: Duration) -> Hook {
    Box::new(move |e, sim| {
        if let Event::Phase {
            step: s,
            phase: Phase::Acquiring,
        } = e
            && *s == step
            && !sim.is_slow()
        {
            sim.hold_replies(delay, None);
        }
        None
    })
}

fn assert_at_rest_now(sim: &TableHandle, summary: &RunSummary) {
    let rate = sim.actual_rate(Instant::now());
    assert!(
        rate.abs() < 0.01,
        "the run returned with the table turning at {rate} °/s ({:?})",
        summary.table
    );
    assert_eq!(sim.mode(), SimMode::Off, "{:?}", summary.table);
}

/// Every recorded step's measured table rate is the demanded one: a late reply taken for a
/// `:Read:Rate?` (an error-queue entry, a status byte, a mode) would show here, or fail the
/// parse and the run.
fn assert_rates_are_rates(dir: &Path) {
    for s in load(dir).unwrap().steps {
        let meas = s.rate_meas_dps.expect("measured rate");
        assert!(
            (meas - s.rate_dps).abs() < 0.01,
            "step {} at {} °/s recorded a table rate of {meas} °/s",
            s.step,
            s.rate_dps
        );
        let (lo, hi) = (s.rate_meas_min_dps.unwrap(), s.rate_meas_max_dps.unwrap());
        assert!(
            (lo - s.rate_dps).abs() < 0.01 && (hi - s.rate_dps).abs() < 0.01,
            "step {}: a sample of {lo}..{hi} °/s at {} °/s",
            s.step,
            s.rate_dps
        );
    }
}

/// The operator's "decelerating from" quotes a rate measured in that exchange, or none. The
/// stop was sent first, so a rate read after it may be anything from `top` °/s down to rest;
/// what it must not be is another query's reply (a status byte, an error code).
fn assert_stopping_rate_measured(events: &[Event], top: f64) {
    let from = events.iter().find_map(|e| match e {
        Event::Stopping { from_dps, .. } => Some(*from_dps),
        _ => None,
    });
    if let Some(Some(from)) = from {
        assert!(
            (-0.05..top + 0.05).contains(&from),
            "decelerating from {from}"
        );
    }
}

fn retry_messages(dir: &Path) -> Vec<String> {
    load(dir)
        .unwrap()
        .manifest
        .retries
        .into_iter()
        .filter(|r| r.instrument == "table")
        .map(|r| r.message)
        .collect()
}

/// The delays the issue tried (0.5, 0.9 and 1.2 s, against a 333 ms attempt deadline), from
/// the middle of a run: the late replies are recognised and discarded, the deadlines adapt,
/// the run completes with every step's measured rate its own, and the table ends at rest.
#[tokio::test(start_paused = true)]
async fn a_table_that_turns_slow_mid_run_keeps_the_run_in_step_and_ends_at_rest() {
    for delay_ms in [350u64, 500, 900, 1200] {
        let plan = plan_with_rates(&[0.0, 5.0, -2.0, 2.0]);
        slow_run_keeps_in_step(&plan, delay_ms).await;
    }
}

/// `plan` with every table reply `delay_ms` late from step 1's acquisition on: the run
/// completes at rest, every step's measured rate is its own, the late replies were recognised
/// and discarded, and the operator was told that the table answers slowly.
async fn slow_run_keeps_in_step(plan: &Plan, delay_ms: u64) {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let (summary, _events, sim) = run(
        plan,
        &dir,
        slow_from_step(1, Duration::from_millis(delay_ms)),
    )
    .await;
    assert_at_rest_now(&sim, &summary);
    assert_eq!(
        summary.status,
        Status::Complete,
        "{delay_ms} ms: {:?}",
        summary.reason
    );
    assert!(
        matches!(summary.table, TableRest::AtRest { .. }),
        "{delay_ms} ms: {:?}",
        summary.table
    );
    assert_rates_are_rates(&dir);
    let notes = retry_messages(&dir);
    assert!(
        notes.iter().any(|m| m.contains("the table answers slowly")),
        "{delay_ms} ms: the operator was not told: {notes:#?}"
    );
    assert!(
        notes
            .iter()
            .any(|m| m.contains("late repl") && m.contains("discarded")),
        "{delay_ms} ms: {notes:#?}"
    );
}

/// A stop while the replies are late: the stop command is executed at once, and gyrocal keeps
/// asking until the table reports rest, whatever the latency below the rest deadline.
#[tokio::test(start_paused = true)]
async fn a_stop_on_a_slow_table_waits_for_the_late_replies_and_confirms_rest() {
    let plan = plan_with_rates(&[0.0, 10.0]);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let hook: Hook = Box::new(|e, sim| match e {
        Event::Phase {
            step: 1,
            phase: Phase::Acquiring,
        } => {
            sim.hold_replies(Duration::from_millis(1500), None);
            Some(StopRequest::Controlled("test"))
        }
        _ => None,
    });
    let (summary, events, sim) = run(&plan, &dir, hook).await;
    assert_eq!(summary.status, Status::Aborted, "{:?}", summary.reason);
    assert!(
        matches!(summary.table, TableRest::AtRest { .. }),
        "{:?}",
        summary.table
    );
    assert_at_rest_now(&sim, &summary);
    // the operator's "decelerating from" quotes a rate measured in that exchange, or none
    assert_stopping_rate_measured(&events, 10.0);
}

/// A table whose first late reply comes after the whole deadline of the query it answers (2 s
/// here, the heartbeat deadline) cannot be told from a silent one during that query: the run
/// fails. But the table is alive, and the stop path, which keeps asking with deadlines that
/// have adapted to the late replies meanwhile, confirms it at rest.
#[tokio::test(start_paused = true)]
async fn a_table_slower_than_its_first_deadline_fails_the_run_but_is_confirmed_at_rest() {
    let plan = plan_with_rates(&[0.0, 10.0, -5.0]);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let (summary, events, sim) =
        run(&plan, &dir, slow_from_step(1, Duration::from_millis(2000))).await;
    assert_eq!(summary.status, Status::Failed, "{:?}", summary.reason);
    assert!(
        matches!(summary.table, TableRest::AtRest { .. }),
        "{:?}",
        summary.table
    );
    assert_at_rest_now(&sim, &summary);
    // step 1 was not recorded: the table's rate during it is unknown
    assert_eq!(load(&dir).unwrap().steps.len(), 1);
    assert_stopping_rate_measured(&events, 10.0);
}

/// A table slower than the slow-reply limit (5 s) is silent as far as gyrocal can tell: the
/// run fails, and the last word is that the table could NOT be confirmed at rest — never "at
/// rest" from a reply that was not its own.
#[tokio::test(start_paused = true)]
async fn a_table_slower_than_the_limit_is_never_called_at_rest() {
    let plan = plan_with_rates(&[0.0, 10.0]);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let (summary, _events, sim) = run(&plan, &dir, slow_from_step(1, Duration::from_secs(8))).await;
    assert_eq!(summary.status, Status::Failed, "{:?}", summary.reason);
    assert!(
        matches!(summary.table, TableRest::NotConfirmed { .. }),
        "{:?}",
        summary.table
    );
    // the stop itself was obeyed (commands are executed when they arrive)
    sim.hold_replies(Duration::ZERO, None);
    tokio::time::sleep(Duration::from_secs(10)).await;
    assert!(sim.actual_rate(Instant::now()).abs() < 0.01);
}

/// The same policy for the Aerosmith dialect, which counts the prompts it is owed: a table
/// slow from mid-run completes with every step's rate its own and ends at rest.
#[tokio::test(start_paused = true)]
async fn an_aerosmith_table_that_turns_slow_mid_run_keeps_the_run_in_step_and_ends_at_rest() {
    for delay_ms in [500u64, 1200] {
        let plan = plan_from("aerosmith.toml", &[0.0, 5.0, -2.0]);
        slow_run_keeps_in_step(&plan, delay_ms).await;
    }
}

/// A second request during the deceleration of a slow table: the emergency stop waits for the
/// link as long as a query to that table may hold it, and goes through.
#[tokio::test(start_paused = true)]
async fn an_emergency_stop_gets_through_while_a_slow_query_holds_the_link() {
    let plan = plan_with_rates(&[0.0, 20.0]);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    // replies 2.6 s late: a poll holds the link longer than the 2.5 s a stop used to wait
    let hook: Hook = Box::new(|e, sim| match e {
        Event::Phase {
            step: 1,
            phase: Phase::Acquiring,
        } => {
            sim.hold_replies(Duration::from_millis(2600), None);
            Some(StopRequest::Controlled("test"))
        }
        Event::Stopping { .. } => Some(StopRequest::Emergency("test again")),
        _ => None,
    });
    let (summary, _events, sim) = run(&plan, &dir, hook).await;
    assert!(!sim.interlock_closed(), "the emergency stop was not sent");
    assert!(summary.emergency_stop);
    assert!(
        summary
            .reason
            .as_deref()
            .unwrap_or_default()
            .contains("emergency stop"),
        "{:?}",
        summary.reason
    );
    assert!(
        matches!(summary.table, TableRest::AtRest { .. }),
        "{:?}",
        summary.table
    );
    assert_at_rest_now(&sim, &summary);
}
