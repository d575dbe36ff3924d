//! The simulated bench a plan describes: its flat `[simulation]` section mapped onto the
//! simulator's [`BenchConfig`], with the plan's own link settings (baud, framing, line
//! frequency) so the simulated instruments time their wires like the real ones would.
//!
//! Mapping (plan key → simulator):
//!
//! | `[simulation]` | bench |
//! |---|---|
//! | `seed` | `seed` |
//! | `scale_factor`, `asymmetry` | `gyro.k1 = K·(1 + a/2)` (positive rates), `gyro.k1_neg = K·(1 − a/2)` |
//! | `bias`, `k2`, `k3` | `gyro.k0`, `gyro.k2`, `gyro.k3` |
//! | `noise_v` | `dmm.noise_v`: the standard deviation of one reading |
//! | `bias_walk` | `gyro.bias_random_walk` |
//! | `latitude_deg` | `gyro.latitude_deg` (vertical Earth rate on) |
//! | `rate_noise_dps`, `ripple_dps` | `table.rate_noise_std`, `table.ripple_amplitude` |
//! | `arw_deg_rt_h`, `bias_instability_dph`, `rrw_dph_rt_h`, `quantization_arcsec`, `warmup_dph`, `warmup_tau_s` | the same `gyro` fields (rate noise in °/h through the scale factor; see [`crate::gyro`]) |
//!
//! | `room_c`, `t_ref_c`, `k_tempco_ppm_per_c`, `k_tempco2_ppm_per_c2`, `bias_tempco_dph_per_c`, `bias_tempco2_dph_per_c2`, `k2_tempco_ppm_per_c`, `hysteresis_k_ppm`, `hysteresis_dph` | the same `gyro` fields (its K, bias and K2 follow its inside temperature; see [`crate::gyro`]) |
//! | `chamber_heat_c_per_min`, `chamber_cool_c_per_min`, `case_tau_s`, `inside_tau_s`, `chamber_noise_c`, `room_c` | the chamber's `thermal` physics (`heat_c_per_min`, `cool_c_per_min`, `case_tau_s`, `inside_tau_s`, `sensor_noise_c`, `room_c`) |
//!
//! A plan with a `[chamber]` gets a simulated controller of its `model`, with its `slave` and
//! `chamber_on_output`, on the link the run's real driver is given.
//!
//! The gyro's own white noise is switched off, so `noise_v` alone sets the reading scatter
//! and a plan reads as what it means.

use gyrocal_files::plan::ChamberModel;
use gyrocal_files::{DmmModel, Plan, TableDialect};

use crate::bench::{BenchConfig, DmmLink, TableWire};

/// The bench configuration for `plan`'s `[simulation]` section, at real instrument timing
/// (`time_scale` 1; set it for a real-time bench).
pub fn bench_config(plan: &Plan) -> BenchConfig {
    let s = plan.simulation();
    let mut b = BenchConfig {
        seed: s.seed,
        time_scale: 1.0,
        ..BenchConfig::default()
    };
    let k = s.scale_factor;
    let a = s.asymmetry;
    b.gyro.k0 = s.bias;
    b.gyro.k1 = k * (1.0 + a / 2.0);
    b.gyro.k1_neg = (a != 0.0).then(|| k * (1.0 - a / 2.0));
    b.gyro.k2 = s.k2;
    b.gyro.k3 = s.k3;
    b.gyro.noise_std = 0.0;
    b.gyro.bias_random_walk = s.bias_walk;
    b.gyro.latitude_deg = s.latitude_deg;
    b.gyro.earth_rate = true;
    b.gyro.arw_deg_rt_h = s.arw_deg_rt_h;
    b.gyro.bias_instability_dph = s.bias_instability_dph;
    b.gyro.rrw_dph_rt_h = s.rrw_dph_rt_h;
    b.gyro.quantization_arcsec = s.quantization_arcsec;
    b.gyro.warmup_dph = s.warmup_dph;
    b.gyro.warmup_tau_s = s.warmup_tau_s;
    b.gyro.set_temperature_keys(s);
    b.chamber = plan_chamber(plan);
    // the plan's dialect is the wire the simulated table speaks (the Aerosmith wire with the
    // defaults the driver assumes)
    b.table_wire = match plan.table().dialect {
        TableDialect::Acl => TableWire::Acl,
        TableDialect::Aerosmith => TableWire::Aerosmith(Default::default()),
    };
    // a Truevolt is served on its LAN socket; a 34401A the plan reaches through a Prologix
    // controller sits behind a simulated one
    b.dmm_model = match plan.dmm().model {
        DmmModel::Hp34401a => crate::bench::DmmModel::Hp34401a,
        DmmModel::K34460a => crate::bench::DmmModel::Truevolt(gyrocal_truevolt::Model::M34460A),
        DmmModel::K34461a => crate::bench::DmmModel::Truevolt(gyrocal_truevolt::Model::M34461A),
        DmmModel::K34465a => crate::bench::DmmModel::Truevolt(gyrocal_truevolt::Model::M34465A),
        DmmModel::K34470a => crate::bench::DmmModel::Truevolt(gyrocal_truevolt::Model::M34470A),
    };
    if plan.dmm().scpi_socket() {
        b.dmm_link = DmmLink::Lan;
    } else if plan.dmm().port.is_gpib() {
        b.dmm_link = DmmLink::Prologix(Default::default());
    }
    b.table.rate_noise_std = s.rate_noise_dps;
    b.table.ripple_amplitude = s.ripple_dps;
    b.dmm.noise_v = s.noise_v;
    b.dmm.baud = plan.dmm().baud;
    b.dmm.line_hz = plan.dmm().line_hz;
    b.dmm.framing = plan.dmm().framing;
    b
}

/// The simulated controller for the plan's `[chamber]` (none without one), with the
/// `[simulation]` section's chamber physics.
fn plan_chamber(plan: &Plan) -> Option<crate::chamber::ChamberSimConfig> {
    let c = plan.chamber()?;
    let model = match c.model {
        ChamberModel::WatlowF4 => crate::chamber::ChamberModel::WatlowF4,
        ChamberModel::Espec => crate::chamber::ChamberModel::Espec,
    };
    let mut sim =
        crate::chamber::ChamberSimConfig::from_simulation(model, c.slave, plan.simulation());
    sim.chamber_on_output = c.chamber_on_output;
    Some(sim)
}
