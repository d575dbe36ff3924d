//! `gyrocal report`: the HTML calibration report of run directories or steps CSV files.
//!
//! Before a run directory's files are used they are checked against the run's record
//! ([`gyrocal_report::check_run`]: the SHA-256 its manifest holds of steps.csv and fit.json,
//! and of samples.csv and allan.json for a drift record; the steps the manifest records as
//! done): a run whose files differ is refused with exit 1 naming them, or, with
//! `--allow-modified`, reported with a banner naming them. Why: a report is a certificate; it
//! must never vouch for a `fit.json` whose `steps.csv` was emptied or edited.

use std::path::PathBuf;

use anyhow::Context as _;
use clap::Args;
use gyrocal_report::ReportError;

use crate::BadInput;

/// Arguments of `gyrocal report`.
#[derive(Debug, Args)]
pub struct ReportArgs {
    /// Run directories (manifest.json, steps.csv, fit.json) or steps CSV files (columns
    /// rate_dps, volts; optional volts_std, n, rate_meas_dps). Several: one report with the
    /// repeatability across them (runs of different plans are reported, with a warning, but
    /// get no repeatability).
    #[arg(required = true, value_name = "RUN_DIR|STEPS.csv")]
    pub inputs: Vec<PathBuf>,
    /// The HTML file to write; the plots (.svg) are written next to it. Default: report.html
    /// in the run directory (for a steps CSV, in the CSV's directory). Required with several
    /// inputs, whose combined report belongs to none of them.
    #[arg(short = 'o', long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// Print exactly one JSON document on stdout (the report's path, every file written, the
    /// warnings) instead of the human line.
    #[arg(long)]
    pub json: bool,
    /// Acceptance limits to evaluate the run against instead of its plan's `[acceptance]`
    /// (a TOML file with `decision_rule` and a table per quantity, as in
    /// configs/acceptance.example.toml). One run directory only; its fit.json is not changed.
    #[arg(long, value_name = "FILE")]
    pub acceptance: Option<PathBuf>,
    /// Make the report even when files of a run differ from the run's record of them (their
    /// SHA-256 in its manifest, or a steps.csv that lacks steps the manifest records): the
    /// report then opens with a banner naming each such file. Without it such a run is
    /// refused (exit 1), so a certificate is never issued from files nobody vouches for.
    #[arg(long)]
    pub allow_modified: bool,
}

/// Where the report goes: `--out`, else beside the one input (never the current directory,
/// where the report and its many plots would land among unrelated files).
fn destination(args: &ReportArgs) -> Result<PathBuf, BadInput> {
    match (&args.out, args.inputs.as_slice()) {
        (Some(out), _) => Ok(out.clone()),
        (None, [one]) if one.is_dir() => Ok(one.join(gyrocal_files::rundir::REPORT_HTML)),
        (None, [one]) => Ok(one
            .parent()
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or(std::path::Path::new("."))
            .join(gyrocal_files::rundir::REPORT_HTML)),
        (None, many) => Err(BadInput(format!(
            "{} inputs: say where their combined report goes with -o FILE (for example -o \
             reports/combined.html; the plots are written beside it); each run directory keeps \
             its own report.html",
            many.len()
        ))),
    }
}

/// Runs `gyrocal report`: prints the path of the HTML written.
pub fn run(args: &ReportArgs) -> anyhow::Result<()> {
    // a run whose report is a page of its kind's own (a drift record's Allan page): the report
    // crate's one dispatch on the kind says which, and writes it
    if let Some((input, page)) = args
        .inputs
        .iter()
        .find_map(|i| gyrocal_report::own_page(i).map(|p| (i, p)))
    {
        if args.inputs.len() > 1 || args.out.is_some() || args.acceptance.is_some() {
            return Err(BadInput((page.alone)(input)).into());
        }
        let notes = checked(input, page.files_read, args.allow_modified)?;
        for n in &notes {
            eprintln!("gyrocal: warning: {n}");
        }
        let files = (page.write)(input, &notes).map_err(classify)?;
        let html = files
            .iter()
            .find(|f| f.extension().is_some_and(|e| e == "html"))
            .cloned()
            .unwrap_or_else(|| input.clone());
        if args.json {
            println!(
                "{:#}",
                serde_json::json!({
                    "report": html,
                    "files": files,
                    "inputs": args.inputs,
                    "warnings": notes,
                    "kind": page.kind,
                })
            );
        } else {
            println!("report: {} ({})", html.display(), page.what);
        }
        return Ok(());
    }
    let out = destination(args)?;
    let report = match &args.acceptance {
        None => gyrocal_report::render(
            &gyrocal_report::load_inputs_checked(&args.inputs, args.allow_modified)
                .map_err(classify)?,
        )
        .map_err(classify)?,
        Some(path) => {
            let [one] = args.inputs.as_slice() else {
                return Err(BadInput(
                    "--acceptance applies to one run directory: give exactly one".into(),
                )
                .into());
            };
            let spec = gyrocal_files::plan::load_acceptance(path)
                .map_err(|e| BadInput(format!("--acceptance: {e}")))?;
            let mut input =
                gyrocal_report::load_inputs_checked(std::slice::from_ref(one), args.allow_modified)
                    .map_err(classify)?
                    .pop()
                    .ok_or_else(|| BadInput("--acceptance: no input".into()))?;
            if let Err(e) = &input.analysis {
                return Err(BadInput(format!(
                    "--acceptance: {} has no fit to evaluate: {e}",
                    one.display()
                ))
                .into());
            }
            gyrocal_report::apply_acceptance(&mut input, &spec, &path.display().to_string());
            gyrocal_report::render(&[input]).map_err(classify)?
        }
    };
    for w in &report.warnings {
        eprintln!("gyrocal: warning: {w}");
    }
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("{}: cannot create the directory", dir.display()))?;
    }
    let written = report.write(&out).map_err(classify)?;
    if args.json {
        println!(
            "{:#}",
            serde_json::json!({
                "report": out,
                "files": written,
                "inputs": args.inputs,
                "warnings": report.warnings,
                "acceptance": report.acceptance,
            })
        );
    } else {
        println!("report: {}", out.display());
    }
    tracing::info!(files = written.len(), "report written");
    Ok(())
}

/// The files `files` of the drift run `dir` checked against the run's record: the banners for
/// the page when `allow` and some differ; an error (exit 1, naming them) when not `allow`.
fn checked(dir: &std::path::Path, files: &[&str], allow: bool) -> anyhow::Result<Vec<String>> {
    gyrocal_report::check_run(dir, files)
        .and_then(|c| c.notes(dir, allow))
        .map_err(classify)
}

/// Input problems (missing or malformed files) exit with 2, others with 1.
fn classify(e: ReportError) -> anyhow::Error {
    if e.is_input_error() {
        BadInput(e.to_string()).into()
    } else {
        anyhow::Error::new(e)
    }
}
