//! The expanded-uncertainty budget: hand-checked figures for the 34401A on its 10 V range
//! (1 year) and a 10 ppm table, and the budget's arithmetic.

// Helpers outside #[test] functions may unwrap too: a panic there is a failed test.
#![allow(clippy::unwrap_used)]

use gyrocal_fit::uncertainty::{COVERAGE_FACTOR, Distribution, EvaluationType};
use gyrocal_fit::{
    Analysis, Dataset, MeterAccuracy, Method, Model, Options, TableRateAccuracy, Uncertainty,
    UncertaintyInputs, analyze,
};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution as _, Normal};

const RATES: [f64; 19] = [
    -20.0, -15.0, -10.0, -7.0, -3.0, -1.0, -0.7, -0.3, -0.1, 0.0, 0.1, 0.3, 0.7, 1.0, 3.0, 7.0,
    10.0, 15.0, 20.0,
];

fn ls_only() -> Options {
    Options {
        methods: vec![Method::LeastSquares],
        surface_size: 0,
        ..Options::default()
    }
}

fn inputs() -> UncertaintyInputs {
    UncertaintyInputs {
        meter: Some(MeterAccuracy::from_percent(
            "HP 34401A 10 V range, 1 year",
            0.0035,
            0.0005,
            10.0,
        )),
        table_rate: Some(TableRateAccuracy::rectangular(
            10.0,
            Some("table datasheet"),
        )),
    }
}

fn line(k: f64, k0: f64, sigma: f64, seed: u64) -> Analysis {
    let mut rng = StdRng::seed_from_u64(seed);
    let noise = Normal::new(0.0, sigma).unwrap();
    let data = Dataset::from_pairs(
        RATES
            .iter()
            .map(|&w| (w, k0 + k * w + noise.sample(&mut rng))),
    );
    analyze(&data, &ls_only()).unwrap()
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * b.abs()
}

fn row<'a>(
    u: &'a Uncertainty,
    quantity: &str,
    source: &str,
) -> &'a gyrocal_fit::uncertainty::BudgetRow {
    u.quantity(quantity)
        .unwrap()
        .rows
        .iter()
        .find(|r| r.source.starts_with(source))
        .unwrap_or_else(|| panic!("{quantity}: no row {source}"))
}

#[test]
fn hand_checked_34401a_10v_one_year_and_10_ppm_table() {
    let mut a = line(0.05, 0.0, 0.0, 0);
    a.attach_uncertainty(&inputs());
    let u = a.uncertainty.as_ref().unwrap();
    let sqrt3 = 3.0_f64.sqrt();
    assert_eq!(u.coverage_factor, 2.0);

    // Gain 0.0035 % of reading: 35 ppm / √3 = 20.207 ppm of K.
    let gain = row(u, "scale_factor", "meter gain");
    assert_eq!(gain.kind, EvaluationType::B);
    assert_eq!(gain.distribution, Distribution::Rectangular);
    assert!(close(gain.relative_ppm.unwrap(), 35.0 / sqrt3), "{gain:?}");
    assert!(close(gain.relative_ppm.unwrap(), 20.207_259_421_636_9));
    // Table 10 ppm rectangular: 5.774 ppm of K.
    let table = row(u, "scale_factor", "table rate");
    assert!(
        close(table.relative_ppm.unwrap(), 10.0 / sqrt3),
        "{table:?}"
    );
    assert!(close(table.relative_ppm.unwrap(), 5.773_502_691_896_258));
    // Offset 0.0005 % of 10 V = 50 µV: 28.87 µV on K0, 2.078 °/h on the bias.
    let off_v = row(u, "bias_v", "meter offset");
    assert!(
        close(off_v.standard_uncertainty, 50e-6 / sqrt3),
        "{off_v:?}"
    );
    assert!(close(off_v.standard_uncertainty, 28.867_513_459_481_29e-6));
    let off_dph = row(u, "bias_dph", "meter offset");
    assert!(close(
        off_dph.standard_uncertainty,
        50e-6 / sqrt3 / 0.05 * 3600.0
    ));
    assert!(close(off_dph.standard_uncertainty, 2.078_460_969_082_652_5));
    // The offset is no error of K; the gain none of K0/K.
    assert!(
        !u.quantity("scale_factor")
            .unwrap()
            .rows
            .iter()
            .any(|r| r.source.starts_with("meter offset"))
    );
    assert_eq!(row(u, "bias_dph", "meter gain").standard_uncertainty, 0.0);

    // Every quantity: combined = RSS of its rows, expanded = 2·combined.
    for q in &u.quantities {
        let rss = q
            .rows
            .iter()
            .map(|r| r.standard_uncertainty.powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(close(q.standard_uncertainty, rss), "{q:?}");
        assert!(close(q.expanded_uncertainty, COVERAGE_FACTOR * rss));
        assert_eq!(
            a.expanded_uncertainty(&q.quantity),
            Some(q.expanded_uncertainty)
        );
    }
    // Noise-free data: K's budget is the two type B rows, 2·√(35² + 10²)/√3 ppm.
    let k = u.quantity("scale_factor").unwrap();
    assert!(
        (k.relative_expanded_ppm.unwrap() - 2.0 * (35.0_f64.powi(2) + 100.0).sqrt() / sqrt3).abs()
            < 1e-6
    );
}

#[test]
fn noisy_fit_adds_its_type_a_term_with_welch_satterthwaite_degrees_of_freedom() {
    let mut a = line(0.3612, 0.0088, 2e-4, 7);
    a.attach_uncertainty(&inputs());
    let u = a.uncertainty.as_ref().unwrap();
    let lin = a.fit(Method::LeastSquares, Model::Linear).unwrap();
    let k = u.quantity("scale_factor").unwrap();
    let stat = &k.rows[0];
    assert_eq!(stat.kind, EvaluationType::A);
    assert_eq!(stat.standard_uncertainty, lin.std_errors.k1.unwrap());
    assert_eq!(stat.degrees_of_freedom, Some(17.0));
    // Welch–Satterthwaite with one type A row: ν = 17·(u_c/u_A)⁴ ≥ 17.
    let nu = k.effective_degrees_of_freedom.unwrap();
    assert!(close(
        nu,
        17.0 * (k.standard_uncertainty / stat.standard_uncertainty).powi(4)
    ));
    // The bias as a rate propagates K0 and K with their correlation.
    let m = &a.metrics;
    let b = u.quantity("bias_dph").unwrap();
    assert!(close(b.value, m.bias_dph));
    let rho = m.scale_factor_bias_correlation.unwrap();
    let (sk, sk0) = (lin.std_errors.k1.unwrap(), lin.std_errors.k0.unwrap());
    let (kk, k0) = (m.scale_factor, m.bias_volts);
    let d0 = 3600.0 / kk;
    let dk = -3600.0 * k0 / (kk * kk);
    let expected =
        (d0 * d0 * sk0 * sk0 + dk * dk * sk * sk + 2.0 * d0 * dk * rho * sk0 * sk).sqrt();
    assert!(close(b.rows[0].standard_uncertainty, expected));
    // K+ and K− from the split fit, each with its side's degrees of freedom (10 points − 2).
    for key in ["k_pos", "k_neg"] {
        let q = u.quantity(key).unwrap();
        assert_eq!(q.rows[0].degrees_of_freedom, Some(8.0));
        assert!(a.expanded_uncertainty(key).unwrap() > 0.0);
    }
    // Metrics: the joint-fit asymmetry has U = 2·SE.
    let asym = m.asymmetry_common_k2.as_ref().unwrap();
    assert!(close(
        a.expanded_uncertainty("asymmetry_common_k2").unwrap(),
        2.0 * asym.asymmetry_std_error_ppm
    ));
    assert!(a.expanded_uncertainty("asymmetry_ppm").is_some());
    // The nonlinearity has one too, by Monte Carlo, and the budget says so.
    let nl = m.nonlinearity_uncertainty.as_ref().unwrap();
    assert_eq!(
        a.expanded_uncertainty("nonlinearity_ppm"),
        Some(nl.expanded_uncertainty_ppm)
    );
    let entry = u
        .metrics
        .entries
        .iter()
        .find(|e| e.metric == "nonlinearity_ppm")
        .unwrap();
    assert!(entry.method.starts_with("Monte Carlo"), "{}", entry.method);
    assert!(
        !u.metrics
            .not_available
            .iter()
            .any(|n| n.metric == "nonlinearity_ppm")
    );
}

#[test]
fn budget_json_has_its_shape_names_units_and_round_trips() {
    let mut a = line(0.3612, 0.0088, 2e-4, 3);
    a.attach_uncertainty(&inputs());
    let v = serde_json::to_value(&a).unwrap();
    let u = &v["uncertainty"];
    assert_eq!(u["coverage_factor"], 2.0);
    let method = u["method"].as_str().unwrap();
    for words in ["GUM", "root-sum-of-squares", "type A", "√3", "k = 2"] {
        assert!(method.contains(words), "{words}: {method}");
    }
    assert_eq!(u["inputs"]["meter"]["gain_fraction"], 0.0035 / 100.0);
    assert_eq!(u["inputs"]["table_rate"]["distribution"], "rectangular");
    let units: Vec<&str> = u["quantities"]
        .as_array()
        .unwrap()
        .iter()
        .map(|q| q["unit"].as_str().unwrap())
        .collect();
    assert_eq!(units, ["V/(°/s)", "V", "°/h", "V/(°/s)", "V/(°/s)"]);
    let q = &u["quantities"][0];
    assert_eq!(q["quantity"], "scale_factor");
    for key in [
        "from",
        "value",
        "standard_uncertainty",
        "expanded_uncertainty",
        "relative_expanded_ppm",
        "effective_degrees_of_freedom",
    ] {
        assert!(q.get(key).is_some(), "{key}");
    }
    let r = &q["rows"][1];
    assert_eq!(r["type"], "B");
    for key in [
        "source",
        "distribution",
        "stated",
        "stated_unit",
        "divisor",
        "sensitivity",
        "standard_uncertainty",
    ] {
        assert!(r.get(key).is_some(), "{key}");
    }
    assert!(
        u["not_included"]
            .as_array()
            .unwrap()
            .iter()
            .any(|s| s.as_str().unwrap().contains("alignment"))
    );
    assert!(u["metrics"]["entries"].is_array() && u["metrics"]["not_available"].is_array());
    assert!(!serde_json::to_string(u).unwrap().contains("null"));
    let back: Analysis = serde_json::from_value(v).unwrap();
    assert_eq!(back, a);
}

#[test]
fn missing_or_bad_inputs_are_listed_not_nan() {
    let mut a = line(0.3612, 0.0088, 2e-4, 5);
    a.attach_uncertainty(&UncertaintyInputs::default());
    let u = a.uncertainty.as_ref().unwrap();
    assert!(
        u.not_included
            .iter()
            .any(|s| s.contains("multimeter accuracy: not given"))
    );
    assert!(
        u.not_included
            .iter()
            .any(|s| s.contains("table rate accuracy: not given"))
    );
    // Type A only: U = 2·SE(K).
    let se = a
        .fit(Method::LeastSquares, Model::Linear)
        .unwrap()
        .std_errors
        .k1
        .unwrap();
    assert!(close(
        a.expanded_uncertainty("scale_factor").unwrap(),
        2.0 * se
    ));

    let bad = UncertaintyInputs {
        meter: Some(MeterAccuracy {
            label: "broken".into(),
            gain_fraction: Some(f64::NAN),
            offset_fraction: Some(-1.0),
            range_v: Some(10.0),
        }),
        table_rate: Some(TableRateAccuracy::rectangular(f64::INFINITY, None)),
    };
    a.attach_uncertainty(&bad);
    let u = a.uncertainty.as_ref().unwrap();
    assert!(
        u.not_included
            .iter()
            .filter(|s| s.contains("not included"))
            .count()
            >= 3
    );
    let json = serde_json::to_string(u).unwrap();
    assert!(!json.contains("null"), "{json}");
    assert!(close(
        a.expanded_uncertainty("scale_factor").unwrap(),
        2.0 * se
    ));
}
