//! How long a plan takes, from the instruments' own timing models, and the physical bound a run
//! is measured against.
//!
//! The bound of a step is what no sequencer can beat: the ramp at the acceleration limit, the
//! settling dwell the plan asks for, and the multimeter's arming and reading time; and the wire,
//! which carries every reading once. When streaming, the transfer overlaps the measurement (the
//! step takes the longer of the two); in memory mode the meter cannot measure while it
//! transfers, but the table is on another port, so a step's `FETC?` can overlap the next step's
//! ramp and dwell (that part takes the longer of the two). The one transfer that overlaps with
//! nothing comes at the very end (the last reading's characters when streaming, the last
//! burst's `FETC?` in memory mode). With the paper's settings (NPLC 1, 9600 baud) the wire keeps
//! up and the bound is ramps + dwells + arming + readings + one reading's transfer. A run's
//! `elapsed / bound` says how much instrument time the sequencer wasted; polling one reading at
//! a time is measured against the same bound, which is why it scores badly.

use std::time::Duration;

use gyrocal_hp34401a::{AutoZero, DcvConfig, Strategy, Timing};

use crate::plan::{Acquisition, Plan, Step};

/// The multimeter configuration a plan asks for.
pub fn dcv_config(plan: &Plan) -> DcvConfig {
    let d = plan.dmm();
    DcvConfig {
        range: Some(d.range_v),
        nplc: d.nplc,
        autozero: if d.autozero {
            AutoZero::On
        } else {
            AutoZero::Off
        },
        line_hz: d.line_hz,
        baud: d.baud,
        ..DcvConfig::default()
    }
}

/// The DC-volts settings a plan's `[dmm]` section asks any meter for.
pub fn dc_volts(plan: &Plan) -> gyrocal_meter::DcVolts {
    let d = plan.dmm();
    gyrocal_meter::DcVolts {
        range_v: Some(d.range_v),
        nplc: d.nplc,
        autozero: d.autozero,
        line_hz: d.line_hz,
    }
}

/// The 34401A on `link` as a plan sets it up (its acquisition strategy and the link's baud
/// rate for the timing model), in the multimeter role.
pub fn hp34401a<T: gyrocal_link::Transport>(
    link: T,
    plan: &Plan,
    options: gyrocal_hp34401a::DriverOptions,
) -> gyrocal_hp34401a::Hp34401aMeter<T> {
    gyrocal_hp34401a::Hp34401aMeter::new(
        link,
        options,
        strategy(plan.dmm().acquisition),
        plan.dmm().baud,
    )
}

/// The driver strategy a plan's `acquisition` key names.
pub fn strategy(acquisition: Acquisition) -> Strategy {
    match acquisition {
        Acquisition::Auto => Strategy::Auto,
        Acquisition::Stream => Strategy::Stream,
        Acquisition::Memory => Strategy::Memory,
        Acquisition::Poll => Strategy::Poll,
    }
}

/// The ramp time from `from` to `to` at `acceleration` (no jerk limit).
pub fn ramp_time(from: f64, to: f64, acceleration: f64) -> Duration {
    if acceleration > 0.0 && acceleration.is_finite() {
        Duration::from_secs_f64((to - from).abs() / acceleration)
    } else {
        Duration::ZERO
    }
}

/// One step's figures.
#[derive(Debug, Clone, PartialEq)]
pub struct StepEstimate {
    /// The step.
    pub step: Step,
    /// Readings it takes.
    pub samples: u64,
    /// Ramp from the previous rate.
    pub ramp: Duration,
    /// Time from the end of the ramp to the start of the acquisition: the plan's `settle_s`, or
    /// the table's stability window when that is longer (the window is spent at rate, so it
    /// counts towards the dwell).
    pub settle: Duration,
    /// The acquisition itself with the resolved strategy (for memory mode without the last
    /// fetch, which overlaps with the next ramp).
    pub acquire: Duration,
    /// This step's share of the physical bound.
    pub bound: Duration,
}

/// A plan's estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimate {
    /// The strategy `auto` resolves to (or the one asked for).
    pub strategy: Strategy,
    /// One reading's time at the plan's settings.
    pub reading_time: Duration,
    /// Per step.
    pub steps: Vec<StepEstimate>,
    /// The transfer at the end that overlaps with nothing.
    pub final_transfer: Duration,
    /// The expected duration of the steps (ramps, dwells, acquisitions, final transfer).
    pub total: Duration,
    /// The physical bound (see the module docs).
    pub bound: Duration,
}

/// Estimates `steps` of `plan`, starting from a table at `start_rate`.
pub fn estimate(plan: &Plan, steps: &[Step], start_rate: f64) -> Estimate {
    let timing = Timing::new(&dcv_config(plan));
    let strategy = timing.resolve(strategy(plan.dmm().acquisition));
    let reading_time = timing.reading_time();
    let accel = plan.table().acceleration_dps2;
    let dwell = plan.settle().max(plan.table().stability_window);
    let mut prev = start_rate;
    let mut out = Vec::with_capacity(steps.len());
    let mut total = Duration::ZERO;
    let mut bound = Duration::ZERO;
    let mut last_n = 0usize;
    // the previous step's last memory burst, still to be fetched during this step's ramp
    let mut pending = Duration::ZERO;
    let wire = timing.wire_time_per_reading();
    for step in steps {
        let n = step.sample_count(reading_time);
        let n_usize = usize::try_from(n).unwrap_or(usize::MAX);
        let ramp = ramp_time(prev, step.rate_dps, accel);
        let readings = reading_time * n_u32(n);
        let (acquire, step_bound) = match strategy {
            Strategy::Memory => {
                // every burst's fetch but the last is paid in the step; the last overlaps
                // with the next ramp and dwell
                let last = timing.fetch_time(last_burst(n_usize));
                let all = timing.estimate(Strategy::Memory, n_usize);
                let acquire = all.saturating_sub(last);
                let transfers = wire * n_u32(n);
                let in_step = transfers.saturating_sub(wire * n_u32(last_burst(n_usize) as u64));
                let lead = (ramp + plan.settle()).max(pending);
                total += (ramp + dwell).max(pending) + acquire;
                pending = last;
                (acquire, lead + timing.arming_time() + readings + in_step)
            }
            s => {
                let acquire = timing.estimate(s, n_usize);
                total += ramp + dwell + acquire;
                // streaming overlaps the transfer with the measurement
                let measure = readings.max(wire * n_u32(n));
                (
                    acquire,
                    ramp + plan.settle() + timing.arming_time() + measure,
                )
            }
        };
        bound += step_bound;
        out.push(StepEstimate {
            step: *step,
            samples: n,
            ramp,
            settle: dwell,
            acquire,
            bound: step_bound,
        });
        prev = step.rate_dps;
        last_n = n_usize;
    }
    let final_transfer = match strategy {
        Strategy::Memory if last_n > 0 => timing.fetch_time(last_burst(last_n)),
        _ if last_n > 0 => timing.wire_time_per_reading(),
        _ => Duration::ZERO,
    };
    total += final_transfer;
    bound += final_transfer;
    Estimate {
        strategy,
        reading_time,
        steps: out,
        final_transfer,
        total,
        bound,
    }
}

/// Readings in the last memory burst of an `n`-reading acquisition.
fn last_burst(n: usize) -> usize {
    let max = gyrocal_hp34401a::timing::MEMORY_READINGS;
    match n % max {
        0 if n > 0 => max,
        r => r,
    }
}

fn n_u32(n: u64) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn paper() -> Plan {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/paper.toml");
        Plan::from_file(&path).unwrap()
    }

    #[test]
    fn paper_plan_bound_follows_the_timing_model() {
        let plan = paper();
        let e = estimate(&plan, &plan.schedule(), 0.0);
        assert_eq!(e.steps.len(), 19);
        // NPLC 1 at 50 Hz with autozero: 1.5 ms + 2 x 20 ms per reading
        assert!((e.reading_time.as_secs_f64() - 0.0415).abs() < 1e-9);
        // the wire (54.5 readings/s) keeps up with 24.1 readings/s: streaming
        assert_eq!(e.strategy, Strategy::Stream);
        let acquiring = 19.0 * (0.020 + 500.0 * 0.0415);
        let settling = 19.0 * plan.settle().as_secs_f64();
        let ramps: f64 = e.steps.iter().map(|s| s.ramp.as_secs_f64()).sum();
        let expect = acquiring + settling + ramps + e.final_transfer.as_secs_f64();
        assert!(
            (e.bound.as_secs_f64() - expect).abs() < 1e-6,
            "{:?} vs {expect}",
            e.bound
        );
        assert!(e.total >= e.bound);
    }

    #[test]
    fn ramps_follow_the_schedule_order() {
        let plan = paper();
        let e = estimate(&plan, &plan.schedule(), 0.0);
        let accel = plan.table().acceleration_dps2;
        for w in e.steps.windows(2) {
            let want = (w[1].step.rate_dps - w[0].step.rate_dps).abs() / accel;
            assert!((w[1].ramp.as_secs_f64() - want).abs() < 1e-9);
        }
    }
}
