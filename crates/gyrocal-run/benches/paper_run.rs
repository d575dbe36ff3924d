//! Wall time of a whole simulated calibration: the paper plan (19 rates × 500 readings, about
//! ten simulated minutes) through the real drivers and the simulated bench in virtual time, with
//! the run directory written to a temporary folder. This is what `gyrocal run --simulate` costs
//! and bounds how fast CI can exercise the sequencer.

#![allow(missing_docs, clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

#[path = "../tests/common/mod.rs"]
mod common;

use common::table_config;
use criterion::{Criterion, criterion_group, criterion_main};
use gyrocal_acl::AclTable;
use gyrocal_files::{Plan, RunDir, RunMeta, Status};
use gyrocal_run::{Sequencer, SequencerOptions, StopRequest};
use gyrocal_sim::bench::Bench;
use gyrocal_sim::from_plan::bench_config;

/// One run in virtual time: (simulated seconds, elapsed / physical bound).
fn run_once(plan: &Plan) -> (f64, f64) {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .start_paused(true)
        .build()
        .unwrap();
    let tmp = tempfile::tempdir().unwrap();
    rt.block_on(async {
        let bench = Bench::spawn(bench_config(plan));
        let run = RunDir::create(&tmp.path().join("run"), plan, RunMeta::default()).unwrap();
        let dmm = common::hp34401a(bench.dmm, plan);
        let table = AclTable::new(bench.table, table_config(plan));
        let mut seq = Sequencer::new(plan.clone(), dmm, table, run, SequencerOptions::default());
        let (_tx, rx) = tokio::sync::watch::channel(StopRequest::None);
        let summary = seq.run(rx).await;
        assert_eq!(summary.status, Status::Complete);
        let ratio = summary.timing.map_or(f64::NAN, |t| t.ratio);
        (summary.elapsed_s, ratio)
    })
}

fn paper_run(c: &mut Criterion) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/paper.toml");
    let plan = Plan::from_file(&path).unwrap();
    let (simulated, ratio) = run_once(&plan);
    eprintln!(
        "one run = {simulated:.1} simulated seconds; elapsed / physical bound {ratio:.5} \
         (issue 11's target: <= 1.002)"
    );
    let mut g = c.benchmark_group("simulated run");
    g.sample_size(10);
    g.bench_function("paper plan, 19 x 500 readings, virtual time", |b| {
        b.iter(|| run_once(&plan))
    });
    g.finish();
}

criterion_group!(benches, paper_run);
criterion_main!(benches);
