use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

use super::*;

fn normal(rng: &mut StdRng) -> f64 {
    let u1 = 1.0 - rng.random::<f64>();
    let u2 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// A simulated gyro: K(T) = K25·(1 + α·(T − 25)), K0(T) = K0_25 + β·(T − 25) (V), plus a
/// hysteresis step in K after the cold point.
struct Gyro {
    k25: f64,
    alpha_ppm: f64,
    k0_25: f64,
    beta_v_per_c: f64,
    hysteresis_ppm_after_cold: f64,
}

/// The issue's gyro: K −60 ppm/°C, K0 +2 µV/°C.
const ISSUE_GYRO: Gyro = Gyro {
    k25: 0.0125,
    alpha_ppm: -60.0,
    k0_25: 0.004,
    beta_v_per_c: 2e-6,
    hysteresis_ppm_after_cold: 0.0,
};

const RATES: [f64; 9] = [-100.0, -50.0, -20.0, -5.0, 0.0, 5.0, 20.0, 50.0, 100.0];
const NOISE_V: f64 = 2e-4;
const READINGS: u64 = 100;

fn series(g: &Gyro, setpoints: &[f64], seed: u64, bias: bool) -> SeriesInput {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut cold_seen = false;
    let points = setpoints
        .iter()
        .enumerate()
        .map(|(i, &sp)| {
            let t = sp + 0.3 * normal(&mut rng);
            let hyst = if cold_seen {
                g.hysteresis_ppm_after_cold
            } else {
                0.0
            };
            if sp < 0.0 {
                cold_seen = true;
            }
            let k = g.k25 * (1.0 + (g.alpha_ppm * (t - 25.0) + hyst) * 1e-6);
            let k0 = g.k0_25 + g.beta_v_per_c * (t - 25.0);
            let sem = NOISE_V / (READINGS as f64).sqrt();
            let sweep = gyrocal_fit::Dataset {
                source: None,
                points: RATES
                    .iter()
                    .map(|&w| gyrocal_fit::Point {
                        rate_dps: w,
                        volts: k0 + k * w + sem * normal(&mut rng),
                        volts_std: Some(NOISE_V),
                        n: Some(READINGS),
                        line: None,
                    })
                    .collect(),
            };
            PointInput {
                series_point: i,
                setpoint_c: sp,
                temp_min_c: t - 0.1,
                temp_mean_c: t,
                temp_max_c: t + 0.1,
                sweep: Some(sweep),
                bias: bias.then(|| BiasRecord {
                    mean_v: k0 + sem * normal(&mut rng),
                    std_v: NOISE_V,
                    n: READINGS,
                }),
            }
        })
        .collect();
    SeriesInput {
        points,
        uncertainty: gyrocal_fit::UncertaintyInputs::default(),
        limits: TempcoLimits {
            k_tempco_ppm_per_c_max: Some(100.0),
            bias_tempco_dph_per_c_max: Some(0.5),
        },
    }
}

fn ls_only() -> Options {
    Options {
        fit: gyrocal_fit::Options {
            methods: vec![gyrocal_fit::Method::LeastSquares],
            ..gyrocal_fit::Options::default()
        },
        reference_c: None,
    }
}

#[test]
fn the_issue_s_series_recovers_the_gyro_s_coefficients_within_their_stated_u() {
    let g = ISSUE_GYRO;
    let input = series(&g, &[25.0, -20.0, 60.0, 25.0], 3, true);
    let doc = analyse_input(&input, &ls_only(), "synthetic").expect("analysis");
    assert_eq!(doc.points.len(), 4);
    assert_eq!(doc.reference_c, 25.0);
    let k = doc.k_tempco_ppm_per_c.as_ref().expect("K tempco");
    assert!(
        (k.value - g.alpha_ppm).abs() <= k.u,
        "{} ± {}",
        k.value,
        k.u
    );
    assert!(
        k.u < 20.0,
        "U of K's tempco too loose to be useful: {}",
        k.u
    );
    // bias as a rate K0(T)/K(T)·3600: its slope at the model's mid-range temperature (K's own
    // change moves it too: K0·α·3600/K is 0.07 °/h/°C here)
    let rate = |t: f64| {
        (g.k0_25 + g.beta_v_per_c * (t - 25.0)) / (g.k25 * (1.0 + g.alpha_ppm * 1e-6 * (t - 25.0)))
            * 3600.0
    };
    let mid = doc
        .bias_model
        .as_ref()
        .expect("bias model")
        .chosen()
        .t_mid_c;
    let b_true = (rate(mid + 0.5) - rate(mid - 0.5)) / 1.0;
    let b = doc.bias_tempco_dph_per_c.as_ref().expect("bias tempco");
    assert!(
        (b.value - b_true).abs() <= b.u,
        "{} ± {} vs {b_true}",
        b.value,
        b.u
    );
    assert_eq!(doc.points[0].bias_from.as_deref(), Some("bias record"));
    // one revisit, no hysteresis in the truth
    assert_eq!(doc.hysteresis_k_ppm.len(), 1);
    let h = &doc.hysteresis_k_ppm[0];
    assert!(h.difference.abs() <= h.u, "{} ± {}", h.difference, h.u);
    // |−60| ppm/°C against a 100 ppm/°C limit, 0.58 °/h/°C against 0.5
    assert_eq!(doc.acceptance[0].verdict, "pass");
    assert_ne!(doc.acceptance[1].verdict, "pass");
    // the catalog member carries the same figures
    let c = &doc.catalog;
    assert_eq!(c.k_tempco_ppm_per_c, Some(k.value));
    assert_eq!(c.k_model_order, Some(1));
    assert_eq!(c.points.len(), 4);
    assert!(c.t_min_c.unwrap_or(0.0) < -19.0 && c.t_max_c.unwrap_or(0.0) > 59.0);
}

#[test]
fn a_hysteresis_step_after_the_cold_point_is_seen_with_its_sign() {
    let g = Gyro {
        k25: 0.0125,
        alpha_ppm: 20.0,
        k0_25: 0.0,
        beta_v_per_c: 0.0,
        hysteresis_ppm_after_cold: 200.0,
    };
    let input = series(&g, &[25.0, -20.0, 60.0, 25.0], 11, false);
    let doc = analyse_input(&input, &ls_only(), "synthetic").expect("analysis");
    let h = &doc.hysteresis_k_ppm[0];
    assert!(
        (h.difference - 200.0).abs() <= h.u,
        "{} ± {}",
        h.difference,
        h.u
    );
    assert!(
        h.difference > h.u,
        "the step is not told from zero: {} ± {}",
        h.difference,
        h.u
    );
    assert_eq!(doc.catalog.hysteresis_k_ppm, Some(h.difference));
}

#[test]
fn the_catalog_member_has_exactly_the_contract_s_keys() {
    let g = Gyro {
        k25: 0.01,
        alpha_ppm: 10.0,
        k0_25: 0.001,
        beta_v_per_c: 1e-6,
        hysteresis_ppm_after_cold: 0.0,
    };
    let input = series(&g, &[25.0, 60.0], 5, false);
    let doc = analyse_input(&input, &ls_only(), "synthetic").expect("analysis");
    let v = serde_json::to_value(&doc).expect("json");
    let c = v["catalog"].as_object().expect("catalog");
    let mut keys: Vec<&str> = c.keys().map(String::as_str).collect();
    keys.sort_unstable();
    assert_eq!(
        keys,
        [
            "bias_model_order",
            "bias_tempco_dph_per_c",
            "hysteresis_bias_dph",
            "hysteresis_k_ppm",
            "k_model_order",
            "k_tempco_ppm_per_c",
            "points",
            "t_max_c",
            "t_min_c",
            "u_bias_tempco_dph_per_c",
            "u_k_tempco_ppm_per_c",
        ]
    );
    assert!(c["hysteresis_k_ppm"].is_null());
    let p = c["points"][0].as_object().expect("point");
    let mut keys: Vec<&str> = p.keys().map(String::as_str).collect();
    keys.sort_unstable();
    assert_eq!(
        keys,
        [
            "bias_dph",
            "k",
            "nonlinearity_ppm",
            "series_point",
            "setpoint_c",
            "temp_max_c",
            "temp_mean_c",
            "temp_min_c",
            "u_bias_dph",
            "u_k",
        ]
    );
    let back: SeriesDocument = serde_json::from_value(v).expect("round trip");
    assert_eq!(back, doc);
}

#[test]
fn a_series_without_points_or_with_a_garbled_temperature_is_a_plain_error() {
    let empty = SeriesInput {
        points: Vec::new(),
        uncertainty: Default::default(),
        limits: Default::default(),
    };
    let e = analyse_input(&empty, &ls_only(), "run-x").expect_err("empty");
    assert!(e.to_string().contains("run-x"), "{e}");
    let g = Gyro {
        k25: 0.01,
        alpha_ppm: 10.0,
        k0_25: 0.0,
        beta_v_per_c: 0.0,
        hysteresis_ppm_after_cold: 0.0,
    };
    let mut input = series(&g, &[25.0, 60.0], 1, false);
    input.points[1].temp_mean_c = f64::NAN;
    let e = analyse_input(&input, &ls_only(), "run-x").expect_err("nan");
    assert!(e.to_string().contains("series point 1"), "{e}");
    assert_eq!(e.kind(), crate::ErrorKind::Input);
}

#[test]
fn a_bias_record_without_a_sweep_says_why_it_has_no_rate() {
    let g = Gyro {
        k25: 0.01,
        alpha_ppm: 10.0,
        k0_25: 0.002,
        beta_v_per_c: 0.0,
        hysteresis_ppm_after_cold: 0.0,
    };
    let mut input = series(&g, &[25.0, 60.0], 2, true);
    for p in &mut input.points {
        p.sweep = None;
    }
    let doc = analyse_input(&input, &ls_only(), "r").expect("analysis");
    assert!(doc.points[0].bias_dph.is_none());
    assert!(
        doc.points[0].notes[0].contains("no scale factor"),
        "{:?}",
        doc.points[0].notes
    );
    assert!(doc.k_tempco_ppm_per_c.is_none());
    assert_eq!(doc.acceptance[0].verdict, "indeterminate");
    assert_eq!(doc.verdict.as_deref(), Some("indeterminate"));
}

/// The whole pipeline (each temperature's sweep fitted by gyrocal-fit, its U from the budget,
/// the bias records turned into °/h, the models in temperature) over many seeds: the stated U
/// of both sensitivities covers the simulated gyro's truth about 95 % of the time. (Before K
/// was weighted by its prior U and the parabola needed four temperatures, this measured 91 %
/// for K: see `SeriesPoint::u_k_weight` and `tempco::QUADRATIC_MIN_TEMPERATURES`.)
#[test]
fn monte_carlo_the_series_sensitivities_cover_the_truth_about_95_percent() {
    let g = ISSUE_GYRO;
    let rate = |t: f64| {
        (g.k0_25 + g.beta_v_per_c * (t - 25.0)) / (g.k25 * (1.0 + g.alpha_ppm * 1e-6 * (t - 25.0)))
            * 3600.0
    };
    let runs = 800;
    let (mut k_in, mut b_in) = (0, 0);
    for seed in 0..runs {
        let input = series(&g, &[25.0, -20.0, 60.0, 25.0], 50_000 + seed, true);
        let doc = analyse_input(&input, &ls_only(), "mc").expect("analysis");
        // ppm/°C relative to K at 25 °C: exactly α for this gyro
        let k = doc.k_tempco_ppm_per_c.as_ref().expect("K");
        k_in += usize::from((k.value - g.alpha_ppm).abs() <= k.u);
        let b = doc.bias_tempco_dph_per_c.as_ref().expect("bias");
        let mid = doc.bias_model.as_ref().expect("model").chosen().t_mid_c;
        let b_true = rate(mid + 0.5) - rate(mid - 0.5);
        b_in += usize::from((b.value - b_true).abs() <= b.u);
    }
    let pct = |c: usize| 100.0 * c as f64 / runs as f64;
    eprintln!(
        "series pipeline coverage over {runs} seeds: K tempco {:.1} %, bias tempco {:.1} %",
        pct(k_in),
        pct(b_in)
    );
    // 800 runs: one standard error of a 95 % coverage is 0.8 %
    assert!((92.5..=97.5).contains(&pct(k_in)), "K: {:.1} %", pct(k_in));
    assert!((92.5..=97.5).contains(&pct(b_in)), "bias: {:.1} %", pct(b_in));
}

#[test]
fn sweeps_of_two_rates_say_that_k_has_no_u_not_that_temperatures_are_missing() {
    let g = ISSUE_GYRO;
    let mut input = series(&g, &[25.0, -20.0, 60.0, 25.0], 5, false);
    // each sweep at two rates only: the line through them has no residual
    for p in &mut input.points {
        if let Some(sweep) = &mut p.sweep {
            sweep
                .points
                .retain(|pt| pt.rate_dps == 20.0 || pt.rate_dps == -20.0);
        }
    }
    let doc = analyse_input(&input, &ls_only(), "two-rates").expect("analysis");
    // K is there at every temperature, its U is not: no tempco
    assert!(
        doc.points.iter().all(|p| p.k.is_some() && p.u_k.is_none()),
        "{:#?} {:?}",
        doc.points,
        doc.notes
    );
    assert!(doc.k_tempco_ppm_per_c.is_none());
    let note = doc
        .notes
        .iter()
        .find(|n| n.starts_with("no model of K"))
        .expect("a note on K's model");
    assert!(
        note.contains("4 of 4 temperatures have K without an uncertainty")
            && note.contains("at least 3 distinct rates"),
        "{note}"
    );
    assert!(
        !doc.notes.iter().any(|n| n.contains("(0 given)")),
        "{:?}",
        doc.notes
    );
    // each point says why its K has no U (never a U of zero)
    assert!(
        doc.points[0]
            .notes
            .iter()
            .any(|n| n.contains("a sweep of 2 distinct rates")),
        "{:?}",
        doc.points[0].notes
    );
}

#[test]
fn check_warns_of_a_series_whose_sweeps_have_fewer_than_three_rates() {
    use crate::KindAnalysis;
    let plan_with = |rates: &str| {
        let text = format!(
            "[plan]\nkind = \"temperature_series\"\nname = \"s\"\nrates_dps = {rates}\n\
             samples_per_rate = 20\nsettle_s = 0\n\
             [table]\ndialect = \"acl\"\nport = \"/dev/ttyUSB1\"\nmax_rate_dps = 20\nacceleration_dps2 = 10\n\
             [dmm]\nport = \"/dev/ttyUSB0\"\nrange_v = 10\nnplc = 1\nautozero = false\nline_hz = 50\n\
             [series]\ntemperatures_c = [25, -20, 60, 25]\nmeasure = \"sweep\"\n\
             [chamber]\nmodel = \"watlow_f4\"\nport = \"/dev/ttyUSB2\"\n"
        );
        gyrocal_files::Plan::from_toml_str(&text, std::path::Path::new("two.toml"))
            .expect("plan")
    };
    let path = std::path::Path::new("two.toml");
    let w = Kind::plan_warnings(&plan_with("[10, -10]"), path);
    assert!(
        w.iter().any(|l| l.starts_with("two.toml: [plan] rates_dps has 2 distinct rates")
            && l.contains("at least 3 rates per sweep")),
        "{w:?}"
    );
    let w = Kind::plan_warnings(&plan_with("[0, 10, -10]"), path);
    assert!(!w.iter().any(|l| l.contains("rates_dps")), "{w:?}");
}
