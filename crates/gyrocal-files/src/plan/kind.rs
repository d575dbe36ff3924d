//! What a plan measures ([`PlanKind`]) and the one dispatch on it in the plan crate: each
//! kind's own rules live in its module ([`super::sweep`], [`super::drift`]); adding a kind is
//! a variant here, an arm in each match below (its rules, its compile to steps) and its
//! module.

use super::error::PlanError;
use super::validate::Ctx;
use super::{drift, sweep};

pub(super) fn default_kind() -> String {
    PlanKind::ScaleFactor.as_str().to_string()
}

pub(super) fn is_scale_factor(kind: &str) -> bool {
    kind == PlanKind::ScaleFactor.as_str()
}

/// What a plan measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PlanKind {
    /// A sweep of rates for the scale factor (the paper's method).
    #[default]
    ScaleFactor,
    /// A static record at zero rate (IEEE 952 §6.6 drift test) in durable segments: every
    /// rate is 0, `samples_per_rate` readings make one segment (one step) and `repeat`
    /// segments the record; analysed by Allan deviation instead of a line.
    Drift,
}

impl PlanKind {
    /// All kinds.
    pub const ALL: [PlanKind; 2] = [PlanKind::ScaleFactor, PlanKind::Drift];

    /// `scale_factor` or `drift`, as written in a plan.
    pub fn as_str(self) -> &'static str {
        match self {
            PlanKind::ScaleFactor => "scale_factor",
            PlanKind::Drift => "drift",
        }
    }
}

/// Compiles `plan` (of this kind) for a session that runs `remaining` steps of its schedule:
/// the one dispatch on the kind for the run's engine (see [`crate::steps::compile`]).
pub(crate) fn compile(
    plan: &super::Plan,
    remaining: &[super::Step],
    warmup_done: bool,
) -> crate::steps::Compiled {
    match plan.kind() {
        PlanKind::ScaleFactor => sweep::compile(plan, remaining, warmup_done),
        PlanKind::Drift => drift::compile(plan, remaining, warmup_done),
    }
}

/// What a kind says of itself in `gyrocal check` (its own section of the plan).
#[derive(Debug, Clone, PartialEq)]
pub struct KindSummary {
    /// One line for the terminal.
    pub line: String,
    /// Its settings for `gyrocal check --json` (under the kind's name).
    pub json: serde_json::Value,
}

pub(super) fn summary(plan: &super::Plan) -> Option<KindSummary> {
    match plan.kind() {
        PlanKind::ScaleFactor => None,
        PlanKind::Drift => Some(drift::summary(&plan.drift())),
    }
}

/// `[plan] kind` as written.
pub(super) fn parse(kind: &str, cx: &Ctx<'_>) -> Result<PlanKind, PlanError> {
    PlanKind::ALL
        .into_iter()
        .find(|k| k.as_str() == kind.trim())
        .ok_or_else(|| {
            cx.err(
                "plan.kind",
                format!(
                    "unknown kind {kind:?}: write \"scale_factor\" (a sweep of rates) or \"drift\" (a static record at zero rate)"
                ),
            )
        })
}

/// The kind's own rule on the rates of one pass (`rates`, validated; `written`, as in the
/// file, for the message).
pub(super) fn check_rates(
    kind: PlanKind,
    rates: &[f64],
    written: &[f64],
    cx: &Ctx<'_>,
) -> Result<(), PlanError> {
    match kind {
        PlanKind::ScaleFactor => sweep::check_rates(rates, cx),
        PlanKind::Drift => drift::check_rates(rates, written, cx),
    }
}
