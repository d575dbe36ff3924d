//! The chamber's part of a run (a temperature series): the soak, the watch of a step at a
//! temperature, and the chamber's safe state at the teardown.
//!
//! - **The soak** ([`Engine::soak`]): the setpoint is stepped from where the air is towards
//!   the target at the plan's ramp (`[chamber] ramp_c_per_min`), one step per poll, written
//!   once here for every dialect (the controllers' own ramps are profile features that differ
//!   from one to the next); then the run waits until the gyro's temperature (the product
//!   input) is within `band_c` of the target and changing slower than
//!   `stability_c_per_min`, without a break, for `soak_min`. The rate of change is the
//!   least-squares slope of the gyro's readings over the last [`stability_window`] (a
//!   difference of two readings would be mostly sensor noise: 0.05–0.1 °C on a 10 s poll
//!   is 0.3–0.6 °C/min). The chamber is read every `poll_s`, each reading a row of
//!   `temps.csv` (phase `ramp` while the setpoint moves, `soak` after). Past `max_wait_min`
//!   the run fails plainly: which temperature, what the gyro read, the band.
//! - **The watch** ([`watch_while`]): during a step's acquisition the chamber is read every
//!   `poll_s` (phase `measure`); the gyro's min/mean/max go into the step's row, and a step
//!   during which it left the band is refused and measured again (the bounded repeat), like
//!   a step whose table did not hold the rate.
//! - **Alarms**: a reading with alarms (or the driver's alarm error) stops the run like a
//!   table fault: the table brought to rest, the step in progress not recorded, resumable.
//! - **The safe state** ([`Engine::chamber_to_safety`]): on every way out, after the table is
//!   at rest, the chamber goes to the plan's safe state and is read back: confirmed, or "could
//!   NOT be confirmed" with the reason.
//!
//! Time is the run's own clock (tokio's), so a soak of hours runs in virtual time in a test
//! and its end is exact.

use std::future::Future;
use std::time::Duration;

use gyrocal_chamber::{Chamber, ChamberError, ChamberErrorKind, ChamberReading, SafeState};
use gyrocal_files::plan::{ChamberSettings, SafeStateChoice};
use gyrocal_files::rundir::temps::{Phase as TempPhase, TempRow};
use gyrocal_files::steps::{Soak, Watch};
use tokio::time::Instant;

use super::{ChamberRest, Engine, SequenceError};
use crate::bench::Bench;

/// The longest window of the soak's rate of change (10 minutes: "0.1 °C per 10 min" is how
/// labs write the criterion).
pub const STABILITY_WINDOW_MAX: Duration = Duration::from_secs(600);

/// The window over which the soak's rate of change is fitted: the soak time, at least two
/// polls, at most [`STABILITY_WINDOW_MAX`].
pub fn stability_window(soak: &Soak) -> Duration {
    soak.soak.max(soak.poll * 2).min(STABILITY_WINDOW_MAX)
}

/// The least-squares slope of `(t_s, value)` points, per minute; `None` below two points or
/// when they share one time.
pub fn slope_per_min(points: &[(f64, f64)]) -> Option<f64> {
    if points.len() < 2 {
        return None;
    }
    let n = points.len() as f64;
    let (mt, mv) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), (t, v)| (a + t / n, b + v / n));
    let (sxy, sxx) = points.iter().fold((0.0, 0.0), |(xy, xx), (t, v)| {
        (xy + (t - mt) * (v - mv), xx + (t - mt) * (t - mt))
    });
    (sxx > 0.0).then(|| sxy / sxx * 60.0)
}

/// The setpoint `elapsed` into a ramp from `from` to `target` at `rate_c_per_min`.
pub fn ramped_setpoint(from: f64, target: f64, rate_c_per_min: f64, elapsed: Duration) -> f64 {
    let reach = rate_c_per_min * elapsed.as_secs_f64() / 60.0;
    if !reach.is_finite() || reach >= (target - from).abs() {
        target
    } else {
        from + reach * (target - from).signum()
    }
}

/// The gyro's temperature during a step at a temperature (the readings of the watch).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct TempStats {
    pub(super) min: f64,
    pub(super) max: f64,
    pub(super) mean: f64,
    pub(super) count: usize,
    /// The reading farthest outside the band, when one was.
    pub(super) outside: Option<f64>,
}

impl TempStats {
    fn of(temps: &[f64], watch: &Watch) -> Option<TempStats> {
        let first = *temps.first()?;
        let (mut min, mut max, mut sum) = (first, first, 0.0);
        let mut outside: Option<f64> = None;
        for &t in temps {
            min = min.min(t);
            max = max.max(t);
            sum += t;
            let off = (t - watch.setpoint_c).abs();
            if off > watch.band_c && outside.is_none_or(|o| off > (o - watch.setpoint_c).abs()) {
                outside = Some(t);
            }
        }
        Some(TempStats {
            min,
            max,
            mean: (sum / temps.len() as f64).clamp(min, max),
            count: temps.len(),
            outside,
        })
    }

    /// Why the step must be measured again, when the gyro left the band.
    pub(super) fn refusal(&self, watch: &Watch) -> Option<String> {
        self.outside.map(|t| {
            format!(
                "the gyro's temperature left the band during the acquisition: {t} °C (setpoint \
                 {} °C, band ±{} °C; {} chamber readings from {} to {} °C)",
                watch.setpoint_c, watch.band_c, self.count, self.min, self.max
            )
        })
    }
}

/// What a watch of the chamber during a step saw.
#[derive(Debug, Default)]
pub(super) struct Watched {
    /// The readings, with the run clock at each.
    pub(super) readings: Vec<(f64, ChamberReading)>,
    /// The chamber failed or raised an alarm: the run ends.
    pub(super) error: Option<SequenceError>,
}

impl Watched {
    /// The gyro's temperature statistics (the product input; the air when the chamber has
    /// none).
    pub(super) fn stats(&self, watch: &Watch) -> Option<TempStats> {
        let temps: Vec<f64> = self
            .readings
            .iter()
            .map(|(_, r)| r.product_c.unwrap_or(r.air_c))
            .collect();
        TempStats::of(&temps, watch)
    }
}

/// A reading's alarms as the run's error (none: `Ok`).
fn alarms(r: &ChamberReading, step: Option<usize>) -> Result<(), SequenceError> {
    if r.alarms.is_empty() {
        Ok(())
    } else {
        Err(SequenceError::ChamberAlarm {
            alarms: r.alarms.clone(),
            step,
        })
    }
}

/// A driver's error as the run's: an alarm it raised is the run's alarm.
fn chamber_error(e: ChamberError, step: Option<usize>) -> SequenceError {
    match &e {
        ChamberError::Alarm { alarms, .. } if e.kind() == ChamberErrorKind::Alarm => {
            SequenceError::ChamberAlarm {
                alarms: alarms.split(", ").map(str::to_string).collect(),
                step,
            }
        }
        _ => SequenceError::from(e),
    }
}

/// Runs `work` while reading `chamber` every `poll` (at once, then after each poll), the run
/// clock of each reading from `clock` (seconds since `origin`, plus `offset_s`). Stops
/// reading when `work` ends (a reading under way then is finished first, and counts: a
/// request left without its reply would desynchronise the link); a chamber that fails or
/// reports an alarm ends the watch at once
/// (`work` is dropped: the step is not recorded) with the error in [`Watched::error`].
pub(super) async fn watch_while<C: Chamber, F: Future>(
    chamber: &mut C,
    poll: Duration,
    step: Option<usize>,
    clock: impl Fn() -> f64,
    work: F,
) -> (Option<F::Output>, Watched) {
    let mut work = std::pin::pin!(work);
    let mut watched = Watched::default();
    let out = loop {
        // a reading under way when the work ends is finished, never dropped: its request is on
        // the wire, and the reply left behind was taken for the next request's (a series over
        // a real Modbus RTU link: "garbled reply: 1 registers instead of 9", then register
        // 1061's door alarm read back as 1063's over-temperature)
        let mut read = std::pin::pin!(chamber.read());
        tokio::select! {
            biased;
            out = &mut work => {
                let r = read.await;
                if let Some(e) = take_reading(&mut watched, r, step, &clock) {
                    watched.error = Some(e);
                    return (None, watched);
                }
                break out;
            }
            r = &mut read => {
                if let Some(e) = take_reading(&mut watched, r, step, &clock) {
                    watched.error = Some(e);
                    return (None, watched);
                }
            }
        }
        tokio::select! {
            biased;
            out = &mut work => break out,
            () = tokio::time::sleep(poll) => {}
        }
    };
    // every step has the gyro's temperature of its own: a step that ended before its first
    // reading of the chamber did (a short step; a paced virtual clock that moves both in one
    // tick) is read at its end (without it a series' step had empty temperature cells and
    // the whole series no analysis)
    if watched.readings.is_empty()
        && let Some(e) = take_reading(&mut watched, chamber.read().await, step, &clock)
    {
        watched.error = Some(e);
        return (None, watched);
    }
    (Some(out), watched)
}

/// Keeps a reading of the watch; the run's error when the chamber failed or raised an alarm.
fn take_reading(
    watched: &mut Watched,
    r: Result<ChamberReading, ChamberError>,
    step: Option<usize>,
    clock: &impl Fn() -> f64,
) -> Option<SequenceError> {
    match r {
        Ok(r) => {
            let alarm = alarms(&r, step).err();
            watched.readings.push((clock(), r));
            alarm
        }
        Err(e) => Some(chamber_error(e, step)),
    }
}

/// The plan's safe state as the driver's.
pub fn safe_state(c: &ChamberSettings) -> SafeState {
    match c.safe_state {
        SafeStateChoice::Ambient => SafeState::Ambient {
            setpoint_c: c.ambient_c,
        },
        SafeStateChoice::Standby => SafeState::Standby,
        SafeStateChoice::Off => SafeState::Off,
    }
}

impl<B: Bench> Engine<B> {
    /// A row of temps.csv for `r`.
    pub(super) fn note_temp(
        &mut self,
        t_s: f64,
        r: &ChamberReading,
        point: Option<u32>,
        phase: TempPhase,
    ) -> Result<(), SequenceError> {
        let row = TempRow {
            t_s,
            setpoint_c: r.setpoint_c,
            air_c: r.air_c,
            product_c: r.product_c,
            series_point: point,
            phase,
        };
        Ok(self.sinks.run.append_temp(&row)?)
    }

    /// The chamber driver's link retries go to the manifest like the meter's and the table's.
    pub(super) fn log_chamber_retries(&mut self, step: Option<usize>) -> Result<(), SequenceError> {
        for note in self.bench.chamber().take_retries() {
            self.log_retry(step, "chamber", note)?;
        }
        Ok(())
    }

    /// One reading of the chamber, its row in temps.csv; an alarm is the run's error.
    async fn read_chamber(
        &mut self,
        point: u32,
        phase: TempPhase,
    ) -> Result<ChamberReading, SequenceError> {
        let r = self
            .bench
            .chamber()
            .read()
            .await
            .map_err(|e| chamber_error(e, None))?;
        self.log_chamber_retries(None)?;
        let now = self.now_s();
        self.note_temp(now, &r, Some(point), phase)?;
        alarms(&r, None)?;
        Ok(r)
    }

    /// The soak at one temperature (see the module docs). Ends when the criterion has held
    /// for the soak time, at a reading of the chamber; fails at the maximum wait.
    pub(super) async fn soak(&mut self, soak: &Soak) -> Result<(), SequenceError> {
        let start = Instant::now();
        let first = self.read_chamber(soak.point, TempPhase::Ramp).await?;
        let from = first.air_c;
        let window = stability_window(soak);
        tracing::info!(
            point = soak.point,
            target_c = soak.setpoint_c,
            from_c = from,
            "soak: ramping the setpoint"
        );
        let mut gyro: Vec<(f64, f64)> = Vec::new();
        let mut held_since: Option<Instant> = None;
        let mut demanded: Option<f64> = None;
        let mut reading = Some(first);
        let mut warned_no_product = false;
        loop {
            let elapsed = start.elapsed();
            let setpoint = ramped_setpoint(from, soak.setpoint_c, soak.ramp_c_per_min, elapsed);
            let ramping = setpoint != soak.setpoint_c;
            if demanded.is_none_or(|d| d.to_bits() != setpoint.to_bits()) {
                self.bench
                    .chamber()
                    .set_setpoint(setpoint)
                    .await
                    .map_err(|e| chamber_error(e, None))?;
                demanded = Some(setpoint);
            }
            let phase = if ramping {
                TempPhase::Ramp
            } else {
                TempPhase::Soak
            };
            let r = match reading.take() {
                Some(r) => r,
                None => self.read_chamber(soak.point, phase).await?,
            };
            let now_s = self.now_s();
            let t = match r.product_c {
                Some(t) => t,
                None => {
                    if !warned_no_product {
                        warned_no_product = true;
                        self.log_retry(
                            None,
                            "chamber",
                            "the chamber reports no gyro (product) temperature: the soak watches the air"
                                .into(),
                        )?;
                    }
                    r.air_c
                }
            };
            gyro.push((now_s, t));
            let since = now_s - window.as_secs_f64();
            gyro.retain(|(ts, _)| *ts >= since - 1e-9);
            let rate = slope_per_min(&gyro);
            let holds = !ramping
                && (t - soak.setpoint_c).abs() <= soak.band_c
                && rate.is_some_and(|r| r.abs() <= soak.stability_c_per_min);
            let now = Instant::now();
            held_since = if holds {
                held_since.or(Some(now))
            } else {
                None
            };
            self.emit(super::Event::Soak {
                point: soak.point,
                target_c: soak.setpoint_c,
                setpoint_c: r.setpoint_c,
                air_c: r.air_c,
                gyro_c: r.product_c,
                held: held_since.map(|since| now - since),
                soak: soak.soak,
                waited: start.elapsed(),
            })?;
            if let Some(since) = held_since
                && now - since >= soak.soak
            {
                tracing::info!(
                    point = soak.point,
                    gyro_c = t,
                    waited_s = start.elapsed().as_secs_f64(),
                    "soaked"
                );
                self.sinks.checkpoint(now_s)?;
                return Ok(());
            }
            if start.elapsed() >= soak.max_wait {
                return Err(SequenceError::NotSoaked {
                    point: soak.point,
                    setpoint_c: soak.setpoint_c,
                    product_c: Some(t),
                    band_c: soak.band_c,
                    rate_c_per_min: rate,
                    stability_c_per_min: soak.stability_c_per_min,
                    waited_min: start.elapsed().as_secs_f64() / 60.0,
                });
            }
            // the run clock at every poll: the run directory writes it now and then
            // (RunDir::checkpoint), not at every poll
            self.sinks.checkpoint(now_s)?;
            tokio::time::sleep(soak.poll).await;
        }
    }

    /// The teardown's part for the chamber, after the table is at rest: the plan's safe
    /// state, read back (never an error: confirmed, or not with the reason).
    pub(super) async fn chamber_to_safety(&mut self) -> ChamberRest {
        let Some(settings) = self
            .plan
            .chamber()
            .filter(|_| self.program.uses_chamber)
            .cloned()
        else {
            return ChamberRest::NoChamber;
        };
        let state = safe_state(&settings);
        let words = settings.describe_safe_state();
        if !self.bench.chamber().present() {
            // the plan's chamber is not on this bench: nothing drove it, nothing can confirm it
            return ChamberRest::NotConfirmed {
                state: words,
                reason: "this bench has no chamber: the plan's chamber was never reached in this \
                         session"
                    .into(),
            };
        }
        let limit = self.options.cleanup_timeout * 4;
        let report = match tokio::time::timeout(limit, self.bench.chamber().go_safe(state)).await {
            Ok(report) => report,
            Err(_) => {
                let rest = ChamberRest::NotConfirmed {
                    state: words,
                    reason: format!(
                        "the chamber did not answer within {} s",
                        limit.as_secs_f64()
                    ),
                };
                tracing::error!(?rest, "chamber safe state NOT confirmed");
                return rest;
            }
        };
        if let Err(e) = self.log_chamber_retries(None) {
            tracing::warn!(error = %e, "could not log the chamber's retries");
        }
        // one more reading for temps.csv, best effort (a silent chamber already said so)
        if report.confirmed
            && let Ok(Ok(r)) = tokio::time::timeout(limit, self.bench.chamber().read()).await
        {
            let now = self.now_s();
            if let Err(e) = self.note_temp(now, &r, None, TempPhase::Safe) {
                tracing::warn!(error = %e, "could not write the chamber's last reading");
            }
        }
        let rest = if report.confirmed {
            ChamberRest::Confirmed {
                state: words,
                detail: report.detail,
            }
        } else {
            ChamberRest::NotConfirmed {
                state: words,
                reason: report.detail,
            }
        };
        match &rest {
            ChamberRest::Confirmed { .. } => tracing::info!(?rest, "chamber in its safe state"),
            _ => tracing::error!(?rest, "chamber safe state could NOT be confirmed"),
        }
        rest
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_setpoint_ramps_at_the_plans_rate_and_stops_at_the_target() {
        let min = |m: u64| Duration::from_secs(m * 60);
        assert_eq!(ramped_setpoint(25.0, -20.0, 1.0, min(0)), 25.0);
        assert_eq!(ramped_setpoint(25.0, -20.0, 1.0, min(10)), 15.0);
        assert_eq!(ramped_setpoint(25.0, -20.0, 1.0, min(45)), -20.0);
        assert_eq!(ramped_setpoint(25.0, 60.0, 2.0, min(10)), 45.0);
        assert_eq!(ramped_setpoint(25.0, 60.0, 2.0, min(100)), 60.0);
    }

    #[test]
    fn the_rate_of_change_is_a_fitted_slope_per_minute() {
        let pts: Vec<(f64, f64)> = (0..10)
            .map(|i| (f64::from(i) * 30.0, 20.0 + 0.01 * f64::from(i) * 30.0))
            .collect();
        let s = slope_per_min(&pts).unwrap();
        assert!((s - 0.6).abs() < 1e-12, "{s}");
        assert_eq!(slope_per_min(&pts[..1]), None);
        assert_eq!(slope_per_min(&[(1.0, 2.0), (1.0, 3.0)]), None);
    }

    #[test]
    fn a_step_whose_gyro_left_the_band_is_refused_saying_where() {
        let watch = Watch {
            point: 1,
            setpoint_c: -20.0,
            band_c: 0.5,
            poll: Duration::from_secs(10),
        };
        let ok = TempStats::of(&[-20.1, -19.8, -20.2], &watch).unwrap();
        assert_eq!(ok.refusal(&watch), None);
        assert_eq!((ok.min, ok.max), (-20.2, -19.8));
        let bad = TempStats::of(&[-20.1, -19.2, -20.7, -19.9], &watch).unwrap();
        let why = bad.refusal(&watch).unwrap();
        assert!(why.contains("-19.2 °C") && why.contains("±0.5"), "{why}");
    }
}
