//! Reading a record: a run directory's `samples.csv` or a CSV file, through gyrocal's one CSV
//! reader (`gyrocal-csv`), streaming, each error naming the file and the line (see the
//! module docs of [`super`], *Input*). Pass 1 finds τ0 ([`median_interval`]); pass 2
//! ([`read_record`]) reads the values into memory or temporary files and splits the record
//! into gap-free segments.

use std::fs::File;
use std::path::Path;

use gyrocal_files::rundir::{FIT_JSON, MAX_FIT_BYTES};

use super::bounded::{self, Samples, Spill};
use super::{GAP_FACTOR, IRREGULAR_FRACTION, MAX_INPUT_BYTES, Segment, fmt_g};
use crate::DriftError;

/// A temporary directory the user named ([`super::AllanOptions::temp_dir`], `--temp-dir`) must exist,
/// be a directory and take a file: checked before the record is read, so a typing error is
/// bad input (exit 2) at once rather than a failure halfway through a long record. (The
/// default, `$TMPDIR`, is the environment's: its failures stay failures of the run.)
pub fn check_temp_dir(dir: &Path) -> Result<(), DriftError> {
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

pub(super) fn data_err(path: &Path, line: Option<u64>, message: impl Into<String>) -> DriftError {
    DriftError::Data {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

/// The columns of a record's header.
pub(super) struct Columns {
    pub(super) value: usize,
    pub(super) value_name: String,
    pub(super) time: Option<(usize, String)>,
    pub(super) overload: Option<usize>,
}

/// Opens a record: a regular file only (`gyrocal-csv`'s `open`: a named pipe or a device is
/// refused before it is opened), at most [`MAX_INPUT_BYTES`].
fn open_checked(path: &Path) -> Result<File, DriftError> {
    let file = gyrocal_csv::open(path).map_err(|e| csv_err(path, &e))?;
    let len = file.metadata().map_err(|source| DriftError::Io {
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

/// The record's CSV reader: gyrocal's one reader, chunked (`gyrocal-csv`'s `ChunkedReader`:
/// blocks parsed in parallel into typed columns, bounded lines, a byte-order mark skipped,
/// every line counted); its header is read when it is made.
pub(super) type CsvReader = gyrocal_csv::ChunkedReader<File>;

pub(super) fn reader(path: &Path) -> Result<CsvReader, DriftError> {
    gyrocal_csv::ChunkedReader::new(
        open_checked(path)?,
        path.display().to_string(),
        gyrocal_csv::Options::default(),
    )
    .map_err(|e| csv_err(path, &e))
}

fn csv_err(path: &Path, e: &gyrocal_csv::Error) -> DriftError {
    use gyrocal_csv::ErrorKind;
    match e.kind() {
        ErrorKind::NotFound => data_err(path, None, "no such file or run directory"),
        ErrorKind::NotAFile => DriftError::NotAFile {
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

/// A reading error of the data rows: a bad cell is said as this module always said it
/// (`` `volts` is not a number: "x" ``), the column named as it was asked for.
fn row_err(path: &Path, e: &gyrocal_csv::Error, cols: &Columns) -> DriftError {
    use gyrocal_csv::Problem;
    let gyrocal_csv::Error::Value {
        line,
        column,
        text,
        problem,
        ..
    } = e
    else {
        return csv_err(path, e);
    };
    let name = [Some(&cols.value_name), cols.time.as_ref().map(|t| &t.1)]
        .into_iter()
        .flatten()
        .find(|n| n.eq_ignore_ascii_case(column))
        .unwrap_or(column);
    let message = match problem {
        Problem::Empty => format!("`{name}` is empty"),
        Problem::NotFinite(v) => format!("`{name}` is not finite ({v})"),
        _ => format!("`{name}` is not a number: {:?}", text.trim()),
    };
    data_err(path, Some(*line), message)
}

pub(super) fn columns(
    path: &Path,
    rdr: &mut CsvReader,
    wanted: Option<&str>,
) -> Result<Columns, DriftError> {
    let header = rdr.header();
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

/// The columns a pass reads: `time` (pass 1) or the value, the time and the demanded rate
/// (pass 2), overload rows skipped and counted.
fn spec(cols: &Columns, value: bool, rate: Option<usize>) -> gyrocal_csv::Spec {
    use gyrocal_csv::Cell;
    let mut spec = gyrocal_csv::Spec::new();
    if value {
        spec = spec.column(cols.value, Cell::Number);
    }
    if let Some((ti, _)) = &cols.time {
        spec = spec.column(*ti, Cell::Number);
    }
    if let Some(ri) = rate {
        spec = spec.column(ri, Cell::Lenient);
    }
    if let Some(oi) = cols.overload {
        spec = spec.skip_flagged(oi);
    }
    spec
}

/// Pass 1: the median interval of the time column (over rows that are not overloads), and
/// whether the intervals went to a temporary file (more than `cap` of them).
pub(super) fn median_interval(
    path: &Path,
    column: Option<&str>,
    cap: usize,
    temp_dir: &Path,
) -> Result<(Option<f64>, bool), DriftError> {
    let mut rdr = reader(path)?;
    let cols = columns(path, &mut rdr, column)?;
    if cols.time.is_none() {
        return Ok((None, false));
    }
    let spec = spec(&cols, false, None);
    let mut intervals = Spill::new(cap, temp_dir);
    let mut prev: Option<f64> = None;
    while let Some(chunk) = rdr
        .next_chunk(&spec)
        .map_err(|e| row_err(path, &e, &cols))?
    {
        for &t in chunk.column(0) {
            if let Some(p) = prev {
                intervals.push(t - p)?;
            }
            prev = Some(t);
        }
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
pub(super) fn run_scale_factor(dir: &Path) -> Result<Option<f64>, String> {
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

/// The sample interval τ0 and where it came from: the option, else the median interval of
/// the time column (pass 1, which sets `cap` to 0 when its intervals went to a temporary file,
/// so the values follow them there). Returns the reader positioned for pass 2 (`rdr`, or a new
/// one after pass 1 read the file).
pub(super) fn sample_interval(
    file: &Path,
    column: Option<&str>,
    cols: &Columns,
    option: Option<f64>,
    cap: &mut usize,
    temp_dir: &Path,
    rdr: CsvReader,
) -> Result<(f64, String, CsvReader), DriftError> {
    match (option, &cols.time) {
        (Some(t), _) => Ok((t, "option".to_string(), rdr)),
        (None, Some((_, name))) => {
            drop(rdr);
            let (m, spilled) = median_interval(file, column, *cap, temp_dir)?;
            if spilled {
                *cap = 0;
            }
            let m = m.ok_or_else(|| {
                data_err(file, None, "fewer than two samples: no sample interval")
            })?;
            if !(m.is_finite() && m > 0.0) {
                return Err(data_err(
                    file,
                    None,
                    format!("the median interval of {name} is {m} s: the time does not increase"),
                ));
            }
            Ok((m, format!("median interval of {name}"), reader(file)?))
        }
        (None, None) => Err(data_err(
            file,
            Some(1),
            "no time column (t_s or time): give the sample interval with --tau0",
        )),
    }
}

/// Pass 2 over a record: what it needs.
pub(super) struct RecordPass<'a> {
    /// The file read.
    pub(super) file: &'a Path,
    /// Its columns.
    pub(super) cols: &'a Columns,
    /// Whether to watch the demanded rate (`rate_dps`, a run's samples.csv).
    pub(super) rate_column: bool,
    /// The sample interval, s.
    pub(super) tau0: f64,
    /// Every value is multiplied by it (volts to °/h).
    pub(super) factor: f64,
    /// Gaps up to this long, s, are joined as dead time.
    pub(super) join_below: Option<f64>,
    /// Values kept in memory at most (then temporary files).
    pub(super) cap: usize,
    /// Directory of the temporary files.
    pub(super) temp_dir: &'a Path,
}

/// Pass 2's result: the values and the gap-free segments, with the counts the document reports.
pub(super) struct RecordRead<'a> {
    /// The values (factor applied), in memory or in a temporary file.
    pub(super) values: Spill<'a>,
    /// The gap-free segments, in file order.
    pub(super) segments: Vec<Segment>,
    /// The index in `values` of each segment's first value.
    pub(super) seg_start_idx: Vec<usize>,
    /// Data rows read (overloads included).
    pub(super) rows: u64,
    /// Overload rows skipped.
    pub(super) overloads: u64,
    /// Irregular intervals within segments.
    pub(super) irregular: u64,
    /// The line of the first.
    pub(super) first_irregular: Option<u64>,
}

impl<'a> RecordPass<'a> {
    /// Reads the values and splits the record into segments; the notes on joined gaps,
    /// overloads, a varying demanded rate and irregular sampling go into `notes`, in that
    /// order.
    pub(super) fn read(
        &self,
        mut rdr: CsvReader,
        notes: &mut Vec<String>,
    ) -> Result<RecordRead<'a>, DriftError> {
        let (file, cols, tau0) = (self.file, self.cols, self.tau0);
        let mut values = Spill::new(self.cap, self.temp_dir);
        let mut segments: Vec<Segment> = Vec::new();
        let mut seg_start_idx: Vec<usize> = Vec::new();
        let (mut rows, mut overloads, mut irregular) = (0u64, 0u64, 0u64);
        let mut first_irregular = None;
        let mut joined_gaps = 0usize;
        let mut dead_time_s = 0.0_f64;
        let mut prev_t: Option<f64> = None;
        let (mut rate_lo, mut rate_hi) = (f64::INFINITY, f64::NEG_INFINITY);
        let rate_col = if self.rate_column {
            rdr.header().find("rate_dps")
        } else {
            None
        };
        let spec = spec(cols, true, rate_col);
        // the spec's columns: the value, then the time and the rate when there are
        let k_rate = 1 + usize::from(cols.time.is_some());
        while let Some(chunk) = rdr.next_chunk(&spec).map_err(|e| row_err(file, &e, cols))? {
            rows += chunk.len() as u64 + chunk.skipped();
            overloads += chunk.skipped();
            let times = cols.time.as_ref().map(|_| chunk.column(1));
            let rates = rate_col.map(|_| chunk.column(k_rate));
            for (i, (&v, &line)) in chunk.column(0).iter().zip(chunk.lines()).enumerate() {
                let t = match times.and_then(|ts| ts.get(i)) {
                    Some(&t) => t,
                    None => values.len() as f64 * tau0,
                };
                if let Some(&r) = rates.and_then(|rs| rs.get(i))
                    && !r.is_nan()
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
                                file,
                                Some(line),
                                format!("the time does not increase ({t} s after {p} s)"),
                            ));
                        }
                        if dt > GAP_FACTOR * tau0 {
                            if self.join_below.is_some_and(|j| dt <= j) {
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
                values.push(v * self.factor)?;
            }
        }
        drop(rdr);
        if values.len() == 0 {
            return Err(data_err(file, None, "no samples (only a header?)"));
        }
        if joined_gaps > 0 {
            notes.push(format!(
                "{joined_gaps} gap(s) of at most {} s joined as dead time ({} s in all, {:.2} % of the record): the readings on both sides are analysed as one record",
                fmt_g(self.join_below.unwrap_or(0.0)),
                fmt_g(dead_time_s),
                100.0 * dead_time_s
                    / (values.len() as f64 * tau0 + dead_time_s).max(f64::MIN_POSITIVE)
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
        Ok(RecordRead {
            values,
            segments,
            seg_start_idx,
            rows,
            overloads,
            irregular,
            first_irregular,
        })
    }
}
