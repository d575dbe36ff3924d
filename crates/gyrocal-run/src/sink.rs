//! Where a run's results go: one trait every consumer implements, pushed to by the engine.
//!
//! Model: ripgrep's `crates/searcher/src/sink.rs` (`Sink`: begin / matched / finish, push
//! model, each call returning a `Result` so a consumer can stop the search). Here the engine
//! pushes:
//!
//! - [`Sink::begin`]: the run clock's origin, before any instrument is asked anything;
//! - [`Sink::connected`]: what answered;
//! - [`Sink::samples`] then [`Sink::recorded`]: a step's raw readings, then its row (only
//!   complete steps are recorded; see the run directory's contract);
//! - [`Sink::event`]: progress and notes (phases, retries, the warm-up's state, the end
//!   state of the table);
//! - [`Sink::checkpoint`]: the run clock at a durable point;
//! - [`Sink::finish`]: how the run ended.
//!
//! Consumers today: the run directory (the durable record, always first: `impl Sink for
//! RunDir`), the progress display ([`EventChannel`], today's [`Event`] channel) and the live
//! monitors ([`Monitors`]: the running Allan deviation and the warm-up watched in a record's
//! segments). A new consumer (a live web feed) is one more `impl Sink` handed to
//! [`crate::Engine::with_sink`]; the engine does not change.
//!
//! A consumer that fails (a full disk under the run directory) returns the error: the engine
//! ends the run the way it ends every failed run, with the table brought to rest, the meter
//! released and the run marked failed (exit 1).
//!
//! What a sink derives from a record (a monitor's running deviation, the warm-up's state) it
//! pushes to `derived`; the engine hands those events to every sink after the record, so the
//! run directory stores the warm-up a monitor computed and the display shows it.

use std::sync::Arc;

use gyrocal_files::plan::Step;
use gyrocal_files::steps::Record;

use crate::engine::Event;
use crate::monitor::{self, AdevWatch, WarmupWatch};
use gyrocal_files::plan::WarmupSettings;
use gyrocal_files::rundir::{Instruments, RunDir, RunError, Sample, Status, StepRecord, Timing};

/// A live feed: called from inside the instruments' callbacks (each table sample while the
/// engine waits for a rate, each reading the meter receives), so it must not block. Events
/// sent this way are progress only: nothing durable depends on them.
pub type LiveFn = Arc<dyn Fn(Event) + Send + Sync>;

/// Why a consumer could not take what the engine pushed.
#[derive(Debug, thiserror::Error)]
pub enum SinkError {
    /// The run directory could not be written (its own error says the file and the cause).
    #[error("run directory: {0}")]
    RunDir(#[from] RunError),
    /// Another consumer failed.
    #[error("{sink}: {message}")]
    Other {
        /// Which consumer (`web feed`, ...).
        sink: String,
        /// What went wrong.
        message: String,
    },
}

/// What kind of failure a [`SinkError`] is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SinkErrorKind {
    /// The run directory failed (see its own kind).
    RunDir,
    /// Another consumer failed.
    Other,
}

impl SinkError {
    /// What kind of failure this is.
    pub fn kind(&self) -> SinkErrorKind {
        match self {
            SinkError::RunDir(_) => SinkErrorKind::RunDir,
            SinkError::Other { .. } => SinkErrorKind::Other,
        }
    }
}

/// The start of a run.
#[derive(Debug, Clone, PartialEq)]
pub struct Begin {
    /// The run clock when this session starts (earlier sessions' elapsed time), s.
    pub offset_s: f64,
}

/// The instruments answered.
#[derive(Debug, Clone, PartialEq)]
pub struct Connected {
    /// The multimeter's `*IDN?`.
    pub dmm: String,
    /// The table's identity (`manufacturer,model,serial,version`).
    pub table: String,
    /// The instruments identify as simulators and the run was not marked simulated yet:
    /// why it must now be.
    pub mark_simulated: Option<&'static str>,
}

/// A step's result, complete: its readings are already pushed with [`Sink::samples`].
#[derive(Debug, Clone, Copy)]
pub struct Recorded<'a> {
    /// The schedule's step (its `index` is the run directory's `step`).
    pub step: &'a Step,
    /// How the step asked to be recorded (a row, or a segment the monitors watch).
    pub record: &'a Record,
    /// The row of `steps.csv`.
    pub row: &'a StepRecord,
    /// The valid readings, V (overloads left out).
    pub volts: &'a [f64],
    /// The run clock at the start and end of the acquisition, s.
    pub t_start: f64,
    /// See `t_start`.
    pub t_end: f64,
    /// The run clock now, s (the manifest's `elapsed_s`).
    pub elapsed_s: f64,
}

/// How the run ended.
#[derive(Debug, Clone, PartialEq)]
pub struct Finish {
    /// `complete`, `aborted` or `failed`.
    pub status: Status,
    /// Why, when not complete (or a note when complete).
    pub reason: Option<String>,
    /// The run clock at the end, s.
    pub elapsed_s: f64,
    /// The session's bound versus elapsed, when it completed.
    pub timing: Option<Timing>,
}

/// A consumer of what the engine produces. Every method has a default that ignores it, so a
/// consumer implements only what it wants.
pub trait Sink: Send {
    /// The run starts.
    fn begin(&mut self, _begin: &Begin) -> Result<(), SinkError> {
        Ok(())
    }
    /// The instruments answered.
    fn connected(&mut self, _connected: &Connected) -> Result<(), SinkError> {
        Ok(())
    }
    /// A step's raw readings (before its row).
    fn samples(&mut self, _step: &Step, _samples: &[Sample]) -> Result<(), SinkError> {
        Ok(())
    }
    /// A step recorded. Events derived from it go to `derived` (every sink receives them).
    fn recorded(
        &mut self,
        _recorded: &Recorded<'_>,
        _derived: &mut Vec<Event>,
    ) -> Result<(), SinkError> {
        Ok(())
    }
    /// A progress event or a note.
    fn event(&mut self, _event: &Event) -> Result<(), SinkError> {
        Ok(())
    }
    /// The run clock at a point where nothing else is recorded (a warm-up chunk, a soak's
    /// poll), s; as often as the caller likes (the run directory decides when to write it).
    fn checkpoint(&mut self, _elapsed_s: f64) -> Result<(), SinkError> {
        Ok(())
    }
    /// The run ended.
    fn finish(&mut self, _finish: &Finish) -> Result<(), SinkError> {
        Ok(())
    }
    /// A live feed for the events sent from inside the instruments' callbacks (settle
    /// samples, each reading); `None` (the default): the sink does not want them.
    fn live(&mut self) -> Option<LiveFn> {
        None
    }
}

/// The durable record: `samples.csv`, `steps.csv` and `manifest.json` (see
/// [`gyrocal_files::rundir`]).
impl Sink for RunDir {
    fn begin(&mut self, begin: &Begin) -> Result<(), SinkError> {
        // the run directory converts run-clock times into UTC from this instant
        self.anchor_clock(begin.offset_s);
        Ok(())
    }

    fn connected(&mut self, c: &Connected) -> Result<(), SinkError> {
        if let Some(why) = c.mark_simulated {
            self.mark_simulated(why)?;
        }
        self.set_instruments(Instruments {
            dmm: Some(c.dmm.clone()),
            table: Some(c.table.clone()),
        })?;
        Ok(())
    }

    fn samples(&mut self, step: &Step, samples: &[Sample]) -> Result<(), SinkError> {
        Ok(self.append_samples(step.index, samples)?)
    }

    fn recorded(&mut self, r: &Recorded<'_>, _: &mut Vec<Event>) -> Result<(), SinkError> {
        self.append_step(r.row.clone())?;
        self.set_elapsed(r.elapsed_s)?;
        // run.log: one line per durable step, so `tail -f run.log` follows the run
        tracing::info!("{}", recorded_line(r, self.schedule().len()));
        Ok(())
    }

    fn event(&mut self, event: &Event) -> Result<(), SinkError> {
        match event {
            Event::Retry(retry) => self.log_retry(retry.clone())?,
            Event::Warmup(w) => self.set_warmup(w.clone())?,
            _ => {}
        }
        Ok(())
    }

    fn checkpoint(&mut self, elapsed_s: f64) -> Result<(), SinkError> {
        // written to disk at most every few minutes of run clock (RunDir::checkpoint)
        RunDir::checkpoint(self, elapsed_s)?;
        Ok(())
    }

    fn finish(&mut self, f: &Finish) -> Result<(), SinkError> {
        if let Some(t) = &f.timing {
            self.set_timing(t.clone())?;
        }
        Ok(RunDir::finish(
            self,
            f.status,
            f.reason.clone(),
            f.elapsed_s,
        )?)
    }
}

/// The log's line for a recorded step: the plan's numbering (`step 4/19`, `segment 12/167`),
/// which is steps.csv's `step_no` (both count from 1), the file it went to, and its key
/// figures.
pub fn recorded_line(r: &Recorded<'_>, of: usize) -> String {
    let what = match r.record {
        Record::Segment(_) => "segment",
        Record::Row(_) | Record::Warmup | Record::Soak => "step",
    };
    let row = r.row;
    let spread = row.volts_std.map_or(String::new(), |s| {
        format!(", σ {} V", gyrocal_fit::display::significant(s, 3))
    });
    let overloads = if row.overloads > 0 {
        format!(", {} overloads", row.overloads)
    } else {
        String::new()
    };
    format!(
        "{what} {}/{of} recorded in steps.csv: {:+} °/s, mean {:.6} V{spread}, n {}{overloads}, run clock {:.1} s",
        row.step + 1,
        row.rate_dps,
        row.volts,
        row.n,
        r.t_end
    )
}

/// The progress display's feed: every event on an unbounded channel, so a display never
/// slows the run down (a display that went away is ignored).
#[derive(Debug, Clone)]
pub struct EventChannel(pub tokio::sync::mpsc::UnboundedSender<Event>);

impl Sink for EventChannel {
    fn event(&mut self, event: &Event) -> Result<(), SinkError> {
        let _ = self.0.send(event.clone());
        Ok(())
    }

    fn live(&mut self) -> Option<LiveFn> {
        let tx = self.0.clone();
        Some(Arc::new(move |e| {
            let _ = tx.send(e);
        }))
    }
}

/// The live monitors of a record's segments ([`Record::Segment`]): the running overlapping
/// Allan deviation ([`AdevWatch`], built at the first segment from its reading period) and,
/// while it lasts, a warm-up watched in the record ([`WarmupWatch`]). They derive
/// [`Event::Warmup`] (which the run directory stores) and [`Event::Drift`].
#[derive(Debug)]
pub struct Monitors {
    adev: Option<AdevWatch>,
    warmup: Option<WarmupWatch>,
    of: usize,
}

impl Monitors {
    /// Monitors for a schedule of `of` steps; `warmup`: a warm-up to watch in the segments,
    /// from run-clock `started_s`, readings every `period_s`.
    pub fn new(of: usize, warmup: Option<&WarmupSettings>, period_s: f64, started_s: f64) -> Self {
        Monitors {
            adev: None,
            warmup: warmup
                .map(|w| WarmupWatch::new(w, period_s, started_s, monitor::WARMUP_IN_RECORD)),
            of,
        }
    }
}

impl Sink for Monitors {
    fn recorded(&mut self, r: &Recorded<'_>, derived: &mut Vec<Event>) -> Result<(), SinkError> {
        if !matches!(r.record, Record::Segment(_)) {
            return Ok(());
        }
        let period = (r.t_end - r.t_start) / r.volts.len().max(1) as f64;
        let adev = self.adev.get_or_insert_with(|| AdevWatch::new(period));
        adev.push(r.volts);
        if let Some(w) = self.warmup.as_mut()
            && !w.is_complete()
        {
            w.push(r.volts, r.t_start, r.t_end);
            derived.push(Event::Warmup(w.record().clone()));
        }
        derived.push(Event::Drift {
            segment: r.step.index + 1,
            of: self.of,
            readings: adev.readings(),
            elapsed_s: r.t_end,
            adev_v: adev.shown(),
            adev_curve_v: adev.curve(),
        });
        Ok(())
    }
}

/// The engine's consumers: the run directory first (the durable record), then the others in
/// the order they were added.
pub(crate) struct Sinks {
    pub(crate) run: RunDir,
    pub(crate) others: Vec<Box<dyn Sink>>,
}

impl Sinks {
    fn each(
        &mut self,
        mut f: impl FnMut(&mut dyn Sink) -> Result<(), SinkError>,
    ) -> Result<(), SinkError> {
        f(&mut self.run)?;
        for s in &mut self.others {
            f(s.as_mut())?;
        }
        Ok(())
    }

    pub(crate) fn begin(&mut self, b: &Begin) -> Result<(), SinkError> {
        self.each(|s| s.begin(b))
    }

    pub(crate) fn connected(&mut self, c: &Connected) -> Result<(), SinkError> {
        self.each(|s| s.connected(c))
    }

    pub(crate) fn samples(&mut self, step: &Step, samples: &[Sample]) -> Result<(), SinkError> {
        self.each(|s| s.samples(step, samples))
    }

    /// The record to every sink, then `after` (the engine's own event for it) and what the
    /// sinks derived, in that order, to every sink.
    pub(crate) fn recorded(&mut self, r: &Recorded<'_>, after: Event) -> Result<(), SinkError> {
        let mut derived = Vec::new();
        self.each(|s| s.recorded(r, &mut derived))?;
        self.event(&after)?;
        for e in &derived {
            self.event(e)?;
        }
        Ok(())
    }

    pub(crate) fn event(&mut self, e: &Event) -> Result<(), SinkError> {
        self.each(|s| s.event(e))
    }

    pub(crate) fn checkpoint(&mut self, t: f64) -> Result<(), SinkError> {
        self.each(|s| s.checkpoint(t))
    }

    /// Every sink hears the end, even after one failed; the first error is returned.
    pub(crate) fn finish(&mut self, f: &Finish) -> Result<(), SinkError> {
        let mut first = None;
        let _ = self.each(|s| {
            if let Err(e) = s.finish(f) {
                tracing::error!(error = %e, "a consumer could not take the end of the run");
                first.get_or_insert(e);
            }
            Ok(())
        });
        first.map_or(Ok(()), Err)
    }

    pub(crate) fn live(&mut self) -> Vec<LiveFn> {
        let mut out: Vec<LiveFn> = Vec::new();
        if let Some(l) = self.run.live() {
            out.push(l);
        }
        out.extend(self.others.iter_mut().filter_map(|s| s.live()));
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gyrocal_files::plan::Acquire;
    use std::time::Duration;

    fn row(step: &Step) -> StepRecord {
        StepRecord {
            step: step.index,
            pass: 0,
            rate_dps: 0.0,
            rate_meas_dps: None,
            rate_meas_std_dps: None,
            rate_meas_min_dps: None,
            rate_meas_max_dps: None,
            rate_samples: None,
            volts: 0.0,
            volts_std: None,
            n: 100,
            overloads: 0,
            retries: 0,
            t_start_s: 0.0,
            t_end_s: 10.0,
            series: None,
        }
    }

    #[test]
    fn the_monitors_watch_segments_only_and_derive_the_warm_up_and_the_running_deviation() {
        let settings = WarmupSettings {
            window: Duration::from_secs(1),
            tolerance_v: Some(1.0),
            max: Duration::from_secs(600),
        };
        let mut m = Monitors::new(5, Some(&settings), 0.1, 0.0);
        let step = Step {
            index: 2,
            pass: 0,
            rate_dps: 0.0,
            acquire: Acquire::Samples(100),
            series: None,
        };
        let volts: Vec<f64> = (0..100).map(|i| f64::from(i % 7) * 1e-6).collect();
        let r = row(&step);
        let mut derived = Vec::new();
        // a sweep's row: nothing to watch
        let as_row = Record::Row(step);
        let rec = Recorded {
            step: &step,
            record: &as_row,
            row: &r,
            volts: &volts,
            t_start: 0.0,
            t_end: 10.0,
            elapsed_s: 10.0,
        };
        m.recorded(&rec, &mut derived).unwrap();
        assert!(derived.is_empty());
        // a segment: the warm-up's state (for the manifest) and the running deviation
        let as_segment = Record::Segment(step);
        let rec = Recorded {
            record: &as_segment,
            ..rec
        };
        m.recorded(&rec, &mut derived).unwrap();
        assert!(matches!(&derived[0], Event::Warmup(w) if w.mode == monitor::WARMUP_IN_RECORD));
        assert!(
            matches!(&derived[1], Event::Drift { segment: 3, of: 5, readings: 100, elapsed_s, .. } if *elapsed_s == 10.0),
            "{:?}",
            derived[1]
        );
    }
}
