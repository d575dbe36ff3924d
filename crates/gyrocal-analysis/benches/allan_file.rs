//! `gyrocal allan`'s analysis of a long record from its CSV file, reading included: 10⁶ rows of
//! `t_s,volts` (25 MB), in memory and on the bounded-memory path (`--streaming`). The reader
//! alone is `gyrocal-csv`'s `reader` bench; the estimators alone, `gyrocal-allan`'s `allan`.
//! 10⁷ and 10⁸ rows, whole process: `bench/run.sh allan` (bench/README.md).

use std::hint::black_box;
use std::io::Write as _;
use std::path::Path;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use gyrocal_analysis::drift::{AllanOptions, analyse_input};

const ROWS: usize = 1_000_000;

/// A drift record as `bench/gen_allan.py` writes it: τ0 = 0.01 s, white noise on a bias.
fn write_record(path: &Path) {
    let file = std::fs::File::create(path).unwrap_or_else(|e| panic!("{e}"));
    let mut out = std::io::BufWriter::new(file);
    let _ = writeln!(out, "t_s,volts");
    let mut x: u64 = 0x2545_F491_4F6C_DD1D;
    for i in 0..ROWS {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        let v = 0.0125 + ((x >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 1e-4;
        let _ = writeln!(out, "{:.6},{v:.9}", i as f64 * 0.01);
    }
}

fn benches(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let path = dir.path().join("record.csv");
    write_record(&path);
    let mut g = c.benchmark_group("allan_file_1e6_rows");
    g.sample_size(10);
    g.throughput(Throughput::Elements(ROWS as u64));
    for streaming in [false, true] {
        let opts = AllanOptions {
            streaming,
            temp_dir: Some(dir.path().to_path_buf()),
            ..AllanOptions::default()
        };
        let name = if streaming { "bounded" } else { "in_memory" };
        g.bench_function(name, |b| {
            b.iter(|| analyse_input(black_box(&path), &opts).unwrap_or_else(|e| panic!("{e}")))
        });
    }
    g.finish();
}

criterion_group!(allan_file, benches);
criterion_main!(allan_file);
