//! The durable run directory: `samples.csv`, `steps.csv`, `manifest.json`, `fit.json` (and,
//! written by others, `report.html` with its `.svg` plots and `run.log`).
//!
//! # Files
//!
//! - `samples.csv`: `step_no,sample_no,t_s,rate_dps,volts,overload,t_utc`, one row per raw
//!   reading in the order taken. The `_no` columns count from 1, as the terminal and the
//!   report do: `step_no` is the plan's step number (its position in the plan's `repeat ×
//!   rates_dps`; "step 4 of 19" on the terminal is `step_no` 4 here), `sample_no` the
//!   reading's number within its step, contiguous (1, 2, 3, ...); `t_s` is the run clock
//!   (seconds, see `elapsed_s` below); `rate_dps` the demanded rate. **Overloads are written,
//!   never dropped**: the row has `overload = 1` and an *empty* `volts` (the meter's `9.9E+37`
//!   is a marker, not a voltage; an empty field makes a naive reader fail loudly instead of
//!   averaging it), so the numbers stay contiguous and the overload count is auditable.
//! - `steps.csv`: one row per finished step, see [`StepRecord`] and [`STEPS_HEADER`]; its
//!   `step_no` and `pass_no` count from 1 too. It is a valid input of `gyrocal fit`, which
//!   reads `rate_dps`, `volts`, `volts_std` (optional, empty when `n = 1`) and `n` by name.
//!   A temperature series fills its last six columns (`series_point`, `setpoint_c`, the gyro's
//!   `temp_min_c`/`temp_mean_c`/`temp_max_c` during the acquisition, `bias_record`: 1 on the
//!   bias record at a temperature), empty for every other kind ([`SeriesCells`]).
//! - `temps.csv` (a run with a thermal chamber): every reading of the chamber,
//!   `t_s,setpoint_c,air_c,product_c,series_point,phase` (see [`temps`]).
//!
//! In memory ([`StepRecord`], [`SampleRow`], the manifest's `steps_done` and `from_step`)
//! steps, readings and passes are 0-based, the schedule's index; the conversion is made at the
//! CSV boundary only, in `columns` (a private module), by the file's header. Why the columns
//! are named `_no` and not `step`, `index`, `pass`: the suffix says "counted from 1" where a
//! bare name would not, and `index` and `pass` collide with pandas (`df.index` is the
//! DataFrame's own index, `df.pass` a syntax error).
//! - `manifest.json`: [`Manifest`], replaced atomically (temp file in the same directory,
//!   fsync, rename, fsync of the directory) at every change, so it always parses. It holds the
//!   run's state, the plan, the instruments, the times and, once fitted, a [`FitSummary`]: the
//!   name and SHA-256 of `fit.json` and the headline figures (K, K0, their standard errors,
//!   the best model). It stays a few kilobytes, so an index of many runs reads it cheaply.
//! - `fit.json`: the whole fit (the `gyrocal fit --json` document: every model, the
//!   residuals, the error surface), written by
//!   `gyrocal_analysis::sweep::fit_run`; read it with [`load_fit`].
//! - `allan.json`, `allan.html`: a drift record's Allan analysis (`gyrocal-analysis`) and its
//!   page (`gyrocal-report`), written through [`RunDir::write_result`] or [`RunResults`]
//!   (atomically, under the run's lock, with its SHA-256 recorded in the manifest's
//!   `checksums`).
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
//! `fit`, read into [`Manifest::legacy_fit`]); CSV files of formats 1 and 2, whose counted
//! columns are `step`, `index` and `pass`, counted from 0 ([`STEPS_HEADER_V3`],
//! [`SAMPLES_HEADER_V2`]), read with their values as before; a `steps.csv` without the UTC
//! columns or without `rate_samples`; a `samples.csv` without `t_utc`. Which format a CSV
//! file has is told by its header, never by its values. A resume rewrites `steps.csv` with the
//! current header (the old rows' `step` and `pass` plus one, their new cells empty, every other
//! cell as it was) and keeps appending rows of `samples.csv`'s own columns to it, counted as
//! its header counts (the file is never rewritten: it can be gigabytes), so a run an older
//! gyrocal began stays consistent and verifies. A resume rewrites the manifest in the current
//! format: its `format_version` is then 3 while such a `samples.csv` keeps its older header.
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
//!
//! # Modules, one concern each
//!
//! `error` ([`RunError`] and its kind), `records` (the rows of the CSV files), `manifest`
//! ([`Manifest`], read and stored atomically), `lock` (one writer at a time), `writer`
//! ([`RunDir`]: create, append, finish), `resume` ([`RunDir::open_for_resume`]), `csvfile`
//! (lines, headers and rows of the CSV files), `columns` (the counted columns across formats:
//! from 1 in the files since format 3, 0-based in memory), `read` ([`load`], [`load_fit`],
//! [`load_samples`]), `results` (result files written through the run directory:
//! [`WriteResult`], [`RunResults`]), `integrity` (the checksums checked: [`verify`]).

use std::collections::{BTreeMap, BTreeSet};
use std::fs::{self, File, OpenOptions};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::num::{round_json, round_opt, round_significant};
use crate::open::open_regular;
use crate::plan::{Plan, Step};
use crate::time::{ClockAnchor, now_utc};

mod columns;
mod csvfile;
mod error;
mod integrity;
mod lock;
mod manifest;
mod read;
mod records;
mod results;
mod resume;
pub mod temps;
mod writer;

// the modules' crate-private helpers, for one another (each `use super::*`)
#[allow(unused_imports)]
use {
    columns::*, csvfile::*, error::*, lock::*, manifest::*, read::*, records::*, results::*,
    resume::*, writer::*,
};

pub use error::{RunError, RunErrorKind};
pub use integrity::{
    DATA_FILES, Discrepancy, FileCheck, FileState, RESULT_FILES, Verification, check_files,
    sha256_file, sha256_hex, verify,
};
pub use lock::{HolderState, LOCK_FILE, LockHolder, host_name, lock_holder};
pub use manifest::{
    ChamberRecord, Deviation, Dut, FitSummary, Instruments, Manifest, Resume, Retry, RunContext,
    RunData, RunMeta, Status, Timing, WarmupRecord,
};
pub use read::{load, load_fit, load_samples, plan_changes, read_capped, run_plan};
pub use records::{STEPS_HEADER, STEPS_HEADER_V4, Sample, SampleRow, SeriesCells, StepRecord};
pub use results::{RunResults, WriteResult};
pub use writer::RunDir;

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
/// File name of a drift record's Allan analysis document (`gyrocal-analysis`'s, written through
/// [`RunDir::write_result`] or [`RunResults::write_result`], recorded in `checksums`).
pub const ALLAN_JSON: &str = "allan.json";
/// File name of a drift record's Allan page (written and recorded as [`ALLAN_JSON`]).
pub const ALLAN_HTML: &str = "allan.html";
/// A temperature series' analysis (written by `gyrocal-analysis`).
pub const SERIES_JSON: &str = "series.json";
/// The temperatures of a run with a chamber (see [`temps`]).
pub const TEMPS_CSV: &str = "temps.csv";
/// Version of the run-directory format written, recorded in the manifest. Version 3 counts
/// steps, readings and passes from 1 in the CSV files (`step_no`, `sample_no`, `pass_no`);
/// version 2 (`step`, `index`, `pass`, from 0) and version 1 (before the UTC columns and the
/// slim manifest) are still read: see [`FORMAT_VERSIONS_READ`] and the module docs, *Formats
/// read*.
pub const FORMAT_VERSION: u32 = 3;
/// The manifest versions this gyrocal reads.
pub const FORMAT_VERSIONS_READ: [u32; 3] = [1, 2, 3];

/// Columns of `samples.csv`, in order; `step_no` and `sample_no` count from 1 (the plan's step
/// number, the reading's number within its step); `t_utc` is the run directory's conversion of
/// `t_s` (see the module docs, *Times*), last so that readers by position keep working.
pub const SAMPLES_HEADER: [&str; 7] = [
    "step_no",
    "sample_no",
    "t_s",
    "rate_dps",
    "volts",
    "overload",
    "t_utc",
];
/// Columns of `samples.csv` of format 2: `step` and `index` counted from 0. Such a file still
/// reads (its values as before), and a resume keeps appending rows of these columns to it (the
/// file is never rewritten: it can hold gigabytes).
pub const SAMPLES_HEADER_V2: [&str; 7] = [
    "step", "index", "t_s", "rate_dps", "volts", "overload", "t_utc",
];
/// Columns of `samples.csv` before `t_utc` existed (counted from 0). Such a file still reads,
/// and a resume keeps appending rows of these columns to it.
pub const SAMPLES_HEADER_V1: [&str; 6] = ["step", "index", "t_s", "rate_dps", "volts", "overload"];
/// Columns of `steps.csv` of format 2: [`STEPS_HEADER`]'s with `step` and `pass` counted from
/// 0. Such a file still reads; a resume rewrites it with [`STEPS_HEADER`] (the old rows' step
/// and pass numbers plus one, every other cell as it was) before appending.
pub const STEPS_HEADER_V3: [&str; 17] = [
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
pub(super) const STEPS_HEADERS: &[&[&str]] = &[
    &STEPS_HEADER,
    &STEPS_HEADER_V4,
    &STEPS_HEADER_V3,
    &STEPS_HEADER_V2,
    &STEPS_HEADER_V1,
];
/// Every `samples.csv` header read, current first.
pub(super) const SAMPLES_HEADERS: &[&[&str]] =
    &[&SAMPLES_HEADER, &SAMPLES_HEADER_V2, &SAMPLES_HEADER_V1];

/// How far ahead of the manifest on disk the run clock of a [`RunDir::checkpoint`] may be
/// before the manifest is written again, s of run clock (5 min).
pub const CHECKPOINT_INTERVAL_S: f64 = 300.0;

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

/// Writes `name` in `dir` atomically ([`crate::atomic`]): temp file in the same directory,
/// fsync, rename, fsync of the directory; the temp file removed on any failure. Readers see
/// the old or the new content, never a mix.
pub(super) fn write_atomic(dir: &Path, name: &str, bytes: &[u8]) -> Result<(), RunError> {
    crate::atomic::write_atomic(&dir.join(name), bytes).map_err(|e| RunError::Io {
        path: e.path,
        action: e.action,
        source: e.source,
    })
}

pub(super) fn sync_dir(dir: &Path) -> Result<(), RunError> {
    crate::atomic::sync_dir(dir).map_err(io(dir, "sync the directory"))
}
