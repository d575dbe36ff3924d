//! `gyrocal fit`: fit models to measured data files and report them.

use std::fmt::Write as _;
use std::io::{BufWriter, Write as _};
use std::path::PathBuf;

use anyhow::Context as _;
use clap::{Args, ValueEnum};
use gyrocal_fit::{
    Columns, Method, Model, MultiAnalysis, MultiWithPointResiduals, NeuronOptions, Options,
    POINT_RESIDUALS_MAX, Weighting, analyze_columns, input,
};

/// Above this many points the human report's table has one row per distinct rate (with the
/// number of points and mean residuals) instead of one row per point.
pub const HUMAN_POINT_ROWS_MAX: usize = 1_000;

/// The most points `--residuals` accepts in the human report (one table row per point, built
/// in memory: per-point residuals of five fits take 160 bytes a point, 320 MB here); a larger
/// file is refused with exit 2. `--json --residuals` has no such limit: the residuals are
/// computed while the document is written ([`gyrocal_fit::WithPointResiduals`]).
pub const RESIDUALS_POINTS_MAX: usize = 2_000_000;

use crate::BadInput;

/// A model, as spelled on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ModelArg {
    /// D = K0 + K1·ω
    Linear,
    /// D = K0 + K1·ω + K2·ω²
    Quadratic,
    /// D = K0 + K1·ω + K2·ω² + K3·ω³
    Cubic,
    /// separate lines for ω ≥ 0 and ω ≤ 0
    Split,
}

impl From<ModelArg> for Model {
    fn from(m: ModelArg) -> Self {
        match m {
            ModelArg::Linear => Model::Linear,
            ModelArg::Quadratic => Model::Quadratic,
            ModelArg::Cubic => Model::Cubic,
            ModelArg::Split => Model::Split,
        }
    }
}

/// A method, as spelled on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MethodArg {
    /// least squares (QR), every model
    LeastSquares,
    /// the paper's neuron (gradient descent with momentum), linear model only
    Neuron,
}

impl From<MethodArg> for Method {
    fn from(m: MethodArg) -> Self {
        match m {
            MethodArg::LeastSquares => Method::LeastSquares,
            MethodArg::Neuron => Method::Neuron,
        }
    }
}

/// Arguments of `gyrocal fit`.
#[derive(Debug, Args)]
pub struct FitArgs {
    /// CSV files with columns rate_dps and volts (optional volts_std, n), or run directories
    /// (their steps.csv). Several: each is fitted, and the repeatability across them is
    /// reported.
    #[arg(required = true, value_name = "FILE")]
    pub files: Vec<PathBuf>,
    /// Print exactly one JSON document on stdout instead of the human report, of one shape
    /// whatever the number of files: `{"files": [ANALYSIS, ...], "scale_factors": [K, ...],
    /// "repeatability_ppm": R}`, one ANALYSIS per FILE in the order given (the shape of a run's
    /// fit.json; `jq '.files[0]'` for one file) and `repeatability_ppm` null for one file.
    /// Changed after 0.1.0 (deprecation note): one file printed the bare ANALYSIS, several
    /// this object; a script that read `.metrics` of one file reads `.files[0].metrics` now.
    #[arg(long)]
    pub json: bool,
    /// Model to fit (repeatable, or a comma list: `--model linear,quadratic`). Default: every
    /// model the data can determine (the others are skipped with the reason). A model named
    /// here that the data cannot determine is an error.
    #[arg(
        long = "model",
        value_enum,
        value_name = "MODEL",
        value_delimiter = ','
    )]
    pub models: Vec<ModelArg>,
    /// Method to use (repeatable, or a comma list). Default: least squares for every model plus
    /// the neuron on the linear model.
    #[arg(
        long = "method",
        value_enum,
        value_name = "METHOD",
        value_delimiter = ','
    )]
    pub methods: Vec<MethodArg>,
    /// Ignore volts_std/n and weight every point equally.
    #[arg(long)]
    pub unweighted: bool,
    /// Neuron: learning rate η of the online passes (normalised units).
    #[arg(long, default_value_t = NeuronOptions::default().eta)]
    pub eta: f64,
    /// Neuron: momentum α.
    #[arg(long, default_value_t = NeuronOptions::default().alpha)]
    pub alpha: f64,
    /// Neuron: tolerance ε on the relative change of the pass error (ends the online passes).
    #[arg(long, default_value_t = NeuronOptions::default().epsilon)]
    pub epsilon: f64,
    /// Neuron: maximum number of passes.
    #[arg(long, default_value_t = NeuronOptions::default().max_passes)]
    pub max_passes: u64,
    /// Neuron: seed of the random initial weight and threshold.
    #[arg(long, default_value_t = NeuronOptions::default().seed)]
    pub seed: u64,
    /// Neuron: online passes only, as in the paper (stops near, not at, the minimum).
    #[arg(long)]
    pub no_batch_finish: bool,
    /// Per-point residuals in every fit whatever the size of the data. Without it, data sets
    /// of more than 10000 points (1000 in the human report) get per-rate summaries instead
    /// (JSON `rate_residuals`, one table row per rate; per rate bin on continuous data, more
    /// than 200 distinct rates). With --json they are written as they are computed, for any
    /// number of points (about 850 bytes of JSON a point for the five default fits); the
    /// human report takes at most 2000000 points.
    #[arg(long)]
    pub residuals: bool,
}

impl FitArgs {
    fn options(&self) -> anyhow::Result<Options> {
        for (name, v) in [
            ("--eta", self.eta),
            ("--alpha", self.alpha),
            ("--epsilon", self.epsilon),
        ] {
            if !v.is_finite() || v < 0.0 {
                return Err(
                    BadInput(format!("{name} must be a finite non-negative number")).into(),
                );
            }
        }
        let defaults = Options::default();
        Ok(Options {
            models: if self.models.is_empty() {
                defaults.models
            } else {
                self.models.iter().map(|&m| m.into()).collect()
            },
            methods: if self.methods.is_empty() {
                defaults.methods
            } else {
                self.methods.iter().map(|&m| m.into()).collect()
            },
            neuron: NeuronOptions {
                eta: self.eta,
                alpha: self.alpha,
                epsilon: self.epsilon,
                max_passes: self.max_passes,
                seed: self.seed,
                batch_finish: !self.no_batch_finish,
                ..NeuronOptions::default()
            },
            weighting: if self.unweighted {
                Weighting::Unweighted
            } else {
                Weighting::Auto
            },
            // Models asked for by name must be fitted; the default "every model" skips the
            // ones the data cannot determine and says so.
            skip_unsupported: self.models.is_empty(),
            // `--json --residuals` streams the per-point residuals from the data while writing
            // (below): the analysis itself keeps summaries above the usual limit.
            point_residuals_max: if self.residuals && !self.json {
                usize::MAX
            } else if self.json {
                POINT_RESIDUALS_MAX
            } else {
                HUMAN_POINT_ROWS_MAX
            },
            ..defaults
        })
    }
}

/// Reads one file into column arrays, streaming, through gyrocal's one CSV reader; errors name
/// the file (and the line). A regular file only: a named pipe or a device (`/dev/zero`) is
/// refused before it is opened. Memory is bounded by [`input::MAX_ROWS`] rows and
/// [`input::MAX_LINE_BYTES`] a line. A UTF-8 byte-order mark (Excel's) is skipped.
///
/// A run directory is read by its `steps.csv` (the step means the run's own fit uses); any
/// other directory is refused naming what to give.
fn read(path: &std::path::Path) -> anyhow::Result<Columns> {
    let steps = path.join(gyrocal_files::rundir::STEPS_CSV);
    let path = if path.is_dir() {
        if !steps.is_file() {
            return Err(BadInput(format!(
                "{}: a directory without {}: give a data file (CSV with rate_dps and volts) or a run directory",
                path.display(),
                gyrocal_files::rundir::STEPS_CSV
            ))
            .into());
        }
        steps.as_path()
    } else {
        path
    };
    input::read_columns(path).map_err(|e| BadInput(e.to_string()).into())
}

/// Runs `gyrocal fit`.
pub fn run(args: &FitArgs) -> anyhow::Result<()> {
    let opts = args.options()?;
    let mut analyses = Vec::new();
    // `--json --residuals`: the columns of every file, to write each point's residuals from.
    let stream = args.json && args.residuals;
    let mut kept: Vec<Columns> = Vec::new();
    for path in &args.files {
        let data = read(path)?;
        if args.residuals && !args.json && data.len() > RESIDUALS_POINTS_MAX {
            return Err(BadInput(format!(
                "{}: {} points: --residuals in the human report (one row per point) is limited to {RESIDUALS_POINTS_MAX} points; with --json it is not (the residuals are written as they are computed); without it the fits carry per-rate residuals",
                path.display(),
                data.len()
            ))
            .into());
        }
        let _span = tracing::info_span!("fit", file = %path.display()).entered();
        let analysis = analyze_columns(&data, &opts).map_err(|e| {
            let name = path.display();
            let place = match data.last_line {
                Some(l) => format!("line {l} (end of data)"),
                None => "no data rows".to_string(),
            };
            let hint = if args.models.is_empty() {
                ""
            } else {
                " (asked for with --model; without --model the models the data cannot determine are skipped)"
            };
            BadInput(format!("{name}: {place}: {e}{hint}"))
        })?;
        if stream {
            kept.push(data);
        }
        // Otherwise the columns are dropped here: one file's data in memory at a time.
        analyses.push(analysis);
    }
    let mut stdout = BufWriter::with_capacity(1 << 16, std::io::stdout().lock());
    if args.json {
        // Straight to stdout: no copy of the document in memory; with --residuals each
        // point's residuals are computed as they are written.
        // One shape whatever the number of files (`{"files": [...], ...}`, see --json).
        let multi = MultiAnalysis::from_analyses(analyses);
        if stream {
            serde_json::to_writer_pretty(&mut stdout, &MultiWithPointResiduals::new(&multi, &kept))
        } else {
            serde_json::to_writer_pretty(&mut stdout, &multi)
        }
        .context("writing the result to stdout")?;
        stdout.write_all(b"\n").context("writing to stdout")?;
    } else {
        let mut out = String::new();
        let multi = MultiAnalysis::from_analyses(analyses);
        for a in &multi.files {
            gyrocal_report::text::fit_summary(&mut out, a);
        }
        if multi.files.len() > 1 {
            let _ = writeln!(out, "== repeatability over {} files", multi.files.len());
            let ks: Vec<String> = multi
                .scale_factors
                .iter()
                .map(|k| format!("{k:.7}"))
                .collect();
            let _ = writeln!(
                out,
                "K_i (least-squares linear) [V/(°/s)]: {}",
                ks.join(", ")
            );
            if let Some(r) = multi.repeatability_ppm {
                let _ = writeln!(out, "repeatability std(K_i)/mean(K_i): {r:.1} ppm");
            }
        }
        stdout
            .write_all(out.as_bytes())
            .context("writing to stdout")?;
    }
    stdout.flush().context("writing to stdout")?;
    Ok(())
}
