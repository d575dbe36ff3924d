//! Times the stages of `gyrocal fit --json` on one file, in a release build of this crate
//! alone (the whole CLI takes a quarter of an hour to build in release here):
//!
//! `cargo run --release -p gyrocal-fit --example fit_file -- FILE.csv [OUT.json]`
//!
//! Prints the time of reading, of the default analysis and of writing the JSON document (to
//! OUT.json, or discarded), and the document's size, on stderr.

use std::io::Write;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let Some(path) = args.get(1) else {
        return Err("usage: fit_file FILE.csv [OUT.json]".into());
    };
    let t0 = Instant::now();
    let cols = gyrocal_fit::input::read_columns(std::path::Path::new(path))?;
    let t1 = Instant::now();
    let a = gyrocal_fit::analyze_columns(&cols, &gyrocal_fit::Options::default())?;
    let t2 = Instant::now();
    let mut counter = Counter(0);
    match args.get(2) {
        Some(out) => {
            let mut f = std::io::BufWriter::new(std::fs::File::create(out)?);
            serde_json::to_writer_pretty(&mut f, &a)?;
            f.flush()?;
            counter.0 = std::fs::metadata(out)?.len();
        }
        None => serde_json::to_writer_pretty(&mut counter, &a)?,
    }
    let t3 = Instant::now();
    eprintln!(
        "{} points, {:?} distinct rates, detail {:?}: read {:.3} s, analyse {:.3} s, json {:.3} s ({} bytes)",
        cols.len(),
        a.distinct_rates,
        a.residual_detail,
        (t1 - t0).as_secs_f64(),
        (t2 - t1).as_secs_f64(),
        (t3 - t2).as_secs_f64(),
        counter.0
    );
    Ok(())
}

struct Counter(u64);

impl Write for Counter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0 += buf.len() as u64;
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}
