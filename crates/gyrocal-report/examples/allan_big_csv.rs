//! Writes a long simulated drift record as `t_s,rate_dph` for measuring `gyrocal allan`'s two
//! memory paths (peak resident memory and time):
//!
//! ```sh
//! cargo build --release -p gyrocal --bin gyrocal -p gyrocal-report --example allan_big_csv
//! target/release/examples/allan_big_csv 20000000 /var/tmp/big.csv     # 2·10⁷ rows, ~0.6 GB
//! /usr/bin/time -v target/release/gyrocal allan /var/tmp/big.csv > /dev/null               # in memory
//! /usr/bin/time -v target/release/gyrocal allan /var/tmp/big.csv --streaming > /dev/null   # bounded
//! ```
//!
//! ("Maximum resident set size" and "Elapsed (wall clock) time" are the figures.)
#![allow(clippy::print_stdout)]

use std::fs::File;
use std::io::{BufWriter, Write};

use gyrocal_allan::sim::{Generator, GyroNoise};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let n: usize = args
        .next()
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(20_000_000);
    let path = args.next().unwrap_or_else(|| "big.csv".to_string());
    let tau0 = 0.01;
    let noise = GyroNoise {
        bias_deg_per_h: 3.0,
        arw_deg_per_sqrt_h: 0.05,
        bias_instability_deg_per_h: 0.2,
        rrw_deg_per_h_per_sqrt_h: 0.5,
        ..GyroNoise::default()
    };
    let mut generator = Generator::new(&noise, tau0, 1)?;
    let mut out = BufWriter::with_capacity(1 << 20, File::create(&path)?);
    writeln!(out, "t_s,rate_dph")?;
    let mut buf = vec![0.0; 1 << 16];
    let mut i = 0usize;
    while i < n {
        let k = (n - i).min(buf.len());
        generator.fill(&mut buf[..k]);
        for r in &buf[..k] {
            writeln!(out, "{:.2},{r:.6}", i as f64 * tau0)?;
            i += 1;
        }
    }
    out.flush()?;
    println!("{n} rows written to {path}");
    Ok(())
}
