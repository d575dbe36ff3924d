//! One clock, said: which figure of a run is on the run clock and which on the wall clock, an
//! ETA that follows the pace the run actually keeps, and the closing timing line of a session
//! (this session told apart from the whole run; no ratio to the physical bound that physics
//! forbids).
//!
//! The run clock is the engine's (`t_s` in the files, `elapsed_s` in the manifest): on real
//! instruments it is the wall clock; with `--simulate` it is the simulated bench's virtual
//! clock, which runs as fast as the computer allows (or at `--sim-time-scale X` simulated
//! seconds per real second). Every time the display prints is on the run clock and says so
//! once; the ending adds the wall time the session took when the two differ.

use std::sync::OnceLock;
use std::time::Duration;

use gyrocal_files::rundir::Timing;

use super::*;

/// What this session of the run is, on which clock: set when the run directory is open.
#[derive(Debug, Clone)]
pub(super) struct SessionClock {
    /// The run clock when this session started (earlier sessions' elapsed time), s.
    pub(super) offset_s: f64,
    /// Sessions of the run so far, this one included (1 + the manifest's resumes).
    pub(super) sessions: usize,
    /// The run clock is the simulated bench's virtual clock.
    pub(super) virtual_time: bool,
    /// `--sim-time-scale`: simulated seconds per real second (`None`: as fast as possible).
    pub(super) pace: Option<f64>,
    /// When the session's run directory was opened, on the wall clock.
    pub(super) wall_start: std::time::Instant,
}

/// This process's session (one run per process, like [`CATALOG`]).
pub(super) static SESSION: OnceLock<SessionClock> = OnceLock::new();

impl SessionClock {
    /// Notes the session of `run` (just opened or resumed).
    pub(super) fn note(run: &RunDir, args: &RunArgs) {
        let m = run.manifest();
        let _ = SESSION.set(SessionClock {
            offset_s: m.elapsed_s,
            sessions: 1 + m.resumes.len(),
            virtual_time: args.simulate,
            pace: args.sim_time_scale,
            wall_start: std::time::Instant::now(),
        });
    }

    /// What the run clock is, in words, for the line that opens the schedule.
    pub(super) fn words(&self) -> String {
        match (self.virtual_time, self.pace) {
            (false, _) => "times are on the run clock, which is the wall clock".into(),
            (true, None) => {
                "times are on the run clock: the simulated bench's virtual time, not the wall clock"
                    .into()
            }
            (true, Some(x)) => format!(
                "times are on the run clock: the simulated bench's virtual time, at {x} s a second"
            ),
        }
    }
}

/// The time left in a run, from the plan's schedule (the instruments' timing models) scaled by
/// the pace the run keeps: the run clock the finished steps took over what the schedule gave
/// them. A simulator sped up with `gyrocal sim --time-scale` (the run's clock is the wall
/// clock, the instruments' is faster) gets an ETA that shrinks with it instead of counting
/// the physical schedule down.
#[derive(Debug, Default)]
pub(super) struct Eta {
    /// The current step: when it started (run clock), its own estimate, what the later steps
    /// take.
    current: Option<(tokio::time::Instant, Duration, Duration)>,
    /// The estimates of the steps finished so far, and the run clock they took.
    estimated: Duration,
    took: Duration,
}

impl Eta {
    /// A step starts: `remaining` is the schedule's time to the end from its start, `after`
    /// what follows it. The step before it is finished.
    pub(super) fn start(&mut self, remaining: Duration, after: Duration) {
        let now = tokio::time::Instant::now();
        if let Some((started, own, _)) = self.current.take() {
            self.estimated += own;
            self.took += now.saturating_duration_since(started);
        }
        self.current = Some((now, remaining.saturating_sub(after), after));
    }

    /// The run clock per second of schedule so far (1 until a step has finished; bounded to
    /// 1/1000..1000 so a step of no estimated time cannot blow it up).
    pub(super) fn pace(&self) -> f64 {
        if self.estimated < Duration::from_millis(100) {
            return 1.0;
        }
        (self.took.as_secs_f64() / self.estimated.as_secs_f64()).clamp(1e-3, 1e3)
    }

    /// The time left: the current step's estimate at the observed pace counted down on the
    /// run clock (never below zero), plus the later steps at that pace.
    pub(super) fn remaining(&self) -> Option<Duration> {
        let (started, own, after) = self.current?;
        let pace = self.pace();
        let in_step = tokio::time::Instant::now().saturating_duration_since(started);
        Some(own.mul_f64(pace).saturating_sub(in_step) + after.mul_f64(pace))
    }

    /// Something that is not a step runs (a temperature series' soak): the step before it
    /// is finished, and the time until the next step starts is not counted in the pace. A
    /// soak lasts as long as the gyro takes to reach its temperature, not as long as the
    /// instruments' links take; counted, one soak of 2 h after a step estimated at 1 min set
    /// the pace to the clamp and the time left to a thousand hours.
    pub(super) fn interlude(&mut self) {
        if let Some((started, own, _)) = self.current.take() {
            self.estimated += own;
            self.took += tokio::time::Instant::now().saturating_duration_since(started);
        }
    }

    /// No step is running (the run is stopping).
    pub(super) fn stop(&mut self) {
        self.current = None;
    }
}

/// The closing timing lines of a complete session: the schedule against the physical bound
/// (this session's, labelled so after a resume), the wall time when the run clock was
/// virtual, the whole run's run clock over its sessions. A ratio below 1 is not shown: no
/// sequencer beats the instruments' physical bound, so the instruments' clock was not the
/// run's (a simulator sped up with `gyrocal sim --time-scale`), and the ratio would mean
/// nothing.
pub(super) fn timing_lines(t: &Timing, session_end_s: f64) -> Vec<String> {
    let s = SESSION.get();
    let resumed = s.is_some_and(|s| s.sessions > 1);
    let offset = s.map_or(0.0, |s| s.offset_s);
    let label = if resumed {
        "timing, this session"
    } else {
        "timing"
    };
    let acquisition = t.acquisition.as_deref().unwrap_or("?");
    // no sequencer beats the bound: below it, the instruments kept another clock than the run
    let beaten = t.ratio.is_finite() && t.ratio < 1.0;
    let ratio = if beaten {
        String::new()
    } else {
        format!(": ratio {:.4}", t.ratio)
    };
    let session = (session_end_s - offset).max(0.0);
    let mut lines = vec![
        format!(
            "{label}: schedule {} on the run clock (acquisition {acquisition})",
            hms(t.elapsed_s)
        ),
        format!(
            "  physical bound {}{ratio}; {} with connecting and the stop",
            hms(t.bound_s),
            hms(session)
        ),
    ];
    if beaten {
        lines.push(
            "  the schedule beat the physical bound: a time-scaled simulator? (no ratio shown)"
                .into(),
        );
    }
    if let Some(s) = s.filter(|s| s.virtual_time) {
        let pace = s.pace.map_or("as fast as possible".to_string(), |x| {
            format!("paced at {x}×")
        });
        lines.push(format!(
            "  the run clock was virtual (the simulated bench, {pace}): {} of wall time",
            hms(s.wall_start.elapsed().as_secs_f64())
        ));
    }
    if resumed {
        lines.push(format!(
            "  the whole run: {} on the run clock over {} sessions (not counting between them)",
            hms(session_end_s),
            s.map_or(1, |s| s.sessions)
        ));
    }
    lines
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A simulator 20 times faster than the schedule: after one step the ETA is the rest of
    /// the schedule at that pace, not the schedule itself (virtual time: exact).
    #[tokio::test(start_paused = true)]
    async fn the_eta_follows_the_pace_the_run_keeps() {
        let mut eta = Eta::default();
        // five steps of 4 s each by the schedule
        let step = Duration::from_secs(4);
        eta.start(step * 5, step * 4);
        assert_eq!(eta.remaining(), Some(step * 5));
        // the first takes 0.2 s
        tokio::time::advance(Duration::from_millis(200)).await;
        eta.start(step * 4, step * 3);
        assert!((eta.pace() - 0.05).abs() < 1e-9, "{}", eta.pace());
        assert_eq!(eta.remaining(), Some(Duration::from_millis(800)));
        // half-way through the second step: 0.1 s of it left, and three more at 0.2 s
        tokio::time::advance(Duration::from_millis(100)).await;
        assert_eq!(eta.remaining(), Some(Duration::from_millis(700)));
        // a step that overruns counts down to the later steps, not below
        tokio::time::advance(Duration::from_secs(10)).await;
        assert_eq!(eta.remaining(), Some(Duration::from_millis(600)));
        eta.stop();
        assert_eq!(eta.remaining(), None);
    }

    /// A soak between two steps lasts as long as the gyro takes, not as long as the schedule's
    /// links: its run clock stays out of the pace, and the time left after it is the rest of
    /// the schedule (the soak still ahead counted at its own estimate) at the pace the steps
    /// kept. Counted in, the 2 h soak below after a step of 3 s would make the pace 120 and the
    /// time left 120 times the schedule (the bug was "1074:41:16 left" at step 6 of 20).
    #[tokio::test(start_paused = true)]
    async fn a_soak_is_not_counted_in_the_pace_of_the_time_left() {
        let mut eta = Eta::default();
        let step = Duration::from_secs(60);
        let soak = Duration::from_secs(3600);
        // step 1, a soak, step 2, a soak, step 3: each step estimated at 60 s, each soak at 1 h
        eta.start(step * 3 + soak * 2, step * 2 + soak * 2);
        // a simulator 20 times faster than the schedule: step 1 takes 3 s
        tokio::time::advance(Duration::from_secs(3)).await;
        // the soak: its polls, 2 h of run clock in all
        for _ in 0..12 {
            eta.interlude();
            tokio::time::advance(Duration::from_secs(600)).await;
        }
        eta.start(step * 2 + soak, step + soak);
        assert!((eta.pace() - 0.05).abs() < 1e-12, "{}", eta.pace());
        // (60 s of step 2 + 60 s of step 3 + 1 h of soak) × 0.05
        let left = eta.remaining().unwrap().as_secs_f64();
        assert!((left - 186.0).abs() < 1e-6, "{left}");
        // step 2 takes its 3 s: the pace stays, the time left counts down to the rest
        tokio::time::advance(Duration::from_secs(3)).await;
        eta.interlude();
        assert!((eta.pace() - 0.05).abs() < 1e-12, "{}", eta.pace());
    }

    #[test]
    fn a_ratio_below_one_is_not_shown() {
        let t = Timing {
            bound_s: 20.0,
            elapsed_s: 11.7,
            ratio: 0.585,
            acquisition: Some("stream".into()),
        };
        let text = timing_lines(&t, 14.0).join("\n");
        assert!(!text.contains("0.58"), "{text}");
        assert!(text.contains("a time-scaled simulator?"), "{text}");
        let t = Timing { ratio: 1.02, ..t };
        assert!(timing_lines(&t, 14.0).join("\n").contains("ratio 1.0200"));
    }
}
