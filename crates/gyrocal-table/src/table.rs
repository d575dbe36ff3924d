//! [`Table`]: the one implementation of [`RateTable`], over any [`Dialect`].
//!
//! The policy every table shares lives here, once: client-side limits, the state machine,
//! at-rate detection, waiting for rest, the heartbeat deadline, recording, fault latching and
//! the stop handle. See the [`dialect`](crate::dialect) module for the split.

use std::future::Future;
use std::pin::Pin;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use tokio::time::Instant;

use crate::dialect::{Dialect, DialectError};
use crate::{
    Capabilities, Identity, Limits, RateAccumulator, RateStats, RateTable, RestReport,
    SettleCriteria, SettleProgress, SettleReport, StopHandle, StopKind, StopPath, TableError,
    TableMode, TableState, TableStatus, stop_time,
};

/// The policy's settings, whatever the dialect.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PolicyConfig {
    /// Client-side limits.
    pub limits: Limits,
    /// Reply timeout of ordinary queries, retries included. Default 1 s.
    pub reply_timeout: Duration,
    /// Reply deadline of monitoring samples and heartbeats; a table silent for longer is a
    /// fault. Default 2 s.
    pub heartbeat_deadline: Duration,
    /// |rate| at or below which [`RateTable::wait_stopped`] considers the table stopped (with
    /// the mode OFF), deg/s. Default 0.01.
    pub stop_tolerance: f64,
    /// Sampling interval of [`RateTable::wait_stopped`]. Default 100 ms.
    pub stop_poll_interval: Duration,
}

impl Default for PolicyConfig {
    fn default() -> Self {
        PolicyConfig {
            limits: Limits::default(),
            reply_timeout: Duration::from_secs(1),
            heartbeat_deadline: Duration::from_secs(2),
            stop_tolerance: 0.01,
            stop_poll_interval: Duration::from_millis(100),
        }
    }
}

#[derive(Debug, Clone)]
struct Status {
    state: TableState,
    interlock_closed: bool,
    fault: Option<String>,
}

struct Shared<D> {
    dialect: D,
    reply_timeout: Duration,
    status: Mutex<Status>,
}

impl<D: Dialect> Shared<D> {
    fn status(&self) -> MutexGuard<'_, Status> {
        // A poisoned lock only means another thread panicked while holding plain data.
        self.status
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn note_stop(&self, kind: StopKind) {
        let mut st = self.status();
        if kind == StopKind::Emergency {
            st.interlock_closed = false;
        }
        if !matches!(st.state, TableState::Faulted | TableState::Disconnected) {
            st.state = TableState::Stopping;
        }
    }

    async fn stop(&self, kind: StopKind) -> Result<(), TableError> {
        let attempt = self.dialect.send_stop(kind, self.reply_timeout).await;
        if attempt.attempted {
            self.note_stop(kind);
        }
        attempt.result
    }

    /// Marks the driver faulted and tries a controlled stop (the link may be dead: errors are
    /// logged, not returned).
    async fn fault(&self, reason: String) -> TableError {
        let device = self.dialect.describe();
        {
            let mut st = self.status();
            st.state = TableState::Faulted;
            st.fault = Some(reason.clone());
        }
        tracing::error!(device = %device, "fault: {reason}; sending a controlled stop");
        if let Err(e) = self.stop(StopKind::Controlled).await {
            tracing::error!(device = %device, "controlled stop after the fault failed: {e}");
        }
        TableError::Fault {
            device: device.to_string(),
            reason,
        }
    }
}

impl<D: Dialect> StopPath for Shared<D> {
    fn describe(&self) -> &str {
        self.dialect.describe()
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

/// A rate table of any dialect: the one implementation of [`RateTable`].
///
/// Build it from a dialect and the policy's settings with [`Table::with_dialect`], or through a
/// dialect's constructor: `gyrocal_acl::AclTable::new` (ACUTROL),
/// `gyrocal_aerosmith::AerosmithTable::new` (Ideal Aerosmith, experimental).
pub struct Table<D: Dialect> {
    shared: Arc<Shared<D>>,
    policy: PolicyConfig,
    demand: f64,
    ramp: Option<Ramp>,
    /// The acceleration limit last sent, deg/s²: a controlled stop decelerates with it.
    acceleration: Option<f64>,
    recorder: Option<RateAccumulator>,
}

impl<D: Dialect> std::fmt::Debug for Table<D> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Table")
            .field("dialect", &D::NAME)
            .field("device", &self.device())
            .field("state", &self.shared.status().state)
            .field("demand", &self.demand)
            .finish_non_exhaustive()
    }
}

impl<D: crate::dialect::Build> Table<D> {
    /// Builds the dialect on `transport` with `config`; nothing is sent until
    /// [`RateTable::connect`].
    pub fn new(transport: D::Transport, config: D::Config) -> Self {
        let (dialect, policy) = D::build(transport, config);
        Table::with_dialect(dialect, policy)
    }

    /// The dialect's configuration in force.
    pub fn config(&self) -> &D::Config {
        self.dialect().config()
    }
}

impl<D: Dialect> Table<D> {
    /// Wraps a dialect; nothing is sent until [`RateTable::connect`].
    pub fn with_dialect(dialect: D, policy: PolicyConfig) -> Self {
        Table {
            shared: Arc::new(Shared {
                dialect,
                reply_timeout: policy.reply_timeout,
                status: Mutex::new(Status {
                    state: TableState::Disconnected,
                    interlock_closed: false,
                    fault: None,
                }),
            }),
            policy,
            demand: 0.0,
            ramp: None,
            acceleration: None,
            recorder: None,
        }
    }

    /// The dialect.
    pub fn dialect(&self) -> &D {
        &self.shared.dialect
    }

    /// The policy's settings in force.
    pub fn policy(&self) -> &PolicyConfig {
        &self.policy
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
        self.shared.dialect.describe()
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

    /// Runs a dialect operation; a failed link faults the driver (after a best-effort stop),
    /// except before it ever identified the table.
    async fn call<R>(
        &self,
        op: impl Future<Output = Result<R, DialectError>>,
    ) -> Result<R, TableError> {
        match op.await {
            Ok(v) => Ok(v),
            Err(DialectError { error, link_failed }) => {
                if link_failed && self.state() != TableState::Disconnected {
                    // The returned Fault is replaced by the more precise link error.
                    let _ = self.shared.fault(error.to_string()).await;
                }
                Err(error)
            }
        }
    }

    /// Acts on a fault poll: a latched fault faults the driver with the table's text.
    async fn check_faults(&mut self, timeout: Duration) -> Result<(), TableError> {
        let polled = self.call(self.shared.dialect.poll_faults(timeout)).await?;
        match polled {
            None => Ok(()),
            Some(reason) => {
                self.demand = 0.0;
                self.ramp = None;
                Err(self.shared.fault(reason).await)
            }
        }
    }

    fn check_limits(&self, rate: f64, acceleration: f64) -> Result<(), TableError> {
        let l = &self.policy.limits;
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
}

impl<D: Dialect> RateTable for Table<D> {
    fn describe(&self) -> &str {
        self.device()
    }

    fn state(&self) -> TableState {
        self.shared.status().state
    }

    fn capabilities(&self) -> Capabilities {
        Capabilities {
            dialect: D::NAME,
            axes: 1,
            max_rate: self.policy.limits.max_rate,
            max_acceleration: self.policy.limits.max_acceleration,
            position_readback: D::POSITION_READBACK,
        }
    }

    async fn connect(&mut self) -> Result<Identity, TableError> {
        let connected = self
            .call(self.shared.dialect.connect(self.policy.reply_timeout))
            .await?;
        let mode = connected.mode;
        {
            let mut st = self.shared.status();
            st.fault = None;
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
            tracing::warn!(device = %self.device(), "table found in mode {mode:?}");
        }
        let id = &connected.identity;
        tracing::info!(
            device = %self.device(),
            "connected to {},{},{},{}",
            id.manufacturer,
            id.model,
            id.serial,
            id.version
        );
        Ok(connected.identity)
    }

    async fn enable(&mut self) -> Result<(), TableError> {
        match self.state() {
            TableState::Disconnected | TableState::Ramping { .. } | TableState::AtRate { .. } => {
                return Err(self.state_error("enable the servo"));
            }
            _ => {}
        }
        let limits = self.policy.limits;
        self.call(
            self.shared
                .dialect
                .enable(&limits, self.policy.reply_timeout),
        )
        .await?;
        let mut st = self.shared.status();
        st.state = TableState::Servoed;
        st.interlock_closed = true;
        st.fault = None;
        drop(st);
        self.demand = 0.0;
        self.ramp = None;
        Ok(())
    }

    async fn set_rate(&mut self, rate: f64, acceleration: f64) -> Result<(), TableError> {
        self.check_limits(rate, acceleration)?;
        let (state, interlock_closed) = {
            let st = self.shared.status();
            (st.state, st.interlock_closed)
        };
        let allowed = match state {
            TableState::Servoed | TableState::Ramping { .. } | TableState::AtRate { .. } => true,
            TableState::Stopping => interlock_closed,
            _ => false,
        };
        if !allowed {
            return Err(self.state_error(&format!("demand {rate} deg/s")));
        }
        // The acceleration limit is sent only when it changes while the table is under our
        // demand (a stop, an enable or a fault may have reset it on the controller).
        let unchanged = self.acceleration == Some(acceleration)
            && matches!(
                state,
                TableState::Ramping { .. } | TableState::AtRate { .. }
            );
        let send_acceleration = (!unchanged).then_some(acceleration);
        // no limit may be assumed on the table until the demand went through
        self.acceleration = None;
        let start = self
            .call(self.shared.dialect.demand_rate(
                rate,
                send_acceleration,
                self.policy.reply_timeout,
            ))
            .await?;
        self.acceleration = Some(acceleration);
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
        self.call(self.shared.dialect.read_rate(self.policy.reply_timeout))
            .await
    }

    async fn read_position(&mut self) -> Result<f64, TableError> {
        let p = self
            .call(self.shared.dialect.read_position(self.policy.reply_timeout))
            .await?;
        Ok(p.rem_euclid(360.0))
    }

    async fn status(&mut self) -> Result<TableStatus, TableError> {
        self.call(self.shared.dialect.status(self.policy.reply_timeout))
            .await
    }

    async fn sample(&mut self) -> Result<f64, TableError> {
        let deadline = self.policy.heartbeat_deadline;
        let rate = self.call(self.shared.dialect.read_rate(deadline)).await?;
        self.check_faults(deadline).await?;
        self.record(rate);
        Ok(rate)
    }

    async fn wait_at_rate(
        &mut self,
        criteria: &SettleCriteria,
    ) -> Result<SettleReport, TableError> {
        self.wait_at_rate_observed(criteria, &mut |_| {}).await
    }

    async fn wait_at_rate_observed(
        &mut self,
        criteria: &SettleCriteria,
        observe: &mut (dyn FnMut(SettleProgress) + Send),
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
        // Samples during the ramp are heartbeats on the interval; one is taken exactly at the
        // end of the computed ramp, and the stability window runs on the interval from
        // there, so a table that follows its profile is declared at rate one window after
        // the ramp, not up to an interval later. A sample's time is when it was asked (the
        // controller reads its rate as the query arrives), not when the reply came back.
        let mut next = now;
        loop {
            tokio::time::sleep_until(next).await;
            let t = Instant::now();
            let rate = self.sample().await?;
            last = if rate.is_finite() { rate } else { last };
            if t >= ramp_end && (rate - demand).abs() <= tolerance {
                let t0 = *since.get_or_insert(t);
                window.push(rate);
                observe(SettleProgress {
                    demand,
                    rate,
                    ramping: false,
                    stable_for: t - t0,
                    window: criteria.window,
                });
                if t - t0 >= criteria.window {
                    self.set_state(TableState::AtRate { rate: demand });
                    return Ok(SettleReport {
                        demand,
                        ramp_time,
                        settled_after: Instant::now() - start,
                        at_rate_since: t0,
                        window: window.stats(),
                    });
                }
            } else {
                since = None;
                window = RateAccumulator::default();
                observe(SettleProgress {
                    demand,
                    rate,
                    ramping: t < ramp_end,
                    stable_for: Duration::ZERO,
                    window: criteria.window,
                });
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
            next = (t + criteria.interval).max(Instant::now());
            if t < ramp_end {
                next = next.min(ramp_end);
            }
            next = next.min(deadline);
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
        self.check_faults(self.policy.heartbeat_deadline).await
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

    /// Polls rate and mode every [`PolicyConfig::stop_poll_interval`] until the table reports
    /// rest or `timeout` passes. A poll that gets no usable reply (a slow table, a lost or
    /// garbled reply) is asked again until the deadline, whatever the reply latency below it:
    /// after a stop, only a dead link or the deadline ends the wait unconfirmed. The reason
    /// then quotes the last rate measured, or says none was.
    async fn wait_stopped(&mut self, timeout: Duration) -> Result<RestReport, TableError> {
        let start = Instant::now();
        let deadline = start + timeout;
        let mut last: (Option<f64>, Option<TableMode>) = (None, None);
        let mut last_error: Option<TableError>;
        let mut misses = 0u32;
        let seen = |last: &(Option<f64>, Option<TableMode>)| match last {
            (None, _) => "no rate was measured".to_string(),
            (Some(rate), None) => format!("last measured {rate:+.6} deg/s, mode not read"),
            (Some(rate), Some(mode)) => format!("last measured {rate:+.6} deg/s in mode {mode}"),
        };
        loop {
            // straight through the dialect: a missed poll here is asked again, not a fault
            let poll = async {
                let rate = self
                    .shared
                    .dialect
                    .read_rate(self.policy.reply_timeout)
                    .await
                    .map_err(|e| (None, e))?;
                let mode = self
                    .shared
                    .dialect
                    .read_mode(self.policy.reply_timeout)
                    .await
                    .map_err(|e| (Some(rate), e))?;
                Ok::<_, (Option<f64>, DialectError)>((rate, mode))
            };
            match poll.await {
                Ok((rate, mode)) => {
                    last = (Some(rate), Some(mode));
                    last_error = None;
                    if rate.abs() <= self.policy.stop_tolerance && mode == TableMode::Off {
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
                }
                Err((rate, DialectError { error, .. })) => {
                    if let Some(rate) = rate {
                        last = (Some(rate), None);
                    }
                    misses += 1;
                    tracing::warn!(
                        device = %self.device(),
                        "no usable reply while waiting for rest ({error}); asking again until \
                         the rest deadline"
                    );
                    let dead = matches!(&error, TableError::Link { source, .. }
                        if source.kind() == gyrocal_link::ErrorKind::Disconnected);
                    last_error = Some(error);
                    if dead {
                        break;
                    }
                }
            }
            if Instant::now() >= deadline {
                break;
            }
            tokio::time::sleep(self.policy.stop_poll_interval).await;
        }
        let reason = match &last_error {
            Some(e) => format!(
                "could not confirm the table at rest within {:.1} s after the stop ({}; {misses} \
                 polls got no usable reply, the last: {e})",
                timeout.as_secs_f64(),
                seen(&last)
            ),
            _ => format!(
                "table not at rest {:.1} s after the stop: {} (rest is |rate| <= {} deg/s in \
                 mode OFF)",
                timeout.as_secs_f64(),
                seen(&last),
                self.policy.stop_tolerance
            ),
        };
        Err(self.shared.fault(reason).await)
    }

    /// `|from_rate|/a · 1.5 + 5 s` ([`stop_time`]) with `a` the acceleration limit last sent
    /// (which a controlled stop decelerates with; a gentler ramp than the client maximum makes
    /// a slower stop), else the client-side maximum. An emergency stop decelerates at the
    /// table's own maximum, faster: the bound holds for it too.
    fn stop_deadline(&self, from_rate: f64) -> Duration {
        let a = self
            .acceleration
            .unwrap_or(self.policy.limits.max_acceleration)
            .min(self.policy.limits.max_acceleration);
        stop_time(from_rate, a)
    }

    fn stop_handle(&self) -> StopHandle {
        StopHandle::new(self.shared.clone())
    }

    fn take_retries(&mut self) -> Vec<String> {
        self.shared.dialect.take_retries()
    }
}
