//! The Allan analysis of a drift record and its HTML page (`gyrocal allan`).
//!
//! [`analyse_input`] reads a run directory (its `samples.csv`) or a CSV file into an
//! [`AllanDocument`]: the stability curve with EDF and chi-squared intervals, the IEEE 952 noise
//! terms, the bias and GJB 2426A bias stability, the warm-up, the gaps. It is what
//! `gyrocal allan --json` prints and what [`render_allan`] turns into a self-contained page.
//! Synchronous, no runtime: callable at the end of a drift run.
//!
//! # Input
//! * A run directory: `samples.csv` (`step,index,t_s,rate_dps,volts,overload,t_utc`), time `t_s`,
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
//!   for bit (module `bounded` says how; `tests/allan_bounded.rs` checks every field). Put
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
//! noise to the w samples of a window). The Allan analysis and the bias figures use the record
//! after the warm-up. A window of 0 turns the warm-up off.

use std::fmt::Write as _;
use std::fs::File;
use std::path::{Path, PathBuf};

use gyrocal_allan::{
    BiasFigures, Curve, DiskRecord, Estimator, NoiseTerms, Record, TauSet, Term, bias_figures,
    bias_figures_in, compute_record, noise_terms,
};
use gyrocal_files::rundir::{FIT_JSON, MAX_FIT_BYTES, MAX_SAMPLES_BYTES, SAMPLES_CSV};
use plotters::prelude::*;
use serde::{Deserialize, Serialize};

use crate::ReportError;
use crate::html::esc;

mod bounded;

pub use bounded::{AnalysisPath, DEFAULT_MAX_MEMORY_MIB, IN_MEMORY_BYTES_PER_SAMPLE, MemoryUse};
use bounded::{Samples, Spill};

/// Largest input file read (the limit of a run's `samples.csv`: about 10⁸ readings).
pub const MAX_INPUT_BYTES: u64 = MAX_SAMPLES_BYTES;
/// An interval longer than this many τ0 is a gap.
pub const GAP_FACTOR: f64 = 1.5;
/// An interval differing from τ0 by more than this fraction is irregular.
pub const IRREGULAR_FRACTION: f64 = 0.1;
/// Default warm-up window, s.
pub const DEFAULT_WARMUP_WINDOW_S: f64 = 60.0;
/// Default warm-up tolerance, in white-noise standard deviations of a window mean.
pub const DEFAULT_WARMUP_SIGMAS: f64 = 3.0;
/// Most points of the warm-up curve kept in the document.
const MAX_WARMUP_POINTS: usize = 2000;

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

/// What a run directory's record is and whose: the head of the page, as on a certificate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunHeader {
    /// The plan's name.
    pub plan_name: String,
    /// The plan's hash.
    pub plan_hash: String,
    /// `complete`, `aborted`, `failed` or `running`.
    pub status: String,
    /// The record was taken on the simulated bench.
    pub simulated: bool,
    /// The gyro's serial number and model, when named.
    pub dut_serial: Option<String>,
    /// The gyro's model.
    pub dut_model: Option<String>,
    /// The station's id and lab.
    pub station: Option<String>,
    /// Who ran it.
    pub operator: Option<String>,
    /// When the record started and ended, UTC.
    pub started_utc: String,
    /// When it ended (absent while running).
    pub ended_utc: Option<String>,
    /// The multimeter's identity.
    pub multimeter: Option<String>,
    /// The table's identity, and its role during the record.
    pub table: String,
    /// Departures from the method (`kind: text`).
    pub deviations: Vec<String>,
}

impl RunHeader {
    fn of(m: &gyrocal_files::Manifest) -> RunHeader {
        let d = m.plan.drift();
        let role = d.table.describe();
        RunHeader {
            plan_name: m.plan.name().to_string(),
            plan_hash: m.plan_hash.clone(),
            status: serde_json::to_value(m.status)
                .ok()
                .and_then(|v| v.as_str().map(str::to_string))
                .unwrap_or_default(),
            simulated: m.simulated,
            dut_serial: m.dut.as_ref().and_then(|d| d.serial.clone()),
            dut_model: m.dut.as_ref().and_then(|d| d.model.clone()),
            station: m.station.as_ref().map(|s| format!("{} — {}", s.id, s.lab)),
            operator: m.context.as_ref().and_then(|c| c.operator.clone()),
            started_utc: m.started_utc.clone(),
            ended_utc: m.ended_utc.clone(),
            multimeter: m.instruments.dmm.clone(),
            table: match (&m.instruments.table, d.table) {
                (_, gyrocal_files::plan::TableRole::None) => "none (the plan has no table)".into(),
                (Some(id), _) => format!("{id} ({role})"),
                (None, _) => format!("({role})"),
            },
            deviations: m
                .deviations
                .iter()
                .map(|x| format!("{}: {}", x.kind, x.text))
                .collect(),
        }
    }
}

/// The bias with the Earth rate removed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EarthRateRemoved {
    /// Input axis direction.
    pub axis: Axis,
    /// Latitude, degrees (north positive).
    pub latitude_deg: f64,
    /// Earth-rate component along the axis, °/h.
    pub component_dph: f64,
    /// The measured mean rate, °/h.
    pub bias_measured_dph: f64,
    /// The gyro's own bias: measured minus the component, °/h.
    pub bias_dph: f64,
}

/// How long a gap between a drift run's segments may be and still be joined as dead time,
/// s: the at-rate stability window, the settle and the meter's re-arming between segments
/// take a few seconds; a longer gap is a real interruption and splits the record.
pub const DRIFT_SEGMENT_JOIN_S: f64 = 10.0;

/// The scale factor used and where it came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScaleFactorUsed {
    /// K, V/(°/s).
    pub v_per_dps: f64,
    /// `option` (given) or the path of the fit.json it was read from.
    pub source: String,
}

/// A gap-free stretch of the record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Segment {
    /// 1-based line of its first and last row in the file.
    pub lines: (u64, u64),
    /// Time of its first and last sample, s (τ0-spaced indices without a time column).
    pub t_s: (f64, f64),
    /// Number of samples.
    pub samples: usize,
    /// This is the segment analysed.
    pub analysed: bool,
}

/// What was analysed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Analysed {
    /// Index into [`AllanDocument::segments`].
    pub segment: usize,
    /// Time of the first sample analysed (after the warm-up) and of the last, s.
    pub t_s: (f64, f64),
    /// Samples analysed (after the warm-up).
    pub samples: usize,
    /// Their duration N·τ0, s.
    pub duration_s: f64,
    /// Samples of the segment left out as warm-up.
    pub warmup_samples: usize,
}

/// The warm-up found on the analysed segment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Warmup {
    /// Window of the rolling mean, s (a whole number of samples).
    pub window_s: f64,
    /// Tolerance on the change of consecutive window means, in [`AllanDocument::unit`].
    pub tolerance: f64,
    /// `option` or `3 x white-noise sigma of a window mean (sigma_A(tau0)/sqrt(w))`.
    pub tolerance_source: String,
    /// The cap given, s.
    pub max_s: Option<f64>,
    /// Warm-up time from the start of the segment, s.
    pub time_s: f64,
    /// How it ended: `criterion`, `max` (capped), `not_reached` (never settled: nothing cut).
    pub ended_by: String,
    /// Window means: (time of the window's centre, s; mean in [`AllanDocument::unit`]), at most
    /// 2000 points (evenly decimated).
    pub curve: Vec<(f64, f64)>,
}

/// Everything `gyrocal allan` found: what `--json` prints and the page shows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AllanDocument {
    /// The input given.
    pub input: PathBuf,
    /// The file read (the run's samples.csv for a run directory).
    pub file: PathBuf,
    /// The value column.
    pub value_column: String,
    /// The time column, if any.
    pub time_column: Option<String>,
    /// Unit of the deviations and the bias: `deg/h`, or the input's (`V`, `unit of <column>`).
    pub unit: String,
    /// The scale factor used to convert volts to °/h.
    pub scale_factor: Option<ScaleFactorUsed>,
    /// Data rows read (including overloads).
    pub rows: u64,
    /// Rows skipped because overload = 1.
    pub overloads_skipped: u64,
    /// Sample interval, s.
    pub tau0_s: f64,
    /// `median interval of <column>` or `option`.
    pub tau0_source: String,
    /// Intervals within segments differing from τ0 by more than 10 %.
    pub irregular_intervals: u64,
    /// Line of the first irregular interval.
    pub first_irregular_line: Option<u64>,
    /// The gap-free segments, in file order.
    pub segments: Vec<Segment>,
    /// What was analysed.
    pub analysed: Analysed,
    /// The warm-up (`None` when off or the segment is shorter than two windows).
    pub warmup: Option<Warmup>,
    /// The stability curve.
    pub curve: Curve,
    /// The IEEE 952 noise terms (`None` without a rate in °/h).
    pub noise_terms: Option<NoiseTerms>,
    /// Bias and GJB bias stability over 10 s and 100 s, in [`AllanDocument::unit`].
    pub bias: BiasFigures,
    /// The bias with the Earth's rate along the input axis removed, when the axis and the
    /// latitude were given and the record is a rate in °/h.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub earth_rate: Option<EarthRateRemoved>,
    /// The run the record belongs to (a run directory's input; `None` for a CSV file).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub run: Option<RunHeader>,
    /// What the reader must be told (gaps, irregular sampling, skipped rows, units, warm-up).
    pub notes: Vec<String>,
    /// Which path analysed the record (in memory or bounded) and why.
    #[serde(default)]
    pub memory: MemoryUse,
}

/// A temporary directory the user named ([`AllanOptions::temp_dir`], `--temp-dir`) must exist,
/// be a directory and take a file: checked before the record is read, so a typing error is
/// bad input (exit 2) at once rather than a failure halfway through a long record. (The
/// default, `$TMPDIR`, is the environment's: its failures stay failures of the run.)
pub fn check_temp_dir(dir: &Path) -> Result<(), ReportError> {
    let problem = |message: String| data_err(dir, None, message);
    match std::fs::metadata(dir) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Err(problem(
            "no such directory (given as the directory for temporary files, --temp-dir)".into(),
        )),
        Err(e) => Err(problem(format!(
            "cannot use it as the directory for temporary files (--temp-dir): {e}"
        ))),
        Ok(m) if !m.is_dir() => Err(problem(
            "not a directory (given as the directory for temporary files, --temp-dir)".into(),
        )),
        Ok(_) => tempfile::tempfile_in(dir).map(drop).map_err(|e| {
            problem(format!(
                "cannot create a temporary file there (--temp-dir): {e}"
            ))
        }),
    }
}

fn data_err(path: &Path, line: Option<u64>, message: impl Into<String>) -> ReportError {
    ReportError::Data {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

struct Columns {
    value: usize,
    value_name: String,
    time: Option<(usize, String)>,
    overload: Option<usize>,
}

/// Opens a record: a regular file only (`gyrocal-csv`'s `open`: a named pipe or a device is
/// refused before it is opened), at most [`MAX_INPUT_BYTES`].
fn open_checked(path: &Path) -> Result<File, ReportError> {
    let file = gyrocal_csv::open(path).map_err(|e| csv_err(path, &e))?;
    let len = file.metadata().map_err(|source| ReportError::Io {
        path: path.to_path_buf(),
        action: "read",
        source,
    })?;
    let len = len.len();
    if len > MAX_INPUT_BYTES {
        return Err(data_err(
            path,
            None,
            format!(
                "{len} bytes: larger than the {} MiB limit of a record (about 10^8 readings); is it the right file?",
                MAX_INPUT_BYTES / (1024 * 1024)
            ),
        ));
    }
    Ok(file)
}

/// The record's CSV reader: gyrocal's one reader (`gyrocal-csv`: bounded lines, a byte-order
/// mark skipped, every line counted).
type CsvReader = gyrocal_csv::Reader<File>;

fn reader(path: &Path) -> Result<CsvReader, ReportError> {
    Ok(gyrocal_csv::Reader::new(
        open_checked(path)?,
        path.display().to_string(),
    ))
}

fn csv_err(path: &Path, e: &gyrocal_csv::Error) -> ReportError {
    use gyrocal_csv::ErrorKind;
    match e.kind() {
        ErrorKind::NotFound => data_err(path, None, "no such file or run directory"),
        ErrorKind::NotAFile => ReportError::NotAFile {
            path: path.to_path_buf(),
        },
        ErrorKind::NoHeader => data_err(
            path,
            Some(1),
            "no header line (expected a value column: volts, value or rate_dph)",
        ),
        _ => data_err(path, e.line(), e.detail()),
    }
}

fn columns(path: &Path, rdr: &mut CsvReader, wanted: Option<&str>) -> Result<Columns, ReportError> {
    let header = rdr.header().map_err(|e| csv_err(path, &e))?;
    let names = header.names();
    let line = Some(header.line());
    let find = |n: &str| header.find(n);
    let value = match wanted {
        Some(w) => find(w).map(|i| (i, w.to_string())).ok_or_else(|| {
            data_err(
                path,
                line,
                format!(
                    "the header has no `{w}` column (columns: {})",
                    names.join(", ")
                ),
            )
        })?,
        None => ["volts", "value", "rate_dph"]
            .iter()
            .find_map(|n| find(n).map(|i| (i, (*n).to_string())))
            .ok_or_else(|| {
                data_err(
                    path,
                    line,
                    format!(
                        "the header has no value column: volts, value or rate_dph (or name one with --column); columns: {}",
                        names.join(", ")
                    ),
                )
            })?,
    };
    let time = ["t_s", "time"]
        .iter()
        .find_map(|n| find(n).map(|i| (i, (*n).to_string())));
    Ok(Columns {
        value: value.0,
        value_name: value.1,
        time,
        overload: find("overload"),
    })
}

fn number(path: &Path, line: u64, column: &str, field: Option<&[u8]>) -> Result<f64, ReportError> {
    let text = field.map(String::from_utf8_lossy).unwrap_or_default();
    let text = text.trim();
    if text.is_empty() {
        return Err(data_err(path, Some(line), format!("`{column}` is empty")));
    }
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(v) => Err(data_err(
            path,
            Some(line),
            format!("`{column}` is not finite ({v})"),
        )),
        Err(_) => Err(data_err(
            path,
            Some(line),
            format!("`{column}` is not a number: {text:?}"),
        )),
    }
}

fn is_overload(rec: &gyrocal_csv::Row<'_>, cols: &Columns) -> bool {
    cols.overload
        .and_then(|i| rec.get(i))
        .is_some_and(|f| f == b"1")
}

/// Pass 1: the median interval of the time column (over rows that are not overloads), and
/// whether the intervals went to a temporary file (more than `cap` of them).
fn median_interval(
    path: &Path,
    column: Option<&str>,
    cap: usize,
    temp_dir: &Path,
) -> Result<(Option<f64>, bool), ReportError> {
    let mut rdr = reader(path)?;
    let cols = columns(path, &mut rdr, column)?;
    let Some((ti, tname)) = &cols.time else {
        return Ok((None, false));
    };
    let mut intervals = Spill::new(cap, temp_dir);
    let mut prev: Option<f64> = None;
    while let Some(rec) = rdr.next_row().map_err(|e| csv_err(path, &e))? {
        if is_overload(&rec, &cols) {
            continue;
        }
        let line = rec.line();
        let t = number(path, line, tname, rec.get(*ti))?;
        if let Some(p) = prev {
            intervals.push(t - p)?;
        }
        prev = Some(t);
    }
    let spilled = intervals.spilled();
    let mid = intervals.len() / 2;
    let m = match intervals.finish()? {
        Samples::Memory(mut intervals) => {
            if intervals.is_empty() {
                return Ok((None, spilled));
            }
            let (_, m, _) = intervals.select_nth_unstable_by(mid, f64::total_cmp);
            *m
        }
        Samples::Disk(file) => {
            match bounded::kth_smallest(&file, mid).map_err(|e| bounded::temp_err(temp_dir, e))? {
                Some(m) => m,
                None => return Ok((None, spilled)),
            }
        }
    };
    Ok((Some(round_significant(m, 9)), spilled))
}

/// `v` rounded to `digits` significant digits: a median of time differences carries the
/// rounding of the time stamps (0.1 s read as 0.10000000000002274 s).
fn round_significant(v: f64, digits: i32) -> f64 {
    if v == 0.0 || !v.is_finite() {
        return v;
    }
    let scale = 10f64.powi(digits - 1 - v.abs().log10().floor() as i32);
    (v * scale).round() / scale
}

/// The scale factor of a run's fit.json (`metrics.scale_factor`), or why there is none.
fn run_scale_factor(dir: &Path) -> Result<Option<f64>, String> {
    let path = dir.join(FIT_JSON);
    if !path.exists() {
        return Ok(None);
    }
    let bytes =
        gyrocal_files::rundir::read_capped(&path, MAX_FIT_BYTES).map_err(|e| e.to_string())?;
    let v: serde_json::Value =
        serde_json::from_slice(&bytes).map_err(|e| format!("{}: not JSON: {e}", path.display()))?;
    Ok(v["metrics"]["scale_factor"]
        .as_f64()
        .filter(|k| k.is_finite() && *k != 0.0))
}

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
pub fn analyse_input(path: &Path, opts: &AllanOptions) -> Result<AllanDocument, ReportError> {
    let mut notes = Vec::new();
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
    let join_below = opts.join_gaps_below_s.or_else(|| {
        manifest
            .as_ref()
            .is_some_and(|m| m.plan.kind() == gyrocal_files::PlanKind::Drift)
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
    let mut joined_gaps = 0usize;
    let mut dead_time_s = 0.0_f64;
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

    // units
    let mut rdr = reader(&file)?;
    let cols = columns(&file, &mut rdr, column)?;
    let already_rate = cols.value_name.eq_ignore_ascii_case("rate_dph");
    let scale_factor = match (opts.scale_factor, already_rate) {
        (Some(_), true) => {
            return Err(data_err(
                &file,
                Some(1),
                "the value column rate_dph is already a rate in °/h: --scale-factor does not apply",
            ));
        }
        (Some(k), false) => Some(ScaleFactorUsed {
            v_per_dps: k,
            source: "option".into(),
        }),
        (None, false) if is_run => match run_scale_factor(path) {
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
            Ok(None) => match &manifest {
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
        (None, false) if cols.value_name.eq_ignore_ascii_case("volts") => (1.0, "V".to_string()),
        (None, false) => (1.0, format!("unit of {}", cols.value_name)),
    };
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
    let (tau0, tau0_source) = match (opts.tau0_s, &cols.time) {
        (Some(t), _) => (t, "option".to_string()),
        (None, Some((_, name))) => {
            drop(rdr);
            let (m, spilled) = median_interval(&file, column, cap, &temp_dir)?;
            if spilled {
                cap = 0;
            }
            let m = m.ok_or_else(|| {
                data_err(&file, None, "fewer than two samples: no sample interval")
            })?;
            if !(m.is_finite() && m > 0.0) {
                return Err(data_err(
                    &file,
                    None,
                    format!("the median interval of {name} is {m} s: the time does not increase"),
                ));
            }
            rdr = reader(&file)?;
            (m, format!("median interval of {name}"))
        }
        (None, None) => {
            return Err(data_err(
                &file,
                Some(1),
                "no time column (t_s or time): give the sample interval with --tau0",
            ));
        }
    };
    let cols = columns(&file, &mut rdr, column)?;

    // pass 2: the values and the segments
    let mut values = Spill::new(cap, &temp_dir);
    let mut segments: Vec<Segment> = Vec::new();
    let mut seg_start_idx: Vec<usize> = Vec::new();
    let (mut rows, mut overloads, mut irregular) = (0u64, 0u64, 0u64);
    let mut first_irregular = None;
    let mut prev_t: Option<f64> = None;
    let (mut rate_lo, mut rate_hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let rate_col = if is_run {
        rdr.header().ok().and_then(|h| h.find("rate_dps"))
    } else {
        None
    };
    while let Some(rec) = rdr.next_row().map_err(|e| csv_err(&file, &e))? {
        rows += 1;
        if is_overload(&rec, &cols) {
            overloads += 1;
            continue;
        }
        let line = rec.line();
        let v = number(&file, line, &cols.value_name, rec.get(cols.value))?;
        let t = match &cols.time {
            Some((ti, tname)) => number(&file, line, tname, rec.get(*ti))?,
            _ => values.len() as f64 * tau0,
        };
        if let Some(ri) = rate_col
            && let Some(r) = rec
                .get(ri)
                .and_then(|f| std::str::from_utf8(f).ok())
                .and_then(|s| s.parse::<f64>().ok())
        {
            rate_lo = rate_lo.min(r);
            rate_hi = rate_hi.max(r);
        }
        let new_segment = match prev_t {
            None => true,
            Some(p) => {
                let dt = t - p;
                if dt <= 0.0 {
                    return Err(data_err(
                        &file,
                        Some(line),
                        format!("the time does not increase ({t} s after {p} s)"),
                    ));
                }
                if dt > GAP_FACTOR * tau0 {
                    if join_below.is_some_and(|j| dt <= j) {
                        joined_gaps += 1;
                        dead_time_s += dt - tau0;
                        false
                    } else {
                        true
                    }
                } else {
                    if (dt - tau0).abs() > IRREGULAR_FRACTION * tau0 {
                        irregular += 1;
                        first_irregular.get_or_insert(line);
                    }
                    false
                }
            }
        };
        if new_segment {
            seg_start_idx.push(values.len());
            segments.push(Segment {
                lines: (line, line),
                t_s: (t, t),
                samples: 0,
                analysed: false,
            });
        }
        if let Some(s) = segments.last_mut() {
            s.lines.1 = line;
            s.t_s.1 = t;
            s.samples += 1;
        }
        prev_t = Some(t);
        values.push(v * factor)?;
    }
    drop(rdr);
    if values.len() == 0 {
        return Err(data_err(&file, None, "no samples (only a header?)"));
    }
    if joined_gaps > 0 {
        notes.push(format!(
            "{joined_gaps} gap(s) of at most {} s joined as dead time ({} s in all, {:.2} % of the record): the readings on both sides are analysed as one record",
            fmt_g(join_below.unwrap_or(0.0)),
            fmt_g(dead_time_s),
            100.0 * dead_time_s / (values.len() as f64 * tau0 + dead_time_s).max(f64::MIN_POSITIVE)
        ));
    }
    if overloads > 0 {
        notes.push(format!(
            "{overloads} overload row(s) skipped (overload = 1; each leaves a gap in the record)"
        ));
    }
    if rate_hi > rate_lo {
        notes.push(format!(
            "the demanded rate varies from {rate_lo} to {rate_hi} °/s across the record: an Allan analysis assumes a constant input"
        ));
    }
    if irregular > 0 {
        notes.push(format!(
            "irregular sampling: {irregular} interval(s) differ from τ0 = {} s by more than {} % (first at line {}); analysed as if evenly spaced",
            fmt_g(tau0),
            IRREGULAR_FRACTION * 100.0,
            first_irregular.unwrap_or(0)
        ));
    }

    // the longest segment
    let (si, _) = segments
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.samples.cmp(&b.1.samples).then(b.0.cmp(&a.0)))
        .ok_or_else(|| data_err(&file, None, "no samples"))?;
    segments[si].analysed = true;
    if segments.len() > 1 {
        let s = &segments[si];
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
    let start = seg_start_idx[si];
    let seg_len = segments[si].samples;

    // warm-up
    let warmup = match &samples {
        Samples::Memory(values) => detect_warmup(
            &values[start..start + seg_len],
            tau0,
            segments[si].t_s.0,
            factor,
            &warmup_opts,
            &mut notes,
        ),
        Samples::Disk(values) => bounded::detect_warmup_file(
            values,
            start..start + seg_len,
            tau0,
            segments[si].t_s.0,
            factor,
            &warmup_opts,
            &mut notes,
        )
        .map_err(|e| bounded::temp_err(&temp_dir, e))?,
    };
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
    let t_first = segments[si].t_s.0 + warmup_samples as f64 * tau0;
    let analysed = Analysed {
        segment: si,
        t_s: (t_first, segments[si].t_s.1),
        samples: n,
        duration_s: n as f64 * tau0,
        warmup_samples,
    };
    let first = start + warmup_samples;
    let allan_err = |e: gyrocal_allan::Error| match e {
        gyrocal_allan::Error::Io(e) => bounded::temp_err(&temp_dir, e),
        e => data_err(&file, None, e.to_string()),
    };
    let (curve, bias) = match samples {
        Samples::Memory(mut values) => {
            values.truncate(first + n);
            values.drain(..first);
            let rec = Record::from_vec(values, tau0).map_err(allan_err)?;
            let curve = compute_record(&rec, opts.estimator, &opts.taus).map_err(allan_err)?;
            (curve, bias_figures(&rec, &unit))
        }
        Samples::Disk(values) => {
            let prefix = bounded::temp_file(&temp_dir)?;
            let rec = DiskRecord::from_samples(&values, first..first + n, prefix, tau0)
                .map_err(allan_err)?;
            drop(values);
            let curve = compute_record(&rec, opts.estimator, &opts.taus).map_err(allan_err)?;
            (curve, bias_figures_in(&rec, &unit).map_err(allan_err)?)
        }
    };
    let noise_terms = if is_rate {
        Some(noise_terms(&curve))
    } else {
        notes.push(format!(
            "the curve is in {unit}: the noise terms need a rate in °/h (give --scale-factor K in V/(°/s))"
        ));
        None
    };
    // the option, else the run's plan (`[drift] axis` and `latitude_deg`)
    let earth = opts
        .earth
        .or_else(|| manifest.as_ref().and_then(|m| m.plan.drift().earth));
    let earth_rate = match earth {
        Some((axis, latitude_deg)) if is_rate => {
            let component_dph = axis.earth_rate_dph(latitude_deg);
            Some(EarthRateRemoved {
                axis,
                latitude_deg,
                component_dph,
                bias_measured_dph: bias.bias.value,
                bias_dph: bias.bias.value - component_dph,
            })
        }
        Some(_) => {
            notes.push(
                "the Earth rate is not removed: the record is not a rate in °/h (give --scale-factor)"
                    .to_string(),
            );
            None
        }
        None => None,
    };
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
        memory,
    })
}

fn detect_warmup(
    y: &[f64],
    tau0: f64,
    t0: f64,
    factor: f64,
    opts: &WarmupOptions,
    notes: &mut Vec<String>,
) -> Option<Warmup> {
    let chunks = |r: std::ops::Range<usize>, f: &mut dyn FnMut(&[f64])| {
        f(y.get(r).unwrap_or(&[]));
        Ok(())
    };
    // reading a slice cannot fail
    detect_warmup_in(chunks, y.len(), tau0, t0, factor, opts, notes).unwrap_or(None)
}

/// The warm-up criterion over a segment of `n` samples handed over in chunks by `chunks(range,
/// f)` (a slice in memory; a file's buffers on the bounded path): one pass for the white-noise
/// σ when the tolerance is the default, one for the window means. Written once for both
/// paths, so their cuts are the same bits.
pub(crate) fn detect_warmup_in<F>(
    mut chunks: F,
    n: usize,
    tau0: f64,
    t0: f64,
    factor: f64,
    opts: &WarmupOptions,
    notes: &mut Vec<String>,
) -> std::io::Result<Option<Warmup>>
where
    F: FnMut(std::ops::Range<usize>, &mut dyn FnMut(&[f64])) -> std::io::Result<()>,
{
    if !(opts.window_s.is_finite() && opts.window_s > 0.0) {
        return Ok(None);
    }
    let w = (opts.window_s / tau0).round().max(1.0) as usize;
    let n_means = n / w;
    if n_means < 2 {
        notes.push(format!(
            "no warm-up detection: the analysed segment is shorter than two {} s windows",
            fmt_g(w as f64 * tau0)
        ));
        return Ok(None);
    }
    let (tolerance, tolerance_source) = match opts.tolerance {
        Some(t) => (t * factor.abs(), "option".to_string()),
        None => {
            let mut ss = 0.0_f64;
            let mut prev: Option<f64> = None;
            chunks(0..n, &mut |c: &[f64]| {
                for &v in c {
                    if let Some(p) = prev {
                        ss += (v - p).powi(2);
                    }
                    prev = Some(v);
                }
            })?;
            let sigma_a = (ss / (2.0 * (n - 1) as f64)).sqrt();
            (
                DEFAULT_WARMUP_SIGMAS * sigma_a / (w as f64).sqrt(),
                "3 x white-noise sigma of a window mean (sigma_A(tau0)/sqrt(w))".to_string(),
            )
        }
    };
    let window_s = w as f64 * tau0;
    let step = n_means.div_ceil(MAX_WARMUP_POINTS).max(1);
    let mut curve = Vec::with_capacity(n_means.min(MAX_WARMUP_POINTS));
    let mut found = None;
    let mut prev_mean: Option<f64> = None;
    let (mut i, mut in_window, mut acc) = (0usize, 0usize, 0.0_f64);
    chunks(0..n_means * w, &mut |c: &[f64]| {
        for &v in c {
            acc += v;
            in_window += 1;
            if in_window < w {
                continue;
            }
            let m = acc / w as f64;
            if found.is_none()
                && let Some(p) = prev_mean
                && (m - p).abs() < tolerance
            {
                found = Some((i - 1) as f64 * window_s);
            }
            if i % step == 0 {
                curve.push((t0 + (i as f64 + 0.5) * window_s, m));
            }
            prev_mean = Some(m);
            i += 1;
            in_window = 0;
            acc = 0.0;
        }
    })?;
    let (time_s, ended_by) = match (found, opts.max_s) {
        (Some(t), Some(m)) if t > m => (m, "max"),
        (Some(t), _) => (t, "criterion"),
        (None, Some(m)) => (m, "max"),
        (None, None) => {
            notes.push(
                "warm-up criterion never met (consecutive window means never agreed within the tolerance): nothing cut; give --warmup-max to cut"
                    .into(),
            );
            (0.0, "not_reached")
        }
    };
    Ok(Some(Warmup {
        window_s,
        tolerance,
        tolerance_source,
        max_s: opts.max_s,
        time_s,
        ended_by: ended_by.into(),
        curve,
    }))
}

// ---------------------------------------------------------------------------------------------
// The page

const CSS: &str = r#"
:root { color-scheme: light; }
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, Helvetica, Arial, sans-serif;
  color: #1a1a1a; background: #fff; margin: 0 auto; padding: 1rem 1.5rem 3rem; max-width: 64rem;
  line-height: 1.45; }
h1 { font-size: 1.6rem; margin: 0.5rem 0 0.25rem; }
h2 { font-size: 1.3rem; border-bottom: 1px solid #ccc; padding-bottom: 0.2rem; margin-top: 2rem; }
.sub { color: #555; margin: 0 0 1rem; }
.banner { border: 2px solid #7a4d00; background: #fff4d6; color: #4a2f00; padding: 0.75rem 1rem;
  border-radius: 4px; margin: 1rem 0; }
.note { color: #444; font-size: 0.95rem; }
table { border-collapse: collapse; margin: 0.5rem 0 1rem; font-size: 0.92rem; }
th, td { border: 1px solid #ccc; padding: 0.25rem 0.6rem; text-align: left; vertical-align: top; }
th { background: #f2f2f2; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
tr.beyond td { color: #888; }
figure { margin: 1rem 0 1.5rem; }
figure svg { display: block; width: 100%; max-width: 800px; height: auto; border: 1px solid #e3e3e3; }
figcaption { font-size: 0.92rem; color: #333; max-width: 800px; margin-top: 0.35rem; }
code { font-size: 0.9em; word-break: break-all; }
@media print {
  body { max-width: none; padding: 0; font-size: 10pt; }
  h2 { break-after: avoid; }
  figure, table, .banner { break-inside: avoid; }
  figure svg { max-width: 100%; border: none; }
  th { background: #fff; }
}
"#;

const FONT: &str = "sans-serif";
const LIGHT: RGBColor = RGBColor(235, 235, 235);
const BOLD: RGBColor = RGBColor(205, 205, 205);
const BLUE: RGBColor = RGBColor(31, 119, 180);
const TERM_COLORS: [RGBColor; 5] = [
    RGBColor(148, 103, 189),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(214, 39, 40),
    RGBColor(140, 86, 75),
];

type PlotResult = Result<(), Box<dyn std::error::Error>>;

fn draw(name: &str, f: impl FnOnce(&mut String) -> PlotResult) -> Result<String, ReportError> {
    let mut s = String::new();
    f(&mut s).map_err(|e| ReportError::Plot {
        name: name.to_string(),
        message: e.to_string(),
    })?;
    Ok(s)
}

/// Short name of a term.
pub fn term_name(t: Term) -> &'static str {
    match t {
        Term::Quantization => "quantization Q",
        Term::AngleRandomWalk => "angle random walk N",
        Term::BiasInstability => "bias instability B",
        Term::RateRandomWalk => "rate random walk K",
        Term::RateRamp => "rate ramp R",
    }
}

/// The noise type of a power-law exponent α, with the gyro term it corresponds to.
pub fn noise_name(alpha: i32) -> &'static str {
    match alpha {
        2 => "white PM (quantization)",
        1 => "flicker PM",
        0 => "white FM (ARW)",
        -1 => "flicker FM (bias inst.)",
        -2 => "random-walk FM (RRW)",
        _ => "?",
    }
}

fn basis(t: Term, tau: f64) -> f64 {
    match t {
        Term::Quantization => tau.powi(-2),
        Term::AngleRandomWalk => 1.0 / tau,
        Term::BiasInstability => 1.0,
        Term::RateRandomWalk => tau,
        Term::RateRamp => tau * tau,
    }
}

fn log_grid(lo: f64, hi: f64, n: usize) -> impl Iterator<Item = f64> {
    let (a, b) = (lo.ln(), hi.ln());
    (0..n).map(move |i| (a + (b - a) * i as f64 / (n - 1) as f64).exp())
}

fn curve_plot(doc: &AllanDocument) -> Result<String, ReportError> {
    draw("allan.svg", |s| {
        let root = SVGBackend::with_string(s, (800, 520)).into_drawing_area();
        root.fill(&WHITE)?;
        let pts: Vec<_> = doc
            .curve
            .points
            .iter()
            .filter(|p| p.deviation.is_finite() && p.deviation > 0.0)
            .collect();
        let (mut x0, mut x1) = (f64::INFINITY, 0.0f64);
        let (mut y0, mut y1) = (f64::INFINITY, 0.0f64);
        for p in &pts {
            x0 = x0.min(p.tau_s);
            x1 = x1.max(p.tau_s);
            for v in [p.deviation, p.ci95.0, p.ci95.1] {
                if v.is_finite() && v > 0.0 {
                    y0 = y0.min(v);
                    y1 = y1.max(v);
                }
            }
        }
        if !(x0.is_finite() && x1 > 0.0 && y0.is_finite() && y1 > 0.0) {
            (x0, x1, y0, y1) = (0.1, 10.0, 0.1, 10.0);
        }
        let (x0, x1, y0, y1) = (x0 / 1.5, x1 * 1.5, y0 / 2.0, y1 * 2.0);
        let unit = doc.unit.replace("deg", "°");
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!(
                    "{} of the rate record",
                    doc.curve.estimator.name().to_uppercase()
                ),
                (FONT, 20),
            )
            .margin(12)
            .x_label_area_size(48)
            .y_label_area_size(80)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())?;
        chart
            .configure_mesh()
            .x_desc("averaging time τ (s)")
            .y_desc(format!("σ(τ) ({unit})"))
            .x_label_formatter(&|v| format!("{v:.0e}"))
            .y_label_formatter(&|v| format!("{v:.1e}"))
            .axis_desc_style((FONT, 16))
            .label_style((FONT, 14))
            .light_line_style(LIGHT)
            .bold_line_style(BOLD)
            .draw()?;
        let within = |y: f64| y >= y0 && y <= y1 && y.is_finite();
        // slope guides through the minimum
        if let Some(pm) = pts
            .iter()
            .min_by(|a, b| a.deviation.total_cmp(&b.deviation))
        {
            let g = RGBColor(150, 150, 150);
            for (k, slope) in [-0.5f64, 0.0, 0.5].into_iter().enumerate() {
                let line: Vec<(f64, f64)> = log_grid(x0, x1, 60)
                    .map(|t| (t, pm.deviation * (t / pm.tau_s).powf(slope)))
                    .filter(|p| within(p.1))
                    .collect();
                let series =
                    chart.draw_series(DashedLineSeries::new(line, 5, 5, g.stroke_width(1)))?;
                if k == 0 {
                    series
                        .label("slope guides −½, 0, +½")
                        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], g));
                }
            }
        }
        // the fitted model and its terms
        if let Some(fit) = doc.noise_terms.as_ref().and_then(|n| n.fit.as_ref()) {
            for (k, term) in Term::ALL.iter().enumerate() {
                let c = fit.coefficients[k];
                if c <= 0.0 {
                    continue;
                }
                let col = TERM_COLORS[k];
                let line: Vec<(f64, f64)> = log_grid(x0, x1, 120)
                    .map(|t| (t, (c * basis(*term, t)).sqrt()))
                    .filter(|p| within(p.1))
                    .collect();
                chart
                    .draw_series(LineSeries::new(line, col.stroke_width(1)))?
                    .label(term_name(*term))
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], col));
            }
            let line: Vec<(f64, f64)> = log_grid(x0, x1, 200)
                .map(|t| (t, fit.variance(t).sqrt()))
                .filter(|p| within(p.1))
                .collect();
            chart
                .draw_series(LineSeries::new(line, BLACK.stroke_width(2)))?
                .label("five-term model (weighted fit)")
                .legend(|(x, y)| {
                    PathElement::new(vec![(x, y), (x + 24, y)], BLACK.stroke_width(2))
                });
        }
        let faded = BLUE.mix(0.35);
        chart
            .draw_series(
                pts.iter()
                    .filter(|p| p.ci95.0.is_finite() && p.ci95.1.is_finite())
                    .map(|p| {
                        let style = if p.beyond_quarter {
                            faded.stroke_width(1)
                        } else {
                            BLUE.stroke_width(1)
                        };
                        ErrorBar::new_vertical(
                            p.tau_s,
                            p.ci95.0.max(y0),
                            p.deviation,
                            p.ci95.1.min(y1),
                            style,
                            6,
                        )
                    }),
            )?
            .label("σ(τ) with 95 % interval (pale: τ > T/4)")
            .legend(|(x, y)| Circle::new((x + 12, y), 3, BLUE.filled()));
        chart.draw_series(pts.iter().map(|p| {
            let c = if p.beyond_quarter {
                faded.filled()
            } else {
                BLUE.filled()
            };
            Circle::new((p.tau_s, p.deviation), 3, c)
        }))?;
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font((FONT, 13))
            .background_style(WHITE.mix(0.9))
            .border_style(BOLD)
            .draw()?;
        root.present()?;
        Ok(())
    })
}

fn warmup_plot(doc: &AllanDocument, w: &Warmup) -> Result<String, ReportError> {
    draw("warmup.svg", |s| {
        let root = SVGBackend::with_string(s, (800, 400)).into_drawing_area();
        root.fill(&WHITE)?;
        let (mut x0, mut x1, mut y0, mut y1) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        for &(t, m) in &w.curve {
            x0 = x0.min(t);
            x1 = x1.max(t);
            y0 = y0.min(m);
            y1 = y1.max(m);
        }
        if !(x0.is_finite() && x1 > x0) {
            (x0, x1) = (0.0, 1.0);
        }
        if !(y0.is_finite() && y1 > y0) {
            let c = if y0.is_finite() { y0 } else { 0.0 };
            (y0, y1) = (c - 1.0, c + 1.0);
        }
        let pad = (y1 - y0) * 0.08;
        let (y0, y1) = (y0 - pad, y1 + pad);
        let unit = doc.unit.replace("deg", "°");
        let mut chart = ChartBuilder::on(&root)
            .caption("Warm-up: rolling mean of the output", (FONT, 20))
            .margin(12)
            .x_label_area_size(48)
            .y_label_area_size(90)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        chart
            .configure_mesh()
            .x_desc("time (s)")
            .y_desc(format!("{} s mean ({unit})", fmt_g(w.window_s)))
            .axis_desc_style((FONT, 16))
            .label_style((FONT, 14))
            .light_line_style(LIGHT)
            .bold_line_style(BOLD)
            .draw()?;
        chart
            .draw_series(LineSeries::new(
                w.curve.iter().copied(),
                BLUE.stroke_width(2),
            ))?
            .label("window means")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], BLUE.stroke_width(2)));
        let tw = doc.segments[doc.analysed.segment].t_s.0 + w.time_s;
        let red = RGBColor(214, 39, 40);
        chart
            .draw_series(DashedLineSeries::new(
                [(tw, y0), (tw, y1)],
                6,
                4,
                red.stroke_width(2),
            ))?
            .label(format!(
                "warm-up complete: {} s ({})",
                fmt_g(w.time_s),
                w.ended_by
            ))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], red.stroke_width(2)));
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font((FONT, 13))
            .background_style(WHITE.mix(0.9))
            .border_style(BOLD)
            .draw()?;
        root.present()?;
        Ok(())
    })
}

fn q(v: &gyrocal_allan::Quantity) -> String {
    format!(
        "{} ± {} {}",
        fmt_g(v.value),
        fmt_g(v.uncertainty),
        esc(&v.unit.replace("deg", "°"))
    )
}

/// The rows of the noise-term table: (term, slope read, five-term fit), plain text.
pub fn noise_term_rows(nt: &NoiseTerms) -> Vec<(Term, String, String)> {
    let plain = |v: &gyrocal_allan::Quantity| {
        format!("{} ± {} {}", fmt_g(v.value), fmt_g(v.uncertainty), v.unit)
    };
    Term::ALL
        .iter()
        .enumerate()
        .map(|(k, &t)| {
            let read = match t {
                Term::Quantization => nt.quantization.as_ref(),
                Term::AngleRandomWalk => nt.angle_random_walk.as_ref(),
                Term::RateRandomWalk => nt.rate_random_walk.as_ref(),
                Term::RateRamp => nt.rate_ramp.as_ref(),
                Term::BiasInstability => None,
            };
            let slope = match (t, read) {
                (Term::BiasInstability, _) => match &nt.bias_instability {
                    Some(b) => format!(
                        "{} (σ_min {} at τ = {} s{})",
                        plain(&b.value),
                        fmt_g(b.sigma_min.value),
                        fmt_g(b.tau_min_s),
                        if b.flat {
                            ""
                        } else {
                            "; not flat there: indicative"
                        }
                    ),
                    None => "-".into(),
                },
                (_, Some(r)) => format!(
                    "{} (line over τ {}–{} s, read at τ = {} s{})",
                    plain(&r.value),
                    fmt_g(r.tau_range_s.0),
                    fmt_g(r.tau_range_s.1),
                    fmt_g(r.read_at_tau_s),
                    if r.extrapolated { ", extrapolated" } else { "" }
                ),
                (_, None) => "- (no region of that slope)".into(),
            };
            let fit = nt
                .fit
                .as_ref()
                .and_then(|f| f.terms.get(k))
                .map_or("-".into(), |ft| {
                    if ft.at_zero {
                        format!(
                            "0 (held at zero; 1σ could be {} {})",
                            fmt_g(ft.value.uncertainty),
                            ft.value.unit
                        )
                    } else {
                        plain(&ft.value)
                    }
                });
            (t, slope, fit)
        })
        .collect()
}

/// The head of a run's page: whose record, where, by whom, when, with what; a simulated record
/// says so first.
fn render_run_header(h: &mut String, r: &RunHeader) {
    if r.simulated {
        h.push_str("<div class=\"banner\" id=\"simulated\"><strong>SIMULATED</strong>: this record was taken on gyrocal's simulated bench, not on instruments; it is not a measurement of a gyro.</div>\n");
    }
    h.push_str("<h2 id=\"run\">The record</h2>\n<table>\n");
    let mut row = |k: &str, v: String| {
        let _ = writeln!(h, "<tr><th>{}</th><td>{v}</td></tr>", esc(k));
    };
    row(
        "gyro",
        match (&r.dut_serial, &r.dut_model) {
            (Some(s), Some(m)) => {
                format!("<strong id=\"dut-serial\">{}</strong> ({})", esc(s), esc(m))
            }
            (Some(s), None) => format!("<strong id=\"dut-serial\">{}</strong>", esc(s)),
            (None, Some(m)) => format!("{} (serial not given)", esc(m)),
            (None, None) => "not identified (give --dut-serial, or [dut] in the plan)".into(),
        },
    );
    row(
        "station",
        r.station.as_deref().map_or("not identified".into(), esc),
    );
    row("operator", r.operator.as_deref().map_or("-".into(), esc));
    row(
        "performed (UTC)",
        format!(
            "{} to {}",
            esc(&r.started_utc),
            r.ended_utc.as_deref().map_or("(not ended)".into(), esc)
        ),
    );
    row(
        "plan",
        format!(
            "{} (hash <code>{}</code>), {}",
            esc(&r.plan_name),
            esc(r.plan_hash.get(..12).unwrap_or(&r.plan_hash)),
            esc(&r.status)
        ),
    );
    row(
        "multimeter",
        r.multimeter.as_deref().map_or("-".into(), esc),
    );
    row("rate table", esc(&r.table));
    if !r.deviations.is_empty() {
        row(
            "deviations",
            r.deviations
                .iter()
                .map(|d| esc(d))
                .collect::<Vec<_>>()
                .join("<br>"),
        );
    }
    h.push_str("</table>\n");
}

/// The self-contained HTML page of an Allan analysis: the σ(τ) plot with 95 % bars, the fitted
/// five-term model, each term and slope guides; the noise-term table; bias and bias stability;
/// the warm-up curve; the curve table; the notes.
pub fn render_allan(doc: &AllanDocument) -> Result<String, ReportError> {
    let mut h = String::with_capacity(64 * 1024);
    let name = doc.input.display().to_string();
    let unit = doc.unit.replace("deg", "°");
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>Allan analysis: {}</title>\n<style>{CSS}</style>\n</head>\n<body>\n<h1>Allan analysis of a gyro rate record</h1>\n<p class=\"sub\"><code>{}</code>: column <code>{}</code>{}, {} rows</p>\n",
        esc(&name),
        esc(&doc.file.display().to_string()),
        esc(&doc.value_column),
        doc.time_column
            .as_ref()
            .map(|t| format!(", time <code>{}</code>", esc(t)))
            .unwrap_or_default(),
        doc.rows
    );
    if let Some(r) = &doc.run {
        render_run_header(&mut h, r);
    }
    h.push_str("<table>\n");
    let mut row = |k: &str, v: String| {
        let _ = writeln!(h, "<tr><th>{}</th><td>{v}</td></tr>", esc(k));
    };
    row("estimator", esc(doc.curve.estimator.name()));
    row("deviation unit", esc(&unit));
    row(
        "scale factor",
        doc.scale_factor
            .as_ref()
            .map_or("none (input unit)".into(), |k| {
                format!("{} V/(°/s) ({})", k.v_per_dps, esc(&k.source))
            }),
    );
    row(
        "τ0",
        format!("{} s ({})", fmt_g(doc.tau0_s), esc(&doc.tau0_source)),
    );
    row(
        "analysed",
        format!(
            "segment {} of {}: {} samples, t = {} s to {} s, T = {} s ({} h)",
            doc.analysed.segment + 1,
            doc.segments.len(),
            doc.analysed.samples,
            fmt_g(doc.analysed.t_s.0),
            fmt_g(doc.analysed.t_s.1),
            fmt_g(doc.analysed.duration_s),
            fmt_g(doc.analysed.duration_s / 3600.0)
        ),
    );
    row(
        "warm-up",
        doc.warmup.as_ref().map_or("not detected".into(), |w| {
            format!(
                "{} s ({}; window {} s, tolerance {} {})",
                fmt_g(w.time_s),
                esc(&w.ended_by),
                fmt_g(w.window_s),
                fmt_g(w.tolerance),
                esc(&unit)
            )
        }),
    );
    h.push_str("</table>\n");
    if !doc.notes.is_empty() {
        h.push_str("<div class=\"banner\"><ul>\n");
        for n in &doc.notes {
            let _ = writeln!(h, "<li>{}</li>", esc(n));
        }
        h.push_str("</ul></div>\n");
    }
    let _ = write!(
        h,
        "<h2 id=\"curve\">Stability curve</h2>\n<figure>{}<figcaption>{} with 95 % chi-squared intervals (Greenhall EDF); pale points are τ > T/4 (too few averages to trust). Lines: the five-term model fitted by weighted least squares and each of its terms; dashed: slopes −½, 0, +½ through the minimum.</figcaption></figure>\n",
        curve_plot(doc)?,
        esc(doc.curve.estimator.name())
    );
    h.push_str("<h2 id=\"terms\">Noise terms (IEEE 952)</h2>\n");
    match &doc.noise_terms {
        Some(nt) => {
            h.push_str("<table id=\"noise-terms\">\n<tr><th>term</th><th>slope read (± 1σ)</th><th>five-term fit (± 1σ)</th></tr>\n");
            for (t, slope, fit) in noise_term_rows(nt) {
                let _ = writeln!(
                    h,
                    "<tr><td>{}</td><td>{}</td><td>{}</td></tr>",
                    esc(term_name(t)),
                    esc(&slope.replace("deg", "°")),
                    esc(&fit.replace("deg", "°"))
                );
            }
            h.push_str("</table>\n");
            if let Some(f) = &nt.fit {
                let _ = writeln!(
                    h,
                    "<p class=\"note\">Fit over {} points (τ ≤ T/4), reduced χ² = {}. N read at τ = 1 s on the −½ line, K at τ = 3 s on the +½ line, B = σ_min / 0.6643.</p>",
                    f.points_used,
                    fmt_g(f.chi2_reduced)
                );
            }
            for n in &nt.notes {
                let _ = writeln!(h, "<p class=\"note\">{}</p>", esc(n));
            }
        }
        None => h.push_str("<p class=\"banner\">No noise terms: the curve is not a rate in °/h. Give the scale factor (<code>--scale-factor K</code>, V/(°/s)).</p>\n"),
    }
    h.push_str("<h2 id=\"bias\">Bias and bias stability (GJB 2426A)</h2>\n<table>\n");
    let _ = writeln!(
        h,
        "<tr><th>bias (mean)</th><td class=\"num\">{}</td></tr>",
        q(&doc.bias.bias)
    );
    if let Some(e) = &doc.earth_rate {
        let _ = writeln!(
            h,
            "<tr><th>bias without the Earth rate</th><td class=\"num\" id=\"bias-earth-removed\">{} deg/h (Earth rate along the {:?} axis at latitude {}°: {} deg/h removed)</td></tr>",
            fmt_num(e.bias_dph),
            e.axis,
            fmt_g(e.latitude_deg),
            fmt_num(e.component_dph)
        );
    }
    for (label, st) in [
        ("bias stability, 10 s", &doc.bias.stability_10s),
        ("bias stability, 100 s", &doc.bias.stability_100s),
    ] {
        let v = st
            .as_ref()
            .map_or("- (fewer than two windows)".into(), |s| {
                format!("{} ({} windows)", q(&s.stability), s.windows)
            });
        let _ = writeln!(h, "<tr><th>{label}</th><td class=\"num\">{v}</td></tr>");
    }
    h.push_str("</table>\n");
    if let Some(w) = &doc.warmup {
        let _ = write!(
            h,
            "<h2 id=\"warmup\">Warm-up (IEEE 1431 §12.6)</h2>\n<figure>{}<figcaption>Means of consecutive {} s windows; the warm-up is complete when two consecutive means differ by less than {} {} ({}). The analysis uses the record after it.</figcaption></figure>\n",
            warmup_plot(doc, w)?,
            fmt_g(w.window_s),
            fmt_g(w.tolerance),
            esc(&unit),
            esc(&w.tolerance_source)
        );
    }
    h.push_str("<h2 id=\"points\">Curve</h2>\n<table id=\"curve-table\">\n<tr><th>τ (s)</th><th>m</th><th>σ</th><th>68 % interval</th><th>95 % interval</th><th>edf</th><th>noise</th></tr>\n");
    for p in &doc.curve.points {
        let _ = writeln!(
            h,
            "<tr{}><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{} – {}</td><td class=\"num\">{} – {}</td><td class=\"num\">{}</td><td>{}{}</td></tr>",
            if p.beyond_quarter {
                " class=\"beyond\""
            } else {
                ""
            },
            fmt_g(p.tau_s),
            p.m,
            fmt_g(p.deviation),
            fmt_g(p.ci68.0),
            fmt_g(p.ci68.1),
            fmt_g(p.ci95.0),
            fmt_g(p.ci95.1),
            fmt_g(p.edf),
            noise_name(p.noise_alpha),
            if p.beyond_quarter { " (τ > T/4)" } else { "" }
        );
    }
    let _ = write!(
        h,
        "</table>\n<p class=\"note\">Deviations in {}. Made by gyrocal allan {}.</p>\n</body>\n</html>\n",
        esc(&unit),
        env!("CARGO_PKG_VERSION")
    );
    Ok(h)
}
