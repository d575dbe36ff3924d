//! The HP 34401A in the multimeter role ([`gyrocal_meter::Multimeter`]).
//!
//! The run asks for N readings; how they are taken is this meter's business: streamed with
//! `READ?` (the transfer overlaps the measurement), polled, or measured into the 512-reading
//! memory in bursts (`INIT;*OPC?`, then `FETC?`). In memory mode every burst but the last is
//! fetched at once, and the last may be left in the meter ([`Measured::Pending`]) so its
//! `FETC?` (9.4 s for 512 readings at 9600 baud) overlaps the table's next ramp. Retries are
//! counted here, once: a failed burst or transfer is recovered (device clear, or a full
//! re-establish after a power cycle) and taken again, up to [`DriverOptions::retries`] per
//! measurement, and every recovery is described in the returned [`Acquired`].

use gyrocal_link::Transport;
use gyrocal_meter::{Acquired, DcVolts, Identity, Measured, Multimeter, ProgressFn, TimingModel};

use crate::timing::{MEMORY_READINGS, MeterTiming};
use crate::{
    AutoZero, Burst, DcvConfig, DriverOptions, Error, ErrorKind, Hp34401a, Reading, Strategy,
    Timing,
};

/// A 34401A as a [`Multimeter`]: the driver plus the choices a plan makes for it (how to
/// acquire, and the baud rate its timing model needs).
pub struct Hp34401aMeter<T: Transport> {
    driver: Hp34401a<T>,
    strategy: Strategy,
    baud: u32,
    gpib: bool,
}

/// The last memory burst of a measurement, still in the meter, with the readings before it.
#[derive(Debug)]
pub struct PendingBurst {
    burst: Burst,
    earlier: Acquired,
    retries_left: u32,
}

impl<T: Transport> Hp34401aMeter<T> {
    /// The meter on `link`, acquiring with `strategy` (`Auto`: streaming when the wire keeps
    /// up, else memory); `baud` is the link's speed (the timing model's wire time).
    pub fn new(link: T, options: DriverOptions, strategy: Strategy, baud: u32) -> Self {
        Hp34401aMeter {
            driver: Hp34401a::new(link, options),
            strategy,
            baud,
            gpib: false,
        }
    }

    /// The meter is reached over GPIB (through a controller): its timing model uses the bus's
    /// wire time, not the baud rate's.
    pub fn over_gpib(mut self, gpib: bool) -> Self {
        self.gpib = gpib;
        self
    }

    /// The driver underneath.
    pub fn driver(&self) -> &Hp34401a<T> {
        &self.driver
    }

    /// The driver underneath, mutably.
    pub fn driver_mut(&mut self) -> &mut Hp34401a<T> {
        &mut self.driver
    }

    /// The strategy measurements use at the configured settings (`Auto` resolved).
    pub fn strategy(&self) -> Strategy {
        match self.driver.timing() {
            Some(t) => t.resolve(self.strategy),
            None => self.strategy,
        }
    }

    /// A failed exchange: recover and count it, or give up with `e` when the budget is spent
    /// or `e` is not retryable.
    ///
    /// After a timeout the late reply is waited for first ([`Hp34401a::await_late_reply`]):
    /// thrown away if it comes, and the deadlines widened.
    async fn recover_or(&mut self, e: Error, acc: &mut Acquired, what: &str) -> Result<(), Error> {
        let allowed = self.driver.options().retries;
        if !e.is_retryable() {
            return Err(e);
        }
        let late = if e.kind() == ErrorKind::Timeout {
            self.driver.await_late_reply(&e).await
        } else {
            None
        };
        if acc.retries >= allowed {
            return Err(Error::GaveUp {
                device: self.driver.device().to_string(),
                attempts: acc.retries + 1,
                slow: self.driver.slow_note(),
                last: Box::new(e),
            });
        }
        acc.retries += 1;
        let r = self.driver.recover().await?;
        let r = crate::Recovery { late, ..r };
        acc.notes.push(format!(
            "{what} failed ({e}); {}; taken again (retry {})",
            r.describe(),
            acc.retries
        ));
        Ok(())
    }

    /// One burst armed and waited for (retried).
    async fn burst(&mut self, k: usize, acc: &mut Acquired) -> Result<Burst, Error> {
        loop {
            let b = async {
                let b = self.driver.arm_burst(k).await?;
                self.driver.wait_burst(&b).await?;
                Ok::<_, Error>(b)
            }
            .await;
            match b {
                Ok(b) => return Ok(b),
                Err(e) => self.recover_or(e, acc, "memory burst").await?,
            }
        }
    }

    /// `FETC?` of `burst`, a garbled transfer fetched again (the readings stay in memory until
    /// the next `INIT`). `ReadingsLost` goes back to the caller.
    async fn fetch(&mut self, burst: &Burst, acc: &mut Acquired) -> Result<Vec<Reading>, Error> {
        loop {
            match self.driver.fetch(burst).await {
                Ok(r) => return Ok(r),
                Err(e) if e.kind() == ErrorKind::ReadingsLost => return Err(e),
                Err(e) => self.recover_or(e, acc, "FETC?").await?,
            }
        }
    }

    async fn measure_memory(
        &mut self,
        n: usize,
        may_defer: bool,
    ) -> Result<Measured<PendingBurst>, Error> {
        let mut acc = Acquired::default();
        while acc.readings.len() < n {
            let k = (n - acc.readings.len()).min(MEMORY_READINGS);
            let last = acc.readings.len() + k >= n;
            let burst = self.burst(k, &mut acc).await?;
            if last && may_defer {
                let retries_left = self.driver.options().retries.saturating_sub(acc.retries);
                return Ok(Measured::Pending(PendingBurst {
                    burst,
                    earlier: acc,
                    retries_left,
                }));
            }
            match self.fetch(&burst, &mut acc).await {
                Ok(r) => acc.readings.extend(r),
                // lost with a power cycle while we waited: the burst is measured again
                Err(e) if e.kind() == ErrorKind::ReadingsLost && acc.retries < self.retries() => {
                    acc.retries += 1;
                    acc.notes.push(format!("{e}; burst measured again"));
                }
                Err(e) => return Err(e),
            }
        }
        Ok(Measured::Complete(acc))
    }

    fn retries(&self) -> u32 {
        self.driver.options().retries
    }
}

impl<T: Transport + 'static> Multimeter for Hp34401aMeter<T> {
    type Error = Error;
    type Pending = PendingBurst;

    fn describe(&self) -> &str {
        self.driver.device()
    }

    async fn connect(&mut self) -> Result<Identity, Error> {
        let id = self.driver.connect().await?;
        let fields: Vec<&str> = id.raw.split(',').map(str::trim).collect();
        let field = |i: usize| fields.get(i).copied().unwrap_or("").to_string();
        Ok(Identity {
            raw: id.raw.clone(),
            manufacturer: field(0),
            model: field(1),
            serial: field(2),
            version: field(3),
        })
    }

    async fn configure(&mut self, s: &DcVolts) -> Result<(), Error> {
        let config = DcvConfig {
            range: s.range_v,
            nplc: s.nplc,
            autozero: if s.autozero {
                AutoZero::On
            } else {
                AutoZero::Off
            },
            line_hz: s.line_hz,
            baud: self.baud,
            gpib: self.gpib,
            ..DcvConfig::default()
        };
        self.driver.configure(&config).await
    }

    fn timing(&self) -> Option<Box<dyn TimingModel>> {
        self.driver.timing().map(|timing: Timing| {
            Box::new(MeterTiming {
                timing,
                strategy: timing.resolve(self.strategy),
            }) as Box<dyn TimingModel>
        })
    }

    async fn measure(
        &mut self,
        n: usize,
        may_defer: bool,
    ) -> Result<Measured<PendingBurst>, Error> {
        match self.strategy() {
            Strategy::Memory => self.measure_memory(n, may_defer).await,
            s => {
                let acq = self.driver.acquire(n, s).await?;
                let mut notes: Vec<String> = acq
                    .recoveries
                    .iter()
                    .map(|r| format!("acquisition retried: {}", r.describe()))
                    .collect();
                let unexplained = (acq.retries as usize).saturating_sub(notes.len());
                if unexplained > 0 {
                    notes.push(format!(
                        "{unexplained} acquisition retries after device clear (see log)"
                    ));
                }
                Ok(Measured::Complete(Acquired {
                    readings: acq.readings,
                    retries: acq.retries,
                    notes,
                }))
            }
        }
    }

    async fn collect(&mut self, pending: PendingBurst) -> Result<Acquired, Error> {
        let PendingBurst {
            burst,
            mut earlier,
            retries_left,
        } = pending;
        // the budget left by the measurement applies to its transfer
        let mut acc = Acquired {
            retries: self.retries().saturating_sub(retries_left),
            ..Acquired::default()
        };
        let base = acc.retries;
        let readings = self.fetch(&burst, &mut acc).await?;
        earlier.readings.extend(readings);
        earlier.retries += acc.retries - base;
        earlier.notes.extend(acc.notes);
        Ok(earlier)
    }

    async fn recover(&mut self) -> Result<String, Error> {
        self.driver.recover().await.map(|r| r.describe())
    }

    async fn release(&mut self) -> Result<(), Error> {
        self.driver.local().await
    }

    fn set_progress(&mut self, progress: Option<ProgressFn>) {
        match progress {
            Some(f) => self.driver.set_progress(f),
            None => self.driver.clear_progress(),
        }
    }
}
