//! What a lab sees in a run directory's files: UTC times beside the run clock, numbers without
//! float noise, a slim manifest that references fit.json, no `.lock` in a finished run; and run
//! directories written by the previous format still load and resume.

// Test helpers outside #[test] functions may unwrap too: a panic is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::fs;
use std::path::Path;
use std::time::{Duration, SystemTime};

use gyrocal_files::rundir::{LOCK_FILE, MANIFEST_JSON, SAMPLES_CSV, STEPS_CSV};
use gyrocal_files::{
    Plan, RunDir, RunError, RunMeta, Sample, Status, StepRecord, Timing, load, load_fit,
    load_samples, parse_rfc3339_utc,
};

/// The plan of these tests' run directories (5 rates, 4 readings).
fn plan_text() -> String {
    common::plans::sweep("format test", &[0.0, 1.0, -1.0, 2.0, -2.0], 4)
}

fn plan() -> Plan {
    Plan::from_toml_str(&plan_text(), Path::new("test.toml")).unwrap()
}

fn meta() -> RunMeta {
    RunMeta {
        gyrocal_version: "0.1.0-test".into(),
        ..RunMeta::default()
    }
}

/// Records `step` with computed (noisy) numbers, as the sequencer's arithmetic makes them.
fn record(rd: &mut RunDir, step: usize) {
    let s = rd.schedule()[step];
    let t0 = 10.0 * step as f64 + 0.1;
    let t1 = t0 + 0.7;
    let volts: Vec<f64> = (0..4)
        .map(|i| 0.0088 + 0.3612 * s.rate_dps + f64::from(i) * 1e-6)
        .collect();
    let samples: Vec<Sample> = volts
        .iter()
        .enumerate()
        .map(|(i, &v)| Sample {
            index: i as u64,
            // an interpolated time: t0 + (t1 - t0) * (i + 1) / n carries binary noise
            t_s: t0 + (t1 - t0) * (i as f64 + 1.0) / 4.0,
            volts: Some(v),
        })
        .collect();
    rd.append_samples(step, &samples).unwrap();
    let mean = volts.iter().sum::<f64>() / 4.0;
    rd.append_step(StepRecord {
        step,
        pass: s.pass,
        rate_dps: s.rate_dps,
        rate_meas_dps: Some(s.rate_dps + 0.1 + 0.2 - 0.3),
        rate_meas_std_dps: Some(1e-4),
        rate_meas_min_dps: Some(s.rate_dps - 2e-4),
        rate_meas_max_dps: Some(s.rate_dps + 2e-4),
        rate_samples: Some(12),
        volts: mean,
        volts_std: Some(1.2909944487358056e-6),
        n: 4,
        overloads: 0,
        retries: 0,
        t_start_s: t0,
        t_end_s: t1,
        series: None,
    })
    .unwrap();
}

/// `v` one unit in the last place above: `40.0` becomes `40.00000000000001`.
fn noisy(v: f64) -> f64 {
    f64::from_bits(v.to_bits() + 1)
}

fn complete_run(dir: &Path) -> RunDir {
    let mut rd = RunDir::create(dir, &plan(), meta()).unwrap();
    for step in 0..5 {
        record(&mut rd, step);
    }
    // figures one bit off their round values, as sums and differences of clock readings are
    let (bound, schedule) = (noisy(40.0), noisy(42.1));
    rd.set_timing(Timing {
        bound_s: bound,
        elapsed_s: schedule,
        ratio: schedule / bound,
        acquisition: Some("stream".into()),
    })
    .unwrap();
    rd.finish(Status::Complete, None, noisy(44.3)).unwrap();
    gyrocal_analysis::sweep::fit_run(&mut rd, &gyrocal_fit::Options::default()).unwrap();
    rd
}

/// Every number token of a CSV or JSON text.
fn numbers(text: &str) -> Vec<&str> {
    text.split(|c: char| !(c.is_ascii_digit() || matches!(c, '.' | '-' | 'e' | 'E' | '+')))
        .filter(|t| {
            t.contains('.')
                && t.chars()
                    .next()
                    .is_some_and(|c| c.is_ascii_digit() || c == '-')
        })
        .collect()
}

/// Significant digits of a number token (`-0.000123450` → 5).
fn significant(token: &str) -> usize {
    let mantissa = token.split(['e', 'E']).next().unwrap_or(token);
    let digits: String = mantissa.chars().filter(char::is_ascii_digit).collect();
    digits.trim_start_matches('0').trim_end_matches('0').len()
}

#[test]
fn every_sample_and_step_has_a_utc_time_beside_its_run_clock_time() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let before = SystemTime::now();
    let rd = complete_run(&dir);
    let after = SystemTime::now();
    let anchor = rd.clock_anchor();
    drop(rd);

    let samples = load_samples(&dir).unwrap();
    assert_eq!(samples.len(), 20);
    for row in &samples {
        let utc = row.t_utc.as_deref().expect("t_utc");
        assert!(utc.ends_with('Z') && utc.len() == 24, "{utc}");
        let t = parse_rfc3339_utc(utc).unwrap();
        // the run clock started when the directory was created: t_utc = start + t_s
        let lo = before + Duration::from_secs_f64(row.t_s) - Duration::from_millis(1);
        let hi = after + Duration::from_secs_f64(row.t_s);
        assert!(t >= lo && t <= hi, "{utc} for t_s {}", row.t_s);
        assert_eq!(utc, anchor.utc(row.t_s));
    }
    let mut rdr = csv::Reader::from_path(dir.join(STEPS_CSV)).unwrap();
    let h = rdr.headers().unwrap().clone();
    let col = |c: &str| h.iter().position(|x| x == c).unwrap();
    let (ts, te, us, ue) = (
        col("t_start_s"),
        col("t_end_s"),
        col("t_start_utc"),
        col("t_end_utc"),
    );
    for row in rdr.records().map(Result::unwrap) {
        let t0: f64 = row[ts].parse().unwrap();
        let t1: f64 = row[te].parse().unwrap();
        let u0 = parse_rfc3339_utc(&row[us]).unwrap();
        let u1 = parse_rfc3339_utc(&row[ue]).unwrap();
        let span = u1.duration_since(u0).unwrap().as_secs_f64();
        assert!((span - (t1 - t0)).abs() < 0.002, "{row:?}");
        assert_eq!(&row[us], anchor.utc(t0));
    }
}

#[test]
fn the_files_carry_no_float_noise() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    drop(complete_run(&dir));
    for name in [SAMPLES_CSV, STEPS_CSV, MANIFEST_JSON, "fit.json"] {
        let text = fs::read_to_string(dir.join(name)).unwrap();
        for n in numbers(&text) {
            assert!(significant(n) <= 12, "{name}: {n} has float noise");
        }
    }
    let steps = fs::read_to_string(dir.join(STEPS_CSV)).unwrap();
    // t0 + 0.7 for step 1 is 10.799999999999999 in binary arithmetic
    assert!(steps.contains(",10.1,10.8,"), "{steps}");
    let m: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(dir.join(MANIFEST_JSON)).unwrap()).unwrap();
    assert_eq!(m["elapsed_s"], serde_json::json!(44.3));
    assert_eq!(m["timing"]["schedule_elapsed_s"], serde_json::json!(42.1));
    assert_eq!(m["timing"]["bound_s"], serde_json::json!(40.0));
}

#[test]
fn the_manifest_references_fit_json_and_names_its_elapsed_times() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    drop(complete_run(&dir));
    let text = fs::read_to_string(dir.join(MANIFEST_JSON)).unwrap();
    let m: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert!(
        m.get("fit").is_none(),
        "the manifest embeds the fit: {text}"
    );
    assert!(!text.contains("error_surface"), "{text}");
    let fit_bytes = fs::read(dir.join("fit.json")).unwrap();
    assert!(
        text.len() < fit_bytes.len(),
        "{} vs {}",
        text.len(),
        fit_bytes.len()
    );
    let s = &m["fit_summary"];
    assert_eq!(s["file"], "fit.json");
    assert_eq!(
        s["sha256"].as_str().unwrap(),
        gyrocal_files::rundir::sha256_hex(&fit_bytes)
    );
    let fit = load_fit(&dir).unwrap().unwrap();
    assert_eq!(
        s["scale_factor"].as_f64().unwrap(),
        fit.metrics.scale_factor
    );
    assert_eq!(s["bias_volts"].as_f64().unwrap(), fit.metrics.bias_volts);
    assert!(s["scale_factor_std_error"].as_f64().unwrap() > 0.0);
    assert!(s["bias_std_error"].as_f64().unwrap() > 0.0);
    assert!(s["best_model"].is_string());
    // the plan's name where one looks for it, not at plan.plan.name
    assert_eq!(m["plan"]["name"], "format test");
    assert!(m["plan"].get("plan").is_none(), "{text}");
    assert_eq!(m["plan"]["table"]["max_rate_dps"], serde_json::json!(20.0));
    // two elapsed figures, each named for what it covers
    assert!(m["timing"].get("elapsed_s").is_none(), "{text}");
    assert!(
        m["timing"]["schedule_elapsed_s"].as_f64().unwrap() <= m["elapsed_s"].as_f64().unwrap()
    );
    // and it reads back, plan and all
    let data = load(&dir).unwrap();
    assert_eq!(data.manifest.plan, plan());
    assert_eq!(data.manifest.timing.unwrap().elapsed_s, 42.1);
}

#[test]
fn a_finished_run_leaves_no_lock_and_a_live_one_holds_it() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let p = plan();
    let mut rd = RunDir::create(&dir, &p, meta()).unwrap();
    record(&mut rd, 0);
    assert!(dir.join(LOCK_FILE).exists());
    let err = RunDir::open_for_resume(&dir, &p).unwrap_err();
    assert!(matches!(err, RunError::Locked { .. }), "{err}");
    rd.finish(Status::Aborted, Some("test".into()), 3.0)
        .unwrap();
    // closed but still open for the fit and the report: still locked
    let err = RunDir::open_for_resume(&dir, &p).unwrap_err();
    assert!(matches!(err, RunError::Locked { .. }), "{err}");
    drop(rd);
    assert!(
        !dir.join(LOCK_FILE).exists(),
        "a finished run left its .lock"
    );

    // a resume locks again, and a complete run leaves no lock either
    let mut rd = RunDir::open_for_resume(&dir, &p).unwrap();
    assert!(dir.join(LOCK_FILE).exists());
    for step in 1..5 {
        record(&mut rd, step);
    }
    rd.finish(Status::Complete, None, 50.0).unwrap();
    drop(rd);
    assert!(!dir.join(LOCK_FILE).exists());
}

#[test]
fn a_crashed_runs_lock_file_does_not_block_a_resume() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let p = plan();
    let mut rd = RunDir::create(&dir, &p, meta()).unwrap();
    record(&mut rd, 0);
    // the process "dies": the manifest still says running, the OS drops the lock, the file
    // stays
    drop(rd);
    assert!(dir.join(LOCK_FILE).exists());
    assert_eq!(load(&dir).unwrap().manifest.status, Status::Running);
    let rd = RunDir::open_for_resume(&dir, &p).unwrap();
    assert_eq!(rd.done_steps().len(), 1);
}

/// Rewrites a run directory as gyrocal wrote it before this format: manifest format 1 with
/// the nested plan, `timing.elapsed_s`, the whole fit embedded and no fit summary; no UTC
/// columns in either CSV.
fn make_format_1(dir: &Path) {
    let path = dir.join(MANIFEST_JSON);
    let mut m: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(&path).unwrap()).unwrap();
    let obj = m.as_object_mut().unwrap();
    obj.insert("format_version".into(), 1.into());
    obj.remove("virtual_time");
    obj.remove("fit_summary");
    let mut plan = obj.remove("plan").unwrap();
    let p = plan.as_object_mut().unwrap();
    let mut nested = serde_json::json!({"plan": {}});
    for key in ["table", "dmm", "simulation"] {
        nested[key] = p.remove(key).unwrap();
    }
    nested["plan"] = serde_json::Value::Object(p.clone());
    obj.insert("plan".into(), nested);
    if let Some(t) = obj.get_mut("timing").and_then(|t| t.as_object_mut()) {
        let e = t.remove("schedule_elapsed_s").unwrap();
        t.insert("elapsed_s".into(), e);
    }
    if let Ok(fit) = fs::read_to_string(dir.join("fit.json")) {
        obj.insert("fit".into(), serde_json::from_str(&fit).unwrap());
        fs::remove_file(dir.join("fit.json")).unwrap();
    }
    fs::write(&path, serde_json::to_vec_pretty(&m).unwrap()).unwrap();
    let drop_cols = |name: &str, k: usize| {
        let text = fs::read_to_string(dir.join(name)).unwrap();
        let out: String = text
            .lines()
            .map(|l| {
                let cells: Vec<&str> = l.split(',').collect();
                format!("{}\n", cells[..cells.len() - k].join(","))
            })
            .collect();
        fs::write(dir.join(name), common::counted_from_zero(&out)).unwrap();
    };
    drop_cols(SAMPLES_CSV, 1);
    drop_cols(STEPS_CSV, 2);
}

#[test]
fn a_run_directory_of_the_previous_format_loads_and_resumes() {
    let tmp = tempfile::tempdir().unwrap();
    let p = plan();

    // a complete old run, fit embedded in the manifest: it loads, fit and all
    let done = tmp.path().join("done");
    drop(complete_run(&done));
    make_format_1(&done);
    let text = fs::read_to_string(done.join(MANIFEST_JSON)).unwrap();
    assert!(text.contains("\"format_version\": 1") && text.contains("\"error_surface\""));
    let data = load(&done).unwrap();
    assert_eq!(data.manifest.plan, p);
    assert_eq!(data.steps.len(), 5);
    assert_eq!(data.manifest.timing.unwrap().elapsed_s, 42.1);
    assert!(data.manifest.legacy_fit.is_some());
    let samples = load_samples(&done).unwrap();
    assert_eq!(samples.len(), 20);
    assert!(samples.iter().all(|s| s.t_utc.is_none()));

    // an interrupted old run resumes: steps.csv gets the UTC columns (empty in the old rows),
    // samples.csv keeps its columns
    let dir = tmp.path().join("run");
    let mut rd = RunDir::create(&dir, &p, meta()).unwrap();
    record(&mut rd, 0);
    record(&mut rd, 1);
    rd.finish(Status::Aborted, Some("SIGINT".into()), 20.0)
        .unwrap();
    drop(rd);
    make_format_1(&dir);
    let mut rd = RunDir::open_for_resume(&dir, &p).unwrap();
    for step in 2..5 {
        record(&mut rd, step);
    }
    rd.finish(Status::Complete, None, 50.0).unwrap();
    drop(rd);
    let data = load(&dir).unwrap();
    assert_eq!(data.steps.len(), 5);
    assert_eq!(data.manifest.format_version, 3);
    let samples = load_samples(&dir).unwrap();
    assert_eq!(samples.len(), 20);
    // read back 0-based like the schedule, the old rows and the resumed ones alike
    let steps: Vec<usize> = samples.iter().map(|s| s.step).collect();
    assert_eq!(steps, (0..5).flat_map(|s| [s; 4]).collect::<Vec<_>>());
    assert!(samples.iter().all(|s| s.index < 4));
    let text = fs::read_to_string(dir.join(SAMPLES_CSV)).unwrap();
    assert!(
        text.starts_with("step,index,t_s,rate_dps,volts,overload\n"),
        "{text}"
    );
    assert!(text.lines().all(|l| l.split(',').count() == 6), "{text}");
    // the resumed session's rows are in the file's own format: counted from 0
    assert!(text.lines().any(|l| l.starts_with("4,0,")), "{text}");
    assert!(!text.lines().any(|l| l.starts_with("5,")), "{text}");
    let mut rdr = csv::Reader::from_path(dir.join(STEPS_CSV)).unwrap();
    let h = rdr.headers().unwrap().clone();
    let u = h.iter().position(|x| x == "t_start_utc").unwrap();
    let rows: Vec<_> = rdr.records().map(Result::unwrap).collect();
    assert!(rows[..2].iter().all(|r| r[u].is_empty()));
    assert!(rows[2..].iter().all(|r| parse_rfc3339_utc(&r[u]).is_some()));
}

#[test]
fn a_bad_plan_key_in_the_manifest_is_named_with_the_file_and_line() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let mut rd = RunDir::create(&dir, &plan(), meta()).unwrap();
    record(&mut rd, 0);
    rd.finish(Status::Aborted, Some("test".into()), 1.0)
        .unwrap();
    drop(rd);
    let path = dir.join(MANIFEST_JSON);
    let text = fs::read_to_string(&path).unwrap();
    // a misspelt key of the [plan] section, now at the top of the manifest's plan
    fs::write(&path, text.replacen("\"rates_dps\"", "\"rate_dps\"", 1)).unwrap();
    let msg = load(&dir).unwrap_err().to_string();
    assert!(
        msg.contains("manifest.json:") && msg.contains("`rate_dps`"),
        "{msg}"
    );
    let msg = RunDir::open_for_resume(&dir, &plan())
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("manifest.json:") && msg.contains("`rate_dps`"),
        "{msg}"
    );
}

#[test]
fn a_refused_resume_of_a_finished_run_leaves_no_lock() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    drop(complete_run(&dir));
    assert!(!dir.join(LOCK_FILE).exists());
    let err = RunDir::open_for_resume(&dir, &plan()).unwrap_err();
    assert!(matches!(err, RunError::AlreadyComplete { .. }), "{err}");
    assert!(
        !dir.join(LOCK_FILE).exists(),
        "a refused resume left a .lock"
    );
    let other =
        Plan::from_toml_str(&plan_text().replace("= 4", "= 5"), Path::new("other.toml")).unwrap();
    let err = RunDir::open_for_resume(&dir, &other).unwrap_err();
    assert!(matches!(err, RunError::PlanChanged { .. }), "{err}");
    assert!(
        !dir.join(LOCK_FILE).exists(),
        "a refused resume left a .lock"
    );
}
