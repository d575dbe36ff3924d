//! What a run tells its consumers while it runs (see [`crate::sink`]): the phases of a step and
//! the progress events.

use std::time::Duration;

use gyrocal_files::plan::Step;
use gyrocal_files::rundir::{Retry, StepRecord, WarmupRecord};

use super::TableRest;

/// The phase of a step, for progress displays.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// The table ramps to the step's rate (and waits for the stability window).
    Ramping,
    /// Dwelling at rate before acquiring.
    Settling,
    /// The multimeter is reading.
    Acquiring,
    /// Readings are transferred from the multimeter's memory.
    Fetching,
}

/// Progress events, sent on an unbounded channel so a display never slows the run down.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// Both instruments answered.
    Connected {
        /// The multimeter's `*IDN?`.
        dmm: String,
        /// The table's `*IDN?`.
        table: String,
    },
    /// The schedule this session runs, with its estimate.
    Planned {
        /// Steps to run in this session.
        steps: usize,
        /// Steps already done (resume).
        done: usize,
        /// Expected duration of the remaining steps.
        estimate: Duration,
        /// How the multimeter acquires (`stream`, `memory`, ...).
        acquisition: &'static str,
    },
    /// A step begins. Operators see one numbering, the plan's: `number` of `of` (`step 4/19`),
    /// the same in every session of a resumed run, and the run directory's `step_no` column
    /// (the 0-based index is `number - 1`).
    StepStarted {
        /// The step.
        step: Step,
        /// 1-based number of the step in the plan's schedule (`step.index + 1`).
        number: usize,
        /// Steps in the plan's schedule.
        of: usize,
        /// 1-based position in this session's steps (a step measured again counts twice).
        position: usize,
        /// Steps in this session.
        total: usize,
        /// Estimated time to the end of the run from the start of this step (the instruments'
        /// timing models, see [`crate::estimate`]).
        remaining: Duration,
        /// Of `remaining`, what the steps after this one take: a display counts the time down
        /// within the step from `remaining` towards it.
        after: Duration,
    },
    /// A sample of the table while waiting for the rate.
    Settle(gyrocal_table::SettleProgress),
    /// A step entered a phase.
    Phase {
        /// Step index.
        step: usize,
        /// The phase.
        phase: Phase,
    },
    /// A reading received in the current acquisition.
    Acquiring {
        /// Readings so far.
        done: usize,
        /// Readings asked for.
        total: usize,
        /// The reading just received, V (`None`: an overload).
        latest: Option<f64>,
        /// Mean of this acquisition's valid readings so far, V (NaN before the first).
        mean: f64,
        /// Their sample standard deviation, V (`None` below two readings).
        std: Option<f64>,
    },
    /// A step was recorded.
    StepDone(StepRecord),
    /// The warm-up's state after a chunk of readings (also written to the manifest).
    Warmup(WarmupRecord),
    /// A segment of a drift record was recorded: the record so far and its running overlapping
    /// Allan deviation at octave τ near 1, 10 and 100 s (in volts; this session's readings).
    Drift {
        /// 1-based number of the segment just recorded.
        segment: usize,
        /// Segments in the plan.
        of: usize,
        /// Readings in this session's record so far.
        readings: u64,
        /// The run clock at the end of the segment, s (earlier sessions included).
        elapsed_s: f64,
        /// `(τ, σ)`, s and V.
        adev_v: Vec<(f64, f64)>,
        /// `(τ, σ)` at every octave τ of the running deviation (up to 100 s), s and V: the
        /// curve a live view draws while the record runs.
        adev_curve_v: Vec<(f64, f64)>,
    },
    /// A recovery was needed (logged in the manifest too).
    Retry(Retry),
    /// The run is ending: the table was sent a stop and gyrocal waits until it is at rest.
    Stopping {
        /// The table's measured rate when the stop was sent, °/s (`None` if it did not answer).
        from_dps: Option<f64>,
        /// The emergency stop (interlock open) was sent.
        emergency: bool,
        /// How long gyrocal waits for rest before telling the operator it could not confirm it.
        deadline: Duration,
    },
    /// The end state of the table (the last event of a run).
    Rest(TableRest),
    /// A reading of the chamber during a soak of a temperature series (every poll).
    Soak {
        /// 0-based index into `[series] temperatures_c`.
        point: u32,
        /// The target, °C.
        target_c: f64,
        /// The setpoint now (moving towards the target during the ramp), °C.
        setpoint_c: f64,
        /// The air, °C.
        air_c: f64,
        /// The gyro (product), °C, when the chamber reads one.
        gyro_c: Option<f64>,
        /// How long the soak criterion has held, when it holds.
        held: Option<Duration>,
        /// The soak time the criterion must hold.
        soak: Duration,
        /// Since the soak began.
        waited: Duration,
    },
}
