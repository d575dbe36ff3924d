//! What a run watches in its readings while it records: the warm-up (IEEE 1431 §12.6, the
//! criterion of [`gyrocal_allan::warmup`]) and, in a drift record, a running overlapping Allan
//! deviation at a few τ for the operator. Both are bounded in memory whatever the record's
//! length: window sums and thinned means for the warm-up, the streaming accumulator's last
//! 2·m_max + 1 phase values for the deviation (m_max·τ0 ≤ [`ADEV_LONGEST_TAU_S`]).

use std::collections::VecDeque;

use gyrocal_allan::Streaming;
use gyrocal_allan::warmup::{Tolerance, WarmupDetector};

use gyrocal_files::plan::WarmupSettings;
use gyrocal_files::rundir::WarmupRecord;

/// The default warm-up tolerance, in white-noise standard deviations of a window mean (the
/// same as `gyrocal allan`'s).
pub const WARMUP_SIGMAS: f64 = 3.0;
/// Most window means a warm-up record keeps (thinned by doubling the stride).
pub const WARMUP_MAX_POINTS: usize = 400;
/// The longest τ of the running deviation shown while a drift record runs, s.
pub const ADEV_LONGEST_TAU_S: f64 = 100.0;
/// The averaging times the progress shows the running deviation nearest to, s.
pub const ADEV_SHOWN_TAUS_S: [f64; 3] = [1.0, 10.0, 100.0];

/// `before_sweep`: a phase of its own before the first step of a scale-factor sweep.
pub const WARMUP_BEFORE_SWEEP: &str = "before_sweep";
/// `in_record`: the first segments of a drift record.
pub const WARMUP_IN_RECORD: &str = "in_record";

/// The warm-up as it is watched: the detector, the record kept in the manifest, and the run-
/// clock times of the last chunks of readings (to date the end, which lies at most two windows
/// back).
#[derive(Debug, Clone)]
pub struct WarmupWatch {
    detector: WarmupDetector,
    record: WarmupRecord,
    period_s: f64,
    /// `(index of the chunk's first reading, readings, t_start, t_end)`, the last few.
    chunks: VecDeque<(u64, u64, f64, f64)>,
}

impl WarmupWatch {
    /// A watch of readings every `period_s` seconds, starting at run-clock `started_s`.
    pub fn new(settings: &WarmupSettings, period_s: f64, started_s: f64, mode: &str) -> Self {
        let period = if period_s.is_finite() && period_s > 0.0 {
            period_s
        } else {
            1.0
        };
        let window = (settings.window.as_secs_f64() / period).round().max(1.0) as u64;
        let max = (settings.max.as_secs_f64() / period).round().max(1.0) as u64;
        let tolerance = settings
            .tolerance_v
            .map_or(Tolerance::WhiteSigmas(WARMUP_SIGMAS), Tolerance::Fixed);
        let record = WarmupRecord {
            mode: mode.into(),
            window_s: window as f64 * period,
            tolerance_v: settings.tolerance_v,
            tolerance_source: match settings.tolerance_v {
                Some(_) => "plan".into(),
                None => format!(
                    "{WARMUP_SIGMAS} x white-noise sigma of a window mean (sigma_A(tau0)/sqrt(w), from the readings so far)"
                ),
            },
            max_s: settings.max.as_secs_f64(),
            started_s,
            complete: false,
            time_s: None,
            ended_by: None,
            last_change_v: None,
            means: Vec::new(),
        };
        WarmupWatch {
            detector: WarmupDetector::new(window, tolerance, Some(max), WARMUP_MAX_POINTS),
            record,
            period_s: period,
            chunks: VecDeque::new(),
        }
    }

    /// Readings per window.
    pub fn window(&self) -> u64 {
        self.detector.window()
    }

    /// Feeds a chunk of valid readings taken from `t_start` to `t_end` (run clock, s); true
    /// when the warm-up ended in this chunk.
    pub fn push(&mut self, volts: &[f64], t_start: f64, t_end: f64) -> bool {
        let first = self.detector.samples();
        self.chunks
            .push_back((first, volts.len() as u64, t_start, t_end));
        // the end lies at most two windows back: the chunks covering them are enough
        while self.chunks.len() > 2
            && self.chunks.iter().skip(1).map(|c| c.1).sum::<u64>() > 3 * self.window()
        {
            self.chunks.pop_front();
        }
        let end = self.detector.push(volts);
        let started = self.record.started_s;
        let window = self.window();
        self.record.means = self
            .detector
            .means()
            .iter()
            .map(|&(i, m)| [self.time_of(i) + 0.5 * window as f64 * self.period_s, m])
            .collect();
        self.record.last_change_v = self.detector.last_change();
        // the tolerance in force: the plan's, or the white-noise estimate so far
        self.record.tolerance_v = self.detector.tolerance();
        if let Some(end) = end {
            self.record.complete = true;
            self.record.time_s = Some((self.time_of(end.samples) - started).max(0.0));
            self.record.ended_by = Some(end.ended_by.as_str().into());
            self.record.tolerance_v = Some(end.tolerance).filter(|t| t.is_finite());
            return true;
        }
        false
    }

    /// The run-clock time of reading `index` (counted from the watch's first): within a kept
    /// chunk, spread evenly over it; otherwise counted from the start at the reading period.
    fn time_of(&self, index: u64) -> f64 {
        for &(first, n, t0, t1) in &self.chunks {
            if index >= first && index < first + n.max(1) {
                let frac = (index - first) as f64 / n.max(1) as f64;
                return t0 + (t1 - t0) * frac;
            }
        }
        self.record.started_s + index as f64 * self.period_s
    }

    /// The record for the manifest.
    pub fn record(&self) -> &WarmupRecord {
        &self.record
    }

    /// The warm-up is over.
    pub fn is_complete(&self) -> bool {
        self.record.complete
    }
}

/// A running overlapping Allan deviation of a drift record, octave τ up to
/// [`ADEV_LONGEST_TAU_S`].
#[derive(Debug, Clone)]
pub struct AdevWatch {
    stream: Streaming,
}

impl AdevWatch {
    /// For readings every `period_s` seconds.
    pub fn new(period_s: f64) -> Self {
        let period = if period_s.is_finite() && period_s > 0.0 {
            period_s
        } else {
            1.0
        };
        let m_max = (ADEV_LONGEST_TAU_S / period).max(1.0) as usize;
        AdevWatch {
            stream: Streaming::new(period, m_max),
        }
    }

    /// Feeds valid readings (a chunk of any size).
    pub fn push(&mut self, volts: &[f64]) {
        // the stream refuses only non-finite values, which the caller never passes
        if let Err(e) = self.stream.push(volts) {
            tracing::debug!(error = %e, "running deviation: chunk skipped");
        }
    }

    /// Readings fed so far.
    pub fn readings(&self) -> u64 {
        self.stream.len() as u64
    }

    /// `(τ, σ)` at every octave τ up to [`ADEV_LONGEST_TAU_S`] with a finite deviation (σ in
    /// the readings' unit): the running curve a live view draws, a dozen points at most
    /// whatever the record's length.
    pub fn curve(&self) -> Vec<(f64, f64)> {
        let Ok(points) = self.stream.deviations() else {
            return Vec::new();
        };
        points
            .iter()
            .filter(|p| p.deviation.is_finite() && p.tau_s.is_finite())
            .map(|p| (p.tau_s, p.deviation))
            .collect()
    }

    /// `(τ, σ)` at the octave τ nearest each of [`ADEV_SHOWN_TAUS_S`] that has at least two
    /// terms (σ in the readings' unit); empty before there are enough readings.
    pub fn shown(&self) -> Vec<(f64, f64)> {
        let Ok(points) = self.stream.deviations() else {
            return Vec::new();
        };
        let mut out: Vec<(f64, f64)> = Vec::new();
        for want in ADEV_SHOWN_TAUS_S {
            let best = points
                .iter()
                .filter(|p| p.deviation.is_finite())
                .min_by(|a, b| {
                    let da = (a.tau_s / want).ln().abs();
                    let db = (b.tau_s / want).ln().abs();
                    da.total_cmp(&db)
                });
            if let Some(p) = best
                && (p.tau_s / want).ln().abs() < std::f64::consts::LN_2
                && !out.iter().any(|&(t, _)| t == p.tau_s)
            {
                out.push((p.tau_s, p.deviation));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn the_warm_up_end_is_dated_on_the_run_clock() {
        // 10 readings/s; a bias settling over 100 s; windows of 10 s; chunks of 5 s with a
        // 1 s gap between them (re-arming)
        let settings = WarmupSettings {
            window: Duration::from_secs(10),
            tolerance_v: Some(1e-3),
            max: Duration::from_secs(3600),
        };
        let mut w = WarmupWatch::new(&settings, 0.1, 100.0, WARMUP_BEFORE_SWEEP);
        assert_eq!(w.window(), 100);
        let mut t = 100.0;
        let mut i = 0u64;
        let mut ended_at = None;
        for _ in 0..200 {
            let chunk: Vec<f64> = (0..50)
                .map(|k| 0.1 * (-((i + k) as f64 * 0.1) / 30.0).exp())
                .collect();
            i += 50;
            if w.push(&chunk, t, t + 5.0) {
                ended_at = Some(w.record().time_s);
                break;
            }
            t += 6.0;
        }
        let rec = w.record();
        assert!(rec.complete, "{rec:?}");
        assert_eq!(rec.ended_by.as_deref(), Some("criterion"));
        // the end is the start of a window: a whole number of windows of readings, 12 s of
        // run clock per 100 readings (5 s + 1 s gap per 50)
        let time = ended_at.flatten().expect("dated");
        let windows = time / 12.0;
        assert!((windows - windows.round()).abs() < 1e-9, "{time}");
        assert!(time > 0.0 && time < 600.0, "{time}");
        assert!(!rec.means.is_empty());
    }

    #[test]
    fn the_running_deviation_shows_white_noise_falling_as_one_over_root_tau() {
        let mut a = AdevWatch::new(0.1);
        // uniform white noise from a xorshift generator: the slope is what matters
        let mut rng = 12345u64;
        let y: Vec<f64> = (0..200_000)
            .map(|_| {
                rng ^= rng << 13;
                rng ^= rng >> 7;
                rng ^= rng << 17;
                (rng >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .collect();
        for c in y.chunks(3000) {
            a.push(c);
        }
        let shown = a.shown();
        assert_eq!(shown.len(), 3, "{shown:?}");
        let (t1, s1) = shown[0];
        let (t3, s3) = shown[2];
        let slope = (s3 / s1).ln() / (t3 / t1).ln();
        assert!((slope + 0.5).abs() < 0.1, "slope {slope} from {shown:?}");
    }
}
