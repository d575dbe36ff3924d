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
        }
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
        }
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
        let mut sum = 0.0;
        for i in 0..n {
            let at = start + window.mul_f64((f64::from(i) + 0.5) / f64::from(n));
            sum += self.truth.output(self.table.actual_rate(at));
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
