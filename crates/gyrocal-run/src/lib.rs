//! gyrocal-run: what a calibration run is made of, on paper and on disk.
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
//!   and a torn last line, and tells the sequencer where to continue.
//!
//! Why a crate of its own: the sequencer (which drives the instruments), the CLI (`gyrocal
//! check`, `gyrocal run`) and the report all read these formats, and none of them should have
//! to know how durability is achieved. This crate does no instrument I/O and depends on no
//! driver; it is synchronous and small, so the sequencer can call it between async steps
//! (writes are a few kilobytes per chunk).

pub mod plan;
pub mod rundir;
mod time;

pub use plan::{
    Acquire, Acquisition, DmmSettings, Framing, Location, Plan, PlanDoc, PlanError, Port,
    Simulation, Step, TableDialect, TableSettings,
};
pub use rundir::{
    Instruments, Manifest, Resume, Retry, RunData, RunDir, RunError, RunMeta, Sample, SampleRow,
    Status, StepRecord, Timing, load, load_samples,
};
pub use time::rfc3339_utc;
