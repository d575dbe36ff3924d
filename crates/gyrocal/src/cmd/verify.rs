//! `gyrocal verify RUN...`: every file a run wrote against the SHA-256 its manifest recorded
//! (samples.csv and steps.csv at completion, fit.json and the Allan results when they were
//! written). Exit 0 only when every file of every run is as recorded; 1 naming each file that
//! changed, went missing, is not a regular file or is not recorded, a complete run whose
//! checksums are missing, or a run that is not complete (it has no checksums yet); 2 when a
//! path is not a readable run directory.

use std::path::PathBuf;

use clap::Args;

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
        let v = gyrocal_files::rundir::verify(dir).map_err(|e| crate::run_dir_error(e, None))?;
        for p in &v.problems {
            bad += 1;
            println!("{}: {p}", dir.display());
        }
        if v.checks.is_empty() && v.problems.is_empty() {
            // a complete run always has data files to check: this cannot be a clean run
            bad += 1;
            println!(
                "{}: no file recorded: nothing can be verified",
                dir.display()
            );
        }
        for c in &v.checks {
            if !c.ok() {
                bad += 1;
            }
            println!("{}: {}", dir.display(), c.describe());
        }
        let missing: Vec<&str> = v
            .checks
            .iter()
            .filter(|c| c.state == gyrocal_files::rundir::FileState::NotRecorded)
            .filter(|c| gyrocal_files::rundir::DATA_FILES.contains(&c.file.as_str()))
            .map(|c| c.file.as_str())
            .collect();
        if !missing.is_empty() {
            println!(
                "{}: the checksums of {} are missing from manifest.json: this run cannot be verified",
                dir.display(),
                missing.join(" and ")
            );
        }
    }
    Ok(u8::from(bad > 0))
}
