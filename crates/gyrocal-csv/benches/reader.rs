//! The reader on a drift record (`t_s,volts`, 10⁶ rows, 25 MB, in the page cache): the line
//! reader row by row with the standard library's parser (what `gyrocal allan` and `fit` did
//! before the chunked reader), and the chunked reader on 1 and 2 threads. Run with
//! `cargo bench -p gyrocal-csv --bench reader`; the rows per second are criterion's
//! throughput.

use std::hint::black_box;
use std::io::Write as _;
use std::path::Path;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use gyrocal_csv::{Cell, ChunkedReader, Options, Reader, Spec};

const ROWS: usize = 1_000_000;

/// A record as `bench/gen_allan.py` writes it (a deterministic stand-in for its noise).
fn write_record(path: &Path) {
    let mut out =
        std::io::BufWriter::new(std::fs::File::create(path).unwrap_or_else(|e| panic!("{e}")));
    let _ = writeln!(out, "t_s,volts");
    let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
    for i in 0..ROWS {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        let v = 0.0125 + (x >> 11) as f64 / (1u64 << 53) as f64 * 1e-3;
        let _ = writeln!(out, "{:.6},{v:.9}", i as f64 * 0.01);
    }
}

fn line_reader(path: &Path) -> f64 {
    let mut r = Reader::open(path).unwrap_or_else(|e| panic!("{e}"));
    let mut sum = 0.0;
    while let Some(row) = r.next_row().unwrap_or_else(|e| panic!("{e}")) {
        let t: f64 = row.text(0).and_then(|s| s.parse().ok()).unwrap_or(0.0);
        let v: f64 = row.text(1).and_then(|s| s.parse().ok()).unwrap_or(0.0);
        sum += t + v;
    }
    sum
}

fn chunked(path: &Path, threads: usize) -> f64 {
    let opts = Options {
        threads,
        ..Options::default()
    };
    let mut r = ChunkedReader::open(path, opts).unwrap_or_else(|e| panic!("{e}"));
    let spec = Spec::new().column(0, Cell::Number).column(1, Cell::Number);
    let mut sum = 0.0;
    while let Some(c) = r.next_chunk(&spec).unwrap_or_else(|e| panic!("{e}")) {
        sum += c.column(0).iter().sum::<f64>() + c.column(1).iter().sum::<f64>();
    }
    sum
}

fn benches(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let path = dir.path().join("record.csv");
    write_record(&path);
    let mut g = c.benchmark_group("reader_1e6_rows");
    g.sample_size(10);
    g.throughput(Throughput::Elements(ROWS as u64));
    g.bench_function("line_reader_std_parse", |b| {
        b.iter(|| line_reader(black_box(&path)))
    });
    for threads in [1, 2] {
        g.bench_function(format!("chunked_{threads}_threads"), |b| {
            b.iter(|| chunked(black_box(&path), threads))
        });
    }
    g.finish();
}

criterion_group!(reader, benches);
criterion_main!(reader);
