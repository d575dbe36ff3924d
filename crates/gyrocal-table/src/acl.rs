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
//! A limit of an untagged line protocol: a reply that comes *later* than its attempt's timeout
//! but after the input was cleared is taken as the answer to the retry (the same question, so
//! the same kind of answer). The retry's own reply then comes extra: the next query clears the
//! input first after any retry, but a reply still in flight then is read in its place. Replies
//! of the status queries (`*STB?`, `:Mode?`, `:System:Error?`) do not parse as each other, so
//! such a mix-up is caught and retried; two numeric reads in a row (rate, then position) cannot
//! be told apart. The simulator's `table:drop` loses replies for good, as a framing error does.

use std::future::Future;
use std::pin::Pin;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use gyrocal_link::{ErrorKind as LinkErrorKind, LinkError, Transport, show_bytes};
use tokio::time::Instant;

use crate::{
    Capabilities, Identity, Limits, RateAccumulator, RateStats, RateTable, RestReport,
    SettleCriteria, SettleReport, StopHandle, StopKind, StopPath, TableError, TableMode,
    TableState, TableStatus, stop_time,
};

/// Most errors read from the queue in one go (the queue is finite; a table that keeps
/// answering errors is broken, not informative).
const MAX_QUEUE_READS: usize = 32;

/// Configuration of the ACL driver.
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
        }
    }
}

struct Link<T> {
    transport: T,
    /// A query was started and its reply not consumed (timeout or cancelled future): a late
    /// reply may be waiting, so the next query clears the input first.
    dirty: bool,
}

#[derive(Debug, Clone)]
struct Status {
    state: TableState,
    interlock_closed: bool,
    rate_mode: bool,
    /// We opened the interlock ourselves: the interlock-event bit is expected.
    opened_by_us: bool,
    fault: Option<String>,
}

struct Shared<T> {
    device: String,
    axis: u8,
    reply_timeout: Duration,
    link: tokio::sync::Mutex<Link<T>>,
    status: Mutex<Status>,
}

impl<T: Transport> Shared<T> {
    fn status(&self) -> MutexGuard<'_, Status> {
        // A poisoned lock only means another thread panicked while holding plain data.
        self.status
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn stop_line(&self, kind: StopKind) -> String {
        match kind {
            StopKind::Controlled => format!(":Mode:Off {}", self.axis),
            StopKind::Emergency => format!(":Interlock:Open {}", self.axis),
        }
    }

    fn note_stop(&self, kind: StopKind) {
        let mut st = self.status();
        st.rate_mode = false;
        if kind == StopKind::Emergency {
            st.interlock_closed = false;
            st.opened_by_us = true;
        }
        if !matches!(st.state, TableState::Faulted | TableState::Disconnected) {
            st.state = TableState::Stopping;
        }
    }

    /// Sends a stop line, waiting at most a little over one exchange for the link.
    async fn stop(&self, kind: StopKind) -> Result<(), TableError> {
        let line = self.stop_line(kind);
        let wait = self.reply_timeout * 2 + Duration::from_millis(500);
        let mut link = tokio::time::timeout(wait, self.link.lock())
            .await
            .map_err(|_| TableError::Fault {
                device: self.device.clone(),
                reason: format!("could not get the link within {wait:?} to send `{line}`"),
            })?;
        tracing::info!(device = %self.device, "{line}");
        let sent = tokio::time::timeout(self.reply_timeout, link.transport.send_line(&line)).await;
        drop(link);
        self.note_stop(kind);
        match sent {
            Ok(r) => r.map_err(|e| TableError::from_link(&self.device, &line, e)),
            Err(_) => Err(TableError::Fault {
                device: self.device.clone(),
                reason: format!(
                    "`{line}` could not be written within {:?}",
                    self.reply_timeout
                ),
            }),
        }
    }

    /// Marks the driver faulted and tries a controlled stop (the link may be dead: errors are
    /// logged, not returned).
    async fn fault(&self, reason: String) -> TableError {
        {
            let mut st = self.status();
            st.state = TableState::Faulted;
            st.fault = Some(reason.clone());
        }
        tracing::error!(device = %self.device, "fault: {reason}; sending a controlled stop");
        if let Err(e) = self.stop(StopKind::Controlled).await {
            tracing::error!(device = %self.device, "controlled stop after the fault failed: {e}");
        }
        TableError::Fault {
            device: self.device.clone(),
            reason,
        }
    }
}

impl<T: Transport + 'static> StopPath for Shared<T> {
    fn describe(&self) -> &str {
        &self.device
    }

    fn send_stop(
        &self,
        kind: StopKind,
    ) -> Pin<Box<dyn Future<Output = Result<(), TableError>> + Send + '_>> {
        Box::pin(self.stop(kind))
    }
}

#[derive(Debug, Clone, Copy)]
struct Ramp {
    start: Instant,
    from: f64,
    target: f64,
    acceleration: f64,
}

impl Ramp {
    fn duration(&self) -> Duration {
        Duration::try_from_secs_f64((self.target - self.from).abs() / self.acceleration)
            .unwrap_or(Duration::ZERO)
    }
}

/// An ACUTROL-family rate table over any line transport.
///
/// ```no_run
/// # async fn demo() -> Result<(), gyrocal_table::TableError> {
/// use gyrocal_table::{RateTable, SettleCriteria, acl::{AclConfig, AclTable}};
/// let (transport, _device) = gyrocal_link::memory_pair("table");
/// let mut table = AclTable::new(transport, AclConfig::default());
/// table.connect().await?;
/// table.enable().await?;
/// table.set_rate(10.0, 5.0).await?;
/// table.wait_at_rate(&SettleCriteria::default()).await?;
/// table.stop().await?;
/// # Ok(()) }
/// ```
pub struct AclTable<T> {
    shared: Arc<Shared<T>>,
    config: AclConfig,
    demand: f64,
    ramp: Option<Ramp>,
    /// The acceleration limit last sent, deg/s²: a controlled stop decelerates with it.
    acceleration: Option<f64>,
    recorder: Option<RateAccumulator>,
    /// Retry notes not yet taken by [`RateTable::take_retries`].
    retries: Vec<String>,
}

/// One failed attempt at a query.
enum Miss {
    /// Nothing (or not a line of text) came back.
    Link(LinkError),
    /// A line came back that is not a valid reply.
    Reply { reply: String, reason: &'static str },
}

impl Miss {
    /// What went wrong, for a retry note.
    fn describe(&self) -> String {
        match self {
            Miss::Link(LinkError::Timeout {
                timeout, partial, ..
            }) if partial.is_empty() => {
                format!("no reply within {:.3} s", timeout.as_secs_f64())
            }
            Miss::Link(LinkError::Timeout {
                timeout, partial, ..
            }) => format!(
                "no complete reply within {:.3} s (got {})",
                timeout.as_secs_f64(),
                show_bytes(partial)
            ),
            Miss::Link(LinkError::Garbled { reason, bytes, .. }) => {
                format!("garbled reply {} ({reason})", show_bytes(bytes))
            }
            Miss::Link(e) => e.to_string(),
            Miss::Reply { reply, reason } => {
                format!("unusable reply {} ({reason})", show_bytes(reply.as_bytes()))
            }
        }
    }
}

/// Whether asking again can help: a lost or corrupted reply can, a dead link cannot.
fn retryable(e: &LinkError) -> bool {
    matches!(e.kind(), LinkErrorKind::Timeout | LinkErrorKind::Garbled)
}

impl<T: Transport> std::fmt::Debug for AclTable<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AclTable")
            .field("device", &self.shared.device)
            .field("state", &self.shared.status().state)
            .field("demand", &self.demand)
            .finish_non_exhaustive()
    }
}

impl<T: Transport + 'static> AclTable<T> {
    /// Takes the transport by value; nothing is sent until [`RateTable::connect`].
    pub fn new(transport: T, config: AclConfig) -> Self {
        let device = transport.describe().to_string();
        AclTable {
            shared: Arc::new(Shared {
                device,
                axis: config.axis,
                reply_timeout: config.reply_timeout,
                link: tokio::sync::Mutex::new(Link {
                    transport,
                    dirty: false,
                }),
                status: Mutex::new(Status {
                    state: TableState::Disconnected,
                    interlock_closed: false,
                    rate_mode: false,
                    opened_by_us: false,
                    fault: None,
                }),
            }),
            config,
            demand: 0.0,
            ramp: None,
            acceleration: None,
            recorder: None,
            retries: Vec::new(),
        }
    }

    /// The configuration in force.
    pub fn config(&self) -> &AclConfig {
        &self.config
    }

    /// The last demanded rate, deg/s (0 after a stop).
    pub fn demand(&self) -> f64 {
        self.demand
    }

    /// The reason of the last fault, if the driver faulted since the last `enable`.
    pub fn last_fault(&self) -> Option<String> {
        self.shared.status().fault.clone()
    }

    fn device(&self) -> &str {
        &self.shared.device
    }

    fn set_state(&self, state: TableState) {
        self.shared.status().state = state;
    }

    fn state_error(&self, action: &str) -> TableError {
        TableError::State {
            device: self.device().to_string(),
            action: action.to_string(),
            state: self.state(),
        }
    }

    /// Sends command lines (no reply expected).
    async fn commands(&self, lines: &[String]) -> Result<(), TableError> {
        let mut link = self.shared.link.lock().await;
        for line in lines {
            tracing::debug!(device = %self.shared.device, "> {line}");
            if let Err(e) = link.transport.send_line(line).await {
                drop(link);
                return Err(self.lost(line, e).await);
            }
        }
        Ok(())
    }

    /// Sends a query once and returns its one-line reply (no retry, no fault).
    async fn exchange(&self, line: &str, timeout: Duration) -> Result<String, LinkError> {
        let mut link = self.shared.link.lock().await;
        if link.dirty {
            let dropped = link.transport.discard_input().await.unwrap_or(0);
            tracing::debug!(device = %self.shared.device, "cleared {dropped} stale bytes");
        }
        link.dirty = true;
        link.transport.send_line(line).await?;
        let reply = link.transport.read_line(Some(timeout)).await?;
        link.dirty = false;
        tracing::trace!(device = %self.shared.device, "> {line} < {reply}");
        Ok(reply)
    }

    /// Asks the idempotent query `line` until `parse` accepts the reply, at most
    /// `1 + retries` times within `timeout` in total (see the module documentation). A dead link
    /// faults the driver at once; a lost or garbled reply only when no attempt succeeded; when
    /// every attempt got a line that does not parse, a [`TableError::Reply`] is returned
    /// without faulting (as a single bad reply always was).
    async fn ask<R>(
        &mut self,
        line: &str,
        timeout: Duration,
        parse: impl Fn(&str) -> Result<R, &'static str>,
    ) -> Result<R, TableError> {
        let attempts = self.config.retries.saturating_add(1);
        let deadline = Instant::now() + timeout;
        let mut first: Option<Miss> = None;
        let mut last = String::new();
        let mut link_missed = false;
        for attempt in 1..=attempts {
            let left = attempts - attempt + 1;
            let budget = deadline.saturating_duration_since(Instant::now()) / left;
            let miss = match self.exchange(line, budget).await {
                Ok(reply) => match parse(&reply) {
                    Ok(v) => {
                        if attempt > 1 {
                            // a late reply to an earlier attempt may have been taken for this
                            // one; then this attempt's reply is still to come: clear it first
                            self.shared.link.lock().await.dirty = true;
                        }
                        return Ok(v);
                    }
                    Err(reason) => Miss::Reply { reply, reason },
                },
                Err(e) if retryable(&e) => Miss::Link(e),
                Err(e) => return Err(self.lost(line, e).await),
            };
            last = miss.describe();
            link_missed |= matches!(miss, Miss::Link(_));
            if attempt < attempts {
                let mut note = format!(
                    "`{line}`: {last}; asked again (retry {attempt} of {})",
                    attempts - 1
                );
                if line.starts_with(":System:Error?") {
                    note.push_str(
                        "; the table had already removed the error-queue entry of that reply, \
                         so a table error may be missing",
                    );
                }
                self.note_retry(note);
                // the reply may have been late or followed by more junk: clear it first
                self.shared.link.lock().await.dirty = true;
            }
            first.get_or_insert(miss);
        }
        let err = match first {
            Some(Miss::Reply { reply, reason }) if attempts > 1 => self.reply_error(
                line,
                &reply,
                &format!("{reason}; no usable reply in {attempts} attempts"),
            ),
            Some(Miss::Reply { reply, reason }) => self.reply_error(line, &reply, reason),
            Some(Miss::Link(e)) => TableError::from_link(self.device(), line, e),
            None => TableError::Reply {
                device: self.device().to_string(),
                command: line.to_string(),
                reason: "no attempt was made".into(),
                bytes: String::new(),
            },
        };
        if attempts > 1 {
            self.note_retry(format!(
                "`{line}`: {last}; no usable reply in {attempts} attempts, gave up"
            ));
        }
        // A link that lost or mangled a reply and never gave a usable one cannot be trusted
        // with the table's motion: fault, as a single lost reply did before retries.
        if link_missed && self.state() != TableState::Disconnected {
            // The returned Fault is replaced by the more precise link error.
            let _ = self.shared.fault(err.to_string()).await;
        }
        Err(err)
    }

    fn note_retry(&mut self, note: String) {
        tracing::warn!(device = %self.shared.device, "{note}");
        self.retries.push(note);
    }

    /// A link failure during an exchange: the table's motion is now unknown, so the driver
    /// faults (after a best-effort stop), except before it ever identified the table.
    async fn lost(&self, line: &str, e: LinkError) -> TableError {
        let err = TableError::from_link(self.device(), line, e);
        if self.state() != TableState::Disconnected {
            // The returned Fault is replaced by the more precise link error.
            let _ = self.shared.fault(err.to_string()).await;
        }
        err
    }

    fn reply_error(&self, command: &str, reply: &str, reason: &str) -> TableError {
        TableError::Reply {
            device: self.device().to_string(),
            command: command.to_string(),
            reason: reason.to_string(),
            bytes: show_bytes(reply.as_bytes()),
        }
    }

    async fn query_number(&mut self, line: &str, timeout: Duration) -> Result<f64, TableError> {
        self.ask(line, timeout, |reply| match reply.trim().parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err("not a finite decimal number"),
        })
        .await
    }

    async fn query_stb(&mut self, timeout: Duration) -> Result<u8, TableError> {
        self.ask("*STB?", timeout, |reply| {
            reply
                .trim()
                .parse::<u8>()
                .map_err(|_| "not a status byte (0..=255)")
        })
        .await
    }

    async fn query_mode(&mut self) -> Result<TableMode, TableError> {
        let line = format!(":Mode? {}", self.config.axis);
        self.ask(&line, self.config.reply_timeout, |reply| {
            parse_mode(reply).ok_or("unknown mode")
        })
        .await
    }

    /// Reads the error queue until `0,"No error"`; returns every (code, text) read.
    async fn drain_errors(&mut self) -> Result<Vec<(i32, String)>, TableError> {
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
            device: self.device().to_string(),
            command: ":System:Error?".into(),
            reason: format!("error queue not empty after {MAX_QUEUE_READS} reads"),
            bytes: String::new(),
        })
    }

    /// Reads the queue after a command batch; the first error is returned with its text.
    async fn check_errors(&mut self, after: &[String]) -> Result<(), TableError> {
        let errors = self.drain_errors().await?;
        let mut errors = errors.into_iter();
        match errors.next() {
            None => Ok(()),
            Some((code, text)) => {
                for (c, t) in errors {
                    tracing::warn!(device = %self.shared.device, "further table error: {c},\"{t}\"");
                }
                Err(TableError::Table {
                    device: self.device().to_string(),
                    command: after.join("; "),
                    code,
                    text,
                })
            }
        }
    }

    /// Acts on a status byte: a latched fault is a driver fault with the table's text; a
    /// queued error outside a command batch is reported.
    async fn check_stb(&mut self, stb: u8) -> Result<(), TableError> {
        if stb & 0x81 == 0 {
            return Ok(());
        }
        let errors = self.drain_errors().await?;
        let text = errors
            .iter()
            .map(|(c, t)| format!("{c},\"{t}\""))
            .collect::<Vec<_>>();
        let expected_event = self.shared.status().opened_by_us;
        if stb & 0x01 != 0 && !expected_event {
            let reason = if text.is_empty() {
                format!("interlock event (status byte {stb}), no error text")
            } else {
                format!("table reports {}", text.join("; "))
            };
            self.demand = 0.0;
            self.ramp = None;
            return Err(self.shared.fault(reason).await);
        }
        match errors.into_iter().next() {
            Some((code, text)) => Err(TableError::Table {
                device: self.device().to_string(),
                command: "(status poll)".into(),
                code,
                text,
            }),
            None => Ok(()),
        }
    }

    fn check_limits(&self, rate: f64, acceleration: f64) -> Result<(), TableError> {
        let l = &self.config.limits;
        let what = if !rate.is_finite() {
            Some(format!("rate {rate} is not a number"))
        } else if rate.abs() > l.max_rate {
            Some(format!(
                "|rate| {} deg/s above the maximum {} deg/s",
                rate.abs(),
                l.max_rate
            ))
        } else if !acceleration.is_finite() || acceleration <= 0.0 {
            Some(format!(
                "acceleration {acceleration} deg/s^2 must be positive"
            ))
        } else if acceleration > l.max_acceleration {
            Some(format!(
                "acceleration {acceleration} deg/s^2 above the maximum {} deg/s^2",
                l.max_acceleration
            ))
        } else {
            None
        };
        match what {
            Some(what) => Err(TableError::Limit {
                device: self.device().to_string(),
                what,
            }),
            None => Ok(()),
        }
    }

    fn record(&mut self, rate: f64) {
        if let Some(acc) = self.recorder.as_mut() {
            acc.push(rate);
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

impl<T: Transport + 'static> RateTable for AclTable<T> {
    fn describe(&self) -> &str {
        self.device()
    }

    fn state(&self) -> TableState {
        self.shared.status().state
    }

    fn capabilities(&self) -> Capabilities {
        Capabilities {
            dialect: "acl",
            axes: 1,
            max_rate: self.config.limits.max_rate,
            max_acceleration: self.config.limits.max_acceleration,
            position_readback: true,
        }
    }

    async fn connect(&mut self) -> Result<Identity, TableError> {
        {
            let mut link = self.shared.link.lock().await;
            let dropped = link
                .transport
                .discard_input()
                .await
                .map_err(|e| TableError::from_link(&self.shared.device, "(clear input)", e))?;
            link.dirty = false;
            if dropped > 0 {
                tracing::info!(device = %self.shared.device, "cleared {dropped} stale bytes");
            }
        }
        let (reply, identity) = self
            .ask("*IDN?", self.config.reply_timeout, |reply| {
                let fields: Vec<&str> = reply.split(',').map(str::trim).collect();
                let [manufacturer, model, serial, version] = fields[..] else {
                    return Err("expected 4 comma-separated fields");
                };
                let identity = Identity {
                    manufacturer: manufacturer.to_string(),
                    model: model.to_string(),
                    serial: serial.to_string(),
                    version: version.to_string(),
                };
                Ok((reply.to_string(), identity))
            })
            .await?;
        for (code, text) in self.drain_errors().await? {
            tracing::warn!(device = %self.shared.device, "stale table error: {code},\"{text}\"");
        }
        let mode = self.query_mode().await?;
        {
            let mut st = self.shared.status();
            st.fault = None;
            st.opened_by_us = false;
            st.rate_mode = mode == TableMode::Rate;
            st.interlock_closed = matches!(mode, TableMode::Rate | TableMode::Position);
            st.state = match mode {
                TableMode::Off => TableState::Connected,
                TableMode::Abort => TableState::Stopping,
                // Servo on and possibly turning (left so by an earlier program): the driver
                // does not know the demand, so it treats the table as servoed; the caller
                // should stop it or set a rate.
                TableMode::Rate | TableMode::Position => TableState::Servoed,
            };
        }
        if mode != TableMode::Off {
            tracing::warn!(device = %self.shared.device, "table found in mode {mode:?}");
        }
        tracing::info!(device = %self.shared.device, "connected to {reply}");
        Ok(identity)
    }

    async fn enable(&mut self) -> Result<(), TableError> {
        match self.state() {
            TableState::Disconnected | TableState::Ramping { .. } | TableState::AtRate { .. } => {
                return Err(self.state_error("enable the servo"));
            }
            _ => {}
        }
        let axis = self.config.axis;
        let lines = vec![
            ":Interlock:Reset".to_string(),
            format!(":Interlock:Close {axis}"),
            format!(
                ":Limit:Rate R,{axis},{}",
                Self::num(self.config.limits.max_rate)
            ),
            format!(":Mode:Rate {axis}"),
        ];
        self.commands(&lines).await?;
        self.check_errors(&lines).await?;
        let mut st = self.shared.status();
        st.state = TableState::Servoed;
        st.interlock_closed = true;
        st.rate_mode = true;
        st.opened_by_us = false;
        st.fault = None;
        drop(st);
        self.demand = 0.0;
        self.ramp = None;
        Ok(())
    }

    async fn set_rate(&mut self, rate: f64, acceleration: f64) -> Result<(), TableError> {
        self.check_limits(rate, acceleration)?;
        let (state, interlock_closed, rate_mode) = {
            let st = self.shared.status();
            (st.state, st.interlock_closed, st.rate_mode)
        };
        let allowed = match state {
            TableState::Servoed | TableState::Ramping { .. } | TableState::AtRate { .. } => true,
            TableState::Stopping => interlock_closed,
            _ => false,
        };
        if !allowed {
            return Err(self.state_error(&format!("demand {rate} deg/s")));
        }
        let axis = self.config.axis;
        let mut lines = Vec::with_capacity(3);
        if !rate_mode {
            lines.push(format!(":Mode:Rate {axis}"));
        }
        lines.push(format!(
            ":Limit:Acceleration R,{axis},{}",
            Self::num(acceleration)
        ));
        lines.push(format!(":Demand:Rate {axis},{}", Self::num(rate)));
        let start = Instant::now();
        self.acceleration = Some(acceleration);
        self.commands(&lines).await?;
        self.shared.status().rate_mode = true;
        self.check_errors(&lines).await?;
        self.ramp = Some(Ramp {
            start,
            from: self.demand,
            target: rate,
            acceleration,
        });
        self.demand = rate;
        self.set_state(TableState::Ramping { target: rate });
        Ok(())
    }

    async fn read_rate(&mut self) -> Result<f64, TableError> {
        let line = format!(":Read:Rate? {}", self.config.axis);
        self.query_number(&line, self.config.reply_timeout).await
    }

    async fn read_position(&mut self) -> Result<f64, TableError> {
        let line = format!(":Read:Position? {}", self.config.axis);
        let p = self.query_number(&line, self.config.reply_timeout).await?;
        Ok(p.rem_euclid(360.0))
    }

    async fn status(&mut self) -> Result<TableStatus, TableError> {
        let mode = self.query_mode().await?;
        let status_byte = self.query_stb(self.config.reply_timeout).await?;
        Ok(TableStatus { mode, status_byte })
    }

    async fn sample(&mut self) -> Result<f64, TableError> {
        let line = format!(":Read:Rate? {}", self.config.axis);
        let rate = self
            .query_number(&line, self.config.heartbeat_deadline)
            .await?;
        let stb = self.query_stb(self.config.heartbeat_deadline).await?;
        self.check_stb(stb).await?;
        self.record(rate);
        Ok(rate)
    }

    async fn wait_at_rate(
        &mut self,
        criteria: &SettleCriteria,
    ) -> Result<SettleReport, TableError> {
        match self.state() {
            TableState::Servoed | TableState::Ramping { .. } | TableState::AtRate { .. } => {}
            _ => return Err(self.state_error("wait for the rate")),
        }
        let now = Instant::now();
        let demand = self.demand;
        let (start, ramp_time) = match self.ramp {
            Some(r) => (r.start, r.duration()),
            None => (now, Duration::ZERO),
        };
        let ramp_end = start + ramp_time;
        let deadline = ramp_end.max(now) + criteria.timeout;
        let tolerance = criteria.tolerance_at(demand);
        let mut since: Option<Instant> = None;
        let mut window = RateAccumulator::default();
        let mut last = f64::NAN;
        let mut next = now;
        loop {
            let rate = self.sample().await?;
            last = if rate.is_finite() { rate } else { last };
            let t = Instant::now();
            if t >= ramp_end && (rate - demand).abs() <= tolerance {
                let t0 = *since.get_or_insert(t);
                window.push(rate);
                if t - t0 >= criteria.window {
                    self.set_state(TableState::AtRate { rate: demand });
                    return Ok(SettleReport {
                        demand,
                        ramp_time,
                        settled_after: t - start,
                        window: window.stats(),
                    });
                }
            } else {
                since = None;
                window = RateAccumulator::default();
            }
            if t >= deadline {
                self.demand = 0.0;
                self.ramp = None;
                let reason = format!(
                    "rate not settled within {:?} after the {:?} ramp: demand {demand} deg/s, \
                     tolerance {tolerance} deg/s, last measured {last} deg/s",
                    criteria.timeout, ramp_time
                );
                return Err(self.shared.fault(reason).await);
            }
            next = (next + criteria.interval).max(Instant::now());
            tokio::time::sleep_until(next.min(deadline)).await;
        }
    }

    fn start_recording(&mut self) {
        self.recorder = Some(RateAccumulator::default());
    }

    fn stop_recording(&mut self) -> RateStats {
        self.recorder
            .take()
            .map(|a| a.stats())
            .unwrap_or(RateStats::EMPTY)
    }

    async fn heartbeat(&mut self) -> Result<(), TableError> {
        let stb = self.query_stb(self.config.heartbeat_deadline).await?;
        self.check_stb(stb).await
    }

    async fn stop(&mut self) -> Result<(), TableError> {
        self.demand = 0.0;
        self.ramp = None;
        self.shared.stop(StopKind::Controlled).await
    }

    async fn emergency_stop(&mut self) -> Result<(), TableError> {
        self.demand = 0.0;
        self.ramp = None;
        self.shared.stop(StopKind::Emergency).await
    }

    async fn wait_stopped(&mut self, timeout: Duration) -> Result<RestReport, TableError> {
        let start = Instant::now();
        let deadline = start + timeout;
        let mut last: (Option<f64>, Option<TableMode>) = (None, None);
        let seen = |last: &(Option<f64>, Option<TableMode>)| match last {
            (None, _) => "no rate measured yet".to_string(),
            (Some(rate), None) => format!("last measured {rate} deg/s, mode not read"),
            (Some(rate), Some(mode)) => format!("last measured {rate} deg/s in mode {mode}"),
        };
        loop {
            let rate = match self.read_rate().await {
                Ok(rate) => rate,
                Err(e) => {
                    let reason =
                        format!("could not confirm the table at rest ({}): {e}", seen(&last));
                    return Err(self.shared.fault(reason).await);
                }
            };
            last = (Some(rate), None);
            let mode = match self.query_mode().await {
                Ok(mode) => mode,
                Err(e) => {
                    let reason =
                        format!("could not confirm the table at rest ({}): {e}", seen(&last));
                    return Err(self.shared.fault(reason).await);
                }
            };
            last = (Some(rate), Some(mode));
            if rate.abs() <= self.config.stop_tolerance && mode == TableMode::Off {
                let mut st = self.shared.status();
                if st.state != TableState::Faulted {
                    st.state = if st.interlock_closed {
                        TableState::Servoed
                    } else {
                        TableState::Connected
                    };
                }
                return Ok(RestReport {
                    rate_dps: rate,
                    mode,
                    waited: start.elapsed(),
                });
            }
            if Instant::now() >= deadline {
                let reason = format!(
                    "table not at rest {timeout:?} after the stop: {} (rest is |rate| <= {} \
                     deg/s in mode OFF)",
                    seen(&last),
                    self.config.stop_tolerance
                );
                return Err(self.shared.fault(reason).await);
            }
            tokio::time::sleep(self.config.stop_poll_interval).await;
        }
    }

    /// `|from_rate|/a · 1.5 + 5 s` ([`stop_time`]) with `a` the acceleration limit last sent
    /// (which `:Mode:Off` decelerates with; a gentler ramp than the client maximum makes a
    /// slower stop), else the client-side maximum. An emergency stop decelerates at the
    /// table's own maximum, faster: the bound holds for it too.
    fn stop_deadline(&self, from_rate: f64) -> Duration {
        let a = self
            .acceleration
            .unwrap_or(self.config.limits.max_acceleration)
            .min(self.config.limits.max_acceleration);
        stop_time(from_rate, a)
    }

    fn stop_handle(&self) -> StopHandle {
        StopHandle::new(self.shared.clone())
    }

    fn take_retries(&mut self) -> Vec<String> {
        std::mem::take(&mut self.retries)
    }
}
