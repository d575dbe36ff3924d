//! The Truevolt timing model, public so a planner can estimate a run before anything is
//! connected, and shared with the simulator (which paces its readings by it).
//!
//! - integration `t_int = NPLC / f_line`; autozero on doubles it (a zero measurement per
//!   reading);
//! - a trigger delay before every sample: the automatic delay [U: the 34401A's, 1.5 ms at
//!   NPLC >= 1 and 1.0 ms below, assumed] or the configured one;
//! - arming (`INIT`) [U: 20 ms assumed, as the 34401A];
//! - the LAN transfer of one reading [U: 250 µs, from the predecessor 34410A's ~4,000
//!   readings/s of ASCII over a socket]: see [`TimingDefaults`].
//!
//! One reading takes `delay + t_int·(2 if autozero)`: 41.5 ms at NPLC 1, 50 Hz, autozero on.
//!
//! How the time of a step is spent ([`TruevoltTiming`]'s `cost`):
//!
//! - **stream** (`SAMP:COUN n`, `INIT`, then `DATA:REMove? k,WAIT` while it measures): the
//!   meter measures into its memory and the host removes readings as they come, so every
//!   transfer but the last overlaps the measurement. The chunks are about
//!   [`TimingDefaults::chunk_period`] of readings (progress stays live; never more than half
//!   the memory, so the meter cannot overflow while a chunk travels), halved towards the end
//!   so that the last one, whose transfer the step waits for, holds at most
//!   [`TimingDefaults::tail_transfer`] worth of readings ([`TruevoltTiming::stream_chunks`]).
//! - **memory** (`INIT`, `*OPC?`, `FETC?`, in parts of at most the memory): the meter measures,
//!   then the part is fetched; the last part's `FETC?` may be left pending, overlapping the
//!   table's next ramp.
//!
//! The physical bound ([`gyrocal_meter::Cost::bound`]) is arming, the readings (or the wire
//! when it is the slower) and one reading's transfer (the host learns from it that the last
//! reading was taken); commands and protocol overhead are not in it.

use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::facts::{MAX_SAMPLE_COUNT, Model};

/// The timing facts that are \[U\]: documented defaults a lab can change.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TimingDefaults {
    /// Entering wait-for-trigger (`INIT`). \[U\] Default 20 ms (the 34401A's figure).
    pub arm_time: Duration,
    /// One reading's transfer over the socket (ASCII, `+1.23456789E+00,`). \[U\] Default
    /// 250 µs: the 34410A's ~4,000 readings/s memory-to-PC over sockets.
    pub transfer_per_reading: Duration,
    /// Automatic trigger delay at NPLC >= 1. \[U\] Default 1.5 ms (the 34401A's).
    pub auto_delay_slow: Duration,
    /// Automatic trigger delay below NPLC 1. \[U\] Default 1.0 ms (the 34401A's).
    pub auto_delay_fast: Duration,
    /// Readings per stream chunk: about this long of measuring. Default 0.5 s.
    pub chunk_period: Duration,
    /// The last stream chunk's transfer (the one the step waits for) is at most this long.
    /// Default 1 ms (4 readings at the default transfer rate).
    pub tail_transfer: Duration,
}

impl Default for TimingDefaults {
    fn default() -> Self {
        TimingDefaults {
            arm_time: Duration::from_millis(20),
            transfer_per_reading: Duration::from_micros(250),
            auto_delay_slow: Duration::from_micros(1500),
            auto_delay_fast: Duration::from_micros(1000),
            chunk_period: Duration::from_millis(500),
            tail_transfer: Duration::from_millis(1),
        }
    }
}

/// How readings leave the meter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Acquisition {
    /// Drained with `DATA:REMove? k,WAIT` while the meter measures.
    Stream,
    /// `INIT`, `*OPC?`, `FETC?` in memory-sized parts; the last fetch may be deferred.
    Memory,
    /// Stream (the wire is never the bottleneck on a LAN).
    #[default]
    Auto,
}

impl Acquisition {
    /// `Auto` resolved: stream.
    pub fn resolve(self) -> Acquisition {
        match self {
            Acquisition::Auto => Acquisition::Stream,
            a => a,
        }
    }
}

/// A Truevolt's timing at one configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruevoltTiming {
    /// The model.
    pub model: Model,
    /// Readings the memory holds (the MEM option counted).
    pub memory: usize,
    /// Integration time, power-line cycles.
    pub nplc: f64,
    /// Mains frequency, Hz.
    pub line_hz: u32,
    /// Autozero on.
    pub autozero: bool,
    /// Trigger delay (`None`: automatic).
    pub trigger_delay: Option<Duration>,
    /// The \[U\] figures.
    pub defaults: TimingDefaults,
    /// How readings leave the meter (never `Auto`).
    pub acquisition: Acquisition,
}

fn n32(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

impl TruevoltTiming {
    /// The trigger delay in force.
    pub fn trigger_delay(&self) -> Duration {
        self.trigger_delay.unwrap_or(if self.nplc >= 1.0 {
            self.defaults.auto_delay_slow
        } else {
            self.defaults.auto_delay_fast
        })
    }

    /// The integration time `NPLC / f_line`.
    pub fn integration(&self) -> Duration {
        Duration::from_secs_f64((self.nplc / f64::from(self.line_hz.max(1))).max(0.0))
    }

    /// One reading: `delay + t_int·(2 if autozero)`.
    pub fn reading_time(&self) -> Duration {
        let t = self.integration();
        self.trigger_delay() + if self.autozero { t * 2 } else { t }
    }

    /// The transfer of `n` readings.
    pub fn transfer(&self, n: usize) -> Duration {
        self.defaults.transfer_per_reading * n32(n)
    }

    /// Readings per full stream chunk: [`TimingDefaults::chunk_period`] of measuring, at
    /// least 1, at most half the memory.
    pub fn big_chunk(&self) -> usize {
        let rt = self.reading_time().as_secs_f64().max(1e-9);
        let per = (self.defaults.chunk_period.as_secs_f64() / rt).floor();
        // a float that big is clamped anyway
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let per = per.clamp(1.0, 1e9) as usize;
        per.clamp(1, (self.memory / 2).max(1))
    }

    /// Most readings in the last stream chunk: [`TimingDefaults::tail_transfer`] of transfer,
    /// at least 1.
    pub fn tail_chunk(&self) -> usize {
        let tx = self.defaults.transfer_per_reading.as_secs_f64().max(1e-12);
        let k = (self.defaults.tail_transfer.as_secs_f64() / tx).floor();
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let k = k.clamp(1.0, 1e9) as usize;
        k.min(self.big_chunk())
    }

    /// The size of the next `DATA:REMove?` when `remaining` readings are still to come.
    pub fn next_chunk(&self, remaining: usize) -> usize {
        let big = self.big_chunk();
        let tail = self.tail_chunk();
        if remaining > 2 * big {
            big
        } else if remaining <= tail {
            remaining
        } else {
            remaining.div_ceil(2).max(tail).min(remaining)
        }
    }

    /// Every chunk of a stream of `n` readings (one `INIT` of at most
    /// [`MAX_SAMPLE_COUNT`]), in order.
    pub fn stream_chunks(&self, n: usize) -> Vec<usize> {
        let mut out = Vec::new();
        let mut left = n;
        while left > 0 {
            let k = self.next_chunk(left);
            out.push(k);
            left -= k;
        }
        out
    }

    /// The parts (one `INIT` each) an acquisition of `n` readings is split into: at most
    /// [`MAX_SAMPLE_COUNT`] when streaming, at most the memory in memory mode.
    pub fn parts(&self, n: usize) -> Vec<usize> {
        let size = match self.acquisition {
            Acquisition::Memory => self.memory,
            _ => MAX_SAMPLE_COUNT,
        }
        .max(1);
        let mut out = vec![size; n / size];
        if !n.is_multiple_of(size) {
            out.push(n % size);
        }
        out
    }

    /// Measuring `k` readings while the wire carries them, the step waiting for the last
    /// `last` of them: the readings or the wire, whichever is the slower.
    fn streamed(&self, k: usize, last: usize) -> Duration {
        let rt = self.reading_time();
        (rt * n32(k) + self.transfer(last)).max(rt + self.transfer(k))
    }
}

impl gyrocal_meter::TimingModel for TruevoltTiming {
    fn reading_time(&self) -> Duration {
        TruevoltTiming::reading_time(self)
    }

    fn acquisition(&self) -> &'static str {
        match self.acquisition {
            Acquisition::Memory => "memory",
            _ => "stream",
        }
    }

    /// Commands over the socket are counted as free (their time is protocol overhead, small
    /// on a LAN, not modelled).
    fn cost(&self, n: usize, defer: bool) -> gyrocal_meter::Cost {
        let mut cost = gyrocal_meter::Cost::default();
        let parts = self.parts(n);
        let count = parts.len();
        for (i, k) in parts.into_iter().enumerate() {
            let arm = self.defaults.arm_time;
            match self.acquisition {
                Acquisition::Memory => {
                    cost.in_step += arm + self.reading_time() * n32(k);
                    cost.bound += arm + self.reading_time() * n32(k);
                    let fetch = self.transfer(k);
                    if defer && i + 1 == count {
                        cost.deferred = fetch;
                        cost.bound_deferred = fetch;
                    } else {
                        cost.in_step += fetch;
                        cost.bound += fetch;
                    }
                }
                _ => {
                    let last = self.stream_chunks(k).last().copied().unwrap_or(0);
                    cost.in_step += arm + self.streamed(k, last);
                    cost.bound += arm + self.streamed(k, 1);
                }
            }
        }
        cost
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gyrocal_meter::TimingModel;

    fn nplc1(model: Model, acquisition: Acquisition) -> TruevoltTiming {
        TruevoltTiming {
            model,
            memory: model.memory(false),
            nplc: 1.0,
            line_hz: 50,
            autozero: true,
            trigger_delay: None,
            defaults: TimingDefaults::default(),
            acquisition,
        }
    }

    #[test]
    fn figures() {
        let t = nplc1(Model::M34461A, Acquisition::Stream);
        assert_eq!(t.reading_time(), Duration::from_micros(41_500));
        // 0.5 s of readings per chunk, the last one 4 readings (1 ms of transfer)
        assert_eq!(t.big_chunk(), 12);
        assert_eq!(t.tail_chunk(), 4);
        let chunks = t.stream_chunks(500);
        assert_eq!(chunks.iter().sum::<usize>(), 500);
        assert!(chunks.iter().all(|&k| k <= 12), "{chunks:?}");
        assert!(*chunks.last().unwrap() <= 4, "{chunks:?}");
        // 500 readings: 20 ms + 500 x 41.5 ms + the last chunk's transfer
        let c = t.cost(500, true);
        let last = Duration::from_micros(250) * u32::try_from(*chunks.last().unwrap()).unwrap();
        assert_eq!(
            c.in_step,
            Duration::from_millis(20) + Duration::from_micros(20_750_000) + last
        );
        assert_eq!(c.deferred, Duration::ZERO);
        assert_eq!(
            c.bound,
            Duration::from_millis(20) + Duration::from_micros(20_750_000 + 250)
        );
        // what the meter adds to the bound is under 0.01 %
        let ratio = c.in_step.as_secs_f64() / c.bound.as_secs_f64();
        assert!(ratio < 1.0001, "{ratio}");
    }

    #[test]
    fn a_small_memory_is_never_overfilled_by_a_chunk() {
        let mut t = nplc1(Model::M34460A, Acquisition::Stream);
        t.nplc = 0.02;
        t.autozero = false;
        // 1.4 ms a reading: 357 readings in 0.5 s, half the memory is 500
        assert_eq!(t.big_chunk(), 357);
        t.defaults.chunk_period = Duration::from_secs(10);
        assert_eq!(t.big_chunk(), 500);
        let chunks = t.stream_chunks(10_000);
        assert!(chunks.iter().all(|&k| k <= 500));
        assert_eq!(chunks.iter().sum::<usize>(), 10_000);
    }

    #[test]
    fn memory_mode_splits_at_the_memory_and_defers_the_last_fetch() {
        let t = nplc1(Model::M34460A, Acquisition::Memory);
        assert_eq!(t.parts(2_500), vec![1_000, 1_000, 500]);
        let c = t.cost(2_500, true);
        // three armings and 2,500 readings; two fetches of 1,000 in the step, 500 deferred
        let measure = Duration::from_millis(60) + Duration::from_micros(41_500) * 2_500;
        assert_eq!(c.in_step, measure + Duration::from_micros(250) * 2_000);
        assert_eq!(c.deferred, Duration::from_micros(250) * 500);
        assert_eq!(c.bound_deferred, c.deferred);
        let c = t.cost(2_500, false);
        assert_eq!(c.deferred, Duration::ZERO);
        assert_eq!(c.in_step, measure + Duration::from_micros(250) * 2_500);
    }
}
