//! The 34401A timing model (from `shared/docs/hp34401a.md`), public so a run planner can estimate
//! a calibration's duration before it starts, and used by the driver to scale its timeouts.
//!
//! - integration `t_int = NPLC / f_line`; autozero on doubles the measurement time;
//! - automatic trigger delay 1.5 ms at NPLC >= 1, 1.0 ms below, before every sample;
//! - entering wait-for-trigger (`INIT`, `READ?`) costs 20 ms;
//! - every character is 11 bits on the wire; a reading is 15 characters plus a comma (or CR LF).
//!
//! One reading therefore takes `delay + t_int * (2 if autozero else 1)`: 41.5 ms at NPLC 1, 50 Hz,
//! autozero on.

use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::{AutoZero, DcvConfig};

/// Entering wait-for-trigger (`INIT`, `READ?`) costs about this long.
pub const ARM_TIME: Duration = Duration::from_millis(20);
/// Characters of one reading on the wire, with its comma.
pub const READING_CHARS: usize = 16;
/// Bits per character on the wire (1 start, 7+parity or 8 data, 2 stop).
pub const BITS_PER_CHAR: u32 = 11;
/// Most readings one `INIT` can store in the meter's memory.
pub const MEMORY_READINGS: usize = 512;
/// Time of one character on a GPIB bus behind a Prologix controller: about 100 kB/s end to
/// end \[U\] (the bus itself is faster; the controller's USB or TCP side and its `++read`
/// handling bound it). The simulated bench's GPIB uses the same figure.
pub const GPIB_CHAR_TIME: Duration = Duration::from_micros(10);
/// Most readings per trigger (`SAMP:COUN`).
pub const MAX_SAMPLE_COUNT: usize = 50_000;

/// How readings travel from the meter to the host.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Strategy {
    /// `SAMP:COUN n` then `READ?`: readings stream out as they are taken.
    Stream,
    /// `INIT;*OPC?` then `FETC?`, in bursts of at most 512 readings.
    Memory,
    /// One `READ?` per reading: the slow baseline.
    Poll,
    /// Stream when the wire keeps up with the reading rate, memory otherwise.
    #[default]
    Auto,
}

/// Time of one character at `baud` (11 bits).
pub fn char_time(baud: u32) -> Duration {
    Duration::from_secs_f64(f64::from(BITS_PER_CHAR) / f64::from(baud.max(1)))
}

/// Integration time `NPLC / f_line`.
pub fn integration_time(nplc: f64, line_hz: u32) -> Duration {
    Duration::from_secs_f64((nplc / f64::from(line_hz.max(1))).max(0.0))
}

/// The automatic trigger delay for DC volts: 1.5 ms at NPLC >= 1, 1.0 ms below.
pub fn auto_trigger_delay(nplc: f64) -> Duration {
    if nplc >= 1.0 {
        Duration::from_micros(1500)
    } else {
        Duration::from_micros(1000)
    }
}

/// Time of one reading: `delay + t_int * (2 if autozero else 1)`.
pub fn reading_time(nplc: f64, line_hz: u32, autozero: bool, delay: Duration) -> Duration {
    let t = integration_time(nplc, line_hz);
    delay + if autozero { t * 2 } else { t }
}

/// The timing model for one configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Timing {
    /// Integration time in power-line cycles.
    pub nplc: f64,
    /// Power-line frequency, Hz.
    pub line_hz: u32,
    /// Autozero on (doubles the measurement time).
    pub autozero: bool,
    /// Trigger delay before every sample.
    pub trigger_delay: Duration,
    /// Link baud rate (RS-232).
    pub baud: u32,
    /// Reached over GPIB: the wire time is [`GPIB_CHAR_TIME`] per character, not the baud's.
    pub gpib: bool,
}

impl Timing {
    /// The model for `config` (autozero `ONCE` counts as off: one zero at the start only).
    pub fn new(config: &DcvConfig) -> Self {
        Timing {
            nplc: config.nplc,
            line_hz: config.line_hz,
            autozero: config.autozero == AutoZero::On,
            trigger_delay: config
                .trigger_delay
                .and_then(|d| Duration::try_from_secs_f64(d).ok())
                .unwrap_or_else(|| auto_trigger_delay(config.nplc)),
            baud: config.baud,
            gpib: config.gpib,
        }
    }

    /// Time of one reading.
    pub fn reading_time(&self) -> Duration {
        reading_time(self.nplc, self.line_hz, self.autozero, self.trigger_delay)
    }

    /// Time one character takes on the wire.
    pub fn char_time(&self) -> Duration {
        if self.gpib {
            GPIB_CHAR_TIME
        } else {
            char_time(self.baud)
        }
    }

    /// Time `chars` characters take on the wire.
    pub fn wire_time(&self, chars: usize) -> Duration {
        self.char_time() * u32::try_from(chars).unwrap_or(u32::MAX)
    }

    /// Wire time of one reading with its comma (16 characters).
    pub fn wire_time_per_reading(&self) -> Duration {
        self.wire_time(READING_CHARS)
    }

    /// Time to enter wait-for-trigger (`INIT`, `READ?`).
    pub fn arming_time(&self) -> Duration {
        ARM_TIME
    }

    /// Time a command line takes to reach the meter (its characters plus LF).
    pub fn command_time(&self, line: &str) -> Duration {
        self.wire_time(line.len() + 1)
    }

    /// Whether the wire carries readings at least as fast as the meter takes them.
    pub fn wire_keeps_up(&self) -> bool {
        self.wire_time_per_reading() <= self.reading_time()
    }

    /// The concrete strategy `Auto` stands for with this configuration (others map to themselves).
    ///
    /// Stream when the wire keeps up; otherwise memory: a stream would then be throttled by the
    /// meter's output buffer (readings no longer evenly spaced, the dwell at each rate dominated
    /// by the transfer), while memory samples at full speed and its transfer can overlap moving
    /// the table to the next rate.
    pub fn resolve(&self, strategy: Strategy) -> Strategy {
        match strategy {
            Strategy::Auto if self.wire_keeps_up() => Strategy::Stream,
            Strategy::Auto => Strategy::Memory,
            s => s,
        }
    }

    /// Expected duration of `SAMP:COUN n` + `READ?` streaming `n` readings (`n` <= 50000).
    fn stream_chunk(&self, n: usize) -> Duration {
        if n == 0 {
            return Duration::ZERO;
        }
        let n32 = u32::try_from(n).unwrap_or(u32::MAX);
        let cmds = self.command_time(&format!("SAMP:COUN {n}")) + self.command_time("READ?");
        let body = if self.wire_keeps_up() {
            self.reading_time() * n32 + self.wire_time(READING_CHARS + 1)
        } else {
            self.reading_time() + self.wire_time_per_reading() * n32 + self.wire_time(1)
        };
        cmds + self.arming_time() + body
    }

    /// Expected duration of arming and waiting for one memory burst of `n` readings (<= 512).
    pub fn burst_time(&self, n: usize) -> Duration {
        let n32 = u32::try_from(n).unwrap_or(u32::MAX);
        self.command_time(&format!("SAMP:COUN {n}"))
            + self.command_time("INIT;*OPC?")
            + self.arming_time()
            + self.reading_time() * n32
            + self.wire_time(3)
    }

    /// Expected duration of the `FETC?` of `n` readings.
    pub fn fetch_time(&self, n: usize) -> Duration {
        self.command_time("FETC?") + self.wire_time(n * READING_CHARS + 1)
    }

    /// Expected duration of one polled reading (`READ?` and its reply).
    pub fn poll_time(&self) -> Duration {
        self.command_time("READ?") + self.arming_time() + self.reading_time() + self.wire_time(17)
    }

    /// Expected duration of acquiring `n` readings with `strategy` (`Auto` resolved first),
    /// excluding retries. Memory bursts are counted one after the other, with no overlap.
    pub fn estimate(&self, strategy: Strategy, n: usize) -> Duration {
        match self.resolve(strategy) {
            Strategy::Stream | Strategy::Auto => {
                let mut left = n;
                let mut total = Duration::ZERO;
                while left > 0 {
                    let k = left.min(MAX_SAMPLE_COUNT);
                    total += self.stream_chunk(k);
                    left -= k;
                }
                total
            }
            Strategy::Memory => {
                let mut left = n;
                let mut total = Duration::ZERO;
                while left > 0 {
                    let k = left.min(MEMORY_READINGS);
                    total += self.burst_time(k) + self.fetch_time(k);
                    left -= k;
                }
                total
            }
            Strategy::Poll => {
                if n == 0 {
                    return Duration::ZERO;
                }
                self.command_time("SAMP:COUN 1")
                    + self.poll_time() * u32::try_from(n).unwrap_or(u32::MAX)
            }
        }
    }
}

/// The 34401A's timing in the multimeter role: the model at one configuration and the
/// strategy it acquires with (`Auto` resolved).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeterTiming {
    /// The model.
    pub timing: Timing,
    /// The strategy (never `Auto`).
    pub strategy: Strategy,
}

impl MeterTiming {
    /// The timing of a meter configured with `config` acquiring with `strategy`.
    pub fn new(config: &DcvConfig, strategy: Strategy) -> Self {
        let timing = Timing::new(config);
        MeterTiming {
            timing,
            strategy: timing.resolve(strategy),
        }
    }

    /// The readings of each memory burst of an `n`-reading acquisition.
    fn bursts(n: usize) -> impl Iterator<Item = usize> {
        let full = n / MEMORY_READINGS;
        let rest = n % MEMORY_READINGS;
        std::iter::repeat_n(MEMORY_READINGS, full).chain((rest > 0).then_some(rest))
    }

    /// The streaming bound: arming, then the readings or the wire, whichever is slower, and
    /// the last reading's characters (the host learns the acquisition is over from them).
    fn stream_bound(&self, n: usize) -> Duration {
        if n == 0 {
            return Duration::ZERO;
        }
        let t = &self.timing;
        let n32 = u32::try_from(n).unwrap_or(u32::MAX);
        let wire = t.wire_time_per_reading();
        let measure = (t.reading_time() * n32 + wire).max(t.reading_time() + wire * n32);
        t.arming_time() + measure
    }
}

impl gyrocal_meter::TimingModel for MeterTiming {
    fn reading_time(&self) -> Duration {
        self.timing.reading_time()
    }

    fn acquisition(&self) -> &'static str {
        match self.strategy {
            Strategy::Stream => "stream",
            Strategy::Memory => "memory",
            Strategy::Poll => "poll",
            Strategy::Auto => "auto",
        }
    }

    /// Streaming and polling: the whole acquisition is in the step (polling is judged against
    /// the streaming bound, which is why it scores badly). Memory: each burst is armed,
    /// measured and fetched in turn (the meter cannot measure while it sends); the last
    /// burst's `FETC?` is deferred when asked.
    fn cost(&self, n: usize, defer: bool) -> gyrocal_meter::Cost {
        let t = &self.timing;
        match self.strategy {
            Strategy::Memory => {
                let mut cost = gyrocal_meter::Cost::default();
                let count = Self::bursts(n).count();
                for (i, k) in Self::bursts(n).enumerate() {
                    let k32 = u32::try_from(k).unwrap_or(u32::MAX);
                    cost.in_step += t.burst_time(k);
                    // arming, the readings, the `*OPC?` reply that says they are taken
                    cost.bound += t.arming_time() + t.reading_time() * k32 + t.wire_time(2);
                    let fetch = t.fetch_time(k);
                    let fetch_bound = t.wire_time(k * READING_CHARS + 1);
                    if defer && i + 1 == count {
                        cost.deferred = fetch;
                        cost.bound_deferred = fetch_bound;
                    } else {
                        cost.in_step += fetch;
                        cost.bound += fetch_bound;
                    }
                }
                cost
            }
            s => gyrocal_meter::Cost {
                in_step: t.estimate(s, n),
                deferred: Duration::ZERO,
                bound: self.stream_bound(n),
                bound_deferred: Duration::ZERO,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn nplc1() -> Timing {
        Timing::new(&DcvConfig {
            nplc: 1.0,
            ..DcvConfig::default()
        })
    }

    #[test]
    fn doc_figures() {
        let t = nplc1();
        assert_eq!(t.reading_time(), Duration::from_micros(41_500));
        let t10 = Timing::new(&DcvConfig {
            nplc: 10.0,
            ..DcvConfig::default()
        });
        assert_eq!(t10.reading_time(), Duration::from_micros(401_500));
        // 9600 baud: 872.7 characters/s, a reading every 18.33 ms: at most 54.5 readings/s
        assert!((1.0 / t.wire_time_per_reading().as_secs_f64() - 54.5).abs() < 0.1);
        // a FETC? of 512 readings takes about 9.4 s
        assert!((t.fetch_time(512).as_secs_f64() - 9.4).abs() < 0.05);
    }

    #[test]
    fn auto_picks_stream_when_the_wire_keeps_up() {
        assert_eq!(nplc1().resolve(Strategy::Auto), Strategy::Stream);
        let fast = Timing::new(&DcvConfig {
            nplc: 0.2,
            autozero: AutoZero::Off,
            ..DcvConfig::default()
        });
        assert_eq!(fast.resolve(Strategy::Auto), Strategy::Memory);
        let slow_wire = Timing::new(&DcvConfig {
            nplc: 1.0,
            baud: 1200,
            ..DcvConfig::default()
        });
        assert_eq!(slow_wire.resolve(Strategy::Auto), Strategy::Memory);
    }

    #[test]
    fn poll_is_slowest() {
        let t = nplc1();
        let s = t.estimate(Strategy::Stream, 500);
        let p = t.estimate(Strategy::Poll, 500);
        let m = t.estimate(Strategy::Memory, 500);
        assert!(s < m && m < p, "{s:?} {m:?} {p:?}");
        // 20 ms + 500 x 41.5 ms = 20.77 s, plus the command and the last reading on the wire
        assert!((s.as_secs_f64() - 20.77).abs() / 20.77 < 0.01, "{s:?}");
    }
}
