//! The joint-fit asymmetry (`K0 + K+·ω⁺ + K−·ω⁻ + K2·ω²`) is unbiased where the GJB
//! separate-lines asymmetry absorbs the even-order term.

// Helpers outside #[test] functions may unwrap too: a panic there is a failed test.
#![allow(clippy::unwrap_used)]

use gyrocal_fit::{ASYMMETRY_COMMON_K2_MODEL, Dataset, Metrics, Weighting};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};

const RATES: [f64; 19] = [
    -20.0, -15.0, -10.0, -7.0, -3.0, -1.0, -0.7, -0.3, -0.1, 0.0, 0.1, 0.3, 0.7, 1.0, 3.0, 7.0,
    10.0, 15.0, 20.0,
];
const K: f64 = 0.3612;
const K0: f64 = 0.0088;
const K2: f64 = 2e-5;
/// K± 100 ppm apart: (K+ − K−)/((K+ + K−)/2) = 100e-6 exactly.
const K_POS: f64 = K * (1.0 + 50e-6);
const K_NEG: f64 = K * (1.0 - 50e-6);

fn simulate(seed: u64, k2: f64, sigma: f64) -> Dataset {
    let mut rng = StdRng::seed_from_u64(seed);
    let noise = Normal::new(0.0, sigma).unwrap();
    Dataset::from_pairs(RATES.iter().map(|&w| {
        let k = if w >= 0.0 { K_POS } else { K_NEG };
        (w, K0 + k * w + k2 * w * w + noise.sample(&mut rng))
    }))
}

#[test]
fn joint_fit_recovers_a_100_ppm_asymmetry_that_the_gjb_lines_miss() {
    let seeds = 3000;
    let (mut sum, mut sum_sq, mut sum_se, mut sum_gjb) = (0.0, 0.0, 0.0, 0.0);
    for seed in 0..seeds {
        let m = Metrics::compute(&simulate(seed, K2, 2e-5), Weighting::Auto).unwrap();
        let a = m.asymmetry_common_k2.as_ref().unwrap();
        assert_eq!(a.model, ASYMMETRY_COMMON_K2_MODEL);
        assert_eq!((a.points, a.degrees_of_freedom), (19, 15));
        sum += a.asymmetry_ppm;
        sum_sq += a.asymmetry_ppm * a.asymmetry_ppm;
        sum_se += a.asymmetry_std_error_ppm;
        sum_gjb += m.asymmetry_ppm.unwrap();
    }
    let n = seeds as f64;
    let mean = sum / n;
    let sd = (sum_sq / n - mean * mean).sqrt();
    let mean_se = sum_se / n;
    let gjb = sum_gjb / n;
    eprintln!(
        "joint fit over {seeds} seeds: mean asymmetry {mean:.2} ppm (truth 100), spread {sd:.2} ppm, mean reported SE {mean_se:.2} ppm; GJB separate lines: mean {gjb:.1} ppm"
    );
    assert!((mean - 100.0).abs() < 5.0, "mean {mean}");
    // The mean is within its own standard error (spread/√n) three times over.
    assert!(
        (mean - 100.0).abs() < 3.0 * sd / n.sqrt(),
        "mean {mean}, sd {sd}"
    );
    // The reported standard error matches the scatter actually seen.
    assert!(
        (mean_se / sd - 1.0).abs() < 0.1,
        "SE {mean_se} vs spread {sd}"
    );
    // The GJB lines absorb K2: about 2000 ppm reported for 100.
    assert!(gjb > 1500.0, "GJB {gjb}");
}

#[test]
fn joint_fit_is_exact_on_noise_free_data_and_its_k2_matches_the_truth() {
    let m = Metrics::compute(&simulate(0, K2, 0.0), Weighting::Auto).unwrap();
    let a = m.asymmetry_common_k2.unwrap();
    assert!((a.asymmetry_ppm - 100.0).abs() < 1e-6, "{a:?}");
    assert!((a.k2 - K2).abs() < 1e-12 && (a.k0 - K0).abs() < 1e-12);
    assert!((a.k_pos - K_POS).abs() < 1e-12 && (a.k_neg - K_NEG).abs() < 1e-12);
    assert!(a.k_pos_k_neg_correlation.abs() <= 1.0);
}

#[test]
fn one_direction_only_is_not_computed_with_the_reason() {
    let data = Dataset::from_pairs(
        [0.0, 1.0, 3.0, 7.0, 10.0, 20.0]
            .iter()
            .map(|&w| (w, K0 + K * w)),
    );
    let m = Metrics::compute(&data, Weighting::Auto).unwrap();
    assert!(m.asymmetry_common_k2.is_none());
    let nc = m
        .not_computed
        .iter()
        .find(|n| n.metric == "asymmetry_common_k2")
        .unwrap();
    assert!(
        nc.reason.contains("both turning directions"),
        "{}",
        nc.reason
    );
    // One-sided rates: K and K0 are strongly (negatively) correlated.
    assert!(m.scale_factor_bias_correlation.unwrap() < -0.5);
    let json = serde_json::to_value(&m).unwrap();
    assert!(json.get("asymmetry_common_k2").is_none());
}

#[test]
fn symmetric_rates_leave_scale_factor_and_bias_uncorrelated() {
    let m = Metrics::compute(&simulate(1, K2, 2e-5), Weighting::Auto).unwrap();
    assert!(m.scale_factor_bias_correlation.unwrap().abs() < 1e-12);
    let v = serde_json::to_value(&m).unwrap();
    for key in [
        "k0",
        "k_pos",
        "k_neg",
        "k2",
        "k0_std_error",
        "k_pos_std_error",
        "k_neg_std_error",
        "k2_std_error",
        "k_pos_k_neg_correlation",
        "asymmetry_ppm",
        "asymmetry_std_error_ppm",
        "points",
        "degrees_of_freedom",
        "model",
        "units",
    ] {
        assert!(v["asymmetry_common_k2"].get(key).is_some(), "{key}");
    }
    // Documents written before the fields existed still read.
    let mut old = v;
    let o = old.as_object_mut().unwrap();
    o.remove("asymmetry_common_k2");
    o.remove("scale_factor_bias_correlation");
    let back: Metrics = serde_json::from_value(old).unwrap();
    assert!(back.asymmetry_common_k2.is_none());
}
