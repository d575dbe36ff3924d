//! Property ("fuzz") tests of the record parsers: station files, standalone acceptance files
//! and plans with `[dut]`/`[acceptance]`. Arbitrary text and the shipped examples with one
//! line changed must give a value or an error naming the file and, when placed, a line inside
//! it; never a panic.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::path::Path;

use gyrocal_files::Plan;
use gyrocal_files::plan::acceptance_from_toml_str;
use gyrocal_files::station::Station;
use gyrocal_fit::acceptance::{Measured, evaluate};
use proptest::prelude::*;

const STATION: &str = include_str!("../../../configs/station.example.toml");
const ACCEPTANCE: &str = include_str!("../../../configs/acceptance.example.toml");
const QUICK: &str = include_str!("../../../configs/quick.toml");

fn line_ok(src: &str, line: Option<u32>, text: &str) -> Result<(), TestCaseError> {
    if let Some(line) = line {
        let lines = src.split('\n').count().max(1);
        prop_assert!(
            line >= 1 && line as usize <= lines,
            "line {} of {}: {}",
            line,
            lines,
            text
        );
    }
    Ok(())
}

fn check_station(src: &str) -> Result<(), TestCaseError> {
    match Station::from_toml_str(src, Path::new("fuzzed.toml")) {
        Ok(s) => {
            let _ = s.overdue(jiff::civil::date(2026, 1, 1));
            let _ = s.meter_accuracy();
            // reads back (serde_json's float parsing may differ in the last bit: no equality)
            let json = serde_json::to_string(&s).unwrap();
            serde_json::from_str::<Station>(&json).unwrap();
        }
        Err(e) => {
            let text = e.to_string();
            prop_assert!(text.contains("fuzzed.toml"), "{}", text);
            line_ok(src, e.location().and_then(|l| l.line), &text)?;
        }
    }
    Ok(())
}

fn check_acceptance(src: &str) -> Result<(), TestCaseError> {
    match acceptance_from_toml_str(src, Path::new("fuzzed.toml")) {
        Ok(spec) => {
            let _ = evaluate(&spec, |_| Measured::new(0.05, 0.001));
            let json = serde_json::to_string(&spec).unwrap();
            serde_json::from_str::<gyrocal_fit::acceptance::AcceptanceSpec>(&json).unwrap();
        }
        Err(e) => {
            let text = e.to_string();
            prop_assert!(text.contains("fuzzed.toml"), "{}", text);
            line_ok(src, e.location().and_then(|l| l.line), &text)?;
        }
    }
    Ok(())
}

fn check_plan(src: &str) -> Result<(), TestCaseError> {
    match Plan::from_toml_str(src, Path::new("fuzzed.toml")) {
        Ok(plan) => {
            let _ = plan.hash();
            // the manifest's form reads back, with its records
            let json = serde_json::to_string(&plan).unwrap();
            let back: Plan = serde_json::from_str(&json).unwrap();
            prop_assert_eq!(back.dut(), plan.dut());
            prop_assert_eq!(
                back.acceptance().map(|a| a.limits.len()),
                plan.acceptance().map(|a| a.limits.len())
            );
        }
        Err(e) => {
            let text = e.to_string();
            prop_assert!(text.contains("fuzzed.toml"), "{}", text);
            line_ok(src, e.location().and_then(|l| l.line), &text)?;
        }
    }
    Ok(())
}

/// A value a key could be given.
fn value() -> impl Strategy<Value = String> {
    prop_oneof![
        "[^\n]{0,20}",
        any::<i64>().prop_map(|v| v.to_string()),
        any::<f64>().prop_map(|v| format!("{v:?}")),
        Just("nan".to_string()),
        Just("-inf".to_string()),
        Just("1e309".to_string()),
        Just("[]".to_string()),
        Just("{}".to_string()),
        Just("{ min = 1 }".to_string()),
        Just("\"\"".to_string()),
        Just("\"2026-02-30\"".to_string()),
        Just("0000-01-01".to_string()),
        Just("9999-12-31".to_string()),
        Just("2026-04-12T10:00:00Z".to_string()),
        Just("10:00:00".to_string()),
        Just("\"guarded\"".to_string()),
        Just("true".to_string()),
    ]
}

/// `base` with the value of one keyed line replaced by `v`.
fn one_value_changed(base: &str, pick: prop::sample::Index, v: &str) -> String {
    let mut lines: Vec<String> = base.lines().map(str::to_string).collect();
    let keyed: Vec<usize> = (0..lines.len())
        .filter(|&i| !lines[i].trim_start().starts_with('#') && lines[i].contains('='))
        .collect();
    let i = keyed[pick.index(keyed.len())];
    let key = lines[i].split('=').next().unwrap().to_string();
    lines[i] = format!("{key}= {v}");
    lines.join("\n")
}

/// `base` with one line removed, or a line inserted.
fn one_line_edited(base: &str, pick: prop::sample::Index, insert: Option<String>) -> String {
    let mut lines: Vec<String> = base.lines().map(str::to_string).collect();
    let i = pick.index(lines.len());
    match insert {
        Some(s) => lines.insert(i, s),
        None => {
            lines.remove(i);
        }
    }
    lines.join("\n")
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(500))]

    #[test]
    fn any_text_is_a_station_or_an_error(src in any::<String>()) {
        check_station(&src)?;
    }

    #[test]
    fn any_text_is_an_acceptance_spec_or_an_error(src in any::<String>()) {
        check_acceptance(&src)?;
    }

    #[test]
    fn station_with_one_value_changed(pick in any::<prop::sample::Index>(), v in value()) {
        check_station(&one_value_changed(STATION, pick, &v))?;
    }

    #[test]
    fn station_with_one_line_edited(
        pick in any::<prop::sample::Index>(),
        insert in proptest::option::of("[^\n]{0,30}"),
    ) {
        check_station(&one_line_edited(STATION, pick, insert))?;
    }

    #[test]
    fn acceptance_with_one_value_changed(pick in any::<prop::sample::Index>(), v in value()) {
        check_acceptance(&one_value_changed(ACCEPTANCE, pick, &v))?;
    }

    #[test]
    fn acceptance_with_one_line_edited(
        pick in any::<prop::sample::Index>(),
        insert in proptest::option::of("[^\n]{0,30}"),
    ) {
        check_acceptance(&one_line_edited(ACCEPTANCE, pick, insert))?;
    }

    #[test]
    fn a_plan_with_records_and_one_value_changed(
        pick in any::<prop::sample::Index>(),
        v in value(),
    ) {
        // the example's tables under [acceptance], and a [dut]
        let records = ACCEPTANCE
            .replace("decision_rule", "[acceptance]\ndecision_rule")
            .replace("\n[", "\n[acceptance.")
            .replace("[acceptance.acceptance]", "[acceptance]");
        let plan = format!(
            "{QUICK}\n[dut]\nserial = \"HRG-1\"\nmodel = \"HRG\"\n{records}"
        );
        check_plan(&plan)?;
        check_plan(&one_value_changed(&plan, pick, &v))?;
    }
}

#[test]
fn the_examples_parse() {
    check_station(STATION).unwrap();
    let spec = acceptance_from_toml_str(ACCEPTANCE, Path::new("acceptance.example.toml"))
        .unwrap_or_else(|e| panic!("{e}"));
    // scale factor, bias, nonlinearity, asymmetry: what a single pass can measure
    assert_eq!(spec.limits.len(), 4);
    let records = ACCEPTANCE
        .replace("decision_rule", "[acceptance]\ndecision_rule")
        .replace("\n[", "\n[acceptance.")
        .replace("[acceptance.acceptance]", "[acceptance]");
    let plan = Plan::from_toml_str(&format!("{QUICK}\n{records}"), Path::new("p.toml"))
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(plan.acceptance(), Some(&spec));
}
