//! The run directory: writing, torn tails, resume, manifest atomicity, fit compatibility.

// Test helpers outside #[test] functions may unwrap too: a panic is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::{meta, plan, plan_text, run_step};

use std::fs::{self, OpenOptions};
use std::io::Write;
use std::path::Path;

use gyrocal_files::rundir::{MANIFEST_JSON, SAMPLES_CSV, STEPS_CSV};
use gyrocal_files::{
    Instruments, Plan, Retry, RunDir, RunError, Sample, Status, StepRecord, load, load_samples,
};

fn append_raw(path: &Path, bytes: &[u8]) {
    OpenOptions::new()
        .append(true)
        .open(path)
        .unwrap()
        .write_all(bytes)
        .unwrap();
}

#[test]
fn create_refuses_a_non_empty_directory() {
    let tmp = tempfile::tempdir().unwrap();
    fs::write(tmp.path().join("x"), b"x").unwrap();
    let err = RunDir::create(tmp.path(), &plan(), meta()).unwrap_err();
    assert!(matches!(err, RunError::NotEmpty { .. }), "{err}");
    // an empty existing directory is fine
    let empty = tmp.path().join("empty");
    fs::create_dir(&empty).unwrap();
    RunDir::create(&empty, &plan(), meta()).unwrap();
}

#[test]
fn a_full_run_writes_what_the_fit_needs() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let p = plan();
    let mut rd = RunDir::create(&dir, &p, meta()).unwrap();
    rd.set_instruments(Instruments {
        dmm: Some("HEWLETT-PACKARD,34401A,0,11-5-2".into()),
        table: Some("ACUTRONIC,ACUTROL3000,1,1.0".into()),
    })
    .unwrap();
    for step in 0..5 {
        run_step(&mut rd, step, true);
    }
    rd.log_retry(Retry {
        t_s: 3.0,
        step: Some(2),
        instrument: "dmm".into(),
        message: "timeout".into(),
    })
    .unwrap();
    let steps = gyrocal_files::load(&dir).unwrap().steps;
    let analysis = gyrocal_fit::analyze(
        &gyrocal_analysis::sweep::dataset_from_steps(&steps, "steps.csv"),
        &gyrocal_fit::Options::default(),
    )
    .unwrap();
    rd.set_fit(analysis.clone()).unwrap();
    rd.finish(Status::Complete, None, 51.5).unwrap();

    // steps.csv: the columns `gyrocal fit` reads by name, with numbers in them
    let mut rdr = csv::Reader::from_path(dir.join(STEPS_CSV)).unwrap();
    let headers = rdr.headers().unwrap().clone();
    for col in ["rate_dps", "volts", "volts_std", "n"] {
        assert!(
            headers.iter().any(|h| h == col),
            "steps.csv lacks {col}: {headers:?}"
        );
    }
    let idx = |c: &str| headers.iter().position(|h| h == c).unwrap();
    let rows: Vec<csv::StringRecord> = rdr.records().map(Result::unwrap).collect();
    assert_eq!(rows.len(), 5);
    for (i, row) in rows.iter().enumerate() {
        let rate: f64 = row[idx("rate_dps")].parse().unwrap();
        let v: f64 = row[idx("volts")].parse().unwrap();
        let n: u64 = row[idx("n")].parse().unwrap();
        assert_eq!(rate, p.rates_dps()[i]);
        assert!((v - 0.3612 * rate - 0.0088).abs() < 1e-4, "{v}");
        assert_eq!(n, 6);
    }

    // samples.csv: one row per reading, overload marked and its volts empty
    let samples = load_samples(&dir).unwrap();
    assert_eq!(samples.len(), 35);
    let ov: Vec<_> = samples.iter().filter(|s| s.overload == 1).collect();
    assert_eq!(ov.len(), 5);
    assert!(ov.iter().all(|s| s.volts.is_none() && s.index == 4));
    let text = fs::read_to_string(dir.join(SAMPLES_CSV)).unwrap();
    assert!(
        text.starts_with("step_no,sample_no,t_s,rate_dps,volts,overload,t_utc\n"),
        "{text}"
    );
    // counted from 1: the first step's fifth reading (`index` 4 in memory)
    assert!(
        text.lines()
            .any(|l| l.starts_with("1,5,") && l.contains(",,1,")),
        "{text}"
    );

    // manifest
    let data = load(&dir).unwrap();
    let m = &data.manifest;
    assert_eq!(m.status, Status::Complete);
    assert_eq!(m.steps_done, vec![0, 1, 2, 3, 4]);
    assert_eq!(m.plan_hash, p.hash());
    assert_eq!(m.plan, p);
    assert_eq!(m.elapsed_s, 51.5);
    assert_eq!(m.retries.len(), 1);
    assert!(m.ended_utc.as_deref().is_some_and(|t| t.ends_with('Z')));
    assert_eq!(
        m.instruments.dmm.as_deref(),
        Some("HEWLETT-PACKARD,34401A,0,11-5-2")
    );
    // the fit is fit.json's, read back as written (to the 12 significant digits the run
    // directory writes); the manifest names it and carries its headline figures
    let back = gyrocal_files::load_fit(&dir).unwrap().expect("fit.json");
    assert_eq!(back.fits.len(), analysis.fits.len());
    let k = |a: &gyrocal_fit::Analysis| a.metrics.scale_factor;
    assert!((k(&back) / k(&analysis) - 1.0).abs() < 1e-11);
    let summary = m.fit_summary.as_ref().expect("fit summary in the manifest");
    assert_eq!(summary.file, "fit.json");
    assert!((summary.scale_factor / k(&analysis) - 1.0).abs() < 1e-11);
    assert!(m.legacy_fit.is_none());
    assert_eq!(data.steps.len(), 5);
    // no temp file left behind
    let leftovers: Vec<_> = fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n != gyrocal_files::rundir::LOCK_FILE)
        .filter(|n| n.starts_with('.') || n.ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

#[test]
fn resume_after_a_torn_tail_keeps_exactly_the_finished_steps() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let p = plan();
    {
        let mut rd = RunDir::create(&dir, &p, meta()).unwrap();
        run_step(&mut rd, 0, true);
        run_step(&mut rd, 1, true);
        run_step(&mut rd, 2, false); // partial: samples but no row
        // the program is killed in the middle of a write: half a row in each file
        drop(rd);
    }
    append_raw(&dir.join(SAMPLES_CSV), b"2,7,20.29,-1.0,-0.35");
    append_raw(&dir.join(STEPS_CSV), b"2,0,-1.0,-1.00001,0.0001");

    let mut rd = RunDir::open_for_resume(&dir, &p).unwrap();
    assert_eq!(
        rd.done_steps().iter().copied().collect::<Vec<_>>(),
        vec![0, 1]
    );
    assert_eq!(
        rd.remaining_steps()
            .iter()
            .map(|s| s.index)
            .collect::<Vec<_>>(),
        vec![2, 3, 4]
    );
    let m = rd.manifest();
    assert_eq!(m.status, Status::Running);
    assert_eq!(m.resumes.len(), 1);
    assert_eq!(m.resumes[0].from_step, Some(2));
    assert_eq!(m.resumes[0].samples_dropped, 7);
    assert!(m.resumes[0].torn_bytes_dropped > 0);

    // only the finished steps' samples are left, and the file ends with a newline
    let text = fs::read_to_string(dir.join(SAMPLES_CSV)).unwrap();
    assert!(text.ends_with('\n'));
    let rows = load_samples(&dir).unwrap();
    assert_eq!(rows.len(), 14);
    assert!(rows.iter().all(|r| r.step < 2));

    // finish the run; every step once, every sample once
    for step in 2..5 {
        run_step(&mut rd, step, true);
    }
    rd.finish(Status::Complete, None, 60.0).unwrap();
    drop(rd);
    let rows = load_samples(&dir).unwrap();
    assert_eq!(rows.len(), 35);
    let mut keys: Vec<(usize, u64)> = rows.iter().map(|r| (r.step, r.index)).collect();
    keys.sort_unstable();
    keys.dedup();
    assert_eq!(keys.len(), 35, "duplicated samples");
    let data = load(&dir).unwrap();
    assert_eq!(
        data.steps.iter().map(|s| s.step).collect::<Vec<_>>(),
        vec![0, 1, 2, 3, 4]
    );

    // a complete run is not resumed
    let err = RunDir::open_for_resume(&dir, &p).unwrap_err();
    assert!(matches!(err, RunError::AlreadyComplete { .. }), "{err}");
}

#[test]
fn resume_of_a_run_killed_before_any_row_and_twice() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let p = plan();
    let mut rd = RunDir::create(&dir, &p, meta()).unwrap();
    rd.append_samples(
        0,
        &[Sample {
            index: 0,
            t_s: 0.0,
            volts: Some(0.01),
        }],
    )
    .unwrap();
    drop(rd);
    let rd = RunDir::open_for_resume(&dir, &p).unwrap();
    assert!(rd.done_steps().is_empty());
    drop(rd);
    let rd = RunDir::open_for_resume(&dir, &p).unwrap();
    assert_eq!(rd.manifest().resumes.len(), 2);
    assert_eq!(load_samples(&dir).unwrap().len(), 0);
}

#[test]
fn resume_with_a_changed_plan_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let p = plan();
    let mut rd = RunDir::create(&dir, &p, meta()).unwrap();
    run_step(&mut rd, 0, true);
    rd.finish(Status::Aborted, Some("SIGINT".into()), 5.0)
        .unwrap();
    drop(rd);
    let changed = Plan::from_toml_str(
        &plan_text().replace("[0, 1, -1, 2, -2]", "[0, 1, -1, 3, -3]"),
        Path::new("c"),
    )
    .unwrap();
    let err = RunDir::open_for_resume(&dir, &changed).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, RunError::PlanChanged { .. }), "{msg}");
    // the key that changed and both values, not two hashes
    assert!(
        msg.contains(
            "[plan] rates_dps: [0.0,1.0,-1.0,2.0,-2.0] (run) vs [0.0,1.0,-1.0,3.0,-3.0] (this plan)"
        ),
        "{msg}"
    );
    // nothing was touched: the original plan still resumes, and the abort is recorded
    let rd = RunDir::open_for_resume(&dir, &p).unwrap();
    assert_eq!(rd.manifest().resumes[0].previous_status, Status::Aborted);
    assert_eq!(
        rd.manifest().resumes[0].previous_reason.as_deref(),
        Some("SIGINT")
    );
}

#[test]
fn manifest_is_replaced_atomically() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let mut rd = RunDir::create(&dir, &plan(), meta()).unwrap();
    // a stale temp file from an earlier crash does not matter
    fs::write(dir.join(".manifest.json.tmp"), b"{garbage").unwrap();
    for i in 0..20 {
        rd.set_elapsed(f64::from(i)).unwrap();
        let text = fs::read_to_string(dir.join(MANIFEST_JSON)).unwrap();
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(v["elapsed_s"], serde_json::json!(f64::from(i)));
        assert!(!dir.join(".manifest.json.tmp").exists());
    }
    assert_eq!(load(&dir).unwrap().manifest.status, Status::Running);
}

#[test]
fn protocol_violations_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let mut rd = RunDir::create(&dir, &plan(), meta()).unwrap();
    let s = |index| Sample {
        index,
        t_s: 0.0,
        volts: Some(1.0),
    };
    // index gap
    assert!(rd.append_samples(0, &[s(1)]).is_err());
    rd.append_samples(0, &[s(0), s(1)]).unwrap();
    // duplicate index
    assert!(rd.append_samples(0, &[s(1)]).is_err());
    // another step while step 0 is in progress
    assert!(rd.append_samples(1, &[s(0)]).is_err());
    // NaN is not an overload
    assert!(
        rd.append_samples(
            0,
            &[Sample {
                index: 2,
                t_s: 0.0,
                volts: Some(f64::NAN)
            }]
        )
        .is_err()
    );
    // record with the wrong count
    let rec = StepRecord {
        step: 0,
        pass: 0,
        rate_dps: 0.0,
        rate_meas_dps: None,
        rate_meas_std_dps: None,
        rate_meas_min_dps: None,
        rate_meas_max_dps: None,
        rate_samples: None,
        volts: 1.0,
        volts_std: None,
        n: 3,
        overloads: 0,
        retries: 0,
        t_start_s: 0.0,
        t_end_s: 1.0,
        series: None,
    };
    assert!(rd.append_step(rec.clone()).is_err());
    // wrong rate for the step
    assert!(
        rd.append_step(StepRecord {
            n: 2,
            rate_dps: 1.0,
            ..rec.clone()
        })
        .is_err()
    );
    // restart drops the step's samples; it starts again at 0
    rd.restart_step(0).unwrap();
    rd.append_samples(0, &[s(0)]).unwrap();
    rd.append_step(StepRecord {
        n: 1,
        ..rec.clone()
    })
    .unwrap();
    assert!(
        rd.append_step(StepRecord { n: 1, ..rec }).is_err(),
        "recorded twice"
    );
    // complete refused while steps remain
    assert!(rd.finish(Status::Complete, None, 1.0).is_err());
    assert_eq!(load_samples(&dir).unwrap().len(), 1);
}

#[test]
fn corrupt_files_are_reported_with_file_and_line() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let p = plan();
    let mut rd = RunDir::create(&dir, &p, meta()).unwrap();
    run_step(&mut rd, 0, true);
    drop(rd);
    // a garbage (complete) line in steps.csv
    append_raw(&dir.join(STEPS_CSV), b"1,0,one,,,,,0.37,,7,0,0,1,2\n");
    let err = RunDir::open_for_resume(&dir, &p).unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("steps.csv:3:"), "{msg}");
    let err = load(&dir).unwrap_err();
    assert!(err.to_string().contains("steps.csv:3:"), "{err}");

    // the first data row is line 2 (the header is line 1)
    let dir2 = tmp.path().join("run2");
    drop(RunDir::create(&dir2, &p, meta()).unwrap());
    append_raw(&dir2.join(STEPS_CSV), b"0,0,zero,,,,,0.37,,7,0,0,1,2\n");
    let err = load(&dir2).unwrap_err();
    assert!(err.to_string().contains("steps.csv:2:"), "{err}");

    // a manifest that does not parse names its line
    fs::write(
        dir.join(MANIFEST_JSON),
        b"{\n\"status\": \"running\",\n  oops\n}",
    )
    .unwrap();
    let err = load(&dir).unwrap_err();
    assert!(err.to_string().contains("manifest.json:3:"), "{err}");
}

#[test]
fn a_step_row_without_its_samples_is_refused_on_resume() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let p = plan();
    let mut rd = RunDir::create(&dir, &p, meta()).unwrap();
    run_step(&mut rd, 0, true);
    drop(rd);
    // lose the last sample row of step 0 (not something this crate ever writes)
    let text = fs::read_to_string(dir.join(SAMPLES_CSV)).unwrap();
    let mut lines: Vec<&str> = text.lines().collect();
    lines.pop();
    fs::write(dir.join(SAMPLES_CSV), lines.join("\n") + "\n").unwrap();
    let err = RunDir::open_for_resume(&dir, &p).unwrap_err();
    assert!(matches!(err, RunError::Inconsistent { .. }), "{err}");
    assert!(err.to_string().contains("samples.csv"), "{err}");
}

#[test]
fn a_run_directory_in_use_is_refused_until_its_writer_is_gone() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let p = plan();
    let mut first = RunDir::create(&dir, &p, meta()).unwrap();
    run_step(&mut first, 0, true);
    let err = RunDir::open_for_resume(&dir, &p).unwrap_err();
    assert!(
        matches!(err, gyrocal_files::RunError::Locked { .. }),
        "{err}"
    );
    assert!(err.to_string().contains("in use"), "{err}");
    // the refused second writer changed nothing
    assert_eq!(load(&dir).unwrap().steps.len(), 1);
    drop(first);
    let second = RunDir::open_for_resume(&dir, &p).unwrap();
    assert_eq!(second.done_steps().len(), 1);
}

#[test]
fn dropping_a_partial_first_step_keeps_the_header_in_place() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let p = plan();
    let mut rd = RunDir::create(&dir, &p, meta()).unwrap();
    let header = fs::read(dir.join(SAMPLES_CSV)).unwrap();
    rd.append_samples(
        0,
        &[Sample {
            index: 0,
            t_s: 0.0,
            volts: Some(0.01),
        }],
    )
    .unwrap();
    drop(rd);
    let _rd = RunDir::open_for_resume(&dir, &p).unwrap();
    // exactly the header is left: the partial row is cut at its own start, not at the file's
    assert_eq!(fs::read(dir.join(SAMPLES_CSV)).unwrap(), header);
}

/// A directory path (under `base`, not created) whose `samples.csv`, `steps.csv` and `.lock`
/// fit within Linux's PATH_MAX (4096 bytes with the NUL) but whose `.manifest.json.tmp` does
/// not: creating the run directory fails half way, at the manifest, with ENAMETOOLONG, after
/// the lock and both CSV files were created. A real failure, reproducible without a full disk
/// or a test hook (and as root, whom permissions do not stop).
fn manifest_fails_path(base: &Path) -> std::path::PathBuf {
    const LEN: usize = 4080; // + "/samples.csv" = 4092 < 4096; + "/.manifest.json.tmp" = 4099
    let mut p = base.to_path_buf();
    while p.as_os_str().len() + 1 + 200 < LEN {
        p.push("d".repeat(200));
    }
    let rest = LEN - p.as_os_str().len() - 1;
    assert!((1..=255).contains(&rest));
    p.push("r".repeat(rest));
    assert_eq!(p.as_os_str().len(), LEN);
    p
}

#[test]
fn a_creation_that_fails_half_way_removes_what_it_created() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = manifest_fails_path(tmp.path());
    let err = RunDir::create(&dir, &plan(), meta()).unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(err, RunError::Io { .. }) && msg.contains(".manifest.json.tmp"),
        "{msg}"
    );
    // Nothing is left: not the run directory, not the parents the creation made.
    assert!(!dir.exists());
    assert_eq!(fs::read_dir(tmp.path()).unwrap().count(), 0);

    // A directory that existed before is left in place, empty.
    fs::create_dir_all(&dir).unwrap();
    RunDir::create(&dir, &plan(), meta()).unwrap_err();
    assert!(dir.is_dir());
    assert_eq!(fs::read_dir(&dir).unwrap().count(), 0);
}

#[test]
fn a_half_created_directory_is_reused_and_one_with_data_is_not() {
    let tmp = tempfile::tempdir().unwrap();
    // What a kill between the first file and the manifest leaves.
    let dir = tmp.path().join("half");
    fs::create_dir(&dir).unwrap();
    fs::write(dir.join(".lock"), b"").unwrap();
    fs::write(
        dir.join(SAMPLES_CSV),
        b"step,index,t_s,rate_dps,volts,overload\n",
    )
    .unwrap();
    fs::write(dir.join(STEPS_CSV), b"step,pass,rate_d").unwrap(); // torn header
    fs::write(dir.join(".manifest.json.tmp"), b"{\"format_ver").unwrap();
    assert!(RunDir::is_half_created(&dir).unwrap());
    let mut rd = RunDir::create(&dir, &plan(), meta()).unwrap();
    run_step(&mut rd, 0, true);
    drop(rd);
    let data = load(&dir).unwrap();
    assert_eq!(data.steps.len(), 1);
    assert!(!RunDir::is_half_created(&dir).unwrap());

    // A readings row means a run took data there: never reused, never emptied.
    let dir = tmp.path().join("data");
    fs::create_dir(&dir).unwrap();
    let samples = b"step,index,t_s,rate_dps,volts,overload\n0,0,0.1,0,0.0088,0\n";
    fs::write(dir.join(SAMPLES_CSV), samples).unwrap();
    assert!(!RunDir::is_half_created(&dir).unwrap());
    let err = RunDir::create(&dir, &plan(), meta()).unwrap_err();
    assert!(matches!(err, RunError::NotEmpty { .. }), "{err}");
    assert_eq!(fs::read(dir.join(SAMPLES_CSV)).unwrap(), samples);
}

#[test]
fn rate_samples_round_trip_and_older_steps_csv_still_read_and_resume() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let mut rd = RunDir::create(&dir, &plan(), meta()).unwrap();
    run_step(&mut rd, 0, true);
    run_step(&mut rd, 1, true);
    drop(rd);
    let text = fs::read_to_string(dir.join(STEPS_CSV)).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let pos = |c: &str| header.iter().position(|h| *h == c).unwrap();
    assert_eq!(pos("rate_samples"), pos("rate_meas_max_dps") + 1);
    assert_eq!(load(&dir).unwrap().steps[0].rate_samples, Some(12));

    // The same run as an older gyrocal wrote it: no rate_samples column (and none of the
    // UTC columns, which came later).
    let old: String = text
        .lines()
        .map(|l| {
            let mut cells: Vec<&str> = l.split(',').collect();
            cells.truncate(pos("t_start_utc"));
            cells.remove(pos("rate_samples"));
            cells.join(",") + "\n"
        })
        .collect();
    let old = common::counted_from_zero(&old);
    fs::write(dir.join(STEPS_CSV), &old).unwrap();
    let data = load(&dir).unwrap();
    assert_eq!(data.steps.len(), 2);
    assert_eq!(data.steps[1].rate_samples, None);
    assert_eq!(data.steps[1].n, 6);
    // A resume upgrades the file to the current columns and appends in them.
    let mut rd = RunDir::open_for_resume(&dir, &plan()).unwrap();
    assert_eq!(rd.done_steps().len(), 2);
    run_step(&mut rd, 2, true);
    drop(rd);
    let text = fs::read_to_string(dir.join(STEPS_CSV)).unwrap();
    // a sweep's steps.csv: format 4's columns (no temperature series' ones)
    assert!(text.starts_with(&gyrocal_files::rundir::STEPS_HEADER_V4.join(",")));
    assert!(text.lines().all(|l| l.split(',').count() == 17), "{text}");
    // the old rows' step and pass re-based: step_no 1, 2, then the new row's 3
    let nos: Vec<&str> = text.lines().skip(1).map(|l| &l[..4]).collect();
    assert_eq!(nos, ["1,1,", "2,1,", "3,1,"], "{text}");
    let steps = load(&dir).unwrap().steps;
    assert_eq!(
        steps.iter().map(|s| s.rate_samples).collect::<Vec<_>>(),
        [None, None, Some(12)]
    );
}

#[test]
fn a_duplicated_column_is_named_with_both_positions() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let mut rd = RunDir::create(&dir, &plan(), meta()).unwrap();
    run_step(&mut rd, 0, true);
    drop(rd);
    let text = fs::read_to_string(dir.join(STEPS_CSV)).unwrap();
    let dup = text.replacen("volts_std", "volts", 1);
    fs::write(dir.join(STEPS_CSV), dup).unwrap();
    let msg = load(&dir).unwrap_err().to_string();
    assert!(
        msg.contains("steps.csv:1:") && msg.contains("`volts` twice (columns 9 and 10)"),
        "{msg}"
    );
    let msg = RunDir::open_for_resume(&dir, &plan())
        .unwrap_err()
        .to_string();
    assert!(msg.contains("twice"), "{msg}");
}

#[test]
fn huge_or_endless_run_files_are_refused_naming_them() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let mut rd = RunDir::create(&dir, &plan(), meta()).unwrap();
    run_step(&mut rd, 0, true);
    drop(rd);
    // A steps.csv past its cap (sparse: no disk used).
    let steps = OpenOptions::new()
        .write(true)
        .open(dir.join(STEPS_CSV))
        .unwrap();
    steps
        .set_len(gyrocal_files::rundir::MAX_STEPS_BYTES + 1)
        .unwrap();
    let started = std::time::Instant::now();
    let msg = load(&dir).unwrap_err().to_string();
    assert!(msg.contains("steps.csv") && msg.contains("64 MiB"), "{msg}");
    let msg = RunDir::open_for_resume(&dir, &plan())
        .unwrap_err()
        .to_string();
    assert!(msg.contains("steps.csv") && msg.contains("64 MiB"), "{msg}");
    // An endless manifest: a device where the file should be.
    fs::remove_file(dir.join(MANIFEST_JSON)).unwrap();
    std::os::unix::fs::symlink("/dev/zero", dir.join(MANIFEST_JSON)).unwrap();
    let msg = load(&dir).unwrap_err().to_string();
    assert!(
        msg.contains("manifest.json") && msg.contains("not a regular file"),
        "{msg}"
    );
    assert!(started.elapsed() < std::time::Duration::from_secs(10));
}

#[test]
fn a_samples_csv_over_its_cap_is_refused_on_resume_from_its_size() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let mut rd = RunDir::create(&dir, &plan(), meta()).unwrap();
    run_step(&mut rd, 0, true);
    drop(rd);
    OpenOptions::new()
        .write(true)
        .open(dir.join(SAMPLES_CSV))
        .unwrap()
        .set_len(gyrocal_files::rundir::MAX_SAMPLES_BYTES + 1)
        .unwrap();
    let started = std::time::Instant::now();
    let msg = RunDir::open_for_resume(&dir, &plan())
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("samples.csv") && msg.contains("4096 MiB"),
        "{msg}"
    );
    assert!(started.elapsed() < std::time::Duration::from_secs(5));
}

#[test]
fn a_manifest_fit_this_version_cannot_read_leaves_the_run_readable() {
    // a manifest written by another version, with a fit document this one does not know:
    // the run directory still loads (the fit is ignored with a warning; fit.json is the
    // source of truth)
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let p = plan();
    let mut rd = RunDir::create(&dir, &p, meta()).unwrap();
    run_step(&mut rd, 0, true);
    rd.finish(Status::Aborted, Some("test".into()), 1.0)
        .unwrap();
    drop(rd);
    let path = dir.join("manifest.json");
    let mut m: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(&path).unwrap()).unwrap();
    m["fit"] = serde_json::json!({"scale_factor": 0.3612});
    fs::write(&path, serde_json::to_string_pretty(&m).unwrap()).unwrap();
    let data = gyrocal_files::load(&dir).unwrap();
    assert!(data.manifest.legacy_fit.is_none());
    assert_eq!(data.steps.len(), 1);
}

#[test]
fn the_run_clock_resumes_after_the_last_finished_step_even_when_the_manifest_lags() {
    // A kill between fsyncing a step's row and rewriting the manifest leaves the manifest's
    // elapsed_s behind the step's end: the resumed clock must not run back into kept data.
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let mut rd = RunDir::create(&dir, &plan(), meta()).unwrap();
    run_step(&mut rd, 0, true);
    run_step(&mut rd, 1, true);
    rd.set_elapsed(5.0).unwrap(); // the manifest as if written before step 1 ended (10.3 s)
    drop(rd);
    let rd = RunDir::open_for_resume(&dir, &plan()).unwrap();
    assert!(
        rd.manifest().elapsed_s >= 10.3,
        "resumed clock {} s is before the end of the last kept step (10.3 s)",
        rd.manifest().elapsed_s
    );
}

#[test]
fn a_step_no_of_zero_is_refused_naming_the_column_and_line() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let p = plan();
    let mut rd = RunDir::create(&dir, &p, meta()).unwrap();
    run_step(&mut rd, 0, true);
    drop(rd);
    // step_no counts from 1: a 0 is not the first step of an older file, it is an error
    let text = fs::read_to_string(dir.join(STEPS_CSV)).unwrap();
    let bad = text.replacen("\n1,1,", "\n0,1,", 1);
    assert_ne!(bad, text);
    fs::write(dir.join(STEPS_CSV), bad).unwrap();
    let err = load(&dir).unwrap_err().to_string();
    assert!(
        err.contains("steps.csv:2:") && err.contains("step_no is counted from 1 (got 0)"),
        "{err}"
    );
    let text = fs::read_to_string(dir.join(SAMPLES_CSV)).unwrap();
    fs::write(dir.join(SAMPLES_CSV), text.replacen("\n1,1,", "\n1,0,", 1)).unwrap();
    let err = load_samples(&dir).unwrap_err().to_string();
    assert!(
        err.contains("samples.csv:2:") && err.contains("sample_no is counted from 1 (got 0)"),
        "{err}"
    );
}

/// The manifest's run clock as on disk.
fn elapsed_on_disk(dir: &Path) -> f64 {
    let text = fs::read_to_string(dir.join(MANIFEST_JSON)).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["elapsed_s"].as_f64().unwrap()
}

#[test]
fn checkpoints_write_the_manifest_at_most_every_few_minutes_of_run_clock() {
    use gyrocal_files::rundir::CHECKPOINT_INTERVAL_S;
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let mut rd = RunDir::create(&dir, &plan(), meta()).unwrap();
    // an hour's soak polled every 10 s: 360 checkpoints, 12 manifest writes
    let mut written = Vec::new();
    for i in 1..=360 {
        let t = f64::from(i) * 10.0;
        if rd.checkpoint(t).unwrap() {
            written.push(t);
            assert_eq!(elapsed_on_disk(&dir), t);
        }
    }
    assert_eq!(written.len(), 12, "{written:?}");
    assert!(
        written
            .windows(2)
            .all(|w| w[1] - w[0] >= CHECKPOINT_INTERVAL_S)
    );
    // the run clock is held at once, and any other write of the manifest writes it
    assert_eq!(rd.manifest().elapsed_s, 3600.0);
    rd.checkpoint(3610.0).unwrap();
    assert_eq!(elapsed_on_disk(&dir), 3600.0);
    rd.log_retry(Retry {
        t_s: 3610.0,
        step: None,
        instrument: "chamber".into(),
        message: "a garbled reply".into(),
    })
    .unwrap();
    assert_eq!(elapsed_on_disk(&dir), 3610.0);
    // killed now: a resume goes on from the durable clock (no step, no temps.csv later)
    rd.checkpoint(3650.0).unwrap();
    drop(rd);
    let rd = RunDir::open_for_resume(&dir, &plan()).unwrap();
    assert_eq!(rd.manifest().elapsed_s, 3610.0);
}
