//! [`Hp34401a`]: the driver proper: its options, the identity, connecting and configuring,
//! and the exchange rules on the link (one query outstanding, the in-flight budget, the device
//! clear). Acquiring readings is in [`acquire`], recovering after a failure in [`recovery`].

mod acquire;
mod recovery;

pub use acquire::{Acquisition, Burst};
pub use recovery::{LinkLoss, Recovery};

use std::time::Duration;

use gyrocal_link::{LinkError, Transport};
use gyrocal_meter::LateReplies;
use tokio::time::Instant;

use crate::timing::Timing;
use crate::{DcvConfig, Error};

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
