//! Acquisition: [`Hp34401a::acquire`] by streaming (`READ?`), memory bursts (`INIT;*OPC?`,
//! `FETC?`, [`Burst`]) or polling, each part retried after a recovery, and the readings'
//! parsing and progress ([`Acquisition`]).

use std::time::Duration;

use gyrocal_link::Transport;
use tokio::time::Instant;

use super::{Hp34401a, LinkLoss, Progress, Recovery};
use crate::timing::{MAX_SAMPLE_COUNT, MEMORY_READINGS, Strategy, Timing};
use crate::{Error, Reading, TriggerSource, parse_reading};

/// The result of [`Hp34401a::acquire`].
#[derive(Debug, Clone, PartialEq)]
pub struct Acquisition {
    /// Every reading, in order, overloads included.
    pub readings: Vec<Reading>,
    /// The strategy used (`Auto` resolved).
    pub strategy: Strategy,
    /// Retries needed (each after a [`Hp34401a::recover`]).
    pub retries: u32,
    /// What each of those recoveries did, in order ([`Recovery::reestablished`] tells a re-established
    /// link, whose failed part was measured again after the configuration was sent again).
    pub recoveries: Vec<Recovery>,
    /// When the acquisition started (tokio clock).
    pub started: Instant,
    /// How long it took.
    pub elapsed: Duration,
}

impl Acquisition {
    /// The voltages, overloads left out.
    pub fn volts(&self) -> Vec<f64> {
        self.readings.iter().filter_map(|r| r.volts()).collect()
    }

    /// How many readings were overloads.
    pub fn overloads(&self) -> usize {
        self.readings.iter().filter(|r| r.is_overload()).count()
    }

    /// How many of the recoveries re-established the link (a power cycle, a meter in LOCAL).
    pub fn reestablished(&self) -> usize {
        self.recoveries.iter().filter(|r| r.reestablished).count()
    }
}

/// A memory burst in progress: from [`Hp34401a::arm_burst`] to [`Hp34401a::fetch`].
#[derive(Debug, Clone, PartialEq)]
pub struct Burst {
    /// Readings the burst takes.
    pub count: usize,
    /// When `INIT;*OPC?` was sent.
    pub armed_at: Instant,
    /// Expected time from arming to the `1` of `*OPC?`.
    pub expected: Duration,
    /// [`Hp34401a::link_epoch`] when armed: a burst from an older epoch is lost.
    epoch: u64,
}

impl<T: Transport> Hp34401a<T> {
    /// Acquires `n` readings with `strategy`, retrying each step (the stream, a memory burst, a
    /// polled reading) after a timeout or garbled reply up to [`crate::DriverOptions::retries`] times
    /// in all, with [`Hp34401a::recover`] before each retry.
    pub async fn acquire(&mut self, n: usize, strategy: Strategy) -> Result<Acquisition, Error> {
        let timing = self.acquisition_timing()?;
        let strategy = timing.resolve(strategy);
        let started = Instant::now();
        tracing::debug!(
            device = self.device(),
            n,
            ?strategy,
            expected_s = timing.estimate(strategy, n).as_secs_f64(),
            "acquisition"
        );
        let mut readings = Vec::with_capacity(n);
        let mut failures = 0;
        let mut recoveries = Vec::new();
        match strategy {
            Strategy::Stream | Strategy::Auto => {
                while readings.len() < n {
                    let k = (n - readings.len()).min(MAX_SAMPLE_COUNT);
                    match self.stream(k, readings.len(), n, &timing).await {
                        Ok(r) => readings.extend(r),
                        Err(e) => recoveries.push(self.after_failure(e, &mut failures).await?),
                    }
                }
            }
            Strategy::Memory => {
                while readings.len() < n {
                    let k = (n - readings.len()).min(MEMORY_READINGS);
                    let base = readings.len();
                    match self.burst(k, base, n).await {
                        Ok(r) => readings.extend(r),
                        Err(e) => recoveries.push(self.after_failure(e, &mut failures).await?),
                    }
                }
            }
            Strategy::Poll => {
                while readings.len() < n {
                    let step = async {
                        self.set_sample_count(1).await?;
                        self.poll_once(&timing).await
                    };
                    match step.await {
                        Ok(r) => {
                            readings.push(r);
                            self.report(readings.len(), n, r);
                        }
                        Err(e) => {
                            recoveries.push(self.after_failure(e, &mut failures).await?);
                        }
                    }
                }
            }
        }
        Ok(Acquisition {
            readings,
            strategy,
            retries: failures,
            recoveries,
            started,
            elapsed: started.elapsed(),
        })
    }

    /// Memory mode, first step: `SAMP:COUN n` and `INIT;*OPC?` (1 <= n <= 512). The meter now
    /// measures and hears nothing until the burst ends; the `*OPC?` is outstanding, so send
    /// nothing to the meter before [`Hp34401a::wait_burst`]. No retries at this level.
    pub async fn arm_burst(&mut self, n: usize) -> Result<Burst, Error> {
        let timing = self.acquisition_timing()?;
        if n == 0 || n > MEMORY_READINGS {
            return Err(Error::Config(format!(
                "a memory burst holds 1 to 512 readings, not {n}"
            )));
        }
        self.set_sample_count(n).await?;
        self.send_query("INIT;*OPC?").await?;
        let expected = timing.burst_time(n);
        Ok(Burst {
            count: n,
            armed_at: Instant::now(),
            expected,
            epoch: self.epoch,
        })
    }

    /// [`Error::ReadingsLost`] for a burst armed before the link was last re-established.
    fn check_epoch(&self, burst: &Burst) -> Result<(), Error> {
        if burst.epoch == self.epoch {
            return Ok(());
        }
        Err(Error::ReadingsLost {
            device: self.device().to_string(),
            count: burst.count,
            cause: self
                .last_loss
                .map_or("the link was re-established", LinkLoss::memory_cause)
                .to_string(),
        })
    }

    /// Memory mode, second step: waits for the `1` that ends the burst. A burst armed before
    /// the link was re-established is [`Error::ReadingsLost`] (nothing is read).
    pub async fn wait_burst(&mut self, burst: &Burst) -> Result<(), Error> {
        self.check_epoch(burst)?;
        let deadline = burst.armed_at + self.scaled(burst.expected);
        let timeout = deadline
            .saturating_duration_since(Instant::now())
            .max(self.options.timeout_slack)
            + self.late.reply_delay();
        let reply = self.link.read_line(Some(timeout)).await?;
        self.in_flight = 0;
        if reply.trim() != "1" {
            return Err(Error::InvalidReply {
                device: self.device().to_string(),
                expected: "1 from *OPC? at the end of the burst",
                bytes: reply.into_bytes(),
            });
        }
        Ok(())
    }

    /// Memory mode, third step: `FETC?` and the burst's readings, parsed as they arrive. The
    /// table can move meanwhile (it is on another link).
    ///
    /// A burst armed before [`Hp34401a::recover`] re-established the link (the meter was
    /// power-cycled or found in LOCAL; its memory is empty or not this burst's) fails at once
    /// with [`Error::ReadingsLost`], never with other readings: arm a new burst.
    pub async fn fetch(&mut self, burst: &Burst) -> Result<Vec<Reading>, Error> {
        self.fetch_progress(burst, 0, burst.count).await
    }

    async fn fetch_progress(
        &mut self,
        burst: &Burst,
        base: usize,
        total: usize,
    ) -> Result<Vec<Reading>, Error> {
        self.check_epoch(burst)?;
        let timing = self.acquisition_timing()?;
        self.send_query("FETC?").await?;
        let first = self.scaled(timing.command_time("FETC?") + timing.wire_time_per_reading());
        let next = self.scaled(timing.wire_time_per_reading());
        self.read_readings(burst.count, first, next, base, total)
            .await
    }

    async fn burst(&mut self, k: usize, base: usize, total: usize) -> Result<Vec<Reading>, Error> {
        let b = self.arm_burst(k).await?;
        self.wait_burst(&b).await?;
        self.fetch_progress(&b, base, total).await
    }

    async fn stream(
        &mut self,
        k: usize,
        base: usize,
        total: usize,
        timing: &Timing,
    ) -> Result<Vec<Reading>, Error> {
        self.set_sample_count(k).await?;
        self.send_query("READ?").await?;
        let first = self.scaled(
            timing.command_time("READ?")
                + timing.arming_time()
                + timing.reading_time()
                + timing.wire_time_per_reading(),
        );
        let next = self.scaled(timing.reading_time().max(timing.wire_time_per_reading()));
        self.read_readings(k, first, next, base, total).await
    }

    /// `SAMP:COUN k`, unless the meter already holds `k`.
    async fn set_sample_count(&mut self, k: usize) -> Result<(), Error> {
        if self.sample_count == Some(k) {
            return Ok(());
        }
        self.sample_count = None;
        self.command(&format!("SAMP:COUN {k}")).await?;
        self.sample_count = Some(k);
        Ok(())
    }

    async fn poll_once(&mut self, timing: &Timing) -> Result<Reading, Error> {
        let reply = self.query("READ?", self.scaled(timing.poll_time())).await?;
        parse_reading(&reply).ok_or_else(|| Error::InvalidReply {
            device: self.device().to_string(),
            expected: "one reading",
            bytes: reply.into_bytes(),
        })
    }

    /// Reads `k` comma-separated readings ending one line, parsing each as it arrives.
    async fn read_readings(
        &mut self,
        k: usize,
        first: Duration,
        next: Duration,
        base: usize,
        total: usize,
    ) -> Result<Vec<Reading>, Error> {
        let mut out = Vec::with_capacity(k);
        let mut timeout = first + self.late.reply_delay();
        loop {
            let field = self.link.read_field(b',', Some(timeout)).await?;
            for piece in field.text.split(',') {
                if out.len() >= k {
                    return Err(self.wrong_count(k, out.len() + 1));
                }
                let r = parse_reading(piece).ok_or_else(|| Error::InvalidReply {
                    device: self.device().to_string(),
                    expected: "a reading",
                    bytes: piece.as_bytes().to_vec(),
                })?;
                out.push(r);
                self.report(base + out.len(), total, r);
            }
            if field.end_of_line {
                break;
            }
            timeout = next;
        }
        self.in_flight = 0;
        if out.len() != k {
            return Err(self.wrong_count(k, out.len()));
        }
        Ok(out)
    }

    fn wrong_count(&self, expected: usize, got: usize) -> Error {
        Error::WrongCount {
            device: self.device().to_string(),
            expected,
            got,
        }
    }

    fn report(&mut self, done: usize, total: usize, latest: Reading) {
        if let Some(f) = self.progress.as_mut() {
            f(Progress {
                done,
                total,
                latest,
            });
        }
    }

    fn acquisition_timing(&self) -> Result<Timing, Error> {
        let config = self.config.as_ref().ok_or(Error::NotConfigured)?;
        if config.trigger_source != TriggerSource::Immediate {
            return Err(Error::Config(
                "acquisition needs the immediate trigger source (TRIG:SOUR IMM)".into(),
            ));
        }
        Ok(Timing::new(config))
    }
}
