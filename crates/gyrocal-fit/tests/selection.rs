//! Model choice by nested F-tests: how often it picks a bigger model than the truth, and what
//! it picks on paper-like quadratic data (against the old smallest-residual-standard-error
//! rule).

// Helpers outside #[test] functions may unwrap too: a panic there is a failed test.
#![allow(clippy::unwrap_used)]

use gyrocal_fit::{
    Analysis, Dataset, MODEL_SELECTION_LEVEL, Method, Model, Options, Point, analyze,
};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};

const RATES: [f64; 19] = [
    -20.0, -15.0, -10.0, -7.0, -3.0, -1.0, -0.7, -0.3, -0.1, 0.0, 0.1, 0.3, 0.7, 1.0, 3.0, 7.0,
    10.0, 15.0, 20.0,
];

/// Vertical Earth rate at 45° latitude, °/s (the simulator's default bench).
const EARTH_DPS: f64 = 15.041 / 3600.0 * std::f64::consts::FRAC_1_SQRT_2;

fn ls_only() -> Options {
    Options {
        methods: vec![Method::LeastSquares],
        surface_size: 0,
        ..Options::default()
    }
}

/// `D = K0 + K1·(ω + Ω_E) + K2·(ω + Ω_E)²` plus white noise of `sigma` V on each rate's mean.
fn simulate(seed: u64, k: [f64; 3], sigma: f64) -> Dataset {
    let mut rng = StdRng::seed_from_u64(seed);
    let noise = Normal::new(0.0, sigma).unwrap();
    Dataset::from_pairs(RATES.iter().map(|&w| {
        let x = w + EARTH_DPS;
        (w, k[0] + k[1] * x + k[2] * x * x + noise.sample(&mut rng))
    }))
}

/// The rule `best_model` used before: the smallest residual standard error.
fn smallest_rse(a: &Analysis) -> Model {
    a.fits
        .iter()
        .filter(|f| f.method == Method::LeastSquares)
        .filter_map(|f| f.residual_std_error.map(|s| (s, f.model)))
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .unwrap()
        .1
}

#[test]
fn on_linear_truth_a_bigger_model_is_chosen_about_as_often_as_the_level() {
    let seeds = 1000;
    let (mut f_test, mut old) = (0, 0);
    for seed in 0..seeds {
        let a = analyze(&simulate(seed, [0.0088, 0.3612, 0.0], 2e-5), &ls_only()).unwrap();
        let s = a.model_selection.as_ref().unwrap();
        assert_eq!(a.best_model, Some(s.chosen));
        assert_eq!(s.level, MODEL_SELECTION_LEVEL);
        assert_eq!(s.tests[0].reduced, Model::Linear);
        assert_eq!(s.tests[0].full, Model::Quadratic);
        assert_eq!((s.tests[0].df1, s.tests[0].df2), (1, 16));
        if s.chosen != Model::Linear {
            f_test += 1;
        }
        if smallest_rse(&a) != Model::Linear {
            old += 1;
        }
    }
    let rate = f_test as f64 / seeds as f64;
    let old_rate = old as f64 / seeds as f64;
    eprintln!(
        "false-positive rate over {seeds} seeds: F-test {rate:.3}, smallest RSE {old_rate:.3}"
    );
    assert!(
        (0.02..=0.09).contains(&rate),
        "F-test false positives {rate}"
    );
    // The old rule takes a step whenever F > 1: roughly a third of the time at the first step
    // alone, half of all runs in the chain.
    assert!(old_rate > 0.3, "smallest RSE false positives {old_rate}");
}

#[test]
fn on_paper_like_quadratic_truth_quadratic_is_chosen() {
    // The simulator's default gyro (K0 0.0088 V, K 0.3612 V/(°/s), Earth rate at 45°) with
    // K2 = 2e-5 V/(°/s)² and the mean of 500 readings of 0.2 s each at 2e-4 V/√Hz:
    // σ ≈ 2e-5 V per rate.
    let seeds = 400;
    let (mut quadratic, mut cubic_old) = (0, 0);
    for seed in 0..seeds {
        let a = analyze(&simulate(seed, [0.0088, 0.3612, 2e-5], 2e-5), &ls_only()).unwrap();
        let s = a.model_selection.as_ref().unwrap();
        assert_ne!(s.chosen, Model::Linear, "seed {seed}");
        let step1 = &s.tests[0];
        assert!(
            step1.significant && step1.f.unwrap() > 1e4,
            "seed {seed}: {step1:?}"
        );
        // The second step's F is the squared t of K3 (one extra coefficient).
        let cubic = a.fit(Method::LeastSquares, Model::Cubic).unwrap();
        let t3 = cubic.coefficients.k3.unwrap() / cubic.std_errors.k3.unwrap();
        let f2 = s.tests[1].f.unwrap();
        assert!(
            (f2 - t3 * t3).abs() <= 1e-6 * f2.max(1.0),
            "F {f2} vs t² {}",
            t3 * t3
        );
        if seed == 0 {
            eprintln!("{}", serde_json_pretty(s));
        }
        if s.chosen == Model::Quadratic {
            quadratic += 1;
        }
        if smallest_rse(&a) == Model::Cubic {
            cubic_old += 1;
            // Where the old rule took the cubic for a K3 under 2σ, the F-test keeps quadratic.
            if t3.abs() < 1.9 {
                assert_eq!(s.chosen, Model::Quadratic, "seed {seed}: t3 {t3}");
            }
        }
    }
    let share = quadratic as f64 / seeds as f64;
    eprintln!(
        "quadratic truth, {seeds} seeds: F-test chose quadratic {share:.3}; smallest RSE chose cubic {:.3}",
        cubic_old as f64 / seeds as f64
    );
    assert!(share >= 0.9, "quadratic chosen in {share}");
    assert!(cubic_old as f64 / seeds as f64 > 0.2);
}

fn serde_json_pretty<T: serde::Serialize>(v: &T) -> String {
    serde_json::to_string_pretty(v).unwrap()
}

#[test]
fn exact_data_and_no_degrees_of_freedom_give_notes_not_nan() {
    // Noise-free quadratic: the quadratic fit is exact to rounding, the cubic adds nothing.
    let exact = Dataset::from_pairs(RATES.iter().map(|&w| (w, 0.01 + 0.36 * w + 2e-5 * w * w)));
    let a = analyze(&exact, &ls_only()).unwrap();
    let s = a.model_selection.as_ref().unwrap();
    assert_eq!(s.chosen, Model::Quadratic, "{s:?}");
    assert!(s.tests[0].significant && s.tests[0].note.is_some());
    assert!(!s.tests[1].significant && s.tests[1].note.is_some());
    // serde_json writes NaN as null: the selection has no null.
    let json = serde_json::to_string(&a.model_selection).unwrap();
    assert!(!json.contains("null"), "{json}");

    // Four points of a clear bowl: the quadratic step is significant even on one degree of
    // freedom, and the cubic leaves none.
    let four = Dataset {
        source: None,
        points: [(-10.0, -3.49), (0.0, 0.01), (5.0, 1.8351), (10.0, 3.71)]
            .iter()
            .map(|&(w, d)| Point::new(w, d))
            .collect(),
    };
    let a = analyze(&four, &ls_only()).unwrap();
    let s = a.model_selection.as_ref().unwrap();
    let last = s.tests.last().unwrap();
    assert_eq!(last.full, Model::Cubic);
    assert_eq!(last.df2, 0);
    assert!(!last.significant && last.f.is_none() && last.note.is_some());
    assert_eq!(a.best_model, Some(Model::Quadratic));
    // The split model is fitted but is no candidate, and the note says so.
    assert!(s.note.as_deref().unwrap().contains("split"));
    // serde_json writes NaN as null: the selection has no null.
    let json = serde_json::to_string(&a.model_selection).unwrap();
    assert!(!json.contains("null"), "{json}");
}

#[test]
fn selection_round_trips_and_old_documents_still_read() {
    let a = analyze(&simulate(3, [0.0088, 0.3612, 2e-5], 2e-5), &ls_only()).unwrap();
    let v = serde_json::to_value(&a).unwrap();
    assert_eq!(v["model_selection"]["method"], "nested F-test");
    assert_eq!(v["model_selection"]["level"], 0.05);
    assert_eq!(v["model_selection"]["tests"][0]["reduced"], "linear");
    assert_eq!(v["best_model"], v["model_selection"]["chosen"]);
    let back: Analysis = serde_json::from_value(v.clone()).unwrap();
    assert_eq!(back, a);
    let mut old = v;
    old.as_object_mut().unwrap().remove("model_selection");
    let back: Analysis = serde_json::from_value(old).unwrap();
    assert!(back.model_selection.is_none());
}

#[test]
fn with_the_simulators_bias_walk_the_f_test_still_mostly_keeps_quadratic() {
    // The simulator's default bias random walk (1e-6 V/√s) over 120 s a rate, rates applied
    // in increasing order: the walk is a smooth function of the rate, which the cubic term
    // partly absorbs. The residuals are then not independent, so the F-test's level no longer
    // holds exactly, but it still keeps the quadratic far more often than the old rule.
    let seeds = 400;
    let (mut cubic, mut cubic_old) = (0, 0);
    for seed in 0..seeds {
        let mut rng = StdRng::seed_from_u64(seed);
        let white = Normal::new(0.0, 2e-5).unwrap();
        let step = Normal::new(0.0, 1e-6 * 120.0_f64.sqrt()).unwrap();
        let mut walk = 0.0;
        let data = Dataset::from_pairs(RATES.iter().map(|&w| {
            walk += step.sample(&mut rng);
            let x = w + EARTH_DPS;
            (
                w,
                0.0088 + 0.3612 * x + 2e-5 * x * x + walk + white.sample(&mut rng),
            )
        }));
        let a = analyze(&data, &ls_only()).unwrap();
        assert_ne!(a.best_model, Some(Model::Linear));
        if a.best_model == Some(Model::Cubic) {
            cubic += 1;
        }
        if smallest_rse(&a) == Model::Cubic {
            cubic_old += 1;
        }
    }
    let (share, old) = (cubic as f64 / seeds as f64, cubic_old as f64 / seeds as f64);
    eprintln!(
        "bias walk, {seeds} seeds: cubic chosen by the F-test {share:.3}, by smallest RSE {old:.3}"
    );
    assert!(share < 0.2, "F-test cubic {share}");
    assert!(old > 2.0 * share, "old rule cubic {old}");
}
