//! Helpers shared by gyrocal-files' tests (`mod common;`): the plans written once for every
//! crate's tests (`tests/support/plans.rs`, see there), and the small run directory the
//! run-directory and integrity tests write.

#![allow(dead_code)] // each test file uses a subset

#[path = "../../../../tests/support/plans.rs"]
pub mod plans;

use std::path::Path;

use gyrocal_files::{Plan, RunDir, RunMeta, Sample, StepRecord};

/// The plan of these tests' run directories (5 rates, 7 readings).
pub fn plan_text() -> String {
    plans::sweep("rundir test", &[0.0, 1.0, -1.0, 2.0, -2.0], 7)
}

pub fn plan() -> Plan {
    Plan::from_toml_str(&plan_text(), Path::new("test.toml")).unwrap()
}

pub fn meta() -> RunMeta {
    RunMeta {
        gyrocal_version: "0.1.0-test".into(),
        ..RunMeta::default()
    }
}

pub fn volts(step: usize, i: u64) -> f64 {
    0.0088 + 0.3612 * [0.0, 1.0, -1.0, 2.0, -2.0][step] + (i as f64) * 1e-6
}

/// Writes all samples of `step` in chunks of 3 (with an overload at index 4) and its record.
pub fn run_step(rd: &mut RunDir, step: usize, record: bool) {
    let n = 7u64;
    let samples: Vec<Sample> = (0..n)
        .map(|i| Sample {
            index: i,
            t_s: step as f64 * 10.0 + i as f64 * 0.0415,
            volts: (i != 4).then(|| volts(step, i)),
        })
        .collect();
    for chunk in samples.chunks(3) {
        rd.append_samples(step, chunk).unwrap();
    }
    if record {
        let s = rd.schedule()[step];
        let good: Vec<f64> = samples.iter().filter_map(|s| s.volts).collect();
        let mean = good.iter().sum::<f64>() / good.len() as f64;
        rd.append_step(StepRecord {
            step,
            pass: s.pass,
            rate_dps: s.rate_dps,
            rate_meas_dps: Some(s.rate_dps + 1e-5),
            rate_meas_std_dps: Some(1e-4),
            rate_meas_min_dps: Some(s.rate_dps - 2e-4),
            rate_meas_max_dps: Some(s.rate_dps + 2e-4),
            rate_samples: Some(12),
            volts: mean,
            volts_std: Some(1e-6),
            n: good.len() as u64,
            overloads: 1,
            retries: 0,
            t_start_s: step as f64 * 10.0,
            t_end_s: step as f64 * 10.0 + 0.3,
            series: None,
        })
        .unwrap();
    }
}

/// `text` (a samples.csv or steps.csv of the current format) as gyrocal wrote it before
/// format 3: the counted columns named `step`, `index`, `pass` and counted from 0.
#[allow(dead_code)] // not every test file uses every helper
pub fn counted_from_zero(text: &str) -> String {
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let counted: Vec<bool> = header
        .iter()
        .map(|h| ["step_no", "sample_no", "pass_no"].contains(h))
        .collect();
    let renamed: Vec<&str> = header
        .iter()
        .map(|h| match *h {
            "step_no" => "step",
            "sample_no" => "index",
            "pass_no" => "pass",
            h => h,
        })
        .collect();
    let mut out = renamed.join(",") + "\n";
    for l in lines {
        let cells: Vec<String> = l
            .split(',')
            .zip(&counted)
            .map(|(c, &k)| {
                if k {
                    (c.parse::<u64>().unwrap() - 1).to_string()
                } else {
                    c.to_string()
                }
            })
            .collect();
        out += &(cells.join(",") + "\n");
    }
    out
}
