//! The simulated 34401A's configuration ([`DmmConfig`]): its interface, what it does in
//! LOCAL, its timing, noise and scheduled faults, each with its documented default; invalid
//! values are logged and replaced by the defaults when the meter is spawned.

use serde::{Deserialize, Serialize};

use super::{DEFAULT_IDENTITY, Fault, Framing};

/// Which remote interface the simulated meter serves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Interface {
    /// The RS-232 port (the default): `SYST:REM` first, replies end CR LF, 11-bit characters
    /// at the configured baud, Ctrl-C device clear.
    #[default]
    Rs232,
    /// GPIB behind a controller (see the module documentation).
    Gpib,
}

/// A fault from the configuration, injected once `after_commands` commands have been seen.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScheduledFault {
    /// Commands (program message units, from the first) seen before the fault is injected.
    pub after_commands: u64,
    /// The fault.
    pub fault: Fault,
}

/// The simulated meter's configuration. Every field has a default; TOML or JSON may give any.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DmmConfig {
    /// `*IDN?` reply. Default [`DEFAULT_IDENTITY`].
    pub identity: String,
    /// Require `SYST:REM` (or `SYST:RWL`) before other commands take effect. Default true.
    /// False is the same as `local_mode = "obey"`: the meter also starts (and comes back from a
    /// power cycle) in remote.
    pub strict_remote: bool,
    /// What the meter does with commands and queries received over RS-232 in LOCAL (before
    /// `SYST:REM`, after `SYST:LOC` or a power cycle) when `strict_remote` is true. The manual
    /// only says the results are then unpredictable; default `refuse`.
    pub local_mode: LocalMode,
    /// Off time of a power cycle ([`Fault::PowerCycle`] without its own), in sim seconds.
    /// Default 5.
    pub power_off_s: f64,
    /// Baud rate for the wire timing. Default 9600 (factory setting).
    pub baud: u32,
    /// Framing; every framing is 11 bits per character, so it does not change the timing.
    /// Default 8N2.
    pub framing: Framing,
    /// Power-line frequency (50 or 60 Hz) setting the integration time. Default 50.
    pub line_hz: u32,
    /// Standard deviation of the gaussian reading noise, volts. Default 1 µV.
    pub noise_v: f64,
    /// Output buffer for `READ?`, in characters: measuring pauses while a reading does not fit.
    /// Unconfirmed in the manual; default 512 (32 readings).
    pub output_buffer: usize,
    /// 1.0 = real instrument timing; 10.0 runs everything ten times faster (for pseudo-terminal
    /// tests in real time). Default 1.0.
    pub time_scale: f64,
    /// Faults injected when the command count reaches their mark. Default none.
    pub faults: Vec<ScheduledFault>,
    /// The remote interface served. Default `rs232`.
    pub interface: Interface,
}

impl Default for DmmConfig {
    fn default() -> Self {
        DmmConfig {
            identity: DEFAULT_IDENTITY.to_string(),
            strict_remote: true,
            local_mode: LocalMode::Refuse,
            power_off_s: 5.0,
            baud: 9600,
            framing: Framing::EightNone,
            line_hz: 50,
            noise_v: 1e-6,
            output_buffer: 512,
            time_scale: 1.0,
            faults: Vec::new(),
            interface: Interface::Rs232,
        }
    }
}

impl DmmConfig {
    /// Checks the values [`super::SimDmm::spawn`] needs.
    pub fn validate(&self) -> Result<(), String> {
        if !gyrocal_link::SUPPORTED_BAUDS.contains(&self.baud) {
            return Err(format!("baud {} not supported", self.baud));
        }
        if self.line_hz != 50 && self.line_hz != 60 {
            return Err(format!("line_hz {} is neither 50 nor 60", self.line_hz));
        }
        if !(self.time_scale.is_finite() && self.time_scale > 0.0) {
            return Err(format!("time_scale {} must be positive", self.time_scale));
        }
        if !(self.noise_v.is_finite() && self.noise_v >= 0.0) {
            return Err(format!("noise_v {} must be >= 0", self.noise_v));
        }
        if !(self.power_off_s.is_finite() && self.power_off_s >= 0.0) {
            return Err(format!("power_off_s {} must be >= 0", self.power_off_s));
        }
        if self.output_buffer < 17 {
            return Err(format!(
                "output_buffer {} cannot hold a reading",
                self.output_buffer
            ));
        }
        Ok(())
    }
}

/// What the simulated meter does in LOCAL with everything but `SYST:REM` and `SYST:RWL`.
///
/// The User's Guide says `SYST:REM` must be sent first over RS-232, otherwise "results are
/// unpredictable", and lists error 550 "Command not allowed in local" for a `READ?` received
/// in local over RS-232. `refuse` applies that error to every command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LocalMode {
    /// Every command and query is refused with error 550 "Command not allowed in local"
    /// queued; queries are not answered (so `SYST:ERR?` cannot read it before `SYST:REM`).
    #[default]
    Refuse,
    /// Everything is ignored: nothing executed, nothing answered, nothing queued.
    Ignore,
    /// Everything is executed as in remote (only the remote flag differs).
    Obey,
}

pub(super) fn sanitize(mut c: DmmConfig) -> DmmConfig {
    if let Err(e) = c.validate() {
        tracing::warn!(error = %e, "simulated 34401A: invalid configuration, using defaults for bad values");
        let d = DmmConfig::default();
        if !gyrocal_link::SUPPORTED_BAUDS.contains(&c.baud) {
            c.baud = d.baud;
        }
        if c.line_hz != 50 && c.line_hz != 60 {
            c.line_hz = d.line_hz;
        }
        if !(c.time_scale.is_finite() && c.time_scale > 0.0) {
            c.time_scale = 1.0;
        }
        if !(c.noise_v.is_finite() && c.noise_v >= 0.0) {
            c.noise_v = d.noise_v;
        }
        c.output_buffer = c.output_buffer.max(17);
        if !(c.power_off_s.is_finite() && c.power_off_s >= 0.0) {
            c.power_off_s = d.power_off_s;
        }
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn config_defaults_and_toml() {
        let c: DmmConfig = toml::from_str("").unwrap();
        assert_eq!(c, DmmConfig::default());
        let c: DmmConfig = toml::from_str(
            "baud = 1200\nframing = \"7E2\"\ntime_scale = 10.0\n[[faults]]\nafter_commands = 5\nfault = { kind = \"overload\", readings = 3 }\n",
        )
        .unwrap();
        assert_eq!(c.baud, 1200);
        assert_eq!(c.faults[0].fault, Fault::Overload { readings: 3 });
        assert!(toml::from_str::<DmmConfig>("bogus = 1").is_err());
    }
}
