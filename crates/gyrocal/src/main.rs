//! `gyrocal`: calibrate a gyroscope's scale factor on a rate table.
//!
//! Each subcommand lives in its own module under [`cmd`]; this file holds the argument
//! definitions and the dispatch. Errors the user can fix (a missing file, a bad value at some
//! line) are reported on one line with exit code 2; anything else exits with 1.

// The doc comments of this binary's argument types are clap's help text, read in a terminal:
// `[table]`, `runs/<plan>-<UTC time>` and URLs there are literal text, not rustdoc links or HTML.
#![allow(
    rustdoc::broken_intra_doc_links,
    rustdoc::invalid_html_tags,
    rustdoc::bare_urls
)]

mod chamber;
mod cmd;
mod examples;
mod instruments;
mod runlog;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// Calibrate a gyroscope's scale factor on a rate table.
#[derive(Debug, Parser)]
// every subcommand's long help and man page end with its examples (src/examples.rs)
#[command(name = "gyrocal", version, about, mut_subcommands = examples::attach)]
pub struct Cli {
    /// More log on stderr: -v info, -vv debug (RUST_LOG, when set, decides instead). Without
    /// it the terminal shows gyrocal's own messages only; a run's log is always in its
    /// run.log.
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    verbose: u8,
    #[command(subcommand)]
    command: Command,
}

/// The subcommands.
// parsed once per process: the size of `gyrocal run`'s many options costs nothing
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Subcommand)]
enum Command {
    /// Fit scale factor and bias to measured (rate, volts) data and report the metrics.
    Fit(cmd::fit::FitArgs),
    /// Validate a test plan and print its schedule and estimated duration.
    Check(cmd::check::CheckArgs),
    /// Run a calibration plan (on the instruments, or --simulate on the simulated bench).
    Run(cmd::run::RunArgs),
    /// Serve the simulated bench (34401A, rate table, gyro) on pseudo-terminals until SIGINT.
    Sim(cmd::sim::SimArgs),
    /// Write the HTML calibration report (with SVG plots) of run directories or steps CSV files.
    Report(cmd::report::ReportArgs),
    /// Check that the data files of completed runs are as recorded (SHA-256 in the manifest).
    Verify(cmd::verify::VerifyArgs),
    /// List the runs in the calibration catalog, newest first.
    Runs(cmd::runs::RunsArgs),
    /// A gyro's calibrations over time from the catalog: results, repeatability, trends.
    History(cmd::history::HistoryArgs),
    /// Fill the calibration catalog from run directories (import, rebuild).
    Catalog(cmd::catalog::CatalogArgs),
    /// Serve the runs' live view in a browser: dashboard, run pages, gyro history (read-only).
    Serve(cmd::serve::ServeArgs),
    // the one-line summary here; `gyrocal allan --help` shows the arguments' own long text
    #[command(
        about = "Allan deviation, noise terms, bias stability and warm-up of a drift record (run directory or CSV)"
    )]
    Allan(Box<cmd::allan::AllanArgs>),
    /// Print the shell completion script for SHELL (bash, zsh, fish, elvish, powershell).
    Completions(cmd::completions::CompletionsArgs),
    /// Print the man page (roff), or write one page per subcommand into a directory.
    Man(cmd::completions::ManArgs),
}

/// An error caused by the user's input (file, values, options): exit code 2.
#[derive(Debug)]
pub struct BadInput(pub String);

impl std::fmt::Display for BadInput {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for BadInput {}

/// A run directory's error with its exit code chosen by its kind: bad input (a malformed
/// file, a wrong path, a directory in use) exits 2 through [`BadInput`]; a failure of the
/// environment (a full disk, an I/O error) or of gyrocal itself exits 1. `context` (e.g.
/// `--resume`) goes before the message.
pub fn run_dir_error(e: gyrocal_files::RunError, context: Option<&str>) -> anyhow::Error {
    use gyrocal_files::rundir::RunErrorKind;
    let text = match context {
        Some(c) => format!("{c}: {e}"),
        None => e.to_string(),
    };
    match e.kind() {
        RunErrorKind::Input | RunErrorKind::Busy => BadInput(text).into(),
        RunErrorKind::Environment | RunErrorKind::Internal => anyhow::Error::msg(text),
    }
}

fn main() -> ExitCode {
    use tracing_subscriber::layer::SubscriberExt as _;
    use tracing_subscriber::util::SubscriberInitExt as _;
    use tracing_subscriber::{EnvFilter, Layer as _, filter::LevelFilter, fmt};
    let cli = Cli::parse();
    // The console shows gyrocal's own messages; the log only when asked for (-v, RUST_LOG),
    // and in colour only on a terminal without NO_COLOR.
    let filter = match (std::env::var_os("RUST_LOG"), cli.verbose) {
        (Some(_), _) => {
            EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("warn"))
        }
        (None, 0) => EnvFilter::new("off"),
        (None, 1) => EnvFilter::new("info"),
        (None, _) => EnvFilter::new("debug"),
    };
    let console = fmt::layer()
        .with_writer(std::io::stderr)
        .with_ansi(cmd::color_on_stderr())
        .with_filter(filter);
    // gyrocal run plugs its run directory's run.log in here (see runlog)
    let file = fmt::layer()
        .with_writer(runlog::RunLog)
        .with_ansi(false)
        .with_filter(LevelFilter::INFO);
    tracing_subscriber::registry()
        .with(console)
        .with(file)
        .init();
    let result = match cli.command {
        Command::Fit(args) => cmd::fit::run(&args).map(|()| 0),
        Command::Check(args) => cmd::check::run(&args).map(|()| 0),
        Command::Run(args) => cmd::run::run(&args),
        Command::Sim(args) => cmd::sim::run(&args).map(|()| 0),
        Command::Report(args) => cmd::report::run(&args).map(|()| 0),
        Command::Verify(args) => cmd::verify::run(&args),
        Command::Runs(args) => cmd::runs::run(&args),
        Command::History(args) => cmd::history::run(&args),
        Command::Catalog(args) => cmd::catalog::run(&args),
        Command::Serve(args) => cmd::serve::run(&args),
        Command::Allan(args) => cmd::allan::run(&args),
        Command::Completions(args) => cmd::completions::completions(&args).map(|()| 0),
        Command::Man(args) => cmd::completions::man(&args).map(|()| 0),
    };
    match result {
        Ok(code) => ExitCode::from(code),
        Err(err) => {
            let message = one_line(&err);
            eprintln!("gyrocal: error: {message}");
            if err.downcast_ref::<BadInput>().is_some() {
                ExitCode::from(2)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}

/// The error and its causes on one line. The libraries' errors already name their source in
/// their own message (so they read well alone); a cause whose text is already there is not
/// repeated.
fn one_line(err: &anyhow::Error) -> String {
    let mut message = String::new();
    for cause in err.chain() {
        let text = cause.to_string();
        if message.contains(&text) {
            continue;
        }
        if !message.is_empty() {
            message.push_str(": ");
        }
        message.push_str(&text);
    }
    message.replace('\n', " ")
}
