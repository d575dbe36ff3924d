//! The schedule a plan expands into: one [`Step`] per rate of each pass, in order, with what
//! it acquires ([`Acquire`]). A step's index is stable for a given plan: it is the run
//! directory's `step_no` minus one and the key a resume continues from.

use std::time::Duration;

use super::{MAX_DURATION_S, Plan};

/// What a step acquires.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Acquire {
    /// A fixed number of readings (`samples_per_rate`; also zero-rate steps of a
    /// whole-revolution plan).
    Samples(u32),
    /// Readings spanning this long, a whole number of table turns
    /// (`whole_revolutions · 360 / |ω|`); see [`Step::sample_count`].
    Span {
        /// Required acquisition duration.
        duration: Duration,
        /// Number of whole turns it covers.
        revolutions: u32,
    },
}

/// One step of the schedule: one rate of one pass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Step {
    /// 0-based position in the schedule; stable for a given plan (the run directory's
    /// `step_no` minus one).
    pub index: usize,
    /// 0-based pass (`0..repeat`).
    pub pass: u32,
    /// Demanded rate, °/s.
    pub rate_dps: f64,
    /// What to acquire.
    pub acquire: Acquire,
    /// The temperature this step measures at, on a temperature series (`None` for every
    /// other kind).
    pub series: Option<SeriesStep>,
}

/// Where a step of a temperature series sits in the series: steps.csv's `series_point`,
/// `setpoint_c` and `bias_record` columns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SeriesStep {
    /// 0-based index into `[series] temperatures_c`.
    pub point: u32,
    /// The chamber's setpoint, °C.
    pub setpoint_c: f64,
    /// The step is the bias record at this temperature (0 °/s, `bias_readings` readings),
    /// not a step of its sweep.
    pub bias_record: bool,
}

impl Step {
    /// Readings to take given the meter's time per reading: `Samples(n)` gives `n`; `Span`
    /// gives `round(duration / reading_period)` (at least 1), the count whose total time is
    /// closest to the whole turns.
    pub fn sample_count(&self, reading_period: Duration) -> u64 {
        match self.acquire {
            Acquire::Samples(n) => u64::from(n),
            Acquire::Span { duration, .. } => {
                let p = reading_period.as_secs_f64();
                if p <= 0.0 || !p.is_finite() {
                    return 1;
                }
                let n = (duration.as_secs_f64() / p).round();
                // `as` saturates; the bound keeps a silly period from asking for billions.
                (n.max(1.0) as u64).min(u64::from(u32::MAX))
            }
        }
    }

    /// The required acquisition duration, for whole-revolution steps.
    pub fn span(&self) -> Option<Duration> {
        match self.acquire {
            Acquire::Samples(_) => None,
            Acquire::Span { duration, .. } => Some(duration),
        }
    }
}

impl Plan {
    /// The schedule, by the plan's kind: `repeat` passes over `rates_dps`, in order (a
    /// temperature series: those passes and its bias record at each temperature).
    pub fn schedule(&self) -> Vec<Step> {
        super::kind::schedule(self)
    }

    /// Number of steps of the schedule.
    pub fn step_count(&self) -> usize {
        super::kind::step_count(self)
    }

    /// `repeat` passes over `rates_dps`, the first step numbered `first`, each tagged with
    /// `series`.
    pub(super) fn passes_schedule(&self, first: usize, series: Option<SeriesStep>) -> Vec<Step> {
        let mut steps = Vec::with_capacity(self.passes_count());
        for pass in 0..self.repeat {
            for &rate_dps in &self.rates_dps {
                let acquire = if self.whole_revolutions > 0 && rate_dps != 0.0 {
                    let secs = f64::from(self.whole_revolutions) * 360.0 / rate_dps.abs();
                    // Validation bounds `secs` to MAX_DURATION_S; the fallback is unreachable.
                    let duration = Duration::try_from_secs_f64(secs)
                        .unwrap_or(Duration::from_secs_f64(MAX_DURATION_S));
                    Acquire::Span {
                        duration,
                        revolutions: self.whole_revolutions,
                    }
                } else {
                    Acquire::Samples(self.samples_per_rate)
                };
                steps.push(Step {
                    index: first + steps.len(),
                    pass,
                    rate_dps,
                    acquire,
                    series,
                });
            }
        }
        steps
    }

    /// Number of steps of `repeat` passes (`repeat × rates`).
    pub(super) fn passes_count(&self) -> usize {
        self.rates_dps.len() * self.repeat as usize
    }
}
