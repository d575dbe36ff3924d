//! The durable run directory: `samples.csv`, `steps.csv`, `manifest.json` (and later
//! `fit.json`, `report.html`).
//!
//! # Files
//!
//! - `samples.csv`: `step,index,t_s,rate_dps,volts,overload`, one row per raw reading in the
//!   order taken. `index` is 0-based and contiguous within a step; `t_s` is the run clock
//!   (seconds); `rate_dps` the demanded rate. **Overloads are written, never dropped**: the row
//!   has `overload = 1` and an *empty* `volts` (the meter's `9.9E+37` is a marker, not a
//!   voltage; an empty field makes a naive reader fail loudly instead of averaging it), so the
//!   indices stay contiguous and the overload count is auditable.
//! - `steps.csv`: one row per finished step, see [`StepRecord`] and [`STEPS_HEADER`]. It is a
//!   valid input of `gyrocal fit`, which reads `rate_dps`, `volts`, `volts_std` (optional,
//!   empty when `n = 1`) and `n` by name.
//! - `manifest.json`: [`Manifest`], replaced atomically (temp file in the same directory,
//!   fsync, rename, fsync of the directory) at every change, so it always parses.
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
//!
//! # Bounds and failures
//!
//! Every file is read with a size limit ([`MAX_MANIFEST_BYTES`], [`MAX_STEPS_BYTES`],
//! [`MAX_SAMPLES_BYTES`], [`MAX_FIT_BYTES`]) and must be a regular file: a huge or endless file
//! is an error naming it, never a memory exhaustion. A header naming a column twice is an error
//! naming both positions. [`RunDir::create`] is all or nothing (a failure removes what it
//! created), and a directory left half created by a crash during creation is reused by the
//! next `create` ([`RunDir::is_half_created`]).

use std::collections::{BTreeMap, BTreeSet};
use std::fs::{self, File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::plan::{Plan, Step};
use crate::time::now_utc;

/// File name of the raw readings.
pub const SAMPLES_CSV: &str = "samples.csv";
/// File name of the finished steps.
pub const STEPS_CSV: &str = "steps.csv";
/// File name of the manifest.
pub const MANIFEST_JSON: &str = "manifest.json";
/// File name of the fit document.
pub const FIT_JSON: &str = "fit.json";
/// File name of the HTML report (written by the report crate via [`RunDir::write_file`]).
pub const REPORT_HTML: &str = "report.html";
/// Version of the run-directory format, recorded in the manifest.
pub const FORMAT_VERSION: u32 = 1;

/// Columns of `samples.csv`, in order.
pub const SAMPLES_HEADER: [&str; 6] = ["step", "index", "t_s", "rate_dps", "volts", "overload"];
/// Columns of `steps.csv`, in order.
pub const STEPS_HEADER: [&str; 15] = [
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
/// still reads; a resume rewrites it with [`STEPS_HEADER`] (an empty `rate_samples` in the old
/// rows) before appending.
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
        "{}: the plan changed since this run started (run's plan hash {run_hash}, this plan's {plan_hash}); resume with the original plan or start a new run",
        path.display()
    )]
    PlanChanged {
        /// The manifest.
        path: PathBuf,
        /// Hash recorded in the run.
        run_hash: String,
        /// Hash of the plan given now.
        plan_hash: String,
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
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
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

/// Timing figures of a run (the physical bound versus the elapsed time).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Timing {
    /// The physical lower bound of the run's duration, s.
    pub bound_s: f64,
    /// Elapsed on the run clock, s.
    pub elapsed_s: f64,
    /// `elapsed_s / bound_s`.
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
    /// The plan as parsed (validated again when read).
    pub plan: Plan,
    /// Whether the run uses the simulated bench.
    pub simulated: bool,
    /// Instrument identities.
    pub instruments: Instruments,
    /// Wall-clock start, RFC 3339 UTC.
    pub started_utc: String,
    /// Wall-clock end (set when the run stops), RFC 3339 UTC.
    pub ended_utc: Option<String>,
    /// Wall-clock time of the last manifest write, RFC 3339 UTC.
    pub updated_utc: String,
    /// Elapsed on the run's own clock, s (the caller's figure).
    pub elapsed_s: f64,
    /// Steps in the schedule.
    pub steps_total: usize,
    /// Indices of the finished steps, ascending.
    pub steps_done: Vec<usize>,
    /// Resumes, oldest first.
    pub resumes: Vec<Resume>,
    /// Retries, oldest first.
    pub retries: Vec<Retry>,
    /// Bound versus elapsed, when computed.
    pub timing: Option<Timing>,
    /// The fit (the fit crate's [`gyrocal_fit::Analysis`], the `gyrocal fit --json`
    /// document), when done. A fit this version cannot read back (written by another version)
    /// is `None` here, with a warning: `fit.json` beside the manifest stays the source of truth.
    #[serde(default, deserialize_with = "lenient_fit")]
    pub fit: Option<gyrocal_fit::Analysis>,
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
fn lock_dir(dir: &Path) -> Result<File, RunError> {
    let path = dir.join(LOCK_FILE);
    let file = fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&path)
        .map_err(io(&path, "open the lock file"))?;
    match file.try_lock() {
        Ok(()) => Ok(file),
        Err(std::fs::TryLockError::WouldBlock) => Err(RunError::Locked {
            path: dir.to_path_buf(),
        }),
        Err(std::fs::TryLockError::Error(e)) => Err(io(&path, "lock")(e)),
    }
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
    steps: csv::Writer<File>,
    done: BTreeSet<usize>,
    current: Option<Current>,
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
                SAMPLES_CSV => regular && holds_at_most_header(&file, &[&SAMPLES_HEADER]),
                STEPS_CSV => {
                    regular && holds_at_most_header(&file, &[&STEPS_HEADER, &STEPS_HEADER_V1])
                }
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
            instruments: meta.instruments,
            started_utc: now.clone(),
            ended_utc: None,
            updated_utc: now,
            elapsed_s: 0.0,
            steps_total: plan.step_count(),
            steps_done: Vec::new(),
            resumes: Vec::new(),
            retries: Vec::new(),
            timing: None,
            fit: None,
        };
        let mut rd = RunDir {
            dir: path.to_path_buf(),
            _lock: lock,
            schedule: plan.schedule(),
            manifest,
            samples,
            steps,
            done: BTreeSet::new(),
            current: None,
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
        let mut manifest = read_manifest(&mpath)?;
        let lock = lock_dir(path)?;
        let plan_hash = plan.hash();
        if manifest.plan_hash != plan_hash {
            return Err(RunError::PlanChanged {
                path: mpath,
                run_hash: manifest.plan_hash,
                plan_hash,
            });
        }
        if manifest.status == Status::Complete {
            return Err(RunError::AlreadyComplete { path: mpath });
        }
        let schedule = plan.schedule();

        // steps.csv: repair the tail, then every row must fit the schedule.
        let spath = path.join(STEPS_CSV);
        let (steps_bytes, torn_steps) =
            read_repaired(&spath, &[&STEPS_HEADER, &STEPS_HEADER_V1], MAX_STEPS_BYTES)?;
        let records = parse_steps(&spath, &steps_bytes, &schedule)?;
        let done: BTreeSet<usize> = records.iter().map(|r| r.step).collect();
        let expected: BTreeMap<usize, u64> = records
            .iter()
            .map(|r| (r.step, r.n + r.overloads))
            .collect();

        // samples.csv: keep the finished steps' rows, drop everything from the first other row.
        let sapath = path.join(SAMPLES_CSV);
        let (samples_len, torn_samples) = repair_samples(&sapath)?;
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
        let mut rd = RunDir {
            dir: path.to_path_buf(),
            _lock: lock,
            schedule,
            manifest,
            samples,
            steps,
            done,
            current: None,
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
                t_s: smp.t_s,
                rate_dps: s.rate_dps,
                volts: smp.volts,
                overload: u8::from(smp.volts.is_none()),
            };
            self.samples
                .serialize(row)
                .map_err(|e| csv_write(&path, e))?;
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
        self.steps
            .serialize(&rec)
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

    /// Sets the instruments' identities.
    pub fn set_instruments(&mut self, instruments: Instruments) -> Result<(), RunError> {
        self.manifest.instruments = instruments;
        self.write_manifest()
    }

    /// Sets the elapsed run-clock time, s (the caller's figure; finite, ≥ 0).
    pub fn set_elapsed(&mut self, elapsed_s: f64) -> Result<(), RunError> {
        self.check_finite("elapsed_s", elapsed_s)?;
        self.manifest.elapsed_s = elapsed_s;
        self.write_manifest()
    }

    /// Logs a retry.
    pub fn log_retry(&mut self, retry: Retry) -> Result<(), RunError> {
        self.check_finite("retry t_s", retry.t_s)?;
        self.manifest.retries.push(retry);
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
        self.manifest.timing = Some(timing);
        self.write_manifest()
    }

    /// Stores the fit document: writes `fit.json` atomically and puts it in the manifest.
    pub fn set_fit(&mut self, fit: gyrocal_fit::Analysis) -> Result<(), RunError> {
        let path = self.dir.join(FIT_JSON);
        let bytes = serde_json::to_vec_pretty(&fit).map_err(|e| RunError::Protocol {
            path: path.clone(),
            message: format!("cannot serialise the fit: {e}"),
        })?;
        write_atomic(&self.dir, FIT_JSON, &bytes)?;
        self.manifest.fit = Some(fit);
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
        self.manifest.status = status;
        self.manifest.reason = reason;
        self.manifest.elapsed_s = elapsed_s;
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
        self.manifest.updated_utc = now_utc();
        let path = self.dir.join(MANIFEST_JSON);
        let bytes = serde_json::to_vec_pretty(&self.manifest).map_err(|e| RunError::Protocol {
            path,
            message: format!("cannot serialise the manifest: {e}"),
        })?;
        write_atomic(&self.dir, MANIFEST_JSON, &bytes)
    }
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
    check_header(&spath, bytes, &[&STEPS_HEADER, &STEPS_HEADER_V1])?;
    let schedule = manifest.plan.schedule();
    let steps = parse_steps(&spath, bytes, &schedule)?;
    Ok(RunData { manifest, steps })
}

/// Reads every complete row of samples.csv (a torn last line is ignored).
pub fn load_samples(dir: &Path) -> Result<Vec<SampleRow>, RunError> {
    let path = dir.join(SAMPLES_CSV);
    let bytes = read_capped(&path, MAX_SAMPLES_BYTES)?;
    let (bytes, _) = complete_lines(&bytes);
    check_header(&path, bytes, &[&SAMPLES_HEADER])?;
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .from_reader(bytes);
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
    let file = File::open(path).map_err(io(path, "read"))?;
    let meta = file.metadata().map_err(io(path, "read"))?;
    if !meta.is_file() {
        return Err(RunError::Inconsistent {
            path: path.to_path_buf(),
            message: "not a regular file".into(),
        });
    }
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

fn read_manifest(path: &Path) -> Result<Manifest, RunError> {
    let bytes = read_capped(path, MAX_MANIFEST_BYTES)?;
    let m: Manifest = serde_json::from_slice(&bytes).map_err(|e| RunError::Json {
        path: path.to_path_buf(),
        line: e.line(),
        column: e.column(),
        message: e.to_string(),
    })?;
    if m.format_version != FORMAT_VERSION {
        return Err(RunError::Inconsistent {
            path: path.to_path_buf(),
            message: format!(
                "format_version {} is not {FORMAT_VERSION}, the one this gyrocal writes",
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
/// writes the header into an empty file. Returns (length of the complete lines, torn bytes).
fn repair_samples(path: &Path) -> Result<(u64, u64), RunError> {
    use std::io::{Read as _, Seek as _, SeekFrom};
    let mut file = File::open(path).map_err(io(path, "read"))?;
    let meta = file.metadata().map_err(io(path, "read"))?;
    if !meta.is_file() {
        return Err(RunError::Inconsistent {
            path: path.to_path_buf(),
            message: "not a regular file".into(),
        });
    }
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
        return Ok((h.len() as u64, torn));
    }
    let mut first = Vec::new();
    file.seek(SeekFrom::Start(0)).map_err(io(path, "read"))?;
    (&mut file)
        .take(4096.min(keep))
        .read_to_end(&mut first)
        .map_err(io(path, "read"))?;
    check_header(path, &first, &[&SAMPLES_HEADER])?;
    if torn > 0 {
        tracing::warn!(file = %path.display(), bytes = torn, "dropping a torn last line");
    }
    Ok((keep, torn))
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
    let file = File::open(path).map_err(io(path, "read"))?;
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .from_reader(std::io::BufReader::new(file.take(len)));
    let mut counts: BTreeMap<usize, u64> = BTreeMap::new();
    let mut cut: Option<u64> = None;
    let mut dropped = 0u64;
    let mut rec = csv::StringRecord::new();
    // The header's end, in case there is no row at all.
    rdr.headers().map_err(|e| csv_read(path, &e))?;
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
        let row: SampleRow = rec.deserialize(None).map_err(|e| bad(e.to_string()))?;
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

/// Writes `name` in `dir` atomically: temp file in the same directory, fsync, rename, fsync
/// of the directory. Readers see the old or the new content, never a mix.
fn write_atomic(dir: &Path, name: &str, bytes: &[u8]) -> Result<(), RunError> {
    let tmp = dir.join(format!(".{name}.tmp"));
    let dest = dir.join(name);
    let mut f = File::create(&tmp).map_err(io(&tmp, "create"))?;
    f.write_all(bytes).map_err(io(&tmp, "write"))?;
    f.sync_all().map_err(io(&tmp, "sync"))?;
    drop(f);
    fs::rename(&tmp, &dest).map_err(io(&dest, "replace"))?;
    sync_dir(dir)
}

fn sync_dir(dir: &Path) -> Result<(), RunError> {
    #[cfg(unix)]
    {
        File::open(dir)
            .and_then(|d| d.sync_all())
            .map_err(io(dir, "sync the directory"))?;
    }
    #[cfg(not(unix))]
    let _ = dir;
    Ok(())
}
