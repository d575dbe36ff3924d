//! Property ("fuzz") tests of the plan parser, run in CI: arbitrary text and near-valid plans
//! (the shipped configs with one line changed) must give a plan or an error naming the file
//! and, for TOML and value errors, a line inside it; never a panic. The cargo-fuzz target
//! `plan` in `fuzz/` searches longer (see TESTING.md).
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::path::Path;

use gyrocal_files::Plan;
use proptest::prelude::*;

const QUICK: &str = include_str!("../../../configs/quick.toml");
const PAPER: &str = include_str!("../../../configs/paper.toml");

fn check(src: &str) -> Result<(), TestCaseError> {
    match Plan::from_toml_str(src, Path::new("fuzzed.toml")) {
        Ok(plan) => {
            let _ = plan.schedule();
            let _ = plan.hash();
        }
        Err(e) => {
            let text = e.to_string();
            prop_assert!(text.contains("fuzzed.toml"), "{}", text);
            if let Some(line) = e.location().and_then(|l| l.line) {
                let lines = src.split('\n').count().max(1);
                prop_assert!(
                    line >= 1 && line as usize <= lines,
                    "line {} of {}: {}",
                    line,
                    lines,
                    text
                );
            }
        }
    }
    Ok(())
}

/// A value a plan key could be given.
fn value() -> impl Strategy<Value = String> {
    prop_oneof![
        "[^\n]{0,20}",
        any::<i64>().prop_map(|v| v.to_string()),
        any::<f64>().prop_map(|v| format!("{v:?}")),
        Just("nan".to_string()),
        Just("inf".to_string()),
        Just("-0.0".to_string()),
        Just("1e309".to_string()),
        Just("[]".to_string()),
        Just("[1, -1, 1e400]".to_string()),
        Just("\"\"".to_string()),
        Just("\"tcp://\"".to_string()),
        Just("{}".to_string()),
        Just("true".to_string()),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1000))]

    #[test]
    fn any_text_is_a_plan_or_an_error(src in any::<String>()) {
        check(&src)?;
    }

    #[test]
    fn one_value_changed(pick in any::<prop::sample::Index>(), v in value(), paper in any::<bool>()) {
        let base = if paper { PAPER } else { QUICK };
        let mut lines: Vec<String> = base.lines().map(str::to_string).collect();
        let keyed: Vec<usize> = (0..lines.len())
            .filter(|&i| !lines[i].trim_start().starts_with('#') && lines[i].contains('='))
            .collect();
        let i = keyed[pick.index(keyed.len())];
        let key = lines[i].split('=').next().unwrap().to_string();
        lines[i] = format!("{key}= {v}");
        check(&lines.join("\n"))?;
    }

    #[test]
    fn one_line_removed_or_inserted(
        pick in any::<prop::sample::Index>(),
        insert in proptest::option::of("[^\n]{0,30}"),
    ) {
        let mut lines: Vec<&str> = QUICK.lines().collect();
        let i = pick.index(lines.len());
        let inserted;
        match &insert {
            Some(s) => {
                inserted = s.clone();
                lines.insert(i, &inserted);
            }
            None => {
                lines.remove(i);
            }
        }
        check(&lines.join("\n"))?;
    }
}
