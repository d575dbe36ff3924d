//! The simulated thermal chamber: its physics ([`thermal`]) and its controller on the wire,
//! a Watlow F4 (Modbus RTU or Modbus TCP, [`watlow`]) or an Espec SH-641 (text lines,
//! [`espec`]), with faults ([`faults`]).
//!
//! One [`ChamberHandle`] holds the chamber's state (its temperatures over time, setpoint,
//! mode, alarms, faults); any number of links can serve it ([`ChamberHandle::serve`]). Time
//! is the bench's clock: sim seconds since the bench started, `time_scale` sim seconds per
//! tokio second, the same as the table's, so the gyro on the table reads the chamber's
//! inside temperature at each reading's instant ([`ChamberHandle::inside_c`]).
//!
//! The slaves are written by hand from the Modbus specification (not with the driver's
//! crate), so a driver test checks the driver's framing against an independent one.

pub mod espec;
pub mod faults;
pub mod thermal;
pub mod watlow;

use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::Duration;

use rand::RngExt;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use tokio::io::{AsyncRead, AsyncWrite};
use tokio::task::JoinHandle;
use tokio::time::Instant;

pub use faults::{ChamberAlarm, ChamberFault, ChamberFaultKind, ChamberTrigger};
pub use thermal::{Temperatures, Thermal, ThermalConfig};

use faults::{Fate, WireFaults};

/// The Watlow register the simulated door alarm is latched in (1 active, 0 clear).
pub const REG_ALARM_DOOR: u16 = 1061;
/// The Watlow register the simulated over-temperature alarm is latched in.
pub const REG_ALARM_OVERTEMP: u16 = 1063;

/// Which controller the simulated chamber has.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ChamberModel {
    /// A Watlow F4 (Modbus RTU on its serial link; Modbus TCP with [`ChamberHandle::serve_tcp`]).
    #[default]
    WatlowF4,
    /// An Espec SH-641 (text lines, CR LF).
    Espec,
}

impl std::str::FromStr for ChamberModel {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "watlow_f4" | "watlow" | "f4" => Ok(ChamberModel::WatlowF4),
            "espec" => Ok(ChamberModel::Espec),
            _ => Err(format!("{s:?} is not a chamber (watlow_f4, espec)")),
        }
    }
}

/// The simulated chamber's configuration (every field has a default).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ChamberSimConfig {
    /// The controller. Default Watlow F4.
    pub model: ChamberModel,
    /// The Modbus slave address (Watlow). Default 1.
    pub slave: u8,
    /// The physics.
    pub thermal: ThermalConfig,
    /// Decimal places of every input and the setpoint (registers 606/616/626). Default 1.
    pub decimals: u8,
    /// The temperature unit register 901: 1 = °C (default), 0 = °F (the driver refuses it;
    /// the sim keeps working in °C).
    pub units: u16,
    /// Input 1's range (registers 602/603; the Espec's alarm temperatures in `TEMP?`), °C:
    /// a setpoint outside is refused (exception 3, `NA:`). Default −70 .. 180.
    pub range_c: (f64, f64),
    /// The controller starts running a profile of its own (mode 2 on the F4, `RUN` on the
    /// Espec): the driver must terminate it before it sets a setpoint. Default false.
    pub start_in_profile: bool,
    /// The event output (1–8) that switches the chamber on: written 0 the chamber stops
    /// controlling and its air drifts back to the room (the driver's `standby`/`off` safe
    /// state). Default none (every output is a plain register).
    pub chamber_on_output: Option<u8>,
    /// The identity the Espec answers to `TYPE?`. Default `T,T,S2,160.0`.
    pub espec_identity: String,
    /// The controller's reply latency, sim seconds (after the request, before the reply).
    /// Default 0.02.
    pub latency_s: f64,
    /// Faults armed from the start.
    #[serde(skip)]
    pub faults: Vec<ChamberFault>,
}

impl Default for ChamberSimConfig {
    fn default() -> Self {
        ChamberSimConfig {
            model: ChamberModel::WatlowF4,
            slave: 1,
            thermal: ThermalConfig::default(),
            decimals: 1,
            units: 1,
            range_c: (-70.0, 180.0),
            start_in_profile: false,
            chamber_on_output: None,
            espec_identity: "T,T,S2,160.0".into(),
            latency_s: 0.02,
            faults: Vec::new(),
        }
    }
}

impl ChamberSimConfig {
    /// The chamber a plan's `[simulation]` section describes the physics of (`room_c`,
    /// `chamber_heat_c_per_min`, `chamber_cool_c_per_min`, `case_tau_s`, `inside_tau_s`,
    /// `chamber_noise_c`), with the controller `model` and Modbus `slave` of its `[chamber]`.
    /// The rest stays at the defaults above (range −70 .. 180 °C, one decimal, alarms at 1061
    /// and 1063): a plan's `alarm_registers` should name 1061 and 1063 with `active = 1`, and
    /// its `chamber_on_output` goes to [`ChamberSimConfig::chamber_on_output`].
    pub fn from_simulation(
        model: ChamberModel,
        slave: u8,
        s: &gyrocal_files::plan::Simulation,
    ) -> Self {
        ChamberSimConfig {
            model,
            slave,
            thermal: ThermalConfig {
                room_c: s.room_c,
                heat_c_per_min: s.chamber_heat_c_per_min,
                cool_c_per_min: s.chamber_cool_c_per_min,
                case_tau_s: s.case_tau_s,
                inside_tau_s: s.inside_tau_s,
                sensor_noise_c: s.chamber_noise_c,
            },
            ..ChamberSimConfig::default()
        }
    }
}

/// The controller's mode as the simulated chamber keeps it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SimMode {
    /// Controlling to the static setpoint.
    Constant,
    /// A profile of its own running (F4 mode 2).
    Profile,
    /// Standby (Espec): not controlling.
    Standby,
    /// Off (Espec): not controlling.
    Off,
}

/// The chamber's state, behind the handle's lock.
#[derive(Debug)]
pub(crate) struct State {
    pub(crate) config: ChamberSimConfig,
    thermal: Thermal,
    origin: Instant,
    time_scale: f64,
    rng: StdRng,
    pub(crate) setpoint_c: f64,
    pub(crate) mode: SimMode,
    pub(crate) outputs: [u16; 8],
    door: bool,
    overtemp: bool,
    armed: Vec<ChamberFault>,
    pub(crate) wire: WireFaults,
    requests: u64,
}

impl State {
    pub(crate) fn sim_time(&self, at: Instant) -> f64 {
        at.saturating_duration_since(self.origin).as_secs_f64() * self.time_scale
    }

    pub(crate) fn now_s(&self) -> f64 {
        self.sim_time(Instant::now())
    }

    /// Whether the controller controls (otherwise the air returns to the room).
    fn controlling(&self) -> bool {
        let on = self
            .config
            .chamber_on_output
            .and_then(|n| self.outputs.get(usize::from(n).saturating_sub(1)))
            .is_none_or(|&v| v != 0);
        on && matches!(self.mode, SimMode::Constant | SimMode::Profile)
    }

    /// Re-aims the physics after a change of setpoint, mode or output.
    pub(crate) fn retarget(&mut self) {
        let target = if self.controlling() {
            self.setpoint_c
        } else {
            self.config.thermal.room_c
        };
        let now = self.now_s();
        self.thermal.set_target(now, target);
    }

    /// A sensor reading now: the true value plus the sensor's noise.
    fn sensed(&mut self, true_c: f64) -> f64 {
        let sd = self.config.thermal.sensor_noise_c;
        if sd == 0.0 {
            return true_c;
        }
        let z: f64 = self.rng.sample(StandardNormal);
        true_c + sd * z
    }

    /// The air as the controller's sensor reads it now.
    pub(crate) fn sensed_air(&mut self) -> f64 {
        let t = self.thermal.at(self.now_s()).air_c;
        self.sensed(t)
    }

    /// The product (the gyro's case thermocouple) as the controller reads it now.
    pub(crate) fn sensed_product(&mut self) -> f64 {
        let t = self.thermal.at(self.now_s()).case_c;
        self.sensed(t)
    }

    pub(crate) fn alarm(&self, a: ChamberAlarm) -> bool {
        match a {
            ChamberAlarm::Door => self.door,
            ChamberAlarm::OverTemperature => self.overtemp,
        }
    }

    pub(crate) fn set_alarm(&mut self, a: ChamberAlarm, on: bool) {
        match a {
            ChamberAlarm::Door => self.door = on,
            ChamberAlarm::OverTemperature => self.overtemp = on,
        }
    }

    /// Fires the armed faults that are due (at the time, or at this request's number).
    fn fire_due(&mut self, request: Option<u64>) {
        let now = self.now_s();
        let armed = std::mem::take(&mut self.armed);
        for f in armed {
            let due = match f.trigger {
                ChamberTrigger::Time(t) => now >= t,
                ChamberTrigger::Request(n) => request.is_some_and(|r| r >= n),
            };
            if due {
                tracing::info!(fault = ?f, "chamber fault fires");
                self.apply(f);
            } else {
                self.armed.push(f);
            }
        }
    }

    fn apply(&mut self, f: ChamberFault) {
        match f.kind {
            ChamberFaultKind::Alarm(a) => self.set_alarm(a, true),
            ChamberFaultKind::Silent => self.wire.silent = true,
            ChamberFaultKind::Exception => self.wire.exceptions_left += f.count.max(1),
            ChamberFaultKind::Corrupt => self.wire.corrupt_left += f.count.max(1),
            ChamberFaultKind::Slow(d) => {
                self.wire.slow = Some((d, (f.count > 0).then_some(f.count)));
            }
        }
    }

    /// A request has come: counted, the due faults fired, its fate decided.
    pub(crate) fn begin_request(&mut self) -> Fate {
        self.requests += 1;
        self.fire_due(Some(self.requests));
        let mut fate = self.wire.next();
        fate.delay_s += self.config.latency_s;
        fate
    }
}

/// The simulated chamber: its state, its truth and its fault injection, shared by every link
/// serving it.
#[derive(Debug, Clone)]
pub struct ChamberHandle {
    inner: Arc<Mutex<State>>,
}

impl ChamberHandle {
    /// A chamber at room temperature, starting now, running `time_scale` sim seconds per
    /// tokio second (the bench's). Must be called inside a tokio runtime.
    pub fn new(config: ChamberSimConfig, time_scale: f64, seed: u64) -> ChamberHandle {
        let time_scale = if time_scale.is_finite() && time_scale > 0.0 {
            time_scale
        } else {
            1.0
        };
        let thermal = Thermal::new(&config.thermal);
        let mut outputs = [0u16; 8];
        if let Some(n) = config.chamber_on_output
            && let Some(o) = outputs.get_mut(usize::from(n).saturating_sub(1))
        {
            *o = 1;
        }
        let mode = if config.start_in_profile {
            SimMode::Profile
        } else {
            SimMode::Constant
        };
        let state = State {
            setpoint_c: config.thermal.room_c,
            armed: config.faults.clone(),
            config,
            thermal,
            origin: Instant::now(),
            time_scale,
            rng: StdRng::seed_from_u64(seed),
            mode,
            outputs,
            door: false,
            overtemp: false,
            wire: WireFaults::default(),
            requests: 0,
        };
        ChamberHandle {
            inner: Arc::new(Mutex::new(state)),
        }
    }

    pub(crate) fn lock(&self) -> MutexGuard<'_, State> {
        self.inner.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The configuration.
    pub fn config(&self) -> ChamberSimConfig {
        self.lock().config.clone()
    }

    /// Sim seconds since the chamber started, at `at`.
    pub fn sim_time(&self, at: Instant) -> f64 {
        self.lock().sim_time(at)
    }

    /// The true (noise-free) temperatures at `at`.
    pub fn temperatures(&self, at: Instant) -> Temperatures {
        let s = self.lock();
        let t = s.sim_time(at);
        s.thermal.at(t)
    }

    /// The true temperatures at sim time `t_s`.
    pub fn temperatures_at_sim(&self, t_s: f64) -> Temperatures {
        self.lock().thermal.at(t_s)
    }

    /// The gyro's inside temperature at `at` (what its coefficients follow), °C.
    pub fn inside_c(&self, at: Instant) -> f64 {
        self.temperatures(at).inside_c
    }

    /// The setpoint the controller holds, °C.
    pub fn setpoint_c(&self) -> f64 {
        self.lock().setpoint_c
    }

    /// The mode the controller is in.
    pub fn mode(&self) -> SimMode {
        self.lock().mode
    }

    /// Sets the setpoint as an operator at the panel would (no range check).
    pub fn set_setpoint(&self, c: f64) {
        let mut s = self.lock();
        s.setpoint_c = c;
        s.retarget();
    }

    /// Latches an alarm now.
    pub fn latch_alarm(&self, a: ChamberAlarm) {
        self.lock().set_alarm(a, true);
    }

    /// Clears every latched alarm (the operator at the panel).
    pub fn reset_alarms(&self) {
        let mut s = self.lock();
        s.door = false;
        s.overtemp = false;
    }

    /// The alarms latched now (time-triggered alarm faults that are due included).
    pub fn alarms(&self) -> Vec<ChamberAlarm> {
        let mut s = self.lock();
        s.fire_due(None);
        [ChamberAlarm::Door, ChamberAlarm::OverTemperature]
            .into_iter()
            .filter(|&a| s.alarm(a))
            .collect()
    }

    /// Arms a fault.
    pub fn arm(&self, fault: ChamberFault) {
        self.lock().armed.push(fault);
    }

    /// The controller stops (or resumes) answering.
    pub fn set_silent(&self, silent: bool) {
        self.lock().wire.silent = silent;
    }

    /// Every request touching `register` (Watlow) is refused with exception `code` from now
    /// on (on the Espec, a `TEMP` command or query with `NA:DEVICE FAULT` when `register` is
    /// 300 or 100).
    pub fn exception_on_register(&self, register: u16, code: u8) {
        self.lock().wire.register_exceptions.push((register, code));
    }

    /// Ends every [`ChamberHandle::exception_on_register`].
    pub fn clear_register_exceptions(&self) {
        self.lock().wire.register_exceptions.clear();
    }

    /// How many requests the chamber has seen.
    pub fn requests_seen(&self) -> u64 {
        self.lock().requests
    }

    /// Serves the configured controller's wire (RTU for a Watlow F4, text for an Espec) on
    /// `stream` until it closes.
    pub fn serve<S>(&self, stream: S) -> JoinHandle<()>
    where
        S: AsyncRead + AsyncWrite + Send + Unpin + 'static,
    {
        let model = self.lock().config.model;
        match model {
            ChamberModel::WatlowF4 => tokio::spawn(watlow::serve_rtu(self.clone(), stream)),
            ChamberModel::Espec => tokio::spawn(espec::serve(self.clone(), stream)),
        }
    }

    /// Serves Modbus TCP (the Watlow F4 behind a gateway) on `stream` until it closes.
    pub fn serve_tcp<S>(&self, stream: S) -> JoinHandle<()>
    where
        S: AsyncRead + AsyncWrite + Send + Unpin + 'static,
    {
        tokio::spawn(watlow::serve_tcp(self.clone(), stream))
    }

    /// A sim duration as tokio time.
    pub(crate) fn real(&self, sim_s: f64) -> Duration {
        let scale = self.lock().time_scale;
        Duration::from_secs_f64((sim_s / scale).clamp(0.0, 1e9))
    }
}
