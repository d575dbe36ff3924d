//! The bounded repeat: a step that could not be recorded is measured again, at most a set
//! number of times, then the run fails (OpenHTF's `PhaseResult.REPEAT` with its
//! `repeat_limit`).
//!
//! Two causes, each with its own bound (the engine's [`SequencerOptions`]):
//!
//! - **refused**: the table did not hold the step's rate during the acquisition, but is
//!   healthy again (it reached the next rate and held it for the stability window). The step
//!   is measured again at once, at most `step_retries` times; then [`SequenceError::NotHeld`].
//! - **readings lost**: the meter lost a step's readings before they were fetched (its memory
//!   was cleared: a power cycle, or its own recovery configured it again). The step is
//!   measured again right after the one in progress, at most `lost_retries` times; then
//!   [`SequenceError::ReadingsLostAgain`] with the meter's own words for what cleared its
//!   memory. This bounds the loop as a whole: a meter that loses a step's readings at every
//!   attempt ends the run after 1 + `lost_retries` attempts at that step.
//!
//! [`SequencerOptions`]: super::SequencerOptions

use std::collections::HashMap;

use gyrocal_meter::ErrorKind;

use gyrocal_files::steps::Action;

use super::SequenceError;
use gyrocal_files::plan::Step;

/// The counts of the bounded repeat, per step of the schedule.
#[derive(Debug, Clone, Default)]
pub struct Repeats {
    step_retries: u32,
    lost_retries: u32,
    /// Times each step was refused (table did not hold) and measured again.
    refused: HashMap<usize, u32>,
    /// Times each step's readings were lost.
    lost_count: HashMap<usize, u32>,
    /// Steps whose readings were lost, to measure again after the current one.
    lost: Vec<Action>,
}

impl Repeats {
    /// At most `step_retries` repeats of a refused step, `lost_retries` of a step whose
    /// readings were lost.
    pub fn new(step_retries: u32, lost_retries: u32) -> Self {
        Repeats {
            step_retries,
            lost_retries,
            ..Repeats::default()
        }
    }

    /// `step` was refused (`detail`: what the table did): `Ok` when it may be measured
    /// again (counted), the run's error when its repeats are spent.
    pub fn refused(&mut self, step: &Step, detail: &str) -> Result<(), SequenceError> {
        let used = self.refused.entry(step.index).or_default();
        if *used >= self.step_retries {
            return Err(SequenceError::NotHeld {
                step: step.index,
                rate_dps: step.rate_dps,
                detail: detail.to_string(),
            });
        }
        *used += 1;
        Ok(())
    }

    /// The meter failed to hand over `step`'s readings with `error`: `Ok` when they were
    /// lost and the step is queued to be measured again (see [`Repeats::take_lost`]); the
    /// run's error when it is not a loss, or when the step's repeats are spent.
    pub fn lost(
        &mut self,
        step: &Step,
        action: Action,
        error: SequenceError,
    ) -> Result<(), SequenceError> {
        if !readings_lost(&error) {
            return Err(error);
        }
        let times = self.lost_count.entry(step.index).or_default();
        *times += 1;
        if *times > self.lost_retries {
            let attempts = *times;
            let SequenceError::Dmm(last) = error else {
                return Err(error);
            };
            return Err(SequenceError::ReadingsLostAgain {
                step: step.index,
                rate_dps: step.rate_dps,
                attempts,
                last,
            });
        }
        self.lost.push(action);
        Ok(())
    }

    /// The steps queued by [`Repeats::lost`] since the last call.
    pub fn take_lost(&mut self) -> Vec<Action> {
        std::mem::take(&mut self.lost)
    }
}

/// The meter lost readings it still held (a power cycle): the step must be measured again.
fn readings_lost(e: &SequenceError) -> bool {
    matches!(e, SequenceError::Dmm(d) if d.kind() == ErrorKind::ReadingsLost)
}

#[cfg(test)]
mod tests {
    use super::*;
    use gyrocal_files::plan::Acquire;

    fn step(index: usize) -> Step {
        Step {
            index,
            pass: 0,
            rate_dps: 5.0,
            acquire: Acquire::Samples(10),
            series: None,
        }
    }

    #[test]
    fn a_refused_step_is_repeated_at_most_step_retries_times() {
        let mut r = Repeats::new(2, 0);
        assert!(r.refused(&step(3), "moved").is_ok());
        assert!(r.refused(&step(3), "moved").is_ok());
        // another step has its own count
        assert!(r.refused(&step(4), "moved").is_ok());
        let e = r.refused(&step(3), "moved off").unwrap_err();
        assert!(
            matches!(&e, SequenceError::NotHeld { step: 3, detail, .. } if detail == "moved off"),
            "{e}"
        );
        assert!(
            e.to_string().starts_with("step 4 at 5 °/s not recorded"),
            "{e}"
        );
    }
}
