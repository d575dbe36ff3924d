//! gyrocal-run: a calibration run on the instruments.
//!
//! - [`estimate`]: the plan's duration from the instruments' timing models, and the physical
//!   bound a run's elapsed time is judged against (`gyrocal check` prints it).
//! - [`monitor`]: what the run watches in its readings: the warm-up, and a drift record's
//!   running Allan deviation.
//! - [`sequencer`]: the run itself. Generic over the multimeter's transport and the
//!   [`gyrocal_table::RateTable`], so the same code drives real instruments and the simulated
//!   bench, in real or virtual time.
//!
//! The plan and run-directory formats are gyrocal-files' (synchronous, no instrument I/O; the
//! sequencer calls them between async steps: writes are a few kilobytes per chunk); they are
//! re-exported here so a run's code reads as one crate.

pub mod estimate;
pub mod monitor;
pub mod sequencer;

pub use gyrocal_files::{
    Acquire, Acquisition, DmmSettings, Dut, FitSummary, Framing, Instruments, Location, Manifest,
    Plan, PlanDoc, PlanError, PlanKind, Port, Resume, Retry, RunContext, RunData, RunDir, RunError,
    RunMeta, Sample, SampleRow, Simulation, Status, Step, StepRecord, TableDialect, TableSettings,
    Timing, load, load_fit, load_samples, num, parse_rfc3339_utc, plan, rfc3339_utc, rundir,
    station,
};
pub use sequencer::{
    Event, Phase, RunSummary, SequenceError, Sequencer, SequencerOptions, StopRequest, TableRest,
};
