//! The simulated hemispherical resonator gyro (HRG) on the simulated table: its output voltage
//! is what the simulated multimeter reads.
//!
//! Model (`shared/docs/method.md`), with ω the input rate in deg/s:
//!
//! ```text
//! ω = ω_table + Ω_E·sin(latitude)          Ω_E = 15.041 deg/h (vertical Earth-rate component)
//! D = K0 + K1±·ω + K2·ω² + K3·ω³ + bias walk + thermal drift + white noise
//! ```
//!
//! `K1±` is `k1` for ω ≥ 0 and `k1_neg` (if set) for ω < 0: a scale-factor asymmetry. The
//! table's *actual* rate (profile, ripple, wobble; no readback noise) is sampled at a few
//! instants inside each reading's integration window and the output averaged, as an
//! integrating A/D converter does. White noise is given as the standard deviation of the
//! output averaged over one second, so a longer integration gives a quieter reading.
//!
//! # Rate noise (IEEE 952 terms)
//!
//! On top of that, the gyro can carry the noise terms of IEEE 952 as *input-referred rate* in
//! °/h (all off by default), turned into volts through the scale factor `k1`:
//! `v = k1 · rate_dph / 3600`.
//!
//! * Angle random walk N (`arw_deg_rt_h`, °/√h), bias instability B (`bias_instability_dph`,
//!   °/h, flicker rate noise as a sum of Gauss–Markov processes flat from about 10 steps to
//!   `flicker_max_tau_s`/10) and rate random walk K (`rrw_dph_rt_h`, °/h/√h) come from
//!   [`gyrocal_allan::sim::Generator`] run on the gyro's own fixed time base of
//!   `noise_step_s` sim seconds (default 10 ms): the rate is constant within a step and the
//!   integrated noise angle θ(t) is continuous. A reading over `[t0, t1]` gets the mean rate
//!   (θ(t1) − θ(t0))/(t1 − t0), so the noise is the same process whatever the meter's
//!   integration time, interval or dead time; an Allan deviation of readings every τ0 s shows
//!   σ(τ) = 60·N/√τ °/h (τ in s), the flicker floor 0.664·B and K·√(τ/3)/60.
//!   Windows shorter than a step see the rate of a whole step (the noise is band-limited to
//!   1/(2·noise_step_s)).
//! * Quantization (`quantization_arcsec`, the angle step q in arcsec): the gyro's indicated
//!   angle A = ∫ output/k1 dt (1″ = 1 (°/h)·s) is quantized in steps of q, and a reading is
//!   the change of the quantized angle over its window divided by the window:
//!   `rate + (φ(t0) − φ(t1))/T`, with φ = A mod q. With back-to-back windows and enough motion
//!   (or noise) between readings, φ is uniform and independent per reading, so the Allan
//!   variance has IEEE 952's 3Q²/τ² with Q = q/√12 ([`RateNoise::quantization_q_arcsec`]).
//!   Over a dead time between windows the angle advances at the next window's mean rate (an
//!   approximation: φ is effectively random there anyway). The per-reading white output
//!   noise `noise_std` is added after the quantizer (readout noise at the meter's input).
//! * Warm-up (`warmup_dph`, °/h, `warmup_tau_s`, s): the bias starts off by `warmup_dph` and
//!   decays as `warmup_dph · exp(−t/warmup_tau_s)` (t the sim time since the table started);
//!   a reading gets its exact mean over the window.
//!
//! Each process draws from its own stream derived from the gyro's seed, and only when it is
//! on: with every term at 0 the readings are bit for bit what they were without them.
//!
//! # Temperature (issue 26)
//!
//! The scale factor, the bias and K2 follow the gyro's **inside** temperature T (the
//! chamber's [`crate::chamber::ChamberHandle::inside_c`] at the middle of each reading's
//! window when the bench has a chamber, `room_c` otherwise), with ΔT = T − `t_ref_c`:
//!
//! ```text
//! K1±(T)   = K1± · f,   f = 1 + 1e-6·(k_tempco_ppm_per_c·ΔT + k_tempco2_ppm_per_c2·ΔT² + h·hysteresis_k_ppm/2)
//! bias(T)  = K0/K̄1·3600 + bias_tempco_dph_per_c·ΔT + bias_tempco2_dph_per_c2·ΔT² + h·hysteresis_dph/2   (°/h)
//! K0(T)    = K̄1(T) · bias(T) / 3600        (so K0(T)/K̄1(T)·3600 is exactly bias(T); K̄1 the two directions' mean)
//! K2(T)    = K2 · (1 + 1e-6·k2_tempco_ppm_per_c·ΔT)
//! ```
//!
//! `h` is the hysteresis side: +1 when the inside temperature was last moving up (the
//! temperature reached from below), −1 when moving down, 0 before it has moved: a play
//! (backlash) operator of width [`HYSTERESIS_PLAY_C`] on the inside temperature, updated at
//! each reading. So a temperature revisited from the other side shows K differing by
//! `hysteresis_k_ppm` and the bias by `hysteresis_dph`. The bias tempcos are of the
//! rate-referred bias (°/h), the quantity a series reports. Every coefficient is 0 by
//! default, and then the temperature is not even looked at: readings are bit for bit what
//! they were. [`GyroTruth::at_temperature`] gives the coefficients at a temperature.

use std::time::Duration;

use gyrocal_allan::sim::{Generator, GyroNoise};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use tokio::time::Instant;

use crate::SignalSource;
use crate::table::TableHandle;

/// Earth's rotation rate, deg/h: the plan's one constant (the simulated truth and the drift
/// analysis's Earth-rate correction must agree on it).
pub const EARTH_RATE_DEG_PER_H: f64 = gyrocal_files::plan::EARTH_RATE_DPH;

/// Configuration of the simulated gyro. Every field has a default; unknown fields are errors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GyroConfig {
    /// Bias K0, V. Default 0.0088 (the paper's least-squares bias).
    pub k0: f64,
    /// Scale factor K1 for ω ≥ 0 (and for ω < 0 when `k1_neg` is unset), V/(deg/s).
    /// Default 0.3612 (the paper's).
    pub k1: f64,
    /// Scale factor for ω < 0, V/(deg/s); unset means symmetric. Default unset.
    pub k1_neg: Option<f64>,
    /// Second-order coefficient K2, V/(deg/s)². Default 0.
    pub k2: f64,
    /// Third-order coefficient K3, V/(deg/s)³. Default 0.
    pub k3: f64,
    /// Latitude of the bench, degrees (north positive). Default 45.
    pub latitude_deg: f64,
    /// Whether the vertical Earth-rate component adds to the input. Default true.
    pub earth_rate: bool,
    /// White output noise: standard deviation of the output averaged over 1 s, V. A reading
    /// integrated over T seconds has `noise_std/√T`. Default 0.0002.
    pub noise_std: f64,
    /// Bias random walk, V/√s (sim time). Default 1e-6.
    pub bias_random_walk: f64,
    /// Thermal drift amplitude: the bias rises by this much with a first-order warm-up,
    /// V. Default 0 (off).
    pub thermal_drift: f64,
    /// Time constant of the thermal warm-up, s (sim time). Default 600.
    pub thermal_time_constant: f64,
    /// Sub-samples of the table rate per reading window. Default 8.
    pub subsamples: u32,
    /// Angle random walk N (white rate noise), °/√h: the Allan deviation of the rate is
    /// 60·N/√τ °/h at τ seconds. Default 0 (off).
    pub arw_deg_rt_h: f64,
    /// Bias instability B (flicker rate noise), °/h: the Allan deviation's flat floor is
    /// 0.664·B. Default 0 (off).
    pub bias_instability_dph: f64,
    /// Rate random walk K, °/h/√h: the Allan deviation is K·√(τ/3)/60 °/h at τ seconds.
    /// Default 0 (off).
    pub rrw_dph_rt_h: f64,
    /// Angle quantization: the step q of the quantized output angle, arcsec (IEEE 952's
    /// Q = q/√12). Default 0 (off).
    pub quantization_arcsec: f64,
    /// Warm-up transient of the bias: the bias starts off by this much and decays with
    /// `warmup_tau_s`, °/h. Default 0 (off).
    pub warmup_dph: f64,
    /// Time constant of the warm-up transient, s (sim time). Default 600.
    pub warmup_tau_s: f64,
    /// Time step of the rate-noise processes (ARW, bias instability, RRW), s (sim time).
    /// Default 0.01.
    pub noise_step_s: f64,
    /// Longest τ over which the bias-instability (flicker) model stays flat, s. Default 10⁴.
    pub flicker_max_tau_s: f64,
    /// The gyro's temperature without a chamber, °C. Default 23.
    pub room_c: f64,
    /// The temperature the coefficients above are at, °C. Default 25.
    pub t_ref_c: f64,
    /// Scale factor's first-order tempco, ppm/°C. Default 0.
    pub k_tempco_ppm_per_c: f64,
    /// Scale factor's second-order tempco, ppm/°C². Default 0.
    pub k_tempco2_ppm_per_c2: f64,
    /// The bias's first-order tempco, (°/h)/°C. Default 0.
    pub bias_tempco_dph_per_c: f64,
    /// The bias's second-order tempco, (°/h)/°C². Default 0.
    pub bias_tempco2_dph_per_c2: f64,
    /// K2's tempco, ppm/°C (relative). Default 0.
    pub k2_tempco_ppm_per_c: f64,
    /// Scale-factor hysteresis: K reached from below minus K reached from above, ppm.
    /// Default 0.
    pub hysteresis_k_ppm: f64,
    /// Bias hysteresis: the bias reached from below minus from above, °/h. Default 0.
    pub hysteresis_dph: f64,
}

impl Default for GyroConfig {
    fn default() -> Self {
        GyroConfig {
            k0: 0.0088,
            k1: 0.3612,
            k1_neg: None,
            k2: 0.0,
            k3: 0.0,
            latitude_deg: 45.0,
            earth_rate: true,
            noise_std: 0.0002,
            bias_random_walk: 1e-6,
            thermal_drift: 0.0,
            thermal_time_constant: 600.0,
            subsamples: 8,
            arw_deg_rt_h: 0.0,
            bias_instability_dph: 0.0,
            rrw_dph_rt_h: 0.0,
            quantization_arcsec: 0.0,
            warmup_dph: 0.0,
            warmup_tau_s: 600.0,
            noise_step_s: 0.01,
            flicker_max_tau_s: 1.0e4,
            room_c: 23.0,
            t_ref_c: 25.0,
            k_tempco_ppm_per_c: 0.0,
            k_tempco2_ppm_per_c2: 0.0,
            bias_tempco_dph_per_c: 0.0,
            bias_tempco2_dph_per_c2: 0.0,
            k2_tempco_ppm_per_c: 0.0,
            hysteresis_k_ppm: 0.0,
            hysteresis_dph: 0.0,
        }
    }
}

impl GyroConfig {
    /// Takes the temperature keys of a plan's `[simulation]` section (`room_c`, `t_ref_c`,
    /// the tempcos and the hysteresis), leaving every other field as it is.
    pub fn set_temperature_keys(&mut self, s: &gyrocal_files::plan::Simulation) {
        self.room_c = s.room_c;
        self.t_ref_c = s.t_ref_c;
        self.k_tempco_ppm_per_c = s.k_tempco_ppm_per_c;
        self.k_tempco2_ppm_per_c2 = s.k_tempco2_ppm_per_c2;
        self.bias_tempco_dph_per_c = s.bias_tempco_dph_per_c;
        self.bias_tempco2_dph_per_c2 = s.bias_tempco2_dph_per_c2;
        self.k2_tempco_ppm_per_c = s.k2_tempco_ppm_per_c;
        self.hysteresis_k_ppm = s.hysteresis_k_ppm;
        self.hysteresis_dph = s.hysteresis_dph;
    }
}

/// The IEEE 952 rate-noise terms and the warm-up of a simulated gyro as set (a value that is
/// not finite or is negative is 0, off; so is a warm-up with a time constant that is not > 0).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct RateNoise {
    /// Angle random walk N, °/√h.
    pub arw_deg_rt_h: f64,
    /// Bias instability B, °/h.
    pub bias_instability_dph: f64,
    /// Rate random walk K, °/h/√h.
    pub rrw_dph_rt_h: f64,
    /// Angle quantization step q, arcsec.
    pub quantization_arcsec: f64,
    /// Warm-up amplitude, °/h (the bias offset at t = 0).
    pub warmup_dph: f64,
    /// Warm-up time constant, s.
    pub warmup_tau_s: f64,
}

fn amplitude(x: f64) -> f64 {
    if x.is_finite() && x > 0.0 { x } else { 0.0 }
}

impl RateNoise {
    /// The terms of a configuration.
    pub fn from_config(c: &GyroConfig) -> Self {
        let tau = amplitude(c.warmup_tau_s);
        let warmup = if tau > 0.0 && c.warmup_dph.is_finite() {
            c.warmup_dph
        } else {
            0.0
        };
        RateNoise {
            arw_deg_rt_h: amplitude(c.arw_deg_rt_h),
            bias_instability_dph: amplitude(c.bias_instability_dph),
            rrw_dph_rt_h: amplitude(c.rrw_dph_rt_h),
            quantization_arcsec: amplitude(c.quantization_arcsec),
            warmup_dph: warmup,
            warmup_tau_s: c.warmup_tau_s,
        }
    }

    /// IEEE 952's quantization coefficient Q = q/√12, arcsec (what an Allan-deviation fit
    /// reports for the quantization step q).
    pub fn quantization_q_arcsec(&self) -> f64 {
        self.quantization_arcsec / 12f64.sqrt()
    }

    /// The Allan deviation of the rate at τ seconds the terms add up to, °/h (IEEE 952:
    /// 3Q²/τ² + N²/τ + (2 ln 2/π)B² + K²τ/3 in mixed units; the warm-up is left out).
    pub fn adev_dph(&self, tau_s: f64) -> f64 {
        let q = self.quantization_q_arcsec();
        let n = 60.0 * self.arw_deg_rt_h;
        let b = gyrocal_allan::FLICKER_FLOOR * self.bias_instability_dph;
        let k = self.rrw_dph_rt_h / 60.0;
        (3.0 * q * q / (tau_s * tau_s) + n * n / tau_s + b * b + k * k * tau_s / 3.0).sqrt()
    }

    /// The warm-up offset of the bias at sim time `t_s`, °/h.
    pub fn warmup_at(&self, t_s: f64) -> f64 {
        if self.warmup_dph == 0.0 {
            return 0.0;
        }
        self.warmup_dph * (-t_s.max(0.0) / self.warmup_tau_s).exp()
    }

    /// The mean warm-up offset over `[t0, t1]` (sim seconds), °/h.
    pub fn warmup_mean(&self, t0: f64, t1: f64) -> f64 {
        if self.warmup_dph == 0.0 {
            return 0.0;
        }
        let (t0, t1) = (t0.max(0.0), t1.max(0.0));
        if t1 > t0 {
            let tau = self.warmup_tau_s;
            self.warmup_dph * tau * ((-t0 / tau).exp() - (-t1 / tau).exp()) / (t1 - t0)
        } else {
            self.warmup_at(t0)
        }
    }

    fn stochastic(&self) -> bool {
        self.arw_deg_rt_h > 0.0 || self.bias_instability_dph > 0.0 || self.rrw_dph_rt_h > 0.0
    }

    /// True when every term is off.
    pub fn is_off(&self) -> bool {
        !self.stochastic() && self.quantization_arcsec == 0.0 && self.warmup_dph == 0.0
    }
}

/// The "true" model of a simulated gyro, for tests to compare fits against.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GyroTruth {
    /// Bias K0, V (without the Earth-rate contribution).
    pub k0: f64,
    /// Scale factor for ω ≥ 0, V/(deg/s).
    pub k1_pos: f64,
    /// Scale factor for ω < 0, V/(deg/s).
    pub k1_neg: f64,
    /// K2, V/(deg/s)².
    pub k2: f64,
    /// K3, V/(deg/s)³.
    pub k3: f64,
    /// Vertical Earth-rate component added to every input, deg/s.
    pub earth_rate: f64,
    /// The rate-noise terms and the warm-up as set.
    #[serde(default)]
    pub rate_noise: RateNoise,
    /// How the coefficients above (at `t_ref_c`) follow the temperature.
    #[serde(default)]
    pub temperature: TempModel,
}

/// The width of the play operator deciding the hysteresis side, °C: the inside temperature
/// must move this much against its last direction to turn it.
pub const HYSTERESIS_PLAY_C: f64 = 1.0;

/// How a gyro's coefficients follow its inside temperature (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct TempModel {
    /// The reference temperature, °C.
    pub t_ref_c: f64,
    /// K's tempco, ppm/°C.
    pub k_tempco_ppm_per_c: f64,
    /// K's second-order tempco, ppm/°C².
    pub k_tempco2_ppm_per_c2: f64,
    /// The bias's tempco, (°/h)/°C.
    pub bias_tempco_dph_per_c: f64,
    /// The bias's second-order tempco, (°/h)/°C².
    pub bias_tempco2_dph_per_c2: f64,
    /// K2's tempco, ppm/°C.
    pub k2_tempco_ppm_per_c: f64,
    /// K hysteresis (from below − from above), ppm.
    pub hysteresis_k_ppm: f64,
    /// Bias hysteresis (from below − from above), °/h.
    pub hysteresis_dph: f64,
}

fn finite_or_zero(x: f64) -> f64 {
    if x.is_finite() { x } else { 0.0 }
}

impl TempModel {
    /// From a configuration (a coefficient that is not finite is 0).
    pub fn from_config(c: &GyroConfig) -> Self {
        TempModel {
            t_ref_c: if c.t_ref_c.is_finite() {
                c.t_ref_c
            } else {
                25.0
            },
            k_tempco_ppm_per_c: finite_or_zero(c.k_tempco_ppm_per_c),
            k_tempco2_ppm_per_c2: finite_or_zero(c.k_tempco2_ppm_per_c2),
            bias_tempco_dph_per_c: finite_or_zero(c.bias_tempco_dph_per_c),
            bias_tempco2_dph_per_c2: finite_or_zero(c.bias_tempco2_dph_per_c2),
            k2_tempco_ppm_per_c: finite_or_zero(c.k2_tempco_ppm_per_c),
            hysteresis_k_ppm: finite_or_zero(c.hysteresis_k_ppm),
            hysteresis_dph: finite_or_zero(c.hysteresis_dph),
        }
    }

    /// True when nothing depends on the temperature.
    pub fn is_off(&self) -> bool {
        self.k_tempco_ppm_per_c == 0.0
            && self.k_tempco2_ppm_per_c2 == 0.0
            && self.bias_tempco_dph_per_c == 0.0
            && self.bias_tempco2_dph_per_c2 == 0.0
            && self.k2_tempco_ppm_per_c == 0.0
            && self.hysteresis_k_ppm == 0.0
            && self.hysteresis_dph == 0.0
    }
}

/// The hysteresis side of the inside temperature: a play operator of width
/// [`HYSTERESIS_PLAY_C`].
#[derive(Debug, Clone, Copy, Default)]
struct Play {
    side: f64,
    /// The extreme reached in the current direction (the start before any move).
    extreme: Option<f64>,
}

impl Play {
    /// The side after the temperature `t_c`: +1 moving up, −1 moving down, 0 not yet moved.
    fn update(&mut self, t_c: f64) -> f64 {
        let Some(ext) = self.extreme else {
            self.extreme = Some(t_c);
            return self.side;
        };
        let moved = t_c - ext;
        if (self.side > 0.0 && t_c > ext) || (self.side < 0.0 && t_c < ext) {
            self.extreme = Some(t_c);
        } else if moved.abs() > HYSTERESIS_PLAY_C {
            self.side = moved.signum();
            self.extreme = Some(t_c);
        }
        self.side
    }
}

impl GyroTruth {
    /// From a configuration.
    pub fn from_config(c: &GyroConfig) -> Self {
        let earth_rate = if c.earth_rate {
            EARTH_RATE_DEG_PER_H / 3600.0 * c.latitude_deg.to_radians().sin()
        } else {
            0.0
        };
        GyroTruth {
            k0: c.k0,
            k1_pos: c.k1,
            k1_neg: c.k1_neg.unwrap_or(c.k1),
            k2: c.k2,
            k3: c.k3,
            earth_rate,
            rate_noise: RateNoise::from_config(c),
            temperature: TempModel::from_config(c),
        }
    }

    /// The coefficients at the inside temperature `t_c`, °C, without hysteresis (midway
    /// between the two sides): what an ideal calibration at that temperature finds.
    pub fn at_temperature(&self, t_c: f64) -> GyroTruth {
        self.at_temperature_side(t_c, 0.0)
    }

    /// The coefficients at `t_c` reached from below (`from_below`, heating) or from above.
    pub fn at_temperature_reached(&self, t_c: f64, from_below: bool) -> GyroTruth {
        self.at_temperature_side(t_c, if from_below { 1.0 } else { -1.0 })
    }

    fn at_temperature_side(&self, t_c: f64, side: f64) -> GyroTruth {
        let m = &self.temperature;
        if m.is_off() {
            return *self;
        }
        let dt = t_c - m.t_ref_c;
        let f = 1.0
            + 1e-6
                * (m.k_tempco_ppm_per_c * dt
                    + m.k_tempco2_ppm_per_c2 * dt * dt
                    + side * m.hysteresis_k_ppm / 2.0);
        let k1_mean = (self.k1_pos + self.k1_neg) / 2.0;
        let bias_shift_dph = m.bias_tempco_dph_per_c * dt
            + m.bias_tempco2_dph_per_c2 * dt * dt
            + side * m.hysteresis_dph / 2.0;
        GyroTruth {
            k0: f * (self.k0 + k1_mean * bias_shift_dph / 3600.0),
            k1_pos: self.k1_pos * f,
            k1_neg: self.k1_neg * f,
            k2: self.k2 * (1.0 + 1e-6 * m.k2_tempco_ppm_per_c * dt),
            ..*self
        }
    }

    /// The rate-referred bias K0/K̄1·3600, °/h (K̄1 the two directions' mean; no Earth rate).
    pub fn bias_dph(&self) -> f64 {
        self.k0 / ((self.k1_pos + self.k1_neg) / 2.0) * 3600.0
    }

    /// Noise-free output (no walk, no drift) at input rate `input` (Earth rate included), V.
    pub fn output_at_input(&self, input: f64) -> f64 {
        let k1 = if input >= 0.0 {
            self.k1_pos
        } else {
            self.k1_neg
        };
        self.k0 + k1 * input + self.k2 * input * input + self.k3 * input.powi(3)
    }

    /// Noise-free output at table rate `table_rate`, deg/s (the Earth rate is added), V.
    pub fn output(&self, table_rate: f64) -> f64 {
        self.output_at_input(table_rate + self.earth_rate)
    }

    /// The bias a calibration should find: the output at zero table rate, including the
    /// Earth-rate term, V.
    pub fn effective_k0(&self) -> f64 {
        self.output(0.0)
    }

    /// The least-squares line `(K, K0)` through the noise-free outputs at `rates`: what an
    /// ideal linear calibration over that schedule returns (equals `(k1, effective_k0)` for a
    /// linear, symmetric gyro).
    pub fn fit_line(&self, rates: &[f64]) -> (f64, f64) {
        let n = rates.len() as f64;
        if rates.len() < 2 {
            return (f64::NAN, f64::NAN);
        }
        let mx = rates.iter().sum::<f64>() / n;
        let ys: Vec<f64> = rates.iter().map(|&w| self.output(w)).collect();
        let my = ys.iter().sum::<f64>() / n;
        let sxy: f64 = rates
            .iter()
            .zip(&ys)
            .map(|(x, y)| (x - mx) * (y - my))
            .sum();
        let sxx: f64 = rates.iter().map(|x| (x - mx).powi(2)).sum();
        let k = sxy / sxx;
        (k, my - k * mx)
    }
}

/// SplitMix64: independent sub-seeds from the gyro's seed.
fn sub_seed(seed: u64, stream: u64) -> u64 {
    let mut z = seed.wrapping_add(stream.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// ARW + bias instability + RRW on the fixed time base: step k covers `[k·h, (k+1)·h)` with
/// the constant rate `rate`, and `theta` is the integrated noise angle at `k·h`, arcsec.
#[derive(Debug)]
struct NoiseClock {
    generator: Generator,
    step: f64,
    k: u64,
    theta: f64,
    rate: f64,
}

impl NoiseClock {
    /// The integrated noise angle at sim time `t`, arcsec ((°/h)·s). Times must not go back
    /// by more than the current step (earlier ones read as its start).
    fn theta(&mut self, t: f64) -> f64 {
        while t >= (self.k + 1) as f64 * self.step {
            self.theta += self.rate * self.step;
            self.k += 1;
            self.rate = self.generator.next_sample();
        }
        self.theta + self.rate * (t - self.k as f64 * self.step).max(0.0)
    }
}

/// The phase of the indicated angle within a quantization step, arcsec, at the end of the
/// last reading.
#[derive(Debug)]
struct Quantizer {
    step: f64,
    phase: f64,
    last_end: Option<f64>,
}

/// The gyro's output voltage as a [`SignalSource`] for the simulated multimeter.
pub struct GyroSignal {
    config: GyroConfig,
    truth: GyroTruth,
    table: TableHandle,
    rng: StdRng,
    walk: f64,
    last_t: Option<f64>,
    noise: Option<NoiseClock>,
    quantizer: Option<Quantizer>,
    chamber: Option<crate::chamber::ChamberHandle>,
    play: Play,
}

impl std::fmt::Debug for GyroSignal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GyroSignal")
            .field("truth", &self.truth)
            .finish_non_exhaustive()
    }
}

impl GyroSignal {
    /// A gyro mounted on `table`, with its own seeded noise.
    pub fn new(config: GyroConfig, table: TableHandle, seed: u64) -> Self {
        let truth = GyroTruth::from_config(&config);
        let rn = truth.rate_noise;
        let noise = rn.stochastic().then(|| {
            let step = if config.noise_step_s.is_finite() && config.noise_step_s > 0.0 {
                config.noise_step_s
            } else {
                0.01
            };
            let flicker_max_tau_s =
                if config.flicker_max_tau_s.is_finite() && config.flicker_max_tau_s > 0.0 {
                    config.flicker_max_tau_s
                } else {
                    1.0e4
                };
            let spec = GyroNoise {
                arw_deg_per_sqrt_h: rn.arw_deg_rt_h,
                bias_instability_deg_per_h: rn.bias_instability_dph,
                rrw_deg_per_h_per_sqrt_h: rn.rrw_dph_rt_h,
                flicker_max_tau_s,
                ..GyroNoise::default()
            };
            // the terms are finite and ≥ 0 and the step > 0: the generator cannot refuse them
            Generator::new(&spec, step, sub_seed(seed, 1)).map(|mut generator| {
                let rate = generator.next_sample();
                NoiseClock {
                    generator,
                    step,
                    k: 0,
                    theta: 0.0,
                    rate,
                }
            })
        });
        let quantizer = (rn.quantization_arcsec > 0.0 && config.k1 != 0.0).then(|| {
            let step = rn.quantization_arcsec;
            let u: f64 = StdRng::seed_from_u64(sub_seed(seed, 2)).random();
            Quantizer {
                step,
                phase: u * step,
                last_end: None,
            }
        });
        GyroSignal {
            config,
            truth,
            table,
            rng: StdRng::seed_from_u64(seed),
            walk: 0.0,
            last_t: None,
            noise: noise.and_then(Result::ok),
            quantizer,
            chamber: None,
            play: Play::default(),
        }
    }

    /// The gyro sits in `chamber`: its coefficients follow the chamber's inside temperature.
    pub fn in_chamber(mut self, chamber: crate::chamber::ChamberHandle) -> Self {
        self.chamber = Some(chamber);
        self
    }

    /// The gyro's inside temperature at `at`, °C.
    pub fn inside_c(&self, at: Instant) -> f64 {
        match &self.chamber {
            Some(c) => c.inside_c(at),
            None => self.config.room_c,
        }
    }

    /// The true coefficients.
    pub fn truth(&self) -> GyroTruth {
        self.truth
    }

    /// The current bias random-walk offset, V (for tests that want the exact expectation).
    pub fn bias_walk(&self) -> f64 {
        self.walk
    }
}

impl SignalSource for GyroSignal {
    fn volts(&mut self, start: Instant, window: Duration) -> f64 {
        let n = self.config.subsamples.max(1);
        let truth = if self.truth.temperature.is_off() {
            self.truth
        } else {
            let t_c = self.inside_c(start + window / 2);
            let side = self.play.update(t_c);
            self.truth.at_temperature_side(t_c, side)
        };
        let mut sum = 0.0;
        for i in 0..n {
            let at = start + window.mul_f64((f64::from(i) + 0.5) / f64::from(n));
            sum += truth.output(self.table.actual_rate(at));
        }
        let mean = sum / f64::from(n);
        let t_mid = self.table.sim_time(start + window / 2);
        if let Some(last) = self.last_t
            && t_mid > last
        {
            let z: f64 = self.rng.sample(StandardNormal);
            self.walk += self.config.bias_random_walk * (t_mid - last).sqrt() * z;
        }
        if self.last_t.is_none_or(|l| t_mid > l) {
            self.last_t = Some(t_mid);
        }
        let thermal = if self.config.thermal_drift != 0.0 && self.config.thermal_time_constant > 0.0
        {
            self.config.thermal_drift * (1.0 - (-t_mid / self.config.thermal_time_constant).exp())
        } else {
            0.0
        };
        let z: f64 = self.rng.sample(StandardNormal);
        let noise = self.config.noise_std / window.as_secs_f64().max(1e-3).sqrt() * z;
        let out = mean + self.walk + thermal;
        if self.truth.rate_noise.is_off() {
            return out + noise;
        }
        out + self.rate_noise_volts(out, start, window) + noise
    }
}

impl GyroSignal {
    /// The rate-noise terms' contribution to a reading over `[start, start + window]`, V, given
    /// the rest of the output's mean `out` (for the quantizer's angle).
    fn rate_noise_volts(&mut self, out: f64, start: Instant, window: Duration) -> f64 {
        let t0 = self.table.sim_time(start);
        let t1 = self.table.sim_time(start + window).max(t0);
        let span = t1 - t0;
        let mut rate = self.truth.rate_noise.warmup_mean(t0, t1);
        if let Some(n) = &mut self.noise {
            let th0 = n.theta(t0);
            let th1 = n.theta(t1);
            rate += if span > 0.0 {
                (th1 - th0) / span
            } else {
                n.rate
            };
        }
        let k1 = self.config.k1;
        let mut v = k1 * rate / 3600.0;
        if let Some(q) = &mut self.quantizer {
            // the indicated rate over the window, °/h = ″/s
            let indicated = (out + v) / k1 * 3600.0;
            if let Some(end) = q.last_end
                && t0 > end
            {
                q.phase = (q.phase + indicated * (t0 - end)).rem_euclid(q.step);
            }
            let start_phase = q.phase;
            q.phase = (q.phase + indicated * span).rem_euclid(q.step);
            q.last_end = Some(t1);
            if span > 0.0 {
                v += k1 * (start_phase - q.phase) / span / 3600.0;
            }
        }
        v
    }
}

#[cfg(test)]
mod temperature_tests {
    use super::*;

    fn tempco_gyro() -> GyroTruth {
        GyroTruth::from_config(&GyroConfig {
            k_tempco_ppm_per_c: 40.0,
            k_tempco2_ppm_per_c2: 0.5,
            bias_tempco_dph_per_c: 2.0,
            k2_tempco_ppm_per_c: 100.0,
            k2: 1e-5,
            hysteresis_k_ppm: 20.0,
            hysteresis_dph: 0.8,
            ..GyroConfig::default()
        })
    }

    #[test]
    fn coefficients_at_a_temperature() {
        let g = tempco_gyro();
        assert_eq!(g.at_temperature(25.0), g);
        let hot = g.at_temperature(60.0);
        let expect = 1.0 + 1e-6 * (40.0 * 35.0 + 0.5 * 35.0 * 35.0);
        assert!((hot.k1_pos / g.k1_pos - expect).abs() < 1e-12);
        assert!((hot.bias_dph() - g.bias_dph() - 70.0).abs() < 1e-9);
        assert!((hot.k2 / g.k2 - (1.0 + 100e-6 * 35.0)).abs() < 1e-12);
        // reached from below minus from above: the hysteresis, K in ppm and bias in °/h
        let below = g.at_temperature_reached(25.0, true);
        let above = g.at_temperature_reached(25.0, false);
        assert!(((below.k1_pos - above.k1_pos) / g.k1_pos * 1e6 - 20.0).abs() < 1e-6);
        assert!((below.bias_dph() - above.bias_dph() - 0.8).abs() < 1e-9);
        // off: nothing changes, whatever the temperature
        let plain = GyroTruth::from_config(&GyroConfig::default());
        assert_eq!(plain.at_temperature(-40.0), plain);
    }

    #[test]
    fn the_hysteresis_side_turns_after_the_play() {
        let mut p = Play::default();
        assert_eq!(p.update(25.0), 0.0);
        assert_eq!(p.update(25.9), 0.0, "within the play");
        assert_eq!(p.update(60.0), 1.0, "heating");
        assert_eq!(p.update(59.5), 1.0, "a wobble is not a turn");
        assert_eq!(p.update(25.0), -1.0, "cooling: 25 reached from above");
        assert_eq!(p.update(-20.0), -1.0);
        assert_eq!(p.update(25.0), 1.0, "25 reached from below");
    }
}
