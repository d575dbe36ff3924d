//! # gyrocal-chamber
//!
//! The thermal-chamber role: the [`Chamber`] trait a temperature series programs against, the
//! readings and errors every chamber shares, and [`NoChamber`] for a bench without one. The
//! controllers' dialects (Watlow F4 over Modbus RTU and TCP, the experimental Espec text
//! protocol) implement the trait, so the run's engine depends on no driver.
//!
//! Why a role of its own: a chamber is the second machine a run must leave safe (a gyro taken
//! from −40 °C to room air condenses water; a chamber left at 85 °C overnight cooks it), and
//! the run must stop when the chamber raises an alarm. So, like the rate table's, the role
//! says what "safe" means ([`SafeState`]) and whether it was confirmed ([`SafeReport`]), and
//! the alarms are part of every reading ([`ChamberReading::alarms`]), not an afterthought.
//!
//! Temperatures are °C everywhere in this crate: a dialect converts at the wire (and refuses a
//! controller set to °F rather than guess).
//!
//! The dialects, and how a bench builds one from a plan's `[chamber]` section:
//! - [`WatlowF4`] ([`watlow`]): Modbus RTU on a serial port ([`WatlowF4::open_rtu`]: path,
//!   baud, 8N1), Modbus TCP ([`WatlowF4::connect_tcp`]: `host:port`), or RTU over any byte
//!   stream ([`WatlowF4::over_stream`]: a simulator's in-memory pipe or pseudo-terminal), with a
//!   [`WatlowConfig`] (slave, product input, limits, timeouts, the optional alarm registers and
//!   "chamber on" output). The Modbus policy (deadlines, read retries, exception / garbled /
//!   silent) is written once in [`modbus`].
//! - [`Espec`] ([`espec`], experimental): text lines over a gyrocal-link [`gyrocal_link::Link`]
//!   ([`Espec::open`]: a port string) or any [`gyrocal_link::Transport`]
//!   ([`Espec::over_transport`]), with an [`EspecConfig`].
//! - [`AnyChamber`]: the one a plan names, chosen at run time, so the engine is not
//!   instantiated once per chamber dialect.
//!
//! What is confirmed and what is an option is in the crate's README and each dialect's docs.

mod any;
mod error;
pub mod espec;
pub mod modbus;
mod none;
pub mod watlow;

pub use any::AnyChamber;
pub use error::{ChamberError, ChamberErrorKind};
pub use espec::{Espec, EspecConfig};
pub use none::{NO_CHAMBER, NoChamber};
pub use watlow::{AlarmRegister, ProductInput, WatlowConfig, WatlowF4};

use std::fmt;
use std::future::Future;
use std::time::Duration;

use serde::{Deserialize, Serialize};

/// What the chamber's controller says it is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ChamberMode {
    /// Controlling to a static setpoint (Watlow F4 mode 0/1, Espec `CONSTANT`).
    Constant,
    /// Running a profile of the controller's own (Watlow F4 mode 2): the setpoint is not ours.
    Profile,
    /// A profile paused (Watlow F4 mode 3).
    Paused,
    /// Standby: the controller is on but not controlling (Espec `STANDBY`).
    Standby,
    /// Off: not controlling (Espec `OFF`).
    Off,
}

impl fmt::Display for ChamberMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            ChamberMode::Constant => "constant",
            ChamberMode::Profile => "profile running",
            ChamberMode::Paused => "profile paused",
            ChamberMode::Standby => "standby",
            ChamberMode::Off => "off",
        })
    }
}

/// One reading of the chamber: its temperatures, setpoint, mode and alarms, read together.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChamberReading {
    /// The air temperature (the controlled input), °C.
    pub air_c: f64,
    /// The product's temperature (the gyro's case or its own sensor, read through the
    /// controller's second or third input), °C; `None` when the chamber has no product input
    /// configured.
    pub product_c: Option<f64>,
    /// The setpoint the controller holds, °C.
    pub setpoint_c: f64,
    /// The controller's mode.
    pub mode: ChamberMode,
    /// The alarms active now (empty when none, or when the dialect cannot read them: see its
    /// documentation). A non-empty list stops a run.
    pub alarms: Vec<String>,
}

/// The state a chamber is left in when a run ends, whatever way it ends.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "state")]
pub enum SafeState {
    /// The setpoint back to ambient, the controller still controlling (the default: a gyro
    /// brought back to room temperature slowly does not condense water).
    Ambient {
        /// The ambient setpoint, °C (23 by default).
        setpoint_c: f64,
    },
    /// The controller in standby (not controlling, still on).
    Standby,
    /// The controller off.
    Off,
}

impl Default for SafeState {
    fn default() -> Self {
        SafeState::Ambient {
            setpoint_c: DEFAULT_AMBIENT_C,
        }
    }
}

/// The default ambient setpoint of [`SafeState::Ambient`], °C.
pub const DEFAULT_AMBIENT_C: f64 = 23.0;

impl fmt::Display for SafeState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SafeState::Ambient { setpoint_c } => {
                write!(f, "setpoint {setpoint_c} °C (ambient), in control")
            }
            SafeState::Standby => f.write_str("standby"),
            SafeState::Off => f.write_str("off"),
        }
    }
}

/// What [`Chamber::go_safe`] saw: whether the chamber was read back in the state asked for.
#[derive(Debug, Clone, PartialEq)]
pub struct SafeReport {
    /// The state asked for.
    pub state: SafeState,
    /// The chamber was read back in that state (setpoint and mode); `false`: it could NOT be
    /// confirmed, and [`SafeReport::detail`] says why.
    pub confirmed: bool,
    /// What was read back, or why nothing could be.
    pub detail: String,
}

/// Who the chamber's controller says it is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChamberIdentity {
    /// The controller (`Watlow F4`, `Espec SH-641`).
    pub model: String,
    /// What it answered to identify itself (the Espec `TYPE?` reply; the F4's units and
    /// decimal places), for the run's manifest.
    pub detail: String,
}

/// How long the chamber's link takes, for the run's estimate and the drivers' deadlines.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChamberTiming {
    /// A whole reading ([`Chamber::read`]: every query it takes, replies included).
    pub read: Duration,
    /// The longest a single reply may take before the chamber counts as silent.
    pub reply_timeout: Duration,
}

/// A thermal chamber, as a temperature series uses it. Every method may be called after any
/// error; [`Chamber::go_safe`] in particular is the teardown's and must try its best whatever
/// state the link is in.
pub trait Chamber: Send {
    /// The chamber's link, for messages (`/dev/ttyUSB2 (Watlow F4, Modbus RTU, slave 1)`).
    fn describe(&self) -> &str;

    /// Whether this is a real chamber role ([`NoChamber`] says `false`).
    fn present(&self) -> bool {
        true
    }

    /// Identifies the controller and reads what the dialect needs before anything is set (the
    /// F4's temperature unit and decimal places: a controller in °F is refused).
    fn connect(&mut self) -> impl Future<Output = Result<ChamberIdentity, ChamberError>> + Send;

    /// Sets the setpoint, °C, and puts the controller in control (constant mode; a running
    /// profile of the controller's own is terminated first). A setpoint outside the driver's
    /// limits is refused before anything is sent ([`ChamberErrorKind::Limit`]). There is no
    /// ramp here on purpose: a plan's ramp rate is the run's (the setpoint stepped towards the
    /// target at each poll), written once for every dialect, since the controllers' own ramps
    /// are profile features that differ from one to the next.
    fn set_setpoint(
        &mut self,
        setpoint_c: f64,
    ) -> impl Future<Output = Result<(), ChamberError>> + Send;

    /// Reads the temperatures, setpoint, mode and alarms. Idempotent queries: a garbled or
    /// lost reply is asked again within the deadline (noted in [`Chamber::take_retries`]).
    fn read(&mut self) -> impl Future<Output = Result<ChamberReading, ChamberError>> + Send;

    /// Clears latched alarms where the dialect can (an operator's explicit act; never done by
    /// a run on its own).
    fn reset_alarms(&mut self) -> impl Future<Output = Result<(), ChamberError>> + Send;

    /// Puts the chamber in `state` and reads it back: confirmed or not, never an error (the
    /// teardown's call: a silent chamber gives `confirmed: false` with the reason).
    fn go_safe(&mut self, state: SafeState) -> impl Future<Output = SafeReport> + Send;

    /// The link's timing.
    fn timing(&self) -> ChamberTiming;

    /// The retries since the last call (a garbled or lost reply asked again), one line each,
    /// for the run's manifest.
    fn take_retries(&mut self) -> Vec<String> {
        Vec::new()
    }
}
