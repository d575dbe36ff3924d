//! Simulated gyro rate noise with known IEEE 952 terms, for the simulator and for tests.
//!
//! The output is a rate in °/h sampled every τ0 seconds (each sample the mean rate over its
//! interval, like an integrating gyro read out at a fixed rate). The terms take the units of
//! [`crate::noise_terms`]:
//!
//! * **Quantization Q** (arcsec = (°/h)·s): angle readout error e uniform with standard deviation
//!   Q, independent per sample; rate y = (e_{k+1} − e_k)/τ0. Allan variance 3Q²/τ².
//! * **Angle random walk N** (°/√h): white rate with standard deviation 60·N/√τ0 (°/h). Allan
//!   variance (60 N)²/τ.
//! * **Bias instability B** (°/h): flicker rate noise approximated by a sum of first-order
//!   Gauss–Markov processes with correlation times three per decade from τ0/3 to 30·τ_max
//!   (τ_max = [`GyroNoise::flicker_max_tau_s`]); each process has variance
//!   B²·ln(10)/3/π, so that the sum of Lorentzians approximates IEEE 952's two-sided PSD
//!   B²/(2π f) (one-sided B²/(π f)), whose Allan variance is (2 ln 2/π)·B² on the flat (within a few per cent, ripple included,
//!   for τ0·10 ≲ τ ≲ τ_max/10).
//! * **Rate random walk K** (°/h/√h): rate performing a random walk with steps of standard
//!   deviation (K/60)·√τ0 (°/h) per sample. Allan variance (K/60)²τ/3.
//! * **Rate ramp R** (°/h²): a linear rate drift R/3600 (°/h per s). Allan variance (R/3600)²τ²/2.
//! * **bias** (°/h): a constant.

use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal, Uniform};

use crate::error::{Error, Result};

/// The noise terms of a simulated gyro (all zero by default).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GyroNoise {
    /// Constant bias, °/h.
    pub bias_deg_per_h: f64,
    /// Quantization Q, arcsec ((°/h)·s).
    pub quantization_arcsec: f64,
    /// Angle random walk N, °/√h.
    pub arw_deg_per_sqrt_h: f64,
    /// Bias instability B, °/h.
    pub bias_instability_deg_per_h: f64,
    /// Rate random walk K, °/h/√h.
    pub rrw_deg_per_h_per_sqrt_h: f64,
    /// Rate ramp R, °/h².
    pub rate_ramp_deg_per_h2: f64,
    /// Longest τ (s) over which the flicker model stays flat (default 10⁴ s).
    pub flicker_max_tau_s: f64,
}

impl Default for GyroNoise {
    fn default() -> Self {
        GyroNoise {
            bias_deg_per_h: 0.0,
            quantization_arcsec: 0.0,
            arw_deg_per_sqrt_h: 0.0,
            bias_instability_deg_per_h: 0.0,
            rrw_deg_per_h_per_sqrt_h: 0.0,
            rate_ramp_deg_per_h2: 0.0,
            flicker_max_tau_s: 1.0e4,
        }
    }
}

/// A seeded generator of gyro rate samples (°/h).
#[derive(Debug)]
pub struct Generator {
    rng: StdRng,
    tau0: f64,
    bias: f64,
    white_sd: f64,
    quant: Option<Uniform<f64>>,
    prev_e: f64,
    rw_step: f64,
    rw: f64,
    ramp_per_sample: f64,
    k: u64,
    gm: Vec<(f64, f64, f64)>, // (a, w_sd, state)
}

impl Generator {
    /// A generator for `noise` at sample interval `tau0_s`, seeded with `seed`.
    pub fn new(noise: &GyroNoise, tau0_s: f64, seed: u64) -> Result<Generator> {
        if !(tau0_s.is_finite() && tau0_s > 0.0) {
            return Err(Error::InvalidParameter {
                name: "tau0_s",
                value: tau0_s,
                why: "must be finite and > 0",
            });
        }
        let fields = [
            ("bias_deg_per_h", noise.bias_deg_per_h),
            ("quantization_arcsec", noise.quantization_arcsec),
            ("arw_deg_per_sqrt_h", noise.arw_deg_per_sqrt_h),
            (
                "bias_instability_deg_per_h",
                noise.bias_instability_deg_per_h,
            ),
            ("rrw_deg_per_h_per_sqrt_h", noise.rrw_deg_per_h_per_sqrt_h),
            ("rate_ramp_deg_per_h2", noise.rate_ramp_deg_per_h2),
            ("flicker_max_tau_s", noise.flicker_max_tau_s),
        ];
        for (name, value) in fields {
            if !value.is_finite()
                || (name != "bias_deg_per_h" && name != "rate_ramp_deg_per_h2" && value < 0.0)
            {
                return Err(Error::InvalidParameter {
                    name,
                    value,
                    why: "must be finite (and ≥ 0 for a noise amplitude)",
                });
            }
        }
        let q = noise.quantization_arcsec;
        let quant = if q > 0.0 {
            let half = q * 3f64.sqrt(); // uniform with standard deviation q
            Uniform::new(-half, half).ok()
        } else {
            None
        };
        let mut rng = StdRng::seed_from_u64(seed);
        let prev_e = quant.as_ref().map_or(0.0, |u| u.sample(&mut rng));
        let mut gm = Vec::new();
        let b = noise.bias_instability_deg_per_h;
        if b > 0.0 && noise.flicker_max_tau_s > tau0_s {
            let per_decade = 3.0;
            let var = b * b * std::f64::consts::LN_10 / per_decade / std::f64::consts::PI;
            // correlation times 1/(2π f_k) from τ0/3 to 30·τ_max: the Allan deviation of a sum of
            // Lorentzians is flat only a decade inside the range of its corners
            let t_lo = tau0_s / 3.0;
            let decades = (30.0 * noise.flicker_max_tau_s / t_lo).log10();
            let count = (decades * per_decade).ceil() as i32 + 1;
            for i in 0..count {
                let tc = t_lo * 10f64.powf(f64::from(i) / per_decade);
                let a = (-tau0_s / tc).exp();
                let sd = (var * (1.0 - a * a)).sqrt();
                let z: f64 = StandardNormal.sample(&mut rng);
                gm.push((a, sd, z * var.sqrt()));
            }
        }
        Ok(Generator {
            rng,
            tau0: tau0_s,
            bias: noise.bias_deg_per_h,
            white_sd: 60.0 * noise.arw_deg_per_sqrt_h / tau0_s.sqrt(),
            quant,
            prev_e,
            rw_step: noise.rrw_deg_per_h_per_sqrt_h / 60.0 * tau0_s.sqrt(),
            rw: 0.0,
            ramp_per_sample: noise.rate_ramp_deg_per_h2 / 3600.0 * tau0_s,
            k: 0,
            gm,
        })
    }

    /// The next rate sample, °/h.
    pub fn next_sample(&mut self) -> f64 {
        let mut y = self.bias + self.ramp_per_sample * self.k as f64;
        if self.white_sd > 0.0 {
            let z: f64 = StandardNormal.sample(&mut self.rng);
            y += self.white_sd * z;
        }
        if let Some(u) = &self.quant {
            let e = u.sample(&mut self.rng);
            y += (e - self.prev_e) / self.tau0;
            self.prev_e = e;
        }
        if self.rw_step > 0.0 {
            y += self.rw;
            let z: f64 = StandardNormal.sample(&mut self.rng);
            self.rw += self.rw_step * z;
        }
        for g in &mut self.gm {
            y += g.2;
            let z: f64 = StandardNormal.sample(&mut self.rng);
            g.2 = g.0 * g.2 + g.1 * z;
        }
        self.k += 1;
        y
    }

    /// Fills `out` with the next samples.
    pub fn fill(&mut self, out: &mut [f64]) {
        for v in out {
            *v = self.next_sample();
        }
    }
}

/// `n` samples of `noise` at `tau0_s`, seeded.
pub fn generate(noise: &GyroNoise, tau0_s: f64, n: usize, seed: u64) -> Result<Vec<f64>> {
    let mut g = Generator::new(noise, tau0_s, seed)?;
    let mut v = vec![0.0; n];
    g.fill(&mut v);
    Ok(v)
}
