//! The sequencer against the simulated bench, in virtual time: whole plans through the real
//! drivers and the real run directory.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use std::path::Path;
use std::time::Duration;

use common::{config, new_run, plan_with, set, table_config};
use gyrocal_acl::AclTable;
use gyrocal_analysis::sweep::fit_run;
use gyrocal_files::{Plan, RunDir, RunMeta, Status, load, load_samples};
use gyrocal_run::{RunSummary, Sequencer, SequencerOptions, StopRequest};
use gyrocal_sim::bench::{Bench, BenchHandle};
use gyrocal_sim::from_plan::bench_config;
use tokio::sync::watch;

/// Runs `plan` on `bench` into `run`, asking for a stop once `stop_after` steps were recorded
/// in this session (if given); fits a complete run as the CLI does.
async fn run_with(
    plan: &Plan,
    bench: Bench,
    run: RunDir,
    stop_after: Option<usize>,
) -> (RunSummary, BenchHandle) {
    let dmm = common::hp34401a(bench.dmm, plan);
    let table = AclTable::new(bench.table, table_config(plan));
    let (events_tx, mut events) = tokio::sync::mpsc::unbounded_channel();
    let mut seq = Sequencer::new(plan.clone(), dmm, table, run, SequencerOptions::default())
        .with_events(events_tx);
    let (stop_tx, stop_rx) = watch::channel(StopRequest::None);
    tokio::spawn(async move {
        let mut done = 0;
        while let Some(e) = events.recv().await {
            if matches!(e, gyrocal_run::Event::StepDone(_)) {
                done += 1;
                if Some(done) == stop_after {
                    let _ = stop_tx.send(StopRequest::Controlled("test"));
                }
            }
        }
    });
    let summary = seq.run(stop_rx).await;
    if summary.status == Status::Complete {
        let mut run = seq.into_run_dir();
        fit_run(&mut run, &gyrocal_fit::Options::default()).unwrap();
    }
    (summary, bench.handle)
}

/// Runs `plan` on a fresh bench into `dir` (created or resumed), stopping when `stop_after`
/// steps were recorded in this session, if given.
async fn run_plan(
    plan: &Plan,
    dir: &Path,
    resume: bool,
    stop_after: Option<usize>,
) -> (RunSummary, BenchHandle) {
    let bench = Bench::spawn(bench_config(plan));
    let run = if resume {
        RunDir::open_for_resume(dir, plan).unwrap()
    } else {
        new_run(plan, dir)
    };
    run_with(plan, bench, run, stop_after).await
}

#[tokio::test(start_paused = true)]
async fn paper_plan_completes_and_recovers_the_truth() {
    let plan = Plan::from_file(&config("paper.toml")).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let (summary, bench) = run_plan(&plan, &dir, false, None).await;
    assert_eq!(summary.status, Status::Complete, "{:?}", summary.reason);

    let data = load(&dir).unwrap();
    assert_eq!(data.steps.len(), 19);
    assert_eq!(load_samples(&dir).unwrap().len(), 19 * 500);
    assert_eq!(data.manifest.status, Status::Complete);

    // the linear fit recovers the simulated gyro's line over the same schedule (the ideal
    // linear calibration of the true, slightly nonlinear and asymmetric model) within 3
    // reported standard errors
    let fit = gyrocal_files::load_fit(&dir).unwrap().expect("fit.json");
    let lin = fit
        .fit(
            gyrocal_fit::Method::LeastSquares,
            gyrocal_fit::Model::Linear,
        )
        .unwrap();
    let (true_k, true_k0) = bench.truth.fit_line(plan.rates_dps());
    let k = lin.scale_factor;
    let k0 = lin.bias;
    let sk = lin.std_errors.k1.unwrap();
    let sk0 = lin.std_errors.k0.unwrap();
    assert!((k - true_k).abs() < 3.0 * sk, "K {k} vs {true_k} ± {sk}");
    assert!(
        (k0 - true_k0).abs() < 3.0 * sk0,
        "K0 {k0} vs {true_k0} ± {sk0}"
    );
    // and the fit is sharp: the simulated K to 100 ppm
    assert!((k / true_k - 1.0).abs() < 1e-4, "K {k} vs {true_k}");

    // the table was parked at the end
    tokio::time::sleep(Duration::from_millis(10)).await;
    assert!(bench.table.is_stopped());

    // no instrument time wasted: within 3 % of the physical bound
    let timing = summary.timing.unwrap();
    assert!(
        timing.ratio < 1.03,
        "elapsed {} s vs bound {} s",
        timing.elapsed_s,
        timing.bound_s
    );
    assert!(timing.ratio >= 1.0, "faster than physics? {timing:?}");
}

#[tokio::test(start_paused = true)]
async fn a_stopped_run_resumes_to_completion_with_every_rate_once() {
    let plan = plan_with("quick.toml", |_| {});
    let n = plan.schedule().len();
    assert!(n >= 4);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let (summary, bench) = run_plan(&plan, &dir, false, Some(2)).await;
    assert_eq!(summary.status, Status::Aborted);
    tokio::time::sleep(Duration::from_millis(10)).await;
    assert!(bench.table.is_stopped() || bench.table.mode() != gyrocal_sim::table::SimMode::Rate);
    let partial = load(&dir).unwrap();
    assert_eq!(partial.manifest.status, Status::Aborted);
    assert!(partial.steps.len() >= 2 && partial.steps.len() < n);

    let (summary, _) = run_plan(&plan, &dir, true, None).await;
    assert_eq!(summary.status, Status::Complete, "{:?}", summary.reason);
    let data = load(&dir).unwrap();
    let mut steps: Vec<usize> = data.steps.iter().map(|s| s.step).collect();
    steps.sort_unstable();
    assert_eq!(steps, (0..n).collect::<Vec<_>>(), "every step exactly once");
    let samples = load_samples(&dir).unwrap();
    let per_step = plan.samples_per_rate() as usize;
    assert_eq!(samples.len(), n * per_step, "no lost or duplicated sample");
    assert_eq!(data.manifest.resumes.len(), 1);
}

#[tokio::test(start_paused = true)]
async fn memory_mode_overlaps_the_fetch_with_the_next_ramp() {
    // fast readings: the wire cannot keep up, so auto picks memory mode
    let plan = plan_with("quick.toml", |d| {
        set(d, "dmm", "nplc", toml::Value::Float(0.02));
        set(d, "dmm", "autozero", toml::Value::Boolean(false));
        set(d, "plan", "samples_per_rate", toml::Value::Integer(500));
    });
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let (summary, _) = run_plan(&plan, &dir, false, None).await;
    assert_eq!(summary.status, Status::Complete, "{:?}", summary.reason);
    let timing = summary.timing.unwrap();
    assert_eq!(timing.acquisition.as_deref(), Some("memory"));
    assert!(timing.ratio < 1.03, "{timing:?}");
    assert_eq!(
        load_samples(&dir).unwrap().len(),
        plan.schedule().len() * 500
    );
}

#[tokio::test(start_paused = true)]
async fn a_table_fault_fails_the_run_with_the_tables_message_and_stops_it() {
    let plan = plan_with("quick.toml", |_| {});
    let mut cfg = bench_config(&plan);
    cfg.table.faults.inject_after = Some(8.0);
    let bench = Bench::spawn(cfg);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let (summary, handle) = run_with(&plan, bench, new_run(&plan, &dir), None).await;
    assert_eq!(summary.status, Status::Failed);
    let manifest = load(&dir).unwrap().manifest;
    assert_eq!(manifest.status, Status::Failed);
    let reason = manifest.reason.unwrap();
    assert!(reason.contains("Tracking error limit exceeded"), "{reason}");
    tokio::time::sleep(Duration::from_millis(10)).await;
    assert_ne!(handle.table.mode(), gyrocal_sim::table::SimMode::Rate);
    // a fault takes the emergency path too: servo off
    assert!(
        !handle.table.interlock_closed(),
        "interlock still closed after a fault"
    );
}

/// The plan's bench with `fault` armed for the `reading`-th reading the meter takes.
fn bench_with_fault(plan: &Plan, reading: u64, fault: gyrocal_sim::dmm::Fault) -> Bench {
    let bench = Bench::spawn(bench_config(plan));
    bench.handle.dmm.inject_at_reading(reading, fault);
    bench
}

/// Runs `plan` on `bench` into a fresh `dir` without stop requests.
async fn run_on(plan: &Plan, bench: Bench, dir: &Path) -> RunSummary {
    run_with(plan, bench, new_run(plan, dir), None).await.0
}

#[tokio::test(start_paused = true)]
async fn multimeter_faults_mid_acquisition_are_retried_and_the_run_completes() {
    use gyrocal_sim::dmm::Fault;
    let plan = plan_with("quick.toml", |_| {});
    for (fault, what) in [
        (Fault::NoReply, "timeout"),
        (Fault::Garble, "garbled"),
        (Fault::Truncate, "truncated"),
    ] {
        // in the middle of the third step's readings
        let bench = bench_with_fault(&plan, 2 * 50 + 25, fault.clone());
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("run");
        let summary = run_on(&plan, bench, &dir).await;
        assert_eq!(
            summary.status,
            Status::Complete,
            "{what}: {:?}",
            summary.reason
        );
        let data = load(&dir).unwrap();
        assert_eq!(data.steps.len(), plan.schedule().len(), "{what}");
        // the retry is logged in the manifest and on the step
        assert!(!data.manifest.retries.is_empty(), "{what}: no retry logged");
        assert_eq!(
            data.manifest.retries[0].step,
            Some(2),
            "{what}: {:?}",
            data.manifest.retries
        );
        assert_eq!(
            data.steps.iter().find(|s| s.step == 2).unwrap().retries,
            1,
            "{what}"
        );
        // and the step still has exactly its readings
        assert_eq!(
            load_samples(&dir)
                .unwrap()
                .iter()
                .filter(|s| s.step == 2)
                .count(),
            50,
            "{what}"
        );
    }
}

#[tokio::test(start_paused = true)]
async fn overload_readings_are_counted_and_left_out_of_the_mean() {
    use gyrocal_sim::dmm::Fault;
    let plan = plan_with("quick.toml", |_| {});
    let bench = bench_with_fault(&plan, 3 * 50 + 10, Fault::Overload { readings: 4 });
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let summary = run_on(&plan, bench, &dir).await;
    assert_eq!(summary.status, Status::Complete, "{:?}", summary.reason);
    let data = load(&dir).unwrap();
    let step = data.steps.iter().find(|s| s.step == 3).unwrap();
    assert_eq!((step.n, step.overloads), (46, 4));
    // the mean is a voltage near the gyro's output, not polluted by 9.9E+37
    assert!(step.volts.abs() < 10.0, "{}", step.volts);
    let rows = load_samples(&dir).unwrap();
    assert_eq!(
        rows.iter().filter(|s| s.step == 3).count(),
        50,
        "overloads are kept in samples.csv"
    );
}

#[tokio::test(start_paused = true)]
async fn a_disconnected_multimeter_fails_the_run_cleanly_and_it_resumes() {
    use gyrocal_sim::dmm::Fault;
    let plan = plan_with("quick.toml", |_| {});
    let bench = bench_with_fault(&plan, 2 * 50 + 5, Fault::Disconnect);
    let table = bench.handle.table.clone();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let summary = run_on(&plan, bench, &dir).await;
    assert_eq!(summary.status, Status::Failed);
    assert!(
        summary
            .reason
            .as_deref()
            .unwrap_or("")
            .contains("multimeter"),
        "{:?}",
        summary.reason
    );
    tokio::time::sleep(Duration::from_millis(10)).await;
    assert_ne!(
        table.mode(),
        gyrocal_sim::table::SimMode::Rate,
        "table left spinning"
    );
    let data = load(&dir).unwrap();
    assert_eq!(data.steps.len(), 2, "the two finished steps are kept");
    let (summary, _) = run_plan(&plan, &dir, true, None).await;
    assert_eq!(summary.status, Status::Complete, "{:?}", summary.reason);
    assert_eq!(
        load_samples(&dir).unwrap().len(),
        plan.schedule().len() * 50
    );
}

#[tokio::test(start_paused = true)]
async fn paper_plan_in_memory_mode_hides_every_fetch_but_the_last() {
    // settle_s (10 s) is longer than the stability window (2 s) and than a 500-reading FETC?
    // (9.2 s at 9600 baud): each fetch must vanish into the next ramp and dwell
    let plan = plan_with("paper.toml", |d| {
        set(
            d,
            "dmm",
            "acquisition",
            toml::Value::String("memory".into()),
        );
    });
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let (summary, _) = run_plan(&plan, &dir, false, None).await;
    assert_eq!(summary.status, Status::Complete, "{:?}", summary.reason);
    let timing = summary.timing.unwrap();
    assert_eq!(timing.acquisition.as_deref(), Some("memory"));
    assert!(timing.ratio < 1.01, "{timing:?}");
}

#[tokio::test(start_paused = true)]
async fn a_repeated_schedule_reports_the_repeatability_of_its_passes() {
    let plan = plan_with("quick.toml", |d| {
        set(d, "plan", "repeat", toml::Value::Integer(3))
    });
    assert_eq!(plan.schedule().len(), 15);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let (summary, _) = run_plan(&plan, &dir, false, None).await;
    assert_eq!(summary.status, Status::Complete, "{:?}", summary.reason);
    let fit = gyrocal_files::load_fit(&dir).unwrap().unwrap();
    let r = fit
        .metrics
        .repeatability_ppm
        .expect("repeatability over 3 passes");
    // three passes of 50 readings with 2 mV noise: K to some tens of ppm, not zero, not wild
    assert!(r > 0.0 && r < 1000.0, "{r}");

    // one pass: no repeatability to speak of
    let single = tmp.path().join("single");
    let one = plan_with("quick.toml", |_| {});
    run_plan(&one, &single, false, None).await;
    let fit = gyrocal_files::load_fit(&single).unwrap().unwrap();
    assert!(fit.metrics.repeatability_ppm.is_none());
}

#[tokio::test(start_paused = true)]
async fn a_table_fault_during_a_long_fetch_is_caught_at_once() {
    // 1000 fast readings: two memory bursts; the first burst's FETC? (512 readings, ~9.4 s at
    // 9600 baud) overlaps with nothing, and the table must still be watched during it
    let plan = plan_with("quick.toml", |d| {
        set(d, "dmm", "nplc", toml::Value::Float(0.02));
        set(d, "dmm", "autozero", toml::Value::Boolean(false));
        set(d, "plan", "samples_per_rate", toml::Value::Integer(1000));
    });
    let mut cfg = bench_config(&plan);
    // the first step's acquisition starts ~2 s in (stability window), its first burst takes
    // 0.7 s: at 6 s the meter is mid-transfer
    cfg.table.faults.inject_after = Some(6.0);
    let bench = Bench::spawn(cfg);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let (summary, _) = run_with(&plan, bench, new_run(&plan, &dir), None).await;
    assert_eq!(summary.status, Status::Failed);
    assert!(
        summary
            .reason
            .as_deref()
            .unwrap_or("")
            .contains("Tracking error limit exceeded"),
        "{:?}",
        summary.reason
    );
    // caught within the sampling interval (plus the stop), not ~6 s later when the transfer ends
    assert!(
        summary.elapsed_s < 7.0,
        "fault noticed after {} s",
        summary.elapsed_s
    );
    assert!(load(&dir).unwrap().steps.is_empty());
}

/// A run whose steps were measured on instruments that did not identify as simulators is not
/// continued on a simulated bench (nor the reverse): the refusal comes before the table moves.
#[tokio::test(start_paused = true)]
async fn a_run_is_never_continued_on_the_other_kind_of_bench() {
    let plan = plan_with("quick.toml", |_| {});
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    // "real" instruments: the serial fields a real 34401A and table answer
    let mut real = bench_config(&plan);
    real.dmm.identity = "HEWLETT-PACKARD,34401A,0,11-5-2".into();
    real.table.identity = "ACUTRONIC,ACUTROL3000,1234,3.1".into();
    let meta = RunMeta {
        gyrocal_version: "test".into(),
        ..RunMeta::default()
    };
    let run = RunDir::create(&dir, &plan, meta).unwrap();
    let (summary, _) = run_with(&plan, Bench::spawn(real), run, Some(2)).await;
    assert_eq!(summary.status, Status::Aborted);
    assert!(!load(&dir).unwrap().manifest.simulated);
    let done = load(&dir).unwrap().steps.len();
    assert!(done >= 2);

    // the same run on the simulated bench (serial SIM0001)
    let run = RunDir::open_for_resume(&dir, &plan).unwrap();
    let bench = Bench::spawn(bench_config(&plan));
    let (summary, handle) = run_with(&plan, bench, run, None).await;
    assert_eq!(summary.status, Status::Failed);
    let reason = summary.reason.unwrap();
    assert!(
        reason.contains("mix simulated and measured data"),
        "{reason}"
    );
    assert!(!summary.resumable);
    assert_eq!(
        handle.table.demands_seen(),
        0,
        "the simulated table never moved"
    );
    // and the operator is told where the table was left: confirmed at rest
    assert!(summary.table.is_at_rest(), "{:?}", summary.table);
    tokio::time::sleep(Duration::from_millis(10)).await;
    assert!(handle.table.is_stopped());
    assert_eq!(load(&dir).unwrap().steps.len(), done, "nothing recorded");
}
