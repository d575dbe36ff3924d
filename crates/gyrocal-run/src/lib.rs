//! gyrocal-run: a calibration run on the instruments.
//!
//! - [`engine`]: executes a plan's compiled steps ([`gyrocal_files::steps`]: the one dispatch
//!   on the plan's kind) without asking which kind of plan it runs; owns the guaranteed
//!   teardown (table at rest, meter released) and the bounded repeat of a refused step.
//! - [`bench`](mod@bench): the instruments by role ([`Bench`]), so the engine is generic over one
//!   parameter whatever the number of roles, and the same code drives real instruments and
//!   the simulated bench, in real or virtual time.
//!   A temperature series adds the thermal chamber ([`MeterTableChamber`]): the engine soaks
//!   at each temperature, watches the chamber during each step, stops on its alarms and
//!   leaves it in its safe state (after the table) on every way out ([`ChamberRest`]).
//! - [`sink`]: where the results go ([`Sink`]): the run directory, the progress display, the
//!   live monitors, and whatever is added next, through one trait.
//! - [`live`]: the live state a run publishes for viewers (`live.json`, `gyrocal serve`).
//! - [`estimate`]: the plan's duration from the instruments' timing models, and the physical
//!   bound a run's elapsed time is judged against (`gyrocal check` prints it).
//! - [`monitor`]: what the run watches in its readings: the warm-up, and a record's running
//!   Allan deviation.
//! - [`sequencer`]: the names of the first release (`Sequencer` is the engine over a meter
//!   and a table).
//!
//! The plan and run-directory formats are gyrocal-files' (synchronous, no instrument I/O; the
//! engine calls them between async steps: writes are a few kilobytes per chunk); a caller
//! names them from gyrocal-files (no re-export: each type has one name).

pub mod bench;
pub mod engine;
pub mod estimate;
pub mod live;
pub mod monitor;
pub mod sequencer;
pub mod sink;

pub use bench::{Bench, MeterAndTable, MeterTableChamber};
pub use engine::{
    ChamberRest, Engine, Event, Phase, Repeats, RunSummary, SequenceError, SequenceErrorKind,
    Sequencer, SequencerOptions, StopRequest, TableRest,
};
pub use sink::{EventChannel, Sink, SinkError, SinkErrorKind};
