//! Reads the first two columns of a CSV file as numbers, for timing and profiling the reader
//! (`bench/README.md`): `chunked` (the default) or `lines` (the line reader and the standard
//! library's parser, as before the chunked reader), and the threads of the chunked reader.
//!
//! ```sh
//! cargo build --release -p gyrocal-csv --example read_record
//! /usr/bin/time -v target/release/examples/read_record /tmp/allan_1e7.csv chunked 2
//! valgrind --tool=callgrind target/release/examples/read_record /tmp/allan_1e5.csv chunked 1
//! ```
#![allow(clippy::print_stdout, clippy::print_stderr)]

use std::path::PathBuf;
use std::process::ExitCode;

use gyrocal_csv::{Cell, ChunkedReader, Options, Reader, Spec};

fn lines(path: &std::path::Path) -> Result<(u64, f64), gyrocal_csv::Error> {
    let mut r = Reader::open(path)?;
    let (mut n, mut sum) = (0u64, 0.0);
    while let Some(row) = r.next_row()? {
        let t: f64 = row.text(0).and_then(|s| s.parse().ok()).unwrap_or(f64::NAN);
        let v: f64 = row.text(1).and_then(|s| s.parse().ok()).unwrap_or(f64::NAN);
        sum += t + v;
        n += 1;
    }
    Ok((n, sum))
}

fn chunked(path: &std::path::Path, threads: usize) -> Result<(u64, f64), gyrocal_csv::Error> {
    let opts = Options {
        threads,
        ..Options::default()
    };
    let mut r = ChunkedReader::open(path, opts)?;
    let spec = Spec::new().column(0, Cell::Number).column(1, Cell::Number);
    let (mut n, mut sum) = (0u64, 0.0);
    while let Some(c) = r.next_chunk(&spec)? {
        sum += c.column(0).iter().sum::<f64>() + c.column(1).iter().sum::<f64>();
        n += c.len() as u64;
    }
    Ok((n, sum))
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first().map(PathBuf::from) else {
        eprintln!("usage: read_record FILE.csv [chunked|lines] [THREADS]");
        return ExitCode::from(2);
    };
    let how = args.get(1).map_or("chunked", String::as_str);
    let threads = args
        .get(2)
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| Options::default().threads);
    let started = std::time::Instant::now();
    let result = if how == "lines" {
        lines(&path)
    } else {
        chunked(&path, threads)
    };
    match result {
        Ok((n, sum)) => {
            println!(
                "{n} rows in {:.3} s ({how}, sum {sum})",
                started.elapsed().as_secs_f64()
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("{e}");
            ExitCode::from(2)
        }
    }
}
