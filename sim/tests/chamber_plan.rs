//! A plan's `[simulation]` temperature keys: read with their defaults, checked (a bad value
//! names its key), and carried onto the simulated gyro and chamber.

// Test helpers outside #[test] functions may unwrap too: a panic is a failed test.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::Path;

use gyrocal_files::Plan;
use gyrocal_sim::chamber::{ChamberModel, ChamberSimConfig};
use gyrocal_sim::gyro::{GyroConfig, GyroTruth};

fn plan(simulation: &str) -> Result<Plan, String> {
    let text = format!(
        "{}[simulation]\n{simulation}\n",
        common::plans::sweep("temps", &[0.0, 10.0, -10.0], 10)
    );
    Plan::from_toml_str(&text, Path::new("temps.toml")).map_err(|e| e.to_string())
}

#[test]
fn the_temperature_keys_reach_the_gyro_and_the_chamber() {
    let p = plan(
        "k_tempco_ppm_per_c = 30.0\nbias_tempco_dph_per_c = 1.5\nhysteresis_dph = 0.4\n\
         room_c = 21.0\ncase_tau_s = 900.0\nchamber_cool_c_per_min = 1.0",
    )
    .unwrap();
    let s = p.simulation();
    let mut gyro = GyroConfig::default();
    gyro.set_temperature_keys(s);
    let truth = GyroTruth::from_config(&gyro);
    let hot = truth.at_temperature(60.0);
    assert!(((hot.k1_pos / truth.k1_pos - 1.0) * 1e6 - 30.0 * 35.0).abs() < 1e-6);
    assert!((hot.bias_dph() - truth.bias_dph() - 52.5).abs() < 1e-9);
    assert_eq!(gyro.room_c, 21.0);
    let chamber = ChamberSimConfig::from_simulation(ChamberModel::Espec, 3, s);
    assert_eq!(chamber.model, ChamberModel::Espec);
    assert_eq!(chamber.thermal.room_c, 21.0);
    assert_eq!(chamber.thermal.case_tau_s, 900.0);
    assert_eq!(chamber.thermal.cool_c_per_min, 1.0);
    assert_eq!(chamber.thermal.heat_c_per_min, 3.0, "the default");
    assert_eq!(chamber.thermal.inside_tau_s, 600.0, "the default");
}

#[test]
fn defaults_leave_the_gyro_independent_of_temperature_and_the_hash_unchanged() {
    let with = plan("seed = 3").unwrap();
    let mut gyro = GyroConfig::default();
    gyro.set_temperature_keys(with.simulation());
    let truth = GyroTruth::from_config(&gyro);
    assert_eq!(truth.at_temperature(-40.0), truth);
    // the keys at their defaults are not serialised: a plan that writes them out is the
    // same plan (same hash) as one that does not
    let explicit =
        plan("seed = 3\nroom_c = 23.0\nt_ref_c = 25.0\nk_tempco_ppm_per_c = 0.0").unwrap();
    assert_eq!(
        serde_json::to_string(with.simulation()).unwrap(),
        serde_json::to_string(explicit.simulation()).unwrap()
    );
    assert!(
        !serde_json::to_string(with.simulation())
            .unwrap()
            .contains("tempco")
    );
}

#[test]
fn a_bad_temperature_key_is_refused_by_name() {
    for (line, key) in [
        ("k_tempco_ppm_per_c = 1e9", "k_tempco_ppm_per_c"),
        ("case_tau_s = 0.0", "case_tau_s"),
        ("chamber_heat_c_per_min = -1.0", "chamber_heat_c_per_min"),
        ("chamber_noise_c = 10.0", "chamber_noise_c"),
        ("room_c = 500.0", "room_c"),
    ] {
        let err = plan(line).unwrap_err();
        // the file, its line, the section and the key
        assert!(err.contains("temps.toml:"), "{line}: {err}");
        assert!(
            err.contains(&format!("[simulation] {key}")),
            "{line}: {err}"
        );
    }
}
