//! [`Hp34401a`]: the driver proper.

use std::time::Duration;

use gyrocal_link::{LinkError, Transport};
use gyrocal_meter::LateReplies;
use tokio::time::Instant;

use crate::timing::{MAX_SAMPLE_COUNT, MEMORY_READINGS, Strategy, Timing};
use crate::{DcvConfig, Error, ErrorKind, InstrumentError, Reading, TriggerSource, parse_reading};

/// Driver settings that are not the meter's measurement configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct DriverOptions {
    /// How many times an acquisition step (a stream, a burst, a polled reading) is retried after
    /// a timeout or a garbled reply, with a device clear before each retry. Default 2.
    pub retries: u32,
    /// Timeout for short replies (`*IDN?`, `SYST:ERR?`, `*OPC?` after commands). Default 3 s,
    /// enough for `*IDN?` at 300 baud.
    pub query_timeout: Duration,
    /// Acquisition timeouts are `factor * expected + slack`, the expected time from the timing
    /// model. Default factor 1.5.
    pub timeout_factor: f64,
    /// See `timeout_factor`. Default 1 s.
    pub timeout_slack: Duration,
    /// Send `SYST:RWL` (also locks the front panel's LOCAL key) instead of `SYST:REM`.
    /// Default false.
    pub lock_front_panel: bool,
    /// Pause after a device clear before stale input is thrown away. Default 100 ms.
    pub clear_settle: Duration,
    /// Most characters of commands sent without a reply read in between; past it the driver
    /// inserts `*OPC?` and waits for its `1`. The meter's input buffer holds about 100.
    /// Default 80.
    pub in_flight_budget: usize,
    /// How long [`Hp34401a::recover`] keeps trying to re-establish the link with a meter that
    /// stopped answering (switched off, unplugged, rebooting) before it gives up with
    /// [`Error::NotBack`]. Counted from the start of the recovery. Default 30 s.
    pub reconnect_timeout: Duration,
    /// Pause between two attempts to re-establish the link. Default 1 s.
    pub reconnect_pause: Duration,
    /// After a reply timeout, how long the driver waits for the late reply before its
    /// recovery. When it comes it is thrown away (never taken as the next query's answer),
    /// every later deadline is widened by about twice the lateness seen (at most
    /// [`DriverOptions::max_reply_delay`]), and each device clear then waits until the link
    /// has been quiet that long, so bytes still on their way (a serial converter's deep
    /// buffer, a network bridge) are thrown away too. A reply later than this counts as lost.
    /// It is also what every lost reply costs. Default 3 s.
    pub late_reply_wait: Duration,
    /// The most the deadlines are widened by for a meter seen answering late. Default 5 s.
    pub max_reply_delay: Duration,
}

impl Default for DriverOptions {
    fn default() -> Self {
        DriverOptions {
            retries: 2,
            query_timeout: Duration::from_secs(3),
            timeout_factor: 1.5,
            timeout_slack: Duration::from_secs(1),
            lock_front_panel: false,
            clear_settle: Duration::from_millis(100),
            in_flight_budget: 80,
            reconnect_timeout: Duration::from_secs(30),
            reconnect_pause: Duration::from_secs(1),
            late_reply_wait: Duration::from_secs(3),
            max_reply_delay: Duration::from_secs(5),
        }
    }
}

/// What `*IDN?` said.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Identity {
    /// `HEWLETT-PACKARD` (later units: Agilent, Keysight).
    pub manufacturer: String,
    /// `34401A`.
    pub model: String,
    /// Serial field (`0` on the 34401A).
    pub serial: String,
    /// Firmware revisions, such as `11-5-2`.
    pub firmware: String,
    /// The whole reply.
    pub raw: String,
}

impl Identity {
    /// Parses a `*IDN?` reply; `None` unless it names a 34401A.
    pub fn parse(reply: &str) -> Option<Identity> {
        let f: Vec<&str> = reply.split(',').map(str::trim).collect();
        if f.len() != 4 || !f[1].eq_ignore_ascii_case("34401A") {
            return None;
        }
        Some(Identity {
            manufacturer: f[0].to_string(),
            model: f[1].to_string(),
            serial: f[2].to_string(),
            firmware: f[3].to_string(),
            raw: reply.to_string(),
        })
    }
}

/// Progress of an acquisition and its callback: the multimeter role's own types, so the
/// driver's progress reaches a run unchanged.
pub use gyrocal_meter::{Progress, ProgressFn};

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
            None => format!(
                "device clear; error queue: {}",
                self.errors
                    .iter()
                    .map(ToString::to_string)
                    .collect::<Vec<_>>()
                    .join("; ")
            ),
        }
    }
}

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

/// The HP 34401A driver, generic over its link.
///
/// Protocol rules it keeps: never more than one query outstanding (every reply is read before
/// anything else is sent); never more than [`DriverOptions::in_flight_budget`] characters of
/// commands unacknowledged; every command line short.
pub struct Hp34401a<T: Transport> {
    link: T,
    options: DriverOptions,
    identity: Option<Identity>,
    config: Option<DcvConfig>,
    in_flight: usize,
    progress: Option<ProgressFn>,
    epoch: u64,
    /// The `SAMP:COUN` the meter holds, as far as the driver knows (sent since the last
    /// connection, configuration or recovery): settings are sent only when they change.
    sample_count: Option<usize>,
    /// Why the link was last re-established (what cleared the memory, for
    /// [`Error::ReadingsLost`]).
    last_loss: Option<LinkLoss>,
    /// The widening of the reply deadlines after late replies.
    late: LateReplies,
}

impl<T: Transport> Hp34401a<T> {
    /// Wraps a link. Nothing is sent until [`Hp34401a::connect`].
    pub fn new(link: T, options: DriverOptions) -> Self {
        let late = LateReplies::new(
            options.max_reply_delay,
            options.timeout_slack,
            "DriverOptions::max_reply_delay",
        );
        Hp34401a {
            link,
            options,
            identity: None,
            config: None,
            in_flight: 0,
            progress: None,
            epoch: 0,
            sample_count: None,
            last_loss: None,
            late,
        }
    }

    /// What every reply deadline has been widened by, after replies came late (zero for a
    /// meter that answers in time).
    pub fn reply_delay(&self) -> Duration {
        self.late.reply_delay()
    }

    /// After a query timed out: waits up to [`DriverOptions::late_reply_wait`] for its late
    /// reply. When something comes, the meter is alive but slow: what came is thrown away
    /// (the caller's recovery clears the rest), the deadlines are widened, and the returned
    /// note says so. `None` when nothing came (the reply was lost, or the meter is gone).
    ///
    /// Only one query is ever outstanding (see the type's protocol rules), so whatever comes
    /// now can only be the answer to the one that timed out. `timed_out` is that timeout's
    /// error: the unterminated bytes it held came in time and are no sign of a late reply.
    pub async fn await_late_reply(&mut self, timed_out: &Error) -> Option<String> {
        let already = match timed_out {
            Error::Link(LinkError::Timeout { partial, .. }) => partial.len(),
            _ => 0,
        };
        let waited_from = Instant::now();
        let got = self
            .link
            .read_field(b',', Some(self.options.late_reply_wait))
            .await;
        let came = match &got {
            Ok(_) => true,
            Err(LinkError::Timeout { partial, .. }) => partial.len() > already,
            Err(_) => false,
        };
        if !came {
            return None;
        }
        let late = waited_from.elapsed();
        let note = self.late.saw(late);
        tracing::warn!(
            device = self.device(),
            late_s = late.as_secs_f64(),
            reply_delay_s = self.late.reply_delay().as_secs_f64(),
            "the multimeter answers late; its late reply is thrown away and deadlines widened"
        );
        Some(note)
    }

    /// For [`Error::GaveUp`]: what was seen of a slow meter, or nothing.
    pub fn slow_note(&self) -> String {
        self.late.note()
    }

    /// The link's description.
    pub fn device(&self) -> &str {
        self.link.describe()
    }

    /// The identity read by [`Hp34401a::connect`].
    pub fn identity(&self) -> Option<&Identity> {
        self.identity.as_ref()
    }

    /// The configuration applied by [`Hp34401a::configure`].
    pub fn config(&self) -> Option<&DcvConfig> {
        self.config.as_ref()
    }

    /// The timing model of the applied configuration.
    pub fn timing(&self) -> Option<Timing> {
        self.config.as_ref().map(Timing::new)
    }

    /// How many times [`Hp34401a::recover`] has found the link lost (the meter dead, in LOCAL
    /// or powered on again) since the driver was made. Bursts armed in an earlier epoch cannot
    /// be fetched ([`Error::ReadingsLost`]).
    pub fn link_epoch(&self) -> u64 {
        self.epoch
    }

    /// The driver options.
    pub fn options(&self) -> &DriverOptions {
        &self.options
    }

    /// Calls `f` with every reading received ("acquiring k of N").
    pub fn set_progress(&mut self, f: impl FnMut(Progress) + Send + 'static) {
        self.progress = Some(Box::new(f));
    }

    /// Removes the progress callback.
    pub fn clear_progress(&mut self) {
        self.progress = None;
    }

    /// The link back, without saying goodbye (see [`Hp34401a::close`]).
    pub fn into_inner(self) -> T {
        self.link
    }

    /// Device clear, `SYST:REM` (or `SYST:RWL`; neither over GPIB, see
    /// [`Transport::needs_remote_command`]), `*IDN?` checked to be a 34401A, `*RST;*CLS`,
    /// then the error queue drained (entries left from before are logged).
    pub async fn connect(&mut self) -> Result<&Identity, Error> {
        self.device_clear().await?;
        if let Some(remote) = self.remote_command() {
            self.command(remote).await?;
        }
        let reply = self.query("*IDN?", self.options.query_timeout).await?;
        let Some(id) = Identity::parse(&reply) else {
            return Err(Error::NotA34401A {
                device: self.device().to_string(),
                reply,
            });
        };
        tracing::info!(device = self.device(), idn = %id.raw, "34401A connected");
        self.command("*RST;*CLS").await?;
        self.config = None;
        self.sample_count = None;
        for e in self.drain_errors().await? {
            tracing::warn!(device = self.device(), error = %e, "stale error after *RST;*CLS");
        }
        Ok(self.identity.insert(id))
    }

    /// Hands the meter back to its front panel (`SYST:LOC`, on links that need remote commands:
    /// see [`Transport::needs_remote_command`]; over GPIB going to local is the controller's
    /// business) and returns the link.
    pub async fn close(mut self) -> Result<T, Error> {
        self.local().await?;
        Ok(self.link)
    }

    /// Hands the meter back to its front panel (`SYST:LOC` on links that need remote
    /// commands; over GPIB the interface's go-to-local, `++loc` through a Prologix), keeping
    /// the driver.
    pub async fn local(&mut self) -> Result<(), Error> {
        if self.link.needs_remote_command() {
            self.command("SYST:LOC").await?;
        } else {
            self.link.return_to_local().await?;
        }
        Ok(())
    }

    /// Configures DC volts. `config` is validated before anything is sent; afterwards the error
    /// queue must be empty, or the error carries the meter's messages.
    pub async fn configure(&mut self, config: &DcvConfig) -> Result<(), Error> {
        config.validate()?;
        self.config = None;
        self.sample_count = None;
        self.apply(config, "configuring DC volts").await?;
        self.config = Some(config.clone());
        Ok(())
    }

    /// Sends `config`'s commands, then drains the error queue, which must be empty.
    async fn apply(&mut self, config: &DcvConfig, context: &str) -> Result<(), Error> {
        for line in config.commands() {
            self.command(&line).await?;
        }
        let errors = self.drain_errors().await?;
        if !errors.is_empty() {
            return Err(Error::Instrument {
                device: self.device().to_string(),
                context: context.into(),
                errors,
            });
        }
        Ok(())
    }

    /// `SYST:REM` (or `SYST:RWL`) when the link needs it ([`Transport::needs_remote_command`]:
    /// RS-232 does; over GPIB the bus puts the meter in remote and the 34401A takes no
    /// `SYST:REM`, an RS-232-only command).
    fn remote_command(&self) -> Option<&'static str> {
        if !self.link.needs_remote_command() {
            None
        } else if self.options.lock_front_panel {
            Some("SYST:RWL")
        } else {
            Some("SYST:REM")
        }
    }

    /// Reads the whole error queue (until `+0,"No error"`), oldest first.
    pub async fn drain_errors(&mut self) -> Result<Vec<InstrumentError>, Error> {
        let mut out = Vec::new();
        // 20 entries at most, plus the overflow entry; a few more in case new ones arrive
        for _ in 0..24 {
            let reply = self.query("SYST:ERR?", self.options.query_timeout).await?;
            let e = parse_error(&reply).ok_or_else(|| Error::InvalidReply {
                device: self.device().to_string(),
                expected: "an error-queue entry",
                bytes: reply.into_bytes(),
            })?;
            if e.code == 0 {
                break;
            }
            out.push(e);
        }
        Ok(out)
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
    ///    tried again every [`DriverOptions::reconnect_pause`] until
    ///    [`DriverOptions::reconnect_timeout`] after the start of the recovery, then
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

    /// Acquires `n` readings with `strategy`, retrying each step (the stream, a memory burst, a
    /// polled reading) after a timeout or garbled reply up to [`DriverOptions::retries`] times
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

    /// Decides after a failed step: retry (after recovery, returned) or give up.
    async fn after_failure(&mut self, error: Error, failures: &mut u32) -> Result<Recovery, Error> {
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

    fn scaled(&self, expected: Duration) -> Duration {
        expected.mul_f64(self.options.timeout_factor.max(1.0)) + self.options.timeout_slack
    }

    /// The interface's device clear ([`Transport::device_clear`]: the 0x03 byte on RS-232,
    /// `++clr` through a Prologix GPIB controller), then the settle pause and the stale input
    /// thrown away.
    ///
    /// Once the meter was seen answering late ([`Hp34401a::reply_delay`] above zero), the
    /// input is drained until the link has been quiet for that long (at most
    /// [`DriverOptions::max_reply_delay`] more): bytes the meter sent before the clear and
    /// still on their way are thrown away here, not read as the next query's answer.
    async fn device_clear(&mut self) -> Result<(), Error> {
        self.link.device_clear().await?;
        self.in_flight = 0;
        tokio::time::sleep(self.options.clear_settle).await;
        let mut dropped = self.link.discard_input().await?;
        if !self.late.reply_delay().is_zero() {
            dropped += self.drain_until_quiet(self.late.reply_delay()).await?;
        }
        if dropped > 0 {
            tracing::debug!(
                device = self.device(),
                dropped,
                "stale input discarded after device clear"
            );
        }
        Ok(())
    }

    /// Throws input away until nothing has come for `quiet` (bounded: at most
    /// `quiet + max_reply_delay`). Returns the bytes dropped.
    async fn drain_until_quiet(&mut self, quiet: Duration) -> Result<usize, Error> {
        let limit = Instant::now() + quiet + self.options.max_reply_delay;
        let mut dropped = 0;
        while Instant::now() < limit {
            match self.link.read_field(b',', Some(quiet)).await {
                Ok(f) => dropped += f.text.len() + 1,
                Err(LinkError::Timeout { partial, .. }) if partial.is_empty() => break,
                // bytes without a separator yet: not quiet
                Err(LinkError::Timeout { .. }) => dropped += self.link.discard_input().await?,
                Err(e) => return Err(e.into()),
            }
        }
        Ok(dropped)
    }

    /// Makes room for `len` more characters within the in-flight budget: when they would not
    /// fit, sends `*OPC?` and waits for its `1` (the meter has then read everything before it).
    async fn make_room(&mut self, len: usize) -> Result<(), Error> {
        if self.in_flight > 0 && self.in_flight + len > self.options.in_flight_budget {
            self.link.send_line("*OPC?").await?;
            let reply = self
                .link
                .read_line(Some(self.options.query_timeout + self.late.reply_delay()))
                .await?;
            self.in_flight = 0;
            if reply.trim() != "1" {
                return Err(Error::InvalidReply {
                    device: self.device().to_string(),
                    expected: "1 from *OPC?",
                    bytes: reply.into_bytes(),
                });
            }
        }
        Ok(())
    }

    /// Sends a command (no reply expected).
    async fn command(&mut self, line: &str) -> Result<(), Error> {
        self.make_room(line.len() + 1).await?;
        self.link.send_line(line).await?;
        self.in_flight += line.len() + 1;
        Ok(())
    }

    /// Sends a query; its reply must be read before anything else is sent.
    async fn send_query(&mut self, line: &str) -> Result<(), Error> {
        self.make_room(line.len() + 1).await?;
        self.link.send_line(line).await?;
        self.in_flight += line.len() + 1;
        Ok(())
    }

    /// Sends a query and reads its one-line reply.
    async fn query(&mut self, line: &str, timeout: Duration) -> Result<String, Error> {
        self.make_room(line.len() + 1).await?;
        self.link.send_line(line).await?;
        let reply = self
            .link
            .read_line(Some(timeout + self.late.reply_delay()))
            .await?;
        self.in_flight = 0;
        Ok(reply)
    }
}

/// Parses an error-queue entry such as `-222,"Data out of range"` or `+0,"No error"`.
pub fn parse_error(reply: &str) -> Option<InstrumentError> {
    let (code, message) = reply.split_once(',')?;
    let code: i32 = code.trim().trim_start_matches('+').parse().ok()?;
    let message = message.trim().trim_matches('"').to_string();
    Some(InstrumentError { code, message })
}
