//! The one dispatch on a run's kind: a sweep's run directory gets its scale-factor fit and a
//! drift record's its Allan analysis, each result written through the run directory so that
//! `verify` vouches for it; the drift result read back typed (the catalog's figures).

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

use gyrocal_analysis::drift::{AllanDocument, DriftFigures};
use gyrocal_analysis::{Analysis, Options, RunKind, analyse, analyse_run};
use gyrocal_files::rundir::{ALLAN_JSON, FIT_JSON, FileState, verify};
use gyrocal_files::{Plan, RunDir, RunMeta, Sample, Status, StepRecord};

const SWEEP: &str = "[plan]\nname = \"dispatch sweep\"\nrates_dps = [0, 1, -1, 10, -10]\nsamples_per_rate = 5\n[table]\nport = \"/dev/ttyUSB1\"\nmax_rate_dps = 20\nacceleration_dps2 = 10\n[dmm]\nport = \"/dev/ttyUSB0\"\n";

const DRIFT: &str = "[plan]\nkind = \"drift\"\nname = \"dispatch drift\"\nrates_dps = [0]\nsamples_per_rate = 1500\nrepeat = 2\nsettle_s = 0\n[table]\nport = \"/dev/ttyUSB1\"\nmax_rate_dps = 20\nacceleration_dps2 = 10\n[dmm]\nport = \"/dev/ttyUSB0\"\n[drift]\ntable = \"hold\"\naxis = \"up\"\nlatitude_deg = 45\n";

/// K of the simulated gyro, V/(°/s).
const K: f64 = 0.36;

/// Writes a complete run of `toml` into `dir`: every step's readings `volts(step, rate, j)`,
/// 0.1 s apart on one continuous clock.
fn write_run(dir: &Path, toml: &str, volts: impl Fn(usize, f64, u64) -> f64) -> RunDir {
    let plan = Plan::from_toml_str(toml, Path::new("test.toml")).unwrap();
    let n = u64::from(plan.samples_per_rate());
    let mut rd = RunDir::create(dir, &plan, RunMeta::default()).unwrap();
    let schedule = rd.schedule().to_vec();
    let mut t = 0.0_f64;
    for (i, s) in schedule.iter().enumerate() {
        let w = s.rate_dps;
        let t_start = t;
        let samples: Vec<Sample> = (0..n)
            .map(|j| {
                let sample = Sample {
                    index: j,
                    t_s: t,
                    volts: Some(volts(i, w, j)),
                };
                t = ((t + 0.1) * 10.0).round() / 10.0;
                sample
            })
            .collect();
        let vs: Vec<f64> = samples.iter().filter_map(|s| s.volts).collect();
        let mean = vs.iter().sum::<f64>() / vs.len() as f64;
        let std =
            (vs.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (vs.len() - 1) as f64).sqrt();
        rd.append_samples(s.index, &samples).unwrap();
        rd.append_step(StepRecord {
            step: s.index,
            pass: s.pass,
            rate_dps: w,
            rate_meas_dps: Some(w),
            rate_meas_std_dps: None,
            rate_meas_min_dps: None,
            rate_meas_max_dps: None,
            rate_samples: None,
            volts: mean,
            volts_std: Some(std),
            n,
            overloads: 0,
            retries: 0,
            t_start_s: t_start,
            t_end_s: t,
            series: None,
        })
        .unwrap();
    }
    rd.finish(Status::Complete, None, t).unwrap();
    rd
}

/// A deterministic ±0.5 noise sequence.
fn noise(i: usize, j: u64) -> f64 {
    let mut x =
        (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ j.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x ^= x >> 31;
    x = x.wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^= x >> 29;
    (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
}

fn sweep_volts(i: usize, w: f64, j: u64) -> f64 {
    0.01 + K * w + 1e-4 * noise(i, j)
}

/// At rest: 10 mV of bias and white noise; the `[drift]` axis is up at 45°.
fn drift_volts(i: usize, _w: f64, j: u64) -> f64 {
    0.01 + 1e-4 * noise(i, j)
}

fn state_of(dir: &Path, file: &str) -> FileState {
    verify(dir)
        .unwrap()
        .checks
        .into_iter()
        .find(|c| c.file == file)
        .map(|c| c.state)
        .unwrap_or_else(|| panic!("{file} not checked"))
}

#[test]
fn a_sweep_is_fitted_and_its_fit_json_recorded() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let mut rd = write_run(&dir, SWEEP, sweep_volts);
    assert_eq!(RunKind::of(rd.manifest()), RunKind::Sweep);
    assert_eq!(RunKind::of_dir(&dir), Some(RunKind::Sweep));
    assert_eq!(RunKind::Sweep.result_file(), FIT_JSON);

    let stored = match analyse_run(&mut rd, &Options::default()).unwrap() {
        Analysis::Sweep(a) => a,
        Analysis::Drift(_) => panic!("a sweep analysed as a drift record"),
    };
    assert!(
        (stored.metrics.scale_factor - K).abs() < 1e-4,
        "K = {}",
        stored.metrics.scale_factor
    );
    drop(rd);
    assert_eq!(state_of(&dir, FIT_JSON), FileState::Ok);
    assert!(
        !dir.join(ALLAN_JSON).exists(),
        "a sweep has no Allan analysis"
    );

    // the read-only dispatch gives what was stored
    let again = analyse(&dir, &Options::default()).unwrap();
    assert_eq!(again.kind(), RunKind::Sweep);
    let Analysis::Sweep(again) = again else {
        unreachable!()
    };
    assert_eq!(again.metrics.scale_factor, stored.metrics.scale_factor);
    // fit.json holds 12 significant digits (see gyrocal_files::num)
    let on_disk = gyrocal_files::load_fit(&dir).unwrap().unwrap();
    assert!(
        (on_disk.metrics.scale_factor - stored.metrics.scale_factor).abs()
            <= 1e-11 * stored.metrics.scale_factor.abs()
    );
}

#[test]
fn a_drift_record_gets_its_allan_analysis_recorded_and_verified() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let mut rd = write_run(&dir, DRIFT, drift_volts);
    assert_eq!(RunKind::of(rd.manifest()), RunKind::Drift);
    assert_eq!(RunKind::of_dir(&dir), Some(RunKind::Drift));
    assert_eq!(RunKind::Drift.result_file(), ALLAN_JSON);

    let doc: AllanDocument = match analyse_run(&mut rd, &Options::default()).unwrap() {
        Analysis::Drift(d) => *d,
        Analysis::Sweep(_) => panic!("a drift record fitted as a sweep"),
    };
    drop(rd);
    // the two segments (steps) are one record: 3000 readings 0.1 s apart, no gap
    assert_eq!(doc.rows, 3000);
    assert_eq!(doc.segments.len(), 1);
    assert_eq!(doc.tau0_s, 0.1);
    assert_eq!(doc.run.as_ref().unwrap().plan_name, "dispatch drift");
    // not fitted: the curve is in volts, the Earth rate cannot be removed (and says so)
    assert_eq!(doc.unit, "V");
    assert!(doc.noise_terms.is_none());
    assert!(
        (doc.bias.bias.value - 0.01).abs() < 1e-5,
        "{}",
        doc.bias.bias.value
    );

    // allan.json is the document, written through the run directory and verified
    let on_disk = std::fs::read_to_string(dir.join(ALLAN_JSON)).unwrap();
    assert_eq!(on_disk, doc.to_json());
    assert_eq!(state_of(&dir, ALLAN_JSON), FileState::Ok);
    assert!(verify(&dir).unwrap().ok());
    assert!(!dir.join(FIT_JSON).exists(), "a drift record is not fitted");

    // the read-only dispatch gives the same document
    let Analysis::Drift(again) = analyse(&dir, &Options::default()).unwrap() else {
        panic!("not a drift analysis")
    };
    assert_eq!(again.to_json(), on_disk);

    // an edited allan.json is caught by verify
    std::fs::write(dir.join(ALLAN_JSON), on_disk.replace("\"V\"", "\"mV\"")).unwrap();
    assert!(matches!(
        state_of(&dir, ALLAN_JSON),
        FileState::Changed { .. }
    ));
}

#[test]
fn a_drift_record_in_deg_per_hour_gives_the_catalog_its_figures_typed() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let mut rd = write_run(&dir, DRIFT, drift_volts);
    let opts = Options {
        drift: gyrocal_analysis::drift::AllanOptions {
            scale_factor: Some(0.02),
            ..Default::default()
        },
        ..Options::default()
    };
    let Analysis::Drift(doc) = analyse_run(&mut rd, &opts).unwrap() else {
        panic!("not a drift analysis")
    };
    drop(rd);
    assert_eq!(doc.unit, "deg/h");
    let earth = doc
        .earth_rate
        .as_ref()
        .expect("the plan's axis and latitude");
    let figures = DriftFigures::load(&dir).unwrap().expect("allan.json");
    assert_eq!(figures, DriftFigures::of(&doc));
    assert_eq!(figures.unit.as_deref(), Some("deg/h"));
    assert_eq!(figures.duration_s, Some(doc.analysed.duration_s));
    // the bias is the gyro's own: the Earth's rate along the axis removed
    assert_eq!(figures.bias.value, Some(earth.bias_dph));
    assert_eq!(figures.bias.uncertainty, Some(doc.bias.bias.uncertainty));
    let fit = doc.noise_terms.as_ref().unwrap().fit.as_ref().unwrap();
    let arw = fit
        .terms
        .iter()
        .find(|t| t.term == gyrocal_allan::Term::AngleRandomWalk)
        .unwrap();
    assert_eq!(figures.arw.value, Some(arw.value.value));
    assert_eq!(figures.arw.uncertainty, Some(arw.value.uncertainty));
}

#[test]
fn figures_are_read_leniently_and_a_garbled_allan_json_is_named() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(DriftFigures::load(tmp.path()).unwrap(), None);
    // a figure that came out null (a non-finite interval) or a part an earlier gyrocal did not
    // write costs that figure only
    std::fs::write(
        tmp.path().join(ALLAN_JSON),
        r#"{"unit": "deg/h", "analysed": {"duration_s": 300.0},
            "bias": {"bias": {"value": 1.5, "uncertainty": null, "unit": "deg/h"}}}"#,
    )
    .unwrap();
    let f = DriftFigures::load(tmp.path()).unwrap().unwrap();
    assert_eq!(f.duration_s, Some(300.0));
    assert_eq!(f.bias.value, Some(1.5));
    assert_eq!(f.bias.uncertainty, None);
    assert_eq!(f.arw.value, None);
    // a record left in volts has no figures in °/h
    std::fs::write(
        tmp.path().join(ALLAN_JSON),
        r#"{"unit": "V", "analysed": {"duration_s": 300.0}, "bias": {"bias": {"value": 0.01}}}"#,
    )
    .unwrap();
    let f = DriftFigures::load(tmp.path()).unwrap().unwrap();
    assert_eq!(f.bias.value, None);
    assert_eq!(f.duration_s, Some(300.0));
    // not JSON: an error naming the file and the line
    std::fs::write(tmp.path().join(ALLAN_JSON), "{\n  \"unit\": deg/h\n}").unwrap();
    let e = DriftFigures::load(tmp.path()).unwrap_err().to_string();
    assert!(e.contains("allan.json:2:"), "{e}");
}

#[test]
fn a_directory_that_is_no_run_has_no_kind() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(RunKind::of_dir(tmp.path()), None);
    assert_eq!(RunKind::of_dir(&tmp.path().join("missing")), None);
    assert!(analyse(tmp.path(), &Options::default()).is_err());
}

/// The catalog's figures of a sweep come through the same dispatch, read typed from its
/// `fit.json`: K as fitted, its expanded uncertainty, the model chosen; a figure of another
/// type (a fit written by another gyrocal) costs that figure only.
#[test]
fn a_sweeps_figures_are_read_typed_from_its_fit_and_leniently() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let mut rd = write_run(&dir, SWEEP, sweep_volts);
    let Analysis::Sweep(stored) = analyse_run(&mut rd, &Options::default()).unwrap() else {
        panic!("a sweep analysed as a drift record")
    };
    let m = rd.manifest().clone();
    drop(rd);
    let fit: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join(FIT_JSON)).unwrap()).unwrap();
    let f = gyrocal_analysis::figures(&dir, &m, Some(&fit))
        .unwrap()
        .unwrap();
    let k = f.scale_factor.unwrap();
    assert!(
        (k - stored.metrics.scale_factor).abs() <= 1e-11 * k.abs(),
        "{k}"
    );
    assert_eq!(
        f.best_model,
        stored.best_model.map(|m| serde_json::to_value(m)
            .unwrap()
            .as_str()
            .unwrap()
            .to_string())
    );
    assert!(f.best_model.is_some());
    assert!(f.scale_factor_std_error.is_some_and(|s| s > 0.0));
    assert_eq!(f.arw_deg_rt_h, None, "a sweep has no noise terms");

    let mut odd = fit.clone();
    odd["metrics"]["nonlinearity_ppm"] = serde_json::json!("n/a");
    odd["fits"] = serde_json::json!("not a list");
    let g = gyrocal_analysis::figures(&dir, &m, Some(&odd))
        .unwrap()
        .unwrap();
    assert_eq!(g.nonlinearity_ppm, None);
    assert_eq!(g.scale_factor, f.scale_factor);
    assert_eq!(g.asymmetry_ppm, f.asymmetry_ppm);
    // without a fit document a sweep has no figures yet
    assert_eq!(gyrocal_analysis::figures(&dir, &m, None).unwrap(), None);
}
