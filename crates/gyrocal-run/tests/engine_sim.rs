//! The engine's seams against the simulated bench, in virtual time: a consumer of the results
//! is added without touching the engine (the sink), a consumer that fails ends the run
//! through the guaranteed teardown with the table at rest, and a drift record with the servo
//! off and a sweep end at rest through the same teardown, whether they complete or are
//! stopped.

#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)] // test helpers

mod common;

use std::path::Path;
use std::sync::{Arc, Mutex};

use common::{config, new_run, plan_with_rates, table_config};
use gyrocal_acl::AclTable;
use gyrocal_files::{Plan, Status, StepRecord, load};
use gyrocal_run::sink::{Recorded, SinkError};
use gyrocal_run::{Event, RunSummary, Sequencer, SequencerOptions, Sink, StopRequest, TableRest};
use gyrocal_sim::bench::{Bench, BenchHandle};
use gyrocal_sim::from_plan::bench_config;
use gyrocal_sim::table::SimMode;
use tokio::sync::watch;

/// A consumer the engine never heard of: it keeps every step row it is pushed, and fails
/// (as a full disk would) at the `fail_at`-th row when asked to.
#[derive(Clone, Default)]
struct CollectRows {
    rows: Arc<Mutex<Vec<StepRecord>>>,
    fail_at: Option<usize>,
}

impl Sink for CollectRows {
    fn recorded(&mut self, r: &Recorded<'_>, _: &mut Vec<Event>) -> Result<(), SinkError> {
        let mut rows = self.rows.lock().unwrap();
        rows.push(r.row.clone());
        if Some(rows.len()) == self.fail_at {
            return Err(SinkError::Other {
                sink: "row collector".into(),
                message: "no space left on device".into(),
            });
        }
        Ok(())
    }
}

/// Runs `plan` on a fresh simulated bench with `sink` added, asking for a controlled stop
/// once `stop_after` rows were recorded (if given).
async fn run(
    plan: &Plan,
    dir: &Path,
    sink: CollectRows,
    stop_after: Option<usize>,
) -> (RunSummary, BenchHandle) {
    let bench = Bench::spawn(bench_config(plan));
    let handle = bench.handle;
    let dmm = common::hp34401a(bench.dmm, plan);
    let table = AclTable::new(bench.table, table_config(plan));
    let (events_tx, mut events) = tokio::sync::mpsc::unbounded_channel();
    let mut seq = Sequencer::new(
        plan.clone(),
        dmm,
        table,
        new_run(plan, dir),
        SequencerOptions::default(),
    )
    .with_sink(sink)
    .with_events(events_tx);
    let (stop_tx, stop_rx) = watch::channel(StopRequest::None);
    tokio::spawn(async move {
        let mut done = 0;
        while let Some(e) = events.recv().await {
            if matches!(e, Event::StepDone(_)) {
                done += 1;
                if Some(done) == stop_after {
                    let _ = stop_tx.send(StopRequest::Controlled("test"));
                }
            }
        }
    });
    let summary = seq.run(stop_rx).await;
    (summary, handle)
}

/// configs/drift.toml, short, with `[drift] table = table`.
fn drift(table: &str) -> Plan {
    let path = config("drift.toml");
    let mut doc: toml::Table = std::fs::read_to_string(&path).unwrap().parse().unwrap();
    let p = doc.get_mut("plan").unwrap().as_table_mut().unwrap();
    p.insert("samples_per_rate".into(), 200.into());
    p.insert("repeat".into(), 4.into());
    let d = doc.get_mut("drift").unwrap().as_table_mut().unwrap();
    d.insert("table".into(), table.into());
    Plan::from_toml_str(&toml::to_string(&doc).unwrap(), &path).unwrap()
}

/// The simulated table's own account: at rest, in `mode`.
fn assert_at_rest(summary: &RunSummary, handle: &BenchHandle, mode: SimMode) {
    assert!(
        matches!(summary.table, TableRest::AtRest { .. }),
        "{:?}",
        summary.table
    );
    assert!(handle.table.is_stopped(), "the simulated table still turns");
    assert_eq!(handle.table.mode(), mode);
}

#[tokio::test(start_paused = true)]
async fn a_consumer_added_without_touching_the_engine_receives_every_step_row() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = plan_with_rates(&[0.0, 5.0, -5.0]);
    let sink = CollectRows::default();
    let (summary, handle) = run(&plan, &tmp.path().join("run"), sink.clone(), None).await;
    assert_eq!(summary.status, Status::Complete, "{:?}", summary.reason);
    assert_at_rest(&summary, &handle, SimMode::Off);
    let collected = sink.rows.lock().unwrap().clone();
    let on_disk = load(&tmp.path().join("run")).unwrap().steps;
    assert_eq!(collected.len(), 3);
    // the consumer saw what steps.csv holds (the file writes 12 significant digits)
    assert_eq!(collected.len(), on_disk.len());
    for (c, d) in collected.iter().zip(&on_disk) {
        assert_eq!(
            (c.step, c.n, c.t_start_s, c.t_end_s),
            (d.step, d.n, d.t_start_s, d.t_end_s)
        );
        assert!(
            (c.volts - d.volts).abs() <= 1e-9 * d.volts.abs().max(1e-3),
            "{c:?} vs {d:?}"
        );
    }
    let rates: Vec<f64> = collected.iter().map(|r| r.rate_dps).collect();
    assert_eq!(rates, [0.0, 5.0, -5.0]);
}

#[tokio::test(start_paused = true)]
async fn a_consumer_that_fails_ends_the_run_failed_with_the_table_at_rest() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = plan_with_rates(&[0.0, 10.0, -10.0, 5.0]);
    let sink = CollectRows {
        fail_at: Some(2),
        ..CollectRows::default()
    };
    let (summary, handle) = run(&plan, &tmp.path().join("run"), sink, None).await;
    assert_eq!(summary.status, Status::Failed);
    let reason = summary.reason.clone().unwrap();
    assert!(
        reason.contains("row collector: no space left on device"),
        "{reason}"
    );
    assert!(summary.resumable);
    assert_at_rest(&summary, &handle, SimMode::Off);
    // the run directory (the first consumer) has the rows it took, and says failed
    let data = load(&tmp.path().join("run")).unwrap();
    assert_eq!(data.steps.len(), 2);
    assert_eq!(data.manifest.status, Status::Failed);
}

#[tokio::test(start_paused = true)]
async fn a_servo_off_drift_record_and_a_sweep_end_at_rest_through_the_same_teardown() {
    let tmp = tempfile::tempdir().unwrap();
    // complete: every segment recorded, the servo was off throughout and stays off
    let plan = drift("servo_off");
    let (summary, handle) = run(
        &plan,
        &tmp.path().join("drift"),
        CollectRows::default(),
        None,
    )
    .await;
    assert_eq!(summary.status, Status::Complete, "{:?}", summary.reason);
    assert_eq!(summary.steps_recorded, 4);
    assert_at_rest(&summary, &handle, SimMode::Off);
    assert!(!handle.table.interlock_closed(), "the servo stays off");
    // stopped after its second segment: the same teardown
    let (summary, handle) = run(
        &plan,
        &tmp.path().join("drift-stopped"),
        CollectRows::default(),
        Some(2),
    )
    .await;
    assert_eq!(summary.status, Status::Aborted, "{:?}", summary.reason);
    assert_eq!(summary.steps_recorded, 2);
    assert_at_rest(&summary, &handle, SimMode::Off);

    // a sweep, complete and stopped after its second step while turning
    let sweep = plan_with_rates(&[0.0, 10.0, -10.0, 5.0]);
    let (summary, handle) = run(
        &sweep,
        &tmp.path().join("sweep"),
        CollectRows::default(),
        None,
    )
    .await;
    assert_eq!(summary.status, Status::Complete, "{:?}", summary.reason);
    assert_at_rest(&summary, &handle, SimMode::Off);
    let (summary, handle) = run(
        &sweep,
        &tmp.path().join("sweep-stopped"),
        CollectRows::default(),
        Some(2),
    )
    .await;
    assert_eq!(summary.status, Status::Aborted, "{:?}", summary.reason);
    assert_at_rest(&summary, &handle, SimMode::Off);
}

#[tokio::test(start_paused = true)]
async fn a_drift_record_without_a_table_says_no_table_and_moves_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = drift("none");
    let bench = Bench::spawn(bench_config(&plan));
    let handle = bench.handle;
    let dmm = common::hp34401a(bench.dmm, &plan);
    let mut seq = Sequencer::new(
        plan.clone(),
        dmm,
        gyrocal_table::NoTable::new(),
        new_run(&plan, &tmp.path().join("run")),
        SequencerOptions::default(),
    );
    let (_tx, rx) = watch::channel(StopRequest::None);
    let summary = seq.run(rx).await;
    assert_eq!(summary.status, Status::Complete, "{:?}", summary.reason);
    assert_eq!(summary.table, TableRest::NoTable);
    assert_eq!(summary.steps_recorded, 4);
    assert!(handle.table.is_stopped());
}
