//! The gyro in the simulated chamber: its scale factor and bias, read through the simulated
//! meter while the table turns, follow its inside temperature by the configured tempcos.

// Test helpers outside #[test] functions may unwrap too: a panic is a failed test.
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use gyrocal_link::{StreamTransport, Transport};
use gyrocal_sim::bench::{Bench, BenchConfig};
use gyrocal_sim::chamber::ChamberSimConfig;
use gyrocal_sim::gyro::GyroConfig;
use tokio::io::DuplexStream;
use tokio::time::Instant;

const T: Option<Duration> = Some(Duration::from_secs(1));

async fn table_to(link: &mut StreamTransport<DuplexStream>, from: f64, rate: f64) {
    for c in [
        ":Interlock:Reset".to_string(),
        ":Interlock:Close 1".into(),
        ":Mode:Rate 1".into(),
        ":Limit:Acceleration R,1,5.000000".into(),
        format!(":Demand:Rate 1,{rate:.6}"),
    ] {
        link.send_line(&c).await.unwrap();
    }
    link.send_line(":System:Error?").await.unwrap();
    assert_eq!(link.read_line(T).await.unwrap(), "0,\"No error\"");
    tokio::time::sleep(Duration::from_secs_f64((rate - from).abs() / 5.0 + 1.0)).await;
}

/// The mean of `n` readings at 10 PLC through raw SCPI.
async fn mean_volts(link: &mut StreamTransport<DuplexStream>, n: u32) -> f64 {
    for c in [
        "SYST:REM",
        "*CLS",
        "CONF:VOLT:DC 10",
        "VOLT:DC:NPLC 10",
        &format!("SAMP:COUN {n}"),
    ] {
        link.send_line(c).await.unwrap();
    }
    link.send_line("READ?").await.unwrap();
    let line = link
        .read_line(Some(Duration::from_secs(600)))
        .await
        .unwrap();
    let xs: Vec<f64> = line
        .split(',')
        .map(|r| r.trim().parse::<f64>().unwrap())
        .collect();
    xs.iter().sum::<f64>() / xs.len() as f64
}

/// K from ±20 °/s and the output at rest, measured now.
async fn measure(
    table: &mut StreamTransport<DuplexStream>,
    dmm: &mut StreamTransport<DuplexStream>,
) -> (f64, f64) {
    table_to(table, 0.0, 20.0).await;
    let up = mean_volts(dmm, 40).await;
    table_to(table, 20.0, -20.0).await;
    let down = mean_volts(dmm, 40).await;
    table_to(table, -20.0, 0.0).await;
    let rest = mean_volts(dmm, 40).await;
    ((up - down) / 40.0, rest)
}

#[tokio::test(start_paused = true)]
async fn the_gyros_scale_factor_and_bias_follow_the_chamber_by_their_tempcos() {
    let config = BenchConfig {
        seed: 5,
        gyro: GyroConfig {
            noise_std: 0.0,
            bias_random_walk: 0.0,
            k_tempco_ppm_per_c: 30.0,
            bias_tempco_dph_per_c: 1.5,
            ..GyroConfig::default()
        },
        chamber: Some(ChamberSimConfig::default()),
        ..BenchConfig::default()
    };
    let mut bench = Bench::spawn(config.clone());
    let truth = bench.handle.truth;
    let chamber = bench.handle.chamber.clone().unwrap();
    // soaked at 25 °C, then at 60 °C (six hours each: every lag long settled)
    chamber.set_setpoint(25.0);
    tokio::time::sleep(Duration::from_secs(6 * 3600)).await;
    assert!((chamber.inside_c(Instant::now()) - 25.0).abs() < 1e-3);
    let (k25, rest25) = measure(&mut bench.table, &mut bench.dmm).await;
    chamber.set_setpoint(60.0);
    tokio::time::sleep(Duration::from_secs(6 * 3600)).await;
    assert!((chamber.inside_c(Instant::now()) - 60.0).abs() < 1e-3);
    let (k60, rest60) = measure(&mut bench.table, &mut bench.dmm).await;

    // the table's rate noise and ripple and the meter's noise limit K to a few ppm
    let ppm = (k60 / k25 - 1.0) * 1e6;
    assert!((ppm - 30.0 * 35.0).abs() < 25.0, "K changed by {ppm} ppm");
    let at60 = truth.at_temperature(60.0);
    assert!((k60 / at60.k1_pos - 1.0).abs() < 25e-6, "{k60} vs {at60:?}");
    assert!(
        (k25 / truth.k1_pos - 1.0).abs() < 25e-6,
        "{k25} vs {truth:?}"
    );
    // the bias in °/h: 1.5 (°/h)/°C over 35 °C; the Earth rate is the same at both
    let bias_shift_dph = (rest60 / k60 - rest25 / k25) * 3600.0;
    assert!(
        (bias_shift_dph - 52.5).abs() < 2.0,
        "bias moved by {bias_shift_dph} °/h"
    );
    assert!((at60.bias_dph() - truth.bias_dph() - 52.5).abs() < 1e-9);
}

#[tokio::test(start_paused = true)]
async fn without_a_chamber_the_gyro_is_at_room_temperature() {
    let config = BenchConfig {
        gyro: GyroConfig {
            noise_std: 0.0,
            bias_random_walk: 0.0,
            k_tempco_ppm_per_c: 500.0,
            room_c: 15.0,
            ..GyroConfig::default()
        },
        ..BenchConfig::default()
    };
    let mut bench = Bench::spawn(config);
    assert!(bench.chamber_link().is_none());
    let truth = bench.handle.truth;
    let (k, _) = measure(&mut bench.table, &mut bench.dmm).await;
    // 10 °C below the reference: 5000 ppm lower
    let ppm = (k / truth.k1_pos - 1.0) * 1e6;
    assert!((ppm + 5000.0).abs() < 25.0, "{ppm}");
}

/// The bias at rest, °/h (with the Earth rate, the same at every temperature), after soaking
/// the chamber at `setpoint_c` for six hours.
async fn soaked_bias_dph(bench: &mut Bench, setpoint_c: f64, k: f64) -> f64 {
    let chamber = bench.handle.chamber.clone().unwrap();
    chamber.set_setpoint(setpoint_c);
    tokio::time::sleep(Duration::from_secs(6 * 3600)).await;
    assert!((chamber.inside_c(Instant::now()) - setpoint_c).abs() < 1e-3);
    mean_volts(&mut bench.dmm, 40).await / k * 3600.0
}

#[tokio::test(start_paused = true)]
async fn a_temperature_revisited_from_the_other_side_shows_the_hysteresis() {
    let config = BenchConfig {
        seed: 8,
        gyro: GyroConfig {
            noise_std: 0.0,
            bias_random_walk: 0.0,
            bias_tempco_dph_per_c: 1.0,
            hysteresis_dph: 5.0,
            ..GyroConfig::default()
        },
        chamber: Some(ChamberSimConfig::default()),
        ..BenchConfig::default()
    };
    let mut bench = Bench::spawn(config);
    let k = bench.handle.truth.k1_pos;
    // the series 25 → 60 → 25 → −20 → 25: the middle 25 is reached from above, the last
    // from below; the meter reads while the chamber holds each temperature
    soaked_bias_dph(&mut bench, 25.0, k).await;
    soaked_bias_dph(&mut bench, 60.0, k).await;
    let from_above = soaked_bias_dph(&mut bench, 25.0, k).await;
    soaked_bias_dph(&mut bench, -20.0, k).await;
    let from_below = soaked_bias_dph(&mut bench, 25.0, k).await;
    assert!(
        (from_below - from_above - 5.0).abs() < 0.3,
        "from below {from_below} °/h, from above {from_above} °/h"
    );
}
