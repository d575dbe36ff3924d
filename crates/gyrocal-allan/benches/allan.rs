//! Benchmarks of the issue-15 targets: octave OADEV on 10⁶/10⁷ samples, the full curve (noise
//! id, EDF, 68/95 % intervals for every octave τ) on 10⁶ samples, and the streaming accumulator.
//! 10⁸ samples (time and peak RSS) is `examples/big.rs` under `/usr/bin/time -v`.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use gyrocal_allan::sim::{GyroNoise, generate};
use gyrocal_allan::{Estimator, Record, Streaming, TauSet, compute_record, deviations};

fn record(n: usize) -> Vec<f64> {
    let noise = GyroNoise {
        arw_deg_per_sqrt_h: 0.1,
        bias_instability_deg_per_h: 0.05,
        rrw_deg_per_h_per_sqrt_h: 0.01,
        ..GyroNoise::default()
    };
    generate(&noise, 0.01, n, 7).unwrap_or_else(|e| panic!("{e}"))
}

fn benches(c: &mut Criterion) {
    let mut g = c.benchmark_group("allan");
    g.sample_size(10);
    for n in [1_000_000usize, 10_000_000] {
        let rec = Record::from_vec(record(n), 0.01).unwrap_or_else(|e| panic!("{e}"));
        g.bench_function(format!("oadev_octave_{n}"), |b| {
            b.iter(|| deviations(black_box(&rec), Estimator::Oadev, &TauSet::Octave))
        });
    }
    let y = record(1_000_000);
    let rec = Record::from_slice(&y, 0.01).unwrap_or_else(|e| panic!("{e}"));
    g.bench_function("oadev_octave_with_ci_1000000", |b| {
        b.iter(|| compute_record(black_box(&rec), Estimator::Oadev, &TauSet::Octave))
    });
    g.bench_function("record_from_slice_1000000", |b| {
        b.iter(|| Record::from_slice(black_box(&y), 0.01))
    });
    g.bench_function("streaming_octave_1000000", |b| {
        b.iter(|| {
            let mut s = Streaming::new(0.01, 1 << 18);
            for chunk in y.chunks(65536) {
                s.push(chunk).unwrap_or_else(|e| panic!("{e}"));
            }
            s.deviations()
        })
    });
    g.finish();
}

criterion_group!(allan, benches);
criterion_main!(allan);
