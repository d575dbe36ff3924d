//! A scale-factor sweep compiled to steps: the table enabled, an optional warm-up at 0 °/s
//! first (a step of its own, acquired until the readings settle), then every remaining step
//! of the schedule: demand its rate, dwell, acquire, check the hold, record a row.

use std::time::Duration;

use super::{Acquiring, Action, Analysis, Compiled, HoldCheck, Record, Setup, TableAction};
use crate::plan::{Plan, Step};

/// See the module docs.
pub(super) fn compile(plan: &Plan, remaining: &[Step], warmup_done: bool) -> Compiled {
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
        }))
        .collect();
    Compiled {
        setup: Setup::EnableTable,
        steps,
        warmup_in_record: None,
        schedule_len: plan.step_count(),
        uses_table: true,
        analysis: Analysis::Fit,
    }
}
