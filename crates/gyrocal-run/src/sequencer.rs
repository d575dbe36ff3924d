//! The names of the first release: the sequencer is the [`crate::engine`] over a bench of a
//! multimeter and a rate table ([`crate::MeterAndTable`]).

pub use crate::engine::{
    Event, Phase, RunSummary, SequenceError, Sequencer, SequencerOptions, StopRequest, TableRest,
};
