//! The scale-factor sweep (`[plan] kind = "scale_factor"`, the default): `repeat` passes over
//! `rates_dps`, each step's mean voltage fitted to a line (the paper's method). Everything
//! only a sweep has is here: its rule on the rates. (Whole-turn acquisition,
//! `whole_revolutions`, is a `[plan]` key every kind parses; only a sweep has non-zero rates
//! for it to act on.)

use super::error::PlanError;
use super::validate::Ctx;

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
