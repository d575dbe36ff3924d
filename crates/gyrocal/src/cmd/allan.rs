//! `gyrocal allan`: Allan deviation, noise terms, bias stability and warm-up of a drift record
//! (a run directory's samples.csv or any CSV). The analysis is `gyrocal_analysis::drift`, the
//! page `gyrocal_report::allan`; this module parses the options and prints.

use std::path::PathBuf;

use anyhow::Context as _;
use clap::{Args, ValueEnum};
use gyrocal_allan::{Estimator, TauSet};
use gyrocal_analysis::drift::{
    AllanDocument, AllanOptions, AnalysisPath, Axis, DEFAULT_MAX_MEMORY_MIB,
    DEFAULT_WARMUP_WINDOW_S, WarmupOptions, analyse_input, fmt_num,
};
use gyrocal_analysis::{DriftError, ErrorKind};
use gyrocal_report::ReportError;
use gyrocal_report::allan::{noise_name, noise_term_rows, render_allan, term_name};

use crate::BadInput;

/// The estimator (`--estimator`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum EstimatorArg {
    /// Overlapping Allan deviation (the default; the IEEE 952 reads assume it).
    Oadev,
    /// Non-overlapping Allan deviation.
    Adev,
    /// Modified Allan deviation.
    Mdev,
    /// Overlapping Hadamard deviation (insensitive to a linear rate drift).
    Ohdev,
    /// Total deviation (better confidence at long τ).
    Totdev,
}

impl From<EstimatorArg> for Estimator {
    fn from(e: EstimatorArg) -> Estimator {
        match e {
            EstimatorArg::Oadev => Estimator::Oadev,
            EstimatorArg::Adev => Estimator::Adev,
            EstimatorArg::Mdev => Estimator::Mdev,
            EstimatorArg::Ohdev => Estimator::Ohdev,
            EstimatorArg::Totdev => Estimator::Totdev,
        }
    }
}

fn parse_taus(s: &str) -> Result<TauSet, String> {
    match s {
        "octave" => Ok(TauSet::Octave),
        "decade" => Ok(TauSet::Decade),
        "all" => Ok(TauSet::All),
        _ => match s.strip_prefix("per-decade:").map(str::parse::<u32>) {
            Some(Ok(n)) if (1..=1000).contains(&n) => Ok(TauSet::PerDecade(n)),
            _ => Err(format!(
                "`{s}`: expected octave, decade, per-decade:N (N = 1..1000) or all"
            )),
        },
    }
}

fn positive(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("`{s}`: expected a finite number > 0")),
    }
}

fn non_negative(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!("`{s}`: expected a finite number ≥ 0")),
    }
}

/// Allan deviation, noise terms, bias stability and warm-up of a drift record.
///
/// Input: a run directory (its samples.csv: time t_s, value volts; rows with overload = 1 are
/// skipped and counted) or a CSV file with a header naming a value column (volts, value,
/// rate_dph in °/h, or --column) and optionally a time column (t_s or time, seconds; without
/// one --tau0 is required).
///
/// Sampling: τ0 is the median interval of the time column. An interval longer than 1.5 τ0 is a
/// gap (an interrupted and resumed recording, a skipped overload): the record is split into
/// gap-free segments and only the LONGEST segment is analysed; the output lists the segments
/// and says which one (JSON: "segments", "analysed"). In a drift run directory, gaps up to
/// 10 s (the re-arming between its segments; --join-gaps-below) are dead time, not breaks.
/// Intervals off τ0 by more than 10 % are counted and reported as irregular sampling.
///
/// Earth rate: --axis and --latitude (for a drift run directory, the plan's [drift] axis and
/// latitude_deg when the options are absent) remove the Earth's rate along the input axis
/// from the bias.
///
/// Units: with --scale-factor K (V/(°/s)) the values become rates (v/K)·3600 in °/h and the
/// noise terms are in IEEE 952 units (Q arcsec, N °/√h, B °/h, K °/h/√h, R °/h²). For a run
/// directory the run's fit.json supplies K when the option is absent (a simulated run: the
/// simulated gyro's K). Without K the curve is
/// in the input's unit and no noise term is computed.
///
/// Warm-up (IEEE 1431 §12.6): means of consecutive windows (--warmup-window, 60 s); the warm-up
/// is complete at the start of the first pair of consecutive windows whose means differ by less
/// than the tolerance (--warmup-tolerance, in the value column's unit; default 3 × the white-noise
/// σ of a window mean, σ_A(τ0)/√w), or at --warmup-max. The analysis and the bias figures use
/// the record after the warm-up. A run that watched its warm-up ([warmup] in its plan) is cut
/// with the run's window, maximum and the tolerance it used, unless these options say otherwise.
///
/// Memory: while the record fits the budget (--max-memory-mib, 1024 MiB; 16 bytes a sample of
/// the whole record) it is analysed in memory. A larger record, or any with --streaming, takes
/// the bounded path: the values go to unnamed temporary files (--temp-dir, else $TMPDIR; about
/// 16 bytes a sample of disk, removed at the end) and everything is computed from them through
/// fixed-size buffers, so the resident memory stays a few MiB however long the record. The
/// figures are the same, bit for bit; the output says which path ran (text: "memory:", JSON:
/// "memory", and a note for the bounded path).
///
/// Output: the curve (τ, m, σ, 68 %/95 % chi-squared intervals, EDF, noise type, τ > T/4
/// flagged), the noise terms by slope reads and by a weighted five-term fit, each ± its standard
/// uncertainty, the bias and the GJB bias stability over 10 s and 100 s. Exit 2 for a bad input
/// (naming the file and the line).
#[derive(Debug, Args)]
pub struct AllanArgs {
    /// A run directory or a CSV file.
    #[arg(value_name = "RUN_DIR|FILE.csv")]
    pub input: PathBuf,
    /// Scale factor K in V/(°/s): converts the values to a rate in °/h.
    #[arg(long, value_name = "K", allow_negative_numbers = true)]
    pub scale_factor: Option<f64>,
    /// The estimator.
    #[arg(long, value_enum, default_value = "oadev")]
    pub estimator: EstimatorArg,
    /// The averaging times: octave (1, 2, 4, … τ0), decade (1, 2, 4, 10, 20, 40, …),
    /// per-decade:N, or all (slow on long records).
    #[arg(long, value_name = "SET", default_value = "octave", value_parser = parse_taus)]
    pub taus: TauSet,
    /// Sample interval in seconds (required without a time column; overrides the median
    /// interval otherwise).
    #[arg(long, value_name = "S", value_parser = positive)]
    pub tau0: Option<f64>,
    /// The value column (default: volts, value or rate_dph).
    #[arg(long, value_name = "NAME")]
    pub column: Option<String>,
    /// Print exactly one JSON document (every figure) instead of the text.
    #[arg(long)]
    pub json: bool,
    /// Also write the HTML page (σ(τ) plot, noise terms, warm-up) to FILE.
    #[arg(short = 'o', long = "out", value_name = "FILE.html")]
    pub out: Option<PathBuf>,
    /// Window of the warm-up's rolling mean, s (0: no warm-up detection).
    #[arg(long, value_name = "S", default_value_t = DEFAULT_WARMUP_WINDOW_S, value_parser = non_negative)]
    pub warmup_window: f64,
    /// Change of consecutive window means below which the output is warmed up, in the value
    /// column's unit (default: 3 × the white-noise σ of a window mean).
    #[arg(long, value_name = "V", value_parser = positive)]
    pub warmup_tolerance: Option<f64>,
    /// The warm-up ends here at the latest, s.
    #[arg(long, value_name = "S", value_parser = non_negative)]
    pub warmup_max: Option<f64>,
    /// Join gaps up to S seconds as dead time instead of splitting the record there (default
    /// for a drift run directory: 10 s, the pause between its segments; else 0).
    #[arg(long, value_name = "S", value_parser = non_negative)]
    pub join_gaps_below: Option<f64>,
    /// Where the gyro's input axis points (up, down, north, south, east, west): with
    /// --latitude, the Earth's rate along it is removed from the reported bias.
    #[arg(long, value_name = "DIR", requires = "latitude", value_parser = parse_axis)]
    pub axis: Option<Axis>,
    /// The bench's latitude, degrees north (negative south), for --axis.
    #[arg(long, value_name = "DEG", requires = "axis", allow_hyphen_values = true, value_parser = latitude)]
    pub latitude: Option<f64>,
    /// Take the bounded-memory path whatever the record's size: the record goes to temporary
    /// files and is analysed through fixed-size buffers, with the same figures as in memory.
    #[arg(long)]
    pub streaming: bool,
    /// Memory budget of the in-memory path, MiB: a record that would take more (16 bytes a
    /// sample) takes the bounded path (0: always).
    #[arg(long, value_name = "MIB", default_value_t = DEFAULT_MAX_MEMORY_MIB)]
    pub max_memory_mib: u64,
    /// Directory of the bounded path's temporary files (default: $TMPDIR, else /tmp); on a disk,
    /// not a tmpfs, which keeps them in memory.
    #[arg(long, value_name = "DIR")]
    pub temp_dir: Option<PathBuf>,
}

fn parse_axis(s: &str) -> Result<Axis, String> {
    match s.trim().to_ascii_lowercase().as_str() {
        "up" => Ok(Axis::Up),
        "down" => Ok(Axis::Down),
        "north" => Ok(Axis::North),
        "south" => Ok(Axis::South),
        "east" => Ok(Axis::East),
        "west" => Ok(Axis::West),
        other => Err(format!(
            "{other:?}: write up, down, north, south, east or west"
        )),
    }
}

fn latitude(s: &str) -> Result<f64, String> {
    let v: f64 = s.trim().parse().map_err(|e| format!("{s:?}: {e}"))?;
    if (-90.0..=90.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{v} is not a latitude (-90 to 90 degrees)"))
    }
}

/// Input problems exit with 2, others with 1.
fn classify_analysis(e: DriftError) -> anyhow::Error {
    if e.kind() == ErrorKind::Input {
        BadInput(e.to_string()).into()
    } else {
        anyhow::Error::new(e)
    }
}

/// Input problems exit with 2, others with 1.
fn classify(e: ReportError) -> anyhow::Error {
    if e.is_input_error() {
        BadInput(e.to_string()).into()
    } else {
        anyhow::Error::new(e)
    }
}

/// Runs `gyrocal allan`.
pub fn run(args: &AllanArgs) -> anyhow::Result<u8> {
    let opts = AllanOptions {
        scale_factor: args.scale_factor,
        estimator: args.estimator.into(),
        taus: args.taus.clone(),
        tau0_s: args.tau0,
        column: args.column.clone(),
        warmup: WarmupOptions {
            window_s: args.warmup_window,
            tolerance: args.warmup_tolerance,
            max_s: args.warmup_max,
        },
        join_gaps_below_s: args.join_gaps_below,
        earth: args.axis.zip(args.latitude),
        streaming: args.streaming,
        max_memory_bytes: Some(args.max_memory_mib.saturating_mul(1024 * 1024)),
        temp_dir: args.temp_dir.clone(),
    };
    let doc = analyse_input(&args.input, &opts).map_err(classify_analysis)?;
    if let Some(out) = &args.out {
        let html = render_allan(&doc).map_err(classify)?;
        if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("{}: cannot create the directory", dir.display()))?;
        }
        std::fs::write(out, html).with_context(|| format!("{}: cannot write", out.display()))?;
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&doc)?);
    } else {
        print!("{}", text(&doc));
        if let Some(out) = &args.out {
            println!("page: {}", out.display());
        }
    }
    Ok(0)
}

/// The human output.
fn text(doc: &AllanDocument) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let unit = doc.unit.replace("deg", "°");
    let _ = writeln!(
        s,
        "{}: {} rows, column {}{}",
        doc.file.display(),
        doc.rows,
        doc.value_column,
        doc.time_column
            .as_ref()
            .map(|t| format!(", time {t}"))
            .unwrap_or_default()
    );
    let _ = writeln!(
        s,
        "tau0 = {} s ({}); deviation in {unit}{}",
        fmt_num(doc.tau0_s),
        doc.tau0_source,
        doc.scale_factor
            .as_ref()
            .map(|k| format!(" (scale factor {} V/(°/s))", k.v_per_dps))
            .unwrap_or_default()
    );
    let a = &doc.analysed;
    let _ = writeln!(
        s,
        "analysed: segment {} of {}, {} samples, t = {} s to {} s (T = {} s = {} h)",
        a.segment + 1,
        doc.segments.len(),
        a.samples,
        fmt_num(a.t_s.0),
        fmt_num(a.t_s.1),
        fmt_num(a.duration_s),
        fmt_num(a.duration_s / 3600.0)
    );
    let _ = writeln!(
        s,
        "memory: {} ({})",
        match doc.memory.path {
            AnalysisPath::InMemory => "in memory",
            AnalysisPath::Bounded => "bounded",
        },
        doc.memory.reason
    );
    if let Some(w) = &doc.warmup {
        let _ = writeln!(
            s,
            "warm-up: {} s ({}; {} s windows, tolerance {} {unit})",
            fmt_num(w.time_s),
            w.ended_by,
            fmt_num(w.window_s),
            fmt_num(w.tolerance)
        );
    }
    for n in &doc.notes {
        let _ = writeln!(s, "note: {}", gyrocal_report::allan::note_words(n));
    }
    let _ = writeln!(
        s,
        "\n{} ({unit})\n{:>10} {:>8} {:>11} {:>23} {:>23} {:>9}  noise",
        doc.curve.estimator.name(),
        "tau (s)",
        "m",
        "sigma",
        "68 % interval",
        "95 % interval",
        "edf"
    );
    for p in &doc.curve.points {
        let _ = writeln!(
            s,
            "{:>10} {:>8} {:>11} {:>23} {:>23} {:>9}  {}{}",
            fmt_num(p.tau_s),
            p.m,
            fmt_num(p.deviation),
            format!("{} – {}", fmt_num(p.ci68.0), fmt_num(p.ci68.1)),
            format!("{} – {}", fmt_num(p.ci95.0), fmt_num(p.ci95.1)),
            fmt_num(p.edf),
            noise_name(p.noise_alpha),
            if p.beyond_quarter {
                "  [tau > T/4]"
            } else {
                ""
            }
        );
    }
    match &doc.noise_terms {
        Some(nt) => {
            let _ = writeln!(s, "\nnoise terms (± 1 sigma):");
            for (t, slope, fit) in noise_term_rows(nt) {
                let _ = writeln!(
                    s,
                    "  {:<20} slope read: {}\n  {:<20} five-term fit: {}",
                    term_name(t),
                    slope,
                    "",
                    fit
                );
            }
            if let Some(f) = &nt.fit {
                let _ = writeln!(
                    s,
                    "  fit: {} points (tau <= T/4), reduced chi2 {}",
                    f.points_used,
                    fmt_num(f.chi2_reduced)
                );
            }
            for n in &nt.notes {
                let _ = writeln!(s, "  note: {}", gyrocal_report::allan::note_words(n));
            }
        }
        None => {
            let _ = writeln!(
                s,
                "\nnoise terms: need a rate in °/h: give --scale-factor K (V/(°/s))"
            );
        }
    }
    let b = &doc.bias;
    let _ = writeln!(s, "\nbias: {}", gyrocal_report::allan::pm(&b.bias));
    if let Some(e) = &doc.earth_rate {
        let _ = writeln!(
            s,
            "bias without the Earth rate: {} °/h (along the {:?} axis at latitude {}°: {} °/h removed)",
            fmt_num(e.bias_dph),
            e.axis,
            e.latitude_deg,
            fmt_num(e.component_dph)
        );
    }
    for (label, st) in [("10 s", &b.stability_10s), ("100 s", &b.stability_100s)] {
        match st {
            Some(x) => {
                let _ = writeln!(
                    s,
                    "bias stability ({label}, GJB 2426A): {} ({} windows)",
                    gyrocal_report::allan::pm(&x.stability),
                    x.windows
                );
            }
            None => {
                let _ = writeln!(s, "bias stability ({label}): fewer than two windows");
            }
        }
    }
    s
}
