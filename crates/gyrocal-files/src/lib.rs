//! gyrocal-files: the files a calibration is made of, on paper and on disk. Synchronous, no
//! instrument and no async code: the sequencer writes these formats, and the report, the fit
//! and the CLI read them without pulling in drivers, a runtime or the simulator.
//!
//! - [`plan`]: the operator's test plan. A TOML file is parsed into raw serde structs that
//!   reject unknown keys and keep every value's position, then validated into a typed
//!   [`Plan`] (instrument limits, durations, enums, ports) whose errors name the file, the
//!   line, the column and the key. The plan expands into a stable [`Step`] schedule and has a
//!   content hash that a resume checks.
//! - [`rundir`]: the durable run directory. Every raw reading is appended to `samples.csv` and
//!   flushed per chunk; every finished step is appended to `steps.csv` and fsynced (after the
//!   samples) before the sequencer moves on; `manifest.json` is replaced atomically at every
//!   change. After a crash, even a `SIGKILL` in the middle of a write,
//!   [`RunDir::open_for_resume`] keeps every finished step, drops the partial step's readings
//!   and a torn last line, and tells the sequencer where to continue. The file formats are
//!   documented in [`rundir`]; [`num`] says how computed numbers are written.
//! - [`steps`]: the step vocabulary a plan compiles to (one dispatch on its kind) and the run
//!   engine executes without asking which kind of plan it runs.
//! - [`station`]: the bench a run is made on: laboratory, conditions and the instruments'
//!   calibration records (traceability, due dates), from a station file.
//! - The analysis of a run (the scale-factor fit of a sweep, the Allan analysis of a drift
//!   record) is not here: it is the `gyrocal-analysis` crate's, which writes its results
//!   through [`rundir`] ([`RunDir::set_fit`], [`rundir::WriteResult`]).
//! - [`open`]: data files are opened only when they are regular files (never a device, a FIFO
//!   or a directory); [`atomic`]: a file replaced atomically, its temporary file removed on
//!   any failure.

pub mod atomic;
pub mod num;
pub mod open;
pub mod plan;
pub mod rundir;
pub mod station;
pub mod steps;
mod time;

pub use plan::{
    Acquire, Acquisition, DmmModel, DmmSettings, Framing, Location, Plan, PlanDoc, PlanDut,
    PlanError, PlanErrorKind, PlanKind, Port, Simulation, Step, TableDialect, TableSettings,
    acceptance_from_toml_str, load_acceptance,
};
pub use rundir::{
    Deviation, Dut, FitSummary, Instruments, Manifest, Resume, Retry, RunContext, RunData, RunDir,
    RunError, RunErrorKind, RunMeta, RunResults, Sample, SampleRow, Status, StepRecord, Timing,
    WriteResult, load, load_fit, load_samples,
};
pub use station::{
    InstrumentRecord, MeterAccuracySpec, Overdue, STATION_ENV, SpecPeriod, Station, StationError,
    StationErrorKind,
};
pub use time::{ClockAnchor, parse_rfc3339_utc, rfc3339_utc};
