//! `gyrocal`: calibrate a gyroscope's scale factor on a rate table.
//!
//! Each subcommand lives in its own module under [`cmd`]; this file holds the argument
//! definitions and the dispatch. Errors the user can fix (a missing file, a bad value at some
//! line) are reported on one line with exit code 2; anything else exits with 1.

mod cmd;
mod instruments;
mod runlog;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// Calibrate a gyroscope's scale factor on a rate table.
#[derive(Debug, Parser)]
#[command(name = "gyrocal", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// The subcommands.
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

fn main() -> ExitCode {
    use tracing_subscriber::layer::SubscriberExt as _;
    use tracing_subscriber::util::SubscriberInitExt as _;
    use tracing_subscriber::{EnvFilter, Layer as _, filter::LevelFilter, fmt};
    let console = fmt::layer()
        .with_writer(std::io::stderr)
        .with_filter(EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("warn")));
    // gyrocal run plugs its run directory's run.log in here (see runlog)
    let file = fmt::layer()
        .with_writer(runlog::RunLog)
        .with_ansi(false)
        .with_filter(LevelFilter::INFO);
    tracing_subscriber::registry()
        .with(console)
        .with(file)
        .init();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Fit(args) => cmd::fit::run(&args).map(|()| 0),
        Command::Check(args) => cmd::check::run(&args).map(|()| 0),
        Command::Run(args) => cmd::run::run(&args),
        Command::Sim(args) => cmd::sim::run(&args).map(|()| 0),
        Command::Report(args) => cmd::report::run(&args).map(|()| 0),
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
