//! A plan's `[dut]` and `[acceptance]` sections, standalone acceptance files, and the hash
//! that ignores both.

// Test helpers outside #[test] functions may unwrap too: a panic is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::path::Path;

use gyrocal_files::plan::{
    Plan, PlanError, PlanErrorKind, acceptance_from_toml_str, load_acceptance,
};
use gyrocal_files::rundir::{RunDir, RunMeta};
use gyrocal_fit::acceptance::{Limits, Quantity, Rule};

/// A valid plan without `[dut]` or `[acceptance]` (3 rates, 10 readings).
fn good() -> String {
    common::plans::sweep("t", &[0.0, 1.0, -1.0], 10)
}

const RECORDS: &str = r#"
[dut]
serial = "HRG-0042"
model = "HRG-50"
manufacturer = "Example Gyro Works"
condition = "new, no visible damage"
notes = """two lines
of notes"""

[acceptance]
decision_rule = "guarded"

[acceptance.scale_factor]
min = 0.049
max = 0.051
marginal_min = 0.0495
marginal_max = 0.0505

[acceptance.nonlinearity_ppm]
max = 200
"#;

fn parse(src: &str) -> Result<Plan, PlanError> {
    Plan::from_toml_str(src, Path::new("configs/bad.toml"))
}

fn err(src: &str) -> String {
    parse(src).expect_err("must be refused").to_string()
}

#[test]
fn dut_and_acceptance_parse() {
    let good = good();
    let plan = parse(&format!("{good}{RECORDS}")).unwrap();
    let dut = plan.dut().unwrap();
    assert_eq!(dut.serial.as_deref(), Some("HRG-0042"));
    assert_eq!(dut.model.as_deref(), Some("HRG-50"));
    assert_eq!(dut.manufacturer.as_deref(), Some("Example Gyro Works"));
    assert_eq!(dut.condition.as_deref(), Some("new, no visible damage"));
    assert_eq!(dut.notes.as_deref(), Some("two lines\nof notes"));
    assert_eq!(dut.serial.as_deref(), Some("HRG-0042"));
    let a = plan.acceptance().unwrap();
    assert_eq!(a.rule, Rule::Guarded);
    assert_eq!(a.limits.len(), 2);
    assert_eq!(
        a.limits[&Quantity::ScaleFactor],
        Limits {
            min: Some(0.049),
            max: Some(0.051),
            marginal_min: Some(0.0495),
            marginal_max: Some(0.0505),
        }
    );
    assert_eq!(a.limits[&Quantity::NonlinearityPpm].max, Some(200.0));
    assert_eq!(a.limits[&Quantity::NonlinearityPpm].min, None);

    // neither is required; the rule defaults to simple; inline tables work too
    let plain = parse(&good).unwrap();
    assert!(plain.dut().is_none() && plain.acceptance().is_none());
    let inline = parse(&format!(
        "{good}[acceptance]\nbias_v = {{ min = -0.02, max = 0.02 }}\n"
    ))
    .unwrap();
    assert_eq!(inline.acceptance().unwrap().rule, Rule::Simple);
    // an empty [dut] is no [dut]
    assert!(parse(&format!("{good}[dut]\n")).unwrap().dut().is_none());
}

#[test]
fn hash_ignores_dut_and_acceptance() {
    let good = good();
    let plain = parse(&good).unwrap();
    let with = parse(&format!("{good}{RECORDS}")).unwrap();
    let other = parse(&format!(
        "{good}{}",
        RECORDS
            .replace("HRG-0042", "HRG-0043")
            .replace("max = 0.051", "max = 0.052")
            .replace("guarded", "simple")
    ))
    .unwrap();
    assert_eq!(plain.hash(), with.hash());
    assert_eq!(plain.hash(), other.hash());
    assert_ne!(with, other);
    // but a rate still changes it
    let rate = parse(&format!(
        "{}{RECORDS}",
        good.replace("[0, 1, -1]", "[0, 2, -2]")
    ))
    .unwrap();
    assert_ne!(rate.hash(), with.hash());
}

#[test]
fn the_manifest_keeps_both_and_a_resume_accepts_other_records() {
    let good = good();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let plan = parse(&format!("{good}{RECORDS}")).unwrap();
    let run = RunDir::create(&dir, &plan, RunMeta::default()).unwrap();
    drop(run);
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(manifest["plan"]["dut"]["serial"], "HRG-0042");
    assert_eq!(manifest["plan"]["acceptance"]["decision_rule"], "guarded");
    assert_eq!(manifest["plan"]["acceptance"]["scale_factor"]["max"], 0.051);
    let back = gyrocal_files::rundir::run_plan(&dir).unwrap();
    assert_eq!(back, plan);
    // another gyro's serial and other limits: the same method, the run resumes
    let other = parse(&format!(
        "{good}{}",
        RECORDS.replace("max = 200", "max = 100")
    ))
    .unwrap();
    RunDir::open_for_resume(&dir, &other).unwrap();
    assert!(gyrocal_files::rundir::plan_changes(&plan, &other).is_empty());
}

#[test]
fn dut_errors_name_the_line_and_key() {
    let good = good();
    let e = err(&format!("{good}[dut]\nserial = \"A1\"\ncolour = \"red\"\n"));
    assert!(
        e.starts_with("configs/bad.toml:13:1: [dut] unknown key `colour`"),
        "{e}"
    );
    assert!(
        e.contains("serial, model, manufacturer, condition and notes"),
        "{e}"
    );
    let e = err(&format!("{good}[dut]\nserial = 42\n"));
    assert!(
        e.starts_with("configs/bad.toml:12:10: [dut] serial = 42 is a whole number"),
        "{e}"
    );
    let e = err(&format!("{good}[dut]\nserial = \" \"\n"));
    assert_eq!(
        e,
        "configs/bad.toml:12:10: [dut] serial must not be empty: leave the key out when it is \
         not known"
    );
    let e = err(&format!("{good}[dut]\nseriel = \"x\"\n"));
    assert!(e.contains("did you mean `serial`?"), "{e}");
}

#[test]
fn acceptance_errors_name_the_line_and_key() {
    let good = good();
    // unknown quantity: named, with the valid ones
    let e = err(&format!("{good}[acceptance.scale]\nmax = 1\n"));
    assert!(
        e.starts_with(
            "configs/bad.toml:11:13: [acceptance] unknown key `scale`: did you mean `scale_factor`?"
        ),
        "{e}"
    );
    assert!(
        e.contains(
            "scale_factor, bias_v, bias_dph, nonlinearity_ppm, asymmetry_ppm, \
             asymmetry_gjb_ppm, repeatability_ppm, k2"
        ),
        "{e}"
    );
    let e = err(&format!(
        "{good}[acceptance]\ntemperature = {{ max = 1 }}\n"
    ));
    assert!(e.starts_with("configs/bad.toml:12:1: [acceptance] unknown key `temperature`: the keys of [acceptance] are decision_rule and the quantities scale_factor"), "{e}");
    // unknown key in a limits table
    let e = err(&format!("{good}[acceptance.k2]\nmaximum = 1\n"));
    assert!(
        e.starts_with(
            "configs/bad.toml:12:1: [acceptance.k2] unknown key `maximum`: did you mean `max`?"
        ),
        "{e}"
    );
    // a limit that is not a number
    let e = err(&format!("{good}[acceptance.k2]\nmax = \"1\"\n"));
    assert!(
        e.starts_with("configs/bad.toml:12:7: [acceptance.k2] max = \"1\" is text, not a number"),
        "{e}"
    );
    // a quantity that is not a table
    let e = err(&format!("{good}[acceptance]\nk2 = 1\n"));
    assert!(
        e.starts_with(
            "configs/bad.toml:12:6: [acceptance] k2 = 1 is a whole number: write a table of limits"
        ),
        "{e}"
    );
    // limits out of order: at the later key
    let e = err(&format!(
        "{good}[acceptance.scale_factor]\nmin = 0.051\nmax = 0.049\n"
    ));
    assert_eq!(
        e,
        "configs/bad.toml:13:7: [acceptance.scale_factor] max = 0.049 must be >= min = 0.051 \
         (the limits ascend: min <= marginal_min <= marginal_max <= max)"
    );
    let e = err(&format!(
        "{good}[acceptance.scale_factor]\nmin = 0.049\nmax = 0.051\nmarginal_max = 0.06\n"
    ));
    assert!(
        e.starts_with(
            "configs/bad.toml:14:16: [acceptance.scale_factor] marginal_max = 0.06 must be <= max = 0.051"
        ),
        "{e}"
    );
    // not finite
    let e = err(&format!("{good}[acceptance.bias_v]\nmax = nan\n"));
    assert_eq!(
        e,
        "configs/bad.toml:12:7: [acceptance.bias_v] max must be a finite number (got NaN)"
    );
    // no limit at all
    let e = err(&format!("{good}[acceptance.bias_v]\n"));
    assert!(
        e.starts_with("configs/bad.toml:11:1: [acceptance] bias_v sets no limit"),
        "{e}"
    );
    // the decision rule
    let e = err(&format!("{good}[acceptance]\ndecision_rule = \"strict\"\n"));
    assert_eq!(
        e,
        "configs/bad.toml:12:17: [acceptance] decision_rule = \"strict\" is not a decision rule: \
         write \"simple\" or \"guarded\""
    );
    assert_eq!(
        parse(&format!("{good}[acceptance]\ndecision_rule = 1\n"))
            .unwrap_err()
            .kind(),
        PlanErrorKind::Invalid
    );
}

#[test]
fn a_standalone_acceptance_file() {
    let good = good();
    let text = r#"# limits for HRG-50
decision_rule = "guarded"

[scale_factor]
min = 0.049
max = 0.051

[repeatability_ppm]
max = 50
"#;
    let spec = acceptance_from_toml_str(text, Path::new("limits.toml")).unwrap();
    assert_eq!(spec.rule, Rule::Guarded);
    assert_eq!(spec.limits[&Quantity::RepeatabilityPpm].max, Some(50.0));
    assert_eq!(spec.limits.len(), 2);

    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("limits.toml");
    std::fs::write(&path, text).unwrap();
    assert_eq!(load_acceptance(&path).unwrap(), spec);

    let bad = |t: &str| {
        acceptance_from_toml_str(t, Path::new("limits.toml"))
            .unwrap_err()
            .to_string()
    };
    let e = bad("[scale]\nmax = 1\n");
    assert!(
        e.starts_with(
            "limits.toml:1:2: [acceptance] unknown key `scale`: did you mean `scale_factor`?"
        ),
        "{e}"
    );
    let e = bad("[k2]\nmin = 2\nmax = 1\n");
    assert!(
        e.starts_with("limits.toml:3:7: [acceptance.k2] max = 1 must be >= min = 2"),
        "{e}"
    );
    let e = bad("decision_rule = \"maybe\"\n");
    assert!(
        e.starts_with("limits.toml:1:17: [acceptance] decision_rule"),
        "{e}"
    );
    let e = bad("[k2\n");
    assert!(e.starts_with("limits.toml:1:"), "{e}");
    // a whole plan is not an acceptance file
    let e = bad(&good);
    assert!(e.contains("unknown key `plan`"), "{e}");

    // reading: the document is named, the size is capped
    let missing = load_acceptance(&tmp.path().join("nope.toml")).unwrap_err();
    assert_eq!(missing.kind(), PlanErrorKind::Read);
    assert!(
        missing
            .to_string()
            .contains("cannot read the acceptance file"),
        "{missing}"
    );
    let device = load_acceptance(Path::new("/dev/zero")).unwrap_err();
    assert_eq!(device.kind(), PlanErrorKind::Read);
    assert!(device.to_string().contains("a device"), "{device}");
    let sparse = tmp.path().join("huge.toml");
    std::fs::File::create(&sparse)
        .unwrap()
        .set_len(8 << 20)
        .unwrap();
    let big = load_acceptance(&sparse).unwrap_err();
    assert_eq!(big.kind(), PlanErrorKind::TooLarge);
    assert_eq!(
        big.to_string(),
        format!(
            "{}: larger than the 1024 KiB limit for an acceptance file (an acceptance file \
             is a few kilobytes); is it the right file?",
            sparse.display()
        )
    );
}
