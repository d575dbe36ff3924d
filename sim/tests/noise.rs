//! The gyro's IEEE 952 rate-noise terms (angle random walk, bias instability, rate random walk,
//! quantization) and its warm-up transient: recovered from simulated drift records with the
//! Allan deviation, and bit-for-bit absent when off.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::time::Duration;

use gyrocal_sim::SignalSource;
use gyrocal_sim::gyro::{GyroConfig, GyroSignal};
use gyrocal_sim::table::{SimTable, TableConfig, TableHandle};
use tokio::time::Instant;

fn resting_table(seed: u64) -> TableHandle {
    let (_link, dev) = gyrocal_link::memory_pair("t");
    SimTable::spawn(dev, TableConfig::default(), seed)
}

/// Readings of the gyro captured before the rate-noise terms existed (default gyro with a
/// thermal drift, seed 7, table seed 3, irregular windows and gaps): with every new term off
/// the readings are bit for bit the same.
const BEFORE: [u64; 12] = [
    0x3f812f86cc19d8a7,
    0x3f834caa6df5fd36,
    0x3f83b88166cd1d75,
    0x3f827394246cc971,
    0x3f83053bba9d0979,
    0x3f8486c8b646e594,
    0x3f821c714623d1ae,
    0x3f850c568f375323,
    0x3f8524dc4d1bbfc7,
    0x3f845342d38b0674,
    0x3f83cccd11e64d7e,
    0x3f8440ace562c3b3,
];

fn irregular_readings(cfg: GyroConfig) -> Vec<u64> {
    let table = resting_table(3);
    let mut g = GyroSignal::new(cfg, table, 7);
    let t0 = Instant::now();
    (0..12u64)
        .map(|k| {
            let start = t0 + Duration::from_millis(k * 350 / 2 * 2);
            let w = Duration::from_millis(20 + (k % 3) * 80);
            g.volts(start, w).to_bits()
        })
        .collect()
}

#[tokio::test(start_paused = true)]
async fn terms_off_leave_the_readings_exactly_as_before() {
    let cfg = GyroConfig {
        thermal_drift: 0.01,
        ..GyroConfig::default()
    };
    assert_eq!(irregular_readings(cfg.clone()), BEFORE);
    // a warm-up time constant alone, or a negative or non-finite amplitude, is off too
    let off = GyroConfig {
        warmup_tau_s: 10.0,
        arw_deg_rt_h: -1.0,
        rrw_dph_rt_h: f64::NAN,
        ..cfg.clone()
    };
    assert_eq!(irregular_readings(off), BEFORE);
    // and a term that is on changes them
    let on = GyroConfig {
        arw_deg_rt_h: 0.01,
        ..cfg
    };
    assert_ne!(irregular_readings(on), BEFORE);
}
