//! `gyrocal fit` at scale, on shuffled raw samples (issue 16): the whole default analysis
//! (parse of an in-memory CSV + every model, the neuron, the metrics and the error surface, as
//! `gyrocal fit --json` computes them) and least squares alone (linear and cubic), at 10^5 and
//! 10^6 points of the paper's 19-rate schedule (`shuffled_N`), and on continuous rates
//! (`continuous_N`, issue 24: every rate drawn from ±20 °/s and written with 6 decimals, so
//! nearly all distinct; the per-rate summaries are then over rate bins) at 10^6, plus the
//! JSON document `gyrocal fit --json` writes (serialized to a byte counter).
//!
//! 10^7 points takes about 250 MB of CSV and several seconds an iteration: it runs only with
//! `GYROCAL_BENCH_1E7=1 cargo bench -p gyrocal-fit --bench scale` (sample size 10). Benches
//! are not run in CI. The data are those of `examples/gen_samples.rs` (same rates, model,
//! noise and shuffled order; `continuous` for the continuous ones).

use std::fmt::Write as _;
use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use gyrocal_fit::{Model, Options, Weighting, analyze_columns, fit_least_squares_columns, input};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};

const RATES: [f64; 19] = [
    -20.0, -15.0, -10.0, -7.0, -3.0, -1.0, -0.7, -0.3, -0.1, 0.0, 0.1, 0.3, 0.7, 1.0, 3.0, 7.0,
    10.0, 15.0, 20.0,
];

/// A CSV of `n` samples at continuous rates, as `gen_samples N FILE 1 continuous` writes it.
fn continuous_csv(n: usize) -> String {
    let mut rng = StdRng::seed_from_u64(1);
    let noise = Normal::new(0.0, 1e-3).unwrap_or_else(|_| unreachable!());
    let mut s = String::with_capacity(n * 22 + 16);
    s.push_str("rate_dps,volts\n");
    for _ in 0..n {
        let w: f64 = rng.random_range(-20.0..=20.0);
        let w: f64 = format!("{w:.6}").parse().unwrap_or(w);
        let d = 0.0088 + 0.3612 * w + 2e-6 * w * w + noise.sample(&mut rng);
        let _ = writeln!(s, "{w:.6},{d:.7}");
    }
    s
}

/// Bytes written, nothing kept: the cost of serializing a document.
struct Counter(usize);

impl std::io::Write for Counter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0 += buf.len();
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// A shuffled CSV of `n` samples, as `gen_samples` writes it.
fn csv(n: usize) -> String {
    let mut rng = StdRng::seed_from_u64(1);
    let noise = Normal::new(0.0, 1e-3).unwrap_or_else(|_| unreachable!());
    let mut s = String::with_capacity(n * 26 + 16);
    s.push_str("rate_dps,volts\n");
    for _ in 0..n {
        let w = RATES[rng.random_range(0..RATES.len())];
        let d = 0.0088 + 0.3612 * w + 2e-6 * w * w + noise.sample(&mut rng);
        let _ = writeln!(s, "{w},{d:.7}");
    }
    s
}

fn benches(c: &mut Criterion) {
    let mut sizes = vec![100_000_usize, 1_000_000];
    if std::env::var_os("GYROCAL_BENCH_1E7").is_some() {
        sizes.push(10_000_000);
    }
    let opts = Options::default();
    for &n in &sizes {
        if n < 1_000_000 {
            continue;
        }
        let text = continuous_csv(n);
        let cols =
            input::parse_columns(text.as_bytes(), "bench.csv").unwrap_or_else(|e| panic!("{e}"));
        let mut g = c.benchmark_group(format!("continuous_{n}"));
        g.sample_size(10);
        g.bench_function(BenchmarkId::new("fit_default_columns", n), |b| {
            b.iter(|| analyze_columns(black_box(&cols), &opts))
        });
        g.bench_function(BenchmarkId::new("fit_default_columns_and_json", n), |b| {
            b.iter(|| {
                analyze_columns(black_box(&cols), &opts).map(|a| {
                    let mut out = Counter(0);
                    serde_json::to_writer_pretty(&mut out, &a).map(|()| out.0)
                })
            })
        });
        for model in [Model::Linear, Model::Cubic] {
            g.bench_function(BenchmarkId::new(format!("least_squares_{model}"), n), |b| {
                b.iter(|| fit_least_squares_columns(black_box(&cols), model, Weighting::Auto))
            });
        }
        g.finish();
    }
    for n in sizes {
        let text = csv(n);
        let cols =
            input::parse_columns(text.as_bytes(), "bench.csv").unwrap_or_else(|e| panic!("{e}"));
        let mut g = c.benchmark_group(format!("shuffled_{n}"));
        g.sample_size(10);
        g.bench_function(BenchmarkId::new("fit_default_with_parse", n), |b| {
            b.iter(|| {
                let cols = input::parse_columns(black_box(text.as_bytes()), "bench.csv");
                cols.map(|cols| analyze_columns(&cols, &opts))
            })
        });
        g.bench_function(BenchmarkId::new("fit_default_columns", n), |b| {
            b.iter(|| analyze_columns(black_box(&cols), &opts))
        });
        for model in [Model::Linear, Model::Cubic] {
            g.bench_function(BenchmarkId::new(format!("least_squares_{model}"), n), |b| {
                b.iter(|| fit_least_squares_columns(black_box(&cols), model, Weighting::Auto))
            });
        }
        g.finish();
    }
}

criterion_group!(scale, benches);
criterion_main!(scale);
