//! The step vocabulary: what a plan compiles to, and what the run's engine (gyrocal-run)
//! executes without ever asking which kind of plan it runs.
//!
//! Why: a kind of test (a scale-factor sweep, a drift record; next a temperature series or a
//! turn-on repeatability) is a way of composing a few things the bench can do, the way
//! Bluesky composes `mv` / `trigger_and_read` stubs into plans. A step says all the engine
//! needs, in the bench's words:
//!
//! - what the table does ([`TableAction`]: a rate, nothing demanded with the servo off, or
//!   untouched because there is no table; a position later),
//! - how long the engine dwells once the table holds it,
//! - how the meter acquires ([`Acquiring`]: n readings, or until the readings settle; whole
//!   turns are already a span of readings, see [`Acquire`]),
//! - how the hold is checked afterwards ([`HoldCheck`]),
//! - how the result is recorded ([`Record`]: a row of `steps.csv`, a segment of a record
//!   that the live monitors watch, or the warm-up in the manifest).
//!
//! The run as a whole adds its [`Setup`] (enable the table, or bring it to rest and switch
//! its servo off, or nothing) and whether its teardown must bring a table to rest.
//!
//! [`compile`] goes through the one dispatch on the plan's kind (`plan/kind.rs`); each kind's
//! compile lives in that kind's own plan module (`plan/sweep.rs`, `plan/drift.rs`), beside its
//! keys and rules. Resume keys are unchanged: every step that
//! records carries the plan schedule's [`Step`] (its `index` is the run directory's `step_no` minus one).

use std::time::Duration;

use crate::plan::{Acquire, Plan, Step, WarmupSettings};

/// What the run does once, before its first step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Setup {
    /// Enable the table (servo on, RATE mode): every step demands a rate.
    EnableTable,
    /// Bring the table to rest, then switch its servo off the orderly way its controller
    /// offers; it is never enabled again in this run (a record with the servo off).
    RestThenServoOff,
    /// Nothing: the run has no table.
    Nothing,
}

/// What the table does during a step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TableAction {
    /// Demand this rate (°/s; 0 is a zero-rate hold with the servo on) and wait until the
    /// table holds it for its stability window.
    Rate(f64),
    /// Nothing is demanded: the table is at rest with its servo off (see
    /// [`Setup::RestThenServoOff`]); it is still sampled.
    ServoOff,
    /// Nothing is demanded and nothing turns: the run has no table.
    Untouched,
}

impl TableAction {
    /// The rate demanded, when the step demands one.
    pub fn demand_dps(&self) -> Option<f64> {
        match self {
            TableAction::Rate(r) => Some(*r),
            TableAction::ServoOff | TableAction::Untouched => None,
        }
    }
}

/// How the meter acquires during a step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Acquiring {
    /// A number of readings, or readings spanning whole turns (the schedule's [`Acquire`];
    /// the count follows the meter's time per reading, [`Step::sample_count`]).
    Readings(Acquire),
    /// Chunks of one warm-up window each, until consecutive window means settle or the
    /// warm-up's longest time is reached (IEEE 1431 §12.6).
    UntilSettled(WarmupSettings),
    /// No readings: the step is a chamber's soak ([`ChamberAction::Soak`]).
    Nothing,
}

/// How the table's hold is checked after the acquisition (a step that fails it is not
/// recorded and is measured again, a bounded number of times).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum HoldCheck {
    /// The table stayed in RATE mode and its measured rate within the tolerance of the
    /// demand (single samples within a multiple of it, see the engine's options).
    Rate {
        /// The demand, °/s.
        demand_dps: f64,
        /// The plan's at-rate tolerance, °/s.
        tolerance_dps: f64,
    },
    /// The table stayed in mode OFF (servo off) and did not move more than the tolerance.
    ServoOff {
        /// The plan's at-rate tolerance, °/s.
        tolerance_dps: f64,
    },
    /// Nothing to check (no table, or a warm-up whose readings are not a result).
    None,
}

/// How a step's result is recorded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Record {
    /// A row of `steps.csv` (today's `StepRecord`) after its readings in `samples.csv`.
    Row(Step),
    /// A segment of a record: a row like [`Record::Row`], and the live monitors (the running
    /// Allan deviation, a warm-up watched in the record) see its readings.
    Segment(Step),
    /// The warm-up: its state goes to the manifest's `warmup`, no row.
    Warmup,
    /// A soak: no row (the temperatures go to `temps.csv`, phases `ramp` and `soak`).
    Soak,
}

impl Record {
    /// The schedule's step this record fills (its resume key), if it fills one.
    pub fn step(&self) -> Option<&Step> {
        match self {
            Record::Row(s) | Record::Segment(s) => Some(s),
            Record::Warmup | Record::Soak => None,
        }
    }
}

/// One self-describing step of a run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Action {
    /// What the table does.
    pub table: TableAction,
    /// How long to stay once the table holds (counted from the first sample of its
    /// stability window) before acquiring.
    pub dwell: Duration,
    /// How the meter acquires.
    pub acquire: Acquiring,
    /// How the hold is checked afterwards.
    pub hold: HoldCheck,
    /// How the result is recorded.
    pub record: Record,
    /// What the chamber does (nothing on a bench without one).
    pub chamber: ChamberAction,
}

/// What the thermal chamber does during a step (a temperature series; see
/// `plan/series.rs`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ChamberAction {
    /// Nothing: no chamber, or one not watched during this step.
    None,
    /// The step is a soak: the setpoint stepped towards the target, then a wait until the
    /// gyro's temperature meets the criterion; the chamber read every `poll`.
    Soak(Soak),
    /// The step measures at a temperature: the chamber is read every `poll` during the
    /// acquisition (temps.csv phase `measure`), the gyro's temperature min/mean/max go into
    /// the step's row, and a step during which it left the band is measured again.
    Watch(Watch),
}

/// A soak at one temperature of a series.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Soak {
    /// 0-based index into `[series] temperatures_c`.
    pub point: u32,
    /// The target setpoint, °C.
    pub setpoint_c: f64,
    /// The run's ramp: the setpoint is stepped towards the target at this rate, °C/min.
    pub ramp_c_per_min: f64,
    /// Soaked when the gyro's temperature is within ± this of the target, °C ...
    pub band_c: f64,
    /// ... changing slower than this, °C/min ...
    pub stability_c_per_min: f64,
    /// ... for this long.
    pub soak: Duration,
    /// The run fails if the criterion has not held `soak` long after this long.
    pub max_wait: Duration,
    /// The chamber is read (and temps.csv written) at this interval.
    pub poll: Duration,
}

/// What a measuring step at a temperature of a series watches.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Watch {
    /// 0-based index into `[series] temperatures_c`.
    pub point: u32,
    /// The setpoint, °C.
    pub setpoint_c: f64,
    /// The step is refused if the gyro's temperature leaves ± this of the setpoint, °C.
    pub band_c: f64,
    /// The chamber is read at this interval.
    pub poll: Duration,
}

impl Action {
    /// The schedule's step (resume key) this action records, if any.
    pub fn step(&self) -> Option<&Step> {
        self.record.step()
    }
}

/// A plan compiled for one session: its setup, its steps in order, and what watches them.
#[derive(Debug, Clone, PartialEq)]
pub struct Compiled {
    /// Done once before the first step.
    pub setup: Setup,
    /// The session's steps, in order.
    pub steps: Vec<Action>,
    /// A warm-up watched in the readings of the record's segments (rather than a step of
    /// its own), when the plan has one and no earlier session completed it.
    pub warmup_in_record: Option<WarmupSettings>,
    /// Steps in the plan's whole schedule (what "step 4/19" counts).
    pub schedule_len: usize,
    /// The run moves or samples a table: its teardown must bring it to rest.
    pub uses_table: bool,
    /// The run drives a chamber: its teardown must put it in its safe state.
    pub uses_chamber: bool,
}

impl Compiled {
    /// The steps that fill the schedule (every step but a warm-up step).
    pub fn recording(&self) -> impl Iterator<Item = &Step> {
        self.steps.iter().filter_map(Action::step)
    }
}

/// Compiles `plan` for a session that runs `remaining` steps of its schedule (all of them on
/// a fresh run; the run directory's `remaining_steps` on a resume). `warmup_done`: an
/// earlier session completed the warm-up (manifest `warmup.complete`), so it is not repeated.
/// Through the one dispatch on the plan's kind (`plan/kind.rs`).
pub fn compile(plan: &Plan, remaining: &[Step], warmup_done: bool) -> Compiled {
    crate::plan::compile(plan, remaining, warmup_done)
}

#[cfg(test)]
mod tests;
