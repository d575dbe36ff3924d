//! `gyrocal verify RUN...`: the data files of completed runs against the SHA-256 their
//! manifests recorded (samples.csv and steps.csv at completion, fit.json when it was written).
//! Exit 0 when every file is as recorded; 1 naming each file that changed or went missing, or
//! a run that recorded no checksums.

use std::path::PathBuf;

use clap::Args;

use crate::BadInput;

/// Arguments of `gyrocal verify`.
#[derive(Debug, Args)]
pub struct VerifyArgs {
    /// Run directories.
    #[arg(required = true, value_name = "RUN_DIR")]
    pub runs: Vec<PathBuf>,
}

/// Runs `gyrocal verify`; the exit code.
pub fn run(args: &VerifyArgs) -> anyhow::Result<u8> {
    let mut bad = 0usize;
    for dir in &args.runs {
        let checks = gyrocal_run::rundir::verify(dir).map_err(|e| BadInput(e.to_string()))?;
        if checks.is_empty() {
            println!(
                "{}: no checksums recorded (the run is not complete, or an earlier gyrocal \
                 wrote it): nothing to verify",
                dir.display()
            );
            bad += 1;
            continue;
        }
        for c in &checks {
            match &c.now {
                _ if c.ok() => println!("{}: {} ok", dir.display(), c.file),
                Some(now) => {
                    bad += 1;
                    println!(
                        "{}: {} CHANGED since the run recorded it (sha256 {} recorded, {} now)",
                        dir.display(),
                        c.file,
                        c.recorded,
                        now
                    );
                }
                None => {
                    bad += 1;
                    println!("{}: {} MISSING or unreadable", dir.display(), c.file);
                }
            }
        }
    }
    Ok(u8::from(bad > 0))
}
