//! The scale-factor sweep (`[plan] kind = "scale_factor"`, the default): `repeat` passes over
//! `rates_dps`, each step's mean voltage fitted to a line (the paper's method). Everything
//! only a sweep has is here: its rule on the rates. (Whole-turn acquisition,
//! `whole_revolutions`, is a `[plan]` key every kind parses; only a sweep has non-zero rates
//! for it to act on.)

use super::error::PlanError;
use super::validate::Ctx;
use std::time::Duration;

use super::Plan;
use super::schedule::Step;
use crate::steps::{Acquiring, Action, ChamberAction, Compiled, HoldCheck, Record, Setup, TableAction};

/// A sweep fits a line: it needs at least two distinct rates.
pub(super) fn check_rates(rates: &[f64], cx: &Ctx<'_>) -> Result<(), PlanError> {
    let mut distinct = rates.to_vec();
    distinct.sort_by(f64::total_cmp);
    distinct.dedup();
    if distinct.len() < 2 {
        return Err(cx.err(
            "plan.rates_dps",
            format!(
                "needs at least two distinct rates to fit a line (got {})",
                distinct.len()
            ),
        ));
    }
    Ok(())
}

/// The sweep compiled to steps (see [`crate::steps`]): the table enabled, an optional warm-up at
/// 0 °/s first (a step of its own, acquired until the readings settle), then every remaining
/// step of the schedule: demand its rate, dwell, acquire, check the hold, record a row.
pub(crate) fn compile(plan: &Plan, remaining: &[Step], warmup_done: bool) -> Compiled {
    let tolerance_dps = plan.table().rate_tolerance_dps;
    let warmup = plan
        .warmup()
        .filter(|_| !warmup_done)
        .map(|settings| Action {
            // the table holds 0 °/s while the readings settle; no dwell: the readings are
            // what is watched
            table: TableAction::Rate(0.0),
            dwell: Duration::ZERO,
            acquire: Acquiring::UntilSettled(*settings),
            hold: HoldCheck::None,
            record: Record::Warmup,
            chamber: ChamberAction::None,
        });
    let steps = warmup
        .into_iter()
        .chain(remaining.iter().map(|step| Action {
            table: TableAction::Rate(step.rate_dps),
            dwell: plan.settle(),
            acquire: Acquiring::Readings(step.acquire),
            hold: HoldCheck::Rate {
                demand_dps: step.rate_dps,
                tolerance_dps,
            },
            record: Record::Row(*step),
            chamber: ChamberAction::None,
        }))
        .collect();
    Compiled {
        setup: Setup::EnableTable,
        steps,
        warmup_in_record: None,
        schedule_len: plan.step_count(),
        uses_table: true,
        uses_chamber: false,
    }
}
