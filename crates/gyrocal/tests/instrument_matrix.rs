//! The same plan on every instrument combination gyrocal supports, and the fault matrix on
//! each: the 34401A over RS-232, through a Prologix GPIB-USB and a GPIB-Ethernet controller,
//! the Keysight 34461A and 34465A over LAN; each with the ACUTROL (ACL) and the Ideal
//! Aerosmith table. Runs `gyrocal run --simulate` (virtual time, the real drivers against
//! simulators that serve each wire protocol) with the plan's `[dmm]`/`[table]` sections
//! changed and nothing else, and checks what an operator would: the run completes or fails
//! as the fault demands, retries are counted the same in steps.csv and the manifest, a
//! faulted step is never recorded, and the table ends at rest.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use common::final_table_state as table_at_end;
use common::manifest;

use std::path::{Path, PathBuf};

const METERS: &[(&str, &str)] = &[
    ("34401A RS-232", ""),
    (
        "34401A Prologix USB",
        "port = \"prologix:/dev/ttyUSB0?addr=22\"\n",
    ),
    (
        "34401A Prologix Ethernet",
        "port = \"prologix-tcp://192.0.2.1:1234?addr=22\"\n",
    ),
    (
        "34461A LAN",
        "model = \"34461a\"\nport = \"tcp://192.0.2.10:5025\"\n",
    ),
    (
        "34465A LAN",
        "model = \"34465a\"\nport = \"tcp://192.0.2.10:5025\"\n",
    ),
];

const TABLES: &[&str] = &["acl", "aerosmith"];

fn config(name: &str) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../configs")
        .join(name);
    std::fs::read_to_string(path).unwrap()
}

/// A plan of configs/ with the meter's keys put first in `[dmm]` (replacing its `port`) and
/// the table's dialect.
fn plan(dir: &Path, base: &str, meter: &str, dialect: &str) -> PathBuf {
    let mut text = config(base).replace("dialect = \"acl\"", &format!("dialect = \"{dialect}\""));
    if !meter.is_empty() {
        text = text.replace("port = \"/dev/ttyUSB0\"\n", "");
        text = text.replace("[dmm]\n", &format!("[dmm]\n{meter}"));
    }
    let path = dir.join("plan.toml");
    std::fs::write(&path, text).unwrap();
    path
}

struct Outcome {
    code: Option<i32>,
    stderr: String,
    dir: PathBuf,
}

fn run(
    tmp: &Path,
    config: &str,
    name: &str,
    meter: &str,
    dialect: &str,
    fault: Option<&str>,
) -> Outcome {
    let base = tmp.join(name.replace(' ', "_"));
    std::fs::create_dir_all(&base).unwrap();
    let plan = plan(&base, config, meter, dialect);
    let dir = base.join("run");
    let mut cmd = common::gyrocal();
    cmd.arg("run")
        .arg(&plan)
        .args(["--simulate", "--no-report", "-o"])
        .arg(&dir)
        .env_remove("RUST_LOG")
        .env("GYROCAL_CATALOG", "off");
    if let Some(f) = fault {
        cmd.args(["--sim-fault", f]);
    }
    let out = cmd.output().unwrap();
    Outcome {
        code: out.status.code(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
        dir,
    }
}

/// (step, n + overloads, retries) of each row of steps.csv; the step 0-based (the file's
/// `step_no` minus one).
fn steps(dir: &Path) -> Vec<(usize, u64, u64)> {
    let mut r = csv::Reader::from_path(dir.join("steps.csv")).unwrap();
    let h = r.headers().unwrap().clone();
    let col = |name: &str| h.iter().position(|c| c == name).unwrap();
    let (s, n, o, re) = (col("step_no"), col("n"), col("overloads"), col("retries"));
    r.records()
        .map(|rec| {
            let rec = rec.unwrap();
            let num = |i: usize| rec[i].parse::<u64>().unwrap();
            (num(s) as usize - 1, num(n) + num(o), num(re))
        })
        .collect()
}

/// Every combination on quick.toml, in parallel threads (each run is its own process).
fn each(fault: Option<&'static str>, check: fn(&str, &Outcome)) {
    each_on("quick.toml", fault, check)
}

fn each_on(config: &'static str, fault: Option<&'static str>, check: fn(&str, &Outcome)) {
    let tmp = tempfile::tempdir().unwrap();
    let tmp = tmp.path().to_path_buf();
    std::thread::scope(|s| {
        for (meter_name, meter) in METERS {
            for dialect in TABLES {
                let tmp = tmp.clone();
                s.spawn(move || {
                    let name = format!("{meter_name} + {dialect}");
                    let o = run(&tmp, config, &name, meter, dialect, fault);
                    check(&name, &o);
                });
            }
        }
    });
}

#[test]
fn the_paper_method_runs_on_every_combination() {
    each(None, |name, o| {
        assert_eq!(o.code, Some(0), "{name}:\n{}", o.stderr);
        let m = manifest(&o.dir);
        assert_eq!(m["status"], "complete", "{name}");
        let rows = steps(&o.dir);
        assert_eq!(rows.len(), 5, "{name}");
        assert!(
            rows.iter().all(|r| r.1 == 50 && r.2 == 0),
            "{name}: {rows:?}"
        );
        assert_eq!(table_at_end(&o.stderr)["stopped"], true, "{name}");
        // no instrument time wasted on any combination
        let ratio = m["timing"]["ratio"].as_f64().unwrap();
        assert!((1.0..1.01).contains(&ratio), "{name}: ratio {ratio}");
    });
}

/// The done-when of the instrument roles: the paper plan, unchanged but for its `[dmm]` and
/// `[table]` sections, on every combination, within 0.2 % of the physical bound.
#[test]
fn the_paper_plan_runs_on_every_combination_within_0_2_percent_of_the_bound() {
    each_on("paper.toml", None, |name, o| {
        assert_eq!(o.code, Some(0), "{name}:\n{}", o.stderr);
        let rows = steps(&o.dir);
        assert_eq!(rows.len(), 19, "{name}");
        assert!(rows.iter().all(|r| r.1 == 500), "{name}: {rows:?}");
        let ratio = manifest(&o.dir)["timing"]["ratio"].as_f64().unwrap();
        eprintln!("paper plan, {name}: ratio elapsed/bound {ratio:.5}");
        assert!((1.0..=1.002).contains(&ratio), "{name}: ratio {ratio}");
    });
}

#[test]
fn a_garbled_reading_is_retried_and_counted_once_on_every_combination() {
    each(Some("dmm:garble@reading60"), |name, o| {
        assert_eq!(o.code, Some(0), "{name}:\n{}", o.stderr);
        let rows = steps(&o.dir);
        assert_eq!(rows.len(), 5, "{name}");
        let in_csv: u64 = rows.iter().map(|r| r.2).sum();
        let m = manifest(&o.dir);
        let in_manifest = m["retries"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| r["instrument"] == "dmm")
            .count() as u64;
        assert!(in_csv >= 1, "{name}: the retry is in steps.csv");
        assert_eq!(
            in_csv, in_manifest,
            "{name}: steps.csv vs manifest.json\n{m}"
        );
        assert!(rows.iter().all(|r| r.1 == 50), "{name}: {rows:?}");
    });
}

#[test]
fn a_meter_power_cycle_loses_no_recorded_data_on_every_combination() {
    each(Some("dmm:powercycle@reading60/2s"), |name, o| {
        assert_eq!(o.code, Some(0), "{name}:\n{}", o.stderr);
        let rows = steps(&o.dir);
        let mut idx: Vec<usize> = rows.iter().map(|r| r.0).collect();
        idx.sort_unstable();
        assert_eq!(idx, [0, 1, 2, 3, 4], "{name}: every step exactly once");
        assert!(rows.iter().all(|r| r.1 == 50), "{name}: {rows:?}");
    });
}

#[test]
fn a_table_trip_fails_the_run_records_no_faulted_step_and_ends_at_rest_on_every_combination() {
    each(Some("table:trip@demand3"), |name, o| {
        assert_eq!(o.code, Some(1), "{name}:\n{}", o.stderr);
        let m = manifest(&o.dir);
        assert_eq!(m["status"], "failed", "{name}");
        let idx: Vec<usize> = steps(&o.dir).iter().map(|r| r.0).collect();
        assert_eq!(idx, [0, 1], "{name}: the tripped step is not recorded");
        let t = table_at_end(&o.stderr);
        assert_eq!(t["stopped"], true, "{name}: {t}");
    });
}

#[test]
fn a_meter_that_disconnects_fails_the_run_with_the_table_at_rest_on_every_combination() {
    each(Some("dmm:disconnect@reading60"), |name, o| {
        assert_eq!(o.code, Some(1), "{name}:\n{}", o.stderr);
        assert_eq!(manifest(&o.dir)["status"], "failed", "{name}");
        let idx: Vec<usize> = steps(&o.dir).iter().map(|r| r.0).collect();
        assert_eq!(idx, [0], "{name}: only the step before the loss");
        let t = table_at_end(&o.stderr);
        assert_eq!(t["stopped"], true, "{name}: {t}");
        assert!(o.stderr.contains("table at rest"), "{name}:\n{}", o.stderr);
    });
}
