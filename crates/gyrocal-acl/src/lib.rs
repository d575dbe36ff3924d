//! The ACUTROL command language (ACL), in gyrocal's serial dialect.
//!
//! One line per message ending in LF; commands get no reply; queries get exactly one line;
//! numbers are plain decimals with six digits after the point; errors are read from the
//! `:System:Error?` queue after every command batch. The driver sends the long forms of the
//! headers so transcripts read like the manual.
//!
//! ```text
//! connect:    *IDN?   :System:Error? (until 0)   :Mode? 1
//! enable:     :Interlock:Reset  :Interlock:Close 1  :Limit:Rate R,1,<max>  :Mode:Rate 1  :System:Error?
//! set_rate:   [:Mode:Rate 1]  :Limit:Acceleration R,1,<a>  :Demand:Rate 1,<w>  :System:Error?
//! sample:     :Read:Rate? 1  *STB?  [:System:Error? ... when bit 0 or 7 is set]
//! stop:       :Mode:Off 1            emergency: :Interlock:Open 1
//! wait_stopped: (:Read:Rate? 1  :Mode? 1) every stop_poll_interval until at rest
//! ```
//!
//! ## Retries on a flaky link
//!
//! A serial line to a table across the lab loses or corrupts a reply now and then. Every query
//! of this dialect (`*IDN?`, `*STB?`, `:Mode?`, `:Read:Rate?`, `:Read:Position?`,
//! `:System:Error?`) only reads state, so asking it again is harmless: after a reply that does
//! not come ([`LinkError::Timeout`]), that is not text ([`LinkError::Garbled`], a noise byte) or
//! that does not parse, the driver clears stale input and asks again, at most
//! [`AclConfig::retries`] times. Commands (lines without `?`: a demand, a mode change, a stop)
//! have no reply to check and are never repeated blindly; the error-queue read after them is a
//! query and is retried. A disconnected or failed link is not retried.
//!
//! A query's timeout bounds the whole exchange, retries included: each attempt gets the time
//! left divided by the attempts left (with the defaults a silent table gets three chances of
//! ⅔ s within the 2 s heartbeat deadline; a reply garbled at once leaves more time for the
//! next). So a table that went silent still fails a monitoring sample
//! ([`RateTable::sample`], [`RateTable::heartbeat`]) within [`AclConfig::heartbeat_deadline`] of
//! the unanswered query, as without retries. Only when the attempts are used up does a link
//! failure fault the driver, as before; the error is that of the first attempt (it names the
//! bytes received).
//!
//! Every retry is logged (`tracing::warn!`) and kept as a sentence for the run manifest
//! ([`RateTable::take_retries`]). A `:System:Error?` whose reply was lost or garbled has already
//! removed its entry from the table's queue: the note says that a table error may be missing.
//!
//! ## Late replies and a slow table
//!
//! ACL is an untagged line protocol: a reply that comes after its query's deadline (a busy
//! controller, a serial converter with a deep buffer, a network bridge) would be read as the
//! answer to the next query. The driver keeps a ledger of the replies it is owed
//! ([`gyrocal_table::latency::Pending`]): a query whose deadline passed, or whose future was
//! cancelled, stays owed. Before its next query the driver gets back in step: it sends `*IDN?`
//! as a marker and reads up to its reply, which nothing else in this dialect looks like (four
//! comma-separated fields, the first not a number; the identity the table gave at connection
//! when known). Every line before it is a late reply: it is recognised as such (the query it
//! answers and how late it came are logged) and thrown away, never taken for another query's
//! answer; a query still owed when the marker's reply arrives got no reply at all (lost). A
//! marker whose own reply is late stays owed like any query. Each late reply tells how slowly
//! the table answers, and the deadlines adapt to it
//! ([`gyrocal_table::latency::ReplyLatency`], at most [`AclConfig::slow_reply_limit`]); the
//! operator is told once (a retry note in the manifest and on the terminal) that the table
//! answers slowly. The simulator's `table:slow` fault holds replies back this way;
//! `table:drop` loses them for good, as a framing error does.
//!
//! ## The split
//!
//! [`Acl`] is only the wire protocol (a [`Dialect`]); the policy (limits, state machine,
//! at-rate detection, rest, heartbeat, recording, stop handle) is the generic
//! [`Table`]. [`AclTable<T>`] is `Table<Acl<T>>`, built with
//! [`AclTable::new`](Table::new) from a transport and an [`AclConfig`].

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use tokio::time::Instant;

use gyrocal_link::{LinkError, Transport};
#[cfg(doc)]
use gyrocal_table::RateTable;
use gyrocal_table::ask::{Asking, Attempt, RetryNotes};
use gyrocal_table::dialect::{Connected, Dialect, DialectError, StopAttempt};
use gyrocal_table::latency::{DEFAULT_SLOW_REPLY_LIMIT, Late, Pending, ReplyLatency};
use gyrocal_table::{Identity, Limits, StopKind, TableError, TableMode, TableStatus};
use gyrocal_table::{PolicyConfig, Table};

/// Most errors read from the queue in one go (the queue is finite; a table that keeps
/// answering errors is broken, not informative).
const MAX_QUEUE_READS: usize = 32;

/// Configuration of the ACL driver: the policy's settings and the dialect's, in one struct.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AclConfig {
    /// Client-side limits.
    pub limits: Limits,
    /// The axis driven. Default 1.
    pub axis: u8,
    /// Reply timeout of ordinary queries, retries included (each attempt gets a share).
    /// Default 1 s.
    pub reply_timeout: Duration,
    /// Reply deadline of monitoring samples and heartbeats; a table silent for longer is a
    /// fault. Default 2 s. It bounds each query of a sample with its retries: a table that
    /// goes silent fails the sample at most this long after its unanswered query was sent.
    pub heartbeat_deadline: Duration,
    /// |rate| at or below which [`RateTable::wait_stopped`] considers the table stopped (with
    /// the mode OFF), deg/s. Default 0.01: twenty times the simulator's readback noise, well
    /// below any calibration rate.
    pub stop_tolerance: f64,
    /// Sampling interval of [`RateTable::wait_stopped`]. Default 100 ms.
    pub stop_poll_interval: Duration,
    /// How many times an idempotent query is asked again after a lost, garbled or unparseable
    /// reply, within the query's timeout (see the [module documentation](self)). Default 2: a
    /// flaky link rarely hits two replies in a row, and three attempts still leave each ⅔ s of
    /// the 2 s heartbeat deadline. 0 disables retries.
    pub retries: u32,
    /// The longest a reply may take when deadlines adapt to a table seen to answer slowly
    /// (see the [module documentation](self)): a reply later than this is no reply. Default
    /// [`DEFAULT_SLOW_REPLY_LIMIT`] (5 s).
    pub slow_reply_limit: Duration,
}

impl Default for AclConfig {
    fn default() -> Self {
        AclConfig {
            limits: Limits::default(),
            axis: 1,
            reply_timeout: Duration::from_secs(1),
            heartbeat_deadline: Duration::from_secs(2),
            stop_tolerance: 0.01,
            stop_poll_interval: Duration::from_millis(100),
            retries: 2,
            slow_reply_limit: DEFAULT_SLOW_REPLY_LIMIT,
        }
    }
}

impl AclConfig {
    /// The policy's part of the configuration.
    pub fn policy(&self) -> PolicyConfig {
        PolicyConfig {
            limits: self.limits,
            reply_timeout: self.reply_timeout,
            heartbeat_deadline: self.heartbeat_deadline,
            stop_tolerance: self.stop_tolerance,
            stop_poll_interval: self.stop_poll_interval,
        }
    }
}

/// An ACUTROL-family rate table over any line transport: the generic [`Table`] over the
/// [`Acl`] dialect.
///
/// ```no_run
/// # async fn demo() -> Result<(), gyrocal_table::TableError> {
/// use gyrocal_acl::{AclConfig, AclTable};
/// use gyrocal_table::{RateTable, SettleCriteria};
/// let (transport, _device) = gyrocal_link::memory_pair("table");
/// let mut table = AclTable::new(transport, AclConfig::default());
/// table.connect().await?;
/// table.enable().await?;
/// table.set_rate(10.0, 5.0).await?;
/// table.wait_at_rate(&SettleCriteria::default()).await?;
/// table.stop().await?;
/// # Ok(()) }
/// ```
pub type AclTable<T> = Table<Acl<T>>;

impl<T: Transport + 'static> gyrocal_table::dialect::Build for Acl<T> {
    type Transport = T;
    type Config = AclConfig;

    fn build(transport: T, config: AclConfig) -> (Self, PolicyConfig) {
        (Acl::new(transport, config), config.policy())
    }

    fn config(&self) -> &AclConfig {
        &self.config
    }
}

struct Link<T> {
    transport: T,
    /// A reply was unusable (garbled, noise): more junk may follow, so the next query clears
    /// the input first.
    dirty: bool,
    /// Replies owed by queries whose deadline passed or whose future was cancelled.
    pending: Pending,
}

/// The marker query that gets the link back in step.
const MARKER: &str = "*IDN?";

/// The least quiet window after a marker's reply when earlier markers are still owed.
const MARKER_WINDOW: Duration = Duration::from_millis(20);

/// The ACL dialect over a line transport. Use it through [`AclTable`].
pub struct Acl<T> {
    device: String,
    config: AclConfig,
    link: tokio::sync::Mutex<Link<T>>,
    /// The table is in RATE mode as far as the dialect knows (a demand needs no `:Mode:Rate`).
    rate_mode: AtomicBool,
    /// We opened the interlock ourselves: the interlock-event bit is expected.
    opened_by_us: AtomicBool,
    /// Retry notes not yet taken.
    retries: RetryNotes,
    /// How slowly the table answers.
    latency: ReplyLatency,
    /// The identity line the table gave at connection (the marker's expected reply).
    identity: std::sync::Mutex<Option<Identity>>,
}

impl<T> std::fmt::Debug for Acl<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Acl")
            .field("device", &self.device)
            .field("axis", &self.config.axis)
            .finish_non_exhaustive()
    }
}

impl<T: Transport + 'static> Acl<T> {
    /// The dialect over `transport`; nothing is sent until the table connects.
    pub fn new(transport: T, config: AclConfig) -> Self {
        Acl {
            device: transport.describe().to_string(),
            config,
            link: tokio::sync::Mutex::new(Link {
                transport,
                dirty: false,
                pending: Pending::default(),
            }),
            rate_mode: AtomicBool::new(false),
            opened_by_us: AtomicBool::new(false),
            retries: RetryNotes::default(),
            latency: ReplyLatency::new(config.slow_reply_limit),
            identity: std::sync::Mutex::new(None),
        }
    }

    /// Whether `line` is the marker's reply: the identity given at connection, or before
    /// that anything of its form (four comma-separated fields, the first not a number, which
    /// no other reply of this dialect has; an error text with commas starts with its code).
    fn is_marker_reply(&self, line: &str) -> bool {
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        let known = self
            .identity
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone();
        match known {
            Some(id) => fields == [&*id.manufacturer, &*id.model, &*id.serial, &*id.version],
            None => {
                fields.len() == 4
                    && !fields[0].is_empty()
                    && fields[0].parse::<f64>().is_err()
                    && !fields[0].starts_with('"')
            }
        }
    }

    /// Gets the link back in step after replies went owed: sends the marker and reads up to
    /// its reply by `deadline`, throwing away (and logging) every late reply before it. Fails
    /// like a query when the marker's reply does not come in time (it is then owed too).
    async fn resync(&self, link: &mut Link<T>, deadline: Instant) -> Result<(), LinkError> {
        let now = Instant::now();
        let forgotten = link.pending.forget_older_than(self.latency.limit(), now);
        if forgotten > 0 {
            tracing::debug!(device = %self.device, "{forgotten} owed replies older than the slow-reply limit: lost");
        }
        if link.pending.is_empty() {
            return Ok(());
        }
        let owed = link.pending.len() - link.pending.markers();
        tracing::debug!(device = %self.device, "{owed} replies owed: getting back in step with {MARKER}");
        link.pending.sent(MARKER, true);
        let marker_sent = Instant::now();
        link.transport.send_line(MARKER).await?;
        let mut discarded = Vec::new();
        // after a marker's reply, the wait for the reply of a later marker (sent because an
        // earlier one was late or lost): a reply to marker k comes at most the time between
        // their sends after that of marker k - 1, so a quiet window that long ends the wait
        let mut window: Option<Duration> = None;
        let result = loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let wait = window.map_or(left, |w| w.min(left));
            let line = match link.transport.read_line(Some(wait)).await {
                Ok(line) => line,
                Err(e) if window.is_some() && e.kind() == gyrocal_link::ErrorKind::Timeout => {
                    // the earlier markers' replies were lost: the one read was the last's
                    link.pending.clear();
                    break Ok(());
                }
                Err(e) => break Err(e),
            };
            let now = Instant::now();
            if self.is_marker_reply(&line) {
                let (lost, latency) = link.pending.marker_line(now);
                for q in lost {
                    tracing::debug!(device = %self.device, "no reply ever came to `{q}`");
                }
                if let Some(latency) = latency
                    && latency > now.saturating_duration_since(marker_sent)
                {
                    // an earlier marker, itself late: it tells the latency as well
                    self.note_latency(latency, None);
                }
                if link.pending.is_empty() {
                    break Ok(());
                }
                // the reply read was the popped marker's: the newest (this resync's) follows
                // about the time between their sends later
                let spread = latency.map_or(Duration::ZERO, |l| {
                    marker_sent.saturating_duration_since(now.checked_sub(l).unwrap_or(now))
                });
                window = Some(spread + spread / 2 + MARKER_WINDOW);
                continue;
            }
            match link.pending.late_line(now) {
                Late::Reply { query, latency } => {
                    tracing::info!(
                        device = %self.device,
                        "late reply {} to `{query}` ({:.3} s after it was asked) discarded",
                        gyrocal_link::show_bytes(line.as_bytes()),
                        latency.as_secs_f64()
                    );
                    self.note_latency(latency, None);
                    discarded.push(format!(
                        "{} to `{query}` ({:.3} s late)",
                        gyrocal_link::show_bytes(line.as_bytes()),
                        latency.as_secs_f64()
                    ));
                }
                Late::Unexpected => {
                    tracing::warn!(
                        device = %self.device,
                        "unexpected line {} discarded while getting back in step",
                        gyrocal_link::show_bytes(line.as_bytes())
                    );
                }
            }
        };
        if !discarded.is_empty() {
            self.retries.push(
                &self.device,
                format!(
                    "late replies recognised and discarded (never taken for another query's): {}",
                    discarded.join("; ")
                ),
            );
        }
        result
    }

    fn note_latency(&self, latency: Duration, deadline: Option<Duration>) {
        if let Some(note) = self.latency.observe(latency, deadline) {
            self.retries.push(&self.device, note);
        }
    }

    fn lost(&self, line: &str, e: LinkError) -> DialectError {
        DialectError::link(TableError::from_link(&self.device, line, e))
    }

    /// Sends command lines (no reply expected).
    async fn commands(&self, lines: &[String]) -> Result<(), DialectError> {
        let mut link = self.link.lock().await;
        for line in lines {
            tracing::debug!(device = %self.device, "> {line}");
            if let Err(e) = link.transport.send_line(line).await {
                return Err(self.lost(line, e));
            }
        }
        Ok(())
    }

    /// Sends a query once and returns its one-line reply (no retry), after getting back in
    /// step if replies are owed. A reply that does not come by `timeout` stays owed.
    async fn exchange(&self, line: &str, timeout: Duration) -> Result<String, LinkError> {
        let deadline = Instant::now() + timeout;
        let mut link = self.link.lock().await;
        if link.dirty {
            let dropped = link.transport.discard_input().await.unwrap_or(0);
            tracing::debug!(device = %self.device, "cleared {dropped} stale bytes");
            link.dirty = false;
        }
        if !link.pending.is_empty() {
            self.resync(&mut link, deadline).await?;
        }
        // an owed `*IDN?` is answered like a marker: its reply has the marker's form
        link.pending.sent(line, line == MARKER);
        link.transport.send_line(line).await?;
        let left = deadline.saturating_duration_since(Instant::now());
        let reply = link.transport.read_line(Some(left)).await?;
        link.pending.answered();
        tracing::trace!(device = %self.device, "> {line} < {reply}");
        Ok(reply)
    }

    /// Asks the idempotent query `line` until `parse` accepts the reply, under the retry
    /// policy every dialect shares ([`gyrocal_table::ask`]).
    async fn ask<R>(
        &self,
        line: &str,
        timeout: Duration,
        parse: impl Fn(&str) -> Result<R, &'static str>,
    ) -> Result<R, DialectError> {
        let parse = &parse;
        gyrocal_table::ask::ask(self, line, timeout, |budget| async move {
            match self.exchange(line, budget).await {
                Ok(reply) => match parse(&reply) {
                    Ok(v) => Attempt::Value(v),
                    Err(reason) => Attempt::Unusable { reply, reason },
                },
                Err(e) => Attempt::Link(e),
            }
        })
        .await
    }

    async fn query_number(&self, line: &str, timeout: Duration) -> Result<f64, DialectError> {
        self.ask(line, timeout, |reply| match reply.trim().parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err("not a finite decimal number"),
        })
        .await
    }

    async fn query_stb(&self, timeout: Duration) -> Result<u8, DialectError> {
        self.ask("*STB?", timeout, |reply| {
            reply
                .trim()
                .parse::<u8>()
                .map_err(|_| "not a status byte (0..=255)")
        })
        .await
    }

    async fn query_mode(&self) -> Result<TableMode, DialectError> {
        let line = format!(":Mode? {}", self.config.axis);
        self.ask(&line, self.config.reply_timeout, |reply| {
            parse_mode(reply).ok_or("unknown mode")
        })
        .await
    }

    /// Reads the error queue until `0,"No error"`; returns every (code, text) read.
    async fn drain_errors(&self) -> Result<Vec<(i32, String)>, DialectError> {
        let mut errors = Vec::new();
        for _ in 0..MAX_QUEUE_READS {
            let line = ":System:Error?";
            let entry = self
                .ask(line, self.config.reply_timeout, |reply| {
                    reply
                        .split_once(',')
                        .and_then(|(code, text)| {
                            let code = code.trim().parse::<i32>().ok()?;
                            let text = text.trim();
                            let text = text.strip_prefix('"')?.strip_suffix('"')?;
                            Some((code, text.to_string()))
                        })
                        .ok_or("not `<code>,\"<text>\"`")
                })
                .await?;
            match entry {
                (0, _) => return Ok(errors),
                e => errors.push(e),
            }
        }
        Err(TableError::Reply {
            device: self.device.clone(),
            command: ":System:Error?".into(),
            reason: format!("error queue not empty after {MAX_QUEUE_READS} reads"),
            bytes: String::new(),
        }
        .into())
    }

    /// Reads the queue after a command batch; the first error is returned with its text.
    async fn check_errors(&self, after: &[String]) -> Result<(), DialectError> {
        let errors = self.drain_errors().await?;
        let mut errors = errors.into_iter();
        match errors.next() {
            None => Ok(()),
            Some((code, text)) => {
                for (c, t) in errors {
                    tracing::warn!(device = %self.device, "further table error: {c},\"{t}\"");
                }
                Err(TableError::Table {
                    device: self.device.clone(),
                    command: after.join("; "),
                    code,
                    text,
                }
                .into())
            }
        }
    }

    fn num(v: f64) -> String {
        format!("{v:.6}")
    }
}

fn parse_mode(reply: &str) -> Option<TableMode> {
    match reply.trim().to_ascii_uppercase().as_str() {
        "OFF" => Some(TableMode::Off),
        "RATE" => Some(TableMode::Rate),
        "POSITION" | "POS" => Some(TableMode::Position),
        "ABORT" => Some(TableMode::Abort),
        _ => None,
    }
}

impl<T: Transport + 'static> Asking for Acl<T> {
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

    fn retry_caveat(&self, line: &str) -> Option<&'static str> {
        line.starts_with(":System:Error?").then_some(
            "; the table had already removed the error-queue entry of that reply, so a table \
             error may be missing",
        )
    }
}

impl<T: Transport + 'static> Dialect for Acl<T> {
    const NAME: &'static str = "acl";

    fn describe(&self) -> &str {
        &self.device
    }

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
        *self
            .identity
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = None;
        let identity = self
            .ask("*IDN?", timeout, |reply| {
                let fields: Vec<&str> = reply.split(',').map(str::trim).collect();
                let [manufacturer, model, serial, version] = fields[..] else {
                    return Err("expected 4 comma-separated fields");
                };
                Ok(Identity {
                    manufacturer: manufacturer.to_string(),
                    model: model.to_string(),
                    serial: serial.to_string(),
                    version: version.to_string(),
                })
            })
            .await?;
        *self
            .identity
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = Some(identity.clone());
        for (code, text) in self.drain_errors().await? {
            tracing::warn!(device = %self.device, "stale table error: {code},\"{text}\"");
        }
        let mode = self.query_mode().await?;
        self.opened_by_us.store(false, Ordering::SeqCst);
        self.rate_mode
            .store(mode == TableMode::Rate, Ordering::SeqCst);
        Ok(Connected { identity, mode })
    }

    async fn enable(&self, limits: &Limits, _timeout: Duration) -> Result<(), DialectError> {
        let axis = self.config.axis;
        let lines = vec![
            ":Interlock:Reset".to_string(),
            format!(":Interlock:Close {axis}"),
            format!(":Limit:Rate R,{axis},{}", Self::num(limits.max_rate)),
            format!(":Mode:Rate {axis}"),
        ];
        self.commands(&lines).await?;
        self.check_errors(&lines).await?;
        self.rate_mode.store(true, Ordering::SeqCst);
        self.opened_by_us.store(false, Ordering::SeqCst);
        Ok(())
    }

    async fn demand_rate(
        &self,
        rate: f64,
        acceleration: Option<f64>,
        _timeout: Duration,
    ) -> Result<Instant, DialectError> {
        let axis = self.config.axis;
        let mut lines = Vec::with_capacity(3);
        if !self.rate_mode.load(Ordering::SeqCst) {
            lines.push(format!(":Mode:Rate {axis}"));
        }
        if let Some(a) = acceleration {
            lines.push(format!(":Limit:Acceleration R,{axis},{}", Self::num(a)));
        }
        lines.push(format!(":Demand:Rate {axis},{}", Self::num(rate)));
        self.commands(&lines).await?;
        // the table ramps from here; the error check below overlaps the ramp
        let written = Instant::now();
        self.rate_mode.store(true, Ordering::SeqCst);
        self.check_errors(&lines).await?;
        Ok(written)
    }

    async fn read_rate(&self, timeout: Duration) -> Result<f64, DialectError> {
        let line = format!(":Read:Rate? {}", self.config.axis);
        self.query_number(&line, timeout).await
    }

    async fn read_position(&self, timeout: Duration) -> Result<f64, DialectError> {
        let line = format!(":Read:Position? {}", self.config.axis);
        self.query_number(&line, timeout).await
    }

    async fn read_mode(&self, _timeout: Duration) -> Result<TableMode, DialectError> {
        self.query_mode().await
    }

    async fn status(&self, timeout: Duration) -> Result<TableStatus, DialectError> {
        let mode = self.query_mode().await?;
        let status_byte = self.query_stb(timeout).await?;
        Ok(TableStatus { mode, status_byte })
    }

    /// `*STB?`; with bit 0 (interlock event) or bit 7 (error queued) set, the error queue is
    /// read: an interlock event we did not cause is a fault with the table's text, a queued
    /// error alone a [`TableError::Table`].
    async fn poll_faults(&self, timeout: Duration) -> Result<Option<String>, DialectError> {
        let stb = self.query_stb(timeout).await?;
        if stb & 0x81 == 0 {
            return Ok(None);
        }
        let errors = self.drain_errors().await?;
        let text = errors
            .iter()
            .map(|(c, t)| format!("{c},\"{t}\""))
            .collect::<Vec<_>>();
        let expected_event = self.opened_by_us.load(Ordering::SeqCst);
        if stb & 0x01 != 0 && !expected_event {
            return Ok(Some(if text.is_empty() {
                format!("interlock event (status byte {stb}), no error text")
            } else {
                format!("table reports {}", text.join("; "))
            }));
        }
        match errors.into_iter().next() {
            Some((code, text)) => Err(TableError::Table {
                device: self.device.clone(),
                command: "(status poll)".into(),
                code,
                text,
            }
            .into()),
            None => Ok(None),
        }
    }

    /// `:Mode:Off <axis>` or `:Interlock:Open <axis>`, waiting at most a little over one
    /// exchange for the link and never for a reply (commands have none).
    async fn send_stop(&self, kind: StopKind, timeout: Duration) -> StopAttempt {
        let line = match kind {
            StopKind::Controlled => format!(":Mode:Off {}", self.config.axis),
            StopKind::Emergency => format!(":Interlock:Open {}", self.config.axis),
        };
        let text = line.as_str();
        let attempt = gyrocal_table::dialect::send_stop_with(
            &self.device,
            text,
            // a query to a table seen to answer slowly holds the link longer
            self.latency.deadline(timeout),
            self.link.lock(),
            |mut link| async move { link.transport.send_line(text).await },
        )
        .await;
        self.rate_mode.store(false, Ordering::SeqCst);
        if kind == StopKind::Emergency && attempt.attempted {
            self.opened_by_us.store(true, Ordering::SeqCst);
        }
        attempt
    }

    fn take_retries(&self) -> Vec<String> {
        self.retries.take()
    }
}
