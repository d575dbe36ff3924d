//! `[simulation]`: the truth of the simulated bench (`gyrocal run --simulate`): the gyro's
//! model and noise, the table's and the meter's imperfections, with each key's default and
//! check. Part of the hash: a different truth is a different run.

use serde::{Deserialize, Serialize};

use super::error::PlanError;
use super::raw::{RawInt, S, Spans};
use super::schema::{IntRule, KeySchema, Kind, int_error};
use super::validate::Ctx;

/// The keys of `[simulation]`.
pub(super) const KEYS: &[KeySchema] = &[
    ("seed", Kind::Int(IntRule::NON_NEGATIVE), false),
    ("scale_factor", Kind::Number, false),
    ("bias", Kind::Number, false),
    ("k2", Kind::Number, false),
    ("k3", Kind::Number, false),
    ("asymmetry", Kind::Number, false),
    ("noise_v", Kind::Number, false),
    ("bias_walk", Kind::Number, false),
    ("latitude_deg", Kind::Number, false),
    ("rate_noise_dps", Kind::Number, false),
    ("ripple_dps", Kind::Number, false),
    ("arw_deg_rt_h", Kind::Number, false),
    ("bias_instability_dph", Kind::Number, false),
    ("rrw_dph_rt_h", Kind::Number, false),
    ("quantization_arcsec", Kind::Number, false),
    ("warmup_dph", Kind::Number, false),
    ("warmup_tau_s", Kind::Number, false),
    ("room_c", Kind::Number, false),
    ("t_ref_c", Kind::Number, false),
    ("k_tempco_ppm_per_c", Kind::Number, false),
    ("k_tempco2_ppm_per_c2", Kind::Number, false),
    ("bias_tempco_dph_per_c", Kind::Number, false),
    ("bias_tempco2_dph_per_c2", Kind::Number, false),
    ("k2_tempco_ppm_per_c", Kind::Number, false),
    ("hysteresis_k_ppm", Kind::Number, false),
    ("hysteresis_dph", Kind::Number, false),
    ("chamber_heat_c_per_min", Kind::Number, false),
    ("chamber_cool_c_per_min", Kind::Number, false),
    ("case_tau_s", Kind::Number, false),
    ("inside_tau_s", Kind::Number, false),
    ("chamber_noise_c", Kind::Number, false),
];

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawSimulation {
    pub(super) seed: Option<S<RawInt>>,
    pub(super) scale_factor: Option<S<f64>>,
    pub(super) bias: Option<S<f64>>,
    pub(super) k2: Option<S<f64>>,
    pub(super) k3: Option<S<f64>>,
    pub(super) asymmetry: Option<S<f64>>,
    pub(super) noise_v: Option<S<f64>>,
    pub(super) bias_walk: Option<S<f64>>,
    pub(super) latitude_deg: Option<S<f64>>,
    pub(super) rate_noise_dps: Option<S<f64>>,
    pub(super) ripple_dps: Option<S<f64>>,
    pub(super) arw_deg_rt_h: Option<S<f64>>,
    pub(super) bias_instability_dph: Option<S<f64>>,
    pub(super) rrw_dph_rt_h: Option<S<f64>>,
    pub(super) quantization_arcsec: Option<S<f64>>,
    pub(super) warmup_dph: Option<S<f64>>,
    pub(super) warmup_tau_s: Option<S<f64>>,
    pub(super) room_c: Option<S<f64>>,
    pub(super) t_ref_c: Option<S<f64>>,
    pub(super) k_tempco_ppm_per_c: Option<S<f64>>,
    pub(super) k_tempco2_ppm_per_c2: Option<S<f64>>,
    pub(super) bias_tempco_dph_per_c: Option<S<f64>>,
    pub(super) bias_tempco2_dph_per_c2: Option<S<f64>>,
    pub(super) k2_tempco_ppm_per_c: Option<S<f64>>,
    pub(super) hysteresis_k_ppm: Option<S<f64>>,
    pub(super) hysteresis_dph: Option<S<f64>>,
    pub(super) chamber_heat_c_per_min: Option<S<f64>>,
    pub(super) chamber_cool_c_per_min: Option<S<f64>>,
    pub(super) case_tau_s: Option<S<f64>>,
    pub(super) inside_tau_s: Option<S<f64>>,
    pub(super) chamber_noise_c: Option<S<f64>>,
}

/// `[simulation]`: the truth of the in-process simulated bench used by `--simulate`.
/// Every key is optional; the defaults resemble the paper's HRG.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Simulation {
    /// Seed of every random stream (default 1).
    pub seed: u64,
    /// Scale factor `Kn`, V/(°/s) (default 0.3612, the paper's result; non-zero).
    pub scale_factor: f64,
    /// Bias `K0`, V (default 0.0088, the paper's result).
    pub bias: f64,
    /// Second-order term, V/(°/s)² (default 2e-5: about 8 mV at 20 °/s, the even-order
    /// residual shape of the paper).
    pub k2: f64,
    /// Third-order term, V/(°/s)³ (default 0).
    pub k3: f64,
    /// Relative difference of the two directions' scale factors, `(K+ - K-)/Kbar` (default 0,
    /// |asymmetry| < 0.1).
    pub asymmetry: f64,
    /// Standard deviation of one reading's noise, V (default 0.002, ≥ 0).
    pub noise_v: f64,
    /// Bias random walk, V/√s (default 0, ≥ 0).
    pub bias_walk: f64,
    /// Latitude of the bench, degrees; the vertical Earth rate 15.041 °/h · sin(latitude) adds
    /// to every input (default 0, within ±90).
    pub latitude_deg: f64,
    /// Table rate noise std, °/s (default 0.0002, ≥ 0).
    pub rate_noise_dps: f64,
    /// Table once-per-revolution rate ripple amplitude, °/s (default 0.0005, ≥ 0).
    pub ripple_dps: f64,
    /// The gyro's angle random walk N (white rate noise), °/√h: an Allan deviation of the
    /// rate reads 60·N °/h at τ = 1 s (default 0 = off, 0 to 100). The rate-noise keys are
    /// left out of the serialised form (and so of the hash) when at their default, so an
    /// older plan's hash is what it was before they existed.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub arw_deg_rt_h: f64,
    /// The gyro's bias instability B (flicker rate noise), °/h: the Allan deviation's floor is
    /// 0.664·B (default 0 = off, 0 to 1000).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub bias_instability_dph: f64,
    /// The gyro's rate random walk K, °/h/√h: the Allan deviation reads K/60 °/h at τ = 3 s
    /// (default 0 = off, 0 to 1000).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub rrw_dph_rt_h: f64,
    /// The step of the gyro's quantized output angle, arcsec (IEEE 952's Q = step/√12;
    /// default 0 = off, 0 to 3600).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub quantization_arcsec: f64,
    /// Warm-up transient: the gyro's bias starts off by this much and decays with
    /// `warmup_tau_s`, °/h (default 0 = off, 0 to 36000).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub warmup_dph: f64,
    /// Time constant of the warm-up transient, s (default 600, > 0 and at most 86400).
    #[serde(
        default = "default_warmup_tau_s",
        skip_serializing_if = "is_default_warmup_tau_s"
    )]
    pub warmup_tau_s: f64,
    // The temperature keys (issue 26): like the rate-noise keys, left out of the serialised
    // form (and so of the hash) at their defaults, so an older plan's hash is unchanged.
    /// The room's temperature, °C: the gyro's without a chamber, and where a simulated chamber starts (default 23, within ±60).
    #[serde(default = "default_room_c", skip_serializing_if = "is_default_room_c")]
    pub room_c: f64,
    /// The temperature `scale_factor`, `bias` and `k2` are at, °C (default 25, within ±100).
    #[serde(
        default = "default_t_ref_c",
        skip_serializing_if = "is_default_t_ref_c"
    )]
    pub t_ref_c: f64,
    /// The scale factor's tempco, ppm/°C of the gyro's inside temperature (default 0 = none, within ±10000).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub k_tempco_ppm_per_c: f64,
    /// The scale factor's second-order tempco, ppm/°C² (default 0, within ±1000).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub k_tempco2_ppm_per_c2: f64,
    /// The bias's tempco, (°/h)/°C, of the rate-referred bias K0/K·3600 (default 0, within ±1000).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub bias_tempco_dph_per_c: f64,
    /// The bias's second-order tempco, (°/h)/°C² (default 0, within ±100).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub bias_tempco2_dph_per_c2: f64,
    /// K2's relative tempco, ppm/°C (default 0, within ±100000).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub k2_tempco_ppm_per_c: f64,
    /// Scale-factor hysteresis: K at a temperature reached from below minus from above, ppm (default 0, within ±10000).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub hysteresis_k_ppm: f64,
    /// Bias hysteresis: the bias at a temperature reached from below minus from above, °/h (default 0, within ±1000).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub hysteresis_dph: f64,
    /// A simulated chamber's fastest heating, °C/min (default 3, > 0 and at most 100).
    #[serde(
        default = "default_chamber_heat_c_per_min",
        skip_serializing_if = "is_default_chamber_heat_c_per_min"
    )]
    pub chamber_heat_c_per_min: f64,
    /// A simulated chamber's fastest cooling, °C/min (default 2, > 0 and at most 100).
    #[serde(
        default = "default_chamber_cool_c_per_min",
        skip_serializing_if = "is_default_chamber_cool_c_per_min"
    )]
    pub chamber_cool_c_per_min: f64,
    /// Time constant of the gyro's case following the chamber's air, s (default 1200, > 0 and at most 86400).
    #[serde(
        default = "default_case_tau_s",
        skip_serializing_if = "is_default_case_tau_s"
    )]
    pub case_tau_s: f64,
    /// Time constant of the gyro's inside following its case, s (default 600, > 0 and at most 86400).
    #[serde(
        default = "default_inside_tau_s",
        skip_serializing_if = "is_default_inside_tau_s"
    )]
    pub inside_tau_s: f64,
    /// Noise of the chamber's temperature sensors, °C standard deviation (default 0.05, 0 to 5).
    #[serde(
        default = "default_chamber_noise_c",
        skip_serializing_if = "is_default_chamber_noise_c"
    )]
    pub chamber_noise_c: f64,
}

/// `[simulation] warmup_tau_s` when the plan does not say, s.
const DEFAULT_WARMUP_TAU_S: f64 = 600.0;

fn default_warmup_tau_s() -> f64 {
    DEFAULT_WARMUP_TAU_S
}

#[allow(clippy::trivially_copy_pass_by_ref)] // serde's skip_serializing_if passes a &f64
fn is_default_warmup_tau_s(v: &f64) -> bool {
    *v == DEFAULT_WARMUP_TAU_S
}

/// `[simulation] room_c` when the plan does not say, °C.
const DEFAULT_ROOM_C: f64 = 23.0;
/// `[simulation] t_ref_c` when the plan does not say, °C.
const DEFAULT_T_REF_C: f64 = 25.0;
/// `[simulation] chamber_heat_c_per_min` when the plan does not say.
const DEFAULT_HEAT_C_PER_MIN: f64 = 3.0;
/// `[simulation] chamber_cool_c_per_min` when the plan does not say.
const DEFAULT_COOL_C_PER_MIN: f64 = 2.0;
/// `[simulation] case_tau_s` when the plan does not say.
const DEFAULT_CASE_TAU_S: f64 = 1200.0;
/// `[simulation] inside_tau_s` when the plan does not say.
const DEFAULT_INSIDE_TAU_S: f64 = 600.0;
/// `[simulation] chamber_noise_c` when the plan does not say.
const DEFAULT_CHAMBER_NOISE_C: f64 = 0.05;

fn default_room_c() -> f64 {
    DEFAULT_ROOM_C
}

#[allow(clippy::trivially_copy_pass_by_ref)] // serde's skip_serializing_if passes a &f64
fn is_default_room_c(v: &f64) -> bool {
    *v == DEFAULT_ROOM_C
}

fn default_t_ref_c() -> f64 {
    DEFAULT_T_REF_C
}

#[allow(clippy::trivially_copy_pass_by_ref)] // serde's skip_serializing_if passes a &f64
fn is_default_t_ref_c(v: &f64) -> bool {
    *v == DEFAULT_T_REF_C
}

fn default_chamber_heat_c_per_min() -> f64 {
    DEFAULT_HEAT_C_PER_MIN
}

#[allow(clippy::trivially_copy_pass_by_ref)] // serde's skip_serializing_if passes a &f64
fn is_default_chamber_heat_c_per_min(v: &f64) -> bool {
    *v == DEFAULT_HEAT_C_PER_MIN
}

fn default_chamber_cool_c_per_min() -> f64 {
    DEFAULT_COOL_C_PER_MIN
}

#[allow(clippy::trivially_copy_pass_by_ref)] // serde's skip_serializing_if passes a &f64
fn is_default_chamber_cool_c_per_min(v: &f64) -> bool {
    *v == DEFAULT_COOL_C_PER_MIN
}

fn default_case_tau_s() -> f64 {
    DEFAULT_CASE_TAU_S
}

#[allow(clippy::trivially_copy_pass_by_ref)] // serde's skip_serializing_if passes a &f64
fn is_default_case_tau_s(v: &f64) -> bool {
    *v == DEFAULT_CASE_TAU_S
}

fn default_inside_tau_s() -> f64 {
    DEFAULT_INSIDE_TAU_S
}

#[allow(clippy::trivially_copy_pass_by_ref)] // serde's skip_serializing_if passes a &f64
fn is_default_inside_tau_s(v: &f64) -> bool {
    *v == DEFAULT_INSIDE_TAU_S
}

fn default_chamber_noise_c() -> f64 {
    DEFAULT_CHAMBER_NOISE_C
}

#[allow(clippy::trivially_copy_pass_by_ref)] // serde's skip_serializing_if passes a &f64
fn is_default_chamber_noise_c(v: &f64) -> bool {
    *v == DEFAULT_CHAMBER_NOISE_C
}

#[allow(clippy::trivially_copy_pass_by_ref)] // serde's skip_serializing_if passes a &f64
fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

impl Default for Simulation {
    fn default() -> Self {
        Simulation {
            seed: 1,
            scale_factor: 0.3612,
            bias: 0.0088,
            k2: 2e-5,
            k3: 0.0,
            asymmetry: 0.0,
            noise_v: 0.002,
            bias_walk: 0.0,
            latitude_deg: 0.0,
            rate_noise_dps: 0.0002,
            ripple_dps: 0.0005,
            arw_deg_rt_h: 0.0,
            bias_instability_dph: 0.0,
            rrw_dph_rt_h: 0.0,
            quantization_arcsec: 0.0,
            warmup_dph: 0.0,
            warmup_tau_s: DEFAULT_WARMUP_TAU_S,
            room_c: DEFAULT_ROOM_C,
            t_ref_c: DEFAULT_T_REF_C,
            k_tempco_ppm_per_c: 0.0,
            k_tempco2_ppm_per_c2: 0.0,
            bias_tempco_dph_per_c: 0.0,
            bias_tempco2_dph_per_c2: 0.0,
            k2_tempco_ppm_per_c: 0.0,
            hysteresis_k_ppm: 0.0,
            hysteresis_dph: 0.0,
            chamber_heat_c_per_min: DEFAULT_HEAT_C_PER_MIN,
            chamber_cool_c_per_min: DEFAULT_COOL_C_PER_MIN,
            case_tau_s: DEFAULT_CASE_TAU_S,
            inside_tau_s: DEFAULT_INSIDE_TAU_S,
            chamber_noise_c: DEFAULT_CHAMBER_NOISE_C,
        }
    }
}

impl Simulation {
    /// `[simulation]` as written, defaults filled in, spans kept; a negative seed is an error.
    pub(super) fn from_raw(
        s: RawSimulation,
        sp: &mut Spans,
    ) -> Result<Simulation, (&'static str, String)> {
        let d = Simulation::default();
        Ok(Simulation {
            seed: {
                let seed = sp.int("simulation.seed", s.seed, 1)?;
                u64::try_from(seed).map_err(|_| {
                    (
                        "simulation.seed",
                        int_error("simulation.seed", &seed.to_string(), true),
                    )
                })?
            },
            scale_factor: sp.opt("simulation.scale_factor", s.scale_factor, d.scale_factor),
            bias: sp.opt("simulation.bias", s.bias, d.bias),
            k2: sp.opt("simulation.k2", s.k2, d.k2),
            k3: sp.opt("simulation.k3", s.k3, d.k3),
            asymmetry: sp.opt("simulation.asymmetry", s.asymmetry, d.asymmetry),
            noise_v: sp.opt("simulation.noise_v", s.noise_v, d.noise_v),
            bias_walk: sp.opt("simulation.bias_walk", s.bias_walk, d.bias_walk),
            latitude_deg: sp.opt("simulation.latitude_deg", s.latitude_deg, d.latitude_deg),
            rate_noise_dps: sp.opt(
                "simulation.rate_noise_dps",
                s.rate_noise_dps,
                d.rate_noise_dps,
            ),
            ripple_dps: sp.opt("simulation.ripple_dps", s.ripple_dps, d.ripple_dps),
            arw_deg_rt_h: sp.opt("simulation.arw_deg_rt_h", s.arw_deg_rt_h, d.arw_deg_rt_h),
            bias_instability_dph: sp.opt(
                "simulation.bias_instability_dph",
                s.bias_instability_dph,
                d.bias_instability_dph,
            ),
            rrw_dph_rt_h: sp.opt("simulation.rrw_dph_rt_h", s.rrw_dph_rt_h, d.rrw_dph_rt_h),
            quantization_arcsec: sp.opt(
                "simulation.quantization_arcsec",
                s.quantization_arcsec,
                d.quantization_arcsec,
            ),
            warmup_dph: sp.opt("simulation.warmup_dph", s.warmup_dph, d.warmup_dph),
            warmup_tau_s: sp.opt("simulation.warmup_tau_s", s.warmup_tau_s, d.warmup_tau_s),
            room_c: sp.opt("simulation.room_c", s.room_c, d.room_c),
            t_ref_c: sp.opt("simulation.t_ref_c", s.t_ref_c, d.t_ref_c),
            k_tempco_ppm_per_c: sp.opt(
                "simulation.k_tempco_ppm_per_c",
                s.k_tempco_ppm_per_c,
                d.k_tempco_ppm_per_c,
            ),
            k_tempco2_ppm_per_c2: sp.opt(
                "simulation.k_tempco2_ppm_per_c2",
                s.k_tempco2_ppm_per_c2,
                d.k_tempco2_ppm_per_c2,
            ),
            bias_tempco_dph_per_c: sp.opt(
                "simulation.bias_tempco_dph_per_c",
                s.bias_tempco_dph_per_c,
                d.bias_tempco_dph_per_c,
            ),
            bias_tempco2_dph_per_c2: sp.opt(
                "simulation.bias_tempco2_dph_per_c2",
                s.bias_tempco2_dph_per_c2,
                d.bias_tempco2_dph_per_c2,
            ),
            k2_tempco_ppm_per_c: sp.opt(
                "simulation.k2_tempco_ppm_per_c",
                s.k2_tempco_ppm_per_c,
                d.k2_tempco_ppm_per_c,
            ),
            hysteresis_k_ppm: sp.opt(
                "simulation.hysteresis_k_ppm",
                s.hysteresis_k_ppm,
                d.hysteresis_k_ppm,
            ),
            hysteresis_dph: sp.opt(
                "simulation.hysteresis_dph",
                s.hysteresis_dph,
                d.hysteresis_dph,
            ),
            chamber_heat_c_per_min: sp.opt(
                "simulation.chamber_heat_c_per_min",
                s.chamber_heat_c_per_min,
                d.chamber_heat_c_per_min,
            ),
            chamber_cool_c_per_min: sp.opt(
                "simulation.chamber_cool_c_per_min",
                s.chamber_cool_c_per_min,
                d.chamber_cool_c_per_min,
            ),
            case_tau_s: sp.opt("simulation.case_tau_s", s.case_tau_s, d.case_tau_s),
            inside_tau_s: sp.opt("simulation.inside_tau_s", s.inside_tau_s, d.inside_tau_s),
            chamber_noise_c: sp.opt(
                "simulation.chamber_noise_c",
                s.chamber_noise_c,
                d.chamber_noise_c,
            ),
        })
    }
}

/// Checks `[simulation]`.
pub(super) fn validate(s: &Simulation, cx: &Ctx<'_>) -> Result<(), PlanError> {
    let scale_factor = cx.finite("simulation.scale_factor", s.scale_factor)?;
    if scale_factor == 0.0 {
        return Err(cx.err("simulation.scale_factor", "must be non-zero (got 0)".into()));
    }
    cx.finite("simulation.bias", s.bias)?;
    cx.finite("simulation.k2", s.k2)?;
    cx.finite("simulation.k3", s.k3)?;
    let asym = cx.finite("simulation.asymmetry", s.asymmetry)?;
    if asym.abs() >= 0.1 {
        return Err(cx.err(
            "simulation.asymmetry",
            format!("must be within ±0.1 (got {asym})"),
        ));
    }
    for (key, v) in [
        ("simulation.noise_v", s.noise_v),
        ("simulation.bias_walk", s.bias_walk),
        ("simulation.rate_noise_dps", s.rate_noise_dps),
        ("simulation.ripple_dps", s.ripple_dps),
    ] {
        let v = cx.finite(key, v)?;
        if v < 0.0 {
            return Err(cx.err(key, format!("must be >= 0 (got {v})")));
        }
    }
    let lat = cx.finite("simulation.latitude_deg", s.latitude_deg)?;
    if lat.abs() > 90.0 {
        return Err(cx.err(
            "simulation.latitude_deg",
            format!("must be within ±90 (got {lat})"),
        ));
    }
    // the gyro's rate-noise terms: finite, ≥ 0 (0 = off), below a bound no gyro comes near
    for (key, v, max, unit) in [
        ("simulation.arw_deg_rt_h", s.arw_deg_rt_h, 100.0, "°/√h"),
        (
            "simulation.bias_instability_dph",
            s.bias_instability_dph,
            1000.0,
            "°/h",
        ),
        ("simulation.rrw_dph_rt_h", s.rrw_dph_rt_h, 1000.0, "°/h/√h"),
        (
            "simulation.quantization_arcsec",
            s.quantization_arcsec,
            3600.0,
            "arcsec",
        ),
        ("simulation.warmup_dph", s.warmup_dph, 36000.0, "°/h"),
    ] {
        let v = cx.finite(key, v)?;
        if !(0.0..=max).contains(&v) {
            return Err(cx.err(key, format!("must be from 0 to {max} {unit} (got {v})")));
        }
    }
    // the temperature keys: finite, within a bound no gyro or chamber comes near
    for (key, v, bound) in [
        ("simulation.room_c", s.room_c, 60.0),
        ("simulation.t_ref_c", s.t_ref_c, 100.0),
        (
            "simulation.k_tempco_ppm_per_c",
            s.k_tempco_ppm_per_c,
            10000.0,
        ),
        (
            "simulation.k_tempco2_ppm_per_c2",
            s.k_tempco2_ppm_per_c2,
            1000.0,
        ),
        (
            "simulation.bias_tempco_dph_per_c",
            s.bias_tempco_dph_per_c,
            1000.0,
        ),
        (
            "simulation.bias_tempco2_dph_per_c2",
            s.bias_tempco2_dph_per_c2,
            100.0,
        ),
        (
            "simulation.k2_tempco_ppm_per_c",
            s.k2_tempco_ppm_per_c,
            100000.0,
        ),
        ("simulation.hysteresis_k_ppm", s.hysteresis_k_ppm, 10000.0),
        ("simulation.hysteresis_dph", s.hysteresis_dph, 1000.0),
    ] {
        let v = cx.finite(key, v)?;
        if v.abs() > bound {
            return Err(cx.err(key, format!("must be within ±{bound} (got {v})")));
        }
    }
    for (key, v, max, unit) in [
        (
            "simulation.chamber_heat_c_per_min",
            s.chamber_heat_c_per_min,
            100.0,
            "°C/min",
        ),
        (
            "simulation.chamber_cool_c_per_min",
            s.chamber_cool_c_per_min,
            100.0,
            "°C/min",
        ),
        ("simulation.case_tau_s", s.case_tau_s, 86400.0, "s"),
        ("simulation.inside_tau_s", s.inside_tau_s, 86400.0, "s"),
    ] {
        let v = cx.finite(key, v)?;
        if !(v > 0.0 && v <= max) {
            return Err(cx.err(
                key,
                format!("must be > 0 and at most {max} {unit} (got {v})"),
            ));
        }
    }
    let noise = cx.finite("simulation.chamber_noise_c", s.chamber_noise_c)?;
    if !(0.0..=5.0).contains(&noise) {
        return Err(cx.err(
            "simulation.chamber_noise_c",
            format!("must be from 0 to 5 °C (got {noise})"),
        ));
    }
    let tau = cx.finite("simulation.warmup_tau_s", s.warmup_tau_s)?;
    if !(tau > 0.0 && tau <= 86400.0) {
        return Err(cx.err(
            "simulation.warmup_tau_s",
            format!("must be > 0 and at most 86400 s (got {tau})"),
        ));
    }
    Ok(())
}
