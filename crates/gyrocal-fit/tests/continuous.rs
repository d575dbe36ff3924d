//! Continuous-rate data (nearly every rate distinct, issue 24): the per-rate summaries and the
//! neuron's online passes are over rate bins, every figure over all points stays exact, and a
//! schedule keeps its per-rate groups.

#![allow(clippy::unwrap_used)]

use gyrocal_fit::{
    Analysis, Columns, Method, Model, Options, RATE_BINS, RATE_GROUPS_MAX, ResidualDetail,
    TrainingData, WithPointResiduals, analyze_columns,
};

/// `n` points with rates spread over ±20 °/s (all distinct: an irrational step, shuffled by the
/// multiplier), a bowl-shaped gyro and ±0.5 mV of deterministic pseudo-noise.
fn continuous(n: usize) -> Columns {
    let mut rates = Vec::with_capacity(n);
    let mut volts = Vec::with_capacity(n);
    for i in 0..n {
        let w = -20.0 + 40.0 * ((i as f64 * 0.754_877_666_2).fract());
        let noise = 1e-3 * ((i as f64 * 0.618_033_988_7).fract() - 0.5);
        rates.push(w);
        volts.push(0.0088 + 0.3612 * w + 2e-6 * w * w + noise);
    }
    Columns {
        source: Some("continuous.csv".to_string()),
        rates,
        volts,
        sigmas: None,
        last_line: Some(n as u64 + 1),
    }
}

/// `n` points cycling through `rates`.
fn schedule(rates: &[f64], n: usize) -> Columns {
    let mut c = continuous(n);
    for (i, w) in c.rates.iter_mut().enumerate() {
        *w = rates[(i * 7) % rates.len()];
    }
    for (i, (d, w)) in c.volts.iter_mut().zip(&c.rates).enumerate() {
        *d = 0.0088
            + 0.3612 * w
            + 2e-6 * w * w
            + 1e-3 * ((i as f64 * 0.618_033_988_7).fract() - 0.5);
    }
    c
}

/// The least-squares line by an independent computation (centred sums), and its SSE.
fn exact_line(c: &Columns) -> (f64, f64, f64) {
    let n = c.len() as f64;
    let mw = c.rates.iter().sum::<f64>() / n;
    let md = c.volts.iter().sum::<f64>() / n;
    let (mut sxx, mut sxy) = (0.0, 0.0);
    for (w, d) in c.rates.iter().zip(&c.volts) {
        sxx += (w - mw) * (w - mw);
        sxy += (w - mw) * (d - md);
    }
    let k = sxy / sxx;
    let k0 = md - k * mw;
    let sse = c
        .rates
        .iter()
        .zip(&c.volts)
        .map(|(w, d)| (d - k0 - k * w).powi(2))
        .sum();
    (k, k0, sse)
}

fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs())
}

#[test]
fn continuous_rates_are_summarised_over_rate_bins_with_exact_k_k0_and_sse() {
    let data = continuous(50_000);
    let a = analyze_columns(&data, &Options::default()).unwrap();
    assert_eq!(a.points, 50_000);
    assert_eq!(a.distinct_rates, Some(50_000));
    assert_eq!(a.residual_detail, ResidualDetail::PerRateBin);
    let bins = a.rate_bins.as_ref().unwrap();
    assert_eq!(bins.bins, RATE_BINS);
    assert_eq!(RATE_BINS, 200);
    assert!(bins.lo_dps >= -20.0 && bins.hi_dps <= 20.0, "{bins:?}");
    assert!(bins.rule.contains("200 equal-width bins"), "{}", bins.rule);

    // K, K0 and the SSE are those of every point, not of the bins.
    let (k, k0, sse) = exact_line(&data);
    let ls = a.fit(Method::LeastSquares, Model::Linear).unwrap();
    assert!(
        close(ls.scale_factor, k, 1e-12),
        "{} vs {k}",
        ls.scale_factor
    );
    assert!(close(ls.bias, k0, 1e-9), "{} vs {k0}", ls.bias);
    assert!(close(ls.sse, sse, 1e-9), "{} vs {sse}", ls.sse);
    assert!(close(a.metrics.scale_factor, k, 1e-12));

    // Every fit: one summary per non-empty bin (here every bin), the points all counted,
    // each bin's mean residual the mean of its points' residuals.
    for f in &a.fits {
        assert!(f.residuals.is_empty());
        assert_eq!(
            f.rate_residuals.len(),
            RATE_BINS,
            "{} {}",
            f.method,
            f.model
        );
        assert_eq!(f.rate_residuals.iter().map(|r| r.n).sum::<u64>(), 50_000);
        for r in &f.rate_residuals {
            let (lo, hi) = (r.rate_min_dps.unwrap(), r.rate_max_dps.unwrap());
            assert!(lo <= r.rate_dps && r.rate_dps <= hi, "{r:?}");
        }
    }
    let first = &ls.rate_residuals[0];
    let (lo, hi) = (first.rate_min_dps.unwrap(), first.rate_max_dps.unwrap());
    let inside: Vec<(f64, f64)> = data
        .rates
        .iter()
        .zip(&data.volts)
        .filter(|(w, _)| **w >= lo && **w < hi)
        .map(|(w, d)| (*w, *d))
        .collect();
    assert_eq!(inside.len() as u64, first.n);
    let mean_r = inside
        .iter()
        .map(|(w, d)| d - (ls.bias + ls.scale_factor * w))
        .sum::<f64>()
        / inside.len() as f64;
    assert!(
        (mean_r - first.mean_residual).abs() < 1e-12,
        "{mean_r} vs {}",
        first.mean_residual
    );
    let max_r = inside
        .iter()
        .map(|(w, d)| (d - (ls.bias + ls.scale_factor * w)).abs())
        .fold(0.0, f64::max);
    assert!((max_r - first.max_abs_residual).abs() < 1e-12);

    // The neuron's online passes present the bins; it still reaches the line of every point.
    let nn = a.fit(Method::Neuron, Model::Linear).unwrap();
    let t = nn.neuron.as_ref().unwrap();
    assert_eq!(
        t.training_data,
        TrainingData::RateBins {
            bins: RATE_BINS,
            points: 50_000
        }
    );
    assert!(nn.converged);
    assert!(close(nn.sse, ls.sse, 1e-9), "{} vs {}", nn.sse, ls.sse);
    assert!(close(nn.scale_factor, k, 1e-9));
}

#[test]
fn binning_changes_no_figure_over_the_points() {
    // The same data with per-point residuals: every fit's coefficients, standard errors and
    // figures, the metrics, the model selection and the error surface are bit-identical.
    let data = continuous(20_000);
    let binned = analyze_columns(&data, &Options::default()).unwrap();
    let per_point = analyze_columns(
        &data,
        &Options {
            point_residuals_max: usize::MAX,
            ..Options::default()
        },
    )
    .unwrap();
    assert_eq!(per_point.residual_detail, ResidualDetail::PerPoint);
    assert_eq!(binned.residual_detail, ResidualDetail::PerRateBin);
    assert_eq!(binned.metrics, per_point.metrics);
    assert_eq!(binned.model_selection, per_point.model_selection);
    assert_eq!(binned.error_surface, per_point.error_surface);
    assert_eq!(binned.fits.len(), per_point.fits.len());
    for (b, p) in binned.fits.iter().zip(&per_point.fits) {
        assert_eq!(b.coefficients, p.coefficients);
        assert_eq!(b.std_errors, p.std_errors);
        assert_eq!(b.sse.to_bits(), p.sse.to_bits());
        assert_eq!(b.max_abs_residual.to_bits(), p.max_abs_residual.to_bits());
        assert_eq!(b.r_squared.to_bits(), p.r_squared.to_bits());
        assert_eq!(b.neuron, p.neuron);
        assert_eq!(p.residuals.len(), 20_000);
    }
}

#[test]
fn a_schedule_keeps_one_summary_per_rate() {
    let rates = [
        -20.0, -15.0, -10.0, -7.0, -3.0, -1.0, -0.7, -0.3, -0.1, 0.0, 0.1, 0.3, 0.7, 1.0, 3.0, 7.0,
        10.0, 15.0, 20.0,
    ];
    let a = analyze_columns(&schedule(&rates, 19_000), &Options::default()).unwrap();
    assert_eq!(a.residual_detail, ResidualDetail::PerRate);
    assert_eq!(a.rate_bins, None);
    for f in &a.fits {
        let got: Vec<f64> = f.rate_residuals.iter().map(|r| r.rate_dps).collect();
        assert_eq!(got, rates);
        assert!(
            f.rate_residuals
                .iter()
                .all(|r| r.n == 1000 && r.rate_min_dps.is_none())
        );
    }
    let t = a
        .fit(Method::Neuron, Model::Linear)
        .unwrap()
        .neuron
        .clone()
        .unwrap();
    assert_eq!(
        t.training_data,
        TrainingData::RateMeans {
            rates: 19,
            points: 19_000
        }
    );
    let json = serde_json::to_string(&a).unwrap();
    assert!(!json.contains("rate_bins") && !json.contains("rate_min_dps"));
}

#[test]
fn the_rule_is_at_most_rate_groups_max_distinct_rates_for_a_schedule() {
    let at_limit: Vec<f64> = (0..RATE_GROUPS_MAX)
        .map(|k| k as f64 * 0.1 - 10.0)
        .collect();
    let a = analyze_columns(&schedule(&at_limit, 20_000), &Options::default()).unwrap();
    assert_eq!(a.distinct_rates, Some(RATE_GROUPS_MAX));
    assert_eq!(a.residual_detail, ResidualDetail::PerRate);
    assert_eq!(a.fits[0].rate_residuals.len(), RATE_GROUPS_MAX);

    let over: Vec<f64> = (0..=RATE_GROUPS_MAX)
        .map(|k| k as f64 * 0.1 - 10.0)
        .collect();
    let a = analyze_columns(&schedule(&over, 20_000), &Options::default()).unwrap();
    assert_eq!(a.distinct_rates, Some(RATE_GROUPS_MAX + 1));
    assert_eq!(a.residual_detail, ResidualDetail::PerRateBin);
    // 201 rates in 200 bins: none empty here, every point counted once.
    let rr = &a.fits[0].rate_residuals;
    assert!(rr.len() <= RATE_BINS);
    assert_eq!(rr.iter().map(|r| r.n).sum::<u64>(), 20_000);
}

#[test]
fn clustered_continuous_data_leave_empty_bins_out() {
    // Rates in two narrow clusters at the ends of the range: most bins are empty.
    let mut data = continuous(30_000);
    for w in &mut data.rates {
        *w = if *w < 0.0 {
            -20.0 + *w / 200.0 + 0.1
        } else {
            20.0 - *w / 200.0
        };
    }
    let a = analyze_columns(&data, &Options::default()).unwrap();
    assert_eq!(a.residual_detail, ResidualDetail::PerRateBin);
    let rr = &a.fits[0].rate_residuals;
    assert!(rr.len() < 20, "{}", rr.len());
    assert!(rr.iter().all(|r| r.n > 0));
    assert_eq!(rr.iter().map(|r| r.n).sum::<u64>(), 30_000);
    let nn = a.fit(Method::Neuron, Model::Linear).unwrap();
    assert!(nn.converged);
    assert!(matches!(
        nn.neuron.as_ref().unwrap().training_data,
        TrainingData::RateBins { bins, .. } if bins == rr.len()
    ));
    let ls = a.fit(Method::LeastSquares, Model::Linear).unwrap();
    assert!(close(nn.sse, ls.sse, 1e-9), "{} vs {}", nn.sse, ls.sse);
}

fn per_point_document(data: &Columns) -> (Analysis, Vec<u8>) {
    let summarised = analyze_columns(data, &Options::default()).unwrap();
    let per_point = analyze_columns(
        data,
        &Options {
            point_residuals_max: usize::MAX,
            ..Options::default()
        },
    )
    .unwrap();
    (summarised, serde_json::to_vec_pretty(&per_point).unwrap())
}

#[test]
fn streamed_point_residuals_are_the_per_point_document_byte_for_byte() {
    for data in [
        continuous(12_000),
        schedule(&[-10.0, -1.0, 0.0, 1.0, 10.0], 12_000),
    ] {
        let (summarised, expected) = per_point_document(&data);
        assert_ne!(summarised.residual_detail, ResidualDetail::PerPoint);
        let streamed =
            serde_json::to_vec_pretty(&WithPointResiduals::new(&summarised, &data)).unwrap();
        assert_eq!(
            String::from_utf8(streamed).unwrap(),
            String::from_utf8(expected).unwrap()
        );
    }
}
