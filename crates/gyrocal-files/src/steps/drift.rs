//! A drift record compiled to steps: segment steps at zero rate, the table's part set by
//! `[drift] table` (hold 0 °/s with the servo on, at rest with the servo off, or no table),
//! the warm-up (when asked for) watched in the record's first segments.

use super::{Acquiring, Action, Analysis, Compiled, HoldCheck, Record, Setup, TableAction};
use crate::plan::{Plan, Step, TableRole};

/// See the module docs.
pub(super) fn compile(plan: &Plan, remaining: &[Step], warmup_done: bool) -> Compiled {
    let role = plan.drift().table;
    let tolerance_dps = plan.table().rate_tolerance_dps;
    let setup = match role {
        TableRole::Hold => Setup::EnableTable,
        TableRole::ServoOff => Setup::RestThenServoOff,
        TableRole::None => Setup::Nothing,
    };
    let steps = remaining
        .iter()
        .map(|step| {
            let (table, hold) = match role {
                TableRole::Hold => (
                    TableAction::Rate(step.rate_dps),
                    HoldCheck::Rate {
                        demand_dps: step.rate_dps,
                        tolerance_dps,
                    },
                ),
                TableRole::ServoOff => {
                    (TableAction::ServoOff, HoldCheck::ServoOff { tolerance_dps })
                }
                TableRole::None => (TableAction::Untouched, HoldCheck::None),
            };
            Action {
                table,
                dwell: plan.settle(),
                acquire: Acquiring::Readings(step.acquire),
                hold,
                record: Record::Segment(*step),
            }
        })
        .collect();
    Compiled {
        setup,
        steps,
        warmup_in_record: plan.warmup().copied().filter(|_| !warmup_done),
        schedule_len: plan.step_count(),
        uses_table: role != TableRole::None,
        analysis: Analysis::Allan,
    }
}
