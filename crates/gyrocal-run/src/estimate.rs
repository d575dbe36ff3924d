//! How long a plan takes, from the instruments' own timing models, and the physical bound a run
//! is measured against.
//!
//! The bound of a step is what no sequencer can beat: the ramp at the acceleration limit, the
//! settling dwell the plan asks for, and the multimeter's share, which its own timing model
//! states ([`gyrocal_meter::Cost::bound`]): arming, the readings or the wire (whichever is the
//! slower), and the transfer that tells the host the last reading was taken (the table must not
//! move before that). A transfer the meter may leave pending (a memory burst still in the
//! instrument) overlaps the next step's ramp and dwell, on another port: that part takes the
//! longer of the two. A run's `elapsed / bound` says how much instrument time the sequencer
//! wasted; polling one reading at a time is measured against the same bound, which is why it
//! scores badly.
//!
//! This module knows no meter: the caller hands it the meter's [`TimingModel`] (the CLI builds
//! it from the plan; a connected meter gives it with [`gyrocal_meter::Multimeter::timing`]).

use std::time::Duration;

use gyrocal_meter::TimingModel;

use gyrocal_files::plan::{Plan, Step};
use gyrocal_files::steps::{Action, ChamberAction, Soak};

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
    /// How the meter acquires (`stream`, `memory`, ...).
    pub acquisition: &'static str,
    /// One reading's time at the plan's settings.
    pub reading_time: Duration,
    /// Per step.
    pub steps: Vec<StepEstimate>,
    /// The soaks of a temperature series among them: the chamber's ramps at the plan's ramp
    /// rate and the soak time at each temperature, at least (a gyro lagging the air takes
    /// longer; no run can take less). Included in `total` and `bound`.
    pub soaks: Duration,
    /// The expected duration of the steps (ramps, dwells, acquisitions and transfers, soaks).
    pub total: Duration,
    /// The physical bound (see the module docs).
    pub bound: Duration,
}

/// The least a soak takes when the chamber starts at `from_c`: the setpoint's ramp to the
/// target at the plan's ramp rate, then the soak time.
pub fn soak_time(from_c: f64, soak: &Soak) -> Duration {
    let ramp_min = (soak.setpoint_c - from_c).abs() / soak.ramp_c_per_min;
    let ramp = Duration::try_from_secs_f64(ramp_min * 60.0).unwrap_or(Duration::ZERO);
    ramp + soak.soak
}

/// The least the soaks among `actions` take, the chamber starting at `from_c`.
pub fn soaks_ahead<'a>(actions: impl IntoIterator<Item = &'a Action>, from_c: f64) -> Duration {
    let mut at = from_c;
    let mut total = Duration::ZERO;
    for a in actions {
        if let ChamberAction::Soak(s) = &a.chamber {
            total += soak_time(at, s);
            at = s.setpoint_c;
        }
    }
    total
}

/// Estimates `steps` of `plan` on a meter with `timing`, starting from a table at
/// `start_rate`. Every step but the last may leave its last transfer pending, as the
/// sequencer does.
pub fn estimate(
    plan: &Plan,
    steps: &[Step],
    start_rate: f64,
    timing: &dyn TimingModel,
) -> Estimate {
    let reading_time = timing.reading_time();
    let accel = plan.table().acceleration_dps2;
    let dwell = plan.settle().max(plan.table().stability_window);
    let mut prev = start_rate;
    let mut out = Vec::with_capacity(steps.len());
    let mut total = Duration::ZERO;
    let mut bound = Duration::ZERO;
    // the previous step's deferred transfer, overlapping this step's ramp and dwell
    let (mut pending, mut pending_bound) = (Duration::ZERO, Duration::ZERO);
    for (i, step) in steps.iter().enumerate() {
        let last = i + 1 == steps.len();
        let n = step.sample_count(reading_time);
        let cost = timing.cost(usize::try_from(n).unwrap_or(usize::MAX), !last);
        let ramp = ramp_time(prev, step.rate_dps, accel);
        let lead = (ramp + dwell).max(pending);
        let lead_bound = (ramp + plan.settle()).max(pending_bound);
        total += lead + cost.in_step;
        let step_bound = lead_bound + cost.bound;
        bound += step_bound;
        out.push(StepEstimate {
            step: *step,
            samples: n,
            ramp,
            settle: dwell,
            acquire: cost.in_step,
            bound: step_bound,
        });
        (pending, pending_bound) = (cost.deferred, cost.bound_deferred);
        prev = step.rate_dps;
    }
    let soaks = series_soaks(plan, steps);
    Estimate {
        acquisition: timing.acquisition(),
        reading_time,
        steps: out,
        soaks,
        total: total + soaks,
        bound: bound + soaks,
    }
}

/// The soaks a temperature series' `steps` need (one before the first step at each
/// temperature, as the plan compiles them), the chamber starting at its ambient setpoint.
fn series_soaks(plan: &Plan, steps: &[Step]) -> Duration {
    let (Some(series), Some(chamber)) = (plan.series(), plan.chamber()) else {
        return Duration::ZERO;
    };
    let mut at = chamber.ambient_c;
    let mut point = None;
    let mut total = Duration::ZERO;
    for s in steps {
        let Some(p) = s.series else { continue };
        if point != Some(p.point) {
            point = Some(p.point);
            total += soak_time(
                at,
                &Soak {
                    point: p.point,
                    setpoint_c: p.setpoint_c,
                    ramp_c_per_min: chamber.ramp_c_per_min,
                    band_c: series.band_c,
                    stability_c_per_min: series.stability_c_per_min,
                    soak: series.soak(),
                    max_wait: series.max_wait(),
                    poll: series.poll(),
                },
            );
            at = p.setpoint_c;
        }
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;
    use gyrocal_hp34401a::{AutoZero, DcvConfig, MeterTiming, Strategy};
    use std::path::Path;

    fn paper() -> Plan {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/paper.toml");
        Plan::from_file(&path).unwrap()
    }

    fn timing(plan: &Plan) -> MeterTiming {
        let d = plan.dmm();
        let config = DcvConfig {
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
        };
        MeterTiming::new(&config, Strategy::Auto)
    }

    #[test]
    fn paper_plan_bound_follows_the_timing_model() {
        let plan = paper();
        let e = estimate(&plan, &plan.schedule(), 0.0, &timing(&plan));
        assert_eq!(e.steps.len(), 19);
        // NPLC 1 at 50 Hz with autozero: 1.5 ms + 2 x 20 ms per reading
        assert!((e.reading_time.as_secs_f64() - 0.0415).abs() < 1e-9);
        // the wire (54.5 readings/s) keeps up with 24.1 readings/s: streaming
        assert_eq!(e.acquisition, "stream");
        // per step: arming, 500 readings, the last reading's 16 characters at 9600 baud
        let last_reading = 16.0 * 11.0 / 9600.0;
        let acquiring = 19.0 * (0.020 + 500.0 * 0.0415 + last_reading);
        let settling = 19.0 * plan.settle().as_secs_f64();
        let ramps: f64 = e.steps.iter().map(|s| s.ramp.as_secs_f64()).sum();
        let expect = acquiring + settling + ramps;
        assert!(
            (e.bound.as_secs_f64() - expect).abs() < 1e-6,
            "{:?} vs {expect}",
            e.bound
        );
        assert!(e.total >= e.bound);
    }

    #[test]
    fn a_deferred_fetch_overlaps_the_next_ramp_but_not_the_last_step() {
        let plan = paper();
        let d = plan.dmm();
        let config = DcvConfig {
            nplc: d.nplc,
            line_hz: d.line_hz,
            baud: d.baud,
            ..DcvConfig::default()
        };
        let memory = MeterTiming::new(&config, Strategy::Memory);
        let e = estimate(&plan, &plan.schedule(), 0.0, &memory);
        assert_eq!(e.acquisition, "memory");
        // 500 readings: one burst; its FETC? (9.2 s) is longer than most ramps + dwells, so
        // a step's lead is the previous fetch, and only the last step fetches in the step
        let last = e.steps.last().unwrap();
        let first = &e.steps[0];
        let fetch = 500.0 * 16.0 * 11.0 / 9600.0;
        assert!(last.acquire.as_secs_f64() - first.acquire.as_secs_f64() > fetch);
        assert!(e.total >= e.bound);
    }

    #[test]
    fn ramps_follow_the_schedule_order() {
        let plan = paper();
        let e = estimate(&plan, &plan.schedule(), 0.0, &timing(&plan));
        let accel = plan.table().acceleration_dps2;
        for w in e.steps.windows(2) {
            let want = (w[1].step.rate_dps - w[0].step.rate_dps).abs() / accel;
            assert!((w[1].ramp.as_secs_f64() - want).abs() < 1e-9);
        }
    }
}
