//! The simulated bench: a rate held on the table while the simulated multimeter reads the
//! simulated gyro gives the true model's voltage within the expected noise.

// Test helpers outside #[test] functions may unwrap too: a panic is a failed test.
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use gyrocal_link::{StreamTransport, Transport};
use gyrocal_sim::SignalSource;
use gyrocal_sim::bench::{Bench, BenchConfig};
use gyrocal_sim::gyro::{GyroConfig, GyroSignal, GyroTruth};
use gyrocal_sim::table::{SimTable, TableConfig};
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

/// `n` readings at 10 PLC through raw SCPI (the 34401A driver is another crate).
async fn read_dmm(link: &mut StreamTransport<DuplexStream>, n: u32) -> Vec<f64> {
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
    link.send_line("SYST:ERR?").await.unwrap();
    let err = link.read_line(T).await.unwrap();
    assert!(err.starts_with("+0,"), "{err}");
    line.split(',')
        .map(|r| r.trim().parse::<f64>().unwrap())
        .collect()
}

fn mean(xs: &[f64]) -> f64 {
    xs.iter().sum::<f64>() / xs.len() as f64
}

#[tokio::test(start_paused = true)]
async fn bench_constant_rate_reads_the_true_model_voltage() {
    let config = BenchConfig {
        seed: 11,
        ..BenchConfig::default()
    };
    let Bench {
        mut dmm,
        mut table,
        handle,
        ..
    } = Bench::spawn(config.clone());
    let truth = handle.truth;
    // per reading: the gyro's 1 s noise over a 0.2 s window (10 PLC at 50 Hz) and the meter's
    let sigma = (config.gyro.noise_std.powi(2) / 0.2 + config.dmm.noise_v.powi(2)).sqrt();
    let n = 100;
    let tol = 4.0 * sigma / (n as f64).sqrt() + 1e-4; // + walk and ripple (both < 1e-4 V here)

    let mut from = 0.0;
    for rate in [0.0, 10.0, -20.0] {
        table_to(&mut table, from, rate).await;
        from = rate;
        let readings = read_dmm(&mut dmm, n).await;
        assert_eq!(readings.len(), n as usize);
        let m = mean(&readings);
        let expected = truth.output(rate);
        assert!(
            (m - expected).abs() < tol,
            "rate {rate}: mean {m} vs true {expected} (tol {tol})"
        );
        let sd = (readings.iter().map(|r| (r - m).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
        assert!(
            sd > 0.5 * sigma && sd < 1.5 * sigma,
            "reading std {sd} vs expected {sigma}"
        );
    }
    // at zero rate the Earth-rate term is visible in the bias, as the method says
    assert!((truth.effective_k0() - truth.k0 - 0.3612 * truth.earth_rate).abs() < 1e-12);
    assert!(truth.effective_k0() - truth.k0 > 8.0 * tol / 4.0);
    assert_eq!(handle.table.demanded_rate(), -20.0);
}

#[tokio::test(start_paused = true)]
async fn bench_gyro_model_asymmetry_nonlinearity_and_window_integration() {
    let (_link, dev) = gyrocal_link::memory_pair("t");
    let table = SimTable::spawn(
        dev,
        TableConfig {
            rate_noise_std: 0.0,
            ripple_amplitude: 0.0,
            ..Default::default()
        },
        1,
    );
    let cfg = GyroConfig {
        k1_neg: Some(0.3600),
        k2: 1e-4,
        k3: -2e-6,
        noise_std: 0.0,
        bias_random_walk: 0.0,
        latitude_deg: 30.0,
        ..GyroConfig::default()
    };
    let mut gyro = GyroSignal::new(cfg.clone(), table.clone(), 5);
    let truth: GyroTruth = gyro.truth();
    assert!((truth.earth_rate - 15.041 / 3600.0 * 0.5).abs() < 1e-12);
    assert_eq!((truth.k1_pos, truth.k1_neg), (0.3612, 0.3600));
    let w = -10.0 + truth.earth_rate;
    let manual = 0.0088 + 0.36 * w + 1e-4 * w * w - 2e-6 * w.powi(3);
    assert!((truth.output(-10.0) - manual).abs() < 1e-15);
    // a stationary table: the output is the effective bias
    let v = gyro.volts(Instant::now(), Duration::from_millis(200));
    assert!((v - truth.effective_k0()).abs() < 1e-12, "{v}");
    // the least-squares line over a symmetric schedule sees the asymmetry as a mean K
    let (k, _) = truth.fit_line(&[-20.0, -10.0, 10.0, 20.0]);
    assert!(k > 0.3590 && k < 0.3612, "{k}");
    // for a linear, symmetric gyro the line is (K1, K0 + K1 * earth rate)
    let linear = GyroTruth {
        k1_neg: 0.3612,
        k2: 0.0,
        k3: 0.0,
        ..truth
    };
    let (k, k0) = linear.fit_line(&[-20.0, -1.0, 0.0, 3.0, 20.0]);
    assert!((k - 0.3612).abs() < 1e-12 && (k0 - linear.effective_k0()).abs() < 1e-12);
    // seeded: two gyros with the same seed give the same noisy readings
    let noisy = GyroConfig {
        noise_std: 0.001,
        ..cfg
    };
    let mut a = GyroSignal::new(noisy.clone(), table.clone(), 9);
    let mut b = GyroSignal::new(noisy, table.clone(), 9);
    let t = Instant::now();
    assert_eq!(
        a.volts(t, Duration::from_millis(20)),
        b.volts(t, Duration::from_millis(20))
    );
}

#[test]
fn bench_config_from_toml_with_defaults_and_unknown_fields_refused() {
    let c: BenchConfig = toml::from_str(
        "seed = 42\ntime_scale = 10.0\n[table]\nnever_settle = true\n[table.faults]\ninject_at_rate = 8.0\n\
         [gyro]\nk1_neg = 0.361\nlatitude_deg = 34.3\n[dmm]\nline_hz = 60\n",
    )
    .unwrap();
    assert_eq!(c.seed, 42);
    assert!(c.table.never_settle);
    assert_eq!(c.table.faults.inject_at_rate, Some(8.0));
    assert_eq!(c.gyro.k1_neg, Some(0.361));
    assert_eq!(c.gyro.k1, GyroConfig::default().k1);
    assert_eq!(c.dmm.line_hz, 60);
    assert_eq!(
        toml::from_str::<BenchConfig>("").unwrap(),
        BenchConfig::default()
    );
    assert!(toml::from_str::<BenchConfig>("[gyro]\nk4 = 1.0\n").is_err());
    assert!(toml::from_str::<BenchConfig>("[table]\nmax_speed = 1.0\n").is_err());
}
