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

use std::time::Duration;

use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use tokio::time::Instant;

use crate::SignalSource;
use crate::table::TableHandle;

/// Earth's rotation rate, deg/h.
pub const EARTH_RATE_DEG_PER_H: f64 = 15.041;

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
        }
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

/// The gyro's output voltage as a [`SignalSource`] for the simulated multimeter.
pub struct GyroSignal {
    config: GyroConfig,
    truth: GyroTruth,
    table: TableHandle,
    rng: StdRng,
    walk: f64,
    last_t: Option<f64>,
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
        GyroSignal {
            config,
            truth,
            table,
            rng: StdRng::seed_from_u64(seed),
            walk: 0.0,
            last_t: None,
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
        mean + self.walk + thermal + noise
    }
}
