//! The calibration sequencer: for each step of the plan, demand the rate, wait until the table
//! is at rate, dwell, acquire, record; at the end stop the table and fit.
//!
//! Why it looks the way it does:
//!
//! - **Nothing is recorded that is not complete.** A step's row goes to `steps.csv` (fsynced,
//!   after its samples) only when all its readings are in; a resume drops whatever a step left
//!   behind and runs it again.
//! - **The table is stopped on every way out.** Errors, a stop request (Ctrl-C, SIGTERM) and a
//!   dropped future all end in the same cleanup: a controlled stop through the table's
//!   [`StopHandle`] (an emergency stop on a second request), a device clear and `SYST:LOC` for
//!   the multimeter, and the manifest marked `aborted` or `failed` with the reason.
//! - **No instrument time is wasted.** The table is on another port than the multimeter, so in
//!   memory mode the last burst of a step is fetched while the table already ramps to the next
//!   rate; the stability window counts towards the settling dwell (the table is at rate during
//!   it); streaming overlaps the transfer with the measurement. The run reports its elapsed time
//!   against the physical bound of [`crate::estimate`].
//! - **Time is the run's own clock** (tokio's `Instant`), so a simulated run in virtual time is
//!   exact and reproducible, and the same code runs in real time on real instruments.

use std::time::Duration;

use gyrocal_hp34401a::{Burst, Hp34401a, Reading, Strategy, Timing};
use gyrocal_link::Transport;
use gyrocal_table::{RateStats, RateTable, SettleCriteria, StopHandle, TableError};
use tokio::sync::{mpsc, watch};
use tokio::time::Instant;
use tracing::Instrument as _;

use crate::estimate::{self, Estimate};
use crate::plan::{Plan, Step};
use crate::rundir::{
    Instruments, Retry, RunDir, RunError, Sample, Status, StepRecord, Timing as RunTiming,
};

/// What the operator (or a signal) asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum StopRequest {
    /// Keep going.
    #[default]
    None,
    /// Stop: controlled stop of the table, run marked `aborted`.
    Controlled,
    /// Stop now: emergency stop of the table (interlock open), run marked `aborted`.
    Emergency,
}

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
        /// The strategy the acquisition uses.
        strategy: Strategy,
    },
    /// A step begins (`position` counts from 1 within this session).
    StepStarted {
        /// The step.
        step: Step,
        /// 1-based position in this session's steps.
        position: usize,
        /// Steps in this session.
        total: usize,
        /// Estimated time to the end of the run from the start of this step (the instruments'
        /// timing models, see [`crate::estimate`]).
        remaining: Duration,
    },
    /// A step entered a phase.
    Phase {
        /// Step index.
        step: usize,
        /// The phase.
        phase: Phase,
    },
    /// Readings received in the current acquisition.
    Acquiring {
        /// Readings so far.
        done: usize,
        /// Readings asked for.
        total: usize,
    },
    /// A step was recorded.
    StepDone(StepRecord),
    /// A recovery was needed (logged in the manifest too).
    Retry(Retry),
}

/// Tunables of the sequencer that are not in the plan.
#[derive(Debug, Clone, PartialEq)]
pub struct SequencerOptions {
    /// Table sampling interval while waiting, dwelling and acquiring (each sample is also a
    /// heartbeat). Default 200 ms.
    pub sample_interval: Duration,
    /// Time allowed for the table to come to rest at the end of a run. Default 60 s.
    pub stop_timeout: Duration,
    /// Time allowed for each cleanup exchange with an instrument after an error. Default 5 s.
    pub cleanup_timeout: Duration,
    /// Fetch a memory burst while the table ramps to the next rate. Default true.
    pub overlap_fetch: bool,
}

impl Default for SequencerOptions {
    fn default() -> Self {
        SequencerOptions {
            sample_interval: Duration::from_millis(200),
            stop_timeout: Duration::from_secs(60),
            cleanup_timeout: Duration::from_secs(5),
            overlap_fetch: true,
        }
    }
}

/// Why a run did not complete.
#[derive(Debug, thiserror::Error)]
pub enum SequenceError {
    /// The multimeter failed (after its own retries).
    #[error("multimeter: {0}")]
    Dmm(Box<gyrocal_hp34401a::Error>),
    /// The rate table failed or faulted.
    #[error("rate table: {0}")]
    Table(Box<TableError>),
    /// The run directory could not be written.
    #[error("run directory: {0}")]
    RunDir(Box<RunError>),
    /// A step produced no valid reading.
    #[error(
        "step {step} at {rate_dps} °/s: all {count} readings were overloads (9.9E+37); is range_v too small?"
    )]
    AllOverloaded {
        /// Step index.
        step: usize,
        /// The step's rate.
        rate_dps: f64,
        /// Readings taken.
        count: usize,
    },
    /// The operator stopped the run.
    #[error("stopped by the operator ({0:?})")]
    Stopped(StopRequest),
}

// The drivers' errors carry context (device, command, bytes) and are large; boxed, the
// sequencer's results stay small on every `?` path.
impl From<gyrocal_hp34401a::Error> for SequenceError {
    fn from(e: gyrocal_hp34401a::Error) -> Self {
        SequenceError::Dmm(Box::new(e))
    }
}

impl From<TableError> for SequenceError {
    fn from(e: TableError) -> Self {
        SequenceError::Table(Box::new(e))
    }
}

impl From<RunError> for SequenceError {
    fn from(e: RunError) -> Self {
        SequenceError::RunDir(Box::new(e))
    }
}

/// How a run ended.
#[derive(Debug, Clone, PartialEq)]
pub struct RunSummary {
    /// `complete`, `aborted` or `failed`.
    pub status: Status,
    /// Why, when not complete.
    pub reason: Option<String>,
    /// Steps recorded in this session.
    pub steps_recorded: usize,
    /// The session's bound versus elapsed, when it completed.
    pub timing: Option<RunTiming>,
    /// Elapsed on the run clock, including earlier sessions, s.
    pub elapsed_s: f64,
}

/// The ACL driver configuration for `plan`: its client-side limits are the plan's.
pub fn table_config(plan: &Plan) -> gyrocal_table::acl::AclConfig {
    gyrocal_table::acl::AclConfig {
        limits: gyrocal_table::Limits {
            max_rate: plan.table().max_rate_dps,
            max_acceleration: plan.table().acceleration_dps2,
        },
        ..gyrocal_table::acl::AclConfig::default()
    }
}

/// A memory burst whose readings are still in the meter.
struct PendingFetch {
    step: Step,
    burst: Burst,
    /// Readings of the step's earlier bursts.
    readings: Vec<Reading>,
    stats: RateStats,
    retries: u32,
    t_start: f64,
    t_end: f64,
}

/// The sequencer. Build it with the connected-or-not drivers, the run directory and the plan,
/// then call [`Sequencer::run`].
pub struct Sequencer<D: Transport, T: RateTable> {
    plan: Plan,
    dmm: Option<Hp34401a<D>>,
    table: T,
    stop_handle: StopHandle,
    run: RunDir,
    options: SequencerOptions,
    events: Option<mpsc::UnboundedSender<Event>>,
    origin: Instant,
    offset_s: f64,
    recorded: usize,
    strategy_used: Option<Strategy>,
}

impl<D: Transport + 'static, T: RateTable> Sequencer<D, T> {
    /// A sequencer for `plan` writing to `run` (fresh or opened for resume).
    pub fn new(
        plan: Plan,
        dmm: Hp34401a<D>,
        table: T,
        run: RunDir,
        options: SequencerOptions,
    ) -> Self {
        let stop_handle = table.stop_handle();
        let offset_s = run.manifest().elapsed_s;
        Sequencer {
            plan,
            dmm: Some(dmm),
            table,
            stop_handle,
            run,
            options,
            events: None,
            origin: Instant::now(),
            offset_s,
            recorded: 0,
            strategy_used: None,
        }
    }

    /// Sends progress events to `tx`.
    pub fn with_events(mut self, tx: mpsc::UnboundedSender<Event>) -> Self {
        self.events = Some(tx);
        self
    }

    /// The table's stop handle, for a signal handler's emergency stop.
    pub fn stop_handle(&self) -> StopHandle {
        self.stop_handle.clone()
    }

    /// The run directory (for the caller to fit, report and inspect after the run).
    pub fn run_dir(&self) -> &RunDir {
        &self.run
    }

    /// Consumes the sequencer and returns the run directory.
    pub fn into_run_dir(self) -> RunDir {
        self.run
    }

    fn now_s(&self) -> f64 {
        self.offset_s + self.origin.elapsed().as_secs_f64()
    }

    fn emit(&self, event: Event) {
        if let Some(tx) = &self.events {
            let _ = tx.send(event);
        }
    }

    /// Runs the remaining steps of the plan until done, failed or stopped through `stop`.
    /// Whatever happens, the table is stopped, the multimeter returned to local and the manifest
    /// left with a final status; the result says which. The fit is the caller's (see
    /// [`crate::fit_run`]), so a failed fit never loses the data.
    pub async fn run(&mut self, mut stop: watch::Receiver<StopRequest>) -> RunSummary {
        self.origin = Instant::now();
        let run_span =
            tracing::info_span!("run", plan = %self.plan.name(), dir = %self.run.path().display());
        let outcome = {
            let wait_stop = async {
                loop {
                    let req = *stop.borrow_and_update();
                    if req != StopRequest::None {
                        return req;
                    }
                    if stop.changed().await.is_err() {
                        // sender gone: nobody can ask for a stop any more
                        std::future::pending::<()>().await;
                    }
                }
            };
            tokio::select! {
                biased;
                req = wait_stop => Err(SequenceError::Stopped(req)),
                r = self.steps().instrument(run_span) => r,
            }
        };
        match outcome {
            Ok(timing) => self.finish_ok(timing).await,
            Err(e) => {
                let emergency = matches!(e, SequenceError::Stopped(StopRequest::Emergency))
                    || *stop.borrow() == StopRequest::Emergency;
                self.finish_err(e, emergency).await
            }
        }
    }

    async fn finish_ok(&mut self, timing: RunTiming) -> RunSummary {
        // the table is already stopped by `steps`; say goodbye to the meter
        self.release_dmm(false).await;
        let elapsed_s = self.now_s();
        let mut summary = RunSummary {
            status: Status::Complete,
            reason: None,
            steps_recorded: self.recorded,
            timing: Some(timing.clone()),
            elapsed_s,
        };
        let result = self
            .run
            .set_timing(timing)
            .and_then(|()| self.run.finish(Status::Complete, None, elapsed_s));
        if let Err(e) = result {
            tracing::error!(error = %e, "could not close the run directory");
            summary.status = Status::Failed;
            summary.reason = Some(format!("run directory: {e}"));
        }
        summary
    }

    async fn finish_err(&mut self, error: SequenceError, emergency: bool) -> RunSummary {
        let status = match error {
            SequenceError::Stopped(_) => Status::Aborted,
            _ => Status::Failed,
        };
        let reason = error.to_string();
        tracing::warn!(%reason, ?status, "run stopping");
        // Table first: it is the dangerous one. A table that faulted or stopped answering gets
        // the emergency path too (rate-table.md: "for a second interrupt or a fault"): a
        // controlled stop that was written may still not have been heard.
        let table_fault = matches!(&error, SequenceError::Table(e) if e.ends_run());
        let stopped = if emergency {
            self.stop_handle.emergency_stop().await
        } else {
            self.stop_handle.stop().await
        };
        if let Err(e) = &stopped {
            tracing::error!(error = %e, "stop command failed; trying the emergency stop");
        }
        if !emergency && (table_fault || stopped.is_err()) {
            tracing::warn!("table fault: emergency stop (interlock open)");
            if let Err(e) = self.stop_handle.emergency_stop().await {
                tracing::error!(error = %e, "emergency stop failed: STOP THE TABLE BY HAND");
            }
        }
        self.release_dmm(true).await;
        let elapsed_s = self.now_s();
        if let Err(e) = self.run.finish(status, Some(reason.clone()), elapsed_s) {
            tracing::error!(error = %e, "could not write the final manifest");
        }
        RunSummary {
            status,
            reason: Some(reason),
            steps_recorded: self.recorded,
            timing: None,
            elapsed_s,
        }
    }

    /// Device clear (after an interrupted exchange), then `SYST:LOC`; bounded in time, errors
    /// logged (the run's outcome is already decided).
    async fn release_dmm(&mut self, after_error: bool) {
        let Some(mut dmm) = self.dmm.take() else {
            return;
        };
        let limit = self.options.cleanup_timeout;
        if after_error {
            match tokio::time::timeout(limit, dmm.recover()).await {
                Ok(Ok(errors)) if !errors.is_empty() => {
                    tracing::info!(?errors, "multimeter error queue at the stop");
                }
                Ok(Ok(_)) => {}
                Ok(Err(e)) => tracing::warn!(error = %e, "multimeter clear failed"),
                Err(_) => tracing::warn!("multimeter clear timed out"),
            }
        }
        match tokio::time::timeout(limit, dmm.close()).await {
            Ok(Ok(_)) => {}
            Ok(Err(e)) => tracing::warn!(error = %e, "multimeter did not go back to local"),
            Err(_) => tracing::warn!("multimeter did not go back to local in time"),
        }
    }

    fn log_retry(
        &mut self,
        step: Option<usize>,
        instrument: &str,
        message: String,
    ) -> Result<(), RunError> {
        let retry = Retry {
            t_s: self.now_s(),
            step,
            instrument: instrument.into(),
            message,
        };
        tracing::warn!(step, instrument, message = %retry.message, "retry");
        self.emit(Event::Retry(retry.clone()));
        self.run.log_retry(retry)
    }

    /// Connects, configures and runs every remaining step; stops the table at the end.
    async fn steps(&mut self) -> Result<RunTiming, SequenceError> {
        let Some(dmm) = self.dmm.as_mut() else {
            return Err(released());
        };
        let dmm_id = dmm.connect().await?.raw.clone();
        let t = self.table.connect().await?;
        let table_id = format!("{},{},{},{}", t.manufacturer, t.model, t.serial, t.version);
        self.emit(Event::Connected {
            dmm: dmm_id.clone(),
            table: table_id.clone(),
        });
        self.run.set_instruments(Instruments {
            dmm: Some(dmm_id),
            table: Some(table_id),
        })?;

        let dcv = estimate::dcv_config(&self.plan);
        let dmm = self.dmm_mut()?;
        dmm.configure(&dcv).await?;
        let timing = Timing::new(&dcv);
        let strategy = timing.resolve(estimate::strategy(self.plan.dmm().acquisition));
        self.strategy_used = Some(strategy);
        self.table.enable().await?;

        let steps = self.run.remaining_steps();
        let est: Estimate = estimate::estimate(&self.plan, &steps, 0.0);
        self.emit(Event::Planned {
            steps: steps.len(),
            done: self.run.done_steps().len(),
            estimate: est.total,
            strategy,
        });
        tracing::info!(
            steps = steps.len(),
            estimate_s = est.total.as_secs_f64(),
            bound_s = est.bound.as_secs_f64(),
            ?strategy,
            "starting the schedule"
        );

        let t0 = Instant::now();
        let criteria = SettleCriteria {
            tolerance: self.plan.table().rate_tolerance_dps,
            relative_tolerance: 0.0,
            window: self.plan.table().stability_window,
            interval: self
                .options
                .sample_interval
                .min(self.plan.table().stability_window / 4),
            timeout: self.plan.table().at_rate_timeout,
        };
        let accel = self.plan.table().acceleration_dps2;
        let dwell = self.plan.settle().saturating_sub(criteria.window);
        let mut pending: Option<PendingFetch> = None;
        let total = steps.len();
        for (i, step) in steps.iter().enumerate() {
            let remaining = est.steps[i..]
                .iter()
                .map(|e| e.ramp + e.settle + e.acquire)
                .sum::<Duration>()
                + est.final_transfer;
            self.emit(Event::StepStarted {
                step: *step,
                position: i + 1,
                total,
                remaining,
            });
            let span = tracing::info_span!("step", index = step.index, rate_dps = step.rate_dps);
            async {
                let at_rate;
                self.table.set_rate(step.rate_dps, accel).await?;
                self.emit(Event::Phase {
                    step: step.index,
                    phase: Phase::Ramping,
                });
                if let Some(p) = pending.take() {
                    // the previous step's readings come over while the table ramps
                    self.emit(Event::Phase {
                        step: p.step.index,
                        phase: Phase::Fetching,
                    });
                    let Self { table, dmm, .. } = self;
                    let dmm = dmm.as_mut().ok_or_else(released)?;
                    // the dwell runs from the moment the table is at rate, fetch or no fetch
                    let wait = async {
                        let r = table.wait_at_rate(&criteria).await;
                        (r, Instant::now())
                    };
                    let ((settled, at), fetched) =
                        tokio::join!(wait, fetch_with_retry(dmm, &p.burst));
                    at_rate = at;
                    // record the previous step before anything else can fail
                    let (readings, notes) = match fetched {
                        Ok(ok) => ok,
                        Err((e, notes)) => {
                            for m in notes {
                                self.log_retry(Some(p.step.index), "dmm", m)?;
                            }
                            return Err(e);
                        }
                    };
                    for m in notes {
                        self.log_retry(Some(p.step.index), "dmm", m)?;
                    }
                    self.record_fetched(p, readings)?;
                    settled?;
                } else {
                    self.table.wait_at_rate(&criteria).await?;
                    at_rate = Instant::now();
                }
                let dwell_end = at_rate + dwell;
                if dwell_end > Instant::now() {
                    self.emit(Event::Phase {
                        step: step.index,
                        phase: Phase::Settling,
                    });
                    let interval = self.options.sample_interval;
                    self.table
                        .record_while(interval, tokio::time::sleep_until(dwell_end))
                        .await?;
                }
                self.emit(Event::Phase {
                    step: step.index,
                    phase: Phase::Acquiring,
                });
                let n =
                    usize::try_from(step.sample_count(timing.reading_time())).unwrap_or(usize::MAX);
                let last = i + 1 == total;
                match strategy {
                    Strategy::Memory => {
                        let p = self.acquire_memory(step, n).await?;
                        if self.options.overlap_fetch && !last {
                            pending = Some(p);
                        } else {
                            self.emit(Event::Phase {
                                step: step.index,
                                phase: Phase::Fetching,
                            });
                            let fetched = self.fetch_monitored(&p.burst).await?;
                            let readings = self.retries_logged(p.step.index, fetched)?;
                            self.record_fetched(p, readings)?;
                        }
                    }
                    s => self.acquire_direct(step, n, s).await?,
                }
                Ok::<(), SequenceError>(())
            }
            .instrument(span)
            .await?;
        }
        let elapsed = t0.elapsed();
        // park the table; a table that does not come to rest is a failure of the run
        self.table.stop().await?;
        self.table.wait_stopped(self.options.stop_timeout).await?;
        let bound = est.bound.as_secs_f64();
        let elapsed_s = elapsed.as_secs_f64();
        let ratio = if bound > 0.0 {
            elapsed_s / bound
        } else {
            f64::NAN
        };
        tracing::info!(bound_s = bound, elapsed_s, ratio, "schedule done");
        Ok(RunTiming {
            bound_s: bound,
            elapsed_s,
            ratio: if ratio.is_finite() { ratio } else { 1.0 },
            acquisition: Some(strategy_name(strategy).into()),
        })
    }

    /// A `FETC?` that overlaps with nothing: the table keeps being sampled (the heartbeat)
    /// while the readings come over; those samples are not the step's (the meter is not
    /// measuring), so their statistics are dropped.
    async fn fetch_monitored(&mut self, burst: &Burst) -> Result<FetchResult, SequenceError> {
        let interval = self.options.sample_interval;
        let Self { table, dmm, .. } = self;
        let dmm = dmm.as_mut().ok_or_else(released)?;
        let (fetched, _not_measuring) = table
            .record_while(interval, fetch_with_retry(dmm, burst))
            .await?;
        Ok(fetched)
    }

    /// Logs a fetch's retries in the manifest and passes its result on.
    fn retries_logged(
        &mut self,
        step: usize,
        fetched: FetchResult,
    ) -> Result<Vec<Reading>, SequenceError> {
        let (result, notes) = match fetched {
            Ok((r, notes)) => (Ok(r), notes),
            Err((e, notes)) => (Err(e), notes),
        };
        for m in notes {
            self.log_retry(Some(step), "dmm", m)?;
        }
        result
    }

    fn dmm_mut(&mut self) -> Result<&mut Hp34401a<D>, SequenceError> {
        self.dmm.as_mut().ok_or_else(released)
    }

    fn progress_to_events(&mut self) {
        let tx = self.events.clone();
        if let Some(dmm) = self.dmm.as_mut() {
            match tx {
                Some(tx) => dmm.set_progress(move |p| {
                    let _ = tx.send(Event::Acquiring {
                        done: p.done,
                        total: p.total,
                    });
                }),
                None => dmm.clear_progress(),
            }
        }
    }

    /// Stream or poll: the meter's readings arrive while the table is sampled.
    async fn acquire_direct(
        &mut self,
        step: &Step,
        n: usize,
        strategy: Strategy,
    ) -> Result<(), SequenceError> {
        self.progress_to_events();
        let t_start = self.now_s();
        let interval = self.options.sample_interval;
        let Self { table, dmm, .. } = self;
        let dmm = dmm.as_mut().ok_or_else(released)?;
        let (acq, stats) = table
            .record_while(interval, dmm.acquire(n, strategy))
            .await?;
        let acq = acq?;
        let t_end = self.now_s();
        if acq.retries > 0 {
            self.log_retry(
                Some(step.index),
                "dmm",
                format!(
                    "{} acquisition retr{} after device clear (see log)",
                    acq.retries,
                    if acq.retries == 1 { "y" } else { "ies" }
                ),
            )?;
        }
        self.record(step, &acq.readings, stats, acq.retries, t_start, t_end)
    }

    /// Memory mode: every burst but the last is armed, waited for and fetched; the last is
    /// armed and waited for, and its fetch returned as pending.
    async fn acquire_memory(
        &mut self,
        step: &Step,
        n: usize,
    ) -> Result<PendingFetch, SequenceError> {
        self.progress_to_events();
        let t_start = self.now_s();
        let interval = self.options.sample_interval;
        let retries_allowed = self.dmm_mut()?.options().retries;
        let mut readings = Vec::with_capacity(n);
        let mut stats = Vec::new();
        let mut retries = 0u32;
        let max = gyrocal_hp34401a::timing::MEMORY_READINGS;
        loop {
            let k = (n - readings.len()).min(max);
            let last = readings.len() + k >= n;
            let Self { table, dmm, .. } = self;
            let dmm = dmm.as_mut().ok_or_else(released)?;
            let burst = async {
                let b = dmm.arm_burst(k).await?;
                dmm.wait_burst(&b).await?;
                Ok::<_, gyrocal_hp34401a::Error>(b)
            };
            let (burst, s) = table.record_while(interval, burst).await?;
            let burst = match burst {
                Ok(b) => b,
                Err(e) if e.is_retryable() && retries < retries_allowed => {
                    retries += 1;
                    let msg =
                        format!("memory burst failed ({e}); device clear and retry {retries}");
                    self.log_retry(Some(step.index), "dmm", msg)?;
                    self.dmm_mut()?.recover().await?;
                    continue;
                }
                Err(e) => return Err(e.into()),
            };
            stats.push(s);
            if last {
                return Ok(PendingFetch {
                    step: *step,
                    burst,
                    readings,
                    stats: merge_stats(&stats),
                    retries,
                    t_start,
                    t_end: self.now_s(),
                });
            }
            self.emit(Event::Phase {
                step: step.index,
                phase: Phase::Fetching,
            });
            let fetched = self.fetch_monitored(&burst).await?;
            let got = self.retries_logged(step.index, fetched)?;
            readings.extend(got);
            self.emit(Event::Phase {
                step: step.index,
                phase: Phase::Acquiring,
            });
        }
    }

    fn record_fetched(
        &mut self,
        p: PendingFetch,
        mut last: Vec<Reading>,
    ) -> Result<(), SequenceError> {
        let mut readings = p.readings;
        readings.append(&mut last);
        self.record(&p.step, &readings, p.stats, p.retries, p.t_start, p.t_end)
    }

    /// Writes a complete step: samples (flushed), then the step row (fsynced).
    fn record(
        &mut self,
        step: &Step,
        readings: &[Reading],
        stats: RateStats,
        retries: u32,
        t_start: f64,
        t_end: f64,
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
        self.run.append_samples(step.index, &samples)?;
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
        let rec = StepRecord {
            step: step.index,
            pass: step.pass,
            rate_dps: step.rate_dps,
            rate_meas_dps: measured.then_some(stats.mean),
            rate_meas_std_dps: (measured && stats.std.is_finite()).then_some(stats.std),
            rate_meas_min_dps: measured.then_some(stats.min),
            rate_meas_max_dps: measured.then_some(stats.max),
            rate_samples: None,
            volts: mean,
            volts_std: std,
            n: volts.len() as u64,
            overloads,
            retries,
            t_start_s: t_start,
            t_end_s: t_end,
        };
        if overloads > 0 {
            tracing::warn!(
                step = step.index,
                overloads,
                "overload readings excluded from the mean"
            );
        }
        self.run.append_step(rec.clone())?;
        let elapsed = self.now_s();
        self.run.set_elapsed(elapsed)?;
        self.recorded += 1;
        self.emit(Event::StepDone(rec));
        Ok(())
    }
}

/// Readings with the retry notes, or the error with the notes so far.
type FetchResult = Result<(Vec<Reading>, Vec<String>), (SequenceError, Vec<String>)>;

fn released() -> SequenceError {
    SequenceError::from(gyrocal_hp34401a::Error::Config(
        "multimeter already released".into(),
    ))
}

/// `FETC?` with retries: the readings stay in the meter's memory until the next `INIT`, so a
/// garbled transfer is fetched again after a device clear.
async fn fetch_with_retry<D: Transport>(dmm: &mut Hp34401a<D>, burst: &Burst) -> FetchResult {
    let mut notes = Vec::new();
    let allowed = dmm.options().retries;
    let mut tries = 0;
    loop {
        match dmm.fetch(burst).await {
            Ok(r) => return Ok((r, notes)),
            Err(e) if e.is_retryable() && tries < allowed => {
                tries += 1;
                notes.push(format!("FETC? failed ({e}); device clear and fetch again"));
                tracing::warn!(error = %e, "FETC? failed; device clear and fetch again");
                if let Err(e) = dmm.recover().await {
                    return Err((e.into(), notes));
                }
            }
            Err(e) => return Err((e.into(), notes)),
        }
    }
}

fn strategy_name(s: Strategy) -> &'static str {
    match s {
        Strategy::Stream => "stream",
        Strategy::Memory => "memory",
        Strategy::Poll => "poll",
        Strategy::Auto => "auto",
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
