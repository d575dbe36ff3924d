//! [`TruevoltMeter`]: a Truevolt on a LAN SCPI socket in the multimeter role.

use std::time::Duration;

use gyrocal_link::Transport;
use gyrocal_meter::{
    Acquired, DcVolts, Identity, LateReplies, Measured, MeterError, Multimeter, OVERLOAD,
    ProgressFn, Reading, TimingModel,
};
use tokio::time::Instant;

use crate::error::{Error, InstrumentError};
use crate::facts::{self, MAX_SAMPLE_COUNT, Model};
use crate::timing::{Acquisition, TimingDefaults, TruevoltTiming};
use gyrocal_meter::scpi::{ErrorQueue, NotAnEntry};

/// What the plan (and the lab) choose for the meter, beside its measurement settings.
#[derive(Debug, Clone, PartialEq)]
pub struct TruevoltOptions {
    /// The model the plan names: the meter must be it (see [`TruevoltMeter::connect`]).
    pub model: Model,
    /// The MEM option (34465A/70A: 2,000,000 readings). Default false.
    pub mem_option: bool,
    /// How readings leave the meter. Default `Auto` (stream).
    pub acquisition: Acquisition,
    /// The \[U\] timing figures.
    pub timing: TimingDefaults,
    /// Recoveries (each followed by a retry of the failed part) per measurement. Default 2.
    pub retries: u32,
    /// Timeout of short replies (`*IDN?`, `SYST:ERR?`, `*ESR?`). Default 3 s.
    pub query_timeout: Duration,
    /// How long a `SYST:IDEN?` may go unanswered before the error queue is read (a real
    /// 34401A does not answer it: -113). Default 1 s.
    pub iden_timeout: Duration,
    /// Acquisition timeouts are `factor · expected + slack`. Default 1.5.
    pub timeout_factor: f64,
    /// See `timeout_factor`. Default 1 s.
    pub timeout_slack: Duration,
    /// How long a recovery keeps reconnecting to a meter that stopped answering. Default 30 s.
    pub reconnect_timeout: Duration,
    /// Pause between two reconnect attempts. Default 1 s.
    pub reconnect_pause: Duration,
    /// After a reply timeout, how long the driver waits on the same connection for the late
    /// reply before the recovery's reconnect. When it comes it is thrown away (the reconnect
    /// drops anything else owed to the old connection), and every later deadline is widened
    /// by about twice the lateness seen (at most [`TruevoltOptions::max_reply_delay`]). A
    /// reply later than this counts as lost; it is also what every lost reply costs.
    /// Default 3 s.
    pub late_reply_wait: Duration,
    /// The most the deadlines are widened by for a meter seen answering late. Default 5 s.
    pub max_reply_delay: Duration,
}

impl TruevoltOptions {
    /// The defaults for `model`.
    pub fn new(model: Model) -> Self {
        TruevoltOptions {
            model,
            mem_option: false,
            acquisition: Acquisition::Auto,
            timing: TimingDefaults::default(),
            retries: 2,
            query_timeout: Duration::from_secs(3),
            iden_timeout: Duration::from_secs(1),
            timeout_factor: 1.5,
            timeout_slack: Duration::from_secs(1),
            reconnect_timeout: Duration::from_secs(30),
            reconnect_pause: Duration::from_secs(1),
            late_reply_wait: Duration::from_secs(3),
            max_reply_delay: Duration::from_secs(5),
        }
    }

    /// The timing model at `settings`.
    pub fn timing_at(&self, settings: &DcVolts) -> TruevoltTiming {
        TruevoltTiming {
            model: self.model,
            memory: self.model.memory(self.mem_option),
            nplc: settings.nplc,
            line_hz: settings.line_hz,
            autozero: settings.autozero,
            trigger_delay: None,
            defaults: self.timing,
            acquisition: self.acquisition.resolve(),
        }
    }
}

/// The last memory part of a measurement, still in the meter (see [`Measured::Pending`]).
#[derive(Debug)]
pub struct PendingFetch {
    count: usize,
    epoch: u64,
    earlier: Acquired,
}

/// A Keysight Truevolt on a link (a [`gyrocal_link::SocketTransport`] in practice, whose
/// device clear reconnects).
pub struct TruevoltMeter<T: Transport> {
    link: T,
    options: TruevoltOptions,
    identity: Option<Identity>,
    settings: Option<DcVolts>,
    /// The `SAMP:COUN` the meter holds, when known (sent only when it changes).
    samp_count: Option<usize>,
    progress: Option<ProgressFn>,
    /// Incremented whenever the link is re-established (the meter may have lost its memory).
    epoch: u64,
    /// What cleared the memory the last time the link was re-established (for
    /// [`Error::ReadingsLost`]).
    loss_cause: Option<String>,
    /// The widening of the reply deadlines after late replies.
    late: LateReplies,
}

/// Parses one reading (`+1.00010310E+01`; ±9.9E37 is an overload).
pub fn parse_reading(text: &str) -> Option<Reading> {
    let t = text.trim();
    if t.is_empty()
        || t.len() > 24
        || !t
            .bytes()
            .all(|b| b.is_ascii_digit() || matches!(b, b'+' | b'-' | b'.' | b'E' | b'e'))
    {
        return None;
    }
    let v: f64 = t.parse().ok()?;
    if !v.is_finite() {
        return None;
    }
    if v.abs() >= OVERLOAD * 0.999_999 {
        return Some(Reading::Overload { positive: v > 0.0 });
    }
    Some(Reading::Volts(v))
}

fn fmt_num(v: f64) -> String {
    format!("{v}")
}

impl<T: Transport> TruevoltMeter<T> {
    /// The meter on `link`. Nothing is sent until [`Multimeter::connect`].
    pub fn new(link: T, options: TruevoltOptions) -> Self {
        let late = LateReplies::new(
            options.max_reply_delay,
            options.timeout_slack,
            "TruevoltOptions::max_reply_delay",
        );
        TruevoltMeter {
            link,
            options,
            identity: None,
            settings: None,
            samp_count: None,
            progress: None,
            epoch: 0,
            loss_cause: None,
            late,
        }
    }

    /// What every reply deadline has been widened by, after replies came late (zero for a
    /// meter that answers in time).
    pub fn reply_delay(&self) -> Duration {
        self.late.reply_delay()
    }

    /// After a query timed out: waits up to [`TruevoltOptions::late_reply_wait`] on the same
    /// connection for its late reply. When it comes the meter is alive but slow: the reply is
    /// thrown away, the deadlines are widened, and the returned note says so. `None` when
    /// nothing came. One query at a time is outstanding, so what comes can only be its reply.
    /// `timed_out` is that timeout's error: the unterminated bytes it held came in time and
    /// are no sign of a late reply.
    async fn await_late_reply(&mut self, timed_out: &Error) -> Option<String> {
        let already = match timed_out {
            Error::Link {
                source: gyrocal_link::LinkError::Timeout { partial, .. },
                ..
            } => partial.len(),
            _ => 0,
        };
        let waited_from = Instant::now();
        let came = match self
            .link
            .read_line(Some(self.options.late_reply_wait))
            .await
        {
            Ok(_) => true,
            Err(e) => {
                matches!(&e, gyrocal_link::LinkError::Timeout { partial, .. } if partial.len() > already)
            }
        };
        if !came {
            return None;
        }
        let late = waited_from.elapsed();
        let note = self.late.saw(late);
        tracing::warn!(
            device = %self.device(),
            late_s = late.as_secs_f64(),
            reply_delay_s = self.late.reply_delay().as_secs_f64(),
            "the multimeter answers late; its late reply is thrown away and deadlines widened"
        );
        Some(note)
    }

    /// For [`Error::GaveUp`]: what was seen of a slow meter, or nothing.
    fn slow_note(&self) -> String {
        self.late.note()
    }

    /// The options.
    pub fn options(&self) -> &TruevoltOptions {
        &self.options
    }

    /// The identity read at connect.
    pub fn identity(&self) -> Option<&Identity> {
        self.identity.as_ref()
    }

    /// The link back.
    pub fn into_inner(self) -> T {
        self.link
    }

    fn device(&self) -> String {
        self.link.describe().to_string()
    }

    fn timing_model(&self) -> Option<TruevoltTiming> {
        self.settings.as_ref().map(|s| self.options.timing_at(s))
    }

    fn scaled(&self, expected: Duration) -> Duration {
        expected.mul_f64(self.options.timeout_factor.max(1.0)) + self.options.timeout_slack
    }

    async fn send(&mut self, command: &str) -> Result<(), Error> {
        self.link
            .send_line(command)
            .await
            .map_err(|source| Error::Link {
                command: command.to_string(),
                source,
            })
    }

    async fn query(&mut self, command: &str, timeout: Duration) -> Result<String, Error> {
        self.send(command).await?;
        self.link
            .read_line(Some(timeout + self.late.reply_delay()))
            .await
            .map_err(|source| Error::Link {
                command: command.to_string(),
                source,
            })
    }

    /// Reads the whole error queue (until `+0,"No error"`), oldest first.
    /// At most [`gyrocal_meter::scpi::ERROR_QUEUE_READS`] queries (the role's [`ErrorQueue`]).
    async fn drain_errors(&mut self) -> Result<Vec<InstrumentError>, Error> {
        let mut queue = ErrorQueue::new();
        while let Some(q) = queue.next_query() {
            let reply = self.query(q, self.options.query_timeout).await?;
            queue
                .accept(&reply)
                .map_err(|NotAnEntry(reply)| Error::InvalidReply {
                    device: self.device(),
                    command: q.into(),
                    expected: NotAnEntry::EXPECTED,
                    bytes: reply.into_bytes(),
                })?;
        }
        Ok(queue.into_entries())
    }

    async fn expect_no_errors(&mut self, context: &str) -> Result<(), Error> {
        let errors = self.drain_errors().await?;
        if errors.is_empty() {
            Ok(())
        } else {
            Err(Error::Instrument {
                device: self.device(),
                context: context.into(),
                errors,
            })
        }
    }

    /// `*IDN?`, then identification by model (see [`Multimeter::connect`]).
    async fn identify(&mut self, timeout: Duration) -> Result<Identity, Error> {
        let want = self.options.model;
        let raw = self.query("*IDN?", timeout).await?;
        let f: Vec<&str> = raw.split(',').map(str::trim).collect();
        let field = |i: usize| f.get(i).copied().unwrap_or("").to_string();
        let said = field(1);
        let device = self.device();
        let refuse = move |message: String| Error::Identity { device, message };
        if let Some(model) = Model::from_idn(&said) {
            if model != want {
                return Err(refuse(format!(
                    "the plan names a {want} but a {model} answered (*IDN? {raw:?})"
                )));
            }
            return Ok(Identity {
                raw: raw.clone(),
                manufacturer: field(0),
                model: said,
                serial: field(2),
                version: field(3),
            });
        }
        if !want
            .personalities()
            .iter()
            .any(|p| p.eq_ignore_ascii_case(&said))
        {
            return Err(refuse(format!(
                "the plan names a {want} but *IDN? answered {raw:?}, not a Truevolt"
            )));
        }
        // a Truevolt posing as an older meter answers SYST:IDEN? with that personality; the
        // older meter itself does not know the command (-113) and answers nothing
        self.send("SYST:IDEN?").await?;
        let iden_timeout = self.options.iden_timeout + self.late.reply_delay();
        match self.link.read_line(Some(iden_timeout)).await {
            Ok(reply) if reply.trim().trim_matches('"').ends_with(said.as_str()) => {
                tracing::info!(device = %self.device(), idn = %raw, model = %want,
                    "a Truevolt posing as a {said} (SYST:IDEN {reply}): trusting the plan's model");
                Ok(Identity {
                    raw: raw.clone(),
                    manufacturer: field(0),
                    model: format!(
                        "{} (posing as {said}: SYST:IDEN {}; model from the plan)",
                        want.name(),
                        reply.trim()
                    ),
                    serial: field(2),
                    version: field(3),
                })
            }
            Ok(reply) => Err(refuse(format!(
                "the plan names a {want}; *IDN? answered {raw:?} and SYST:IDEN? {reply:?}"
            ))),
            Err(e) if e.kind() == gyrocal_link::ErrorKind::Timeout => {
                let errors = self.drain_errors().await?;
                let shown = errors
                    .iter()
                    .map(ToString::to_string)
                    .collect::<Vec<_>>()
                    .join("; ");
                Err(refuse(format!(
                    "the plan names a {want} but a {said} answered (*IDN? {raw:?}; SYST:IDEN? \
                     unanswered, error queue: {shown})"
                )))
            }
            Err(source) => Err(Error::Link {
                command: "SYST:IDEN?".into(),
                source,
            }),
        }
    }

    /// The configuration commands for `s`.
    fn config_commands(s: &DcVolts) -> Vec<String> {
        let mut c = vec![match s.range_v {
            Some(r) => format!("CONF:VOLT:DC {}", fmt_num(r)),
            None => "CONF:VOLT:DC AUTO".to_string(),
        }];
        c.push(format!("VOLT:DC:NPLC {}", fmt_num(s.nplc)));
        c.push(format!(
            "VOLT:DC:ZERO:AUTO {}",
            if s.autozero { "ON" } else { "OFF" }
        ));
        c.push("TRIG:SOUR IMM".into());
        c.push("TRIG:DEL:AUTO ON".into());
        c
    }

    async fn apply(&mut self, s: &DcVolts, context: &str) -> Result<(), Error> {
        for line in Self::config_commands(s) {
            self.send(&line).await?;
        }
        // CONF resets the sample count to 1
        self.samp_count = Some(1);
        self.expect_no_errors(context).await
    }

    async fn set_samp_count(&mut self, n: usize) -> Result<(), Error> {
        if self.samp_count != Some(n) {
            self.samp_count = None;
            self.send(&format!("SAMP:COUN {n}")).await?;
            self.samp_count = Some(n);
        }
        Ok(())
    }

    /// Reads one reply of exactly `expected` readings, parsed as they arrive; the first piece
    /// may take `first` (the meter answers once the readings are taken), the rest `rest`.
    async fn read_readings(
        &mut self,
        command: &str,
        expected: usize,
        first: Duration,
        base: usize,
        total: usize,
    ) -> Result<Vec<Reading>, Error> {
        let mut out = Vec::with_capacity(expected);
        let mut timeout = first + self.late.reply_delay();
        loop {
            let field = self
                .link
                .read_field(b',', Some(timeout))
                .await
                .map_err(|source| Error::Link {
                    command: command.to_string(),
                    source,
                })?;
            timeout = self.options.query_timeout;
            for piece in field.text.split(',') {
                let Some(r) = parse_reading(piece) else {
                    if !field.end_of_line {
                        // skip the rest of the reply, so the next exchange starts clean (a
                        // reply cut short times out here, and the recovery drops it anyway)
                        let _ = self.link.read_line(Some(Duration::from_millis(100))).await;
                    }
                    return Err(Error::InvalidReply {
                        device: self.device(),
                        command: command.to_string(),
                        expected: "a reading",
                        bytes: piece.as_bytes().to_vec(),
                    });
                };
                out.push(r);
            }
            if field.end_of_line {
                break;
            }
            if out.len() > expected {
                break;
            }
        }
        if out.len() != expected {
            // whatever is left of the line is stale now
            let _ = self.link.discard_input().await;
            return Err(Error::WrongCount {
                device: self.device(),
                command: command.to_string(),
                expected,
                got: out.len(),
            });
        }
        if let Some(p) = self.progress.as_mut() {
            // one call per reading: the run's display keeps a running mean over all of them
            for (i, &latest) in out.iter().enumerate() {
                p(gyrocal_meter::Progress {
                    done: base + i + 1,
                    total,
                    latest,
                });
            }
        }
        Ok(out)
    }

    /// One streamed part: `SAMP:COUN k` (if it changed), `INIT`, then `DATA:REMove? c,WAIT`
    /// chunk after chunk while the meter measures. Readings received are appended to `out`
    /// as they come, so a failure keeps them.
    async fn stream_part(
        &mut self,
        k: usize,
        out: &mut Vec<Reading>,
        total: usize,
        timing: &TruevoltTiming,
    ) -> Result<(), Error> {
        self.set_samp_count(k).await?;
        self.send("INIT").await?;
        let mut first = true;
        for c in timing.stream_chunks(k) {
            let command = format!("DATA:REM? {c},WAIT");
            let mut expected =
                timing.reading_time() * u32::try_from(c).unwrap_or(u32::MAX) + timing.transfer(c);
            if first {
                expected += timing.defaults.arm_time;
                first = false;
            }
            self.send(&command).await?;
            let base = out.len();
            let r = self
                .read_readings(&command, c, self.scaled(expected), base, total)
                .await?;
            out.extend(r);
        }
        Ok(())
    }

    /// One memory part: `SAMP:COUN k` (if it changed), `INIT`, `*OPC?` (its `1` says the
    /// readings are taken).
    async fn memory_part(&mut self, k: usize, timing: &TruevoltTiming) -> Result<(), Error> {
        self.set_samp_count(k).await?;
        self.send("INIT").await?;
        let expected =
            timing.defaults.arm_time + timing.reading_time() * u32::try_from(k).unwrap_or(u32::MAX);
        let reply = self.query("*OPC?", self.scaled(expected)).await?;
        if reply.trim() != "1" {
            return Err(Error::InvalidReply {
                device: self.device(),
                command: "*OPC?".into(),
                expected: "1 once the readings are taken",
                bytes: reply.into_bytes(),
            });
        }
        Ok(())
    }

    /// `FETC?` of the `count` readings in memory (taken in link epoch `epoch`).
    async fn fetch(
        &mut self,
        count: usize,
        epoch: u64,
        base: usize,
        total: usize,
        timing: &TruevoltTiming,
    ) -> Result<Vec<Reading>, Error> {
        if epoch != self.epoch {
            return Err(Error::ReadingsLost {
                device: self.device(),
                count,
                cause: self
                    .loss_cause
                    .clone()
                    .unwrap_or_else(|| "the link was re-established".into()),
            });
        }
        self.send("FETC?").await?;
        let expected = self.scaled(timing.transfer(count));
        self.read_readings("FETC?", count, expected, base, total)
            .await
    }

    /// A failed exchange: recover and count it in `acc`, or give up when the budget is spent
    /// or `e` is not retryable.
    ///
    /// After a timeout the late reply is waited for first (see
    /// [`TruevoltOptions::late_reply_wait`]): thrown away if it comes, and the deadlines
    /// widened, so a meter that is slow but alive is not reconnected again and again.
    async fn recover_or(&mut self, e: Error, acc: &mut Acquired, what: &str) -> Result<(), Error> {
        if !e.is_retryable() {
            return Err(e);
        }
        let late = if gyrocal_meter::MeterError::kind(&e) == gyrocal_meter::ErrorKind::Timeout {
            self.await_late_reply(&e).await
        } else {
            None
        };
        if acc.retries >= self.options.retries {
            return Err(Error::GaveUp {
                device: self.device(),
                attempts: acc.retries + 1,
                slow: self.slow_note(),
                last: Box::new(e),
            });
        }
        acc.retries += 1;
        let note = self.recover_inner().await?;
        let note = match late {
            Some(late) => format!("{late}; {note}"),
            None => note,
        };
        acc.notes.push(format!(
            "{what} failed ({e}); {note}; taken again (retry {})",
            acc.retries
        ));
        Ok(())
    }

    /// Recovery: device clear (a reconnect on a socket), `ABOR`, the error queue, `*ESR?`;
    /// when the meter did not answer or its Power On bit is set, the link is re-established
    /// (`*CLS`, identity, configuration) until [`TruevoltOptions::reconnect_timeout`].
    async fn recover_inner(&mut self) -> Result<String, Error> {
        let started = Instant::now();
        let plain = async {
            self.link
                .device_clear()
                .await
                .map_err(|source| Error::Link {
                    command: "device clear".into(),
                    source,
                })?;
            self.send("ABOR").await?;
            let errors = self.drain_errors().await?;
            let esr = self.query("*ESR?", self.options.query_timeout).await?;
            Ok::<_, Error>((errors, esr))
        }
        .await;
        let (cause, memory_cause) = match plain {
            Ok((errors, esr)) => {
                let value: u16 = esr.trim().trim_start_matches('+').parse().map_err(|_| {
                    Error::InvalidReply {
                        device: self.device(),
                        command: "*ESR?".into(),
                        expected: "a number",
                        bytes: esr.clone().into_bytes(),
                    }
                })?;
                if value & 128 == 0 {
                    let shown: Vec<String> = errors.iter().map(ToString::to_string).collect();
                    return Ok(if shown.is_empty() {
                        "device clear (reconnect), ABOR".to_string()
                    } else {
                        format!(
                            "device clear (reconnect), ABOR; error queue: {}",
                            shown.join("; ")
                        )
                    });
                }
                (
                    "the Power On status bit was set (power cycle)".to_string(),
                    "the meter was power-cycled: its Power On status bit was set".to_string(),
                )
            }
            Err(e) if e.is_retryable() => (
                format!("the meter did not answer ({e})"),
                "gyrocal configured the meter again after it did not answer, which clears its \
                 memory; no power cycle was seen: its replies may be too late or lost"
                    .to_string(),
            ),
            // the reconnect itself failed (a meter switched off or rebooting refuses the
            // connection): the same come-back window as a meter that does not answer
            Err(e @ Error::Link { .. }) => (
                format!("the connection was lost ({e})"),
                "the connection to the meter was lost and gyrocal configured it again, which \
                 clears its memory"
                    .to_string(),
            ),
            Err(e) => return Err(e),
        };
        // whatever the meter held may be gone
        self.epoch += 1;
        self.loss_cause = Some(memory_cause);
        self.samp_count = None;
        tracing::warn!(device = %self.device(), %cause, "multimeter link lost; re-establishing it");
        let deadline = started + self.options.reconnect_timeout;
        let mut attempts = 0u32;
        loop {
            attempts += 1;
            match self.reestablish_once(deadline).await {
                Ok(()) => {
                    return Ok(format!(
                        "link re-established ({cause}; {attempts} attempt{}, {:.1} s): *CLS, \
                         *IDN? and the configuration sent again",
                        if attempts == 1 { "" } else { "s" },
                        started.elapsed().as_secs_f64()
                    ));
                }
                Err(e) if e.is_retryable() || matches!(e, Error::Link { .. }) => {
                    let now = Instant::now();
                    if now >= deadline {
                        return Err(Error::NotBack {
                            device: self.device(),
                            waited: now - started,
                            slow: self.slow_note(),
                            last: Box::new(e),
                        });
                    }
                    tracing::info!(device = %self.device(), attempt = attempts, error = %e, "multimeter not back yet");
                    tokio::time::sleep(self.options.reconnect_pause.min(deadline - now)).await;
                }
                Err(e) => return Err(e),
            }
        }
    }

    async fn reestablish_once(&mut self, deadline: Instant) -> Result<(), Error> {
        self.link
            .device_clear()
            .await
            .map_err(|source| Error::Link {
                command: "device clear".into(),
                source,
            })?;
        self.send("*CLS").await?;
        let left = deadline.saturating_duration_since(Instant::now());
        let timeout = self
            .options
            .query_timeout
            .min(left)
            .max(Duration::from_millis(100));
        let id = self.identify(timeout).await?;
        self.identity = Some(id);
        match self.settings {
            Some(s) => {
                self.apply(
                    &s,
                    "re-applying the configuration after re-establishing the link",
                )
                .await
            }
            None => self.expect_no_errors("re-establishing the link").await,
        }
    }

    async fn measure_stream(
        &mut self,
        n: usize,
        timing: &TruevoltTiming,
    ) -> Result<Acquired, Error> {
        let mut acc = Acquired::default();
        let mut readings = Vec::with_capacity(n);
        while readings.len() < n {
            let k = (n - readings.len()).min(MAX_SAMPLE_COUNT);
            if let Err(e) = self.stream_part(k, &mut readings, n, timing).await {
                self.recover_or(e, &mut acc, "streaming").await?;
            }
        }
        acc.readings = readings;
        Ok(acc)
    }

    async fn measure_memory(
        &mut self,
        n: usize,
        may_defer: bool,
        timing: &TruevoltTiming,
    ) -> Result<Measured<PendingFetch>, Error> {
        let mut acc = Acquired::default();
        while acc.readings.len() < n {
            let k = (n - acc.readings.len()).min(timing.memory);
            let last = acc.readings.len() + k >= n;
            if let Err(e) = self.memory_part(k, timing).await {
                self.recover_or(e, &mut acc, "memory acquisition").await?;
                continue;
            }
            let epoch = self.epoch;
            if last && may_defer {
                return Ok(Measured::Pending(PendingFetch {
                    count: k,
                    epoch,
                    earlier: acc,
                }));
            }
            let base = acc.readings.len();
            match self
                .fetch_retrying(k, epoch, base, n, timing, &mut acc)
                .await
            {
                Ok(r) => acc.readings.extend(r),
                Err(e)
                    if e.kind() == gyrocal_meter::ErrorKind::ReadingsLost
                        && acc.retries < self.options.retries =>
                {
                    acc.retries += 1;
                    acc.notes.push(format!("{e}; part measured again"));
                }
                Err(e) => return Err(e),
            }
        }
        Ok(Measured::Complete(acc))
    }

    /// `FETC?`, a failed transfer recovered and fetched again (the readings stay in memory
    /// until the next `INIT`); `ReadingsLost` goes back to the caller.
    async fn fetch_retrying(
        &mut self,
        count: usize,
        epoch: u64,
        base: usize,
        total: usize,
        timing: &TruevoltTiming,
        acc: &mut Acquired,
    ) -> Result<Vec<Reading>, Error> {
        loop {
            match self.fetch(count, epoch, base, total, timing).await {
                Ok(r) => return Ok(r),
                Err(e) if e.kind() == gyrocal_meter::ErrorKind::ReadingsLost => return Err(e),
                Err(e) => self.recover_or(e, acc, "FETC?").await?,
            }
        }
    }

    fn configured(&self) -> Result<TruevoltTiming, Error> {
        self.timing_model().ok_or_else(|| Error::NotConfigured {
            device: self.device(),
        })
    }
}

impl<T: Transport + 'static> Multimeter for TruevoltMeter<T> {
    type Error = Error;
    type Pending = PendingFetch;

    fn describe(&self) -> &str {
        self.link.describe()
    }

    /// Device clear (a reconnect), `*IDN?` identified by model, `*RST;*CLS`, the error queue
    /// drained.
    ///
    /// A Truevolt may answer `*IDN?` as an HP 34401A (`SYSTem:IDENtify HP34401A`; a 34465A/70A
    /// also as a 34410A/11A), so the name is not trusted: for such an answer `SYST:IDEN?` is
    /// asked. A Truevolt answers with the personality and is accepted as the plan's model
    /// (the identity says so); the older meter does not know the command (no answer, -113 in
    /// its queue) and is refused. Another Truevolt model than the plan's is refused.
    async fn connect(&mut self) -> Result<Identity, Error> {
        self.link
            .device_clear()
            .await
            .map_err(|source| Error::Link {
                command: "device clear".into(),
                source,
            })?;
        let id = self.identify(self.options.query_timeout).await?;
        tracing::info!(device = %self.device(), idn = %id.raw, "Truevolt connected");
        self.send("*RST;*CLS").await?;
        self.settings = None;
        self.samp_count = None;
        for e in self.drain_errors().await? {
            tracing::warn!(device = %self.device(), error = %e, "stale error after *RST;*CLS");
        }
        self.identity = Some(id.clone());
        Ok(id)
    }

    async fn configure(&mut self, s: &DcVolts) -> Result<(), Error> {
        facts::check(self.options.model, s, self.options.mem_option).map_err(|e| {
            Error::Config {
                model: self.options.model.to_string(),
                message: e.message,
            }
        })?;
        self.settings = None;
        self.apply(s, "configuring DC volts").await?;
        self.settings = Some(*s);
        Ok(())
    }

    fn timing(&self) -> Option<Box<dyn TimingModel>> {
        self.timing_model()
            .map(|t| Box::new(t) as Box<dyn TimingModel>)
    }

    async fn measure(
        &mut self,
        n: usize,
        may_defer: bool,
    ) -> Result<Measured<PendingFetch>, Error> {
        let timing = self.configured()?;
        match timing.acquisition {
            Acquisition::Memory => self.measure_memory(n, may_defer, &timing).await,
            _ => self
                .measure_stream(n, &timing)
                .await
                .map(Measured::Complete),
        }
    }

    async fn collect(&mut self, pending: PendingFetch) -> Result<Acquired, Error> {
        let timing = self.configured()?;
        let PendingFetch {
            count,
            epoch,
            mut earlier,
        } = pending;
        // the measurement's retry budget carries over to its transfer
        let mut acc = Acquired {
            retries: earlier.retries,
            ..Acquired::default()
        };
        let base = earlier.readings.len();
        let total = base + count;
        let r = self
            .fetch_retrying(count, epoch, base, total, &timing, &mut acc)
            .await?;
        earlier.readings.extend(r);
        earlier.retries = acc.retries;
        earlier.notes.extend(acc.notes);
        Ok(earlier)
    }

    async fn recover(&mut self) -> Result<String, Error> {
        self.recover_inner().await
    }

    /// On a socket there is nothing to hand back but what the link does
    /// ([`Transport::return_to_local`]: nothing for TCP; the front panel is usable while a
    /// client is connected, and the meter goes local when the socket closes).
    async fn release(&mut self) -> Result<(), Error> {
        self.link
            .return_to_local()
            .await
            .map_err(|source| Error::Link {
                command: "return to local".into(),
                source,
            })
    }

    fn set_progress(&mut self, progress: Option<ProgressFn>) {
        self.progress = progress;
    }
}
