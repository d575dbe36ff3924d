//! `gyrocal fit`: fit models to measured data files and report them.

use std::fmt::Write as _;
use std::io::{BufWriter, Write as _};
use std::path::PathBuf;

use anyhow::Context as _;
use clap::{Args, ValueEnum};
use gyrocal_fit::{
    Analysis, Columns, Fit, Method, Model, MultiAnalysis, MultiWithPointResiduals, NeuronOptions,
    NeuronStatus, Options, POINT_RESIDUALS_MAX, ResidualDetail, TrainingData, Weighting,
    WithPointResiduals, analyze_columns, input,
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
    /// CSV files with columns rate_dps and volts (optional volts_std, n). Several files: each is
    /// fitted, and the repeatability across them is reported.
    #[arg(required = true, value_name = "FILE")]
    pub files: Vec<PathBuf>,
    /// Print exactly one JSON document on stdout instead of the human report.
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
fn read(path: &std::path::Path) -> anyhow::Result<Columns> {
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
        match (analyses.len(), stream) {
            (1, false) => serde_json::to_writer_pretty(&mut stdout, &analyses[0]),
            (1, true) => serde_json::to_writer_pretty(
                &mut stdout,
                &WithPointResiduals::new(&analyses[0], &kept[0]),
            ),
            (_, false) => {
                serde_json::to_writer_pretty(&mut stdout, &MultiAnalysis::from_analyses(analyses))
            }
            (_, true) => serde_json::to_writer_pretty(
                &mut stdout,
                &MultiWithPointResiduals::new(&MultiAnalysis::from_analyses(analyses), &kept),
            ),
        }
        .context("writing the result to stdout")?;
        stdout.write_all(b"\n").context("writing to stdout")?;
    } else {
        let mut out = String::new();
        let multi = MultiAnalysis::from_analyses(analyses);
        for a in &multi.files {
            human(&mut out, a);
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

fn pm(v: Option<f64>, se: Option<f64>, digits: usize) -> String {
    match (v, se) {
        (Some(v), Some(se)) => format!("{v:.digits$} ± {se:.1e}"),
        (Some(v), None) => format!("{v:.digits$}"),
        _ => "-".to_string(),
    }
}

fn fit_label(f: &Fit) -> String {
    format!("{} {}", f.method, f.model)
}

/// Appends the human-readable summary and per-rate table of `a` to `out`.
pub(crate) fn human(out: &mut String, a: &Analysis) {
    let source = a.source.as_deref().unwrap_or("<data>");
    let weighted = a.fits.first().is_some_and(|f| f.weighted);
    let _ = writeln!(
        out,
        "== {source}: {} points, {}",
        a.points,
        if weighted {
            "weighted by 1/σ² (σ = volts_std/√n)"
        } else {
            "unweighted"
        }
    );
    let _ = writeln!(out);
    for s in &a.skipped {
        let _ = writeln!(out, "not fitted: {} — {}", s.model, s.reason);
    }
    if !a.skipped.is_empty() {
        let _ = writeln!(out);
    }
    let _ = writeln!(out, "fits (K [V/(°/s)], K0 [V]; ± one standard error)");
    for f in &a.fits {
        let c = &f.coefficients;
        let s = &f.std_errors;
        let mut line = format!("  {:<24}", fit_label(f));
        match f.model {
            Model::Split => {
                let _ = write!(
                    line,
                    " K+ = {}  K- = {}  K0 = {}",
                    pm(c.k_pos, s.k_pos, 7),
                    pm(c.k_neg, s.k_neg, 7),
                    pm(c.k0, s.k0, 6)
                );
            }
            _ => {
                let _ = write!(
                    line,
                    " K = {}  K0 = {}",
                    pm(c.k1, s.k1, 7),
                    pm(c.k0, s.k0, 6)
                );
                if c.k2.is_some() {
                    let _ = write!(line, "  K2 = {}", pm(c.k2, s.k2, 9));
                }
                if c.k3.is_some() {
                    let _ = write!(line, "  K3 = {}", pm(c.k3, s.k3, 11));
                }
            }
        }
        let _ = writeln!(out, "{line}");
        let _ = writeln!(
            out,
            "  {:<24} SSE {:.4e} V²  RMS {:.4} mV  max|r| {:.4} mV  R² {:.10}",
            "",
            f.sse,
            f.rms_residual * 1e3,
            f.max_abs_residual * 1e3,
            f.r_squared
        );
        if let Some(t) = &f.neuron {
            let status = match t.status {
                NeuronStatus::Converged => format!(
                    "converged after {} passes ({} online with momentum, {} full-batch)",
                    t.online_passes + t.batch_passes,
                    t.online_passes,
                    t.batch_passes
                ),
                NeuronStatus::MaxPasses => format!(
                    "NOT CONVERGED: stopped at the limit of {} passes",
                    t.online_passes + t.batch_passes
                ),
                NeuronStatus::Diverged { pass } => format!(
                    "DIVERGED at pass {pass} (η = {}): the result is the last finite weights, not a fit",
                    t.eta
                ),
            };
            let _ = writeln!(out, "  {:<24} {status}", "");
            if let TrainingData::RateBins { bins, points } = t.training_data {
                let limit = t
                    .online_pass_limit
                    .map(|l| format!(", online passes limited to {l}"))
                    .unwrap_or_default();
                let _ = writeln!(
                    out,
                    "  {:<24} online passes on the means of {bins} rate bins (continuous rates, above {} points), batch passes and errors over all {points} points{limit}",
                    "",
                    gyrocal_fit::neuron::RATE_MEANS_ABOVE_POINTS
                );
            }
            if let TrainingData::RateMeans { rates, points } = t.training_data {
                let limit = t
                    .online_pass_limit
                    .map(|l| format!(", online passes limited to {l}"))
                    .unwrap_or_default();
                let _ = writeln!(
                    out,
                    "  {:<24} online passes on the means of the {rates} rates (above {} points), batch passes and errors over all {points} points{limit}",
                    "",
                    gyrocal_fit::neuron::RATE_MEANS_ABOVE_POINTS
                );
            }
        }
    }
    let _ = writeln!(out);

    let ls = a.fit(Method::LeastSquares, Model::Linear);
    let nn = a.fit(Method::Neuron, Model::Linear);
    if let (Some(ls), Some(nn)) = (ls, nn) {
        let rel = if ls.sse > 0.0 {
            (nn.sse - ls.sse) / ls.sse
        } else {
            nn.sse - ls.sse
        };
        let verdict = if !nn.converged {
            format!(
                "the neuron did not converge; its SSE is {:.3}× that of least squares",
                nn.sse / ls.sse.max(f64::MIN_POSITIVE)
            )
        } else if rel.abs() <= 1e-9 {
            "the neuron reaches the least-squares line (SSE equal within 1e-9 relative): \
             it is the same estimate, not a better one"
                .to_string()
        } else if rel > 0.0 {
            format!(
                "the neuron's SSE is larger by {:.3e} relative: least squares fits better",
                rel
            )
        } else {
            "the neuron's SSE is below least squares only by rounding: the same estimate"
                .to_string()
        };
        let dk = (nn.scale_factor - ls.scale_factor) / ls.scale_factor;
        let _ = writeln!(
            out,
            "neuron vs least squares (linear): {verdict}; ΔK/K = {dk:.2e}"
        );
        let _ = writeln!(out);
    }
    if let Some(best) = a.best_model {
        let why = match &a.model_selection {
            Some(sel) => {
                let tests: Vec<String> = sel
                    .tests
                    .iter()
                    .map(|t| format!("{t}{}", if t.significant { " significant" } else { "" }))
                    .collect();
                format!(
                    "the simplest model whose added terms are significant, {} at level {}: {}",
                    sel.method,
                    sel.level,
                    tests.join("; ")
                )
            }
            None => "chosen by an earlier gyrocal (smallest residual standard error)".to_string(),
        };
        let _ = writeln!(out, "best model: {best} ({why})");
        if let (Some(lin), Some(b)) = (ls, a.fit(Method::LeastSquares, best))
            && best != Model::Linear
            && b.sse > 0.0
        {
            let _ = writeln!(
                out,
                "  it reduces the SSE of the line {:.1}-fold",
                lin.sse / b.sse
            );
        }
        let _ = writeln!(out);
    }

    // Per-rate table in the paper's layout.
    let best_fit = a.best_model.and_then(|m| a.fit(Method::LeastSquares, m));
    let mut header = format!("{:>10} {:>14}", "rate [°/s]", "measured [V]");
    if ls.is_some() {
        let _ = write!(header, " {:>17}", "LS resid. [mV]");
    }
    if nn.is_some() {
        let _ = write!(header, " {:>17}", "neuron resid. [mV]");
    }
    if let Some(b) = best_fit {
        let _ = write!(header, " {:>17}", format!("{} resid. [mV]", b.model));
    }
    let per_rate = a.fits.first().is_some_and(|f| !f.rate_residuals.is_empty());
    if per_rate {
        // One row per distinct rate (per rate bin on continuous data): the mean output and
        // the mean residuals.
        if let (ResidualDetail::PerRateBin, Some(b)) = (a.residual_detail, &a.rate_bins) {
            let _ = writeln!(
                out,
                "continuous rates ({} distinct, more than {}): one row per rate bin, {} bins of {:.4} °/s over [{}, {}] °/s (empty bins left out); the rate is the mean rate of the bin's points, the figures above are over every point",
                a.distinct_rates
                    .map_or_else(|| "?".to_string(), |d| d.to_string()),
                gyrocal_fit::RATE_GROUPS_MAX,
                b.bins,
                b.width_dps,
                b.lo_dps,
                b.hi_dps
            );
        }
        let mut header = format!("{:>10} {:>9} {:>14}", "rate [°/s]", "n", "mean [V]");
        if ls.is_some() {
            let _ = write!(header, " {:>17}", "LS mean r. [mV]");
        }
        if nn.is_some() {
            let _ = write!(header, " {:>17}", "neuron mean r. [mV]");
        }
        if let Some(b) = best_fit {
            let _ = write!(header, " {:>17}", format!("{} mean r. [mV]", b.model));
        }
        let _ = writeln!(out, "{header}");
        let Some(base) = a.fits.first() else {
            return;
        };
        for (i, r) in base.rate_residuals.iter().enumerate() {
            // A schedule's rates as written; a bin's mean rate to 0.1 m°/s.
            let rate = if r.rate_min_dps.is_some() {
                format!("{:.4}", r.rate_dps)
            } else {
                r.rate_dps.to_string()
            };
            let mut row = format!("{rate:>10} {:>9} {:>14.7}", r.n, r.mean_volts);
            for f in [ls, nn, best_fit].into_iter().flatten() {
                if let Some(fr) = f.rate_residuals.get(i) {
                    let _ = write!(row, " {:>+17.4}", fr.mean_residual * 1e3);
                }
            }
            let _ = writeln!(out, "{row}");
        }
    } else {
        let _ = writeln!(out, "{header}");
    }
    for i in 0..a.points {
        let Some(r) = a.fits.first().and_then(|f| f.residuals.get(i)) else {
            break;
        };
        let mut row = format!("{:>10} {:>14.7}", r.rate_dps, r.volts);
        for f in [ls, nn, best_fit].into_iter().flatten() {
            let _ = write!(row, " {:>+17.4}", f.residuals[i].residual * 1e3);
        }
        let _ = writeln!(out, "{row}");
    }
    let _ = writeln!(out);

    let m = &a.metrics;
    let _ = writeln!(out, "metrics (least squares)");
    let _ = writeln!(out, "  scale factor K        {:.7} V/(°/s)", m.scale_factor);
    let _ = writeln!(
        out,
        "  bias K0               {:.6} V = {:.4} °/s = {:.1} °/h",
        m.bias_volts, m.bias_dps, m.bias_dph
    );
    let _ = writeln!(
        out,
        "  nonlinearity          {:.1} ppm of F_m = {:.4} V (max |line − F_j| / max |F_j|)",
        m.nonlinearity_ppm, m.full_scale_output
    );
    match (
        m.asymmetry_ppm,
        m.scale_factor_positive,
        m.scale_factor_negative,
    ) {
        (Some(asym), Some(kp), Some(kn)) => {
            let _ = writeln!(
                out,
                "  asymmetry             {asym:.1} ppm (K+ = {kp:.7}, K- = {kn:.7} V/(°/s))"
            );
        }
        _ => {
            let reason = m
                .not_computed
                .iter()
                .find(|n| n.metric == "asymmetry_ppm")
                .map_or("needs both turning directions", |n| n.reason.as_str());
            let _ = writeln!(out, "  asymmetry             not computed: {reason}");
        }
    }
    if let Some(c) = &m.asymmetry_common_k2 {
        let _ = writeln!(
            out,
            "  asymmetry, common K2  {:.1} ± {:.1} ppm (1σ; one fit K0 + K+·ω⁺ + K−·ω⁻ + K2·ω², K2 = {:.3e} V/(°/s)²: not biased by the even-order term as the line pair above is)",
            c.asymmetry_ppm, c.asymmetry_std_error_ppm, c.k2
        );
    }
    if let Some(r) = m.repeatability_ppm {
        let _ = writeln!(out, "  repeatability         {r:.1} ppm");
    }
    let _ = writeln!(out);
    if let Some(u) = &a.uncertainty {
        let _ = writeln!(
            out,
            "expanded uncertainty (k = {}; budget in fit.json and the report)",
            u.coverage_factor
        );
        for q in &u.quantities {
            let _ = writeln!(
                out,
                "  {:<20}  {:.7e} ± {:.2e} {}{}",
                q.quantity,
                q.value,
                q.expanded_uncertainty,
                q.unit,
                q.relative_expanded_ppm
                    .map_or_else(String::new, |r| format!(" ({r:.1} ppm)"))
            );
        }
        let _ = writeln!(out);
    }
    if let Some(acc) = &a.acceptance {
        let _ = writeln!(out, "{}", verdict_line(acc));
        for c in &acc.checks {
            let _ = writeln!(
                out,
                "  {:<18} {:<13} {}{}",
                c.quantity.name(),
                c.verdict.label(),
                c.value
                    .map_or_else(|| "not measured".into(), |v| format!("{v:.7e} {}", c.unit)),
                c.reason
                    .as_deref()
                    .map_or_else(String::new, |r| format!(": {r}"))
            );
        }
        let _ = writeln!(out);
    }
}

/// "verdict: FAIL (simple rule): nonlinearity_ppm" — the run's verdict and the quantities
/// that make it.
pub fn verdict_line(acc: &gyrocal_fit::acceptance::Acceptance) -> String {
    let deciding: Vec<&str> = acc.deciding().map(|c| c.quantity.name()).collect();
    format!(
        "verdict: {} ({} rule){}",
        acc.verdict.label(),
        acc.rule.as_str(),
        if deciding.is_empty() {
            String::new()
        } else {
            format!(": {}", deciding.join(", "))
        }
    )
}
