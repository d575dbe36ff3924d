//! The Allan analysis of a drift record (`gyrocal allan`, `allan.json`).
//!
//! [`analyse_input`] reads a run directory (its `samples.csv`) or a CSV file into an
//! [`AllanDocument`]: the stability curve with EDF and chi-squared intervals, the IEEE 952 noise
//! terms, the bias and GJB 2426A bias stability, the warm-up, the gaps. It is what
//! `gyrocal allan --json` prints, what a drift run's `allan.json` holds and what the report
//! crate's drift page (`gyrocal_report::allan::render_allan`) renders.
//! Synchronous, no runtime: callable at the end of a drift run.
//!
//! # Input
//! * A run directory: `samples.csv` (`step_no,sample_no,t_s,rate_dps,volts,overload,t_utc`, or
//!   `step,index,...` in a run of format 2 or earlier), time `t_s`,
//!   value `volts`; rows with `overload = 1` are skipped and counted (each leaves a gap).
//!   When no scale factor is given, the run's `fit.json` (`metrics.scale_factor`) supplies it.
//! * A CSV file with a header: the value column is `--column`, else the first of `volts`,
//!   `value`, `rate_dph` (already °/h); the time column `t_s` or `time` (seconds), else τ0 must be
//!   given. An `overload` column, when present, is honoured as in `samples.csv`.
//!
//! The file is read with gyrocal's one CSV reader (`gyrocal-csv`, as `gyrocal fit` and
//! `gyrocal report` read theirs), streaming: one pass over the time column for τ0 (its
//! intervals kept for the median), one for the values and the segments. At most
//! [`MAX_INPUT_BYTES`]; a regular file only (a named pipe or a device is refused before it is
//! opened); a line of at most 1 MiB (a file without newlines is refused after reading that
//! much, before or after a valid header, naming the file and the line and never echoing it);
//! a UTF-8 byte-order mark skipped; lines counted over every line (comments included); a
//! column named twice refused.
//!
//! # Memory: two paths, the same figures
//! * **In memory** (the default while it fits): the intervals, then every value of the record,
//!   are held in memory ([`IN_MEMORY_BYTES_PER_SAMPLE`] = 16 bytes a sample at the peak: the
//!   value and a vector's growth), and the analysis runs on a `Record`.
//! * **Bounded** (`--streaming`, [`AllanOptions::streaming`], or automatically once the record
//!   would take more than the budget, [`AllanOptions::max_memory_bytes`], default
//!   [`DEFAULT_MAX_MEMORY_MIB`] MiB, `--max-memory-mib`): the same passes write the intervals
//!   and the values to unnamed temporary files ([`AllanOptions::temp_dir`], default `$TMPDIR`;
//!   16 bytes a sample of disk at most, gone when the analysis ends, even after a crash), and
//!   everything is computed from the files through fixed-size buffers: the resident memory
//!   stays a few MiB whatever the record. Under an automatic switch the values already read
//!   (up to the budget) are written out and freed. The figures are the in-memory path's, bit
//!   for bit (module `bounded` says how; `tests/drift_bounded.rs` checks every field). Put
//!   `$TMPDIR` (or `--temp-dir`) on a disk: a `tmpfs` keeps the files in memory.
//!
//! [`AllanDocument::memory`] says which path ran and why; the bounded path also adds a note.
//!
//! # Sampling, gaps
//! τ0 is the median interval of the time column rounded to 9 significant digits (or the one
//! given). An interval more than
//! [`GAP_FACTOR`]·τ0 is a gap: the record is split into gap-free segments and the **longest**
//! is analysed (the document lists every segment and says which). Intervals within the
//! segments that differ from τ0 by more than [`IRREGULAR_FRACTION`] are counted and reported
//! (irregular sampling), not corrected. A time that does not increase is an error naming the
//! line.
//!
//! # Units
//! With a scale factor K (V/(°/s)) every value v becomes the rate (v / K)·3600 in °/h and the
//! noise terms come out in their IEEE 952 units. A `rate_dph` column is already °/h. Otherwise
//! the curve is in the input's unit and no noise term is computed (they need a rate in °/h).
//! The bias is the mean of the analysed rate: the gyro's bias as an equivalent rate, including
//! whatever the input axis sees of the Earth's rate.
//!
//! # Warm-up (IEEE 1431 §12.6)
//! On the analysed segment: the means of consecutive non-overlapping windows of
//! [`WarmupOptions::window_s`] (default 60 s). The warm-up is complete at the start of the first
//! pair of consecutive windows whose means differ by less than the tolerance, or at
//! [`WarmupOptions::max_s`] if that comes first. Default tolerance: 3 × the white-noise
//! standard deviation of a window mean, estimated from the segment as σ_A(τ0)/√w (the Allan
//! deviation at τ0, which first differences make insensitive to a slow drift, scaled as white
//! noise to the w samples of a window). With the default tolerance a warm-up found is then
//! tested: it is cut only when the first window's mean differs from the mean where the
//! criterion settled by more than 3 × the record's own wander over the same span, measured in
//! the settled record (the robust spread of changes of window means that far apart). A record
//! whose level wanders (rate random walk, flicker) meets the criterion late by chance; without
//! this test that chance was cut as a "warm-up". The Allan analysis and the bias figures use
//! the record after the warm-up. A window of 0 turns the warm-up off.
//!
//! # Modules, by concern
//! * `input`: reading the record (pass 1: τ0; pass 2: the values and the gap-free segments);
//! * `warmup`: the warm-up criterion;
//! * `stability`: the stability curve, the bias figures and the IEEE 952 noise terms;
//! * `earth`: the Earth's rate removed from the bias;
//! * `bounded`: the bounded-memory path;
//! * `document`: the result, [`AllanDocument`] (`allan.json`), and [`DriftFigures`].

use std::path::{Path, PathBuf};

use gyrocal_allan::{Estimator, TauSet};
use gyrocal_files::rundir::{FIT_JSON, MAX_SAMPLES_BYTES, SAMPLES_CSV};
use serde::{Deserialize, Serialize};

use crate::DriftError;

mod bounded;
mod document;
mod earth;
mod input;
mod stability;
mod warmup;

use bounded::Samples;
pub use bounded::{AnalysisPath, DEFAULT_MAX_MEMORY_MIB, IN_MEMORY_BYTES_PER_SAMPLE, MemoryUse};
pub use document::{
    AllanDocument, Analysed, DriftFigures, EarthRateRemoved, RunHeader, ScaleFactorUsed, Segment,
    Warmup, WarmupSignificance, write_document,
};
pub use input::check_temp_dir;
use input::data_err;

/// Largest input file read (the limit of a run's `samples.csv`: about 10⁸ readings).
pub const MAX_INPUT_BYTES: u64 = MAX_SAMPLES_BYTES;
/// An interval longer than this many τ0 is a gap.
pub const GAP_FACTOR: f64 = 1.5;
/// An interval differing from τ0 by more than this fraction is irregular.
pub const IRREGULAR_FRACTION: f64 = 0.1;
/// Default warm-up tolerance, in white-noise standard deviations of a window mean.
pub use gyrocal_files::plan::DEFAULT_WARMUP_SIGMAS;
/// Default warm-up window, s: the plan's `[warmup] window_s` default, so a run's live
/// monitor and this analysis agree on "settled".
pub use gyrocal_files::plan::DEFAULT_WARMUP_WINDOW_S;

/// The warm-up criterion.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WarmupOptions {
    /// Window of the rolling mean, s (0: no warm-up detection).
    pub window_s: f64,
    /// Largest change between consecutive window means that counts as settled, in the unit of
    /// the value column (volts for volts); `None`: 3 × the white-noise σ of a window mean.
    pub tolerance: Option<f64>,
    /// The warm-up ends here at the latest, s from the start of the analysed segment.
    pub max_s: Option<f64>,
}

impl Default for WarmupOptions {
    fn default() -> Self {
        WarmupOptions {
            window_s: DEFAULT_WARMUP_WINDOW_S,
            tolerance: None,
            max_s: None,
        }
    }
}

/// How to analyse an input.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct AllanOptions {
    /// Scale factor K, V/(°/s): values become rates in °/h. `None`: the run's fit.json, if any.
    pub scale_factor: Option<f64>,
    /// The estimator (default overlapping ADEV).
    pub estimator: Estimator,
    /// The τ set (default octave).
    pub taus: TauSet,
    /// Sample interval, s; required without a time column, else it replaces the median interval
    /// (the time column still decides the gaps).
    pub tau0_s: Option<f64>,
    /// The value column (default: `volts`, `value` or `rate_dph`).
    pub column: Option<String>,
    /// The warm-up criterion.
    pub warmup: WarmupOptions,
    /// Gaps up to this long, s, are dead time, not breaks: the readings on both sides are
    /// analysed as one record (the dead time, reported, slightly biases σ at τ near the
    /// segment length for non-white noise). `None`: [`DRIFT_SEGMENT_JOIN_S`] for a drift run
    /// directory (its segments are separated by the table's at-rate check and the meter's
    /// re-arming), no joining otherwise.
    pub join_gaps_below_s: Option<f64>,
    /// Where the input axis points and the latitude, to remove the Earth's rate from the bias.
    /// `None`: a run directory's plan (`[drift] axis`, `latitude_deg`), if it has them.
    pub earth: Option<(Axis, f64)>,
    /// Take the bounded-memory path whatever the record's size (`--streaming`).
    pub streaming: bool,
    /// Memory budget of the in-memory path, bytes: a record that would take more (at
    /// [`IN_MEMORY_BYTES_PER_SAMPLE`]) takes the bounded path. `None`:
    /// [`DEFAULT_MAX_MEMORY_MIB`] MiB.
    pub max_memory_bytes: Option<u64>,
    /// Directory of the bounded path's temporary files. `None`: the system's (`$TMPDIR`).
    pub temp_dir: Option<PathBuf>,
}

/// Where a gyro's input axis points, and Earth's rotation rate: the plan's (`[drift] axis`).
pub use gyrocal_files::plan::{Axis, EARTH_RATE_DPH};

/// How long a gap between a drift run's segments may be and still be joined as dead time,
/// s: the at-rate stability window, the settle and the meter's re-arming between segments
/// take a few seconds; a longer gap is a real interruption and splits the record.
pub const DRIFT_SEGMENT_JOIN_S: f64 = 10.0;

fn fmt_g(v: f64) -> String {
    if !v.is_finite() {
        return "-".to_string();
    }
    if v == 0.0 {
        return "0".to_string();
    }
    let e = v.abs().log10().floor();
    if (-3.0..6.0).contains(&e) {
        let decimals = (3.0 - e).max(0.0) as usize;
        format!("{v:.decimals$}")
    } else {
        format!("{v:.3e}")
    }
}

/// A number with 4 significant digits (scientific outside 1e-3 … 1e6), `-` when not finite.
pub fn fmt_num(v: f64) -> String {
    fmt_g(v)
}

/// Reads a run directory or a CSV file and computes the whole Allan analysis (see the module
/// docs). Errors name the file and, where it applies, the line.
pub fn analyse_input(path: &Path, opts: &AllanOptions) -> Result<AllanDocument, DriftError> {
    let mut notes = Vec::new();
    let Source {
        is_run,
        file,
        manifest,
        join_below,
        warmup_opts,
        column,
    } = source(path, opts)?;

    // units
    let mut rdr = input::reader(&file)?;
    let cols = input::columns(&file, &mut rdr, column)?;
    let (scale_factor, factor, unit) = units(
        path,
        &file,
        &cols.value_name,
        manifest.as_ref().filter(|_| is_run),
        is_run,
        opts.scale_factor,
        &mut notes,
    )?;
    let is_rate = unit == "deg/h";

    // where the numbers are kept: in memory up to the budget, else in temporary files
    let budget = opts
        .max_memory_bytes
        .unwrap_or(DEFAULT_MAX_MEMORY_MIB * 1024 * 1024);
    let mut cap = if opts.streaming {
        0
    } else {
        usize::try_from(budget / IN_MEMORY_BYTES_PER_SAMPLE).unwrap_or(usize::MAX)
    };
    let temp_dir = opts.temp_dir.clone().unwrap_or_else(std::env::temp_dir);

    // τ0
    let (tau0, tau0_source, mut rdr) =
        input::sample_interval(&file, column, &cols, opts.tau0_s, &mut cap, &temp_dir, rdr)?;
    let cols = input::columns(&file, &mut rdr, column)?;

    // pass 2: the values and the segments
    let pass = input::RecordPass {
        file: &file,
        cols: &cols,
        rate_column: is_run,
        tau0,
        factor,
        join_below,
        cap,
        temp_dir: &temp_dir,
    };
    let input::RecordRead {
        values,
        mut segments,
        seg_start_idx,
        rows,
        overloads,
        irregular,
        first_irregular,
    } = pass.read(rdr, &mut notes)?;

    // the longest segment
    let si = longest_segment(&mut segments, &file, &mut notes)?;
    let join_gaps_hint_s = join_gaps_hint(&segments, &mut notes);
    let (seg_t0, seg_t1, seg_len) = segments
        .get(si)
        .map_or((0.0, 0.0, 0), |s| (s.t_s.0, s.t_s.1, s.samples));
    let record_samples = values.len();
    let samples = values.finish()?;
    let memory = bounded::memory_use(
        matches!(samples, Samples::Disk(_)),
        opts.streaming,
        record_samples,
        budget,
    );
    if memory.path == AnalysisPath::Bounded {
        notes.push(format!(
            "bounded-memory path ({}): the record was read into temporary files in {} and analysed from them through fixed-size buffers; the figures are those of the in-memory path",
            memory.reason,
            temp_dir.display()
        ));
    }
    let start = seg_start_idx.get(si).copied().unwrap_or(0);

    // warm-up
    let warmup = match &samples {
        Samples::Memory(values) => warmup::detect_warmup(
            values.get(start..start + seg_len).unwrap_or(&[]),
            tau0,
            seg_t0,
            factor,
            &warmup_opts,
            &mut notes,
        ),
        Samples::Disk(values) => bounded::detect_warmup_file(
            values,
            start..start + seg_len,
            tau0,
            seg_t0,
            factor,
            &warmup_opts,
            &mut notes,
        )
        .map_err(|e| bounded::temp_err(&temp_dir, e))?,
    };
    if let Some(sig) = warmup.as_ref().and_then(|w| w.significance.as_ref()) {
        notes.push(warmup_significance_note(sig, &unit));
    }
    let warmup_samples = warmup
        .as_ref()
        .map_or(0, |w| ((w.time_s / tau0).round() as usize).min(seg_len));
    if warmup_samples > 0 {
        notes.push(format!(
            "the first {} s of the analysed segment are warm-up ({warmup_samples} samples): the Allan analysis and the bias figures use the record after it",
            fmt_g(warmup_samples as f64 * tau0)
        ));
    }
    let n = seg_len - warmup_samples;
    if n < gyrocal_allan::MIN_SAMPLES {
        return Err(data_err(
            &file,
            None,
            format!("{n} sample(s) left to analyse after gaps and warm-up: too few"),
        ));
    }
    let t_first = seg_t0 + warmup_samples as f64 * tau0;
    let analysed = Analysed {
        segment: si,
        t_s: (t_first, seg_t1),
        samples: n,
        duration_s: n as f64 * tau0,
        warmup_samples,
    };
    let first = start + warmup_samples;

    // the stability curve, the bias, the noise terms
    let (curve, bias) = stability::curve_and_bias(
        samples,
        first..first + n,
        tau0,
        &unit,
        opts,
        &file,
        &temp_dir,
    )?;
    let noise_terms = stability::noise_terms_of(&curve, is_rate, &unit, &mut notes);
    // the option, else the run's plan (`[drift] axis` and `latitude_deg`)
    let earth = opts
        .earth
        .or_else(|| manifest.as_ref().and_then(|m| m.plan.drift().earth));
    let earth_rate = earth::removed(earth, is_rate, &bias, &mut notes);
    Ok(AllanDocument {
        run: manifest.as_ref().map(RunHeader::of),
        input: path.to_path_buf(),
        file,
        value_column: cols.value_name,
        time_column: cols.time.map(|t| t.1),
        unit,
        scale_factor,
        rows,
        overloads_skipped: overloads,
        tau0_s: tau0,
        tau0_source,
        irregular_intervals: irregular,
        first_irregular_line: first_irregular,
        segments,
        analysed,
        warmup,
        curve,
        noise_terms,
        bias,
        earth_rate,
        notes,
        join_gaps_hint_s,
        memory,
    })
}

/// What the input brings to its analysis besides the record: the file read (a run
/// directory's samples.csv), a run's manifest, and the options a run's plan sets when the
/// caller did not.
struct Source<'a> {
    /// The input is a run directory.
    is_run: bool,
    /// The file read.
    file: PathBuf,
    /// A run directory's manifest, read once: its plan's kind, its warm-up, its simulated gyro.
    manifest: Option<gyrocal_files::Manifest>,
    /// Gaps up to this long, s, are joined as dead time.
    join_below: Option<f64>,
    /// The warm-up criterion.
    warmup_opts: WarmupOptions,
    /// The value column asked for.
    column: Option<&'a str>,
}

/// The input's [`Source`], the options checked first (a typing error is bad input at once,
/// before a long record is read).
fn source<'a>(path: &Path, opts: &'a AllanOptions) -> Result<Source<'a>, DriftError> {
    if let Some(dir) = &opts.temp_dir {
        check_temp_dir(dir)?;
    }
    let is_run = path.is_dir();
    let file = if is_run {
        path.join(SAMPLES_CSV)
    } else {
        path.to_path_buf()
    };
    // a run directory's manifest, read once: its plan's kind and its simulated gyro
    let manifest = if is_run {
        gyrocal_files::load(path).ok().map(|r| r.manifest)
    } else {
        None
    };
    // a drift run's segments are joined across the meter's re-arming (the kind read once, by
    // the crate's one dispatch)
    let join_below = opts.join_gaps_below_s.or_else(|| {
        manifest
            .as_ref()
            .is_some_and(|m| crate::RunKind::of(m) == crate::RunKind::Drift)
            .then_some(DRIFT_SEGMENT_JOIN_S)
    });
    // a run that watched its warm-up (`[warmup]`): the same criterion, with the tolerance it
    // used, unless the options ask for another
    let warmup_opts = match manifest.as_ref().and_then(|m| m.warmup.as_ref()) {
        Some(w) if opts.warmup == WarmupOptions::default() => WarmupOptions {
            window_s: w.window_s,
            tolerance: w.tolerance_v,
            max_s: Some(w.max_s),
        },
        _ => opts.warmup.clone(),
    };
    if let Some(k) = opts.scale_factor
        && (!k.is_finite() || k == 0.0)
    {
        return Err(data_err(
            path,
            None,
            format!("scale factor {k}: must be finite and non-zero"),
        ));
    }
    if let Some(t) = opts.tau0_s
        && (!t.is_finite() || t <= 0.0)
    {
        return Err(data_err(
            path,
            None,
            format!("tau0 {t}: must be finite and > 0"),
        ));
    }
    let column = opts
        .column
        .as_deref()
        .or(if is_run { Some("volts") } else { None });
    Ok(Source {
        is_run,
        file,
        manifest,
        join_below,
        warmup_opts,
        column,
    })
}

/// What the test of a warm-up's significance found, in words.
fn warmup_significance_note(sig: &WarmupSignificance, unit: &str) -> String {
    let span = fmt_g(sig.span_s);
    match sig.wander {
        None => format!(
            "the warm-up of {span} s was not tested against the record's own wander: after it the record has {} pairs of windows {span} s apart (needs {})",
            sig.pairs,
            warmup::MIN_WANDER_PAIRS
        ),
        Some(w) if sig.significant => format!(
            "the warm-up of {span} s is more than the record's own wander: the start differs from the settled level by {} {unit}, more than {} × {} {unit} (the spread of changes over {span} s in the settled record, {} pairs)",
            fmt_g(sig.change),
            fmt_g(warmup::WARMUP_SIGNIFICANCE),
            fmt_g(w),
            sig.pairs
        ),
        Some(w) => format!(
            "no warm-up: the window means first agreed after {span} s, but the start differs from there by {} {unit}, within {} × the record's own wander over {span} s ({} {unit}, from {} settled pairs): that is the noise (a random walk or flicker meets the criterion late by chance), nothing is cut",
            fmt_g(sig.change),
            fmt_g(warmup::WARMUP_SIGNIFICANCE),
            fmt_g(w),
            sig.pairs
        ),
    }
}

/// The largest share of the record's span its gaps may take for the analysis to suggest
/// joining them (1 %: a resume's or a re-arming's seconds in hours of record; a long break,
/// where the gyro may have been switched off or moved, is not suggested).
pub const JOIN_GAPS_HINT_FRACTION: f64 = 0.01;

/// When the record has gaps, all of them short beside its span (together at most
/// [`JOIN_GAPS_HINT_FRACTION`] of it): the `--join-gaps-below` value that joins them, said in
/// a note. A whole second above the longest gap, so the value given back is not on its edge.
fn join_gaps_hint(segments: &[Segment], notes: &mut Vec<String>) -> Option<f64> {
    let gaps: Vec<f64> = segments
        .windows(2)
        .map(|w| w[1].t_s.0 - w[0].t_s.1)
        .filter(|g| g.is_finite())
        .collect();
    let longest = gaps.iter().copied().fold(f64::NAN, f64::max);
    let (first, last) = (segments.first()?, segments.last()?);
    let span = last.t_s.1 - first.t_s.0;
    let total: f64 = gaps.iter().sum();
    if gaps.is_empty() || !(longest > 0.0 && span > 0.0) || total > JOIN_GAPS_HINT_FRACTION * span {
        return None;
    }
    let hint = longest.floor() + 1.0;
    notes.push(format!(
        "the record's {} gap(s) take {} s of its {} s (the longest {} s, e.g. a resume): to analyse it as one record with the gaps as dead time, give --join-gaps-below {} (only if the gyro was left untouched across them)",
        gaps.len(),
        fmt_g(total),
        fmt_g(span),
        fmt_g(longest),
        fmt_g(hint)
    ));
    Some(hint)
}

/// Marks the longest segment (the first of equals) as the one analysed and says so when the
/// record has gaps; its index.
fn longest_segment(
    segments: &mut [Segment],
    file: &Path,
    notes: &mut Vec<String>,
) -> Result<usize, DriftError> {
    let (si, _) = segments
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.samples.cmp(&b.1.samples).then(b.0.cmp(&a.0)))
        .ok_or_else(|| data_err(file, None, "no samples"))?;
    if let Some(s) = segments.get_mut(si) {
        s.analysed = true;
    }
    if segments.len() > 1
        && let Some(s) = segments.get(si)
    {
        notes.push(format!(
            "the record has {} gap(s) (intervals > {GAP_FACTOR} τ0): {} segments; only the longest is analysed: segment {} of {}, lines {}–{}, t = {} s to {} s, {} samples",
            segments.len() - 1,
            segments.len(),
            si + 1,
            segments.len(),
            s.lines.0,
            s.lines.1,
            fmt_g(s.t_s.0),
            fmt_g(s.t_s.1),
            s.samples
        ));
    }
    Ok(si)
}

/// The scale factor (the option, else the run's `fit.json`, else a simulated run's gyro), the
/// factor every value is multiplied by, and the unit of the result (`deg/h`, `V` or the
/// column's).
fn units(
    path: &Path,
    file: &Path,
    value_name: &str,
    manifest: Option<&gyrocal_files::Manifest>,
    is_run: bool,
    option: Option<f64>,
    notes: &mut Vec<String>,
) -> Result<(Option<ScaleFactorUsed>, f64, String), DriftError> {
    let already_rate = value_name.eq_ignore_ascii_case("rate_dph");
    let scale_factor = match (option, already_rate) {
        (Some(_), true) => {
            return Err(data_err(
                file,
                Some(1),
                "the value column rate_dph is already a rate in °/h: --scale-factor does not apply",
            ));
        }
        (Some(k), false) => Some(ScaleFactorUsed {
            v_per_dps: k,
            source: "option".into(),
        }),
        (None, false) if is_run => match input::run_scale_factor(path) {
            Ok(Some(k)) => {
                notes.push(format!(
                    "scale factor K = {k} V/(°/s) from the run's fit.json (metrics.scale_factor); --scale-factor overrides it"
                ));
                Some(ScaleFactorUsed {
                    v_per_dps: k,
                    source: path.join(FIT_JSON).display().to_string(),
                })
            }
            // a simulated run's gyro has a known K: the plan's [simulation] scale_factor
            Ok(None) => match manifest {
                Some(m) if m.simulated => {
                    let k = m.plan.simulation().scale_factor;
                    notes.push(format!(
                        "scale factor K = {k} V/(°/s): the simulated gyro's ([simulation] scale_factor); --scale-factor overrides it"
                    ));
                    Some(ScaleFactorUsed {
                        v_per_dps: k,
                        source: "the simulated gyro ([simulation] scale_factor)".into(),
                    })
                }
                _ => None,
            },
            Err(e) => {
                notes.push(format!("no scale factor from fit.json: {e}"));
                None
            }
        },
        (None, _) => None,
    };
    let (factor, unit) = match (&scale_factor, already_rate) {
        (Some(k), _) => (3600.0 / k.v_per_dps, "deg/h".to_string()),
        (None, true) => (1.0, "deg/h".to_string()),
        (None, false) if value_name.eq_ignore_ascii_case("volts") => (1.0, "V".to_string()),
        (None, false) => (1.0, format!("unit of {value_name}")),
    };
    Ok((scale_factor, factor, unit))
}

/// The drift record's part of the analysis crate's one dispatch.
pub struct Kind;

impl crate::KindAnalysis for Kind {
    type Output = AllanDocument;
    type Options = AllanOptions;

    /// A drift record is analysed by Allan deviation, not fitted: nothing to warn about.
    fn plan_warnings(_plan: &gyrocal_files::Plan, _path: &Path) -> Vec<String> {
        Vec::new()
    }

    fn analyse(
        dir: &Path,
        _data: &gyrocal_files::rundir::RunData,
        opts: &AllanOptions,
    ) -> Result<AllanDocument, crate::AnalysisError> {
        Ok(analyse_input(dir, opts)?)
    }

    fn analyse_run(
        run: &mut gyrocal_files::RunDir,
        opts: &AllanOptions,
    ) -> Result<AllanDocument, crate::AnalysisError> {
        let doc = analyse_input(run.path(), opts)?;
        write_document(run, &doc)?;
        Ok(doc)
    }

    fn figures(
        dir: &Path,
        _m: &gyrocal_files::Manifest,
        _fit: Option<&serde_json::Value>,
    ) -> Result<Option<crate::Figures>, crate::AnalysisError> {
        Ok(DriftFigures::load(dir)?.map(|d| d.figures()))
    }
}
