//! The durable run directory: `samples.csv`, `steps.csv`, `manifest.json`, `fit.json` (and,
//! written by others, `report.html` with its `.svg` plots and `run.log`).
//!
//! # Files
//!
//! - `samples.csv`: `step,index,t_s,rate_dps,volts,overload,t_utc`, one row per raw reading in
//!   the order taken. `step` is the schedule's 0-based index of the step (its position in the
//!   plan's `repeat × rates_dps`; gyrocal's messages, display and report say `step + 1`, the
//!   plan's step number: `step 4/19` is `step = 3` here); `index` is 0-based and contiguous within a step; `t_s` is the
//!   run clock (seconds, see `elapsed_s` below); `rate_dps` the demanded rate. **Overloads are
//!   written, never dropped**: the row has `overload = 1` and an *empty* `volts` (the meter's
//!   `9.9E+37` is a marker, not a voltage; an empty field makes a naive reader fail loudly
//!   instead of averaging it), so the indices stay contiguous and the overload count is
//!   auditable.
//! - `steps.csv`: one row per finished step, see [`StepRecord`] and [`STEPS_HEADER`]. It is a
//!   valid input of `gyrocal fit`, which reads `rate_dps`, `volts`, `volts_std` (optional,
//!   empty when `n = 1`) and `n` by name.
//! - `manifest.json`: [`Manifest`], replaced atomically (temp file in the same directory,
//!   fsync, rename, fsync of the directory) at every change, so it always parses. It holds the
//!   run's state, the plan, the instruments, the times and, once fitted, a [`FitSummary`]: the
//!   name and SHA-256 of `fit.json` and the headline figures (K, K0, their standard errors,
//!   the best model). It stays a few kilobytes, so an index of many runs reads it cheaply.
//! - `fit.json`: the whole fit (the `gyrocal fit --json` document: every model, the
//!   residuals, the error surface), written by `gyrocal_analysis::sweep::fit_run`; read it with [`load_fit`].
//! - `allan.json`, `allan.html`: a drift record's Allan analysis (`gyrocal-analysis`) and its
//!   page (`gyrocal-report`), written through [`RunDir::write_result`] or [`RunResults`] (atomically, under the run's lock, with
//!   its SHA-256 recorded in the manifest's `checksums`).
//!
//! ## Integrity
//!
//! The manifest records the SHA-256 of every file the run wrote: `samples.csv` and
//! `steps.csv` when the run completes, `fit.json` in its `fit_summary`, every result file when
//! it is written. [`verify`] checks them all and fails a complete run whose record is missing;
//! [`check_files`] is what `gyrocal report` checks before it uses a run's files. See
//! `integrity` (a private module) for the rules and why they are strict.
//!
//! ## Times
//!
//! Every row has two times: the run clock `t_s` (`t_start_s`, `t_end_s` in steps.csv),
//! seconds since the run began, exact and monotonic, and `t_utc` (`t_start_utc`,
//! `t_end_utc`), the same instant as UTC wall-clock time, RFC 3339 with milliseconds
//! (`2026-03-21T10:22:33.123Z`), for joining with other logs (a lab's temperature record).
//! The run directory converts one into the other through a [`ClockAnchor`]: the wall-clock time
//! at which the run clock read a known value, taken when a session starts (see
//! [`RunDir::anchor_clock`]). The run clock does not count the time between sessions (a
//! resume continues from the previous `elapsed_s`); the anchor is taken again at each
//! session, so `t_utc` is right across resumes. In a simulated run in virtual time
//! ([`Manifest::virtual_time`]) the run clock counts the time a real bench would have taken,
//! and `t_utc` is the start time plus that: ahead of the wall clock.
//!
//! The manifest's `elapsed_s` is the run clock at its last write: the whole run, each session
//! from connecting to the instruments to the table at rest, added up. `timing` compares the
//! last session's *schedule* alone (`schedule_elapsed_s`: first rate demanded to the stop
//! command) with its physical bound: it leaves out connecting and the table's stop, so it is
//! a little shorter.
//!
//! ## Numbers
//!
//! Computed numbers (means, standard deviations, interpolated times, the elapsed time, the
//! fit) are rounded once to 12 significant digits and written as the shortest text that reads
//! back to the same value, so the files carry no float noise (`10.521512`, not
//! `10.521512000000001`); values read as text (the plan's rates, the meter's readings) come
//! out as they went in. Why 12 digits: see [`crate::num`].
//!
//! ## Formats read
//!
//! Files written by earlier gyrocal versions still load, resume and report: a manifest of
//! format 1 (the plan nested as `plan.plan`, `timing.elapsed_s`, the whole fit embedded as
//! `fit`, read into [`Manifest::legacy_fit`]); a `steps.csv` without the UTC columns or
//! without `rate_samples` (a resume rewrites it with the current header, the old rows' new
//! cells empty); a `samples.csv` without `t_utc` (a resume keeps appending rows of its
//! columns: the file is never rewritten, it can be gigabytes). A resume rewrites the manifest
//! in the current format.
//!
//! # Durability rules
//!
//! - [`RunDir::append_samples`] writes and flushes every chunk to the OS (a crash of the
//!   program loses nothing; a power cut may lose the unsynced tail of the current step, which
//!   a resume re-runs anyway).
//! - [`RunDir::append_step`] syncs `samples.csv` *first*, then writes, flushes and fsyncs the
//!   step row, then updates the manifest: a step row never exists without its samples.
//! - [`RunDir::open_for_resume`] trusts nothing: it drops a torn last line (no trailing
//!   newline) of either CSV, checks every row against the plan's schedule, keeps the finished
//!   steps, checks their sample counts, and truncates `samples.csv` to the end of the last
//!   finished step's rows.
//!
//! One process at a time: a writer holds an OS lock on `.lock` (released even by a crash).
//! A writer that closes the run (complete, failed or aborted) removes `.lock` when it lets go,
//! so a finished run directory holds only data; a run left `running` (a crash, a kill) keeps
//! the file, whose lock died with its process: the next resume takes it.
//!
//! # Bounds and failures
//!
//! Every file is read with a size limit ([`MAX_MANIFEST_BYTES`], [`MAX_STEPS_BYTES`],
//! [`MAX_SAMPLES_BYTES`], [`MAX_FIT_BYTES`]) and must be a regular file, checked before it is
//! opened ([`crate::open::open_regular`]: a FIFO never blocks, a device is never read): a huge
//! or endless file is an error naming it, never a memory exhaustion. Every file replaced is
//! replaced atomically ([`crate::atomic`]), its temporary file removed on any failure (a full
//! disk leaves no `.NAME.tmp`). [`RunError::kind`] says whose fault an error is: a full disk
//! is the environment's, a malformed file the input's. A header naming a column twice is an error
//! naming both positions. [`RunDir::create`] is all or nothing (a failure removes what it
//! created), and a directory left half created by a crash during creation is reused by the
//! next `create` ([`RunDir::is_half_created`]).

use std::collections::{BTreeMap, BTreeSet};
use std::fs::{self, File, OpenOptions};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::num::{round_json, round_opt, round_significant};
use crate::open::open_regular;
use crate::plan::{Plan, Step};
use crate::time::{ClockAnchor, now_utc};

mod integrity;
mod results;

pub use integrity::{
    DATA_FILES, Discrepancy, FileCheck, FileState, RESULT_FILES, Verification, check_files,
    sha256_file, sha256_hex, verify,
};
pub use results::{RunResults, WriteResult};

/// File name of the raw readings.
pub const SAMPLES_CSV: &str = "samples.csv";
/// File name of the finished steps.
pub const STEPS_CSV: &str = "steps.csv";
/// File name of the manifest.
pub const MANIFEST_JSON: &str = "manifest.json";
/// The start of the serial field of an instrument's identity (`*IDN?`) by which gyrocal's
/// simulators say they are simulators (`ACUTRONIC,ACUTROL3000,SIM0001,1.0`), so a run against
/// `gyrocal sim` is recorded as simulated.
pub const SIMULATOR_SERIAL_PREFIX: &str = "SIM";
/// File name of the fit document.
pub const FIT_JSON: &str = "fit.json";
/// File name of the HTML report (written by the report crate via [`RunDir::write_file`]).
pub const REPORT_HTML: &str = "report.html";
/// File name of a drift record's Allan analysis document (written by the report crate through
/// [`RunDir::write_result`] or [`RunResults::write_result`], recorded in `checksums`).
pub const ALLAN_JSON: &str = "allan.json";
/// File name of a drift record's Allan page (written and recorded as [`ALLAN_JSON`]).
pub const ALLAN_HTML: &str = "allan.html";
/// Version of the run-directory format written, recorded in the manifest. Version 1
/// (gyrocal before the UTC columns and the slim manifest) is still read: see
/// [`FORMAT_VERSIONS_READ`].
pub const FORMAT_VERSION: u32 = 2;
/// The manifest versions this gyrocal reads.
pub const FORMAT_VERSIONS_READ: [u32; 2] = [1, 2];

/// Columns of `samples.csv`, in order; `t_utc` is the run directory's conversion of `t_s`
/// (see the module docs, *Times*), last so that readers by position keep working.
pub const SAMPLES_HEADER: [&str; 7] = [
    "step", "index", "t_s", "rate_dps", "volts", "overload", "t_utc",
];
/// Columns of `samples.csv` before `t_utc` existed. Such a file still reads, and a resume
/// keeps appending rows of these columns to it (the file is never rewritten: it can hold
/// gigabytes).
pub const SAMPLES_HEADER_V1: [&str; 6] = ["step", "index", "t_s", "rate_dps", "volts", "overload"];
/// Columns of `steps.csv`, in order: the [`StepRecord`]'s fields, then `t_start_utc` and
/// `t_end_utc`, which the run directory computes from `t_start_s` and `t_end_s` (see the
/// module docs, *Times*). New columns go at the end, so a script that reads columns by
/// position keeps working.
pub const STEPS_HEADER: [&str; 17] = [
    "step",
    "pass",
    "rate_dps",
    "rate_meas_dps",
    "rate_meas_std_dps",
    "rate_meas_min_dps",
    "rate_meas_max_dps",
    "rate_samples",
    "volts",
    "volts_std",
    "n",
    "overloads",
    "retries",
    "t_start_s",
    "t_end_s",
    "t_start_utc",
    "t_end_utc",
];

/// Columns of `steps.csv` before the UTC columns existed. Such a file still reads; a resume
/// rewrites it with [`STEPS_HEADER`] (empty UTC cells in the old rows) before appending.
pub const STEPS_HEADER_V2: [&str; 15] = [
    "step",
    "pass",
    "rate_dps",
    "rate_meas_dps",
    "rate_meas_std_dps",
    "rate_meas_min_dps",
    "rate_meas_max_dps",
    "rate_samples",
    "volts",
    "volts_std",
    "n",
    "overloads",
    "retries",
    "t_start_s",
    "t_end_s",
];

/// Columns of `steps.csv` as gyrocal wrote them before `rate_samples` existed. Such a file
/// still reads; a resume rewrites it with [`STEPS_HEADER`] (an empty `rate_samples` and empty
/// UTC cells in the old rows) before appending.
pub const STEPS_HEADER_V1: [&str; 14] = [
    "step",
    "pass",
    "rate_dps",
    "rate_meas_dps",
    "rate_meas_std_dps",
    "rate_meas_min_dps",
    "rate_meas_max_dps",
    "volts",
    "volts_std",
    "n",
    "overloads",
    "retries",
    "t_start_s",
    "t_end_s",
];

/// Every `steps.csv` header read, current first.
const STEPS_HEADERS: &[&[&str]] = &[&STEPS_HEADER, &STEPS_HEADER_V2, &STEPS_HEADER_V1];
/// Every `samples.csv` header read, current first.
const SAMPLES_HEADERS: &[&[&str]] = &[&SAMPLES_HEADER, &SAMPLES_HEADER_V1];

/// The most bytes read from `manifest.json` (64 MiB; a manifest is kilobytes, a megabyte or
/// two with a large fit document).
pub const MAX_MANIFEST_BYTES: u64 = 64 * 1024 * 1024;
/// The most bytes read from `steps.csv` (64 MiB, some 400 000 steps; a plan of the largest
/// size gyrocal accepts stays below it).
pub const MAX_STEPS_BYTES: u64 = 64 * 1024 * 1024;
/// The largest `samples.csv` accepted (4 GiB, about 100 million readings: weeks of readings
/// at the 34401A's rates). A resume streams the file (it never holds it in memory);
/// [`load_samples`] reads it whole.
pub const MAX_SAMPLES_BYTES: u64 = 4 * 1024 * 1024 * 1024;
/// The most bytes read from `fit.json` by the report (64 MiB).
pub const MAX_FIT_BYTES: u64 = 64 * 1024 * 1024;

// ---------------------------------------------------------------------------------------------
// Errors
// ---------------------------------------------------------------------------------------------

/// Everything that can go wrong with a run directory. Every variant names the file (and the
/// line where there is one).
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// An I/O operation failed.
    #[error("{}: cannot {action}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// What was being done (`create`, `write`, `sync`, ...).
        action: &'static str,
        /// The I/O error.
        source: std::io::Error,
    },
    /// Another process (or another open `RunDir`) is writing this run directory.
    #[error("{}: the run directory is in use by another gyrocal process", path.display())]
    Locked {
        /// The directory.
        path: PathBuf,
    },
    /// `create` was given a directory that already holds files.
    #[error("{}: the run directory exists and is not empty (use --resume to continue it)", path.display())]
    NotEmpty {
        /// The directory.
        path: PathBuf,
    },
    /// A file of the run directory is larger than gyrocal ever writes it (or endless).
    #[error(
        "{}: larger than the {} MiB limit for this file; it is not a file gyrocal wrote",
        path.display(),
        cap / (1024 * 1024)
    )]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// The limit, bytes.
        cap: u64,
    },
    /// A CSV row or header that does not parse or does not fit the plan.
    #[error("{}:{line}: {message}", path.display())]
    Csv {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: u64,
        /// What is wrong.
        message: String,
    },
    /// The manifest does not parse (or its plan does not validate).
    #[error("{}:{line}:{column}: {message}", path.display())]
    Json {
        /// The file.
        path: PathBuf,
        /// 1-based line (0 when unknown).
        line: usize,
        /// 1-based column (0 when unknown).
        column: usize,
        /// What is wrong.
        message: String,
    },
    /// The files contradict each other (or the manifest contradicts itself).
    #[error("{}: {message}", path.display())]
    Inconsistent {
        /// The file found wrong.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// `--resume` with a plan whose hash differs from the run's.
    #[error(
        "{}: the plan changed since this run started: {}; resume without a plan (the run's own is in its manifest) or start a new run",
        path.display(),
        if changes.is_empty() { format!("plan hash {run_hash} vs {plan_hash}") } else { changes.join("; ") }
    )]
    PlanChanged {
        /// The manifest.
        path: PathBuf,
        /// Hash recorded in the run.
        run_hash: String,
        /// Hash of the plan given now.
        plan_hash: String,
        /// What differs, one entry per key: `[dmm] range_v: 10 (run) vs 100 (this plan)`.
        changes: Vec<String>,
    },
    /// A directory that holds no run (no `manifest.json`).
    #[error(
        "{} is not a gyrocal run directory (it has no manifest.json); give the directory a run wrote",
        path.display()
    )]
    NotARun {
        /// The directory.
        path: PathBuf,
    },
    /// `--resume` of a run that is already complete.
    #[error("{}: the run is already complete; nothing to resume", path.display())]
    AlreadyComplete {
        /// The manifest.
        path: PathBuf,
    },
    /// The caller broke the writing protocol (wrong step, index gap, count mismatch, NaN).
    #[error("{}: {message}", path.display())]
    Protocol {
        /// The file that would have been written.
        path: PathBuf,
        /// What was wrong with the call.
        message: String,
    },
}

/// What kind of [`RunError`] it is: whose the fault is, so the CLI picks its exit code (2 for
/// bad input, 1 for a failure of the environment) without matching messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RunErrorKind {
    /// The files or the arguments: a malformed or inconsistent file, a directory that holds
    /// no run, a path that does not exist or may not be written, a changed plan.
    Input,
    /// Another process is writing the run directory.
    Busy,
    /// The system failed: the disk is full, a quota is exhausted, an I/O error. Nothing the
    /// operator typed is wrong; the same command succeeds once the cause is removed.
    Environment,
    /// gyrocal broke its own writing protocol (a bug).
    Internal,
}

impl RunError {
    /// The kind of error. An I/O error is [`RunErrorKind::Input`] when it says the path is
    /// wrong (not found, permission denied, read-only file system, not a directory, ...) and
    /// [`RunErrorKind::Environment`] otherwise (a full disk, an exhausted quota, an I/O error).
    pub fn kind(&self) -> RunErrorKind {
        match self {
            RunError::Io { source, .. } => io_kind(source),
            RunError::Locked { .. } => RunErrorKind::Busy,
            RunError::Protocol { .. } => RunErrorKind::Internal,
            RunError::NotEmpty { .. }
            | RunError::TooLarge { .. }
            | RunError::Csv { .. }
            | RunError::Json { .. }
            | RunError::Inconsistent { .. }
            | RunError::PlanChanged { .. }
            | RunError::NotARun { .. }
            | RunError::AlreadyComplete { .. } => RunErrorKind::Input,
        }
    }
}

/// Whose fault an I/O error is (see [`RunError::kind`]).
fn io_kind(e: &std::io::Error) -> RunErrorKind {
    use std::io::ErrorKind as K;
    match e.kind() {
        K::NotFound
        | K::PermissionDenied
        | K::AlreadyExists
        | K::InvalidInput
        | K::InvalidData
        | K::NotADirectory
        | K::IsADirectory
        | K::DirectoryNotEmpty
        | K::ReadOnlyFilesystem
        | K::InvalidFilename
        | K::NotSeekable => RunErrorKind::Input,
        _ => RunErrorKind::Environment,
    }
}

/// A data file [`open_regular`] refused or could not open, as a run-directory error naming it.
fn opened(e: crate::open::OpenError) -> RunError {
    match e {
        crate::open::OpenError::NotRegular { path, what } => RunError::Inconsistent {
            path,
            message: format!(
                "not a regular file (it is {what}); a run directory's files are regular files"
            ),
        },
        crate::open::OpenError::Io { path, source } => RunError::Io {
            path,
            action: "read",
            source,
        },
    }
}

fn io(path: &Path, action: &'static str) -> impl FnOnce(std::io::Error) -> RunError {
    let path = path.to_path_buf();
    move |source| RunError::Io {
        path,
        action,
        source,
    }
}

// ---------------------------------------------------------------------------------------------
// Records
// ---------------------------------------------------------------------------------------------

/// One raw reading handed to [`RunDir::append_samples`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// 0-based, contiguous within the step (chunk after chunk).
    pub index: u64,
    /// Run clock, seconds.
    pub t_s: f64,
    /// The reading in volts; `None` for an overload (`9.9E+37`).
    pub volts: Option<f64>,
}

/// One row of `samples.csv`, as read back by [`load_samples`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SampleRow {
    /// Step index in the schedule.
    pub step: usize,
    /// Reading index within the step.
    pub index: u64,
    /// Run clock, seconds.
    pub t_s: f64,
    /// Demanded rate, °/s.
    pub rate_dps: f64,
    /// Volts; empty (`None`) for an overload.
    pub volts: Option<f64>,
    /// 1 for an overload, else 0.
    pub overload: u8,
    /// `t_s` as UTC wall-clock time, RFC 3339 with milliseconds (see [`ClockAnchor`]); `None`
    /// in files written before the column existed.
    #[serde(default)]
    pub t_utc: Option<String>,
}

/// A row of `steps.csv` as written: the sequencer's [`StepRecord`] with its times converted
/// to UTC by the run directory and its computed numbers rounded (see [`crate::num`]).
#[derive(Debug, Serialize)]
struct StepRow<'a> {
    step: usize,
    pass: u32,
    rate_dps: f64,
    rate_meas_dps: Option<f64>,
    rate_meas_std_dps: Option<f64>,
    rate_meas_min_dps: Option<f64>,
    rate_meas_max_dps: Option<f64>,
    rate_samples: Option<u64>,
    volts: f64,
    volts_std: Option<f64>,
    n: u64,
    overloads: u64,
    retries: u32,
    t_start_s: f64,
    t_end_s: f64,
    t_start_utc: &'a str,
    t_end_utc: &'a str,
}

/// `rec` with its computed numbers rounded once (the demanded rate, the plan's own number,
/// is kept bit for bit: a resume compares it with the schedule).
fn rounded(rec: &StepRecord) -> StepRecord {
    StepRecord {
        rate_meas_dps: round_opt(rec.rate_meas_dps),
        rate_meas_std_dps: round_opt(rec.rate_meas_std_dps),
        rate_meas_min_dps: round_opt(rec.rate_meas_min_dps),
        rate_meas_max_dps: round_opt(rec.rate_meas_max_dps),
        volts: round_significant(rec.volts),
        volts_std: round_opt(rec.volts_std),
        t_start_s: round_significant(rec.t_start_s),
        t_end_s: round_significant(rec.t_end_s),
        ..rec.clone()
    }
}

/// One row of `steps.csv`: a finished step. The sequencer fills it; [`RunDir::append_step`]
/// checks it against the schedule and the samples written.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StepRecord {
    /// Step index in the schedule.
    pub step: usize,
    /// Pass (0-based).
    pub pass: u32,
    /// Demanded rate, °/s (must equal the schedule's).
    pub rate_dps: f64,
    /// Mean measured table rate during the acquisition, °/s (empty if not measured).
    pub rate_meas_dps: Option<f64>,
    /// Std of the measured rate, °/s.
    pub rate_meas_std_dps: Option<f64>,
    /// Minimum measured rate, °/s.
    pub rate_meas_min_dps: Option<f64>,
    /// Maximum measured rate, °/s.
    pub rate_meas_max_dps: Option<f64>,
    /// Number of table rate samples taken during the acquisition (the basis of the
    /// `rate_meas_*` figures); empty when not recorded, and in files written before the column
    /// existed.
    #[serde(default)]
    pub rate_samples: Option<u64>,
    /// Mean of the valid readings, V.
    pub volts: f64,
    /// Sample standard deviation of the valid readings, V (empty when `n = 1`).
    pub volts_std: Option<f64>,
    /// Number of valid readings averaged (≥ 1).
    pub n: u64,
    /// Number of overload readings (written to samples.csv, excluded from the mean).
    pub overloads: u64,
    /// Retries during this step.
    pub retries: u32,
    /// Run clock at the start of the acquisition, s.
    pub t_start_s: f64,
    /// Run clock at the end of the acquisition, s.
    pub t_end_s: f64,
}

/// State of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// In progress (or the program died: a resume finds out).
    Running,
    /// Every step done and the run closed.
    Complete,
    /// Stopped by the operator (Ctrl-C, SIGTERM).
    Aborted,
    /// Stopped by an error; the reason says which.
    Failed,
}

/// The instruments' identities (`*IDN?` replies), filled by the caller.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Instruments {
    /// The multimeter's identity.
    pub dmm: Option<String>,
    /// The rate table's identity.
    pub table: Option<String>,
}

/// A resume of the run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Resume {
    /// Wall-clock time of the resume, RFC 3339 UTC.
    pub at_utc: String,
    /// The first step not done, where the run continues (`None`: all steps were done).
    pub from_step: Option<usize>,
    /// Steps kept.
    pub steps_done: usize,
    /// Rows of the partial step dropped from samples.csv.
    pub samples_dropped: u64,
    /// Bytes of torn last lines dropped (both CSV files).
    pub torn_bytes_dropped: u64,
    /// The manifest's status before the resume, with its reason.
    pub previous_status: Status,
    /// The previous reason, if any.
    pub previous_reason: Option<String>,
}

/// A retry logged by the sequencer (per the drivers' recovery).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Retry {
    /// Run clock, s.
    pub t_s: f64,
    /// Step in progress, if any.
    pub step: Option<usize>,
    /// `dmm` or `table`.
    pub instrument: String,
    /// What failed and what was done.
    pub message: String,
}

/// Timing figures of the schedule of the last session (the physical bound versus the time the
/// schedule took). Not the run's elapsed time: see [`Manifest::elapsed_s`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Timing {
    /// The physical lower bound of the schedule's duration, s.
    pub bound_s: f64,
    /// The schedule of the last session on the run clock, s: from the first rate demanded to
    /// the stop command after the last step. Without connecting, identifying and configuring
    /// the instruments before it and the wait for the table's rest after it, which
    /// [`Manifest::elapsed_s`] includes. Written as `schedule_elapsed_s` (manifests of format 1
    /// called it `elapsed_s`, still read).
    #[serde(rename = "schedule_elapsed_s", alias = "elapsed_s")]
    pub elapsed_s: f64,
    /// `schedule_elapsed_s / bound_s`.
    pub ratio: f64,
    /// The acquisition strategy actually used (`stream`, `memory`, `poll`).
    pub acquisition: Option<String>,
}

/// What the caller knows when it creates a run.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RunMeta {
    /// gyrocal's version (`env!("CARGO_PKG_VERSION")` of the CLI).
    pub gyrocal_version: String,
    /// Instrument identities, if already known (else set them later).
    pub instruments: Instruments,
    /// Whether the run uses the simulated bench.
    pub simulated: bool,
    /// Whether the run clock is virtual (the simulated bench in virtual time): see
    /// [`Manifest::virtual_time`].
    pub virtual_time: bool,
    /// The gyro under test, as the operator entered it.
    pub dut: Option<Dut>,
    /// Who ran it, for whom, and in what environment, as entered.
    pub context: Option<RunContext>,
    /// The station: the lab, the bench and its instruments' records (asset ids, serials,
    /// calibration certificates, due dates, accuracy classes), from the station file.
    pub station: Option<crate::station::Station>,
}

/// The gyro under test. Not part of the plan (one plan serves many gyros): the operator names
/// it per run; a resume refuses another serial.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Dut {
    /// Serial number.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub serial: Option<String>,
    /// Model.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<String>,
    /// Manufacturer.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub manufacturer: Option<String>,
    /// Condition as received (ISO/IEC 17025 §7.8.2.1 g), e.g. "new, no visible damage".
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub condition: Option<String>,
    /// Free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub notes: Option<String>,
}

impl Dut {
    /// `(key, value)` of every key, in the order a plan's `[dut]` lists them.
    pub(crate) fn fields(&self) -> [(&'static str, &Option<String>); 5] {
        [
            ("serial", &self.serial),
            ("model", &self.model),
            ("manufacturer", &self.manufacturer),
            ("condition", &self.condition),
            ("notes", &self.notes),
        ]
    }

    /// Whether nothing is known about the gyro.
    pub fn is_empty(&self) -> bool {
        self.serial.is_none()
            && self.model.is_none()
            && self.manufacturer.is_none()
            && self.condition.is_none()
            && self.notes.is_none()
    }

    /// `self` with every field `over` sets replaced by `over`'s (the command line over the
    /// plan's `[dut]`).
    pub fn overridden_by(self, over: Dut) -> Dut {
        Dut {
            serial: over.serial.or(self.serial),
            model: over.model.or(self.model),
            manufacturer: over.manufacturer.or(self.manufacturer),
            condition: over.condition.or(self.condition),
            notes: over.notes.or(self.notes),
        }
    }
}

/// A departure from the method, recorded when it happens (ISO/IEC 17025 §7.8.2.1 n): for
/// example a run started with an instrument whose calibration was overdue
/// (`--allow-expired`). The report lists these with the deviations it derives from the
/// manifest itself (resumes, retries, a simulated bench).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Deviation {
    /// A short machine-readable kind, e.g. `expired-calibration`.
    pub kind: String,
    /// What happened, in words.
    pub text: String,
    /// When it was recorded, RFC 3339 UTC.
    pub at_utc: String,
}

/// Who ran a run, for whom, and the environment as entered (not measured).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunContext {
    /// The operator.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub operator: Option<String>,
    /// The customer.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub customer: Option<String>,
    /// Ambient temperature, °C.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ambient_c: Option<f64>,
    /// Relative humidity, %.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub humidity_pct: Option<f64>,
}

/// What the manifest says about the fit: a reference to `fit.json` and the headline figures
/// an index of runs needs. The fit itself (every model, residuals, the error surface) lives
/// only in `fit.json`, which can be large.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FitSummary {
    /// The fit document's file name in the run directory ([`FIT_JSON`]).
    pub file: String,
    /// SHA-256 (lower-case hex) of that file's bytes as written: a `fit.json` edited or
    /// replaced afterwards no longer matches.
    pub sha256: String,
    /// Scale factor K of the least-squares line, V/(°/s).
    pub scale_factor: f64,
    /// Standard error of K, V/(°/s) (absent without degrees of freedom).
    pub scale_factor_std_error: Option<f64>,
    /// Bias K0 of the least-squares line, V.
    pub bias_volts: f64,
    /// Standard error of K0, V.
    pub bias_std_error: Option<f64>,
    /// The model chosen by the fit's model selection (nested F-test), if any.
    pub best_model: Option<gyrocal_fit::Model>,
}

impl FitSummary {
    /// The summary of `fit`, whose document's bytes hash to `sha256`.
    pub fn of(fit: &gyrocal_fit::Analysis, sha256: String) -> FitSummary {
        let line = fit.fit(
            gyrocal_fit::Method::LeastSquares,
            gyrocal_fit::Model::Linear,
        );
        FitSummary {
            file: FIT_JSON.to_string(),
            sha256,
            scale_factor: round_significant(fit.metrics.scale_factor),
            scale_factor_std_error: round_opt(line.and_then(|l| l.std_errors.k1)),
            bias_volts: round_significant(fit.metrics.bias_volts),
            bias_std_error: round_opt(line.and_then(|l| l.std_errors.k0)),
            best_model: fit.best_model,
        }
    }
}

/// The warm-up (IEEE 1431 §12.6) as a run found it online: consecutive window means of the
/// readings at rest, complete when two agree within the tolerance (or at the maximum). Before a
/// scale-factor sweep its readings are not kept (only the window means, here); in a drift run
/// they are the start of the record, and the Allan analysis cuts them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WarmupRecord {
    /// `before_sweep` (a phase of its own before the first step) or `in_record` (the first
    /// segments of a drift record).
    pub mode: String,
    /// Window of the rolling mean, s.
    pub window_s: f64,
    /// The tolerance in force, V (`None` until it could be estimated).
    pub tolerance_v: Option<f64>,
    /// Where the tolerance came from: `plan` or the white-noise estimate.
    pub tolerance_source: String,
    /// The maximum, s.
    pub max_s: f64,
    /// Run-clock time of the warm-up's first reading, s.
    pub started_s: f64,
    /// The warm-up is over.
    pub complete: bool,
    /// Warm-up time, s from `started_s` (when complete).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_s: Option<f64>,
    /// `criterion` or `max` (when complete).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ended_by: Option<String>,
    /// The change between the last two window means, V.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub last_change_v: Option<f64>,
    /// Window means `[run-clock time of the window's middle, s; mean, V]`, thinned to a few
    /// hundred points.
    pub means: Vec<[f64; 2]>,
}

/// `manifest.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// [`FORMAT_VERSION`].
    pub format_version: u32,
    /// Run state.
    pub status: Status,
    /// Why it is `aborted` or `failed` (or a note for `complete`).
    pub reason: Option<String>,
    /// gyrocal's version.
    pub gyrocal_version: String,
    /// SHA-256 of the plan ([`Plan::hash`]).
    pub plan_hash: String,
    /// The plan as parsed, defaults explicit (validated again when read). Written with the
    /// `[plan]` section's keys at the top (`plan.name`, `plan.rates_dps`, ...) and the other
    /// sections beside them (`plan.table`, `plan.dmm`, `plan.simulation`); a manifest of
    /// format 1 nested the `[plan]` section (`plan.plan.name`) and still reads.
    #[serde(with = "manifest_plan")]
    pub plan: Plan,
    /// Whether the run uses a simulated bench: the in-process one (`gyrocal run --simulate`),
    /// or instruments that identify themselves as simulators (`gyrocal sim`; see
    /// [`SIMULATOR_SERIAL_PREFIX`] and `simulated_by`).
    pub simulated: bool,
    /// Who said the run is simulated when it was not started with `--simulate`: the
    /// instruments' identities (a run against `gyrocal sim`). Absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simulated_by: Option<String>,
    /// Whether a session of the run ran the simulated bench in virtual time: the run clock
    /// (`elapsed_s`, every `t_s`, and the `t_utc` derived from it) then counts the time a
    /// real bench would have taken, while the wall clock (`started_utc` to `ended_utc`) shows
    /// the seconds the simulation took. Absent (false) in manifests of format 1.
    #[serde(default)]
    pub virtual_time: bool,
    /// The gyro under test, as entered (absent: not named).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dut: Option<Dut>,
    /// Operator, customer and environment, as entered (absent: not given).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub context: Option<RunContext>,
    /// The station and its instruments' calibration records, from the station file (absent:
    /// no station file; the report then says the instruments are not identified).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub station: Option<crate::station::Station>,
    /// Instrument identities.
    pub instruments: Instruments,
    /// Departures from the method recorded during the run, oldest first (absent: none).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub deviations: Vec<Deviation>,
    /// Wall-clock start, RFC 3339 UTC.
    pub started_utc: String,
    /// Wall-clock end (set when the run stops), RFC 3339 UTC.
    pub ended_utc: Option<String>,
    /// Wall-clock time of the last manifest write, RFC 3339 UTC.
    pub updated_utc: String,
    /// The run clock at the last write, s: the run's elapsed time, every session from
    /// connecting to the instruments to the table at rest, added up over the resumes. It is
    /// the time base of every `t_s`. The schedule alone is `timing.schedule_elapsed_s`.
    pub elapsed_s: f64,
    /// Steps in the schedule.
    pub steps_total: usize,
    /// Indices of the finished steps, ascending.
    pub steps_done: Vec<usize>,
    /// Resumes, oldest first.
    pub resumes: Vec<Resume>,
    /// Retries, oldest first.
    pub retries: Vec<Retry>,
    /// Bound versus elapsed of the last session's schedule, when it completed.
    pub timing: Option<Timing>,
    /// The verdict against the plan's acceptance limits, as in `fit.json` (absent: no limits,
    /// or not fitted yet).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub acceptance: Option<gyrocal_fit::acceptance::Acceptance>,
    /// The fit's reference and headline figures, when fitted; the fit is in `fit.json`.
    #[serde(default)]
    pub fit_summary: Option<FitSummary>,
    /// The warm-up as the run found it while recording (plans with `[warmup]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub warmup: Option<WarmupRecord>,
    /// SHA-256 (lower-case hex) of the data files as they were when the run completed
    /// (`samples.csv`, `steps.csv`; `fit.json`'s is in `fit_summary`), so a file edited
    /// afterwards is found (`gyrocal verify`). Empty until the run completes, and in runs of
    /// earlier versions.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub checksums: BTreeMap<String, String>,
    /// The whole fit as manifests of format 1 embedded it (key `fit`): read, never written.
    /// A fit this version cannot read back is `None` here, with a warning: `fit.json` beside
    /// the manifest is the source of truth (see [`load_fit`]).
    #[serde(
        default,
        rename = "fit",
        deserialize_with = "lenient_fit",
        skip_serializing
    )]
    pub legacy_fit: Option<gyrocal_fit::Analysis>,
}

/// The manifest's plan: the [`crate::PlanDoc`] with the `[plan]` section's keys lifted to the
/// top (no `plan.plan.name`). Reading accepts both shapes.
mod manifest_plan {
    use std::path::Path;

    use serde::de::Error as _;
    use serde::ser::Error as _;
    use serde::{Deserialize as _, Deserializer, Serialize as _, Serializer};
    use serde_json::{Map, Value};

    use crate::plan::{Plan, PlanDoc};

    /// The sections that stay sections; every other key belongs to `[plan]`.
    const SECTIONS: [&str; 7] = [
        "table",
        "dmm",
        "simulation",
        "dut",
        "acceptance",
        "drift",
        "warmup",
    ];

    pub(super) fn serialize<S: Serializer>(plan: &Plan, s: S) -> Result<S::Ok, S::Error> {
        let doc = serde_json::to_value(plan.to_doc()).map_err(S::Error::custom)?;
        let Value::Object(mut doc) = doc else {
            return Err(S::Error::custom("a plan serialises to a JSON object"));
        };
        let mut out = match doc.remove("plan") {
            Some(Value::Object(section)) => section,
            _ => return Err(S::Error::custom("a plan has a [plan] section")),
        };
        for key in SECTIONS {
            if let Some(v) = doc.remove(key) {
                out.insert(key.to_string(), v);
            }
        }
        // a section a later plan format adds stays a section
        out.extend(doc);
        Value::Object(out).serialize(s)
    }

    pub(super) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Plan, D::Error> {
        let value = Value::deserialize(d)?;
        let Value::Object(mut obj) = value else {
            return Err(D::Error::custom("`plan` must be an object"));
        };
        let nested = matches!(obj.get("plan"), Some(Value::Object(_)));
        let doc = if nested {
            // format 1: the TOML document's shape
            Value::Object(obj)
        } else {
            let mut doc = Map::new();
            for key in SECTIONS {
                if let Some(v) = obj.remove(key) {
                    doc.insert(key.to_string(), v);
                }
            }
            doc.insert("plan".to_string(), Value::Object(obj));
            Value::Object(doc)
        };
        let doc: PlanDoc =
            serde_json::from_value(doc).map_err(|e| D::Error::custom(format!("plan: {e}")))?;
        Plan::from_doc(doc, Path::new("manifest.json: plan")).map_err(D::Error::custom)
    }
}

/// Reads the manifest's fit, or `None` (with a warning) when it is not an analysis this
/// version understands: an unreadable fit must never make a run directory unreadable.
fn lenient_fit<'de, D>(de: D) -> Result<Option<gyrocal_fit::Analysis>, D::Error>
where
    D: serde::Deserializer<'de>,
{
    let value = Option::<serde_json::Value>::deserialize(de)?;
    Ok(value.and_then(|v| match serde_json::from_value(v) {
        Ok(a) => Some(a),
        Err(e) => {
            tracing::warn!(error = %e, "the manifest's fit is not readable by this version; ignored");
            None
        }
    }))
}

/// A run directory read back by [`load`].
#[derive(Debug, Clone, PartialEq)]
pub struct RunData {
    /// The manifest.
    pub manifest: Manifest,
    /// The finished steps, in file order.
    pub steps: Vec<StepRecord>,
}

// ---------------------------------------------------------------------------------------------
// The writer
// ---------------------------------------------------------------------------------------------

/// The lock file inside a run directory (see [`RunDir`]).
pub const LOCK_FILE: &str = ".lock";

/// The temporary file of an atomic manifest replacement.
const MANIFEST_TMP: &str = ".manifest.json.tmp";

/// Removes what a failed [`RunDir::create`] may have written (its fixed file names only;
/// missing ones are fine). The lock file goes last.
fn remove_skeleton(dir: &Path) {
    for name in [
        MANIFEST_JSON,
        MANIFEST_TMP,
        SAMPLES_CSV,
        STEPS_CSV,
        LOCK_FILE,
    ] {
        let f = dir.join(name);
        match fs::remove_file(&f) {
            Ok(()) => tracing::debug!(file = %f.display(), "removed a file of a failed creation"),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => tracing::warn!(file = %f.display(), error = %e, "cannot remove"),
        }
    }
}

/// True when the file is empty or holds only a (possibly torn) header line of one of `headers`.
fn holds_at_most_header(path: &Path, headers: &[&[&str]]) -> bool {
    let longest = headers
        .iter()
        .map(|h| h.join(",").len() + 2)
        .max()
        .unwrap_or(0);
    let Ok(bytes) = read_capped(path, longest as u64) else {
        return false;
    };
    headers.iter().any(|h| {
        let full = format!("{}\n", h.join(","));
        let crlf = format!("{}\r\n", h.join(","));
        full.as_bytes().starts_with(&bytes) || crlf.as_bytes().starts_with(&bytes)
    })
}

/// Takes the run directory's exclusive lock.
///
/// A finished run's writer removes `.lock` (see [`RunDir`]'s `Drop`), so the file may vanish
/// between this process opening it and locking it: the lock would then be on a file nobody
/// else can find, while another process creates and locks a new `.lock`. So the lock counts
/// only when the file locked is still the one at the path (same device and inode); otherwise
/// it is taken again.
fn lock_dir(dir: &Path) -> Result<File, RunError> {
    let path = dir.join(LOCK_FILE);
    for _ in 0..8 {
        let file = fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&path)
            .map_err(io(&path, "open the lock file"))?;
        match file.try_lock() {
            Ok(()) => {}
            Err(std::fs::TryLockError::WouldBlock) => {
                return Err(RunError::Locked {
                    path: dir.to_path_buf(),
                });
            }
            Err(std::fs::TryLockError::Error(e)) => return Err(io(&path, "lock")(e)),
        }
        if still_at_path(&file, &path) {
            return Ok(file);
        }
        tracing::debug!(file = %path.display(), "the lock file was replaced meanwhile; locking again");
    }
    // the file keeps being replaced under us: another process is busy with this directory
    Err(RunError::Locked {
        path: dir.to_path_buf(),
    })
}

/// True when `file` is the file at `path` (same device and inode).
#[cfg(unix)]
fn still_at_path(file: &File, path: &Path) -> bool {
    use std::os::unix::fs::MetadataExt as _;
    match (file.metadata(), fs::metadata(path)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

/// Elsewhere the lock file is never removed (see `Drop for RunDir`), so it cannot be replaced.
#[cfg(not(unix))]
fn still_at_path(_file: &File, _path: &Path) -> bool {
    true
}

/// The step whose samples are being written.
#[derive(Debug, Clone, Copy)]
struct Current {
    step: usize,
    /// Length of samples.csv before this step's first row.
    start_len: u64,
    /// Rows written so far.
    count: u64,
}

/// An open run directory, for writing. See the module docs for the protocol.
#[derive(Debug)]
pub struct RunDir {
    dir: PathBuf,
    /// An exclusive advisory lock on `DIR/.lock`, held while this value lives: a second
    /// process (or a second `RunDir`) writing the same run directory is refused. The operating
    /// system drops the lock when the process dies, even by SIGKILL, so a resume is never
    /// blocked by a crashed run.
    _lock: File,
    schedule: Vec<Step>,
    manifest: Manifest,
    samples: csv::Writer<File>,
    /// Whether samples.csv has the `t_utc` column (not when a resume appends to a file an
    /// older gyrocal began).
    samples_utc: bool,
    steps: csv::Writer<File>,
    done: BTreeSet<usize>,
    current: Option<Current>,
    /// Converts the run clock to UTC for the `t_utc` columns.
    clock: ClockAnchor,
}

/// A finished run (complete, failed or aborted) leaves no `.lock` behind: the file is removed
/// while the lock is still held (the lock itself goes with the file handle, right after).
/// A run still `running` keeps it: its process died or failed to close the manifest, and the
/// next resume takes the lock as usual (an OS lock dies with its process, so a stale `.lock`
/// never blocks). Not on Windows, where an open file cannot be removed.
impl Drop for RunDir {
    fn drop(&mut self) {
        if self.manifest.status == Status::Running || cfg!(not(unix)) {
            return;
        }
        let path = self.dir.join(LOCK_FILE);
        match fs::remove_file(&path) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => {
                tracing::warn!(file = %path.display(), error = %e, "cannot remove the lock file")
            }
        }
    }
}

impl RunDir {
    /// Creates a new run directory (or fills an existing empty one) for `plan`, writes both CSV
    /// headers and a `running` manifest. Refuses a directory that holds anything but what an
    /// interrupted creation leaves ([`RunDir::is_half_created`]), which it reuses.
    ///
    /// Creation is all or nothing: when a step fails (disk full, permissions), the files this
    /// call created are removed again, and so are the directories it created (the run directory
    /// and missing parents, when empty); a directory that existed before is left in place,
    /// empty. The error names the file that could not be written.
    pub fn create(path: &Path, plan: &Plan, meta: RunMeta) -> Result<RunDir, RunError> {
        if path.exists() && !Self::is_half_created(path)? {
            return Err(RunError::NotEmpty {
                path: path.to_path_buf(),
            });
        }
        // The directories this call creates, deepest first, for the cleanup.
        let mut created_dirs = Vec::new();
        let mut p = path;
        while !p.as_os_str().is_empty() && fs::symlink_metadata(p).is_err() {
            created_dirs.push(p.to_path_buf());
            match p.parent() {
                Some(parent) => p = parent,
                None => break,
            }
        }
        let remove_dirs = |dirs: &[PathBuf]| {
            for d in dirs {
                // only empty ones: what someone else put there meanwhile stays
                if fs::remove_dir(d).is_ok() {
                    tracing::debug!(dir = %d.display(), "removed a directory of a failed creation");
                }
            }
        };
        if let Err(e) = fs::create_dir_all(path) {
            remove_dirs(&created_dirs);
            return Err(io(path, "create the directory")(e));
        }
        let lock = match lock_dir(path) {
            Ok(lock) => lock,
            // Another process holds the lock: it is creating or writing this run; touch nothing.
            Err(e @ RunError::Locked { .. }) => return Err(e),
            Err(e) => {
                // Without the lock, only a directory this call created is cleaned.
                if !created_dirs.is_empty() {
                    remove_skeleton(path);
                }
                remove_dirs(&created_dirs);
                return Err(e);
            }
        };
        // Under the lock, the directory must still be empty or half created (another process
        // may have finished creating it between the check above and the lock).
        let result = match Self::is_half_created(path) {
            Ok(true) => Self::create_locked(path, plan, meta, lock),
            Ok(false) => {
                return Err(RunError::NotEmpty {
                    path: path.to_path_buf(),
                });
            }
            Err(e) => Err(e),
        };
        match result {
            Ok(rd) => Ok(rd),
            Err(e) => {
                tracing::warn!(dir = %path.display(), error = %e, "run directory creation failed; removing what it created");
                remove_skeleton(path);
                remove_dirs(&created_dirs);
                Err(e)
            }
        }
    }

    /// True when `path` is a directory that is empty or holds only what an interrupted
    /// [`RunDir::create`] leaves (a crash, a kill or a power cut between its first file and its
    /// manifest): no `manifest.json` (so no run ever started in it and no reading was ever
    /// taken), and nothing but `.lock`, `.manifest.json.tmp` and `samples.csv` / `steps.csv`
    /// holding at most their header. `gyrocal run --out DIR` and `--resume DIR` start the run
    /// in such a directory instead of refusing it. Errors only when the directory cannot be
    /// read.
    pub fn is_half_created(path: &Path) -> Result<bool, RunError> {
        if !path.is_dir() {
            return Ok(false);
        }
        let entries = fs::read_dir(path).map_err(io(path, "read the directory"))?;
        for entry in entries {
            let entry = entry.map_err(io(path, "read the directory"))?;
            let name = entry.file_name();
            let Some(name) = name.to_str() else {
                return Ok(false);
            };
            let file = entry.path();
            let regular = fs::symlink_metadata(&file).is_ok_and(|m| m.is_file());
            let ok = match name {
                LOCK_FILE | MANIFEST_TMP => regular,
                SAMPLES_CSV => regular && holds_at_most_header(&file, SAMPLES_HEADERS),
                STEPS_CSV => regular && holds_at_most_header(&file, STEPS_HEADERS),
                _ => false,
            };
            if !ok {
                return Ok(false);
            }
        }
        Ok(true)
    }

    fn create_locked(
        path: &Path,
        plan: &Plan,
        meta: RunMeta,
        lock: File,
    ) -> Result<RunDir, RunError> {
        // A half-created directory's CSVs start again from nothing.
        for name in [SAMPLES_CSV, STEPS_CSV] {
            let f = path.join(name);
            match fs::remove_file(&f) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(io(&f, "remove")(e)),
            }
        }
        let samples = open_csv(&path.join(SAMPLES_CSV), &SAMPLES_HEADER, true)?;
        let steps = open_csv(&path.join(STEPS_CSV), &STEPS_HEADER, true)?;
        let now = now_utc();
        let manifest = Manifest {
            format_version: FORMAT_VERSION,
            status: Status::Running,
            reason: None,
            gyrocal_version: meta.gyrocal_version,
            plan_hash: plan.hash(),
            plan: plan.clone(),
            simulated: meta.simulated,
            simulated_by: None,
            checksums: BTreeMap::new(),
            dut: meta.dut,
            context: meta.context,
            station: meta.station,
            virtual_time: meta.virtual_time,
            instruments: meta.instruments,
            deviations: Vec::new(),
            started_utc: now.clone(),
            ended_utc: None,
            updated_utc: now,
            elapsed_s: 0.0,
            steps_total: plan.step_count(),
            steps_done: Vec::new(),
            resumes: Vec::new(),
            retries: Vec::new(),
            timing: None,
            fit_summary: None,
            warmup: None,
            acceptance: None,
            legacy_fit: None,
        };
        let mut rd = RunDir {
            dir: path.to_path_buf(),
            _lock: lock,
            schedule: plan.schedule(),
            manifest,
            samples,
            samples_utc: true,
            steps,
            done: BTreeSet::new(),
            current: None,
            clock: ClockAnchor::now(0.0),
        };
        sync_dir(path)?;
        rd.write_manifest()?;
        tracing::info!(dir = %path.display(), hash = %rd.manifest.plan_hash, "run directory created");
        Ok(rd)
    }

    /// Reopens an interrupted run to continue it with `plan`: refuses a different plan (by
    /// hash) or a complete run, keeps every finished step, drops the partial step's samples
    /// and torn last lines, records the resume and marks the run `running`.
    pub fn open_for_resume(path: &Path, plan: &Plan) -> Result<RunDir, RunError> {
        let mpath = path.join(MANIFEST_JSON);
        let manifest = read_manifest(&mpath)?;
        let finished = manifest.status != Status::Running;
        let mut lock = Some(lock_dir(path)?);
        let result = Self::resume_locked(path, plan, manifest, &mut lock);
        // A refused resume of a finished run leaves it as it was: without a `.lock` (removed
        // while still held, as `Drop` does).
        if result.is_err()
            && finished
            && let Some(file) = lock.take()
        {
            let lpath = path.join(LOCK_FILE);
            if let Err(e) = fs::remove_file(&lpath)
                && e.kind() != std::io::ErrorKind::NotFound
            {
                tracing::warn!(file = %lpath.display(), error = %e, "cannot remove the lock file");
            }
            drop(file);
        }
        result
    }

    /// [`RunDir::open_for_resume`] under the lock, which it takes from `lock` into the
    /// [`RunDir`] it returns (and leaves there on an error).
    fn resume_locked(
        path: &Path,
        plan: &Plan,
        mut manifest: Manifest,
        lock: &mut Option<File>,
    ) -> Result<RunDir, RunError> {
        let mpath = path.join(MANIFEST_JSON);
        let plan_hash = plan.hash();
        if manifest.plan_hash != plan_hash {
            let changes = plan_changes(&manifest.plan, plan);
            return Err(RunError::PlanChanged {
                path: mpath,
                run_hash: manifest.plan_hash,
                plan_hash,
                changes,
            });
        }
        if manifest.status == Status::Complete {
            return Err(RunError::AlreadyComplete { path: mpath });
        }
        let schedule = plan.schedule();

        // steps.csv: repair the tail, then every row must fit the schedule.
        let spath = path.join(STEPS_CSV);
        let (steps_bytes, torn_steps) = read_repaired(&spath, STEPS_HEADERS, MAX_STEPS_BYTES)?;
        let records = parse_steps(&spath, &steps_bytes, &schedule)?;
        let done: BTreeSet<usize> = records.iter().map(|r| r.step).collect();
        let expected: BTreeMap<usize, u64> = records
            .iter()
            .map(|r| (r.step, r.n + r.overloads))
            .collect();

        // samples.csv: keep the finished steps' rows, drop everything from the first other row.
        let sapath = path.join(SAMPLES_CSV);
        let (samples_len, torn_samples, samples_utc) = repair_samples(&sapath)?;
        let (keep_len, dropped) = scan_samples(&sapath, samples_len, &schedule, &expected)?;
        truncate(&sapath, keep_len)?;
        truncate(&spath, steps_bytes.len() as u64)?;

        let samples = open_csv(&sapath, &SAMPLES_HEADER, false)?;
        let steps = open_csv(&spath, &STEPS_HEADER, false)?;
        let from_step = schedule.iter().map(|s| s.index).find(|i| !done.contains(i));
        manifest.resumes.push(Resume {
            at_utc: now_utc(),
            from_step,
            steps_done: done.len(),
            samples_dropped: dropped,
            torn_bytes_dropped: torn_steps + torn_samples,
            previous_status: manifest.status,
            previous_reason: manifest.reason.take(),
        });
        manifest.status = Status::Running;
        manifest.ended_utc = None;
        manifest.steps_done = done.iter().copied().collect();
        tracing::info!(
            dir = %path.display(),
            steps_done = done.len(),
            samples_dropped = dropped,
            from_step = ?from_step,
            "resuming run"
        );
        // the manifest is rewritten in this version's format (steps.csv was upgraded above)
        manifest.format_version = FORMAT_VERSION;
        // The run clock goes on from the last time on disk: the manifest's `elapsed_s`, or
        // the end of the last finished step when the process died after fsyncing that step
        // but before rewriting the manifest (else the resumed readings' t_s would run back
        // into the kept ones, and a drift record would overlap itself).
        let last_step_end = records.iter().map(|r| r.t_end_s).fold(0.0_f64, f64::max);
        if last_step_end > manifest.elapsed_s {
            tracing::info!(
                manifest_elapsed_s = manifest.elapsed_s,
                last_step_end_s = last_step_end,
                "the run clock resumes from the last finished step"
            );
            manifest.elapsed_s = last_step_end;
        }
        let clock = ClockAnchor::now(manifest.elapsed_s);
        let Some(lock) = lock.take() else {
            return Err(RunError::Protocol {
                path: path.join(LOCK_FILE),
                message: "the run directory's lock was not held".into(),
            });
        };
        let mut rd = RunDir {
            dir: path.to_path_buf(),
            _lock: lock,
            schedule,
            manifest,
            samples,
            samples_utc,
            steps,
            done,
            current: None,
            clock,
        };
        rd.write_manifest()?;
        Ok(rd)
    }

    /// The run directory.
    pub fn path(&self) -> &Path {
        &self.dir
    }

    /// The manifest as last written.
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    /// Tells the run directory that the run clock reads `run_clock_s` now, so that the `t_utc`
    /// columns are the wall-clock times of the run clock's `t_s`. [`RunDir::create`] and
    /// [`RunDir::open_for_resume`] set this (run clock 0, or the manifest's `elapsed_s`), which
    /// is right to the few milliseconds between opening the directory and starting the clock;
    /// a writer whose clock starts later calls this when it starts it. A non-finite or
    /// negative value is ignored.
    pub fn anchor_clock(&mut self, run_clock_s: f64) {
        if run_clock_s.is_finite() && run_clock_s >= 0.0 {
            self.clock = ClockAnchor::now(run_clock_s);
        }
    }

    /// The wall-clock anchor of the run clock (see [`RunDir::anchor_clock`]).
    pub fn clock_anchor(&self) -> ClockAnchor {
        self.clock
    }

    /// Records that this session runs in virtual time ([`Manifest::virtual_time`]; a
    /// [`RunMeta`] says so for a new run).
    pub fn set_virtual_time(&mut self) -> Result<(), RunError> {
        if self.manifest.virtual_time {
            return Ok(());
        }
        self.manifest.virtual_time = true;
        self.write_manifest()
    }

    /// The schedule of the plan this run follows.
    pub fn schedule(&self) -> &[Step] {
        &self.schedule
    }

    /// Indices of the finished steps.
    pub fn done_steps(&self) -> &BTreeSet<usize> {
        &self.done
    }

    /// The steps still to run, in schedule order.
    pub fn remaining_steps(&self) -> Vec<Step> {
        self.schedule
            .iter()
            .filter(|s| !self.done.contains(&s.index))
            .copied()
            .collect()
    }

    /// Appends a chunk of raw readings of `step` to samples.csv and flushes it. Indices must
    /// continue the step's previous chunks (0, 1, 2, ...); only one step may be in progress.
    pub fn append_samples(&mut self, step: usize, samples: &[Sample]) -> Result<(), RunError> {
        let path = self.dir.join(SAMPLES_CSV);
        let proto = |message: String| RunError::Protocol {
            path: path.clone(),
            message,
        };
        let Some(s) = self.schedule.get(step).copied() else {
            return Err(proto(format!("step {step} is not in the schedule")));
        };
        if self.done.contains(&step) {
            return Err(proto(format!("step {step} is already recorded")));
        }
        let mut cur = match self.current {
            Some(c) if c.step == step => c,
            Some(c) => {
                return Err(proto(format!(
                    "step {} is in progress; record or restart it before step {step}",
                    c.step
                )));
            }
            None => {
                let start_len = self
                    .samples
                    .get_ref()
                    .metadata()
                    .map_err(io(&path, "read the length of"))?
                    .len();
                Current {
                    step,
                    start_len,
                    count: 0,
                }
            }
        };
        for (k, smp) in samples.iter().enumerate() {
            let want = cur.count + k as u64;
            if smp.index != want {
                return Err(proto(format!(
                    "step {step}: sample index {} where {want} was due",
                    smp.index
                )));
            }
            if !smp.t_s.is_finite() || smp.volts.is_some_and(|v| !v.is_finite()) {
                return Err(proto(format!(
                    "step {step}: sample {} is not finite (t_s {}, volts {:?}); an overload is volts = None",
                    smp.index, smp.t_s, smp.volts
                )));
            }
        }
        for smp in samples {
            let row = SampleRow {
                step,
                index: smp.index,
                t_s: round_significant(smp.t_s),
                rate_dps: s.rate_dps,
                volts: round_opt(smp.volts),
                overload: u8::from(smp.volts.is_none()),
                t_utc: self.samples_utc.then(|| self.clock.utc(smp.t_s)),
            };
            let written = if self.samples_utc {
                self.samples.serialize(row)
            } else {
                // an older file's columns: no t_utc
                self.samples.serialize((
                    row.step,
                    row.index,
                    row.t_s,
                    row.rate_dps,
                    row.volts,
                    row.overload,
                ))
            };
            written.map_err(|e| csv_write(&path, e))?;
        }
        self.samples.flush().map_err(io(&path, "write"))?;
        cur.count += samples.len() as u64;
        self.current = Some(cur);
        Ok(())
    }

    /// Drops the samples written so far for `step` (e.g. before re-acquiring it after a
    /// failure), so the step starts again at index 0. A no-op for a step with no samples.
    pub fn restart_step(&mut self, step: usize) -> Result<(), RunError> {
        let path = self.dir.join(SAMPLES_CSV);
        if self.done.contains(&step) {
            return Err(RunError::Protocol {
                path,
                message: format!("step {step} is already recorded and cannot be restarted"),
            });
        }
        if let Some(c) = self.current.filter(|c| c.step == step) {
            self.samples.flush().map_err(io(&path, "write"))?;
            let f = self.samples.get_ref();
            f.set_len(c.start_len).map_err(io(&path, "truncate"))?;
            f.sync_data().map_err(io(&path, "sync"))?;
            self.current = None;
            tracing::debug!(step, dropped = c.count, "step restarted");
        }
        Ok(())
    }

    /// Records a finished step: syncs samples.csv, appends the row to steps.csv, flushes and
    /// fsyncs it, then updates the manifest. The record must match the schedule (step, pass,
    /// rate) and the samples written (`n + overloads`), with `n ≥ 1` and a finite mean.
    pub fn append_step(&mut self, rec: StepRecord) -> Result<(), RunError> {
        let spath = self.dir.join(STEPS_CSV);
        let proto = |message: String| RunError::Protocol {
            path: spath.clone(),
            message,
        };
        let Some(s) = self.schedule.get(rec.step).copied() else {
            return Err(proto(format!("step {} is not in the schedule", rec.step)));
        };
        if self.done.contains(&rec.step) {
            return Err(proto(format!("step {} is already recorded", rec.step)));
        }
        if rec.pass != s.pass || rec.rate_dps.to_bits() != s.rate_dps.to_bits() {
            return Err(proto(format!(
                "step {}: pass {} rate {} where the schedule has pass {} rate {}",
                rec.step, rec.pass, rec.rate_dps, s.pass, s.rate_dps
            )));
        }
        let written = self
            .current
            .filter(|c| c.step == rec.step)
            .map_or(0, |c| c.count);
        if rec.n == 0 || rec.n.checked_add(rec.overloads) != Some(written) {
            return Err(proto(format!(
                "step {}: n {} + overloads {} must equal the {written} samples written, with n >= 1",
                rec.step, rec.n, rec.overloads
            )));
        }
        if let Some(msg) = record_problem(&rec) {
            return Err(proto(format!("step {}: {msg}", rec.step)));
        }
        let sapath = self.dir.join(SAMPLES_CSV);
        self.samples.flush().map_err(io(&sapath, "write"))?;
        self.samples
            .get_ref()
            .sync_data()
            .map_err(io(&sapath, "sync"))?;
        let start_utc = self.clock.utc(rec.t_start_s);
        let end_utc = self.clock.utc(rec.t_end_s);
        let r = rounded(&rec);
        let row = StepRow {
            step: r.step,
            pass: r.pass,
            rate_dps: r.rate_dps,
            rate_meas_dps: r.rate_meas_dps,
            rate_meas_std_dps: r.rate_meas_std_dps,
            rate_meas_min_dps: r.rate_meas_min_dps,
            rate_meas_max_dps: r.rate_meas_max_dps,
            rate_samples: r.rate_samples,
            volts: r.volts,
            volts_std: r.volts_std,
            n: r.n,
            overloads: r.overloads,
            retries: r.retries,
            t_start_s: r.t_start_s,
            t_end_s: r.t_end_s,
            t_start_utc: &start_utc,
            t_end_utc: &end_utc,
        };
        self.steps
            .serialize(&row)
            .map_err(|e| csv_write(&spath, e))?;
        self.steps.flush().map_err(io(&spath, "write"))?;
        self.steps
            .get_ref()
            .sync_data()
            .map_err(io(&spath, "sync"))?;
        self.done.insert(rec.step);
        self.current = None;
        self.manifest.steps_done = self.done.iter().copied().collect();
        tracing::debug!(
            step = rec.step,
            rate_dps = rec.rate_dps,
            n = rec.n,
            "step recorded"
        );
        self.write_manifest()
    }

    /// Marks the run simulated because `by` says so (instruments that identify as
    /// simulators); a run started with `--simulate` is already.
    pub fn mark_simulated(&mut self, by: &str) -> Result<(), RunError> {
        if self.manifest.simulated {
            return Ok(());
        }
        self.manifest.simulated = true;
        self.manifest.simulated_by = Some(by.to_string());
        self.write_manifest()
    }

    /// Sets the instruments' identities.
    pub fn set_instruments(&mut self, instruments: Instruments) -> Result<(), RunError> {
        self.manifest.instruments = instruments;
        self.write_manifest()
    }

    /// Records the warm-up's state (written at every window, so a crash keeps the curve).
    pub fn set_warmup(&mut self, warmup: WarmupRecord) -> Result<(), RunError> {
        self.manifest.warmup = Some(warmup);
        self.write_manifest()
    }

    /// Records a departure from the method (see [`Deviation`]).
    pub fn add_deviation(&mut self, kind: &str, text: &str) -> Result<(), RunError> {
        self.manifest.deviations.push(Deviation {
            kind: kind.to_string(),
            text: text.to_string(),
            at_utc: now_utc(),
        });
        self.write_manifest()
    }

    /// Sets the elapsed run-clock time, s (the caller's figure; finite, ≥ 0).
    pub fn set_elapsed(&mut self, elapsed_s: f64) -> Result<(), RunError> {
        self.check_finite("elapsed_s", elapsed_s)?;
        self.manifest.elapsed_s = round_significant(elapsed_s);
        self.write_manifest()
    }

    /// Logs a retry.
    pub fn log_retry(&mut self, retry: Retry) -> Result<(), RunError> {
        self.check_finite("retry t_s", retry.t_s)?;
        self.manifest.retries.push(Retry {
            t_s: round_significant(retry.t_s),
            ..retry
        });
        self.write_manifest()
    }

    /// Records bound versus elapsed.
    pub fn set_timing(&mut self, timing: Timing) -> Result<(), RunError> {
        for (what, v) in [
            ("bound_s", timing.bound_s),
            ("elapsed_s", timing.elapsed_s),
            ("ratio", timing.ratio),
        ] {
            self.check_finite(what, v)?;
        }
        self.manifest.timing = Some(Timing {
            bound_s: round_significant(timing.bound_s),
            elapsed_s: round_significant(timing.elapsed_s),
            ratio: round_significant(timing.ratio),
            ..timing
        });
        self.write_manifest()
    }

    /// Stores the fit document: writes `fit.json` atomically (every computed number rounded
    /// once, see [`crate::num`]) and references it from the manifest ([`FitSummary`]: its
    /// name, the SHA-256 of its bytes, the headline figures).
    pub fn set_fit(&mut self, fit: gyrocal_fit::Analysis) -> Result<(), RunError> {
        let path = self.dir.join(FIT_JSON);
        let cannot = |e: serde_json::Error| RunError::Protocol {
            path: path.clone(),
            message: format!("cannot serialise the fit: {e}"),
        };
        let mut doc = serde_json::to_value(&fit).map_err(cannot)?;
        round_json(&mut doc);
        let mut bytes = serde_json::to_vec_pretty(&doc).map_err(cannot)?;
        bytes.push(b'\n');
        write_atomic(&self.dir, FIT_JSON, &bytes)?;
        self.manifest.fit_summary = Some(FitSummary::of(&fit, sha256_hex(&bytes)));
        // the verdict as fit.json holds it (rounded alike), so the two documents agree
        self.manifest.acceptance = serde_json::from_value(doc["acceptance"].clone()).ok();
        self.manifest.legacy_fit = None;
        self.write_manifest()
    }

    /// Closes the run with `status` (not `running`) and its reason, the run-clock elapsed
    /// time and the wall-clock end. `complete` is refused while steps remain.
    pub fn finish(
        &mut self,
        status: Status,
        reason: Option<String>,
        elapsed_s: f64,
    ) -> Result<(), RunError> {
        self.check_finite("elapsed_s", elapsed_s)?;
        let path = self.dir.join(MANIFEST_JSON);
        if status == Status::Running {
            return Err(RunError::Protocol {
                path,
                message: "finish with status running".into(),
            });
        }
        if status == Status::Complete && self.done.len() != self.schedule.len() {
            return Err(RunError::Protocol {
                path,
                message: format!(
                    "cannot mark complete: {} of {} steps done",
                    self.done.len(),
                    self.schedule.len()
                ),
            });
        }
        // Best effort to get everything on disk before the final word.
        let sapath = self.dir.join(SAMPLES_CSV);
        self.samples.flush().map_err(io(&sapath, "write"))?;
        self.samples
            .get_ref()
            .sync_data()
            .map_err(io(&sapath, "sync"))?;
        if status == Status::Complete {
            for name in [SAMPLES_CSV, STEPS_CSV] {
                let path = self.dir.join(name);
                let sum = sha256_file(&path).map_err(opened)?;
                self.manifest.checksums.insert(name.to_string(), sum);
            }
        }
        self.manifest.status = status;
        self.manifest.reason = reason;
        self.manifest.elapsed_s = round_significant(elapsed_s);
        self.manifest.ended_utc = Some(now_utc());
        self.write_manifest()
    }

    /// Writes another file of the run (e.g. `report.html`) atomically.
    pub fn write_file(&self, name: &str, bytes: &[u8]) -> Result<(), RunError> {
        if name.contains(['/', '\\']) || name.starts_with('.') || name.is_empty() {
            return Err(RunError::Protocol {
                path: self.dir.join(name),
                message: "a run file name must be a plain, non-hidden name".into(),
            });
        }
        write_atomic(&self.dir, name, bytes)
    }

    fn check_finite(&self, what: &str, v: f64) -> Result<(), RunError> {
        if v.is_finite() && v >= 0.0 || (what == "ratio" && v.is_finite()) {
            Ok(())
        } else {
            Err(RunError::Protocol {
                path: self.dir.join(MANIFEST_JSON),
                message: format!("{what} must be finite and >= 0 (got {v})"),
            })
        }
    }

    fn write_manifest(&mut self) -> Result<(), RunError> {
        store_manifest(&self.dir, &mut self.manifest)
    }

    /// Writes a result file of the run (`allan.json`, `allan.html`, any later one) atomically
    /// and records its SHA-256 in the manifest's `checksums`, so `gyrocal verify` checks it
    /// and `gyrocal report` refuses it edited. Not for the data files, the manifest or
    /// `fit.json` (see [`RunDir::set_fit`]).
    pub fn write_result(&mut self, name: &str, bytes: &[u8]) -> Result<(), RunError> {
        record_result(&self.dir, &mut self.manifest, name, bytes)
    }
}

/// Replaces the manifest of `dir` with `m` (its `updated_utc` set to now), atomically.
fn store_manifest(dir: &Path, m: &mut Manifest) -> Result<(), RunError> {
    m.updated_utc = now_utc();
    let bytes = serde_json::to_vec_pretty(m).map_err(|e| RunError::Protocol {
        path: dir.join(MANIFEST_JSON),
        message: format!("cannot serialise the manifest: {e}"),
    })?;
    write_atomic(dir, MANIFEST_JSON, &bytes)
}

/// The files a result may not replace: the data, the record, the fit (which has its own
/// record), the lock and the log.
const NOT_RESULTS: [&str; 6] = [
    SAMPLES_CSV,
    STEPS_CSV,
    MANIFEST_JSON,
    FIT_JSON,
    LOCK_FILE,
    "run.log",
];

/// Writes the result `name` into `dir` atomically, then records its SHA-256 in `m` and
/// stores the manifest (the caller holds the run's lock). If the manifest cannot be stored,
/// the result file is on disk without a record (`gyrocal verify` then says so).
fn record_result(dir: &Path, m: &mut Manifest, name: &str, bytes: &[u8]) -> Result<(), RunError> {
    if name.contains(['/', '\\'])
        || name.starts_with('.')
        || name.is_empty()
        || NOT_RESULTS.contains(&name)
    {
        return Err(RunError::Protocol {
            path: dir.join(name),
            message: "a result file name must be a plain, non-hidden name other than the run's data, manifest, fit, lock and log".into(),
        });
    }
    write_atomic(dir, name, bytes)?;
    m.checksums.insert(name.to_string(), sha256_hex(bytes));
    store_manifest(dir, m)?;
    tracing::info!(file = %dir.join(name).display(), "result written and recorded");
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Readers
// ---------------------------------------------------------------------------------------------

/// Reads a run directory (for the report and `gyrocal fit`): the manifest and the finished
/// steps. Read-only: a torn last line of steps.csv is ignored, not repaired.
pub fn load(dir: &Path) -> Result<RunData, RunError> {
    let manifest = read_manifest(&dir.join(MANIFEST_JSON))?;
    let spath = dir.join(STEPS_CSV);
    let bytes = read_capped(&spath, MAX_STEPS_BYTES)?;
    let (bytes, _) = complete_lines(&bytes);
    check_header(&spath, bytes, STEPS_HEADERS)?;
    let schedule = manifest.plan.schedule();
    let steps = parse_steps(&spath, bytes, &schedule)?;
    Ok(RunData { manifest, steps })
}

/// Reads a run directory's `fit.json` (what `gyrocal_analysis::sweep::fit_run` wrote): `Ok(None)` when the run
/// has none (not fitted yet, or written before fit.json existed: see
/// [`Manifest::legacy_fit`]). A file that does not parse is an error naming it, its line and
/// column.
pub fn load_fit(dir: &Path) -> Result<Option<gyrocal_fit::Analysis>, RunError> {
    let path = dir.join(FIT_JSON);
    match fs::symlink_metadata(&path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(io(&path, "read")(e)),
        Ok(_) => {}
    }
    let bytes = read_capped(&path, MAX_FIT_BYTES)?;
    serde_json::from_slice(&bytes)
        .map(Some)
        .map_err(|e| RunError::Json {
            path: path.clone(),
            line: e.line(),
            column: e.column(),
            message: e.to_string(),
        })
}

/// Reads every complete row of samples.csv (a torn last line is ignored).
pub fn load_samples(dir: &Path) -> Result<Vec<SampleRow>, RunError> {
    let path = dir.join(SAMPLES_CSV);
    let bytes = read_capped(&path, MAX_SAMPLES_BYTES)?;
    let (bytes, _) = complete_lines(&bytes);
    check_header(&path, bytes, SAMPLES_HEADERS)?;
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .from_reader(bytes);
    // by name: files written before `t_utc` existed lack that column
    let mut out = Vec::new();
    for row in rdr.deserialize::<SampleRow>() {
        out.push(row.map_err(|e| csv_read(&path, &e))?);
    }
    Ok(out)
}

/// Reads a file of a run directory whole, refusing anything but a regular file and more than
/// `cap` bytes (checked from the size first, then by reading at most `cap + 1` bytes, so a file
/// that grows or never ends costs at most `cap` bytes of memory).
pub fn read_capped(path: &Path, cap: u64) -> Result<Vec<u8>, RunError> {
    use std::io::Read as _;
    let file = open_regular(path).map_err(opened)?;
    let meta = file.metadata().map_err(io(path, "read"))?;
    let too_large = || RunError::TooLarge {
        path: path.to_path_buf(),
        cap,
    };
    if meta.len() > cap {
        return Err(too_large());
    }
    let mut bytes = Vec::with_capacity(usize::try_from(meta.len()).unwrap_or(0));
    file.take(cap.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(io(path, "read"))?;
    if bytes.len() as u64 > cap {
        return Err(too_large());
    }
    Ok(bytes)
}

/// The plan a run was started with, from its manifest: `gyrocal run --resume DIR` needs no
/// plan file. A directory without a manifest is said to be no run directory.
pub fn run_plan(dir: &Path) -> Result<Plan, RunError> {
    let path = dir.join(MANIFEST_JSON);
    if !path.exists() {
        return Err(RunError::NotARun {
            path: dir.to_path_buf(),
        });
    }
    read_manifest(&path).map(|m| m.plan)
}

/// The keys whose values differ between the plan of a run and another plan, as
/// `[section] key: run's value (run) vs other value (this plan)`, in the plan file's order.
pub fn plan_changes(run: &Plan, other: &Plan) -> Vec<String> {
    let (Ok(a), Ok(b)) = (
        serde_json::to_value(run.to_doc()),
        serde_json::to_value(other.to_doc()),
    ) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for section in ["plan", "table", "dmm", "simulation"] {
        let empty = serde_json::Map::new();
        let sa = a.get(section).and_then(|v| v.as_object()).unwrap_or(&empty);
        let sb = b.get(section).and_then(|v| v.as_object()).unwrap_or(&empty);
        let mut keys: Vec<&String> = sa.keys().chain(sb.keys()).collect();
        keys.dedup();
        let mut seen = std::collections::BTreeSet::new();
        for key in keys {
            if !seen.insert(key) {
                continue;
            }
            let (va, vb) = (sa.get(key), sb.get(key));
            if va != vb {
                let show =
                    |v: Option<&serde_json::Value>| v.map_or("(none)".into(), |v| v.to_string());
                out.push(format!(
                    "[{section}] {key}: {} (run) vs {} (this plan)",
                    show(va),
                    show(vb)
                ));
            }
        }
    }
    out
}

fn read_manifest(path: &Path) -> Result<Manifest, RunError> {
    let bytes = read_capped(path, MAX_MANIFEST_BYTES)?;
    let m: Manifest = serde_json::from_slice(&bytes).map_err(|e| RunError::Json {
        path: path.to_path_buf(),
        line: e.line(),
        column: e.column(),
        message: e.to_string(),
    })?;
    if !FORMAT_VERSIONS_READ.contains(&m.format_version) {
        return Err(RunError::Inconsistent {
            path: path.to_path_buf(),
            message: format!(
                "format_version {} is not one this gyrocal reads ({FORMAT_VERSIONS_READ:?}); \
                 a newer gyrocal wrote it",
                m.format_version
            ),
        });
    }
    let h = m.plan.hash();
    if h != m.plan_hash {
        return Err(RunError::Inconsistent {
            path: path.to_path_buf(),
            message: format!(
                "plan_hash {} does not match its plan (hash {h})",
                m.plan_hash
            ),
        });
    }
    Ok(m)
}

/// Splits off a torn last line: returns the bytes up to and including the last newline, and
/// how many bytes followed it.
fn complete_lines(bytes: &[u8]) -> (&[u8], u64) {
    let keep = bytes.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
    (
        bytes.get(..keep).unwrap_or_default(),
        (bytes.len() - keep) as u64,
    )
}

/// Checks the first line against the accepted headers (current first); returns the index of
/// the one found. A column name that appears twice is named with both positions.
fn check_header(path: &Path, bytes: &[u8], accepted: &[&[&str]]) -> Result<usize, RunError> {
    let first = bytes.split(|&b| b == b'\n').next().unwrap_or_default();
    let first = first.strip_suffix(b"\r").unwrap_or(first);
    let text = String::from_utf8_lossy(first);
    let names: Vec<&str> = text.split(',').collect();
    for (j, name) in names.iter().enumerate() {
        if let Some(i) = names.iter().take(j).position(|n| n == name) {
            return Err(RunError::Csv {
                path: path.to_path_buf(),
                line: 1,
                message: format!(
                    "the header names column `{name}` twice (columns {} and {})",
                    i + 1,
                    j + 1
                ),
            });
        }
    }
    if let Some(k) = accepted
        .iter()
        .position(|h| h.len() == names.len() && h.iter().zip(&names).all(|(a, b)| a == b))
    {
        return Ok(k);
    }
    Err(RunError::Csv {
        path: path.to_path_buf(),
        line: 1,
        message: format!(
            "header is {text:?}, expected {:?}",
            accepted.first().map(|h| h.join(",")).unwrap_or_default()
        ),
    })
}

/// Reads a CSV for resume: drops a torn last line; an empty file (or one with only a torn
/// header) gets its header back; a file with an older accepted header (`accepted[1..]`) is
/// rewritten, atomically, with the current one (`accepted[0]`), each old row getting an empty
/// cell in every column the old header lacks (see `upgrade_steps`). Returns the repaired
/// content and the bytes dropped.
fn read_repaired(path: &Path, accepted: &[&[&str]], cap: u64) -> Result<(Vec<u8>, u64), RunError> {
    let header = accepted.first().copied().unwrap_or_default();
    let bytes = read_capped(path, cap)?;
    let (keep, torn) = complete_lines(&bytes);
    if keep.is_empty() {
        let mut h = header.join(",").into_bytes();
        h.push(b'\n');
        fs::write(path, &h).map_err(io(path, "write"))?;
        return Ok((h, torn));
    }
    let which = check_header(path, keep, accepted)?;
    if torn > 0 {
        tracing::warn!(file = %path.display(), bytes = torn, "dropping a torn last line");
    }
    if which == 0 {
        return Ok((keep.to_vec(), torn));
    }
    let old = accepted.get(which).copied().unwrap_or_default();
    let upgraded = upgrade_steps(keep, old, header);
    let dir = path.parent().unwrap_or(Path::new("."));
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    write_atomic(dir, &name, &upgraded)?;
    tracing::info!(file = %path.display(), "rewrote an older header with the current columns");
    Ok((upgraded, torn))
}

/// Prepares samples.csv for a resume without reading it whole: finds the end of its last
/// complete line (a torn tail is dropped later by the truncation), checks the header, and
/// writes the header into an empty file. Returns (length of the complete lines, torn bytes,
/// whether the header has `t_utc`).
fn repair_samples(path: &Path) -> Result<(u64, u64, bool), RunError> {
    use std::io::{Read as _, Seek as _, SeekFrom};
    let mut file = open_regular(path).map_err(opened)?;
    let meta = file.metadata().map_err(io(path, "read"))?;
    let len = meta.len();
    if len > MAX_SAMPLES_BYTES {
        return Err(RunError::TooLarge {
            path: path.to_path_buf(),
            cap: MAX_SAMPLES_BYTES,
        });
    }
    // The last newline, reading backwards in blocks.
    let mut keep = 0u64;
    let mut end = len;
    let mut block = vec![0u8; 64 * 1024];
    while end > 0 {
        let start = end.saturating_sub(block.len() as u64);
        let n = usize::try_from(end - start).unwrap_or(block.len());
        let buf = block.get_mut(..n).unwrap_or_default();
        file.seek(SeekFrom::Start(start))
            .map_err(io(path, "read"))?;
        file.read_exact(buf).map_err(io(path, "read"))?;
        if let Some(i) = buf.iter().rposition(|&b| b == b'\n') {
            keep = start + i as u64 + 1;
            break;
        }
        end = start;
    }
    let torn = len - keep;
    if keep == 0 {
        let mut h = SAMPLES_HEADER.join(",").into_bytes();
        h.push(b'\n');
        fs::write(path, &h).map_err(io(path, "write"))?;
        return Ok((h.len() as u64, torn, true));
    }
    let mut first = Vec::new();
    file.seek(SeekFrom::Start(0)).map_err(io(path, "read"))?;
    (&mut file)
        .take(4096.min(keep))
        .read_to_end(&mut first)
        .map_err(io(path, "read"))?;
    let which = check_header(path, &first, SAMPLES_HEADERS)?;
    if torn > 0 {
        tracing::warn!(file = %path.display(), bytes = torn, "dropping a torn last line");
    }
    if which != 0 {
        tracing::info!(file = %path.display(), "samples.csv has no t_utc column (an older gyrocal began it); its rows stay without one");
    }
    Ok((keep, torn, which == 0))
}

/// Rewrites CSV rows written with the columns `old` for the columns `new` (which contain every
/// column of `old`): an empty cell for each new column. The rows are gyrocal's own (numbers,
/// no quoting), so a row is one line and a cell is between commas.
fn upgrade_steps(bytes: &[u8], old: &[&str], new: &[&str]) -> Vec<u8> {
    let map: Vec<Option<usize>> = new
        .iter()
        .map(|c| old.iter().position(|o| o == c))
        .collect();
    let mut out = new.join(",").into_bytes();
    out.push(b'\n');
    for line in bytes.split(|&b| b == b'\n').skip(1) {
        let line = line.strip_suffix(b"\r").unwrap_or(line);
        if line.is_empty() {
            continue;
        }
        let cells: Vec<&[u8]> = line.split(|&b| b == b',').collect();
        for (k, m) in map.iter().enumerate() {
            if k > 0 {
                out.push(b',');
            }
            if let Some(cell) = m.and_then(|i| cells.get(i)) {
                out.extend_from_slice(cell);
            }
        }
        out.push(b'\n');
    }
    out
}

fn parse_steps(path: &Path, bytes: &[u8], schedule: &[Step]) -> Result<Vec<StepRecord>, RunError> {
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .from_reader(bytes);
    let mut seen = BTreeSet::new();
    let mut out = Vec::new();
    let mut rec = csv::StringRecord::new();
    // by name: files written before `rate_samples` existed lack that column
    let headers = rdr.headers().map_err(|e| csv_read(path, &e))?.clone();
    loop {
        match rdr.read_record(&mut rec) {
            Ok(false) => break,
            Ok(true) => {}
            Err(e) => return Err(csv_read(path, &e)),
        }
        // the record's own position: taken before the first read, the reader's position
        // would still point at the header
        let line = rec.position().map_or(0, csv::Position::line);
        let bad = |message: String| RunError::Csv {
            path: path.to_path_buf(),
            line,
            message,
        };
        let r: StepRecord = rec
            .deserialize(Some(&headers))
            .map_err(|e| bad(e.to_string()))?;
        let Some(s) = schedule.get(r.step) else {
            return Err(bad(format!(
                "step {} is not in the plan's schedule",
                r.step
            )));
        };
        if r.pass != s.pass || r.rate_dps.to_bits() != s.rate_dps.to_bits() {
            return Err(bad(format!(
                "step {} has pass {} rate {}, the schedule pass {} rate {}",
                r.step, r.pass, r.rate_dps, s.pass, s.rate_dps
            )));
        }
        if !seen.insert(r.step) {
            return Err(bad(format!("step {} appears twice", r.step)));
        }
        if r.n == 0 || r.n.checked_add(r.overloads).is_none() {
            return Err(bad(format!(
                "step {}: n must be >= 1 (got {})",
                r.step, r.n
            )));
        }
        if let Some(msg) = record_problem(&r) {
            return Err(bad(format!("step {}: {msg}", r.step)));
        }
        out.push(r);
    }
    Ok(out)
}

/// Checks the finished steps' rows in samples.csv and finds where the unfinished rows start.
/// Returns (bytes to keep, rows dropped).
///
/// Streams the first `len` bytes of the file (its complete lines, see [`repair_samples`]): a
/// long run's samples.csv is never held in memory.
fn scan_samples(
    path: &Path,
    len: u64,
    schedule: &[Step],
    expected: &BTreeMap<usize, u64>,
) -> Result<(u64, u64), RunError> {
    use std::io::Read as _;
    let file = open_regular(path).map_err(opened)?;
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .from_reader(std::io::BufReader::new(file.take(len)));
    let mut counts: BTreeMap<usize, u64> = BTreeMap::new();
    let mut cut: Option<u64> = None;
    let mut dropped = 0u64;
    let mut rec = csv::StringRecord::new();
    // The header's end, in case there is no row at all; rows are read by name (files written
    // before `t_utc` existed lack that column).
    let headers = rdr.headers().map_err(|e| csv_read(path, &e))?.clone();
    let mut keep = rdr.position().byte();
    loop {
        match rdr.read_record(&mut rec) {
            Ok(false) => break,
            Ok(true) => {}
            Err(e) => return Err(csv_read(path, &e)),
        }
        // the record's own start: the reader's position before the first read is the header's
        let Some(pos) = rec.position().cloned() else {
            return Err(RunError::Csv {
                path: path.to_path_buf(),
                line: 0,
                message: "a row without a position".into(),
            });
        };
        let line = pos.line();
        let bad = |message: String| RunError::Csv {
            path: path.to_path_buf(),
            line,
            message,
        };
        if cut.is_some() {
            // Rows of the partial step: dropped, but a finished step's row here means the
            // file is not what this program writes.
            let step = rec.get(0).and_then(|s| s.parse::<usize>().ok());
            if step.is_some_and(|s| expected.contains_key(&s)) {
                return Err(bad(format!(
                    "a row of finished step {} follows rows of an unfinished step",
                    step.unwrap_or_default()
                )));
            }
            dropped += 1;
            continue;
        }
        let row: SampleRow = rec
            .deserialize(Some(&headers))
            .map_err(|e| bad(e.to_string()))?;
        if !expected.contains_key(&row.step) {
            cut = Some(pos.byte());
            dropped += 1;
            continue;
        }
        let Some(s) = schedule.get(row.step) else {
            return Err(bad(format!(
                "step {} is not in the plan's schedule",
                row.step
            )));
        };
        if row.rate_dps.to_bits() != s.rate_dps.to_bits() {
            return Err(bad(format!(
                "step {} has rate {}, the schedule {}",
                row.step, row.rate_dps, s.rate_dps
            )));
        }
        let c = counts.entry(row.step).or_insert(0);
        if row.index != *c {
            return Err(bad(format!(
                "step {}: sample index {} where {} was due (duplicate or missing reading)",
                row.step, row.index, c
            )));
        }
        if row.volts.is_none() != (row.overload == 1) || row.overload > 1 {
            return Err(bad(format!(
                "step {}: overload must be 1 exactly when volts is empty",
                row.step
            )));
        }
        *c += 1;
        keep = rdr.position().byte();
    }
    for (step, want) in expected {
        let got = counts.get(step).copied().unwrap_or(0);
        if got != *want {
            return Err(RunError::Inconsistent {
                path: path.to_path_buf(),
                message: format!(
                    "step {step}: steps.csv records {want} readings (n + overloads), samples.csv holds {got}"
                ),
            });
        }
    }
    Ok((cut.unwrap_or(keep), dropped))
}

/// Problems of a step record's numbers, if any.
fn record_problem(r: &StepRecord) -> Option<String> {
    if !r.volts.is_finite() {
        return Some(format!("volts must be finite (got {})", r.volts));
    }
    let opts = [
        ("volts_std", r.volts_std),
        ("rate_meas_dps", r.rate_meas_dps),
        ("rate_meas_std_dps", r.rate_meas_std_dps),
        ("rate_meas_min_dps", r.rate_meas_min_dps),
        ("rate_meas_max_dps", r.rate_meas_max_dps),
    ];
    for (what, v) in opts {
        if v.is_some_and(|v| !v.is_finite()) {
            return Some(format!("{what} must be finite or empty (got {v:?})"));
        }
    }
    if !r.t_start_s.is_finite() || !r.t_end_s.is_finite() || r.t_end_s < r.t_start_s {
        return Some(format!(
            "t_start_s {} and t_end_s {} must be finite and ordered",
            r.t_start_s, r.t_end_s
        ));
    }
    None
}

fn csv_read(path: &Path, e: &csv::Error) -> RunError {
    RunError::Csv {
        path: path.to_path_buf(),
        line: e.position().map_or(0, csv::Position::line),
        message: e.to_string(),
    }
}

fn csv_write(path: &Path, e: csv::Error) -> RunError {
    match e.into_kind() {
        csv::ErrorKind::Io(source) => RunError::Io {
            path: path.to_path_buf(),
            action: "write",
            source,
        },
        other => RunError::Protocol {
            path: path.to_path_buf(),
            message: format!("{other:?}"),
        },
    }
}

/// Opens a CSV for appending; `new` writes (and syncs) the header into an empty file.
fn open_csv(path: &Path, header: &[&str], new: bool) -> Result<csv::Writer<File>, RunError> {
    let file = OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .map_err(io(path, "open"))?;
    let mut w = csv::WriterBuilder::new()
        .has_headers(false)
        .from_writer(file);
    if new {
        w.write_record(header).map_err(|e| csv_write(path, e))?;
        w.flush().map_err(io(path, "write"))?;
        w.get_ref().sync_all().map_err(io(path, "sync"))?;
    }
    Ok(w)
}

fn truncate(path: &Path, len: u64) -> Result<(), RunError> {
    let f = OpenOptions::new()
        .write(true)
        .open(path)
        .map_err(io(path, "open"))?;
    let cur = f.metadata().map_err(io(path, "read the length of"))?.len();
    if cur != len {
        f.set_len(len).map_err(io(path, "truncate"))?;
        f.sync_all().map_err(io(path, "sync"))?;
    }
    Ok(())
}

/// Writes `name` in `dir` atomically ([`crate::atomic`]): temp file in the same directory,
/// fsync, rename, fsync of the directory; the temp file removed on any failure. Readers see
/// the old or the new content, never a mix.
fn write_atomic(dir: &Path, name: &str, bytes: &[u8]) -> Result<(), RunError> {
    crate::atomic::write_atomic(&dir.join(name), bytes).map_err(|e| RunError::Io {
        path: e.path,
        action: e.action,
        source: e.source,
    })
}

fn sync_dir(dir: &Path) -> Result<(), RunError> {
    crate::atomic::sync_dir(dir).map_err(io(dir, "sync the directory"))
}
