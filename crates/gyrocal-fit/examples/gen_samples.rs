//! Writes a shuffled raw-sample data file for the scale benchmarks and the numpy comparison.
//!
//! `cargo run --release -p gyrocal-fit --example gen_samples -- N OUT.csv [SEED] [full|continuous]`
//!
//! N samples at the paper's 19 rates (±20 °/s), each line a rate drawn uniformly (so the file
//! is in shuffled order, not grouped by step), the output a gyro with a small even-order
//! nonlinearity plus Gaussian noise of 1 mV: `D = 0.0088 + 0.3612·ω + 2e-6·ω² + N(0, 1e-3)`.
//! With `continuous` the rates are drawn uniformly from [−20, 20] °/s and written with 6
//! decimals (a table's measured rate per reading: 10^6 lines hold about 987 600 distinct
//! rates, the data of issue 24), the outputs with 7 decimals.
//! Columns `rate_dps,volts`; volts with 7 decimals (about 14 bytes a line, 10^7 lines ≈ 139 MB),
//! or with `full` the shortest round-trip representation (about 22 bytes a line, 10^7 lines
//! ≈ 225 MB, closer to a logger writing f64s). Large files are not committed: generate them.

use std::io::{BufWriter, Write};

use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};

/// The paper's rates, °/s.
pub const RATES: [f64; 19] = [
    -20.0, -15.0, -10.0, -7.0, -3.0, -1.0, -0.7, -0.3, -0.1, 0.0, 0.1, 0.3, 0.7, 1.0, 3.0, 7.0,
    10.0, 15.0, 20.0,
];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        return Err("usage: gen_samples N OUT.csv [SEED] [full|continuous]".into());
    }
    let n: u64 = args[1].parse()?;
    let seed: u64 = args.get(3).map_or(Ok(1), |s| s.parse())?;
    let mut out = BufWriter::with_capacity(1 << 20, std::fs::File::create(&args[2])?);
    let mut rng = StdRng::seed_from_u64(seed);
    let full = args.get(4).is_some_and(|a| a == "full");
    let continuous = args.get(4).is_some_and(|a| a == "continuous");
    let noise = Normal::new(0.0, 1e-3)?;
    writeln!(out, "rate_dps,volts")?;
    for _ in 0..n {
        if continuous {
            let w: f64 = rng.random_range(-20.0..=20.0);
            // The rate as written (6 decimals) is the rate the fit sees.
            let w: f64 = format!("{w:.6}").parse()?;
            let d = 0.0088 + 0.3612 * w + 2e-6 * w * w + noise.sample(&mut rng);
            writeln!(out, "{w:.6},{d:.7}")?;
            continue;
        }
        let w = RATES[rng.random_range(0..RATES.len())];
        let d = 0.0088 + 0.3612 * w + 2e-6 * w * w + noise.sample(&mut rng);
        if full {
            writeln!(out, "{w},{d}")?;
        } else {
            writeln!(out, "{w},{d:.7}")?;
        }
    }
    out.flush()?;
    Ok(())
}
