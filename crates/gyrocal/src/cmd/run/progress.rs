//! The progress display: the engine's events as lines (or a live bar on a terminal).

use super::*;

/// An indicatif display on a terminal; plain lines otherwise.
pub(super) async fn show_progress(mut rx: mpsc::UnboundedReceiver<Event>) {
    // the bar draws on stderr; with either stream redirected (a log file, CI), plain lines
    let tty = std::io::stdout().is_terminal() && std::io::stderr().is_terminal();
    let mut view = Progress::new(tty);
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
/// instruments' timing models that move within a step, the phase, and the step's latest
/// reading with its running mean and σ.
pub(super) struct Progress {
    tty: bool,
    bar: indicatif::ProgressBar,
    /// The session's estimated duration (the bar's length, ms).
    estimate: Duration,
    /// The current step: its label, when it started, its `remaining` and `after`.
    step: Option<(String, tokio::time::Instant, Duration, Duration)>,
    /// Steps started and not yet recorded (a memory-mode step is recorded during the next
    /// ramp), with the readings received so far: on a stop, these are discarded.
    open: Vec<(usize, String, usize)>,
    phase: String,
    /// The warm-up's end was said.
    warmup_reported: bool,
}

impl Progress {
    fn new(tty: bool) -> Self {
        let bar = indicatif::ProgressBar::hidden();
        if tty {
            bar.set_draw_target(indicatif::ProgressDrawTarget::stderr());
            bar.set_style(
                indicatif::ProgressStyle::with_template(
                    "{prefix:.bold} {elapsed_precise} [{bar:16}] {wide_msg}",
                )
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
                .progress_chars("=> "),
            );
        }
        Progress {
            tty,
            bar,
            estimate: Duration::ZERO,
            step: None,
            open: Vec::new(),
            phase: String::new(),
            warmup_reported: false,
        }
    }

    /// The time left in the run by the clock: the step's estimate counted down, never below
    /// what the later steps take.
    fn remaining(&self) -> Option<Duration> {
        let (_, started, remaining, after) = self.step.as_ref()?;
        Some(remaining.saturating_sub(started.elapsed()).max(*after))
    }

    fn redraw(&self) {
        let eta = match self.remaining() {
            Some(r) => {
                let done = self.estimate.saturating_sub(r);
                self.bar.set_position(done.as_millis() as u64);
                format!("ETA {}", short_hms(r.as_secs_f64()))
            }
            None => String::new(),
        };
        self.bar.set_message(format!("{eta} · {}", self.phase));
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
                self.line(format!(
                    "{steps} steps to run ({done} already done), acquisition {acquisition}, estimated {}",
                    hms(estimate.as_secs_f64())
                ));
            }
            Event::StepStarted {
                step,
                number,
                of,
                remaining,
                after,
                ..
            } => {
                let label = format!("step {number}/{of} {:+} °/s", step.rate_dps);
                self.step = Some((label.clone(), tokio::time::Instant::now(), remaining, after));
                self.open.push((step.index, label.clone(), 0));
                self.bar.set_prefix(label.clone());
                self.phase = "ramping".into();
                if !self.tty {
                    say!("{label} (ETA {})", hms(remaining.as_secs_f64()));
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
                let spread = std.map_or(String::new(), |s| format!(", σ {s:.1e}"));
                self.phase = format!("{done}/{total}: {latest} (mean {mean:.6}{spread})");
                if self.tty {
                    self.redraw();
                }
            }
            Event::StepDone(r) => {
                self.open.retain(|(index, ..)| *index != r.step);
                self.line(format!(
                    "  step {} done: {:+.4} °/s -> {:.6} V (σ {:.1e} V, n {}, overloads {})",
                    r.step + 1,
                    r.rate_dps,
                    r.volts,
                    r.volts_std.unwrap_or(f64::NAN),
                    r.n,
                    r.overloads
                ));
            }
            Event::Warmup(w) => {
                let tol = w
                    .tolerance_v
                    .map_or("not yet estimated".into(), |t| format!("{t:.1e} V"));
                let change = w.last_change_v.map_or("-".into(), |c| format!("{c:.1e} V"));
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
                readings,
                elapsed_s,
                adev_v,
            } => {
                let adev = adev_v
                    .iter()
                    .map(|(tau, s)| format!("{} s {s:.2e} V", significant3(*tau)))
                    .collect::<Vec<_>>()
                    .join(" · ");
                let left = self.remaining().map_or(String::new(), |r| {
                    format!(", about {} left", hms(r.as_secs_f64()))
                });
                self.line(format!(
                    "  record: segment {segment}/{of} at {}{left}, {readings} readings this session{}",
                    hms(elapsed_s),
                    if adev.is_empty() {
                        String::new()
                    } else {
                        format!("; running ADEV at τ {adev}")
                    }
                ));
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
                self.step = None;
                self.phase = "stopping the table".into();
                self.redraw();
                self.line(text);
            }
            Event::Rest(rest) => self.line(rest_text(&rest)),
        }
    }
}

/// A τ with three significant digits (`1.39`, `11.1`, `88.8`).
pub(super) fn significant3(v: f64) -> String {
    if v >= 100.0 {
        format!("{v:.0}")
    } else if v >= 10.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.2}")
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
