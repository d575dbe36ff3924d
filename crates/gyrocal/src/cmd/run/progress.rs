//! The progress display: the engine's events as lines (or a live bar on a terminal).
//!
//! Every time it shows is on the run clock (see [`super::clock`]), said once when the schedule
//! starts. A sweep prints a line when a step starts and one when it is recorded (19 to 40
//! steps); a drift record, whose segments come every minute for hours, prints one short line
//! at most every [`DRIFT_LINE_EVERY`] of run clock: the segment, the time left, the bias and
//! the running Allan deviation in °/h when the scale factor is known (in volts, said once,
//! when it is not). Every line fits 100 columns.

use super::*;
use gyrocal_fit::display::significant;

/// A drift record prints at most one progress line per this much run clock (a few a minute).
pub(super) const DRIFT_LINE_EVERY: Duration = Duration::from_secs(20);

/// What the display knows about the run besides its events.
#[derive(Debug, Clone, Default)]
pub(super) struct ViewContext {
    /// A drift record (its steps are segments of one record).
    pub(super) drift: bool,
    /// The scale factor that converts the record's volts to a rate, V/(°/s), and where it
    /// comes from (as the Allan analysis finds it: a simulated gyro's); `None`: volts.
    pub(super) scale: Option<(f64, &'static str)>,
    /// The Earth's rate along the input axis, °/h ([drift] axis and latitude), removed from
    /// the bias as the analysis does.
    pub(super) earth_dph: Option<f64>,
}

impl ViewContext {
    /// The display's context for `plan` written to `run`.
    pub(super) fn of(plan: &Plan, run: &RunDir) -> ViewContext {
        let drift = plan.kind() == gyrocal_files::PlanKind::Drift;
        let k = plan.simulation().scale_factor;
        ViewContext {
            drift,
            // the analysis of a simulated record converts with the simulated gyro's K
            scale: (run.manifest().simulated && k.is_finite() && k != 0.0)
                .then_some((k, "the simulated gyro's")),
            earth_dph: plan
                .drift()
                .earth
                .map(|(axis, latitude)| axis.earth_rate_dph(latitude)),
        }
    }
}

/// An indicatif display on a terminal; plain lines otherwise.
pub(super) async fn show_progress(mut rx: mpsc::UnboundedReceiver<Event>, cx: ViewContext) {
    // the bar draws on stderr; with either stream redirected (a log file, CI), plain lines
    let tty = std::io::stdout().is_terminal() && std::io::stderr().is_terminal();
    let mut view = Progress::new(tty, cx);
    // the ETA and the bar count down between events too
    let mut tick = tokio::time::interval(Duration::from_secs(1));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            e = rx.recv() => match e {
                Some(e) => {
                    if matches!(e, Event::StepDone(_)) {
                        catalog_note(|w, dir| w.step_done(dir));
                    }
                    view.event(e)
                }
                None => break,
            },
            _ = tick.tick(), if tty => view.redraw(),
        }
    }
    view.bar.finish_and_clear();
}

/// The live view of a run: one line per step and event (or a bar on a terminal, which fits
/// 80 columns: the message is cut, not wrapped), a time-based bar and ETA from the
/// instruments' timing models at the pace the run keeps, that move within a step, the phase,
/// and the step's latest reading with its running mean and σ.
pub(super) struct Progress {
    tty: bool,
    cx: ViewContext,
    bar: indicatif::ProgressBar,
    /// The session's estimated duration (the bar's length, ms).
    estimate: Duration,
    /// The time left (the schedule at the observed pace).
    eta: Eta,
    /// The run clock at the display's start (the session's offset) and when that was.
    origin: (f64, tokio::time::Instant),
    /// Steps started and not yet recorded (a memory-mode step is recorded during the next
    /// ramp), with the readings received so far: on a stop, these are discarded.
    open: Vec<(usize, String, usize)>,
    phase: String,
    /// The warm-up's end was said.
    warmup_reported: bool,
    /// A drift record's display: the bias so far, its last line.
    record: RecordView,
    /// A soak's last line without a terminal: the temperature's index and the run clock, s.
    soak_line: Option<(u32, f64)>,
}

/// What a drift record's display accumulates between its lines.
#[derive(Debug, Default)]
struct RecordView {
    /// Σ volts·n and Σ n of this session's segments (the mean output).
    sum_v: f64,
    count: u64,
    /// Overloads since the last line.
    overloads: u64,
    /// The run clock of the last line, s.
    last_line_s: Option<f64>,
}

impl Progress {
    fn new(tty: bool, cx: ViewContext) -> Self {
        let bar = indicatif::ProgressBar::hidden();
        if tty {
            bar.set_draw_target(indicatif::ProgressDrawTarget::stderr());
            // no wall-clock elapsed beside a run-clock ETA: the message says the run clock
            bar.set_style(
                indicatif::ProgressStyle::with_template("{prefix:.bold} [{bar:16}] {wide_msg}")
                    .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
                    .progress_chars("=> "),
            );
        }
        let offset = SESSION.get().map_or(0.0, |s| s.offset_s);
        Progress {
            tty,
            cx,
            bar,
            estimate: Duration::ZERO,
            eta: Eta::default(),
            origin: (offset, tokio::time::Instant::now()),
            open: Vec::new(),
            phase: String::new(),
            warmup_reported: false,
            record: RecordView::default(),
            soak_line: None,
        }
    }

    /// The time left in the run on the run clock: the schedule at the pace the run keeps.
    fn remaining(&self) -> Option<Duration> {
        self.eta.remaining()
    }

    /// The run clock now, s.
    fn run_clock(&self) -> f64 {
        self.origin.0 + self.origin.1.elapsed().as_secs_f64()
    }

    fn redraw(&self) {
        // on the run clock, as the line before the schedule says (80 columns: no room for
        // the words here)
        let clock = format!("at {}", short_hms(self.run_clock()));
        let eta = match self.remaining() {
            Some(r) => {
                let done = self.estimate.saturating_sub(r);
                self.bar.set_position(done.as_millis() as u64);
                format!(", {} left", short_hms(r.as_secs_f64()))
            }
            None => String::new(),
        };
        self.bar
            .set_message(format!("{clock}{eta} · {}", self.phase));
    }

    /// What a step of this plan is called: a drift record's steps are its segments.
    fn noun(&self) -> &'static str {
        if self.cx.drift { "segment" } else { "step" }
    }

    fn line(&self, text: String) {
        line(self.tty, &self.bar, text);
    }

    fn event(&mut self, e: Event) {
        match e {
            Event::Connected { dmm, table } => {
                self.line(format!("multimeter: {dmm}\nrate table: {table}"))
            }
            Event::Planned {
                steps,
                done,
                estimate,
                acquisition,
            } => {
                self.estimate = estimate;
                self.bar.set_length(estimate.as_millis().max(1) as u64);
                let noun = self.noun();
                self.line(format!(
                    "{steps} {noun}s to run ({done} already done), acquisition {acquisition}, estimated {}",
                    hms(estimate.as_secs_f64())
                ));
                if let Some(s) = SESSION.get() {
                    self.line(s.words());
                }
                if self.cx.drift {
                    let header = self.drift_header();
                    self.line(header);
                }
            }
            Event::StepStarted {
                step,
                number,
                of,
                remaining,
                after,
                ..
            } => {
                let label = if self.cx.drift {
                    format!("segment {number}/{of}")
                } else {
                    format!("step {number}/{of} {:+} °/s", step.rate_dps)
                };
                self.eta.start(remaining, after);
                self.open.push((step.index, label.clone(), 0));
                self.bar.set_prefix(label.clone());
                self.phase = "ramping".into();
                // a sweep's step is a line; a record's segments are summed up every 20 s
                if !self.tty && !self.cx.drift {
                    let left = self.remaining().unwrap_or(remaining);
                    say!(
                        "{label} ({} left on the run clock)",
                        short_hms(left.as_secs_f64())
                    );
                }
                self.redraw();
            }
            Event::Settle(p) => {
                self.phase = if p.ramping {
                    format!("ramping ({:+.3} °/s)", p.rate)
                } else {
                    format!(
                        "waiting for at-rate ({:.1} s stable of {:.1} s)",
                        p.stable_for.as_secs_f64(),
                        p.window.as_secs_f64()
                    )
                };
                self.redraw();
            }
            Event::Phase { phase, .. } => {
                self.phase = match phase {
                    Phase::Ramping => "ramping",
                    Phase::Settling => "settling",
                    Phase::Acquiring => "acquiring",
                    Phase::Fetching => "fetching readings",
                }
                .into();
                self.redraw();
            }
            Event::Acquiring {
                done,
                total,
                latest,
                mean,
                std,
            } => {
                if let Some(open) = self.open.last_mut() {
                    open.2 = done;
                }
                let latest = latest.map_or("overload".into(), |v| format!("{v:.6} V"));
                let spread = std.map_or(String::new(), |s| format!(", σ {}", significant(s, 2)));
                self.phase = format!("{done}/{total}: {latest} (mean {mean:.6}{spread})");
                if self.tty {
                    self.redraw();
                }
            }
            Event::StepDone(r) => {
                self.open.retain(|(index, ..)| *index != r.step);
                if self.cx.drift {
                    // summed up in the record's next line
                    self.record.sum_v += r.volts * r.n as f64;
                    self.record.count += r.n;
                    self.record.overloads += r.overloads;
                    return;
                }
                let spread = r
                    .volts_std
                    .map_or(String::new(), |s| format!("σ {} V, ", significant(s, 2)));
                let overloads = if r.overloads > 0 {
                    format!(", {} overloads", r.overloads)
                } else {
                    String::new()
                };
                self.line(format!(
                    "  step {} done: {:+.4} °/s -> {:.6} V ({spread}n {}{overloads})",
                    r.step + 1,
                    r.rate_dps,
                    r.volts,
                    r.n,
                ));
            }
            Event::Warmup(w) => {
                let tol = w.tolerance_v.map_or("not yet estimated".into(), |t| {
                    format!("{} V", significant(t, 2))
                });
                let change = w
                    .last_change_v
                    .map_or("-".into(), |c| format!("{} V", significant(c, 2)));
                if !w.complete {
                    self.phase = format!(
                        "warm-up: window means change {change} (settled below {tol}), at most {}",
                        hms(w.max_s)
                    );
                    if self.tty {
                        self.redraw();
                    } else if w.mode == gyrocal_run::monitor::WARMUP_BEFORE_SWEEP {
                        say!("  {}", self.phase);
                    }
                } else if !self.warmup_reported {
                    self.warmup_reported = true;
                    let time = hms(w.time_s.unwrap_or(0.0));
                    self.line(if w.ended_by.as_deref() == Some("max") {
                        format!(
                            "warm-up ended at its maximum ({time}) WITHOUT settling: the last window means changed by {change} (settled below {tol})"
                        )
                    } else {
                        format!(
                            "warm-up complete after {time}: consecutive {:.1} s window means agree within {tol}",
                            w.window_s
                        )
                    });
                }
            }
            Event::Drift {
                segment,
                of,
                elapsed_s,
                adev_v,
                ..
            } => {
                // at most one line per DRIFT_LINE_EVERY of run clock, and the last segment's
                let every = DRIFT_LINE_EVERY.as_secs_f64();
                let due = self
                    .record
                    .last_line_s
                    .is_none_or(|t| elapsed_s - t >= every - 1e-9);
                if !due && segment < of {
                    return;
                }
                self.record.last_line_s = Some(elapsed_s);
                let left = self.remaining().filter(|_| segment < of);
                let text = self.drift_line(segment, of, elapsed_s, left, &adev_v);
                self.record.overloads = 0;
                self.line(text);
            }
            Event::Retry(r) => self.line(format!("  retry ({}): {}", r.instrument, r.message)),
            Event::Stopping {
                from_dps,
                emergency,
                deadline,
            } => {
                for (_, label, readings) in std::mem::take(&mut self.open) {
                    self.line(format!(
                        "{label}: not recorded ({readings} reading(s) discarded); it is measured \
                         again when the run is resumed"
                    ));
                }
                let how = if emergency {
                    "emergency stop sent"
                } else {
                    "controlled stop sent"
                };
                let text = match from_dps {
                    Some(r) if r.abs() > 1e-3 => format!(
                        "{how}: table decelerating from {r:+.3} °/s … (waiting up to {} for rest)",
                        hms(deadline.as_secs_f64())
                    ),
                    Some(r) => format!("{how}: table measured at {r:+.4} °/s, confirming rest …"),
                    None => format!(
                        "{how}: no rate measured (the table did not answer in time); waiting up \
                         to {} for rest …",
                        hms(deadline.as_secs_f64())
                    ),
                };
                self.eta.stop();
                self.phase = "stopping the table".into();
                self.redraw();
                self.line(text);
            }
            Event::Rest(rest) => self.line(rest_text(&rest)),
            // a temperature series' soak: the phase says where the chamber and the gyro are
            Event::Soak {
                point,
                target_c,
                setpoint_c,
                air_c,
                gyro_c,
                held,
                soak,
                waited,
            } => {
                self.eta.interlude();
                let gyro = gyro_c.map_or("no gyro sensor".into(), |t| format!("gyro {t:.2} °C"));
                let state = match held {
                    Some(h) => format!(
                        "soaked for {} of {}",
                        hms(h.as_secs_f64()),
                        hms(soak.as_secs_f64())
                    ),
                    None if setpoint_c != target_c => {
                        format!("ramping, setpoint {setpoint_c:.2} °C")
                    }
                    None => "waiting for the gyro to settle".into(),
                };
                self.phase = format!(
                    "temperature {} ({target_c} °C): {state}; air {air_c:.2} °C, {gyro}; {} so far",
                    point + 1,
                    hms(waited.as_secs_f64())
                );
                // without a terminal to redraw, a line when a soak starts and every
                // SOAK_LINE_EVERY of run clock: a log of a day-long series shows it alive
                if !self.tty {
                    let now = self.run_clock();
                    let due = match self.soak_line {
                        Some((p, at)) => p != point || now - at >= SOAK_LINE_EVERY.as_secs_f64(),
                        None => true,
                    };
                    if due {
                        self.soak_line = Some((point, now));
                        say!("  soak: {}", self.phase);
                    }
                }
                self.redraw();
            }
        }
    }
}

/// How often a soak prints its state without a terminal, on the run clock.
const SOAK_LINE_EVERY: Duration = Duration::from_secs(600);

impl Progress {
    /// The lines that open a drift record's display: how often it prints, what, in which
    /// unit (said once).
    fn drift_header(&self) -> String {
        let every = DRIFT_LINE_EVERY.as_secs();
        let unit = match (self.cx.scale, self.cx.earth_dph) {
            (Some((k, source)), Some(e)) => format!(
                "  in °/h with K = {k} V/(°/s), {source}; the bias without the Earth's {e:.2} °/h"
            ),
            (Some((k, source)), None) => format!("  in °/h with K = {k} V/(°/s), {source}"),
            (None, _) => {
                "  the mean in V, the ADEV in µV: no scale factor is known during the run \
                 (`gyrocal allan RUN --scale-factor K` gives °/h)"
                    .to_string()
            }
        };
        let what = if self.cx.scale.is_some() {
            "bias"
        } else {
            "mean"
        };
        format!(
            "record: a line every {every} s of run clock with the {what} and the running ADEV at \
             τ near 1, 10, 100 s\n{unit}"
        )
    }

    /// A drift record's progress line (under 100 columns).
    fn drift_line(
        &self,
        segment: usize,
        of: usize,
        elapsed_s: f64,
        left: Option<Duration>,
        adev_v: &[(f64, f64)],
    ) -> String {
        drift_line(
            &self.cx,
            segment,
            of,
            elapsed_s,
            left,
            (self.record.count > 0).then(|| self.record.sum_v / self.record.count as f64),
            adev_v,
            self.record.overloads,
        )
    }
}

/// `segment 12/167 at 13:05, 2:48:10 left · bias +10.6 · ADEV 1.4 s 0.31, 11 s 0.10, 89 s
/// 0.040 °/h`: the run clock, the time left, the bias (or the mean output in volts) and the
/// running deviation at the τ the monitor shows, two significant digits, the unit once at the
/// end (the header says it too). Under 100 columns: should a line grow longer (an overload
/// count, a bias of thousands), the shortest τ goes first.
#[allow(clippy::too_many_arguments)]
pub(super) fn drift_line(
    cx: &ViewContext,
    segment: usize,
    of: usize,
    elapsed_s: f64,
    left: Option<Duration>,
    mean_v: Option<f64>,
    adev_v: &[(f64, f64)],
    overloads: u64,
) -> String {
    let mut head = format!("segment {segment}/{of} at {}", short_hms(elapsed_s));
    if let Some(left) = left {
        head.push_str(&format!(", {} left", short_hms(left.as_secs_f64())));
    }
    // volts to °/h: V / K is °/s
    let to_dph = cx.scale.map(|(k, _)| 3600.0 / k);
    match (mean_v, to_dph) {
        (Some(v), Some(f)) => {
            let bias = v * f - cx.earth_dph.unwrap_or(0.0);
            head.push_str(&format!(" · bias {}", signed3(bias)));
        }
        (Some(v), None) => head.push_str(&format!(" · mean {v:.6} V")),
        _ => {}
    }
    // in volts the deviations are µV: two digits stay short
    let (factor, unit) = match to_dph {
        Some(f) => (f, "°/h"),
        None => (1e6, "µV"),
    };
    let tail = if overloads > 0 {
        format!(" · {overloads} overloads")
    } else {
        String::new()
    };
    let mut terms: Vec<String> = adev_v
        .iter()
        .map(|&(tau, sigma)| format!("{} s {}", sig2(tau), sig2(sigma * factor)))
        .collect();
    loop {
        let line = if terms.is_empty() {
            let unit = if to_dph.is_some() && mean_v.is_some() {
                " °/h"
            } else {
                ""
            };
            format!("{head}{unit}{tail}")
        } else {
            format!("{head} · ADEV {} {unit}{tail}", terms.join(", "))
        };
        if line.chars().count() < 100 || terms.is_empty() {
            return line;
        }
        terms.remove(0);
    }
}

/// Two significant digits (`0.31`, `1.4`, `89`, `1.2 × 10⁻⁵`: no e-notation, as every figure
/// gyrocal prints).
pub(super) fn sig2(v: f64) -> String {
    let a = v.abs();
    if !v.is_finite() {
        "?".into()
    } else if a == 0.0 {
        "0".into()
    } else if !(1e-3..1e4).contains(&a) {
        significant(v, 2)
    } else {
        let decimals = (1.0 - a.log10().floor()).max(0.0) as usize;
        format!("{v:.decimals$}")
    }
}

/// Three significant digits with a sign (`+10.6`, `-0.512`, `+213`).
pub(super) fn signed3(v: f64) -> String {
    let a = v.abs();
    if !v.is_finite() {
        "?".into()
    } else if a == 0.0 {
        "0".into()
    } else if !(1e-3..1e5).contains(&a) {
        let s = significant(v, 3);
        if v > 0.0 { format!("+{s}") } else { s }
    } else {
        let decimals = (2.0 - a.log10().floor()).max(0.0) as usize;
        format!("{v:+.decimals$}")
    }
}

/// `1:02:03` or `2:03` (a countdown that fits a narrow line).
pub(super) fn short_hms(s: f64) -> String {
    let s = s.max(0.0).round() as u64;
    let (h, m, sec) = (s / 3600, (s / 60) % 60, s % 60);
    if h > 0 {
        format!("{h}:{m:02}:{sec:02}")
    } else {
        format!("{m}:{sec:02}")
    }
}

/// The operator's line about the table at the end of a run: "at rest" only when the table
/// said so.
pub(super) fn rest_text(rest: &TableRest) -> String {
    match rest {
        TableRest::AtRest { rate_dps, waited } => format!(
            "table at rest ({rate_dps:+.4} °/s, mode OFF, after {:.1} s)",
            waited.as_secs_f64()
        ),
        TableRest::NotConfirmed { reason } => {
            format!("the table could NOT be confirmed at rest: stop it by hand ({reason})")
        }
        TableRest::NeverReached { reason } => {
            format!("the table could NOT be confirmed at rest: {reason}; check it is not turning")
        }
        TableRest::NoTable => "no rate table in this plan: nothing was moved".into(),
    }
}

pub(super) fn line(tty: bool, bar: &indicatif::ProgressBar, text: String) {
    if tty {
        bar.println(text);
    } else {
        say!("{text}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cx(scale: bool) -> ViewContext {
        ViewContext {
            drift: true,
            // 0.36 V/(°/s): 1 mV is 10 °/h
            scale: scale.then_some((0.36, "the simulated gyro's")),
            earth_dph: Some(10.64),
        }
    }

    /// The longest line a record prints fits 100 columns, in °/h and in volts.
    #[test]
    fn a_record_line_fits_100_columns() {
        // 0.31, 0.10 and 0.040 °/h (31, 10 and 4.0 µV) at τ 1.39, 11.1 and 88.8 s
        let adev = [(1.39, 3.1e-5), (11.1, 1.0e-5), (88.8, 4.0e-6)];
        let left = Some(Duration::from_secs(2 * 3600 + 48 * 60 + 10));
        for scale in [true, false] {
            let l = drift_line(
                &cx(scale),
                166,
                167,
                10_805.0,
                left,
                Some(-1.2345e-3),
                &adev,
                0,
            );
            assert!(
                l.chars().count() < 100,
                "{} columns: {l}",
                l.chars().count()
            );
        }
        let l = drift_line(&cx(true), 12, 167, 785.0, left, Some(1.066e-3), &adev, 0);
        assert_eq!(
            l,
            "segment 12/167 at 13:05, 2:48:10 left · bias +0.0200 · ADEV 1.4 s 0.31, 11 s 0.10, \
             89 s 0.040 °/h"
        );
        // in volts, the deviations in µV
        let l = drift_line(&cx(false), 12, 167, 785.0, None, Some(1.066e-3), &adev, 0);
        assert_eq!(
            l,
            "segment 12/167 at 13:05 · mean 0.001066 V · ADEV 1.4 s 31, 11 s 10, 89 s 4.0 µV"
        );
        // a line that would be longer loses its shortest τ first (a bias of 3589 °/h, small
        // deviations with more digits)
        let small = [(1.39, 2.2e-6), (11.1, 7.1e-7), (88.8, 3.3e-7)];
        let l = drift_line(&cx(true), 166, 167, 10_805.0, left, Some(0.36), &small, 0);
        assert!(l.chars().count() < 100, "{l}");
        assert!(
            l.ends_with("bias +3589 · ADEV 11 s 0.0071, 89 s 0.0033 °/h"),
            "{l}"
        );
        let l = drift_line(&cx(true), 166, 167, 10_805.0, left, Some(0.36), &small, 7);
        assert!(
            l.chars().count() < 100 && l.ends_with(" · 7 overloads"),
            "{l}"
        );
    }

    #[test]
    fn figures_have_their_significant_digits() {
        assert_eq!(sig2(0.3123), "0.31");
        assert_eq!(sig2(1.39), "1.4");
        assert_eq!(sig2(88.8), "89");
        assert_eq!(sig2(2.2e-6), "2.2 × 10⁻⁶");
        assert_eq!(signed3(10.64), "+10.6");
        assert_eq!(signed3(-0.5123), "-0.512");
    }
}
