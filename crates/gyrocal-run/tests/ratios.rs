//! No wasted instrument time: a run's elapsed time against its physical bound (ramps at the
//! acceleration limit, the plan's dwells, the meter's arming, readings and the transfers no
//! sequencer can hide; see `gyrocal_run::estimate`), on the simulated bench in virtual time,
//! where the figures are exact and reproducible. The targets are issue 11's: the paper plan
//! within 0.2 %, a 200-rate × 50-reading plan within 0.4 %, memory mode within the same.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use common::{set, table_config};
use gyrocal_acl::AclTable;
use gyrocal_files::{Plan, RunDir, RunMeta, Status};
use gyrocal_run::{Sequencer, SequencerOptions, StopRequest};
use gyrocal_sim::bench::Bench;
use gyrocal_sim::from_plan::bench_config;

/// `configs/paper.toml` with `edit` applied.
fn paper_with(edit: impl FnOnce(&mut toml::Table)) -> Plan {
    common::plan_with("paper.toml", edit)
}

/// Runs `plan` to completion; returns (ratio, elapsed s, bound s, acquisition).
async fn ratio(plan: &Plan) -> (f64, f64, f64, String) {
    let tmp = tempfile::tempdir().unwrap();
    let bench = Bench::spawn(bench_config(plan));
    let run = RunDir::create(&tmp.path().join("run"), plan, RunMeta::default()).unwrap();
    let dmm = common::hp34401a(bench.dmm, plan);
    let table = AclTable::new(bench.table, table_config(plan));
    let mut seq = Sequencer::new(plan.clone(), dmm, table, run, SequencerOptions::default());
    let (_tx, rx) = tokio::sync::watch::channel(StopRequest::None);
    let summary = seq.run(rx).await;
    assert_eq!(summary.status, Status::Complete, "{:?}", summary.reason);
    let t = summary.timing.unwrap();
    eprintln!(
        "{}: elapsed {:.3} s, bound {:.3} s, ratio {:.5} ({})",
        plan.name(),
        t.elapsed_s,
        t.bound_s,
        t.ratio,
        t.acquisition.as_deref().unwrap_or("?")
    );
    assert!(t.ratio >= 1.0, "faster than physics? {t:?}");
    (
        t.ratio,
        t.elapsed_s,
        t.bound_s,
        t.acquisition.unwrap_or_default(),
    )
}

#[tokio::test(start_paused = true)]
async fn paper_plan_streams_within_0_2_percent_of_the_physical_bound() {
    let plan = paper_with(|_| {});
    let (r, ..) = ratio(&plan).await;
    assert!(r <= 1.002, "ratio {r}");
}

#[tokio::test(start_paused = true)]
async fn paper_plan_in_memory_mode_within_0_2_percent_of_the_physical_bound() {
    let plan = paper_with(|d| set(d, "dmm", "acquisition", "memory".into()));
    let (r, _, _, acq) = ratio(&plan).await;
    assert_eq!(acq, "memory");
    assert!(r <= 1.002, "ratio {r}");
}

#[tokio::test(start_paused = true)]
async fn two_hundred_rates_of_fifty_readings_within_0_4_percent_of_the_physical_bound() {
    let plan = paper_with(|d| {
        // ±0.1 ... ±10 °/s in 0.1 °/s steps, the directions alternating: 200 steps
        let rates: Vec<toml::Value> = (1..=100)
            .flat_map(|k| {
                let r = f64::from(k) / 10.0;
                [toml::Value::Float(r), toml::Value::Float(-r)]
            })
            .collect();
        set(d, "plan", "rates_dps", toml::Value::Array(rates));
        set(d, "plan", "samples_per_rate", toml::Value::Integer(50));
        set(d, "plan", "name", "200 rates x 50 readings".into());
    });
    assert_eq!(plan.schedule().len(), 200);
    let (r, ..) = ratio(&plan).await;
    assert!(r <= 1.004, "ratio {r}");
}
