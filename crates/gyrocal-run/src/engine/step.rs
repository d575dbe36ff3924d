//! One step executed: the table's part ([`TableAction`]), the dwell, the one acquire path
//! ([`Acquiring`]: n readings, or chunks until settled), the hold check ([`HoldCheck`]) and
//! the record ([`Record`]), pushed to the sinks.

use gyrocal_files::rundir::temps::Phase as TempPhase;
use gyrocal_files::steps::{
    Acquiring, Action, ChamberAction, HoldCheck, Record, TableAction, Watch,
};
use gyrocal_meter::{Acquired, Measured, Multimeter, Reading};
use gyrocal_table::{RateStats, RateTable, TableMode};
use tokio::time::Instant;

use super::chamber::{TempStats, watch_while};
use super::{Engine, Event, Phase, SequenceError, StepContext, dmm_error};
use crate::bench::Bench;
use crate::monitor::{self, WarmupWatch};
use crate::sink::Recorded;
use gyrocal_files::plan::Step;
use gyrocal_files::rundir::{Sample, StepRecord};

/// How a step ended (errors aside).
pub(super) enum StepOutcome<P> {
    /// Its readings and row are on disk.
    Recorded,
    /// Its readings are in the meter's memory, to be fetched during the next ramp.
    Pending(P),
    /// Nothing was recorded and the step must be measured again: the table did not hold the
    /// rate during the acquisition.
    Again {
        /// `table`: whose doing.
        instrument: &'static str,
        /// What happened.
        detail: String,
    },
}

/// A step whose last readings are still in the meter.
pub(super) struct PendingFetch<P> {
    step: Step,
    action: Action,
    pending: P,
    stats: RateStats,
    t_start: f64,
    t_end: f64,
    /// The gyro's temperature during the acquisition (a step at a temperature).
    temps: Option<TempStats>,
}

/// One acquisition: the readings (or the meter's pending burst) and the table's samples.
struct Acquisition<P> {
    measured: Measured<P>,
    stats: RateStats,
    t_start: f64,
    t_end: f64,
    /// The gyro's temperature during it (a step at a temperature).
    temps: Option<TempStats>,
}

impl<B: Bench> Engine<B> {
    /// One step that records a row: the table's part (the previous step's readings fetched
    /// while the table ramps), dwell, acquire, check the hold, record (or hand the last
    /// memory burst back as pending, to be fetched during the next ramp).
    pub(super) async fn measure_step(
        &mut self,
        action: &Action,
        step: &Step,
        pending: Option<PendingFetch<<B::Meter as Multimeter>::Pending>>,
        last: bool,
        ctx: &StepContext,
    ) -> Result<StepOutcome<PendingFetch<<B::Meter as Multimeter>::Pending>>, SequenceError> {
        let at_rate = self
            .table_action(action, Some(step.index), pending, ctx)
            .await?;
        self.dwell(action, step.index, at_rate).await?;
        self.emit(Event::Phase {
            step: step.index,
            phase: Phase::Acquiring,
        })?;
        let Acquiring::Readings(acquire) = action.acquire else {
            return Err(SequenceError::Panicked(
                "a step that fills a row must acquire a number of readings".into(),
            ));
        };
        let n = Step { acquire, ..*step }.sample_count(ctx.reading_time);
        let n = usize::try_from(n).unwrap_or(usize::MAX);
        let may_defer = self.options.overlap_fetch && !last;
        let watch = match action.chamber {
            ChamberAction::Watch(w) => Some(w),
            ChamberAction::None | ChamberAction::Soak(_) => None,
        };
        let acq = self
            .acquire(n, may_defer, true, watch.map(|w| (w, step)))
            .await?;
        // the meter's recoveries are logged whatever the table did
        if let Measured::Complete(a) = &acq.measured {
            for note in &a.notes {
                self.log_retry(Some(step.index), "dmm", note.clone())?;
            }
        }
        let mut stats = acq.stats;
        if let Some(why) = self.check_hold(action.hold, step, &mut stats).await? {
            return Ok(StepOutcome::Again {
                instrument: "table",
                detail: why,
            });
        }
        // the gyro left the band: refused like a step the table did not hold
        if let (Some(w), Some(t)) = (watch, acq.temps)
            && let Some(why) = t.refusal(&w)
        {
            return Ok(StepOutcome::Again {
                instrument: "chamber",
                detail: why,
            });
        }
        match acq.measured {
            Measured::Complete(a) => {
                let Acquired {
                    readings, retries, ..
                } = a;
                self.record(
                    step,
                    &action.record,
                    &readings,
                    stats,
                    retries,
                    (acq.t_start, acq.t_end),
                    acq.temps,
                )?;
                Ok(StepOutcome::Recorded)
            }
            Measured::Pending(pending) => Ok(StepOutcome::Pending(PendingFetch {
                step: *step,
                action: *action,
                pending,
                stats,
                t_start: acq.t_start,
                t_end: acq.t_end,
                temps: acq.temps,
            })),
        }
    }

    /// A warm-up step ([`Acquiring::UntilSettled`]): the table's part, then chunks of one
    /// window each through the same acquire path as every step, until the watch says the
    /// readings settled (or its longest time passed). Its state goes to the manifest (through
    /// [`Event::Warmup`]) after every chunk.
    pub(super) async fn warm_up(
        &mut self,
        action: &Action,
        ctx: &StepContext,
    ) -> Result<(), SequenceError> {
        let Acquiring::UntilSettled(settings) = action.acquire else {
            return Err(SequenceError::Panicked(
                "a step that fills no row must acquire until settled".into(),
            ));
        };
        let at_rate = self.table_action(action, None, None, ctx).await?;
        self.dwell(action, 0, at_rate).await?;
        let period = ctx.reading_time.as_secs_f64();
        let mut watch = WarmupWatch::new(
            &settings,
            period,
            self.now_s(),
            monitor::WARMUP_BEFORE_SWEEP,
        );
        tracing::info!(window = watch.window(), "warm-up before the steps");
        self.emit(Event::Warmup(watch.record().clone()))?;
        let n = usize::try_from(watch.window()).unwrap_or(usize::MAX);
        loop {
            let acq = self.acquire(n, false, false, None).await?;
            let a = match acq.measured {
                Measured::Complete(a) => a,
                Measured::Pending(p) => self.dmm_mut()?.collect(p).await.map_err(dmm_error)?,
            };
            let t_end = self.now_s();
            for note in &a.notes {
                self.log_retry(None, "dmm", format!("warm-up: {note}"))?;
            }
            let volts: Vec<f64> = a.readings.iter().filter_map(|r| r.volts()).collect();
            let ended = watch.push(&volts, acq.t_start, t_end);
            self.emit(Event::Warmup(watch.record().clone()))?;
            self.sinks.checkpoint(t_end)?;
            if ended {
                tracing::info!(time_s = watch.record().time_s, "warm-up complete");
                return Ok(());
            }
        }
    }

    /// The table's part of a step; returns when the table has held since (for the dwell).
    /// A rate is demanded and waited for, the previous step's pending readings fetched
    /// meanwhile (the table is on another port); otherwise nothing is demanded, the pending
    /// readings are fetched at once, and the hold starts now.
    pub(super) async fn table_action(
        &mut self,
        action: &Action,
        index: Option<usize>,
        pending: Option<PendingFetch<<B::Meter as Multimeter>::Pending>>,
        ctx: &StepContext,
    ) -> Result<Instant, SequenceError> {
        let TableAction::Rate(rate) = action.table else {
            // nothing to demand: the table is at rest with its servo off, or there is none;
            // it holds from now (the dwell overlaps the fetch)
            let at_rest = Instant::now();
            if let Some(p) = pending {
                self.emit(Event::Phase {
                    step: p.step.index,
                    phase: Phase::Fetching,
                })?;
                let fetched = self.dmm_mut()?.collect(p.pending).await;
                self.take_fetched(
                    p.step,
                    p.action,
                    fetched,
                    p.stats,
                    (p.t_start, p.t_end),
                    p.temps,
                )?;
            }
            return Ok(at_rest);
        };
        self.moved = true;
        self.bench.table().set_rate(rate, ctx.accel).await?;
        if let Some(index) = index {
            self.emit(Event::Phase {
                step: index,
                phase: Phase::Ramping,
            })?;
        }
        let mut observe = self.settle_observer();
        let Some(p) = pending else {
            let settled = self
                .bench
                .table()
                .wait_at_rate_observed(&ctx.criteria, &mut observe)
                .await?;
            return Ok(settled.at_rate_since);
        };
        // the previous step's readings come over while the table ramps
        self.emit(Event::Phase {
            step: p.step.index,
            phase: Phase::Fetching,
        })?;
        if self.meter_released {
            return Err(super::released());
        }
        let (dmm, table) = self.bench.meter_and_table();
        // the dwell runs from the moment the table is at rate, fetch or no fetch
        let wait = table.wait_at_rate_observed(&ctx.criteria, &mut observe);
        let (settled, fetched) = tokio::join!(wait, dmm.collect(p.pending));
        // record the previous step before anything else can fail
        self.take_fetched(
            p.step,
            p.action,
            fetched,
            p.stats,
            (p.t_start, p.t_end),
            p.temps,
        )?;
        Ok(settled?.at_rate_since)
    }

    /// The settling dwell, counted from the first sample of the stability window (the table
    /// has held the rate since `at_rate`), the table sampled meanwhile.
    async fn dwell(
        &mut self,
        action: &Action,
        index: usize,
        at_rate: Instant,
    ) -> Result<(), SequenceError> {
        let dwell_end = at_rate + action.dwell;
        if dwell_end > Instant::now() {
            self.emit(Event::Phase {
                step: index,
                phase: Phase::Settling,
            })?;
            let interval = self.options.sample_interval;
            self.bench
                .table()
                .record_while(interval, tokio::time::sleep_until(dwell_end))
                .await?;
        }
        Ok(())
    }

    /// The one acquire path: `n` readings while the table is sampled every
    /// `sample_interval`; `may_defer`: the meter may leave its last burst pending; `live`:
    /// each reading goes to the live feeds; `watch`: a step at a temperature, during which the
    /// chamber is read every poll (temps.csv phase `measure`) and the gyro's temperature kept
    /// for the step's row (a chamber that fails or raises an alarm ends the step, unrecorded).
    async fn acquire(
        &mut self,
        n: usize,
        may_defer: bool,
        live: bool,
        watch: Option<(Watch, &Step)>,
    ) -> Result<Acquisition<<B::Meter as Multimeter>::Pending>, SequenceError> {
        if live {
            self.progress_to_live()?;
        }
        let t_start = self.now_s();
        let interval = self.options.sample_interval;
        if self.meter_released {
            return Err(super::released());
        }
        let Some((w, step)) = watch else {
            let (dmm, table) = self.bench.meter_and_table();
            let (measured, stats) = table
                .record_while(interval, dmm.measure(n, may_defer))
                .await?;
            let measured = measured.map_err(dmm_error)?;
            return Ok(Acquisition {
                measured,
                stats,
                t_start,
                t_end: self.now_s(),
                temps: None,
            });
        };
        let (origin, offset_s) = (self.origin, self.offset_s);
        let clock = move || offset_s + origin.elapsed().as_secs_f64();
        let (dmm, table, chamber) = self.bench.instruments();
        let work = table.record_while(interval, dmm.measure(n, may_defer));
        let (out, watched) = watch_while(chamber, w.poll, Some(step.index), clock, work).await;
        for (t_s, r) in &watched.readings {
            self.note_temp(*t_s, r, Some(w.point), TempPhase::Measure)?;
        }
        self.log_chamber_retries(Some(step.index))?;
        if let Some(e) = watched.error {
            return Err(e);
        }
        let Some(result) = out else {
            return Err(SequenceError::Panicked(
                "the chamber's watch ended without the acquisition or an error".into(),
            ));
        };
        let (measured, stats) = result?;
        let measured = measured.map_err(dmm_error)?;
        Ok(Acquisition {
            measured,
            stats,
            t_start,
            t_end: self.now_s(),
            temps: watched.stats(&w),
        })
    }

    /// The table's side of a finished acquisition, checked as the step asks
    /// ([`HoldCheck`]) before its readings are accepted: one more sample right after the
    /// last reading (a latched fault or an opened interlock is an error there, as in every
    /// sample), the mode, and every sample of the acquisition against the demand. `Ok(None)`:
    /// the table held; `Ok(Some(why))`: it did not, the step must not be recorded but the
    /// table is still in its mode (the step may be measured again); `Err`: the table faulted
    /// or left its mode, and the run ends. `stats` gains the final sample.
    async fn check_hold(
        &mut self,
        hold: HoldCheck,
        step: &Step,
        stats: &mut RateStats,
    ) -> Result<Option<String>, SequenceError> {
        let (demand, tol, expected, name) = match hold {
            HoldCheck::None => return Ok(None),
            HoldCheck::Rate {
                demand_dps,
                tolerance_dps,
            } => (demand_dps, tolerance_dps, TableMode::Rate, "RATE"),
            HoldCheck::ServoOff { tolerance_dps } => {
                (0.0, tolerance_dps, TableMode::Off, "OFF (servo off)")
            }
        };
        let table = self.bench.table();
        let end = table.sample().await?;
        *stats = merge_stats(&[*stats, RateStats::from_samples(&[end])]);
        let status = table.status().await?;
        if status.mode != expected {
            return Err(SequenceError::NotHeld {
                step: step.index,
                rate_dps: step.rate_dps,
                detail: format!(
                    "the table left {name} mode during the acquisition (now {:?}, measured {end:+.6} °/s)",
                    status.mode
                ),
            });
        }
        let hold = tol * self.options.hold_tolerance_factor;
        let farthest = if (stats.min - demand).abs() > (stats.max - demand).abs() {
            stats.min
        } else {
            stats.max
        };
        if !(stats.count > 0 && (farthest - demand).abs() <= hold) {
            return Ok(Some(format!(
                "the measured rate reached {farthest:+.6} °/s during the acquisition (demand \
                 {demand:+} °/s, allowed ±{hold} °/s; {} table samples)",
                stats.count
            )));
        }
        if (stats.mean - demand).abs() > tol {
            return Ok(Some(format!(
                "the mean measured rate during the acquisition was {:+.6} °/s (demand {demand:+} \
                 °/s, tolerance ±{tol} °/s; {} table samples)",
                stats.mean, stats.count
            )));
        }
        Ok(None)
    }

    /// Each reading to the live feeds, with the running mean and deviation of the step's
    /// valid readings.
    fn progress_to_live(&mut self) -> Result<(), SequenceError> {
        let live = self.live.clone();
        let progress = (!live.is_empty()).then(|| {
            // Welford's running mean and variance of the step's valid readings
            let (mut n, mut mean, mut m2) = (0u64, 0.0f64, 0.0f64);
            Box::new(move |p: gyrocal_meter::Progress| {
                if p.done <= 1 {
                    (n, mean, m2) = (0, 0.0, 0.0);
                }
                let latest = p.latest.volts();
                if let Some(v) = latest {
                    n += 1;
                    let d = v - mean;
                    mean += d / n as f64;
                    m2 += d * (v - mean);
                }
                let event = Event::Acquiring {
                    done: p.done,
                    total: p.total,
                    latest,
                    mean: if n > 0 { mean } else { f64::NAN },
                    std: (n > 1).then(|| (m2 / (n - 1) as f64).sqrt()),
                };
                for f in &live {
                    f(event.clone());
                }
            }) as gyrocal_meter::ProgressFn
        });
        self.dmm_mut()?.set_progress(progress);
        Ok(())
    }

    /// The previous step's readings fetched from the meter's memory: recorded, or, when the
    /// meter lost them (a power cycle), queued to be measured again right after this step
    /// (the bounded repeat, [`super::Repeats::lost`]).
    fn take_fetched(
        &mut self,
        step: Step,
        action: Action,
        fetched: Result<Acquired, <B::Meter as Multimeter>::Error>,
        stats: RateStats,
        times: (f64, f64),
        temps: Option<TempStats>,
    ) -> Result<(), SequenceError> {
        match fetched {
            Ok(acq) => {
                for note in acq.notes {
                    self.log_retry(Some(step.index), "dmm", note)?;
                }
                self.record(
                    &step,
                    &action.record,
                    &acq.readings,
                    stats,
                    acq.retries,
                    times,
                    temps,
                )
            }
            Err(e) => {
                let e = dmm_error(e);
                let message = format!(
                    "{e}; step {} is measured again after this one",
                    step.index + 1
                );
                self.repeats.lost(&step, action, e)?;
                self.log_retry(Some(step.index), "dmm", message)
            }
        }
    }

    /// Writes a complete step: samples, then the step row (through the sinks: the run
    /// directory flushes the samples and fsyncs the row), then the live monitors.
    #[allow(clippy::too_many_arguments)] // the parts of one finished acquisition
    fn record(
        &mut self,
        step: &Step,
        record: &Record,
        readings: &[Reading],
        stats: RateStats,
        retries: u32,
        (t_start, t_end): (f64, f64),
        temps: Option<TempStats>,
    ) -> Result<(), SequenceError> {
        let n = readings.len();
        // Reading times are spread evenly over the acquisition: the meter paces them itself.
        let samples: Vec<Sample> = readings
            .iter()
            .enumerate()
            .map(|(i, r)| Sample {
                index: i as u64,
                t_s: t_start + (t_end - t_start) * (i as f64 + 1.0) / n.max(1) as f64,
                volts: r.volts(),
            })
            .collect();
        self.sinks.samples(step, &samples)?;
        let volts: Vec<f64> = readings.iter().filter_map(|r| r.volts()).collect();
        let overloads = (n - volts.len()) as u64;
        if volts.is_empty() {
            return Err(SequenceError::AllOverloaded {
                step: step.index,
                rate_dps: step.rate_dps,
                count: n,
            });
        }
        let (mean, std) = mean_std(&volts);
        let measured = stats.count > 0 && stats.mean.is_finite();
        let row = StepRecord {
            step: step.index,
            pass: step.pass,
            rate_dps: step.rate_dps,
            rate_meas_dps: measured.then_some(stats.mean),
            rate_meas_std_dps: (measured && stats.std.is_finite()).then_some(stats.std),
            rate_meas_min_dps: measured.then_some(stats.min),
            rate_meas_max_dps: measured.then_some(stats.max),
            rate_samples: measured.then_some(stats.count),
            volts: mean,
            volts_std: std,
            n: volts.len() as u64,
            overloads,
            retries,
            t_start_s: t_start,
            t_end_s: t_end,
            series: step.series.map(|at| gyrocal_files::rundir::SeriesCells {
                series_point: at.point,
                setpoint_c: at.setpoint_c,
                temp_min_c: temps.map(|t| t.min),
                temp_mean_c: temps.map(|t| t.mean),
                temp_max_c: temps.map(|t| t.max),
                bias_record: at.bias_record,
            }),
        };
        if overloads > 0 {
            tracing::warn!(
                step = step.index,
                overloads,
                "overload readings excluded from the mean"
            );
        }
        let recorded = Recorded {
            step,
            record,
            row: &row,
            volts: &volts,
            t_start,
            t_end,
            elapsed_s: self.now_s(),
        };
        self.sinks
            .recorded(&recorded, Event::StepDone(row.clone()))?;
        self.recorded += 1;
        Ok(())
    }
}

/// Mean and sample standard deviation (`None` for one value).
fn mean_std(v: &[f64]) -> (f64, Option<f64>) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    if v.len() < 2 {
        return (mean, None);
    }
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, Some(var.sqrt()))
}

/// Pools the statistics of several recordings.
fn merge_stats(parts: &[RateStats]) -> RateStats {
    let parts: Vec<&RateStats> = parts.iter().filter(|s| s.count > 0).collect();
    let count: u64 = parts.iter().map(|s| s.count).sum();
    if count == 0 {
        return RateStats::EMPTY;
    }
    let n = count as f64;
    let mean = parts.iter().map(|s| s.mean * s.count as f64).sum::<f64>() / n;
    // pooled sum of squares about the overall mean
    let ss: f64 = parts
        .iter()
        .map(|s| {
            let within = if s.count > 1 && s.std.is_finite() {
                s.std.powi(2) * (s.count as f64 - 1.0)
            } else {
                0.0
            };
            within + s.count as f64 * (s.mean - mean).powi(2)
        })
        .sum();
    let std = if count > 1 {
        (ss / (n - 1.0)).sqrt()
    } else {
        f64::NAN
    };
    RateStats {
        count,
        mean,
        std,
        min: parts.iter().map(|s| s.min).fold(f64::INFINITY, f64::min),
        max: parts
            .iter()
            .map(|s| s.max)
            .fold(f64::NEG_INFINITY, f64::max),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn merged_stats_equal_stats_of_all_samples() {
        let a = [1.0, 2.0, 3.0];
        let b = [10.0, 11.0];
        let all: Vec<f64> = a.iter().chain(b.iter()).copied().collect();
        let m = merge_stats(&[RateStats::from_samples(&a), RateStats::from_samples(&b)]);
        let want = RateStats::from_samples(&all);
        assert_eq!(m.count, want.count);
        assert!((m.mean - want.mean).abs() < 1e-12);
        assert!((m.std - want.std).abs() < 1e-12);
        assert_eq!((m.min, m.max), (1.0, 11.0));
    }

    #[test]
    fn mean_std_of_one_value_has_no_std() {
        assert_eq!(mean_std(&[2.5]), (2.5, None));
        let (m, s) = mean_std(&[1.0, 3.0]);
        assert_eq!(m, 2.0);
        assert!((s.unwrap() - 2f64.sqrt()).abs() < 1e-12);
    }
}
