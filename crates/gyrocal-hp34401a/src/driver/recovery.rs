//! Recovery: what [`Hp34401a::recover`] does after a timeout or a garbled reply (device clear,
//! the error queue read, the Power On bit), re-establishing a lost link (a power cycle, a meter
//! in LOCAL), and the retry budget of a failed exchange ([`LinkLoss`], [`Recovery`]).

use std::time::Duration;

use gyrocal_link::Transport;
use gyrocal_meter::scpi::{ErrorQueue, NotAnEntry, list};
use tokio::time::Instant;

use super::{Hp34401a, Identity};
use crate::{Error, ErrorKind, InstrumentError};

/// Why [`Hp34401a::recover`] re-established the link instead of a plain device clear.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LinkLoss {
    /// The meter did not answer `SYST:ERR?` after the device clear: switched off, rebooting,
    /// unplugged, or in LOCAL (a 34401A back from a power cycle is in LOCAL, where RS-232
    /// queries may go unanswered).
    NoAnswer,
    /// The error queue held 550 "Command not allowed in local": the meter is in LOCAL (a power
    /// cycle, or someone pressed LOCAL).
    Local,
    /// `*ESR?` had the Power On bit (128) set: the meter was switched off and on since the
    /// driver cleared it (`*CLS` at connect), so its configuration and memory are gone.
    PowerOn,
}

impl LinkLoss {
    /// What cleared the meter's memory when the link was re-established for this cause, for
    /// [`Error::ReadingsLost`]: a power cycle, or gyrocal's own reconfiguration.
    pub fn memory_cause(self) -> &'static str {
        match self {
            LinkLoss::PowerOn => "the meter was power-cycled: its Power On status bit was set",
            LinkLoss::Local => {
                "the meter was found in LOCAL (error 550) and gyrocal configured it again, \
                 which clears its memory"
            }
            LinkLoss::NoAnswer => {
                "gyrocal configured the meter again after it did not answer, which clears its \
                 memory; no power cycle was seen: its replies may be too late or lost"
            }
        }
    }
}

impl std::fmt::Display for LinkLoss {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            LinkLoss::NoAnswer => "the meter did not answer after a device clear",
            LinkLoss::Local => "the meter reported 550 \"Command not allowed in local\"",
            LinkLoss::PowerOn => "the meter's Power On status bit was set (power cycle)",
        })
    }
}

/// What [`Hp34401a::recover`] did.
#[derive(Debug, Clone, PartialEq)]
pub struct Recovery {
    /// The entries that were in the meter's error queue after the device clear, oldest first
    /// (empty when the meter had lost its queue).
    pub errors: Vec<InstrumentError>,
    /// True when the link was re-established as at connect (`SYST:REM`, `*CLS`, `*IDN?`, the
    /// configuration applied again): readings in the meter's memory from before are gone, and
    /// a caller should log this as a retry.
    pub reestablished: bool,
    /// Why the link was re-established (`None` for a plain device clear).
    pub cause: Option<LinkLoss>,
    /// Attempts at re-establishing the link (0 for a plain device clear).
    pub attempts: u32,
    /// How long the recovery took.
    pub elapsed: Duration,
    /// The late reply seen before it (see [`Hp34401a::await_late_reply`]), if one came.
    pub late: Option<String>,
}

impl Recovery {
    /// One line for a log or a run manifest.
    pub fn describe(&self) -> String {
        let what = self.what();
        match &self.late {
            Some(late) => format!("{late}; {what}"),
            None => what,
        }
    }

    fn what(&self) -> String {
        match self.cause {
            Some(cause) => format!(
                "link re-established ({cause}; {} attempt{}, {:.1} s): SYST:REM, *CLS, *IDN? and \
                 the configuration sent again",
                self.attempts,
                if self.attempts == 1 { "" } else { "s" },
                self.elapsed.as_secs_f64()
            ),
            None if self.errors.is_empty() => "device clear".to_string(),
            None => format!("device clear; error queue: {}", list(&self.errors)),
        }
    }
}

impl<T: Transport> Hp34401a<T> {
    /// Reads the whole error queue (until `+0,"No error"`), oldest first.
    /// At most [`gyrocal_meter::scpi::ERROR_QUEUE_READS`] queries (the role's [`ErrorQueue`]).
    pub async fn drain_errors(&mut self) -> Result<Vec<InstrumentError>, Error> {
        let mut queue = ErrorQueue::new();
        while let Some(q) = queue.next_query() {
            let reply = self.query(q, self.options.query_timeout).await?;
            queue
                .accept(&reply)
                .map_err(|NotAnEntry(reply)| Error::InvalidReply {
                    device: self.device().to_string(),
                    expected: NotAnEntry::EXPECTED,
                    bytes: reply.into_bytes(),
                })?;
        }
        Ok(queue.into_entries())
    }

    /// Recovery after a timeout or a garbled reply. It escalates:
    ///
    /// 1. a plain recovery, as cheap as it can be, since most failures are one lost or garbled
    ///    reply: device clear (0x03), stale input thrown away, error queue drained
    ///    (`SYST:ERR?`), then `*ESR?` to look at the Power On bit;
    /// 2. when that shows the link lost ([`LinkLoss`]: no answer to `SYST:ERR?`, error 550
    ///    "not allowed in local" in the queue, or the Power On bit set), the link is
    ///    re-established as at connect: device clear, `SYST:REM` (or `SYST:RWL`), `*CLS`,
    ///    `*IDN?` checked to be a 34401A, the configuration of [`Hp34401a::configure`] sent
    ///    again, the error queue drained (it must be empty). A meter that does not answer is
    ///    tried again every [`crate::DriverOptions::reconnect_pause`] until
    ///    [`crate::DriverOptions::reconnect_timeout`] after the start of the recovery, then
    ///    [`Error::NotBack`].
    ///
    /// Why not always the full sequence: a plain recovery costs two short exchanges and keeps
    /// the meter's memory valid (a burst can be fetched again after a garbled `FETC?`); the full
    /// one resends the configuration and makes every burst armed before it
    /// [`Error::ReadingsLost`], which is only right when the meter may have lost them. A
    /// 34401A back from a power cycle cannot be missed: it was dead for a while (the failed
    /// exchange and `SYST:ERR?` time out), it comes back in LOCAL (550, or no answer), and its
    /// Power On bit is set until `*CLS` (even a meter that answers in LOCAL shows it).
    ///
    /// A garbled reply to `SYST:ERR?` or `*ESR?` is returned as an error (the caller's retry
    /// budget counts it), as before.
    ///
    /// Limit: the driver looks for a power cycle only here, after a failed exchange. A power
    /// cycle while the driver is idle (between two acquisitions) is caught by the next
    /// exchange when the meter ignores or refuses commands in LOCAL, as the simulator does by
    /// default and the manual's error 550 suggests for `READ?`; a meter that obeyed every
    /// command in LOCAL would measure at its power-on settings until something fails.
    pub async fn recover(&mut self) -> Result<Recovery, Error> {
        let started = Instant::now();
        self.sample_count = None;
        self.device_clear().await?;
        let (errors, cause) = match self.drain_errors().await {
            Ok(errors) => {
                for e in &errors {
                    tracing::info!(device = self.device(), error = %e, "error queue entry after device clear");
                }
                if errors.iter().any(|e| e.code == 550) {
                    (errors, LinkLoss::Local)
                } else {
                    match self.power_on_bit().await {
                        Ok(false) => {
                            return Ok(Recovery {
                                errors,
                                reestablished: false,
                                cause: None,
                                attempts: 0,
                                elapsed: started.elapsed(),
                                late: None,
                            });
                        }
                        Ok(true) => (errors, LinkLoss::PowerOn),
                        Err(e) if e.kind() == ErrorKind::Timeout => (errors, LinkLoss::NoAnswer),
                        Err(e) => return Err(e),
                    }
                }
            }
            Err(e) if e.kind() == ErrorKind::Timeout => (Vec::new(), LinkLoss::NoAnswer),
            Err(e) => return Err(e),
        };
        // whatever the meter held may be gone: bursts armed until now cannot be fetched
        self.epoch += 1;
        self.last_loss = Some(cause);
        tracing::warn!(device = self.device(), %cause, "multimeter link lost; re-establishing it");
        let attempts = self.reestablish(started).await?;
        let recovery = Recovery {
            errors,
            reestablished: true,
            cause: Some(cause),
            attempts,
            elapsed: started.elapsed(),
            late: None,
        };
        tracing::warn!(device = self.device(), what = %recovery.describe(), "multimeter link re-established");
        Ok(recovery)
    }

    /// `*ESR?`: whether the Power On bit (128) of the Standard Event register is set (the
    /// query clears the register).
    async fn power_on_bit(&mut self) -> Result<bool, Error> {
        let reply = self.query("*ESR?", self.options.query_timeout).await?;
        let value: u16 =
            reply
                .trim()
                .trim_start_matches('+')
                .parse()
                .map_err(|_| Error::InvalidReply {
                    device: self.device().to_string(),
                    expected: "a number from *ESR?",
                    bytes: reply.clone().into_bytes(),
                })?;
        Ok(value & 128 != 0)
    }

    /// Re-establishes the link until it works or `reconnect_timeout` after `started`; returns
    /// the attempts made.
    async fn reestablish(&mut self, started: Instant) -> Result<u32, Error> {
        let deadline = started + self.options.reconnect_timeout;
        let mut attempts = 0;
        loop {
            attempts += 1;
            let error = match self.reestablish_once(deadline).await {
                Ok(()) => return Ok(attempts),
                Err(e) => e,
            };
            // no answer, a garbled answer, or (garbled) another identity: try again in time
            let again = error.is_retryable() || error.kind() == ErrorKind::Identity;
            if !again {
                return Err(error);
            }
            let now = Instant::now();
            if now >= deadline {
                return Err(Error::NotBack {
                    device: self.device().to_string(),
                    waited: now - started,
                    slow: self.slow_note(),
                    last: Box::new(error),
                });
            }
            tracing::info!(device = self.device(), attempt = attempts, %error, "multimeter not back yet");
            tokio::time::sleep(self.options.reconnect_pause.min(deadline - now)).await;
        }
    }

    /// One attempt: device clear, `SYST:REM`, `*CLS`, `*IDN?` (its timeout cut at `deadline`),
    /// the configuration again, the error queue drained (must be empty).
    async fn reestablish_once(&mut self, deadline: Instant) -> Result<(), Error> {
        self.device_clear().await?;
        if let Some(remote) = self.remote_command() {
            self.command(remote).await?;
        }
        self.command("*CLS").await?;
        let left = deadline.saturating_duration_since(Instant::now());
        let timeout = self
            .options
            .query_timeout
            .min(left)
            .max(Duration::from_millis(100));
        let reply = self.query("*IDN?", timeout).await?;
        let Some(id) = Identity::parse(&reply) else {
            return Err(Error::NotA34401A {
                device: self.device().to_string(),
                reply,
            });
        };
        if self.identity.as_ref().is_some_and(|old| old.raw != id.raw) {
            tracing::warn!(device = self.device(), idn = %id.raw, "another 34401A answers now");
        }
        self.identity = Some(id);
        match self.config.clone() {
            Some(config) => {
                self.apply(
                    &config,
                    "re-applying the configuration after re-establishing the link",
                )
                .await
            }
            None => {
                let errors = self.drain_errors().await?;
                if errors.is_empty() {
                    Ok(())
                } else {
                    Err(Error::Instrument {
                        device: self.device().to_string(),
                        context: "re-establishing the link".into(),
                        errors,
                    })
                }
            }
        }
    }

    /// Decides after a failed step: retry (after recovery, returned) or give up.
    pub(super) async fn after_failure(
        &mut self,
        error: Error,
        failures: &mut u32,
    ) -> Result<Recovery, Error> {
        let mut error = error;
        loop {
            if !error.is_retryable() {
                return Err(error);
            }
            let late = if error.kind() == ErrorKind::Timeout {
                self.await_late_reply(&error).await
            } else {
                None
            };
            if *failures >= self.options.retries {
                return Err(Error::GaveUp {
                    device: self.device().to_string(),
                    attempts: *failures + 1,
                    slow: self.slow_note(),
                    last: Box::new(error),
                });
            }
            *failures += 1;
            tracing::warn!(
                device = self.device(),
                retry = *failures,
                of = self.options.retries,
                %error,
                "acquisition step failed; device clear and retry"
            );
            match self.recover().await {
                Ok(r) => return Ok(Recovery { late, ..r }),
                Err(e) => error = e,
            }
        }
    }
}
