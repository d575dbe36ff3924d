//! Run directories for the catalog's tests: one written by the real run-directory writer
//! (gyrocal-files), cloned with other serials, start times and results (the files copied,
//! manifest.json and fit.json edited as JSON).

#![allow(clippy::unwrap_used, clippy::expect_used, dead_code)]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use gyrocal_files::{Dut, Instruments, Plan, RunDir, RunMeta, Sample, Status, StepRecord};

/// The plans written once for every crate's tests.
#[path = "../../../../tests/support/plans.rs"]
pub mod plans;

const RATES: [f64; 5] = [0.0, 1.0, -1.0, 10.0, -10.0];
const N: u64 = 5;

/// The template run (written once per test binary).
pub fn template() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| {
        let tmp = tempfile::tempdir().unwrap();
        write_template(&tmp.path().join("run"));
        tmp
    })
    .path()
    .join("run")
    .leak()
}

fn write_template(dir: &Path) {
    let toml = plans::sweep("catalog test", &RATES, N);
    let plan = Plan::from_toml_str(&toml, Path::new("test.toml")).unwrap();
    let meta = RunMeta {
        gyrocal_version: "0.1.0-test".into(),
        instruments: Instruments {
            dmm: Some("HEWLETT-PACKARD,34401A,3146A12345,11-5-2".into()),
            table: Some("ACUTRONIC,ACUTROL3000,SIM0001,1.0".into()),
        },
        simulated: true,
        dut: Some(Dut {
            serial: Some("TEMPLATE".into()),
            model: Some("HRG-1".into()),
            ..Dut::default()
        }),
        ..RunMeta::default()
    };
    let mut rd = RunDir::create(dir, &plan, meta).unwrap();
    let schedule = rd.schedule().to_vec();
    for (i, s) in schedule.iter().enumerate() {
        let w = s.rate_dps;
        let samples: Vec<Sample> = (0..N)
            .map(|j| Sample {
                index: j,
                t_s: i as f64 * 10.0 + j as f64 * 0.1,
                volts: Some(0.01 + 0.36 * w + 1e-5 * w * w + 1e-4 * (j as f64 - 2.0)),
            })
            .collect();
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
            volts: 0.01 + 0.36 * w + 1e-5 * w * w,
            volts_std: Some(1.6e-4),
            n: N,
            overloads: 0,
            retries: 0,
            t_start_s: i as f64 * 10.0,
            t_end_s: i as f64 * 10.0 + 0.5,
            series: None,
        })
        .unwrap();
    }
    let options = gyrocal_fit::Options {
        methods: vec![gyrocal_fit::Method::LeastSquares],
        ..gyrocal_fit::Options::default()
    };
    gyrocal_analysis::sweep::fit_run(&mut rd, &options).unwrap();
    rd.finish(Status::Complete, None, 50.0).unwrap();
}

/// What a clone changes.
#[derive(Debug, Clone)]
pub struct Spec {
    pub serial: String,
    pub started_utc: String,
    pub scale_factor: f64,
    pub bias_dph: f64,
    pub simulated: bool,
    pub status: &'static str,
    /// `uncertainty` and `acceptance` in fit.json, `asymmetry_common_k2` in the metrics.
    pub extras: bool,
}

impl Spec {
    pub fn new(serial: &str, day: u32, k: f64) -> Spec {
        Spec {
            serial: serial.into(),
            started_utc: format!("2026-{:02}-{:02}T10:00:00.000Z", 1 + day / 28, 1 + day % 28),
            scale_factor: k,
            bias_dph: 36.0,
            simulated: false,
            status: "complete",
            extras: false,
        }
    }
}

fn read_json(p: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(p).unwrap()).unwrap()
}

/// A copy of the template at `dest` with `spec`'s values.
pub fn clone_run(dest: &Path, spec: &Spec) -> PathBuf {
    let src = template();
    std::fs::create_dir_all(dest).unwrap();
    for name in ["samples.csv", "steps.csv"] {
        std::fs::copy(src.join(name), dest.join(name)).unwrap();
    }
    let mut m = read_json(&src.join("manifest.json"));
    m["dut"]["serial"] = spec.serial.clone().into();
    m["started_utc"] = spec.started_utc.clone().into();
    m["simulated"] = spec.simulated.into();
    m["status"] = spec.status.into();
    m["fit_summary"]["scale_factor"] = spec.scale_factor.into();
    std::fs::write(dest.join("manifest.json"), serde_json::to_vec(&m).unwrap()).unwrap();
    let mut f = read_json(&src.join("fit.json"));
    f["metrics"]["scale_factor"] = spec.scale_factor.into();
    f["metrics"]["bias_dph"] = spec.bias_dph.into();
    if spec.extras {
        f["metrics"]["asymmetry_common_k2"] =
            serde_json::json!({"asymmetry_ppm": 12.5, "k2": 1.1e-5});
        f["uncertainty"] = serde_json::json!({"quantities": [
            {"quantity": "scale_factor", "expanded_uncertainty": 3.6e-5},
            {"quantity": "bias_dph", "expanded_uncertainty": 2.0},
        ]});
        f["acceptance"] = serde_json::json!({"verdict": "pass", "rule": "guarded", "checks": [
            {"quantity": "scale_factor", "value": spec.scale_factor, "unit": "V/(°/s)",
             "expanded_uncertainty": 3.6e-5, "min": 0.355, "max": 0.365,
             "marginal_min": null, "marginal_max": null, "verdict": "pass"}
        ]});
    }
    std::fs::write(dest.join("fit.json"), serde_json::to_vec(&f).unwrap()).unwrap();
    dest.to_path_buf()
}
