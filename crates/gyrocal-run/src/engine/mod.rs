//! The engine: executes a plan's compiled steps ([`gyrocal_files::steps`]) on a [`Bench`],
//! pushing what it produces to its [`crate::sink`]s. It never asks which kind of plan it
//! runs: the steps say what the table does, how the meter acquires, how the hold is checked
//! and how the result is recorded.
//!
//! Why it looks the way it does:
//!
//! - **Nothing is recorded that is not complete.** A step's row goes to `steps.csv` (fsynced,
//!   after its samples) only when all its readings are in; a resume drops whatever a step left
//!   behind and runs it again.
//! - **The table is stopped on every way out: the guaranteed teardown (`engine/teardown.rs`).** Errors, a
//!   stop request (Ctrl-C, SIGTERM), a failed consumer and a panic all end in the same
//!   cleanup: a controlled stop through the table's [`StopHandle`] (an emergency stop on a
//!   second request), the wait until the table reports rest, a device clear and `SYST:LOC` for
//!   the multimeter, and the manifest marked `aborted` or `failed` with the reason.
//! - **A refused step is measured again, a bounded number of times: the repeat ([`Repeats`]).**
//!   A step the table did not hold, or whose readings the meter lost before they were
//!   fetched, is queued again (OpenHTF's REPEAT with a `repeat_limit`); past the limit the run
//!   fails.
//! - **No instrument time is wasted.** The table is on another port than the multimeter, so in
//!   memory mode the last burst of a step is fetched while the table already ramps to the next
//!   rate; the stability window counts towards the settling dwell (the table is at rate during
//!   it); streaming overlaps the transfer with the measurement. The run reports its elapsed time
//!   against the physical bound of [`crate::estimate`].
//! - **Time is the run's own clock** (tokio's `Instant`), so a simulated run in virtual time is
//!   exact and reproducible, and the same code runs in real time on real instruments.

mod chamber;
mod events;
mod outcome;
mod repeat;
mod step;
mod teardown;

use std::collections::VecDeque;
use std::time::Duration;

use gyrocal_chamber::Chamber as _;
use gyrocal_files::steps::{self, Action, ChamberAction, Compiled, Setup};
use gyrocal_meter::{ErrorKind, MeterError, Multimeter};
use gyrocal_table::{RateTable, SettleCriteria, SettleProgress, StopHandle};
use tokio::sync::{mpsc, watch};
use tokio::time::Instant;
use tracing::Instrument as _;

use crate::bench::{Bench, MeterAndTable};
use crate::estimate::{self, Estimate};
use crate::sink::{Begin, Connected, EventChannel, LiveFn, Monitors, Sink, Sinks};
use gyrocal_files::plan::{Plan, Step};
use gyrocal_files::rundir::{RunDir, Timing as RunTiming};

pub use chamber::{
    STABILITY_WINDOW_MAX, ramped_setpoint, safe_state, slope_per_min, stability_window,
};
pub use events::{Event, Phase};
pub(crate) use outcome::dmm_error;
pub use outcome::{
    ChamberRest, RunSummary, SequenceError, SequenceErrorKind, SequencerOptions, StopRequest,
    TableRest,
};
pub use repeat::Repeats;
use step::{PendingFetch, StepOutcome};

/// What the steps share: how to reach the rate and how to read.
struct StepContext {
    criteria: SettleCriteria,
    accel: f64,
    reading_time: Duration,
}

/// The engine. Build it with the bench (any [`Bench`]: the CLI builds it from the plan), the
/// run directory and the plan, add consumers ([`Engine::with_sink`]), then call
/// [`Engine::run`].
pub struct Engine<B: Bench> {
    plan: Plan,
    bench: B,
    /// The meter was handed back to its front panel (the teardown's last act).
    meter_released: bool,
    stop_handle: StopHandle,
    sinks: Sinks,
    /// The live feeds of the sinks that want them (settle samples, each reading).
    live: Vec<LiveFn>,
    options: SequencerOptions,
    /// The plan compiled for this session (at construction, again at the start of
    /// [`Engine::run`] from the run directory as it is then).
    program: Compiled,
    origin: Instant,
    offset_s: f64,
    recorded: usize,
    /// The table identified itself in this session.
    table_reached: bool,
    /// A rate was demanded in this session.
    moved: bool,
    /// An emergency stop was sent in this session (the interlock is open).
    emergency_sent: bool,
    /// The bounded repeat of refused steps.
    repeats: Repeats,
}

/// The engine over today's bench of a multimeter and a rate table (the name the CLI, the
/// tests and the bench harness know).
pub type Sequencer<M, T> = Engine<MeterAndTable<M, T>>;

impl<M: Multimeter, T: RateTable> Engine<MeterAndTable<M, T>> {
    /// An engine for `plan` on `dmm` and `table`, writing to `run` (fresh or opened for
    /// resume).
    pub fn new(plan: Plan, dmm: M, table: T, run: RunDir, options: SequencerOptions) -> Self {
        Engine::on_bench(plan, MeterAndTable::new(dmm, table), run, options)
    }
}

impl<B: Bench> Engine<B> {
    /// An engine for `plan` on `bench`, writing to `run` (fresh or opened for resume).
    pub fn on_bench(plan: Plan, mut bench: B, run: RunDir, options: SequencerOptions) -> Self {
        let stop_handle = bench.table().stop_handle();
        let offset_s = run.manifest().elapsed_s;
        let repeats = Repeats::new(options.step_retries, options.lost_retries);
        let program = compile_for(&plan, &run);
        Engine {
            plan,
            bench,
            meter_released: false,
            stop_handle,
            sinks: Sinks {
                run,
                others: Vec::new(),
            },
            live: Vec::new(),
            options,
            program,
            origin: Instant::now(),
            offset_s,
            recorded: 0,
            table_reached: false,
            moved: false,
            emergency_sent: false,
            repeats,
        }
    }

    /// Sends progress events to `tx` (the progress display's feed, [`EventChannel`]).
    pub fn with_events(self, tx: mpsc::UnboundedSender<Event>) -> Self {
        self.with_sink(EventChannel(tx))
    }

    /// Adds a consumer of the run's results (after the run directory and the ones added
    /// before).
    pub fn with_sink(mut self, sink: impl Sink + 'static) -> Self {
        self.sinks.others.push(Box::new(sink));
        self
    }

    /// The table's stop handle, for a signal handler's emergency stop.
    pub fn stop_handle(&self) -> StopHandle {
        self.stop_handle.clone()
    }

    /// The run directory (for the caller to fit, report and inspect after the run).
    pub fn run_dir(&self) -> &RunDir {
        &self.sinks.run
    }

    /// Consumes the engine and returns the run directory.
    pub fn into_run_dir(self) -> RunDir {
        self.sinks.run
    }

    fn now_s(&self) -> f64 {
        self.offset_s + self.origin.elapsed().as_secs_f64()
    }

    /// An event to every consumer.
    fn emit(&mut self, event: Event) -> Result<(), SequenceError> {
        Ok(self.sinks.event(&event)?)
    }

    /// The one observer of the table's settle samples: to every live feed.
    fn settle_observer(&self) -> impl FnMut(SettleProgress) + Send + 'static {
        settle_observer(self.live.clone())
    }

    /// Runs the remaining steps of the plan until done, failed or stopped through `stop`.
    /// Whatever happens (a panic inside the steps included), the teardown stops
    /// the table and waits until it reports rest (a further [`StopRequest::Emergency`]
    /// during that wait sends the emergency stop at once), returns the multimeter to local
    /// and leaves the manifest with a final status; the summary says which, and where the
    /// table was left. The fit is the caller's (see `gyrocal_analysis::sweep::fit_run`), so a failed fit
    /// never loses the data.
    pub async fn run(&mut self, mut stop: watch::Receiver<StopRequest>) -> RunSummary {
        use futures_util::FutureExt as _;
        self.origin = Instant::now();
        // the plan compiled for this session: what the teardown must bring to rest is known
        // before any instrument is asked anything
        let run = &self.sinks.run;
        self.program = compile_for(&self.plan, run);
        if let Some(done) = run.manifest().warmup.as_ref().filter(|w| w.complete)
            && self.plan.warmup().is_some()
        {
            tracing::info!(
                time_s = done.time_s,
                "warm-up completed in an earlier session: not repeated"
            );
        }
        self.live = self.sinks.live();
        let run_span = tracing::info_span!(
            "run",
            plan = %self.plan.name(),
            dir = %self.sinks.run.path().display()
        );
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
            // A panic in the steps (a bug) must not skip the teardown: it becomes an error
            // here, with the table driver still in hand to confirm rest.
            let steps =
                std::panic::AssertUnwindSafe(self.steps().instrument(run_span)).catch_unwind();
            tokio::select! {
                biased;
                req = wait_stop => Err(SequenceError::Stopped(req)),
                r = steps => r.unwrap_or_else(|panic| Err(SequenceError::Panicked(panic_text(&panic)))),
            }
        };
        match outcome {
            Ok(timing) => self.finish_ok(timing, &mut stop).await,
            Err(e) => {
                let emergency = matches!(e, SequenceError::Stopped(StopRequest::Emergency(_)))
                    || matches!(*stop.borrow(), StopRequest::Emergency(_));
                self.finish_err(e, emergency, &mut stop).await
            }
        }
    }

    /// Connects, sets up, and runs every step of the session; stops the table at the end.
    async fn steps(&mut self) -> Result<RunTiming, SequenceError> {
        self.sinks.begin(&Begin {
            offset_s: self.offset_s,
        })?;
        let reading_time = self.connect_and_configure().await?;
        let (setup, schedule_len, warmup_in_record, actions, recording) = {
            let p = &self.program;
            (
                p.setup,
                p.schedule_len,
                p.warmup_in_record,
                p.steps.clone(),
                p.recording().copied().collect::<Vec<Step>>(),
            )
        };
        self.set_up(setup).await?;

        let timing = self.meter_timing()?;
        let acquisition = timing.acquisition();
        let est: Estimate = estimate::estimate(&self.plan, &recording, 0.0, timing.as_ref());
        self.emit(Event::Planned {
            steps: recording.len(),
            done: self.sinks.run.done_steps().len(),
            estimate: est.total,
            acquisition,
        })?;
        tracing::info!(
            steps = recording.len(),
            estimate_s = est.total.as_secs_f64(),
            bound_s = est.bound.as_secs_f64(),
            acquisition,
            "starting the schedule"
        );

        let t0 = Instant::now();
        let table = self.plan.table();
        let ctx = StepContext {
            criteria: SettleCriteria {
                tolerance: table.rate_tolerance_dps,
                relative_tolerance: 0.0,
                window: table.stability_window,
                interval: self.options.sample_interval.min(table.stability_window / 4),
                timeout: table.at_rate_timeout,
            },
            accel: table.acceleration_dps2,
            reading_time,
        };
        // the live monitors of a record's segments
        let monitors = Monitors::new(
            schedule_len,
            warmup_in_record.as_ref(),
            reading_time.as_secs_f64(),
            self.now_s(),
        );
        self.sinks.others.insert(0, Box::new(monitors));

        let mut pending: Option<PendingFetch<<B::Meter as Multimeter>::Pending>> = None;
        // A refused step is measured again at once; the queue makes that (and the session's
        // step count) explicit.
        let mut queue: VecDeque<Action> = actions.into_iter().collect();
        let mut total = recording.len();
        let mut position = 0;
        while let Some(action) = queue.pop_front() {
            if let ChamberAction::Soak(soak) = action.chamber {
                // the table held at 0 °/s while the chamber moves (the previous step's
                // readings fetched meanwhile); a step whose readings the meter lost is
                // measured again before the chamber leaves its temperature
                self.table_action(&action, None, pending.take(), &ctx)
                    .await?;
                let lost = self.repeats.take_lost();
                if !lost.is_empty() {
                    queue.push_front(action);
                    for a in lost.into_iter().rev() {
                        queue.push_front(a);
                        total += 1;
                    }
                    continue;
                }
                let span =
                    tracing::info_span!("soak", point = soak.point, target_c = soak.setpoint_c);
                self.soak(&soak).instrument(span).await?;
                continue;
            }
            let Some(step) = action.step().copied() else {
                // a step that fills no row of the schedule (the warm-up)
                self.warm_up(&action, &ctx).await?;
                continue;
            };
            position += 1;
            // remaining: this step and every queued one, from the plan's estimate
            let cost = |s: &Step| {
                est.steps
                    .iter()
                    .find(|e| e.step.index == s.index)
                    .map_or(Duration::ZERO, |e| e.ramp + e.settle + e.acquire)
            };
            // the soaks still queued count too: hours of a series are spent in them
            let after = queue
                .iter()
                .filter_map(Action::step)
                .map(cost)
                .sum::<Duration>()
                + estimate::soaks_ahead(&queue, step.series.map_or(f64::NAN, |at| at.setpoint_c));
            self.emit(Event::StepStarted {
                step,
                number: step.index + 1,
                of: schedule_len,
                position,
                total,
                remaining: cost(&step) + after,
                after,
            })?;
            let last = queue.is_empty();
            let span = tracing::info_span!("step", index = step.index, rate_dps = step.rate_dps);
            let outcome = self
                .measure_step(&action, &step, pending.take(), last, &ctx)
                .instrument(span)
                .await?;
            self.log_table_retries(Some(step.index))?;
            for lost in self.repeats.take_lost() {
                queue.push_front(lost);
                total += 1;
            }
            match outcome {
                StepOutcome::Recorded => {}
                StepOutcome::Pending(p) => pending = Some(p),
                StepOutcome::Again { instrument, detail } => {
                    self.repeats.refused(&step, &detail)?;
                    self.log_retry(
                        Some(step.index),
                        instrument,
                        format!("step not recorded: {detail}; measuring it again"),
                    )?;
                    queue.push_front(action);
                    total += 1;
                }
            }
        }
        // park the table: the controlled stop; the wait for rest is the teardown, whatever
        // way the run ends
        self.bench.table().stop().await?;
        let elapsed = t0.elapsed();
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
            acquisition: Some(acquisition.into()),
        })
    }

    /// Both instruments identified, the run marked (or refused) as simulated, the meter
    /// configured; returns its time per reading.
    async fn connect_and_configure(&mut self) -> Result<Duration, SequenceError> {
        let dmm_identity = self.dmm_mut()?.connect().await.map_err(dmm_error)?;
        let dmm_id = dmm_identity.raw.clone();
        let t = self.bench.table().connect().await?;
        self.table_reached = true;
        let table_id = format!("{},{},{},{}", t.manufacturer, t.model, t.serial, t.version);
        // simulators say so in their serial field: a run's data are all simulated or all
        // measured, never both
        let prefix = gyrocal_files::rundir::SIMULATOR_SERIAL_PREFIX;
        let simulators = dmm_identity.serial.starts_with(prefix) || t.serial.starts_with(prefix);
        let run = &self.sinks.run;
        let recorded = !run.done_steps().is_empty();
        let mut mark_simulated = None;
        if simulators != run.manifest().simulated {
            if recorded {
                return Err(SequenceError::Mixed {
                    recorded_on: if run.manifest().simulated {
                        "a simulated bench"
                    } else {
                        "real instruments"
                    },
                    now: if simulators {
                        "simulators"
                    } else {
                        "real instruments"
                    },
                });
            }
            if simulators {
                mark_simulated = Some("the instruments identify as simulators (serial SIM...)");
            }
        }
        let connected = Connected {
            dmm: dmm_id.clone(),
            table: table_id.clone(),
            mark_simulated,
        };
        self.sinks.connected(&connected)?;
        if self.program.uses_chamber {
            // a series on a bench without a chamber is refused before anything moves
            let chamber = self.bench.chamber();
            if !chamber.present() {
                return Err(SequenceError::Chamber(Box::new(
                    gyrocal_chamber::ChamberError::State {
                        device: chamber.describe().to_string(),
                        what: "the plan is a temperature series and this bench has no chamber"
                            .into(),
                    },
                )));
            }
            let id = chamber.connect().await?;
            let text = format!("{} ({}) on {}", id.model, id.detail, chamber.describe());
            tracing::info!(chamber = %text, "chamber connected");
            self.sinks.run.set_chamber_identity(&text)?;
            self.log_chamber_retries(None)?;
        }
        self.emit(Event::Connected {
            dmm: dmm_id,
            table: table_id,
        })?;
        let dcv = estimate::dc_volts(&self.plan);
        let dmm = self.dmm_mut()?;
        dmm.configure(&dcv).await.map_err(dmm_error)?;
        Ok(self.meter_timing()?.reading_time())
    }

    fn meter_timing(&mut self) -> Result<Box<dyn gyrocal_meter::TimingModel>, SequenceError> {
        self.dmm_mut()?.timing().ok_or_else(|| dmm_error(NoTiming))
    }

    /// The run's [`Setup`], before its first step.
    async fn set_up(&mut self, setup: Setup) -> Result<(), SequenceError> {
        let table = self.bench.table();
        match setup {
            Setup::Nothing => {
                tracing::info!("no rate table in this plan: the record is taken without one");
            }
            Setup::RestThenServoOff => {
                // the table is brought to rest (mode OFF, a zero-rate hold with the servo
                // still on), then the servo is switched off the orderly way the controller
                // offers (ACL `:Interlock:Open`: an ABORT profile to zero, at rest already,
                // then servo off), and it is never enabled again; the driver knows the
                // interlock event is its own
                table.stop().await?;
                let deadline = table.stop_deadline(self.plan.table().max_rate_dps);
                table.wait_stopped(deadline).await?;
                table.emergency_stop().await?;
                let rest = table.wait_stopped(deadline).await?;
                tracing::info!(
                    rate_dps = rest.rate_dps,
                    "table at rest, servo off, for the record"
                );
            }
            Setup::EnableTable => table.enable().await?,
        }
        Ok(())
    }

    fn log_retry(
        &mut self,
        step: Option<usize>,
        instrument: &str,
        message: String,
    ) -> Result<(), SequenceError> {
        let retry = gyrocal_files::rundir::Retry {
            t_s: self.now_s(),
            step,
            instrument: instrument.into(),
            message,
        };
        tracing::warn!(step, instrument, message = %retry.message, "retry");
        self.emit(Event::Retry(retry))
    }

    /// The table driver's link retries (a lost or garbled reply asked again) go to the
    /// manifest like the meter's.
    fn log_table_retries(&mut self, step: Option<usize>) -> Result<(), SequenceError> {
        for note in self.bench.table().take_retries() {
            self.log_retry(step, "table", note)?;
        }
        Ok(())
    }

    fn dmm_mut(&mut self) -> Result<&mut B::Meter, SequenceError> {
        if self.meter_released {
            return Err(released());
        }
        Ok(self.bench.meter())
    }
}

/// Each settle sample to every live feed (see [`Engine::settle_observer`]).
fn settle_observer(live: Vec<LiveFn>) -> impl FnMut(SettleProgress) + Send + 'static {
    move |p| {
        for f in &live {
            f(Event::Settle(p));
        }
    }
}

fn released() -> SequenceError {
    SequenceError::Dmm(Box::new(Released))
}

/// The multimeter was used after the engine handed it back (a bug).
#[derive(Debug, thiserror::Error)]
#[error("multimeter already released")]
struct Released;

impl MeterError for Released {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Other
    }
}

/// The meter gave no timing model after its configuration (a bug in its driver).
#[derive(Debug, thiserror::Error)]
#[error("the multimeter has no timing model after its configuration")]
struct NoTiming;

impl MeterError for NoTiming {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Other
    }
}

/// The message of a caught panic.
fn panic_text(panic: &Box<dyn std::any::Any + Send>) -> String {
    panic
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".into())
}

/// `plan` compiled for a session on `run`: its remaining steps, the warm-up left out when an
/// earlier session completed it.
fn compile_for(plan: &Plan, run: &RunDir) -> Compiled {
    let warmup_done = run.manifest().warmup.as_ref().is_some_and(|w| w.complete);
    steps::compile(plan, &run.remaining_steps(), warmup_done)
}
