//! Least squares on 10^6 points (linear and cubic) and the neuron on the paper's 19 points.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use gyrocal_fit::{Dataset, Model, NeuronOptions, Weighting, fit_least_squares, fit_neuron};

fn million() -> Dataset {
    let n = 1_000_000;
    Dataset::from_pairs((0..n).map(|i| {
        let w = -20.0 + 40.0 * i as f64 / (n - 1) as f64;
        // Deterministic pseudo-noise of ±1e-4 V.
        let noise = 1e-4 * ((i as f64 * 0.618_033_988_7).fract() - 0.5);
        (w, 0.0088 + 0.3612 * w + 2e-6 * w * w + noise)
    }))
}

fn paper() -> Dataset {
    let rates = [
        -20.0, -15.0, -10.0, -7.0, -3.0, -1.0, -0.7, -0.3, -0.1, 0.0, 0.1, 0.3, 0.7, 1.0, 3.0, 7.0,
        10.0, 15.0, 20.0,
    ];
    Dataset::from_pairs(
        rates
            .iter()
            .map(|&w| (w, 0.0088 + 0.3612 * w + 2e-6 * w * w)),
    )
}

fn benches(c: &mut Criterion) {
    let big = million();
    let mut g = c.benchmark_group("least_squares_1e6");
    g.sample_size(10);
    g.bench_function("linear", |b| {
        b.iter(|| fit_least_squares(black_box(&big), Model::Linear, Weighting::Auto))
    });
    g.bench_function("cubic", |b| {
        b.iter(|| fit_least_squares(black_box(&big), Model::Cubic, Weighting::Auto))
    });
    g.finish();
    let small = paper();
    let opts = NeuronOptions::default();
    c.bench_function("neuron_19_points_to_convergence", |b| {
        b.iter(|| fit_neuron(black_box(&small), &opts, Weighting::Auto))
    });
}

criterion_group!(fit, benches);
criterion_main!(fit);
