//! `gyrocal allan FILE --json` without the CLI around it: the same analysis
//! ([`gyrocal_analysis::drift::analyse_input`], default options) and the same JSON document on
//! stdout, in a binary that builds in release in a few minutes (the whole `gyrocal` binary takes
//! about a quarter of an hour on two cores). For timing the reader and the analysis on long
//! records (`bench/README.md`):
//!
//! ```sh
//! cargo build --release -p gyrocal-analysis --example allan_file
//! /usr/bin/time -v target/release/examples/allan_file /tmp/allan_1e7.csv > /dev/null
//! /usr/bin/time -v target/release/examples/allan_file /tmp/allan_1e8.csv --streaming > /dev/null
//! target/release/examples/allan_file /tmp/allan_1e7.csv --no-warmup > gyrocal.json # the whole record
//! ```
#![allow(clippy::print_stdout, clippy::print_stderr)]

use std::path::PathBuf;
use std::process::ExitCode;

use gyrocal_analysis::drift::{AllanOptions, analyse_input};

fn main() -> ExitCode {
    let mut args = std::env::args_os().skip(1);
    let Some(path) = args.next().map(PathBuf::from) else {
        eprintln!("usage: allan_file FILE.csv [--streaming] [--no-warmup] [--max-memory-mib N]");
        return ExitCode::from(2);
    };
    let rest: Vec<_> = args.collect();
    let mut opts = AllanOptions {
        streaming: rest.iter().any(|a| a == "--streaming"),
        ..AllanOptions::default()
    };
    // `gyrocal allan --max-memory-mib N`
    if let Some(mib) = rest
        .iter()
        .position(|a| a == "--max-memory-mib")
        .and_then(|i| rest.get(i + 1))
        .and_then(|n| n.to_str()?.parse::<u64>().ok())
    {
        opts.max_memory_bytes = Some(mib * 1024 * 1024);
    }
    // `gyrocal allan --warmup-window 0`: the whole record analysed (to compare with allantools)
    if rest.iter().any(|a| a == "--no-warmup") {
        opts.warmup.window_s = 0.0;
    }
    let started = std::time::Instant::now();
    match analyse_input(&path, &opts) {
        Ok(doc) => match serde_json::to_string_pretty(&doc) {
            Ok(json) => {
                println!("{json}");
                eprintln!("analysed in {:.3} s", started.elapsed().as_secs_f64());
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("{e}");
                ExitCode::from(1)
            }
        },
        Err(e) => {
            eprintln!("{e}");
            ExitCode::from(2)
        }
    }
}
