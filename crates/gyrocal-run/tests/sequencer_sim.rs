//! The sequencer against the simulated bench, in virtual time: whole plans through the real
//! drivers and the real run directory.

use std::path::{Path, PathBuf};
use std::time::Duration;

use gyrocal_hp34401a::{DriverOptions, Hp34401a};
use gyrocal_run::sequencer::table_config;
use gyrocal_run::simulate::bench_config;
use gyrocal_run::{
    Plan, RunDir, RunMeta, RunSummary, Sequencer, SequencerOptions, Status, StopRequest, fit_run,
    load, load_samples,
};
use gyrocal_sim::bench::{Bench, BenchHandle};
use gyrocal_table::acl::AclTable;
use tokio::sync::watch;

fn config(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../configs")
        .join(name)
}

fn plan_with(name: &str, edit: impl FnOnce(&mut toml::Table)) -> Plan {
    let path = config(name);
    let mut doc: toml::Table = std::fs::read_to_string(&path).unwrap().parse().unwrap();
    edit(&mut doc);
    Plan::from_toml_str(&toml::to_string(&doc).unwrap(), &path).unwrap()
}

fn set(doc: &mut toml::Table, section: &str, key: &str, value: toml::Value) {
    doc.get_mut(section)
        .unwrap()
        .as_table_mut()
        .unwrap()
        .insert(key.into(), value);
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
        let meta = RunMeta {
            gyrocal_version: "test".into(),
            simulated: true,
            ..RunMeta::default()
        };
        RunDir::create(dir, plan, meta).unwrap()
    };
    let dmm = Hp34401a::new(bench.dmm, DriverOptions::default());
    let table = AclTable::new(bench.table, table_config(plan));
    let (events_tx, mut events) = tokio::sync::mpsc::unbounded_channel();
    let mut seq = Sequencer::new(plan.clone(), dmm, table, run, SequencerOptions::default())
        .with_events(events_tx);
    let (stop_tx, stop_rx) = watch::channel(StopRequest::None);
    if let Some(k) = stop_after {
        tokio::spawn(async move {
            let mut done = 0;
            while let Some(e) = events.recv().await {
                if matches!(e, gyrocal_run::Event::StepDone(_)) {
                    done += 1;
                    if done == k {
                        let _ = stop_tx.send(StopRequest::Controlled);
                    }
                }
            }
        });
    }
    let summary = seq.run(stop_rx).await;
    if summary.status == Status::Complete {
        let mut run = seq.into_run_dir();
        fit_run(&mut run, &gyrocal_fit::Options::default()).unwrap();
    }
    (summary, bench.handle)
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
    let fit = data.manifest.fit.expect("fit in manifest");
    let lin = fit["fits"]
        .as_array()
        .unwrap()
        .iter()
        .find(|f| f["method"] == "least-squares" && f["model"] == "linear")
        .unwrap();
    let (true_k, true_k0) = bench.truth.fit_line(plan.rates_dps());
    let k = lin["scale_factor"].as_f64().unwrap();
    let k0 = lin["bias"].as_f64().unwrap();
    let sk = lin["std_errors"]["k1"].as_f64().unwrap();
    let sk0 = lin["std_errors"]["k0"].as_f64().unwrap();
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
    let meta = RunMeta {
        gyrocal_version: "test".into(),
        simulated: true,
        ..RunMeta::default()
    };
    let run = RunDir::create(&dir, &plan, meta).unwrap();
    let dmm = Hp34401a::new(bench.dmm, DriverOptions::default());
    let table = AclTable::new(bench.table, table_config(&plan));
    let mut seq = Sequencer::new(plan.clone(), dmm, table, run, SequencerOptions::default());
    let (_stop_tx, stop_rx) = watch::channel(StopRequest::None);
    let summary = seq.run(stop_rx).await;
    assert_eq!(summary.status, Status::Failed);
    let manifest = load(&dir).unwrap().manifest;
    assert_eq!(manifest.status, Status::Failed);
    let reason = manifest.reason.unwrap();
    assert!(reason.contains("Tracking error limit exceeded"), "{reason}");
    tokio::time::sleep(Duration::from_millis(10)).await;
    assert_ne!(bench.handle.table.mode(), gyrocal_sim::table::SimMode::Rate);
}
