//! A record in a file ([`DiskRecord`]) gives the same bits as the same record in memory
//! ([`Record`]) for every estimator, τ set, noise identification and bias figure, whatever the
//! read buffer (small buffers force the cursors to refill mid-block and the strided reads to
//! take both of their ways).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use gyrocal_allan::disk::{SampleFile, SampleWriter};
use gyrocal_allan::noise_id::{autocorr_noise_id, autocorr_noise_id_in};
use gyrocal_allan::sim::{GyroNoise, generate};
use gyrocal_allan::{
    DiskRecord, ErrorKind, Estimator, Record, TauSet, bias_figures, bias_figures_in, compute_record,
};

fn samples(y: &[f64], buffer: usize) -> SampleFile {
    let mut w = SampleWriter::new(tempfile::tempfile().unwrap()).unwrap();
    w.extend_from_slice(y).unwrap();
    w.finish().unwrap().with_buffer_len(buffer)
}

fn record(n: usize, seed: u64) -> Vec<f64> {
    let noise = GyroNoise {
        bias_deg_per_h: 1234.5,
        quantization_arcsec: 0.5,
        arw_deg_per_sqrt_h: 0.2,
        bias_instability_deg_per_h: 0.1,
        rrw_deg_per_h_per_sqrt_h: 0.5,
        rate_ramp_deg_per_h2: 3.0,
        ..GyroNoise::default()
    };
    generate(&noise, 0.01, n, seed).unwrap()
}

/// Debug of f64 is the shortest text that reads back to the same bits: equal text, equal bits.
fn bits<T: std::fmt::Debug>(v: &T) -> String {
    format!("{v:?}")
}

fn same_everything(y: &[f64], skip: usize, buffer: usize, taus: &[TauSet]) {
    let mem = Record::from_slice(&y[skip..], 0.01).unwrap();
    let file = samples(y, buffer);
    let disk = DiskRecord::from_samples(&file, skip..y.len(), tempfile::tempfile().unwrap(), 0.01)
        .unwrap();
    assert_eq!(disk.len(), mem.len());
    assert_eq!(disk.mean().to_bits(), mem.mean().to_bits());
    let mut prefix = vec![0.0; mem.len() + 1];
    disk.prefix().read_values(0, &mut prefix).unwrap();
    assert_eq!(bits(&prefix), bits(&mem.prefix()), "prefix sums");
    for taus in taus {
        for est in Estimator::ALL {
            let a = compute_record(&mem, est, taus).unwrap();
            let b = compute_record(&disk, est, taus).unwrap();
            assert!(!a.points.is_empty());
            assert_eq!(bits(&a), bits(&b), "{est:?} {taus:?} buffer {buffer}");
        }
    }
    for m in [1usize, 2, 3, 7, 64, 333] {
        for dmax in [2u32, 3] {
            let a = autocorr_noise_id(mem.prefix(), m, dmax);
            let b = autocorr_noise_id_in(disk.prefix(), m, dmax).unwrap();
            assert_eq!(bits(&a), bits(&b), "noise id m={m} dmax={dmax}");
        }
    }
    assert_eq!(
        bits(&bias_figures(&mem, "deg/h")),
        bits(&bias_figures_in(&disk, "deg/h").unwrap())
    );
}

#[test]
fn every_estimator_and_tau_set_is_the_same_from_a_file() {
    // every m on a short record, small buffers: refills inside blocks, reflected TOTDEV reads
    // longer than a buffer, gathers far apart and close together
    let y = record(2_500, 5);
    for buffer in [1024, 4096] {
        same_everything(&y, 17, buffer, &[TauSet::All]);
    }
    // a longer record, several blocks of 1024 terms and the bias windows of 10 s and 100 s
    let y = record(40_000, 6);
    same_everything(
        &y,
        1_000,
        1024,
        &[
            TauSet::Octave,
            TauSet::Decade,
            TauSet::PerDecade(7),
            TauSet::Explicit(vec![0.05, 3.33, 77.7]),
        ],
    );
}

#[test]
fn a_disk_record_reports_bad_samples_and_ranges() {
    let mut y = record(100, 1);
    y[40] = f64::NAN;
    let f = samples(&y, 1024);
    let e = DiskRecord::from_samples(&f, 10..100, tempfile::tempfile().unwrap(), 0.01).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::NonFinite);
    assert!(e.to_string().contains("sample 30"), "{e}");
    let e = DiskRecord::from_samples(&f, 0..101, tempfile::tempfile().unwrap(), 0.01).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::InvalidParameter);
    let e = DiskRecord::from_samples(&f, 5..5, tempfile::tempfile().unwrap(), 0.01).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Empty);
    let e = DiskRecord::from_samples(&f, 0..10, tempfile::tempfile().unwrap(), 0.0).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::InvalidParameter);
    // reading past the end is an error, not a panic
    let mut out = [0.0; 3];
    assert!(f.read_values(98, &mut out).is_err());
    assert!(f.chunks(0..101).is_err());
}
