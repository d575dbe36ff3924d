//! A temperature series run directory written by the real writer (steps with their series
//! cells, temps.csv), ended by the report's one dispatch: series.json (with the catalog
//! member) and series.html written through the run directory and recorded in the manifest,
//! the sensitivities recovered within their stated U, the result said.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

use gyrocal_files::rundir::temps::{Phase, TempRow};
use gyrocal_files::rundir::{SERIES_JSON, SeriesCells};
use gyrocal_files::{Plan, RunDir, RunMeta, Sample, Status, StepRecord};

const PLAN: &str = "[plan]\nkind = \"temperature_series\"\nname = \"series <e2e>\"\n\
    rates_dps = [0, 2, -2, 5, -5, 10, -10, 20, -20]\nsamples_per_rate = 20\nsettle_s = 0\n\
    [table]\ndialect = \"acl\"\nport = \"/dev/ttyUSB1\"\nmax_rate_dps = 20\nacceleration_dps2 = 10\n\
    [dmm]\nport = \"/dev/ttyUSB0\"\nrange_v = 10\nnplc = 1\nautozero = false\nline_hz = 50\n\
    [series]\ntemperatures_c = [25, -20, 60, 25]\nmeasure = \"both\"\nbias_readings = 40\n\
    [chamber]\nmodel = \"watlow_f4\"\nport = \"/dev/ttyUSB2\"\n\
    [acceptance]\ndecision_rule = \"guarded\"\nk_tempco_ppm_per_c_max = 200\nbias_tempco_dph_per_c_max = 5\n";

struct Noise(u64);

impl Noise {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let x = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D);
        ((x >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    fn gauss(&mut self) -> f64 {
        let (u, v) = (self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    }
}

const K25: f64 = 0.3612;
const ALPHA_PPM: f64 = 80.0;
const K0_25: f64 = 0.0088;
const BETA_V: f64 = 4e-6;
const NOISE_V: f64 = 0.0005;

/// The gyro at `t_c`: (K, K0).
fn gyro(t_c: f64) -> (f64, f64) {
    (
        K25 * (1.0 + ALPHA_PPM * 1e-6 * (t_c - 25.0)),
        K0_25 + BETA_V * (t_c - 25.0),
    )
}

fn write_run(dir: &Path) -> RunDir {
    let plan = Plan::from_toml_str(PLAN, Path::new("series.toml")).unwrap();
    let meta = RunMeta {
        gyrocal_version: "0.1.0-test".into(),
        simulated: true,
        ..RunMeta::default()
    };
    let mut rd = RunDir::create(dir, &plan, meta).unwrap();
    let mut noise = Noise(0x1234_5678_9ABC_DEF1);
    let schedule = rd.schedule().to_vec();
    let mut clock = 0.0;
    let mut last_point = None;
    let mut gyro_t = 25.0;
    for s in &schedule {
        let at = s.series.unwrap();
        if last_point != Some(at.point) {
            // ramp and soak: an hour of history, the gyro settling a little off the setpoint
            for i in 0..60 {
                clock += 60.0;
                gyro_t += (at.setpoint_c + 0.4 - gyro_t) * 0.15;
                rd.append_temp(&TempRow {
                    t_s: clock,
                    setpoint_c: at.setpoint_c,
                    air_c: at.setpoint_c + 0.1,
                    product_c: Some(gyro_t),
                    series_point: Some(at.point),
                    phase: if i < 30 { Phase::Ramp } else { Phase::Soak },
                })
                .unwrap();
            }
            gyro_t = at.setpoint_c + 0.4 + 0.2 * noise.gauss();
            last_point = Some(at.point);
        }
        let (k, k0) = gyro(gyro_t);
        let n = s.sample_count(std::time::Duration::from_millis(40));
        let samples: Vec<Sample> = (0..n)
            .map(|i| Sample {
                index: i,
                t_s: clock + i as f64 * 0.04,
                volts: Some(k0 + k * s.rate_dps + NOISE_V * noise.gauss()),
            })
            .collect();
        rd.append_samples(s.index, &samples).unwrap();
        let v: Vec<f64> = samples.iter().filter_map(|s| s.volts).collect();
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (v.len() - 1) as f64;
        rd.append_temp(&TempRow {
            t_s: clock,
            setpoint_c: at.setpoint_c,
            air_c: at.setpoint_c + 0.1,
            product_c: Some(gyro_t),
            series_point: Some(at.point),
            phase: Phase::Measure,
        })
        .unwrap();
        rd.append_step(StepRecord {
            step: s.index,
            pass: s.pass,
            rate_dps: s.rate_dps,
            rate_meas_dps: None,
            rate_meas_std_dps: None,
            rate_meas_min_dps: None,
            rate_meas_max_dps: None,
            rate_samples: None,
            volts: mean,
            volts_std: Some(var.sqrt()),
            n,
            overloads: 0,
            retries: 0,
            t_start_s: clock,
            t_end_s: clock + 1.0,
            series: Some(SeriesCells {
                series_point: at.point,
                setpoint_c: at.setpoint_c,
                temp_min_c: Some(gyro_t - 0.05),
                temp_mean_c: Some(gyro_t),
                temp_max_c: Some(gyro_t + 0.05),
                bias_record: at.bias_record,
            }),
        })
        .unwrap();
        clock += 2.0;
    }
    rd.finish(Status::Complete, None, clock).unwrap();
    rd
}

#[test]
fn a_series_run_ends_with_series_json_and_its_page_and_recovers_the_coefficients() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let mut rd = write_run(&dir);
    let end = gyrocal_report::end_of_run(&mut rd, true).unwrap();
    assert!(end.warnings.is_empty(), "{:?}", end.warnings);
    let result = end.result.clone().unwrap();
    assert!(
        result.contains("ppm/°C") && result.contains("°/h/°C"),
        "{result}"
    );
    assert!(
        end.results.contains("series.json and series.html"),
        "{}",
        end.results
    );
    let page = end.page.clone().unwrap();
    assert!(page.ends_with("series.html"));
    drop(rd);

    let doc = gyrocal_analysis::series::load_document(&dir)
        .unwrap()
        .unwrap();
    assert_eq!(doc.points.len(), 4);
    assert_eq!(doc.points[0].bias_from.as_deref(), Some("bias record"));
    let k = doc.k_tempco_ppm_per_c.as_ref().unwrap();
    assert!(
        (k.value - ALPHA_PPM).abs() <= k.u,
        "K: {} ± {}",
        k.value,
        k.u
    );
    // the bias as a rate K0(T)/K(T)·3600 at the model's mid-range temperature
    let rate = |t: f64| {
        let (k, k0) = gyro(t);
        k0 / k * 3600.0
    };
    let mid = doc.bias_model.as_ref().unwrap().chosen().t_mid_c;
    let b_true = rate(mid + 0.5) - rate(mid - 0.5);
    let b = doc.bias_tempco_dph_per_c.as_ref().unwrap();
    assert!(
        (b.value - b_true).abs() <= b.u,
        "bias: {} ± {} vs {b_true}",
        b.value,
        b.u
    );
    // the gyro's measured temperatures, not the setpoints
    assert!((doc.points[1].temp_mean_c - (-19.6)).abs() < 1.0);
    assert!(doc.points[1].temp_min_c < doc.points[1].temp_mean_c);
    // the plan's limits judged
    assert_eq!(doc.acceptance.len(), 2);
    assert!(doc.verdict.is_some());
    // the catalog member as the catalog reads it: plain JSON with the contract's keys
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join(SERIES_JSON)).unwrap()).unwrap();
    assert_eq!(v["catalog"]["points"].as_array().unwrap().len(), 4);
    assert_eq!(v["catalog"]["k_tempco_ppm_per_c"].as_f64(), Some(k.value));
    assert!(v["catalog"]["hysteresis_k_ppm"].is_number());
    // both files recorded in the manifest with their SHA-256
    let m = gyrocal_files::load(&dir).unwrap().manifest;
    for f in [SERIES_JSON, "series.html"] {
        assert!(m.checksums.contains_key(f), "{f} not in checksums");
    }
    let html = std::fs::read_to_string(&page).unwrap();
    if let Ok(out) = std::env::var("GYROCAL_SHOT_HTML") {
        std::fs::write(out, &html).unwrap();
    }
    assert!(html.contains("id=\"plot-history\""));
    assert!(html.contains("watlow_f4"));
    assert!(html.contains("series &lt;e2e&gt;"));
    // gyrocal report's own page for this run
    let own = gyrocal_report::own_page(&dir).unwrap();
    assert_eq!(own.kind, "temperature_series");
    let files = (own.write)(&dir, &["re-written by a test".to_string()]).unwrap();
    assert_eq!(files.len(), 2);
    let again = gyrocal_analysis::series::load_document(&dir)
        .unwrap()
        .unwrap();
    assert_eq!(
        again.notes.first().map(String::as_str),
        Some("re-written by a test")
    );
}

#[test]
fn the_one_dispatch_analyses_a_series_and_its_figures_are_the_first_temperature_s() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let mut rd = write_run(&dir);
    let a = gyrocal_analysis::analyse_run(&mut rd, &Default::default()).unwrap();
    assert_eq!(a.kind(), gyrocal_analysis::RunKind::Series);
    drop(rd);
    let m = gyrocal_files::load(&dir).unwrap().manifest;
    let f = gyrocal_analysis::figures(&dir, &m, None).unwrap().unwrap();
    let k = f.scale_factor.unwrap();
    assert!((k - K25).abs() / K25 < 1e-3, "{k}");
    assert!(f.u_scale_factor.unwrap() > 0.0);
}

#[test]
fn a_series_whose_rows_lack_the_gyro_temperature_is_a_plain_error_naming_the_point() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    drop(write_run(&dir));
    // blank the temperature cells of every row (a product sensor that never answered)
    let path = dir.join(gyrocal_files::rundir::STEPS_CSV);
    let text = std::fs::read_to_string(&path).unwrap();
    let mut out = String::new();
    for (i, line) in text.lines().enumerate() {
        if i == 0 {
            out.push_str(line);
        } else {
            let cells: Vec<&str> = line.split(',').collect();
            let n = cells.len();
            let mut cells: Vec<String> = cells.iter().map(|c| c.to_string()).collect();
            for c in &mut cells[n - 4..n - 1] {
                c.clear();
            }
            out.push_str(&cells.join(","));
        }
        out.push('\n');
    }
    std::fs::write(&path, out).unwrap();
    let data = gyrocal_files::load(&dir).unwrap();
    let e = gyrocal_analysis::series::analyse_run_data(&dir, &data, &Default::default())
        .expect_err("no temperatures");
    let msg = e.to_string();
    assert!(
        msg.contains("series point 0") && msg.contains("no gyro (product) temperature"),
        "{msg}"
    );
    assert_eq!(e.kind(), gyrocal_analysis::ErrorKind::Input);
}

#[test]
fn check_warns_of_a_series_with_one_temperature_or_without_a_sweep() {
    use gyrocal_analysis::KindAnalysis;
    let one = PLAN
        .replace(
            "temperatures_c = [25, -20, 60, 25]",
            "temperatures_c = [25, 25]",
        )
        .replace("measure = \"both\"", "measure = \"bias\"");
    let plan = Plan::from_toml_str(&one, Path::new("one.toml")).unwrap();
    let w = gyrocal_analysis::series::Kind::plan_warnings(&plan, Path::new("one.toml"));
    assert!(
        w.iter().any(|l| l.contains("1 distinct temperature")),
        "{w:?}"
    );
    assert!(w.iter().any(|l| l.contains("measure = \"bias\"")), "{w:?}");
    let plan = Plan::from_toml_str(PLAN, Path::new("series.toml")).unwrap();
    assert!(gyrocal_analysis::series::Kind::plan_warnings(&plan, Path::new("s")).is_empty());
}
