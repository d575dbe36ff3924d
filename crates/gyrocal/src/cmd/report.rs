//! `gyrocal report`: the HTML calibration report of run directories or steps CSV files.

use std::path::PathBuf;

use anyhow::Context as _;
use clap::Args;
use gyrocal_report::{ReportError, render_many};

use crate::BadInput;

/// Arguments of `gyrocal report`.
#[derive(Debug, Args)]
pub struct ReportArgs {
    /// Run directories (manifest.json, steps.csv, fit.json) or steps CSV files (columns
    /// rate_dps, volts; optional volts_std, n, rate_meas_dps). Several: one report with the
    /// repeatability across them.
    #[arg(required = true, value_name = "RUN_DIR|STEPS.csv")]
    pub inputs: Vec<PathBuf>,
    /// The HTML file to write; the plots (.svg) are written next to it. Default:
    /// RUN_DIR/report.html for one run directory, else report.html in the current directory.
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
}

/// Runs `gyrocal report`: prints the path of the HTML written.
pub fn run(args: &ReportArgs) -> anyhow::Result<()> {
    let out = match (&args.out, args.inputs.as_slice()) {
        (Some(out), _) => out.clone(),
        (None, [one]) if one.is_dir() => one.join(gyrocal_run::rundir::REPORT_HTML),
        (None, _) => PathBuf::from(gyrocal_run::rundir::REPORT_HTML),
    };
    let report = render_many(&args.inputs).map_err(classify)?;
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("{}: cannot create the directory", dir.display()))?;
    }
    let written = report.write(&out).map_err(classify)?;
    println!("report: {}", out.display());
    tracing::info!(files = written.len(), "report written");
    Ok(())
}

/// Input problems (missing or malformed files) exit with 2, others with 1.
fn classify(e: ReportError) -> anyhow::Error {
    if e.is_input_error() {
        BadInput(e.to_string()).into()
    } else {
        anyhow::Error::new(e)
    }
}
