//! Octave OADEV on a large simulated record, for timing and peak memory:
//!
//! ```sh
//! cargo build --release -p gyrocal-allan --example big
//! /usr/bin/time -v target/release/examples/big 100000000          # batch, in place
//! /usr/bin/time -v target/release/examples/big 100000000 stream   # streaming accumulator
//! /usr/bin/time -v target/release/examples/big 100000000 stream 1048576   # τ ≤ 2^20·τ0 only
//! ```
#![allow(clippy::print_stdout)]

use std::time::Instant;

use gyrocal_allan::sim::{Generator, GyroNoise};
use gyrocal_allan::{Estimator, Record, Streaming, TauSet, deviations};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let n: usize = args
        .get(1)
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(10_000_000);
    let stream = args.get(2).is_some_and(|s| s == "stream");
    // streaming: longest averaging factor kept (default N/4); the buffer is ≤ 2·(2·max_m + 1) f64
    let max_m: usize = args.get(3).map(|s| s.parse()).transpose()?.unwrap_or(n / 4);
    let tau0 = 0.01;
    let noise = GyroNoise {
        arw_deg_per_sqrt_h: 0.1,
        rrw_deg_per_h_per_sqrt_h: 0.01,
        ..GyroNoise::default()
    };
    let mut generator = Generator::new(&noise, tau0, 1)?;
    if stream {
        let mut acc = Streaming::new(tau0, max_m);
        let mut buf = vec![0.0; 1 << 20];
        let mut left = n;
        let mut busy = std::time::Duration::ZERO;
        while left > 0 {
            let k = left.min(buf.len());
            generator.fill(&mut buf[..k]);
            let t = Instant::now();
            acc.push(&buf[..k])?;
            busy += t.elapsed();
            left -= k;
        }
        let t = Instant::now();
        let pts = acc.deviations()?;
        busy += t.elapsed();
        println!(
            "streaming N={n}: {} points, accumulator time {:.3} s",
            pts.len(),
            busy.as_secs_f64()
        );
    } else {
        let mut y = vec![0.0; n];
        generator.fill(&mut y);
        let t = Instant::now();
        let rec = Record::from_vec(y, tau0)?;
        let t_rec = t.elapsed();
        let pts = deviations(&rec, Estimator::Oadev, &TauSet::Octave)?;
        let t_all = t.elapsed();
        println!(
            "batch N={n}: {} points, prefix sums {:.3} s, total {:.3} s",
            pts.len(),
            t_rec.as_secs_f64(),
            t_all.as_secs_f64()
        );
    }
    Ok(())
}
