//! Behaviour a user relies on: streaming equals batch, simulated terms are recovered, bad input
//! gives a clear error, the uncertainty never fails.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use gyrocal_allan::sim::{GyroNoise, generate};
use gyrocal_allan::{
    ErrorKind, Estimator, NoiseIdMethod, Record, Streaming, TauSet, Term, bias_figures, compute,
    compute_record, deviations, noise_terms,
};
use proptest::prelude::*;

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

#[test]
fn streaming_equals_batch_for_any_chunking() {
    let noise = GyroNoise {
        bias_deg_per_h: 1234.5,
        arw_deg_per_sqrt_h: 0.2,
        bias_instability_deg_per_h: 0.1,
        rrw_deg_per_h_per_sqrt_h: 0.5,
        ..GyroNoise::default()
    };
    let y = generate(&noise, 0.01, 100_003, 3).unwrap();
    let rec = Record::from_slice(&y, 0.01).unwrap();
    let batch = deviations(&rec, Estimator::Oadev, &TauSet::Octave).unwrap();
    for chunk in [1usize, 7, 4096, 100_003] {
        let max_m = 1 << 16;
        let mut s = Streaming::new(0.01, max_m);
        for c in y.chunks(chunk) {
            s.push(c).unwrap();
            assert!(s.buffered() <= 2 * (2 * max_m + 1) + chunk);
        }
        let st = s.deviations().unwrap();
        assert_eq!(st.len(), batch.len(), "chunk {chunk}");
        for (a, b) in st.iter().zip(&batch) {
            assert_eq!((a.m, a.n_terms), (b.m, b.n_terms));
            assert!(
                rel(a.deviation, b.deviation) < 1e-9,
                "chunk {chunk} m={} {} vs {}",
                a.m,
                a.deviation,
                b.deviation
            );
        }
        let curve = s.curve().unwrap();
        assert!(
            curve
                .points
                .iter()
                .all(|p| p.ci95.0 < p.deviation && p.deviation < p.ci95.1)
        );
    }
    // a smaller max_m keeps only the octaves up to it, with a small buffer
    let mut s = Streaming::new(0.01, 64);
    for c in y.chunks(1000) {
        s.push(c).unwrap();
    }
    assert!(s.buffered() <= 2 * 129 + 1000);
    let st = s.deviations().unwrap();
    assert_eq!(st.last().unwrap().m, 64);
    for (a, b) in st.iter().zip(&batch) {
        assert!(rel(a.deviation, b.deviation) < 1e-9);
    }
    assert_eq!(
        s.push(&[1.0, f64::NAN]).unwrap_err().kind(),
        ErrorKind::NonFinite
    );
}

/// A term set alone in a simulated record: the model σ at the term's read τ lies inside the 95 %
/// interval of the curve there, and both the slope read and the fit land within 2.5 standard
/// uncertainties (the uncertainties ignore the correlation of overlapping points).
fn recover(noise: GyroNoise, term: Term, truth: f64, n: usize) {
    let tau0 = 1.0 / 128.0;
    let y = generate(&noise, tau0, n, 11).unwrap();
    let curve = compute(&y, tau0, Estimator::Oadev, &TauSet::Octave).unwrap();
    let terms = noise_terms(&curve);
    let fit = terms.fit.as_ref().expect("fit");
    let ft = fit.terms.iter().find(|t| t.term == term).unwrap();
    let read = match term {
        Term::Quantization => terms.quantization.clone(),
        Term::AngleRandomWalk => terms.angle_random_walk.clone(),
        Term::RateRandomWalk => terms.rate_random_walk.clone(),
        Term::RateRamp => terms.rate_ramp.clone(),
        Term::BiasInstability => None,
    };
    eprintln!(
        "{term:?}: truth {truth}, fit {:?}, read {:?}, chi2r {}",
        ft.value,
        read.as_ref().map(|r| &r.value),
        fit.chi2_reduced
    );
    if term == Term::BiasInstability {
        // the generator's flicker is a sum of Gauss-Markov processes, flat to a few per cent only
        assert!(rel(ft.value.value, truth) < 0.1, "fit {term:?}");
    } else {
        assert!(
            (ft.value.value - truth).abs() <= 2.5 * ft.value.uncertainty,
            "fit {term:?}"
        );
    }
    if let Some(r) = read {
        assert!(
            (r.value.value - truth).abs() <= 2.5 * r.value.uncertainty,
            "read {term:?}"
        );
    }
    if term == Term::BiasInstability {
        let b = terms.bias_instability.unwrap();
        eprintln!("B read {:?}", b.value);
        // σ_min with its 95 % interval contains the flicker floor 0.664·B
        let p = curve
            .points
            .iter()
            .find(|p| p.tau_s == b.tau_min_s)
            .unwrap();
        let floor = truth * gyrocal_allan::FLICKER_FLOOR;
        assert!(
            p.ci95.0 <= floor && floor <= p.ci95.1,
            "{p:?} floor {floor}"
        );
    } else {
        let tau = term.read_tau_s();
        let p = curve
            .points
            .iter()
            .min_by(|a, b| {
                (a.tau_s / tau)
                    .ln()
                    .abs()
                    .total_cmp(&(b.tau_s / tau).ln().abs())
            })
            .unwrap();
        let model = fit_sigma(term, truth, p.tau_s);
        assert!(
            p.ci95.0 <= model && model <= p.ci95.1,
            "{term:?} at τ={}: {model} not in {:?}",
            p.tau_s,
            p.ci95
        );
    }
}

/// σ(τ) in °/h of a single term with value `v` in its reported unit.
fn fit_sigma(term: Term, v: f64, tau: f64) -> f64 {
    let c = v / term.unit_factor();
    match term {
        Term::Quantization => 3f64.sqrt() * c / tau,
        Term::AngleRandomWalk => c / tau.sqrt(),
        Term::BiasInstability => gyrocal_allan::FLICKER_FLOOR * c,
        Term::RateRandomWalk => c * (tau / 3.0).sqrt(),
        Term::RateRamp => c * tau / 2f64.sqrt(),
    }
}

#[test]
fn recovers_angle_random_walk() {
    let n = GyroNoise {
        arw_deg_per_sqrt_h: 0.15,
        ..GyroNoise::default()
    };
    recover(n, Term::AngleRandomWalk, 0.15, 1 << 18);
}

#[test]
fn recovers_quantization() {
    let n = GyroNoise {
        quantization_arcsec: 2.0,
        ..GyroNoise::default()
    };
    recover(n, Term::Quantization, 2.0, 1 << 18);
}

#[test]
fn recovers_rate_random_walk() {
    let n = GyroNoise {
        rrw_deg_per_h_per_sqrt_h: 3.0,
        ..GyroNoise::default()
    };
    recover(n, Term::RateRandomWalk, 3.0, 1 << 18);
}

#[test]
fn recovers_rate_ramp() {
    let n = GyroNoise {
        rate_ramp_deg_per_h2: 50.0,
        arw_deg_per_sqrt_h: 1e-5,
        ..GyroNoise::default()
    };
    recover(n, Term::RateRamp, 50.0, 1 << 18);
}

#[test]
fn recovers_bias_instability() {
    let n = GyroNoise {
        bias_instability_deg_per_h: 0.5,
        flicker_max_tau_s: 1.0e3,
        ..GyroNoise::default()
    };
    recover(n, Term::BiasInstability, 0.5, 1 << 20);
}

#[test]
fn bias_figures_and_windows() {
    let y: Vec<f64> = (0..2000)
        .map(|i| 5.0 + if i % 2 == 0 { 1.0 } else { -1.0 })
        .collect();
    let rec = Record::from_slice(&y, 0.1).unwrap();
    let b = bias_figures(&rec, "deg/h");
    assert!((b.bias.value - 5.0).abs() < 1e-12);
    let s10 = b.stability_10s.unwrap();
    assert_eq!(s10.windows, 20);
    assert!(s10.stability.value.abs() < 1e-12);
    assert_eq!(b.stability_100s.unwrap().windows, 2);
}

#[test]
fn bad_input_gives_clear_errors() {
    assert_eq!(
        Record::from_slice(&[], 1.0).unwrap_err().kind(),
        ErrorKind::Empty
    );
    assert_eq!(
        Record::from_slice(&[1.0, f64::NAN], 1.0)
            .unwrap_err()
            .kind(),
        ErrorKind::NonFinite
    );
    assert_eq!(
        Record::from_slice(&[1.0], 0.0).unwrap_err().kind(),
        ErrorKind::InvalidParameter
    );
    assert_eq!(
        compute(&[1.0, 2.0], 1.0, Estimator::Oadev, &TauSet::Octave)
            .unwrap_err()
            .kind(),
        ErrorKind::TooShort
    );
    let e = compute(
        &[1.0, 2.0, 3.0, 4.0],
        1.0,
        Estimator::Oadev,
        &TauSet::Explicit(vec![100.0]),
    )
    .unwrap_err();
    assert_eq!(e.kind(), ErrorKind::NoTaus);
    let e = Record::from_reader("t,rate\n0,1\n1,2\n2,3\n5,4\n".as_bytes(), None).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Parse);
    assert!(e.to_string().contains("line 5"), "{e}");
    let e = Record::from_reader("0,1\n1,2\n2,3\n3,4\n".as_bytes(), None).unwrap();
    assert_eq!(e.tau0_s(), 1.0);
    assert_eq!(
        Record::from_reader("1\n2\nx\n".as_bytes(), Some(1.0))
            .unwrap_err()
            .kind(),
        ErrorKind::Parse
    );
    assert_eq!(
        Record::from_reader("1\n2\n".as_bytes(), None)
            .unwrap_err()
            .kind(),
        ErrorKind::InvalidParameter
    );
    // a line without end (after two good ones) is refused after a bounded read, not echoed
    let endless = std::io::Read::chain("t,rate\n0,1\n".as_bytes(), std::io::repeat(b'7'));
    let e = Record::from_reader(endless, None).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Parse);
    assert!(
        e.to_string().contains("line 3") && e.to_string().contains("longer than"),
        "{e}"
    );
    assert!(!e.to_string().contains("777"), "{e}");
    // a byte-order mark before the first sample: the sample is read, not taken as a header
    let r = Record::from_reader("\u{feff}0,1\n1,2\n2,3\n".as_bytes(), None).unwrap();
    assert_eq!(r.len(), 3);
}

#[test]
fn parses_time_value_and_value_only() {
    let rec = Record::from_reader(
        "# gyro\ntime_s;rate\n0.0;1\n0.5;2\n1.0;3\n1.5;6\n".as_bytes(),
        None,
    )
    .unwrap();
    assert_eq!(rec.len(), 4);
    assert!((rec.tau0_s() - 0.5).abs() < 1e-15);
    assert!((rec.mean() - 3.0).abs() < 1e-15);
    let rec = Record::from_reader("1 \n 2\n\n3\n".as_bytes(), Some(0.1)).unwrap();
    assert_eq!(rec.len(), 3);
}

#[test]
fn every_point_gets_an_interval_and_a_method() {
    let y = generate(
        &GyroNoise {
            arw_deg_per_sqrt_h: 0.1,
            rrw_deg_per_h_per_sqrt_h: 1.0,
            ..GyroNoise::default()
        },
        0.01,
        5000,
        5,
    )
    .unwrap();
    let rec = Record::from_slice(&y, 0.01).unwrap();
    for est in Estimator::ALL {
        for taus in [TauSet::Octave, TauSet::Decade, TauSet::PerDecade(5)] {
            let c = compute_record(&rec, est, &taus).unwrap();
            assert!(
                c.points
                    .iter()
                    .any(|p| p.noise_id_method != NoiseIdMethod::Lag1Autocorrelation)
            );
            for p in &c.points {
                assert!(p.edf > 0.0 && p.edf.is_finite(), "{est:?} {p:?}");
                assert!(
                    p.ci95.0 < p.ci68.0 && p.ci68.0 < p.deviation,
                    "{est:?} {p:?}"
                );
                assert!(
                    p.deviation < p.ci68.1 && p.ci68.1 < p.ci95.1,
                    "{est:?} {p:?}"
                );
                assert_eq!(p.beyond_quarter, p.tau_s > 50.0 / 4.0);
            }
        }
    }
    let per: Vec<usize> = TauSet::PerDecade(10).factors(1000, 1.0);
    assert_eq!(&per[..12], &[1, 2, 3, 4, 5, 6, 8, 10, 13, 16, 20, 25]);
    assert_eq!(
        TauSet::Decade.factors(1000, 1.0),
        vec![1, 2, 4, 10, 20, 40, 100, 200, 400, 1000]
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    /// Any finite record: no panic, deviations ≥ 0, intervals ordered; a constant offset and a
    /// linear ramp (for OHDEV) change nothing.
    #[test]
    fn never_panics_and_is_offset_invariant(
        y in proptest::collection::vec(-1e3f64..1e3, 3..300),
        offset in -1e6f64..1e6,
    ) {
        for est in Estimator::ALL {
            let c = compute(&y, 0.5, est, &TauSet::All);
            if let Ok(c) = c {
                for p in &c.points {
                    prop_assert!(p.deviation >= 0.0);
                    prop_assert!(p.edf > 0.0);
                }
                let shifted: Vec<f64> = y.iter().map(|v| v + offset).collect();
                let c2 = compute(&shifted, 0.5, est, &TauSet::All).unwrap();
                for (a, b) in c.points.iter().zip(&c2.points) {
                    prop_assert!((a.deviation - b.deviation).abs() <= 1e-6 * (1.0 + a.deviation), "{est:?} {} {}", a.deviation, b.deviation);
                }
            }
        }
    }
}

#[test]
#[ignore = "prints the flicker curve"]
fn print_flicker_curve() {
    let n = GyroNoise {
        bias_instability_deg_per_h: 0.5,
        flicker_max_tau_s: 1.0e3,
        ..GyroNoise::default()
    };
    let y = generate(&n, 1.0 / 128.0, 1 << 20, 11).unwrap();
    let c = compute(&y, 1.0 / 128.0, Estimator::Oadev, &TauSet::Octave).unwrap();
    for p in &c.points {
        eprintln!(
            "{:10.4} {:.4} {:.4}",
            p.tau_s,
            p.deviation,
            p.deviation / 0.5 / gyrocal_allan::FLICKER_FLOOR
        );
    }
}
