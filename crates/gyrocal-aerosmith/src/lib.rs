//! **Experimental**: the Ideal Aerosmith three-letter ASCII dialect.
//!
//! No vendor manual was found; this dialect follows public third-party scripts
//! (`shared/docs/instruments.md`), and where they disagree the choice is an
//! [`AerosmithConfig`] option with a documented default. It has run against gyrocal's
//! simulator only. **Before trusting it on a real table, a lab must verify, at low rate with the
//! hardware E-stop at hand:**
//!
//! 1. the line ending the controller expects ([`AerosmithConfig::line_ending`], default CR);
//! 2. the units of `JOG` and `PVE` ([`AerosmithConfig::rate_units`], default deg/s; one script
//!    comments "1–21600 deg/min"): `JOG1` must turn the table at 1 deg/s, not 1 deg/min;
//! 3. the polarity of `MCO` ([`AerosmithConfig::mco_polarity`], default `1` = complete);
//! 4. the bits of the `STA` status word ([`AerosmithConfig::status_bits`], defaults servo on
//!    `0x01`, jogging `0x02`, fault `0x04`, all unconfirmed);
//! 5. that every command, `JOG` included, ends its reply with the `>` prompt (one script does
//!    not wait for a reply to `JOG`).
//!
//! ## The wire
//!
//! 9600 baud, 8N1. gyrocal-link offers 8N2 as its only 8-bit framing: open the port at 9600
//! 8N2 (an 8N1 receiver takes the second stop bit as idle time, and UARTs check only the first
//! stop bit of what they receive), or over a serial-to-Ethernet converter set to 8N1. Each
//! command is a mnemonic and its argument, then the line ending; the controller answers with
//! optional data lines and a `>` prompt (not followed by a line ending). A `?` in a reply is an
//! error (a [`TableError::Table`] with code [`NO_CODE`]: the controller gives none). The driver
//! reads every reply up to the prompt ([`gyrocal_link::Transport::read_until`]), tolerates an
//! echo of the command, and takes the last data line as a query's value.
//!
//! ```text
//! connect:      STA                       (no identification command is known)
//! enable:       SRV                       (servo on; also clears a latched fault [U])
//! set_rate:     ACL<deg/s²>  JOG<rate>
//! sample:       PVE  STA
//! read_mode:    STA  [MCO<tol> when not jogging]
//! stop:         STO                       emergency: STO as well (see below)
//! ```
//!
//! Modes are derived: jogging (status bit) is [`TableMode::Rate`]; not jogging with `MCO`
//! saying the motion is complete is [`TableMode::Off`]; not jogging with the motion still
//! running (a stop decelerating) is reported as [`TableMode::Abort`], so the policy's rest check
//! (|rate| small *and* mode OFF) waits for the controller to finish too. A latched fault is the
//! fault bit of `STA`; the controller gives no text, so the fault reason names the status word.
//!
//! ## No emergency stop command
//!
//! No interlock command is known beyond `SRV`: [`RateTable::emergency_stop`] sends `STO`, a
//! controlled stop, and logs that. **The hardware E-stop is the only true emergency stop of an
//! Aerosmith table**; the operator must have it within reach. After an emergency stop the
//! driver still treats the servo as off (a new demand needs [`RateTable::enable`]).
//!
//! The stop path does not wait for the prompt of `STO` (a stop must not hang on a reply): the
//! prompt it owes is read before the next exchange.
//!
//! ## Retries
//!
//! As in ACL, the queries (`PVE`, `PPO`, `STA`, `MCO`) only read state and are asked again after
//! a lost, garbled or unparseable reply, within the query's timeout ([`AerosmithConfig::retries`]),
//! each retry noted for the run manifest. Commands (`SRV`, `ACL`, `JOG`, `STO`) are never
//! repeated; a command without its prompt is a link failure.
//!
//! ## Late replies
//!
//! Every exchange, a stop's included, ends with exactly one prompt, so the driver counts the
//! prompts it is owed ([`gyrocal_table::latency::Pending`]): an exchange whose deadline passed
//! (or whose future was cancelled) owes its prompt, and before the next exchange the owed
//! prompts are read, each recognised as the late reply it is (logged with how late it came) and
//! thrown away. An owed prompt that has not come when the next exchange's deadline passes fails
//! that exchange without sending anything, so a late reply is never read as another command's;
//! one owed longer than [`AerosmithConfig::slow_reply_limit`] is taken as lost. The deadlines
//! adapt to the slowest late reply seen, within that limit, and the operator is told once that
//! the table answers slowly ([`gyrocal_table::latency::ReplyLatency`]).

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use gyrocal_link::{LinkError, Transport};
use tokio::time::Instant;

#[cfg(doc)]
use gyrocal_table::RateTable;
use gyrocal_table::ask::{Asking, Attempt, RetryNotes};
use gyrocal_table::dialect::{Connected, Dialect, DialectError, StopAttempt};
use gyrocal_table::latency::{DEFAULT_SLOW_REPLY_LIMIT, Late, Pending, ReplyLatency};
use gyrocal_table::{Identity, Limits, StopKind, TableError, TableMode, TableStatus};
use gyrocal_table::{PolicyConfig, Table};

/// The prompt that ends every reply.
pub const PROMPT: u8 = b'>';

/// The code of a [`TableError::Table`] from a `?` reply: the controller gives no code.
pub const NO_CODE: i32 = -1;

/// The line ending of commands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LineEnding {
    /// CR only (default): what one script sends; a controller that ends commands on CR would
    /// take a following LF as the start of the next command.
    #[default]
    Cr,
    /// CR LF: what another script sends.
    CrLf,
}

impl LineEnding {
    /// The bytes.
    pub fn bytes(self) -> &'static [u8] {
        match self {
            LineEnding::Cr => b"\r",
            LineEnding::CrLf => b"\r\n",
        }
    }
}

/// The units of `JOG` and `PVE`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RateUnits {
    /// Degrees per second (default; one script).
    #[default]
    DegPerSec,
    /// Degrees per minute (a comment of another script: "1–21600 deg/min").
    DegPerMin,
}

impl RateUnits {
    /// Multiplier from deg/s to these units.
    pub fn per_deg_per_sec(self) -> f64 {
        match self {
            RateUnits::DegPerSec => 1.0,
            RateUnits::DegPerMin => 60.0,
        }
    }
}

/// What `MCO<tol>` answers when the motion is complete.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum McoPolarity {
    /// `1` means complete (default).
    #[default]
    OneIsComplete,
    /// `0` means complete.
    ZeroIsComplete,
}

/// Bit masks of the `STA` status word (all unconfirmed).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StatusBits {
    /// Servo on. Default `0x01`.
    pub servo: u32,
    /// Jogging (a continuous-rate command in force). Default `0x02`.
    pub jog: u32,
    /// A fault is latched. Default `0x04`.
    pub fault: u32,
}

impl Default for StatusBits {
    fn default() -> Self {
        StatusBits {
            servo: 0x01,
            jog: 0x02,
            fault: 0x04,
        }
    }
}

/// Configuration of the Aerosmith driver: the policy's settings and the dialect's options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AerosmithConfig {
    /// The policy's settings (limits, timeouts, rest tolerance).
    pub policy: PolicyConfig,
    /// Line ending of commands. Default CR.
    pub line_ending: LineEnding,
    /// Units of `JOG` and `PVE`. Default deg/s.
    pub rate_units: RateUnits,
    /// Polarity of `MCO`. Default `1` = complete.
    pub mco_polarity: McoPolarity,
    /// Tolerance sent with `MCO`, deg/s (converted to [`AerosmithConfig::rate_units`]).
    /// Default 0.01.
    pub mco_tolerance: f64,
    /// Bits of the `STA` status word.
    pub status_bits: StatusBits,
    /// How many times an idempotent query is asked again. Default 2.
    pub retries: u32,
    /// The longest a reply may take when deadlines adapt to a table seen to answer slowly
    /// (see "Late replies" in the [crate documentation](crate)). Default
    /// [`DEFAULT_SLOW_REPLY_LIMIT`] (5 s).
    pub slow_reply_limit: Duration,
}

impl Default for AerosmithConfig {
    fn default() -> Self {
        AerosmithConfig {
            policy: PolicyConfig::default(),
            line_ending: LineEnding::Cr,
            rate_units: RateUnits::DegPerSec,
            mco_polarity: McoPolarity::OneIsComplete,
            mco_tolerance: 0.01,
            status_bits: StatusBits::default(),
            retries: 2,
            slow_reply_limit: DEFAULT_SLOW_REPLY_LIMIT,
        }
    }
}

/// An Ideal Aerosmith table (experimental): the generic [`Table`] over the [`Aerosmith`]
/// dialect.
///
/// ```no_run
/// # async fn demo() -> Result<(), gyrocal_table::TableError> {
/// use gyrocal_aerosmith::{AerosmithConfig, AerosmithTable};
/// use gyrocal_table::RateTable;
/// let (transport, _device) = gyrocal_link::memory_pair("table");
/// let mut table = AerosmithTable::new(transport, AerosmithConfig::default());
/// table.connect().await?;
/// table.enable().await?;
/// # Ok(()) }
/// ```
pub type AerosmithTable<T> = Table<Aerosmith<T>>;

impl<T: Transport + 'static> gyrocal_table::dialect::Build for Aerosmith<T> {
    type Transport = T;
    type Config = AerosmithConfig;

    fn build(transport: T, config: AerosmithConfig) -> (Self, PolicyConfig) {
        (Aerosmith::new(transport, config), config.policy)
    }

    fn config(&self) -> &AerosmithConfig {
        &self.config
    }
}

struct Link<T> {
    transport: T,
    /// A reply was unusable: more junk may follow, so clear the input first.
    dirty: bool,
    /// Prompts owed (by exchanges whose deadline passed or whose future was cancelled, and by
    /// stops sent without waiting): read before the next exchange.
    pending: Pending,
}

/// The command a stop sends (its prompt is owed, not late).
const STOP: &str = "STO";

/// The Ideal Aerosmith dialect over a transport that can read up to a prompt. Use it through
/// [`AerosmithTable`].
pub struct Aerosmith<T> {
    device: String,
    config: AerosmithConfig,
    link: tokio::sync::Mutex<Link<T>>,
    /// The servo was turned on by us (or found on): its bit dropping is a fault.
    expect_servo: AtomicBool,
    retries: RetryNotes,
    latency: ReplyLatency,
}

impl<T> std::fmt::Debug for Aerosmith<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Aerosmith")
            .field("device", &self.device)
            .field("config", &self.config)
            .finish_non_exhaustive()
    }
}

/// The data lines of a reply (prompt removed): trimmed, empty lines and an echo dropped.
fn data_lines<'a>(body: &'a str, command: &str) -> Vec<&'a str> {
    body.split(['\r', '\n'])
        .map(str::trim)
        .filter(|l| !l.is_empty() && *l != command)
        .collect()
}

impl<T: Transport + 'static> Aerosmith<T> {
    /// The dialect over `transport`; nothing is sent until the table connects.
    pub fn new(transport: T, config: AerosmithConfig) -> Self {
        Aerosmith {
            device: transport.describe().to_string(),
            config,
            link: tokio::sync::Mutex::new(Link {
                transport,
                dirty: false,
                pending: Pending::default(),
            }),
            expect_servo: AtomicBool::new(false),
            retries: RetryNotes::default(),
            latency: ReplyLatency::new(config.slow_reply_limit),
        }
    }

    fn frame(&self, command: &str) -> Vec<u8> {
        let mut bytes = command.as_bytes().to_vec();
        bytes.extend_from_slice(self.config.line_ending.bytes());
        bytes
    }

    fn num(&self, v: f64) -> String {
        format!("{v:.4}")
    }

    /// Reads the prompts owed by earlier exchanges by `deadline`, each one recognised as the
    /// late reply it is and thrown away. A prompt owed longer than the slow-reply limit is
    /// lost; one still to come when `deadline` passes fails this exchange (nothing is sent), so
    /// a late reply is never read as another command's.
    async fn catch_up(&self, link: &mut Link<T>, deadline: Instant) -> Result<(), LinkError> {
        link.pending
            .forget_older_than(self.latency.limit(), Instant::now());
        while !link.pending.is_empty() {
            let left = deadline.saturating_duration_since(Instant::now());
            let body = link.transport.read_until(PROMPT, Some(left)).await?;
            if let Late::Reply { query, latency } = link.pending.late_line(Instant::now()) {
                if query == STOP {
                    continue;
                }
                tracing::info!(
                    device = %self.device,
                    "late reply {} to `{query}` ({:.3} s after it was sent) discarded",
                    gyrocal_link::show_bytes(body.as_bytes()),
                    latency.as_secs_f64()
                );
                self.retries.push(
                    &self.device,
                    format!(
                        "late reply {} to `{query}` ({:.3} s late) recognised and discarded \
                         (never taken for another command's)",
                        gyrocal_link::show_bytes(body.as_bytes()),
                        latency.as_secs_f64()
                    ),
                );
                if let Some(note) = self.latency.observe(latency, None) {
                    self.retries.push(&self.device, note);
                }
            }
        }
        Ok(())
    }

    /// Sends `command` and reads its reply up to the prompt (no retry), after the prompts
    /// owed by earlier exchanges. A reply that does not come by `timeout` stays owed.
    async fn exchange(&self, command: &str, timeout: Duration) -> Result<String, LinkError> {
        let deadline = Instant::now() + timeout;
        let mut link = self.link.lock().await;
        self.catch_up(&mut link, deadline).await?;
        if link.dirty {
            let dropped = link.transport.discard_input().await.unwrap_or(0);
            tracing::debug!(device = %self.device, "cleared {dropped} stale bytes");
            link.dirty = false;
        }
        link.pending.sent(command, false);
        link.transport.write_raw(&self.frame(command)).await?;
        let left = deadline.saturating_duration_since(Instant::now());
        let body = link.transport.read_until(PROMPT, Some(left)).await?;
        link.pending.answered();
        tracing::trace!(device = %self.device, "> {command} < {body:?}>");
        Ok(body)
    }

    fn table_error(&self, command: &str, body: &str) -> TableError {
        TableError::Table {
            device: self.device.clone(),
            command: command.to_string(),
            code: NO_CODE,
            text: data_lines(body, command).join(" "),
        }
    }

    /// Sends a command (not repeated); its prompt must come, and without a `?`.
    async fn command(&self, command: &str, timeout: Duration) -> Result<(), DialectError> {
        tracing::debug!(device = %self.device, "> {command}");
        // a table seen to answer slowly gets longer for a command's prompt as for a query
        let timeout = self.latency.deadline(timeout);
        let body = self
            .exchange(command, timeout)
            .await
            .map_err(|e| DialectError::link(TableError::from_link(&self.device, command, e)))?;
        if body.contains('?') {
            return Err(self.table_error(command, &body).into());
        }
        Ok(())
    }

    /// Asks an idempotent query until `parse` accepts its value line, under the retry policy
    /// every dialect shares ([`gyrocal_table::ask`]). A `?` reply is a table error, not retried.
    async fn ask<R>(
        &self,
        command: &str,
        timeout: Duration,
        parse: impl Fn(&str) -> Result<R, &'static str>,
    ) -> Result<R, DialectError> {
        let parse = &parse;
        gyrocal_table::ask::ask(self, command, timeout, |budget| async move {
            match self.exchange(command, budget).await {
                Ok(body) if body.contains('?') => {
                    Attempt::Final(self.table_error(command, &body).into())
                }
                Ok(body) => {
                    let value = data_lines(&body, command).last().copied().unwrap_or("");
                    match parse(value) {
                        Ok(v) => Attempt::Value(v),
                        Err(reason) => Attempt::Unusable {
                            reply: body,
                            reason,
                        },
                    }
                }
                Err(e) => Attempt::Link(e),
            }
        })
        .await
    }

    async fn query_number(&self, command: &str, timeout: Duration) -> Result<f64, DialectError> {
        self.ask(command, timeout, |v| match v.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err("not a finite decimal number"),
        })
        .await
    }

    async fn query_status(&self, timeout: Duration) -> Result<u32, DialectError> {
        self.ask("STA", timeout, |v| {
            v.parse::<u32>().map_err(|_| "not a status word")
        })
        .await
    }

    /// `MCO<tol>`: whether the controller says the motion is complete.
    async fn motion_complete(&self, timeout: Duration) -> Result<bool, DialectError> {
        let tol = self.config.mco_tolerance * self.config.rate_units.per_deg_per_sec();
        let command = format!("MCO{}", self.num(tol));
        let one = self.ask(&command, timeout, |v| match v {
            "1" => Ok(true),
            "0" => Ok(false),
            _ => Err("not 0 or 1"),
        });
        let one = one.await?;
        Ok(match self.config.mco_polarity {
            McoPolarity::OneIsComplete => one,
            McoPolarity::ZeroIsComplete => !one,
        })
    }

    /// The mode a status word stands for (asking `MCO` when not jogging).
    async fn mode_of(&self, status: u32, timeout: Duration) -> Result<TableMode, DialectError> {
        if status & self.config.status_bits.jog != 0 {
            return Ok(TableMode::Rate);
        }
        Ok(if self.motion_complete(timeout).await? {
            TableMode::Off
        } else {
            TableMode::Abort
        })
    }
}

impl<T: Transport + 'static> Asking for Aerosmith<T> {
    fn device(&self) -> &str {
        &self.device
    }

    fn retries(&self) -> u32 {
        self.config.retries
    }

    fn retry_notes(&self) -> &RetryNotes {
        &self.retries
    }

    async fn mark_dirty(&self) {
        self.link.lock().await.dirty = true;
    }

    fn latency(&self) -> &ReplyLatency {
        &self.latency
    }
}

impl<T: Transport + 'static> Dialect for Aerosmith<T> {
    const NAME: &'static str = "aerosmith";

    fn describe(&self) -> &str {
        &self.device
    }

    /// Clears stale input, then `STA` (and `MCO` when not jogging): a table that answers a
    /// status word is taken as identified; there is no identification command.
    async fn connect(&self, timeout: Duration) -> Result<Connected, DialectError> {
        {
            let mut link = self.link.lock().await;
            let dropped = link
                .transport
                .discard_input()
                .await
                .map_err(|e| TableError::from_link(&self.device, "(clear input)", e))?;
            link.dirty = false;
            link.pending.clear();
            if dropped > 0 {
                tracing::info!(device = %self.device, "cleared {dropped} stale bytes");
            }
        }
        let status = self.query_status(timeout).await?;
        let mode = self.mode_of(status, timeout).await?;
        self.expect_servo.store(
            status & self.config.status_bits.servo != 0,
            Ordering::SeqCst,
        );
        Ok(Connected {
            identity: Identity {
                manufacturer: "Ideal Aerosmith".into(),
                model: "(no identification command)".into(),
                serial: String::new(),
                version: format!("STA {status}"),
            },
            mode,
        })
    }

    async fn enable(&self, _limits: &Limits, timeout: Duration) -> Result<(), DialectError> {
        self.command("SRV", timeout).await?;
        self.expect_servo.store(true, Ordering::SeqCst);
        Ok(())
    }

    async fn demand_rate(
        &self,
        rate: f64,
        acceleration: Option<f64>,
        timeout: Duration,
    ) -> Result<Instant, DialectError> {
        let units = self.config.rate_units.per_deg_per_sec();
        if let Some(a) = acceleration {
            self.command(&format!("ACL{}", self.num(a)), timeout)
                .await?;
        }
        // the controller acts on the line as it arrives; its prompt follows
        let written = Instant::now();
        self.command(&format!("JOG{}", self.num(rate * units)), timeout)
            .await?;
        Ok(written)
    }

    async fn read_rate(&self, timeout: Duration) -> Result<f64, DialectError> {
        let v = self.query_number("PVE", timeout).await?;
        Ok(v / self.config.rate_units.per_deg_per_sec())
    }

    async fn read_position(&self, timeout: Duration) -> Result<f64, DialectError> {
        self.query_number("PPO", timeout).await
    }

    async fn read_mode(&self, timeout: Duration) -> Result<TableMode, DialectError> {
        let status = self.query_status(timeout).await?;
        self.mode_of(status, timeout).await
    }

    /// The mode, and a status byte with bit 0 set when the fault bit is (bit 7, an error
    /// queue, never: the controller has none).
    async fn status(&self, timeout: Duration) -> Result<TableStatus, DialectError> {
        let status = self.query_status(timeout).await?;
        let mode = self.mode_of(status, timeout).await?;
        let status_byte = u8::from(status & self.config.status_bits.fault != 0);
        Ok(TableStatus { mode, status_byte })
    }

    /// `STA`: the fault bit, or the servo bit dropping while the servo should be on, is a
    /// fault (the controller gives no text: the reason names the status word).
    async fn poll_faults(&self, timeout: Duration) -> Result<Option<String>, DialectError> {
        let status = self.query_status(timeout).await?;
        let bits = self.config.status_bits;
        if status & bits.fault != 0 {
            return Ok(Some(format!(
                "table reports a fault (STA status word {status} = {status:#x}, fault bit \
                 {:#x}; the controller gives no fault text)",
                bits.fault
            )));
        }
        if status & bits.servo == 0 && self.expect_servo.load(Ordering::SeqCst) {
            return Ok(Some(format!(
                "servo turned off by itself (STA status word {status} = {status:#x})"
            )));
        }
        Ok(None)
    }

    /// `STO` for both kinds (no interlock command is known: the hardware E-stop is the only
    /// true emergency stop). Does not wait for the prompt; the next exchange reads it.
    async fn send_stop(&self, kind: StopKind, timeout: Duration) -> StopAttempt {
        let command = STOP;
        if kind == StopKind::Emergency {
            tracing::warn!(
                device = %self.device,
                "emergency stop: the Aerosmith dialect has no interlock command, sending STO \
                 (a controlled stop); the hardware E-stop is the only true emergency stop"
            );
        }
        let frame = self.frame(command);
        gyrocal_table::dialect::send_stop_with(
            &self.device,
            command,
            // a query to a table seen to answer slowly holds the link longer
            self.latency.deadline(timeout),
            self.link.lock(),
            |mut link| async move {
                // the controller answers a stop with a prompt, read before the next exchange (a
                // write cut short owes it too: the marker-less dialect cannot tell)
                link.pending.sent(STOP, false);
                link.transport.write_raw(&frame).await?;
                Ok(())
            },
        )
        .await
    }

    fn take_retries(&self) -> Vec<String> {
        self.retries.take()
    }
}
