#![allow(clippy::unwrap_used, clippy::expect_used)] // tests: a panic is a failed test

use std::path::Path;
use std::time::Duration;

use super::*;

const DMM: &str =
    "[dmm]\nport = \"/dev/ttyUSB0\"\nrange_v = 10\nnplc = 1\nautozero = false\nline_hz = 50\n";
const TABLE: &str = "[table]\ndialect = \"acl\"\nport = \"/dev/ttyUSB1\"\nmax_rate_dps = 20\nacceleration_dps2 = 10\nrate_tolerance_dps = 0.002\n";
const WARMUP: &str = "[warmup]\nwindow_s = 10\nmax_s = 600\n";

fn sweep(warmup: bool) -> Plan {
    let src = format!(
        "[plan]\nname = \"s\"\nrates_dps = [0, 5, -5]\nsamples_per_rate = 20\nsettle_s = 3\nrepeat = 2\n{TABLE}{DMM}{}",
        if warmup { WARMUP } else { "" }
    );
    Plan::from_toml_str(&src, Path::new("sweep.toml")).unwrap()
}

fn drift(table: &str, warmup: bool) -> Plan {
    let section = if table == "none" { "" } else { TABLE };
    let src = format!(
        "[plan]\nkind = \"drift\"\nname = \"d\"\nrates_dps = [0]\nsamples_per_rate = 100\nrepeat = 4\nsettle_s = 0\n{section}{DMM}[drift]\ntable = \"{table}\"\n{}",
        if warmup { WARMUP } else { "" }
    );
    Plan::from_toml_str(&src, Path::new("drift.toml")).unwrap()
}

#[test]
fn a_sweep_is_its_schedule_with_rate_steps_rows_and_the_hold_checked() {
    let plan = sweep(false);
    let schedule = plan.schedule();
    let c = compile(&plan, &schedule, false);
    assert_eq!(c.setup, Setup::EnableTable);
    assert!(c.uses_table);
    assert_eq!(c.schedule_len, 6);
    assert_eq!(c.recording().copied().collect::<Vec<_>>(), schedule);
    for (a, s) in c.steps.iter().zip(&schedule) {
        assert_eq!(a.table, TableAction::Rate(s.rate_dps));
        assert_eq!(a.dwell, Duration::from_secs(3));
        assert_eq!(a.acquire, Acquiring::Readings(s.acquire));
        assert_eq!(
            a.hold,
            HoldCheck::Rate {
                demand_dps: s.rate_dps,
                tolerance_dps: 0.002
            }
        );
        assert_eq!(a.record, Record::Row(*s));
    }
}

#[test]
fn a_sweep_warm_up_is_a_first_step_at_zero_rate_not_repeated_once_complete() {
    let plan = sweep(true);
    let schedule = plan.schedule();
    let c = compile(&plan, &schedule[2..], false);
    assert_eq!(c.steps.len(), 5);
    let w = &c.steps[0];
    assert_eq!(w.table, TableAction::Rate(0.0));
    assert_eq!(w.dwell, Duration::ZERO);
    assert!(matches!(w.acquire, Acquiring::UntilSettled(s) if s.window == Duration::from_secs(10)));
    assert_eq!(w.hold, HoldCheck::None);
    assert_eq!(w.record, Record::Warmup);
    assert_eq!(w.step(), None);
    // resume keys: the remaining steps, in order, after it
    assert_eq!(c.recording().copied().collect::<Vec<_>>(), schedule[2..]);
    assert_eq!(c.warmup_in_record, None);

    let again = compile(&plan, &schedule[2..], true);
    assert_eq!(again.steps.len(), 4);
    assert!(again.steps.iter().all(|a| a.record != Record::Warmup));
}

#[test]
fn a_drift_record_is_segment_steps_with_the_table_role_in_each_step() {
    let hold = drift("hold", false);
    let c = compile(&hold, &hold.schedule(), false);
    assert_eq!(c.setup, Setup::EnableTable);
    assert!(c.uses_table);
    assert_eq!(c.steps.len(), 4);
    assert!(c.steps.iter().all(|a| a.table == TableAction::Rate(0.0)
        && matches!(a.hold, HoldCheck::Rate { demand_dps, .. } if demand_dps == 0.0)
        && matches!(a.record, Record::Segment(_))));

    let off = drift("servo_off", false);
    let c = compile(&off, &off.schedule(), false);
    assert_eq!(c.setup, Setup::RestThenServoOff);
    assert!(c.uses_table);
    assert!(c.steps.iter().all(|a| a.table == TableAction::ServoOff
        && a.table.demand_dps().is_none()
        && matches!(a.hold, HoldCheck::ServoOff { .. })));

    let none = drift("none", false);
    let c = compile(&none, &none.schedule()[1..], false);
    assert_eq!(c.setup, Setup::Nothing);
    assert!(!c.uses_table);
    assert_eq!(c.steps.len(), 3);
    assert_eq!(c.steps[0].step().map(|s| s.index), Some(1));
    assert!(
        c.steps
            .iter()
            .all(|a| a.table == TableAction::Untouched && a.hold == HoldCheck::None)
    );
}

#[test]
fn a_drift_warm_up_is_watched_in_the_record_not_a_step_and_not_repeated() {
    let plan = drift("hold", true);
    let c = compile(&plan, &plan.schedule(), false);
    assert_eq!(c.steps.len(), 4);
    assert!(c.steps.iter().all(|a| a.record != Record::Warmup));
    assert_eq!(
        c.warmup_in_record.map(|w| w.max),
        Some(Duration::from_secs(600))
    );
    let again = compile(&plan, &plan.schedule()[2..], true);
    assert_eq!(again.warmup_in_record, None);
}
