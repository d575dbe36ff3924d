//! Behaviour of the fitting crate as a user of its results would notice it.

// Helpers outside #[test] functions may unwrap too: a panic there is a failed test.
#![allow(clippy::unwrap_used)]

use gyrocal_fit::input::{InputError, parse_csv};
use gyrocal_fit::{
    Analysis, Dataset, FitError, Method, Model, NeuronOptions, NeuronStatus, Options, Point,
    Weighting, analyze, analyze_many, fit_least_squares, fit_neuron, repeatability_ppm,
};
use proptest::prelude::*;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};

const PAPER_CSV: &str = include_str!("../../../tests/data/paper-shaped.csv");
const RATES: [f64; 19] = [
    -20.0, -15.0, -10.0, -7.0, -3.0, -1.0, -0.7, -0.3, -0.1, 0.0, 0.1, 0.3, 0.7, 1.0, 3.0, 7.0,
    10.0, 15.0, 20.0,
];

fn paper() -> Dataset {
    parse_csv(PAPER_CSV.as_bytes(), "paper-shaped.csv").unwrap()
}

fn poly(k: [f64; 4]) -> Dataset {
    Dataset::from_pairs(
        RATES
            .iter()
            .map(|&w| (w, k[0] + w * (k[1] + w * (k[2] + w * k[3])))),
    )
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

#[test]
fn noise_free_polynomials_are_recovered_exactly() {
    let truth = [0.0088, 0.3612, 2e-6, -3e-8];
    for (model, k) in [
        (Model::Linear, [truth[0], truth[1], 0.0, 0.0]),
        (Model::Quadratic, [truth[0], truth[1], truth[2], 0.0]),
        (Model::Cubic, truth),
    ] {
        let fit = fit_least_squares(&poly(k), model, Weighting::Auto).unwrap();
        let got = fit.coefficients.polynomial();
        for j in 0..model.coefficient_count() {
            assert!(
                (got[j] - k[j]).abs() <= 1e-12 * k[j].abs().max(1e-3),
                "{model} k{j}: {got:?}"
            );
        }
        assert!(fit.sse < 1e-24, "{model}: sse {}", fit.sse);
        assert!(fit.max_abs_residual < 1e-12);
    }
}

#[test]
fn noise_free_split_lines_are_recovered_exactly() {
    let (k0, kp, kn) = (0.0088, 0.3615, 0.3609);
    let data = Dataset::from_pairs(
        RATES
            .iter()
            .map(|&w| (w, k0 + if w >= 0.0 { kp * w } else { kn * w })),
    );
    let fit = fit_least_squares(&data, Model::Split, Weighting::Auto).unwrap();
    let c = fit.coefficients;
    assert!(rel(c.k_pos.unwrap(), kp) < 1e-12);
    assert!(rel(c.k_neg.unwrap(), kn) < 1e-12);
    assert!(rel(c.k0.unwrap(), k0) < 1e-10);
    assert!(rel(fit.scale_factor, (kp + kn) / 2.0) < 1e-12);
    assert!(fit.max_abs_residual < 1e-12);
    // The metrics see the same asymmetry.
    let a = analyze(&data, &Options::default()).unwrap();
    let expected = (kp - kn) / ((kp + kn) / 2.0) * 1e6;
    assert!((a.metrics.asymmetry_ppm.unwrap() - expected).abs() < 1e-3);
}

#[test]
fn noisy_fits_recover_the_truth_within_three_standard_errors() {
    let truth = [0.0088, 0.3612, 2e-6, -3e-8];
    let noise = Normal::new(0.0, 2e-5).unwrap();
    for (seed, model) in [
        (1_u64, Model::Linear),
        (2, Model::Quadratic),
        (3, Model::Cubic),
    ] {
        let mut k = [0.0; 4];
        k[..=model.degree()].copy_from_slice(&truth[..=model.degree()]);
        let mut rng = StdRng::seed_from_u64(seed);
        let mut data = poly(k);
        for p in &mut data.points {
            p.volts += noise.sample(&mut rng);
        }
        let fit = fit_least_squares(&data, model, Weighting::Auto).unwrap();
        let got = fit.coefficients.polynomial();
        let se = fit.std_errors.polynomial();
        for j in 0..model.coefficient_count() {
            assert!(se[j] > 0.0, "{model} k{j} has no standard error");
            assert!(
                (got[j] - k[j]).abs() <= 3.0 * se[j],
                "{model} k{j}: {} vs {} ± {}",
                got[j],
                k[j],
                se[j]
            );
        }
        // The standard errors are of the right size: the line's K uncertainty for σ = 2e-5 V is
        // σ/sqrt(Σω²) ≈ 7e-7; a factor 2 either way would be a wrong formula.
        if model == Model::Linear {
            let expected = 2e-5 / RATES.iter().map(|w| w * w).sum::<f64>().sqrt();
            let ratio = se[1] / expected;
            assert!(
                (0.5..2.0).contains(&ratio),
                "se(K) {} vs {}",
                se[1],
                expected
            );
        }
    }
}

#[test]
fn weights_follow_volts_std_and_n() {
    // One wild point with a huge σ barely moves the weighted line but moves the unweighted one.
    let mut data = poly([0.0088, 0.3612, 0.0, 0.0]);
    for p in &mut data.points {
        p.volts_std = Some(1e-3);
        p.n = Some(100);
    }
    data.points[0].volts += 0.1;
    data.points[0].volts_std = Some(1e3);
    let weighted = fit_least_squares(&data, Model::Linear, Weighting::Auto).unwrap();
    let unweighted = fit_least_squares(&data, Model::Linear, Weighting::Unweighted).unwrap();
    assert!(weighted.weighted && !unweighted.weighted);
    assert!(rel(weighted.scale_factor, 0.3612) < 1e-9);
    assert!(rel(unweighted.scale_factor, 0.3612) > 1e-4);
    assert_eq!(data.points[1].sigma(), Some(1e-4));
}

#[test]
fn neuron_reaches_least_squares_on_paper_data_with_defaults() {
    let data = paper();
    let ls = fit_least_squares(&data, Model::Linear, Weighting::Auto).unwrap();
    let nn = fit_neuron(&data, &NeuronOptions::default(), Weighting::Auto).unwrap();
    assert!(nn.converged);
    assert_eq!(nn.neuron.as_ref().unwrap().status, NeuronStatus::Converged);
    assert!(
        rel(nn.scale_factor, ls.scale_factor) < 1e-6,
        "K {} vs {}",
        nn.scale_factor,
        ls.scale_factor
    );
    assert!(
        rel(nn.bias, ls.bias) < 1e-6,
        "K0 {} vs {}",
        nn.bias,
        ls.bias
    );
    // Its SSE can't be below the least-squares minimum (beyond rounding).
    assert!(nn.sse >= ls.sse * (1.0 - 1e-9));
    // Every pass error is recorded, finite, and ends at the least-squares SSE.
    let trace = nn.neuron.unwrap();
    assert_eq!(trace.pass_errors.len() as u64, nn.passes.unwrap());
    assert!(trace.pass_errors.iter().all(|e| e.is_finite()));
    assert!(rel(*trace.pass_errors.last().unwrap(), ls.sse) < 1e-6);
    assert!(
        trace.pass_errors[0] > 10.0 * ls.sse,
        "the first pass starts far from the minimum"
    );
}

#[test]
fn neuron_unweighted_also_reaches_unweighted_least_squares() {
    let data = paper();
    let ls = fit_least_squares(&data, Model::Linear, Weighting::Unweighted).unwrap();
    let nn = fit_neuron(&data, &NeuronOptions::default(), Weighting::Unweighted).unwrap();
    assert!(rel(nn.scale_factor, ls.scale_factor) < 1e-6);
    assert!(rel(nn.bias, ls.bias) < 1e-6);
}

#[test]
fn online_only_neuron_stops_near_but_not_at_the_minimum() {
    let data = paper();
    let ls = fit_least_squares(&data, Model::Linear, Weighting::Unweighted).unwrap();
    let opts = NeuronOptions {
        batch_finish: false,
        eta_decay_passes: 0.0,
        ..NeuronOptions::default()
    };
    let nn = fit_neuron(&data, &opts, Weighting::Unweighted).unwrap();
    assert!(
        nn.sse > ls.sse,
        "a fixed-step online neuron can't beat least squares"
    );
    assert!(
        rel(nn.bias, ls.bias) > 1e-6,
        "fixed-step online updates should end off the minimum"
    );
}

#[test]
fn huge_learning_rate_is_reported_as_divergence() {
    let data = paper();
    let opts = NeuronOptions {
        eta: 100.0,
        ..NeuronOptions::default()
    };
    let nn = fit_neuron(&data, &opts, Weighting::Auto).unwrap();
    assert!(!nn.converged);
    assert!(matches!(
        nn.neuron.as_ref().unwrap().status,
        NeuronStatus::Diverged { .. }
    ));
    assert!(nn.scale_factor.is_finite() && nn.bias.is_finite() && nn.sse.is_finite());
    let json = serde_json::to_string(&nn).unwrap();
    assert!(!json.contains("null") && !json.contains("NaN"), "{json}");
    assert!(json.contains("\"status\":\"diverged\""), "{json}");
}

#[test]
fn too_few_passes_is_reported_as_not_converged() {
    let opts = NeuronOptions {
        max_passes: 5,
        ..NeuronOptions::default()
    };
    let nn = fit_neuron(&paper(), &opts, Weighting::Auto).unwrap();
    assert!(!nn.converged);
    assert_eq!(nn.neuron.unwrap().status, NeuronStatus::MaxPasses);
    assert_eq!(nn.passes, Some(5));
}

#[test]
fn analysis_document_has_the_issue_shape_and_round_trips() {
    let a = analyze(&paper(), &Options::default()).unwrap();
    assert_eq!(a.points, 19);
    assert_eq!(a.fits.len(), 5, "4 least-squares models + the neuron");
    let v = serde_json::to_value(&a).unwrap();
    assert_eq!(v["points"], 19);
    let ls = &v["fits"][0];
    assert_eq!(ls["method"], "least-squares");
    assert_eq!(ls["model"], "linear");
    for key in [
        "scale_factor",
        "bias",
        "sse",
        "rms_residual",
        "max_abs_residual",
        "r_squared",
    ] {
        assert!(ls[key].is_number(), "{key}");
    }
    assert!(ls["coefficients"]["k1"].is_number() && ls["std_errors"]["k0"].is_number());
    assert!(
        ls["coefficients"].get("k2").is_none(),
        "keys that do not apply are omitted"
    );
    assert_eq!(ls["converged"], true);
    let r0 = &ls["residuals"][0];
    for key in ["rate_dps", "volts", "fitted", "residual"] {
        assert!(r0[key].is_number(), "{key}");
    }
    let nn = &v["fits"][4];
    assert_eq!(nn["method"], "neuron");
    assert!(nn["passes"].as_u64().unwrap() > 0);
    let m = &v["metrics"];
    for key in [
        "nonlinearity_ppm",
        "asymmetry_ppm",
        "scale_factor_positive",
        "scale_factor_negative",
        "bias_dps",
        "bias_dph",
    ] {
        assert!(m[key].is_number(), "{key}");
    }
    assert!(m["repeatability_ppm"].is_null());
    assert!(
        m["nonlinearity_normalisation"]
            .as_str()
            .unwrap()
            .contains("max_j |F_j|")
    );
    let back: Analysis = serde_json::from_value(v).unwrap();
    assert_eq!(back, a);
}

#[test]
fn paper_pattern_is_captured_by_the_quadratic_model() {
    let a = analyze(&paper(), &Options::default()).unwrap();
    let lin = a.fit(Method::LeastSquares, Model::Linear).unwrap();
    let quad = a.fit(Method::LeastSquares, Model::Quadratic).unwrap();
    // Linear residuals: positive at both ends, negative in the middle.
    let r = &lin.residuals;
    assert!(r[0].residual > 0.0 && r[18].residual > 0.0 && r[9].residual < 0.0);
    assert!(quad.sse < lin.sse / 50.0);
    assert!(rel(quad.coefficients.k2.unwrap(), 2e-6) < 0.1);
    assert_ne!(a.best_model, Some(Model::Linear));
    // Nonlinearity from its definition.
    let fm = r.iter().map(|p| p.volts.abs()).fold(0.0, f64::max);
    let expected = r.iter().map(|p| p.residual.abs()).fold(0.0, f64::max) / fm * 1e6;
    assert!((a.metrics.nonlinearity_ppm - expected).abs() < 1e-9);
    assert!((a.metrics.bias_dph - a.metrics.bias_dps * 3600.0).abs() < 1e-9);
    assert!(rel(a.metrics.bias_dps, lin.bias / lin.scale_factor) < 1e-12);
}

#[test]
fn error_surface_is_lowest_at_the_least_squares_optimum() {
    let a = analyze(
        &paper(),
        &Options {
            surface_size: 21,
            ..Options::default()
        },
    )
    .unwrap();
    let s = a.error_surface.unwrap();
    assert_eq!((s.weights.len(), s.thresholds.len()), (21, 21));
    assert_eq!(s.sse.len(), 21);
    let min = s
        .sse
        .iter()
        .flatten()
        .cloned()
        .fold(f64::INFINITY, f64::min);
    assert_eq!(min, s.sse[10][10]);
    assert!(s.sse[0][0] > 100.0 * min);
}

#[test]
fn compensation_inverts_every_model() {
    let a = analyze(&paper(), &Options::default()).unwrap();
    for f in &a.fits {
        for w in [-19.0, -2.5, -0.05, 0.0, 0.2, 12.0] {
            let d = f.predict(w);
            let back = f.compensate(d).unwrap();
            assert!(
                (back - w).abs() < 1e-9,
                "{} {}: {w} -> {d} -> {back}",
                f.method,
                f.model
            );
        }
    }
    let lin = a.fit(Method::LeastSquares, Model::Linear).unwrap();
    let d = 1.234;
    assert!((lin.compensate(d).unwrap() - (d - lin.bias) / lin.scale_factor).abs() < 1e-12);
}

#[test]
fn repeatability_over_several_data_sets() {
    assert_eq!(repeatability_ppm(&[0.3612]), None);
    let r = repeatability_ppm(&[0.3611, 0.3612, 0.3613]).unwrap();
    assert!((r - 1e-4 / 0.3612 * 1e6).abs() < 1e-6, "{r}");
    let sets: Vec<Dataset> = [0.3611, 0.3613]
        .iter()
        .map(|&k| poly([0.0088, k, 0.0, 0.0]))
        .collect();
    let m = analyze_many(&sets, &Options::default()).unwrap();
    let expected = (2e-4 / 2f64.sqrt()) / 0.3612 * 1e6;
    assert!((m.repeatability_ppm.unwrap() - expected).abs() < 1e-3);
    assert_eq!(m.files[0].metrics.repeatability_ppm, m.repeatability_ppm);
}

#[test]
fn data_that_cannot_determine_a_model_is_an_error() {
    let two = Dataset::from_pairs([(0.0, 0.0), (1.0, 0.36)]);
    assert!(matches!(
        fit_least_squares(&two, Model::Quadratic, Weighting::Auto),
        Err(FitError::RankDeficient {
            needed: 3,
            distinct: 2,
            ..
        })
    ));
    let same = Dataset::from_pairs([(1.0, 0.36), (1.0, 0.37), (1.0, 0.35)]);
    assert!(matches!(
        analyze(&same, &Options::default()),
        Err(FitError::TooFewDistinctRates { distinct: 1 })
    ));
    let positive = Dataset::from_pairs([(0.0, 0.0), (1.0, 0.36), (2.0, 0.72)]);
    assert!(matches!(
        fit_least_squares(&positive, Model::Split, Weighting::Auto),
        Err(FitError::SplitNeedsBothSigns {
            side: "negative",
            ..
        })
    ));
    let three = Dataset::from_pairs([(-1.0, -0.36), (0.0, 0.0), (1.0, 0.36), (1.0, 0.37)]);
    assert!(matches!(
        fit_least_squares(&three, Model::Cubic, Weighting::Auto),
        Err(FitError::RankDeficient {
            needed: 4,
            distinct: 3,
            ..
        })
    ));
    let only_quadratic = Options {
        models: vec![Model::Quadratic],
        methods: vec![Method::Neuron],
        ..Options::default()
    };
    assert!(matches!(
        analyze(&paper(), &only_quadratic),
        Err(FitError::Unsupported(_))
    ));
    let mut nan = paper();
    nan.points[3] = Point::new(f64::NAN, 1.0);
    assert!(matches!(
        analyze(&nan, &Options::default()),
        Err(FitError::NonFinite { index: 3 })
    ));
}

#[test]
fn csv_columns_are_found_by_name_with_comments_and_extra_columns() {
    let csv = "# header comment\nTemp,VOLTS,n,Rate_Dps,volts_std\n25,0.0088,500,0,0.0003\n# mid\n25,0.37,,1,\n";
    let d = parse_csv(csv.as_bytes(), "x.csv").unwrap();
    assert_eq!(d.source.as_deref(), Some("x.csv"));
    assert_eq!(d.points.len(), 2);
    assert_eq!(
        d.points[0],
        Point {
            rate_dps: 0.0,
            volts: 0.0088,
            volts_std: Some(0.0003),
            n: Some(500),
            line: Some(3)
        }
    );
    assert_eq!(
        (d.points[1].volts_std, d.points[1].n, d.points[1].line),
        (None, None, Some(5))
    );
}

#[test]
fn csv_errors_name_the_source_and_line() {
    let cases: [(&str, u64, &str); 5] = [
        ("rate_dps,voltage\n0,1\n", 1, "volts"),
        ("rate_dps,volts\n0,0.1\n1,abc\n", 3, "not a number"),
        ("# c\nrate_dps,volts\n0,0.1\n1,NaN\n", 4, "finite"),
        ("rate_dps,volts\n0,0.1\ninf,0.3\n", 3, "finite"),
        ("rate_dps,volts\n0,0.1\n1,0.3,7\n", 3, "fields"),
    ];
    for (csv, line, needle) in cases {
        let e: InputError = parse_csv(csv.as_bytes(), "bad.csv").unwrap_err();
        let msg = e.to_string();
        assert_eq!(e.line(), line, "{msg}");
        assert!(msg.starts_with(&format!("bad.csv: line {line}:")), "{msg}");
        assert!(msg.contains(needle), "{msg}");
    }
    assert!(matches!(
        parse_csv("".as_bytes(), "e.csv"),
        Err(InputError::NoHeader { .. })
    ));
}

proptest! {
    #[test]
    fn linear_residuals_sum_to_zero_and_are_orthogonal_to_rate(
        pts in prop::collection::vec((-30.0_f64..30.0, -10.0_f64..10.0), 3..40),
    ) {
        let data = Dataset::from_pairs(pts.clone());
        prop_assume!(data.distinct_rates() >= 2);
        let fit = fit_least_squares(&data, Model::Linear, Weighting::Auto).unwrap();
        let scale_d = pts.iter().map(|p| p.1.abs()).fold(1.0, f64::max);
        let scale_w = pts.iter().map(|p| p.0.abs()).fold(1.0, f64::max);
        let n = pts.len() as f64;
        let sum: f64 = fit.residuals.iter().map(|r| r.residual).sum();
        let dot: f64 = fit.residuals.iter().map(|r| r.residual * r.rate_dps).sum();
        prop_assert!(sum.abs() <= 1e-10 * n * scale_d, "sum {}", sum);
        prop_assert!(dot.abs() <= 1e-10 * n * scale_d * scale_w, "dot {}", dot);
    }
}

/// A whole-turn plan's data: 60 times more readings at 0.3 °/s than at 20 °/s, so the
/// least-squares weights (n/σ²) differ by as much.
fn whole_turn_shaped() -> Dataset {
    let rates_n = [
        (0.0, 500u64),
        (0.3, 28916),
        (-0.3, 28916),
        (1.0, 8675),
        (-1.0, 8675),
        (3.0, 2892),
        (-3.0, 2892),
        (10.0, 867),
        (-10.0, 867),
        (20.0, 434),
        (-20.0, 434),
        (0.0, 500),
    ];
    let mut rng = StdRng::seed_from_u64(11);
    let noise = Normal::new(0.0, 1.0).unwrap();
    Dataset {
        source: None,
        points: rates_n
            .iter()
            .map(|&(w, n)| {
                let sigma_mean = 0.002 / (n as f64).sqrt();
                Point {
                    rate_dps: w,
                    volts: 0.0099
                        + 0.3612 * w
                        + 2.1e-5 * w * w
                        + sigma_mean * noise.sample(&mut rng),
                    volts_std: Some(0.002),
                    n: Some(n),
                    line: None,
                }
            })
            .collect(),
    }
}

#[test]
fn neuron_reaches_weighted_least_squares_on_strongly_unequal_weights() {
    let data = whole_turn_shaped();
    let ls = fit_least_squares(&data, Model::Linear, Weighting::Auto).unwrap();
    assert!(ls.weighted);
    let nn = fit_neuron(&data, &NeuronOptions::default(), Weighting::Auto).unwrap();
    assert!(nn.converged, "{:?}", nn.neuron.as_ref().map(|t| t.status));
    assert!(rel(nn.scale_factor, ls.scale_factor) < 1e-6);
    assert!(rel(nn.bias, ls.bias) < 1e-6);
    let trace = nn.neuron.unwrap();
    assert!(
        trace.batch_passes > 0,
        "the batch finish did the converging"
    );
}

#[test]
fn online_only_neuron_at_its_pass_limit_is_not_called_converged() {
    let opts = NeuronOptions {
        batch_finish: false,
        max_online_passes: 10,
        ..NeuronOptions::default()
    };
    let nn = fit_neuron(&whole_turn_shaped(), &opts, Weighting::Auto).unwrap();
    assert!(!nn.converged);
    assert_eq!(nn.neuron.unwrap().status, NeuronStatus::MaxPasses);
}

#[test]
fn models_the_data_cannot_determine_are_skipped_with_the_reason() {
    // Three rates: every model but the cubic (4 coefficients).
    let three = Dataset::from_pairs([
        (0.0, 0.0088),
        (10.0, 3.6208),
        (-10.0, -3.6032),
        (10.0, 3.6209),
    ]);
    let a = analyze(&three, &Options::default()).unwrap();
    let fitted: Vec<Model> = a
        .fits
        .iter()
        .filter(|f| f.method == Method::LeastSquares)
        .map(|f| f.model)
        .collect();
    assert_eq!(fitted, [Model::Linear, Model::Quadratic, Model::Split]);
    assert_eq!(a.skipped.len(), 1);
    assert_eq!(a.skipped[0].model, Model::Cubic);
    assert!(
        a.skipped[0].reason.contains("4 coefficients")
            && a.skipped[0].reason.contains("the data have 3"),
        "{}",
        a.skipped[0].reason
    );
    assert!(a.fit(Method::Neuron, Model::Linear).is_some());
    let v = serde_json::to_value(&a).unwrap();
    assert_eq!(v["skipped"][0]["model"], "cubic");
    assert!(v["skipped"][0]["reason"].is_string());
    let back: Analysis = serde_json::from_value(v).unwrap();
    assert_eq!(back, a);

    // One turning direction: no split model, and no asymmetry, K+ or K-, each with the reason.
    let one_way =
        Dataset::from_pairs([0.0, 1.0, 3.0, 10.0, 20.0].map(|w| (w, 0.0088 + 0.3612 * w)));
    let a = analyze(&one_way, &Options::default()).unwrap();
    assert_eq!(
        a.skipped.iter().map(|s| s.model).collect::<Vec<_>>(),
        [Model::Split]
    );
    assert!(
        a.skipped[0].reason.contains("negative side"),
        "{:?}",
        a.skipped
    );
    assert!(a.fit(Method::LeastSquares, Model::Cubic).is_some());
    let m = &a.metrics;
    assert_eq!(
        (
            m.asymmetry_ppm,
            m.scale_factor_positive,
            m.scale_factor_negative
        ),
        (None, None, None)
    );
    let missing: Vec<&str> = m.not_computed.iter().map(|n| n.metric.as_str()).collect();
    assert_eq!(
        missing,
        [
            "asymmetry_ppm",
            "scale_factor_positive",
            "scale_factor_negative",
            "asymmetry_common_k2"
        ]
    );
    assert!(m.not_computed[0].reason.contains("both turning directions"));
    let v = serde_json::to_value(&a).unwrap();
    assert!(v["metrics"]["asymmetry_ppm"].is_null());
    assert_eq!(v["metrics"]["not_computed"][0]["metric"], "asymmetry_ppm");

    // Complete data: nothing skipped, nothing missing, and the fields are there (empty).
    let a = analyze(&paper(), &Options::default()).unwrap();
    assert!(a.skipped.is_empty() && a.metrics.not_computed.is_empty());
    let v = serde_json::to_value(&a).unwrap();
    assert_eq!(v["skipped"], serde_json::json!([]));

    // A document written before the fields existed still reads.
    let mut old = v.clone();
    old.as_object_mut().unwrap().remove("skipped");
    old["metrics"]
        .as_object_mut()
        .unwrap()
        .remove("not_computed");
    let back: Analysis = serde_json::from_value(old).unwrap();
    assert!(back.skipped.is_empty());
}

#[test]
fn models_asked_for_by_name_are_an_error_when_the_data_cannot_determine_them() {
    let three = Dataset::from_pairs([
        (0.0, 0.0088),
        (10.0, 3.6208),
        (-10.0, -3.6032),
        (0.0, 0.0089),
    ]);
    let strict = Options {
        models: vec![Model::Linear, Model::Cubic],
        skip_unsupported: false,
        ..Options::default()
    };
    assert!(matches!(
        analyze(&three, &strict),
        Err(FitError::RankDeficient {
            model: Model::Cubic,
            needed: 4,
            distinct: 3
        })
    ));
    // Not even a line: an error however the options read.
    let same = Dataset::from_pairs([(1.0, 0.36), (1.0, 0.37)]);
    assert!(matches!(
        analyze(&same, &Options::default()),
        Err(FitError::TooFewDistinctRates { distinct: 1 })
    ));
}

#[test]
fn the_rule_for_a_schedule_is_the_rule_of_the_fit() {
    use gyrocal_fit::{check_rates, unsupported_models};
    let schedule = [0.0, 10.0, -10.0, 0.0, 10.0, -10.0];
    let skipped = unsupported_models(&schedule, &Model::ALL);
    assert_eq!(
        skipped.iter().map(|s| s.model).collect::<Vec<_>>(),
        [Model::Cubic]
    );
    let data = Dataset::from_pairs(schedule.map(|w| (w, 0.0088 + 0.3612 * w)));
    let a = analyze(&data, &Options::default()).unwrap();
    assert_eq!(a.skipped, skipped);
    assert!(check_rates(&[0.0, 1.0, 2.0, 3.0], Model::Split).is_err());
    assert!(check_rates(&[0.0, 1.0, -1.0, 2.0, -2.0], Model::Split).is_ok());
}

#[test]
fn csv_with_a_duplicated_column_names_both_positions() {
    let e = parse_csv(
        "rate_dps,volts,n,Volts\n0,0.1,1,0.2\n".as_bytes(),
        "dup.csv",
    )
    .unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.starts_with("dup.csv: line 1:") && msg.contains("columns 2 and 4"),
        "{msg}"
    );
    assert!(matches!(e, InputError::DuplicateColumn { .. }));
}

/// Valid rows without end: `1,2,` then a 1000-byte note and a newline (long rows, so the
/// 64 MiB cap is reached after some 65 000 rows, not millions).
struct EndlessRows(usize);

impl std::io::Read for EndlessRows {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        const ROW: usize = 1005;
        for b in buf.iter_mut() {
            *b = match self.0 % ROW {
                0 => b'1',
                1 | 3 => b',',
                2 => b'2',
                k if k == ROW - 1 => b'\n',
                _ => b'x',
            };
            self.0 += 1;
        }
        Ok(buf.len())
    }
}

#[test]
fn endless_input_is_refused_at_the_cap() {
    let started = std::time::Instant::now();
    // without newlines: refused at the line limit
    let e = parse_csv(std::io::repeat(b'0'), "/dev/zero").unwrap_err();
    assert!(matches!(e, InputError::LineTooLong { line: 1, .. }), "{e}");
    // valid rows without end: refused at the size limit
    let endless_rows = std::io::Read::chain(&b"rate_dps,volts,note\n"[..], EndlessRows(0));
    let e = parse_csv(endless_rows, "/dev/zero").unwrap_err();
    assert!(matches!(e, InputError::TooLarge { .. }), "{e}");
    let msg = e.to_string();
    assert!(
        msg.starts_with("/dev/zero:") && msg.contains("64 MiB"),
        "{msg}"
    );
    assert!(started.elapsed() < std::time::Duration::from_secs(20));
}

#[test]
fn blocked_qr_on_many_points_recovers_a_noise_free_cubic_and_matches_the_neuron() {
    // 20 000 points (five QR blocks), shuffled rates: the blocked factorisation is exact.
    let rates = [
        -20.0, -15.0, -7.0, -1.0, -0.3, 0.0, 0.3, 1.0, 7.0, 15.0, 20.0,
    ];
    let data = Dataset::from_pairs((0..20_000).map(|i| {
        let w = rates[(i * 7) % rates.len()];
        (w, 0.0088 + 0.3612 * w + 2e-6 * w * w - 3e-8 * w * w * w)
    }));
    let fit = fit_least_squares(&data, Model::Cubic, Weighting::Auto).unwrap();
    let c = fit.coefficients;
    assert!((c.k0.unwrap() - 0.0088).abs() < 1e-12, "{c:?}");
    assert!((c.k1.unwrap() - 0.3612).abs() < 1e-12, "{c:?}");
    assert!((c.k2.unwrap() - 2e-6).abs() < 1e-13, "{c:?}");
    assert!((c.k3.unwrap() + 3e-8).abs() < 1e-14, "{c:?}");
    // The neuron trains on the 11 rate means above 10 000 points and reaches the line.
    let noisy = Dataset::from_pairs(data.points.iter().enumerate().map(|(i, p)| {
        let noise = 1e-4 * ((i as f64 * 0.618_033_988_7).fract() - 0.5);
        (p.rate_dps, p.volts + noise)
    }));
    let ls = fit_least_squares(&noisy, Model::Linear, Weighting::Auto).unwrap();
    let nn = fit_neuron(&noisy, &NeuronOptions::default(), Weighting::Auto).unwrap();
    let t = nn.neuron.as_ref().unwrap();
    assert_eq!(
        t.training_data,
        gyrocal_fit::TrainingData::RateMeans {
            rates: 11,
            points: 20_000
        }
    );
    assert!(nn.converged);
    assert!(
        (nn.sse - ls.sse).abs() <= 1e-9 * ls.sse,
        "{} {}",
        nn.sse,
        ls.sse
    );
    assert!((nn.scale_factor - ls.scale_factor).abs() <= 1e-9 * ls.scale_factor);
    // The last pass error (from the sufficient statistics) is the fit's SSE.
    let last = *t.pass_errors.last().unwrap();
    assert!((last - nn.sse).abs() <= 1e-9 * nn.sse, "{last} {}", nn.sse);
}
